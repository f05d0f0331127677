/* config.c — one table of settings drives defaults, SUBDIVD_* environment variables, flags and
 * the usage text, so the three can never disagree. */
#include "config.h"
#include "../api/out.h"
#include <ctype.h>
#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef enum { T_INT, T_U32, T_U64, T_SIZE, T_STR, T_FLAG, T_LOG, T_SYNC } kind;

typedef struct setting {
    const char *flag;   /* --flag; env SUBDIVD_FLAG with '-' -> '_' */
    kind k;
    size_t off;
    long long lo, hi;
    const char *help;
} setting;

#define OFF(f) offsetof(config, f)
static const setting S[] = {
    {"listen", T_STR, OFF(listen), 0, 0, "address to bind (default 127.0.0.1)"},
    {"port", T_INT, OFF(port), 0, 65535, "TCP port (default 8080; 0 picks a free one)"},
    {"threads", T_INT, OFF(threads), 1, 256, "concurrent computations (default: CPU count)"},
    {"level-threads", T_INT, OFF(level_threads), 1, 64,
     "threads one computation may use, divided among the computations running at once "
     "(default: CPU count, at most 8; 1: each computation on its request's thread alone)"},
    {"max-connections", T_INT, OFF(max_connections), 1, 100000, "open connections (default 256)"},
    {"max-connections-per-client", T_INT, OFF(max_connections_per_client), 0, 100000,
     "open connections of one client address (default 32; 0: no cap)"},
    {"connection-reserve", T_INT, OFF(connection_reserve), 0, 100000,
     "connections kept free: beyond max minus this, waiting ones are evicted (default 16, "
     "at most half of --max-connections)"},
    {"connection-timeout", T_INT, OFF(connection_timeout_s), 1, 86400,
     "idle timeout of a kept-alive connection in seconds (default 30)"},
    {"header-timeout", T_INT, OFF(header_timeout_s), 1, 3600,
     "seconds a new connection has to send its request headers (default 10)"},
    {"body-min-rate", T_INT, OFF(body_min_rate), 0, 1 << 30,
     "bytes/s a request body must average after --header-timeout (default 65536; 0: any)"},
    {"queue-timeout", T_INT, OFF(queue_timeout_s), 0, 3600,
     "seconds a computation waits for a free thread before 429 (default 30)"},
    {"drain-timeout", T_INT, OFF(drain_timeout_s), 0, 86400,
     "on SIGTERM or SIGINT, seconds the requests in flight may take to finish while no new "
     "connection is taken (default 60; 0: cut them at once; a second signal cuts them)"},
    {"max-sessions", T_INT, OFF(max_sessions), 1, 1000000, "live sessions (default 64)"},
    {"max-sessions-per-client", T_INT, OFF(max_sessions_per_client), 0, 1000000,
     "resident sessions one client address may have created (default: a quarter of --max-sessions, at least 1; 0: no cap; 429 beyond)"},
    {"max-stored-sessions-per-client", T_INT, OFF(max_stored_sessions_per_client), 0, 1000000,
     "unexpired sessions one client address may have created in a durable --store, resident or not (default: --max-sessions; 0: no cap; 429 beyond)"},
    {"ttl", T_INT, OFF(ttl_s), 1, API_MAX_TTL_S, "default session idle TTL in seconds (3600)"},
    {"max-ttl", T_INT, OFF(max_ttl_s), 1, API_MAX_TTL_S,
     "largest session TTL granted, seconds (default 86400; a larger ttl_s is clamped)"},
    {"session-rate", T_INT, OFF(session_rate), 1, 1000000,
     "sessions one client address may create per minute, in bursts of as many (default 30)"},
    {"max-body-bytes", T_SIZE, OFF(limits.max_body_bytes), 1, 1LL << 40,
     "request body bytes (default 64 MiB)"},
    {"max-vertices", T_U32, OFF(limits.max_vertices), 1, 0xfffffffeLL,
     "control vertices per complex (default 2000000)"},
    {"max-simplices", T_U32, OFF(limits.max_simplices), 1, 0xfffffffeLL,
     "control simplices per complex (default 8000000)"},
    {"max-cells", T_U64, OFF(limits.max_cells), 1, 1LL << 40,
     "top cells of one level (default 20000000)"},
    {"max-session-bytes", T_U64, OFF(limits.max_session_bytes), 1 << 20, 1LL << 50,
     "core memory per session (default 4 GiB)"},
    {"max-memory", T_U64, OFF(max_memory), 16LL << 20, 1LL << 50,
     "memory budget of all requests and sessions, bytes (default 3/4 of RAM or cgroup limit)"},
    {"max-client-body-bytes", T_U64, OFF(max_client_body_bytes), 0, 1LL << 50,
     "bytes of request bodies one client address may hold while they arrive (default: a "
     "quarter of --max-memory, at least --max-body-bytes; 0: no cap; 429 beyond)"},
    {"keep-memory", T_U64, OFF(keep_memory), 0, 1LL << 50,
     "bytes of freed level arrays kept about a second for the next build, within --max-memory "
     "(default: an eighth of it, at most 1 GiB; 0: none)"},
    {"fill-timeout", T_U32, OFF(limits.fill_seconds), 1, 86400,
     "seconds the TetGen fill of one request may take, all its entries together (default 60)"},
    {"fill-memory", T_U64, OFF(limits.fill_memory_bytes), 64LL << 20, 1LL << 46,
     "address space of the TetGen helper in bytes (default 2 GiB)"},
    {"max-embedded-vertices", T_U32, OFF(limits.max_embedded_vertices), 1, 0xfffffffeLL,
     "vertices of one embedded model (default 2000000)"},
    {"tetgen", T_STR, OFF(limits.tetgen_helper), 0, 0,
     "the TetGen helper (default: subdivd-tetgen beside subdivd, else on PATH)"},
    {"sse-heartbeat", T_INT, OFF(sse_heartbeat_s), 1, 3600,
     "seconds between heartbeat comments of an event stream (default 15; keep it below "
     "--connection-timeout)"},
    {"max-listeners", T_INT, OFF(max_listeners), 1, 10000,
     "event streams one session may have open (default 16; 429 beyond)"},
    {"cors-origin", T_STR, OFF(cors_origin), 0, 0, "allowed browser origin (default *)"},
    {"store", T_STR, OFF(store), 0, 0,
     "where sessions are kept: memory (default), sqlite:PATH or redis://HOST:PORT"},
    {"sync", T_SYNC, OFF(sync_full), 0, 0,
     "normal (a store write survives a crash of the daemon; default) or full (also a power loss)"},
    {"log-level", T_LOG, OFF(log_level), 0, 0, "error|warn|info|debug (default info)"},
    {"no-auth", T_FLAG, OFF(no_auth), 0, 0, "accept requests without bearer tokens (local dev)"},
};
#define NS (sizeof S / sizeof *S)

void config_usage(FILE *f)
{
    char exts[128];
    fprintf(f, "usage: subdivd [options]            run the daemon\n"
               "       subdivd refine INPUT.json --level L [--tags T.json] [--rules R.json]\n"
               "               [--repair] [--crease-angle DEG]\n"
               "               [--format F] [--parts P] [--slice nx,ny,nz,d] [--attributes A]\n"
               "               [--colormap NAME:min:max] [--octahedra tets|polyhedra]\n"
               "               [--names true|false] [--compress none|zlib] [--limit] [--threads N]\n"
               "               -o OUT%s\n"
               "       subdivd deform COMPLEX.json --embed MODEL.obj|.json [--level L]\n"
               "               [--outside refuse|fixed|nearest] [--moves MOVES.json] [--tags T.json]\n"
               "               [--rules R.json] -o OUT.obj|.json|.glb\n"
               "       subdivd --list-routes | --list-formats | --version\n"
               "       subdivd --healthcheck [URL]   (exit 0 if URL, default "
               "http://127.0.0.1:8080/healthz, answers 200)\n\noptions (each also read from "
               "SUBDIVD_<NAME>):\n", out_format_list(exts, sizeof exts, true, "|", "|"));
    for (size_t i = 0; i < NS; i++)
        fprintf(f, "  --%-27s %s\n", S[i].flag, S[i].help);
}

static int set(config *c, const setting *s, const char *v, const char *from)
{
    char *p = (char *)c + s->off;
    if (s->k == T_STR) {
        size_t cap = s->off == OFF(listen)                 ? sizeof c->listen
                     : s->off == OFF(limits.tetgen_helper) ? sizeof c->limits.tetgen_helper
                     : s->off == OFF(store)                ? sizeof c->store
                                                           : sizeof c->cors_origin;
        if (strlen(v) >= cap)
            goto bad;
        strcpy(p, v);
        return 0;
    }
    if (s->k == T_FLAG) {
        *(int *)p = !(!strcmp(v, "0") || !strcmp(v, "false") || !strcmp(v, "no"));
        return 0;
    }
    if (s->k == T_SYNC) {
        if (strcmp(v, "normal") && strcmp(v, "full"))
            goto bad;
        *(int *)p = !strcmp(v, "full");
        return 0;
    }
    if (s->k == T_LOG) {
        static const char *const lv[] = {"error", "warn", "info", "debug"};
        for (int i = 0; i < 4; i++)
            if (!strcmp(v, lv[i])) {
                *(int *)p = i;
                return 0;
            }
        goto bad;
    }
    char *end;
    errno = 0;
    long long x = strtoll(v, &end, 10);
    if (!*v || *end || errno || x < s->lo || x > s->hi)
        goto bad;
    switch (s->k) {
    case T_INT: *(int *)p = (int)x; break;
    case T_U32: *(uint32_t *)p = (uint32_t)x; break;
    case T_U64: *(uint64_t *)p = (uint64_t)x; break;
    case T_SIZE: *(size_t *)p = (size_t)x; break;
    default: break;
    }
    return 0;
bad:
    fprintf(stderr, "subdivd: bad value \"%s\" for %s%s (%s)\n", v, from, s->flag, s->help);
    return -1;
}

/* 3/4 of the memory the daemon may use: the physical RAM, or the cgroup's limit (cgroup v2
 * memory.max, v1 memory.limit_in_bytes) when it is smaller. */
static uint64_t default_max_memory(void)
{
    long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
    uint64_t ram = pages > 0 && page > 0 ? (uint64_t)pages * (uint64_t)page : 4ull << 30;
    static const char *const files[] = {"/sys/fs/cgroup/memory.max",
                                        "/sys/fs/cgroup/memory/memory.limit_in_bytes"};
    for (int i = 0; i < 2; i++) {
        FILE *f = fopen(files[i], "r");
        unsigned long long v;
        if (f && fscanf(f, "%llu", &v) == 1 && v > 0 && v < ram)
            ram = v;
        if (f)
            fclose(f);
    }
    return ram / 4 * 3;
}

int config_default_level_threads(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n <= 0 ? 1 : n > 8 ? 8 : (int)n;
}

int config_load(config *c, int argc, char **argv, int first, int *exit_code)
{
    memset(c, 0, sizeof *c);
    strcpy(c->listen, "127.0.0.1");
    c->port = 8080;
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    c->threads = n > 0 ? (int)n : 2;
    c->level_threads = config_default_level_threads();
    c->max_connections = 256;
    c->max_connections_per_client = 32;
    c->connection_reserve = 16;
    c->connection_timeout_s = 30;
    c->header_timeout_s = 10;
    c->body_min_rate = 65536;
    c->queue_timeout_s = 30;
    c->drain_timeout_s = 60;
    c->sse_heartbeat_s = 15;
    c->max_listeners = 16;
    c->max_sessions = API_DEFAULT_MAX_SESSIONS;
    c->max_sessions_per_client = -1; /* a quarter of --max-sessions, unless given */
    c->max_stored_sessions_per_client = -1; /* --max-sessions, unless given */
    c->ttl_s = API_DEFAULT_TTL_S;
    c->max_ttl_s = API_DEFAULT_MAX_TTL_S;
    c->session_rate = API_DEFAULT_SESSION_RATE;
    c->log_level = LOG_INFO;
    strcpy(c->cors_origin, "*");
    strcpy(c->store, "memory");
    c->max_memory = default_max_memory();
    c->keep_memory = UINT64_MAX; /* an eighth of --max-memory, at most 1 GiB, unless given */
    c->max_client_body_bytes = UINT64_MAX; /* a quarter of --max-memory, unless given */
    c->limits = api_default_limits();
    *exit_code = 2;
    for (size_t i = 0; i < NS; i++) {
        char env[64] = "SUBDIVD_";
        for (const char *f = S[i].flag; *f; f++) {
            size_t l = strlen(env);
            env[l] = *f == '-' ? '_' : (char)toupper((unsigned char)*f);
            env[l + 1] = 0;
        }
        const char *v = getenv(env);
        if (v && set(c, &S[i], v, "environment for --"))
            return 1;
    }
    for (int a = first; a < argc; a++) {
        if (!strcmp(argv[a], "-h") || !strcmp(argv[a], "--help")) {
            config_usage(stdout);
            *exit_code = 0;
            return 1;
        }
        const char *arg = argv[a];
        if (strncmp(arg, "--", 2)) {
            fprintf(stderr, "subdivd: unexpected argument \"%s\"\n", arg);
            config_usage(stderr);
            return 1;
        }
        arg += 2;
        const char *eq = strchr(arg, '=');
        size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
        size_t i = 0;
        while (i < NS && !(strlen(S[i].flag) == len && !strncmp(S[i].flag, arg, len)))
            i++;
        if (i == NS) {
            fprintf(stderr, "subdivd: unknown option \"%s\"\n", argv[a]);
            config_usage(stderr);
            return 1;
        }
        const char *v = eq ? eq + 1 : NULL;
        if (!v && S[i].k == T_FLAG)
            v = "1";
        if (!v) {
            if (a + 1 >= argc) {
                fprintf(stderr, "subdivd: --%s needs a value\n", S[i].flag);
                return 1;
            }
            v = argv[++a];
        }
        if (set(c, &S[i], v, "--"))
            return 1;
    }
    if (c->connection_reserve > c->max_connections / 2)
        c->connection_reserve = c->max_connections / 2;
    if (c->ttl_s > c->max_ttl_s)
        c->ttl_s = c->max_ttl_s;
    if (c->max_stored_sessions_per_client < 0)
        c->max_stored_sessions_per_client = c->max_sessions;
    if (c->max_sessions_per_client < 0)
        c->max_sessions_per_client = c->max_sessions / 4 > 1 ? c->max_sessions / 4 : 1;
    if (c->max_client_body_bytes == UINT64_MAX) {
        c->max_client_body_bytes = c->max_memory / 4;
        if (c->max_client_body_bytes <= c->limits.max_body_bytes) /* one largest body always */
            c->max_client_body_bytes = c->limits.max_body_bytes + 1;
    }
    if (c->keep_memory == UINT64_MAX)
        c->keep_memory = c->max_memory / 8 < (1ULL << 30) ? c->max_memory / 8 : 1ULL << 30;
    if (c->keep_memory > c->max_memory / 2)
        c->keep_memory = c->max_memory / 2;
    return 0;
}
