/* reply.c — the daemon's answers: the headers every answer carries, JSON and problem+json bodies
 * (with the memory budget's Retry-After), entity tags, and streamed responses read from a source
 * (a level writer, GET /complex) while the response holds references on the session's model and
 * no lock (http.c queues them; routes.c builds them).
 *
 * Event streams (http_reply_events) read a listener of the session's hub (server/events.h):
 * libmicrohttpd calls the reader in the connection's own thread (thread-per-connection,
 * docs/DECISIONS.md 33) when the socket takes more, and it blocks there on the hub's condition
 * variable until an event, a heartbeat or the end. A client that does not read never has its
 * reader called: the hub's bounded buffer fills and the listener is dropped, the socket's own
 * buffer kept small (EV_SOCKET_BYTES) so that this happens after some 100 KiB of events rather
 * than after megabytes of kernel buffers (docs/DECISIONS.md 37).
 */
#include "request.h"
#include "../api/mem.h"
#include "../api/handlers.h"
#include "events.h"
#include "metrics.h"
#include <microhttpd.h>
#include <sys/socket.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- responses ------------------------------------------------------------------------------ */

/* The headers every answer carries (CORS, nosniff): their number, at most 4. */
int http_common_header_list(const req *r, http_header_pair out[4])
{
    const char *origin = r->srv->cfg.cors_origin;
    int n = 0;
    out[n++] = (http_header_pair){MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_ORIGIN, origin};
    if (strcmp(origin, "*"))
        out[n++] = (http_header_pair){MHD_HTTP_HEADER_VARY, "Origin"};
    out[n++] = (http_header_pair){MHD_HTTP_HEADER_ACCESS_CONTROL_EXPOSE_HEADERS,
                        "ETag, Location, Retry-After, Content-Disposition, "
                        "X-Attribute-Components, X-Updated-Points"};
    out[n++] = (http_header_pair){"X-Content-Type-Options", "nosniff"};
    return n;
}

static void common_headers(req *r, struct MHD_Response *resp)
{
    http_header_pair h[4];
    int n = http_common_header_list(r, h);
    for (int i = 0; i < n; i++)
        MHD_add_response_header(resp, h[i].name, h[i].value);
}

void http_queue(req *r, int status, struct MHD_Response *resp)
{
    common_headers(r, resp);
    /* libmicrohttpd closes the connection after an answer saying so; a stopping daemon closes
     * every connection it answers on, so no client sends it another request */
    if (r->close_after || atomic_load(&r->srv->draining))
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONNECTION, "close");
    r->status = status;
    r->queued = 1;
    MHD_queue_response(r->conn, (unsigned)status, resp);
    MHD_destroy_response(resp);
}

struct MHD_Response *http_empty(void)
{
    return MHD_create_response_from_buffer(0, NULL, MHD_RESPMEM_PERSISTENT);
}

struct MHD_Response *http_static_response(const void *data, size_t n)
{
    return MHD_create_response_from_buffer(n, (void *)data, MHD_RESPMEM_PERSISTENT);
}

void http_add_header(struct MHD_Response *resp, const char *name, const char *value)
{
    MHD_add_response_header(resp, name, value);
}

struct MHD_Response *http_buffer_response(const char *ctype, char *text, size_t n)
{
    struct MHD_Response *resp = MHD_create_response_from_buffer_with_free_callback(n, text, api_free);
    if (!resp) {
        api_free(text);
        return NULL;
    }
    if (ctype)
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    return resp;
}

void http_set_etag(struct MHD_Response *resp, uint64_t version)
{
    char etag[32];
    snprintf(etag, sizeof etag, "\"%llu\"", (unsigned long long)version);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
}

/* A response owning `text` (an api_malloc block, counted in r->bytes) of type ctype; without
 * text, for lack of memory to render it, the static problem `fallback` instead. */
static struct MHD_Response *text_response(req *r, const char *ctype, char *text,
                                          const char *fallback)
{
    if (!text) { /* nothing left to allocate a body from */
        struct MHD_Response *resp = http_static_response(fallback, strlen(fallback));
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, "application/problem+json");
        atomic_store(&r->bytes, strlen(fallback));
        return resp;
    }
    size_t n = strlen(text);
    atomic_store(&r->bytes, n);
    return http_buffer_response(ctype, text, n);
}

static void reply_json(req *r, int status, json_t *body, uint64_t version, bool tag);

void http_reply_json(req *r, int status, json_t *body, uint64_t version)
{
    reply_json(r, status, body, version, version != 0);
}

void http_reply_session_json(req *r, int status, json_t *body, uint64_t version)
{
    reply_json(r, status, body, version, true);
}

static void reply_json(req *r, int status, json_t *body, uint64_t version, bool tag)
{
    char *text = body ? json_dumps(body, JSON_COMPACT) : NULL;
    json_decref(body);
    if (!text)
        status = 500;
    struct MHD_Response *resp = text_response(
        r, status >= 400 ? "application/problem+json" : "application/json", text,
        "{\"type\":\"/errors/internal\",\"title\":\"Internal Server Error\",\"status\":500,"
        "\"detail\":\"could not render the response\"}");
    if (tag)
        http_set_etag(resp, version);
    http_queue(r, status, resp);
}

/* Memory the budget refused during the request (api/mem.h) is not the machine's: the request
 * may succeed once others give some back, so say so (memory-budget, with Retry-After) — unless
 * what it held and asked for passed the whole budget, which no retry changes (413 naming
 * max_memory). */
static const api_problem *budget_problem(req *r, const api_problem *p, api_problem *q)
{
    if (p->status != 503 || !p->slug || strcmp(p->slug, "out-of-memory") || !r->mem.over_budget)
        return p;
    if (r->mem.beyond) {
        api_fail_limit(q, "max_memory", api_mem_budget(), r->mem.beyond,
                       "the request needs over %llu bytes, more than the daemon's memory budget "
                       "(--max-memory, %zu bytes) holds; send less or raise --max-memory",
                       (unsigned long long)r->mem.beyond, api_mem_budget());
        return q;
    }
    /* nor when it does with what its own session holds, which it keeps while it runs */
    uint64_t own = 0, v;
    api_model *m = r->s && r->mem.need ? session_model(r->s, &v) : NULL;
    if (m) {
        own = atomic_load(&m->memory_bytes);
        api_model_unref(m);
    }
    if (own && r->mem.need + own > api_mem_budget()) {
        api_fail_limit(q, "max_memory", api_mem_budget(), r->mem.need + own,
                       "the request needs over %llu bytes besides the %llu its session holds, "
                       "more than the daemon's memory budget (--max-memory, %zu bytes) holds; "
                       "send less or raise --max-memory", (unsigned long long)r->mem.need,
                       (unsigned long long)own, api_mem_budget());
        return q;
    }
    api_fail(q, 503, "memory-budget", "the daemon's memory budget (--max-memory, %zu bytes) is in "
             "use by other requests and sessions; retry later (%s)", api_mem_budget(), p->detail);
    q->retry_after = 2;
    return q;
}

/* The problem+json response of p (with Retry-After and WWW-Authenticate where they apply). */
struct MHD_Response *http_problem_response(req *r, const api_problem *p0)
{
    api_problem q = {0};
    const api_problem *p = budget_problem(r, p0, &q);
    r->problem = p->slug ? p->slug : "error"; /* slugs are static strings */
    json_t *j = api_problem_json(p);
    char *text = j ? json_dumps(j, JSON_COMPACT) : NULL;
    json_decref(j);
    struct MHD_Response *resp = text_response(r, "application/problem+json", text,
                                              "{\"status\":503}");
    if (p->retry_after) {
        char ra[16];
        snprintf(ra, sizeof ra, "%d", p->retry_after);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_RETRY_AFTER, ra);
    }
    if (p->status == 401)
        MHD_add_response_header(resp, MHD_HTTP_HEADER_WWW_AUTHENTICATE, "Bearer realm=\"subdivd\"");
    return resp;
}

void http_reply_problem(req *r, const api_problem *p0)
{
    api_problem q = {0};
    const api_problem *p = budget_problem(r, p0, &q); /* its status is the answer's */
    http_queue(r, p->status ? p->status : 500, http_problem_response(r, p));
}

void http_reply_versioned(req *r, json_t *j, uint64_t version, const api_problem *p)
{
    if (!j) {
        http_reply_problem(r, p);
        return;
    }
    json_object_set_new(j, "version", json_integer((json_int_t)version));
    http_reply_json(r, 200, j, version);
}

void http_fail(req *r, int status, const char *slug, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
void http_fail(req *r, int status, const char *slug, const char *fmt, ...)
{
    api_problem p = {0};
    va_list ap;
    va_start(ap, fmt);
    char detail[320];
    vsnprintf(detail, sizeof detail, fmt, ap);
    va_end(ap);
    api_fail(&p, status, slug, "%s", detail);
    http_reply_problem(r, &p);
}

/* ---- streaming ------------------------------------------------------------------------------ */

typedef struct stream_ctx {
    req *r;
    api_model *m;
    http_source src;
} stream_ctx;

static ssize_t stream_read(void *cls, uint64_t pos, char *buf, size_t max)
{
    (void)pos;
    stream_ctx *sc = cls;
    ssize_t n = sc->src.read(sc->src.ctx, buf, max);
    if (n > 0) {
        atomic_fetch_add(&sc->r->bytes, (uint64_t)n);
        metrics_bytes((uint64_t)n);
        return n;
    }
    return n == 0 ? MHD_CONTENT_READER_END_OF_STREAM : MHD_CONTENT_READER_END_WITH_ERROR;
}

/* The end of a stream: its source, the model and the request go, counted on the request's
 * meter (a snapshot given back is memory moved: see http_req_unref). */
static void stream_free(void *cls)
{
    stream_ctx *sc = cls;
    req *r = sc->r;
    api_mem_meter *prev = api_mem_meter_set(&r->mem);
    sc->src.close(sc->src.ctx);
    api_model_unref(sc->m);
    api_free(sc);
    api_mem_meter_set(prev);
    http_req_unref(r);
}

void http_reply_stream(req *r, api_model *m, http_source src, uint64_t size, const char *ctype,
                       const char *disposition, uint64_t version)
{
    stream_ctx *sc = api_malloc(sizeof *sc);
    if (!sc) {
        src.close(src.ctx);
        api_model_unref(m);
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    *sc = (stream_ctx){r, m, src};
    atomic_fetch_add(&r->refs, 1);
    struct MHD_Response *resp = MHD_create_response_from_callback(
        size == UINT64_MAX ? MHD_SIZE_UNKNOWN : size, 256 * 1024, stream_read, sc, stream_free);
    if (!resp) {
        stream_free(sc);
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    if (disposition)
        MHD_add_response_header(resp, "Content-Disposition", disposition);
    http_set_etag(resp, version);
    http_queue(r, 200, resp);
}

/* ---- event streams ---------------------------------------------------------------------- */

typedef struct events_ctx {
    req *r;
    struct ev_listener *l;
    int fd;                   /* the connection's socket (-1: not known), to see the client go */
} events_ctx;

/* Blocks in the connection's own thread until there is something to send (DECISIONS 33). */
static ssize_t events_read(void *cls, uint64_t pos, char *buf, size_t max)
{
    (void)pos;
    events_ctx *ec = cls;
    ssize_t n = ev_read(ec->l, buf, max, ec->r->srv->cfg.sse_heartbeat_s, ec->fd);
    if (n <= 0)
        return MHD_CONTENT_READER_END_OF_STREAM;
    atomic_fetch_add(&ec->r->bytes, (uint64_t)n);
    metrics_bytes((uint64_t)n);
    return n;
}

static void events_free(void *cls)
{
    events_ctx *ec = cls;
    ev_unlisten(ec->l);
    http_req_unref(ec->r);
    api_free(ec);
}

void http_reply_events(req *r, struct ev_listener *l)
{
    events_ctx *ec = api_malloc(sizeof *ec);
    struct MHD_Response *resp = NULL;
    if (ec) {
        const union MHD_ConnectionInfo *fi =
            MHD_get_connection_info(r->conn, MHD_CONNECTION_INFO_CONNECTION_FD);
        *ec = (events_ctx){r, l, fi ? fi->connect_fd : -1};
        atomic_fetch_add(&r->refs, 1);
        resp = MHD_create_response_from_callback(MHD_SIZE_UNKNOWN, 4096, events_read, ec,
                                                 events_free);
        if (!resp)
            events_free(ec);
    } else
        ev_unlisten(l);
    if (!resp) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    /* what the kernel holds for a client that does not read is bounded too (the hub's buffer
     * is the rest), so such a listener is found out and dropped after some 100 KiB of events */
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(r->conn, MHD_CONNECTION_INFO_CONNECTION_FD);
    int sndbuf = EV_SOCKET_BYTES;
    if (ci)
        setsockopt(ci->connect_fd, SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof sndbuf);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, "text/event-stream");
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, "no-cache");
    MHD_add_response_header(resp, "X-Accel-Buffering", "no");
    http_queue(r, 200, resp);
}
