/* refine.c — local red-green refinement of a control complex (000 Sec. 4.2, 002).
 *
 * Marked simplices are split red (segment -> 2, triangle -> 4, tetrahedron -> 4 corner tets + its
 * octahedron cut into 4 tets along the tetrahedron's diagonal: pair k of SDI_TET_E's edges
 * (e_k, e_(5-k)) gives the axis joining their midpoints, pair 0 — 01 and 23 — when none is
 * given). The
 * closure then makes the result conforming, deciding every simplex by the set of its edges that
 * are split (shared edges are split for all their simplices at once, so faces always match):
 *   triangle: none -> kept; one -> green (2 triangles); three -> red; two -> upgraded to red;
 *   tetrahedron: none -> kept; one -> Green-I (2 tets); the three edges of one face ->
 *     Green-III (that face split in 4, coned to the opposite vertex); six -> red; any other set
 *     -> upgraded to red;
 *   segment: split when its edge is.
 * Upgrades split more edges, so the closure repeats until nothing changes (it ends: edges only
 * ever become split). A face then has 0, 1 or 3 split edges and both its cells cut it the same
 * way: no hanging vertex. Untouched simplices keep their place and vertex order; new vertices
 * (one per split edge, placed at the midpoint — the caller may move them) follow the old ones.
 */
#include "hash.h"
#include <assert.h>
#include <stdlib.h>
#include <string.h>

static const uint8_t TRI_E[3][2] = {{0, 1}, {1, 2}, {2, 0}};
/* SDI_TET_E order: 01 02 03 12 13 23 */
static const uint8_t TE[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
/* the three edges of the face opposite vertex i, as indices into TE */
static const uint8_t FACE_EDGES[4][3] = {{3, 4, 5}, {1, 2, 5}, {0, 2, 4}, {0, 1, 3}};

typedef struct ref {
    sd_mem *m;
    sd_hash h;
    uint32_t ne;
    uint8_t *split;       /* per edge */
    uint32_t *mid;        /* per edge: new vertex id */
    uint32_t *eids;       /* per simplex slot: edge ids (6 per simplex) */
} ref;

static uint32_t edge_of(ref *r, uint32_t a, uint32_t b)
{
    uint32_t ab[2] = {a, b}, k[4];
    sdi_key(k, ab, 2);
    uint32_t got = sdi_hash_get_or_put(&r->h, k, r->ne);
    return got == UINT32_MAX ? r->ne++ : got;
}

void sd_refine_free(sd_refinement *o)
{
    if (!o)
        return;
    free(o->xyz);
    free(o->idx);
    free(o->size);
    free(o->parent);
    free(o->split);
    memset(o, 0, sizeof *o);
}

static int tet_pattern(const uint8_t *s, int *face)
{
    int n = 0;
    for (int i = 0; i < 6; i++)
        n += s[i];
    if (n == 0 || n == 1 || n == 6)
        return n;
    if (n == 3)
        for (int f = 0; f < 4; f++)
            if (s[FACE_EDGES[f][0]] && s[FACE_EDGES[f][1]] && s[FACE_EDGES[f][2]]) {
                *face = f;
                return 3;
            }
    return -1; /* no green pattern: red */
}

static const int NEDGES[5] = {0, 0, 1, 3, 6};

/* The edge ids of every simplex (6 slots each), in r->eids. */
static void edge_ids(ref *r, const uint32_t *idx, const uint8_t *size, size_t ns)
{
    for (size_t s = 0, off = 0; s < ns; off += size[s++]) {
        const uint32_t *v = idx + off;
        int k = size[s];
        if (k == 2)
            r->eids[6 * s] = edge_of(r, v[0], v[1]);
        else if (k == 3)
            for (int e = 0; e < 3; e++)
                r->eids[6 * s + e] = edge_of(r, v[TRI_E[e][0]], v[TRI_E[e][1]]);
        else if (k == 4)
            for (int e = 0; e < 6; e++)
                r->eids[6 * s + e] = edge_of(r, v[TE[e][0]], v[TE[e][1]]);
    }
}

/* The marked simplices red with all their edges split, then the closure: upgrade to red every
 * triangle or tetrahedron whose split edges fit no green pattern, until nothing changes. */
static void closure(ref *r, const uint8_t *size, size_t ns, const uint8_t *marked, uint8_t *red)
{
    for (size_t s = 0; s < ns; s++)
        if (marked[s] && size[s] >= 2) {
            red[s] = 1;
            for (int e = 0; e < NEDGES[size[s]]; e++)
                r->split[r->eids[6 * s + e]] = 1;
        }
    for (bool changed = true; changed;) {
        changed = false;
        for (size_t s = 0; s < ns; s++) {
            int k = size[s], n = 0, face;
            if (k < 3 || red[s])
                continue;
            uint8_t st[6];
            for (int e = 0; e < NEDGES[k]; e++)
                n += st[e] = r->split[r->eids[6 * s + e]];
            bool upgrade = k == 3 ? n == 2 || n == 3 : tet_pattern(st, &face) < 0 || n == 6;
            if (upgrade) {
                red[s] = 1;
                for (int e = 0; e < NEDGES[k]; e++)
                    if (!r->split[r->eids[6 * s + e]]) {
                        r->split[r->eids[6 * s + e]] = 1;
                        changed = true;
                    }
            }
        }
    }
}

/* The number of children of every simplex after the closure, and of their vertex ids (as
 * emit_children makes them). */
static void count_children(const ref *r, const uint8_t *size, size_t ns, size_t *nout, size_t *nids)
{
    size_t c = 0, ids = 0;
    for (size_t s = 0; s < ns; s++) {
        int k = size[s], n = 0, face = -1, kids = 1;
        uint8_t st[6] = {0};
        for (int e = 0; k >= 2 && e < NEDGES[k]; e++)
            n += st[e] = r->split[r->eids[6 * s + e]];
        if (n && k == 2)
            kids = 2;
        else if (n && k == 3)
            kids = n == 1 ? 2 : 4;
        else if (n && k == 4)
            kids = tet_pattern(st, &face) == 1 ? 2 : n == 3 && face >= 0 ? 4 : 8;
        c += (size_t)kids;
        ids += (size_t)kids * (size_t)k;
    }
    *nout = c;
    *nids = ids;
}

/* The new vertices' ids, one per split edge after the old ones (r->mid); returns their number. */
static uint32_t number_splits(ref *r, size_t nv)
{
    uint32_t nsplit = 0;
    for (uint32_t e = 0; e < r->ne; e++)
        if (r->split[e])
            r->mid[e] = (uint32_t)nv + nsplit++;
    return nsplit;
}

/* The nsplit new vertices at their edges' midpoints; out's arrays allocated for nout children
 * of nids vertex ids in all. false: no memory. */
static bool new_vertices(ref *r, const double *xyz, size_t nv, uint32_t nsplit, size_t nout,
                         size_t nids, sd_refinement *out)
{
    out->nv = nv + nsplit;
    out->xyz = malloc(out->nv * 3 * sizeof *out->xyz);
    out->split = malloc(((size_t)nsplit + 1) * sizeof *out->split);
    out->idx = malloc((nids + 1) * sizeof *out->idx);
    out->size = malloc(nout + 1);
    out->parent = malloc((nout + 1) * sizeof *out->parent);
    if (!out->xyz || !out->split || !out->idx || !out->size || !out->parent)
        return false;
    memcpy(out->xyz, xyz, nv * 3 * sizeof *xyz);
    for (size_t i = 0; i < r->h.cap; i++) { /* every split edge: its ends and midpoint */
        uint32_t e = r->h.val[i];
        if (r->h.key[i][0] == UINT32_MAX || !r->split[e])
            continue;
        uint32_t a = r->h.key[i][0], b = r->h.key[i][1], m = r->mid[e];
        out->split[m - nv][0] = a;
        out->split[m - nv][1] = b;
        for (int q = 0; q < 3; q++)
            out->xyz[3 * (size_t)m + q] = 0.5 * (xyz[3 * (size_t)a + q] + xyz[3 * (size_t)b + q]);
    }
    out->nsplit = nsplit;
    return true;
}

/* Appending the new simplices of one input simplex. */
typedef struct emitter {
    sd_refinement *out;
    size_t oi;
    uint32_t parent;
} emitter;

static void put(emitter *E, int n, const uint32_t *v)
{
    sd_refinement *o = E->out;
    memcpy(o->idx + E->oi, v, n * sizeof *v);
    E->oi += n;
    o->parent[o->ns] = E->parent;
    o->size[o->ns++] = (uint8_t)n;
}
#define EMIT(n, ...) put(E, (n), (const uint32_t[]){__VA_ARGS__})

/* A triangle with n split edges (st): green (one) or red. */
static void split_triangle(emitter *E, const uint32_t *v, const uint32_t *M, const uint8_t *st, int n)
{
    if (n == 1) {
        int e = st[0] ? 0 : st[1] ? 1 : 2;
        uint32_t a = v[TRI_E[e][0]], b = v[TRI_E[e][1]], c = v[3 - TRI_E[e][0] - TRI_E[e][1]];
        EMIT(3, a, M[e], c);
        EMIT(3, M[e], b, c);
        E->out->green++;
        return;
    }
    EMIT(3, v[0], M[0], M[2]);
    EMIT(3, M[0], v[1], M[1]);
    EMIT(3, M[2], M[1], v[2]);
    EMIT(3, M[0], M[1], M[2]);
    E->out->red++;
}

/* A tetrahedron with n split edges (st): Green-I, Green-III or red. */
static void split_tetra(emitter *E, const uint32_t *v, const uint32_t *M, const uint8_t *st, int n,
                        int pair)
{
    int face = -1;
    if (tet_pattern(st, &face) == 1) {
        int e = 0;
        while (!st[e])
            e++;
        uint32_t a = v[TE[e][0]], b = v[TE[e][1]], c = UINT32_MAX, d = UINT32_MAX;
        for (int i = 0; i < 4; i++)
            if (i != TE[e][0] && i != TE[e][1])
                *(c == UINT32_MAX ? &c : &d) = v[i];
        EMIT(4, a, M[e], c, d);
        EMIT(4, M[e], b, c, d);
        E->out->green++;
    } else if (n == 3) { /* Green-III: face opposite vertex `face` */
        uint32_t apex = v[face], f[3], fm[3];
        int j = 0;
        for (int i = 0; i < 4; i++)
            if (i != face)
                f[j++] = v[i];
        for (int i = 0; i < 3; i++) { /* the midpoint of f[i]-f[i+1] */
            uint32_t x = f[i], y = f[(i + 1) % 3];
            for (int e = 0; e < 6; e++)
                if ((v[TE[e][0]] == x && v[TE[e][1]] == y) || (v[TE[e][0]] == y && v[TE[e][1]] == x))
                    fm[i] = M[e];
        }
        EMIT(4, f[0], fm[0], fm[2], apex);
        EMIT(4, fm[0], f[1], fm[1], apex);
        EMIT(4, fm[2], fm[1], f[2], apex);
        EMIT(4, fm[0], fm[1], fm[2], apex);
        E->out->green++;
    } else { /* red: 4 corners + the octahedron around the diagonal's axis */
        uint32_t m01 = M[0], m02 = M[1], m03 = M[2], m12 = M[3], m13 = M[4], m23 = M[5];
        EMIT(4, v[0], m01, m02, m03);
        EMIT(4, m01, v[1], m12, m13);
        EMIT(4, m02, m12, v[2], m23);
        EMIT(4, m03, m13, m23, v[3]);
        /* the axis (midpoints of the pair's edges) and the equator around it, a cycle of the
         * other four (opposite midpoints are never neighbours on it) */
        static const uint8_t AX[3][2] = {{0, 5}, {1, 4}, {2, 3}};
        static const uint8_t EQ[3][4] = {{1, 2, 4, 3}, {0, 2, 5, 3}, {0, 1, 5, 4}};
        int k = pair >= 0 && pair < 3 ? pair : 0;
        for (int i = 0; i < 4; i++)
            EMIT(4, M[AX[k][0]], M[AX[k][1]], M[EQ[k][i]], M[EQ[k][(i + 1) % 4]]);
        E->out->red++;
    }
}

/* Every input simplex: kept as it is, or its children. */
static void emit_children(const ref *r, const uint32_t *idx, const uint8_t *size, size_t ns,
                          const uint8_t *red, const uint8_t *diag, sd_refinement *out)
{
    emitter E = {out, 0, 0};
    out->ns = 0;
    for (size_t s = 0, off = 0; s < ns; off += size[s++]) {
        const uint32_t *v = idx + off;
        int k = size[s], n = 0;
        uint32_t M[6]; /* the midpoints of the simplex's split edges */
        uint8_t st[6] = {0};
        for (int e = 0; k >= 2 && e < NEDGES[k]; e++) {
            n += st[e] = r->split[r->eids[6 * s + e]];
            M[e] = st[e] ? r->mid[r->eids[6 * s + e]] : UINT32_MAX;
        }
        E.parent = (uint32_t)s;
        if (n == 0) {
            put(&E, k, v);
        } else if (k == 2) {
            put(&E, 2, (const uint32_t[]){v[0], M[0]});
            put(&E, 2, (const uint32_t[]){M[0], v[1]});
            out->red += red[s];
            out->green += !red[s];
        } else if (k == 3) {
            split_triangle(&E, v, M, st, n);
        } else {
            split_tetra(&E, v, M, st, n, diag ? diag[s] : 0);
        }
    }
}
#undef EMIT

sd_result sd_refine(const double *xyz, size_t nv, const uint32_t *idx, const uint8_t *size,
                    size_t ns, const uint8_t *marked, const uint8_t *diag,
                    const sd_refine_limits *lim, sd_refinement *out, sd_error *err)
{
    memset(out, 0, sizeof *out);
    sd_mem mem;
    sdi_mem_init(&mem, lim ? lim->allocator : NULL, 0);
    ref r = {.m = &mem};
    sd_result rc = SD_OK;
    size_t least = 0; /* simplices at least: a marked one's red children, one for the others */
    for (size_t s = 0; s < ns; s++) {
        if (size[s] < 1 || size[s] > 4)
            return sdi_fail(err, SD_ERR_ARITY, (long)s, -1, "simplex %zu has %d vertices", s, size[s]);
        static const uint8_t RED[5] = {1, 1, 2, 4, 8};
        least += marked[s] ? RED[size[s]] : 1;
    }
    if (lim && lim->max_simplices && least > lim->max_simplices) /* before any work */
        return sdi_fail(err, SD_ERR_LIMIT, (long)least, 1, "the refined complex would have at "
                        "least %zu simplices (at most %zu)", least, lim->max_simplices);
    if (!sdi_hash_init(&mem, &r.h, 6 * ns + 16))
        return sdi_fail_nomem(err, &mem);
    r.eids = sdi_alloc(&mem, (6 * ns + 1) * sizeof *r.eids);
    r.split = sdi_calloc(&mem, 6 * ns + 1, 1);
    r.mid = sdi_alloc(&mem, (6 * ns + 1) * sizeof *r.mid);
    uint8_t *red = sdi_calloc(&mem, ns + 1, 1);
    size_t nout, nids, nsplit;
    if (!r.eids || !r.split || !r.mid || !red) {
        rc = sdi_fail_nomem(err, &mem);
        goto done;
    }
    edge_ids(&r, idx, size, ns);
    closure(&r, size, ns, marked, red);
    count_children(&r, size, ns, &nout, &nids);
    nsplit = number_splits(&r, nv);
    if (lim && lim->max_vertices && nv + nsplit > lim->max_vertices) {
        rc = sdi_fail(err, SD_ERR_LIMIT, (long)(nv + nsplit), 0, "the refined complex would have "
                      "%zu vertices (at most %zu)", nv + nsplit, lim->max_vertices);
        goto done;
    }
    if (lim && lim->max_simplices && nout > lim->max_simplices) {
        rc = sdi_fail(err, SD_ERR_LIMIT, (long)nout, 1, "the refined complex would have %zu "
                      "simplices (at most %zu)", nout, lim->max_simplices);
        goto done;
    }
    if (!new_vertices(&r, xyz, nv, (uint32_t)nsplit, nout, nids, out)) {
        rc = sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
        goto done;
    }
    emit_children(&r, idx, size, ns, red, diag, out);
    assert(out->ns == nout); /* count_children and emit_children agree: the arrays are exact */
done:
    sdi_free(&mem, r.eids);
    sdi_free(&mem, r.split);
    sdi_free(&mem, r.mid);
    sdi_free(&mem, red);
    sdi_hash_free(&mem, &r.h);
    if (rc)
        sd_refine_free(out);
    return rc;
}
