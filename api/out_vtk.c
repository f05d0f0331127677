/* out_vtk.c — VTK unstructured grids: XML .vtu (appended raw binary, or inline zlib-compressed
 * blocks with compress=zlib) and legacy .vtk (binary).
 *
 * Cells are written sorted by VTK type, as meshio expects: vertices (1) for isolated points,
 * lines (3) for curve segments, triangles (5) for surface triangles followed by the slice
 * triangles, tetrahedra (10) for tetrahedra followed by the octahedra split into 4 tets along
 * their major diagonal — or, on request in VTU, octahedra as polyhedra (42) last.
 * Points: the level's vertices, then 3 points per slice triangle.
 * Point data: every requested attribute (Float64; slice points interpolated along the cut edge)
 * and "rule" (the sd_rule id; 255 for slice points; "rule_2" if an attribute is called "rule"). Cell data: "dimension" (0..3; 2 for the
 * slice), "kind" (sd_cell_kind; 5 for the slice), "source_cell" (the cell's index within its
 * kind at this level; for an octahedron's tets and a slice triangle, the cut/split cell's), with
 * a slice "source_kind" (the kind source_cell counts in: a slice triangle's cut cell's, 3 or 4;
 * any other cell's own kind) and
 * "control_cell" (the posted simplex it descends from, sd_level_control_cell). FieldData: "level",
 * "version", and on request the names of the rule and kind values (string arrays).
 *
 * Both formats are a sequence of arrays produced item by item; their sizes are exact before the
 * first byte. VTU blocks carry a UInt64 byte count; legacy data are big-endian.
 *
 * VTU's appended blocks are stored in the reverse order of their <DataArray> elements. VTK does
 * not care; meshio 7 does: its raw reader walks the blocks in file order, finds each one's element
 * by `offset` and rewrites that offset (to a base64 position) as it goes, so a rewritten offset
 * can equal a later block's and capture it. With the elements in reverse order the element it
 * looks for always comes before every rewritten one.
 */
#include "out_internal.h"
#include "mem.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

enum { VT_VERTEX = 1, VT_LINE = 3, VT_TRIANGLE = 5, VT_TETRA = 10, VT_POLYHEDRON = 42 };
enum { SLICE_KIND = 5 };

typedef enum {
    A_ATTR, A_RULE, A_DIM, A_KIND, A_SRC, A_SKIND, A_CTRL, A_POINTS, A_CONN, A_OFFS, A_TYPES, A_FACES, A_FOFFS
} arr_id;

/* Arrays (out_section): id an arr_id, arg the attribute (A_ATTR), width the bytes per component
 * (8 Float64, 4 Int32, 1 UInt8), count the items (tuples or cells), head the text before the
 * data (XML: none; legacy: the keyword lines). */
typedef out_section arr;

typedef struct vstate {
    bool legacy;
    uint64_t npts, ncell, nconn;
    /* cell ranges (start of each block, in cells) */
    uint64_t r_pt, r_cu, r_tr, r_sl, r_tet, r_oct, r_poly, r_end;
    out_sections a;
    char *header;        /* XML text before the appended data, or legacy file header */
    size_t header_len;
    int phase;           /* 0 header, 1 arrays, 2 trailer */
    bool prefix_done;
    char rule_name[80];  /* "rule", or "rule_2", ... if an attribute is called that */
    /* compress=zlib (VTU): see "compressed VTU" below */
    bool z;
    size_t zpos[OUT_MAX_SECTIONS]; /* header text before section i's data ends here */
    z_stream zs;
    bool zs_ready;
    unsigned char *cbuf;  /* the current array's compressed blocks */
    size_t ccap, clen, zbound; /* zbound: deflateBound of one block */
    unsigned char *hbuf;  /* its header: UInt64 nblocks, block size, last block size, sizes */
    uint64_t nblk, blk_fill;
    int zstep;            /* per array: 0 text, 1 compress, 2 header, 3 data, 4 next */
    size_t epos;          /* base64: bytes of hbuf / cbuf encoded so far */
} vstate;

/* ---- cells in file order ------------------------------------------------------------------ */

typedef struct vcell {
    int type, dim, kind, n;
    long src;
    uint32_t v[6];
} vcell;

static void cell_at(const out_stream *s, const vstate *st, uint64_t c, vcell *o)
{
    if (c < st->r_cu) {
        uint32_t v[6];
        sd_level_cell(s->lv, SD_CELL_POINT, (uint32_t)(c - st->r_pt), v);
        *o = (vcell){VT_VERTEX, 0, SD_CELL_POINT, 1, (long)(c - st->r_pt), {v[0]}};
    } else if (c < st->r_tr) {
        uint32_t v[6];
        sd_level_cell(s->lv, SD_CELL_CURVE, (uint32_t)(c - st->r_cu), v);
        *o = (vcell){VT_LINE, 1, SD_CELL_CURVE, 2, (long)(c - st->r_cu), {v[0], v[1]}};
    } else if (c < st->r_sl) {
        uint32_t v[6];
        sd_level_cell(s->lv, SD_CELL_TRIANGLE, (uint32_t)(c - st->r_tr), v);
        *o = (vcell){VT_TRIANGLE, 2, SD_CELL_TRIANGLE, 3, (long)(c - st->r_tr), {v[0], v[1], v[2]}};
    } else if (c < st->r_tet) {
        uint64_t t = c - st->r_sl, p = s->nv + 3 * t;
        *o = (vcell){VT_TRIANGLE, 2, SLICE_KIND, 3, (long)s->slice.cell[t],
                     {(uint32_t)p, (uint32_t)p + 1, (uint32_t)p + 2}};
    } else if (c < st->r_oct) {
        uint32_t v[6];
        sd_level_cell(s->lv, SD_CELL_TETRA, (uint32_t)(c - st->r_tet), v);
        *o = (vcell){VT_TETRA, 3, SD_CELL_TETRA, 4, (long)(c - st->r_tet), {v[0], v[1], v[2], v[3]}};
    } else if (c < st->r_poly) {
        uint64_t k = c - st->r_oct;
        uint32_t v[6], t[4];
        sd_level_cell(s->lv, SD_CELL_OCTA, (uint32_t)(k / 4), v);
        sd_octa_tet(v, (int)(k % 4), t);
        *o = (vcell){VT_TETRA, 3, SD_CELL_OCTA, 4, (long)(k / 4), {t[0], t[1], t[2], t[3]}};
    } else {
        uint32_t v[6];
        sd_level_cell(s->lv, SD_CELL_OCTA, (uint32_t)(c - st->r_poly), v);
        *o = (vcell){VT_POLYHEDRON, 3, SD_CELL_OCTA, 6, (long)(c - st->r_poly),
                     {v[0], v[1], v[2], v[3], v[4], v[5]}};
    }
}

/* Connectivity entries before cell c (closed form per block). */
static uint64_t conn_before(const vstate *st, uint64_t c)
{
    static const int per[] = {1, 2, 3, 3, 4, 4, 6};
    const uint64_t start[] = {st->r_pt, st->r_cu, st->r_tr, st->r_sl, st->r_tet, st->r_oct, st->r_poly, st->r_end};
    uint64_t n = 0;
    for (int b = 0; b < 7; b++) {
        if (c <= start[b])
            break;
        uint64_t end = c < start[b + 1] ? c : start[b + 1];
        n += (end - start[b]) * per[b];
    }
    return n;
}

/* ---- items -------------------------------------------------------------------------------- */

static void put_num(out_stream *s, const vstate *st, int width, double x, long long i)
{
    if (!st->legacy && width == 4) { /* the common case: a little-endian Int32 */
        int32_t v = (int32_t)i;
        memcpy(s->buf + s->len, &v, 4);
        s->len += 4;
        return;
    }
    unsigned char b[8];
    if (width == 8)
        memcpy(b, &x, 8);
    else if (width == 4) {
        int32_t v = (int32_t)i;
        memcpy(b, &v, 4);
    } else
        b[0] = (unsigned char)i;
    if (st->legacy) /* big-endian */
        for (int k = 0; k < width / 2; k++) {
            unsigned char t = b[k];
            b[k] = b[width - 1 - k];
            b[width - 1 - k] = t;
        }
    out_put(s, b, (size_t)width);
}

static const uint8_t OCT_FACES[8][3] = {{0, 2, 4}, {0, 4, 3}, {0, 3, 5}, {0, 5, 2},
                                        {1, 4, 2}, {1, 3, 4}, {1, 5, 3}, {1, 2, 5}};

static void put_item(out_stream *s, const vstate *st, const arr *a, uint64_t i)
{
    vcell c;
    switch (a->id) {
    case A_ATTR:
    case A_POINTS: {
        const double *x;
        int nc = a->ncomp;
        if (i < s->nv)
            x = a->id == A_POINTS ? s->xyz + 3 * i : s->attr[a->arg] + i * nc;
        else
            x = a->id == A_POINTS ? s->slice.xyz + 3 * (i - s->nv)
                                  : s->slice.attr[a->arg] + (i - s->nv) * nc;
        for (int k = 0; k < nc; k++)
            put_num(s, st, 8, x[k], 0);
        break;
    }
    case A_RULE: put_num(s, st, a->width, 0, i < s->nv ? sd_level_vertex_rule(s->lv, (uint32_t)i) : 255); break;
    case A_DIM:
    case A_KIND:
    case A_SRC:
    case A_TYPES:
        cell_at(s, st, i, &c);
        put_num(s, st, a->width, 0,
                a->id == A_DIM ? c.dim : a->id == A_KIND ? c.kind : a->id == A_SRC ? c.src : c.type);
        break;
    case A_SKIND: /* with a slice: the kind source_cell counts in */
    case A_CTRL: {
        cell_at(s, st, i, &c);
        /* a slice triangle's: the cut cell's (src names it, slice.kind its kind) */
        int k = c.kind == SLICE_KIND ? s->slice.kind[i - st->r_sl] : c.kind;
        put_num(s, st, a->width, 0, a->id == A_SKIND ? (long long)k
                                    : (long long)sd_level_control_cell(s->lv, (sd_cell_kind)k,
                                                                       (uint32_t)c.src));
        break;
    }
    case A_CONN:
        cell_at(s, st, i, &c);
        if (st->legacy)
            put_num(s, st, 4, 0, c.n);
        for (int k = 0; k < c.n; k++)
            put_num(s, st, 4, 0, c.v[k]);
        break;
    case A_OFFS: put_num(s, st, 4, 0, (long long)conn_before(st, i + 1)); break;
    case A_FACES: /* polyhedra only: 8 faces of 3 */
        cell_at(s, st, st->r_poly + i, &c);
        put_num(s, st, 4, 0, 8);
        for (int f = 0; f < 8; f++) {
            put_num(s, st, 4, 0, 3);
            for (int k = 0; k < 3; k++)
                put_num(s, st, 4, 0, c.v[OCT_FACES[f][k]]);
        }
        break;
    case A_FOFFS:
        put_num(s, st, 4, 0, i < st->r_poly ? -1 : (long long)(33 * (i - st->r_poly + 1)));
        break;
    }
}

/* ---- generator ---------------------------------------------------------------------------- */

#define ROOM(s) ((s)->len < OUT_BUF_CAP / 2)

/* ---- compressed VTU -----------------------------------------------------------------------
 * compress=zlib writes each array as VTK's vtkZLibDataCompressor does — a header of UInt64
 * [nblocks, block size, last block size (0: full), compressed size of each block] and the
 * blocks, each a zlib stream of ZBLOCK bytes (the last one shorter) — but inline, as
 * format="binary" (the header and the blocks base64-encoded separately, as VTK writes them),
 * not appended: an appended array's offset is its predecessors' compressed size, unknown before
 * they are compressed, and the offsets come first in the file. So one array at a time is
 * compressed into cbuf (its blocks' bound, allocated at open for the largest array, counted
 * like every api_malloc block), then encoded; the size is not known in advance (chunked). */

#define ZBLOCK 32768u /* VTK's default block size */
#define ZLEVEL 1      /* deflate's fastest level (VTK reads any; its own default is 5) */

static voidpf z_alloc(voidpf op, uInt n, uInt size) { (void)op; return api_calloc(n, size); }
static void z_free(voidpf op, voidpf p) { (void)op; api_free(p); }

static uint64_t z_nblocks(uint64_t bytes) { return (bytes + ZBLOCK - 1) / ZBLOCK; }

/* End the current block: its compressed size into the header. */
static void z_end_block(vstate *st)
{
    st->zs.next_in = NULL;
    st->zs.avail_in = 0;
    int rc = deflate(&st->zs, Z_FINISH);
    if (rc != Z_STREAM_END) { /* cbuf holds the bound of every block: a writer bug */
        fprintf(stderr, "out_vtk: deflate %d\n", rc);
        abort();
    }
    uint64_t c = st->zs.total_out;
    memcpy(st->hbuf + 8 * (3 + st->nblk), &c, 8);
    st->clen += (size_t)c;
    st->nblk++;
    st->blk_fill = 0;
    deflateReset(&st->zs);
}

/* Compress n raw bytes of the current array. */
static void z_feed(vstate *st, const unsigned char *p, size_t n)
{
    while (n) {
        if (st->blk_fill == 0) { /* a new block */
            st->zs.next_out = st->cbuf + st->clen; /* room for the block's bound (uInt) */
            st->zs.avail_out = (uInt)st->zbound;
        }
        size_t k = ZBLOCK - st->blk_fill;
        if (k > n)
            k = n;
        st->zs.next_in = (unsigned char *)p;
        st->zs.avail_in = (uInt)k;
        if (deflate(&st->zs, Z_NO_FLUSH) != Z_OK || st->zs.avail_in) {
            fprintf(stderr, "out_vtk: deflate\n");
            abort();
        }
        st->blk_fill += k;
        p += k;
        n -= k;
        if (st->blk_fill == ZBLOCK)
            z_end_block(st);
    }
}

/* Base64 of p[0..n) from *pos, as much as fits the chunk (whole groups of 3 but at the end). */
static bool b64_step(out_stream *s, const unsigned char *p, size_t n, size_t *pos)
{
    static const char T[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    size_t room = (OUT_BUF_CAP - s->len) / 4 * 3, i = *pos; /* len < OUT_BUF_CAP / 2 */
    size_t end = n - i > room ? i + room : n;
    char *o = s->buf + s->len;
    for (; i + 3 <= end; i += 3) {
        unsigned v = (unsigned)p[i] << 16 | (unsigned)p[i + 1] << 8 | p[i + 2];
        *o++ = T[v >> 18], *o++ = T[(v >> 12) & 63], *o++ = T[(v >> 6) & 63], *o++ = T[v & 63];
    }
    if (end == n && i < n) { /* 1 or 2 bytes left: padded */
        unsigned v = (unsigned)p[i] << 16 | (i + 1 < n ? (unsigned)p[i + 1] << 8 : 0);
        *o++ = T[v >> 18], *o++ = T[(v >> 12) & 63];
        *o++ = i + 1 < n ? T[(v >> 6) & 63] : '=';
        *o++ = '=';
        i = n;
    }
    s->len = (size_t)(o - s->buf);
    *pos = i;
    return i == n;
}

static int produce_z(out_stream *s, vstate *st)
{
    while (ROOM(s)) {
        if (s->section < 0) { /* the text after the last array */
            out_put(s, st->header + st->zpos[0], st->header_len - st->zpos[0]);
            return 0;
        }
        int i = s->section;
        const arr *a = &st->a.s[i];
        switch (st->zstep) {
        case 0: { /* the text before the array: up to its <DataArray ...> */
            size_t from = i == st->a.n - 1 ? 0 : st->zpos[i + 1];
            out_put(s, st->header + from, st->zpos[i] - from);
            st->nblk = st->blk_fill = 0;
            st->clen = 0;
            s->item = 0;
            st->zstep = 1;
            break;
        }
        case 1: { /* items into the chunk buffer, compressed from there */
            uint64_t k = s->item;
            size_t base = s->len;
            for (; k < a->count && ROOM(s); k++)
                put_item(s, st, a, k);
            s->item = k;
            z_feed(st, (unsigned char *)s->buf + base, s->len - base);
            s->len = base;
            if (k < a->count)
                return 1;
            if (st->blk_fill)
                z_end_block(st);
            uint64_t h[3] = {st->nblk, ZBLOCK, a->bytes % ZBLOCK};
            memcpy(st->hbuf, h, sizeof h);
            st->epos = 0;
            st->zstep = 2;
            break;
        }
        case 2:
            if (b64_step(s, st->hbuf, 8 * (3 + st->nblk), &st->epos))
                st->epos = 0, st->zstep = 3;
            break;
        case 3:
            if (b64_step(s, st->cbuf, st->clen, &st->epos))
                st->zstep = 4;
            break;
        default:
            s->section--;
            st->zstep = 0;
        }
    }
    return 1;
}

/* At open: the deflate state and the buffers for the largest array (false: out of memory). */
static bool z_prepare(vstate *st)
{
    uint64_t most = 0;
    for (int i = 0; i < st->a.n; i++)
        if (st->a.s[i].bytes > most)
            most = st->a.s[i].bytes;
    st->zs.zalloc = z_alloc;
    st->zs.zfree = z_free;
    if (deflateInit(&st->zs, ZLEVEL) != Z_OK)
        return false;
    st->zs_ready = true;
    uint64_t nb = z_nblocks(most);
    st->zbound = deflateBound(&st->zs, ZBLOCK);
    st->ccap = (size_t)(nb * st->zbound);
    st->cbuf = api_malloc(st->ccap ? st->ccap : 1);
    st->hbuf = api_malloc((size_t)(8 * (3 + nb)));
    return st->cbuf && st->hbuf;
}

static int produce(out_stream *s)
{
    vstate *st = s->fmt_state;
    if (st->z)
        return produce_z(s, st);
    if (st->phase == 0) { /* the header is at most a few kB */
        out_put(s, st->header, st->header_len);
        st->phase = 1;
        s->section = 0;
        s->item = 0;
        return 1;
    }
    while (st->phase == 1 && ROOM(s)) {
        if (s->section == st->a.n) {
            st->phase = 2;
            break;
        }
        const arr *a = &st->a.s[s->section];
        if (!st->prefix_done) {
            if (st->legacy)
                out_printf(s, "%s", a->head);
            else
                out_put(s, &a->bytes, 8); /* UInt64 block size, little-endian like the data */
            st->prefix_done = true;
        }
        uint64_t i = s->item;
        for (; i < a->count && ROOM(s); i++)
            put_item(s, st, a, i);
        s->item = i;
        if (i < a->count)
            return 1;
        if (st->legacy)
            out_put(s, "\n", 1);
        s->section++;
        s->item = 0;
        st->prefix_done = false;
    }
    if (st->phase == 2) {
        if (!st->legacy)
            out_printf(s, "\n  </AppendedData>\n</VTKFile>\n");
        st->phase = 3;
        return 0;
    }
    return 1;
}

static void vfree(void *p)
{
    vstate *st = p;
    if (st) {
        api_free(st->header);
        if (st->zs_ready)
            deflateEnd(&st->zs);
        api_free(st->cbuf);
        api_free(st->hbuf);
    }
    api_free(st);
}

static int setup(out_stream *s, vstate *st, bool legacy, sd_error *err)
{
    st->legacy = legacy;
    st->z = !legacy && s->rq.compress == OUT_COMPRESS_ZLIB;
    snprintf(st->rule_name, sizeof st->rule_name, "rule");
    for (int suffix = 2, clash = 1; clash; suffix++) {
        clash = 0;
        for (int a = 0; a < s->rq.nattrs && !clash; a++)
            clash = !strcmp(s->rq.attrs[a].name, st->rule_name);
        if (clash)
            snprintf(st->rule_name, sizeof st->rule_name, "rule_%d", suffix);
    }
    bool poly = !legacy && s->rq.octahedra_as_polyhedra;
    uint64_t ns = s->slice.ntri;
    st->r_pt = 0;
    st->r_cu = st->r_pt + s->ncells[SD_CELL_POINT];
    st->r_tr = st->r_cu + s->ncells[SD_CELL_CURVE];
    st->r_sl = st->r_tr + s->ncells[SD_CELL_TRIANGLE];
    st->r_tet = st->r_sl + ns;
    st->r_oct = st->r_tet + s->ncells[SD_CELL_TETRA];
    st->r_poly = st->r_oct + (poly ? 0 : 4ull * s->ncells[SD_CELL_OCTA]);
    st->r_end = st->r_poly + (poly ? s->ncells[SD_CELL_OCTA] : 0);
    st->ncell = st->r_end;
    st->nconn = conn_before(st, st->ncell);
    st->npts = s->nv + 3 * ns;
    if (st->ncell > INT32_MAX || st->nconn + st->ncell > INT32_MAX || st->npts > INT32_MAX) {
        err->code = SD_ERR_LIMIT;
        snprintf(err->message, sizeof err->message, "the level is too large for 32-bit VTK ids");
        return SD_ERR_LIMIT;
    }
    arr *a;
    /* legacy order: POINTS, CELLS, CELL_TYPES, CELL_DATA, POINT_DATA; XML: point data, cell
     * data, points, cells (the order of the XML elements) */
    if (legacy) {
        a = out_section_add(&st->a, A_POINTS, 0, 3, 8, st->npts);
        snprintf(a->head, sizeof a->head, "POINTS %llu double\n", (unsigned long long)st->npts);
        a = out_section_add(&st->a, A_CONN, 0, 1, 4, st->ncell);
        a->bytes = 4 * (st->nconn + st->ncell);
        snprintf(a->head, sizeof a->head, "CELLS %llu %llu\n", (unsigned long long)st->ncell,
                 (unsigned long long)(st->nconn + st->ncell));
        a = out_section_add(&st->a, A_TYPES, 0, 1, 4, st->ncell);
        snprintf(a->head, sizeof a->head, "CELL_TYPES %llu\n", (unsigned long long)st->ncell);
        static const char *const cnames[] = {"dimension", "kind", "source_cell", "source_kind",
                                             "control_cell"};
        static const arr_id cids[] = {A_DIM, A_KIND, A_SRC, A_SKIND, A_CTRL};
        const int ncd = s->rq.has_slice ? 5 : 4;
        for (int k = 0; k < 5; k++) {
            if (cids[k] == A_SKIND && !s->rq.has_slice)
                continue;
            a = out_section_add(&st->a, cids[k], 0, 1, 4, st->ncell);
            char first[64] = "";
            if (k == 0) /* the block header comes with the first array */
                snprintf(first, sizeof first, "CELL_DATA %llu\nFIELD FieldData %d\n",
                         (unsigned long long)st->ncell, ncd);
            snprintf(a->head, sizeof a->head, "%s%s 1 %llu int\n", first, cnames[k],
                     (unsigned long long)st->ncell);
        }
        for (int i = 0; i <= s->rq.nattrs; i++) {
            bool rule = i == s->rq.nattrs;
            a = rule ? out_section_add(&st->a, A_RULE, 0, 1, 4, st->npts)
                     : out_section_add(&st->a, A_ATTR, i, s->rq.attrs[i].ncomp, 8, st->npts);
            char body[128];
            snprintf(body, sizeof body, "%s %d %llu %s\n", rule ? st->rule_name : s->rq.attrs[i].name,
                     a->ncomp, (unsigned long long)st->npts, rule ? "int" : "double");
            if (i == 0)
                snprintf(a->head, sizeof a->head, "POINT_DATA %llu\nFIELD FieldData %d\n%s",
                         (unsigned long long)st->npts, s->rq.nattrs + 1, body);
            else
                snprintf(a->head, sizeof a->head, "%s", body);
        }
    } else { /* the appended blocks in the reverse order of their XML elements (see the top) */
        if (poly) {
            out_section_add(&st->a, A_FOFFS, 0, 1, 4, st->ncell);
            out_section_add(&st->a, A_FACES, 0, 1, 4, st->r_end - st->r_poly)->bytes =
                4ull * 33 * (st->r_end - st->r_poly);
        }
        out_section_add(&st->a, A_TYPES, 0, 1, 1, st->ncell);
        out_section_add(&st->a, A_OFFS, 0, 1, 4, st->ncell);
        a = out_section_add(&st->a, A_CONN, 0, 1, 4, st->ncell);
        a->bytes = 4 * st->nconn;
        out_section_add(&st->a, A_POINTS, 0, 3, 8, st->npts);
        out_section_add(&st->a, A_CTRL, 0, 1, 4, st->ncell);
        if (s->rq.has_slice)
            out_section_add(&st->a, A_SKIND, 0, 1, 1, st->ncell);
        out_section_add(&st->a, A_SRC, 0, 1, 4, st->ncell);
        out_section_add(&st->a, A_KIND, 0, 1, 1, st->ncell);
        out_section_add(&st->a, A_DIM, 0, 1, 1, st->ncell);
        out_section_add(&st->a, A_RULE, 0, 1, 1, st->npts);
        for (int i = s->rq.nattrs - 1; i >= 0; i--)
            out_section_add(&st->a, A_ATTR, i, s->rq.attrs[i].ncomp, 8, st->npts);
    }
    return 0;
}

/* The names of the `kind` cell data values (sd_cell_kind, then the slice). */
static const char *const KIND_NAMES[] = {"point", "curve", "triangle", "tetrahedron", "octahedron",
                                         "slice"};

/* One string array of FieldData: n names, name(i) the i-th. XML: ASCII character codes, each
 * string ended by 0 (VTK's own XML writer); legacy binary: each string after its length byte
 * 0xC0 | length (vtkDataWriter, strings shorter than 64 bytes). */
static void string_array(FILE *f, bool legacy, const char *array, int n, const char *(*name)(int))
{
    if (legacy)
        fprintf(f, "%s 1 %d string\n", array, n);
    else
        fprintf(f, "      <Array type=\"String\" Name=\"%s\" NumberOfTuples=\"%d\" "
                   "format=\"ascii\">\n       ", array, n);
    for (int i = 0; i < n; i++) {
        const char *t = name(i);
        size_t len = strlen(t);
        if (legacy) {
            fputc(0xC0 | (int)len, f); /* the names are short (asserted by their tables) */
            fwrite(t, 1, len, f);
        } else {
            for (size_t k = 0; k <= len; k++)
                fprintf(f, " %d", (unsigned char)t[k]);
        }
    }
    fprintf(f, legacy ? "\n" : "\n      </Array>\n");
}

static const char *rule_name_at(int i) { return sd_rule_name((sd_rule)i); }
static const char *kind_name_at(int i) { return KIND_NAMES[i]; }

/* The dataset's FieldData: `level` (Int32) and `version` (Int64; legacy: double), and with rq.field_names
 * `rule_names` (index = the `rule` point data value) and `kind_names` (index = `kind`). */
static void field_data(const out_stream *s, FILE *f, bool legacy)
{
    bool names = s->rq.field_names;
    if (legacy) {
        unsigned char b[8];
        uint32_t l = (uint32_t)s->rq.level;
        uint64_t v = s->rq.version;
        fprintf(f, "FIELD FieldData %d\nlevel 1 1 int\n", names ? 4 : 2);
        for (int k = 0; k < 4; k++)
            b[k] = (unsigned char)(l >> (24 - 8 * k)); /* big-endian */
        fwrite(b, 1, 4, f);
        /* legacy: a double (exact below 2^53), since meshio 7 reads no vtktypeint64 and
         * "long" is 4 bytes on some platforms */
        fprintf(f, "\nversion 1 1 double\n");
        double d = (double)v;
        uint64_t u;
        memcpy(&u, &d, 8);
        for (int k = 0; k < 8; k++)
            b[k] = (unsigned char)(u >> (56 - 8 * k));
        fwrite(b, 1, 8, f);
        fprintf(f, "\n");
    } else
        fprintf(f, "    <FieldData>\n"
                   "      <DataArray type=\"Int32\" Name=\"level\" NumberOfTuples=\"1\" "
                   "format=\"ascii\">%d</DataArray>\n"
                   "      <DataArray type=\"Int64\" Name=\"version\" NumberOfTuples=\"1\" "
                   "format=\"ascii\">%llu</DataArray>\n",
                s->rq.level, (unsigned long long)s->rq.version);
    if (names) {
        string_array(f, legacy, "rule_names", SD_RULE_COUNT, rule_name_at);
        string_array(f, legacy, "kind_names", 6, kind_name_at);
    }
    if (!legacy)
        fprintf(f, "    </FieldData>\n");
}

static int build_header(out_stream *s, vstate *st, sd_error *err)
{
    char *text = NULL;
    size_t n = 0;
    FILE *f = open_memstream(&text, &n);
    if (!f)
        return out_nomem(err);
    if (st->legacy) {
        fprintf(f, "# vtk DataFile Version 3.0\nsubdivd level %d version %llu\nBINARY\n"
                   "DATASET UNSTRUCTURED_GRID\n", s->rq.level, (unsigned long long)s->rq.version);
        field_data(s, f, true);
    } else {
        static const char *const tname[] = {[1] = "UInt8", [4] = "Int32", [8] = "Float64"};
        uint64_t off[OUT_MAX_ATTRS + 12];
        for (int k = 0; k < st->a.n; k++)
            off[k] = k ? off[k - 1] + 8 + st->a.s[k - 1].bytes : 0;
        int i = st->a.n - 1; /* elements in XML order = blocks from the last */
        fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" "
                   "byte_order=\"LittleEndian\" header_type=\"UInt64\"%s>\n  <UnstructuredGrid>\n",
                st->z ? " compressor=\"vtkZLibDataCompressor\"" : "");
        field_data(s, f, false);
        fprintf(f, "    <Piece NumberOfPoints=\"%llu\" NumberOfCells=\"%llu\">\n      <PointData>\n",
                (unsigned long long)st->npts, (unsigned long long)st->ncell);
#define DA(name, extra)                                                                            \
    do {                                                                                           \
        const arr *a = &st->a.s[i];                                                                  \
        if (st->z) { /* inline: the data goes at zpos[i] */                                        \
            fprintf(f, "        <DataArray type=\"%s\" Name=\"%s\"%s format=\"binary\">\n"         \
                       "          ", tname[a->width], name, extra);                                \
            fflush(f);                                                                             \
            st->zpos[i] = n;                                                                       \
            fprintf(f, "\n        </DataArray>\n");                                                \
        } else                                                                                     \
            fprintf(f, "        <DataArray type=\"%s\" Name=\"%s\"%s format=\"appended\" "         \
                       "offset=\"%llu\"/>\n", tname[a->width], name, extra,                        \
                    (unsigned long long)off[i]);                                                   \
        i--;                                                                                       \
    } while (0)
        for (int k = 0; k < s->rq.nattrs; k++) {
            char nc[48];
            snprintf(nc, sizeof nc, " NumberOfComponents=\"%d\"", s->rq.attrs[k].ncomp);
            DA(s->rq.attrs[k].name, nc);
        }
        DA(st->rule_name, "");
        fprintf(f, "      </PointData>\n      <CellData>\n");
        DA("dimension", "");
        DA("kind", "");
        DA("source_cell", "");
        if (s->rq.has_slice)
            DA("source_kind", "");
        DA("control_cell", "");
        fprintf(f, "      </CellData>\n      <Points>\n");
        DA("Points", " NumberOfComponents=\"3\"");
        fprintf(f, "      </Points>\n      <Cells>\n");
        DA("connectivity", "");
        DA("offsets", "");
        DA("types", "");
        if (i >= 0) {
            DA("faces", "");
            DA("faceoffsets", "");
        }
#undef DA
        if (st->z)
            fprintf(f, "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
        else
            fprintf(f, "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n"
                       "  <AppendedData encoding=\"raw\">\n   _");
    }
    if (fclose(f)) {
        free(text); /* open_memstream's buffer belongs to the C library */
        return out_nomem(err);
    }
    st->header = api_malloc(n + 1); /* a copy: open_memstream's buffer belongs to the C library */
    if (st->header)
        memcpy(st->header, text, n);
    free(text); /* open_memstream's buffer belongs to the C library */
    if (!st->header)
        return out_nomem(err);
    st->header_len = n;
    uint64_t total = n;
    for (int i = 0; i < st->a.n; i++)
        total += st->legacy ? strlen(st->a.s[i].head) + st->a.s[i].bytes + 1 : 8 + st->a.s[i].bytes;
    if (!st->legacy)
        total += strlen("\n  </AppendedData>\n</VTKFile>\n");
    s->size = st->z ? UINT64_MAX : total; /* compressed: known only once written */
    if (st->z) {
        s->section = st->a.n - 1; /* the arrays in XML order: from the last section */
        if (!z_prepare(st))
            return out_nomem(err);
    }
    return 0;
}

static int init(out_stream *s, bool legacy, sd_error *err)
{
    vstate *st = out_state_new(s, sizeof *st, vfree, produce);
    if (!st)
        return out_nomem(err);
    int rc = setup(s, st, legacy, err);
    return rc ? rc : build_header(s, st, err);
}

int out_vtu_init(out_stream *s, sd_error *err) { return init(s, false, err); }
int out_vtk_init(out_stream *s, sd_error *err) { return init(s, true, err); }
