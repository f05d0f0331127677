/* export.c — a session as one document, and a session from one (docs/API.md "Persistence and
 * sessions"): GET /export, POST /v1/sessions {"import": …}, and the snapshots of the durable
 * store (server/persist.h), which are the same documents.
 *
 * The document holds the control data only — the complex as PUT /complex takes it back (every
 * tetrahedron's diagonal and stored orientation, so the levels come out numbered as before), the
 * detail offsets, the tags, the rules — and the version. Levels are not in it: they are rebuilt,
 * and are bit-identical, because every input of the build is in the document exactly (reals as
 * jansson writes them, "%.17g", which reads back to the same double) and edits recompute
 * (DECISIONS 17). Importing replays the changes a client would make — rules (preferences),
 * complex (with its details), rules (overrides, which name simplices), tags — through the same
 * handlers, so an import is checked like those requests, and a problem points into the
 * document ("/import/complex/vertices/3").
 */
#include "embedded.h"
#include "handlers.h"
#include "internal.h"
#include "jsonin.h"
#include "mem.h"
#include <stdio.h>
#include <string.h>

#define EXPORT_FORMAT "subdivd-session"
#define EXPORT_FORMAT_VERSION 1

json_t *api_export(api_model *m, uint64_t version)
{
    json_t *cx = api_complex_json(m), *tags = api_tags_json(m), *rules = api_rules_json(m);
    json_t *j = json_pack("{s:s, s:i, s:I, s:o*, s:o*, s:o*, s:o*}", "format", EXPORT_FORMAT,
                          "format_version", EXPORT_FORMAT_VERSION, "version", (json_int_t)version,
                          "complex", cx, "tags", tags, "rules", rules, "embedded",
                          api_embed_export(m));
    return j;
}

/* Prefix every pointer of a problem with `base` (the import's place in the body). */
static int rebase(api_problem *p, const char *base)
{
    for (int i = 0; i < p->nerrors; i++) {
        char tmp[sizeof p->errors[i].pointer];
        snprintf(tmp, sizeof tmp, "%s%s", base, p->errors[i].pointer);
        memcpy(p->errors[i].pointer, tmp, sizeof tmp);
    }
    return p->status;
}

/* One step of the import: next = fn(*cur, body), *cur replaced. */
static int step(change_fn_t fn, api_model **cur, json_t *body, const api_limits *lim,
                const char *base, api_problem *p)
{
    api_model *next = NULL;
    if (fn(*cur, body, lim, &next, p))
        return rebase(p, base);
    api_model_unref(*cur);
    *cur = next;
    return 0;
}

static bool tags_empty(json_t *t)
{
    json_t *s = json_object_get(t, "singular"), *pe = json_object_get(t, "petals");
    json_t *sh = json_object_get(t, "sharpness");
    static const char *const more[] = {"normals", "tangents", "tangent_edges"};
    for (int i = 0; i < 3; i++) {
        json_t *x = json_object_get(t, more[i]);
        if (x && (!json_is_array(x) || json_array_size(x)))
            return false;
    }
    return json_array_size(s) == 0 && json_array_size(pe) == 0 && json_array_size(sh) == 0 &&
           (!s || json_is_array(s)) && (!pe || json_is_array(pe)) && (!sh || json_is_array(sh));
}

int api_import(json_t *doc, const char *base, const api_limits *lim, long long max_version,
               api_model **out, uint64_t *version, api_problem *p)
{
    static const char *const keys[] = {"format", "format_version", "version", "complex", "tags",
                                       "rules", "embedded", NULL};
    char at[128];
    *out = NULL;
    if (!json_is_object(doc))
        return api_fail_at(p, 400, "wrong-type", base, "must be a document of GET /export");
    if (api_only_keys(doc, base, keys, p))
        return p->status;
    json_t *f = json_object_get(doc, "format"), *fv = json_object_get(doc, "format_version");
    snprintf(at, sizeof at, "%s/format", base);
    if (!json_is_string(f) || strcmp(json_string_value(f), EXPORT_FORMAT))
        return api_fail_at(p, 422, "unknown-value", at, "must be \"" EXPORT_FORMAT "\"");
    snprintf(at, sizeof at, "%s/format_version", base);
    if (!json_is_integer(fv) || json_integer_value(fv) != EXPORT_FORMAT_VERSION)
        return api_fail_at(p, 422, "unknown-value", at,
                           "this daemon reads format_version %d", EXPORT_FORMAT_VERSION);
    long long v = 0;
    json_t *vj = json_object_get(doc, "version");
    snprintf(at, sizeof at, "%s/version", base);
    if (!vj)
        return api_fail_at(p, 400, "missing-field", at, "\"version\" is required");
    if (api_get_int(vj, at, 0, max_version, &v, p))
        return p->status;
    json_t *emb = json_object_get(doc, "embedded");
    snprintf(at, sizeof at, "%s/embedded", base);
    if (emb && !json_is_object(emb))
        return api_fail_at(p, 400, "wrong-type", at, "must be an object: name -> model");
    json_t *cx = json_object_get(doc, "complex"), *tags = json_object_get(doc, "tags");
    json_t *rules = json_object_get(doc, "rules");
    if (rules && !json_is_object(rules)) {
        snprintf(at, sizeof at, "%s/rules", base);
        return api_fail_at(p, 400, "wrong-type", at, "must be the body of PUT /rules");
    }
    if (tags && !json_is_object(tags)) {
        snprintf(at, sizeof at, "%s/tags", base);
        return api_fail_at(p, 400, "wrong-type", at, "must be the body of PUT /tags");
    }
    if (cx && !json_is_null(cx) && !json_is_object(cx)) {
        snprintf(at, sizeof at, "%s/complex", base);
        return api_fail_at(p, 400, "wrong-type", at, "must be the body of PUT /complex, or null");
    }
    sd_error e;
    api_model *m = api_model_new(NULL, NULL, 0, false, &e);
    if (!m)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    int rc = 0;
    json_t *ov = rules ? json_object_get(rules, "overrides") : NULL;
    if (ov && !json_is_array(ov)) {
        snprintf(at, sizeof at, "%s/rules/overrides", base);
        api_model_unref(m);
        return api_fail_at(p, 400, "wrong-type", at, "must be an array of overrides");
    }
    if (rules) { /* the preferences first: PUT /complex keeps them */
        json_t *pref = json_copy(rules);
        if (!pref)
            rc = api_fail(p, 503, "out-of-memory", "out of memory");
        else {
            json_object_del(pref, "overrides");
            snprintf(at, sizeof at, "%s/rules", base);
            rc = step(api_put_rules, &m, pref, lim, at, p);
            json_decref(pref);
        }
    }
    if (!rc && cx && !json_is_null(cx)) {
        snprintf(at, sizeof at, "%s/complex", base);
        rc = step(api_put_complex, &m, cx, lim, at, p);
    }
    if (!rc && ov && json_array_size(ov)) {
        snprintf(at, sizeof at, "%s/rules", base);
        rc = step(api_put_rules, &m, rules, lim, at, p);
    }
    if (!rc && tags && !tags_empty(tags)) {
        snprintf(at, sizeof at, "%s/tags", base);
        rc = step(api_import_tags, &m, tags, lim, at, p);
    }
    if (!rc && emb && json_object_size(emb)) { /* bound to the imported levels */
        atomic_store(&m->version, (uint64_t)v);
        snprintf(at, sizeof at, "%s/embedded", base);
        rc = api_embed_import(m, emb, at, lim, p);
    }
    if (rc) {
        api_model_unref(m);
        return rc;
    }
    *out = m;
    *version = (uint64_t)v;
    return 0;
}
