/* out.c — the writer interface of out.h: format names, validation, the shared precomputation
 * (cells per part, solid boundary, normals, the plane cross-section) and the pull loop.
 *
 * Precomputed arrays are proportional to the boundary, the slice or the vertex count (normals),
 * never to the output: the output itself is generated chunk by chunk in out_read.
 */
#include "out_internal.h"
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const NAMES[] = {"glb", "gltf", "vtu", "vtk", "json"};
static const char *const TYPES[] = {"model/gltf-binary", "model/gltf+json",
                                    "application/vnd.unstructured-grid+xml",
                                    "application/octet-stream", "application/json"};
static const char *const EXTS[] = {".glb", ".gltf", ".vtu", ".vtk", ".json"};

int out_format_parse(const char *name)
{
    for (int i = 0; i < OUT_FORMAT_COUNT; i++)
        if (!strcmp(name, NAMES[i]))
            return i;
    return -1;
}
const char *out_format_name(out_format f) { return (unsigned)f < OUT_FORMAT_COUNT ? NAMES[f] : "?"; }
const char *out_content_type(out_format f) { return (unsigned)f < OUT_FORMAT_COUNT ? TYPES[f] : "application/octet-stream"; }
const char *out_file_extension(out_format f) { return (unsigned)f < OUT_FORMAT_COUNT ? EXTS[f] : ""; }

void out_put(out_stream *s, const void *p, size_t n)
{
    if (s->len + n > OUT_BUF_CAP) { /* a writer bug; never silently truncate */
        fprintf(stderr, "out: chunk overflow\n");
        abort();
    }
    memcpy(s->buf + s->len, p, n);
    s->len += n;
}

void out_printf(out_stream *s, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(s->buf + s->len, OUT_BUF_CAP - s->len, fmt, ap);
    va_end(ap);
    if (n < 0 || (size_t)n >= OUT_BUF_CAP - s->len) {
        fprintf(stderr, "out: chunk overflow\n");
        abort();
    }
    s->len += (size_t)n;
}

/* Viridis (matplotlib's colour map sampled at t = 0, 1/8, ..., 1), linear in between. */
void out_viridis(double t, float rgb[3])
{
    static const float V[9][3] = {
        {0.267004f, 0.004874f, 0.329415f}, {0.282623f, 0.140926f, 0.457517f},
        {0.229739f, 0.322361f, 0.545706f}, {0.172719f, 0.448791f, 0.557885f},
        {0.127568f, 0.566949f, 0.550556f}, {0.157851f, 0.683765f, 0.501686f},
        {0.369214f, 0.788888f, 0.382914f}, {0.678489f, 0.863742f, 0.189503f},
        {0.993248f, 0.906157f, 0.143936f}};
    if (!(t > 0))
        t = 0;
    if (t > 1)
        t = 1;
    double x = t * 8;
    int i = (int)x;
    if (i > 7)
        i = 7;
    double f = x - i;
    for (int k = 0; k < 3; k++) {
        double c = V[i][k] + (V[i + 1][k] - V[i][k]) * f;
        rgb[k] = (float)(c < 0 ? 0 : c > 1 ? 1 : c);
    }
}

/* Octahedron (p,q,a,a2,b,b2) with equator cycle a,b,a2,b2: four tetrahedra around the major
 * diagonal p-q. The order (q,p,...) makes them positive for a positive octahedron (checked by
 * the output tests through their volumes). */
void out_oct_tet(const uint32_t o[6], int k, uint32_t t[4])
{
    static const int eq[4] = {2, 4, 3, 5}; /* a, b, a2, b2 */
    t[0] = o[1];
    t[1] = o[0];
    t[2] = o[eq[k]];
    t[3] = o[eq[(k + 1) & 3]];
}

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
    double *xyz = realloc(o->xyz, (size_t)cap * 9 * sizeof *xyz);
    if (xyz)
        o->xyz = xyz;
    uint32_t *cell = realloc(o->cell, (size_t)cap * sizeof *cell);
    if (cell)
        o->cell = cell;
    uint8_t *kind = realloc(o->kind, cap);
    if (kind)
        o->kind = kind;
    if (!xyz || !cell || !kind)
        return false;
    for (int a = 0; a < sl->s->rq.nattrs; a++) {
        int nc = sl->s->rq.attrs[a].ncomp;
        double *v = realloc(o->attr[a], (size_t)cap * 3 * nc * sizeof *v);
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
#define CUT(i, j) ((cut){t[i], t[j], f[i] / (f[i] - f[j])})
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

static bool compute_slice(out_stream *s)
{
    slicer sl = {.s = s};
    double len = sqrt(s->rq.slice[0] * s->rq.slice[0] + s->rq.slice[1] * s->rq.slice[1] +
                      s->rq.slice[2] * s->rq.slice[2]);
    for (int k = 0; k < 3; k++)
        sl.n[k] = s->rq.slice[k] / len;
    sl.d = s->rq.slice[3] / len;
    uint32_t v[6], t[4];
    uint32_t nt = sd_level_num_cells(s->lv, SD_CELL_TETRA), no = sd_level_num_cells(s->lv, SD_CELL_OCTA);
    for (uint32_t i = 0; i < nt && !sl.failed; i++) {
        sd_level_cell(s->lv, SD_CELL_TETRA, i, v);
        slice_tet(&sl, v, i, SD_CELL_TETRA);
    }
    for (uint32_t i = 0; i < no && !sl.failed; i++) {
        sd_level_cell(s->lv, SD_CELL_OCTA, i, v);
        for (int k = 0; k < 4; k++) {
            out_oct_tet(v, k, t);
            slice_tet(&sl, t, i, SD_CELL_OCTA);
        }
    }
    return !sl.failed;
}

/* ---- open / read / close ------------------------------------------------------------------ */

void out_close(out_stream *s)
{
    if (!s)
        return;
    if (s->fmt_free)
        s->fmt_free(s->fmt_state);
    free(s->buf);
    free(s->own_bnd);
    free(s->own_normals);
    free(s->slice.xyz);
    free(s->slice.cell);
    free(s->slice.kind);
    for (int a = 0; a < OUT_MAX_ATTRS; a++)
        free(s->slice.attr[a]);
    free(s);
}

static out_stream *fail(out_stream *s, sd_error *err, sd_result code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static out_stream *fail(out_stream *s, sd_error *err, sd_result code, const char *fmt, ...)
{
    if (err) {
        err->code = code;
        err->item = -1;
        err->field = -1;
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err->message, sizeof err->message, fmt, ap);
        va_end(ap);
    }
    out_close(s);
    return NULL;
}

/* Attribute names go verbatim into JSON keys, XML attributes and VTK keyword lines: keep them
 * to characters that need no escaping anywhere (the API's rule for names, api/handlers.c). */
static bool valid_name(const char *name)
{
    size_t n = 0;
    if (!name)
        return false;
    for (; name[n]; n++)
        if (n == 63 || !((name[n] >= 'a' && name[n] <= 'z') || (name[n] >= 'A' && name[n] <= 'Z') ||
                         (name[n] >= '0' && name[n] <= '9') || name[n] == '_' || name[n] == '-'))
            return false;
    return n > 0;
}

out_stream *out_open(const out_request *rq, out_format f, sd_error *err)
{
    if ((unsigned)f >= OUT_FORMAT_COUNT)
        return fail(NULL, err, SD_ERR_ARG, "format: unknown output format");
    if (rq->parts & ~(unsigned)OUT_PART_ALL)
        return fail(NULL, err, SD_ERR_ARG, "parts: unknown part (mask 0x%x)", rq->parts);
    if (rq->nattrs < 0 || rq->nattrs > OUT_MAX_ATTRS)
        return fail(NULL, err, SD_ERR_ARG, "attributes: %d; at most %d", rq->nattrs, OUT_MAX_ATTRS);
    for (int a = 0; a < rq->nattrs; a++) {
        if (!valid_name(rq->attrs[a].name))
            return fail(NULL, err, SD_ERR_ARG,
                        "attributes: names have 1 to 63 letters, digits, '_' or '-'");
        if (rq->attrs[a].ncomp < 1 || rq->attrs[a].ncomp > 16)
            return fail(NULL, err, SD_ERR_ARG, "attributes: 1 to 16 components");
        for (int b = 0; b < a; b++)
            if (!strcmp(rq->attrs[a].name, rq->attrs[b].name))
                return fail(NULL, err, SD_ERR_ARG, "attributes: a name is given twice");
    }
    if (rq->has_slice) {
        double n2 = 0;
        for (int k = 0; k < 4; k++)
            if (!isfinite(rq->slice[k]))
                return fail(NULL, err, SD_ERR_ARG, "slice: the plane must be finite");
        for (int k = 0; k < 3; k++)
            n2 += rq->slice[k] * rq->slice[k];
        if (!(n2 > 0))
            return fail(NULL, err, SD_ERR_ARG, "slice: the normal must not be zero");
    }
    if (rq->colormap_attr < -1 || rq->colormap_attr >= rq->nattrs)
        return fail(NULL, err, SD_ERR_ARG, "colormap: attribute %d of %d", rq->colormap_attr,
                    rq->nattrs);
    if (rq->colormap_attr >= 0 && !(isfinite(rq->colormap_min) && isfinite(rq->colormap_max) &&
                                    rq->colormap_min < rq->colormap_max))
        return fail(NULL, err, SD_ERR_ARG, "colormap: min and max must be finite with min < max");
    if (!rq->complex)
        return fail(NULL, err, SD_ERR_ARG, "level: no complex");
    int computed = sd_complex_levels_computed(rq->complex);
    if (rq->level < 0 || rq->level >= computed)
        return fail(NULL, err, SD_ERR_ARG, "level: %d has not been computed (%d levels are)",
                    rq->level, computed);
    out_stream *s = calloc(1, sizeof *s);
    if (!s)
        return fail(NULL, err, SD_ERR_NOMEM, "out of memory");
    s->rq = *rq;
    if (!s->rq.parts)
        s->rq.parts = OUT_PART_ALL;
    s->fmt = f;
    sd_error e = {0};
    s->lv = sd_complex_level(rq->complex, rq->level, &e);
    if (s->lv && sd_complex_prepare_vertex_rules(rq->complex, rq->level, &e))
        s->lv = NULL;
    if (!s->lv) {
        if (err)
            *err = e;
        out_close(s);
        return NULL;
    }
    s->nv = sd_level_num_vertices(s->lv);
    int nc;
    s->xyz = sd_level_channel(s->lv, 0, &nc);
    for (int a = 0; a < rq->nattrs; a++) {
        s->attr[a] = sd_level_channel(s->lv, rq->attrs[a].channel, &nc);
        if (!s->attr[a] || nc != rq->attrs[a].ncomp)
            return fail(s, err, SD_ERR_ARG, "attributes: \"%s\" is not a channel of %d components",
                        rq->attrs[a].name, rq->attrs[a].ncomp);
    }
    static const unsigned part_of[5] = {OUT_PART_POINTS, OUT_PART_CURVES, OUT_PART_SURFACES,
                                        OUT_PART_SOLIDS, OUT_PART_SOLIDS};
    for (int k = 0; k < 5; k++)
        s->ncells[k] = (s->rq.parts & part_of[k]) ? sd_level_num_cells(s->lv, (sd_cell_kind)k) : 0;
    bool solids = (s->rq.parts & OUT_PART_SOLIDS) != 0;
    if (rq->has_slice && solids && !compute_slice(s))
        return fail(s, err, SD_ERR_NOMEM, "out of memory computing the cross-section");
    s->buf = malloc(OUT_BUF_CAP);
    if (!s->buf)
        return fail(s, err, SD_ERR_NOMEM, "out of memory");
    int rc;
    switch (f) {
    case OUT_GLB:
    case OUT_GLTF:
        if (solids && rq->geometry) { /* precomputed with every part: reuse what applies */
            s->nbnd = rq->geometry->nbnd;
            s->bnd = rq->geometry->bnd;
            if (s->rq.parts == OUT_PART_ALL)
                s->normals = rq->geometry->normals;
        } else if (solids) {
            s->nbnd = sd_level_solid_boundary(s->lv, NULL);
            s->bnd = s->own_bnd = malloc(((size_t)s->nbnd * 3 + 1) * sizeof *s->bnd);
            if (!s->bnd)
                return fail(s, err, SD_ERR_NOMEM, "out of memory");
            sd_level_solid_boundary(s->lv, s->own_bnd);
        }
        rc = out_gltf_init(s, err);
        break;
    case OUT_VTU: rc = out_vtu_init(s, err); break;
    case OUT_VTK: rc = out_vtk_init(s, err); break;
    default: rc = out_json_init(s, err); break;
    }
    if (rc) {
        out_close(s);
        return NULL;
    }
    return s;
}

uint64_t out_size(const out_stream *s) { return s->size; }

ssize_t out_read(out_stream *s, char *buf, size_t cap)
{
    size_t n = 0;
    while (n < cap) {
        if (s->pos == s->len) {
            if (s->done)
                break;
            s->len = s->pos = 0;
            if (!s->produce(s))
                s->done = true;
            continue;
        }
        size_t k = s->len - s->pos;
        if (k > cap - n)
            k = cap - n;
        memcpy(buf + n, s->buf + s->pos, k);
        s->pos += k;
        n += k;
    }
    return (ssize_t)n;
}
