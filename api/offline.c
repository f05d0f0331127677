/* offline.c — a change applied from a file's text, as the offline modes (`subdivd refine`,
 * `subdivd deform`, subdivd-mpi) apply theirs: parsed as the daemon parses that handler's body
 * (the big arrays of a complex or of tags packed beside the tree), then the handler. */
#include "handlers.h"
#include "jsonin.h"
#include "packed.h"

int api_apply_text(const api_model *cur, change_fn_t fn, char *buf, size_t len, json_t *body,
                   json_t *extra, const api_limits *lim, api_model **out, api_problem *p)
{
    api_packs packs = {0};
    const char *const *packed = fn == api_put_complex ? api_complex_packed
                                : fn == api_put_tags  ? api_tags_packed
                                                      : NULL;
    json_t *b = body     ? body
                : !buf   ? json_object()
                : packed ? api_parse_body_packed(buf, len, 0, packed, API_PACK_MIN_BYTES, &packs, p)
                         : api_parse_body(buf, len, 0, p);
    *out = NULL;
    if (b && extra && json_is_object(b))
        json_object_update(b, extra);
    if (b && fn == api_put_complex)
        api_put_complex_packed(cur, b, &packs, lim, out, p);
    else if (b && fn == api_put_tags)
        api_put_tags_packed(cur, b, &packs, lim, out, p);
    else if (b)
        fn(cur, b, lim, out, p);
    json_decref(b);
    api_packs_free(&packs);
    return *out ? 0 : p->status ? p->status : 500;
}
