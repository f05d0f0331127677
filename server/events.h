/* events.h — Server-Sent Events of one session (GET /v1/sessions/{id}/events).
 *
 * A hub per session holds the text of its recent events (a bounded ring, for Last-Event-ID
 * replay) and its listeners. Publishing copies an event into the ring and into every listener's
 * bounded buffer and wakes them: it takes the hub's mutex for a memcpy and never waits for a
 * client. A listener whose buffer would overflow (a client that does not read) is dropped: its
 * stream ends, and the browser's EventSource reconnects with Last-Event-ID and is replayed what
 * it missed, or told `event: resync` when the ring no longer holds it. A listener's reader runs
 * in its connection's own thread (libmicrohttpd thread-per-connection) and blocks there on the
 * hub's condition variable, waking for events, for heartbeats (a comment line every
 * `heartbeat_s`) and for the end (`event: deleted` when the session is deleted or expires; no
 * event when the daemon drops its copy of a session to load it again from the store).
 */
#ifndef SUBDIVD_EVENTS_H
#define SUBDIVD_EVENTS_H

#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#define EV_RING 256               /* events kept for replay */
#define EV_LISTENER_BYTES 65536   /* a listener's buffer: more unread and it is dropped */
#define EV_SOCKET_BYTES 16384     /* SO_SNDBUF of an event stream's socket (Linux doubles it) */

typedef struct ev_hub ev_hub;
typedef struct ev_listener ev_listener;

/* A hub (one reference, for its owner). NULL for lack of memory. */
ev_hub *ev_hub_new(void);
ev_hub *ev_hub_ref(ev_hub *h);
void ev_hub_unref(ev_hub *h);

/* Publish one event: `id: version`, `event: name`, `data: data` (one line of JSON). Copies. */
void ev_publish(ev_hub *h, uint64_t version, const char *name, const char *data);
/* The session is gone: every listener gets `event: deleted` (data: {"reason": why}) and its
 * stream ends; later listeners get the same at once. With why NULL (the session is not gone: this
 * daemon dropped its copy, to load it again from the durable store) the streams end without an
 * event, and the clients reconnect with Last-Event-ID to the copy loaded again. */
void ev_close(ev_hub *h, const char *why);

/* A new listener, unless the hub has `max` already (*full set) or there is no memory (NULL).
 * Its stream starts with a comment naming current_version (so the response's headers go out at
 * once); with has_last (the client sent Last-Event-ID: last), the events after `last` are
 * replayed next, or `event: resync` is sent when some of them are no longer kept (or last is
 * ahead of the newest). */
ev_listener *ev_listen(ev_hub *h, int has_last, uint64_t last, uint64_t current_version,
                       unsigned max, int *full);
/* Up to max bytes of the stream into buf, waiting for something to send (an event, a heartbeat
 * comment after heartbeat_s seconds of silence, or the end). Returns the bytes, or -1 at the end
 * of the stream (closed, dropped, the daemon stopping: ev_stop_all, or the client gone: `fd`, the
 * connection's socket or -1, hung up — looked at every half second while waiting, so a listener
 * that went away frees its place within a second instead of at the next writes). */
ssize_t ev_read(ev_listener *l, char *buf, size_t max, double heartbeat_s, int fd);
void ev_unlisten(ev_listener *l);

/* Listeners now open, and dropped ones since the start (metrics). */
void ev_stats(unsigned *listeners, uint64_t *dropped);
/* Wake every reader and end every stream (daemon shutdown). */
void ev_stop_all(void);

#endif
