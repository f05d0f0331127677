/* keep_test: the big core and api blocks api/mem.c keeps between builds
 * (tests/python/test_kept_memory.py).
 *
 * Through api_mem_core_allocator, as a complex allocates: a block given back is kept and handed
 * out again for the next block of its size class (the same pages, filled with 0xff bytes when
 * SUBDIVD_KEEP_POISON=1), not for another class; the kept bytes stay within the limit (oldest
 * dropped first) and counted against the budget; kept blocks idle for over a second go back;
 * a reservation that would not fit beside the kept blocks drops them instead of failing. Big
 * api_* blocks are kept blocks too (zeroed by api_calloc, remapped by api_realloc).
 * Under AddressSanitizer every block is malloc's and none is kept. Exit 0 when every check
 * holds. */
#include "../../api/mem.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define MIB ((size_t)1 << 20)

static int passed, failed;

static void check(int ok, const char *what)
{
    if (ok)
        passed++;
    else {
        failed++;
        printf("FAIL: %s\n", what);
    }
}

#if !defined(SD_UNDER_ASAN)
static uint64_t hits(void)
{
    uint64_t h, m;
    api_mem_keep_counts(&h, &m);
    return h;
}
#endif

int main(void)
{
    setenv("SUBDIVD_KEEP_POISON", "1", 1);
    sd_allocator a = api_mem_core_allocator();
    api_mem_keep_set(12 * MIB);
    size_t base = api_mem_budget_used();

    unsigned char *p = a.alloc(3 * MIB, a.ud);
    check(p != NULL, "a 3 MiB block");
    memset(p, 1, 3 * MIB);
    a.release(p, 3 * MIB, a.ud);
#if defined(SD_UNDER_ASAN)
    check(api_mem_kept() == 0, "under ASan nothing is kept");
    check(api_mem_budget_used() == base, "under ASan the block's bytes are given back");
#else
    check(api_mem_kept() == 3 * MIB, "a 3 MiB block is kept (its class: 3 MiB)");
    check(api_mem_budget_used() == base + 3 * MIB, "kept bytes stay counted against the budget");

    /* the next block of the class gets the same pages, poisoned */
    uint64_t h0 = hits();
    unsigned char *q = a.alloc(3 * MIB - 12345, a.ud); /* rounded up to 256 KiB: 3 MiB */
    check(q == p, "the next block of the class reuses the kept one");
    check(hits() == h0 + 1, "counted as reused");
    check(api_mem_kept() == 0, "taken out of the kept ones");
    int all = 1;
    for (size_t i = 0; i < 3 * MIB - 12345; i += 4099)
        all &= q[i] == 0xff;
    check(all, "a reused block is handed out poisoned (SUBDIVD_KEEP_POISON=1)");
    a.release(q, 3 * MIB - 12345, a.ud);

    /* another class maps a block of its own */
    unsigned char *r = a.alloc(7 * MIB, a.ud);
    check(r != NULL && r != p, "another class is not served by the kept block");
    check(hits() == h0 + 1, "nor counted as reused");
    memset(r, 2, 7 * MIB);
    a.release(r, 7 * MIB, a.ud); /* over half the room: not kept */
    check(api_mem_kept() == 3 * MIB, "a block larger than half the room is not kept");

    /* the room: three 3 MiB blocks and a 5 MiB one into 12 MiB, the oldest dropped */
    void *b[4];
    size_t bn[4] = {3 * MIB, 3 * MIB, 3 * MIB, 5 * MIB};
    for (int i = 0; i < 4; i++)
        b[i] = a.alloc(bn[i], a.ud);
    check(api_mem_kept() == 0, "the first of them took the kept block");
    for (int i = 0; i < 4; i++)
        a.release(b[i], bn[i], a.ud);
    check(api_mem_kept() == 11 * MIB, "at most the limit is kept, the oldest dropped first");
    check(api_mem_budget_used() == base + 11 * MIB, "dropped blocks leave the budget");

    /* idle blocks go back */
    sleep(1);
    usleep(150 * 1000);
    api_mem_keep_trim();
    check(api_mem_kept() == 0, "blocks idle for over a second are given back");
    check(api_mem_budget_used() == base, "and leave the budget");

    /* kept blocks give way to a reservation that would not fit beside them */
    api_mem_set_budget(base + 20 * MIB);
    uint64_t refused = api_mem_budget_refusals();
    void *c1 = a.alloc(3 * MIB, a.ud), *c2 = a.alloc(3 * MIB, a.ud);
    a.release(c1, 3 * MIB, a.ud);
    a.release(c2, 3 * MIB, a.ud);
    check(api_mem_kept() == 6 * MIB, "two 3 MiB blocks kept");
    void *big = a.alloc(15 * MIB, a.ud);
    check(big != NULL, "a 15 MiB block fits once the kept 6 MiB give way");
    check(((uintptr_t)big & ((2u << 20) - 1)) == 0, "a block of 2 MiB or more starts on 2 MiB");
    check(api_mem_budget_refusals() == refused, "without a refusal");
    check(api_mem_kept() == 0, "the kept blocks were dropped");
    void *over = a.alloc(8 * MIB, a.ud);
    check(over == NULL, "a block past the budget is still refused");
    a.release(big, 15 * MIB, a.ud);

    /* ... and so do they to a reservation and to an api block */
    void *k1 = a.alloc(3 * MIB, a.ud), *k2 = a.alloc(3 * MIB, a.ud);
    a.release(k1, 3 * MIB, a.ud);
    a.release(k2, 3 * MIB, a.ud);
    check(api_mem_kept() == 6 * MIB, "6 MiB kept again");
    refused = api_mem_budget_refusals();
    check(api_mem_reserve(16 * MIB), "a reservation of 16 MiB fits once the kept blocks give way");
    check(api_mem_kept() == 0 && api_mem_budget_refusals() == refused, "without a refusal");
    api_mem_unreserve(16 * MIB);
    k1 = a.alloc(3 * MIB, a.ud);
    k2 = a.alloc(3 * MIB, a.ud);
    a.release(k1, 3 * MIB, a.ud);
    a.release(k2, 3 * MIB, a.ud);
    void *blk = api_malloc(16 * MIB);
    check(blk != NULL && api_mem_kept() == 0, "an api block of 16 MiB too");
    api_free(blk);
    api_mem_set_budget(0);

    /* api blocks of 256 KiB and more are kept blocks too (what a build's outputs, normals and
     * edit maps take), counted in api_mem_in_use by their class */
    size_t in0 = api_mem_in_use(), used0 = api_mem_budget_used(), kept0 = api_mem_kept();
    unsigned char *x = api_malloc(3 * MIB - 100);
    check(x != NULL && api_mem_in_use() == in0 + 3 * MIB, "a big api block counts its class");
    memset(x, 7, 3 * MIB - 100);
    api_free(x);
    check(api_mem_in_use() == in0 && api_mem_kept() == kept0 + 3 * MIB,
          "a big api block is kept when freed");
    check(api_mem_budget_used() == used0 + 3 * MIB, "its bytes stay counted as kept ones");
    h0 = hits();
    unsigned char *y = api_calloc(1, 3 * MIB - 200);
    check(y == x && hits() == h0 + 1, "the next api block of the class reuses it");
    all = 1;
    for (size_t i = 0; i < 3 * MIB - 200; i++)
        all &= y[i] == 0;
    check(all, "api_calloc on a reused (poisoned) block gives zeros");
    for (size_t i = 0; i < 3 * MIB - 200; i += 997)
        y[i] = (unsigned char)(i / 997);
    unsigned char *z = api_realloc(y, 3 * MIB - 50);
    check(z == y, "it grows in place within its class");
    unsigned char *w = api_realloc(z, 5 * MIB);
    check(w != NULL, "and is remapped past it");
    all = 1;
    for (size_t i = 0; i < 3 * MIB - 200; i += 997)
        all &= w[i] == (unsigned char)(i / 997);
    check(all, "with its bytes");
    check(api_mem_in_use() == in0 + 5 * MIB + MIB / 2, "counted by its new class (5.5 MiB)");
    check(api_mem_kept() == kept0, "nothing copied, nothing left behind");
    unsigned char *u = api_realloc(w, MIB);
    check(u != NULL && api_mem_in_use() == in0 + MIB + MIB / 8,
          "shrinking remaps it to the smaller class (1.125 MiB)");
    check(u[997] == 1, "with its bytes");
    unsigned char *v = api_realloc(u, 1000);
    check(v != NULL && v != u && v[997] == 1, "below 256 KiB it moves to a C-library block");
    check(api_mem_in_use() == in0 + 1000 + 16, "counted by its size");
    check(api_mem_kept() == kept0 + MIB + MIB / 8, "the block it left is kept");
    api_free(v);
    /* a buffer doubling from 300 KiB, as a body or an output grows: each remap may move it off
     * a 2 MiB boundary, and every later one must still find it one mapping */
    unsigned char *gb = api_malloc(300 << 10);
    memset(gb, 9, 300 << 10);
    int grown_ok = gb != NULL;
    for (size_t sz = 600 << 10; grown_ok && sz <= 40 * MIB; sz *= 2) {
        unsigned char *g2 = api_realloc(gb, sz);
        grown_ok = g2 != NULL && g2[0] == 9 && g2[(300 << 10) - 1] == 9;
        if (g2) {
            gb = g2;
            memset(gb, 9, sz);
        }
    }
    check(grown_ok, "a doubling buffer is remapped at every size");
    api_free(gb);
    check(api_mem_in_use() == in0, "and given back");
    char *sm = api_malloc(1000);
    memset(sm, 'a', 1000);
    char *grown = api_realloc(sm, 4 * MIB);
    check(grown != NULL && grown[0] == 'a' && grown[999] == 'a',
          "a small block grows into a big one");
    api_free(grown);
    check(api_mem_in_use() == in0, "every api byte given back");

    /* each allocation of a sequence through every big-block path failed in turn: what
     * succeeded is given back, nothing stays counted but the kept blocks */
    int walk_ok = 1;
    for (uint64_t nth = 1; nth <= 8; nth++) {
        size_t u0 = api_mem_in_use(), b0 = api_mem_budget_used() - api_mem_kept();
        api_mem_fail_at(nth, 0);
        unsigned char *f1 = api_malloc(3 * MIB);
        unsigned char *f2 = f1 ? api_realloc(f1, 5 * MIB) : NULL;
        if (f2)
            f1 = f2;
        unsigned char *f3 = f1 ? api_realloc(f1, 1000) : NULL;
        if (f3)
            f1 = f3;
        unsigned char *f4 = api_calloc(1, 2 * MIB);
        unsigned char *f5 = api_malloc(100);
        unsigned char *f6 = f5 ? api_realloc(f5, MIB) : NULL;
        if (f6)
            f5 = f6;
        api_mem_fail_at(0, 0);
        api_free(f1);
        api_free(f4);
        api_free(f5);
        walk_ok &= api_mem_in_use() == u0 && api_mem_budget_used() - api_mem_kept() == b0;
    }
    check(walk_ok, "failures on the big-block paths leave nothing counted");

    api_mem_keep_set(0);
    api_mem_keep_set(12 * MIB);
    api_mem_set_budget(api_mem_budget_used() + 2 * MIB);
    refused = api_mem_budget_refusals();
    check(api_malloc(4 * MIB) == NULL && api_mem_budget_refusals() == refused + 1,
          "a big api block past the budget is refused");
    check(api_mem_in_use() == in0, "and counts nothing");
    api_mem_set_budget(0);

    /* off: nothing kept */
    api_mem_keep_set(0);
    check(api_mem_kept() == 0, "setting 0 drops what is kept");
    void *d = a.alloc(3 * MIB, a.ud);
    a.release(d, 3 * MIB, a.ud);
    check(api_mem_kept() == 0, "with 0 nothing is kept");
    check(api_mem_budget_used() == base, "every byte given back");
#endif
    printf("keep: %d passed, %d failed\n", passed, failed);
    return failed != 0;
}
