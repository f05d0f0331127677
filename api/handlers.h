/* handlers.h — the v1 endpoints as functions of (model, parsed request) -> (new model, JSON).
 *
 * No HTTP here: the transport (server/routes.c, or the offline `subdivd refine` of server/main.c)
 * parses the body with api_parse_body, picks the handler from its route table, and maps the
 * returned status and api_problem to a response. One file per resource defines them:
 * complex.c, rules.c (rules and tags), levels.c, edit.c, inspect.c (analysis, matrices) and
 * refine.c; what those share is internal.h. Handlers that change a session return a NEW model (the current one
 * is never modified) which the caller publishes with the next version number; on any failure
 * nothing is returned and the session stays as it was (all-or-nothing).
 */
#ifndef SUBDIVD_HANDLERS_H
#define SUBDIVD_HANDLERS_H

#include "limits.h"
#include "model.h"
#include "out.h"
#include "packed.h"
#include "problem.h"
#include <jansson.h>

/* The signature shared by the three change handlers below. */
typedef int (*change_fn_t)(const api_model *cur, json_t *body, const api_limits *lim,
                           api_model **out, api_problem *p);

/* PUT /complex: the body of docs/API.md. Keeps the current rule choices. On success *out is the new
 * model and the function returns 0; else the problem's status. */
int api_put_complex(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                    api_problem *p);
/* The same with the big arrays of the body packed beside the tree (api/packed.h; packs may be
 * NULL): the answers are those of the unpacked body. api_complex_packed lists the JSON pointers
 * to pack (NULL-terminated patterns for api_parse_body_packed). */
int api_put_complex_packed(const api_model *cur, json_t *body, const api_packs *packs,
                           const api_limits *lim, api_model **out, api_problem *p);
extern const char *const api_complex_packed[];
/* PUT /rules: replaces every rule preference (absent fields = defaults). */
int api_put_rules(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                  api_problem *p);
/* PUT /tags: validates the singular simplices against the complex. */
int api_put_tags(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                 api_problem *p);
/* The same with "singular" packed beside the tree (api_tags_packed: the patterns). */
int api_put_tags_packed(const api_model *cur, json_t *body, const api_packs *packs,
                        const api_limits *lim, api_model **out, api_problem *p);
/* The tags of an imported document (api/export.c): as PUT /tags, but a singular simplex listed
 * twice, which daemons before 2026-12-07 took and exported, is taken once. */
int api_import_tags(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                    api_problem *p);
extern const char *const api_tags_packed[];
/* The offline modes' change (api/offline.c): fn applied to the text buf (len bytes; NULL: an empty
 * object) parsed as the daemon parses that body, or to `body` (stolen) when not NULL, with the
 * members of `extra` (borrowed, may be NULL) added. 0 and *out the new model, else the status. */
int api_apply_text(const api_model *cur, change_fn_t fn, char *buf, size_t len, json_t *body,
                   json_t *extra, const api_limits *lim, api_model **out, api_problem *p);

/* The summary of a model's complex (new reference; {} without a complex). */
json_t *api_summary(const api_model *m);
/* GET /complex (new reference), or NULL + 409 when no complex was posted. Locks the model. */
json_t *api_get_complex(api_model *m, api_problem *p);
/* The complex as PUT /complex takes it back (no classes, tags, rules or summary; "details"
 * included), json null without a complex. The parts of GET /complex that say the tags and the
 * rules as PUT /tags and PUT /rules take them. All new references. */
json_t *api_complex_json(api_model *m);
json_t *api_tags_json(const api_model *m);
json_t *api_rules_json(const api_model *m);
/* GET /export (api/export.c): the session's control data at `version` as one document. */
json_t *api_export(api_model *m, uint64_t version);
/* The model of an export document (POST /v1/sessions {"import"}, the durable store's
 * snapshots); `base` is the document's JSON pointer in the request ("/import"), prefixed to
 * every problem's pointer. *version is the document's, at most max_version: a client's import
 * API_IMPORT_MAX_VERSION, which leaves room for more changes than a session can see while every
 * version stays exact as a JSON number (2^53); a restore from the store whatever the daemon
 * wrote (LLONG_MAX). */
#define API_IMPORT_MAX_VERSION ((long long)1 << 52)
int api_import(json_t *doc, const char *base, const api_limits *lim, long long max_version,
               api_model **out, uint64_t *version, api_problem *p);
/* GET /complex as a stream (api/complex_stream.h): the same bytes as json_dumps(JSON_COMPACT) of
 * api_get_complex's document with "version" added last, which is *version, the version of the
 * points and attributes it copied. Keep a reference on m until api_cstream_free. NULL + 409 or
 * 503. */
struct api_cstream *api_get_complex_stream(api_model *m, uint64_t *version, api_problem *p);

/* Query options of GET /levels/{L} (NULL = absent). */
typedef struct api_level_query {
    const char *format, *parts, *slice, *attributes, *colormap, *octahedra, *names, *compress,
        *limit;
} api_level_query;

/* A compute slot of the transport (the daemon's scheduler; NULL offline): take waits for one
 * to compute `level` (0) or fills a problem (429) and returns its status; give returns it.
 * The handlers that may compute a level take one only once they hold the model's lock (a
 * request waiting for its own session's computation holds no slot). */
typedef struct api_slot {
    int (*take)(void *ud, int level, api_problem *p);
    void (*give)(void *ud);
    void *ud;
} api_slot;

/* Checks the query and the limits, computes level L if needed (in a slot), and opens the
 * output stream on a snapshot of what edits change (points, channels, normals), with that
 * content's version in *version. The stream holds no lock: close it with out_close, keeping a
 * reference on the model until then. */
int api_level_open(api_model *m, int level, const api_level_query *q, const api_limits *lim,
                   const api_slot *slot, out_stream **out, const out_format **fmt,
                   uint64_t *version, api_problem *p);

/* PATCH /control-points: moves and attribute values of control points, and moves of points of
 * finer levels ("level": l, stored as detail offsets; missing levels are computed, within lim),
 * applied to every cached level through the matrices, in place, and the model's version set to
 * `version` (the one the session publishes it with): the changed points are stamped with it
 * (api/delta.h). Validates all first. An edit that moves a point a level's rules read
 * (Ying-Zorin's corner angle) is answered with a new model instead (*rebuilt, built in a compute
 * slot of `slot`, with the session's detail offsets and the edit's), to be published in place of
 * m, which is left unchanged. counts[l] = points updated at level l; *levels = levels computed
 * now. 0 or the status. A failed edit leaves m as it was; only when undoing a half-applied edit
 * runs out of memory too is *rebuilt set with the status: a model built again from m's input
 * and offsets (the content before the edit), to be published in place of m. */
int api_edit(api_model *m, json_t *body, uint64_t version, const api_limits *lim,
             const api_slot *slot, uint64_t *counts, int *levels, api_model **rebuilt,
             api_problem *p);
/* The same, where the transport must keep the edit before anyone sees it (the durable store,
 * server/persist.h): once the edit is applied in place, and while the model's locks still keep
 * readers out, commit->fn is called; when it fails (0 or the status of its problem) the edit is
 * undone — the points and offsets back to the bytes they had — and its problem returned. Not
 * called for an edit answered with *rebuilt (nothing changed in place: the caller keeps the new
 * model before publishing it). */
typedef struct api_edit_commit {
    int (*fn)(void *ud, api_problem *p);
    void *ud;
} api_edit_commit;
int api_edit_commit_by(api_model *m, json_t *body, uint64_t version, const api_limits *lim,
                       const api_slot *slot, const api_edit_commit *commit, uint64_t *counts,
                       int *levels, api_model **rebuilt, api_problem *p);

/* GET /levels/{L}/stats (new reference). */
json_t *api_level_stats(api_model *m, int level, const api_limits *lim, const api_slot *slot,
                        api_problem *p);

/* GET /analysis?vertex=i | ?edge=i,j (001 Sec. 4.1): the local subdivision matrix of a control
 * vertex (1-ring block M) or edge (block L of its midpoint) and its eigenvalues, largest in
 * magnitude first, the centre's limit mask (at its limit level) and, where the neighbourhood is
 * invariant, the full matrix (levels 1 and 2). Locks the model (an edge needs level 1). Levels
 * past lim are not computed for the limit mask or the full matrix: they are null then. New
 * reference or NULL + problem. */
json_t *api_analysis(api_model *m, const char *vertex, const char *edge, const api_limits *lim,
                     const api_slot *slot, api_problem *p);

/* GET /matrices/{L}?from=F&format=mtx|json: computes level L if needed and opens the stream of
 * the matrix mapping level F (default 0) to level L. *ctype: the Content-Type. */
int api_matrix_open(api_model *m, int level, const char *from, const char *format,
                    const api_limits *lim, const api_slot *slot, out_stream **out,
                    const char **ctype, api_problem *p);

/* What a refinement did: the simplices split red and green, the steps made (a step made again
 * when a later one takes back its green cells counts again), and whether the cap on steps left
 * green cells that a later step split (their parents were not split red). */
typedef struct api_refined {
    uint64_t red, green;
    int steps;
    bool capped;
} api_refined;

/* POST /refine: red-green refinement of the control complex (000 Sec. 4.2) around the selected
 * simplices (by vertex lists), box or sphere (centroids), `depth` times, new points placed by
 * the subdivision rules or at midpoints. A new model, and what was split into *done. */
int api_refine(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
               api_refined *done, api_problem *p);

/* Level from a path segment: 0..SD_MAX_LEVEL, else -1 + problem (400 not a number, 422 range). */
int api_parse_level(const char *s, api_problem *p);
/* parts=points,curves,surfaces,solids (a comma list; NULL: all) into an OUT_PART_* mask: 0, or
 * the status of the problem (422 naming "parts"). */
int api_parse_parts(const char *text, unsigned *parts, api_problem *p);
/* Estimated core bytes needed to hold levels up to `level` (limits check before computing). */
uint64_t api_estimate_bytes(const sd_complex *c, int level);

#endif
