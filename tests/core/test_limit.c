/* test_limit.c — limit masks (core/limit.c; docs/RULES.md "Limits"). Expected values: the left
 * eigenvector of 001 Appendix B.1's printed block (by power iteration here), the cubic
 * B-spline's (1/6, 2/3, 1/6) and Warren's closed form 1/2, 1/(2n) (the icosahedron: n = 5). */
#include "test.h"

static double weight_of(const sd_limit_mask *m, uint32_t id)
{
    double w = 0;
    for (int i = 0; i < m->n; i++)
        if (m->points[i] == id)
            w += m->w[i];
    return w;
}

TEST(limit_appendix_b1_centre)
{
    mesh m = {0};
    shape_bipyramid(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    const double s = 1.0 / 16, e = 1.0 / 8, q = 1.0 / 4, f = 5.0 / 16, w = 7.0 / 80;
    const double B1[6][6] = {
        {9 * s, w, w, w, w, w}, {f, f, e, e, e, 0}, {q, e, q, e, e, e},
        {q, e, e, q, e, e},     {q, e, e, e, q, e}, {f, 0, e, e, e, f}};
    double l[6] = {1, 0, 0, 0, 0, 0}, t[6];
    for (int it = 0; it < 400; it++) { /* l <- l B1: the rows sum to 1, so sum(l) stays 1 */
        for (int j = 0; j < 6; j++) {
            t[j] = 0;
            for (int i = 0; i < 6; i++)
                t[j] += l[i] * B1[i][j];
        }
        memcpy(l, t, sizeof l);
    }
    sd_limit_mask lm;
    CHECK(sd_limit_mask_of(c, 0, 0, &lm, NULL) == SD_OK);
    CHECK(lm.method == SD_LIMIT_EIGEN && lm.level == 0 && lm.eval_level == 1);
    CHECK(!lm.t1 && !lm.t2);
    for (uint32_t v = 0; v < 6; v++)
        CHECK_NEAR(weight_of(&lm, v), l[v], 1e-12);
    double x[18];
    CHECK(sd_complex_limit(c, 0, 0, x, NULL, NULL) == SD_OK);
    for (int k = 0; k < 3; k++) {
        double want = 0;
        for (int v = 0; v < 6; v++)
            want += l[v] * m.xyz[3 * v + k];
        CHECK_NEAR(x[k], want, 1e-12);
    }
    sd_limit_mask_free(&lm);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(limit_curves)
{
    mesh m = {0};
    for (int i = 0; i < 5; i++)
        mesh_v(&m, i, (i * i) % 3, 0.5 * i);
    for (uint32_t i = 0; i + 1 < 5; i++)
        mesh_s(&m, 2, i, i + 1);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    sd_limit_mask lm;
    CHECK(sd_limit_mask_of(c, 0, 2, &lm, NULL) == SD_OK);
    CHECK(lm.method == SD_LIMIT_BSPLINE && lm.n == 3);
    CHECK_NEAR(weight_of(&lm, 2), 2.0 / 3, 1e-15);
    CHECK_NEAR(weight_of(&lm, 1), 1.0 / 6, 1e-15);
    CHECK_NEAR(weight_of(&lm, 3), 1.0 / 6, 1e-15);
    sd_limit_mask_free(&lm);
    CHECK(sd_limit_mask_of(c, 0, 0, &lm, NULL) == SD_OK); /* a curve end: fixed */
    CHECK(lm.method == SD_LIMIT_FIXED && lm.n == 1 && lm.points[0] == 0 && lm.w[0] == 1);
    sd_limit_mask_free(&lm);
    double x[15], n[15];
    CHECK(sd_complex_limit(c, 0, 0, x, n, NULL) == SD_OK);
    for (int k = 0; k < 15; k++)
        CHECK(n[k] == 0); /* curves have no tangent plane */
    /* bad arguments */
    sd_error err;
    CHECK(sd_limit_mask_of(c, 0, 5, &lm, &err) == SD_ERR_INDEX && err.item == 5);
    CHECK(sd_limit_mask_of(c, 13, 0, &lm, &err) == SD_ERR_ARG);
    CHECK(sd_complex_limit(c, -1, 0, x, NULL, &err) == SD_ERR_ARG);
    CHECK(sd_complex_limit(c, 0, 7, x, NULL, &err) == SD_ERR_ARG);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(limit_warren_icosahedron)
{
    mesh m = {0};
    shape_icosahedron(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL); /* Warren's weights: the default */
    CHECK(c);
    CHECK(sd_complex_limit_level(c, 0) == 0 && sd_complex_limit_level(c, 2) == 2);
    for (uint32_t v = 0; v < 12; v++) {
        sd_limit_mask lm;
        CHECK(sd_limit_mask_of(c, 0, v, &lm, NULL) == SD_OK);
        CHECK(lm.method == SD_LIMIT_LOOP && lm.n == 6 && lm.t1 && lm.t2);
        double st1 = 0, st2 = 0;
        for (int i = 0; i < lm.n; i++) {
            CHECK_NEAR(lm.w[i], lm.points[i] == v ? 0.5 : 0.1, 1e-15);
            st1 += lm.t1[i];
            st2 += lm.t2[i];
        }
        CHECK_NEAR(st1, 0, 1e-14);
        CHECK_NEAR(st2, 0, 1e-14);
        sd_limit_mask_free(&lm);
    }
    /* the limit normal of a vertex of the (centred) icosahedron points away from the centre */
    double x[36], n[36];
    CHECK(sd_complex_limit(c, 0, 0, x, n, NULL) == SD_OK);
    for (int v = 0; v < 12; v++) {
        const double *p = m.xyz + 3 * v;
        double r = sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
        CHECK_NEAR(fabs(n[3 * v] * p[0] + n[3 * v + 1] * p[1] + n[3 * v + 2] * p[2]) / r, 1, 1e-12);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(limit_level_solids_and_sharpness)
{
    mesh m = {0};
    shape_tet(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    CHECK(sd_complex_limit_level(c, 0) == 1 && sd_complex_limit_level(c, 3) == 3);
    sd_complex_free(c);
    mesh_free(&m);
    shape_icosahedron(&m);
    c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    sd_sharpness sh = {{0, 1, 0}, 2, 2.5f};
    uint32_t ne;
    const uint32_t *ev = sd_level_edges(sd_complex_level(c, 0, NULL), &ne);
    sh.v[0] = ev[0];
    sh.v[1] = ev[1];
    CHECK(sd_complex_set_sharpness(c, &sh, 1, SD_CREASE_UNIFORM, NULL) == SD_OK);
    CHECK(sd_complex_limit_level(c, 0) == 3 && sd_complex_limit_level(c, 4) == 4);
    sd_limit_mask lm;
    CHECK(sd_limit_mask_of(c, 0, ev[0], &lm, NULL) == SD_OK);
    CHECK(lm.eval_level == 3 && lm.level == 0);
    double sum = 0;
    for (int i = 0; i < lm.n; i++)
        sum += lm.w[i];
    CHECK_NEAR(sum, 1, 1e-13);
    sd_limit_mask_free(&lm);
    sd_complex_free(c);
    mesh_free(&m);
}
