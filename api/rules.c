/* rules.c — PUT /rules and PUT /tags (docs/API.md "Tags and rules"): the rule preferences and
 * per-simplex overrides (000 Sec. 3.5: N1, N2, G1, G2), the singular simplices and the petal tags
 * of Ying-Zorin's corners (003 Sec. 2).
 *
 * Both handlers check shapes, enumerations and index ranges here, with a pointer for every
 * refusal, and leave to the core what needs the complex (a tag is a simplex of it, a petal is open,
 * an override fits its simplex), which api_build_model maps back to pointers. The new model keeps
 * the session's input and its detail offsets (api/details.c); only the rules or the tags change.
 */
#include "handlers.h"
#include "details.h"
#include "mem.h"
#include "internal.h"
#include "crease.h"
#include "jsonin.h"
#include "rows.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The detail offsets of cur onto the model just built (*out, when rc is 0); the status. */
static int keep_details(const api_model *cur, int rc, api_model **out, api_problem *p)
{
    if (!rc && *out && (rc = api_details_carry(cur, *out, p))) {
        api_model_unref(*out);
        *out = NULL;
    }
    return rc;
}

/* A model of cur's complex with other rules or tags, built from a copy of cur's input: an edit
 * writes the input of the model it edits in place (api/edit.c), which must not be the input a
 * stream of the previous model still reads. */
static int build_from_copy(const api_model *cur, const api_rules *rules, const api_tags *tags,
                           const api_limits *lim, api_model **out, api_problem *p)
{
    if (!cur->in) /* no complex yet */
        return api_build_model(NULL, rules, tags, lim, out, p);
    api_input *in = api_input_copy(cur->in);
    if (!in)
        return api_fail(p, 503, "out-of-memory", "out of memory copying the complex");
    int rc = api_build_model(in, rules, tags, lim, out, p);
    api_input_unref(in);
    return rc;
}

/* ---- PUT /rules ---------------------------------------------------------------------------- */

static const char *const NM_RULES[] = {"G2", "G1", "N1", "N2", NULL};

/* An N2 override's "pair" at `at`: two curve segments holding the simplex, or two triangles. */
static int parse_pair(json_t *pr, const char *at, uint32_t nv, sd_override *x, api_problem *p)
{
    char at2[160];
    if (!json_is_array(pr) || json_array_size(pr) != 2)
        return api_fail_at(p, json_is_array(pr) ? 422 : 400,
                           json_is_array(pr) ? "invalid-override" : "wrong-type", at,
                           "a pair is an array of two simplices");
    for (size_t j = 0; j < 2; j++) {
        json_t *q = json_array_get(pr, j);
        api_ptr_index(at2, sizeof at2, at, j);
        if (!json_is_array(q))
            return api_fail_at(p, 400, "wrong-type", at2, "a simplex is an array of vertex indices");
        size_t kq = json_array_size(q);
        if (kq < 2 || kq > 3 || (j == 1 && (int)kq != x->pair_size))
            return api_fail_at(p, 422, "invalid-override", at2,
                               "the pair is two curve segments (2 indices each) or two "
                               "triangles (3 each)");
        x->pair_size = (int)kq;
        for (size_t u = 0; u < kq; u++) {
            long long id;
            char at3[192];
            api_ptr_index(at3, sizeof at3, at2, u);
            if (api_get_int(json_array_get(q, u), at3, 0, (long long)nv - 1, &id, p))
                return p->status;
            x->pair[j][u] = (uint32_t)id;
        }
    }
    return 0;
}

/* Override i of "overrides" into *x: {"simplex": vertex or edge, "rule", "dimension" (N1 only),
 * "pair" (N2 only)}. 0 or the problem's status. */
static int parse_override(json_t *o, size_t i, uint32_t nv, sd_override *x, api_problem *p)
{
    static const char *const okeys[] = {"simplex", "rule", "dimension", "pair", NULL};
    char ptr[96], at[128], at2[160];
    api_ptr_index(ptr, sizeof ptr, "/overrides", i);
    if (!json_is_object(o))
        return api_fail_at(p, 400, "wrong-type", ptr, "an override is an object");
    if (api_only_keys(o, ptr, okeys, p))
        return p->status;
    json_t *sx = json_object_get(o, "simplex"), *ru = json_object_get(o, "rule");
    json_t *dim = json_object_get(o, "dimension"), *pr = json_object_get(o, "pair");
    snprintf(at, sizeof at, "%s/simplex", ptr);
    if (!sx)
        return api_fail_at(p, 400, "missing-field", at, "\"simplex\" is required");
    if (!json_is_array(sx))
        return api_fail_at(p, 400, "wrong-type", at, "a simplex is an array of vertex indices");
    size_t k = json_array_size(sx);
    if (k < 1 || k > 2)
        return api_fail_at(p, 422, "invalid-override", at,
                           "rules are chosen per vertex or edge (1 or 2 indices), not for %zu "
                           "vertices: a %s has no point of its own", k,
                           k == 3 ? "triangle" : k == 4 ? "tetrahedron" : "simplex");
    for (size_t j = 0; j < k; j++) {
        long long id;
        api_ptr_index(at2, sizeof at2, at, j);
        if (api_get_int(json_array_get(sx, j), at2, 0, (long long)nv - 1, &id, p))
            return p->status;
        x->simplex[j] = (uint32_t)id;
    }
    x->nverts = (int)k;
    snprintf(at, sizeof at, "%s/rule", ptr);
    if (!ru)
        return api_fail_at(p, 400, "missing-field", at, "\"rule\" is required");
    int which = api_get_enum(ru, at, NM_RULES, p);
    if (which < 0)
        return p->status;
    static const sd_rule map[] = {SD_RULE_G2, SD_RULE_G1, SD_RULE_N1, SD_RULE_N2};
    x->rule = map[which];
    snprintf(at, sizeof at, "%s/dimension", ptr);
    if (x->rule == SD_RULE_N1 && !dim)
        return api_fail_at(p, 400, "missing-field", at, "N1 needs the \"dimension\" to follow");
    if (x->rule != SD_RULE_N1 && dim)
        return api_fail_at(p, 422, "invalid-override", at, "only N1 takes a dimension");
    if (dim) {
        long long d;
        if (api_get_int(dim, at, 1, 3, &d, p))
            return p->status;
        x->dimension = (int)d;
    }
    snprintf(at, sizeof at, "%s/pair", ptr);
    if (x->rule == SD_RULE_N2 && !pr)
        return api_fail_at(p, 400, "missing-field", at, "N2 needs the \"pair\" of simplices to follow");
    if (x->rule != SD_RULE_N2 && pr)
        return api_fail_at(p, 422, "invalid-override", at, "only N2 takes a pair");
    return pr ? parse_pair(pr, at, nv, x, p) : 0;
}

int api_put_rules(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                  api_problem *p)
{
    static const char *const keys[] = {"nonmanifold_default", "overrides", "solid_scheme",
                                       "surface_weights", "nonmanifold_surface", "crease_method",
                                       NULL};
    static const char *const creases[] = {"uniform", "chaikin", NULL};
    static const char *const schemes[] = {"box", "averaged", NULL};
    static const char *const weights[] = {"warren", "loop", NULL};
    static const char *const surfaces[] = {"chang-qin", "ying-zorin", NULL};
    *out = NULL;
    if (api_only_keys(body, "", keys, p))
        return p->status;
    api_rules r = {0};
    json_t *v;
    int nm = 0, surf = 0;
    if ((v = json_object_get(body, "solid_scheme")) &&
        (r.solid_scheme = api_get_enum(v, "/solid_scheme", schemes, p)) < 0)
        return p->status;
    if ((v = json_object_get(body, "surface_weights")) &&
        (r.surface_weights = api_get_enum(v, "/surface_weights", weights, p)) < 0)
        return p->status;
    if ((v = json_object_get(body, "nonmanifold_default")) &&
        (nm = api_get_enum(v, "/nonmanifold_default", NM_RULES, p)) < 0)
        return p->status;
    if ((v = json_object_get(body, "nonmanifold_surface")) &&
        (surf = api_get_enum(v, "/nonmanifold_surface", surfaces, p)) < 0)
        return p->status;
    if ((v = json_object_get(body, "crease_method")) &&
        (r.crease_method = api_get_enum(v, "/crease_method", creases, p)) < 0)
        return p->status;
    if (nm >= 2)
        return api_fail_at(p, 422, "invalid-rule", "/nonmanifold_default",
                           "%s needs a per-simplex choice of dimension or pair; use G1 or G2 as "
                           "the default and give N1/N2 in \"overrides\"", NM_RULES[nm]);
    r.nonmanifold_default = nm == 1 ? SD_NM_G1 : SD_NM_G2;
    r.nonmanifold_surface = surf == 1 ? SD_NMSURF_YING_ZORIN : SD_NMSURF_CHANG_QIN;
    json_t *ov = json_object_get(body, "overrides");
    if (ov && !json_is_array(ov))
        return api_fail_at(p, 400, "wrong-type", "/overrides", "must be an array of overrides");
    size_t nov = ov ? json_array_size(ov) : 0;
    if (nov && !cur->in)
        return api_fail_at(p, 409, "no-complex", "/overrides",
                           "overrides name simplices of the complex; PUT the complex first");
    if (nov && nov > (size_t)cur->in->nv + 6 * (size_t)cur->in->ns) /* > vertices + edges */
        return api_fail_at(p, 422, "too-many-entries", "/overrides",
                           "%zu overrides for a complex of %u vertices and %u simplices: at most "
                           "one per vertex or edge", nov, cur->in->nv, cur->in->ns);
    sd_override *list = api_calloc(nov + 1, sizeof *list);
    if (!list)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    int rc = 0;
    size_t i;
    json_t *o;
    json_array_foreach(ov, i, o)
        if ((rc = parse_override(o, i, cur->in->nv, &list[i], p)))
            break;
    if (!rc) {
        r.overrides = list;
        r.noverrides = (uint32_t)nov;
        rc = build_from_copy(cur, &r, &cur->tags, lim, out, p);
    }
    api_free(list);
    return keep_details(cur, rc, out, p);
}

/* ---- PUT /tags ----------------------------------------------------------------------------- */

/* "petals": [{"vertex", "triangle", "kind"}] (docs/API.md, docs/SERVICE.md "Tags"): the corner
 * kind of open petals at complex singular vertices (003 Sec. 2). Shapes and ranges here, the
 * rest (the triangle holds the vertex, the petal is open, ...) in the core. */
static int parse_petals(json_t *a, uint32_t nv, api_tags *tags, api_problem *p)
{
    static const char *const keys[] = {"vertex", "triangle", "kind", NULL};
    static const char *const kinds[] = {"convex", "concave", "smooth", NULL};
    if (!json_is_array(a))
        return api_fail_at(p, 400, "wrong-type", "/petals",
                           "must be an array of {\"vertex\", \"triangle\", \"kind\"}");
    size_t n = json_array_size(a), i;
    tags->pet = api_plain_malloc((n + 1) * sizeof *tags->pet);
    if (!tags->pet)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    json_t *o;
    char ptr[96], at[112], at2[128];
    json_array_foreach(a, i, o) {
        api_ptr_index(ptr, sizeof ptr, "/petals", i);
        if (!json_is_object(o))
            return api_fail_at(p, 400, "wrong-type", ptr,
                               "a petal tag is an object {\"vertex\", \"triangle\", \"kind\"}");
        if (api_only_keys(o, ptr, keys, p))
            return p->status;
        sd_petal_tag *t = &tags->pet[i];
        long long x;
        json_t *v = json_object_get(o, "vertex"), *tr = json_object_get(o, "triangle"),
               *k = json_object_get(o, "kind");
        for (int f = 0; f < 3; f++)
            if (!(f == 0 ? v : f == 1 ? tr : k)) {
                api_ptr_key(at, sizeof at, ptr, keys[f]);
                return api_fail_at(p, 400, "missing-field", at, "\"%s\" is required", keys[f]);
            }
        api_ptr_key(at, sizeof at, ptr, "vertex");
        if (api_get_int(v, at, 0, (long long)nv - 1, &x, p))
            return p->status;
        t->vertex = (uint32_t)x;
        api_ptr_key(at, sizeof at, ptr, "triangle");
        if (!json_is_array(tr) || json_array_size(tr) != 3)
            return api_fail_at(p, json_is_array(tr) ? 422 : 400,
                               json_is_array(tr) ? "invalid-tag" : "wrong-type", at,
                               "a triangle is an array of 3 vertex indices");
        for (size_t j = 0; j < 3; j++) {
            api_ptr_index(at2, sizeof at2, at, j);
            if (api_get_int(json_array_get(tr, j), at2, 0, (long long)nv - 1, &x, p))
                return p->status;
            t->triangle[j] = (uint32_t)x;
            for (size_t q = 0; q < j; q++)
                if (t->triangle[q] == t->triangle[j])
                    return api_fail_at(p, 422, "invalid-tag", at2, "vertex %lld appears twice", x);
        }
        api_ptr_key(at, sizeof at, ptr, "kind");
        if ((t->kind = api_get_enum(k, at, kinds, p)) < 0)
            return p->status;
        tags->npet++;
    }
    return 0;
}

/* ---- tangent-plane constraints (003 Sec. 3; docs/API.md "Tangent planes") ------------------ */

/* [x, y, z]: three finite numbers (the core refuses the zero vector and the rest). */
static int get_vec3(json_t *a, const char *at, double out[3], api_problem *p)
{
    if (!json_is_array(a) || json_array_size(a) != 3)
        return api_fail_at(p, json_is_array(a) ? 422 : 400,
                           json_is_array(a) ? "invalid-tag" : "wrong-type", at,
                           "a direction is an array of 3 numbers");
    char at2[160];
    for (size_t j = 0; j < 3; j++) {
        api_ptr_index(at2, sizeof at2, at, j);
        if (api_get_number(json_array_get(a, j), at2, 1e300, &out[j], p))
            return p->status;
    }
    return 0;
}

/* [a, b, c]: three different vertex indices. */
static int get_triangle(json_t *tr, const char *at, uint32_t nv, uint32_t out[3], api_problem *p)
{
    if (!json_is_array(tr) || json_array_size(tr) != 3)
        return api_fail_at(p, json_is_array(tr) ? 422 : 400,
                           json_is_array(tr) ? "invalid-tag" : "wrong-type", at,
                           "a triangle is an array of 3 vertex indices");
    char at2[160];
    for (size_t j = 0; j < 3; j++) {
        long long x;
        api_ptr_index(at2, sizeof at2, at, j);
        if (api_get_int(json_array_get(tr, j), at2, 0, (long long)nv - 1, &x, p))
            return p->status;
        out[j] = (uint32_t)x;
        for (size_t q = 0; q < j; q++)
            if (out[q] == out[j])
                return api_fail_at(p, 422, "invalid-tag", at2, "vertex %lld appears twice", x);
    }
    return 0;
}

/* An entry's object with its allowed and required keys. */
static int tt_entry(json_t *o, const char *ptr, const char *const *keys, int nreq,
                    const char *shape, api_problem *p)
{
    if (!json_is_object(o))
        return api_fail_at(p, 400, "wrong-type", ptr, "an entry is an object %s", shape);
    if (api_only_keys(o, ptr, keys, p))
        return p->status;
    char at[160];
    for (int f = 0; f < nreq; f++)
        if (!json_object_get(o, keys[f])) {
            api_ptr_key(at, sizeof at, ptr, keys[f]);
            return api_fail_at(p, 400, "missing-field", at, "\"%s\" is required", keys[f]);
        }
    return 0;
}

static int tt_push(api_tags *tags, uint32_t *cap, sd_tangent_tag x, api_problem *p)
{
    if (tags->ntt == *cap) {
        uint32_t nc = *cap ? 2 * *cap : 16;
        sd_tangent_tag *n = api_plain_realloc(tags->tt, (size_t)nc * sizeof *n);
        if (!n)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        tags->tt = n;
        *cap = nc;
    }
    tags->tt[tags->ntt++] = x;
    return 0;
}

/* "normals": [{"vertex", "triangles": [[a, b, c], ...], "normal"?}], "tangents": [{"vertex",
 * "triangle", "tangent"}], "tangent_edges": [{"edge": [a, b], "triangles"?: [t0, t1]}]: shapes
 * and ranges here, the rest (the petal is closed, the vertex simple, ...) in the core. */
static int parse_tangents(json_t *nm, json_t *tg, json_t *te, const api_input *in,
                          api_tags *tags, api_problem *p)
{
    const uint32_t nv = in ? in->nv : 0;
    /* at most one entry per petal or edge: fewer than vertices + edges + faces, before
     * allocating (as for sharpness) */
    const size_t most = in ? (size_t)in->nv + 10 * (size_t)in->ns : 0;
    static const char *const lists[] = {"/normals", "/tangents", "/tangent_edges"};
    static const char *const shapes[] = {"{\"vertex\", \"triangles\", \"normal\"}",
                                         "{\"vertex\", \"triangle\", \"tangent\"}",
                                         "{\"edge\", \"triangles\"}"};
    static const char *const kn[] = {"vertex", "triangles", "normal", NULL};
    static const char *const kt[] = {"vertex", "triangle", "tangent", NULL};
    static const char *const ke[] = {"edge", "triangles", NULL};
    json_t *l3[3] = {nm, tg, te};
    uint32_t cap = 0;
    char ptr[96], at[160], at2[176];
    for (int L = 0; L < 3; L++) {
        json_t *a = l3[L], *o;
        if (!a)
            continue;
        if (!json_is_array(a))
            return api_fail_at(p, 400, "wrong-type", lists[L], "must be an array of %s",
                               shapes[L]);
        if (json_array_size(a) > most)
            return api_fail_at(p, 422, "too-many-entries", lists[L],
                               "%zu entries for a complex of %u vertices and %u simplices: at "
                               "most one per petal or edge", json_array_size(a), nv,
                               in ? in->ns : 0);
        size_t i;
        json_array_foreach(a, i, o) {
            api_ptr_index(ptr, sizeof ptr, lists[L], i);
            if (tt_entry(o, ptr, L == 0 ? kn : L == 1 ? kt : ke, L == 2 ? 1 : L == 0 ? 2 : 3,
                         shapes[L], p))
                return p->status;
            sd_tangent_tag x = {.kind = L == 0   ? SD_TT_NORMAL
                                        : L == 1 ? SD_TT_TANGENT
                                                 : SD_TT_EDGE};
            long long id;
            if (L < 2) {
                api_ptr_key(at, sizeof at, ptr, "vertex");
                if (api_get_int(json_object_get(o, "vertex"), at, 0, (long long)nv - 1, &id, p))
                    return p->status;
                x.vertex = (uint32_t)id;
                json_t *vec = json_object_get(o, L == 0 ? "normal" : "tangent");
                api_ptr_key(at, sizeof at, ptr, L == 0 ? "normal" : "tangent");
                if (!vec)
                    x.vec[0] = x.vec[1] = x.vec[2] = NAN; /* a shared normal (Fig. 6(b)) */
                else if (get_vec3(vec, at, x.vec, p))
                    return p->status;
            }
            if (L == 1) {
                api_ptr_key(at, sizeof at, ptr, "triangle");
                if (get_triangle(json_object_get(o, "triangle"), at, nv, x.triangle, p) ||
                    tt_push(tags, &cap, x, p))
                    return p->status;
                tags->ntangents++;
                continue;
            }
            json_t *trs = json_object_get(o, "triangles");
            api_ptr_key(at, sizeof at, ptr, "triangles");
            if (L == 2) {
                json_t *ed = json_object_get(o, "edge");
                api_ptr_key(at2, sizeof at2, ptr, "edge");
                if (!json_is_array(ed) || json_array_size(ed) != 2)
                    return api_fail_at(p, json_is_array(ed) ? 422 : 400,
                                       json_is_array(ed) ? "invalid-tag" : "wrong-type", at2,
                                       "an edge is an array of 2 vertex indices");
                for (size_t j = 0; j < 2; j++) {
                    char at3[192];
                    api_ptr_index(at3, sizeof at3, at2, j);
                    if (api_get_int(json_array_get(ed, j), at3, 0, (long long)nv - 1, &id, p))
                        return p->status;
                    x.edge[j] = (uint32_t)id;
                }
                if (x.edge[0] == x.edge[1])
                    return api_fail_at(p, 422, "invalid-tag", at2, "vertex %u appears twice",
                                       x.edge[0]);
                if (trs) {
                    if (!json_is_array(trs) || json_array_size(trs) != 2)
                        return api_fail_at(p, json_is_array(trs) ? 422 : 400,
                                           json_is_array(trs) ? "invalid-tag" : "wrong-type", at,
                                           "the two triangles of the edge whose petals share "
                                           "a tangent plane (003 Fig. 6(c))");
                    for (size_t h = 0; h < 2; h++) {
                        api_ptr_index(at2, sizeof at2, at, h);
                        if (get_triangle(json_array_get(trs, h), at2, nv, x.pair[h], p))
                            return p->status;
                    }
                    x.npair = 2;
                }
                if (tt_push(tags, &cap, x, p))
                    return p->status;
                continue;
            }
            /* normals: one core entry per petal, the group being the entry */
            if (!json_is_array(trs) || json_array_size(trs) == 0 || json_array_size(trs) > most)
                return api_fail_at(p, json_is_array(trs) ? 422 : 400,
                                   json_is_array(trs) ? "invalid-tag" : "wrong-type", at,
                                   "an array of triangles, one in each closed petal");
            if ((size_t)tags->ntt + json_array_size(trs) > most)
                return api_fail_at(p, 422, "too-many-entries", at,
                                   "%zu petals in all for a complex of %u vertices and %u "
                                   "simplices: at most %zu (one per petal or edge)",
                                   (size_t)tags->ntt + json_array_size(trs), nv,
                                   in ? in->ns : 0, most);
            size_t h;
            json_t *tr;
            x.group = (uint32_t)i;
            json_array_foreach(trs, h, tr) {
                api_ptr_index(at2, sizeof at2, at, h);
                if (get_triangle(tr, at2, nv, x.triangle, p) || tt_push(tags, &cap, x, p))
                    return p->status;
            }
            tags->nnormals++;
        }
    }
    return 0;
}

void api_tangent_ptr(const api_tags *t, long item, int field, char *ptr, size_t n)
{
    if (item < 0 || (size_t)item >= t->ntt) {
        snprintf(ptr, n, "/normals");
        return;
    }
    const sd_tangent_tag *x = &t->tt[item];
    uint32_t nn = 0, nt = 0;
    for (uint32_t i = 0; i < t->ntt; i++) { /* core entries of the normals, of the tangents */
        nn += t->tt[i].kind == SD_TT_NORMAL;
        nt += t->tt[i].kind == SD_TT_TANGENT;
    }
    char at[64];
    if (x->kind == SD_TT_NORMAL) {
        long sub = 0;
        while (item - sub > 0 && t->tt[item - sub - 1].kind == SD_TT_NORMAL &&
               t->tt[item - sub - 1].group == x->group)
            sub++;
        api_ptr_index(at, sizeof at, "/normals", x->group);
        if (field == SD_TT_FIELD_TRIANGLE)
            snprintf(ptr, n, "%s/triangles/%ld", at, sub);
        else
            snprintf(ptr, n, "%s/%s", at,
                     field == SD_TT_FIELD_VERTEX ? "vertex"
                     : isnan(x->vec[0])          ? "triangles"
                                                 : "normal");
    } else if (x->kind == SD_TT_TANGENT) {
        api_ptr_index(at, sizeof at, "/tangents", (size_t)(item - nn));
        snprintf(ptr, n, "%s/%s", at,
                 field == SD_TT_FIELD_VERTEX     ? "vertex"
                 : field == SD_TT_FIELD_TRIANGLE ? "triangle"
                                                 : "tangent");
    } else {
        api_ptr_index(at, sizeof at, "/tangent_edges", (size_t)(item - nn - nt));
        snprintf(ptr, n, "%s/%s", at,
                 field == SD_TT_FIELD_PAIR0   ? "triangles/0"
                 : field == SD_TT_FIELD_PAIR1 ? "triangles/1"
                                              : "edge");
    }
}

static json_t *tri_json(const uint32_t v[3])
{
    return json_pack("[I, I, I]", (json_int_t)v[0], (json_int_t)v[1], (json_int_t)v[2]);
}

void api_tangents_json(const api_tags *t, json_t *obj)
{
    if (!t->ntt)
        return;
    json_t *nm = json_array(), *tg = json_array(), *te = json_array();
    for (uint32_t i = 0, j; i < t->ntt; i = j) {
        const sd_tangent_tag *x = &t->tt[i];
        j = i + 1;
        if (x->kind == SD_TT_NORMAL) {
            json_t *trs = json_array();
            json_array_append_new(trs, tri_json(x->triangle));
            for (; j < t->ntt && t->tt[j].kind == SD_TT_NORMAL && t->tt[j].group == x->group; j++)
                json_array_append_new(trs, tri_json(t->tt[j].triangle));
            json_t *o = json_pack("{s:I, s:o}", "vertex", (json_int_t)x->vertex, "triangles", trs);
            if (!isnan(x->vec[0]))
                json_object_set_new(o, "normal",
                                    json_pack("[f, f, f]", x->vec[0], x->vec[1], x->vec[2]));
            json_array_append_new(nm, o);
        } else if (x->kind == SD_TT_TANGENT) {
            json_array_append_new(tg, json_pack("{s:I, s:o, s:[f, f, f]}", "vertex",
                                                (json_int_t)x->vertex, "triangle",
                                                tri_json(x->triangle), "tangent", x->vec[0],
                                                x->vec[1], x->vec[2]));
        } else {
            json_t *o = json_pack("{s:[I, I]}", "edge", (json_int_t)x->edge[0],
                                  (json_int_t)x->edge[1]);
            if (x->npair == 2)
                json_object_set_new(o, "triangles",
                                    json_pack("[o, o]", tri_json(x->pair[0]), tri_json(x->pair[1])));
            json_array_append_new(te, o);
        }
    }
    json_t *l3[3] = {nm, tg, te};
    static const char *const names[] = {"normals", "tangents", "tangent_edges"};
    for (int L = 0; L < 3; L++) {
        if (json_array_size(l3[L]))
            json_object_set(obj, names[L], l3[L]);
        json_decref(l3[L]);
    }
}

/* Sharpness entries by simplex (sorted ends), then by position. */
typedef struct sharp_key {
    uint32_t v[3], i; /* sorted ids, UINT32_MAX past the simplex's size; the entry */
} sharp_key;
static int cmp_sharp_key(const void *x, const void *y)
{
    const sharp_key *p = x, *q = y;
    for (int k = 0; k < 3; k++)
        if (p->v[k] != q->v[k])
            return p->v[k] < q->v[k] ? -1 : 1;
    return (p->i > q->i) - (p->i < q->i);
}

/* 422 for the first entry naming the same vertex or edge as an earlier one. */
static int sharpness_repeat(const api_tags *t, api_problem *p)
{
    sharp_key *k = api_plain_malloc((t->nsh + 1) * sizeof *k);
    if (!k)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    for (uint32_t i = 0; i < t->nsh; i++) {
        const api_sharp *x = &t->sh[i];
        sharp_key q = {{UINT32_MAX, UINT32_MAX, UINT32_MAX}, i};
        for (int j = 0; j < x->nverts; j++) { /* insertion sort of at most 3 */
            int at = j;
            while (at > 0 && q.v[at - 1] > x->v[j]) {
                q.v[at] = q.v[at - 1];
                at--;
            }
            q.v[at] = x->v[j];
        }
        k[i] = q;
    }
    qsort(k, t->nsh, sizeof *k, cmp_sharp_key);
    uint32_t bad = UINT32_MAX;
    for (uint32_t i = 1; i < t->nsh; i++)
        if (!memcmp(k[i].v, k[i - 1].v, sizeof k[i].v) && k[i].i < bad)
            bad = k[i].i;
    api_plain_free(k);
    if (bad == UINT32_MAX)
        return 0;
    char at[112];
    api_ptr_index(at, sizeof at, "/sharpness", bad);
    strncat(at, "/simplex", sizeof at - strlen(at) - 1);
    static const char *const what[] = {"vertex", "edge", "triangle"};
    return api_fail_at(p, 422, "invalid-tag", at, "names the same %s as an earlier entry",
                       what[(t->sh[bad].nverts - 1) % 3]);
}

/* "sharpness": [{"simplex": [v] | [a, b], "value": s}] (docs/API.md "Creases"): shapes, ranges
 * and repeats here; whether the simplex is a vertex or a surface edge of the complex in the
 * core. At most one entry per vertex or edge of the complex. */
static int parse_sharpness(json_t *a, const api_input *in, api_tags *tags, api_problem *p)
{
    static const char *const keys[] = {"simplex", "value", NULL};
    if (!json_is_array(a))
        return api_fail_at(p, 400, "wrong-type", "/sharpness",
                           "must be an array of {\"simplex\", \"value\"}");
    size_t n = json_array_size(a), i;
    if (!in)
        return n ? api_fail_at(p, 409, "no-complex", "/sharpness",
                               "sharpness names simplices of the complex; PUT the complex first")
                 : 0;
    if (n > (size_t)in->nv + 10 * (size_t)in->ns) /* > vertices + edges + faces: before allocating */
        return api_fail_at(p, 422, "too-many-entries", "/sharpness",
                           "%zu sharpness values for a complex of %u vertices and %u simplices: "
                           "at most one per vertex, edge or triangle", n, in->nv, in->ns);
    tags->sh = api_plain_malloc((n + 1) * sizeof *tags->sh);
    if (!tags->sh)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    json_t *o;
    char ptr[96], at[112], at2[128];
    json_array_foreach(a, i, o) {
        api_ptr_index(ptr, sizeof ptr, "/sharpness", i);
        if (!json_is_object(o))
            return api_fail_at(p, 400, "wrong-type", ptr,
                               "a sharpness is an object {\"simplex\", \"value\"}");
        if (api_only_keys(o, ptr, keys, p))
            return p->status;
        json_t *sx = json_object_get(o, "simplex"), *v = json_object_get(o, "value");
        api_ptr_key(at, sizeof at, ptr, "simplex");
        if (!sx)
            return api_fail_at(p, 400, "missing-field", at, "\"simplex\" is required");
        if (!json_is_array(sx))
            return api_fail_at(p, 400, "wrong-type", at, "a simplex is an array of vertex indices");
        size_t k = json_array_size(sx);
        if (k < 1 || k > 3)
            return api_fail_at(p, 422, "invalid-tag", at,
                               "a sharpness is on a vertex, an edge or a triangle (1 to 3 "
                               "indices), not %zu", k);
        api_sharp *x = &tags->sh[i];
        memset(x->v, 0, sizeof x->v);
        x->nverts = (int)k;
        for (size_t j = 0; j < k; j++) {
            long long id;
            api_ptr_index(at2, sizeof at2, at, j);
            if (api_get_int(json_array_get(sx, j), at2, 0, (long long)in->nv - 1, &id, p))
                return p->status;
            x->v[j] = (uint32_t)id;
            for (size_t q = 0; q < j; q++)
                if (x->v[q] == x->v[j])
                    return api_fail_at(p, 422, "invalid-tag", at2, "vertex %u appears twice",
                                       x->v[j]);
        }
        api_ptr_key(at, sizeof at, ptr, "value");
        if (!v)
            return api_fail_at(p, 400, "missing-field", at, "\"value\" is required");
        if (!json_is_number(v))
            return api_fail_at(p, 400, "wrong-type", at, "a sharpness is a number");
        x->value = json_number_value(v);
        if (!(x->value >= 0) || !isfinite(x->value))
            return api_fail_at(p, 422, "invalid-tag", at,
                               "a sharpness is 0 or more (10 and more: infinitely sharp)");
        tags->nsh++;
    }
    return sharpness_repeat(tags, p);
}

/* A singular simplex listed twice (in any vertex order): 422 at the later entry, as the other
 * lists refuse their repeats. Keys: the sorted ids (UINT32_MAX padded) and the entry. */
static int cmp_tag_key(const void *x, const void *y)
{
    const uint32_t *a = x, *b = y;
    for (int i = 0; i < 4; i++) /* numerically: equal simplices then come by entry */
        if (a[i] != b[i])
            return a[i] < b[i] ? -1 : 1;
    return 0;
}

static int singular_repeats(api_tags *tags, bool drop, api_problem *p)
{
    uint32_t (*key)[4] = api_plain_malloc((size_t)tags->n * sizeof *key);
    uint8_t *gone = drop ? api_plain_malloc(tags->n) : NULL;
    if (drop)
        tags->from = api_plain_malloc((size_t)tags->n * sizeof *tags->from);
    if (!key || (drop && (!gone || !tags->from))) {
        api_plain_free(key);
        api_plain_free(gone);
        return api_fail(p, 503, "out-of-memory", "out of memory");
    }
    size_t off = 0;
    for (size_t i = 0; i < tags->n; i++) {
        uint32_t k[3] = {UINT32_MAX, UINT32_MAX, UINT32_MAX};
        for (int j = 0; j < tags->size[i]; j++) { /* insertion into ascending order */
            uint32_t x = tags->idx[off + j];
            int q = j;
            for (; q > 0 && k[q - 1] > x; q--)
                k[q] = k[q - 1];
            k[q] = x;
        }
        off += tags->size[i];
        memcpy(key[i], k, sizeof k);
        key[i][3] = (uint32_t)i;
    }
    qsort(key, tags->n, sizeof *key, cmp_tag_key);
    int rc = 0;
    if (drop)
        memset(gone, 0, tags->n);
    uint32_t repeat = UINT32_MAX, first = 0; /* the earliest repeat in the body, and its first */
    for (size_t i = 1, run = 0; i < tags->n; i++) {
        if (memcmp(key[i - 1], key[i], 3 * sizeof(uint32_t))) {
            run = i;
            continue;
        }
        if (drop) /* equal keys are by entry: the first stays */
            gone[key[i][3]] = 1;
        else if (key[i][3] < repeat) {
            repeat = key[i][3];
            first = key[run][3];
        }
    }
    if (repeat != UINT32_MAX) {
        char ptr[96];
        api_ptr_index(ptr, sizeof ptr, "/singular", repeat);
        rc = api_fail_at(p, 422, "invalid-tag", ptr,
                         "the same simplex as /singular/%u: each simplex is tagged once", first);
    }
    if (drop) { /* the entries kept, in their order, each with the entry it was */
        uint32_t n = 0;
        size_t from = 0, to = 0;
        for (uint32_t i = 0; i < tags->n; i++) {
            uint8_t k = tags->size[i];
            if (!gone[i]) {
                memmove(tags->idx + to, tags->idx + from, k * sizeof *tags->idx);
                tags->from[n] = i;
                tags->size[n++] = k;
                to += k;
            }
            from += k;
        }
        tags->n = tags->nfrom = n;
    }
    api_plain_free(key);
    api_plain_free(gone);
    return rc;
}

const char *const api_tags_packed[] = {"/singular", NULL};

static int put_tags(const api_model *cur, json_t *body, const api_packs *packs,
                    const api_limits *lim, bool drop_repeats, api_model **out, api_problem *p);

int api_put_tags(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                 api_problem *p)
{
    return put_tags(cur, body, NULL, lim, false, out, p);
}

int api_put_tags_packed(const api_model *cur, json_t *body, const api_packs *packs,
                        const api_limits *lim, api_model **out, api_problem *p)
{
    return put_tags(cur, body, packs, lim, false, out, p);
}

int api_import_tags(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                    api_problem *p)
{
    return put_tags(cur, body, NULL, lim, true, out, p);
}

/* PUT /tags; an import (drop_repeats) takes a singular simplex listed twice once. */
static int put_tags(const api_model *cur, json_t *body, const api_packs *packs,
                    const api_limits *lim, bool drop_repeats, api_model **out, api_problem *p)
{
    static const char *const keys[] = {"singular", "petals", "sharpness", "crease_angle",
                                       "normals", "tangents", "tangent_edges", NULL};
    *out = NULL;
    if (api_only_keys(body, "", keys, p))
        return p->status;
    json_t *s = json_object_get(body, "singular"), *pe = json_object_get(body, "petals");
    json_t *sh = json_object_get(body, "sharpness"), *ca = json_object_get(body, "crease_angle");
    json_t *nm = json_object_get(body, "normals"), *tg = json_object_get(body, "tangents");
    json_t *te = json_object_get(body, "tangent_edges");
    if (!s && !pe && !sh && !ca && !nm && !tg && !te)
        return api_fail_at(p, 400, "missing-field", "/singular",
                           "\"singular\" is required (or \"petals\", \"sharpness\", "
                           "\"crease_angle\", \"normals\", \"tangents\" or "
                           "\"tangent_edges\" alone: no listed singular simplices)");
    api_rows rows = {0}; /* absent: no singular simplices */
    if (s && !api_rows_open(&rows, s, packs, "/singular"))
        return api_fail_at(p, 400, "wrong-type", "/singular",
                           "must be an array of simplices (1 to 3 vertex indices)");
    size_t n = api_rows_count(&rows);
    if ((n || (pe && (!json_is_array(pe) || json_array_size(pe)))) && !cur->in)
        return api_fail_at(p, 409, "no-complex", n ? "/singular" : "/petals",
                           "tags name simplices of the complex; PUT the complex first");
    json_t *l3[3] = {nm, tg, te};
    static const char *const l3n[] = {"/normals", "/tangents", "/tangent_edges"};
    for (int L = 0; L < 3; L++)
        if (l3[L] && (!json_is_array(l3[L]) || json_array_size(l3[L])) && !cur->in)
            return api_fail_at(p, 409, "no-complex", l3n[L],
                               "tags name simplices of the complex; PUT the complex first");
    api_tags tags = {0};
    tags.size = api_plain_malloc(n + 1);
    tags.idx = api_plain_malloc((3 * n + 1) * sizeof *tags.idx);
    int rc = !tags.size || !tags.idx ? api_fail(p, 503, "out-of-memory", "out of memory") : 0;
    size_t off = 0;
    api_row t;
    char ptr[96], at[96];
    for (size_t i = 0; !rc && api_rows_next(&rows, &t); i++) {
        api_ptr_index(ptr, sizeof ptr, "/singular", i);
        if (!api_row_is_array(&t)) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "a tag is an array of 1 to 3 vertex indices");
            break;
        }
        size_t k = api_row_size(&t);
        if (k < 1 || k > 3) {
            rc = api_fail_at(p, 422, "invalid-tag", ptr,
                             "a singular simplex is a vertex, an edge or a triangle (1 to 3 "
                             "indices), not %zu", k);
            break;
        }
        long long seen[3];
        for (size_t j = 0; j < k && !rc; j++) {
            api_ptr_index(at, sizeof at, ptr, j);
            if ((rc = api_num_get_int(api_row_get(&t, j), at, 0, (long long)cur->in->nv - 1,
                                      &seen[j], p)))
                break;
            for (size_t q = 0; q < j && !rc; q++)
                if (seen[q] == seen[j])
                    rc = api_fail_at(p, 422, "invalid-tag", at, "vertex %lld appears twice", seen[j]);
            tags.idx[off + j] = (uint32_t)seen[j];
        }
        tags.size[i] = (uint8_t)k;
        off += k;
        tags.n++;
    }
    if (!rc && tags.n > 1)
        rc = singular_repeats(&tags, drop_repeats, p);
    if (!rc && pe)
        rc = parse_petals(pe, cur->in ? cur->in->nv : 0, &tags, p);
    if (!rc && sh)
        rc = parse_sharpness(sh, cur->in, &tags, p);
    if (!rc && (nm || tg || te))
        rc = parse_tangents(nm, tg, te, cur->in, &tags, p);
    if (!rc && ca) /* the edges over the angle join the listed ones (api/crease.c) */
        rc = api_crease_tags(cur, ca, &tags, p);
    if (!rc) /* the core checks each tag is a vertex, edge or triangle of the complex */
        rc = build_from_copy(cur, &cur->rules, &tags, lim, out, p);
    api_tags_free(&tags);
    return keep_details(cur, rc, out, p);
}
