/* model.c — building, sharing and freeing session models (see model.h).
 *
 * A model is built whole, then published and never changed but for the core's lazily computed
 * levels (under `lock`) and an edit's positions (under the `data` write lock). References: the
 * session holds one, every request and stream in flight one each; the input is shared between
 * the successive models of a session by its own count. Which arrays are C-library blocks and
 * which are api_malloc ones is in model.h; api_model_unref frees each with its own family.
 */
#include "model.h"
#include "embedded.h"
#include "mem.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <jansson.h>
#include "out.h"
#include "delta.h"

api_input *api_input_new(void)
{
    api_input *in = api_calloc(1, sizeof *in);
    if (in)
        atomic_init(&in->refs, 1);
    return in;
}

bool api_input_reserve(api_input *in, size_t n)
{
    if (!api_mem_reserve(n))
        return false;
    in->reserved += n;
    return true;
}

bool api_input_account(api_input *in)
{
    size_t nidx = 0;
    for (uint32_t s = 0; s < in->ns; s++)
        nidx += in->size[s];
    size_t n = 3 * sizeof(double) * (size_t)in->nv + in->ns + nidx * sizeof(uint32_t);
    for (int a = 0; a < in->nattrs; a++)
        n += sizeof(double) * (size_t)in->nv * (size_t)in->attrs[a].ncomp;
    return n <= in->reserved || api_input_reserve(in, n - in->reserved);
}

api_input *api_input_copy(const api_input *in)
{
    api_input *c = api_input_new();
    if (!c)
        return NULL;
    size_t nidx = 0;
    for (uint32_t s = 0; s < in->ns; s++)
        nidx += in->size[s];
    c->nv = in->nv;
    c->ns = in->ns;
    c->nattrs = in->nattrs;
    c->ndiag = in->ndiag;
    c->nfill = in->nfill;
    size_t bytes = 3 * sizeof(double) * (size_t)in->nv + in->ns + nidx * sizeof(uint32_t);
    for (int a = 0; a < in->nattrs; a++)
        bytes += sizeof(double) * (size_t)in->nv * (size_t)in->attrs[a].ncomp;
    bool ok = api_input_reserve(c, bytes);
    size_t nxyz = 3 * sizeof(double) * ((size_t)in->nv + 1);
    if (ok && (c->xyz = api_plain_malloc(nxyz)))
        memcpy(c->xyz, in->xyz, 3 * sizeof(double) * (size_t)in->nv);
    if (ok && (c->size = api_plain_malloc((size_t)in->ns + 1)))
        memcpy(c->size, in->size, in->ns);
    if (ok && (c->idx = api_plain_malloc((nidx + 1) * sizeof *c->idx)))
        memcpy(c->idx, in->idx, nidx * sizeof *c->idx);
    ok = ok && c->xyz && c->size && c->idx;
    for (int a = 0; a < in->nattrs; a++) {
        c->attrs[a] = in->attrs[a];
        size_t n = sizeof(double) * (size_t)in->nv * (size_t)in->attrs[a].ncomp;
        c->attrs[a].data = ok ? api_plain_malloc(n + 1) : NULL;
        if (c->attrs[a].data)
            memcpy(c->attrs[a].data, in->attrs[a].data, n);
        ok = ok && c->attrs[a].data;
    }
    if (ok && in->ndiag)
        ok = (c->diag = api_memdup(in->diag, in->ndiag * sizeof *in->diag)) != NULL;
    if (ok && in->reoriented)
        ok = (c->reoriented = api_memdup(in->reoriented, (size_t)in->ns + 1)) != NULL;
    if (ok && in->nfill)
        ok = (c->fill = api_memdup(in->fill, in->nfill * sizeof *in->fill)) != NULL;
    c->repaired = json_incref(in->repaired);
    if (!ok) {
        api_input_unref(c);
        return NULL;
    }
    return c;
}

void api_input_unref(api_input *in)
{
    if (!in || atomic_fetch_sub(&in->refs, 1) != 1)
        return;
    api_mem_unreserve(in->reserved);
    api_plain_free(in->xyz);
    api_plain_free(in->size);
    api_plain_free(in->idx);
    for (int a = 0; a < in->nattrs; a++)
        api_plain_free(in->attrs[a].data);
    api_free(in->diag);
    api_free(in->reoriented);
    api_free(in->fill);
    json_decref(in->repaired);
    api_free(in);
}

int api_input_find_attr(const api_input *in, const char *name)
{
    for (int a = 0; a < in->nattrs; a++)
        if (!strcmp(in->attrs[a].name, name))
            return a;
    return -1;
}

void api_model_publish(api_model *m)
{
    size_t geo = 0;
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        geo += m->geometry[l] ? m->geometry[l]->bytes : 0;
    atomic_store(&m->levels_cached, m->c ? sd_complex_levels_computed(m->c) : 0);
    atomic_store(&m->memory_bytes, (m->c ? sd_complex_memory(m->c) : 0) + geo +
                                       api_delta_bytes(m->delta) + api_embed_bytes(m));
}

struct out_geometry *api_model_geometry_locked(api_model *m, int level)
{
    if (!m->geometry[level]) {
        sd_error e;
        const sd_level *lv = sd_complex_level(m->c, level, &e);
        if (lv)
            m->geometry[level] = out_geometry_compute(lv);
        if (m->geometry[level])
            api_delta_prepare(m, level);
        api_model_publish(m);
    }
    return m->geometry[level];
}

static _Thread_local int compute_threads = 1;

void api_set_compute_threads(int n) { compute_threads = n > 1 ? n : 1; }

int api_compute_threads(void) { return compute_threads; }

api_model *api_model_new(api_input *in, const api_rules *rules, uint64_t max_bytes, bool batch,
                         sd_error *err)
{
    api_model *m = api_calloc(1, sizeof *m);
    if (!m) {
        err->code = SD_ERR_NOMEM;
        snprintf(err->message, sizeof err->message, "out of memory");
        return NULL;
    }
    atomic_init(&m->refs, 1);
    atomic_init(&m->progress, -1.0);
    m->delta = api_delta_new();
    if (!m->delta) {
        api_free(m);
        err->code = SD_ERR_NOMEM;
        snprintf(err->message, sizeof err->message, "out of memory");
        return NULL;
    }
    pthread_mutex_init(&m->lock, NULL);
    pthread_rwlockattr_t ra;
    pthread_rwlockattr_init(&ra); /* an edit waits for the streams in flight, not for new ones */
    pthread_rwlockattr_setkind_np(&ra, PTHREAD_RWLOCK_PREFER_WRITER_NONRECURSIVE_NP);
    pthread_rwlock_init(&m->data, &ra);
    pthread_rwlockattr_destroy(&ra);
    if (rules)
        m->rules = *rules;
    m->rules.overrides = NULL; /* copied by api_model_set_overrides */
    m->rules.noverrides = 0;
    if (in) {
        sd_options opt = {.surface_weights = m->rules.surface_weights,
                          .solid_scheme = m->rules.solid_scheme,
                          .nonmanifold_default = m->rules.nonmanifold_default,
                          .nonmanifold_surface = m->rules.nonmanifold_surface,
                          .max_bytes = (size_t)max_bytes,
                          .allocator = api_mem_core_allocator(),
                          .reoriented = in->reoriented,
                          .classes = in->classes,
                          /* batch: levels written out, never edited (DECISIONS 46) */
                          .edit_index = batch ? SD_EDIT_INDEX_LAZY : SD_EDIT_INDEX_WITH_LEVELS,
                          .threads = compute_threads};
        int8_t *given = NULL; /* the chosen diagonals: Algorithm 2 picks the others against them */
        if (in->ndiag) {
            if (!(given = api_malloc((size_t)in->ns + 1))) {
                api_model_unref(m);
                err->code = SD_ERR_NOMEM;
                snprintf(err->message, sizeof err->message, "out of memory");
                return NULL;
            }
            memset(given, -1, (size_t)in->ns + 1);
            for (uint32_t d = 0; d < in->ndiag; d++)
                given[in->diag[d][0]] = (int8_t)in->diag[d][1];
            opt.diagonals = given;
        }
        m->c = sd_complex_new(in->xyz, in->nv, in->idx, in->size, in->ns, &opt, err);
        api_free(given);
        if (m->c) /* later computations take the threads of the request that runs them */
            sd_complex_set_threads(m->c, 1);
        if (!m->c) {
            api_model_unref(m);
            return NULL;
        }
        for (int a = 0; a < in->nattrs; a++) {
            m->channel[a] = sd_complex_add_channel(m->c, in->attrs[a].data, in->attrs[a].ncomp, err);
            if (m->channel[a] < 0) {
                err->item = a; /* which attribute; the core's item (vertex) is in the message */
                api_model_unref(m);
                return NULL;
            }
        }
        atomic_fetch_add(&in->refs, 1);
        m->in = in;
    }
    api_model_publish(m);
    return m;
}

void api_tags_free(api_tags *t)
{
    api_plain_free(t->size);
    api_plain_free(t->idx);
    api_plain_free(t->from);
    api_plain_free(t->pet);
    api_plain_free(t->sh);
    api_plain_free(t->tt);
    *t = (api_tags){0};
}

bool api_tags_copy(api_tags *dst, const api_tags *src)
{
    size_t nidx = 0;
    for (uint32_t i = 0; i < src->n; i++)
        nidx += src->size[i];
    api_tags t = {.n = src->n, .npet = src->npet, .nsh = src->nsh, .ntt = src->ntt,
                  .nnormals = src->nnormals, .ntangents = src->ntangents};
    t.crease = src->crease;
    t.size = api_plain_malloc(src->n + 1);
    t.idx = api_plain_malloc((nidx + 1) * sizeof *t.idx);
    t.pet = api_plain_malloc((src->npet + 1) * sizeof *t.pet);
    t.sh = api_plain_malloc((src->nsh + 1) * sizeof *t.sh);
    t.tt = api_plain_malloc((src->ntt + 1) * sizeof *t.tt);
    if (!t.size || !t.idx || !t.pet || !t.sh || !t.tt) {
        api_tags_free(&t);
        *dst = t;
        return false;
    }
    if (src->n) {
        memcpy(t.size, src->size, src->n);
        memcpy(t.idx, src->idx, nidx * sizeof *t.idx);
    }
    if (src->npet)
        memcpy(t.pet, src->pet, src->npet * sizeof *t.pet);
    if (src->nsh)
        memcpy(t.sh, src->sh, src->nsh * sizeof *t.sh);
    if (src->ntt)
        memcpy(t.tt, src->tt, src->ntt * sizeof *t.tt);
    *dst = t;
    return true;
}

/* Whether a sharpness is infinitely sharp: 10 or more as the 32-bit float the core (and
 * OpenSubdiv) holds, so that a value just below 10 that rounds to 10.0f is one. */
static bool sharp_infinite(double s)
{
    return s >= 10 || (float)s >= 10.0f; /* (the cast only of values in float's range) */
}

/* The singular tags with the infinitely sharp sharpness after them (s >= 10 is a singular tag:
 * docs/API.md "Creases"), and the finite sharpness for the core; then all three lists. */
int api_model_set_tags(api_model *m, const api_tags *t, sd_error *err, int *which)
{
    *which = API_TAG_SINGULAR;
    if (!api_tags_copy(&m->tags, t)) {
        err->code = SD_ERR_NOMEM;
        snprintf(err->message, sizeof err->message, "out of memory");
        return SD_ERR_NOMEM;
    }
    if (!m->c)
        return 0;
    size_t nidx = 0, ninf = 0;
    for (uint32_t i = 0; i < t->n; i++)
        nidx += t->size[i];
    for (uint32_t i = 0; i < t->nsh; i++)
        ninf += sharp_infinite(t->sh[i].value);
    uint8_t *size = api_plain_malloc(t->n + ninf + 1);
    uint32_t *idx = api_plain_malloc((nidx + 3 * ninf + 1) * sizeof *idx);
    uint32_t *from = api_plain_malloc((ninf + 1) * sizeof *from); /* sharpness entry of each */
    sd_sharpness *fin = api_plain_malloc((t->nsh - ninf + 1) * sizeof *fin);
    uint32_t *fin_from = api_plain_malloc((t->nsh - ninf + 1) * sizeof *fin_from);
    int rc = SD_OK;
    if (!size || !idx || !from || !fin || !fin_from) {
        err->code = SD_ERR_NOMEM;
        snprintf(err->message, sizeof err->message, "out of memory");
        rc = SD_ERR_NOMEM;
        goto out;
    }
    if (t->n) {
        memcpy(size, t->size, t->n);
        memcpy(idx, t->idx, nidx * sizeof *idx);
    }
    size_t ns = t->n, nf = 0;
    for (uint32_t i = 0; i < t->nsh; i++) {
        const api_sharp *x = &t->sh[i];
        if (sharp_infinite(x->value)) {
            from[ns - t->n] = i;
            for (int j = 0; j < x->nverts; j++)
                idx[nidx++] = x->v[j];
            size[ns++] = (uint8_t)x->nverts;
        } else {
            fin_from[nf] = i;
            fin[nf++] = (sd_sharpness){{x->v[0], x->v[1], x->v[2]}, x->nverts, (float)x->value};
        }
    }
    rc = sd_complex_set_singular(m->c, idx, size, ns, err);
    if (rc && err->item >= (long)t->n) { /* an infinitely sharp entry */
        *which = API_TAG_SHARPNESS;
        err->item = from[err->item - t->n];
        err->field = SD_SH_FIELD_SIMPLEX;
    }
    if (!rc && t->npet) {
        rc = sd_complex_set_petals(m->c, t->pet, t->npet, err);
        if (rc)
            *which = API_TAG_PETAL;
    }
    if (!rc && t->ntt) {
        rc = sd_complex_set_tangents(m->c, t->tt, t->ntt, err);
        if (rc)
            *which = API_TAG_TANGENT;
    }
    if (!rc && (nf || m->rules.crease_method)) {
        rc = sd_complex_set_sharpness(m->c, fin, nf, m->rules.crease_method, err);
        if (rc) {
            *which = API_TAG_SHARPNESS;
            if (err->item >= 0 && (size_t)err->item < nf)
                err->item = fin_from[err->item];
        }
    }
out:
    api_plain_free(size);
    api_plain_free(idx);
    api_plain_free(from);
    api_plain_free(fin);
    api_plain_free(fin_from);
    return rc;
}

int api_model_set_overrides(api_model *m, const sd_override *ov, uint32_t n, sd_error *err)
{
    if (!n)
        return 0;
    m->rules.overrides = api_plain_malloc(n * sizeof *ov);
    if (!m->rules.overrides) {
        err->code = SD_ERR_NOMEM;
        snprintf(err->message, sizeof err->message, "out of memory");
        return SD_ERR_NOMEM;
    }
    memcpy(m->rules.overrides, ov, n * sizeof *ov);
    m->rules.noverrides = n;
    return m->c ? sd_complex_set_overrides(m->c, ov, n, err) : 0;
}

api_model *api_model_ref(api_model *m)
{
    atomic_fetch_add(&m->refs, 1);
    return m;
}

void api_model_unref(api_model *m)
{
    if (!m || atomic_fetch_sub(&m->refs, 1) != 1)
        return;
    api_tags_free(&m->tags);
    api_plain_free(m->rules.overrides);
    json_decref(m->summary);
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        out_geometry_free(m->geometry[l]);
    api_delta_free(m->delta);
    api_embed_free_all(m); /* before the complex: the bindings are to its level */
    sd_complex_free(m->c);
    api_input_unref(m->in);
    pthread_mutex_destroy(&m->lock);
    pthread_rwlock_destroy(&m->data);
    api_free(m);
}

const sd_level *api_model_level_locked(api_model *m, int level, sd_error *err)
{
    struct timespec t0, t1;
    sd_complex_set_threads(m->c, compute_threads);
    int before = sd_complex_levels_computed(m->c);
    clock_gettime(CLOCK_MONOTONIC, &t0);
    const sd_level *lv = NULL;
    if (before > level)
        lv = sd_complex_level(m->c, level, err);
    else { /* one level at a time, so GET /v1/sessions/{id} can say how far the work is */
        double total = (double)sd_complex_estimate_bytes(m->c, level);
        atomic_store(&m->progress, 0.0);
        for (int l = before; l <= level; l++) {
            if (!(lv = sd_complex_level(m->c, l, err)))
                break;
            if (total > 0)
                atomic_store(&m->progress, 1.0 - (double)sd_complex_estimate_bytes(m->c, level) / total);
        }
        atomic_store(&m->progress, -1.0);
    }
    sd_complex_set_threads(m->c, 1); /* edits and the rest: the caller's thread */
    clock_gettime(CLOCK_MONOTONIC, &t1);
    if (lv && before <= level) /* the time of the levels computed now goes to the highest */
        m->seconds[level] += (double)(t1.tv_sec - t0.tv_sec) + (t1.tv_nsec - t0.tv_nsec) * 1e-9;
    api_model_publish(m);
    return lv;
}
