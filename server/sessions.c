/* sessions.c — session ids, tokens, the store and expiry (see sessions.h).
 *
 * Ids and tokens come from getrandom(); the store is a fixed array of at most max_sessions
 * resident sessions, searched linearly under its mutex (tens of sessions, held for
 * microseconds). A session leaves the store on DELETE, expiry or eviction but lives until its
 * last reference goes, so requests and streams in flight keep a valid session and model. A full
 * table makes room from sessions that hold nothing: expired ones, then empty idle ones (an
 * unauthenticated client can create sessions, so empty ones must not lock the table). Tokens are
 * compared in constant time.
 */
#include "sessions.h"
#include "events.h"
#include "../api/mem.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>

struct store {
    pthread_mutex_t mu;
    int cap, n;
    session **s;
};

double mono_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int random_bytes(unsigned char *b, size_t n)
{
    while (n) {
        ssize_t r = getrandom(b, n, 0);
        if (r < 0)
            return -1;
        b += r;
        n -= (size_t)r;
    }
    return 0;
}

store *store_new(int max_sessions)
{
    store *st = api_calloc(1, sizeof *st);
    if (!st)
        return NULL;
    st->cap = max_sessions;
    st->s = api_calloc((size_t)max_sessions, sizeof *st->s);
    if (!st->s) {
        api_free(st);
        return NULL;
    }
    pthread_mutex_init(&st->mu, NULL);
    return st;
}

void store_free(store *st)
{
    if (!st)
        return;
    for (int i = 0; i < st->n; i++)
        session_unref(st->s[i]);
    pthread_mutex_destroy(&st->mu);
    api_free(st->s);
    api_free(st);
}

static int remove_at(store *st, int i, const char *why);

/* Remove the sessions idle past their TTL (none computing). Caller holds st->mu. */
static int expire_locked(store *st, double now)
{
    int gone = 0;
    for (int i = 0; i < st->n;) {
        session *s = st->s[i];
        pthread_mutex_lock(&s->mu);
        int idle = now - s->last_used > s->ttl_s && atomic_load(&s->busy_level) < 0;
        pthread_mutex_unlock(&s->mu);
        if (idle)
            gone += remove_at(st, i, "expired");
        else
            i++;
    }
    return gone;
}

/* Remove the least recently used session that never received a complex and that nobody else
 * holds (no request or stream in flight: store_get takes its reference under st->mu, which the
 * caller holds). 1 if one went. */
static int evict_empty_locked(store *st)
{
    int best = -1;
    double best_used = 0;
    for (int i = 0; i < st->n; i++) {
        session *s = st->s[i];
        if (atomic_load(&s->refs) != 1 || atomic_load(&s->busy_level) >= 0)
            continue;
        pthread_mutex_lock(&s->mu);
        int empty = !s->model->c;
        double used = s->last_used;
        pthread_mutex_unlock(&s->mu);
        if (empty && (best < 0 || used < best_used)) {
            best = i;
            best_used = used;
        }
    }
    return best >= 0 ? remove_at(st, best, "evicted") : 0;
}

/* Seconds until the soonest expiry of a resident session (>= 1). Caller holds st->mu. */
static int soonest_expiry_locked(store *st, double now)
{
    double soonest = -1;
    for (int i = 0; i < st->n; i++) {
        session *s = st->s[i];
        pthread_mutex_lock(&s->mu);
        double left = s->ttl_s - (now - s->last_used);
        pthread_mutex_unlock(&s->mu);
        if (soonest < 0 || left < soonest)
            soonest = left;
    }
    double c = ceil(soonest);
    return c < 1 ? 1 : c > 1e9 ? 1000000000 : (int)c;
}

session *store_create(store *st, int ttl_s, store_admission *a)
{
    memset(a, 0, sizeof *a);
    unsigned char rid[16], rtok[32];
    if (random_bytes(rid, sizeof rid) || random_bytes(rtok, sizeof rtok))
        return NULL;
    session *s = api_calloc(1, sizeof *s);
    if (!s)
        return NULL;
    sd_error e;
    s->model = api_model_new(NULL, NULL, 0, &e);
    s->events = s->model ? ev_hub_new() : NULL;
    if (!s->events) {
        api_model_unref(s->model);
        api_free(s);
        return NULL;
    }
    for (int i = 0; i < 16; i++)
        sprintf(s->id + 2 * i, "%02x", rid[i]);
    static const char b64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
    int k = 0; /* 32 bytes -> 43 base64url characters, no padding */
    for (int i = 0; i < 32; i += 3) {
        uint32_t v = (uint32_t)rtok[i] << 16 | (i + 1 < 32 ? (uint32_t)rtok[i + 1] << 8 : 0) |
                     (i + 2 < 32 ? rtok[i + 2] : 0);
        int nch = i + 2 < 32 ? 4 : 3;
        for (int j = 0; j < nch; j++)
            s->token[k++] = b64[(v >> (18 - 6 * j)) & 63];
    }
    s->token[k] = 0;
    atomic_init(&s->refs, 2); /* the store's and the caller's */
    pthread_mutex_init(&s->mu, NULL);
    pthread_mutex_init(&s->write, NULL);
    s->ttl_s = ttl_s;
    s->last_used = mono_now();
    s->created = time(NULL);
    atomic_init(&s->busy_level, -1);
    pthread_mutex_lock(&st->mu);
    double now = mono_now();
    if (st->n >= st->cap)
        expire_locked(st, now);
    if (st->n >= st->cap)
        a->evicted = evict_empty_locked(st);
    if (st->n >= st->cap) {
        a->retry_after_s = soonest_expiry_locked(st, now);
        pthread_mutex_unlock(&st->mu);
        atomic_store(&s->refs, 1);
        session_unref(s);
        return NULL;
    }
    st->s[st->n++] = s;
    pthread_mutex_unlock(&st->mu);
    return s;
}

session *store_get(store *st, const char *id)
{
    session *found = NULL;
    if (strlen(id) != 32)
        return NULL;
    pthread_mutex_lock(&st->mu);
    for (int i = 0; i < st->n && !found; i++)
        if (!memcmp(st->s[i]->id, id, 32))
            found = st->s[i];
    if (found) {
        atomic_fetch_add(&found->refs, 1);
        pthread_mutex_lock(&found->mu);
        found->last_used = mono_now();
        pthread_mutex_unlock(&found->mu);
    }
    pthread_mutex_unlock(&st->mu);
    return found;
}

/* Take session i out of the store; its event listeners get `event: deleted` with `why`. */
static int remove_at(store *st, int i, const char *why)
{
    session *s = st->s[i];
    ev_close(s->events, why);
    st->s[i] = st->s[--st->n];
    st->s[st->n] = NULL;
    session_unref(s);
    return 1;
}

int store_remove(store *st, session *s)
{
    int done = 0;
    pthread_mutex_lock(&st->mu);
    for (int i = 0; i < st->n && !done; i++)
        if (st->s[i] == s)
            done = remove_at(st, i, "deleted");
    pthread_mutex_unlock(&st->mu);
    return done;
}

int store_expire(store *st, double now)
{
    pthread_mutex_lock(&st->mu);
    int gone = expire_locked(st, now);
    pthread_mutex_unlock(&st->mu);
    return gone;
}

int store_count(store *st)
{
    pthread_mutex_lock(&st->mu);
    int n = st->n;
    pthread_mutex_unlock(&st->mu);
    return n;
}

void store_foreach(store *st, void (*fn)(session *s, void *ud), void *ud)
{
    pthread_mutex_lock(&st->mu);
    for (int i = 0; i < st->n; i++)
        fn(st->s[i], ud);
    pthread_mutex_unlock(&st->mu);
}

void session_unref(session *s)
{
    if (!s || atomic_fetch_sub(&s->refs, 1) != 1)
        return;
    api_model_unref(s->model);
    ev_hub_unref(s->events);
    pthread_mutex_destroy(&s->mu);
    pthread_mutex_destroy(&s->write);
    explicit_bzero(s->token, sizeof s->token);
    api_free(s);
}

api_model *session_model(session *s, uint64_t *version)
{
    pthread_mutex_lock(&s->mu);
    api_model *m = api_model_ref(s->model);
    if (version)
        *version = s->version;
    pthread_mutex_unlock(&s->mu);
    return m;
}

uint64_t session_publish(session *s, api_model *m)
{
    pthread_mutex_lock(&s->mu);
    api_model *old = s->model;
    uint64_t v = ++s->version;
    atomic_store(&m->version, v); /* before anyone can read m */
    s->model = m;
    pthread_mutex_unlock(&s->mu);
    api_model_unref(old);
    return v;
}

void session_adopt(session *s, api_model *m, uint64_t version)
{
    pthread_mutex_lock(&s->mu);
    api_model *old = s->model;
    s->version = version;
    atomic_store(&m->version, version);
    s->model = m;
    pthread_mutex_unlock(&s->mu);
    api_model_unref(old);
}

uint64_t session_bump(session *s)
{
    pthread_mutex_lock(&s->mu);
    uint64_t v = ++s->version;
    pthread_mutex_unlock(&s->mu);
    return v;
}

time_t session_expires_at(session *s)
{
    pthread_mutex_lock(&s->mu);
    time_t t = time(NULL) + (time_t)(s->ttl_s - (mono_now() - s->last_used));
    pthread_mutex_unlock(&s->mu);
    return t;
}

int session_token_ok(const session *s, const char *presented)
{
    size_t n = strlen(s->token);
    if (!presented || strlen(presented) != n)
        return 0;
    unsigned char d = 0;
    for (size_t i = 0; i < n; i++)
        d |= (unsigned char)(s->token[i] ^ presented[i]);
    return d == 0;
}
