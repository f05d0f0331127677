/* fuzz_packed — api/packed.c against jansson, differentially.
 *
 * For every input: jansson parses the body as it is (tree A, or an error); the body is packed
 * (api_pack_body, patterns "/vertices", "/simplices", "/attributes/ *", "/fill/ * /surface") and
 * jansson parses the blanked text (tree B, or an error). The packed arrays are put back into B
 * as jansson would have built them (integer literals as integers, others as reals), and B must
 * then equal A bit for bit — the same types, the same doubles (-0.0 apart from +0.0), the same
 * order — or both must fail with the same error (line, column, position, text). Any difference
 * aborts.
 *
 * Built two ways: with clang's libFuzzer (-DSD_LIBFUZZER, `make fuzz`) and as a plain program
 * (gcc, `make test`) that runs the seeds below and N deterministic mutations of them:
 *     fuzz_packed [ITERATIONS [SEED]] | --write-seeds DIR
 */
#include "../../api/packed.h"
#include "plain.h"
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const patterns[] = {"/vertices", "/simplices", "/attributes/*",
                                       "/fill/*/surface", NULL};

static int same(json_t *a, json_t *b)
{
    if (json_typeof(a) != json_typeof(b))
        return 0;
    switch (json_typeof(a)) {
    case JSON_OBJECT: {
        if (json_object_size(a) != json_object_size(b))
            return 0;
        const char *k;
        json_t *v;
        json_object_foreach(a, k, v) {
            json_t *w = json_object_get(b, k);
            if (!w || !same(v, w))
                return 0;
        }
        return 1;
    }
    case JSON_ARRAY:
        if (json_array_size(a) != json_array_size(b))
            return 0;
        for (size_t i = 0; i < json_array_size(a); i++)
            if (!same(json_array_get(a, i), json_array_get(b, i)))
                return 0;
        return 1;
    case JSON_INTEGER:
        return json_integer_value(a) == json_integer_value(b);
    case JSON_REAL: {
        double x = json_real_value(a), y = json_real_value(b);
        return !memcmp(&x, &y, sizeof x);
    }
    case JSON_STRING:
        return json_string_length(a) == json_string_length(b) &&
               !memcmp(json_string_value(a), json_string_value(b), json_string_length(a));
    default:
        return 1;
    }
}

static json_t *number(const api_packed *p, size_t i)
{
    return api_packed_isint(p, i) ? json_integer((json_int_t)p->val[i]) : json_real(p->val[i]);
}

static json_t *unpack(const api_packed *p)
{
    json_t *a = json_array();
    size_t k = 0;
    for (size_t r = 0; r < p->nrows; r++) {
        if (p->len[r] == API_PACKED_BARE) {
            json_array_append_new(a, number(p, k++));
            continue;
        }
        json_t *row = json_array();
        for (int j = 0; j < p->len[r]; j++)
            json_array_append_new(row, number(p, k++));
        json_array_append_new(a, row);
    }
    if (k != p->nval)
        abort();
    return a;
}

/* Put every packed array back at its pointer in tree t (the tree holds "[]" there). */
static void restore(json_t *t, const api_packs *ps)
{
    for (int i = 0; i < ps->n; i++) {
        const char *ptr = ps->a[i].ptr;
        json_t *parent = t, *node = NULL;
        char seg[128];
        const char *p = ptr;
        while (*p == '/') {
            const char *e = strchr(p + 1, '/');
            size_t n = e ? (size_t)(e - p - 1) : strlen(p + 1);
            memcpy(seg, p + 1, n);
            seg[n] = 0;
            node = json_is_object(parent) ? json_object_get(parent, seg)
                                          : json_array_get(parent, strtoul(seg, NULL, 10));
            if (!node)
                abort();
            if (!e) {
                if (!json_is_array(node) || json_array_size(node))
                    abort();       /* the blanked text must read as [] */
                json_t *full = unpack(&ps->a[i]);
                if (json_is_object(parent))
                    json_object_set_new(parent, seg, full);
                else
                    json_array_set_new(parent, strtoul(seg, NULL, 10), full);
                break;
            }
            parent = node;
            p = e;
        }
    }
}

static long packed_inputs; /* inputs of which something was packed (the check is not vacuous) */

static void check(const uint8_t *data, size_t n, size_t min_bytes)
{
    char *a = malloc(n + 1), *b = malloc(n + 1);
    memcpy(a, data, n);
    memcpy(b, data, n);
    a[n] = b[n] = 0;
    json_error_t ea, eb;
    json_t *ta = json_loadb(a, n, JSON_REJECT_DUPLICATES, &ea);
    api_packs ps;
    if (api_pack_body(b, n, patterns, min_bytes, 16, &ps))
        abort();                      /* no allocation fails here */
    packed_inputs += ps.n > 0;
    json_t *tb = json_loadb(b, n, JSON_REJECT_DUPLICATES, &eb);
    if (!ta != !tb) {
        fprintf(stderr, "one side failed: %s / %s\n", ta ? "-" : ea.text, tb ? "-" : eb.text);
        abort();
    }
    if (!ta) {
        if (ea.line != eb.line || ea.column != eb.column || ea.position != eb.position ||
            strcmp(ea.text, eb.text)) {
            fprintf(stderr, "errors differ: %d:%d %s / %d:%d %s\n", ea.line, ea.column, ea.text,
                    eb.line, eb.column, eb.text);
            abort();
        }
    } else {
        restore(tb, &ps);
        if (!same(ta, tb)) {
            fprintf(stderr, "trees differ\n");
            abort();
        }
    }
    json_decref(ta);
    json_decref(tb);
    api_packs_free(&ps);
    free(a);
    free(b);
}

#ifdef SD_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t n)
{
    check(data, n, 1);
    return 0;
}
#else
static const char *const seeds[] = {
    "{\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],\"simplices\":[[0,1,2,3]]}",
    "{\"vertices\":[[-0,0.0,-0.0],[1e-320,-1e-400,1E+2],[9007199254740993,-9007199254740992,"
    "12345678901234567890],[1.5e308,1e309,-1e309]],\"simplices\":[[0],[1,2],[0,1,2],[3]]}",
    "{\"vertices\": [\n [0, 0, 0],\n [1, 0, 0]\n ], \"simplices\": [[0, 1]],\n \"attributes\": "
    "{\"t\": [1, 2], \"uv\": [[0, 1], [1, 0]], \"a~b\": [1, 2], \"c\\u0041\": [3, 4]}}",
    "{\"vertices\":[[0,0,\"x\"]],\"simplices\":[[0,1],[1,2]]}",
    "{\"vertices\":[[0,0,0]],\"vertices\":[[1,1,1]]}",
    "{\"vertices\":[[01,0,0]]}",
    "{\"vertices\":[[0,0,0],],\"simplices\":[]}",
    "{\"vertices\":[[0,0,0]] \"simplices\":[]}",
    "{\"vertices\":[[[0]]],\"simplices\":[[0,1,2,3,4,5]]}",
    "{\"fill\":[{\"surface\":[[0,1,2],[2,1,3]],\"max_volume\":0.1},{\"surface\":[]}],"
    "\"vertices\":[1,2,3],\"simplices\":[[0,1,2]]}",
    "{\"vertices\":[[1.0,2.5e-3,-7],[3,4,5]],\"simplices\":[[0,1]],\"x\":[[1,2]]}",
    "[[0,0,0]]",
    "{\"vertices\":[[0,0,0],[1,0,0]],\"simplices\":[[0,1]]} x",
    "{\"vertices\":[ [0 ,0, 0 ] , [ 1,0,0]],\"simplices\":[[0,1,]]}",
};
#define NSEEDS (sizeof seeds / sizeof *seeds)
static const char *const tokens[] = {"[", "]", "{", "}", ",", ":", "\"", "0", "-", "-0", "1e308",
                                     "1e309", "4294967296", "99999999999999999999", "null",
                                     "1.5", ".5", "1.", "e5", "\n", " ", "\\u0041", "[]", "[0,0,0]"};
int main(int argc, char **argv)
{
    long iters = 20000;
    int rc = fuzz_plain_args(argc, argv, seeds, NSEEDS, &iters);
    if (rc >= 0)
        return rc;
    char buf[4096];
    for (size_t s = 0; s < NSEEDS; s++) {
        check((const uint8_t *)seeds[s], strlen(seeds[s]), 1);
        check((const uint8_t *)seeds[s], strlen(seeds[s]), 16);
    }
    for (long it = 0; it < iters; it++) {
        const char *seed = seeds[fuzz_rnd(NSEEDS)];
        size_t n = strlen(seed);
        memcpy(buf, seed, n);
        n = fuzz_mutate(buf, n, sizeof buf, 3, tokens, sizeof tokens / sizeof *tokens,
                        "0123456789-+.eE[],{}\" \n");
        check((const uint8_t *)buf, n, fuzz_rnd(2) ? 1 : 1 + fuzz_rnd(32));
    }
    printf("fuzz_packed: %zu seeds and %ld mutations agree with jansson (%ld packed)\n", NSEEDS,
           iters, packed_inputs);
    if (packed_inputs < iters / 10)
        return 1; /* the mutations should leave most inputs packable */
    return 0;
}
#endif
