/* csr.c — the subdivision matrices S_l, stored compactly.
 *
 * The rules use a handful of distinct weight sets (a Loop vertex of valence k, a solid edge with
 * a ring of 6, ...) and every row starts with columns the level's topology already holds, so S
 * keeps per row only a weight-pattern id (1, 2 or 4 bytes, by the number of patterns) and the
 * columns that are not implicit:
 *   vertex row v      [v | rho(v)]           v implicit, rho in col
 *   edge row e        [a, b | ring(e)]       the ends ev[e] implicit, the ring in col
 *   octahedron row o  [its 6 vertices]       all implicit (oct[o])
 * Pattern p is the row's weights, one per entry in that order: wt[woff[p] .. woff[p+1]), so its
 * length is the row's length. Patterns are interned (same weights bit for bit -> same id).
 * For a 12^3-cube solid that is ~2.8 bytes per non-zero instead of 16 (CSR with doubles).
 * Rows are walked in order (apply, the column index) with a cursor into col; random access goes
 * through a table of row starts made for the occasion, or, for edits, through the checkpoints
 * of the column index (below). Every row is summed by one function, row_sum, whether by the level
 * build (sdi_csr_apply) or by an edit recomputing a point (sdi_csrb_eval): the two cannot give
 * different bits. The public CSR view of sd_complex_matrix (rowptr, col, val) is materialized on
 * demand and kept with the matrix.
 */
#include "internal.h"
#include <string.h>

bool sdi_csrb_init(sd_mem *m, sd_csrb *b, uint32_t nvr, uint32_t ner, uint32_t nor, uint32_t ncols,
                  const uint32_t (*ev)[2], const uint32_t (*oct)[6])
{
    memset(b, 0, sizeof *b);
    b->nrows = nvr + ner + nor;
    b->nvr = nvr;
    b->ner = ner;
    b->ncols = ncols;
    b->ev = ev;
    b->oct = oct;
    b->pw = 1;
    b->pat = sdi_alloc(m, (size_t)b->nrows + 1);
    b->kchk = sdi_alloc(m, ((size_t)b->nrows / SD_CHK + 2) * sizeof *b->kchk);
    return b->pat && b->kchk;
}

bool sdi_csrb_set_pat_slow(sd_mem *m, sd_csrb *b, uint32_t r, uint32_t id)
{
    uint8_t pw = id < 256 ? 1 : id < 65536 ? 2 : 4;
    if (pw > b->pw) { /* widen the ids set so far */
        void *np = sdi_alloc(m, ((size_t)b->nrows + 1) * pw);
        if (!np)
            return false;
        for (uint32_t i = 0; i < b->nrows; i++) {
            uint32_t q = sdi_csrb_pat(b, i);
            if (pw == 2)
                ((uint16_t *)np)[i] = (uint16_t)q;
            else
                ((uint32_t *)np)[i] = q;
        }
        sdi_free(m, b->pat);
        b->pat = np;
        b->pw = pw;
    }
    if (b->pw == 1)
        ((uint8_t *)b->pat)[r] = (uint8_t)id;
    else if (b->pw == 2)
        ((uint16_t *)b->pat)[r] = (uint16_t)id;
    else
        ((uint32_t *)b->pat)[r] = id;
    return true;
}

void sdi_csrb_free(sd_mem *m, sd_csrb *b)
{
    sdi_free(m, b->col);
    sdi_free(m, b->eopp);
    sdi_free(m, b->pat);
    sdi_free(m, b->wt);
    sdi_free(m, b->woff);
    sdi_free(m, b->vrowptr);
    sdi_free(m, b->vcol);
    sdi_free(m, b->vval);
    sdi_free(m, b->kchk);
    sdi_free(m, b->ub);
    sdi_free(m, b->ubase);
    sdi_free(m, b->urel);
    sdi_free(m, b->rchk);
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
    uint32_t *slot = sdi_alloc(m, (size_t)cap * sizeof *slot);
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
    sdi_free(m, p->slot);
    p->slot = slot;
    p->hcap = cap;
    return true;
}

uint32_t sdi_pats_intern(sd_mem *m, sd_pats *p, const double *w, uint32_t len)
{
    if (2 * (p->n + 1) > p->hcap && !pat_rehash(m, p, p->hcap ? 2 * p->hcap : 64))
        return UINT32_MAX;
    uint32_t i = (uint32_t)pat_hash(w, len) & (p->hcap - 1);
    for (; p->slot[i] != UINT32_MAX; i = (i + 1) & (p->hcap - 1))
        if (pat_equal(p, p->slot[i], w, len))
            return p->slot[i];
    if (p->n + 2 > p->capn) {
        uint32_t cap = p->capn ? 2 * p->capn : 64;
        uint32_t *off = sdi_realloc(m, p->off, (size_t)cap * sizeof *off);
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
        double *nw = sdi_realloc(m, p->w, (size_t)cap * sizeof *nw);
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

void sdi_pats_free(sd_mem *m, sd_pats *p)
{
    sdi_free(m, p->w);
    sdi_free(m, p->off);
    sdi_free(m, p->slot);
    memset(p, 0, sizeof *p);
}

bool sdi_csrb_finish(sd_mem *m, sd_csrb *b, sd_pats *p, size_t nnz)
{
    uint32_t nw = p->n ? p->off[p->n] : 0;
    b->wt = sdi_alloc(m, ((size_t)nw + 1) * sizeof *b->wt);
    b->woff = sdi_alloc(m, ((size_t)p->n + 1) * sizeof *b->woff);
    if (!b->wt || !b->woff)
        return false;
    b->npat = p->n;
    if (nw)
        memcpy(b->wt, p->w, nw * sizeof *b->wt);
    b->woff[0] = 0;
    if (p->n)
        memcpy(b->woff, p->off, ((size_t)p->n + 1) * sizeof *b->woff);
    b->maxlen = 0;
    for (uint32_t q = 0; q < p->n; q++)
        if (p->off[q + 1] - p->off[q] > b->maxlen)
            b->maxlen = p->off[q + 1] - p->off[q];
    b->nnz = nnz;
    return true;
}

/* ---- use ------------------------------------------------------------------------------------ */

size_t *sdi_csrb_starts(sd_mem *m, const sd_csrb *b)
{
    size_t *s = sdi_alloc(m, ((size_t)b->nrows + 1) * sizeof *s), k = 0;
    if (!s)
        return NULL;
    for (uint32_t r = 0; r < b->nrows; r++) {
        s[r] = k;
        k += sdi_csrb_nexp(b, r);
    }
    s[b->nrows] = k;
    return s;
}

bool sdi_csrb_view(sd_mem *m, sd_csrb *b)
{
    if (b->vval)
        return true;
    uint32_t *rp = sdi_alloc(m, ((size_t)b->nrows + 1) * sizeof *rp);
    uint32_t *col = sdi_alloc(m, (b->nnz + 1) * sizeof *col);
    double *val = sdi_alloc(m, (b->nnz + 1) * sizeof *val);
    if (!rp || !col || !val) {
        sdi_free(m, rp);
        sdi_free(m, col);
        sdi_free(m, val);
        return false;
    }
    size_t k = 0, at = 0;
    for (uint32_t r = 0; r < b->nrows; r++) {
        rp[r] = (uint32_t)at;
        uint32_t n = sdi_csrb_len(b, r);
        const double *w = sdi_csrb_row(b, r, &k, col + at);
        memcpy(val + at, w, n * sizeof *val);
        at += n;
    }
    rp[b->nrows] = (uint32_t)at;
    b->vrowptr = rp;
    b->vcol = col;
    b->vval = val;
    return true;
}

/* ---- one row: the only place a row of S is summed ------------------------------------------- */

/* out = sum_i w[i] p(c_i) over the row's n entries, its nimp implicit columns imp[] first, then
 * its explicit ones exp[], in that order from 0 — the order the public view lists them. p(c) is
 * in + nc c, or, where slot is not NULL and slot[c] >= 0, alt + nc slot[c] (an edit's new value
 * of a point it has not written yet). The level build (sdi_csr_apply) and edits
 * (sdi_csrb_eval) both sum through this function, so a recomputed point gets exactly the bits a
 * fresh build gives it. Inlined into each caller with its constants (nc = 3, slot = NULL). */
static inline __attribute__((always_inline)) void
row_sum(const double *w, uint32_t n, uint32_t nimp, const uint32_t *imp, const uint32_t *exp,
        const double *in, const int32_t *slot, const double *alt, int nc, double *out)
{
#define SRC(c) (slot && slot[c] >= 0 ? alt + (size_t)nc * (uint32_t)slot[c] : in + (size_t)nc * (c))
    /* (slot is a constant NULL or not in each copy: the test is folded away) */
    const uint32_t ni = nimp < n ? nimp : n;
    uint32_t i = 0;
    if (nc == 3) {
        double x = 0, y = 0, z = 0;
        for (; i < ni; i++) {
            const double *p = SRC(imp[i]);
            x += w[i] * p[0];
            y += w[i] * p[1];
            z += w[i] * p[2];
        }
        for (const uint32_t *e = exp; i < n; i++, e++) {
            const double *p = SRC(*e);
            x += w[i] * p[0];
            y += w[i] * p[1];
            z += w[i] * p[2];
        }
        out[0] = x;
        out[1] = y;
        out[2] = z;
        return;
    }
    double acc[16];
    for (int j = 0; j < nc; j++)
        acc[j] = 0;
    for (; i < n; i++) {
        const double *p = SRC(i < ni ? imp[i] : exp[i - ni]);
        for (int j = 0; j < nc; j++)
            acc[j] += w[i] * p[j];
    }
    for (int j = 0; j < nc; j++)
        out[j] = acc[j];
#undef SRC
}

static inline uint32_t pat_of(const sd_csrb *s, int pw, uint32_t r)
{
    return pw == 1 ? ((const uint8_t *)s->pat)[r]
         : pw == 2 ? ((const uint16_t *)s->pat)[r] : ((const uint32_t *)s->pat)[r];
}

/* Rows [lo, hi) of block `blk` (0 vertex rows, 1 edge rows, 2 octahedron rows; see the top of
 * this file for their implicit columns), pattern ids of pw bytes; *k: the cursor into col. */
static inline __attribute__((always_inline)) void
apply_block(const sd_csrb *s, int pw, int blk, uint32_t lo, uint32_t hi, size_t *k,
            const double *in, double *out, int nc)
{
    const uint32_t b1 = s->nvr, b2 = s->nvr + s->ner;
    for (uint32_t r = lo; r < hi; r++) {
        uint32_t q = pat_of(s, pw, r), n = s->woff[q + 1] - s->woff[q], self = r;
        const uint32_t *imp = blk == 0 ? &self : blk == 1 ? s->ev[r - b1] : s->oct[r - b2];
        const uint32_t nimp = blk == 0 ? 1 : blk == 1 ? 2 : 6;
        const bool opp = blk == 1 && s->eopp;
        row_sum(s->wt + s->woff[q], n, nimp, imp, opp ? s->eopp[r - b1] : s->col + *k, in, NULL,
                NULL, nc, out + (size_t)nc * r);
        if (!opp)
            *k += n > nimp ? n - nimp : 0;
    }
}

#define MINU(a, b) ((a) < (b) ? (a) : (b))
#define MAXU(a, b) ((a) > (b) ? (a) : (b))

static inline __attribute__((always_inline)) void
apply_rows(const sd_csrb *s, int pw, uint32_t rlo, uint32_t rhi, size_t k, const double *in,
           double *out, int nc)
{
    const uint32_t b1 = s->nvr, b2 = s->nvr + s->ner;
    apply_block(s, pw, 0, rlo, MINU(rhi, b1), &k, in, out, nc);
    apply_block(s, pw, 1, MAXU(rlo, b1), MINU(rhi, b2), &k, in, out, nc);
    apply_block(s, pw, 2, MAXU(rlo, b2), rhi, &k, in, out, nc);
}

typedef struct ajob {
    const sd_csrb *s;
    const double *in;
    double *out;
    int nc;
} ajob;

/* The entries of S before row r (a multiple of SD_CHK, or nrows): the explicit columns kchk
 * counts, the implicit ones of each block, and the edge rows' opposite vertices if kept apart. */
static uint64_t entries_before(const sd_csrb *s, uint64_t r)
{
    const uint64_t nv = MINU(r, s->nvr), ne = r > s->nvr ? MINU(r - s->nvr, s->ner) : 0;
    const uint64_t no = r > (uint64_t)s->nvr + s->ner ? r - s->nvr - s->ner : 0;
    return s->kchk[(r + SD_CHK - 1) / SD_CHK] + nv + 2 * ne + 6 * no + (s->eopp ? 2 * ne : 0);
}

/* The first chunk of SD_CHK rows at or after which `goal` entries of S lie before. */
static uint64_t chunk_at(const sd_csrb *s, uint64_t nchunks, uint64_t goal)
{
    uint64_t c = 0;
    while (c < nchunks && entries_before(s, c * SD_CHK) < goal)
        c++;
    return c;
}

static void apply_part(void *arg, uint32_t part, uint32_t nparts)
{
    const ajob *J = arg;
    const sd_csrb *s = J->s;
    /* whole chunks of SD_CHK rows, whose first explicit column kchk gives, cut so that each part
     * sums about as many entries (a vertex row of Loop has 7, an edge row 4: rows alone would
     * give the part with the vertex rows half as much again) */
    const uint64_t nchunks = ((uint64_t)s->nrows + SD_CHK - 1) / SD_CHK;
    const uint64_t total = entries_before(s, s->nrows);
    uint64_t c0 = chunk_at(s, nchunks, total * part / nparts);
    uint64_t c1 = part + 1 == nparts ? nchunks : chunk_at(s, nchunks, total * (part + 1) / nparts);
    uint32_t rlo = (uint32_t)(c0 * SD_CHK), rhi = (uint32_t)MINU(c1 * SD_CHK, (uint64_t)s->nrows);
    if (rlo >= rhi)
        return;
    size_t k = s->kchk[c0];
    if (J->nc == 3) {
        switch (s->pw) {
        case 1: apply_rows(s, 1, rlo, rhi, k, J->in, J->out, 3); break;
        case 2: apply_rows(s, 2, rlo, rhi, k, J->in, J->out, 3); break;
        default: apply_rows(s, 4, rlo, rhi, k, J->in, J->out, 3); break;
        }
    } else {
        apply_rows(s, s->pw, rlo, rhi, k, J->in, J->out, J->nc);
    }
}

void sdi_csr_apply(const sd_csrb *s, const double *in, double *out, int nc, int threads)
{
    ajob J = {s, in, out, nc};
    sdi_par_dyn(threads, s->nnz, 4, apply_part, &J);
}

/* ---- by columns: the rows that use each column (edits) --------------------------------------- */

/* An edit recomputes the rows that read a changed point, so it needs S by columns: for column j
 * (a point of this level), the rows (next-level points) that use it. Built with the next level
 * (levels.c), so an edit never waits for it. Rows come in increasing order, so each column's list
 * is kept as varint deltas: the first row as zigzag(r - j) (a point's own vertex row is among the
 * first, so this is small), then r - previous. That takes 1.2-1.8 bytes per entry on the meshes
 * of bench/ instead of 4 (docs/DECISIONS.md). Column j's bytes are
 * ub[ubase[j >> SDI_UBLK] + urel[j] .. same for j + 1). rchk gives the start in col of every
 * SD_RCHK-th row, so sdi_csrb_eval reaches any row after at most SD_RCHK - 1 row lengths. */

static inline uint32_t vlen(uint64_t v)
{
    uint32_t n = 1;
    while (v >= 128) {
        v >>= 7;
        n++;
    }
    return n;
}

static inline uint64_t zigzag(int64_t d) { return ((uint64_t)d << 1) ^ (uint64_t)(d >> 63); }

/* The code of row r in column c's list, whose previous row is last (UINT32_MAX: none yet). */
static inline uint64_t ucode(uint32_t r, uint32_t c, uint32_t last)
{
    return last == UINT32_MAX ? zigzag((int64_t)r - (int64_t)c) : (uint64_t)(r - last);
}

/* Per column while the index is made: the last row seen, and the bytes so far (pass 1) or where
 * the next code goes relative to the column's block (pass 2); one entry, so one cache line. */
typedef struct ucol {
    uint32_t last, at;
} ucol;

/* Pass 1 (ub = NULL) counts each column's bytes; pass 2 writes the codes (column c's block at
 * ubase[c >> SDI_UBLK]). Rows in order. */
static void index_pass(const sd_csrb *s, ucol *u, uint8_t *ub, const uint64_t *ubase, uint32_t *rchk)
{
    const uint32_t b1 = s->nvr, b2 = s->nvr + s->ner;
    size_t k = 0;
    for (uint32_t r = 0; r < s->nrows; r++) {
        if (rchk && r % SD_RCHK == 0)
            rchk[r / SD_RCHK] = (uint32_t)k; /* k < nnz < 2^32 (stencil.c) */
        uint32_t n = sdi_csrb_len(s, r), self = r;
        const uint32_t *imp = r < b1 ? &self : r < b2 ? s->ev[r - b1] : s->oct[r - b2];
        const uint32_t nimp = r < b1 ? 1 : r < b2 ? 2 : 6;
        const bool opp = r >= b1 && r < b2 && s->eopp;
        const uint32_t *exp = opp ? s->eopp[r - b1] : s->col + k;
        for (uint32_t i = 0; i < n; i++) {
            const uint32_t c = i < nimp ? imp[i] : exp[i - nimp];
            ucol *x = &u[c];
            uint64_t v = ucode(r, c, x->last);
            x->last = r;
            if (!ub) {
                x->at += vlen(v);
                continue;
            }
            uint8_t *p = ub + ubase[c >> SDI_UBLK] + x->at;
            uint32_t len = 0;
            while (v >= 128) {
                p[len++] = (uint8_t)(v | 128);
                v >>= 7;
            }
            p[len++] = (uint8_t)v;
            x->at += len;
        }
        if (!opp)
            k += n > nimp ? n - nimp : 0;
    }
}

sd_result sdi_csrb_index(sd_mem *m, sd_csrb *s, sd_error *err)
{
    if (s->ub)
        return SD_OK;
    const uint32_t nc = s->ncols, nr = s->nrows, nblk = (nc >> SDI_UBLK) + 1;
    ucol *u = sdi_alloc(m, ((size_t)nc + 1) * sizeof *u);
    uint32_t *rchk = sdi_alloc(m, ((size_t)nr / SD_RCHK + 1) * sizeof *rchk);
    uint64_t *ubase = sdi_alloc(m, (size_t)nblk * sizeof *ubase);
    uint32_t *urel = sdi_alloc(m, ((size_t)nc + 1) * sizeof *urel);
    uint8_t *ub = NULL;
    sd_result rc = SD_OK;
    if (!u || !rchk || !ubase || !urel)
        goto nomem;
    for (uint32_t j = 0; j < nc; j++)
        u[j] = (ucol){UINT32_MAX, 0};
    index_pass(s, u, NULL, NULL, rchk); /* each column's bytes, and the row checkpoints */
    uint64_t total = 0;
    for (uint32_t j = 0; j <= nc; j++) {
        if ((j & ((1u << SDI_UBLK) - 1)) == 0)
            ubase[j >> SDI_UBLK] = total;
        uint64_t rel = total - ubase[j >> SDI_UBLK];
        if (rel > UINT32_MAX) {
            rc = sdi_fail(err, SD_ERR_LIMIT, -1, -1, "subdivision matrix too large to index by columns");
            goto out;
        }
        urel[j] = (uint32_t)rel;
        total += j < nc ? u[j].at : 0;
    }
    if (!(ub = sdi_alloc(m, total ? total : 1)))
        goto nomem;
    for (uint32_t j = 0; j < nc; j++)
        u[j] = (ucol){UINT32_MAX, urel[j]};
    index_pass(s, u, ub, ubase, NULL);
    s->ub = ub;
    s->ubase = ubase;
    s->urel = urel;
    s->rchk = rchk;
    ub = NULL;
    ubase = NULL;
    urel = NULL;
    rchk = NULL;
    goto out;
nomem:
    rc = sdi_fail_nomem(err, m);
out:
    sdi_free(m, ub);
    sdi_free(m, ubase);
    sdi_free(m, urel);
    sdi_free(m, rchk);
    sdi_free(m, u);
    return rc;
}

void sdi_csrb_prefetch(const sd_csrb *s, uint32_t r, int stage)
{
    if (stage == 0) { /* what locates the row */
        __builtin_prefetch(&s->rchk[r / SD_RCHK]);
        __builtin_prefetch((const uint8_t *)s->pat + (size_t)r * s->pw);
        if (r >= s->nvr && r < s->nvr + s->ner)
            __builtin_prefetch(s->eopp ? s->eopp[r - s->nvr] : s->ev[r - s->nvr]);
    } else /* its explicit columns, near its checkpoint's */
        __builtin_prefetch(s->col + s->rchk[r / SD_RCHK]);
}

void sdi_csrb_eval(const sd_csrb *s, uint32_t r, const double *in, const int32_t *slot,
                   const double *alt, int nc, double *out, sdi_rowpos *at)
{
    /* row r's explicit columns: from its checkpoint, or from the row before (rows in order) */
    uint32_t r0 = r - r % SD_RCHK;
    size_t k = s->rchk[r0 / SD_RCHK];
    if (at && at->r >= r0 && at->r <= r) {
        r0 = at->r;
        k = at->k;
    }
    for (; r0 < r; r0++)
        k += sdi_csrb_nexp(s, r0);
    if (at) {
        at->r = r;
        at->k = k;
    }
    const uint32_t b1 = s->nvr, b2 = s->nvr + s->ner;
    uint32_t q = sdi_csrb_pat(s, r), n = s->woff[q + 1] - s->woff[q], self = r;
    const int blk = r < b1 ? 0 : r < b2 ? 1 : 2;
    const uint32_t *imp = blk == 0 ? &self : blk == 1 ? s->ev[r - b1] : s->oct[r - b2];
    const uint32_t nimp = blk == 0 ? 1 : blk == 1 ? 2 : 6;
    const uint32_t *exp = blk == 1 && s->eopp ? s->eopp[r - b1] : s->col + k;
    if (slot) /* two copies of row_sum: with the edit's new values, and without */
        row_sum(s->wt + s->woff[q], n, nimp, imp, exp, in, slot, alt, nc, out);
    else
        row_sum(s->wt + s->woff[q], n, nimp, imp, exp, in, NULL, NULL, nc, out);
}
