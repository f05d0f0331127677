/* test_yz.c — nonmanifold_surface = ying-zorin (003 Sec. 2): classes, stencil weights derived by
 * hand from 003's formulas, and invariants through levels. */
#include "test.h"
#include <stdbool.h>

static const sd_options YZ = {.surface_weights = SD_WEIGHTS_LOOP,
                              .nonmanifold_surface = SD_NMSURF_YING_ZORIN};

static void three_fins(mesh *m) { shape_three_fins(m); }

static uint8_t vrule(sd_complex *c, int L, uint32_t v)
{
    sd_class cl;
    sd_error err;
    return sd_complex_vertex_class(c, L, v, &cl, &err) ? 255 : cl.rule;
}

static uint8_t erule(sd_complex *c, int L, uint32_t a, uint32_t b)
{
    sd_class cl;
    sd_error err;
    const sd_level *lv = sd_complex_level(c, L, &err);
    uint32_t e = lv ? sd_level_find_edge(lv, a, b) : UINT32_MAX;
    return e == UINT32_MAX || sd_complex_edge_class(c, L, e, &cl, &err) ? 255 : cl.rule;
}

/* The weight of column `col` in row `row` of S_L (0 if absent). */
static double weight(sd_complex *c, int L, uint32_t row, uint32_t col)
{
    sd_csr S;
    sd_error err;
    if (sd_complex_matrix(c, L, &S, &err))
        return NAN;
    double w = 0;
    for (uint32_t k = S.rowptr[row]; k < S.rowptr[row + 1]; k++)
        if (S.col[k] == col)
            w += S.val[k];
    return w;
}

static uint32_t row_len(sd_complex *c, int L, uint32_t row)
{
    sd_csr S;
    sd_error err;
    return sd_complex_matrix(c, L, &S, &err) ? 0 : S.rowptr[row + 1] - S.rowptr[row];
}

TEST(yz_three_fins_classes)
{
    mesh m = {0};
    three_fins(&m);
    sd_error err;
    sd_complex *c = mesh_complex(&m, &YZ, &err);
    CHECK(c);
    /* spine ends: one flower but 2 + 3 singular edges -> complex -> corner; s1: simple */
    CHECK(vrule(c, 0, 0) == SD_RULE_YZ_CORNER);
    CHECK(vrule(c, 0, 2) == SD_RULE_YZ_CORNER);
    CHECK(vrule(c, 0, 1) == SD_RULE_YZ_CREASE);
    CHECK(erule(c, 0, 0, 1) == SD_RULE_YZ_CREASE);
    CHECK(erule(c, 0, 1, 2) == SD_RULE_YZ_CREASE);
    for (uint32_t f = 3; f < 12; f += 3) {
        CHECK(vrule(c, 0, f) == SD_RULE_LOOP_BOUNDARY);   /* plain boundary: the B-spline */
        CHECK(erule(c, 0, 1, f + 1) == SD_RULE_YZ_PETAL);
        CHECK(erule(c, 0, 0, f + 1) == SD_RULE_YZ_PETAL);
        CHECK(erule(c, 0, f, f + 1) == SD_RULE_LOOP_BOUNDARY);
    }
    /* level 1: the spine's new points are simple singular vertices, the ends stay corners */
    const sd_level *l1 = sd_complex_level(c, 1, &err);
    CHECK(l1);
    int crease = 0, corner = 0;
    for (uint32_t v = 0; v < sd_level_num_vertices(l1); v++) {
        uint8_t r = vrule(c, 1, v);
        crease += r == SD_RULE_YZ_CREASE;
        corner += r == SD_RULE_YZ_CORNER;
    }
    CHECK(crease == 3 && corner == 2);
    /* the same complex under chang-qin has none of these */
    sd_options cq = YZ;
    cq.nonmanifold_surface = SD_NMSURF_CHANG_QIN;
    sd_complex *d = mesh_complex(&m, &cq, &err);
    CHECK(d);
    CHECK(vrule(d, 0, 1) == SD_RULE_G2);
    sd_complex_free(d);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(yz_petal_weights)
{
    mesh m = {0};
    three_fins(&m);
    sd_error err;
    sd_complex *c = mesh_complex(&m, &YZ, &err);
    CHECK(c);
    const sd_level *l0 = sd_complex_level(c, 0, &err);
    CHECK(l0);
    uint32_t nv = sd_level_num_vertices(l0);
    /* s1: B-spline along the spine, 6/8 and 1/8 */
    CHECK_NEAR(weight(c, 0, 1, 1), 0.75, 1e-15);
    CHECK_NEAR(weight(c, 0, 1, 0), 0.125, 1e-15);
    CHECK_NEAR(weight(c, 0, 1, 2), 0.125, 1e-15);
    CHECK(row_len(c, 0, 1) == 3);
    /* spine ends fixed */
    CHECK(row_len(c, 0, 0) == 1 && weight(c, 0, 0, 0) == 1.0);
    for (uint32_t f = 3; f < 12; f += 3) {
        /* s1-f1, petal of k = 2 at the simple vertex s1: theta = pi/2, g = 1/2:
         * 1/4 s1 + 1/2 f1 + 1/8 (s0 + s2) (003 Fig. 4f) */
        uint32_t r = nv + sd_level_find_edge(l0, 1, f + 1);
        CHECK_NEAR(weight(c, 0, r, 1), 0.25, 1e-15);
        CHECK_NEAR(weight(c, 0, r, f + 1), 0.5, 1e-15);
        CHECK_NEAR(weight(c, 0, r, 0), 0.125, 1e-15);
        CHECK_NEAR(weight(c, 0, r, 2), 0.125, 1e-15);
        CHECK(row_len(c, 0, r) == 4);
        /* s0-f1 at the corner s0: petal {(s0,s1,f1), (s0,f1,f0)}, k = 2, alpha the angle
         * between s1 - s0 and f0 - s0; theta = alpha/2, g = 1/2 - cos(theta)/4 */
        const double *x = m.xyz;
        double u[3], w[3], uu = 0, ww = 0, uw = 0;
        for (int d = 0; d < 3; d++) {
            u[d] = x[3 + d] - x[d];
            w[d] = x[3 * f + d] - x[d];
            uu += u[d] * u[d];
            ww += w[d] * w[d];
            uw += u[d] * w[d];
        }
        double g = 0.5 - cos(acos(uw / sqrt(uu * ww)) / 2) / 4;
        r = nv + sd_level_find_edge(l0, 0, f + 1);
        CHECK_NEAR(weight(c, 0, r, 0), 0.75 - g, 1e-15);
        CHECK_NEAR(weight(c, 0, r, f + 1), g, 1e-15);
        CHECK_NEAR(weight(c, 0, r, 1), 0.125, 1e-15);
        CHECK_NEAR(weight(c, 0, r, f), 0.125, 1e-15);
        /* a boundary edge of the fin: midpoint */
        r = nv + sd_level_find_edge(l0, f, f + 1);
        CHECK_NEAR(weight(c, 0, r, f), 0.5, 1e-15);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

/* The cubic B-spline subdivision of an open polygon with fixed ends (docs/RULES.md `curve`). */
static int bspline_step(const double *p, int n, double *q)
{
    for (int i = 0; i < n; i++) {
        for (int d = 0; d < 3; d++) {
            double x = p[3 * i + d];
            q[6 * i + d] = i == 0 || i == n - 1 ? x
                           : (p[3 * (i - 1) + d] + 6 * x + p[3 * (i + 1) + d]) / 8;
            if (i + 1 < n)
                q[6 * i + 3 + d] = (x + p[3 * (i + 1) + d]) / 2;
        }
    }
    return 2 * n - 1;
}

TEST(yz_spine_stays_a_bspline)
{
    mesh m = {0};
    three_fins(&m);
    sd_error err;
    sd_complex *c = mesh_complex(&m, &YZ, &err);
    CHECK(c);
    enum { MAXN = 64 };
    uint32_t ids[MAXN], nids = 3;
    double poly[3 * MAXN], next[3 * MAXN];
    int n = 3;
    for (uint32_t i = 0; i < 3; i++) {
        ids[i] = i;
        memcpy(poly + 3 * i, m.xyz + 3 * i, 3 * sizeof *poly);
    }
    for (int L = 0; L < 4; L++) {
        const sd_level *lv = sd_complex_level(c, L, &err), *l1 = sd_complex_level(c, L + 1, &err);
        CHECK(lv && l1);
        /* children along the spine: vertex i's child and the edges' midpoints */
        uint32_t nid[MAXN], k = 0, nvL = sd_level_num_vertices(lv);
        for (uint32_t i = 0; i < nids; i++) {
            nid[k++] = ids[i];
            if (i + 1 < nids) {
                uint32_t e = sd_level_find_edge(lv, ids[i], ids[i + 1]);
                CHECK(e != UINT32_MAX);
                nid[k++] = nvL + e;
            }
        }
        for (uint32_t i = 0; i < k; i++) {
            uint32_t a, b;
            sd_origin_kind o = sd_level_origin(l1, nid[i], &a, &b);
            CHECK(i % 2 ? o == SD_ORIGIN_EDGE : o == SD_ORIGIN_VERTEX);
            CHECK(i % 2 || a == ids[i / 2]);
        }
        n = bspline_step(poly, n, next);
        memcpy(poly, next, 3 * (size_t)n * sizeof *poly);
        memcpy(ids, nid, k * sizeof *ids);
        nids = k;
        int nc;
        const double *x = sd_level_channel(l1, 0, &nc);
        for (uint32_t i = 0; i < nids; i++)
            for (int d = 0; d < 3; d++)
                CHECK_NEAR(x[3 * ids[i] + d], poly[3 * i + d], 1e-13);
        /* the complex singular vertices (the spine's ends) keep their positions */
        for (int d = 0; d < 3; d++) {
            CHECK(x[d] == m.xyz[d]);
            CHECK(x[6 + d] == m.xyz[6 + d]);
        }
        CHECK(vrule(c, L + 1, ids[1]) == SD_RULE_YZ_CREASE);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

/* Two closed surfaces touching at vertex 0: a tetrahedron's (ring 1 2 3) and a square pyramid
 * closed by two triangles (apex 0, ring 4 5 6 7). Vertex 0 has two flowers, each one closed
 * petal (k = 3 and k = 4): a complex vertex (corner) with fixed-disk petals. */
static void touching_closed_surfaces(mesh *m)
{
    mesh_v(m, 0, 0, 0);
    mesh_v(m, 1, 0, 0.8);
    mesh_v(m, -0.5, 0.9, 1);
    mesh_v(m, -0.4, -0.8, 1.1);
    mesh_v(m, 1, 0.1, -1);
    mesh_v(m, 0.1, 1, -1.1);
    mesh_v(m, -1, 0, -0.9);
    mesh_v(m, 0, -1, -1);
    mesh_s(m, 3, 0u, 1u, 2u);
    mesh_s(m, 3, 0u, 2u, 3u);
    mesh_s(m, 3, 0u, 3u, 1u);
    mesh_s(m, 3, 1u, 3u, 2u);
    for (uint32_t i = 0; i < 4; i++)
        mesh_s(m, 3, 0u, 4u + i, 4u + (i + 1) % 4);
    mesh_s(m, 3, 4u, 7u, 6u);
    mesh_s(m, 3, 4u, 6u, 5u);
}

TEST(yz_fixed_disk)
{
    mesh m = {0};
    touching_closed_surfaces(&m);
    sd_error err;
    sd_complex *c = mesh_complex(&m, &YZ, &err);
    CHECK(c);
    const sd_level *l0 = sd_complex_level(c, 0, &err);
    CHECK(l0);
    uint32_t nv = sd_level_num_vertices(l0);
    CHECK(vrule(c, 0, 0) == SD_RULE_YZ_CORNER);
    for (uint32_t v = 1; v < 8; v++) {
        CHECK(vrule(c, 0, v) == SD_RULE_LOOP);
        CHECK(erule(c, 0, 0, v) == SD_RULE_YZ_FIXED_DISK);
    }
    CHECK(erule(c, 0, 1, 2) == SD_RULE_LOOP);
    /* hand-derived from 003 (Loop, then p <- (1-s) p + s (a0 x0 + a1 x1 + a2 x2) with App. A's
     * eigenvectors), s = 3/4:
     *   k = 3 (lambda = 1/4): centre 27/32, p0 7/32, p1 = p2 = -1/32;
     *   k = 4 (lambda = 3/8): centre 27/32, p0 15/64, p1 = p3 = 1/32, p2 = -9/64. */
    uint32_t r = nv + sd_level_find_edge(l0, 0, 1);
    CHECK_NEAR(weight(c, 0, r, 0), 27.0 / 32, 1e-15);
    CHECK_NEAR(weight(c, 0, r, 1), 7.0 / 32, 1e-15);
    CHECK_NEAR(weight(c, 0, r, 2), -1.0 / 32, 1e-15);
    CHECK_NEAR(weight(c, 0, r, 3), -1.0 / 32, 1e-15);
    CHECK(row_len(c, 0, r) == 4);
    for (uint32_t i = 0; i < 4; i++) {
        r = nv + sd_level_find_edge(l0, 0, 4 + i);
        CHECK_NEAR(weight(c, 0, r, 0), 27.0 / 32, 1e-15);
        CHECK_NEAR(weight(c, 0, r, 4 + i), 15.0 / 64, 1e-15);
        CHECK_NEAR(weight(c, 0, r, 4 + (i + 1) % 4), 1.0 / 32, 1e-15);
        CHECK_NEAR(weight(c, 0, r, 4 + (i + 3) % 4), 1.0 / 32, 1e-15);
        CHECK_NEAR(weight(c, 0, r, 4 + (i + 2) % 4), -9.0 / 64, 1e-15);
        CHECK(row_len(c, 0, r) == 5);
    }
    /* the corner stays put; the rule follows the children (k stays 3 and 4 at every level) */
    for (int L = 1; L <= 3; L++) {
        const sd_level *lv = sd_complex_level(c, L, &err);
        CHECK(lv);
        int nc;
        const double *x = sd_level_channel(lv, 0, &nc);
        CHECK(x[0] == 0 && x[1] == 0 && x[2] == 0);
        CHECK(vrule(c, L, 0) == SD_RULE_YZ_CORNER);
        int fd = 0;
        for (uint32_t v = 1; v < sd_level_num_vertices(lv); v++)
            fd += erule(c, L, 0, v) == SD_RULE_YZ_FIXED_DISK;
        CHECK(fd == 7);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

/* Failure injection (test.h's counting allocator) for an edit that moves a point a corner's
 * alpha is measured on: the level's rules are rebuilt. Every allocation that can fail either
 * leaves the levels exactly as they were (SD_ERR_NOMEM) or gives the levels of a new complex
 * with the moved point; nothing leaks. */
/* the positions of levels 0..2 of complex c (sizes in n[]) into one buffer */
static double *yz_levels(sd_complex *c, size_t *n)
{
    sd_error err;
    size_t total = 0, at = 0;
    for (int L = 0; L <= 2; L++) {
        const sd_level *lv = sd_complex_level(c, L, &err);
        if (!lv)
            return NULL;
        total += 3 * (size_t)sd_level_num_vertices(lv);
    }
    double *x = malloc(total * sizeof *x);
    for (int L = 0; x && L <= 2; L++) {
        const sd_level *lv = sd_complex_level(c, L, &err);
        int nc;
        size_t k = 3 * (size_t)sd_level_num_vertices(lv);
        memcpy(x + at, sd_level_channel(lv, 0, &nc), k * sizeof *x);
        at += k;
    }
    *n = total;
    return x;
}

TEST(yz_edit_rebuilds_alpha_rules)
{
    mesh m = {0};
    three_fins(&m);
    const uint32_t moved = 3; /* fin 0's boundary end at s0: alpha of s0's petal reads it */
    const double to[3] = {1.3, 0.6, -0.2};
    sd_error err;
    /* the reference: a new complex with the moved point */
    mesh w = m;
    double *xyz = malloc(3 * m.nv * sizeof *xyz);
    memcpy(xyz, m.xyz, 3 * m.nv * sizeof *xyz);
    memcpy(xyz + 3 * moved, to, sizeof to);
    w.xyz = xyz;
    sd_complex *ref = mesh_complex(&w, &YZ, &err);
    CHECK(ref);
    size_t nref = 0, nbefore = 0;
    double *want = yz_levels(ref, &nref);
    CHECK(want);
    sd_complex *plain = mesh_complex(&m, &YZ, &err);
    double *before = yz_levels(plain, &nbefore);
    CHECK(before && nbefore == nref);
    /* the edit takes the rebuild path (levels 1 and 2 recomputed: all their points) and gives
     * the levels of the new complex */
    uint64_t counts[SD_MAX_LEVEL + 1];
    CHECK(sd_complex_edit(plain, 0, 1, &moved, to, counts, &err) == SD_OK);
    CHECK(counts[0] == 1 && counts[2] == sd_level_num_vertices(sd_complex_level(plain, 2, &err)));
    size_t ngot = 0;
    double *got = yz_levels(plain, &ngot);
    CHECK(got && ngot == nref);
    double diff = 0;
    for (size_t i = 0; i < nref; i++)
        diff = fmax(diff, fabs(got[i] - want[i]));
    CHECK(diff < 1e-12);
    free(got);
    sd_complex_free(plain);
    long n = 1;
    for (;; n++) {
        counting cc = {0, -1, 0};
        sd_options o = YZ;
        o.allocator = TEST_COUNTING(&cc);
        sd_complex *c = mesh_complex(&m, &o, &err);
        CHECK(c);
        size_t nb = 0;
        double *b = yz_levels(c, &nb);
        CHECK(b);
        cc.fail_at = cc.calls + n;
        sd_result r = sd_complex_edit(c, 0, 1, &moved, to, counts, &err);
        bool reached = cc.calls >= cc.fail_at;
        cc.fail_at = -1;
        size_t na = 0;
        double *a = yz_levels(c, &na);
        CHECK(a && na == nref);
        const double *expect = r == SD_OK ? want : b;
        CHECK(r == SD_OK || err.code == SD_ERR_NOMEM);
        double d = 0;
        for (size_t i = 0; a && i < nref; i++)
            d = fmax(d, fabs(a[i] - expect[i]));
        CHECK(d < 1e-12);
        free(a);
        free(b);
        sd_complex_free(c);
        CHECK(cc.bytes == 0);
        if (!reached)
            break; /* the edit made fewer than n allocations: every one has failed once */
    }
    CHECK(n > 30); /* the rules of a level and two levels' worth of allocations */
    free(want);
    free(before);
    free(xyz);
    sd_complex_free(ref);
    mesh_free(&m);
}
