/* test_classify.c — classification (000 Sec. 2.3-2.4, Fig. 5; 002 Sec. 5.2) on hand-built
 * complexes whose classes are known from the definitions, and the rules chosen for them. */
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
