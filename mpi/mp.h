/* mp.h — the pieces of subdivd-mpi (docs/BATCH.md "Partitioned refinement on MPI", DECISIONS 44).
 *
 * Rank 0 reads the mesh into a model exactly as `subdivd refine` does (api/), partitions the
 * level-0 maximal simplices with METIS (part.c), and cuts one mp_piece per rank: the rank's own
 * simplices plus a halo of whole rings of simplices around them, with the vertices, attributes,
 * tags and overrides restricted to that sub-complex, the global choices (diagonals, orientation)
 * of its tetrahedra, the whole complex's level-0 classes and rules where the piece holds an
 * entity's star, and what the rank needs to number its level-L points and cells as the
 * one-process level numbers them (the global ids of its level-0 vertices, edges, faces and cells,
 * and the global counts of every level). A piece travels as one flat byte buffer (mp_pack /
 * mp_unpack). Each rank then builds its sub-complex with the same api/ and core/ code, refines
 * it, maps its entities to global ids level by level (piece.c) and writes the cells it owns
 * (vtu.c).
 *
 * Ownership: every mp_* that allocates says so; mp_piece_free frees a piece's arrays.
 */
#ifndef SUBDIVD_MP_H
#define SUBDIVD_MP_H

#include "../api/model.h"
#include "../core/sd.h"
#include <stddef.h>
#include <stdint.h>

enum { MP_UNCHECKED = 0xff };

/* One rank's share of the control complex, in its local numbering (vertices ascending by global
 * id, simplices ascending by global input index: the sub-complex's own numbering then follows
 * the one-process numbering wherever the star of an entity is whole; piece.c relies on that). */
typedef struct mp_piece {
    int rank, nparts, level;
    int halo;                     /* rings of simplices around the owned ones */
    api_rules rules;              /* the rule preferences (overrides below) */
    sd_counts global[SD_MAX_LEVEL + 1]; /* the one-process counts of levels 0..level */
    uint64_t global_ns;           /* input simplices of the whole mesh */
    uint32_t nv;
    uint32_t *vg;                 /* global vertex id */
    uint8_t *vfull;               /* 1: every simplex around the vertex is in the piece */
    double *xyz;                  /* 3 nv */
    int nattrs;
    api_attribute attrs[API_MAX_ATTRIBUTES]; /* data: nv * ncomp */
    uint32_t ns;                  /* simplices (maximal ones of the whole complex) */
    uint32_t *sg;                 /* global input index */
    uint8_t *ssize;
    uint32_t *sidx;               /* local vertex ids, input order, consecutive */
    int32_t *spart;               /* the rank that owns it */
    uint8_t *sreor;               /* tetrahedra: stored with slots 2 and 3 exchanged */
    int8_t *sdiag;                /* tetrahedra: the diagonal pair in use (else -1) */
    uint32_t *scell;              /* index of the level-0 cell among those of its kind */
    uint32_t ne0, nf0;            /* level-0 edges and faces between piece vertices: */
    uint32_t *e0;                 /* 2 local ids each, in the one-process orientation */
    uint32_t *e0g;                /* their global ids */
    uint32_t *f0;                 /* 3 local ids each, in the one-process order */
    uint32_t *f0g;
    /* the whole complex's level-0 classification (DECISIONS 44): class codes
     * (sd_complex_class_codes) of the entities whose star the piece holds whole (0 for the
     * others: the piece classifies those itself), taken by the piece's core instead of its own;
     * and the rule and valence each vertex of the owned simplices and each edge at one follows
     * in the whole complex (MP_UNCHECKED elsewhere), which the piece checks its own against */
    uint16_t *vcls, *ecls, *fcls; /* nv, ne0, nf0 */
    uint8_t *vrule, *erule;       /* sd_rule or MP_UNCHECKED; nv, ne0 */
    uint32_t *vval, *eval;
    api_tags tags;                /* restricted to the piece, local ids */
    uint32_t nov;
    sd_override *ov;              /* the same for the per-simplex rules */
    uint32_t nhalo;               /* simplices of the piece not owned by it */
} mp_piece;

void mp_piece_free(mp_piece *p);

/* A growable byte buffer (malloc'd; free data). */
typedef struct mp_buf {
    unsigned char *data;
    size_t len, cap;
    int failed;
} mp_buf;

/* Flatten a piece into b (b->failed when out of memory), and back: mp_unpack fills *p with new
 * arrays (mp_piece_free) from `len` bytes; -1 if the bytes are not a whole piece. */
void mp_pack(const mp_piece *p, mp_buf *b);
int mp_unpack(const unsigned char *data, size_t len, mp_piece *p);

/* part.c (rank 0). Partition the maximal simplices of m's level 0 into `nparts` parts with METIS
 * (dual graph: simplices sharing a facet of the smaller one, or a vertex for points and curves;
 * weighted by what each becomes at `level`) and cut the pieces: pieces[r] for rank r, with
 * `halo` rings of simplices (by shared vertices) around the owned ones (-1: the default of
 * DECISIONS 44: three rings with tetrahedra and a non-manifold simplex, two with either or
 * Ying-Zorin's rules in the complex, else one). `seconds` gets the time of the partition alone. 0, or -1 with a message in err. */
int mp_partition(api_model *m, int level, int nparts, int halo, mp_piece *pieces,
                 double *seconds, char *err, size_t errlen);

/* piece.c. What a rank computes from its piece: the level, and the maps that give the global id
 * of every level-L point and cell (those of level L-1, from which level L's follow in closed
 * form: kept 8 times smaller than level L's would be). */
typedef struct mp_maps mp_maps;
typedef struct mp_result {
    const mp_piece *p;
    api_model *m;                 /* the sub-complex's model (NULL for an empty piece) */
    const sd_level *lv;           /* level L of it */
    mp_maps *g;
    int32_t *vowner;              /* per level-L vertex: the lowest rank owning a cell around it */
    uint32_t ncell[5];            /* per sd_cell_kind */
    uint64_t owned_cells, local_cells; /* top cells of level L: owned / in the piece */
    uint64_t classes_shipped;     /* level-0 vertices, edges and faces given the whole complex's
                                   * class; of those, how many differed from the piece's own */
    uint64_t classes_differing;
    uint64_t rules_checked;       /* level-0 vertices and edges whose rule and valence were
                                   * checked equal to the whole complex's */
    double seconds_build, seconds_refine, seconds_ids;
} mp_result;

/* Level-L vertex v's index in the one-process level; cell i of kind k's index among that
 * level's cells of its kind; the piece's simplex (local input index) the cell descends from. */
uint64_t mp_vgid(const mp_result *r, uint32_t v);
uint64_t mp_cgid(const mp_result *r, int k, uint32_t i);
uint32_t mp_csrc(const mp_result *r, int k, uint32_t i);
static inline int mp_cown(const mp_result *r, int k, uint32_t i)
{
    return r->p->spart[mp_csrc(r, k, i)] == r->p->rank;
}

/* Build the piece's sub-complex, compute its level `p->level` (a line per level on stderr,
 * prefixed `tag`, unless quiet) and map it to global ids. 0, or -1 with a message in err. */
int mp_refine(const mp_piece *p, uint64_t max_bytes, int quiet, const char *tag, mp_result *r,
              char *err, size_t errlen);
void mp_result_free(mp_result *r);

/* vtu.c. The rank's owned cells as one VTU piece (appended raw binary): the points they use with
 * point data global_id, owner, rule and the attributes, cell data kind, cell_id (the one-process index
 * within its kind) and control_cell (the input simplex). An octahedron is written as its 4
 * tetrahedra around the major diagonal, as `subdivd refine` writes VTU. 0 or -1 + err. */
int mp_write_piece(const mp_piece *p, const mp_result *r, const char *path, uint64_t *bytes,
                   char *err, size_t errlen);
/* The .pvtu index over `nparts` pieces named by `piece_name(r)` (relative to the .pvtu). */
int mp_write_pvtu(const char *path, const mp_piece *p, int nparts, char **piece_names, char *err,
                  size_t errlen);
/* The owned cells as a byte blob for rank 0 (mp_merge_write), and the merged VTU: points in
 * one-process order (every point of the level), cells sorted by kind and one-process index —
 * the order of `subdivd refine`'s VTU. */
void mp_merge_blob(const mp_piece *p, const mp_result *r, mp_buf *b);
int mp_merge_write(const char *path, const mp_piece *p0, const unsigned char *const *blobs,
                   const size_t *lens, int n, uint64_t *bytes, char *err, size_t errlen);

/* helpers (piece.c) */
void mp_buf_put(mp_buf *b, const void *d, size_t n);
double mp_now(void);

#endif
