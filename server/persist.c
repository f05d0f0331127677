/* persist.c — the durable session store's front (persist.h): the spec parsed, the calls
 * dispatched to the back end, and the last failure remembered for /readyz. The memory store is
 * here too: it has nothing to write, so every call succeeds and loads find nothing.
 */
#include "persist_impl.h"
#include <assert.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

struct persist {
    persist_kind kind;
    char name[256];
    const persist_ops *ops;
    void *b;
    pthread_mutex_t mu;       /* the health fields */
    bool failing;
    double failed_at;         /* monotonic seconds of the last failure */
    char why[256];            /* where and what (the log) */
    char what[256];           /* what alone (answers: a client is not told the file or server) */
};

static double mono(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

persist *persist_open(const char *spec, bool sync_full, char *err, size_t cap)
{
    persist *p = calloc(1, sizeof *p);
    if (!p) {
        snprintf(err, cap, "out of memory");
        return NULL;
    }
    pthread_mutex_init(&p->mu, NULL);
    snprintf(p->name, sizeof p->name, "%s", spec);
    if (!strcmp(spec, "memory")) {
        p->kind = PERSIST_MEMORY;
        return p;
    }
    if (!strncmp(spec, "sqlite:", 7)) {
        if (!spec[7]) {
            snprintf(err, cap, "--store sqlite:PATH needs a file path");
            free(p);
            return NULL;
        }
        p->kind = PERSIST_SQLITE;
        p->ops = &persist_sqlite_ops;
        p->b = persist_sqlite_open(spec + 7, sync_full, err, cap);
    } else if (!strncmp(spec, "redis://", 8)) {
        char host[200];
        int port = 6379;
        const char *h = spec + 8, *colon = strrchr(h, ':');
        size_t n = colon ? (size_t)(colon - h) : strlen(h);
        if (colon) {
            char *end;
            long v = strtol(colon + 1, &end, 10);
            if (*end || v < 1 || v > 65535) {
                snprintf(err, cap, "--store %s: the port must be 1-65535", spec);
                free(p);
                return NULL;
            }
            port = (int)v;
        }
        if (!n || n >= sizeof host || memchr(h, '@', n) || memchr(h, '/', n)) {
            snprintf(err, cap, "--store %s: expected redis://HOST:PORT", spec);
            free(p);
            return NULL;
        }
        memcpy(host, h, n);
        host[n] = 0;
        p->kind = PERSIST_REDIS;
        p->ops = &persist_redis_ops;
        p->b = persist_redis_open(host, port, err, cap);
    } else {
        snprintf(err, cap, "--store %s: expected memory, sqlite:PATH or redis://HOST:PORT", spec);
        free(p);
        return NULL;
    }
    if (!p->b) {
        pthread_mutex_destroy(&p->mu);
        free(p);
        return NULL;
    }
    return p;
}

void persist_close(persist *p)
{
    if (!p)
        return;
    if (p->ops)
        p->ops->close(p->b);
    pthread_mutex_destroy(&p->mu);
    free(p);
}

persist_kind persist_kind_of(const persist *p) { return p->kind; }
const char *persist_kind_name(const persist *p)
{
    return p->kind == PERSIST_SQLITE ? "sqlite" : p->kind == PERSIST_REDIS ? "redis" : "memory";
}
const char *persist_name(const persist *p) { return p->name; }
bool persist_shared(const persist *p) { return p->kind == PERSIST_REDIS; }
bool persist_durable(const persist *p) { return p->kind != PERSIST_MEMORY; }

/* Remember how the last call went: an unavailable store makes the daemon not ready until a
 * write succeeds again (a read that works says nothing of a full disk). */
static persist_rc noted_as(persist *p, persist_rc rc, bool write)
{
    pthread_mutex_lock(&p->mu);
    if (rc == PERSIST_UNAVAILABLE) {
        p->failing = true;
        p->failed_at = mono();
        snprintf(p->why, sizeof p->why, "%s", p->ops->last_error(p->b));
        snprintf(p->what, sizeof p->what, "%s", p->ops->last_what(p->b));
    } else if (write && rc == PERSIST_OK)
        p->failing = false;
    pthread_mutex_unlock(&p->mu);
    return rc;
}
#define noted(p, rc) noted_as(p, rc, true)
#define noted_read(p, rc) noted_as(p, rc, false)

persist_rc persist_create(persist *p, const persist_meta *m)
{
    return p->ops ? noted(p, p->ops->create(p->b, m)) : PERSIST_OK;
}

persist_rc persist_snapshot(persist *p, const char *id, uint64_t expect, uint64_t version,
                            int64_t expires_at, const char *doc, size_t len)
{
    return p->ops ? noted(p, p->ops->snapshot(p->b, id, expect, version, expires_at, doc, len))
                  : PERSIST_OK;
}

persist_rc persist_append(persist *p, const char *id, uint64_t expect, uint64_t version,
                          int64_t expires_at, const char *entry, size_t len)
{
    return p->ops ? noted(p, p->ops->append(p->b, id, expect, version, expires_at, entry, len))
                  : PERSIST_OK;
}

persist_rc persist_touch(persist *p, const char *id, int64_t expires_at)
{
    return p->ops ? noted(p, p->ops->touch(p->b, id, 0, expires_at)) : PERSIST_OK;
}

persist_rc persist_retime(persist *p, const char *id, int ttl_s, int64_t expires_at)
{
    assert(ttl_s > 0); /* 0 means "keep" to the back ends */
    return p->ops ? noted(p, p->ops->touch(p->b, id, ttl_s, expires_at)) : PERSIST_OK;
}

persist_rc persist_delete(persist *p, const char *id)
{
    return p->ops ? noted(p, p->ops->del(p->b, id)) : PERSIST_OK;
}

persist_rc persist_version(persist *p, const char *id, uint64_t *version, int *ttl_s)
{
    return p->ops ? noted_read(p, p->ops->version(p->b, id, version, ttl_s)) : PERSIST_ABSENT;
}

persist_rc persist_load(persist *p, const char *id, persist_loaded *out)
{
    memset(out, 0, sizeof *out);
    if (!p->ops)
        return PERSIST_ABSENT;
    persist_rc rc = noted_read(p, p->ops->load(p->b, id, out));
    if (rc != PERSIST_OK && rc != PERSIST_ABSENT)
        snprintf(out->why, sizeof out->why, "%s", p->ops->last_error(p->b));
    return rc;
}

void persist_loaded_free(persist_loaded *l)
{
    free(l->snapshot);
    for (size_t i = 0; i < l->njournal; i++)
        free(l->journal[i].text);
    free(l->journal);
    l->snapshot = NULL;
    l->journal = NULL;
    l->njournal = 0;
}

long persist_expire(persist *p, int64_t now) { return p->ops ? p->ops->expire(p->b, now) : 0; }
long persist_count(persist *p, int64_t now)
{
    if (!p->ops)
        return 0;
    long n = p->ops->count(p->b, now);
    if (n < 0) /* the store cannot be read: not ready until a probe write succeeds */
        noted_read(p, PERSIST_UNAVAILABLE);
    return n;
}

persist_rc persist_owned(persist *p, const char *owner, int64_t now, long enough, long *n,
                         int64_t *soonest)
{
    *n = 0;
    *soonest = 0;
    return p->ops ? noted_read(p, p->ops->owned(p->b, owner, now, enough, n, soonest)) : PERSIST_OK;
}

persist_rc persist_admit(persist *p, const char *owner, bool hold)
{
    if (!p->ops || !p->ops->admit)
        return PERSIST_OK;
    persist_rc rc = p->ops->admit(p->b, owner, hold);
    return hold ? noted_read(p, rc) : rc;
}

void persist_last_failure(persist *p, char *why, size_t cap)
{
    pthread_mutex_lock(&p->mu);
    snprintf(why, cap, "%s", p->why);
    pthread_mutex_unlock(&p->mu);
}

void persist_last_failure_what(persist *p, char *what, size_t cap)
{
    pthread_mutex_lock(&p->mu);
    snprintf(what, cap, "%s", p->what);
    pthread_mutex_unlock(&p->mu);
}

bool persist_healthy(persist *p, char *why, size_t cap)
{
    pthread_mutex_lock(&p->mu);
    bool probe = p->failing && mono() - p->failed_at > PERSIST_PROBE_AFTER_S;
    pthread_mutex_unlock(&p->mu);
    if (probe) { /* is it back? a real write that names no session */
        pthread_mutex_lock(&p->mu);
        p->failed_at = mono(); /* one probe at a time, every PERSIST_PROBE_AFTER_S */
        pthread_mutex_unlock(&p->mu);
        noted(p, p->ops->probe(p->b));
    }
    pthread_mutex_lock(&p->mu);
    bool ok = !p->failing;
    if (!ok)
        snprintf(why, cap, "%s", p->what);
    pthread_mutex_unlock(&p->mu);
    return ok;
}

const char *persist_rc_name(persist_rc rc)
{
    static const char *const names[] = {"ok", "conflict", "absent", "unavailable", "corrupt"};
    return (unsigned)rc < 5 ? names[rc] : "?";
}
