/* config.h — the daemon's settings: defaults, then environment (SUBDIVD_*), then flags. */
#ifndef SUBDIVD_CONFIG_H
#define SUBDIVD_CONFIG_H

#include "../api/limits.h"
#include <stdio.h>

enum { LOG_ERROR = 0, LOG_WARN, LOG_INFO, LOG_DEBUG };

typedef struct config {
    char listen[64];          /* address to bind, default 127.0.0.1 */
    int port;                 /* default 8080; 0 = any free port (printed at start) */
    int threads;              /* concurrent computations (default: CPU count) */
    uint64_t keep_memory;     /* big freed core blocks kept for the next build (api/mem.h) */
    int level_threads;        /* threads one computation may use when the other slots are idle */
    int max_connections;
    int max_connections_per_client; /* per client address (0: no cap) */
    int connection_reserve;   /* slots kept free: beyond max - reserve the guard evicts */
    int connection_timeout_s; /* idle kept-alive connections */
    int header_timeout_s;     /* a new connection's request headers */
    int body_min_rate;        /* bytes/s a request body must average after header_timeout_s */
    int queue_timeout_s;      /* how long a computation waits for a slot before 429 */
    int drain_timeout_s;      /* on SIGTERM/SIGINT, how long requests in flight may finish */
    int max_sessions;         /* resident sessions */
    int max_sessions_per_client; /* resident sessions one client address created (0: any) */
    int max_stored_sessions_per_client; /* unexpired ones in a durable store (0: any) */
    int ttl_s;                /* default session idle TTL */
    int max_ttl_s;            /* a larger ttl_s asked for is granted as this */
    int session_rate;         /* sessions one client may create per minute (burst as many) */
    int sse_heartbeat_s;      /* seconds between heartbeat comments of an event stream */
    int max_listeners;        /* event streams open at once per session (429 beyond) */
    int no_auth;
    int log_level;
    char cors_origin[256];    /* "*" or one origin */
    char store[512];          /* the durable session store: memory | sqlite:PATH | redis://HOST:PORT */
    int sync_full;            /* --sync full: fsync every commit of the store (power loss) */
    uint64_t max_memory;      /* the memory budget of every request (api/mem.h), bytes */
    uint64_t max_client_body_bytes; /* bodies one client address may hold while they arrive
                                     * (server/holds.h; 0: no cap) */
    api_limits limits;
} config;

/* Fill from defaults, environment and argv (argv[first..]). Returns 0, or 1 after printing usage
 * (help asked: *exit_code = 0; bad flag: 2). */
/* The threads one computation may use unless told: the CPU count, at most 8 (--level-threads,
 * and `subdivd refine --threads`). */
int config_default_level_threads(void);
int config_load(config *c, int argc, char **argv, int first, int *exit_code);
void config_usage(FILE *f);

#endif
