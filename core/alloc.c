/* alloc.c — the one allocation wrapper of the core.
 *
 * Every byte the core allocates goes through sd_mem: a pluggable allocator (libc by default), a
 * running count of bytes in use (feeds per-session memory accounting and /metrics) and an
 * optional cap. A failing allocation returns NULL; callers turn it into SD_ERR_NOMEM or
 * SD_ERR_LIMIT and leave the complex as it was. Tests plug an allocator that fails the Nth call.
 * Each block carries a 16-byte header holding its size so that frees can be counted.
 * Big blocks ask for transparent huge pages (sd_advise_huge): a level's arrays are written
 * once, front to back, and on a virtual machine a 4 KiB page fault costs more than the writing.
 */
#include "internal.h"
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#define HDR 16

void sdi_mem_init(sd_mem *m, const sd_allocator *a, size_t limit)
{
    memset(m, 0, sizeof *m);
    if (a)
        m->a = *a;
    m->limit = limit;
}

/* Without an allocator of the caller's, blocks of 2 MiB and more start on a 2 MiB boundary
 * (posix_memalign) and are advised as huge pages whole, so a fresh block faults in 2 MiB at a
 * time (malloc's own chunks start 16 bytes past a page, so only their aligned interior could
 * be); they stay the C library's, so a process that keeps freed memory (glibc's tunables, a
 * service's steady state) reuses them as before. Under AddressSanitizer, plain malloc's. */
#if defined(SD_UNDER_ASAN) || !defined(MADV_HUGEPAGE)
#define ALIGN_MIN SIZE_MAX
#else
#define ALIGN_MIN ((size_t)2 << 20)
#endif

static void *raw_alloc(sd_mem *m, size_t n)
{
    if (m->a.alloc)
        return m->a.alloc(n, m->a.ud);
    if (n < ALIGN_MIN)
        return malloc(n);
    void *p;
    return posix_memalign(&p, (size_t)2 << 20, n) ? NULL : p; /* advised by sdi_alloc */
}

static void raw_free(sd_mem *m, void *p, size_t n)
{
    if (m->a.release)
        m->a.release(p, n, m->a.ud);
    else
        free(p);
}

void sd_advise_huge(void *p, size_t n)
{
#ifdef MADV_HUGEPAGE
    enum { THP = 2u << 20 };
    if (!p || n < THP)
        return;
    uintptr_t a = ((uintptr_t)p + THP - 1) & ~(uintptr_t)(THP - 1);
    uintptr_t b = ((uintptr_t)p + n) & ~(uintptr_t)(THP - 1);
    if (b > a)
        (void)madvise((void *)a, b - a, MADV_HUGEPAGE); /* advice: refused or not, all works */
#else
    (void)p;
    (void)n;
#endif
}

void *sdi_alloc(sd_mem *m, size_t n)
{
    if (n > SIZE_MAX - HDR)
        return NULL;
    if (m->limit && (m->used + n + HDR > m->limit || m->used + n + HDR < m->used)) {
        m->failed_limit = true;
        return NULL;
    }
    unsigned char *p = raw_alloc(m, n + HDR);
    if (!p)
        return NULL;
    sd_advise_huge(p, n + HDR);
    memcpy(p, &n, sizeof n);
    m->used += n + HDR;
    return p + HDR;
}

void *sdi_calloc(sd_mem *m, size_t n, size_t size)
{
    if (size && n > SIZE_MAX / size)
        return NULL;
    void *p = sdi_alloc(m, n * size);
    if (p)
        memset(p, 0, n * size);
    return p;
}

void sdi_free(sd_mem *m, void *p)
{
    if (!p)
        return;
    unsigned char *b = (unsigned char *)p - HDR;
    size_t n;
    memcpy(&n, b, sizeof n);
    m->used -= n + HDR;
    raw_free(m, b, n + HDR);
}

void *sdi_realloc(sd_mem *m, void *p, size_t n)
{
    if (!p)
        return sdi_alloc(m, n);
    size_t old;
    memcpy(&old, (unsigned char *)p - HDR, sizeof old);
    void *q = sdi_alloc(m, n);
    if (!q)
        return NULL;
    memcpy(q, p, old < n ? old : n);
    sdi_free(m, p);
    return q;
}
