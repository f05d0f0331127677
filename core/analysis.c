/* analysis.c — local subdivision matrices and their eigenvalues (001 Sec. 4.1, Appendix B).
 *
 * For a vertex x with 1-ring rho(x) = {x_1..x_k} (as its rule reads it: edges, and major
 * diagonals in solids) the block M is (k+1)x(k+1): row 0 is x's vertex point, row i the new point
 * between x and x_i — the edge point of [x, x_i], or, when x_i is reached through an octahedron's
 * major diagonal, that octahedron's cell point — each as a function of x and its 1-ring. The rows
 * are read straight out of S_l, so the analysis uses exactly the stencils the service uses.
 * For an edge [a,b] the block L is M of the edge's midpoint after one level (a vertex of valence
 * 2k+2 with skew diagonals), which is how 001 Sec. 4.1 obtains the (2k+3)x(2k+3) block.
 * `closed` tells whether every row's support lies inside the block (the neighbourhood is then
 * invariant under subdivision, as for interior vertices and edges).
 */
#include "internal.h"
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

static int cmp_eig(const void *x, const void *y)
{
    const double *a = x, *b = y;
    double ma = hypot(a[0], a[1]), mb = hypot(b[0], b[1]);
    if (fabs(ma - mb) > 1e-12 * fmax(1, fmax(ma, mb)))
        return ma < mb ? 1 : -1;
    return a[0] < b[0] ? 1 : a[0] > b[0] ? -1 : (a[1] < b[1]) - (a[1] > b[1]);
}

static uint32_t find_diag_oct(const sd_topo *t, uint32_t a, uint32_t b)
{
    for (uint32_t o = 0; o < t->noct; o++)
        if ((t->oct[o][0] == a && t->oct[o][1] == b) || (t->oct[o][0] == b && t->oct[o][1] == a))
            return o;
    return UINT32_MAX;
}

static sd_result analyze(sd_complex *c, int level, uint32_t v, sd_analysis *out, sd_error *err)
{
    sd_result r = sdi_ensure_rules(c, level, err);
    if (r)
        return r;
    const sd_level *lv = c->lv[level];
    const sd_topo *t = &lv->t;
    const sd_csrb *S = &lv->S;
    size_t *start = sdi_csrb_starts(&c->mem, S); /* rows of S by id (a temporary table) */
    uint32_t *vcols = start ? malloc(2 * ((size_t)S->maxlen + 1) * sizeof *vcols) : NULL;
    if (!vcols) {
        sdi_free(&c->mem, start);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    uint32_t *pcols = vcols + S->maxlen + 1, vn = sdi_csrb_len(S, v);
    size_t k0 = start[v];
    sdi_csrb_row(S, v, &k0, vcols);
    int n = 1;
    for (uint32_t k = 0; k < vn; k++)
        n += vcols[k] != v;
    memset(out, 0, sizeof *out);
    out->size = n;
    out->level = level;
    out->rule = (sd_rule)lv->vrule[v];
    out->points = malloc((size_t)n * sizeof *out->points);
    uint32_t *rows = malloc((size_t)n * sizeof *rows);
    out->matrix = calloc((size_t)n * n, sizeof *out->matrix);
    out->eig_re = malloc((size_t)n * sizeof *out->eig_re);
    out->eig_im = malloc((size_t)n * sizeof *out->eig_im);
    double *a = malloc((size_t)n * n * sizeof *a);
    if (!out->points || !rows || !out->matrix || !out->eig_re || !out->eig_im || !a) {
        free(rows);
        free(a);
        free(vcols);
        sdi_free(&c->mem, start);
        sd_analysis_free(out);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    out->points[0] = v;
    rows[0] = v;
    int i = 1;
    for (uint32_t k = 0; k < vn; k++) {
        uint32_t x = vcols[k];
        if (x == v)
            continue;
        out->points[i] = x;
        uint32_t e = sdi_topo_find_edge(t, v, x);
        if (e != UINT32_MAX) {
            rows[i] = t->nv + e;
        } else {
            uint32_t o = find_diag_oct(t, v, x);
            rows[i] = o == UINT32_MAX ? UINT32_MAX : t->nv + t->ne + o;
        }
        i++;
    }
    out->closed = 1;
    for (int p = 0; p < n; p++) {
        if (rows[p] == UINT32_MAX) {
            out->closed = 0;
            continue;
        }
        size_t k = start[rows[p]];
        uint32_t pn = sdi_csrb_len(S, rows[p]);
        const double *w = sdi_csrb_row(S, rows[p], &k, pcols);
        for (uint32_t j = 0; j < pn; j++) {
            int q = 0;
            while (q < n && out->points[q] != pcols[j])
                q++;
            if (q == n)
                out->closed = 0;
            else
                out->matrix[(size_t)p * n + q] += w[j];
        }
    }
    free(rows);
    free(vcols);
    sdi_free(&c->mem, start);
    memcpy(a, out->matrix, (size_t)n * n * sizeof *a);
    lapack_int info = LAPACKE_dgeev(LAPACK_ROW_MAJOR, 'N', 'N', n, a, n, out->eig_re, out->eig_im,
                                    NULL, 1, NULL, 1);
    free(a);
    if (info != 0) {
        sd_analysis_free(out);
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "eigenvalue computation did not converge (%d)", (int)info);
    }
    double *pairs = malloc((size_t)n * 2 * sizeof *pairs);
    if (!pairs) {
        sd_analysis_free(out);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    for (int p = 0; p < n; p++) {
        pairs[2 * p] = out->eig_re[p];
        pairs[2 * p + 1] = out->eig_im[p];
    }
    qsort(pairs, (size_t)n, 2 * sizeof *pairs, cmp_eig);
    for (int p = 0; p < n; p++) {
        out->eig_re[p] = pairs[2 * p];
        out->eig_im[p] = pairs[2 * p + 1];
    }
    free(pairs);
    return SD_OK;
}

sd_result sd_analyze_vertex(sd_complex *c, uint32_t v, sd_analysis *out, sd_error *err)
{
    if (v >= c->lv[0]->t.nv)
        return sdi_fail(err, SD_ERR_ARG, v, -1, "vertex %u out of range (%u vertices)", v, c->lv[0]->t.nv);
    return analyze(c, 0, v, out, err);
}

sd_result sd_analyze_edge(sd_complex *c, uint32_t a, uint32_t b, sd_analysis *out, sd_error *err)
{
    const sd_topo *t0 = &c->lv[0]->t;
    uint32_t e = a < t0->nv && b < t0->nv ? sdi_topo_find_edge(t0, a, b) : UINT32_MAX;
    if (e == UINT32_MAX)
        return sdi_fail(err, SD_ERR_ARG, a, -1, "%u-%u is not an edge of the complex", a, b);
    sd_error local;
    if (!err)
        err = &local;
    if (!sd_complex_level(c, 1, err))
        return err->code;
    return analyze(c, 1, t0->nv + e, out, err);
}

void sd_analysis_free(sd_analysis *a)
{
    free(a->matrix);
    free(a->eig_re);
    free(a->eig_im);
    free(a->points);
    memset(a, 0, sizeof *a);
}
