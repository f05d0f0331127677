/* csr.c — sparse subdivision matrices in compressed-row form, with shared weight patterns.
 *
 * The rules use a handful of distinct weight sets (a Loop vertex of valence k, a solid edge with
 * a ring of 6, ...), so S stores no weight per entry: row r has column indices
 * col[rowptr[r] .. rowptr[r+1]-1] and a pattern id pat[r], and its weights are the pattern's,
 * wt[woff[pat[r]] ..] (one per entry, in order). That is 4 bytes per non-zero instead of 12.
 * Patterns are interned (sd_pats_intern: same length and same weights bit for bit -> same id).
 * Public callers of sd_complex_matrix get a plain CSR view; its per-entry values are materialized
 * once, on demand (sd_csrb_values), and kept with the matrix.
 * One builder and one apply serve positions, attributes and edits. Column indices are uint32_t;
 * nnz is checked to fit.
 */
#include "internal.h"
#include <string.h>

bool sd_csrb_init(sd_mem *m, sd_csrb *b, uint32_t nrows, uint32_t ncols)
{
    memset(b, 0, sizeof *b);
    b->nrows = nrows;
    b->ncols = ncols;
    b->rowptr = sd_alloc(m, ((size_t)nrows + 1) * sizeof *b->rowptr);
    b->pat = sd_alloc(m, ((size_t)nrows + 1) * sizeof *b->pat);
    if (!b->rowptr || !b->pat) {
        sd_csrb_free(m, b);
        return false;
    }
    b->rowptr[0] = 0;
    return true;
}

void sd_csrb_free(sd_mem *m, sd_csrb *b)
{
    sd_free(m, b->rowptr);
    sd_free(m, b->col);
    sd_free(m, b->pat);
    sd_free(m, b->wt);
    sd_free(m, b->woff);
    sd_free(m, b->val);
    memset(b, 0, sizeof *b);
}

/* ---- weight patterns ---------------------------------------------------------------------- */

static uint64_t pat_hash(const double *w, uint32_t len)
{
    uint64_t h = 0x9e3779b97f4a7c15ull ^ len;
    for (uint32_t i = 0; i < len; i++) {
        uint64_t x;
        memcpy(&x, &w[i], sizeof x);
        h = (h ^ x) * 0xff51afd7ed558ccdull;
        h ^= h >> 32;
    }
    return h;
}

static bool pat_equal(const sd_pats *p, uint32_t id, const double *w, uint32_t len)
{
    return p->off[id + 1] - p->off[id] == len &&
           (len == 0 || !memcmp(p->w + p->off[id], w, len * sizeof *w));
}

static bool pat_rehash(sd_mem *m, sd_pats *p, uint32_t cap)
{
    uint32_t *slot = sd_alloc(m, (size_t)cap * sizeof *slot);
    if (!slot)
        return false;
    for (uint32_t i = 0; i < cap; i++)
        slot[i] = UINT32_MAX;
    for (uint32_t id = 0; id < p->n; id++) {
        uint32_t i = (uint32_t)pat_hash(p->w + p->off[id], p->off[id + 1] - p->off[id]) & (cap - 1);
        while (slot[i] != UINT32_MAX)
            i = (i + 1) & (cap - 1);
        slot[i] = id;
    }
    sd_free(m, p->slot);
    p->slot = slot;
    p->hcap = cap;
    return true;
}

uint32_t sd_pats_intern(sd_mem *m, sd_pats *p, const double *w, uint32_t len)
{
    if (2 * (p->n + 1) > p->hcap && !pat_rehash(m, p, p->hcap ? 2 * p->hcap : 64))
        return UINT32_MAX;
    uint32_t i = (uint32_t)pat_hash(w, len) & (p->hcap - 1);
    for (; p->slot[i] != UINT32_MAX; i = (i + 1) & (p->hcap - 1))
        if (pat_equal(p, p->slot[i], w, len))
            return p->slot[i];
    if (p->n + 2 > p->capn) {
        uint32_t cap = p->capn ? 2 * p->capn : 64;
        uint32_t *off = sd_realloc(m, p->off, (size_t)cap * sizeof *off);
        if (!off)
            return UINT32_MAX;
        p->off = off;
        p->capn = cap;
        if (p->n == 0)
            p->off[0] = 0;
    }
    uint32_t at = p->off[p->n];
    if (at + len > p->capw) {
        uint32_t cap = p->capw ? p->capw : 256;
        while (cap < at + len)
            cap *= 2;
        double *nw = sd_realloc(m, p->w, (size_t)cap * sizeof *nw);
        if (!nw)
            return UINT32_MAX;
        p->w = nw;
        p->capw = cap;
    }
    memcpy(p->w + at, w, len * sizeof *w);
    p->off[p->n + 1] = at + len;
    p->slot[i] = p->n;
    return p->n++;
}

/* Hand the patterns to the matrix (trimmed to size) and free the builder. */
bool sd_pats_finish(sd_mem *m, sd_pats *p, sd_csrb *b)
{
    sd_free(m, p->slot);
    p->slot = NULL;
    uint32_t nw = p->n ? p->off[p->n] : 0;
    b->npat = p->n;
    b->wt = sd_alloc(m, ((size_t)nw + 1) * sizeof *b->wt);
    b->woff = sd_alloc(m, ((size_t)p->n + 1) * sizeof *b->woff);
    if (!b->wt || !b->woff) {
        sd_pats_free(m, p);
        return false;
    }
    if (nw)
        memcpy(b->wt, p->w, nw * sizeof *b->wt);
    if (p->n)
        memcpy(b->woff, p->off, ((size_t)p->n + 1) * sizeof *b->woff);
    else
        b->woff[0] = 0;
    sd_pats_free(m, p);
    return true;
}

void sd_pats_free(sd_mem *m, sd_pats *p)
{
    sd_free(m, p->w);
    sd_free(m, p->off);
    sd_free(m, p->slot);
    memset(p, 0, sizeof *p);
}

/* ---- use ------------------------------------------------------------------------------------ */

const double *sd_csrb_values(sd_mem *m, sd_csrb *b)
{
    if (b->val)
        return b->val;
    double *v = sd_alloc(m, (b->nnz + 1) * sizeof *v);
    if (!v)
        return NULL;
    for (uint32_t r = 0; r < b->nrows; r++) {
        const double *w = b->wt + b->woff[b->pat[r]];
        uint32_t k0 = b->rowptr[r], n = b->rowptr[r + 1] - k0;
        memcpy(v + k0, w, n * sizeof *v);
    }
    b->val = v;
    return v;
}

void sd_csr_apply(const sd_csrb *s, const double *in, double *out, int nc)
{
    const uint32_t *rp = s->rowptr, *col = s->col, *pat = s->pat, *woff = s->woff;
    const double *wt = s->wt;
    if (nc == 3) {
        for (uint32_t r = 0; r < s->nrows; r++) {
            double x = 0, y = 0, z = 0;
            const double *w = wt + woff[pat[r]];
            const uint32_t *c = col + rp[r];
            for (uint32_t k = 0, n = rp[r + 1] - rp[r]; k < n; k++) {
                const double *p = in + 3 * (size_t)c[k];
                x += w[k] * p[0];
                y += w[k] * p[1];
                z += w[k] * p[2];
            }
            out[3 * (size_t)r] = x;
            out[3 * (size_t)r + 1] = y;
            out[3 * (size_t)r + 2] = z;
        }
        return;
    }
    for (uint32_t r = 0; r < s->nrows; r++) {
        double *o = out + (size_t)nc * r;
        const double *w = wt + woff[pat[r]];
        for (int j = 0; j < nc; j++)
            o[j] = 0;
        for (uint32_t k = rp[r]; k < rp[r + 1]; k++) {
            const double *p = in + (size_t)nc * col[k];
            for (int j = 0; j < nc; j++)
                o[j] += w[k - rp[r]] * p[j];
        }
    }
}
