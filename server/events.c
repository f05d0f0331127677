/* events.c — Server-Sent Events of one session (see events.h for the model).
 *
 * Everything of a hub is under its mutex: the ring of recent event texts, the listener list and
 * each listener's buffer. Readers wait on the hub's condition variable in slices of at most
 * half a second, so a daemon that stops (ev_stop_all) ends every stream promptly and MHD can
 * join the connection threads.
 */
#include "events.h"
#include "../api/mem.h"
#include <poll.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

typedef struct ev_text {
    uint64_t version;
    char *text;
    size_t len;
} ev_text;

struct ev_listener {
    ev_hub *h;
    ev_listener *next;
    bool dropped;            /* its buffer overflowed: end the stream */
    bool counted;            /* counts among the hub's listeners (not once dropped) */
    bool ending;             /* the hub closed: end after the buffer is sent */
    double last_send;
    size_t start, len;       /* unread bytes: buf[start, len) */
    char buf[EV_LISTENER_BYTES];
};

struct ev_hub {
    atomic_int refs;
    pthread_mutex_t mu;
    pthread_cond_t cv;
    bool closed;
    char *close_text;
    size_t close_len;
    ev_text ring[EV_RING];
    unsigned nring, head;    /* ring[(head + i) % EV_RING] for i < nring, oldest first */
    ev_listener *listeners;
    unsigned nlisteners;
    uint64_t newest;         /* the version of the last event published */
};

static atomic_bool stopping;
static atomic_uint nlisteners;
static atomic_uint_fast64_t ndropped;

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

ev_hub *ev_hub_new(void)
{
    ev_hub *h = api_calloc(1, sizeof *h);
    if (!h)
        return NULL;
    atomic_init(&h->refs, 1);
    pthread_mutex_init(&h->mu, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&h->cv, &ca);
    pthread_condattr_destroy(&ca);
    return h;
}

ev_hub *ev_hub_ref(ev_hub *h)
{
    atomic_fetch_add(&h->refs, 1);
    return h;
}

void ev_hub_unref(ev_hub *h)
{
    if (!h || atomic_fetch_sub(&h->refs, 1) != 1)
        return;
    for (unsigned i = 0; i < h->nring; i++)
        api_free(h->ring[(h->head + i) % EV_RING].text);
    api_free(h->close_text);
    pthread_cond_destroy(&h->cv);
    pthread_mutex_destroy(&h->mu);
    api_free(h);
}

/* A dropped or leaving listener stops counting against --max-listeners and in the gauge: a
 * client that does not read holds no place another listener could take. mu held. */
static void uncount(ev_listener *l)
{
    if (!l->counted)
        return;
    l->counted = false;
    l->h->nlisteners--;
    atomic_fetch_sub(&nlisteners, 1);
}

/* Append text to a listener's buffer, or drop the listener when it does not fit. mu held. */
static void deliver(ev_listener *l, const char *text, size_t n)
{
    if (l->dropped)
        return;
    if (l->len + n > sizeof l->buf && l->start) { /* compact */
        memmove(l->buf, l->buf + l->start, l->len - l->start);
        l->len -= l->start;
        l->start = 0;
    }
    if (l->len + n > sizeof l->buf) {
        l->dropped = true;
        atomic_fetch_add(&ndropped, 1);
        uncount(l);
        return;
    }
    memcpy(l->buf + l->len, text, n);
    l->len += n;
}

static char *event_text(uint64_t version, const char *name, const char *data, size_t *len)
{
    int n = snprintf(NULL, 0, "id: %llu\nevent: %s\ndata: %s\n\n", (unsigned long long)version,
                     name, data);
    char *t = n < 0 ? NULL : api_malloc((size_t)n + 1);
    if (!t)
        return NULL;
    snprintf(t, (size_t)n + 1, "id: %llu\nevent: %s\ndata: %s\n\n", (unsigned long long)version,
             name, data);
    *len = (size_t)n;
    return t;
}

void ev_publish(ev_hub *h, uint64_t version, const char *name, const char *data)
{
    size_t n;
    char *t = event_text(version, name, data, &n);
    pthread_mutex_lock(&h->mu);
    if (!t) { /* out of memory: forget the ring and end every stream, so that nobody misses an
               * event unawares (reconnecting listeners are told to resync) */
        for (unsigned i = 0; i < h->nring; i++)
            api_free(h->ring[(h->head + i) % EV_RING].text);
        h->nring = h->head = 0;
        for (ev_listener *l = h->listeners; l; l = l->next)
            if (!l->dropped) {
                l->dropped = true;
                atomic_fetch_add(&ndropped, 1);
                uncount(l);
            }
        pthread_cond_broadcast(&h->cv);
        pthread_mutex_unlock(&h->mu);
        return;
    }
    if (h->closed) {
        pthread_mutex_unlock(&h->mu);
        api_free(t);
        return;
    }
    if (h->nring == EV_RING) { /* forget the oldest */
        api_free(h->ring[h->head].text);
        h->head = (h->head + 1) % EV_RING;
        h->nring--;
    }
    h->newest = version;
    h->ring[(h->head + h->nring) % EV_RING] = (ev_text){version, t, n};
    h->nring++;
    for (ev_listener *l = h->listeners; l; l = l->next)
        deliver(l, t, n);
    pthread_cond_broadcast(&h->cv);
    pthread_mutex_unlock(&h->mu);
}

void ev_close(ev_hub *h, const char *why)
{
    char text[256];
    int n = why ? snprintf(text, sizeof text, "event: deleted\ndata: {\"reason\":\"%s\"}\n\n", why)
                : 0;
    pthread_mutex_lock(&h->mu);
    if (!h->closed) {
        h->closed = true;
        h->close_text = n ? api_malloc((size_t)n + 1) : NULL;
        if (h->close_text) {
            memcpy(h->close_text, text, (size_t)n + 1);
            h->close_len = (size_t)n;
        }
        for (ev_listener *l = h->listeners; l; l = l->next) {
            if (n)
                deliver(l, text, (size_t)n);
            l->ending = true;
        }
        pthread_cond_broadcast(&h->cv);
    }
    pthread_mutex_unlock(&h->mu);
}

ev_listener *ev_listen(ev_hub *h, int has_last, uint64_t last, uint64_t current_version,
                       unsigned max, int *full)
{
    *full = 0;
    ev_listener *l = api_calloc(1, sizeof *l);
    if (!l)
        return NULL;
    l->last_send = now_s();
    pthread_mutex_lock(&h->mu);
    if (h->nlisteners >= max) {
        pthread_mutex_unlock(&h->mu);
        api_free(l);
        *full = 1;
        return NULL;
    }
    l->h = ev_hub_ref(h);
    if (current_version < h->newest) /* published since the caller read its version */
        current_version = h->newest;
    char hello[64];
    int hn = snprintf(hello, sizeof hello, ": version %llu\n\n", (unsigned long long)current_version);
    deliver(l, hello, (size_t)hn);
    if (has_last && last != current_version) {
        /* the events after `last` are all kept if the ring holds version last + 1 */
        bool kept = false;
        unsigned from = 0;
        for (unsigned i = 0; i < h->nring; i++)
            if (h->ring[(h->head + i) % EV_RING].version == last + 1) {
                kept = true;
                from = i;
                break;
            }
        if (last > current_version || !kept) {
            char text[96];
            int n = snprintf(text, sizeof text, "id: %llu\nevent: resync\ndata: {\"version\":%llu}\n\n",
                             (unsigned long long)current_version,
                             (unsigned long long)current_version);
            deliver(l, text, (size_t)n);
        } else
            for (unsigned i = from; i < h->nring; i++) {
                const ev_text *e = &h->ring[(h->head + i) % EV_RING];
                deliver(l, e->text, e->len);
            }
    }
    if (h->closed) {
        if (h->close_text)
            deliver(l, h->close_text, h->close_len);
        l->ending = true;
    }
    l->next = h->listeners;
    h->listeners = l;
    if (!l->dropped) { /* (a replay that did not fit ends the stream at once) */
        l->counted = true;
        h->nlisteners++;
        atomic_fetch_add(&nlisteners, 1);
    }
    pthread_mutex_unlock(&h->mu);
    return l;
}

/* The peer closed its side (or the socket failed): poll without waiting. */
static bool peer_gone(int fd)
{
    struct pollfd p = {.fd = fd, .events = POLLRDHUP};
    return fd >= 0 && poll(&p, 1, 0) == 1 && (p.revents & (POLLRDHUP | POLLHUP | POLLERR));
}

ssize_t ev_read(ev_listener *l, char *buf, size_t max, double heartbeat_s, int fd)
{
    ev_hub *h = l->h;
    pthread_mutex_lock(&h->mu);
    for (;;) {
        if (l->dropped || atomic_load(&stopping)) {
            pthread_mutex_unlock(&h->mu);
            return -1;
        }
        if (l->start < l->len) {
            size_t n = l->len - l->start < max ? l->len - l->start : max;
            memcpy(buf, l->buf + l->start, n);
            l->start += n;
            if (l->start == l->len)
                l->start = l->len = 0;
            l->last_send = now_s();
            pthread_mutex_unlock(&h->mu);
            return (ssize_t)n;
        }
        if (l->ending) {
            pthread_mutex_unlock(&h->mu);
            return -1;
        }
        double t = now_s(), due = l->last_send + heartbeat_s;
        if (t >= due) {
            static const char hb[] = ": heartbeat\n\n";
            size_t n = sizeof hb - 1 < max ? sizeof hb - 1 : max;
            memcpy(buf, hb, n);
            l->last_send = t;
            pthread_mutex_unlock(&h->mu);
            return (ssize_t)n;
        }
        if (peer_gone(fd)) {
            pthread_mutex_unlock(&h->mu);
            return -1;
        }
        double wait = due - t < 0.5 ? due - t : 0.5;
        struct timespec until;
        clock_gettime(CLOCK_MONOTONIC, &until);
        long ns = until.tv_nsec + (long)(wait * 1e9);
        until.tv_sec += ns / 1000000000L;
        until.tv_nsec = ns % 1000000000L;
        pthread_cond_timedwait(&h->cv, &h->mu, &until);
    }
}

void ev_unlisten(ev_listener *l)
{
    if (!l)
        return;
    ev_hub *h = l->h;
    pthread_mutex_lock(&h->mu);
    for (ev_listener **p = &h->listeners; *p; p = &(*p)->next)
        if (*p == l) {
            *p = l->next;
            uncount(l);
            break;
        }
    pthread_mutex_unlock(&h->mu);
    api_free(l);
    ev_hub_unref(h);
}

void ev_stats(unsigned *listeners, uint64_t *dropped)
{
    *listeners = atomic_load(&nlisteners);
    *dropped = atomic_load(&ndropped);
}

void ev_stop_all(void)
{
    atomic_store(&stopping, true);
}
