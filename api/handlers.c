/* handlers.c — complex, tags, rules, levels and stats (API.md) as transport-free functions.
 *
 * Every handler validates its whole request before it builds anything, and builds the new state
 * beside the old one: the caller publishes the result or drops it, so a refused request leaves
 * the session untouched. Sizes are checked against api_limits before the arrays are allocated.
 */
#include "handlers.h"
#include "fill.h"
#include "jsonin.h"
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- PUT /complex ------------------------------------------------------------------------- */

static int parse_vertices(json_t *v, const api_limits *lim, api_input *in, api_problem *p)
{
    if (!json_is_array(v))
        return api_fail_at(p, 400, "wrong-type", "/vertices", "must be an array of [x, y, z]");
    size_t n = json_array_size(v);
    if (n > lim->max_vertices)
        return api_fail_limit(p, "max_vertices", lim->max_vertices, n,
                              "%zu vertices exceed the limit of %u; split the model or raise "
                              "--max-vertices", n, lim->max_vertices);
    in->xyz = malloc((n ? n : 1) * 3 * sizeof *in->xyz);
    if (!in->xyz)
        return api_fail(p, 503, "out-of-memory", "out of memory reading %zu vertices", n);
    in->nv = (uint32_t)n;
    char ptr[96];
    for (size_t i = 0; i < n; i++) {
        json_t *x = json_array_get(v, i);
        api_ptr_index(ptr, sizeof ptr, "/vertices", i);
        if (!json_is_array(x) || json_array_size(x) != 3)
            return api_fail_at(p, 400, "wrong-type", ptr, "a vertex is an array of 3 numbers");
        for (int k = 0; k < 3; k++) {
            json_t *c = json_array_get(x, k);
            if (!json_is_number(c)) {
                char at[96];
                api_ptr_index(at, sizeof at, ptr, k);
                return api_fail_at(p, 400, "wrong-type", at, "a coordinate must be a number");
            }
            in->xyz[3 * i + k] = json_number_value(c);
        }
    }
    return 0;
}

static int parse_simplices(json_t *v, const api_limits *lim, api_input *in, api_problem *p)
{
    if (!json_is_array(v))
        return api_fail_at(p, 400, "wrong-type", "/simplices",
                           "must be an array of simplices (arrays of 1 to 4 vertex indices)");
    size_t n = json_array_size(v);
    if (n > lim->max_simplices)
        return api_fail_limit(p, "max_simplices", lim->max_simplices, n,
                              "%zu simplices exceed the limit of %u; split the model or raise "
                              "--max-simplices", n, lim->max_simplices);
    char ptr[96];
    size_t total = 0;
    for (size_t i = 0; i < n; i++) {   /* shapes first, so the index array is sized exactly */
        json_t *s = json_array_get(v, i);
        api_ptr_index(ptr, sizeof ptr, "/simplices", i);
        if (!json_is_array(s))
            return api_fail_at(p, 400, "wrong-type", ptr,
                               "a simplex is an array of 1 to 4 vertex indices");
        size_t k = json_array_size(s);
        if (k < 1 || k > 4)
            return api_fail_at(p, 422, "invalid-complex", ptr,
                               "simplex %zu has %zu vertices; a simplex has 1 to 4 (point, edge, "
                               "triangle, tetrahedron)", i, k);
        total += k;
    }
    in->size = malloc(n ? n : 1);
    in->idx = malloc((total ? total : 1) * sizeof *in->idx);
    if (!in->size || !in->idx)
        return api_fail(p, 503, "out-of-memory", "out of memory reading %zu simplices", n);
    in->ns = (uint32_t)n;
    size_t off = 0;
    for (size_t i = 0; i < n; i++) {
        json_t *s = json_array_get(v, i);
        size_t k = json_array_size(s);
        in->size[i] = (uint8_t)k;
        for (size_t j = 0; j < k; j++) {
            long long x;
            char at[96];
            api_ptr_index(ptr, sizeof ptr, "/simplices", i);
            api_ptr_index(at, sizeof at, ptr, j);
            json_t *e = json_array_get(s, j);
            if (!json_is_integer(e))
                return api_fail_at(p, 400, "wrong-type", at, "a vertex index must be an integer");
            x = json_integer_value(e);
            if (x < 0 || x >= (long long)in->nv)
                return api_fail_at(p, 422, "invalid-complex", at,
                                   "index %lld out of range (%u vertices)", x, in->nv);
            in->idx[off++] = (uint32_t)x;
        }
    }
    return 0;
}

static int valid_name(const char *s)
{
    size_t n = strlen(s);
    if (n < 1 || n > API_MAX_ATTRIBUTE_NAME)
        return 0;
    for (const char *c = s; *c; c++)
        if (!isalnum((unsigned char)*c) && *c != '_' && *c != '-')
            return 0;
    return 1;
}

static int parse_attributes(json_t *v, api_input *in, api_problem *p)
{
    if (!json_is_object(v))
        return api_fail_at(p, 400, "wrong-type", "/attributes",
                           "must be an object: name -> one value per vertex");
    if (json_object_size(v) > API_MAX_ATTRIBUTES)
        return api_fail_at(p, 422, "too-many-attributes", "/attributes",
                           "%zu attributes; at most %d", json_object_size(v), API_MAX_ATTRIBUTES);
    const char *name;
    json_t *a;
    char ptr[96], at[96];
    json_object_foreach(v, name, a) {
        api_ptr_key(ptr, sizeof ptr, "/attributes", name);
        if (!valid_name(name))
            return api_fail_at(p, 422, "invalid-name", ptr,
                               "attribute names have 1 to %d letters, digits, '_' or '-'",
                               API_MAX_ATTRIBUTE_NAME);
        if (!json_is_array(a))
            return api_fail_at(p, 400, "wrong-type", ptr, "must be an array with one value per vertex");
        if (json_array_size(a) != in->nv)
            return api_fail_at(p, 422, "wrong-length", ptr, "has %zu values for %u vertices",
                               json_array_size(a), in->nv);
        api_attribute *t = &in->attrs[in->nattrs];
        snprintf(t->name, sizeof t->name, "%s", name);
        json_t *first = json_array_get(a, 0);
        t->scalar_form = !json_is_array(first);
        t->ncomp = t->scalar_form ? 1 : (int)json_array_size(first);
        if (t->ncomp < 1 || t->ncomp > 16) {
            api_ptr_index(at, sizeof at, ptr, 0);
            return api_fail_at(p, 422, "wrong-length", at,
                               "a vector value has 1 to 16 components, not %d", t->ncomp);
        }
        t->data = malloc((in->nv ? in->nv : 1) * (size_t)t->ncomp * sizeof *t->data);
        if (!t->data)
            return api_fail(p, 503, "out-of-memory", "out of memory reading attribute %s", name);
        in->nattrs++;
        for (uint32_t i = 0; i < in->nv; i++) {
            json_t *x = json_array_get(a, i);
            api_ptr_index(at, sizeof at, ptr, i);
            if (t->scalar_form) {
                if (!json_is_number(x))
                    return api_fail_at(p, 400, "wrong-type", at,
                                       "must be a number like the attribute's first value");
                t->data[i] = json_number_value(x);
                continue;
            }
            if (!json_is_array(x) || json_array_size(x) != (size_t)t->ncomp)
                return api_fail_at(p, 400, "wrong-type", at,
                                   "must be an array of %d numbers like the attribute's first value",
                                   t->ncomp);
            for (int k = 0; k < t->ncomp; k++) {
                json_t *c = json_array_get(x, k);
                if (!json_is_number(c)) {
                    char ck[96];
                    api_ptr_index(ck, sizeof ck, at, k);
                    return api_fail_at(p, 400, "wrong-type", ck, "must be a number");
                }
                t->data[(size_t)i * t->ncomp + k] = json_number_value(c);
            }
        }
    }
    return 0;
}

/* "diagonals": [[simplex, pair]...] — the major diagonal of chosen tetrahedra (001 Sec. 3:
 * pair 0 = edges 01|23, 1 = 02|13, 2 = 03|12 of the simplex as posted). */
static int parse_diagonals(json_t *v, api_input *in, api_problem *p)
{
    if (!json_is_array(v))
        return api_fail_at(p, 400, "wrong-type", "/diagonals", "must be an array of [simplex, pair]");
    size_t n = json_array_size(v);
    if (n > in->ns)
        return api_fail_at(p, 422, "repeated-index", "/diagonals",
                           "%zu choices for %u simplices: some tetrahedron is listed twice", n, in->ns);
    in->diag = malloc((n ? n : 1) * sizeof *in->diag);
    uint8_t *seen = calloc((size_t)in->ns + 1, 1);
    int rc = 0;
    if (!in->diag || !seen)
        rc = api_fail(p, 503, "out-of-memory", "out of memory");
    char ptr[96], at[96];
    for (size_t i = 0; i < n && !rc; i++) {
        json_t *d = json_array_get(v, i);
        long long s, k;
        api_ptr_index(ptr, sizeof ptr, "/diagonals", i);
        if (!json_is_array(d) || json_array_size(d) != 2) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "a choice is [simplex index, pair 0..2]");
            break;
        }
        api_ptr_index(at, sizeof at, ptr, 0);
        if ((rc = api_get_int(json_array_get(d, 0), at, 0, (long long)in->ns - 1, &s, p)))
            break;
        if (in->size[s] != 4) {
            rc = api_fail_at(p, 422, "not-a-tetrahedron", at, "simplex %lld is not a tetrahedron", s);
            break;
        }
        if (seen[s]++) {
            rc = api_fail_at(p, 422, "repeated-index", at, "simplex %lld is listed twice", s);
            break;
        }
        api_ptr_index(at, sizeof at, ptr, 1);
        if ((rc = api_get_int(json_array_get(d, 1), at, 0, 2, &k, p)))
            break;
        in->diag[i][0] = (uint32_t)s;
        in->diag[i][1] = (uint32_t)k;
        in->ndiag++;
    }
    free(seen);
    return rc;
}

/* Build the model of `in` + rules, mapping core refusals to problems with pointers. */
static int build_model(api_input *in, const api_rules *rules, const api_tags *tags,
                       const api_limits *lim, api_model **out, api_problem *p)
{
    sd_error e = {0};
    api_model *m = api_model_new(in, rules, lim->max_session_bytes, &e);
    /* overrides name simplices: kept by a change of tags or rules, not by a new complex (the
     * callers with a new complex pass rules without them) */
    if (m && rules && rules->noverrides &&
        api_model_set_overrides(m, rules->overrides, rules->noverrides, &e)) {
        api_model_unref(m);
        if (e.code == SD_ERR_NOMEM)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        static const char *const fields[] = {"/simplex", "/rule", "/dimension", "/pair",
                                             "/pair/0", "/pair/1"};
        char ptr[128];
        api_ptr_index(ptr, sizeof ptr, "/overrides", (size_t)(e.item < 0 ? 0 : e.item));
        if (e.field >= 0 && e.field < 6)
            strncat(ptr, fields[e.field], sizeof ptr - strlen(ptr) - 1);
        return api_fail_at(p, 422, "invalid-override", ptr, "%s", e.message);
    }
    bool petal = false;
    if (m && tags && (tags->n || tags->npet) && api_model_set_tags(m, tags, &e, &petal)) {
        api_model_unref(m);
        if (e.code == SD_ERR_NOMEM)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        char ptr[96];
        api_ptr_index(ptr, sizeof ptr, petal ? "/petals" : "/singular",
                      (size_t)(e.item < 0 ? 0 : e.item));
        static const char *const fields[] = {"/vertex", "/triangle", "/kind"};
        if (petal && e.field >= 0 && e.field < 3)
            strncat(ptr, fields[e.field], sizeof ptr - strlen(ptr) - 1);
        return api_fail_at(p, 422, "invalid-tag", ptr, "%s", e.message);
    }
    if (!m) {
        if (e.code == SD_ERR_VALUE && e.item >= 0 && in && in->nattrs && strstr(e.message, "channel")) {
            char ptr[96];
            api_ptr_key(ptr, sizeof ptr, "/attributes", in->attrs[e.item].name);
            return api_fail_at(p, 422, "invalid-complex", ptr, "%s", e.message);
        }
        return api_fail_core(p, &e, "/simplices", "/vertices");
    }
    sd_error e0 = {0};
    sd_class k;
    if (m->c && sd_complex_vertex_class(m->c, 0, 0, &k, &e0) == SD_OK) /* builds level-0 rules */
        m->level0 = sd_complex_level(m->c, 0, &e0);
    else if (m->c) {
        api_model_unref(m);
        return api_fail_core(p, &e0, NULL, NULL);
    }
    m->summary = api_summary(m);
    *out = m;
    return 0;
}

int api_put_complex(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                    api_problem *p)
{
    static const char *const keys[] = {"vertices", "simplices", "attributes", "diagonals",
                                       "fill", NULL};
    *out = NULL;
    if (api_only_keys(body, "", keys, p))
        return p->status;
    json_t *vs = json_object_get(body, "vertices"), *ss = json_object_get(body, "simplices");
    if (!vs)
        return api_fail_at(p, 400, "missing-field", "/vertices", "\"vertices\" is required");
    if (!ss && !json_object_get(body, "fill"))
        return api_fail_at(p, 400, "missing-field", "/simplices", "\"simplices\" is required");
    api_input *in = api_input_new();
    if (!in)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    int rc = parse_vertices(vs, lim, in, p);
    if (!rc && ss)
        rc = parse_simplices(ss, lim, in, p);
    json_t *attrs = json_object_get(body, "attributes");
    if (!rc && attrs)
        rc = parse_attributes(attrs, in, p);
    json_t *dg = json_object_get(body, "diagonals");
    if (!rc && dg)
        rc = parse_diagonals(dg, in, p);
    uint32_t nv_posted = in->nv, ns_posted = in->ns;
    json_t *fill = json_object_get(body, "fill");
    if (!rc && fill) /* TetGen: the tets and Steiner points are appended to `in` (api/fill.c) */
        rc = api_fill(fill, in, lim, p);
    if (!rc && !in->nv)   /* the core's "no vertices" would point at /simplices */
        rc = api_fail_at(p, 422, "invalid-complex", "/vertices", "the complex has no vertices");
    api_rules keep = cur->rules; /* the preferences stay; overrides named the old simplices */
    keep.noverrides = 0;
    keep.overrides = NULL;
    if (!rc && (rc = build_model(in, &keep, NULL, lim, out, p)) && in->nfill)
        api_fill_blame(in, nv_posted, ns_posted, p);
    api_input_unref(in);
    return rc;
}

/* ---- PUT /rules, PUT /tags ------------------------------------------------------------------ */

int api_put_rules(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                  api_problem *p)
{
    static const char *const keys[] = {"nonmanifold_default", "overrides", "solid_scheme",
                                       "surface_weights", "nonmanifold_surface", NULL};
    static const char *const nm_rules[] = {"G2", "G1", "N1", "N2", NULL};
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
        (nm = api_get_enum(v, "/nonmanifold_default", nm_rules, p)) < 0)
        return p->status;
    if ((v = json_object_get(body, "nonmanifold_surface")) &&
        (surf = api_get_enum(v, "/nonmanifold_surface", surfaces, p)) < 0)
        return p->status;
    if (nm >= 2)
        return api_fail_at(p, 422, "invalid-rule", "/nonmanifold_default",
                           "%s needs a per-simplex choice of dimension or pair; use G1 or G2 as "
                           "the default and give N1/N2 in \"overrides\"", nm_rules[nm]);
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
        return api_fail_at(p, 422, "limit-exceeded", "/overrides",
                           "%zu overrides for a complex of %u vertices and %u simplices: at most "
                           "one per vertex or edge", nov, cur->in->nv, cur->in->ns);
    sd_override *list = calloc(nov + 1, sizeof *list);
    if (!list)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    int rc = 0;
    size_t i;
    json_t *o;
    char ptr[96], at[128], at2[160];
    json_array_foreach(ov, i, o) {
        static const char *const okeys[] = {"simplex", "rule", "dimension", "pair", NULL};
        sd_override *x = &list[i];
        api_ptr_index(ptr, sizeof ptr, "/overrides", i);
        if (!json_is_object(o)) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "an override is an object");
            break;
        }
        if ((rc = api_only_keys(o, ptr, okeys, p)))
            break;
        json_t *sx = json_object_get(o, "simplex"), *ru = json_object_get(o, "rule");
        json_t *dim = json_object_get(o, "dimension"), *pr = json_object_get(o, "pair");
        snprintf(at, sizeof at, "%s/simplex", ptr);
        if (!sx) {
            rc = api_fail_at(p, 400, "missing-field", at, "\"simplex\" is required");
            break;
        }
        if (!json_is_array(sx)) {
            rc = api_fail_at(p, 400, "wrong-type", at, "a simplex is an array of vertex indices");
            break;
        }
        size_t k = json_array_size(sx);
        if (k < 1 || k > 2) {
            rc = api_fail_at(p, 422, "invalid-override", at,
                             "rules are chosen per vertex or edge (1 or 2 indices), not for %zu "
                             "vertices: a %s has no point of its own", k,
                             k == 3 ? "triangle" : k == 4 ? "tetrahedron" : "simplex");
            break;
        }
        for (size_t j = 0; j < k && !rc; j++) {
            long long id;
            api_ptr_index(at2, sizeof at2, at, j);
            if (!(rc = api_get_int(json_array_get(sx, j), at2, 0, (long long)cur->in->nv - 1, &id, p)))
                x->simplex[j] = (uint32_t)id;
        }
        if (rc)
            break;
        x->nverts = (int)k;
        snprintf(at, sizeof at, "%s/rule", ptr);
        if (!ru) {
            rc = api_fail_at(p, 400, "missing-field", at, "\"rule\" is required");
            break;
        }
        int which = api_get_enum(ru, at, nm_rules, p);
        if (which < 0) {
            rc = p->status;
            break;
        }
        static const sd_rule map[] = {SD_RULE_G2, SD_RULE_G1, SD_RULE_N1, SD_RULE_N2};
        x->rule = map[which];
        snprintf(at, sizeof at, "%s/dimension", ptr);
        if (x->rule == SD_RULE_N1 && !dim) {
            rc = api_fail_at(p, 400, "missing-field", at, "N1 needs the \"dimension\" to follow");
            break;
        }
        if (x->rule != SD_RULE_N1 && dim) {
            rc = api_fail_at(p, 422, "invalid-override", at, "only N1 takes a dimension");
            break;
        }
        if (dim) {
            long long d;
            if ((rc = api_get_int(dim, at, 1, 3, &d, p)))
                break;
            x->dimension = (int)d;
        }
        snprintf(at, sizeof at, "%s/pair", ptr);
        if (x->rule == SD_RULE_N2 && !pr) {
            rc = api_fail_at(p, 400, "missing-field", at, "N2 needs the \"pair\" of simplices to follow");
            break;
        }
        if (x->rule != SD_RULE_N2 && pr) {
            rc = api_fail_at(p, 422, "invalid-override", at, "only N2 takes a pair");
            break;
        }
        if (pr) {
            if (!json_is_array(pr) || json_array_size(pr) != 2) {
                rc = api_fail_at(p, json_is_array(pr) ? 422 : 400,
                                 json_is_array(pr) ? "invalid-override" : "wrong-type", at,
                                 "a pair is an array of two simplices");
                break;
            }
            for (size_t j = 0; j < 2 && !rc; j++) {
                json_t *q = json_array_get(pr, j);
                api_ptr_index(at2, sizeof at2, at, j);
                if (!json_is_array(q)) {
                    rc = api_fail_at(p, 400, "wrong-type", at2, "a simplex is an array of vertex indices");
                    break;
                }
                size_t kq = json_array_size(q);
                if (kq < 2 || kq > 3 || (j == 1 && (int)kq != x->pair_size)) {
                    rc = api_fail_at(p, 422, "invalid-override", at2,
                                     "the pair is two curve segments (2 indices each) or two "
                                     "triangles (3 each)");
                    break;
                }
                x->pair_size = (int)kq;
                for (size_t u = 0; u < kq && !rc; u++) {
                    long long id;
                    char at3[192];
                    api_ptr_index(at3, sizeof at3, at2, u);
                    if (!(rc = api_get_int(json_array_get(q, u), at3, 0, (long long)cur->in->nv - 1,
                                           &id, p)))
                        x->pair[j][u] = (uint32_t)id;
                }
            }
            if (rc)
                break;
        }
    }
    if (!rc) {
        r.overrides = list;
        r.noverrides = (uint32_t)nov;
        rc = build_model(cur->in, &r, &cur->tags, lim, out, p);
    }
    free(list);
    return rc;
}

/* "petals": [{"vertex", "triangle", "kind"}] (API.md extension, docs/SERVICE.md): the corner
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
    tags->pet = malloc((n + 1) * sizeof *tags->pet);
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

int api_put_tags(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                 api_problem *p)
{
    static const char *const keys[] = {"singular", "petals", NULL};
    *out = NULL;
    if (api_only_keys(body, "", keys, p))
        return p->status;
    json_t *s = json_object_get(body, "singular"), *pe = json_object_get(body, "petals");
    if (!s && !pe)
        return api_fail_at(p, 400, "missing-field", "/singular",
                           "\"singular\" is required (or \"petals\" alone: no singular simplices)");
    if (s && !json_is_array(s)) /* absent: no singular simplices (json_array_* take NULL) */
        return api_fail_at(p, 400, "wrong-type", "/singular",
                           "must be an array of simplices (1 to 3 vertex indices)");
    if ((json_array_size(s) || (pe && (!json_is_array(pe) || json_array_size(pe)))) && !cur->in)
        return api_fail_at(p, 409, "no-complex", json_array_size(s) ? "/singular" : "/petals",
                           "tags name simplices of the complex; PUT the complex first");
    size_t n = json_array_size(s);
    api_tags tags = {0};
    tags.size = malloc(n + 1);
    tags.idx = malloc((3 * n + 1) * sizeof *tags.idx);
    int rc = !tags.size || !tags.idx ? api_fail(p, 503, "out-of-memory", "out of memory") : 0;
    size_t i, off = 0;
    json_t *t;
    char ptr[96], at[96];
    json_array_foreach(s, i, t) {
        if (rc)
            break;
        api_ptr_index(ptr, sizeof ptr, "/singular", i);
        if (!json_is_array(t)) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "a tag is an array of 1 to 3 vertex indices");
            break;
        }
        size_t k = json_array_size(t);
        if (k < 1 || k > 3) {
            rc = api_fail_at(p, 422, "invalid-tag", ptr,
                             "a singular simplex is a vertex, an edge or a triangle (1 to 3 "
                             "indices), not %zu", k);
            break;
        }
        long long seen[3];
        for (size_t j = 0; j < k && !rc; j++) {
            api_ptr_index(at, sizeof at, ptr, j);
            if ((rc = api_get_int(json_array_get(t, j), at, 0, (long long)cur->in->nv - 1,
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
    if (!rc && pe)
        rc = parse_petals(pe, cur->in ? cur->in->nv : 0, &tags, p);
    if (!rc) /* the core checks each tag is a vertex, edge or triangle of the complex */
        rc = build_model(cur->in, &cur->rules, &tags, lim, out, p);
    free(tags.size);
    free(tags.idx);
    free(tags.pet);
    return rc;
}

/* ---- summary and GET /complex ------------------------------------------------------------- */

static json_t *family_json(uint8_t fam)
{
    json_t *a = json_array();
    for (int k = 0; k < 4; k++)
        if (fam & (1u << k))
            json_array_append_new(a, json_integer(k));
    return a;
}

static json_t *class_json(const sd_class *c, int singular)
{
    return json_pack("{s:o, s:b, s:i, s:b, s:s, s:i, s:b}", "family", family_json(c->family),
                     "boundary", c->boundary, "nonmanifold", c->nonmanifold, "singular", singular,
                     "rule", sd_rule_name((sd_rule)c->rule), "valence", (int)c->valence,
                     "extraordinary", c->extraordinary);
}

json_t *api_summary(const api_model *m)
{
    if (!m->c)
        return json_object();
    sd_complex *c = m->c;
    sd_counts n;
    sd_complex_counts(c, 0, &n);
    uint64_t bv = 0, be = 0, xv = 0, xe = 0, nmv[5] = {0}, nme[5] = {0};
    sd_class k;
    const sd_level *lv = m->level0;
    for (uint32_t i = 0; lv && i < n.vertices; i++)
        if (!sd_level_vertex_class(lv, i, &k)) {
            bv += k.boundary;
            xv += k.extraordinary;
            nmv[k.nonmanifold < 5 ? k.nonmanifold : 0]++;
        }
    for (uint32_t i = 0; lv && i < n.edges; i++)
        if (!sd_level_edge_class(lv, i, &k)) {
            be += k.boundary;
            xe += k.extraordinary;
            nme[k.nonmanifold < 5 ? k.nonmanifold : 0]++;
        }
    json_t *nm = json_object();
    for (int t = 1; t <= 4; t++) {
        char key[16];
        snprintf(key, sizeof key, "type%d", t);
        json_object_set_new(nm, key, json_pack("{s:I, s:I}", "vertices", (json_int_t)nmv[t],
                                               "edges", (json_int_t)nme[t]));
    }
    json_t *fill = api_fill_summary(m->in);
    return json_pack("{s:I, s:I, s:I, s:{s:I, s:I, s:I, s:I}, s:{s:I, s:I}, s:o, s:{s:I, s:I}, s:o*}",
                     "vertices", (json_int_t)n.vertices, "edges", (json_int_t)n.edges, "faces",
                     (json_int_t)n.faces, "simplices", "0", (json_int_t)n.points, "1",
                     (json_int_t)n.curves, "2", (json_int_t)n.triangles, "3",
                     (json_int_t)n.tetrahedra, "boundary", "vertices", (json_int_t)bv, "edges",
                     (json_int_t)be, "nonmanifold", nm, "extraordinary", "vertices",
                     (json_int_t)xv, "edges", (json_int_t)xe, "fill", fill);
}

static json_t *doubles_json(const double *x, size_t n)
{
    json_t *a = json_array();
    for (size_t i = 0; i < n; i++)
        json_array_append_new(a, json_real(x[i]));
    return a;
}

json_t *api_get_complex(api_model *m, api_problem *p)
{
    const api_input *in = m->in;
    if (!in) {
        api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
        return NULL;
    }
    pthread_rwlock_rdlock(&m->data);
    json_t *vs = json_array(), *ss = json_array(), *at = json_object();
    for (uint32_t i = 0; i < in->nv; i++)
        json_array_append_new(vs, doubles_json(in->xyz + 3 * (size_t)i, 3));
    size_t off = 0;
    for (uint32_t s = 0; s < in->ns; s++) {
        json_t *a = json_array();
        for (int j = 0; j < in->size[s]; j++)
            json_array_append_new(a, json_integer(in->idx[off++]));
        json_array_append_new(ss, a);
    }
    for (int a = 0; a < in->nattrs; a++) {
        const api_attribute *t = &in->attrs[a];
        json_t *arr = json_array();
        for (uint32_t i = 0; i < in->nv; i++)
            json_array_append_new(arr, t->scalar_form ? json_real(t->data[i])
                                                      : doubles_json(t->data + (size_t)i * t->ncomp,
                                                                     t->ncomp));
        json_object_set_new(at, t->name, arr);
    }
    json_t *cv = json_array(), *ce = json_array();
    const sd_level *lv = m->level0; /* immutable: no lock, so a computing session still answers */
    uint32_t ne = 0;
    const uint32_t *ev = sd_level_edges(lv, &ne);
    sd_class k;
    for (uint32_t i = 0; i < in->nv; i++)
        if (!sd_level_vertex_class(lv, i, &k))
            json_array_append_new(cv, class_json(&k, sd_level_vertex_singular(lv, i)));
    for (uint32_t i = 0; i < ne; i++)
        if (!sd_level_edge_class(lv, i, &k)) {
            json_t *o = class_json(&k, sd_level_edge_singular(lv, i));
            json_object_set_new(o, "vertices", json_pack("[I, I]", (json_int_t)ev[2 * i],
                                                         (json_int_t)ev[2 * i + 1]));
            json_array_append_new(ce, o);
        }
    json_t *tj = json_array();
    for (uint32_t i = 0, off = 0; i < m->tags.n; off += m->tags.size[i++]) {
        json_t *a = json_array();
        for (int j = 0; j < m->tags.size[i]; j++)
            json_array_append_new(a, json_integer(m->tags.idx[off + j]));
        json_array_append_new(tj, a);
    }
    json_t *pj = json_array();
    for (uint32_t i = 0; i < m->tags.npet; i++) {
        static const char *const kinds[] = {"convex", "concave", "smooth"};
        const sd_petal_tag *q = &m->tags.pet[i];
        json_array_append_new(pj, json_pack("{s:I, s:[I, I, I], s:s}", "vertex",
                                            (json_int_t)q->vertex, "triangle",
                                            (json_int_t)q->triangle[0], (json_int_t)q->triangle[1],
                                            (json_int_t)q->triangle[2], "kind", kinds[q->kind % 3]));
    }
    json_t *dj = json_array();
    for (uint32_t s = 0; s < in->ns; s++)
        if (in->size[s] == 4)
            json_array_append_new(dj, json_pack("[I, i]", (json_int_t)s, sd_complex_diagonal(m->c, s)));
    pthread_rwlock_unlock(&m->data);
    static const char *const schemes[] = {"box", "averaged"}, *const weights[] = {"warren", "loop"};
    static const char *const nmd[] = {"G2", "G1"}, *const surfs[] = {"chang-qin", "ying-zorin"};
    json_t *oj = json_array();
    for (uint32_t i = 0; i < m->rules.noverrides; i++) {
        const sd_override *o = &m->rules.overrides[i];
        json_t *sx = json_array();
        for (int j = 0; j < o->nverts; j++)
            json_array_append_new(sx, json_integer(o->simplex[j]));
        json_t *x = json_pack("{s:o, s:s}", "simplex", sx, "rule", sd_rule_name(o->rule));
        if (o->rule == SD_RULE_N1)
            json_object_set_new(x, "dimension", json_integer(o->dimension));
        if (o->rule == SD_RULE_N2) {
            json_t *pr = json_array();
            for (int j = 0; j < 2; j++) {
                json_t *q = json_array();
                for (int u = 0; u < o->pair_size; u++)
                    json_array_append_new(q, json_integer(o->pair[j][u]));
                json_array_append_new(pr, q);
            }
            json_object_set_new(x, "pair", pr);
        }
        json_array_append_new(oj, x);
    }
    json_t *tags = json_pack("{s:o}", "singular", tj);
    if (json_array_size(pj)) /* only when given: {"singular"} as PUT otherwise */
        json_object_set(tags, "petals", pj);
    json_decref(pj);
    return json_pack("{s:o, s:o, s:o, s:o, s:{s:o, s:o}, s:o, s:{s:s, s:o, s:s, s:s, s:s}, s:O}",
                     "vertices", vs, "simplices", ss, "attributes", at, "diagonals", dj,
                     "classes", "vertices", cv,
                     "edges", ce, "tags", tags, "rules", "nonmanifold_default",
                     nmd[m->rules.nonmanifold_default & 1], "overrides", oj,
                     "solid_scheme", schemes[m->rules.solid_scheme & 1],
                     "surface_weights", weights[m->rules.surface_weights & 1],
                     "nonmanifold_surface", surfs[m->rules.nonmanifold_surface & 1],
                     "summary", m->summary);
}

/* ---- levels ------------------------------------------------------------------------------- */

int api_parse_level(const char *s, api_problem *p)
{
    char *end;
    errno = 0;
    if (!s || !*s || !isdigit((unsigned char)*s))
        return -(api_fail(p, 400, "bad-level", "the level must be a non-negative integer") != 0);
    long l = strtol(s, &end, 10);
    if (*end)
        return -(api_fail(p, 400, "bad-level", "the level must be a non-negative integer") != 0);
    if (errno || l > SD_MAX_LEVEL)
        return -(api_fail(p, 422, "level-out-of-range",
                          "level %.20s is out of range 0..%d", s, SD_MAX_LEVEL) != 0);
    return (int)l;
}

uint64_t api_estimate_bytes(const sd_complex *c, int level)
{
    return sd_complex_estimate_bytes(c, level); /* the core's per-entity sizes */
}

static int check_level_limits(api_model *m, int level, const api_limits *lim, api_problem *p)
{
    sd_counts n;
    sd_complex_counts(m->c, level, &n);
    uint64_t cells = n.points + n.curves + n.triangles + n.tetrahedra + n.octahedra;
    if (cells > lim->max_cells)
        return api_fail_limit(p, "max_cells", lim->max_cells, cells,
                              "level %d has %llu cells, over the limit of %llu per level; ask for "
                              "a lower level or refine locally", level, (unsigned long long)cells,
                              (unsigned long long)lim->max_cells);
    uint64_t need = atomic_load(&m->memory_bytes) + api_estimate_bytes(m->c, level);
    if (need > lim->max_session_bytes)
        return api_fail_limit(p, "max_session_bytes", lim->max_session_bytes, need,
                              "level %d needs about %llu bytes, over the session limit of %llu; "
                              "ask for a lower level", level, (unsigned long long)need,
                              (unsigned long long)lim->max_session_bytes);
    return 0;
}

/* Comma-separated list item iteration: copies the next item into buf; returns 0 at the end. */
static int next_item(const char **s, char *buf, size_t cap)
{
    if (!*s || !**s)
        return 0;
    const char *e = strchr(*s, ',');
    size_t n = e ? (size_t)(e - *s) : strlen(*s);
    snprintf(buf, cap, "%.*s", (int)(n < cap ? n : cap - 1), *s);
    *s = e ? e + 1 : *s + n;
    return 1;
}

static int parse_double(const char *s, double *x)
{
    char *end;
    errno = 0;
    *x = strtod(s, &end);
    return *s && !*end && !errno && isfinite(*x);
}

static int find_attr(const api_input *in, const char *name)
{
    for (int a = 0; a < in->nattrs; a++)
        if (!strcmp(in->attrs[a].name, name))
            return a;
    return -1;
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

static int parse_query(const api_model *m, const api_level_query *q, out_request *rq,
                       out_format *fmt, api_problem *p)
{
    char item[64];
    *fmt = OUT_GLB;
    if (q->format) {
        int f = out_format_parse(q->format);
        if (f < 0)
            return api_fail_at(p, 422, "unknown-value", "format",
                               "format \"%.20s\" is not one of glb, gltf, vtu, vtk, json", q->format);
        *fmt = (out_format)f;
    }
    rq->parts = OUT_PART_ALL;
    if (q->parts) {
        static const char *const names[] = {"points", "curves", "surfaces", "solids"};
        const char *s = q->parts;
        rq->parts = 0;
        while (next_item(&s, item, sizeof item)) {
            int k = 0;
            while (k < 4 && strcmp(item, names[k]))
                k++;
            if (k == 4)
                return api_fail_at(p, 422, "unknown-value", "parts",
                                   "part \"%.20s\" is not one of points, curves, surfaces, solids",
                                   item);
            rq->parts |= 1u << k;
        }
        if (!rq->parts)
            return api_fail_at(p, 422, "unknown-value", "parts", "parts must name at least one part");
    }
    if (q->slice) {
        const char *s = q->slice;
        int k = 0;
        while (next_item(&s, item, sizeof item)) {
            if (k == 4 || !parse_double(item, &rq->slice[k]))
                return api_fail_at(p, 422, "bad-slice", "slice",
                                   "slice is nx,ny,nz,d: four finite numbers");
            k++;
        }
        if (k != 4)
            return api_fail_at(p, 422, "bad-slice", "slice", "slice is nx,ny,nz,d: four finite numbers");
        if (rq->slice[0] == 0 && rq->slice[1] == 0 && rq->slice[2] == 0)
            return api_fail_at(p, 422, "bad-slice", "slice", "the slice normal must not be zero");
        rq->has_slice = 1;
    }
    rq->colormap_attr = -1;
    const api_input *in = m->in;
    if (q->attributes) {
        const char *s = q->attributes;
        while (next_item(&s, item, sizeof item)) {
            int a = find_attr(in, item);
            if (a < 0)
                return api_fail_at(p, 422, "unknown-attribute", "attributes",
                                   "no attribute \"%.40s\" in this complex", item);
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
            return api_fail_at(p, 422, "bad-colormap", "colormap", "colormap is NAME:min:max");
        snprintf(name, sizeof name, "%.*s", (int)(c1 - q->colormap), q->colormap);
        snprintf(num, sizeof num, "%.*s", (int)(c2 - c1 - 1), c1 + 1);
        if (!parse_double(num, &lo) || !parse_double(c2 + 1, &hi) || !(lo < hi))
            return api_fail_at(p, 422, "bad-colormap", "colormap",
                               "colormap min and max must be finite numbers with min < max");
        int a = find_attr(in, name);
        if (a < 0)
            return api_fail_at(p, 422, "unknown-attribute", "colormap",
                               "no attribute \"%.40s\" in this complex", name);
        rq->colormap_attr = add_attr(m, rq, a);
        rq->colormap_min = lo;
        rq->colormap_max = hi;
    }
    if (q->octahedra) {
        if (!strcmp(q->octahedra, "polyhedra"))
            rq->octahedra_as_polyhedra = 1;
        else if (strcmp(q->octahedra, "tets"))
            return api_fail_at(p, 422, "unknown-value", "octahedra",
                               "octahedra is \"tets\" (4 tetrahedra each) or \"polyhedra\"");
    }
    return 0;
}

int api_level_open(api_model *m, int level, const api_level_query *q, const api_limits *lim,
                   uint64_t version, out_stream **out, out_format *fmt, api_problem *p)
{
    *out = NULL;
    if (!m->c)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    out_request rq;
    memset(&rq, 0, sizeof rq);
    if (parse_query(m, q, &rq, fmt, p) || check_level_limits(m, level, lim, p))
        return p->status;
    rq.complex = m->c;
    rq.level = level;
    rq.version = version;
    sd_error e = {0};
    pthread_mutex_lock(&m->lock);
    if (api_model_level_locked(m, level, &e)) {
        if (*fmt == OUT_GLB || *fmt == OUT_GLTF)
            rq.geometry = api_model_geometry_locked(m, level);
        pthread_rwlock_rdlock(&m->data); /* held until api_level_close */
        *out = out_open(&rq, *fmt, &e);
        if (!*out)
            pthread_rwlock_unlock(&m->data);
    }
    pthread_mutex_unlock(&m->lock);
    if (!*out)
        return e.code == SD_ERR_ARG ? api_fail(p, 422, "invalid-argument", "%s", e.message)
                                    : api_fail_core(p, &e, NULL, NULL);
    return 0;
}

void api_level_close(api_model *m, out_stream *os)
{
    if (!os)
        return;
    out_close(os);
    pthread_rwlock_unlock(&m->data);
}

json_t *api_level_stats(api_model *m, int level, const api_limits *lim, api_problem *p)
{
    if (!m->c) {
        api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
        return NULL;
    }
    if (check_level_limits(m, level, lim, p))
        return NULL;
    sd_error e = {0};
    pthread_mutex_lock(&m->lock);
    const sd_level *lv = api_model_level_locked(m, level, &e);
    json_t *bytes = json_object();
    double secs = m->seconds[level];
    for (int f = 0; lv && f < OUT_FORMAT_COUNT; f++) {
        out_request rq;
        memset(&rq, 0, sizeof rq);
        rq.complex = m->c;
        rq.level = level;
        rq.parts = OUT_PART_ALL;
        rq.colormap_attr = -1;
        if (f == OUT_GLB || f == OUT_GLTF)
            rq.geometry = api_model_geometry_locked(m, level);
        out_stream *s = out_open(&rq, (out_format)f, &e);
        if (s && out_size(s) != UINT64_MAX)
            json_object_set_new(bytes, out_format_name((out_format)f), json_integer((json_int_t)out_size(s)));
        out_close(s);
    }
    pthread_mutex_unlock(&m->lock);
    if (!lv) {
        json_decref(bytes);
        api_fail_core(p, &e, NULL, NULL);
        return NULL;
    }
    sd_counts n;
    sd_complex_counts(m->c, level, &n);
    return json_pack("{s:i, s:{s:I, s:I, s:I, s:I, s:I, s:I, s:I, s:I}, s:o, s:f, s:I}", "level",
                     level, "counts", "vertices", (json_int_t)n.vertices, "edges",
                     (json_int_t)n.edges, "faces", (json_int_t)n.faces, "points",
                     (json_int_t)n.points, "curves", (json_int_t)n.curves, "triangles",
                     (json_int_t)n.triangles, "tetrahedra", (json_int_t)n.tetrahedra, "octahedra",
                     (json_int_t)n.octahedra, "bytes", bytes, "seconds", secs, "memory_bytes",
                     (json_int_t)atomic_load(&m->memory_bytes));
}

/* ---- local analysis ----------------------------------------------------------------------- */

/* A non-negative decimal index below `n` from a query value; -1 + problem otherwise. */
static long query_index(const char *s, uint32_t n, const char *name, api_problem *p)
{
    char *end;
    errno = 0;
    long v = s && isdigit((unsigned char)*s) ? strtol(s, &end, 10) : -1;
    if (v < 0 || *end || errno) {
        api_fail_at(p, 400, "wrong-type", name, "%s must be a vertex index (a non-negative integer)",
                    name);
        return -1;
    }
    if ((unsigned long)v >= n) {
        api_fail_at(p, 422, "out-of-range", name, "vertex %ld out of range (%u vertices)", v, n);
        return -1;
    }
    return v;
}

json_t *api_analysis(api_model *m, const char *vertex, const char *edge, api_problem *p)
{
    if (!m->c) {
        api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
        return NULL;
    }
    if (!vertex == !edge) {
        api_fail(p, 400, "missing-field", "give exactly one of vertex=i or edge=i,j");
        return NULL;
    }
    long a, b = -1;
    if (vertex) {
        if ((a = query_index(vertex, m->in->nv, "vertex", p)) < 0)
            return NULL;
    } else {
        char first[24];
        const char *comma = strchr(edge, ',');
        if (!comma || (size_t)(comma - edge) >= sizeof first) {
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
    sd_analysis an;
    sd_error e = {0};
    pthread_mutex_lock(&m->lock);
    sd_result r = b < 0 ? sd_analyze_vertex(m->c, (uint32_t)a, &an, &e)
                        : sd_analyze_edge(m->c, (uint32_t)a, (uint32_t)b, &an, &e);
    pthread_mutex_unlock(&m->lock);
    if (r) {
        if (r == SD_ERR_ARG)
            api_fail_at(p, 422, "not-analysable", b < 0 ? "vertex" : "edge", "%s", e.message);
        else
            api_fail_core(p, &e, NULL, NULL);
        return NULL;
    }
    json_t *mat = json_array(), *eig = json_array(), *pts = json_array();
    for (int i = 0; i < an.size; i++) {
        json_array_append_new(mat, doubles_json(an.matrix + (size_t)i * an.size, (size_t)an.size));
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
    sd_analysis_free(&an);
    return j;
}

/* ---- PATCH /control-points ---------------------------------------------------------------- */

/* One channel's part of an edit: indices and new values (ncomp each). */
typedef struct edit_part {
    int channel, attr;        /* attr: index into the input's attributes, -1 for positions */
    int ncomp;
    size_t n;
    uint32_t *idx;
    double *val, *old;        /* old: the values before, for undoing a half-applied edit */
} edit_part;

static int parse_edit_entries(json_t *arr, const char *base, const char *vkey, int ncomp,
                              uint32_t nv, edit_part *e, int32_t *seen, api_problem *p)
{
    char ptr[96], at[96];
    if (!json_is_array(arr))
        return api_fail_at(p, 400, "wrong-type", base, "must be an array of {\"index\", \"%s\"}", vkey);
    size_t n = json_array_size(arr);
    if (n > nv)
        return api_fail_at(p, 422, "repeated-index", base,
                           "%zu entries for %u control points: some point is listed twice", n, nv);
    e->idx = malloc((n ? n : 1) * sizeof *e->idx);
    e->val = malloc((n ? n : 1) * ncomp * sizeof *e->val);
    e->old = malloc((n ? n : 1) * ncomp * sizeof *e->old);
    if (!e->idx || !e->val || !e->old)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    e->ncomp = ncomp;
    const char *const keys[] = {"index", vkey, NULL};
    int rc = 0;
    size_t i;
    for (i = 0; i < n && !rc; i++) {
        json_t *o = json_array_get(arr, i), *x;
        api_ptr_index(ptr, sizeof ptr, base, i);
        if (!json_is_object(o)) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "an entry is {\"index\", \"%s\"}", vkey);
            break;
        }
        long long v;
        if ((rc = api_only_keys(o, ptr, keys, p)))
            break;
        api_ptr_key(at, sizeof at, ptr, "index");
        if (!(x = json_object_get(o, "index"))) {
            rc = api_fail_at(p, 400, "missing-field", at, "\"index\" is required");
            break;
        }
        if ((rc = api_get_int(x, at, 0, (long long)nv - 1, &v, p)))
            break;
        if (seen[v] >= 0) {
            rc = api_fail_at(p, 422, "repeated-index", at, "point %lld is edited twice", v);
            break;
        }
        seen[v] = (int32_t)i;
        e->idx[i] = (uint32_t)v;
        api_ptr_key(at, sizeof at, ptr, vkey);
        if (!(x = json_object_get(o, vkey))) {
            rc = api_fail_at(p, 400, "missing-field", at, "\"%s\" is required", vkey);
            break;
        }
        if (ncomp == 1 && json_is_number(x)) {
            rc = api_get_number(x, at, 1e15, &e->val[i], p);
            continue;
        }
        if (!json_is_array(x) || json_array_size(x) != (size_t)ncomp) {
            rc = api_fail_at(p, 400, "wrong-type", at, "must be %s%d numbers",
                             ncomp == 1 ? "a number or an array of " : "an array of ", ncomp);
            break;
        }
        for (int k = 0; k < ncomp && !rc; k++) {
            char ck[96];
            api_ptr_index(ck, sizeof ck, at, k);
            rc = api_get_number(json_array_get(x, k), ck, 1e15, &e->val[i * ncomp + k], p);
        }
    }
    for (size_t j = 0; j < i; j++) /* leave `seen` clean for the next list */
        if (j < n)
            seen[e->idx[j]] = -1;
    e->n = n;
    return rc;
}

static void edit_parts_free(edit_part *parts, int n)
{
    for (int i = 0; i < n; i++) {
        free(parts[i].idx);
        free(parts[i].val);
        free(parts[i].old);
    }
}

int api_edit(api_model *m, json_t *body, uint64_t *counts, int *levels, api_problem *p)
{
    static const char *const keys[] = {"moves", "attributes", NULL};
    if (!m->c)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    if (api_only_keys(body, "", keys, p))
        return p->status;
    api_input *in = m->in;
    edit_part parts[1 + API_MAX_ATTRIBUTES];
    memset(parts, 0, sizeof parts);
    int np = 0, rc = 0;
    int32_t *seen = malloc(((size_t)in->nv + 1) * sizeof *seen);
    if (!seen)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    for (uint32_t i = 0; i < in->nv; i++)
        seen[i] = -1;
    json_t *mv = json_object_get(body, "moves"), *at = json_object_get(body, "attributes");
    if (mv) {
        parts[np] = (edit_part){.channel = 0, .attr = -1};
        rc = parse_edit_entries(mv, "/moves", "position", 3, in->nv, &parts[np++], seen, p);
    }
    if (!rc && at && !json_is_object(at))
        rc = api_fail_at(p, 400, "wrong-type", "/attributes", "must be an object: name -> entries");
    const char *name;
    json_t *list;
    if (!rc && at)
        json_object_foreach(at, name, list) {
            char ptr[96];
            api_ptr_key(ptr, sizeof ptr, "/attributes", name);
            int a = find_attr(in, name);
            if (a < 0) {
                rc = api_fail_at(p, 422, "unknown-attribute", ptr, "no attribute \"%.40s\"", name);
                break;
            }
            parts[np] = (edit_part){.channel = m->channel[a], .attr = a};
            if ((rc = parse_edit_entries(list, ptr, "value", in->attrs[a].ncomp, in->nv,
                                         &parts[np++], seen, p)))
                break;
        }
    free(seen);
    if (!rc && !mv && !at)
        rc = api_fail(p, 400, "missing-field", "give \"moves\" and/or \"attributes\"");
    if (rc) {
        edit_parts_free(parts, np);
        return rc;
    }
    /* everything is valid: apply under the compute lock and the data write lock */
    pthread_mutex_lock(&m->lock);
    pthread_rwlock_wrlock(&m->data);
    *levels = sd_complex_levels_computed(m->c);
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        counts[l] = 0;
    sd_error e = {0};
    int done = 0;
    for (; done < np; done++) {
        edit_part *q = &parts[done];
        const double *cur = sd_level_channel(sd_complex_level(m->c, 0, &e), q->channel, NULL);
        for (size_t i = 0; i < q->n; i++)
            memcpy(q->old + i * q->ncomp, cur + (size_t)q->idx[i] * q->ncomp, q->ncomp * sizeof *cur);
        uint64_t c[SD_MAX_LEVEL + 1];
        if (sd_complex_edit(m->c, q->channel, q->n, q->idx, q->val, c, &e))
            break;
        for (int l = 0; l <= SD_MAX_LEVEL; l++)
            counts[l] = c[l] > counts[l] ? c[l] : counts[l];
    }
    if (done < np) { /* out of memory half-way: undo what was applied */
        for (int i = done - 1; i >= 0; i--)
            sd_complex_edit(m->c, parts[i].channel, parts[i].n, parts[i].idx, parts[i].old, NULL, NULL);
        rc = api_fail_core(p, &e, NULL, NULL);
    } else {
        /* the posted input follows (GET /complex, later rule changes rebuild from it) */
        for (int i = 0; i < np; i++) {
            double *dst = parts[i].attr < 0 ? in->xyz : in->attrs[parts[i].attr].data;
            for (size_t k = 0; k < parts[i].n; k++)
                memcpy(dst + (size_t)parts[i].idx[k] * parts[i].ncomp, parts[i].val + k * parts[i].ncomp,
                       parts[i].ncomp * sizeof *dst);
        }
        for (int l = 0; l <= SD_MAX_LEVEL; l++) { /* normals follow the positions */
            out_geometry_free(m->geometry[l]);
            m->geometry[l] = NULL;
        }
    }
    api_model_publish(m); /* the by-column matrices of the first edit count as session memory */
    pthread_rwlock_unlock(&m->data);
    pthread_mutex_unlock(&m->lock);
    edit_parts_free(parts, np);
    return rc;
}

/* ---- GET /matrices/{L} -------------------------------------------------------------------- */

int api_matrix_open(api_model *m, int level, const char *from, const char *format,
                    const api_limits *lim, out_stream **out, const char **ctype, api_problem *p)
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
    if (level < 1 || f >= level)
        return api_fail_at(p, 422, "out-of-range", "from",
                           "from (%ld) must be below the level (%d); level 0 has no matrix", f, level);
    if (check_level_limits(m, level, lim, p))
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

/* ---- POST /refine ------------------------------------------------------------------------- */

typedef struct selection {
    int kind;                 /* 0 simplices, 1 box, 2 sphere */
    uint32_t n;               /* simplices: sorted vertex lists, 4 ids each (UINT32_MAX padded) */
    uint32_t (*keys)[4];
    double lo[3], hi[3];      /* box */
    double c[3], r;           /* sphere */
} selection;

static int cmp_key4(const void *x, const void *y) { return memcmp(x, y, 4 * sizeof(uint32_t)); }

static void sort_key(uint32_t k[4], const uint32_t *v, int n)
{
    for (int i = 0; i < 4; i++)
        k[i] = i < n ? v[i] : UINT32_MAX;
    for (int i = 1; i < n; i++) /* insertion sort of at most 4 */
        for (int j = i; j > 0 && k[j - 1] > k[j]; j--) {
            uint32_t t = k[j];
            k[j] = k[j - 1];
            k[j - 1] = t;
        }
}

static int parse_point(json_t *v, const char *ptr, double out[3], api_problem *p)
{
    if (!json_is_array(v) || json_array_size(v) != 3)
        return api_fail_at(p, 400, "wrong-type", ptr, "must be an array of 3 numbers");
    for (int k = 0; k < 3; k++) {
        char at[96];
        api_ptr_index(at, sizeof at, ptr, k);
        if (api_get_number(json_array_get(v, k), at, 1e15, &out[k], p))
            return p->status;
    }
    return 0;
}

static int parse_selection(json_t *sel, const api_input *in, selection *s, api_problem *p)
{
    static const char *const keys[] = {"simplices", "box", "sphere", NULL};
    if (!json_is_object(sel))
        return api_fail_at(p, 400, "wrong-type", "/select",
                           "must be {\"simplices\": […]}, {\"box\": …} or {\"sphere\": …}");
    if (api_only_keys(sel, "/select", keys, p))
        return p->status;
    if (json_object_size(sel) != 1)
        return api_fail_at(p, 400, "wrong-type", "/select", "give exactly one of simplices, box, sphere");
    json_t *v;
    if ((v = json_object_get(sel, "simplices"))) {
        s->kind = 0;
        if (!json_is_array(v))
            return api_fail_at(p, 400, "wrong-type", "/select/simplices", "must be an array of simplices");
        s->keys = malloc((json_array_size(v) + 1) * sizeof *s->keys);
        if (!s->keys)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        /* every posted simplex, sorted, to find the selected ones */
        uint32_t (*all)[4] = malloc(((size_t)in->ns + 1) * sizeof *all);
        if (!all)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        for (uint32_t q = 0, off = 0; q < in->ns; off += in->size[q++])
            sort_key(all[q], in->idx + off, in->size[q]);
        qsort(all, in->ns, sizeof *all, cmp_key4);
        size_t i;
        json_t *x;
        int rc = 0;
        json_array_foreach(v, i, x) {
            char ptr[96], at[96];
            api_ptr_index(ptr, sizeof ptr, "/select/simplices", i);
            size_t k = json_is_array(x) ? json_array_size(x) : 0;
            if (k < 1 || k > 4) {
                rc = api_fail_at(p, 400, "wrong-type", ptr, "a simplex is an array of 1 to 4 indices");
                break;
            }
            uint32_t ids[4];
            for (size_t j = 0; j < k && !rc; j++) {
                long long id;
                api_ptr_index(at, sizeof at, ptr, j);
                rc = api_get_int(json_array_get(x, j), at, 0, (long long)in->nv - 1, &id, p);
                ids[j] = (uint32_t)id;
            }
            if (rc)
                break;
            sort_key(s->keys[s->n], ids, (int)k);
            if (!bsearch(s->keys[s->n], all, in->ns, sizeof *all, cmp_key4)) {
                rc = api_fail_at(p, 422, "no-such-simplex", ptr, "not a simplex of the complex");
                break;
            }
            s->n++;
        }
        free(all);
        if (!rc)
            qsort(s->keys, s->n, sizeof *s->keys, cmp_key4);
        return rc;
    }
    if ((v = json_object_get(sel, "box"))) {
        static const char *const bk[] = {"min", "max", NULL};
        s->kind = 1;
        if (!json_is_object(v))
            return api_fail_at(p, 400, "wrong-type", "/select/box", "must be {\"min\", \"max\"}");
        if (api_only_keys(v, "/select/box", bk, p) ||
            parse_point(json_object_get(v, "min"), "/select/box/min", s->lo, p) ||
            parse_point(json_object_get(v, "max"), "/select/box/max", s->hi, p))
            return p->status;
        for (int k = 0; k < 3; k++)
            if (s->lo[k] > s->hi[k])
                return api_fail_at(p, 422, "out-of-range", "/select/box", "min must not exceed max");
        return 0;
    }
    v = json_object_get(sel, "sphere");
    static const char *const sk[] = {"center", "radius", NULL};
    s->kind = 2;
    if (!json_is_object(v))
        return api_fail_at(p, 400, "wrong-type", "/select/sphere", "must be {\"center\", \"radius\"}");
    if (api_only_keys(v, "/select/sphere", sk, p) ||
        parse_point(json_object_get(v, "center"), "/select/sphere/center", s->c, p))
        return p->status;
    json_t *r = json_object_get(v, "radius");
    if (!r)
        return api_fail_at(p, 400, "missing-field", "/select/sphere/radius", "\"radius\" is required");
    if (api_get_number(r, "/select/sphere/radius", 1e15, &s->r, p))
        return p->status;
    if (!(s->r > 0))
        return api_fail_at(p, 422, "out-of-range", "/select/sphere/radius", "radius must be positive");
    return 0;
}

/* Does simplex v[0..n) fall in a geometric selection (its centroid inside)? */
static bool in_region(const selection *s, const double *xyz, const uint32_t *v, int n)
{
    double c[3] = {0, 0, 0};
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 3; k++)
            c[k] += xyz[3 * (size_t)v[i] + k] / n;
    if (s->kind == 1)
        return c[0] >= s->lo[0] && c[0] <= s->hi[0] && c[1] >= s->lo[1] && c[1] <= s->hi[1] &&
               c[2] >= s->lo[2] && c[2] <= s->hi[2];
    double d2 = 0;
    for (int k = 0; k < 3; k++)
        d2 += (c[k] - s->c[k]) * (c[k] - s->c[k]);
    return d2 <= s->r * s->r;
}

static int cmp_pair(const void *x, const void *y) { return memcmp(x, y, 2 * sizeof(uint32_t)); }

/* A model of `in` with the rules, tags and overrides, dropping the overrides the refined complex
 * refuses (an override carried to a simplex whose type no longer fits it). */
static api_model *model_with(api_input *in, const api_rules *rules, const api_tags *tags,
                             sd_override *ov, uint32_t nov, const api_limits *lim, sd_error *e)
{
    api_model *m = api_model_new(in, rules, lim->max_session_bytes, e);
    if (!m)
        return NULL;
    while (nov && api_model_set_overrides(m, ov, nov, e)) {
        free(m->rules.overrides);
        m->rules.overrides = NULL;
        m->rules.noverrides = 0;
        if (e->code != SD_ERR_ARG && e->code != SD_ERR_INDEX)
            break;
        long bad = e->item < 0 ? 0 : e->item;
        memmove(ov + bad, ov + bad + 1, (nov - bad - 1) * sizeof *ov);
        nov--;
    }
    bool petal;
    if ((tags->n || tags->npet) && api_model_set_tags(m, tags, e, &petal)) {
        api_model_unref(m);
        return NULL;
    }
    return m;
}

/* Place the new vertices of one refinement step by the subdivision rules: the level-1 edge
 * points of the complex before the step (positions and attributes alike). */
static int subdivision_positions(const api_input *in, const api_rules *rules, const api_tags *tags,
                                 sd_override *ov, uint32_t nov, sd_refinement *r,
                                 double **attr_new, const api_limits *lim, api_problem *p)
{
    sd_error e = {0};
    api_model *tmp = model_with((api_input *)in, rules, tags, ov, nov, lim, &e);
    const sd_level *l1 = tmp ? sd_complex_level(tmp->c, 1, &e) : NULL;
    if (!l1) {
        api_model_unref(tmp);
        return api_fail_core(p, &e, "/simplices", "/vertices");
    }
    /* sorted (a<b, new id) so each level-1 edge point finds its new vertex */
    uint32_t (*key)[3] = malloc((r->nsplit + 1) * sizeof *key);
    if (!key) {
        api_model_unref(tmp);
        return api_fail(p, 503, "out-of-memory", "out of memory");
    }
    for (size_t i = 0; i < r->nsplit; i++) {
        uint32_t a = r->split[i][0], b = r->split[i][1];
        key[i][0] = a < b ? a : b;
        key[i][1] = a < b ? b : a;
        key[i][2] = (uint32_t)(in->nv + i);
    }
    qsort(key, r->nsplit, sizeof *key, cmp_pair);
    uint32_t n1 = sd_level_num_vertices(l1);
    const double *x1 = sd_level_channel(l1, 0, NULL);
    for (uint32_t v = in->nv; v < n1; v++) {
        uint32_t a, b;
        if (sd_level_origin(l1, v, &a, &b) != SD_ORIGIN_EDGE)
            continue;
        uint32_t k[3] = {a < b ? a : b, a < b ? b : a, 0};
        uint32_t (*hit)[3] = bsearch(k, key, r->nsplit, sizeof *key, cmp_pair);
        if (!hit)
            continue;
        uint32_t id = (*hit)[2];
        memcpy(r->xyz + 3 * (size_t)id, x1 + 3 * (size_t)v, 3 * sizeof *x1);
        for (int t = 0; t < in->nattrs; t++) {
            int nc = in->attrs[t].ncomp;
            const double *a1 = sd_level_channel(l1, tmp->channel[t], NULL);
            memcpy(attr_new[t] + (size_t)id * nc, a1 + (size_t)v * nc, nc * sizeof *a1);
        }
    }
    free(key);
    api_model_unref(tmp);
    return 0;
}

int api_refine(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
               uint64_t *red, uint64_t *green, api_problem *p)
{
    static const char *const keys[] = {"select", "depth", "positions", NULL};
    static const char *const placements[] = {"subdivision", "midpoint", NULL};
    *out = NULL;
    *red = *green = 0;
    if (api_only_keys(body, "", keys, p))
        return p->status;
    if (!cur->in)
        return api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
    json_t *v;
    long long depth = 1;
    int place = 0;
    if ((v = json_object_get(body, "depth")) && api_get_int(v, "/depth", 1, 4, &depth, p))
        return p->status;
    if ((v = json_object_get(body, "positions")) &&
        (place = api_get_enum(v, "/positions", placements, p)) < 0)
        return p->status;
    if (!(v = json_object_get(body, "select")))
        return api_fail_at(p, 400, "missing-field", "/select", "\"select\" is required");
    selection sel = {0};
    int rc = parse_selection(v, cur->in, &sel, p);
    /* the working complex: starts as the posted one, replaced after every step, with its tags
     * and overrides */
    api_input *in = cur->in;
    api_tags tags = {0};
    uint32_t nov = cur->rules.noverrides;
    sd_override *ov = malloc((nov + 1) * sizeof *ov);
    bool copied = api_tags_copy(&tags, &cur->tags);
    if (!ov || !copied)
        rc = rc ? rc : api_fail(p, 503, "out-of-memory", "out of memory");
    else if (nov)
        memcpy(ov, cur->rules.overrides, nov * sizeof *ov);
    atomic_fetch_add(&in->refs, 1);
    uint8_t *marked = NULL;
    for (int step = 0; !rc && step < depth; step++) {
        if (step == 0 || sel.kind != 0) { /* later steps of a simplex selection: its children */
            free(marked);
            marked = calloc((size_t)in->ns + 1, 1);
            if (!marked) {
                rc = api_fail(p, 503, "out-of-memory", "out of memory");
                break;
            }
            for (uint32_t s = 0, off = 0; s < in->ns; off += in->size[s++]) {
                if (in->size[s] < 2)
                    continue;
                if (sel.kind == 0) {
                    uint32_t k[4];
                    sort_key(k, in->idx + off, in->size[s]);
                    marked[s] = bsearch(k, sel.keys, sel.n, sizeof *sel.keys, cmp_key4) != NULL;
                } else
                    marked[s] = in_region(&sel, in->xyz, in->idx + off, in->size[s]);
            }
        }
        uint64_t nmarked = 0;
        for (uint32_t s = 0; s < in->ns; s++)
            nmarked += marked[s] = marked[s] && in->size[s] >= 2;
        if (!nmarked)
            break;
        sd_refinement r;
        sd_error e = {0};
        if (sd_refine(in->xyz, in->nv, in->idx, in->size, in->ns, marked, &r, &e)) {
            rc = api_fail_core(p, &e, "/select", NULL);
            break;
        }
        if (r.nv > lim->max_vertices || r.ns > lim->max_simplices) {
            rc = r.nv > lim->max_vertices
                     ? api_fail_limit(p, "max_vertices", lim->max_vertices, r.nv,
                                      "the refined complex would have %zu vertices; refine a "
                                      "smaller region or less deep", r.nv)
                     : api_fail_limit(p, "max_simplices", lim->max_simplices, r.ns,
                                      "the refined complex would have %zu simplices; refine a "
                                      "smaller region or less deep", r.ns);
            sd_refine_free(&r);
            break;
        }
        *red += r.red;
        *green += r.green;
        /* new attribute arrays: old values, then the new points at midpoints */
        double *attr_new[API_MAX_ATTRIBUTES] = {0};
        for (int t = 0; t < in->nattrs && !rc; t++) {
            int nc = in->attrs[t].ncomp;
            if (!(attr_new[t] = malloc(r.nv * nc * sizeof(double) + 8))) {
                rc = api_fail(p, 503, "out-of-memory", "out of memory");
                break;
            }
            memcpy(attr_new[t], in->attrs[t].data, (size_t)in->nv * nc * sizeof(double));
            for (size_t i = 0; i < r.nsplit; i++)
                for (int k = 0; k < nc; k++)
                    attr_new[t][(in->nv + i) * nc + k] =
                        0.5 * (in->attrs[t].data[(size_t)r.split[i][0] * nc + k] +
                               in->attrs[t].data[(size_t)r.split[i][1] * nc + k]);
        }
        /* or where the subdivision rules put them: level-1 edge points of the step's input */
        if (!rc && place == 0) {
            sd_override *ovc = malloc((nov + 1) * sizeof *ovc); /* model_with may drop some */
            if (!ovc)
                rc = api_fail(p, 503, "out-of-memory", "out of memory");
            else {
                memcpy(ovc, ov, nov * sizeof *ov);
                rc = subdivision_positions(in, &cur->rules, &tags, ovc, nov, &r, attr_new, lim, p);
                free(ovc);
            }
        }
        if (!rc) { /* the step's tags and overrides, carried to the children (core) */
            sd_tag_set was = {tags.idx, tags.size, tags.n, tags.pet, tags.npet, ov, nov}, now;
            if (sd_refine_carry(&r, &was, &now, &e)) {
                rc = api_fail(p, 503, "out-of-memory", "out of memory");
            } else {
                sd_tag_set_free(&was); /* malloc'ed, as the carried ones */
                tags = (api_tags){.n = (uint32_t)now.ntags, .size = now.size, .idx = now.idx,
                                  .npet = (uint32_t)now.npetals, .pet = now.petals};
                ov = now.overrides;
                nov = (uint32_t)now.noverrides;
            }
        }
        api_input *nx = rc ? NULL : api_input_new();
        if (!rc && !nx)
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
        if (rc) {
            for (int t = 0; t < in->nattrs; t++)
                free(attr_new[t]);
            sd_refine_free(&r);
            break;
        }
        nx->nv = (uint32_t)r.nv; /* the refinement's arrays move into the next input */
        nx->ns = (uint32_t)r.ns;
        nx->xyz = r.xyz;
        nx->idx = r.idx;
        nx->size = r.size;
        r.xyz = NULL;
        r.idx = NULL;
        r.size = NULL;
        nx->nattrs = in->nattrs;
        for (int t = 0; t < in->nattrs; t++) {
            nx->attrs[t] = in->attrs[t];
            nx->attrs[t].data = attr_new[t];
        }
        uint8_t *next_marked = calloc(r.ns + 1, 1); /* children of selected simplices */
        if (next_marked)
            for (size_t i = 0; i < r.ns; i++)
                next_marked[i] = marked[r.parent[i]];
        free(marked);
        marked = next_marked;
        sd_refine_free(&r);
        api_input_unref(in);
        in = nx;
        if (!marked && step + 1 < depth && sel.kind == 0)
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
    }
    free(marked);
    free(sel.keys);
    if (!rc) { /* with the carried tags and overrides (those that no longer fit are dropped) */
        sd_error e = {0};
        api_model *m = model_with(in, &cur->rules, &tags, ov, nov, lim, &e);
        api_rules keep = cur->rules;
        keep.overrides = m ? m->rules.overrides : NULL;
        keep.noverrides = m ? m->rules.noverrides : 0;
        rc = build_model(in, &keep, &tags, lim, out, p);
        api_model_unref(m);
    }
    free(ov);
    free(tags.size);
    free(tags.idx);
    free(tags.pet);
    api_input_unref(in);
    return rc;
}
