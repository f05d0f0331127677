/* jsonin.c — parsing request bodies with jansson and checked field access (see jsonin.h).
 *
 * A body is an object without duplicate keys, nested at most API_MAX_JSON_DEPTH deep (checked
 * after jansson's parse, which allows 2048); everything else is the getters' business, each of
 * which fills the problem with the pointer of the field it refused. Nothing here allocates but
 * jansson, whose allocations go through api/mem.h: a parse during which one was refused is a 503,
 * never a 400, and never a document (jansson's lexer drops what it cannot store).
 */
#include "jsonin.h"
#include "limits.h"
#include "mem.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Depth of nesting, stopping as soon as it passes `max` (jansson itself allows 2048). */
static int too_deep(json_t *v, int depth, int max)
{
    if (depth > max)
        return 1;
    if (json_is_array(v)) {
        size_t i;
        json_t *x;
        json_array_foreach(v, i, x) if ((json_is_array(x) || json_is_object(x)) &&
                                        too_deep(x, depth + 1, max)) return 1;
    } else if (json_is_object(v)) {
        const char *k;
        json_t *x;
        json_object_foreach(v, k, x) if ((json_is_array(x) || json_is_object(x)) &&
                                         too_deep(x, depth + 1, max)) return 1;
    }
    return 0;
}

json_t *api_parse_body(const char *buf, size_t len, int empty_ok, api_problem *p)
{
    size_t i = 0;
    while (i < len && (buf[i] == ' ' || buf[i] == '\n' || buf[i] == '\r' || buf[i] == '\t'))
        i++;
    if (i == len) {
        if (empty_ok)
            return json_object();
        api_fail(p, 400, "malformed-json", "the request needs a JSON object body");
        return NULL;
    }
    json_error_t e;
    uint64_t refused = api_mem_refused_here();
    json_t *j = json_loadb(buf, len, JSON_REJECT_DUPLICATES, &e);
    /* jansson reports a failed allocation as whatever it was parsing then, and its lexer drops
     * the character it could not store and goes on: a document parsed while an allocation was
     * refused is not the one that was sent, even when json_loadb returns one */
    if (api_mem_refused_here() != refused) {
        json_decref(j);
        api_fail(p, 503, "out-of-memory", "out of memory reading the body; retry later");
        return NULL;
    }
    if (!j) {
        const char *what = json_error_code(&e) == json_error_numeric_overflow ? "number too large"
                           : json_error_code(&e) == json_error_duplicate_key ? "duplicate key"
                                                                              : "malformed JSON";
        api_fail(p, 400, "malformed-json", "%s at line %d, column %d: %s", what, e.line, e.column,
                 e.text);
        return NULL;
    }
    if (!json_is_object(j)) {
        json_decref(j);
        api_fail_at(p, 400, "wrong-type", "", "the body must be a JSON object");
        return NULL;
    }
    if (too_deep(j, 1, API_MAX_JSON_DEPTH)) {
        json_decref(j);
        api_fail(p, 400, "malformed-json", "the document nests deeper than %d levels",
                 API_MAX_JSON_DEPTH);
        return NULL;
    }
    return j;
}

json_t *api_parse_body_packed(char *buf, size_t len, int empty_ok, const char *const *patterns,
                              size_t min_bytes, api_packs *packs, api_problem *p)
{
    if (api_pack_body(buf, len, patterns, min_bytes, API_MAX_JSON_DEPTH, packs)) {
        api_fail(p, 503, "out-of-memory", "out of memory reading the body; retry later");
        return NULL;
    }
    json_t *j = api_parse_body(buf, len, empty_ok, p);
    if (!j)
        api_packs_free(packs);
    return j;
}

int api_only_keys(json_t *obj, const char *ptr, const char *const *allowed, api_problem *p)
{
    const char *k;
    json_t *v;
    json_object_foreach(obj, k, v) {
        int ok = 0;
        for (const char *const *a = allowed; *a && !ok; a++)
            ok = !strcmp(*a, k);
        if (!ok) {
            char at[96], list[200] = "";
            api_ptr_key(at, sizeof at, ptr, k);
            for (const char *const *a = allowed; *a; a++)
                snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s",
                         a == allowed ? "" : ", ", *a);
            return api_fail_at(p, 400, "unknown-field", at, "unknown field \"%.40s\" (allowed: %s)",
                               k, list);
        }
    }
    return 0;
}

static const char *type_name(json_t *v)
{
    switch (json_typeof(v)) {
    case JSON_OBJECT: return "an object";
    case JSON_ARRAY: return "an array";
    case JSON_STRING: return "a string";
    case JSON_INTEGER: return "an integer";
    case JSON_REAL: return "a number";
    case JSON_TRUE:
    case JSON_FALSE: return "a boolean";
    default: return "null";
    }
}

int api_get_enum(json_t *v, const char *ptr, const char *const *names, api_problem *p)
{
    char list[200] = "";
    for (const char *const *a = names; *a; a++)
        snprintf(list + strlen(list), sizeof list - strlen(list), "%s\"%s\"",
                 a == names ? "" : ", ", *a);
    if (!json_is_string(v)) {
        api_fail_at(p, 400, "wrong-type", ptr, "must be a string, one of %s, not %s", list,
                    type_name(v));
        return -1;
    }
    const char *s = json_string_value(v);
    for (int i = 0; names[i]; i++)
        if (!strcmp(names[i], s))
            return i;
    api_fail_at(p, 422, "unknown-value", ptr, "\"%.40s\" is not one of %s", s, list);
    return -1;
}

int api_num_is_number(api_num v) { return v.packed || json_is_number(v.json); }

int api_num_is_integer(api_num v) { return v.packed ? v.isint : json_is_integer(v.json); }

double api_num_value(api_num v) { return v.packed ? v.x : json_number_value(v.json); }

/* A packed integer is at most 2^53 in magnitude (packed.h): the double holds it exactly. */
long long api_num_integer(api_num v) { return v.packed ? (long long)v.x : json_integer_value(v.json); }

static const char *num_type_name(api_num v)
{
    if (v.packed)
        return v.isint ? "an integer" : "a number";
    return v.json ? type_name(v.json) : "missing";
}

int api_num_get_int(api_num v, const char *ptr, long long lo, long long hi, long long *out,
                    api_problem *p)
{
    if (!api_num_is_integer(v))
        return api_fail_at(p, 400, "wrong-type", ptr, "must be an integer, not %s",
                           num_type_name(v));
    long long x = api_num_integer(v);
    if (x < lo || x > hi)
        return api_fail_at(p, 422, "out-of-range", ptr, "%lld is outside %lld..%lld", x, lo, hi);
    *out = x;
    return 0;
}

int api_num_get_number(api_num v, const char *ptr, double maxabs, double *out, api_problem *p)
{
    if (!api_num_is_number(v))
        return api_fail_at(p, 400, "wrong-type", ptr, "must be a number, not %s",
                           num_type_name(v));
    double x = api_num_value(v);
    if (!isfinite(x) || fabs(x) > maxabs) {
        char t[32];
        return api_fail_at(p, 422, "out-of-range", ptr, "%s exceeds the allowed magnitude %g",
                           sd_shortest(x, t), maxabs);
    }
    *out = x;
    return 0;
}

int api_get_int(json_t *v, const char *ptr, long long lo, long long hi, long long *out,
                api_problem *p)
{
    return api_num_get_int(api_num_json(v), ptr, lo, hi, out, p);
}

int api_get_number(json_t *v, const char *ptr, double maxabs, double *out, api_problem *p)
{
    return api_num_get_number(api_num_json(v), ptr, maxabs, out, p);
}

void api_ptr_index(char *dst, size_t cap, const char *base, size_t i)
{
    /* what snprintf(dst, cap, "%s/%zu", base, i) writes, without a formatted print: the readers
     * of big arrays name every element they look at */
    if (!cap)
        return;
    char digits[24];
    int nd = 0;
    do
        digits[nd++] = (char)('0' + i % 10);
    while ((i /= 10) != 0);
    size_t n = 0;
    for (; *base && n + 1 < cap; base++)
        dst[n++] = *base;
    if (n + 1 < cap)
        dst[n++] = '/';
    while (nd && n + 1 < cap)
        dst[n++] = digits[--nd];
    dst[n] = 0;
}

void api_ptr_key(char *dst, size_t cap, const char *base, const char *key)
{
    size_t n = (size_t)snprintf(dst, cap, "%s/", base);
    for (const char *k = key; *k && n + 3 < cap; k++) {
        if (*k == '~' || *k == '/') {
            dst[n++] = '~';
            dst[n++] = *k == '~' ? '0' : '1';
        } else
            dst[n++] = *k;
    }
    if (n < cap)
        dst[n] = 0;
}
