/* hash.h — an open-addressing map from up to four sorted vertex ids to a uint32_t id.
 * Used only to build level 0 (unique edges, faces, duplicate simplices); later levels number
 * their entities directly from the parent's. */
#ifndef SD_HASH_H
#define SD_HASH_H
#include "internal.h"

typedef struct sd_hash {
    size_t cap, n;
    uint32_t (*key)[4];
    uint32_t *val;
} sd_hash;

bool sdi_hash_init(sd_mem *m, sd_hash *h, size_t expected);
void sdi_hash_free(sd_mem *m, sd_hash *h);
/* Look up key k (sorted, unused slots UINT32_MAX). If absent, insert it with value `v` and
 * return UINT32_MAX; if present return its value. */
uint32_t sdi_hash_get_or_put(sd_hash *h, const uint32_t k[4], uint32_t v);
uint32_t sdi_hash_get(const sd_hash *h, const uint32_t k[4]);

/* The same for edges (two ids), a key and its value in one 16-byte slot, so a probe reads one
 * cache line: level 0 looks up every edge of every simplex. */
typedef struct sd_ehash {
    unsigned shift; /* 64 - log2(capacity) */
    size_t cap;
    struct sd_eslot {
        uint64_t k; /* min id << 32 | max id; UINT64_MAX: empty */
        uint32_t v, pad;
    } *s;
} sd_ehash;

bool sdi_ehash_init(sd_mem *m, sd_ehash *h, size_t expected);
void sdi_ehash_free(sd_mem *m, sd_ehash *h);
/* The value of edge {a, b}; if absent, it is inserted with `v` and UINT32_MAX returned. */
uint32_t sdi_ehash_get_or_put(sd_ehash *h, uint32_t a, uint32_t b, uint32_t v);
/* Sort n (1..4) ids into k, padding with UINT32_MAX (ids may be k itself). Inline, with no
 * data-dependent branch: level 0 makes a key for every edge and face of every simplex. */
static inline void sdi_sort2(uint32_t *a, uint32_t *b)
{
    uint32_t x = *a < *b ? *a : *b, y = *a < *b ? *b : *a;
    *a = x;
    *b = y;
}

static inline void sdi_key(uint32_t k[4], const uint32_t *ids, int n)
{
    uint32_t a = ids[0], b = n > 1 ? ids[1] : UINT32_MAX, c = n > 2 ? ids[2] : UINT32_MAX,
             d = n > 3 ? ids[3] : UINT32_MAX;
    sdi_sort2(&a, &b); /* a sorting network of four (padding sorts last) */
    sdi_sort2(&c, &d);
    sdi_sort2(&a, &c);
    sdi_sort2(&b, &d);
    sdi_sort2(&b, &c);
    k[0] = a;
    k[1] = b;
    k[2] = c;
    k[3] = d;
}
#endif
