/* test_threads.c — sd_options.threads: every level is the same bytes whatever the number of
 * threads (positions, channels, cells, edges, origins, rules, classes, solid boundary, matrices),
 * on meshes large enough that the parallel regions really split (core/par.c). */
#include "test.h"

#define DIFF(what)                                                                                 \
    do {                                                                                           \
        fprintf(stderr, "threads: %s differs (line %d)\n", what, __LINE__);                        \
        return 0;                                                                                  \
    } while (0)

/* Level `top` of `m` with each thread count must equal the serial result; prep (if not NULL)
 * sets each complex up before its levels are computed. */
static int same_levels_prep(const mesh *m, const sd_options *base, int top, int (*prep)(sd_complex *))
{
    sd_complex *c[3];
    const int threads[3] = {1, 2, 3};
    for (int i = 0; i < 3; i++) {
        sd_options o = *base;
        o.threads = threads[i];
        c[i] = mesh_complex(m, &o, NULL);
        if (!c[i] || (prep && !prep(c[i])))
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

static int same_levels(const mesh *m, const sd_options *base, int top)
{
    return same_levels_prep(m, base, top, NULL);
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

/* Semi-sharp creases and corners spread over all the ids of levels whose rows are made in
 * parallel parts (each part finds where the sorted lists of sharp rows reach its first row,
 * stencil.c): a 128 x 128 grid of triangle pairs, every 97th diagonal and 101st vertex sharp. */
enum { GRID = 128 };

static void shape_grid(mesh *m)
{
    for (int y = 0; y <= GRID; y++)
        for (int x = 0; x <= GRID; x++)
            mesh_v(m, x, y, 0.1 * sin(x + 0.3 * y));
    for (uint32_t y = 0; y < GRID; y++)
        for (uint32_t x = 0; x < GRID; x++) {
            uint32_t a = y * (GRID + 1) + x, b = a + 1, c = a + GRID + 1, d = c + 1;
            mesh_s(m, 3, a, b, c);
            mesh_s(m, 3, b, d, c);
        }
}

static int sharp_grid(sd_complex *c)
{
    sd_sharpness s[2 * GRID * GRID / 97 + (GRID + 1) * (GRID + 1) / 101 + 2];
    size_t n = 0;
    for (uint32_t i = 0; i < GRID * GRID; i += 97) {
        uint32_t a = i / GRID * (GRID + 1) + i % GRID;
        s[n++] = (sd_sharpness){{a + 1, a + GRID + 1, 0}, 2, 3.5f}; /* the cell's diagonal */
    }
    for (uint32_t v = 50; v < (GRID + 1) * (GRID + 1); v += 101)
        s[n++] = (sd_sharpness){{v, 0, 0}, 1, 2.5f};
    return sd_complex_set_sharpness(c, s, n, SD_CREASE_CHAIKIN, NULL) == SD_OK;
}

/* ... and a sharp embedded surface: a triangle inside a solid (a face of the first cube's first
 * two tetrahedra), an edge of its boundary and one of its corners */
static int sharp_cube(sd_complex *c)
{
    const sd_sharpness s[] = {{{0, 1, 21}, 3, 5.0f}, {{0, 1, 0}, 2, 4.5f}, {{3, 0, 0}, 1, 4.0f}};
    return sd_complex_set_sharpness(c, s, 3, SD_CREASE_UNIFORM, NULL) == SD_OK;
}

TEST(threads_same_bytes_sharp)
{
    mesh m = {0};
    shape_grid(&m);
    sd_options o = {.surface_weights = SD_WEIGHTS_LOOP};
    CHECK(same_levels_prep(&m, &o, 2, sharp_grid));
    mesh_free(&m);
    shape_cube_tets(&m, 3);
    sd_options so = {0};
    CHECK(same_levels_prep(&m, &so, 3, sharp_cube));
    mesh_free(&m);
}
