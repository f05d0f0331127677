/* stream.c — responses that are read from a callback after the handler returned: level and
 * complex streams, and Server-Sent Events.
 *
 * A stream (http_reply_stream) reads a source (out_read, api_cstream_read) that holds a reference
 * on the session's model until the last byte is sent, and no lock: the source copied what edits
 * change when it opened. An event stream (http_reply_events) reads a listener of the session's
 * hub (server/events.h): libmicrohttpd calls its reader in the connection's own thread
 * (thread-per-connection, docs/DECISIONS.md 33) when the socket can take more, and the reader
 * blocks there on the hub's condition variable until an event, a heartbeat or the end. A client
 * that does not read never has its reader called: the hub's bounded buffer fills and the
 * listener is dropped, with the socket's own buffer kept small (EV_SOCKET_BYTES) so that this
 * happens after some 100 KiB rather than after megabytes of kernel buffers.
 */
#include "request.h"
#include "events.h"
#include "metrics.h"
#include "../api/mem.h"
#include <microhttpd.h>
#include <sys/socket.h>

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
} events_ctx;

/* Blocks in the connection's own thread until there is something to send (DECISIONS 33). */
static ssize_t events_read(void *cls, uint64_t pos, char *buf, size_t max)
{
    (void)pos;
    events_ctx *ec = cls;
    ssize_t n = ev_read(ec->l, buf, max, ec->r->srv->cfg.sse_heartbeat_s);
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
        *ec = (events_ctx){r, l};
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

