/* overrides.c — the per-simplex non-manifold rules (000 Sec. 3.5; docs/RULES.md; DECISIONS 23-25):
 * checking them against level 0 and marking their bits.
 *
 * G1 is a singularity — a vertex becomes a corner, an edge a crease, exactly as a tag, marked
 * NM_G1 so that it is reported as G1. G2 (the default rule, also undoing a G1 default), N1 and N2
 * are codes in the high bits of vnm / enm that children keep (split.c; the edge point of an N1
 * edge is an N1 vertex of the same dimension). N1 needs the part of the chosen dimension to be
 * manifold at the simplex (else one dimension decides nothing: a 422 naming the dimension). N2
 * marks the chosen curve segments (EF_N2SEL) or triangles (FF_N2SEL; at a vertex the whole fans
 * holding the two chosen triangles, petals.c), and their sides (EF_N2SEL, and EF_N2BND where
 * exactly one chosen triangle meets); a marked simplex touching another N2 simplex must be in
 * its pair too, or the choices contradict each other (a 422, not a silent choice).
 *
 * Checking is all-or-nothing: every override is validated and located before anything changes;
 * then singular.c re-applies tags, overrides and defaults together (sdi_apply_singular), which
 * calls the marking and the pair check here. rules.c and rings.c turn the bits into rules.
 */
#include "internal.h"
#include <stdio.h>
#include <string.h>

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

/* Counting with mark_petal on a scratch copy: the FF_N2SEL marks of the faces at v move to bit
 * 64 of fflag (a bit no flag uses), and back. */
enum { SAVED = 64 };
static void save_marks(sd_topo *t, const sdi_rel *vf, uint32_t v)
{
    for (uint32_t k = vf->off[v]; k < vf->off[v + 1]; k++) {
        uint32_t f = vf->item[k];
        t->fflag[f] = (uint8_t)((t->fflag[f] & ~FF_N2SEL) | ((t->fflag[f] & FF_N2SEL) ? SAVED : 0));
    }
}
static void restore_marks(sd_topo *t, const sdi_rel *vf, uint32_t v)
{
    for (uint32_t k = vf->off[v]; k < vf->off[v + 1]; k++) {
        uint32_t f = vf->item[k];
        t->fflag[f] = (uint8_t)((t->fflag[f] & ~(FF_N2SEL | SAVED)) |
                                ((t->fflag[f] & SAVED) ? FF_N2SEL : 0));
    }
}

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
                           "meet; %s is of type %d (use %sG1 or G2)", name, type,
                           type == 2 || type == 4 ? "N2, " : "");
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
                       "it) and their faces; %s is of type %d (use %sG1 or G2)", name, type,
                       type == 1 ? "N1, " : "");
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
        /* one petal holds every maximal triangle around the vertex */
        uint32_t total = 0, first = UINT32_MAX;
        save_marks(t, vf, id);
        for (uint32_t k = vf->off[id]; k < vf->off[id + 1]; k++) {
            uint32_t f = vf->item[k];
            if (t->fflag[f] & FF_MAX) {
                total++;
                first = first == UINT32_MAX ? f : first;
            }
        }
        if (!ti->stack && !(ti->stack = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *ti->stack)))
            return sdi_fail_nomem(err, m);
        uint32_t got = first == UINT32_MAX ? 0 : mark_petal(t, R, id, first, ti->stack, t->nf + 1);
        restore_marks(t, vf, id);
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
    if (!copy || !at || (n && !sdi_rels_need(m, &R, SDI_TAG_RELS))) {
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

void sdi_overrides_mark(sd_complex *c, const sdi_rels *R, uint32_t *stack)
{
    sd_topo *t = &c->lv[0]->t;
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
}

sd_result sdi_overrides_check(sd_complex *c, const sdi_rels *R, uint8_t *nface, uint32_t *stack,
                              sd_error *err)
{
    sd_topo *t = &c->lv[0]->t;
    const sdi_rel *ve = &R->r[SDI_VE], *vf = &R->r[SDI_VF];
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
            save_marks(t, vf, id);
            uint32_t p0 = mark_petal(t, R, id, sdi_rels_face(R, o->pair[0]), stack, t->nf + 1);
            uint32_t p1 = mark_petal(t, R, id, sdi_rels_face(R, o->pair[1]), stack, t->nf + 1);
            own = p0 + p1;
            restore_marks(t, vf, id);
            if (!p1) {
                return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_PAIR1,
                                "both triangles of the pair lie in the same petal (fan of "
                                "triangles joined by manifold edges) around vertex %u: choose "
                                "triangles of two different petals", id);
            }
        }
        if (chosen != own) {
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_OV_FIELD_PAIR,
                            "the pair conflicts with another N2 choice: %u %s at this %s are "
                            "chosen, its own pair gives %u (a chosen %s touching another N2 "
                            "simplex must be in that simplex's pair too)", chosen,
                            o->pair_size == 2 ? "curve segments" : "triangles",
                            edge ? "edge" : "vertex", own,
                            o->pair_size == 2 ? "segment" : "triangle");
        }
    }
    return SD_OK;
}
