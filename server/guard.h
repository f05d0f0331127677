/* guard.h — connection slots under hostile clients: deadlines, per-client caps, eviction.
 *
 * libmicrohttpd runs one thread per connection and offers an idle timeout, a global and a
 * per-address connection limit. An idle timeout does not stop a client that sends its headers
 * one byte a second (slowloris), and a full table of such sockets, or of idle keep-alive ones,
 * locks everybody out, health checks included. The guard keeps a record of every connection
 * (MHD's connection notifications), knows which phase it is in, and enforces on top of MHD:
 *
 *   WAIT     waiting for request headers: a new connection must complete them within
 *            header_timeout_s; a kept-alive one between requests within idle_timeout_s.
 *   BODY     receiving a body: it must arrive at body_min_rate bytes/s on average, after a
 *            grace of header_timeout_s.
 *   WORK     a handler runs or a response is being sent: no deadline here (MHD's idle timeout
 *            closes a client that stops reading).
 *
 * Under pressure — more than max_connections - reserve connections open — a connection being
 * accepted evicts the connection that has been waiting longest (WAIT phase, preferring the
 * address with most connections), and WAIT deadlines shrink to one second. So a flood of slow or
 * idle sockets keeps turning over while a client that sends a whole request at once is served:
 * /healthz and authenticated clients get through. A connection is closed by shutdown(2) on its
 * socket from the guard's reaper thread (or the accept callback); MHD then sees the end of the
 * stream and cleans up as for any client that went away. All of it runs under one mutex; the
 * table is as large as MHD's connection limit, and each scan is linear in it.
 *
 * The per-address cap is MHD's own (MHD_OPTION_PER_IP_CONNECTION_LIMIT), applied before the
 * accept callback. Eviction must happen before MHD's connection limit is reached: a connection
 * arriving at the limit is closed by MHD without calling the accept callback — hence the
 * reserve.
 */
#ifndef SUBDIVD_GUARD_H
#define SUBDIVD_GUARD_H

#include <microhttpd.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>

typedef struct guard_config {
    unsigned max_connections;     /* MHD's connection limit */
    unsigned reserve;             /* slots kept free for eviction under pressure */
    double header_timeout_s;      /* a new connection's request headers */
    double idle_timeout_s;        /* a kept-alive connection between requests */
    double body_min_rate;         /* bytes/s a body must average (0 = no minimum) */
} guard_config;

typedef struct guard guard;
typedef struct guard_conn guard_conn;

guard *guard_new(const guard_config *cfg);
/* Stops the reaper; call after MHD_stop_daemon (every connection has gone). */
void guard_free(guard *g);

/* MHD hooks: MHD_start_daemon(…, apc = guard_accept, g, …, MHD_OPTION_NOTIFY_CONNECTION,
 * guard_notify, g, MHD_OPTION_UNESCAPE_CALLBACK, guard_unescape, g, …). */
enum MHD_Result guard_accept(void *cls, const struct sockaddr *addr, socklen_t len);
void guard_notify(void *cls, struct MHD_Connection *c, void **socket_context,
                  enum MHD_ConnectionNotificationCode code);
/* Percent-decoding of the path and query (as MHD's own), which also notes a decoded NUL byte
 * in the connection's record so the request can be refused (guard_request_had_nul). */
size_t guard_unescape(void *cls, struct MHD_Connection *c, char *s);

/* The record of a connection (NULL if unknown). */
guard_conn *guard_conn_of(struct MHD_Connection *c);
/* A request's headers are complete; it has a body of content_length bytes (UINT64_MAX: chunked,
 * 0: none). */
void guard_request_begin(guard *g, guard_conn *k, uint64_t content_length);
/* n more body bytes arrived. */
void guard_body_progress(guard *g, guard_conn *k, size_t n);
/* The body is complete: the handler runs (no deadline until the response is done). */
void guard_request_work(guard *g, guard_conn *k);
/* The response is done: the connection waits for its next request (or closes). */
void guard_request_done(guard *g, guard_conn *k);
/* A NUL byte was decoded in this request's path or query. */
int guard_request_had_nul(const guard_conn *k);

/* Figures for /metrics. */
typedef struct guard_stats {
    unsigned open, waiting, receiving, working;
    uint64_t evicted, header_timeouts, body_timeouts, idle_timeouts;
} guard_stats;
void guard_get_stats(guard *g, guard_stats *out);

#endif
