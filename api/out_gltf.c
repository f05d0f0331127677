/* out_gltf.c — glTF 2.0: binary .glb (default) and .gltf with the buffer embedded as base64.
 *
 * One scene, one node, one mesh whose primitives share the level's vertex accessors:
 *   points (mode 0, isolated points), curves (mode 1, curve segments), surfaces (mode 4, surface
 *   triangles), solids (mode 4, the outward boundary of the tetrahedra and octahedra), and the
 *   optional slice (mode 4, non-indexed, its own POSITION, NORMAL, `_<NAME>` and COLOR_0: the
 *   cross-section of the solids by the plane, facing +n, attributes interpolated on the cut edges).
 * Shared accessors: POSITION (float32, min/max from the written floats), NORMAL (area-weighted,
 * unit; (0,0,1) where a vertex has no triangle; triangle primitives only), `_<NAME>` per
 * attribute (float32, the first 4 components of longer vectors; made unique with a `_2` suffix),
 * `_RULE` (the sd_rule id as a float) and COLOR_0 (viridis of an attribute's first component
 * over [min,max], float32 RGB).
 * Indices are u16 when the level has at most 65535 vertices, else u32. One material:
 * metallicFactor 0, doubleSided. asset.extras carries the level and version.
 *
 * The JSON part is small and built in out_open; the binary part is generated section by
 * section. Sizes are exact in advance (Content-Length).
 */
#include "out_internal.h"
#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef enum { /* in buffer order; the index sections are G_IPT..G_IBD */
    G_POS, G_NRM, G_ATTR, G_RULE, G_COLOR, G_IPT, G_ILN, G_ITR, G_IBD, G_SPOS, G_SNRM, G_SATTR,
    G_SCOLOR
} gsec_id;

typedef struct gsec {
    gsec_id id;
    int attr, ncomp;      /* components per item */
    int width;            /* bytes per component: 4 float/u32, 2 u16 */
    uint64_t count;       /* items */
    uint64_t bytes;       /* unpadded */
    uint64_t offset;      /* in the buffer */
    int accessor;
} gsec;

typedef struct gstate {
    bool glb;
    int nsec;
    gsec sec[16 + 2 * OUT_MAX_ATTRS];
    char *json;           /* GLB: the JSON chunk (padded); glTF: everything before the base64 */
    size_t json_len;
    uint64_t bin_len;     /* padded */
    int phase;            /* 0 prefix, 1 binary, 2 suffix */
    uint64_t pad_done;
    char *scratch;        /* glTF: binary produced before base64 encoding */
    unsigned char carry[3];
    int ncarry;
    float nrm_plane[3];
    char name[OUT_MAX_ATTRS + 1][80]; /* glTF attribute names: `_<NAME>` per attribute, _RULE */
} gstate;

static const char B64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/* ---- normals ------------------------------------------------------------------------------ */

static void add_normal(float *acc, const double *x, const uint32_t *t)
{
    const double *a = x + 3 * (size_t)t[0], *b = x + 3 * (size_t)t[1], *c = x + 3 * (size_t)t[2];
    double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    float n[3] = {(float)(u[1] * v[2] - u[2] * v[1]), (float)(u[2] * v[0] - u[0] * v[2]),
                  (float)(u[0] * v[1] - u[1] * v[0])};
    for (int k = 0; k < 3; k++)
        for (int j = 0; j < 3; j++)
            acc[3 * (size_t)t[k] + j] += n[j];
}

/* Area-weighted vertex normals, accumulated in place (float is plenty for a unit direction). */
float *out_normals(const sd_level *lv, uint32_t ntr, const uint32_t *bnd, uint32_t nbnd)
{
    uint32_t nv = sd_level_num_vertices(lv);
    const double *xyz = sd_level_channel(lv, 0, NULL);
    float *acc = calloc((size_t)nv * 3 + 1, sizeof *acc);
    if (!acc)
        return NULL;
    uint32_t v[6];
    for (uint32_t i = 0; i < ntr; i++) {
        sd_level_cell(lv, SD_CELL_TRIANGLE, i, v);
        add_normal(acc, xyz, v);
    }
    for (uint32_t i = 0; i < nbnd; i++)
        add_normal(acc, xyz, bnd + 3 * (size_t)i);
    for (uint32_t i = 0; i < nv; i++) {
        float *f = acc + 3 * (size_t)i;
        if (f[0] == 0 && f[1] == 0 && f[2] == 0) { /* on no triangle (most solid vertices) */
            f[2] = 1;
            continue;
        }
        double len = sqrt((double)f[0] * f[0] + (double)f[1] * f[1] + (double)f[2] * f[2]);
        if (!(len > 1e-30) || !isfinite(len)) {
            f[0] = f[1] = 0;
            f[2] = 1;
        } else
            for (int k = 0; k < 3; k++)
                f[k] = (float)(f[k] / len);
    }
    return acc;
}

out_geometry *out_geometry_compute(const sd_level *lv)
{
    out_geometry *g = calloc(1, sizeof *g);
    if (!g)
        return NULL;
    g->nbnd = sd_level_solid_boundary(lv, NULL);
    g->bnd = malloc(((size_t)g->nbnd * 3 + 1) * sizeof *g->bnd);
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

void out_geometry_free(out_geometry *g)
{
    if (!g)
        return;
    free(g->bnd);
    free(g->normals);
    free(g);
}

/* ---- binary ------------------------------------------------------------------------------- */

static void put_f(out_stream *s, double x)
{
    float f = (float)x;
    out_put(s, &f, 4);
}

static void put_index(out_stream *s, int width, uint32_t i)
{
    if (width == 2) {
        uint16_t v = (uint16_t)i;
        out_put(s, &v, 2);
    } else
        out_put(s, &i, 4);
}

/* Position of value x in the colour map's range (out_viridis clamps it to [0,1]). */
static double colormap_t(const out_stream *s, double x)
{
    return (x - s->rq.colormap_min) / (s->rq.colormap_max - s->rq.colormap_min);
}

static void put_item(out_stream *s, gstate *g, const gsec *c, uint64_t i)
{
    uint32_t v[6];
    switch (c->id) {
    case G_POS:
        for (int k = 0; k < 3; k++)
            put_f(s, s->xyz[3 * i + k]);
        break;
    case G_NRM: out_put(s, s->normals + 3 * i, 12); break;
    case G_ATTR: {
        int nc = s->rq.attrs[c->attr].ncomp;
        for (int k = 0; k < c->ncomp; k++)
            put_f(s, s->attr[c->attr][i * nc + k]);
        break;
    }
    case G_RULE: put_f(s, sd_level_vertex_rule(s->lv, (uint32_t)i)); break;
    case G_COLOR: {
        int a = s->rq.colormap_attr, nc = s->rq.attrs[a].ncomp;
        float rgb[3];
        out_viridis(colormap_t(s, s->attr[a][i * nc]), rgb);
        out_put(s, rgb, 12);
        break;
    }
    case G_IPT:
    case G_ILN:
    case G_ITR: {
        sd_cell_kind k = c->id == G_IPT ? SD_CELL_POINT : c->id == G_ILN ? SD_CELL_CURVE : SD_CELL_TRIANGLE;
        sd_level_cell(s->lv, k, (uint32_t)i, v);
        for (int j = 0; j < sd_cell_size(k); j++)
            put_index(s, c->width, v[j]);
        break;
    }
    case G_IBD:
        for (int j = 0; j < 3; j++)
            put_index(s, c->width, s->bnd[3 * i + j]);
        break;
    case G_SPOS:
        for (int k = 0; k < 3; k++)
            put_f(s, s->slice.xyz[3 * i + k]);
        break;
    case G_SNRM: out_put(s, g->nrm_plane, 12); break;
    case G_SATTR: {
        int nc = s->rq.attrs[c->attr].ncomp;
        for (int k = 0; k < c->ncomp; k++)
            put_f(s, s->slice.attr[c->attr][i * nc + k]);
        break;
    }
    case G_SCOLOR: {
        int a = s->rq.colormap_attr, nc = s->rq.attrs[a].ncomp;
        float rgb[3];
        out_viridis(colormap_t(s, s->slice.attr[a][i * nc]), rgb);
        out_put(s, rgb, 12);
        break;
    }
    }
}

#define ROOM(s) ((s)->len < OUT_BUF_CAP / 3)

/* Bulk conversion of items [i, end) of the float sections that dominate the output: one tight
 * loop instead of a call per item. Returns the next item. */
static uint64_t put_bulk(out_stream *s, const gsec *c, uint64_t i, uint64_t end)
{
    float *dst = (float *)(void *)(s->buf + s->len); /* s->len is a multiple of 4 here */
    size_t k = 0;
    switch (c->id) {
    case G_POS:
        for (const double *x = s->xyz + 3 * i; i < end; i++, x += 3) {
            dst[k++] = (float)x[0];
            dst[k++] = (float)x[1];
            dst[k++] = (float)x[2];
        }
        break;
    case G_NRM:
        memcpy(dst, s->normals + 3 * i, (end - i) * 12);
        k = 3 * (end - i);
        i = end;
        break;
    case G_RULE:
        for (; i < end; i++)
            dst[k++] = (float)sd_level_vertex_rule(s->lv, (uint32_t)i);
        break;
    default: {
        int nc = s->rq.attrs[c->attr].ncomp;
        for (const double *x = s->attr[c->attr] + i * nc; i < end; i++, x += nc)
            for (int j = 0; j < c->ncomp; j++)
                dst[k++] = (float)x[j];
        break;
    }
    }
    s->len += k * 4;
    return i;
}

/* Binary bytes into s->buf while there is room; returns 0 when the binary part is complete. */
static int produce_bin(out_stream *s, gstate *g)
{
    while (ROOM(s) && s->section < g->nsec) {
        const gsec *c = &g->sec[s->section];
        uint64_t i = s->item;
        if ((c->id == G_POS || c->id == G_NRM || c->id == G_RULE || c->id == G_ATTR) &&
            s->len % 4 == 0) {
            uint64_t fit = (OUT_BUF_CAP / 3 - s->len) / ((uint64_t)c->ncomp * 4) + 1;
            i = put_bulk(s, c, i, c->count - i < fit ? c->count : i + fit);
        }
        for (; i < c->count && ROOM(s); i++)
            put_item(s, g, c, i);
        s->item = i;
        if (i < c->count)
            return 1;
        static const char zeros[4] = {0};
        out_put(s, zeros, (size_t)((4 - c->bytes % 4) % 4));
        s->section++;
        s->item = 0;
    }
    return s->section < g->nsec;
}

static void b64_flush(out_stream *s, gstate *g, const unsigned char *p, size_t n, bool final)
{
    char quad[4];
    size_t i = 0;
    while (g->ncarry && g->ncarry < 3 && i < n)
        g->carry[g->ncarry++] = p[i++];
    if (g->ncarry == 3) {
        quad[0] = B64[g->carry[0] >> 2];
        quad[1] = B64[((g->carry[0] & 3) << 4) | (g->carry[1] >> 4)];
        quad[2] = B64[((g->carry[1] & 15) << 2) | (g->carry[2] >> 6)];
        quad[3] = B64[g->carry[2] & 63];
        out_put(s, quad, 4);
        g->ncarry = 0;
    }
    for (; i + 3 <= n; i += 3) {
        quad[0] = B64[p[i] >> 2];
        quad[1] = B64[((p[i] & 3) << 4) | (p[i + 1] >> 4)];
        quad[2] = B64[((p[i + 1] & 15) << 2) | (p[i + 2] >> 6)];
        quad[3] = B64[p[i + 2] & 63];
        out_put(s, quad, 4);
    }
    while (i < n)
        g->carry[g->ncarry++] = p[i++];
    if (final && g->ncarry) {
        unsigned char c1 = g->ncarry > 1 ? g->carry[1] : 0;
        quad[0] = B64[g->carry[0] >> 2];
        quad[1] = B64[((g->carry[0] & 3) << 4) | (c1 >> 4)];
        quad[2] = g->ncarry > 1 ? B64[(c1 & 15) << 2] : '=';
        quad[3] = '=';
        out_put(s, quad, 4);
        g->ncarry = 0;
    }
}

static int produce(out_stream *s)
{
    gstate *g = s->fmt_state;
    if (g->phase == 0) {
        out_put(s, g->json, g->json_len);
        if (g->glb) {
            uint32_t hdr[2] = {(uint32_t)g->bin_len, 0x004E4942};
            out_put(s, hdr, 8);
        }
        g->phase = 1;
        s->section = 0;
        s->item = 0;
        return 1;
    }
    if (g->phase == 1) {
        int more;
        if (g->glb)
            more = produce_bin(s, g);
        else {
            char *out = s->buf;
            size_t out_len = s->len;
            s->buf = g->scratch; /* produce binary into the scratch buffer, then encode */
            s->len = 0;
            more = produce_bin(s, g);
            size_t n = s->len;
            s->buf = out;
            s->len = out_len;
            b64_flush(s, g, (const unsigned char *)g->scratch, n, !more);
        }
        if (more)
            return 1;
        g->phase = 2;
    }
    if (g->phase == 2 && !g->glb)
        out_printf(s, "\"}]}");
    g->phase = 3;
    return 0;
}

/* ---- JSON --------------------------------------------------------------------------------- */

static gsec *add_sec(gstate *g, gsec_id id, int attr, int ncomp, int width, uint64_t count)
{
    gsec *c = &g->sec[g->nsec++];
    memset(c, 0, sizeof *c);
    c->id = id;
    c->attr = attr;
    c->ncomp = ncomp;
    c->width = width;
    c->count = count;
    c->bytes = count * (uint64_t)ncomp * (uint64_t)width;
    return c;
}

static void gfree(void *p)
{
    gstate *g = p;
    if (g) {
        free(g->json);
        free(g->scratch);
    }
    free(g);
}

static int nomem(sd_error *err)
{
    err->code = SD_ERR_NOMEM;
    snprintf(err->message, sizeof err->message, "out of memory");
    return SD_ERR_NOMEM;
}

/* glTF names of the per-vertex attributes: `_RULE` (name[nattrs]) first, then per attribute `_` +
 * the posted name upper-cased with `-` as `_` (custom semantics must start with `_`); a name
 * already taken (e.g. "a-b" and "A_B", or an attribute called "rule") gets `_2`, `_3`, ... */
static void attribute_names(const out_stream *s, gstate *g)
{
    int n = s->rq.nattrs;
    snprintf(g->name[n], sizeof g->name[n], "_RULE");
    for (int a = 0; a < n; a++) {
        char base[72];
        size_t k = 0;
        base[k++] = '_';
        for (const char *p = s->rq.attrs[a].name; *p && k < 64; p++)
            base[k++] = *p == '-' ? '_' : (char)toupper((unsigned char)*p);
        base[k] = 0;
        snprintf(g->name[a], sizeof g->name[a], "%s", base);
        for (int suffix = 2, clash = 1; clash; suffix++) {
            clash = !strcmp(g->name[a], g->name[n]);
            for (int b = 0; b < a && !clash; b++)
                clash = !strcmp(g->name[a], g->name[b]);
            if (clash)
                snprintf(g->name[a], sizeof g->name[a], "%s_%d", base, suffix);
        }
    }
}

int out_gltf_init(out_stream *s, sd_error *err)
{
    gstate *g = calloc(1, sizeof *g);
    if (!g)
        return nomem(err);
    s->fmt_state = g;
    s->fmt_free = gfree;
    s->produce = produce;
    g->glb = s->fmt == OUT_GLB;
    if (!g->glb && !(g->scratch = malloc(OUT_BUF_CAP)))
        return nomem(err);
    uint32_t ntr = s->ncells[SD_CELL_TRIANGLE], nst = s->slice.ntri;
    bool tris = ntr || s->nbnd;
    if (tris && !s->normals) {
        if (!(s->own_normals = out_normals(s->lv, ntr, s->bnd, s->nbnd)))
            return nomem(err);
        s->normals = s->own_normals;
    }
    int iw = s->nv <= 65535 ? 2 : 4;
    gsec *pos = add_sec(g, G_POS, 0, 3, 4, s->nv), *nrm = NULL, *col = NULL, *rule;
    if (tris)
        nrm = add_sec(g, G_NRM, 0, 3, 4, s->nv);
    int first_attr = g->nsec;
    for (int a = 0; a < s->rq.nattrs; a++)
        add_sec(g, G_ATTR, a, s->rq.attrs[a].ncomp < 4 ? s->rq.attrs[a].ncomp : 4, 4, s->nv);
    rule = add_sec(g, G_RULE, 0, 1, 4, s->nv);
    if (s->rq.colormap_attr >= 0)
        col = add_sec(g, G_COLOR, 0, 3, 4, s->nv);
    gsec *ipt = s->ncells[SD_CELL_POINT] ? add_sec(g, G_IPT, 0, 1, iw, s->ncells[SD_CELL_POINT]) : NULL;
    gsec *iln = s->ncells[SD_CELL_CURVE] ? add_sec(g, G_ILN, 0, 2, iw, s->ncells[SD_CELL_CURVE]) : NULL;
    gsec *itr = ntr ? add_sec(g, G_ITR, 0, 3, iw, ntr) : NULL;
    gsec *ibd = s->nbnd ? add_sec(g, G_IBD, 0, 3, iw, s->nbnd) : NULL;
    gsec *spos = nst ? add_sec(g, G_SPOS, 0, 3, 4, 3ull * nst) : NULL;
    gsec *snrm = nst ? add_sec(g, G_SNRM, 0, 3, 4, 3ull * nst) : NULL;
    int first_sattr = g->nsec; /* the slice's own attribute values, interpolated on the cut edges */
    for (int a = 0; nst && a < s->rq.nattrs; a++)
        add_sec(g, G_SATTR, a, s->rq.attrs[a].ncomp < 4 ? s->rq.attrs[a].ncomp : 4, 4, 3ull * nst);
    gsec *scol = nst && col ? add_sec(g, G_SCOLOR, 0, 3, 4, 3ull * nst) : NULL;
    attribute_names(s, g);
    if (nst) {
        double l = sqrt(s->rq.slice[0] * s->rq.slice[0] + s->rq.slice[1] * s->rq.slice[1] +
                        s->rq.slice[2] * s->rq.slice[2]);
        float f[3] = {(float)(s->rq.slice[0] / l), (float)(s->rq.slice[1] / l), (float)(s->rq.slice[2] / l)};
        double fl = sqrt((double)f[0] * f[0] + (double)f[1] * f[1] + (double)f[2] * f[2]);
        for (int k = 0; k < 3; k++)
            g->nrm_plane[k] = (float)(f[k] / fl);
    }
    uint64_t off = 0;
    for (int i = 0; i < g->nsec; i++) {
        g->sec[i].offset = off;
        g->sec[i].accessor = i;
        off += (g->sec[i].bytes + 3) / 4 * 4;
    }
    g->bin_len = off;

    char *text = NULL;
    size_t n = 0;
    FILE *f = open_memstream(&text, &n);
    if (!f)
        return nomem(err);
    fprintf(f, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"subdivd\",\"extras\":{\"level\":%d,"
               "\"version\":%llu}},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],",
            s->rq.level, (unsigned long long)s->rq.version);
    /* buffer views and accessors, one each per section */
    fprintf(f, "\"bufferViews\":[");
    for (int i = 0; i < g->nsec; i++) {
        const gsec *c = &g->sec[i];
        bool index = c->id >= G_IPT && c->id <= G_IBD;
        fprintf(f, "%s{\"buffer\":0,\"byteOffset\":%llu,\"byteLength\":%llu,\"target\":%d}",
                i ? "," : "", (unsigned long long)c->offset, (unsigned long long)c->bytes,
                index ? 34963 : 34962);
    }
    fprintf(f, "],\"accessors\":[");
    for (int i = 0; i < g->nsec; i++) {
        const gsec *c = &g->sec[i];
        bool index = c->id >= G_IPT && c->id <= G_IBD;
        static const char *const vt[] = {"", "SCALAR", "VEC2", "VEC3", "VEC4"};
        uint64_t count = index ? c->count * (uint64_t)c->ncomp : c->count;
        fprintf(f, "%s{\"bufferView\":%d,\"componentType\":%d,\"count\":%llu,\"type\":\"%s\"",
                i ? "," : "", i, index ? (c->width == 2 ? 5123 : 5125) : 5126,
                (unsigned long long)count, index ? "SCALAR" : vt[c->ncomp]);
        if (c->id == G_POS || c->id == G_SPOS) { /* min/max of the float32 values written */
            float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
            const double *x = c->id == G_POS ? s->xyz : s->slice.xyz;
            for (uint64_t j = 0; j < c->count; j++)
                for (int k = 0; k < 3; k++) {
                    float v = (float)x[3 * j + k];
                    lo[k] = v < lo[k] ? v : lo[k];
                    hi[k] = v > hi[k] ? v : hi[k];
                }
            fprintf(f, ",\"min\":[%.9g,%.9g,%.9g],\"max\":[%.9g,%.9g,%.9g]", lo[0], lo[1], lo[2],
                    hi[0], hi[1], hi[2]);
        }
        fprintf(f, "}");
    }
    fprintf(f, "],\"materials\":[{\"name\":\"subdivd\",\"pbrMetallicRoughness\":{\"baseColorFactor\":"
               "[0.8,0.8,0.8,1],\"metallicFactor\":0,\"roughnessFactor\":0.8},\"doubleSided\":true}],");
    int nprim = 0;
    fprintf(f, "\"meshes\":[{\"name\":\"level %d\",\"primitives\":[", s->rq.level);
    const gsec *prims[4] = {ipt, iln, itr, ibd};
    static const int modes[4] = {0, 1, 4, 4};
    for (int p = 0; p < 4; p++) {
        if (!prims[p])
            continue;
        fprintf(f, "%s{\"attributes\":{\"POSITION\":%d", nprim++ ? "," : "", pos->accessor);
        if (modes[p] == 4)
            fprintf(f, ",\"NORMAL\":%d", nrm->accessor);
        for (int a = 0; a < s->rq.nattrs; a++)
            fprintf(f, ",\"%s\":%d", g->name[a], first_attr + a);
        fprintf(f, ",\"%s\":%d", g->name[s->rq.nattrs], rule->accessor);
        if (col)
            fprintf(f, ",\"COLOR_0\":%d", col->accessor);
        fprintf(f, "},\"indices\":%d,\"mode\":%d,\"material\":0}", prims[p]->accessor, modes[p]);
    }
    if (spos) {
        fprintf(f, "%s{\"attributes\":{\"POSITION\":%d,\"NORMAL\":%d", nprim++ ? "," : "",
                spos->accessor, snrm->accessor);
        for (int a = 0; a < s->rq.nattrs; a++)
            fprintf(f, ",\"%s\":%d", g->name[a], first_sattr + a);
        if (scol)
            fprintf(f, ",\"COLOR_0\":%d", scol->accessor);
        fprintf(f, "},\"mode\":4,\"material\":0}");
    }
    fprintf(f, "]}],");
    if (nprim)
        fprintf(f, "\"nodes\":[{\"name\":\"level %d\",\"mesh\":0}],", s->rq.level);
    else /* nothing to draw in the chosen parts: an empty node (a mesh needs a primitive) */
        fprintf(f, "\"nodes\":[{\"name\":\"level %d (empty)\"}],", s->rq.level);
    if (g->glb)
        fprintf(f, "\"buffers\":[{\"byteLength\":%llu}]}", (unsigned long long)g->bin_len);
    else
        fprintf(f, "\"buffers\":[{\"byteLength\":%llu,\"uri\":\"data:application/octet-stream;base64,",
                (unsigned long long)g->bin_len);
    if (fclose(f)) {
        free(text);
        return nomem(err);
    }
    if (!nprim) { /* drop the "meshes" member: a mesh without primitives is invalid */
        char *m = strstr(text, "\"meshes\":[{");
        char *e = m ? strstr(m, "]}],") : NULL;
        if (m && e) {
            memmove(m, e + 4, strlen(e + 4) + 1);
            n = strlen(text);
        }
    }
    if (g->glb) { /* 12-byte header + JSON chunk padded with spaces */
        size_t pad = (4 - n % 4) % 4;
        char *j = malloc(12 + 8 + n + pad);
        if (!j) {
            free(text);
            return nomem(err);
        }
        uint32_t total = (uint32_t)(12 + 8 + n + pad + 8 + g->bin_len);
        uint32_t hdr[5] = {0x46546C67, 2, total, (uint32_t)(n + pad), 0x4E4F534A};
        if (12 + 8 + n + pad + 8 + g->bin_len > UINT32_MAX) {
            free(j);
            free(text);
            err->code = SD_ERR_LIMIT;
            snprintf(err->message, sizeof err->message,
                     "the level is larger than a GLB file can be (4 GiB); ask for a lower level or "
                     "fewer parts");
            return SD_ERR_LIMIT;
        }
        memcpy(j, hdr, 20);
        memcpy(j + 20, text, n);
        memset(j + 20 + n, ' ', pad);
        free(text);
        g->json = j;
        g->json_len = 20 + n + pad;
        s->size = g->json_len + 8 + g->bin_len;
    } else {
        g->json = text;
        g->json_len = n;
        s->size = n + (g->bin_len + 2) / 3 * 4 + 4;
    }
    return 0;
}
