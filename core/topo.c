/* topo.c — a level's topology (sd_topo, internal.h): the lifecycle of its parts and its
 * incidence relations.
 *
 * The parts (cells, edges, faces) are made by complex.c (level 0) and split.c (levels >= 1) and
 * freed here: the faces part alone (sdi_topo_free_faces, dropped at levels >= 1 once the rules
 * and the next split are made), the edges part, or all of it.
 *
 * The incidence relations — vertex -> edges, vertex -> faces, edge -> faces, vertex, edge and face
 * -> tetrahedra, vertex -> the octahedra whose major diagonal ends there — are the one place the
 * core inverts its entity -> vertex / edge / face tables (edit.c keeps S_l by columns too, but
 * that is a matrix's transpose, built once per level and kept for edits). They are a call's scratch, not the level's state: the call that needs them holds an
 * sdi_rels for the level, asks sdi_rels_need for the relations it reads (built once, then shared
 * by everything the call does at that level: classification and the first diagonals, tags,
 * overrides and the default rules, the G2 and Ying-Zorin rings), passes it down and frees it
 * before returning. So no relation outlives a public call, the level's structures stay the size
 * they are (sd_complex_memory counts them, and the stats report it), and no lock-free reader of
 * a level can meet one. Items come in increasing id, so every walk over them has a fixed order.
 */
#include "internal.h"
#include <string.h>

bool sdi_rel_build(sd_mem *m, sdi_rel *r, uint32_t nkeys, uint32_t nitems, int stride, int per,
                   const uint32_t *keys)
{
    /* off[k + 2] counts key k; summed, off[k + 1] is where key k starts, and filling moves it
     * to the start of key k + 1, so at the end off[k] is the start of key k */
    r->off = sdi_calloc(m, (size_t)nkeys + 2, sizeof *r->off);
    r->item = sdi_alloc(m, ((size_t)nitems * per + 1) * sizeof *r->item);
    if (!r->off || !r->item) {
        sdi_rel_free(m, r);
        return false;
    }
    for (size_t i = 0; i < nitems; i++)
        for (int j = 0; j < per; j++)
            r->off[keys[i * stride + j] + 2]++;
    for (uint32_t k = 0; k < nkeys; k++)
        r->off[k + 2] += r->off[k + 1];
    for (size_t i = 0; i < nitems; i++)
        for (int j = 0; j < per; j++)
            r->item[r->off[keys[i * stride + j] + 1]++] = (uint32_t)i;
    return true;
}

void sdi_rel_free(sd_mem *m, sdi_rel *r)
{
    sdi_free(m, r->off);
    sdi_free(m, r->item);
    r->off = r->item = NULL;
}

bool sdi_rels_need(sd_mem *m, sdi_rels *R, unsigned which)
{
    const sd_topo *t = R->t;
    /* each relation inverts an array of `per` keys every `stride` ids (casts: no arithmetic on
     * an array that may be absent, e.g. level 0's octahedra) */
    const struct {
        uint32_t nkeys, nitems;
        int stride, per;
        const uint32_t *keys;
    } spec[SDI_NREL] = {
        [SDI_VE] = {t->nv, t->ne, 2, 2, (const uint32_t *)t->ev},
        [SDI_VF] = {t->nv, t->nf, 3, 3, (const uint32_t *)t->fv},
        [SDI_EF] = {t->ne, t->nf, 3, 3, (const uint32_t *)t->fe},
        [SDI_VT] = {t->nv, t->ntet, 4, 4, (const uint32_t *)t->tet},
        [SDI_ET] = {t->ne, t->ntet, 6, 6, (const uint32_t *)t->tet_e},
        [SDI_FT] = {t->nf, t->ntet, 4, 4, (const uint32_t *)t->tet_f},
        [SDI_VD] = {t->nv, t->noct, 6, 2, (const uint32_t *)t->oct}, /* the diagonal's ends */
    };
    for (int k = 0; k < SDI_NREL; k++)
        if ((which & 1u << k) && !R->r[k].off &&
            !sdi_rel_build(m, &R->r[k], spec[k].nkeys, spec[k].nitems, spec[k].stride,
                           spec[k].per, spec[k].keys))
            return false;
    return true;
}

void sdi_rels_free(sd_mem *m, sdi_rels *R)
{
    for (int k = 0; k < SDI_NREL; k++)
        sdi_rel_free(m, &R->r[k]);
}

uint32_t sdi_rels_edge(const sdi_rels *R, uint32_t a, uint32_t b)
{
    const sd_topo *t = R->t;
    const sdi_rel *ve = &R->r[SDI_VE];
    if (ve->off[a + 1] - ve->off[a] > ve->off[b + 1] - ve->off[b]) { /* the shorter list */
        uint32_t s = a;
        a = b;
        b = s;
    }
    for (uint32_t k = ve->off[a]; k < ve->off[a + 1]; k++) {
        uint32_t e = ve->item[k];
        if (t->ev[e][0] == b || t->ev[e][1] == b)
            return e;
    }
    return UINT32_MAX;
}

bool sdi_face_has(const sd_topo *t, uint32_t f, uint32_t v)
{
    return t->fv[f][0] == v || t->fv[f][1] == v || t->fv[f][2] == v;
}

uint32_t sdi_rels_face(const sdi_rels *R, const uint32_t v[3])
{
    const sd_topo *t = R->t;
    const sdi_rel *vf = &R->r[SDI_VF];
    int s = 0;
    for (int i = 1; i < 3; i++) /* the vertex with the fewest faces */
        if (vf->off[v[i] + 1] - vf->off[v[i]] < vf->off[v[s] + 1] - vf->off[v[s]])
            s = i;
    for (uint32_t k = vf->off[v[s]]; k < vf->off[v[s] + 1]; k++) {
        uint32_t f = vf->item[k];
        if (sdi_face_has(t, f, v[0]) && sdi_face_has(t, f, v[1]) && sdi_face_has(t, f, v[2]))
            return f;
    }
    return UINT32_MAX;
}

uint32_t sdi_topo_find_edge(const sd_topo *t, uint32_t a, uint32_t b)
{
    for (uint32_t e = 0; e < t->ne; e++)
        if ((t->ev[e][0] == a && t->ev[e][1] == b) || (t->ev[e][0] == b && t->ev[e][1] == a))
            return e;
    return UINT32_MAX;
}

/* ---- lifecycle ----------------------------------------------------------------------------- */

void sdi_topo_free_faces(sd_mem *m, sd_topo *t)
{
    if (t->fv != t->trv) /* fv may be the triangles' own array (tr_ident) */
        sdi_free(m, t->fv);
    void *arrays[] = {t->fe, t->cu, t->tr, t->tet_e, t->tet_f, t->oct_e, t->oct_f, t->fn3, t->fflag};
    for (size_t i = 0; i < sizeof arrays / sizeof *arrays; i++)
        sdi_free(m, arrays[i]);
    t->fv = t->fe = NULL;
    t->cu = t->tr = NULL;
    t->tet_e = NULL;
    t->tet_f = NULL;
    t->oct_e = NULL;
    t->oct_f = NULL;
    t->fn3 = t->fflag = NULL;
    t->faces = false;
}

void sdi_topo_free_edges(sd_mem *m, sd_topo *t)
{
    void *arrays[] = {t->ev, t->efam, t->eflag, t->enm};
    for (size_t i = 0; i < sizeof arrays / sizeof *arrays; i++)
        sdi_free(m, arrays[i]);
    t->ev = NULL;
    t->efam = t->eflag = t->enm = NULL;
    t->derived = false;
}

void sdi_topo_free(sd_mem *m, sd_topo *t)
{
    sdi_topo_free_faces(m, t);
    sdi_topo_free_edges(m, t);
    void *arrays[] = {t->pt, t->cuv, t->trv, t->tet, t->tet_d, t->tet_b, t->oct, t->oct_b,
                      t->vfam, t->vflag, t->vnm};
    for (size_t i = 0; i < sizeof arrays / sizeof *arrays; i++)
        sdi_free(m, arrays[i]);
    memset(t, 0, sizeof *t);
}
