/* csr.c — sparse subdivision matrices in compressed-row form.
 *
 * One builder and one apply serve positions, attributes and (later) edits: rules.c sizes every
 * row first and fills the arrays in place, sd_csr_apply multiplies any channel.
 * Column indices are uint32_t; nnz is checked to fit.
 */
#include "internal.h"
#include <string.h>

bool sd_csrb_init(sd_mem *m, sd_csrb *b, uint32_t nrows, uint32_t ncols, size_t nnz_hint)
{
    memset(b, 0, sizeof *b);
    b->nrows = nrows;
    b->ncols = ncols;
    b->rowptr = sd_alloc(m, ((size_t)nrows + 1) * sizeof *b->rowptr);
    if (!b->rowptr)
        return false;
    b->rowptr[0] = 0;
    return sd_csrb_reserve(m, b, nnz_hint ? nnz_hint : 16);
}

bool sd_csrb_reserve(sd_mem *m, sd_csrb *b, size_t extra)
{
    if (b->nnz + extra <= b->cap)
        return true;
    size_t cap = b->cap ? b->cap : 16;
    while (cap < b->nnz + extra)
        cap += cap / 2 + 16;
    if (cap > UINT32_MAX)
        cap = UINT32_MAX;
    if (b->nnz + extra > cap)
        return false;
    uint32_t *col = sd_realloc(m, b->col, cap * sizeof *col);
    if (!col)
        return false;
    b->col = col;
    double *val = sd_realloc(m, b->val, cap * sizeof *val);
    if (!val)
        return false;
    b->val = val;
    b->cap = cap;
    return true;
}

void sd_csrb_free(sd_mem *m, sd_csrb *b)
{
    sd_free(m, b->rowptr);
    sd_free(m, b->col);
    sd_free(m, b->val);
    memset(b, 0, sizeof *b);
}

void sd_csr_apply(const sd_csrb *s, const double *in, double *out, int nc)
{
    const uint32_t *rp = s->rowptr, *col = s->col;
    const double *val = s->val;
    if (nc == 3) {
        for (uint32_t r = 0; r < s->nrows; r++) {
            double x = 0, y = 0, z = 0;
            for (uint32_t k = rp[r]; k < rp[r + 1]; k++) {
                const double *p = in + 3 * (size_t)col[k];
                double w = val[k];
                x += w * p[0];
                y += w * p[1];
                z += w * p[2];
            }
            out[3 * (size_t)r] = x;
            out[3 * (size_t)r + 1] = y;
            out[3 * (size_t)r + 2] = z;
        }
        return;
    }
    for (uint32_t r = 0; r < s->nrows; r++) {
        double *o = out + (size_t)nc * r;
        for (int j = 0; j < nc; j++)
            o[j] = 0;
        for (uint32_t k = rp[r]; k < rp[r + 1]; k++) {
            const double *p = in + (size_t)nc * col[k];
            for (int j = 0; j < nc; j++)
                o[j] += val[k] * p[j];
        }
    }
}
