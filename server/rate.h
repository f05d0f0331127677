/* rate.h — per-client token buckets: how often one client may do a costly thing (create a
 * session).
 *
 * A client is its address: an IPv4 address, or the /64 prefix of an IPv6 one (one host usually
 * holds a whole /64, so its single addresses would be free to rotate); IPv4-mapped IPv6
 * addresses count as IPv4. Each client has a bucket of `burst` tokens refilled at `per_minute`;
 * taking from an empty bucket is refused with the seconds until its next token. The table holds
 * at most `max_clients` buckets: a new client takes the slot of the bucket that is fullest now
 * (a full bucket carries no information), the least recently used among equals — so the table's
 * memory is fixed, and a client forgotten this way starts again with a full bucket. One mutex;
 * a linear scan per take (session creation is rare, and the table a few thousand entries).
 */
#ifndef SUBDIVD_RATE_H
#define SUBDIVD_RATE_H

#include <stddef.h>
#include <stdint.h>
#include <sys/socket.h>

typedef struct rate rate;

/* The key of a client address (IPv4, or an IPv6 /64 prefix; unknown families share one key). */
typedef struct rate_key {
    uint8_t b[17];
} rate_key;

rate_key rate_key_of(const struct sockaddr *sa);

/* NULL when out of memory. */
rate *rate_new(double per_minute, double burst, size_t max_clients);
void rate_free(rate *rt);

/* Take one token of `key`'s bucket at monotonic time `now` (seconds): 0 when taken, else the
 * whole seconds (>= 1) until the bucket has a token again. */
int rate_take(rate *rt, const rate_key *key, double now);

#endif
