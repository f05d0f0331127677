/* seeds.h — what the plain builds of the fuzz targets share: `TARGET --write-seeds DIR` writes
 * the target's seed inputs, one file each, as the corpus `make fuzz` starts libFuzzer from (the
 * seeds live in the target's source, so the corpus is the repository's). */
#ifndef SUBDIVD_FUZZ_SEEDS_H
#define SUBDIVD_FUZZ_SEEDS_H

#include <stdio.h>
#include <string.h>

/* 1 if argv asks for the seeds (then they are written: *rc is the exit code), else 0. */
static inline int fuzz_write_seeds(int argc, char **argv, const char *const *seeds, size_t n, int *rc)
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

#endif
