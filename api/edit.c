/* edit.c — PATCH /control-points (docs/API.md "Control-point edits", "Live edits"): moves and
 * attribute values of control points, and moves of points of finer levels, pushed through the
 * cached subdivision matrices into every computed level (004 Sec. 4.1: the matrix is built once
 * per topology and applied many times; Sec. 5.2: a move at level l >= 1 is a detail offset the
 * session keeps, sd_complex_move).
 *
 * All-or-nothing: every entry is checked (level and index ranges, repeats, value shapes, and no
 * simplex of the control complex made degenerate by the control-point moves) before anything
 * changes; then the edit runs under the model's compute lock and its data write lock — which
 * streams hold only while they copy what they send (api/levels.c), so an edit never waits for a
 * slow client — the positions in one sd_complex_move (coarse to fine), then each attribute, and
 * one that fails half-way is undone part by part (control points put back, the offsets as they
 * were). Each call reports the points it changed to api/delta.c, which stamps them with the
 * edit's version and keeps the cached glTF normals in step (copy on write: a stream may hold
 * them). The edit changes channel values only (rep.in_place): where a level's rules read a moved
 * point (Ying-Zorin's corner angle), it becomes a new model built from the edited input, with the
 * session's offsets and the edit's finer moves applied to it, instead of a rebuild of levels in
 * place, since streams in flight read those levels' topology and rules without a lock. The posted
 * input follows the control-point moves, so later rule changes rebuild from the new values; the
 * model's version becomes the edit's, with the values.
 *
 * Moves at levels >= 1 are not checked for degeneracy: they change no simplex of the control
 * complex (which is what PUT /complex validates), only a point of a subdivided level, whose
 * cells may fold as the levels of any folded control complex do (docs/DECISIONS.md 35).
 */
#include "handlers.h"
#include "delta.h"
#include "details.h"
#include "mem.h"
#include "internal.h"
#include "jsonin.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- PATCH /control-points ---------------------------------------------------------------- */

/* One channel's part of an edit: the points (body order) and their new values (ncomp each); of
 * them, the n0 control points (entry numbers k0) with their values before (for an undo). */
typedef struct edit_part {
    int channel, attr;        /* attr: index into the input's attributes, -1 for positions */
    int ncomp;
    size_t n, n0;
    sd_vertex_at *at, *at0;
    uint32_t *k0;
    double *val, *old;
} edit_part;

/* No point of a level >= 1 named twice (control points are checked with `seen`). */
static int repeated_fine(const edit_part *e, const char *base, api_problem *p)
{
    size_t n = 0;
    for (size_t i = 0; i < e->n; i++)
        n += e->at[i].level > 0;
    if (n < 2)
        return 0;
    api_ptkey *k = api_malloc(n * sizeof *k);
    if (!k)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    n = 0;
    for (size_t i = 0; i < e->n; i++)
        if (e->at[i].level > 0)
            k[n++] = (api_ptkey){(uint32_t)e->at[i].level, e->at[i].index, i};
    qsort(k, n, sizeof *k, api_ptkey_cmp);
    int rc = 0;
    for (size_t i = 1; i < n && !rc; i++)
        if (k[i].level == k[i - 1].level && k[i].index == k[i - 1].index) {
            char ptr[96], at[96];
            api_ptr_index(ptr, sizeof ptr, base, k[i].k);
            api_ptr_key(at, sizeof at, ptr, "index");
            rc = api_fail_at(p, 422, "repeated-index", at, "point %u of level %u is moved twice",
                             k[i].index, k[i].level);
        }
    api_free(k);
    return rc;
}

/* The entries of one list: {"index", vkey[, "level"]} (levels: moves may name one, default 0,
 * whose points are counted by the split table). */
static int parse_edit_entries(json_t *arr, const char *base, const char *vkey, int ncomp,
                              bool levels, const api_model *m, edit_part *e, int32_t *seen,
                              api_problem *p)
{
    char ptr[96], at[96];
    uint32_t nv = m->in->nv;
    if (!json_is_array(arr))
        return api_fail_at(p, 400, "wrong-type", base, "must be an array of {\"index\", \"%s\"%s}",
                           vkey, levels ? ", \"level\"" : "");
    size_t n = json_array_size(arr);
    if (n > nv && !levels)
        return api_fail_at(p, 422, "repeated-index", base,
                           "%zu entries for %u control points: some point is listed twice", n, nv);
    e->at = api_malloc((n ? n : 1) * sizeof *e->at);
    e->at0 = api_malloc((n ? n : 1) * sizeof *e->at0);
    e->k0 = api_malloc((n ? n : 1) * sizeof *e->k0);
    e->val = api_malloc((n ? n : 1) * ncomp * sizeof *e->val);
    e->old = api_malloc((n ? n : 1) * ncomp * sizeof *e->old);
    if (!e->at || !e->at0 || !e->k0 || !e->val || !e->old)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    e->ncomp = ncomp;
    const char *const keys[] = {"index", vkey, levels ? "level" : NULL, NULL};
    uint64_t count[SD_MAX_LEVEL + 1] = {nv};
    int rc = 0;
    size_t i;
    for (i = 0; i < n && !rc; i++) {
        json_t *o = json_array_get(arr, i), *x;
        api_ptr_index(ptr, sizeof ptr, base, i);
        if (!json_is_object(o)) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "an entry is {\"index\", \"%s\"%s}", vkey,
                             levels ? ", \"level\"" : "");
            break;
        }
        long long v, lv = 0;
        if ((rc = api_only_keys(o, ptr, keys, p)))
            break;
        api_ptr_key(at, sizeof at, ptr, "level");
        if ((x = json_object_get(o, "level")) && (rc = api_get_int(x, at, 0, SD_MAX_LEVEL, &lv, p)))
            break;
        if (lv && !count[lv]) {
            sd_counts k;
            sd_complex_counts(m->c, (int)lv, &k);
            count[lv] = k.vertices < UINT32_MAX ? k.vertices : UINT32_MAX;
        }
        api_ptr_key(at, sizeof at, ptr, "index");
        if (!(x = json_object_get(o, "index"))) {
            rc = api_fail_at(p, 400, "missing-field", at, "\"index\" is required");
            break;
        }
        if ((rc = api_get_int(x, at, 0, (long long)count[lv] - 1, &v, p)))
            break;
        if (!lv && seen[v] >= 0) {
            rc = api_fail_at(p, 422, "repeated-index", at, "point %lld is edited twice", v);
            break;
        }
        e->at[i] = (sd_vertex_at){(int)lv, (uint32_t)v};
        if (!lv) {
            seen[v] = (int32_t)i;
            e->k0[e->n0] = (uint32_t)i;
            e->at0[e->n0++] = e->at[i];
        }
        api_ptr_key(at, sizeof at, ptr, vkey);
        if (!(x = json_object_get(o, vkey))) {
            rc = api_fail_at(p, 400, "missing-field", at, "\"%s\" is required", vkey);
            break;
        }
        if (ncomp == 1 && json_is_number(x)) {
            rc = api_get_number(x, at, API_MAX_VALUE, &e->val[i], p);
            continue;
        }
        if (!json_is_array(x) || json_array_size(x) != (size_t)ncomp) {
            rc = api_fail_at(p, 400, "wrong-type", at, "must be %s%d numbers",
                             ncomp == 1 ? "a number or an array of " : "an array of ", ncomp);
            break;
        }
        for (int k = 0; k < ncomp && !rc; k++) {
            char ck[96];
            api_ptr_index(ck, sizeof ck, at, k);
            rc = api_get_number(json_array_get(x, k), ck, API_MAX_VALUE, &e->val[i * ncomp + k], p);
        }
    }
    for (size_t j = 0; j < e->n0; j++) /* leave `seen` clean for the next list */
        seen[e->at0[j].index] = -1;
    e->n = n;
    if (!rc && levels)
        rc = repeated_fine(e, base, p);
    return rc;
}

static void edit_parts_free(edit_part *parts, int n)
{
    for (int i = 0; i < n; i++) {
        api_free(parts[i].at);
        api_free(parts[i].at0);
        api_free(parts[i].k0);
        api_free(parts[i].val);
        api_free(parts[i].old);
    }
}

/* A refusal of the core for part q as a problem pointing into the body. */
static int part_failed(const edit_part *q, const api_input *in, const sd_error *e, api_problem *p)
{
    if (e->code == SD_ERR_NOMEM || e->code == SD_ERR_LIMIT || e->item < 0)
        return api_fail_core(p, e, NULL, NULL);
    char base[96], ptr[128];
    if (q->attr < 0)
        snprintf(base, sizeof base, "/moves");
    else
        api_ptr_key(base, sizeof base, "/attributes", in->attrs[q->attr].name);
    api_ptr_index(ptr, sizeof ptr, base, (size_t)e->item);
    const char *field = e->code == SD_ERR_VALUE ? (q->attr < 0 ? "position" : "value")
                        : e->code == SD_ERR_ARG ? "level" : "index";
    size_t u = strlen(ptr);
    snprintf(ptr + u, sizeof ptr - u, "/%s", field);
    if (e->code == SD_ERR_VALUE && e->field >= 0 && q->ncomp > 1) {
        u = strlen(ptr);
        snprintf(ptr + u, sizeof ptr - u, "/%d", e->field);
    }
    return api_fail_at(p, 422, e->code == SD_ERR_VALUE ? "out-of-range" : "invalid-edit", ptr, "%s",
                       e->message);
}

/* The detail offsets of the positions, all levels, as sd_complex_set_details takes them (to put
 * back after a failure, or onto a rebuilt model). */
typedef struct saved_details {
    size_t n;
    sd_vertex_at *at;
    double *off;
} saved_details;

static bool save_details(const sd_complex *c, saved_details *s)
{
    size_t k = 0;
    for (int l = 1; l <= SD_MAX_LEVEL; l++)
        k += sd_complex_details(c, 0, l, NULL, NULL);
    s->at = api_malloc((k + 1) * sizeof *s->at);
    s->off = api_malloc((k + 1) * 3 * sizeof *s->off);
    if (!s->at || !s->off)
        return false;
    k = 0;
    for (int l = 1; l <= SD_MAX_LEVEL; l++) {
        const uint32_t *idx;
        const double *d;
        size_t m = sd_complex_details(c, 0, l, &idx, &d);
        for (size_t i = 0; i < m; i++, k++) {
            s->at[k] = (sd_vertex_at){l, idx[i]};
            memcpy(s->off + 3 * k, d + 3 * i, 3 * sizeof *s->off);
        }
    }
    s->n = k;
    return true;
}

/* Write the edit's control-point values into an input's arrays. */
static void apply_to_input(api_input *in, const edit_part *parts, int np)
{
    for (int i = 0; i < np; i++) {
        double *dst = parts[i].attr < 0 ? in->xyz : in->attrs[parts[i].attr].data;
        const int nc = parts[i].ncomp;
        for (size_t k = 0; k < parts[i].n0; k++)
            memcpy(dst + (size_t)parts[i].at0[k].index * nc,
                   parts[i].val + (size_t)parts[i].k0[k] * nc, nc * sizeof *dst);
    }
}

/* The moves of points of levels >= 1 of part q (the positions), as one sd_complex_move call
 * takes them: *at and *val, new blocks; their number. */
static size_t fine_moves(const edit_part *q, sd_vertex_at **at, double **val)
{
    size_t n = q->n - q->n0, k = 0;
    *at = api_malloc((n + 1) * sizeof **at);
    *val = api_malloc((n + 1) * 3 * sizeof **val);
    if (!*at || !*val)
        return SIZE_MAX;
    for (size_t i = 0; i < q->n; i++)
        if (q->at[i].level > 0) {
            (*at)[k] = q->at[i];
            memcpy(*val + 3 * k++, q->val + 3 * i, 3 * sizeof **val);
        }
    return k;
}

/* The edit as a new model: a copy of m's input with the control-point values applied, built
 * with m's rules, overrides and tags (they name simplices, which an edit does not change) in a
 * compute slot; then m's detail offsets (sv) and the edit's moves at finer levels, applied to it
 * as to any complex (nobody reads it yet). Its other levels are computed again when asked for;
 * the result is the one a new complex with the moved points and those offsets gives. */
static int rebuilt_model(const api_model *m, const edit_part *parts, int np,
                         const saved_details *sv, const api_limits *lim, const api_slot *slot,
                         api_model **out, api_problem *p)
{
    api_input *in = api_input_copy(m->in);
    if (!in)
        return api_fail(p, 503, "out-of-memory", "out of memory copying the complex for the edit");
    apply_to_input(in, parts, np);
    int rc = slot ? slot->take(slot->ud, 0, p) : 0;
    if (!rc) {
        rc = api_build_model(in, &m->rules, &m->tags, lim, out, p);
        sd_error e = {0};
        sd_vertex_at *at = NULL;
        double *val = NULL;
        size_t nf = !rc && np && parts[0].attr < 0 ? fine_moves(&parts[0], &at, &val) : 0;
        bool moved = false; /* the finer moves were refused (not the offsets put back) */
        if (!rc && (nf == SIZE_MAX ||
                    (sv->n && sd_complex_set_details((*out)->c, 0, sv->n, sv->at, sv->off, NULL,
                                                     &e)) ||
                    (nf && (moved = sd_complex_move((*out)->c, 0, nf, at, val, NULL, &e))))) {
            if (nf == SIZE_MAX)
                rc = api_fail(p, 503, "out-of-memory", "out of memory");
            else if (moved && e.item >= 0 && (size_t)e.item < nf) {
                /* a finer move refused (its offset beyond 1e15): e.item counts the finer
                 * moves alone; point at that move in the body, as an edit in place does */
                size_t k = 0, i = 0;
                for (; i < parts[0].n; i++)
                    if (parts[0].at[i].level > 0 && k++ == (size_t)e.item)
                        break;
                e.item = (long)i;
                rc = part_failed(&parts[0], m->in, &e, p);
            } else
                rc = api_fail_core(p, &e, NULL, NULL);
            api_model_unref(*out);
            *out = NULL;
        }
        if (!rc) {
            pthread_mutex_lock(&(*out)->lock);
            api_model_publish(*out); /* the levels the finer moves computed */
            pthread_mutex_unlock(&(*out)->lock);
        }
        api_free(at);
        api_free(val);
        if (slot)
            slot->give(slot->ud);
    }
    api_input_unref(in);
    return rc;
}

/* No simplex at a moved control point may become degenerate (PUT /complex's test; inverted is
 * fine): sd_complex_check_moves on the level-0 moves of part q. 0 or the problem's status. */
static int check_moves(api_model *m, const edit_part *q, api_problem *p)
{
    if (!q->n0)
        return 0;
    double *xyz = api_malloc(q->n0 * 3 * sizeof *xyz);
    uint32_t *idx = api_malloc(q->n0 * sizeof *idx);
    int rc = 0;
    sd_error e = {0};
    if (!xyz || !idx)
        rc = api_fail(p, 503, "out-of-memory", "out of memory");
    for (size_t i = 0; !rc && i < q->n0; i++) {
        idx[i] = q->at0[i].index;
        memcpy(xyz + 3 * i, q->val + 3 * (size_t)q->k0[i], 3 * sizeof *xyz);
    }
    if (!rc && sd_complex_check_moves(m->c, q->n0, idx, xyz, &e)) {
        char at[64];
        snprintf(at, sizeof at, "/moves/%u/position", e.item < 0 ? 0 : q->k0[e.item]);
        rc = e.code == SD_ERR_DEGENERATE ? api_fail_at(p, 422, "invalid-complex", at, "%s", e.message)
                                         : api_fail_core(p, &e, NULL, NULL);
    }
    api_free(xyz);
    api_free(idx);
    return rc;
}

/* *rebuild after a failed edit whose undo failed too (out of memory): m's complex is no longer
 * its input, so the session gets a model built again from the input and offsets as they were. */
#define RESTORE (-2)

/* Apply the parts to m (its compute lock and data write lock held): every part in place, or
 * nothing — refused, undone after a failure half-way (or, if the undo fails, *rebuild =
 * RESTORE), or, when a level's rules read a moved position, *rebuild set to that level (the edit
 * then becomes a new model). 0 or the status. */
static int apply_locked(api_model *m, edit_part *parts, int np, uint64_t version,
                        const saved_details *sv, uint64_t *counts, int *rebuild,
                        const api_edit_commit *commit, api_problem *p)
{
    sd_error e = {0};
    int done = 0, rc = np && parts[0].attr < 0 ? check_moves(m, &parts[0], p) : 0;
    bool fine = np && parts[0].attr < 0 && parts[0].n0 < parts[0].n; /* offsets change */
    *rebuild = -1;
    for (; !rc && done < np; done++) {
        edit_part *q = &parts[done];
        const double *cur = sd_level_channel(sd_complex_level(m->c, 0, &e), q->channel, NULL);
        for (size_t i = 0; i < q->n0; i++)
            memcpy(q->old + i * q->ncomp, cur + (size_t)q->at0[i].index * q->ncomp,
                   q->ncomp * sizeof *cur);
        api_delta_edit de = {m, q->attr, version};
        sd_edit_report rep;
        api_delta_report(&de, &rep);
        rep.in_place = 1;
        if (sd_complex_move(m->c, q->channel, q->n, q->at, q->val, &rep, &e))
            break;
        for (int l = 0; l <= SD_MAX_LEVEL; l++)
            counts[l] = rep.recomputed[l] > counts[l] ? rep.recomputed[l] : counts[l];
        if (rep.rules_rebuilt >= 0) { /* nothing changed (counts: what the new model differs
                                       * in); moves are the first part, the only one whose values
                                       * a level's rules read */
            *rebuild = rep.rules_rebuilt;
            return 0;
        }
    }
    if (rc)
        return rc; /* refused before anything changed */
    /* applied in full: kept unless the commit (the durable store) refuses it */
    bool kept = done == np && (!commit || !(rc = commit->fn(commit->ud, p)));
    if (!kept) { /* refused by the core, out of memory half-way, or not committed: undo */
        if (done < np)
            rc = part_failed(&parts[done], m->in, &e, p);
        bool undone = true;
        for (int i = done - 1; i >= 0; i--) {
            const edit_part *q = &parts[i];
            api_delta_edit de = {m, q->attr, version};
            sd_edit_report rep;
            if (q->attr < 0 && fine) {
                api_delta_report(&de, &rep);
                rep.in_place = 1;
                undone &= !sd_complex_set_details(m->c, 0, sv->n, sv->at, sv->off, &rep, NULL);
            }
            api_delta_report(&de, &rep);
            rep.in_place = 1;
            undone &= !sd_complex_move(m->c, q->channel, q->n0, q->at0, q->old, &rep, NULL);
        }
        if (!undone) /* out of memory for the undo too: the caller restores a new model */
            *rebuild = RESTORE;
        return rc;
    }
    apply_to_input(m->in, parts, np); /* GET /complex, later rule changes rebuild from it */
    api_delta_end_edit(m);
    atomic_store(&m->version, version);
    return 0;
}

int api_edit(api_model *m, json_t *body, uint64_t version, const api_limits *lim,
             const api_slot *slot, uint64_t *counts, int *levels, api_model **rebuilt,
             api_problem *p)
{
    return api_edit_commit_by(m, body, version, lim, slot, NULL, counts, levels, rebuilt, p);
}

int api_edit_commit_by(api_model *m, json_t *body, uint64_t version, const api_limits *lim,
                       const api_slot *slot, const api_edit_commit *commit, uint64_t *counts,
                       int *levels, api_model **rebuilt, api_problem *p)
{
    *rebuilt = NULL;
    static const char *const keys[] = {"moves", "attributes", NULL};
    if (!m->c)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    if (api_only_keys(body, "", keys, p))
        return p->status;
    api_input *in = m->in;
    edit_part parts[1 + API_MAX_ATTRIBUTES];
    memset(parts, 0, sizeof parts);
    int np = 0, rc = 0;
    int32_t *seen = api_malloc(((size_t)in->nv + 1) * sizeof *seen);
    if (!seen)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    for (uint32_t i = 0; i < in->nv; i++)
        seen[i] = -1;
    json_t *mv = json_object_get(body, "moves"), *at = json_object_get(body, "attributes");
    if (mv) {
        parts[np] = (edit_part){.channel = 0, .attr = -1};
        rc = parse_edit_entries(mv, "/moves", "position", 3, true, m, &parts[np++], seen, p);
    }
    if (!rc && at && !json_is_object(at))
        rc = api_fail_at(p, 400, "wrong-type", "/attributes", "must be an object: name -> entries");
    const char *name;
    json_t *list;
    if (!rc && at)
        json_object_foreach(at, name, list) {
            char ptr[96];
            api_ptr_key(ptr, sizeof ptr, "/attributes", name);
            int a = api_input_find_attr(in, name);
            if (a < 0) {
                rc = strlen(name) > API_MAX_ATTRIBUTE_NAME /* not shown cut */
                         ? api_fail_at(p, 422, "unknown-attribute", ptr,
                                       "no attribute: a name of %zu characters (attribute names "
                                       "have at most %d)", strlen(name), API_MAX_ATTRIBUTE_NAME)
                         : api_fail_at(p, 422, "unknown-attribute", ptr, "no attribute \"%s\"",
                                       name);
                break;
            }
            parts[np] = (edit_part){.channel = m->channel[a], .attr = a};
            if ((rc = parse_edit_entries(list, ptr, "value", in->attrs[a].ncomp, false, m,
                                         &parts[np++], seen, p)))
                break;
        }
    api_free(seen);
    if (!rc && !mv && !at) {
        rc = api_fail_at(p, 400, "missing-field", "/moves", "give \"moves\" and/or \"attributes\"");
        api_add_error(p, "/attributes", "or this one");
    }
    int top = 0; /* the finest level a move names: computed first, within the limits */
    for (size_t i = 0; !rc && mv && i < parts[0].n; i++)
        top = parts[0].at[i].level > top ? parts[0].at[i].level : top;
    if (!rc && top >= atomic_load(&m->levels_cached))
        rc = api_check_level_limits(m, top, lim, p);
    /* the levels the moves need, computed first in a compute slot like GET /levels/{L}'s */
    if (!rc && top >= atomic_load(&m->levels_cached))
        rc = api_level_compute(m, top, slot, p);
    if (rc) {
        edit_parts_free(parts, np);
        return rc;
    }
    /* everything is valid: apply under the compute lock and the data write lock */
    pthread_mutex_lock(&m->lock);
    pthread_rwlock_wrlock(&m->data);
    api_delta_begin_edit(m);
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        counts[l] = 0;
    saved_details sv = {0};
    int rebuild = -1;
    if (!save_details(m->c, &sv))
        rc = api_fail(p, 503, "out-of-memory", "out of memory");
    else
        rc = apply_locked(m, parts, np, version, &sv, counts, &rebuild, commit, p);
    *levels = sd_complex_levels_computed(m->c);
    api_model_publish(m); /* the by-column matrices of the first edit count as session memory */
    pthread_rwlock_unlock(&m->data);
    pthread_mutex_unlock(&m->lock);
    if (!rc && rebuild >= 0)
        rc = rebuilt_model(m, parts, np, &sv, lim, slot, rebuilt, p);
    else if (rc && rebuild == RESTORE) { /* the edit failed: its problem stands */
        api_problem q = {0};
        if (rebuilt_model(m, parts, 0, &sv, lim, NULL, rebuilt, &q))
            *rebuilt = NULL; /* still no memory: the next change of the session rebuilds it */
    }
    api_free(sv.at);
    api_free(sv.off);
    edit_parts_free(parts, np);
    return rc;
}
