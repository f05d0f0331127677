/* par.c — optional parallel loops over both (or more) cores (sd_options.threads).
 *
 * A parallel region splits its work into `n` parts by fixed rules (contiguous ranges) and each
 * part writes its own disjoint outputs with the very arithmetic the serial code uses, so results
 * are the same bytes whatever the number of threads. Part 0 runs in the calling thread, the
 * others in threads created for the region and joined at its end (a region is a level's loop
 * over millions of items: creating a thread costs ~20 us). If a thread cannot be created its part
 * runs in the caller. No state outlives a call. Loops whose results do not depend on where they
 * are cut (each item's outputs its own) may instead be cut into more chunks than threads, taken
 * in turn (sdi_par_dyn): the same bytes, whoever computes a chunk.
 */
#include "internal.h"
#include <pthread.h>
#include <stdatomic.h>

typedef struct job {
    sd_part_fn fn;
    void *arg;
    uint32_t part, nparts;
} job;

static void *run_job(void *p)
{
    job *j = p;
    j->fn(j->arg, j->part, j->nparts);
    return NULL;
}

uint32_t sdi_par_parts(int threads, uint64_t work)
{
    if (threads <= 1 || work < SD_PAR_MIN)
        return 1;
    uint64_t n = work / (SD_PAR_MIN / 2), t = threads < SD_PAR_MAXT ? (uint64_t)threads : SD_PAR_MAXT;
    return (uint32_t)(n < t ? n : t);
}

void sdi_par(int threads, uint64_t work, sd_part_fn fn, void *arg)
{
    enum { MAXT = SD_PAR_MAXT };
    uint32_t n = sdi_par_parts(threads, work);
    job jobs[MAXT];
    pthread_t tid[MAXT];
    bool started[MAXT] = {false};
    for (uint32_t i = 1; i < n; i++) {
        jobs[i] = (job){fn, arg, i, n};
        started[i] = pthread_create(&tid[i], NULL, run_job, &jobs[i]) == 0;
    }
    fn(arg, 0, n);
    for (uint32_t i = 1; i < n; i++)
        if (started[i])
            pthread_join(tid[i], NULL);
        else
            fn(arg, i, n);
}

/* A region cut into chunks taken in turn: each thread takes the next chunk when done with its
 * last, so a core that another process slows down (a shared machine) or a thread that starts
 * late does less, instead of the region waiting for it. One atomic add per chunk, not per item. */
typedef struct dyn {
    sd_part_fn fn;
    void *arg;
    uint32_t nchunks;
    atomic_uint next;
} dyn;

static void run_dyn(void *p, uint32_t part, uint32_t n)
{
    dyn *d = p;
    (void)part;
    (void)n;
    for (uint32_t c; (c = atomic_fetch_add_explicit(&d->next, 1, memory_order_relaxed)) < d->nchunks;)
        d->fn(d->arg, c, d->nchunks);
}

void sdi_par_dyn(int threads, uint64_t work, uint32_t per_thread, sd_part_fn fn, void *arg)
{
    uint32_t n = sdi_par_parts(threads, work);
    if (n == 1) {
        fn(arg, 0, 1);
        return;
    }
    dyn d = {fn, arg, n * per_thread, 0};
    sdi_par(threads, work, run_dyn, &d);
}

void sdi_range(uint64_t n, uint32_t part, uint32_t nparts, uint64_t *lo, uint64_t *hi)
{
    *lo = n * part / nparts;
    *hi = n * (part + 1) / nparts;
}
