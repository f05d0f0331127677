/* embed.c — models embedded in the subdivision solid: the core of free-form deformation
 * (004 Sec. 5.1, eq. 13).
 *
 * A model vertex is located in a solid cell of level L and bound to its 4 vertices by
 * barycentric coordinates; afterwards it is the same combination of those vertices' current
 * positions, so it follows the solid as control points move (an edit changes a level's
 * positions in place and keeps its topology, so the binding stays valid). Barycentric
 * coordinates reproduce affine functions, so an affine map of the control points (which
 * subdivision commutes with) maps the model by the same map, and a model bound without any
 * edit sits exactly where it was given.
 *
 * Cells: a level's tetrahedra, then each octahedron as the 4 tetrahedra around its major
 * diagonal (004 eq. 13), split the way the outputs write it (sd_octa_tet): octahedron
 * (p,q,a,a2,b,b2) with equator cycle a,b,a2,b2 gives (q,p,a,b), (q,p,b,a2), (q,p,a2,b2),
 * (q,p,b2,a), positive like the octahedron. Cell T + 4o + k is octahedron o's k-th.
 *
 * Locating is a uniform grid over the level's bounding box, in coordinates quantized to 16 bits
 * a side: each cell is listed, in increasing index, in every bucket its (widened, quantized) box
 * meets; buckets are about the mean size of a cell's box (from a sample of cells), so a cell is
 * in ~8 of them and a bucket lists ~70 (a tetrahedron's box is ~10 times its volume). Model
 * vertices are taken in bucket order (a counting sort) so that consecutive vertices test the
 * same cells while they are in cache; each tests its bucket's cells in increasing index — the
 * quantized box first (12 bytes a cell, one branch), then the exact test — and the first that
 * holds it wins, so a point on a shared face, or in overlapping cells, goes to the lowest index.
 * "Holds" means: within 1e-12 of the cell's longest edge of every face plane (all barycentric
 * coordinates >= -1e-12 settles it at once, since a height is at most the longest edge; a
 * coordinate below that is checked against the face's true height only when a cheap bound does
 * not reject it). Boxes are widened by 1e-6 of the longest
 * edge so that such points are in the cell's buckets (exact for cells whose corners are not
 * sharper than that).
 * A vertex in no cell is, by mode, refused, fixed (kept at its rest position, stored in place of
 * its weights), or bound to the nearest cell: searched in the grid (shells of buckets around
 * the vertex's) while each vertex finds it within its share of the work, through a tree of the
 * boxes of the cells at the boundary from the first one that does not (a vertex far from a
 * curved solid) on; the distance is the exact point-tetrahedron distance (closest point on its
 * faces), skipped for cells whose box is farther than the best so far; the lowest index wins
 * among cells as near within 1e-12 of the cell's longest edge (IN_TOL, as on shared faces). Its
 * coordinates then extrapolate.
 *
 * Bindings are stored by slot, the model's vertices in bucket order, so that the vertices an edit
 * moves (near each other in space) are near each other in memory whatever the model's order.
 * Updates: at bind time the inverse map (level vertex -> slots bound to it, CSR, each row
 * ascending) is built, so the model vertices an edit moves are found in time proportional to
 * their number; a per-slot stamp array dedupes them (a counter, not a clear per call), they are
 * recomputed in slot order, and a radix sort (insertion sort when few) returns their model
 * indices ascending.
 *
 * Memory: the embedding's own sd_mem (allocator and cap as sd_options'), counting the locating
 * grid while it exists (~16 bytes a cell + 4 per entry, ~50 per cell in all) and, with vertices
 * outside in "nearest", the tree of boxes (~36 bytes a cell with a boundary vertex); sd_embed_memory
 * is what stays (80 bytes per model vertex plus 4 per level vertex).
 */
#include "internal.h"
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define IN_TOL 1e-12   /* distance to a face plane, relative to the cell's longest edge */
#define BOX_TOL 1e-6   /* box widening, relative to the cell's longest edge */
#define NONE UINT32_MAX
/* The nearest-cell searches of the vertices outside ("nearest") look at most at this many grid
 * buckets and entries, tree nodes and cells in all, per vertex outside and once. A vertex near
 * the solid takes 200 to 2000 in the grid, and this is also what one may take there before the
 * tree takes over; in the tree a vertex near or far takes tens; one that many cells are almost
 * equally near (the centre of a hollow sphere) takes them all, which this bounds */
#define NEAREST_WORK_PER_VERTEX 2048u
#define NEAREST_WORK_BASE (1u << 24)

struct sd_embedding {
    sd_mem mem;
    size_t n;
    uint32_t nlv;       /* level vertices at bind time */
    /* bindings are stored by slot, model vertices in bucket order (so that the vertices an edit
     * moves, which are near each other, are mostly near each other in memory too) */
    uint32_t *model;    /* n: slot -> model vertex */
    uint32_t *slot;     /* n: model vertex -> slot */
    uint32_t *idx;      /* 4 per slot: the cell's vertices, or idx[4s] = NONE: fixed */
    double *w;          /* 4 per slot: weights, or the rest position (3) of a fixed vertex */
    uint32_t *rowptr;   /* nlv + 1: level vertex -> slots */
    uint32_t *col;
    uint32_t *stamp;    /* per slot: the last update that listed it */
    uint32_t *scratch;  /* n: the radix sort's other half */
    uint32_t epoch;
};

/* ---- cells ------------------------------------------------------------------------------- */

typedef struct cells {
    const sd_level *lv;
    const double *x;
    uint32_t ntet, nc, nv;
} cells;

static void cell_verts(const cells *C, uint32_t c, uint32_t v[4])
{
    if (c < C->ntet) {
        sd_level_cell(C->lv, SD_CELL_TETRA, c, v);
        return;
    }
    uint32_t o[6];
    sd_level_cell(C->lv, SD_CELL_OCTA, (c - C->ntet) >> 2, o);
    sd_octa_tet(o, (int)((c - C->ntet) & 3), v);
}

static inline void sub3(const double *a, const double *b, double *r)
{
    r[0] = a[0] - b[0];
    r[1] = a[1] - b[1];
    r[2] = a[2] - b[2];
}
static inline double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
static inline void cross3(const double *a, const double *b, double *r)
{
    r[0] = a[1] * b[2] - a[2] * b[1];
    r[1] = a[2] * b[0] - a[0] * b[2];
    r[2] = a[0] * b[1] - a[1] * b[0];
}

static double longest_edge(const double *const P[4])
{
    double m = 0;
    for (int i = 0; i < 4; i++)
        for (int j = i + 1; j < 4; j++) {
            double d[3];
            sub3(P[i], P[j], d);
            double l = dot3(d, d);
            m = l > m ? l : m;
        }
    return sqrt(m);
}

/* Barycentric coordinates of p in tetrahedron P (Cramer on the 3x3 system of the edges from
 * P[0]); false for a degenerate one. */
static bool bary(const double *const P[4], const double *p, double lam[4])
{
    double e1[3], e2[3], e3[3], d[3], n[3];
    sub3(P[1], P[0], e1);
    sub3(P[2], P[0], e2);
    sub3(P[3], P[0], e3);
    sub3(p, P[0], d);
    cross3(e2, e3, n);
    double det = dot3(e1, n);
    if (!(det != 0) || !isfinite(det))
        return false;
    double dn[3], nd[3];
    cross3(d, e3, dn);
    cross3(e2, d, nd);
    lam[1] = dot3(d, n) / det;
    lam[2] = dot3(e1, dn) / det;
    lam[3] = dot3(e1, nd) / det;
    lam[0] = 1 - lam[1] - lam[2] - lam[3];
    return true;
}

/* Does tetrahedron P (longest edge L) hold p, within IN_TOL L of each face plane? lam gets the
 * coordinates. The distance beyond face i is -lam_i h_i, h_i = |det| / (2 A_i) <= L. */
static bool holds(const double *const P[4], double L, const double *p, double lam[4])
{
    double e1[3], e2[3], e3[3], d[3], n[3];
    sub3(P[1], P[0], e1);
    sub3(P[2], P[0], e2);
    sub3(P[3], P[0], e3);
    sub3(p, P[0], d);
    cross3(e2, e3, n);
    double det = dot3(e1, n);
    if (!(det != 0))
        return false;
    const double ad = fabs(det), tl = IN_TOL * L;
    /* distance_i >= -lam_i |det| / L^2 (a face's area is at most L^2 / 2): reject on that */
    const double cut = tl * L * L;
    lam[1] = dot3(d, n) / det;
    if (-lam[1] * ad > cut)
        return false;
    double dn[3], nd[3];
    cross3(d, e3, dn);
    lam[2] = dot3(e1, dn) / det;
    if (-lam[2] * ad > cut)
        return false;
    cross3(e2, d, nd);
    lam[3] = dot3(e1, nd) / det;
    if (-lam[3] * ad > cut)
        return false;
    lam[0] = 1 - lam[1] - lam[2] - lam[3];
    if (-lam[0] * ad > cut)
        return false;
    for (int i = 0; i < 4; i++) {
        if (lam[i] >= -IN_TOL)
            continue;
        const double *f[3];
        for (int j = 0, k = 0; j < 4; j++)
            if (j != i)
                f[k++] = P[j];
        double u[3], v[3], c[3];
        sub3(f[1], f[0], u);
        sub3(f[2], f[0], v);
        cross3(u, v, c);
        double area2 = sqrt(dot3(c, c)); /* twice the face's area */
        if (-lam[i] * ad > tl * area2)
            return false;
    }
    return true;
}

/* Squared distance from p to segment xy, the same bits whichever way round and whichever
 * triangle it is an edge of (its ends taken in lexicographic order of their coordinates): cells
 * that share the edge nearest to p are then exactly as near, and the lowest index wins. */
static double seg_dist2(const double *p, const double *x, const double *y)
{
    if (x[0] > y[0] || (x[0] == y[0] && (x[1] > y[1] || (x[1] == y[1] && x[2] > y[2])))) {
        const double *t = x;
        x = y;
        y = t;
    }
    double e[3], xp[3], q[3], d[3];
    sub3(y, x, e);
    sub3(p, x, xp);
    double ee = dot3(e, e), t = ee > 0 ? dot3(e, xp) / ee : 0;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    for (int k = 0; k < 3; k++)
        q[k] = x[k] + t * e[k];
    sub3(p, q, d);
    return dot3(d, d);
}

/* Closest point to p on triangle abc, squared distance (Ericson, Real-Time Collision Detection
 * 5.1.5: Voronoi regions of the vertices, edges and face; an edge's distance by seg_dist2). */
static double tri_dist2(const double *p, const double *a, const double *b, const double *c)
{
    double ab[3], ac[3], ap[3], q[3];
    sub3(b, a, ab);
    sub3(c, a, ac);
    sub3(p, a, ap);
    double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
    if (d1 <= 0 && d2 <= 0) {
        memcpy(q, a, sizeof q);
        goto done;
    }
    double bp[3];
    sub3(p, b, bp);
    double d3 = dot3(ab, bp), d4 = dot3(ac, bp);
    if (d3 >= 0 && d4 <= d3) {
        memcpy(q, b, sizeof q);
        goto done;
    }
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0)
        return seg_dist2(p, a, b);
    double cp[3];
    sub3(p, c, cp);
    double d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    if (d6 >= 0 && d5 <= d6) {
        memcpy(q, c, sizeof q);
        goto done;
    }
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0)
        return seg_dist2(p, a, c);
    double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return seg_dist2(p, b, c);
    double den = 1 / (va + vb + vc), v = vb * den, w = vc * den;
    for (int k = 0; k < 3; k++)
        q[k] = a[k] + ab[k] * v + ac[k] * w;
done:;
    double d[3];
    sub3(p, q, d);
    return dot3(d, d);
}

/* Squared distance from p to tetrahedron P: 0 inside, else to the nearest face. */
static double tet_dist2(const double *const P[4], const double *p)
{
    double lam[4];
    if (bary(P, p, lam) && lam[0] >= 0 && lam[1] >= 0 && lam[2] >= 0 && lam[3] >= 0)
        return 0;
    double best = DBL_MAX;
    for (int i = 0; i < 4; i++) {
        const double *f[3];
        for (int j = 0, k = 0; j < 4; j++)
            if (j != i)
                f[k++] = P[j];
        double d = tri_dist2(p, f[0], f[1], f[2]);
        best = d < best ? d : best;
    }
    return best;
}

/* ---- the grid ------------------------------------------------------------------------------ */

/* Coordinates are quantized to 16 bits a side over the cells' bounding box (floor, clamped);
 * each cell keeps its widened box so quantized (min and max floored: a point of the box
 * quantizes inside it, floor being monotone), a cheap test before the exact one. Buckets are
 * ranges of quantized values, bucket (q * dim) >> 16 on each axis, so a point's bucket lies in
 * the bucket range of every box holding it. */
#define QBITS 16
#define QMAX 65535u

typedef struct grid {
    double lo[3], qs[3], quantum[3];
    uint32_t dim[3];
    size_t nb;
    uint32_t *start;    /* nb + 1 */
    uint32_t *cell;     /* the cells of bucket b: cell[start[b] .. start[b+1]) */
    float *len;         /* per cell: its longest edge, rounded up */
    double maxlen;      /* the largest of them */
    uint16_t (*box)[6]; /* per cell: its widened box, quantized (min xyz, max xyz) */
} grid;

static inline uint32_t quant(const grid *g, int a, double x)
{
    double t = floor((x - g->lo[a]) * g->qs[a]);
    if (!(t > 0))
        return 0;
    return t >= QMAX ? QMAX : (uint32_t)t;
}

static inline uint32_t axis_of(const grid *g, int a, uint32_t q)
{
    return (uint32_t)(((uint64_t)q * g->dim[a]) >> QBITS);
}

static inline size_t bucket_q(const grid *g, const uint32_t q[3])
{
    return ((size_t)axis_of(g, 2, q[2]) * g->dim[1] + axis_of(g, 1, q[1])) * g->dim[0] +
           axis_of(g, 0, q[0]);
}

static void cell_pts(const cells *C, uint32_t c, const double *P[4])
{
    uint32_t v[4];
    cell_verts(C, c, v);
    for (int k = 0; k < 4; k++)
        P[k] = C->x + 3 * (size_t)v[k];
}

static void grid_free(sd_mem *m, grid *g)
{
    sdi_free(m, g->start);
    sdi_free(m, g->cell);
    sdi_free(m, g->len);
    sdi_free(m, g->box);
}

static sd_result grid_build(sd_mem *m, const cells *C, grid *g, sd_error *err)
{
    memset(g, 0, sizeof *g);
    g->len = sdi_alloc(m, (size_t)C->nc * sizeof *g->len);
    g->box = g->len ? sdi_alloc(m, (size_t)C->nc * sizeof *g->box) : NULL;
    if (!g->box)
        return sdi_fail_nomem(err, m);
    /* the grid spans the level's vertices (those of any part: a far curve only makes it
     * coarser); the mean box extent of the cells, from a sample of at most 2^16 */
    double lo[3] = {DBL_MAX, DBL_MAX, DBL_MAX}, hi[3] = {-DBL_MAX, -DBL_MAX, -DBL_MAX}, ext = 0;
    for (uint32_t v = 0; v < C->nv; v++)
        for (int a = 0; a < 3; a++) {
            double x = C->x[3 * (size_t)v + a];
            lo[a] = x < lo[a] ? x : lo[a];
            hi[a] = x > hi[a] ? x : hi[a];
        }
    const uint32_t stride = C->nc > 65536 ? C->nc / 65536 : 1;
    uint32_t nsample = 0;
    for (uint32_t c = 0; c < C->nc; c += stride, nsample++) {
        const double *P[4];
        cell_pts(C, c, P);
        for (int a = 0; a < 3; a++) {
            double l = fmin(fmin(P[0][a], P[1][a]), fmin(P[2][a], P[3][a]));
            double h = fmax(fmax(P[0][a], P[1][a]), fmax(P[2][a], P[3][a]));
            ext += h - l;
        }
    }
    /* buckets about the mean box extent (a cell then meets ~8), at most ~2 per cell and 2048 a side */
    double s = ext / (3.0 * nsample), span[3];
    for (int a = 0; a < 3; a++) {
        span[a] = hi[a] - lo[a];
        double pad = 1e-6 * span[a] + 1e-12 * (fabs(lo[a]) + fabs(hi[a])) + DBL_MIN;
        lo[a] -= pad;
        span[a] += 2 * pad;
        g->lo[a] = lo[a];
        g->qs[a] = (QMAX + 1.0) / span[a];
        g->quantum[a] = span[a] / (QMAX + 1.0);
    }
    for (;;) {
        double nb = 1;
        for (int a = 0; a < 3; a++) {
            double d = s > 0 ? ceil(span[a] / s) : 1;
            g->dim[a] = d < 1 ? 1 : d > 2048 ? 2048 : (uint32_t)d;
            nb *= g->dim[a];
        }
        if ((nb <= 2.0 * C->nc + 8 && nb < UINT32_MAX) || !(s > 0))
            break;
        s *= 1.25;
    }
    g->nb = (size_t)g->dim[0] * g->dim[1] * g->dim[2];
    g->start = sdi_calloc(m, g->nb + 1, sizeof *g->start);
    if (!g->start)
        return sdi_fail_nomem(err, m);
    /* pass 1: the longest edges, the quantized boxes and the entries per bucket; pass 2: the
     * entries, cells in increasing order */
    uint64_t total = 0;
    for (int pass = 0; pass < 2; pass++) {
        for (uint32_t c = 0; c < C->nc; c++) {
            uint16_t *q = g->box[c];
            if (pass == 0) {
                const double *P[4];
                cell_pts(C, c, P);
                double L = longest_edge(P);
                float f = (float)L;
                g->len[c] = (double)f < L ? nextafterf(f, FLT_MAX) : f;
                g->maxlen = g->len[c] > g->maxlen ? g->len[c] : g->maxlen;
                double pad = BOX_TOL * g->len[c];
                for (int a = 0; a < 3; a++) {
                    double l = P[0][a], h = P[0][a];
                    for (int k = 1; k < 4; k++) {
                        l = P[k][a] < l ? P[k][a] : l;
                        h = P[k][a] > h ? P[k][a] : h;
                    }
                    q[a] = (uint16_t)quant(g, a, l - pad);
                    q[3 + a] = (uint16_t)quant(g, a, h + pad);
                }
            }
            uint32_t i0[3], i1[3];
            for (int a = 0; a < 3; a++) {
                i0[a] = axis_of(g, a, q[a]);
                i1[a] = axis_of(g, a, q[3 + a]);
            }
            for (uint32_t z = i0[2]; z <= i1[2]; z++)
                for (uint32_t y = i0[1]; y <= i1[1]; y++) {
                    size_t row = ((size_t)z * g->dim[1] + y) * g->dim[0];
                    for (uint32_t x = i0[0]; x <= i1[0]; x++) {
                        if (pass == 0)
                            g->start[row + x + 1]++;
                        else
                            g->cell[g->start[row + x]++] = c;
                    }
                    if (pass == 0)
                        total += i1[0] - i0[0] + 1;
                }
        }
        if (pass == 0) {
            if (total >= UINT32_MAX)
                return sdi_fail(err, SD_ERR_LIMIT, -1, -1,
                                "the locating grid would hold %llu cell entries (at most %u)",
                                (unsigned long long)total, UINT32_MAX - 1);
            for (size_t b = 0; b < g->nb; b++)
                g->start[b + 1] += g->start[b];
            g->cell = sdi_alloc(m, (size_t)total * sizeof *g->cell);
            if (!g->cell)
                return sdi_fail_nomem(err, m);
        }
    }
    /* pass 2 advanced each start to the next bucket's: shift back */
    memmove(g->start + 1, g->start, g->nb * sizeof *g->start);
    g->start[0] = 0;
    return SD_OK;
}

static inline bool box_has(const uint16_t b[6], const uint32_t q[3])
{
    /* one branch: q - min <= max - min, unsigned, fails below min too */
    return ((q[0] - b[0] <= (uint32_t)(b[3] - b[0])) & (q[1] - b[1] <= (uint32_t)(b[4] - b[1])) &
            (q[2] - b[2] <= (uint32_t)(b[5] - b[2]))) != 0;
}

/* The first cell of p's bucket that holds p (NONE if none), its coordinates in lam. */
static uint32_t locate(const cells *C, const grid *g, const uint32_t q[3], const double *p,
                       double lam[4])
{
    size_t b = bucket_q(g, q);
    for (uint32_t j = g->start[b]; j < g->start[b + 1]; j++) {
        uint32_t c = g->cell[j];
        if (!box_has(g->box[c], q))
            continue;
        const double *P[4];
        cell_pts(C, c, P);
        if (holds(P, g->len[c], p, lam))
            return c;
    }
    return NONE;
}

/* A lower bound on the squared distance from p to cell c (its quantized box, one quantum wider
 * on each side against rounding): a cheap test before the exact distance. */
static double box_dist2(const grid *g, uint32_t c, const double *p)
{
    double s = 0;
    for (int a = 0; a < 3; a++) {
        double l = g->lo[a] + ((double)g->box[c][a] - 1) * g->quantum[a];
        double h = g->lo[a] + ((double)g->box[c][3 + a] + 2) * g->quantum[a];
        double d = p[a] < l ? l - p[a] : p[a] > h ? p[a] - h : 0;
        s += d * d;
    }
    return s;
}

/* Cell c as a candidate nearest to p: the best so far (*best, squared, and *bc) if nearer, or
 * as near with a lower index. "As near" is within IN_TOL of the cell's longest edge in distance,
 * as for points on shared faces: a nearest point on an edge or a vertex is reached through the
 * interior of a face for one cell and through the edge for another when p lies on the side of
 * the edge's (vertex's) region, the same distance but for rounding. Its quantized box first, a
 * cheap bound (widened by BOX_TOL, so a cell as near as the best is never skipped by it). */
static inline void consider(const cells *C, const grid *g, const double *p, uint32_t c,
                            double *best, uint32_t *bc)
{
    if (box_dist2(g, c, p) > *best)
        return;
    const double *P[4];
    cell_pts(C, c, P);
    double q = tet_dist2(P, p);
    if (*bc == NONE) {
        *best = q;
        *bc = c;
        return;
    }
    double tol = IN_TOL * g->len[c], d = sqrt(q), db = sqrt(*best);
    if (d < db - tol) { /* nearer */
        *best = q;
        *bc = c;
    } else if (d <= db + tol) { /* as near */
        *bc = c < *bc ? c : *bc;
        *best = q < *best ? q : *best;
    }
}

/* The nearest cell to p (lowest index among equals) by the grid: shells of buckets around p's
 * until no unexplored bucket can be nearer than the best cell. Each bucket looked at takes one
 * unit of *work and one per entry; NONE when it runs out first. Quick for a vertex near the
 * solid; one far from a curved boundary would look at most of the grid, so the bind gives it
 * a small allowance and goes to the tree (below) when it runs out. */
static uint32_t nearest_grid(const cells *C, const grid *g, const double *p, uint64_t *work)
{
    int64_t b[3], d[3];
    double out2 = 0, out[3]; /* how far p is outside the grid's box, per axis */
    for (int a = 0; a < 3; a++) {
        b[a] = axis_of(g, a, quant(g, a, p[a]));
        d[a] = g->dim[a];
        double l = g->lo[a], h = g->lo[a] + (QMAX + 1.0) * g->quantum[a];
        out[a] = p[a] < l ? l - p[a] : p[a] > h ? p[a] - h : 0;
        out2 += out[a] * out[a];
    }
    double best = DBL_MAX;
    uint32_t bc = NONE;
    for (int64_t r = 0;; r++) {
        int64_t l[3], h[3];
        for (int a = 0; a < 3; a++) {
            l[a] = b[a] - r < 0 ? 0 : b[a] - r;
            h[a] = b[a] + r >= d[a] ? d[a] - 1 : b[a] + r;
        }
        for (int64_t z = l[2]; z <= h[2]; z++)
            for (int64_t y = l[1]; y <= h[1]; y++) {
                bool edge = llabs(z - b[2]) == r || llabs(y - b[1]) == r;
                for (int64_t x = l[0]; x <= h[0]; x++) {
                    if (!edge && llabs(x - b[0]) != r) { /* inside the shell: jump across */
                        if (x < b[0] + r)
                            x = b[0] + r - 1;
                        continue;
                    }
                    size_t k = ((size_t)z * g->dim[1] + (size_t)y) * g->dim[0] + (size_t)x;
                    uint64_t cost = (uint64_t)(g->start[k + 1] - g->start[k]) + 1; /* an empty
                                                                     * bucket costs a look too */
                    if (cost > *work)
                        return NONE;
                    *work -= cost;
                    for (uint32_t j = g->start[k]; j < g->start[k + 1]; j++)
                        consider(C, g, p, g->cell[j], &best, &bc);
                }
            }
        /* what the buckets beyond the shell can offer (squared): a point there is beyond the
         * shell along some axis a — the gap to the first bucket past it (bucket i starts at
         * quantized value ceil(i 2^16 / dim)), less a quantum for rounding — and inside the
         * grid's box along the others, so at least as far as p is outside it along those */
        double bound = DBL_MAX;
        bool more = false;
        for (int a = 0; a < 3; a++) {
            double rest = out2 - out[a] * out[a];
            if (b[a] + r + 1 < d[a]) {
                double q0 = ceil((double)(b[a] + r + 1) * (QMAX + 1.0) / (double)d[a]) - 1;
                double e = g->lo[a] + q0 * g->quantum[a] - p[a];
                e = e > 0 ? e : 0;
                bound = fmin(bound, e * e + rest);
                more = true;
            }
            if (b[a] - r - 1 >= 0) {
                double q1 = ceil((double)(b[a] - r) * (QMAX + 1.0) / (double)d[a]) + 1;
                double e = p[a] - (g->lo[a] + q1 * g->quantum[a]);
                e = e > 0 ? e : 0;
                bound = fmin(bound, e * e + rest);
                more = true;
            }
        }
        if (!more || (bc != NONE && best < bound))
            return bc;
    }
}

/* ---- the nearest cell: a bounding-volume tree ---------------------------------------------- */

/* For a vertex outside every cell ("nearest"): a tree of boxes over the cells (median splits of
 * the cells' centroids along the widest axis, leaves of at most 4 cells; the boxes in float,
 * rounded outward), searched depth first, nearer child first, skipping a subtree whose box is
 * farther than the best cell so far (with a relative slack of 1e-12 for rounding, and IN_TOL of
 * the longest cell edge, the tolerance of "as near" in consider(), so every cell as near as the
 * best one is tested and the lowest index among equals wins, whatever the order of the search). The distance to a box bounds the distance to its cells from below, so the
 * search is exact; far from the solid only the cells whose boxes reach toward the vertex are
 * looked at. ~36 bytes a cell of the tree, made only when a vertex outside needs it. */
typedef struct bnode {
    float lo[3], hi[3];
    uint32_t first, n;   /* a leaf: cells ids[first .. first + n); n = 0: children node + 1 and
                          * node `first` */
} bnode;

typedef struct bvh {
    bnode *node;
    uint32_t nnode, nids;
    uint32_t *ids;
    float (*cen)[3];     /* while building: the centroid of the cell ids[i] */
} bvh;

static inline float f_down(double x)
{
    float f = (float)x;
    return (double)f > x ? nextafterf(f, -FLT_MAX) : f;
}

static inline float f_up(double x)
{
    float f = (float)x;
    return (double)f < x ? nextafterf(f, FLT_MAX) : f;
}

static void bvh_free(sd_mem *m, bvh *b)
{
    sdi_free(m, b->node);
    sdi_free(m, b->ids);
    sdi_free(m, b->cen);
    memset(b, 0, sizeof *b);
}

/* Reorder ids[lo, hi) so that ids[k] has the k-th smallest centroid along axis a, the smaller
 * ones before it (Hoare's selection; ties by id so the tree does not depend on the order). */
static void bvh_select(const bvh *b, uint32_t lo, uint32_t hi, uint32_t k, int a)
{
    uint32_t *id = b->ids;
    while (hi - lo > 1) {
        uint32_t mid = lo + (hi - lo - 1) / 2; /* the lower middle: j < hi - 1 after */
        float pv = b->cen[mid][a];
        uint32_t pid = id[mid];
        uint32_t i = lo, j = hi - 1;
        for (;;) {
            while (b->cen[i][a] < pv || (b->cen[i][a] == pv && id[i] < pid))
                i++;
            while (b->cen[j][a] > pv || (b->cen[j][a] == pv && id[j] > pid))
                j--;
            if (i >= j)
                break;
            uint32_t t = id[i];
            id[i] = id[j];
            id[j] = t;
            float c[3];
            memcpy(c, b->cen[i], sizeof c);
            memcpy(b->cen[i], b->cen[j], sizeof c);
            memcpy(b->cen[j], c, sizeof c);
            i++;
            j--;
        }
        /* [lo, j] <= pivot <= [j + 1, hi) */
        if (k <= j)
            hi = j + 1;
        else
            lo = j + 1;
    }
}

/* The node of cells ids[lo, hi) and those below it (depth first: its first child is the next
 * node); a leaf's box is its cells' corners', a node's the union of its children's. */
static uint32_t bvh_make(const cells *C, bvh *b, uint32_t lo, uint32_t hi)
{
    uint32_t at = b->nnode++;
    bnode *nd = &b->node[at];
    for (int a = 0; a < 3; a++) {
        nd->lo[a] = FLT_MAX;
        nd->hi[a] = -FLT_MAX;
    }
    if (hi - lo <= 4) {
        nd->first = lo;
        nd->n = hi - lo;
        for (uint32_t i = lo; i < hi; i++) {
            const double *P[4];
            cell_pts(C, b->ids[i], P);
            for (int k = 0; k < 4; k++)
                for (int a = 0; a < 3; a++) {
                    nd->lo[a] = fminf(nd->lo[a], f_down(P[k][a]));
                    nd->hi[a] = fmaxf(nd->hi[a], f_up(P[k][a]));
                }
        }
        return at;
    }
    /* split at the median centroid along the axis the centroids spread widest */
    float clo[3] = {FLT_MAX, FLT_MAX, FLT_MAX}, chi[3] = {-FLT_MAX, -FLT_MAX, -FLT_MAX};
    for (uint32_t i = lo; i < hi; i++)
        for (int a = 0; a < 3; a++) {
            clo[a] = fminf(clo[a], b->cen[i][a]);
            chi[a] = fmaxf(chi[a], b->cen[i][a]);
        }
    int a = 0;
    for (int k = 1; k < 3; k++)
        if (chi[k] - clo[k] > chi[a] - clo[a])
            a = k;
    uint32_t mid = lo + (hi - lo) / 2;
    bvh_select(b, lo, hi, mid, a);
    uint32_t left = bvh_make(C, b, lo, mid), right = bvh_make(C, b, mid, hi);
    nd = &b->node[at];
    nd->n = 0;
    nd->first = right; /* the left child is at + 1 */
    for (int k = 0; k < 3; k++) {
        nd->lo[k] = fminf(b->node[left].lo[k], b->node[right].lo[k]);
        nd->hi[k] = fmaxf(b->node[left].hi[k], b->node[right].hi[k]);
    }
    return at;
}

/* The tree holds the cells with a vertex on the solids' boundary only: the point of the solid
 * nearest to a vertex outside lies on a boundary face, and a cell holding it holds the face,
 * edge or vertex of that face it lies inside of (a conforming complex; an octahedron's 4
 * tetrahedra conform too), so has a boundary vertex. The other cells are never nearest. */
static sd_result bvh_build(sd_mem *m, const cells *C, bvh *b, sd_error *err)
{
    memset(b, 0, sizeof *b);
    uint32_t nb = sd_level_solid_boundary(C->lv, NULL);
    uint8_t *on = sdi_calloc(m, C->nv ? C->nv : 1, 1);
    uint32_t *tri = on ? sdi_alloc(m, (3 * (size_t)nb + 1) * sizeof *tri) : NULL;
    if (!tri) {
        sdi_free(m, on);
        return sdi_fail_nomem(err, m);
    }
    sd_level_solid_boundary(C->lv, tri);
    for (size_t i = 0; i < 3 * (size_t)nb; i++)
        on[tri[i]] = 1;
    sdi_free(m, tri);
    uint32_t n = 0;
    for (uint32_t c = 0; c < C->nc; c++) {
        uint32_t v[4];
        cell_verts(C, c, v);
        n += (on[v[0]] | on[v[1]] | on[v[2]] | on[v[3]]) != 0;
    }
    /* leaves hold 2 to 4 cells (halves of more than 4 have at least 2), so fewer than n nodes */
    size_t nn = n < 2 ? 1 : n;
    b->ids = sdi_alloc(m, nn * sizeof *b->ids);
    b->cen = b->ids ? sdi_alloc(m, nn * sizeof *b->cen) : NULL;
    b->node = b->cen ? sdi_alloc(m, nn * sizeof *b->node) : NULL;
    if (!b->node) {
        sdi_free(m, on);
        bvh_free(m, b);
        return sdi_fail_nomem(err, m);
    }
    n = 0;
    for (uint32_t c = 0; c < C->nc; c++) {
        uint32_t v[4];
        cell_verts(C, c, v);
        if (!(on[v[0]] | on[v[1]] | on[v[2]] | on[v[3]]))
            continue;
        const double *P[4];
        cell_pts(C, c, P);
        for (int a = 0; a < 3; a++)
            b->cen[n][a] = (float)(0.25 * (P[0][a] + P[1][a] + P[2][a] + P[3][a]));
        b->ids[n++] = c;
    }
    sdi_free(m, on);
    b->nids = n;
    if (n) /* a solid has boundary faces */
        bvh_make(C, b, 0, n);
    sdi_free(m, b->cen);
    b->cen = NULL;
    return SD_OK;
}

static inline double node_dist2(const bnode *nd, const double *p)
{
    double s = 0;
    for (int a = 0; a < 3; a++) {
        double d = p[a] < nd->lo[a] ? nd->lo[a] - p[a] : p[a] > nd->hi[a] ? p[a] - nd->hi[a] : 0;
        s += d * d;
    }
    return s;
}

#define SLACK (1 + 1e-12)

/* The nearest cell to p (lowest index among equals) by the tree. Each node looked at and each
 * cell tested takes one unit of *work; NONE when it runs out first. */
static uint32_t nearest_tree(const cells *C, const grid *g, const bvh *b, const double *p,
                             uint64_t *work)
{
    uint32_t stack[128];
    double sd[128];
    int top = 0;
    double best = DBL_MAX;
    uint32_t bc = NONE;
    if (!b->nids)
        return NONE;
    stack[top] = 0;
    sd[top++] = node_dist2(&b->node[0], p);
    while (top > 0) {
        top--;
        if (sd[top] > best * SLACK && sqrt(sd[top]) > sqrt(best) + IN_TOL * g->maxlen)
            continue;
        uint32_t at = stack[top];
        const bnode *nd = &b->node[at];
        uint64_t cost = 1 + nd->n;
        if (cost > *work)
            return NONE;
        *work -= cost;
        if (nd->n) {
            for (uint32_t i = nd->first; i < nd->first + nd->n; i++)
                consider(C, g, p, b->ids[i], &best, &bc);
            continue;
        }
        uint32_t l = at + 1, r = nd->first;
        double dl = node_dist2(&b->node[l], p), dr = node_dist2(&b->node[r], p);
        /* the nearer one on top; depth is at most ~log2(cells) + 1, one slot a level plus one */
        if (dl <= dr) {
            stack[top] = r, sd[top++] = dr;
            stack[top] = l, sd[top++] = dl;
        } else {
            stack[top] = l, sd[top++] = dl;
            stack[top] = r, sd[top++] = dr;
        }
    }
    return bc;
}

/* ---- binding ------------------------------------------------------------------------------- */

void sd_embed_free(sd_embedding *e)
{
    if (!e)
        return;
    sd_mem m = e->mem;
    sdi_free(&m, e->model);
    sdi_free(&m, e->slot);
    sdi_free(&m, e->idx);
    sdi_free(&m, e->w);
    sdi_free(&m, e->rowptr);
    sdi_free(&m, e->col);
    sdi_free(&m, e->stamp);
    sdi_free(&m, e->scratch);
    sdi_free(&m, e);
}

static void note_outside(sd_bind_report *rep, size_t i)
{
    if (rep->nfirst < (int)(sizeof rep->first / sizeof *rep->first))
        rep->first[rep->nfirst++] = i;
    rep->outside++;
}

/* The inverse map: level vertex -> the slots bound to it (ascending). */
static bool build_inverse(sd_embedding *e)
{
    e->rowptr = sdi_calloc(&e->mem, (size_t)e->nlv + 1, sizeof *e->rowptr);
    if (!e->rowptr)
        return false;
    size_t nent = 0;
    for (size_t i = 0; i < e->n; i++)
        if (e->idx[4 * i] != NONE) {
            for (int k = 0; k < 4; k++)
                e->rowptr[e->idx[4 * i + k] + 1]++;
            nent += 4;
        }
    for (uint32_t v = 0; v < e->nlv; v++)
        e->rowptr[v + 1] += e->rowptr[v];
    e->col = sdi_alloc(&e->mem, (nent ? nent : 1) * sizeof *e->col);
    if (!e->col)
        return false;
    for (size_t i = 0; i < e->n; i++)
        if (e->idx[4 * i] != NONE)
            for (int k = 0; k < 4; k++)
                e->col[e->rowptr[e->idx[4 * i + k]]++] = (uint32_t)i;
    memmove(e->rowptr + 1, e->rowptr, (size_t)e->nlv * sizeof *e->rowptr);
    e->rowptr[0] = 0;
    return true;
}

sd_result sd_embed_bind(const sd_level *lv, const double *xyz, size_t n, sd_outside mode,
                        const sd_allocator *alloc, size_t max_bytes, sd_embedding **out,
                        sd_bind_report *rep, sd_error *err)
{
    sd_bind_report dummy;
    if (!rep)
        rep = &dummy;
    memset(rep, 0, sizeof *rep);
    if (out)
        *out = NULL;
    if (!lv || !out || (n && !xyz))
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "no level, model or result given");
    if (mode != SD_OUTSIDE_REFUSE && mode != SD_OUTSIDE_FIXED && mode != SD_OUTSIDE_NEAREST)
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "unknown outside mode %d", (int)mode);
    if (n > UINT32_MAX / 4)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1, "%zu model vertices (at most %u)", n,
                        UINT32_MAX / 4);
    cells C = {lv, sd_level_channel(lv, 0, NULL), sd_level_num_cells(lv, SD_CELL_TETRA), 0,
               sd_level_num_vertices(lv)};
    uint64_t nc = C.ntet + 4 * (uint64_t)sd_level_num_cells(lv, SD_CELL_OCTA);
    if (nc == 0)
        return sdi_fail(err, SD_ERR_VALUE, -1, -1, "level %u has no solid cells", sd_level_index(lv));
    if (nc >= UINT32_MAX)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1, "%llu solid cells (at most %u)",
                        (unsigned long long)nc, UINT32_MAX - 1);
    C.nc = (uint32_t)nc;
    for (size_t i = 0; i < 3 * n; i++)
        if (!isfinite(xyz[i]))
            return sdi_fail(err, SD_ERR_VALUE, (long)(i / 3), (int)(i % 3),
                            "model vertex %zu: coordinate %d is not finite", i / 3, (int)(i % 3));

    sd_mem m;
    sdi_mem_init(&m, alloc, max_bytes);
    const uint32_t nlv = sd_level_num_vertices(lv);
    /* what stays: the vertices' cells and weights, the inverse map, stamps and scratch */
    const double keep = 16.0 * 10 + (double)n * (16 + 32 + 16 + 4 + 4 + 8) + 4.0 * ((double)nlv + 1);
    if (max_bytes && keep > (double)max_bytes)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1,
                        "binding %zu model vertices takes %.0f bytes (limit %zu)", n, keep,
                        max_bytes);
    sd_embedding *e = sdi_calloc(&m, 1, sizeof *e);
    if (!e)
        return sdi_fail_nomem(err, &m);
    e->n = n;
    e->nlv = nlv;
    e->model = sdi_alloc(&m, (n ? n : 1) * sizeof *e->model);
    e->slot = e->model ? sdi_alloc(&m, (n ? n : 1) * sizeof *e->slot) : NULL;
    e->idx = e->slot ? sdi_alloc(&m, (n ? 4 * n : 1) * sizeof *e->idx) : NULL;
    e->w = e->idx ? sdi_alloc(&m, (n ? 4 * n : 1) * sizeof *e->w) : NULL;
    e->stamp = e->w ? sdi_calloc(&m, n ? n : 1, sizeof *e->stamp) : NULL;
    e->scratch = e->stamp ? sdi_alloc(&m, (n ? n : 1) * sizeof *e->scratch) : NULL;
    sd_result r = SD_OK;
    grid g = {0};
    bvh tree = {0};
    uint32_t *ord = e->model, *cnt = NULL;
    if (!e->scratch) {
        r = sdi_fail_nomem(err, &m);
        goto fail;
    }
    if ((r = grid_build(&m, &C, &g, err)))
        goto fail;

    /* model vertices in bucket order (their slots): e->scratch holds each one's bucket meanwhile */
    cnt = sdi_calloc(&m, g.nb + 1, sizeof *cnt);
    if (!cnt) {
        r = sdi_fail_nomem(err, &m);
        goto fail;
    }
    for (size_t i = 0; i < n; i++) {
        uint32_t q[3];
        for (int a = 0; a < 3; a++)
            q[a] = quant(&g, a, xyz[3 * i + a]);
        e->scratch[i] = (uint32_t)bucket_q(&g, q);
        cnt[e->scratch[i] + 1]++;
    }
    for (size_t b = 0; b < g.nb; b++)
        cnt[b + 1] += cnt[b];
    for (size_t i = 0; i < n; i++) {
        e->slot[i] = cnt[e->scratch[i]]++;
        ord[e->slot[i]] = (uint32_t)i;
    }
    sdi_free(&m, cnt);
    cnt = NULL;

    for (size_t j = 0; j < n; j++) {
        size_t i = ord[j];
        double lam[4];
        uint32_t q[3];
        for (int a = 0; a < 3; a++)
            q[a] = quant(&g, a, xyz[3 * i + a]);
        uint32_t c = locate(&C, &g, q, xyz + 3 * i, lam);
        if (c == NONE) {
            e->idx[4 * j] = NONE; /* settled below, in model order */
            continue;
        }
        cell_verts(&C, c, e->idx + 4 * j);
        memcpy(e->w + 4 * j, lam, sizeof lam);
    }
    size_t nout = 0;
    for (size_t j = 0; j < n; j++)
        nout += e->idx[4 * j] == NONE;
    const uint64_t budget = NEAREST_WORK_BASE + (uint64_t)NEAREST_WORK_PER_VERTEX * nout;
    uint64_t work = budget;
    for (size_t i = 0; i < n; i++) {
        size_t j = e->slot[i];
        if (e->idx[4 * j] != NONE)
            continue;
        note_outside(rep, i);
        if (mode == SD_OUTSIDE_FIXED) {
            memcpy(e->w + 4 * j, xyz + 3 * i, 3 * sizeof *e->w);
            e->w[4 * j + 3] = 0;
        } else if (mode == SD_OUTSIDE_NEAREST) {
            /* the grid (vertices near the solid) with its share of the work, until a vertex
             * runs out of it; the tree from then on (made then: quick for near and far vertices
             * alike, but its making costs more than the grid's searches of a few thousand near
             * ones). The same cell either way: both search exhaustively what could be as near
             * as the best. */
            uint32_t c = NONE;
            if (!tree.node) {
                uint64_t grid_work = work < NEAREST_WORK_PER_VERTEX ? work : NEAREST_WORK_PER_VERTEX;
                uint64_t left = grid_work;
                c = nearest_grid(&C, &g, xyz + 3 * i, &left);
                work -= grid_work - left;
            }
            if (c == NONE && work) {
                if (!tree.node && (r = bvh_build(&m, &C, &tree, err)))
                    goto fail;
                c = nearest_tree(&C, &g, &tree, xyz + 3 * i, &work);
            }
            if (c == NONE) {
                r = sdi_fail(err, SD_ERR_VALUE, (long)i, SD_EMBED_TOO_FAR,
                             "vertex %zu: too many cells of level %u are about as near to it "
                             "for \"nearest\" (the searches passed their budget of %llu "
                             "buckets, boxes and cells looked at); move the model or give \"outside\": "
                             "\"fixed\"",
                             i, sd_level_index(lv), (unsigned long long)budget);
                goto fail;
            }
            const double *P[4];
            cell_pts(&C, c, P);
            cell_verts(&C, c, e->idx + 4 * j);
            if (!bary(P, xyz + 3 * i, e->w + 4 * j)) { /* not for a valid complex's cells */
                r = sdi_fail(err, SD_ERR_DEGENERATE, (long)i, -1,
                             "model vertex %zu: its nearest cell %u is degenerate", i, c);
                goto fail;
            }
        }
    }
    if (mode == SD_OUTSIDE_REFUSE && rep->outside) {
        r = sdi_fail(err, SD_ERR_VALUE, (long)rep->first[0], -1,
                     "%zu of %zu model vertices are in no solid cell of level %u (the first: %zu)",
                     rep->outside, n, sd_level_index(lv), rep->first[0]);
        goto fail;
    }
    grid_free(&m, &g);
    memset(&g, 0, sizeof g);
    bvh_free(&m, &tree);
    e->mem = m; /* from here on the embedding counts itself */
    memset(e->stamp, 0, (n ? n : 1) * sizeof *e->stamp); /* pages written now, not by updates */
    if (!build_inverse(e)) {
        m = e->mem;
        r = sdi_fail_nomem(err, &m);
        sd_embed_free(e);
        return r;
    }
    *out = e;
    return SD_OK;

fail:
    sdi_free(&m, cnt);
    grid_free(&m, &g);
    bvh_free(&m, &tree);
    e->mem = m;
    sd_embed_free(e);
    return r;
}

sd_result sd_embed_restore(const sd_level *lv, size_t n, const uint32_t *idx, const double *w,
                           const double *rest, const sd_allocator *alloc, size_t max_bytes,
                           sd_embedding **out, sd_error *err)
{
    if (out)
        *out = NULL;
    if (!lv || !out || (n && (!idx || !w || !rest)))
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "no level, binding or result given");
    if (n > UINT32_MAX / 4)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1, "%zu model vertices (at most %u)", n,
                        UINT32_MAX / 4);
    const uint32_t nlv = sd_level_num_vertices(lv);
    for (size_t i = 0; i < n; i++) { /* a binding of another level, or damaged: refused */
        if (idx[4 * i] == NONE)
            continue;
        double sum = 0, mag = 0;
        for (int k = 0; k < 4; k++) {
            if (idx[4 * i + k] >= nlv)
                return sdi_fail(err, SD_ERR_VALUE, (long)i, k, "model vertex %zu: level vertex "
                                "%u is not one of level %u (%u points)", i, idx[4 * i + k],
                                sd_level_index(lv), nlv);
            if (!isfinite(w[4 * i + k]))
                return sdi_fail(err, SD_ERR_VALUE, (long)i, 4 + k, "model vertex %zu: weight %d "
                                "is not finite", i, k);
            sum += w[4 * i + k];
            mag += fabs(w[4 * i + k]);
        }
        if (!(fabs(sum - 1) <= 1e-9 * (mag > 1 ? mag : 1))) /* "nearest" weights can be large */
            return sdi_fail(err, SD_ERR_VALUE, (long)i, -1, "model vertex %zu: its weights add "
                            "up to %.17g, not 1", i, sum);
    }
    sd_mem m;
    sdi_mem_init(&m, alloc, max_bytes);
    sd_embedding *e = sdi_calloc(&m, 1, sizeof *e);
    if (!e)
        return sdi_fail_nomem(err, &m);
    e->n = n;
    e->nlv = nlv;
    e->model = sdi_alloc(&m, (n ? n : 1) * sizeof *e->model);
    e->slot = e->model ? sdi_alloc(&m, (n ? n : 1) * sizeof *e->slot) : NULL;
    e->idx = e->slot ? sdi_alloc(&m, (n ? 4 * n : 1) * sizeof *e->idx) : NULL;
    e->w = e->idx ? sdi_alloc(&m, (n ? 4 * n : 1) * sizeof *e->w) : NULL;
    e->stamp = e->w ? sdi_calloc(&m, n ? n : 1, sizeof *e->stamp) : NULL;
    e->scratch = e->stamp ? sdi_alloc(&m, (n ? n : 1) * sizeof *e->scratch) : NULL;
    e->mem = m;
    if (!e->scratch) {
        sd_result r = sdi_fail_nomem(err, &m);
        sd_embed_free(e);
        return r;
    }
    memset(e->stamp, 0, (n ? n : 1) * sizeof *e->stamp); /* pages written now, not by updates */
    for (size_t i = 0; i < n; i++) { /* slots in model order (a bind's bucket order is lost) */
        e->model[i] = e->slot[i] = (uint32_t)i;
        memcpy(e->idx + 4 * i, idx + 4 * i, 4 * sizeof *idx);
        if (idx[4 * i] == NONE) {
            memcpy(e->w + 4 * i, rest + 3 * i, 3 * sizeof *e->w);
            e->w[4 * i + 3] = 0;
        } else
            memcpy(e->w + 4 * i, w + 4 * i, 4 * sizeof *w);
    }
    if (!build_inverse(e)) {
        m = e->mem;
        sd_result r = sdi_fail_nomem(err, &m);
        sd_embed_free(e);
        return r;
    }
    *out = e;
    return SD_OK;
}

/* ---- reading ------------------------------------------------------------------------------- */

size_t sd_embed_count(const sd_embedding *e)
{
    return e ? e->n : 0;
}

size_t sd_embed_memory(const sd_embedding *e)
{
    return e ? e->mem.used : 0;
}

int sd_embed_weights(const sd_embedding *e, size_t i, uint32_t idx[4], double w[4])
{
    if (!e || i >= e->n || e->idx[4 * (size_t)e->slot[i]] == NONE)
        return 0;
    memcpy(idx, e->idx + 4 * (size_t)e->slot[i], 4 * sizeof *idx);
    memcpy(w, e->w + 4 * (size_t)e->slot[i], 4 * sizeof *w);
    return 1;
}

/* The position of slot s at positions x. */
static inline void place(const sd_embedding *e, const double *x, size_t s, double *o)
{
    const uint32_t *v = e->idx + 4 * s;
    const double *w = e->w + 4 * s;
    if (v[0] == NONE) {
        memcpy(o, w, 3 * sizeof *o);
        return;
    }
    const double *a = x + 3 * (size_t)v[0], *b = x + 3 * (size_t)v[1], *c = x + 3 * (size_t)v[2],
                 *d = x + 3 * (size_t)v[3];
    for (int k = 0; k < 3; k++)
        o[k] = w[0] * a[k] + w[1] * b[k] + w[2] * c[k] + w[3] * d[k];
}

void sd_embed_positions(const sd_embedding *e, const sd_level *lv, double *out)
{
    const double *x = sd_level_channel(lv, 0, NULL);
    for (size_t s = 0; s < e->n; s++)
        place(e, x, s, out + 3 * (size_t)e->model[s]);
}

/* Ascending order of a[0..k) (distinct values below 2^32), tmp of k. */
static void sort_ids(uint32_t *a, uint32_t *tmp, size_t k)
{
    if (k < 64) {
        for (size_t i = 1; i < k; i++) {
            uint32_t v = a[i];
            size_t j = i;
            for (; j && a[j - 1] > v; j--)
                a[j] = a[j - 1];
            a[j] = v;
        }
        return;
    }
    uint32_t mx = 0;
    for (size_t i = 0; i < k; i++)
        mx = a[i] > mx ? a[i] : mx;
    uint32_t *src = a, *dst = tmp;
    for (int shift = 0; shift < 32 && (mx >> shift); shift += 11) {
        size_t c[2049] = {0};
        for (size_t i = 0; i < k; i++)
            c[((src[i] >> shift) & 2047) + 1]++;
        for (int d = 0; d < 2048; d++)
            c[d + 1] += c[d];
        for (size_t i = 0; i < k; i++)
            dst[c[(src[i] >> shift) & 2047]++] = src[i];
        uint32_t *t = src;
        src = dst;
        dst = t;
    }
    if (src != a)
        memcpy(a, src, k * sizeof *a);
}

size_t sd_embed_update(sd_embedding *e, const sd_level *lv, const uint32_t *changed,
                       size_t nchanged, double *out, uint32_t *moved)
{
    if (++e->epoch == 0) { /* the counter wrapped: start the stamps afresh */
        memset(e->stamp, 0, e->n * sizeof *e->stamp);
        e->epoch = 1;
    }
    const uint32_t ep = e->epoch;
    size_t k = 0;
    for (size_t j = 0; j < nchanged; j++) {
        uint32_t v = changed[j];
        if (v >= e->nlv)
            continue;
        for (uint32_t q = e->rowptr[v]; q < e->rowptr[v + 1]; q++) {
            uint32_t s = e->col[q];
            if (e->stamp[s] != ep) {
                e->stamp[s] = ep;
                moved[k++] = s;
            }
        }
    }
    /* slots found near each other are near each other in memory: place them in that order */
    const double *x = sd_level_channel(lv, 0, NULL);
    for (size_t j = 0; j < k; j++) {
        uint32_t s = moved[j], i = e->model[s];
        place(e, x, s, out + 3 * (size_t)i);
        moved[j] = i;
    }
    sort_ids(moved, e->scratch, k);
    return k;
}
