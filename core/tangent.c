/* tangent.c — Ying-Zorin's tangent-plane constraints (003 Sec. 3, Appendix B): prescribed
 * normals of closed petals at complex singular vertices, prescribed interior tangents of open
 * petals at simple singular vertices, and their interpolation along tagged singular edges; the
 * two inferred forms of 003 Fig. 6(b) (a normal shared by closed petals) and 6(c) (two petals
 * made tangent across a singular curve: t and -t along the difference of their a_1, none where
 * that is zero or along the curve).
 *
 * The modifications act on the points of level l + 1 once S_l has made them (levels.c), each in
 * the 1-ring N_1(v) of a constrained vertex v within its petal, with s = SD_TT_S = 3/4 (003:
 * "we use the value 3/4"). Writing p for those points and a_i = (l^i, p) for their components on
 * the petal's left eigenvectors:
 *   normal modification  p <- p - s ((a_1, n) n x^1 + (a_2, n) n x^2)
 *   tangent modification p <- p + s ((lambda_1^r t_1 - a_1) x^1 + (lambda_2^r t_2 - a_2) x^2)
 * Closed petal (fixed disk, its centre a fixed complex vertex; ring q_0 .. q_{k-1}): yz.c's
 *   tangent pair, x^1_j = sin(2 pi j/k), x^2_j = cos(2 pi j/k), l^i = 2/k x^i, both vanishing at
 *   the centre (003 App. A). The flattened petal keeps (l^i, p) as the eigenvalue lambda's
 *   component, so each level removes the fraction s of a_i's part along n and the limit tangent
 *   plane span(a_1, a_2) is the one normal to n: its n-parts shrink as ((1 - s) lambda)^r
 *   against lambda^r.
 * Open petal of a simple singular vertex (ring q_0 .. q_k, q_0 and q_k on the singular curve,
 *   003 Fig. 4f with theta = pi/k inside, B-spline on the curve): the eigenvalue 1/2 is double,
 *   on the curve tangent x^2 (q_0: 1, q_k: -1, q_j: cos j theta, the centre 0), l^2 = (q_0 -
 *   q_k)/2, and on the interior tangent x^1_j = sin(j theta) (0 at the centre and on the curve).
 *   Its left eigenvector, derived here from l S = l/2 column by column (columns q_j inside give
 *   sin(j theta), q_0 the centre weight, the centre the ends' weight; scaled so (l^1, x^1) = 1):
 *     l^1 = 2/k (centre: -sin theta; q_0, q_k: sin(theta)/4 - (1 + cos theta) cot(theta/2)/4;
 *                q_j: sin(j theta))
 *   It sums to 0 and vanishes on x^2. Only the x^1 term is applied: the curve tangent t_2 is the
 *   curve's own (003: "using the tangent to the singular curve as t_2"), so the curve and its
 *   points do not move. The target lambda_1^r t_1 is kept per level as T (level 0: the given
 *   direction scaled to |a_1| there, 003: "we scale the prescribed tangents to have the same
 *   length as a_1"), halved each level (lambda_1 = 1/2); a vertex inserted on a tagged edge
 *   between two constrained petals gets (T_a + T_b)/4, the midpoint rule with 003 App. B's
 *   factor 1/2 (t_1^{j+1} = (t_0^j + t_1^j)/4), and is constrained from then on; the two halves
 *   of a tagged edge are tagged. The limit tangent plane at v is then the one of the curve
 *   tangent and T_0, the limit normal T_0 x (the curve tangent).
 * A vertex's modification moves only the midpoints of its own level-l edges, and the block of v
 * and its 1-ring is closed under S, so two vertices' modifications meet only at a shared point:
 * the midpoint of a level-0 inner edge joining two constrained vertices of a curve (a curve
 * edge's midpoint is on the curve, where x^1 vanishes). There applying them in sequence would
 * depend on the order, so all the modifications of a level are computed from S's points and
 * added together; elsewhere that is the same as applying them one by one. Each step takes the
 * fraction s of a_1's difference to T, and S scales a_1 by lambda_1, so a_1 / lambda_1^r tends
 * to T_0 with the one mode (1 - s)^r and no part along the curve
 * (tests/python/test_tangent_planes.py checks the limits from levels 2 to 6). Inferred data
 * (Fig. 6) is taken from level 0's positions: the Loop normal of a closed petal is a_1 x a_2
 * there, a petal's interior tangent a_1.
 *
 * A vertex whose rule at a level is not Ying-Zorin's petal rule (a PUT /rules choice of its
 * own, chang-qin) is left alone there and its data is not carried further.
 */
#include "internal.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* One constrained petal of a level: its vertex and one of its faces, and the data. */
typedef struct sdi_tprec {
    uint32_t v, f;
    uint32_t key;    /* level 0: the petal's smallest face (one entry per petal) */
    uint8_t kind;    /* SD_TT_NORMAL, SD_TT_TANGENT */
    uint8_t given;   /* level 0: given by a tag (not inferred) */
    double d[3];     /* the unit normal, or the target T of a_1 at this level */
} sdi_tprec;

struct sdi_tplane {
    uint32_t n, ne;
    sdi_tprec *r;
    uint32_t (*e)[2]; /* the tagged edges, by their ends */
};

void sdi_tp_free(sd_mem *m, struct sdi_tplane *tp)
{
    if (!tp)
        return;
    sdi_free(m, tp->r);
    sdi_free(m, tp->e);
    sdi_free(m, tp);
}

static inline uint32_t other_end(const sd_topo *t, uint32_t e, uint32_t v)
{
    return t->ev[e][0] == v ? t->ev[e][1] : t->ev[e][0];
}

static inline double dot3(const double *a, const double *b)
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* |a|, without overflow for directions given as large as the API takes (1e300) */
static inline double norm3(const double *a)
{
    return hypot(hypot(a[0], a[1]), a[2]);
}

/* a scaled by a power of two (exact) so that its largest component is in [1/2, 1): a direction
 * given with subnormal components (the API takes any finite non-zero vector) keeps its bits, and
 * its length and cross products neither lose precision nor underflow; a zero vector stays zero */
static inline void rescale3(const double *a, double *o)
{
    double m = fmax(fmax(fabs(a[0]), fabs(a[1])), fabs(a[2]));
    int e = 0;
    if (m > 0 && isfinite(m))
        frexp(m, &e);
    for (int k = 0; k < 3; k++)
        o[k] = ldexp(a[k], -e);
}

static inline void cross3(const double *a, const double *b, double *c)
{
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

/* Whether directions a and b are parallel to 1e-9 (a zero one counts as parallel). */
static bool parallel3(const double *a0, const double *b0)
{
    double a[3], b[3], w[3];
    rescale3(a0, a);
    rescale3(b0, b);
    cross3(a, b, w);
    return norm3(w) <= 1e-9 * norm3(a) * norm3(b);
}

/* ---- petals ------------------------------------------------------------------------------- */

enum { RING_NONE, RING_CLOSED, RING_OPEN };

/* The edges at v of v's petal holding face f, in order (Ying-Zorin's joining, petals.c): a closed
 * petal's k from f's first edge at v round; an open one's k + 1 from one singular edge to the
 * other. faces: scratch (cap), and then the petal's faces (*nf). Darts and failures: RING_NONE. */
static int petal_ring(const sd_topo *t, const sdi_rel *ef, uint32_t v, uint32_t f, uint32_t *ring,
                      uint32_t *tmp, uint32_t *faces, uint32_t cap, uint32_t *n, uint32_t *nf)
{
    uint32_t at[2], na = 0;
    for (int j = 0; j < 3; j++) {
        uint32_t e = t->fe[f][j];
        if (t->ev[e][0] == v || t->ev[e][1] == v) {
            if (na < 2)
                at[na] = e;
            na++;
        }
    }
    if (na != 2 || cap < 4)
        return RING_NONE;
    faces[0] = f;
    /* from at[0] into f, out through at[1] and on */
    sdi_walk wb = {faces + 1, tmp, 0, cap - 3};
    uint32_t b = sdi_petal_walk(t, ef, SDI_PETAL_YZ, v, at[0], f, &wb);
    if (b == UINT32_MAX)
        return RING_NONE;
    if (b == at[0]) { /* closed: at[0], then the edges crossed */
        ring[0] = at[0];
        memcpy(ring + 1, tmp, wb.n * sizeof *ring);
        *n = wb.n + 1;
        *nf = wb.n + 1;
        return RING_CLOSED;
    }
    /* open: the other way from at[1], out through at[0]; ring = a, reversed, f, the first way, b */
    sdi_walk wa = {faces + 1 + wb.n, ring + 1, 0, cap - 3 - wb.n};
    uint32_t a = sdi_petal_walk(t, ef, SDI_PETAL_YZ, v, at[1], f, &wa);
    if (a == UINT32_MAX || a == b)
        return RING_NONE;
    ring[0] = a;
    for (uint32_t i = 0; i < wa.n / 2; i++) {
        uint32_t x = ring[1 + i];
        ring[1 + i] = ring[wa.n - i];
        ring[wa.n - i] = x;
    }
    memcpy(ring + 1 + wa.n, tmp, wb.n * sizeof *ring);
    ring[1 + wa.n + wb.n] = b;
    *n = wa.n + wb.n + 2;
    *nf = wa.n + wb.n + 1;
    return RING_OPEN;
}

/* a_1 of an open petal of k triangles (ring points q[0..k], centre v) on positions x: the left
 * eigenvector l^1 of the header. */
static void open_a1(const double *x, uint32_t v, const uint32_t *q, uint32_t k, double a[3])
{
    const double th = M_PI / k, end = sin(th) / 4 - (1 + cos(th)) / (4 * tan(th / 2));
    for (int d = 0; d < 3; d++) {
        double s = -sin(th) * x[3 * (size_t)v + d] + end * (x[3 * (size_t)q[0] + d] +
                                                            x[3 * (size_t)q[k] + d]);
        for (uint32_t j = 1; j < k; j++)
            s += sin(j * th) * x[3 * (size_t)q[j] + d];
        a[d] = 2.0 / k * s;
    }
}

/* a_1, a_2 of a closed petal of k triangles (ring q[0..k), centre v) on positions x. */
static void closed_a(const double *x, uint32_t v, const uint32_t *q, uint32_t k, double a1[3],
                     double a2[3])
{
    for (int d = 0; d < 3; d++) {
        double s1 = 0, s2 = 0, c = x[3 * (size_t)v + d];
        for (uint32_t j = 0; j < k; j++) {
            double y = x[3 * (size_t)q[j] + d] - c;
            s1 += sin(2 * M_PI * j / k) * y;
            s2 += cos(2 * M_PI * j / k) * y;
        }
        a1[d] = 2.0 / k * s1;
        a2[d] = 2.0 / k * s2;
    }
}

static inline uint32_t child_at(const sd_topo *t, uint32_t f, uint32_t v)
{
    uint32_t j = t->fv[f][0] == v ? 0 : t->fv[f][1] == v ? 1 : 2;
    return 4 * f + j;
}

/* The level-0 checks shared by the tags and the steps: a vertex of Ying-Zorin's petal rules of
 * the kind wanted (complex: fixed; simple: on a curve), its tags not winning. */
static bool yz_at(const sd_topo *t, uint32_t v, int kind)
{
    return nm_ov(t->vnm[v]) == (kind == SD_TT_NORMAL ? OV_YZX : OV_YZS) &&
           !(t->vflag[v] & (VF_SING | VF_S_ANY));
}

/* ---- the tags ----------------------------------------------------------------------------- */

typedef struct scratch {
    uint32_t *ring, *tmp, *faces, cap;
} scratch;

static bool scratch_init(sd_mem *m, scratch *s, uint32_t cap)
{
    s->cap = cap;
    s->ring = sdi_alloc(m, (size_t)cap * sizeof *s->ring);
    s->tmp = sdi_alloc(m, (size_t)cap * sizeof *s->tmp);
    s->faces = sdi_alloc(m, (size_t)cap * sizeof *s->faces);
    return s->ring && s->tmp && s->faces;
}

static void scratch_free(sd_mem *m, scratch *s)
{
    sdi_free(m, s->ring);
    sdi_free(m, s->tmp);
    sdi_free(m, s->faces);
}

static int cmp_u64pair(const void *a, const void *b)
{
    const uint64_t *p = a, *q = b;
    return p[0] != q[0] ? (p[0] > q[0]) - (p[0] < q[0]) : (p[1] > q[1]) - (p[1] < q[1]);
}

static sd_result check_petal(const sd_complex *c, const sdi_rels *R, const uint8_t *tagv,
                             scratch *S, uint32_t *owner, const sd_tangent_tag *tt, size_t i,
                             sd_error *err)
{
    const sd_topo *t = &c->lv[0]->t;
    const sdi_rel *ve = &R->r[SDI_VE];
    const sd_tangent_tag *g = &tt[i];
    const uint32_t v = g->vertex;
    const char *what = g->kind == SD_TT_NORMAL ? "normal" : "tangent";
    uint32_t f = sdi_rels_face(R, g->triangle);
    if (f == UINT32_MAX || !(t->fflag[f] & FF_MAX))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_TRIANGLE,
                        "%s: [%u, %u, %u] is not a surface triangle of the complex", what,
                        g->triangle[0], g->triangle[1], g->triangle[2]);
    if (!sdi_face_has(t, f, v))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_TRIANGLE,
                        "%s: the triangle does not hold vertex %u", what, v);
    uint32_t nsing = 0;
    for (uint32_t k = ve->off[v]; k < ve->off[v + 1]; k++)
        nsing += sdi_yz_counts_singular(t, ve->item[k]);
    const bool nm = t->vfam[v] == FAM2 && nm_type(t->vnm[v]);
    const bool simple = nm && sdi_yz_simple(nm_type(t->vnm[v]), nsing);
    if (g->kind == SD_TT_NORMAL && (!nm || simple))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_VERTEX,
                        "normal: vertex %u is not a complex singular vertex of a triangle "
                        "mesh (a non-manifold vertex where only triangles meet, not one flower "
                        "with exactly two singular edges): prescribed normals are for its "
                        "closed petals", v);
    if (g->kind == SD_TT_TANGENT && !simple)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_VERTEX,
                        "tangent: vertex %u is not a simple singular vertex of a triangle "
                        "mesh (one flower with exactly two singular edges, non-manifold): "
                        "interior tangents are for the open petals along a singular curve", v);
    if (tagv[v])
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_VERTEX,
                        "%s: vertex %u %s, so its petals have no Ying-Zorin rule", what, v,
                        tagv[v] == 1 ? "is tagged singular"
                                     : "lies on a tagged crease or embedded surface");
    uint32_t n, nf;
    int kind = petal_ring(t, &R->r[SDI_EF], v, f, S->ring, S->tmp, S->faces, S->cap, &n, &nf);
    if (g->kind == SD_TT_NORMAL && kind != RING_CLOSED)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_TRIANGLE,
                        "normal: the petal of vertex %u holding this triangle is not closed "
                        "(it meets a singular edge); a normal is prescribed for a closed petal",
                        v);
    if (g->kind == SD_TT_TANGENT && (kind != RING_OPEN || nf < 2))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_TRIANGLE,
                        "tangent: the petal of vertex %u holding this triangle is %s; an "
                        "interior tangent needs an open petal of 2 or more triangles", v,
                        kind == RING_OPEN ? "one triangle" : "not open");
    for (uint32_t k = 0; k < nf; k++) {
        uint32_t h = S->faces[k], slot = 3 * h + (child_at(t, h, v) & 3);
        if (owner[slot] != UINT32_MAX)
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_TRIANGLE,
                            "%s: an earlier entry already constrains this petal of vertex %u",
                            what, v);
        owner[slot] = (uint32_t)i;
    }
    const double *x = c->lv[0]->ch[0].data;
    if (g->kind == SD_TT_TANGENT) { /* not along the curve: q_0 - q_k is its direction at v */
        double cv[3];
        uint32_t q0 = other_end(t, S->ring[0], v), qk = other_end(t, S->ring[n - 1], v);
        for (int d = 0; d < 3; d++)
            cv[d] = x[3 * (size_t)q0 + d] - x[3 * (size_t)qk + d];
        if (parallel3(cv, g->vec))
            return sdi_fail(err, SD_ERR_VALUE, (long)i, SD_TT_FIELD_VECTOR,
                            "tangent: the interior tangent is along the singular curve at "
                            "vertex %u, so it spans no tangent plane with it", v);
    }
    return SD_OK;
}

static sd_result check_edge(const sd_complex *c, const sdi_rels *R, const sd_tangent_tag *tt,
                            size_t i, uint32_t *tt_f, uint64_t *key, sd_error *err)
{
    const sd_topo *t = &c->lv[0]->t;
    const sd_tangent_tag *g = &tt[i];
    uint32_t e = g->edge[0] == g->edge[1] ? UINT32_MAX : sdi_rels_edge(R, g->edge[0], g->edge[1]);
    if (e == UINT32_MAX)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_EDGE,
                        "tangent edge: [%u, %u] is not an edge of the complex",
                        g->edge[0], g->edge[1]);
    if (!sdi_yz_counts_singular(t, e) || (t->eflag[e] & (EF_CREASE | EF_SSURF)))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_EDGE,
                        "tangent edge: [%u, %u] is not a singular edge of triangles (a "
                        "non-manifold or boundary edge where only triangles meet, not tagged)",
                        g->edge[0], g->edge[1]);
    uint32_t a = g->edge[0] < g->edge[1] ? g->edge[0] : g->edge[1];
    *key = (uint64_t)a << 32 | (g->edge[0] ^ g->edge[1] ^ a);
    for (int h = 0; h < g->npair; h++) {
        uint32_t f = sdi_rels_face(R, g->pair[h]);
        int field = h ? SD_TT_FIELD_PAIR1 : SD_TT_FIELD_PAIR0;
        if (f == UINT32_MAX || !(t->fflag[f] & FF_MAX))
            return sdi_fail(err, SD_ERR_ARG, (long)i, field,
                            "tangent edge: [%u, %u, %u] is not a surface triangle of the "
                            "complex", g->pair[h][0], g->pair[h][1], g->pair[h][2]);
        if (!sdi_face_has(t, f, g->edge[0]) || !sdi_face_has(t, f, g->edge[1]))
            return sdi_fail(err, SD_ERR_ARG, (long)i, field,
                            "tangent edge: the triangle does not hold the edge");
        if (h && f == tt_f[2 * i])
            return sdi_fail(err, SD_ERR_ARG, (long)i, field,
                            "tangent edge: the two triangles are the same");
        tt_f[2 * i + h] = f;
    }
    return SD_OK;
}

sd_result sd_complex_set_tangents(sd_complex *c, const sd_tangent_tag *tt, size_t n,
                                  sd_error *err)
{
    sd_mem *m = &c->mem;
    const sd_topo *t = &c->lv[0]->t;
    for (size_t i = 0; i < n; i++) { /* ids and values before anything reads them */
        const sd_tangent_tag *g = &tt[i];
        if (g->kind < SD_TT_NORMAL || g->kind > SD_TT_EDGE)
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_VERTEX,
                            "tangent tag: unknown kind");
        if (g->kind == SD_TT_EDGE) {
            for (int j = 0; j < 2; j++)
                if (g->edge[j] >= t->nv)
                    return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_TT_FIELD_EDGE,
                                    "tangent edge: vertex %u out of range", g->edge[j]);
            if (g->npair != 0 && g->npair != 2)
                return sdi_fail(err, SD_ERR_ARG, (long)i, SD_TT_FIELD_PAIR0,
                                "tangent edge: a pair is two triangles");
            for (int h = 0; h < g->npair; h++)
                for (int j = 0; j < 3; j++)
                    if (g->pair[h][j] >= t->nv)
                        return sdi_fail(err, SD_ERR_INDEX, (long)i,
                                        h ? SD_TT_FIELD_PAIR1 : SD_TT_FIELD_PAIR0,
                                        "tangent edge: vertex %u out of range",
                                        g->pair[h][j]);
            continue;
        }
        if (g->vertex >= t->nv)
            return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_TT_FIELD_VERTEX,
                            "tangent tag: vertex %u out of range", g->vertex);
        for (int j = 0; j < 3; j++)
            if (g->triangle[j] >= t->nv)
                return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_TT_FIELD_TRIANGLE,
                                "tangent tag: vertex %u out of range", g->triangle[j]);
        bool shared = g->kind == SD_TT_NORMAL && isnan(g->vec[0]) && isnan(g->vec[1]) &&
                      isnan(g->vec[2]);
        double len = norm3(g->vec);
        if (!shared && !(isfinite(len) && len > 0))
            return sdi_fail(err, SD_ERR_VALUE, (long)i, SD_TT_FIELD_VECTOR,
                            "tangent tag: the %s is not a finite vector of non-zero length",
                            g->kind == SD_TT_NORMAL ? "normal" : "tangent");
    }
    /* a group (consecutive entries): the petals of one vertex, with one normal or none; none
     * needs two or more petals to share */
    for (size_t i = 0, j; i < n; i = j) {
        j = i + 1;
        if (tt[i].kind != SD_TT_NORMAL)
            continue;
        while (j < n && tt[j].kind == SD_TT_NORMAL && tt[j].group == tt[i].group) {
            if (tt[j].vertex != tt[i].vertex)
                return sdi_fail(err, SD_ERR_ARG, (long)j, SD_TT_FIELD_VERTEX,
                                "normal: the petals sharing a normal are at one vertex");
            j++;
        }
        if (isnan(tt[i].vec[0]) && j - i < 2)
            return sdi_fail(err, SD_ERR_VALUE, (long)i, SD_TT_FIELD_VECTOR,
                            "normal: without a normal, two or more petals share the average "
                            "of their normals (003 Fig. 6(b)); one petal has nothing to share");
    }
    sd_result rc = SD_OK;
    sdi_rels R = {.t = t};
    scratch S = {0};
    uint32_t *owner = NULL, *tt_f = NULL;
    uint8_t *tagv = NULL;
    uint64_t *keys = NULL;
    sd_tangent_tag *copy = NULL;
    if (n && (!sdi_rels_need(m, &R, SDI_TAG_RELS) || !scratch_init(m, &S, t->nf + 4) ||
              !(owner = sdi_alloc(m, (3 * (size_t)t->nf + 1) * sizeof *owner)) ||
              !(tagv = sdi_calloc(m, (size_t)t->nv + 1, 1)) ||
              !(tt_f = sdi_alloc(m, 2 * n * sizeof *tt_f)) ||
              !(keys = sdi_alloc(m, 2 * n * sizeof *keys)) ||
              !(copy = sdi_alloc(m, n * sizeof *copy)))) {
        rc = sdi_fail_nomem(err, m);
        goto out;
    }
    if (n) {
        memcpy(copy, tt, n * sizeof *copy);
        for (size_t f = 0; f < 3 * (size_t)t->nf; f++)
            owner[f] = UINT32_MAX;
        sdi_tagged_vertices(c, t, tagv);
    }
    size_t nk = 0;
    for (size_t i = 0; i < n && !rc; i++) {
        tt_f[2 * i] = tt_f[2 * i + 1] = UINT32_MAX;
        if (tt[i].kind == SD_TT_EDGE) {
            uint64_t key = 0;
            rc = check_edge(c, &R, tt, i, tt_f, &key, err);
            if (!rc) /* by edge, then entry: a repeat sorts after its first */
                keys[2 * nk] = key, keys[2 * nk + 1] = i, nk++;
        } else {
            rc = check_petal(c, &R, tagv, &S, owner, tt, i, err);
            if (!rc)
                tt_f[2 * i] = sdi_rels_face(&R, tt[i].triangle);
        }
    }
    if (!rc && nk > 1) { /* one entry per edge: the first repeat, by entry */
        qsort(keys, nk, 2 * sizeof *keys, cmp_u64pair);
        size_t bad = SIZE_MAX;
        for (size_t i = 1; i < nk; i++)
            if (keys[2 * i] == keys[2 * i - 2] && keys[2 * i + 1] < bad)
                bad = keys[2 * i + 1];
        if (bad != SIZE_MAX) /* no entry numbers: the API numbers its lists its own way */
            rc = sdi_fail(err, SD_ERR_ARG, (long)bad, SD_TT_FIELD_EDGE,
                          "tangent edge: [%u, %u] is named by an earlier entry too",
                          tt[bad].edge[0], tt[bad].edge[1]);
    }
    if (rc)
        goto out;
    sdi_free(m, c->tt);
    sdi_free(m, c->tt_f);
    c->tt = n ? copy : NULL;
    c->tt_f = n ? tt_f : NULL;
    c->ntt = n;
    if (n)
        copy = NULL, tt_f = NULL;
    sdi_drop_rules(c, c->lv[0]); /* every finer level follows */
    sdi_tp_free(m, c->lv[0]->tp);
    c->lv[0]->tp = NULL;
out:
    sdi_free(m, copy);
    sdi_free(m, tt_f);
    sdi_free(m, keys);
    sdi_free(m, owner);
    sdi_free(m, tagv);
    scratch_free(m, &S);
    sdi_rels_free(m, &R);
    return rc;
}

/* ---- level 0's data from the tags ----------------------------------------------------------- */

typedef struct tplist {
    sdi_tprec *r;
    uint32_t n, cap;
} tplist;

static bool tp_push(sd_mem *m, tplist *L, sdi_tprec x)
{
    if (L->n == L->cap) {
        uint32_t cap = L->cap ? 2 * L->cap : 16;
        sdi_tprec *nr = sdi_realloc(m, L->r, (size_t)cap * sizeof *nr);
        if (!nr)
            return false;
        L->r = nr;
        L->cap = cap;
    }
    L->r[L->n++] = x;
    return true;
}

static int cmp_rec(const void *a, const void *b)
{
    const sdi_tprec *p = a, *q = b;
    if (p->v != q->v)
        return p->v < q->v ? -1 : 1;
    if (p->key != q->key)
        return p->key < q->key ? -1 : 1;
    return (q->given > p->given) - (q->given < p->given); /* given first */
}

/* The smallest face of the petal just walked (S->faces[0 .. nf)). */
static uint32_t petal_key(const scratch *S, uint32_t nf)
{
    uint32_t k = UINT32_MAX;
    for (uint32_t i = 0; i < nf; i++)
        if (S->faces[i] < k)
            k = S->faces[i];
    return k;
}

/* The interior tangent a_1 of v's open petal holding f, and its key; false if not such a petal. */
static bool petal_a1(const sd_topo *t, const sdi_rel *ef, const double *x, scratch *S, uint32_t v,
                     uint32_t f, double a1[3], uint32_t *key)
{
    uint32_t n, nf;
    if (petal_ring(t, ef, v, f, S->ring, S->tmp, S->faces, S->cap, &n, &nf) != RING_OPEN || nf < 2)
        return false;
    *key = petal_key(S, nf);
    for (uint32_t j = 0; j < n; j++)
        S->tmp[j] = other_end(t, S->ring[j], v);
    open_a1(x, v, S->tmp, n - 1, a1);
    S->tmp[1] = S->tmp[n - 1]; /* the curve's ends q_0, q_k, for the caller */
    return true;
}

static const sdi_tprec *find_rec(const tplist *L, uint32_t v, uint32_t key)
{
    size_t lo = 0, hi = L->n;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        const sdi_tprec *r = &L->r[mid];
        if (r->v < v || (r->v == v && r->key < key))
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < L->n && L->r[lo].v == v && L->r[lo].key == key ? &L->r[lo] : NULL;
}

static void scale_to(double *d, const double *dir0, double len)
{
    double dir[3];
    rescale3(dir0, dir);
    double l = norm3(dir);
    for (int k = 0; k < 3; k++)
        d[k] = l > 0 ? dir[k] / l * len : 0;
}

/* 003 Fig. 6(b): the unit average of the Loop normals a_1 x a_2 of the closed petals of the
 * group starting at entry i, each oriented like the first (the modification reads n n^T only);
 * false if it has no direction. */
static bool shared_normal(const sd_complex *c, const sd_topo *t, const sdi_rel *ef,
                          const double *x, scratch *S, size_t i, double out[3])
{
    const sd_tangent_tag *g = &c->tt[i];
    double sum[3] = {0, 0, 0}, first[3] = {0, 0, 0};
    for (size_t j = i; j < c->ntt && c->tt[j].kind == SD_TT_NORMAL && c->tt[j].group == g->group;
         j++) {
        uint32_t n, nf;
        if (petal_ring(t, ef, g->vertex, c->tt_f[2 * j], S->ring, S->tmp, S->faces, S->cap, &n,
                       &nf) != RING_CLOSED)
            continue;
        for (uint32_t q = 0; q < n; q++)
            S->tmp[q] = other_end(t, S->ring[q], g->vertex);
        double a1[3], a2[3], nn[3];
        closed_a(x, g->vertex, S->tmp, n, a1, a2);
        cross3(a1, a2, nn);
        if (dot3(nn, nn) == 0)
            continue;
        scale_to(nn, nn, 1);
        if (dot3(first, first) == 0)
            memcpy(first, nn, sizeof first);
        const double sg = dot3(nn, first) < 0 ? -1 : 1;
        for (int d = 0; d < 3; d++)
            sum[d] += sg * nn[d];
    }
    if (dot3(sum, sum) == 0)
        return false;
    scale_to(out, sum, 1);
    return true;
}

static sd_result level0(sd_complex *c, const sdi_rels *R, scratch *S, struct sdi_tplane **out,
                        sd_error *err)
{
    sd_mem *m = &c->mem;
    const sd_topo *t = &c->lv[0]->t;
    const sdi_rel *ef = &R->r[SDI_EF];
    const double *x = c->lv[0]->ch[0].data;
    tplist L = {0};
    struct sdi_tplane *tp = sdi_calloc(m, 1, sizeof *tp);
    size_t ne = 0;
    double avg[3] = {0, 0, 0}; /* the current group's shared normal */
    if (!tp)
        goto nomem;
    for (size_t i = 0; i < c->ntt; i++) {
        const sd_tangent_tag *g = &c->tt[i];
        const uint32_t v = g->vertex, f = c->tt_f[2 * i];
        if (g->kind == SD_TT_EDGE) {
            ne++;
            continue;
        }
        sdi_tprec r = {.v = v, .f = f, .kind = (uint8_t)g->kind, .given = 1};
        if (g->kind == SD_TT_TANGENT) {
            double a1[3];
            if (!petal_a1(t, ef, x, S, v, f, a1, &r.key))
                continue;
            double len = norm3(a1);
            scale_to(r.d, g->vec, len > 0 ? len : 1);
        } else {
            uint32_t n, nf;
            if (petal_ring(t, ef, v, f, S->ring, S->tmp, S->faces, S->cap, &n, &nf) != RING_CLOSED)
                continue;
            r.key = petal_key(S, nf);
            if (!isnan(g->vec[0])) {
                scale_to(r.d, g->vec, 1);
            } else { /* 003 Fig. 6(b): the group's shared normal, made at its first entry */
                size_t j0 = i;
                while (j0 > 0 && c->tt[j0 - 1].kind == SD_TT_NORMAL &&
                       c->tt[j0 - 1].group == g->group)
                    j0--;
                if (j0 == i && !shared_normal(c, t, ef, x, S, i, avg))
                    memset(avg, 0, sizeof avg);
                if (dot3(avg, avg) == 0)
                    continue;
                memcpy(r.d, avg, sizeof r.d);
            }
        }
        if (!tp_push(m, &L, r))
            goto nomem;
    }
    if (L.n)
        qsort(L.r, L.n, sizeof *L.r, cmp_rec);
    /* 003 Fig. 6(c): the pairs of petals along tagged edges, at both ends */
    tplist I = {0};
    for (size_t i = 0; i < c->ntt; i++) {
        const sd_tangent_tag *g = &c->tt[i];
        if (g->kind != SD_TT_EDGE || g->npair != 2)
            continue;
        for (int end = 0; end < 2; end++) {
            const uint32_t v = g->edge[end];
            if (!yz_at(t, v, SD_TT_TANGENT))
                continue;
            double a[2][3], T[2][3];
            uint32_t key[2];
            const sdi_tprec *giv[2];
            if (!petal_a1(t, ef, x, S, v, c->tt_f[2 * i], a[0], &key[0]) ||
                !petal_a1(t, ef, x, S, v, c->tt_f[2 * i + 1], a[1], &key[1]) || key[0] == key[1])
                continue;
            for (int h = 0; h < 2; h++) {
                giv[h] = find_rec(&L, v, key[h]);
                if (giv[h] && giv[h]->kind != SD_TT_TANGENT)
                    giv[h] = NULL;
            }
            if (giv[0] && giv[1])
                continue;
            if (giv[0] || giv[1]) { /* one given: the other takes its opposite */
                int h = giv[0] ? 1 : 0;
                double neg[3] = {-giv[1 - h]->d[0], -giv[1 - h]->d[1], -giv[1 - h]->d[2]};
                double len = norm3(a[h]);
                scale_to(T[h], neg, len > 0 ? len : 1);
                sdi_tprec r = {.v = v, .f = c->tt_f[2 * i + h], .key = key[h],
                               .kind = SD_TT_TANGENT};
                memcpy(r.d, T[h], sizeof r.d);
                if (!tp_push(m, &I, r))
                    goto nomem_i;
                continue;
            }
            /* "t and -t": P_1 takes -unit(d), P_2 unit(d), each at its |a_1| */
            double d[3], cv[3];
            for (int k = 0; k < 3; k++) {
                d[k] = a[1][k] - a[0][k];
                cv[k] = x[3 * (size_t)S->tmp[0] + k] - x[3 * (size_t)S->tmp[1] + k];
            }
            double dl = norm3(d);
            if (!(dl > 1e-12 * (norm3(a[0]) + norm3(a[1]))))
                continue; /* the same interior tangent: nothing to project onto */
            if (parallel3(cv, d))
                continue; /* along the curve: no tangent plane with it, neither constrained */
            for (int h = 0; h < 2; h++) {
                double len = norm3(a[h]);
                scale_to(T[h], d, (h ? 1 : -1) * (len > 0 ? len : 1));
                sdi_tprec r = {.v = v, .f = c->tt_f[2 * i + h], .key = key[h],
                               .kind = SD_TT_TANGENT};
                memcpy(r.d, T[h], sizeof r.d);
                if (!tp_push(m, &I, r))
                    goto nomem_i;
            }
        }
    }
    for (uint32_t i = 0; i < I.n; i++)
        if (!tp_push(m, &L, I.r[i]))
            goto nomem_i;
    sdi_free(m, I.r);
    if (L.n) { /* one record per petal: the given one, else the first inferred */
        qsort(L.r, L.n, sizeof *L.r, cmp_rec);
        uint32_t w = 0;
        for (uint32_t i = 0; i < L.n; i++)
            if (!w || L.r[i].v != L.r[w - 1].v || L.r[i].key != L.r[w - 1].key)
                L.r[w++] = L.r[i];
        L.n = w;
    }
    tp->r = L.r;
    tp->n = L.n;
    tp->e = sdi_alloc(m, (ne + 1) * sizeof *tp->e);
    if (!tp->e) {
        sdi_tp_free(m, tp);
        return sdi_fail_nomem(err, m);
    }
    for (size_t i = 0; i < c->ntt; i++)
        if (c->tt[i].kind == SD_TT_EDGE) {
            tp->e[tp->ne][0] = c->tt[i].edge[0];
            tp->e[tp->ne++][1] = c->tt[i].edge[1];
        }
    *out = tp;
    return SD_OK;
nomem_i:
    sdi_free(m, I.r);
nomem:
    sdi_free(m, L.r);
    sdi_tp_free(m, tp);
    return sdi_fail_nomem(err, m);
}

/* ---- one level ---------------------------------------------------------------------------- */

/* A face of a constrained open petal at v (the record it belongs to), for the tagged edges. */
typedef struct pface {
    uint32_t v, f, rec;
} pface;

static int cmp_pface(const void *a, const void *b)
{
    const pface *p = a, *q = b;
    if (p->v != q->v)
        return p->v < q->v ? -1 : 1;
    return (p->f > q->f) - (p->f < q->f);
}

static const pface *find_pface(const pface *P, size_t n, uint32_t v, uint32_t f)
{
    pface want = {v, f, 0};
    return n ? bsearch(&want, P, n, sizeof *P, cmp_pface) : NULL;
}

typedef struct corr {
    uint32_t id;
    double d[3];
} corr;

sd_result sdi_tp_step(sd_complex *c, int l, sd_level *next, double *x, sd_error *err)
{
    if (c->opt.nonmanifold_surface != SD_NMSURF_YING_ZORIN || !c->ntt)
        return SD_OK;
    sd_mem *m = &c->mem;
    sd_level *lv = c->lv[l];
    const sd_topo *t = &lv->t;
    const uint32_t nv = t->nv;
    sdi_rels R = {.t = t};
    scratch S = {0};
    sd_result rc = SD_OK;
    corr *cs = NULL;
    pface *pf = NULL;
    size_t ncs = 0, ccs = 0, npf = 0, cpf = 0;
    struct sdi_tplane *nx = NULL;
    tplist L = {0};
    if (!sdi_rels_need(m, &R, SDI_REL(SDI_VE) | SDI_REL(SDI_EF)) ||
        !scratch_init(m, &S, t->nf + 4))
        goto nomem;
    if (l == 0) {
        sdi_tp_free(m, lv->tp);
        lv->tp = NULL;
        if ((rc = level0(c, &R, &S, &lv->tp, err)))
            goto out;
    }
    const struct sdi_tplane *tp = lv->tp;
    if (!tp)
        goto out;
    const sdi_rel *ef = &R.r[SDI_EF];
    const double s = SD_TT_S;
    for (uint32_t i = 0; i < tp->n; i++) {
        const sdi_tprec *r = &tp->r[i];
        const uint32_t v = r->v;
        uint32_t n, nf;
        if (!yz_at(t, v, r->kind))
            continue;
        int kind = petal_ring(t, ef, v, r->f, S.ring, S.tmp, S.faces, S.cap, &n, &nf);
        if (kind != (r->kind == SD_TT_NORMAL ? RING_CLOSED : RING_OPEN) ||
            (kind == RING_OPEN && nf < 2))
            continue;
        /* N_1(v) at level l + 1: v itself and the points of its edges, in the ring's order */
        for (uint32_t j = 0; j < n; j++)
            S.tmp[j] = nv + S.ring[j];
        if (ncs + n > ccs) {
            size_t cap = ccs ? 2 * ccs : 64;
            while (cap < ncs + n)
                cap *= 2;
            corr *nc = sdi_realloc(m, cs, cap * sizeof *nc);
            if (!nc)
                goto nomem;
            cs = nc;
            ccs = cap;
        }
        sdi_tprec child = *r;
        child.f = child_at(t, r->f, v);
        if (r->kind == SD_TT_NORMAL) {
            /* p <- p - s ((a_1, n) n x^1 + (a_2, n) n x^2) */
            double a1[3], a2[3];
            closed_a(x, v, S.tmp, n, a1, a2);
            const double d1 = dot3(a1, r->d), d2 = dot3(a2, r->d);
            for (uint32_t j = 0; j < n; j++) {
                const double w = -s * (sin(2 * M_PI * j / n) * d1 + cos(2 * M_PI * j / n) * d2);
                corr *q = &cs[ncs++];
                q->id = S.tmp[j];
                for (int d = 0; d < 3; d++)
                    q->d[d] = w * r->d[d];
            }
        } else {
            /* p <- p + s (lambda_1^r t_1 - a_1) x^1, lambda_1^r t_1 = T / 2 at level l + 1 */
            const uint32_t k = n - 1;
            double a1[3];
            open_a1(x, v, S.tmp, k, a1);
            for (int d = 0; d < 3; d++)
                child.d[d] = r->d[d] / 2;
            for (uint32_t j = 1; j < k; j++) {
                corr *q = &cs[ncs++];
                q->id = S.tmp[j];
                for (int d = 0; d < 3; d++)
                    q->d[d] = s * sin(j * M_PI / k) * (child.d[d] - a1[d]);
            }
            if (tp->ne) { /* the petal's faces, for the tagged edges at v */
                if (npf + nf > cpf) {
                    size_t cap = cpf ? 2 * cpf : 64;
                    while (cap < npf + nf)
                        cap *= 2;
                    pface *np = sdi_realloc(m, pf, cap * sizeof *np);
                    if (!np)
                        goto nomem;
                    pf = np;
                    cpf = cap;
                }
                for (uint32_t q = 0; q < nf; q++)
                    pf[npf++] = (pface){v, S.faces[q], L.n};
            }
        }
        if (!tp_push(m, &L, child))
            goto nomem;
    }
    for (size_t i = 0; i < ncs; i++) /* all from S's points, then added (the header) */
        for (int d = 0; d < 3; d++)
            x[3 * (size_t)cs[i].id + d] += cs[i].d[d];
    if (npf)
        qsort(pf, npf, sizeof *pf, cmp_pface);
    /* the tagged edges: their halves stay tagged; the vertex between them interpolates */
    nx = sdi_calloc(m, 1, sizeof *nx);
    if (!nx || !(nx->e = sdi_alloc(m, (2 * (size_t)tp->ne + 1) * sizeof *nx->e)))
        goto nomem;
    const uint32_t nrec = L.n;
    for (uint32_t i = 0; i < tp->ne; i++) {
        const uint32_t a = tp->e[i][0], b = tp->e[i][1], e = sdi_rels_edge(&R, a, b);
        if (e == UINT32_MAX)
            continue;
        const uint32_t mid = nv + e;
        nx->e[nx->ne][0] = a;
        nx->e[nx->ne++][1] = mid;
        nx->e[nx->ne][0] = mid;
        nx->e[nx->ne++][1] = b;
        for (uint32_t k = ef->off[e]; k < ef->off[e + 1]; k++) {
            const uint32_t g = ef->item[k];
            if (!(t->fflag[g] & FF_MAX))
                continue;
            const pface *pa = find_pface(pf, npf, a, g), *pb = find_pface(pf, npf, b, g);
            if (!pa || !pb || pa->rec >= nrec || pb->rec >= nrec)
                continue;
            /* 003 App. B: t^{j+1} = (t_a^j + t_b^j)/4 (the children's T are T_a/2, T_b/2) */
            sdi_tprec r = {.v = mid, .f = 4 * g + 3, .kind = SD_TT_TANGENT};
            for (int d = 0; d < 3; d++)
                r.d[d] = (L.r[pa->rec].d[d] + L.r[pb->rec].d[d]) / 2;
            if (!tp_push(m, &L, r))
                goto nomem;
        }
    }
    nx->r = L.r;
    nx->n = L.n;
    L.r = NULL;
    sdi_tp_free(m, next->tp);
    next->tp = nx;
    nx = NULL;
    goto out;
nomem:
    rc = sdi_fail_nomem(err, m);
out:
    sdi_free(m, L.r);
    sdi_tp_free(m, nx);
    sdi_free(m, cs);
    sdi_free(m, pf);
    scratch_free(m, &S);
    sdi_rels_free(m, &R);
    return rc;
}
