/* details.c — a session's detail offsets (004 Sec. 5.2) as the JSON of docs/API.md "Live edits":
 * "details": [{"level", "index", "offset": [x, y, z]}] in GET /complex, the same accepted by PUT
 * /complex, carried by PUT /tags and PUT /rules into the model they build, and counted when a new
 * complex (PUT /complex without them, POST /refine) drops them.
 *
 * The offsets live in the core complex (sd_complex_details, per level, ascending indices); a
 * PATCH move at level l >= 1 stores one (api/edit.c). Only positions have offsets through the
 * API. Callers exclude edits of the model they read (GET /complex holds its data lock for
 * reading; the change handlers run under the session's write lock, which edits take too).
 */
#include "details.h"
#include "jsonin.h"
#include "mem.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

size_t api_details_count(const api_model *m)
{
    size_t n = 0;
    for (int l = 1; m->c && l <= SD_MAX_LEVEL; l++)
        n += sd_complex_details(m->c, 0, l, NULL, NULL);
    return n;
}

json_t *api_details_json(const api_model *m)
{
    json_t *a = json_array();
    for (int l = 1; a && m->c && l <= SD_MAX_LEVEL; l++) {
        const uint32_t *idx;
        const double *d;
        size_t n = sd_complex_details(m->c, 0, l, &idx, &d);
        for (size_t i = 0; i < n; i++)
            json_array_append_new(a, json_pack("{s:i, s:I, s:[f, f, f]}", "level", l, "index",
                                               (json_int_t)idx[i], "offset", d[3 * i],
                                               d[3 * i + 1], d[3 * i + 2]));
    }
    return a;
}

int api_ptkey_cmp(const void *x, const void *y)
{
    const api_ptkey *a = x, *b = y;
    if (a->level != b->level)
        return a->level < b->level ? -1 : 1;
    if (a->index != b->index)
        return a->index < b->index ? -1 : 1;
    return (a->k > b->k) - (a->k < b->k);
}

/* Set n offsets on a model's complex (levels not computed: the lists only). */
static int set_all(api_model *m, size_t n, const sd_vertex_at *at, const double *off,
                   api_problem *p)
{
    sd_error e = {0};
    if (!sd_complex_set_details(m->c, 0, n, at, off, NULL, &e))
        return 0;
    if (e.code == SD_ERR_NOMEM || e.item < 0)
        return api_fail_core(p, &e, NULL, NULL);
    char ptr[96];
    snprintf(ptr, sizeof ptr, "/details/%ld/%s", e.item,
             e.code == SD_ERR_VALUE ? "offset" : e.code == SD_ERR_ARG ? "level" : "index");
    return api_fail_at(p, 422, "invalid-detail", ptr, "%s", e.message);
}

int api_details_put(api_model *m, json_t *v, api_problem *p)
{
    if (!json_is_array(v))
        return api_fail_at(p, 400, "wrong-type", "/details",
                           "must be an array of {\"level\", \"index\", \"offset\"}");
    size_t n = json_array_size(v);
    sd_vertex_at *at = api_malloc((n + 1) * sizeof *at);
    double *off = api_malloc((n + 1) * 3 * sizeof *off);
    api_ptkey *keys = api_malloc((n + 1) * sizeof *keys);
    int rc = !at || !off || !keys ? api_fail(p, 503, "out-of-memory", "out of memory") : 0;
    static const char *const names[] = {"level", "index", "offset", NULL};
    uint64_t count[SD_MAX_LEVEL + 1] = {0};
    char ptr[96], f[112];
    for (size_t i = 0; i < n && !rc; i++) {
        json_t *o = json_array_get(v, i), *x;
        api_ptr_index(ptr, sizeof ptr, "/details", i);
        if (!json_is_object(o)) {
            rc = api_fail_at(p, 400, "wrong-type", ptr,
                             "a detail is {\"level\", \"index\", \"offset\": [x, y, z]}");
            break;
        }
        if ((rc = api_only_keys(o, ptr, names, p)))
            break;
        long long l, k;
        for (int j = 0; j < 3 && !rc; j++) {
            api_ptr_key(f, sizeof f, ptr, names[j]);
            if (!json_object_get(o, names[j]))
                rc = api_fail_at(p, 400, "missing-field", f, "\"%s\" is required", names[j]);
        }
        api_ptr_key(f, sizeof f, ptr, "level");
        if (rc || (rc = api_get_int(json_object_get(o, "level"), f, 1, SD_MAX_LEVEL, &l, p)))
            break;
        if (!count[l]) {
            sd_counts c;
            sd_complex_counts(m->c, (int)l, &c);
            count[l] = c.vertices;
        }
        api_ptr_key(f, sizeof f, ptr, "index");
        x = json_object_get(o, "index");
        if (!json_is_integer(x)) {
            rc = api_get_int(x, f, 0, 0, &k, p);
            break;
        }
        k = json_integer_value(x);
        if (k < 0 || (unsigned long long)k >= count[l]) {
            rc = api_fail_at(p, 422, "out-of-range", f,
                             "point %lld is out of range (level %lld has %llu points)", k, l,
                             (unsigned long long)count[l]);
            break;
        }
        if ((unsigned long long)k >= UINT32_MAX) { /* a level's indices are 32-bit */
            rc = api_fail_at(p, 422, "out-of-range", f,
                             "point %lld is past the 2^32 - 1 points a level's indices can name "
                             "(level %lld has %llu points)", k, l, (unsigned long long)count[l]);
            break;
        }
        api_ptr_key(f, sizeof f, ptr, "offset");
        x = json_object_get(o, "offset");
        if (!json_is_array(x) || json_array_size(x) != 3) {
            rc = api_fail_at(p, 400, "wrong-type", f, "an offset is an array of 3 numbers");
            break;
        }
        for (int c = 0; c < 3 && !rc; c++) {
            char fc[128];
            api_ptr_index(fc, sizeof fc, f, (size_t)c);
            rc = api_get_number(json_array_get(x, (size_t)c), fc, 1e15, &off[3 * i + c], p);
        }
        at[i] = (sd_vertex_at){(int)l, (uint32_t)k};
        keys[i] = (api_ptkey){(uint32_t)l, (uint32_t)k, i};
    }
    if (!rc && n > 1) { /* no point twice */
        qsort(keys, n, sizeof *keys, api_ptkey_cmp);
        for (size_t i = 1; i < n && !rc; i++)
            if (keys[i].level == keys[i - 1].level && keys[i].index == keys[i - 1].index) {
                api_ptr_index(ptr, sizeof ptr, "/details", keys[i].k);
                api_ptr_key(f, sizeof f, ptr, "index");
                rc = api_fail_at(p, 422, "repeated-index", f,
                                 "point %u of level %u has an offset twice", keys[i].index,
                                 keys[i].level);
                /* the other entry as a pointer of its own: an import prefixes it (a pointer in
                 * the message would name the wrong place in an import's document) */
                api_ptr_index(ptr, sizeof ptr, "/details", keys[i - 1].k);
                api_ptr_key(f, sizeof f, ptr, "index");
                api_add_error(p, f, "the same point");
            }
    }
    if (!rc && n)
        rc = set_all(m, n, at, off, p);
    api_free(at);
    api_free(off);
    api_free(keys);
    return rc;
}

int api_details_carry(const api_model *from, api_model *to, api_problem *p)
{
    size_t n = api_details_count(from);
    if (!n || !to->c)
        return 0;
    sd_vertex_at *at = api_malloc(n * sizeof *at);
    double *off = api_malloc(n * 3 * sizeof *off);
    int rc = 0;
    if (!at || !off)
        rc = api_fail(p, 503, "out-of-memory", "out of memory keeping the detail offsets");
    size_t k = 0;
    for (int l = 1; !rc && l <= SD_MAX_LEVEL; l++) {
        const uint32_t *idx;
        const double *d;
        size_t m = sd_complex_details(from->c, 0, l, &idx, &d);
        for (size_t i = 0; i < m; i++, k++) {
            at[k] = (sd_vertex_at){l, idx[i]};
            memcpy(off + 3 * k, d + 3 * i, 3 * sizeof *off);
        }
    }
    if (!rc)
        rc = set_all(to, n, at, off, p);
    api_free(at);
    api_free(off);
    return rc;
}
