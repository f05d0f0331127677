/* out.h — streaming writers of one subdivided level: GLB / glTF, VTU / legacy VTK, JSON.
 *
 * A writer is a pull stream: out_open() validates the request and does every precomputation
 * (counts, sizes, bounding boxes, normals) so that errors surface before the first byte; then
 * out_read() fills the caller's buffer chunk by chunk, producing the bytes as it goes (never a
 * whole copy of the output in memory). The daemon hands out_read to libmicrohttpd's callback
 * response; the offline `subdivd refine` mode loops it into a file. Same bytes either way.
 *
 * The stream borrows the level (and its arrays) from the complex: the caller keeps the complex
 * alive and does not change that level until out_close(). Computing further levels of the same
 * complex is allowed meanwhile (it never touches the lower levels' arrays the writers read).
 */
#ifndef SUBDIVD_OUT_H
#define SUBDIVD_OUT_H

#include "../core/sd.h"
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct out_stream out_stream;

/* One output format of a level: a row of the table in api/formats.c, which everything that
 * names a format reads — the `format=` query, Content-Type, Content-Disposition, the offline
 * mode's choice by file extension, the stats' sizes and `subdivd --list-formats`. */
typedef struct out_format {
    const char *name;        /* "glb": the value of format= */
    const char *mime;        /* the Content-Type of the stream */
    const char *extension;   /* ".glb": download names and `subdivd refine -o` */
    const char *disposition; /* "inline" (viewers open it) or "attachment" (saved) */
    bool geometry;           /* reads out_request.geometry (the per-level solid boundary, normals) */
    int (*init)(out_stream *s, sd_error *err); /* the writer (out_internal.h) */
} out_format;

/* The formats, in table order, ended by a row whose name is NULL. */
extern const out_format out_formats[];
/* The format called `name`, or NULL. */
const out_format *out_format_find(const char *name);
/* The format whose extension ends `path` ("level.vtu" -> vtu), or NULL. */
const out_format *out_format_for_path(const char *path);
/* The formats' names (or extensions) as one list, e.g. "glb, gltf, vtu, vtk or json":
 * `sep` between names, `last` before the last one. Returns buf. */
char *out_format_list(char *buf, size_t cap, bool extensions, const char *sep, const char *last);

enum {
    OUT_PART_POINTS = 1,
    OUT_PART_CURVES = 2,
    OUT_PART_SURFACES = 4,
    OUT_PART_SOLIDS = 8,
    OUT_PART_ALL = 15,       /* the level's parts; 0 in out_request.parts means these */
    OUT_PART_EMBEDDED = 16   /* glTF: also out_request.meshes (not part of OUT_PART_ALL) */
};

/* An extra mesh a glTF writes after the level's parts when parts has OUT_PART_EMBEDDED: an
 * embedded model, deformed (api/embedded.c). out_open copies it; it is not a level's. */
#define OUT_MAX_MESHES 8
typedef struct out_mesh {
    const char *name;        /* node and mesh "embedded/<name>": letters, digits, '_', '-' */
    uint32_t nv, nt;         /* vertices; triangles (none: the vertices are drawn as points) */
    const double *xyz;       /* 3 per vertex */
    const uint32_t *tri;     /* 3 per triangle, vertex ids < nv */
} out_mesh;

#define OUT_MAX_ATTRS 32

enum { OUT_COMPRESS_NONE = 0, OUT_COMPRESS_ZLIB = 1 };

/* One per-vertex attribute to write: a channel of the complex. */
typedef struct out_attr {
    const char *name;   /* as posted, e.g. "temperature" (glTF writes "_TEMPERATURE") */
    int channel;        /* sd channel id (>= 1) */
    int ncomp;          /* components per vertex (1..16) */
} out_attr;

typedef struct out_request {
    sd_complex *complex;     /* the level is computed already; the writer may ensure its rules */
    int level;
    uint64_t version;        /* written into JSON output ("version") and glTF asset.extras */
    unsigned parts;          /* OUT_PART_* mask; 0 means OUT_PART_ALL; OUT_PART_EMBEDDED alone:
                              * none of the level's parts, only the meshes */
    int nmeshes;             /* with OUT_PART_EMBEDDED (glb and gltf only): these meshes too */
    const out_mesh *meshes;
    int has_slice;           /* cross-section of the solids by the plane n.x = d */
    double slice[4];         /* nx, ny, nz, d (n need not be unit; must be non-zero) */
    int nattrs;
    out_attr attrs[OUT_MAX_ATTRS];
    int colormap_attr;       /* index into attrs of the attribute coloured into COLOR_0, or -1 */
    double colormap_min, colormap_max;
    int octahedra_as_polyhedra; /* VTU/VTK: octahedra as VTK_POLYHEDRON (42) instead of 4 tets */
    int field_names;         /* VTU/VTK: FieldData string arrays rule_names and kind_names */
    int compress;            /* VTU: OUT_COMPRESS_ZLIB (vtkZLibDataCompressor blocks), else raw */
    /* Optional: geometry computed earlier for this level with all parts (see
     * out_geometry_compute), so that a cached level streams without recomputing it. The stream
     * takes a reference on it. */
    struct out_geometry *geometry;
    /* Copy the positions and the requested attribute channels at out_open: the stream then
     * reads no array that an edit changes in place (channel values), only the level's topology
     * and rules, and its content is that of the moment it opened. */
    bool snapshot;
    /* Every point at its limit position (sd_complex_limit: the limit level is computed already),
     * and glTF normals from the limit tangents (the area-weighted normal where a point has no
     * tangent plane); geometry must then be NULL (its normals are the level's). */
    bool limit;
} out_request;

/* The solid boundary and vertex normals of a level with every part shown — what glTF needs
 * before its first byte. Computing it once per level and passing it in out_request.geometry
 * makes later glTF responses of that level stream at once. */
typedef struct out_geometry {
    atomic_int refs;    /* the model's cache and every stream reading it */
    uint32_t nbnd;
    uint32_t *bnd;      /* 3 per boundary triangle, outward */
    float *normals;     /* 3 per vertex */
    size_t bytes;
} out_geometry;
/* A new geometry (one reference) or NULL; out_geometry_ref adds a reference, out_geometry_free
 * drops one and frees it with the last. */
out_geometry *out_geometry_compute(const sd_level *lv);
out_geometry *out_geometry_ref(out_geometry *g);
/* A copy of g (nv: its level's vertex count), one reference, for a writer that must not change
 * what a stream reads (api/delta.c); NULL without memory. */
out_geometry *out_geometry_copy(const out_geometry *g, uint32_t nv);
void out_geometry_free(out_geometry *g);

/* Validate and prepare (with rq->snapshot, copy what edits change: see out_request). The stream
 * borrows nothing of rq but the complex. Returns NULL and fills err (code SD_ERR_ARG for a bad request, message
 * naming the offending option) on failure. */
out_stream *out_open(const out_request *rq, const out_format *f, sd_error *err);
/* Total size in bytes if known in advance (GLB, glTF, VTU, VTK), else UINT64_MAX (JSON,
 * compressed VTU). */
uint64_t out_size(const out_stream *s);
/* Fill up to `cap` bytes of buf; returns the number written (> 0), 0 at the end, -1 on an
 * internal failure (the stream can only be cut short then). */
ssize_t out_read(out_stream *s, char *buf, size_t cap);
void out_close(out_stream *s);

/* The subdivision matrix mapping level `from` points to level `to` points (the product of the
 * cached S_l; level `to` computed already), streamed as Matrix Market (1-based coordinate) or as
 * JSON CSR {"from","to","rows","cols","nnz","rowptr","col","val"}. Refuses (SD_ERR_LIMIT) a
 * product with more than max_nnz entries. Close with out_close. */
out_stream *out_matrix_open(sd_complex *c, int from, int to, bool json, uint64_t max_nnz,
                            sd_error *err);

#ifdef __cplusplus
}
#endif
#endif
