/* edit_bench — cost of one control-point edit propagated to level L through the cached matrices
 * (docs/API.md "Control-point edits", issue goal: <= 2 ms median on one core, independent of mesh size within 2x).
 * usage: edit_bench MESH.txt LEVEL [EDITS]  — prints cells, memory and the median/p90 edit time
 * of EDITS single-point edits at random control points. */
#define _POSIX_C_SOURCE 200809L
#include "../core/sd.h"
#include "../tests/tools/textmesh.h"
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: edit_bench MESH.txt LEVEL [EDITS]\n");
        return 2;
    }
    int level = atoi(argv[2]), edits = argc > 3 ? atoi(argv[3]) : 200;
    textmesh tm;
    char msg[256];
    if (textmesh_read(argv[1], &tm, msg, sizeof msg)) {
        fprintf(stderr, "edit_bench: %s\n", msg);
        return 2;
    }
    sd_error e;
    sd_complex *c = sd_complex_new(tm.xyz, tm.nv, tm.idx, tm.size, tm.ns, NULL, &e);
    if (!c || !sd_complex_level(c, level, &e)) {
        fprintf(stderr, "edit_bench: %s\n", e.message);
        return 1;
    }
    sd_counts n;
    sd_complex_counts(c, level, &n);
    /* the first edit builds the by-column matrices; not part of the steady state */
    uint32_t idx = 0;
    double p[3] = {tm.xyz[0], tm.xyz[1], tm.xyz[2]};
    double t0 = now();
    sd_complex_edit(c, 0, 1, &idx, p, NULL, &e);
    double first = now() - t0;
    double *t = malloc(edits * sizeof *t);
    uint64_t counts[SD_MAX_LEVEL + 1], touched = 0;
    srand(1);
    for (int i = 0; i < edits; i++) {
        idx = (uint32_t)(rand() % tm.nv);
        for (int k = 0; k < 3; k++)
            p[k] = tm.xyz[3 * idx + k] + 1e-3 * ((rand() % 2001) - 1000) / 1000.0;
        double a = now();
        if (sd_complex_edit(c, 0, 1, &idx, p, counts, &e)) {
            fprintf(stderr, "edit_bench: %s\n", e.message);
            return 1;
        }
        t[i] = now() - a;
        touched += counts[level];
    }
    qsort(t, edits, sizeof *t, cmp);
    printf("edit level=%d cells=%llu vertices=%llu memory_bytes=%zu first_edit_s=%.4f "
           "median_ms=%.4f p90_ms=%.4f mean_points_touched=%.0f\n", level,
           (unsigned long long)(n.points + n.curves + n.triangles + n.tetrahedra + n.octahedra),
           (unsigned long long)n.vertices, sd_complex_memory(c), first, t[edits / 2] * 1e3,
           t[edits * 9 / 10] * 1e3, (double)touched / edits);
    free(t);
    sd_complex_free(c);
    textmesh_free(&tm);
    return 0;
}
