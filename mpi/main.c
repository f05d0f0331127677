/* main.c — subdivd-mpi: one level of a big mesh refined by several MPI processes.
 *
 *     mpirun -n N subdivd-mpi refine INPUT.json|INPUT.txt --level L -o OUT.pvtu [--tags T.json]
 *            [--rules R.json] [--merge] [--halo K] [--max-memory BYTES] [--stats S.json]
 *            [--no-write] [-q | -qq]
 *
 * Rank 0 reads the mesh as `subdivd refine` does (the same api/ handlers: PUT /rules, PUT
 * /complex, PUT /tags bodies; the same validation and errors), partitions it and sends every
 * rank its piece (part.c); each rank refines its piece (piece.c) and writes the cells it owns
 * (vtu.c): OUT_R.vtu beside OUT.pvtu, which rank 0 writes last; with --merge (or an output
 * ending in .vtu), one VTU that rank 0 assembles in the one-process order.
 *
 * Failures: every phase ends with a collective check, so a failure on any rank stops every rank
 * there; the failing rank says what failed, rank 0 says where the run stopped, and all exit with
 * the same code (1: the mesh or tags were refused, 2: usage or a file, 3: a rank failed); rank 0
 * removes an index an earlier run left at OUT.pvtu before the pieces are written, and when a
 * piece or the index cannot be written, every rank removes the piece at its name. A rank
 * that dies outright is mpirun's to report (it then ends the others, non-zero).
 * Progress: one line per rank and phase on stderr, prefixed "subdivd-mpi: rank R/N" (-q: none
 * but errors and the summary; -qq: errors alone). Test hook: SUBDIVD_MPI_FAIL_AT=R:N fails the N-th allocation of
 * rank R from the refinement on (api_mem_fail_at), to test one rank failing alone.
 */
#include "../api/buf.h"
#include "../api/details.h"
#include "../api/handlers.h"
#include "../api/jsonin.h"
#include "../api/mem.h"
#include "../tests/tools/textmesh.h"
#include "mp.h"
#include <errno.h>
#include <mpi.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

enum { EXIT_REFUSED = 1, EXIT_USAGE = 2, EXIT_FAILED = 3 };

typedef struct args {
    const char *input, *out, *tags, *rules, *stats;
    int level, halo, merge, nowrite, quiet, one_at_a_time;
    uint64_t max_bytes;
} args;

static int rank_, nranks_;
static char tag_[64];

static void usage(FILE *f)
{
    fprintf(f, "usage: mpirun -n N subdivd-mpi refine INPUT.json --level L -o OUT.pvtu|OUT.vtu\n"
               "       [--tags T.json] [--rules R.json] [--merge] [--halo K] [--max-memory BYTES]\n"
               "       [--stats S.json] [--no-write] [--one-at-a-time] [-q | -qq]\n"
               "INPUT, --tags and --rules are the bodies of PUT /complex, /tags and /rules\n"
               "(docs/API.md), or INPUT.txt the text format of docs/TEXT_FORMAT.md;\n"
               "`subdiv refine --mpi N` converts other mesh files first.\n");
}

/* 0, or the exit code after saying what is wrong (rank 0 speaks). */
static int parse_args(int argc, char **argv, args *a)
{
    memset(a, 0, sizeof *a);
    a->level = -1;
    a->halo = -1; /* DECISIONS 44: 3 rings with tetrahedra and a non-manifold simplex, 2 with
                   * either, Ying-Zorin's rules or Chaikin's with a semi-sharp edge, else 1 */
    const char *why = NULL;
    if (argc < 2 || strcmp(argv[1], "refine"))
        why = "the command is `refine`";
    const char *level = NULL, *halo = NULL, *maxm = NULL;
    for (int i = 2; !why && i < argc; i++) {
        const char *o = argv[i];
        const char **dst = !strcmp(o, "--level") || !strcmp(o, "-l") ? &level
                           : !strcmp(o, "-o") || !strcmp(o, "--output") ? &a->out
                           : !strcmp(o, "--tags") ? &a->tags
                           : !strcmp(o, "--rules") ? &a->rules
                           : !strcmp(o, "--stats") ? &a->stats
                           : !strcmp(o, "--halo") ? &halo
                           : !strcmp(o, "--max-memory") ? &maxm
                                                        : NULL;
        if (dst) {
            if (i + 1 >= argc)
                why = "an option needs a value";
            else
                *dst = argv[++i];
        } else if (!strcmp(o, "--merge"))
            a->merge = 1;
        else if (!strcmp(o, "--no-write"))
            a->nowrite = 1;
        else if (!strcmp(o, "--one-at-a-time"))
            a->one_at_a_time = 1;
        else if (!strcmp(o, "-q") || !strcmp(o, "--quiet"))
            a->quiet = a->quiet > 1 ? 2 : 1;
        else if (!strcmp(o, "-qq"))
            a->quiet = 2;
        else if (o[0] == '-' && o[1]) {
            if (!rank_)
                fprintf(stderr, "subdivd-mpi: unknown option %s\n", o);
            why = "";
        } else if (!a->input)
            a->input = o;
        else
            why = "more than one INPUT";
    }
    char *end = NULL;
    if (!why && (!a->input || !level || (!a->out && !a->nowrite)))
        why = "INPUT, --level L and -o OUT are required";
    if (!why) {
        long l = strtol(level, &end, 10);
        if (!*level || *end || l < 0 || l > SD_MAX_LEVEL)
            why = "--level takes a whole number 0..12";
        a->level = (int)l;
    }
    if (!why && halo) {
        long h = strtol(halo, &end, 10);
        if (!*halo || *end || h < 0 || h > 8)
            why = "--halo takes a whole number 0..8";
        a->halo = (int)h;
    }
    if (!why && maxm) {
        unsigned long long m = strtoull(maxm, &end, 10);
        if (!*maxm || *end || maxm[0] == '-')
            why = "--max-memory takes a number of bytes";
        a->max_bytes = m;
    }
    if (!why && a->out) {
        size_t n = strlen(a->out);
        int vtu = n > 4 && !strcmp(a->out + n - 4, ".vtu");
        int pvtu = n > 5 && !strcmp(a->out + n - 5, ".pvtu");
        if (!vtu && !pvtu)
            why = "-o must end in .pvtu (a piece per rank) or .vtu (merged)";
        else if (a->merge && pvtu)
            why = "--merge writes one .vtu";
        a->merge |= vtu;
    }
    if (why) {
        if (!rank_) {
            if (*why)
                fprintf(stderr, "subdivd-mpi: %s\n", why);
            usage(stderr);
        }
        return EXIT_USAGE;
    }
    return 0;
}

/* ---- reading the mesh (rank 0), as `subdivd refine` does ----------------------------------- */

static char *read_file(const char *path, size_t *len)
{
    return api_read_file(tag_, path, SIZE_MAX, len);
}

static int report(const api_problem *p, const char *what)
{
    json_t *j = api_problem_json(p);
    char *t = json_dumps(j, JSON_INDENT(2));
    fprintf(stderr, "%s: %s refused (%d):\n%s\n", tag_, what, p->status, t ? t : "");
    api_free(t); /* jansson allocates with api/mem.c's functions */
    json_decref(j);
    return p->status == 413 || p->status == 422 || p->status == 400 ? EXIT_REFUSED : EXIT_FAILED;
}

/* Apply one change handler to *m: the body of a JSON file, or `given` (stolen) when not NULL. */
static int apply_file(api_model **m, const char *path, change_fn_t fn, const api_limits *lim,
                      json_t *given)
{
    size_t len = 0;
    char *buf = given ? NULL : read_file(path, &len);
    if (!buf && !given)
        return EXIT_USAGE;
    api_problem p = {0};
    api_model *next = NULL;
    api_apply_text(*m, fn, buf, len, given, NULL, lim, &next, &p);
    api_free(buf);
    if (!next)
        return report(&p, path);
    api_model_unref(*m);
    *m = next;
    return 0;
}

/* A mesh in the text format of docs/TEXT_FORMAT.md as the bodies of PUT /complex (vertices,
 * simplices, the `d` lines as diagonals) and PUT /tags (the `c` lines as sharpness; NULL when
 * there are none). 0, or EXIT_USAGE after saying why. */
static int text_bodies(const char *path, json_t **complex, json_t **tags)
{
    textmesh tm;
    char why[256];
    if (textmesh_read(path, &tm, why, sizeof why)) {
        fprintf(stderr, "%s: %s: %s\n", tag_, path, why);
        return EXIT_USAGE;
    }
    json_t *v = json_array(), *sx = json_array(), *dg = json_array(), *sh = json_array();
    for (size_t i = 0; i < tm.nv; i++)
        json_array_append_new(v, json_pack("[f,f,f]", tm.xyz[3 * i], tm.xyz[3 * i + 1],
                                           tm.xyz[3 * i + 2]));
    size_t o = 0, ntet = 0;
    long *tet_at = malloc((tm.ns + 1) * sizeof *tet_at); /* t-th tetrahedron -> simplex */
    for (size_t i = 0; i < tm.ns; i++) {
        json_t *q = json_array();
        for (int j = 0; j < tm.size[i]; j++)
            json_array_append_new(q, json_integer(tm.idx[o + (size_t)j]));
        o += tm.size[i];
        json_array_append_new(sx, q);
        if (tm.size[i] == 4 && tet_at)
            tet_at[ntet++] = (long)i;
    }
    int rc = 0;
    for (size_t i = 0; tet_at && i < tm.ndiag; i++) {
        long t = tm.diag[2 * i], k = tm.diag[2 * i + 1];
        if (t < 0 || (size_t)t >= ntet) {
            fprintf(stderr, "%s: %s: 'd %ld %ld' names no tetrahedron\n", tag_, path, t, k);
            rc = EXIT_USAGE;
            break;
        }
        json_array_append_new(dg, json_pack("[I,I]", (json_int_t)tet_at[t], (json_int_t)k));
    }
    for (size_t i = 0; i < tm.ncr; i++) {
        json_t *q = json_array();
        for (int j = 0; j < tm.crn[i]; j++)
            json_array_append_new(q, json_integer(tm.crv[3 * i + (size_t)j]));
        json_array_append_new(sh, json_pack("{s:o,s:f}", "simplex", q, "value", tm.crs[i]));
    }
    free(tet_at);
    *complex = json_pack("{s:o,s:o}", "vertices", v, "simplices", sx);
    if (json_array_size(dg))
        json_object_set(*complex, "diagonals", dg);
    json_decref(dg);
    *tags = json_array_size(sh) ? json_pack("{s:o}", "sharpness", sh) : (json_decref(sh), NULL);
    textmesh_free(&tm);
    if (rc || !tet_at) {
        json_decref(*complex);
        json_decref(*tags);
        if (!rc)
            fprintf(stderr, "%s: out of memory reading %s\n", tag_, path);
        return EXIT_USAGE;
    }
    return 0;
}

static int is_text(const char *path)
{
    size_t n = strlen(path);
    return n > 4 && !strcmp(path + n - 4, ".txt");
}

static int read_model(const args *a, api_model **out)
{
    api_limits lim = api_default_limits();
    lim.max_body_bytes = (size_t)1 << 40;
    lim.batch = true;
    lim.max_vertices = UINT32_MAX - 1;
    lim.max_simplices = UINT32_MAX - 1;
    lim.max_cells = UINT64_MAX;
    lim.max_session_bytes = 0;
    sd_error e = {0};
    api_model *m = api_model_new(NULL, NULL, 0, false, &e);
    if (!m)
        return EXIT_FAILED;
    int rc = 0;
    json_t *cb = NULL, *tb = NULL;
    if (is_text(a->input))
        rc = text_bodies(a->input, &cb, &tb);
    if (!rc)
        rc = apply_file(&m, a->input, api_put_complex, &lim, cb);
    else
        json_decref(tb), tb = NULL;
    if (!rc && a->rules) /* after the complex: overrides name its simplices */
        rc = apply_file(&m, a->rules, api_put_rules, &lim, NULL);
    if (!rc && a->tags) /* --tags replaces the text file's sharpness, as a PUT does */
        rc = apply_file(&m, a->tags, api_put_tags, &lim, NULL);
    else if (!rc && tb) {
        rc = apply_file(&m, a->input, api_put_tags, &lim, tb);
        tb = NULL;
    }
    json_decref(tb);
    if (rc) {
        api_model_unref(m);
        return rc;
    }
    *out = m;
    return 0;
}

/* ---- collective steps ---------------------------------------------------------------------- */

/* Every rank says whether it failed (with its exit code); all learn the worst. Returns 0 or the
 * exit code every rank then returns. */
/* Wait for a request, sleeping between tests: Open MPI's blocking calls poll a core flat out,
 * which a rank that finished early would take from the ranks still computing when the machine
 * has fewer cores than ranks (or other work). */
static void wait_sleeping(MPI_Request *rq)
{
    int done = 0;
    struct timespec ts = {0, 1000000};
    for (MPI_Test(rq, &done, MPI_STATUS_IGNORE); !done; MPI_Test(rq, &done, MPI_STATUS_IGNORE))
        nanosleep(&ts, NULL);
}

static int checkpoint(int code, const char *phase)
{
    int mine[2] = {code, code ? rank_ + 1 : 0}, all[2];
    MPI_Request rq;
    MPI_Iallreduce(mine, all, 2, MPI_INT, MPI_MAX, MPI_COMM_WORLD, &rq);
    wait_sleeping(&rq);
    if (all[0] && !rank_ && !code)
        fprintf(stderr, "subdivd-mpi: stopped (%s) after a failure on rank %d\n", phase,
                all[1] - 1);
    return all[0];
}

static int send_bytes(const unsigned char *d, uint64_t n, int to)
{
    MPI_Send(&n, 1, MPI_UINT64_T, to, 1, MPI_COMM_WORLD);
    for (uint64_t o = 0; o < n; o += 1u << 30) {
        int c = (int)(n - o < (1u << 30) ? n - o : (1u << 30));
        MPI_Send(d + o, c, MPI_BYTE, to, 2, MPI_COMM_WORLD);
    }
    return 0;
}

static unsigned char *recv_bytes(int from, uint64_t *n)
{
    MPI_Request rq;
    MPI_Irecv(n, 1, MPI_UINT64_T, from, 1, MPI_COMM_WORLD, &rq);
    wait_sleeping(&rq);
    unsigned char *d = malloc((size_t)*n + 1);
    for (uint64_t o = 0; o < *n; o += 1u << 30) {
        int c = (int)(*n - o < (1u << 30) ? *n - o : (1u << 30));
        /* without memory, still drain the message (into a scratch byte), then fail */
        if (d)
            MPI_Recv(d + o, c, MPI_BYTE, from, 2, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
        else {
            unsigned char *s = malloc((size_t)c);
            MPI_Recv(s, c, MPI_BYTE, from, 2, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
            free(s);
        }
    }
    return d;
}

typedef struct rstat {
    double t_read, t_partition, t_cut, t_distribute, t_build, t_refine, t_ids, t_compute, t_write;
    double cpu_compute;
    long maxrss_kb;
    uint64_t owned_simplices, halo_simplices, owned_cells, local_cells, bytes;
    uint64_t classes_shipped, classes_differing, rules_checked;
} rstat;

static double cpu_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* OUT.pvtu -> OUT_R.vtu (path) and its name relative to the .pvtu */
static void piece_path(const char *out, int r, char *path, size_t n)
{
    size_t l = strlen(out) - 5;
    snprintf(path, n, "%.*s_%d.vtu", (int)l, out, r);
}

static int write_stats(const args *a, const rstat *st, const mp_piece *p)
{
    json_t *ranks = json_array();
    for (int r = 0; r < nranks_; r++) {
        const rstat *s = &st[r];
        json_array_append_new(
            ranks, json_pack("{s:i,s:I,s:I,s:I,s:I,s:f,s:f,s:f,s:f,s:f,s:f,s:f,s:f,s:f,s:I,s:I}",
                             "rank", r, "owned_simplices", (json_int_t)s->owned_simplices,
                             "halo_simplices", (json_int_t)s->halo_simplices, "owned_cells",
                             (json_int_t)s->owned_cells, "local_cells", (json_int_t)s->local_cells,
                             "read_s", s->t_read, "partition_s", s->t_partition, "cut_s", s->t_cut,
                             "distribute_s", s->t_distribute, "build_s", s->t_build, "refine_s",
                             s->t_refine, "ids_s", s->t_ids, "compute_s", s->t_compute,
                             "compute_cpu_s", s->cpu_compute, "write_bytes", (json_int_t)s->bytes,
                             "peak_rss_bytes", (json_int_t)s->maxrss_kb * 1024));
        json_t *o = json_array_get(ranks, (size_t)r);
        json_object_set_new(o, "write_s", json_real(s->t_write));
        json_object_set_new(o, "classes_shipped", json_integer((json_int_t)s->classes_shipped));
        json_object_set_new(o, "classes_differing", json_integer((json_int_t)s->classes_differing));
        json_object_set_new(o, "rules_checked", json_integer((json_int_t)s->rules_checked));
    }
    const sd_counts *G = &p->global[p->level];
    json_t *j = json_pack("{s:i,s:i,s:i,s:{s:I,s:I,s:I,s:I,s:I,s:I},s:o}", "ranks", nranks_,
                          "level", a->level, "halo", p->halo, "level_counts", "points",
                          (json_int_t)G->vertices, "point_cells", (json_int_t)G->points, "curves",
                          (json_int_t)G->curves, "triangles", (json_int_t)G->triangles,
                          "tetrahedra", (json_int_t)G->tetrahedra, "octahedra",
                          (json_int_t)G->octahedra, "per_rank", ranks);
    int rc = 0;
    if (!j || json_dump_file(j, a->stats, JSON_INDENT(1))) {
        fprintf(stderr, "subdivd-mpi: cannot write %s\n", a->stats);
        rc = EXIT_USAGE;
    }
    json_decref(j);
    return rc;
}

/* Whether the directory of file `path` takes new files; says so when not. */
static bool dir_writable(const char *path)
{
    const char *slash = strrchr(path, '/');
    char dir[4096];
    snprintf(dir, sizeof dir, "%.*s", !slash ? 1 : slash == path ? 1 : (int)(slash - path),
             slash ? path : ".");
    struct stat sb;
    if (!stat(dir, &sb) && !S_ISDIR(sb.st_mode))
        errno = ENOTDIR; /* access() would say "Permission denied" (no search bit), even to root */
    else if (!access(dir, W_OK | X_OK))
        return true;
    fprintf(stderr, "%s: cannot write into %s: %s\n", tag_, dir, strerror(errno));
    return false;
}

/* EXIT_USAGE ("a file") when this rank is to write into the directory of OUT (every rank for
 * pieces, rank 0 for a merged VTU) or of --stats (rank 0) and cannot: found before the work,
 * not after it. */
static int check_output_dir(const args *a)
{
    bool ok = true;
    if (!a->nowrite && !(a->merge && rank_))
        ok = dir_writable(a->out);
    if (ok && a->stats && !rank_)
        ok = dir_writable(a->stats);
    return ok ? 0 : EXIT_USAGE;
}

static int run(const args *a)
{
    rstat st = {0};
    char err[512] = "";
    mp_piece *pieces = NULL, piece = {0};
    mp_result res = {0};
    int rc = checkpoint(check_output_dir(a), "checking the output directory");
    if (rc)
        return rc;
    double t = mp_now();
    /* 1. rank 0 reads, partitions and cuts */
    if (!rank_) {
        api_model *m = NULL;
        rc = read_model(a, &m);
        st.t_read = mp_now() - t;
        if (!rc && m->tags.ntt) { /* the modifications read whole curves and petals (DECISIONS 47) */
            fprintf(stderr, "%s: tangent-plane constraints (normals, tangents, tangent_edges) are "
                            "not offered across ranks; use subdivd refine\n", tag_);
            rc = EXIT_REFUSED;
        }
        if (!rc && api_details_count(m)) { /* offsets of level-l points by one-process index */
            fprintf(stderr, "%s: detail offsets (PUT /complex \"details\") are not applied across "
                            "ranks; use subdivd refine\n", tag_);
            rc = EXIT_REFUSED;
        }
        if (!rc) {
            double tp = mp_now();
            pieces = calloc((size_t)nranks_, sizeof *pieces);
            if (!pieces || mp_partition(m, a->level, nranks_, a->halo, pieces, &st.t_partition,
                                        err, sizeof err)) {
                fprintf(stderr, "%s: partition failed: %s\n", tag_, pieces ? err : "out of memory");
                rc = EXIT_FAILED;
            }
            st.t_cut = mp_now() - tp - st.t_partition;
            if (!rc && !a->quiet)
                fprintf(stderr, "%s: read %u vertices, %u simplices (%.2f s); %d parts (%.2f s)\n",
                        tag_, m->in->nv, m->in->ns, st.t_read, nranks_, mp_now() - tp);
        }
        if (m)
            api_model_unref(m);
    }
    if ((rc = checkpoint(rc, "reading and partitioning")))
        goto done;
    double tc = mp_now(), cpu0 = cpu_now();
    if (!rank_)
        tc -= st.t_partition + st.t_cut, cpu0 -= st.t_partition + st.t_cut;
    /* 2. distribute */
    double td = mp_now();
    if (!rank_) {
        for (int r = 1; r < nranks_; r++) {
            mp_buf b = {0};
            mp_pack(&pieces[r], &b);
            if (b.failed) {
                fprintf(stderr, "%s: out of memory packing piece %d\n", tag_, r);
                b.len = 0; /* the rank then fails to unpack an empty piece */
            }
            send_bytes(b.data, b.len, r);
            free(b.data);
            mp_piece_free(&pieces[r]);
        }
        piece = pieces[0];
        free(pieces);
        pieces = NULL;
    } else {
        uint64_t n;
        unsigned char *d = recv_bytes(0, &n);
        if (!d || mp_unpack(d, (size_t)n, &piece)) {
            fprintf(stderr, "%s: %s\n", tag_, d ? "the piece did not arrive whole" : "out of memory");
            rc = EXIT_FAILED;
        }
        free(d);
    }
    st.t_distribute = mp_now() - td;
    if ((rc = checkpoint(rc, "distributing the pieces")))
        goto done;
    if (!a->quiet)
        fprintf(stderr, "%s: piece of %u simplices (%u owned, %u in %d halo rings), %u vertices\n",
                tag_, piece.ns, piece.ns - piece.nhalo, piece.nhalo, piece.halo, piece.nv);
    st.owned_simplices = piece.ns - piece.nhalo;
    st.halo_simplices = piece.nhalo;
    /* 3. refine (--one-at-a-time: rank r starts when rank r-1 is done, so each is timed as if
     * alone on its machine; a benchmark of a machine with fewer free cores than ranks) */
    int turn = 0;
    if (a->one_at_a_time && rank_) {
        MPI_Request rq;
        MPI_Irecv(&turn, 1, MPI_INT, rank_ - 1, 3, MPI_COMM_WORLD, &rq);
        wait_sleeping(&rq);
        tc = mp_now() - st.t_distribute; /* its share of the distribution still counts */
        cpu0 = cpu_now();
    }
    /* test hook: SUBDIVD_MPI_FAIL_AT=R:N fails rank R's N-th allocation from here on (api/mem.h),
     * so tests see one rank fail alone */
    const char *hook = getenv("SUBDIVD_MPI_FAIL_AT");
    int hook_rank;
    unsigned long long hook_n;
    if (hook && sscanf(hook, "%d:%llu", &hook_rank, &hook_n) == 2 && hook_rank == rank_)
        api_mem_fail_at(hook_n, 0);
    if (mp_refine(&piece, a->max_bytes, a->quiet, tag_, &res, err, sizeof err)) {
        fprintf(stderr, "%s: %s\n", tag_, err);
        rc = EXIT_FAILED;
    }
    st.t_build = res.seconds_build;
    st.t_refine = res.seconds_refine;
    st.t_ids = res.seconds_ids;
    st.owned_cells = res.owned_cells;
    st.local_cells = res.local_cells;
    st.classes_shipped = res.classes_shipped;
    st.classes_differing = res.classes_differing;
    st.rules_checked = res.rules_checked;
    st.t_compute = mp_now() - tc;
    st.cpu_compute = cpu_now() - cpu0;
    if (a->one_at_a_time && a->nowrite) /* as on a machine of its own: the next rank does not
                                          * find this one's memory taken */
        mp_result_free(&res);
    if (a->one_at_a_time && rank_ + 1 < nranks_)
        MPI_Send(&turn, 1, MPI_INT, rank_ + 1, 3, MPI_COMM_WORLD);
    if ((rc = checkpoint(rc, "refining")))
        goto done;
    if (!a->quiet) {
        fprintf(stderr, "%s: level-0 classes: %llu from the whole complex (%llu differing from "
                "the piece's own), %llu rules checked equal\n", tag_,
                (unsigned long long)st.classes_shipped, (unsigned long long)st.classes_differing,
                (unsigned long long)st.rules_checked);
        fprintf(stderr, "%s: level %d: %llu of %llu cells owned (compute %.2f s)\n", tag_,
                a->level, (unsigned long long)st.owned_cells, (unsigned long long)st.local_cells,
                st.t_compute);
    }
    /* 4. write */
    double tw = mp_now();
    if (a->nowrite) {
        /* benchmarks: nothing written */
    } else if (!a->merge) {
        char path[4096];
        /* an index left by an earlier run names pieces about to be replaced (or removed, if this
         * write fails): it goes first, so a failure leaves no index that opens as a result */
        if (!rank_ && unlink(a->out) && errno != ENOENT)
            fprintf(stderr, "%s: cannot remove the old %s: %s\n", tag_, a->out, strerror(errno));
        piece_path(a->out, rank_, path, sizeof path);
        int wrote = !mp_write_piece(&piece, &res, path, &st.bytes, err, sizeof err);
        if (!wrote) {
            fprintf(stderr, "%s: %s\n", tag_, err);
            rc = EXIT_FAILED;
        }
        if (!(rc = checkpoint(rc, "writing the pieces")) && !rank_) {
            char **names = calloc((size_t)nranks_, sizeof *names);
            const char *slash = strrchr(a->out, '/');
            for (int r = 0; names && r < nranks_; r++) {
                piece_path(slash ? slash + 1 : a->out, r, path, sizeof path);
                names[r] = strdup(path);
            }
            if (!names || mp_write_pvtu(a->out, &piece, nranks_, names, err, sizeof err)) {
                fprintf(stderr, "%s: %s\n", tag_, names ? err : "out of memory");
                rc = EXIT_FAILED;
            }
            for (int r = 0; names && r < nranks_; r++)
                free(names[r]);
            free(names);
        }
        if ((rc = checkpoint(rc, "writing the index"))) {
            /* a piece without the others or the index is no result: each rank removes its own
             * (path again: rank 0 reused it for the index's names), or the one an earlier run
             * left at its name when it could not write (a file: unlink leaves a directory) */
            piece_path(a->out, rank_, path, sizeof path);
            unlink(path);
            goto done;
        }
    } else {
        mp_buf b = {0};
        mp_merge_blob(&piece, &res, &b);
        if (b.failed) {
            fprintf(stderr, "%s: out of memory preparing the merge\n", tag_);
            rc = EXIT_FAILED;
        }
        if ((rc = checkpoint(rc, "preparing the merge"))) {
            free(b.data);
            goto done;
        }
        if (rank_) {
            send_bytes(b.data, b.len, 0);
        } else {
            unsigned char **blobs = calloc((size_t)nranks_, sizeof *blobs);
            size_t *lens = calloc((size_t)nranks_, sizeof *lens);
            int ok = blobs && lens;
            if (ok) {
                blobs[0] = b.data;
                lens[0] = b.len;
                for (int r = 1; r < nranks_; r++) {
                    uint64_t n;
                    blobs[r] = recv_bytes(r, &n);
                    lens[r] = (size_t)n;
                    ok &= blobs[r] != NULL;
                }
            }
            if (!ok || mp_merge_write(a->out, &piece, (const unsigned char *const *)blobs, lens,
                                      nranks_, &st.bytes, err, sizeof err)) {
                fprintf(stderr, "%s: merge failed: %s\n", tag_, ok ? err : "out of memory");
                rc = EXIT_FAILED;
            }
            for (int r = 1; blobs && r < nranks_; r++)
                free(blobs[r]);
            free(blobs);
            free(lens);
        }
        free(b.data);
        if ((rc = checkpoint(rc, "merging")))
            goto done;
    }
    st.t_write = mp_now() - tw;
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    st.maxrss_kb = ru.ru_maxrss;
    rstat *all = rank_ ? NULL : calloc((size_t)nranks_, sizeof *all);
    MPI_Gather(&st, (int)sizeof st, MPI_BYTE, all, (int)sizeof st, MPI_BYTE, 0, MPI_COMM_WORLD);
    if (!rank_ && all) {
        double comp = 0, cpu = 0, wr = 0;
        long rss = 0;
        uint64_t local = 0, owned = 0;
        for (int r = 0; r < nranks_; r++) {
            comp = all[r].t_compute > comp ? all[r].t_compute : comp;
            cpu = all[r].cpu_compute > cpu ? all[r].cpu_compute : cpu;
            wr = all[r].t_write > wr ? all[r].t_write : wr;
            rss = all[r].maxrss_kb > rss ? all[r].maxrss_kb : rss;
            local += all[r].local_cells;
            owned += all[r].owned_cells;
        }
        if (a->quiet < 2)
            fprintf(stderr, "subdivd-mpi: level %d on %d ranks: compute %.2f s (CPU %.2f s on the "
                            "slowest rank; read %.2f s apart), write %.2f s, peak memory %.1f MB "
                            "on the largest rank, halo %.1f%% of the cells computed -> %s\n",
                    a->level, nranks_, comp, cpu, all[0].t_read, wr, rss / 1024.0,
                    local ? 100.0 * (double)(local - owned) / (double)local : 0.0,
                    a->nowrite ? "(not written)" : a->out);
        if (a->stats && write_stats(a, all, &piece) && !rc)
            rc = EXIT_USAGE; /* "a file" (docs/BATCH.md): the pieces stay, the stats are not */
    }
    free(all);
done:
    mp_result_free(&res);
    mp_piece_free(&piece);
    return rc;
}

int main(int argc, char **argv)
{
    MPI_Init(&argc, &argv);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
    MPI_Comm_size(MPI_COMM_WORLD, &nranks_);
    snprintf(tag_, sizeof tag_, "subdivd-mpi: rank %d/%d", rank_, nranks_);
    if (argc > 1 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        if (!rank_)
            usage(stdout);
        MPI_Finalize();
        return 0;
    }
    args a;
    int rc = parse_args(argc, argv, &a);
    if (!rc)
        rc = run(&a);
    MPI_Finalize();
    return rc;
}
