/* delta.c — GET /levels/{L}/delta: the stamps edits leave on a model's computed levels, the
 * normals they keep up to date, and the "SDD1" / JSON answer built from them (see delta.h).
 *
 * Per computed level: `base`, the version from which its stamps are complete (the model's
 * version when the level was first seen by an edit or a delta: a level computed later than an
 * edit is seen at the next one, and its content is then that of the model's version); `pos[v]`,
 * the last version at which point v's position changed (0 = not since base), and `attr[a][v]`
 * the same per attribute, each allocated at the first change it records (the positions' made
 * with the level's glTF geometry, api_delta_prepare, so that a first edit costs what later ones
 * do, DECISIONS 38). A delta since V lists
 * the points stamped after V, plus — when the level has drawn triangles (surface triangles, the
 * solids' boundary: the glTF's NORMAL accessor) — every vertex of a triangle at a moved point,
 * whose glTF normal may have changed with it. That neighbourhood comes from `first`/`tri`: per
 * vertex, its drawn triangles in out_normals' order (surface triangles, then the boundary), built
 * once per level with the glTF geometry. An edit recomputes the cached normal of each of those
 * vertices with out_triangle_normal and out_normal_unit, summed in that order, so the normals
 * equal out_normals' of the edited level bit for bit (docs/DECISIONS.md 36). A geometry a stream
 * holds a reference on is never written: the model's cache becomes a copy first.
 *
 * Costs (docs/SERVICE.md "Live edits"): with a level's glTF geometry, 4 bytes per point of
 * stamps, 4 bytes per vertex plus 12 per drawn triangle for the incidence and a bit per point
 * (the bitmap that gathers a moved point's neighbours); 4 more per point per attribute changed
 * there; a copy of the normals while a stream holds them. A delta scans its level's stamps and
 * walks the triangles at the moved points. Stamps are 32-bit: a model past version 2^32 - 1
 * answers 410 (refetch) rather than wrap.
 */
#include "delta.h"
#include "buf.h"
#include "handlers.h"
#include "mem.h"
#include "out_internal.h"
#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct dlevel {
    bool seen;                 /* base is set */
    uint64_t base;
    uint32_t nv;
    uint32_t *pos;             /* nv stamps, or NULL: no position changed since base */
    uint32_t *attr[API_MAX_ATTRIBUTES];
    uint32_t ntr;              /* surface triangles; drawn triangle t >= ntr is boundary t - ntr */
    uint32_t *first, *tri;     /* vertex v's drawn triangles: tri[first[v] .. first[v+1]) */
    uint64_t *mark;            /* a bit per point, all clear between calls (with_neighbours) */
    size_t bytes;
} dlevel;

struct api_delta {
    dlevel lv[SD_MAX_LEVEL + 1];
};

api_delta *api_delta_new(void) { return api_calloc(1, sizeof(api_delta)); }

static void level_free(dlevel *L)
{
    api_free(L->pos);
    for (int a = 0; a < API_MAX_ATTRIBUTES; a++)
        api_free(L->attr[a]);
    api_free(L->first);
    api_free(L->tri);
    api_free(L->mark);
    memset(L, 0, sizeof *L);
}

void api_delta_free(api_delta *d)
{
    if (!d)
        return;
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        level_free(&d->lv[l]);
    api_free(d);
}

size_t api_delta_bytes(const api_delta *d)
{
    size_t n = 0;
    for (int l = 0; d && l <= SD_MAX_LEVEL; l++)
        n += d->lv[l].bytes;
    return n;
}

/* Levels computed and not seen yet start at the model's version. */
static void observe(api_model *m)
{
    int n = sd_complex_levels_computed(m->c);
    uint64_t v = atomic_load(&m->version);
    for (int l = 0; l < n && l <= SD_MAX_LEVEL; l++) {
        dlevel *L = &m->delta->lv[l];
        if (L->seen)
            continue;
        sd_error e;
        L->seen = true;
        L->base = v;
        L->nv = sd_level_num_vertices(sd_complex_level(m->c, l, &e));
    }
}

/* A model rebuilt from the store (its snapshot imported, its journal replayed): the stamps the
 * replay left are not a history clients saw before the daemon restarted or loaded the session
 * again (docs/SERVICE.md "Live edits"), so no delta reaches back before the model's version. */
void api_delta_loaded(api_model *m)
{
    if (!m->c) /* no complex: no levels */
        return;
    observe(m);
    uint64_t v = atomic_load(&m->version);
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        if (m->delta->lv[l].seen && m->delta->lv[l].base < v)
            m->delta->lv[l].base = v;
}

/* ---- drawn triangles and normals ---------------------------------------------------------- */

/* The vertices of drawn triangle t. */
static void drawn(const sd_level *lv, const dlevel *L, const out_geometry *g, uint32_t t,
                  uint32_t v[3])
{
    if (t < L->ntr) {
        uint32_t c[6];
        sd_level_cell(lv, SD_CELL_TRIANGLE, t, c);
        memcpy(v, c, 3 * sizeof *v);
    } else
        memcpy(v, g->bnd + 3 * (size_t)(t - L->ntr), 3 * sizeof *v);
}

/* Vertex -> drawn triangles, ascending (out_normals' order). false: out of memory or too many. */
static bool ensure_incidence(dlevel *L, const sd_level *lv, const out_geometry *g)
{
    if (L->first)
        return true;
    uint32_t nv = sd_level_num_vertices(lv), ntr = sd_level_num_cells(lv, SD_CELL_TRIANGLE);
    uint64_t nt = (uint64_t)ntr + g->nbnd;
    if (3 * nt >= UINT32_MAX)
        return false;
    uint32_t *first = api_calloc((size_t)nv + 2, sizeof *first);
    uint32_t *tri = api_malloc((3 * (size_t)nt + 1) * sizeof *tri);
    if (!first || !tri) {
        api_free(first);
        api_free(tri);
        return false;
    }
    L->ntr = ntr;
    uint32_t v[3];
    for (uint32_t t = 0; t < nt; t++) {
        drawn(lv, L, g, t, v);
        for (int k = 0; k < 3; k++)
            first[v[k] + 2]++;
    }
    for (uint32_t i = 2; i <= nv + 1; i++) /* first[v + 1] = where v's list starts */
        first[i] += first[i - 1];
    for (uint32_t t = 0; t < nt; t++) {
        drawn(lv, L, g, t, v);
        for (int k = 0; k < 3; k++)
            tri[first[v[k] + 1]++] = t;
    }
    /* now first[v + 1] is where v's list ends, first[0] = 0 */
    L->first = first;
    L->tri = tri;
    L->bytes += ((size_t)nv + 2) * sizeof *first + (3 * (size_t)nt + 1) * sizeof *tri;
    return true;
}

/* The level's bitmap of points (kept, all clear between calls). false: out of memory. */
static bool ensure_mark(dlevel *L, uint32_t nv)
{
    size_t nw = ((size_t)nv + 63) / 64 + 1;
    if (!L->mark && (L->mark = api_calloc(nw, sizeof *L->mark)))
        L->bytes += nw * sizeof *L->mark;
    return L->mark != NULL;
}

/* ids (n) plus every vertex of a drawn triangle at one of the first `moved` of them, sorted and
 * unique, into *out (a new block) and *nout: marked in the level's bitmap, which is then read in
 * order and left clear (no sort: the lists hold tens of thousands of repeats). false: out of
 * memory. */
static bool with_neighbours(const sd_level *lv, dlevel *L, const out_geometry *g,
                            const uint32_t *ids, size_t n, size_t moved, uint32_t **out,
                            size_t *nout)
{
    uint32_t nv = sd_level_num_vertices(lv);
    size_t nw = ((size_t)nv + 63) / 64;
    if (!ensure_mark(L, nv))
        return false;
    uint64_t *bit = L->mark;
    size_t k = 0;
#define MARK(v)                                                                                    \
    do {                                                                                           \
        uint32_t v_ = (v);                                                                         \
        uint64_t b_ = (uint64_t)1 << (v_ & 63);                                                    \
        k += !(bit[v_ >> 6] & b_);                                                                 \
        bit[v_ >> 6] |= b_;                                                                        \
    } while (0)
    for (size_t i = 0; i < n; i++)
        MARK(ids[i]);
    for (size_t i = 0; L->first && i < moved; i++)
        for (uint32_t j = L->first[ids[i]]; j < L->first[ids[i] + 1]; j++) {
            uint32_t v[3];
            drawn(lv, L, g, L->tri[j], v);
            MARK(v[0]);
            MARK(v[1]);
            MARK(v[2]);
        }
#undef MARK
    uint32_t *a = api_malloc((k + 1) * sizeof *a);
    size_t u = 0;
    for (size_t w = 0; w < nw && u < k; w++) {
        for (uint64_t x = bit[w]; a && x; x &= x - 1)
            a[u++] = (uint32_t)(64 * w + (size_t)__builtin_ctzll(x));
        u += a ? 0 : (size_t)__builtin_popcountll(bit[w]);
        bit[w] = 0;
    }
    if (!a)
        return false;
    *out = a;
    *nout = u;
    return true;
}

/* The cached normals of the vertices around the moved points idx of a level, recomputed as
 * out_normals computes them. A geometry a stream holds too (refs > 1: the streams took their
 * references under m->lock, which the edit holds, so none is taken meanwhile) is never written:
 * the model's cache becomes a copy, and the stream keeps reading the normals of its moment.
 * Without memory for that the cache goes (the next glTF builds it). */
static void update_normals(api_model *m, int level, const uint32_t *idx, size_t n)
{
    out_geometry *g = m->geometry[level];
    if (!g)
        return;
    sd_error e;
    const sd_level *lv = sd_complex_level(m->c, level, &e);
    dlevel *L = &m->delta->lv[level];
    uint32_t *ids = NULL;
    size_t nids = 0;
    if (lv && atomic_load(&g->refs) > 1) { /* copy on write */
        out_geometry *c = out_geometry_copy(g, sd_level_num_vertices(lv));
        out_geometry_free(g);
        m->geometry[level] = g = c;
        if (!g)
            return;
    }
    if (!lv || !ensure_incidence(L, lv, g) || !with_neighbours(lv, L, g, idx, n, n, &ids, &nids)) {
        out_geometry_free(g);
        m->geometry[level] = NULL;
        return;
    }
    const double *xyz = sd_level_channel(lv, 0, NULL);
    for (size_t i = 0; i < nids; i++) {
        float acc[3] = {0, 0, 0}, t[3];
        uint32_t v[3];
        for (uint32_t j = L->first[ids[i]]; j < L->first[ids[i] + 1]; j++) {
            drawn(lv, L, g, L->tri[j], v);
            out_triangle_normal(xyz, v, t);
            for (int k = 0; k < 3; k++)
                acc[k] += t[k];
        }
        out_normal_unit(acc);
        memcpy(g->normals + 3 * (size_t)ids[i], acc, sizeof acc);
    }
    api_free(ids);
}

/* What the first edit would otherwise build, built with the level's geometry (the first edit
 * costs what later ones do, DECISIONS 38): the stamps of the computed levels, their pages
 * written now (a fresh page costs a fault when first touched), and the level's incidence. A
 * failure here only leaves them to the edit. */
void api_delta_prepare(api_model *m, int level)
{
    observe(m);
    int n = sd_complex_levels_computed(m->c);
    for (int l = 0; l < n && l <= SD_MAX_LEVEL; l++) {
        dlevel *L = &m->delta->lv[l];
        if (!L->pos && (L->pos = api_malloc(((size_t)L->nv + 1) * sizeof *L->pos))) {
            memset(L->pos, 0, ((size_t)L->nv + 1) * sizeof *L->pos);
            L->bytes += ((size_t)L->nv + 1) * sizeof *L->pos;
        }
    }
    sd_error e;
    const sd_level *lv = sd_complex_level(m->c, level, &e);
    if (lv && m->geometry[level]) {
        ensure_incidence(&m->delta->lv[level], lv, m->geometry[level]);
        ensure_mark(&m->delta->lv[level], sd_level_num_vertices(lv));
    }
    sd_complex_prepare_edits(m->c, &e); /* the core's part */
}

/* ---- edits ----------------------------------------------------------------------------------- */

void api_delta_begin_edit(api_model *m) { observe(m); }

/* sd_edit_report's callback: stamp the points of one level that changed. */
static void changed(void *ud, int level, const uint32_t *idx, size_t n)
{
    api_delta_edit *de = ud;
    api_model *m = de->m;
    dlevel *L = &m->delta->lv[level];
    sd_error e;
    if (!L->seen) { /* computed by this edit: its changes are against its values before it */
        L->seen = true;
        L->base = atomic_load(&m->version);
        L->nv = sd_level_num_vertices(sd_complex_level(m->c, level, &e));
    }
    uint32_t **st = de->attr < 0 ? &L->pos : &L->attr[de->attr];
    if (!*st && de->version <= UINT32_MAX) {
        *st = api_calloc((size_t)L->nv + 1, sizeof **st);
        L->bytes += *st ? ((size_t)L->nv + 1) * sizeof **st : 0;
    }
    if (!*st) { /* no room to say what changed: no delta reaches back across this edit */
        if (L->base < de->version)
            L->base = de->version;
    } else
        for (size_t i = 0; i < n; i++)
            (*st)[idx[i]] = (uint32_t)de->version;
    if (de->attr < 0)
        update_normals(m, level, idx, n);
}

void api_delta_report(api_delta_edit *de, sd_edit_report *rep)
{
    memset(rep, 0, sizeof *rep);
    rep->changed = changed;
    rep->ud = de;
}

void api_delta_end_edit(api_model *m)
{
    observe(m); /* levels the edit computed without changing them: as they were before it */
}

/* ---- the answer ------------------------------------------------------------------------------ */

static int gone(api_problem *p, const char *fmt, unsigned long long a, unsigned long long b)
{
    char d[320];
    snprintf(d, sizeof d, fmt, a, b);
    return api_fail(p, 410, "delta-unavailable", "%s; GET the level again", d);
}

/* Can level L's delta since `since` be answered (m->lock held)? 0, or the 410 (api/delta.h). */
static int since_ok(api_model *m, int level, uint64_t since, api_problem *p)
{
    uint64_t cur = atomic_load(&m->version);
    if (level >= sd_complex_levels_computed(m->c))
        return gone(p, "level %llu is not computed in this session's current model (version %llu)",
                    (unsigned long long)level, (unsigned long long)cur);
    if (since > cur)
        return gone(p, "version %llu is ahead of the session's version %llu",
                    (unsigned long long)since, (unsigned long long)cur);
    if (cur > UINT32_MAX)
        return gone(p, "versions past %llu (here %llu) have no deltas", UINT32_MAX,
                    (unsigned long long)cur);
    observe(m);
    uint64_t from = m->delta->lv[level].base;
    if (since < from)
        return gone(p, "since version %llu the level changed other than by edits (a new "
                    "complex, tags, rules or refinement, or an edit that built rules again), or "
                    "was computed after it: deltas of it start at version %llu",
                    (unsigned long long)since, (unsigned long long)from);
    return 0;
}

/* The query: since, format (0 bin, 1 json), the attributes. 0 or the problem's status. */
static int parse_query(const api_model *m, const api_delta_query *q, uint64_t *since, int *json,
                       int *attrs, int *nattrs, unsigned *parts, api_problem *p)
{
    const char *s = q->since;
    if (!s)
        return api_fail_at(p, 400, "missing-parameter", "since",
                           "give since=<version>, the version of the level you hold");
    char *end;
    errno = 0;
    unsigned long long v = isdigit((unsigned char)*s) ? strtoull(s, &end, 10) : 0;
    if (!isdigit((unsigned char)*s) || *end || errno)
        return api_fail_at(p, 400, "bad-parameter", "since",
                           "since must be a version: a non-negative integer");
    *since = v;
    *json = 0;
    if (q->format && !strcmp(q->format, "json"))
        *json = 1;
    else if (q->format && strcmp(q->format, "bin"))
        return api_fail_at(p, 422, "unknown-value", "format",
                           "format \"%.20s\" is not one of bin, json", q->format);
    *nattrs = 0;
    /* as GET /levels: an empty text names none, and after a comma comes a name ("t," ends in an
     * empty one, refused) */
    for (const char *a = q->attributes && *q->attributes ? q->attributes : NULL; a;) {
        const char *e = strchr(a, ',');
        size_t n = e ? (size_t)(e - a) : strlen(a);
        char name[API_MAX_ATTRIBUTE_NAME + 2];
        snprintf(name, sizeof name, "%.*s", (int)(n < sizeof name - 1 ? n : sizeof name - 1), a);
        int k = n < sizeof name - 1 && m->in ? api_input_find_attr(m->in, name) : -1;
        if (k < 0 && n > API_MAX_ATTRIBUTE_NAME) /* not shown cut */
            return api_fail_at(p, 422, "unknown-attribute", "attributes",
                               "attributes: a name of %zu characters (attribute names have at "
                               "most %d)", n, API_MAX_ATTRIBUTE_NAME);
        if (k < 0)
            return api_fail_at(p, 422, "unknown-attribute", "attributes",
                               "attributes: no attribute \"%s\" in this complex", name);
        for (int i = 0; i < *nattrs; i++)
            if (attrs[i] == k) /* as GET /levels: docs/OUTPUTS.md */
                return api_fail_at(p, 422, "repeated-attribute", "attributes",
                                   "attributes: \"%s\" is named twice", name);
        attrs[(*nattrs)++] = k;
        a = e ? e + 1 : NULL;
    }
    if (api_parse_parts(q->parts, parts, p))
        return p->status;
    *parts &= OUT_PART_ALL; /* the GLB's embedded models have deltas of their own */
    if (!*parts)
        return api_fail_at(p, 422, "unknown-value", "parts", "parts: name at least one part of "
                           "the level (an embedded model's delta: GET .../embedded/{name}/delta)");
    return 0;
}

int api_delta_check(const api_model *m, const api_delta_query *q, api_problem *p)
{
    uint64_t since;
    int json, attrs[API_MAX_ATTRIBUTES], nattrs;
    unsigned parts;
    return parse_query(m, q, &since, &json, attrs, &nattrs, &parts, p);
}

/* Append to *a (k of cap) the points whose stamp st[v] is after `since`. false: no memory. */
static bool stamped(const uint32_t *st, uint32_t nv, uint64_t since, uint32_t **a, size_t *k,
                    size_t *cap)
{
    for (uint32_t v = 0; st && v < nv; v++) {
        if (st[v] <= since)
            continue;
        if (*k == *cap) {
            size_t c = *cap ? 2 * *cap : 1024;
            uint32_t *x = api_realloc(*a, c * sizeof *x);
            if (!x)
                return false;
            *a = x;
            *cap = c;
        }
        (*a)[(*k)++] = v;
    }
    return true;
}

/* The points of a level stamped after `since` in positions or in one of the attributes, and,
 * with normals, every vertex of a drawn triangle at a moved point: sorted, each once. */
static bool collect(dlevel *L, const sd_level *lv, const out_geometry *g, bool normals,
                    uint64_t since, const int *attrs, int nattrs, uint32_t **ids, size_t *n)
{
    uint32_t *a = NULL;
    size_t k = 0, cap = 0;
    bool ok = stamped(L->pos, L->nv, since, &a, &k, &cap);
    if (ok && normals && k) {
        uint32_t *b;
        ok = with_neighbours(lv, L, g, a, k, k, &b, &k);
        api_free(a);
        a = ok ? b : NULL;
        cap = k;
    }
    for (int i = 0; ok && i < nattrs; i++)
        ok = stamped(L->attr[attrs[i]], L->nv, since, &a, &k, &cap);
    if (ok && nattrs && k) { /* the union of the lists */
        uint32_t *b;
        ok = with_neighbours(lv, L, g, a, k, 0, &b, &k);
        api_free(a);
        a = ok ? b : NULL;
    }
    if (!ok) {
        api_free(a);
        return false;
    }
    *ids = a;
    *n = k;
    return true;
}

/* The normals of points ids (n) over the drawn triangles of one kind — the surface triangles
 * (surf) or the solids' boundary — as out_normals computes them for a GLB of those parts alone
 * (that kind's triangles in order): n rows, a new block, or NULL without memory. */
static float *parts_normals(const sd_level *lv, const dlevel *L, const out_geometry *g, bool surf,
                            const uint32_t *ids, size_t n)
{
    float *out = api_malloc((3 * n + 1) * sizeof *out);
    if (!out)
        return NULL;
    const double *xyz = sd_level_channel(lv, 0, NULL);
    for (size_t i = 0; i < n; i++) {
        float acc[3] = {0, 0, 0}, t[3];
        uint32_t v[3];
        for (uint32_t j = L->first[ids[i]]; j < L->first[ids[i] + 1]; j++) {
            if ((L->tri[j] < L->ntr) != surf)
                continue;
            drawn(lv, L, g, L->tri[j], v);
            out_triangle_normal(xyz, v, t);
            for (int k = 0; k < 3; k++)
                acc[k] += t[k];
        }
        out_normal_unit(acc);
        memcpy(out + 3 * i, acc, sizeof acc);
    }
    return out;
}

int api_level_delta(api_model *m, int level, const api_delta_query *q, char **body, size_t *len,
              const char **ctype, char *components, size_t ccap, uint64_t *version,
              api_problem *p)
{
    uint64_t since = 0;
    int json = 0, attrs[API_MAX_ATTRIBUTES], nattrs = 0;
    unsigned parts = OUT_PART_ALL;
    *body = NULL;
    if (!m->c)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    if (parse_query(m, q, &since, &json, attrs, &nattrs, &parts, p))
        return p->status;
    components[0] = 0;
    for (int i = 0; i < nattrs; i++) {
        const api_attribute *a = &m->in->attrs[attrs[i]];
        size_t u = strlen(components);
        snprintf(components + u, ccap - u, "%s%s=%d", i ? "," : "", a->name, a->ncomp);
    }
    pthread_mutex_lock(&m->lock);
    uint64_t cur = *version = atomic_load(&m->version);
    int rc = since_ok(m, level, since, p);
    if (rc) {
        pthread_mutex_unlock(&m->lock);
        return rc;
    }
    dlevel *L = &m->delta->lv[level];
    sd_error e = {0};
    const sd_level *lv = sd_complex_level(m->c, level, &e);
    const out_geometry *g = api_model_geometry_locked(m, level);
    /* the drawn triangles of the parts the client holds (its GLB's NORMAL accessor): the
     * cached normals are those of both kinds; one kind alone has its own (parts_normals) */
    bool surf = parts & OUT_PART_SURFACES, sol = parts & OUT_PART_SOLIDS;
    bool normals = g && ((surf && sd_level_num_cells(lv, SD_CELL_TRIANGLE)) || (sol && g->nbnd));
    uint32_t *ids = NULL;
    size_t n = 0;
    float *own = NULL;
    if (!g || (normals && !ensure_incidence(L, lv, g)) ||
        !collect(L, lv, g, normals, since, attrs, nattrs, &ids, &n) ||
        (normals && !(surf && sol) && !(own = parts_normals(lv, L, g, surf, ids, n)))) {
        api_free(ids);
        api_model_publish(m);
        pthread_mutex_unlock(&m->lock);
        return api_fail(p, 503, "out-of-memory", "out of memory building the delta; retry later");
    }
/* the normal of the delta's i-th point: own's row i, else the cached one of the point */
#define NORMAL_AT(i) (own ? own + 3 * (i) : g->normals + 3 * (size_t)ids[i])
    const double *xyz = sd_level_channel(lv, 0, NULL);
    api_buf o = {0};
    size_t per = 12 + (normals ? 12 : 0);
    for (int a = 0; a < nattrs; a++)
        per += 4 * (size_t)m->in->attrs[attrs[a]].ncomp;
    if (!json) {
        api_buf_reserve(&o, 24 + n * (4 + per));
        api_buf_put(&o, "SDD1", 4);
        api_buf_u32(&o, (uint32_t)level);
        api_buf_u32(&o, (uint32_t)since);
        api_buf_u32(&o, (uint32_t)cur);
        api_buf_u32(&o, (uint32_t)n);
        api_buf_u32(&o, (normals ? 1u : 0u) | (nattrs ? 2u : 0u));
        api_buf_put(&o, ids, n * sizeof *ids);
        for (size_t i = 0; i < n; i++)
            for (int k = 0; k < 3; k++)
                api_buf_f32(&o, xyz[3 * (size_t)ids[i] + k]);
        for (size_t i = 0; normals && i < n; i++)
            api_buf_put(&o, NORMAL_AT(i), 12);
        for (int a = 0; a < nattrs; a++) {
            int nc;
            const double *x = sd_level_channel(lv, m->channel[attrs[a]], &nc);
            for (size_t i = 0; i < n; i++)
                for (int k = 0; k < nc; k++)
                    api_buf_f32(&o, x[(size_t)ids[i] * nc + k]);
        }
    } else {
        api_buf_reserve(&o, 256 + n * (16 + 5 * per)); /* a guess (put grows it): %.17g and %.9g numbers */
        char head[160];
        snprintf(head, sizeof head, "{\"level\":%d,\"since\":%llu,\"version\":%llu,\"indices\":[",
                 level, (unsigned long long)since, (unsigned long long)cur);
        api_buf_put(&o, head, strlen(head));
        for (size_t i = 0; i < n; i++) {
            char t[16];
            api_buf_put(&o, t, (size_t)snprintf(t, sizeof t, i ? ",%u" : "%u", ids[i]));
        }
        api_buf_put(&o, "],\"positions\":[", 15);
        for (size_t i = 0; i < n; i++) {
            if (i)
                api_buf_put(&o, ",", 1);
            api_buf_reals(&o, xyz + 3 * (size_t)ids[i], 3);
        }
        api_buf_put(&o, "]", 1);
        if (normals) {
            api_buf_put(&o, ",\"normals\":[", 12);
            for (size_t i = 0; i < n; i++) {
                const float *f = NORMAL_AT(i);
                api_buf_put(&o, i ? ",[" : "[", i ? 2 : 1);
                for (int k = 0; k < 3; k++)
                    api_buf_printf(&o, k ? ",%.9g" : "%.9g", (double)f[k]);
                api_buf_put(&o, "]", 1);
            }
            api_buf_put(&o, "]", 1);
        }
        api_buf_put(&o, ",\"attributes\":{", 15);
        for (int a = 0; a < nattrs; a++) {
            int nc;
            const double *x = sd_level_channel(lv, m->channel[attrs[a]], &nc);
            char t[API_MAX_ATTRIBUTE_NAME + 8];
            api_buf_put(&o, t, (size_t)snprintf(t, sizeof t, "%s\"%s\":[", a ? "," : "",
                                        m->in->attrs[attrs[a]].name));
            for (size_t i = 0; i < n; i++) {
                if (i)
                    api_buf_put(&o, ",", 1);
                api_buf_reals(&o, x + (size_t)ids[i] * nc, nc);
            }
            api_buf_put(&o, "]", 1);
        }
        api_buf_put(&o, "}}", 2);
    }
#undef NORMAL_AT
    api_model_publish(m); /* the incidence and the geometry count as session memory */
    pthread_mutex_unlock(&m->lock);
    api_free(ids);
    api_free(own);
    if (o.failed || !o.b) {
        api_free(o.b);
        return api_fail(p, 503, "out-of-memory", "out of memory writing the delta; retry later");
    }
    *body = o.b;
    *len = o.n;
    *ctype = json ? "application/json" : "application/octet-stream";
    return 0;
}

int api_delta_moved(api_model *m, int level, const char *since_text, uint64_t *since,
                    int *json, const char *format, uint32_t **ids, size_t *n, api_problem *p)
{
    api_delta_query q = {since_text, format, NULL, NULL};
    int attrs[API_MAX_ATTRIBUTES], nattrs;
    unsigned parts;
    *ids = NULL;
    *n = 0;
    if (parse_query(m, &q, since, json, attrs, &nattrs, &parts, p))
        return p->status;
    if (since_ok(m, level, *since, p))
        return p->status;
    dlevel *L = &m->delta->lv[level];
    size_t cap = 0;
    if (!stamped(L->pos, L->nv, *since, ids, n, &cap)) {
        api_free(*ids);
        *ids = NULL;
        return api_fail(p, 503, "out-of-memory", "out of memory building the delta; retry later");
    }
    return 0;
}
