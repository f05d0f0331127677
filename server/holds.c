/* holds.c — bytes held per client, in a fixed table (see holds.h). */
#include "holds.h"
#include "../api/mem.h"
#include <pthread.h>
#include <string.h>

typedef struct hold {
    rate_key key;
    size_t bytes;
} hold;

struct holds {
    pthread_mutex_t mu;
    size_t cap, n, max;
    hold *h;
};

holds *holds_new(size_t cap, size_t max_clients)
{
    holds *h = api_calloc(1, sizeof *h);
    if (!h || !(h->h = api_calloc(max_clients ? max_clients : 1, sizeof *h->h))) {
        api_free(h);
        return NULL;
    }
    h->cap = cap;
    h->max = max_clients ? max_clients : 1;
    pthread_mutex_init(&h->mu, NULL);
    return h;
}

void holds_free(holds *h)
{
    if (!h)
        return;
    pthread_mutex_destroy(&h->mu);
    api_free(h->h);
    api_free(h);
}

static hold *find(holds *h, const rate_key *key)
{
    for (size_t i = 0; i < h->n; i++)
        if (!memcmp(&h->h[i].key, key, sizeof *key))
            return &h->h[i];
    return NULL;
}

bool holds_take(holds *h, const rate_key *key, size_t n)
{
    pthread_mutex_lock(&h->mu);
    hold *e = find(h, key);
    bool ok = !h->cap || n <= h->cap - (e ? e->bytes : 0);
    if (ok && !e) {
        if (h->n == h->max)
            ok = false;
        else {
            e = &h->h[h->n++];
            e->key = *key;
            e->bytes = 0;
        }
    }
    if (ok)
        e->bytes += n;
    pthread_mutex_unlock(&h->mu);
    return ok;
}

void holds_give(holds *h, const rate_key *key, size_t n)
{
    pthread_mutex_lock(&h->mu);
    hold *e = find(h, key);
    if (e) {
        n = n < e->bytes ? n : e->bytes;
        e->bytes -= n;
        if (!e->bytes)
            *e = h->h[--h->n]; /* the last entry takes its place */
    }
    pthread_mutex_unlock(&h->mu);
}

size_t holds_cap(const holds *h) { return h->cap; }

size_t holds_held(holds *h, const rate_key *key)
{
    pthread_mutex_lock(&h->mu);
    hold *e = find(h, key);
    size_t n = e ? e->bytes : 0;
    pthread_mutex_unlock(&h->mu);
    return n;
}
