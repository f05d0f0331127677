/* embedded.h — models embedded in a session's solid (free-form deformation, 004 Sec. 5.1;
 * docs/API.md "Embedded models").
 *
 * A model (vertices, optional triangles: its rest shape, as posted) is bound to level L of the
 * session's solid: every vertex located in a level-L solid cell (an octahedron as the 4
 * tetrahedra around its major diagonal) with barycentric coordinates (core/embed.c). Its
 * deformed shape is then the same combination of the cell's *current* points, so it follows
 * every edit through the level the edit already updated: nothing is recomputed when a point
 * moves; a read combines, a delta combines only the model vertices bound to the level points
 * stamped since (api/delta.h), at a cost proportional to those.
 *
 * A definition (name, rest shape, level, outside mode) is immutable and shared by the models of a
 * session; the binding belongs to one model (its complex's level L). Changing the complex, the
 * tags or the rules makes a new model, to which every definition is bound anew (all or nothing:
 * a vertex outside under "refuse" fails the change with 422); a new model of the same topology
 * (an edit that built rules again, a replayed journal) carries the bindings over instead. PUT and DELETE change the current
 * model's list in place, under its lock, with a new session version, like an edit.
 * Locking: the list and the bindings are read and changed with m->lock held.
 */
#ifndef SUBDIVD_API_EMBEDDED_H
#define SUBDIVD_API_EMBEDDED_H

#include "handlers.h"
#include "model.h"
#include <jansson.h>
#include <stdatomic.h>

typedef struct api_embed_def {
    atomic_int refs;
    char name[API_MAX_EMBED_NAME + 1];
    int level;
    int outside;              /* sd_outside */
    uint32_t nv, nt;
    double *rest;             /* 3 nv: the posted vertices */
    uint32_t *tri;            /* 3 nt */
} api_embed_def;

typedef struct api_embed {
    api_embed_def *def;
    struct sd_embedding *bind; /* to level def->level of the model's complex */
    uint64_t since;           /* the version it was bound at: deltas from before it are 410 */
    size_t outside;           /* vertices outside every cell (kept rigid, or bound to the nearest) */
    double *scratch;          /* 3 nv: what sd_embed_update writes */
    uint32_t *moved;          /* nv */
} api_embed;

/* Parse the body of PUT /embedded/{name} into a new definition (reference 1): {"vertices",
 * "triangles", "level", "outside"}; the name checked (1-48 of [A-Za-z0-9_-]), the vertex count
 * against lim->max_embedded_vertices before anything is allocated. 0 or the problem's status. */
int api_embed_parse(json_t *body, const char *name, const api_limits *lim, api_embed_def **out,
                    api_problem *p);
/* The same from the binary body (application/octet-stream: uint32 nv, uint32 nt, nv*3 float64,
 * nt*3 uint32, little endian) with level and outside from the query (NULL: the defaults). */
int api_embed_parse_binary(const char *body, size_t len, const char *name, const char *level,
                           const char *outside, const api_limits *lim, api_embed_def **out,
                           api_problem *p);
void api_embed_def_unref(api_embed_def *d);

/* Bind d to m's level (computed first, within lim, in `slot`: NULL when the caller holds one)
 * and put it in m's list (replacing the model of that name), stamped `version`; then
 * commit->fn (may be NULL) is called with m's lock held — the durable store — and a failure
 * there takes it out again. *summary: {"name", "vertices", "level", "outside", "seconds",
 * "outside_vertices"}. 0 or the problem's status: 422 (vertices outside under "refuse": the count
 * and the first indices; a complex without solid cells), 409 (no complex), 413, 429, 503. */
int api_embed_put(api_model *m, api_embed_def *d, uint64_t version, const api_limits *lim,
                  const api_slot *slot, const api_edit_commit *commit, json_t **summary,
                  api_problem *p);
/* Take model `name` out of m's list (404 when there is none), commit as for put. */
int api_embed_delete(api_model *m, const char *name, uint64_t version,
                     const api_edit_commit *commit, api_problem *p);
/* GET /embedded: [{"name", "vertices", "triangles", "level", "outside"}]. */
json_t *api_embed_list(api_model *m);
/* GET /embedded/{name}?format=json|obj|glb: the deformed model as a complete body (api_malloc),
 * its content type, and the model version (ETag). 0, 404, 422 (format), 503. */
int api_embed_get(api_model *m, const char *name, const char *format, char **body, size_t *len,
                  const char **ctype, uint64_t *version, api_problem *p);
/* GET /embedded/{name}/delta?since=&format=bin|json: the model vertices that moved since a
 * version (binary "SDD1" as for levels, the level field being the binding's level; JSON
 * {"name", "level", "since", "version", "indices", "positions"}). 410 as for levels, and for a
 * version before the model was bound. */
int api_embed_delta(api_model *m, const char *name, const char *since, const char *format,
                    char **body, size_t *len, const char **ctype, uint64_t *version,
                    api_problem *p);

/* Every model of `from` bound to `to` (a new model of the session, not yet published), its rest
 * shape posted anew: levels computed within lim (in `slot`, NULL when the caller holds one).
 * 0, or 422 naming the model whose vertices fall outside under "refuse" (to is unchanged). */
int api_embed_rebind(const api_model *from, api_model *to, const api_limits *lim,
                     const api_slot *slot, api_problem *p);
/* Every model of `from` put into `to` with the binding it has — `to` being a model of the same
 * topology (an edit that built rules again, a replayed journal): the models go on from where
 * they are, not from their rest shape. 0, or the status (to's list then empty). */
int api_embed_carry(const api_model *from, api_model *to, const api_limits *lim, api_problem *p);
/* The models as GET /export holds them: {name: {"vertices", "triangles", "level", "outside"}}. */
json_t *api_embed_export(const api_model *m);
/* The "embedded" member of an import document into m (freshly built): 0 or the status, the
 * problem's pointers under `base`. */
int api_embed_import(api_model *m, json_t *emb, const char *base, const api_limits *lim,
                     api_problem *p);
/* Free m's list (the model is being freed). */
void api_embed_free_all(api_model *m);
/* Bytes m's bindings and their buffers hold (session memory). */
size_t api_embed_bytes(const api_model *m);

#endif
