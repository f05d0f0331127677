/* yz.c — Ying-Zorin's fixed-disk rule (003 Sec. 2 and Appendix A): the edges of a closed petal at
 * a non-manifold vertex.
 *
 * A closed petal (no singular edge) at a complex singular vertex v is a disk of k triangles
 * around v; v itself is a corner, fixed. Its edge points take two stages (003 Sec. 2):
 *   1. Loop's edge rule inside the petal (theta = pi/3 in Fig. 4f):
 *        E_j = 3/8 v + 3/8 p_j + 1/8 (p_{j-1} + p_{j+1}),   p_0 .. p_{k-1} the petal's ring in order;
 *   2. the flatness modification p <- (1 - s) p + s (a_0 x^0 + a_1 x^1 + a_2 x^2), with the
 *      fixed-disk eigenvectors of Appendix A: a_0 = v (l^0 = the centre), x^1_i = sin(2 pi i/k),
 *      x^2_i = cos(2 pi i/k), l^{1,2}_i = 2/k sin, 2/k cos. For the edge point i this is
 *        (1 - s) E_i + s (v + 2/k sum_j cos(2 pi (i - j)/k) E_j),
 *      and, E_j written out, (cos addition) the row of edge v-p_0:
 *        v:   (1 - s) 3/8 + s
 *        p_j: (1 - s) Loop_j + s 2/k lambda cos(2 pi j/k),   lambda = 3/8 + cos(2 pi/k)/4,
 *      Loop_j = 3/8 at j = 0, 1/8 at j = 1 and k - 1, else 0. The row sums to 1 (sum cos = 0).
 * s (003 leaves it open for this rule): the petal's matrix has eigenvalues 1, 5/8 (the "cone"
 * mode, all ring points alike), lambda_j = 3/8 + cos(2 pi j/k)/4; after the modification the cone
 * and j >= 2 modes are scaled by 1 - s, so lambda_1 is subdominant iff (1 - s) 5/8 < lambda_1,
 * i.e. s > (2 - 2 cos(2 pi/k))/5 (3/5 at k = 3). SD_YZ_FLAT_S = 3/4 satisfies it for every k >= 3
 * (docs/DECISIONS.md 27).
 * Where the edge's other end is also singular the petal rules of both ends are averaged (003:
 * "use the average of the conflicting positions"); each end's rule is complete (both stages)
 * before averaging. The other end's rule is 003 Fig. 4f with its gamma (rules.c, yz_gammas), or
 * its own fixed disk.
 *
 * Only levels built with nonmanifold_surface = ying-zorin that have closed petals at singular
 * vertices come here; the rows are few and built one by one.
 */
#include "internal.h"
#include <assert.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define SD_YZ_FLAT_S 0.75

void sd_yzrows_free(sd_mem *m, sd_yzrows *y)
{
    sd_free(m, y->off);
    sd_free(m, y->col);
    sd_free(m, y->w);
    sd_free(m, y->ends);
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
        entry *ne = sd_realloc(m, a->e, cap * sizeof *ne);
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

/* The ring of the closed petal at v that holds edge e0, starting at e0: ring[j] = p_j. The
 * faces of each petal edge are efc[e][0..1]. Returns k, or 0 if the walk does not close (not a
 * disk: left to the first stage). */
static uint32_t petal_ring(const sd_topo *t, const uint32_t (*efc)[2], uint32_t v, uint32_t e0,
                           uint32_t *ring, uint32_t cap)
{
    uint32_t e = e0, f = efc[e0][0], k = 0;
    ring[k++] = other_end(t, e0, v);
    for (;;) {
        uint32_t next = UINT32_MAX;
        for (int j = 0; j < 3; j++) {
            uint32_t x = t->fe[f][j];
            if (x != e && (t->ev[x][0] == v || t->ev[x][1] == v))
                next = x;
        }
        if (next == UINT32_MAX || efc[next][1] == UINT32_MAX)
            return 0;
        if (next == e0)
            return k;
        if (k == cap)
            return 0;
        ring[k++] = other_end(t, next, v);
        f = efc[next][0] == f ? efc[next][1] : efc[next][0];
        e = next;
    }
}

/* Add the fixed-disk row of edge v-ring[0] (petal of k) times `scale` to a. */
static bool fixed_disk_row(sd_mem *m, acc *a, uint32_t v, const uint32_t *ring, uint32_t k,
                           double scale)
{
    const double s = SD_YZ_FLAT_S, lam = 3.0 / 8.0 + cos(2 * M_PI / k) / 4;
    if (!acc_add(m, a, v, scale * ((1 - s) * 3.0 / 8.0 + s)))
        return false;
    for (uint32_t j = 0; j < k; j++) {
        double loop = j == 0 ? 3.0 / 8.0 : (j == 1 || j == k - 1) ? 1.0 / 8.0 : 0.0;
        double w = (1 - s) * loop + s * 2.0 / k * lam * cos(2 * M_PI * j / k);
        if (!acc_add(m, a, ring[j], scale * w))
            return false;
    }
    return true;
}

bool sd_yz_fixed_disks(sd_mem *m, const sd_topo *t, const double (*gam)[2], uint8_t *er,
                       sd_yzrows *y)
{
    const uint32_t ne = t->ne;
    memset(y, 0, sizeof *y);
    uint32_t nfd = 0;
    for (uint32_t e = 0; e < ne; e++)
        nfd += gam[e][0] == SD_YZ_DISK || gam[e][1] == SD_YZ_DISK;
    if (!nfd)
        return true;
    bool ok = false;
    uint32_t (*efc)[2] = sd_alloc(m, ((size_t)ne + 1) * sizeof *efc), *ring = NULL;
    uint32_t cap = t->ntr + 1;
    acc a = {0};
    y->off = sd_calloc(m, (size_t)ne + 1, sizeof *y->off);
    y->ends = sd_alloc(m, ((size_t)ne + 1) * sizeof *y->ends);
    ring = sd_alloc(m, (size_t)cap * sizeof *ring);
    if (!efc || !y->off || !y->ends || !ring)
        goto out;
    for (uint32_t e = 0; e < ne; e++)
        efc[e][0] = efc[e][1] = UINT32_MAX;
    for (uint32_t i = 0; i < t->ntr; i++) {
        uint32_t f = sd_tr(t, i);
        for (int j = 0; j < 3; j++) {
            uint32_t e = t->fe[f][j];
            if (gam[e][0] != SD_YZ_DISK && gam[e][1] != SD_YZ_DISK)
                continue;
            if (efc[e][0] == UINT32_MAX)
                efc[e][0] = f;
            else
                efc[e][1] = f;
        }
    }
    /* two passes: count the ring columns of each row, then fill them */
    for (int pass = 0; pass < 2; pass++) {
        uint32_t row = 0;
        for (uint32_t e = 0; e < ne; e++) {
            if (gam[e][0] != SD_YZ_DISK && gam[e][1] != SD_YZ_DISK)
                continue;
            uint32_t ends[2] = {t->ev[e][0], t->ev[e][1]};
            int sides = (gam[e][0] != -1) + (gam[e][1] != -1);
            a.n = 0;
            if (!acc_add(m, &a, ends[0], 0) || !acc_add(m, &a, ends[1], 0))
                goto out;
            bool fine = true;
            for (int i = 0; i < 2 && fine; i++) {
                uint32_t v = ends[i], w = ends[1 - i];
                if (gam[e][i] == SD_YZ_DISK) {
                    uint32_t k = petal_ring(t, (const uint32_t(*)[2])efc, v, e, ring, cap);
                    fine = k >= 3;
                    if (fine && !fixed_disk_row(m, &a, v, ring, k, 1.0 / sides))
                        goto out;
                } else if (gam[e][i] >= 0) { /* 003 Fig. 4f from this end */
                    double g = gam[e][i];
                    if (!acc_add(m, &a, v, (0.75 - g) / sides) || !acc_add(m, &a, w, g / sides))
                        goto out;
                    for (int h = 0; h < 2; h++) { /* the opposite vertices */
                        const uint32_t *q = t->fv[efc[e][h]];
                        uint32_t o = q[0] != v && q[0] != w ? q[0] : q[1] != v && q[1] != w ? q[1] : q[2];
                        if (!acc_add(m, &a, o, 0.125 / sides))
                            goto out;
                    }
                }
            }
            acc_merge(&a);
            if (!fine) { /* not a disk after all: leave the edge to the first stage */
                if (pass == 0)
                    y->off[e + 1] = UINT32_MAX;
                continue;
            }
            if (pass == 0) {
                er[e] = SD_RULE_YZ_FIXED_DISK;
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
            y->col = sd_alloc(m, ((size_t)y->off[ne] + 1) * sizeof *y->col);
            y->w = sd_alloc(m, ((size_t)y->off[ne] + 1) * sizeof *y->w);
            if (!y->col || !y->w)
                goto out;
        }
        y->n = row;
    }
    ok = true;
out:
    sd_free(m, efc);
    sd_free(m, ring);
    sd_free(m, a.e);
    if (!ok)
        sd_yzrows_free(m, y);
    return ok;
}
