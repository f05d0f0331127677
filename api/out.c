/* out.c — the writer interface of out.h: validation of a request, what every writer starts
 * from (the level's arrays, cells per part, the slice), the chunk buffer and the pull loop.
 *
 * out_open checks everything a writer could refuse before the format's init runs, so a stream
 * that opens is written to the end; the formats themselves are the table of api/formats.c and
 * their shared geometry is api/geom.c. The output is generated chunk by chunk in out_read, never
 * held whole.
 */
#include "out_internal.h"
#include "mem.h"
#include <assert.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int out_nomem(sd_error *err)
{
    err->code = SD_ERR_NOMEM;
    snprintf(err->message, sizeof err->message, "out of memory");
    return SD_ERR_NOMEM;
}

void *out_state_new(out_stream *s, size_t size, void (*free_state)(void *), int (*produce)(out_stream *))
{
    void *st = api_calloc(1, size);
    if (st) {
        s->fmt_state = st;
        s->fmt_free = free_state;
        s->produce = produce;
    }
    return st;
}

out_section *out_section_add(out_sections *l, int id, int arg, int ncomp, int width,
                             uint64_t count)
{
    assert(l->n < OUT_MAX_SECTIONS); /* the writers' section counts are bounded by design */
    out_section *c = &l->s[l->n++];
    memset(c, 0, sizeof *c);
    c->id = id;
    c->arg = arg;
    c->ncomp = ncomp;
    c->width = width;
    c->count = count;
    c->bytes = count * (uint64_t)ncomp * (uint64_t)width;
    return c;
}

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

/* sRGB's transfer function undone (IEC 61966-2-1; glTF 2.0 3.7.2.1 wants linear COLOR_0). */
static double srgb_to_linear(double c)
{
    return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

/* Viridis: matplotlib's colour map (sRGB) sampled at t = 0, 1/8, ..., 1, piecewise linear in sRGB
 * in between, then each channel converted to linear. */
void out_viridis(double t, float rgb[3])
{
    static const float V[9][3] = {
        {0.267004f, 0.004874f, 0.329415f}, {0.278826f, 0.175490f, 0.483397f},
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
        c = srgb_to_linear(c < 0 ? 0 : c > 1 ? 1 : c);
        rgb[k] = (float)(c < 0 ? 0 : c > 1 ? 1 : c);
    }
}

/* ---- open / read / close ------------------------------------------------------------------ */

void out_close(out_stream *s)
{
    if (!s)
        return;
    if (s->fmt_free)
        s->fmt_free(s->fmt_state);
    api_free(s->buf);
    api_free(s->own_bnd);
    api_free(s->own_normals);
    api_free(s->own_xyz);
    for (int a = 0; a < OUT_MAX_ATTRS; a++)
        api_free(s->own_attr[a]);
    for (int i = 0; i < s->nmesh; i++) {
        api_free((void *)s->mesh[i].name);
        api_free((void *)s->mesh[i].xyz);
        api_free((void *)s->mesh[i].tri);
    }
    out_geometry_free(s->rq.geometry);
    out_slice_free(&s->slice);
    api_free(s);
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
 * to characters that need no escaping anywhere (the API's rule for names, api/complex.c). */
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

/* The stream's own copies of the positions and the requested channels (rq.snapshot). */
static bool snapshot(out_stream *s)
{
    size_t n = (size_t)s->nv * 3;
    if (!(s->own_xyz = api_memdup(s->xyz, n * sizeof *s->xyz)))
        return false;
    s->xyz = s->own_xyz;
    for (int a = 0; a < s->rq.nattrs; a++) {
        n = (size_t)s->nv * (size_t)s->rq.attrs[a].ncomp;
        if (!(s->own_attr[a] = api_memdup(s->attr[a], n * sizeof *s->attr[a])))
            return false;
        s->attr[a] = s->own_attr[a];
    }
    return true;
}

/* The level's points at their limit positions (into the stream's own copy) and their limit
 * normals (0 0 0 where a point has none; the glTF writer fills those in). */
static int limit_points(out_stream *s, sd_error *err)
{
    size_t n = (size_t)s->nv * 3;
    double *x = api_malloc((n + 1) * sizeof *x), *nrm = api_malloc((n + 1) * sizeof *nrm);
    float *f = api_malloc((n + 1) * sizeof *f);
    if (!x || !nrm || !f) {
        api_free(x);
        api_free(nrm);
        api_free(f);
        return out_nomem(err);
    }
    sd_result r = sd_complex_limit(s->rq.complex, s->rq.level, 0, x, nrm, err);
    if (r) {
        api_free(x);
        api_free(nrm);
        api_free(f);
        return r;
    }
    for (size_t i = 0; i < n; i++)
        f[i] = (float)nrm[i];
    api_free(nrm);
    api_free(s->own_xyz);
    s->xyz = s->own_xyz = x;
    s->normals = s->own_normals = f;
    return 0;
}

out_stream *out_open(const out_request *rq, const out_format *f, sd_error *err)
{
    if (!f || !f->init)
        return fail(NULL, err, SD_ERR_ARG, "format: unknown output format");
    if (rq->parts & ~(unsigned)(OUT_PART_ALL | OUT_PART_EMBEDDED))
        return fail(NULL, err, SD_ERR_ARG, "parts: unknown part (mask 0x%x)", rq->parts);
    bool gltf = !strcmp(f->name, "glb") || !strcmp(f->name, "gltf");
    if ((rq->parts & OUT_PART_EMBEDDED) && !gltf)
        return fail(NULL, err, SD_ERR_ARG, "parts: embedded applies to format glb and gltf only, "
                    "not %s", f->name);
    int nmeshes = (rq->parts & OUT_PART_EMBEDDED) ? rq->nmeshes : 0;
    if (nmeshes < 0 || nmeshes > OUT_MAX_MESHES)
        return fail(NULL, err, SD_ERR_ARG, "parts: %d embedded meshes; at most %d", nmeshes,
                    OUT_MAX_MESHES);
    for (int i = 0; i < nmeshes; i++) {
        const out_mesh *q = &rq->meshes[i];
        if (!valid_name(q->name) || !q->xyz || (q->nt && !q->tri))
            return fail(NULL, err, SD_ERR_ARG, "parts: embedded mesh %d is not valid", i);
        for (size_t j = 0; j < 3 * (size_t)q->nt; j++)
            if (q->tri[j] >= q->nv)
                return fail(NULL, err, SD_ERR_ARG, "parts: embedded mesh %s: a vertex id is out "
                            "of range", q->name);
    }
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
        for (int k = 0; k < 4; k++)
            if (!isfinite(rq->slice[k]))
                return fail(NULL, err, SD_ERR_ARG, "slice: the plane must be finite");
        /* a component, not the sum of squares, which underflows for |n| below 1e-154 */
        if (rq->slice[0] == 0 && rq->slice[1] == 0 && rq->slice[2] == 0)
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
    out_stream *s = api_calloc(1, sizeof *s);
    if (!s)
        return fail(NULL, err, SD_ERR_NOMEM, "out of memory");
    s->rq = *rq;
    s->rq.meshes = NULL;
    s->rq.nmeshes = 0;
    out_geometry_ref(s->rq.geometry);
    for (int i = 0; i < nmeshes; i++) { /* the stream's own copies: read after the caller's lock */
        const out_mesh *q = &rq->meshes[i];
        out_mesh *c = &s->mesh[s->nmesh++];
        c->nv = q->nv;
        c->nt = q->nt;
        c->name = api_strdup(q->name);
        c->xyz = api_memdup(q->xyz, (size_t)q->nv * 3 * sizeof *q->xyz);
        c->tri = api_memdup(q->tri, (size_t)q->nt * 3 * sizeof *q->tri);
        if (!c->name || !c->xyz || !c->tri)
            return fail(s, err, SD_ERR_NOMEM, "out of memory copying the embedded models");
    }
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
    if (rq->limit && rq->geometry)
        return fail(s, err, SD_ERR_ARG, "limit: no cached geometry with limit positions");
    if (rq->snapshot && !snapshot(s))
        return fail(s, err, SD_ERR_NOMEM, "out of memory copying the level's points");
    if (rq->limit && limit_points(s, &e)) {
        if (err)
            *err = e;
        out_close(s);
        return NULL;
    }
    static const unsigned part_of[5] = {OUT_PART_POINTS, OUT_PART_CURVES, OUT_PART_SURFACES,
                                        OUT_PART_SOLIDS, OUT_PART_SOLIDS};
    for (int k = 0; k < 5; k++)
        s->ncells[k] = (s->rq.parts & part_of[k]) ? sd_level_num_cells(s->lv, (sd_cell_kind)k) : 0;
    if (rq->has_slice && (s->rq.parts & OUT_PART_SOLIDS) && !out_compute_slice(s))
        return fail(s, err, SD_ERR_NOMEM, "out of memory computing the cross-section");
    s->buf = api_malloc(OUT_BUF_CAP);
    if (!s->buf)
        return fail(s, err, SD_ERR_NOMEM, "out of memory");
    if (f->init(s, err)) {
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
