/* rate.c — per-client token buckets in a fixed table (see rate.h). */
#include "rate.h"
#include "../api/mem.h"
#include <math.h>
#include <netinet/in.h>
#include <pthread.h>
#include <string.h>

typedef struct bucket {
    rate_key key;
    double tokens, at;       /* tokens at time `at` */
} bucket;

struct rate {
    pthread_mutex_t mu;
    double per_s, burst;
    size_t n, cap;
    bucket *b;
};

rate_key rate_key_of(const struct sockaddr *sa)
{
    static const uint8_t mapped[12] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff};
    rate_key k;
    memset(&k, 0, sizeof k);
    if (sa && sa->sa_family == AF_INET) {
        k.b[0] = 4;
        memcpy(k.b + 1, &((const struct sockaddr_in *)sa)->sin_addr, 4);
    } else if (sa && sa->sa_family == AF_INET6) {
        const uint8_t *a = ((const struct sockaddr_in6 *)sa)->sin6_addr.s6_addr;
        if (!memcmp(a, mapped, sizeof mapped)) {
            k.b[0] = 4;
            memcpy(k.b + 1, a + 12, 4);
        } else {
            k.b[0] = 6;
            memcpy(k.b + 1, a, 8); /* the /64 prefix */
        }
    }
    return k;
}

rate *rate_new(double per_minute, double burst, size_t max_clients)
{
    rate *rt = api_calloc(1, sizeof *rt);
    if (!rt)
        return NULL;
    rt->b = api_calloc(max_clients ? max_clients : 1, sizeof *rt->b);
    if (!rt->b) {
        api_free(rt);
        return NULL;
    }
    rt->per_s = per_minute / 60.0;
    rt->burst = burst < 1 ? 1 : burst;
    rt->cap = max_clients ? max_clients : 1;
    pthread_mutex_init(&rt->mu, NULL);
    return rt;
}

void rate_free(rate *rt)
{
    if (!rt)
        return;
    pthread_mutex_destroy(&rt->mu);
    api_free(rt->b);
    api_free(rt);
}

/* The bucket's tokens at `now`. */
static double level(const rate *rt, const bucket *b, double now)
{
    double t = b->tokens + (now - b->at) * rt->per_s;
    return t < rt->burst ? t : rt->burst;
}

int rate_take(rate *rt, const rate_key *key, double now)
{
    pthread_mutex_lock(&rt->mu);
    bucket *b = NULL, *spare = NULL;
    double spare_level = -1;
    for (size_t i = 0; i < rt->n && !b; i++) {
        bucket *c = &rt->b[i];
        if (!memcmp(&c->key, key, sizeof *key))
            b = c;
        else {
            double l = level(rt, c, now);
            if (l > spare_level || (l == spare_level && c->at < spare->at)) {
                spare = c;
                spare_level = l;
            }
        }
    }
    if (!b) {
        b = rt->n < rt->cap ? &rt->b[rt->n++] : spare;
        b->key = *key;
        b->tokens = rt->burst;
        b->at = now;
    }
    double t = level(rt, b, now);
    int wait = 0;
    if (t >= 1)
        t -= 1;
    else {
        double s = ceil((1 - t) / rt->per_s);
        wait = s < 1 ? 1 : s > 86400 ? 86400 : (int)s;
    }
    b->tokens = t;
    b->at = now;
    pthread_mutex_unlock(&rt->mu);
    return wait;
}
