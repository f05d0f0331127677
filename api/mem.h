/* mem.h — the one allocation wrapper of api/ and server/ (the core has its own, core/alloc.c).
 *
 * Every block api/ and server/ allocate goes through api_malloc and its siblings, and so does
 * jansson (json_set_alloc_funcs, installed before main): a 16-byte header keeps each block's
 * size, so frees are counted too. What it gives:
 *   - api_mem_in_use(): the bytes of live blocks, headers included, a big block's by its size
 *     class while big blocks are kept (see api_mem_keep_set; exported on /metrics as
 *     subdivd_api_bytes);
 *   - a per-thread meter (api_mem_meter_set): what one thread — one request, the daemon being
 *     one thread per connection — allocates while it is set, with an optional limit past which
 *     its allocations fail: the hook for a per-request memory budget;
 *   - a test hook (api_mem_fail_at) that fails the Nth allocation from now, and every Kth after,
 *     so tests can walk the failure paths of every api/ entry point (tests/api/faults.c).
 * A failed allocation returns NULL like malloc; callers answer 503 out-of-memory and leave the
 * session as it was.
 *
 * Ownership: free a block with the family that allocated it. api_free releases api_malloc,
 * api_calloc, api_realloc, api_strdup and api_memdup blocks and everything jansson hands out
 * (json_dumps strings). The api_plain_* functions allocate from the C library itself (uncounted,
 * though the test hook still fails them) for blocks that change hands with code that releases
 * them with free(): sd_refine's results, adopted into an api_input, and the refine bodies of
 * api/refine.c, kept as they were for the merge with the core's refactor, which allocate with
 * malloc and free the input's arrays, tags and overrides they work on. So the arrays of an
 * api_input (xyz, size, idx, attribute data), of api_tags and the overrides of api_rules are
 * plain blocks (model.h). The other C-library blocks are open_memstream's buffers (the C library
 * owns them; their text is copied or freed at once, each place says which). Plain blocks are not
 * counted one by one (they change hands with free()); the input arrays are counted against the
 * memory budget as a whole instead, reserved by their api_input (model.h).
 */
#ifndef SUBDIVD_API_MEM_H
#define SUBDIVD_API_MEM_H

#include "../core/sd.h"
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

void *api_malloc(size_t n);
void *api_calloc(size_t n, size_t size);
void *api_realloc(void *p, size_t n);   /* NULL: p is left as it was */
void api_free(void *p);
char *api_strdup(const char *s);
void *api_memdup(const void *p, size_t n);

/* C-library blocks (see above): free() or api_plain_free releases them. */
void *api_plain_malloc(size_t n);
void *api_plain_calloc(size_t n, size_t size);
void *api_plain_realloc(void *p, size_t n);
void api_plain_free(void *p);

/* Bytes of live api_* blocks (jansson's included), headers included. */
size_t api_mem_in_use(void);

/* What one thread allocated and freed while the meter was set (bytes, headers included). */
typedef struct api_mem_meter {
    int64_t net;        /* allocated minus freed: can go below 0 when older blocks are freed */
    int64_t peak;       /* the largest `net` seen */
    uint64_t limit;     /* > 0: an allocation that would take `net` above it fails */
    uint64_t refused;   /* allocations the limit refused */
    uint64_t over_budget; /* allocations and reservations the memory budget refused */
    int64_t held_elsewhere; /* core blocks and reservations taken minus given back (can go
                         * below 0 when older ones are given back) */
    uint64_t beyond;    /* the largest of those refused where the thread's own api and core
                         * blocks and reservations plus the request passed the whole budget
                         * (bytes: what it needed), else 0 */
    uint64_t moved;     /* bytes taken and given back in all, core blocks and reservations too */
    uint64_t need;      /* the largest of what the thread held and asked for where the budget
                         * refused it, past the whole budget or not (bytes) */
} api_mem_meter;

/* ---- the memory budget -------------------------------------------------------------------
 * One number bounds what the daemon holds (--max-memory): the api_* blocks, the core's blocks
 * (every complex allocates through api_mem_core_allocator) and what is reserved for blocks
 * allocated otherwise (the input arrays of model.h, api_input_reserve). An allocation or
 * reservation that would take the total past the budget fails like an allocation that found no
 * memory, and is counted as over_budget on the thread's meter, so the transport can tell a full
 * budget (503 memory-budget, retry later) from a machine out of memory. Blocks of at most
 * API_MEM_SMALL bytes may go past the budget by its headroom (a 32nd of it, at least 1 MiB):
 * the bookkeeping of requests and the problem that refuses one never fail for want of a few
 * bytes. 0 (the default) means no budget. */
#define API_MEM_SMALL (64u << 10)

void api_mem_set_budget(size_t bytes);
size_t api_mem_budget(void);
/* Bytes counted against the budget: api blocks + core blocks + reservations. */
size_t api_mem_budget_used(void);
/* Refusals of the budget so far, all threads (/metrics). */
uint64_t api_mem_budget_refusals(void);
/* Count n bytes allocated elsewhere against the budget: false (nothing counted) when they do
 * not fit. api_mem_unreserve gives them back. */
bool api_mem_reserve(size_t n);
void api_mem_unreserve(size_t n);
/* The allocator of core complexes (sd_options.allocator): C-library blocks counted against the
 * budget. */
sd_allocator api_mem_core_allocator(void);
/* Big blocks (256 KiB and more: the core's, and while blocks are kept the api_* ones too,
 * mapped in size classes) given back are kept for the next block of their size class, up to
 * `bytes` in all (0, the default: none), each for about a second (see mem.c); they stay
 * counted against the budget and give way to any allocation or reservation that would not fit
 * beside them.
 * api_mem_keep_trim drops those idle for over a second (the daemon calls it 5 times a second),
 * and trims glibc's heaps (malloc_trim) when api_mem_trim_soon asked for it (after a request
 * that moved many bytes) over half a second before: back-to-back builds reuse those pages.
 * api_mem_kept says how many bytes are kept; the counts say how many big blocks were taken
 * from the kept ones and how many were mapped anew. */
void api_mem_keep_set(size_t bytes);
void api_mem_keep_trim(void);
void api_mem_trim_soon(void);
size_t api_mem_kept(void);
void api_mem_keep_counts(uint64_t *hits, uint64_t *misses);

/* Set this thread's meter (NULL: none); returns the one it replaces. */
api_mem_meter *api_mem_meter_set(api_mem_meter *m);

/* Allocations refused on this thread so far (out of memory, a meter's limit, the test hook):
 * compare before and after a library call that does not say why it failed (json_loadb). */
uint64_t api_mem_refused_here(void);

/* Test hook: the nth allocation from now fails (1: the next one), and then every `every`-th
 * one (0: only that one); nth = 0 turns it off. Counts api_* and api_plain_* calls of every
 * thread. Returns nothing; api_mem_failures() counts the failures injected so far. */
void api_mem_fail_at(uint64_t nth, uint64_t every);
uint64_t api_mem_failures(void);

#endif
