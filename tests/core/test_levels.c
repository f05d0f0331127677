/* test_levels.c — uniform subdivision: cell counts per level (the split table of docs/RULES.md "Splitting",
 * counted here from the cells themselves), stencil rows summing to 1, the octet-truss invariants
 * (|rho| = 14, |rho(e)| in {4,6}), rule formulas from the papers, and affine invariance. */
#include "test.h"

static int cmp64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

/* Number of distinct edges of a level, counted from its cells (no core bookkeeping used). */
static uint64_t count_edges(const sd_level *lv)
{
    static const int te[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
    static const int oe[12][2] = {{0, 2}, {0, 4}, {0, 3}, {0, 5}, {1, 2}, {1, 4},
                                  {1, 3}, {1, 5}, {2, 4}, {4, 3}, {3, 5}, {5, 2}};
    size_t cap = 16, n = 0;
    uint64_t *k = malloc(cap * sizeof *k);
    for (int kind = 1; kind <= 4; kind++) {
        uint32_t nc = sd_level_num_cells(lv, (sd_cell_kind)kind), v[6];
        for (uint32_t i = 0; i < nc; i++) {
            sd_level_cell(lv, (sd_cell_kind)kind, i, v);
            int pairs[12][2], np = 0;
            if (kind == 1) { pairs[0][0] = 0; pairs[0][1] = 1; np = 1; }
            if (kind == 2) { int t[3][2] = {{0, 1}, {1, 2}, {2, 0}}; memcpy(pairs, t, sizeof t); np = 3; }
            if (kind == 3) { memcpy(pairs, te, sizeof te); np = 6; }
            if (kind == 4) { memcpy(pairs, oe, sizeof oe); np = 12; }
            for (int p = 0; p < np; p++) {
                uint64_t a = v[pairs[p][0]], b = v[pairs[p][1]];
                if (n == cap)
                    k = realloc(k, (cap *= 2) * sizeof *k);
                k[n++] = a < b ? a << 32 | b : b << 32 | a;
            }
        }
    }
    qsort(k, n, sizeof *k, cmp64);
    uint64_t u = 0;
    for (size_t i = 0; i < n; i++)
        u += i == 0 || k[i] != k[i - 1];
    free(k);
    return u;
}

static void check_counts(const mesh *m, int levels)
{
    sd_complex *c = mesh_complex(m, NULL, NULL);
    CHECK(c);
    const sd_level *l0 = sd_complex_level(c, 0, NULL);
    uint64_t P = sd_level_num_cells(l0, SD_CELL_POINT), Cu = sd_level_num_cells(l0, SD_CELL_CURVE);
    uint64_t Tr = sd_level_num_cells(l0, SD_CELL_TRIANGLE), T = sd_level_num_cells(l0, SD_CELL_TETRA);
    uint64_t O = 0, V = sd_level_num_vertices(l0), E = count_edges(l0);
    for (int L = 1; L <= levels; L++) {
        /* docs/RULES.md "Splitting": edge -> 2, triangle -> 4, tet -> 4 tets + octahedron, octahedron -> 6 + 8 */
        uint64_t V2 = V + E + O, T2 = 4 * T + 8 * O, O2 = T + 6 * O;
        const sd_level *lv = sd_complex_level(c, L, NULL);
        CHECK(lv);
        CHECK(sd_level_num_vertices(lv) == V2);
        CHECK(sd_level_num_cells(lv, SD_CELL_POINT) == P);
        CHECK(sd_level_num_cells(lv, SD_CELL_CURVE) == Cu << L);
        CHECK(sd_level_num_cells(lv, SD_CELL_TRIANGLE) == Tr << (2 * L));
        CHECK(sd_level_num_cells(lv, SD_CELL_TETRA) == T2);
        CHECK(sd_level_num_cells(lv, SD_CELL_OCTA) == O2);
        sd_counts pred;
        sd_complex_counts(c, L, &pred);
        CHECK(pred.vertices == V2 && pred.tetrahedra == T2 && pred.octahedra == O2);
        V = V2, T = T2, O = O2, E = count_edges(lv);
        CHECK(pred.edges == E);
    }
    sd_complex_free(c);
}

TEST(levels_cell_counts)
{
    mesh a = {0}, b = {0}, d = {0}, e = {0}, f = {0};
    shape_tet(&a);
    check_counts(&a, 4);
    shape_two_tets(&b);
    check_counts(&b, 3);
    shape_mixed(&d);
    check_counts(&d, 3);
    shape_icosahedron(&e);
    check_counts(&e, 4);
    shape_cube_tets(&f, 2);
    check_counts(&f, 2);
    mesh_free(&a), mesh_free(&b), mesh_free(&d), mesh_free(&e), mesh_free(&f);
}

/* Every stencil row sums to 1 and has non-negative weights, all rule families, all levels. */
static void check_rows(const mesh *m, const sd_options *o, int levels)
{
    sd_complex *c = mesh_complex(m, o, NULL);
    CHECK(c);
    for (int L = 0; L < levels; L++) {
        sd_csr s;
        CHECK(sd_complex_matrix(c, L, &s, NULL) == SD_OK);
        for (uint32_t r = 0; r < s.nrows; r++) {
            double sum = 0;
            for (uint32_t k = s.rowptr[r]; k < s.rowptr[r + 1]; k++) {
                CHECK(s.val[k] >= 0 && s.col[k] < s.ncols);
                sum += s.val[k];
            }
            CHECK_NEAR(sum, 1.0, 1e-14);
        }
    }
    sd_complex_free(c);
}

TEST(levels_rows_sum_to_one)
{
    mesh ms[6] = {{0}};
    shape_tet(&ms[0]);
    shape_two_tets(&ms[1]);
    shape_mixed(&ms[2]);
    shape_icosahedron(&ms[3]);
    shape_cube_tets(&ms[4], 2);
    shape_bipyramid(&ms[5]);
    sd_options opts[3] = {{0}, {.surface_weights = SD_WEIGHTS_LOOP}, {.solid_scheme = SD_SOLID_AVERAGED}};
    for (int i = 0; i < 6; i++)
        for (int o = 0; o < 3; o++)
            check_rows(&ms[i], &opts[o], i == 4 ? 2 : 3);
    for (int i = 0; i < 6; i++)
        mesh_free(&ms[i]);
}

/* docs/RULES.md "Splitting": after 3 levels of one tetrahedron, and of two sharing a face, every interior
 * vertex has |rho| = 14 and every interior edge |rho(e)| in {4, 6}. */
static void check_octet(const mesh *m)
{
    sd_complex *c = mesh_complex(m, NULL, NULL);
    CHECK(c);
    const sd_level *lv = sd_complex_level(c, 3, NULL);
    CHECK(lv);
    int interior_v = 0, interior_e = 0;
    for (uint32_t i = 0; i < sd_level_num_vertices(lv); i++) {
        sd_class k;
        CHECK(sd_complex_vertex_class(c, 3, i, &k, NULL) == SD_OK);
        if (!k.boundary) {
            interior_v++;
            CHECK(k.rule == SD_RULE_SOLID && k.valence == 14);
        }
    }
    uint32_t ne;
    sd_level_edges(lv, &ne);
    for (uint32_t e = 0; e < ne; e++) {
        sd_class k;
        CHECK(sd_complex_edge_class(c, 3, e, &k, NULL) == SD_OK);
        if (!k.boundary) {
            interior_e++;
            CHECK(k.valence == 4 || k.valence == 6);
        }
    }
    CHECK(interior_v > 30 && interior_e > 300);
    sd_complex_free(c);
}

TEST(levels_octet_invariants)
{
    mesh a = {0}, b = {0};
    shape_tet(&a);
    check_octet(&a);
    shape_two_tets(&b);
    check_octet(&b);
    mesh_free(&a);
    mesh_free(&b);
}

/* Warren's weights (000 eq. 16) on the icosahedron (m = 5) and an octahedron (m = 4), and Loop's
 * original beta on request; edge points 3/8, 1/8 — all computed here from the input triangles. */
static void check_loop_surface(const mesh *m, int weights)
{
    sd_options o = {.surface_weights = weights};
    sd_complex *c = mesh_complex(m, &o, NULL);
    CHECK(c);
    const sd_level *l1 = sd_complex_level(c, 1, NULL);
    CHECK(l1);
    const double *x1 = sd_level_channel(l1, 0, NULL);
    for (uint32_t v = 0; v < m->nv; v++) {
        /* neighbours from the triangles */
        uint32_t nb[32];
        int n = 0;
        for (size_t s = 0; s < m->ns; s++) {
            const uint32_t *t = m->idx + 3 * s;
            for (int j = 0; j < 3; j++)
                if (t[j] == v)
                    for (int q = 1; q <= 2; q++) {
                        uint32_t w = t[(j + q) % 3];
                        int seen = 0;
                        for (int i = 0; i < n; i++)
                            seen |= nb[i] == w;
                        if (!seen)
                            nb[n++] = w;
                    }
        }
        double cw = weights == SD_WEIGHTS_LOOP
                        ? (5.0 / 8 - pow(3.0 / 8 + cos(2 * M_PI / n) / 4, 2)) / n
                        : (n == 3 ? 3.0 / 16 : 3.0 / (8.0 * n));
        for (int k = 0; k < 3; k++) {
            double want = (1 - n * cw) * m->xyz[3 * v + k];
            for (int i = 0; i < n; i++)
                want += cw * m->xyz[3 * nb[i] + k];
            CHECK_NEAR(x1[3 * v + k], want, 1e-14);
        }
    }
    /* edge points: find the two opposite vertices from the triangles */
    for (uint32_t i = (uint32_t)m->nv; i < sd_level_num_vertices(l1); i++) {
        uint32_t a, b, opp[2], no = 0;
        CHECK(sd_level_origin(l1, i, &a, &b) == SD_ORIGIN_EDGE);
        for (size_t s = 0; s < m->ns; s++) {
            const uint32_t *t = m->idx + 3 * s;
            int ha = 0, hb = 0;
            for (int j = 0; j < 3; j++)
                ha |= t[j] == a, hb |= t[j] == b;
            if (ha && hb)
                for (int j = 0; j < 3; j++)
                    if (t[j] != a && t[j] != b && no < 2)
                        opp[no++] = t[j];
        }
        CHECK(no == 2);
        for (int k = 0; k < 3; k++)
            CHECK_NEAR(x1[3 * i + k], 3.0 / 8 * (m->xyz[3 * a + k] + m->xyz[3 * b + k]) +
                                          1.0 / 8 * (m->xyz[3 * opp[0] + k] + m->xyz[3 * opp[1] + k]), 1e-14);
    }
    sd_complex_free(c);
}

TEST(levels_loop_weights)
{
    mesh a = {0}, b = {0};
    shape_icosahedron(&a);
    shape_octahedron_surface(&b);
    check_loop_surface(&a, SD_WEIGHTS_WARREN);
    check_loop_surface(&b, SD_WEIGHTS_WARREN);
    check_loop_surface(&a, SD_WEIGHTS_LOOP);
    check_loop_surface(&b, SD_WEIGHTS_LOOP);
    mesh_free(&a);
    mesh_free(&b);
}

/* Cubic B-spline curves: (6x + a + b)/8 inside, ends fixed, midpoints (000 eq. 13-14, k = 1). */
TEST(levels_curve_rules)
{
    mesh m = {0};
    double p[5][3] = {{0, 0, 0}, {1, 2, 0}, {3, 1, 1}, {4, 4, 2}, {6, 3, 5}};
    for (int i = 0; i < 5; i++)
        mesh_v(&m, p[i][0], p[i][1], p[i][2]);
    for (int i = 0; i < 4; i++)
        mesh_s(&m, 2, i, i + 1);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    const sd_level *l1 = sd_complex_level(c, 1, NULL);
    const double *x = sd_level_channel(l1, 0, NULL);
    for (int k = 0; k < 3; k++) {
        CHECK_NEAR(x[k], p[0][k], 0);
        CHECK_NEAR(x[12 + k], p[4][k], 0);
        for (int i = 1; i < 4; i++)
            CHECK_NEAR(x[3 * i + k], (6 * p[i][k] + p[i - 1][k] + p[i + 1][k]) / 8, 1e-15);
    }
    for (uint32_t i = 5; i < 9; i++) {
        uint32_t a, b;
        sd_level_origin(l1, i, &a, &b);
        for (int k = 0; k < 3; k++)
            CHECK_NEAR(x[3 * i + k], (p[a][k] + p[b][k]) / 2, 1e-15);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

/* Solid rules on known neighbourhoods: the centre of 2x2x2 Kuhn cubes (valence 14, 001 eq. 3.7)
 * and, at level 2 of one tetrahedron, the cell point of the level-1 octahedron (001 eq. 3.6). */
TEST(levels_solid_rules)
{
    mesh m = {0};
    shape_cube_tets(&m, 2);
    /* move the centre so the test is not symmetric */
    m.xyz[3 * 13] += 0.1, m.xyz[3 * 13 + 1] -= 0.05;
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    const sd_level *l1 = sd_complex_level(c, 1, NULL);
    const double *x = sd_level_channel(l1, 0, NULL);
    /* neighbours of the centre: every vertex sharing a tet with it */
    int nb[27] = {0}, k = 0;
    for (size_t s = 0; s < m.ns; s++) {
        const uint32_t *t = m.idx + 4 * s;
        int has = 0;
        for (int j = 0; j < 4; j++)
            has |= t[j] == 13;
        if (has)
            for (int j = 0; j < 4; j++)
                if (t[j] != 13 && !nb[t[j]])
                    nb[t[j]] = 1, k++;
    }
    CHECK(k == 14);
    for (int d = 0; d < 3; d++) {
        double want = 9.0 / 16 * m.xyz[3 * 13 + d];
        for (int i = 0; i < 27; i++)
            if (nb[i])
                want += 7.0 / (16 * k) * m.xyz[3 * i + d];
        CHECK_NEAR(x[3 * 13 + d], want, 1e-14);
    }
    sd_complex_free(c);
    mesh_free(&m);

    mesh t = {0};
    shape_tet(&t);
    c = mesh_complex(&t, NULL, NULL);
    CHECK(c);
    l1 = sd_complex_level(c, 1, NULL);
    const sd_level *l2 = sd_complex_level(c, 2, NULL);
    uint32_t o[6];
    sd_level_cell(l1, SD_CELL_OCTA, 0, o);
    const double *y1 = sd_level_channel(l1, 0, NULL), *y2 = sd_level_channel(l2, 0, NULL);
    uint32_t n2 = sd_level_num_vertices(l2), found = 0;
    for (uint32_t i = 0; i < n2; i++) {
        uint32_t a, b;
        if (sd_level_origin(l2, i, &a, &b) != SD_ORIGIN_CELL)
            continue;
        found++;
        for (int d = 0; d < 3; d++) {
            double want = 0.25 * (y1[3 * o[0] + d] + y1[3 * o[1] + d]);
            for (int j = 2; j < 6; j++)
                want += 0.125 * y1[3 * o[j] + d];
            CHECK_NEAR(y2[3 * i + d], want, 1e-15);
        }
    }
    CHECK(found == 1);
    sd_complex_free(c);
    mesh_free(&t);
}

/* A linear attribute f(x) = a.x + b stays exactly linear in the positions (rows sum to 1). */
TEST(levels_linear_attribute)
{
    mesh ms[3] = {{0}};
    shape_mixed(&ms[0]);
    shape_cube_tets(&ms[1], 1);
    shape_icosahedron(&ms[2]);
    const double a[3] = {0.3, -1.7, 2.25}, b = 4.5;
    for (int s = 0; s < 3; s++) {
        mesh *m = &ms[s];
        double *f = malloc(m->nv * 2 * sizeof *f);
        for (size_t i = 0; i < m->nv; i++) {
            f[2 * i] = a[0] * m->xyz[3 * i] + a[1] * m->xyz[3 * i + 1] + a[2] * m->xyz[3 * i + 2] + b;
            f[2 * i + 1] = -m->xyz[3 * i + 2];
        }
        for (int scheme = 0; scheme < 2; scheme++) {
            sd_options o = {.solid_scheme = scheme};
            sd_complex *c = mesh_complex(m, &o, NULL);
            CHECK(c);
            int ch = sd_complex_add_channel(c, f, 2, NULL);
            CHECK(ch == 1);
            const sd_level *lv = sd_complex_level(c, 3, NULL);
            CHECK(lv);
            int nc;
            const double *x = sd_level_channel(lv, 0, NULL), *g = sd_level_channel(lv, ch, &nc);
            CHECK(nc == 2);
            for (uint32_t i = 0; i < sd_level_num_vertices(lv); i++) {
                double want = a[0] * x[3 * i] + a[1] * x[3 * i + 1] + a[2] * x[3 * i + 2] + b;
                CHECK_NEAR(g[2 * i], want, 1e-12);
                CHECK_NEAR(g[2 * i + 1], -x[3 * i + 2], 1e-12);
            }
            sd_complex_free(c);
        }
        free(f);
        mesh_free(m);
    }
}

/* Every level-1 cell is positively oriented when the input is (tets are reoriented at level 0). */
TEST(levels_orientation)
{
    mesh m = {0};
    shape_two_tets(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    for (int L = 1; L <= 3; L++) {
        const sd_level *lv = sd_complex_level(c, L, NULL);
        const double *x = sd_level_channel(lv, 0, NULL);
        for (uint32_t i = 0; i < sd_level_num_cells(lv, SD_CELL_TETRA); i++) {
            uint32_t v[4];
            sd_level_cell(lv, SD_CELL_TETRA, i, v);
            double p[3][3];
            for (int j = 0; j < 3; j++)
                for (int d = 0; d < 3; d++)
                    p[j][d] = x[3 * v[j + 1] + d] - x[3 * v[0] + d];
            double det = p[0][0] * (p[1][1] * p[2][2] - p[1][2] * p[2][1]) -
                         p[0][1] * (p[1][0] * p[2][2] - p[1][2] * p[2][0]) +
                         p[0][2] * (p[1][0] * p[2][1] - p[1][1] * p[2][0]);
            CHECK(det > 0);
        }
    }
    sd_complex_free(c);
    mesh_free(&m);
}
