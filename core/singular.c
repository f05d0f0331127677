/* singular.c — the singular complex S (000 Sec. 4.1) and the default non-manifold rules, as bits
 * on level 0 that every child inherits (split.c).
 *
 * Singular tags: vertices (corners), edges (creases) and triangles (embedded surfaces). Halves of
 * a crease are creases, children of a tagged triangle and the edges inside it are tagged, edge
 * points of S-edges lie on S. Derived bits: a tagged edge that is a side of a tagged triangle
 * belongs to the surface, not to a crease; a surface edge with exactly one tagged triangle is the
 * surface's boundary; a vertex carries the kinds of S-edges it lies on.
 *
 * The defaults for non-manifold simplices without a choice of their own (overrides.c): G1 makes
 * every non-manifold edge a crease, every triangle shared by three or more solids an embedded
 * surface and every non-manifold vertex on none of them a corner (DECISIONS 25); Ying-Zorin's
 * preference makes, where only triangles meet, non-manifold edges creases and non-manifold
 * vertices simple (one flower, two singular edges) or complex (003 Sec. 2; DECISIONS 26).
 *
 * Priority (docs/RULES.md "Conventions"): tag > the simplex's own choice > the default rule. rules.c turns the
 * bits into rules. Everything is recomputed from the stored tags and overrides on each change
 * (sdi_apply_singular), and the changed level 0 drops its rules and the finer levels.
 */
#include "internal.h"
#include <string.h>

sd_result sd_complex_set_singular(sd_complex *c, const uint32_t *idx, const uint8_t *size,
                                  size_t n, sd_error *err)
{
    sd_topo *t = &c->lv[0]->t;
    sd_mem *m = &c->mem;
    /* validate and locate every tag first: all-or-nothing */
    uint32_t *where = sdi_alloc(m, (n ? n : 1) * sizeof *where);
    uint8_t *kind = sdi_alloc(m, n ? n : 1);
    sdi_rels rels = {.t = t}, *R = &rels;
    if (!where || !kind || (n && !sdi_rels_need(m, R, SDI_TAG_RELS))) {
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
            rc = k == 2 ? sdi_fail(err, SD_ERR_ARG, (long)i, -1,
                                   "%u-%u is not an edge of the complex", v[0], v[1])
                        : sdi_fail(err, SD_ERR_ARG, (long)i, -1,
                                   "%u-%u-%u is not a triangle of the complex", v[0], v[1], v[2]);
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

/* Level 0's bits without any tag, choice or default (the classification's). */
static void clear_bits(sd_complex *c, sd_topo *t)
{
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
}

/* Ying-Zorin's classes where only triangles meet (see the header). */
static bool yz_default(sd_mem *m, sd_topo *t)
{
    uint8_t *nface = sdi_calloc(m, (size_t)t->nv + 1, 1); /* singular edges per vertex, saturating */
    if (!nface)
        return false;
    for (uint32_t e = 0; e < t->ne; e++) {
        if (t->efam[e] != FAM2)
            continue;
        if (nm_type(t->enm[e]) == 2 && !nm_ov(t->enm[e]) && !(t->enm[e] & NM_G1) &&
            !(t->eflag[e] & EF_CREASE))
            t->enm[e] |= OV_YZS << NM_OV_SHIFT;
        if (sdi_yz_counts_singular(t, e))
            for (int k = 0; k < 2; k++)
                if (nface[t->ev[e][k]] < 255)
                    nface[t->ev[e][k]]++;
    }
    for (uint32_t v = 0; v < t->nv; v++)
        if (t->vfam[v] == FAM2 && nm_type(t->vnm[v]) && !nm_ov(t->vnm[v]) &&
            !(t->vnm[v] & NM_G1) && !(t->vflag[v] & VF_SING))
            t->vnm[v] |= (uint8_t)((sdi_yz_simple(nm_type(t->vnm[v]), nface[v]) ? OV_YZS : OV_YZX)
                                   << NM_OV_SHIFT);
    sdi_free(m, nface);
    return true;
}

/* The G1 default on edges: non-manifold edges without a choice or a tag become creases; and a
 * triangle shared by three or more solids an embedded surface (a 2-singularity, 000 Fig. 17e),
 * so its children, edges inside it included, stay singular at every level. */
static void g1_default_edges(sd_topo *t)
{
    for (uint32_t e = 0; e < t->ne; e++)
        if (nm_type(t->enm[e]) && !nm_ov(t->enm[e]) && !(t->enm[e] & NM_G1) &&
            !(t->eflag[e] & EF_CREASE)) {
            t->enm[e] |= NM_G1;
            t->eflag[e] |= EF_CREASE;
        }
    for (uint32_t f = 0; f < t->nf; f++)
        if (t->fn3[f] >= 3 && !(t->fflag[f] & FF_MAX))
            t->fflag[f] |= FF_SING;
}

/* The derived bits: surface edges, their boundary, and the vertices on S; nface: ne + 1 bytes
 * of scratch (zeroed), left with the number of tagged triangles on each edge (saturating). */
static void derive(sd_topo *t, uint8_t *nface)
{
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
}

/* The G1 default on vertices: a non-manifold vertex without a choice or a tag on no crease is a
 * corner; one on creases of the default rule follows them but is reported G1. */
static void g1_default_vertices(sd_topo *t)
{
    for (uint32_t v = 0; v < t->nv; v++) {
        if (!nm_type(t->vnm[v]) || nm_ov(t->vnm[v]) || (t->vflag[v] & VF_SING))
            continue;
        if (!(t->vflag[v] & VF_S_ANY)) { /* on no crease: a corner */
            t->vnm[v] |= NM_G1;
            t->vflag[v] |= VF_SING;
        } else if (t->vflag[v] & VF_SCREASE) { /* on creases of the default rule */
            t->vnm[v] |= NM_G1;
        }
    }
}

sd_result sdi_apply_singular(sd_complex *c, sdi_rels *R, sd_error *err)
{
    sd_level *l0 = c->lv[0];
    sd_topo *t = &l0->t;
    sd_mem *m = &c->mem;
    const bool g1_default = c->opt.nonmanifold_default == SD_NM_G1;
    uint8_t *nface = NULL;
    uint32_t *stack = NULL;
    sd_result rc = SD_OK;
    if (c->nov && (!sdi_rels_need(m, R, SDI_TAG_RELS) ||
                   !(stack = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *stack))))
        goto nomem;
    clear_bits(c, t);
    /* tags */
    for (size_t i = 0; i < c->ntags; i++)
        if (c->tag_k[i] == 1)
            t->vflag[c->tag_at[i]] |= VF_SING;
        else if (c->tag_k[i] == 2)
            t->eflag[c->tag_at[i]] |= EF_CREASE;
        else
            t->fflag[c->tag_at[i]] |= FF_SING;
    sdi_overrides_mark(c, R, stack); /* per-simplex rules */
    if ((t->ovmask & OVM_YZ) && !yz_default(m, t))
        goto nomem;
    if (g1_default)
        g1_default_edges(t);
    if (!(nface = sdi_calloc(m, (size_t)t->ne + 1, 1)))
        goto nomem;
    derive(t, nface);
    if (g1_default)
        g1_default_vertices(t);
    rc = sdi_overrides_check(c, R, nface, stack, err); /* N2 pairs against each other */
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
