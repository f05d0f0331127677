/* out_matrix.c — the subdivision matrix from level `from` to level `to` (GET /matrices/{L}),
 * streamed as Matrix Market (coordinate real general, 1-based) or JSON CSR.
 *
 * P = S_{to-1} ... S_{from}. A row of P is built on demand by pushing the row of S_{to-1} down
 * through the coarser matrices (sparse accumulators with a touched list per level), so nothing
 * of the size of P is ever held. out_open's counterpart does one pass to count the entries of
 * every row (both formats need the count, or the row pointers, before the entries); the stream
 * then rebuilds each row as it writes it. Columns are written in increasing order.
 */
#include "out_internal.h"
#include "mem.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct acc {          /* a sparse vector over one level's points */
    double *val;              /* dense, zero outside `touched` */
    uint8_t *on;              /* listed in `touched` */
    uint32_t *touched;
    uint32_t n;
} acc;

typedef struct mstate {
    int from, to;
    bool json;
    sd_csr S[SD_MAX_LEVEL];   /* S[l] maps level l to l+1 */
    acc a[SD_MAX_LEVEL + 1];  /* accumulators per level */
    uint64_t *rowptr;         /* nrows + 1 */
    uint32_t nrows, ncols;
    int phase;                /* 0 header, 1 rows (mtx) / rowptr, col, val (json), 2 end */
    int part;                 /* json: 0 rowptr, 1 col, 2 val */
    uint32_t cur_row;         /* the row held in a[from], or UINT32_MAX */
} mstate;

static int cmp_u32(const void *x, const void *y)
{
    uint32_t a = *(const uint32_t *)x, b = *(const uint32_t *)y;
    return (a > b) - (a < b);
}

static void acc_add(acc *a, uint32_t j, double w)
{
    if (!a->on[j]) {
        a->on[j] = 1;
        a->touched[a->n++] = j;
    }
    a->val[j] += w;
}

static void acc_clear(acc *a)
{
    for (uint32_t i = 0; i < a->n; i++) {
        a->val[a->touched[i]] = 0;
        a->on[a->touched[i]] = 0;
    }
    a->n = 0;
}

/* Row r of P into a[from] (sorted, deduplicated touched list). */
static void build_row(mstate *m, uint32_t r)
{
    if (m->cur_row == r)
        return;
    acc_clear(&m->a[m->from]);
    const sd_csr *S = &m->S[m->to - 1];
    acc *top = &m->a[m->to - 1];
    for (uint32_t k = S->rowptr[r]; k < S->rowptr[r + 1]; k++)
        acc_add(top, S->col[k], S->val[k]);
    for (int l = m->to - 2; l >= m->from; l--) {
        acc *src = &m->a[l + 1], *dst = &m->a[l];
        const sd_csr *T = &m->S[l];
        for (uint32_t i = 0; i < src->n; i++) {
            uint32_t j = src->touched[i];
            double w = src->val[j];
            if (w == 0)
                continue;
            for (uint32_t k = T->rowptr[j]; k < T->rowptr[j + 1]; k++)
                acc_add(dst, T->col[k], w * T->val[k]);
        }
        acc_clear(src);
    }
    acc *out = &m->a[m->from];
    qsort(out->touched, out->n, sizeof *out->touched, cmp_u32);
    m->cur_row = r;
}

#define ROOM(s) ((s)->len < OUT_BUF_CAP / 2)

static double entry(const acc *a, uint32_t i) { return a->val[a->touched[i]]; }

static int produce(out_stream *s)
{
    mstate *m = s->fmt_state;
    if (m->phase == 0) {
        uint64_t nnz = m->rowptr[m->nrows];
        if (m->json)
            out_printf(s, "{\"from\":%d,\"to\":%d,\"rows\":%u,\"cols\":%u,\"nnz\":%llu,\"rowptr\":[",
                       m->from, m->to, m->nrows, m->ncols, (unsigned long long)nnz);
        else
            out_printf(s, "%%%%MatrixMarket matrix coordinate real general\n"
                          "%% subdivd: points of level %d (rows) from points of level %d (columns)\n"
                          "%u %u %llu\n", m->to, m->from, m->nrows, m->ncols, (unsigned long long)nnz);
        m->phase = 1;
        s->item = 0;
        return 1;
    }
    if (m->phase == 1 && m->json && m->part == 0) {
        for (; s->item <= m->nrows && ROOM(s); s->item++)
            out_printf(s, "%s%llu", s->item ? "," : "", (unsigned long long)m->rowptr[s->item]);
        if (s->item <= m->nrows)
            return 1;
        out_printf(s, "],\"col\":[");
        m->part = 1;
        s->item = 0;
        return 1;
    }
    if (m->phase == 1) { /* rows: item = row; json writes all columns first, then all values */
        while (s->item < m->nrows && ROOM(s)) {
            uint32_t r = (uint32_t)s->item;
            build_row(m, r);
            const acc *a = &m->a[m->from];
            for (uint32_t i = 0; i < a->n; i++) {
                if (!m->json)
                    out_printf(s, "%u %u %.17g\n", r + 1, a->touched[i] + 1, entry(a, i));
                else if (m->part == 1)
                    out_printf(s, "%s%u", m->rowptr[r] + i ? "," : "", a->touched[i]);
                else
                    out_printf(s, "%s%.17g", m->rowptr[r] + i ? "," : "", entry(a, i));
            }
            s->item++;
        }
        if (s->item < m->nrows)
            return 1;
        if (m->json && m->part == 1) {
            out_printf(s, "],\"val\":[");
            m->part = 2;
            s->item = 0;
            return 1;
        }
        if (m->json)
            out_printf(s, "]}");
        m->phase = 2;
    }
    return 0;
}

static void mfree(void *p)
{
    mstate *m = p;
    if (!m)
        return;
    for (int l = 0; l <= SD_MAX_LEVEL; l++) {
        api_free(m->a[l].val);
        api_free(m->a[l].on);
        api_free(m->a[l].touched);
    }
    api_free(m->rowptr);
    api_free(m);
}

static out_stream *fail(out_stream *s, sd_error *err, sd_result code, const char *msg)
{
    err->code = code;
    err->item = err->field = -1;
    snprintf(err->message, sizeof err->message, "%s", msg);
    out_close(s);
    return NULL;
}

out_stream *out_matrix_open(sd_complex *c, int from, int to, bool json, uint64_t max_nnz,
                            sd_error *err)
{
    if (from < 0 || to <= from || to >= sd_complex_levels_computed(c))
        return fail(NULL, err, SD_ERR_ARG, "from must be below the level, and the level computed");
    out_stream *s = api_calloc(1, sizeof *s);
    mstate *m = api_calloc(1, sizeof *m);
    if (!s || !m) {
        api_free(m);
        return fail(s, err, SD_ERR_NOMEM, "out of memory");
    }
    s->fmt_state = m;
    s->fmt_free = mfree;
    s->produce = produce;
    s->size = UINT64_MAX;
    m->from = from;
    m->to = to;
    m->json = json;
    m->cur_row = UINT32_MAX;
    for (int l = from; l < to; l++)
        if (sd_complex_matrix(c, l, &m->S[l], err)) {
            out_close(s); /* err is filled by the core */
            return NULL;
        }
    for (int l = from; l < to; l++) {
        uint32_t n = m->S[l].ncols;
        m->a[l].val = api_calloc((size_t)n + 1, sizeof *m->a[l].val);
        m->a[l].on = api_calloc((size_t)n + 1, 1);
        m->a[l].touched = api_malloc(((size_t)n + 1) * sizeof *m->a[l].touched);
        if (!m->a[l].val || !m->a[l].on || !m->a[l].touched)
            return fail(s, err, SD_ERR_NOMEM, "out of memory");
    }
    m->nrows = m->S[to - 1].nrows;
    m->ncols = m->S[from].ncols;
    m->rowptr = api_malloc(((size_t)m->nrows + 1) * sizeof *m->rowptr);
    s->buf = api_malloc(OUT_BUF_CAP);
    if (!m->rowptr || !s->buf)
        return fail(s, err, SD_ERR_NOMEM, "out of memory");
    m->rowptr[0] = 0;
    for (uint32_t r = 0; r < m->nrows; r++) { /* counting pass */
        build_row(m, r);
        m->rowptr[r + 1] = m->rowptr[r] + m->a[from].n;
        if (m->rowptr[r + 1] > max_nnz) {
            char msg[160];
            snprintf(msg, sizeof msg, "the matrix from level %d to %d has more than %llu entries",
                     from, to, (unsigned long long)max_nnz);
            return fail(s, err, SD_ERR_LIMIT, msg);
        }
    }
    return s;
}
