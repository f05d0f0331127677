/* metrics.c — request counters and latency histograms, compute seconds, streamed bytes (see
 * metrics.h).
 *
 * One process-wide table under a mutex (held for a few comparisons per request); the series
 * are keyed by pointers to static strings (route templates, interned methods, compute kinds), at
 * most MAX_SERIES requests series and MAX_KINDS kinds — a new series beyond that is not counted. The gauges are not kept here:
 * the caller samples them when /metrics is scraped.
 */
#include "metrics.h"
#include "../api/mem.h"
#include "guard.h"
#include <pthread.h>
#include <stdatomic.h>
#include <string.h>

#define MAX_SERIES 512
static const double bucket_le[] = {0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05,
                                   0.1,    0.25,  0.5,    1,     2.5,  5,     10};
#define NBUCKETS (sizeof bucket_le / sizeof *bucket_le)
#define MAX_KINDS 32

static struct {
    pthread_mutex_t mu;
    int n;
    struct {
        const char *route, *method;
        int status;
        uint64_t count, bucket[NBUCKETS + 1]; /* latency: per bucket, not cumulated */
        double sum;
    } s[MAX_SERIES];
    int nk;
    struct { const char *kind; uint64_t count; double seconds; } k[MAX_KINDS];
    atomic_uint_fast64_t bytes;
} M = {.mu = PTHREAD_MUTEX_INITIALIZER};

void metrics_init(void) {}

void metrics_request(const char *route, const char *method, int status, double seconds)
{
    pthread_mutex_lock(&M.mu);
    int i = 0;
    while (i < M.n && !(M.s[i].status == status && !strcmp(M.s[i].route, route) &&
                        !strcmp(M.s[i].method, method)))
        i++;
    if (i == M.n && M.n < MAX_SERIES) {
        M.s[i].route = route; /* route templates and methods are static strings */
        M.s[i].method = method;
        M.s[i].status = status;
        M.s[i].count = 0;
        memset(M.s[i].bucket, 0, sizeof M.s[i].bucket);
        M.s[i].sum = 0;
        M.n++;
    }
    if (i < M.n) {
        size_t b = 0;
        while (b < NBUCKETS && seconds > bucket_le[b])
            b++;
        M.s[i].count++;
        M.s[i].bucket[b]++;
        M.s[i].sum += seconds;
    }
    pthread_mutex_unlock(&M.mu);
}

void metrics_compute(const char *kind, double seconds)
{
    pthread_mutex_lock(&M.mu);
    int i = 0;
    while (i < M.nk && strcmp(M.k[i].kind, kind))
        i++;
    if (i == M.nk && M.nk < MAX_KINDS) {
        M.k[i].kind = kind; /* a static string */
        M.k[i].count = 0;
        M.k[i].seconds = 0;
        M.nk++;
    }
    if (i < M.nk) {
        M.k[i].count++;
        M.k[i].seconds += seconds;
    }
    pthread_mutex_unlock(&M.mu);
}

void metrics_bytes(uint64_t n) { atomic_fetch_add(&M.bytes, n); }

/* One metric without labels: its HELP and TYPE lines and its value. */
static void sample(FILE *f, const char *name, const char *type, const char *help, uint64_t v)
{
    fprintf(f, "# HELP %s %s\n# TYPE %s %s\n%s %llu\n", name, help, name, type, name,
            (unsigned long long)v);
}

void metrics_write(FILE *f, int sessions, uint64_t cached_cells, uint64_t session_bytes,
                   uint64_t api_bytes)
{
    pthread_mutex_lock(&M.mu);
    fprintf(f, "# HELP subdivd_requests_total HTTP requests by route template, method and status.\n"
               "# TYPE subdivd_requests_total counter\n");
    for (int i = 0; i < M.n; i++)
        fprintf(f, "subdivd_requests_total{route=\"%s\",method=\"%s\",status=\"%d\"} %llu\n",
                M.s[i].route, M.s[i].method, M.s[i].status, (unsigned long long)M.s[i].count);
    fprintf(f, "# HELP subdivd_request_duration_seconds Time from request start to response queued, "
               "by route template, method and status.\n"
               "# TYPE subdivd_request_duration_seconds histogram\n");
    for (int i = 0; i < M.n; i++) {
        char labels[256];
        snprintf(labels, sizeof labels, "route=\"%s\",method=\"%s\",status=\"%d\"", M.s[i].route,
                 M.s[i].method, M.s[i].status);
        uint64_t cum = 0;
        for (size_t b = 0; b <= NBUCKETS; b++) {
            cum += M.s[i].bucket[b];
            if (b < NBUCKETS)
                fprintf(f, "subdivd_request_duration_seconds_bucket{%s,le=\"%g\"} %llu\n", labels,
                        bucket_le[b], (unsigned long long)cum);
            else
                fprintf(f, "subdivd_request_duration_seconds_bucket{%s,le=\"+Inf\"} %llu\n",
                        labels, (unsigned long long)cum);
        }
        fprintf(f, "subdivd_request_duration_seconds_sum{%s} %.6f\n", labels, M.s[i].sum);
        fprintf(f, "subdivd_request_duration_seconds_count{%s} %llu\n", labels,
                (unsigned long long)M.s[i].count);
    }
    fprintf(f, "# HELP subdivd_compute_seconds_total Seconds compute slots were held, by kind of "
               "work.\n# TYPE subdivd_compute_seconds_total counter\n");
    for (int i = 0; i < M.nk; i++)
        fprintf(f, "subdivd_compute_seconds_total{kind=\"%s\"} %.6f\n", M.k[i].kind,
                M.k[i].seconds);
    fprintf(f, "# HELP subdivd_compute_total Compute slots taken, by kind of work.\n"
               "# TYPE subdivd_compute_total counter\n");
    for (int i = 0; i < M.nk; i++)
        fprintf(f, "subdivd_compute_total{kind=\"%s\"} %llu\n", M.k[i].kind,
                (unsigned long long)M.k[i].count);
    pthread_mutex_unlock(&M.mu);
    sample(f, "subdivd_sessions", "gauge", "Live sessions.", (uint64_t)sessions);
    sample(f, "subdivd_cached_cells", "gauge",
           "Top cells of every computed level of every session.", cached_cells);
    sample(f, "subdivd_session_memory_bytes", "gauge", "Core memory held by all sessions.",
           session_bytes);
    sample(f, "subdivd_api_bytes", "gauge", "Memory held by api/ and server/ (requests, parsed "
           "bodies, models, output streams; api/mem.h).", api_bytes);
    sample(f, "subdivd_streamed_bytes_total", "counter", "Body bytes of streamed level responses.",
           atomic_load(&M.bytes));
}

void metrics_write_budget(FILE *f, uint64_t budget, uint64_t used, uint64_t refusals)
{
    sample(f, "subdivd_memory_budget_bytes", "gauge",
           "The memory budget of the daemon (--max-memory).", budget);
    sample(f, "subdivd_memory_used_bytes", "gauge", "Memory counted against the budget: api/ and "
           "server/ blocks, core blocks of every complex, input arrays, stream copies.", used);
    sample(f, "subdivd_memory_refusals_total", "counter",
           "Allocations the memory budget refused.", refusals);
    uint64_t hits, misses;
    api_mem_keep_counts(&hits, &misses);
    sample(f, "subdivd_kept_bytes", "gauge", "Big blocks of freed levels kept for the next "
           "build (--keep-memory), counted in subdivd_memory_used_bytes.", api_mem_kept());
    sample(f, "subdivd_kept_reused_total", "counter",
           "Big core blocks taken from the kept ones (no fresh pages).", hits);
    sample(f, "subdivd_kept_mapped_total", "counter", "Big core blocks mapped anew.", misses);
}

void metrics_write_connections(FILE *f, const guard_stats *s)
{
    fprintf(f, "# HELP subdivd_connections Open connections by phase: waiting for a request's "
               "headers, receiving its body, handled or answered.\n"
               "# TYPE subdivd_connections gauge\n"
               "subdivd_connections{phase=\"waiting\"} %u\n"
               "subdivd_connections{phase=\"receiving\"} %u\n"
               "subdivd_connections{phase=\"working\"} %u\n",
            s->waiting, s->receiving, s->working);
    fprintf(f, "# HELP subdivd_connections_closed_total Connections the guard closed: evicted under "
               "pressure, or past the header, body-rate or idle deadline.\n"
               "# TYPE subdivd_connections_closed_total counter\n"
               "subdivd_connections_closed_total{reason=\"evicted\"} %llu\n"
               "subdivd_connections_closed_total{reason=\"header_timeout\"} %llu\n"
               "subdivd_connections_closed_total{reason=\"body_timeout\"} %llu\n"
               "subdivd_connections_closed_total{reason=\"idle_timeout\"} %llu\n",
            (unsigned long long)s->evicted, (unsigned long long)s->header_timeouts,
            (unsigned long long)s->body_timeouts, (unsigned long long)s->idle_timeouts);
}

void metrics_write_events(FILE *f, unsigned listeners, uint64_t dropped)
{
    sample(f, "subdivd_event_listeners", "gauge",
           "Open event streams (GET /v1/sessions/{id}/events).", listeners);
    sample(f, "subdivd_event_listeners_dropped_total", "counter",
           "Event streams ended because their client did not read (its buffer filled).", dropped);
}
