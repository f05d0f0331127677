/* http.c — libmicrohttpd glue: routing, bodies, auth, CORS, versions, streaming, logging.
 *
 * Threading: MHD runs one thread per connection (MHD_USE_THREAD_PER_CONNECTION), so a handler
 * may block — on a session's write lock or a model's compute lock — without stalling other
 * connections. Computations additionally take one of `threads` compute slots (a semaphore), with
 * a bounded wait and a 429 + Retry-After when the daemon is saturated, so /healthz, /readyz and
 * /metrics never queue behind work.
 *
 * A request goes: first callback (no body yet) -> route lookup, 404/405/OPTIONS, Content-Length
 * check (413 before reading anything), session and token check (404/401); body callbacks ->
 * append to a buffer capped at max_body_bytes; final callback -> the route's handler, which
 * calls api/ and queues one response. Level responses stream through out_read() from a callback
 * response that holds references on the session's model until the last byte is sent.
 */
#include "server.h"
#include "../api/handlers.h"
#include "../api/jsonin.h"
#include "metrics.h"
#include <arpa/inet.h>
#include <errno.h>
#include <microhttpd.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

typedef struct req req;
typedef void (*handler_fn)(req *r);

typedef struct route {
    const char *method;
    const char *pattern;   /* segments; "{id}" and "{L}" match one segment */
    handler_fn fn;
    int session;           /* needs a session ({id}) and its token */
    int body;              /* takes a JSON body */
} route;

struct req {
    server *srv;
    struct MHD_Connection *conn;
    const char *method;
    char path[256];
    const route *rt;
    const char *route_name;   /* pattern for metrics and logs */
    char *body;
    size_t len, cap;
    int too_big;
    double t0;
    session *s;
    char seg_id[40];
    char seg_level[24];
    int status;
    atomic_uint_fast64_t bytes;
    int queued;
    atomic_int refs;          /* the connection and a streaming response */
};

/* ---- logging -------------------------------------------------------------------------------- */

void log_line(const server *srv, int level, const char *fmt, ...)
{
    if (level > srv->cfg.log_level)
        return;
    static const char *const names[] = {"error", "warn", "info", "debug"};
    char ts[32];
    struct timespec now;
    clock_gettime(CLOCK_REALTIME, &now);
    struct tm tm;
    gmtime_r(&now.tv_sec, &tm);
    strftime(ts, sizeof ts, "%Y-%m-%dT%H:%M:%S", &tm);
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    fprintf(stderr, "%s.%03ldZ %s %s\n", ts, now.tv_nsec / 1000000, names[level], msg);
}

/* The method as a static string (MHD's own buffer does not outlive the request; metrics keep
 * the pointer). */
static const char *intern_method(const char *m)
{
    static const char *const known[] = {"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"};
    for (size_t i = 0; i < sizeof known / sizeof *known; i++)
        if (!strcmp(known[i], m))
            return known[i];
    return "OTHER";
}

static void req_unref(req *r)
{
    if (atomic_fetch_sub(&r->refs, 1) != 1)
        return;
    session_unref(r->s);
    free(r->body);
    free(r);
}

/* ---- responses ------------------------------------------------------------------------------ */

static void common_headers(req *r, struct MHD_Response *resp)
{
    const char *origin = r->srv->cfg.cors_origin;
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_ORIGIN, origin);
    if (strcmp(origin, "*"))
        MHD_add_response_header(resp, MHD_HTTP_HEADER_VARY, "Origin");
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_EXPOSE_HEADERS,
                            "ETag, Location, Retry-After, Content-Disposition");
    MHD_add_response_header(resp, "X-Content-Type-Options", "nosniff");
}

static void queue(req *r, int status, struct MHD_Response *resp)
{
    common_headers(r, resp);
    r->status = status;
    r->queued = 1;
    MHD_queue_response(r->conn, (unsigned)status, resp);
    MHD_destroy_response(resp);
}

static struct MHD_Response *buffer_response(const char *ctype, char *text, size_t n)
{
    struct MHD_Response *resp = MHD_create_response_from_buffer(n, text, MHD_RESPMEM_MUST_FREE);
    if (ctype)
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    return resp;
}

static void set_etag(struct MHD_Response *resp, uint64_t version)
{
    char etag[32];
    snprintf(etag, sizeof etag, "\"%llu\"", (unsigned long long)version);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
}

/* Queue a JSON body (steals `body`); version > 0 adds an ETag. */
static void reply_json(req *r, int status, json_t *body, uint64_t version)
{
    char *text = body ? json_dumps(body, JSON_COMPACT) : NULL;
    json_decref(body);
    if (!text) {
        text = strdup("{\"type\":\"/errors/internal\",\"title\":\"Internal Server Error\","
                      "\"status\":500,\"detail\":\"could not render the response\"}");
        status = 500;
    }
    size_t n = strlen(text);
    atomic_store(&r->bytes, n);
    struct MHD_Response *resp = buffer_response(
        status >= 400 ? "application/problem+json" : "application/json", text, n);
    if (version)
        set_etag(resp, version);
    queue(r, status, resp);
}

static void reply_problem(req *r, const api_problem *p)
{
    json_t *j = api_problem_json(p);
    char *text = j ? json_dumps(j, JSON_COMPACT) : NULL;
    json_decref(j);
    if (!text)
        text = strdup("{\"status\":500}");
    size_t n = strlen(text);
    atomic_store(&r->bytes, n);
    struct MHD_Response *resp = buffer_response("application/problem+json", text, n);
    if (p->retry_after) {
        char ra[16];
        snprintf(ra, sizeof ra, "%d", p->retry_after);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_RETRY_AFTER, ra);
    }
    if (p->status == 401)
        MHD_add_response_header(resp, MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"subdivd\"");
    queue(r, p->status ? p->status : 500, resp);
}

/* A JSON answer that carries the session version (member and ETag), or the problem if none. */
static void reply_versioned(req *r, json_t *j, uint64_t version, const api_problem *p)
{
    if (!j) {
        reply_problem(r, p);
        return;
    }
    json_object_set_new(j, "version", json_integer((json_int_t)version));
    reply_json(r, 200, j, version);
}

static void fail(req *r, int status, const char *slug, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static void fail(req *r, int status, const char *slug, const char *fmt, ...)
{
    api_problem p = {0};
    va_list ap;
    va_start(ap, fmt);
    char detail[320];
    vsnprintf(detail, sizeof detail, fmt, ap);
    va_end(ap);
    api_fail(&p, status, slug, "%s", detail);
    reply_problem(r, &p);
}

/* ---- compute slots ---------------------------------------------------------------------- */

static int take_slot(req *r, api_problem *p)
{
    struct timespec until;
    clock_gettime(CLOCK_REALTIME, &until);
    until.tv_sec += r->srv->cfg.queue_timeout_s;
    while (sem_timedwait(&r->srv->compute, &until)) {
        if (errno == EINTR)
            continue;
        p->retry_after = 5;
        api_fail(p, 429, "busy", "all %d compute threads are busy; retry in a few seconds",
                 r->srv->cfg.threads);
        return -1;
    }
    if (r->s) {
        atomic_store(&r->s->busy_since, mono_now());
        atomic_store(&r->s->busy_level, 0);
    }
    return 0;
}

static void give_slot(req *r)
{
    if (r->s)
        atomic_store(&r->s->busy_level, -1);
    sem_post(&r->srv->compute);
}

/* ---- handlers: service ------------------------------------------------------------------- */

static void h_healthz(req *r) { reply_json(r, 200, json_pack("{s:s}", "status", "ok"), 0); }

static void h_readyz(req *r)
{
    if (atomic_load(&r->srv->draining)) {
        api_problem p = {0};
        p.retry_after = 5;
        api_fail(&p, 503, "not-ready", "the daemon is starting or shutting down");
        reply_problem(r, &p);
        return;
    }
    reply_json(r, 200, json_pack("{s:s}", "status", "ready"), 0);
}

typedef struct gauges {
    uint64_t cells, bytes;
} gauges;

static void add_gauges(session *s, void *ud)
{
    gauges *g = ud;
    api_model *m = session_model(s, NULL);
    if (m->c) {
        int n = atomic_load(&m->levels_cached);
        for (int l = 0; l < n; l++) {
            sd_counts c;
            sd_complex_counts(m->c, l, &c);
            g->cells += c.points + c.curves + c.triangles + c.tetrahedra + c.octahedra;
        }
        g->bytes += atomic_load(&m->memory_bytes);
    }
    api_model_unref(m);
}

static void h_metrics(req *r)
{
    char *text = NULL;
    size_t n = 0;
    FILE *f = open_memstream(&text, &n);
    if (!f) {
        fail(r, 500, "internal", "could not render metrics");
        return;
    }
    gauges g = {0};
    store_foreach(r->srv->st, add_gauges, &g);
    metrics_write(f, store_count(r->srv->st), g.cells, g.bytes);
    fclose(f);
    atomic_store(&r->bytes, n);
    queue(r, 200, buffer_response("text/plain; version=0.0.4; charset=utf-8", text, n));
}

static void h_asset(req *r)
{
    const asset *a = asset_find(r->path);
    if (!a) {
        fail(r, 404, "not-found", "no resource at %.100s", r->path);
        return;
    }
    /* The web front end's bundles have content-hashed names and are immutable; index.html and
     * the OpenAPI document are revalidated (no-cache) against the ETag: 304 while unchanged. */
    const char *inm = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                  MHD_HTTP_HEADER_IF_NONE_MATCH);
    int fresh = inm && (strstr(inm, a->etag) || !strcmp(inm, "*"));
    struct MHD_Response *resp =
        fresh ? MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT)
              : MHD_create_response_from_buffer(a->size, (void *)a->data, MHD_RESPMEM_PERSISTENT);
    if (!fresh)
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, a->content_type);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, a->cache_control);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, a->etag);
    atomic_store(&r->bytes, fresh ? 0 : a->size);
    queue(r, fresh ? 304 : 200, resp);
}

/* ---- handlers: sessions ------------------------------------------------------------------ */

static json_t *parse_body(req *r, int empty_ok, api_problem *p)
{
    return api_parse_body(r->body ? r->body : "", r->len, empty_ok, p);
}

static void iso_time(char *buf, size_t cap, time_t t)
{
    struct tm tm;
    gmtime_r(&t, &tm);
    strftime(buf, cap, "%Y-%m-%dT%H:%M:%SZ", &tm);
}

static void h_create_session(req *r)
{
    api_problem p = {0};
    json_t *b = parse_body(r, 1, &p);
    static const char *const keys[] = {"ttl_s", NULL};
    long long ttl = r->srv->cfg.ttl_s;
    json_t *t;
    if (!b || api_only_keys(b, "", keys, &p) ||
        ((t = json_object_get(b, "ttl_s")) && api_get_int(t, "/ttl_s", 1, API_MAX_TTL_S, &ttl, &p))) {
        json_decref(b);
        reply_problem(r, &p);
        return;
    }
    json_decref(b);
    session *s = store_create(r->srv->st, (int)ttl);
    if (!s) {
        p.retry_after = 60;
        api_fail(&p, 429, "too-many-sessions",
                 "the daemon holds its maximum of %d sessions; delete unused sessions or wait for "
                 "idle ones to expire", r->srv->cfg.max_sessions);
        reply_problem(r, &p);
        return;
    }
    char exp[32], loc[64];
    iso_time(exp, sizeof exp, session_expires_at(s));
    snprintf(loc, sizeof loc, "/v1/sessions/%s", s->id);
    json_t *j = json_pack("{s:s, s:s, s:s, s:I}", "id", s->id, "token", s->token, "expires_at",
                          exp, "ttl_s", (json_int_t)ttl);
    session_unref(s);
    char *text = json_dumps(j, JSON_COMPACT);
    json_decref(j);
    size_t n = strlen(text);
    atomic_store(&r->bytes, n);
    struct MHD_Response *resp = buffer_response("application/json", text, n);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_LOCATION, loc);
    queue(r, 201, resp);
}

static void h_get_session(req *r)
{
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    char exp[32];
    iso_time(exp, sizeof exp, session_expires_at(r->s));
    json_t *progress = json_null();
    int busy = atomic_load(&r->s->busy_level);
    if (busy >= 0)
        progress = json_pack("{s:s, s:i, s:f}", "state", "computing", "level", busy, "seconds",
                             mono_now() - atomic_load(&r->s->busy_since));
    json_t *summary = m->summary ? json_incref(m->summary) : json_object();
    json_t *j = json_pack("{s:s, s:I, s:i, s:I, s:o, s:s, s:o}", "id", r->s->id, "version",
                          (json_int_t)version, "levels_cached", atomic_load(&m->levels_cached),
                          "memory_bytes", (json_int_t)atomic_load(&m->memory_bytes), "summary",
                          summary, "expires_at", exp, "progress", progress);
    api_model_unref(m);
    reply_json(r, 200, j, version);
}

static void h_delete_session(req *r)
{
    store_remove(r->srv->st, r->s);
    queue(r, 204, MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT));
}

/* If-Match on a change: absent is fine (except where a route requires it), "*" matches any
 * version, otherwise one of the listed strong tags must equal the current version. */
static int if_match_ok(req *r, uint64_t version)
{
    const char *h = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND, MHD_HTTP_HEADER_IF_MATCH);
    if (!h)
        return 1;
    char want[32];
    snprintf(want, sizeof want, "\"%llu\"", (unsigned long long)version);
    for (const char *s = h; *s;) {
        while (*s == ' ' || *s == ',')
            s++;
        if (*s == '*')
            return 1;
        size_t n = strcspn(s, ",");
        while (n && s[n - 1] == ' ')
            n--;
        if (n == strlen(want) && !strncmp(s, want, n))
            return 1;
        s += strcspn(s, ",");
    }
    return 0;
}

/* A change builds the session's next model from the current one and may add members to the
 * answer (the summary, what was refined). */
typedef int (*change_op)(const api_model *cur, json_t *body, const api_limits *lim,
                         api_model **next, json_t *answer, api_problem *p);

/* PUT complex / tags / rules, POST refine: parse, check If-Match, build the new model in a
 * compute slot, publish. The session's write lock makes concurrent changes of one session
 * sequential. */
static void change(req *r, change_op op)
{
    api_problem p = {0};
    json_t *b = parse_body(r, 0, &p);
    if (!b) {
        reply_problem(r, &p);
        return;
    }
    pthread_mutex_lock(&r->s->write);
    uint64_t version;
    api_model *cur = session_model(r->s, &version), *next = NULL;
    json_t *answer = json_object();
    int rc;
    if (!if_match_ok(r, version))
        rc = api_fail(&p, 412, "stale-version",
                      "If-Match does not match the current version \"%llu\"; GET the session "
                      "again", (unsigned long long)version);
    else if (!(rc = take_slot(r, &p))) {
        rc = op(cur, b, &r->srv->cfg.limits, &next, answer, &p);
        give_slot(r);
    }
    json_decref(b);
    api_model_unref(cur);
    if (rc) {
        pthread_mutex_unlock(&r->s->write);
        json_decref(answer);
        reply_problem(r, &p);
        return;
    }
    version = session_publish(r->s, next);
    pthread_mutex_unlock(&r->s->write);
    json_object_set_new(answer, "version", json_integer((json_int_t)version));
    reply_json(r, 200, answer, version);
}

static int op_complex(const api_model *cur, json_t *body, const api_limits *lim, api_model **next,
                      json_t *answer, api_problem *p)
{
    int rc = api_put_complex(cur, body, lim, next, p);
    if (!rc && (*next)->summary)
        json_object_set(answer, "summary", (*next)->summary);
    return rc;
}

static int op_tags(const api_model *cur, json_t *body, const api_limits *lim, api_model **next,
                   json_t *answer, api_problem *p)
{
    (void)answer;
    return api_put_tags(cur, body, lim, next, p);
}

static int op_rules(const api_model *cur, json_t *body, const api_limits *lim, api_model **next,
                    json_t *answer, api_problem *p)
{
    (void)answer;
    return api_put_rules(cur, body, lim, next, p);
}

static int op_refine(const api_model *cur, json_t *body, const api_limits *lim, api_model **next,
                     json_t *answer, api_problem *p)
{
    uint64_t red, green;
    int rc = api_refine(cur, body, lim, next, &red, &green, p);
    if (!rc) {
        if ((*next)->summary)
            json_object_set(answer, "summary", (*next)->summary);
        json_object_set_new(answer, "refined", json_pack("{s:I, s:I}", "red", (json_int_t)red,
                                                         "green", (json_int_t)green));
    }
    return rc;
}

static void h_put_complex(req *r) { change(r, op_complex); }
static void h_put_tags(req *r) { change(r, op_tags); }
static void h_put_rules(req *r) { change(r, op_rules); }
static void h_refine(req *r) { change(r, op_refine); }

/* PATCH control-points: If-Match is required (428 without, 412 when stale); the model is changed
 * in place under its data lock, so the edit waits for that session's streams in flight. */
static void h_edit(req *r)
{
    api_problem p = {0};
    if (!MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND, MHD_HTTP_HEADER_IF_MATCH)) {
        api_fail(&p, 428, "precondition-required",
                 "send If-Match: \"<version>\" (the session's ETag) with an edit");
        reply_problem(r, &p);
        return;
    }
    json_t *b = parse_body(r, 0, &p);
    if (!b) {
        reply_problem(r, &p);
        return;
    }
    pthread_mutex_lock(&r->s->write);
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    uint64_t counts[SD_MAX_LEVEL + 1];
    int levels = 0, rc;
    if (!if_match_ok(r, version))
        rc = api_fail(&p, 412, "stale-version",
                      "If-Match does not match the current version \"%llu\"; GET the session "
                      "again", (unsigned long long)version);
    else
        rc = api_edit(m, b, counts, &levels, &p);
    if (!rc)
        version = session_bump(r->s);
    pthread_mutex_unlock(&r->s->write);
    json_decref(b);
    api_model_unref(m);
    if (rc) {
        reply_problem(r, &p);
        return;
    }
    json_t *up = json_object();
    for (int l = 0; l < levels; l++) {
        char key[8];
        snprintf(key, sizeof key, "%d", l);
        json_object_set_new(up, key, json_integer((json_int_t)counts[l]));
    }
    reply_json(r, 200, json_pack("{s:I, s:o}", "version", (json_int_t)version, "updated_points", up),
               version);
}

static void h_get_complex(req *r)
{
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    api_problem p = {0};
    json_t *j = api_get_complex(m, &p);
    api_model_unref(m);
    reply_versioned(r, j, version, &p);
}

/* ---- handlers: levels ------------------------------------------------------------------- */

typedef struct stream_ctx {
    req *r;
    api_model *m;
    out_stream *os;
    int level_data;   /* a level stream: holds the model's data lock (api_level_close) */
} stream_ctx;

static ssize_t stream_read(void *cls, uint64_t pos, char *buf, size_t max)
{
    (void)pos;
    stream_ctx *sc = cls;
    ssize_t n = out_read(sc->os, buf, max);
    if (n > 0) {
        atomic_fetch_add(&sc->r->bytes, (uint64_t)n);
        metrics_bytes((uint64_t)n);
        return n;
    }
    return n == 0 ? MHD_CONTENT_READER_END_OF_STREAM : MHD_CONTENT_READER_END_WITH_ERROR;
}

static void stream_free(void *cls)
{
    stream_ctx *sc = cls;
    if (sc->level_data)
        api_level_close(sc->m, sc->os);
    else
        out_close(sc->os);
    api_model_unref(sc->m);
    req_unref(sc->r);
    free(sc);
}

static int query_only(req *r, const char *const *allowed);

static int if_none_match_hit(req *r, uint64_t version)
{
    const char *h =
        MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND, MHD_HTTP_HEADER_IF_NONE_MATCH);
    char want[32];
    snprintf(want, sizeof want, "\"%llu\"", (unsigned long long)version);
    return h && (strstr(h, want) || !strcmp(h, "*"));
}

/* The query check and level of a /levels/{L} request; -1 when a problem was answered. */
static int level_of(req *r, const char *const *keys)
{
    if (query_only(r, keys))
        return -1;
    api_problem p = {0};
    int level = api_parse_level(r->seg_level, &p);
    if (level < 0)
        reply_problem(r, &p);
    return level;
}

/* Take a compute slot when level L of m still has to be computed (*slot says whether one was
 * taken; give it back with give_slot). Non-zero with a problem when none came free in time. */
static int slot_for_level(req *r, api_model *m, int level, int *slot, api_problem *p)
{
    *slot = 0;
    if (!m->c || atomic_load(&m->levels_cached) > level)
        return 0;
    if (take_slot(r, p))
        return -1;
    *slot = 1;
    atomic_store(&r->s->busy_level, level);
    return 0;
}

static void h_get_level(req *r)
{
    static const char *const keys[] = {"format", "parts", "slice", "attributes", "colormap",
                                       "octahedra", NULL};
    int level = level_of(r, keys);
    if (level < 0)
        return;
    api_problem p = {0};
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    if (m->c && if_none_match_hit(r, version)) {
        api_model_unref(m);
        struct MHD_Response *resp = MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
        set_etag(resp, version);
        queue(r, 304, resp);
        return;
    }
#define Q(k) MHD_lookup_connection_value(r->conn, MHD_GET_ARGUMENT_KIND, k)
    api_level_query q = {Q("format"), Q("parts"), Q("slice"), Q("attributes"), Q("colormap"),
                         Q("octahedra")};
#undef Q
    out_stream *os = NULL;
    const out_format *fmt;
    int slot, rc = slot_for_level(r, m, level, &slot, &p);
    if (!rc)
        rc = api_level_open(m, level, &q, &r->srv->cfg.limits, version, &os, &fmt, &p);
    if (slot)
        give_slot(r);
    if (rc) {
        api_model_unref(m);
        reply_problem(r, &p);
        return;
    }
    stream_ctx *sc = malloc(sizeof *sc);
    if (!sc) {
        api_level_close(m, os);
        api_model_unref(m);
        fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    sc->r = r;
    sc->m = m;
    sc->os = os;
    sc->level_data = 1;
    atomic_fetch_add(&r->refs, 1);
    uint64_t size = out_size(os);
    struct MHD_Response *resp = MHD_create_response_from_callback(
        size == UINT64_MAX ? MHD_SIZE_UNKNOWN : size, 256 * 1024, stream_read, sc, stream_free);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, fmt->mime);
    char disp[96];
    snprintf(disp, sizeof disp, "%s; filename=\"level-%d%s\"", fmt->disposition, level,
             fmt->extension);
    MHD_add_response_header(resp, "Content-Disposition", disp);
    set_etag(resp, version);
    queue(r, 200, resp);
}

static void h_level_stats(req *r)
{
    static const char *const keys[] = {NULL};
    int level = level_of(r, keys);
    if (level < 0)
        return;
    api_problem p = {0};
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    int slot, rc = slot_for_level(r, m, level, &slot, &p);
    json_t *j = rc ? NULL : api_level_stats(m, level, &r->srv->cfg.limits, &p);
    if (slot)
        give_slot(r);
    api_model_unref(m);
    reply_versioned(r, j, version, &p);
}

static void h_matrix(req *r)
{
    static const char *const keys[] = {"from", "format", NULL};
    int level = level_of(r, keys);
    if (level < 0)
        return;
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    api_problem p = {0};
    out_stream *os = NULL;
    const char *ctype = NULL;
    const char *from = MHD_lookup_connection_value(r->conn, MHD_GET_ARGUMENT_KIND, "from");
    const char *fmt = MHD_lookup_connection_value(r->conn, MHD_GET_ARGUMENT_KIND, "format");
    int slot, rc = slot_for_level(r, m, level, &slot, &p);
    if (!rc)
        rc = api_matrix_open(m, level, from, fmt, &r->srv->cfg.limits, &os, &ctype, &p);
    if (slot)
        give_slot(r);
    stream_ctx *sc = rc ? NULL : malloc(sizeof *sc);
    if (!sc) {
        out_close(os);
        api_model_unref(m);
        if (!rc)
            api_fail(&p, 503, "out-of-memory", "out of memory");
        reply_problem(r, &p);
        return;
    }
    *sc = (stream_ctx){r, m, os, 0};
    atomic_fetch_add(&r->refs, 1);
    struct MHD_Response *resp =
        MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 256 * 1024, stream_read, sc, stream_free);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    char disp[96];
    snprintf(disp, sizeof disp, "attachment; filename=\"S_%s_%d.%s\"", from ? from : "0", level,
             fmt && !strcmp(fmt, "json") ? "json" : "mtx");
    MHD_add_response_header(resp, "Content-Disposition", disp);
    set_etag(resp, version);
    queue(r, 200, resp);
}

static void h_analysis(req *r)
{
    static const char *const keys[] = {"vertex", "edge", NULL};
    if (query_only(r, keys))
        return;
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    api_problem p = {0};
    int slot, rc = slot_for_level(r, m, 1, &slot, &p); /* an edge's block lives at level 1 */
    json_t *j = rc ? NULL
                   : api_analysis(m,
                                  MHD_lookup_connection_value(r->conn, MHD_GET_ARGUMENT_KIND, "vertex"),
                                  MHD_lookup_connection_value(r->conn, MHD_GET_ARGUMENT_KIND, "edge"), &p);
    if (slot)
        give_slot(r);
    api_model_unref(m);
    reply_versioned(r, j, version, &p);
}

/* ---- routing ---------------------------------------------------------------------------- */

static const route ROUTES[] = {
    {"POST", "/v1/sessions", h_create_session, 0, 1},
    {"GET", "/v1/sessions/{id}", h_get_session, 1, 0},
    {"DELETE", "/v1/sessions/{id}", h_delete_session, 1, 0},
    {"PUT", "/v1/sessions/{id}/complex", h_put_complex, 1, 1},
    {"GET", "/v1/sessions/{id}/complex", h_get_complex, 1, 0},
    {"PATCH", "/v1/sessions/{id}/control-points", h_edit, 1, 1},
    {"POST", "/v1/sessions/{id}/refine", h_refine, 1, 1},
    {"PUT", "/v1/sessions/{id}/tags", h_put_tags, 1, 1},
    {"PUT", "/v1/sessions/{id}/rules", h_put_rules, 1, 1},
    {"GET", "/v1/sessions/{id}/levels/{L}", h_get_level, 1, 0},
    {"GET", "/v1/sessions/{id}/levels/{L}/stats", h_level_stats, 1, 0},
    {"GET", "/v1/sessions/{id}/analysis", h_analysis, 1, 0},
    {"GET", "/v1/sessions/{id}/matrices/{L}", h_matrix, 1, 0},
    {"GET", "/healthz", h_healthz, 0, 0},
    {"GET", "/livez", h_healthz, 0, 0},
    {"GET", "/readyz", h_readyz, 0, 0},
    {"GET", "/metrics", h_metrics, 0, 0},
    {"GET", "/v1/openapi.json", h_asset, 0, 0},
};
#define NROUTES (sizeof ROUTES / sizeof *ROUTES)

void http_list_routes(FILE *f)
{
    for (size_t i = 0; i < NROUTES; i++)
        fprintf(f, "%s %s\n", ROUTES[i].method, ROUTES[i].pattern);
}

/* Match `path` against a pattern; captures {id} and {L}. */
static int match(const char *pattern, const char *path, req *r)
{
    const char *p = pattern, *s = path;
    while (*p && *s) {
        if (*p == '{') {
            const char *pe = strchr(p, '}');
            size_t n = strcspn(s, "/");
            if (n == 0)
                return 0;
            char *dst = p[1] == 'i' ? r->seg_id : r->seg_level;
            size_t cap = p[1] == 'i' ? sizeof r->seg_id : sizeof r->seg_level;
            if (n >= cap)
                return 0;
            memcpy(dst, s, n);
            dst[n] = 0;
            p = pe + 1;
            s += n;
            continue;
        }
        if (*p != *s)
            return 0;
        p++;
        s++;
    }
    return !*p && !*s;
}

static int query_only(req *r, const char *const *allowed);

typedef struct qcheck {
    const char *const *allowed;
    const char *bad;
} qcheck;

static enum MHD_Result q_iter(void *cls, enum MHD_ValueKind kind, const char *key, const char *value)
{
    (void)kind;
    (void)value;
    qcheck *q = cls;
    for (const char *const *a = q->allowed; *a; a++)
        if (!strcmp(*a, key))
            return MHD_YES;
    q->bad = key;
    return MHD_NO;
}

static int query_only(req *r, const char *const *allowed)
{
    qcheck q = {allowed, NULL};
    MHD_get_connection_values(r->conn, MHD_GET_ARGUMENT_KIND, q_iter, &q);
    if (!q.bad)
        return 0;
    char list[160] = "";
    for (const char *const *a = allowed; *a; a++)
        snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", a == allowed ? "" : ", ", *a);
    api_problem p = {0};
    api_fail_at(&p, 400, "unknown-parameter", q.bad, "unknown query parameter \"%.40s\" (allowed: %s)",
                q.bad, *allowed ? list : "none");
    reply_problem(r, &p);
    return 1;
}

static int methods_for(const char *path, req *r, char *allow, size_t cap)
{
    int n = 0;
    allow[0] = 0;
    for (size_t i = 0; i < NROUTES; i++)
        if (match(ROUTES[i].pattern, path, r)) {
            snprintf(allow + strlen(allow), cap - strlen(allow), "%s%s", n ? ", " : "",
                     ROUTES[i].method);
            n++;
            if (!strcmp(ROUTES[i].method, "GET")) {
                snprintf(allow + strlen(allow), cap - strlen(allow), ", HEAD");
            }
        }
    return n;
}

static int is_static_path(const char *path)
{
    return !strncmp(path, "/v1/", 4) ? 0 : asset_find(path) != NULL;
}

/* Route lookup and every check that needs no body. Returns 1 when a response was queued. */
static int early(req *r)
{
    const char *m = r->method;
    char allow[128];
    int known = methods_for(r->path, r, allow, sizeof allow);
    if (!known && is_static_path(r->path)) {
        static const route asset_route = {"GET", "static", h_asset, 0, 0};
        if (strcmp(m, "GET") && strcmp(m, "HEAD") && strcmp(m, "OPTIONS")) {
            api_problem p = {0};
            api_fail(&p, 405, "method-not-allowed", "%s is not allowed on %.100s", m, r->path);
            json_t *j = api_problem_json(&p);
            char *text = json_dumps(j, JSON_COMPACT);
            json_decref(j);
            struct MHD_Response *resp = buffer_response("application/problem+json", text, strlen(text));
            MHD_add_response_header(resp, MHD_HTTP_HEADER_ALLOW, "GET, HEAD");
            r->route_name = "static";
            queue(r, 405, resp);
            return 1;
        }
        r->rt = &asset_route;
        r->route_name = "static";
        strcpy(allow, "GET, HEAD");
        known = 1;
    }
    if (!known) {
        r->route_name = "unknown";
        fail(r, 404, "not-found", "no resource at %.100s", r->path);
        return 1;
    }
    if (!strcmp(m, "OPTIONS")) {
        r->route_name = "preflight";
        struct MHD_Response *resp = MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
        char methods[160];
        snprintf(methods, sizeof methods, "%s, OPTIONS", allow);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ALLOW, methods);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_METHODS, methods);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_HEADERS,
                                "Authorization, Content-Type, If-Match, If-None-Match");
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_MAX_AGE, "600");
        queue(r, 204, resp);
        return 1;
    }
    if (!r->rt) {
        const char *want = !strcmp(m, "HEAD") ? "GET" : m;
        for (size_t i = 0; i < NROUTES && !r->rt; i++)
            if (!strcmp(ROUTES[i].method, want) && match(ROUTES[i].pattern, r->path, r))
                r->rt = &ROUTES[i];
    }
    if (!r->rt) {
        r->route_name = "unknown";
        for (size_t i = 0; i < NROUTES; i++)
            if (match(ROUTES[i].pattern, r->path, r))
                r->route_name = ROUTES[i].pattern;
        api_problem p = {0};
        api_fail(&p, 405, "method-not-allowed", "%s is not allowed on %.100s (allowed: %s)", m,
                 r->path, allow);
        json_t *j = api_problem_json(&p);
        char *text = json_dumps(j, JSON_COMPACT);
        json_decref(j);
        struct MHD_Response *resp = buffer_response("application/problem+json", text, strlen(text));
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ALLOW, allow);
        atomic_store(&r->bytes, strlen(text));
        queue(r, 405, resp);
        return 1;
    }
    if (r->rt->pattern[0] == '/')
        r->route_name = r->rt->pattern;
    match(r->rt->pattern, r->path, r); /* re-capture the segments of the chosen route */
    /* who is asking comes first: a client without the session's token learns nothing else */
    if (r->rt->session) {
        r->s = store_get(r->srv->st, r->seg_id);
        if (!r->s) {
            fail(r, 404, "no-session", "no session %.40s (it may have expired or been deleted)",
                 r->seg_id);
            return 1;
        }
        if (!r->srv->cfg.no_auth) {
            const char *h = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                        MHD_HTTP_HEADER_AUTHORIZATION);
            /* credentials = auth-scheme 1*SP token68 (RFC 9110 11.4): the scheme is
             * case-insensitive, and trailing whitespace is not part of the field value */
            const char *tok = NULL;
            char tbuf[128];
            if (h && !strncasecmp(h, "Bearer ", 7)) {
                const char *t = h + 7;
                while (*t == ' ')
                    t++;
                size_t n = strlen(t);
                while (n && (t[n - 1] == ' ' || t[n - 1] == '\t'))
                    n--;
                if (n < sizeof tbuf) {
                    memcpy(tbuf, t, n);
                    tbuf[n] = 0;
                    tok = tbuf;
                }
            }
            if (!session_token_ok(r->s, tok)) {
                api_problem p = {0};
                api_fail(&p, 401, "unauthorized",
                         h ? "the bearer token does not match this session"
                           : "send the session's token as \"Authorization: Bearer <token>\"");
                reply_problem(r, &p);
                return 1;
            }
        }
    }
    /* MHD frames a body only by Content-Length or chunked; any other transfer coding would have
     * it read until the client closes (RFC 9112 6.1: 501 for a coding we do not understand) */
    const char *te0 = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                  MHD_HTTP_HEADER_TRANSFER_ENCODING);
    if (te0 && strcasecmp(te0, "chunked")) {
        fail(r, 501, "unsupported-transfer-encoding",
             "Transfer-Encoding \"%.40s\" is not supported; send the body with Content-Length or "
             "chunked", te0);
        return 1;
    }
    const char *cl = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                 MHD_HTTP_HEADER_CONTENT_LENGTH);
    if (cl) {
        char *end;
        errno = 0;
        unsigned long long n = strtoull(cl, &end, 10);
        if (*end || errno || n > r->srv->cfg.limits.max_body_bytes) {
            api_problem p = {0};
            api_fail_limit(&p, "max_body_bytes", r->srv->cfg.limits.max_body_bytes,
                           errno || *end ? UINT64_MAX : n,
                           "the body of %s bytes exceeds the limit of %zu bytes; send a smaller "
                           "complex or raise --max-body-bytes", cl,
                           r->srv->cfg.limits.max_body_bytes);
            reply_problem(r, &p);
            return 1;
        }
        if (n > 0 && !r->rt->body) {
            fail(r, 400, "unexpected-body", "%s %s takes no request body", m, r->rt->pattern);
            return 1;
        }
    }
    if (r->rt->body && (cl ? strcmp(cl, "0") : 1)) {
        const char *ct = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                     MHD_HTTP_HEADER_CONTENT_TYPE);
        int json = ct && !strncasecmp(ct, "application/json", 16) &&
                   (ct[16] == 0 || ct[16] == ';' || ct[16] == ' ');
        const char *te = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                     MHD_HTTP_HEADER_TRANSFER_ENCODING);
        if (!json && (cl || te)) {
            fail(r, 415, "unsupported-media-type",
                 "send the body as application/json (got %.60s)", ct ? ct : "no Content-Type");
            return 1;
        }
    }
    return 0;
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *conn, const char *url,
                                  const char *method, const char *version,
                                  const char *upload_data, size_t *upload_size, void **con_cls)
{
    (void)version;
    server *srv = cls;
    req *r = *con_cls;
    if (!r) {
        r = calloc(1, sizeof *r);
        if (!r)
            return MHD_NO;
        atomic_init(&r->refs, 1);
        r->srv = srv;
        r->conn = conn;
        r->method = intern_method(method);
        r->t0 = mono_now();
        r->route_name = "unknown";
        snprintf(r->path, sizeof r->path, "%s", url);
        *con_cls = r;
        if (strlen(url) >= sizeof r->path) {
            fail(r, 404, "not-found", "the path is too long");
            return MHD_YES;
        }
        early(r);
        return MHD_YES;
    }
    if (r->queued) { /* answered early: swallow any body */
        *upload_size = 0;
        return MHD_YES;
    }
    if (*upload_size) {
        size_t n = *upload_size;
        *upload_size = 0;
        if (r->too_big || r->len + n > srv->cfg.limits.max_body_bytes) {
            r->too_big = 1;
            return MHD_YES;
        }
        if (r->len + n + 1 > r->cap) {
            size_t cap = r->cap ? r->cap : 4096;
            while (cap < r->len + n + 1)
                cap *= 2;
            char *b = realloc(r->body, cap);
            if (!b) {
                r->too_big = 1;
                return MHD_YES;
            }
            r->body = b;
            r->cap = cap;
        }
        memcpy(r->body + r->len, upload_data, n);
        r->len += n;
        r->body[r->len] = 0;
        return MHD_YES;
    }
    if (r->too_big) {
        api_problem p = {0};
        api_fail_limit(&p, "max_body_bytes", srv->cfg.limits.max_body_bytes,
                       srv->cfg.limits.max_body_bytes + 1,
                       "the body exceeds the limit of %zu bytes; send a smaller complex or raise "
                       "--max-body-bytes", srv->cfg.limits.max_body_bytes);
        reply_problem(r, &p);
        return MHD_YES;
    }
    if (r->len && !r->rt->body) {
        fail(r, 400, "unexpected-body", "%s %s takes no request body", method, r->rt->pattern);
        return MHD_YES;
    }
    r->rt->fn(r);
    if (!r->queued)
        fail(r, 500, "internal", "the handler produced no response");
    return MHD_YES;
}

static void on_completed(void *cls, struct MHD_Connection *conn, void **con_cls,
                         enum MHD_RequestTerminationCode code)
{
    (void)conn;
    server *srv = cls;
    req *r = *con_cls;
    if (!r)
        return;
    double ms = (mono_now() - r->t0) * 1e3;
    if (r->queued) {
        metrics_request(r->route_name, r->method, r->status, ms / 1e3);
        log_line(srv, LOG_INFO, "%s %s %d %lluB %.2fms%s", r->method, r->path, r->status,
                 (unsigned long long)atomic_load(&r->bytes), ms,
                 code == MHD_REQUEST_TERMINATED_COMPLETED_OK ? "" : " (cut short)");
    }
    *con_cls = NULL;
    req_unref(r);
}

static void mhd_log(void *cls, const char *fmt, va_list ap)
{
    server *srv = cls;
    char msg[512];
    vsnprintf(msg, sizeof msg, fmt, ap);
    size_t n = strlen(msg);
    while (n && msg[n - 1] == '\n')
        msg[--n] = 0;
    log_line(srv, LOG_WARN, "http: %s", msg);
}

int http_start(server *srv)
{
    struct sockaddr_storage ss;
    memset(&ss, 0, sizeof ss);
    unsigned flags = MHD_USE_AUTO_INTERNAL_THREAD | MHD_USE_THREAD_PER_CONNECTION | MHD_USE_ERROR_LOG;
    if (strchr(srv->cfg.listen, ':')) {
        struct sockaddr_in6 *a = (struct sockaddr_in6 *)&ss;
        a->sin6_family = AF_INET6;
        a->sin6_port = htons((uint16_t)srv->cfg.port);
        if (inet_pton(AF_INET6, srv->cfg.listen, &a->sin6_addr) != 1)
            goto bad_addr;
        flags |= MHD_USE_IPv6;
    } else {
        struct sockaddr_in *a = (struct sockaddr_in *)&ss;
        a->sin_family = AF_INET;
        a->sin_port = htons((uint16_t)srv->cfg.port);
        if (inet_pton(AF_INET, srv->cfg.listen, &a->sin_addr) != 1)
            goto bad_addr;
    }
    srv->mhd = MHD_start_daemon(
        flags, (uint16_t)srv->cfg.port, NULL, NULL, on_request, srv, MHD_OPTION_EXTERNAL_LOGGER,
        mhd_log, srv, MHD_OPTION_SOCK_ADDR, &ss,
        MHD_OPTION_NOTIFY_COMPLETED, on_completed, srv, MHD_OPTION_CONNECTION_LIMIT,
        (unsigned)srv->cfg.max_connections, MHD_OPTION_CONNECTION_TIMEOUT,
        (unsigned)srv->cfg.connection_timeout_s, MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)64 * 1024, MHD_OPTION_END);
    if (!srv->mhd) {
        log_line(srv, LOG_ERROR, "cannot listen on %s port %d: %s", srv->cfg.listen, srv->cfg.port,
                 strerror(errno));
        return -1;
    }
    const union MHD_DaemonInfo *info = MHD_get_daemon_info(srv->mhd, MHD_DAEMON_INFO_BIND_PORT);
    srv->port = info ? info->port : srv->cfg.port;
    return 0;
bad_addr:
    log_line(srv, LOG_ERROR, "--listen %s is not an IP address", srv->cfg.listen);
    return -1;
}

void http_stop(server *srv)
{
    if (srv->mhd) {
        MHD_stop_daemon(srv->mhd);
        srv->mhd = NULL;
    }
}
