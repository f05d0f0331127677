/* hash.c — see hash.h. Linear probing over a power-of-two table at most half full. */
#include "hash.h"
#include <string.h>

bool sdi_hash_init(sd_mem *m, sd_hash *h, size_t expected)
{
    size_t cap = 16;
    while (cap < 2 * expected + 16)
        cap <<= 1;
    h->cap = cap;
    h->n = 0;
    h->key = sdi_alloc(m, cap * sizeof *h->key);
    h->val = sdi_alloc(m, cap * sizeof *h->val);
    if (!h->key || !h->val) {
        sdi_hash_free(m, h);
        return false;
    }
    memset(h->key, 0xff, cap * sizeof *h->key);
    return true;
}

void sdi_hash_free(sd_mem *m, sd_hash *h)
{
    sdi_free(m, h->key);
    sdi_free(m, h->val);
    h->key = NULL;
    h->val = NULL;
}

static size_t hash4(const uint32_t k[4])
{
    uint64_t x = k[0] * 0x9E3779B97F4A7C15ull;
    x ^= (k[1] + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
    x ^= (k[2] + 0x85EBCA77C2B2AE63ull) * 0x165667B19E3779F9ull;
    x ^= (k[3] + 0x27D4EB2F165667C5ull) * 0x9E3779B97F4A7C15ull;
    x ^= x >> 29;
    return (size_t)x;
}

uint32_t sdi_hash_get_or_put(sd_hash *h, const uint32_t k[4], uint32_t v)
{
    size_t i = hash4(k) & (h->cap - 1);
    for (;;) {
        uint32_t *s = h->key[i];
        if (s[0] == UINT32_MAX) {
            memcpy(s, k, 4 * sizeof *k);
            h->val[i] = v;
            h->n++;
            return UINT32_MAX;
        }
        if (!memcmp(s, k, 4 * sizeof *k))
            return h->val[i];
        i = (i + 1) & (h->cap - 1);
    }
}

uint32_t sdi_hash_get(const sd_hash *h, const uint32_t k[4])
{
    size_t i = hash4(k) & (h->cap - 1);
    for (;;) {
        const uint32_t *s = h->key[i];
        if (s[0] == UINT32_MAX)
            return UINT32_MAX;
        if (!memcmp(s, k, 4 * sizeof *k))
            return h->val[i];
        i = (i + 1) & (h->cap - 1);
    }
}

bool sdi_ehash_init(sd_mem *m, sd_ehash *h, size_t expected)
{
    size_t cap = 16;
    unsigned bits = 4;
    while (cap < 2 * expected + 16)
        cap <<= 1, bits++;
    h->cap = cap;
    h->shift = 64 - bits;
    if (!(h->s = sdi_alloc(m, cap * sizeof *h->s)))
        return false;
    memset(h->s, 0xff, cap * sizeof *h->s);
    return true;
}

void sdi_ehash_free(sd_mem *m, sd_ehash *h)
{
    sdi_free(m, h->s);
    h->s = NULL;
}

uint32_t sdi_ehash_get_or_put(sd_ehash *h, uint32_t a, uint32_t b, uint32_t v)
{
    uint64_t k = a < b ? (uint64_t)a << 32 | b : (uint64_t)b << 32 | a;
    size_t i = (size_t)((k * 0x9E3779B97F4A7C15ull) >> h->shift);
    for (;;) {
        struct sd_eslot *s = &h->s[i];
        if (s->k == k)
            return s->v;
        if (s->k == UINT64_MAX) {
            s->k = k;
            s->v = v;
            return UINT32_MAX;
        }
        i = (i + 1) & (h->cap - 1);
    }
}
