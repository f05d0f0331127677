/* request.h — one HTTP request as the two halves of server/ see it: http.c (the libmicrohttpd
 * glue: connection callbacks, the checks before the body, body collection, responses, streaming,
 * compute slots) and routes.c (the route table and each route's handler: request -> api/ call ->
 * response). Only http.c includes libmicrohttpd; a handler reads headers and query arguments and
 * answers through the functions below.
 *
 * Every handler queues exactly one response (http.c answers 500 for one that does not). Replies
 * that take a problem turn it into application/problem+json with its status; JSON replies steal
 * the json_t they are given.
 */
#ifndef SUBDIVD_REQUEST_H
#define SUBDIVD_REQUEST_H

#include "server.h"
#include "parse.h"
#include "rate.h"
#include "../api/limits.h"
#include "../api/mem.h"
#include "../api/out.h"
#include "../api/problem.h"
#include <stdatomic.h>
#include <stdint.h>
#include <sys/types.h>

struct MHD_Connection;
struct MHD_Response;
struct guard_conn;

typedef struct req req;
typedef void (*handler_fn)(req *r);

/* One row of the route table (routes.c). */
typedef struct route {
    const char *method;
    const char *pattern;   /* segments; "{id}" and "{L}" match one segment */
    handler_fn fn;
    int session;           /* needs a session ({id}) and its token */
    int body;              /* takes a JSON body (2: or application/octet-stream) */
    const char *const *query; /* the query parameters it takes, NULL-terminated ({"*", NULL}:
                                 any); NULL: none (http.c answers 400 for others). One that
                                 lists "access_token" also takes the session's token there
                                 (EventSource cannot send headers; queries are never logged) */
} route;

struct req {
    server *srv;
    struct MHD_Connection *conn;
    struct guard_conn *gk;            /* the connection's record in the guard (or NULL) */
    const char *method;               /* one of the known methods or "OTHER" (metrics, logs) */
    char method_sent[24];             /* the method as sent (token characters, cut at 20): 405s */
    char path[API_MAX_PATH_BYTES];   /* decoded, without the query; longer is a 414 */
    char *query;                      /* the raw query (api_malloc), decoded into params */
    parse_param params[API_MAX_QUERY_PARAMS];
    size_t nparams;
    int started;                      /* the first access-handler call has been made */
    int oom;                          /* the query could not be kept: 503 */
    const route *rt;
    const char *route_name;   /* pattern for metrics and logs */
    const char *problem;      /* the slug of the problem answered (static), logged; or NULL */
    double slot_t0;           /* when the compute slot was taken (compute seconds by kind) */
    char *body;
    size_t len, cap;
    int too_big;              /* the body could not be kept (out of memory): refused at its end */
    int client_full;          /* it would pass --max-client-body-bytes: refused at its end */
    size_t received;          /* body bytes received, kept or discarded */
    size_t held;              /* body bytes held for the client (server/holds.h) */
    rate_key client;          /* the client's key, set when `held` first grows */
    int answered_raw;         /* answered on the socket itself (a chunked body over the limit) */
    double t0;
    session *s;
    int using;                /* r->s counts this request in its in_use (session_use) */
    char seg_id[40];
    char seg_level[64];    /* {L}, or an embedded model's {name} */
    int status;
    atomic_uint_fast64_t bytes;
    int queued;
    int close_after;          /* Transfer-Encoding beside Content-Length: close after answering */
    int in_flight;            /* counted in server.in_flight until on_completed */
    atomic_int refs;          /* the connection and a streaming response */
    api_mem_meter mem;        /* what the request's callbacks allocate (api/mem.h) */
};

/* ---- routes.c ---- */

/* Match `path` against a route pattern; captures {L} and {name} into seg_level, {id} and {slug}
 * into seg_id. */
int route_match(const char *pattern, const char *path, req *r);
/* The route for method (HEAD as GET) and path, with its segments captured; NULL if none. */
const route *route_find(const char *method, const char *path, req *r);
/* The methods allowed on path ("GET, HEAD, PUT"); their number (0: no such resource). */
int route_methods(const char *path, req *r, char *allow, size_t cap);
/* The pattern of the last route matching path, or "unknown" (a 405's metrics label). */
const char *route_name_of(const char *path, req *r);
/* The kind of work a route's compute slot does, for subdivd_compute_seconds_total: complex,
 * tags, rules, refine, edit, level, stats, delta, analysis, matrix (else "other"). */
const char *route_kind(const route *rt);
/* A static asset of the web front end (not under /v1/), served by the route below. */
int route_is_static(const char *path);
const route *route_static(void);

/* ---- http.c: reading the request ---- */

const char *http_header(req *r, const char *name);   /* NULL when absent */
const char *http_arg(req *r, const char *key);       /* a query argument, NULL when absent */
const struct sockaddr *http_client_address(req *r); /* NULL when unknown */

/* ---- reply.c: answering ---- */

struct MHD_Response *http_empty(void);
struct MHD_Response *http_static_response(const void *data, size_t n);
/* A response owning `text`, an api_malloc block (api/mem.h) freed with the response. */
struct MHD_Response *http_buffer_response(const char *ctype, char *text, size_t n);
void http_add_header(struct MHD_Response *resp, const char *name, const char *value);
void http_set_etag(struct MHD_Response *resp, uint64_t version);
/* Queue resp with the common headers (CORS, nosniff) and destroy our reference. */
void http_queue(req *r, int status, struct MHD_Response *resp);
/* A JSON body (steals `body`); version > 0 adds an ETag. */
void http_reply_json(req *r, int status, json_t *body, uint64_t version);
/* The same for an answer about the session itself (GET, PATCH /sessions/{id}, GET /export): its
 * version goes out as the ETag even when it is 0, a session that has not changed yet. */
void http_reply_session_json(req *r, int status, json_t *body, uint64_t version);
void http_reply_problem(req *r, const api_problem *p);
/* A JSON answer that carries the session version (member and ETag), or the problem if none. */
void http_reply_versioned(req *r, json_t *j, uint64_t version, const api_problem *p);
void http_fail(req *r, int status, const char *slug, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* What a streamed response reads: `read` fills up to max bytes of buf (0 at the end, -1 on a
 * failure, which cuts the response short); `close` frees ctx. */
typedef struct http_source {
    void *ctx;
    ssize_t (*read)(void *ctx, char *buf, size_t max);
    void (*close)(void *ctx);
} http_source;

/* 200 with a stream (size or UINT64_MAX: chunked; disposition may be NULL) that holds m and r
 * until its last byte, then closes the source. On failure everything is released and a 503
 * queued. */
void http_reply_stream(req *r, api_model *m, http_source src, uint64_t size, const char *ctype,
                       const char *disposition, uint64_t version);

/* 200 with a text/event-stream of listener l (server/events.h), read in this connection's
 * thread until the stream ends (heartbeats every cfg.sse_heartbeat_s); ev_unlisten when the
 * response goes. On failure l is released and a 503 queued. */
struct ev_listener;
void http_reply_events(req *r, struct ev_listener *l);

/* The headers every answer carries (CORS, nosniff): their number, at most 4 — for answers
 * written on the socket itself (a chunked body over the limit, http.c). */
typedef struct http_header_pair {
    const char *name, *value;
} http_header_pair;
int http_common_header_list(const req *r, http_header_pair out[4]);
/* The problem+json response of p (a refusal of the memory budget gets its Retry-After). */
struct MHD_Response *http_problem_response(req *r, const api_problem *p);

/* ---- http.c: a request's end ---- */

/* Drop a reference on r; the last frees it (and trims the heap after a big request). */
void http_req_unref(req *r);
/* Let the request's session go (r->s NULL after): its use ends (store_unuse) if it counted. */
void http_session_done(req *r);

/* ---- http.c: compute slots ---- */

/* Take one of cfg.threads compute slots, waiting at most queue_timeout_s; -1 + a 429 problem. */
int http_take_slot(req *r, api_problem *p);
void http_give_slot(req *r);

#endif
