/* server.h — the daemon: configuration, session store, compute slots and the HTTP front. */
#ifndef SUBDIVD_SERVER_H
#define SUBDIVD_SERVER_H

#include "config.h"
#include "sessions.h"
#include <semaphore.h>
#include <stdatomic.h>

typedef struct server {
    config cfg;
    store *st;
    sem_t compute;            /* cfg.threads slots for computations */
    atomic_int draining;      /* /readyz answers 503 while starting or stopping */
    struct MHD_Daemon *mhd;
    int port;                 /* the bound port */
} server;

/* Start listening (0) or print why not (-1). */
int http_start(server *srv);
void http_stop(server *srv);
/* The route templates the server answers, one per line ("METHOD /path"), for --list-routes. */
void http_list_routes(FILE *f);

void log_line(const server *srv, int level, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* Embedded files (build/assets.c, generated from api/openapi.json and web/). */
typedef struct asset {
    const char *path;          /* URL path, e.g. "/v1/openapi.json" */
    const char *content_type;
    const unsigned char *data;
    size_t size;
} asset;
const asset *asset_find(const char *path);

#endif
