/* sdlevel — read a complex in the text format of docs/TEXT_FORMAT.md, subdivide it with the
 * core library and print one level (with origins, classes or matrix rows on request).
 * A thin client of core/: parsing and printing only. Exit codes: 0 ok, 1 core error, 2 usage or
 * input error. */
#define _POSIX_C_SOURCE 200809L
#include "../../core/sd.h"
#include "textmesh.h"
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

static void usage(void)
{
    fprintf(stderr, "usage: sdlevel [-l L] [-w warren|loop] [-s box|averaged] [-n chang-qin|ying-zorin] "
                    "[--classes] "
                    "[--chaikin] [--matrix] [--stats] [--limit] INPUT\n");
    exit(2);
}

int main(int argc, char **argv)
{
    int level = 1, classes = 0, matrix = 0, stats = 0, chaikin = 0, limit = 0;
    sd_options opt = {0};
    const char *path = NULL;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-l") && i + 1 < argc)
            level = atoi(argv[++i]);
        else if (!strcmp(argv[i], "-w") && i + 1 < argc) {
            const char *w = argv[++i];
            if (!strcmp(w, "loop"))
                opt.surface_weights = SD_WEIGHTS_LOOP;
            else if (strcmp(w, "warren"))
                usage();
        } else if (!strcmp(argv[i], "-s") && i + 1 < argc) {
            const char *s = argv[++i];
            if (!strcmp(s, "averaged"))
                opt.solid_scheme = SD_SOLID_AVERAGED;
            else if (strcmp(s, "box"))
                usage();
        } else if (!strcmp(argv[i], "-n") && i + 1 < argc) {
            const char *n = argv[++i];
            if (!strcmp(n, "ying-zorin"))
                opt.nonmanifold_surface = SD_NMSURF_YING_ZORIN;
            else if (strcmp(n, "chang-qin"))
                usage();
        } else if (!strcmp(argv[i], "--classes"))
            classes = 1;
        else if (!strcmp(argv[i], "--matrix"))
            matrix = 1;
        else if (!strcmp(argv[i], "--chaikin"))
            chaikin = 1;
        else if (!strcmp(argv[i], "--stats"))
            stats = 1;
        else if (!strcmp(argv[i], "--limit"))
            limit = 1;
        else if (argv[i][0] == '-' && argv[i][1])
            usage();
        else
            path = argv[i];
    }
    if (!path)
        usage();
    textmesh tm;
    char msg[512];
    if (textmesh_read(path, &tm, msg, sizeof msg)) {
        fprintf(stderr, "sdlevel: %s\n", msg);
        return 2;
    }
    sd_error err;
    double t0 = now();
    sd_complex *c = sd_complex_new(tm.xyz, tm.nv, tm.idx, tm.size, tm.ns, &opt, &err);
    if (!c) {
        fprintf(stderr, "sdlevel: %s (item %ld, field %d): %s\n", sd_result_name(err.code), err.item,
                err.field, err.message);
        return 1;
    }
    /* `d t k`: t counts tetrahedra among the simplices in input order */
    for (size_t i = 0; i < tm.ndiag; i++) {
        long *d = tm.diag + 2 * i, seen = -1;
        size_t s;
        for (s = 0; s < tm.ns; s++)
            if (tm.size[s] == 4 && ++seen == d[0])
                break;
        if (s == tm.ns || sd_complex_set_diagonal(c, s, (int)d[1], &err)) {
            fprintf(stderr, "sdlevel: bad diagonal line 'd %ld %ld'\n", d[0], d[1]);
            return 2;
        }
    }
    /* `c` lines: a sharpness; 10 and more is infinitely sharp, a singular tag */
    if (tm.ncr) {
        sd_sharpness *sh = calloc(tm.ncr, sizeof *sh);
        uint32_t *tag = calloc(3 * tm.ncr, sizeof *tag);
        uint8_t *tsz = calloc(tm.ncr, 1);
        size_t nsh = 0, ntag = 0, ntid = 0;
        if (!sh || !tag || !tsz) {
            fprintf(stderr, "sdlevel: out of memory\n");
            return 1;
        }
        for (size_t i = 0; i < tm.ncr; i++) {
            int n = tm.crn[i];
            if (tm.crs[i] >= 10) {
                for (int k = 0; k < n; k++)
                    tag[ntid++] = tm.crv[3 * i + k];
                tsz[ntag++] = (uint8_t)n;
            } else
                sh[nsh++] = (sd_sharpness){{tm.crv[3 * i], tm.crv[3 * i + 1], tm.crv[3 * i + 2]}, n,
                                           (float)tm.crs[i]};
        }
        if ((ntag && sd_complex_set_singular(c, tag, tsz, ntag, &err)) ||
            sd_complex_set_sharpness(c, sh, nsh, chaikin ? SD_CREASE_CHAIKIN : SD_CREASE_UNIFORM,
                                     &err)) {
            fprintf(stderr, "sdlevel: bad sharpness (item %ld): %s\n", err.item, err.message);
            return 2;
        }
        free(sh);
        free(tag);
        free(tsz);
    }
    const sd_level *lv = sd_complex_level(c, level, &err);
    if (!lv) {
        fprintf(stderr, "sdlevel: %s: %s\n", sd_result_name(err.code), err.message);
        return 1;
    }
    double t1 = now();
    static const char *const kinds[] = {"points", "edges", "triangles", "tetrahedra", "octahedra"};
    static const char tags[] = "petTO";
    if (stats) {
        printf("level %d vertices %u", level, sd_level_num_vertices(lv));
        for (int k = 0; k < 5; k++)
            printf(" %s %u", kinds[k], sd_level_num_cells(lv, (sd_cell_kind)k));
        printf(" seconds %.6f memory %zu\n", t1 - t0, sd_complex_memory(c));
        sd_complex_free(c);
        return 0;
    }
    int nc;
    const double *x = sd_level_channel(lv, 0, &nc);
    uint32_t nv = sd_level_num_vertices(lv);
    /* --limit: the points at their limit positions, then their limit normals (sd_complex_limit) */
    double *lim = NULL, *nrm = NULL;
    if (limit) {
        lim = malloc((size_t)nv * 3 * sizeof *lim);
        nrm = malloc((size_t)nv * 3 * sizeof *nrm);
        if (!lim || !nrm || sd_complex_limit(c, level, 0, lim, nrm, &err)) {
            fprintf(stderr, "sdlevel: limit: %s\n", lim && nrm ? err.message : "out of memory");
            return 1;
        }
        lv = sd_complex_level(c, level, &err);
        x = lim;
    }
    printf("level %d\nvertices %u\n", level, nv);
    for (uint32_t i = 0; i < nv; i++) {
        uint32_t a, b;
        sd_origin_kind k = sd_level_origin(lv, i, &a, &b);
        printf("v %.17g %.17g %.17g", x[3 * i], x[3 * i + 1], x[3 * i + 2]);
        switch (k) {
        case SD_ORIGIN_INPUT: printf(" I\n"); break;
        case SD_ORIGIN_VERTEX: printf(" V %u\n", a); break;
        case SD_ORIGIN_EDGE: printf(" E %u %u\n", a, b); break;
        case SD_ORIGIN_CELL: printf(" C %u\n", a); break;
        }
    }
    if (limit) {
        printf("normals %u\n", nv);
        for (uint32_t i = 0; i < nv; i++)
            printf("n %.17g %.17g %.17g\n", nrm[3 * i], nrm[3 * i + 1], nrm[3 * i + 2]);
        free(lim);
        free(nrm);
    }
    for (int k = 0; k < 5; k++) {
        uint32_t n = sd_level_num_cells(lv, (sd_cell_kind)k), v[6];
        int m = sd_cell_size((sd_cell_kind)k);
        printf("%s %u\n", kinds[k], n);
        for (uint32_t i = 0; i < n; i++) {
            sd_level_cell(lv, (sd_cell_kind)k, i, v);
            putchar(tags[k]);
            for (int j = 0; j < m; j++)
                printf(" %u", v[j]);
            putchar('\n');
        }
    }
    if (classes) {
        sd_class cl;
        for (uint32_t i = 0; i < nv; i++) {
            if (sd_complex_vertex_class(c, level, i, &cl, &err))
                return 1;
            printf("vclass %u %u %u %u %s %u\n", i, cl.family, cl.boundary, cl.nonmanifold,
                   sd_rule_name((sd_rule)cl.rule), cl.valence);
        }
        uint32_t ne;
        const uint32_t *ev = sd_level_edges(lv, &ne);
        for (uint32_t e = 0; e < ne; e++) {
            if (sd_complex_edge_class(c, level, e, &cl, &err))
                return 1;
            printf("eclass %u %u %u %u %u %s %u\n", ev[2 * e], ev[2 * e + 1], cl.family, cl.boundary,
                   cl.nonmanifold, sd_rule_name((sd_rule)cl.rule), cl.valence);
        }
    }
    if (matrix && level > 0) {
        sd_csr s;
        if (sd_complex_matrix(c, level - 1, &s, &err))
            return 1;
        for (uint32_t r = 0; r < s.nrows; r++) {
            printf("row %u %u", r, s.rowptr[r + 1] - s.rowptr[r]);
            for (uint32_t k = s.rowptr[r]; k < s.rowptr[r + 1]; k++)
                printf(" %u %.17g", s.col[k], s.val[k]);
            putchar('\n');
        }
    }
    sd_complex_free(c);
    textmesh_free(&tm);
    return 0;
}
