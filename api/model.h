/* model.h — what one session holds: the posted control complex, its tags and rule choices, and
 * the core complex built from them (with its cached levels).
 *
 * A model is immutable once published, except for the core complex's lazily computed levels,
 * which only grow and are computed under `lock`. Every change (PUT complex, tags, rules) builds a
 * new model next to the old one and the session swaps the pointer, so a request that is still
 * streaming a level of the old model keeps reading valid memory: models are reference counted
 * (api_model_ref / api_model_unref) and the last holder frees them.
 *
 * The posted input (coordinates, simplices, attributes) is shared between successive models of a
 * session through its own reference count, since tags and rules changes do not copy it.
 *
 * Memory (api/mem.h): the structs, diagonals, fill statistics and caches are api_malloc blocks;
 * the arrays of api_input (xyz, size, idx, attribute data), of api_tags and the overrides of
 * api_rules are C-library blocks (api_plain_*), since sd_refine hands over C-library arrays and
 * the refine bodies of api/refine.c release these with free(). The input's arrays are counted
 * against the memory budget through its `reserved` bytes, and the core complex allocates with
 * api_mem_core_allocator (api/mem.h): one budget bounds sessions and requests alike.
 */
#ifndef SUBDIVD_MODEL_H
#define SUBDIVD_MODEL_H

#include "../core/sd.h"
#include "limits.h"
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

struct json_t;

typedef struct api_attribute {
    char name[API_MAX_ATTRIBUTE_NAME + 1];
    int ncomp;
    int scalar_form;          /* posted as plain numbers (ncomp 1) rather than arrays */
    double *data;             /* nv * ncomp */
} api_attribute;

/* What one entry of "fill" added (api/fill.c): tets are simplices [first_simplex, +tets),
 * TetGen's Steiner points vertices [first_vertex, +added_vertices). */
typedef struct api_fill_stats {
    uint32_t surface_triangles, tets, added_vertices, first_vertex, first_simplex;
    double volume;            /* of the tetrahedra */
    double largest;           /* volume of the largest tetrahedron */
    double max_volume;        /* as asked (0: none) */
    double largest_ratio;     /* largest radius-edge ratio (circumradius / shortest edge) */
    double min_ratio;         /* as asked (0: none) */
} api_fill_stats;

typedef struct api_input {
    atomic_int refs;
    uint32_t nv;
    double *xyz;              /* 3 nv */
    uint32_t ns;
    uint8_t *size;            /* ns */
    uint32_t *idx;            /* sum of sizes */
    int nattrs;
    api_attribute attrs[API_MAX_ATTRIBUTES];
    uint32_t ndiag;           /* major diagonals chosen by the client: */
    uint32_t (*diag)[2];      /* (simplex index, pair 0..2) */
    uint8_t *reoriented;      /* ns bytes (api_malloc) or NULL: which tetrahedra the core stores
                               * with slots 2 and 3 exchanged (sd_options.reoriented); recorded
                               * when the input is first built, so a rebuild (rules, tags, an
                               * edit that changes rules) keeps the numbering even after edits
                               * turned tetrahedra inside out */
    uint32_t nfill;           /* "fill" entries run; their tets and points are in the arrays above */
    api_fill_stats *fill;
    size_t reserved;          /* bytes of the C-library arrays above counted against the memory
                               * budget (api_input_reserve; given back by the last unref) */
    struct json_t *repaired;  /* PUT /complex "repair": what was dropped (api/repair.c), shared
                               * read-only by copies; NULL without a repair */
    const sd_level0_classes *classes; /* borrowed, or NULL: level-0 classes computed elsewhere
                               * (sd_options.classes; subdivd-mpi's pieces), read only while a
                               * model is built from this input (the caller clears it after);
                               * not copied by api_input_copy */
} api_input;

/* The rule preferences of PUT /rules (docs/API.md); zero = the default. */
typedef struct api_rules {
    int solid_scheme;         /* SD_SOLID_* */
    int surface_weights;      /* SD_WEIGHTS_* */
    int nonmanifold_default;  /* SD_NM_* */
    int nonmanifold_surface;  /* SD_NMSURF_* */
    int crease_method;        /* SD_CREASE_*: how semi-sharp creases decrease */
    uint32_t noverrides;      /* per-simplex choices (owned by the model that holds them) */
    sd_override *overrides;
} api_rules;

/* The last "crease_angle" of PUT /tags (api/crease.c): its edges are among the singular tags. */
typedef struct api_crease {
    bool set;                 /* given with the tags now in force */
    double degrees;
    uint32_t tagged;          /* edges over the angle (some may also have been listed) */
} api_crease;

/* A sharpness of PUT /tags: a vertex, an edge or a triangle and its value as given (>= 10: infinitely sharp,
 * applied as a singular tag). */
typedef struct api_sharp {
    uint32_t v[3];
    int nverts;                /* 1 vertex, 2 edge, 3 triangle inside a solid */
    double value;
} api_sharp;

/* Tags (PUT /tags): n singular simplices of 1..3 vertex ids, stored consecutively, npet petal
 * tags (corner kinds of open petals, 003 Sec. 2) and nsh sharpness values. */
typedef struct api_tags {
    uint32_t n;
    uint8_t *size;
    uint32_t *idx;
    uint32_t *from;           /* the request's entry of each of the first nfrom singular tags
                               * where an import dropped repeats (NULL: entry i is tag i; tags
                               * crease_angle adds after them have no entry); an error names
                               * that entry. Not part of a model's copy. */
    uint32_t nfrom;
    uint32_t npet;
    sd_petal_tag *pet;
    uint32_t nsh;
    api_sharp *sh;
    api_crease crease;        /* what "crease_angle" added (api/crease.c), for the report */
    /* tangent-plane constraints (003 Sec. 3): "normals" (one entry per petal, group = the
     * entry), then "tangents", then "tangent_edges", in the core's form; nnormals and ntangents
     * count the JSON entries of the first two lists */
    uint32_t ntt, nnormals, ntangents;
    sd_tangent_tag *tt;
} api_tags;

typedef struct api_model {
    atomic_int refs;
    pthread_mutex_t lock;     /* serialises computation on `c`, edits, and the snapshots that
                               * level streams take when they open */
    pthread_rwlock_t data;    /* readers of the input that do not take `lock` (GET /complex
                               * copies positions and attributes) vs edits, which change
                               * positions and attributes in place */
    api_input *in;            /* NULL: no complex posted yet */
    api_rules rules;
    api_tags tags;            /* owned copy */
    sd_complex *c;            /* NULL iff in == NULL */
    const sd_level *level0;   /* level 0 with its rules built (read without the lock) */
    int channel[API_MAX_ATTRIBUTES]; /* core channel id of each attribute */
    double seconds[SD_MAX_LEVEL + 1]; /* time spent computing each level (under lock) */
    struct json_t *summary;   /* level-0 summary (docs/API.md PUT /complex), read-only once built */
    struct out_geometry *geometry[SD_MAX_LEVEL + 1]; /* glTF geometry per level, built under lock */
    struct api_delta *delta;  /* what edits changed in the computed levels (api/delta.h), under lock */
    struct api_embed *embed;  /* API_MAX_EMBEDDED embedded models (api/embedded.h), nembed in use;
                               * under lock */
    int nembed;
    /* published figures, readable without the lock */
    atomic_int levels_cached;
    atomic_size_t memory_bytes;
    _Atomic double progress;  /* while levels are computed: the fraction of that work done (by
                               * the bytes the levels take, sd_complex_estimate_bytes); else -1 */
    /* the session version of the model's content: set when the model is published and by
     * every edit (under both locks), so a reader that copies what edits change reads, with
     * the same lock held, the version of what it copied (a response's ETag is its content's) */
    _Atomic uint64_t version;
} api_model;

api_input *api_input_new(void);
void api_input_unref(api_input *in);
/* A deep copy of an input (a new one, reference 1), its arrays reserved; NULL without memory. */
api_input *api_input_copy(const api_input *in);
/* Count n more bytes of the input's C-library arrays against the memory budget (api/mem.h),
 * before allocating them; false when they do not fit. */
bool api_input_reserve(api_input *in, size_t n);
/* Reserve whatever the input's arrays hold beyond in->reserved (for arrays adopted from
 * elsewhere: sd_refine's); false when it does not fit. */
bool api_input_account(api_input *in);
/* The index of the attribute called `name`, or -1. */
int api_input_find_attr(const api_input *in, const char *name);

/* A new model from an input (borrowed: the model takes its own reference; may be NULL) and
 * rules; builds and classifies the core complex under `max_bytes`. NULL + err on failure. */
api_model *api_model_new(api_input *in, const api_rules *rules, uint64_t max_bytes, bool batch,
                         sd_error *err);
/* Apply per-simplex rule overrides to a model being built (copies them into m->rules).
 * SD_ERR_* + err (item = the override, field = SD_OV_FIELD_*). */
int api_model_set_overrides(api_model *m, const sd_override *ov, uint32_t n, sd_error *err);
api_model *api_model_ref(api_model *m);
void api_model_unref(api_model *m);

/* Apply singular and petal tags and sharpness to a model being built (copies them). SD_ERR_* +
 * err (item = the tag); *which says which list the refused tag is in (API_TAG_*; field =
 * SD_PT_FIELD_* for a petal, SD_SH_FIELD_* for a sharpness). */
enum { API_TAG_SINGULAR, API_TAG_PETAL, API_TAG_SHARPNESS, API_TAG_TANGENT };
int api_model_set_tags(api_model *m, const api_tags *t, sd_error *err, int *which);
/* Whether t holds anything. */
static inline bool api_tags_any(const api_tags *t)
{
    return t->n || t->npet || t->nsh || t->ntt || t->crease.set;
}
/* The JSON pointer (/normals/0/triangles/1, /tangents/2/tangent, ...) of core tangent tag `item`'s
 * field (SD_TT_FIELD_*), for a refused one. */
void api_tangent_ptr(const api_tags *t, long item, int field, char *ptr, size_t n);
/* The "normals", "tangents" and "tangent_edges" members of t's JSON form into obj (none when
 * empty). */
void api_tangents_json(const api_tags *t, struct json_t *obj);
/* A deep copy of src into *dst (arrays never NULL); false (dst empty) for lack of memory. */
bool api_tags_copy(api_tags *dst, const api_tags *src);
/* Free t's arrays (the C library's blocks) and empty it. */
void api_tags_free(api_tags *t);

/* Compute level L (under the model's lock) and record the time; NULL + err on failure. The
 * caller holds m->lock. The computation uses the calling thread's compute threads (below). */
const sd_level *api_model_level_locked(api_model *m, int level, sd_error *err);

/* The threads a computation started by the calling thread may use (sd_complex_set_threads):
 * 1 unless set. The daemon sets it when a request takes a compute slot (from --level-threads
 * and the slots busy then) and back to 1 when it gives the slot; the offline modes set it
 * once. Thread-local. */
void api_set_compute_threads(int n);
int api_compute_threads(void);

/* Refresh levels_cached and memory_bytes after the complex changed (caller holds m->lock). */
void api_model_publish(api_model *m);

/* The glTF geometry (solid boundary, normals) of a computed level, built once (NULL if out of
 * memory — writers then compute their own). The caller holds m->lock. */
struct out_geometry *api_model_geometry_locked(api_model *m, int level);

#endif
