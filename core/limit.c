/* limit.c — limit positions and limit normals of a level's points (001 Sec. 4; docs/RULES.md
 * "Limits").
 *
 * The limit of a point v of level L is l . p over v's 1-ring at a level E >= L, l the dominant
 * left eigenvector (eigenvalue 1) of v's local subdivision matrix there (the 1-ring block of
 * analysis.c: v's vertex point and the new points between v and its neighbours, read out of
 * S_E). E is the first level from which S no longer changes around v: past every detail offset
 * (the limit includes them), past every semi-sharp crease (s expires after ceil(s) levels) and,
 * for solids, level 1 at least (001 Sec. 4.1: the invariant neighbourhood); v keeps its index
 * from L to E (vertex points come first), so its limit is read at E directly, and a mask on
 * level-L points is the level-E mask composed with S_{E-1} ... S_L.
 *
 * Where the block is one of the closed forms, its eigenvector is written down, which is what
 * OpenSubdiv's Sdc limit masks are (the block is recognised from the rows of S themselves, so a
 * neighbour whose row differs — a dart's crease edge, a Ying-Zorin petal — falls to the
 * eigenvector):
 *   fixed     the vertex row is v alone: the limit is v;
 *   B-spline  the vertex row is 3/4 v + 1/8 (a + b), its edges to a and b midpoints (curves,
 *             surface boundaries and creases): 2/3 v + 1/6 (a + b);
 *   Loop      the vertex row is (1 - n beta) v + beta sum q, each edge row 3/8 (v + q_i) + 1/8
 *             over two ring points (Loop's or Warren's beta, surfaces and the solids' boundary):
 *             (1 - n chi) v + chi sum q, chi = 1 / (n + 3 / (8 beta)).
 * The Loop form is the left eigenvector of the block for any beta (its column 0 gives
 * n chi 3/8 = (1 - n chi) beta); Warren's beta = 3/(8n) (n > 3) makes it 1/2 v + 1/(2n) sum q,
 * and beta = 3/16 at n = 3 makes it 2/5 v + 1/5 sum q.
 * Every other block (solid interiors, G2, N1/N2 choices, Ying-Zorin's rows, darts) is solved
 * (LAPACKE_dgeev), cached by the block's bytes, so a configuration is solved once per call.
 *
 * Tangents: on a surface (its maximal triangles and the solids' boundary, oriented) a point whose
 * triangles make one fan gets OpenSubdiv's Loop tangent masks (Sdc::Scheme<SCHEME_LOOP>
 * assign*LimitTangentMasks): smooth (a closed fan, Loop block): cos / sin (2 pi i / n) over the
 * ring in the triangles' order; crease (B-spline block): 3/2 (q_a - q_b) along it and the
 * across mask over the ring between its two crease neighbours; corner (fixed): 3 (q_0 - v),
 * 3 (q_1 - v). The normal is t1 x t2, unit; on an interior crease (a closed fan) it is the unit
 * sum of its two sides' normals. No tangent plane elsewhere (curves, points, solid interiors,
 * fans that are not one).
 * The core does no I/O; temporaries come from the C library, as analysis.c's.
 */
#include "internal.h"
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- the evaluation level ---------------------------------------------------------------- */

int sd_complex_limit_level(const sd_complex *c, int level)
{
    int e = level;
    for (int l = level + 1; l <= SD_MAX_LEVEL; l++)
        for (int ch = 0; ch < c->lv[0]->nch; ch++)
            if (sdi_det(c, ch, l))
                e = l;
    float s = 0;
    for (uint32_t i = 0; i < c->sh.ne; i++)
        s = fmaxf(s, c->sh.es[i]);
    for (uint32_t i = 0; i < c->sh.nv; i++)
        s = fmaxf(s, c->sh.vs[i]);
    for (uint32_t i = 0; i < c->sh.nf; i++)
        s = fmaxf(s, c->sh.fs[i]);
    int sl = (int)ceilf(s);
    if (sl > e)
        e = sl;
    const sd_topo *t = &c->lv[0]->t;
    if (t->ntet && e < 1)
        e = 1;
    return e > SD_MAX_LEVEL ? SD_MAX_LEVEL : e;
}

/* ---- one level's context ----------------------------------------------------------------- */

typedef struct cache_entry {
    uint64_t h;
    int n;
    double *m, *l; /* the block and its limit weights */
} cache_entry;

typedef struct ctx {
    sd_complex *c;
    const sd_level *lv;
    const sd_topo *t;
    const sd_csrb *S;
    size_t *start;
    sdi_rels R;
    sdi_rel vo; /* vertex -> the octahedra holding it (any of their six vertices) */
    /* surface triangles around each vertex: tri[toff[v] .. toff[v+1]) (3 ids each, oriented) */
    uint32_t *toff, *tri, *tvert;
    uint32_t ntri;
    uint32_t *cols, *cols2, *fanbuf;
    uint32_t maxfan;
    cache_entry *cache;
    uint32_t ncache, capcache;
    int weights;
} ctx;

static void ctx_free(ctx *x)
{
    sdi_free(&x->c->mem, x->start);
    sdi_rels_free(&x->c->mem, &x->R);
    sdi_rel_free(&x->c->mem, &x->vo);
    free(x->toff);
    free(x->tri);
    free(x->tvert);
    free(x->cols);
    free(x->fanbuf);
    for (uint32_t i = 0; i < x->capcache; i++) {
        free(x->cache[i].m);
        free(x->cache[i].l);
    }
    free(x->cache);
    memset(x, 0, sizeof *x);
}

static sd_result ctx_init(ctx *x, sd_complex *c, int level, sd_error *err)
{
    memset(x, 0, sizeof *x);
    x->c = c;
    sd_result r = sdi_ensure_rules(c, level, err);
    if (r)
        return r;
    x->lv = c->lv[level];
    x->t = &x->lv->t;
    x->S = &x->lv->S;
    x->R.t = x->t;
    x->start = sdi_csrb_starts(&c->mem, x->S);
    uint32_t nv = x->t->nv;
    uint32_t ntr = sd_level_num_cells(x->lv, SD_CELL_TRIANGLE);
    uint32_t nb = sd_level_solid_boundary(x->lv, NULL);
    x->ntri = ntr + nb;
    x->tri = malloc(((size_t)x->ntri * 3 + 1) * sizeof *x->tri);
    x->toff = calloc((size_t)nv + 2, sizeof *x->toff);
    x->tvert = malloc(((size_t)x->ntri * 3 + 1) * sizeof *x->tvert);
    x->cols = malloc(2 * ((size_t)x->S->maxlen + 8) * sizeof *x->cols);
    if (!x->start || !x->tri || !x->toff || !x->tvert || !x->cols ||
        !sdi_rels_need(&c->mem, &x->R, SDI_REL(SDI_VE)) ||
        !sdi_rel_build(&c->mem, &x->vo, nv, x->t->noct, 6, 6, (const uint32_t *)x->t->oct)) {
        ctx_free(x);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    x->cols2 = x->cols + x->S->maxlen + 8;
    for (uint32_t i = 0; i < ntr; i++)
        sd_level_cell(x->lv, SD_CELL_TRIANGLE, i, x->tri + 3 * (size_t)i);
    sd_level_solid_boundary(x->lv, x->tri + 3 * (size_t)ntr);
    for (size_t k = 0; k < (size_t)x->ntri * 3; k++)
        x->toff[x->tri[k] + 2]++;
    for (uint32_t v = 0; v < nv; v++)
        x->toff[v + 2] += x->toff[v + 1];
    for (uint32_t f = 0; f < x->ntri; f++)
        for (int j = 0; j < 3; j++)
            x->tvert[x->toff[x->tri[3 * (size_t)f + j] + 1]++] = f;
    for (uint32_t v = 0; v < nv; v++)
        if (x->toff[v + 1] - x->toff[v] > x->maxfan)
            x->maxfan = x->toff[v + 1] - x->toff[v];
    if (!(x->fanbuf = malloc(2 * ((size_t)x->maxfan + 1) * sizeof *x->fanbuf))) {
        ctx_free(x);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    x->weights = c->opt.surface_weights;
    return SD_OK;
}

/* Row r of S: its length, columns into cols, weights returned. */
static const double *row(const ctx *x, uint32_t r, uint32_t *cols, uint32_t *len)
{
    size_t k = x->start[r];
    *len = sdi_csrb_len(x->S, r);
    return sdi_csrb_row(x->S, r, &k, cols);
}

/* The row of the new point between v and x: the edge point, or the cell point of the octahedron
 * in which v and x are opposite (its major diagonal, which the box spline's rows read, or another
 * opposite pair, which the averaged scheme's read: the cell point is the centroid, and at the next
 * level it is v's opposite in v's corner octahedron); UINT32_MAX if neither. */
static uint32_t between(const ctx *x, uint32_t v, uint32_t w)
{
    uint32_t e = sdi_rels_edge(&x->R, v, w);
    if (e != UINT32_MAX)
        return x->t->nv + e;
    const sdi_rel *d = &x->vo;
    for (uint32_t k = d->off[v]; k < d->off[v + 1]; k++) {
        const uint32_t *o = x->t->oct[d->item[k]];
        for (int j = 0; j < 6; j++)
            if (o[j] == v && o[j ^ 1] == w)
                return x->t->nv + x->t->ne + d->item[k];
    }
    return UINT32_MAX;
}

static bool near(double a, double b) { return fabs(a - b) <= 1e-14; }

/* The ring of v (as its vertex row reads it) in points[0..n), v first. */
static int ring_of(const ctx *x, uint32_t v, uint32_t *points, double *vw)
{
    uint32_t len;
    const double *w = row(x, v, x->cols, &len);
    int n = 1;
    points[0] = v;
    vw[0] = 0;
    for (uint32_t k = 0; k < len; k++) {
        int q = 0;
        while (q < n && points[q] != x->cols[k])
            q++;
        if (q == n) {
            points[n] = x->cols[k];
            vw[n++] = 0;
        }
        vw[q] += w[k];
    }
    return n;
}

/* The closed forms (see the head of the file): SD_LIMIT_FIXED, _BSPLINE, _LOOP or -1. */
static int closed_form(const ctx *x, uint32_t v, int n, const uint32_t *pts, const double *vw,
                       double *l)
{
    if (n == 1 && near(vw[0], 1)) {
        l[0] = 1;
        return SD_LIMIT_FIXED;
    }
    uint32_t len;
    if (n == 3 && near(vw[0], 0.75) && near(vw[1], 0.125) && near(vw[2], 0.125)) {
        for (int i = 1; i < 3; i++) {
            uint32_t r = between(x, v, pts[i]);
            if (r == UINT32_MAX)
                return -1;
            const double *w = row(x, r, x->cols2, &len);
            double a = 0, b = 0;
            for (uint32_t k = 0; k < len; k++) {
                if (x->cols2[k] == v)
                    a += w[k];
                else if (x->cols2[k] == pts[i])
                    b += w[k];
                else if (w[k] != 0)
                    return -1;
            }
            if (!near(a, 0.5) || !near(b, 0.5))
                return -1;
        }
        l[0] = 2.0 / 3;
        l[1] = l[2] = 1.0 / 6;
        return SD_LIMIT_BSPLINE;
    }
    if (n < 4)
        return -1;
    double beta = vw[1];
    for (int i = 1; i < n; i++)
        if (!near(vw[i], beta))
            return -1;
    if (!near(vw[0], 1 - (n - 1) * beta) || beta <= 0)
        return -1;
    for (int i = 1; i < n; i++) {
        uint32_t r = between(x, v, pts[i]);
        if (r == UINT32_MAX)
            return -1;
        const double *w = row(x, r, x->cols2, &len);
        double a = 0, b = 0, o = 0;
        int no = 0;
        for (uint32_t k = 0; k < len; k++) {
            if (x->cols2[k] == v)
                a += w[k];
            else if (x->cols2[k] == pts[i])
                b += w[k];
            else {
                int q = 1;
                while (q < n && pts[q] != x->cols2[k])
                    q++;
                if (q == n && w[k] != 0)
                    return -1;
                o += w[k];
                no += w[k] != 0;
            }
        }
        if (!near(a, 0.375) || !near(b, 0.375) || !near(o, 0.25) || no != 2)
            return -1;
    }
    int m = n - 1;
    double chi = 1.0 / (m + 3.0 / (8.0 * beta));
    l[0] = 1 - m * chi;
    for (int i = 1; i < n; i++)
        l[i] = chi;
    return SD_LIMIT_LOOP;
}

static uint64_t hash_block(const double *m, int n)
{
    uint64_t h = 1469598103934665603ull ^ (uint64_t)n;
    const unsigned char *p = (const unsigned char *)m;
    for (size_t i = 0; i < (size_t)n * n * sizeof *m; i++)
        h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

/* The block of v on pts (n points) into m (n x n); false if a row reads outside it. */
static bool block(const ctx *x, uint32_t v, int n, const uint32_t *pts, const double *vw, double *m)
{
    memset(m, 0, (size_t)n * n * sizeof *m);
    memcpy(m, vw, (size_t)n * sizeof *m);
    for (int i = 1; i < n; i++) {
        uint32_t r = between(x, v, pts[i]), len;
        if (r == UINT32_MAX)
            return false;
        const double *w = row(x, r, x->cols2, &len);
        for (uint32_t k = 0; k < len; k++) {
            int q = 0;
            while (q < n && pts[q] != x->cols2[k])
                q++;
            if (q == n)
                return false;
            m[(size_t)i * n + q] += w[k];
        }
    }
    return true;
}

/* The left eigenvector of eigenvalue 1 of the n x n block m, summing to 1, into l; lambda1 the
 * largest magnitude of the other eigenvalues. false: no simple dominant eigenvalue 1. */
static bool eigen_limit(const double *m, int n, double *l, double *lambda1)
{
    double *a = malloc((size_t)n * n * sizeof *a), *wr = malloc((size_t)n * 3 * sizeof *wr);
    double *vl = malloc((size_t)n * n * sizeof *vl);
    bool ok = false;
    if (!a || !wr || !vl)
        goto out;
    double *wi = wr + n;
    memcpy(a, m, (size_t)n * n * sizeof *a);
    if (LAPACKE_dgeev(LAPACK_ROW_MAJOR, 'V', 'N', n, a, n, wr, wi, vl, n, NULL, 1) != 0)
        goto out;
    int j = -1;
    for (int i = 0; i < n; i++)
        if (fabs(wi[i]) < 1e-12 && (j < 0 || fabs(wr[i] - 1) < fabs(wr[j] - 1)))
            j = i;
    if (j < 0 || fabs(wr[j] - 1) > 1e-9)
        goto out;
    double s = 0, lam = 0;
    for (int i = 0; i < n; i++) {
        s += vl[(size_t)i * n + j];
        if (i != j)
            lam = fmax(lam, hypot(wr[i], wi[i]));
    }
    if (fabs(s) < 1e-300 || lam >= 1 - 1e-9)
        goto out;
    for (int i = 0; i < n; i++)
        l[i] = vl[(size_t)i * n + j] / s;
    *lambda1 = lam;
    ok = true;
out:
    free(a);
    free(wr);
    free(vl);
    return ok;
}

/* The limit weights of v on pts (n points, v first) at this level: the method. */
static int position_mask(ctx *x, uint32_t v, int *np, uint32_t *pts, double *l, double *m)
{
    double *vw = l; /* the vertex row's weights, replaced by the mask */
    int n = ring_of(x, v, pts, vw);
    *np = n;
    int how = closed_form(x, v, n, pts, vw, l); /* writes l only when it succeeds */
    if (how >= 0)
        return how;
    if (n > SD_ANALYSIS_MAX_POINTS) /* (sd.h: the eigenvectors of a larger block are not sought) */
        return SD_LIMIT_NONE;
    if (!block(x, v, n, pts, vw, m))
        return SD_LIMIT_NONE;
    uint64_t h = hash_block(m, n);
    if (x->capcache) {
        uint32_t i = (uint32_t)(h % x->capcache);
        for (; x->cache[i].m; i = (i + 1) % x->capcache)
            if (x->cache[i].h == h && x->cache[i].n == n &&
                !memcmp(x->cache[i].m, m, (size_t)n * n * sizeof *m)) {
                memcpy(l, x->cache[i].l, (size_t)n * sizeof *l);
                return SD_LIMIT_EIGEN;
            }
    }
    double lam;
    if (!eigen_limit(m, n, l, &lam))
        return SD_LIMIT_NONE;
    if (2 * (x->ncache + 1) > x->capcache) { /* grow (rehash) */
        uint32_t cap = x->capcache ? 2 * x->capcache : 64;
        cache_entry *nc = calloc(cap, sizeof *nc);
        if (!nc)
            return SD_LIMIT_EIGEN; /* not cached */
        for (uint32_t i = 0; i < x->capcache; i++)
            if (x->cache[i].m) {
                uint32_t k = (uint32_t)(x->cache[i].h % cap);
                while (nc[k].m)
                    k = (k + 1) % cap;
                nc[k] = x->cache[i];
            }
        free(x->cache);
        x->cache = nc;
        x->capcache = cap;
    }
    double *cm = malloc((size_t)n * n * sizeof *cm), *cl = malloc((size_t)n * sizeof *cl);
    if (!cm || !cl) {
        free(cm);
        free(cl);
        return SD_LIMIT_EIGEN;
    }
    memcpy(cm, m, (size_t)n * n * sizeof *cm);
    memcpy(cl, l, (size_t)n * sizeof *cl);
    uint32_t k = (uint32_t)(h % x->capcache);
    while (x->cache[k].m)
        k = (k + 1) % x->capcache;
    x->cache[k] = (cache_entry){h, n, cm, cl};
    x->ncache++;
    return SD_LIMIT_EIGEN;
}

/* ---- tangents ---------------------------------------------------------------------------- */

/* v's triangles as one fan: ring[0..*nr) in the triangles' order (around v counter-clockwise
 * for outward orientation); *closed when the fan goes all round. false: not one fan. */
static bool fan(const ctx *x, uint32_t v, uint32_t *ring, int *nr, bool *closed, int cap)
{
    uint32_t b = x->toff[v], e = x->toff[v + 1], n = e - b;
    if (n == 0 || (int)n + 1 > cap)
        return false;
    /* each triangle as (a, b) after v */
    uint32_t *A = x->fanbuf, *B = x->fanbuf + n;
    for (uint32_t i = 0; i < n; i++) {
        const uint32_t *f = x->tri + 3 * (size_t)x->tvert[b + i];
        int j = f[0] == v ? 0 : f[1] == v ? 1 : 2;
        A[i] = f[(j + 1) % 3];
        B[i] = f[(j + 2) % 3];
    }
    /* the start: a triangle whose a is no triangle's b (an open fan), else the first */
    uint32_t s = 0;
    int starts = 0;
    for (uint32_t i = 0; i < n; i++) {
        bool prev = false;
        for (uint32_t k = 0; k < n && !prev; k++)
            prev = B[k] == A[i];
        if (!prev) {
            s = i;
            starts++;
        }
    }
    if (starts > 1)
        return false;
    ring[0] = A[s];
    uint32_t cur = s, got = 1;
    ring[1] = B[s];
    int m = 2;
    while (got < n) {
        uint32_t nx = UINT32_MAX;
        for (uint32_t k = 0; k < n; k++)
            if (A[k] == B[cur]) {
                if (nx != UINT32_MAX)
                    return false; /* two triangles continue the fan */
                nx = k;
            }
        if (nx == UINT32_MAX)
            return false;
        cur = nx;
        got++;
        ring[m++] = B[cur];
    }
    *closed = starts == 0;
    if (*closed) {
        if (ring[m - 1] != ring[0])
            return false;
        m--;
    }
    for (int i = 0; i < m; i++)
        for (int k = i + 1; k < m; k++)
            if (ring[i] == ring[k])
                return false;
    *nr = m;
    return true;
}

/* OpenSubdiv's crease tangents (assignCreaseLimitTangentMasks) for the span ring[c0 .. c1]
 * of v: weights t1, t2 on v (index 0) and ring[i] (index i + 1). */
static void crease_tangents(int nr, int c0, int c1, double *t1, double *t2)
{
    memset(t1, 0, (size_t)(nr + 1) * sizeof *t1);
    memset(t2, 0, (size_t)(nr + 1) * sizeof *t2);
    t1[1 + c0] = 1.5;
    t1[1 + c1 % nr] = -1.5;
    int inner = c1 - c0 - 1;
    if (inner == 2) {
        double r3 = 1.73205080756887729352, r32 = r3 * 0.5;
        t2[0] = -r3;
        t2[1 + c0] = -r32;
        t2[1 + c1 % nr] += -r32;
        t2[1 + (c0 + 1) % nr] = r3;
        t2[1 + (c0 + 2) % nr] = r3;
    } else if (inner > 2) {
        double th = M_PI / (inner + 1), cw = -3.0 * sin(th), ec = -3.0 * 2.0 * (cos(th) - 1.0);
        t2[1 + c0] = cw;
        t2[1 + c1 % nr] += cw;
        for (int i = 1; i <= inner; i++)
            t2[1 + (c0 + i) % nr] = ec * sin(i * th);
    } else if (inner == 1) {
        t2[0] = -3.0;
        t2[1 + (c0 + 1) % nr] = 3.0;
    } else {
        t2[0] = -6.0;
        t2[1 + c0] += 3.0;
        t2[1 + c1 % nr] += 3.0;
    }
}

static void apply3(const double *x, uint32_t v, const uint32_t *ring, int nr, const double *w,
                   double out[3])
{
    for (int k = 0; k < 3; k++) {
        double s = w[0] * x[3 * (size_t)v + k];
        for (int i = 0; i < nr; i++)
            s += w[i + 1] * x[3 * (size_t)ring[i] + k];
        out[k] = s;
    }
}

static bool unit_cross(const double a[3], const double b[3], double n[3])
{
    n[0] = a[1] * b[2] - a[2] * b[1];
    n[1] = a[2] * b[0] - a[0] * b[2];
    n[2] = a[0] * b[1] - a[1] * b[0];
    double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (!(len > 0))
        return false;
    for (int k = 0; k < 3; k++)
        n[k] /= len;
    return true;
}

/* The tangent masks of v (method how, position mask on pts) on ring order: returns how many
 * tangent pairs (0: none, 1, or 2 for the two sides of an interior crease) with weights on v then
 * ring[0..nr) in t (2 (nr + 1) doubles per pair). */
static int tangent_masks(ctx *x, uint32_t v, int how, const uint32_t *pts, int n, uint32_t *ring,
                         int *nrp, double *t, int cap)
{
    int nr;
    bool closed;
    if (how < 0 || how == SD_LIMIT_EIGEN || !fan(x, v, ring, &nr, &closed, cap))
        return 0;
    *nrp = nr;
    double *t1 = t, *t2 = t + nr + 1;
    if (how == SD_LIMIT_LOOP) {
        if (!closed || nr != n - 1)
            return 0;
        t1[0] = t2[0] = 0;
        for (int i = 0; i < nr; i++) {
            double a = 2.0 * M_PI / nr * i;
            t1[i + 1] = nr == 6 ? (double[]){1, .5, -.5, -1, -.5, .5}[i] : cos(a);
            t2[i + 1] = nr == 6 ? 0.5 * 1.73205080756887729352 * (double[]){0, 1, 1, 0, -1, -1}[i]
                                : sin(a);
        }
        return 1;
    }
    if (how == SD_LIMIT_FIXED) {
        if (nr < 2)
            return 0;
        memset(t, 0, 2 * (size_t)(nr + 1) * sizeof *t);
        t1[0] = t2[0] = -3.0;
        t1[1] = 3.0;
        t2[2] = 3.0;
        return 1;
    }
    /* B-spline: the crease neighbours' places in the ring */
    int c[2], nc = 0;
    for (int i = 0; i < nr; i++)
        if (ring[i] == pts[1] || ring[i] == pts[2]) {
            if (nc == 2)
                return 0;
            c[nc++] = i;
        }
    if (nc != 2)
        return 0;
    if (!closed) {
        if (c[0] != 0 || c[1] != nr - 1)
            return 0;
        crease_tangents(nr, 0, nr - 1, t1, t2);
        return 1;
    }
    crease_tangents(nr, c[0], c[1], t1, t2);
    crease_tangents(nr, c[1], c[0] + nr, t + 2 * (nr + 1), t + 3 * (nr + 1));
    return 2;
}

/* ---- public ------------------------------------------------------------------------------ */

/* Scratch for one point's masks: room for its ring. */
typedef struct scratch {
    uint32_t *pts, *ring;
    double *l, *m, *t;
    int cap;
} scratch;

static bool scratch_init(scratch *s, int cap)
{
    s->cap = cap;
    s->pts = malloc((size_t)cap * sizeof *s->pts);
    s->ring = malloc((size_t)cap * sizeof *s->ring);
    s->l = malloc((size_t)cap * sizeof *s->l);
    s->m = malloc((size_t)cap * cap * sizeof *s->m);
    s->t = malloc(4 * ((size_t)cap + 1) * sizeof *s->t);
    return s->pts && s->ring && s->l && s->m && s->t;
}

static void scratch_free(scratch *s)
{
    free(s->pts);
    free(s->ring);
    free(s->l);
    free(s->m);
    free(s->t);
}

sd_result sd_complex_limit(sd_complex *c, int level, int channel, double *out, double *normals,
                           sd_error *err)
{
    if (level < 0 || level > SD_MAX_LEVEL)
        return sdi_fail(err, SD_ERR_ARG, level, -1, "level %d out of range 0..%d", level,
                        SD_MAX_LEVEL);
    int e = sd_complex_limit_level(c, level);
    sd_error local;
    if (!err)
        err = &local;
    const sd_level *lvl = sd_complex_level(c, level, err), *lve = sd_complex_level(c, e, err);
    if (!lvl || !lve)
        return err->code;
    int nc;
    const double *p = sd_level_channel(lve, channel, &nc);
    if (!p)
        return sdi_fail(err, SD_ERR_ARG, channel, -1, "no channel %d", channel);
    const double *x = sd_level_channel(lve, 0, &(int){0});
    ctx X;
    sd_result r = ctx_init(&X, c, e, err);
    if (r)
        return r;
    scratch s;
    if (!scratch_init(&s, (int)(X.S->maxlen > X.maxfan ? X.S->maxlen : X.maxfan) + 4)) {
        scratch_free(&s);
        ctx_free(&X);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    uint32_t nv = sd_level_num_vertices(lvl);
    for (uint32_t v = 0; v < nv; v++) {
        int n;
        int how = position_mask(&X, v, &n, s.pts, s.l, s.m);
        double *o = out + (size_t)v * nc;
        if (how == SD_LIMIT_NONE)
            n = 1, s.l[0] = 1, s.pts[0] = v;
        for (int k = 0; k < nc; k++) {
            double acc = 0;
            for (int i = 0; i < n; i++)
                acc += s.l[i] * p[(size_t)s.pts[i] * nc + k];
            o[k] = acc;
        }
        if (!normals)
            continue;
        double *nn = normals + 3 * (size_t)v;
        nn[0] = nn[1] = nn[2] = 0;
        int nr = 0;
        int pairs = tangent_masks(&X, v, how, s.pts, n, s.ring, &nr, s.t, s.cap);
        double acc[3] = {0, 0, 0};
        for (int q = 0; q < pairs; q++) {
            double a[3], b[3], u[3];
            apply3(x, v, s.ring, nr, s.t + 2 * q * (nr + 1), a);
            apply3(x, v, s.ring, nr, s.t + (2 * q + 1) * (nr + 1), b);
            if (unit_cross(a, b, u))
                for (int k = 0; k < 3; k++)
                    acc[k] += u[k];
        }
        double len = sqrt(acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]);
        if (len > 0)
            for (int k = 0; k < 3; k++)
                nn[k] = acc[k] / len;
    }
    scratch_free(&s);
    ctx_free(&X);
    return SD_OK;
}

/* A sparse vector on one level's points (sorted insert, small). */
static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

typedef struct svec {
    uint32_t n, cap;
    uint32_t *id;
    double *w;
} svec;

static bool svec_add(svec *s, uint32_t id, double w)
{
    for (uint32_t i = 0; i < s->n; i++)
        if (s->id[i] == id) {
            s->w[i] += w;
            return true;
        }
    if (s->n == s->cap) {
        uint32_t cap = s->cap ? 2 * s->cap : 32;
        uint32_t *ni = realloc(s->id, cap * sizeof *ni);
        if (!ni)
            return false;
        s->id = ni;
        double *nw = realloc(s->w, cap * sizeof *nw);
        if (!nw)
            return false;
        s->w = nw;
        s->cap = cap;
    }
    s->id[s->n] = id;
    s->w[s->n++] = w;
    return true;
}

void sd_limit_mask_free(sd_limit_mask *m)
{
    free(m->points);
    free(m->w);
    free(m->t1);
    free(m->t2);
    memset(m, 0, sizeof *m);
}

sd_result sd_limit_mask_of(sd_complex *c, int level, uint32_t v, sd_limit_mask *out,
                           sd_error *err)
{
    memset(out, 0, sizeof *out);
    sd_error local;
    if (!err)
        err = &local;
    if (level < 0 || level > SD_MAX_LEVEL)
        return sdi_fail(err, SD_ERR_ARG, level, -1, "level %d out of range 0..%d", level,
                        SD_MAX_LEVEL);
    const sd_level *lvl = sd_complex_level(c, level, err);
    if (!lvl)
        return err->code;
    if (v >= sd_level_num_vertices(lvl))
        return sdi_fail(err, SD_ERR_INDEX, v, -1, "vertex %u out of range (%u vertices)", v,
                        sd_level_num_vertices(lvl));
    int e = sd_complex_limit_level(c, level);
    if (!sd_complex_level(c, e, err))
        return err->code;
    ctx X;
    sd_result r = ctx_init(&X, c, e, err);
    if (r)
        return r;
    scratch s;
    svec vec[3] = {{0}};
    if (!scratch_init(&s, (int)(X.S->maxlen > X.maxfan ? X.S->maxlen : X.maxfan) + 4)) {
        scratch_free(&s);
        ctx_free(&X);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    int n;
    int how = position_mask(&X, v, &n, s.pts, s.l, s.m);
    if (how == SD_LIMIT_NONE)
        n = 1, s.l[0] = 1, s.pts[0] = v;
    int nr = 0;
    int pairs = tangent_masks(&X, v, how, s.pts, n, s.ring, &nr, s.t, s.cap);
    bool ok = true;
    for (int i = 0; i < n && ok; i++)
        ok = svec_add(&vec[0], s.pts[i], s.l[i]);
    if (pairs == 1)
        for (int q = 0; q < 2 && ok; q++) {
            const double *w = s.t + q * (nr + 1);
            ok = svec_add(&vec[1 + q], v, w[0]);
            for (int i = 0; i < nr && ok; i++)
                ok = svec_add(&vec[1 + q], s.ring[i], w[i + 1]);
        }
    scratch_free(&s);
    ctx_free(&X);
    /* compose down to `level`: a point of level l + 1 is its row of S_l on level l's points
     * plus its detail offset, which goes to the constant terms */
    double *cst[3] = {out->offset, out->t_offset[0], out->t_offset[1]};
    for (int l = e - 1; l >= level && ok; l--) {
        const uint32_t *didx;
        const double *doff;
        size_t nd = sd_complex_details(c, 0, l + 1, &didx, &doff);
        for (int q = 0; q < 3 && nd; q++)
            for (uint32_t i = 0; i < vec[q].n; i++) {
                const uint32_t *hit = bsearch(&vec[q].id[i], didx, nd, sizeof *didx, cmp_u32);
                for (int k = 0; hit && k < 3; k++)
                    cst[q][k] += vec[q].w[i] * doff[3 * (size_t)(hit - didx) + k];
            }
        ctx Y;
        if ((r = ctx_init(&Y, c, l, err))) {
            for (int q = 0; q < 3; q++)
                free(vec[q].id), free(vec[q].w);
            return r;
        }
        for (int q = 0; q < 3 && ok; q++) {
            svec nv2 = {0};
            for (uint32_t i = 0; i < vec[q].n && ok; i++) {
                uint32_t len;
                const double *w = row(&Y, vec[q].id[i], Y.cols, &len);
                for (uint32_t k = 0; k < len && ok; k++)
                    ok = svec_add(&nv2, Y.cols[k], vec[q].w[i] * w[k]);
            }
            free(vec[q].id);
            free(vec[q].w);
            vec[q] = nv2;
        }
        ctx_free(&Y);
    }
    if (!ok) {
        for (int q = 0; q < 3; q++)
            free(vec[q].id), free(vec[q].w);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    /* the tangents' points join the position mask's (with weight 0 there) */
    for (int q = 1; q < 3 && ok; q++)
        for (uint32_t i = 0; i < vec[q].n && ok; i++)
            ok = svec_add(&vec[0], vec[q].id[i], 0);
    out->t1 = pairs == 1 ? calloc(vec[0].n + 1, sizeof *out->t1) : NULL;
    out->t2 = pairs == 1 ? calloc(vec[0].n + 1, sizeof *out->t2) : NULL;
    if (!ok || (pairs == 1 && (!out->t1 || !out->t2))) {
        for (int q = 0; q < 3; q++)
            free(vec[q].id), free(vec[q].w);
        sd_limit_mask_free(out);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory");
    }
    for (int q = 1; q < 3 && pairs == 1; q++)
        for (uint32_t i = 0; i < vec[q].n; i++) {
            uint32_t k = 0;
            while (vec[0].id[k] != vec[q].id[i])
                k++;
            (q == 1 ? out->t1 : out->t2)[k] += vec[q].w[i];
        }
    out->n = (int)vec[0].n;
    out->points = vec[0].id;
    out->w = vec[0].w;
    out->level = level;
    out->eval_level = e;
    out->method = how;
    for (int q = 1; q < 3; q++)
        free(vec[q].id), free(vec[q].w);
    return SD_OK;
}
