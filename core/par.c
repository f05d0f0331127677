/* par.c — optional parallel loops over both (or more) cores (sd_options.threads).
 *
 * A parallel region splits its work into `n` parts by fixed rules (contiguous ranges) and each
 * part writes its own disjoint outputs with the very arithmetic the serial code uses, so results
 * are the same bytes whatever the number of threads. The parts are taken in turn by the calling
 * thread and the region's helper threads: which thread runs a part does not matter, and on a
 * shared machine a thread that starts late or a core another process holds leaves its parts to
 * the others instead of the region waiting for it. Loops whose results do not depend on where
 * they are cut (each item's outputs its own) may be cut into more parts than threads
 * (sdi_par_dyn), so the parts balance too.
 *
 * The helpers: a call that runs many regions in a row (sd_complex_level: about ten a level)
 * brackets them with sdi_pool_begin / sdi_pool_end, and its regions are run by helpers started
 * once for the call (at its first region with parts to share), which wait for the next region
 * by spinning a while, then sleeping on a condition variable; such a region is cut from fewer
 * items (SD_PAR_MIN_POOL). A region outside a bracket (or called from a part) has a pool of its
 * own, its helpers started and joined with it (~20-60 us a thread here): one way to share parts
 * either way. If a thread cannot be created the others take its parts. The
 * pool belongs to the calling thread (thread-local), so concurrent calls from other threads
 * (the daemon's requests) each have their own, and nothing outlives the bracket.
 */
#include "internal.h"
#include <pthread.h>
#include <stdatomic.h>
#include <stdalign.h>
#include <stdlib.h>
#include <string.h>

static _Thread_local uint32_t par_min = SD_PAR_MIN;

uint32_t sdi_par_parts(int threads, uint64_t work)
{
    if (threads <= 1 || work < par_min)
        return 1;
    uint64_t n = work / (par_min / 2), t = threads < SD_PAR_MAXT ? (uint64_t)threads : SD_PAR_MAXT;
    return (uint32_t)(n < t ? n : t);
}

/* ---- the helpers of a bracket ------------------------------------------------------------
 * A region of the pool is published as a generation: its function and argument in the pool,
 * then `claim` = generation << 32 | part count << 16 | next part. A part is claimed by a
 * compare-and-swap of `claim`, so only while that generation is current: a helper that wakes
 * late for a region that is over claims nothing, and the caller never waits for a helper to
 * wake, only for the parts being run (`done`). */
#define SPIN_ROUNDS 4000     /* pauses (~80 us here) a waiting thread spins before it sleeps */
#define POOL_MAXPARTS 0xffff /* parts of a pool region (the width of claim's fields) */

typedef struct pool {
    uint32_t want, nhelpers, depth; /* helpers wanted (started at the first parallel region) */
    bool started, running;          /* running: a region is being run (one called from its parts
                                     * creates threads) */
    uint32_t gen;                   /* the caller's count of regions */
    sd_part_fn fn; /* the current region's (read only by a thread holding one of its parts) */
    void *arg;
    _Atomic uint64_t claim;
    atomic_uint done;     /* parts of the current region finished */
    atomic_bool waiting;  /* the caller sleeps until the last part is done */
    alignas(64) atomic_uint pub; /* the generation helpers wait for (UINT32_MAX: stop), on a line
                                  * of its own, away from the claims */
    atomic_uint sleepers;
    pthread_t tid[SD_PAR_MAXT];
    pthread_mutex_t mu;
    pthread_cond_t cv, cv_done;
} pool;

static _Thread_local pool *cur_pool;

static inline void cpu_relax(void)
{
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
}

/* Runs parts of generation g while it is current and has parts left; the thread that finishes
 * the last part wakes the caller if it sleeps. */
static void take_gen(pool *q, uint32_t g)
{
    uint64_t c = atomic_load_explicit(&q->claim, memory_order_acquire);
    for (;;) {
        uint32_t next = (uint32_t)c & POOL_MAXPARTS, n = (uint32_t)(c >> 16) & POOL_MAXPARTS;
        if ((uint32_t)(c >> 32) != g || next >= n)
            return;
        if (atomic_compare_exchange_weak_explicit(&q->claim, &c, c + 1, memory_order_acquire,
                                                  memory_order_acquire)) {
            q->fn(q->arg, next, n);
            if (atomic_fetch_add(&q->done, 1) + 1 == n && atomic_load(&q->waiting)) {
                pthread_mutex_lock(&q->mu);
                pthread_cond_signal(&q->cv_done);
                pthread_mutex_unlock(&q->mu);
            }
            c = atomic_load_explicit(&q->claim, memory_order_acquire);
        }
    }
}

static void *helper(void *p)
{
    pool *q = p;
    uint32_t seen = 0;
    for (;;) {
        uint32_t g = atomic_load_explicit(&q->pub, memory_order_acquire);
        for (int i = 0; g == seen && i < SPIN_ROUNDS; i++) {
            cpu_relax();
            g = atomic_load_explicit(&q->pub, memory_order_acquire);
        }
        if (g == seen) {
            pthread_mutex_lock(&q->mu);
            atomic_fetch_add(&q->sleepers, 1);
            while ((g = atomic_load(&q->pub)) == seen)
                pthread_cond_wait(&q->cv, &q->mu);
            atomic_fetch_sub(&q->sleepers, 1);
            pthread_mutex_unlock(&q->mu);
        }
        if (g == UINT32_MAX)
            return NULL;
        seen = g;
        take_gen(q, g);
    }
}

/* Publishes generation g (a region, or UINT32_MAX: stop) and wakes the helpers that sleep. */
static void publish(pool *q, uint32_t g)
{
    atomic_store(&q->pub, g);
    if (atomic_load(&q->sleepers)) {
        pthread_mutex_lock(&q->mu);
        pthread_cond_broadcast(&q->cv);
        pthread_mutex_unlock(&q->mu);
    }
}

/* A pool for up to `want` helpers (none started yet); NULL without memory. */
static pool *pool_new(uint32_t want)
{
    /* (aligned as its type asks: pub has a cache line of its own) */
    const size_t a = alignof(pool), n = (sizeof(pool) + a - 1) / a * a;
    pool *q = aligned_alloc(a, n);
    if (!q)
        return NULL;
    memset(q, 0, sizeof *q);
    pthread_mutex_init(&q->mu, NULL);
    pthread_cond_init(&q->cv, NULL);
    pthread_cond_init(&q->cv_done, NULL);
    q->want = want < SD_PAR_MAXT ? want : SD_PAR_MAXT - 1;
    return q;
}

static void start_helpers(pool *q)
{
    q->started = true;
    while (q->nhelpers < q->want && pthread_create(&q->tid[q->nhelpers], NULL, helper, q) == 0)
        q->nhelpers++;
}

static void pool_free(pool *q)
{
    if (!q)
        return;
    publish(q, UINT32_MAX);
    for (uint32_t i = 0; i < q->nhelpers; i++)
        pthread_join(q->tid[i], NULL);
    pthread_cond_destroy(&q->cv);
    pthread_cond_destroy(&q->cv_done);
    pthread_mutex_destroy(&q->mu);
    free(q);
}

void sdi_pool_begin(int threads)
{
    if (cur_pool) {
        cur_pool->depth++;
        return;
    }
    if (threads <= 1 || !(cur_pool = pool_new((uint32_t)threads - 1)))
        return;
    cur_pool->depth = 1;
    par_min = SD_PAR_MIN_POOL;
}

void sdi_pool_end(void)
{
    if (!cur_pool || --cur_pool->depth)
        return;
    pool_free(cur_pool);
    cur_pool = NULL;
    par_min = SD_PAR_MIN;
}

/* A region run by the pool's helpers and the caller, who spins a while for the parts still
 * being run, then sleeps until the last is done. */
static void pool_region(pool *q, uint32_t nparts, sd_part_fn fn, void *arg)
{
    q->running = true;
    uint32_t g = ++q->gen;
    if (g == UINT32_MAX) /* the stop value: skip it (after 2^32 regions) */
        g = q->gen = 1;
    q->fn = fn;
    q->arg = arg;
    atomic_store_explicit(&q->done, 0, memory_order_relaxed);
    atomic_store_explicit(&q->claim, (uint64_t)g << 32 | (uint64_t)nparts << 16, memory_order_release);
    publish(q, g);
    take_gen(q, g);
    for (int i = 0; i < SPIN_ROUNDS && atomic_load_explicit(&q->done, memory_order_acquire) < nparts; i++)
        cpu_relax();
    if (atomic_load_explicit(&q->done, memory_order_acquire) < nparts) {
        atomic_store(&q->waiting, true);
        pthread_mutex_lock(&q->mu);
        while (atomic_load(&q->done) < nparts)
            pthread_cond_wait(&q->cv_done, &q->mu);
        pthread_mutex_unlock(&q->mu);
        atomic_store(&q->waiting, false);
    }
    q->running = false;
}

/* nthreads threads (the caller and nthreads - 1 helpers) take the nparts parts in turn: the
 * helpers of the caller's bracket, started at its first region with parts to share (if none
 * could be, regions are cut as outside a bracket again), or else — outside a bracket, or in a
 * region called from a part — helpers started for this region alone. Without any, the caller
 * runs every part. */
static void run_region(uint32_t nthreads, uint32_t nparts, sd_part_fn fn, void *arg)
{
    if (nparts == 1) {
        fn(arg, 0, 1);
        return;
    }
    pool *q = cur_pool, *own = NULL;
    if (q && !q->running && !q->started) {
        start_helpers(q);
        if (!q->nhelpers)
            par_min = SD_PAR_MIN;
    }
    if (!q || q->running || !q->nhelpers) {
        if ((q = own = pool_new(nthreads - 1)))
            start_helpers(q);
    }
    if (q && q->nhelpers)
        pool_region(q, nparts, fn, arg);
    else
        for (uint32_t p = 0; p < nparts; p++)
            fn(arg, p, nparts);
    pool_free(own);
}

void sdi_par(int threads, uint64_t work, sd_part_fn fn, void *arg)
{
    uint32_t n = sdi_par_parts(threads, work);
    run_region(n, n, fn, arg);
}

void sdi_par_dyn(int threads, uint64_t work, uint32_t per_thread, sd_part_fn fn, void *arg)
{
    uint32_t n = sdi_par_parts(threads, work);
    if (per_thread > POOL_MAXPARTS / SD_PAR_MAXT) /* (such a region's cut does not matter) */
        per_thread = POOL_MAXPARTS / SD_PAR_MAXT;
    run_region(n, n == 1 ? 1 : n * per_thread, fn, arg);
}

void sdi_range(uint64_t n, uint32_t part, uint32_t nparts, uint64_t *lo, uint64_t *hi)
{
    *lo = n * part / nparts;
    *hi = n * (part + 1) / nparts;
}
