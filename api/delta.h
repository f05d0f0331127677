/* delta.h — what changed in a model's computed levels since a session version, for clients that
 * already hold a level (GET /v1/sessions/{id}/levels/{L}/delta, docs/API.md "Live edits").
 *
 * A model keeps, per computed level, the version at which each point's position last changed and,
 * per attribute, the version at which its value did (stamps, fed by sd_edit_report's callback
 * while the edit holds the model's locks), plus the level's drawn-triangle incidence, with which
 * an edit updates the cached glTF normals (m->geometry) of the vertices around moved points —
 * copy on write, since a stream may hold the geometry — summed in out_normals' order, so the glTF
 * after an edit is the bytes of a fresh one, and the normals a delta sends are the glTF's. Only
 * edits are deltas: a new model (complex, tags, rules, refine, or an edit that moved what a
 * level's rules read, api/edit.c) starts without stamps, so a delta from before it is refused
 * (410), as is one from before the level was computed, one ahead of the model, or one of a level
 * not computed (docs/DECISIONS.md 36).
 *
 * Locking: every function here is called with m->lock held (the edit functions also with the
 * data write lock); the stamps and the incidence are m's, freed with it.
 */
#ifndef SUBDIVD_API_DELTA_H
#define SUBDIVD_API_DELTA_H

#include "model.h"
#include "problem.h"
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef struct api_delta api_delta;

/* A model's (empty) delta state; NULL for lack of memory. */
api_delta *api_delta_new(void);
void api_delta_free(api_delta *d);
/* Bytes held by the stamps and incidence lists (counted as session memory). */
size_t api_delta_bytes(const api_delta *d);

/* One sd_complex_move call of an edit: which channel it moves and the version the edit will
 * have. api_delta_report points rep's callback at it. */
typedef struct api_delta_edit {
    api_model *m;
    int attr;            /* -1: positions (channel 0); else the index of the input's attribute */
    uint64_t version;    /* the edit's version (the model's current one + 1) */
} api_delta_edit;

/* With a level's geometry (api_model_geometry_locked): the stamps and incidence edits of it
 * need, made now rather than by the first edit. */
void api_delta_prepare(api_model *m, int level);
/* Before an edit: levels computed since the last edit or delta start at the model's version. */
void api_delta_begin_edit(api_model *m);
/* Zero rep and set its callback to stamp, for this call, the points that changed (and, for
 * positions, to update the cached normals around them). */
void api_delta_report(api_delta_edit *de, sd_edit_report *rep);
/* After a successful edit (m->version still the old one). */
void api_delta_end_edit(api_model *m);

/* After a model was rebuilt from the store (server/sessions.c), at its stored version: deltas
 * since an older version are 410 (the delta history is not stored; the replay's stamps are not
 * the history the clients saw). Called before the model is shared. */
void api_delta_loaded(api_model *m);

/* The query of GET /levels/{L}/delta (NULL = absent). */
typedef struct api_delta_query {
    const char *since, *format, *attributes;
    const char *parts;   /* the GLB's parts= the client holds: the normals are those of its
                          * drawn triangles (NULL: all parts) */
} api_delta_query;

/* The delta of level L since q->since as a complete body (an api_malloc block the caller owns),
 * "SDD1" binary or JSON (docs/API.md), with its content type, and the model version it brings
 * the level to (the ETag). Locks the model. 0, or the status of the problem: 400 (since missing or
 * not a number), 422 (format, attributes), 409 (no complex), 410 (see above), 503. */
int api_level_delta(api_model *m, int level, const api_delta_query *q, char **body, size_t *len,
              const char **ctype, char *components, size_t ccap, uint64_t *version,
              api_problem *p);

/* The query's format and attributes checked against m as api_level_delta would (since must be
 * given): 0, or the status of the problem. PATCH ?delta= checks it before the edit. */
int api_delta_check(const api_model *m, const api_delta_query *q, api_problem *p);

/* The points of level L whose position changed after version *since (parsed from since_text,
 * with format bin|json into *json), in ascending order (an api_malloc block, may be NULL when
 * none), under the rules of api_level_delta (410 ...). The caller holds m->lock. For the deltas
 * of what follows a level (embedded models). */
int api_delta_moved(api_model *m, int level, const char *since_text, uint64_t *since,
                    int *json, const char *format, uint32_t **ids, size_t *n, api_problem *p);

#endif
