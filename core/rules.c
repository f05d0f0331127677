/* rules.c — one rule per vertex and edge, and the stencils that make up S_l (SPEC Sec. 3).
 *
 * Rule choice (priority: non-manifold default > boundary > interior; tags and user choices come
 * with the non-manifold issue):
 *   isolated point, curve end, junction of 3+ curves   corner (0-mask)
 *   curve                    cubic B-spline: (6x + a + b)/8, edge midpoint
 *   surface                  Loop: (1 - m c) x + c sum rho, Warren c (default) or Loop's beta;
 *                            edge 3/8 (a+b) + 1/8 (c+d)
 *   surface boundary         cubic B-spline along the boundary curve
 *   solid                    box spline (001 eqs. 3.3-3.8): vertex 9/16 x + 7/(16k) sum rho, rho by
 *                            edges and major diagonals (001 Def. 3.3); edge by the ring rho(e):
 *                            k=6: 10/32, 2/32; k=4: 8/32, 4/32; else 5/16, 3/(8k); cell point of
 *                            an octahedron 1/4 on its diagonal ends, 1/8 on the others. Or the
 *                            averaged scheme (001 App. A; SPEC Sec. 3.1 fixes its masks).
 *   solid boundary           Loop on the boundary surface (rho restricted to it)
 *   non-manifold (types 1-4) G2: the 3-simplex rules with the relieved topology condition
 *                            (000 Sec. 3.5): rho = every vertex joined by an edge (or diagonal);
 *                            where the junction lies on dC, neighbours strictly inside a solid
 *                            are left out (000 Fig. 14). An edge's ring = common neighbours.
 * rho is filtered to the rule's family (000 Algorithm 5 line 3) by the edges it is read through:
 * a curve vertex reads curve edges, a surface-boundary vertex boundary edges, and so on.
 *
 * The ring of an edge is the set of the other vertices of the cells that contain it, an
 * octahedron counted as the 4 tetrahedra around its major diagonal (SPEC Sec. 3). A rule whose
 * neighbourhood is degenerate (no neighbours) falls back to the 0-mask / midpoint; the rule
 * reported is then the one actually used.
 *
 * S is assembled in two passes — count each row, then fill in place — so no adjacency lists are
 * built for the common cases and memory stays at the matrix itself. Every row sums to 1.
 */
#include "internal.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The names and regular sizes of the rules (rule_table.h). */
#define RULE_NAME(id, name, ...) [id] = name,
static const char *const rule_names[SD_RULE_COUNT] = {SD_RULE_TABLE(RULE_NAME)};
#undef RULE_NAME
#define RULE_REGULAR(id, name, vregular, eregular) [id] = {vregular, eregular},
static const uint32_t rule_regular[SD_RULE_COUNT][2] = {SD_RULE_TABLE(RULE_REGULAR)};
#undef RULE_REGULAR

const char *sd_rule_name(sd_rule r)
{
    return (unsigned)r < SD_RULE_COUNT ? rule_names[r] : "unknown";
}

bool sdi_rule_extraordinary(uint8_t rule, uint32_t k, bool edge)
{
    uint32_t regular = rule < SD_RULE_COUNT ? rule_regular[rule][edge] : 0;
    return regular && !(k < 32 && (regular >> k & 1));
}

uint8_t sdi_vertex_rule(const sd_topo *t, uint32_t v)
{
    uint8_t fam = t->vfam[v], nm = t->vnm[v], fl = t->vflag[v];
    /* singular tags first (SPEC Sec. 3 priority): corner; crease (B-spline along the creases);
     * embedded surface (Loop over the tagged triangles, B-spline along its boundary). A vertex
     * where creases meet a surface is a corner. */
    if (fl & VF_SING || (fl & VF_S_ANY) == VF_S_ANY)
        return SD_RULE_CORNER;
    if (fl & VF_SCREASE)
        return SD_RULE_CURVE;
    if (fl & VF_SSURF)
        return fl & VF_SBND ? SD_RULE_LOOP_BOUNDARY : SD_RULE_LOOP;
    if (nm) {
        switch (nm_ov(nm)) { /* the simplex's own choice (tags.c); vertex_rules settles N1, N2 */
        case OV_N1_1:
            return SD_RULE_CURVE;
        case OV_N1_2:
            return SD_RULE_LOOP;
        case OV_N1_3:
            return fl & VF_DC ? SD_RULE_SOLID_BOUNDARY : SD_RULE_SOLID;
        case OV_N2:
            return fam == FAM1 ? SD_RULE_CURVE : SD_RULE_LOOP;
        case OV_YZS:
            return SD_RULE_CURVE;
        case OV_YZX:
            return SD_RULE_CORNER;
        default:
            break;
        }
        if (nm_type(nm))
            return nm_type(nm) == 2 && fam == FAM1 ? SD_RULE_CORNER : SD_RULE_G2;
    }
    switch (fam) {
    case FAM1:
        return fl & VF_CURVE_END ? SD_RULE_CORNER : SD_RULE_CURVE;
    case FAM2:
        return fl & VF_DC ? SD_RULE_LOOP_BOUNDARY : SD_RULE_LOOP;
    case FAM3:
        return fl & VF_DC ? SD_RULE_SOLID_BOUNDARY : SD_RULE_SOLID;
    default:
        return SD_RULE_CORNER;
    }
}

static uint8_t edge_rule(const sd_topo *t, uint32_t e)
{
    uint8_t fl = t->eflag[e];
    if (fl & (EF_CREASE | EF_SBND))
        return SD_RULE_CURVE;
    if (fl & EF_SSURF)
        return SD_RULE_LOOP;
    if (t->enm[e] & (NM_TYPE | NM_OV)) {
        switch (nm_ov(t->enm[e])) { /* the edge's own choice (tags.c) */
        case OV_N1_1:
            return SD_RULE_CURVE;
        case OV_N1_2: /* as in C_2 alone: between two triangles, or its boundary */
            return t->enm[e] & NM_C2B ? SD_RULE_LOOP_BOUNDARY : SD_RULE_LOOP;
        case OV_N1_3: /* as in C_3 alone */
            return fl & EF_DC ? SD_RULE_SOLID_BOUNDARY : SD_RULE_SOLID;
        case OV_N2: /* Loop between the two chosen triangles (opp_task) */
            return SD_RULE_LOOP;
        case OV_YZS: /* a Ying-Zorin crease */
            return SD_RULE_CURVE;
        default:
            break;
        }
        if (nm_type(t->enm[e]))
            return SD_RULE_G2;
    }
    switch (t->efam[e]) {
    case FAM1:
        return SD_RULE_CURVE;
    case FAM2:
        return t->eflag[e] & EF_BND2 ? SD_RULE_LOOP_BOUNDARY : SD_RULE_LOOP;
    case FAM3:
        return t->eflag[e] & EF_DC ? SD_RULE_SOLID_BOUNDARY : SD_RULE_SOLID;
    default:
        return SD_RULE_CURVE;
    }
}

sd_rule sdi_reported_vertex_rule(const sd_topo *t, uint32_t v, uint8_t r)
{
    uint8_t nm = t->vnm[v];
    if (nm & NM_G1)
        return SD_RULE_G1;
    if (t->vflag[v] & (VF_SING | VF_S_ANY)) /* a tag wins over the vertex's choice */
        return (sd_rule)r;
    int ov = nm_ov(nm);
    if (ov == OV_YZX || (ov == OV_YZS && r == SD_RULE_CORNER))
        return SD_RULE_YZ_CORNER;
    if (ov == OV_YZS)
        return SD_RULE_YZ_CREASE;
    if (r == SD_RULE_CORNER) /* the choice's part has no rule here (e.g. N1 1 at a curve end) */
        return SD_RULE_CORNER;
    return ov >= OV_N1_1 && ov <= OV_N1_3 ? SD_RULE_N1 : ov == OV_N2 ? SD_RULE_N2 : (sd_rule)r;
}

sd_rule sdi_reported_edge_rule(const sd_topo *t, uint32_t e, uint8_t r)
{
    uint8_t nm = t->enm[e];
    if (nm & NM_G1)
        return SD_RULE_G1;
    if (t->eflag[e] & (EF_CREASE | EF_SSURF))
        return (sd_rule)r;
    int ov = nm_ov(nm);
    if (ov == OV_YZS)
        return SD_RULE_YZ_CREASE;
    if ((t->ovmask & OVM_YZ) && r == SD_RULE_LOOP && !ov &&
        (nm_ov(t->vnm[t->ev[e][0]]) >= OV_YZS || nm_ov(t->vnm[t->ev[e][1]]) >= OV_YZS))
        return SD_RULE_YZ_PETAL;
    return ov >= OV_N1_1 && ov <= OV_N1_3 ? SD_RULE_N1 : ov == OV_N2 ? SD_RULE_N2 : (sd_rule)r;
}

/* G2's relieved ring: keep neighbour n of a junction c unless c lies on dC (or outside solids)
 * and n is strictly inside a solid. `inside` tells whether the centre is strictly inside. */
static inline bool strictly_inside(const sd_topo *t, uint32_t v)
{
    return t->vfam[v] == FAM3 && !(t->vflag[v] & VF_DC);
}
static inline bool g2_keep(const sd_topo *t, bool centre_inside, uint32_t n)
{
    return centre_inside || !strictly_inside(t, n);
}

/* Does neighbour n, reached from centre c (rule r) through edge e, belong to c's rho? */
static inline bool via_edge(const sd_topo *t, uint8_t r, uint32_t c, uint32_t n, uint32_t e)
{
    if (t->vflag[c] & VF_S_ANY) /* a singular vertex sees only the singular complex */
        return r == SD_RULE_CURVE ? (t->eflag[e] & EF_CREASE) != 0
               : r == SD_RULE_LOOP ? (t->eflag[e] & EF_SSURF) != 0
               : r == SD_RULE_LOOP_BOUNDARY && (t->eflag[e] & EF_SBND);
    switch (r) {
    case SD_RULE_CURVE:
        return t->eflag[e] & EF_CURVE;
    case SD_RULE_LOOP:
        return t->efam[e] & FAM2;
    case SD_RULE_LOOP_BOUNDARY:
        return t->eflag[e] & EF_BND2;
    case SD_RULE_SOLID:
        return t->efam[e] & FAM3;
    case SD_RULE_SOLID_BOUNDARY:
        return (t->efam[e] & FAM3) && (t->eflag[e] & EF_DC);
    case SD_RULE_G2:
        return g2_keep(t, strictly_inside(t, c), n);
    default:
        return false;
    }
}
static inline bool via_diag(const sd_topo *t, uint8_t r, int scheme, uint32_t c, uint32_t n)
{
    if (r == SD_RULE_SOLID)
        return scheme == SD_SOLID_BOX;
    if (r == SD_RULE_G2)
        return g2_keep(t, strictly_inside(t, c), n);
    return false;
}

/* Loop's original beta(m) (SPEC Sec. 3), or Warren's c. */
static double loop_weight(int weights, uint32_t m)
{
    if (weights == SD_WEIGHTS_LOOP) {
        double x = 3.0 / 8.0 + cos(2 * M_PI / m) / 4;
        return (5.0 / 8.0 - x * x) / m;
    }
    return m == 3 ? 3.0 / 16.0 : 3.0 / (8.0 * m);
}

/* Weights of a vertex row: self, class A (rho), class B (octahedral opposites, averaged). */
typedef struct vw {
    double self, a, b;
} vw;

static vw vertex_weights(uint8_t r, int weights, int scheme, uint32_t na, uint32_t nb,
                         const double *loopc)
{
    vw w = {1, 0, 0};
    switch (r) {
    case SD_RULE_CURVE:
    case SD_RULE_LOOP_BOUNDARY:
        w.self = 6.0 / 8.0;
        w.a = 1.0 / 8.0;
        break;
    case SD_RULE_LOOP:
    case SD_RULE_SOLID_BOUNDARY: {
        double c = na < 64 ? loopc[na] : loop_weight(weights, na);
        w.self = 1 - na * c;
        w.a = c;
        break;
    }
    case SD_RULE_SOLID:
        w.self = 9.0 / 16.0;
        if (scheme == SD_SOLID_AVERAGED) {
            double d = 3.0 * na + nb;
            w.a = 7.0 / 16.0 * 3.0 / d;
            w.b = 7.0 / 16.0 / d;
        } else {
            w.a = 7.0 / (16.0 * na);
        }
        break;
    case SD_RULE_G2:
        w.self = 9.0 / 16.0;
        w.a = 7.0 / (16.0 * na);
        break;
    default:
        break;
    }
    return w;
}

/* 3-simplex edge weights for a ring of k (001 eqs. 3.4, 3.5, 3.8): ends, ring. */
static void solid_edge_weights(uint32_t k, double *end, double *ring)
{
    if (k == 6) {
        *end = 10.0 / 32.0;
        *ring = 2.0 / 32.0;
    } else if (k == 4) {
        *end = 8.0 / 32.0;
        *ring = 4.0 / 32.0;
    } else {
        *end = 5.0 / 16.0;
        *ring = 3.0 / (8.0 * k);
    }
}

/* Equator neighbours in an octahedron: cycle a(2), b(4), a2(3), b2(5). */
static const uint8_t OCT_EQ_NB[6][2] = {{0, 0}, {0, 0}, {5, 4}, {4, 5}, {2, 3}, {3, 2}};

/* Per-edge variable-size rings (solid and G2 edges), CSR; class 0 = ring/face, 1 = diagonal. */
typedef struct rings {
    uint32_t *off, *v;
    uint8_t *cls;
    uint32_t *len;   /* after dedup */
} rings;

static void rings_free(sd_mem *m, rings *r)
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

/* Ring candidates of SOLID edges from the cells; then sorted and deduplicated per edge. */
typedef struct ring_sort_job {
    rings *R;
    uint32_t ne;
    volatile bool ok;
} ring_sort_job;

static void ring_sort_part(void *arg, uint32_t part, uint32_t nparts)
{
    ring_sort_job *J = arg;
    rings *R = J->R;
    uint64_t lo, hi;
    sdi_range(J->ne, part, nparts, &lo, &hi);
    uint64_t buf[256];
    for (uint32_t e = (uint32_t)lo; e < (uint32_t)hi; e++) {
        uint32_t b = R->off[e], n = R->off[e + 1] - b, w = 0;
        if (n == 0)
            continue;
        uint64_t *s = n <= 256 ? buf : malloc(n * sizeof *s);
        if (!s) {
            J->ok = false;
            return;
        }
        for (uint32_t i = 0; i < n; i++)
            s[i] = (uint64_t)R->v[b + i] << 1 | R->cls[b + i];
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
                R->v[b + w] = (uint32_t)(s[i] >> 1);
                R->cls[b + w] = (uint8_t)(s[i] & 1);
                w++;
            }
        R->len[e] = w;
        if (s != buf)
            free(s);
    }
}

static bool solid_rings(sd_mem *m, const sd_topo *t, const uint8_t *erule, int scheme, int threads,
                        rings *R)
{
    uint32_t ne = t->ne;
    R->off = sdi_calloc(m, (size_t)ne + 1, sizeof *R->off);
    R->len = sdi_calloc(m, ne ? ne : 1, sizeof *R->len);
    if (!R->off || !R->len)
        return false;
    bool avg = scheme == SD_SOLID_AVERAGED;
    /* count */
    for (uint32_t c = 0; c < t->ntet; c++)
        for (int k = 0; k < 6; k++)
            if (erule[t->tet_e[c][k]] == SD_RULE_SOLID)
                R->off[t->tet_e[c][k] + 1] += 2;
    for (uint32_t o = 0; o < t->noct; o++)
        for (int k = 0; k < 12; k++)
            if (erule[t->oct_e[o][k]] == SD_RULE_SOLID)
                R->off[t->oct_e[o][k] + 1] += avg ? 4 : (k < 8 ? 3 : 2);
    for (uint32_t e = 0; e < ne; e++)
        R->off[e + 1] += R->off[e];
    size_t total = R->off[ne];
    R->v = sdi_alloc(m, (total + 1) * sizeof *R->v);
    R->cls = sdi_alloc(m, total + 1);
    uint32_t *cur = sdi_alloc(m, ((size_t)ne + 1) * sizeof *cur);
    if (!R->v || !R->cls || !cur) {
        sdi_free(m, cur);
        return false;
    }
    memcpy(cur, R->off, (size_t)ne * sizeof *cur);
#define PUSH(e, x, c)                                                                        \
    do {                                                                                     \
        R->v[cur[e]] = (x);                                                                  \
        R->cls[cur[e]++] = (c);                                                              \
    } while (0)
    for (uint32_t c = 0; c < t->ntet; c++)
        for (int k = 0; k < 6; k++) {
            uint32_t e = t->tet_e[c][k];
            if (erule[e] != SD_RULE_SOLID)
                continue;
            /* the two vertices not on edge k: those of the opposite edge 5-k */
            PUSH(e, t->tet[c][SDI_TET_E[5 - k][0]], 0);
            PUSH(e, t->tet[c][SDI_TET_E[5 - k][1]], 0);
        }
    for (uint32_t o = 0; o < t->noct; o++)
        for (int k = 0; k < 12; k++) {
            uint32_t e = t->oct_e[o][k];
            if (erule[e] != SD_RULE_SOLID)
                continue;
            const uint32_t *q = t->oct[o];
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
    sdi_free(m, cur);
    /* sort and deduplicate each edge's list (as (vertex, class) pairs), edges in parallel */
    ring_sort_job J = {R, ne, true};
    sdi_par(threads, R->off[ne], ring_sort_part, &J);
    return J.ok;
}

/* Rings of G2 edges: the common neighbours (edges and diagonals) of both ends, filtered. */
static bool g2_rings(sd_mem *m, const sd_topo *t, const uint8_t *erule, rings *R)
{
    uint32_t nv = t->nv, ne = t->ne;
    uint32_t *off = sdi_calloc(m, (size_t)nv + 1, sizeof *off), *adj = NULL, *cur = NULL;
    R->off = sdi_calloc(m, (size_t)ne + 1, sizeof *R->off);
    R->len = sdi_calloc(m, ne ? ne : 1, sizeof *R->len);
    if (!off || !R->off || !R->len)
        goto fail;
    for (uint32_t e = 0; e < ne; e++) {
        off[t->ev[e][0] + 1]++;
        off[t->ev[e][1] + 1]++;
    }
    for (uint32_t o = 0; o < t->noct; o++) {
        off[t->oct[o][0] + 1]++;
        off[t->oct[o][1] + 1]++;
    }
    for (uint32_t v = 0; v < nv; v++)
        off[v + 1] += off[v];
    adj = sdi_alloc(m, ((size_t)off[nv] + 1) * sizeof *adj);
    cur = sdi_alloc(m, ((size_t)nv + 1) * sizeof *cur);
    if (!adj || !cur)
        goto fail;
    memcpy(cur, off, (size_t)nv * sizeof *cur);
    for (uint32_t e = 0; e < ne; e++) {
        adj[cur[t->ev[e][0]]++] = t->ev[e][1];
        adj[cur[t->ev[e][1]]++] = t->ev[e][0];
    }
    for (uint32_t o = 0; o < t->noct; o++) {
        adj[cur[t->oct[o][0]]++] = t->oct[o][1];
        adj[cur[t->oct[o][1]]++] = t->oct[o][0];
    }
    for (uint32_t v = 0; v < nv; v++)
        qsort(adj + off[v], off[v + 1] - off[v], sizeof *adj, cmp_u32);
    /* count, then fill, the common neighbours of each G2 edge */
    for (int pass = 0; pass < 2; pass++) {
        for (uint32_t e = 0; e < ne; e++) {
            if (erule[e] != SD_RULE_G2)
                continue;
            uint32_t a = t->ev[e][0], b = t->ev[e][1], n = 0;
            bool inside = (t->efam[e] == FAM3) && !(t->eflag[e] & EF_DC);
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
    sdi_free(m, cur);
    return true;
fail:
    sdi_free(m, off);
    sdi_free(m, adj);
    sdi_free(m, cur);
    return false;
}

/* The rules (other than the G2 and singular ones, which ask via_edge) whose rho reads
 * through an edge of family `fam` and flags `fl`, as a bit mask over sd_rule. */
static inline unsigned edge_readers(uint8_t fam, uint8_t fl)
{
    unsigned m = 0;
    if (fl & EF_CURVE)
        m |= 1u << SD_RULE_CURVE;
    if (fam & FAM2)
        m |= 1u << SD_RULE_LOOP;
    if (fl & EF_BND2)
        m |= 1u << SD_RULE_LOOP_BOUNDARY;
    if (fam & FAM3) {
        m |= 1u << SD_RULE_SOLID;
        if (fl & EF_DC)
            m |= 1u << SD_RULE_SOLID_BOUNDARY;
    }
    return m;
}

/* N1 / N2 (tags.c): is e, at a vertex with choice ov, on the boundary of the part it follows? */
static inline bool ov_boundary_edge(const sd_topo *t, int ov, uint32_t e)
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
/* ... and does a vertex with choice ov, following rule r, read its neighbour through e? */
static inline bool ov_take(const sd_topo *t, uint8_t r, uint32_t v, uint32_t e)
{
    int ov = nm_ov(t->vnm[v]);
    uint8_t fam = t->efam[e], fl = t->eflag[e];
    switch (ov) {
    case OV_N1_1:
        return fl & EF_CURVE;
    case OV_N1_2:
        return r == SD_RULE_LOOP ? (fam & FAM2) != 0 : ov_boundary_edge(t, ov, e);
    case OV_N1_3:
        return r == SD_RULE_SOLID ? (fam & FAM3) != 0 : ov_boundary_edge(t, ov, e);
    case OV_N2:
        if (t->vfam[v] == FAM1)
            return (fl & (EF_CURVE | EF_N2SEL)) == (EF_CURVE | EF_N2SEL);
        return r == SD_RULE_LOOP ? (fl & EF_N2SEL) != 0 : ov_boundary_edge(t, ov, e);
    case OV_YZS: /* along the singular edges: boundary or non-manifold ones */
        return fam == FAM2 && ((fl & EF_BND2) || nm_type(t->enm[e]) == 2);
    default:
        return false;
    }
}

/* The rule of every vertex and the sizes of its rho (cnt_a: edge and diagonal neighbours,
 * cnt_b: the averaged scheme's octahedral opposites, NULL for the box scheme; zeroed by the
 * caller): the
 * classification's rule, turned into a corner where its neighbourhood does not fit it (a curve or
 * surface boundary point with other than 2 neighbours, any rule with none). If `take` is not
 * NULL, take[e] gets bit 0 if ev[e][0] reads ev[e][1] through e, bit 1 for the converse. */
static void vertex_rules(const sd_topo *t, int scheme, uint8_t *vr, uint32_t *cnt_a, uint32_t *cnt_b,
                         uint8_t *take)
{
    const uint32_t nv = t->nv, ne = t->ne, no = t->noct;
    /* in vr while counting: the rule needs via_edge (G2, singular) or ov_take (a simplex's own
     * N1/N2 choice); ON_BND: such a vertex has an edge of its part's boundary */
    enum { SLOW = 0x80, OVR = 0x40, ON_BND = 0x10 };
    for (uint32_t v = 0; v < nv; v++) {
        uint8_t r = sdi_vertex_rule(t, v);
        vr[v] = r | ((r == SD_RULE_G2 || (t->vflag[v] & VF_S_ANY)) ? SLOW : 0);
    }
    if (t->ovmask) { /* vertices with their own N1 / N2 choice and no tag */
        for (uint32_t v = 0; v < nv; v++) {
            int ov = nm_ov(t->vnm[v]);
            if (ov && ov != OV_G2 && !(t->vflag[v] & (VF_SING | VF_S_ANY)))
                vr[v] = (uint8_t)((vr[v] & 0x0f) | OVR);
        } /* N1 / N2 vertices: interior or boundary of the part they follow */
        for (uint32_t e = 0; e < ne; e++)
            for (int k = 0; k < 2; k++) {
                uint32_t v = t->ev[e][k];
                if (vr[v] & OVR && ov_boundary_edge(t, nm_ov(t->vnm[v]), e))
                    vr[v] |= ON_BND;
            }
        for (uint32_t v = 0; v < nv; v++)
            if (vr[v] & OVR) {
                int ov = nm_ov(t->vnm[v]);
                bool bnd = vr[v] & ON_BND;
                uint8_t r = ov == OV_YZX ? SD_RULE_CORNER
                          : ov == OV_N1_1 || ov == OV_YZS || (ov == OV_N2 && t->vfam[v] == FAM1) ? SD_RULE_CURVE
                          : ov == OV_N1_3 ? (bnd ? SD_RULE_SOLID_BOUNDARY : SD_RULE_SOLID)
                          : bnd ? SD_RULE_LOOP_BOUNDARY : SD_RULE_LOOP;
                vr[v] = r | OVR;
            }
    }
    /* vertex rho sizes */
    for (uint32_t e = 0; e < ne; e++) {
        uint32_t a = t->ev[e][0], b = t->ev[e][1];
        unsigned m = edge_readers(t->efam[e], t->eflag[e]);
        uint8_t ra = vr[a], rb = vr[b];
        unsigned ta = ra & OVR ? ov_take(t, ra & 0x0f, a, e)
                    : ra & SLOW ? via_edge(t, ra & ~SLOW, a, b, e) : (m >> ra) & 1u;
        unsigned tb = rb & OVR ? ov_take(t, rb & 0x0f, b, e)
                    : rb & SLOW ? via_edge(t, rb & ~SLOW, b, a, e) : (m >> rb) & 1u;
        cnt_a[a] += ta;
        cnt_a[b] += tb;
        if (take)
            take[e] = (uint8_t)(ta | tb << 1);
    }
    for (uint32_t v = 0; v < nv; v++)
        vr[v] &= 0x0f;
    for (uint32_t o = 0; o < no; o++) {
        uint32_t p = t->oct[o][0], q = t->oct[o][1];
        if (via_diag(t, vr[p], scheme, p, q))
            cnt_a[p]++;
        if (via_diag(t, vr[q], scheme, q, p))
            cnt_a[q]++;
        if (scheme == SD_SOLID_AVERAGED)
            for (int i = 0; i < 6; i++)
                if (vr[t->oct[o][i]] == SD_RULE_SOLID)
                    cnt_b[t->oct[o][i]]++;
    }
    for (uint32_t v = 0; v < nv; v++) {
        bool degenerate = false;
        switch (vr[v]) {
        case SD_RULE_CURVE:
        case SD_RULE_LOOP_BOUNDARY:
            degenerate = cnt_a[v] != 2;
            break;
        default:
            degenerate = vr[v] != SD_RULE_CORNER && cnt_a[v] == 0;
        }
        if (degenerate || vr[v] == SD_RULE_CORNER) {
            vr[v] = SD_RULE_CORNER;
            cnt_a[v] = 0;
            if (cnt_b)
                cnt_b[v] = 0;
        }
    }
}

sd_result sdi_vertex_rules_only(sd_mem *m, const sd_topo *t, int scheme, uint8_t *vr)
{
    uint32_t *a = sdi_calloc(m, (size_t)t->nv + 1, sizeof *a), *b = sdi_calloc(m, (size_t)t->nv + 1, sizeof *b);
    if (a && b)
        vertex_rules(t, scheme, vr, a, b, NULL);
    sdi_free(m, a);
    sdi_free(m, b);
    return a && b ? SD_OK : SD_ERR_NOMEM;
}

/* The state shared by the steps of sdi_build_rules that may run in parallel (each writes only its
 * own arrays or its own rows of col). */
typedef struct rjob {
    const sd_topo *t;
    int scheme;
    uint8_t *vr, *er, *take, *nopp;
    uint32_t *cnt_a, *cnt_b, *cur, *col;
    uint32_t (*opp)[2];
    const rings *sr, *gr;
    const sd_yzrows *yz;             /* fixed-disk rows (yz.c) */
    uint64_t ebase;
    bool stride;                     /* edge rings stay in opp (S.eopp): no solid or G2 rings */
    bool any_g2e[SD_PAR_MAXT], any_opp[SD_PAR_MAXT];   /* per part */
} rjob;

enum { M_SSURF = 4, M_LOOP = 8, M_SB = 16, M_N2 = 32 }; /* which faces give an edge its opposite
                                                          * vertices */

/* The explicit columns of edge e's row: its ring. */
static inline uint32_t ring_len(const rjob *J, uint32_t e)
{
    switch (J->er[e]) {
    case SD_RULE_LOOP:
    case SD_RULE_SOLID_BOUNDARY:
        return (J->nopp[e] & 3) == 2 ? 2u : 0u;
    case SD_RULE_SOLID:
        return J->sr->len[e];
    case SD_RULE_G2:
        return J->gr->len[e];
    case SD_RULE_YZ_FIXED_DISK:
    case SD_RULE_YZ_DART:
    case SD_RULE_YZ_CONCAVE:
        return J->yz->off[e + 1] - J->yz->off[e];
    default:
        return 0;
    }
}
static inline const uint32_t *ring_of(const rjob *J, uint32_t e)
{
    switch (J->er[e]) {
    case SD_RULE_LOOP:
    case SD_RULE_SOLID_BOUNDARY:
        return J->opp[e];
    case SD_RULE_SOLID:
        return J->sr->v + J->sr->off[e];
    case SD_RULE_YZ_FIXED_DISK:
    case SD_RULE_YZ_DART:
    case SD_RULE_YZ_CONCAVE:
        return J->yz->col + J->yz->off[e];
    default:
        return J->gr->v + J->gr->off[e];
    }
}

static void erule_part(void *arg, uint32_t part, uint32_t nparts)
{
    rjob *J = arg;
    uint64_t lo, hi;
    sdi_range(J->t->ne, part, nparts, &lo, &hi);
    bool g2 = false, op = false;
    for (uint32_t e = (uint32_t)lo; e < (uint32_t)hi; e++) {
        uint8_t r = J->er[e] = edge_rule(J->t, e);
        g2 |= r == SD_RULE_G2;
        op |= r == SD_RULE_LOOP || r == SD_RULE_SOLID_BOUNDARY;
    }
    J->any_g2e[part] = g2;
    J->any_opp[part] = op;
}

static void vrules_task(void *arg)
{
    rjob *J = arg;
    vertex_rules(J->t, J->scheme, J->vr, J->cnt_a, J->cnt_b, J->take);
}

/* Edge neighbourhoods: the opposite vertices of Loop and solid-boundary edges. nopp[e]: the
 * number of faces seen (bits 0-1, saturating at 3) and which faces count (the mode bits). */
static void opp_task(void *arg)
{
    rjob *J = arg;
    const sd_topo *t = J->t;
    uint8_t *nopp = J->nopp, *er = J->er;
    if (!nopp)
        return;
    for (uint32_t e = 0; e < t->ne; e++) {
        /* an embedded surface's edge takes its opposite vertices from tagged triangles */
        bool ss = t->eflag[e] & EF_SSURF;
        bool n2 = (t->ovmask & OVM_N2T) && nm_ov(t->enm[e]) == OV_N2 && !ss &&
                  !(t->eflag[e] & EF_CREASE);
        nopp[e] = er[e] == SD_RULE_LOOP ? (ss ? M_SSURF : n2 ? M_N2 : M_LOOP)
                : er[e] == SD_RULE_SOLID_BOUNDARY && !ss ? M_SB : 0;
    }
    for (uint32_t f = 0; f < t->nf; f++) {
        uint8_t ff = t->fflag[f];
        if (!(ff & (FF_MAX | FF_BND3 | FF_SING)))
            continue;
        unsigned want = (ff & FF_SING ? M_SSURF : 0) | (ff & FF_MAX ? M_LOOP : M_SB) |
                        (ff & FF_N2SEL ? M_N2 : 0);
        for (int j = 0; j < 3; j++) {
            uint32_t e = t->fe[f][j];
            unsigned n = nopp[e];
            if (!(n & want))
                continue;
            if ((n & 3) < 2)
                J->opp[e][n & 3] = t->fv[f][(j + 2) % 3];
            if ((n & 3) < 3)
                nopp[e] = (uint8_t)(n + 1);
        }
    }
}

/* Vertex rows: (the centre, implicit) then rho in edge order, then diagonals and opposites. */
static void vrows_task(void *arg)
{
    rjob *J = arg;
    const sd_topo *t = J->t;
    const uint8_t *vr = J->vr, *take = J->take;
    uint32_t *cur = J->cur, *col = J->col;
    for (uint32_t e = 0; e < t->ne; e++) {
        uint32_t a = t->ev[e][0], b = t->ev[e][1];
        if ((take[e] & 1) && vr[a] != SD_RULE_CORNER)
            col[cur[a]++] = b;
        if ((take[e] & 2) && vr[b] != SD_RULE_CORNER)
            col[cur[b]++] = a;
    }
    for (uint32_t o = 0; o < t->noct; o++) {
        const uint32_t *q = t->oct[o];
        for (int i = 0; i < 2; i++)
            if (vr[q[i]] != SD_RULE_CORNER && via_diag(t, vr[q[i]], J->scheme, q[i], q[i ^ 1]))
                col[cur[q[i]]++] = q[i ^ 1];
        if (J->scheme == SD_SOLID_AVERAGED)
            for (int i = 0; i < 6; i++)
                if (vr[q[i]] == SD_RULE_SOLID)
                    col[cur[q[i]]++] = q[i ^ 1];
    }
}

/* Edge rows: (the ends, implicit) then the ring. */
static void erows_task(void *arg)
{
    rjob *J = arg;
    if (J->stride)
        return;
    uint64_t at = J->ebase;
    for (uint32_t e = 0; e < J->t->ne; e++) {
        uint32_t k = ring_len(J, e);
        if (k) {
            memcpy(J->col + at, ring_of(J, e), k * sizeof *J->col);
            at += k;
        }
    }
}

/* ---- Ying-Zorin petals (003 Sec. 2) --------------------------------------------------------
 * At a singular vertex v (a Ying-Zorin crease or corner vertex), the maximal triangles around v
 * fall into petals, joined across non-singular edges (between exactly two triangles, no tag).
 * A non-singular edge v-w of a petal with k triangles takes the piecewise smooth rule (003
 * Fig. 4f): (3/4 - g) v + g w + 1/8 (c + d), g = 1/2 - cos(theta)/4, with theta = 2 pi/k for a
 * dart petal (one singular edge), pi/k for an open petal of a simple vertex, and for an open
 * petal of a complex vertex by its tag (sd_complex_set_petals): alpha/k for a convex corner (the
 * default), (2 pi - alpha)/k for a concave one, pi/k for a smooth one (alpha the angle between
 * the petal's two singular edges, measured on the level's positions when the rules are built).
 * A closed petal takes the Loop rule, and closed, dart and concave petals at a complex vertex
 * (fixed) then the flatness modification (yz.c). An edge with a singular vertex at both ends
 * takes the average of the two (003: on the first level). */
/* The tag of the petal of v holding face f of level `level` (its level-0 ancestor is f >> 2
 * per level: a face's children are 4 f + j). */
static int petal_tag(const sd_complex *cx, int level, uint32_t v, uint32_t f)
{
    uint32_t f0 = f >> (2 * level);
    size_t lo = 0, hi = cx->npet;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        const sd_petal_at *p = &cx->pet[mid];
        if (p->v < v || (p->v == v && p->f < f0))
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < cx->npet && cx->pet[lo].v == v && cx->pet[lo].f == f0 ? cx->pet[lo].kind
                                                                       : SD_PETAL_CONVEX;
}

/* A vertex that takes Ying-Zorin's petal rules: a crease or corner vertex of the Ying-Zorin
 * rules without a tag (tags win: the vertex follows them). */
static inline bool yz_vertex(const sd_topo *t, uint32_t v)
{
    return nm_ov(t->vnm[v]) >= OV_YZS && !(t->vflag[v] & (VF_SING | VF_S_ANY));
}

/* The angle between the singular edges v-a and v-c (0 to pi), from the level's positions x. */
static double petal_angle(const double *x, uint32_t v, uint32_t a, uint32_t c)
{
    const double *p = x + 3 * (size_t)v, *pa = x + 3 * (size_t)a, *pc = x + 3 * (size_t)c;
    double u[3], w[3], dot = 0, nu = 0, nw = 0;
    for (int d = 0; d < 3; d++) {
        u[d] = pa[d] - p[d];
        w[d] = pc[d] - p[d];
        dot += u[d] * w[d];
        nu += u[d] * u[d];
        nw += w[d] * w[d];
    }
    double cs = nu > 0 && nw > 0 ? dot / sqrt(nu * nw) : -1;
    return acos(cs < -1 ? -1 : cs > 1 ? 1 : cs);
}

/* The rule at v of the inner edges of v's petal p (kind: its tag): 003 Fig. 4f's theta and g, and
 * whether the flatness modification follows (yz.c). Marks in *geo the points whose positions it
 * read (false: no memory for geo). */
static bool yz_petal_end(sd_mem *m, const sd_topo *t, const double *x, uint32_t v,
                         const sdi_petal *p, int kind, uint8_t **geo, sd_yzend *end)
{
    const bool fixed = nm_ov(t->vnm[v]) == OV_YZX; /* a complex vertex: a corner */
    const uint32_t kk = p->nf, ns = p->nsing;
    double theta;
    end->kind = SD_YZ_FIRST;
    end->s = SD_YZ_FLAT_S;
    if (ns == 0) { /* closed petal: the fixed-disk rule (yz.c) */
        end->kind = SD_YZ_DISK;
        theta = M_PI / 3;
    } else if (ns == 1) { /* dart: flattened where the centre is fixed (yz.c) */
        theta = 2 * M_PI / kk;
        if (fixed)
            end->kind = SD_YZ_DART;
    } else if (ns == 2 && fixed && kind != SD_PETAL_SMOOTH) {
        uint32_t a = t->ev[p->sing[0]][0] == v ? t->ev[p->sing[0]][1] : t->ev[p->sing[0]][0];
        uint32_t c = t->ev[p->sing[1]][0] == v ? t->ev[p->sing[1]][1] : t->ev[p->sing[1]][0];
        double alpha = petal_angle(x, v, a, c);
        if (!*geo && !(*geo = sdi_calloc(m, t->nv, 1)))
            return false;
        (*geo)[v] = (*geo)[a] = (*geo)[c] = 1;
        if (kind == SD_PETAL_CONCAVE) {
            theta = (2 * M_PI - alpha) / kk;
            /* the flatness modification divides by sin(k theta) = -sin(alpha): with the
             * singular edges in line it has no tangent plane to flatten to, and near
             * that s fades (SD_YZ_RAMP) so the rule stays continuous in alpha */
            double q = sin(alpha) / SD_YZ_RAMP, fs = SD_YZ_FLAT_S * (q < 1 ? q * q : 1);
            if (fs > 1e-20 && kk >= 2) { /* else (sin alpha < 1e-11) the first stage */
                end->kind = SD_YZ_CONCAVE;
                end->s = fs;
            }
        } else {
            theta = alpha / kk;
        }
    } else { /* an open petal of a simple vertex, or a smooth one */
        theta = M_PI / kk;
    }
    end->theta = theta;
    end->g = 0.5 - cos(theta) / 4;
    return true;
}

/* The Ying-Zorin rule of each end of every edge (gam[e][i], SD_YZ_NONE where end i is not a
 * singular vertex): each petal of each singular vertex walked once (petals.c), its tag that of
 * its last triangle tagged otherwise than convex. */
static bool yz_gammas(sd_mem *m, const sd_complex *cx, int level, const sd_topo *t,
                      const sdi_rels *R, const double *x, sd_yzend (*gam)[2], uint8_t **geo)
{
    const sdi_rel *vf = &R->r[SDI_VF], *ef = &R->r[SDI_EF];
    const uint32_t cap = t->nf + 2;
    uint32_t *face = sdi_alloc(m, (size_t)cap * sizeof *face);
    uint32_t *inner = sdi_alloc(m, (size_t)cap * sizeof *inner);
    uint8_t *done = sdi_calloc(m, (size_t)t->nf + 1, 1); /* faces of v already in a petal */
    bool ok = false;
    memset(gam, 0, (size_t)t->ne * sizeof *gam); /* SD_YZ_NONE */
    if (!face || !inner || !done)
        goto out;
    for (uint32_t v = 0; v < t->nv; v++) {
        if (!yz_vertex(t, v))
            continue;
        for (uint32_t k = vf->off[v]; k < vf->off[v + 1]; k++) {
            uint32_t f = vf->item[k];
            if (!(t->fflag[f] & FF_MAX) || done[f])
                continue;
            sdi_petal p = {.face = face, .inner = inner, .cap = cap};
            done[f] = 1;
            if (!sdi_petal_of(t, ef, SDI_PETAL_YZ, v, f, &p))
                continue;
            int kind = SD_PETAL_CONVEX;
            uint32_t last = 0;
            for (uint32_t i = 0; i < p.nf; i++) {
                done[p.face[i]] = 1;
                int pk = cx->npet ? petal_tag(cx, level, v, p.face[i]) : SD_PETAL_CONVEX;
                if (pk != SD_PETAL_CONVEX && p.face[i] >= last) {
                    kind = pk;
                    last = p.face[i];
                }
            }
            sd_yzend end;
            if (p.ninner && !yz_petal_end(m, t, x, v, &p, kind, geo, &end))
                goto out;
            for (uint32_t i = 0; i < p.ninner; i++) {
                uint32_t e = p.inner[i];
                gam[e][t->ev[e][0] == v ? 0 : 1] = end;
            }
        }
        for (uint32_t k = vf->off[v]; k < vf->off[v + 1]; k++)
            done[vf->item[k]] = 0;
    }
    ok = true;
out:
    sdi_free(m, face);
    sdi_free(m, inner);
    sdi_free(m, done);
    return ok;
}

sd_result sdi_build_rules(sd_complex *cx, sd_level *lv, sd_error *err)
{
    sd_mem *m = &cx->mem;
    const sd_topo *t = &lv->t;
    const int weights = cx->opt.surface_weights, scheme = cx->opt.solid_scheme;
    const int threads = cx->opt.threads;
    const uint32_t nv = t->nv, ne = t->ne, no = t->noct;
    uint32_t *cnt_a = NULL, *cnt_b = NULL, *cur;
    uint32_t(*opp)[2] = NULL;
    uint8_t *nopp = NULL;
    double *wbuf = NULL;
    uint32_t wcap = 64;
    uint8_t *take = NULL;   /* per edge: which end reads the other through it */
    sd_yzend (*gam)[2] = NULL; /* Ying-Zorin petal rules per edge end (yz_gammas) */
    sd_pats pats = {0};
    rings sr = {0}, gr = {0};
    sd_yzrows yzr = {0};
    sdi_rels R = {.t = t};
    sd_result rc = SD_OK;
    double loopc[64];
    for (uint32_t k = 1; k < 64; k++)
        loopc[k] = loop_weight(weights, k);
    loopc[0] = 0;

    uint64_t nrows = (uint64_t)nv + ne + no;
    if (nrows >= UINT32_MAX)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1, "too many points for 32-bit ids");
    lv->vrule = sdi_alloc(m, (size_t)nv + 1);
    lv->erule = sdi_alloc(m, (size_t)ne + 1);
    cnt_a = sdi_calloc(m, nv, sizeof *cnt_a);
    if (scheme == SD_SOLID_AVERAGED && (t->ntet || no))
        cnt_b = sdi_calloc(m, nv, sizeof *cnt_b);
    take = sdi_alloc(m, (size_t)ne + 1);
    if (!lv->vrule || !lv->erule || !cnt_a || (!cnt_b && scheme == SD_SOLID_AVERAGED && (t->ntet || no)) || !take)
        goto nomem;
    uint8_t *vr = lv->vrule, *er = lv->erule;
    rjob J = {.t = t, .scheme = scheme, .vr = vr, .er = er, .take = take, .cnt_a = cnt_a,
              .cnt_b = cnt_b, .sr = &sr, .gr = &gr, .yz = &yzr};
    sdi_par(threads, ne, erule_part, &J);
    bool any_g2e = false, any_opp = false;
    for (uint32_t i = 0; i < sdi_par_parts(threads, ne); i++) {
        any_g2e |= J.any_g2e[i];
        any_opp |= J.any_opp[i];
    }
    if (any_opp) {
        J.opp = opp = sdi_alloc(m, (size_t)ne * sizeof *opp);
        J.nopp = nopp = sdi_alloc(m, (size_t)ne + 1);
        if (!opp || !nopp)
            goto nomem;
    }
    /* vertex rules and rho sizes, and the edges' opposite vertices, at once */
    sdi_par2(threads, nv + (uint64_t)ne, vrules_task, &J, opp_task, &J);
    if ((t->ntet || no) && !solid_rings(m, t, er, scheme, threads, &sr))
        goto nomem;
    if (any_g2e && !g2_rings(m, t, er, &gr))
        goto nomem;
    J.stride = any_opp && !t->ntet && !no && !any_g2e;
    if (t->ovmask & OVM_YZ) { /* Ying-Zorin petal rules for the edges at singular vertices */
        gam = sdi_alloc(m, ((size_t)ne + 1) * sizeof *gam);
        if (!gam || !sdi_rels_need(m, &R, SDI_REL(SDI_VF) | SDI_REL(SDI_EF)) ||
            !yz_gammas(m, cx, lv->index, t, &R, lv->ch[0].data, gam, &lv->geo) ||
            !sdi_yz_flat_rows(m, t, &R.r[SDI_EF], (const sd_yzend(*)[2])gam, er, &yzr))
            goto nomem;
        if (yzr.n) /* flattened rows are wider than two opposite vertices */
            J.stride = false;
    }

    /* sizes and weight patterns of the rows: a vertex row is [self, a x |rho|, b x octahedral
     * opposites], an edge row [end, end, ring...]; the common ones are memoized by rule and
     * size. cur[v] (in cnt_a's place): where v's rho goes in col. */
    cur = cnt_a;
    wbuf = sdi_alloc(m, (size_t)wcap * sizeof *wbuf);
    if (!wbuf || !sdi_csrb_init(m, &lv->S, nv, ne, no, nv, t->ev, t->oct))
        goto nomem;
#define WBUF(n)                                                                                    \
    do {                                                                                           \
        if ((n) > wcap) {                                                                          \
            double *w_ = sdi_realloc(m, wbuf, (size_t)(n) * sizeof *wbuf);                          \
            if (!w_)                                                                               \
                goto nomem;                                                                        \
            wbuf = w_;                                                                             \
            wcap = (n);                                                                            \
        }                                                                                          \
    } while (0)
    enum { MEMO = 64 };
    uint32_t vmemo[SD_RULE_COUNT][MEMO], ememo[SD_RULE_COUNT][MEMO];
    memset(vmemo, 0xff, sizeof vmemo);
    memset(ememo, 0xff, sizeof ememo);
    size_t *kchk = lv->S.kchk;
    uint64_t nexp = 0, nring = 0;
    for (uint32_t v = 0; v < nv; v++) {
        uint32_t na = cnt_a[v], nb = cnt_b ? cnt_b[v] : 0, id = UINT32_MAX;
        if (v % SD_CHK == 0)
            kchk[v / SD_CHK] = nexp;
        cur[v] = (uint32_t)nexp;
        nexp += na + nb;
        bool memo = nb == 0 && na < MEMO;
        if (memo)
            id = vmemo[vr[v]][na];
        if (id == UINT32_MAX) {
            vw w = vertex_weights(vr[v], weights, scheme, na, nb, loopc);
            WBUF(1 + na + nb);
            wbuf[0] = w.self;
            for (uint32_t i = 0; i < na; i++)
                wbuf[1 + i] = w.a;
            for (uint32_t i = 0; i < nb; i++)
                wbuf[1 + na + i] = w.b;
            if ((id = sdi_pats_intern(m, &pats, wbuf, 1 + na + nb)) == UINT32_MAX)
                goto nomem;
            if (memo)
                vmemo[vr[v]][na] = id;
        }
        if (!sdi_csrb_set_pat(m, &lv->S, v, id))
            goto nomem;
    }
    J.ebase = nexp;
    for (uint32_t e = 0; e < ne; e++) {
        uint32_t k = ring_len(&J, e), r = nv + e;
        if (r % SD_CHK == 0)
            kchk[r / SD_CHK] = nexp;
        nring += k;
        if (!J.stride)
            nexp += k;
        const uint8_t *cls = er[e] == SD_RULE_SOLID && scheme == SD_SOLID_AVERAGED
                             ? sr.cls + sr.off[e] : NULL;
        bool petal = gam && er[e] == SD_RULE_LOOP && k == 2 &&
                     (gam[e][0].kind == SD_YZ_FIRST || gam[e][1].kind == SD_YZ_FIRST);
        bool flat = er[e] == SD_RULE_YZ_FIXED_DISK || er[e] == SD_RULE_YZ_DART ||
                    er[e] == SD_RULE_YZ_CONCAVE;
        bool memo = !cls && k < MEMO && !petal && !flat;
        uint32_t id = memo ? ememo[er[e]][k] : UINT32_MAX;
        if (flat) { /* yz.c */
            WBUF(2 + k);
            wbuf[0] = yzr.ends[e][0];
            wbuf[1] = yzr.ends[e][1];
            memcpy(wbuf + 2, yzr.w + yzr.off[e], k * sizeof *wbuf);
            if ((id = sdi_pats_intern(m, &pats, wbuf, 2 + k)) == UINT32_MAX)
                goto nomem;
        } else if (petal) { /* 003 Fig. 4f from each singular end, averaged where both are */
            double w0 = 0, w1 = 0;
            int sides = 0;
            for (int i = 0; i < 2; i++)
                if (gam[e][i].kind == SD_YZ_FIRST) {
                    double g = gam[e][i].g;
                    w0 += i == 0 ? 0.75 - g : g;
                    w1 += i == 0 ? g : 0.75 - g;
                    sides++;
                }
            WBUF(4);
            wbuf[0] = w0 / sides;
            wbuf[1] = w1 / sides;
            wbuf[2] = wbuf[3] = 1.0 / 8.0;
            if ((id = sdi_pats_intern(m, &pats, wbuf, 4)) == UINT32_MAX)
                goto nomem;
        }
        if (id == UINT32_MAX) {
            double wend = 0.5, wring = 0, wdiag = 0;
            switch (er[e]) {
            case SD_RULE_LOOP:
            case SD_RULE_SOLID_BOUNDARY:
                if (k == 2) {
                    wend = 3.0 / 8.0;
                    wring = 1.0 / 8.0;
                }
                break;
            case SD_RULE_SOLID:
                if (cls) {
                    uint32_t nf = 0, nd = 0;
                    for (uint32_t i = 0; i < k; i++)
                        cls[i] ? nd++ : nf++;
                    double d = 4.0 * nf + nd;
                    wend = 7.0 / 24.0;
                    wring = 5.0 / 12.0 * 4.0 / d;
                    wdiag = 5.0 / 12.0 / d;
                } else {
                    solid_edge_weights(k, &wend, &wring);
                }
                break;
            case SD_RULE_G2:
                if (k)
                    solid_edge_weights(k, &wend, &wring);
                break;
            default:
                break;
            }
            WBUF(2 + k);
            wbuf[0] = wbuf[1] = wend;
            for (uint32_t i = 0; i < k; i++)
                wbuf[2 + i] = cls && cls[i] ? wdiag : wring;
            if ((id = sdi_pats_intern(m, &pats, wbuf, 2 + k)) == UINT32_MAX)
                goto nomem;
            if (memo)
                ememo[er[e]][k] = id;
        }
        if (!sdi_csrb_set_pat(m, &lv->S, nv + e, id))
            goto nomem;
    }
    /* cell points of octahedra (all implicit): box 1/4 on the diagonal, 1/8 on the rest;
     * averaged: centroid */
    for (uint64_t r = (uint64_t)nv + ne; r < nrows; r++)
        if (r % SD_CHK == 0)
            kchk[r / SD_CHK] = nexp;
    kchk[(nrows + SD_CHK - 1) / SD_CHK] = nexp;
    if (no) {
        for (int i = 0; i < 6; i++)
            wbuf[i] = scheme == SD_SOLID_AVERAGED ? 1.0 / 6.0 : (i < 2 ? 0.25 : 0.125);
        uint32_t id = sdi_pats_intern(m, &pats, wbuf, 6);
        if (id == UINT32_MAX)
            goto nomem;
        for (uint32_t o = 0; o < no; o++)
            if (!sdi_csrb_set_pat(m, &lv->S, nv + ne + o, id))
                goto nomem;
    }
#undef WBUF
    uint64_t nnz = (nexp - (J.stride ? 0 : nring)) + nring + nv + 2ull * ne + 6ull * no;
    if (nnz >= UINT32_MAX) {
        rc = sdi_fail(err, SD_ERR_LIMIT, -1, -1, "subdivision matrix too large for 32-bit offsets");
        goto fail;
    }
    lv->S.nexp = nexp;
    J.col = lv->S.col = sdi_alloc(m, (nexp + 1) * sizeof *lv->S.col);
    J.cur = cur;
    if (!lv->S.col || !sdi_csrb_finish(m, &lv->S, &pats, nnz))
        goto nomem;
    if (J.stride) { /* the opposite vertices are the edge rows' explicit columns as they are */
        lv->S.eopp = opp;
        opp = NULL;
    }
    /* the columns: vertex rows and edge rows at once */
    sdi_par2(threads, nexp, vrows_task, &J, erows_task, &J);

    lv->have_rules = true;
    goto out;

nomem:
    rc = sdi_fail_nomem(err, m);
fail:
    sdi_free(m, lv->vrule);
    sdi_free(m, lv->erule);
    sdi_free(m, lv->geo);
    lv->vrule = lv->erule = lv->geo = NULL;
    sdi_csrb_free(m, &lv->S);
out:
    sdi_pats_free(m, &pats);
    sdi_free(m, take);
    sdi_free(m, gam);
    sdi_free(m, wbuf);
    sdi_free(m, cnt_a);
    sdi_free(m, cnt_b);
    sdi_free(m, opp);
    sdi_free(m, nopp);
    rings_free(m, &sr);
    rings_free(m, &gr);
    sdi_yzrows_free(m, &yzr);
    sdi_rels_free(m, &R);
    return rc;
}
