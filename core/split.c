/* split.c — the topology of one level (docs/RULES.md "Splitting"; 000 Algorithm 6; 001 Algorithm 1).
 *
 *   edge        -> 2 edges at the edge point
 *   triangle    -> 4 triangles
 *   tetrahedron -> 4 corner tetrahedra + 1 octahedron on the 6 edge points
 *   octahedron  -> 6 corner octahedra + 8 face tetrahedra around the new cell point
 *
 * Numbering is direct, with no search: level l+1 has vertices [vertex points | edge points |
 * cell points]; edges [2 halves per edge | 3 per face (cutting its corners) | 12 per octahedron
 * (cell point to edge points)]; faces [4 per face (corners, middle) | 4 per tetrahedron | 24 per
 * octahedron]. Each cell type has a template, built once per split from the local tables, that
 * says for every child cell which parent entity each of its vertices, edges and faces comes from;
 * the split then only maps local references to global ids.
 *
 * Diagonals (docs/RULES.md "Diagonal inheritance"): a tetrahedron with pair (e_k, e_5-k) gives its octahedron the
 * diagonal joining those edges' points; corner tetrahedra keep the parent's pair (they are
 * scaled copies). An octahedron with diagonal (p,q) gives its corner octahedra diagonals parallel
 * to it — [vertex point, cell point] at p and q, [m(v,p), m(v,q)] at an equator vertex v — and its
 * face tetrahedron over (P,U,W) the pair ([m(P,U), m(P,W)], [m(U,W), cell point]).
 * Every child is oriented like its parent (checked on reference coordinates when the templates
 * are built).
 *
 * In three parts (see sd_topo in internal.h): sdi_split_cells makes the child's cells, vertex
 * classes and boundary masks (which faces of a cell are on the solids' boundary: the children of a
 * boundary face are, faces inside a parent cell are not); sdi_split_edges its edges and their
 * classes, sdi_split_faces its faces, per-cell edge and face ids and face classes — both only when
 * the child's rules, its own children or an edge accessor need them. They walk the parent's cells
 * with the same templates, so they agree on every child's number.
 *
 * Classification is inherited (see classify.c): halves keep their edge's class; an edge point
 * takes its edge's family and dC flag and becomes type 1 (if the edge was) or type 4 (if the edge
 * was of type 2, 3 or 4); edges inside a face take the face's family and boundary status and are
 * type 4 inside a type-2 face; everything inside a cell is interior and manifold.
 */
#include "internal.h"
#ifdef __SSE2__
#include <emmintrin.h>
enum { STREAM_MIN = 8 << 20 }; /* bytes of a level's triangles written past the caches */
#endif
#include <assert.h>
#include <string.h>

enum { R_HALF, R_FINT, R_OINT };   /* edge references */
enum { R_FCHILD, R_CINT };         /* face references */
#define MKREF(t, a, b) ((uint16_t)((t) << 12 | (a) << 4 | (b)))
#define RT(r) ((r) >> 12)
#define RA(r) (((r) >> 4) & 0xff)
#define RB(r) ((r) & 0xf)
#define MIDDLE 15

typedef struct tcell {
    uint8_t kind, diag; /* kind 4 = tetrahedron, 6 = octahedron */
    uint8_t v[6];
    uint16_t e[12], f[8];
    uint8_t es[12], fs[8]; /* e, f as slots of the per-parent tables (see slots()) */
    uint8_t bmask[256];    /* the child's boundary mask for each mask of its parent */
} tcell;

typedef struct tface {
    uint8_t v[3];
    uint16_t e[3];
    uint8_t es[3];
} tface;

typedef struct tmpl {
    int n, ne, nfc;
    const uint8_t (*pe)[2];
    const uint8_t (*pf)[3];
    int ncell;
    tcell cell[14];
    int nif;
    tface iface[24];
} tmpl;

static int vkind(const tmpl *T, int u) { return u < T->n ? 0 : u < T->n + T->ne ? 1 : 2; }

static int tm_face(const tmpl *T, int a, int b, int c)
{
    for (int f = 0; f < T->nfc; f++) {
        int hit = 0;
        for (int j = 0; j < 3; j++)
            hit += T->pf[f][j] == a || T->pf[f][j] == b || T->pf[f][j] == c;
        if (hit == 3)
            return f;
    }
    return -1;
}

static uint16_t tm_edge_ref(const tmpl *T, int u, int w)
{
    if (vkind(T, u) > vkind(T, w)) {
        int x = u;
        u = w;
        w = x;
    }
    int ku = vkind(T, u), kw = vkind(T, w);
    if (ku == 0 && kw == 1) {
        int k = w - T->n;
        assert(T->pe[k][0] == u || T->pe[k][1] == u);
        return MKREF(R_HALF, k, u);
    }
    if (ku == 1 && kw == 1) {
        const uint8_t *a = T->pe[u - T->n], *b = T->pe[w - T->n];
        int s = (a[0] == b[0] || a[0] == b[1]) ? a[0] : a[1];
        int oa = a[0] == s ? a[1] : a[0], ob = b[0] == s ? b[1] : b[0];
        int lf = tm_face(T, s, oa, ob);
        assert(lf >= 0);
        return MKREF(R_FINT, lf, s);
    }
    assert(ku == 1 && kw == 2);
    return MKREF(R_OINT, u - T->n, 0);
}

static uint16_t tm_face_ref(tmpl *T, int u, int w, int z)
{
    int s[3] = {u, w, z};
    for (int i = 1; i < 3; i++) /* sort by kind, then id */
        for (int j = i; j > 0 && (vkind(T, s[j - 1]) * 64 + s[j - 1] > vkind(T, s[j]) * 64 + s[j]); j--) {
            int x = s[j];
            s[j] = s[j - 1];
            s[j - 1] = x;
        }
    int k0 = vkind(T, s[0]), k1 = vkind(T, s[1]), k2 = vkind(T, s[2]);
    if (k0 == 0 && k1 == 1 && k2 == 1) {
        const uint8_t *a = T->pe[s[1] - T->n], *b = T->pe[s[2] - T->n];
        int oa = a[0] == s[0] ? a[1] : a[0], ob = b[0] == s[0] ? b[1] : b[0];
        int lf = tm_face(T, s[0], oa, ob);
        assert(lf >= 0);
        return MKREF(R_FCHILD, lf, s[0]);
    }
    if (k0 == 1 && k1 == 1 && k2 == 1) {
        int vs[6], nvs = 0;
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 2; j++) {
                int x = T->pe[s[i] - T->n][j], seen = 0;
                for (int q = 0; q < nvs; q++)
                    seen |= vs[q] == x;
                if (!seen)
                    vs[nvs++] = x;
            }
        if (nvs == 3) {
            int lf = tm_face(T, vs[0], vs[1], vs[2]);
            assert(lf >= 0);
            return MKREF(R_FCHILD, lf, MIDDLE);
        }
    }
    /* a face inside the parent cell */
    for (int i = 0; i < T->nif; i++) {
        int hit = 0;
        for (int j = 0; j < 3; j++)
            hit += T->iface[i].v[j] == u || T->iface[i].v[j] == w || T->iface[i].v[j] == z;
        if (hit == 3)
            return MKREF(R_CINT, i, 0);
    }
    assert(T->nif < 24);
    tface *f = &T->iface[T->nif];
    f->v[0] = (uint8_t)u;
    f->v[1] = (uint8_t)w;
    f->v[2] = (uint8_t)z;
    for (int j = 0; j < 3; j++)
        f->e[j] = tm_edge_ref(T, f->v[j], f->v[(j + 1) % 3]);
    return MKREF(R_CINT, T->nif++, 0);
}

/* Reference coordinates of template vertex u (for the orientation check). */
static void tm_coord(const tmpl *T, const double (*ref)[3], int u, double *o)
{
    if (u < T->n) {
        memcpy(o, ref[u], 3 * sizeof *o);
    } else if (u < T->n + T->ne) {
        const uint8_t *e = T->pe[u - T->n];
        for (int k = 0; k < 3; k++)
            o[k] = 0.5 * (ref[e[0]][k] + ref[e[1]][k]);
    } else {
        for (int k = 0; k < 3; k++) {
            o[k] = 0;
            for (int i = 0; i < T->n; i++)
                o[k] += ref[i][k] / T->n;
        }
    }
}

static double orient(const tmpl *T, const double (*ref)[3], const tcell *c)
{
    double x[6][3];
    for (int i = 0; i < c->kind; i++)
        tm_coord(T, ref, c->v[i], x[i]);
    double a[3], b[3], d[3];
    if (c->kind == 4) {
        for (int k = 0; k < 3; k++) {
            a[k] = x[1][k] - x[0][k];
            b[k] = x[2][k] - x[0][k];
            d[k] = x[3][k] - x[0][k];
        }
    } else { /* (a - centre) x (b - centre) . (p - centre) */
        double ctr[3] = {0, 0, 0};
        for (int i = 0; i < 6; i++)
            for (int k = 0; k < 3; k++)
                ctr[k] += x[i][k] / 6;
        for (int k = 0; k < 3; k++) {
            a[k] = x[2][k] - ctr[k];
            b[k] = x[4][k] - ctr[k];
            d[k] = x[0][k] - ctr[k];
        }
    }
    return (a[1] * b[2] - a[2] * b[1]) * d[0] + (a[2] * b[0] - a[0] * b[2]) * d[1] +
           (a[0] * b[1] - a[1] * b[0]) * d[2];
}

static void tm_add(tmpl *T, const double (*ref)[3], int kind, const int *v, int diag)
{
    tcell *c = &T->cell[T->ncell++];
    memset(c, 0, sizeof *c);
    c->kind = (uint8_t)kind;
    c->diag = (uint8_t)diag;
    for (int i = 0; i < kind; i++)
        c->v[i] = (uint8_t)v[i];
    if (orient(T, ref, c) < 0) {
        int a = kind == 4 ? 2 : 4, b = kind == 4 ? 3 : 5;
        uint8_t x = c->v[a];
        c->v[a] = c->v[b];
        c->v[b] = x;
        if (kind == 4 && diag)
            c->diag = (uint8_t)(3 - diag); /* slots 2,3 swapped: pairs 1 and 2 trade places */
    }
    assert(orient(T, ref, c) > 0);
    const uint8_t (*E)[2] = kind == 4 ? SDI_TET_E : SDI_OCT_E;
    const uint8_t (*F)[3] = kind == 4 ? SDI_TET_F : SDI_OCT_F;
    for (int k = 0; k < (kind == 4 ? 6 : 12); k++)
        c->e[k] = tm_edge_ref(T, c->v[E[k][0]], c->v[E[k][1]]);
    for (int k = 0; k < (kind == 4 ? 4 : 8); k++)
        c->f[k] = tm_face_ref(T, c->v[F[k][0]], c->v[F[k][1]], c->v[F[k][2]]);
}

static int ledge(const tmpl *T, int i, int j)
{
    for (int k = 0; k < T->ne; k++)
        if ((T->pe[k][0] == i && T->pe[k][1] == j) || (T->pe[k][0] == j && T->pe[k][1] == i))
            return T->n + k;
    assert(0);
    return -1;
}

static void tm_tet(tmpl *T, int d)
{
    static const double ref[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    memset(T, 0, sizeof *T);
    T->n = 4;
    T->ne = 6;
    T->nfc = 4;
    T->pe = SDI_TET_E;
    T->pf = SDI_TET_F;
    for (int i = 0; i < 4; i++) { /* corner tetrahedra: scaled copies, same pair */
        int v[4];
        for (int s = 0; s < 4; s++)
            v[s] = s == i ? i : ledge(T, i, s);
        tm_add(T, ref, 4, v, d);
    }
    int o[6] = {4 + d, 4 + 5 - d}, n = 2;
    for (int k = 0; k < 3; k++)
        if (k != d) {
            o[n++] = 4 + k;
            o[n++] = 4 + 5 - k;
        }
    tm_add(T, ref, 6, o, 0);
}

static void tm_oct(tmpl *T)
{
    static const double ref[6][3] = {{0, 0, 1}, {0, 0, -1}, {1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}};
    memset(T, 0, sizeof *T);
    T->n = 6;
    T->ne = 12;
    T->nfc = 8;
    T->pe = SDI_OCT_E;
    T->pf = SDI_OCT_F;
    const int C = 18;
#define E(i, j) ledge(T, i, j)
    /* corner octahedra; slots (p,q,a,a2,b,b2), diagonal first (docs/RULES.md "Diagonal inheritance") */
    int c0[6] = {0, C, E(0, 2), E(0, 3), E(0, 4), E(0, 5)};
    int c1[6] = {1, C, E(1, 2), E(1, 3), E(1, 4), E(1, 5)};
    int c2[6] = {E(2, 0), E(2, 1), 2, C, E(2, 4), E(2, 5)};
    int c3[6] = {E(3, 0), E(3, 1), 3, C, E(3, 4), E(3, 5)};
    int c4[6] = {E(4, 0), E(4, 1), 4, C, E(4, 2), E(4, 3)};
    int c5[6] = {E(5, 0), E(5, 1), 5, C, E(5, 2), E(5, 3)};
    const int *corners[6] = {c0, c1, c2, c3, c4, c5};
    for (int i = 0; i < 6; i++)
        tm_add(T, ref, 6, corners[i], 0);
    /* face tetrahedra over (P,U,W), pair 0 = ([m(P,U), m(P,W)], [m(U,W), cell point]) */
    for (int f = 0; f < 8; f++) {
        int P = SDI_OCT_F[f][0], U = SDI_OCT_F[f][1], W = SDI_OCT_F[f][2];
        int v[4] = {E(P, U), E(P, W), E(U, W), C};
        tm_add(T, ref, 4, v, 0);
    }
#undef E
}

/* ---- runtime ---------------------------------------------------------------------------- */

typedef struct ctx {
    const sd_topo *P;
    const uint32_t *pv, *pe, *pf;
    uint32_t center, ibase_e, ibase_f;
} ctx;

static inline uint32_t half(const sd_topo *P, uint32_t e, uint32_t x)
{
    return 2 * e + (P->ev[e][0] == x ? 0 : 1);
}
/* The split of a parent tetrahedron makes 4 corner tetrahedra, then its octahedron; that of a
 * parent octahedron 6 corner octahedra, then 8 face tetrahedra (tm_tet, tm_oct; checked by
 * templates()). The emitters below are written for these two shapes, with constant counts. */
/* the emitters' shape arguments: child tetrahedra, child octahedra, the parent's vertices and
 * edges, the faces inside it */
#define TET_KIDS 4, 1, 4, 6, 4
#define OCT_KIDS 8, 6, 6, 12, 24

/* The global ids behind the template's local vertices [parent's vertices | its edge points |
 * cell point]. */
static inline __attribute__((always_inline)) void vertex_table(const ctx *x, int n, int ne,
                                                               uint32_t *lv)
{
    const uint32_t pnv = x->P->nv;
    for (int u = 0; u < n; u++)
        lv[u] = x->pv[u];
    for (int k = 0; k < ne; k++)
        lv[n + k] = pnv + x->pe[k];
    lv[n + ne] = x->center;
}

static inline __attribute__((always_inline)) void put_tet(sd_topo *C, const tcell *c,
                                                          const uint32_t *lv, unsigned pmask,
                                                          uint32_t t)
{
    uint32_t *d = C->tet[t];
    d[0] = lv[c->v[0]];
    d[1] = lv[c->v[1]];
    d[2] = lv[c->v[2]];
    d[3] = lv[c->v[3]];
    C->tet_d[t] = c->diag;
    C->tet_b[t] = c->bmask[pmask];
}

static inline __attribute__((always_inline)) void put_oct(sd_topo *C, const tcell *c,
                                                          const uint32_t *lv, unsigned pmask,
                                                          uint32_t o)
{
    uint32_t *d = C->oct[o];
    for (int k = 0; k < 6; k++)
        d[k] = lv[c->v[k]];
    C->oct_b[o] = c->bmask[pmask];
}

/* Phase A (ids false) writes a child's vertices, diagonal and boundary mask, phase B (ids true)
 * its edge and face ids. */
static inline __attribute__((always_inline)) void
put_child(sd_topo *C, const tcell *c, bool oct, bool ids, const uint32_t *lv, const uint32_t *le,
          const uint32_t *lf, unsigned pmask, uint32_t at);

/* The children of one parent cell in template order: ntk tetrahedra and nok octahedra, the
 * octahedra first for a parent octahedron (n, its vertices, is 6). */
static inline __attribute__((always_inline)) void
put_children(sd_topo *C, const tmpl *T, bool ids, const uint32_t *lv, const uint32_t *le,
             const uint32_t *lf, unsigned pmask, uint32_t tet_at, uint32_t oct_at, int ntk,
             int nok, int n)
{
    const bool octa_first = n == 6;
    const tcell *c = T->cell;
    if (octa_first)
        for (int i = 0; i < nok; i++)
            put_child(C, c++, true, ids, lv, le, lf, pmask, oct_at + (uint32_t)i);
    for (int i = 0; i < ntk; i++)
        put_child(C, c++, false, ids, lv, le, lf, pmask, tet_at + (uint32_t)i);
    if (!octa_first)
        for (int i = 0; i < nok; i++)
            put_child(C, c++, true, ids, lv, le, lf, pmask, oct_at + (uint32_t)i);
}

/* Phase A for one parent cell (the shape arguments as TET_KIDS / OCT_KIDS). */
static inline __attribute__((always_inline)) void
emit_cells(sd_topo *C, const ctx *x, const tmpl *T, unsigned pmask, uint32_t tet_at,
           uint32_t oct_at, int ntk, int nok, int n, int ne, int nif)
{
    (void)nif;
    uint32_t lv[19];
    vertex_table(x, n, ne, lv);
    put_children(C, T, false, lv, NULL, NULL, pmask, tet_at, oct_at, ntk, nok, n);
}

/* The per-parent edge and face tables (slots as edge_slot and face_slot number them). */
static inline __attribute__((always_inline)) void edge_face_tables(const ctx *x, const tmpl *T,
                                                                   int n, int ne, int nif,
                                                                   uint32_t *le, uint32_t *lf)
{
    const sd_topo *P = x->P;
    const int nfc = n == 4 ? 4 : 8;
    for (int k = 0; k < ne; k++) {
        uint32_t g = x->pe[k];
        uint32_t s = P->ev[g][0] == x->pv[T->pe[k][0]] ? 0 : 1;
        le[2 * k] = 2 * g + s;
        le[2 * k + 1] = 2 * g + 1 - s;
    }
    for (int q = 0; q < nfc; q++) {
        uint32_t f = x->pf[q];
        const uint32_t *fv = P->fv[f];
        for (int j = 0; j < 3; j++) {
            uint32_t v = x->pv[T->pf[q][j]];
            uint32_t p = fv[0] == v ? 0 : fv[1] == v ? 1 : 2;
            le[2 * ne + 3 * q + j] = 2 * P->ne + 3 * f + p;
            lf[4 * q + j] = 4 * f + p;
        }
        lf[4 * q + 3] = 4 * f + 3;
    }
    if (n == 6)
        for (int k = 0; k < 12; k++)
            le[2 * ne + 3 * nfc + k] = x->ibase_e + (uint32_t)k;
    for (int i = 0; i < nif; i++)
        lf[4 * nfc + i] = x->ibase_f + (uint32_t)i;
}

static inline __attribute__((always_inline)) void put_tet_ids(sd_topo *C, const tcell *c,
                                                              const uint32_t *le,
                                                              const uint32_t *lf, uint32_t t)
{
    for (int k = 0; k < 6; k++)
        C->tet_e[t][k] = le[c->es[k]];
    for (int k = 0; k < 4; k++)
        C->tet_f[t][k] = lf[c->fs[k]];
}

static inline __attribute__((always_inline)) void put_oct_ids(sd_topo *C, const tcell *c,
                                                              const uint32_t *le,
                                                              const uint32_t *lf, uint32_t o)
{
    for (int k = 0; k < 12; k++)
        C->oct_e[o][k] = le[c->es[k]];
    for (int k = 0; k < 8; k++)
        C->oct_f[o][k] = lf[c->fs[k]];
}

/* Phase B for one parent cell: the faces inside it and the edge and face ids of its children. */
static inline __attribute__((always_inline)) void
emit_ids(sd_topo *C, const ctx *x, const tmpl *T, uint32_t tet_at, uint32_t oct_at, int ntk,
         int nok, int n, int ne, int nif)
{
    uint32_t lv[19], le[2 * 12 + 3 * 8 + 12], lf[4 * 8 + 24];
    vertex_table(x, n, ne, lv);
    edge_face_tables(x, T, n, ne, nif, le, lf);
    for (int i = 0; i < nif; i++) {
        uint32_t f = x->ibase_f + (uint32_t)i;
        for (int j = 0; j < 3; j++) {
            C->fv[f][j] = lv[T->iface[i].v[j]];
            C->fe[f][j] = le[T->iface[i].es[j]];
        }
        C->fn3[f] = 2;
        C->fflag[f] = 0;
    }
    put_children(C, T, true, lv, le, lf, 0, tet_at, oct_at, ntk, nok, n);
}

static inline __attribute__((always_inline)) void
put_child(sd_topo *C, const tcell *c, bool oct, bool ids, const uint32_t *lv, const uint32_t *le,
          const uint32_t *lf, unsigned pmask, uint32_t at)
{
    if (ids && oct)
        put_oct_ids(C, c, le, lf, at);
    else if (ids)
        put_tet_ids(C, c, le, lf, at);
    else if (oct)
        put_oct(C, c, lv, pmask, at);
    else
        put_tet(C, c, lv, pmask, at);
}

/* Boundary mask of a child cell: face k lies on the solids' boundary iff it is a child of a
 * parent face that does (bit RA of the parent's mask); faces inside the parent never do. */
static uint8_t child_mask(const tcell *c, unsigned pmask)
{
    unsigned m = 0;
    for (int k = 0; k < (c->kind == 4 ? 4 : 8); k++)
        if (RT(c->f[k]) == R_FCHILD)
            m |= (pmask >> RA(c->f[k]) & 1u) << k;
    return (uint8_t)m;
}

/* The slots of the per-parent tables the split reads (vertex_table, edge_face_tables): edges [2
 * halves per parent edge, in the template's end order | 3 per parent face, at its template
 * vertices in order | inside the cell]; faces [4 per parent face: at its template vertices in
 * order, middle | inside the cell]. */
static int vslot(const uint8_t *fv, int s) { return fv[0] == s ? 0 : fv[1] == s ? 1 : 2; }

static uint8_t edge_slot(const tmpl *T, uint16_t r)
{
    switch (RT(r)) {
    case R_HALF: return (uint8_t)(2 * RA(r) + (T->pe[RA(r)][0] == RB(r) ? 0 : 1));
    case R_FINT: return (uint8_t)(2 * T->ne + 3 * RA(r) + vslot(T->pf[RA(r)], RB(r)));
    default: return (uint8_t)(2 * T->ne + 3 * T->nfc + RA(r));
    }
}

static uint8_t face_slot(const tmpl *T, uint16_t r)
{
    if (RT(r) == R_CINT)
        return (uint8_t)(4 * T->nfc + RA(r));
    return (uint8_t)(4 * RA(r) + (RB(r) == MIDDLE ? 3 : vslot(T->pf[RA(r)], RB(r))));
}

static void slots(tmpl *T)
{
    for (int i = 0; i < T->ncell; i++) {
        tcell *c = &T->cell[i];
        for (int k = 0; k < (c->kind == 4 ? 6 : 12); k++)
            c->es[k] = edge_slot(T, c->e[k]);
        for (int k = 0; k < (c->kind == 4 ? 4 : 8); k++)
            c->fs[k] = face_slot(T, c->f[k]);
        for (unsigned m = 0; m < (T->nfc == 4 ? 16u : 256u); m++)
            c->bmask[m] = child_mask(c, m);
    }
    for (int i = 0; i < T->nif; i++)
        for (int j = 0; j < 3; j++)
            T->iface[i].es[j] = edge_slot(T, T->iface[i].e[j]);
}

/* Whether template T has the shape the emitters are written for: ntk tetrahedra and nok
 * octahedra (the octahedra first for a parent octahedron), nif faces inside. */
static __attribute__((unused)) bool shape(const tmpl *T, int ntk, int nok, int n, int ne, int nif)
{
    bool ok = T->ncell == ntk + nok && T->n == n && T->ne == ne && T->nif == nif;
    for (int i = 0; ok && i < T->ncell; i++)
        ok = T->cell[i].kind == (n == 6 ? (i < nok ? 6 : 4) : (i < ntk ? 4 : 6));
    return ok;
}

static void templates(tmpl tt[3], tmpl *to)
{
    for (int d = 0; d < 3; d++) {
        tm_tet(&tt[d], d);
        slots(&tt[d]);
        assert(shape(&tt[d], TET_KIDS));
    }
    tm_oct(to);
    slots(to);
    assert(shape(to, OCT_KIDS));
}

/* Children of parent tetrahedron t: tets 4t..4t+3, octahedron t; of parent octahedron o: tets
 * 4 ntet + 8o.., octahedra ntet + 6o.. (the order emit_* produce them in). */
#define TET_CTX(P, t) {P, P->tet[t], P->tet_e[t], P->tet_f ? P->tet_f[t] : NULL, 0, 0, 4 * P->nf + 4 * (t)}
#define OCT_CTX(P, o)                                                                              \
    {P, P->oct[o], P->oct_e[o], P->oct_f ? P->oct_f[o] : NULL, P->nv + P->ne + (o),                \
     2 * P->ne + 3 * P->nf + 12 * (o), 4 * P->nf + 4 * P->ntet + 24 * (o)}

/* A split's loops run in parts (par.c): each part takes its share of every loop below and
 * writes only the children of its own parent entities, so they may be cut into chunks taken in
 * turn (sdi_par_dyn). */
typedef struct sjob {
    const sd_topo *P;
    sd_topo *C;
    tmpl tt[3], to;
    bool alias;
} sjob;

#define RANGE(n, i0, i1)                                                                           \
    uint64_t i0##_, i1##_;                                                                         \
    sdi_range((n), part, nparts, &i0##_, &i1##_);                                                   \
    const uint32_t i0 = (uint32_t)i0##_, i1 = (uint32_t)i1##_

static uint64_t split_work(const sd_topo *P)
{
    return (uint64_t)P->nv + P->ne + P->nf + 8ull * P->ntet + 14ull * P->noct;
}

static void cells_part(void *arg, uint32_t part, uint32_t nparts)
{
    const sjob *J = arg;
    const sd_topo *P = J->P;
    sd_topo *C = J->C;
    const uint32_t pnv = P->nv, pne = P->ne;
    {   /* vertices: classes */
        RANGE(pnv, v0, v1);
        memcpy(C->vfam + v0, P->vfam + v0, v1 - v0);
        memcpy(C->vflag + v0, P->vflag + v0, v1 - v0);
        memcpy(C->vnm + v0, P->vnm + v0, v1 - v0);
    }
    {   /* (the arrays in locals: a byte store could alias C's and P's fields) */
        RANGE(pne, e0, e1);
        uint8_t *vfam = C->vfam + pnv, *vflag = C->vflag + pnv, *vnm = C->vnm + pnv;
        const uint8_t *efam = P->efam, *eflag = P->eflag, *enm = P->enm;
        for (uint32_t e = e0; e < e1; e++) {
            vfam[e] = efam[e];
            uint8_t pf = eflag[e];
            vflag[e] = ((pf & EF_DC) ? VF_DC : 0) | ((pf & EF_CREASE) ? VF_SCREASE : 0) |
                       ((pf & EF_SSURF) ? VF_SSURF : 0) | ((pf & EF_SBND) ? VF_SBND : 0);
            uint8_t pt = (uint8_t)nm_type(enm[e]);
            vnm[e] = (uint8_t)((pt == 1 ? 1 : pt ? 4 : 0) | (enm[e] & (NM_OV | NM_G1)));
        }
    }
    {
        RANGE(P->noct, o0, o1);
        memset(C->vfam + pnv + pne + o0, FAM3, o1 - o0);
        memset(C->vflag + pnv + pne + o0, 0, o1 - o0);
        memset(C->vnm + pnv + pne + o0, 0, o1 - o0);
    }
    {
        RANGE(P->ntr, i0, i1);
#ifdef __SSE2__
        /* a level's cells are read again by the next split; past the caches only where they
         * would not stay in them anyway */
        const bool stream = (uint64_t)P->ntr * 48 >= STREAM_MIN;
#endif
        for (uint32_t i = i0; i < i1; i++) { /* the children of face f, as fv[4f..4f+3] below */
            uint32_t f = sdi_tr(P, i);
            const uint32_t *x = P->fv[f], *fe = P->fe[f];
            uint32_t(*c)[3] = C->trv + 4 * (size_t)i;
#ifdef __SSE2__
            if (stream && ((uintptr_t)c & 15) == 0) { /* 48 bytes written past the caches */
                const uint32_t m0 = pnv + fe[0], m1 = pnv + fe[1], m2 = pnv + fe[2];
                __m128i *q = (__m128i *)c;
                _mm_stream_si128(q, _mm_set_epi32((int)x[1], (int)m2, (int)m0, (int)x[0]));
                _mm_stream_si128(q + 1, _mm_set_epi32((int)m2, (int)x[2], (int)m0, (int)m1));
                _mm_stream_si128(q + 2, _mm_set_epi32((int)m2, (int)m1, (int)m0, (int)m1));
                continue;
            }
#endif
            for (int j = 0; j < 3; j++) {
                int jp = (j + 2) % 3;
                c[j][0] = x[j];
                c[j][1] = pnv + fe[j];
                c[j][2] = pnv + fe[jp];
                c[3][j] = pnv + fe[j];
            }
        }
#ifdef __SSE2__
        if (stream)
            _mm_sfence(); /* the streamed stores seen before the region ends */
#endif
    }
    {   /* solid cells */
        RANGE(P->ntet, t0, t1);
        for (uint32_t t = t0; t < t1; t++) {
            ctx x = TET_CTX(P, t);
            emit_cells(C, &x, &J->tt[P->tet_d[t] % 3], P->tet_b[t], 4 * t, t, TET_KIDS);
        }
    }
    {
        RANGE(P->noct, o0, o1);
        for (uint32_t o = o0; o < o1; o++) {
            ctx x = OCT_CTX(P, o);
            emit_cells(C, &x, &J->to, P->oct_b[o], 4 * P->ntet + 8 * o, P->ntet + 6 * o, OCT_KIDS);
        }
    }
}

sd_result sdi_split_cells(sd_mem *m, const sd_topo *P, sd_topo *C, int threads, sd_error *err)
{
    uint64_t nv = (uint64_t)P->nv + P->ne + P->noct;
    uint64_t ne = 2ull * P->ne + 3ull * P->nf + 12ull * P->noct;
    uint64_t nf = 4ull * P->nf + 4ull * P->ntet + 24ull * P->noct;
    uint64_t ntet = 4ull * P->ntet + 8ull * P->noct, noct = (uint64_t)P->ntet + 6ull * P->noct;
    if (nv >= UINT32_MAX || ne >= UINT32_MAX || nf >= UINT32_MAX || ntet >= UINT32_MAX ||
        noct >= UINT32_MAX || 4ull * P->ntr >= UINT32_MAX)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1,
                       "the next level would exceed 32-bit ids (%llu edges, %llu faces)",
                       (unsigned long long)ne, (unsigned long long)nf);
    memset(C, 0, sizeof *C);
    C->nv = (uint32_t)nv;
    C->ne = (uint32_t)ne;
    C->nf = (uint32_t)nf;
    C->npt = P->npt;
    C->ncu = 2 * P->ncu;
    C->ntr = 4 * P->ntr;
    C->ntet = (uint32_t)ntet;
    C->noct = (uint32_t)noct;
    C->tr_ident = P->tr_ident && C->nf == C->ntr;
    C->ovmask = P->ovmask;
#define A(f, n) (C->f = sdi_alloc(m, ((size_t)(n) + 1) * sizeof *C->f))
    if (!A(pt, C->npt) || !A(cuv, C->ncu) || !A(trv, C->ntr) || !A(tet, ntet) ||
        !A(tet_d, ntet) || !A(tet_b, ntet) || !A(oct, noct) || !A(oct_b, noct) ||
        !A(vfam, nv) || !A(vflag, nv) || !A(vnm, nv)) {
        sdi_topo_free(m, C);
        return sdi_fail_nomem(err, m);
    }
#undef A
    /* lower-dimensional cells: few */
    memcpy(C->pt, P->pt, (size_t)P->npt * sizeof *C->pt);
    for (uint32_t i = 0; i < P->ncu; i++) {
        uint32_t e = P->cu[i];
        C->cuv[2 * i][0] = P->ev[e][0];
        C->cuv[2 * i][1] = P->nv + e;
        C->cuv[2 * i + 1][0] = P->nv + e;
        C->cuv[2 * i + 1][1] = P->ev[e][1];
    }
    sjob J = {.P = P, .C = C};
    if (P->ntet || P->noct)
        templates(J.tt, &J.to);
    sdi_par_dyn(threads, split_work(P), 4, cells_part, &J);
    return SD_OK;
}

static void edges_part(void *arg, uint32_t part, uint32_t nparts)
{
    const sjob *J = arg;
    const sd_topo *P = J->P;
    sd_topo *C = J->C;
    const uint32_t pnv = P->nv, pne = P->ne, pnf = P->nf;
    /* (the arrays in locals: a byte store could alias C's and P's fields) */
    uint32_t(*cev)[2] = C->ev;
    uint8_t *cefam = C->efam, *ceflag = C->eflag, *cenm = C->enm;
    {   /* halves */
        RANGE(pne, e0, e1);
        const uint32_t(*pev)[2] = P->ev;
        const uint8_t *efam = P->efam, *eflag = P->eflag, *enm = P->enm;
        for (uint32_t e = e0; e < e1; e++) {
            uint32_t mid = pnv + e;
            cev[2 * e][0] = pev[e][0];
            cev[2 * e][1] = mid;
            cev[2 * e + 1][0] = mid;
            cev[2 * e + 1][1] = pev[e][1];
            for (int k = 0; k < 2; k++) {
                cefam[2 * e + k] = efam[e];
                ceflag[2 * e + k] = eflag[e];
                cenm[2 * e + k] = enm[e];
            }
        }
    }
    {   /* inside faces: cutting the corners */
        RANGE(pnf, f0, f1);
        const uint32_t(*pfe)[3] = P->fe;
        const uint8_t *fflag = P->fflag, *fn3 = P->fn3;
        for (uint32_t f = f0; f < f1; f++) {
            const uint32_t *fe = pfe[f];
            uint8_t fam = (fflag[f] & FF_MAX) ? FAM2 : FAM3;
            uint8_t flag = ((fflag[f] & FF_BND3) ? EF_DC : 0) |
                           ((fflag[f] & FF_SING) ? EF_SSURF : 0) | /* inside an embedded surface */
                           ((fflag[f] & FF_N2SEL) ? EF_N2SEL : 0); /* ... a chosen triangle */
            uint8_t nm = fn3[f] >= 3 ? 4 : 0;
            for (int j = 0; j < 3; j++) {
                uint32_t e = 2 * pne + 3 * f + j;
                cev[e][0] = pnv + fe[(j + 2) % 3];
                cev[e][1] = pnv + fe[j];
                cefam[e] = fam;
                ceflag[e] = flag;
                cenm[e] = nm;
            }
        }
    }
    {   /* inside octahedra: cell point to each edge point */
        RANGE(P->noct, o0, o1);
        for (uint32_t o = o0; o < o1; o++)
            for (int k = 0; k < 12; k++) {
                uint32_t e = 2 * pne + 3 * pnf + 12 * o + k;
                C->ev[e][0] = pnv + pne + o;
                C->ev[e][1] = pnv + P->oct_e[o][k];
                C->efam[e] = FAM3;
                C->eflag[e] = 0;
                C->enm[e] = 0;
            }
    }
}

sd_result sdi_split_edges(sd_mem *m, const sd_topo *P, sd_topo *C, int threads, sd_error *err)
{
    const uint32_t ne = C->ne;
#define A(f, n) (C->f = sdi_alloc(m, ((size_t)(n) + 1) * sizeof *C->f))
    if (!A(ev, ne) || !A(efam, ne) || !A(eflag, ne) || !A(enm, ne)) {
        sdi_topo_free_edges(m, C);
        return sdi_fail_nomem(err, m);
    }
#undef A
    sjob J = {.P = P, .C = C};
    sdi_par_dyn(threads, split_work(P), 4, edges_part, &J);
    C->derived = true;
    return SD_OK;
}

static void faces_part(void *arg, uint32_t part, uint32_t nparts)
{
    const sjob *J = arg;
    const sd_topo *P = J->P;
    sd_topo *C = J->C;
    const bool alias = J->alias;
    const uint32_t pnv = P->nv, pne = P->ne;
    {   /* the 4 children of each face */
        RANGE(P->nf, f0, f1);
        for (uint32_t f = f0; f < f1; f++) {
            const uint32_t *x = P->fv[f], *fe = P->fe[f];
            for (int j = 0; j < 3; j++) {
                uint32_t e = 2 * pne + 3 * f + j;
                uint32_t jp = (uint32_t)(j + 2) % 3;
                uint32_t g = 4 * f + j;
                if (!alias) {
                    C->fv[g][0] = x[j];
                    C->fv[g][1] = pnv + fe[j];
                    C->fv[g][2] = pnv + fe[jp];
                }
                C->fe[g][0] = half(P, fe[j], x[j]);
                C->fe[g][1] = e;
                C->fe[g][2] = half(P, fe[jp], x[j]);
            }
            uint32_t g = 4 * f + 3;
            for (int j = 0; j < 3; j++) {
                if (!alias)
                    C->fv[g][j] = pnv + fe[j];
                C->fe[g][j] = 2 * pne + 3 * f + (uint32_t)(j + 1) % 3;
            }
            for (int j = 0; j < 4; j++) {
                C->fn3[4 * f + j] = P->fn3[f];
                C->fflag[4 * f + j] = P->fflag[f];
            }
        }
    }
    if (C->tr) {
        RANGE(P->ntr, i0, i1);
        for (uint32_t i = i0; i < i1; i++)
            for (uint32_t j = 0; j < 4; j++)
                C->tr[4 * i + j] = 4 * sdi_tr(P, i) + j;
    }
    {   /* solid cells */
        RANGE(P->ntet, t0, t1);
        for (uint32_t t = t0; t < t1; t++) {
            ctx x = TET_CTX(P, t);
            emit_ids(C, &x, &J->tt[P->tet_d[t] % 3], 4 * t, t, TET_KIDS);
        }
    }
    {
        RANGE(P->noct, o0, o1);
        for (uint32_t o = o0; o < o1; o++) {
            ctx x = OCT_CTX(P, o);
            emit_ids(C, &x, &J->to, 4 * P->ntet + 8 * o, P->ntet + 6 * o, OCT_KIDS);
        }
    }
}

sd_result sdi_split_faces(sd_mem *m, const sd_topo *P, sd_topo *C, int threads, sd_error *err)
{
    const uint32_t nf = C->nf, ntet = C->ntet, noct = C->noct;
    /* a pure surface whose face i is triangle i: the faces' vertices are the triangles' */
    bool alias = C->tr_ident && C->trv;
#define A(f, n) (C->f = sdi_alloc(m, ((size_t)(n) + 1) * sizeof *C->f))
    if ((alias ? !(C->fv = C->trv) : !A(fv, nf)) || !A(fe, nf) || !A(cu, C->ncu) ||
        (!C->tr_ident && !A(tr, C->ntr)) || !A(tet_e, ntet) || !A(tet_f, ntet) ||
        !A(oct_e, noct) || !A(oct_f, noct) || !A(fn3, nf) || !A(fflag, nf)) {
        sdi_topo_free_faces(m, C);
        return sdi_fail_nomem(err, m);
    }
#undef A
    for (uint32_t i = 0; i < P->ncu; i++) { /* curves as edge ids: few */
        C->cu[2 * i] = 2 * P->cu[i];
        C->cu[2 * i + 1] = 2 * P->cu[i] + 1;
    }
    sjob J = {.P = P, .C = C, .alias = alias};
    if (P->ntet || P->noct)
        templates(J.tt, &J.to);
    sdi_par_dyn(threads, split_work(P), 4, faces_part, &J);
    C->faces = true;
    return SD_OK;
}
