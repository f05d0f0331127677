/* mem.c — the allocation wrapper of api/ and server/ (see mem.h for the contract).
 *
 * Each api_* block is a block of n + HDR bytes with n stored in front, so api_free knows what to
 * subtract, and the capacity of its mapping after it (0: the C library's block); HDR is 16 so
 * the caller's pointer keeps malloc's alignment. While big blocks are kept (api_mem_keep_set),
 * an api_* block of KEEP_MIN bytes or more is a mapping of its size class like the core's big
 * blocks (below), counted in in_use by its capacity, and kept when freed; else it is malloc's.
 * The global count is one relaxed atomic add per call (the daemon's threads share it; nothing orders
 * against it). The per-thread meter is a thread-local pointer, so metering costs nothing on
 * threads that set none. The failure hook is one relaxed load while it is off.
 *
 * jansson is pointed at api_malloc/api_free by a constructor, before main and so before any
 * json_t exists: every binary that links api/ (the daemon, the offline mode, the tests) frees
 * jansson's strings with api_free, and none can mix the two allocators by forgetting a call.
 * This file and the api_plain_* functions are the only callers of malloc, realloc and free in
 * api/ and server/, besides the refine bodies and open_memstream's buffers that mem.h names.
 */
#include "mem.h"
#include "../core/sd.h"
#include <jansson.h>
#include <malloc.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>

#define HDR 16
#define KEEP_MIN ((size_t)256 << 10) /* big blocks (below): the daemon's mmap threshold */
_Static_assert(2 * sizeof(size_t) <= HDR, "a block's header holds its size and capacity");

static atomic_size_t in_use;
static atomic_size_t elsewhere;        /* core blocks and reservations */
static size_t budget;                  /* 0: none */
static _Atomic uint64_t budget_refusals;
static _Thread_local api_mem_meter *meter;
static _Atomic uint64_t fail_in;      /* allocations until the next injected failure; 0: off */
static _Atomic uint64_t fail_every;
static _Atomic uint64_t failures;
static _Thread_local uint64_t refused_here; /* allocations refused on this thread */

/* Whether this allocation is the one the test hook fails. */
static bool injected(void)
{
    uint64_t n = atomic_load_explicit(&fail_in, memory_order_relaxed);
    if (!n)
        return false;
    if (n > 1) {
        atomic_fetch_sub_explicit(&fail_in, 1, memory_order_relaxed);
        return false;
    }
    atomic_store_explicit(&fail_in, atomic_load(&fail_every), memory_order_relaxed);
    atomic_fetch_add(&failures, 1);
    return true;
}

static bool keep_give_way(void);
/* Big api blocks (see the keep below): a block of class cap for n + HDR bytes, or NULL to use
 * malloc (nothing kept); *fresh when its bytes are a new mapping's zeros. Released with
 * big_release(b, cap). */
static bool big_due(size_t total); /* whether a block of total bytes is one */
static void *big_alloc(size_t total, size_t *cap, bool *fresh);
static void big_release(void *b, size_t cap);
static void *big_resize(void *b, size_t *cap, size_t total);

/* Whether n more bytes fit the budget, counted in `on` (in_use or elsewhere) when they do. Kept
 * blocks (below) give way first: a refusal is only ever for what is really held. */
static bool within_budget(atomic_size_t *on, size_t n)
{
    for (int tries = 0;; tries++) {
        size_t was = atomic_fetch_add_explicit(on, n, memory_order_relaxed);
        if (!budget)
            return true;
        size_t other = on == &in_use ? atomic_load_explicit(&elsewhere, memory_order_relaxed)
                                     : atomic_load_explicit(&in_use, memory_order_relaxed);
        size_t total = was + n + other;
        size_t room = budget;
        if (n <= API_MEM_SMALL)
            room += budget / 32 > (1u << 20) ? budget / 32 : (1u << 20);
        if (total <= room && total >= n)
            return true;
        atomic_fetch_sub_explicit(on, n, memory_order_relaxed);
        if (tries == 0 && keep_give_way())
            continue;
        atomic_fetch_add_explicit(&budget_refusals, 1, memory_order_relaxed);
        if (meter) {
            meter->over_budget++;
            /* what the request holds and asked for passes the whole budget: waiting for others
             * to give some back cannot help */
            uint64_t need = (uint64_t)(meter->net > 0 ? meter->net : 0) +
                            (uint64_t)(meter->held_elsewhere > 0 ? meter->held_elsewhere : 0) + n;
            if (need > budget && need > meter->beyond)
                meter->beyond = need;
            if (need > meter->need)
                meter->need = need;
        }
        return false;
    }
}

/* Charge n bytes to this thread's meter; false when its limit refuses them. */
static bool charge(size_t n)
{
    api_mem_meter *m = meter;
    if (!m)
        return true;
    m->moved += n;
    if (m->limit && m->net + (int64_t)n > (int64_t)m->limit) {
        m->refused++;
        return false;
    }
    m->net += (int64_t)n;
    if (m->net > m->peak)
        m->peak = m->net;
    return true;
}

static void credit(size_t n)
{
    if (meter) {
        meter->net -= (int64_t)n;
        meter->moved += n;
    }
}

/* A C-library block of total bytes counted in in_use, or NULL (refused, counted as such). */
static unsigned char *small_alloc(size_t total)
{
    if (!within_budget(&in_use, total)) {
        refused_here++;
        return NULL;
    }
    unsigned char *b = malloc(total);
    if (!b) {
        atomic_fetch_sub_explicit(&in_use, total, memory_order_relaxed);
        refused_here++;
        return NULL;
    }
    sd_advise_huge(b, total); /* as the core's blocks (core/alloc.c) */
    return b;
}

/* An api block of n bytes: *fresh when they are zeros already. */
static void *api_alloc(size_t n, bool *fresh)
{
    *fresh = false;
    if (n > SIZE_MAX - HDR || injected() || !charge(n + HDR)) {
        refused_here++;
        return NULL;
    }
    size_t cap = 0; /* set by big_alloc when the block is a big one, refused or not */
    unsigned char *b = big_alloc(n + HDR, &cap, fresh);
    if (!b && !cap)
        b = small_alloc(n + HDR);
    if (!b) {
        credit(n + HDR);
        return NULL;
    }
    memcpy(b, &n, sizeof n);
    memcpy(b + sizeof n, &cap, sizeof cap);
    return b + HDR;
}

void *api_malloc(size_t n)
{
    bool fresh;
    return api_alloc(n, &fresh);
}

void *api_calloc(size_t n, size_t size)
{
    if (size && n > SIZE_MAX / size) {
        refused_here++;
        return NULL;
    }
    bool fresh;
    void *p = api_alloc(n * size, &fresh);
    if (p && !fresh)
        memset(p, 0, n * size);
    return p;
}

static void block_head(void *p, size_t *n, size_t *cap)
{
    const unsigned char *b = (const unsigned char *)p - HDR;
    memcpy(n, b, sizeof *n);
    memcpy(cap, b + sizeof *n, sizeof *cap);
}

void api_free(void *p)
{
    if (!p)
        return;
    unsigned char *b = (unsigned char *)p - HDR;
    size_t n, cap;
    block_head(p, &n, &cap);
    credit(n + HDR);
    if (cap) {
        big_release(b, cap);
        return;
    }
    atomic_fetch_sub_explicit(&in_use, n + HDR, memory_order_relaxed);
    free(b);
}

/* The C library's realloc on the whole block (header included), so a growing buffer is moved
 * by mremap rather than copied once it is mmapped; the meter is charged the growth first. A
 * block of a size class (big_alloc) is remapped to the new size's class, or moved to a C-library
 * block below KEEP_MIN bytes. */
void *api_realloc(void *p, size_t n)
{
    if (!p)
        return api_malloc(n);
    unsigned char *b = (unsigned char *)p - HDR;
    size_t old, cap;
    block_head(p, &old, &cap);
    size_t grow = n > old ? n - old : 0;
    if (n > SIZE_MAX - HDR || injected() || !charge(grow)) {
        refused_here++;
        return NULL;
    }
    if (cap && n + HDR < KEEP_MIN) { /* below the big blocks: a C-library block */
        bool counted = within_budget(&in_use, n + HDR);
        unsigned char *q = counted ? malloc(n + HDR) : NULL;
        if (n < old)
            credit(old - n);
        if (!q) { /* this never fails: the block (capacity cap > n + HDR) stays as it is */
            if (counted)
                atomic_fetch_sub_explicit(&in_use, n + HDR, memory_order_relaxed);
            memcpy(b, &n, sizeof n);
            return p;
        }
        memcpy(q + HDR, p, old < n ? old : n);
        memcpy(q, &n, sizeof n);
        memset(q + sizeof n, 0, sizeof cap);
        big_release(b, cap);
        return q + HDR;
    }
    if (cap) {
        unsigned char *q = big_resize(b, &cap, n + HDR);
        if (!q) {
            if (grow) {
                credit(grow);
                return NULL;
            }
            q = b; /* a shrink that could not be remapped stays as it is */
        }
        if (n < old)
            credit(old - n);
        memcpy(q, &n, sizeof n);
        memcpy(q + sizeof n, &cap, sizeof cap);
        return q + HDR;
    }
    if (big_due(n + HDR)) { /* a C-library block grown into a big one */
        credit(grow);
        void *q = api_malloc(n);
        if (!q)
            return NULL;
        memcpy(q, p, old);
        api_free(p);
        return q;
    }
    if (grow && !within_budget(&in_use, grow)) {
        credit(grow);
        refused_here++;
        return NULL;
    }
    unsigned char *q = realloc(b, n + HDR);
    if (!q) {
        atomic_fetch_sub_explicit(&in_use, grow, memory_order_relaxed);
        credit(grow);
        refused_here++;
        return NULL;
    }
    if (grow)
        sd_advise_huge(q, n + HDR);
    if (n < old) {
        atomic_fetch_sub_explicit(&in_use, old - n, memory_order_relaxed);
        credit(old - n);
    }
    memcpy(q, &n, sizeof n);
    return q + HDR;
}

void *api_memdup(const void *p, size_t n)
{
    void *q = api_malloc(n ? n : 1);
    if (q && n)
        memcpy(q, p, n);
    return q;
}

char *api_strdup(const char *s)
{
    return api_memdup(s, strlen(s) + 1);
}

/* The result of a C-library allocation, counted as refused when NULL. */
static void *plain(void *p)
{
    if (!p)
        refused_here++;
    return p;
}

void *api_plain_malloc(size_t n) { return plain(injected() ? NULL : malloc(n)); }
void *api_plain_calloc(size_t n, size_t size) { return plain(injected() ? NULL : calloc(n, size)); }
void *api_plain_realloc(void *p, size_t n) { return plain(injected() ? NULL : realloc(p, n)); }
void api_plain_free(void *p) { free(p); }

size_t api_mem_in_use(void) { return atomic_load_explicit(&in_use, memory_order_relaxed); }

static double mono(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + t.tv_nsec * 1e-9;
}

static _Atomic int64_t trim_asked; /* ms (monotonic, + 1) of the last api_mem_trim_soon; 0: none */

void api_mem_trim_soon(void) { atomic_store(&trim_asked, (int64_t)(mono() * 1000) + 1); }

/* The heaps' free memory back to the system if it was asked for over half a second ago. */
static void heap_trim_due(void)
{
    int64_t asked = atomic_load(&trim_asked);
    if (asked && (int64_t)(mono() * 1000) + 1 - asked > 500 &&
        atomic_compare_exchange_strong(&trim_asked, &asked, 0))
        malloc_trim(0);
}

void api_mem_set_budget(size_t bytes) { budget = bytes; }

size_t api_mem_budget(void) { return budget; }

size_t api_mem_budget_used(void)
{
    return atomic_load_explicit(&in_use, memory_order_relaxed) +
           atomic_load_explicit(&elsewhere, memory_order_relaxed);
}

uint64_t api_mem_budget_refusals(void) { return atomic_load(&budget_refusals); }

bool api_mem_reserve(size_t n)
{
    if (!within_budget(&elsewhere, n)) {
        refused_here++;
        return false;
    }
    if (meter) {
        meter->moved += n;
        meter->held_elsewhere += (int64_t)n;
    }
    return true;
}

void api_mem_unreserve(size_t n)
{
    atomic_fetch_sub_explicit(&elsewhere, n, memory_order_relaxed);
    if (meter) {
        meter->moved += n;
        meter->held_elsewhere -= (int64_t)n;
    }
}

/* The core's blocks from the C library, reserved in the budget. */
static void *core_alloc_plain(size_t n, void *ud)
{
    (void)ud;
    if (!api_mem_reserve(n))
        return NULL;
    void *p = malloc(n);
    if (!p)
        api_mem_unreserve(n);
    return p;
}

static void core_release_plain(void *p, size_t n, void *ud)
{
    (void)ud;
    free(p);
    api_mem_unreserve(n);
}

/* ---- the core's big blocks, kept for the next build -------------------------------------
 * A level's arrays are written once, front to back, and a fresh page costs more than the
 * writing (docs/BENCHMARKS.md): a core block of KEEP_MIN bytes or more is mapped by itself, in
 * a size class (rounded up to an eighth of its power of two, at least 64 KiB; from 2 MiB on on
 * a 2 MiB boundary, asking for transparent huge pages), and when freed it
 * is kept, pages and all, for the next block of its class — the transient arrays of a build,
 * the levels of the model a change replaced, a deleted session's — up to `keep_limit` bytes, for
 * at most KEEP_IDLE seconds (api_mem_keep_trim, called by the daemon's main loop), so the
 * resident size still follows what the daemon holds. Kept blocks stay counted against the
 * budget; any allocation or reservation that would not fit drops them all first (within_budget).
 * Under AddressSanitizer every block is malloc's, so that it keeps watching them, and none is
 * kept. */
#ifndef SD_UNDER_ASAN
#define KEEP_GRAIN ((size_t)64 << 10)
#define KEEP_SLOTS 1024
#define KEEP_IDLE 1.0

typedef struct kept {
    void *p;
    size_t cap;
    double t;          /* when it was given back */
} kept;
static pthread_mutex_t keep_mu = PTHREAD_MUTEX_INITIALIZER;
static kept keep[KEEP_SLOTS];
static int nkeep;                      /* oldest first */
static size_t keep_bytes;
static _Atomic size_t keep_limit;      /* 0: none kept */
static _Atomic uint64_t keep_hits, keep_misses;
static bool keep_poison; /* SUBDIVD_KEEP_POISON=1: a kept block is filled with 0xff bytes (NaN
                          * doubles, huge ids) when taken, so tests show any reader of a block
                          * the core did not write (tests/run_all.sh sets it) */

static size_t keep_class(size_t n)
{
    size_t g = (size_t)1 << (63 - __builtin_clzll((unsigned long long)n)); /* power of two <= n */
    g = g / 8 > KEEP_GRAIN ? g / 8 : KEEP_GRAIN;
    return n > SIZE_MAX - g ? n : (n + g - 1) / g * g;
}

/* A mapping of n fresh zero bytes of its own (0 < n <= SIZE_MAX / 2), or NULL; from 2 MiB on
 * it starts on a 2 MiB boundary and asks for transparent huge pages over all of it, so it faults
 * in 2 MiB at a time. unmap_block(p, n), with the same n, gives it back. */
static void *map_block(size_t n)
{
    const size_t thp = (size_t)2 << 20;
    if (n == 0 || n > SIZE_MAX / 2)
        return NULL;
    if (n < thp) {
        void *p = mmap(NULL, n, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        return p == MAP_FAILED ? NULL : p;
    }
    unsigned char *p = mmap(NULL, n + thp, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS,
                            -1, 0);
    if (p == MAP_FAILED)
        return NULL;
    size_t head = (thp - (uintptr_t)p % thp) % thp;
    if (head)
        munmap(p, head);
    /* the rest past n, from the page after it (munmap takes whole pages) */
    size_t page = (size_t)4096, end = (head + n + page - 1) / page * page;
    if (end < n + thp)
        munmap(p + end, n + thp - end);
#ifdef MADV_HUGEPAGE
    (void)madvise(p + head, n, MADV_HUGEPAGE); /* advice: refused or not, all works */
#endif
    return p + head;
}

static void unmap_block(void *p, size_t n)
{
    if (p)
        munmap(p, n);
}

/* Take out the entries given back before `older`, and the oldest until `need` more bytes fit
 * the limit; unmapped after the lock. How many were taken out. */
static int keep_drop(size_t need, double older)
{
    kept gone[KEEP_SLOTS];
    int ng = 0, k = 0;
    pthread_mutex_lock(&keep_mu);
    for (int i = 0; i < nkeep; i++)
        if (keep[i].t < older || keep_bytes + need > atomic_load(&keep_limit)) {
            keep_bytes -= keep[i].cap;
            gone[ng++] = keep[i];
        } else
            keep[k++] = keep[i];
    nkeep = k;
    pthread_mutex_unlock(&keep_mu);
    for (int i = 0; i < ng; i++) {
        unmap_block(gone[i].p, gone[i].cap);
        /* the reservation only: the meter of whoever gave the block back counted that already,
         * and the thread dropping it (a request making room, the main loop) never held it */
        atomic_fetch_sub_explicit(&elsewhere, gone[i].cap, memory_order_relaxed);
    }
    return ng;
}

static bool keep_give_way(void) { return keep_drop(SIZE_MAX / 2, HUGE_VAL) > 0; }

void api_mem_keep_set(size_t bytes)
{
    const char *poison = getenv("SUBDIVD_KEEP_POISON");
    keep_poison = poison && *poison == '1';
    atomic_store(&keep_limit, bytes);
    keep_drop(0, bytes ? 0 : HUGE_VAL);
}

void api_mem_keep_trim(void)
{
    keep_drop(0, mono() - KEEP_IDLE);
    heap_trim_due();
}

size_t api_mem_kept(void)
{
    pthread_mutex_lock(&keep_mu);
    size_t n = keep_bytes;
    pthread_mutex_unlock(&keep_mu);
    return n;
}

void api_mem_keep_counts(uint64_t *hits, uint64_t *misses)
{
    *hits = atomic_load(&keep_hits);
    *misses = atomic_load(&keep_misses);
}

/* A kept block of class cap (the latest given back), or NULL. Its reservation passes on. */
static void *keep_take(size_t cap)
{
    void *p = NULL;
    pthread_mutex_lock(&keep_mu);
    for (int i = nkeep - 1; i >= 0; i--)
        if (keep[i].cap == cap) {
            p = keep[i].p;
            keep_bytes -= cap;
            memmove(&keep[i], &keep[i + 1], (size_t)(nkeep - i - 1) * sizeof *keep);
            nkeep--;
            break;
        }
    pthread_mutex_unlock(&keep_mu);
    return p;
}

/* Keep block p of class cap, making room by dropping the oldest; false if it is not kept. */
static bool keep_put(void *p, size_t cap)
{
    size_t limit = atomic_load(&keep_limit);
    if (cap > limit / 2) /* one block never takes the whole room */
        return false;
    keep_drop(cap, mono() - KEEP_IDLE);
    bool kept_it = false;
    pthread_mutex_lock(&keep_mu);
    if (nkeep < KEEP_SLOTS && keep_bytes + cap <= limit) {
        keep[nkeep++] = (kept){p, cap, mono()};
        keep_bytes += cap;
        kept_it = true;
    }
    pthread_mutex_unlock(&keep_mu);
    return kept_it;
}

/* A block of class cap: a kept one (its reservation moved from `elsewhere` to `on`) or a new
 * mapping (*fresh) counted in `on`; NULL when the budget (kept blocks giving way first) or the
 * system refuses it. `used` bytes of a kept one are poisoned under SUBDIVD_KEEP_POISON=1. */
static void *class_block(size_t cap, atomic_size_t *on, size_t used, bool *fresh)
{
    *fresh = false;
    void *p = keep_take(cap);
    if (p) {
        if (on != &elsewhere) { /* added first: the total never dips below what is held */
            atomic_fetch_add_explicit(on, cap, memory_order_relaxed);
            atomic_fetch_sub_explicit(&elsewhere, cap, memory_order_relaxed);
        }
        if (keep_poison)
            memset(p, 0xff, used);
        atomic_fetch_add_explicit(&keep_hits, 1, memory_order_relaxed);
        return p;
    }
    if (!within_budget(on, cap)) {
        refused_here++;
        return NULL;
    }
    if (!(p = map_block(cap))) {
        atomic_fetch_sub_explicit(on, cap, memory_order_relaxed);
        refused_here++;
        return NULL;
    }
    atomic_fetch_add_explicit(&keep_misses, 1, memory_order_relaxed);
    *fresh = true;
    return p;
}

/* Block p of class cap given back, counted in `on` till now: kept (its bytes reserved in
 * `elsewhere`), or unmapped and uncounted. */
static void class_release(void *p, size_t cap, atomic_size_t *on)
{
    if (on != &elsewhere) {
        atomic_fetch_add_explicit(&elsewhere, cap, memory_order_relaxed);
        atomic_fetch_sub_explicit(on, cap, memory_order_relaxed);
    }
    if (keep_put(p, cap))
        return;
    unmap_block(p, cap);
    atomic_fetch_sub_explicit(&elsewhere, cap, memory_order_relaxed);
}

static void *core_alloc(size_t n, void *ud)
{
    if (n < KEEP_MIN)
        return core_alloc_plain(n, ud);
    size_t cap = keep_class(n);
    bool fresh;
    void *p = class_block(cap, &elsewhere, n, &fresh);
    if (p && meter) {
        meter->moved += cap;
        meter->held_elsewhere += (int64_t)cap;
    }
    return p;
}

static void core_release(void *p, size_t n, void *ud)
{
    if (n < KEEP_MIN) {
        core_release_plain(p, n, ud);
        return;
    }
    size_t cap = keep_class(n);
    if (meter) {
        meter->moved += cap;
        meter->held_elsewhere -= (int64_t)cap;
    }
    class_release(p, cap, &elsewhere);
}

/* ---- the api's big blocks ---------------------------------------------------------------
 * While blocks are kept (keep_limit > 0), an api_* block of KEEP_MIN bytes or more, header
 * included, is a block of its size class like the core's, counted in in_use by its capacity and
 * kept when freed; its header says the capacity (0: malloc's block). */
static bool big_due(size_t total) { return total >= KEEP_MIN && atomic_load(&keep_limit); }

/* A block for total bytes: of its class when big_due (*cap set; NULL if refused), else NULL
 * with *cap 0 (the caller takes malloc's). */
static void *big_alloc(size_t total, size_t *cap, bool *fresh)
{
    *cap = 0;
    *fresh = false;
    if (!big_due(total))
        return NULL;
    *cap = keep_class(total);
    return class_block(*cap, &in_use, total, fresh);
}

static void big_release(void *b, size_t cap) { class_release(b, cap, &in_use); }

/* Block b of capacity *cap resized to hold total (>= KEEP_MIN) bytes: remapped to total's class
 * (the kernel moves the pages, nothing is copied), the difference counted in in_use; NULL (b
 * left as it was) when the budget or the system refuses the growth. */
static void *big_resize(void *b, size_t *cap, size_t total)
{
    size_t want = keep_class(total);
    if (want == *cap)
        return b;
    if (want > *cap && !within_budget(&in_use, want - *cap)) {
        refused_here++;
        return NULL;
    }
    void *q = mremap(b, *cap, want, MREMAP_MAYMOVE);
    if (q == MAP_FAILED) {
        if (want > *cap)
            atomic_fetch_sub_explicit(&in_use, want - *cap, memory_order_relaxed);
        refused_here++;
        return NULL;
    }
    if (want < *cap)
        atomic_fetch_sub_explicit(&in_use, *cap - want, memory_order_relaxed);
#ifdef MADV_HUGEPAGE
    /* the whole mapping, as map_block: advice on a part would split it in two mappings, and a
     * later mremap of the block (which must lie in one) would fail */
    (void)madvise(q, want, MADV_HUGEPAGE);
#endif
    *cap = want;
    return q;
}

#else /* AddressSanitizer: the C library's blocks, none kept */
static bool keep_give_way(void) { return false; }
static bool big_due(size_t total)
{
    (void)total;
    return false;
}
static void *big_alloc(size_t total, size_t *cap, bool *fresh)
{
    (void)total;
    *cap = 0;
    *fresh = false;
    return NULL;
}
static void big_release(void *b, size_t cap)
{
    (void)b;
    (void)cap;
}
static void *big_resize(void *b, size_t *cap, size_t total)
{
    (void)b;
    (void)cap;
    (void)total;
    return NULL;
}
void api_mem_keep_set(size_t bytes) { (void)bytes; }
void api_mem_keep_trim(void) { heap_trim_due(); }
size_t api_mem_kept(void) { return 0; }

void api_mem_keep_counts(uint64_t *hits, uint64_t *misses)
{
    *hits = 0;
    *misses = 0;
}

#define core_alloc core_alloc_plain
#define core_release core_release_plain
#endif

sd_allocator api_mem_core_allocator(void)
{
    sd_allocator a = {core_alloc, core_release, NULL};
    return a;
}

api_mem_meter *api_mem_meter_set(api_mem_meter *m)
{
    api_mem_meter *old = meter;
    meter = m;
    return old;
}

void api_mem_fail_at(uint64_t nth, uint64_t every)
{
    atomic_store(&fail_every, every);
    atomic_store(&fail_in, nth);
}

uint64_t api_mem_failures(void) { return atomic_load(&failures); }

uint64_t api_mem_refused_here(void) { return refused_here; }

__attribute__((constructor)) static void install_jansson_allocator(void)
{
    json_set_alloc_funcs(api_malloc, api_free);
}
