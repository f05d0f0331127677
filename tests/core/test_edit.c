/* Edits and detail offsets (docs/API.md "Control-point edits", "Live edits"; 004 Sec. 4.1, 5.2):
 * after hundreds of random edits every computed level is bit for bit a new complex built from the
 * edited control points (and the same offsets); offsets follow coarser edits (checked against
 * S p + d summed here from sd_complex_matrix); the changed points an edit reports are exactly the
 * ones a before/after comparison finds; refused or failed edits change nothing. */
#include "test.h"
#include <stdbool.h>

static uint64_t rng = 12345;
static double urand(void)
{
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(rng >> 11) / 9007199254740992.0;
}

static const sd_options YZ = {.surface_weights = SD_WEIGHTS_LOOP,
                              .nonmanifold_surface = SD_NMSURF_YING_ZORIN};

/* Every channel of levels 0..L, one after the other (malloc'd; NULL if a level fails). */
static double *levels_of(sd_complex *c, int L, size_t *n)
{
    size_t total = 0, at = 0;
    for (int pass = 0; pass < 2; pass++) {
        double *x = pass ? malloc((total ? total : 1) * sizeof *x) : NULL;
        if (pass && !x)
            return NULL;
        for (int l = 0; l <= L; l++) {
            const sd_level *lv = sd_complex_level(c, l, NULL);
            if (!lv) {
                free(x);
                return NULL;
            }
            int nc;
            for (int ch = 0; sd_level_channel(lv, ch, &nc); ch++) {
                size_t k = (size_t)sd_level_num_vertices(lv) * nc;
                if (pass)
                    memcpy(x + at, sd_level_channel(lv, ch, NULL), k * sizeof *x);
                at += pass ? k : 0;
                total += pass ? 0 : k;
            }
        }
        if (pass) {
            *n = total;
            return x;
        }
    }
    return NULL;
}

/* Are levels 0..L of a and b the same bytes? */
static bool same_bytes(sd_complex *a, sd_complex *b, int L)
{
    size_t na = 0, nb = 0;
    double *x = levels_of(a, L, &na), *y = levels_of(b, L, &nb);
    bool ok = x && y && na == nb && !memcmp(x, y, na * sizeof *x);
    free(x);
    free(y);
    return ok;
}

/* The detail offsets of every channel of c, restored on f (as a stored session would be). */
static bool copy_details(sd_complex *c, sd_complex *f)
{
    const sd_level *l0 = sd_complex_level(c, 0, NULL);
    int nc;
    for (int ch = 0; sd_level_channel(l0, ch, &nc); ch++) {
        size_t n = 0;
        for (int l = 1; l <= SD_MAX_LEVEL; l++)
            n += sd_complex_details(c, ch, l, NULL, NULL);
        sd_vertex_at *at = malloc((n + 1) * sizeof *at);
        double *d = malloc((n + 1) * nc * sizeof *d);
        size_t k = 0;
        for (int l = 1; l <= SD_MAX_LEVEL; l++) {
            const uint32_t *idx;
            const double *off;
            size_t m = sd_complex_details(c, ch, l, &idx, &off);
            for (size_t i = 0; i < m; i++, k++) {
                at[k] = (sd_vertex_at){l, idx[i]};
                memcpy(d + k * nc, off + i * nc, nc * sizeof *d);
            }
        }
        sd_result r = sd_complex_set_details(f, ch, n, at, d, NULL, NULL);
        free(at);
        free(d);
        if (r)
            return false;
    }
    return true;
}

/* A new complex on m's simplices with c's control points, channels and offsets. */
static sd_complex *fresh(sd_complex *c, const mesh *m, const sd_options *o, bool details)
{
    const sd_level *l0 = sd_complex_level(c, 0, NULL);
    int nc;
    sd_complex *f = sd_complex_new(sd_level_channel(l0, 0, NULL), m->nv, m->idx, m->sz, m->ns, o, NULL);
    for (int ch = 1; f && sd_level_channel(l0, ch, &nc); ch++)
        if (sd_complex_add_channel(f, sd_level_channel(l0, ch, NULL), nc, NULL) != ch) {
            sd_complex_free(f);
            return NULL;
        }
    if (f && details && !copy_details(c, f)) {
        sd_complex_free(f);
        return NULL;
    }
    return f;
}

/* ---- what an edit reports ------------------------------------------------------------------ */

typedef struct seen {
    uint8_t *hit[SD_MAX_LEVEL + 1];
    uint64_t n[SD_MAX_LEVEL + 1];
    bool bad;
} seen;

static void on_changed(void *ud, int level, const uint32_t *idx, size_t n)
{
    seen *s = ud;
    if (level < 0 || level > SD_MAX_LEVEL || !s->hit[level] || s->n[level]) {
        s->bad = true; /* a level twice, or one that was not computed */
        return;
    }
    s->n[level] = n;
    for (size_t i = 0; i < n; i++)
        s->bad |= s->hit[level][idx[i]]++ != 0;
}

/* Levels 0..L of c as separate copies (channel by channel), to compare after an edit. */
typedef struct copy {
    int L, nch;
    uint32_t nv[SD_MAX_LEVEL + 1];
    int nc[8];
    double *x[SD_MAX_LEVEL + 1][8];
} copy;

static void take(copy *k, sd_complex *c, int L)
{
    memset(k, 0, sizeof *k);
    k->L = L;
    for (int l = 0; l <= L; l++) {
        const sd_level *lv = sd_complex_level(c, l, NULL);
        k->nv[l] = sd_level_num_vertices(lv);
        int nc;
        for (int ch = 0; ch < 8 && sd_level_channel(lv, ch, &nc); ch++) {
            k->nc[ch] = nc;
            k->nch = ch + 1;
            size_t b = (size_t)k->nv[l] * nc * sizeof(double);
            k->x[l][ch] = malloc(b);
            memcpy(k->x[l][ch], sd_level_channel(lv, ch, NULL), b);
        }
    }
}

static void drop(copy *k)
{
    for (int l = 0; l <= k->L; l++)
        for (int ch = 0; ch < k->nch; ch++)
            free(k->x[l][ch]);
}

static void seen_init(seen *s, const copy *k)
{
    memset(s, 0, sizeof *s);
    for (int l = 0; l <= k->L; l++)
        s->hit[l] = calloc(k->nv[l] + 1, 1);
}

/* Do the points reported (s, rep) match the points whose values differ between `before` and c? */
static bool report_matches(const seen *s, const sd_edit_report *rep, const copy *before, sd_complex *c)
{
    bool ok = !s->bad;
    for (int l = 0; ok && l <= before->L; l++) {
        const sd_level *lv = sd_complex_level(c, l, NULL);
        uint64_t n = 0;
        for (uint32_t v = 0; ok && v < before->nv[l]; v++) {
            bool differs = false;
            for (int ch = 0; ch < before->nch; ch++) {
                int nc = before->nc[ch];
                differs |= memcmp(before->x[l][ch] + (size_t)v * nc,
                                  sd_level_channel(lv, ch, NULL) + (size_t)v * nc,
                                  nc * sizeof(double)) != 0;
            }
            ok = differs == (s->hit[l][v] != 0);
            n += differs;
        }
        ok = ok && n == s->n[l] && rep->nchanged[l] == n && rep->recomputed[l] >= n;
    }
    return ok;
}

static void seen_free(seen *s)
{
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        free(s->hit[l]);
}

/* ---- random edits --------------------------------------------------------------------------- */

static void shape(int i, mesh *m, const sd_options **o)
{
    *o = NULL;
    switch (i) {
    case 0: shape_cube_tets(m, 2); break;   /* a solid */
    case 1: shape_icosahedron(m); break;    /* a surface */
    case 2: shape_curves(m); break;         /* curves with a junction and a loop */
    case 3: shape_mixed(m); break;          /* solid, fin, curve, point */
    default: shape_three_fins(m); *o = &YZ; break; /* Ying-Zorin: moves rebuild rules */
    }
}

/* One random call: 1..4 points of channel ch (0 positions, 1 a 2-component attribute), at level 0
 * only or at levels 0..L; positions near the original control points (level 0) or near where the
 * point is (finer levels), so no tetrahedron turns over. */
static sd_result random_call(sd_complex *c, const mesh *m, int L, bool levels, sd_edit_report *rep)
{
    int ch = urand() < 0.6 ? 0 : 1, nc = ch ? 2 : 3;
    size_t n = 1 + (size_t)(urand() * 4);
    sd_vertex_at at[4];
    double v[12];
    for (size_t i = 0; i < n; i++) {
        bool again;
        do {
            at[i].level = levels ? (int)(urand() * (L + 1)) : 0;
            const sd_level *lv = sd_complex_level(c, at[i].level, NULL);
            at[i].index = (uint32_t)(urand() * sd_level_num_vertices(lv));
            again = false;
            for (size_t j = 0; j < i; j++)
                again |= at[j].level == at[i].level && at[j].index == at[i].index;
        } while (again);
        const double *p = sd_level_channel(sd_complex_level(c, at[i].level, NULL), ch, NULL);
        bool stay = urand() < 0.15; /* recomputed, and nothing changes */
        for (int k = 0; k < nc; k++)
            v[i * nc + k] = stay ? p[(size_t)at[i].index * nc + k]
                          : ch ? urand()
                          : at[i].level == 0 ? m->xyz[3 * at[i].index + k] + 0.1 * (urand() - 0.5)
                                             : p[(size_t)at[i].index * 3 + k] + 0.03 * (urand() - 0.5);
    }
    if (!levels && !rep) {
        uint32_t idx[4];
        for (size_t i = 0; i < n; i++)
            idx[i] = at[i].index;
        uint64_t counts[SD_MAX_LEVEL + 1];
        sd_result r = sd_complex_edit(c, ch, n, idx, v, counts, NULL);
        return r || counts[0] != n || counts[L + 1] != 0 ? SD_ERR_ARG : SD_OK;
    }
    return sd_complex_move(c, ch, n, at, v, rep, NULL);
}

/* lazy: the complex edited is made with sd_options.edit_index LAZY (the fresh builds it is
 * compared with are not), so the first edit makes the by-column index. */
static void random_edits(bool levels, bool lazy)
{
    const int L = 3, rounds = lazy ? 100 : 300;
    for (int sh = 0; sh < 5; sh++) {
        mesh m = {0};
        const sd_options *o;
        shape(sh, &m, &o);
        sd_options lo = o ? *o : (sd_options){0};
        lo.edit_index = SD_EDIT_INDEX_LAZY;
        double *attr = malloc(m.nv * 2 * sizeof *attr);
        for (size_t i = 0; i < 2 * m.nv; i++)
            attr[i] = urand();
        sd_complex *c = mesh_complex(&m, lazy ? &lo : o, NULL);
        CHECK(c && sd_complex_add_channel(c, attr, 2, NULL) == 1 && sd_complex_level(c, L, NULL));
        for (int round = 0; round < rounds; round++) {
            bool check = round % 3 == 0; /* the report against a before/after comparison */
            copy before;
            seen s;
            sd_edit_report rep = {0};
            if (check) {
                take(&before, c, L);
                seen_init(&s, &before);
                rep.changed = on_changed;
                rep.ud = &s;
            }
            CHECK(random_call(c, &m, L, levels, check || round % 2 ? &rep : NULL) == SD_OK);
            CHECK(sd_complex_levels_computed(c) == L + 1);
            if (check) {
                bool ok = report_matches(&s, &rep, &before, c);
                drop(&before);
                seen_free(&s);
                CHECK(ok);
            }
            if (round % 50 == 49 || round == rounds - 1) {
                sd_complex *f = fresh(c, &m, o, levels);
                CHECK(f);
                bool same = same_bytes(c, f, L);
                sd_complex_free(f);
                CHECK(same);
            }
        }
        sd_complex_free(c);
        free(attr);
        mesh_free(&m);
    }
}

TEST(edit_random_is_a_fresh_build)
{
    /* control points only (sd_complex_edit and level-0 moves): no drift, to the last bit */
    random_edits(false, false);
}

TEST(edit_random_with_details_is_a_fresh_build)
{
    /* moves at levels 0..3: the same bytes as a new complex given the same offsets */
    random_edits(true, false);
}

TEST(edit_lazy_index_is_a_fresh_build)
{
    /* levels built without the edit index (batch refinement), then edited at every level,
     * Ying-Zorin rule rebuilds included: the first edit makes the index, results unchanged */
    random_edits(true, true);
}

/* ---- detail offsets ----------------------------------------------------------------------- */

/* p^l computed here: row r of S_{l-1} (the public view, summed in its order) on p^{l-1}, plus the
 * offset listed for r. */
static bool level_is_S_p_plus_d(sd_complex *S_of, sd_complex *c, int l)
{
    sd_csr S;
    if (sd_complex_matrix(S_of, l - 1, &S, NULL))
        return false;
    const double *up = sd_level_channel(sd_complex_level(c, l - 1, NULL), 0, NULL);
    const double *p = sd_level_channel(sd_complex_level(c, l, NULL), 0, NULL);
    const uint32_t *idx;
    const double *d;
    size_t nd = sd_complex_details(c, 0, l, &idx, &d), k = 0;
    for (uint32_t r = 0; r < S.nrows; r++) {
        double x[3] = {0, 0, 0};
        for (uint32_t e = S.rowptr[r]; e < S.rowptr[r + 1]; e++)
            for (int q = 0; q < 3; q++)
                x[q] += S.val[e] * up[3 * (size_t)S.col[e] + q];
        if (k < nd && idx[k] == r) {
            for (int q = 0; q < 3; q++)
                x[q] += d[3 * k + q];
            k++;
        }
        if (memcmp(x, p + 3 * (size_t)r, sizeof x))
            return false;
    }
    return k == nd;
}

TEST(details_follow_a_coarser_edit)
{
    mesh m = {0};
    shape_cube_tets(&m, 2);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_level(c, 2, NULL));
    /* offsets at levels 1 and 2 (level 2's read the moved level-1 point) */
    const sd_level *l2 = sd_complex_level(c, 2, NULL);
    sd_vertex_at at[4] = {{1, 30}, {2, 30}, {2, 200}, {2, 400}};
    double v[12];
    for (int i = 0; i < 4; i++) {
        const double *p = sd_level_channel(sd_complex_level(c, at[i].level, NULL), 0, NULL);
        for (int q = 0; q < 3; q++)
            v[3 * i + q] = p[3 * at[i].index + q] + 0.05 * (q + 1) * (i % 2 ? -1 : 1);
    }
    CHECK(sd_complex_move(c, 0, 4, at, v, NULL, NULL) == SD_OK);
    CHECK(sd_complex_details(c, 0, 1, NULL, NULL) == 1 && sd_complex_details(c, 0, 2, NULL, NULL) == 3);
    for (int i = 0; i < 4; i++) { /* each point where it was put */
        const double *p = sd_level_channel(sd_complex_level(c, at[i].level, NULL), 0, NULL);
        for (int q = 0; q < 3; q++)
            CHECK_NEAR(p[3 * at[i].index + q], v[3 * i + q], 1e-15);
    }
    const double *d2;
    sd_complex_details(c, 0, 2, NULL, &d2);
    double keep[9];
    memcpy(keep, d2, sizeof keep);
    /* a later edit of control points near them */
    uint32_t idx[3] = {13, 4, 22};
    double w[9];
    for (int i = 0; i < 9; i++)
        w[i] = m.xyz[3 * idx[i / 3] + i % 3] + 0.07 * (i % 2 ? 1 : -1);
    CHECK(sd_complex_edit(c, 0, 3, idx, w, NULL, NULL) == SD_OK);
    for (int i = 0; i < 9; i++)
        m.xyz[3 * idx[i / 3] + i % 3] = w[i];
    CHECK(sd_complex_details(c, 0, 2, NULL, &d2) == 3 && !memcmp(keep, d2, sizeof keep));
    /* p^l = S_{l-1} p^{l-1} + d^l with S from a new complex of the edited control points */
    sd_complex *f = mesh_complex(&m, NULL, NULL);
    CHECK(f && level_is_S_p_plus_d(f, c, 1) && level_is_S_p_plus_d(f, c, 2));
    (void)l2;
    sd_complex_free(f);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(details_levels_2_then_0_then_1)
{
    mesh m = {0};
    shape_mixed(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    /* level 2 first (computing levels 1 and 2 on the way): the vertex point of control point 1 */
    sd_vertex_at p2 = {2, 1};
    sd_complex *plain = mesh_complex(&m, NULL, NULL);
    CHECK(plain);
    const double *x = sd_level_channel(sd_complex_level(plain, 2, NULL), 0, NULL);
    double t2[3] = {x[3] * 1.25, x[4] + 0.05, x[5] - 0.05};
    sd_complex_free(plain);
    CHECK(sd_complex_move(c, 0, 1, &p2, t2, NULL, NULL) == SD_OK && sd_complex_levels_computed(c) == 3);
    x = sd_level_channel(sd_complex_level(c, 2, NULL), 0, NULL);
    CHECK(x[3] == t2[0]); /* within a factor 2 of where it was: exactly there */
    for (int q = 0; q < 3; q++)
        CHECK_NEAR(x[3 + q], t2[q], 1e-15);
    const double *d;
    CHECK(sd_complex_details(c, 0, 2, NULL, &d) == 1);
    double d2[3];
    memcpy(d2, d, sizeof d2);
    /* then a control point: the level-2 point moves, its offset stays */
    uint32_t i0 = 1;
    double t0[3] = {1.1, 0.1, -0.05};
    CHECK(sd_complex_edit(c, 0, 1, &i0, t0, NULL, NULL) == SD_OK);
    memcpy(m.xyz + 3, t0, sizeof t0);
    CHECK(sd_complex_details(c, 0, 2, NULL, &d) == 1 && !memcmp(d, d2, sizeof d2));
    x = sd_level_channel(sd_complex_level(c, 2, NULL), 0, NULL);
    CHECK(memcmp(x + 3, t2, sizeof t2) != 0);
    /* then level 1 (the point the level-2 point comes from) and level 2 again in one call: the
     * level-2 offset is taken after the level-1 move, so it ends where it was put */
    sd_vertex_at at[2] = {{2, 1}, {1, 1}};
    const double *x1 = sd_level_channel(sd_complex_level(c, 1, NULL), 0, NULL);
    double t[6] = {1.2, 0.05, -0.1, x1[3] + 0.1, x1[4], x1[5] - 0.1};
    CHECK(sd_complex_move(c, 0, 2, at, t, NULL, NULL) == SD_OK);
    x1 = sd_level_channel(sd_complex_level(c, 1, NULL), 0, NULL);
    x = sd_level_channel(sd_complex_level(c, 2, NULL), 0, NULL);
    for (int q = 0; q < 3; q++) {
        CHECK_NEAR(x[3 + q], t[q], 1e-15);
        CHECK_NEAR(x1[3 + q], t[3 + q], 1e-15);
    }
    CHECK(sd_complex_details(c, 0, 1, NULL, NULL) == 1 && sd_complex_details(c, 0, 2, NULL, NULL) == 1);
    /* and the same bytes as a new complex given the same offsets, at every level */
    sd_complex *f = fresh(c, &m, NULL, true);
    CHECK(f && same_bytes(c, f, 3));
    sd_complex_free(f);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(details_set_and_listed)
{
    mesh m = {0};
    shape_icosahedron(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    double a[12];
    for (int i = 0; i < 12; i++)
        a[i] = i;
    CHECK(c && sd_complex_add_channel(c, a, 1, NULL) == 1);
    /* set before any level is computed, then computed: the same as setting them afterwards */
    sd_vertex_at at[3] = {{3, 100}, {1, 5}, {1, 2}};
    double d[9] = {0.1, 0, 0, 0, 0.2, 0, 0, 0, -0.3};
    CHECK(sd_complex_set_details(c, 0, 3, at, d, NULL, NULL) == SD_OK);
    CHECK(sd_complex_levels_computed(c) == 1);
    const uint32_t *idx;
    const double *off;
    CHECK(sd_complex_details(c, 0, 1, &idx, &off) == 2 && idx[0] == 2 && idx[1] == 5);
    CHECK(!memcmp(off, d + 6, 3 * sizeof *off) && !memcmp(off + 3, d + 3, 3 * sizeof *off));
    CHECK(sd_complex_details(c, 0, 3, NULL, NULL) == 1 && sd_complex_details(c, 1, 1, NULL, NULL) == 0);
    CHECK(sd_complex_details(c, 0, 0, NULL, NULL) == 0 && sd_complex_details(c, 2, 1, NULL, NULL) == 0);
    sd_complex *b = mesh_complex(&m, NULL, NULL);
    CHECK(b && sd_complex_add_channel(b, a, 1, NULL) == 1 && sd_complex_level(b, 3, NULL));
    CHECK(sd_complex_set_details(b, 0, 3, at, d, NULL, NULL) == SD_OK);
    CHECK(same_bytes(c, b, 3));
    /* an attribute's offsets, and a replacement that drops one */
    sd_vertex_at aa = {2, 7};
    double ad = 5;
    CHECK(sd_complex_set_details(c, 1, 1, &aa, &ad, NULL, NULL) == SD_OK);
    CHECK(sd_level_channel(sd_complex_level(c, 2, NULL), 1, NULL)[7] ==
          sd_level_channel(sd_complex_level(b, 2, NULL), 1, NULL)[7] + 5);
    CHECK(sd_complex_set_details(c, 0, 2, at + 1, d + 3, NULL, NULL) == SD_OK);
    CHECK(sd_complex_details(c, 0, 3, NULL, NULL) == 0 && sd_complex_details(c, 0, 1, NULL, NULL) == 2);
    CHECK(sd_complex_details(c, 1, 2, NULL, NULL) == 1);
    CHECK(sd_complex_set_details(c, 0, 0, NULL, NULL, NULL, NULL) == SD_OK);
    CHECK(sd_complex_details(c, 0, 1, NULL, NULL) == 0);
    sd_complex_free(b);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(details_survive_drops_and_diagonals)
{
    mesh m = {0};
    shape_cube_tets(&m, 2);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_level(c, 3, NULL));
    sd_vertex_at at[3] = {{1, 10}, {2, 100}, {3, 1000}};
    double v[9];
    for (int i = 0; i < 3; i++) {
        const double *p = sd_level_channel(sd_complex_level(c, at[i].level, NULL), 0, NULL);
        for (int q = 0; q < 3; q++)
            v[3 * i + q] = p[3 * at[i].index + q] + 0.02;
    }
    CHECK(sd_complex_move(c, 0, 3, at, v, NULL, NULL) == SD_OK);
    size_t n0 = 0, n1 = 0;
    double *before = levels_of(c, 3, &n0);
    /* a new channel drops the levels; they come back with the offsets */
    double *a = calloc(m.nv, sizeof *a);
    CHECK(sd_complex_add_channel(c, a, 1, NULL) == 1 && sd_complex_levels_computed(c) == 1);
    double *after = levels_of(c, 3, &n1);
    CHECK(before && after);
    size_t np = 0; /* positions only: compare level by level */
    bool same = true;
    for (int l = 0, at0 = 0, at1 = 0; l <= 3; l++) {
        uint32_t nv = sd_level_num_vertices(sd_complex_level(c, l, NULL));
        same &= !memcmp(before + at0, after + at1, 3 * (size_t)nv * sizeof *before);
        at0 += 3 * nv;
        at1 += 4 * nv;
        np += nv;
    }
    CHECK(same && n1 == n0 + np);
    /* tags drop the levels too; the offsets stay */
    uint32_t tag = 0;
    uint8_t one = 1;
    CHECK(sd_complex_set_singular(c, &tag, &one, 1, NULL) == SD_OK);
    CHECK(sd_complex_details(c, 0, 3, NULL, NULL) == 1);
    /* a diagonal that changes renumbers levels 3 and finer: their offsets go */
    int d = sd_complex_diagonal(c, 0);
    CHECK(sd_complex_set_diagonal(c, 0, d, NULL) == SD_OK && sd_complex_details(c, 0, 3, NULL, NULL) == 1);
    CHECK(sd_complex_set_diagonal(c, 0, (d + 1) % 3, NULL) == SD_OK);
    CHECK(sd_complex_details(c, 0, 1, NULL, NULL) == 1 && sd_complex_details(c, 0, 2, NULL, NULL) == 1);
    CHECK(sd_complex_details(c, 0, 3, NULL, NULL) == 0);
    free(a);
    free(before);
    free(after);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(edit_refused_changes_nothing)
{
    mesh m = {0};
    shape_two_tets(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_level(c, 2, NULL));
    size_t n0;
    double *x0 = levels_of(c, 2, &n0);
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
    /* moves and offsets */
    sd_vertex_at at[3] = {{1, 3}, {2, 7}, {1, 3}};
    double v[9] = {0, 0, 0, 1, 1, 1, 2, 2, 2};
    CHECK(sd_complex_move(c, 0, 3, at, v, NULL, &e) == SD_ERR_REPEATED && e.item == 2);
    at[2] = (sd_vertex_at){0, 3}; /* the same index at another level is another point */
    at[1].level = SD_MAX_LEVEL + 1;
    CHECK(sd_complex_move(c, 0, 3, at, v, NULL, &e) == SD_ERR_ARG && e.item == 1);
    at[1] = (sd_vertex_at){2, 100000}; /* beyond level 2's points */
    CHECK(sd_complex_move(c, 0, 3, at, v, NULL, &e) == SD_ERR_INDEX && e.item == 1);
    at[1].index = 7;
    v[5] = 2e15;
    CHECK(sd_complex_move(c, 0, 3, at, v, NULL, &e) == SD_ERR_VALUE && e.item == 1 && e.field == 2);
    /* a position within bounds whose offset from S p is not */
    uint32_t far = 0;
    double big[3] = {1e15, 0, 0};
    CHECK(sd_complex_edit(c, 0, 1, &far, big, NULL, NULL) == SD_OK);
    sd_vertex_at p1 = {1, 0};
    double to[3] = {-1e15, 0, 0};
    CHECK(sd_complex_move(c, 0, 1, &p1, to, NULL, &e) == SD_ERR_VALUE && e.item == 0 && e.field == 0);
    CHECK(sd_complex_edit(c, 0, 1, &far, m.xyz, NULL, NULL) == SD_OK);
    double d1[3] = {0, 0, 0};
    sd_vertex_at p0 = {0, 1};
    CHECK(sd_complex_set_details(c, 0, 1, &p0, d1, NULL, &e) == SD_ERR_ARG && e.item == 0);
    sd_vertex_at two[2] = {{1, 2}, {1, 2}};
    double d2[6] = {0};
    CHECK(sd_complex_set_details(c, 0, 2, two, d2, NULL, &e) == SD_ERR_REPEATED && e.item == 1);
    d2[4] = INFINITY;
    two[1].index = 3;
    CHECK(sd_complex_set_details(c, 0, 2, two, d2, NULL, &e) == SD_ERR_VALUE && e.item == 1);
    /* still the unedited complex, with no offsets */
    size_t n1;
    double *x1 = levels_of(c, 2, &n1);
    CHECK(x0 && x1 && n0 == n1 && !memcmp(x0, x1, n0 * sizeof *x0));
    CHECK(sd_complex_details(c, 0, 1, NULL, NULL) == 0 && sd_complex_details(c, 0, 2, NULL, NULL) == 0);
    free(x0);
    free(x1);
    sd_complex_free(c);
    mesh_free(&m);
}

/* Fail each allocation of one call in turn: a failed call leaves the complex as it was (levels
 * computed, values, offsets), a call that gets through gives the reference result. */
static void failures(const mesh *m, const sd_options *base, int computed, int ch, size_t n,
                     const sd_vertex_at *at, const double *v, bool set)
{
    sd_complex *ref = mesh_complex(m, base, NULL);
    double a[64];
    for (int i = 0; i < 64; i++)
        a[i] = 0.01 * i;
    CHECK(ref && sd_complex_add_channel(ref, a, 2, NULL) == 1 && sd_complex_level(ref, computed, NULL));
    sd_result want_r = set ? sd_complex_set_details(ref, ch, n, at, v, NULL, NULL)
                           : sd_complex_move(ref, ch, n, at, v, NULL, NULL);
    CHECK(want_r == SD_OK);
    const int top = sd_complex_levels_computed(ref) - 1;
    size_t nw;
    double *want = levels_of(ref, top, &nw);
    long k = 1;
    for (;; k++) {
        counting cc = {0, -1, 0};
        sd_options o = base ? *base : (sd_options){0};
        o.allocator = TEST_COUNTING(&cc);
        sd_complex *c = mesh_complex(m, &o, NULL);
        CHECK(c && sd_complex_add_channel(c, a, 2, NULL) == 1 && sd_complex_level(c, computed, NULL));
        size_t nb;
        double *before = levels_of(c, computed, &nb);
        cc.fail_at = cc.calls + k;
        sd_error e;
        sd_result r = set ? sd_complex_set_details(c, ch, n, at, v, NULL, &e)
                          : sd_complex_move(c, ch, n, at, v, NULL, &e);
        bool reached = cc.calls >= cc.fail_at;
        cc.fail_at = -1;
        CHECK(r == SD_OK || e.code == SD_ERR_NOMEM);
        size_t ng;
        if (r == SD_OK) {
            double *got = levels_of(c, top, &ng);
            CHECK(got && ng == nw && !memcmp(got, want, nw * sizeof *got));
            free(got);
        } else {
            CHECK(sd_complex_levels_computed(c) == computed + 1);
            for (int l = 1; l <= SD_MAX_LEVEL; l++)
                CHECK(sd_complex_details(c, ch, l, NULL, NULL) == 0);
            double *got = levels_of(c, computed, &ng);
            CHECK(got && ng == nb && !memcmp(got, before, nb * sizeof *got));
            free(got);
        }
        free(before);
        sd_complex_free(c);
        CHECK(cc.bytes == 0);
        if (!reached)
            break; /* the call made fewer than k allocations: each has failed once */
    }
    CHECK(k > 10);
    free(want);
    sd_complex_free(ref);
}

TEST(edit_failures_change_nothing)
{
    mesh m = {0};
    shape_cube_tets(&m, 2);
    /* moves at levels 0..3 with levels 2 and 3 computed by the call */
    sd_vertex_at at[4] = {{3, 2000}, {0, 13}, {2, 300}, {1, 40}};
    double v[12] = {1.3, 1.2, 0.9, 1.05, 1.0, 0.95, 0.4, 0.5, 0.6, 0.2, 0.1, 0.3};
    failures(&m, NULL, 1, 0, 4, at, v, false);
    failures(&m, NULL, 3, 1, 4, at, v, false); /* an attribute, everything computed */
    sd_vertex_at given[4] = {{3, 2000}, {1, 13}, {2, 300}, {1, 40}};
    failures(&m, NULL, 2, 0, 4, given, v, true); /* offsets given back */
    mesh_free(&m);
    /* Ying-Zorin: a move of a point alpha reads rebuilds rules, then a level-2 move */
    shape_three_fins(&m);
    sd_vertex_at yz[2] = {{0, 3}, {2, 20}};
    double w[6] = {1.3, 0.6, -0.2, 0.1, 0.2, 0.3};
    failures(&m, &YZ, 2, 0, 2, yz, w, false);
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
    size_t mem = sd_complex_memory(c);
    CHECK(sd_complex_edit(c, 0, 1, &idx, val, counts, NULL) == SD_OK);
    uint32_t nv2 = sd_level_num_vertices(sd_complex_level(c, 2, NULL));
    CHECK(counts[0] == 1 && counts[1] > 1 && counts[2] > counts[1]);
    CHECK(counts[2] * 50 < nv2);
    /* what the first edit adds is its scratch (a map per point of the coarser levels, a bit per
     * point of the finest, and the lists of points it recomputed, 53 bytes an entry, kept for
     * the next edit): the rows by column came with the levels */
    uint32_t coarse = sd_level_num_vertices(sd_complex_level(c, 0, NULL)) +
                      sd_level_num_vertices(sd_complex_level(c, 1, NULL));
    size_t lists = 0;
    for (int l = 0; l <= 2; l++)
        lists += (2 * counts[l] + 256) * (4 + 1 + 2 * 3 * sizeof(double));
    CHECK(sd_complex_memory(c) - mem < 4 * (size_t)coarse + nv2 / 8 + lists + 4096);
    sd_complex_free(c);
    mesh_free(&m);
}

TEST(edit_then_deeper_level)
{
    /* edit at level 1, compute level 3, edit again: the new levels follow the edited points and
     * the second edit reaches them (the old finest level's scratch is reused, not leaked) */
    mesh m = {0};
    shape_cube_tets(&m, 2);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c && sd_complex_level(c, 1, NULL));
    /* small moves: a fresh build of a grossly deformed complex may orient its tetrahedra, and
     * so choose its diagonals, differently — an edit keeps the topology it was made on */
    uint32_t idx = 5;
    double v[3] = {m.xyz[15] + 0.03, m.xyz[16] - 0.02, m.xyz[17] + 0.01};
    CHECK(sd_complex_edit(c, 0, 1, &idx, v, NULL, NULL) == SD_OK);
    CHECK(sd_complex_level(c, 3, NULL));
    idx = 7;
    double w[3] = {m.xyz[21] - 0.02, m.xyz[22] + 0.01, m.xyz[23] + 0.03};
    uint64_t counts[SD_MAX_LEVEL + 1];
    CHECK(sd_complex_edit(c, 0, 1, &idx, w, counts, NULL) == SD_OK && counts[3] > 0);
    sd_complex *f = fresh(c, &m, NULL, false);
    CHECK(f && same_bytes(c, f, 3));
    sd_complex_free(f);
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
    sd_complex *f = mesh_complex(&m, NULL, NULL); /* nothing changed */
    CHECK(f && same_bytes(c, f, 1));
    sd_complex_free(f);
    sd_complex_free(c);
    mesh_free(&m);
}

/* sd_complex_edit_in_place: a move of a point whose position a level's rules read (Ying-Zorin's
 * alpha, shape_three_fins' point 3) changes nothing and names that level, with the counts
 * sd_complex_edit reports; any other move is sd_complex_edit, bit for bit. */
TEST(edit_in_place_stops_before_rebuilding)
{
    mesh m = {0};
    shape_three_fins(&m);
    uint32_t far = (uint32_t)m.nv; /* and a triangle apart, whose points no alpha reads */
    mesh_v(&m, 5, 5, 0);
    mesh_v(&m, 6, 5, 0.2);
    mesh_v(&m, 5, 6, 0.1);
    mesh_s(&m, 3, far, far + 1, far + 2);
    sd_complex *c = mesh_complex(&m, &YZ, NULL), *g = mesh_complex(&m, &YZ, NULL);
    CHECK(c && g && sd_complex_level(c, 2, NULL) && sd_complex_level(g, 2, NULL));
    size_t n0 = 0, n1 = 0;
    double *before = levels_of(c, 2, &n0);
    uint32_t idx = 3;
    double v[3] = {m.xyz[9] + 0.05, m.xyz[10] - 0.04, m.xyz[11] + 0.03};
    uint64_t in_place[SD_MAX_LEVEL + 1], full[SD_MAX_LEVEL + 1];
    int rebuild = 7;
    CHECK(sd_complex_edit_in_place(c, 0, 1, &idx, v, in_place, &rebuild, NULL) == SD_OK);
    CHECK(rebuild == 0);
    double *after = levels_of(c, 2, &n1);
    CHECK(before && after && n0 == n1 && !memcmp(before, after, n0 * sizeof *before));
    CHECK(sd_complex_edit(g, 0, 1, &idx, v, full, NULL) == SD_OK);
    for (int l = 0; l <= 2; l++)
        CHECK(in_place[l] == full[l]);
    /* a point no rule reads: applied, as sd_complex_edit applies it */
    sd_complex *h = mesh_complex(&m, &YZ, NULL);
    CHECK(h && sd_complex_level(h, 2, NULL));
    double w[3] = {m.xyz[3 * far] + 0.02, m.xyz[3 * far + 1], m.xyz[3 * far + 2] - 0.01};
    CHECK(sd_complex_edit_in_place(h, 0, 1, &far, w, in_place, &rebuild, NULL) == SD_OK);
    CHECK(rebuild == -1);
    sd_complex *k = mesh_complex(&m, &YZ, NULL);
    CHECK(k && sd_complex_level(k, 2, NULL) &&
          sd_complex_edit(k, 0, 1, &far, w, full, NULL) == SD_OK && same_bytes(h, k, 2));
    sd_complex_free(k);
    free(before);
    free(after);
    sd_complex_free(h);
    sd_complex_free(g);
    sd_complex_free(c);
    mesh_free(&m);
}
