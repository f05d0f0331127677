/* rules.c — one rule per vertex and edge of a level (docs/RULES.md).
 *
 * Priority: singular tags (000 Sec. 4.1) > the simplex's own choice (N1, N2, G1, G2; overrides.c) > the
 * default non-manifold rule (G2, or G1 as tags; Ying-Zorin's where only triangles meet) >
 * boundary > interior:
 *   isolated point, curve end, junction of 3+ curves   corner
 *   curve                                              curve (cubic B-spline)
 *   surface / its boundary                             loop / loop-boundary
 *   solid / its boundary                               solid / solid-boundary
 *   non-manifold (types 1-4)                           G2 (000 Sec. 3.5), or the choice's part
 * A vertex whose neighbourhood does not fit its rule (a curve or boundary point with other than
 * two neighbours in its rho, any rule with none) is a corner: the rule reported is the one used.
 * Rules only reported (N1, N2, G1, the Ying-Zorin crease, corner and petal; rule_table.h) come
 * from the computed rule and the simplex's bits (sdi_reported_*_rule).
 *
 * The rule table (rule_table.h) gives each rule its name, its neighbours (rings.c), its masks
 * (masks.c) and its regular valences; choosing it is the cases below. The Ying-Zorin rules of
 * the edges at singular vertices are chosen per petal (sdi_yz_rules, 003 Sec. 2).
 */
#include "internal.h"
#include <math.h>
#include <string.h>

/* ---- the rule table ----------------------------------------------------------------------- */

#define RULE_NAME(id, name, ...) [id] = name,
static const char *const rule_names[SD_RULE_COUNT] = {SD_RULE_TABLE(RULE_NAME)};
#undef RULE_NAME
#define RULE_REGULAR(id, name, rho, vmask, ring, emask, vregular, eregular) [id] = {vregular, eregular},
static const uint32_t rule_regular[SD_RULE_COUNT][2] = {SD_RULE_TABLE(RULE_REGULAR)};
#undef RULE_REGULAR
#define RULE_RHO(id, name, rho, ...) [id] = SDI_RHO_##rho,
const uint8_t SDI_RULE_RHO[SD_RULE_COUNT] = {SD_RULE_TABLE(RULE_RHO)};
#undef RULE_RHO
#define RULE_RING(id, name, rho, vmask, ring, ...) [id] = SDI_RING_##ring,
const uint8_t SDI_RULE_RING[SD_RULE_COUNT] = {SD_RULE_TABLE(RULE_RING)};
#undef RULE_RING

const char *sd_rule_name(sd_rule r)
{
    return (unsigned)r < SD_RULE_COUNT ? rule_names[r] : "unknown";
}

bool sdi_rule_extraordinary(uint8_t rule, uint32_t k, bool edge)
{
    uint32_t regular = rule < SD_RULE_COUNT ? rule_regular[rule][edge] : 0;
    return regular && !(k < 32 && (regular >> k & 1));
}

/* ---- vertices and edges ------------------------------------------------------------------- */

uint8_t sdi_vertex_rule(const sd_topo *t, uint32_t v)
{
    uint8_t fam = t->vfam[v], nm = t->vnm[v], fl = t->vflag[v];
    /* singular tags first (docs/RULES.md "Priority"): corner; crease (B-spline along the creases);
     * embedded surface (Loop over the tagged triangles, B-spline along its boundary). A vertex
     * where creases meet a surface is a corner. */
    if (fl & VF_SING || (fl & VF_S_ANY) == VF_S_ANY)
        return SD_RULE_CORNER;
    if (fl & VF_SCREASE)
        return SD_RULE_CURVE;
    if (fl & VF_SSURF)
        return fl & VF_SBND ? SD_RULE_LOOP_BOUNDARY : SD_RULE_LOOP;
    if (nm) {
        switch (nm_ov(nm)) { /* the simplex's own choice (overrides.c); sdi_vertex_rules settles N1, N2 */
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
        switch (nm_ov(t->enm[e])) { /* the edge's own choice (overrides.c) */
        case OV_N1_1:
            return SD_RULE_CURVE;
        case OV_N1_2: /* as in C_2 alone: between two triangles, or its boundary */
            return t->enm[e] & NM_C2B ? SD_RULE_LOOP_BOUNDARY : SD_RULE_LOOP;
        case OV_N1_3: /* as in C_3 alone */
            return fl & EF_DC ? SD_RULE_SOLID_BOUNDARY : SD_RULE_SOLID;
        case OV_N2: /* Loop between the two chosen triangles (rings.c, sdi_edge_opposites) */
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

/* The rules of every edge, in parallel parts; any: whether some edge's ring is G2's or the
 * opposite vertices of its faces (per part). */
typedef struct erjob {
    const sd_topo *t;
    uint8_t *er;
    bool any_g2[SD_PAR_MAXT], any_opp[SD_PAR_MAXT];
} erjob;

static void erule_part(void *arg, uint32_t part, uint32_t nparts)
{
    erjob *J = arg;
    uint64_t lo, hi;
    sdi_range(J->t->ne, part, nparts, &lo, &hi);
    bool g2 = false, op = false;
    for (uint32_t e = (uint32_t)lo; e < (uint32_t)hi; e++) {
        uint8_t ring = SDI_RULE_RING[J->er[e] = edge_rule(J->t, e)];
        g2 |= ring == SDI_RING_G2;
        op |= ring == SDI_RING_OPPOSITE || ring == SDI_RING_BOUNDARY_OPPOSITE;
    }
    J->any_g2[part] = g2;
    J->any_opp[part] = op;
}

void sdi_edge_rules(const sd_topo *t, int threads, uint8_t *er, bool *any_g2, bool *any_opp)
{
    erjob J = {.t = t, .er = er};
    sdi_par(threads, t->ne, erule_part, &J);
    *any_g2 = *any_opp = false;
    for (uint32_t i = 0; i < sdi_par_parts(threads, t->ne); i++) {
        *any_g2 |= J.any_g2[i];
        *any_opp |= J.any_opp[i];
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

/* The per-vertex steps of sdi_vertex_rules, in parallel parts (ranges of vertices). */
typedef struct vrjob {
    const sd_topo *t;
    uint8_t *vr;
    uint32_t *cnt_a, *cnt_b;
} vrjob;

static void vrule_part(void *arg, uint32_t part, uint32_t nparts)
{
    const vrjob *J = arg;
    uint64_t lo, hi;
    sdi_range(J->t->nv, part, nparts, &lo, &hi);
    for (uint32_t v = (uint32_t)lo; v < hi; v++) {
        uint8_t r = sdi_vertex_rule(J->t, v);
        J->vr[v] = r | ((r == SD_RULE_G2 || (J->t->vflag[v] & VF_S_ANY)) ? SDI_VR_SLOW : 0);
    }
}

static void degenerate_part(void *arg, uint32_t part, uint32_t nparts)
{
    const vrjob *J = arg;
    uint8_t *vr = J->vr;
    uint32_t *cnt_a = J->cnt_a, *cnt_b = J->cnt_b;
    uint64_t lo, hi;
    sdi_range(J->t->nv, part, nparts, &lo, &hi);
    for (uint32_t v = (uint32_t)lo; v < hi; v++) {
        uint8_t rho = SDI_RULE_RHO[vr[v]];
        bool degenerate = rho == SDI_RHO_CURVE || rho == SDI_RHO_SURFACE_BOUNDARY
                          ? cnt_a[v] != 2 /* a point of a curve: two neighbours on it */
                          : vr[v] != SD_RULE_CORNER && cnt_a[v] == 0;
        if (degenerate || vr[v] == SD_RULE_CORNER) {
            vr[v] = SD_RULE_CORNER;
            cnt_a[v] = 0;
            if (cnt_b)
                cnt_b[v] = 0;
        }
    }
}

bool sdi_vertex_rules(sd_mem *m, const sd_topo *t, int scheme, int threads, uint8_t *vr,
                      uint32_t *cnt_a, uint32_t *cnt_b, uint8_t *take)
{
    const uint32_t nv = t->nv, ne = t->ne;
    vrjob J = {t, vr, cnt_a, cnt_b};
    /* in vr while rho is counted (rings.c): SDI_VR_SLOW, rho is decided per neighbour (G2,
     * singular); SDI_VR_OWN, by the simplex's own N1/N2 choice; SDI_VR_BND, such a vertex has an
     * edge of its part's boundary */
    sdi_par(threads, nv, vrule_part, &J);
    if (t->ovmask) { /* vertices with their own N1 / N2 choice and no tag */
        for (uint32_t v = 0; v < nv; v++) {
            int ov = nm_ov(t->vnm[v]);
            if (ov && ov != OV_G2 && !(t->vflag[v] & (VF_SING | VF_S_ANY)))
                vr[v] = (uint8_t)((vr[v] & SDI_VR_RULE) | SDI_VR_OWN);
        } /* N1 / N2 vertices: interior or boundary of the part they follow */
        for (uint32_t e = 0; e < ne; e++)
            for (int k = 0; k < 2; k++) {
                uint32_t v = t->ev[e][k];
                if (vr[v] & SDI_VR_OWN && sdi_ov_boundary_edge(t, nm_ov(t->vnm[v]), e))
                    vr[v] |= SDI_VR_BND;
            }
        for (uint32_t v = 0; v < nv; v++)
            if (vr[v] & SDI_VR_OWN) {
                int ov = nm_ov(t->vnm[v]);
                bool bnd = vr[v] & SDI_VR_BND;
                uint8_t r = ov == OV_YZX ? SD_RULE_CORNER
                          : ov == OV_N1_1 || ov == OV_YZS || (ov == OV_N2 && t->vfam[v] == FAM1) ? SD_RULE_CURVE
                          : ov == OV_N1_3 ? (bnd ? SD_RULE_SOLID_BOUNDARY : SD_RULE_SOLID)
                          : bnd ? SD_RULE_LOOP_BOUNDARY : SD_RULE_LOOP;
                vr[v] = r | SDI_VR_OWN;
            }
    }
    /* rho sizes; the flags go */
    if (!sdi_vertex_rho(m, t, scheme, threads, vr, cnt_a, cnt_b, take))
        return false;
    sdi_par(threads, nv, degenerate_part, &J);
    return true;
}

sd_result sdi_vertex_rules_only(sd_mem *m, const sd_topo *t, int scheme, uint8_t *vr)
{
    uint32_t *a = sdi_calloc(m, (size_t)t->nv + 1, sizeof *a), *b = sdi_calloc(m, (size_t)t->nv + 1, sizeof *b);
    bool ok = a && b && sdi_vertex_rules(m, t, scheme, 1, vr, a, b, NULL);
    sdi_free(m, a);
    sdi_free(m, b);
    return ok ? SD_OK : SD_ERR_NOMEM;
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
    end->g = sdi_mask_yz_gamma(theta);
    return true;
}

/* Each petal of each singular vertex walked once (petals.c); its tag is that of its last
 * triangle tagged otherwise than convex. */
bool sdi_yz_rules(sd_mem *m, const sd_complex *cx, int level, const sd_topo *t, const sdi_rels *R,
                  const double *x, sd_yzend (*gam)[2], uint8_t **geo)
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
