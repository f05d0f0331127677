/* guard.c — connection slots under hostile clients (see guard.h for the policy).
 *
 * Records live in one doubly linked list under `mu`; a record is created by MHD's STARTED
 * notification and unlinked by CLOSED, which MHD sends before it closes the socket — so a
 * shutdown(2) done under `mu` always hits the connection it was meant for, never a reused
 * descriptor. Per-address counts are needed only to choose whom to evict: one pass over the
 * list counts them in a small open-addressing table (twice the connection limit, slots
 * invalidated by a generation number rather than cleared), so eviction stays linear in the
 * number of connections. Records and the table come from the C library, not api/mem.h: the
 * guard has to keep working when the budget of api/ is spent.
 */
#include "guard.h"
#include <netinet/in.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

enum { PH_WAIT_NEW, PH_WAIT_IDLE, PH_BODY, PH_WORK };

struct guard_conn {
    guard_conn *prev, *next;
    int fd;
    uint8_t addr[16];       /* IPv4 in the first 4 bytes, or IPv6 */
    uint8_t family_v6;
    uint8_t phase;
    bool closing;           /* shut down by the guard: not chosen again */
    bool nul;               /* a NUL byte was decoded in this request */
    double since;           /* start of the phase (monotonic seconds) */
    uint64_t body_len, body_got;
};

/* One address's count in victim()'s scratch table; a slot is empty unless gen is current. */
typedef struct addr_count {
    uint8_t addr[16];
    uint8_t v6;
    unsigned gen, n;
} addr_count;

struct guard {
    guard_config cfg;
    addr_count *counts;
    size_t ncounts;        /* a power of two, at least twice max_connections */
    unsigned gen;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    pthread_t reaper;
    bool stop, started;
    guard_conn *head;
    unsigned open;
    uint64_t evicted, header_timeouts, body_timeouts, idle_timeouts;
};

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void addr_key(const struct sockaddr *sa, uint8_t out[16], uint8_t *v6)
{
    memset(out, 0, 16);
    *v6 = 0;
    if (sa && sa->sa_family == AF_INET)
        memcpy(out, &((const struct sockaddr_in *)sa)->sin_addr, 4);
    else if (sa && sa->sa_family == AF_INET6) {
        memcpy(out, &((const struct sockaddr_in6 *)sa)->sin6_addr, 16);
        *v6 = 1;
    }
}

/* The scratch slot of k's address (found or taken), NULL if the table is full. Caller holds
 * mu. */
static addr_count *addr_slot(guard *g, const guard_conn *k)
{
    uint64_t h = 1469598103934665603ull; /* FNV-1a */
    for (int i = 0; i < 16; i++)
        h = (h ^ k->addr[i]) * 1099511628211ull;
    h = (h ^ k->family_v6) * 1099511628211ull;
    for (size_t i = 0; i < g->ncounts; i++) {
        addr_count *c = &g->counts[(h + i) & (g->ncounts - 1)];
        if (c->gen != g->gen) {
            memcpy(c->addr, k->addr, 16);
            c->v6 = k->family_v6;
            c->gen = g->gen;
            c->n = 0;
            return c;
        }
        if (c->v6 == k->family_v6 && !memcmp(c->addr, k->addr, 16))
            return c;
    }
    return NULL;
}

static bool pressure(const guard *g)
{
    unsigned soft = g->cfg.max_connections > g->cfg.reserve ? g->cfg.max_connections - g->cfg.reserve : 0;
    return g->open >= soft;
}

static void close_conn(guard_conn *k)
{
    k->closing = true;
    shutdown(k->fd, SHUT_RDWR);
}

/* The WAIT-phase connection to give up under pressure: the address with the most connections
 * first, then the one that has waited longest. Caller holds mu. */
static guard_conn *victim(guard *g)
{
    if (++g->gen == 0) { /* wrapped: old slots could look current */
        memset(g->counts, 0, g->ncounts * sizeof *g->counts);
        g->gen = 1;
    }
    for (guard_conn *k = g->head; k; k = k->next) {
        addr_count *c = k->closing ? NULL : addr_slot(g, k);
        if (c)
            c->n++;
    }
    guard_conn *best = NULL;
    unsigned best_n = 0;
    for (guard_conn *k = g->head; k; k = k->next) {
        if (k->closing || (k->phase != PH_WAIT_NEW && k->phase != PH_WAIT_IDLE))
            continue;
        addr_count *c = addr_slot(g, k);
        unsigned n = c ? c->n : 1;
        if (!best || n > best_n || (n == best_n && k->since < best->since)) {
            best = k;
            best_n = n;
        }
    }
    return best;
}

enum MHD_Result guard_accept(void *cls, const struct sockaddr *addr, socklen_t len)
{
    (void)len;
    guard *g = cls;
    pthread_mutex_lock(&g->mu);
    if (pressure(g)) {
        guard_conn *v = victim(g);
        if (v) {
            close_conn(v);
            g->evicted++;
        }
    }
    /* MHD applies its own per-address limit before this callback; a second check here would
     * count the connections the guard is closing, which MHD still holds */
    (void)addr;
    pthread_mutex_unlock(&g->mu);
    return MHD_YES;
}

void guard_notify(void *cls, struct MHD_Connection *c, void **socket_context,
                  enum MHD_ConnectionNotificationCode code)
{
    guard *g = cls;
    if (code == MHD_CONNECTION_NOTIFY_STARTED) {
        guard_conn *k = calloc(1, sizeof *k);
        *socket_context = k;
        if (!k)
            return;
        const union MHD_ConnectionInfo *fi = MHD_get_connection_info(c, MHD_CONNECTION_INFO_CONNECTION_FD);
        const union MHD_ConnectionInfo *ai = MHD_get_connection_info(c, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
        k->fd = fi ? fi->connect_fd : -1;
        addr_key(ai ? ai->client_addr : NULL, k->addr, &k->family_v6);
        k->phase = PH_WAIT_NEW;
        k->since = now_s();
        pthread_mutex_lock(&g->mu);
        k->next = g->head;
        if (g->head)
            g->head->prev = k;
        g->head = k;
        g->open++;
        pthread_mutex_unlock(&g->mu);
    } else if (code == MHD_CONNECTION_NOTIFY_CLOSED) {
        guard_conn *k = *socket_context;
        if (!k)
            return;
        pthread_mutex_lock(&g->mu);
        if (k->prev)
            k->prev->next = k->next;
        else
            g->head = k->next;
        if (k->next)
            k->next->prev = k->prev;
        g->open--;
        pthread_mutex_unlock(&g->mu);
        free(k);
        *socket_context = NULL;
    }
}

guard_conn *guard_conn_of(struct MHD_Connection *c)
{
    const union MHD_ConnectionInfo *i = MHD_get_connection_info(c, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
    return i ? i->socket_context : NULL;
}

size_t guard_unescape(void *cls, struct MHD_Connection *c, char *s)
{
    (void)cls;
    size_t n = MHD_http_unescape(s);
    if (memchr(s, 0, n)) {
        guard_conn *k = guard_conn_of(c);
        if (k)
            k->nul = true; /* only this connection's own thread reads or writes it */
    }
    return n;
}

static void set_phase(guard *g, guard_conn *k, int phase)
{
    if (!k)
        return;
    pthread_mutex_lock(&g->mu);
    k->phase = (uint8_t)phase;
    k->since = now_s();
    pthread_mutex_unlock(&g->mu);
}

void guard_request_begin(guard *g, guard_conn *k, uint64_t content_length)
{
    if (!k)
        return;
    pthread_mutex_lock(&g->mu);
    k->body_len = content_length;
    k->body_got = 0;
    k->phase = content_length ? PH_BODY : PH_WORK;
    k->since = now_s();
    pthread_mutex_unlock(&g->mu);
}

void guard_body_progress(guard *g, guard_conn *k, size_t n)
{
    if (!k)
        return;
    pthread_mutex_lock(&g->mu);
    k->body_got += n;
    pthread_mutex_unlock(&g->mu);
}

void guard_request_work(guard *g, guard_conn *k) { set_phase(g, k, PH_WORK); }

void guard_request_done(guard *g, guard_conn *k)
{
    if (k)
        k->nul = false;
    set_phase(g, k, PH_WAIT_IDLE);
}

int guard_request_had_nul(const guard_conn *k) { return k && k->nul; }

/* Close what is past its deadline. Caller holds mu. */
static void reap(guard *g, double t)
{
    bool tight = pressure(g);
    for (guard_conn *k = g->head; k; k = k->next) {
        if (k->closing)
            continue;
        double age = t - k->since;
        switch (k->phase) {
        case PH_WAIT_NEW:
            if (age > (tight ? 1.0 : g->cfg.header_timeout_s)) {
                close_conn(k);
                g->header_timeouts++;
            }
            break;
        case PH_WAIT_IDLE:
            if (age > (tight ? 1.0 : g->cfg.idle_timeout_s)) {
                close_conn(k);
                g->idle_timeouts++;
            }
            break;
        case PH_BODY:
            if (g->cfg.body_min_rate > 0 && age > g->cfg.header_timeout_s &&
                (double)k->body_got < (age - g->cfg.header_timeout_s) * g->cfg.body_min_rate &&
                k->body_got < k->body_len) {
                close_conn(k);
                g->body_timeouts++;
            }
            break;
        default:
            break;
        }
    }
}

static void *reaper_main(void *arg)
{
    guard *g = arg;
    pthread_mutex_lock(&g->mu);
    while (!g->stop) {
        struct timespec until;
        clock_gettime(CLOCK_MONOTONIC, &until);
        until.tv_nsec += 200 * 1000000L;
        if (until.tv_nsec >= 1000000000L) {
            until.tv_sec++;
            until.tv_nsec -= 1000000000L;
        }
        pthread_cond_timedwait(&g->cv, &g->mu, &until);
        if (!g->stop)
            reap(g, now_s());
    }
    pthread_mutex_unlock(&g->mu);
    return NULL;
}

guard *guard_new(const guard_config *cfg)
{
    guard *g = calloc(1, sizeof *g);
    if (!g)
        return NULL;
    g->cfg = *cfg;
    g->ncounts = 16;
    while (g->ncounts < 2 * (size_t)cfg->max_connections)
        g->ncounts *= 2;
    g->counts = calloc(g->ncounts, sizeof *g->counts);
    if (!g->counts) {
        free(g);
        return NULL;
    }
    pthread_mutex_init(&g->mu, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&g->cv, &ca);
    pthread_condattr_destroy(&ca);
    if (pthread_create(&g->reaper, NULL, reaper_main, g)) {
        pthread_cond_destroy(&g->cv);
        pthread_mutex_destroy(&g->mu);
        free(g->counts);
        free(g);
        return NULL;
    }
    g->started = true;
    return g;
}

void guard_free(guard *g)
{
    if (!g)
        return;
    pthread_mutex_lock(&g->mu);
    g->stop = true;
    pthread_cond_signal(&g->cv);
    pthread_mutex_unlock(&g->mu);
    if (g->started)
        pthread_join(g->reaper, NULL);
    pthread_cond_destroy(&g->cv);
    pthread_mutex_destroy(&g->mu);
    free(g->counts);
    free(g);
}

void guard_get_stats(guard *g, guard_stats *out)
{
    memset(out, 0, sizeof *out);
    pthread_mutex_lock(&g->mu);
    for (const guard_conn *k = g->head; k; k = k->next) {
        out->open++;
        if (k->phase == PH_WAIT_NEW || k->phase == PH_WAIT_IDLE)
            out->waiting++;
        else if (k->phase == PH_BODY)
            out->receiving++;
        else
            out->working++;
    }
    out->evicted = g->evicted;
    out->header_timeouts = g->header_timeouts;
    out->body_timeouts = g->body_timeouts;
    out->idle_timeouts = g->idle_timeouts;
    pthread_mutex_unlock(&g->mu);
}
