/* geom.c — the geometry the writers share, computed before the first byte is written: the
 * outward boundary of the solids and area-weighted vertex normals (glTF; cached per level through
 * out_geometry), the cross-section of the solids by a plane (every writer), and an octahedron as
 * the 4 tetrahedra around its major diagonal (VTK's cells, the slice).
 *
 * Arrays here are proportional to the boundary, the slice or the vertex count, never to the
 * output. The slice cuts each tetrahedron (and each of an octahedron's 4 tetrahedra) by the plane
 * n.x = d with n made unit: one triangle where one corner is apart, two where two are, each facing
 * +n, its point data interpolated along the cut edges; a corner on the plane counts as below it,
 * and a triangle that would have two corners at one point (the plane through a vertex) is not
 * made. Nothing here writes bytes.
 */
#include "out_internal.h"
#include "mem.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- the cross-section ------------------------------------------------------------------ */

typedef struct slicer {
    out_stream *s;
    double n[3], d;
    uint32_t cap;
    bool failed;
} slicer;

static bool slice_grow(slicer *sl)
{
    out_slice *o = &sl->s->slice;
    if (o->ntri < sl->cap)
        return true;
    uint32_t cap = sl->cap ? 2 * sl->cap : 1024;
    double *xyz = api_realloc(o->xyz, (size_t)cap * 9 * sizeof *xyz);
    if (xyz)
        o->xyz = xyz;
    uint32_t *cell = api_realloc(o->cell, (size_t)cap * sizeof *cell);
    if (cell)
        o->cell = cell;
    uint8_t *kind = api_realloc(o->kind, cap);
    if (kind)
        o->kind = kind;
    if (!xyz || !cell || !kind)
        return false;
    for (int a = 0; a < sl->s->rq.nattrs; a++) {
        int nc = sl->s->rq.attrs[a].ncomp;
        double *v = api_realloc(o->attr[a], (size_t)cap * 3 * nc * sizeof *v);
        if (!v)
            return false;
        o->attr[a] = v;
    }
    sl->cap = cap;
    return true;
}

/* A point on edge a-b at parameter t, written as point `slot` of the current triangle. */
static void slice_point(slicer *sl, uint32_t a, uint32_t b, double t, int slot)
{
    out_stream *s = sl->s;
    out_slice *o = &s->slice;
    for (int k = 0; k < 3; k++)
        o->xyz[9 * (size_t)o->ntri + 3 * slot + k] =
            s->xyz[3 * (size_t)a + k] + t * (s->xyz[3 * (size_t)b + k] - s->xyz[3 * (size_t)a + k]);
    for (int i = 0; i < s->rq.nattrs; i++) {
        int nc = s->rq.attrs[i].ncomp;
        const double *v = s->attr[i];
        for (int k = 0; k < nc; k++)
            o->attr[i][((size_t)o->ntri * 3 + slot) * nc + k] =
                v[(size_t)a * nc + k] + t * (v[(size_t)b * nc + k] - v[(size_t)a * nc + k]);
    }
}

typedef struct cut { uint32_t a, b; double t; } cut;

static void slice_tri(slicer *sl, const cut *c0, const cut *c1, const cut *c2, uint32_t cell,
                      uint8_t kind)
{
    if (!slice_grow(sl)) {
        sl->failed = true;
        return;
    }
    out_slice *o = &sl->s->slice;
    const cut *c[3] = {c0, c1, c2};
    for (int i = 0; i < 3; i++)
        slice_point(sl, c[i]->a, c[i]->b, c[i]->t, i);
    double *p = o->xyz + 9 * (size_t)o->ntri, u[3], v[3];
    /* two corners at one point (cuts at a vertex on the plane, or rounded onto one): no area,
     * and its two other sides are one segment both ways, so leaving it out leaves the section
     * as closed as it was; what was written in this slot is overwritten by the next one */
    if (!memcmp(p, p + 3, 3 * sizeof *p) || !memcmp(p + 3, p + 6, 3 * sizeof *p) ||
        !memcmp(p + 6, p, 3 * sizeof *p))
        return;
    for (int k = 0; k < 3; k++) {
        u[k] = p[3 + k] - p[k];
        v[k] = p[6 + k] - p[k];
    }
    double w[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    if (w[0] * sl->n[0] + w[1] * sl->n[1] + w[2] * sl->n[2] < 0) { /* face along +n */
        double tmp[3];
        memcpy(tmp, p + 3, sizeof tmp);
        memcpy(p + 3, p + 6, sizeof tmp);
        memcpy(p + 6, tmp, sizeof tmp);
        for (int i = 0; i < sl->s->rq.nattrs; i++) {
            int nc = sl->s->rq.attrs[i].ncomp;
            double *q = o->attr[i] + (size_t)o->ntri * 3 * nc;
            for (int k = 0; k < nc; k++) {
                double x = q[nc + k];
                q[nc + k] = q[2 * nc + k];
                q[2 * nc + k] = x;
            }
        }
    }
    o->cell[o->ntri] = cell;
    o->kind[o->ntri] = kind;
    o->ntri++;
}

static void slice_tet(slicer *sl, const uint32_t t[4], uint32_t cell, uint8_t kind)
{
    const double *x = sl->s->xyz;
    double f[4];
    int pos[4], np = 0, neg[4], nn = 0;
    for (int i = 0; i < 4; i++) {
        const double *p = x + 3 * (size_t)t[i];
        f[i] = sl->n[0] * p[0] + sl->n[1] * p[1] + sl->n[2] * p[2] - sl->d;
        if (f[i] > 0)
            pos[np++] = i;
        else
            neg[nn++] = i;
    }
    if (np == 0 || nn == 0)
        return;
    /* the cut of edge i-j (i above the plane, j below, or the other way round); a corner on the
     * plane (f = 0, counted below) is the cut of each of its edges that reaches above, exactly
     * its own point: the triangles that meet there share that point bit for bit, and one with
     * two corners there (a 2|2 cut through a vertex, a lone corner on the plane) is left out */
#define CUT(i, j) (f[j] == 0   ? (cut){t[j], t[j], 0}                                          \
                   : f[i] == 0 ? (cut){t[i], t[i], 0}                                          \
                               : (cut){t[i], t[j], f[i] / (f[i] - f[j])})
    if (np == 1 || nn == 1) {
        int lone = np == 1 ? pos[0] : neg[0];
        int *others = np == 1 ? neg : pos;
        cut a = CUT(lone, others[0]), b = CUT(lone, others[1]), c = CUT(lone, others[2]);
        slice_tri(sl, &a, &b, &c, cell, kind);
    } else {
        cut ac = CUT(pos[0], neg[0]), ad = CUT(pos[0], neg[1]), bd = CUT(pos[1], neg[1]),
            bc = CUT(pos[1], neg[0]);
        slice_tri(sl, &ac, &ad, &bd, cell, kind);
        slice_tri(sl, &ac, &bd, &bc, cell, kind);
    }
#undef CUT
}

void out_slice_plane(const double p[4], double n[3], double *d)
{
    /* scalbn by a power of 2 is exact (barring a component 2^1022 times smaller than the
     * largest, which does not count next to it), so u/|u| is n/|n| rounded once, as before */
    int e = ilogb(fmax(fabs(p[0]), fmax(fabs(p[1]), fabs(p[2]))));
    double u[3], len2 = 0;
    for (int k = 0; k < 3; k++) {
        u[k] = scalbn(p[k], -e);
        len2 += u[k] * u[k];
    }
    double len = sqrt(len2); /* in [1, 2 sqrt 3) */
    for (int k = 0; k < 3; k++)
        n[k] = u[k] / len;
    *d = scalbn(p[3] / len, -e);
}

bool out_compute_slice(out_stream *s)
{
    slicer sl = {.s = s};
    out_slice_plane(s->rq.slice, sl.n, &sl.d);
    uint32_t v[6], t[4];
    uint32_t nt = sd_level_num_cells(s->lv, SD_CELL_TETRA), no = sd_level_num_cells(s->lv, SD_CELL_OCTA);
    for (uint32_t i = 0; i < nt && !sl.failed; i++) {
        sd_level_cell(s->lv, SD_CELL_TETRA, i, v);
        slice_tet(&sl, v, i, SD_CELL_TETRA);
    }
    for (uint32_t i = 0; i < no && !sl.failed; i++) {
        sd_level_cell(s->lv, SD_CELL_OCTA, i, v);
        for (int k = 0; k < 4; k++) {
            sd_octa_tet(v, k, t);
            slice_tet(&sl, t, i, SD_CELL_OCTA);
        }
    }
    return !sl.failed;
}

void out_slice_free(out_slice *sl)
{
    api_free(sl->xyz);
    api_free(sl->cell);
    api_free(sl->kind);
    for (int a = 0; a < OUT_MAX_ATTRS; a++)
        api_free(sl->attr[a]);
}

/* ---- solid boundary and normals ----------------------------------------------------------- */

bool out_solid_boundary(out_stream *s)
{
    if (!(s->rq.parts & OUT_PART_SOLIDS))
        return true;
    if (s->rq.geometry) { /* precomputed with every part: reuse what applies */
        s->nbnd = s->rq.geometry->nbnd;
        s->bnd = s->rq.geometry->bnd;
        if ((s->rq.parts & OUT_PART_ALL) == OUT_PART_ALL)
            s->normals = s->rq.geometry->normals;
        return true;
    }
    s->nbnd = sd_level_solid_boundary(s->lv, NULL);
    s->bnd = s->own_bnd = api_malloc(((size_t)s->nbnd * 3 + 1) * sizeof *s->bnd);
    if (!s->bnd)
        return false;
    sd_level_solid_boundary(s->lv, s->own_bnd);
    return true;
}

void out_triangle_normal(const double *x, const uint32_t t[3], float n[3])
{
    const double *a = x + 3 * (size_t)t[0], *b = x + 3 * (size_t)t[1], *c = x + 3 * (size_t)t[2];
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    n[0] = (float)(u[1] * v[2] - u[2] * v[1]);
    n[1] = (float)(u[2] * v[0] - u[0] * v[2]);
    n[2] = (float)(u[0] * v[1] - u[1] * v[0]);
}

void out_normal_unit(float f[3])
{
    if (f[0] == 0 && f[1] == 0 && f[2] == 0) { /* on no triangle (most solid vertices) */
        f[2] = 1;
        return;
    }
    double len = sqrt((double)f[0] * f[0] + (double)f[1] * f[1] + (double)f[2] * f[2]);
    if (!(len > 1e-30) || !isfinite(len)) {
        f[0] = f[1] = 0;
        f[2] = 1;
    } else
        for (int k = 0; k < 3; k++)
            f[k] = (float)(f[k] / len);
}

static void add_normal(float *acc, const double *x, const uint32_t *t)
{
    float n[3];
    out_triangle_normal(x, t, n);
    for (int k = 0; k < 3; k++)
        for (int j = 0; j < 3; j++)
            acc[3 * (size_t)t[k] + j] += n[j];
}

/* Area-weighted vertex normals, accumulated in place (float is plenty for a unit direction):
 * each vertex sums its triangles' out_triangle_normal in triangle order, surface triangles
 * first, then the boundary ones (api/delta.c recomputes single vertices in the same order). */
float *out_normals(const sd_level *lv, uint32_t ntr, const uint32_t *bnd, uint32_t nbnd)
{
    uint32_t nv = sd_level_num_vertices(lv);
    const double *xyz = sd_level_channel(lv, 0, NULL);
    float *acc = api_calloc((size_t)nv * 3 + 1, sizeof *acc);
    if (!acc)
        return NULL;
    uint32_t v[6];
    for (uint32_t i = 0; i < ntr; i++) {
        sd_level_cell(lv, SD_CELL_TRIANGLE, i, v);
        add_normal(acc, xyz, v);
    }
    for (uint32_t i = 0; i < nbnd; i++)
        add_normal(acc, xyz, bnd + 3 * (size_t)i);
    for (uint32_t i = 0; i < nv; i++)
        out_normal_unit(acc + 3 * (size_t)i);
    return acc;
}

out_geometry *out_geometry_compute(const sd_level *lv)
{
    out_geometry *g = api_calloc(1, sizeof *g);
    if (!g)
        return NULL;
    atomic_init(&g->refs, 1);
    g->nbnd = sd_level_solid_boundary(lv, NULL);
    g->bnd = api_malloc(((size_t)g->nbnd * 3 + 1) * sizeof *g->bnd);
    if (g->bnd) {
        sd_level_solid_boundary(lv, g->bnd);
        g->normals = out_normals(lv, sd_level_num_cells(lv, SD_CELL_TRIANGLE), g->bnd, g->nbnd);
    }
    if (!g->bnd || !g->normals) {
        out_geometry_free(g);
        return NULL;
    }
    g->bytes = sizeof *g + (size_t)g->nbnd * 12 + (size_t)sd_level_num_vertices(lv) * 12;
    return g;
}

out_geometry *out_geometry_copy(const out_geometry *g, uint32_t nv)
{
    out_geometry *c = api_calloc(1, sizeof *c);
    if (!c)
        return NULL;
    atomic_init(&c->refs, 1);
    c->nbnd = g->nbnd;
    c->bytes = g->bytes;
    c->bnd = api_malloc(((size_t)g->nbnd * 3 + 1) * sizeof *c->bnd);
    c->normals = api_malloc(((size_t)nv * 3 + 1) * sizeof *c->normals);
    if (!c->bnd || !c->normals) {
        out_geometry_free(c);
        return NULL;
    }
    memcpy(c->bnd, g->bnd, (size_t)g->nbnd * 3 * sizeof *c->bnd);
    memcpy(c->normals, g->normals, (size_t)nv * 3 * sizeof *c->normals);
    return c;
}

out_geometry *out_geometry_ref(out_geometry *g)
{
    if (g)
        atomic_fetch_add(&g->refs, 1);
    return g;
}

void out_geometry_free(out_geometry *g)
{
    if (!g || atomic_fetch_sub(&g->refs, 1) != 1)
        return;
    api_free(g->bnd);
    api_free(g->normals);
    api_free(g);
}
