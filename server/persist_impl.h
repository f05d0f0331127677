/* persist_impl.h — what a back end of persist.h provides (persist.c dispatches and records the
 * last failure for persist_healthy; the back ends only talk to their store). */
#ifndef SUBDIVD_PERSIST_IMPL_H
#define SUBDIVD_PERSIST_IMPL_H

#include "persist.h"

typedef struct persist_ops {
    persist_rc (*create)(void *b, const persist_meta *m);
    persist_rc (*snapshot)(void *b, const char *id, uint64_t expect, uint64_t version,
                           int64_t expires_at, const char *doc, size_t len);
    persist_rc (*append)(void *b, const char *id, uint64_t expect, uint64_t version,
                         int64_t expires_at, const char *entry, size_t len);
    /* ttl_s > 0: the record's TTL becomes it too */
    persist_rc (*touch)(void *b, const char *id, int ttl_s, int64_t expires_at);
    persist_rc (*del)(void *b, const char *id);
    /* *ttl_s (unless NULL): the record's TTL */
    persist_rc (*version)(void *b, const char *id, uint64_t *version, int *ttl_s);
    persist_rc (*load)(void *b, const char *id, persist_loaded *out);
    long (*expire)(void *b, int64_t now);
    /* a real write that names no session (it allocates space, as a change would): does the
     * store take writes again? */
    persist_rc (*probe)(void *b);
    long (*count)(void *b, int64_t now);
    persist_rc (*owned)(void *b, const char *owner, int64_t now, long enough, long *n,
                        int64_t *soonest);
    /* hold (hold true) or let go of the admission of owner's new sessions among every daemon
     * on the store, so that its count (owned) and the create it admits are one step; NULL when
     * the process's own lock is enough (one daemon per store) */
    persist_rc (*admit)(void *b, const char *owner, bool hold);
    /* the back end's own description of its last failure (after a non-OK return), "<where>:
     * <what>" (the file or the server, then what happened); last_what is the <what> alone */
    const char *(*last_error)(void *b);
    const char *(*last_what)(void *b);
    void (*close)(void *b);
} persist_ops;

/* Back ends: open returns the handle, or NULL with a message. */
void *persist_sqlite_open(const char *path, bool sync_full, char *err, size_t cap);
extern const persist_ops persist_sqlite_ops;
void *persist_redis_open(const char *host, int port, char *err, size_t cap);
extern const persist_ops persist_redis_ops;

#endif
