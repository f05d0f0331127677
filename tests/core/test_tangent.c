/* test_tangent.c — sd_complex_set_tangents (003 Sec. 3's tangent-plane constraints): refusals
 * with their fields, what the modifications leave alone (the curve, the other sheets, chang-qin),
 * and edits and allocation failures on a constrained complex. The limit planes themselves are
 * checked against 003's petal analysis in tests/python/test_tangent_planes.py. */
#include "test.h"
#include <stdbool.h>

static const sd_options YZ = {.surface_weights = SD_WEIGHTS_LOOP,
                              .nonmanifold_surface = SD_NMSURF_YING_ZORIN};

/* shape_three_fins: spine 0 1 2 (1 simple, 0 and 2 complex), fin i = 3 + 3 i .. 5 + 3 i; at 1
 * each fin's petal is (0, 1, f1), (1, 2, f1). */
static sd_tangent_tag tangent(uint32_t fin, double x, double y, double z)
{
    uint32_t f = 3 + 3 * fin;
    return (sd_tangent_tag){.kind = SD_TT_TANGENT, .vertex = 1, .triangle = {0, 1, f + 1},
                            .vec = {x, y, z}};
}

static sd_tangent_tag edge(uint32_t a, uint32_t b)
{
    return (sd_tangent_tag){.kind = SD_TT_EDGE, .edge = {a, b}};
}

static int refused(sd_complex *c, const sd_tangent_tag *t, size_t n, sd_result code, long item,
                   int field)
{
    sd_error err;
    sd_result r = sd_complex_set_tangents(c, t, n, &err);
    return r == code && err.item == item && err.field == field;
}

TEST(tangent_refusals)
{
    mesh m = {0};
    shape_three_fins(&m);
    sd_error err;
    sd_complex *c = mesh_complex(&m, &YZ, &err);
    CHECK(c);
    sd_tangent_tag t[3] = {tangent(0, 1, 0, 0), tangent(1, -1, 0, 0), edge(0, 1)};
    CHECK(sd_complex_set_tangents(c, t, 3, &err) == SD_OK);
    sd_tangent_tag x = tangent(0, 1, 0, 0);
    x.vertex = 0; /* a complex vertex: no interior tangent */
    CHECK(refused(c, &x, 1, SD_ERR_ARG, 0, SD_TT_FIELD_VERTEX));
    x = tangent(0, 0, 0, 0);
    CHECK(refused(c, &x, 1, SD_ERR_VALUE, 0, SD_TT_FIELD_VECTOR));
    x = tangent(0, 0.1, 0, 1); /* the spine's direction at 1 (0 -> 2: 0.2, 0, 2) */
    CHECK(refused(c, &x, 1, SD_ERR_VALUE, 0, SD_TT_FIELD_VECTOR));
    x = tangent(0, NAN, 1, 0);
    CHECK(refused(c, &x, 1, SD_ERR_VALUE, 0, SD_TT_FIELD_VECTOR));
    x = tangent(0, 1, 0, 0);
    x.triangle[0] = 2, x.triangle[1] = 3 + 2, x.triangle[2] = 3 + 1; /* (2, f2, f1): not at 1 */
    CHECK(refused(c, &x, 1, SD_ERR_ARG, 0, SD_TT_FIELD_TRIANGLE));
    x.triangle[0] = 99;
    CHECK(refused(c, &x, 1, SD_ERR_INDEX, 0, SD_TT_FIELD_TRIANGLE));
    sd_tangent_tag two[2] = {tangent(0, 1, 0, 0), tangent(0, 0, 1, 0)};
    two[1].triangle[0] = 1, two[1].triangle[1] = 2; /* (1, 2, f1): the same petal */
    CHECK(refused(c, two, 2, SD_ERR_ARG, 1, SD_TT_FIELD_TRIANGLE));
    sd_tangent_tag e2[2] = {edge(1, 4), edge(0, 1)}; /* 1-4: inside fin 0 */
    CHECK(refused(c, e2, 2, SD_ERR_ARG, 0, SD_TT_FIELD_EDGE));
    e2[0] = edge(1, 0);
    CHECK(refused(c, e2, 2, SD_ERR_ARG, 1, SD_TT_FIELD_EDGE)); /* the same edge twice */
    e2[0] = edge(0, 2);
    CHECK(refused(c, e2, 1, SD_ERR_ARG, 0, SD_TT_FIELD_EDGE)); /* no such edge */
    e2[0] = edge(0, 1);
    e2[0].npair = 2;
    memcpy(e2[0].pair[0], (uint32_t[]){0, 1, 4}, sizeof e2[0].pair[0]);
    memcpy(e2[0].pair[1], (uint32_t[]){0, 1, 4}, sizeof e2[0].pair[1]);
    CHECK(refused(c, e2, 1, SD_ERR_ARG, 0, SD_TT_FIELD_PAIR1));
    sd_tangent_tag nrm = {.kind = SD_TT_NORMAL, .vertex = 1, .triangle = {0, 1, 4},
                          .vec = {0, 0, 1}};
    CHECK(refused(c, &nrm, 1, SD_ERR_ARG, 0, SD_TT_FIELD_VERTEX)); /* simple: no closed petal */
    nrm.vertex = 0;
    CHECK(refused(c, &nrm, 1, SD_ERR_ARG, 0, SD_TT_FIELD_TRIANGLE)); /* 0's petals are open */
    /* the accepted tags stayed */
    const sd_level *l1 = sd_complex_level(c, 1, &err);
    CHECK(l1);
    sd_complex_free(c);
    mesh_free(&m);
}

static double *levels(sd_complex *c, size_t *n)
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

static sd_complex *constrained(const mesh *m, const sd_options *o, sd_error *err)
{
    sd_complex *c = mesh_complex(m, o, err);
    sd_tangent_tag t[4] = {tangent(0, 0.2, 1, 0.3), tangent(1, -0.2, -1, -0.3), edge(0, 1),
                           edge(1, 2)};
    if (c && sd_complex_set_tangents(c, t, 4, err)) {
        sd_complex_free(c);
        return NULL;
    }
    return c;
}

/* Which fin a level-L point belongs to: 0..2, or 3 on the spine (x y z near the spine). */
static int fin_of(const sd_level *lv, uint32_t v)
{
    int nc;
    const double *x = sd_level_channel(lv, 0, &nc) + 3 * (size_t)v;
    if (hypot(x[0] - 0.05 * x[2] * x[2], x[1]) < 0.02)
        return 3;
    double a = atan2(x[1], x[0]);
    int best = 0;
    double bd = 10;
    for (int i = 0; i < 3; i++) {
        double d = fabs(remainder(a - (2 * M_PI * i / 3 + 0.1 * i), 2 * M_PI));
        if (d < bd)
            bd = d, best = i;
    }
    return best;
}

TEST(tangent_moves_only_the_constrained_sheets)
{
    mesh m = {0};
    shape_three_fins(&m);
    sd_error err;
    sd_complex *plain = mesh_complex(&m, &YZ, &err), *c = constrained(&m, &YZ, &err);
    CHECK(plain && c);
    size_t np = 0, nc = 0;
    double *a = levels(plain, &np), *b = levels(c, &nc);
    CHECK(a && b && np == nc);
    /* the curve and fin 2 keep their points; fins 0 and 1 move near the curve */
    size_t at = 0;
    int moved[4] = {0};
    for (int L = 0; L <= 2; L++) {
        const sd_level *lv = sd_complex_level(plain, L, &err);
        for (uint32_t v = 0; v < sd_level_num_vertices(lv); v++, at += 3) {
            int f = fin_of(lv, v);
            double d = 0;
            for (int q = 0; q < 3; q++)
                d += fabs(a[at + q] - b[at + q]);
            if (d > 1e-12)
                moved[f]++;
        }
    }
    CHECK(moved[0] > 0 && moved[1] > 0 && moved[2] == 0 && moved[3] == 0);
    /* chang-qin: the tags are kept and do nothing */
    sd_options cq = YZ;
    cq.nonmanifold_surface = SD_NMSURF_CHANG_QIN;
    sd_complex *p2 = mesh_complex(&m, &cq, &err), *c2 = constrained(&m, &cq, &err);
    CHECK(p2 && c2);
    size_t n2 = 0, n3 = 0;
    double *x2 = levels(p2, &n2), *x3 = levels(c2, &n3);
    CHECK(x2 && x3 && n2 == n3 && !memcmp(x2, x3, n2 * sizeof *x2));
    free(a), free(b), free(x2), free(x3);
    sd_complex_free(plain), sd_complex_free(c), sd_complex_free(p2), sd_complex_free(c2);
    mesh_free(&m);
}

TEST(tangent_edit_is_a_fresh_build_and_all_or_nothing)
{
    mesh m = {0};
    shape_three_fins(&m);
    const uint32_t moved = 4; /* fin 0's f1: in the constrained petal at 1 */
    const double to[3] = {1.2, 0.3, 1.1};
    sd_error err;
    mesh w = m;
    double *xyz = malloc(3 * m.nv * sizeof *xyz);
    memcpy(xyz, m.xyz, 3 * m.nv * sizeof *xyz);
    memcpy(xyz + 3 * moved, to, sizeof to);
    w.xyz = xyz;
    sd_complex *ref = constrained(&w, &YZ, &err);
    CHECK(ref);
    size_t nref = 0;
    double *want = levels(ref, &nref);
    CHECK(want);
    long n = 1;
    for (;; n++) {
        counting cc = {0, -1, 0};
        sd_options o = YZ;
        o.allocator = TEST_COUNTING(&cc);
        sd_complex *c = constrained(&m, &o, &err);
        CHECK(c);
        size_t nb = 0;
        double *b = levels(c, &nb);
        CHECK(b && nb == nref);
        uint64_t counts[SD_MAX_LEVEL + 1];
        cc.fail_at = cc.calls + n;
        sd_result r = sd_complex_edit(c, 0, 1, &moved, to, counts, &err);
        bool reached = cc.calls >= cc.fail_at;
        cc.fail_at = -1;
        size_t na = 0;
        double *a = levels(c, &na);
        CHECK(a && na == nref);
        CHECK(r == SD_OK || err.code == SD_ERR_NOMEM);
        const double *expect = r == SD_OK ? want : b;
        double d = 0;
        for (size_t i = 0; i < nref; i++)
            d = fmax(d, fabs(a[i] - expect[i]));
        CHECK(d < 1e-12);
        free(a);
        free(b);
        sd_complex_free(c);
        CHECK(cc.bytes == 0);
        if (!reached)
            break;
    }
    CHECK(n > 30);
    free(want);
    free(xyz);
    sd_complex_free(ref);
    mesh_free(&m);
}

/* A move at level 1 of a point a modification moves (fin 0's inner point on edge 1-4): the point
 * goes where asked, and its offset is against S p plus the modification, so a new complex given
 * that offset builds the same levels, bit for bit (the session store's round trip). */
TEST(tangent_level1_move_offsets_are_against_the_modified_points)
{
    mesh m = {0};
    shape_three_fins(&m);
    sd_error err;
    sd_complex *c = constrained(&m, &YZ, &err);
    CHECK(c);
    const sd_level *l1 = sd_complex_level(c, 1, &err);
    CHECK(l1);
    const uint32_t e = sd_level_find_edge(sd_complex_level(c, 0, &err), 1, 4);
    CHECK(e != UINT32_MAX);
    sd_vertex_at at = {1, (uint32_t)m.nv + e};
    const double to[3] = {0.9, 0.2, 1.3};
    CHECK(sd_complex_move(c, 0, 1, &at, to, NULL, &err) == SD_OK);
    int nc;
    const double *x = sd_level_channel(sd_complex_level(c, 1, &err), 0, &nc) + 3 * at.index;
    CHECK(fabs(x[0] - to[0]) + fabs(x[1] - to[1]) + fabs(x[2] - to[2]) < 1e-12);
    const uint32_t *idx;
    const double *off;
    CHECK(sd_complex_details(c, 0, 1, &idx, &off) == 1 && idx[0] == at.index);
    sd_complex *d = constrained(&m, &YZ, &err);
    CHECK(d && sd_complex_set_details(d, 0, 1, &at, off, NULL, &err) == SD_OK);
    size_t na = 0, nb = 0;
    double *a = levels(c, &na), *b = levels(d, &nb);
    CHECK(a && b && na == nb && !memcmp(a, b, na * sizeof *a)); /* bit for bit */
    free(a), free(b);
    sd_complex_free(c), sd_complex_free(d);
    mesh_free(&m);
}
