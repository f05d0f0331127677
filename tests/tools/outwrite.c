/* outwrite — write one subdivided level of a text-format complex (docs/TEXT_FORMAT.md) through
 * the streaming writers of api/out.h, the same code the daemon streams with. A test tool: it pulls
 * the output in chunks of a chosen size (every size must give the same bytes) and checks that the
 * byte count equals out_size() where that is known in advance.
 *
 *   outwrite MESH.txt -l L -f glb|gltf|vtu|vtk|json -o OUT
 *            [--parts points,curves,surfaces,solids] [--slice nx,ny,nz,d]
 *            [--xattr NAME[:N]]... [--colormap NAME:min:max] [--polyhedra]
 *            [--chunk N] [--geometry] [--version V] [--compute C] [--stats]
 *   outwrite MESH.txt --check-errors
 *
 * The text format has no attributes: `--xattr NAME:N` adds a synthetic N-component attribute
 * (default 1) whose component k at a control vertex (x,y,z) is x + k*y + k*k*z + k. Subdivision
 * rows sum to 1, so at every level the attribute is the same affine function of the subdivided
 * positions — tests check values without trusting the writer. `--geometry` passes a precomputed
 * out_geometry (the daemon's per-level cache) instead of letting out_open compute it.
 * `--stats` prints one line: level, vertices, the cell counts per kind, boundary triangles and
 * the byte count. `--parts` also takes a raw OUT_PART_* mask (a number); `--compute C` computes
 * only levels up to C before out_open (default L). `--check-errors` runs out_open on a list of
 * bad requests and prints one line per case: its name, the result code and the message; exit 0
 * if every one was refused with SD_ERR_ARG.
 * Exit codes: 0 ok, 1 core or writer error, 2 usage or input error.
 */
#define _POSIX_C_SOURCE 200809L
#include "../../api/out.h"
#include "textmesh.h"
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void usage(void)
{
    fprintf(stderr,
            "usage: outwrite MESH.txt [-l L] -f glb|gltf|vtu|vtk|json -o OUT [--parts LIST]\n"
            "       [--slice nx,ny,nz,d] [--xattr NAME[:N]]... [--colormap NAME:min:max]\n"
            "       [--polyhedra] [--chunk N] [--geometry] [--version V] [--compute C] [--stats]\n"
            "       outwrite MESH.txt --check-errors\n");
    exit(2);
}

static unsigned parse_parts(const char *s)
{
    if (*s >= '0' && *s <= '9')
        return (unsigned)strtoul(s, NULL, 0);
    static const char *const names[] = {"points", "curves", "surfaces", "solids"};
    unsigned mask = 0;
    char *copy = strdup(s), *save = NULL;
    for (char *t = strtok_r(copy, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
        int k;
        for (k = 0; k < 4 && strcmp(t, names[k]); k++)
            ;
        if (k == 4) {
            fprintf(stderr, "outwrite: unknown part '%s'\n", t);
            exit(2);
        }
        mask |= 1u << k;
    }
    free(copy);
    return mask;
}

/* out_open must refuse each of these with SD_ERR_ARG and a message naming the option. */
static int check_errors(sd_complex *c)
{
    sd_error err;
    if (!sd_complex_level(c, 1, &err))
        return 1;
    double *one = calloc(sd_level_num_vertices(sd_complex_level(c, 0, &err)), sizeof *one);
    int ch = sd_complex_add_channel(c, one, 1, &err);
    free(one);
    if (ch < 0 || !sd_complex_level(c, 1, &err))
        return 1;
    const out_request ok = {.complex = c, .level = 1, .colormap_attr = -1, .nattrs = 1,
                            .attrs = {{.name = "t", .channel = ch, .ncomp = 1}}};
    struct bad { const char *name; out_request rq; const out_format *fmt; } cases[32];
    int n = 0;
#define CASE(nm, f, ...)                                                                           \
    do {                                                                                           \
        cases[n] = (struct bad){nm, ok, f};                                                        \
        out_request *r = &cases[n++].rq;                                                           \
        __VA_ARGS__;                                                                               \
        (void)r;                                                                                   \
    } while (0)
    CASE("format", NULL);
    CASE("parts-unknown", out_format_find("glb"), r->parts = 32);
    CASE("parts-embedded-vtu", out_format_find("vtu"), r->parts = OUT_PART_EMBEDDED);
    static const double mesh_xyz[3] = {0, 0, 0};
    static const uint32_t mesh_tri[3] = {0, 0, 1};
    static const out_mesh bad_mesh = {"m", 1, 1, mesh_xyz, mesh_tri};
    CASE("parts-embedded-range", out_format_find("glb"), r->parts = OUT_PART_EMBEDDED,
         r->nmeshes = 1, r->meshes = &bad_mesh);
    CASE("parts-embedded-many", out_format_find("glb"), r->parts = OUT_PART_EMBEDDED,
         r->nmeshes = OUT_MAX_MESHES + 1, r->meshes = &bad_mesh);
    CASE("slice-zero", out_format_find("glb"), r->has_slice = 1, r->slice[3] = 1);
    CASE("slice-nan", out_format_find("vtu"), r->has_slice = 1, r->slice[0] = 1, r->slice[1] = NAN);
    CASE("slice-inf-d", out_format_find("json"), r->has_slice = 1, r->slice[2] = 1, r->slice[3] = INFINITY);
    CASE("colormap-index", out_format_find("glb"), r->colormap_attr = 1);
    CASE("colormap-negative", out_format_find("glb"), r->colormap_attr = -2);
    CASE("colormap-range", out_format_find("glb"), r->colormap_attr = 0, r->colormap_min = 1, r->colormap_max = 1);
    CASE("colormap-nan", out_format_find("glb"), r->colormap_attr = 0, r->colormap_min = NAN, r->colormap_max = 1);
    CASE("colormap-inf", out_format_find("gltf"), r->colormap_attr = 0, r->colormap_max = INFINITY);
    CASE("level-not-computed", out_format_find("vtk"), r->level = 2);
    CASE("level-negative", out_format_find("json"), r->level = -1);
    CASE("attributes-name", out_format_find("vtu"), r->attrs[0].name = "a\"b");
    CASE("attributes-empty-name", out_format_find("vtu"), r->attrs[0].name = "");
    CASE("attributes-null-name", out_format_find("vtu"), r->attrs[0].name = NULL);
    CASE("attributes-ncomp", out_format_find("glb"), r->attrs[0].ncomp = 0);
    CASE("attributes-channel", out_format_find("glb"), r->attrs[0].channel = ch + 1);
    CASE("attributes-ncomp-mismatch", out_format_find("json"), r->attrs[0].ncomp = 2);
    CASE("attributes-duplicate", out_format_find("json"), r->nattrs = 2, r->attrs[1] = r->attrs[0]);
    CASE("attributes-count", out_format_find("json"), r->nattrs = OUT_MAX_ATTRS + 1);
    CASE("no-complex", out_format_find("json"), r->complex = NULL);
#undef CASE
    int bad = 0;
    for (int i = 0; i < n; i++) {
        sd_error e = {0};
        out_stream *s = out_open(&cases[i].rq, cases[i].fmt, &e);
        printf("%s %s %s\n", cases[i].name, s ? "ACCEPTED" : sd_result_name(e.code), s ? "" : e.message);
        bad += s != NULL || e.code != SD_ERR_ARG;
        out_close(s);
    }
    out_stream *s = out_open(&ok, out_format_find("glb"), &err); /* and the good request is fine */
    printf("ok %s\n", s ? "OK" : err.message);
    bad += s == NULL;
    out_close(s);
    return bad ? 1 : 0;
}

/* The command line. */
typedef struct opts {
    const char *path, *outpath, *fmtname, *parts, *slice, *cmap;
    const char *xname[OUT_MAX_ATTRS];
    int xcomp[OUT_MAX_ATTRS], nx, level, compute, poly, stats, use_geometry, errors;
    size_t chunk;
    unsigned long long version;
} opts;

static void parse_args(int argc, char **argv, opts *o)
{
    *o = (opts){.level = 1, .compute = -1, .chunk = 65536, .version = 1};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        bool more = i + 1 < argc;
        if (!strcmp(a, "-l") && more)
            o->level = atoi(argv[++i]);
        else if (!strcmp(a, "-f") && more)
            o->fmtname = argv[++i];
        else if (!strcmp(a, "-o") && more)
            o->outpath = argv[++i];
        else if (!strcmp(a, "--parts") && more)
            o->parts = argv[++i];
        else if (!strcmp(a, "--slice") && more)
            o->slice = argv[++i];
        else if (!strcmp(a, "--colormap") && more)
            o->cmap = argv[++i];
        else if (!strcmp(a, "--chunk") && more) {
            long n = atol(argv[++i]);
            if (n < 1)
                usage();
            o->chunk = (size_t)n;
        } else if (!strcmp(a, "--version") && more)
            o->version = strtoull(argv[++i], NULL, 10);
        else if (!strcmp(a, "--xattr") && more) {
            if (o->nx == OUT_MAX_ATTRS)
                usage();
            char *spec = argv[++i], *colon = strchr(spec, ':');
            o->xcomp[o->nx] = 1;
            if (colon) {
                *colon = 0;
                o->xcomp[o->nx] = atoi(colon + 1);
            }
            if (!*spec || o->xcomp[o->nx] < 1 || o->xcomp[o->nx] > 16)
                usage();
            o->xname[o->nx++] = spec;
        } else if (!strcmp(a, "--compute") && more)
            o->compute = atoi(argv[++i]);
        else if (!strcmp(a, "--check-errors"))
            o->errors = 1;
        else if (!strcmp(a, "--polyhedra"))
            o->poly = 1;
        else if (!strcmp(a, "--stats"))
            o->stats = 1;
        else if (!strcmp(a, "--geometry"))
            o->use_geometry = 1;
        else if (a[0] == '-' && a[1])
            usage();
        else if (!o->path)
            o->path = a;
        else
            usage();
    }
}

/* The complex of a text-format mesh with its diagonal lines applied; NULL after saying why
 * (*rc: the exit code; tm is freed then). */
static sd_complex *load(const char *path, textmesh *tm, int *rc)
{
    char msg[512];
    if (textmesh_read(path, tm, msg, sizeof msg)) {
        fprintf(stderr, "outwrite: %s\n", msg);
        *rc = 2;
        return NULL;
    }
    sd_error err = {0};
    sd_complex *c = sd_complex_new(tm->xyz, tm->nv, tm->idx, tm->size, tm->ns, NULL, &err);
    if (!c) {
        fprintf(stderr, "outwrite: %s: %s\n", sd_result_name(err.code), err.message);
        textmesh_free(tm);
        *rc = 1;
        return NULL;
    }
    for (size_t i = 0; i < tm->ndiag; i++) { /* `d t k`: t counts tetrahedra in input order */
        long *d = tm->diag + 2 * i, seen = -1;
        size_t s;
        for (s = 0; s < tm->ns; s++)
            if (tm->size[s] == 4 && ++seen == d[0])
                break;
        if (s == tm->ns || sd_complex_set_diagonal(c, s, (int)d[1], &err)) {
            fprintf(stderr, "outwrite: bad diagonal line 'd %ld %ld'\n", d[0], d[1]);
            sd_complex_free(c);
            textmesh_free(tm);
            *rc = 2;
            return NULL;
        }
    }
    return c;
}

/* Pull the whole stream in chunks of `chunk` bytes into outpath (or nowhere), checking the
 * reader's promises: no chunk larger than asked, the end stays the end, out_size() is exact
 * when known. 0, 1 (a broken promise) or 2 (I/O); *total = the bytes read. */
static int drain(out_stream *s, const char *outpath, size_t chunk, uint64_t *total)
{
    FILE *f = NULL;
    char *buf = NULL;
    int rc = 1;
    if (outpath && !(f = fopen(outpath, "wb"))) {
        fprintf(stderr, "outwrite: %s: %s\n", outpath, strerror(errno));
        return 2;
    }
    if (!(buf = malloc(chunk)))
        goto done;
    ssize_t n;
    while ((n = out_read(s, buf, chunk)) > 0) {
        if ((size_t)n > chunk) {
            fprintf(stderr, "outwrite: out_read returned %zd > %zu bytes\n", n, chunk);
            goto done;
        }
        if (f && fwrite(buf, 1, (size_t)n, f) != (size_t)n) {
            fprintf(stderr, "outwrite: %s: %s\n", outpath, strerror(errno));
            rc = 2;
            goto done;
        }
        *total += (uint64_t)n;
    }
    if (n < 0) {
        fprintf(stderr, "outwrite: the writer failed after %llu bytes\n", (unsigned long long)*total);
        goto done;
    }
    if (out_read(s, buf, chunk) != 0) { /* the end stays the end */
        fprintf(stderr, "outwrite: bytes after the end of the stream\n");
        goto done;
    }
    if (out_size(s) != UINT64_MAX && out_size(s) != *total) {
        fprintf(stderr, "outwrite: out_size %llu but %llu bytes written\n",
                (unsigned long long)out_size(s), (unsigned long long)*total);
        goto done;
    }
    FILE *closing = f;
    f = NULL;
    if (closing && fclose(closing)) {
        fprintf(stderr, "outwrite: %s: %s\n", outpath, strerror(errno));
        rc = 2;
        goto done;
    }
    rc = 0;
done:
    if (f)
        fclose(f);
    free(buf);
    return rc;
}

int main(int argc, char **argv)
{
    opts o;
    parse_args(argc, argv, &o);
    const char *path = o.path, *outpath = o.outpath, *parts = o.parts, *slice = o.slice,
               *cmap = o.cmap;
    const char *const *xname = o.xname;
    const int *xcomp = o.xcomp;
    int nx = o.nx, level = o.level, compute = o.compute, poly = o.poly, stats = o.stats,
        use_geometry = o.use_geometry, errors = o.errors;
    size_t chunk = o.chunk;
    unsigned long long version = o.version;
    const out_format *fmt = o.fmtname ? out_format_find(o.fmtname) : NULL;
    if (!path || (!errors && (!fmt || (!outpath && !stats))))
        usage();
    textmesh tm;
    int rc = 1;
    sd_complex *c = load(path, &tm, &rc);
    if (!c)
        return rc;
    sd_error err = {0};

    /* from here on every exit goes through `done`, which frees everything (clean under LSan) */
    out_geometry *geo = NULL;
    out_stream *s = NULL;
    const sd_level *lv = NULL;
    if (errors) {
        rc = check_errors(c);
        goto done;
    }
    out_request rq = {.complex = c, .level = level, .version = version, .colormap_attr = -1,
                      .octahedra_as_polyhedra = poly, .nattrs = nx};
    for (int a = 0; a < nx; a++) {
        int n = xcomp[a];
        double *data = malloc(tm.nv * (size_t)n * sizeof *data + 1);
        if (!data)
            goto done;
        for (size_t v = 0; v < tm.nv; v++)
            for (int k = 0; k < n; k++) {
                const double *p = tm.xyz + 3 * v;
                data[v * n + k] = p[0] + k * p[1] + k * k * p[2] + k;
            }
        int ch = sd_complex_add_channel(c, data, n, &err);
        free(data);
        if (ch < 0) {
            fprintf(stderr, "outwrite: %s: %s\n", sd_result_name(err.code), err.message);
            goto done;
        }
        rq.attrs[a] = (out_attr){.name = xname[a], .channel = ch, .ncomp = n};
    }
    if (parts)
        rq.parts = parse_parts(parts);
    if (slice) {
        if (sscanf(slice, "%lf,%lf,%lf,%lf", &rq.slice[0], &rq.slice[1], &rq.slice[2],
                   &rq.slice[3]) != 4)
            usage();
        rq.has_slice = 1;
    }
    if (cmap) {
        char name[128];
        if (sscanf(cmap, "%127[^:]:%lf:%lf", name, &rq.colormap_min, &rq.colormap_max) != 3)
            usage();
        for (int a = 0; a < nx; a++)
            if (!strcmp(name, xname[a]))
                rq.colormap_attr = a;
        if (rq.colormap_attr < 0) {
            fprintf(stderr, "outwrite: --colormap: no attribute '%s' (add it with --xattr)\n", name);
            rc = 2;
            goto done;
        }
    }

    lv = sd_complex_level(c, compute >= 0 ? compute : level, &err);
    if (lv && compute >= 0)
        lv = compute >= level ? sd_complex_level(c, level, &err) : NULL;
    if (!lv && compute >= 0 && compute < level) { /* out_open must refuse an uncomputed level */
        if ((s = out_open(&rq, fmt, &err)))
            fprintf(stderr, "outwrite: out_open accepted level %d with %d computed\n", level,
                    sd_complex_levels_computed(c));
        else
            fprintf(stderr, "outwrite: %s: %s\n", sd_result_name(err.code), err.message);
        goto done;
    }
    if (!lv) {
        fprintf(stderr, "outwrite: %s: %s\n", sd_result_name(err.code), err.message);
        goto done;
    }
    if (use_geometry && !(rq.geometry = geo = out_geometry_compute(lv))) {
        fprintf(stderr, "outwrite: out of memory computing the geometry\n");
        goto done;
    }
    s = out_open(&rq, fmt, &err);
    if (!s) {
        fprintf(stderr, "outwrite: %s: %s\n", sd_result_name(err.code), err.message);
        goto done;
    }
    uint64_t total = 0;
    if ((rc = drain(s, outpath, chunk, &total)))
        goto done;
    if (stats) {
        static const char *const kinds[] = {"points", "edges", "triangles", "tetrahedra", "octahedra"};
        printf("level %d vertices %u", level, sd_level_num_vertices(lv));
        for (int k = 0; k < 5; k++)
            printf(" %s %u", kinds[k], sd_level_num_cells(lv, (sd_cell_kind)k));
        printf(" boundary %u bytes %llu\n", sd_level_solid_boundary(lv, NULL),
               (unsigned long long)total);
    }
    rc = 0;
done:
    out_close(s);
    out_geometry_free(geo);
    sd_complex_free(c);
    textmesh_free(&tm);
    return rc;
}
