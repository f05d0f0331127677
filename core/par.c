/* par.c — optional parallel loops over both (or more) cores (sd_options.threads).
 *
 * A parallel region splits its work into `n` parts by fixed rules (contiguous ranges, or two
 * different tasks) and each part writes its own disjoint outputs with the very arithmetic the
 * serial code uses, so results are the same bytes whatever the number of threads. Part 0 runs in
 * the calling thread, the others in threads created for the region and joined at its end (a
 * region is a level's loop over millions of items: creating a thread costs ~20 us). If a thread
 * cannot be created its part runs in the caller. No state outlives a call.
 */
#include "internal.h"
#include <pthread.h>

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

typedef struct two {
    void (*f[2])(void *);
    void *a[2];
} two;

static void run_two(void *p, uint32_t part, uint32_t n)
{
    two *t = p;
    if (n == 1) {
        t->f[0](t->a[0]);
        t->f[1](t->a[1]);
    } else {
        t->f[part](t->a[part]);
    }
}

void sdi_par2(int threads, uint64_t work, void (*f0)(void *), void *a0, void (*f1)(void *), void *a1)
{
    two t = {{f0, f1}, {a0, a1}};
    sdi_par(threads > 2 ? 2 : threads, work, run_two, &t);
}

void sdi_range(uint64_t n, uint32_t part, uint32_t nparts, uint64_t *lo, uint64_t *hi)
{
    *lo = n * part / nparts;
    *hi = n * (part + 1) / nparts;
}
