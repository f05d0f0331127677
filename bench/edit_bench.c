/* edit_bench — cost of control-point edits propagated to level L through the cached matrices
 * (docs/API.md "Control-point edits", issue goal: <= 2 ms median on one core, independent of mesh
 * size within 2x; the first edit after a build of the same order as the later ones).
 *
 *   edit_bench MESH.txt LEVEL [EDITS] [--at-level K] [--report]
 *
 * Builds levels 0..LEVEL (timed), then makes EDITS single-point edits at random points: control
 * points (default) or points of level K (--at-level: moves that store detail offsets, through
 * sd_complex_move), with the changed points reported through a callback if --report. Prints one
 * line: cells and vertices of level LEVEL, the build's seconds, the memory before and after the
 * edits (bytes, and bytes per finest cell before), the first edit (a point moved by the same
 * small amount as the others) and the median and p90 of the others, and the points recomputed
 * at level LEVEL per edit. */
#define _POSIX_C_SOURCE 200809L
#include "../core/sd.h"
#include "../tests/tools/textmesh.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
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

static void count_changed(void *ud, int level, const uint32_t *idx, size_t n)
{
    (void)level;
    (void)idx;
    *(uint64_t *)ud += n;
}

int main(int argc, char **argv)
{
    const char *path = NULL;
    int level = -1, edits = 200, at_level = 0, report = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--at-level") && i + 1 < argc)
            at_level = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--report"))
            report = 1;
        else if (!path)
            path = argv[i];
        else if (level < 0)
            level = atoi(argv[i]);
        else
            edits = atoi(argv[i]);
    }
    if (!path || level < 0 || edits < 1 || at_level < 0 || at_level > level) {
        fprintf(stderr, "usage: edit_bench MESH.txt LEVEL [EDITS] [--at-level K] [--report]\n");
        return 2;
    }
    textmesh tm;
    char msg[256];
    if (textmesh_read(path, &tm, msg, sizeof msg)) {
        fprintf(stderr, "edit_bench: %s\n", msg);
        return 2;
    }
    sd_error e;
    double t0 = now();
    sd_complex *c = sd_complex_new(tm.xyz, tm.nv, tm.idx, tm.size, tm.ns, NULL, &e);
    if (!c || !sd_complex_level(c, level, &e)) {
        fprintf(stderr, "edit_bench: %s\n", e.message);
        return 1;
    }
    double build = now() - t0;
    sd_counts n;
    sd_complex_counts(c, level, &n);
    const uint64_t cells = n.points + n.curves + n.triangles + n.tetrahedra + n.octahedra;
    const size_t mem0 = sd_complex_memory(c);
    const sd_level *lk = sd_complex_level(c, at_level, &e);
    const uint32_t nk = sd_level_num_vertices(lk);
    const double *pk = sd_level_channel(lk, 0, NULL);
    double *home = malloc(3 * (size_t)nk * sizeof *home); /* the points where they started */
    memcpy(home, pk, 3 * (size_t)nk * sizeof *home);
    double *t = malloc((edits + 1) * sizeof *t);
    uint64_t touched = 0, changed = 0;
    srand(1);
    for (int i = 0; i <= edits; i++) { /* edit 0 is the first after the build */
        uint32_t idx = (uint32_t)(rand() % nk);
        double p[3];
        for (int k = 0; k < 3; k++)
            p[k] = home[3 * (size_t)idx + k] + 1e-3 * ((rand() % 2001) - 1000) / 1000.0;
        sd_edit_report rep = {0};
        rep.changed = report ? count_changed : NULL;
        rep.ud = &changed;
        uint64_t counts[SD_MAX_LEVEL + 1];
        sd_vertex_at at = {at_level, idx};
        double a = now();
        sd_result r = at_level == 0 && !report ? sd_complex_edit(c, 0, 1, &idx, p, counts, &e)
                                               : sd_complex_move(c, 0, 1, &at, p, &rep, &e);
        t[i] = now() - a;
        if (r) {
            fprintf(stderr, "edit_bench: %s\n", e.message);
            return 1;
        }
        if (i)
            touched += at_level == 0 && !report ? counts[level] : rep.recomputed[level];
    }
    qsort(t + 1, edits, sizeof *t, cmp);
    printf("edit level=%d at_level=%d cells=%llu vertices=%llu build_s=%.4f memory_bytes=%zu "
           "bytes_per_cell=%.1f memory_after_bytes=%zu first_edit_ms=%.4f median_ms=%.4f "
           "p90_ms=%.4f mean_points_touched=%.0f", level, at_level, (unsigned long long)cells,
           (unsigned long long)n.vertices, build, mem0, (double)mem0 / cells, sd_complex_memory(c),
           t[0] * 1e3, t[1 + edits / 2] * 1e3, t[1 + edits * 9 / 10] * 1e3, (double)touched / edits);
    if (report)
        printf(" mean_points_changed=%.0f", (double)changed / (edits + 1));
    printf("\n");
    free(t);
    free(home);
    sd_complex_free(c);
    textmesh_free(&tm);
    return 0;
}
