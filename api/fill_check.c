/* fill_check.c — the checks of a fill surface before TetGen sees it, and of TetGen's tetrahedra
 * after (see fill.h for what a fill is).
 *
 * Debian's TetGen 1.5 crashes rather than refuse on some bad input, so everything that can be
 * judged from the surface alone is judged here, each refusal a 422 pointing at the triangle
 * (/fill/0/surface/7) or vertex: finite coordinates, a bounding box with volume, no degenerate
 * triangle (as the core judges them), no triangle twice, closed (every edge in exactly two
 * triangles, up to API_MAX_FIELD_ERRORS edges listed), orientable (a walk across the edges that
 * never contradicts itself; it also gives the enclosed volume), no coincident points. After TetGen:
 * the boundary of its tetrahedra must be the surface as posted (a 500 otherwise: TetGen broke its
 * promise, the request was fine). Tolerances are relative to the bounding box's diagonal.
 */
#include "fill_internal.h"
#include "mem.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct edge_rec {
    uint32_t a, b;      /* a < b, local */
    uint32_t tri;
    uint32_t forward;   /* the triangle runs a -> b */
} edge_rec;

static int cmp_edge(const void *x, const void *y)
{
    const edge_rec *e = x, *f = y;
    if (e->a != f->a)
        return e->a < f->a ? -1 : 1;
    if (e->b != f->b)
        return e->b < f->b ? -1 : 1;
    return e->tri < f->tri ? -1 : e->tri > f->tri;
}

typedef struct tri_key {
    uint32_t v[3];
    uint32_t tri;
} tri_key;

static int cmp_tri_key(const void *x, const void *y)
{
    const tri_key *e = x, *f = y;
    int c = memcmp(e->v, f->v, sizeof e->v);
    return c ? c : (e->tri < f->tri ? -1 : e->tri > f->tri);
}

void api_fill_sort3(uint32_t v[3])
{
    uint32_t t;
    if (v[0] > v[1]) t = v[0], v[0] = v[1], v[1] = t;
    if (v[1] > v[2]) t = v[1], v[1] = v[2], v[2] = t;
    if (v[0] > v[1]) t = v[0], v[0] = v[1], v[1] = t;
}

static int by_x(const void *x, const void *y, void *xyz)
{
    const double *c = xyz;
    double a = c[3 * (size_t)*(const uint32_t *)x], b = c[3 * (size_t)*(const uint32_t *)y];
    return a < b ? -1 : a > b;
}

double api_fill_det3(const double *a, const double *b, const double *c, const double *o)
{
    double u[3], v[3], w[3];
    for (int k = 0; k < 3; k++)
        u[k] = a[k] - o[k], v[k] = b[k] - o[k], w[k] = c[k] - o[k];
    return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
           u[2] * (v[0] * w[1] - v[1] * w[0]);
}

void api_fill_tri_ptr(char *dst, size_t cap, size_t k, size_t j)
{
    snprintf(dst, cap, "/fill/%zu/surface/%zu", k, j);
}

int api_fill_cmp_u32x3(const void *x, const void *y) { return memcmp(x, y, 3 * sizeof(uint32_t)); }

void api_fill_surface_free(surface *s)
{
    api_free(s->tri);
    api_free(s->ltri);
    api_free(s->glob);
    api_free(s->xyz);
}

/* The surface's numbering and extent, shared by the checks. */
typedef struct extent {
    double lo[3], hi[3];
    double diag, tol;         /* the bounding box's diagonal, FILL_TOL times it */
} extent;

/* Local numbering in order of global index (s->ltri, glob, xyz, nloc), first[g] = the first slot
 * (3 j + m) using global vertex g, the bounding box; finite coordinates within +-1e15. */
static int number(surface *s, const api_input *in, uint32_t *map, uint32_t *first, extent *x,
                  api_problem *p)
{
    char ptr[96];
    memset(map, 0xff, (size_t)in->nv * sizeof *map);
    for (size_t i = 0; i < 3 * (size_t)s->nt; i++)
        if (map[s->tri[i]] == UINT32_MAX) {
            map[s->tri[i]] = 0;
            first[s->tri[i]] = (uint32_t)i;
        }
    s->nloc = 0;
    for (uint32_t g = 0; g < in->nv; g++)
        if (map[g] != UINT32_MAX)
            map[g] = s->nloc++;
    s->glob = api_malloc((size_t)s->nloc * sizeof *s->glob);
    s->xyz = api_malloc(3 * (size_t)s->nloc * sizeof *s->xyz);
    if (!s->glob || !s->xyz)
        return api_fail(p, 503, "out-of-memory", "out of memory checking the surface");
    for (int c = 0; c < 3; c++)
        x->lo[c] = INFINITY, x->hi[c] = -INFINITY;
    for (uint32_t g = 0; g < in->nv; g++) {
        if (map[g] == UINT32_MAX)
            continue;
        s->glob[map[g]] = g;
        for (int c = 0; c < 3; c++) {
            double v = in->xyz[3 * (size_t)g + c];
            if (!isfinite(v) || fabs(v) > FILL_MAX_COORD) {
                snprintf(ptr, sizeof ptr, "/vertices/%u/%d", g, c);
                return api_fail_at(p, 422, "invalid-complex", ptr,
                                   "coordinate %g of vertex %u is beyond +-1e15", v, g);
            }
            s->xyz[3 * (size_t)map[g] + c] = v;
            x->lo[c] = fmin(x->lo[c], v);
            x->hi[c] = fmax(x->hi[c], v);
        }
    }
    for (size_t i = 0; i < 3 * (size_t)s->nt; i++)
        s->ltri[i] = map[s->tri[i]];
    return 0;
}

/* A bounding box with volume: something to fill. */
static int check_flat(size_t k, extent *x, api_problem *p)
{
    char ptr[96];
    double ext[3] = {x->hi[0] - x->lo[0], x->hi[1] - x->lo[1], x->hi[2] - x->lo[2]};
    x->diag = sqrt(ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]);
    x->tol = FILL_TOL * x->diag;
    snprintf(ptr, sizeof ptr, "/fill/%zu/surface", k);
    if (!(x->diag > 0) || fmin(ext[0], fmin(ext[1], ext[2])) <= x->tol)
        return api_fail_at(p, 422, "invalid-surface", ptr,
                           "the surface is flat: its bounding box (%g x %g x %g) has no volume, so "
                           "there is nothing to fill", ext[0], ext[1], ext[2]);
    return 0;
}

/* Degenerate triangles, as the core judges them. */
static int check_degenerate(const surface *s, size_t k, const extent *x, api_problem *p)
{
    char ptr[96];
    for (uint32_t j = 0; j < s->nt; j++) {
        const uint32_t *t = s->ltri + 3 * (size_t)j;
        double lmax = 0, e[3][3];
        for (int m = 0; m < 3; m++) {
            const double *a = s->xyz + 3 * (size_t)t[m], *b = s->xyz + 3 * (size_t)t[(m + 1) % 3];
            for (int c = 0; c < 3; c++)
                e[m][c] = b[c] - a[c];
            lmax = fmax(lmax, sqrt(e[m][0] * e[m][0] + e[m][1] * e[m][1] + e[m][2] * e[m][2]));
        }
        double cr[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1], e[0][2] * e[1][0] - e[0][0] * e[1][2],
                        e[0][0] * e[1][1] - e[0][1] * e[1][0]};
        double area = 0.5 * sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        double emin = INFINITY;
        for (int m = 0; m < 3; m++)
            emin = fmin(emin, sqrt(e[m][0] * e[m][0] + e[m][1] * e[m][1] + e[m][2] * e[m][2]));
        if (emin <= x->tol || area <= FILL_TOL * lmax * lmax) {
            api_fill_tri_ptr(ptr, sizeof ptr, k, j);
            return api_fail_at(p, 422, "invalid-surface", ptr,
                               "triangle %u (%u, %u, %u) is degenerate (area %g, shortest edge %g)", j,
                               s->tri[3 * j], s->tri[3 * j + 1], s->tri[3 * j + 2], area, emin);
        }
    }
    return 0;
}

/* The same triangle twice (tk: scratch of nt keys). */
static int check_repeated(const surface *s, size_t k, tri_key *tk, api_problem *p)
{
    char ptr[96];
    for (uint32_t j = 0; j < s->nt; j++) {
        memcpy(tk[j].v, s->ltri + 3 * (size_t)j, sizeof tk[j].v);
        api_fill_sort3(tk[j].v);
        tk[j].tri = j;
    }
    qsort(tk, s->nt, sizeof *tk, cmp_tri_key);
    for (uint32_t j = 1; j < s->nt; j++)
        if (!memcmp(tk[j].v, tk[j - 1].v, sizeof tk[j].v)) {
            api_fill_tri_ptr(ptr, sizeof ptr, k, tk[j].tri);
            return api_fail_at(p, 422, "invalid-surface", ptr, "triangle %u repeats triangle %u",
                               tk[j].tri, tk[j - 1].tri);
        }
    return 0;
}

/* Closed: every edge in exactly two triangles (reports up to API_MAX_FIELD_ERRORS edges). er
 * (3 nt) comes back sorted, each edge's two uses side by side. */
static int check_closed(const surface *s, size_t k, edge_rec *er, api_problem *p)
{
    char ptr[96];
    for (uint32_t j = 0; j < s->nt; j++)
        for (int m = 0; m < 3; m++) {
            uint32_t a = s->ltri[3 * (size_t)j + m], b = s->ltri[3 * (size_t)j + (m + 1) % 3];
            edge_rec *r = &er[3 * (size_t)j + m];
            r->a = a < b ? a : b;
            r->b = a < b ? b : a;
            r->tri = j;
            r->forward = a < b;
        }
    size_t ne = 3 * (size_t)s->nt;
    qsort(er, ne, sizeof *er, cmp_edge);
    int nbad = 0;
    for (size_t i = 0; i < ne;) {
        size_t e = i + 1;
        while (e < ne && er[e].a == er[i].a && er[e].b == er[i].b)
            e++;
        if (e - i != 2) {
            char msg[200];
            if (e - i == 1)
                snprintf(msg, sizeof msg, "edge (%u, %u) of triangle %u has no other triangle: the "
                         "surface is not closed", s->glob[er[i].a], s->glob[er[i].b], er[i].tri);
            else
                snprintf(msg, sizeof msg, "edge (%u, %u) is shared by %zu triangles (%u, %u, %u...); "
                         "a closed surface has exactly 2 at every edge", s->glob[er[i].a],
                         s->glob[er[i].b], e - i, er[i].tri, er[i + 1].tri, er[i + 2].tri);
            api_fill_tri_ptr(ptr, sizeof ptr, k, er[e - i == 1 ? i : i + 2].tri);
            if (!nbad++)
                api_fail_at(p, 422, "invalid-surface", ptr, "%s", msg);
            else
                api_add_error(p, ptr, "%s", msg);
        }
        i = e;
    }
    if (!nbad)
        return 0;
    if (nbad > 1)
        snprintf(p->detail, sizeof p->detail, "the surface of /fill/%zu is not closed: %d edges "
                 "do not have exactly two triangles (the first %d are listed)", k, nbad,
                 nbad < API_MAX_FIELD_ERRORS ? nbad : API_MAX_FIELD_ERRORS);
    return 422;
}

/* Orientable: walk the triangles across edges (er from check_closed), flipping where a neighbour
 * runs the shared edge the same way; a contradiction means no consistent orientation exists.
 * s->volume = the sum of the components' enclosed volumes. */
static int check_orientable(surface *s, size_t k, const edge_rec *er, const extent *x,
                            api_problem *p)
{
    char ptr[96];
    uint32_t nt = s->nt;
    size_t ne = 3 * (size_t)nt;
    uint32_t *nb = api_malloc(3 * (size_t)nt * sizeof *nb), *queue = api_malloc((size_t)nt * sizeof *queue);
    uint8_t *deg = api_calloc(nt, 1), *flip = api_malloc(3 * (size_t)nt), *orient = api_malloc(nt);
    double *cvol = api_calloc(nt, sizeof *cvol);
    int rc = 0;
    if (!nb || !queue || !deg || !flip || !orient || !cvol) {
        rc = api_fail(p, 503, "out-of-memory", "out of memory checking the surface");
        goto out;
    }
    for (size_t i = 0; i < ne; i += 2) {
        uint32_t t1 = er[i].tri, t2 = er[i + 1].tri;
        uint8_t f = er[i].forward == er[i + 1].forward;
        nb[3 * (size_t)t1 + deg[t1]] = t2, flip[3 * (size_t)t1 + deg[t1]++] = f;
        nb[3 * (size_t)t2 + deg[t2]] = t1, flip[3 * (size_t)t2 + deg[t2]++] = f;
    }
    memset(orient, 2, nt);
    double o[3] = {(x->lo[0] + x->hi[0]) / 2, (x->lo[1] + x->hi[1]) / 2, (x->lo[2] + x->hi[2]) / 2};
    uint32_t ncomp = 0;
    for (uint32_t seed = 0; seed < nt && !rc; seed++) {
        if (orient[seed] != 2)
            continue;
        size_t head = 0, tail = 0;
        orient[seed] = 0;
        queue[tail++] = seed;
        double v = 0;
        while (head < tail && !rc) {
            uint32_t t = queue[head++];
            const uint32_t *q = s->ltri + 3 * (size_t)t;
            double d = api_fill_det3(s->xyz + 3 * (size_t)q[0], s->xyz + 3 * (size_t)q[1],
                                     s->xyz + 3 * (size_t)q[2], o) / 6;
            v += orient[t] ? -d : d;
            for (int m = 0; m < 3; m++) {
                uint32_t u = nb[3 * (size_t)t + m];
                uint8_t want = orient[t] ^ flip[3 * (size_t)t + m];
                if (orient[u] == 2) {
                    orient[u] = want;
                    queue[tail++] = u;
                } else if (orient[u] != want) {
                    api_fill_tri_ptr(ptr, sizeof ptr, k, u);
                    rc = api_fail_at(p, 422, "invalid-surface", ptr,
                                     "the surface is not orientable (like a Moebius strip): "
                                     "triangle %u cannot be oriented consistently with its "
                                     "neighbours", u);
                }
            }
        }
        cvol[ncomp++] = fabs(v);
    }
    s->volume = 0;
    for (uint32_t c = 0; c < ncomp; c++)
        s->volume += cvol[c];
    if (!rc && s->volume <= FILL_TOL * x->diag * x->diag * x->diag) {
        snprintf(ptr, sizeof ptr, "/fill/%zu/surface", k);
        rc = api_fail_at(p, 422, "invalid-surface", ptr, "the surface encloses no volume");
    }
out:
    api_free(nb);
    api_free(queue);
    api_free(deg);
    api_free(flip);
    api_free(orient);
    api_free(cvol);
    return rc;
}

/* Coincident points (TetGen crashes on them): sort by x, compare within the tolerance; the
 * pointer names the later vertex's first use (first[]). */
static int check_coincident(const surface *s, size_t k, const uint32_t *first, const extent *x,
                            api_problem *p)
{
    char ptr[96];
    uint32_t *ord = api_malloc((size_t)s->nloc * sizeof *ord);
    if (!ord)
        return api_fail(p, 503, "out-of-memory", "out of memory checking the surface");
    for (uint32_t i = 0; i < s->nloc; i++)
        ord[i] = i;
    qsort_r(ord, s->nloc, sizeof *ord, by_x, s->xyz);
    int rc = 0;
    for (uint32_t i = 0; i < s->nloc && !rc; i++)
        for (uint32_t j = i + 1; j < s->nloc && !rc; j++) {
            const double *a = s->xyz + 3 * (size_t)ord[i], *b = s->xyz + 3 * (size_t)ord[j];
            if (b[0] - a[0] > x->tol)
                break;
            double d = sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                            (a[2] - b[2]) * (a[2] - b[2]));
            if (d <= x->tol) {
                uint32_t ga = s->glob[ord[i]], gb = s->glob[ord[j]];
                if (ga > gb) {
                    uint32_t t = ga;
                    ga = gb;
                    gb = t;
                }
                snprintf(ptr, sizeof ptr, "/fill/%zu/surface/%u/%u", k, first[gb] / 3, first[gb] % 3);
                rc = api_fail_at(p, 422, "invalid-surface", ptr,
                                 "vertices %u and %u coincide (%g apart); TetGen needs distinct "
                                 "points", ga, gb, d);
            }
        }
    api_free(ord);
    return rc;
}

int api_fill_check_surface(surface *s, size_t k, const api_input *in, api_problem *p)
{
    uint32_t nt = s->nt;
    uint32_t *map = api_malloc(((size_t)in->nv + 1) * sizeof *map);
    uint32_t *first = api_malloc(((size_t)in->nv + 1) * sizeof *first);
    s->ltri = api_malloc(3 * (size_t)nt * sizeof *s->ltri);
    edge_rec *er = api_malloc(3 * (size_t)nt * sizeof *er);
    tri_key *tk = api_malloc((size_t)nt * sizeof *tk);
    extent x;
    int rc;
    if (!map || !first || !s->ltri || !er || !tk)
        rc = api_fail(p, 503, "out-of-memory", "out of memory checking the surface");
    else if (!(rc = number(s, in, map, first, &x, p)) && !(rc = check_flat(k, &x, p)) &&
             !(rc = check_degenerate(s, k, &x, p)) && !(rc = check_repeated(s, k, tk, p)) &&
             !(rc = check_closed(s, k, er, p)) && !(rc = check_orientable(s, k, er, &x, p)))
        rc = check_coincident(s, k, first, &x, p);
    api_free(map);
    api_free(first);
    api_free(er);
    api_free(tk);
    return rc;
}

/* The boundary of the tetrahedra is the surface: every face used once is a surface triangle,
 * and every surface triangle is a face (used twice when it lies inside, e.g. nested shells). */
int api_fill_check_boundary(const surface *s, const uint32_t *tets, uint32_t nt4, size_t k,
                            api_problem *p)
{
    static const int F[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
    uint32_t *faces = api_malloc(12 * (size_t)nt4 * sizeof *faces);
    uint32_t *sf = api_malloc(3 * (size_t)s->nt * sizeof *sf);
    int rc = 0;
    if (!faces || !sf) {
        rc = api_fail(p, 503, "out-of-memory", "out of memory checking TetGen's result");
        goto out;
    }
    for (size_t t = 0; t < nt4; t++)
        for (int f = 0; f < 4; f++) {
            uint32_t *d = faces + 12 * t + 3 * (size_t)f;
            for (int m = 0; m < 3; m++)
                d[m] = tets[4 * t + (size_t)F[f][m]];
            api_fill_sort3(d);
        }
    qsort(faces, 4 * (size_t)nt4, 3 * sizeof *faces, api_fill_cmp_u32x3);
    for (uint32_t j = 0; j < s->nt; j++) {
        memcpy(sf + 3 * (size_t)j, s->ltri + 3 * (size_t)j, 3 * sizeof *sf);
        api_fill_sort3(sf + 3 * (size_t)j);
        if (!bsearch(sf + 3 * (size_t)j, faces, 4 * (size_t)nt4, 3 * sizeof *faces, api_fill_cmp_u32x3)) {
            char ptr[96];
            api_fill_tri_ptr(ptr, sizeof ptr, k, j);
            rc = api_fail_at(p, 500, "fill-failed", ptr, "TetGen did not keep triangle %u of "
                             "/fill/%zu", j, k);
            goto out;
        }
    }
    qsort(sf, s->nt, 3 * sizeof *sf, api_fill_cmp_u32x3);
    for (size_t i = 0, n = 4 * (size_t)nt4; i < n;) {
        size_t e = i + 1;
        while (e < n && !api_fill_cmp_u32x3(faces + 3 * i, faces + 3 * e))
            e++;
        if (e - i == 1 && !bsearch(faces + 3 * i, sf, s->nt, 3 * sizeof *sf, api_fill_cmp_u32x3)) {
            rc = api_fail(p, 500, "fill-failed", "the boundary of TetGen's tetrahedra for /fill/%zu "
                          "is not the surface", k);
            goto out;
        }
        if (e - i > 2) {
            rc = api_fail(p, 500, "fill-failed", "TetGen's tetrahedra for /fill/%zu overlap", k);
            goto out;
        }
        i = e;
    }
out:
    api_free(faces);
    api_free(sf);
    return rc;
}
