/* embed_bench — binding a model to the solid and following edits (core/embed.c; 004 Sec. 5.1).
 * Goals: 1 M model vertices bound to a >= 1 M-cell level in <= 2 s on one core; an update after
 * a one-point edit well under 5 ms.
 *
 *   embed_bench MESH.txt LEVEL [POINTS] [EDITS] [--margin M]
 *
 * Builds level LEVEL of MESH (e.g. `make_mesh.py cubes 10` at level 3), draws POINTS (default
 * 1 M) uniform random points in the mesh's bounding box shrunk by M (default 0.05) on every side,
 * and times sd_embed_bind (SD_OUTSIDE_NEAREST, best of 3; points outside the subdivided solid,
 * which is smaller than its control block at the rounded edges, are bound to the nearest cell
 * and counted). Then EDITS (default 50) single control-point edits (sd_complex_move, reporting
 * the changed points of LEVEL through sd_edit_report.changed) each followed by sd_embed_update
 * over those points; prints the median edit and update times and the model vertices moved. */
#define _POSIX_C_SOURCE 200809L
#include "../core/sd.h"
#include "../tests/tools/textmesh.h"
#include <math.h>
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
    return (x > y) - (x < y);
}

static uint64_t rng = 42;
static double urand(void)
{
    rng = rng * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(rng >> 11) / 9007199254740992.0;
}

typedef struct changed {
    int level;
    uint32_t *v;
    size_t n, cap;
} changed;

static void on_changed(void *ud, int level, const uint32_t *idx, size_t n)
{
    changed *c = ud;
    if (level != c->level)
        return;
    if (c->n + n > c->cap) {
        c->cap = 2 * (c->n + n);
        c->v = realloc(c->v, c->cap * sizeof *c->v);
    }
    memcpy(c->v + c->n, idx, n * sizeof *idx);
    c->n += n;
}

int main(int argc, char **argv)
{
    const char *path = NULL;
    int level = -1, edits = 50;
    long npts = 1000000;
    double margin = 0.05;
    int pos = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--margin") && i + 1 < argc)
            margin = atof(argv[++i]);
        else if (pos == 0 && ++pos)
            path = argv[i];
        else if (pos == 1 && ++pos)
            level = atoi(argv[i]);
        else if (pos == 2 && ++pos)
            npts = atol(argv[i]);
        else
            edits = atoi(argv[i]);
    }
    if (!path || level < 0 || npts < 1 || edits < 1) {
        fprintf(stderr, "usage: embed_bench MESH.txt LEVEL [POINTS] [EDITS] [--margin M]\n");
        return 2;
    }
    textmesh tm;
    char msg[256];
    if (textmesh_read(path, &tm, msg, sizeof msg)) {
        fprintf(stderr, "embed_bench: %s\n", msg);
        return 2;
    }
    sd_error e;
    sd_complex *c = sd_complex_new(tm.xyz, tm.nv, tm.idx, tm.size, tm.ns, NULL, &e);
    const sd_level *lv = c ? sd_complex_level(c, level, &e) : NULL;
    if (!lv || sd_complex_prepare_edits(c, &e)) {
        fprintf(stderr, "embed_bench: %s\n", e.message);
        return 1;
    }
    const uint32_t T = sd_level_num_cells(lv, SD_CELL_TETRA), O = sd_level_num_cells(lv, SD_CELL_OCTA);
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (size_t v = 0; v < tm.nv; v++)
        for (int k = 0; k < 3; k++) {
            lo[k] = tm.xyz[3 * v + k] < lo[k] ? tm.xyz[3 * v + k] : lo[k];
            hi[k] = tm.xyz[3 * v + k] > hi[k] ? tm.xyz[3 * v + k] : hi[k];
        }
    const size_t n = (size_t)npts;
    double *p = malloc(3 * n * sizeof *p), *out = malloc(3 * n * sizeof *out);
    uint32_t *moved = malloc(n * sizeof *moved);
    for (size_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++)
            p[3 * i + k] = lo[k] + margin + urand() * (hi[k] - lo[k] - 2 * margin);

    double best = 1e300;
    sd_embedding *em = NULL;
    sd_bind_report rep;
    for (int r = 0; r < 3; r++) {
        sd_embed_free(em);
        em = NULL;
        double t0 = now();
        if (sd_embed_bind(lv, p, n, SD_OUTSIDE_NEAREST, NULL, 0, &em, &rep, &e)) {
            fprintf(stderr, "embed_bench: %s\n", e.message);
            return 1;
        }
        double t = now() - t0;
        best = t < best ? t : best;
    }
    sd_embed_positions(em, lv, out);
    double err = 0;
    for (size_t i = 0; i < 3 * n; i++)
        err = fabs(out[i] - p[i]) > err ? fabs(out[i] - p[i]) : err;

    double *tu = malloc(edits * sizeof *tu), *te = malloc(edits * sizeof *te);
    double *nm = malloc(edits * sizeof *nm), *nc = malloc(edits * sizeof *nc);
    const double *x0 = sd_level_channel(sd_complex_level(c, 0, NULL), 0, NULL);
    changed ch = {level, NULL, 0, 0};
    for (int i = 0; i < edits; i++) {
        uint32_t cp = (uint32_t)(urand() * tm.nv);
        double to[3];
        for (int k = 0; k < 3; k++)
            to[k] = x0[3 * cp + k] + 0.05 * (urand() - 0.5);
        sd_vertex_at at = {0, cp};
        sd_edit_report er = {0};
        er.changed = on_changed;
        er.ud = &ch;
        ch.n = 0;
        double a = now();
        if (sd_complex_move(c, 0, 1, &at, to, &er, &e)) {
            fprintf(stderr, "embed_bench: %s\n", e.message);
            return 1;
        }
        double b = now();
        size_t k = sd_embed_update(em, lv, ch.v, ch.n, out, moved);
        double d = now();
        te[i] = b - a;
        tu[i] = d - b;
        nm[i] = (double)k;
        nc[i] = (double)ch.n;
    }
    qsort(tu, edits, sizeof *tu, cmpd);
    qsort(te, edits, sizeof *te, cmpd);
    qsort(nm, edits, sizeof *nm, cmpd);
    qsort(nc, edits, sizeof *nc, cmpd);
    /* the last update agrees with a full evaluation */
    double *full = malloc(3 * n * sizeof *full);
    sd_embed_positions(em, lv, full);
    int same = !memcmp(full, out, 3 * n * sizeof *out);

    printf("embed level=%d tetrahedra=%u octahedra=%u embed_cells=%llu level_vertices=%u "
           "model_vertices=%zu outside=%zu bind_best_s=%.3f (goal <= 2) memory_bytes=%zu "
           "rest_max_error=%.2g\n",
           level, T, O, (unsigned long long)T + 4ull * O, sd_level_num_vertices(lv), n, rep.outside,
           best, sd_embed_memory(em), err);
    printf("embed edits=%d edit_median_ms=%.3f update_median_ms=%.3f (goal <= 5) update_p90_ms=%.3f "
           "level_points_changed_median=%.0f model_vertices_moved_median=%.0f update_equals_full=%s\n",
           edits, te[edits / 2] * 1e3, tu[edits / 2] * 1e3, tu[edits * 9 / 10] * 1e3,
           nc[edits / 2], nm[edits / 2], same ? "yes" : "NO");
    sd_embed_free(em);
    sd_complex_free(c);
    textmesh_free(&tm);
    free(p);
    free(out);
    free(full);
    free(moved);
    free(tu);
    free(te);
    free(nm);
    free(nc);
    free(ch.v);
    return same ? 0 : 1;
}
