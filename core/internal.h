/* internal.h — data structures shared by the core's files (not part of the public API).
 *
 * A level is flat arrays (struct-of-arrays, uint32_t ids). Every level keeps its unique edges and
 * triangles (faces) with, for each cell, the ids of its edges and faces. That lets the split
 * (split.c) number the next level's edges and faces directly from the parent's — no hashing after
 * level 0 — and lets classification be inherited entity by entity (classify.c).
 *
 * The core in layers, in OpenSubdiv's shape: a level's topology (topo.c: its parts and incidence
 * relations; split.c: the next level's; classify.c: level 0's classes) — Vtr; the rules (rules.c
 * chooses, rings.c finds the neighbours, petals.c walks petals, masks.c weighs, yz.c the
 * Ying-Zorin rows) — Sdc; the stencils they make (stencil.c assembles S_l, csr.c stores and
 * applies it) — Far. Above them the complex and its levels (complex.c, levels.c), its tags and
 * rules (singular.c, overrides.c), edits and their detail offsets, analysis and refinement
 * (edit.c, details.c, analysis.c, refine.c, carry.c). Calls go down the layers; a level's lifecycle is levels.c's, the complex's complex.c's.
 * sd_complex_memory counts every allocation, these structures included: growing sd_level or
 * sd_complex changes the memory the daemon reports (the golden stats compare it).
 *
 * Local numbering (used everywhere):
 *   tetrahedron t[0..3]: edges SDI_TET_E, face i opposite vertex i (SDI_TET_F, outward for
 *     positive volume); diagonal pair k = (edge k, edge 5-k).
 *   octahedron o[0..5] = p, q, a, a2, b, b2 (three opposite pairs, the major diagonal p-q first);
 *     equator cycle a, b, a2, b2; edges SDI_OCT_E; faces SDI_OCT_F (outward for positive
 *     orientation).
 *   face f: fv[f][0..2], fe[f][j] = edge (fv[j], fv[j+1]).
 *
 * Names: functions shared between the core's files are sdi_* (constant tables SDI_*), file-local
 * ones static; only sd.h's sd_* functions are the library's API (tests/python/test_exports.py
 * checks the global symbols of libsubdiv.a). The internal types keep the sd_ prefix of the
 * structures they describe (sd_topo, sd_mem, ...); none of them is in sd.h.
 */
#ifndef SD_INTERNAL_H
#define SD_INTERNAL_H

#include "sd.h"
#include <stdbool.h>

extern const uint8_t SDI_TET_E[6][2];
extern const uint8_t SDI_TET_F[4][3];
extern const uint8_t SDI_OCT_E[12][2];
extern const uint8_t SDI_OCT_F[8][3];

/* ---- memory (alloc.c) ------------------------------------------------------------------- */
typedef struct sd_mem {
    sd_allocator a;
    size_t used, limit;
    bool failed_limit;
} sd_mem;

void sdi_mem_init(sd_mem *m, const sd_allocator *a, size_t limit);
void *sdi_alloc(sd_mem *m, size_t n);                 /* NULL on failure or over the limit */
void *sdi_calloc(sd_mem *m, size_t n, size_t size);   /* zeroed, overflow-checked */
void *sdi_realloc(sd_mem *m, void *p, size_t n);
void sdi_free(sd_mem *m, void *p);

/* ---- parallel regions (par.c) ------------------------------------------------------------ */
#define SD_PAR_MIN 65536   /* items of work below which a region runs serially */
#define SD_PAR_MIN_POOL 16384 /* the same within sdi_pool_begin / end (no threads to create) */
#define SD_PAR_MAXT 64     /* parts at most */
typedef void (*sd_part_fn)(void *arg, uint32_t part, uint32_t nparts);
/* How many parts a region of `work` items is split into with `threads` threads (1 = serial). */
uint32_t sdi_par_parts(int threads, uint64_t work);
/* fn(arg, i, n) for every part i of n, taken in turn by the calling thread and the region's
 * threads (a part's outputs must not depend on which thread runs it). */
void sdi_par(int threads, uint64_t work, sd_part_fn fn, void *arg);
/* fn(arg, c, n) for every chunk c of n = per_thread times the parts of sdi_par, the threads
 * taking chunks in turn; fn(arg, 0, 1) if serial. Only for fn whose results do not depend on
 * the cut (each item's outputs are its own). */
void sdi_par_dyn(int threads, uint64_t work, uint32_t per_thread, sd_part_fn fn, void *arg);
/* Brackets a run of regions (one sd_complex_level call): their helper threads are started once
 * by the outermost begin and joined by its end; nests; a no-op with threads <= 1. */
void sdi_pool_begin(int threads);
void sdi_pool_end(void);
/* Part `part` of nparts of [0, n): [*lo, *hi). */
void sdi_range(uint64_t n, uint32_t part, uint32_t nparts, uint64_t *lo, uint64_t *hi);

/* ---- errors (error.c) ------------------------------------------------------------------- */
sd_result sdi_fail(sd_error *err, sd_result code, long item, int field, const char *fmt, ...)
    __attribute__((format(printf, 5, 6)));
sd_result sdi_fail_nomem(sd_error *err, const sd_mem *m);

/* ---- flags ------------------------------------------------------------------------------ */
enum {
    VF_DC = 1,          /* vertex in the boundary complex dC */
    VF_CURVE_END = 2,   /* boundary simplex of C_1 (end of a curve) */
    /* the singular complex S of tags (000 Sec. 4.1), inherited by children (singular.c) */
    VF_SING = 4,        /* tagged vertex: a corner */
    VF_SCREASE = 8,     /* on a crease (a tagged edge that is not a side of a tagged triangle) */
    VF_SSURF = 16,      /* on an embedded surface (a tagged triangle) */
    VF_SBND = 32,       /* on the boundary of an embedded surface */
};
enum {
    EF_DC = 1,          /* edge in dC */
    EF_BND2 = 2,        /* boundary simplex of C_2: edge of exactly one triangle, nothing else */
    EF_CURVE = 4,       /* a maximal 1-simplex (curve segment) */
    EF_CREASE = 8,      /* a crease of S */
    EF_SSURF = 16,      /* a side of a tagged triangle */
    EF_SBND = 32,       /* ... of exactly one (the embedded surface's boundary) */
};
enum {
    FF_MAX = 1,         /* a maximal triangle (surface part) */
    FF_BND3 = 2,        /* boundary simplex of C_3: face of exactly one 3-cell */
    FF_SING = 4,        /* tagged: part of an embedded surface */
};
enum { VF_S_ANY = VF_SCREASE | VF_SSURF };
enum {
    EF_N2SEL = 64,      /* a curve segment chosen by an N2 pair, or a side of a chosen triangle */
    EF_N2BND = 128,     /* ... of exactly one chosen triangle */
    FF_N2SEL = 8,       /* a maximal triangle chosen by an N2 pair (or in a chosen petal) */
};
/* vnm / enm pack the non-manifold type (bits 0-2) with the per-simplex rule (overrides.c):
 * bits 3-5 an override code, NM_C2B (edges) "in C_2 but not between exactly 2 maximal
 * triangles" (a boundary of C_2 for N1 with dimension 2), NM_G1 "singular by rule G1". All are
 * inherited by children (split.c). */
enum { NM_TYPE = 7, NM_OV_SHIFT = 3, NM_OV = 7 << 3, NM_C2B = 64, NM_G1 = 128 };
enum { OV_NONE = 0, OV_N1_1 = 1, OV_N1_2 = 2, OV_N1_3 = 3, OV_N2 = 4, OV_G2 = 5,
       OV_YZS = 6,      /* Ying-Zorin: a non-manifold edge (crease) or a simple singular vertex */
       OV_YZX = 7 };    /* Ying-Zorin: a complex singular vertex (corner) */
static inline int nm_type(uint8_t x) { return x & NM_TYPE; }
static inline int nm_ov(uint8_t x) { return (x & NM_OV) >> NM_OV_SHIFT; }
enum { OVM_N1 = 1, OVM_N2T = 2, OVM_N2C = 4, OVM_YZ = 8 }; /* sd_topo.ovmask: which overrides
                                                              * occur; the Ying-Zorin rules */
enum { FAM0 = 1, FAM1 = 2, FAM2 = 4, FAM3 = 8 };

/* ---- incidence relations (topo.c) ---------------------------------------------------------- */
/* A relation from keys to items in CSR form: key k's items are item[off[k] .. off[k+1]), in
 * increasing order. */
typedef struct sdi_rel {
    uint32_t *off, *item;
} sdi_rel;
/* Invert the map item i -> keys[i * stride + 0 .. per) (keys < nkeys). false: no memory. */
bool sdi_rel_build(sd_mem *m, sdi_rel *r, uint32_t nkeys, uint32_t nitems, int stride, int per,
                   const uint32_t *keys);
void sdi_rel_free(sd_mem *m, sdi_rel *r);
/* The relations of a level: vertex -> edges, vertex -> faces, edge -> faces, vertex / edge /
 * face -> tetrahedra, vertex -> octahedra whose major diagonal ends there. */
enum { SDI_VE, SDI_VF, SDI_EF, SDI_VT, SDI_ET, SDI_FT, SDI_VD, SDI_NREL };
#define SDI_REL(k) (1u << (k))

/* ---- one level's topology and classification ---------------------------------------- */
/* Three parts, built at different times (split.c, levels.c):
 *   cells    counts, cell vertices, tet diagonals, boundary masks, vertex classes: all that the
 *            lock-free accessors of a level read. Made when the level is computed.
 *   edges    (`derived`) ev and the edge classes: persistent once built, as sd_level_edges hands
 *            ev out and S_l reads its edge rows' ends from it. Built when the level's rules, its
 *            children's derived parts or an edge accessor need them.
 *   faces    (`faces`) fv, fe, face classes, per-cell edge and face ids, cu, tr: only the rules of
 *            the level and the next split read them, so they are transient at levels >= 1 —
 *            made (from the parent's faces, again if need be) for those and dropped after, so a
 *            computed hierarchy holds no faces but level 0's.
 * Arrays of the cells and edges are never moved or freed once built (lock-free readers may hold
 * them while other parts are added). */
typedef struct sd_topo {
    uint32_t nv, ne, nf;
    uint32_t npt, ncu, ntr, ntet, noct;
    bool derived;              /* the edges part is built */
    bool faces;                /* the faces part is built */
    uint8_t ovmask;            /* OVM_*: per-simplex rules occur (singular.c; same at every level) */
    bool tr_ident;             /* every face is a maximal triangle and face i is triangle i: at
                                * levels >= 1, tr is not stored and fv is trv */
    /* cells */
    uint32_t *pt;              /* vertex ids of isolated points */
    uint32_t (*cuv)[2];        /* vertex ids of curve segments (levels >= 1) */
    uint32_t (*trv)[3];        /* vertex ids of maximal triangles (levels >= 1) */
    uint32_t (*tet)[4];
    uint8_t *tet_d;            /* diagonal pair 0..2 */
    uint8_t *tet_b;            /* bit i: face i lies on the solids' boundary (a face of one cell) */
    uint32_t (*oct)[6];
    uint8_t *oct_b;            /* the same for the 8 faces of an octahedron */
    uint8_t *vfam, *vflag, *vnm;   /* vertex classification (classify.c) */
    /* edges */
    uint32_t (*ev)[2];
    uint8_t *efam, *eflag, *enm;
    /* faces */
    uint32_t (*fv)[3];
    uint32_t (*fe)[3];
    uint32_t *cu;              /* edge ids of curve segments */
    uint32_t *tr;              /* face ids of maximal triangles (NULL: tr_ident, face i) */
    uint32_t (*tet_e)[6];
    uint32_t (*tet_f)[4];
    uint32_t (*oct_e)[12];
    uint32_t (*oct_f)[8];
    uint8_t *fn3, *fflag;      /* fn3: number of 3-cells on the face (saturating) */
} sd_topo;

static inline uint32_t sdi_tr(const sd_topo *t, uint32_t i) { return t->tr ? t->tr[i] : i; }

/* complex.c: whether simplex s (n vertex ids into xyz) is degenerate — an edge shorter than
 * 1e-12 of `diag` (the bounding box's diagonal: SDI_SHORT_EDGE), an area or volume below 1e-12
 * of the longest edge squared or cubed (SDI_FLAT): the test of sd_complex_new and of
 * sd_complex_check_moves; 0 when it is not. */
enum { SDI_SHORT_EDGE = 1, SDI_FLAT = 2 };
int sdi_simplex_degenerate(const double *xyz, const uint32_t *s, int n, double diag);
/* Why a simplex of n vertices is degenerate (the code above), for a message. */
const char *sdi_degenerate_why(int code, int n);

/* topo.c: freeing the parts (all of them, the edges part, the faces part) */
void sdi_topo_free(sd_mem *m, sd_topo *t);
void sdi_topo_free_edges(sd_mem *m, sd_topo *t);
void sdi_topo_free_faces(sd_mem *m, sd_topo *t);
/* The incidence relations of one level, held by the call that needs them (on its stack, passed
 * down to whoever reads them: sdi_rels R = {.t = t}) and freed by it before it returns. */
typedef struct sdi_rels {
    const sd_topo *t;
    sdi_rel r[SDI_NREL];
} sdi_rels;
/* Build the relations SDI_REL(k) in `which` that R does not hold yet (VF, EF, FT need t's faces
 * part, VE its edges); false for lack of memory (those built stay until sdi_rels_free). */
bool sdi_rels_need(sd_mem *m, sdi_rels *R, unsigned which);
void sdi_rels_free(sd_mem *m, sdi_rels *R);
/* Lookups through the relations: the edge a-b (needs VE), the face with the three vertices v
 * (needs VF), or UINT32_MAX; whether face f has vertex v. */
uint32_t sdi_rels_edge(const sdi_rels *R, uint32_t a, uint32_t b);
uint32_t sdi_rels_face(const sdi_rels *R, const uint32_t v[3]);
bool sdi_face_has(const sd_topo *t, uint32_t f, uint32_t v);
/* The edge a-b by a scan of the edges (no relation needed), or UINT32_MAX. */
uint32_t sdi_topo_find_edge(const sd_topo *t, uint32_t a, uint32_t b);

/* ---- subdivision matrices (csr.c) ------------------------------------------------------ */
/* S_l: rows [vertex rows | edge rows | octahedron rows]; per row a weight-pattern id and the
 * columns that are not implicit (see csr.c). The public view (vrowptr, vcol, vval) is made only
 * when sd_complex_matrix asks for it. */
typedef struct sd_csrb {
    uint32_t nrows, ncols, npat, maxlen;
    uint32_t nvr, ner;                /* vertex rows [0,nvr), edge rows [nvr,nvr+ner), then cells */
    const uint32_t (*ev)[2];          /* implicit columns: the level's edges and octahedra */
    const uint32_t (*oct)[6];
    size_t nnz, nexp;                 /* entries: all / explicit (in col) */
    uint8_t pw;                       /* bytes per pattern id: 1, 2 or 4 */
    void *pat;
    uint32_t *col;
    uint32_t (*eopp)[2];              /* if set, edge row e's ring is eopp[e] (rings of 0 or 2
                                       * entries, a surface's opposite vertices), not in col */
    uint32_t *woff;                   /* npat + 1 */
    double *wt;
    size_t *kchk;                     /* col position of rows 0, SD_CHK, 2 SD_CHK, ... */
    uint32_t *vrowptr, *vcol;         /* the public CSR view, or NULL */
    double *vval;
    /* by columns, for edits (sdi_csrb_index, built with the next level): column j's rows,
     * varint-coded, at ub[ubase[j >> SDI_UBLK] + urel[j] ..) up to the same for j + 1; rchk the
     * col position of rows 0, SD_RCHK, 2 SD_RCHK, ... */
    uint8_t *ub;
    uint64_t *ubase;
    uint32_t *urel, *rchk;
} sd_csrb;

/* Interning of weight patterns while a matrix is built. */
typedef struct sd_pats {
    double *w;
    uint32_t *off, *slot;
    uint32_t n, capn, capw, hcap;
} sd_pats;

/* Allocates the pattern ids and kchk; the caller sets every row's pattern (sdi_csrb_set_pat) and
 * kchk, allocates and fills col (nexp) and calls finish. */
bool sdi_csrb_init(sd_mem *m, sd_csrb *b, uint32_t nvr, uint32_t ner, uint32_t nor, uint32_t ncols,
                  const uint32_t (*ev)[2], const uint32_t (*oct)[6]);
void sdi_csrb_free(sd_mem *m, sd_csrb *b);
uint32_t sdi_pats_intern(sd_mem *m, sd_pats *p, const double *w, uint32_t len); /* UINT32_MAX: no memory */
void sdi_pats_free(sd_mem *m, sd_pats *p);
/* Copy the patterns into b (the caller frees p); nnz: the number of entries. */
bool sdi_csrb_finish(sd_mem *m, sd_csrb *b, sd_pats *p, size_t nnz);

static inline uint32_t sdi_csrb_pat(const sd_csrb *s, uint32_t r)
{
    return s->pw == 1 ? ((const uint8_t *)s->pat)[r]
         : s->pw == 2 ? ((const uint16_t *)s->pat)[r] : ((const uint32_t *)s->pat)[r];
}
/* Row r's pattern id; ids are stored in 1 byte until one needs 2 or 4 (then all are widened). */
bool sdi_csrb_set_pat_slow(sd_mem *m, sd_csrb *b, uint32_t r, uint32_t id);
static inline bool sdi_csrb_set_pat(sd_mem *m, sd_csrb *b, uint32_t r, uint32_t id)
{
    if (b->pw == 1 && id < 256) {
        ((uint8_t *)b->pat)[r] = (uint8_t)id;
        return true;
    }
    return sdi_csrb_set_pat_slow(m, b, r, id);
}
/* Entries of row r, and how many of them are implicit. */
static inline uint32_t sdi_csrb_len(const sd_csrb *s, uint32_t r)
{
    uint32_t q = sdi_csrb_pat(s, r);
    return s->woff[q + 1] - s->woff[q];
}
static inline uint32_t sdi_csrb_nimp(const sd_csrb *s, uint32_t r)
{
    return r < s->nvr ? 1 : r < s->nvr + s->ner ? 2 : 6;
}
/* Entries of row r kept in col. */
static inline uint32_t sdi_csrb_nexp(const sd_csrb *s, uint32_t r)
{
    if (s->eopp && r >= s->nvr && r < s->nvr + s->ner)
        return 0;
    return sdi_csrb_len(s, r) - sdi_csrb_nimp(s, r);
}
/* Row r, whose explicit columns start at col[*k]: its columns into cols (sdi_csrb_len of them);
 * returns its weights and moves *k past the row. */
static inline const double *sdi_csrb_row(const sd_csrb *s, uint32_t r, size_t *k, uint32_t *cols)
{
    uint32_t q = sdi_csrb_pat(s, r), n = s->woff[q + 1] - s->woff[q], i = 0;
    if (r < s->nvr)
        cols[i++] = r;
    else if (r < s->nvr + s->ner) {
        cols[i++] = s->ev[r - s->nvr][0];
        cols[i++] = s->ev[r - s->nvr][1];
        if (s->eopp) {
            for (; i < n; i++)
                cols[i] = s->eopp[r - s->nvr][i - 2];
            return s->wt + s->woff[q];
        }
    } else
        for (; i < 6; i++)
            cols[i] = s->oct[r - s->nvr - s->ner][i];
    for (; i < n; i++)
        cols[i] = s->col[(*k)++];
    return s->wt + s->woff[q];
}
/* The start in col of every row (nrows + 1), for random access; the caller frees it. */
size_t *sdi_csrb_starts(sd_mem *m, const sd_csrb *b);
/* Make the public CSR view (kept with the matrix); false for lack of memory. */
bool sdi_csrb_view(sd_mem *m, sd_csrb *b);
#define SD_CHK 65536u
/* out[r*nc + k] = sum_j S[r][j] in[j*nc + k], rows in parallel parts (same bytes for any number) */
void sdi_csr_apply(const sd_csrb *s, const double *in, double *out, int nc, int threads);

/* S by columns (csr.c): build the index (no-op if built; SD_ERR_NOMEM, or SD_ERR_LIMIT past its
 * 32-bit offsets), then walk the rows that use column j in increasing order:
 *     sdi_users u = sdi_csrb_users(S, j); for (uint32_t r; sdi_users_next(&u, &r);) ...
 * (a row that lists j twice comes twice). */
#define SDI_UBLK 16
#define SD_RCHK 8u
sd_result sdi_csrb_index(sd_mem *m, sd_csrb *s, sd_error *err);
typedef struct sdi_users {
    const uint8_t *p, *end;
    uint32_t j, r;
    bool first;
} sdi_users;
static inline sdi_users sdi_csrb_users(const sd_csrb *s, uint32_t j)
{
    const uint8_t *b = s->ub;
    sdi_users u = {b + s->ubase[j >> SDI_UBLK] + s->urel[j],
                   b + s->ubase[(j + 1) >> SDI_UBLK] + s->urel[j + 1], j, 0, true};
    return u;
}
static inline bool sdi_users_next(sdi_users *u, uint32_t *r)
{
    if (u->p == u->end)
        return false;
    uint64_t v = 0;
    unsigned sh = 0;
    uint8_t b;
    do {
        b = *u->p++;
        v |= (uint64_t)(b & 127) << sh;
        sh += 7;
    } while (b & 128);
    if (u->first) { /* zigzag(r - j) */
        u->first = false;
        u->r = (uint32_t)((int64_t)u->j + (int64_t)((v >> 1) ^ (0 - (v & 1))));
    } else
        u->r += (uint32_t)v;
    *r = u->r;
    return true;
}
/* Row r of S on `in` as sdi_csr_apply sums it, bit for bit, except that a column c with slot
 * not NULL and slot[c] >= 0 reads alt + nc slot[c] (an edit's new value); needs the index. `at`
 * (optional, {UINT32_MAX} at first) remembers where the last row started, so rows taken in
 * increasing order are found without going back to their checkpoint. */
typedef struct sdi_rowpos {
    uint32_t r;
    size_t k;
} sdi_rowpos;
void sdi_csrb_eval(const sd_csrb *s, uint32_t r, const double *in, const int32_t *slot,
                   const double *alt, int nc, double *out, sdi_rowpos *at);
/* Ask for row r's data ahead of sdi_csrb_eval: stage 0 what locates it, stage 1 (after stage 0
 * has had time) its columns. */
void sdi_csrb_prefetch(const sd_csrb *s, uint32_t r, int stage);

/* ---- levels and the complex -------------------------------------------------------------- */
/* An edit's recomputed points of one level (edit.c): kept between edits so that an edit's lists
 * cost no allocation once they have grown; clean (mark all 0) between edits. */
typedef struct sdi_escratch {
    uint64_t *mark;            /* a bit per point (the finest level's set; others use slot) */
    uint32_t cap;              /* entries of id and chg */
    size_t dcap;               /* doubles of nv and ov */
    uint32_t *id;
    double *nv, *ov;           /* new and old values */
    uint8_t *chg;
} sdi_escratch;
void sdi_escratch_free(sd_mem *m, sdi_escratch *s);
typedef struct sd_channel {
    int ncomp;
    double *data;
} sd_channel;

#define SD_MAX_CHANNELS 32

struct sd_level {
    int index;
    uint32_t parent_nv, parent_ne;   /* sizes of level index-1 (origin of the points) */
    sd_complex *cx;                  /* the owner (lazy parts are built with its allocator) */
    const sd_topo *parent;           /* level index-1's topology, or NULL */
    sd_topo t;
    /* rules and stencils (rules.c, stencil.c), built lazily: they define S mapping this level to
     * the next */
    bool have_rules;
    uint8_t *vrule, *erule;   /* the |rho| / |ring| a rule uses is its row's length in S - 1 / - 2 */
    uint8_t *vrule_only;      /* the vertex rules alone, for outputs of a level without stencils */
    sd_csrb S;
    /* edits' scratch (edit.c), made by the first edit and kept: a map from this level's points to
     * their entries in an edit's list of recomputed points (-1 = none; levels with a finer
     * computed level), and the list itself (sdi_escratch) */
    int32_t *slot;
    struct sdi_escratch *es;
    /* per point of this level: 1 where the rules read its position (Ying-Zorin's corner angle
     * alpha: the corner and the far ends of its petal's singular edges), or NULL if none; an
     * edit moving such a point rebuilds this level's rules (edit.c) */
    uint8_t *geo;
    /* the tangent-plane constraints' data at this level's points (tangent.c), made with the next
     * level (level 0's from the tags, finer ones from the coarser data), or NULL */
    struct sdi_tplane *tp;
    /* channels of this level (channel 0 = positions) */
    int nch;
    sd_channel ch[SD_MAX_CHANNELS];
};

/* sharp.c: the edges (ids, sharpness) and vertices with a sharpness in (0, 10) of one level,
 * each list in increasing id (see sharp.c). */
typedef struct sdi_sharp {
    uint32_t ne, nv;
    uint32_t *e;
    float *es;
    uint32_t *v;
    float *vs;
    /* sharp triangles inside solids: level-0 face ids and their sharpness at this level; at
     * level l a level-0 face f stands for the faces [f span, (f + 1) span), span = 4^l */
    uint32_t nf, span;
    uint32_t *f;
    float *fs;
} sdi_sharp;

typedef struct sd_petal_at {
    uint32_t v, f;
    uint8_t kind; /* SD_PETAL_* */
} sd_petal_at;

struct sd_complex {
    sd_mem mem;
    sd_options opt;
    /* input bookkeeping */
    uint32_t nin;              /* number of input simplices */
    uint32_t *in_tet;          /* input simplex -> tetrahedron id (or UINT32_MAX) */
    uint32_t *in_src[5];       /* per sd_cell_kind, level-0 cell -> input simplex (one block
                                * of nin at in_src[SD_CELL_TETRA]; no octahedra at level 0) */
    uint8_t *tet_swapped;      /* level-0 tet reoriented (slots 2,3 swapped) */
    int nlevels;               /* computed levels */
    bool edit_indexed;         /* an edit was prepared: levels made later index S with them
                                * (sd_options.edit_index LAZY) */
    /* the singular tags and per-simplex rules as given (singular.c re-applies both to level 0) */
    size_t ntags;
    uint32_t *tag_at;          /* vertex, edge or face id of level 0 */
    uint8_t *tag_k;            /* 1, 2, 3 */
    size_t nov;
    sd_override *ov;
    /* petal tags (sd_complex_set_petals), one entry per level-0 triangle of each tagged petal,
     * sorted by (v, f); a face f of level L reads the entry of f >> 2 L */
    size_t npet;
    sd_petal_at *pet;
    /* tangent-plane constraints (sd_complex_set_tangents, tangent.c) as given, with the level-0
     * face of each entry's triangle (tt_f[2 i]) or pair (tt_f[2 i], tt_f[2 i + 1]) */
    size_t ntt;
    sd_tangent_tag *tt;
    uint32_t *tt_f;
    sd_level *lv[SD_MAX_LEVEL + 1];
    /* semi-sharp creases (sharp.c): level 0's lists and the crease method (SD_CREASE_*) */
    sdi_sharp sh;
    int sh_method;
    /* detail offsets (details.c): SD_MAX_CHANNELS x (SD_MAX_LEVEL + 1) lists, NULL until the
     * first offset is stored */
    struct sdi_dlist *det;
};

/* ---- details.c: detail offsets ------------------------------------------------------------- */
/* The offsets of one channel at one level: n points, ascending idx, ncomp values each. A level
 * l >= 1 is built as S_{l-1} p^{l-1}, then each listed point gets its offset added. */
typedef struct sdi_dlist {
    uint32_t n;
    uint32_t *idx;
    double *d;
} sdi_dlist;
#define SD_MAX_OFFSET 1e15
/* The list of (channel, level), or NULL when it holds none. */
const sdi_dlist *sdi_det(const sd_complex *c, int channel, int level);
/* The offset of point i in L, or NULL. */
const double *sdi_det_find(const sdi_dlist *L, uint32_t i, int nc);
/* data (nc per point, a channel of level `level` just computed) += its offsets. */
void sdi_det_add(const sd_complex *c, int channel, int level, double *data, int nc);
/* Make the table of lists (false: no memory), then swap the list of (channel, level) with *L. */
bool sdi_det_ready(sd_complex *c);
void sdi_det_swap(sd_complex *c, int channel, int level, sdi_dlist *L);
void sdi_dlist_free(sd_mem *m, sdi_dlist *L);
/* Drop the offsets of levels >= from (every channel), or all and the table (from = 0). */
void sdi_det_drop(sd_complex *c, int from);

/* ---- complex.c: level 0 ------------------------------------------------------------------ */
sd_result sdi_level0_build(sd_complex *c, const double *xyz, uint32_t nv, const uint32_t *idx,
                           const uint8_t *size, uint32_t ns, sd_error *err);

/* ---- classify.c: classes of level 0 (R: its relations, built as needed) -------------------- */
sd_result sdi_classify_level0(sd_mem *m, sd_topo *t, sdi_rels *R, sd_error *err);
/* The class codes of level 0 (sd_complex_class_codes), and taking shipped ones instead of the
 * classification's (sd_options.classes; sets *K->differing). */
void sdi_class_codes(const sd_topo *t, uint16_t *vertex, uint16_t *edge, uint16_t *face);
sd_result sdi_take_classes(sd_mem *m, sd_topo *t, sdi_rels *R, const sd_level0_classes *K,
                           sd_error *err);
sd_result sdi_choose_diagonals(sd_mem *m, sd_topo *t, sdi_rels *R, const int8_t *fixed,
                               sd_error *err);

/* ---- split.c: child topology and inherited classification of the next level, part by part
 * (see sd_topo); each needs the parent's edges and faces (cells: and the child's nothing; faces:
 * the child's edges) */
sd_result sdi_split_cells(sd_mem *m, const sd_topo *p, sd_topo *c, int threads, sd_error *err);
sd_result sdi_split_edges(sd_mem *m, const sd_topo *p, sd_topo *c, int threads, sd_error *err);
sd_result sdi_split_faces(sd_mem *m, const sd_topo *p, sd_topo *c, int threads, sd_error *err);

/* ---- levels.c: the hierarchy --------------------------------------------------------------- */
void sdi_level_free(sd_mem *m, sd_level *lv);
/* Forget a level's rules and every finer level. */
void sdi_drop_rules(sd_complex *c, sd_level *lv);
/* Free a level's rules part: rules, stencils S, edit columns, vrule_only, geo (not its points,
 * cells or scratch map `slot`). */
void sdi_level_free_rules(sd_mem *m, sd_level *lv);
void sdi_drop_levels(sd_complex *c, int from); /* levels from.. (they are recomputed on demand) */
/* Build level `level`'s rules and stencils if they are not yet (faces made on the way are
 * dropped again). */
sd_result sdi_ensure_rules(sd_complex *cx, int level, sd_error *err);
/* ... of levels 0 .. n-1 (the faces dropped once, at the end). */
sd_result sdi_ensure_rules_below(sd_complex *cx, int n, sd_error *err);
/* Build level `level`'s edges if they are not yet (under the caller's lock; faces made on the way
 * are dropped again). */
sd_result sdi_ensure_derived(sd_complex *cx, int level, sd_error *err);
/* The same from a const accessor of the level (see sd.h on locking); false if it failed. */
bool sdi_need_derived(const sd_level *lv);

/* ---- singular.c, overrides.c: tags, per-simplex rules and defaults on level 0 --------------- */
/* The relations their lookups use (a tag or override is found in time linear in the complex). */
#define SDI_TAG_RELS (SDI_REL(SDI_VE) | SDI_REL(SDI_VF) | SDI_REL(SDI_EF))
/* (Re)apply tags, overrides and the default non-manifold rules to level 0's flags. R: level 0's
 * relations, held by the caller (built here as needed). */
sd_result sdi_apply_singular(sd_complex *c, sdi_rels *R, sd_error *err);
/* overrides.c, called by sdi_apply_singular: mark the overrides' bits (stack: nf + 1 ids of
 * scratch), and, once the other bits are applied, the sides of N2 triangles and the check that
 * every N2 simplex sees exactly its own pair (nface: ne + 1 bytes of scratch). */
void sdi_overrides_mark(sd_complex *c, const sdi_rels *R, uint32_t *stack);
sd_result sdi_overrides_check(sd_complex *c, const sdi_rels *R, uint8_t *nface, uint32_t *stack,
                              sd_error *err);

/* ---- rules.c: one rule per vertex and edge ------------------------------------------------- */
/* The rule table's columns (rule_table.h) as numbers: rho and ring kinds per rule. */
enum { SDI_RHO_NONE, SDI_RHO_CURVE, SDI_RHO_SURFACE, SDI_RHO_SURFACE_BOUNDARY, SDI_RHO_SOLID,
       SDI_RHO_SOLID_BOUNDARY, SDI_RHO_G2 };
enum { SDI_RING_NONE, SDI_RING_OPPOSITE, SDI_RING_BOUNDARY_OPPOSITE, SDI_RING_SOLID, SDI_RING_G2,
       SDI_RING_FLAT };
extern const uint8_t SDI_RULE_RHO[SD_RULE_COUNT], SDI_RULE_RING[SD_RULE_COUNT];
/* Whether a vertex (edge false) or edge whose computed rule is `rule` and whose rho / ring has k
 * entries is extraordinary (rule_table.h). */
bool sdi_rule_extraordinary(uint8_t rule, uint32_t k, bool edge);
/* The rule of vertex v from the level's classification alone (no stencils needed). */
uint8_t sdi_vertex_rule(const sd_topo *t, uint32_t v);
/* The rule of every edge into er, in parallel parts; whether any edge's ring is G2's, and whether
 * any is the opposite vertices of its faces. */
void sdi_edge_rules(const sd_topo *t, int threads, uint8_t *er, bool *any_g2, bool *any_opp);
/* The rule of every vertex and the sizes of its rho (cnt_a: edge and diagonal neighbours, cnt_b:
 * the averaged scheme's octahedral opposites, NULL for the box scheme; zeroed by the caller): the
 * classification's rule, turned into a corner where its neighbourhood does not fit it (a curve or
 * surface boundary point with other than 2 neighbours, any rule with none). If `take` is not
 * NULL, take[e] gets bit 0 if ev[e][0] reads ev[e][1] through e, bit 1 for the converse. In
 * parallel parts (threads). false: no memory. */
bool sdi_vertex_rules(sd_mem *m, const sd_topo *t, int scheme, int threads, uint8_t *vr,
                      uint32_t *cnt_a, uint32_t *cnt_b, uint8_t *take);
/* The same without rho: nv entries into vr (no stencils needed). */
sd_result sdi_vertex_rules_only(sd_mem *m, const sd_topo *t, int scheme, uint8_t *vr);
/* The rule reported for a vertex / edge whose computed rule is r (N1, N2, G1, Ying-Zorin's where
 * they apply). */
sd_rule sdi_reported_vertex_rule(const sd_topo *t, uint32_t v, uint8_t r);
sd_rule sdi_reported_edge_rule(const sd_topo *t, uint32_t e, uint8_t r);

/* ---- Ying-Zorin (003 Sec. 2): petals.c, rules.c (sdi_yz_rules), yz.c ------------------------ */
/* An edge Ying-Zorin's rules treat as singular: a boundary or non-manifold edge of the surfaces,
 * one also in another part, a crease or an edge of an embedded surface. */
static inline bool sdi_yz_singular_edge(const sd_topo *t, uint32_t e)
{
    return t->efam[e] != FAM2 || (t->enm[e] & NM_C2B) || (t->eflag[e] & (EF_CREASE | EF_SSURF));
}
/* 003's simple/complex split of a non-manifold vertex where only triangles meet: an edge that
 * counts as singular there (non-manifold or boundary), and whether a vertex of non-manifold type
 * `type` with `nsing` of them is simple (one flower, exactly two singular edges). */
static inline bool sdi_yz_counts_singular(const sd_topo *t, uint32_t e)
{
    return t->efam[e] == FAM2 && (nm_type(t->enm[e]) == 2 || (t->eflag[e] & EF_BND2));
}
static inline bool sdi_yz_simple(int type, uint32_t nsing)
{
    return type != 3 && nsing == 2;
}
/* petals.c: walking the petals of a vertex (see there). */
/* The vertices of the singular tags (1: tagged, 2: on a tagged edge or triangle) into tagv. */
void sdi_tagged_vertices(const sd_complex *c, const sd_topo *t, uint8_t *tagv);
/* tangent.c: 003 Sec. 3's tangent and normal modification of level l + 1's positions x (S_l
 * applied), from level l's constraint data, which it makes first at level 0; level l + 1's data
 * goes to next->tp. Needs level l's faces. A complex without tangent tags, or not under
 * ying-zorin, returns at once. */
sd_result sdi_tp_step(sd_complex *c, int l, sd_level *next, double *x, sd_error *err);
void sdi_tp_free(sd_mem *m, struct sdi_tplane *tp);
enum { SDI_PETAL_FAN, SDI_PETAL_YZ };
/* The maximal triangles of edge e (needs the relation edge -> faces): their number, the first two
 * (in increasing id) into two. */
uint32_t sdi_max_faces(const sd_topo *t, const sdi_rel *ef, uint32_t e, uint32_t two[2]);
/* One way round v: from edge e0 into its maximal triangle f, out through f's other edge at v and
 * across it while it joins, appending each edge crossed and the triangle entered to w (at most
 * cap; edges only if w->edge is set). Returns the edge it stopped at: e0 again (the petal is
 * closed, if e0 joins) or one that does not join; UINT32_MAX past cap. */
typedef struct sdi_walk {
    uint32_t *face, *edge;
    uint32_t n, cap;
} sdi_walk;
uint32_t sdi_petal_walk(const sd_topo *t, const sdi_rel *ef, int mode, uint32_t v, uint32_t e0,
                        uint32_t f, sdi_walk *w);
/* The petal of v holding maximal triangle f0: its triangles (f0 first, then each way round in
 * order), its inner edges at v and the distinct edges at v that end it (0: closed, 1: a dart, 2:
 * open). face and inner are the caller's, cap entries each (the triangles at v, + 2; inner may be
 * NULL). false past cap or where f0 does not hold v. */
typedef struct sdi_petal {
    uint32_t *face, *inner, cap;
    uint32_t nf, ninner, nsing, sing[2];
} sdi_petal;
bool sdi_petal_of(const sd_topo *t, const sdi_rel *ef, int mode, uint32_t v, uint32_t f0,
                  sdi_petal *p);
/* How end i of edge e reads the edge under the Ying-Zorin rules (end[e][i], rules.c):
 * SD_YZ_NONE (not a singular vertex), SD_YZ_FIRST (003 Fig. 4f with gamma g, first stage only),
 * SD_YZ_DISK (the centre of a closed petal), SD_YZ_DART (the fixed centre of a dart petal) or
 * SD_YZ_CONCAVE (the fixed centre of a concave corner petal, theta its angle step). */
#define SD_YZ_FLAT_S 0.75 /* the flatness modification's s (docs/DECISIONS.md 27, 28) */
/* A concave corner whose singular edges are nearly in line (sin alpha < SD_YZ_RAMP, ~5.7
 * degrees) has no well-defined tangent pair: its s fades as (sin alpha / SD_YZ_RAMP)^2, so the
 * rule is continuous in alpha and tends to the first stage (DECISIONS 28). */
#define SD_YZ_RAMP 0.1
enum { SD_YZ_NONE, SD_YZ_FIRST, SD_YZ_DISK, SD_YZ_DART, SD_YZ_CONCAVE };
typedef struct sd_yzend {
    double g, theta, s; /* g of 003 Fig. 4f, its theta, the flatness modification's s */
    uint8_t kind;
} sd_yzend;
static inline bool sdi_yz_flat(uint8_t kind)
{
    return kind >= SD_YZ_DISK;
}
/* rules.c: the Ying-Zorin rule of both ends of every edge of level `level` (t, its relations
 * vertex -> faces and edge -> faces in R, positions x); *geo (allocated if need be) marks the
 * points whose positions they read. false: no memory. */
bool sdi_yz_rules(sd_mem *m, const sd_complex *cx, int level, const sd_topo *t, const sdi_rels *R,
                  const double *x, sd_yzend (*gam)[2], uint8_t **geo);
/* yz.c: the rows with 003's flatness modification (fixed disk, dart, concave corner). Every edge
 * with a flattened end gets er[e] = SD_RULE_YZ_FIXED_DISK, _DART or _CONCAVE and its row: ends[e]
 * the weights of its two ends, then col/w[off[e] .. off[e+1]) the rest. */
typedef struct sd_yzrows {
    uint32_t *off, *col, n;
    double *w;
    double (*ends)[2];
} sd_yzrows;
bool sdi_yz_flat_rows(sd_mem *m, const sd_topo *t, const sdi_rel *ef, const sd_yzend (*end)[2],
                      uint8_t *er, sd_yzrows *y);
void sdi_yzrows_free(sd_mem *m, sd_yzrows *y);

/* ---- rings.c: rho(x) and the rings of edges -------------------------------------------------- */
/* Flags in a vertex's rule while rho is counted: the rule itself is vr & SDI_VR_RULE. */
enum { SDI_VR_RULE = 0x1f, SDI_VR_BND = 0x20, SDI_VR_OWN = 0x40, SDI_VR_SLOW = 0x80 };
/* The sizes of every vertex's rho (see sdi_vertex_rules) for the rules in vr, flagged: SLOW, rho
 * decided per neighbour (G2, singular vertices); OWN, by the simplex's own choice. Clears the
 * flags. In parallel parts (threads). false: no memory. */
bool sdi_vertex_rho(sd_mem *m, const sd_topo *t, int scheme, int threads, uint8_t *vr,
                    uint32_t *cnt_a, uint32_t *cnt_b, uint8_t *take);
/* rho itself: vertex v's neighbours into col from cur[v] on (cur advances), in the order counted:
 * through edges (in edge order), then major diagonals, then octahedral opposites; in parallel
 * parts by ranges of vertices. */
void sdi_vertex_rho_cols(const sd_topo *t, int scheme, int threads, const uint8_t *vr,
                         const uint8_t *take, uint32_t *cur, uint32_t *col);
/* N1 / N2 (overrides.c): is e, at a vertex with choice ov, on the boundary of the part it follows? */
bool sdi_ov_boundary_edge(const sd_topo *t, int ov, uint32_t e);
/* The opposite vertices of the edges whose ring is OPPOSITE or BOUNDARY_OPPOSITE (rules er):
 * opp[e], and in nopp[e] how many faces were seen (bits 0-1, saturating at 3; 2 makes a ring). */
void sdi_edge_opposites(const sd_topo *t, int threads, const uint8_t *er, uint32_t (*opp)[2],
                        uint8_t *nopp);
/* The ring size of an edge of rule r if its ring is its opposite vertices: 2 where two faces gave
 * them (nopp as above), else 0; 0 for the other rings too. */
static inline uint32_t sdi_opp_ring_len(uint8_t r, uint8_t nopp)
{
    uint8_t ring = SDI_RULE_RING[r];
    return (ring == SDI_RING_OPPOSITE || ring == SDI_RING_BOUNDARY_OPPOSITE) && (nopp & 3) == 2
           ? 2u : 0u;
}
/* Per-edge variable-size rings (solid and G2 edges), CSR; class 0 = ring/face, 1 = diagonal. */
typedef struct sdi_rings {
    uint32_t *off, *v;
    uint8_t *cls;  /* 1: through an octahedron's diagonal (averaged scheme; else NULL) */
    uint32_t *len; /* after dedup */
} sdi_rings;
bool sdi_solid_rings(sd_mem *m, const sd_topo *t, const uint8_t *erule, int scheme, int threads,
                     sdi_rings *R);
/* (needs the relations vertex -> edges and -> diagonals: built into rel) */
bool sdi_g2_rings(sd_mem *m, sdi_rels *rel, const uint8_t *erule, sdi_rings *R);
void sdi_rings_free(sd_mem *m, sdi_rings *r);

/* ---- direct.c: S applied without being made (batch refinement) ------------------------------ */
/* Whether level p's next level may be computed without S: batch refinement (edit_index LAZY,
 * nothing edited), no rules built, no solids, Ying-Zorin rows, semi-sharp creases or
 * tangent-plane constraints. */
bool sdi_direct_ok(const sd_complex *c, const sd_level *p);
/* The valences of a plain level (direct.c), handed from one level to the next within one
 * sd_complex_level call, and the faces of the edges of the last two plain levels split (ef[k]
 * of level ef_level[k]: per edge, 3 f + j for its faces f in order, the edge being f's edge j);
 * top: the level the call makes. Freed by sdi_plain_free. */
typedef struct sdi_plain {
    uint32_t *cnt;
    int level, top;
    uint32_t (*ef[2])[2];
    int ef_level[2];
} sdi_plain;
void sdi_plain_free(sd_mem *m, sdi_plain *pl);
/* lv's channels (allocated) from p's (faces built) as S_p would make them, the same bytes; *done
 * false if the level has rows direct.c does not make (G2 rings): then nothing was written. pl:
 * the plain valences of p's parent if known, replaced by p's if p is plain. */
sd_result sdi_direct_apply(sd_complex *c, sd_level *p, sd_level *lv, sdi_plain *pl, bool *done,
                           sd_error *err);

/* ---- masks.c: the weights of the rules ------------------------------------------------------ */
/* A vertex mask: the centre, each of rho (class A), each octahedral opposite (class B). */
typedef struct sdi_vmask {
    double self, a, b;
} sdi_vmask;
/* An edge mask: the two ends, each ring point, each diagonal-class ring point (averaged). */
typedef struct sdi_emask {
    double end[2], ring, diag;
} sdi_emask;
#define SDI_LOOP_CACHE 64
/* What a mask sees: sizes and options (loopc: Loop weights by valence below SDI_LOOP_CACHE). */
typedef struct sdi_vnb {
    uint32_t na, nb;
    int weights, scheme;
    const double *loopc;
} sdi_vnb;
typedef struct sdi_enb {
    uint32_t k;
    const uint8_t *cls; /* the ring's classes (averaged solid scheme), or NULL */
} sdi_enb;
/* The masks of rule r (rule_table.h). */
sdi_vmask sdi_vertex_mask(uint8_t rule, const sdi_vnb *n);
sdi_emask sdi_edge_mask(uint8_t rule, const sdi_enb *n);
/* Loop's weight c of a vertex of valence m: Warren's or Loop's beta(m) / m (SD_WEIGHTS_*). */
double sdi_loop_weight(int weights, uint32_t m);
/* The octahedron cell point's weight of its vertex i (0, 1: the major diagonal). */
double sdi_mask_cell(int scheme, int i);
/* 003 Fig. 4f from the centre v of a petal: v, the far end w, each opposite vertex; gamma of
 * the petal's angle step theta. */
typedef struct sdi_yzmask {
    double centre, far, opposite;
} sdi_yzmask;
sdi_yzmask sdi_mask_yz_petal(double g);
double sdi_mask_yz_gamma(double theta);
/* The row of an edge with 003 Fig. 4f at its singular ends (averaged where both are). */
sdi_emask sdi_mask_yz_petal_edge(const sd_yzend end[2]);
/* The flattened row's weight (yz.c) of ring point j in the row of edge v-ring[i] of a petal of k
 * triangles whose centre reads it as x (on q = p - v: the centre takes the rest of 1). */
double sdi_mask_yz_flat(const sd_yzend *x, uint32_t k, uint32_t i, uint32_t j);

/* ---- sharp.c: semi-sharp creases (OpenSubdiv's Sdc::Crease) ------------------------------ */
void sdi_sharp_free(sd_mem *m, sdi_sharp *s);
/* Level `level`'s lists from level 0's (levels below it computed, with their edges); empty when
 * the complex has none. false: no memory. */
bool sdi_sharp_level(sd_complex *c, int level, sdi_sharp *out);
/* The sharpness of the halves of each listed edge of level t (cs[i][k]: the half at ev[e][k]). */
bool sdi_sharp_children(sd_mem *m, const sd_topo *t, const sdi_sharp *s, int method,
                        float (*cs)[2]);
/* What the rows a sharpness reaches become (stencil.c applies them on the base rows): */
typedef struct sdi_sharp_vertex {
    uint32_t v;
    uint8_t prule, crule;  /* this level's and the child's rule: smooth, crease, corner */
    uint8_t nedge[2];      /* a crease's two sharp edges (parent, child); 0: the base's own */
    uint32_t edge[2][2];
    int32_t pos[2][2];     /* their places in rho */
    double w;              /* the parent rule's weight in the blend */
} sdi_sharp_vertex;
typedef struct sdi_sharp_edge {
    uint32_t e;
    bool crease;           /* the midpoint; else the blend with w = the sharpness */
    double w;
} sdi_sharp_edge;
/* Rows of the sharp embedded surface (sharp triangles inside solids): the surface's rule
 * (SDI_SURF_*) blended with the solid's row by w. */
enum { SDI_SURF_LOOP = 1, SDI_SURF_BSPLINE, SDI_SURF_CORNER, SDI_SURF_MIDPOINT };
typedef struct sdi_surf_vertex {
    uint32_t v, off, n;    /* its surface neighbours: nb[off .. off + n) (rho positions) */
    uint8_t kind;
    double w;
} sdi_surf_vertex;
typedef struct sdi_surf_edge {
    uint32_t e, opp[2];    /* Loop's opposite vertices (kind LOOP) */
    uint8_t kind;
    double w;
} sdi_surf_edge;
typedef struct sdi_sharp_rows_t {
    uint32_t nvert, nedge;
    sdi_sharp_vertex *vert; /* in increasing vertex id */
    sdi_sharp_edge *edge;   /* in increasing edge id */
    uint32_t nsvert, nsedge;
    sdi_surf_vertex *svert; /* in increasing vertex id */
    sdi_surf_edge *sedge;   /* in increasing edge id */
    int32_t *nbpos;         /* rho positions of the surface vertices' neighbours (-1: none) */
} sdi_sharp_rows_t;
/* From a level's lists, its vertex rules vr and rho's `take` (rules.c). false: no memory. */
bool sdi_sharp_rows(sd_mem *m, const sd_topo *t, const sdi_sharp *s, int method,
                    const uint8_t *vr, const uint8_t *take, sdi_sharp_rows_t *out);
void sdi_sharp_rows_free(sd_mem *m, sdi_sharp_rows_t *r);
/* Turn a base row w (len entries: centre, rho, ...) into the sharp one (tmp: 2 len doubles). */
void sdi_sharp_vertex_row(const sdi_sharp_vertex *x, double *w, uint32_t len, double *tmp);
/* The same for an edge row (ends, ring). */
void sdi_sharp_edge_row(const sdi_sharp_edge *x, double *w, uint32_t len);
/* The sharp surface's rows on a solid's base rows (weights: SD_WEIGHTS_*; ring: the edge row's
 * ring, len - 2 entries); unchanged if a neighbour is not in the row. */
void sdi_surf_vertex_row(const sdi_sharp_rows_t *r, const sdi_surf_vertex *x, int weights,
                         double *w, uint32_t len, double *tmp);
void sdi_surf_edge_row(const sdi_surf_edge *x, const uint32_t *ring, double *w, uint32_t len);

/* ---- stencil.c: S_l from the rules, rings and masks ------------------------------------------ */
sd_result sdi_build_rules(sd_complex *cx, sd_level *lv, sd_error *err);

#endif
