/* test_direct.c — batch refinement without S (core/direct.c): with sd_options.edit_index LAZY the
 * levels of a complex without solids are computed straight from the rules; every level must be
 * the bytes the path through S gives (edit_index WITH_LEVELS, the same complex), for every rule
 * family direct.c makes (Loop, Warren, boundaries, corners, curves and their junctions, points,
 * creases, embedded surfaces, N1 / N2 choices, G1), for the levels where it declines (G2 rings,
 * solids, semi-sharp creases), with extra channels and 1-3 threads; and S, classes and edits made
 * afterwards must be those of the other path. */
#include "test.h"
#include <stdbool.h>

#define DIFF(what)                                                                                 \
    do {                                                                                           \
        fprintf(stderr, "direct: %s differs (line %d)\n", what, __LINE__);                         \
        return 0;                                                                                  \
    } while (0)

static int same_channels(const sd_level *a, const sd_level *b)
{
    uint32_t nv = sd_level_num_vertices(a);
    if (sd_level_num_vertices(b) != nv)
        return 0;
    for (int ch = 0; ch < 3; ch++) {
        int na = 0, nb = 0;
        const double *pa = sd_level_channel(a, ch, &na), *pb = sd_level_channel(b, ch, &nb);
        if ((pa == NULL) != (pb == NULL) || na != nb ||
            (pa && memcmp(pa, pb, (size_t)nv * na * sizeof *pa)))
            return 0;
    }
    return 1;
}

/* Levels 0..top of m built both ways (prep sets each complex up) must be the same bytes; then
 * the matrices and classes, then a move of two control points and one level-1 point. */
static int same_both_ways(const mesh *m, const sd_options *base, int top, int threads,
                          int (*prep)(sd_complex *))
{
    sd_complex *c[2];
    for (int i = 0; i < 2; i++) {
        sd_options o = *base;
        o.threads = threads;
        o.edit_index = i ? SD_EDIT_INDEX_LAZY : SD_EDIT_INDEX_WITH_LEVELS;
        c[i] = mesh_complex(m, &o, NULL);
        if (!c[i] || (prep && !prep(c[i])))
            DIFF("the complex");
        /* a channel of 2 components and one of 5 (the general path) */
        double *a2 = malloc(2 * m->nv * sizeof *a2), *a5 = malloc(5 * m->nv * sizeof *a5);
        for (size_t v = 0; v < 2 * m->nv; v++)
            a2[v] = sin(0.7 * (double)v);
        for (size_t v = 0; v < 5 * m->nv; v++)
            a5[v] = cos(1.3 * (double)v) * (v % 3 ? 1 : -1e-3);
        int ok = sd_complex_add_channel(c[i], a2, 2, NULL) == 1 &&
                 sd_complex_add_channel(c[i], a5, 5, NULL) == 2;
        free(a2);
        free(a5);
        if (!ok || !sd_complex_level(c[i], top, NULL))
            DIFF("a level");
    }
    for (int l = 0; l <= top; l++)
        if (!same_channels(sd_complex_level(c[0], l, NULL), sd_complex_level(c[1], l, NULL)))
            DIFF("a level's points");
    for (int l = 0; l <= top; l++) {
        const sd_level *la = sd_complex_level(c[0], l, NULL), *lb = sd_complex_level(c[1], l, NULL);
        /* exact below the top either way (the S path built them, direct.c kept them); the top's
         * once prepared */
        if (l == top && (sd_complex_prepare_vertex_rules(c[0], l, NULL) ||
                         sd_complex_prepare_vertex_rules(c[1], l, NULL)))
            DIFF("a vertex rule");
        for (uint32_t v = 0; v < sd_level_num_vertices(la); v += 7)
            if (sd_level_vertex_rule(la, v) != sd_level_vertex_rule(lb, v))
                DIFF("a vertex rule");
        if (l == top)
            break;
        sd_csr s[2];
        for (int i = 0; i < 2; i++)
            if (sd_complex_matrix(c[i], l, &s[i], NULL))
                DIFF("a matrix");
        if (s[1].nrows != s[0].nrows || s[1].ncols != s[0].ncols ||
            memcmp(s[1].rowptr, s[0].rowptr, ((size_t)s[0].nrows + 1) * sizeof *s[0].rowptr) ||
            memcmp(s[1].col, s[0].col, (size_t)s[0].rowptr[s[0].nrows] * sizeof *s[0].col) ||
            memcmp(s[1].val, s[0].val, (size_t)s[0].rowptr[s[0].nrows] * sizeof *s[0].val))
            DIFF("a matrix");
        for (uint32_t v = 0; v < sd_level_num_vertices(la); v += 5) {
            sd_class k0, k1;
            memset(&k0, 0, sizeof k0);
            memset(&k1, 0, sizeof k1);
            if (sd_complex_vertex_class(c[0], l, v, &k0, NULL) ||
                sd_complex_vertex_class(c[1], l, v, &k1, NULL) || memcmp(&k0, &k1, sizeof k0))
                DIFF("a class");
        }
    }
    /* edits after: the lazy complex makes its matrices now */
    sd_vertex_at at[3] = {{0, 0}, {0, (uint32_t)(m->nv - 1)}, {1, 1}};
    const double val[9] = {0.25, -0.5, 1.0, 2, 2, 2, -1, 0.5, 0.125};
    for (int i = 0; i < 2; i++)
        if (sd_complex_move(c[i], 0, 3, at, val, NULL, NULL))
            DIFF("an edit");
    for (int l = 0; l <= top; l++)
        if (!same_channels(sd_complex_level(c[0], l, NULL), sd_complex_level(c[1], l, NULL)))
            DIFF("a level after an edit");
    /* and a level made after the edit (the lazy complex is indexed now: through S) */
    if (top < 5) {
        for (int i = 0; i < 2; i++)
            if (!sd_complex_level(c[i], top + 1, NULL))
                DIFF("a level");
        if (!same_channels(sd_complex_level(c[0], top + 1, NULL),
                           sd_complex_level(c[1], top + 1, NULL)))
            DIFF("a level after an edit");
    }
    sd_complex_free(c[0]);
    sd_complex_free(c[1]);
    return 1;
}

static int all_threads(const mesh *m, const sd_options *o, int top, int (*prep)(sd_complex *))
{
    for (int t = 1; t <= 3; t++)
        if (!same_both_ways(m, o, top, t, prep))
            return 0;
    return 1;
}

/* A wavy n x n grid of triangle pairs (a boundary, corners of valence 2 and 3). */
static void shape_wavy_grid(mesh *m, int n)
{
    for (int y = 0; y <= n; y++)
        for (int x = 0; x <= n; x++)
            mesh_v(m, x + 0.1 * sin(y), y, 0.2 * sin(x + 0.3 * y));
    for (uint32_t y = 0; y < (uint32_t)n; y++)
        for (uint32_t x = 0; x < (uint32_t)n; x++) {
            uint32_t a = y * (n + 1) + x, b = a + 1, c = a + n + 1, d = c + 1;
            mesh_s(m, 3, a, b, c);
            mesh_s(m, 3, b, d, c);
        }
}

/* The grid with a polyline hanging from its corner 0, a point, and a fin on the diagonal 1 - n+1
 * (a non-manifold edge of three triangles: G2 by default, G1 as an option). */
static void shape_mixed_surface(mesh *m, int n, bool fin)
{
    shape_wavy_grid(m, n);
    uint32_t prev = 0;
    for (int i = 1; i <= 6; i++) {
        uint32_t v = mesh_v(m, -0.3 * i, -0.2 * i, 0.1 * i * i);
        mesh_s(m, 2, prev, v);
        prev = v;
    }
    mesh_s(m, 1, mesh_v(m, 3, 3, 3));
    if (fin)
        mesh_s(m, 3, 1u, (uint32_t)n + 1, mesh_v(m, 0.5, 0.5, 1.5));
}

TEST(direct_loop_and_warren)
{
    mesh m = {0};
    shape_icosahedron(&m);
    sd_options o = {.surface_weights = SD_WEIGHTS_LOOP};
    CHECK(all_threads(&m, &o, 5, NULL));
    o.surface_weights = SD_WEIGHTS_WARREN;
    CHECK(all_threads(&m, &o, 4, NULL));
    mesh_free(&m);
    shape_octahedron_surface(&m);
    CHECK(same_both_ways(&m, &o, 5, 1, NULL));
    mesh_free(&m);
}

/* A closed n x m torus of triangle pairs: plain levels, whose rules come from the level before
 * (direct.c), and from level 2 on cut into parts. */
static void shape_torus(mesh *m, int n, int k)
{
    for (int i = 0; i < n; i++)
        for (int j = 0; j < k; j++) {
            double u = 2 * M_PI * i / n, v = 2 * M_PI * j / k, r = 1 + 0.3 * cos(v) + 0.05 * sin(3 * u);
            mesh_v(m, r * cos(u), r * sin(u), 0.3 * sin(v));
        }
    for (uint32_t i = 0; i < (uint32_t)n; i++)
        for (uint32_t j = 0; j < (uint32_t)k; j++) {
            uint32_t a = i * k + j, b = ((i + 1) % n) * k + j, c = i * k + (j + 1) % k,
                     d = ((i + 1) % n) * k + (j + 1) % k;
            mesh_s(m, 3, a, b, d);
            mesh_s(m, 3, a, d, c);
        }
}

TEST(direct_plain_closed_surface)
{
    mesh m = {0};
    shape_torus(&m, 40, 37);
    sd_options o = {.surface_weights = SD_WEIGHTS_LOOP};
    CHECK(all_threads(&m, &o, 3, NULL));
    /* level 4: the parent's 71 040 edges are cut into parts too (derived opposite vertices, the
     * edge and vertex points); the points alone, each way, 2 and 3 threads */
    for (int th = 2; th <= 3; th++) {
        sd_complex *c[2];
        for (int i = 0; i < 2; i++) {
            sd_options oi = o;
            oi.threads = th;
            oi.edit_index = i ? SD_EDIT_INDEX_LAZY : SD_EDIT_INDEX_WITH_LEVELS;
            c[i] = mesh_complex(&m, &oi, NULL);
            CHECK(c[i] && sd_complex_level(c[i], 4, NULL));
        }
        for (int l = 1; l <= 4; l++)
            CHECK(same_channels(sd_complex_level(c[0], l, NULL), sd_complex_level(c[1], l, NULL)));
        sd_complex_free(c[0]);
        sd_complex_free(c[1]);
    }
    o.surface_weights = SD_WEIGHTS_WARREN;
    CHECK(same_both_ways(&m, &o, 3, 2, NULL));
    mesh_free(&m);
}

TEST(direct_boundary_parallel)
{
    mesh m = {0};
    shape_wavy_grid(&m, 96); /* levels 1-3 are cut into parts */
    sd_options o = {0};
    CHECK(all_threads(&m, &o, 3, NULL));
    mesh_free(&m);
}

TEST(direct_curves_points_mixed)
{
    mesh m = {0};
    shape_curves(&m);
    sd_options o = {0};
    CHECK(all_threads(&m, &o, 6, NULL));
    mesh_free(&m);
    shape_mixed_surface(&m, 40, false);
    CHECK(all_threads(&m, &o, 3, NULL));
    mesh_free(&m);
}

TEST(direct_nonmanifold)
{
    mesh m = {0};
    shape_mixed_surface(&m, 40, true); /* G2 rings at the fin: direct.c declines */
    sd_options o = {0};
    CHECK(all_threads(&m, &o, 3, NULL));
    o.nonmanifold_default = SD_NM_G1;
    CHECK(all_threads(&m, &o, 3, NULL));
    mesh_free(&m);
    shape_three_fins(&m);
    CHECK(same_both_ways(&m, &o, 4, 1, NULL));
    o.nonmanifold_default = SD_NM_G2;
    CHECK(same_both_ways(&m, &o, 4, 1, NULL));
    mesh_free(&m);
    shape_mixed(&m); /* a tetrahedron: solids go through S */
    CHECK(same_both_ways(&m, &o, 4, 2, NULL));
    mesh_free(&m);
}

/* Tags on the 40 x 40 grid: a crease along row 5, a corner, an embedded-surface triangle pair. */
static int grid_tags(sd_complex *c)
{
    enum { N = 40 };
    uint32_t idx[64];
    uint8_t size[32];
    size_t k = 0, n = 0;
    for (uint32_t x = 3; x < 20; x++) {
        idx[k++] = 5 * (N + 1) + x;
        idx[k++] = 5 * (N + 1) + x + 1;
        size[n++] = 2;
    }
    idx[k++] = 10 * (N + 1) + 10;
    size[n++] = 1;
    uint32_t a = 20 * (N + 1) + 20, b = a + 1, cc = a + N + 1, d = cc + 1;
    idx[k++] = a, idx[k++] = b, idx[k++] = cc;
    idx[k++] = b, idx[k++] = d, idx[k++] = cc;
    size[n++] = 3;
    size[n++] = 3;
    return sd_complex_set_singular(c, idx, size, n, NULL) == SD_OK;
}

/* On the grid with the fin: the fin's edge follows the grid's first triangle and the fin (N2),
 * vertex 0 (curve and surfaces) the curve (N1). */
static int fin_overrides(sd_complex *c)
{
    enum { N = 40, FIN = (N + 1) * (N + 1) + 7 };
    sd_override ov[2] = {
        {.simplex = {1, N + 1}, .nverts = 2, .rule = SD_RULE_N2,
         .pair = {{0, 1, N + 1}, {1, N + 1, FIN}}, .pair_size = 3},
        {.simplex = {0}, .nverts = 1, .rule = SD_RULE_N1, .dimension = 1},
    };
    sd_error e;
    sd_result r = sd_complex_set_overrides(c, ov, 2, &e);
    if (r)
        fprintf(stderr, "overrides: %s\n", e.message);
    return r == SD_OK;
}

static int sharp_edge(sd_complex *c)
{
    const sd_sharpness s[] = {{{0, 1, 0}, 2, 2.5f}};
    return sd_complex_set_sharpness(c, s, 1, SD_CREASE_UNIFORM, NULL) == SD_OK;
}

TEST(direct_tags_overrides_sharp)
{
    mesh m = {0};
    shape_mixed_surface(&m, 40, false);
    sd_options o = {0};
    CHECK(all_threads(&m, &o, 3, grid_tags));
    CHECK(same_both_ways(&m, &o, 3, 1, sharp_edge)); /* semi-sharp: through S */
    mesh_free(&m);
    shape_mixed_surface(&m, 40, true);
    CHECK(all_threads(&m, &o, 3, fin_overrides));
    o.nonmanifold_default = SD_NM_G1;
    CHECK(same_both_ways(&m, &o, 3, 2, fin_overrides));
    mesh_free(&m);
}
