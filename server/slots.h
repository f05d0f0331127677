/* slots.h — the compute slots of the daemon: `threads` computations at once, shared fairly
 * between sessions (slots.c).
 *
 * A request that computes (builds a complex, computes a level, runs a fill) takes a slot and
 * gives it back when done; one that finds none free waits, at most the queue timeout, and is then
 * refused (429 + Retry-After). When a slot comes free it goes to the waiter whose session holds
 * the fewest slots, the earliest of those first: one session asking for much work at once gets
 * its turns between the others', not before them. Waiting happens without any model lock held
 * beyond the waiter's own session's (api_level_compute takes the model's lock first).
 */
#ifndef SUBDIVD_SLOTS_H
#define SUBDIVD_SLOTS_H

typedef struct slots slots;

/* n slots (>= 1); NULL for lack of memory. */
slots *slots_new(int n);
void slots_free(slots *s);
/* A slot for `owner` (a session, compared by address; NULL for none), waiting at most
 * timeout_s seconds: 0, or -1 when none came free in time. */
int slots_take(slots *s, const void *owner, int timeout_s);
/* Give back a slot `owner` took. */
void slots_give(slots *s, const void *owner);
/* Slots held by `owner` now. */
int slots_held(slots *s, const void *owner);
/* Slots taken now, by anyone. */
int slots_busy(slots *s);

#endif
