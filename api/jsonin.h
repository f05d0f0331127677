/* jsonin.h — reading untrusted JSON request bodies into checked values.
 *
 * Every getter either returns the value or fills an api_problem naming the JSON pointer of the
 * offending field (400 for malformed JSON, wrong types, unknown or missing fields; 422 for
 * values outside their domain). Nothing here allocates beyond jansson's own parse.
 */
#ifndef SUBDIVD_JSONIN_H
#define SUBDIVD_JSONIN_H

#include "problem.h"
#include <jansson.h>
#include <stddef.h>

/* Parse a request body: an object, no duplicate keys, nesting at most API_MAX_JSON_DEPTH.
 * An empty body is read as {} when `empty_ok`. New reference or NULL + problem (400). */
json_t *api_parse_body(const char *buf, size_t len, int empty_ok, api_problem *p);

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

/* Append a decimal index or a key (escaped per RFC 6901) to a JSON pointer buffer. */
void api_ptr_index(char *dst, size_t cap, const char *base, size_t i);
void api_ptr_key(char *dst, size_t cap, const char *base, const char *key);

#endif
