/* persist_redis.c — placeholder until the redis back end lands: --store redis:// is refused. */
#include "persist_impl.h"
#include <stdio.h>

void *persist_redis_open(const char *host, int port, char *err, size_t cap)
{
    snprintf(err, cap, "--store redis://%s:%d: this build has no redis back end", host, port);
    return NULL;
}

const persist_ops persist_redis_ops;
