/* Red-green refinement (000 Sec. 4.2): random selections on a tetrahedral block stay conforming
 * (no simplex keeps an edge that was split — no hanging vertex), the volume and the boundary
 * area are unchanged (no gap, no overlap), untouched tetrahedra are kept as they were, and the
 * triangle and segment patterns work on a mixed complex. */
#include "test.h"

static uint64_t rs = 99;
static uint32_t rnd(uint32_t n)
{
    rs = rs * 6364136223846793005ull + 1442695040888963407ull;
    return (uint32_t)((rs >> 33) % n);
}

static double tet_vol(const double *x, const uint32_t *t)
{
    const double *a = x + 3 * t[0], *b = x + 3 * t[1], *c = x + 3 * t[2], *d = x + 3 * t[3];
    double u[3], v[3], w[3];
    for (int k = 0; k < 3; k++) {
        u[k] = b[k] - a[k];
        v[k] = c[k] - a[k];
        w[k] = d[k] - a[k];
    }
    return fabs(u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
                u[2] * (v[0] * w[1] - v[1] * w[0])) / 6;
}

static double tri_area(const double *x, uint32_t a, uint32_t b, uint32_t c)
{
    double u[3], v[3];
    for (int k = 0; k < 3; k++) {
        u[k] = x[3 * b + k] - x[3 * a + k];
        v[k] = x[3 * c + k] - x[3 * a + k];
    }
    double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    return 0.5 * sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

static int cmp3(const void *x, const void *y) { return memcmp(x, y, 3 * sizeof(uint32_t)); }
static int cmpu(const void *x, const void *y)
{
    uint32_t a = *(const uint32_t *)x, b = *(const uint32_t *)y;
    return (a > b) - (a < b);
}

/* Volume and the area of faces used by exactly one tetrahedron. */
static void measure(const double *x, const uint32_t *idx, const uint8_t *sz, size_t ns, double *vol,
                    double *area)
{
    size_t nt = 0;
    for (size_t s = 0; s < ns; s++)
        nt += sz[s] == 4;
    uint32_t (*f)[3] = malloc(4 * nt * sizeof *f + 1);
    size_t nf = 0, off = 0;
    *vol = 0;
    for (size_t s = 0; s < ns; off += sz[s++]) {
        if (sz[s] != 4)
            continue;
        *vol += tet_vol(x, idx + off);
        for (int i = 0; i < 4; i++) {
            int j = 0;
            for (int k = 0; k < 4; k++)
                if (k != i)
                    f[nf][j++] = idx[off + k];
            qsort(f[nf], 3, sizeof(uint32_t), cmpu);
            nf++;
        }
    }
    qsort(f, nf, sizeof *f, cmp3);
    *area = 0;
    for (size_t i = 0; i < nf;) {
        size_t j = i;
        while (j < nf && !memcmp(f[i], f[j], sizeof *f))
            j++;
        if (j - i == 1)
            *area += tri_area(x, f[i][0], f[i][1], f[i][2]);
        i = j;
    }
    free(f);
}

TEST(refine_random_selections_conform)
{
    mesh m = {0};
    shape_cube_tets(&m, 3);
    double vol0, area0;
    measure(m.xyz, m.idx, m.sz, m.ns, &vol0, &area0);
    uint8_t *marked = calloc(m.ns, 1);
    for (int round = 0; round < 200; round++) {
        memset(marked, 0, m.ns);
        int k = 1 + (int)rnd(8);
        for (int i = 0; i < k; i++)
            marked[rnd((uint32_t)m.ns)] = 1;
        sd_refinement r;
        CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, NULL, &r, NULL) == SD_OK);
        CHECK(r.red >= (uint64_t)1 && r.nv == m.nv + r.nsplit);
        /* no simplex uses an edge that was split */
        size_t off = 0;
        for (size_t s = 0; s < r.ns; off += r.size[s++])
            for (int a = 0; a < r.size[s]; a++)
                for (int b = a + 1; b < r.size[s]; b++) {
                    uint32_t x = r.idx[off + a], y = r.idx[off + b];
                    for (size_t q = 0; q < r.nsplit; q++)
                        CHECK(!((r.split[q][0] == x && r.split[q][1] == y) ||
                                (r.split[q][0] == y && r.split[q][1] == x)));
                }
        double vol, area;
        measure(r.xyz, r.idx, r.size, r.ns, &vol, &area);
        CHECK_NEAR(vol, vol0, 1e-12);
        CHECK_NEAR(area, area0, 1e-12);
        /* the result is a valid complex (no duplicate or degenerate simplex) */
        sd_complex *c = sd_complex_new(r.xyz, r.nv, r.idx, r.size, r.ns, NULL, NULL);
        CHECK(c && sd_complex_level(c, 1, NULL));
        sd_complex_free(c);
        /* untouched tetrahedra (no split edge) are kept verbatim */
        size_t kept = 0;
        off = 0;
        for (size_t s = 0; s < m.ns; off += m.sz[s++]) {
            size_t o2 = 0;
            for (size_t t = 0; t < r.ns; o2 += r.size[t++])
                if (r.size[t] == 4 && !memcmp(r.idx + o2, m.idx + off, 4 * sizeof(uint32_t))) {
                    kept++;
                    break;
                }
        }
        CHECK(kept + r.red + r.green == m.ns);
        sd_refine_free(&r);
    }
    free(marked);
    mesh_free(&m);
}

TEST(refine_mixed_patterns)
{
    /* a tet, a fin on its edge 1-2, a curve from vertex 3: marking the tet splits the fin's
     * shared edge (green fin) and nothing else; marking the curve splits only it */
    mesh m = {0};
    shape_mixed(&m);
    uint8_t marked[16] = {0};
    marked[0] = 1; /* the tetrahedron */
    sd_refinement r;
    CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, NULL, &r, NULL) == SD_OK);
    CHECK(r.nsplit == 6 && r.red == 1 && r.green == 1);
    size_t tets = 0, tris = 0;
    for (size_t s = 0; s < r.ns; s++) {
        tets += r.size[s] == 4;
        tris += r.size[s] == 3;
    }
    CHECK(tets == 8 && tris == 2);
    sd_refine_free(&r);
    memset(marked, 0, sizeof marked);
    for (size_t s = 0; s < m.ns; s++)
        marked[s] = m.sz[s] == 2;
    CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, NULL, &r, NULL) == SD_OK);
    size_t segs = 0;
    for (size_t s = 0; s < r.ns; s++)
        segs += r.size[s] == 2;
    CHECK(segs == 4 && r.nsplit == 2);
    sd_refine_free(&r);
    mesh_free(&m);
}

/* An allocator that counts its live bytes and refuses past `cap` (0: never). */
typedef struct counted {
    size_t live, peak, cap;
} counted;
static void *counted_alloc(size_t n, void *ud)
{
    counted *c = ud;
    if (c->cap && c->live + n > c->cap)
        return NULL;
    c->live += n;
    c->peak = c->live > c->peak ? c->live : c->peak;
    return malloc(n);
}
static void counted_release(void *p, size_t n, void *ud)
{
    ((counted *)ud)->live -= n;
    free(p);
}

TEST(refine_limits_before_the_result)
{
    /* a red tetrahedron makes 8 and 6 new vertices; a marked cube of 5 tetrahedra its children
     * and its neighbours' greens: the limits at the exact counts pass with the same result, one
     * below fails with SD_ERR_LIMIT naming what and how many; the working arrays come from the
     * allocator given, all of them given back */
    mesh m = {0};
    shape_cube_tets(&m, 3);
    uint8_t *marked = calloc(m.ns, 1);
    marked[0] = marked[m.ns / 2] = 1;
    sd_refinement a, b;
    CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, NULL, &a, NULL) == SD_OK);
    CHECK(a.ns > m.ns + 14 && a.nv >= m.nv + 12);
    counted cnt = {0};
    sd_allocator al = {counted_alloc, counted_release, &cnt};
    sd_refine_limits lim = {a.nv, a.ns, &al};
    CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, &lim, &b, NULL) == SD_OK);
    CHECK(b.ns == a.ns && b.nv == a.nv && !memcmp(a.idx, b.idx, sizeof *a.idx * 4 * a.ns) &&
          !memcmp(a.size, b.size, a.ns));
    CHECK(cnt.live == 0 && cnt.peak >= 6 * m.ns * sizeof(uint32_t));
    sd_refine_free(&b);
    sd_error e = {0};
    lim.max_simplices = a.ns - 1;
    CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, &lim, &b, &e) == SD_ERR_LIMIT);
    CHECK(e.field == 1 && e.item == (long)a.ns && !b.idx && !b.xyz && cnt.live == 0);
    lim.max_simplices = a.ns;
    lim.max_vertices = a.nv - 1;
    CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, &lim, &b, &e) == SD_ERR_LIMIT);
    CHECK(e.field == 0 && e.item == (long)a.nv && !b.idx && cnt.live == 0);
    /* every simplex marked: its red children alone pass the limit, found before any work */
    memset(marked, 1, m.ns);
    lim.max_vertices = 0;
    lim.max_simplices = 8 * m.ns - 1;
    cnt.peak = 0;
    CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, &lim, &b, &e) == SD_ERR_LIMIT);
    CHECK(e.field == 1 && e.item == (long)(8 * m.ns) && cnt.peak == 0);
    /* the allocator's refusal of the working arrays */
    lim.max_simplices = 0;
    cnt.cap = 1024;
    CHECK(sd_refine(m.xyz, m.nv, m.idx, m.sz, m.ns, marked, NULL, &lim, &b, &e) == SD_ERR_NOMEM);
    CHECK(cnt.live == 0 && !b.idx);
    sd_refine_free(&a);
    free(marked);
    mesh_free(&m);
}
