/* edit.c — PATCH /control-points (docs/API.md "Control-point edits"): moves and attribute values
 * of control points pushed through the cached subdivision matrices into every computed level
 * (004 Sec. 4.1: the matrix is built once per topology and applied many times).
 *
 * All-or-nothing: every entry is checked (index range, repeats, value shapes) before anything
 * changes; then the edit runs under the model's compute lock and its data write lock — which
 * streams hold only while they copy what they send (api/levels.c), so an edit never waits for a
 * slow client — and one that runs out of memory half-way is undone channel by channel. The
 * edit changes channel values only (sd_complex_edit_in_place): where a level's rules read a
 * moved point (Ying-Zorin's corner angle), it becomes a new model built from the edited input
 * instead of a rebuild of levels in place, since streams in flight read those levels' topology
 * and rules without a lock. The posted input follows the edit, so later rule changes rebuild
 * from the new values; the model's version becomes the edit's, with the values.
 */
#include "handlers.h"
#include "mem.h"
#include "internal.h"
#include "jsonin.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- PATCH /control-points ---------------------------------------------------------------- */

/* One channel's part of an edit: indices and new values (ncomp each). */
typedef struct edit_part {
    int channel, attr;        /* attr: index into the input's attributes, -1 for positions */
    int ncomp;
    size_t n;
    uint32_t *idx;
    double *val, *old;        /* old: the values before, for undoing a half-applied edit */
} edit_part;

static int parse_edit_entries(json_t *arr, const char *base, const char *vkey, int ncomp,
                              uint32_t nv, edit_part *e, int32_t *seen, api_problem *p)
{
    char ptr[96], at[96];
    if (!json_is_array(arr))
        return api_fail_at(p, 400, "wrong-type", base, "must be an array of {\"index\", \"%s\"}", vkey);
    size_t n = json_array_size(arr);
    if (n > nv)
        return api_fail_at(p, 422, "repeated-index", base,
                           "%zu entries for %u control points: some point is listed twice", n, nv);
    e->idx = api_malloc((n ? n : 1) * sizeof *e->idx);
    e->val = api_malloc((n ? n : 1) * ncomp * sizeof *e->val);
    e->old = api_malloc((n ? n : 1) * ncomp * sizeof *e->old);
    if (!e->idx || !e->val || !e->old)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    e->ncomp = ncomp;
    const char *const keys[] = {"index", vkey, NULL};
    int rc = 0;
    size_t i;
    for (i = 0; i < n && !rc; i++) {
        json_t *o = json_array_get(arr, i), *x;
        api_ptr_index(ptr, sizeof ptr, base, i);
        if (!json_is_object(o)) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "an entry is {\"index\", \"%s\"}", vkey);
            break;
        }
        long long v;
        if ((rc = api_only_keys(o, ptr, keys, p)))
            break;
        api_ptr_key(at, sizeof at, ptr, "index");
        if (!(x = json_object_get(o, "index"))) {
            rc = api_fail_at(p, 400, "missing-field", at, "\"index\" is required");
            break;
        }
        if ((rc = api_get_int(x, at, 0, (long long)nv - 1, &v, p)))
            break;
        if (seen[v] >= 0) {
            rc = api_fail_at(p, 422, "repeated-index", at, "point %lld is edited twice", v);
            break;
        }
        seen[v] = (int32_t)i;
        e->idx[i] = (uint32_t)v;
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
    for (size_t j = 0; j < i; j++) /* leave `seen` clean for the next list */
        if (j < n)
            seen[e->idx[j]] = -1;
    e->n = n;
    return rc;
}

static void edit_parts_free(edit_part *parts, int n)
{
    for (int i = 0; i < n; i++) {
        api_free(parts[i].idx);
        api_free(parts[i].val);
        api_free(parts[i].old);
    }
}

/* Write the edit's values into an input's arrays. */
static void apply_to_input(api_input *in, const edit_part *parts, int np)
{
    for (int i = 0; i < np; i++) {
        double *dst = parts[i].attr < 0 ? in->xyz : in->attrs[parts[i].attr].data;
        for (size_t k = 0; k < parts[i].n; k++)
            memcpy(dst + (size_t)parts[i].idx[k] * parts[i].ncomp, parts[i].val + k * parts[i].ncomp,
                   parts[i].ncomp * sizeof *dst);
    }
}

/* The edit as a new model: a copy of m's input with the edit applied, built with m's rules,
 * overrides and tags (they name simplices, which an edit does not change) in a compute slot.
 * Its levels are computed again when asked for; the result is the one a new complex with the
 * moved points gives. */
static int rebuilt_model(const api_model *m, const edit_part *parts, int np,
                         const api_limits *lim, const api_slot *slot, api_model **out,
                         api_problem *p)
{
    api_input *in = api_input_copy(m->in);
    if (!in)
        return api_fail(p, 503, "out-of-memory", "out of memory copying the complex for the edit");
    apply_to_input(in, parts, np);
    int rc = slot ? slot->take(slot->ud, 0, p) : 0;
    if (!rc) {
        rc = api_build_model(in, &m->rules, &m->tags, lim, out, p);
        if (slot)
            slot->give(slot->ud);
    }
    api_input_unref(in);
    return rc;
}

int api_edit(api_model *m, json_t *body, uint64_t version, const api_limits *lim,
             const api_slot *slot, uint64_t *counts, int *levels, api_model **rebuilt,
             api_problem *p)
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
        rc = parse_edit_entries(mv, "/moves", "position", 3, in->nv, &parts[np++], seen, p);
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
                rc = api_fail_at(p, 422, "unknown-attribute", ptr, "no attribute \"%.40s\"", name);
                break;
            }
            parts[np] = (edit_part){.channel = m->channel[a], .attr = a};
            if ((rc = parse_edit_entries(list, ptr, "value", in->attrs[a].ncomp, in->nv,
                                         &parts[np++], seen, p)))
                break;
        }
    api_free(seen);
    if (!rc && !mv && !at)
        rc = api_fail(p, 400, "missing-field", "give \"moves\" and/or \"attributes\"");
    if (rc) {
        edit_parts_free(parts, np);
        return rc;
    }
    /* everything is valid: apply under the compute lock and the data write lock */
    pthread_mutex_lock(&m->lock);
    pthread_rwlock_wrlock(&m->data);
    *levels = sd_complex_levels_computed(m->c);
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        counts[l] = 0;
    sd_error e = {0};
    int done = 0, rebuild = -1;
    /* no simplex at a moved point may become degenerate (PUT /complex's test; inverted is fine) */
    if (np && parts[0].attr < 0 && sd_complex_check_moves(m->c, parts[0].n, parts[0].idx,
                                                         parts[0].val, &e)) {
        char at[64];
        snprintf(at, sizeof at, "/moves/%ld/position", e.item < 0 ? 0 : e.item);
        rc = e.code == SD_ERR_DEGENERATE ? api_fail_at(p, 422, "invalid-complex", at, "%s", e.message)
                                         : api_fail_core(p, &e, NULL, NULL);
        done = np; /* nothing to apply */
    }
    for (; !rc && done < np && rebuild < 0; done++) {
        edit_part *q = &parts[done];
        const double *cur = sd_level_channel(sd_complex_level(m->c, 0, &e), q->channel, NULL);
        for (size_t i = 0; i < q->n; i++)
            memcpy(q->old + i * q->ncomp, cur + (size_t)q->idx[i] * q->ncomp, q->ncomp * sizeof *cur);
        uint64_t c[SD_MAX_LEVEL + 1];
        if (sd_complex_edit_in_place(m->c, q->channel, q->n, q->idx, q->val, c, &rebuild, &e))
            break;
        for (int l = 0; l <= SD_MAX_LEVEL; l++)
            counts[l] = c[l] > counts[l] ? c[l] : counts[l];
    }
    if (rc) {
        /* refused before anything changed */
    } else if (rebuild >= 0) {
        /* a level's rules read a moved position (Ying-Zorin's corner angle): nothing changed
         * (moves are the first part, the only one that can need this); the edit becomes a new
         * model below, and this one stays as it is for whoever reads it */
    } else if (done < np) { /* out of memory half-way: undo what was applied */
        for (int i = done - 1; i >= 0; i--)
            sd_complex_edit_in_place(m->c, parts[i].channel, parts[i].n, parts[i].idx,
                                     parts[i].old, NULL, &rebuild, NULL);
        rc = api_fail_core(p, &e, NULL, NULL);
    } else {
        /* the posted input follows (GET /complex, later rule changes rebuild from it) */
        apply_to_input(in, parts, np);
        for (int l = 0; l <= SD_MAX_LEVEL; l++) { /* normals follow the positions (a stream
                                                    * keeps its own reference) */
            out_geometry_free(m->geometry[l]);
            m->geometry[l] = NULL;
        }
        atomic_store(&m->version, version);
    }
    api_model_publish(m); /* the by-column matrices of the first edit count as session memory */
    pthread_rwlock_unlock(&m->data);
    pthread_mutex_unlock(&m->lock);
    if (rebuild >= 0)
        rc = rebuilt_model(m, parts, np, lim, slot, rebuilt, p);
    edit_parts_free(parts, np);
    return rc;
}
