/* sessions.h — the in-memory session store of the daemon.
 *
 * A session is an unguessable id (128 random bits, hex) plus a bearer token (256 random bits,
 * base64url) and the session's current api_model. Sessions are reference counted: the store
 * holds one reference, every request in flight another, so deleting or expiring a session while
 * one of its levels is still streaming is safe. Locking: `mu` guards the few fields that change
 * (model pointer, version, expiry; held for microseconds), `write` serialises the requests that
 * change the session (held while the new model is built), and computation happens under the
 * model's own lock — so one session's long computation never blocks another session, nor the
 * reads of its own already computed levels.
 */
#ifndef SUBDIVD_SESSIONS_H
#define SUBDIVD_SESSIONS_H

#include "../api/limits.h"
#include "../api/model.h"
#include "persist.h"
#include "rate.h"
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <time.h>

typedef struct session {
    atomic_int refs;
    char id[33];
    char token[48];           /* only when created here (the answer of POST /v1/sessions) */
    unsigned char token_hash[32]; /* SHA-256 of the token: what is compared, and stored */
    pthread_mutex_t mu;       /* model, version, ttl, last_used */
    pthread_mutex_t write;    /* serialises changes */
    api_model *model;
    uint64_t version;
    _Atomic int ttl_s;        /* idle TTL, seconds (store_retime changes it) */
    double last_used;         /* monotonic seconds: when a request last came or ended (mu) */
    atomic_int in_use;        /* requests of its holder handled or still streaming (event
                                 streams aside): it does not expire meanwhile */
    time_t created;
    rate_key owner;           /* the client address that created it (has_owner) */
    bool has_owner;           /* created here (a session loaded from the store has none) */
    struct ev_hub *events;    /* its Server-Sent Events (events.h), told when it leaves the store */
    uint32_t journal_len;     /* edits in the durable store's journal since its snapshot (write lock) */
    double touched;           /* monotonic time the durable store last got its expiry (mu) */
    /* progress of a computation in this session, readable without a lock */
    atomic_int busy_level;    /* -1 when idle */
    _Atomic double busy_since;
} session;

typedef struct store store;

/* The table of resident sessions over a durable store (persist.h; the store is borrowed, and
 * may be the memory store). With a durable store, a session that is not resident is loaded from
 * it on first use (its snapshot imported, its journal replayed within `lim`), and resident
 * sessions that are idle may leave the table to make room: the store has them. */
store *store_new(int max_sessions, persist *p, const api_limits *lim);
void store_free(store *st);

/* What store_create did to find room, or why there was none. */
typedef struct store_admission {
    int evicted;              /* an empty idle session went to make room */
    int evicted_own;          /* ... one of the creating client's, for its share */
    int retry_after_s;        /* refused, the table full: seconds until the soonest expiry (>= 1) */
    int client_full;          /* refused: the creating client holds its maximum of sessions
                                 (retry_after_s: until the soonest of theirs expires) */
    int client_stored_full;   /* refused: the durable store holds the client's maximum of
                                 stored sessions (retry_after_s likewise) */
    persist_rc stored;        /* refused by the durable store (PERSIST_UNAVAILABLE ...), else OK */
} store_admission;

/* Create a session (new reference) for a client (`owner`, may be NULL) that may hold at most
 * `per_client` resident sessions (0: any number). When the table is full, sessions past their
 * TTL go first, then the least recently used idle session that never received a complex (none
 * with a request or a stream in flight: the store holds its only reference; with a durable
 * store any idle one, the store keeps it); NULL when none can go (or out of memory: then
 * retry_after_s is 0). When the client holds its maximum, expired sessions go, then its own
 * least recently used idle one (as above), else refused with client_full. With a durable store
 * the client may also have at most `stored_per_client` unexpired sessions in the store (0: any
 * number; idle ones leave memory but stay there), else refused with client_stored_full; the
 * count and the stored record it admits are one step per client, for all the daemons of a shared
 * store (concurrent creates wait: persist_admit). */
session *store_create(store *st, int ttl_s, const rate_key *owner, int per_client,
                          int stored_per_client, store_admission *a);
/* Why store_get found nothing. */
typedef enum store_miss {
    STORE_NONE = 0,           /* no such session (never, expired, deleted) */
    STORE_UNAVAILABLE,        /* the durable store cannot be read now */
    STORE_CORRUPT,            /* the stored session cannot be rebuilt (damaged data) */
    STORE_DAMAGED,            /* the same, but its record is whole and the token given is its own
                                 (or no token is asked for): it may still be deleted */
    STORE_BUSY,               /* stored and whole, but rebuilding it needs memory that is in use
                                 now (its import or a replayed edit was a 503): retry */
    STORE_OVER_LIMITS,        /* stored and whole, but rebuilding it needs more than this daemon's
                                 limits allow (a 413: a move at a level over --max-cells, say);
                                 its holder may still delete it */
    STORE_FULL,               /* stored, but no room to make it resident (every session busy) */
    STORE_UNAUTHORIZED        /* stored, but the token given is not its own (nothing was loaded) */
} store_miss;

/* The live session with this id (new reference) or NULL with *miss (may be NULL) and, for
 * STORE_CORRUPT, STORE_DAMAGED, STORE_BUSY, STORE_OVER_LIMITS and STORE_UNAVAILABLE, the reason in why (cap bytes; may be NULL; for the log,
 * not for clients). Touches its idle clock (and, now and then, its expiry in the durable store).
 * A session that is not resident is loaded only for the holder of its `token` (NULL: anyone,
 * --no-auth); a resident one is returned whatever the token (the caller checks it). With a
 * shared store, a resident copy older than the stored version is dropped and loaded again. */
session *store_get(store *st, const char *id, const char *token, store_miss *miss, char *why,
                   size_t cap);
/* Forget the resident copy of s (the durable store has the truth: after a write it refused, or
 * lost to another daemon); the next request loads it again. Its listeners' streams end: with
 * `event: deleted` ("deleted") when `gone` (the store no longer has it), else without an event
 * (they reconnect with Last-Event-ID to the copy loaded again). */
void store_drop(store *st, session *s, bool gone);
persist *store_persist(store *st);
/* Remove from the store (the session lives on until its last reference goes). 0 if absent. */
int store_remove(store *st, session *s);
/* Remove sessions idle for longer than their TTL; returns how many went. */
int store_expire(store *st, double now);
int store_count(store *st);
/* Call fn for every live session under the store lock (metrics). */
void store_foreach(store *st, void (*fn)(session *s, void *ud), void *ud);

/* A request of s's holder starts (session_use) and ends, its answer sent (store_unuse): while
 * one is in flight s does not expire, and its idle TTL counts from the end of the last one (with
 * a durable store, the stored expiry follows as store_get's touches do). */
void session_use(session *s);
void store_unuse(store *st, session *s);

void session_unref(session *s);
/* The current model and version (model: new reference). */
api_model *session_model(session *s, uint64_t *version);
/* Publish a new model (the session takes the reference); returns the new version. */
uint64_t session_publish(session *s, api_model *m);
/* Give a new session (nobody else holds it yet) its first model at `version` (an import). */
void session_adopt(session *s, api_model *m, uint64_t version);
/* Raise the version after an in-place change of the current model; returns it. */
uint64_t session_bump(session *s);
/* Expiry time (wall clock, seconds since the epoch). */
time_t session_expires_at(session *s);
/* The expiry to store with a change made now: now + TTL (wall clock). */
int64_t session_stored_expiry(session *s);
/* A new idle TTL for s, counted from now: the durable store's record first (its ttl_s and
 * expiry), then the resident session. Not PERSIST_OK: nothing changed. */
persist_rc store_retime(store *st, session *s, int ttl_s);

/* Constant-time comparison of a presented token with the session's. */
int session_token_ok(const session *s, const char *presented);

double mono_now(void);

#endif
