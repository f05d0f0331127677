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
#include "../api/delta.h"
#include "../api/embedded.h"
#include "../api/handlers.h"
#include "../api/mem.h"
#include <limits.h>
#include <math.h>
#include <nettle/sha2.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <time.h>

/* A session's last use to write to the durable store once st->mu is released. */
typedef struct pending_touch {
    char id[33];
    int64_t expires_at;
} pending_touch;

struct store {
    pthread_mutex_t mu;
    int cap, n;
    session **s;
    pending_touch pend[4];    /* made under mu by evictions, written by unlock_store */
    int npend;
    persist *p;               /* the durable store (borrowed) */
    api_limits lim;           /* what a replayed journal may compute */
    pthread_mutex_t load[16]; /* loads from the durable store: one at a time per stripe of ids */
    /* a durable store's count of a client's sessions and the creation it admits, one client at a
     * time per stripe of client keys (two creates counting at once would both see room) */
    pthread_mutex_t admit[16];
};

static void token_hash(const char *token, unsigned char out[32])
{
    struct sha256_ctx c;
    sha256_init(&c);
    sha256_update(&c, strlen(token), (const uint8_t *)token);
    sha256_digest(&c, 32, out);
}

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

store *store_new(int max_sessions, persist *p, const api_limits *lim)
{
    store *st = api_calloc(1, sizeof *st);
    if (!st)
        return NULL;
    st->p = p;
    st->lim = *lim;
    st->cap = max_sessions;
    st->s = api_calloc((size_t)max_sessions, sizeof *st->s);
    if (!st->s) {
        api_free(st);
        return NULL;
    }
    pthread_mutex_init(&st->mu, NULL);
    for (int i = 0; i < 16; i++) {
        pthread_mutex_init(&st->load[i], NULL);
        pthread_mutex_init(&st->admit[i], NULL);
    }
    return st;
}

persist *store_persist(store *st) { return st->p; }

static bool unstored_use(session *s, int64_t *expires_at);

void store_free(store *st)
{
    if (!st)
        return;
    for (int i = 0; i < st->n; i++) {
        session *s = st->s[i]; /* a use since the last stored expiry: stored before stopping */
        int64_t exp;
        if (persist_durable(st->p) && unstored_use(s, &exp))
            persist_touch(st->p, s->id, exp);
        session_unref(s);
    }
    pthread_mutex_destroy(&st->mu);
    for (int i = 0; i < 16; i++) {
        pthread_mutex_destroy(&st->load[i]);
        pthread_mutex_destroy(&st->admit[i]);
    }
    api_free(st->s);
    api_free(st);
}

static int remove_at(store *st, int i, const char *why);

/* Release st->mu, then write the last uses the evictions made under it left (store I/O is never
 * done under st->mu, which every request takes). */
static void unlock_store(store *st)
{
    pending_touch pend[sizeof st->pend / sizeof *st->pend];
    int n = st->npend;
    memcpy(pend, st->pend, (size_t)n * sizeof *pend);
    st->npend = 0;
    pthread_mutex_unlock(&st->mu);
    for (int i = 0; i < n; i++)
        persist_touch(st->p, pend[i].id, pend[i].expires_at);
}

/* How often a session's expiry is written to the durable store for reads alone: a tenth of its
 * TTL, at most a minute. The stored expiry carries as much slack, so the store never forgets a
 * session before the resident copy would expire. */
static double slack_of(int ttl_s)
{
    return ttl_s / 10.0 < 60 ? ttl_s / 10.0 : 60;
}

static double touch_every(const session *s) { return slack_of(s->ttl_s); }

/* The expiry the store is given for a session of TTL ttl_s last used at wall time `used`: the
 * TTL after that use, plus the touches' slack. */
static int64_t stored_expiry(int ttl_s, int64_t used)
{
    return used + ttl_s + (int64_t)ceil(slack_of(ttl_s));
}

/* Whether s was used since its expiry was last stored; *expires_at that use's stored expiry. */
static bool unstored_use(session *s, int64_t *expires_at)
{
    pthread_mutex_lock(&s->mu);
    bool due = s->last_used > s->touched;
    double idle = mono_now() - s->last_used;
    pthread_mutex_unlock(&s->mu);
    *expires_at = stored_expiry(s->ttl_s, (int64_t)time(NULL) - (int64_t)idle);
    return due;
}

/* Remove the sessions idle past their TTL (none with a request in flight: one computing, being
 * changed, or whose answer is still being sent). Caller holds st->mu. */
static int expire_locked(store *st, double now)
{
    int gone = 0;
    for (int i = 0; i < st->n;) {
        session *s = st->s[i];
        pthread_mutex_lock(&s->mu);
        int idle = now - s->last_used > s->ttl_s && atomic_load(&s->busy_level) < 0 &&
                   atomic_load(&s->in_use) == 0;
        pthread_mutex_unlock(&s->mu);
        if (idle)
            gone += remove_at(st, i, "expired");
        else
            i++;
    }
    return gone;
}

/* Whether s was created by the client `owner` (NULL: any session). */
static bool owned_by(const session *s, const rate_key *owner)
{
    return !owner || (s->has_owner && !memcmp(&s->owner, owner, sizeof *owner));
}

/* Remove the least recently used session (of `owner`, unless NULL) that never received a complex
 * (with a durable store: any session, since the store has it) and that nobody else holds (no
 * request or stream in flight: store_get takes its reference under st->mu, which the caller
 * holds). 1 if one went. */
static int evict_empty_locked(store *st, const rate_key *owner)
{
    bool any = persist_durable(st->p);
    int best = -1;
    double best_used = 0;
    for (int i = 0; i < st->n; i++) {
        session *s = st->s[i];
        if (!owned_by(s, owner) || atomic_load(&s->refs) != 1 || atomic_load(&s->busy_level) >= 0)
            continue;
        pthread_mutex_lock(&s->mu);
        int empty = any || !s->model->c;
        double used = s->last_used;
        pthread_mutex_unlock(&s->mu);
        if (empty && (best < 0 || used < best_used)) {
            best = i;
            best_used = used;
        }
    }
    if (best >= 0 && any) { /* a use since the last stored expiry: stored now, so that the
                             * session is not taken for expired when it is loaded again */
        session *s = st->s[best];
        int64_t exp;
        if (unstored_use(s, &exp) && st->npend < (int)(sizeof st->pend / sizeof *st->pend)) {
            pending_touch *t = &st->pend[st->npend++];
            memcpy(t->id, s->id, sizeof t->id);
            t->expires_at = exp;
        }
    }
    return best >= 0 ? remove_at(st, best, any ? NULL : "evicted") : 0; /* stored: not gone */
}

/* Seconds until the soonest expiry of a resident session (of `owner`, unless NULL; >= 1).
 * Caller holds st->mu. */
static int soonest_expiry_locked(store *st, double now, const rate_key *owner)
{
    double soonest = -1;
    for (int i = 0; i < st->n; i++) {
        session *s = st->s[i];
        if (!owned_by(s, owner))
            continue;
        pthread_mutex_lock(&s->mu);
        double left = s->ttl_s - (now - s->last_used);
        pthread_mutex_unlock(&s->mu);
        if (soonest < 0 || left < soonest)
            soonest = left;
    }
    double c = ceil(soonest);
    return c < 1 ? 1 : c > 1e9 ? 1000000000 : (int)c;
}



/* A session struct (reference 1) with an empty model, or NULL for lack of memory. */
static session *session_alloc(const char *id, const unsigned char hash[32], int ttl_s, time_t created)
{
    session *s = api_calloc(1, sizeof *s);
    if (!s)
        return NULL;
    sd_error e;
    s->model = api_model_new(NULL, NULL, 0, false, &e);
    s->events = s->model ? ev_hub_new() : NULL;
    if (!s->events) {
        api_model_unref(s->model);
        api_free(s);
        return NULL;
    }
    memcpy(s->id, id, 32);
    memcpy(s->token_hash, hash, 32);
    atomic_init(&s->refs, 1);
    pthread_mutex_init(&s->mu, NULL);
    pthread_mutex_init(&s->write, NULL);
    s->ttl_s = ttl_s;
    s->last_used = mono_now();
    s->touched = -1e300; /* the first use writes the expiry (a loaded session's may be close) */
    s->created = created;
    atomic_init(&s->busy_level, -1);
    atomic_init(&s->in_use, 0);
    return s;
}

/* How many resident sessions `owner` created. Caller holds st->mu. */
static int count_owned_locked(store *st, const rate_key *owner)
{
    int n = 0;
    for (int i = 0; i < st->n; i++)
        n += owned_by(st->s[i], owner);
    return n;
}

/* Make room for one more resident session (expired ones first, then an idle one that can go),
 * created by `owner` (NULL: a load from the store, which counts for nobody) when that client may
 * hold at most per_client (> 0) of them: beyond, expired sessions go, then its own least
 * recently used idle one, else refused with client_full. Caller holds st->mu; false when there
 * is no room (*retry_after_s then says when the soonest expiry, of the table or of the
 * client's sessions, is). */
static bool room_locked(store *st, const rate_key *owner, int per_client, store_admission *a)
{
    double now = mono_now();
    if (owner && per_client > 0 && count_owned_locked(st, owner) >= per_client) {
        expire_locked(st, now);
        /* sessions loaded back count for their client too: it may hold more than its share */
        while (count_owned_locked(st, owner) >= per_client && evict_empty_locked(st, owner))
            a->evicted = a->evicted_own = 1;
        if (count_owned_locked(st, owner) >= per_client) {
            a->client_full = 1;
            a->retry_after_s = soonest_expiry_locked(st, now, owner);
            return false;
        }
    }
    if (st->n >= st->cap)
        expire_locked(st, now);
    if (st->n >= st->cap)
        a->evicted = evict_empty_locked(st, NULL);
    if (st->n >= st->cap) {
        a->retry_after_s = soonest_expiry_locked(st, now, NULL);
        return false;
    }
    return true;
}

/* A client's key as the store records it (hex). */
static void owner_hex(const rate_key *k, char out[PERSIST_OWNER_CAP])
{
    for (size_t i = 0; i < sizeof k->b; i++)
        sprintf(out + 2 * i, "%02x", k->b[i]);
}

/* The client key a stored owner names (false when it names none, or not one of ours). */
static bool owner_of_hex(const char *hex, rate_key *k)
{
    if (strlen(hex) != 2 * sizeof k->b || strspn(hex, "0123456789abcdef") != 2 * sizeof k->b)
        return false;
    for (size_t i = 0; i < sizeof k->b; i++) {
        unsigned v;
        sscanf(hex + 2 * i, "%2x", &v);
        k->b[i] = (uint8_t)v;
    }
    return true;
}

session *store_create(store *st, int ttl_s, const rate_key *owner, int per_client,
                          int stored_per_client, store_admission *a)
{
    memset(a, 0, sizeof *a);
    unsigned char rid[16], rtok[32], hash[32];
    if (random_bytes(rid, sizeof rid) || random_bytes(rtok, sizeof rtok))
        return NULL;
    char id[33], token[48];
    for (int i = 0; i < 16; i++)
        sprintf(id + 2 * i, "%02x", rid[i]);
    static const char b64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
    int k = 0; /* 32 bytes -> 43 base64url characters, no padding */
    for (int i = 0; i < 32; i += 3) {
        uint32_t v = (uint32_t)rtok[i] << 16 | (i + 1 < 32 ? (uint32_t)rtok[i + 1] << 8 : 0) |
                     (i + 2 < 32 ? rtok[i + 2] : 0);
        int nch = i + 2 < 32 ? 4 : 3;
        for (int j = 0; j < nch; j++)
            token[k++] = b64[(v >> (18 - 6 * j)) & 63];
    }
    token[k] = 0;
    token_hash(token, hash);
    session *s = session_alloc(id, hash, ttl_s, time(NULL));
    if (!s)
        return NULL;
    memcpy(s->token, token, sizeof token);
    explicit_bzero(token, sizeof token);
    if (owner) {
        s->owner = *owner;
        s->has_owner = true;
    }
    char why[8];
    if (persist_durable(st->p) && !persist_healthy(st->p, why, sizeof why)) {
        a->stored = PERSIST_UNAVAILABLE; /* refused before anything resident makes room */
        session_unref(s);
        return NULL;
    }
    char ohex[PERSIST_OWNER_CAP] = "";
    if (owner)
        owner_hex(owner, ohex);
    pthread_mutex_t *admit = NULL;
    if (owner && stored_per_client > 0 && persist_durable(st->p)) {
        /* idle sessions leave memory for the store, so the table's share alone does not bound
         * what one client keeps: the store counts its unexpired ones. The count and the record
         * it admits are one step for this client (another create of it waits here) */
        unsigned stripe = 0;
        for (size_t i = 0; i < sizeof owner->b; i++)
            stripe = stripe * 31 + owner->b[i];
        admit = &st->admit[stripe & 15];
        pthread_mutex_lock(admit);
        long n = 0;
        int64_t soonest = 0, now = (int64_t)time(NULL);
        /* and for every daemon on a shared store (its creates of this client wait there) */
        a->stored = persist_admit(st->p, ohex, true);
        bool held = a->stored == PERSIST_OK;
        if (held)
            a->stored = persist_owned(st->p, ohex, now, stored_per_client, &n, &soonest);
        if (a->stored != PERSIST_OK || n >= stored_per_client) {
            if (held)
                persist_admit(st->p, ohex, false);
            pthread_mutex_unlock(admit);
            if (a->stored == PERSIST_OK) {
                /* a stored session counts through its expiry's second (persist.h) */
                a->client_stored_full = 1;
                a->retry_after_s = soonest >= now ? (int)(soonest - now) + 1 : 1;
            }
            session_unref(s);
            return NULL;
        }
    }
    pthread_mutex_lock(&st->mu);
    bool ok = room_locked(st, owner, per_client, a);
    unlock_store(st);
    if (ok && persist_durable(st->p)) { /* in the store before anyone learns the id */
        persist_meta m = {.ttl_s = ttl_s, .created = s->created,
                          .expires_at = stored_expiry(ttl_s, (int64_t)time(NULL))};
        memcpy(m.id, s->id, sizeof m.id);
        memcpy(m.owner, ohex, sizeof m.owner);
        memcpy(m.token_hash, hash, sizeof hash);
        if ((a->stored = persist_create(st->p, &m)) != PERSIST_OK)
            ok = false;
    }
    if (admit) { /* counted from now on */
        persist_admit(st->p, ohex, false);
        pthread_mutex_unlock(admit);
    }
    s->touched = mono_now(); /* the store has its expiry */
    if (ok) {
        pthread_mutex_lock(&st->mu);
        ok = room_locked(st, owner, per_client, a);
        if (ok) {
            atomic_fetch_add(&s->refs, 1); /* the store's and the caller's */
            st->s[st->n++] = s;
        }
        unlock_store(st);
        if (!ok && a->stored == PERSIST_OK && persist_durable(st->p))
            persist_delete(st->p, s->id);
    }
    if (!ok) {
        session_unref(s);
        return NULL;
    }
    return s;
}

/* The model a stored session had: its snapshot imported, its journal replayed (edits recompute,
 * so the levels are those it had). NULL with the reason in why, and in *status the status of
 * the import's or the replayed edit's refusal when that is not about the stored data: 503 when
 * the memory it needs is in use now (a retry may load it), 413 when it needs more than this
 * daemon's limits allow (a move at a finer level computes that level first: a daemon started
 * with a lower --max-cells, say); 0 for data that cannot be read or applied (damaged). */
static api_model *rebuild(const persist_loaded *l, const api_limits *lim, char *why, size_t cap,
                          int *status)
{
    *status = 0;
    api_model *m = NULL;
    api_problem p = {0};
    uint64_t v = 0;
    if (l->snapshot) {
        json_error_t je;
        json_t *doc = json_loadb(l->snapshot, l->snapshot_len, JSON_REJECT_DUPLICATES, &je);
        if (!doc) {
            snprintf(why, cap, "the snapshot of version %llu is not JSON: %s",
                     (unsigned long long)l->snapshot_version, je.text);
            return NULL;
        }
        int rc = api_import(doc, "", lim, LLONG_MAX, &m, &v, &p);
        json_decref(doc);
        if (rc) {
            *status = p.status == 503 || p.status == 413 ? p.status : 0;
            snprintf(why, cap, "the snapshot of version %llu cannot be imported: %.160s%s%.60s",
                     (unsigned long long)l->snapshot_version, p.detail, p.nerrors ? " at " : "",
                     p.nerrors ? p.errors[0].pointer : "");
            return NULL;
        }
    } else {
        sd_error e;
        if (!(m = api_model_new(NULL, NULL, 0, false, &e))) {
            snprintf(why, cap, "out of memory");
            return NULL;
        }
    }
    for (size_t i = 0; i < l->njournal; i++) {
        const persist_entry *en = &l->journal[i];
        json_error_t je;
        json_t *b = json_loadb(en->text, en->len, JSON_REJECT_DUPLICATES, &je);
        uint64_t counts[SD_MAX_LEVEL + 1];
        int levels = 0, rc = b ? 0 : -1;
        api_model *rebuilt = NULL;
        memset(&p, 0, sizeof p);
        if (b)
            rc = api_edit(m, b, en->version, lim, NULL, counts, &levels, &rebuilt, &p);
        json_decref(b);
        if (rebuilt && !rc && api_embed_carry(m, rebuilt, lim, &p))
            rc = -1; /* the embedded models do not carry over: as a replay that failed */
        if (rebuilt) {
            api_model_unref(m);
            m = rebuilt;
        }
        if (rc) {
            *status = b && (p.status == 503 || p.status == 413) ? p.status : 0;
            snprintf(why, cap, "the edit of version %llu cannot be replayed: %.200s",
                     (unsigned long long)en->version, b ? p.detail : je.text);
            api_model_unref(m);
            return NULL;
        }
    }
    atomic_store(&m->version, l->meta.version);
    api_delta_loaded(m); /* no delta reaches back across a load: docs/SERVICE.md "Live edits" */
    return m;
}

/* Load session `id` from the durable store into the table (new reference), or NULL + *miss.
 * `token` (NULL: not checked) must be the session's before anything is rebuilt. */
/* Room in the table for a session loaded from the store, waiting a moment when there is none: a
 * request that has sent its answer holds its session until its connection's thread lets it go,
 * which a client quick with its next request (on another connection) can beat — a table full of
 * such sessions is full for a few milliseconds only. Up to 20 looks 10 ms apart; the caller holds
 * st->mu on entry and on return. */
static bool room_soon(store *st, store_admission *a)
{
    for (int k = 0;; k++) {
        memset(a, 0, sizeof *a);
        if (room_locked(st, NULL, 0, a))
            return true;
        if (k == 20)
            return false;
        unlock_store(st);
        nanosleep(&(struct timespec){0, 10 * 1000 * 1000}, NULL);
        pthread_mutex_lock(&st->mu);
    }
}

static session *load(store *st, const char *id, const char *token, store_miss *miss, char *why,
                     size_t cap)
{
    pthread_mutex_t *lk = &st->load[strtol((char[]){id[0], 0}, NULL, 16) & 15];
    pthread_mutex_lock(lk);
    session *s = NULL;
    pthread_mutex_lock(&st->mu); /* loaded meanwhile by another request? */
    for (int i = 0; i < st->n && !s; i++)
        if (!memcmp(st->s[i]->id, id, 32))
            s = st->s[i];
    if (s)
        atomic_fetch_add(&s->refs, 1);
    pthread_mutex_unlock(&st->mu);
    if (s) {
        pthread_mutex_unlock(lk);
        return s;
    }
    store_admission room = {0};
    pthread_mutex_lock(&st->mu); /* room first: a rebuild that cannot be kept is not made */
    bool space = room_soon(st, &room);
    unlock_store(st);
    if (!space) {
        pthread_mutex_unlock(lk);
        *miss = STORE_FULL;
        return NULL;
    }
    persist_loaded l;
    persist_rc rc = persist_load(st->p, id, &l);
    char reason[320] = "";
    unsigned char h[32];
    bool record = rc == PERSIST_OK || (rc == PERSIST_CORRUPT && l.record_ok);
    if (record && token) { /* a damaged content is said only to the holder of the token */
        token_hash(token, h);
        unsigned char d = 0;
        for (int i = 0; i < 32; i++)
            d |= (unsigned char)(h[i] ^ l.meta.token_hash[i]);
        if (d) { /* nothing is rebuilt for a client without the token */
            persist_loaded_free(&l);
            pthread_mutex_unlock(lk);
            *miss = STORE_UNAUTHORIZED;
            return NULL;
        }
    }
    /* the stored expiry carries the touches' slack (touch_every): past the expiry the last
     * write knew of, the session had expired (its resident copy, gone now, was the one to
     * touch it again); it is not brought back, and the store forgets it in its own time */
    if (rc == PERSIST_OK &&
        (int64_t)time(NULL) > l.meta.expires_at - (int64_t)ceil(slack_of(l.meta.ttl_s))) {
        persist_loaded_free(&l);
        rc = PERSIST_ABSENT;
    }
    int refused = 0; /* the rebuild's refusal that is not the data's (rebuild) */
    if (rc == PERSIST_OK) {
        api_model *m = rebuild(&l, &st->lim, reason, sizeof reason, &refused);
        if (!m)
            rc = PERSIST_CORRUPT; /* the record is whole: record stays true */
        else if (!(s = session_alloc(id, l.meta.token_hash, l.meta.ttl_s, (time_t)l.meta.created))) {
            api_model_unref(m);
            rc = PERSIST_UNAVAILABLE;
            snprintf(reason, sizeof reason, "out of memory");
        } else {
            session_adopt(s, m, l.meta.version);
            s->journal_len = (uint32_t)l.njournal;
            s->has_owner = owner_of_hex(l.meta.owner, &s->owner); /* it counts for its client */
            store_admission a = {0};
            pthread_mutex_lock(&st->mu);
            bool ok = room_soon(st, &a);
            if (ok) {
                atomic_fetch_add(&s->refs, 1);
                st->s[st->n++] = s;
            }
            unlock_store(st);
            if (!ok) {
                session_unref(s);
                s = NULL;
                *miss = STORE_FULL;
            }
        }
        persist_loaded_free(&l);
    } else if (rc == PERSIST_CORRUPT || rc == PERSIST_UNAVAILABLE)
        snprintf(reason, sizeof reason, "%s", l.why);
    pthread_mutex_unlock(lk);
    if (!s && rc != PERSIST_OK)
        *miss = rc == PERSIST_CORRUPT ? (refused == 503   ? STORE_BUSY
                                         : refused == 413 ? STORE_OVER_LIMITS
                                         : record         ? STORE_DAMAGED
                                                          : STORE_CORRUPT)
                : rc == PERSIST_UNAVAILABLE ? STORE_UNAVAILABLE : STORE_NONE;
    if (why && cap)
        snprintf(why, cap, "%s", reason);
    return s;
}

static uint64_t version_of(session *s)
{
    pthread_mutex_lock(&s->mu);
    uint64_t v = s->version;
    pthread_mutex_unlock(&s->mu);
    return v;
}

session *store_get(store *st, const char *id, const char *token, store_miss *miss, char *why,
                   size_t cap)
{
    store_miss m0;
    if (!miss)
        miss = &m0;
    *miss = STORE_NONE;
    session *found = NULL;
    if (strlen(id) != 32 || strspn(id, "0123456789abcdef") != 32)
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
    if (!persist_durable(st->p))
        return found;
    if (found && persist_shared(st->p)) {
        /* another daemon may have changed it. The lock is held by a change of our own in flight
         * (stored before it is published: the stored version may be ahead of ours meanwhile) or
         * by another request's check: when it is busy, a stored version other than ours is
         * looked at again once the lock is free, never taken as it is nor let by */
        bool locked = !pthread_mutex_trylock(&found->write);
        uint64_t stored = 0;
        int ttl = 0;
        persist_rc rc = persist_version(st->p, id, &stored, &ttl);
        if (!locked && rc == PERSIST_OK && stored != version_of(found)) {
            pthread_mutex_lock(&found->write);
            locked = true;
            rc = persist_version(st->p, id, &stored, &ttl);
        }
        pthread_mutex_lock(&found->mu);
        uint64_t mine = found->version;
        if (locked && rc == PERSIST_OK && ttl > 0 && ttl != found->ttl_s)
            found->ttl_s = ttl; /* given by another daemon (PATCH): not a change of content */
        pthread_mutex_unlock(&found->mu);
        if (locked)
            pthread_mutex_unlock(&found->write);
        if (rc == PERSIST_ABSENT || (rc == PERSIST_OK && stored != mine)) {
            store_drop(st, found, rc == PERSIST_ABSENT);
            session_unref(found);
            found = NULL;
            if (rc == PERSIST_ABSENT)
                return NULL;
        } /* unavailable: the resident copy is served (reads); writes will fail */
    }
    if (!found && !(found = load(st, id, token, miss, why, cap)))
        return NULL;
    double now = mono_now();
    pthread_mutex_lock(&found->mu);
    bool due = now - found->touched > touch_every(found);
    if (due)
        found->touched = now;
    pthread_mutex_unlock(&found->mu);
    if (due)
        persist_touch(st->p, found->id, session_stored_expiry(found));
    return found;
}

void store_drop(store *st, session *s, bool gone)
{
    pthread_mutex_lock(&st->mu);
    for (int i = 0; i < st->n; i++)
        if (st->s[i] == s) {
            remove_at(st, i, gone ? "deleted" : NULL);
            break;
        }
    pthread_mutex_unlock(&st->mu);
}

/* Take session i out of the store; its event listeners get `event: deleted` with `why`, or with
 * why NULL (a resident copy dropped, the session still stored) their streams end without it. */
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

void session_use(session *s) { atomic_fetch_add(&s->in_use, 1); }

void store_unuse(store *st, session *s)
{
    double now = mono_now();
    pthread_mutex_lock(&s->mu);
    s->last_used = now;
    bool due = persist_durable(st->p) && now - s->touched > touch_every(s);
    if (due)
        s->touched = now;
    pthread_mutex_unlock(&s->mu);
    if (due)
        persist_touch(st->p, s->id, session_stored_expiry(s));
    atomic_fetch_sub(&s->in_use, 1);
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
    explicit_bzero(s->token_hash, sizeof s->token_hash);
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

int64_t session_stored_expiry(session *s)
{
    return stored_expiry(s->ttl_s, (int64_t)time(NULL));
}

persist_rc store_retime(store *st, session *s, int ttl_s)
{
    /* under s->write, as every change: no journal write or snapshot of this session stores an
     * expiry meanwhile. The resident TTL first, so that a touch from a read in between stores
     * the new one (the store's record is written next, and is what counts after a restart). */
    pthread_mutex_lock(&s->write);
    pthread_mutex_lock(&s->mu);
    int was = s->ttl_s;
    s->ttl_s = ttl_s;
    s->last_used = s->touched = mono_now();
    pthread_mutex_unlock(&s->mu);
    persist_rc rc = persist_durable(st->p)
                        ? persist_retime(st->p, s->id, ttl_s, stored_expiry(ttl_s, (int64_t)time(NULL)))
                        : PERSIST_OK;
    if (rc != PERSIST_OK) { /* refused: nothing changed */
        pthread_mutex_lock(&s->mu);
        s->ttl_s = was;
        pthread_mutex_unlock(&s->mu);
    }
    pthread_mutex_unlock(&s->write);
    return rc;
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
    if (!presented)
        return 0;
    unsigned char h[32], d = 0;
    token_hash(presented, h);
    for (size_t i = 0; i < sizeof h; i++)
        d |= (unsigned char)(s->token_hash[i] ^ h[i]);
    return d == 0;
}
