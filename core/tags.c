/* tags.c — the singular complex S (000 Sec. 4.1) and the per-simplex non-manifold rules
 * (000 Sec. 3.5), stored as bits on level 0 and inherited by every child in split.c.
 *
 * Singular tags: vertices (corners), edges (creases) and triangles (embedded surfaces). Halves of
 * a crease are creases, children of a tagged triangle and the edges inside it are tagged, edge
 * points of S-edges lie on S. Derived bits: a tagged edge that is a side of a tagged triangle
 * belongs to the surface, not to a crease; a surface edge with exactly one tagged triangle is the
 * surface's boundary; a vertex carries the kinds of S-edges it lies on.
 *
 * Per-simplex rules (sd_override): G1 is a singularity — a vertex becomes a corner, an edge a
 * crease, exactly as a tag, marked NM_G1 so that it is reported as G1. N1 and N2 are codes in
 * the high bits of vnm / enm that children keep (the edge point of an N1 edge is an N1 vertex of
 * the same dimension). N2 marks the chosen curve segments (EF_N2SEL) or triangles (FF_N2SEL; at
 * a vertex the whole petals holding the two chosen triangles), and their sides (EF_N2SEL, and
 * EF_N2BND where exactly one chosen triangle meets). The default G1 makes every non-manifold
 * edge without a choice a crease and every such vertex on none of them a corner.
 *
 * Priority (SPEC Sec. 3): tag > the simplex's own choice > the default rule. rules.c turns the
 * bits into rules. Everything is recomputed from the stored tags and overrides on each change.
 */
#include "internal.h"
#include <stdlib.h>
#include <stdio.h>
#include <string.h>

/* Level 0's relations (topo.c) the lookups below use: a tag or override is found in time
 * linear in the complex (a lookup scans the smallest list it can). */
#define TAG_RELS (SDI_REL(SDI_VE) | SDI_REL(SDI_VF) | SDI_REL(SDI_EF))

/* Mark with FF_N2SEL every maximal triangle of the fan of v (petals.c: SDI_PETAL_FAN) holding
 * triangle f0; returns the number of triangles marked now (already marked ones are not counted).
 * buf: room for the triangles at v and 2 more. */
static uint32_t mark_petal(sd_topo *t, const sdi_rels *R, uint32_t v, uint32_t f0, uint32_t *buf,
                           uint32_t cap)
{
    sdi_petal p = {.face = buf, .cap = cap};
    sdi_petal_of(t, &R->r[SDI_EF], SDI_PETAL_FAN, v, f0, &p);
    uint32_t added = 0;
    for (uint32_t k = 0; k < p.nf; k++)
        if (!(t->fflag[p.face[k]] & FF_N2SEL)) {
            t->fflag[p.face[k]] |= FF_N2SEL;
            added++;
        }
    return added;
}

/* ---- tags -------------------------------------------------------------------------------- */

sd_result sd_complex_set_singular(sd_complex *c, const uint32_t *idx, const uint8_t *size,
                                  size_t n, sd_error *err)
{
    sd_topo *t = &c->lv[0]->t;
    sd_mem *m = &c->mem;
    /* validate and locate every tag first: all-or-nothing */
    uint32_t *where = sdi_alloc(m, (n ? n : 1) * sizeof *where);
    uint8_t *kind = sdi_alloc(m, n ? n : 1);
    sdi_rels rels = {.t = t}, *R = &rels;
    if (!where || !kind || (n && !sdi_rels_need(m, R, TAG_RELS))) {
        sdi_rels_free(m, R);
        sdi_free(m, where);
        sdi_free(m, kind);
        return sdi_fail_nomem(err, m);
    }
    size_t off = 0;
    sd_result rc = SD_OK;
    for (size_t i = 0; i < n && !rc; off += size[i++]) {
        const uint32_t *v = idx + off;
        int k = size[i];
        if (k < 1 || k > 3) {
            rc = sdi_fail(err, SD_ERR_ARITY, (long)i, -1,
                         "tag %zu has %d vertices: a vertex, an edge or a triangle", i, k);
            break;
        }
        for (int j = 0; j < k && !rc; j++)
            if (v[j] >= t->nv)
                rc = sdi_fail(err, SD_ERR_INDEX, (long)i, j, "tag %zu: vertex %u out of range", i,
                             v[j]);
        if (rc)
            break;
        kind[i] = (uint8_t)k;
        where[i] = k == 1 ? v[0] : k == 2 ? sdi_rels_edge(R, v[0], v[1]) : sdi_rels_face(R, v);
        if (where[i] == UINT32_MAX)
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, -1, "tag %zu is not %s of the complex", i,
                         k == 2 ? "an edge" : "a triangle");
    }
    if (rc) {
        sdi_rels_free(m, R);
        sdi_free(m, where);
        sdi_free(m, kind);
        return rc;
    }
    uint32_t *old_at = c->tag_at;
    uint8_t *old_k = c->tag_k;
    size_t old_n = c->ntags;
    c->tag_at = where;
    c->tag_k = kind;
    c->ntags = n;
    if ((rc = sdi_apply_singular(c, R, err))) { /* only for lack of memory: put the old ones back */
        c->tag_at = old_at;
        c->tag_k = old_k;
        c->ntags = old_n;
        sd_error ignore;
        sdi_apply_singular(c, R, &ignore);
        sdi_rels_free(m, R);
        sdi_free(m, where);
        sdi_free(m, kind);
        return rc;
    }
    sdi_rels_free(m, R);
    sdi_free(m, old_at);
    sdi_free(m, old_k);
    return SD_OK;
}

/* ---- per-simplex rules -------------------------------------------------------------------- */

/* Check one override against level 0 (t) and find its simplex; item i. */
static sd_result check_override(const sdi_rels *R, const sd_override *o, size_t i,
                                uint32_t *at, sd_error *err)
{
    const sd_topo *t = R->t;
    const uint32_t *s = o->simplex;
    if (o->nverts < 1 || o->nverts > 2)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_SIMPLEX,
                       "rules are chosen per vertex or edge, not for a simplex of %d vertices",
                       o->nverts);
    for (int j = 0; j < o->nverts; j++)
        if (s[j] >= t->nv)
            return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_OV_FIELD_SIMPLEX,
                           "vertex %u out of range (%u vertices)", s[j], t->nv);
    bool edge = o->nverts == 2;
    if (edge && s[0] == s[1])
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_SIMPLEX, "vertex %u appears twice", s[0]);
    uint32_t id = edge ? sdi_rels_edge(R, s[0], s[1]) : s[0];
    if (id == UINT32_MAX)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_SIMPLEX,
                       "[%u, %u] is not an edge of the complex", s[0], s[1]);
    *at = id;
    char name[40];
    if (edge)
        snprintf(name, sizeof name, "edge [%u, %u]", s[0], s[1]);
    else
        snprintf(name, sizeof name, "vertex %u", s[0]);
    uint8_t fam = edge ? t->efam[id] : t->vfam[id];
    int type = nm_type(edge ? t->enm[id] : t->vnm[id]);
    if (o->rule != SD_RULE_N1 && o->rule != SD_RULE_N2 && o->rule != SD_RULE_G1 &&
        o->rule != SD_RULE_G2)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_RULE,
                       "the rule of a simplex is N1, N2, G1 or G2");
    if (!type)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_SIMPLEX,
                       "%s is manifold: non-manifold rules are for non-manifold simplices (tag "
                       "it singular to make it a corner or a crease)", name);
    if (o->rule == SD_RULE_N1) {
        if (type != 1)
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_RULE,
                           "N1 is for type-1 simplices, where parts of different dimensions "
                           "meet; %s is of type %d (use %s, G1 or G2)", name, type,
                           type == 2 || type == 4 ? "N2" : "G2");
        int d = o->dimension;
        if (d < 1 || d > 3 || !((fam >> d) & 1)) {
            char dims[16] = "", *p = dims;
            for (int k = 1; k <= 3; k++)
                if ((fam >> k) & 1)
                    p += snprintf(p, (size_t)(dims + sizeof dims - p), "%s%d", p == dims ? "" : ", ", k);
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_DIMENSION,
                           "%s has no part of dimension %d (its parts: %s)", name, d, dims);
        }
        return SD_OK;
    }
    if (o->rule != SD_RULE_N2)
        return SD_OK;
    if (type != 2 && type != 4)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_RULE,
                       "N2 is for type-2 simplices (three or more parts of one dimension sharing "
                       "it) and their faces; %s is of type %d (use %s, G1 or G2)", name, type,
                       type == 1 ? "N1" : "G2");
    bool curves = fam == FAM1;
    if (!curves && !(fam & FAM2))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_RULE,
                       "N2 at %s would choose a pair of tetrahedra: only pairs of curve segments "
                       "or triangles are supported (use G1 or G2)", name);
    if (edge && nm_type(t->enm[id]) != 2)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_RULE,
                       "N2 at an edge chooses two of the triangles sharing it; %s is of type %d",
                       name, type);
    int want = curves ? 2 : 3;
    if (o->pair_size != want)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_PAIR,
                       "the pair at %s is two %s (%d vertex ids each)", name,
                       curves ? "curve segments" : "triangles", want);
    uint32_t got[2];
    for (int j = 0; j < 2; j++) {
        const uint32_t *q = o->pair[j];
        for (int u = 0; u < want; u++)
            if (q[u] >= t->nv)
                return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_OV_FIELD_PAIR0 + j,
                               "vertex %u out of range (%u vertices)", q[u], t->nv);
        got[j] = curves ? sdi_rels_edge(R, q[0], q[1]) : sdi_rels_face(R, q);
        bool ok = got[j] != UINT32_MAX &&
                  (curves ? (t->eflag[got[j]] & EF_CURVE) != 0 : (t->fflag[got[j]] & FF_MAX) != 0);
        if (!ok)
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_PAIR0 + j,
                           "pair %d is not a %s of the complex", j,
                           curves ? "curve segment" : "triangle (a maximal one, not a face of a tetrahedron)");
        bool contains = true;
        for (int k = 0; k < o->nverts; k++) {
            bool in = false;
            for (int u = 0; u < want; u++)
                in |= q[u] == s[k];
            contains &= in;
        }
        if (!contains)
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_PAIR0 + j,
                           "pair %d does not contain %s", j, name);
    }
    if (got[0] == got[1])
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_PAIR1,
                       "the pair names the same simplex twice");
    return SD_OK;
}

/* Scratch for walks over the cells around a simplex (with the relations vertex -> tetrahedra
 * and face -> tetrahedra, built when an N1 with dimension 3 needs them). */
typedef struct tinc {
    uint32_t *stack;
    uint8_t *mark;
} tinc;

/* N1 with dimension d says "follow the rules of C_d alone"; that only decides the simplex's
 * rule if C_d is itself manifold there: its d-cells around the simplex are connected through
 * faces shared by exactly two of them. Otherwise (three fins on an edge, two solids touching at a
 * vertex) it is a 422 pointing at the dimension. */
static sd_result n1_part_manifold(sd_mem *m, sd_topo *t, sdi_rels *R, tinc *ti,
                                  const sd_override *o, size_t i, uint32_t id, sd_error *err)
{
    bool edge = o->nverts == 2;
    const char *what = edge ? "edge" : "vertex";
    const sdi_rel *vf = &R->r[SDI_VF], *ef = &R->r[SDI_EF];
    if (o->dimension == 2) {
        if (edge) {
            uint32_t n = 0;
            for (uint32_t k = ef->off[id]; k < ef->off[id + 1]; k++)
                n += (t->fflag[ef->item[k]] & FF_MAX) != 0;
            if (n <= 2)
                return SD_OK;
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_DIMENSION,
                           "the surfaces are themselves non-manifold at this edge (%u triangles "
                           "share it): N1 cannot pick one surface; use N2, G1 or G2", n);
        }
        /* one petal holds every maximal triangle around the vertex (marks saved in bit 64) */
        uint32_t total = 0, first = UINT32_MAX;
        for (uint32_t k = vf->off[id]; k < vf->off[id + 1]; k++) {
            uint32_t f = vf->item[k];
            t->fflag[f] = (uint8_t)((t->fflag[f] & ~FF_N2SEL) | ((t->fflag[f] & FF_N2SEL) ? 64 : 0));
            if (t->fflag[f] & FF_MAX) {
                total++;
                first = first == UINT32_MAX ? f : first;
            }
        }
        if (!ti->stack && !(ti->stack = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *ti->stack)))
            return sdi_fail_nomem(err, m);
        uint32_t got = first == UINT32_MAX ? 0 : mark_petal(t, R, id, first, ti->stack, t->nf + 1);
        for (uint32_t k = vf->off[id]; k < vf->off[id + 1]; k++) {
            uint32_t f = vf->item[k];
            t->fflag[f] = (uint8_t)((t->fflag[f] & ~(FF_N2SEL | 64)) | ((t->fflag[f] & 64) ? FF_N2SEL : 0));
        }
        if (got == total)
            return SD_OK;
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_DIMENSION,
                       "the surfaces are themselves non-manifold at vertex %u (its %u triangles "
                       "form more than one fan): N1 cannot pick one surface; use N2, G1 or G2",
                       id, total);
    }
    /* dimension 3: the tetrahedra around the simplex, connected through faces holding it */
    if (!sdi_rels_need(m, R, SDI_REL(SDI_VT) | SDI_REL(SDI_FT)) ||
        (!ti->mark && !(ti->mark = sdi_calloc(m, (size_t)t->ntet + 1, 1))) ||
        (!ti->stack && !(ti->stack = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *ti->stack))))
        return sdi_fail_nomem(err, m);
    const sdi_rel *vt = &R->r[SDI_VT], *ft = &R->r[SDI_FT];
    uint32_t a = edge ? t->ev[id][0] : id, b = edge ? t->ev[id][1] : UINT32_MAX;
    uint32_t total = 0, got = 0, top = 0, bad = 0;
    for (uint32_t k = vt->off[a]; k < vt->off[a + 1]; k++) {
        const uint32_t *q = t->tet[vt->item[k]];
        if (!edge || q[0] == b || q[1] == b || q[2] == b || q[3] == b) {
            total++;
            if (!top)
                ti->stack[top++] = vt->item[k], ti->mark[vt->item[k]] = 1;
        }
    }
    while (top) {
        uint32_t c = ti->stack[--top];
        got++;
        for (int j = 0; j < 4; j++) {
            uint32_t opp = t->tet[c][j], f = t->tet_f[c][j];
            if (opp == a || opp == b) /* face j is opposite vertex j: it must hold the simplex */
                continue;
            if (t->fn3[f] > 2)
                bad++;
            for (uint32_t k = ft->off[f]; k < ft->off[f + 1]; k++)
                if (!ti->mark[ft->item[k]]) {
                    ti->mark[ft->item[k]] = 1;
                    ti->stack[top++] = ft->item[k];
                }
        }
    }
    for (uint32_t k = vt->off[a]; k < vt->off[a + 1]; k++)
        ti->mark[vt->item[k]] = 0;
    if (got == total && !bad)
        return SD_OK;
    return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_DIMENSION,
                   "the solids are themselves non-manifold at this %s (its tetrahedra do not "
                   "form one piece joined through faces): N1 cannot pick one solid; use G1 or G2",
                   what);
}

sd_result sd_complex_set_overrides(sd_complex *c, const sd_override *ov, size_t n, sd_error *err)
{
    sd_topo *t = &c->lv[0]->t;
    sd_mem *m = &c->mem;
    tinc ti = {0};
    sdi_rels R = {.t = t};
    sd_override *copy = sdi_alloc(m, (n ? n : 1) * sizeof *copy);
    uint32_t *at = sdi_alloc(m, (n ? n : 1) * sizeof *at);
    uint32_t *vseen = NULL, *eseen = NULL;
    sd_result rc = SD_OK;
    if (!copy || !at || (n && !sdi_rels_need(m, &R, TAG_RELS))) {
        rc = sdi_fail_nomem(err, m);
        goto out;
    }
    if (n) {
        vseen = sdi_alloc(m, ((size_t)t->nv + 1) * sizeof *vseen);
        eseen = sdi_alloc(m, ((size_t)t->ne + 1) * sizeof *eseen);
        if (!vseen || !eseen) {
            rc = sdi_fail_nomem(err, m);
            goto out;
        }
        memset(vseen, 0xff, ((size_t)t->nv + 1) * sizeof *vseen);
        memset(eseen, 0xff, ((size_t)t->ne + 1) * sizeof *eseen);
    }
    for (size_t i = 0; i < n; i++) {
        if ((rc = check_override(&R, &ov[i], i, &at[i], err)))
            goto out;
        uint32_t *seen = ov[i].nverts == 2 ? &eseen[at[i]] : &vseen[at[i]];
        if (*seen != UINT32_MAX) {
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_SIMPLEX,
                         "this simplex already has a rule (override %u)", *seen);
            goto out;
        }
        *seen = (uint32_t)i;
        copy[i] = ov[i];
        if (ov[i].rule == SD_RULE_N1 && ov[i].dimension >= 2 &&
            (rc = n1_part_manifold(m, t, &R, &ti, &ov[i], i, at[i], err)))
            goto out;
    }
    sd_override *old = c->ov;
    size_t old_n = c->nov;
    c->ov = copy;
    c->nov = n;
    if ((rc = sdi_apply_singular(c, &R, err))) { /* a conflict between pairs: put the old ones back */
        c->ov = old;
        c->nov = old_n;
        sd_error ignore;
        sdi_apply_singular(c, &R, &ignore);
        goto out;
    }
    copy = old;
out:
    sdi_free(m, copy);
    sdi_free(m, at);
    sdi_free(m, vseen);
    sdi_free(m, eseen);
    sdi_rels_free(m, &R);
    sdi_free(m, ti.stack);
    sdi_free(m, ti.mark);
    return rc;
}

/* ---- petal tags (003 Sec. 2: convex, concave or smooth corner) ---------------------------- */

/* The petal of v (petals.c: SDI_PETAL_YZ) holding maximal triangle f0: its triangles (out,
 * returns their number; room for nf + 1) and its distinct singular edges at v (sing, *ns). */
static uint32_t petal_faces(const sd_topo *t, const sdi_rels *R, uint32_t v, uint32_t f0,
                            uint32_t *out, uint32_t sing[2], uint32_t *ns)
{
    sdi_petal p = {.face = out, .cap = t->nf + 1};
    sdi_petal_of(t, &R->r[SDI_EF], SDI_PETAL_YZ, v, f0, &p);
    sing[0] = p.sing[0];
    sing[1] = p.sing[1];
    *ns = p.nsing;
    return p.nf;
}

static int cmp_petal_at(const void *a, const void *b)
{
    const sd_petal_at *p = a, *q = b;
    return p->v != q->v ? (p->v > q->v) - (p->v < q->v) : (p->f > q->f) - (p->f < q->f);
}

/* 003's simple/complex split of a non-manifold vertex where only triangles meet: an edge that
 * counts as singular there (non-manifold or boundary), and whether a vertex of non-manifold
 * type `type` with `nsing` of them is simple (one flower, exactly two singular edges). */
static inline bool yz_counts_singular(const sd_topo *t, uint32_t e)
{
    return t->efam[e] == FAM2 && (nm_type(t->enm[e]) == 2 || (t->eflag[e] & EF_BND2));
}
static inline bool yz_simple(int type, uint32_t nsing)
{
    return type != 3 && nsing == 2;
}

/* The (unordered) pair of singular edges bounding an open petal, as one key. */
static uint64_t pair_key(const uint32_t s[2])
{
    uint32_t a = s[0] < s[1] ? s[0] : s[1], b = s[0] < s[1] ? s[1] : s[0];
    return (uint64_t)a << 32 | b;
}

/* A smooth tag: its vertex, index and pair of singular edges. */
typedef struct smooth_at {
    uint32_t v, tag;
    uint64_t key;
} smooth_at;

static int cmp_smooth_at(const void *a, const void *b)
{
    const smooth_at *p = a, *q = b;
    return p->v != q->v ? (p->v > q->v) - (p->v < q->v) : (p->key > q->key) - (p->key < q->key);
}

/* Validation in O(tags + triangles at the tagged vertices): each tag's petal is walked once
 * (a triangle already claimed by an earlier tag is a duplicate, found before the walk), and
 * the smooth rule walks each vertex with a smooth tag once. */
sd_result sd_complex_set_petals(sd_complex *c, const sd_petal_tag *pt, size_t n, sd_error *err)
{
    sd_topo *t = &c->lv[0]->t;
    sd_mem *m = &c->mem;
    sd_result rc = SD_OK;
    sdi_rels rels = {.t = t}, *R = &rels;
    const sdi_rel *ve = &R->r[SDI_VE], *vf = &R->r[SDI_VF];
    uint32_t *faces = NULL, *owner = NULL;
    uint8_t *tagv = NULL, *walked = NULL;
    uint64_t *pairs = NULL;
    smooth_at *sm = NULL;
    sd_petal_at *at = NULL;
    size_t nat = 0, cap = 0;
    for (size_t i = 0; i < n; i++) { /* ids and kinds first: nothing below reads an unchecked one */
        const sd_petal_tag *p = &pt[i];
        if (p->vertex >= t->nv)
            return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_PT_FIELD_VERTEX,
                           "petal tag %zu: vertex %u out of range", i, p->vertex);
        for (int j = 0; j < 3; j++)
            if (p->triangle[j] >= t->nv)
                return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_PT_FIELD_TRIANGLE,
                               "petal tag %zu: vertex %u out of range", i, p->triangle[j]);
        if (p->kind < SD_PETAL_CONVEX || p->kind > SD_PETAL_SMOOTH)
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_KIND,
                           "petal tag %zu: the kind is convex, concave or smooth", i);
    }
    if (n && (!sdi_rels_need(m, R, TAG_RELS) || !(faces = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *faces)) ||
              !(owner = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *owner)) ||
              !(tagv = sdi_calloc(m, (size_t)t->nv + 1, 1)) ||
              !(pairs = sdi_alloc(m, n * sizeof *pairs))))
        goto nomem;
    for (uint32_t f = 0; n && f < t->nf; f++)
        owner[f] = UINT32_MAX;
    /* vertices of the singular tags (1: tagged, 2: on a tagged edge or triangle): they follow
     * the tags whatever the rule preferences, so a petal tag there would never act. (A rule
     * choice of the vertex's own, or the G1 default, can also make a tag idle; those come from
     * PUT /rules and are not refused here: the tag waits, like under chang-qin.) */
    for (size_t k = 0; n && k < c->ntags; k++) {
        uint32_t id = c->tag_at[k];
        if (c->tag_k[k] == 1)
            tagv[id] = 1;
        else
            for (int j = 0; j < c->tag_k[k]; j++) {
                uint32_t w = c->tag_k[k] == 2 ? t->ev[id][j] : t->fv[id][j];
                if (!tagv[w])
                    tagv[w] = 2;
            }
    }
    bool any_smooth = false;
    for (size_t i = 0; i < n; i++) {
        const sd_petal_tag *p = &pt[i];
        uint32_t v = p->vertex;
        uint32_t f = sdi_rels_face(R, p->triangle);
        if (f == UINT32_MAX || !(t->fflag[f] & FF_MAX)) {
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                         "petal tag %zu: [%u, %u, %u] is not a surface triangle of the complex "
                         "(a maximal triangle, not a face of a tetrahedron)", i, p->triangle[0],
                         p->triangle[1], p->triangle[2]);
            goto out;
        }
        if (!sdi_face_has(t, f, v)) {
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                         "petal tag %zu: the triangle does not hold vertex %u", i, v);
            goto out;
        }
        /* a complex singular vertex of triangles only (003 Sec. 2): non-manifold, and not simple
         * (one flower with exactly two singular edges: boundary or non-manifold ones) */
        uint32_t nsing = 0;
        for (uint32_t k = ve->off[v]; k < ve->off[v + 1]; k++)
            nsing += yz_counts_singular(t, ve->item[k]);
        if (t->vfam[v] != FAM2 || !nm_type(t->vnm[v]) || yz_simple(nm_type(t->vnm[v]), nsing)) {
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_VERTEX,
                         "petal tag %zu: vertex %u is not a complex singular vertex of a "
                         "triangle mesh (a non-manifold vertex where only triangles meet, not "
                         "one flower with exactly two singular edges): corner kinds do not "
                         "apply there", i, v);
            goto out;
        }
        if (tagv[v]) { /* as rules.c (YZV): the singular tags win */
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_VERTEX,
                         "petal tag %zu: vertex %u %s, so its petals have no corner rule", i, v,
                         tagv[v] == 1 ? "is tagged singular (fixed with plain edge rules)"
                                     : "lies on a tagged crease or embedded surface (it "
                                       "follows that)");
            goto out;
        }
        if (owner[f] != UINT32_MAX) {
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                         "petal tag %zu: tag %u already names this petal of vertex %u", i,
                         owner[f], v);
            goto out;
        }
        uint32_t sing[2], ns, nf = petal_faces(t, R, v, f, faces, sing, &ns);
        if (ns != 2) {
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                         "petal tag %zu: the petal of vertex %u holding this triangle is %s; "
                         "corner kinds apply to open petals, bounded by two singular edges", i, v,
                         ns == 0 ? "closed (no singular edge)"
                         : ns == 1 ? "a dart (one singular edge)" : "not a fan");
            goto out;
        }
        for (uint32_t k = 0; k < nf; k++)
            if (owner[faces[k]] != UINT32_MAX) { /* a triangle of the petal, but not f */
                rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                             "petal tag %zu: tag %u already names this petal of vertex %u", i,
                             owner[faces[k]], v);
                goto out;
            }
        /* a triangle holds v once, so owner[] marks (v, petal) */
        for (uint32_t k = 0; k < nf; k++)
            owner[faces[k]] = (uint32_t)i;
        pairs[i] = pair_key(sing);
        any_smooth |= p->kind == SD_PETAL_SMOOTH;
        if (nat + nf > cap) {
            size_t nc = cap ? 2 * cap : 64;
            while (nc < nat + nf)
                nc *= 2;
            sd_petal_at *na = sdi_realloc(m, at, nc * sizeof *na);
            if (!na)
                goto nomem;
            at = na;
            cap = nc;
        }
        for (uint32_t k = 0; k < nf; k++)
            at[nat++] = (sd_petal_at){v, faces[k], (uint8_t)p->kind};
    }
    /* 003: petals sharing both singular edges are both corners or both smooth. The smooth tags
     * sorted by (vertex, pair); per such vertex, every petal between a smooth tag's two edges
     * must be tagged smooth (each petal walked once: `walked`, cleared per vertex). */
    if (any_smooth) {
        size_t nsm = 0;
        if (!(sm = sdi_alloc(m, n * sizeof *sm)) || !(walked = sdi_calloc(m, (size_t)t->nf + 1, 1)))
            goto nomem;
        for (size_t i = 0; i < n; i++)
            if (pt[i].kind == SD_PETAL_SMOOTH)
                sm[nsm++] = (smooth_at){pt[i].vertex, (uint32_t)i, pairs[i]};
        qsort(sm, nsm, sizeof *sm, cmp_smooth_at);
        for (size_t a = 0, b; a < nsm; a = b) {
            uint32_t v = sm[a].v;
            for (b = a; b < nsm && sm[b].v == v; b++)
                ;
            for (uint32_t k = vf->off[v]; k < vf->off[v + 1] && !rc; k++) {
                uint32_t g = vf->item[k], s2[2], ns2;
                if (!(t->fflag[g] & FF_MAX) || walked[g])
                    continue;
                uint32_t tag = owner[g];
                bool tagged = tag != UINT32_MAX && pt[tag].vertex == v;
                uint64_t key;
                if (tagged) { /* its key is known; its triangles need no walk */
                    if (pt[tag].kind == SD_PETAL_SMOOTH)
                        continue;
                    key = pairs[tag];
                    ns2 = 2;
                } else {
                    uint32_t ng = petal_faces(t, R, v, g, faces, s2, &ns2);
                    for (uint32_t q = 0; q < ng; q++)
                        walked[faces[q]] = 1;
                    key = pair_key(s2);
                }
                smooth_at want = {v, 0, key};
                const smooth_at *hit = ns2 == 2 ? bsearch(&want, sm + a, b - a, sizeof *sm,
                                                          cmp_smooth_at) : NULL;
                if (hit) {
                    const uint32_t *gv = t->fv[g];
                    rc = sdi_fail(err, SD_ERR_ARG, (long)hit->tag, SD_PT_FIELD_KIND,
                                 "petal tag %u: a smooth petal needs every petal of vertex %u "
                                 "between the same two singular edges smooth too (003 Sec. 2), "
                                 "and the one holding [%u, %u, %u] is not tagged smooth",
                                 hit->tag, v, gv[0], gv[1], gv[2]);
                }
            }
            for (uint32_t k = vf->off[v]; k < vf->off[v + 1]; k++)
                walked[vf->item[k]] = 0;
            if (rc)
                goto out;
        }
    }
    if (nat)
        qsort(at, nat, sizeof *at, cmp_petal_at);
    sdi_free(m, c->pet);
    c->pet = at;
    c->npet = nat;
    at = NULL;
    sdi_drop_rules(c, c->lv[0]); /* level 0's rules change; every finer level follows */
    goto out;
nomem:
    rc = sdi_fail_nomem(err, m);
out:
    sdi_free(m, at);
    sdi_free(m, faces);
    sdi_free(m, owner);
    sdi_free(m, tagv);
    sdi_free(m, pairs);
    sdi_free(m, sm);
    sdi_free(m, walked);
    sdi_rels_free(m, R);
    return rc;
}

/* ---- applying tags and rules to level 0 --------------------------------------------------- */

sd_result sdi_apply_singular(sd_complex *c, sdi_rels *R, sd_error *err)
{
    sd_level *l0 = c->lv[0];
    sd_topo *t = &l0->t;
    sd_mem *m = &c->mem;
    bool g1_default = c->opt.nonmanifold_default == SD_NM_G1;
    const sdi_rel *ve = &R->r[SDI_VE], *vf = &R->r[SDI_VF];
    uint8_t *nface = NULL;
    uint32_t *stack = NULL;
    sd_result rc = SD_OK;
    if (c->nov && !sdi_rels_need(m, R, TAG_RELS))
        goto nomem;

    /* clear */
    for (uint32_t v = 0; v < t->nv; v++) {
        t->vflag[v] &= (uint8_t)~(VF_SING | VF_SCREASE | VF_SSURF | VF_SBND);
        t->vnm[v] &= NM_TYPE;
    }
    for (uint32_t e = 0; e < t->ne; e++) {
        t->eflag[e] &= (uint8_t)~(EF_CREASE | EF_SSURF | EF_SBND | EF_N2SEL | EF_N2BND);
        t->enm[e] &= NM_TYPE | NM_C2B;
    }
    for (uint32_t f = 0; f < t->nf; f++)
        t->fflag[f] &= (uint8_t)~(FF_SING | FF_N2SEL);
    t->ovmask = c->opt.nonmanifold_surface == SD_NMSURF_YING_ZORIN ? OVM_YZ : 0;

    /* tags */
    for (size_t i = 0; i < c->ntags; i++)
        if (c->tag_k[i] == 1)
            t->vflag[c->tag_at[i]] |= VF_SING;
        else if (c->tag_k[i] == 2)
            t->eflag[c->tag_at[i]] |= EF_CREASE;
        else
            t->fflag[c->tag_at[i]] |= FF_SING;

    /* per-simplex rules */
    if (c->nov) {
        stack = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *stack);
        if (!stack)
            goto nomem;
    }
    for (size_t i = 0; i < c->nov; i++) {
        const sd_override *o = &c->ov[i];
        bool edge = o->nverts == 2;
        uint32_t id = edge ? sdi_rels_edge(R, o->simplex[0], o->simplex[1]) : o->simplex[0];
        uint8_t *nm = edge ? &t->enm[id] : &t->vnm[id];
        switch (o->rule) {
        case SD_RULE_G1:
            *nm |= NM_G1;
            if (edge)
                t->eflag[id] |= EF_CREASE;
            else
                t->vflag[id] |= VF_SING;
            break;
        case SD_RULE_G2:
            *nm |= OV_G2 << NM_OV_SHIFT;
            break;
        case SD_RULE_N1:
            *nm |= (uint8_t)((OV_N1_1 + o->dimension - 1) << NM_OV_SHIFT);
            t->ovmask |= OVM_N1;
            break;
        default: /* N2 */
            *nm |= OV_N2 << NM_OV_SHIFT;
            if (o->pair_size == 2) {
                for (int j = 0; j < 2; j++)
                    t->eflag[sdi_rels_edge(R, o->pair[j][0], o->pair[j][1])] |= EF_N2SEL;
                t->ovmask |= OVM_N2C;
            } else {
                for (int j = 0; j < 2; j++) {
                    uint32_t f = sdi_rels_face(R, o->pair[j]);
                    if (edge)
                        t->fflag[f] |= FF_N2SEL;
                    else
                        mark_petal(t, R, id, f, stack, t->nf + 1);
                }
                t->ovmask |= OVM_N2T;
            }
        }
    }

    /* Ying-Zorin (003 Sec. 2) where only triangles meet: a non-manifold edge is singular (a
     * crease); a non-manifold vertex is simple (one flower, exactly two singular edges: boundary
     * or non-manifold ones) or complex; without a choice or a tag */
    if (t->ovmask & OVM_YZ) {
        nface = sdi_calloc(m, (size_t)t->nv + 1, 1); /* singular edges per vertex, saturating */
        if (!nface)
            goto nomem;
        for (uint32_t e = 0; e < t->ne; e++) {
            if (t->efam[e] != FAM2)
                continue;
            if (nm_type(t->enm[e]) == 2 && !nm_ov(t->enm[e]) && !(t->enm[e] & NM_G1) &&
                !(t->eflag[e] & EF_CREASE))
                t->enm[e] |= OV_YZS << NM_OV_SHIFT;
            if (yz_counts_singular(t, e))
                for (int k = 0; k < 2; k++)
                    if (nface[t->ev[e][k]] < 255)
                        nface[t->ev[e][k]]++;
        }
        for (uint32_t v = 0; v < t->nv; v++)
            if (t->vfam[v] == FAM2 && nm_type(t->vnm[v]) && !nm_ov(t->vnm[v]) &&
                !(t->vnm[v] & NM_G1) && !(t->vflag[v] & VF_SING))
                t->vnm[v] |= (uint8_t)((yz_simple(nm_type(t->vnm[v]), nface[v]) ? OV_YZS : OV_YZX)
                                       << NM_OV_SHIFT);
        sdi_free(m, nface);
        nface = NULL;
    }

    /* the default rule G1: non-manifold edges without a choice or a tag become creases, then
     * non-manifold vertices without one become corners unless they lie on a crease */
    if (g1_default) {
        for (uint32_t e = 0; e < t->ne; e++)
            if (nm_type(t->enm[e]) && !nm_ov(t->enm[e]) && !(t->enm[e] & NM_G1) &&
                !(t->eflag[e] & EF_CREASE)) {
                t->enm[e] |= NM_G1;
                t->eflag[e] |= EF_CREASE;
            }
    }

    /* ... and a triangle shared by three or more solids an embedded surface (a 2-singularity,
     * 000 Fig. 17e), so its children, edges inside it included, stay singular at every level */
    for (uint32_t f = 0; f < t->nf && g1_default; f++)
        if (t->fn3[f] >= 3 && !(t->fflag[f] & FF_MAX))
            t->fflag[f] |= FF_SING;

    /* derived: surface edges, their boundary, and the vertices on them */
    nface = sdi_calloc(m, (size_t)t->ne + 1, 1);
    if (!nface)
        goto nomem;
    for (uint32_t f = 0; f < t->nf; f++)
        if (t->fflag[f] & FF_SING)
            for (int j = 0; j < 3; j++)
                if (nface[t->fe[f][j]] < 255)
                    nface[t->fe[f][j]]++;
    for (uint32_t e = 0; e < t->ne; e++) {
        if (nface[e]) {
            t->eflag[e] = (uint8_t)((t->eflag[e] & ~EF_CREASE) | EF_SSURF);
            t->enm[e] &= (uint8_t)~NM_G1; /* a tagged surface's edge: the tag wins */
            if (nface[e] == 1)
                t->eflag[e] |= EF_SBND;
        }
        uint8_t vb = ((t->eflag[e] & EF_CREASE) ? VF_SCREASE : 0) |
                     ((t->eflag[e] & EF_SSURF) ? VF_SSURF : 0) |
                     ((t->eflag[e] & EF_SBND) ? VF_SBND : 0);
        for (int k = 0; k < 2; k++) {
            uint32_t v = t->ev[e][k];
            /* a crease made by the default G1 does not override a vertex's own choice */
            if ((t->enm[e] & NM_G1) && nm_ov(t->vnm[v]) && !(t->eflag[e] & EF_SSURF))
                continue;
            t->vflag[v] |= vb;
        }
    }
    for (uint32_t v = 0; v < t->nv && g1_default; v++) {
        if (!nm_type(t->vnm[v]) || nm_ov(t->vnm[v]) || (t->vflag[v] & VF_SING))
            continue;
        if (!(t->vflag[v] & VF_S_ANY)) { /* on no crease: a corner */
            t->vnm[v] |= NM_G1;
            t->vflag[v] |= VF_SING;
        } else if (t->vflag[v] & VF_SCREASE) { /* on creases of the default rule */
            t->vnm[v] |= NM_G1;
        }
    }

    /* sides of chosen triangles; then every N2 simplex must see exactly its own pair */
    if (t->ovmask & OVM_N2T) {
        memset(nface, 0, (size_t)t->ne + 1);
        for (uint32_t f = 0; f < t->nf; f++)
            if (t->fflag[f] & FF_N2SEL)
                for (int j = 0; j < 3; j++)
                    if (nface[t->fe[f][j]] < 255)
                        nface[t->fe[f][j]]++;
        for (uint32_t e = 0; e < t->ne; e++)
            if (nface[e])
                t->eflag[e] |= nface[e] == 1 ? EF_N2SEL | EF_N2BND : EF_N2SEL;
    }
    for (size_t i = 0; i < c->nov; i++) {
        const sd_override *o = &c->ov[i];
        if (o->rule != SD_RULE_N2)
            continue;
        bool edge = o->nverts == 2;
        uint32_t id = edge ? sdi_rels_edge(R, o->simplex[0], o->simplex[1]) : o->simplex[0];
        uint32_t chosen = 0, own = 2;
        if (o->pair_size == 2) {
            for (uint32_t k = ve->off[id]; k < ve->off[id + 1]; k++)
                chosen += (t->eflag[ve->item[k]] & (EF_CURVE | EF_N2SEL)) == (EF_CURVE | EF_N2SEL);
        } else if (edge) {
            chosen = nface[id];
        } else {
            for (uint32_t k = vf->off[id]; k < vf->off[id + 1]; k++)
                chosen += (t->fflag[vf->item[k]] & FF_N2SEL) != 0;
            /* its own petals, counted on a scratch copy of the marks */
            for (uint32_t k = vf->off[id]; k < vf->off[id + 1]; k++)
                t->fflag[vf->item[k]] = (uint8_t)((t->fflag[vf->item[k]] & ~FF_N2SEL) |
                                             ((t->fflag[vf->item[k]] & FF_N2SEL) ? 64 : 0));
            uint32_t p0 = mark_petal(t, R, id, sdi_rels_face(R, o->pair[0]), stack, t->nf + 1);
            uint32_t p1 = mark_petal(t, R, id, sdi_rels_face(R, o->pair[1]), stack, t->nf + 1);
            own = p0 + p1;
            for (uint32_t k = vf->off[id]; k < vf->off[id + 1]; k++)
                t->fflag[vf->item[k]] = (uint8_t)((t->fflag[vf->item[k]] & ~(FF_N2SEL | 64)) |
                                             ((t->fflag[vf->item[k]] & 64) ? FF_N2SEL : 0));
            if (!p1) {
                rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_PAIR1,
                             "both triangles of the pair lie in the same petal (fan of triangles "
                             "joined by manifold edges) around vertex %u: choose triangles of two "
                             "different petals", id);
                goto out;
            }
        }
        if (chosen != own) {
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_PAIR,
                         "the pair conflicts with another N2 choice: %u %s at this %s are chosen, "
                         "its own pair gives %u (a chosen %s touching another N2 simplex must be "
                         "in that simplex's pair too)", chosen,
                         o->pair_size == 2 ? "curve segments" : "triangles",
                         edge ? "edge" : "vertex", own,
                         o->pair_size == 2 ? "segment" : "triangle");
            goto out;
        }
    }
    goto out;
nomem:
    rc = sdi_fail_nomem(err, m);
out:
    sdi_free(m, nface);
    sdi_free(m, stack);
    sdi_drop_rules(c, l0); /* level 0's rules change; every finer level follows */
    return rc;
}

int sd_level_vertex_singular(const sd_level *lv, uint32_t i)
{
    return i < lv->t.nv && (lv->t.vflag[i] & (VF_SING | VF_SCREASE | VF_SSURF)) != 0;
}

int sd_level_edge_singular(const sd_level *lv, uint32_t e)
{
    return e < lv->t.ne && sdi_need_derived(lv) && (lv->t.eflag[e] & (EF_CREASE | EF_SSURF)) != 0;
}
