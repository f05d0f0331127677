/* slots.c — compute slots with fair hand-over between sessions (see slots.h).
 *
 * One mutex guards the count of free slots, the table of holders (an owner and how many slots it
 * holds: at most n entries, since n slots can have at most n owners) and the list of waiters,
 * each with its own condition variable on the caller's stack. A slot that is given back while
 * someone waits is handed over directly (the chosen waiter is marked granted and woken), so a
 * newcomer can never take it first; a waiter that times out leaves the list, unless it was
 * granted meanwhile, in which case it keeps the slot. Deadlines are on CLOCK_MONOTONIC.
 */
#include "slots.h"
#include "../api/mem.h"
#include <errno.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <time.h>

typedef struct holder {
    const void *owner;
    int n;
} holder;

typedef struct waiter {
    const void *owner;
    uint64_t ticket;          /* arrival order */
    bool granted;
    pthread_cond_t cv;
    struct waiter *next;
} waiter;

struct slots {
    pthread_mutex_t mu;
    int n, free;
    uint64_t tickets;
    holder *held;             /* n entries; n == 0 marks an unused one */
    waiter *waiting;
};

slots *slots_new(int n)
{
    slots *s = api_calloc(1, sizeof *s);
    if (!s)
        return NULL;
    s->held = api_calloc((size_t)n, sizeof *s->held);
    if (!s->held) {
        api_free(s);
        return NULL;
    }
    pthread_mutex_init(&s->mu, NULL);
    s->n = s->free = n;
    return s;
}

void slots_free(slots *s)
{
    if (!s)
        return;
    pthread_mutex_destroy(&s->mu);
    api_free(s->held);
    api_free(s);
}

static holder *holder_of(slots *s, const void *owner)
{
    for (int i = 0; i < s->n; i++)
        if (s->held[i].n && s->held[i].owner == owner)
            return &s->held[i];
    return NULL;
}

static int held_locked(slots *s, const void *owner)
{
    holder *h = holder_of(s, owner);
    return h ? h->n : 0;
}

/* One slot goes to owner (caller holds mu, a slot is free). */
static void grant(slots *s, const void *owner)
{
    holder *h = holder_of(s, owner);
    for (int i = 0; !h && i < s->n; i++)
        if (!s->held[i].n)
            h = &s->held[i];
    h->owner = owner; /* there is room: at most n holders for n slots */
    h->n++;
    s->free--;
}

static void unlink_waiter(slots *s, waiter *w)
{
    for (waiter **p = &s->waiting; *p; p = &(*p)->next)
        if (*p == w) {
            *p = w->next;
            return;
        }
}

int slots_take(slots *s, const void *owner, int timeout_s)
{
    pthread_mutex_lock(&s->mu);
    if (s->free > 0 && !s->waiting) {
        grant(s, owner);
        pthread_mutex_unlock(&s->mu);
        return 0;
    }
    waiter w = {.owner = owner, .ticket = s->tickets++};
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_cond_init(&w.cv, &ca);
    pthread_condattr_destroy(&ca);
    waiter **tail = &s->waiting;
    while (*tail)
        tail = &(*tail)->next;
    *tail = &w;
    struct timespec until;
    clock_gettime(CLOCK_MONOTONIC, &until);
    until.tv_sec += timeout_s;
    int rc = 0;
    while (!w.granted && rc != ETIMEDOUT)
        rc = pthread_cond_timedwait(&w.cv, &s->mu, &until);
    if (!w.granted)
        unlink_waiter(s, &w);
    pthread_mutex_unlock(&s->mu);
    pthread_cond_destroy(&w.cv);
    return w.granted ? 0 : -1;
}

void slots_give(slots *s, const void *owner)
{
    pthread_mutex_lock(&s->mu);
    holder *h = holder_of(s, owner);
    if (h)
        h->n--;
    s->free++;
    /* the waiter whose owner holds the fewest slots; the earliest among those */
    waiter *best = NULL;
    int best_held = 0;
    for (waiter *w = s->waiting; w; w = w->next) {
        int held = held_locked(s, w->owner);
        if (!best || held < best_held || (held == best_held && w->ticket < best->ticket)) {
            best = w;
            best_held = held;
        }
    }
    if (best) {
        unlink_waiter(s, best);
        grant(s, best->owner);
        best->granted = true;
        pthread_cond_signal(&best->cv);
    }
    pthread_mutex_unlock(&s->mu);
}

int slots_held(slots *s, const void *owner)
{
    pthread_mutex_lock(&s->mu);
    int n = held_locked(s, owner);
    pthread_mutex_unlock(&s->mu);
    return n;
}

int slots_busy(slots *s)
{
    pthread_mutex_lock(&s->mu);
    int n = s->n - s->free;
    pthread_mutex_unlock(&s->mu);
    return n;
}
