/* Embedded models (core/embed.c; 004 Sec. 5.1, eq. 13). Expected values come from outside the
 * module: barycentric coordinates from the random ones a point was made with and from a 4x4
 * homogeneous solve by Gaussian elimination written here; an octahedron's 4 tetrahedra from the
 * paper's split around its major diagonal (as vertex sets); the deformed model from the affine
 * map applied here, and from a before/after comparison of the level's positions. */
#include "test.h"
#include <stdbool.h>

static uint64_t rng = 777;
static double urand(void)
{
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(rng >> 11) / 9007199254740992.0;
}

/* Random barycentric coordinates, each at least 0.02. */
static void rand_lam(double l[4])
{
    double s = 0;
    for (int k = 0; k < 4; k++)
        s += l[k] = 0.02 / 0.92 + urand();
    for (int k = 0; k < 4; k++)
        l[k] /= s;
}

/* Cell c of a level as 4 vertex ids: tetrahedra first, then octahedron o's k-th tetrahedron
 * around its major diagonal (p,q): (p,q,a,b), (p,q,b,a2), (p,q,a2,b2), (p,q,b2,a) — as sets. */
static uint32_t ncells(const sd_level *lv)
{
    return sd_level_num_cells(lv, SD_CELL_TETRA) + 4 * sd_level_num_cells(lv, SD_CELL_OCTA);
}
static void cell_of(const sd_level *lv, uint32_t c, uint32_t v[4])
{
    uint32_t T = sd_level_num_cells(lv, SD_CELL_TETRA);
    if (c < T) {
        sd_level_cell(lv, SD_CELL_TETRA, c, v);
        return;
    }
    uint32_t o[6];
    sd_level_cell(lv, SD_CELL_OCTA, (c - T) / 4, o);
    const uint32_t p = o[0], q = o[1], a = o[2], a2 = o[3], b = o[4], b2 = o[5];
    const uint32_t t[4][2] = {{a, b}, {b, a2}, {a2, b2}, {b2, a}};
    v[0] = p;
    v[1] = q;
    v[2] = t[(c - T) % 4][0];
    v[3] = t[(c - T) % 4][1];
}

/* Weight of level vertex id in a binding (0 if absent). */
static double weight_of(const uint32_t idx[4], const double w[4], uint32_t id)
{
    for (int k = 0; k < 4; k++)
        if (idx[k] == id)
            return w[k];
    return 0;
}
static bool same_set(const uint32_t a[4], const uint32_t b[4])
{
    for (int i = 0; i < 4; i++) {
        bool f = false;
        for (int j = 0; j < 4; j++)
            f |= a[i] == b[j];
        if (!f)
            return false;
    }
    return true;
}

/* Solve [v0 v1 v2 v3; 1 1 1 1] w = [p; 1] by Gaussian elimination with partial pivoting. */
static void solve4(const double *x, const uint32_t v[4], const double *p, double w[4])
{
    double A[4][5];
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 4; c++)
            A[r][c] = x[3 * v[c] + r];
        A[r][4] = p[r];
    }
    for (int c = 0; c < 4; c++)
        A[3][c] = 1;
    A[3][4] = 1;
    for (int c = 0; c < 4; c++) {
        int piv = c;
        for (int r = c + 1; r < 4; r++)
            if (fabs(A[r][c]) > fabs(A[piv][c]))
                piv = r;
        for (int k = 0; k < 5; k++) {
            double t = A[c][k];
            A[c][k] = A[piv][k];
            A[piv][k] = t;
        }
        for (int r = 0; r < 4; r++)
            if (r != c) {
                double f = A[r][c] / A[c][c];
                for (int k = c; k < 5; k++)
                    A[r][k] -= f * A[c][k];
            }
    }
    for (int c = 0; c < 4; c++)
        w[c] = A[c][4] / A[c][c];
}

/* n random points in random cells of lv (made from random coordinates). */
static double *points_in(const sd_level *lv, size_t n, uint32_t *cell, double *lam)
{
    const double *x = sd_level_channel(lv, 0, NULL);
    double *p = malloc(3 * n * sizeof *p);
    for (size_t i = 0; i < n; i++) {
        uint32_t c = (uint32_t)(urand() * ncells(lv)), v[4];
        double l[4];
        rand_lam(l);
        cell_of(lv, c, v);
        for (int k = 0; k < 3; k++)
            p[3 * i + k] = l[0] * x[3 * v[0] + k] + l[1] * x[3 * v[1] + k] +
                           l[2] * x[3 * v[2] + k] + l[3] * x[3 * v[3] + k];
        if (cell)
            cell[i] = c;
        if (lam)
            memcpy(lam + 4 * i, l, sizeof l);
    }
    return p;
}

TEST(embed_barycentric_tets_and_octahedron)
{
    mesh m = {0};
    shape_tet(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 1, NULL);
    CHECK(lv && sd_level_num_cells(lv, SD_CELL_TETRA) == 4 && sd_level_num_cells(lv, SD_CELL_OCTA) == 1);
    const double *x = sd_level_channel(lv, 0, NULL);
    enum { PER = 40, N = 8 * PER };
    double p[3 * N], lam[4 * N];
    uint32_t cell[N];
    for (uint32_t i = 0; i < N; i++) { /* PER points in each of the 8 cells */
        uint32_t v[4];
        cell[i] = i / PER;
        cell_of(lv, cell[i], v);
        rand_lam(lam + 4 * i);
        for (int k = 0; k < 3; k++) {
            p[3 * i + k] = 0;
            for (int j = 0; j < 4; j++)
                p[3 * i + k] += lam[4 * i + j] * x[3 * v[j] + k];
        }
    }
    sd_embedding *e = NULL;
    sd_bind_report rep;
    sd_error err;
    CHECK(sd_embed_bind(lv, p, N, SD_OUTSIDE_REFUSE, NULL, 0, &e, &rep, &err) == SD_OK);
    CHECK(rep.outside == 0 && sd_embed_count(e) == N && sd_embed_memory(e) > 0);
    for (uint32_t i = 0; i < N; i++) {
        uint32_t v[4], idx[4];
        double w[4], g[4];
        cell_of(lv, cell[i], v);
        CHECK(sd_embed_weights(e, i, idx, w) == 1);
        CHECK(same_set(v, idx));
        solve4(x, idx, p + 3 * i, g);
        double s = 0;
        for (int k = 0; k < 4; k++) {
            CHECK_NEAR(weight_of(idx, w, v[k]), lam[4 * i + k], 1e-12);
            CHECK_NEAR(w[k], g[k], 1e-12);
            s += w[k];
        }
        CHECK_NEAR(s, 1, 1e-14);
    }
    sd_embed_free(e);
    /* points anywhere in the tetrahedron: weights against the independent solve */
    for (uint32_t i = 0; i < N; i++) {
        double l[4];
        rand_lam(l);
        const double *x0 = sd_level_channel(sd_complex_level(c, 0, NULL), 0, NULL);
        for (int k = 0; k < 3; k++)
            p[3 * i + k] = l[0] * x0[k] + l[1] * x0[3 + k] + l[2] * x0[6 + k] + l[3] * x0[9 + k];
    }
    rep.outside = 1;
    CHECK(sd_embed_bind(lv, p, N, SD_OUTSIDE_FIXED, NULL, 0, &e, &rep, &err) == SD_OK);
    for (uint32_t i = 0; i < N; i++) {
        uint32_t idx[4];
        double w[4], g[4];
        if (!sd_embed_weights(e, i, idx, w))
            continue; /* the level-1 solid is smaller than its control tetrahedron */
        solve4(x, idx, p + 3 * i, g);
        for (int k = 0; k < 4; k++) {
            CHECK(w[k] >= -1e-12);
            CHECK_NEAR(w[k], g[k], 1e-12);
        }
    }
    sd_embed_free(e);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(embed_rest_positions)
{
    mesh m = {0};
    shape_two_tets(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 2, NULL);
    CHECK(lv);
    enum { N = 3000 };
    double *p = points_in(lv, N, NULL, NULL), *q = malloc(3 * N * sizeof *q);
    sd_embedding *e = NULL;
    CHECK(sd_embed_bind(lv, p, N, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, NULL) == SD_OK);
    sd_embed_positions(e, lv, q);
    for (size_t i = 0; i < 3 * N; i++)
        CHECK_NEAR(q[i], p[i], 1e-12);
    sd_embed_free(e);
    free(p);
    free(q);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(embed_affine_map)
{
    mesh m = {0};
    shape_cube_tets(&m, 2);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 2, NULL);
    CHECK(lv);
    enum { N = 4000 };
    double *p = points_in(lv, N, NULL, NULL), *q = malloc(3 * N * sizeof *q);
    sd_embedding *e = NULL;
    CHECK(sd_embed_bind(lv, p, N, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, NULL) == SD_OK);
    const double A[3][3] = {{1.2, 0.3, -0.1}, {-0.2, 0.9, 0.4}, {0.1, -0.3, 1.5}}, b[3] = {3, -1, 0.5};
    const double *x0 = sd_level_channel(sd_complex_level(c, 0, NULL), 0, NULL);
    uint32_t *idx = malloc(m.nv * sizeof *idx);
    double *to = malloc(3 * m.nv * sizeof *to);
    for (size_t v = 0; v < m.nv; v++) {
        idx[v] = (uint32_t)v;
        for (int r = 0; r < 3; r++)
            to[3 * v + r] = b[r] + A[r][0] * x0[3 * v] + A[r][1] * x0[3 * v + 1] + A[r][2] * x0[3 * v + 2];
    }
    CHECK(sd_complex_edit(c, 0, m.nv, idx, to, NULL, NULL) == SD_OK);
    CHECK(sd_complex_level(c, 2, NULL) == lv);
    sd_embed_positions(e, lv, q);
    for (size_t i = 0; i < N; i++)
        for (int r = 0; r < 3; r++)
            CHECK_NEAR(q[3 * i + r], b[r] + A[r][0] * p[3 * i] + A[r][1] * p[3 * i + 1] +
                                         A[r][2] * p[3 * i + 2], 1e-9);
    sd_embed_free(e);
    free(idx);
    free(to);
    free(p);
    free(q);
    sd_complex_free(c);
    mesh_free(&m);
}

typedef struct changed_list {
    uint32_t *v;
    size_t n;
    int level;
} changed_list;
static void on_changed(void *ud, int level, const uint32_t *idx, size_t n)
{
    changed_list *l = ud;
    if (level != l->level)
        return;
    l->v = realloc(l->v, (l->n + 2 * n + 1) * sizeof *l->v);
    for (size_t i = 0; i < n; i++) { /* each twice: update must dedupe */
        l->v[l->n++] = idx[i];
        l->v[l->n++] = idx[n - 1 - i];
    }
}

TEST(embed_locality_and_update)
{
    mesh m = {0};
    shape_cube_tets(&m, 3);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 2, NULL);
    CHECK(lv);
    enum { N = 20000 };
    double *p = points_in(lv, N, NULL, NULL);
    sd_embedding *e = NULL;
    CHECK(sd_embed_bind(lv, p, N, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, NULL) == SD_OK);
    const uint32_t nlv = sd_level_num_vertices(lv);
    double *before = malloc(3 * (size_t)nlv * sizeof *before);
    double *m0 = malloc(3 * N * sizeof *m0), *m1 = malloc(3 * N * sizeof *m1),
           *up = malloc(3 * N * sizeof *up);
    uint32_t *moved = malloc(N * sizeof *moved);
    for (int round = 0; round < 3; round++) {
        memcpy(before, sd_level_channel(lv, 0, NULL), 3 * (size_t)nlv * sizeof *before);
        sd_embed_positions(e, lv, m0);
        uint32_t cp = (uint32_t)(urand() * m.nv);
        const double *x0 = sd_level_channel(sd_complex_level(c, 0, NULL), 0, NULL);
        double to[3] = {x0[3 * cp] + 0.2, x0[3 * cp + 1] - 0.1, x0[3 * cp + 2] + 0.15};
        changed_list cl = {NULL, 0, 2};
        sd_edit_report rep = {0};
        rep.changed = on_changed;
        rep.ud = &cl;
        sd_vertex_at at = {0, cp};
        CHECK(sd_complex_move(c, 0, 1, &at, to, &rep, NULL) == SD_OK);
        const double *after = sd_level_channel(lv, 0, NULL);
        uint8_t *ch = calloc(nlv, 1);
        size_t nch = 0;
        for (uint32_t v = 0; v < nlv; v++)
            if (memcmp(before + 3 * (size_t)v, after + 3 * (size_t)v, 3 * sizeof *after)) {
                ch[v] = 1;
                nch++;
            }
        CHECK(nch > 0 && nch < nlv);
        sd_embed_positions(e, lv, m1);
        uint32_t *expect = malloc(N * sizeof *expect);
        size_t ne = 0;
        for (uint32_t i = 0; i < N; i++) {
            uint32_t idx[4];
            double w[4];
            CHECK(sd_embed_weights(e, i, idx, w));
            if (ch[idx[0]] | ch[idx[1]] | ch[idx[2]] | ch[idx[3]])
                expect[ne++] = i;
            else
                CHECK(!memcmp(m0 + 3 * i, m1 + 3 * i, 3 * sizeof *m1));
        }
        CHECK(ne > 0 && ne < N);
        memcpy(up, m0, 3 * N * sizeof *up);
        size_t k = sd_embed_update(e, lv, cl.v, cl.n, up, moved);
        CHECK(k == ne);
        CHECK(!memcmp(moved, expect, ne * sizeof *moved));
        CHECK(!memcmp(up, m1, 3 * N * sizeof *up));
        /* the level vertices found by comparison, in the other direction and twice */
        uint32_t *cv = malloc(2 * nch * sizeof *cv);
        size_t q = 0;
        for (uint32_t v = nlv; v-- > 0;)
            if (ch[v])
                cv[q++] = v;
        memcpy(cv + nch, cv, nch * sizeof *cv);
        memcpy(up, m0, 3 * N * sizeof *up);
        CHECK(sd_embed_update(e, lv, cv, 2 * nch, up, moved) == ne);
        CHECK(!memcmp(moved, expect, ne * sizeof *moved) && !memcmp(up, m1, 3 * N * sizeof *up));
        CHECK(sd_embed_update(e, lv, NULL, 0, up, moved) == 0);
        free(cv);
        free(expect);
        free(ch);
        free(cl.v);
    }
    sd_embed_free(e);
    free(before);
    free(m0);
    free(m1);
    free(up);
    free(moved);
    free(p);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(embed_outside_modes)
{
    mesh m = {0};
    shape_cube_tets(&m, 1);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 1, NULL);
    CHECK(lv);
    enum { N = 200 };
    double *p = points_in(lv, N, NULL, NULL);
    const double out[][3] = {{2, 2, 2}, {-1, 0.5, 0.5}, {0.5, 0.5, 3}, {0.5, -0.01, 0.5},
                             {-0.3, -0.3, -0.3}, {40, -7, 3}, {0.5, 0.5, -2}, {1.2, 0.4, 0.6},
                             {0.5, 1.5, 0.5}, {-2, -2, 5}};
    const size_t nout = sizeof out / sizeof *out, where[] = {3, 17, 18, 50, 51, 52, 90, 120, 121, 199};
    for (size_t j = 0; j < nout; j++)
        memcpy(p + 3 * where[j], out[j], sizeof out[j]);
    sd_embedding *e = (sd_embedding *)&m; /* overwritten with NULL */
    sd_bind_report rep;
    sd_error err;
    CHECK(sd_embed_bind(lv, p, N, SD_OUTSIDE_REFUSE, NULL, 0, &e, &rep, &err) == SD_ERR_VALUE);
    CHECK(e == NULL && err.item == 3);
    CHECK(rep.outside == nout && rep.nfirst == 8);
    for (int j = 0; j < 8; j++)
        CHECK(rep.first[j] == where[j]);

    double *q = malloc(3 * N * sizeof *q);
    CHECK(sd_embed_bind(lv, p, N, SD_OUTSIDE_FIXED, NULL, 0, &e, &rep, &err) == SD_OK);
    CHECK(rep.outside == nout);
    uint32_t idx[4];
    double w[4];
    for (size_t j = 0; j < nout; j++)
        CHECK(sd_embed_weights(e, where[j], idx, w) == 0);
    sd_embedding *en = NULL;
    CHECK(sd_embed_bind(lv, p, N, SD_OUTSIDE_NEAREST, NULL, 0, &en, &rep, &err) == SD_OK);
    CHECK(rep.outside == nout);
    sd_embed_positions(en, lv, q);
    const double *x = sd_level_channel(lv, 0, NULL);
    const uint32_t nlv = sd_level_num_vertices(lv);
    for (size_t j = 0; j < nout; j++) {
        CHECK(sd_embed_weights(en, where[j], idx, w) == 1);
        CHECK(w[0] < 0 || w[1] < 0 || w[2] < 0 || w[3] < 0);
        CHECK_NEAR(w[0] + w[1] + w[2] + w[3], 1, 1e-12);
        for (int k = 0; k < 3; k++)
            CHECK_NEAR(q[3 * where[j] + k], out[j][k], 1e-9 * (1 + fabs(out[j][k])));
    }
    /* beyond a corner of the block, the nearest cell holds the level vertex nearest to it */
    for (size_t j = 4; j < 6; j += 1) {
        uint32_t best = 0;
        double bd = INFINITY;
        for (uint32_t v = 0; v < nlv; v++) {
            double d = 0;
            for (int k = 0; k < 3; k++)
                d += (x[3 * v + k] - out[j][k]) * (x[3 * v + k] - out[j][k]);
            if (d < bd) {
                bd = d;
                best = v;
            }
        }
        CHECK(sd_embed_weights(en, where[j], idx, w) == 1);
        CHECK(idx[0] == best || idx[1] == best || idx[2] == best || idx[3] == best);
    }
    /* after an edit: the fixed ones stay, bitwise */
    uint32_t cp = 0;
    double to[3] = {-0.5, -0.4, -0.3};
    CHECK(sd_complex_edit(c, 0, 1, &cp, to, NULL, NULL) == SD_OK);
    sd_embed_positions(e, lv, q);
    for (size_t j = 0; j < nout; j++)
        CHECK(!memcmp(q + 3 * where[j], out[j], sizeof out[j]));
    sd_embed_free(e);
    sd_embed_free(en);
    free(p);
    free(q);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(embed_shared_face_lowest_index)
{
    for (int flip = 0; flip < 2; flip++) {
        mesh m = {0};
        mesh_v(&m, 0, 0, 0);
        mesh_v(&m, 1, 0, 0);
        mesh_v(&m, 0, 1, 0);
        mesh_v(&m, 0, 0, 1);
        mesh_v(&m, 1, 1, 1);
        if (flip) {
            mesh_s(&m, 4, 1, 2, 3, 4);
            mesh_s(&m, 4, 0, 1, 2, 3);
        } else {
            mesh_s(&m, 4, 0, 1, 2, 3);
            mesh_s(&m, 4, 1, 2, 3, 4);
        }
        sd_complex *c = mesh_complex(&m, NULL, NULL);
        const sd_level *lv = sd_complex_level(c, 0, NULL);
        const double p[] = {0.25, 0.25, 0.5, 0.5, 0.25, 0.25, 0.125, 0.375, 0.5};
        sd_embedding *e = NULL;
        CHECK(sd_embed_bind(lv, p, 3, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, NULL) == SD_OK);
        for (size_t i = 0; i < 3; i++) {
            uint32_t idx[4], v[4];
            double w[4];
            CHECK(sd_embed_weights(e, i, idx, w));
            sd_level_cell(lv, SD_CELL_TETRA, 0, v);
            CHECK(same_set(idx, v));
            CHECK(fabs(weight_of(idx, w, flip ? 4 : 0)) < 1e-15);
        }
        sd_embed_free(e);
        sd_complex_free(c);
        mesh_free(&m);
    }
    /* level 1 of a tetrahedron: a face between a corner tetrahedron and the octahedron goes to
     * the corner; the octahedron's major diagonal to its first tetrahedron */
    mesh m = {0};
    shape_tet(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 1, NULL);
    const double *x = sd_level_channel(lv, 0, NULL);
    uint32_t o[6], t[4];
    sd_level_cell(lv, SD_CELL_OCTA, 0, o);
    double p[6];
    for (int k = 0; k < 3; k++)
        p[3 + k] = 0.3 * x[3 * o[0] + k] + 0.7 * x[3 * o[1] + k];
    int found = -1;
    for (uint32_t ct = 0; ct < 4 && found < 0; ct++) { /* a face of corner ct that is the octahedron's */
        sd_level_cell(lv, SD_CELL_TETRA, ct, t);
        for (int skip = 0; skip < 4 && found < 0; skip++) {
            int in = 0;
            for (int j = 0; j < 4; j++)
                for (int k = 0; k < 6; k++)
                    in += j != skip && t[j] == o[k];
            if (in == 3) {
                found = (int)ct;
                for (int k = 0; k < 3; k++) {
                    p[k] = 0;
                    for (int j = 0; j < 4; j++)
                        p[k] += j == skip ? 0 : x[3 * t[j] + k] / 3;
                }
            }
        }
    }
    CHECK(found >= 0);
    sd_embedding *e = NULL;
    CHECK(sd_embed_bind(lv, p, 2, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, NULL) == SD_OK);
    uint32_t idx[4], v[4];
    double w[4];
    CHECK(sd_embed_weights(e, 0, idx, w));
    sd_level_cell(lv, SD_CELL_TETRA, (uint32_t)found, v);
    CHECK(same_set(idx, v));
    CHECK(sd_embed_weights(e, 1, idx, w));
    cell_of(lv, 4, v);
    CHECK(same_set(idx, v));
    CHECK_NEAR(weight_of(idx, w, o[0]), 0.3, 1e-12);
    CHECK_NEAR(weight_of(idx, w, o[1]), 0.7, 1e-12);
    sd_embed_free(e);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(embed_errors)
{
    mesh m = {0};
    shape_icosahedron(&m); /* a surface: no solid cells */
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 0, NULL);
    double p[6] = {0, 0, 0, 0.1, 0.1, 0.1};
    sd_embedding *e = NULL;
    sd_error err;
    CHECK(sd_embed_bind(lv, p, 2, SD_OUTSIDE_NEAREST, NULL, 0, &e, NULL, &err) == SD_ERR_VALUE && !e);
    CHECK(strstr(err.message, "no solid cells"));
    sd_complex_free(c);
    mesh_free(&m);

    shape_cube_tets(&m, 2);
    c = mesh_complex(&m, NULL, NULL);
    lv = sd_complex_level(c, 1, NULL);
    CHECK(sd_embed_bind(NULL, p, 2, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, &err) == SD_ERR_ARG);
    CHECK(sd_embed_bind(lv, p, 2, (sd_outside)7, NULL, 0, &e, NULL, &err) == SD_ERR_ARG);
    p[4] = NAN;
    CHECK(sd_embed_bind(lv, p, 2, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, &err) == SD_ERR_VALUE);
    CHECK(err.item == 1 && err.field == 1 && !e);
    p[0] = p[1] = p[2] = 1; /* inside the block [0,2]^3 */
    p[3] = 1.1;
    p[4] = 0.9;
    p[5] = 1.2;
    CHECK(sd_embed_bind(lv, p, 2, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, &err) == SD_OK);
    size_t used = sd_embed_memory(e);
    sd_embed_free(e);
    CHECK(sd_embed_bind(lv, NULL, 0, SD_OUTSIDE_REFUSE, NULL, 0, &e, NULL, &err) == SD_OK);
    CHECK(sd_embed_count(e) == 0);
    sd_embed_free(e);
    /* limits: the permanent part, then the locating grid */
    CHECK(sd_embed_bind(lv, p, 2, SD_OUTSIDE_REFUSE, NULL, 100, &e, NULL, &err) == SD_ERR_LIMIT && !e);
    CHECK(sd_embed_bind(lv, p, 2, SD_OUTSIDE_REFUSE, NULL, used + 64, &e, NULL, &err) == SD_ERR_LIMIT);
    /* every allocation failing in turn: no leak, no result */
    for (long k = 1;; k++) {
        counting cn = {0, k, 0};
        sd_allocator a = TEST_COUNTING(&cn);
        sd_result r = sd_embed_bind(lv, p, 2, SD_OUTSIDE_NEAREST, &a, 0, &e, NULL, &err);
        if (r == SD_OK) {
            CHECK(k > 3 && cn.bytes > 0 && (size_t)cn.bytes == sd_embed_memory(e));
            sd_embed_free(e);
            CHECK(cn.bytes == 0);
            break;
        }
        CHECK(r == SD_ERR_NOMEM && !e && cn.bytes == 0);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

/* Every level vertex and every edge midpoint of a level (on many shared faces at once) goes to
 * the lowest-numbered cell that has it: the first cell listing the vertex, or both ends. */
TEST(embed_vertices_and_edges_lowest_cell)
{
    mesh m = {0};
    shape_cube_tets(&m, 2);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 1, NULL);
    CHECK(lv);
    const double *x = sd_level_channel(lv, 0, NULL);
    const uint32_t nv = sd_level_num_vertices(lv), nc = ncells(lv);
    uint32_t ne = 0;
    const uint32_t *ev = sd_level_edges(lv, &ne);
    CHECK(ev && ne > 0);
    const size_t n = nv + ne;
    double *p = malloc(3 * n * sizeof *p);
    uint32_t *expect = malloc(n * sizeof *expect);
    for (size_t i = 0; i < n; i++) {
        uint32_t a = i < nv ? (uint32_t)i : ev[2 * (i - nv)], b = i < nv ? a : ev[2 * (i - nv) + 1];
        for (int k = 0; k < 3; k++)
            p[3 * i + k] = 0.5 * (x[3 * a + k] + x[3 * b + k]);
        expect[i] = UINT32_MAX;
        for (uint32_t q = 0; q < nc && expect[i] == UINT32_MAX; q++) {
            uint32_t v[4];
            cell_of(lv, q, v);
            bool ha = false, hb = false;
            for (int k = 0; k < 4; k++) {
                ha |= v[k] == a;
                hb |= v[k] == b;
            }
            if (ha && hb)
                expect[i] = q;
        }
        CHECK(expect[i] != UINT32_MAX);
    }
    sd_embedding *e = NULL;
    sd_bind_report rep;
    CHECK(sd_embed_bind(lv, p, n, SD_OUTSIDE_REFUSE, NULL, 0, &e, &rep, NULL) == SD_OK);
    for (size_t i = 0; i < n; i++) {
        uint32_t idx[4], v[4];
        double w[4];
        CHECK(sd_embed_weights(e, i, idx, w));
        cell_of(lv, expect[i], v);
        CHECK(same_set(idx, v));
        uint32_t a = i < nv ? (uint32_t)i : ev[2 * (i - nv)], b = i < nv ? a : ev[2 * (i - nv) + 1];
        CHECK_NEAR(weight_of(idx, w, a) + (a == b ? 0 : weight_of(idx, w, b)), 1, 1e-12);
    }
    sd_embed_free(e);
    free(p);
    free(expect);
    sd_complex_free(c);
    mesh_free(&m);
}

/* The tolerance is a distance: 1e-12 of the longest edge beyond a face plane, also for a flat
 * cell whose barycentric coordinate is then far below -1e-12. */
TEST(embed_tolerance_is_a_distance)
{
    mesh m = {0};
    mesh_v(&m, 0, 0, 0);
    mesh_v(&m, 1, 0, 0);
    mesh_v(&m, 0, 1, 0);
    mesh_v(&m, 0.3, 0.3, 1e-3);
    mesh_s(&m, 4, 0, 1, 2, 3);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    const sd_level *lv = sd_complex_level(c, 0, NULL);
    const double L = sqrt(2.0); /* the edge (1,0,0)-(0,1,0) */
    const double p[6] = {0.2, 0.2, -0.5e-12 * L, 0.2, 0.2, -2e-12 * L};
    sd_embedding *e = NULL;
    sd_bind_report rep;
    CHECK(sd_embed_bind(lv, p, 2, SD_OUTSIDE_FIXED, NULL, 0, &e, &rep, NULL) == SD_OK);
    CHECK(rep.outside == 1 && rep.first[0] == 1);
    uint32_t idx[4];
    double w[4];
    CHECK(sd_embed_weights(e, 0, idx, w) == 1);
    CHECK(weight_of(idx, w, 3) < -1e-10); /* z / height: far below -1e-12 */
    CHECK(sd_embed_weights(e, 1, idx, w) == 0);
    sd_embed_free(e);
    sd_complex_free(c);
    mesh_free(&m);
}
