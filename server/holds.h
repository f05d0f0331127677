/* holds.h — bytes held per client: what the bodies a client is sending take while they arrive.
 *
 * A body's buffer is taken from the memory budget when its Content-Length arrives (or as a
 * chunked body grows), and held until its request ends. A client sending many bodies slowly
 * (each at --body-min-rate, over --max-connections-per-client connections) could hold the whole
 * budget for minutes and turn every other client's upload away. So each client address (a
 * rate_key: IPv4, or an IPv6 /64) may hold at most `cap` bytes of bodies at once; past it the
 * request is refused (429 client-bodies) and the client's other bodies go on. The table has one
 * entry per client with a body in flight, at most one per connection; one mutex, a linear scan
 * per body (bodies are few next to requests). */
#ifndef SUBDIVD_HOLDS_H
#define SUBDIVD_HOLDS_H

#include "rate.h"
#include <stdbool.h>
#include <stddef.h>

typedef struct holds holds;

/* cap 0: no limit. NULL when out of memory. */
holds *holds_new(size_t cap, size_t max_clients);
void holds_free(holds *h);
/* Add n bytes to key's hold: false (nothing added) when that would pass the cap, or when the
 * table is full. */
bool holds_take(holds *h, const rate_key *key, size_t n);
/* Give n bytes of key's hold back (the entry goes with its last byte). */
void holds_give(holds *h, const rate_key *key, size_t n);
/* The cap, and the bytes key holds now. */
size_t holds_cap(const holds *h);
size_t holds_held(holds *h, const rate_key *key);

#endif
