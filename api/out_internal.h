/* out_internal.h — what the writers share: the stream object, its chunk buffer and the
 * precomputed geometry (solid boundary, normals, slice), colour map.
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

struct out_stream {
    out_request rq;
    out_format fmt;
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

/* Viridis colour of t in [0,1] (clamped), linear RGB in [0,1]. */
void out_viridis(double t, float rgb[3]);

/* The k-th of the 4 tetrahedra an octahedron is written as (split along its major diagonal,
 * positively oriented like the octahedron). */
void out_oct_tet(const uint32_t oct[6], int k, uint32_t tet[4]);

/* Writers: fill s->size, s->produce (and fmt_state) — 0 or an sd_result with err filled. */
int out_json_init(out_stream *s, sd_error *err);
int out_vtu_init(out_stream *s, sd_error *err);
int out_vtk_init(out_stream *s, sd_error *err);
int out_gltf_init(out_stream *s, sd_error *err);
/* Area-weighted unit vertex normals of the level's surface triangles (first ntr) and the given
 * boundary triangles; (0,0,1) where a vertex has none. NULL when out of memory. */
float *out_normals(const sd_level *lv, uint32_t ntr, const uint32_t *bnd, uint32_t nbnd);

#endif
