/* packed_parse — PUT /complex (or, with the argument "tags", PUT /tags on a fixed complex) read
 * packed against read from the tree, differentially.
 *
 * Reads request bodies from stdin, one per line (each a JSON string). Each is given to the
 * handler twice: parsed by jansson as it is, and parsed with its big arrays packed
 * (api_parse_body_packed with every array packed, however small: min_bytes 1). Both must give
 * the same status, slug, detail and field errors, or both a model with the same input arrays,
 * tags and summary. Prints "packed_parse: N bodies, P packed arrays, D differ" and exits 1 on
 * any difference (tests/python/test_packed_parse.py feeds it the error catalogue and mutations).
 */
#include "../../api/handlers.h"
#include "../../api/jsonin.h"
#include "../../api/mem.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct outcome {
    api_problem p;
    api_model *m;
    char *summary;
} outcome;

static int tags_mode;

static void run(const char *body, size_t len, int packed, const api_model *cur,
                const api_limits *lim, outcome *o, int *npacked)
{
    memset(o, 0, sizeof *o);
    char *buf = api_malloc(len + 1);
    memcpy(buf, body, len);
    buf[len] = 0;
    api_packs packs = {0};
    const char *const *pat = tags_mode ? api_tags_packed : api_complex_packed;
    json_t *b = packed ? api_parse_body_packed(buf, len, 0, pat, 1, &packs, &o->p)
                       : api_parse_body(buf, len, 0, &o->p);
    api_free(buf);
    *npacked += packs.n;
    const api_packs *pk = packed ? &packs : NULL;
    if (b && !(tags_mode ? api_put_tags_packed(cur, b, pk, lim, &o->m, &o->p)
                         : api_put_complex_packed(cur, b, pk, lim, &o->m, &o->p)))
        o->summary = json_dumps(o->m->summary, JSON_SORT_KEYS | JSON_COMPACT);
    json_decref(b);
    api_packs_free(&packs);
}

static int same_input(const api_input *a, const api_input *b)
{
    if (a->nv != b->nv || a->ns != b->ns || a->nattrs != b->nattrs || a->ndiag != b->ndiag)
        return 0;
    size_t nidx = 0;
    for (uint32_t s = 0; s < a->ns; s++)
        nidx += a->size[s];
    if (memcmp(a->xyz, b->xyz, 3 * sizeof(double) * a->nv) || memcmp(a->size, b->size, a->ns) ||
        memcmp(a->idx, b->idx, nidx * sizeof *a->idx) ||
        (a->ndiag && memcmp(a->diag, b->diag, a->ndiag * sizeof *a->diag)))
        return 0;
    for (int t = 0; t < a->nattrs; t++)
        if (strcmp(a->attrs[t].name, b->attrs[t].name) || a->attrs[t].ncomp != b->attrs[t].ncomp ||
            a->attrs[t].scalar_form != b->attrs[t].scalar_form ||
            memcmp(a->attrs[t].data, b->attrs[t].data,
                   sizeof(double) * a->attrs[t].ncomp * a->nv))
            return 0;
    return 1;
}

static int same(const outcome *a, const outcome *b)
{
    if (!!a->m != !!b->m)
        return 0;
    if (a->m) {
        const api_tags *x = &a->m->tags, *y = &b->m->tags;
        size_t nidx = 0;
        for (uint32_t i = 0; i < x->n; i++)
            nidx += x->size[i];
        return !strcmp(a->summary, b->summary) && same_input(a->m->in, b->m->in) &&
               x->n == y->n && (!x->n || !memcmp(x->size, y->size, x->n)) &&
               (!nidx || !memcmp(x->idx, y->idx, nidx * sizeof *x->idx));
    }
    if (a->p.status != b->p.status || strcmp(a->p.slug, b->p.slug) ||
        strcmp(a->p.detail, b->p.detail) || a->p.nerrors != b->p.nerrors)
        return 0;
    for (int i = 0; i < a->p.nerrors; i++)
        if (strcmp(a->p.errors[i].pointer, b->p.errors[i].pointer) ||
            strcmp(a->p.errors[i].message, b->p.errors[i].message))
            return 0;
    return 1;
}

static void done(outcome *o)
{
    api_model_unref(o->m);
    api_free(o->summary);
}

/* The complex PUT /tags bodies name: a fan of triangles, a tetrahedron on one of them, a curve. */
static const char FAN[] =
    "{\"vertices\": [[0,0,0],[1,0,0],[0.5,0.9,0],[-0.5,0.9,0],[-1,0,0],[-0.5,-0.9,0],"
    "[0.5,-0.9,0],[0.3,0.3,1],[2,0,0],[3,0.2,0]],"
    "\"simplices\": [[0,1,2],[0,2,3],[0,3,4],[0,4,5],[0,5,6],[0,6,1],[0,1,2,7],[1,8],[8,9]]}";

int main(int argc, char **argv)
{
    api_limits lim = api_default_limits();
    lim.max_vertices = 100000;
    lim.max_simplices = 100000;
    sd_error e;
    api_model *cur = api_model_new(NULL, NULL, 0, false, &e);
    tags_mode = argc > 1 && !strcmp(argv[1], "tags");
    if (tags_mode) {
        api_problem p = {0};
        json_t *b = api_parse_body(FAN, strlen(FAN), 0, &p);
        api_model *m = NULL;
        if (!b || api_put_complex(cur, b, &lim, &m, &p)) {
            fprintf(stderr, "packed_parse: the tags' complex was refused: %s\n", p.detail);
            return 2;
        }
        json_decref(b);
        api_model_unref(cur);
        cur = m;
    }
    size_t cap = 0;
    char *line = NULL;
    ssize_t n;
    long bodies = 0, differ = 0;
    int npacked = 0;
    while ((n = getline(&line, &cap, stdin)) > 0) {
        if (line[n - 1] == '\n')
            line[--n] = 0;
        json_error_t je;
        json_t *s = json_loads(line, JSON_DECODE_ANY, &je); /* the body, as a JSON string */
        if (!json_is_string(s)) {
            fprintf(stderr, "packed_parse: line %ld is not a JSON string\n", bodies + 1);
            return 2;
        }
        outcome a, b;
        int ignored = 0;
        run(json_string_value(s), json_string_length(s), 0, cur, &lim, &a, &ignored);
        run(json_string_value(s), json_string_length(s), 1, cur, &lim, &b, &npacked);
        if (!same(&a, &b)) {
            differ++;
            printf("differ: %.200s\n  tree:   %d %s %s %s\n  packed: %d %s %s %s\n",
                   json_string_value(s), a.p.status, a.p.slug ? a.p.slug : "", a.p.detail,
                   a.p.nerrors ? a.p.errors[0].pointer : "", b.p.status, b.p.slug ? b.p.slug : "",
                   b.p.detail, b.p.nerrors ? b.p.errors[0].pointer : "");
        }
        done(&a);
        done(&b);
        json_decref(s);
        bodies++;
    }
    free(line);
    api_model_unref(cur);
    printf("packed_parse: %ld bodies, %d packed arrays, %ld differ\n", bodies, npacked, differ);
    return differ ? 1 : 0;
}
