/* rows.h — the big arrays of a body, row by row, from the jansson tree or packed (rows.c).
 *
 * "vertices", "simplices", "attributes/<name>", "diagonals" and the fill surfaces are arrays of
 * rows, each a number or an array of numbers. A large body has them packed (api/packed.h: the
 * tree's copy of the array is then empty) and a small one has them in the tree; a parser reads
 * either through this one interface, and the values through the api_num getters of jsonin.h, so
 * it has one body and gives the same answers and the same problems from both.
 */
#ifndef SUBDIVD_ROWS_H
#define SUBDIVD_ROWS_H

#include "jsonin.h"
#include "packed.h"
#include <stdbool.h>
#include <stddef.h>

typedef struct api_rows {
    json_t *arr;              /* from the tree (NULL when packed) */
    const api_packed *pk;     /* packed (NULL when from the tree) */
    size_t n;                 /* rows */
    size_t next, at;          /* the next row and, packed, its first value */
} api_rows;

/* One row: an element of the tree's array, or a packed row. */
typedef struct api_row {
    json_t *json;
    const api_packed *pk;
    size_t first;             /* packed: index of its first value */
    unsigned len;             /* packed: its length, or API_PACKED_BARE */
} api_row;

/* The rows of the array at JSON pointer `ptr`, whose value in the tree is `v`: the packed array
 * when `packs` (may be NULL) holds one there, else v's elements. false when there is neither
 * (v is not an array). Borrows v and packs. */
bool api_rows_open(api_rows *rs, json_t *v, const api_packs *packs, const char *ptr);
static inline size_t api_rows_count(const api_rows *rs) { return rs->n; }
/* The next row, in order (*row borrowed); false after the last. */
bool api_rows_next(api_rows *rs, api_row *row);
/* Back to the first row. */
void api_rows_rewind(api_rows *rs);

/* Whether a row is an array (else a single value, api_row_value) and its length. */
bool api_row_is_array(const api_row *r);
size_t api_row_size(const api_row *r);
/* Element k < api_row_size of an array row. */
api_num api_row_get(const api_row *r, size_t k);
/* A row that is not an array, as a value. */
api_num api_row_value(const api_row *r);

#endif
