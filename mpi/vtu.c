/* vtu.c — subdivd-mpi's outputs: one VTU piece per rank, the .pvtu index, or one merged VTU.
 *
 * XML VTU with appended raw binary blocks (header_type UInt64, each block its byte count then
 * its bytes), the cell layout of api/out_vtk.c: vertices (1), lines (3), triangles (5),
 * tetrahedra (10), then each octahedron as its 4 tetrahedra around the major diagonal
 * (sd_octa_tet). Point data: global_id (Int64, the point's index in the one-process level),
 * owner (Int32, the lowest rank among the pieces whose cells use the point), rule (UInt8, the
 * point's sd_rule at level L, as `subdivd refine`'s VTU has it) and every attribute (Float64);
 * each of the first three is "NAME_2", ... if an attribute is called NAME. Cell data: kind (UInt8, sd_cell_kind), cell_id (Int64, the cell's index among the
 * level's cells of its kind in the one-process level; an octahedron's 4 tetrahedra share it) and
 * control_cell (Int64, the posted simplex it descends from). A file is written as PATH.part and
 * renamed at the end.
 *
 * The merged VTU (--merge) has every point of the level in one-process order and the cells in
 * the one-process order of `subdivd refine`'s VTU: rank r sends the points it is the owner of
 * and its owned cells (mp_merge_blob), rank 0 puts each at its one-process index, checking that
 * every point and cell arrives exactly once.
 */
#include "mp.h"
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

typedef struct varr {
    char name[API_MAX_ATTRIBUTE_NAME * 6 + 8]; /* XML-escaped */
    const char *type;
    int ncomp, width;
    const void *data;
} varr;

static const int VT[5] = {1, 3, 5, 10, 10};

static void xml_name(char *dst, size_t n, const char *s)
{
    size_t o = 0;
    for (; *s && o + 7 < n; s++) {
        const char *r = *s == '&' ? "&amp;" : *s == '<' ? "&lt;" : *s == '>' ? "&gt;"
                        : *s == '"' ? "&quot;" : NULL;
        if (r) {
            memcpy(dst + o, r, strlen(r));
            o += strlen(r);
        } else
            dst[o++] = *s;
    }
    dst[o] = 0;
}

/* Write one unstructured grid. conn/offs are Int64, types UInt8. */
static int vtu_file(const char *path, uint64_t npts, const double *xyz, const varr *pd, int npd,
                    uint64_t ncells, const int64_t *conn, const int64_t *offs, const uint8_t *types,
                    const varr *cd, int ncd, uint64_t *bytes, char *err, size_t errlen)
{
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.part", path);
    FILE *f = fopen(tmp, "wb");
    if (!f) {
        snprintf(err, errlen, "cannot write %s: %s", tmp, strerror(errno));
        return -1;
    }
    uint64_t nconn = ncells ? (uint64_t)offs[ncells - 1] : 0, off = 0;
    fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" "
               "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<UnstructuredGrid>\n"
               "<Piece NumberOfPoints=\"%llu\" NumberOfCells=\"%llu\">\n<PointData>\n",
            (unsigned long long)npts, (unsigned long long)ncells);
#define ELEM(type, name, nc, count)                                                                \
    do {                                                                                           \
        fprintf(f, "<DataArray type=\"%s\" Name=\"%s\" NumberOfComponents=\"%d\" "                 \
                   "format=\"appended\" offset=\"%llu\"/>\n",                                      \
                type, name, nc, (unsigned long long)off);                                          \
        off += 8 + (count);                                                                        \
    } while (0)
    for (int i = 0; i < npd; i++)
        ELEM(pd[i].type, pd[i].name, pd[i].ncomp, npts * pd[i].ncomp * pd[i].width);
    fprintf(f, "</PointData>\n<CellData>\n");
    for (int i = 0; i < ncd; i++)
        ELEM(cd[i].type, cd[i].name, cd[i].ncomp, ncells * cd[i].ncomp * cd[i].width);
    fprintf(f, "</CellData>\n<Points>\n");
    ELEM("Float64", "Points", 3, npts * 24);
    fprintf(f, "</Points>\n<Cells>\n");
    ELEM("Int64", "connectivity", 1, nconn * 8);
    ELEM("Int64", "offsets", 1, ncells * 8);
    ELEM("UInt8", "types", 1, ncells);
#undef ELEM
    fprintf(f, "</Cells>\n</Piece>\n</UnstructuredGrid>\n<AppendedData encoding=\"raw\">\n_");
    int ok = 1;
#define BLOCK(ptr, n)                                                                              \
    do {                                                                                           \
        uint64_t n_ = (n);                                                                         \
        ok &= fwrite(&n_, 8, 1, f) == 1;                                                           \
        if (n_)                                                                                    \
            ok &= fwrite((ptr), 1, (size_t)n_, f) == (size_t)n_;                                   \
    } while (0)
    for (int i = 0; i < npd; i++)
        BLOCK(pd[i].data, npts * pd[i].ncomp * pd[i].width);
    for (int i = 0; i < ncd; i++)
        BLOCK(cd[i].data, ncells * cd[i].ncomp * cd[i].width);
    BLOCK(xyz, npts * 24);
    BLOCK(conn, nconn * 8);
    BLOCK(offs, ncells * 8);
    BLOCK(types, ncells);
#undef BLOCK
    fprintf(f, "\n</AppendedData>\n</VTKFile>\n");
    long end = ftell(f);
    if (fclose(f) || !ok) {
        snprintf(err, errlen, "cannot write %s: %s", tmp, strerror(errno));
        unlink(tmp);
        return -1;
    }
    if (rename(tmp, path)) {
        snprintf(err, errlen, "cannot rename %s: %s", tmp, strerror(errno));
        unlink(tmp);
        return -1;
    }
    *bytes = (uint64_t)end;
    return 0;
}

/* Cells of `kind` as VTK cells (an octahedron: 4). */
static int vtk_cells(int kind) { return kind == SD_CELL_OCTA ? 4 : 1; }
static int vtk_size(int kind) { return kind == SD_CELL_OCTA ? 4 : sd_cell_size((sd_cell_kind)kind); }

/* `base`, or "base_2", "base_3", ... when an attribute is called that: as api/out_vtk.c names
 * its rule array, so an attribute keeps its name and no two point arrays share one (VTK's
 * readers and meshio keep one array of a name: an attribute called "global_id" hid the ids). */
static void unclashed(const mp_piece *p, char *name, size_t n, const char *base)
{
    snprintf(name, n, "%s", base);
    for (int suffix = 2, clash = 1; clash; suffix++) {
        clash = 0;
        for (int a = 0; a < p->nattrs && !clash; a++)
            clash = !strcmp(p->attrs[a].name, name);
        if (clash)
            snprintf(name, n, "%s_%d", base, suffix);
    }
}

/* The point data arrays: global_id, owner, rule, the attributes (by name); the first three
 * named by unclashed(). */
static int point_arrays(const mp_piece *p, varr *pd, const int64_t *gid, const int32_t *own,
                        const uint8_t *rule, double *const *attr)
{
    int n = 0;
    pd[n] = (varr){"", "Int64", 1, 8, gid};
    unclashed(p, pd[n++].name, sizeof pd->name, "global_id");
    pd[n] = (varr){"", "Int32", 1, 4, own};
    unclashed(p, pd[n++].name, sizeof pd->name, "owner");
    pd[n] = (varr){"", "UInt8", 1, 1, rule};
    unclashed(p, pd[n++].name, sizeof pd->name, "rule");
    for (int a = 0; a < p->nattrs; a++) {
        pd[n] = (varr){"", "Float64", p->attrs[a].ncomp, 8, attr ? attr[a] : NULL};
        xml_name(pd[n].name, sizeof pd[n].name, p->attrs[a].name);
        n++;
    }
    return n;
}

/* The vertex rules of level L, which the "rule" array gives (as `subdivd refine`'s VTU): made
 * when written, so that --no-write does not time them. 0, or -1 with a message in err. */
static int prepare_rules(const mp_result *r, char *err, size_t errlen)
{
    sd_error e = {0};
    if (r->lv && sd_complex_prepare_vertex_rules(r->m->c, r->p->level, &e)) {
        snprintf(err, errlen, "the rules of level %d: %s", r->p->level, e.message);
        return -1;
    }
    return 0;
}

int mp_write_piece(const mp_piece *p, const mp_result *r, const char *path, uint64_t *bytes,
                   char *err, size_t errlen)
{
    if (prepare_rules(r, err, errlen))
        return -1;
    uint32_t nv = r->lv ? sd_level_num_vertices(r->lv) : 0;
    uint32_t *slot = malloc(((size_t)nv + 1) * sizeof *slot);
    if (!slot) {
        snprintf(err, errlen, "out of memory writing %s", path);
        return -1;
    }
    for (uint32_t v = 0; v < nv; v++)
        slot[v] = UINT32_MAX;
    uint64_t npts = 0, ncells = 0, nconn = 0;
    for (int k = 0; k < 5; k++)
        for (uint32_t i = 0; i < r->ncell[k]; i++)
            if (mp_cown(r, k, i)) {
                uint32_t v[6];
                sd_level_cell(r->lv, (sd_cell_kind)k, i, v);
                for (int j = 0; j < sd_cell_size((sd_cell_kind)k); j++)
                    slot[v[j]] = 0;
                ncells += (uint64_t)vtk_cells(k);
                nconn += (uint64_t)vtk_cells(k) * (uint64_t)vtk_size(k);
            }
    for (uint32_t v = 0; v < nv; v++) /* the piece's points in its level's order */
        if (slot[v] != UINT32_MAX)
            slot[v] = (uint32_t)npts++;
    int na = p->nattrs;
    double *xyz = malloc((size_t)npts * 24 + 8);
    int64_t *gid = malloc((size_t)npts * 8 + 8);
    int32_t *own = malloc((size_t)npts * 4 + 8);
    uint8_t *rule = malloc((size_t)npts + 8);
    int64_t *conn = malloc((size_t)nconn * 8 + 8), *offs = malloc((size_t)ncells * 8 + 8);
    int64_t *cid = malloc((size_t)ncells * 8 + 8), *ctrl = malloc((size_t)ncells * 8 + 8);
    uint8_t *types = malloc((size_t)ncells + 8), *kinds = malloc((size_t)ncells + 8);
    double *attr[API_MAX_ATTRIBUTES] = {0};
    int ok = xyz && gid && own && rule && conn && offs && cid && ctrl && types && kinds;
    for (int a = 0; a < na && ok; a++)
        ok = (attr[a] = malloc((size_t)npts * (size_t)p->attrs[a].ncomp * 8 + 8)) != NULL;
    int rc = -1;
    if (!ok) {
        snprintf(err, errlen, "out of memory writing %s", path);
        goto out;
    }
    int nc3;
    const double *pos = r->lv ? sd_level_channel(r->lv, 0, &nc3) : NULL;
    for (uint32_t v = 0; v < nv; v++)
        if (slot[v] != UINT32_MAX) {
            uint32_t s = slot[v];
            memcpy(xyz + 3 * (size_t)s, pos + 3 * (size_t)v, 24);
            gid[s] = (int64_t)mp_vgid(r, v);
            own[s] = r->vowner[v];
            rule[s] = (uint8_t)sd_level_vertex_rule(r->lv, v);
            for (int a = 0; a < na; a++) {
                int nc;
                const double *d = sd_level_channel(r->lv, r->m->channel[a], &nc);
                memcpy(attr[a] + (size_t)s * nc, d + (size_t)v * nc, (size_t)nc * 8);
            }
        }
    uint64_t c = 0, o = 0;
    for (int k = 0; k < 5; k++)
        for (uint32_t i = 0; i < r->ncell[k]; i++) {
            if (!mp_cown(r, k, i))
                continue;
            uint32_t v[6];
            sd_level_cell(r->lv, (sd_cell_kind)k, i, v);
            for (int q = 0; q < vtk_cells(k); q++) {
                uint32_t tv[4];
                const uint32_t *w = v;
                if (k == SD_CELL_OCTA) {
                    sd_octa_tet(v, q, tv);
                    w = tv;
                }
                for (int j = 0; j < vtk_size(k); j++)
                    conn[o++] = slot[w[j]];
                offs[c] = (int64_t)o;
                types[c] = (uint8_t)VT[k];
                kinds[c] = (uint8_t)k;
                cid[c] = (int64_t)mp_cgid(r, k, i);
                ctrl[c] = (int64_t)r->p->sg[mp_csrc(r, k, i)];
                c++;
            }
        }
    varr pd[3 + API_MAX_ATTRIBUTES], cd[3] = {{"kind", "UInt8", 1, 1, kinds},
                                                 {"cell_id", "Int64", 1, 8, cid},
                                                 {"control_cell", "Int64", 1, 8, ctrl}};
    int npd = point_arrays(p, pd, gid, own, rule, attr);
    rc = vtu_file(path, npts, xyz, pd, npd, ncells, conn, offs, types, cd, 3, bytes, err, errlen);
out:
    free(slot);
    free(xyz);
    free(gid);
    free(own);
    free(rule);
    free(conn);
    free(offs);
    free(cid);
    free(ctrl);
    free(types);
    free(kinds);
    for (int a = 0; a < na; a++)
        free(attr[a]);
    return rc;
}

int mp_write_pvtu(const char *path, const mp_piece *p, int nparts, char **piece_names, char *err,
                  size_t errlen)
{
    char tmp[4096];
    snprintf(tmp, sizeof tmp, "%s.part", path);
    FILE *f = fopen(tmp, "wb");
    if (!f) {
        snprintf(err, errlen, "cannot write %s: %s", tmp, strerror(errno));
        return -1;
    }
    fprintf(f, "<?xml version=\"1.0\"?>\n<VTKFile type=\"PUnstructuredGrid\" version=\"1.0\" "
               "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
               "<PUnstructuredGrid GhostLevel=\"0\">\n<PPointData>\n");
    varr pd[3 + API_MAX_ATTRIBUTES];
    int npd = point_arrays(p, pd, NULL, NULL, NULL, NULL);
    for (int i = 0; i < npd; i++)
        fprintf(f, "<PDataArray type=\"%s\" Name=\"%s\" NumberOfComponents=\"%d\"/>\n", pd[i].type,
                pd[i].name, pd[i].ncomp);
    fprintf(f, "</PPointData>\n<PCellData>\n"
               "<PDataArray type=\"UInt8\" Name=\"kind\" NumberOfComponents=\"1\"/>\n"
               "<PDataArray type=\"Int64\" Name=\"cell_id\" NumberOfComponents=\"1\"/>\n"
               "<PDataArray type=\"Int64\" Name=\"control_cell\" NumberOfComponents=\"1\"/>\n"
               "</PCellData>\n<PPoints>\n"
               "<PDataArray type=\"Float64\" NumberOfComponents=\"3\"/>\n</PPoints>\n");
    for (int r = 0; r < nparts; r++) {
        char name[4096];
        xml_name(name, sizeof name, piece_names[r]);
        fprintf(f, "<Piece Source=\"%s\"/>\n", name);
    }
    fprintf(f, "</PUnstructuredGrid>\n</VTKFile>\n");
    if (fclose(f) || rename(tmp, path)) {
        snprintf(err, errlen, "cannot write %s: %s", path, strerror(errno));
        unlink(tmp);
        return -1;
    }
    return 0;
}

/* ---- merged output -------------------------------------------------------------------------
 * Blob: [npoints u64] then per point gid u64, xyz 3 f64, rule u8, the attributes' values; then per kind
 * [ncells u64] and per cell gid u64, control cell u64, the vertices' gids u64 each. */

void mp_merge_blob(const mp_piece *p, const mp_result *r, mp_buf *b)
{
    char why[256];
    if (prepare_rules(r, why, sizeof why)) {
        b->failed = 1;
        return;
    }
    uint32_t nv = r->lv ? sd_level_num_vertices(r->lv) : 0;
    uint8_t *used = calloc((size_t)nv + 1, 1);
    if (!used) {
        b->failed = 1;
        return;
    }
    for (int k = 0; k < 5; k++)
        for (uint32_t i = 0; i < r->ncell[k]; i++)
            if (mp_cown(r, k, i)) {
                uint32_t v[6];
                sd_level_cell(r->lv, (sd_cell_kind)k, i, v);
                for (int j = 0; j < sd_cell_size((sd_cell_kind)k); j++)
                    used[v[j]] = 1;
            }
    /* a point no cell of the piece uses descends from a posted vertex of no simplex: the piece
     * holding those (part.c) sends them */
    for (uint32_t v = 0; v < nv; v++)
        used[v] |= r->vowner[v] == INT32_MAX;
    uint64_t n = 0;
    for (uint32_t v = 0; v < nv; v++)
        n += used[v] && (r->vowner[v] == p->rank || r->vowner[v] == INT32_MAX);
    mp_buf_put(b, &n, 8);
    int nc3;
    const double *pos = r->lv ? sd_level_channel(r->lv, 0, &nc3) : NULL;
    for (uint32_t v = 0; v < nv; v++)
        if (used[v] && (r->vowner[v] == p->rank || r->vowner[v] == INT32_MAX)) {
            uint64_t gv = mp_vgid(r, v);
            uint8_t rule = (uint8_t)sd_level_vertex_rule(r->lv, v);
            mp_buf_put(b, &gv, 8);
            mp_buf_put(b, pos + 3 * (size_t)v, 24);
            mp_buf_put(b, &rule, 1);
            for (int a = 0; a < p->nattrs; a++) {
                int nc;
                const double *d = sd_level_channel(r->lv, r->m->channel[a], &nc);
                mp_buf_put(b, d + (size_t)v * nc, (size_t)nc * 8);
            }
        }
    free(used);
    for (int k = 0; k < 5; k++) {
        uint64_t nc = 0;
        for (uint32_t i = 0; i < r->ncell[k]; i++)
            nc += mp_cown(r, k, i);
        mp_buf_put(b, &nc, 8);
        for (uint32_t i = 0; i < r->ncell[k]; i++)
            if (mp_cown(r, k, i)) {
                uint32_t v[6];
                uint64_t ctrl = r->p->sg[mp_csrc(r, k, i)], cg = mp_cgid(r, k, i);
                sd_level_cell(r->lv, (sd_cell_kind)k, i, v);
                mp_buf_put(b, &cg, 8);
                mp_buf_put(b, &ctrl, 8);
                for (int j = 0; j < sd_cell_size((sd_cell_kind)k); j++)
                    {
                    uint64_t gw = mp_vgid(r, v[j]);
                    mp_buf_put(b, &gw, 8);
                }
            }
    }
}

int mp_merge_write(const char *path, const mp_piece *p0, const unsigned char *const *blobs,
                   const size_t *lens, int n, uint64_t *bytes, char *err, size_t errlen)
{
    const sd_counts *G = &p0->global[p0->level];
    uint64_t npts = G->vertices, nk[5] = {G->points, G->curves, G->triangles, G->tetrahedra,
                                          G->octahedra};
    int na = p0->nattrs, rc = -1;
    if (npts > UINT32_MAX) {
        snprintf(err, errlen, "%llu points are too many to merge into one VTU; write pieces (.pvtu)",
                 (unsigned long long)npts);
        return -1;
    }
    uint64_t ncells = 0, nconn = 0;
    for (int k = 0; k < 5; k++) {
        ncells += nk[k] * (uint64_t)vtk_cells(k);
        nconn += nk[k] * (uint64_t)vtk_cells(k) * (uint64_t)vtk_size(k);
    }
    double *xyz = malloc((size_t)npts * 24 + 8);
    int64_t *gid = malloc((size_t)npts * 8 + 8);
    int32_t *own = malloc((size_t)npts * 4 + 8);
    uint8_t *rule = malloc((size_t)npts + 8);
    uint8_t *seen = calloc((size_t)npts + 1, 1);
    int64_t *conn = malloc((size_t)nconn * 8 + 8), *offs = malloc((size_t)ncells * 8 + 8);
    int64_t *cid = malloc((size_t)ncells * 8 + 8), *ctrl = malloc((size_t)ncells * 8 + 8);
    uint8_t *types = malloc((size_t)ncells + 8), *kinds = malloc((size_t)ncells + 8);
    uint8_t *cseen = calloc((size_t)ncells + 1, 1);
    double *attr[API_MAX_ATTRIBUTES] = {0};
    int ok = xyz && gid && own && rule && seen && conn && offs && cid && ctrl && types && kinds && cseen;
    for (int a = 0; a < na && ok; a++)
        ok = (attr[a] = malloc((size_t)npts * (size_t)p0->attrs[a].ncomp * 8 + 8)) != NULL;
    if (!ok) {
        snprintf(err, errlen, "out of memory merging %llu points", (unsigned long long)npts);
        goto out;
    }
    uint64_t first[5], o = 0; /* first VTK cell of each kind */
    for (int k = 0; k < 5; k++) {
        first[k] = o;
        o += nk[k] * (uint64_t)vtk_cells(k);
    }
    for (int r = 0; r < n; r++) {
        const unsigned char *d = blobs[r], *end = d + lens[r];
#define TAKE(dst, nb)                                                                              \
    do {                                                                                           \
        if ((size_t)(end - d) < (size_t)(nb))                                                      \
            goto short_blob;                                                                       \
        memcpy((dst), d, (nb));                                                                    \
        d += (nb);                                                                                 \
    } while (0)
        uint64_t np;
        TAKE(&np, 8);
        for (uint64_t i = 0; i < np; i++) {
            uint64_t g;
            TAKE(&g, 8);
            if (g >= npts || seen[g]++) {
                snprintf(err, errlen, "rank %d sent point %llu %s", r, (unsigned long long)g,
                         g >= npts ? "beyond the level" : "that another rank sent");
                goto out;
            }
            TAKE(xyz + 3 * g, 24);
            TAKE(rule + g, 1);
            gid[g] = (int64_t)g;
            own[g] = r;
            for (int a = 0; a < na; a++) {
                int nc = p0->attrs[a].ncomp;
                TAKE(attr[a] + g * (uint64_t)nc, (size_t)nc * 8);
            }
        }
        for (int k = 0; k < 5; k++) {
            uint64_t nc;
            TAKE(&nc, 8);
            int sz = sd_cell_size((sd_cell_kind)k);
            for (uint64_t i = 0; i < nc; i++) {
                uint64_t g, cc, vg[6];
                TAKE(&g, 8);
                TAKE(&cc, 8);
                TAKE(vg, (size_t)sz * 8);
                if (g >= nk[k] || cseen[first[k] + g * (uint64_t)vtk_cells(k)]++) {
                    snprintf(err, errlen, "rank %d sent cell %llu of kind %d %s", r,
                             (unsigned long long)g, k,
                             g >= nk[k] ? "beyond the level" : "that another rank sent");
                    goto out;
                }
                uint32_t v[6];
                for (int j = 0; j < sz; j++)
                    v[j] = (uint32_t)vg[j];
                for (int q = 0; q < vtk_cells(k); q++) {
                    uint64_t c = first[k] + g * (uint64_t)vtk_cells(k) + (uint64_t)q;
                    uint32_t tv[4];
                    const uint32_t *w = v;
                    if (k == SD_CELL_OCTA) {
                        sd_octa_tet(v, q, tv);
                        w = tv;
                    }
                    /* offsets are those of a layout in order; fill connectivity at its place */
                    uint64_t at = 0;
                    for (int kk = 0; kk < k; kk++)
                        at += nk[kk] * (uint64_t)vtk_cells(kk) * (uint64_t)vtk_size(kk);
                    at += (c - first[k]) * (uint64_t)vtk_size(k);
                    for (int j = 0; j < vtk_size(k); j++)
                        conn[at + j] = (int64_t)w[j];
                    types[c] = (uint8_t)VT[k];
                    kinds[c] = (uint8_t)k;
                    cid[c] = (int64_t)g;
                    ctrl[c] = (int64_t)cc;
                }
            }
        }
        if (d != end)
            goto short_blob;
#undef TAKE
    }
    for (uint64_t g = 0; g < npts; g++)
        if (!seen[g]) {
            snprintf(err, errlen, "no rank sent point %llu of the level", (unsigned long long)g);
            goto out;
        }
    o = 0;
    for (int k = 0; k < 5; k++)
        for (uint64_t i = 0; i < nk[k]; i++) {
            if (!cseen[first[k] + i * (uint64_t)vtk_cells(k)]) {
                snprintf(err, errlen, "no rank sent cell %llu of kind %d", (unsigned long long)i, k);
                goto out;
            }
            for (int q = 0; q < vtk_cells(k); q++) {
                o += (uint64_t)vtk_size(k);
                offs[first[k] + i * (uint64_t)vtk_cells(k) + (uint64_t)q] = (int64_t)o;
            }
        }
    varr pd[3 + API_MAX_ATTRIBUTES], cd[3] = {{"kind", "UInt8", 1, 1, kinds},
                                                 {"cell_id", "Int64", 1, 8, cid},
                                                 {"control_cell", "Int64", 1, 8, ctrl}};
    int npd = point_arrays(p0, pd, gid, own, rule, attr);
    rc = vtu_file(path, npts, xyz, pd, npd, ncells, conn, offs, types, cd, 3, bytes, err, errlen);
    goto out;
short_blob:
    snprintf(err, errlen, "a rank's merge data are cut short");
out:
    free(xyz);
    free(gid);
    free(own);
    free(rule);
    free(seen);
    free(conn);
    free(offs);
    free(cid);
    free(ctrl);
    free(types);
    free(kinds);
    free(cseen);
    for (int a = 0; a < na; a++)
        free(attr[a]);
    return rc;
}
