/* complex.c — the control complex: validation of the input and construction of level 0.
 *
 * Input is Algorithm 1's minimum (000 Sec. 5.1): vertices and maximal simplices of any dimension.
 * Validation is its own pass and runs before anything is built, so a refused complex costs no
 * more than the check: every coordinate finite and of sane magnitude; every simplex 1..4
 * vertices, indices in range, no vertex twice, no simplex listed twice, no (near-)zero length,
 * area or volume. Errors name the simplex (`item`) and the slot (`field`).
 *
 * Construction derives all faces (000 Algorithm 2): unique edges and triangles via a hash, each
 * tetrahedron's edge and face ids, and which listed simplices are really maximal — a listed
 * simplex that is a face of another listed one is absorbed. Tetrahedra are reoriented to positive
 * volume (slots 2 and 3 swapped) so that every later cell is positively oriented too — or as the
 * caller says (sd_options.reoriented: a complex saved after edits that turned tetrahedra inside
 * out is rebuilt with its stored orientation, hence the same numbering of every level).
 *
 * The complex object lives here too: sd_complex_new (options checked, level 0 built, the default
 * non-manifold rules applied) and sd_complex_free, and what changes the whole complex or asks
 * about it without computing levels: diagonals, channels, the sizes of any level from the split
 * table (sd_complex_counts, so callers can enforce limits before allocating), the memory in use
 * and the estimate of what levels not computed yet would add. A change that invalidates levels
 * drops them (levels.c); they are recomputed on demand.
 */
#include "hash.h"
#include <math.h>
#include <string.h>

#define SD_MAX_COORD 1e15
#define SD_DEGENERATE_TOL 1e-12

static int map_pair(int pair, bool swapped);

const uint8_t SDI_TET_E[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
const uint8_t SDI_TET_F[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
const uint8_t SDI_OCT_E[12][2] = {{0, 2}, {0, 4}, {0, 3}, {0, 5}, {1, 2}, {1, 4},
                                 {1, 3}, {1, 5}, {2, 4}, {4, 3}, {3, 5}, {5, 2}};
const uint8_t SDI_OCT_F[8][3] = {{0, 2, 4}, {0, 4, 3}, {0, 3, 5}, {0, 5, 2},
                                {1, 4, 2}, {1, 3, 4}, {1, 5, 3}, {1, 2, 5}};

static void sub3(double *o, const double *a, const double *b)
{
    o[0] = a[0] - b[0];
    o[1] = a[1] - b[1];
    o[2] = a[2] - b[2];
}
static void cross3(double *o, const double *a, const double *b)
{
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}
static double dot3(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* Signed 6x volume of a tetrahedron. */
static double tet_vol6(const double *xyz, const uint32_t *t)
{
    double a[3], b[3], d[3], n[3];
    sub3(a, xyz + 3 * (size_t)t[1], xyz + 3 * (size_t)t[0]);
    sub3(b, xyz + 3 * (size_t)t[2], xyz + 3 * (size_t)t[0]);
    sub3(d, xyz + 3 * (size_t)t[3], xyz + 3 * (size_t)t[0]);
    cross3(n, a, b);
    return dot3(n, d);
}

/* Is simplex `s` (n vertices) degenerate? Longest edge L: an edge shorter than tol*bbox, a
 * triangle of area < tol*L^2, a tetrahedron of volume < tol*L^3 are (orientation does not
 * matter). The one test of input and edits (core/edit.c). */
int sdi_simplex_degenerate(const double *xyz, const uint32_t *s, int n, double diag)
{
    if (n < 2)
        return 0;
    double lmax = 0;
    for (int i = 0; i < n; i++)
        for (int j = i + 1; j < n; j++) {
            double d[3];
            sub3(d, xyz + 3 * (size_t)s[i], xyz + 3 * (size_t)s[j]);
            double l = sqrt(dot3(d, d));
            if (l <= SD_DEGENERATE_TOL * diag)
                return SDI_SHORT_EDGE;
            if (l > lmax)
                lmax = l;
        }
    if (n == 3) {
        double a[3], b[3], c[3];
        sub3(a, xyz + 3 * (size_t)s[1], xyz + 3 * (size_t)s[0]);
        sub3(b, xyz + 3 * (size_t)s[2], xyz + 3 * (size_t)s[0]);
        cross3(c, a, b);
        return 0.5 * sqrt(dot3(c, c)) <= SD_DEGENERATE_TOL * lmax * lmax ? SDI_FLAT : 0;
    }
    if (n == 4)
        return fabs(tet_vol6(xyz, s)) / 6 <= SD_DEGENERATE_TOL * lmax * lmax * lmax ? SDI_FLAT : 0;
    return 0;
}

const char *sdi_degenerate_why(int code, int n)
{
    if (code == SDI_SHORT_EDGE)
        return n == 2 ? "zero or near-zero length: below 1e-12 of the bounding box's diagonal"
                      : "an edge of zero or near-zero length: below 1e-12 of the bounding box's "
                        "diagonal";
    return n == 3 ? "zero or near-zero area" : "zero or near-zero volume";
}

static const char *const kind_name[] = {"", "point", "edge", "triangle", "tetrahedron"};

/* The validation pass: nothing is allocated but the duplicate hash. With `why` (ns bytes), the
 * refusals a repair drops are recorded instead (why[s] = SD_ERR_REPEATED, SD_ERR_DEGENERATE or
 * SD_ERR_DUPLICATE, of[s] = the earlier kept simplex a duplicate repeats; SD_OK kept) and only
 * the others fail: the same order of checks either way, so what one refuses the other names. */
static sd_result validate(sd_mem *m, const double *xyz, uint32_t nv, const uint32_t *idx,
                          const uint8_t *size, uint32_t ns, uint8_t *why, uint32_t *of,
                          sd_error *err)
{
    if (nv == 0)
        return sdi_fail(err, SD_ERR_EMPTY, -1, -1, "the complex has no vertices");
    if (ns == 0)
        return sdi_fail(err, SD_ERR_EMPTY, -1, -1, "the complex has no simplices");
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t v = 0; v < nv; v++)
        for (int k = 0; k < 3; k++) {
            double x = xyz[3 * (size_t)v + k];
            if (!isfinite(x))
                return sdi_fail(err, SD_ERR_VALUE, v, k, "vertex %u: coordinate %d is not finite", v, k);
            if (fabs(x) > SD_MAX_COORD) {
                char t[32];
                return sdi_fail(err, SD_ERR_VALUE, v, k,
                               "vertex %u: coordinate %d = %s exceeds the allowed magnitude %g", v, k,
                               sd_shortest(x, t), SD_MAX_COORD);
            }
            lo[k] = fmin(lo[k], x);
            hi[k] = fmax(hi[k], x);
        }
    double d[3];
    sub3(d, hi, lo);
    double diag = sqrt(dot3(d, d));

    size_t off = 0;
    for (uint32_t s = 0; s < ns; s++) {
        int n = size[s];
        if (n < 1 || n > 4)
            return sdi_fail(err, SD_ERR_ARITY, s, -1,
                           "simplex %u has %d vertices; a simplex has 1 to 4 (point, edge, "
                           "triangle, tetrahedron)", s, n);
        const uint32_t *t = idx + off;
        sd_result bad = SD_OK;
        for (int i = 0; i < n; i++) {
            if (t[i] >= nv)
                return sdi_fail(err, SD_ERR_INDEX, s, i,
                               "simplex %u: vertex index %u out of range (%u vertices)", s, t[i], nv);
            for (int j = 0; j < i && !bad; j++)
                if (t[j] == t[i]) {
                    if (!why)
                        return sdi_fail(err, SD_ERR_REPEATED, s, i,
                                       "simplex %u: vertex %u appears twice", s, t[i]);
                    bad = SD_ERR_REPEATED;
                }
        }
        int flat = bad ? 0 : sdi_simplex_degenerate(xyz, t, n, diag);
        if (flat) {
            if (!why)
                return sdi_fail(err, SD_ERR_DEGENERATE, s, -1, "simplex %u: degenerate %s (%s)", s,
                               kind_name[n], sdi_degenerate_why(flat, n));
            bad = SD_ERR_DEGENERATE;
        }
        if (why)
            why[s] = (uint8_t)bad;
        off += n;
    }

    sd_hash h;
    if (!sdi_hash_init(m, &h, ns))
        return sdi_fail_nomem(err, m);
    off = 0;
    for (uint32_t s = 0; s < ns; off += size[s++]) {
        if (why && why[s])
            continue;
        uint32_t k[4];
        sdi_key(k, idx + off, size[s]);
        uint32_t prev = sdi_hash_get_or_put(&h, k, s);
        if (prev != UINT32_MAX && why) {
            why[s] = SD_ERR_DUPLICATE;
            if (of)
                of[s] = prev;
        } else if (prev != UINT32_MAX) {
            sdi_hash_free(m, &h);
            return sdi_fail(err, SD_ERR_DUPLICATE, s, -1,
                           "simplex %u repeats simplex %u (same vertices)", s, prev);
        }
    }
    sdi_hash_free(m, &h);
    return SD_OK;
}

sd_result sd_complex_check(const double *xyz, size_t nv, const uint32_t *idx, const uint8_t *size,
                           size_t ns, const sd_allocator *a, uint8_t *why, uint32_t *of,
                           sd_error *err)
{
    if (!why || nv > UINT32_MAX || ns > UINT32_MAX)
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "sd_complex_check: no `why`, or over 2^32 items");
    sd_mem m;
    sdi_mem_init(&m, a, 0);
    return validate(&m, xyz, (uint32_t)nv, idx, size, (uint32_t)ns, why, of, err);
}

static uint32_t edge_id(sd_ehash *h, sd_topo *t, uint32_t a, uint32_t b)
{
    uint32_t e = sdi_ehash_get_or_put(h, a, b, t->ne);
    if (e != UINT32_MAX)
        return e;
    t->ev[t->ne][0] = a;
    t->ev[t->ne][1] = b;
    return t->ne++;
}

/* Face id of triangle (a,b,c); *isnew tells whether it was created now. */
static uint32_t face_id(sd_hash *h, sd_topo *t, const uint32_t v[3], bool *isnew)
{
    uint32_t k[4];
    sdi_key(k, v, 3);
    uint32_t f = sdi_hash_get_or_put(h, k, t->nf);
    *isnew = f == UINT32_MAX;
    if (!*isnew)
        return f;
    memcpy(t->fv[t->nf], v, 3 * sizeof *v);
    return t->nf++;
}

/* The tetrahedron's edge (index into SDI_TET_E) between its vertices x and y. */
static int tet_edge(int x, int y)
{
    int k = 0;
    while (!((SDI_TET_E[k][0] == x && SDI_TET_E[k][1] == y) ||
             (SDI_TET_E[k][0] == y && SDI_TET_E[k][1] == x)))
        k++;
    return k;
}

/* The input's simplices into level 0 (arrays allocated for them): tetrahedra first, so that
 * faces of tets are known before triangles are looked at, then triangles, curve segments and
 * points, each absorbed when it is a face of one before. A face's edge ids (fe[f][j], the edge
 * from fv[f][j] to fv[f][j + 1]) are set when the face is made. used: per vertex, scratch
 * (zeroed). */
static void add_simplices(sd_complex *c, sd_topo *t, sd_ehash *he, sd_hash *hf, const double *xyz,
                          const uint32_t *idx, const uint8_t *size, uint32_t ns, uint8_t *used)
{
    size_t off = 0;
    /* pass 1: tetrahedra */
    for (uint32_t s = 0; s < ns; s++) {
        c->in_tet[s] = UINT32_MAX;
        if (size[s] == 4) {
            uint32_t *q = t->tet[t->ntet];
            memcpy(q, idx + off, 4 * sizeof *q);
            if (c->opt.reoriented ? c->opt.reoriented[s] != 0 : tet_vol6(xyz, q) < 0) {
                uint32_t tmp = q[2];
                q[2] = q[3];
                q[3] = tmp;
                c->tet_swapped[t->ntet] = 1;
            }
            for (int k = 0; k < 6; k++)
                t->tet_e[t->ntet][k] = edge_id(he, t, q[SDI_TET_E[k][0]], q[SDI_TET_E[k][1]]);
            for (int i = 0; i < 4; i++) {
                uint32_t fv[3] = {q[SDI_TET_F[i][0]], q[SDI_TET_F[i][1]], q[SDI_TET_F[i][2]]};
                bool isnew;
                uint32_t f = face_id(hf, t, fv, &isnew);
                t->tet_f[t->ntet][i] = f;
                for (int j = 0; isnew && j < 3; j++)
                    t->fe[f][j] = t->tet_e[t->ntet][tet_edge(SDI_TET_F[i][j], SDI_TET_F[i][(j + 1) % 3])];
                if (t->fn3[f] < 255)
                    t->fn3[f]++;
            }
            for (int i = 0; i < 4; i++)
                used[q[i]] = 1;
            c->in_src[SD_CELL_TETRA][t->ntet] = s;
            c->in_tet[s] = t->ntet++;
        }
        off += size[s];
    }
    /* pass 2: triangles; a triangle that is a tet face is absorbed */
    off = 0;
    for (uint32_t s = 0; s < ns; s++) {
        if (size[s] == 3) {
            const uint32_t *q = idx + off;
            bool isnew;
            uint32_t f = face_id(hf, t, q, &isnew);
            if (isnew) {
                t->fflag[f] |= FF_MAX;
                c->in_src[SD_CELL_TRIANGLE][t->ntr] = s;
                t->tr[t->ntr++] = f;
                for (int k = 0; k < 3; k++)
                    t->fe[f][k] = edge_id(he, t, q[k], q[(k + 1) % 3]);
                for (int i = 0; i < 3; i++)
                    used[q[i]] = 1;
            }
        }
        off += size[s];
    }
    /* pass 3: curve segments; one that is an edge of a triangle or tet is absorbed */
    off = 0;
    for (uint32_t s = 0; s < ns; s++) {
        if (size[s] == 2) {
            const uint32_t *q = idx + off;
            uint32_t before = t->ne;
            uint32_t e = edge_id(he, t, q[0], q[1]);
            if (e == before) {
                c->in_src[SD_CELL_CURVE][t->ncu] = s;
                t->cu[t->ncu++] = e;
                used[q[0]] = used[q[1]] = 1;
            }
        }
        off += size[s];
    }
    /* pass 4: isolated points; a vertex of anything else is absorbed */
    off = 0;
    for (uint32_t s = 0; s < ns; s++) {
        if (size[s] == 1 && !used[idx[off]]) {
            used[idx[off]] = 2;
            c->in_src[SD_CELL_POINT][t->npt] = s;
            t->pt[t->npt++] = idx[off];
        }
        off += size[s];
    }
}

sd_result sdi_level0_build(sd_complex *c, const double *xyz, uint32_t nv, const uint32_t *idx,
                          const uint8_t *size, uint32_t ns, sd_error *err)
{
    sd_mem *m = &c->mem;
    sd_result r = validate(m, xyz, nv, idx, size, ns, NULL, NULL, err);
    if (r)
        return r;

    size_t count[5] = {0};
    for (uint32_t s = 0; s < ns; s++)
        count[size[s]]++;
    size_t emax = 6 * count[4] + 3 * count[3] + count[2];
    size_t fmax = 4 * count[4] + count[3];
    if (emax >= UINT32_MAX || fmax >= UINT32_MAX)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1, "too many simplices for 32-bit ids");

    sd_level *lv = sdi_calloc(m, 1, sizeof *lv);
    if (!lv)
        return sdi_fail_nomem(err, m);
    sd_topo *t = &lv->t;
    sd_ehash he = {0};
    sd_hash hf = {0};
    uint8_t *used = NULL;
    t->nv = nv;
    t->ev = sdi_alloc(m, (emax ? emax : 1) * sizeof *t->ev);
    t->fv = sdi_alloc(m, (fmax ? fmax : 1) * sizeof *t->fv);
    t->fe = sdi_alloc(m, (fmax ? fmax : 1) * sizeof *t->fe);
    t->fflag = sdi_calloc(m, fmax ? fmax : 1, 1);
    t->fn3 = sdi_calloc(m, fmax ? fmax : 1, 1);
    t->pt = sdi_alloc(m, (count[1] + 1) * sizeof *t->pt);
    t->cu = sdi_alloc(m, (count[2] + 1) * sizeof *t->cu);
    t->tr = sdi_alloc(m, (count[3] + 1) * sizeof *t->tr);
    t->tet = sdi_alloc(m, (count[4] + 1) * sizeof *t->tet);
    t->tet_e = sdi_alloc(m, (count[4] + 1) * sizeof *t->tet_e);
    t->tet_f = sdi_alloc(m, (count[4] + 1) * sizeof *t->tet_f);
    t->tet_d = sdi_calloc(m, count[4] + 1, 1);
    t->tet_b = sdi_calloc(m, count[4] + 1, 1);
    c->in_tet = sdi_alloc(m, (size_t)ns * sizeof *c->in_tet);
    c->in_src[SD_CELL_TETRA] = sdi_alloc(m, ((size_t)ns + 1) * sizeof *c->in_tet);
    if (c->in_src[SD_CELL_TETRA]) { /* kinds in the order of add_simplices, each its count */
        c->in_src[SD_CELL_TRIANGLE] = c->in_src[SD_CELL_TETRA] + count[4];
        c->in_src[SD_CELL_CURVE] = c->in_src[SD_CELL_TRIANGLE] + count[3];
        c->in_src[SD_CELL_POINT] = c->in_src[SD_CELL_CURVE] + count[2];
    }
    c->tet_swapped = sdi_calloc(m, count[4] + 1, 1);
    used = sdi_calloc(m, nv, 1);
    if (!t->ev || !t->fv || !t->fe || !t->fflag || !t->fn3 || !t->pt || !t->cu || !t->tr ||
        !t->tet || !t->tet_e || !t->tet_f || !t->tet_d || !t->tet_b || !c->in_tet || !c->in_src[SD_CELL_TETRA] || !c->tet_swapped ||
        !used || !sdi_ehash_init(m, &he, emax) || !sdi_hash_init(m, &hf, fmax))
        goto nomem;
    c->nin = ns;

    add_simplices(c, t, &he, &hf, xyz, idx, size, ns, used);
    sdi_ehash_free(m, &he);
    sdi_hash_free(m, &hf);
    sdi_free(m, used);
    used = NULL;

    /* channel 0: positions */
    lv->nch = 1;
    lv->ch[0].ncomp = 3;
    lv->ch[0].data = sdi_alloc(m, (size_t)nv * 3 * sizeof(double));
    if (!lv->ch[0].data)
        goto nomem;
    memcpy(lv->ch[0].data, xyz, (size_t)nv * 3 * sizeof(double));

    lv->cx = c;
    t->derived = t->faces = true;
    t->tr_ident = t->nf == t->ntr;
    for (uint32_t i = 0; i < t->ntr && t->tr_ident; i++)
        t->tr_ident = t->tr[i] == i;
    c->lv[0] = lv;
    c->nlevels = 1;
    sdi_rels R = {.t = t};
    r = sdi_classify_level0(m, t, &R, err);
    if (!r && c->opt.classes) /* classes computed elsewhere (subdivd-mpi's whole complex) */
        r = sdi_take_classes(m, t, &R, c->opt.classes, err);
    int8_t *fixed = NULL; /* the caller's pairs (sd_options.diagonals), in stored order */
    if (!r && c->opt.diagonals && t->ntet) {
        if (!(fixed = sdi_alloc(m, t->ntet)))
            r = sdi_fail_nomem(err, m);
        for (uint32_t q = 0; fixed && q < t->ntet; q++) {
            int8_t d = c->opt.diagonals[c->in_src[SD_CELL_TETRA][q]];
            fixed[q] = d >= 0 && d <= 2 ? (int8_t)map_pair(d, c->tet_swapped[q]) : -1;
        }
    }
    if (!r)
        r = sdi_choose_diagonals(m, t, &R, fixed, err);
    sdi_free(m, fixed);
    sdi_rels_free(m, &R);
    if (r) {
        c->lv[0] = NULL;
        c->nlevels = 0;
        sdi_level_free(m, lv);
        return r;
    }
    for (uint32_t q = 0; q < t->ntet; q++) /* the solids' boundary faces, as later levels inherit */
        for (int i = 0; i < 4; i++)
            if (t->fflag[t->tet_f[q][i]] & FF_BND3)
                t->tet_b[q] |= (uint8_t)(1u << i);
    return SD_OK;

nomem:
    sdi_ehash_free(m, &he);
    sdi_hash_free(m, &hf);
    sdi_free(m, used);
    sdi_level_free(m, lv);
    return sdi_fail_nomem(err, m);
}

//END

/* ---- the complex's lifecycle and whole-complex queries ---------------------------------- */

/* The options' enumerations: each is 0 (the default) or 1. */
static sd_result check_options(const sd_options *o, sd_error *err)
{
    const struct {
        const char *name;
        int value;
    } f[] = {{"surface_weights", o->surface_weights},         /* SD_WEIGHTS_* */
             {"nonmanifold_default", o->nonmanifold_default}, /* SD_NM_* */
             {"nonmanifold_surface", o->nonmanifold_surface}, /* SD_NMSURF_* */
             {"solid_scheme", o->solid_scheme},               /* SD_SOLID_* */
             {"edit_index", o->edit_index}};                  /* SD_EDIT_INDEX_* */
    for (size_t i = 0; i < sizeof f / sizeof *f; i++)
        if (f[i].value != 0 && f[i].value != 1)
            return sdi_fail(err, SD_ERR_ARG, -1, -1, "unknown %s %d", f[i].name, f[i].value);
    return SD_OK;
}

sd_complex *sd_complex_new(const double *xyz, size_t nv, const uint32_t *idx, const uint8_t *size,
                           size_t ns, const sd_options *opt, sd_error *err)
{
    sd_options o = {0};
    if (opt)
        o = *opt;
    if (err)
        memset(err, 0, sizeof *err);
    if (check_options(&o, err))
        return NULL;
    if (nv >= UINT32_MAX || ns >= UINT32_MAX) {
        sdi_fail(err, SD_ERR_LIMIT, -1, -1, "too many vertices or simplices for 32-bit ids");
        return NULL;
    }
    if ((nv && !xyz) || (ns && (!idx || !size))) {
        sdi_fail(err, SD_ERR_ARG, -1, -1, "missing input array");
        return NULL;
    }
    sd_mem mem;
    sdi_mem_init(&mem, &o.allocator, o.max_bytes);
    sd_complex *c = sdi_alloc(&mem, sizeof *c);
    if (!c) {
        sdi_fail_nomem(err, &mem);
        return NULL;
    }
    memset(c, 0, sizeof *c);
    c->mem = mem;
    c->opt = o;
    sd_result built = sdi_level0_build(c, xyz, (uint32_t)nv, idx, size, (uint32_t)ns, err);
    c->opt.reoriented = NULL; /* the caller's arrays: not kept */
    c->opt.diagonals = NULL;
    c->opt.classes = NULL;
    if (built) {
        sd_complex_free(c);
        return NULL;
    }
    if (o.nonmanifold_default == SD_NM_G1 || o.nonmanifold_surface == SD_NMSURF_YING_ZORIN) {
        sdi_rels R = {.t = &c->lv[0]->t};
        sd_result r = sdi_apply_singular(c, &R, err);
        sdi_rels_free(&c->mem, &R);
        if (r) {
            sd_complex_free(c);
            return NULL;
        }
    }
    return c;
}

void sd_complex_free(sd_complex *c)
{
    if (!c)
        return;
    sdi_drop_levels(c, 0);
    sdi_det_drop(c, 0);
    sdi_free(&c->mem, c->tag_at);
    sdi_free(&c->mem, c->tag_k);
    sdi_free(&c->mem, c->ov);
    sdi_free(&c->mem, c->pet);
    sdi_free(&c->mem, c->tt);
    sdi_free(&c->mem, c->tt_f);
    sdi_sharp_free(&c->mem, &c->sh);
    sdi_free(&c->mem, c->in_tet);
    sdi_free(&c->mem, c->in_src[SD_CELL_TETRA]);
    sdi_free(&c->mem, c->tet_swapped);
    sd_mem m = c->mem;
    sdi_free(&m, c);
}

/* Map a pair index in the input's vertex order to the stored (possibly reoriented) order:
 * swapping slots 2 and 3 exchanges pairs 1 (02|13) and 2 (03|12). */
static int map_pair(int pair, bool swapped) { return swapped && pair ? 3 - pair : pair; }

sd_result sd_complex_set_diagonal(sd_complex *c, size_t simplex, int pair, sd_error *err)
{
    if (simplex >= c->nin || c->in_tet[simplex] == UINT32_MAX)
        return sdi_fail(err, SD_ERR_ARG, (long)simplex, -1, "simplex %zu is not a tetrahedron", simplex);
    if (pair < 0 || pair > 2)
        return sdi_fail(err, SD_ERR_ARG, (long)simplex, -1, "diagonal pair must be 0, 1 or 2");
    uint32_t t = c->in_tet[simplex];
    sdi_drop_levels(c, 1);
    sd_level *l0 = c->lv[0]; /* level 0's stencils do not depend on diagonals: kept */
    uint8_t d = (uint8_t)map_pair(pair, c->tet_swapped[t]);
    /* the octahedra of level 1 split along the new diagonal: the points of levels 1 and 2 keep
     * their numbers (vertex, edge and cell points of coarser entities that do not depend on it),
     * those of levels 3 and finer do not, so their offsets would name other points */
    if (l0->t.tet_d[t] != d)
        sdi_det_drop(c, 3);
    l0->t.tet_d[t] = d;
    return SD_OK;
}

int sd_complex_diagonal(const sd_complex *c, size_t simplex)
{
    if (simplex >= c->nin || c->in_tet[simplex] == UINT32_MAX)
        return -1;
    uint32_t t = c->in_tet[simplex];
    return map_pair(c->lv[0]->t.tet_d[t], c->tet_swapped[t]);
}

void sd_complex_class_codes(const sd_complex *c, uint16_t *vertex, uint16_t *edge, uint16_t *face)
{
    sdi_class_codes(&c->lv[0]->t, vertex, edge, face);
}

int sd_complex_reoriented(const sd_complex *c, size_t simplex)
{
    if (simplex >= c->nin || c->in_tet[simplex] == UINT32_MAX)
        return -1;
    return c->tet_swapped[c->in_tet[simplex]] != 0;
}

int sd_complex_add_channel(sd_complex *c, const double *data, int ncomp, sd_error *err)
{
    sd_level *l0 = c->lv[0];
    if (ncomp < 1 || ncomp > 16) {
        sdi_fail(err, SD_ERR_ARG, -1, -1, "a channel has 1 to 16 components, not %d", ncomp);
        return -1;
    }
    if (l0->nch >= SD_MAX_CHANNELS) {
        sdi_fail(err, SD_ERR_LIMIT, -1, -1, "at most %d channels", SD_MAX_CHANNELS - 1);
        return -1;
    }
    size_t n = (size_t)l0->t.nv * ncomp;
    for (size_t i = 0; i < n; i++)
        if (!isfinite(data[i])) {
            sdi_fail(err, SD_ERR_VALUE, (long)(i / ncomp), (int)(i % ncomp),
                    "vertex %zu: channel value %zu is not finite", i / ncomp, i % ncomp);
            return -1;
        }
    double *copy = sdi_alloc(&c->mem, n * sizeof *copy);
    if (!copy) {
        sdi_fail_nomem(err, &c->mem);
        return -1;
    }
    memcpy(copy, data, n * sizeof *copy);
    sdi_drop_levels(c, 1);
    l0->ch[l0->nch].ncomp = ncomp;
    l0->ch[l0->nch].data = copy;
    return l0->nch++;
}

void sd_complex_counts(const sd_complex *c, int level, sd_counts *o)
{
    const sd_topo *t = &c->lv[0]->t;
    uint64_t V = t->nv, E = t->ne, F = t->nf, P = t->npt, Cu = t->ncu, Tr = t->ntr, T = t->ntet, O = t->noct;
    for (int l = 0; l < level; l++) {
        uint64_t V2 = V + E + O, E2 = 2 * E + 3 * F + 12 * O, F2 = 4 * F + 4 * T + 24 * O;
        uint64_t T2 = 4 * T + 8 * O, O2 = T + 6 * O;
        V = V2, E = E2, F = F2, T = T2, O = O2, Cu *= 2, Tr *= 4;
    }
    o->vertices = V, o->edges = E, o->faces = F, o->points = P, o->curves = Cu;
    o->triangles = Tr, o->tetrahedra = T, o->octahedra = O;
}

size_t sd_complex_memory(const sd_complex *c) { return c->mem.used; }

/* Bytes a computed level adds, per entity of that level, as measured (sd_complex_memory before
 * and after computing each level of solids, surfaces, curves and mixed complexes, with the
 * level's vertex rules prepared; tests/core/test_carry.c keeps them within 30%, they fit within
 * 13%). A vertex: its positions (24) and classes, and its row of S_{l-1} with the parent level's
 * rules; an edge: its share of the parent level's edges and edge rules and of the level's own
 * classification; a surface triangle and an octahedron: their cells and their rows; a
 * tetrahedron costs nothing beyond its vertices and edges at that count; a level its fixed
 * part. Every channel besides the positions adds 8 bytes per component and vertex. The faces a
 * computation makes and drops again are not counted (they are gone once it returns). */
#define EST_VERTEX 38
#define EST_EDGE 13
#define EST_TRIANGLE 9
#define EST_OCT 64
#define EST_LEVEL 1280

uint64_t sd_complex_estimate_level_bytes(const sd_complex *c, int level)
{
    if (level < 1)
        return 0;
    const sd_level *l0 = c->lv[0];
    uint64_t comps = 0;
    for (int ch = 1; ch < l0->nch; ch++)
        comps += (uint64_t)l0->ch[ch].ncomp;
    sd_counts n;
    sd_complex_counts(c, level, &n);
    return n.vertices * (EST_VERTEX + 8 * comps) + n.edges * EST_EDGE + n.triangles * EST_TRIANGLE +
           n.octahedra * EST_OCT + EST_LEVEL;
}

uint64_t sd_complex_estimate_bytes(const sd_complex *c, int level)
{
    uint64_t total = 0;
    for (int l = sd_complex_levels_computed(c); l <= level; l++)
        total += sd_complex_estimate_level_bytes(c, l);
    return total;
}
int sd_complex_levels_computed(const sd_complex *c) { return c->nlevels; }

void sd_complex_set_threads(sd_complex *c, int threads) { c->opt.threads = threads; }
