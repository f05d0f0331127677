/* plain.h — what the fuzz targets share for their plain builds (and fuzz_api for its choices):
 * a deterministic random source, the mutations of a seed, and `TARGET --write-seeds DIR`, which
 * writes the target's seed inputs, one file each, as the corpus `make fuzz` starts libFuzzer from
 * (the seeds live in the target's source, so the corpus is the repository's). */
#ifndef SUBDIVD_FUZZ_PLAIN_H
#define SUBDIVD_FUZZ_PLAIN_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* xorshift64: never 0 */
static uint64_t fuzz_rng = 88172645463325252ull;

static inline uint32_t fuzz_rnd(uint32_t n)
{
    fuzz_rng ^= fuzz_rng << 13;
    fuzz_rng ^= fuzz_rng >> 7;
    fuzz_rng ^= fuzz_rng << 17;
    return n ? (uint32_t)(fuzz_rng % n) : 0;
}

/* 1 to `most` edits of buf[0..n), each at a random place: insert one of the tokens, delete 1-4
 * bytes, replace a byte (by one of `alphabet`, any byte when NULL), or truncate. The new length,
 * at most cap. */
static inline size_t fuzz_mutate(char *buf, size_t n, size_t cap, uint32_t most,
                                 const char *const *tokens, size_t ntokens, const char *alphabet)
{
    for (int m = 1 + (int)fuzz_rnd(most); m > 0; m--) {
        size_t at = fuzz_rnd((uint32_t)n + 1);
        switch (fuzz_rnd(4)) {
        case 0: { /* insert a token */
            const char *t = tokens[fuzz_rnd((uint32_t)ntokens)];
            size_t k = strlen(t);
            if (n + k < cap) {
                memmove(buf + at + k, buf + at, n - at);
                memcpy(buf + at, t, k);
                n += k;
            }
            break;
        }
        case 1: { /* delete a few bytes */
            size_t k = 1 + fuzz_rnd(4);
            if (at + k <= n) {
                memmove(buf + at, buf + at + k, n - at - k);
                n -= k;
            }
            break;
        }
        case 2: /* replace a byte */
            if (at < n)
                buf[at] = alphabet ? alphabet[fuzz_rnd((uint32_t)strlen(alphabet))]
                                   : (char)fuzz_rnd(256);
            break;
        default: /* truncate */
            n = at;
        }
    }
    return n;
}

/* 1 if argv asks for the seeds (then they are written: *rc is the exit code), else 0. */
static inline int fuzz_write_seeds(int argc, char **argv, const char *const *seeds, size_t n,
                                   int *rc)
{
    if (argc < 3 || strcmp(argv[1], "--write-seeds"))
        return 0;
    *rc = 0;
    for (size_t i = 0; i < n && !*rc; i++) {
        char path[4096];
        snprintf(path, sizeof path, "%s/seed-%03zu", argv[2], i);
        FILE *f = fopen(path, "wb");
        if (!f || fwrite(seeds[i], 1, strlen(seeds[i]), f) != strlen(seeds[i]))
            *rc = 2;
        if (f && fclose(f))
            *rc = 2;
        if (*rc)
            fprintf(stderr, "%s: cannot write %s\n", argv[0], path);
    }
    return 1;
}

/* The plain program's arguments: `--write-seeds DIR` (the seeds are written; returns the exit
 * code), or [ITERATIONS [SEED]] (*iters, default as given, and the random source seeded;
 * returns -1: go on). */
static inline int fuzz_plain_args(int argc, char **argv, const char *const *seeds, size_t n,
                                  long *iters)
{
    int rc;
    if (fuzz_write_seeds(argc, argv, seeds, n, &rc))
        return rc;
    if (argc > 1)
        *iters = atol(argv[1]);
    if (argc > 2)
        fuzz_rng = strtoull(argv[2], NULL, 10) | 1;
    return -1;
}

#endif
