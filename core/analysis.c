/* analysis.c — local subdivision matrices and their eigenvalues (001 Sec. 4.1, Appendix B).
 *
 * For a vertex x with 1-ring rho(x) = {x_1..x_k} (as its rule reads it: edges, and major
 * diagonals in solids) the block M is (k+1)x(k+1): row 0 is x's vertex point, row i the new point
 * between x and x_i — the edge point of [x, x_i], or, when x_i is opposite x in an octahedron (its
 * major diagonal; with the averaged scheme any opposite pair), that octahedron's cell point — each
 * as a function of x and its 1-ring. The rows
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

/* The octahedron in which a and b are opposite: its major diagonal (the box spline's rows read
 * those) or another of its three opposite pairs (the averaged scheme's rows read those too); its
 * cell point is the new point between a and b. */
static uint32_t find_opposite_oct(const sd_topo *t, uint32_t a, uint32_t b)
{
    for (uint32_t o = 0; o < t->noct; o++)
        for (int j = 0; j < 6; j += 2)
            if ((t->oct[o][j] == a && t->oct[o][j + 1] == b) || (t->oct[o][j] == b && t->oct[o][j + 1] == a))
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
    if (n > SD_ANALYSIS_MAX_POINTS) {
        free(vcols);
        sdi_free(&c->mem, start);
        return sdi_fail(err, SD_ERR_ARG, -1, -1,
                        "the block has %d points; analysis is offered for blocks of at most %d",
                        n, SD_ANALYSIS_MAX_POINTS);
    }
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
            uint32_t o = find_opposite_oct(t, v, x);
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

/* ---- the full matrix of the invariant neighbourhood (001 Sec. 4.1, Appendix B) ----------- */

/* The neighbourhood N at level 1 of a control vertex or edge: the level-1 points of the level-0
 * cells containing it (their vertices and the midpoints of their edges; level 1 has no cell
 * points): 5k - 5 points for an interior vertex of a solid, 4k + 3 for an interior edge (001
 * Figs. 16-17). Its points are matched with level-2 points by the scaling about the centre by
 * 1/2, in the parametric sense: each point's linear position (a vertex where it is, an edge point
 * at its edge's midpoint, a cell point at its octahedron's centre) is (c + P) / 2 for the level-2
 * point matched with P. Row i of the full matrix is S_1's row of the point matched with point i,
 * on N; the neighbourhood is invariant when every point has its match and every such row lies
 * inside N. Order: the centre and its 1-ring as the 1-ring block has them, then the rest by id. */

/* Linear position of level-1 point i (3 doubles). */
static void lin1(const sd_complex *c, uint32_t i, double *o)
{
    const sd_topo *t0 = &c->lv[0]->t;
    const double *x = c->lv[0]->ch[0].data;
    if (i < t0->nv) {
        memcpy(o, x + 3 * (size_t)i, 3 * sizeof *o);
        return;
    }
    const uint32_t *e = t0->ev[i - t0->nv];
    for (int k = 0; k < 3; k++)
        o[k] = 0.5 * (x[3 * (size_t)e[0] + k] + x[3 * (size_t)e[1] + k]);
}

static int add_id(uint32_t *ids, int n, int cap, uint32_t id)
{
    for (int i = 0; i < n; i++)
        if (ids[i] == id)
            return n;
    if (n < cap)
        ids[n++] = id;
    return n;
}

static sd_result full(sd_complex *c, uint32_t a, uint32_t b, const sd_analysis *blk,
                      sd_analysis *out, sd_error *err)
{
    memset(out, 0, sizeof *out);
    if (!sd_complex_level(c, 2, err))
        return err->code;
    sd_result r = sdi_ensure_rules(c, 1, err);
    if (r)
        return r;
    const sd_level *l0 = c->lv[0], *l1 = c->lv[1];
    const sd_topo *t0 = &l0->t, *t1 = &l1->t;
    sdi_rels R0 = {.t = t0}, R1 = {.t = t1};
    enum { CAP = 4096 };
    uint32_t *ids = malloc(CAP * sizeof *ids), *cand = malloc(CAP * sizeof *cand);
    double *cpos = malloc(3 * (size_t)CAP * sizeof *cpos);
    size_t *start = sdi_csrb_starts(&c->mem, &l1->S);
    uint32_t *cols = malloc(((size_t)l1->S.maxlen + 1) * sizeof *cols);
    if (!ids || !cand || !cpos || !start || !cols ||
        !sdi_rels_need(&c->mem, &R0, SDI_REL(SDI_VE)) || !sdi_rels_need(&c->mem, &R1, SDI_REL(SDI_VE))) {
        r = sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
        goto done;
    }
    /* N: the block's points first */
    int n = 0;
    for (int i = 0; i < blk->size; i++)
        n = add_id(ids, n, CAP, blk->points[i]);
    int nblk = n;
    for (int k = SD_CELL_CURVE; k <= SD_CELL_TETRA; k++) {
        uint32_t nc = sd_level_num_cells(l0, (sd_cell_kind)k), v[6];
        int m = sd_cell_size((sd_cell_kind)k);
        for (uint32_t i = 0; i < nc; i++) {
            sd_level_cell(l0, (sd_cell_kind)k, i, v);
            int ha = 0, hb = b == UINT32_MAX;
            for (int j = 0; j < m; j++)
                ha |= v[j] == a, hb |= v[j] == b;
            if (!ha || !hb)
                continue;
            for (int j = 0; j < m; j++) {
                n = add_id(ids, n, CAP, v[j]);
                for (int q = j + 1; q < m; q++) {
                    uint32_t e = sdi_rels_edge(&R0, v[j], v[q]);
                    if (e != UINT32_MAX)
                        n = add_id(ids, n, CAP, t0->nv + e);
                }
            }
        }
    }
    if (n >= CAP || n > SD_ANALYSIS_MAX_POINTS) { /* (not analysed: "full" is null) */
        r = sdi_fail(err, SD_ERR_ARG, -1, -1,
                     "the invariant neighbourhood has more than %d points", SD_ANALYSIS_MAX_POINTS);
        goto done;
    }
    /* the rest by id */
    for (int i = nblk; i < n; i++)
        for (int j = i + 1; j < n; j++)
            if (ids[j] < ids[i]) {
                uint32_t s = ids[i];
                ids[i] = ids[j];
                ids[j] = s;
            }
    /* level-2 candidates: children of N's points, of level-1 edges inside N and of octahedra
     * inside N, with their linear positions */
    int nc = 0;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int i = 0; i < n && nc < CAP; i++) {
        cand[nc] = ids[i];
        lin1(c, ids[i], cpos + 3 * (size_t)nc);
        for (int k = 0; k < 3; k++)
            lo[k] = fmin(lo[k], cpos[3 * (size_t)nc + k]), hi[k] = fmax(hi[k], cpos[3 * (size_t)nc + k]);
        nc++;
    }
    for (int i = 0; i < n; i++)
        for (int j = i + 1; j < n && nc < CAP; j++) {
            uint32_t e = sdi_rels_edge(&R1, ids[i], ids[j]);
            if (e == UINT32_MAX)
                continue;
            double p[3], q[3];
            lin1(c, ids[i], p);
            lin1(c, ids[j], q);
            cand[nc] = t1->nv + e;
            for (int k = 0; k < 3; k++)
                cpos[3 * (size_t)nc + k] = 0.5 * (p[k] + q[k]);
            nc++;
        }
    for (uint32_t o = 0; o < t1->noct && nc < CAP; o++) {
        int in = 0;
        for (int j = 0; j < 6; j++)
            for (int i = 0; i < n; i++)
                in += ids[i] == t1->oct[o][j];
        if (in != 6)
            continue;
        double p[3], q[3];
        lin1(c, t1->oct[o][0], p);
        lin1(c, t1->oct[o][1], q);
        cand[nc] = t1->nv + t1->ne + o;
        for (int k = 0; k < 3; k++)
            cpos[3 * (size_t)nc + k] = 0.5 * (p[k] + q[k]);
        nc++;
    }
    double scale = 0;
    for (int k = 0; k < 3; k++)
        scale = fmax(scale, hi[k] - lo[k]);
    double tol = 1e-9 * (scale > 0 ? scale : 1), cen[3];
    lin1(c, ids[0], cen);
    out->size = n;
    out->rule = blk->rule;
    out->level = 1;
    out->points = malloc((size_t)n * sizeof *out->points);
    out->matrix = calloc((size_t)n * n, sizeof *out->matrix);
    out->eig_re = malloc((size_t)n * sizeof *out->eig_re);
    out->eig_im = malloc((size_t)n * sizeof *out->eig_im);
    if (!out->points || !out->matrix || !out->eig_re || !out->eig_im) {
        sd_analysis_free(out);
        r = sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
        goto done;
    }
    memcpy(out->points, ids, (size_t)n * sizeof *ids);
    out->closed = 1;
    for (int i = 0; i < n; i++) {
        double p[3], want[3];
        lin1(c, ids[i], p);
        for (int k = 0; k < 3; k++)
            want[k] = 0.5 * (cen[k] + p[k]);
        int hit = -1, hits = 0;
        for (int j = 0; j < nc; j++)
            if (fabs(cpos[3 * (size_t)j] - want[0]) <= tol && fabs(cpos[3 * (size_t)j + 1] - want[1]) <= tol &&
                fabs(cpos[3 * (size_t)j + 2] - want[2]) <= tol)
                hit = j, hits++;
        if (hits != 1) {
            sd_analysis_free(out);
            r = sdi_fail(err, SD_ERR_ARG, ids[i], -1,
                         "the neighbourhood is not invariant: level-1 point %u has %s", ids[i],
                         hits ? "several matches" : "no match at level 2");
            goto done;
        }
        uint32_t row = cand[hit], len = sdi_csrb_len(&l1->S, row);
        size_t k0 = start[row];
        const double *w = sdi_csrb_row(&l1->S, row, &k0, cols);
        for (uint32_t q = 0; q < len; q++) {
            int j = 0;
            while (j < n && ids[j] != cols[q])
                j++;
            if (j == n) {
                out->closed = 0;
                continue;
            }
            out->matrix[(size_t)i * n + j] += w[q];
        }
    }
    if (!out->closed) {
        sd_analysis_free(out);
        r = sdi_fail(err, SD_ERR_ARG, -1, -1, "the neighbourhood is not invariant: a row reads "
                     "outside it");
        goto done;
    }
    double *m = malloc((size_t)n * n * sizeof *m), *pairs = malloc(2 * (size_t)n * sizeof *pairs);
    lapack_int info = -1;
    if (m && pairs) {
        memcpy(m, out->matrix, (size_t)n * n * sizeof *m);
        info = LAPACKE_dgeev(LAPACK_ROW_MAJOR, 'N', 'N', n, m, n, out->eig_re, out->eig_im, NULL, 1,
                             NULL, 1);
    }
    if (info == 0) {
        for (int p = 0; p < n; p++)
            pairs[2 * p] = out->eig_re[p], pairs[2 * p + 1] = out->eig_im[p];
        qsort(pairs, (size_t)n, 2 * sizeof *pairs, cmp_eig);
        for (int p = 0; p < n; p++)
            out->eig_re[p] = pairs[2 * p], out->eig_im[p] = pairs[2 * p + 1];
    }
    free(m);
    free(pairs);
    if (info != 0) {
        sd_analysis_free(out);
        r = info < 0 ? sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory")
                     : sdi_fail(err, SD_ERR_ARG, -1, -1, "eigenvalue computation did not converge");
        goto done;
    }
    r = SD_OK;
done:
    free(ids);
    free(cand);
    free(cpos);
    free(cols);
    sdi_free(&c->mem, start);
    sdi_rels_free(&c->mem, &R0);
    sdi_rels_free(&c->mem, &R1);
    return r;
}

sd_result sd_analyze_full_vertex(sd_complex *c, uint32_t v, sd_analysis *out, sd_error *err)
{
    sd_error local;
    if (!err)
        err = &local;
    sd_analysis blk;
    sd_result r = sd_analyze_vertex(c, v, &blk, err);
    if (r)
        return r;
    /* the block's points at level 1: v, and the edge points between v and its neighbours */
    sdi_rels R = {.t = &c->lv[0]->t};
    if (!sdi_rels_need(&c->mem, &R, SDI_REL(SDI_VE))) {
        sd_analysis_free(&blk);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    for (int i = 1; i < blk.size; i++) {
        uint32_t e = sdi_rels_edge(&R, v, blk.points[i]);
        if (e == UINT32_MAX) {
            sdi_rels_free(&c->mem, &R);
            sd_analysis_free(&blk);
            return sdi_fail(err, SD_ERR_ARG, v, -1, "vertex %u reads a neighbour through no edge", v);
        }
        blk.points[i] = c->lv[0]->t.nv + e;
    }
    sdi_rels_free(&c->mem, &R);
    r = full(c, v, UINT32_MAX, &blk, out, err);
    sd_analysis_free(&blk);
    return r;
}

sd_result sd_analyze_full_edge(sd_complex *c, uint32_t a, uint32_t b, sd_analysis *out, sd_error *err)
{
    sd_error local;
    if (!err)
        err = &local;
    sd_analysis blk;
    sd_result r = sd_analyze_edge(c, a, b, &blk, err);
    if (r)
        return r;
    r = full(c, a, b, &blk, out, err);
    sd_analysis_free(&blk);
    return r;
}
