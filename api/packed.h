/* packed.h — the big numeric arrays of a request body, read without a JSON tree.
 *
 * A PUT /complex body is mostly numbers: "vertices" [[x, y, z], …], "simplices" [[i, j, k, l], …]
 * and per-vertex "attributes". Parsed into a jansson tree every number costs a json_t and every
 * row an array (about 28 times the text); packed they cost 8 bytes a number and 1 a row.
 *
 * api_pack_body() scans a body once, finds the arrays at the JSON pointers a route names (a
 * pattern segment "*" matches any key or index) whose elements are all numbers or all arrays of
 * numbers, parses them into api_packed arrays and overwrites their text in the body with "[]"
 * and blanks (newlines kept), so jansson then parses a document of the same length, lines and
 * columns in which those arrays are empty. Handlers ask for the packed array of a pointer
 * (api_packed_find) before reading the tree's (empty) one. Anything the scanner is not sure of —
 * a syntax error, a string in the array, deeper nesting, an integer beyond 2^53, a real that
 * overflows, a key with escapes — is left in the text for jansson, whose errors stay as they
 * were: packing changes memory use, never an answer.
 */
#ifndef SUBDIVD_PACKED_H
#define SUBDIVD_PACKED_H

#include <stddef.h>
#include <stdint.h>

#define API_PACKED_BARE 0xFF   /* a row that is a bare number, not an array */
#define API_PACKED_MAX_ROW 254 /* longer rows are left to jansson */

typedef struct api_packed {
    char ptr[128];       /* JSON pointer of the array (RFC 6901 escaped), e.g. "/vertices" */
    size_t nrows;
    uint8_t *len;        /* per row: its number of values, or API_PACKED_BARE */
    size_t nval;
    double *val;         /* every value, row after row */
    uint8_t *isint;      /* bit i: value i was written as an integer (no fraction, no exponent) */
} api_packed;

typedef struct api_packs {
    int n;
    api_packed a[16];
} api_packs;

/* Scan body[0..len) (modified in place as described above) for the arrays at `patterns`
 * (NULL-terminated JSON pointers; "*" segments) whose text is at least `min_bytes` long, at a
 * nesting depth of at most `max_depth` for their rows. Fills *out (caller-owned; free with
 * api_packs_free; the arrays are counted api/mem.h blocks).
 * Returns 0, or -1 when memory ran out: out is then empty and the body, partly
 * blanked, is unusable (answer 503). At most 16 arrays are packed; further ones are left to
 * jansson. */
int api_pack_body(char *body, size_t len, const char *const *patterns, size_t min_bytes,
                  int max_depth, api_packs *out);
void api_packs_free(api_packs *p);

/* The packed array at JSON pointer `ptr`, or NULL. */
const api_packed *api_packed_find(const api_packs *p, const char *ptr);

static inline int api_packed_isint(const api_packed *a, size_t i)
{
    return (a->isint[i >> 3] >> (i & 7)) & 1;
}

#endif
