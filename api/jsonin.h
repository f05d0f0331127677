/* jsonin.h — reading untrusted JSON request bodies into checked values.
 *
 * Every getter either returns the value or fills an api_problem naming the JSON pointer of the
 * offending field (400 for malformed JSON, wrong types, unknown or missing fields; 422 for
 * values outside their domain). Nothing here allocates beyond jansson's own parse.
 */
#ifndef SUBDIVD_JSONIN_H
#define SUBDIVD_JSONIN_H

#include "packed.h"
#include "problem.h"
#include <jansson.h>
#include <stddef.h>

/* Parse a request body: an object, no duplicate keys, nesting at most API_MAX_JSON_DEPTH.
 * An empty body is read as {} when `empty_ok`. New reference or NULL + problem (400). */
json_t *api_parse_body(const char *buf, size_t len, int empty_ok, api_problem *p);

/* The same for a body with big numeric arrays: the arrays at `patterns` (api/packed.h) of at
 * least `min_bytes` of text are packed into *packs (caller-owned, free with api_packs_free; empty
 * on failure) and blanked in `buf` before jansson parses it, so the tree holds them as [] and the
 * parse costs a small multiple of the body (rows.h reads them either way). 503 when packing runs
 * out of memory. */
json_t *api_parse_body_packed(char *buf, size_t len, int empty_ok, const char *const *patterns,
                              size_t min_bytes, api_packs *packs, api_problem *p);

/* Refuse members of `obj` not in the NULL-terminated `allowed` list (400 unknown-field). */
int api_only_keys(json_t *obj, const char *ptr, const char *const *allowed, api_problem *p);

/* Enum: returns the index of the string value in `names` (NULL-terminated), or -1 with a
 * problem (400 wrong type, 422 unknown value listing the allowed ones). */
int api_get_enum(json_t *v, const char *ptr, const char *const *names, api_problem *p);

/* Integer in [lo, hi]: 0 on success. */
int api_get_int(json_t *v, const char *ptr, long long lo, long long hi, long long *out,
                api_problem *p);
/* A JSON number as double (integers included); rejects magnitudes above `maxabs`. */
int api_get_number(json_t *v, const char *ptr, double maxabs, double *out, api_problem *p);

/* One value of a body as the getters read it: a value of the jansson tree, or a number of a
 * packed array (api/packed.h, api/rows.h), which is what jansson would have made of the same
 * text (an integer literal an integer, any other number a real). The api_num_* getters give
 * the same answers and problems for both. */
typedef struct api_num {
    json_t *json;   /* the tree's value (not packed) */
    int packed;     /* a packed number: */
    double x;       /*   its value */
    int isint;      /*   written as an integer */
} api_num;

static inline api_num api_num_json(json_t *v)
{
    api_num n = {v, 0, 0, 0};
    return n;
}
int api_num_is_number(api_num v);
int api_num_is_integer(api_num v);
double api_num_value(api_num v);    /* json_number_value's reading; 0 for a non-number */
long long api_num_integer(api_num v); /* the value of an integer (api_num_is_integer) */
int api_num_get_int(api_num v, const char *ptr, long long lo, long long hi, long long *out,
                    api_problem *p);
int api_num_get_number(api_num v, const char *ptr, double maxabs, double *out, api_problem *p);

/* Append a decimal index or a key (escaped per RFC 6901) to a JSON pointer buffer. */
void api_ptr_index(char *dst, size_t cap, const char *base, size_t i);
void api_ptr_key(char *dst, size_t cap, const char *base, const char *key);

#endif
