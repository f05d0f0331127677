/* rows.c — rows of the big arrays of a body from the tree or packed (see rows.h).
 *
 * A packed array stores its rows' lengths and all values in order, so rows are read in order
 * with a running offset (api_rows_next); nothing here allocates.
 */
#include "rows.h"

bool api_rows_open(api_rows *rs, json_t *v, const api_packs *packs, const char *ptr)
{
    *rs = (api_rows){0};
    rs->pk = packs ? api_packed_find(packs, ptr) : NULL;
    if (rs->pk) {
        rs->n = rs->pk->nrows;
        return true;
    }
    if (!json_is_array(v))
        return false;
    rs->arr = v;
    rs->n = json_array_size(v);
    return true;
}

void api_rows_rewind(api_rows *rs)
{
    rs->next = 0;
    rs->at = 0;
}

bool api_rows_next(api_rows *rs, api_row *row)
{
    if (rs->next >= rs->n)
        return false;
    *row = (api_row){0};
    if (rs->pk) {
        row->pk = rs->pk;
        row->first = rs->at;
        row->len = rs->pk->len[rs->next];
        rs->at += row->len == API_PACKED_BARE ? 1 : row->len;
    } else
        row->json = json_array_get(rs->arr, rs->next);
    rs->next++;
    return true;
}

bool api_row_is_array(const api_row *r)
{
    return r->pk ? r->len != API_PACKED_BARE : json_is_array(r->json);
}

size_t api_row_size(const api_row *r)
{
    return r->pk ? (r->len == API_PACKED_BARE ? 0 : r->len) : json_array_size(r->json);
}

static api_num packed_num(const api_packed *pk, size_t i)
{
    api_num n = {NULL, 1, pk->val[i], api_packed_isint(pk, i)};
    return n;
}

api_num api_row_get(const api_row *r, size_t k)
{
    return r->pk ? packed_num(r->pk, r->first + k) : api_num_json(json_array_get(r->json, k));
}

api_num api_row_value(const api_row *r)
{
    return r->pk ? packed_num(r->pk, r->first) : api_num_json(r->json);
}
