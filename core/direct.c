/* direct.c — S_l applied without being made: level l+1's points straight from level l's rules
 * and neighbourhoods, for batch refinement (sd_options.edit_index LAZY, nothing edited yet).
 *
 * Where every row of S_l is its rule's mask over rho or over the edge's ends and opposite
 * vertices — a level without solids, G2 rings, Ying-Zorin rows, semi-sharp creases or
 * tangent-plane constraints — a row's weights depend on its rule and size only, and its columns
 * are the ones stencil.c would write: a vertex row is [self, rho in edge order], an edge row
 * [end 0, end 1, the opposite vertices in face order]. So each point is summed here term by term
 * in its row's order, with the weights sdi_vertex_mask and sdi_edge_mask give: a vertex point
 * starts from its own term and each edge that feeds it adds its neighbour's term in edge order (a
 * scatter in which every point's sums keep the row's order), an edge point sums its row in
 * place. The bytes are those of S applied (tests/core/test_direct.c compares every level with the
 * path through S), without the patterns, rho's columns and the matrix itself; the rules, rho's
 * sizes and the opposite vertices are computed as stencil.c does, and the vertex rules kept
 * (vrule_only: what sd_level_vertex_rule reads). S is made later if anything asks for it
 * (sdi_ensure_rules: classes, the matrix, limits, edits).
 *
 * A plain level — a closed surface of triangles, no tags or per-simplex rules, every vertex and
 * edge following Loop's rule over all its neighbours and every edge between two triangles —
 * splits into a plain level whose rules need not be found again: every rule is Loop's, a vertex
 * point has its vertex's valence and an edge point 6, and an edge's opposite vertices are the
 * third vertices of its two faces in face order. A plain level's valences go to the next level
 * (sdi_plain) while one sd_complex_level call makes both, and so do the faces of its edges
 * (split.c's numbering gives the child's from them): the passes then work by ranges of items,
 * those whose results do not depend on the cut in more parts than threads (DECISIONS 51).
 */
#include "internal.h"
#include <string.h>

bool sdi_direct_ok(const sd_complex *c, const sd_level *p)
{
    const sd_topo *t = &p->t;
    return c->opt.edit_index == SD_EDIT_INDEX_LAZY && !c->edit_indexed && !p->have_rules &&
           !t->ntet && !t->noct && !(t->ovmask & OVM_YZ) && !c->ntt && !c->sh.ne && !c->sh.nv &&
           !c->sh.nf;
}

enum { MEMO = SDI_LOOP_CACHE }; /* vertex weights memoized by rule and rho's size below this */

typedef struct dweights {
    double w0, w1, wr;
    bool set;
} dweights;

typedef struct djob {
    const sd_topo *t;
    int weights, scheme;
    const uint8_t *vr, *er, *take, *nopp;
    const uint32_t *cnt;
    const uint32_t (*opp)[2];
    const double *loopc;
    double *wa;               /* per vertex: the weight of each of its rho */
    bool plain;               /* every take 3, rule Loop, ring two opposite vertices */
    /* a plain level split from a plain parent P whose faces are known (structured passes): per
     * parent edge, the inside-edge neighbours of its edge point, two per parent face in order */
    const sd_topo *P;
    const uint32_t (*enb)[4];
    /* and when P is itself the split of a plain level PP whose edges' faces are known (efpp:
     * 3 f + j per face of the edge, in face order): P's edge points' vertex rows gathered */
    const sd_topo *PP;
    const uint32_t (*efpp)[2];
    uint32_t ninit;           /* vertices init_part starts (all, or P's vertex points) */
    const double *in;
    double *out;
    int nc;
} djob;

/* The weights of a vertex row of rule r and rho of na: self and each of rho. */
static sdi_vmask vmask(const djob *J, uint8_t r, uint32_t na)
{
    sdi_vnb nbh = {na, 0, J->weights, J->scheme, J->loopc};
    return sdi_vertex_mask(r, &nbh);
}

/* Vertex points' first term (their own) and each vertex's rho weight, by ranges of vertices. */
static void init_part(void *arg, uint32_t part, uint32_t nparts)
{
    const djob *J = arg;
    const int nc = J->nc;
    const double *in = J->in;
    double *out = J->out, *wa = J->wa;
    uint64_t lo, hi;
    sdi_range(J->ninit, part, nparts, &lo, &hi);
    double ms[SD_RULE_COUNT][MEMO], ma[SD_RULE_COUNT][MEMO];
    bool have[SD_RULE_COUNT][MEMO];
    memset(have, 0, sizeof have);
    for (uint32_t v = (uint32_t)lo; v < hi; v++) {
        uint8_t r = J->vr[v];
        uint32_t na = J->cnt[v];
        double s, a;
        if (na < MEMO && have[r][na]) {
            s = ms[r][na];
            a = ma[r][na];
        } else {
            sdi_vmask w = vmask(J, r, na);
            s = w.self;
            a = w.a;
            if (na < MEMO) {
                ms[r][na] = s;
                ma[r][na] = a;
                have[r][na] = true;
            }
        }
        wa[v] = a;
        for (int j = 0; j < nc; j++) {
            double x = 0; /* as a row sums: from 0, its terms in order */
            x += s * in[(size_t)nc * v + j];
            out[(size_t)nc * v + j] = x;
        }
    }
}

/* Three components: x and y in one SSE2 register, z apart (the same operations per component,
 * so the same bytes as the scalar sums). */
#ifdef __SSE2__
#include <emmintrin.h>
typedef struct p3 {
    __m128d xy;
    double z;
} p3;
static inline p3 p3_load(const double *p) { return (p3){_mm_loadu_pd(p), p[2]}; }
static inline void p3_store(double *p, p3 a)
{
    _mm_storeu_pd(p, a.xy);
    p[2] = a.z;
}
static inline p3 p3_zero(void) { return (p3){_mm_setzero_pd(), 0.0}; }
/* a + w b */
static inline p3 p3_madd(p3 a, double w, p3 b)
{
    return (p3){_mm_add_pd(a.xy, _mm_mul_pd(_mm_set1_pd(w), b.xy)), a.z + w * b.z};
}
#else
typedef struct p3 {
    double x, y, z;
} p3;
static inline p3 p3_load(const double *p) { return (p3){p[0], p[1], p[2]}; }
static inline void p3_store(double *p, p3 a)
{
    p[0] = a.x;
    p[1] = a.y;
    p[2] = a.z;
}
static inline p3 p3_zero(void) { return (p3){0.0, 0.0, 0.0}; }
static inline p3 p3_madd(p3 a, double w, p3 b)
{
    return (p3){a.x + w * b.x, a.y + w * b.y, a.z + w * b.z};
}
#endif

/* A row's terms in order, as csr.c sums them: o += w p (three components in SSE2). */
static inline __attribute__((always_inline)) void add_term(double *o, double w, const double *p,
                                                            int nc)
{
    if (nc == 3) {
        p3_store(o, p3_madd(p3_load(o), w, p3_load(p)));
        return;
    }
    for (int j = 0; j < nc; j++)
        o[j] += w * p[j];
}

/* An edge row: o = 0 + w0 a + w1 b, then + wr c + wr d where the ring is c, d (c not NULL). */
static inline __attribute__((always_inline)) void
edge_sum(double *o, const dweights *w, const double *a, const double *b, const double *c,
         const double *d, int nc)
{
    if (nc == 3) {
        p3 x = p3_madd(p3_madd(p3_zero(), w->w0, p3_load(a)), w->w1, p3_load(b));
        if (c)
            x = p3_madd(p3_madd(x, w->wr, p3_load(c)), w->wr, p3_load(d));
        p3_store(o, x);
        return;
    }
    for (int j = 0; j < nc; j++) {
        double x = 0;
        x += w->w0 * a[j];
        x += w->w1 * b[j];
        if (c) {
            x += w->wr * c[j];
            x += w->wr * d[j];
        }
        o[j] = x;
    }
}

/* The weights of an edge row of rule r and ring size k (memo: per rule and k, unset first). */
static inline const dweights *edge_weights(dweights (*memo)[3], uint8_t r, uint32_t k)
{
    dweights *w = &memo[r][k];
    if (!w->set) {
        sdi_enb nbh = {k, NULL};
        sdi_emask m = sdi_edge_mask(r, &nbh);
        *w = (dweights){m.end[0], m.end[1], m.ring, true};
    }
    return w;
}

/* Every edge in order adds to its ends' vertex points (those in [vlo, vhi), or all) the terms of
 * the neighbours they read through it; edge points of [elo, ehi) are summed on the way. plain:
 * see the top (no er, take or nopp read). */
static inline __attribute__((always_inline)) void
edges_of(const djob *J, bool plain, uint32_t vlo, uint32_t vhi, uint32_t elo, uint32_t ehi,
         bool all, int nc)
{
    const sd_topo *t = J->t;
    const uint8_t *vr = J->vr, *take = J->take, *er = J->er, *nopp = J->nopp;
    const uint32_t(*opp)[2] = J->opp;
    const double *in = J->in, *wa = J->wa;
    double *out = J->out, *eout = J->out + (size_t)nc * t->nv;
    dweights memo[SD_RULE_COUNT][3];
    memset(memo, 0, sizeof memo);
#define MINE(v) (all || ((v) >= vlo && (v) < vhi))
    for (uint32_t e = 0; e < t->ne; e++) {
        uint32_t a = t->ev[e][0], b = t->ev[e][1];
        const double *pa = in + (size_t)nc * a, *pb = in + (size_t)nc * b;
        if (MINE(a) && (plain || ((take[e] & 1) && vr[a] != SD_RULE_CORNER)))
            add_term(out + (size_t)nc * a, wa[a], pb, nc);
        if (MINE(b) && (plain || ((take[e] & 2) && vr[b] != SD_RULE_CORNER)))
            add_term(out + (size_t)nc * b, wa[b], pa, nc);
        if (!all && (e < elo || e >= ehi))
            continue;
        uint8_t r = plain ? (uint8_t)SD_RULE_LOOP : er[e];
        uint32_t k = plain ? 2u : sdi_opp_ring_len(r, nopp[e]);
        edge_sum(eout + (size_t)nc * e, edge_weights(memo, r, k), pa, pb,
                 k ? in + (size_t)nc * opp[e][0] : NULL, k ? in + (size_t)nc * opp[e][1] : NULL, nc);
    }
#undef MINE
}

/* edges_of written for three components, plain or not, and for any other count. */
static inline __attribute__((always_inline)) void
edges_run(const djob *J, uint32_t vlo, uint32_t vhi, uint32_t elo, uint32_t ehi, bool all)
{
    if (J->nc == 3 && J->plain)
        edges_of(J, true, vlo, vhi, elo, ehi, all, 3);
    else if (J->nc == 3)
        edges_of(J, false, vlo, vhi, elo, ehi, all, 3);
    else
        edges_of(J, J->plain, vlo, vhi, elo, ehi, all, J->nc);
}

static void edges_part(void *arg, uint32_t part, uint32_t nparts)
{
    const djob *J = arg;
    if (nparts == 1) {
        edges_run(J, 0, 0, 0, 0, true);
        return;
    }
    uint64_t vlo, vhi, elo, ehi;
    sdi_range(J->t->nv, part, nparts, &vlo, &vhi);
    sdi_range(J->t->ne, part, nparts, &elo, &ehi);
    edges_run(J, (uint32_t)vlo, (uint32_t)vhi, (uint32_t)elo, (uint32_t)ehi, false);
}

/* The structured passes of a plain level split from a plain parent P (pnv vertices, pne edges):
 * its vertex points' rows read the edge points of P's edges at them, in P's edge order (their
 * halves come in that order); an edge point's row reads the ends of its edge (halves 2e, 2e+1),
 * then two points per face of its edge (enb): summed whole in place. Parts: edge points and the
 * rows of this level's edges by ranges (cut anywhere, so in more parts than threads: a thread on
 * a busier core takes fewer), vertex points by ranges reading all of P's edges. */
/* f(..., nc) compiled for three components apart (the usual positions) and for any count. */
#define BY_NC(nc, f, ...) ((nc) == 3 ? f(__VA_ARGS__, 3) : f(__VA_ARGS__, (nc)))

static inline __attribute__((always_inline)) void
epoints(const djob *J, uint32_t e0, uint32_t e1, int nc)
{
    const sd_topo *P = J->P;
    const uint32_t pnv = P->nv;
    const uint32_t(*pev)[2] = P->ev, (*enb)[4] = J->enb;
    const double *in = J->in;
    double *out = J->out;
    const sdi_vmask w6 = vmask(J, SD_RULE_LOOP, 6); /* every edge point's */
    const double s6 = w6.self, a6 = w6.a;
    for (uint32_t pe = e0; pe < e1; pe++) { /* edge points */
        const uint32_t m = pnv + pe, *q = enb[pe];
        const double *pm = in + (size_t)nc * m, *pa = in + (size_t)nc * pev[pe][0],
                     *pb = in + (size_t)nc * pev[pe][1], *q0 = in + (size_t)nc * q[0],
                     *q1 = in + (size_t)nc * q[1], *q2 = in + (size_t)nc * q[2],
                     *q3 = in + (size_t)nc * q[3];
        double *o = out + (size_t)nc * m;
        for (int j = 0; j < nc; j++) {
            double x = 0;
            x += s6 * pm[j];
            x += a6 * pa[j];
            x += a6 * pb[j];
            x += a6 * q0[j];
            x += a6 * q1[j];
            x += a6 * q2[j];
            x += a6 * q3[j];
            o[j] = x;
        }
    }
}

/* Edge points by ranges of P's edges (any cut: each row its own). */
static void epoints_part(void *arg, uint32_t part, uint32_t nparts)
{
    const djob *J = arg;
    uint64_t e0, e1;
    sdi_range(J->P->ne, part, nparts, &e0, &e1);
    BY_NC(J->nc, epoints, J, (uint32_t)e0, (uint32_t)e1);
}

/* With PP known, P's vertices are PP's vertices and PP's edge points. The edges of P at the edge
 * point m of PP's edge e, in P's edge order: the halves 2e, 2e+1, then per face f of e (in
 * order; e its edge j) the inside edges 3f + j and 3f + j+1 (mod 3) after PP's halves. Their
 * vertex points' rows are gathered in that order, by ranges of edge points (any cut). */
static inline __attribute__((always_inline)) void vgather(const djob *J, uint32_t e0, uint32_t e1,
                                                          int nc)
{
    const uint32_t pnv = J->P->nv, qnv = J->PP->nv, qne = J->PP->ne;
    const uint32_t(*efpp)[2] = J->efpp;
    const double *in = J->in + (size_t)nc * pnv, *wa = J->wa; /* in: P's edge points */
    double *out = J->out;
    for (uint32_t e = e0; e < e1; e++) {
        const uint32_t v = qnv + e;
        uint32_t id[6] = {2 * e, 2 * e + 1};
        for (int s = 0; s < 2; s++) {
            uint32_t f = efpp[e][s] / 3, j = efpp[e][s] % 3, b = 2 * qne + 3 * f;
            id[2 + 2 * s] = b + (j == 2 ? 0 : j);
            id[3 + 2 * s] = b + (j == 2 ? 2 : j + 1);
        }
        const double w = wa[v];
        double *o = out + (size_t)nc * v;
        for (int j = 0; j < nc; j++) {
            double x = o[j];
            for (int k = 0; k < 6; k++)
                x += w * in[(size_t)nc * id[k] + j];
            o[j] = x;
        }
    }
}

static void vgather_part(void *arg, uint32_t part, uint32_t nparts)
{
    const djob *J = arg;
    uint64_t e0, e1;
    sdi_range(J->PP->ne, part, nparts, &e0, &e1);
    BY_NC(J->nc, vgather, J, (uint32_t)e0, (uint32_t)e1);
}

/* Vertex points' rows by scattering, in edge order, the edge points of the edges at them: P's
 * vertices' from P's edges (edge e's own point), or, with PP known, only PP's vertices' from
 * PP's edges (at end k of edge e, the point of P's half 2e + k: a vertex of PP is on halves
 * only). By ranges of vertices, each part reading all of those edges, so in as many parts as
 * threads. */
static inline __attribute__((always_inline)) void vscatter(const djob *J, uint32_t v0, uint32_t v1,
                                                           bool all, int nc)
{
    const bool halves = J->PP != NULL;
    const sd_topo *S = halves ? J->PP : J->P;
    const uint32_t ne = S->ne;
    const uint32_t(*ev)[2] = S->ev;
    const double *in = J->in + (size_t)nc * J->P->nv, *wa = J->wa; /* in: P's edge points */
    double *out = J->out;
    for (uint32_t e = 0; e < ne; e++)
        for (uint32_t k = 0; k < 2; k++) {
            uint32_t v = ev[e][k];
            if (!all && (v < v0 || v >= v1))
                continue;
            const double *pm = in + (size_t)nc * (halves ? 2 * e + k : e);
            for (int j = 0; j < nc; j++)
                out[(size_t)nc * v + j] += wa[v] * pm[j];
        }
}

static void vscatter_part(void *arg, uint32_t part, uint32_t nparts)
{
    const djob *J = arg;
    uint64_t v0, v1;
    sdi_range((J->PP ? J->PP : J->P)->nv, part, nparts, &v0, &v1);
    BY_NC(J->nc, vscatter, J, (uint32_t)v0, (uint32_t)v1, nparts == 1);
}

/* The rows of this level's edges: ends and opposite vertices. */
static void erows_part(void *arg, uint32_t part, uint32_t nparts)
{
    const djob *J = arg;
    const sd_topo *t = J->t;
    const int nc = J->nc;
    const uint32_t(*ev)[2] = t->ev, (*opp)[2] = J->opp;
    const double *in = J->in;
    double *eout = J->out + (size_t)nc * t->nv;
    dweights memo[SD_RULE_COUNT][3];
    memset(memo, 0, sizeof memo);
    const dweights *w = edge_weights(memo, SD_RULE_LOOP, 2);
    uint64_t lo, hi;
    sdi_range(t->ne, part, nparts, &lo, &hi);
    for (uint32_t e = (uint32_t)lo; e < hi; e++) {
        const double *pa = in + (size_t)nc * ev[e][0], *pb = in + (size_t)nc * ev[e][1],
                     *p0 = in + (size_t)nc * opp[e][0], *p1 = in + (size_t)nc * opp[e][1];
        if (nc == 3)
            edge_sum(eout + 3 * (size_t)e, w, pa, pb, p0, p1, 3);
        else
            edge_sum(eout + (size_t)nc * e, w, pa, pb, p0, p1, nc);
    }
}

/* Conditions of a plain level the rules do not show: no tags, per-simplex rules or petals, no
 * curves or points. */
static bool complex_plain(const sd_complex *c, const sd_topo *t)
{
    return !c->ntags && !c->nov && !c->npet && !t->ovmask && !t->ncu && !t->npt;
}

/* ... and those they show (found by the general path). */
static bool rules_plain(const sd_topo *t, const uint8_t *vr, const uint8_t *er, const uint8_t *take,
                        const uint8_t *nopp, bool any_opp)
{
    if (!any_opp)
        return false;
    for (uint32_t v = 0; v < t->nv; v++)
        if (vr[v] != SD_RULE_LOOP)
            return false;
    for (uint32_t e = 0; e < t->ne; e++)
        if (er[e] != SD_RULE_LOOP || take[e] != 3 || (nopp[e] & 3) != 2)
            return false;
    return true;
}

/* A plain level's opposite vertices, from the faces of the level before (P, whose split this
 * level is: split.c's numbering), a quarter of this level's faces to read: parent face f with
 * corners x and edge points m_j (on its edge j, from x_j to x_j+1) has corner children
 * 4f+j = (x_j, m_j, m_j+2) and middle child (m_0, m_1, m_2). Its inside edge j, m_j+2 - m_j, lies
 * in corner child j, then in the middle one: opposite x_j, then m_j+1. The half of its edge j at
 * x_j lies in corner child j (opposite m_j+2), the half at x_j+1 in corner child j+1 (opposite
 * m_j+1); each half has one child face in each of the two parent faces of its edge, in their
 * order: the faces of P's edges (ef) come from the level before or are found by reading every
 * face once (scan_ef). In parts: the inside edges by ranges of faces, the halves by ranges of
 * P's edges. */
typedef struct pderiv {
    const sd_topo *P;
    uint32_t (*opp)[2];
    uint32_t (*ef)[2];  /* per parent edge, its faces f (edge j of f) as 3 f + j, in face order */
    uint32_t (*efc)[2]; /* the same for this level's edges (NULL: not wanted) */
    uint8_t *slot; /* per parent edge (each part zeroes its range) */
    uint32_t (*enb)[4]; /* per parent edge: see djob (inside edge j' = j of face f reads m_j+2,
                         * j' = j+1 reads m_j+1, in the order of the ids 3f + j') */
    uint8_t *vr;        /* this level's vertex rules and valences, filled by ranges too */
    uint32_t *cnt;
    const uint32_t *pcnt; /* P's valences */
} pderiv;

/* This level's vertex rules (all Loop's) and valences, for vertices [v0, v1): a vertex point
 * keeps its vertex's valence, an edge point has 6 (the two halves and two per triangle). */
static void derive_valences(const pderiv *J, uint32_t v0, uint32_t v1)
{
    const uint32_t pnv = J->P->nv;
    memset(J->vr + v0, SD_RULE_LOOP, v1 - v0);
    uint32_t vm = v1 < pnv ? v1 : pnv;
    if (v0 < vm)
        memcpy(J->cnt + v0, J->pcnt + v0, (size_t)(vm - v0) * sizeof *J->cnt);
    for (uint32_t v = v0 > pnv ? v0 : pnv; v < v1; v++)
        J->cnt[v] = 6;
}

/* The inside edges' opposite vertices, faces [f0, f1) of P. */
static void derive_inside(const pderiv *J, uint32_t f0, uint32_t f1)
{
    const sd_topo *P = J->P;
    const uint32_t pnv = P->nv, pne = P->ne;
    const uint32_t(*fv)[3] = P->fv, (*fe)[3] = P->fe;
    uint32_t(*opp)[2] = J->opp;
    for (uint32_t f = f0; f < f1; f++) {
        const uint32_t *x = fv[f];
        const uint32_t m[3] = {pnv + fe[f][0], pnv + fe[f][1], pnv + fe[f][2]};
        for (int j = 0; j < 3; j++) {
            uint32_t e = 2 * pne + 3 * f + (uint32_t)j;
            opp[e][0] = x[j];
            opp[e][1] = m[j == 2 ? 0 : j + 1];
        }
    }
}

/* Inside edges by ranges of faces and the valences by ranges of vertices (any cut). The faces
 * of inside edge j of f: corner child 4f + j (its edge 1), the middle child 4f + 3 (its edge
 * j + 2 mod 3). */
static void inside_part(void *arg, uint32_t part, uint32_t nparts)
{
    const pderiv *J = arg;
    uint64_t f0, f1, v0, v1;
    sdi_range(J->P->nf, part, nparts, &f0, &f1);
    sdi_range((uint64_t)J->P->nv + J->P->ne, part, nparts, &v0, &v1);
    derive_valences(J, (uint32_t)v0, (uint32_t)v1);
    derive_inside(J, (uint32_t)f0, (uint32_t)f1);
    if (J->efc) {
        const uint32_t pne = J->P->ne;
        for (uint32_t f = (uint32_t)f0; f < f1; f++)
            for (uint32_t j = 0; j < 3; j++) {
                uint32_t e = 2 * pne + 3 * f + j;
                J->efc[e][0] = 3 * (4 * f + j) + 1;
                J->efc[e][1] = 3 * (4 * f + 3) + (j + 2) % 3;
            }
    }
}

/* P's edges' faces, [lo, hi) (every face read; slot: those seen so far). */
static inline __attribute__((always_inline)) void scan_ef(const pderiv *J, uint32_t lo, uint32_t hi,
                                                          bool all)
{
    const sd_topo *P = J->P;
    const uint32_t nf = P->nf;
    const uint32_t(*fe)[3] = P->fe;
    uint32_t(*ef)[2] = J->ef;
    uint8_t *slot = J->slot;
    for (uint32_t f = 0; f < nf; f++)
        for (uint32_t j = 0; j < 3; j++) {
            uint32_t pe = fe[f][j];
            if (!all && (pe < lo || pe >= hi))
                continue;
            ef[pe][slot[pe]++ & 1] = 3 * f + j;
        }
}

/* ... by ranges of P's edges, each part reading every face: as many parts as threads. */
static void scan_ef_part(void *arg, uint32_t part, uint32_t nparts)
{
    const pderiv *J = arg;
    if (nparts == 1) {
        memset(J->slot, 0, J->P->ne);
        scan_ef(J, 0, 0, true);
        return;
    }
    uint64_t lo, hi;
    sdi_range(J->P->ne, part, nparts, &lo, &hi);
    memset(J->slot + lo, 0, hi - lo);
    scan_ef(J, (uint32_t)lo, (uint32_t)hi, false);
}

/* The halves' opposite vertices, enb and faces, by ranges of P's edges (any cut). The half of
 * edge j of f at x_j lies in corner child 4f + j (its edge 0), the half at x_j+1 in corner child
 * 4f + j+1 (its edge 2). */
static void halves_part(void *arg, uint32_t part, uint32_t nparts)
{
    const pderiv *J = arg;
    const sd_topo *P = J->P;
    const uint32_t pnv = P->nv;
    const uint32_t(*fv)[3] = P->fv, (*fe)[3] = P->fe, (*ev)[2] = P->ev, (*ef)[2] = J->ef;
    uint32_t(*opp)[2] = J->opp, (*enb)[4] = J->enb, (*efc)[2] = J->efc;
    uint64_t lo, hi;
    sdi_range(P->ne, part, nparts, &lo, &hi);
    for (uint32_t pe = (uint32_t)lo; pe < hi; pe++)
        for (uint32_t s = 0; s < 2; s++) {
            uint32_t f = ef[pe][s] / 3, j = ef[pe][s] % 3;
            uint32_t j1 = j == 2 ? 0 : j + 1, j2 = j == 0 ? 2 : j - 1;
            uint32_t at0 = ev[pe][0] == fv[f][j] ? 0 : 1; /* x_j's half */
            opp[2 * pe + at0][s] = pnv + fe[f][j2];
            opp[2 * pe + (at0 ^ 1)][s] = pnv + fe[f][j1];
            enb[pe][2 * s] = pnv + fe[f][j == 2 ? j1 : j2];
            enb[pe][2 * s + 1] = pnv + fe[f][j == 2 ? j2 : j1];
            if (efc) {
                efc[2 * pe + at0][s] = 3 * (4 * f + j);
                efc[2 * pe + (at0 ^ 1)][s] = 3 * (4 * f + j1) + 2;
            }
        }
}

void sdi_plain_free(sd_mem *m, sdi_plain *pl)
{
    sdi_free(m, pl->cnt);
    sdi_free(m, pl->ef[0]);
    sdi_free(m, pl->ef[1]);
    pl->cnt = NULL;
    pl->ef[0] = pl->ef[1] = NULL;
}

sd_result sdi_direct_apply(sd_complex *c, sd_level *p, sd_level *lv, sdi_plain *pl, bool *done,
                           sd_error *err)
{
    sd_mem *m = &c->mem;
    const sd_topo *t = &p->t;
    const uint32_t nv = t->nv, ne = t->ne;
    const int threads = c->opt.threads;
    double loopc[SDI_LOOP_CACHE];
    for (uint32_t k = 1; k < SDI_LOOP_CACHE; k++)
        loopc[k] = sdi_loop_weight(c->opt.surface_weights, k);
    loopc[0] = 0;
    *done = false;
    /* a plain parent (pp) makes this level plain: its rules from pp's valences */
    const sd_level *pp = p->index > 0 ? c->lv[p->index - 1] : NULL;
    const bool inherit = pp && pl->cnt && pl->level == pp->index && complex_plain(c, t) &&
                         nv == (uint64_t)pp->t.nv + pp->t.ne && pp->t.fv && pp->t.fe &&
                         pp->t.nf == pp->t.ntr && ne == 2ull * pp->t.ne + 3ull * pp->t.nf;
    /* (er, take and nopp are not needed by the plain passes) */
    uint8_t *er = inherit ? NULL : sdi_alloc(m, (size_t)ne + 1), *vr = NULL, *take = NULL,
            *nopp = NULL;
    uint32_t *cnt = NULL, (*opp)[2] = NULL, (*enb)[4] = NULL, (*ef)[2] = NULL, (*efc)[2] = NULL;
    const uint32_t(*efpp)[2] = NULL; /* the faces of the edges of pp's parent, if known */
    double *wa = NULL;
    bool any_g2e = false, any_opp = true, plain = inherit;
    sd_result rc = SD_OK;
    if (!inherit && !er)
        goto nomem;
    if (!inherit) {
        sdi_edge_rules(t, threads, er, &any_g2e, &any_opp);
        if (any_g2e) /* rings of G2 edges: through S */
            goto out;
    }
    vr = sdi_alloc(m, (size_t)nv + 1);
    cnt = inherit ? sdi_alloc(m, ((size_t)nv + 1) * sizeof *cnt)
                  : sdi_calloc(m, (size_t)nv + 1, sizeof *cnt);
    take = inherit ? NULL : sdi_alloc(m, (size_t)ne + 1);
    wa = sdi_alloc(m, ((size_t)nv + 1) * sizeof *wa);
    nopp = inherit ? NULL : sdi_calloc(m, (size_t)ne + 1, 1);
    if (any_opp)
        opp = sdi_alloc(m, ((size_t)ne + 1) * sizeof *opp);
    if (!vr || !cnt || (!inherit && (!take || !nopp)) || !wa || (any_opp && !opp))
        goto nomem;
    if (inherit) {
        /* from the parent's faces (there while the call that made the parent makes this): its
         * edges' faces handed on from the level before, or found by reading them; this level's
         * made too if another level follows (and their ids hold 3 f + j) */
        for (int k = 0; k < 2; k++)
            if (pl->ef[k] && pl->ef_level[k] == pp->index) {
                ef = pl->ef[k];
                pl->ef[k] = NULL;
            } else if (pl->ef[k] && pl->ef_level[k] == pp->index - 1 && pp->index > 0) {
                efpp = (const uint32_t(*)[2])pl->ef[k];
            }
        enb = sdi_alloc(m, ((size_t)pp->t.ne + 1) * sizeof *enb);
        if (!enb)
            goto nomem;
        cnt[nv] = 0;
        pderiv D = {&pp->t, opp, NULL, NULL, NULL, enb, vr, cnt, pl->cnt};
        if (!ef) {
            ef = sdi_alloc(m, ((size_t)pp->t.ne + 1) * sizeof *ef);
            D.slot = sdi_alloc(m, (size_t)pp->t.ne + 1);
            if (!ef || !D.slot) {
                sdi_free(m, D.slot);
                goto nomem;
            }
            D.ef = ef;
            sdi_par(threads, pp->t.ne, scan_ef_part, &D);
            sdi_free(m, D.slot);
        }
        D.ef = ef;
        if (lv->index < pl->top && 3ull * t->nf < UINT32_MAX) /* (without: read again then) */
            efc = D.efc = sdi_alloc(m, ((size_t)ne + 1) * sizeof *efc);
        sdi_par_dyn(threads, pp->t.ne, 4, inside_part, &D);
        sdi_par_dyn(threads, pp->t.ne, 4, halves_part, &D);
    } else {
        if (!sdi_vertex_rules(m, t, c->opt.solid_scheme, threads, vr, cnt, NULL, take))
            goto nomem;
        if (any_opp)
            sdi_edge_opposites(t, threads, er, opp, nopp);
        plain = complex_plain(c, t) && rules_plain(t, vr, er, take, nopp, any_opp);
    }
    /* the limits S would have (stencil.c), so that a level is refused alike either way: its
     * entries are nv + ne implicit ones, rho's (at most two per edge) and the rings (at most 2) */
    if ((uint64_t)nv + ne >= UINT32_MAX) {
        rc = sdi_fail(err, SD_ERR_LIMIT, -1, -1, "too many points for 32-bit ids");
        goto out;
    }
    if ((uint64_t)nv + 6ull * ne >= UINT32_MAX) {
        uint64_t nnz = (uint64_t)nv + 2ull * ne;
        for (uint32_t v = 0; v < nv; v++)
            nnz += cnt[v];
        for (uint32_t e = 0; e < ne; e++)
            nnz += inherit ? 2 : sdi_opp_ring_len(er[e], nopp[e]);
        if (nnz >= UINT32_MAX) {
            rc = sdi_fail(err, SD_ERR_LIMIT, -1, -1, "subdivision matrix too large for 32-bit offsets");
            goto out;
        }
    }
    djob J = {.t = t, .weights = c->opt.surface_weights, .scheme = c->opt.solid_scheme, .vr = vr,
              .er = er, .take = take, .nopp = nopp, .cnt = cnt, .opp = (const uint32_t(*)[2])opp,
              .loopc = loopc, .wa = wa, .plain = plain, .P = enb ? &pp->t : NULL,
              .enb = (const uint32_t(*)[4])enb, .PP = efpp ? &c->lv[pp->index - 1]->t : NULL,
              .efpp = efpp, .ninit = enb ? pp->t.nv : nv};
    for (int i = 0; i < p->nch; i++) {
        J.in = p->ch[i].data;
        J.out = lv->ch[i].data;
        J.nc = p->ch[i].ncomp;
        sdi_par_dyn(threads, J.ninit, 4, init_part, &J);
        if (enb) { /* structured */
            sdi_par_dyn(threads, pp->t.ne, 4, epoints_part, &J);
            if (efpp)
                sdi_par_dyn(threads, J.PP->ne, 4, vgather_part, &J);
            sdi_par(threads, (efpp ? J.PP : J.P)->ne, vscatter_part, &J);
            sdi_par_dyn(threads, ne, 4, erows_part, &J);
        } else {
            sdi_par(threads, ne, edges_part, &J);
        }
    }
    *done = true;
    if (!p->vrule_only) { /* the rules are exact now (sd_level_vertex_rule): kept */
        p->vrule_only = vr;
        vr = NULL;
    }
    sdi_plain_free(m, pl); /* the parent's valences and the edges' faces before pp's have served */
    if (plain) { /* for the next level's rules */
        pl->cnt = cnt;
        pl->level = p->index;
        cnt = NULL;
        if (efc) { /* pp's edges' faces and this level's, for the next level */
            pl->ef[0] = ef;
            pl->ef_level[0] = pp->index;
            pl->ef[1] = efc;
            pl->ef_level[1] = p->index;
            ef = efc = NULL;
        }
    }
    goto out;
nomem:
    rc = sdi_fail_nomem(err, m);
out:
    sdi_free(m, er);
    sdi_free(m, vr);
    sdi_free(m, cnt);
    sdi_free(m, take);
    sdi_free(m, wa);
    sdi_free(m, nopp);
    sdi_free(m, opp);
    sdi_free(m, enb);
    sdi_free(m, ef);
    sdi_free(m, efc);
    return rc;
}
