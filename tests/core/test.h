/* test.h — a minimal unit-test harness for the core (no dependencies).
 * TEST(name) { ... } registers a test; CHECK* record a failure and stop the test.
 * The runner prints one line per failure and ends with "N passed, N failed". */
#ifndef SD_TEST_H
#define SD_TEST_H
#include "../../core/sd.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void test_register(const char *name, void (*fn)(void));
void test_fail(const char *file, int line, const char *msg);
extern int test_failed_now;

#define TEST(name)                                                                           \
    static void name(void);                                                                  \
    __attribute__((constructor)) static void reg_##name(void) { test_register(#name, name); } \
    static void name(void)

#define CHECK(c)                                                                             \
    do {                                                                                     \
        if (!(c)) {                                                                          \
            test_fail(__FILE__, __LINE__, #c);                                               \
            return;                                                                          \
        }                                                                                    \
    } while (0)

#define CHECK_NEAR(a, b, tol)                                                                \
    do {                                                                                     \
        double _a = (a), _b = (b);                                                           \
        if (!(fabs(_a - _b) <= (tol))) {                                                     \
            char _m[256];                                                                    \
            snprintf(_m, sizeof _m, "%s = %.17g, expected %s = %.17g", #a, _a, #b, _b);      \
            test_fail(__FILE__, __LINE__, _m);                                               \
            return;                                                                          \
        }                                                                                    \
    } while (0)

/* A growable input complex. */
typedef struct mesh {
    double *xyz;
    uint32_t *idx;
    uint8_t *sz;
    size_t nv, ns, ni;
} mesh;

static inline uint32_t mesh_v(mesh *m, double x, double y, double z)
{
    m->xyz = realloc(m->xyz, (m->nv + 1) * 3 * sizeof *m->xyz);
    m->xyz[3 * m->nv] = x;
    m->xyz[3 * m->nv + 1] = y;
    m->xyz[3 * m->nv + 2] = z;
    return (uint32_t)m->nv++;
}
static inline size_t mesh_s(mesh *m, int n, ...)
{
    __builtin_va_list ap;
    __builtin_va_start(ap, n);
    m->idx = realloc(m->idx, (m->ni + n) * sizeof *m->idx);
    for (int i = 0; i < n; i++)
        m->idx[m->ni++] = __builtin_va_arg(ap, uint32_t);
    __builtin_va_end(ap);
    m->sz = realloc(m->sz, m->ns + 1);
    m->sz[m->ns] = (uint8_t)n;
    return m->ns++;
}
static inline void mesh_free(mesh *m)
{
    free(m->xyz);
    free(m->idx);
    free(m->sz);
    memset(m, 0, sizeof *m);
}
static inline sd_complex *mesh_complex(const mesh *m, const sd_options *o, sd_error *err)
{
    return sd_complex_new(m->xyz, m->nv, m->idx, m->sz, m->ns, o, err);
}

/* Failure injection through the pluggable allocator: the call numbered fail_at fails (-1:
 * none); bytes is what is still allocated. sd_options.allocator = TEST_COUNTING(&c). */
typedef struct counting {
    long calls, fail_at;
    long long bytes;
} counting;
static inline void *cnt_alloc(size_t n, void *ud)
{
    counting *c = ud;
    if (++c->calls == c->fail_at)
        return NULL;
    void *p = malloc(n);
    if (p)
        c->bytes += (long long)n;
    return p;
}
static inline void cnt_release(void *p, size_t n, void *ud)
{
    ((counting *)ud)->bytes -= (long long)n;
    free(p);
}
#define TEST_COUNTING(c) ((sd_allocator){cnt_alloc, cnt_release, (c)})

/* shapes (shapes.c) */
void shape_tet(mesh *m);
void shape_two_tets(mesh *m);
void shape_icosahedron(mesh *m);
void shape_octahedron_surface(mesh *m);
void shape_bipyramid(mesh *m);          /* centre 0, pole 1, equator 2,3,4, pole 5 (001 B.1) */
void shape_edge_star(mesh *m, int k);   /* k tets around edge 0-1, ring 2..k+1 */
void shape_mixed(mesh *m);              /* tet + fin triangle + curve + point */
void shape_cube_tets(mesh *m, int n);   /* n^3 cubes, 6 tets each */
/* three fins on a spine s0 s1 s2 (z axis): fin i has vertices f0 f1 f2 (one column at angle
 * 2 pi i/3 + tilt) and triangles (s0,s1,f1), (s0,f1,f0), (s1,s2,f1), (s2,f2,f1): at s1 each fin is
 * a petal of 2 triangles with the non-singular edge s1-f1. Vertex ids: s = 0..2, fin i: 3+3i.. */
void shape_three_fins(mesh *m);
void shape_curves(mesh *m);             /* a polyline with a branch (a junction) and a loop */
#endif
