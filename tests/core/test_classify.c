/* test_classify.c — classification (000 Sec. 2.3-2.4, Fig. 5; 002 Sec. 5.2) on hand-built
 * complexes whose classes are known from the definitions, and the rules chosen for them; the
 * level-0 major diagonals (001 Algorithm 2), which depend on the topology, not the input order. */
#include "test.h"

static sd_class vclass(sd_complex *c, int level, uint32_t v)
{
    sd_class k;
    memset(&k, 0xff, sizeof k);
    sd_complex_vertex_class(c, level, v, &k, NULL);
    return k;
}

static sd_class eclass(sd_complex *c, int level, uint32_t a, uint32_t b)
{
    sd_class k;
    memset(&k, 0xff, sizeof k);
    const sd_level *lv = sd_complex_level(c, level, NULL);
    uint32_t e = sd_level_find_edge(lv, a, b);
    if (e != UINT32_MAX)
        sd_complex_edge_class(c, level, e, &k, NULL);
    return k;
}

/* Fig. 5(a): type 1 — a triangle hinged on an edge of a tetrahedron; a curve on a vertex. */
TEST(classify_type1_fin_and_curve)
{
    mesh m = {0};
    shape_mixed(&m);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    sd_class e12 = eclass(c, 0, 1, 2);
    CHECK(e12.nonmanifold == 1 && e12.family == (4 | 8) && e12.rule == SD_RULE_G2);
    CHECK(vclass(c, 0, 1).nonmanifold == 1 && vclass(c, 0, 2).nonmanifold == 1);
    sd_class v3 = vclass(c, 0, 3); /* tet vertex carrying the curve */
    CHECK(v3.nonmanifold == 1 && v3.family == (2 | 8) && v3.rule == SD_RULE_G2);
    CHECK(vclass(c, 0, 0).nonmanifold == 0 && vclass(c, 0, 0).rule == SD_RULE_SOLID_BOUNDARY);
    CHECK(vclass(c, 0, 4).rule == SD_RULE_LOOP_BOUNDARY && vclass(c, 0, 4).boundary);
    CHECK(eclass(c, 0, 1, 4).rule == SD_RULE_LOOP_BOUNDARY);
    CHECK(vclass(c, 0, 5).rule == SD_RULE_CURVE && !vclass(c, 0, 5).boundary);
    CHECK(vclass(c, 0, 6).rule == SD_RULE_CORNER && vclass(c, 0, 6).boundary); /* curve end */
    CHECK(eclass(c, 0, 3, 5).rule == SD_RULE_CURVE && eclass(c, 0, 3, 5).nonmanifold == 0);
    CHECK(vclass(c, 0, 7).rule == SD_RULE_CORNER && vclass(c, 0, 7).family == 1);
    sd_complex_free(c);
    mesh_free(&m);
}

/* Fig. 5(b): type 2 — three triangles on one edge; the edge's vertices are type 4. */
TEST(classify_type2_three_fins)
{
    mesh m = {0};
    mesh_v(&m, 0, 0, 0);
    mesh_v(&m, 0, 0, 1);
    for (int i = 0; i < 3; i++) {
        mesh_v(&m, cos(2 * M_PI * i / 3), sin(2 * M_PI * i / 3), 0.5);
        mesh_s(&m, 3, 0, 1, 2 + i);
    }
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    CHECK(eclass(c, 0, 0, 1).nonmanifold == 2);
    CHECK(vclass(c, 0, 0).nonmanifold == 4 && vclass(c, 0, 1).nonmanifold == 4);
    CHECK(vclass(c, 0, 2).nonmanifold == 0 && vclass(c, 0, 2).rule == SD_RULE_LOOP_BOUNDARY);
    CHECK(eclass(c, 0, 0, 2).nonmanifold == 0 && eclass(c, 0, 0, 2).boundary);
    /* inherited at level 1: halves stay type 2, the edge point is type 4 */
    const sd_level *l0 = sd_complex_level(c, 0, NULL);
    uint32_t e = sd_level_find_edge(l0, 0, 1);
    uint32_t mid = 5 + e;
    CHECK(vclass(c, 1, mid).nonmanifold == 4);
    CHECK(eclass(c, 1, 0, mid).nonmanifold == 2 && eclass(c, 1, mid, 1).nonmanifold == 2);
    sd_complex_free(c);
    mesh_free(&m);
}

/* Type 2 in C_1: three curves at a vertex — fixed (docs/RULES.md "Conventions"). */
TEST(classify_curve_junction)
{
    mesh m = {0};
    mesh_v(&m, 0, 0, 0);
    for (int i = 0; i < 3; i++) {
        mesh_v(&m, cos(2 * M_PI * i / 3), sin(2 * M_PI * i / 3), 0);
        mesh_s(&m, 2, 0, 1 + i);
    }
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    CHECK(vclass(c, 0, 0).nonmanifold == 2 && vclass(c, 0, 0).rule == SD_RULE_CORNER);
    CHECK(vclass(c, 0, 1).rule == SD_RULE_CORNER && vclass(c, 0, 1).boundary);
    sd_complex_free(c);
    mesh_free(&m);
}

/* Fig. 5(c): type 3 — two triangles / two tetrahedra sharing only a vertex; two tetrahedra
 * sharing only an edge (the edge is type 3, its vertices type 4). */
TEST(classify_type3_bowties)
{
    mesh m = {0};
    mesh_v(&m, 0, 0, 0);
    mesh_v(&m, 1, 0, 0);
    mesh_v(&m, 1, 1, 0);
    mesh_v(&m, -1, 0, 0);
    mesh_v(&m, -1, -1, 0);
    mesh_s(&m, 3, 0, 1, 2);
    mesh_s(&m, 3, 0, 3, 4);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    CHECK(vclass(c, 0, 0).nonmanifold == 3 && vclass(c, 0, 0).rule == SD_RULE_G2);
    CHECK(vclass(c, 0, 1).nonmanifold == 0);
    sd_complex_free(c);
    mesh_free(&m);

    mesh t = {0};
    mesh_v(&t, 0, 0, 0);
    mesh_v(&t, 1, 0, 0);
    mesh_v(&t, 0, 1, 0);
    mesh_v(&t, 0, 0, 1);
    mesh_v(&t, -1, 0, 0);
    mesh_v(&t, 0, -1, 0);
    mesh_v(&t, 0, 0, -1);
    mesh_s(&t, 4, 0, 1, 2, 3);
    mesh_s(&t, 4, 0, 4, 5, 6);
    c = mesh_complex(&t, NULL, NULL);
    CHECK(c);
    CHECK(vclass(c, 0, 0).nonmanifold == 3);
    CHECK(vclass(c, 0, 1).nonmanifold == 0 && eclass(c, 0, 0, 1).nonmanifold == 0);
    sd_complex_free(c);
    mesh_free(&t);

    mesh u = {0};
    mesh_v(&u, 0, 0, 0);
    mesh_v(&u, 0, 0, 1);
    mesh_v(&u, 1, 0, 0.5);
    mesh_v(&u, 1, 1, 0.5);
    mesh_v(&u, -1, 0, 0.5);
    mesh_v(&u, -1, -1, 0.5);
    mesh_s(&u, 4, 0, 1, 2, 3);
    mesh_s(&u, 4, 0, 1, 4, 5);
    c = mesh_complex(&u, NULL, NULL);
    CHECK(c);
    CHECK(eclass(c, 0, 0, 1).nonmanifold == 3 && eclass(c, 0, 0, 1).rule == SD_RULE_G2);
    CHECK(vclass(c, 0, 0).nonmanifold == 4 && vclass(c, 0, 1).nonmanifold == 4);
    CHECK(vclass(c, 0, 2).nonmanifold == 0);
    sd_complex_free(c);
    mesh_free(&u);
}

/* Boundary simplices (000 Sec. 2.3) and interior ones. */
TEST(classify_boundary)
{
    mesh m = {0}; /* a hexagonal fan: centre interior, rim on the boundary */
    mesh_v(&m, 0, 0, 0);
    for (int i = 0; i < 6; i++)
        mesh_v(&m, cos(M_PI * i / 3), sin(M_PI * i / 3), 0);
    for (int i = 0; i < 6; i++)
        mesh_s(&m, 3, 0, 1 + i, 1 + (i + 1) % 6);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    sd_class k = vclass(c, 0, 0);
    CHECK(!k.boundary && k.rule == SD_RULE_LOOP && k.valence == 6 && !k.extraordinary);
    CHECK(vclass(c, 0, 1).boundary && vclass(c, 0, 1).rule == SD_RULE_LOOP_BOUNDARY);
    CHECK(!eclass(c, 0, 0, 1).boundary && eclass(c, 0, 0, 1).rule == SD_RULE_LOOP);
    CHECK(eclass(c, 0, 1, 2).boundary && eclass(c, 0, 1, 2).rule == SD_RULE_LOOP_BOUNDARY);
    sd_complex_free(c);
    mesh_free(&m);

    mesh s = {0}; /* 2x2x2 cubes of tets: the centre vertex is interior */
    shape_cube_tets(&s, 2);
    c = mesh_complex(&s, NULL, NULL);
    CHECK(c);
    uint32_t centre = 13;
    k = vclass(c, 0, centre);
    CHECK(!k.boundary && k.rule == SD_RULE_SOLID && k.valence == 14);
    CHECK(vclass(c, 0, 0).boundary && vclass(c, 0, 0).rule == SD_RULE_SOLID_BOUNDARY);
    CHECK(!eclass(c, 0, centre, centre + 1).boundary && eclass(c, 0, centre, centre + 1).rule == SD_RULE_SOLID);
    /* a chord: interior edge between two boundary vertices is still a solid edge */
    sd_complex_free(c);
    mesh_free(&s);

    mesh t = {0}; /* two tets: the shared face's edges lie on boundary faces too */
    shape_two_tets(&t);
    c = mesh_complex(&t, NULL, NULL);
    CHECK(c);
    CHECK(eclass(c, 0, 1, 2).boundary && eclass(c, 0, 0, 4).nonmanifold == 0xff); /* 0-4 no edge */
    sd_complex_free(c);
    mesh_free(&t);
}

/* Listed faces of listed simplices are absorbed, as in docs/API.md's example. */
TEST(classify_absorbed_faces)
{
    mesh m = {0};
    shape_tet(&m);
    mesh_v(&m, 2, 0, 0);
    mesh_s(&m, 2, 1, 4);
    mesh_s(&m, 1, 4);
    mesh_s(&m, 3, 0, 1, 2);   /* a face of the tet */
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    const sd_level *l = sd_complex_level(c, 0, NULL);
    CHECK(sd_level_num_cells(l, SD_CELL_POINT) == 0);
    CHECK(sd_level_num_cells(l, SD_CELL_CURVE) == 1);
    CHECK(sd_level_num_cells(l, SD_CELL_TRIANGLE) == 0);
    CHECK(sd_level_num_cells(l, SD_CELL_TETRA) == 1);
    CHECK(vclass(c, 0, 1).nonmanifold == 1);
    sd_complex_free(c);
    mesh_free(&m);
}

/* Inherited classes at levels 1 and 2 equal a classification from scratch of the same level
 * posted as a new control complex (surfaces and curves: no octahedra involved). */
TEST(classify_inheritance_matches_recomputation)
{
    mesh shapes[3] = {{0}, {0}, {0}};
    /* three fins + a curve + a bowtie */
    mesh *m = &shapes[0];
    mesh_v(m, 0, 0, 0);
    mesh_v(m, 0, 0, 1);
    for (int i = 0; i < 3; i++) {
        mesh_v(m, cos(2 * M_PI * i / 3), sin(2 * M_PI * i / 3), 0.5);
        mesh_s(m, 3, 0, 1, 2 + i);
    }
    mesh_v(m, 0, 0, 2);
    mesh_s(m, 2, 1, 5);
    mesh_v(m, 2, 0, 0.5);
    mesh_v(m, 2, 1, 0.5);
    mesh_s(m, 3, 2, 6, 7);
    shape_octahedron_surface(&shapes[1]);
    mesh *h = &shapes[2]; /* a fan with a boundary */
    mesh_v(h, 0, 0, 0);
    for (int i = 0; i < 5; i++)
        mesh_v(h, cos(i), sin(i), 0.1 * i);
    for (int i = 0; i < 4; i++)
        mesh_s(h, 3, 0, 1 + i, 2 + i);
    for (int s = 0; s < 3; s++) {
        sd_complex *c = mesh_complex(&shapes[s], NULL, NULL);
        CHECK(c);
        for (int L = 1; L <= 2; L++) {
            const sd_level *lv = sd_complex_level(c, L, NULL);
            CHECK(lv);
            mesh r = {0};
            int nc;
            const double *x = sd_level_channel(lv, 0, &nc);
            for (uint32_t i = 0; i < sd_level_num_vertices(lv); i++)
                mesh_v(&r, x[3 * i], x[3 * i + 1], x[3 * i + 2]);
            for (int k = 0; k < 3; k++)
                for (uint32_t i = 0; i < sd_level_num_cells(lv, (sd_cell_kind)k); i++) {
                    uint32_t v[3];
                    sd_level_cell(lv, (sd_cell_kind)k, i, v);
                    if (k == 0)
                        mesh_s(&r, 1, v[0]);
                    else if (k == 1)
                        mesh_s(&r, 2, v[0], v[1]);
                    else
                        mesh_s(&r, 3, v[0], v[1], v[2]);
                }
            sd_complex *c2 = mesh_complex(&r, NULL, NULL);
            CHECK(c2);
            for (uint32_t i = 0; i < sd_level_num_vertices(lv); i++) {
                sd_class a = vclass(c, L, i), b = vclass(c2, 0, i);
                CHECK(a.family == b.family && a.boundary == b.boundary && a.nonmanifold == b.nonmanifold);
                CHECK(a.rule == b.rule);
            }
            uint32_t ne;
            const uint32_t *ev = sd_level_edges(lv, &ne);
            for (uint32_t e = 0; e < ne; e++) {
                sd_class a = eclass(c, L, ev[2 * e], ev[2 * e + 1]);
                sd_class b = eclass(c2, 0, ev[2 * e], ev[2 * e + 1]);
                CHECK(a.family == b.family && a.boundary == b.boundary && a.nonmanifold == b.nonmanifold);
            }
            sd_complex_free(c2);
            mesh_free(&r);
        }
        sd_complex_free(c);
        mesh_free(&shapes[s]);
    }
}

/* ---- level-0 major diagonals (001 Algorithm 2; docs/DECISIONS.md 1) ----------------------- */

/* Input simplex s's pair `pair` (0: 01|23, 1: 02|13, 2: 03|12 in its input order) as vertex ids:
 * both edges (min, max), the smaller edge first. */
static void geo_pair(const mesh *m, size_t s, int pair, uint32_t k[4])
{
    static const int E[3][4] = {{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 3, 1, 2}};
    size_t off = 0;
    for (size_t i = 0; i < s; i++)
        off += m->sz[i];
    const uint32_t *q = m->idx + off;
    for (int h = 0; h < 2; h++) {
        uint32_t a = q[E[pair][2 * h]], b = q[E[pair][2 * h + 1]];
        k[2 * h] = a < b ? a : b;
        k[2 * h + 1] = a < b ? b : a;
    }
    if (k[2] < k[0]) {
        uint32_t a = k[0], b = k[1];
        k[0] = k[2], k[1] = k[3], k[2] = a, k[3] = b;
    }
}

/* The sorted vertex set of input simplex s (a tetrahedron). */
static void tet_set(const mesh *m, size_t s, uint32_t k[4])
{
    size_t off = 0;
    for (size_t i = 0; i < s; i++)
        off += m->sz[i];
    memcpy(k, m->idx + off, 4 * sizeof *k);
    for (int i = 1; i < 4; i++)
        for (int j = i; j > 0 && k[j - 1] > k[j]; j--) {
            uint32_t x = k[j];
            k[j] = k[j - 1];
            k[j - 1] = x;
        }
}

static uint32_t lcg(uint32_t *s)
{
    *s = *s * 1664525u + 1013904223u;
    return *s >> 8;
}

/* m's vertices, its tetrahedra in a shuffled order (fixed seed), each with its vertex order
 * permuted: all 24 permutations in turn (every other one odd, so about half the copies are
 * reoriented where the originals were not, and the other way round). */
static void permuted_copy(const mesh *m, mesh *out, uint32_t seed)
{
    static const int P[24][4] = {
        {0, 1, 2, 3}, {0, 1, 3, 2}, {0, 2, 3, 1}, {0, 2, 1, 3}, {0, 3, 1, 2}, {0, 3, 2, 1},
        {1, 0, 3, 2}, {1, 0, 2, 3}, {1, 2, 0, 3}, {1, 2, 3, 0}, {1, 3, 2, 0}, {1, 3, 0, 2},
        {2, 0, 1, 3}, {2, 0, 3, 1}, {2, 1, 3, 0}, {2, 1, 0, 3}, {2, 3, 0, 1}, {2, 3, 1, 0},
        {3, 0, 2, 1}, {3, 0, 1, 2}, {3, 1, 0, 2}, {3, 1, 2, 0}, {3, 2, 1, 0}, {3, 2, 0, 1}};
    for (size_t v = 0; v < m->nv; v++)
        mesh_v(out, m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
    size_t *ord = malloc(m->ns * sizeof *ord);
    for (size_t s = 0; s < m->ns; s++)
        ord[s] = s;
    for (size_t s = m->ns; s > 1; s--) {
        size_t j = lcg(&seed) % s, x = ord[s - 1];
        ord[s - 1] = ord[j];
        ord[j] = x;
    }
    for (size_t s = 0; s < m->ns; s++) {
        uint32_t q[4]; /* every simplex here is a tetrahedron */
        size_t off = 0;
        for (size_t i = 0; i < ord[s]; i++)
            off += m->sz[i];
        memcpy(q, m->idx + off, sizeof q);
        const int *p = P[s % 24];
        mesh_s(out, 4, q[p[0]], q[p[1]], q[p[2]], q[p[3]]);
    }
    free(ord);
}

/* Every tetrahedron of a (matched by its vertex set) has the same geometric pair in b. */
static int same_diagonals(const mesh *a, sd_complex *ca, const mesh *b, sd_complex *cb)
{
    for (size_t s = 0; s < a->ns; s++) {
        uint32_t ks[4], kt[4], pa[4], pb[4];
        tet_set(a, s, ks);
        size_t t = 0;
        for (; t < b->ns; t++) {
            tet_set(b, t, kt);
            if (!memcmp(ks, kt, sizeof ks))
                break;
        }
        if (t == b->ns)
            return 0;
        geo_pair(a, s, sd_complex_diagonal(ca, s), pa);
        geo_pair(b, t, sd_complex_diagonal(cb, t), pb);
        if (memcmp(pa, pb, sizeof pa))
            return 0;
    }
    return 1;
}

/* One tetrahedron: no neighbours, all 3 pairs tie, the smallest key wins: edges 01|23 of the
 * vertex ids, whatever the input order. */
TEST(diagonal_single_tet_tie_goes_to_smallest_pair_key)
{
    static const uint32_t orders[4][4] = {{0, 1, 2, 3}, {3, 1, 0, 2}, {2, 0, 3, 1}, {1, 3, 2, 0}};
    for (int o = 0; o < 4; o++) {
        mesh m = {0};
        mesh_v(&m, 0, 0, 0);
        mesh_v(&m, 1, 0, 0);
        mesh_v(&m, 0, 1, 0);
        mesh_v(&m, 0, 0, 1);
        mesh_s(&m, 4, orders[o][0], orders[o][1], orders[o][2], orders[o][3]);
        sd_complex *c = mesh_complex(&m, NULL, NULL);
        CHECK(c);
        uint32_t k[4];
        geo_pair(&m, 0, sd_complex_diagonal(c, 0), k);
        CHECK(k[0] == 0 && k[1] == 1 && k[2] == 2 && k[3] == 3);
        sd_complex_free(c);
        mesh_free(&m);
    }
}

/* Two tetrahedra {0,1,2,3}, {1,2,3,4} on face 123, posted second one first, in odd orders. The
 * search starts at {0,1,2,3} (smallest key): a tie, so 01|23, which crosses face 123 at 23. Then
 * {1,2,3,4}: 12|34 and 13|24 cross it at 12 and 13 (1 conflict each), 14|23 at 23 (none). */
TEST(diagonal_two_tets_start_at_smallest_key)
{
    mesh m = {0};
    mesh_v(&m, 0, 0, 0);
    mesh_v(&m, 1, 0, 0);
    mesh_v(&m, 0, 1, 0);
    mesh_v(&m, 0, 0, 1);
    mesh_v(&m, 1, 1, 1);
    mesh_s(&m, 4, 4u, 2u, 1u, 3u);
    mesh_s(&m, 4, 3u, 0u, 2u, 1u);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    uint32_t k[4];
    geo_pair(&m, 1, sd_complex_diagonal(c, 1), k);
    CHECK(k[0] == 0 && k[1] == 1 && k[2] == 2 && k[3] == 3);
    geo_pair(&m, 0, sd_complex_diagonal(c, 0), k);
    CHECK(k[0] == 1 && k[1] == 4 && k[2] == 2 && k[3] == 3);
    sd_complex_free(c);
    mesh_free(&m);
}

/* A 2x2x2 block of cubes (6 tets each, half of them reoriented), 3 tetrahedra on one face (a
 * non-manifold face: 3 neighbours through it) and 5 around an edge, as 3 components: the same
 * complex with its tetrahedra shuffled and their vertices permuted gets the same diagonals. */
TEST(diagonal_choice_ignores_input_order)
{
    mesh m = {0};
    shape_cube_tets(&m, 2);
    uint32_t b = (uint32_t)m.nv;
    mesh_v(&m, 10, 0, 0);
    mesh_v(&m, 11, 0, 0);
    mesh_v(&m, 10, 1, 0);
    mesh_v(&m, 10.3, 0.3, 1);
    mesh_v(&m, 10.3, 0.3, -1);
    mesh_v(&m, 11, 1, 0.5);
    for (uint32_t a = 3; a < 6; a++)
        mesh_s(&m, 4, b, b + 1, b + 2, b + a);
    b = (uint32_t)m.nv;
    mesh_v(&m, 20, 0, 0);
    mesh_v(&m, 20, 0, 1);
    for (int i = 0; i < 5; i++)
        mesh_v(&m, 20 + cos(2 * M_PI * i / 5), sin(2 * M_PI * i / 5), 0.5);
    for (uint32_t i = 0; i < 5; i++)
        mesh_s(&m, 4, b, b + 1, b + 2 + i, b + 2 + (i + 1) % 5);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    for (uint32_t seed = 1; seed <= 4; seed++) {
        mesh p = {0};
        permuted_copy(&m, &p, seed);
        sd_complex *cp = mesh_complex(&p, NULL, NULL);
        CHECK(cp);
        int same = same_diagonals(&m, c, &p, cp);
        sd_complex_free(cp);
        mesh_free(&p);
        CHECK(same);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

/* The box spline's own lattice (cubes of 6 tetrahedra around a main diagonal, 001 Sec. 3):
 * with the default diagonals every interior vertex of levels 1 and 2 has the regular valence 14
 * (001 Sec. 3: 12 edges and 2 major diagonals), and the lattice is reproduced — the regular
 * masks are symmetric, so away from the boundary (whose rules move the boundary points from
 * level 1 on) the points of level L sit exactly on the lattice of spacing 2^-L (at level 1:
 * vertex points at their vertex, edge points at the midpoints). The start of smallest key alone
 * gave valences 10 and 20 here, and points off the lattice. */
TEST(diagonal_choice_is_regular_on_the_box_spline_lattice)
{
    mesh m = {0};
    shape_cube_tets(&m, 3);
    sd_complex *c = mesh_complex(&m, NULL, NULL);
    CHECK(c);
    for (int L = 1; c && L <= 2; L++) {
        sd_error e = {0};
        const sd_level *lv = sd_complex_level(c, L, &e);
        CHECK(lv);
        if (!lv)
            break;
        const double *x = sd_level_channel(lv, 0, NULL);
        uint32_t nv = sd_level_num_vertices(lv), interior = 0, regular = 0, inner = 0;
        uint32_t on_lattice = 0;
        for (uint32_t v = 0; v < nv; v++) {
            sd_class k = vclass(c, L, v);
            if (k.boundary || k.rule != SD_RULE_SOLID)
                continue;
            interior++;
            regular += k.valence == 14;
            int far = 1, ok = 1; /* far: in the middle cube [1, 2]^3 */
            for (int d = 0; d < 3; d++) {
                double q = x[3 * (size_t)v + d], s = q * (double)(1 << L);
                far &= q > 1 - 1e-3 && q < 2 + 1e-3;
                ok &= fabs(s - nearbyint(s)) < 1e-12;
            }
            inner += far;
            on_lattice += far && ok;
        }
        /* (3 2^L - 1)^3 interior vertices (125, 1331), (2^L + 1)^3 in the middle cube (27, 125) */
        uint32_t want = (uint32_t)((3 << L) - 1) * (uint32_t)((3 << L) - 1) * (uint32_t)((3 << L) - 1);
        uint32_t mid = (uint32_t)((1 << L) + 1) * (uint32_t)((1 << L) + 1) * (uint32_t)((1 << L) + 1);
        CHECK(interior == want);
        CHECK(regular == interior);
        CHECK(inner == mid);
        CHECK(on_lattice == inner);
    }
    sd_complex_free(c);
    mesh_free(&m);
}

/* Classes computed elsewhere (sd_options.classes, what subdivd-mpi ships its pieces): the codes
 * of a complex given back to the same complex change nothing; given to a piece that lacks part of
 * a vertex's star, the vertex takes the whole complex's class and rule; an edge that is not in
 * the complex is refused. */
TEST(classify_shipped_classes)
{
    mesh m = {0}; /* the hexagonal fan of classify_boundary: centre 0 interior, valence 6 */
    mesh_v(&m, 0, 0, 0);
    for (int i = 0; i < 6; i++)
        mesh_v(&m, cos(M_PI * i / 3), sin(M_PI * i / 3), 0.25 * (i % 2));
    for (int i = 0; i < 6; i++)
        mesh_s(&m, 3, 0, 1 + i, 1 + (i + 1) % 6);
    sd_complex *whole = mesh_complex(&m, NULL, NULL);
    CHECK(whole);
    uint32_t ne;
    const uint32_t *ev = sd_level_edges(sd_complex_level(whole, 0, NULL), &ne);
    uint16_t vc[7], ec[12], fc[6];
    sd_complex_class_codes(whole, vc, ec, fc);
    for (int i = 0; i < 7; i++)
        CHECK(vc[i] != 0);
    CHECK(ne == 12);
    uint32_t fv[18];
    for (int i = 0; i < 6; i++) {
        fv[3 * i] = 0;
        fv[3 * i + 1] = 1 + i;
        fv[3 * i + 2] = 1 + (i + 1) % 6;
    }
    /* the same complex with its own codes: nothing differs, the rules are the same */
    size_t differing = 99;
    sd_level0_classes K = {.nv = 7, .vertex = vc, .ne = 12, .edge_v = ev, .edge = ec,
                           .nf = 6, .face_v = fv, .face = fc, .differing = &differing};
    sd_options o = {.classes = &K};
    sd_complex *again = mesh_complex(&m, &o, NULL);
    CHECK(again && differing == 0);
    for (uint32_t v = 0; v < 7; v++)
        CHECK(vclass(again, 0, v).rule == vclass(whole, 0, v).rule &&
              vclass(again, 0, v).boundary == vclass(whole, 0, v).boundary);
    sd_complex_free(again);

    /* a piece: the fan without triangle 0-6-1, so the centre is on the piece's boundary. Shipped
     * the whole fan's class of the centre alone, it follows Loop's interior rule over its six
     * neighbours: 1 - 6 beta at the centre, beta = 1/16 (Loop, valence 6) on each of them. */
    mesh piece = {0};
    for (uint32_t v = 0; v < 7; v++)
        mesh_v(&piece, m.xyz[3 * v], m.xyz[3 * v + 1], m.xyz[3 * v + 2]);
    for (int i = 0; i < 5; i++)
        mesh_s(&piece, 3, 0, 1 + i, 2 + i);
    sd_complex *own = mesh_complex(&piece, NULL, NULL);
    CHECK(own && vclass(own, 0, 0).boundary && vclass(own, 0, 0).rule != SD_RULE_LOOP);
    uint16_t pvc[7] = {vc[0]};
    sd_level0_classes P = {.nv = 7, .vertex = pvc, .differing = &differing};
    o.classes = &P;
    sd_complex *shipped = mesh_complex(&piece, &o, NULL);
    CHECK(shipped && differing == 1);
    sd_class k = vclass(shipped, 0, 0);
    CHECK(!k.boundary && k.rule == SD_RULE_LOOP && k.valence == 6);
    const sd_level *l1 = sd_complex_level(shipped, 1, NULL);
    CHECK(l1);
    if (l1) {
        int nc;
        const double *p = sd_level_channel(l1, 0, &nc);
        for (int d = 0; d < 3; d++) {
            double want = (1 - 6 / 16.0) * m.xyz[d];
            for (int j = 1; j <= 6; j++)
                want += m.xyz[3 * j + d] / 16.0;
            CHECK(fabs(p[d] - want) < 1e-15);
        }
    }
    sd_complex_free(own);
    sd_complex_free(shipped);

    /* an edge the piece does not have (6-1) is refused, naming the entry */
    uint32_t bad_ev[2] = {6, 1};
    uint16_t bad_ec[1] = {ec[0]};
    sd_level0_classes B = {.ne = 1, .edge_v = bad_ev, .edge = bad_ec};
    o.classes = &B;
    sd_error err;
    CHECK(!mesh_complex(&piece, &o, &err) && err.code == SD_ERR_ARG && err.item == 0);
    /* a code cannot change the topology: the centre as a curve vertex (family C_1), or a code
     * without its marker bit, is refused */
    uint16_t topo[7] = {0, (uint16_t)((vc[1] & ~15) | 2)};
    sd_level0_classes T = {.nv = 7, .vertex = topo};
    o.classes = &T;
    CHECK(!mesh_complex(&piece, &o, &err) && err.code == SD_ERR_ARG && err.item == 1);
    topo[1] = vc[1] & 0x7fff;
    CHECK(!mesh_complex(&piece, &o, &err) && err.code == SD_ERR_ARG && err.item == 1);
    sd_complex_free(whole);
    mesh_free(&piece);
    mesh_free(&m);
}
