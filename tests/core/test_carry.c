/* Tags and rules carried through a refinement step (sd_refine_carry, core/carry.c), and the
 * memory estimate of levels not computed yet (sd_complex_estimate_bytes), against what they take. */
#include "test.h"

/* The new vertex of refinement r splitting edge a-b, or UINT32_MAX. */
static uint32_t mid_of(const sd_refinement *r, uint32_t a, uint32_t b)
{
    for (size_t i = 0; i < r->nsplit; i++)
        if ((r->split[i][0] == a && r->split[i][1] == b) || (r->split[i][0] == b && r->split[i][1] == a))
            return (uint32_t)(r->nv - r->nsplit + i);
    return UINT32_MAX;
}

static int has(const uint32_t *v, int n, uint32_t x)
{
    for (int i = 0; i < n; i++)
        if (v[i] == x)
            return 1;
    return 0;
}

/* A square of two triangles, the first refined red: the second goes green across the shared
 * edge 0-2, which splits. */
TEST(carry_through_red_green)
{
    const double xyz[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    const uint32_t idx[] = {0, 1, 2, 0, 2, 3};
    const uint8_t size[] = {3, 3}, marked[] = {1, 0};
    sd_refinement r;
    sd_error err;
    CHECK(sd_refine(xyz, 4, idx, size, 2, marked, NULL, NULL, &r, &err) == SD_OK);
    uint32_t m02 = mid_of(&r, 0, 2), m01 = mid_of(&r, 0, 1);
    CHECK(m02 != UINT32_MAX && m01 != UINT32_MAX && mid_of(&r, 2, 3) == UINT32_MAX);

    /* tags: vertex 1, the split edge 0-2, the unsplit edge 2-3, the green triangle 0-2-3 */
    uint32_t tidx[] = {1, 0, 2, 2, 3, 0, 2, 3};
    uint8_t tsize[] = {1, 2, 2, 3};
    sd_petal_tag pet = {0, {0, 1, 2}, SD_PETAL_CONCAVE};
    sd_override ov[3] = {
        {.simplex = {0, 2}, .nverts = 2, .rule = SD_RULE_N1, .dimension = 2},
        {.simplex = {0, 2}, .nverts = 2, .rule = SD_RULE_G1},
        {.simplex = {0}, .nverts = 1, .rule = SD_RULE_N2, .pair = {{0, 1, 2}, {0, 2, 3}},
         .pair_size = 3},
    };
    sd_tag_set in = {tidx, tsize, 4, &pet, 1, ov, 3, NULL}, out;
    CHECK(sd_refine_carry(&r, &in, &out, &err) == SD_OK);

    /* vertex 1; halves 0-m02, 2-m02; 2-3; the two children of 0-2-3 */
    CHECK(out.ntags == 6);
    const uint8_t want_size[] = {1, 2, 2, 2, 3, 3};
    for (int i = 0; i < 6; i++)
        CHECK(out.size[i] == want_size[i]);
    CHECK(out.idx[0] == 1);
    CHECK(out.idx[1] == 0 && out.idx[2] == m02 && out.idx[3] == 2 && out.idx[4] == m02);
    CHECK(out.idx[5] == 2 && out.idx[6] == 3);
    for (int c = 0; c < 2; c++) { /* children of 0-2-3: each holds 3 and m02 */
        const uint32_t *q = out.idx + 7 + 3 * c;
        CHECK(has(q, 3, 3) && has(q, 3, m02) && (has(q, 3, 0) != has(q, 3, 2)));
    }
    /* the petal tag keeps its vertex, its triangle is the red child at it */
    CHECK(out.npetals == 1 && out.petals[0].vertex == 0 && out.petals[0].kind == SD_PETAL_CONCAVE);
    CHECK(has(out.petals[0].triangle, 3, 0) && has(out.petals[0].triangle, 3, m01) &&
          has(out.petals[0].triangle, 3, m02));
    /* N1 on 0-2: both halves and the midpoint; G1: the halves only; N2 at 0: its pair's
     * children at 0 */
    CHECK(out.noverrides == 6);
    CHECK(out.overrides[0].rule == SD_RULE_N1 && out.overrides[0].nverts == 2 &&
          out.overrides[0].simplex[0] == 0 && out.overrides[0].simplex[1] == m02);
    CHECK(out.overrides[1].simplex[0] == 2 && out.overrides[1].simplex[1] == m02);
    CHECK(out.overrides[2].nverts == 1 && out.overrides[2].simplex[0] == m02 &&
          out.overrides[2].dimension == 2);
    CHECK(out.overrides[3].rule == SD_RULE_G1 && out.overrides[4].rule == SD_RULE_G1 &&
          out.overrides[3].nverts == 2 && out.overrides[4].nverts == 2);
    const sd_override *n2 = &out.overrides[5];
    CHECK(n2->rule == SD_RULE_N2 && n2->simplex[0] == 0);
    CHECK(has(n2->pair[0], 3, 0) && has(n2->pair[0], 3, m01) && has(n2->pair[0], 3, m02));
    CHECK(has(n2->pair[1], 3, 0) && has(n2->pair[1], 3, 3) && has(n2->pair[1], 3, m02));
    /* the input is unchanged */
    CHECK(tidx[1] == 0 && tidx[2] == 2 && ov[2].pair[0][1] == 1 && pet.triangle[1] == 1);
    sd_tag_set_free(&out);
    CHECK(!out.idx && !out.overrides);
    sd_refine_free(&r);
}

/* Nothing to carry: empty results, still freeable. */
TEST(carry_nothing)
{
    const double xyz[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const uint32_t idx[] = {0, 1, 2};
    const uint8_t size[] = {3}, marked[] = {1};
    sd_refinement r;
    sd_error err;
    CHECK(sd_refine(xyz, 3, idx, size, 1, marked, NULL, NULL, &r, &err) == SD_OK);
    sd_tag_set in = {0}, out;
    CHECK(sd_refine_carry(&r, &in, &out, &err) == SD_OK);
    CHECK(out.ntags == 0 && out.npetals == 0 && out.noverrides == 0);
    sd_tag_set_free(&out);
    sd_refine_free(&r);
}

/* The estimate of level l is within 30% of what computing it takes (sd_complex_memory before
 * and after, the level's vertex rules prepared as a stream does), for a solid, a surface, a
 * curve, a mixed complex and a solid with attribute channels; it sums the levels not computed. */
static int estimate_close(sd_complex *cx, int levels)
{
    sd_error err;
    sd_class k;
    int ok = sd_complex_vertex_class(cx, 0, 0, &k, &err) == SD_OK;
    for (int l = 1; ok && l <= levels; l++) {
        uint64_t est = sd_complex_estimate_level_bytes(cx, l);
        size_t before = sd_complex_memory(cx);
        ok = sd_complex_level(cx, l, &err) && !sd_complex_prepare_vertex_rules(cx, l, &err);
        double real = (double)(sd_complex_memory(cx) - before);
        if (ok && !(est >= 0.7 * real && est <= 1.3 * real)) {
            fprintf(stderr, "level %d: estimate %llu, real %.0f\n", l, (unsigned long long)est,
                    real);
            ok = 0;
        }
    }
    return ok;
}

TEST(estimate_bytes)
{
    mesh m = {0};
    uint32_t a = mesh_v(&m, 0, 0, 0), b = mesh_v(&m, 1, 0, 0), c = mesh_v(&m, 0, 1, 0),
             d = mesh_v(&m, 0, 0, 1), e = mesh_v(&m, 2, 2, 2);
    mesh_s(&m, 4, a, b, c, d);
    mesh_s(&m, 3, b, c, e);
    mesh_s(&m, 2, d, e);
    sd_error err;
    sd_complex *cx = sd_complex_new(m.xyz, m.nv, m.idx, m.sz, m.ns, NULL, &err);
    CHECK(cx);
    uint64_t want = sd_complex_estimate_level_bytes(cx, 1) + sd_complex_estimate_level_bytes(cx, 2) +
                    sd_complex_estimate_level_bytes(cx, 3);
    CHECK(sd_complex_levels_computed(cx) == 1); /* level 0 is computed: not counted */
    CHECK(sd_complex_estimate_bytes(cx, 3) == want);
    CHECK(sd_complex_estimate_bytes(cx, 0) == 0 && sd_complex_estimate_level_bytes(cx, 0) == 0);
    CHECK(sd_complex_level(cx, 1, &err));
    CHECK(sd_complex_estimate_bytes(cx, 3) == want - sd_complex_estimate_level_bytes(cx, 1));
    sd_complex_free(cx);
    mesh_free(&m);

    mesh s = {0};
    shape_cube_tets(&s, 4);
    CHECK((cx = mesh_complex(&s, NULL, NULL)) && estimate_close(cx, 3));
    sd_complex_free(cx);
    CHECK((cx = mesh_complex(&s, NULL, NULL)));
    double *t = calloc(3 * s.nv, sizeof *t);
    CHECK(t && sd_complex_add_channel(cx, t, 3, &err) == 1 && estimate_close(cx, 3));
    free(t);
    sd_complex_free(cx);
    mesh_free(&s);
    shape_icosahedron(&s);
    CHECK((cx = mesh_complex(&s, NULL, NULL)) && estimate_close(cx, 5));
    sd_complex_free(cx);
    mesh_free(&s);
    for (uint32_t i = 0; i < 400; i++) { /* a zig-zag curve */
        mesh_v(&s, 0.1 * i, 0.05 * (i % 7), 0);
        if (i)
            mesh_s(&s, 2, i - 1, i);
    }
    CHECK((cx = mesh_complex(&s, NULL, NULL)) && estimate_close(cx, 5));
    sd_complex_free(cx);
    mesh_free(&s);
    shape_mixed(&s);
    CHECK((cx = mesh_complex(&s, NULL, NULL)) && estimate_close(cx, 6));
    sd_complex_free(cx);
    mesh_free(&s);
}
