/* bandwidth — the memory ceiling two threads can reach on this machine, for docs/BENCHMARKS.md.
 *
 *   bandwidth [MIB] [REPS]
 *
 * Copies MIB MiB (default 128) from one buffer to another, written beforehand so no page is
 * touched for the first time, with one thread and then with two (each its half), and prints the
 * best seconds of REPS (default 10) for each and their ratio: what a level's writing can gain at
 * most from a second core. Then what a cold run pays: MIB MiB mapped afresh (advised as huge
 * pages, as core/alloc.c does) written once, page by page touched for the first time, then
 * written again. */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

typedef struct half {
    char *dst;
    const char *src;
    size_t n;
} half;

static void *copy(void *p)
{
    half *h = p;
    memcpy(h->dst, h->src, h->n);
    return NULL;
}

int main(int argc, char **argv)
{
    size_t n = (size_t)(argc > 1 ? atoi(argv[1]) : 128) << 20;
    int reps = argc > 2 ? atoi(argv[2]) : 10;
    char *src = malloc(n), *dst = malloc(n);
    if (!src || !dst || reps < 1)
        return 1;
    memset(src, 1, n);
    memset(dst, 2, n);
    double best[2] = {1e9, 1e9};
    for (int r = 0; r < reps; r++)
        for (int k = 0; k < 2; k++) { /* alternating: one thread, then two */
            half h[2] = {{dst, src, k ? n / 2 : n}, {dst + n / 2, src + n / 2, n - n / 2}};
            pthread_t t;
            double t0 = now();
            if (k && pthread_create(&t, NULL, copy, &h[1]))
                return 1;
            copy(&h[0]);
            if (k)
                pthread_join(t, NULL);
            double dt = now() - t0;
            if (dt < best[k])
                best[k] = dt;
        }
    printf("memcpy %zu MiB: 1 thread %.4f s (%.1f GB/s), 2 threads %.4f s (%.1f GB/s), ratio %.2f\n",
           n >> 20, best[0], n / best[0] * 1e-9, best[1], n / best[1] * 1e-9, best[0] / best[1]);
    free(src);
    free(dst);
    char *p = mmap(NULL, n, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED)
        return 1;
#ifdef MADV_HUGEPAGE
    madvise(p, n, MADV_HUGEPAGE);
#endif
    double t0 = now();
    memset(p, 1, n);
    double t1 = now();
    memset(p, 2, n);
    double t2 = now();
    printf("first touch %zu MiB: %.4f s (%.2f GB/s), written again %.4f s (%.1f GB/s)\n", n >> 20,
           t1 - t0, n / (t1 - t0) * 1e-9, t2 - t1, n / (t2 - t1) * 1e-9);
    munmap(p, n);
    return 0;
}
