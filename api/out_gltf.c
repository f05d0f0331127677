/* out_gltf.c — glTF 2.0: binary .glb (default) and .gltf with the buffer embedded as base64.
 *
 * One scene; its root node "level L" has a child node per part shown, each with its own mesh of
 * one primitive, node and mesh named after the part:
 *   points (mode 0, isolated points), curves (mode 1, curve segments), surfaces (mode 4, surface
 *   triangles), solids (mode 4, the outward boundary of the tetrahedra and octahedra), and the
 *   optional slice (mode 4, non-indexed, its own POSITION, NORMAL, `_<NAME>` and COLOR_0: the
 *   cross-section of the solids by the plane, facing +n, attributes interpolated on the cut edges),
 *   and with parts=embedded one node "embedded/<name>" per embedded model (out_request.meshes:
 *   its own POSITION and u32 indices, mode 4; mode 0 for a model of points).
 * The first four share the level's vertex accessors, in level vertex order (live edits write
 * deltas straight into them): POSITION (float32, min/max from the written floats), NORMAL
 * (area-weighted, unit; (0,0,1) where a vertex has no triangle; triangle primitives only),
 * `_<NAME>` per attribute (float32, the first 4 components of longer vectors; made unique with a
 * `_2` suffix), `_RULE` (the sd_rule id as a float) and COLOR_0 (viridis of an attribute's first
 * component over [min,max], float32 RGB, linear as glTF requires). Accessors carry names.
 * Indices are u16 when the level has at most 65535 vertices, else u32. One material:
 * metallicFactor 0, doubleSided. asset.extras carries the level and version.
 *
 * The JSON part is small and built in out_open; the binary part is generated section by
 * section. Sizes are exact in advance (Content-Length).
 */
#include "out_internal.h"
#include "mem.h"
#include <ctype.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef enum { /* in buffer order; the index sections are G_IPT..G_IBD */
    G_POS, G_NRM, G_ATTR, G_RULE, G_COLOR, G_IPT, G_ILN, G_ITR, G_IBD, G_SPOS, G_SNRM, G_SATTR,
    G_SCOLOR, G_EPOS, G_EIDX /* an embedded model's (arg: which) positions and indices */
} gsec_id;

static bool is_index(int id) { return (id >= G_IPT && id <= G_IBD) || id == G_EIDX; }

/* Sections (out_section): id a gsec_id, arg the attribute, width 4 (float, u32) or 2 (u16),
 * bytes unpadded, offset in the buffer; section i is accessor i and buffer view i. */
typedef out_section gsec;

typedef struct gstate {
    bool glb;
    out_sections sec;
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
    int nattrs;           /* name[nattrs] is _RULE's */
} gstate;

static const char B64[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

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

/* Position of value x in the colour map's range (out_viridis clamps it to [0,1]). A range
 * wider than the largest double (-1e308:1e308) is taken in halves, which neither overflow nor,
 * for such a range, lose anything that shows: (x - min)/(max - min) as written would be x/inf,
 * 0 for every x. A finite width keeps the plain quotient, bit for bit as before. */
static double colormap_t(const out_stream *s, double x)
{
    double lo = s->rq.colormap_min, hi = s->rq.colormap_max;
    if (isfinite(hi - lo))
        return (x - lo) / (hi - lo);
    return (x / 2 - lo / 2) / (hi / 2 - lo / 2);
}

/* The accessor of a section. */
static int acc(const gstate *g, const gsec *c) { return (int)(c - g->sec.s); }

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
        int nc = s->rq.attrs[c->arg].ncomp;
        for (int k = 0; k < c->ncomp; k++)
            put_f(s, s->attr[c->arg][i * nc + k]);
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
        int nc = s->rq.attrs[c->arg].ncomp;
        for (int k = 0; k < c->ncomp; k++)
            put_f(s, s->slice.attr[c->arg][i * nc + k]);
        break;
    }
    case G_SCOLOR: {
        int a = s->rq.colormap_attr, nc = s->rq.attrs[a].ncomp;
        float rgb[3];
        out_viridis(colormap_t(s, s->slice.attr[a][i * nc]), rgb);
        out_put(s, rgb, 12);
        break;
    }
    case G_EPOS:
        for (int k = 0; k < 3; k++)
            put_f(s, s->mesh[c->arg].xyz[3 * i + k]);
        break;
    case G_EIDX: out_put(s, s->mesh[c->arg].tri + 3 * i, 12); break;
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
        int nc = s->rq.attrs[c->arg].ncomp;
        for (const double *x = s->attr[c->arg] + i * nc; i < end; i++, x += nc)
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
    while (ROOM(s) && s->section < g->sec.n) {
        const gsec *c = &g->sec.s[s->section];
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
    return s->section < g->sec.n;
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
        if (g->glb && g->sec.n) { /* no BIN chunk without a buffer */
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
    if (g->phase == 2 && !g->glb && g->sec.n)
        out_printf(s, "\"}]}");
    g->phase = 3;
    return 0;
}

/* ---- JSON --------------------------------------------------------------------------------- */

static void gfree(void *p)
{
    gstate *g = p;
    if (g) {
        api_free(g->json);
        api_free(g->scratch);
    }
    api_free(g);
}

/* glTF names of the per-vertex attributes: `_RULE` (name[nattrs]) first, then per attribute `_` +
 * the posted name upper-cased with `-` as `_` (custom semantics must start with `_`); a name
 * already taken (e.g. "a-b" and "A_B", or an attribute called "rule") gets `_2`, `_3`, ... */
static void attribute_names(const out_stream *s, gstate *g)
{
    int n = g->nattrs = s->rq.nattrs;
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

/* The accessors the JSON part names (NULL: absent). */
typedef struct layout {
    const gsec *pos, *nrm, *rule, *col, *prim[4], *spos, *snrm, *scol;
    const gsec *epos[OUT_MAX_MESHES], *eidx[OUT_MAX_MESHES]; /* embedded models (eidx: NULL
                                                                * for points) */
    int first_attr, first_sattr;   /* accessors of the first `_<NAME>` of the level and slice */
} layout;

/* The sections in buffer order, their offsets, the attribute names and the slice's normal. */
static void plan(out_stream *s, gstate *g, layout *L)
{
    uint32_t ntr = s->ncells[SD_CELL_TRIANGLE], nst = s->slice.ntri;
    int iw = s->nv <= 65535 ? 2 : 4;
    memset(L, 0, sizeof *L);
    bool level = s->rq.parts & OUT_PART_ALL; /* parts=embedded alone: none of the level's data */
    if (level)
        L->pos = out_section_add(&g->sec, G_POS, 0, 3, 4, s->nv);
    if (ntr || s->nbnd)
        L->nrm = out_section_add(&g->sec, G_NRM, 0, 3, 4, s->nv);
    L->first_attr = g->sec.n;
    for (int a = 0; level && a < s->rq.nattrs; a++)
        out_section_add(&g->sec, G_ATTR, a, s->rq.attrs[a].ncomp < 4 ? s->rq.attrs[a].ncomp : 4, 4, s->nv);
    if (level)
        L->rule = out_section_add(&g->sec, G_RULE, 0, 1, 4, s->nv);
    if (level && s->rq.colormap_attr >= 0)
        L->col = out_section_add(&g->sec, G_COLOR, 0, 3, 4, s->nv);
    if (s->ncells[SD_CELL_POINT])
        L->prim[0] = out_section_add(&g->sec, G_IPT, 0, 1, iw, s->ncells[SD_CELL_POINT]);
    if (s->ncells[SD_CELL_CURVE])
        L->prim[1] = out_section_add(&g->sec, G_ILN, 0, 2, iw, s->ncells[SD_CELL_CURVE]);
    if (ntr)
        L->prim[2] = out_section_add(&g->sec, G_ITR, 0, 3, iw, ntr);
    if (s->nbnd)
        L->prim[3] = out_section_add(&g->sec, G_IBD, 0, 3, iw, s->nbnd);
    if (nst) {
        L->spos = out_section_add(&g->sec, G_SPOS, 0, 3, 4, 3ull * nst);
        L->snrm = out_section_add(&g->sec, G_SNRM, 0, 3, 4, 3ull * nst);
    }
    L->first_sattr = g->sec.n; /* the slice's own attribute values, interpolated on the cut edges */
    for (int a = 0; nst && a < s->rq.nattrs; a++)
        out_section_add(&g->sec, G_SATTR, a, s->rq.attrs[a].ncomp < 4 ? s->rq.attrs[a].ncomp : 4, 4, 3ull * nst);
    if (nst && L->col)
        L->scol = out_section_add(&g->sec, G_SCOLOR, 0, 3, 4, 3ull * nst);
    for (int m = 0; m < s->nmesh; m++) {
        L->epos[m] = out_section_add(&g->sec, G_EPOS, m, 3, 4, s->mesh[m].nv);
        if (s->mesh[m].nt)
            L->eidx[m] = out_section_add(&g->sec, G_EIDX, m, 3, 4, s->mesh[m].nt);
    }
    attribute_names(s, g);
    if (nst) {
        double n[3], d;
        out_slice_plane(s->rq.slice, n, &d);
        float f[3] = {(float)n[0], (float)n[1], (float)n[2]};
        double fl = sqrt((double)f[0] * f[0] + (double)f[1] * f[1] + (double)f[2] * f[2]);
        for (int k = 0; k < 3; k++)
            g->nrm_plane[k] = (float)(f[k] / fl);
    }
    uint64_t off = 0;
    for (int i = 0; i < g->sec.n; i++) {
        g->sec.s[i].offset = off;
        off += (g->sec.s[i].bytes + 3) / 4 * 4;
    }
    g->bin_len = off;
}

/* The parts, in primitive order: node and mesh names, and the primitive modes. */
static const char *const PART_NAME[5] = {"points", "curves", "surfaces", "solids", "slice"};
static const int PART_MODE[5] = {0, 1, 4, 4, 4};

/* The accessor's name: the attribute's glTF name (`POSITION`, `_TEMP`, ...), prefixed with
 * "slice " for the slice's own ones; "<part> indices" for index accessors. */
static void accessor_name(FILE *f, const out_stream *s, const gstate *g, const gsec *c)
{
    switch (c->id) {
    case G_POS: fprintf(f, "POSITION"); break;
    case G_NRM: fprintf(f, "NORMAL"); break;
    case G_ATTR: fprintf(f, "%s", g->name[c->arg]); break;
    case G_RULE: fprintf(f, "%s", g->name[g->nattrs]); break;
    case G_COLOR: fprintf(f, "COLOR_0"); break;
    case G_IPT:
    case G_ILN:
    case G_ITR:
    case G_IBD: fprintf(f, "%s indices", PART_NAME[c->id - G_IPT]); break;
    case G_SPOS: fprintf(f, "slice POSITION"); break;
    case G_SNRM: fprintf(f, "slice NORMAL"); break;
    case G_SATTR: fprintf(f, "slice %s", g->name[c->arg]); break;
    case G_SCOLOR: fprintf(f, "slice COLOR_0"); break;
    case G_EPOS: fprintf(f, "embedded/%s POSITION", s->mesh[c->arg].name); break;
    case G_EIDX: fprintf(f, "embedded/%s indices", s->mesh[c->arg].name); break;
    }
}

/* "bufferViews" and "accessors": one each per section, the accessor named; POSITION's min/max
 * of the float32 values written. */
static void json_accessors(FILE *f, const out_stream *s, const gstate *g)
{
    if (!g->sec.n)
        return; /* nothing to store: no buffer, views or accessors (glTF forbids empty arrays) */
    fprintf(f, "\"bufferViews\":[");
    for (int i = 0; i < g->sec.n; i++) {
        const gsec *c = &g->sec.s[i];
        bool index = is_index(c->id);
        fprintf(f, "%s{\"buffer\":0,\"byteOffset\":%llu,\"byteLength\":%llu,\"target\":%d}",
                i ? "," : "", (unsigned long long)c->offset, (unsigned long long)c->bytes,
                index ? 34963 : 34962);
    }
    fprintf(f, "],\"accessors\":[");
    for (int i = 0; i < g->sec.n; i++) {
        const gsec *c = &g->sec.s[i];
        bool index = is_index(c->id);
        static const char *const vt[] = {"", "SCALAR", "VEC2", "VEC3", "VEC4"};
        uint64_t count = index ? c->count * (uint64_t)c->ncomp : c->count;
        fprintf(f, "%s{\"name\":\"", i ? "," : "");
        accessor_name(f, s, g, c);
        fprintf(f, "\",\"bufferView\":%d,\"componentType\":%d,\"count\":%llu,\"type\":\"%s\"",
                i, index ? (c->width == 2 ? 5123 : 5125) : 5126,
                (unsigned long long)count, index ? "SCALAR" : vt[c->ncomp]);
        if (c->id == G_POS || c->id == G_SPOS || c->id == G_EPOS) {
            float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
            const double *x = c->id == G_POS ? s->xyz : c->id == G_SPOS ? s->slice.xyz
                                                                         : s->mesh[c->arg].xyz;
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
    fprintf(f, "],");
}

/* "meshes" (one per part shown, named after it, with its one primitive) and "nodes" (node 0
 * "level L" with a child node per part, named after it); the number of parts. With no part to
 * draw the "meshes" member is left out and node 0 has no children. Parts 0-3 are the level's,
 * 4 the slice, 5 + m embedded model m. */
static int json_meshes(FILE *f, const out_stream *s, const gstate *g, const layout *L)
{
    int part[5 + OUT_MAX_MESHES], nparts = 0;
    for (int p = 0; p < 4; p++)
        if (L->prim[p])
            part[nparts++] = p;
    if (L->spos)
        part[nparts++] = 4;
    for (int m = 0; m < s->nmesh; m++)
        part[nparts++] = 5 + m;
    if (nparts)
        fprintf(f, "\"meshes\":[");
    for (int m = 0; m < nparts; m++) {
        int p = part[m];
        if (p >= 5) { /* an embedded model: its own POSITION, its triangles (or its points) */
            const out_mesh *e = &s->mesh[p - 5];
            fprintf(f, "%s{\"name\":\"embedded/%s\",\"primitives\":[{\"attributes\":{"
                       "\"POSITION\":%d}", m ? "," : "", e->name, acc(g, L->epos[p - 5]));
            if (L->eidx[p - 5])
                fprintf(f, ",\"indices\":%d", acc(g, L->eidx[p - 5]));
            fprintf(f, ",\"mode\":%d,\"material\":0}]}", L->eidx[p - 5] ? 4 : 0);
            continue;
        }
        fprintf(f, "%s{\"name\":\"%s\",\"primitives\":[{\"attributes\":{", m ? "," : "",
                PART_NAME[p]);
        if (p < 4) { /* the shared vertex accessors, in level vertex order */
            fprintf(f, "\"POSITION\":%d", acc(g, L->pos));
            if (PART_MODE[p] == 4)
                fprintf(f, ",\"NORMAL\":%d", acc(g, L->nrm));
            for (int a = 0; a < s->rq.nattrs; a++)
                fprintf(f, ",\"%s\":%d", g->name[a], L->first_attr + a);
            fprintf(f, ",\"%s\":%d", g->name[s->rq.nattrs], acc(g, L->rule));
            if (L->col)
                fprintf(f, ",\"COLOR_0\":%d", acc(g, L->col));
            fprintf(f, "},\"indices\":%d,", acc(g, L->prim[p]));
        } else { /* the slice's own accessors, non-indexed */
            fprintf(f, "\"POSITION\":%d,\"NORMAL\":%d", acc(g, L->spos), acc(g, L->snrm));
            for (int a = 0; a < s->rq.nattrs; a++)
                fprintf(f, ",\"%s\":%d", g->name[a], L->first_sattr + a);
            if (L->scol)
                fprintf(f, ",\"COLOR_0\":%d", acc(g, L->scol));
            fprintf(f, "},");
        }
        fprintf(f, "\"mode\":%d,\"material\":0}]}", PART_MODE[p]);
    }
    if (nparts)
        fprintf(f, "],");
    fprintf(f, "\"nodes\":[{\"name\":\"level %d%s\"", s->rq.level, nparts ? "" : " (empty)");
    if (nparts) {
        fprintf(f, ",\"children\":[");
        for (int m = 0; m < nparts; m++)
            fprintf(f, "%s%d", m ? "," : "", m + 1);
        fprintf(f, "]");
    }
    fprintf(f, "}");
    for (int m = 0; m < nparts; m++)
        if (part[m] >= 5)
            fprintf(f, ",{\"name\":\"embedded/%s\",\"mesh\":%d}", s->mesh[part[m] - 5].name, m);
        else
            fprintf(f, ",{\"name\":\"%s\",\"mesh\":%d}", PART_NAME[part[m]], m);
    fprintf(f, "]");
    return nparts;
}

/* The JSON part (glTF: up to the base64 data). The text is the C library's (open_memstream):
 * free it with api_free(). NULL when out of memory. */
static char *json_part(const out_stream *s, const gstate *g, const layout *L, size_t *len)
{
    char *text = NULL;
    size_t n = 0;
    FILE *f = open_memstream(&text, &n);
    if (!f)
        return NULL;
    fprintf(f, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"subdivd\",\"extras\":{\"level\":%d,"
               "\"version\":%llu}},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],",
            s->rq.level, (unsigned long long)s->rq.version);
    json_accessors(f, s, g);
    fprintf(f, "\"materials\":[{\"name\":\"subdivd\",\"pbrMetallicRoughness\":{\"baseColorFactor\":"
               "[0.8,0.8,0.8,1],\"metallicFactor\":0,\"roughnessFactor\":0.8},\"doubleSided\":true}],");
    json_meshes(f, s, g, L);
    if (!g->sec.n) /* parts=embedded without models: no data at all, so no buffer (a buffer's
                    * byteLength is at least 1) */
        fprintf(f, "}");
    else if (g->glb)
        fprintf(f, ",\"buffers\":[{\"byteLength\":%llu}]}", (unsigned long long)g->bin_len);
    else
        fprintf(f, ",\"buffers\":[{\"byteLength\":%llu,\"uri\":\"data:application/octet-stream;base64,",
                (unsigned long long)g->bin_len);
    if (fclose(f)) {
        free(text); /* open_memstream's buffer belongs to the C library */
        return NULL;
    }
    *len = n;
    return text;
}

/* g->json: GLB's 12-byte header and JSON chunk (padded with spaces), or glTF's text; s->size. */
static int frame(out_stream *s, gstate *g, const char *text, size_t n, sd_error *err)
{
    size_t pad = g->glb ? (4 - n % 4) % 4 : 0, head = g->glb ? 20 : 0;
    if (g->glb && head + n + pad + 8 + g->bin_len > UINT32_MAX) {
        err->code = SD_ERR_LIMIT;
        snprintf(err->message, sizeof err->message,
                 "the level is larger than a GLB file can be (4 GiB); ask for a lower level or "
                 "fewer parts");
        return SD_ERR_LIMIT;
    }
    char *j = api_malloc(head + n + pad + 1);
    if (!j)
        return out_nomem(err);
    if (g->glb) {
        uint32_t total = (uint32_t)(12 + 8 + n + pad + (g->sec.n ? 8 + g->bin_len : 0));
        uint32_t hdr[5] = {0x46546C67, 2, total, (uint32_t)(n + pad), 0x4E4F534A};
        memcpy(j, hdr, 20);
    }
    memcpy(j + head, text, n);
    memset(j + head + n, ' ', pad);
    g->json = j;
    g->json_len = head + n + pad;
    s->size = !g->sec.n ? g->json_len
              : g->glb ? g->json_len + 8 + g->bin_len : n + (g->bin_len + 2) / 3 * 4 + 4;
    return 0;
}

static int init(out_stream *s, bool glb, sd_error *err)
{
    gstate *g = out_state_new(s, sizeof *g, gfree, produce);
    if (!g)
        return out_nomem(err);
    g->glb = glb;
    if (!out_solid_boundary(s) || (!g->glb && !(g->scratch = api_malloc(OUT_BUF_CAP))))
        return out_nomem(err);
    uint32_t ntr = s->ncells[SD_CELL_TRIANGLE];
    if ((ntr || s->nbnd) && !s->normals) {
        if (!(s->own_normals = out_normals(s->lv, ntr, s->bnd, s->nbnd)))
            return out_nomem(err);
        s->normals = s->own_normals;
    } else if (s->rq.limit && s->own_normals) {
        /* limit normals; the area-weighted one where a point has no tangent plane */
        float *area = (ntr || s->nbnd) ? out_normals(s->lv, ntr, s->bnd, s->nbnd) : NULL;
        if ((ntr || s->nbnd) && !area)
            return out_nomem(err);
        for (uint32_t i = 0; i < s->nv; i++) {
            float *q = s->own_normals + 3 * (size_t)i;
            if (q[0] == 0 && q[1] == 0 && q[2] == 0) {
                if (area)
                    memcpy(q, area + 3 * (size_t)i, 3 * sizeof *q);
                else
                    q[2] = 1;
            }
        }
        api_free(area);
    }
    layout L;
    plan(s, g, &L);
    size_t n;
    char *text = json_part(s, g, &L, &n);
    if (!text)
        return out_nomem(err);
    int rc = frame(s, g, text, n, err);
    free(text); /* open_memstream's buffer belongs to the C library */
    return rc;
}

int out_glb_init(out_stream *s, sd_error *err) { return init(s, true, err); }
int out_gltf_init(out_stream *s, sd_error *err) { return init(s, false, err); }
