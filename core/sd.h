/* sd.h — the public C API of subdivd's core library.
 *
 * The core turns a control complex (vertices + maximal simplices of dimension 0..3, mixed freely)
 * into a hierarchy of uniformly subdivided levels. Each level is the previous one split (edge 1->2,
 * triangle 1->4, tetrahedron -> 4 tets + octahedron, octahedron -> 6 octahedra + 8 tets) and its
 * points are a sparse linear map of the previous level's points: p^{l+1} = S_l p^l. The same S_l
 * subdivide positions and any per-vertex attribute ("channel").
 *
 * The core does no I/O: arrays in, arrays out, result codes and a caller-owned error struct.
 * Ownership: every *_new returns an object the caller frees with the matching *_free; pointers
 * returned by accessors are borrowed from the complex and stay valid until the complex is freed
 * or changed (set_diagonal, add_channel).
 *
 * Threading: a complex is not thread-safe; different complexes are fully independent (the core
 * keeps no global state), so one thread per complex needs no locking. Within one complex the
 * caller serialises every call that takes a non-const sd_complex * (and the lazily building
 * accessors below) with a lock, and may read a level without that lock under this contract:
 * once level L has been returned by sd_complex_level() and its rules built (sd_complex_vertex_class
 * or any call that builds them, e.g. computing level L+1), the arrays that the accessors of level
 * L return or read — channels (positions), cells, edges, origins, vertex rules and classes, solid
 * boundary — stay valid and unchanged while other levels are computed. What is built lazily
 * later (a level's rules and stencils, the edges of the finest level, a matrix view) is only
 * added, under the caller's lock; arrays already handed out or read by these accessors are never
 * freed or moved (only sd_complex_free, set_diagonal, add_channel and set_singular drop levels,
 * and edits change channel values in place — or, where they move a point that a level's rules
 * read, rebuild that level's rules and the finer levels; moves at finer levels compute missing
 * levels first; edits exclude readers anyway). The core's own working arrays (faces, per-cell
 * edge ids) are made and dropped again inside such calls; no accessor reads them.
 * Lazily building accessors: the finest computed level is stored as its cells and points only;
 * sd_level_edges, sd_level_find_edge and sd_level_edge_singular build its edges the first time
 * they are asked (so call them under the lock until the level's rules are built).
 * sd_options.threads lets one call use more threads internally; it changes none of the above.
 */
#ifndef SD_H
#define SD_H

#include <stddef.h>
#include <stdint.h>

#include "rule_table.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum sd_result {
    SD_OK = 0,
    SD_ERR_NOMEM,      /* the allocator refused */
    SD_ERR_LIMIT,      /* a configured limit (bytes, vertices, cells) would be exceeded */
    SD_ERR_EMPTY,      /* no vertices or no simplices */
    SD_ERR_VALUE,      /* a coordinate or attribute is NaN, infinite or too large */
    SD_ERR_ARITY,      /* a simplex has 0 or more than 4 vertices */
    SD_ERR_INDEX,      /* a vertex index is out of range */
    SD_ERR_REPEATED,   /* a vertex appears twice in one simplex */
    SD_ERR_DUPLICATE,  /* the same simplex is listed twice */
    SD_ERR_DEGENERATE, /* a simplex has (nearly) zero length, area or volume */
    SD_ERR_ARG         /* a bad argument to an API call (level, vertex, option) */
} sd_result;

/* Filled by every fallible call. `item` is the index of the offending input element (simplex,
 * vertex, ...) or -1; `field` the position inside it (vertex slot, coordinate) or -1. */
typedef struct sd_error {
    sd_result code;
    long item;
    int field;
    char message[240];
} sd_error;

const char *sd_result_name(sd_result r);

/* x in the fewest %g digits (6 to 17) that read back as x, for messages that quote a value
 * (%g alone prints 1.0000001e15 as the bound 1e+15 it passes); out holds at least 32 bytes. */
const char *sd_shortest(double x, char out[32]);

/* SD_UNDER_ASAN: built with AddressSanitizer (gcc's and clang's spellings). The allocators
 * then use the C library's blocks, which it watches, and align or map none of their own. */
#if defined(__SANITIZE_ADDRESS__)
#define SD_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SD_UNDER_ASAN 1
#endif
#endif

/* A pluggable allocator (NULL functions = libc). */
typedef struct sd_allocator {
    void *(*alloc)(size_t size, void *ud);
    void (*release)(void *ptr, size_t size, void *ud);
    void *ud;
} sd_allocator;

enum { SD_WEIGHTS_WARREN = 0, SD_WEIGHTS_LOOP = 1 };   /* Loop vertex weights, docs/RULES.md */
enum { SD_SOLID_BOX = 0, SD_SOLID_AVERAGED = 1 };      /* solid scheme, 001 Sec. 3 / App. A */
enum { SD_NM_G2 = 0, SD_NM_G1 = 1 };                   /* default non-manifold rule, 000 Sec. 3.5 */
enum { SD_NMSURF_CHANG_QIN = 0, SD_NMSURF_YING_ZORIN = 1 }; /* pure-triangle non-manifold regions */

/* Options: zero means default. */
typedef struct sd_options {
    int surface_weights;     /* SD_WEIGHTS_* */
    int solid_scheme;        /* SD_SOLID_* */
    int nonmanifold_default; /* SD_NM_*: the rule of non-manifold simplices without an override */
    int nonmanifold_surface; /* SD_NMSURF_*: rules of non-manifold regions made of triangles only */
    size_t max_bytes;        /* memory cap for the whole complex (0 = none) */
    sd_allocator allocator;
    int threads;             /* threads computing a level may use (0, 1 = the caller's only;
                              * the others are created and joined within the call, and never
                              * allocate); results are the same bytes for any number */
    const uint8_t *reoriented; /* NULL: each tetrahedron is stored reoriented to positive volume
                              * (slots 2 and 3 exchanged) when its volume is negative; else one
                              * byte per input simplex, read for tetrahedra: nonzero = store it
                              * with slots 2 and 3 exchanged, whatever its volume (what
                              * sd_complex_reoriented reported, so a saved complex is rebuilt
                              * with the same numbering). Read by sd_complex_new only. */
    const int8_t *diagonals; /* NULL, or one per input simplex, read for tetrahedra: a pair 0..2
                              * (as sd_complex_set_diagonal takes it) kept as given, or -1: chosen
                              * by 001 Algorithm 2 against the given ones (a refinement keeps its
                              * untouched tetrahedra's). Read by sd_complex_new only. */
    int edit_index;          /* SD_EDIT_INDEX_*: when the by-column index of each level's S that
                              * edits use (sd_complex_move and friends) is made */
    const struct sd_level0_classes *classes; /* NULL, or level-0 classes computed elsewhere
                              * (below), taken instead of the complex's own. Read by
                              * sd_complex_new only. */
} sd_options;

/* Classes of level-0 entities computed elsewhere: subdivd-mpi classifies the whole complex once
 * and ships each piece the classes of the entities whose star the piece holds whole (DECISIONS
 * 44). A class code is what sd_complex_class_codes gives: family, boundary and non-manifold
 * type (000 Sec. 2) of a vertex or edge, maximality, solid boundary and the 3-cells around a
 * face. The complex takes these codes instead of its own for the entities listed (code 0: its
 * own), then derives tags, per-simplex rules and rules from them as it always does, and counts
 * in *differing the entries that were not what it found itself. Only the classes may differ:
 * the boundary bits and the non-manifold type; a code whose topology (family, curve segment,
 * maximal triangle, 3-cells around a face) is not the entity's own, or that is not a code, is
 * SD_ERR_ARG (item = its index in its list), as is an edge or face with a nonzero code that is
 * not one of the complex. Entities are given by input vertex ids. */
typedef struct sd_level0_classes {
    size_t nv;                  /* codes of input vertices 0 .. nv-1 (nv <= the complex's) */
    const uint16_t *vertex;
    size_t ne;                  /* edges: 2 input vertex ids each in edge_v */
    const uint32_t *edge_v;
    const uint16_t *edge;
    size_t nf;                  /* faces: 3 input vertex ids each in face_v */
    const uint32_t *face_v;
    const uint16_t *face;
    size_t *differing;          /* NULL, or set by sd_complex_new: the entries (of any kind)
                                 * whose code was not the complex's own (taken anyway) */
} sd_level0_classes;

/* SD_EDIT_INDEX_WITH_LEVELS (the default): with each level, so the first edit costs what later
 * ones do (a service's live editing). SD_EDIT_INDEX_LAZY: by sd_complex_prepare_edits or the
 * first edit, whichever comes first — batch refinement that never edits skips its time and
 * memory (docs/BENCHMARKS.md); until then a level without solids, G2 rings, Ying-Zorin rows,
 * semi-sharp creases or tangent-plane constraints computes the next one without making its S at
 * all (made when asked for: classes, matrices, limits, edits; docs/DECISIONS.md 50). Levels
 * and edits give the same bytes either way. */
enum { SD_EDIT_INDEX_WITH_LEVELS = 0, SD_EDIT_INDEX_LAZY = 1 };

typedef struct sd_complex sd_complex;

/* Build and validate a control complex. `xyz` has 3*nv doubles. Simplex s has `size[s]` (1..4)
 * vertex indices, stored consecutively in `idx` (simplex s starts after the sizes of 0..s-1).
 * Listed simplices that are faces of other listed simplices are absorbed (not maximal).
 * Returns NULL and fills `err` on failure. Free with sd_complex_free. */
sd_complex *sd_complex_new(const double *xyz, size_t nv, const uint32_t *idx, const uint8_t *size,
                           size_t ns, const sd_options *opt, sd_error *err);
void sd_complex_free(sd_complex *c);

/* What sd_complex_new would refuse in each simplex, for a caller that drops those simplices
 * instead (PUT /complex "repair"): why[s] (ns bytes, caller-owned) = SD_OK (kept),
 * SD_ERR_REPEATED (a vertex twice), SD_ERR_DEGENERATE (sd_complex_new's tolerance: no other
 * test) or SD_ERR_DUPLICATE (the vertices, in any order, of an earlier kept simplex; of[s] =
 * that simplex when `of`, ns entries, is not NULL). A simplex that is a face of another is kept
 * (sd_complex_new absorbs it). The other refusals (no vertices or simplices, a coordinate, an
 * arity, an index out of range) are returned as sd_complex_new returns them. `a`: the allocator
 * of the one scratch hash (NULL = libc). Builds nothing. */
sd_result sd_complex_check(const double *xyz, size_t nv, const uint32_t *idx, const uint8_t *size,
                           size_t ns, const sd_allocator *a, uint8_t *why, uint32_t *of,
                           sd_error *err);

/* Force the major diagonal of the tetrahedron given as input simplex `simplex` to its
 * opposite-edge pair `pair` (0: edges 01|23, 1: 02|13, 2: 03|12 in the input's vertex order),
 * overriding 001 Algorithm 2's choice. Drops computed levels >= 1 and, if the pair changes, the
 * detail offsets of levels >= 3 (the new split renumbers those levels' points; levels 1 and 2
 * keep theirs). */
sd_result sd_complex_set_diagonal(sd_complex *c, size_t simplex, int pair, sd_error *err);
/* The diagonal pair in use for input simplex `simplex` (a tetrahedron), or -1. */
int sd_complex_diagonal(const sd_complex *c, size_t simplex);
/* Whether input simplex `simplex` (a tetrahedron) is stored with slots 2 and 3 exchanged (1) or
 * as given (0); -1 if it is not a tetrahedron. The stored order fixes the numbering of every
 * level (edges and faces are numbered as the tetrahedra's slots meet them). */
int sd_complex_reoriented(const sd_complex *c, size_t simplex);

/* The class codes of level 0 (see sd_level0_classes; never 0): vertex[i] for vertex i (nv
 * entries), edge[e] for edge e in sd_level_edges' order, face[f] for face f of level 0 (faces
 * counts entries, in the order the simplices first meet their faces: tetrahedra first, then
 * triangles; no accessor hands out their vertices — subdivd-mpi reads them from the core's
 * topology). Any of the arrays may be NULL. The codes compare equal exactly when the classes
 * do. */
void sd_complex_class_codes(const sd_complex *c, uint16_t *vertex, uint16_t *edge, uint16_t *face);

/* Add a per-vertex channel of `ncomp` (1..16) doubles per control vertex; returns the channel
 * id (>= 1; channel 0 is the positions) or -1. Data are copied. */
int sd_complex_add_channel(sd_complex *c, const double *data, int ncomp, sd_error *err);

/* Exact sizes of level L, from the split table, without computing it. */
typedef struct sd_counts {
    uint64_t vertices, edges, faces;
    uint64_t points, curves, triangles, tetrahedra, octahedra;
} sd_counts;
void sd_complex_counts(const sd_complex *c, int level, sd_counts *out);

/* Memory in use by the complex (all levels, matrices, channels), in bytes. */
size_t sd_complex_memory(const sd_complex *c);
/* The bytes computing the levels up to `level` would add: the core's measured cost per entity
 * (core/complex.c), summed over the levels not computed yet (from sd_complex_counts, without
 * computing anything), to check a memory limit before asking for a level. Within 30% of what
 * the levels take once computed, for solids, surfaces, curves and mixed complexes alike. */
uint64_t sd_complex_estimate_bytes(const sd_complex *c, int level);
/* The same for level `level` alone (what computing it from level - 1 adds; 0 for level 0),
 * computed or not. */
uint64_t sd_complex_estimate_level_bytes(const sd_complex *c, int level);
int sd_complex_levels_computed(const sd_complex *c);
/* The threads later computations of c may use (sd_options.threads: 0 or 1 = the caller's
 * only); results are the same bytes for any number. Call it while no other call runs on c (a
 * service holding the complex's lock sets it per request from the cores free at the time). */
void sd_complex_set_threads(sd_complex *c, int threads);

/* ---- levels ------------------------------------------------------------------------------ */

typedef struct sd_level sd_level;

#define SD_MAX_LEVEL 12

/* Level L (0 = control complex), computing missing levels first. NULL + err on failure. */
const sd_level *sd_complex_level(sd_complex *c, int level, sd_error *err);

uint32_t sd_level_index(const sd_level *lv);
uint32_t sd_level_num_vertices(const sd_level *lv);
/* Channel data (ncomp doubles per vertex); channel 0 = positions (ncomp 3). */
const double *sd_level_channel(const sd_level *lv, int channel, int *ncomp);

/* Top cells of each part: isolated points, curve segments, surface triangles (not faces of
 * solids), tetrahedra and octahedra. An octahedron lists three opposite pairs (p,q),(a,a2),(b,b2),
 * the major diagonal (p,q) first. */
typedef enum { SD_CELL_POINT = 0, SD_CELL_CURVE, SD_CELL_TRIANGLE, SD_CELL_TETRA, SD_CELL_OCTA } sd_cell_kind;
int sd_cell_size(sd_cell_kind k);   /* 1, 2, 3, 4, 6 */
/* The k-th (0..3) of the 4 tetrahedra around an octahedron's major diagonal (p,q): (q, p, e_k,
 * e_k+1) over the equator cycle a, b, a2, b2 — positively oriented for a positive octahedron.
 * The one split of the outputs (api/geom.c), the embedding (core/embed.c) and 004 eq. 13. */
void sd_octa_tet(const uint32_t oct[6], int k, uint32_t tet[4]);
uint32_t sd_level_num_cells(const sd_level *lv, sd_cell_kind k);
/* Write the vertex ids of cell i of kind k into v (sd_cell_size(k) ids). */
void sd_level_cell(const sd_level *lv, sd_cell_kind k, uint32_t i, uint32_t *v);

/* The input simplex (its index among the posted ones) that cell i of kind k of this level
 * descends from: level 0's cells are posted simplices; a child's parent is closed form
 * (core/split.c): points keep their index, curve i comes from i/2, triangle i from i/4,
 * tetrahedron t from tetrahedron t/4 (t < 4 parent tets) or octahedron (t - 4T)/8, octahedron o
 * from tetrahedron o (o < T) or octahedron (o - T)/6. */
uint32_t sd_level_control_cell(const sd_level *lv, sd_cell_kind k, uint32_t i);

/* All edges of the level (2n ids), in the order edge points are numbered at level L+1. */
/* On the finest computed level, the first call builds the level's edges (see Threading above);
 * NULL and *n = 0 if that fails for lack of memory. */
const uint32_t *sd_level_edges(const sd_level *lv, uint32_t *n);

/* Where vertex i of level L >= 1 came from in level L-1. */
typedef enum { SD_ORIGIN_INPUT = 0, SD_ORIGIN_VERTEX, SD_ORIGIN_EDGE, SD_ORIGIN_CELL } sd_origin_kind;
sd_origin_kind sd_level_origin(const sd_level *lv, uint32_t i, uint32_t *a, uint32_t *b);

/* ---- classification and rules (000 Sec. 2, docs/RULES.md) ----------------------------- */

/* The rules, numbered in the order of the table in rule_table.h (docs/RULES.md says which paper
 * equation each implements). */
typedef enum sd_rule {
#define SD_RULE_ENUM_(id, ...) id,
    SD_RULE_TABLE(SD_RULE_ENUM_)
#undef SD_RULE_ENUM_
    SD_RULE_COUNT
} sd_rule;
const char *sd_rule_name(sd_rule r);

typedef struct sd_class {
    uint8_t family;     /* bit k set: the simplex is in C_k (k = 0..3) */
    uint8_t boundary;   /* in the boundary complex dC */
    uint8_t nonmanifold;/* 0 = manifold, 1..4 = non-manifold type (000 Sec. 2.4) */
    uint8_t rule;       /* sd_rule */
    uint32_t valence;   /* |rho| the rule uses (vertex: 1-ring, edge: ring) */
    uint8_t extraordinary;
} sd_class;

/* Classification of vertex i / edge e of a level (builds that level's stencils if needed). */
sd_result sd_complex_vertex_class(sd_complex *c, int level, uint32_t i, sd_class *out, sd_error *err);
sd_result sd_complex_edge_class(sd_complex *c, int level, uint32_t e, sd_class *out, sd_error *err);
/* Singular tags (000 Sec. 4.1): vertices (1 id: corners, fixed), edges (2 ids: creases, cubic
 * B-spline along them; a vertex where other than 2 creases meet is a corner) and triangles
 * (3 ids: an embedded surface, Loop over the tagged triangles and B-spline along its boundary;
 * inside a solid it splits it smoothly on each side). Each tag must be a vertex, edge or
 * triangle of the complex (SD_ERR_ARG otherwise, item = the tag). Replaces earlier tags; children
 * stay tagged at every level; drops computed levels >= 1. idx/size as for sd_complex_new. */
sd_result sd_complex_set_singular(sd_complex *c, const uint32_t *idx, const uint8_t *size,
                                  size_t n, sd_error *err);
/* Semi-sharp creases with OpenSubdiv's semantics (Sdc::Crease; docs/RULES.md "Semi-sharp
 * creases"): a sharpness s in [0, 10) on a vertex or on an edge of a surface or of the solids'
 * boundary surface. While the level is below s the edge is a crease (the vertex a corner); at a
 * fractional s the rows blend; children decrement (SD_CREASE_UNIFORM) or follow Chaikin's rule
 * (SD_CREASE_CHAIKIN: 3/4 s + 1/4 the mean of the other semi-sharp edges at the end, minus 1). A
 * vertex's rule comes from its sharp edges (OpenSubdiv's smooth, dart, crease, corner), the edges
 * of its own crease (a boundary, singular tags) counting as infinitely sharp. s >= 10 is
 * infinitely sharp: give it as a singular tag (SD_ERR_VALUE here). s = 0 entries are ignored.
 * A triangle inside a solid (a face of two cells) with sharpness s is a sharp embedded surface:
 * its vertices and edges follow the embedded surface's rules (Loop over the sharp triangles,
 * B-spline along its boundary, corners where that is not a curve) blended with the solid's rows
 * by min(1, s_l), s_l = s - l (docs/RULES.md; the sharp triangles of one vertex or edge: the
 * largest). A triangle's children keep s - 1.
 * Errors (item = the entry, field = SD_SH_FIELD_*): SD_ERR_ARITY, SD_ERR_INDEX, SD_ERR_ARG (not an
 * edge, or not a surface or solid-boundary edge), SD_ERR_VALUE, SD_ERR_DUPLICATE. Replaces earlier
 * sharpness; drops computed levels >= 1. */
enum { SD_CREASE_UNIFORM = 0, SD_CREASE_CHAIKIN = 1 };
typedef struct sd_sharpness {
    uint32_t v[3];
    int nverts;                /* 1 vertex, 2 edge, 3 a triangle inside a solid */
    float value;
} sd_sharpness;
enum { SD_SH_FIELD_SIMPLEX = 0, SD_SH_FIELD_VALUE };
sd_result sd_complex_set_sharpness(sd_complex *c, const sd_sharpness *s, size_t n, int method,
                                   sd_error *err);
/* Per-simplex non-manifold rules (000 Sec. 3.5; docs/RULES.md), for non-manifold vertices and
 * edges of level 0; their descendants at every level keep them:
 *   SD_RULE_N1  (type 1) the rules of dimension `dimension` alone: the simplex follows the rule it
 *               has in C_dimension (the complex of the maximal simplices of that dimension), so
 *               that part subdivides as if the others were absent; the other parts read it as an
 *               ordinary neighbour.
 *   SD_RULE_N2  (types 2 and 4) the rules of the pair of incident maximal simplices `pair` (two
 *               curve segments or two triangles, `pair_size` = 2 or 3 ids each), as if only they
 *               existed: at a vertex, the two whole fans (petals) of triangles around it that hold
 *               them. The chosen curve segments / triangles are marked; a marked simplex may not
 *               meet another N2 simplex whose pair leaves it out.
 *   SD_RULE_G1  a singularity: a vertex is fixed (0-mask), an edge a crease (as a singular tag).
 *   SD_RULE_G2  the default 3-simplex rule with the relieved topology condition (also undoes a
 *               G1 default for this simplex).
 * `nonmanifold_default` (sd_options) picks G2 or G1 for the rest: with G1 the non-manifold edges
 * become creases and the non-manifold vertices on none of them corners. Singular tags win over
 * every override. Errors: SD_ERR_ARG / SD_ERR_INDEX with item = the override and field = one of
 * SD_OV_FIELD_*. Replaces earlier overrides; drops computed levels >= 1. */
typedef struct sd_override {
    uint32_t simplex[2];
    int nverts;                /* 1 vertex, 2 edge */
    sd_rule rule;
    int dimension;             /* N1: 1..3 */
    uint32_t pair[2][3];       /* N2 */
    int pair_size;
} sd_override;
enum { SD_OV_FIELD_SIMPLEX = 0, SD_OV_FIELD_RULE, SD_OV_FIELD_DIMENSION, SD_OV_FIELD_PAIR,
       SD_OV_FIELD_PAIR0, SD_OV_FIELD_PAIR1 };
sd_result sd_complex_set_overrides(sd_complex *c, const sd_override *ov, size_t n, sd_error *err);

/* Petal tags (003 Sec. 2): which corner an open petal of a complex singular vertex makes under
 * nonmanifold_surface = ying-zorin. SD_PETAL_CONVEX (the default: theta = alpha/k), CONCAVE
 * (theta = (2 pi - alpha)/k, then the flatness modification) or SMOOTH (theta = pi/k; petals
 * sharing both singular edges must all be smooth). A petal is named by its vertex and one of its
 * triangles. The vertex must be non-manifold where only triangles meet, not simple (one flower,
 * exactly two boundary or non-manifold edges) and not tagged singular; the petal open (two
 * singular edges: boundary, non-manifold or tagged); one tag per petal. Errors: SD_ERR_INDEX /
 * SD_ERR_ARG with item = the tag and field = SD_PT_FIELD_*. Call after the singular tags; the
 * level-0 triangles of each petal keep the tag, and their children at every level. Replaces
 * earlier petal tags; drops computed levels >= 1. */
enum { SD_PETAL_CONVEX, SD_PETAL_CONCAVE, SD_PETAL_SMOOTH };
typedef struct sd_petal_tag {
    uint32_t vertex, triangle[3];
    int kind;
} sd_petal_tag;
enum { SD_PT_FIELD_VERTEX = 0, SD_PT_FIELD_TRIANGLE, SD_PT_FIELD_KIND };
sd_result sd_complex_set_petals(sd_complex *c, const sd_petal_tag *p, size_t n, sd_error *err);

/* Tangent-plane constraints (003 Sec. 3) under nonmanifold_surface = ying-zorin; each entry one
 * piece of 003's "prescribed tangent and normal data":
 *   SD_TT_NORMAL   the closed petal of complex singular vertex `vertex` holding `triangle` gets
 *                  the normal `vec` (normal modification on every level); entries with the same
 *                  `group` and vec NaN share the unit average of their petals' Loop normals
 *                  (003 Fig. 6(b)), each oriented like the group's first;
 *   SD_TT_TANGENT  the open petal of simple singular vertex `vertex` holding `triangle` gets the
 *                  interior tangent `vec` (tangent modification on every level);
 *   SD_TT_EDGE     the singular edge `edge` interpolates its ends' interior tangents to the
 *                  vertices inserted on it (midpoint rule), at every level; with npair = 2, the
 *                  petals holding pair[0] and pair[1] at each end also get the projections of
 *                  their own interior tangents onto their difference (003 Fig. 6(c)) where no
 *                  SD_TT_TANGENT gives one (one given: the other takes its opposite).
 * Every level uses s = SD_TT_S (3/4). The vertex must be a singular vertex of a triangle-only
 * region and not tagged singular (as for petal tags), the triangle a surface triangle holding
 * it, the petal closed (NORMAL, at a complex vertex) or open with 2 or more triangles (TANGENT,
 * at a simple vertex), vec finite and not zero, an interior tangent not along the singular
 * curve; one entry per petal (NORMAL and TANGENT together); the edge a singular edge (boundary
 * or non-manifold) of triangles only, the pair two different surface triangles holding it.
 * Errors: SD_ERR_INDEX / SD_ERR_ARG / SD_ERR_VALUE with item = the entry and field =
 * SD_TT_FIELD_*. Call after the singular tags; replaces earlier tangent tags; drops computed
 * levels >= 1. Edits of positions on a complex with tangent tags recompute the finer levels
 * whole (the modifications read positions). */
enum { SD_TT_NORMAL, SD_TT_TANGENT, SD_TT_EDGE };
typedef struct sd_tangent_tag {
    int kind;
    uint32_t vertex, triangle[3]; /* NORMAL, TANGENT */
    double vec[3];                /* NORMAL (NaN: shared), TANGENT */
    uint32_t group;               /* NORMAL */
    uint32_t edge[2];             /* EDGE */
    uint32_t pair[2][3];          /* EDGE, npair = 2 */
    int npair;
} sd_tangent_tag;
enum { SD_TT_FIELD_VERTEX = 0, SD_TT_FIELD_TRIANGLE, SD_TT_FIELD_VECTOR, SD_TT_FIELD_EDGE,
       SD_TT_FIELD_PAIR0, SD_TT_FIELD_PAIR1 };
#define SD_TT_S 0.75
sd_result sd_complex_set_tangents(sd_complex *c, const sd_tangent_tag *t, size_t n, sd_error *err);

/* Whether vertex i / edge e of a level belongs to the singular complex. */
int sd_level_vertex_singular(const sd_level *lv, uint32_t i);
int sd_level_edge_singular(const sd_level *lv, uint32_t e);

/* The same for a level whose rules are built already (by one of the calls above): const and
 * lock-free, so it may run while other levels of the complex are being computed. SD_ERR_ARG when
 * the index is out of range or the level's rules are not built. */
sd_result sd_level_vertex_class(const sd_level *lv, uint32_t i, sd_class *out);
sd_result sd_level_edge_class(const sd_level *lv, uint32_t e, sd_class *out);
/* Edge id of the edge a-b at a level, or UINT32_MAX. */
uint32_t sd_level_find_edge(const sd_level *lv, uint32_t a, uint32_t b);   /* builds edges as sd_level_edges */

/* The rule vertex i of a level follows, without building stencils (unlike
 * sd_complex_vertex_class): exact once the level's rules are built or after
 * sd_complex_prepare_vertex_rules; before that, the classification's rule (which a vertex whose
 * neighbourhood does not fit it, e.g. where three creases meet, follows as a corner). */
sd_rule sd_level_vertex_rule(const sd_level *lv, uint32_t i);
sd_result sd_complex_prepare_vertex_rules(sd_complex *c, int level, sd_error *err);

/* The boundary surface of the solids of a level: triangles that are a face of exactly one
 * tetrahedron or octahedron, oriented outward. Returns their number and, if `tri` is not NULL,
 * writes 3 vertex ids per triangle into it. */
uint32_t sd_level_solid_boundary(const sd_level *lv, uint32_t *tri);

/* ---- subdivision matrices --------------------------------------------------------------- */

/* Compressed sparse rows: row r has entries rowptr[r] .. rowptr[r+1]-1. */
typedef struct sd_csr {
    uint32_t nrows, ncols;
    const uint32_t *rowptr;
    const uint32_t *col;
    const double *val;
} sd_csr;

/* The matrix S_L mapping level L points to level L+1 points (built if needed). The complex
 * stores S_L as column indices plus shared weight patterns; the per-entry values of this view
 * are materialized on the first call and kept (counted by sd_complex_memory). */
sd_result sd_complex_matrix(sd_complex *c, int level, sd_csr *out, sd_error *err);

/* ---- edits and detail offsets (004 Sec. 4.1 and 5.2; docs/API.md "Control-point edits") -- */

/* A point of a level: vertex `index` of level `level` (0 = a control point). */
typedef struct sd_vertex_at {
    int level;
    uint32_t index;
} sd_vertex_at;

/* What an edit did (sd_complex_move, sd_complex_set_details); optional, zero it first. */
typedef struct sd_edit_report {
    /* in, optional: called once for each level where points changed, with the indices of the
     * points whose values changed bit for bit (each once, in no particular order) — in the edited
     * channel, or, on a level the edit recomputed whole (rules that read a moved position, see
     * sd_complex_move), in any channel. Called when the edit is complete, before the call
     * returns; it may read the complex but not change it, and idx is valid during the call only.
     * Levels the call computed for its moves report changes against their values before them. */
    void (*changed)(void *ud, int level, const uint32_t *idx, size_t n);
    void *ud;
    /* out, per level (0 beyond the computed levels): the points recomputed (the edited points
     * and, level by level, every point whose row of S reads a recomputed one; all points of a
     * level recomputed whole) and, of those, the points that changed */
    uint64_t recomputed[SD_MAX_LEVEL + 1];
    uint64_t nchanged[SD_MAX_LEVEL + 1];
    /* out: the coarsest level whose rules the edit built again because they read a moved
     * position (see sd_complex_move: its finer levels were recomputed whole), or -1 — what reads
     * more of a level than its channel values (its rules, the rule of each vertex) may have
     * changed there too */
    int rules_rebuilt;
    /* in: an edit that would build a level's rules again changes nothing and returns SD_OK with
     * rules_rebuilt set to that level, recomputed[] what it would have recomputed and no
     * changed() call (sd_complex_edit_in_place) */
    int in_place;
} sd_edit_report;

/* Move points of channel `channel` (0 = positions): point at[i] gets values[i*ncomp ..
 * i*ncomp+ncomp-1]. A control point (level 0) takes the value. A point of level l >= 1 becomes a
 * detail offset (004 Sec. 5.2): d = value - (S_{l-1} p^{l-1}) at that point is stored, and from
 * then on the point is S_{l-1} p^{l-1} + d at every build of its level and after every edit, so
 * an edit at a coarser level moves it and keeps its offset (sd_complex_details lists them).
 * Levels are computed first up to the highest level named. Moves are applied coarse to fine: a
 * level-l offset is taken after the coarser moves of the same call, so the point ends at its
 * value: to the last bit whenever the value is within a factor 2 of the point's subdivided
 * position (componentwise), otherwise within rounding.
 * Every computed level is then updated by recomputation, level by level: each point whose row of
 * S reads a changed point is summed again from its whole row, in the order the level build sums
 * it, plus its offset — so every level is the bytes a new complex built from the edited control
 * points with the same offsets has, and the cost follows the edited region, not the mesh. Where a
 * level's rules read a moved position (Ying-Zorin's corner angle), that level's rules are built
 * again and the finer computed levels recomputed whole.
 * Errors (item = the move, field = the component or -1): SD_ERR_ARG (no such channel, a level
 * outside 0..SD_MAX_LEVEL), SD_ERR_INDEX (index not below the level's vertex count,
 * sd_complex_counts), SD_ERR_VALUE (a value not finite, a position or an offset beyond 1e15 in
 * magnitude), SD_ERR_REPEATED (a point named twice), SD_ERR_NOMEM, SD_ERR_LIMIT. All-or-nothing:
 * on failure the complex is as it was, levels the call computed dropped again. rep: see
 * sd_edit_report. Not thread-safe with readers of the same complex: the caller excludes them. */
sd_result sd_complex_move(sd_complex *c, int channel, size_t n, const sd_vertex_at *at,
                          const double *values, sd_edit_report *rep, sd_error *err);

/* Ask the kernel for transparent huge pages over the 2 MiB-aligned part of a block (madvise
 * MADV_HUGEPAGE on the whole 2 MiB pages inside it, if any; advice only, ignored where
 * unsupported or where the memory is not anonymous). The core's allocations do this themselves,
 * also for the blocks of a plugged sd_allocator; exported for the service's own big buffers. */
void sd_advise_huge(void *p, size_t n);

/* Build now what the first edit of the computed levels would build (the maps that find a level's
 * recomputed points), so that edit costs what later ones do. Optional; SD_ERR_NOMEM leaves them
 * to the edit. Not thread-safe with edits of the same complex (readers are not affected). */
sd_result sd_complex_prepare_edits(sd_complex *c, sd_error *err);

/* sd_complex_move with control points only: point idx[i] (level 0) gets values[i*ncomp ..].
 * counts (optional, SD_MAX_LEVEL+1 entries) receives the points recomputed per level
 * (sd_edit_report.recomputed). */
sd_result sd_complex_edit(sd_complex *c, int channel, size_t n, const uint32_t *idx,
                          const double *values, uint64_t *counts, sd_error *err);
/* sd_complex_edit for callers whose readers keep reading a level's topology and rules without
 * a lock (the daemon's streams): an edit that would rebuild a level's rules changes nothing and
 * sets *rebuild to that level (counts then says what sd_complex_edit would have updated: the
 * full sizes of the finer levels) — the caller builds a new complex from the edited input
 * instead; any other edit is applied through the matrices, *rebuild = -1. So no array a reader
 * holds is ever freed or moved, and only channel values change. */
sd_result sd_complex_edit_in_place(sd_complex *c, int channel, size_t n, const uint32_t *idx,
                                   const double *values, uint64_t *counts, int *rebuild,
                                   sd_error *err);

/* Check a move of control points before sd_complex_edit: point idx[i] to xyz[3i..3i+2]. Every
 * maximal simplex (edge, triangle, tetrahedron) of the control complex that holds a moved
 * point must stay non-degenerate by sd_complex_new's test and tolerance (no edge shorter than
 * 1e-12 of the moved complex's bounding-box diagonal, no area or volume below 1e-12 of its
 * longest edge squared or cubed); orientation does not count, so an inverted tetrahedron is
 * fine. Simplices without a moved point are not looked at (a move that grows the bounding box
 * does not make their edges short: their shape did not change). SD_ERR_DEGENERATE with item =
 * the index i of the latest move among the refused simplex's points. Changes nothing. */
sd_result sd_complex_check_moves(sd_complex *c, size_t n, const uint32_t *idx, const double *xyz,
                                 sd_error *err);

/* The detail offsets of channel `channel` at level `level` (1..SD_MAX_LEVEL): returns their number
 * and, if not NULL, points *idx (ascending indices) and *offsets (ncomp doubles each) at them —
 * borrowed, valid until the next call that changes the complex. Offsets belong to the complex,
 * not to its levels: a level dropped and computed again (tags, rules, a new channel) is built
 * with them, and a level not computed yet keeps them. sd_complex_set_diagonal drops those of
 * levels >= 3, whose points it renumbers. 0 for a bad channel or level. */
size_t sd_complex_details(const sd_complex *c, int channel, int level, const uint32_t **idx,
                          const double **offsets);

/* Replace every detail offset of channel `channel` (all levels) by the n given: point at[i]
 * (level >= 1) gets offsets[i*ncomp ..] (as sd_complex_details lists them, e.g. to restore a
 * stored session). Validated like sd_complex_move (levels 1..SD_MAX_LEVEL; offsets finite and at
 * most 1e15 in magnitude; no point twice); computed levels are updated as by an edit (rep as
 * there), levels not computed only keep the offsets. All-or-nothing. */
sd_result sd_complex_set_details(sd_complex *c, int channel, size_t n, const sd_vertex_at *at,
                                 const double *offsets, sd_edit_report *rep, sd_error *err);

/* ---- local red-green refinement (000 Sec. 4.2) ------------------------------------------ */

typedef struct sd_refinement {
    double *xyz;              /* 3 nv: the old vertices, then one per split edge (midpoints) */
    size_t nv;
    uint32_t *idx;            /* the new simplices, like sd_complex_new's input */
    uint8_t *size;
    size_t ns;
    uint32_t *parent;         /* ns: the input simplex each new simplex comes from */
    uint32_t (*split)[2];     /* nsplit: the ends of the edge each new vertex splits */
    size_t nsplit;
    uint64_t red, green;      /* simplices split red (marked or upgraded) / by a green pattern */
} sd_refinement;

/* Refine a control complex (arrays as for sd_complex_new) red where marked[s] != 0 and green
 * around, so the result is conforming (see core/refine.c for the patterns). A tetrahedron split
 * red cuts its octahedron along its diagonal: diag[s] (0..2, as sd_complex_diagonal gives it for
 * the posted vertex order; diag NULL: pair 0 for all). Untouched simplices keep their vertex
 * lists and order; new vertices follow the old ones, at edge midpoints (move them as you like).
 * Free the result with sd_refine_free (it uses the C library's allocator).
 * lim (NULL: none): the result's sizes are counted before it is allocated, and one past
 * max_vertices or max_simplices (0: no limit) fails with SD_ERR_LIMIT, err->field 0 (vertices)
 * or 1 (simplices) and err->item the count it would have (for simplices, when the marked ones'
 * red children alone pass the limit, that lower bound, found before any work); the working arrays (edges, marks:
 * about 100 bytes per input simplex) come from lim->allocator (NULL: the C library's), whose
 * refusal is SD_ERR_NOMEM. */
typedef struct sd_refine_limits {
    size_t max_vertices, max_simplices;
    const sd_allocator *allocator;
} sd_refine_limits;
sd_result sd_refine(const double *xyz, size_t nv, const uint32_t *idx, const uint8_t *size,
                    size_t ns, const uint8_t *marked, const uint8_t *diag,
                    const sd_refine_limits *lim, sd_refinement *out, sd_error *err);
void sd_refine_free(sd_refinement *r);

/* The tags and per-simplex rules of a complex, in the forms sd_complex_set_singular (idx, size,
 * ntags), sd_complex_set_petals and sd_complex_set_overrides take. */
typedef struct sd_tag_set {
    uint32_t *idx;
    uint8_t *size;
    size_t ntags;
    sd_petal_tag *petals;
    size_t npetals;
    sd_override *overrides;
    size_t noverrides;
    uint32_t *from;            /* out only: per tag, the index of the tag of `in` it comes from */
} sd_tag_set;

/* Carry `in`, given for the complex that refinement r was made from, to the refined complex:
 * children of tagged simplices stay tagged and keep their rules (docs/RULES.md "Priority"). A vertex stays
 * itself; a split edge becomes its two halves, and its N1 / N2 / G2 choice also goes to the
 * vertex splitting it; a triangle becomes its children; a petal tag keeps its vertex and names
 * the child of its triangle there; an N2 pair is replaced by the children holding the new
 * simplex (a choice whose triangle has none is dropped). Whether a carried override still fits
 * the refined complex is sd_complex_set_overrides's to say. Fills *out with new arrays (the C
 * library's allocator, as sd_refine's; free with sd_tag_set_free); SD_ERR_NOMEM leaves it
 * empty. `in` is not changed. */
sd_result sd_refine_carry(const sd_refinement *r, const sd_tag_set *in, sd_tag_set *out,
                          sd_error *err);
void sd_tag_set_free(sd_tag_set *t);

/* ---- local analysis (001 Sec. 4.1, Appendix B) ------------------------------------------- */

typedef struct sd_analysis {
    int size;                 /* n: the matrix is n x n */
    sd_rule rule;
    double *matrix;           /* n*n, row-major */
    double *eig_re, *eig_im;  /* n eigenvalues, largest magnitude first */
    uint32_t *points;         /* n ids of the level the matrix acts on (centre first) */
    int level;                /* that level */
    int closed;               /* every row's support lies inside the block */
} sd_analysis;

/* The most points a block or an invariant neighbourhood may have: larger ones are refused with
 * SD_ERR_ARG (not analysable) before any matrix is made (an eigen-decomposition costs the cube of the size; a
 * regular solid vertex's neighbourhood has 65 points, a valence-k surface vertex's block k + 1).
 * A limit mask that would need the eigenvectors of a larger block has method SD_LIMIT_NONE. */
#define SD_ANALYSIS_MAX_POINTS 256

/* The 1-ring block M ((k+1)x(k+1)) of control vertex v: its vertex point and the edge points
 * of its k edges as functions of v and its 1-ring. */
sd_result sd_analyze_vertex(sd_complex *c, uint32_t v, sd_analysis *out, sd_error *err);
/* The block L ((2k+3)x(2k+3)) of control edge a-b: the 1-ring block of the edge's midpoint
 * after one level (001 Sec. 4.1). */
sd_result sd_analyze_edge(sd_complex *c, uint32_t a, uint32_t b, sd_analysis *out, sd_error *err);
/* The full matrix of the invariant neighbourhood (001 Sec. 4.1, Appendix B): at level 1, the
 * points of the control cells containing vertex v (5k - 5 for an interior solid vertex) or edge
 * a-b (4k + 3), centre and 1-ring first (as the block has them), as S_1 maps them onto their
 * counterparts at level 2 (the scaling about the centre by 1/2; core/analysis.c). SD_ERR_ARG
 * when the neighbourhood is not invariant (a point without its counterpart, a row reading
 * outside it: boundaries, neighbourhoods that need more levels). */
sd_result sd_analyze_full_vertex(sd_complex *c, uint32_t v, sd_analysis *out, sd_error *err);
sd_result sd_analyze_full_edge(sd_complex *c, uint32_t a, uint32_t b, sd_analysis *out, sd_error *err);
void sd_analysis_free(sd_analysis *a);

/* ---- limit positions and normals (001 Sec. 4; docs/RULES.md "Limits"; core/limit.c) ------ */

/* How a limit mask was found: the point is fixed, the cubic B-spline's (2/3 centre, 1/6 each
 * of its two curve neighbours), Loop's (1 - n chi) centre + chi each of its n neighbours with
 * chi = 1 / (n + 3 / (8 beta)), beta the vertex row's (Loop's or Warren's) — or the dominant left
 * eigenvector of the point's 1-ring block of S (analysis.c's), or none (the block is not closed,
 * has no simple dominant eigenvalue 1 or more than SD_ANALYSIS_MAX_POINTS points: the point
 * itself is returned). */
enum { SD_LIMIT_NONE = -1, SD_LIMIT_FIXED = 0, SD_LIMIT_BSPLINE, SD_LIMIT_LOOP, SD_LIMIT_EIGEN };

/* The level whose 1-ring blocks give the limits of level `level`'s points: the finest of
 * `level`, the finest level holding detail offsets (any channel), ceil of the largest semi-sharp
 * sharpness (where every sharpness has expired) and, with solids, 1. A point keeps its index
 * from `level` to it (vertex points come first). */
int sd_complex_limit_level(const sd_complex *c, int level);

/* The limit of every point of level `level` (computed if need be, and the limit level with it):
 * channel `channel`'s values into out (ncomp per point), and, if normals is not NULL, the unit
 * limit normal of each point into normals (3 per point; 0 0 0 where the point has no tangent
 * plane: curves, isolated points, solid interiors, vertices whose triangles are not one fan).
 * Normals are t1 x t2 of OpenSubdiv's Loop limit tangent masks (Sdc::Scheme<SCHEME_LOOP>) on
 * the positions of the limit level, over the point's triangles (maximal triangles and the solids'
 * boundary, as oriented); on an interior crease, the unit sum of its two sides' normals. */
sd_result sd_complex_limit(sd_complex *c, int level, int channel, double *out, double *normals,
                           sd_error *err);

/* One point's limit mask: weights on points of level `level` (the mask of the limit level
 * composed with S down to `level`), and its tangent masks (NULL where it has no single tangent
 * plane, an interior crease included). Free with sd_limit_mask_free. */
typedef struct sd_limit_mask {
    int n;
    uint32_t *points;          /* n ids of level `level` */
    double *w;                 /* the position weights, summing to 1 */
    double *t1, *t2;           /* tangent weights on the same points (sum 0), or NULL */
    int level, eval_level;     /* the level of `points`; the level the mask was taken at */
    int method;                /* SD_LIMIT_* */
    /* what the detail offsets of the levels between (level, eval_level] add (channel 0): the
     * limit position is sum w p + offset, the tangents sum t1 p + t_offset[0] and sum t2 p +
     * t_offset[1] (all 0 without offsets there) */
    double offset[3], t_offset[2][3];
} sd_limit_mask;
sd_result sd_limit_mask_of(sd_complex *c, int level, uint32_t v, sd_limit_mask *out,
                           sd_error *err);
void sd_limit_mask_free(sd_limit_mask *m);

/* ---- embedded models (004 Sec. 5.1, eq. 13; core/embed.c) -------------------------------- */

/* Free-form deformation: each vertex of a user's model is located in a solid cell of a level and
 * bound to the cell's 4 vertices by barycentric coordinates; it then follows the solid as the
 * level's points move (edits change positions in place, so an embedding stays valid while the
 * level's topology does: until the level is dropped, by sd_complex_free, set_diagonal,
 * add_channel, set_singular and the other calls that drop levels). Cells are the level's
 * tetrahedra (0..T-1), then each octahedron o as the 4 tetrahedra around its major diagonal,
 * numbered T + 4o + k, split as the outputs write it: (q,p,a,b), (q,p,b,a2), (q,p,a2,b2),
 * (q,p,b2,a) for an octahedron (p,q,a,a2,b,b2). */
typedef enum { SD_OUTSIDE_REFUSE = 0, SD_OUTSIDE_FIXED, SD_OUTSIDE_NEAREST } sd_outside;
typedef struct sd_embedding sd_embedding;

/* What a bind found: how many model vertices lie in no solid cell, and the first of them
 * (indices into the model, ascending). */
typedef struct sd_bind_report {
    size_t outside;
    size_t first[8];
    int nfirst;
} sd_bind_report;

/* Bind n model vertices (xyz: 3n doubles, copied from) to the solid cells of level lv, read at
 * the time of the call. A vertex goes to the lowest-numbered cell that holds it (on a shared face
 * or in overlapping cells, too): within 1e-12 of the cell's longest edge of each of its face
 * planes. A vertex in no cell, by `mode`: SD_OUTSIDE_REFUSE: SD_ERR_VALUE (item = the first such
 * vertex), nothing returned, rep filled; SD_OUTSIDE_FIXED: it keeps its position (kept in the
 * embedding) whatever the level does; SD_OUTSIDE_NEAREST: bound to the cell whose closest point
 * is nearest to it (the lowest index among equals), its coordinates then outside [0,1] (they
 * still sum to 1 and reproduce the vertex at the current positions). Memory comes from `alloc`
 * (NULL: the C library), at most max_bytes (0: no cap) counting the locating grid while it
 * exists. Errors: SD_ERR_ARG (no lv, out or xyz, an unknown mode), SD_ERR_VALUE (a coordinate
 * not finite: item = the vertex, field = the coordinate; a level without solid cells; refused
 * vertices), SD_ERR_LIMIT (over max_bytes, more than 2^30 vertices or 2^32 cells), SD_ERR_NOMEM,
 * SD_ERR_DEGENERATE (a nearest cell of zero volume: not in a level of a valid complex);
 * SD_ERR_VALUE with field SD_EMBED_TOO_FAR (item = the vertex) when the nearest-cell searches
 * of the vertices outside pass their budget (2048 buckets, boxes and cells looked at a vertex outside, plus
 * 2^24: vertices that thousands of cells are about equally near, such as the centre of a hollow
 * sphere; a vertex near the solid or far from it takes tens; the work of a bind stays bounded).
 * rep (optional) is filled in every mode. On success *out is the caller's, freed with
 * sd_embed_free; it borrows nothing (lv is passed again to read positions). Const on the level:
 * may run beside readers of the complex, not beside an edit. */
#define SD_EMBED_TOO_FAR 3 /* sd_error.field: a "nearest" vertex past the search budget */
sd_result sd_embed_bind(const sd_level *lv, const double *xyz, size_t n, sd_outside mode,
                        const sd_allocator *alloc, size_t max_bytes, sd_embedding **out,
                        sd_bind_report *rep, sd_error *err);
/* An embedding from a binding saved with sd_embed_weights (a session's export): per model
 * vertex its 4 level vertices and weights (idx[4i] = UINT32_MAX: a fixed vertex, kept at
 * rest[3i..]), checked against lv (indices in range, weights finite and summing to 1 within
 * 1e-9 of their magnitudes: SD_ERR_VALUE otherwise, its item the model vertex and its field
 * the entry of [i0..i3, w0..w3] at fault, -1 for the sum). The positions it gives are those of the embedding it was saved
 * from, bit for bit. */
sd_result sd_embed_restore(const sd_level *lv, size_t n, const uint32_t *idx, const double *w,
                           const double *rest, const sd_allocator *alloc, size_t max_bytes,
                           sd_embedding **out, sd_error *err);
void sd_embed_free(sd_embedding *e);
/* The number of model vertices, and the bytes the embedding holds (80 per model vertex + 4 per
 * level vertex; binding takes ~50 more per cell of the level meanwhile). */
size_t sd_embed_count(const sd_embedding *e);
size_t sd_embed_memory(const sd_embedding *e);
/* Vertex i's 4 level vertices and weights (summing to 1): returns 1; 0 (idx, w untouched) when
 * it is fixed or i is out of range. */
int sd_embed_weights(const sd_embedding *e, size_t i, uint32_t idx[4], double w[4]);
/* Every model vertex at the current positions of lv (the level it was bound to): 3n doubles
 * into out; fixed vertices at their rest position. */
void sd_embed_positions(const sd_embedding *e, const sd_level *lv, double *out);
/* After an edit that changed the positions of the `nchanged` level vertices `changed` (any
 * order, repeats and indices beyond the level allowed; e.g. what sd_edit_report.changed gives for
 * this level): recompute the model vertices bound to any of them into out (3n doubles holding
 * the previous positions; the others are not written), write their indices to moved (room for
 * n; ascending, each once) and return how many. Costs what the vertices found do, not n. Not
 * thread-safe on the same embedding (it keeps a stamp per vertex). */
size_t sd_embed_update(sd_embedding *e, const sd_level *lv, const uint32_t *changed,
                       size_t nchanged, double *out, uint32_t *moved);

#ifdef __cplusplus
}
#endif
#endif
