/* rings.c — who the neighbours are: rho(x) of a vertex and the ring of an edge (docs/RULES.md),
 * read from a level's topology for the rules rules.c chose.
 *
 * rho(x) is filtered to the vertex's rule by the edges it is read through (000 Algorithm 5 line
 * 3; rule_table.h's rho column): a curve vertex reads curve edges, a surface-boundary vertex the
 * boundary edges, a solid-boundary vertex the edges of boundary faces, an interior solid vertex
 * every solid edge and, in the box scheme, its octahedra's major diagonals (001 Def. 3.3); the
 * averaged scheme adds its octahedral opposites as a second class (001 App. A). A singular vertex
 * reads the singular complex only (000 Sec. 4.1), a vertex with its own N1 / N2 choice its part
 * (000 Sec. 3.5; DECISIONS 23-24), a G2 vertex every edge and diagonal but, where it lies on dC,
 * not the points strictly inside a solid (the relieved ring, 000 Fig. 14; DECISIONS 5).
 *
 * The ring of an edge (rule_table.h's ring column): the far vertices of its two triangles (Loop),
 * of its two faces on the solids' boundary (solid boundary), rho(e) of the solid — the other
 * vertices of the cells containing it, an octahedron counted as the 4 tetrahedra around its major
 * diagonal (box) or its faces' and diagonals' (averaged) — and, for G2, the common neighbours of
 * its ends with the same relief. Counting and filling go over the edges and cells in id order,
 * so the order of rho in a row is fixed: the golden outputs depend on it.
 */
#include "internal.h"
#include <stdlib.h>
#include <string.h>

/* ---- rho(x) ------------------------------------------------------------------------------ */

/* G2's relieved ring: keep neighbour n of a junction c unless c lies on dC (or outside solids)
 * and n is strictly inside a solid. `inside` tells whether the centre is inside a solid: in C_3
 * and off dC, whatever other parts meet there (a curve or a fin reaching into a solid's interior
 * is a junction inside it, which keeps the solid's points around it, as the control vertex did
 * at level 0 whose neighbours were all on dC). A neighbour is strictly inside when it is a
 * solid's point alone, off dC. */
static inline bool strictly_inside(const sd_topo *t, uint32_t v)
{
    return t->vfam[v] == FAM3 && !(t->vflag[v] & VF_DC);
}
static inline bool centre_inside(const sd_topo *t, uint32_t v)
{
    return (t->vfam[v] & FAM3) && !(t->vflag[v] & VF_DC);
}
static inline bool g2_keep(const sd_topo *t, bool centre_inside, uint32_t n)
{
    return centre_inside || !strictly_inside(t, n);
}

/* The rho kinds (SDI_RHO_*, as bits) that read through an edge of family `fam` and flags `fl`;
 * G2's and the singular vertices' are decided per neighbour (via_edge). */
static inline unsigned edge_kinds(uint8_t fam, uint8_t fl)
{
    unsigned m = 0;
    if (fl & EF_CURVE)
        m |= 1u << SDI_RHO_CURVE;
    if (fam & FAM2)
        m |= 1u << SDI_RHO_SURFACE;
    if (fl & EF_BND2)
        m |= 1u << SDI_RHO_SURFACE_BOUNDARY;
    if (fam & FAM3) {
        m |= 1u << SDI_RHO_SOLID;
        if (fl & EF_DC)
            m |= 1u << SDI_RHO_SOLID_BOUNDARY;
    }
    return m;
}

/* Does neighbour n, reached from centre c (rule r) through edge e, belong to c's rho? */
static inline bool via_edge(const sd_topo *t, uint8_t r, uint32_t c, uint32_t n, uint32_t e)
{
    if (t->vflag[c] & VF_S_ANY) /* a singular vertex sees only the singular complex */
        return r == SD_RULE_CURVE ? (t->eflag[e] & EF_CREASE) != 0
               : r == SD_RULE_LOOP ? (t->eflag[e] & EF_SSURF) != 0
               : r == SD_RULE_LOOP_BOUNDARY && (t->eflag[e] & EF_SBND);
    if (SDI_RULE_RHO[r] == SDI_RHO_G2)
        return g2_keep(t, centre_inside(t, c), n);
    return (edge_kinds(t->efam[e], t->eflag[e]) >> SDI_RULE_RHO[r]) & 1u;
}
/* ... and through an octahedron's major diagonal c-n? */
static inline bool via_diag(const sd_topo *t, uint8_t r, int scheme, uint32_t c, uint32_t n)
{
    if (r == SD_RULE_SOLID)
        return scheme == SD_SOLID_BOX;
    if (r == SD_RULE_G2)
        return g2_keep(t, centre_inside(t, c), n);
    return false;
}

bool sdi_ov_boundary_edge(const sd_topo *t, int ov, uint32_t e)
{
    switch (ov) {
    case OV_N1_2:
        return (t->efam[e] & FAM2) && (t->enm[e] & NM_C2B);
    case OV_N1_3:
        return (t->efam[e] & FAM3) && (t->eflag[e] & EF_DC);
    case OV_N2:
        return (t->eflag[e] & EF_N2BND) != 0;
    default:
        return false;
    }
}
/* Does a vertex with its own choice (N1, N2, a Ying-Zorin crease), following rule r, read its
 * neighbour through e? */
static inline bool ov_take(const sd_topo *t, uint8_t r, uint32_t v, uint32_t e)
{
    int ov = nm_ov(t->vnm[v]);
    uint8_t fam = t->efam[e], fl = t->eflag[e];
    switch (ov) {
    case OV_N1_1:
        return fl & EF_CURVE;
    case OV_N1_2:
        return r == SD_RULE_LOOP ? (fam & FAM2) != 0 : sdi_ov_boundary_edge(t, ov, e);
    case OV_N1_3:
        return r == SD_RULE_SOLID ? (fam & FAM3) != 0 : sdi_ov_boundary_edge(t, ov, e);
    case OV_N2:
        if (t->vfam[v] == FAM1)
            return (fl & (EF_CURVE | EF_N2SEL)) == (EF_CURVE | EF_N2SEL);
        return r == SD_RULE_LOOP ? (fl & EF_N2SEL) != 0 : sdi_ov_boundary_edge(t, ov, e);
    case OV_YZS: /* along the singular edges: boundary or non-manifold ones */
        return fam == FAM2 && ((fl & EF_BND2) || nm_type(t->enm[e]) == 2);
    default:
        return false;
    }
}

/* rho in parts (sd_options.threads). Counting: the edges, then the octahedra, are one sequence of
 * items cut into ranges; part 0 counts into cnt_a / cnt_b, part p >= 1 into its own arrays
 * (R->at, R->nb), and the merge (per vertex) adds them up, so no counter is shared. Writing
 * (sdi_vertex_rho_cols): by ranges of vertices instead, each part reading every item and writing
 * only its own vertices' rows, in item order: a row's columns are in the serial order whatever the
 * number of parts (the golden outputs depend on it). Cut by items, the parts would write the
 * same rows — a vertex point's half edges come before the edges inside faces — and fight over
 * their cache lines. */
/* Part p >= 1's counts of each vertex's entries: class A in at[p], class B in nb[p] (arrays of nv
 * counts, so at most RHO_MAXP parts). */
enum { RHO_MAXP = 4 };
typedef struct rho_parts {
    uint32_t n; /* parts (1: in order, alone) */
    uint32_t *at[RHO_MAXP], *nb[RHO_MAXP];
} rho_parts;

typedef struct rhojob {
    const sd_topo *t;
    int scheme;
    uint8_t *vr;                    /* (counting: flagged) */
    const uint8_t *vrule, *take_r;  /* (columns) */
    uint32_t *cnt_a, *cnt_b, *cur, *col;
    uint8_t *take;
    rho_parts *R;
} rhojob;

static void rho_count_part(void *arg, uint32_t part, uint32_t nparts)
{
    const rhojob *J = arg;
    const sd_topo *t = J->t;
    const uint32_t nv = t->nv, ne = t->ne;
    const uint8_t *vr = J->vr;
    uint8_t *take = J->take; /* (J's fields in locals: the stores below could alias them) */
    uint32_t *cnt_a = part ? J->R->at[part] : J->cnt_a, *cnt_b = part ? J->R->nb[part] : J->cnt_b;
    if (part) {
        memset(cnt_a, 0, (size_t)nv * sizeof *cnt_a);
        if (cnt_b)
            memset(cnt_b, 0, (size_t)nv * sizeof *cnt_b);
    }
    uint64_t lo, hi;
    sdi_range((uint64_t)ne + t->noct, part, nparts, &lo, &hi);
    for (uint32_t e = (uint32_t)lo; e < hi && e < ne; e++) {
        uint32_t a = t->ev[e][0], b = t->ev[e][1];
        unsigned m = edge_kinds(t->efam[e], t->eflag[e]);
        uint8_t ra = vr[a], rb = vr[b];
        unsigned ta = ra & SDI_VR_OWN ? ov_take(t, ra & SDI_VR_RULE, a, e)
                    : ra & SDI_VR_SLOW ? via_edge(t, ra & SDI_VR_RULE, a, b, e)
                    : (m >> SDI_RULE_RHO[ra]) & 1u;
        unsigned tb = rb & SDI_VR_OWN ? ov_take(t, rb & SDI_VR_RULE, b, e)
                    : rb & SDI_VR_SLOW ? via_edge(t, rb & SDI_VR_RULE, b, a, e)
                    : (m >> SDI_RULE_RHO[rb]) & 1u;
        cnt_a[a] += ta;
        cnt_a[b] += tb;
        if (take)
            take[e] = (uint8_t)(ta | tb << 1);
    }
    for (uint64_t i = lo > ne ? lo : ne; i < hi; i++) {
        const uint32_t *q = t->oct[i - ne];
        uint32_t p = q[0], r = q[1];
        if (via_diag(t, vr[p] & SDI_VR_RULE, J->scheme, p, r)) /* the flags go in the merge */
            cnt_a[p]++;
        if (via_diag(t, vr[r] & SDI_VR_RULE, J->scheme, r, p))
            cnt_a[r]++;
        if (J->scheme == SD_SOLID_AVERAGED)
            for (int k = 0; k < 6; k++)
                if ((vr[q[k]] & SDI_VR_RULE) == SD_RULE_SOLID)
                    cnt_b[q[k]]++;
    }
}

static void rho_merge_part(void *arg, uint32_t part, uint32_t nparts)
{
    const rhojob *J = arg;
    const rho_parts *R = J->R;
    uint64_t lo, hi;
    sdi_range(J->t->nv, part, nparts, &lo, &hi);
    if (R->n == 1) { /* the counts are all part 0's: only the flags go */
        for (uint32_t v = (uint32_t)lo; v < hi; v++)
            J->vr[v] &= SDI_VR_RULE;
        return;
    }
    for (uint32_t v = (uint32_t)lo; v < hi; v++) {
        J->vr[v] &= SDI_VR_RULE;
        uint32_t a = J->cnt_a[v], b = J->cnt_b ? J->cnt_b[v] : 0;
        for (uint32_t p = 1; p < R->n; p++) {
            a += R->at[p][v];
            b += J->cnt_b ? R->nb[p][v] : 0;
        }
        J->cnt_a[v] = a;
        if (J->cnt_b)
            J->cnt_b[v] = b;
    }
}

static void rho_parts_free(sd_mem *m, rho_parts *R)
{
    for (uint32_t p = 0; p < RHO_MAXP; p++) {
        sdi_free(m, R->at[p]);
        sdi_free(m, R->nb[p]);
    }
}

bool sdi_vertex_rho(sd_mem *m, const sd_topo *t, int scheme, int threads, uint8_t *vr,
                    uint32_t *cnt_a, uint32_t *cnt_b, uint8_t *take)
{
    rho_parts R = {0};
    threads = threads < RHO_MAXP ? threads : RHO_MAXP;
    const uint64_t items = (uint64_t)t->ne + t->noct;
    R.n = sdi_par_parts(threads, items);
    for (uint32_t p = 1; p < R.n; p++)
        if (!(R.at[p] = sdi_alloc(m, ((size_t)t->nv + 1) * sizeof *R.at[p])) ||
            (cnt_b && !(R.nb[p] = sdi_alloc(m, ((size_t)t->nv + 1) * sizeof *R.nb[p])))) {
            rho_parts_free(m, &R);
            return false;
        }
    rhojob J = {.t = t, .scheme = scheme, .vr = vr, .cnt_a = cnt_a, .cnt_b = cnt_b, .take = take,
                .R = &R};
    sdi_par(threads, items, rho_count_part, &J);
    sdi_par(threads, t->nv, rho_merge_part, &J);
    rho_parts_free(m, &R);
    return true;
}

/* Vertices [lo, hi); all: that is every vertex (no test per entry, the serial case). */
static inline __attribute__((always_inline)) void rho_cols_of(const rhojob *J, uint32_t lo,
                                                              uint32_t hi, bool all)
{
    const sd_topo *t = J->t;
    const uint8_t *vr = J->vrule, *take = J->take_r;
    uint32_t *cur = J->cur, *col = J->col;
#define MINE(v) (all || ((v) >= lo && (v) < hi))
    for (uint32_t e = 0; e < t->ne; e++) {
        uint32_t a = t->ev[e][0], b = t->ev[e][1];
        if ((take[e] & 1) && MINE(a) && vr[a] != SD_RULE_CORNER)
            col[cur[a]++] = b;
        if ((take[e] & 2) && MINE(b) && vr[b] != SD_RULE_CORNER)
            col[cur[b]++] = a;
    }
    for (uint32_t o = 0; o < t->noct; o++) {
        const uint32_t *q = t->oct[o];
        for (int k = 0; k < 2; k++)
            if (MINE(q[k]) && vr[q[k]] != SD_RULE_CORNER &&
                via_diag(t, vr[q[k]], J->scheme, q[k], q[k ^ 1]))
                col[cur[q[k]]++] = q[k ^ 1];
        if (J->scheme == SD_SOLID_AVERAGED)
            for (int k = 0; k < 6; k++)
                if (MINE(q[k]) && vr[q[k]] == SD_RULE_SOLID)
                    col[cur[q[k]]++] = q[k ^ 1];
    }
#undef MINE
}

static void rho_cols_part(void *arg, uint32_t part, uint32_t nparts)
{
    const rhojob *J = arg;
    uint64_t lo, hi;
    sdi_range(J->t->nv, part, nparts, &lo, &hi);
    if (nparts == 1)
        rho_cols_of(J, 0, J->t->nv, true);
    else
        rho_cols_of(J, (uint32_t)lo, (uint32_t)hi, false);
}

void sdi_vertex_rho_cols(const sd_topo *t, int scheme, int threads, const uint8_t *vr,
                         const uint8_t *take, uint32_t *cur, uint32_t *col)
{
    rhojob J = {.t = t, .scheme = scheme, .vrule = vr, .take_r = take, .cur = cur, .col = col};
    sdi_par(threads, (uint64_t)t->ne + t->noct, rho_cols_part, &J);
}

/* ---- rings of edges ---------------------------------------------------------------------- */

enum { M_SSURF = 4, M_LOOP = 8, M_SB = 16, M_N2 = 32 }; /* which faces give an edge its opposite
                                                          * vertices */

/* In parts by ranges of edges: each part reads every face but writes only its own edges, which
 * so see their faces in id order, as alone. Every part reads the faces' arrays whole, so two
 * parts gain 1.3x, not 2 (docs/BENCHMARKS.md "Two threads"); cut by faces, the edges two parts
 * share would need a merge of their slots. */
typedef struct oppjob {
    const sd_topo *t;
    const uint8_t *er;
    uint32_t (*opp)[2];
    uint8_t *nopp;
} oppjob;

/* Edges [lo, hi); all: that is every edge (no test per face, the serial case). */
static inline __attribute__((always_inline)) void opp_edges(const oppjob *J, uint32_t lo,
                                                            uint32_t hi, bool all)
{
    const sd_topo *t = J->t;
    const uint8_t *er = J->er;
    uint8_t *nopp = J->nopp;
    uint32_t (*opp)[2] = J->opp;
    for (uint32_t e = lo; e < hi; e++) {
        /* an embedded surface's edge takes its opposite vertices from tagged triangles */
        bool ss = t->eflag[e] & EF_SSURF;
        bool n2 = (t->ovmask & OVM_N2T) && nm_ov(t->enm[e]) == OV_N2 && !ss &&
                  !(t->eflag[e] & EF_CREASE);
        uint8_t ring = SDI_RULE_RING[er[e]];
        nopp[e] = ring == SDI_RING_OPPOSITE ? (ss ? M_SSURF : n2 ? M_N2 : M_LOOP)
                : ring == SDI_RING_BOUNDARY_OPPOSITE && !ss ? M_SB : 0;
    }
    for (uint32_t f = 0; f < t->nf; f++) {
        uint8_t ff = t->fflag[f];
        if (!(ff & (FF_MAX | FF_BND3 | FF_SING)))
            continue;
        unsigned want = (ff & FF_SING ? M_SSURF : 0) | (ff & FF_MAX ? M_LOOP : M_SB) |
                        (ff & FF_N2SEL ? M_N2 : 0);
        for (int j = 0; j < 3; j++) {
            uint32_t e = t->fe[f][j];
            if (!all && (e < lo || e >= hi))
                continue;
            unsigned n = nopp[e];
            if (!(n & want))
                continue;
            if ((n & 3) < 2)
                opp[e][n & 3] = t->fv[f][(j + 2) % 3];
            if ((n & 3) < 3)
                nopp[e] = (uint8_t)(n + 1);
        }
    }
}

static void opp_part(void *arg, uint32_t part, uint32_t nparts)
{
    const oppjob *J = arg;
    uint64_t lo, hi;
    sdi_range(J->t->ne, part, nparts, &lo, &hi);
    if (nparts == 1)
        opp_edges(J, 0, J->t->ne, true);
    else
        opp_edges(J, (uint32_t)lo, (uint32_t)hi, false);
}

void sdi_edge_opposites(const sd_topo *t, int threads, const uint8_t *er, uint32_t (*opp)[2],
                        uint8_t *nopp)
{
    oppjob J = {t, er, opp, nopp};
    sdi_par(threads, t->ne, opp_part, &J);
}

/* Equator neighbours in an octahedron: cycle a(2), b(4), a2(3), b2(5). */
static const uint8_t OCT_EQ_NB[6][2] = {{0, 0}, {0, 0}, {5, 4}, {4, 5}, {2, 3}, {3, 2}};

void sdi_rings_free(sd_mem *m, sdi_rings *r)
{
    sdi_free(m, r->off);
    sdi_free(m, r->v);
    sdi_free(m, r->cls);
    sdi_free(m, r->len);
}

static int cmp_u32(const void *x, const void *y)
{
    uint32_t a = *(const uint32_t *)x, b = *(const uint32_t *)y;
    return a < b ? -1 : a > b;
}

static int cmp_entry(const void *x, const void *y)
{
    uint64_t a = *(const uint64_t *)x, b = *(const uint64_t *)y;
    return a < b ? -1 : a > b;
}

/* rho(e) of solid edges: the candidates from the cells, then sorted and deduplicated per edge. */
typedef struct ring_sort_job {
    sdi_rings *R;
    uint32_t ne;
    volatile bool ok;
} ring_sort_job;

static void ring_sort_part(void *arg, uint32_t part, uint32_t nparts)
{
    ring_sort_job *J = arg;
    sdi_rings *R = J->R;
    uint64_t lo, hi;
    sdi_range(J->ne, part, nparts, &lo, &hi);
    uint32_t *const rv = R->v, *const off = R->off, *const len = R->len;
    uint8_t *const cls = R->cls;
    if (!cls) { /* one class (box scheme): the vertex ids alone, sorted in place, each candidate
                 * inserted unless already there */
        for (uint32_t e = (uint32_t)lo; e < (uint32_t)hi; e++) {
            uint32_t b = off[e], n = off[e + 1] - b, w = 0;
            uint32_t *s = rv + b;
            if (n > 64) {
                qsort(s, n, sizeof *s, cmp_u32);
                for (uint32_t i = 0; i < n; i++)
                    if (i == 0 || s[i] != s[i - 1])
                        s[w++] = s[i];
                len[e] = w;
                continue;
            }
            for (uint32_t i = 0; i < n; i++) {
                uint32_t x = s[i], j = w;
                while (j > 0 && s[j - 1] > x)
                    j--;
                if (j > 0 && s[j - 1] == x)
                    continue;
                for (uint32_t k = w; k > j; k--)
                    s[k] = s[k - 1];
                s[j] = x;
                w++;
            }
            len[e] = w;
        }
        return;
    }
    uint64_t buf[256];
    for (uint32_t e = (uint32_t)lo; e < (uint32_t)hi; e++) {
        uint32_t b = off[e], n = off[e + 1] - b, w = 0;
        if (n == 0)
            continue;
        uint64_t *s = n <= 256 ? buf : malloc(n * sizeof *s);
        if (!s) {
            J->ok = false;
            return;
        }
        for (uint32_t i = 0; i < n; i++)
            s[i] = (uint64_t)rv[b + i] << 1 | cls[b + i];
        if (n <= 32) /* the usual few candidates: insertion sort */
            for (uint32_t i = 1; i < n; i++) {
                uint64_t x = s[i];
                uint32_t j = i;
                for (; j > 0 && s[j - 1] > x; j--)
                    s[j] = s[j - 1];
                s[j] = x;
            }
        else
            qsort(s, n, sizeof *s, cmp_entry);
        for (uint32_t i = 0; i < n; i++)
            if (i == 0 || s[i] != s[i - 1]) {
                rv[b + w] = (uint32_t)(s[i] >> 1);
                cls[b + w] = (uint8_t)(s[i] & 1);
                w++;
            }
        len[e] = w;
        if (s != buf)
            free(s);
    }
}

/* The candidates in parts by ranges of edges: each part reads every cell and counts, then
 * gathers, only its own edges' candidates, in cell order as alone (the sort that follows would
 * make any order the same). Cut by cells instead, two parts would write the same edges' lists. */
typedef struct srjob {
    const sd_topo *t;
    const uint8_t *erule;
    bool avg, fill;                  /* fill: gather (at cur), else count */
    sdi_rings *R;
    uint32_t *cur;
} srjob;

static inline __attribute__((always_inline)) void solid_cands(const srjob *J, uint32_t lo,
                                                              uint32_t hi, bool all, bool fill)
{
    const sd_topo *t = J->t;
    const uint8_t *const erule = J->erule;
    sdi_rings *R = J->R;
    uint32_t *const cnt = R->off + 1, *const cur = J->cur, *const rv = R->v;
    uint8_t *const rcls = R->cls;
    const bool avg = J->avg;
    const uint32_t ntet = t->ntet, noct = t->noct;
    const uint32_t(*const tet)[4] = t->tet, (*const tet_e)[6] = t->tet_e;
    const uint32_t(*const oct)[6] = t->oct, (*const oct_e)[12] = t->oct_e;
#define MINE(e) ((all || ((e) >= lo && (e) < hi)) && SDI_RULE_RING[erule[e]] == SDI_RING_SOLID)
    /* the box scheme has one class: its entries have none (R->cls is NULL) */
#define PUSH(e, x, c)                                                                        \
    do {                                                                                     \
        uint32_t at_ = cur[e]++;                                                             \
        rv[at_] = (x);                                                                       \
        if (avg)                                                                             \
            rcls[at_] = (c);                                                                 \
    } while (0)
    for (uint32_t c = 0; c < ntet; c++)
        for (int k = 0; k < 6; k++) {
            uint32_t e = tet_e[c][k];
            if (!MINE(e))
                continue;
            if (!fill) {
                cnt[e] += 2;
                continue;
            }
            /* the two vertices not on edge k: those of the opposite edge 5-k */
            PUSH(e, tet[c][SDI_TET_E[5 - k][0]], 0);
            PUSH(e, tet[c][SDI_TET_E[5 - k][1]], 0);
        }
    for (uint32_t o = 0; o < noct; o++)
        for (int k = 0; k < 12; k++) {
            uint32_t e = oct_e[o][k];
            if (!MINE(e))
                continue;
            if (!fill) {
                cnt[e] += avg ? 4 : (k < 8 ? 3 : 2);
                continue;
            }
            const uint32_t *q = oct[o];
            int i = SDI_OCT_E[k][0], j = SDI_OCT_E[k][1];
            if (avg) {
                /* faces of the octahedron on the edge: the two common neighbours;
                 * through the octahedron's diagonals: the opposites of both ends */
                int com[2], nc = 0;
                for (int w = 0; w < 6 && nc < 2; w++)
                    if (w != i && w != j && w != (i ^ 1) && w != (j ^ 1))
                        com[nc++] = w;
                PUSH(e, q[com[0]], 0);
                PUSH(e, q[com[1]], 0);
                PUSH(e, q[i ^ 1], 1);
                PUSH(e, q[j ^ 1], 1);
            } else if (k < 8) {
                /* [P, x] with P on the diagonal: tets (p,q,x,prev), (p,q,x,next) */
                int P = i, x = j;
                PUSH(e, q[P ^ 1], 0);
                PUSH(e, q[OCT_EQ_NB[x][0]], 0);
                PUSH(e, q[OCT_EQ_NB[x][1]], 0);
            } else {
                /* an equator edge lies in one of the 4 tets: (p,q,x,y) */
                PUSH(e, q[0], 0);
                PUSH(e, q[1], 0);
            }
        }
#undef PUSH
#undef MINE
}

static void solid_part(void *arg, uint32_t part, uint32_t nparts)
{
    const srjob *J = arg;
    uint64_t lo, hi;
    sdi_range(J->t->ne, part, nparts, &lo, &hi);
    if (nparts == 1 && J->fill)
        solid_cands(J, 0, J->t->ne, true, true);
    else if (nparts == 1)
        solid_cands(J, 0, J->t->ne, true, false);
    else if (J->fill)
        solid_cands(J, (uint32_t)lo, (uint32_t)hi, false, true);
    else
        solid_cands(J, (uint32_t)lo, (uint32_t)hi, false, false);
}

bool sdi_solid_rings(sd_mem *m, const sd_topo *t, const uint8_t *erule, int scheme, int threads,
                     sdi_rings *R)
{
    uint32_t ne = t->ne;
    const uint64_t work = 8ull * t->ntet + 14ull * t->noct; /* as a split's */
    srjob J = {.t = t, .erule = erule, .avg = scheme == SD_SOLID_AVERAGED, .R = R};
    R->off = sdi_calloc(m, (size_t)ne + 1, sizeof *R->off);
    R->len = sdi_calloc(m, ne ? ne : 1, sizeof *R->len);
    if (!R->off || !R->len)
        return false;
    sdi_par(threads, work, solid_part, &J); /* count */
    for (uint32_t e = 0; e < ne; e++)
        R->off[e + 1] += R->off[e];
    size_t total = R->off[ne];
    R->v = sdi_alloc(m, (total + 1) * sizeof *R->v);
    R->cls = J.avg ? sdi_alloc(m, total + 1) : NULL; /* the box scheme has one class */
    J.cur = sdi_alloc(m, ((size_t)ne + 1) * sizeof *J.cur);
    if (!R->v || (J.avg && !R->cls) || !J.cur) {
        sdi_free(m, J.cur);
        return false;
    }
    memcpy(J.cur, R->off, (size_t)ne * sizeof *J.cur);
    J.fill = true;
    sdi_par(threads, work, solid_part, &J);
    sdi_free(m, J.cur);
    /* sort and deduplicate each edge's list (as (vertex, class) pairs in the averaged scheme),
     * edges in parallel */
    ring_sort_job S = {R, ne, true};
    sdi_par(threads, R->off[ne], ring_sort_part, &S);
    return S.ok;
}

/* Rings of G2 edges: the common neighbours (edges and diagonals) of both ends, filtered. The
 * neighbours of each vertex come from the relations vertex -> edges and vertex -> diagonals,
 * sorted, and each edge's ends are merged. */
bool sdi_g2_rings(sd_mem *m, sdi_rels *rel, const uint8_t *erule, sdi_rings *R)
{
    const sd_topo *t = rel->t;
    uint32_t nv = t->nv, ne = t->ne;
    uint32_t *off = NULL, *adj = NULL;
    R->off = sdi_calloc(m, (size_t)ne + 1, sizeof *R->off);
    R->len = sdi_calloc(m, ne ? ne : 1, sizeof *R->len);
    if (!R->off || !R->len || !sdi_rels_need(m, rel, SDI_REL(SDI_VE) | SDI_REL(SDI_VD)))
        goto fail;
    const sdi_rel *ve = &rel->r[SDI_VE], *vd = &rel->r[SDI_VD];
    off = sdi_alloc(m, ((size_t)nv + 1) * sizeof *off);
    adj = sdi_alloc(m, ((size_t)ve->off[nv] + vd->off[nv] + 1) * sizeof *adj);
    if (!off || !adj)
        goto fail;
    for (uint32_t v = 0, n = 0; v <= nv; v++) {
        off[v] = n;
        if (v == nv)
            break;
        for (uint32_t k = ve->off[v]; k < ve->off[v + 1]; k++) {
            const uint32_t *q = t->ev[ve->item[k]];
            adj[n++] = q[0] == v ? q[1] : q[0];
        }
        for (uint32_t k = vd->off[v]; k < vd->off[v + 1]; k++) {
            const uint32_t *q = t->oct[vd->item[k]];
            adj[n++] = q[0] == v ? q[1] : q[0];
        }
        qsort(adj + off[v], n - off[v], sizeof *adj, cmp_u32);
    }
    /* count, then fill, the common neighbours of each G2 edge */
    for (int pass = 0; pass < 2; pass++) {
        for (uint32_t e = 0; e < ne; e++) {
            if (SDI_RULE_RING[erule[e]] != SDI_RING_G2)
                continue;
            uint32_t a = t->ev[e][0], b = t->ev[e][1], n = 0;
            bool inside = (t->efam[e] & FAM3) && !(t->eflag[e] & EF_DC);
            uint32_t i = off[a], j = off[b];
            while (i < off[a + 1] && j < off[b + 1]) {
                if (adj[i] < adj[j])
                    i++;
                else if (adj[i] > adj[j])
                    j++;
                else {
                    uint32_t x = adj[i];
                    if ((i == off[a] || adj[i - 1] != x) && x != a && x != b && g2_keep(t, inside, x)) {
                        if (pass)
                            R->v[R->off[e] + n] = x;
                        n++;
                    }
                    i++;
                    j++;
                }
            }
            if (pass == 0)
                R->off[e + 1] = n;
            else
                R->len[e] = n;
        }
        if (pass == 0) {
            for (uint32_t e = 0; e < ne; e++)
                R->off[e + 1] += R->off[e];
            R->v = sdi_alloc(m, ((size_t)R->off[ne] + 1) * sizeof *R->v);
            R->cls = sdi_calloc(m, (size_t)R->off[ne] + 1, 1);
            if (!R->v || !R->cls)
                goto fail;
        }
    }
    sdi_free(m, off);
    sdi_free(m, adj);
    return true;
fail:
    sdi_free(m, off);
    sdi_free(m, adj);
    return false;
}
