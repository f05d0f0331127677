/* shapes.c — small hand-built complexes for the core tests. */
#include "test.h"

void shape_tet(mesh *m)
{
    mesh_v(m, 0, 0, 0);
    mesh_v(m, 1, 0, 0);
    mesh_v(m, 0, 1, 0);
    mesh_v(m, 0, 0, 1);
    mesh_s(m, 4, 0, 1, 2, 3);
}

void shape_two_tets(mesh *m)
{
    shape_tet(m);
    mesh_v(m, 0.6, 0.7, 0.8);
    mesh_s(m, 4, 1, 2, 3, 4);
}

void shape_icosahedron(mesh *m)
{
    double p = (1 + sqrt(5)) / 2;
    double v[12][3] = {{-1, p, 0}, {1, p, 0}, {-1, -p, 0}, {1, -p, 0}, {0, -1, p}, {0, 1, p},
                       {0, -1, -p}, {0, 1, -p}, {p, 0, -1}, {p, 0, 1}, {-p, 0, -1}, {-p, 0, 1}};
    int f[20][3] = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                    {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
                    {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
    for (int i = 0; i < 12; i++)
        mesh_v(m, v[i][0], v[i][1], v[i][2]);
    for (int i = 0; i < 20; i++)
        mesh_s(m, 3, f[i][0], f[i][1], f[i][2]);
}

void shape_octahedron_surface(mesh *m)
{
    mesh_v(m, 1, 0, 0);
    mesh_v(m, -1, 0, 0);
    mesh_v(m, 0, 1, 0);
    mesh_v(m, 0, -1, 0);
    mesh_v(m, 0, 0, 1.3);
    mesh_v(m, 0, 0, -0.7);
    int f[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
    for (int i = 0; i < 8; i++)
        mesh_s(m, 3, f[i][0], f[i][1], f[i][2]);
}

void shape_bipyramid(mesh *m)
{
    mesh_v(m, 0, 0, 0);
    mesh_v(m, 0, 0, 1);
    for (int i = 0; i < 3; i++)
        mesh_v(m, cos(2 * M_PI * i / 3), sin(2 * M_PI * i / 3), 0.05 * i);
    mesh_v(m, 0.1, 0, -1);
    for (int i = 0; i < 3; i++) {
        uint32_t a = 2 + i, b = 2 + (i + 1) % 3;
        mesh_s(m, 4, 0, 1, a, b);
        mesh_s(m, 4, 0, 5, a, b);
    }
}

void shape_edge_star(mesh *m, int k)
{
    mesh_v(m, 0, 0, 1);
    mesh_v(m, 0, 0, -1);
    for (int i = 0; i < k; i++)
        mesh_v(m, cos(2 * M_PI * i / k), sin(2 * M_PI * i / k), 0);
    for (int i = 0; i < k; i++)
        mesh_s(m, 4, 0, 1, 2 + i, 2 + (i + 1) % k);
}

void shape_mixed(mesh *m)
{
    shape_tet(m);                /* 0..3 */
    mesh_v(m, 1, 1, 0);          /* 4: fin on edge 1-2 */
    mesh_s(m, 3, 1, 2, 4);
    mesh_v(m, 0, 0, 2);          /* 5, 6: curve from 3 */
    mesh_v(m, 0.5, 0, 3);
    mesh_s(m, 2, 3, 5);
    mesh_s(m, 2, 5, 6);
    mesh_v(m, 3, 3, 3);          /* 7: isolated point */
    mesh_s(m, 1, 7);
}

void shape_cube_tets(mesh *m, int n)
{
    for (int z = 0; z <= n; z++)
        for (int y = 0; y <= n; y++)
            for (int x = 0; x <= n; x++)
                mesh_v(m, x, y, z);
#define ID(x, y, z) ((uint32_t)((z) * (n + 1) * (n + 1) + (y) * (n + 1) + (x)))
    /* Kuhn split of each cube into 6 tets along the main diagonal */
    static const int perm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
    for (int z = 0; z < n; z++)
        for (int y = 0; y < n; y++)
            for (int x = 0; x < n; x++)
                for (int p = 0; p < 6; p++) {
                    int c[3] = {x, y, z};
                    uint32_t v[4];
                    v[0] = ID(c[0], c[1], c[2]);
                    for (int s = 0; s < 3; s++) {
                        c[perm[p][s]]++;
                        v[s + 1] = ID(c[0], c[1], c[2]);
                    }
                    mesh_s(m, 4, v[0], v[1], v[2], v[3]);
                }
#undef ID
}

void shape_three_fins(mesh *m)
{
    for (int z = 0; z < 3; z++)
        mesh_v(m, 0.05 * z * z, 0, z);
    for (int i = 0; i < 3; i++) {
        double a = 2 * M_PI * i / 3 + 0.1 * i;
        for (int z = 0; z < 3; z++)
            mesh_v(m, cos(a) * (1 + 0.1 * z), sin(a) * (1 + 0.1 * z), z + 0.05 * i);
        uint32_t f = 3 + 3 * (uint32_t)i;
        mesh_s(m, 3, 0u, 1u, f + 1);
        mesh_s(m, 3, 0u, f + 1, f);
        mesh_s(m, 3, 1u, 2u, f + 1);
        mesh_s(m, 3, 2u, f + 2, f + 1);
    }
}

void shape_curves(mesh *m)
{
    for (int i = 0; i < 6; i++) /* a polyline 0..5 */
        mesh_v(m, i, 0.3 * sin(i), 0.1 * i * i);
    for (uint32_t i = 0; i < 5; i++)
        mesh_s(m, 2, i, i + 1);
    for (int i = 0; i < 3; i++) /* a branch 6..8 from 2: a junction of three */
        mesh_v(m, 2 + 0.2 * i, 1 + i, 0.5 * i);
    mesh_s(m, 2, 2u, 6u);
    mesh_s(m, 2, 6u, 7u);
    mesh_s(m, 2, 7u, 8u);
    for (int i = 0; i < 5; i++) /* a closed loop 9..13 */
        mesh_v(m, 10 + cos(2 * M_PI * i / 5), sin(2 * M_PI * i / 5), 0.2 * i);
    for (uint32_t i = 0; i < 5; i++)
        mesh_s(m, 2, 9 + i, 9 + (i + 1) % 5);
}
