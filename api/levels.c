/* levels.c — GET /levels/{L} and GET /levels/{L}/stats (docs/API.md "Levels"): the level query
 * (format, parts, slice, attributes, colormap, octahedra) into an out_request, the limits checked
 * before a level is computed, and the stream opened on it.
 *
 * A level is computed under the model's lock (api_model_level_locked), in a compute slot taken
 * only once that lock is held (api_level_compute). A stream copies, under the same lock, what
 * edits change in place — the level's points and the requested channels — and takes a reference
 * on the cached glTF geometry, with the version of that content; it then holds no lock while
 * the client reads, and an edit never waits for it (the level's topology and rules, which the
 * writers also read, stay as they are while the model lives: api/edit.c). Formats come from the table of api/formats.c; the glTF ones get the per-level cached
 * geometry. api_estimate_bytes is the core's estimate the session memory limit is checked with.
 */
#include "embedded.h"
#include "handlers.h"
#include "internal.h"
#include "mem.h"
#include <ctype.h>
#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- levels ------------------------------------------------------------------------------- */

int api_parse_level(const char *s, api_problem *p)
{
    char *end;
    errno = 0;
    if (!s || !*s || !isdigit((unsigned char)*s))
        return -(api_fail_at(p, 400, "bad-level", "level",
                             "the level must be a non-negative integer") != 0);
    long l = strtol(s, &end, 10);
    if (*end)
        return -(api_fail_at(p, 400, "bad-level", "level",
                             "the level must be a non-negative integer") != 0);
    if (errno || l > SD_MAX_LEVEL)
        return -(api_fail_at(p, 422, "level-out-of-range", "level",
                             "level %.20s is out of range 0..%d", s, SD_MAX_LEVEL) != 0);
    return (int)l;
}

uint64_t api_estimate_bytes(const sd_complex *c, int level)
{
    return sd_complex_estimate_bytes(c, level); /* the core's per-entity sizes */
}

int api_check_level_limits(api_model *m, int level, const api_limits *lim, api_problem *p)
{
    sd_counts n;
    sd_complex_counts(m->c, level, &n);
    uint64_t cells = n.points + n.curves + n.triangles + n.tetrahedra + n.octahedra;
    if (cells > lim->max_cells)
        return api_fail_limit(p, "max_cells", lim->max_cells, cells,
                              "level %d has %llu cells, over the limit of %llu per level; ask for "
                              "a lower level or refine locally", level, (unsigned long long)cells,
                              (unsigned long long)lim->max_cells);
    /* what the session holds and the levels it has, as one pair: another request may be
     * computing a level of this model (under m->lock, which this check does not take), and the
     * core's own count of levels is that thread's to write; api_model_publish stores the levels,
     * then the bytes, so levels read the same on both sides of the bytes belong with them */
    int have, again;
    uint64_t need;
    do {
        have = atomic_load(&m->levels_cached);
        need = atomic_load(&m->memory_bytes);
        again = atomic_load(&m->levels_cached);
    } while (have != again);
    for (int l = have; l <= level; l++)
        need += sd_complex_estimate_level_bytes(m->c, l);
    if (need > lim->max_session_bytes)
        return api_fail_limit(p, "max_session_bytes", lim->max_session_bytes, need,
                              "level %d needs about %llu bytes, over the session limit of %llu; "
                              "ask for a lower level", level, (unsigned long long)need,
                              (unsigned long long)lim->max_session_bytes);
    /* a level the whole memory budget cannot hold is refused before any of it is built: no
     * retry helps (it was built until the budget ran out, then answered 503 memory-budget) */
    size_t budget = api_mem_budget();
    if (budget && need > budget)
        return api_fail_limit(p, "max_memory", budget, need,
                              "level %d needs about %llu bytes, more than the daemon's memory "
                              "budget (--max-memory, %zu bytes) holds; ask for a lower level or "
                              "raise --max-memory", level, (unsigned long long)need, budget);
    return 0;
}

/* Comma-separated list item iteration: copies the next item into buf; returns 0 at the end, 1
 * for an item, 2 for an item longer than buf holds (refused by the callers: a cut item would
 * name another part or attribute, or another number). An empty text has no items; after a comma
 * there is always one more (possibly empty: "a," is "a" and "", refused like ",a"). */
static int next_item(const char **s, char *buf, size_t cap)
{
    if (!*s)
        return 0;
    const char *e = strchr(*s, ',');
    size_t n = e ? (size_t)(e - *s) : strlen(*s);
    snprintf(buf, cap, "%.*s", (int)(n < cap ? n : cap - 1), *s);
    *s = e ? e + 1 : NULL;
    return n < cap ? 1 : 2;
}

/* A list's start for next_item: none for an absent or empty text. */
static const char *list_start(const char *text)
{
    return text && *text ? text : NULL;
}

/* A finite number written in decimal: [+-]digits[.digits][e[+-]digits] as strtod reads it, but
 * none of what strtod also takes (leading blanks, hexadecimal, inf, nan); strtod's ERANGE on
 * underflow (1e-320: a subnormal or 0) is not an error, only overflow is (C11 7.22.1.3: HUGE_VAL
 * then). */
static int parse_double(const char *s, double *x)
{
    char *end;
    if (!*s || strspn(s, "0123456789+-.eE") != strlen(s))
        return 0;
    errno = 0;
    *x = strtod(s, &end);
    return !*end && (!errno || (errno == ERANGE && fabs(*x) <= DBL_MIN)) && isfinite(*x);
}

static int add_attr(const api_model *m, out_request *rq, int a)
{
    for (int i = 0; i < rq->nattrs; i++)
        if (rq->attrs[i].channel == m->channel[a])
            return i;
    out_attr *o = &rq->attrs[rq->nattrs];
    o->name = m->in->attrs[a].name;
    o->channel = m->channel[a];
    o->ncomp = m->in->attrs[a].ncomp;
    return rq->nattrs++;
}

int api_parse_parts(const char *text, unsigned *parts, api_problem *p)
{
    static const char *const names[] = {"points", "curves", "surfaces", "solids", "embedded"};
    char item[64];
    *parts = OUT_PART_ALL;
    if (!text)
        return 0;
    *parts = 0;
    text = list_start(text);
    for (int r; (r = next_item(&text, item, sizeof item));) {
        int k = r == 1 ? 0 : 5; /* 2: an item too long to be a name */
        while (k < 5 && strcmp(item, names[k]))
            k++;
        if (k == 5)
            return api_fail_at(p, 422, "unknown-value", "parts",
                               "parts: \"%.20s\" is not one of points, curves, surfaces, solids, "
                               "embedded", item);
        if (*parts & (1u << k)) /* as attributes= and its repeated names */
            return api_fail_at(p, 422, "repeated-part", "parts", "parts: \"%s\" is named twice",
                               names[k]);
        *parts |= 1u << k; /* 1 << 4 is OUT_PART_EMBEDDED */
    }
    if (!*parts)
        return api_fail_at(p, 422, "unknown-value", "parts", "parts: name at least one part");
    return 0;
}

static int parse_query(const api_model *m, const api_level_query *q, out_request *rq,
                       const out_format **fmt, api_problem *p)
{
    char item[64];
    *fmt = &out_formats[0];
    if (q->format && !(*fmt = out_format_find(q->format))) {
        char names[128];
        return api_fail_at(p, 422, "unknown-value", "format", "format \"%.20s\" is not one of %s",
                           q->format, out_format_list(names, sizeof names, false, ", ", ", "));
    }
    if (api_parse_parts(q->parts, &rq->parts, p))
        return p->status;
    if ((rq->parts & OUT_PART_EMBEDDED) && strcmp((*fmt)->name, "glb") && strcmp((*fmt)->name, "gltf"))
        return api_fail_at(p, 422, "not-applicable", "parts",
                           "parts: embedded applies to format glb and gltf only, not %s",
                           (*fmt)->name);
    if (q->slice) {
        const char *s = list_start(q->slice);
        int k = 0;
        for (int r; (r = next_item(&s, item, sizeof item));) {
            if (k == 4 || r != 1 || !parse_double(item, &rq->slice[k]))
                return api_fail_at(p, 422, "bad-slice", "slice",
                                   "slice: nx,ny,nz,d, four finite numbers");
            k++;
        }
        if (k != 4)
            return api_fail_at(p, 422, "bad-slice", "slice", "slice: nx,ny,nz,d, four finite numbers");
        if (rq->slice[0] == 0 && rq->slice[1] == 0 && rq->slice[2] == 0)
            return api_fail_at(p, 422, "bad-slice", "slice", "slice: the normal must not be zero");
        rq->has_slice = 1;
    }
    rq->colormap_attr = -1;
    const api_input *in = m->in;
    if (q->attributes) {
        const char *s = list_start(q->attributes);
        for (int r; (r = next_item(&s, item, sizeof item));) {
            if (r != 1) /* refused, never cut: the item is not shown cut either */
                return api_fail_at(p, 422, "unknown-attribute", "attributes",
                                   "attributes: an item longer than %d characters (attribute "
                                   "names have at most %d)", (int)sizeof item - 1,
                                   API_MAX_ATTRIBUTE_NAME);
            int a = api_input_find_attr(in, item);
            if (a < 0) /* the whole item: at most 63 characters */
                return api_fail_at(p, 422, "unknown-attribute", "attributes",
                                   "attributes: no attribute \"%s\" in this complex", item);
            for (int i = 0; i < rq->nattrs; i++)
                if (rq->attrs[i].channel == m->channel[a]) /* docs/OUTPUTS.md */
                    return api_fail_at(p, 422, "repeated-attribute", "attributes",
                                       "attributes: \"%s\" is named twice", item);
            add_attr(m, rq, a);
        }
    } else
        for (int a = 0; a < in->nattrs; a++)
            add_attr(m, rq, a);
    if (q->colormap) {
        char name[API_MAX_ATTRIBUTE_NAME + 1];
        const char *c1 = strchr(q->colormap, ':'), *c2 = c1 ? strchr(c1 + 1, ':') : NULL;
        double lo, hi;
        char num[40];
        if (!c1 || !c2 || (size_t)(c1 - q->colormap) > API_MAX_ATTRIBUTE_NAME ||
            (size_t)(c2 - c1 - 1) >= sizeof num)
            return api_fail_at(p, 422, "bad-colormap", "colormap", "colormap: NAME:min:max");
        snprintf(name, sizeof name, "%.*s", (int)(c1 - q->colormap), q->colormap);
        snprintf(num, sizeof num, "%.*s", (int)(c2 - c1 - 1), c1 + 1);
        if (!parse_double(num, &lo) || !parse_double(c2 + 1, &hi) || !(lo < hi))
            return api_fail_at(p, 422, "bad-colormap", "colormap",
                               "colormap: min and max must be finite numbers with min < max");
        int a = api_input_find_attr(in, name);
        if (a < 0)
            return api_fail_at(p, 422, "unknown-attribute", "colormap",
                               "colormap: no attribute \"%s\" in this complex", name);
        if (strcmp((*fmt)->name, "glb") && strcmp((*fmt)->name, "gltf")) /* COLOR_0 is glTF's */
            return api_fail_at(p, 422, "not-applicable", "colormap",
                               "colormap: applies to format glb and gltf only, not %s (VTK and "
                               "JSON carry the attribute itself)", (*fmt)->name);
        rq->colormap_attr = add_attr(m, rq, a);
        rq->colormap_min = lo;
        rq->colormap_max = hi;
    }
    if (q->octahedra) {
        if (!strcmp(q->octahedra, "polyhedra"))
            rq->octahedra_as_polyhedra = 1;
        else if (strcmp(q->octahedra, "tets"))
            return api_fail_at(p, 422, "unknown-value", "octahedra",
                               "octahedra: \"tets\" (4 tetrahedra each) or \"polyhedra\"");
        if (strcmp((*fmt)->name, "vtu") && strcmp((*fmt)->name, "vtk"))
            return api_fail_at(p, 422, "not-applicable", "octahedra",
                               "octahedra: applies to format vtu and vtk only, not %s",
                               (*fmt)->name);
    }
    if (q->limit) {
        if (!strcmp(q->limit, "true"))
            rq->limit = true;
        else if (strcmp(q->limit, "false"))
            return api_fail_at(p, 422, "unknown-value", "limit", "limit: \"true\" or \"false\"");
    }
    bool vtk = !strcmp((*fmt)->name, "vtu") || !strcmp((*fmt)->name, "vtk");
    if (q->names) {
        if (!strcmp(q->names, "true"))
            rq->field_names = 1;
        else if (strcmp(q->names, "false"))
            return api_fail_at(p, 422, "unknown-value", "names", "names: \"true\" or \"false\"");
        if (!vtk)
            return api_fail_at(p, 422, "not-applicable", "names",
                               "names: applies to format vtu and vtk only, not %s", (*fmt)->name);
    }
    if (q->compress) {
        if (!strcmp(q->compress, "zlib"))
            rq->compress = OUT_COMPRESS_ZLIB;
        else if (strcmp(q->compress, "none"))
            return api_fail_at(p, 422, "unknown-value", "compress",
                               "compress: \"none\" or \"zlib\"");
        if (strcmp((*fmt)->name, "vtu")) /* none as well: like names=false, docs/OUTPUTS.md */
            return api_fail_at(p, 422, "not-applicable", "compress",
                               "compress: applies to format vtu only, not %s", (*fmt)->name);
    }
    return 0;
}

int api_level_compute(api_model *m, int level, const api_slot *slot, api_problem *p)
{
    if (!m->c || atomic_load(&m->levels_cached) > level)
        return 0;
    /* the model's lock first: a request waiting for its own session's computation holds no
     * compute slot, so other sessions' work goes on meanwhile */
    pthread_mutex_lock(&m->lock);
    int rc = 0;
    if (atomic_load(&m->levels_cached) <= level &&
        !(slot && (rc = slot->take(slot->ud, level, p)))) {
        sd_error e = {0};
        if (!api_model_level_locked(m, level, &e))
            rc = api_fail_core(p, &e, NULL, NULL);
        if (slot)
            slot->give(slot->ud);
    }
    pthread_mutex_unlock(&m->lock);
    return rc;
}

/* The session's embedded models as they are drawn now (each at its own level, m->lock held), into
 * mesh and rq->meshes; the positions are the caller's to free (rq->nmeshes of them). */
static bool embedded_meshes(api_model *m, out_mesh *mesh, out_request *rq, sd_error *e)
{
    rq->meshes = mesh;
    rq->nmeshes = 0;
    for (int i = 0; i < m->nembed; i++) {
        const api_embed *em = &m->embed[i];
        const sd_level *lv = sd_complex_level(m->c, em->def->level, e);
        double *x = lv ? api_malloc(3 * sizeof *x * ((size_t)em->def->nv + 1)) : NULL;
        if (!x) {
            if (lv) {
                e->code = SD_ERR_NOMEM;
                snprintf(e->message, sizeof e->message, "out of memory placing the embedded models");
            }
            return false;
        }
        sd_embed_positions(em->bind, lv, x);
        mesh[rq->nmeshes++] = (out_mesh){em->def->name, em->def->nv, em->def->nt, x, em->def->tri};
    }
    return true;
}

int api_level_open(api_model *m, int level, const api_level_query *q, const api_limits *lim,
                   const api_slot *slot, out_stream **out, const out_format **fmt,
                   uint64_t *version, api_problem *p)
{
    *out = NULL;
    if (!m->c)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    out_request rq;
    memset(&rq, 0, sizeof rq);
    if (parse_query(m, q, &rq, fmt, p) || api_check_level_limits(m, level, lim, p) ||
        api_level_compute(m, level, slot, p))
        return p->status;
    bool drawn = rq.parts & OUT_PART_ALL; /* parts=embedded alone writes nothing of the level */
    if (!drawn)
        rq.limit = false;
    if (rq.limit) {
        /* limits are read at the limit level (offsets, sharpness, solids: core/limit.c), which
         * is computed like any level the client asks for */
        pthread_mutex_lock(&m->lock);
        int e = sd_complex_limit_level(m->c, level);
        pthread_mutex_unlock(&m->lock);
        if (e > level && (api_check_level_limits(m, e, lim, p) || api_level_compute(m, e, slot, p)))
            return p->status;
    }
    rq.complex = m->c;
    rq.level = level;
    rq.snapshot = drawn;
    sd_error e = {0};
    /* under the lock that edits take: the points, the channels, the normals, the embedded
     * models and the version are of one moment; then the stream holds no lock while the client
     * reads */
    out_mesh mesh[API_MAX_EMBEDDED];
    _Static_assert(API_MAX_EMBEDDED <= OUT_MAX_MESHES, "a GLB holds every embedded model");
    pthread_mutex_lock(&m->lock);
    if (api_model_level_locked(m, level, &e) &&
        (!(rq.parts & OUT_PART_EMBEDDED) || embedded_meshes(m, mesh, &rq, &e))) {
        if ((*fmt)->geometry && !rq.limit && drawn)
            rq.geometry = api_model_geometry_locked(m, level);
        rq.version = atomic_load(&m->version);
        *out = out_open(&rq, *fmt, &e);
        api_model_publish(m); /* the writer may have built the level's vertex rules */
    }
    for (int i = 0; i < rq.nmeshes; i++)
        api_free((void *)mesh[i].xyz);
    pthread_mutex_unlock(&m->lock);
    if (!*out)
        return e.code == SD_ERR_ARG ? api_fail(p, 422, "invalid-argument", "%s", e.message)
                                    : api_fail_core(p, &e, NULL, NULL);
    *version = rq.version;
    return 0;
}

json_t *api_level_stats(api_model *m, int level, const api_limits *lim, const api_slot *slot,
                        api_problem *p)
{
    if (!m->c) {
        api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
        return NULL;
    }
    if (api_check_level_limits(m, level, lim, p) || api_level_compute(m, level, slot, p))
        return NULL;
    sd_error e = {0};
    pthread_mutex_lock(&m->lock);
    const sd_level *lv = api_model_level_locked(m, level, &e);
    json_t *bytes = json_object();
    double secs = m->seconds[level];
    for (const out_format *f = out_formats; lv && f->name; f++) {
        out_request rq;
        memset(&rq, 0, sizeof rq);
        rq.complex = m->c;
        rq.level = level;
        rq.parts = OUT_PART_ALL;
        rq.colormap_attr = -1;
        rq.version = atomic_load(&m->version); /* in the output (glTF asset.extras, VTK title) */
        for (int a = 0; m->in && a < m->in->nattrs; a++)
            add_attr(m, &rq, a); /* a level's default: every attribute (parse_query) */
        if (f->geometry)
            rq.geometry = api_model_geometry_locked(m, level);
        out_stream *s = out_open(&rq, f, &e);
        if (s && out_size(s) != UINT64_MAX)
            json_object_set_new(bytes, f->name, json_integer((json_int_t)out_size(s)));
        out_close(s);
    }
    api_model_publish(m); /* the writers may have built the level's vertex rules */
    pthread_mutex_unlock(&m->lock);
    if (!lv) {
        json_decref(bytes);
        api_fail_core(p, &e, NULL, NULL);
        return NULL;
    }
    sd_counts n;
    sd_complex_counts(m->c, level, &n);
    uint64_t est = 0; /* what levels 1..L take by the estimate the limits are checked with */
    for (int l = 1; l <= level; l++)
        est += sd_complex_estimate_level_bytes(m->c, l);
    return json_pack("{s:i, s:{s:I, s:I, s:I, s:I, s:I, s:I, s:I, s:I}, s:o, s:f, s:I, s:I}", "level",
                     level, "counts", "vertices", (json_int_t)n.vertices, "edges",
                     (json_int_t)n.edges, "faces", (json_int_t)n.faces, "points",
                     (json_int_t)n.points, "curves", (json_int_t)n.curves, "triangles",
                     (json_int_t)n.triangles, "tetrahedra", (json_int_t)n.tetrahedra, "octahedra",
                     (json_int_t)n.octahedra, "bytes", bytes, "seconds", secs, "memory_bytes",
                     (json_int_t)atomic_load(&m->memory_bytes), "estimated_bytes",
                     (json_int_t)est);
}
