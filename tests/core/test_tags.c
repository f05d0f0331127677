/* Singular tags (000 Sec. 4.1, docs/RULES.md): creases follow the cubic B-spline of the crease
 * polygon ((6x + a + b)/8, midpoints), tagged corners stay fixed, and an embedded surface inside
 * a solid stays a surface (a plane stays the plane) through three levels. */
#include "test.h"

static int on_cube_edge(const double *p)
{
    int k = 0;
    for (int i = 0; i < 3; i++)
        k += fabs(p[i]) < 1e-12 || fabs(p[i] - 1) < 1e-12;
    return k >= 2;
}

TEST(tags_cube_creases_and_corners)
{
    mesh m = {0};
    shape_cube_tets(&m, 1); /* vertex (x,y,z) has id x + 2y + 4z */
    uint32_t idx[24];
    uint8_t sz[12];
    int n = 0;
    for (uint32_t a = 0; a < 8; a++)
        for (uint32_t b = a + 1; b < 8; b++) {
            uint32_t d = a ^ b;
            if (d == 1 || d == 2 || d == 4) { /* the 12 cube edges */
                idx[2 * n] = a;
                idx[2 * n + 1] = b;
                sz[n++] = 2;
            }
        }
    CHECK(n == 12);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_set_singular(c, idx, sz, 12, NULL) == SD_OK);
    for (int l = 1; l <= 3; l++) {
        const sd_level *lv = sd_complex_level(c, l, NULL);
        CHECK(lv);
        const double *x = sd_level_channel(lv, 0, NULL);
        uint32_t ncrease = 0;
        for (uint32_t i = 0; i < sd_level_num_vertices(lv); i++) {
            if (!sd_level_vertex_singular(lv, i))
                continue;
            ncrease++;
            CHECK(on_cube_edge(x + 3 * i)); /* creases stay straight */
        }
        CHECK(ncrease == 8 + 12 * ((1u << l) - 1)); /* the corners and the crease points */
        for (uint32_t i = 0; i < 8; i++)           /* three creases meet: fixed corners */
            for (int k = 0; k < 3; k++)
                CHECK_NEAR(x[3 * i + k], m.xyz[3 * i + k], 0);
        sd_class cl;
        CHECK(sd_complex_vertex_class(c, l, 0, &cl, NULL) == SD_OK && cl.rule == SD_RULE_CORNER);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(tags_crease_polygon_is_bspline)
{
    /* the pentagon around icosahedron vertex 0 (its link: 11, 5, 1, 7, 10) as a closed crease:
     * at level 1 each crease vertex is (6x + a + b)/8 of its crease neighbours, each crease edge
     * point the midpoint, and vertex 0 (off the crease) still follows Loop */
    mesh m = {0};
    shape_icosahedron(&m);
    const uint32_t ring[5] = {11, 5, 1, 7, 10};
    uint32_t idx[10];
    uint8_t sz[5];
    for (int i = 0; i < 5; i++) {
        idx[2 * i] = ring[i];
        idx[2 * i + 1] = ring[(i + 1) % 5];
        sz[i] = 2;
    }
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_set_singular(c, idx, sz, 5, NULL) == SD_OK);
    const sd_level *l1 = sd_complex_level(c, 1, NULL);
    CHECK(l1);
    const double *x = sd_level_channel(l1, 0, NULL), *p = m.xyz;
    for (int i = 0; i < 5; i++) {
        uint32_t v = ring[i], a = ring[(i + 4) % 5], b = ring[(i + 1) % 5];
        for (int k = 0; k < 3; k++)
            CHECK_NEAR(x[3 * v + k], (6 * p[3 * v + k] + p[3 * a + k] + p[3 * b + k]) / 8, 1e-15);
        const sd_level *l0 = sd_complex_level(c, 0, NULL);
        uint32_t e = sd_level_find_edge(l0, v, b);
        uint32_t ep = 12 + e; /* edge points follow the vertex points, in edge order */
        for (int k = 0; k < 3; k++)
            CHECK_NEAR(x[3 * ep + k], (p[3 * v + k] + p[3 * b + k]) / 2, 1e-15);
    }
    sd_class cl;
    CHECK(sd_complex_vertex_class(c, 0, 0, &cl, NULL) == SD_OK && cl.rule == SD_RULE_LOOP);
    CHECK(sd_complex_vertex_class(c, 0, 11, &cl, NULL) == SD_OK && cl.rule == SD_RULE_CURVE);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(tags_embedded_surface_stays_a_surface)
{
    /* a 2x2x2 block of cubes; the 8 triangles of the middle plane z = 1 are tagged */
    mesh m = {0};
    shape_cube_tets(&m, 2);
    uint32_t idx[64];
    uint8_t sz[32];
    int n = 0;
    size_t off = 0;
    for (size_t s = 0; s < m.ns; off += m.sz[s++]) /* faces of tets lying in z = 1 */
        for (int skip = 0; skip < 4; skip++) {
            uint32_t f[3];
            int j = 0, flat = 1;
            for (int k = 0; k < 4; k++)
                if (k != skip) {
                    f[j++] = m.idx[off + k];
                    flat &= fabs(m.xyz[3 * m.idx[off + k] + 2] - 1) < 1e-12;
                }
            if (!flat)
                continue;
            int dup = 0;
            for (int q = 0; q < n; q++) {
                int same = 0;
                for (int a = 0; a < 3; a++)
                    for (int b = 0; b < 3; b++)
                        same += idx[3 * q + a] == f[b];
                dup |= same == 3;
            }
            if (!dup) {
                memcpy(idx + 3 * n, f, sizeof f);
                sz[n++] = 3;
            }
        }
    CHECK(n == 8);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_set_singular(c, idx, sz, (size_t)n, NULL) == SD_OK);
    for (int l = 1; l <= 3; l++) {
        const sd_level *lv = sd_complex_level(c, l, NULL);
        CHECK(lv);
        const double *x = sd_level_channel(lv, 0, NULL);
        uint32_t on = 0;
        for (uint32_t i = 0; i < sd_level_num_vertices(lv); i++)
            if (sd_level_vertex_singular(lv, i)) {
                on++;
                CHECK_NEAR(x[3 * i + 2], 1, 1e-12);
            }
        uint32_t k = 2u << l; /* a (2^(l+1)+1)^2 grid of surface points */
        CHECK(on == (k + 1) * (k + 1));
    }
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(tags_errors)
{
    mesh m = {0};
    shape_icosahedron(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    sd_error e;
    uint32_t four[4] = {0, 1, 5, 11};
    uint8_t s4 = 4, s2[2] = {2, 2}, s1 = 1, s3 = 3;
    CHECK(sd_complex_set_singular(c, four, &s4, 1, &e) == SD_ERR_ARITY && e.item == 0);
    uint32_t range[1] = {12};
    CHECK(sd_complex_set_singular(c, range, &s1, 1, &e) == SD_ERR_INDEX);
    uint32_t edges[4] = {0, 1, 0, 3}; /* 0-1 is an edge, 0-3 is not */
    CHECK(sd_complex_set_singular(c, edges, s2, 2, &e) == SD_ERR_ARG && e.item == 1);
    uint32_t tri[3] = {0, 1, 2}; /* not a face */
    CHECK(sd_complex_set_singular(c, tri, &s3, 1, &e) == SD_ERR_ARG && e.item == 0);
    /* a refused call changed nothing: vertex 0 still follows Loop */
    sd_class cl;
    CHECK(sd_complex_vertex_class(c, 0, 0, &cl, NULL) == SD_OK && cl.rule == SD_RULE_LOOP);
    sd_complex_free(c);
    mesh_free(&m);
}
