/* refine.c — POST /refine (docs/API.md "Local refinement"): red-green refinement of the control
 * complex (000 Sec. 4.2) around a selection — simplices by their vertex lists, or the simplices
 * whose centroid lies in a box or a sphere — `depth` times, the new points at edge midpoints or
 * where the subdivision rules put them, with the tags and overrides carried to the children.
 *
 * Each step runs sd_refine on the working input, places the new points, carries tags and
 * overrides to the children (sd_refine_carry, core/carry.c), and becomes the next step's input;
 * the result is one new model, built like every change by api_build_model. These functions
 * allocate with the C library, as sd_refine and sd_refine_carry do for the arrays they hand
 * over; what they exchange with the rest of api/ (the input's arrays, tags, overrides, the
 * selection) is therefore C-library memory too.
 */
#include "handlers.h"
#include "mem.h"
#include "internal.h"
#include "jsonin.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The name api_refine's body calls api_build_model by. */
static int build_model(api_input *in, const api_rules *rules, const api_tags *tags,
                       const api_limits *lim, api_model **out, api_problem *p)
{
    return api_build_model(in, rules, tags, lim, out, p);
}

/* ---- the selection ------------------------------------------------------------------------ */

typedef struct selection {
    int kind;                 /* 0 simplices, 1 box, 2 sphere */
    uint32_t n;               /* simplices: sorted vertex lists, 4 ids each (UINT32_MAX padded) */
    uint32_t (*keys)[4];
    double lo[3], hi[3];      /* box */
    double c[3], r;           /* sphere */
} selection;

static int cmp_key4(const void *x, const void *y) { return memcmp(x, y, 4 * sizeof(uint32_t)); }

static void sort_key(uint32_t k[4], const uint32_t *v, int n)
{
    for (int i = 0; i < 4; i++)
        k[i] = i < n ? v[i] : UINT32_MAX;
    for (int i = 1; i < n; i++) /* insertion sort of at most 4 */
        for (int j = i; j > 0 && k[j - 1] > k[j]; j--) {
            uint32_t t = k[j];
            k[j] = k[j - 1];
            k[j - 1] = t;
        }
}

static int parse_point(json_t *v, const char *ptr, double out[3], api_problem *p)
{
    if (!json_is_array(v) || json_array_size(v) != 3)
        return api_fail_at(p, 400, "wrong-type", ptr, "must be an array of 3 numbers");
    for (int k = 0; k < 3; k++) {
        char at[96];
        api_ptr_index(at, sizeof at, ptr, k);
        if (api_get_number(json_array_get(v, k), at, 1e15, &out[k], p))
            return p->status;
    }
    return 0;
}

static int parse_selection(json_t *sel, const api_input *in, selection *s, api_problem *p)
{
    static const char *const keys[] = {"simplices", "box", "sphere", NULL};
    if (!json_is_object(sel))
        return api_fail_at(p, 400, "wrong-type", "/select",
                           "must be {\"simplices\": […]}, {\"box\": …} or {\"sphere\": …}");
    if (api_only_keys(sel, "/select", keys, p))
        return p->status;
    if (json_object_size(sel) != 1)
        return api_fail_at(p, 400, "wrong-type", "/select", "give exactly one of simplices, box, sphere");
    json_t *v;
    if ((v = json_object_get(sel, "simplices"))) {
        s->kind = 0;
        if (!json_is_array(v))
            return api_fail_at(p, 400, "wrong-type", "/select/simplices", "must be an array of simplices");
        s->keys = api_plain_malloc((json_array_size(v) + 1) * sizeof *s->keys);
        if (!s->keys)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        /* every posted simplex, sorted, to find the selected ones */
        uint32_t (*all)[4] = api_malloc(((size_t)in->ns + 1) * sizeof *all);
        if (!all)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        for (uint32_t q = 0, off = 0; q < in->ns; off += in->size[q++])
            sort_key(all[q], in->idx + off, in->size[q]);
        qsort(all, in->ns, sizeof *all, cmp_key4);
        size_t i;
        json_t *x;
        int rc = 0;
        json_array_foreach(v, i, x) {
            char ptr[96], at[96];
            api_ptr_index(ptr, sizeof ptr, "/select/simplices", i);
            size_t k = json_is_array(x) ? json_array_size(x) : 0;
            if (k < 1 || k > 4) {
                rc = api_fail_at(p, 400, "wrong-type", ptr, "a simplex is an array of 1 to 4 indices");
                break;
            }
            uint32_t ids[4];
            for (size_t j = 0; j < k && !rc; j++) {
                long long id;
                api_ptr_index(at, sizeof at, ptr, j);
                rc = api_get_int(json_array_get(x, j), at, 0, (long long)in->nv - 1, &id, p);
                ids[j] = (uint32_t)id;
            }
            if (rc)
                break;
            sort_key(s->keys[s->n], ids, (int)k);
            if (!bsearch(s->keys[s->n], all, in->ns, sizeof *all, cmp_key4)) {
                rc = api_fail_at(p, 422, "no-such-simplex", ptr,
                                 "not one of the complex's simplices as GET /complex lists them "
                                 "(a face of one, such as an edge of a tetrahedron, is not "
                                 "selected on its own)");
                break;
            }
            s->n++;
        }
        api_free(all);
        if (!rc)
            qsort(s->keys, s->n, sizeof *s->keys, cmp_key4);
        return rc;
    }
    if ((v = json_object_get(sel, "box"))) {
        static const char *const bk[] = {"min", "max", NULL};
        s->kind = 1;
        if (!json_is_object(v))
            return api_fail_at(p, 400, "wrong-type", "/select/box", "must be {\"min\", \"max\"}");
        if (api_only_keys(v, "/select/box", bk, p) ||
            parse_point(json_object_get(v, "min"), "/select/box/min", s->lo, p) ||
            parse_point(json_object_get(v, "max"), "/select/box/max", s->hi, p))
            return p->status;
        for (int k = 0; k < 3; k++)
            if (s->lo[k] > s->hi[k])
                return api_fail_at(p, 422, "out-of-range", "/select/box", "min must not exceed max");
        return 0;
    }
    v = json_object_get(sel, "sphere");
    static const char *const sk[] = {"center", "radius", NULL};
    s->kind = 2;
    if (!json_is_object(v))
        return api_fail_at(p, 400, "wrong-type", "/select/sphere", "must be {\"center\", \"radius\"}");
    if (api_only_keys(v, "/select/sphere", sk, p) ||
        parse_point(json_object_get(v, "center"), "/select/sphere/center", s->c, p))
        return p->status;
    json_t *r = json_object_get(v, "radius");
    if (!r)
        return api_fail_at(p, 400, "missing-field", "/select/sphere/radius", "\"radius\" is required");
    if (api_get_number(r, "/select/sphere/radius", 1e15, &s->r, p))
        return p->status;
    if (!(s->r > 0))
        return api_fail_at(p, 422, "out-of-range", "/select/sphere/radius", "radius must be positive");
    return 0;
}

/* Does simplex v[0..n) fall in a geometric selection (its centroid inside)? */
static bool in_region(const selection *s, const double *xyz, const uint32_t *v, int n)
{
    double c[3] = {0, 0, 0};
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 3; k++)
            c[k] += xyz[3 * (size_t)v[i] + k] / n;
    if (s->kind == 1)
        return c[0] >= s->lo[0] && c[0] <= s->hi[0] && c[1] >= s->lo[1] && c[1] <= s->hi[1] &&
               c[2] >= s->lo[2] && c[2] <= s->hi[2];
    double d2 = 0;
    for (int k = 0; k < 3; k++)
        d2 += (c[k] - s->c[k]) * (c[k] - s->c[k]);
    return d2 <= s->r * s->r;
}

static int cmp_pair(const void *x, const void *y) { return memcmp(x, y, 2 * sizeof(uint32_t)); }

/* The sharpness of a refinement step's children, carried by the core as tags are (a split
 * edge's halves, a triangle's children; vertices stay) with the value of what they come from:
 * a change of the control complex, not a subdivision level, so nothing decreases. A new array
 * (malloc) and its size in *n_out; NULL without memory. */
static api_sharp *carry_sharpness(const sd_refinement *r, const api_sharp *sh, uint32_t n,
                                  uint32_t *n_out)
{
    sd_tag_set in = {.idx = malloc((3 * (size_t)n + 1) * sizeof *in.idx),
                     .size = malloc((size_t)n + 1)}, out;
    sd_error e;
    api_sharp *res = NULL;
    if (in.idx && in.size) {
        size_t at = 0;
        for (uint32_t i = 0; i < n; i++) {
            in.size[i] = (uint8_t)sh[i].nverts;
            for (int j = 0; j < sh[i].nverts; j++)
                in.idx[at++] = sh[i].v[j];
        }
        in.ntags = n;
        if (sd_refine_carry(r, &in, &out, &e) == SD_OK) {
            if ((res = malloc((out.ntags + 1) * sizeof *res))) {
                size_t off = 0;
                for (size_t k = 0; k < out.ntags; off += out.size[k++]) {
                    res[k] = (api_sharp){.nverts = out.size[k], .value = sh[out.from[k]].value};
                    memcpy(res[k].v, out.idx + off, out.size[k] * sizeof *out.idx);
                }
                *n_out = (uint32_t)out.ntags;
            }
            sd_tag_set_free(&out);
        }
    }
    free(in.idx);
    free(in.size);
    return res;
}

static api_model *model_with(api_input *in, const api_rules *rules, const api_tags *tags,
                             sd_override *ov, uint32_t nov, const api_limits *lim, sd_error *e)
{
    api_model *m = api_model_new(in, rules, lim->max_session_bytes, lim->batch, e);
    if (!m)
        return NULL;
    while (nov && api_model_set_overrides(m, ov, nov, e)) {
        free(m->rules.overrides);
        m->rules.overrides = NULL;
        m->rules.noverrides = 0;
        if (e->code != SD_ERR_ARG && e->code != SD_ERR_INDEX)
            break;
        long bad = e->item < 0 ? 0 : e->item;
        memmove(ov + bad, ov + bad + 1, (nov - bad - 1) * sizeof *ov);
        nov--;
    }
    int which;
    if ((api_tags_any(tags) || rules->crease_method) && api_model_set_tags(m, tags, e, &which)) {
        api_model_unref(m);
        return NULL;
    }
    return m;
}

/* Whether the session's own level 1 is the one a model of its complex would make: computed,
 * and without detail offsets at level 1 (S p alone, as a fresh model's). Under cur->lock. */
static bool level1_reusable(const api_model *cur)
{
    if (!cur->c || atomic_load(&cur->levels_cached) < 2)
        return false;
    for (int t = -1; t < cur->in->nattrs; t++)
        if (sd_complex_details(cur->c, t < 0 ? 0 : cur->channel[t], 1, NULL, NULL))
            return false;
    return true;
}

/* Place the new vertices of one refinement step by the subdivision rules: the level-1 edge
 * points of the complex before the step (positions and attributes alike). The first step's
 * complex is the session's (`cur`, else NULL): its cached level 1 serves when reusable, and no
 * model is made. */
static int subdivision_positions(const api_model *cur, const api_input *in,
                                 const api_rules *rules, const api_tags *tags,
                                 sd_override *ov, uint32_t nov, sd_refinement *r,
                                 double **attr_new, const api_limits *lim, api_problem *p)
{
    sd_error e = {0};
    api_model *tmp = NULL, *held = NULL;
    const sd_level *l1 = NULL;
    if (cur) { /* the lock that computation and edits take: level 1 is read whole below */
        held = (api_model *)cur;
        pthread_mutex_lock(&held->lock);
        if (level1_reusable(cur))
            l1 = sd_complex_level(cur->c, 1, &e);
        if (!l1) {
            pthread_mutex_unlock(&held->lock);
            held = NULL;
        }
    }
    if (!l1) {
        tmp = model_with((api_input *)in, rules, tags, ov, nov, lim, &e);
        if (tmp)
            sd_complex_set_threads(tmp->c, api_compute_threads());
        l1 = tmp ? sd_complex_level(tmp->c, 1, &e) : NULL;
    }
    const api_model *src = held ? held : tmp;
    if (!l1) {
        api_model_unref(tmp);
        return api_fail_core(p, &e, "/simplices", "/vertices");
    }
    /* sorted (a<b, new id) so each level-1 edge point finds its new vertex */
    uint32_t (*key)[3] = malloc((r->nsplit + 1) * sizeof *key);
    if (!key) {
        if (held)
            pthread_mutex_unlock(&held->lock);
        api_model_unref(tmp);
        return api_fail(p, 503, "out-of-memory", "out of memory");
    }
    for (size_t i = 0; i < r->nsplit; i++) {
        uint32_t a = r->split[i][0], b = r->split[i][1];
        key[i][0] = a < b ? a : b;
        key[i][1] = a < b ? b : a;
        key[i][2] = (uint32_t)(in->nv + i);
    }
    qsort(key, r->nsplit, sizeof *key, cmp_pair);
    uint32_t n1 = sd_level_num_vertices(l1);
    const double *x1 = sd_level_channel(l1, 0, NULL);
    for (uint32_t v = in->nv; v < n1; v++) {
        uint32_t a, b;
        if (sd_level_origin(l1, v, &a, &b) != SD_ORIGIN_EDGE)
            continue;
        uint32_t k[3] = {a < b ? a : b, a < b ? b : a, 0};
        uint32_t (*hit)[3] = bsearch(k, key, r->nsplit, sizeof *key, cmp_pair);
        if (!hit)
            continue;
        uint32_t id = (*hit)[2];
        memcpy(r->xyz + 3 * (size_t)id, x1 + 3 * (size_t)v, 3 * sizeof *x1);
        for (int t = 0; t < in->nattrs; t++) {
            int nc = in->attrs[t].ncomp;
            const double *a1 = sd_level_channel(l1, src->channel[t], NULL);
            memcpy(attr_new[t] + (size_t)id * nc, a1 + (size_t)v * nc, nc * sizeof *a1);
        }
    }
    free(key);
    if (held)
        pthread_mutex_unlock(&held->lock);
    api_model_unref(tmp);
    return 0;
}

/* Which simplices of `in` (of 2 or more vertices) the selection takes: ns + 1 flags (calloc'ed),
 * or NULL for lack of memory. */
static uint8_t *mark_selection(const selection *sel, const api_input *in)
{
    uint8_t *marked = calloc((size_t)in->ns + 1, 1);
    if (!marked)
        return NULL;
    for (uint32_t s = 0, off = 0; s < in->ns; off += in->size[s++]) {
        if (in->size[s] < 2)
            continue;
        if (sel->kind == 0) {
            uint32_t k[4];
            sort_key(k, in->idx + off, in->size[s]);
            marked[s] = bsearch(k, sel->keys, sel->n, sizeof *sel->keys, cmp_key4) != NULL;
        } else
            marked[s] = in_region(sel, in->xyz, in->idx + off, in->size[s]);
    }
    return marked;
}

/* The attributes after a step: the old values, then the new points' at their edges' midpoints
 * (malloc'ed into out[0 .. in->nattrs)); false (nothing allocated) for lack of memory. */
static bool midpoint_attributes(const api_input *in, const sd_refinement *r,
                                double *out[API_MAX_ATTRIBUTES])
{
    for (int t = 0; t < in->nattrs; t++) {
        int nc = in->attrs[t].ncomp;
        if (!(out[t] = malloc(r->nv * nc * sizeof(double) + 8))) {
            for (int u = 0; u < t; u++) {
                free(out[u]);
                out[u] = NULL;
            }
            return false;
        }
        memcpy(out[t], in->attrs[t].data, (size_t)in->nv * nc * sizeof(double));
        for (size_t i = 0; i < r->nsplit; i++)
            for (int k = 0; k < nc; k++)
                out[t][(in->nv + i) * nc + k] =
                    0.5 * (in->attrs[t].data[(size_t)r->split[i][0] * nc + k] +
                           in->attrs[t].data[(size_t)r->split[i][1] * nc + k]);
    }
    return true;
}

/* The refinement's arrays and the step's attributes move into the next input nx. */
static void adopt_step(api_input *nx, const api_input *in, sd_refinement *r,
                       double *attr_new[API_MAX_ATTRIBUTES])
{
    nx->nv = (uint32_t)r->nv;
    nx->ns = (uint32_t)r->ns;
    nx->xyz = r->xyz;
    nx->idx = r->idx;
    nx->size = r->size;
    r->xyz = NULL;
    r->idx = NULL;
    r->size = NULL;
    nx->nattrs = in->nattrs;
    for (int t = 0; t < in->nattrs; t++) {
        nx->attrs[t] = in->attrs[t];
        nx->attrs[t].data = attr_new[t];
    }
}

static double vol6(const double *xyz, const uint32_t *t)
{
    const double *a = xyz + 3 * (size_t)t[0], *b = xyz + 3 * (size_t)t[1], *c = xyz + 3 * (size_t)t[2],
                 *d = xyz + 3 * (size_t)t[3];
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]},
           w[3] = {d[0] - a[0], d[1] - a[1], d[2] - a[2]};
    return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
           u[2] * (v[0] * w[1] - v[1] * w[0]);
}

/* The refined input keeps the choices of its untouched tetrahedra (DECISIONS 17): their stored
 * orientation and their diagonal, given to the build so that Algorithm 2 chooses the new
 * tetrahedra's against them; the new ones are oriented by their volume. false without memory. */
static bool keep_choices(const api_model *cur, api_input *in, const uint32_t *orig)
{
    uint32_t ntet = 0;
    for (uint32_t s = 0; s < in->ns; s++)
        ntet += in->size[s] == 4;
    if (!ntet || !orig)
        return true;
    api_free(in->reoriented);
    api_free(in->diag);
    in->ndiag = 0;
    in->reoriented = api_calloc((size_t)in->ns + 1, 1);
    in->diag = api_malloc(((size_t)ntet + 1) * sizeof *in->diag);
    if (!in->reoriented || !in->diag)
        return false;
    for (uint32_t s = 0, off = 0; s < in->ns; off += in->size[s++]) {
        if (in->size[s] != 4)
            continue;
        if (orig[s] != UINT32_MAX) {
            in->reoriented[s] = sd_complex_reoriented(cur->c, orig[s]) == 1;
            in->diag[in->ndiag][0] = s;
            in->diag[in->ndiag++][1] = (uint32_t)sd_complex_diagonal(cur->c, orig[s]);
        } else
            in->reoriented[s] = vol6(in->xyz, in->idx + off) < 0;
    }
    return true;
}

/* The input of one refinement step, kept so that the step can be made again (red-green: a green
 * cell of a step that the next step would split is taken back, its parent split red instead). */
typedef struct rstep {
    api_input *in;            /* a reference */
    api_tags tags;            /* the C library's blocks (sd_refine_carry's) */
    sd_override *ov;
    uint32_t nov;
    uint32_t *orig;           /* per simplex: the posted simplex it still is, or UINT32_MAX (NULL
                               * at step 0: the identity) */
    uint8_t *sel;             /* per simplex: selected (at step 0: by vertex list or by centroid in
                               * the region), or a child of a selected one */
    uint32_t *gparent;        /* per simplex: its parent in the step before when that parent was
                               * split green, else UINT32_MAX (NULL at step 0) */
    uint8_t *up;              /* per simplex: split red for a green cell the next step splits */
    uint64_t red, green;      /* what the step before split to make this input */
} rstep;

static void rstep_clear(rstep *s)
{
    if (s->in)
        api_input_unref(s->in);
    api_tags_free(&s->tags);
    free(s->ov);
    free(s->orig);
    free(s->sel);
    free(s->gparent);
    free(s->up);
    memset(s, 0, sizeof *s);
}

/* One step from S (step j): the simplices marked — the selection's (at step 0) or its children,
 * those S->up names — split
 * red and green around, the new points placed, attributes, tags and overrides carried; the next
 * step's input into *nx, and into *touched which of S's simplices the step split. *none when
 * nothing is marked (no step). 0 or the status of the problem. */
static int run_step(const api_model *cur, const rstep *S, int j, int place,
                    const api_limits *lim, rstep *nx, uint8_t **touched, bool *none,
                    api_problem *p)
{
    const api_input *in = S->in;
    *touched = NULL;
    *none = false;
    memset(nx, 0, sizeof *nx);
    uint8_t *diag = malloc((size_t)in->ns + 1);
    uint8_t *mk = malloc((size_t)in->ns + 1);
    if (!diag || !mk) {
        free(diag);
        free(mk);
        return api_fail(p, 503, "out-of-memory", "out of memory");
    }
    uint64_t nmarked = 0;
    for (uint32_t s = 0; s < in->ns; s++)
        nmarked += mk[s] = (S->sel[s] || (S->up && S->up[s])) && in->size[s] >= 2;
    if (!nmarked) {
        free(mk);
        free(diag);
        *none = true;
        return 0;
    }
    /* a tetrahedron split red cuts its octahedron along its diagonal: the session's for the
     * posted tetrahedra (those of later steps that are still one of them included); the first
     * pair for the children of an earlier step, whose diagonals Algorithm 2 chooses when the
     * refined model is made */
    for (uint32_t s = 0; s < in->ns; s++) {
        uint32_t o = S->orig ? S->orig[s] : s;
        int d = in->size[s] == 4 && o != UINT32_MAX ? sd_complex_diagonal(cur->c, o) : 0;
        diag[s] = (uint8_t)(d >= 0 && d < 3 ? d : 0);
    }
    sd_refinement r;
    sd_error e = {0};
    /* the limits before the result is allocated, the working arrays within the memory budget */
    sd_allocator budget = api_mem_core_allocator();
    sd_refine_limits rl = {lim->max_vertices, lim->max_simplices, &budget};
    int refined = sd_refine(in->xyz, in->nv, in->idx, in->size, in->ns, mk, diag, &rl, &r, &e);
    free(diag);
    free(mk);
    if (refined == SD_ERR_LIMIT && e.item >= 0) /* counted before the result was made */
        return api_fail_limit(p, e.field == 0 ? "max_vertices" : "max_simplices",
                              e.field == 0 ? lim->max_vertices : lim->max_simplices,
                              (uint64_t)e.item, "%s; refine a smaller region or less deep",
                              e.message);
    if (refined)
        return api_fail_core(p, &e, "/select", NULL);
    nx->red = r.red;
    nx->green = r.green;
    int rc = 0;
    /* new attribute arrays: old values, then the new points at midpoints */
    double *attr_new[API_MAX_ATTRIBUTES] = {0};
    if (!midpoint_attributes(in, &r, attr_new))
        rc = api_fail(p, 503, "out-of-memory", "out of memory");
    /* or where the subdivision rules put them: level-1 edge points of the step's input; a
     * tetrahedron they would turn inside out (against the midpoints' placement, which keeps
     * every child's orientation) refuses the placement */
    if (!rc && place == 0) {
        sd_override *ovc = malloc((S->nov + 1) * sizeof *ovc); /* model_with may drop some */
        double *mid = malloc((3 * r.nv + 1) * sizeof *mid);
        if (!ovc || !mid)
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
        else {
            memcpy(mid, r.xyz, 3 * r.nv * sizeof *mid);
            memcpy(ovc, S->ov, S->nov * sizeof *ovc);
            rc = subdivision_positions(j == 0 ? cur : NULL, in, &cur->rules, &S->tags, ovc,
                                       S->nov, &r, attr_new, lim, p);
        }
        size_t folded = 0;
        for (size_t i = 0, off = 0; !rc && i < r.ns; off += r.size[i++])
            if (r.size[i] == 4 && !(vol6(mid, r.idx + off) * vol6(r.xyz, r.idx + off) > 0))
                folded++;
        if (folded)
            rc = api_fail_at(p, 422, "folded-placement", "/positions",
                             "placing the new points by the subdivision rules turns %zu "
                             "tetrahedra of refinement step %d inside out here (the control "
                             "complex is too irregular around the selection for it); "
                             "\"positions\": \"midpoint\" keeps them", folded, j + 1);
        free(ovc);
        free(mid);
    }
    if (!rc) { /* the step's tags and overrides, carried to the children (core) */
        sd_tag_set was = {S->tags.idx, S->tags.size, S->tags.n, S->tags.pet, S->tags.npet, S->ov,
                          S->nov, NULL}, now;
        if (sd_refine_carry(&r, &was, &now, &e)) {
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
        } else {
            uint32_t nsh = S->tags.nsh;
            api_sharp *sh = carry_sharpness(&r, S->tags.sh, S->tags.nsh, &nsh);
            /* tangent-plane constraints act on the first step, not carried */
            nx->tags = (api_tags){.n = (uint32_t)now.ntags, .size = now.size, .idx = now.idx,
                                  .npet = (uint32_t)now.npetals, .pet = now.petals,
                                  .nsh = sh ? nsh : 0, .sh = sh};
            if (!sh)
                rc = api_fail(p, 503, "out-of-memory", "out of memory");
            nx->ov = now.overrides;
            nx->nov = (uint32_t)now.noverrides;
            free(now.from);
        }
    }
    api_input *next = rc ? NULL : api_input_new();
    if (!rc && !next)
        rc = api_fail(p, 503, "out-of-memory", "out of memory");
    /* what the step split, which children are selected, which come from a green split, which
     * posted simplex each new one still is (an untouched one: its parent's only child, the same
     * vertex list) */
    uint32_t *children = rc ? NULL : calloc((size_t)in->ns + 1, sizeof *children);
    if (!rc) {
        nx->orig = malloc((r.ns + 1) * sizeof *nx->orig);
        nx->sel = calloc(r.ns + 1, 1);
        nx->gparent = malloc((r.ns + 1) * sizeof *nx->gparent);
        *touched = calloc((size_t)in->ns + 1, 1);
        if (!children || !nx->orig || !nx->sel || !nx->gparent || !*touched)
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
    }
    if (rc) {
        for (int t = 0; t < in->nattrs; t++)
            free(attr_new[t]);
        free(children);
        free(*touched);
        *touched = NULL;
        if (next)
            api_input_unref(next);
        rstep_clear(nx);
        sd_refine_free(&r);
        return rc;
    }
    for (size_t i = 0; i < r.ns; i++)
        children[r.parent[i]]++;
    for (size_t i = 0; i < r.ns; i++) {
        uint32_t q = r.parent[i];
        bool kept = children[q] == 1 && r.size[i] == in->size[q];
        bool green = (in->size[q] == 4 && (children[q] == 2 || children[q] == 4)) ||
                     (in->size[q] == 3 && children[q] == 2);
        nx->orig[i] = kept ? (S->orig ? S->orig[q] : q) : UINT32_MAX;
        (*touched)[q] = !kept;
        nx->gparent[i] = green ? q : UINT32_MAX;
        nx->sel[i] = S->sel[q]; /* the children of the selection (not of upgrades) */
    }
    free(children);
    adopt_step(next, in, &r, attr_new);
    sd_refine_free(&r);
    nx->in = next;
    if (!api_input_account(next)) { /* the adopted arrays count against the memory budget */
        free(*touched);
        *touched = NULL;
        rstep_clear(nx);
        return api_fail(p, 503, "out-of-memory", "out of memory");
    }
    return 0;
}

/* A refined complex that PUT /complex would refuse — typically a cell under its degeneracy test
 * (DECISIONS 7: an edge shorter than 1e-12 of the bounding box's diagonal, a near-zero area or
 * volume) — is the request's doing: named at /select, not at the /simplices or /vertices this
 * request does not have (the core's reason names the refined complex's simplex or vertex, which
 * the client never sees). */
static int refused_result(api_problem *p)
{
    char why[sizeof p->detail];
    snprintf(why, sizeof why, "%s", p->detail);
    return api_fail_at(p, 422, "invalid-complex", "/select",
                       "the refined complex would be one PUT /complex refuses: %s (numbered in "
                       "the refined complex; a cell with an edge shorter than 1e-12 of the "
                       "bounding box's diagonal is degenerate); refine less deep", why);
}

/* The most steps made (again) in one refinement: past it, the green cells left are kept. */
#define RG_MAX_RUNS 64

/* POST /refine: `depth` steps of sd_refine on the working input, each with its new points placed,
 * its attributes and its tags and overrides carried; then one model from the result. A green
 * cell of a step that the next step would split is taken back: its parent is split red in that
 * step, which is made again (classic red-green refinement), so cells keep their shape however
 * deep the refinement goes. */
int api_refine(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
               api_refined *done, api_problem *p)
{
    static const char *const keys[] = {"select", "depth", "positions", NULL};
    static const char *const placements[] = {"subdivision", "midpoint", NULL};
    *out = NULL;
    memset(done, 0, sizeof *done);
    if (api_only_keys(body, "", keys, p))
        return p->status;
    if (!cur->in)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    json_t *v;
    long long depth = 1;
    int place = 0;
    if ((v = json_object_get(body, "depth")) && api_get_int(v, "/depth", 1, 4, &depth, p))
        return p->status;
    if ((v = json_object_get(body, "positions")) &&
        (place = api_get_enum(v, "/positions", placements, p)) < 0)
        return p->status;
    if (!(v = json_object_get(body, "select")))
        return api_fail_at(p, 400, "missing-field", "/select", "\"select\" is required");
    selection sel = {0};
    int rc = parse_selection(v, cur->in, &sel, p);
    rstep st[5] = {{0}}; /* the input of each step (depth <= 4) */
    if (!rc) {
        st[0].in = cur->in;
        atomic_fetch_add(&cur->in->refs, 1);
        st[0].nov = cur->rules.noverrides;
        st[0].ov = malloc((st[0].nov + 1) * sizeof *st[0].ov);
        bool copied = api_tags_copy(&st[0].tags, &cur->tags);
        st[0].sel = mark_selection(&sel, cur->in); /* later steps: its children */
        if (!st[0].ov || !copied || !st[0].sel)
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
        else if (st[0].nov)
            memcpy(st[0].ov, cur->rules.overrides, st[0].nov * sizeof *st[0].ov);
    }
    /* a bound of the result before any work: every selected simplex of k vertices ends as at
     * least RED[k]^depth (its red descendants; upgrades and green cells taken back only add),
     * every other simplex as at least one */
    if (!rc && lim->max_simplices) {
        static const uint64_t RED[5] = {1, 1, 2, 4, 8};
        uint64_t least = 0;
        for (uint32_t s = 0; s < cur->in->ns; s++) {
            uint64_t n = 1;
            for (long long d = 0; st[0].sel[s] && d < depth; d++)
                n *= RED[cur->in->size[s]];
            least += n;
        }
        if (least > lim->max_simplices)
            rc = api_fail_limit(p, "max_simplices", lim->max_simplices, least,
                                "the refined complex would have at least %llu simplices (the "
                                "selection's red descendants at depth %lld alone); refine a "
                                "smaller region or less deep", (unsigned long long)least, depth);
    }
    int j = 0, runs = 0;
    while (!rc && j < depth) {
        rstep nx;
        uint8_t *touched;
        bool none;
        if ((rc = run_step(cur, &st[j], j, place, lim, &nx, &touched, &none, p)))
            break;
        runs++;
        if (none) { /* nothing (left) to refine */
            if (j == 0 && runs == 1) /* no new version of the same complex */
                rc = api_fail_at(p, 422, "empty-selection", "/select",
                                 "the selection holds no edge, triangle or tetrahedron of the "
                                 "complex (isolated points are not refined): nothing to refine");
            break;
        }
        /* green cells of the step before that this step splits: their parents go red there */
        bool again = false;
        for (uint32_t s = 0; j > 0 && s < st[j].in->ns; s++) {
            uint32_t g = st[j].gparent[s];
            if (!touched[s] || g == UINT32_MAX)
                continue;
            if (runs >= RG_MAX_RUNS) { /* no more steps: this green cell is split as it is */
                done->capped = true;
                break;
            }
            if (!st[j - 1].up && !(st[j - 1].up = calloc((size_t)st[j - 1].in->ns + 1, 1))) {
                rc = api_fail(p, 503, "out-of-memory", "out of memory");
                break;
            }
            st[j - 1].up[g] = 1;
            again = true;
        }
        free(touched);
        if (rc || again) {
            rstep_clear(&nx);
            if (!rc) /* step j - 1 again, with its new red cells */
                rstep_clear(&st[j--]);
            continue;
        }
        st[++j] = nx;
    }
    free(sel.keys);
    for (int k = 1; !rc && k <= j; k++) {
        done->red += st[k].red;
        done->green += st[k].green;
    }
    done->steps = runs;
    rstep *fin = &st[j];
    if (!rc && fin->in != cur->in && !keep_choices(cur, fin->in, fin->orig))
        rc = api_fail(p, 503, "out-of-memory", "out of memory");
    if (!rc) { /* with the carried tags and overrides (those that no longer fit are dropped) */
        sd_error e = {0};
        api_model *m = model_with(fin->in, &cur->rules, &fin->tags, fin->ov, fin->nov, lim, &e);
        api_rules keep = cur->rules;
        keep.overrides = m ? m->rules.overrides : NULL;
        keep.noverrides = m ? m->rules.noverrides : 0;
        rc = build_model(fin->in, &keep, &fin->tags, lim, out, p);
        api_model_unref(m);
    }
    /* the only complexes validated here are refined ones (a step's, for subdivision placement,
     * or the result) */
    if (rc == 422 && p->slug && strcmp(p->slug, "invalid-complex") == 0 &&
        (!p->nerrors || strncmp(p->errors[0].pointer, "/select", 7) != 0))
        rc = refused_result(p);
    for (int k = 0; k <= 4; k++)
        rstep_clear(&st[k]);
    return rc;
}
