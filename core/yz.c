/* yz.c — Ying-Zorin's flatness modification (003 Sec. 2 and Appendix A): the edges of closed
 * petals (the fixed-disk rule), dart petals and concave corner petals at a fixed centre.
 *
 * The centre v of such a petal is a complex singular vertex: a corner, fixed. Each edge point of
 * the petal takes two stages (003 Sec. 2):
 *   1. 003 Fig. 4f inside the petal, E_j = (3/4 - g) v + g p_j + 1/8 (p_{j-1} + p_{j+1}),
 *      g = 1/2 - cos(theta)/4, p_0 .. the petal's ring in order; singular edges take their
 *      midpoint;
 *   2. the flatness modification p <- (1 - s) p + s (a_0 x^0 + a_1 x^1 + a_2 x^2): the part of the
 *      petal's new points in the eigenvectors of 1 and the tangent pair is kept, the rest is
 *      scaled by 1 - s. With v fixed, a_0 x^0 = v and, writing q_j = p_j - v, the first stage is
 *      E - v = T q.
 * Closed petal (fixed disk), ring p_0 .. p_{k-1} around v: theta = pi/3 (Loop); App. A's tangent
 *   pair x^1_i = sin(2 pi i/k), x^2_i = cos(2 pi i/k), l^{1,2} = 2/k sin, 2/k cos, eigenvalue
 *   lambda = 3/8 + cos(2 pi/k)/4. Row of edge v-p_0:
 *     v:   (1 - s) 3/8 + s
 *     p_j: (1 - s) Loop_j + s 2/k lambda cos(2 pi j/k)
 *   (Loop_j = 3/8 at j = 0, 1/8 at j = 1 and k - 1, else 0). The cone mode (eigenvalue 5/8) and
 *   the modes j >= 2 are scaled by 1 - s; lambda is subdominant iff (1 - s) 5/8 < lambda, i.e.
 *   s > (2 - 2 cos(2 pi/k))/5 (3/5 at k = 3).
 * Dart petal, ring p_0 .. p_{k-1} around v, v-p_0 its singular edge: theta = 2 pi/k. T's
 *   eigenvalues (derived here; docs/DECISIONS.md 28): 1/2 twice, on x_i = cos(2 pi i/k) and
 *   sin(2 pi i/k), with left eigenvectors e_0 and 2/k sin(2 pi i/k) (both dual to the pair and
 *   to the other modes, which vanish at p_0); the other modes are sin(j pi i/k) with eigenvalue
 *   1/2 + (cos(j pi/k) - cos(2 pi/k))/4, j != 2 — above 1/2 for j = 1, so the pair is not
 *   subdominant without the modification. Row of edge v-p_i (i >= 1), on q:
 *     q_j: (1 - s) T_ij + s (1/2 cos(2 pi i/k) [j = 0] + 1/k sin(2 pi i/k) sin(2 pi j/k))
 *   and v takes the rest of 1; the singular edge's midpoint is left as it is (the projection
 *   reproduces it: l = e_0). Every kept mode is 1/2 and (1 - s) lambda_1 < 1/2 for s > 1/3.
 * Concave corner petal, ring p_0 .. p_k, v-p_0 and v-p_k its singular edges, alpha the angle
 *   between them: theta = (2 pi - alpha)/k. The eigenvalue 1/2 holds x_i = cos(i theta),
 *   sin(i theta) (any values at p_0, p_k), left eigenvectors e_0 and e_k; the Dirichlet modes
 *   sin(j pi i/k) have 1/2 + (cos(j pi/k) - cos(theta))/4, above 1/2 for j = 1. The projection
 *   interpolates the two crease midpoints: P_i - v = (sin((k-i) theta) (E_0 - v) +
 *   sin(i theta) (E_k - v)) / sin(k theta). Row of edge v-p_i (0 < i < k), on q:
 *     q_j: (1 - s) T_ij + s / (2 sin(k theta)) (sin((k-i) theta) [j = 0] + sin(i theta) [j = k])
 *   (1 - s) lambda_1 < 1/2 holds for s > 1/3 at every k (003: s = 1/2 always suffices).
 * SD_YZ_FLAT_S = 3/4 satisfies all three conditions for every k (docs/DECISIONS.md 27, 28).
 * Where the edge's other end is also singular the petal rules of both ends are averaged (003:
 * "use the average of the conflicting positions"); each end's rule is complete (both stages)
 * before averaging. The other end's rule is 003 Fig. 4f with its gamma (rules.c, sdi_yz_rules), or
 * its own flattened rule.
 *
 * Only levels built with nonmanifold_surface = ying-zorin that have such petals at singular
 * vertices come here; the rows are few and built one by one.
 */
#include "internal.h"
#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>


void sdi_yzrows_free(sd_mem *m, sd_yzrows *y)
{
    sdi_free(m, y->off);
    sdi_free(m, y->col);
    sdi_free(m, y->w);
    sdi_free(m, y->ends);
    memset(y, 0, sizeof *y);
}

/* A (column, weight) accumulator for one row: entries are appended, then merged by column
 * (acc_merge), so a row costs O(n log n) whatever its petals' sizes. */
typedef struct entry {
    uint32_t col;
    double w;
} entry;
typedef struct acc {
    entry *e;
    uint32_t n, cap;
} acc;

static bool acc_add(sd_mem *m, acc *a, uint32_t c, double w)
{
    if (a->n == a->cap) {
        uint32_t cap = a->cap ? 2 * a->cap : 16;
        entry *ne = sdi_realloc(m, a->e, cap * sizeof *ne);
        if (!ne)
            return false;
        a->e = ne;
        a->cap = cap;
    }
    a->e[a->n++] = (entry){c, w};
    return true;
}

static int cmp_entry_col(const void *x, const void *y)
{
    uint32_t p = ((const entry *)x)->col, q = ((const entry *)y)->col;
    return p < q ? -1 : p > q;
}

/* Merge duplicate columns; the first two entries (the edge's ends) stay first. */
static void acc_merge(acc *a)
{
    qsort(a->e + 2, a->n - 2, sizeof *a->e, cmp_entry_col);
    uint32_t w = 2;
    for (uint32_t i = 2; i < a->n; i++) {
        entry x = a->e[i];
        if (x.col == a->e[0].col)
            a->e[0].w += x.w;
        else if (x.col == a->e[1].col)
            a->e[1].w += x.w;
        else if (w > 2 && a->e[w - 1].col == x.col)
            a->e[w - 1].w += x.w;
        else
            a->e[w++] = x;
    }
    a->n = w;
}

static inline uint32_t other_end(const sd_topo *t, uint32_t e, uint32_t v)
{
    return t->ev[e][0] == v ? t->ev[e][1] : t->ev[e][0];
}

enum { WALK_FAIL, WALK_CLOSED, WALK_SINGULAR };

/* From edge e0 at v into its face f, across the petal's inner edges (petals.c): out[0 .. *n)
 * the ring points passed (faces: scratch for the triangles entered). Ends back at e0
 * (WALK_CLOSED) or at a singular edge (WALK_SINGULAR, *last its other end); WALK_FAIL past cap. */
static int ring_walk(const sd_topo *t, const sdi_rel *ef, uint32_t v, uint32_t e0, uint32_t f,
                     uint32_t *out, uint32_t *faces, uint32_t cap, uint32_t *n, uint32_t *last)
{
    sdi_walk w = {faces, out, 0, cap};
    uint32_t end = sdi_petal_walk(t, ef, SDI_PETAL_YZ, v, e0, f, &w);
    *n = w.n;
    for (uint32_t i = 0; i < w.n; i++) /* the edges crossed, as their other ends */
        out[i] = other_end(t, out[i], v);
    if (end == UINT32_MAX)
        return WALK_FAIL;
    if (end == e0)
        return WALK_CLOSED;
    *last = other_end(t, end, v);
    return WALK_SINGULAR;
}

/* The ring of the petal of kind `kind` (SD_YZ_DISK, _DART, _CONCAVE) at v that holds the inner
 * edge e0, in order, e0 = v-ring[*at]: closed p_0 .. p_{k-1} (a disk starts at e0); a dart's and
 * an open petal's ring start at a singular edge's end, an open one ends at the other's, p_k.
 * Returns the petal's number of triangles k, or 0 if the petal is not of that kind. */
static uint32_t petal_ring(const sd_topo *t, const sdi_rel *ef, uint32_t v, uint32_t e0,
                           const uint32_t two[2], uint8_t kind, uint32_t *ring, uint32_t *tmp,
                           uint32_t *faces, uint32_t cap, uint32_t *at)
{
    uint32_t na, nb, la, lb;
    int wa = ring_walk(t, ef, v, e0, two[0], tmp, faces, cap, &na, &la);
    *at = 0;
    if (kind == SD_YZ_DISK) {
        if (wa != WALK_CLOSED || na + 1 > cap)
            return 0;
        ring[0] = other_end(t, e0, v);
        memcpy(ring + 1, tmp, na * sizeof *ring);
        return na + 1;
    }
    if (wa != WALK_SINGULAR || na + 3 > cap)
        return 0;
    ring[0] = la;
    for (uint32_t j = 0; j < na; j++)
        ring[1 + j] = tmp[na - 1 - j];
    ring[na + 1] = other_end(t, e0, v);
    int wb = ring_walk(t, ef, v, e0, two[1], ring + na + 2, faces, cap - na - 3, &nb, &lb);
    if (wb != WALK_SINGULAR || (la == lb) != (kind == SD_YZ_DART))
        return 0;
    uint32_t k = na + nb + 2;
    if (kind == SD_YZ_CONCAVE)
        ring[k] = lb;
    *at = na + 1;
    return k;
}

/* Add the row of edge v-ring[i] of a flattened petal of k triangles (end x: its kind, g, theta
 * and s) times `scale` to a: on q = p - v, (1 - s) T_ij + s P_ij, T the first stage (g at i,
 * 1/8 at i's ring neighbours: cyclic for a disk and a dart, p_0 .. p_k for a concave corner),
 * P the projection on the kept modes (the header); v takes the rest of 1. */
static bool flat_row(sd_mem *m, acc *a, uint32_t v, const uint32_t *ring, uint32_t k, uint32_t i,
                     const sd_yzend *x, double scale)
{
    const bool open = x->kind == SD_YZ_CONCAVE;
    double sum = 0;
    for (uint32_t j = 0; j < (open ? k + 1 : k); j++) {
        double w = sdi_mask_yz_flat(x, k, i, j); /* masks.c */
        sum += w;
        if (!acc_add(m, a, ring[j], scale * w))
            return false;
    }
    return acc_add(m, a, v, scale * (1 - sum));
}

bool sdi_yz_flat_rows(sd_mem *m, const sd_topo *t, const sdi_rel *ef, const sd_yzend (*end)[2],
                      uint8_t *er, sd_yzrows *y)
{
    const uint32_t ne = t->ne;
    memset(y, 0, sizeof *y);
    uint32_t nfd = 0;
    for (uint32_t e = 0; e < ne; e++)
        nfd += sdi_yz_flat(end[e][0].kind) || sdi_yz_flat(end[e][1].kind);
    if (!nfd)
        return true;
    bool ok = false;
    uint32_t *ring = NULL, *tmp = NULL, *faces = NULL;
    uint32_t cap = t->ntr + 2;
    acc a = {0};
    y->off = sdi_calloc(m, (size_t)ne + 1, sizeof *y->off);
    y->ends = sdi_alloc(m, ((size_t)ne + 1) * sizeof *y->ends);
    ring = sdi_alloc(m, (size_t)cap * sizeof *ring);
    tmp = sdi_alloc(m, (size_t)cap * sizeof *tmp);
    faces = sdi_alloc(m, (size_t)cap * sizeof *faces);
    if (!y->off || !y->ends || !ring || !tmp || !faces)
        goto out;
    /* two passes: count the ring columns of each row, then fill them */
    for (int pass = 0; pass < 2; pass++) {
        uint32_t row = 0;
        for (uint32_t e = 0; e < ne; e++) {
            if (!sdi_yz_flat(end[e][0].kind) && !sdi_yz_flat(end[e][1].kind))
                continue;
            uint32_t ends[2] = {t->ev[e][0], t->ev[e][1]};
            int sides = (end[e][0].kind != SD_YZ_NONE) + (end[e][1].kind != SD_YZ_NONE);
            uint8_t best = SD_YZ_CONCAVE;
            a.n = 0;
            if (!acc_add(m, &a, ends[0], 0) || !acc_add(m, &a, ends[1], 0))
                goto out;
            uint32_t two[2]; /* e's two triangles */
            bool fine = sdi_max_faces(t, ef, e, two) >= 2;
            for (int i = 0; i < 2 && fine; i++) {
                uint32_t v = ends[i], w = ends[1 - i], k, at = 0;
                const sd_yzend *x = &end[e][i];
                switch (x->kind) {
                case SD_YZ_DISK:
                case SD_YZ_DART:
                case SD_YZ_CONCAVE:
                    if (x->kind < best) /* the rule named: fixed disk, then dart, then concave */
                        best = x->kind;
                    k = petal_ring(t, ef, v, e, two, x->kind, ring, tmp, faces, cap, &at);
                    fine = k >= (x->kind == SD_YZ_CONCAVE ? 2u : 3u);
                    if (fine && !flat_row(m, &a, v, ring, k, at, x, 1.0 / sides))
                        goto out;
                    break;
                case SD_YZ_FIRST: { /* 003 Fig. 4f from this end */
                    sdi_yzmask y = sdi_mask_yz_petal(x->g);
                    if (!acc_add(m, &a, v, y.centre / sides) || !acc_add(m, &a, w, y.far / sides))
                        goto out;
                    for (int h = 0; h < 2; h++) { /* the opposite vertices */
                        const uint32_t *q = t->fv[two[h]];
                        uint32_t o = q[0] != v && q[0] != w ? q[0] : q[1] != v && q[1] != w ? q[1] : q[2];
                        if (!acc_add(m, &a, o, y.opposite / sides))
                            goto out;
                    }
                    break;
                }
                default:
                    break;
                }
            }
            acc_merge(&a);
            if (!fine) { /* not such a petal after all (not met in practice): the edge keeps the rule
                          * rules.c gave it without these rows */
                if (pass == 0)
                    y->off[e + 1] = UINT32_MAX;
                continue;
            }
            if (pass == 0) {
                er[e] = best == SD_YZ_DISK   ? SD_RULE_YZ_FIXED_DISK
                        : best == SD_YZ_DART ? SD_RULE_YZ_DART
                                             : SD_RULE_YZ_CONCAVE;
                y->off[e + 1] = a.n - 2;
            } else {
                uint32_t at = y->off[e];
                y->ends[e][0] = a.e[0].w;
                y->ends[e][1] = a.e[1].w;
                for (uint32_t i = 2; i < a.n; i++) {
                    y->col[at] = a.e[i].col;
                    y->w[at++] = a.e[i].w;
                }
#ifndef NDEBUG
                double sum = 0;
                for (uint32_t i = 0; i < a.n; i++)
                    sum += a.e[i].w;
                assert(fabs(sum - 1) < 1e-12); /* every row of S sums to 1 */
#endif
            }
            row++;
        }
        if (pass == 0) {
            for (uint32_t e = 0; e < ne; e++)
                y->off[e + 1] = (y->off[e + 1] == UINT32_MAX ? 0 : y->off[e + 1]) + y->off[e];
            y->col = sdi_alloc(m, ((size_t)y->off[ne] + 1) * sizeof *y->col);
            y->w = sdi_alloc(m, ((size_t)y->off[ne] + 1) * sizeof *y->w);
            if (!y->col || !y->w)
                goto out;
        }
        y->n = row;
    }
    ok = true;
out:
    sdi_free(m, faces);
    sdi_free(m, ring);
    sdi_free(m, tmp);
    sdi_free(m, a.e);
    if (!ok)
        sdi_yzrows_free(m, y);
    return ok;
}
