/* bench — uniform subdivision throughput of the core.
 *
 *   bench [--reps N] [-j THREADS] [-w warren|loop] [-s box|averaged] [--edits] MESH LEVEL
 *
 * Times N complete runs (build the complex from arrays, compute levels 1..LEVEL: topology,
 * classification, rules and positions; file reading excluded) and prints one line: best and
 * median seconds, output cells of the finest level per second, and bytes per finest cell
 * (everything the complex holds: all levels, cached matrices, positions).
 *
 * By default the levels are built as batch refinement builds them (sd_options.edit_index
 * LAZY: no edit index, and no S where direct.c computes a level without it, DECISIONS 50), and
 * what edits need (each level's S if not made, the by-column index of each S, the edit maps:
 * sd_complex_prepare_edits) is timed apart after it: edit_seconds_best, and
 * bytes_per_cell_edits with it. --edits builds S and the index with the levels instead, as
 * the daemon does (then the seconds include them). */
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

static int cmpd(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

int main(int argc, char **argv)
{
    int reps = 5, level = -1;
    const char *path = NULL;
    sd_options opt = {.edit_index = SD_EDIT_INDEX_LAZY};
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--edits")) {
            opt.edit_index = SD_EDIT_INDEX_WITH_LEVELS;
            continue;
        }
        if (!strcmp(argv[i], "--reps") && i + 1 < argc)
            reps = atoi(argv[++i]);
        else if (!strcmp(argv[i], "-j") && i + 1 < argc)
            opt.threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "-w") && i + 1 < argc)
            opt.surface_weights = !strcmp(argv[++i], "loop") ? SD_WEIGHTS_LOOP : SD_WEIGHTS_WARREN;
        else if (!strcmp(argv[i], "-s") && i + 1 < argc)
            opt.solid_scheme = !strcmp(argv[++i], "averaged") ? SD_SOLID_AVERAGED : SD_SOLID_BOX;
        else if (!path)
            path = argv[i];
        else
            level = atoi(argv[i]);
    }
    if (!path || level < 0 || reps < 1) {
        fprintf(stderr, "usage: bench [--reps N] [-j THREADS] [-w warren|loop] [-s box|averaged] [--edits] MESH LEVEL\n");
        return 2;
    }
    textmesh tm;
    char msg[512];
    if (textmesh_read(path, &tm, msg, sizeof msg)) {
        fprintf(stderr, "bench: %s\n", msg);
        return 2;
    }
    double *t = malloc(reps * sizeof *t), *te = malloc(reps * sizeof *te);
    uint64_t cells = 0, verts = 0;
    size_t bytes = 0, bytes_e = 0;
    for (int r = 0; r < reps; r++) {
        sd_error err;
        double t0 = now();
        sd_complex *c = sd_complex_new(tm.xyz, tm.nv, tm.idx, tm.size, tm.ns, &opt, &err);
        const sd_level *lv = c ? sd_complex_level(c, level, &err) : NULL;
        t[r] = now() - t0;
        if (!lv) {
            fprintf(stderr, "bench: %s\n", err.message);
            return 1;
        }
        cells = 0;
        for (int k = 0; k < 5; k++)
            cells += sd_level_num_cells(lv, (sd_cell_kind)k);
        verts = sd_level_num_vertices(lv);
        bytes = sd_complex_memory(c);
        double t1 = now();
        if (sd_complex_prepare_edits(c, &err)) {
            fprintf(stderr, "bench: %s\n", err.message);
            return 1;
        }
        te[r] = now() - t1;
        bytes_e = sd_complex_memory(c);
        sd_complex_free(c);
    }
    qsort(t, reps, sizeof *t, cmpd);
    qsort(te, reps, sizeof *te, cmpd);
    printf("subdivd threads=%d level=%d cells_in=%zu cells_out=%llu vertices_out=%llu seconds_best=%.6f "
           "seconds_median=%.6f cells_per_s=%.3g bytes_per_cell=%.1f edit_index=%s edit_seconds_best=%.6f "
           "bytes_per_cell_edits=%.1f\n",
           opt.threads > 1 ? opt.threads : 1, level, tm.ns, (unsigned long long)cells, (unsigned long long)verts, t[0], t[reps / 2],
           cells / t[0], (double)bytes / cells, opt.edit_index == SD_EDIT_INDEX_LAZY ? "lazy" : "levels", te[0],
           (double)bytes_e / cells);
    free(t);
    free(te);
    textmesh_free(&tm);
    return 0;
}
