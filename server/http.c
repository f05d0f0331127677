/* http.c — the libmicrohttpd glue: connection callbacks, the checks made before a body is read,
 * body collection, compute slots, one log line per request (the responses: reply.c).
 *
 * Threading: MHD runs one thread per connection (MHD_USE_THREAD_PER_CONNECTION), so a handler
 * may block — on a session's write lock or a model's compute lock — without stalling other
 * connections. Computations additionally take one of `threads` compute slots (server/slots.c:
 * handed to the waiter whose session holds the fewest, and taken only once the model's lock is
 * held, so a request waiting for its own session's computation holds none), with a bounded wait
 * and a 429 + Retry-After when the daemon is saturated, so /healthz, /readyz and /metrics never
 * queue behind work.
 *
 * A request goes: the request line -> on_uri() creates it and takes its query away from
 * libmicrohttpd; first callback (no body yet) -> early(): target (414 for a long path, 400 for a
 * NUL byte or too many query parameters), match (route lookup: 404, 405, the OPTIONS preflight),
 * auth (the session and its bearer token: 404, 401), body (transfer coding,
 * Content-Length against max_body_bytes before anything is read, a body where none is taken,
 * Content-Type: 501, 413, 400, 415); body callbacks -> append to a buffer capped at
 * max_body_bytes; final callback -> the query parameters the route takes (400 for others), then
 * the route's handler (routes.c), which calls api/ and queues one response. Level responses and
 * GET /complex stream from a callback response (a source: out_read, api_cstream_read) that holds
 * references on the session's model until the last byte is sent, and no lock: the source copied
 * what edits change when it opened.
 */
#include "request.h"
#include "../api/mem.h"
#include "../api/handlers.h"
#include "events.h"
#include "guard.h"
#include "holds.h"
#include "metrics.h"
#include <arpa/inet.h>
#include <ctype.h>
#include <errno.h>
#include <microhttpd.h>
#include <poll.h>
#include <sys/socket.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>
#include <unistd.h>

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
    char msg[2048];
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

/* A request that took or gave back this much (its body, parse, levels, a model it freed) asks
 * for malloc_trim half a second after the last such request (api_mem_trim_soon; the main loop
 * trims): what glibc keeps in its heaps below the mmap threshold goes back to the system, so the
 * resident size follows what the daemon holds, while back-to-back builds reuse those pages (a
 * fresh page costs ~15 µs on a virtual machine). */
#define TRIM_AFTER_BYTES (32u << 20)

void http_session_done(req *r)
{
    if (r->s && r->using)
        store_unuse(r->srv->st, r->s);
    r->using = 0;
    session_unref(r->s);
    r->s = NULL;
}

void http_req_unref(req *r)
{
    if (atomic_fetch_sub(&r->refs, 1) != 1)
        return;
    api_mem_meter *prev = api_mem_meter_set(&r->mem);
    http_session_done(r);
    if (r->held)
        holds_give(r->srv->bodies, &r->client, r->held);
    api_free(r->body);
    api_free(r->query);
    api_mem_meter_set(prev);
    int trim = r->mem.moved > TRIM_AFTER_BYTES;
    api_free(r);
    if (trim)
        api_mem_trim_soon();
}

/* ---- compute slots ---------------------------------------------------------------------- */

int http_take_slot(req *r, api_problem *p)
{
    if (slots_take(r->srv->compute, r->s, r->srv->cfg.queue_timeout_s)) {
        p->retry_after = 5;
        api_fail(p, 429, "busy", "all %d compute threads are busy; retry in a few seconds",
                 r->srv->cfg.threads);
        return -1;
    }
    r->slot_t0 = mono_now();
    /* the cores for this computation: --level-threads shared among the slots taken now (this
     * one included), so one request alone uses them all and concurrent ones do not crowd */
    int busy = slots_busy(r->srv->compute);
    api_set_compute_threads(r->srv->cfg.level_threads / (busy > 0 ? busy : 1));
    if (r->s) {
        atomic_store(&r->s->busy_since, r->slot_t0);
        atomic_store(&r->s->busy_level, 0);
    }
    return 0;
}

void http_give_slot(req *r)
{
    metrics_compute(route_kind(r->rt), mono_now() - r->slot_t0);
    if (r->s)
        atomic_store(&r->s->busy_level, -1);
    slots_give(r->srv->compute, r->s);
    api_set_compute_threads(1);
}


/* ---- reading the request ------------------------------------------------------------------ */

const char *http_header(req *r, const char *name)
{
    return MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND, name);
}

const struct sockaddr *http_client_address(req *r)
{
    const union MHD_ConnectionInfo *i =
        MHD_get_connection_info(r->conn, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
    return i ? i->client_addr : NULL;
}

/* The query is the daemon's own (on_uri below): parsed into r->params at the first call. */
const char *http_arg(req *r, const char *key)
{
    for (size_t i = 0; i < r->nparams; i++)
        if (!strcmp(r->params[i].key, key))
            return r->params[i].value;
    return NULL;
}

/* Refuse a query parameter the route does not take (route.query), or one given twice: 400
 * with its name as the pointer (escaped as in logs: the problem is JSON, a name any bytes).
 * 1 when answered. */
static int query_refused(req *r, const char *const *allowed)
{
    if (allowed && allowed[0] && !strcmp(allowed[0], "*"))
        return 0;
    for (size_t i = 0; i < r->nparams; i++) {
        int ok = 0;
        for (const char *const *a = allowed; !ok && a && *a; a++)
            ok = !strcmp(*a, r->params[i].key);
        char key[64];
        parse_log_escape(key, sizeof key, r->params[i].key);
        api_problem p = {0};
        if (!ok) {
            char list[160] = "";
            for (const char *const *a = allowed; a && *a; a++)
                snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s",
                         a == allowed ? "" : ", ", *a);
            api_fail_at(&p, 400, "unknown-parameter", key,
                        "unknown query parameter \"%.40s\" (allowed: %s)", key,
                        list[0] ? list : "none");
            http_reply_problem(r, &p);
            return 1;
        }
        for (size_t j = 0; j < i; j++)
            if (!strcmp(r->params[j].key, r->params[i].key)) {
                api_fail_at(&p, 400, "repeated-parameter", key,
                            "the query parameter \"%.40s\" is given more than once", key);
                http_reply_problem(r, &p);
                return 1;
            }
    }
    return 0;
}

/* ---- a chunked body over the limit ------------------------------------------------------- */

/* Write all n bytes to the socket before `deadline` (monotonic seconds); 0 or -1. */
static int send_all(int fd, const char *b, size_t n, double deadline)
{
    while (n) {
        ssize_t w = send(fd, b, n, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (w > 0) {
            b += w;
            n -= (size_t)w;
            continue;
        }
        if (w < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)
            return -1;
        double left = deadline - mono_now();
        struct pollfd pf = {fd, POLLOUT, 0};
        if (left <= 0 || poll(&pf, 1, (int)(left * 1000) + 1) < 0)
            return -1;
    }
    return 0;
}

/* Read and drop what the client still sends, until it closes, `max` bytes or `deadline`. */
static void drain(int fd, size_t max, double deadline)
{
    char buf[1 << 16];
    size_t got = 0;
    while (got < max) {
        double left = deadline - mono_now();
        struct pollfd pf = {fd, POLLIN, 0};
        if (left <= 0 || poll(&pf, 1, (int)(left * 1000) + 1) <= 0)
            return;
        ssize_t r = recv(fd, buf, sizeof buf, MSG_DONTWAIT);
        if (r == 0 || (r < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR))
            return;
        if (r > 0)
            got += (size_t)r;
    }
}

/* A chunked body has just passed max_body_bytes: answer 413 now rather than read the rest.
 * libmicrohttpd 0.9.75 cannot queue a response while upload data is pending (MHD_queue_response
 * fails outside HEADERS_PROCESSED and FULL_REQ_RECEIVED), so the whole answer, with
 * "Connection: close", is written to the socket here: this connection's thread is inside our
 * callback, so libmicrohttpd is not writing (and the daemon speaks plain HTTP: no TLS layer to
 * bypass). Then our side is shut for writing and what the client still sends is read and
 * dropped for at most 1 s and 4 MiB, so the client reads the answer before the connection goes
 * (closing with unread data sends a reset, which can destroy an answer not yet read). MHD_NO then
 * makes libmicrohttpd close the connection; the request is logged as a 413 like any other. */
static enum MHD_Result refuse_body_now(req *r)
{
    size_t max = r->srv->cfg.limits.max_body_bytes;
    api_problem p = {0};
    api_fail_limit(&p, "max_body_bytes", max, max + 1,
                   "the body exceeds the limit of %zu bytes; send a smaller one or raise "
                   "--max-body-bytes", max);
    json_t *j = api_problem_json(&p);
    char *body = j ? json_dumps(j, JSON_COMPACT) : NULL;
    json_decref(j);
    const char *text = body ? body : "{\"status\":413}";
    char date[64], head[1024];
    time_t now = time(NULL);
    struct tm tm;
    gmtime_r(&now, &tm);
    strftime(date, sizeof date, "%a, %d %b %Y %H:%M:%S GMT", &tm);
    int n = snprintf(head, sizeof head, "HTTP/1.1 413 %s\r\nDate: %s\r\nConnection: close\r\n"
                     "Content-Type: application/problem+json\r\nContent-Length: %zu\r\n",
                     api_status_title(413), date, strlen(text));
    http_header_pair h[4];
    int nh = http_common_header_list(r, h);
    for (int i = 0; i < nh && n > 0 && (size_t)n < sizeof head; i++)
        n += snprintf(head + n, sizeof head - (size_t)n, "%s: %s\r\n", h[i].name, h[i].value);
    if (n > 0 && (size_t)n < sizeof head - 2)
        n += snprintf(head + n, sizeof head - (size_t)n, "\r\n");
    const union MHD_ConnectionInfo *ci =
        MHD_get_connection_info(r->conn, MHD_CONNECTION_INFO_CONNECTION_FD);
    if (ci && n > 0 && (size_t)n < sizeof head) {
        int fd = ci->connect_fd;
        double deadline = mono_now() + 1.0;
        if (!send_all(fd, head, (size_t)n, deadline) && !send_all(fd, text, strlen(text), deadline)) {
            shutdown(fd, SHUT_WR);
            drain(fd, (size_t)4 << 20, deadline);
        }
    }
    atomic_store(&r->bytes, strlen(text));
    r->status = 413;
    r->queued = 1;
    r->answered_raw = 1;
    api_free(body);
    return MHD_NO;
}

/* ---- before the body: match, auth, body -------------------------------------------------- */

/* The CORS preflight of a known resource: 204 with the allowed methods and headers. */
static void preflight(req *r, const char *allow)
{
    r->route_name = "preflight";
    struct MHD_Response *resp = http_empty();
    char methods[160];
    snprintf(methods, sizeof methods, "%s, OPTIONS", allow);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ALLOW, methods);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_METHODS, methods);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_HEADERS,
                            "Authorization, Content-Type, If-Match, If-None-Match");
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_MAX_AGE, "600");
    http_queue(r, 204, resp);
}

/* 405 naming the allowed methods in the Allow header: the route's, and OPTIONS, which every
 * resource answers (the same list as a preflight's Allow). */
static void method_not_allowed(req *r, const api_problem *p, const char *allow)
{
    struct MHD_Response *resp = http_problem_response(r, p);
    char methods[160];
    snprintf(methods, sizeof methods, "%s, OPTIONS", allow);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ALLOW, methods);
    http_queue(r, 405, resp);
}

/* What is wrong with the request target itself: a path of API_MAX_PATH_BYTES or more (414), a
 * NUL byte decoded in the path or the query (400: a C string would end there, and the request
 * mean something else than it says), more than API_MAX_QUERY_PARAMS query parameters (400).
 * Splits the query into r->params. 1 when a response was queued. */
static int early_target(req *r, const char *url)
{
    if (strlen(url) >= sizeof r->path) {
        http_fail(r, 414, "uri-too-long", "the path has %zu bytes; at most %zu are taken",
                  strlen(url), sizeof r->path - 1);
        return 1;
    }
    if (r->oom) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return 1;
    }
    int rc = r->query ? parse_query(r->query, r->params, API_MAX_QUERY_PARAMS, &r->nparams)
                      : PARSE_QUERY_OK;
    int nul_path = guard_request_had_nul(r->gk); /* noted by guard_unescape */
    if (nul_path || rc == PARSE_QUERY_NUL) {
        http_fail(r, 400, "bad-uri", "the %s holds an encoded NUL byte (%%00)",
                  nul_path ? "path" : "query");
        return 1;
    }
    if (rc == PARSE_QUERY_TOO_MANY) {
        http_fail(r, 400, "too-many-parameters", "the query has more than %d parameters",
                  API_MAX_QUERY_PARAMS);
        return 1;
    }
    return 0;
}

/* The route of the request (r->rt, its segments, r->route_name), or the answer that there is
 * none: 404 for an unknown path, 405 for a method the resource does not take, 204 for an OPTIONS
 * preflight. 1 when a response was queued. */
static int early_match(req *r)
{
    const char *m = r->method;
    char allow[128];
    int known = route_methods(r->path, r, allow, sizeof allow);
    if (!known && route_is_static(r->path)) {
        r->route_name = "static";
        if (strcmp(m, "GET") && strcmp(m, "HEAD") && strcmp(m, "OPTIONS")) {
            api_problem p = {0};
            api_fail(&p, 405, "method-not-allowed", "%s is not allowed on %.100s", r->method_sent,
                     r->path);
            method_not_allowed(r, &p, "GET, HEAD");
            return 1;
        }
        r->rt = route_static();
        strcpy(allow, "GET, HEAD");
        known = 1;
    }
    if (!known) {
        r->route_name = "unknown";
        http_fail(r, 404, "not-found", "no resource at %.100s", r->path);
        return 1;
    }
    if (!strcmp(m, "OPTIONS")) {
        preflight(r, allow);
        return 1;
    }
    if (!r->rt)
        r->rt = route_find(m, r->path, r);
    if (!r->rt) {
        r->route_name = route_name_of(r->path, r);
        api_problem p = {0};
        api_fail(&p, 405, "method-not-allowed", "%s is not allowed on %.100s (allowed: %s)",
                 r->method_sent, r->path, allow);
        method_not_allowed(r, &p, allow);
        return 1;
    }
    if (r->rt->pattern[0] == '/')
        r->route_name = r->rt->pattern;
    route_match(r->rt->pattern, r->path, r); /* re-capture the segments of the chosen route */
    return 0;
}

/* Who is asking comes first: a client without the session's token learns nothing else. The
 * session of a session route (r->s; 404 when there is none) and its bearer token (401). 1 when a
 * response was queued. */
static int early_auth(req *r)
{
    if (!r->rt->session)
        return 0;
    const char *h = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                MHD_HTTP_HEADER_AUTHORIZATION);
    char tbuf[128];
    const char *bearer = parse_bearer(h, tbuf, sizeof tbuf);
    int token_query = 0; /* the route lists access_token among its query parameters */
    for (const char *const *a = r->rt->query; a && *a; a++)
        token_query |= !strcmp(*a, "access_token");
    const char *q = token_query && !h ? http_arg(r, "access_token") : NULL;
    const char *presented = bearer ? bearer : q;
    store_miss miss;
    char why[320];
    r->s = store_get(r->srv->st, r->seg_id, r->srv->cfg.no_auth ? NULL : presented ? presented : "",
                     &miss, why, sizeof why);
    api_problem p = {0};
    if (!r->s && miss == STORE_NONE) {
        http_fail(r, 404, "no-session", "no session %.40s (it may have expired or been deleted)",
                  r->seg_id);
        return 1;
    }
    if (!r->s && (miss == STORE_DAMAGED || miss == STORE_OVER_LIMITS || miss == STORE_BUSY) &&
        !strcmp(r->rt->method, "DELETE") &&
        !strcmp(r->rt->pattern, "/v1/sessions/{id}")) { /* its holder may still let it go */
        persist_rc rc = persist_delete(store_persist(r->srv->st), r->seg_id);
        if (rc == PERSIST_OK || rc == PERSIST_ABSENT) {
            log_line(r->srv, LOG_WARN, "session %.40s: deleted %s (%s)", r->seg_id,
                     miss == STORE_DAMAGED ? "with its damaged data" : "without being rebuilt", why);
            http_queue(r, 204, http_empty());
            return 1;
        }
        api_fail(&p, 503, "store-unavailable", "the session could not be deleted from the store");
        p.retry_after = 5;
        http_reply_problem(r, &p);
        return 1;
    }
    bool damaged = miss == STORE_DAMAGED;
    if (damaged)
        miss = STORE_CORRUPT;
    if (!r->s && miss != STORE_UNAUTHORIZED) { /* the details go to the log, not to the client */
        p.retry_after = miss == STORE_CORRUPT ? 0 : 5;
        if (miss == STORE_FULL)
            api_fail(&p, 429, "too-many-sessions", "session %.40s is stored, but every resident "
                     "session is in use; retry in a few seconds", r->seg_id);
        else if (miss == STORE_BUSY) /* its data is whole: not corrupt, and no advice to delete */
            api_fail(&p, 503, "memory-budget", "session %.40s is stored, but rebuilding it needs "
                     "memory that is in use now; retry in a few seconds", r->seg_id);
        else if (miss == STORE_OVER_LIMITS) {
            api_fail(&p, 503, "store-corrupt", "session %.40s is stored whole, but rebuilding it "
                     "needs more than this daemon's limits allow (the daemon's log says which); a "
                     "daemon with the limits it was made under loads it", r->seg_id);
            p.retry_after = 0;
        } else if (miss == STORE_CORRUPT)
            api_fail(&p, 503, "store-corrupt", "session %.40s cannot be rebuilt from the store "
                     "(damaged data; the daemon's log says where)%s", r->seg_id,
                     damaged ? "; DELETE it to start afresh" : "");
        else
            api_fail(&p, 503, "store-unavailable", "the session store cannot be read now");
        if (miss != STORE_FULL)
            log_line(r->srv, LOG_ERROR, "session %.40s: %s: %s", r->seg_id,
                     miss == STORE_CORRUPT || miss == STORE_OVER_LIMITS ? "store-corrupt"
                     : miss == STORE_BUSY                              ? "memory-budget"
                                                                       : "store-unavailable",
                     why);
        http_reply_problem(r, &p);
        return 1;
    }
    if (r->s && (r->srv->cfg.no_auth || session_token_ok(r->s, presented))) {
        session_use(r->s); /* its holder's request: the session does not expire until it ends */
        r->using = 1;
        return 0;
    }
    api_fail(&p, 401, "unauthorized",
             h || q ? "the bearer token does not match this session"
                    : "send the session's token as \"Authorization: Bearer <token>\"");
    http_reply_problem(r, &p);
    return 1;
}

/* Hold n more body bytes for the request's client (holds.h): false past its cap. */
static bool hold_body(req *r, size_t n)
{
    if (!r->held)
        r->client = rate_key_of(http_client_address(r));
    if (!holds_take(r->srv->bodies, &r->client, n))
        return false;
    r->held += n;
    return true;
}

/* A body of n bytes (its buffer) does not fit the client's --max-client-body-bytes: 413 when it
 * alone passes it (waiting cannot help), else 429 (the client's other bodies hold the rest). */
static void client_bodies_full(req *r, size_t n)
{
    api_problem p = {0};
    size_t cap = holds_cap(r->srv->bodies);
    if (n > cap) {
        api_fail_limit(&p, "max_client_body_bytes", cap, n, "a body of %zu bytes is more than "
                       "one client may send at once (--max-client-body-bytes %zu)", n, cap);
        http_reply_problem(r, &p);
        return;
    }
    p.retry_after = 5;
    size_t others = holds_held(r->srv->bodies, &r->client) - r->held; /* r->held is in it */
    api_fail(&p, 429, "client-bodies", "this client's other request bodies being sent hold about "
             "%zu bytes, and this one's %zu would pass --max-client-body-bytes (%zu); send fewer "
             "at once or retry when they are done", others, n, cap);
    http_reply_problem(r, &p);
}

/* The whole buffer of a body whose Content-Length is known, taken before it is read: one block
 * of the exact size (no doubling), and a body that does not fit the memory budget is refused
 * before a byte of it arrives. 1 when a response was queued. */
static int reserve_body(req *r, size_t n)
{
    if (!hold_body(r, n + 1)) {
        client_bodies_full(r, n + 1);
        return 1;
    }
    r->body = api_malloc(n + 1);
    if (!r->body) {
        http_fail(r, 503, "out-of-memory", "no memory for a body of %zu bytes; retry later", n);
        return 1;
    }
    r->cap = n + 1;
    r->body[0] = 0;
    return 0;
}

/* MHD_get_connection_values iterator: counts the Content-Length headers and whether any differs
 * from the first. */
typedef struct lengths {
    int n;
    bool differ;
    const char *first;
} lengths;
static enum MHD_Result count_length(void *cls, enum MHD_ValueKind kind, const char *key,
                                    const char *value)
{
    lengths *l = cls;
    (void)kind;
    if (key && !strcasecmp(key, MHD_HTTP_HEADER_CONTENT_LENGTH)) {
        if (l->n++ == 0)
            l->first = value;
        else if (!value || !l->first || strcmp(value, l->first))
            l->differ = true;
    }
    return MHD_YES;
}

/* What can be said of the body before reading it: a transfer coding MHD can frame (501), a
 * Content-Length within max_body_bytes (413, before anything is allocated), no body where the
 * route takes none (400), JSON where it takes one (415). 1 when a response was queued. */
static int early_body(req *r)
{
    /* MHD frames a body only by Content-Length or chunked; any other transfer coding would have
     * it read until the client closes (RFC 9112 6.1: 501 for a coding we do not understand) */
    const char *te0 = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                  MHD_HTTP_HEADER_TRANSFER_ENCODING);
    if (te0 && strcasecmp(te0, "chunked")) {
        http_fail(r, 501, "unsupported-transfer-encoding",
                  "Transfer-Encoding \"%.40s\" is not supported; send the body with Content-Length "
                  "or chunked", te0);
        return 1;
    }
    /* two Content-Length values that differ leave the body's end in doubt (RFC 9112 6.3: an
     * unrecoverable framing error; a proxy in front may have read the other one) */
    lengths ls = {0};
    MHD_get_connection_values(r->conn, MHD_HEADER_KIND, count_length, &ls);
    if (ls.differ) {
        http_fail(r, 400, "bad-framing", "the request has %d Content-Length headers that differ; "
                  "send one", ls.n);
        return 1;
    }
    /* with Transfer-Encoding: chunked libmicrohttpd frames the body by the chunks and ignores
     * Content-Length (RFC 9112 6.3), so a "Content-Length: 0" beside it must not pass for no
     * body (it skipped the media type and the guard's body deadline); and since a proxy in
     * front may have framed it by the Content-Length, what follows on the connection may not
     * be the next request it meant: the connection is closed after the answer (6.3: "the
     * server MUST close the connection after responding to such a request") */
    if (te0 && ls.n > 0)
        r->close_after = 1;
    const char *cl = te0 ? NULL
                         : MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
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
            http_reply_problem(r, &p);
            return 1;
        }
        if (n > 0 && !r->rt->body) {
            http_fail(r, 400, "unexpected-body", "%s %s takes no request body", r->method,
                      r->rt->pattern);
            return 1;
        }
        if (n > 0 && reserve_body(r, (size_t)n))
            return 1;
    }
    if (r->rt->body && (cl ? strcmp(cl, "0") : 1)) {
        const char *ct = MHD_lookup_connection_value(r->conn, MHD_HEADER_KIND,
                                                     MHD_HTTP_HEADER_CONTENT_TYPE);
        int json = ct && !strncasecmp(ct, "application/json", 16) &&
                   (ct[16] == 0 || ct[16] == ';' || ct[16] == ' ');
        if (r->rt->body == 2 && ct && !strncasecmp(ct, "application/octet-stream", 24))
            json = 1; /* a route that also takes binary bodies (PUT /embedded/{name}) */
        if (!json && (cl || te0)) {
            http_fail(r, 415, "unsupported-media-type",
                      "send the body as application/json (got %.60s)", ct ? ct : "no Content-Type");
            return 1;
        }
    }
    return 0;
}

/* The body the request announces: Content-Length, UINT64_MAX when chunked, 0 for none. */
static uint64_t body_announced(req *r)
{
    if (http_header(r, MHD_HTTP_HEADER_TRANSFER_ENCODING)) /* chunked wins (early_body) */
        return UINT64_MAX;
    const char *cl = http_header(r, MHD_HTTP_HEADER_CONTENT_LENGTH);
    return cl ? strtoull(cl, NULL, 10) : 0;
}

/* Every check that needs no body, in order. Returns 1 when a response was queued. */
static int early(req *r, const char *url)
{
    return early_target(r, url) || early_match(r) || early_auth(r) || early_body(r);
}

/* MHD_OPTION_URI_LOG_CALLBACK: libmicrohttpd calls it with the raw request target before it
 * parses the target, and makes its answer the request's context (*con_cls). The request is
 * created here so that its query is the daemon's own: copied, then cut off at the '?' for
 * libmicrohttpd, which therefore parses no query arguments. (0.9.75 finds the '?' before this
 * call and parses what follows it after; every argument takes a header record from the
 * connection's memory pool, which ~700 short ones exhaust: it then closes the connection
 * without an answer. The target lies in its read buffer, writable, which it cuts up itself.)
 * early_target splits the copy, with a bound on the count and NUL bytes refused. NULL (out of
 * memory) makes the first access-handler call close the connection. */
static void *on_uri(void *cls, const char *uri, struct MHD_Connection *conn)
{
    char *q = uri ? strchr((char *)uri, '?') : NULL;
    req *r = api_calloc(1, sizeof *r);
    if (r) {
        atomic_init(&r->refs, 1);
        r->srv = cls;
        /* in flight until on_completed (libmicrohttpd calls it for every request whose URI
         * callback it called): a stop waits for it (http_in_flight) */
        atomic_fetch_add(&r->srv->in_flight, 1);
        r->in_flight = 1;
        r->conn = conn;
        r->t0 = mono_now();
        r->method = "OTHER";
        r->route_name = "unknown";
        if (q) {
            api_mem_meter *prev = api_mem_meter_set(&r->mem);
            r->query = api_strdup(q + 1);
            r->oom = !r->query;
            api_mem_meter_set(prev);
        }
    }
    if (q)
        q[1] = 0;
    return r;
}

static enum MHD_Result serve(server *srv, req *r, const char *url, const char *method,
                             const char *upload_data, size_t *upload_size)
{
    if (!r) {
        log_line(srv, LOG_WARN, "out of memory for a request: its connection is closed");
        return MHD_NO;
    }
    if (!r->started) { /* the first call: headers complete, no body read yet */
        r->started = 1;
        r->method = intern_method(method);
        size_t k = 0; /* RFC 9110 token characters only: the detail is JSON and the method free */
        const char *c = method;
        for (; *c && k < 20; c++)
            if (isalnum((unsigned char)*c) || strchr("!#$%&'*+-.^_`|~", *c))
                r->method_sent[k++] = *c;
        strcpy(r->method_sent + k, *c ? "..." : "");
        snprintf(r->path, sizeof r->path, "%s", url);
        r->gk = guard_conn_of(r->conn);
        /* an answer queued now makes libmicrohttpd discard any body and close */
        int answered = early(r, url);
        guard_request_begin(srv->guard, r->gk, answered ? 0 : body_announced(r));
        return MHD_YES;
    }
    if (*upload_size)
        guard_body_progress(srv->guard, r->gk, *upload_size);
    if (r->queued) { /* answered early: swallow any body */
        *upload_size = 0;
        return MHD_YES;
    }
    if (*upload_size) {
        size_t n = *upload_size;
        *upload_size = 0;
        /* chunked: Content-Length was checked; bytes discarded below count too */
        if (r->received + n > srv->cfg.limits.max_body_bytes)
            return refuse_body_now(r);
        r->received += n;
        if (r->too_big || r->client_full)
            return MHD_YES;
        if (r->len + n + 1 > r->cap) {
            size_t cap = r->cap ? r->cap : 4096, most = srv->cfg.limits.max_body_bytes + 1;
            while (cap < r->len + n + 1)
                cap *= 2;
            cap = cap < most ? cap : most; /* r->len + n + 1 <= most (checked above) */
            if (!hold_body(r, cap - r->cap)) { /* discard the rest, answer at the end */
                r->client_full = 1;
                return MHD_YES;
            }
            char *b = api_realloc(r->body, cap);
            if (!b) { /* discard the rest, answer 503 at the end */
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
    guard_request_work(srv->guard, r->gk); /* the body is complete */
    if (r->client_full) {
        client_bodies_full(r, r->received + 1);
        return MHD_YES;
    }
    if (r->too_big) {
        api_problem p = {0};
        p.retry_after = 5;
        api_fail(&p, 503, "out-of-memory", "out of memory while reading the body of %zu bytes; "
                 "retry later", r->len);
        http_reply_problem(r, &p);
        return MHD_YES;
    }
    if (r->len && !r->rt->body) {
        http_fail(r, 400, "unexpected-body", "%s %s takes no request body", method, r->rt->pattern);
        return MHD_YES;
    }
    if (query_refused(r, r->rt->query))
        return MHD_YES;
    r->rt->fn(r);
    if (!r->queued)
        http_fail(r, 500, "internal", "the handler produced no response");
    /* an answer made whole (no stream holds the request) needs the session no more: let it go
     * now, before libmicrohttpd sends the answer, so that a client's next request, or another
     * client's, never finds it still in use (a full session table would turn that one away) */
    if (atomic_load(&r->refs) == 1)
        http_session_done(r);
    return MHD_YES;
}

/* Every callback of a request runs with the request's memory meter set (api/mem.h): what the
 * request allocates on its connection's thread, from the body to the response. */
static enum MHD_Result on_request(void *cls, struct MHD_Connection *conn, const char *url,
                                  const char *method, const char *version,
                                  const char *upload_data, size_t *upload_size, void **con_cls)
{
    (void)version;
    req *r = *con_cls;
    api_mem_meter *prev = api_mem_meter_set(r ? &r->mem : NULL);
    (void)conn;
    enum MHD_Result res = serve(cls, r, url, method, upload_data, upload_size);
    api_mem_meter_set(prev);
    return res;
}

static void on_completed(void *cls, struct MHD_Connection *conn, void **con_cls,
                         enum MHD_RequestTerminationCode code)
{
    (void)conn;
    server *srv = cls;
    req *r = *con_cls;
    if (!r)
        return;
    guard_request_done(srv->guard, r->gk);
    double ms = (mono_now() - r->t0) * 1e3;
    char path[4 * sizeof r->path]; /* the path only: queries will carry tokens */
    parse_log_escape(path, sizeof path, r->path);
    if (r->queued) {
        metrics_request(r->route_name, r->method, r->status, ms / 1e3);
        /* a load balancer's health checks that pass (every second, per daemon) at debug: the
         * info log stays the clients' requests; a check that fails is news */
        bool probe = r->route_name && r->status < 300 &&
                     (!strcmp(r->route_name, "/healthz") || !strcmp(r->route_name, "/readyz"));
        log_line(srv, probe ? LOG_DEBUG : LOG_INFO, "%s %s %d %lluB %.2fms route=%s%s%s%s", r->method, path,
                 r->status, (unsigned long long)atomic_load(&r->bytes), ms,
                 r->route_name ? r->route_name : "unknown", r->problem ? " type=/errors/" : "",
                 r->problem ? r->problem : "",
                 code == MHD_REQUEST_TERMINATED_COMPLETED_OK || r->answered_raw ? ""
                                                                    : " (cut short)");
    }
    log_line(srv, LOG_DEBUG, "%s %s: at most %lld bytes held by the request", r->method, path,
             (long long)r->mem.peak);
    if (r->in_flight)
        atomic_fetch_sub(&srv->in_flight, 1);
    *con_cls = NULL;
    http_req_unref(r);
}

/* libmicrohttpd's messages, as warnings — except those about clients that went away or were
 * turned away (closed mid-request, by the guard or themselves; over a connection limit), which
 * a flood of hostile connections would otherwise turn into a flood of log lines: those are
 * debug, and counted on /metrics (or logged as requests). */
static void mhd_log(void *cls, const char *fmt, va_list ap)
{
    static const char *const routine[] = {"Connection socket is closed",
                                          "Connection was closed by remote side",
                                          "Server reached connection limit",
                                          "Socket has been disconnected",
                                          /* our MHD_NO: refuse_body_now, or out of memory */
                                          "Application reported internal error"};
    server *srv = cls;
    char msg[512];
    vsnprintf(msg, sizeof msg, fmt, ap);
    size_t n = strlen(msg);
    while (n && msg[n - 1] == '\n')
        msg[--n] = 0;
    int level = LOG_WARN;
    for (size_t i = 0; i < sizeof routine / sizeof *routine; i++)
        if (!strncmp(msg, routine[i], strlen(routine[i])))
            level = LOG_DEBUG;
    /* "Failed to send the response body for the request for `...'. Error: ...": a client that
     * closed or reset its connection before the end of an answer (a download given up) */
    if (!strncmp(msg, "Failed to send", 14) && strstr(msg, "closed by remote peer"))
        level = LOG_DEBUG;
    log_line(srv, level, "http: %s", msg);
}

int http_start(server *srv)
{
    struct sockaddr_storage ss;
    memset(&ss, 0, sizeof ss);
    /* MHD_USE_ITC: what MHD_quiesce_daemon needs in this mode (http_quiesce) */
    unsigned flags = MHD_USE_AUTO_INTERNAL_THREAD | MHD_USE_THREAD_PER_CONNECTION |
                     MHD_USE_ERROR_LOG | MHD_USE_ITC;
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
    const config *c = &srv->cfg;
    guard_config gc = {(unsigned)c->max_connections, (unsigned)c->connection_reserve,
                       c->header_timeout_s, c->connection_timeout_s, c->body_min_rate};
    srv->guard = guard_new(&gc);
    if (!srv->guard) {
        log_line(srv, LOG_ERROR, "cannot start the connection guard: out of memory");
        return -1;
    }
    /* 0 for PER_IP_CONNECTION_LIMIT is no limit, as is 0 for --max-connections-per-client */
    srv->mhd = MHD_start_daemon(
        flags, (uint16_t)c->port, guard_accept, srv->guard, on_request, srv,
        MHD_OPTION_EXTERNAL_LOGGER, mhd_log, srv, MHD_OPTION_SOCK_ADDR, &ss,
        MHD_OPTION_NOTIFY_COMPLETED, on_completed, srv, MHD_OPTION_URI_LOG_CALLBACK, on_uri, srv,
        MHD_OPTION_NOTIFY_CONNECTION, guard_notify, srv->guard, MHD_OPTION_UNESCAPE_CALLBACK,
        guard_unescape, srv->guard, MHD_OPTION_CONNECTION_LIMIT, (unsigned)c->max_connections,
        MHD_OPTION_PER_IP_CONNECTION_LIMIT, (unsigned)c->max_connections_per_client,
        MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)c->connection_timeout_s,
        MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)64 * 1024, MHD_OPTION_END);
    if (!srv->mhd) {
        guard_free(srv->guard);
        srv->guard = NULL;
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

void http_quiesce(server *srv)
{
    atomic_store(&srv->draining, 1); /* answers now close their connection (http_queue) */
    ev_stop_all(); /* event streams end: they would hold the stop for ever */
    if (!srv->mhd)
        return;
    MHD_socket ls = MHD_quiesce_daemon(srv->mhd);
    if (ls != MHD_INVALID_SOCKET)
        close(ls);
    else
        log_line(srv, LOG_WARN, "cannot stop listening before the requests in flight finish");
}

int http_in_flight(server *srv) { return atomic_load(&srv->in_flight); }

void http_stop(server *srv)
{
    ev_stop_all(); /* event streams end, so their connection threads can be joined */
    if (srv->mhd) {
        MHD_stop_daemon(srv->mhd);
        srv->mhd = NULL;
    }
    guard_free(srv->guard); /* after MHD: every connection has gone */
    srv->guard = NULL;
}

void http_write_connection_metrics(server *srv, FILE *f)
{
    guard_stats gs = {0};
    if (srv->guard)
        guard_get_stats(srv->guard, &gs);
    metrics_write_connections(f, &gs);
}

