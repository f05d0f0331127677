/* Edits through the cached matrices (docs/API.md "Control-point edits", 004 Sec. 4.1): after
 * random edits every computed level equals a recomputation from the edited control points to
 * 1e-12; refused edits change nothing; a one-point edit touches a bounded neighbourhood. */
#include "test.h"

static uint64_t rng = 12345;
static double urand(void)
{
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(rng >> 11) / 9007199254740992.0;
}

/* Compare every level of `a` (edited) with a fresh complex built on `m` (edited input). */
static int same_levels(sd_complex *a, const mesh *m, int levels, const double *attr, int nattr)
{
    sd_complex *b = mesh_complex(m, NULL, NULL);
    if (!b)
        return 0;
    int ok = attr ? sd_complex_add_channel(b, attr, nattr, NULL) == 1 : 1;
    for (int l = 0; ok && l <= levels; l++) {
        const sd_level *la = sd_complex_level(a, l, NULL), *lb = sd_complex_level(b, l, NULL);
        ok = la && lb && sd_level_num_vertices(la) == sd_level_num_vertices(lb);
        for (int ch = 0; ok && ch <= (attr ? 1 : 0); ch++) {
            int na, nb;
            const double *pa = sd_level_channel(la, ch, &na), *pb = sd_level_channel(lb, ch, &nb);
            for (size_t i = 0; ok && i < (size_t)sd_level_num_vertices(la) * na; i++)
                ok = fabs(pa[i] - pb[i]) <= 1e-12 * (1 + fabs(pb[i]));
        }
    }
    sd_complex_free(b);
    return ok;
}

TEST(edit_random_equals_recompute)
{
    for (int shape = 0; shape < 3; shape++) {
        mesh m = {0};
        if (shape == 0)
            shape_cube_tets(&m, 2);
        else if (shape == 1)
            shape_mixed(&m);
        else
            shape_icosahedron(&m);
        double *attr = malloc(m.nv * 2 * sizeof *attr);
        for (size_t i = 0; i < 2 * m.nv; i++)
            attr[i] = urand();
        sd_complex *c = mesh_complex(&m, NULL, NULL);
        CHECK(c && sd_complex_add_channel(c, attr, 2, NULL) == 1);
        CHECK(sd_complex_level(c, 3, NULL));
        for (int round = 0; round < 5; round++) {
            uint32_t idx[3];
            double val[9], aval[6];
            size_t n = 1 + (size_t)(urand() * 3);
            for (size_t i = 0; i < n; i++) {
                do
                    idx[i] = (uint32_t)(urand() * m.nv);
                while ((i > 0 && idx[i] == idx[0]) || (i > 1 && idx[i] == idx[1]));
                for (int k = 0; k < 3; k++)
                    m.xyz[3 * idx[i] + k] = val[3 * i + k] = m.xyz[3 * idx[i] + k] + 0.1 * (urand() - 0.5);
                for (int k = 0; k < 2; k++)
                    attr[2 * idx[i] + k] = aval[2 * i + k] = urand();
            }
            uint64_t counts[SD_MAX_LEVEL + 1];
            CHECK(sd_complex_edit(c, 0, n, idx, val, counts, NULL) == SD_OK);
            CHECK(counts[0] == n && counts[1] >= n && counts[4] == 0);
            CHECK(sd_complex_edit(c, 1, n, idx, aval, NULL, NULL) == SD_OK);
            CHECK(same_levels(c, &m, 3, attr, 2));
        }
        sd_complex_free(c);
        free(attr);
        mesh_free(&m);
    }
}

TEST(edit_refused_changes_nothing)
{
    mesh m = {0};
    shape_two_tets(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_level(c, 2, NULL));
    uint32_t idx[2] = {1, 1};
    double val[6] = {0, 0, 0, 1, 1, 1};
    sd_error e;
    CHECK(sd_complex_edit(c, 0, 2, idx, val, NULL, &e) == SD_ERR_REPEATED && e.item == 1);
    idx[1] = 99;
    CHECK(sd_complex_edit(c, 0, 2, idx, val, NULL, &e) == SD_ERR_INDEX && e.item == 1);
    idx[1] = 2;
    val[4] = NAN;
    CHECK(sd_complex_edit(c, 0, 2, idx, val, NULL, &e) == SD_ERR_VALUE && e.item == 1 && e.field == 1);
    CHECK(sd_complex_edit(c, 3, 1, idx, val, NULL, &e) == SD_ERR_ARG);
    CHECK(same_levels(c, &m, 2, NULL, 0)); /* still the unedited complex */
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(edit_cost_is_local)
{
    /* a corner point's influence: the same region of space at every level, so the points it
     * touches stay a small share of a fine mesh (here 8^3 cubes, level 2) */
    mesh m = {0};
    shape_cube_tets(&m, 8);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_level(c, 2, NULL));
    uint32_t idx = 0;
    double val[3] = {-0.1, -0.1, -0.1};
    uint64_t counts[SD_MAX_LEVEL + 1];
    CHECK(sd_complex_edit(c, 0, 1, &idx, val, counts, NULL) == SD_OK);
    uint32_t nv2 = sd_level_num_vertices(sd_complex_level(c, 2, NULL));
    CHECK(counts[0] == 1 && counts[1] > 1 && counts[2] > counts[1]);
    CHECK(counts[2] * 50 < nv2);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(edit_then_deeper_level)
{
    /* edit at level 1, compute level 3, edit again: the new levels follow the edited points and
     * the second edit reaches them (the old finest level's scratch map is reused, not leaked) */
    mesh m = {0};
    shape_cube_tets(&m, 2);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_level(c, 1, NULL));
    /* small moves: a fresh build of a grossly deformed complex may orient its tetrahedra, and
     * so choose its diagonals, differently — an edit keeps the topology it was made on */
    uint32_t idx = 5;
    double v[3] = {m.xyz[15] + 0.03, m.xyz[16] - 0.02, m.xyz[17] + 0.01};
    CHECK(sd_complex_edit(c, 0, 1, &idx, v, NULL, NULL) == SD_OK);
    memcpy(m.xyz + 15, v, sizeof v);
    CHECK(sd_complex_level(c, 3, NULL));
    idx = 7;
    double w[3] = {m.xyz[21] - 0.02, m.xyz[22] + 0.01, m.xyz[23] + 0.03};
    uint64_t counts[SD_MAX_LEVEL + 1];
    CHECK(sd_complex_edit(c, 0, 1, &idx, w, counts, NULL) == SD_OK && counts[3] > 0);
    memcpy(m.xyz + 21, w, sizeof w);
    CHECK(same_levels(c, &m, 3, NULL, 0));
    sd_complex_free(c);
    mesh_free(&m);
}

/* sd_complex_check_moves: a move that makes a simplex at a moved point degenerate (PUT's test)
 * is refused, naming the latest move among its points; an inverted tetrahedron is not. */
TEST(edit_check_moves_degenerate)
{
    mesh m = {0};
    shape_two_tets(&m); /* (0,0,0) (1,0,0) (0,1,0) (0,0,1), (0.6,0.7,0.8); [0,1,2,3] [1,2,3,4] */
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    sd_error e;
    uint32_t idx[2] = {3, 1};
    double onto[6] = {0, 0, 0.5, 0, 1, 0};                 /* 1 onto 2: a zero edge */
    CHECK(sd_complex_check_moves(c, 2, idx, onto, &e) == SD_ERR_DEGENERATE && e.item == 1);
    double flat[3] = {0.5, 0.5, 0};                        /* 3 into the plane of 0, 1, 2 */
    CHECK(sd_complex_check_moves(c, 1, idx, flat, &e) == SD_ERR_DEGENERATE && e.item == 0);
    double inverted[3] = {0, 0, -0.5};                     /* [0,1,2,3] turned inside out */
    CHECK(sd_complex_check_moves(c, 1, idx, inverted, &e) == SD_OK);
    double tiny[3] = {0, 0, 1e-13};                        /* volume 1e-13/6 < 1e-12 L^3 */
    CHECK(sd_complex_check_moves(c, 1, idx, tiny, &e) == SD_ERR_DEGENERATE);
    CHECK(same_levels(c, &m, 1, NULL, 0)); /* nothing changed */
    sd_complex_free(c);
    mesh_free(&m);
}
