/* test_errors.c — every refusal of the core, with its code and location, and failure injection:
 * the Nth allocation fails for every N of a full run; nothing crashes, nothing leaks, and a
 * failed level leaves the lower levels intact. */
#include "test.h"

static sd_result try(const mesh *m, const sd_options *o, sd_error *err)
{
    sd_complex *c = mesh_complex(m, o, err);
    if (c) {
        sd_complex_free(c);
        return SD_OK;
    }
    return err->code;
}

TEST(errors_validation)
{
    sd_error err;
    mesh m = {0};
    CHECK(try(&m, NULL, &err) == SD_ERR_EMPTY);
    shape_tet(&m);
    CHECK(try(&m, NULL, &err) == SD_OK);

    m.xyz[4] = NAN;
    CHECK(try(&m, NULL, &err) == SD_ERR_VALUE && err.item == 1 && err.field == 1);
    m.xyz[4] = INFINITY;
    CHECK(try(&m, NULL, &err) == SD_ERR_VALUE);
    m.xyz[4] = 1e300;
    CHECK(try(&m, NULL, &err) == SD_ERR_VALUE && strstr(err.message, "magnitude"));
    m.xyz[4] = 0;

    m.idx[2] = 9;
    CHECK(try(&m, NULL, &err) == SD_ERR_INDEX && err.item == 0 && err.field == 2);
    CHECK(strstr(err.message, "out of range"));
    m.idx[2] = 1;
    CHECK(try(&m, NULL, &err) == SD_ERR_REPEATED && err.item == 0 && err.field == 2);
    m.idx[2] = 2;

    mesh_s(&m, 4, 3, 2, 1, 0);
    CHECK(try(&m, NULL, &err) == SD_ERR_DUPLICATE && err.item == 1);
    m.sz[1] = 0;
    m.ni -= 4;
    CHECK(try(&m, NULL, &err) == SD_ERR_ARITY && err.item == 1);
    mesh_free(&m);

    mesh d = {0};
    mesh_v(&d, 0, 0, 0);
    mesh_v(&d, 1, 0, 0);
    mesh_v(&d, 2, 0, 0);
    mesh_v(&d, 0, 0, 0);
    mesh_v(&d, 0, 1, 0);
    mesh_s(&d, 3, 0, 1, 2); /* collinear */
    CHECK(try(&d, NULL, &err) == SD_ERR_DEGENERATE && err.item == 0);
    d.sz[0] = 2;
    d.idx[1] = 3;           /* edge 0-3: coincident points */
    d.ni = 2;
    CHECK(try(&d, NULL, &err) == SD_ERR_DEGENERATE);
    mesh_free(&d);

    mesh f = {0}; /* flat tetrahedron */
    mesh_v(&f, 0, 0, 0);
    mesh_v(&f, 1, 0, 0);
    mesh_v(&f, 0, 1, 0);
    mesh_v(&f, 1, 1, 0);
    mesh_s(&f, 4, 0, 1, 2, 3);
    CHECK(try(&f, NULL, &err) == SD_ERR_DEGENERATE && strstr(err.message, "volume"));
    mesh_free(&f);

    mesh g = {0};
    shape_tet(&g);
    g.sz[0] = 5;
    mesh_v(&g, 3, 3, 3);
    g.idx = realloc(g.idx, 5 * sizeof *g.idx);
    g.idx[4] = 4;
    g.ni = 5;
    CHECK(try(&g, NULL, &err) == SD_ERR_ARITY && strstr(err.message, "5 vertices"));
    mesh_free(&g);

    mesh h = {0};
    shape_tet(&h);
    sd_options bad = {.surface_weights = 7};
    CHECK(try(&h, &bad, &err) == SD_ERR_ARG);
    bad.surface_weights = 0;
    bad.solid_scheme = -1;
    CHECK(try(&h, &bad, &err) == SD_ERR_ARG);
    mesh_free(&h);
}

TEST(errors_api_arguments)
{
    sd_error err;
    mesh m = {0};
    shape_mixed(&m);
    sd_complex *c = mesh_complex(&m, NULL, &err);
    CHECK(c);
    CHECK(sd_complex_level(c, -1, &err) == NULL && err.code == SD_ERR_ARG);
    CHECK(sd_complex_level(c, SD_MAX_LEVEL + 1, &err) == NULL && err.code == SD_ERR_ARG);
    CHECK(sd_complex_set_diagonal(c, 1, 0, &err) == SD_ERR_ARG);   /* simplex 1 is a triangle */
    CHECK(sd_complex_set_diagonal(c, 0, 3, &err) == SD_ERR_ARG);
    CHECK(sd_complex_set_diagonal(c, 99, 0, &err) == SD_ERR_ARG);
    double bad[8] = {0, 0, 0, NAN, 0, 0, 0, 0};
    CHECK(sd_complex_add_channel(c, bad, 1, &err) == -1 && err.code == SD_ERR_VALUE && err.item == 3);
    CHECK(sd_complex_add_channel(c, bad, 0, &err) == -1 && err.code == SD_ERR_ARG);
    sd_class k;
    CHECK(sd_complex_vertex_class(c, 0, 99, &k, &err) == SD_ERR_ARG);
    CHECK(sd_complex_edge_class(c, 0, 999, &k, &err) == SD_ERR_ARG);
    sd_analysis a;
    CHECK(sd_analyze_vertex(c, 99, &a, &err) == SD_ERR_ARG);
    CHECK(sd_analyze_edge(c, 0, 6, &a, &err) == SD_ERR_ARG);
    sd_complex_free(c);
    mesh_free(&m);
}

/* A memory cap refuses a level with SD_ERR_LIMIT and keeps what was computed. */
TEST(errors_memory_limit_keeps_levels)
{
    sd_error err;
    mesh m = {0};
    shape_cube_tets(&m, 2);
    sd_options o = {.max_bytes = 600000};
    sd_complex *c = mesh_complex(&m, &o, &err);
    CHECK(c);
    const sd_level *l1 = sd_complex_level(c, 1, &err);
    CHECK(l1);
    CHECK(sd_complex_level(c, 4, &err) == NULL && err.code == SD_ERR_LIMIT);
    CHECK(strstr(err.message, "limit"));
    int computed = sd_complex_levels_computed(c);
    CHECK(computed >= 2 && computed <= 4);
    CHECK(sd_complex_memory(c) <= o.max_bytes);
    CHECK(sd_complex_level(c, 1, &err) == l1);
    sd_complex_free(c);
    mesh_free(&m);
}

/* Failure injection through the pluggable allocator (test.h, counting). */
static int full_run(const mesh *m, counting *cc)
{
    sd_options o = {.allocator = TEST_COUNTING(cc)};
    sd_error err;
    sd_complex *c = mesh_complex(m, &o, &err);
    if (!c)
        return err.code == SD_ERR_NOMEM ? 0 : -1;
    int ok = 1;
    double attr[64];
    for (size_t i = 0; i < m->nv && i < 64; i++)
        attr[i] = (double)i;
    if (sd_complex_add_channel(c, attr, 1, &err) < 0)
        ok = err.code == SD_ERR_NOMEM ? 0 : -1;
    if (ok == 1 && !sd_complex_level(c, 2, &err))
        ok = err.code == SD_ERR_NOMEM ? 0 : -1;
    sd_class k;
    if (ok == 1 && sd_complex_vertex_class(c, 2, 0, &k, &err))
        ok = err.code == SD_ERR_NOMEM ? 0 : -1;
    sd_complex_free(c);
    return ok;
}

TEST(errors_allocation_failures)
{
    mesh m = {0};
    shape_mixed(&m);
    counting probe = {0, -1, 0};
    CHECK(full_run(&m, &probe) == 1);
    CHECK(probe.bytes == 0);
    long total = probe.calls;
    CHECK(total > 20);
    for (long n = 1; n <= total; n++) {
        counting cc = {0, n, 0};
        int r = full_run(&m, &cc);
        CHECK(r == 0 || r == 1);
        CHECK(cc.bytes == 0); /* everything allocated was released */
    }
    mesh_free(&m);
}

/* sd_complex_check: the refusals sd_complex_new makes one simplex at a time are recorded, in the
 * same order of tests (a repeated vertex before degeneracy, duplicates among kept ones only);
 * the refusals of the whole input stay errors. */
TEST(errors_check_for_repair)
{
    mesh m = {0};
    mesh_v(&m, 0, 0, 0);
    mesh_v(&m, 1, 0, 0);
    mesh_v(&m, 2, 0, 0);
    mesh_v(&m, 0, 1, 0);
    mesh_s(&m, 3, 0, 1, 3);   /* 0 kept */
    mesh_s(&m, 3, 0, 1, 2);   /* 1 collinear */
    mesh_s(&m, 3, 3, 1, 0);   /* 2 repeats 0 */
    mesh_s(&m, 3, 1, 1, 2);   /* 3 repeated vertex (also degenerate: the repeat is named) */
    mesh_s(&m, 3, 2, 1, 0);   /* 4 repeats 1, which was dropped: degenerate itself */
    mesh_s(&m, 2, 0, 1);      /* 5 an edge of 0: kept (absorbed by sd_complex_new) */
    mesh_s(&m, 2, 1, 0);      /* 6 repeats 5 */
    uint8_t why[7];
    uint32_t of[7];
    sd_error err;
    CHECK(sd_complex_check(m.xyz, m.nv, m.idx, m.sz, m.ns, NULL, why, of, &err) == SD_OK);
    CHECK(why[0] == SD_OK && why[1] == SD_ERR_DEGENERATE && why[2] == SD_ERR_DUPLICATE &&
          of[2] == 0 && why[3] == SD_ERR_REPEATED && why[4] == SD_ERR_DEGENERATE &&
          why[5] == SD_OK && why[6] == SD_ERR_DUPLICATE && of[6] == 5);
    CHECK(try(&m, NULL, &err) == SD_ERR_DEGENERATE && err.item == 1); /* without repair */
    m.idx[m.ni - 1] = 9;
    CHECK(sd_complex_check(m.xyz, m.nv, m.idx, m.sz, m.ns, NULL, why, NULL, &err) == SD_ERR_INDEX &&
          err.item == 6);
    CHECK(sd_complex_check(m.xyz, m.nv, m.idx, m.sz, 0, NULL, why, NULL, &err) == SD_ERR_EMPTY);
    CHECK(sd_complex_check(m.xyz, m.nv, m.idx, m.sz, m.ns, NULL, NULL, NULL, &err) == SD_ERR_ARG);
    mesh_free(&m);
}
