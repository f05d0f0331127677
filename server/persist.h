/* persist.h — the durable session store (docs/SERVICE.md "Persistence"), apart from the table of
 * resident sessions (sessions.h).
 *
 * What is stored per session is its control data, never its levels: a small record (id, the
 * SHA-256 of its token, TTL, creation and expiry times, version, the client that created it) and the session's content as a
 * *snapshot* (the export document of api/export.c at some version) followed by a *journal*:
 * the bodies of the edits (PATCH control-points) answered since, one entry per version. Any
 * change other than an edit writes a new snapshot and empties the journal; the daemon also
 * compacts a long journal into a snapshot. Loading a session is importing its snapshot and
 * replaying its journal: edits recompute (DECISIONS 17), so the levels are bit-identical.
 *
 * Every write is a compare-and-set on the stored version: `expect` must be the version in the
 * store, or the write is refused with PERSIST_CONFLICT (another daemon on the same store got
 * there first: the caller answers 412 and drops its resident copy). Back ends:
 *   memory            nothing is written (the default; every call succeeds)
 *   sqlite:PATH       one SQLite file in WAL mode (persist_sqlite.c)
 *   redis://HOST:PORT a redis server shared by several daemons (persist_redis.c)
 * All functions are thread-safe (each back end serialises its own connection).
 */
#ifndef SUBDIVD_PERSIST_H
#define SUBDIVD_PERSIST_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef enum persist_rc {
    PERSIST_OK = 0,
    PERSIST_CONFLICT,     /* the stored version is not `expect` */
    PERSIST_ABSENT,       /* no such session (deleted, expired, or never stored) */
    PERSIST_UNAVAILABLE,  /* the store cannot be reached or written (disk full, redis down) */
    PERSIST_CORRUPT       /* what is stored cannot be read back (a damaged record or entry) */
} persist_rc;

#define PERSIST_OWNER_CAP 40 /* 34 hex digits and the NUL, with room */

typedef struct persist_meta {
    char id[33];
    unsigned char token_hash[32]; /* SHA-256 of the bearer token */
    int ttl_s;
    int64_t created;              /* wall clock, seconds since the epoch */
    int64_t expires_at;           /* wall clock; the store forgets the session after it */
    uint64_t version;
    /* the client address that created it (rate.h's key in hex; "" when none is known: a session
     * stored before owners were kept): a client's stored sessions are counted by it */
    char owner[PERSIST_OWNER_CAP];
} persist_meta;

/* One journal entry: the edit that made `version`. */
typedef struct persist_entry {
    uint64_t version;
    char *text;                   /* malloc'd, NUL-terminated */
    size_t len;
} persist_entry;

/* What persist_load returns: the record, the snapshot (NULL when none was written yet: an empty
 * session) with the version it was taken at, and the journal entries after it in version order. */
typedef struct persist_loaded {
    persist_meta meta;
    char *snapshot;               /* malloc'd, NUL-terminated, or NULL */
    size_t snapshot_len;
    uint64_t snapshot_version;
    persist_entry *journal;       /* malloc'd array */
    size_t njournal;
    char why[320];                /* after a failure: what the back end said */
    bool record_ok;               /* the record (token hash, expiry) was read whole and is not
                                     expired, even when the content is damaged (PERSIST_CORRUPT):
                                     the holder of the token may still delete the session */
} persist_loaded;

typedef enum persist_kind { PERSIST_MEMORY, PERSIST_SQLITE, PERSIST_REDIS } persist_kind;

typedef struct persist persist;

/* Open the store named by `spec` ("memory", "sqlite:PATH", "redis://HOST:PORT"); sync_full asks
 * for fsync at every commit (SQLite synchronous=FULL: survives power loss, not only a crash).
 * NULL with a message in err on failure (a bad spec, an unreadable file). */
persist *persist_open(const char *spec, bool sync_full, char *err, size_t cap);
void persist_close(persist *p);
persist_kind persist_kind_of(const persist *p);
/* The spec as given, for the log (a redis URL without credentials). */
const char *persist_name(const persist *p);
/* "memory", "sqlite" or "redis": what answers say (/readyz), never the file or the server. */
const char *persist_kind_name(const persist *p);
/* Several daemons may share it: every request checks the stored version (persist_version). */
bool persist_shared(const persist *p);
/* Anything is written at all (not the memory store). */
bool persist_durable(const persist *p);

/* A new session: its record at version 0, no snapshot. PERSIST_CONFLICT if the id exists. */
persist_rc persist_create(persist *p, const persist_meta *m);
/* The session's content at `version` as a snapshot (the journal emptied), if the stored version
 * is `expect` (expect == version: a compaction). */
persist_rc persist_snapshot(persist *p, const char *id, uint64_t expect, uint64_t version,
                            int64_t expires_at, const char *doc, size_t len);
/* Append the edit that made `version` (= expect + 1) to the journal, if the stored version is
 * `expect`. */
persist_rc persist_append(persist *p, const char *id, uint64_t expect, uint64_t version,
                          int64_t expires_at, const char *entry, size_t len);
/* Move the expiry (the session was used). */
persist_rc persist_touch(persist *p, const char *id, int64_t expires_at);
/* A new TTL (PATCH /v1/sessions/{id}) and the expiry it gives. */
persist_rc persist_retime(persist *p, const char *id, int ttl_s, int64_t expires_at);
persist_rc persist_delete(persist *p, const char *id);
/* The stored version and (unless NULL) TTL (shared stores call it per request: another daemon
 * may have changed either); PERSIST_ABSENT when gone. */
persist_rc persist_version(persist *p, const char *id, uint64_t *version, int *ttl_s);
/* Everything needed to rebuild the session (free with persist_loaded_free). An expired session
 * is PERSIST_ABSENT. */
persist_rc persist_load(persist *p, const char *id, persist_loaded *out);
void persist_loaded_free(persist_loaded *l);
/* Forget sessions whose expiry is before `now`; returns how many went (or -1). */
long persist_expire(persist *p, int64_t now);
/* How many unexpired stored sessions `owner` created (*n), and the soonest expiry among them
 * (*soonest, wall clock; 0 when none). The count stops at `enough` (> 0) when the store would
 * have to look further (redis checks each session it counts). */
persist_rc persist_owned(persist *p, const char *owner, int64_t now, long enough, long *n,
                         int64_t *soonest);
/* Hold (hold true) or let go of the admission of `owner`'s new sessions among every daemon on
 * a shared store: between the two, its count (persist_owned) and the create that count admits
 * are one step for all of them (redis: a key held with an expiry, waited for). PERSIST_OK at
 * once when the store is not shared. */
persist_rc persist_admit(persist *p, const char *owner, bool hold);
/* Stored unexpired sessions (-1 if the store cannot say: then unavailable, as persist_healthy
 * tells, until a probe write succeeds). */
long persist_count(persist *p, int64_t now);
/* Can the store be written? false with the reason (the last failure) in why: after a write or
 * read the store refused for want of space or of a connection, until a probe write succeeds
 * (tried at most every PERSIST_PROBE_AFTER_S seconds). */
#define PERSIST_PROBE_AFTER_S 5.0
bool persist_healthy(persist *p, char *why, size_t cap);
/* The last failure: where and what (for the log), and what alone (for an answer: a client is
 * not told the store's file or server). persist_healthy's `why` is the latter. */
void persist_last_failure(persist *p, char *why, size_t cap);
void persist_last_failure_what(persist *p, char *what, size_t cap);
/* "ok", "conflict", … (the log). */
const char *persist_rc_name(persist_rc rc);

#endif
