/* out_internal.h — what the writers share: the stream object and its chunk buffer, the section
 * list every writer describes its output with, and the geometry of api/geom.c (solid boundary,
 * normals, the slice, octahedra as tetrahedra).
 *
 * Every writer is a generator: `produce` appends the next piece of output (a bounded number of
 * items, so the buffer stays small) to the stream's buffer and returns 1 while there is more.
 * out_read copies from the buffer and calls produce again when it runs dry.
 */
#ifndef SUBDIVD_OUT_INTERNAL_H
#define SUBDIVD_OUT_INTERNAL_H

#include "out.h"
#include <stdbool.h>

#define OUT_CHUNK_ITEMS 4096          /* items produced per step */
#define OUT_BUF_CAP (1u << 20)        /* bytes: enough for one step of any section */

/* The cross-section of the solids: independent triangles (3 points each) and, per triangle,
 * the index of the cut cell and its kind. Point data are interpolated along the cut edges. */
typedef struct out_slice {
    uint32_t ntri;
    double *xyz;           /* 9 per triangle */
    double *attr[OUT_MAX_ATTRS]; /* 3 * ncomp per triangle, per requested attribute */
    uint32_t *cell;        /* source cell per triangle */
    uint8_t *kind;         /* SD_CELL_TETRA or SD_CELL_OCTA */
} out_slice;

/* One run of a writer's output: `count` items of one kind (a glTF accessor, a VTK data array, a
 * JSON member), produced item by item. Writers fill the fields they use. */
typedef struct out_section {
    int id;                /* the writer's kind of section */
    int arg;               /* an attribute index or a cell kind */
    int ncomp;             /* components per item */
    int width;             /* bytes per component of binary data */
    uint64_t count;        /* items */
    uint64_t bytes;        /* binary data bytes: count * ncomp * width unless the writer says */
    uint64_t offset;       /* glTF: where the data starts in the buffer */
    char head[192];        /* text before the items (JSON's opening, legacy VTK's keyword lines) */
    const char *tail;      /* text after the items (JSON) */
} out_section;

#define OUT_MAX_SECTIONS (16 + 2 * OUT_MAX_ATTRS + 2 * OUT_MAX_MESHES)

/* A writer's sections in output order. */
typedef struct out_sections {
    int n;
    out_section s[OUT_MAX_SECTIONS];
} out_sections;

/* Append a section (zeroed, then the given fields; bytes = count * ncomp * width). */
out_section *out_section_add(out_sections *l, int id, int arg, int ncomp, int width,
                             uint64_t count);

struct out_stream {
    out_request rq;
    const out_format *fmt;
    const sd_level *lv;
    uint32_t nv;
    const double *xyz;
    const double *attr[OUT_MAX_ATTRS];
    uint32_t ncells[5];        /* per sd_cell_kind, after the parts filter */
    uint32_t nbnd;             /* solid boundary triangles */
    const uint32_t *bnd;       /* 3 per triangle (owned unless borrowed from rq.geometry) */
    const float *normals;      /* glTF: 3 per vertex (idem) */
    uint32_t *own_bnd;
    float *own_normals;
    double *own_xyz;           /* the snapshot (rq.snapshot) */
    double *own_attr[OUT_MAX_ATTRS];
    out_mesh mesh[OUT_MAX_MESHES]; /* copies of rq.meshes (their arrays and names owned) */
    int nmesh;
    out_slice slice;
    uint64_t size;             /* total bytes, or UINT64_MAX */
    /* generator */
    char *buf;
    size_t len, pos;
    int section;
    uint64_t item;
    bool done;
    int (*produce)(out_stream *s);
    void *fmt_state;           /* writer-specific */
    void (*fmt_free)(void *);
};

/* Buffer helpers (the buffer never overflows: writers produce at most OUT_CHUNK_ITEMS items of
 * bounded size per step). */
void out_put(out_stream *s, const void *p, size_t n);
void out_printf(out_stream *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* A writer's zeroed state of `size` bytes, installed as s->fmt_state with the function that frees
 * it (on out_close) and the generator; NULL when out of memory. */
void *out_state_new(out_stream *s, size_t size, void (*free_state)(void *), int (*produce)(out_stream *));

/* Fill err with SD_ERR_NOMEM, "out of memory"; returns SD_ERR_NOMEM. */
int out_nomem(sd_error *err);

/* Viridis colour of t in [0,1] (clamped): matplotlib's sRGB colour converted to linear RGB in
 * [0,1] (what glTF's COLOR_0 holds). */
void out_viridis(double t, float rgb[3]);

/* ---- geometry (api/geom.c) ---- */

/* Area-weighted unit vertex normals of the level's surface triangles (first ntr) and the given
 * boundary triangles; (0,0,1) where a vertex has none. NULL when out of memory. */
float *out_normals(const sd_level *lv, uint32_t ntr, const uint32_t *bnd, uint32_t nbnd);
/* What triangle t (3 ids into the 3-per-vertex positions x) adds to the normal of each of its
 * vertices: the cross product of its edges from t[0], as floats. */
void out_triangle_normal(const double *x, const uint32_t t[3], float n[3]);
/* A vertex's sum of out_triangle_normal made unit in place; (0,0,1) for a zero or degenerate
 * sum. out_normals is these two, summed in its triangle order. */
void out_normal_unit(float f[3]);
/* s->bnd, s->nbnd: the outward boundary of the shown solids, and with every part shown
 * s->normals, borrowed from rq.geometry when given; else the boundary is computed into
 * s->own_bnd (the normals are left to the writer). false: out of memory. */
bool out_solid_boundary(out_stream *s);
/* The plane p = (nx, ny, nz, d), n·x = d with n finite and not zero, as unit n and d: n is
 * first scaled by the power of 2 nearest below its largest |component| (exact), so that no
 * square over- or underflows, whatever the magnitude (1e200,0,0,0.5e200 is x = 0.5); for an n
 * whose squares do not over- or underflow the result is bit for bit that of n/|n|, d/|n|. */
void out_slice_plane(const double p[4], double n[3], double *d);
/* s->slice: the cross-section of the shown solids by rq.slice. false: out of memory. */
bool out_compute_slice(out_stream *s);
/* Free what out_compute_slice allocated. */
void out_slice_free(out_slice *sl);

/* ---- the writers (one file each), listed in api/formats.c ---- */

/* Fill s->size, s->produce (and fmt_state) — 0 or an sd_result with err filled. */
int out_glb_init(out_stream *s, sd_error *err);
int out_gltf_init(out_stream *s, sd_error *err);
int out_vtu_init(out_stream *s, sd_error *err);
int out_vtk_init(out_stream *s, sd_error *err);
int out_json_init(out_stream *s, sd_error *err);

#endif
