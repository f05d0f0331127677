/* tags.c — the singular complex S (000 Sec. 4.1): tagged vertices (corners), edges (creases)
 * and triangles (embedded surfaces), stored as flag bits on level 0 and inherited by every
 * child in split.c (halves of a crease are creases, children of a tagged triangle and the edges
 * inside it are tagged, edge points of S-edges lie on S).
 *
 * Derived bits: a tagged edge that is a side of a tagged triangle belongs to the surface, not to
 * a crease; a surface edge with exactly one tagged triangle is the surface's boundary; a vertex
 * carries the kinds of S-edges it lies on. rules.c turns the bits into rules.
 */
#include "internal.h"
#include <string.h>

static uint32_t find_face(const sd_topo *t, const uint32_t v[3])
{
    for (uint32_t f = 0; f < t->nf; f++) {
        int hit = 0;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                hit += t->fv[f][i] == v[j];
        if (hit == 3)
            return f;
    }
    return UINT32_MAX;
}

sd_result sd_complex_set_singular(sd_complex *c, const uint32_t *idx, const uint8_t *size,
                                  size_t n, sd_error *err)
{
    sd_level *l0 = c->lv[0];
    sd_topo *t = &l0->t;
    sd_mem *m = &c->mem;
    /* validate and locate every tag first: all-or-nothing */
    uint32_t *where = sd_alloc(m, (n ? n : 1) * sizeof *where);
    if (!where)
        return sd_fail_nomem(err, m);
    size_t off = 0;
    for (size_t i = 0; i < n; off += size[i++]) {
        const uint32_t *v = idx + off;
        int k = size[i];
        if (k < 1 || k > 3) {
            sd_free(m, where);
            return sd_fail(err, SD_ERR_ARITY, (long)i, -1,
                           "tag %zu has %d vertices: a vertex, an edge or a triangle", i, k);
        }
        for (int j = 0; j < k; j++)
            if (v[j] >= t->nv) {
                sd_free(m, where);
                return sd_fail(err, SD_ERR_INDEX, (long)i, j, "tag %zu: vertex %u out of range", i,
                               v[j]);
            }
        where[i] = k == 1 ? v[0] : k == 2 ? sd_topo_find_edge(t, v[0], v[1]) : find_face(t, v);
        if (where[i] == UINT32_MAX) {
            sd_free(m, where);
            return sd_fail(err, SD_ERR_ARG, (long)i, -1, "tag %zu is not %s of the complex", i,
                           k == 2 ? "an edge" : "a triangle");
        }
    }
    /* clear old tags, set the new ones */
    for (uint32_t v = 0; v < t->nv; v++)
        t->vflag[v] &= (uint8_t)~(VF_SING | VF_SCREASE | VF_SSURF | VF_SBND);
    for (uint32_t e = 0; e < t->ne; e++)
        t->eflag[e] &= (uint8_t)~(EF_CREASE | EF_SSURF | EF_SBND);
    for (uint32_t f = 0; f < t->nf; f++)
        t->fflag[f] &= (uint8_t)~FF_SING;
    for (size_t i = 0; i < n; i++)
        if (size[i] == 1)
            t->vflag[where[i]] |= VF_SING;
        else if (size[i] == 2)
            t->eflag[where[i]] |= EF_CREASE;
        else
            t->fflag[where[i]] |= FF_SING;
    sd_free(m, where);
    /* derived: surface edges, their boundary, and the vertices on them */
    uint8_t *nface = sd_calloc(m, (size_t)t->ne + 1, 1);
    if (!nface)
        return sd_fail_nomem(err, m);
    for (uint32_t f = 0; f < t->nf; f++)
        if (t->fflag[f] & FF_SING)
            for (int j = 0; j < 3; j++)
                if (nface[t->fe[f][j]] < 255)
                    nface[t->fe[f][j]]++;
    for (uint32_t e = 0; e < t->ne; e++) {
        if (nface[e]) {
            t->eflag[e] = (uint8_t)((t->eflag[e] & ~EF_CREASE) | EF_SSURF);
            if (nface[e] == 1)
                t->eflag[e] |= EF_SBND;
        }
        uint8_t vb = ((t->eflag[e] & EF_CREASE) ? VF_SCREASE : 0) |
                     ((t->eflag[e] & EF_SSURF) ? VF_SSURF : 0) |
                     ((t->eflag[e] & EF_SBND) ? VF_SBND : 0);
        t->vflag[t->ev[e][0]] |= vb;
        t->vflag[t->ev[e][1]] |= vb;
    }
    sd_free(m, nface);
    sd_drop_rules(c, l0); /* level 0's rules change; every finer level follows */
    return SD_OK;
}

int sd_level_vertex_singular(const sd_level *lv, uint32_t i)
{
    return i < lv->t.nv && (lv->t.vflag[i] & (VF_SING | VF_SCREASE | VF_SSURF)) != 0;
}

int sd_level_edge_singular(const sd_level *lv, uint32_t e)
{
    return e < lv->t.ne && sd_need_derived(lv) && (lv->t.eflag[e] & (EF_CREASE | EF_SSURF)) != 0;
}

sd_result sd_complex_set_overrides(sd_complex *c, const sd_override *ov, size_t n, sd_error *err)
{
    (void)c;
    (void)ov;
    if (n)
        return sd_fail(err, SD_ERR_ARG, 0, SD_OV_FIELD_RULE, "overrides are not implemented yet");
    return SD_OK;
}
