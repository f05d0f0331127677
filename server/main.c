/* main.c — the subdivd binary: the daemon, `subdivd refine` and `subdivd deform` (the offline
 * mode).
 *
 * Both modes go through the same api/ handlers: the daemon maps HTTP requests onto them, the
 * offline mode maps files and flags onto them and writes the level with the same streaming
 * writer into a file — same validation, same errors (printed as problem+json), same bytes.
 */
#include "../api/buf.h"
#include "../api/embedded.h"
#include "../api/handlers.h"
#include "../api/mem.h"
#include "../api/jsonin.h"
#include "metrics.h"
#include "holds.h"
#include "probe.h"
#include "rate.h"
#include "server.h"
#include <errno.h>
#include <malloc.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static volatile sig_atomic_t stop_requested; /* signals received: 1 drains, 2 cuts short */
static void on_signal(int sig)
{
    (void)sig;
    if (stop_requested < 2)
        stop_requested++;
}

/* ---- offline mode ------------------------------------------------------------------------- */

static char *read_file(const char *path, size_t max, size_t *len)
{
    return api_read_file("subdivd", path, max, len);
}

static int report(const api_problem *p, const char *what)
{
    json_t *j = api_problem_json(p);
    char *t = json_dumps(j, JSON_INDENT(2));
    fprintf(stderr, "subdivd: %s refused (%d):\n%s\n", what, p->status, t ? t : "");
    api_free(t);
    json_decref(j);
    return p->status == 413 || p->status == 422 || p->status == 400 ? 1 : 3;
}

/* Apply one change handler to *m from a JSON file (NULL: an empty body), with the members of
 * `extra` (borrowed; may be NULL: the command line's --repair, --crease-angle) added. */
static int apply_file(api_model **m, const char *path, change_fn_t fn, const api_limits *lim,
                      const char *what, json_t *extra)
{
    size_t len = 0;
    char *buf = path ? read_file(path, lim->max_body_bytes, &len) : NULL;
    if (path && !buf)
        return 2;
    api_problem p = {0};
    api_model *next = NULL;
    api_apply_text(*m, fn, buf, len, NULL, extra, lim, &next, &p);
    api_free(buf);
    if (!next)
        return report(&p, what);
    api_model_unref(*m);
    *m = next;
    return 0;
}

/* The command line of `subdivd refine`. */
typedef struct refine_args {
    const char *input, *out, *tags, *rules, *level, *crease_angle, *threads;
    int repair;               /* --repair: PUT /complex's "repair" */
    api_level_query q;        /* --format (else from -o's extension), --parts, ... */
} refine_args;

/* 0, or the exit code after saying what is wrong. */
static int parse_refine_args(int argc, char **argv, refine_args *a)
{
    memset(a, 0, sizeof *a);
    for (int i = 2; i < argc; i++) {
        const char *o = argv[i];
        const char **dst = !strcmp(o, "--level") || !strcmp(o, "-l") ? &a->level
                           : !strcmp(o, "-o") || !strcmp(o, "--output") ? &a->out
                           : !strcmp(o, "--tags") ? &a->tags
                           : !strcmp(o, "--rules") ? &a->rules
                           : !strcmp(o, "--format") ? &a->q.format
                           : !strcmp(o, "--parts") ? &a->q.parts
                           : !strcmp(o, "--slice") ? &a->q.slice
                           : !strcmp(o, "--attributes") ? &a->q.attributes
                           : !strcmp(o, "--colormap") ? &a->q.colormap
                           : !strcmp(o, "--octahedra") ? &a->q.octahedra
                           : !strcmp(o, "--names") ? &a->q.names
                           : !strcmp(o, "--compress") ? &a->q.compress
                           : !strcmp(o, "--crease-angle") ? &a->crease_angle
                           : !strcmp(o, "--threads") ? &a->threads
                                                       : NULL;
        if (!strcmp(o, "--repair"))
            a->repair = 1;
        else if (!strcmp(o, "--limit")) /* GET /levels/{L}?limit=true */
            a->q.limit = "true";
        else if (dst) {
            if (i + 1 >= argc) {
                fprintf(stderr, "subdivd refine: %s needs a value\n", o);
                return 2;
            }
            *dst = argv[++i];
        } else if (o[0] == '-' && o[1]) {
            fprintf(stderr, "subdivd refine: unknown option %s\n", o);
            config_usage(stderr);
            return 2;
        } else if (!a->input)
            a->input = o;
        else {
            fprintf(stderr, "subdivd refine: unexpected argument %s\n", o);
            return 2;
        }
    }
    if (!a->input || !a->out || !a->level) {
        fprintf(stderr, "subdivd refine: INPUT.json, --level L and -o OUT are required\n");
        config_usage(stderr);
        return 2;
    }
    if (!a->q.format) { /* from the output's extension (the table of api/formats.c) */
        const out_format *f = out_format_for_path(a->out);
        if (!f) {
            char names[128];
            fprintf(stderr, "subdivd refine: cannot tell the format from \"%s\"; use %s, or "
                    "--format\n", a->out, out_format_list(names, sizeof names, true, ", ", " or "));
            return 2;
        }
        a->q.format = f->name;
    }
    return 0;
}

/* Drain the stream into `out` through OUT.part, renamed at the end: nothing half-written is
 * left behind. 0, 2 (I/O) or 3 (the writer failed); *total = bytes written. */
static int write_stream(out_stream *os, const char *out, uint64_t *total)
{
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.part", out);
    FILE *f = fopen(tmp, "wb");
    int rc = 0;
    if (!f) {
        fprintf(stderr, "subdivd refine: cannot write %s: %s\n", tmp, strerror(errno));
        rc = 2;
    }
    static char buf[1 << 16];
    ssize_t n;
    *total = 0;
    while (!rc && (n = out_read(os, buf, sizeof buf)) > 0) {
        if (fwrite(buf, 1, (size_t)n, f) != (size_t)n)
            rc = 2;
        *total += (uint64_t)n;
    }
    if (!rc && n < 0)
        rc = 3;
    if (f && fclose(f))
        rc = 2;
    if (!rc && rename(tmp, out))
        rc = 2;
    if (rc && f)
        unlink(tmp);
    return rc;
}

static int refine_main(int argc, char **argv)
{
    refine_args a;
    int rc = parse_refine_args(argc, argv, &a);
    if (rc)
        return rc;
    api_limits lim = api_default_limits();
    lim.batch = true; /* written out, never edited: no edit index (DECISIONS 46) */
    long nt = config_default_level_threads(); /* --threads: the same bytes for any */
    if (a.threads) {
        char *end;
        nt = strtol(a.threads, &end, 10);
        if (!*a.threads || *end || nt < 1 || nt > 64) {
            fprintf(stderr, "subdivd refine: --threads needs a whole number from 1 to 64, not "
                    "%s\n", a.threads);
            return 2;
        }
    }
    api_set_compute_threads((int)nt);
    api_mem_keep_set(256u << 20); /* a build's transient arrays reuse each other's pages */
    api_problem p = {0};
    int level = api_parse_level(a.level, &p);
    if (level < 0)
        return report(&p, "--level");
    sd_error e = {0};
    api_model *m = api_model_new(NULL, NULL, 0, false, &e);
    if (!m)
        return 3;
    json_t *repair = json_pack("{s:b}", "repair", a.repair), *crease = NULL;
    if (a.crease_angle) { /* a number here; its range is PUT /tags's (422) */
        char *end;
        double deg = strtod(a.crease_angle, &end);
        /* strtod also reads nan, inf and overflows to inf: JSON has no such number */
        if (!*a.crease_angle || *end || !isfinite(deg)) {
            fprintf(stderr, "subdivd refine: --crease-angle needs a number of degrees, not %s\n",
                    a.crease_angle);
            rc = 2;
        } else
            crease = json_pack("{s:f}", "crease_angle", deg);
    }
    /* the complex first: per-simplex overrides in --rules name its simplices */
    if (!rc)
        rc = apply_file(&m, a.input, api_put_complex, &lim, a.input, a.repair ? repair : NULL);
    if (!rc && a.rules)
        rc = apply_file(&m, a.rules, api_put_rules, &lim, a.rules, NULL);
    if (!rc && (a.tags || crease))
        rc = apply_file(&m, a.tags, api_put_tags, &lim, a.tags ? a.tags : "--crease-angle", crease);
    json_decref(repair);
    json_decref(crease);
    if (!rc && a.repair && m->summary && json_object_get(m->summary, "repaired_count"))
        fprintf(stderr, "subdivd refine: repaired: %lld simplices dropped\n",
                (long long)json_integer_value(json_object_get(m->summary, "repaired_count")));
    if (!rc && crease)
        fprintf(stderr, "subdivd refine: crease angle: %u edges tagged\n", m->tags.crease.tagged);
    out_stream *os = NULL;
    const out_format *fmt;
    uint64_t version;
    atomic_store(&m->version, 1); /* the version a session's first complex has */
    if (!rc && api_level_open(m, level, &a.q, &lim, NULL, &os, &fmt, &version, &p))
        rc = report(&p, "the level request");
    if (rc) {
        api_model_unref(m);
        return rc;
    }
    uint64_t total;
    rc = write_stream(os, a.out, &total);
    if (!rc)
        fprintf(stderr, "subdivd refine: level %d -> %s (%llu bytes, %.3f s)\n", level, a.out,
                (unsigned long long)total, m->seconds[level]);
    out_close(os);
    api_model_unref(m);
    return rc;
}

/* ---- subdivd deform: an embedded model through edits, offline ---------------------------- */

/* A Wavefront OBJ's vertices and faces (polygons as fans) as the body of PUT /embedded/{name}:
 * {"vertices", "triangles"}; NULL (said why) when it cannot be read. Records are "v x y z"
 * (a w or a colour after them ignored) and "f i j k ..." (1-based, negative counting back from
 * the last "v", "i/t/n" forms keep i), their key followed by a space or a tab; "#" starts a
 * comment; other records (vn, vt, o, g, s, usemtl, ...) are skipped. A coordinate that is not a
 * finite number, or an index that is not one, is refused with its line: a vertex silently left
 * out would shift every later index. */
static json_t *obj_model(const char *text, size_t len, const char *path)
{
    json_t *vs = json_array(), *ts = json_array();
    size_t nv = 0;
    const char *s = text, *end = text + len;
    for (int line = 1; vs && ts && s < end; line++) {
        const char *e = memchr(s, '\n', (size_t)(end - s));
        size_t n = e ? (size_t)(e - s) : (size_t)(end - s);
        char buf[4096];
        if (n >= sizeof buf) {
            fprintf(stderr, "subdivd deform: %s:%d: line too long\n", path, line);
            goto bad;
        }
        memcpy(buf, s, n);
        buf[n] = 0;
        s += n + 1;
        char *hash = strchr(buf, '#');
        if (hash)
            *hash = 0;
        char *b = buf + strspn(buf, " \t\r");
        bool vert = b[0] == 'v' && (b[1] == ' ' || b[1] == '\t');
        bool face = b[0] == 'f' && (b[1] == ' ' || b[1] == '\t');
        if (vert) {
            double x[3];
            char *t = b + 2;
            for (int k = 0; k < 3; k++) {
                char *te;
                errno = 0;
                x[k] = strtod(t, &te);
                if (te == t || (*te && !strchr(" \t\r", *te))) {
                    fprintf(stderr, "subdivd deform: %s:%d: a vertex is \"v x y z\"\n", path, line);
                    goto bad;
                }
                if (!isfinite(x[k]) || errno == ERANGE) {
                    fprintf(stderr, "subdivd deform: %s:%d: coordinate %d of the vertex is not a "
                            "finite number\n", path, line, k + 1);
                    goto bad;
                }
                t = te;
            }
            if (json_array_append_new(vs, json_pack("[f, f, f]", x[0], x[1], x[2])))
                goto nomem;
            nv++;
        } else if (face) {
            long first = -1, prev = -1;
            int k = 0;
            for (char *t = strtok(b + 2, " \t\r"); t; t = strtok(NULL, " \t\r"), k++) {
                char *te;
                errno = 0;
                long i = strtol(t, &te, 10); /* "i", "i/t", "i//n", "i/t/n"; negative: relative */
                if (te == t || (*te && *te != '/') || errno == ERANGE) {
                    fprintf(stderr, "subdivd deform: %s:%d: \"%s\" is not a vertex index\n", path,
                            line, t);
                    goto bad;
                }
                long j = i < 0 ? (long)nv + i : i - 1;
                if (i == 0 || j < 0 || (size_t)j >= nv) {
                    fprintf(stderr, "subdivd deform: %s:%d: a face names a vertex not defined "
                            "before it\n", path, line);
                    goto bad;
                }
                if (k >= 2 && json_array_append_new(ts, json_pack("[I, I, I]", (json_int_t)first,
                                                                  (json_int_t)prev, (json_int_t)j)))
                    goto nomem;
                first = k == 0 ? j : first;
                prev = j;
            }
            if (k < 3) {
                fprintf(stderr, "subdivd deform: %s:%d: a face needs at least 3 vertices\n", path,
                        line);
                goto bad;
            }
        }
    }
    if (vs && ts)
        return json_pack("{s:o, s:o}", "vertices", vs, "triangles", ts);
nomem:
    fprintf(stderr, "subdivd deform: %s: out of memory\n", path);
bad:
    json_decref(vs);
    json_decref(ts);
    return NULL;
}

static int deform_main(int argc, char **argv)
{
    const char *input = NULL, *embed = NULL, *level = "2", *outside = "refuse", *moves = NULL,
               *out = NULL, *tags = NULL, *rules = NULL;
    for (int i = 2; i < argc; i++) {
        const char *o = argv[i];
        const char **dst = !strcmp(o, "--embed") ? &embed
                           : !strcmp(o, "--level") || !strcmp(o, "-l") ? &level
                           : !strcmp(o, "--outside") ? &outside
                           : !strcmp(o, "--moves") ? &moves
                           : !strcmp(o, "--tags") ? &tags
                           : !strcmp(o, "--rules") ? &rules
                           : !strcmp(o, "-o") || !strcmp(o, "--output") ? &out
                                                                         : NULL;
        if (dst && i + 1 < argc)
            *dst = argv[++i];
        else if (dst || (o[0] == '-' && o[1])) {
            fprintf(stderr, "subdivd deform: %s %s\n", o, dst ? "needs a value" : "is not an option");
            return 2;
        } else if (!input)
            input = o;
        else {
            fprintf(stderr, "subdivd deform: unexpected argument %s\n", o);
            return 2;
        }
    }
    const char *ext = out ? strrchr(out, '.') : NULL;
    const char *format = !ext ? NULL : !strcmp(ext, ".obj") ? "obj" : !strcmp(ext, ".json") ? "json"
                                     : !strcmp(ext, ".glb") ? "glb" : NULL;
    if (!input || !embed || !out || !format) {
        fprintf(stderr, "usage: subdivd deform COMPLEX.json --embed MODEL.obj|.json [--level L] "
                        "[--outside refuse|fixed|nearest] [--moves MOVES.json] [--tags T.json] "
                        "[--rules R.json] -o OUT.obj|.json|.glb\n");
        return 2;
    }
    api_limits lim = api_default_limits();
    sd_error e = {0};
    api_model *m = api_model_new(NULL, NULL, 0, false, &e);
    if (!m)
        return 3;
    int rc = rules ? apply_file(&m, rules, api_put_rules, &lim, rules, NULL) : 0;
    if (!rc)
        rc = apply_file(&m, input, api_put_complex, &lim, input, NULL);
    if (!rc && tags)
        rc = apply_file(&m, tags, api_put_tags, &lim, tags, NULL);
    size_t len;
    char *text = rc ? NULL : read_file(embed, lim.max_body_bytes, &len);
    json_t *body = NULL;
    api_problem p = {0};
    if (!rc && !text)
        rc = 2;
    else if (!rc) {
        const char *mx = strrchr(embed, '.');
        body = mx && !strcmp(mx, ".json") ? api_parse_body(text, len, 0, &p)
                                          : obj_model(text, len, embed);
        if (!body)
            rc = p.status ? report(&p, embed) : 2;
    }
    api_free(text);
    int lvl = rc ? 0 : api_parse_level(level, &p);
    if (lvl < 0)
        rc = report(&p, "--level");
    api_embed_def *d = NULL;
    uint64_t version = 1;
    atomic_store(&m->version, version);
    if (!rc) {
        json_t *lv = json_integer(lvl), *os = json_string(outside);
        json_object_set_new(body, "level", lv);
        json_object_set_new(body, "outside", os);
        if (api_embed_parse(body, "model", &lim, &d, &p))
            rc = report(&p, embed);
    }
    json_decref(body);
    json_t *summary = NULL;
    if (!rc && api_embed_put(m, d, ++version, &lim, NULL, NULL, &summary, &p))
        rc = report(&p, "binding the model");
    api_embed_def_unref(d);
    if (!rc && summary)
        fprintf(stderr, "subdivd deform: %s bound to level %s (%lld vertices outside)\n", embed,
                level, (long long)json_integer_value(json_object_get(summary, "outside_vertices")));
    json_decref(summary);
    if (!rc && moves) { /* a PATCH body, or an array of them applied in turn */
        char *mt = read_file(moves, lim.max_body_bytes, &len);
        json_t *mj = mt ? api_parse_body(mt, len, 0, &p) : NULL;
        api_free(mt);
        if (!mj)
            rc = mt ? report(&p, moves) : 2;
        for (size_t i = 0; !rc && i < (json_is_array(mj) ? json_array_size(mj) : 1); i++) {
            json_t *b = json_is_array(mj) ? json_array_get(mj, i) : mj;
            uint64_t counts[SD_MAX_LEVEL + 1];
            int levels;
            api_model *rebuilt = NULL;
            if (api_edit(m, b, ++version, &lim, NULL, counts, &levels, &rebuilt, &p))
                rc = report(&p, moves);
            else if (rebuilt && api_embed_carry(m, rebuilt, &lim, &p)) {
                api_model_unref(rebuilt);
                rc = report(&p, moves);
            } else if (rebuilt) {
                api_model_unref(m);
                m = rebuilt;
            }
        }
        json_decref(mj);
    }
    char *res = NULL;
    const char *ctype;
    if (!rc && api_embed_get(m, "model", format, &res, &len, &ctype, &version, &p))
        rc = report(&p, "writing the model");
    if (!rc) {
        char tmp[4096];
        snprintf(tmp, sizeof tmp, "%s.part", out);
        FILE *f = fopen(tmp, "wb");
        if (!f || fwrite(res, 1, len, f) != len || fclose(f) || rename(tmp, out)) {
            fprintf(stderr, "subdivd deform: cannot write %s: %s\n", out, strerror(errno));
            unlink(tmp);
            rc = 2;
        } else
            fprintf(stderr, "subdivd deform: -> %s (%zu bytes)\n", out, len);
    }
    api_free(res);
    api_model_unref(m);
    return rc;
}

/* ---- daemon ------------------------------------------------------------------------------- */

int main(int argc, char **argv)
{
    if (argc > 1 && !strcmp(argv[1], "deform"))
        return deform_main(argc, argv);
    if (argc > 1 && !strcmp(argv[1], "refine"))
        return refine_main(argc, argv);
    if (argc > 1 && !strcmp(argv[1], "--healthcheck")) /* Docker HEALTHCHECK: no curl needed */
        return probe_main(argc > 2 ? argv[2] : NULL);
    if (argc > 1 && !strcmp(argv[1], "--version")) {
        printf("subdivd %s\n", SD_VERSION);
        return 0;
    }
    if (argc > 1 && !strcmp(argv[1], "--list-routes")) {
        route_list(stdout);
        return 0;
    }
    if (argc > 1 && !strcmp(argv[1], "--list-formats")) { /* the table of api/formats.c */
        for (const out_format *f = out_formats; f->name; f++)
            printf("%s %s %s %s\n", f->name, f->mime, f->extension, f->disposition);
        return 0;
    }
    static server srv;
    int code;
    if (config_load(&srv.cfg, argc, argv, 1, &code))
        return code;
    /* Big blocks (bodies, parsed arrays, levels, output buffers) are mmapped and go back to the
     * system when freed: a fixed threshold turns off glibc's dynamic one, which rises to 32 MiB
     * after the first big free and then keeps such blocks in the heap for good. */
    mallopt(M_MMAP_THRESHOLD, 256 * 1024);
    api_mem_set_budget((size_t)srv.cfg.max_memory);
    api_mem_keep_set((size_t)srv.cfg.keep_memory);
    char perr[512];
    srv.persist = persist_open(srv.cfg.store, srv.cfg.sync_full, perr, sizeof perr);
    if (!srv.persist) {
        fprintf(stderr, "subdivd: %s\n", perr);
        return 1;
    }
    srv.st = store_new(srv.cfg.max_sessions, srv.persist, &srv.cfg.limits);
    srv.session_rate = rate_new(srv.cfg.session_rate, srv.cfg.session_rate, API_RATE_CLIENTS);
    srv.compute = slots_new(srv.cfg.threads);
    srv.bodies = holds_new((size_t)srv.cfg.max_client_body_bytes, (size_t)srv.cfg.max_connections + 1);
    if (!srv.st || !srv.session_rate || !srv.compute || !srv.bodies) {
        fprintf(stderr, "subdivd: out of memory\n");
        return 1;
    }
    atomic_store(&srv.draining, 1);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    metrics_init();
    if (http_start(&srv))
        return 1;
    atomic_store(&srv.draining, 0);
    printf("subdivd listening on http://%s:%d/ (%d compute threads%s)\n", srv.cfg.listen, srv.port,
           srv.cfg.threads, srv.cfg.no_auth ? ", no auth" : "");
    fflush(stdout);
    log_line(&srv, LOG_INFO, "listening on %s:%d, limits: body %zu B, %u vertices, %llu cells/level, "
             "%llu B/session, %d sessions, memory budget %llu B", srv.cfg.listen, srv.port,
             srv.cfg.limits.max_body_bytes, srv.cfg.limits.max_vertices,
             (unsigned long long)srv.cfg.limits.max_cells,
             (unsigned long long)srv.cfg.limits.max_session_bytes, srv.cfg.max_sessions,
             (unsigned long long)srv.cfg.max_memory);
    if (persist_durable(srv.persist)) {
        long n = persist_count(srv.persist, (int64_t)time(NULL));
        if (n >= 0)
            log_line(&srv, LOG_INFO, "session store %s: %ld session(s) stored, loaded on first use",
                     persist_name(srv.persist), n);
        else { /* redis not up yet: /readyz says store-unavailable until a probe write works */
            char why[320];
            persist_last_failure(srv.persist, why, sizeof why);
            log_line(&srv, LOG_WARN, "session store %s cannot be read (%s): not ready until it "
                     "can be written; sessions are loaded on first use", persist_name(srv.persist),
                     why);
        }
    }
    double swept = mono_now();
    while (!stop_requested) {
        usleep(200 * 1000);
        api_mem_keep_trim(); /* kept blocks idle for a second go back to the system */
        if (persist_durable(srv.persist) && mono_now() - swept > 60) {
            swept = mono_now();
            long n = persist_expire(srv.persist, (int64_t)time(NULL));
            if (n > 0)
                log_line(&srv, LOG_INFO, "the store forgot %ld expired session(s)", n);
        }
        int gone = store_expire(srv.st, mono_now());
        if (gone) {
            log_line(&srv, LOG_INFO, "expired %d idle session(s)", gone);
            malloc_trim(0); /* what their models held goes back to the system */
        }
    }
    /* drain: no new connection; what is in flight finishes (--drain-timeout, or a second
     * signal), then every connection closes */
    log_line(&srv, LOG_INFO, "shutting down: %d request(s) in flight", http_in_flight(&srv));
    http_quiesce(&srv);
    double drain_end = mono_now() + srv.cfg.drain_timeout_s;
    while (http_in_flight(&srv) > 0 && mono_now() < drain_end && stop_requested < 2)
        usleep(20 * 1000);
    int cut = http_in_flight(&srv);
    if (cut > 0)
        log_line(&srv, LOG_WARN, "%d request(s) still in flight are cut short (%s)", cut,
                 stop_requested > 1 ? "a second signal" : "--drain-timeout");
    http_stop(&srv);
    store_free(srv.st);
    persist_close(srv.persist);
    rate_free(srv.session_rate);
    holds_free(srv.bodies);
    slots_free(srv.compute);
    log_line(&srv, LOG_INFO, "stopped");
    return 0;
}
