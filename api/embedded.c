/* embedded.c — PUT/GET/DELETE /embedded/{name}, its delta, and the models carried through every
 * change of the session (api/embedded.h; docs/API.md "Embedded models"; 004 Sec. 5.1).
 *
 * The binding is the core's (core/embed.c: a grid over the level's solid cells, barycentric
 * coordinates, an octahedron as the 4 tetrahedra around its major diagonal); this file parses,
 * keeps the list of a model, and writes the deformed shape as JSON, OBJ or GLB. Nothing is
 * updated when an edit moves points: the level already holds the new positions, so a read
 * combines them, and a delta combines only the model vertices bound to the level points stamped
 * since (api_delta_moved), which costs what those vertices cost.
 */
#include "embedded.h"
#include "buf.h"
#include "delta.h"
#include "internal.h"
#include "jsonin.h"
#include "mem.h"
#include "rows.h"
#include <ctype.h>
#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static const char *const OUTSIDE[] = {"refuse", "fixed", "nearest", NULL};

/* ---- definitions ---------------------------------------------------------------------------- */

void api_embed_def_unref(api_embed_def *d)
{
    if (!d || atomic_fetch_sub(&d->refs, 1) != 1)
        return;
    api_free(d->rest);
    api_free(d->tri);
    api_free(d);
}

static int name_ok(const char *name, api_problem *p)
{
    size_t n = strlen(name);
    if (n == 0 || n > API_MAX_EMBED_NAME || strspn(name, "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnop"
                                                         "qrstuvwxyz0123456789_-") != n)
        return api_fail_at(p, 400, "bad-parameter", "name", "a model's name is 1 to %d letters, "
                           "digits, '_' or '-'", API_MAX_EMBED_NAME);
    return 0;
}

/* A new definition with room for nv vertices and nt triangles, or NULL. */
static api_embed_def *def_new(const char *name, uint32_t nv, uint32_t nt)
{
    api_embed_def *d = api_calloc(1, sizeof *d);
    if (!d)
        return NULL;
    atomic_init(&d->refs, 1);
    snprintf(d->name, sizeof d->name, "%s", name);
    d->nv = nv;
    d->nt = nt;
    d->rest = api_malloc(3 * sizeof(double) * ((size_t)nv + 1));
    d->tri = api_malloc(3 * sizeof(uint32_t) * ((size_t)nt + 1));
    if (!d->rest || !d->tri) {
        api_embed_def_unref(d);
        return NULL;
    }
    return d;
}

static int check_counts(size_t nv, size_t nt, const api_limits *lim, api_problem *p)
{
    if (nv == 0)
        return api_fail_at(p, 422, "invalid-complex", "/vertices", "a model needs vertices");
    if (nv > lim->max_embedded_vertices)
        return api_fail_limit(p, "max_embedded_vertices", lim->max_embedded_vertices, nv,
                              "the model has %zu vertices; at most %u (--max-embedded-vertices)",
                              nv, lim->max_embedded_vertices);
    if (nt > 4 * (size_t)lim->max_embedded_vertices)
        return api_fail_limit(p, "max_embedded_vertices", 4ull * lim->max_embedded_vertices, nt,
                              "the model has %zu triangles; at most 4 per allowed vertex", nt);
    return 0;
}

static int cmp_tri_key(const void *x, const void *y) /* sorted ids, then the entry */
{
    const uint32_t *a = x, *b = y;
    for (int k = 0; k < 4; k++)
        if (a[k] != b[k])
            return a[k] < b[k] ? -1 : 1;
    return 0;
}

/* The triangles of a PUT's definition: every index in range, no vertex twice in one, no
 * triangle twice (in any vertex order), as the control complex's simplices. */
static int check_triangles(const api_embed_def *d, api_problem *p)
{
    char ptr[192];
    for (size_t i = 0; i < 3 * (size_t)d->nt; i++) {
        const uint32_t *t = d->tri + 3 * (i / 3);
        int k = (int)(i % 3);
        snprintf(ptr, sizeof ptr, "/triangles/%zu/%d", i / 3, k);
        if (t[k] >= d->nv)
            return api_fail_at(p, 422, "invalid-complex", ptr, "vertex %u out of range (%u vertices)",
                               t[k], d->nv);
        for (int j = 0; j < k; j++)
            if (t[j] == t[k])
                return api_fail_at(p, 422, "invalid-complex", ptr,
                                   "vertex %u appears twice in the triangle", t[k]);
    }
    if (d->nt < 2)
        return 0;
    uint32_t (*key)[4] = api_plain_malloc((size_t)d->nt * sizeof *key);
    if (!key)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    for (uint32_t i = 0; i < d->nt; i++) {
        uint32_t a = d->tri[3 * i], b = d->tri[3 * i + 1], c = d->tri[3 * i + 2], x;
        if (a > b) x = a, a = b, b = x;
        if (b > c) x = b, b = c, c = x;
        if (a > b) x = a, a = b, b = x;
        key[i][0] = a, key[i][1] = b, key[i][2] = c, key[i][3] = i;
    }
    qsort(key, d->nt, sizeof *key, cmp_tri_key); /* equal triples by entry: the earlier first */
    int rc = 0;
    for (uint32_t i = 1; i < d->nt && !rc; i++)
        if (!memcmp(key[i - 1], key[i], 3 * sizeof(uint32_t))) {
            snprintf(ptr, sizeof ptr, "/triangles/%u", key[i][3]);
            rc = api_fail_at(p, 422, "invalid-complex", ptr, "the same triangle as /triangles/%u",
                             key[i - 1][3]);
        }
    api_plain_free(key);
    return rc;
}

static int parse_options(json_t *lv, json_t *out, const char *base, api_embed_def *d,
                         api_problem *p)
{
    char at[128];
    long long level = 2;
    snprintf(at, sizeof at, "%s/level", base);
    if (lv && api_get_int(lv, at, 0, SD_MAX_LEVEL, &level, p))
        return p->status;
    d->level = (int)level;
    d->outside = 0;
    snprintf(at, sizeof at, "%s/outside", base);
    if (out && (d->outside = api_get_enum(out, at, OUTSIDE, p)) < 0)
        return p->status;
    return 0;
}

/* The definition in a JSON object at `base` ("" for a PUT body, "/import/embedded/<name>"). */
static int parse_def(json_t *body, const char *name, const char *base, const api_limits *lim,
                     api_embed_def **out, api_problem *p)
{
    static const char *const keys[] = {"vertices", "triangles", "level", "outside", NULL};
    char at[160];
    *out = NULL;
    if (!json_is_object(body))
        return api_fail_at(p, 400, "wrong-type", base[0] ? base : "/", "must be an object");
    if (api_only_keys(body, base, keys, p))
        return p->status;
    json_t *vs = json_object_get(body, "vertices"), *ts = json_object_get(body, "triangles");
    snprintf(at, sizeof at, "%s/vertices", base);
    if (!vs)
        return api_fail_at(p, 400, "missing-field", at, "\"vertices\" is required");
    if (!json_is_array(vs))
        return api_fail_at(p, 400, "wrong-type", at, "must be an array of [x,y,z]");
    snprintf(at, sizeof at, "%s/triangles", base);
    if (ts && !json_is_array(ts))
        return api_fail_at(p, 400, "wrong-type", at, "must be an array of [i,j,k]");
    size_t nv = json_array_size(vs), nt = ts ? json_array_size(ts) : 0;
    if (check_counts(nv, nt, lim, p))
        return p->status;
    api_embed_def *d = def_new(name, (uint32_t)nv, (uint32_t)nt);
    if (!d)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    int rc = parse_options(json_object_get(body, "level"), json_object_get(body, "outside"), base,
                           d, p);
    for (size_t i = 0; !rc && i < nv; i++) {
        json_t *v = json_array_get(vs, i);
        snprintf(at, sizeof at, "%s/vertices/%zu", base, i);
        if (!json_is_array(v) || json_array_size(v) != 3) {
            rc = api_fail_at(p, 400, "wrong-type", at, "a vertex is [x, y, z]");
            break;
        }
        for (int k = 0; !rc && k < 3; k++) {
            char ck[176];
            snprintf(ck, sizeof ck, "%s/%d", at, k);
            rc = api_get_number(json_array_get(v, k), ck, API_MAX_VALUE, &d->rest[3 * i + k], p);
        }
    }
    for (size_t i = 0; !rc && i < nt; i++) {
        json_t *t = json_array_get(ts, i);
        snprintf(at, sizeof at, "%s/triangles/%zu", base, i);
        if (!json_is_array(t) || json_array_size(t) != 3) {
            rc = api_fail_at(p, 400, "wrong-type", at, "a triangle is [i, j, k]");
            break;
        }
        for (int k = 0; !rc && k < 3; k++) {
            char ck[176];
            long long x;
            snprintf(ck, sizeof ck, "%s/%d", at, k);
            if (!(rc = api_get_int(json_array_get(t, k), ck, 0, (long long)nv - 1, &x, p)))
                d->tri[3 * i + k] = (uint32_t)x;
        }
    }
    if (!rc && !base[0]) /* a PUT; an import takes the models its export held (documents
                          * written before repeats were refused may hold some) */
        rc = check_triangles(d, p);
    if (rc) {
        api_embed_def_unref(d);
        return rc;
    }
    *out = d;
    return 0;
}

int api_embed_parse(json_t *body, const char *name, const api_limits *lim, api_embed_def **out,
                    api_problem *p)
{
    *out = NULL;
    if (name_ok(name, p))
        return p->status;
    return parse_def(body, name, "", lim, out, p);
}

static uint32_t get_u32(const unsigned char *b)
{
    return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
}

int api_embed_parse_binary(const char *body, size_t len, const char *name, const char *level,
                           const char *outside, const api_limits *lim, api_embed_def **out,
                           api_problem *p)
{
    *out = NULL;
    if (name_ok(name, p))
        return p->status;
    const unsigned char *b = (const unsigned char *)body;
    if (len < 8)
        return api_fail_at(p, 400, "wrong-type", "/", "a binary model starts with uint32 nv, nt");
    uint32_t nv = get_u32(b), nt = get_u32(b + 4);
    if (check_counts(nv, nt, lim, p))
        return p->status;
    size_t want = 8 + 24 * (size_t)nv + 12 * (size_t)nt;
    if (len != want)
        return api_fail_at(p, 400, "wrong-type", "/", "%u vertices and %u triangles take %zu bytes, "
                           "not %zu", nv, nt, want, len);
    long long lv = 2;
    if (level) {
        lv = api_parse_level(level, p); /* 400 bad-level, 422 level-out-of-range: as GET /levels */
        if (lv < 0)
            return p->status;
    }
    int mode = 0;
    if (outside) {
        for (mode = 0; OUTSIDE[mode] && strcmp(OUTSIDE[mode], outside); mode++)
            ;
        if (!OUTSIDE[mode])
            return api_fail_at(p, 422, "unknown-value", "outside",
                               "outside is one of refuse, fixed, nearest");
    }
    api_embed_def *d = def_new(name, nv, nt);
    if (!d)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    d->level = (int)lv;
    d->outside = mode;
    memcpy(d->rest, b + 8, 24 * (size_t)nv); /* little endian doubles: this host's order */
    for (size_t i = 0; i < 3 * (size_t)nv; i++)
        if (!isfinite(d->rest[i]) || fabs(d->rest[i]) > API_MAX_VALUE) {
            char ptr[64];
            snprintf(ptr, sizeof ptr, "/vertices/%zu/%zu", i / 3, i % 3);
            api_embed_def_unref(d);
            return api_fail_at(p, 422, "out-of-range", ptr, "coordinates are finite, within 1e15");
        }
    for (size_t i = 0; i < 3 * (size_t)nt; i++)
        d->tri[i] = get_u32(b + 8 + 24 * (size_t)nv + 4 * i);
    if (check_triangles(d, p)) {
        api_embed_def_unref(d);
        return p->status;
    }
    *out = d;
    return 0;
}

/* ---- bindings --------------------------------------------------------------------------------- */

static void embed_clear(api_embed *e)
{
    sd_embed_free(e->bind);
    api_free(e->scratch);
    api_free(e->moved);
    api_embed_def_unref(e->def);
    memset(e, 0, sizeof *e);
}

void api_embed_free_all(api_model *m)
{
    for (int i = 0; m->embed && i < m->nembed; i++)
        embed_clear(&m->embed[i]);
    api_free(m->embed);
    m->embed = NULL;
    m->nembed = 0;
}

size_t api_embed_bytes(const api_model *m)
{
    size_t n = 0;
    for (int i = 0; m->embed && i < m->nembed; i++)
        n += sd_embed_memory(m->embed[i].bind) + 16 * (size_t)m->embed[i].def->nv;
    return n;
}

static int find(const api_model *m, const char *name)
{
    for (int i = 0; m->embed && i < m->nembed; i++)
        if (!strcmp(m->embed[i].def->name, name))
            return i;
    return -1;
}

/* The buffers a delta writes into (sd_embed_update's output), their pages written now: a delta
 * touches scattered parts of them, and a first touch costs a page fault each (DECISIONS 38). */
static bool embed_buffers(api_embed *e, uint32_t nv)
{
    size_t nx = 3 * sizeof(double) * ((size_t)nv + 1), nm = sizeof(uint32_t) * ((size_t)nv + 1);
    e->scratch = api_malloc(nx);
    e->moved = api_malloc(nm);
    if (!e->scratch || !e->moved)
        return false;
    memset(e->scratch, 0, nx);
    memset(e->moved, 0, nm);
    return true;
}

/* Bind d to the level of m (computed first), into *e. The caller holds no lock of m. */
static int bind(api_model *m, api_embed_def *d, const api_limits *lim, const api_slot *slot,
                api_embed *e, api_problem *p)
{
    memset(e, 0, sizeof *e);
    if (!m->c)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    if (api_check_level_limits(m, d->level, lim, p) || api_level_compute(m, d->level, slot, p))
        return p->status;
    if (!embed_buffers(e, d->nv)) {
        embed_clear(e);
        return api_fail(p, 503, "out-of-memory", "out of memory");
    }
    pthread_mutex_lock(&m->lock);
    sd_error err = {0};
    sd_bind_report rep = {0};
    const sd_level *lv = sd_complex_level(m->c, d->level, &err);
    sd_allocator al = api_mem_core_allocator();
    /* the session's memory limit bounds its models too: what the model holds already is used */
    size_t used = (m->c ? sd_complex_memory(m->c) : 0) + api_embed_bytes(m);
    size_t room = lim->max_session_bytes > used ? (size_t)(lim->max_session_bytes - used) : 1;
    sd_result r = lv ? sd_embed_bind(lv, d->rest, d->nv, (sd_outside)d->outside, &al, room,
                                     &e->bind, &rep, &err)
                     : err.code;
    e->since = atomic_load(&m->version);
    pthread_mutex_unlock(&m->lock);
    if (r) {
        embed_clear(e);
        if (err.code == SD_ERR_NOMEM)
            return api_fail(p, 503, "out-of-memory", "out of memory binding the model");
        if (err.code == SD_ERR_LIMIT)
            return api_fail_limit(p, "max_session_bytes", lim->max_session_bytes,
                                  (uint64_t)used + 80ull * d->nv, "model \"%s\": %s (the session "
                                  "holds %zu bytes; --max-session-bytes)", d->name, err.message, used);
        if (err.code == SD_ERR_VALUE && err.field == SD_EMBED_TOO_FAR)
            return api_fail_at(p, 422, "outside", "/outside", "model \"%s\": %s", d->name,
                               err.message);
        if (rep.outside) {
            char first[160] = "";
            for (int i = 0; i < rep.nfirst; i++) {
                size_t u = strlen(first);
                snprintf(first + u, sizeof first - u, "%s%zu", i ? ", " : "", rep.first[i]);
            }
            int rc = api_fail_at(p, 422, "outside", "/vertices",
                                 "model \"%s\": %zu of its %u vertices lie outside every solid cell "
                                 "of level %d (the first: %s); move them inside, or give "
                                 "\"outside\": \"fixed\" or \"nearest\"", d->name, rep.outside,
                                 d->nv, d->level, first);
            api_add_error(p, "/outside", "refuse (the default)");
            return rc;
        }
        return api_fail_at(p, 422, "outside", "/level", "model \"%s\": %s", d->name, err.message);
    }
    e->outside = rep.outside;
    atomic_fetch_add(&d->refs, 1);
    e->def = d;
    return 0;
}

static int ensure_list(api_model *m)
{
    if (!m->embed)
        m->embed = api_calloc(API_MAX_EMBEDDED, sizeof *m->embed);
    return m->embed != NULL;
}

int api_embed_put(api_model *m, api_embed_def *d, uint64_t version, const api_limits *lim,
                  const api_slot *slot, const api_edit_commit *commit, json_t **summary,
                  api_problem *p)
{
    *summary = NULL;
    /* a new name in a session already holding the most models is refused before the binding
     * (seconds and hundreds of MB for a big model), as it is after it (changes of one session
     * run one after the other; the check below stays for the list as it is then) */
    pthread_mutex_lock(&m->lock);
    int full = find(m, d->name) < 0 && m->nembed >= API_MAX_EMBEDDED;
    pthread_mutex_unlock(&m->lock);
    if (full)
        return api_fail_at(p, 422, "too-many-entries", "name", "a session holds at most %d embedded "
                           "models; DELETE one first", API_MAX_EMBEDDED);
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    api_embed e;
    if (bind(m, d, lim, slot, &e, p))
        return p->status;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    pthread_mutex_lock(&m->lock);
    int at = find(m, d->name), rc = 0;
    if (at < 0 && m->nembed >= API_MAX_EMBEDDED)
        rc = api_fail_at(p, 422, "too-many-entries", "name", "a session holds at most %d embedded "
                         "models; DELETE one first", API_MAX_EMBEDDED);
    else if (!ensure_list(m))
        rc = api_fail(p, 503, "out-of-memory", "out of memory");
    if (rc) {
        pthread_mutex_unlock(&m->lock);
        embed_clear(&e);
        return rc;
    }
    api_embed old = {0};
    api_delta_begin_edit(m); /* levels computed until now keep their deltas across this version */
    uint64_t was = atomic_load(&m->version);
    if (at >= 0)
        old = m->embed[at];
    else
        at = m->nembed++;
    e.since = version;
    m->embed[at] = e;
    atomic_store(&m->version, version);
    if (commit && (rc = commit->fn(commit->ud, p))) { /* not stored: as it was */
        atomic_store(&m->version, was);
        embed_clear(&m->embed[at]);
        if (old.def)
            m->embed[at] = old;
        else
            m->nembed--;
        pthread_mutex_unlock(&m->lock);
        return rc;
    }
    embed_clear(&old);
    api_model_publish(m);
    pthread_mutex_unlock(&m->lock);
    double secs = (double)(t1.tv_sec - t0.tv_sec) + (t1.tv_nsec - t0.tv_nsec) * 1e-9;
    *summary = json_pack("{s:s, s:I, s:I, s:i, s:s, s:f, s:I}", "name", d->name, "vertices",
                         (json_int_t)d->nv, "triangles", (json_int_t)d->nt, "level", d->level,
                         "outside", OUTSIDE[d->outside], "seconds", secs, "outside_vertices",
                         (json_int_t)e.outside);
    return 0;
}

int api_embed_delete(api_model *m, const char *name, uint64_t version,
                     const api_edit_commit *commit, api_problem *p)
{
    if (name_ok(name, p)) /* no model can have it: the name is what is wrong */
        return p->status;
    pthread_mutex_lock(&m->lock);
    int at = find(m, name), rc = 0;
    if (at < 0) {
        pthread_mutex_unlock(&m->lock);
        return api_fail(p, 404, "not-found", "no embedded model \"%.48s\" in this session", name);
    }
    api_embed gone = m->embed[at];
    api_delta_begin_edit(m);
    uint64_t was = atomic_load(&m->version);
    memmove(&m->embed[at], &m->embed[at + 1], (size_t)(m->nembed - at - 1) * sizeof *m->embed);
    m->nembed--;
    atomic_store(&m->version, version);
    if (commit && (rc = commit->fn(commit->ud, p))) {
        atomic_store(&m->version, was);
        memmove(&m->embed[at + 1], &m->embed[at], (size_t)(m->nembed - at) * sizeof *m->embed);
        m->embed[at] = gone;
        m->nembed++;
        pthread_mutex_unlock(&m->lock);
        return rc;
    }
    embed_clear(&gone);
    api_model_publish(m);
    pthread_mutex_unlock(&m->lock);
    return 0;
}

json_t *api_embed_list(api_model *m)
{
    json_t *a = json_array();
    pthread_mutex_lock(&m->lock);
    for (int i = 0; a && m->embed && i < m->nembed; i++) {
        const api_embed *e = &m->embed[i];
        json_array_append_new(a, json_pack("{s:s, s:I, s:I, s:i, s:s, s:I}", "name", e->def->name,
                                           "vertices", (json_int_t)e->def->nv, "triangles",
                                           (json_int_t)e->def->nt, "level", e->def->level,
                                           "outside", OUTSIDE[e->def->outside],
                                           "outside_vertices", (json_int_t)e->outside));
    }
    pthread_mutex_unlock(&m->lock);
    return a;
}

/* ---- writing a deformed model ----------------------------------------------------------------- */

static void write_json(api_buf *o, const api_embed *e, const double *x, uint64_t version)
{
    api_buf_printf(o, "{\"name\":\"%s\",\"level\":%d,\"version\":%llu,\"vertices\":[", e->def->name,
         e->def->level, (unsigned long long)version);
    for (uint32_t i = 0; i < e->def->nv; i++) {
        if (i)
            api_buf_put(o, ",", 1);
        api_buf_reals(o, x + 3 * (size_t)i, 3);
    }
    api_buf_put(o, "],\"triangles\":[", 15);
    for (uint32_t t = 0; t < e->def->nt; t++) {
        const uint32_t *v = e->def->tri + 3 * (size_t)t;
        api_buf_printf(o, "%s[%u,%u,%u]", t ? "," : "", v[0], v[1], v[2]);
    }
    api_buf_put(o, "]}", 2);
}

static void write_obj(api_buf *o, const api_embed *e, const double *x, uint64_t version)
{
    api_buf_printf(o, "# subdivd: embedded model \"%s\" at level %d, version %llu\n", e->def->name,
         e->def->level, (unsigned long long)version);
    for (uint32_t i = 0; i < e->def->nv; i++) {
        api_buf_put(o, "v ", 2);
        for (int k = 0; k < 3; k++) {
            if (k)
                api_buf_put(o, " ", 1);
            char t[40];
            api_buf_put(o, t, (size_t)snprintf(t, sizeof t, "%.17g", x[3 * (size_t)i + k]));
        }
        api_buf_put(o, "\n", 1);
    }
    for (uint32_t t = 0; t < e->def->nt; t++) {
        const uint32_t *v = e->def->tri + 3 * (size_t)t;
        api_buf_printf(o, "f %u %u %u\n", v[0] + 1, v[1] + 1, v[2] + 1);
    }
}

/* A GLB (glTF 2.0 binary) of one mesh: POSITION (float32, with its bounds) and, with triangles,
 * uint32 indices; points otherwise. */
static void write_glb(api_buf *o, const api_embed *e, const double *x, uint64_t version)
{
    uint32_t nv = e->def->nv, nt = e->def->nt;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < nv; i++)
        for (int k = 0; k < 3; k++) {
            double f = (double)(float)x[3 * i + k];
            lo[k] = f < lo[k] ? f : lo[k];
            hi[k] = f > hi[k] ? f : hi[k];
        }
    size_t pos_bytes = 12 * (size_t)nv, idx_bytes = 12 * (size_t)nt;
    json_t *prim = json_pack("{s:{s:i}, s:i}", "attributes", "POSITION", 0, "mode", nt ? 4 : 0);
    json_t *acc = json_pack("[{s:i, s:i, s:I, s:s, s:[f,f,f], s:[f,f,f]}]", "bufferView", 0,
                            "componentType", 5126, "count", (json_int_t)nv, "type", "VEC3", "min",
                            lo[0], lo[1], lo[2], "max", hi[0], hi[1], hi[2]);
    json_t *views = json_pack("[{s:i, s:i, s:I, s:i}]", "buffer", 0, "byteOffset", 0, "byteLength",
                              (json_int_t)pos_bytes, "target", 34962);
    if (nt && prim && acc && views) {
        json_object_set_new(prim, "indices", json_integer(1));
        json_array_append_new(acc, json_pack("{s:i, s:i, s:I, s:s}", "bufferView", 1,
                                             "componentType", 5125, "count", (json_int_t)(3 * (size_t)nt),
                                             "type", "SCALAR"));
        json_array_append_new(views, json_pack("{s:i, s:I, s:I, s:i}", "buffer", 0, "byteOffset",
                                               (json_int_t)pos_bytes, "byteLength",
                                               (json_int_t)idx_bytes, "target", 34963));
    }
    char gen[80];
    snprintf(gen, sizeof gen, "subdivd embedded model");
    json_t *doc = json_pack("{s:{s:s, s:s, s:{s:s, s:i, s:I}}, s:i, s:[{s:[i]}], s:[{s:s, s:i}], "
                            "s:[{s:s, s:[o]}], s:o, s:o, s:[{s:I}]}",
                            "asset", "version", "2.0", "generator", gen, "extras", "name",
                            e->def->name, "level", e->def->level, "version", (json_int_t)version,
                            "scene", 0, "scenes", "nodes", 0, "nodes", "name", e->def->name, "mesh", 0,
                            "meshes", "name", e->def->name, "primitives", prim, "accessors", acc,
                            "bufferViews", views, "buffers", "byteLength",
                            (json_int_t)(pos_bytes + idx_bytes));
    char *text = doc ? json_dumps(doc, JSON_COMPACT) : NULL;
    json_decref(doc);
    if (!text) {
        o->failed = true;
        return;
    }
    size_t jn = strlen(text), jpad = (4 - jn % 4) % 4, bn = pos_bytes + idx_bytes;
    api_buf_put(o, "glTF", 4);
    api_buf_u32(o, 2);
    api_buf_u32(o, (uint32_t)(12 + 8 + jn + jpad + 8 + bn));
    api_buf_u32(o, (uint32_t)(jn + jpad));
    api_buf_put(o, "JSON", 4);
    api_buf_put(o, text, jn);
    api_buf_put(o, "    ", jpad);
    api_buf_u32(o, (uint32_t)bn);
    api_buf_put(o, "BIN\0", 4);
    for (size_t i = 0; i < 3 * (size_t)nv; i++)
        api_buf_f32(o, x[i]);
    for (size_t i = 0; i < 3 * (size_t)nt; i++)
        api_buf_u32(o, e->def->tri[i]);
    api_free(text);
}

int api_embed_get(api_model *m, const char *name, const char *format, char **body, size_t *len,
                  const char **ctype, uint64_t *version, api_problem *p)
{
    static const char *const formats[] = {"json", "obj", "glb", NULL};
    static const char *const types[] = {"application/json", "text/plain; charset=utf-8",
                                        "model/gltf-binary"};
    int f = 0;
    *body = NULL;
    if (name_ok(name, p)) /* no model can have it: the name is what is wrong */
        return p->status;
    if (format) {
        for (f = 0; formats[f] && strcmp(formats[f], format); f++)
            ;
        if (!formats[f])
            return api_fail_at(p, 422, "unknown-value", "format", "format \"%.20s\" is not one "
                               "of json, obj, glb", format);
    }
    pthread_mutex_lock(&m->lock);
    int at = find(m, name);
    if (at < 0) {
        pthread_mutex_unlock(&m->lock);
        return api_fail(p, 404, "not-found", "no embedded model \"%.48s\" in this session", name);
    }
    const api_embed *e = &m->embed[at];
    sd_error err;
    const sd_level *lv = sd_complex_level(m->c, e->def->level, &err);
    double *x = lv ? api_malloc(3 * sizeof(double) * ((size_t)e->def->nv + 1)) : NULL;
    if (!x) {
        pthread_mutex_unlock(&m->lock);
        return api_fail(p, 503, "out-of-memory", "out of memory");
    }
    sd_embed_positions(e->bind, lv, x);
    *version = atomic_load(&m->version);
    api_buf o = {0};
    if (f == 0)
        write_json(&o, e, x, *version);
    else if (f == 1)
        write_obj(&o, e, x, *version);
    else
        write_glb(&o, e, x, *version);
    pthread_mutex_unlock(&m->lock);
    api_free(x);
    if (o.failed || !o.b) {
        api_free(o.b);
        return api_fail(p, 503, "out-of-memory", "out of memory writing the model");
    }
    *body = o.b;
    *len = o.n;
    *ctype = types[f];
    return 0;
}

int api_embed_delta(api_model *m, const char *name, const char *since, const char *format,
                    char **body, size_t *len, const char **ctype, uint64_t *version,
                    api_problem *p)
{
    *body = NULL;
    if (name_ok(name, p)) /* no model can have it: the name is what is wrong */
        return p->status;
    pthread_mutex_lock(&m->lock);
    int at = find(m, name);
    if (at < 0) {
        pthread_mutex_unlock(&m->lock);
        return api_fail(p, 404, "not-found", "no embedded model \"%.48s\" in this session", name);
    }
    api_embed *e = &m->embed[at];
    uint64_t from;
    int json;
    uint32_t *ids = NULL;
    size_t n = 0;
    int rc = api_delta_moved(m, e->def->level, since, &from, &json, format, &ids, &n, p);
    if (!rc && from < e->since)
        rc = api_fail(p, 410, "delta-unavailable", "model \"%s\" was bound at version %llu, after "
                      "%llu; GET it again", e->def->name, (unsigned long long)e->since,
                      (unsigned long long)from);
    if (rc) {
        pthread_mutex_unlock(&m->lock);
        api_free(ids);
        return rc;
    }
    sd_error err;
    const sd_level *lv = sd_complex_level(m->c, e->def->level, &err);
    size_t k = sd_embed_update(e->bind, lv, ids, n, e->scratch, e->moved);
    api_free(ids);
    uint64_t cur = *version = atomic_load(&m->version);
    api_buf o = {0};
    if (!json) { /* written in place at its exact size: 24 + 16 bytes per vertex */
        size_t need = 24 + 16 * k;
        api_buf_reserve(&o, need);
        if (o.b) {
            uint32_t head[6] = {0, (uint32_t)e->def->level, (uint32_t)from, (uint32_t)cur,
                                (uint32_t)k, 0};
            memcpy(head, "SDD1", 4);
            memcpy(o.b, head, sizeof head); /* little endian: this host's order */
            memcpy(o.b + 24, e->moved, 4 * k);
            float *f = (float *)(void *)(o.b + 24 + 4 * k);
            for (size_t i = 0; i < k; i++) {
                const double *x = e->scratch + 3 * (size_t)e->moved[i];
                f[3 * i] = (float)x[0];
                f[3 * i + 1] = (float)x[1];
                f[3 * i + 2] = (float)x[2];
            }
            o.n = need;
            o.b[need] = 0;
        } else
            o.failed = true;
    } else {
        api_buf_printf(&o, "{\"name\":\"%s\",\"level\":%d,\"since\":%llu,\"version\":%llu,\"indices\":[",
             e->def->name, e->def->level, (unsigned long long)from, (unsigned long long)cur);
        for (size_t i = 0; i < k; i++)
            api_buf_printf(&o, i ? ",%u" : "%u", e->moved[i]);
        api_buf_put(&o, "],\"positions\":[", 15);
        for (size_t i = 0; i < k; i++) {
            if (i)
                api_buf_put(&o, ",", 1);
            api_buf_reals(&o, e->scratch + 3 * (size_t)e->moved[i], 3);
        }
        api_buf_put(&o, "]}", 2);
    }
    pthread_mutex_unlock(&m->lock);
    if (o.failed || !o.b) {
        api_free(o.b);
        return api_fail(p, 503, "out-of-memory", "out of memory writing the delta");
    }
    *body = o.b;
    *len = o.n;
    *ctype = json ? "application/json" : "application/octet-stream";
    return 0;
}

/* ---- through the session's changes ------------------------------------------------------------ */

int api_embed_rebind(const api_model *from, api_model *to, const api_limits *lim,
                     const api_slot *slot, api_problem *p)
{
    if (!from->nembed)
        return 0;
    if (!ensure_list(to))
        return api_fail(p, 503, "out-of-memory", "out of memory");
    for (int i = 0; i < from->nembed; i++) {
        api_embed e;
        if (bind(to, from->embed[i].def, lim, slot, &e, p)) {
            api_embed_free_all(to);
            p->nerrors = 0; /* the pointers were the model's, not this request's */
            return p->status;
        }
        to->embed[to->nembed++] = e;
    }
    api_model_publish(to);
    return 0;
}

json_t *api_embed_export(const api_model *m)
{
    json_t *o = json_object();
    for (int i = 0; o && m->embed && i < m->nembed; i++) {
        const api_embed_def *d = m->embed[i].def;
        json_t *vs = json_array(), *ts = json_array();
        for (uint32_t v = 0; v < d->nv; v++)
            json_array_append_new(vs, api_json_doubles(d->rest + 3 * (size_t)v, 3));
        for (uint32_t t = 0; t < d->nt; t++)
            json_array_append_new(ts, json_pack("[I, I, I]", (json_int_t)d->tri[3 * t],
                                                (json_int_t)d->tri[3 * t + 1],
                                                (json_int_t)d->tri[3 * t + 2]));
        /* the binding itself: re-binding the rest shape to points edited since would differ */
        json_t *bj = json_array();
        for (uint32_t v = 0; bj && v < d->nv; v++) {
            uint32_t idx[4];
            double w[4];
            if (!sd_embed_weights(m->embed[i].bind, v, idx, w)) {
                json_array_append_new(bj, json_null());
                continue;
            }
            json_t *row = json_pack("[I, I, I, I]", (json_int_t)idx[0], (json_int_t)idx[1],
                                    (json_int_t)idx[2], (json_int_t)idx[3]);
            for (int k = 0; row && k < 4; k++)
                json_array_append_new(row, json_real(w[k]));
            json_array_append_new(bj, row);
        }
        json_object_set_new(o, d->name, json_pack("{s:o, s:o, s:i, s:s, s:I, s:o}", "vertices", vs,
                                                  "triangles", ts, "level", d->level, "outside",
                                                  OUTSIDE[d->outside], "outside_vertices",
                                                  (json_int_t)m->embed[i].outside, "binding", bj));
    }
    return o;
}

/* Put d into m's list with a given binding (idx, w: 4 per vertex, idx UINT32_MAX for a fixed
 * vertex) — one saved in a document, or carried from a model of the same topology — instead of
 * binding its rest shape anew. `outside` is the count of its vertices that were outside every
 * cell when it was bound (a "nearest" one's extrapolate: its weights do not tell), or -1 for the
 * fixed ones' count (a document that does not give it). Problems point at `at`. */
static int adopt_binding(api_model *m, api_embed_def *d, const uint32_t *idx, const double *w,
                         long long outside, const char *at, const api_limits *lim,
                         api_problem *p)
{
    if (!m->c)
        return api_fail_at(p, 409, "no-complex", at, "embedded models need a complex with solids");
    if (!ensure_list(m))
        return api_fail(p, 503, "out-of-memory", "out of memory");
    if (find(m, d->name) >= 0 || m->nembed >= API_MAX_EMBEDDED)
        return api_fail_at(p, 422, "too-many-entries", at, "model \"%s\" twice, or too many", d->name);
    if (api_check_level_limits(m, d->level, lim, p) || api_level_compute(m, d->level, NULL, p))
        return p->status;
    api_embed e = {0};
    if (!embed_buffers(&e, d->nv)) {
        embed_clear(&e);
        return api_fail(p, 503, "out-of-memory", "out of memory");
    }
    int rc = 0;
    pthread_mutex_lock(&m->lock);
    sd_error err = {0};
    const sd_level *lv = sd_complex_level(m->c, d->level, &err);
    sd_allocator al = api_mem_core_allocator();
    if (!lv || sd_embed_restore(lv, d->nv, idx, w, d->rest, &al, 0, &e.bind, &err)) {
        char ptr[sizeof p->errors[0].pointer];
        if (err.code == SD_ERR_NOMEM)
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
        else if (lv && *at && err.code == SD_ERR_VALUE && err.item >= 0) {
            /* a saved binding naming a point the level does not have, or weights that do not
             * add up to 1: that entry (its index k when one is named), not "outside" */
            if (err.field >= 0)
                snprintf(ptr, sizeof ptr, "%s/%ld/%d", at, err.item, err.field);
            else
                snprintf(ptr, sizeof ptr, "%s/%ld", at, err.item);
            rc = api_fail_at(p, 422, "out-of-range", ptr, "model \"%s\": %s", d->name,
                             err.message);
        } else
            rc = api_fail_at(p, 422, "outside", at, "model \"%s\": %s", d->name, err.message);
    }
    if (!rc) {
        for (uint32_t v = 0; outside < 0 && v < d->nv; v++)
            e.outside += idx[4 * (size_t)v] == UINT32_MAX;
        if (outside >= 0)
            e.outside = (size_t)outside;
        e.since = atomic_load(&m->version);
        atomic_fetch_add(&d->refs, 1);
        e.def = d;
        m->embed[m->nembed++] = e;
        api_model_publish(m);
    }
    pthread_mutex_unlock(&m->lock);
    if (rc)
        embed_clear(&e);
    return rc;
}

/* A saved binding ([[i0, i1, i2, i3, w0, w1, w2, w3] | null per vertex]) of d into m's list. */
static int restore(api_model *m, api_embed_def *d, json_t *b, json_t *nout, const char *base,
                   const api_limits *lim, api_problem *p)
{
    char at[184];
    long long outside = -1;
    snprintf(at, sizeof at, "%s/outside_vertices", base);
    if (nout && api_get_int(nout, at, 0, d->nv, &outside, p))
        return p->status;
    snprintf(at, sizeof at, "%s/binding", base);
    if (!json_is_array(b) || json_array_size(b) != d->nv)
        return api_fail_at(p, 400, "wrong-type", at, "must be one entry per vertex (%u)", d->nv);
    uint32_t *idx = api_malloc(16 * ((size_t)d->nv + 1));
    double *w = api_malloc(32 * ((size_t)d->nv + 1));
    int rc = !idx || !w ? api_fail(p, 503, "out-of-memory", "out of memory") : 0;
    for (uint32_t v = 0; !rc && v < d->nv; v++) {
        json_t *row = json_array_get(b, v);
        if (json_is_null(row)) {
            idx[4 * (size_t)v] = UINT32_MAX;
            continue;
        }
        char ptr[200];
        snprintf(ptr, sizeof ptr, "%s/%u", at, v);
        if (!json_is_array(row) || json_array_size(row) != 8) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "a binding is [4 level vertices, 4 weights]");
            break;
        }
        for (int k = 0; !rc && k < 4; k++) {
            long long x;
            char ck[216];
            snprintf(ck, sizeof ck, "%s/%d", ptr, k);
            if (!(rc = api_get_int(json_array_get(row, (size_t)k), ck, 0, UINT32_MAX - 1, &x, p)))
                idx[4 * (size_t)v + k] = (uint32_t)x;
            snprintf(ck, sizeof ck, "%s/%d", ptr, 4 + k);
            if (!rc)
                /* any finite weight: a "nearest" vertex far from a small cell extrapolates with
                 * weights far beyond the coordinates' bound (their sum is checked when adopted) */
                rc = api_get_number(json_array_get(row, (size_t)(4 + k)), ck, DBL_MAX,
                                    &w[4 * (size_t)v + k], p);
        }
    }
    if (!rc)
        rc = adopt_binding(m, d, idx, w, outside, at, lim, p);
    api_free(idx);
    api_free(w);
    return rc;
}

int api_embed_carry(const api_model *from, api_model *to, const api_limits *lim, api_problem *p)
{
    int rc = 0;
    for (int i = 0; !rc && i < from->nembed; i++) {
        const api_embed *e = &from->embed[i];
        uint32_t n = e->def->nv, *idx = api_malloc(16 * ((size_t)n + 1));
        double *w = api_malloc(32 * ((size_t)n + 1));
        if (!idx || !w)
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
        for (uint32_t v = 0; !rc && v < n; v++)
            if (!sd_embed_weights(e->bind, v, idx + 4 * (size_t)v, w + 4 * (size_t)v))
                idx[4 * (size_t)v] = UINT32_MAX;
        if (!rc)
            rc = adopt_binding(to, e->def, idx, w, (long long)e->outside, "", lim, p);
        api_free(idx);
        api_free(w);
    }
    if (rc)
        api_embed_free_all(to);
    return rc;
}

int api_embed_import(api_model *m, json_t *emb, const char *base, const api_limits *lim,
                     api_problem *p)
{
    const char *name;
    json_t *v;
    if (json_object_size(emb) > API_MAX_EMBEDDED)
        return api_fail_at(p, 422, "too-many-entries", base, "at most %d embedded models",
                           API_MAX_EMBEDDED);
    json_object_foreach(emb, name, v) {
        char at[160];
        api_ptr_key(at, sizeof at, base, name); /* escaped (RFC 6901), whole when it fits */
        api_embed_def *d = NULL;
        api_problem q = {0};
        json_t *def = json_is_object(v) ? json_copy(v) : json_incref(v), *binding = NULL, *nout = NULL;
        if (json_is_object(def) && (binding = json_object_get(def, "binding")))
            json_incref(binding), json_object_del(def, "binding");
        if (json_is_object(def) && (nout = json_object_get(def, "outside_vertices")))
            json_incref(nout), json_object_del(def, "outside_vertices");
        int rc = name_ok(name, &q) ? api_fail_at(p, 422, "invalid-name", at, "%s", q.detail)
                                   : parse_def(def, name, at, lim, &d, p);
        json_decref(def);
        json_t *unused = NULL;
        if (!rc && binding)
            rc = restore(m, d, binding, nout, at, lim, p);
        else if (!rc)
            rc = api_embed_put(m, d, atomic_load(&m->version), lim, NULL, NULL, &unused, p);
        json_decref(unused);
        json_decref(binding);
        json_decref(nout);
        api_embed_def_unref(d);
        if (rc)
            return rc;
    }
    return 0;
}
