/* classify.c — classification of the control complex (000 Sec. 2; Algorithms 2-4) and the
 * first choice of major diagonals (001 Algorithm 2).
 *
 * For every vertex and edge of level 0 we derive:
 *   family    which C_k it belongs to (bit k): the k-subcomplex of maximal k-simplices and faces;
 *   dC        whether it lies in the boundary complex: boundary simplices (a (k-1)-face of a
 *             maximal k-simplex that is a face of nothing else) and their faces;
 *   type 1-4  non-manifold type (000 Sec. 2.4): 1 in C_k and C_l (k != l); 2 a (k-1)-simplex of
 *             C_k alone shared by 3+ k-simplices; 3 a lower-dimensional simplex of C_k alone where
 *             parts meet — tested, as 002 Sec. 5.2 does, by the connected components of its link;
 *             4 a face (of C_k alone, dim < k-1) of a type-1..3 simplex.
 * Deeper levels inherit these classes entity by entity (split.c), which is exact: the link of a
 * vertex point is isomorphic to its parent's, and the children of a simplex keep its type.
 */
#include "internal.h"
#include <stdlib.h>
#include <string.h>

static int popcount4(uint8_t f) { return (f & 1) + (f >> 1 & 1) + (f >> 2 & 1) + (f >> 3 & 1); }

/* Union-find over the link's nodes, numbered locally through `loc` (stamped per query). */
typedef struct linkuf {
    uint32_t *loc, *stamp, *parent, n, cur;
} linkuf;

static uint32_t uf_node(linkuf *u, uint32_t v)
{
    if (u->stamp[v] != u->cur) {
        u->stamp[v] = u->cur;
        u->loc[v] = u->n;
        u->parent[u->n] = u->n;
        u->n++;
    }
    return u->loc[v];
}
static uint32_t uf_find(linkuf *u, uint32_t a)
{
    while (u->parent[a] != a)
        a = u->parent[a] = u->parent[u->parent[a]];
    return a;
}
static void uf_union(linkuf *u, uint32_t a, uint32_t b)
{
    a = uf_find(u, uf_node(u, a));
    b = uf_find(u, uf_node(u, b));
    if (a != b)
        u->parent[a] = b;
}
static uint32_t uf_components(linkuf *u)
{
    uint32_t c = 0;
    for (uint32_t i = 0; i < u->n; i++)
        c += u->parent[i] == i;
    return c;
}
static void uf_begin(linkuf *u)
{
    u->cur++;
    u->n = 0;
}

/* Families (Algorithm 2): C_k of every vertex and edge; cdeg: curve segments per vertex, n2:
 * maximal triangles per edge. */
static void families(sd_topo *t, uint32_t *cdeg, uint32_t *n2)
{
    for (uint32_t i = 0; i < t->npt; i++)
        t->vfam[t->pt[i]] |= FAM0;
    for (uint32_t i = 0; i < t->ncu; i++) {
        uint32_t e = t->cu[i];
        t->efam[e] |= FAM1;
        t->eflag[e] |= EF_CURVE;
        for (int k = 0; k < 2; k++) {
            t->vfam[t->ev[e][k]] |= FAM1;
            cdeg[t->ev[e][k]]++;
        }
    }
    for (uint32_t i = 0; i < t->ntr; i++) {
        uint32_t f = t->tr[i];
        for (int j = 0; j < 3; j++) {
            t->efam[t->fe[f][j]] |= FAM2;
            n2[t->fe[f][j]]++;
            t->vfam[t->fv[f][j]] |= FAM2;
        }
    }
    for (uint32_t i = 0; i < t->ntet; i++) {
        for (int k = 0; k < 6; k++)
            t->efam[t->tet_e[i][k]] |= FAM3;
        for (int k = 0; k < 4; k++)
            t->vfam[t->tet[i][k]] |= FAM3;
    }
}

/* Boundary simplices and dC (Algorithm 3). */
static void boundary(sd_topo *t, const uint32_t *cdeg, const uint32_t *n2)
{
    const uint32_t nv = t->nv, ne = t->ne;
    for (uint32_t f = 0; f < t->nf; f++)
        if (!(t->fflag[f] & FF_MAX) && t->fn3[f] == 1) {
            t->fflag[f] |= FF_BND3;
            for (int j = 0; j < 3; j++) {
                t->eflag[t->fe[f][j]] |= EF_DC;
                t->vflag[t->fv[f][j]] |= VF_DC;
            }
        }
    for (uint32_t e = 0; e < ne; e++)
        if (t->efam[e] == FAM2 && n2[e] == 1) {
            t->eflag[e] |= EF_BND2 | EF_DC;
            t->vflag[t->ev[e][0]] |= VF_DC;
            t->vflag[t->ev[e][1]] |= VF_DC;
        }
    for (uint32_t v = 0; v < nv; v++)
        if (t->vfam[v] == FAM1 && cdeg[v] == 1)
            t->vflag[v] |= VF_CURVE_END | VF_DC;
}

/* Non-manifold types 1, 2 and 4 (000 Sec. 2.4), and NM_C2B. */
static void types_1_2_4(sd_topo *t, const uint32_t *cdeg, const uint32_t *n2)
{
    const uint32_t nv = t->nv, ne = t->ne;
    for (uint32_t v = 0; v < nv; v++) {
        if (popcount4(t->vfam[v]) >= 2)
            t->vnm[v] = 1;
        else if (t->vfam[v] == FAM1 && cdeg[v] >= 3)
            t->vnm[v] = 2;
    }
    for (uint32_t e = 0; e < ne; e++) {
        if (popcount4(t->efam[e]) >= 2)
            t->enm[e] = 1;
        else if (t->efam[e] == FAM2 && n2[e] >= 3)
            t->enm[e] = 2;
    }
    for (uint32_t e = 0; e < ne; e++)
        if ((t->efam[e] & FAM2) && n2[e] != 2)
            t->enm[e] |= NM_C2B;
    /* type 4: faces of type-2 simplices (exclusive members, dim < k-1) */
    for (uint32_t f = 0; f < t->nf; f++)
        if (t->fn3[f] >= 3)
            for (int j = 0; j < 3; j++) {
                if (nm_type(t->enm[t->fe[f][j]]) == 0)
                    t->enm[t->fe[f][j]] |= 4;
                if (t->vnm[t->fv[f][j]] == 0)
                    t->vnm[t->fv[f][j]] = 4;
            }
    for (uint32_t e = 0; e < ne; e++)
        if (nm_type(t->enm[e]) == 2)
            for (int k = 0; k < 2; k++)
                if (t->vnm[t->ev[e][k]] == 0)
                    t->vnm[t->ev[e][k]] = 4;
}

/* Type 3: a simplex of C_k alone whose link has 2+ connected components (002 Sec. 5.2). false:
 * no memory. */
static bool type_3(sd_mem *m, sd_topo *t, sdi_rels *R)
{
    const uint32_t nv = t->nv, ne = t->ne;
    linkuf u = {0};
    bool ok = false;
    if (!sdi_rels_need(m, R, SDI_REL(SDI_VF) | SDI_REL(SDI_VT) | SDI_REL(SDI_ET)))
        goto out;
    const sdi_rel *vf = &R->r[SDI_VF], *vt = &R->r[SDI_VT], *et = &R->r[SDI_ET];
    u.loc = sdi_alloc(m, (size_t)nv * sizeof *u.loc);
    u.stamp = sdi_calloc(m, nv, sizeof *u.stamp);
    u.parent = sdi_alloc(m, (size_t)nv * sizeof *u.parent);
    if (!u.loc || !u.stamp || !u.parent)
        goto out;

    for (uint32_t e = 0; e < ne; e++) {
        if (t->efam[e] != FAM3 || nm_type(t->enm[e]))
            continue;
        uf_begin(&u);
        for (uint32_t k = et->off[e]; k < et->off[e + 1]; k++) {
            const uint32_t *q = t->tet[et->item[k]];
            uint32_t o[2], n = 0;
            for (int i = 0; i < 4; i++)
                if (q[i] != t->ev[e][0] && q[i] != t->ev[e][1])
                    o[n++] = q[i];
            uf_union(&u, o[0], o[1]);
        }
        if (uf_components(&u) > 1) {
            t->enm[e] |= 3;
            for (int k = 0; k < 2; k++)
                if (t->vnm[t->ev[e][k]] == 0)
                    t->vnm[t->ev[e][k]] = 4;
        }
    }
    for (uint32_t v = 0; v < nv; v++) {
        if (t->vnm[v] || (t->vfam[v] != FAM2 && t->vfam[v] != FAM3))
            continue;
        uf_begin(&u);
        if (t->vfam[v] == FAM3) {
            for (uint32_t k = vt->off[v]; k < vt->off[v + 1]; k++) {
                const uint32_t *q = t->tet[vt->item[k]];
                uint32_t o[3], n = 0;
                for (int i = 0; i < 4; i++)
                    if (q[i] != v)
                        o[n++] = q[i];
                uf_union(&u, o[0], o[1]);
                uf_union(&u, o[1], o[2]);
            }
        } else {
            for (uint32_t k = vf->off[v]; k < vf->off[v + 1]; k++) {
                if (!(t->fflag[vf->item[k]] & FF_MAX)) /* the maximal triangles at v */
                    continue;
                const uint32_t *q = t->fv[vf->item[k]];
                uint32_t o[2], n = 0;
                for (int i = 0; i < 3; i++)
                    if (q[i] != v)
                        o[n++] = q[i];
                uf_union(&u, o[0], o[1]);
            }
        }
        if (uf_components(&u) > 1)
            t->vnm[v] = 3;
    }
    ok = true;
out:
    sdi_free(m, u.loc);
    sdi_free(m, u.stamp);
    sdi_free(m, u.parent);
    return ok;
}

sd_result sdi_classify_level0(sd_mem *m, sd_topo *t, sdi_rels *R, sd_error *err)
{
    uint32_t nv = t->nv, ne = t->ne;
    t->vfam = sdi_calloc(m, nv, 1);
    t->vflag = sdi_calloc(m, nv, 1);
    t->vnm = sdi_calloc(m, nv, 1);
    t->efam = sdi_calloc(m, ne ? ne : 1, 1);
    t->eflag = sdi_calloc(m, ne ? ne : 1, 1);
    t->enm = sdi_calloc(m, ne ? ne : 1, 1);
    uint32_t *cdeg = sdi_calloc(m, nv, sizeof *cdeg);
    uint32_t *n2 = sdi_calloc(m, ne ? ne : 1, sizeof *n2);
    sd_result rc = SD_OK;
    if (!t->vfam || !t->vflag || !t->vnm || !t->efam || !t->eflag || !t->enm || !cdeg || !n2) {
        rc = sdi_fail_nomem(err, m);
    } else {
        families(t, cdeg, n2);
        boundary(t, cdeg, n2);
        types_1_2_4(t, cdeg, n2);
        if (!type_3(m, t, R))
            rc = sdi_fail_nomem(err, m);
    }
    sdi_free(m, cdeg);
    sdi_free(m, n2);
    return rc;
}

/* ---- class codes: classes computed elsewhere (sd_level0_classes) ---------------------------
 * A code packs what classification derives from an entity's star: for vertices and edges the
 * family (bits 0-3), boundary bits and non-manifold type (and NM_C2B); for faces maximality,
 * solid boundary and the saturated number of 3-cells. Tags, overrides and rules come later from
 * these (singular.c, overrides.c, rules.c), so a complex that takes shipped codes derives the
 * shipper's rules wherever its own tags and neighbourhoods are the shipper's. Some of a code is
 * the complex's topology, which a shipped code cannot change: the family, a curve segment, a
 * maximal triangle, the 3-cells around a face (`*_TOPO`); the rest is what a piece that lacks
 * part of an entity's star may get wrong: the boundary bits, the non-manifold type (`*_CLASS`).
 *
 *   vertex  0-3 family | 4 VF_DC | 5 VF_CURVE_END | 6-8 type
 *   edge    0-3 family | 4 EF_DC | 5 EF_BND2 | 6 EF_CURVE | 7-9 type | 10 NM_C2B
 *   face    0 FF_MAX | 1 FF_BND3 | 2-3 3-cells (0, 1, 2, 3 or more)
 */
enum {
    CODE_SET = 0x8000,
    V_TOPO = 0x000f, V_CLASS = 0x01f0,
    E_TOPO = 0x004f, E_CLASS = 0x07b0,
    F_TOPO = 0x000d, F_CLASS = 0x0002,
};
static const uint8_t VF_CLS = VF_DC | VF_CURVE_END, EF_CLS = EF_DC | EF_BND2;

static uint16_t vertex_code(const sd_topo *t, uint32_t v)
{
    return (uint16_t)(CODE_SET | t->vfam[v] | (t->vflag[v] & VF_CLS) << 4 | nm_type(t->vnm[v]) << 6);
}
static uint16_t edge_code(const sd_topo *t, uint32_t e)
{
    return (uint16_t)(CODE_SET | t->efam[e] | (t->eflag[e] & (EF_CLS | EF_CURVE)) << 4 |
                      nm_type(t->enm[e]) << 7 | (t->enm[e] & NM_C2B ? 1u << 10 : 0));
}
static uint16_t face_code(const sd_topo *t, uint32_t f)
{
    return (uint16_t)(CODE_SET | (t->fflag[f] & (FF_MAX | FF_BND3)) |
                      (t->fn3[f] < 3 ? t->fn3[f] : 3) << 2);
}

void sdi_class_codes(const sd_topo *t, uint16_t *vertex, uint16_t *edge, uint16_t *face)
{
    for (uint32_t v = 0; vertex && v < t->nv; v++)
        vertex[v] = vertex_code(t, v);
    for (uint32_t e = 0; edge && e < t->ne; e++)
        edge[e] = edge_code(t, e);
    for (uint32_t f = 0; face && f < t->nf; f++)
        face[f] = face_code(t, f);
}

/* 0 when shipped code k may replace the entity's own (a code of the same topology), else 1. */
static int code_fits(uint16_t k, uint16_t own, uint16_t topo, uint16_t cls)
{
    return !(k & CODE_SET) || (k & ~(CODE_SET | topo | cls)) || ((k ^ own) & topo);
}

sd_result sdi_take_classes(sd_mem *m, sd_topo *t, sdi_rels *R, const sd_level0_classes *K,
                           sd_error *err)
{
    if (K->nv > t->nv || (K->nv && !K->vertex) || (K->ne && (!K->edge_v || !K->edge)) ||
        (K->nf && (!K->face_v || !K->face)))
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "classes: more vertices than the complex, or a missing array");
    if (!sdi_rels_need(m, R, SDI_REL(SDI_VE) | SDI_REL(SDI_VF)))
        return sdi_fail_nomem(err, m);
    /* all checked before any is taken: a refused list leaves nothing changed */
    for (size_t v = 0; v < K->nv; v++)
        if (K->vertex[v] && code_fits(K->vertex[v], vertex_code(t, (uint32_t)v), V_TOPO, V_CLASS))
            return sdi_fail(err, SD_ERR_ARG, (long)v, -1,
                            "classes: vertex %zu: not a class code of its family", v);
    uint32_t *eid = K->ne ? sdi_alloc(m, K->ne * sizeof *eid) : NULL;
    uint32_t *fid = K->nf ? sdi_alloc(m, K->nf * sizeof *fid) : NULL;
    sd_result rc = SD_OK;
    if ((K->ne && !eid) || (K->nf && !fid))
        rc = sdi_fail_nomem(err, m);
    for (size_t i = 0; !rc && i < K->ne; i++) {
        const uint32_t *ab = K->edge_v + 2 * i;
        if (!K->edge[i])
            continue;
        uint32_t e = ab[0] < t->nv && ab[1] < t->nv ? sdi_rels_edge(R, ab[0], ab[1]) : UINT32_MAX;
        eid[i] = e;
        if (e == UINT32_MAX)
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, -1, "classes: edge %zu is not an edge of the complex", i);
        else if (code_fits(K->edge[i], edge_code(t, e), E_TOPO, E_CLASS))
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, -1,
                          "classes: edge %zu: not a class code of its family and kind", i);
    }
    for (size_t i = 0; !rc && i < K->nf; i++) {
        const uint32_t *q = K->face_v + 3 * i;
        if (!K->face[i])
            continue;
        uint32_t f = q[0] < t->nv && q[1] < t->nv && q[2] < t->nv ? sdi_rels_face(R, q) : UINT32_MAX;
        fid[i] = f;
        if (f == UINT32_MAX)
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, -1, "classes: face %zu is not a face of the complex", i);
        else if (code_fits(K->face[i], face_code(t, f), F_TOPO, F_CLASS))
            rc = sdi_fail(err, SD_ERR_ARG, (long)i, -1,
                          "classes: face %zu: not a class code of a face with its cells", i);
    }
    size_t diff = 0;
    for (size_t v = 0; !rc && v < K->nv; v++) {
        uint16_t k = K->vertex[v];
        if (!k || k == vertex_code(t, (uint32_t)v))
            continue;
        diff++;
        t->vflag[v] = (uint8_t)((t->vflag[v] & ~VF_CLS) | (k >> 4 & VF_CLS));
        t->vnm[v] = (uint8_t)((t->vnm[v] & ~NM_TYPE) | (k >> 6 & NM_TYPE));
    }
    for (size_t i = 0; !rc && i < K->ne; i++) {
        uint16_t k = K->edge[i];
        if (!k || k == edge_code(t, eid[i]))
            continue;
        uint32_t e = eid[i];
        diff++;
        t->eflag[e] = (uint8_t)((t->eflag[e] & ~EF_CLS) | (k >> 4 & EF_CLS));
        t->enm[e] = (uint8_t)((t->enm[e] & ~(NM_TYPE | NM_C2B)) | (k >> 7 & NM_TYPE) |
                              (k >> 10 & 1 ? NM_C2B : 0));
    }
    for (size_t i = 0; !rc && i < K->nf; i++) {
        uint16_t k = K->face[i];
        if (!k || k == face_code(t, fid[i]))
            continue;
        diff++;
        t->fflag[fid[i]] = (uint8_t)((t->fflag[fid[i]] & ~FF_BND3) | (k & FF_BND3));
    }
    sdi_free(m, eid);
    sdi_free(m, fid);
    if (!rc && K->differing)
        *K->differing = diff;
    return rc;
}

/* The edge of tetrahedron c's diagonal pair that lies in its local face i (each opposite pair
 * has exactly one edge in every face: the one not touching vertex i). */
static uint32_t pair_edge_in_face(const sd_topo *t, uint32_t c, int pair, int i)
{
    int k = (SDI_TET_E[pair][0] == i || SDI_TET_E[pair][1] == i) ? 5 - pair : pair;
    return t->tet_e[c][k];
}

static int cmp_u32x4(const uint32_t *a, const uint32_t *b)
{
    for (int i = 0; i < 4; i++)
        if (a[i] != b[i])
            return a[i] < b[i] ? -1 : 1;
    return 0;
}

/* A row (key, tetrahedron): the key is the tetrahedron's 4 vertex ids ascending. */
static int cmp_keyrow(const void *a, const void *b)
{
    int r = cmp_u32x4(a, b);
    if (r)
        return r;
    uint32_t x = ((const uint32_t *)a)[4], y = ((const uint32_t *)b)[4];
    return (x > y) - (x < y);
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* Ascending; insertion sort for the usual handful (at most 4 on a manifold). */
static void sort_u32(uint32_t *a, uint32_t n)
{
    if (n > 16) {
        qsort(a, n, sizeof *a, cmp_u32);
        return;
    }
    for (uint32_t i = 1; i < n; i++) {
        uint32_t x = a[i], j = i;
        for (; j > 0 && a[j - 1] > x; j--)
            a[j] = a[j - 1];
        a[j] = x;
    }
}

/* Key of tetrahedron c's pair p: its two edges, each as (min vertex, max vertex), in ascending
 * order. */
static void pair_key(const sd_topo *t, uint32_t c, int p, uint32_t k[4])
{
    for (int s = 0; s < 2; s++) {
        const uint32_t *ev = t->ev[t->tet_e[c][s ? 5 - p : p]];
        k[2 * s] = ev[0] < ev[1] ? ev[0] : ev[1];
        k[2 * s + 1] = ev[0] < ev[1] ? ev[1] : ev[0];
    }
    if (k[2] < k[0] || (k[2] == k[0] && k[3] < k[1])) {
        uint32_t a = k[0], b = k[1];
        k[0] = k[2];
        k[1] = k[3];
        k[2] = a;
        k[3] = b;
    }
}

/* 001 Algorithm 2 (MAJOR-DIAGONAL-CHOOSE): breadth-first over face-adjacent tetrahedra, each
 * taking the pair with the fewest conflicts against its already visited neighbours; every
 * connected component gets its own search. A conflict is measured by 001 Def. 3.2 (proper
 * diagonals): two tetrahedra sharing a face are proper when their pairs cross that face at the
 * same edge, so that both octahedra's diagonals meet at its midpoint. (Reading Algorithm 2's
 * "c.edges - s" literally, i.e. avoiding the neighbours' edges, makes every shared face improper:
 * after 3 levels of two tetrahedra the shared face then carries interior edges with |rho(e)| = 5;
 * with this rule all are 4 or 6.)
 *
 * The choice depends on the topology alone, not on the order of the tetrahedra or of the
 * vertices inside each (nor so on whether one was reoriented): a tetrahedron's key is its 4
 * vertex ids ascending, compared lexicographically; each component starts at its tetrahedron of
 * smallest key (the tetrahedra are walked in key order, so the first unvisited one of a component
 * is its smallest); a dequeued tetrahedron enqueues its new face neighbours in ascending key order;
 * equal conflict counts go to the pair of smallest key (pair_key). The ranks of the keys come from
 * one sort: O(n log n).
 *
 * `fixed` (NULL, or per tetrahedron a pair in stored order, -1 where none): those pairs are kept
 * (a refinement keeps its untouched tetrahedra's), and the search starts from their neighbours,
 * so the new choices are made against them (001 Alg. 2 seeded with the visited set).
 *
 * The start of a component. Where the choice is proper, every tetrahedron around an edge
 * interior to the solids crosses its faces there or none does, so a level-1 point at the
 * midpoint of an edge with n tetrahedra around has valence 2 + 2n + (n or 0), and the first
 * tetrahedron's pair decides, face by face, the whole component's. The regular value is 14
 * (001 Sec. 3: 12 edges and 2 major diagonals): an edge with 4 tetrahedra around wants the
 * diagonals, one with 6 does not; on the box spline's own lattice (cubes of 6 tetrahedra
 * around a main diagonal) only one of the three starts gives every such point 14 — the mask of
 * 001 eq. 3.2 — and the start of smallest key may give 10 and 20. So a component without given
 * pairs is searched from each of its first tetrahedron's three pairs, and the search kept is the
 * one with the fewest conflicts, then the smallest sum over its interior edges of
 * |valence - 14| at their midpoints, then the start pair of smallest key (which is the plain
 * search's choice: meshes where all three tie, e.g. without interior edges, keep it). */
typedef struct diag_search {
    sd_topo *t;
    const sdi_rel *ft;
    uint32_t *queue, *rank;
    uint32_t (*order)[5];
    uint8_t *state;           /* 0 new, 1 queued, 2 visited */
    uint32_t head, tail;
    uint32_t force_tet;       /* takes force_pair whatever its conflicts (UINT32_MAX: none) */
    int force_pair;
    uint64_t conflicts;       /* improper shared faces met by the search */
} diag_search;

/* Queue tetrahedron c's new face neighbours in ascending key order. */
static void queue_neighbours(diag_search *S, uint32_t c)
{
    sd_topo *t = S->t;
    uint32_t fresh = S->tail;
    for (int i = 0; i < 4; i++) {
        uint32_t f = t->tet_f[c][i];
        for (uint32_t k = S->ft->off[f]; k < S->ft->off[f + 1]; k++) {
            uint32_t d = S->ft->item[k];
            if (S->state[d] == 0) {
                S->state[d] = 1;
                S->queue[S->tail++] = S->rank[d]; /* ranks for now, tetrahedra after the sort */
            }
        }
    }
    sort_u32(S->queue + fresh, S->tail - fresh);
    for (uint32_t q = fresh; q < S->tail; q++)
        S->queue[q] = S->order[S->queue[q]][4];
}

/* The breadth-first search from what is queued: each dequeued tetrahedron takes the pair with
 * the fewest conflicts against its visited neighbours (ties: the pair of smallest key). */
static void search(diag_search *S)
{
    sd_topo *t = S->t;
    while (S->head < S->tail) {
        uint32_t c = S->queue[S->head++];
        int conflicts[3] = {0, 0, 0};
        for (int i = 0; i < 4; i++) {
            uint32_t f = t->tet_f[c][i];
            for (uint32_t k = S->ft->off[f]; k < S->ft->off[f + 1]; k++) {
                uint32_t d = S->ft->item[k];
                if (d == c || S->state[d] != 2)
                    continue;
                int j = 0;
                while (j < 3 && t->tet_f[d][j] != f)
                    j++;
                uint32_t theirs = pair_edge_in_face(t, d, t->tet_d[d], j);
                for (int p = 0; p < 3; p++)
                    conflicts[p] += pair_edge_in_face(t, c, p, i) != theirs;
            }
        }
        queue_neighbours(S, c);
        int best = 0;
        uint32_t bkey[4], key[4];
        pair_key(t, c, 0, bkey);
        for (int p = 1; p < 3; p++) {
            pair_key(t, c, p, key);
            if (conflicts[p] < conflicts[best] ||
                (conflicts[p] == conflicts[best] && cmp_u32x4(key, bkey) < 0)) {
                best = p;
                memcpy(bkey, key, sizeof key);
            }
        }
        if (c == S->force_tet)
            best = S->force_pair;
        S->conflicts += (uint64_t)conflicts[best];
        t->tet_d[c] = (uint8_t)best;
        S->state[c] = 2;
    }
}

/* Per edge, the number of tetrahedra around it (at most 255) where the edge is interior to the
 * solids — every face of a tetrahedron around it is shared by exactly two, and its class is a
 * manifold solid edge's (only in C_3: no triangle or curve on it, one ring of tetrahedra: a
 * pinched edge's rings would be counted as one) — else 0. NULL for lack of memory. */
static uint8_t *interior_rings(sd_mem *m, const sd_topo *t, const sdi_rel *ft, bool *any)
{
    uint8_t *ring = sdi_calloc(m, (size_t)t->ne + 1, 1);
    uint8_t *open = sdi_calloc(m, (size_t)t->ne + 1, 1);
    if (!ring || !open) {
        sdi_free(m, ring);
        sdi_free(m, open);
        return NULL;
    }
    for (uint32_t c = 0; c < t->ntet; c++)
        for (int k = 0; k < 6; k++) {
            uint32_t e = t->tet_e[c][k];
            ring[e] += ring[e] < 255;
        }
    for (uint32_t c = 0; c < t->ntet; c++)
        for (int i = 0; i < 4; i++) {
            uint32_t f = t->tet_f[c][i];
            if (ft->off[f + 1] - ft->off[f] == 2)
                continue;
            for (int k = 0; k < 6; k++) /* face i holds the edges without vertex i */
                if (SDI_TET_E[k][0] != i && SDI_TET_E[k][1] != i)
                    open[t->tet_e[c][k]] = 1;
        }
    *any = false;
    for (uint32_t e = 0; e < t->ne; e++) {
        if (open[e] || (t->efam && (t->efam[e] != FAM3 || nm_type(t->enm[e]))))
            ring[e] = 0;
        *any |= ring[e] != 0;
    }
    sdi_free(m, open);
    return ring;
}

/* Sum over the interior edges of the tetrahedra queue[first, last) of |valence - 14| of their
 * midpoints at level 1 with the pairs chosen (2 + 2 n + the pairs that hold the edge). `held`
 * (zero on entry and on return) and `seen` (stamps, `stamp` unused so far) are per edge. */
static uint64_t valence_deviation(const diag_search *S, uint32_t first, uint32_t last,
                                  const uint8_t *ring, uint32_t *held, uint32_t *seen,
                                  uint32_t stamp)
{
    const sd_topo *t = S->t;
    for (uint32_t q = first; q < last; q++) {
        uint32_t c = S->queue[q];
        int p = t->tet_d[c];
        held[t->tet_e[c][p]]++;
        held[t->tet_e[c][5 - p]]++;
    }
    uint64_t dev = 0;
    for (uint32_t q = first; q < last; q++) {
        uint32_t c = S->queue[q];
        for (int k = 0; k < 6; k++) {
            uint32_t e = t->tet_e[c][k];
            if (seen[e] == stamp)
                continue;
            seen[e] = stamp;
            if (ring[e]) {
                int64_t v = 2 + 2 * (int64_t)ring[e] + held[e] - 14;
                dev += (uint64_t)(v < 0 ? -v : v);
            }
        }
    }
    for (uint32_t q = first; q < last; q++) {
        uint32_t c = S->queue[q];
        for (int k = 0; k < 6; k++)
            held[t->tet_e[c][k]] = 0;
    }
    return dev;
}

/* The scratch of the starts' comparison: per edge the interior ring (interior_rings), the pairs
 * holding it and a stamp (valence_deviation), per queue position the best run's pairs. */
typedef struct diag_starts {
    const uint8_t *ring;
    uint32_t *held, *seen, stamp;
    uint8_t *kept;
} diag_starts;

/* The component of `start` searched from each of its three pairs (smallest key first), keeping
 * the fewest conflicts, then the least valence deviation, then the earlier start. */
static void search_best_start(diag_search *S, diag_starts *D, uint32_t start)
{
    sd_topo *t = S->t;
    uint32_t key[3][4];
    int pairs[3] = {0, 1, 2};
    for (int p = 0; p < 3; p++)
        pair_key(t, start, p, key[p]);
    for (int i = 1; i < 3; i++) /* by key */
        for (int j = i; j > 0 && cmp_u32x4(key[pairs[j]], key[pairs[j - 1]]) < 0; j--) {
            int x = pairs[j];
            pairs[j] = pairs[j - 1];
            pairs[j - 1] = x;
        }
    const uint32_t first = S->tail;
    uint32_t last = first;
    uint64_t best_conf = UINT64_MAX, best_dev = UINT64_MAX;
    for (int run = 0; run < 3; run++) {
        for (uint32_t q = first; q < last; q++) /* the previous run's component, unvisited */
            S->state[S->queue[q]] = 0;
        S->head = S->tail = first;
        S->queue[S->tail++] = start;
        S->state[start] = 1;
        S->force_tet = start;
        S->force_pair = pairs[run];
        S->conflicts = 0;
        search(S);
        last = S->tail;
        uint64_t dev = valence_deviation(S, first, last, D->ring, D->held, D->seen, ++D->stamp);
        if (S->conflicts < best_conf || (S->conflicts == best_conf && dev < best_dev)) {
            best_conf = S->conflicts;
            best_dev = dev;
            for (uint32_t q = first; q < last; q++)
                D->kept[q] = t->tet_d[S->queue[q]];
        }
    }
    S->force_tet = UINT32_MAX;
    for (uint32_t q = first; q < last; q++)
        t->tet_d[S->queue[q]] = D->kept[q];
}

sd_result sdi_choose_diagonals(sd_mem *m, sd_topo *t, sdi_rels *R, const int8_t *fixed,
                               sd_error *err)
{
    const uint32_t n = t->ntet;
    if (n == 0)
        return SD_OK;
    sd_result r = SD_OK;
    diag_search S = {.t = t, .force_tet = UINT32_MAX};
    diag_starts D = {0};
    uint8_t *ring = NULL;
    bool any = false;
    S.queue = sdi_alloc(m, (size_t)n * sizeof *S.queue);
    S.rank = sdi_alloc(m, (size_t)n * sizeof *S.rank);
    S.order = sdi_alloc(m, (size_t)n * sizeof *S.order); /* (key, tet) by key */
    S.state = sdi_calloc(m, n, 1);
    if (!S.queue || !S.rank || !S.order || !S.state || !sdi_rels_need(m, R, SDI_REL(SDI_FT)))
        goto nomem;
    S.ft = &R->r[SDI_FT];
    if (!(ring = interior_rings(m, t, S.ft, &any)))
        goto nomem;
    if (any) {
        D = (diag_starts){.ring = ring, .kept = sdi_alloc(m, n),
                          .held = sdi_calloc(m, (size_t)t->ne + 1, sizeof *D.held),
                          .seen = sdi_calloc(m, (size_t)t->ne + 1, sizeof *D.seen)};
        if (!D.kept || !D.held || !D.seen)
            goto nomem;
    }
    for (uint32_t c = 0; c < n; c++) {
        memcpy(S.order[c], t->tet[c], 4 * sizeof **S.order);
        sort_u32(S.order[c], 4);
        S.order[c][4] = c;
    }
    qsort(S.order, n, sizeof *S.order, cmp_keyrow);
    for (uint32_t q = 0; q < n; q++)
        S.rank[S.order[q][4]] = q;
    if (fixed) { /* the given pairs first; the search starts from their neighbours, in key order */
        for (uint32_t c = 0; c < n; c++)
            if (fixed[c] >= 0 && fixed[c] <= 2) {
                t->tet_d[c] = (uint8_t)fixed[c];
                S.state[c] = 2;
            }
        for (uint32_t r0 = 0; r0 < n; r0++) {
            uint32_t c = S.order[r0][4];
            if (fixed[c] >= 0 && fixed[c] <= 2)
                queue_neighbours(&S, c);
        }
        search(&S);
    }
    for (uint32_t r0 = 0; r0 < n; r0++) {
        uint32_t start = S.order[r0][4];
        if (S.state[start])
            continue;
        if (any) {
            search_best_start(&S, &D, start);
            continue;
        }
        S.queue[S.tail++] = start; /* no interior edge anywhere: the plain search */
        S.state[start] = 1;
        search(&S);
    }
    goto out;
nomem:
    r = sdi_fail_nomem(err, m);
out:
    sdi_free(m, ring);
    sdi_free(m, D.kept);
    sdi_free(m, D.held);
    sdi_free(m, D.seen);
    sdi_free(m, S.queue);
    sdi_free(m, S.rank);
    sdi_free(m, S.order);
    sdi_free(m, S.state);
    return r;
}
