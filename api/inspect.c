/* inspect.c — the read-only views of the subdivision itself: GET /analysis (the local
 * subdivision matrix of a vertex or edge neighbourhood and its eigenvalues, 001 Sec. 4.1) and
 * GET /matrices/{L} (the sparse matrix from level F to level L, streamed by api/out_matrix.c).
 *
 * Both take the model's lock only while the core computes; the answers never change the model.
 * An edge's block lives at level 1, which the analysis computes if needed.
 */
#include "handlers.h"
#include "internal.h"
#include "mem.h"
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- local analysis ----------------------------------------------------------------------- */

/* A non-negative decimal index below `n` from a query value; -1 + problem otherwise. */
static long query_index(const char *s, uint32_t n, const char *name, api_problem *p)
{
    char *end = NULL;
    errno = 0;
    long v = s && isdigit((unsigned char)*s) ? strtol(s, &end, 10) : -1;
    if (v < 0 || *end) { /* a query value: bad-parameter, as since= and the other parameters */
        api_fail_at(p, 400, "bad-parameter", name,
                    "%s must be a vertex index (a non-negative integer)", name);
        return -1;
    }
    if (errno || (unsigned long)v >= n) { /* digits past long's range are out of range too */
        api_fail_at(p, 422, "out-of-range", name, "vertex %.*s%s out of range (%u vertices)",
                    (int)(end - s < 24 ? end - s : 24), s, end - s > 24 ? "…" : "", n);
        return -1;
    }
    return v;
}

/* ---- limit masks ---- */

static const char *limit_method_name(int method)
{
    switch (method) {
    case SD_LIMIT_FIXED: return "fixed";
    case SD_LIMIT_BSPLINE: return "bspline";
    case SD_LIMIT_LOOP: return "loop";
    case SD_LIMIT_EIGEN: return "eigenvector";
    default: return "none";
    }
}

/* "limit_mask": the weights on points.ids (0 where the mask does not read a point); into *info
 * ("limit"): what found them and at which level, the tangent masks on the same points where the
 * point has one tangent plane, the points the mask or the tangent masks read outside points.ids
 * (none for a closed block without tangents) with their weights, and what the detail offsets of
 * finer levels add (the constant terms) */
static json_t *limit_mask_json(const sd_analysis *an, const sd_limit_mask *lm, json_t **info)
{
    *info = json_null();
    double *w = api_calloc((size_t)an->size * 3, sizeof *w);
    if (!w)
        return NULL;
    json_t *extra = json_array();
    for (int i = 0; i < lm->n; i++) {
        int k = 0;
        while (k < an->size && an->points[k] != lm->points[i])
            k++;
        if (k == an->size) { /* with tangents, their weights there too (a boundary vertex's
                                across mask reads interior neighbours, a corner's its first two) */
            if (lm->w[i] != 0 || (lm->t1 && (lm->t1[i] != 0 || lm->t2[i] != 0)))
                json_array_append_new(
                    extra, lm->t1 ? json_pack("{s:I, s:f, s:[f, f]}", "id", (json_int_t)lm->points[i],
                                              "weight", lm->w[i], "tangents", lm->t1[i], lm->t2[i])
                                  : json_pack("{s:I, s:f}", "id", (json_int_t)lm->points[i],
                                              "weight", lm->w[i]));
            continue;
        }
        w[k] += lm->w[i];
        if (lm->t1) {
            w[an->size + k] += lm->t1[i];
            w[2 * (size_t)an->size + k] += lm->t2[i];
        }
    }
    json_t *mask = api_json_doubles(w, (size_t)an->size);
    json_t *j = json_pack("{s:s, s:i, s:o, s:o}", "method", limit_method_name(lm->method),
                          "level", lm->eval_level, "outside", extra, "offset",
                          api_json_doubles(lm->offset, 3));
    if (j && lm->t1 &&
        (json_object_set_new(j, "tangents",
                             json_pack("[o, o]", api_json_doubles(w + an->size, (size_t)an->size),
                                       api_json_doubles(w + 2 * (size_t)an->size, (size_t)an->size))) |
         json_object_set_new(j, "tangent_offsets",
                             json_pack("[o, o]", api_json_doubles(lm->t_offset[0], 3),
                                       api_json_doubles(lm->t_offset[1], 3))))) {
        json_decref(j);
        j = NULL;
    }
    *info = j;
    api_free(w);
    return mask;
}

/* "full": {"size", "matrix", "eigenvalues", "points": {"level", "ids"}} */
static json_t *eig_json(const sd_analysis *a)
{
    json_t *eig = json_array();
    for (int i = 0; i < a->size; i++) /* a real eigenvalue as a number, a complex one as [re, im] */
        json_array_append_new(eig, fabs(a->eig_im[i]) <= 1e-12 * (1 + fabs(a->eig_re[i]))
                                       ? json_real(a->eig_re[i])
                                       : json_pack("[f, f]", a->eig_re[i], a->eig_im[i]));
    return eig;
}

static json_t *full_json(const sd_analysis *a)
{
    json_t *mat = json_array(), *pts = json_array();
    bool ok = mat && pts;
    for (int i = 0; i < a->size && ok; i++)
        ok = !json_array_append_new(mat, api_json_doubles(a->matrix + (size_t)i * a->size,
                                                          (size_t)a->size)) &&
             !json_array_append_new(pts, json_integer(a->points[i]));
    if (!ok) {
        json_decref(mat);
        json_decref(pts);
        return NULL;
    }
    return json_pack("{s:i, s:o, s:o, s:{s:i, s:o}}", "size", a->size, "matrix", mat,
                     "eigenvalues", eig_json(a), "points", "level", a->level, "ids", pts);
}

/* The block of vertex a (b < 0) or of edge a-b. */
static sd_result analyze_block(sd_complex *c, long a, long b, sd_analysis *an, sd_error *e)
{
    return b < 0 ? sd_analyze_vertex(c, (uint32_t)a, an, e)
                 : sd_analyze_edge(c, (uint32_t)a, (uint32_t)b, an, e);
}

static json_t *block_failed(sd_result r, const sd_error *e, long b, api_problem *p)
{
    if (r == SD_ERR_ARG) /* the block itself: not invariant, or over SD_ANALYSIS_MAX_POINTS */
        api_fail_at(p, 422, "not-analysable", b < 0 ? "vertex" : "edge", "%s", e->message);
    else
        api_fail_core(p, e, NULL, NULL);
    return NULL;
}

json_t *api_analysis(api_model *m, const char *vertex, const char *edge, const api_limits *lim,
                     const api_slot *slot,
                     api_problem *p)
{
    if (!m->c) {
        api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
        return NULL;
    }
    if (!vertex && !edge) {
        api_fail_at(p, 400, "missing-parameter", "vertex", "give exactly one of vertex=i or edge=i,j");
        api_add_error(p, "edge", "or this one");
        return NULL;
    }
    if (vertex && edge) {
        api_fail_at(p, 400, "bad-parameter", "vertex",
                    "give exactly one of vertex=i or edge=i,j, not both");
        api_add_error(p, "edge", "given with vertex");
        return NULL;
    }
    long a, b = -1;
    if (vertex) {
        if ((a = query_index(vertex, m->in->nv, "vertex", p)) < 0)
            return NULL;
    } else {
        char first[24];
        const char *comma = strchr(edge, ',');
        if (!comma || (size_t)(comma - edge) >= sizeof first || strchr(comma + 1, ',')) {
            api_fail_at(p, 400, "wrong-type", "edge", "edge is two vertex indices: edge=i,j");
            return NULL;
        }
        snprintf(first, sizeof first, "%.*s", (int)(comma - edge), edge);
        if ((a = query_index(first, m->in->nv, "edge", p)) < 0 ||
            (b = query_index(comma + 1, m->in->nv, "edge", p)) < 0)
            return NULL;
        if (sd_level_find_edge(m->level0, (uint32_t)a, (uint32_t)b) == UINT32_MAX) {
            api_fail_at(p, 422, "no-such-edge", "edge", "%ld-%ld is not an edge of the complex", a, b);
            return NULL;
        }
    }
    if (api_level_compute(m, 1, slot, p)) /* an edge's block lives at level 1 */
        return NULL;
    /* the block first: one the core refuses (not invariant, over SD_ANALYSIS_MAX_POINTS) is
     * answered before the finer levels below are made for it. Its eigen-decomposition is compute
     * like a level's: in a slot (its size bounds the time held). */
    sd_analysis an, fa = {0};
    sd_limit_mask lm = {0};
    sd_error e = {0}, fe = {0};
    pthread_mutex_lock(&m->lock);
    if (slot && slot->take(slot->ud, 1, p)) {
        pthread_mutex_unlock(&m->lock);
        return NULL;
    }
    sd_result r = analyze_block(m->c, a, b, &an, &e);
    uint64_t seen = atomic_load(&m->version);
    if (slot)
        slot->give(slot->ud);
    pthread_mutex_unlock(&m->lock);
    if (r)
        return block_failed(r, &e, b, p);
    /* the limit mask is read at the limit level of the block's level (core/limit.c), the full
     * matrix at levels 1 and 2; each only within the limits (else null) */
    pthread_mutex_lock(&m->lock);
    int ll = sd_complex_limit_level(m->c, b < 0 ? 0 : 1);
    pthread_mutex_unlock(&m->lock);
    api_problem skip = {0};
    bool with_limit = !api_check_level_limits(m, ll, lim, &skip);
    bool with_full = !api_check_level_limits(m, 2, lim, &skip);
    if ((with_limit && api_level_compute(m, ll, slot, p)) ||
        (with_full && api_level_compute(m, 2, slot, p))) {
        sd_analysis_free(&an);
        return NULL;
    }
    pthread_mutex_lock(&m->lock);
    if (slot && slot->take(slot->ud, 1, p)) {
        pthread_mutex_unlock(&m->lock);
        sd_analysis_free(&an);
        return NULL;
    }
    /* an edit in between may have changed the rules (a moved corner's angle): the block again,
     * so that every part of the answer is of one version */
    if (atomic_load(&m->version) != seen) {
        sd_analysis_free(&an);
        r = analyze_block(m->c, a, b, &an, &e);
    }
    if (!r && with_limit && (r = sd_limit_mask_of(m->c, an.level, an.points[0], &lm, &e)))
        sd_analysis_free(&an);
    sd_result fr = SD_ERR_ARG;
    if (!r && with_full) {
        fr = b < 0 ? sd_analyze_full_vertex(m->c, (uint32_t)a, &fa, &fe)
                   : sd_analyze_full_edge(m->c, (uint32_t)a, (uint32_t)b, &fa, &fe);
        /* not invariant, or over SD_ANALYSIS_MAX_POINTS, is no error: "full" is null then */
        if (fr && fr != SD_ERR_ARG) {
            r = fr;
            e = fe;
            sd_analysis_free(&an);
            sd_limit_mask_free(&lm);
        }
    }
    if (slot)
        slot->give(slot->ud);
    pthread_mutex_unlock(&m->lock);
    if (r)
        return block_failed(r, &e, b, p);
    json_t *mat = json_array(), *eig = json_array(), *pts = json_array();
    for (int i = 0; i < an.size; i++) {
        json_array_append_new(mat, api_json_doubles(an.matrix + (size_t)i * an.size, (size_t)an.size));
        /* a real eigenvalue as a number, a complex one as [re, im] */
        if (fabs(an.eig_im[i]) <= 1e-12 * (1 + fabs(an.eig_re[i])))
            json_array_append_new(eig, json_real(an.eig_re[i]));
        else
            json_array_append_new(eig, json_pack("[f, f]", an.eig_re[i], an.eig_im[i]));
        json_array_append_new(pts, json_integer(an.points[i]));
    }
    json_t *j = json_pack("{s:s, s:i, s:o, s:o, s:{s:i, s:o}, s:b}", "rule",
                          sd_rule_name(an.rule), "size", an.size, "matrix", mat, "eigenvalues", eig,
                          "points", "level", an.level, "ids", pts, "closed", an.closed);
    json_t *info = json_null();
    json_t *mask = with_limit ? limit_mask_json(&an, &lm, &info) : json_null();
    /* each set takes its value (and drops it when it fails): out of memory is no answer */
    if (json_object_set_new(j, "limit_mask", mask) | json_object_set_new(j, "limit", info) |
        json_object_set_new(j, "full", fr ? json_null() : full_json(&fa))) {
        json_decref(j);
        j = NULL;
    }
    sd_analysis_free(&fa);
    sd_analysis_free(&an);
    sd_limit_mask_free(&lm);
    return j;
}


/* ---- GET /matrices/{L} -------------------------------------------------------------------- */

int api_matrix_open(api_model *m, int level, const char *from, const char *format,
                    const api_limits *lim, const api_slot *slot, out_stream **out,
                    const char **ctype, api_problem *p)
{
    *out = NULL;
    if (!m->c)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    bool json = false;
    if (format && !(json = !strcmp(format, "json")) && strcmp(format, "mtx"))
        return api_fail_at(p, 422, "unknown-value", "format",
                           "format \"%.20s\" is not one of mtx, json", format);
    long f = 0;
    if (from) {
        char *end;
        errno = 0;
        f = isdigit((unsigned char)*from) ? strtol(from, &end, 10) : -1;
        if (f < 0 || *end || errno)
            return api_fail_at(p, 400, "wrong-type", "from", "from must be a level number");
    }
    if (level < 1)
        return api_fail_at(p, 422, "out-of-range", "from",
                           "level 0 has no matrix: ask for a level of 1 or more");
    if (f >= level)
        return api_fail_at(p, 422, "out-of-range", "from",
                           "from (%ld) must be below the level (%d)", f, level);
    if (api_check_level_limits(m, level, lim, p) || api_level_compute(m, level, slot, p))
        return p->status;
    sd_error e = {0};
    pthread_mutex_lock(&m->lock);
    if (api_model_level_locked(m, level, &e))
        *out = out_matrix_open(m->c, (int)f, level, json, 32 * lim->max_cells, &e);
    pthread_mutex_unlock(&m->lock);
    if (!*out)
        return e.code == SD_ERR_LIMIT
                   ? api_fail_limit(p, "max_cells", lim->max_cells, 0,
                                    "%s (the limit is 32 entries per allowed cell); ask for a "
                                    "closer from-level", e.message)
                   : api_fail_core(p, &e, NULL, NULL);
    *ctype = json ? "application/json" : "text/plain; charset=utf-8";
    return 0;
}
