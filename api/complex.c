/* complex.c — PUT /complex and GET /complex (docs/API.md "Control complex"), and the level-0
 * summary both answer with.
 *
 * PUT reads the whole body into a new api_input (vertices, simplices, attributes, diagonals, then
 * the TetGen fill of api/fill.c), checking each array's length against api_limits before it
 * allocates, and builds the model beside the session's current one: a refusal leaves the session
 * as it was. api_build_model is the one place a model is built from an input, rules and tags for
 * every change handler, and the one place the core's refusals become problems with pointers
 * (/simplices/3/2, /overrides/0/pair, /petals/1/kind). GET renders the posted input with the
 * classes of level 0, which is immutable once built and so read without the model's lock.
 */
#include "handlers.h"
#include "details.h"
#include "mem.h"
#include "fill.h"
#include "repair.h"
#include "crease.h"
#include "internal.h"
#include "complex_stream.h"
#include "jsonin.h"
#include "rows.h"
#include <math.h>
#include <stdbool.h>
#include <ctype.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- PUT /complex ------------------------------------------------------------------------- */

static int parse_vertices(json_t *v, const api_packs *packs, const api_limits *lim, api_input *in,
                          api_problem *p)
{
    api_rows rows;
    if (!api_rows_open(&rows, v, packs, "/vertices"))
        return api_fail_at(p, 400, "wrong-type", "/vertices", "must be an array of [x, y, z]");
    size_t n = api_rows_count(&rows);
    if (n > lim->max_vertices)
        return api_fail_limit(p, "max_vertices", lim->max_vertices, n,
                              "%zu vertices exceed the limit of %u; split the model or raise "
                              "--max-vertices", n, lim->max_vertices);
    size_t bytes = (n ? n : 1) * 3 * sizeof *in->xyz;
    in->xyz = api_input_reserve(in, bytes) ? api_plain_malloc(bytes) : NULL;
    if (!in->xyz)
        return api_fail(p, 503, "out-of-memory", "out of memory reading %zu vertices", n);
    in->nv = (uint32_t)n;
    char ptr[96];
    api_row x;
    for (size_t i = 0; api_rows_next(&rows, &x); i++) {
        api_ptr_index(ptr, sizeof ptr, "/vertices", i);
        if (!api_row_is_array(&x) || api_row_size(&x) != 3)
            return api_fail_at(p, 400, "wrong-type", ptr, "a vertex is an array of 3 numbers");
        for (int k = 0; k < 3; k++) {
            api_num c = api_row_get(&x, (size_t)k);
            if (!api_num_is_number(c)) {
                char at[96];
                api_ptr_index(at, sizeof at, ptr, k);
                return api_fail_at(p, 400, "wrong-type", at, "a coordinate must be a number");
            }
            in->xyz[3 * i + k] = api_num_value(c);
        }
    }
    return 0;
}

static int parse_simplices(json_t *v, const api_packs *packs, const api_limits *lim,
                           api_input *in, api_problem *p)
{
    api_rows rows;
    if (!api_rows_open(&rows, v, packs, "/simplices"))
        return api_fail_at(p, 400, "wrong-type", "/simplices",
                           "must be an array of simplices (arrays of 1 to 4 vertex indices)");
    size_t n = api_rows_count(&rows);
    if (n > lim->max_simplices)
        return api_fail_limit(p, "max_simplices", lim->max_simplices, n,
                              "%zu simplices exceed the limit of %u; split the model or raise "
                              "--max-simplices", n, lim->max_simplices);
    char ptr[96];
    size_t total = 0;
    api_row s;
    /* (the pointers of the errors are written only when one is reported) */
    for (size_t i = 0; api_rows_next(&rows, &s); i++) { /* shapes first: the index array is sized exactly */
        size_t k = api_row_is_array(&s) ? api_row_size(&s) : 0;
        if (k < 1 || k > 4) {
            api_ptr_index(ptr, sizeof ptr, "/simplices", i);
            if (!api_row_is_array(&s))
                return api_fail_at(p, 400, "wrong-type", ptr,
                                   "a simplex is an array of 1 to 4 vertex indices");
            return api_fail_at(p, 422, "invalid-complex", ptr,
                               "simplex %zu has %zu vertices; a simplex has 1 to 4 (point, edge, "
                               "triangle, tetrahedron)", i, k);
        }
        total += k;
    }
    size_t bytes = (n ? n : 1) + (total ? total : 1) * sizeof *in->idx;
    if (api_input_reserve(in, bytes)) {
        in->size = api_plain_malloc(n ? n : 1);
        in->idx = api_plain_malloc((total ? total : 1) * sizeof *in->idx);
    }
    if (!in->size || !in->idx)
        return api_fail(p, 503, "out-of-memory", "out of memory reading %zu simplices", n);
    in->ns = (uint32_t)n;
    size_t off = 0;
    api_rows_rewind(&rows);
    for (size_t i = 0; api_rows_next(&rows, &s); i++) {
        size_t k = api_row_size(&s);
        in->size[i] = (uint8_t)k;
        for (size_t j = 0; j < k; j++) {
            api_num e = api_row_get(&s, j);
            long long x = api_num_is_integer(e) ? api_num_integer(e) : -1;
            if (x < 0 || x >= (long long)in->nv) {
                char at[96];
                api_ptr_index(ptr, sizeof ptr, "/simplices", i);
                api_ptr_index(at, sizeof at, ptr, j);
                if (!api_num_is_integer(e))
                    return api_fail_at(p, 400, "wrong-type", at,
                                       "a vertex index must be an integer");
                return api_fail_at(p, 422, "invalid-complex", at,
                                   "index %lld out of range (%u vertices)", x, in->nv);
            }
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

/* One attribute value at `at`: a number within +-API_MAX_VALUE (the bound of coordinates, so
 * that everything the core interpolates stays far from overflow). */
static int attribute_value(api_num x, const char *at, const char *what, double *out, api_problem *p)
{
    if (!api_num_is_number(x))
        return api_fail_at(p, 400, "wrong-type", at, "%s", what);
    double v = api_num_value(x);
    if (!(fabs(v) <= API_MAX_VALUE))
        return api_fail_at(p, 422, "out-of-range", at,
                           "%g is beyond the largest attribute value, +-%g", v, API_MAX_VALUE);
    *out = v;
    return 0;
}

static int parse_attributes(json_t *v, const api_packs *packs, api_input *in, api_problem *p)
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
        api_rows rows;
        if (!api_rows_open(&rows, a, packs, ptr))
            return api_fail_at(p, 400, "wrong-type", ptr, "must be an array with one value per vertex");
        if (api_rows_count(&rows) != in->nv)
            return api_fail_at(p, 422, "wrong-length", ptr, "has %zu values for %u vertices",
                               api_rows_count(&rows), in->nv);
        api_attribute *t = &in->attrs[in->nattrs];
        snprintf(t->name, sizeof t->name, "%s", name);
        api_row x;
        bool any = api_rows_next(&rows, &x);
        t->scalar_form = !any || !api_row_is_array(&x);
        t->ncomp = t->scalar_form ? 1 : (int)api_row_size(&x);
        if (t->ncomp < 1 || t->ncomp > 16) {
            api_ptr_index(at, sizeof at, ptr, 0);
            return api_fail_at(p, 422, "wrong-length", at,
                               "a vector value has 1 to 16 components, not %d", t->ncomp);
        }
        size_t bytes = (in->nv ? in->nv : 1) * (size_t)t->ncomp * sizeof *t->data;
        t->data = api_input_reserve(in, bytes) ? api_plain_malloc(bytes) : NULL;
        if (!t->data)
            return api_fail(p, 503, "out-of-memory", "out of memory reading attribute %s", name);
        in->nattrs++;
        api_rows_rewind(&rows);
        for (uint32_t i = 0; api_rows_next(&rows, &x); i++) {
            api_ptr_index(at, sizeof at, ptr, i);
            if (t->scalar_form) {
                if (api_row_is_array(&x))
                    return api_fail_at(p, 400, "wrong-type", at,
                                       "must be a number like the attribute's first value");
                if (attribute_value(api_row_value(&x), at,
                                    "must be a number like the attribute's first value",
                                    &t->data[i], p))
                    return p->status;
                continue;
            }
            if (!api_row_is_array(&x) || api_row_size(&x) != (size_t)t->ncomp)
                return api_fail_at(p, 400, "wrong-type", at,
                                   "must be an array of %d numbers like the attribute's first value",
                                   t->ncomp);
            for (int k = 0; k < t->ncomp; k++) {
                char ck[96];
                api_ptr_index(ck, sizeof ck, at, k);
                if (attribute_value(api_row_get(&x, (size_t)k), ck, "must be a number",
                                    &t->data[(size_t)i * t->ncomp + k], p))
                    return p->status;
            }
        }
    }
    return 0;
}

/* "diagonals": [[simplex, pair]...] — the major diagonal of chosen tetrahedra (001 Sec. 3:
 * pair 0 = edges 01|23, 1 = 02|13, 2 = 03|12 of the simplex as posted). */
static int parse_diagonals(json_t *v, const api_packs *packs, api_input *in, api_problem *p)
{
    api_rows rows;
    if (!api_rows_open(&rows, v, packs, "/diagonals"))
        return api_fail_at(p, 400, "wrong-type", "/diagonals", "must be an array of [simplex, pair]");
    size_t n = api_rows_count(&rows);
    if (n > in->ns)
        return api_fail_at(p, 422, "repeated-index", "/diagonals",
                           "%zu choices for %u simplices: some tetrahedron is listed twice", n, in->ns);
    in->diag = api_malloc((n ? n : 1) * sizeof *in->diag);
    uint8_t *seen = api_calloc((size_t)in->ns + 1, 1);
    int rc = 0;
    if (!in->diag || !seen)
        rc = api_fail(p, 503, "out-of-memory", "out of memory");
    char ptr[96], at[96];
    api_row d;
    for (size_t i = 0; !rc && api_rows_next(&rows, &d); i++) {
        long long s, k;
        api_ptr_index(ptr, sizeof ptr, "/diagonals", i);
        if (!api_row_is_array(&d) || api_row_size(&d) != 2) {
            rc = api_fail_at(p, 400, "wrong-type", ptr, "a choice is [simplex index, pair 0..2]");
            break;
        }
        api_ptr_index(at, sizeof at, ptr, 0);
        if ((rc = api_num_get_int(api_row_get(&d, 0), at, 0, (long long)in->ns - 1, &s, p)))
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
        if ((rc = api_num_get_int(api_row_get(&d, 1), at, 0, 2, &k, p)))
            break;
        in->diag[i][0] = (uint32_t)s;
        in->diag[i][1] = (uint32_t)k;
        in->ndiag++;
    }
    api_free(seen);
    return rc;
}

/* "reoriented": [simplex...] — the tetrahedra stored with their last two vertices exchanged, as
 * GET /complex lists them; when given, exactly these are (whatever their volume now), so a
 * complex saved after edits that turned tetrahedra inside out rebuilds the same levels. */
static int parse_reoriented(json_t *v, const api_packs *packs, api_input *in, api_problem *p)
{
    api_rows rows;
    if (!api_rows_open(&rows, v, packs, "/reoriented"))
        return api_fail_at(p, 400, "wrong-type", "/reoriented", "must be an array of simplex indices");
    if (api_rows_count(&rows) > in->ns)
        return api_fail_at(p, 422, "repeated-index", "/reoriented",
                           "%zu entries for %u simplices: some tetrahedron is listed twice",
                           api_rows_count(&rows), in->ns);
    if (!(in->reoriented = api_calloc((size_t)in->ns + 1, 1)))
        return api_fail(p, 503, "out-of-memory", "out of memory");
    char ptr[96];
    api_row d;
    for (size_t i = 0; api_rows_next(&rows, &d); i++) {
        long long s;
        api_ptr_index(ptr, sizeof ptr, "/reoriented", i);
        if (api_row_is_array(&d))
            return api_fail_at(p, 400, "wrong-type", ptr, "a simplex index");
        if (api_num_get_int(api_row_value(&d), ptr, 0, (long long)in->ns - 1, &s, p))
            return p->status;
        if (in->size[s] != 4)
            return api_fail_at(p, 422, "not-a-tetrahedron", ptr, "simplex %lld is not a tetrahedron", s);
        if (in->reoriented[s]++)
            return api_fail_at(p, 422, "repeated-index", ptr, "simplex %lld is listed twice", s);
    }
    return 0;
}

int api_build_model(api_input *in, const api_rules *rules, const api_tags *tags,
                       const api_limits *lim, api_model **out, api_problem *p)
{
    sd_error e = {0};
    api_model *m = api_model_new(in, rules, lim->max_session_bytes, lim->batch, &e);
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
    int which = API_TAG_SINGULAR;
    if (m && tags && (api_tags_any(tags) || (rules && rules->crease_method)) &&
        api_model_set_tags(m, tags, &e, &which)) {
        api_model_unref(m);
        if (e.code == SD_ERR_NOMEM)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        char ptr[96];
        if (which == API_TAG_SINGULAR && tags->from && e.item >= 0 && (uint32_t)e.item < tags->nfrom)
            e.item = tags->from[e.item]; /* the request's entry (an import's repeats dropped) */
        static const char *const lists[] = {"/singular", "/petals", "/sharpness", ""};
        api_ptr_index(ptr, sizeof ptr, lists[which], (size_t)(e.item < 0 ? 0 : e.item));
        if (which == API_TAG_TANGENT)
            api_tangent_ptr(tags, e.item, e.field, ptr, sizeof ptr);
        static const char *const fields[] = {"/vertex", "/triangle", "/kind"};
        static const char *const sfields[] = {"/simplex", "/value"};
        if (which == API_TAG_PETAL && e.field >= 0 && e.field < 3)
            strncat(ptr, fields[e.field], sizeof ptr - strlen(ptr) - 1);
        if (which == API_TAG_SHARPNESS && e.field >= 0 && e.field < 2)
            strncat(ptr, sfields[e.field], sizeof ptr - strlen(ptr) - 1);
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
    if (m->c && in && !in->reoriented) { /* the orientation is control data from now on */
        bool any = false;
        for (uint32_t q = 0; q < in->ns && !any; q++)
            any = in->size[q] == 4;
        if (any && !(in->reoriented = api_calloc((size_t)in->ns + 1, 1))) {
            api_model_unref(m);
            return api_fail(p, 503, "out-of-memory", "out of memory");
        }
        for (uint32_t q = 0; any && q < in->ns; q++)
            in->reoriented[q] = sd_complex_reoriented(m->c, q) == 1;
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

const char *const api_complex_packed[] = {"/vertices", "/simplices", "/attributes/*",
                                          "/diagonals", "/reoriented", "/fill/*/surface", NULL};

int api_put_complex(const api_model *cur, json_t *body, const api_limits *lim, api_model **out,
                    api_problem *p)
{
    return api_put_complex_packed(cur, body, NULL, lim, out, p);
}

int api_put_complex_packed(const api_model *cur, json_t *body, const api_packs *packs,
                           const api_limits *lim, api_model **out, api_problem *p)
{
    static const char *const keys[] = {"vertices", "simplices", "attributes", "diagonals",
                                       "reoriented", "fill", "details", "repair", NULL};
    *out = NULL;
    if (api_only_keys(body, "", keys, p))
        return p->status;
    json_t *vs = json_object_get(body, "vertices"), *ss = json_object_get(body, "simplices");
    if (!vs)
        return api_fail_at(p, 400, "missing-field", "/vertices", "\"vertices\" is required");
    if (!ss && !json_object_get(body, "fill"))
        return api_fail_at(p, 400, "missing-field", "/simplices", "\"simplices\" is required");
    json_t *rp = json_object_get(body, "repair");
    if (rp && !json_is_boolean(rp))
        return api_fail_at(p, 400, "wrong-type", "/repair", "must be true or false");
    api_input *in = api_input_new();
    if (!in)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    int rc = parse_vertices(vs, packs, lim, in, p);
    if (!rc && ss)
        rc = parse_simplices(ss, packs, lim, in, p);
    json_t *attrs = json_object_get(body, "attributes");
    if (!rc && attrs)
        rc = parse_attributes(attrs, packs, in, p);
    json_t *dg = json_object_get(body, "diagonals");
    if (!rc && dg)
        rc = parse_diagonals(dg, packs, in, p);
    json_t *ro = json_object_get(body, "reoriented"), *fill = json_object_get(body, "fill");
    if (!rc && ro && fill) /* TetGen's tets have no stored orientation to keep */
        rc = api_fail_at(p, 422, "invalid-complex", "/reoriented",
                         "\"reoriented\" describes a saved complex; it cannot go with \"fill\"");
    if (!rc && ro)
        rc = parse_reoriented(ro, packs, in, p);
    if (!rc && json_is_true(rp)) /* drops what the core would refuse one by one (api/repair.c) */
        rc = api_repair(in, p);
    uint32_t nv_posted = in->nv, ns_posted = in->ns;
    if (!rc && fill) /* TetGen: the tets and Steiner points are appended to `in` (api/fill.c) */
        rc = api_fill(fill, packs, in, lim, p);
    if (!rc && !in->nv)   /* the core's "no vertices" would point at /simplices */
        rc = api_fail_at(p, 422, "invalid-complex", "/vertices", "the complex has no vertices");
    api_rules keep = cur->rules; /* the preferences stay; overrides named the old simplices */
    keep.noverrides = 0;
    keep.overrides = NULL;
    if (!rc && (rc = api_build_model(in, &keep, NULL, lim, out, p)) && in->nfill)
        api_fill_blame(in, nv_posted, ns_posted, p);
    json_t *dt = json_object_get(body, "details");
    if (!rc && dt && (rc = api_details_put(*out, dt, p))) { /* offsets of the new complex */
        api_model_unref(*out);
        *out = NULL;
    }
    api_input_unref(in);
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
    json_t *sum = json_pack("{s:I, s:I, s:I, s:{s:I, s:I, s:I, s:I}, s:{s:I, s:I}, s:o, "
                            "s:{s:I, s:I}, s:o*}",
                     "vertices", (json_int_t)n.vertices, "edges", (json_int_t)n.edges, "faces",
                     (json_int_t)n.faces, "simplices", "0", (json_int_t)n.points, "1",
                     (json_int_t)n.curves, "2", (json_int_t)n.triangles, "3",
                     (json_int_t)n.tetrahedra, "boundary", "vertices", (json_int_t)bv, "edges",
                     (json_int_t)be, "nonmanifold", nm, "extraordinary", "vertices",
                     (json_int_t)xv, "edges", (json_int_t)xe, "fill", fill);
    api_repair_summary(m->in, sum);
    return sum;
}

json_t *api_json_doubles(const double *x, size_t n)
{
    json_t *a = json_array();
    for (size_t i = 0; i < n; i++)
        json_array_append_new(a, json_real(x[i]));
    return a;
}

/* The "tags" member of GET /complex: {"singular": [...]} and "petals" when there are any. */
json_t *api_tags_json(const api_model *m)
{
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
    json_t *tags = json_pack("{s:o}", "singular", tj);
    if (json_array_size(pj)) /* only when given: {"singular"} as PUT otherwise */
        json_object_set(tags, "petals", pj);
    json_decref(pj);
    if (m->tags.nsh) {
        json_t *sj = json_array();
        for (uint32_t i = 0; i < m->tags.nsh; i++) {
            const api_sharp *x = &m->tags.sh[i];
            json_t *sx = json_array();
            for (int j = 0; j < x->nverts; j++)
                json_array_append_new(sx, json_integer(x->v[j]));
            json_array_append_new(sj, json_pack("{s:o, s:f}", "simplex", sx, "value", x->value));
        }
        json_object_set_new(tags, "sharpness", sj);
    }
    api_tangents_json(&m->tags, tags);
    return tags;
}

/* The "tags" member of GET /complex: the tags and, when they came with one, what "crease_angle"
 * added (not in the export: its edges are among the singular tags, which is what an import
 * restores). */
static json_t *tags_report_json(const api_model *m)
{
    json_t *t = api_tags_json(m), *ca = api_crease_json(&m->tags);
    if (t && ca)
        json_object_set_new(t, "crease_angle", ca);
    else
        json_decref(ca);
    return t;
}

/* The "rules" member of GET /complex: the preferences and overrides as last put. */
json_t *api_rules_json(const api_model *m)
{
    static const char *const schemes[] = {"box", "averaged"}, *const weights[] = {"warren", "loop"};
    static const char *const nmd[] = {"G2", "G1"}, *const surfs[] = {"chang-qin", "ying-zorin"};
    static const char *const creases[] = {"uniform", "chaikin"};
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
    return json_pack("{s:s, s:o, s:s, s:s, s:s, s:s}", "nonmanifold_default",
                     nmd[m->rules.nonmanifold_default & 1], "overrides", oj, "solid_scheme",
                     schemes[m->rules.solid_scheme & 1], "surface_weights",
                     weights[m->rules.surface_weights & 1], "nonmanifold_surface",
                     surfs[m->rules.nonmanifold_surface & 1], "crease_method",
                     creases[m->rules.crease_method & 1]);
}

/* The complex as PUT takes it back (vertices, simplices, attributes, every diagonal, the
 * reoriented tetrahedra, the detail offsets), with the level-0 classes when asked (GET /complex).
 * Positions and details are read under the data lock edits take. */
static json_t *complex_json(api_model *m, bool classes)
{
    const api_input *in = m->in;
    pthread_rwlock_rdlock(&m->data);
    json_t *vs = json_array(), *ss = json_array(), *at = json_object();
    for (uint32_t i = 0; i < in->nv; i++)
        json_array_append_new(vs, api_json_doubles(in->xyz + 3 * (size_t)i, 3));
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
                                                      : api_json_doubles(t->data + (size_t)i * t->ncomp,
                                                                     t->ncomp));
        json_object_set_new(at, t->name, arr);
    }
    json_t *dj = json_array(), *rj = json_array();
    for (uint32_t s = 0; s < in->ns; s++)
        if (in->size[s] == 4) {
            json_array_append_new(dj, json_pack("[I, i]", (json_int_t)s, sd_complex_diagonal(m->c, s)));
            if (sd_complex_reoriented(m->c, s) == 1)
                json_array_append_new(rj, json_integer(s));
        }
    json_t *details = api_details_json(m); /* edits change them: under the lock */
    pthread_rwlock_unlock(&m->data);
    json_t *j = json_pack("{s:o, s:o, s:o, s:o, s:o}", "vertices", vs, "simplices", ss,
                          "attributes", at, "diagonals", dj, "reoriented", rj);
    if (j && classes) {
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
        json_object_set_new(j, "classes", json_pack("{s:o, s:o}", "vertices", cv, "edges", ce));
        json_object_set_new(j, "tags", tags_report_json(m));
        json_object_set_new(j, "rules", api_rules_json(m));
    }
    if (j)
        json_object_set_new(j, "details", details);
    else
        json_decref(details);
    if (j && classes)
        json_object_set(j, "summary", m->summary);
    return j;
}

json_t *api_get_complex(api_model *m, api_problem *p)
{
    if (!m->in) {
        api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
        return NULL;
    }
    return complex_json(m, true);
}

json_t *api_complex_json(api_model *m) { return m->in ? complex_json(m, false) : json_null(); }

api_cstream *api_get_complex_stream(api_model *m, uint64_t *version, api_problem *p)
{
    if (!m->in) {
        api_fail(p, 409, "no-complex", "no complex has been posted to this session yet");
        return NULL;
    }
    /* under the lock edits take: the copied points and attributes and the version agree */
    pthread_rwlock_rdlock(&m->data);
    *version = atomic_load(&m->version);
    json_t *t = json_pack("{s:o, s:o, s:o, s:O, s:I}", "tags", tags_report_json(m), "rules",
                          api_rules_json(m), "details", api_details_json(m), "summary", m->summary,
                          "version", (json_int_t)*version);
    char *text = t ? json_dumps(t, JSON_COMPACT) : NULL; /* {"tags":…,"version":N} */
    json_decref(t);
    api_cstream *s = NULL;
    if (text) {
        text[0] = ','; /* it continues the document after "classes" */
        s = api_cstream_new(m, text, strlen(text));
    }
    pthread_rwlock_unlock(&m->data);
    if (!s)
        api_fail(p, 503, "out-of-memory", "out of memory opening the complex's stream");
    return s;
}
