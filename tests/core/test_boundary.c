/* test_boundary.c — sd_level_solid_boundary: the faces of exactly one tetrahedron or octahedron,
 * oriented outward. Checked without the core's face tables: counts, closedness (every directed
 * edge meets its reverse exactly once), each triangle facing away from its own cell, and the
 * volume it encloses (divergence theorem) equal to the sum of the cell volumes. */
#include "test.h"

static double det3(const double *a, const double *b, const double *c, const double *d)
{
    double u[3], v[3], w[3];
    for (int k = 0; k < 3; k++) {
        u[k] = b[k] - a[k];
        v[k] = c[k] - a[k];
        w[k] = d[k] - a[k];
    }
    return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
           u[2] * (v[0] * w[1] - v[1] * w[0]);
}

/* Volume of the level's solids, from the cells: a tetrahedron's |det|/6; an octahedron's the
 * absolute value of the signed sum of the cones from its centroid over its 8 faces (consistently
 * oriented: (p, e_k, e_k+1) and (q, e_k+1, e_k) around the equator e). */
static double cells_volume(const sd_level *lv)
{
    const double *x = sd_level_channel(lv, 0, NULL);
    double vol = 0;
    uint32_t v[6];
    for (uint32_t i = 0; i < sd_level_num_cells(lv, SD_CELL_TETRA); i++) {
        sd_level_cell(lv, SD_CELL_TETRA, i, v);
        vol += fabs(det3(x + 3 * v[0], x + 3 * v[1], x + 3 * v[2], x + 3 * v[3])) / 6;
    }
    /* faces of (p,q,a,a2,b,b2): p and q with each equator edge of the cycle a,b,a2,b2 */
    static const int eq[4] = {2, 4, 3, 5};
    for (uint32_t i = 0; i < sd_level_num_cells(lv, SD_CELL_OCTA); i++) {
        sd_level_cell(lv, SD_CELL_OCTA, i, v);
        double c[3] = {0, 0, 0};
        for (int j = 0; j < 6; j++)
            for (int k = 0; k < 3; k++)
                c[k] += x[3 * v[j] + k] / 6;
        double o = 0;
        for (int e = 0; e < 4; e++) {
            const double *a = x + 3 * v[eq[e]], *b = x + 3 * v[eq[(e + 1) & 3]];
            o += det3(c, x + 3 * v[0], a, b) + det3(c, x + 3 * v[1], b, a);
        }
        vol += fabs(o) / 6;
    }
    return vol;
}

typedef struct bnd_check {
    uint32_t n;
    double enclosed;
    int closed, outward;
} bnd_check;

/* Centroid of the cells that contain triangle t as a face (found by brute force). */
static int cell_of_face(const sd_level *lv, const uint32_t *t, double c[3])
{
    const double *x = sd_level_channel(lv, 0, NULL);
    for (int kind = SD_CELL_TETRA; kind <= SD_CELL_OCTA; kind++) {
        int m = sd_cell_size((sd_cell_kind)kind);
        for (uint32_t i = 0; i < sd_level_num_cells(lv, (sd_cell_kind)kind); i++) {
            uint32_t v[6];
            sd_level_cell(lv, (sd_cell_kind)kind, i, v);
            int hit = 0;
            for (int j = 0; j < m; j++)
                hit += v[j] == t[0] || v[j] == t[1] || v[j] == t[2];
            if (hit < 3)
                continue;
            c[0] = c[1] = c[2] = 0;
            for (int j = 0; j < m; j++)
                for (int k = 0; k < 3; k++)
                    c[k] += x[3 * v[j] + k] / m;
            return 1;
        }
    }
    return 0;
}

static bnd_check check_boundary(const sd_level *lv)
{
    bnd_check r = {0};
    const double *x = sd_level_channel(lv, 0, NULL);
    r.n = sd_level_solid_boundary(lv, NULL);
    uint32_t *t = malloc((3 * (size_t)r.n + 1) * sizeof *t);
    if (sd_level_solid_boundary(lv, t) != r.n) {
        free(t);
        return r;
    }
    const double o[3] = {0, 0, 0};
    r.closed = r.outward = 1;
    for (uint32_t i = 0; i < r.n; i++) {
        const uint32_t *a = t + 3 * i;
        r.enclosed += det3(o, x + 3 * a[0], x + 3 * a[1], x + 3 * a[2]) / 6;
        double c[3];
        if (!cell_of_face(lv, a, c) || det3(c, x + 3 * a[0], x + 3 * a[1], x + 3 * a[2]) <= 0)
            r.outward = 0; /* the cell's centroid must lie behind the triangle */
        for (int k = 0; k < 3; k++) { /* the reverse of each edge once, in another triangle */
            uint32_t u = a[k], w = a[(k + 1) % 3];
            int rev = 0;
            for (uint32_t j = 0; j < r.n; j++)
                for (int l = 0; l < 3; l++)
                    rev += t[3 * j + l] == w && t[3 * j + (l + 1) % 3] == u;
            if (rev != 1)
                r.closed = 0;
        }
    }
    free(t);
    return r;
}

TEST(boundary_single_tet)
{
    mesh m = {0};
    shape_tet(&m);
    sd_error err;
    sd_complex *c = mesh_complex(&m, NULL, &err);
    CHECK(c);
    const sd_level *l0 = sd_complex_level(c, 0, &err);
    bnd_check b = check_boundary(l0);
    CHECK(b.n == 4 && b.closed && b.outward);
    CHECK_NEAR(b.enclosed, 1.0 / 6, 1e-15);
    const sd_level *l1 = sd_complex_level(c, 1, &err); /* 4 corner tets + 1 octahedron */
    b = check_boundary(l1);
    CHECK(b.n == 16 && b.closed && b.outward);
    CHECK_NEAR(b.enclosed, cells_volume(l1), 1e-12);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(boundary_negative_tet_input)
{
    mesh m = {0}; /* listed with negative volume: still outward */
    mesh_v(&m, 0, 0, 0);
    mesh_v(&m, 1, 0, 0);
    mesh_v(&m, 0, 1, 0);
    mesh_v(&m, 0, 0, 1);
    mesh_s(&m, 4, 0, 2, 1, 3);
    sd_error err;
    sd_complex *c = mesh_complex(&m, NULL, &err);
    CHECK(c);
    bnd_check b = check_boundary(sd_complex_level(c, 0, &err));
    CHECK(b.n == 4 && b.closed && b.outward);
    CHECK_NEAR(b.enclosed, 1.0 / 6, 1e-15);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(boundary_two_tets)
{
    mesh m = {0};
    shape_two_tets(&m);
    sd_error err;
    sd_complex *c = mesh_complex(&m, NULL, &err);
    CHECK(c);
    for (int l = 0; l <= 2; l++) {
        const sd_level *lv = sd_complex_level(c, l, &err);
        CHECK(lv);
        bnd_check b = check_boundary(lv);
        CHECK(b.n == 6u << (2 * l) && b.closed && b.outward); /* each face splits into 4 */
        CHECK_NEAR(b.enclosed, cells_volume(lv), 1e-12 * cells_volume(lv));
    }
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(boundary_cube_of_tets)
{
    mesh m = {0};
    shape_cube_tets(&m, 2);
    sd_error err;
    sd_complex *c = mesh_complex(&m, NULL, &err);
    CHECK(c);
    uint32_t n0 = 0;
    for (int l = 0; l <= 2; l++) {
        const sd_level *lv = sd_complex_level(c, l, &err);
        CHECK(lv);
        bnd_check b = check_boundary(lv);
        if (l == 0) {
            n0 = b.n;
            CHECK(n0 == 6 * 2 * 2 * 2); /* 6 sides of 2x2 squares, 2 triangles each */
        }
        CHECK(b.n == n0 << (2 * l) && b.closed && b.outward);
        CHECK_NEAR(b.enclosed, cells_volume(lv), 1e-12 * cells_volume(lv));
    }
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(boundary_mixed_and_surfaces)
{
    mesh m = {0}; /* a tet with a fin, a curve and a point: only the tet's 4 faces */
    shape_mixed(&m);
    sd_error err;
    sd_complex *c = mesh_complex(&m, NULL, &err);
    CHECK(c);
    bnd_check b = check_boundary(sd_complex_level(c, 1, &err));
    CHECK(b.n == 16 && b.closed && b.outward);
    sd_complex_free(c);
    mesh_free(&m);
    shape_icosahedron(&m); /* a closed surface bounds no solid */
    c = mesh_complex(&m, NULL, &err);
    CHECK(c);
    CHECK(sd_level_solid_boundary(sd_complex_level(c, 1, &err), NULL) == 0);
    sd_complex_free(c);
    mesh_free(&m);
}
