/* metrics.h — Prometheus counters of the daemon (text exposition format 0.0.4).
 *
 * Requests are counted, and their latency kept as a histogram, by route template (not raw path,
 * so the label set stays small), method and status; the seconds compute slots are held are
 * summed by kind of work (metrics_compute; kinds: route_kind, request.h). Gauges (sessions, cached cells, session
 * memory of the core, bytes held by api/ and server/) are sampled when /metrics is scraped.
 */
#ifndef SUBDIVD_METRICS_H
#define SUBDIVD_METRICS_H

#include <stdint.h>
#include <stdio.h>

void metrics_init(void);
void metrics_request(const char *route, const char *method, int status, double seconds);
void metrics_bytes(uint64_t n);
/* One hold of a compute slot: `kind` is a static string. */
void metrics_compute(const char *kind, double seconds);
/* Write every metric; the gauges are passed in (api_bytes: api_mem_in_use(), api/mem.h). */
void metrics_write(FILE *f, int sessions, uint64_t cached_cells, uint64_t session_bytes,
                   uint64_t api_bytes);
/* The connection guard's gauges and counters (guard.h). */
struct guard_stats;
void metrics_write_connections(FILE *f, const struct guard_stats *s);
/* The event streams (events.h: ev_stats). */
void metrics_write_events(FILE *f, unsigned listeners, uint64_t dropped);
/* The memory budget (--max-memory, api/mem.h): its size, what is counted against it, and the
 * allocations it refused. */
void metrics_write_budget(FILE *f, uint64_t budget, uint64_t used, uint64_t refusals);

#endif
