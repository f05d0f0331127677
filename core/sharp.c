/* sharp.c — semi-sharp creases: OpenSubdiv's Sdc::Crease semantics on our rows.
 *
 * A sharpness s in (0, 10) on an edge of a surface (or of the solids' boundary surface) or on a
 * vertex; infinitely sharp (s >= 10) is a singular tag and not stored here (the caller turns it
 * into one). Values are floats, and every sharpness computation is done in float as Sdc does it,
 * so a fractional weight is the same number OpenSubdiv computes.
 *
 * Per level (derived from level 0's lists on demand, never stored): the edges and vertices whose
 * sharpness is > 0. Children: a vertex point keeps s - 1 (0 below 1); the half of edge e at its
 * end x (edge 2e at ev[e][0], 2e+1 at ev[e][1]: split.c) gets s - 1, or with the Chaikin rule
 * (3/4 s + 1/4 the mean of the other semi-sharp edges at x) - 1; edges made inside faces are
 * smooth. Rows (stencil.c asks crease_vertex_row / crease_edge_row here for every row that a
 * sharpness reaches, on top of the row the rules made without it — the "base" row):
 *   edge point (Scheme::ComputeEdgeVertexMask): s > 0 and both halves still sharp: the midpoint;
 *     otherwise the smooth row blended with the midpoint by w = s (OpenSubdiv does not clamp it).
 *   vertex point (ComputeVertexVertexMask): the rule of the vertex at this level (pRule) and of
 *     its child (cRule) from the vertex's sharpness and the number of sharp edges at it — any
 *     vertex sharpness or more than two: corner; two: crease (B-spline along them); fewer: smooth
 *     (a dart is smooth) — where edges of the base rule's own creases (surface boundary, singular
 *     tags: infinitely sharp) count as two. Same rules: that rule's mask; else the blend
 *     w pRule + (1 - w) cRule, w = the mean sharpness of what became smooth (<= 1).
 * The base row is the smooth mask (Loop or the solid boundary's Loop) or the crease mask (a
 * boundary or singular crease); every sharper mask reads a subset of its columns (the crease
 * neighbours are points of rho), so a row keeps its columns and only its weights change.
 * Base rules other than these (solid interiors, G2, per-simplex choices) follow only a vertex
 * sharpness (the corner blend); edges do not change their rule (DECISIONS 43).
 */
#include "internal.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define SHARP_INF 10.0f

static float decrement(float s) { return s > 1.0f ? s - 1.0f : 0.0f; }

void sdi_sharp_free(sd_mem *m, sdi_sharp *s)
{
    sdi_free(m, s->e);
    sdi_free(m, s->es);
    sdi_free(m, s->v);
    sdi_free(m, s->vs);
    sdi_free(m, s->f);
    sdi_free(m, s->fs);
    memset(s, 0, sizeof *s);
}

/* Room for ne edges and nv vertices in *s (emptied); false (and nothing held) without memory. */
static bool lists_alloc(sd_mem *m, sdi_sharp *s, size_t ne, size_t nv, size_t nf)
{
    memset(s, 0, sizeof *s);
    s->span = 1;
    s->e = sdi_alloc(m, (ne + 1) * sizeof *s->e);
    s->es = sdi_alloc(m, (ne + 1) * sizeof *s->es);
    s->v = sdi_alloc(m, (nv + 1) * sizeof *s->v);
    s->vs = sdi_alloc(m, (nv + 1) * sizeof *s->vs);
    s->f = sdi_alloc(m, (nf + 1) * sizeof *s->f);
    s->fs = sdi_alloc(m, (nf + 1) * sizeof *s->fs);
    if (s->e && s->es && s->v && s->vs && s->f && s->fs)
        return true;
    sdi_sharp_free(m, s);
    return false;
}

/* ---- level 0: the stored lists ---------------------------------------------------------- */

typedef struct keyed {
    uint32_t id, src; /* the vertex or edge id; the entry's index in the input */
    float s;
} keyed;
static int cmp_keyed(const void *x, const void *y)
{
    const keyed *a = x, *b = y;
    if (a->id != b->id)
        return (a->id > b->id) - (a->id < b->id);
    return (a->src > b->src) - (a->src < b->src);
}

/* Sort by id; the first entry naming the same id as an earlier one, or NULL. */
static const keyed *sort_find_repeat(keyed *a, size_t n)
{
    qsort(a, n, sizeof *a, cmp_keyed);
    const keyed *rep = NULL;
    for (size_t i = 1; i < n; i++)
        if (a[i].id == a[i - 1].id && (!rep || a[i].src < rep->src))
            rep = &a[i];
    return rep;
}

/* Whether edge e of level 0 is an edge of a maximal triangle or of a face on the solids'
 * boundary (needs the relation edge -> faces). */
static bool surface_edge(const sd_topo *t, const sdi_rels *R, uint32_t e)
{
    const sdi_rel *ef = &R->r[SDI_EF];
    for (uint32_t k = ef->off[e]; k < ef->off[e + 1]; k++)
        if (t->fflag[ef->item[k]] & (FF_MAX | FF_BND3))
            return true;
    return false;
}

sd_result sd_complex_set_sharpness(sd_complex *c, const sd_sharpness *sh, size_t n, int method,
                                   sd_error *err)
{
    sd_topo *t = &c->lv[0]->t;
    sd_mem *m = &c->mem;
    if (method != SD_CREASE_UNIFORM && method != SD_CREASE_CHAIKIN)
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "unknown crease method %d", method);
    keyed *e = sdi_alloc(m, (n ? n : 1) * sizeof *e), *v = sdi_alloc(m, (n ? n : 1) * sizeof *v);
    keyed *f = sdi_alloc(m, (n ? n : 1) * sizeof *f);
    sdi_rels rels = {.t = t};
    sd_result rc = SD_OK;
    if (!e || !v || !f ||
        (n && !sdi_rels_need(m, &rels, SDI_REL(SDI_VE) | SDI_REL(SDI_EF) | SDI_REL(SDI_VF)))) {
        rc = sdi_fail_nomem(err, m);
        goto out;
    }
    size_t ne = 0, nv = 0, nf = 0;
    for (size_t i = 0; i < n && !rc; i++) {
        const sd_sharpness *x = sh + i;
        float s = x->value;
        if (x->nverts < 1 || x->nverts > 3) {
            rc = sdi_fail(err, SD_ERR_ARITY, (long)i, SD_SH_FIELD_SIMPLEX,
                          "sharpness %zu: a vertex, an edge or a triangle, not %d vertices", i,
                          x->nverts);
            break;
        }
        for (int j = 0; j < x->nverts; j++)
            if (x->v[j] >= t->nv)
                rc = sdi_fail(err, SD_ERR_INDEX, (long)i, SD_SH_FIELD_SIMPLEX,
                              "sharpness %zu: vertex %u out of range", i, x->v[j]);
        if (rc)
            break;
        if (!(s >= 0.0f) || !(s < SHARP_INF)) { /* NaN included */
            rc = sdi_fail(err, SD_ERR_VALUE, (long)i, SD_SH_FIELD_VALUE,
                          "sharpness %zu: a value in [0, 10) (10 and more is a singular tag)", i);
            break;
        }
        if (x->nverts == 1) {
            v[nv++] = (keyed){x->v[0], (uint32_t)i, s};
            continue;
        }
        if (x->nverts == 3) { /* a face of two solid cells */
            uint32_t id = sdi_rels_face(&rels, x->v);
            if (id == UINT32_MAX || t->fn3[id] != 2)
                rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_SH_FIELD_SIMPLEX,
                              "sharpness %zu: %u-%u-%u is not a triangle inside a solid (a face "
                              "of two cells)", i, x->v[0], x->v[1], x->v[2]);
            else
                f[nf++] = (keyed){id, (uint32_t)i, s};
            continue;
        }
        uint32_t id = x->v[0] == x->v[1] ? UINT32_MAX : sdi_rels_edge(&rels, x->v[0], x->v[1]);
        if (id == UINT32_MAX)
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_SH_FIELD_SIMPLEX,
                          "sharpness %zu: %u-%u is not an edge of the complex", i, x->v[0], x->v[1]);
        else if (!surface_edge(t, &rels, id))
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_SH_FIELD_SIMPLEX,
                          "sharpness %zu: edge %u-%u is neither a surface edge nor on the solids' "
                          "boundary", i, x->v[0], x->v[1]);
        else
            e[ne++] = (keyed){id, (uint32_t)i, s};
    }
    if (rc)
        goto out;
    const keyed *rep[3] = {sort_find_repeat(e, ne), sort_find_repeat(v, nv),
                           sort_find_repeat(f, nf)};
    static const char *const what[3] = {"edge", "vertex", "triangle"};
    int first = -1;
    for (int k = 0; k < 3; k++)
        if (rep[k] && (first < 0 || rep[k]->src < rep[first]->src))
            first = k;
    if (first >= 0) {
        rc = sdi_fail(err, SD_ERR_DUPLICATE, (long)rep[first]->src, SD_SH_FIELD_SIMPLEX,
                      "sharpness %u names the same %s as an earlier one", rep[first]->src,
                      what[first]);
        goto out;
    }
    qsort(f, nf, sizeof *f, cmp_keyed);
    /* keep the nonzero ones */
    size_t je = 0, jv = 0, jf = 0;
    for (size_t i = 0; i < ne; i++)
        if (e[i].s > 0.0f)
            e[je++] = e[i];
    for (size_t i = 0; i < nv; i++)
        if (v[i].s > 0.0f)
            v[jv++] = v[i];
    for (size_t i = 0; i < nf; i++)
        if (f[i].s > 0.0f)
            f[jf++] = f[i];
    sdi_sharp nw;
    if (!lists_alloc(m, &nw, je, jv, jf)) {
        rc = sdi_fail_nomem(err, m);
        goto out;
    }
    for (size_t i = 0; i < je; i++) {
        nw.e[i] = e[i].id;
        nw.es[i] = e[i].s;
    }
    for (size_t i = 0; i < jv; i++) {
        nw.v[i] = v[i].id;
        nw.vs[i] = v[i].s;
    }
    for (size_t i = 0; i < jf; i++) {
        nw.f[i] = f[i].id;
        nw.fs[i] = f[i].s;
    }
    nw.ne = (uint32_t)je;
    nw.nv = (uint32_t)jv;
    nw.nf = (uint32_t)jf;
    sdi_sharp_free(m, &c->sh);
    c->sh = nw;
    c->sh_method = method;
    sdi_drop_rules(c, c->lv[0]); /* level 0's rows change; every finer level follows */
out:
    sdi_rels_free(m, &rels);
    sdi_free(m, e);
    sdi_free(m, v);
    sdi_free(m, f);
    return rc;
}


/* ---- children ---------------------------------------------------------------------------- */

/* The sharp edges at each vertex, as positions into s->e (by vertex, then edge id). */
typedef struct at_vertex {
    uint32_t v, i;
} at_vertex;
static int cmp_at(const void *x, const void *y)
{
    const at_vertex *a = x, *b = y;
    if (a->v != b->v)
        return (a->v > b->v) - (a->v < b->v);
    return (a->i > b->i) - (a->i < b->i);
}

bool sdi_sharp_children(sd_mem *m, const sd_topo *t, const sdi_sharp *s, int method,
                        float (*cs)[2])
{
    for (uint32_t i = 0; i < s->ne; i++)
        cs[i][0] = cs[i][1] = decrement(s->es[i]);
    if (method != SD_CREASE_CHAIKIN || s->ne < 2)
        return true;
    at_vertex *a = sdi_alloc(m, 2 * (size_t)s->ne * sizeof *a);
    if (!a)
        return false;
    for (uint32_t i = 0; i < s->ne; i++)
        for (int k = 0; k < 2; k++)
            a[2 * i + k] = (at_vertex){t->ev[s->e[i]][k], i};
    size_t n = 2 * (size_t)s->ne;
    qsort(a, n, sizeof *a, cmp_at);
    for (size_t j = 0, j1; j < n; j = j1) {
        float sum = 0.0f;
        int cnt = 0;
        for (j1 = j; j1 < n && a[j1].v == a[j].v; j1++) { /* in increasing edge id */
            sum += s->es[a[j1].i];
            cnt++;
        }
        if (cnt < 2)
            continue; /* one semi-sharp edge: a plain decrement */
        for (size_t q = j; q < j1; q++) {
            uint32_t i = a[q].i;
            float p = s->es[i];
            float other = (sum - p) / (float)(cnt - 1);
            float c = ((0.75f * p) + (0.25f * other)) - 1.0f;
            int k = t->ev[s->e[i]][0] == a[q].v ? 0 : 1;
            cs[i][k] = c > 0.0f ? c : 0.0f;
        }
    }
    sdi_free(m, a);
    return true;
}

/* Level l+1's lists from level l's (s, with cs its children's edge sharpness). */
static bool next_lists(sd_mem *m, const sdi_sharp *s, const float (*cs)[2], sdi_sharp *out)
{
    if (!lists_alloc(m, out, 2 * (size_t)s->ne, s->nv, s->nf))
        return false;
    out->span = s->span * 4; /* a face's children: 4 f .. 4 f + 3 (split.c) */
    for (uint32_t i = 0; i < s->nf; i++) {
        float d = s->fs[i] - 1.0f;
        if (d > 0.0f) {
            out->f[out->nf] = s->f[i];
            out->fs[out->nf++] = d;
        }
    }
    for (uint32_t i = 0; i < s->ne; i++) /* halves 2e, 2e + 1: still in increasing order */
        for (int k = 0; k < 2; k++)
            if (cs[i][k] > 0.0f) {
                out->e[out->ne] = 2 * s->e[i] + (uint32_t)k;
                out->es[out->ne++] = cs[i][k];
            }
    for (uint32_t i = 0; i < s->nv; i++) {
        float d = decrement(s->vs[i]);
        if (d > 0.0f) {
            out->v[out->nv] = s->v[i];
            out->vs[out->nv++] = d;
        }
    }
    return true;
}

bool sdi_sharp_level(sd_complex *c, int level, sdi_sharp *out)
{
    sd_mem *m = &c->mem;
    memset(out, 0, sizeof *out);
    if (!c->sh.ne && !c->sh.nv && !c->sh.nf)
        return true;
    sdi_sharp cur; /* a copy of level 0's lists */
    if (!lists_alloc(m, &cur, c->sh.ne, c->sh.nv, c->sh.nf))
        return false;
    cur.nf = c->sh.nf;
    memcpy(cur.f, c->sh.f, cur.nf * sizeof *cur.f);
    memcpy(cur.fs, c->sh.fs, cur.nf * sizeof *cur.fs);
    /* the edges whose rule is a surface's: a boundary or a crease of tags or rules is
     * infinitely sharp already (OpenSubdiv's boundary edges), so its sharpness neither changes
     * its row nor counts at its ends, nor in Chaikin's means (halves keep their edge's rule) */
    const sd_topo *t0 = &c->lv[0]->t;
    uint8_t *er = c->sh.ne ? sdi_alloc(m, (size_t)t0->ne + 1) : NULL;
    if (c->sh.ne && !er) {
        sdi_sharp_free(m, &cur);
        return false;
    }
    if (er) {
        bool g2, opp;
        sdi_edge_rules(t0, 1, er, &g2, &opp);
    }
    for (uint32_t i = 0; i < c->sh.ne; i++)
        if (er[c->sh.e[i]] == SD_RULE_LOOP || er[c->sh.e[i]] == SD_RULE_SOLID_BOUNDARY) {
            cur.e[cur.ne] = c->sh.e[i];
            cur.es[cur.ne++] = c->sh.es[i];
        }
    sdi_free(m, er);
    cur.nv = c->sh.nv;
    memcpy(cur.v, c->sh.v, cur.nv * sizeof *cur.v);
    memcpy(cur.vs, c->sh.vs, cur.nv * sizeof *cur.vs);
    for (int l = 0; l < level && (cur.ne || cur.nv || cur.nf); l++) {
        float (*cs)[2] = sdi_alloc(m, ((size_t)cur.ne + 1) * sizeof *cs);
        sdi_sharp nx;
        bool ok = cs && sdi_sharp_children(m, &c->lv[l]->t, &cur, c->sh_method, cs) &&
                  next_lists(m, &cur, (const float(*)[2])cs, &nx);
        sdi_free(m, cs);
        sdi_sharp_free(m, &cur);
        if (!ok)
            return false;
        cur = nx;
    }
    *out = cur;
    return true;
}

/* ---- rows -------------------------------------------------------------------------------- */

enum { R_SMOOTH, R_CREASE, R_CORNER };

static int vertex_rule(float vs, int nsharp)
{
    return vs > 0.0f || nsharp > 2 ? R_CORNER : nsharp == 2 ? R_CREASE : R_SMOOTH;
}

/* How the base rule of a vertex counts (see the header): 0 smooth, 2 a crease of its own, -1
 * edges do not count (only a vertex sharpness), -2 nothing applies (a corner). */
static int base_count(uint8_t rule)
{
    switch (rule) {
    case SD_RULE_LOOP:
    case SD_RULE_SOLID_BOUNDARY:
        return 0;
    case SD_RULE_LOOP_BOUNDARY:
    case SD_RULE_CURVE:
        return 2;
    case SD_RULE_CORNER:
        return -2;
    default:
        return -1;
    }
}

/* ---- the sharp embedded surface ---------------------------------------------------------- */

typedef struct edge_face {
    uint32_t e, f;
    float s;
} edge_face;
static int cmp_edge_face(const void *x, const void *y)
{
    const edge_face *a = x, *b = y;
    if (a->e != b->e)
        return (a->e > b->e) - (a->e < b->e);
    return (a->f > b->f) - (a->f < b->f);
}
typedef struct vert_edge {
    uint32_t v, e;
    uint8_t bnd;  /* the edge is on the surface's boundary (one sharp triangle) */
    uint8_t nm;   /* ... or on three or more */
    float w;
} vert_edge;
static int cmp_vert_edge(const void *x, const void *y)
{
    const vert_edge *a = x, *b = y;
    if (a->v != b->v)
        return (a->v > b->v) - (a->v < b->v);
    return (a->e > b->e) - (a->e < b->e);
}

static double clamp1(float s) { return s >= 1.0f ? 1.0 : (double)s; }

/* The rows of the sharp triangles alive at this level: each interior solid edge and vertex on
 * them gets the embedded surface's rule (Loop over the sharp triangles, B-spline along their
 * boundary, a corner where neither fits; an edge of three or more sharp triangles is a crease)
 * and a weight min(1, s) of the sharpest triangle at it. */
static bool surf_rows(sd_mem *m, const sd_topo *t, const sdi_sharp *s, const uint8_t *vr,
                      const uint8_t *take, sdi_sharp_rows_t *out)
{
    uint64_t nfaces = (uint64_t)s->nf * s->span;
    edge_face *ef = sdi_alloc(m, (3 * nfaces + 1) * sizeof *ef);
    if (!ef)
        return false;
    size_t n = 0;
    for (uint32_t i = 0; i < s->nf; i++)
        for (uint64_t k = 0; k < s->span; k++) {
            uint32_t f = (uint32_t)((uint64_t)s->f[i] * s->span + k);
            for (int j = 0; j < 3; j++)
                ef[n++] = (edge_face){t->fe[f][j], f, s->fs[i]};
        }
    qsort(ef, n, sizeof *ef, cmp_edge_face);
    size_t nedges = 0;
    for (size_t j = 0; j < n; j++)
        nedges += !j || ef[j].e != ef[j - 1].e;
    out->sedge = sdi_alloc(m, (nedges + 1) * sizeof *out->sedge);
    vert_edge *ve = sdi_alloc(m, (2 * nedges + 1) * sizeof *ve);
    if (!out->sedge || !ve) {
        sdi_free(m, ef);
        sdi_free(m, ve);
        return false;
    }
    size_t nve = 0;
    for (size_t j = 0, j1; j < n; j = j1) {
        uint32_t e = ef[j].e, cnt = 0;
        float smax = 0.0f;
        sdi_surf_edge x = {.e = e};
        for (j1 = j; j1 < n && ef[j1].e == e; j1++) {
            if (cnt < 2) { /* the vertex of the triangle across e */
                const uint32_t *fv = t->fv[ef[j1].f];
                for (int q = 0; q < 3; q++)
                    if (fv[q] != t->ev[e][0] && fv[q] != t->ev[e][1])
                        x.opp[cnt] = fv[q];
            }
            cnt++;
            smax = ef[j1].s > smax ? ef[j1].s : smax;
        }
        x.kind = cnt == 2 ? SDI_SURF_LOOP : SDI_SURF_MIDPOINT;
        x.w = clamp1(smax);
        if (t->efam[e] == FAM3 && !(t->eflag[e] & EF_DC))
            out->sedge[out->nsedge++] = x; /* an edge inside the solids */
        for (int k = 0; k < 2; k++)
            ve[nve++] = (vert_edge){t->ev[e][k], e, cnt == 1, cnt > 2, smax};
    }
    sdi_free(m, ef);
    qsort(ve, nve, sizeof *ve, cmp_vert_edge);
    size_t nverts = 0;
    for (size_t j = 0; j < nve; j++)
        nverts += !j || ve[j].v != ve[j - 1].v;
    out->svert = sdi_alloc(m, (nverts + 1) * sizeof *out->svert);
    uint32_t *nbe = sdi_alloc(m, (nve + 1) * sizeof *nbe); /* the neighbours' edges */
    out->nbpos = sdi_alloc(m, (nve + 1) * sizeof *out->nbpos);
    int32_t *slot = sdi_alloc(m, ((size_t)t->nv + 1) * sizeof *slot);
    uint32_t *cnt = sdi_calloc(m, nverts + 1, sizeof *cnt), *cur = sdi_calloc(m, nverts + 1, sizeof *cur);
    bool ok = out->svert && nbe && out->nbpos && slot && cnt && cur;
    uint32_t off = 0;
    for (size_t j = 0, j1; ok && j < nve; j = j1) {
        uint32_t v = ve[j].v, nb = 0, nbnd = 0;
        bool nm = false;
        float smax = 0.0f;
        for (j1 = j; j1 < nve && ve[j1].v == v; j1++) {
            nb++;
            nbnd += ve[j1].bnd;
            nm |= ve[j1].nm;
            smax = ve[j1].w > smax ? ve[j1].w : smax;
        }
        if ((vr[v] & SDI_VR_RULE) != SD_RULE_SOLID)
            continue; /* on the solids' boundary or of another rule: its own row */
        sdi_surf_vertex x = {.v = v, .off = off, .w = clamp1(smax)};
        x.kind = nm ? SDI_SURF_CORNER : nbnd == 0 ? SDI_SURF_LOOP
               : nbnd == 2 ? SDI_SURF_BSPLINE : SDI_SURF_CORNER;
        for (size_t q = j; q < j1; q++)
            if (x.kind == SDI_SURF_LOOP || (x.kind == SDI_SURF_BSPLINE && ve[q].bnd))
                nbe[off + x.n++] = ve[q].e; /* in increasing edge id, as rho */
        off += x.n;
        out->svert[out->nsvert++] = x;
    }
    /* the neighbours' places in rho (rings.c: increasing edge id, through the edges v reads) */
    if (ok) {
        for (uint32_t i = 0; i < t->nv; i++)
            slot[i] = -1;
        for (uint32_t i = 0; i < out->nsvert; i++)
            slot[out->svert[i].v] = (int32_t)i;
        for (uint32_t i = 0; i < off; i++)
            out->nbpos[i] = -1;
        for (uint32_t e = 0; e < t->ne; e++)
            for (int k = 0; k < 2; k++) {
                int32_t sl = slot[t->ev[e][k]];
                if (sl < 0 || !(take[e] & (1u << k)))
                    continue;
                const sdi_surf_vertex *x = &out->svert[sl];
                if (cur[sl] < x->n && nbe[x->off + cur[sl]] == e)
                    out->nbpos[x->off + cur[sl]++] = (int32_t)cnt[sl];
                cnt[sl]++;
            }
    }
    sdi_free(m, ve);
    sdi_free(m, nbe);
    sdi_free(m, slot);
    sdi_free(m, cnt);
    sdi_free(m, cur);
    return ok;
}

void sdi_surf_vertex_row(const sdi_sharp_rows_t *r, const sdi_surf_vertex *x, int weights,
                         double *w, uint32_t len, double *tmp)
{
    memset(tmp, 0, len * sizeof *tmp);
    if (x->kind == SDI_SURF_CORNER)
        tmp[0] = 1.0;
    else {
        double c = x->kind == SDI_SURF_LOOP ? sdi_loop_weight(weights, x->n) : 1.0 / 8.0;
        tmp[0] = x->kind == SDI_SURF_LOOP ? 1 - x->n * c : 6.0 / 8.0;
        for (uint32_t i = 0; i < x->n; i++) {
            int32_t p = r->nbpos[x->off + i];
            if (p < 0 || (uint32_t)p + 1 >= len)
                return; /* not in the row: it stays */
            tmp[1 + p] = c;
        }
    }
    for (uint32_t i = 0; i < len; i++)
        w[i] = x->w * tmp[i] + (1.0 - x->w) * w[i];
}

void sdi_surf_edge_row(const sdi_surf_edge *x, const uint32_t *ring, double *w, uint32_t len)
{
    int pos[2] = {-1, -1};
    if (x->kind == SDI_SURF_LOOP) {
        for (uint32_t i = 0; i + 2 < len; i++)
            for (int k = 0; k < 2; k++)
                if (ring[i] == x->opp[k] && pos[k] < 0)
                    pos[k] = (int)i;
        if (pos[0] < 0 || pos[1] < 0)
            return; /* not in the ring: the row stays */
    }
    double e = x->kind == SDI_SURF_LOOP ? 3.0 / 8.0 : 0.5, cw = 1.0 - x->w;
    w[0] = x->w * e + cw * w[0];
    w[1] = x->w * e + cw * w[1];
    for (uint32_t i = 2; i < len; i++)
        w[i] *= cw;
    if (x->kind == SDI_SURF_LOOP)
        for (int k = 0; k < 2; k++)
            w[2 + pos[k]] += x->w / 8.0;
}

bool sdi_sharp_rows(sd_mem *m, const sd_topo *t, const sdi_sharp *s, int method,
                    const uint8_t *vr, const uint8_t *take, sdi_sharp_rows_t *out)
{
    memset(out, 0, sizeof *out);
    if (s->nf && !surf_rows(m, t, s, vr, take, out))
        return false;
    if (!s->ne && !s->nv)
        return true;
    float (*cs)[2] = sdi_alloc(m, ((size_t)s->ne + 1) * sizeof *cs);
    int32_t *slot = sdi_alloc(m, ((size_t)t->nv + 1) * sizeof *slot);
    /* per vertex reached: its edges (sharp at this level) as (vertex, edge list index) */
    at_vertex *a = sdi_alloc(m, (2 * (size_t)s->ne + 1) * sizeof *a);
    if (!cs || !slot || !a || !sdi_sharp_children(m, t, s, method, cs))
        goto nomem;
    /* edge rows */
    out->edge = sdi_alloc(m, ((size_t)s->ne + 1) * sizeof *out->edge);
    if (!out->edge)
        goto nomem;
    for (uint32_t i = 0; i < s->ne; i++) {
        sdi_sharp_edge *x = &out->edge[out->nedge++];
        x->e = s->e[i];
        x->crease = cs[i][0] > 0.0f && cs[i][1] > 0.0f;
        x->w = (double)s->es[i];
    }
    /* the vertices reached: ends of sharp edges and sharp vertices, once each */
    size_t na = 0;
    for (uint32_t i = 0; i < s->ne; i++)
        for (int k = 0; k < 2; k++)
            a[na++] = (at_vertex){t->ev[s->e[i]][k], i};
    qsort(a, na, sizeof *a, cmp_at);
    size_t nreach = 0;
    for (size_t j = 0; j < na; j++)
        if (!j || a[j].v != a[j - 1].v)
            nreach++;
    out->vert = sdi_calloc(m, nreach + s->nv + 1, sizeof *out->vert);
    if (!out->vert)
        goto nomem;
    /* merge the two sorted sources into out->vert (sorted by vertex) */
    size_t j = 0, q = 0;
    while (j < na || q < s->nv) {
        uint32_t v = j < na && (q >= s->nv || a[j].v <= s->v[q]) ? a[j].v : s->v[q];
        sdi_sharp_vertex *x = &out->vert[out->nvert];
        memset(x, 0, sizeof *x);
        x->v = v;
        x->pos[0][0] = x->pos[0][1] = x->pos[1][0] = x->pos[1][1] = -1;
        float pvs = 0.0f;
        if (q < s->nv && s->v[q] == v)
            pvs = s->vs[q++];
        float cvs = decrement(pvs);
        int base = base_count(vr[v] & SDI_VR_RULE);
        int np = base > 0 ? base : 0, nc = np;
        /* transitions (Crease::ComputeFractionalWeightAtVertex): vertex first, then edges */
        int tcount = 0;
        float tsum = 0.0f;
        if (pvs > 0.0f && cvs <= 0.0f) {
            tcount = 1;
            tsum = pvs;
        }
        size_t j0 = j;
        for (; j < na && a[j].v == v; j++) {
            if (base < 0)
                continue;
            uint32_t i = a[j].i;
            int k = t->ev[s->e[i]][0] == v ? 0 : 1;
            float ps = s->es[i], c = cs[i][k];
            np++;
            if (c > 0.0f)
                nc++;
            if (method == SD_CREASE_CHAIKIN ? c <= 0.0f : ps <= 1.0f) {
                tsum += ps;
                tcount++;
            }
        }
        if (base == -2) { /* a corner stays one */
            continue;
        }
        int pr = vertex_rule(pvs, np), cr = vertex_rule(cvs, nc);
        if (pr == R_SMOOTH) /* smooth or a dart: the base row */
            continue;
        x->prule = (uint8_t)pr;
        x->crule = (uint8_t)cr;
        float fw = tcount ? tsum / (float)tcount : 0.0f;
        x->w = pr == cr ? 1.0 : (double)(fw > 1.0f ? 1.0f : fw);
        /* the two sharp edges a crease rule reads when they are not the base rule's own (base
         * 0): every sharp edge for the parent, those whose half stays sharp for the child */
        for (size_t jj = j0; jj < j && base == 0; jj++) {
            uint32_t i = a[jj].i;
            int k = t->ev[s->e[i]][0] == v ? 0 : 1;
            if (pr == R_CREASE && x->nedge[0] < 2)
                x->edge[0][x->nedge[0]++] = s->e[i];
            if (cr == R_CREASE && cs[i][k] > 0.0f && x->nedge[1] < 2)
                x->edge[1][x->nedge[1]++] = s->e[i];
        }
        out->nvert++;
    }
    /* positions of those edges in rho (rings.c: rho in increasing edge order, through the edges
     * v reads) */
    for (uint32_t i = 0; i < t->nv; i++)
        slot[i] = -1;
    for (uint32_t i = 0; i < out->nvert; i++)
        if (out->vert[i].nedge[0] || out->vert[i].nedge[1])
            slot[out->vert[i].v] = (int32_t)i;
    uint32_t *cnt = sdi_calloc(m, (size_t)out->nvert + 1, sizeof *cnt);
    if (!cnt)
        goto nomem;
    for (uint32_t e = 0; e < t->ne; e++)
        for (int k = 0; k < 2; k++) {
            int32_t sl = slot[t->ev[e][k]];
            if (sl < 0 || !(take[e] & (1u << k)))
                continue;
            sdi_sharp_vertex *x = &out->vert[sl];
            for (int r = 0; r < 2; r++)
                for (int p = 0; p < x->nedge[r]; p++)
                    if (x->edge[r][p] == e)
                        x->pos[r][p] = (int32_t)cnt[sl];
            cnt[sl]++;
        }
    sdi_free(m, cnt);
    sdi_free(m, cs);
    sdi_free(m, slot);
    sdi_free(m, a);
    return true;
nomem:
    sdi_free(m, cs);
    sdi_free(m, slot);
    sdi_free(m, a);
    sdi_sharp_rows_free(m, out);
    return false;
}

void sdi_sharp_rows_free(sd_mem *m, sdi_sharp_rows_t *r)
{
    sdi_free(m, r->vert);
    sdi_free(m, r->edge);
    sdi_free(m, r->svert);
    sdi_free(m, r->sedge);
    sdi_free(m, r->nbpos);
    memset(r, 0, sizeof *r);
}

/* One rule's mask (which: 0 the parent's, 1 the child's) into w, given the base row of len
 * entries (see the header); false if a crease edge is not in rho (then the base row stays). */
static bool rule_mask(const sdi_sharp_vertex *x, int which, const double *base, uint32_t len,
                      double *w)
{
    int rule = which ? x->crule : x->prule;
    if (rule == R_SMOOTH || (rule == R_CREASE && !x->nedge[which])) { /* the base row */
        memcpy(w, base, len * sizeof *w);
        return true;
    }
    memset(w, 0, len * sizeof *w);
    if (rule == R_CORNER) {
        w[0] = 1.0;
        return true;
    }
    for (int p = 0; p < 2; p++)
        if (x->nedge[which] != 2 || x->pos[which][p] < 0 || (uint32_t)x->pos[which][p] + 1 >= len)
            return false;
    w[0] = 0.75;
    w[1 + x->pos[which][0]] = 0.125;
    w[1 + x->pos[which][1]] = 0.125;
    return true;
}

void sdi_sharp_vertex_row(const sdi_sharp_vertex *x, double *w, uint32_t len, double *tmp)
{
    /* tmp: 2 len doubles. Parent mask into tmp, child mask into tmp + len */
    double *pm = tmp, *cm = tmp + len;
    if (!rule_mask(x, 0, w, len, pm))
        return;
    if (x->prule == x->crule) {
        memcpy(w, pm, len * sizeof *w);
        return;
    }
    if (!rule_mask(x, 1, w, len, cm))
        return;
    double pw = x->w, cw = 1.0 - pw;
    for (uint32_t i = 0; i < len; i++)
        w[i] = pw * pm[i] + cw * cm[i];
}

void sdi_sharp_edge_row(const sdi_sharp_edge *x, double *w, uint32_t len)
{
    if (x->crease) {
        w[0] = w[1] = 0.5;
        for (uint32_t i = 2; i < len; i++)
            w[i] = 0.0;
        return;
    }
    double pw = x->w, cw = 1.0 - pw;
    w[0] = pw * 0.5 + cw * w[0];
    w[1] = pw * 0.5 + cw * w[1];
    for (uint32_t i = 2; i < len; i++)
        w[i] *= cw;
}
