/* limits.h — every configurable limit of the service in one place, with its default.
 *
 * The daemon fills api_limits from flags and environment (server/config.c); the offline mode
 * uses the defaults. Limits are checked before anything is allocated for a request: body bytes
 * from Content-Length, element counts before parsing arrays, the cells of a level from the split
 * table (sd_complex_counts) before computing it.
 */
#ifndef SUBDIVD_LIMITS_H
#define SUBDIVD_LIMITS_H

#include <stddef.h>
#include <stdbool.h>
#include <stdint.h>

#define API_DEFAULT_MAX_BODY_BYTES      (64u << 20)   /* request body */
#define API_DEFAULT_MAX_VERTICES        2000000u      /* control vertices */
#define API_DEFAULT_MAX_SIMPLICES       8000000u      /* control simplices */
#define API_DEFAULT_MAX_CELLS           20000000ull   /* top cells of one level */
#define API_DEFAULT_MAX_SESSION_BYTES   (4ull << 30)  /* core memory of one session */
#define API_DEFAULT_MAX_SESSIONS        64
#define API_DEFAULT_TTL_S               3600
#define API_DEFAULT_MAX_TTL_S           86400         /* a larger ttl_s is granted as this */
#define API_MAX_TTL_S                   (7 * 24 * 3600) /* the largest ttl_s accepted (422) */
#define API_DEFAULT_SESSION_RATE        30            /* sessions per client and minute */
#define API_RATE_CLIENTS                4096          /* clients the session rate remembers */
#define API_MAX_JSON_DEPTH              16
#define API_MAX_ATTRIBUTES              16
#define API_MAX_ATTRIBUTE_NAME          48
#define API_DEFAULT_FILL_SECONDS        60            /* wall deadline of one request's fill */
#define API_DEFAULT_FILL_MEMORY_BYTES   (2ull << 30)  /* address space of the TetGen helper */
#define API_MAX_FILL_SURFACES           16            /* entries of "fill" in one request */
#define API_MAX_PATH_BYTES              256           /* a request's decoded path (414 beyond) */
#define API_MAX_QUERY_PARAMS            64            /* parameters of a request's query (400) */
#define API_PACK_MIN_BYTES              4096          /* body arrays packed beside the tree (packed.h) */
#define API_MAX_VALUE                   1e15          /* magnitude of coordinates and attribute values */
#define API_MAX_EMBEDDED                8             /* embedded models of one session */
#define API_MAX_EMBED_NAME              48            /* an embedded model's name */
#define API_MAX_REPAIRED_LISTED         1000          /* dropped simplices a repair lists (all counted) */
#define API_DEFAULT_MAX_EMBEDDED_VERTICES 2000000u    /* vertices of one embedded model */

typedef struct api_limits {
    size_t max_body_bytes;
    uint32_t max_vertices;
    uint32_t max_simplices;
    uint64_t max_cells;
    uint64_t max_session_bytes;
    /* TetGen fill (api/fill.c): limits of the helper process, and where it is */
    uint32_t fill_seconds;        /* wall deadline of one request's fill, all entries together;
                                     each helper's CPU-time limit is what is left of it */
    uint64_t fill_memory_bytes;   /* RLIMIT_AS of the helper */
    char tetgen_helper[256];      /* "" = subdivd-tetgen beside the running binary, else on PATH */
    uint32_t max_embedded_vertices; /* of one embedded model (PUT /embedded/{name}) */
    bool batch;                   /* the offline `subdivd refine`: levels are written, not edited,
                                     so the core builds no edit index (DECISIONS 46); the daemon
                                     leaves it false */
} api_limits;

static inline api_limits api_default_limits(void)
{
    api_limits l = {API_DEFAULT_MAX_BODY_BYTES, API_DEFAULT_MAX_VERTICES, API_DEFAULT_MAX_SIMPLICES,
                    API_DEFAULT_MAX_CELLS, API_DEFAULT_MAX_SESSION_BYTES, API_DEFAULT_FILL_SECONDS,
                    API_DEFAULT_FILL_MEMORY_BYTES, "", API_DEFAULT_MAX_EMBEDDED_VERTICES, false};
    return l;
}

#endif
