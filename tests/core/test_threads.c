/* test_threads.c — sd_options.threads: every level is the same bytes whatever the number of
 * threads (positions, channels, cells, edges, origins, rules, classes, solid boundary, matrices),
 * on meshes large enough that the parallel regions really split (core/par.c). */
#include "test.h"

#define DIFF(what)                                                                                 \
    do {                                                                                           \
        fprintf(stderr, "threads: %s differs (line %d)\n", what, __LINE__);                        \
        return 0;                                                                                  \
    } while (0)

/* Level `top` of `m` with each thread count must equal the serial result. */
static int same_levels(const mesh *m, const sd_options *base, int top)
{
    sd_complex *c[3];
    const int threads[3] = {1, 2, 3};
    for (int i = 0; i < 3; i++) {
        sd_options o = *base;
        o.threads = threads[i];
        c[i] = mesh_complex(m, &o, NULL);
        if (!c[i])
            DIFF("a level");
        double attr[2 * 64];
        for (size_t v = 0; v < 2 * 64 && v < 2 * m->nv; v++)
            attr[v] = sin((double)v);
        if (m->nv <= 64 && sd_complex_add_channel(c[i], attr, 2, NULL) != 1)
            DIFF("a level");
        if (!sd_complex_level(c[i], top, NULL))
            DIFF("a level");
    }
    for (int l = 0; l <= top; l++) {
        const sd_level *a = sd_complex_level(c[0], l, NULL);
        for (int i = 1; i < 3; i++) {
            const sd_level *b = sd_complex_level(c[i], l, NULL);
            uint32_t nv = sd_level_num_vertices(a);
            if (sd_level_num_vertices(b) != nv)
                DIFF("a level");
            for (int ch = 0; ch < 2; ch++) {
                int na = 0, nb = 0;
                const double *pa = sd_level_channel(a, ch, &na), *pb = sd_level_channel(b, ch, &nb);
                if ((pa == NULL) != (pb == NULL) || na != nb ||
                    (pa && memcmp(pa, pb, (size_t)nv * na * sizeof *pa)))
                    DIFF("a level");
            }
            for (int k = 0; k < 5; k++) {
                uint32_t n = sd_level_num_cells(a, (sd_cell_kind)k);
                if (sd_level_num_cells(b, (sd_cell_kind)k) != n)
                    DIFF("a level");
                for (uint32_t j = 0; j < n; j++) {
                    uint32_t va[6] = {0}, vb[6] = {0};
                    sd_level_cell(a, (sd_cell_kind)k, j, va);
                    sd_level_cell(b, (sd_cell_kind)k, j, vb);
                    if (memcmp(va, vb, sizeof va))
                        DIFF("a level");
                }
            }
            for (uint32_t v = 0; v < nv; v++) {
                uint32_t x0, y0, x1, y1;
                if (sd_level_vertex_rule(a, v) != sd_level_vertex_rule(b, v) ||
                    sd_level_origin(a, v, &x0, &y0) != sd_level_origin(b, v, &x1, &y1) ||
                    x0 != x1 || y0 != y1)
                    DIFF("a level");
            }
            uint32_t nba = sd_level_solid_boundary(a, NULL);
            if (sd_level_solid_boundary(b, NULL) != nba)
                DIFF("a level");
            uint32_t *ta = malloc((3 * (size_t)nba + 1) * sizeof *ta);
            uint32_t *tb = malloc((3 * (size_t)nba + 1) * sizeof *tb);
            sd_level_solid_boundary(a, ta);
            sd_level_solid_boundary(b, tb);
            int same = !memcmp(ta, tb, 3 * (size_t)nba * sizeof *ta);
            free(ta);
            free(tb);
            if (!same)
                DIFF("a level");
        }
    }
    /* rules, classes, matrices and edges of every level below the top, and of the top too */
    for (int l = 0; l <= top; l++) {
        sd_csr s[3];
        for (int i = 0; i < 3; i++)
            if (l < top && sd_complex_matrix(c[i], l, &s[i], NULL))
                DIFF("a level");
        for (int i = 1; i < 3 && l < top; i++) {
            if (s[i].nrows != s[0].nrows || s[i].ncols != s[0].ncols ||
                memcmp(s[i].rowptr, s[0].rowptr, ((size_t)s[0].nrows + 1) * sizeof *s[0].rowptr) ||
                memcmp(s[i].col, s[0].col, (size_t)s[0].rowptr[s[0].nrows] * sizeof *s[0].col) ||
                memcmp(s[i].val, s[0].val, (size_t)s[0].rowptr[s[0].nrows] * sizeof *s[0].val))
                DIFF("a level");
        }
        uint32_t ne[3];
        const uint32_t *ev[3];
        for (int i = 0; i < 3; i++)
            ev[i] = sd_level_edges(sd_complex_level(c[i], l, NULL), &ne[i]);
        for (int i = 1; i < 3; i++)
            if (ne[i] != ne[0] || memcmp(ev[i], ev[0], 2 * (size_t)ne[0] * sizeof *ev[0]))
                DIFF("a level");
        for (uint32_t e = 0; e < ne[0]; e += 97) {
            sd_class k0, k1;
            memset(&k0, 0, sizeof k0); /* padding */
            memset(&k1, 0, sizeof k1);
            for (int i = 1; i < 3; i++) {
                if (sd_complex_edge_class(c[0], l, e, &k0, NULL) ||
                    sd_complex_edge_class(c[i], l, e, &k1, NULL) || memcmp(&k0, &k1, sizeof k0))
                    DIFF("a level");
            }
        }
    }
    for (int i = 0; i < 3; i++)
        sd_complex_free(c[i]);
    return 1;
}

TEST(threads_same_bytes_solid)
{
    mesh m = {0};
    shape_cube_tets(&m, 3); /* 162 tets: levels 2 and 3 are split in parallel parts */
    sd_options o = {0};
    CHECK(same_levels(&m, &o, 3));
    o.solid_scheme = SD_SOLID_AVERAGED;
    CHECK(same_levels(&m, &o, 3));
    mesh_free(&m);
}

TEST(threads_same_bytes_surface)
{
    mesh m = {0};
    shape_icosahedron(&m);
    sd_options o = {.surface_weights = SD_WEIGHTS_LOOP};
    CHECK(same_levels(&m, &o, 7));
    mesh_free(&m);
}

TEST(threads_same_bytes_mixed_nonmanifold)
{
    mesh m = {0};
    shape_mixed(&m);
    sd_options o = {0};
    CHECK(same_levels(&m, &o, 6));
    mesh_free(&m);
    shape_edge_star(&m, 5); /* G2 rules along a non-manifold edge */
    CHECK(same_levels(&m, &o, 5));
    mesh_free(&m);
}
