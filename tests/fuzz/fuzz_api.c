/* fuzz_api — a self-contained mutation fuzzer for the request path of the api/ layer.
 *
 * Starting from valid seed bodies (PUT /complex, /rules, /tags), it applies deterministic random
 * mutations (byte flips, insertions of JSON tokens, deletions, truncations, splices between
 * seeds) and runs each result through api_parse_body and the change handlers with small limits,
 * then opens and drains level 0-2 in every format. It asserts nothing about the answers but
 * that each call returns either a model or a problem with a 4xx/5xx status and a detail; the
 * point is to run under ASan/UBSan (make sanitize) where any memory error aborts.
 * Built two ways, as tests/fuzz/fuzz_packed.c: with libFuzzer (-DSD_LIBFUZZER, `make fuzz`: each
 * input is one body, the handler's choices follow from a hash of it) and as this plain mutation
 * program (`make test`, make sanitize).
 * usage: fuzz_api [ITERATIONS [SEED]] | --write-seeds DIR
 */
#include "../../api/delta.h"
#include "../../api/complex_stream.h"
#include "../../api/handlers.h"
#include "../../api/mem.h"
#include "../../api/jsonin.h"
#include "../../api/mem.h"
#include "plain.h"
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const seeds[] = {
    "{\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[0,0,1],[1,1,0],[0,0,2],[0.5,0,3],[3,3,3]],"
    "\"simplices\":[[0,1,2,3],[1,2,4],[3,5],[5,6],[7]],\"attributes\":{\"h\":[0,0,0,1,0,2,3,3],"
    "\"v\":[[0,1],[1,1],[2,1],[3,1],[4,1],[5,1],[6,1],[7,1]]}}",
    "{\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[0,0,1],[1,1,1]],\"simplices\":[[0,1,2,3],[1,2,3,4]]}",
    "{\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[1,1,0]],\"simplices\":[[0,1,2],[1,3,2],[0,3]]}",
    /* three fins on a spine: vertex 0 complex singular, with open petals (Ying-Zorin corners) */
    "{\"vertices\":[[0,0,0],[0,0,1],[0,0,2],[1,0,0],[1,0,1],[1,0,2],[-0.5,0.8,0],[-0.5,0.8,1],"
    "[-0.5,0.8,2],[-0.5,-0.8,0],[-0.5,-0.8,1],[-0.5,-0.8,2]],\"simplices\":[[0,1,4],[0,4,3],"
    "[1,2,5],[1,5,4],[0,1,7],[0,7,6],[1,2,8],[1,8,7],[0,1,10],[0,10,9],[1,2,11],[1,11,10]]}",
    "{\"solid_scheme\":\"averaged\",\"surface_weights\":\"loop\",\"nonmanifold_default\":\"G2\","
    "\"overrides\":[]}",
    "{\"nonmanifold_default\":\"G1\",\"nonmanifold_surface\":\"ying-zorin\",\"overrides\":["
    "{\"simplex\":[1],\"rule\":\"N1\",\"dimension\":3},{\"simplex\":[1,2],\"rule\":\"N1\","
    "\"dimension\":2},{\"simplex\":[3],\"rule\":\"G1\"},{\"simplex\":[2],\"rule\":\"G2\"},"
    "{\"simplex\":[1,3],\"rule\":\"N2\",\"pair\":[[1,3,0],[1,3,2]]}]}",
    "{\"singular\":[]}",
    /* repair (api/repair.c): a duplicate, a degenerate and a repeated-vertex simplex, a diagonal on
     * a dropped tetrahedron; crease_angle (api/crease.c) alone and with listed tags */
    "{\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[0,0,1],[1,1,1],[2,0,0]],\"simplices\":[[0,1,2,3],"
    "[3,2,1,0],[0,1,5],[1,2,3,4],[4,4,1],[0,1]],\"diagonals\":[[1,2],[3,0]],\"repair\":true}",
    "{\"crease_angle\":30}",
    "{\"singular\":[[0,1]],\"crease_angle\":0,\"petals\":[]}",
    "{\"singular\":[[0],[0,1],[0,1,2]]}",
    "{\"singular\":[[2]],\"petals\":[{\"vertex\":0,\"triangle\":[0,4,3],\"kind\":\"concave\"},"
    "{\"vertex\":0,\"triangle\":[0,1,7],\"kind\":\"smooth\"}]}",
    "{\"select\":{\"simplices\":[[0,1,2,3]]},\"depth\":2,\"positions\":\"subdivision\"}",
    "{\"select\":{\"box\":{\"min\":[0,0,0],\"max\":[1,1,1]}},\"positions\":\"midpoint\"}",
    "{\"select\":{\"sphere\":{\"center\":[0,0,0],\"radius\":0.5}}}",
    "{\"moves\":[{\"index\":1,\"position\":[1,0.1,0]}],\"attributes\":{\"h\":[{\"index\":2,"
    "\"value\":5}]}}",
    /* TetGen fill of an octahedron with a fin (api/fill.c: the surface checks, the helper) */
    "{\"vertices\":[[1,0,0],[-1,0,0],[0,1,0],[0,-1,0],[0,0,1],[0,0,-1],[2,2,2]],"
    "\"simplices\":[[0,2,6]],\"attributes\":{\"h\":[0,1,2,3,4,5,6]},\"fill\":[{\"surface\":"
    "[[0,2,4],[2,1,4],[1,3,4],[3,0,4],[2,0,5],[1,2,5],[3,1,5],[0,3,5]],\"min_ratio\":1.5,"
    "\"max_volume\":0.5}]}",
    /* moves at finer levels (detail offsets), and a complex that brings offsets back */
    "{\"moves\":[{\"index\":1,\"position\":[1,0.1,0]},{\"level\":2,\"index\":20,"
    "\"position\":[0.2,0.3,0.1]},{\"level\":1,\"index\":9,\"position\":[0.5,0.5,0]}]}",
    "{\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[0,0,1],[1,1,1]],\"simplices\":[[0,1,2,3],[1,2,3,4]],"
    "\"details\":[{\"level\":1,\"index\":7,\"offset\":[0,0,0.1]},{\"level\":3,\"index\":40,"
    "\"offset\":[0.01,0,0]}]}",
    /* a GET /export document (POST /v1/sessions {"import"}) with a tetrahedron stored reoriented */
    "{\"format\":\"subdivd-session\",\"format_version\":1,\"version\":5,\"complex\":{"
    "\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[0,0,1],[1,1,1]],\"simplices\":[[0,1,2,3],[1,2,3,4]],"
    "\"attributes\":{},\"diagonals\":[[0,1],[1,0]],\"reoriented\":[1],\"details\":[]},"
    "\"tags\":{\"singular\":[[0,1]]},\"rules\":{\"surface_weights\":\"loop\",\"overrides\":["
    "{\"simplex\":[4],\"rule\":\"G1\"}]},\"embedded\":{}}",
};
#define NSEEDS (sizeof seeds / sizeof *seeds)
#ifndef SD_LIBFUZZER
static const char *const tokens[] = {"[", "]", "{", "}", ",", ":", "\"", "0", "-1", "1e308",
                                     "4294967296", "null", "true", "1.5", "\"x\"", "[]", "{}",
                                     "99999999999999999999", "[0,0,0]", "[0,1,2,3,4]"};
#endif

#ifndef SD_LIBFUZZER
static size_t mutate(char *buf, size_t len, size_t cap)
{
    int steps = (int)fuzz_rnd(3);
    for (int s = 0; s < steps; s++) {
        switch (fuzz_rnd(6)) {
        case 5: { /* replace one number (a run of digits) by a token: keeps the shape */
            size_t at = fuzz_rnd((uint32_t)len + 1);
            while (at < len && !(buf[at] >= '0' && buf[at] <= '9'))
                at++;
            size_t end = at;
            while (end < len && ((buf[end] >= '0' && buf[end] <= '9') || buf[end] == '.'))
                end++;
            const char *t = tokens[fuzz_rnd(sizeof tokens / sizeof *tokens)];
            size_t n = strlen(t);
            if (at < len && len - (end - at) + n < cap) {
                memmove(buf + at + n, buf + end, len - end);
                memcpy(buf + at, t, n);
                len = len - (end - at) + n;
            }
            break;
        }
        case 0: /* flip a byte */
            if (len)
                buf[fuzz_rnd((uint32_t)len)] ^= (char)(1 + fuzz_rnd(255));
            break;
        case 1: { /* insert a token */
            const char *t = tokens[fuzz_rnd(sizeof tokens / sizeof *tokens)];
            size_t n = strlen(t), at = fuzz_rnd((uint32_t)len + 1);
            if (len + n < cap) {
                memmove(buf + at + n, buf + at, len - at);
                memcpy(buf + at, t, n);
                len += n;
            }
            break;
        }
        case 2: { /* delete a run */
            if (!len)
                break;
            size_t at = fuzz_rnd((uint32_t)len), n = 1 + fuzz_rnd(8);
            if (at + n > len)
                n = len - at;
            memmove(buf + at, buf + at + n, len - at - n);
            len -= n;
            break;
        }
        case 3: /* truncate */
            len = fuzz_rnd((uint32_t)len + 1);
            break;
        default: { /* splice the tail of another seed */
            const char *o = seeds[fuzz_rnd(NSEEDS)];
            size_t ol = strlen(o), from = fuzz_rnd((uint32_t)ol), at = fuzz_rnd((uint32_t)len + 1);
            size_t n = ol - from;
            if (at + n < cap) {
                memcpy(buf + at, o + from, n);
                len = at + n;
            }
            break;
        }
        }
    }
    return len;
}
#endif

static void check_problem(const api_problem *p, const char *what)
{
    if (p->status < 400 || p->status > 599 || !p->detail[0]) {
        fprintf(stderr, "fuzz_api: %s returned status %d without a problem\n", what, p->status);
        abort();
    }
}

static void drain_levels(api_model *m, const api_limits *lim)
{
    static char buf[4096];
    static const char *const fmts[] = {"glb", "gltf", "vtu", "vtk", "json"};
    for (int level = 0; level <= 2; level++)
        for (int f = 0; f < 5; f++) {
            api_level_query q = {.format = fmts[f], .slice = f & 1 ? "0,0,1,0.3" : NULL};
            api_problem p = {0};
            out_stream *os = NULL;
            const out_format *fmt;
            uint64_t version;
            if (api_level_open(m, level, &q, lim, NULL, &os, &fmt, &version, &p)) {
                check_problem(&p, "api_level_open");
                continue;
            }
            while (out_read(os, buf, sizeof buf) > 0)
                ;
            out_close(os);
        }
}

/* The deltas of levels 0-2 since the edit's version and the one before, both formats, all parts
 * or one kind of drawn triangles. */
static void drain_deltas(api_model *m)
{
    static const char *const since[] = {"0", "1"};
    for (int level = 0; level <= 2; level++)
        for (int k = 0; k < 6; k++) {
            api_delta_query q = {since[k & 1], k & 2 ? "json" : "bin", k == 3 ? "h" : NULL,
                                 k < 4 ? NULL : k == 4 ? "surfaces" : "solids"};
            api_problem p = {0};
            char *body = NULL, comp[256];
            size_t len;
            const char *ctype;
            uint64_t v;
            if (api_level_delta(m, level, &q, &body, &len, &ctype, comp, sizeof comp, &v, &p))
                check_problem(&p, "api_level_delta");
            api_free(body);
        }
}

/* GET /complex streamed (api/complex_stream.c) must be byte for byte the jansson rendering of
 * the document api_get_complex builds, with "version" last, read in odd-sized pieces. */
static void check_complex_stream(api_model *m)
{
    api_problem gp = {0};
    json_t *g = api_get_complex(m, &gp);
    if (!g)
        return;
    atomic_store(&m->version, 7);
    json_object_set_new(g, "version", json_integer(7));
    char *want = json_dumps(g, JSON_COMPACT);
    json_decref(g);
    uint64_t version;
    api_cstream *cs = api_get_complex_stream(m, &version, &gp);
    size_t cap = want ? strlen(want) + 4096 : 0, n = 0, k;
    char *got = malloc(cap + 1);
    while (cs && got && n < cap && (k = api_cstream_read(cs, got + n, 1 + (n * 7919) % 997)) > 0)
        n += k;
    if (got)
        got[n] = 0;
    if (!want || !cs || !got || version != 7 || n != strlen(want) || memcmp(got, want, n)) {
        fprintf(stderr, "fuzz_api: GET /complex streamed differs from jansson's document\n"
                        "want %.300s\ngot  %.300s\n", want ? want : "(none)", got ? got : "");
        abort();
    }
    api_cstream_free(cs);
    free(got);
    api_free(want);
}

/* Export, import, export again: the same bytes (api/export.c: every input of a build is in the
 * document exactly), and the import of an export never fails. */
static void check_export_roundtrip(api_model *m, const api_limits *lim)
{
    json_t *doc = api_export(m, 3);
    char *text = doc ? json_dumps(doc, JSON_COMPACT) : NULL;
    api_problem p = {0};
    api_model *back = NULL;
    uint64_t v = 0;
    int rc = doc ? api_import(doc, "/import", lim, API_IMPORT_MAX_VERSION, &back, &v, &p) : -1;
    json_decref(doc);
    if (rc && p.status == 503) { /* out of memory is the one excuse */
        api_free(text);
        return;
    }
    json_t *again = rc ? NULL : api_export(back, v);
    char *text2 = again ? json_dumps(again, JSON_COMPACT) : NULL;
    json_decref(again);
    if (!text || rc || v != 3 || !text2 || strcmp(text, text2)) {
        fprintf(stderr, "fuzz_api: export/import/export differs (import: %d %s)\nfirst  %.300s\n"
                        "second %.300s\n", rc, p.detail, text ? text : "", text2 ? text2 : "");
        abort();
    }
    api_model_unref(back);
    api_free(text);
    api_free(text2);
}

/* One body through parsing, a change handler (on an empty model or one with a valid complex)
 * and, when accepted, every writer; 1 when it was accepted. */
static int one(const char *buf, size_t len, const api_limits *lim)
{
    int accepted = 0;
    sd_error e;
    api_model *cur = api_model_new(NULL, NULL, 0, false, &e), *next = NULL;
    if (!cur)
        return 0;
    /* a valid complex first, so tags and overrides have something to refer to */
    if (fuzz_rnd(2)) {
        api_problem p = {0};
        const char *valid = seeds[fuzz_rnd(4)];
        json_t *b = api_parse_body(valid, strlen(valid), 0, &p);
        if (b && !api_put_complex(cur, b, lim, &next, &p)) {
            api_model_unref(cur);
            cur = next;
            next = NULL;
        }
        json_decref(b);
        if (fuzz_rnd(2)) { /* and the Ying-Zorin rules, so petal tags take effect */
            static const char yz[] = "{\"nonmanifold_surface\":\"ying-zorin\"}";
            api_problem q = {0};
            b = api_parse_body(yz, sizeof yz - 1, 0, &q);
            if (b && !api_put_rules(cur, b, lim, &next, &q)) {
                api_model_unref(cur);
                cur = next;
                next = NULL;
            }
            json_decref(b);
        }
    }
    api_problem p = {0};
    json_t *b = api_parse_body(buf, len, fuzz_rnd(2), &p);
    if (!b) {
        check_problem(&p, "api_parse_body");
    } else {
        change_fn_t fns[] = {api_put_complex, api_put_rules, api_put_tags};
        int which = (int)fuzz_rnd(6);
        uint64_t counts[SD_MAX_LEVEL + 1];
        api_refined refined;
        int levels;
        if (which == 3) { /* refinement: a new model like the changes */
            if (api_refine(cur, b, lim, &next, &refined, &p))
                check_problem(&p, "api_refine");
            else {
                accepted = 1;
                api_model_unref(cur);
                cur = next;
            }
        } else if (which == 4) { /* an edit changes the model in place, or makes a new one */
            api_model *rebuilt = NULL;
            if (api_edit(cur, b, 2, lim, NULL, counts, &levels, &rebuilt, &p))
                check_problem(&p, "api_edit");
            else
                accepted = 1;
            if (rebuilt) {
                api_model_unref(cur);
                cur = rebuilt;
            }
            if (accepted)
                drain_deltas(cur);
        } else if (which == 5) { /* an import document: a new model, or a problem */
            uint64_t v;
            if (api_import(b, "/import", lim, API_IMPORT_MAX_VERSION, &next, &v, &p))
                check_problem(&p, "api_import");
            else {
                accepted = 1;
                api_model_unref(cur);
                cur = next;
                check_export_roundtrip(cur, lim);
            }
        } else if (fns[which](cur, b, lim, &next, &p))
            check_problem(&p, "a change handler");
        else {
            accepted = 1;
            api_model_unref(cur);
            cur = next;
            if (cur->c)
                drain_levels(cur, lim);
            check_complex_stream(cur);
            check_export_roundtrip(cur, lim);
        }
        json_decref(b);
    }
    api_model_unref(cur);
    return accepted;
}

static api_limits small_limits(void)
{
    api_limits lim = api_default_limits();
    lim.max_vertices = 64;
    lim.max_simplices = 64;
    lim.max_cells = 20000;
    lim.max_session_bytes = 64u << 20;
    return lim;
}

#ifdef SD_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t n)
{
    static api_limits lim;
    if (!lim.max_vertices)
        lim = small_limits();
    fuzz_rng = 1469598103934665603ull; /* the choices of one() follow from the input */
    for (size_t i = 0; i < n; i++)
        fuzz_rng = (fuzz_rng ^ data[i]) * 1099511628211ull;
    fuzz_rng |= 1;
    one((const char *)data, n, &lim);
    return 0;
}
#else
int main(int argc, char **argv)
{
    long iters = 2000;
    int rc = fuzz_plain_args(argc, argv, seeds, NSEEDS, &iters);
    if (rc >= 0)
        return rc;
    api_limits lim = small_limits();
    static char buf[8192];
    long accepted = 0;
    for (long i = 0; i < iters; i++) {
        const char *seed = seeds[fuzz_rnd(NSEEDS)];
        size_t len = strlen(seed);
        memcpy(buf, seed, len);
        len = mutate(buf, len, sizeof buf);
        accepted += one(buf, len, &lim);
    }
    printf("fuzz_api: %ld inputs, %ld accepted, no memory errors\n", iters, accepted);
    return 0;
}
#endif
