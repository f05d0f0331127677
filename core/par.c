/* par.c — optional parallel loops over both (or more) cores (sd_options.threads).
 *
 * A parallel region splits its work into `n` parts by fixed rules (contiguous ranges) and each
 * part writes its own disjoint outputs with the very arithmetic the serial code uses, so results
 * are the same bytes whatever the number of threads. The parts are taken in turn by the calling
 * thread and the threads created for the region (joined at its end; a region is a level's loop
 * over millions of items: creating a thread costs ~20 us): which thread runs a part does not
 * matter, and on a shared machine a thread that starts late or a core another process holds
 * leaves its parts to the others instead of the region waiting for it. If a thread cannot be
 * created the others take its parts. No state outlives a call. Loops whose results do not depend
 * on where they are cut (each item's outputs its own) may be cut into more parts than threads
 * (sdi_par_dyn), so the parts balance too.
 */
#include "internal.h"
#include <pthread.h>
#include <stdatomic.h>

uint32_t sdi_par_parts(int threads, uint64_t work)
{
    if (threads <= 1 || work < SD_PAR_MIN)
        return 1;
    uint64_t n = work / (SD_PAR_MIN / 2), t = threads < SD_PAR_MAXT ? (uint64_t)threads : SD_PAR_MAXT;
    return (uint32_t)(n < t ? n : t);
}

/* A region's parts, claimed one at a time (one atomic add per part, not per item). */
typedef struct region {
    sd_part_fn fn;
    void *arg;
    uint32_t nparts;
    atomic_uint next;
} region;

static void take_parts(region *g)
{
    for (uint32_t p; (p = atomic_fetch_add_explicit(&g->next, 1, memory_order_relaxed)) < g->nparts;)
        g->fn(g->arg, p, g->nparts);
}

static void *run_thread(void *p)
{
    take_parts(p);
    return NULL;
}

/* nthreads threads (the caller and nthreads - 1 created) take the nparts parts in turn. */
static void run_region(uint32_t nthreads, uint32_t nparts, sd_part_fn fn, void *arg)
{
    if (nparts == 1) {
        fn(arg, 0, 1);
        return;
    }
    region g = {fn, arg, nparts, 0};
    pthread_t tid[SD_PAR_MAXT];
    bool started[SD_PAR_MAXT] = {false};
    for (uint32_t i = 1; i < nthreads; i++)
        started[i] = pthread_create(&tid[i], NULL, run_thread, &g) == 0;
    take_parts(&g);
    for (uint32_t i = 1; i < nthreads; i++)
        if (started[i])
            pthread_join(tid[i], NULL);
}

void sdi_par(int threads, uint64_t work, sd_part_fn fn, void *arg)
{
    uint32_t n = sdi_par_parts(threads, work);
    run_region(n, n, fn, arg);
}

void sdi_par_dyn(int threads, uint64_t work, uint32_t per_thread, sd_part_fn fn, void *arg)
{
    uint32_t n = sdi_par_parts(threads, work);
    run_region(n, n == 1 ? 1 : n * per_thread, fn, arg);
}

void sdi_range(uint64_t n, uint32_t part, uint32_t nparts, uint64_t *lo, uint64_t *hi)
{
    *lo = n * part / nparts;
    *hi = n * (part + 1) / nparts;
}
