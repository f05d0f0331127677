/* fuzz_http — the parsers of server/parse.c on hostile text: route patterns, bearer credentials,
 * entity-tag lists, the query string, log escaping.
 *
 * Each input is used whole as an Authorization value, as If-Match / If-None-Match values, as a
 * query string and as a path to log, and split at its first newline into a route pattern and a
 * path (then the path alone against the daemon's own patterns). Besides running under ASan and
 * UBSan, every answer is checked against what the function promises (parse.h); a broken promise
 * aborts:
 *   route   a literal pattern matches iff it equals the path; a match puts captures that fit
 *           their buffers and hold no '/', and the pattern with its captures put back is the path
 *   bearer  a token only after "Bearer " (any case), shorter than the buffer, untrimmed never,
 *           and found in the field value as it is
 *   etags   a strong match is a weak match too, and names the tag in full in the value
 *   query   at most `max` parameters, inside the buffer; a parse that fits in max = n does not
 *           fit in n - 1
 *   escape  only printable ASCII, within the capacity, and undone exactly when it fits
 *
 * Built two ways, as tests/fuzz/fuzz_packed.c: with libFuzzer (-DSD_LIBFUZZER, `make fuzz`) and as
 * a plain program (gcc, `make test`) running the seeds below and deterministic mutations:
 *     fuzz_http [ITERATIONS [SEED]] | --write-seeds DIR
 */
#include "../../server/parse.h"
#include "plain.h"
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#define MAX_INPUT 8192

static void fail(const char *what, const char *input)
{
    fprintf(stderr, "fuzz_http: %s broken on input \"%.200s\"\n", what, input);
    abort();
}

/* The pattern with its captures put back (only for patterns with at most one of each). */
static int rebuild(const char *pattern, const char *id, const char *level, char *out, size_t cap)
{
    size_t o = 0;
    int nid = 0, nlevel = 0;
    for (const char *p = pattern; *p;) {
        const char *put = NULL;
        if (*p == '{') {
            const char *pe = strchr(p, '}');
            if (!pe)
                return 0;
            /* {id} and {slug} are the id; {L}, {name} and any other capture the level's slot */
            int is_id = p[1] == 'i' || p[1] == 's';
            put = is_id ? id : level;
            *(is_id ? &nid : &nlevel) += 1;
            p = pe + 1;
        }
        size_t n = put ? strlen(put) : 1;
        if (o + n >= cap)
            return 0;
        memcpy(out + o, put ? put : p, n);
        o += n;
        if (!put)
            p++;
    }
    out[o] = 0;
    return nid <= 1 && nlevel <= 1;
}

static void check_route(const char *pattern, const char *path, const char *input)
{
    char id[40], level[24];
    memset(id, 'X', sizeof id);
    memset(level, 'X', sizeof level);
    int m = parse_route(pattern, path, id, sizeof id, level, sizeof level);
    if (!strchr(pattern, '{') && m != !strcmp(pattern, path))
        fail("route (literal)", input);
    if (!m)
        return;
    char back[2 * MAX_INPUT];
    int have_id = memchr(id, 0, sizeof id) != NULL, have_level = memchr(level, 0, sizeof level) != NULL;
    if ((have_id && strchr(id, '/')) || (have_level && strchr(level, '/')))
        fail("route (capture)", input);
    if (have_level && !strcmp(level, ROUTE_TOO_LONG) && strlen(path) > sizeof level)
        return; /* a {L}/{name} segment too long to hold: matched as the mark, for a 400 */
    if (rebuild(pattern, have_id ? id : "", have_level ? level : "", back, sizeof back) &&
        strcmp(back, path))
        fail("route (rebuilt)", input);
}

static const char *const patterns[] = {
    "/v1/sessions", "/v1/sessions/{id}", "/v1/sessions/{id}/complex",
    "/v1/sessions/{id}/levels/{L}", "/v1/sessions/{id}/levels/{L}/stats",
    "/v1/sessions/{id}/matrices/{L}", "/healthz", "/errors/{slug}", NULL};

static void check_bearer(const char *h, const char *input)
{
    char buf[128];
    const char *t = parse_bearer(h, buf, sizeof buf);
    if (!t)
        return;
    size_t n = strlen(t);
    if (strncasecmp(h, "Bearer ", 7) || n >= sizeof buf || !strstr(h + 7, t) ||
        (n && (t[n - 1] == ' ' || t[n - 1] == '\t')))
        fail("bearer", input);
}

static void check_etags(const char *h, const char *input)
{
    static const char *const tags[] = {"\"7\"", "\"abc\"", "\"\""};
    for (size_t i = 0; i < sizeof tags / sizeof *tags; i++) {
        int strong = parse_etag_match(h, tags[i], 0), weak = parse_etag_match(h, tags[i], 1);
        if (strong && !weak)
            fail("etag (strong without weak)", input);
        if (weak && !strstr(h, tags[i]) && !strchr(h, '*'))
            fail("etag (match of an absent tag)", input);
    }
}

static void check_query(const char *q, const char *input)
{
    static char buf[MAX_INPUT + 1];
    parse_param ps[64];
    size_t n, n2;
    size_t len = strlen(q);
    memcpy(buf, q, len + 1);
    int rc = parse_query(buf, ps, 64, &n);
    if (n > 64)
        fail("query (count)", input);
    for (size_t i = 0; i < n; i++)
        if (ps[i].key < buf || ps[i].key > buf + len ||
            (*ps[i].value && (ps[i].value < buf || ps[i].value > buf + len)))
            fail("query (bounds)", input);
    if (rc == PARSE_QUERY_OK && n > 0) {
        memcpy(buf, q, len + 1);
        if (parse_query(buf, ps, n, &n2) != PARSE_QUERY_OK || n2 != n)
            fail("query (fits in n)", input);
        memcpy(buf, q, len + 1);
        if (parse_query(buf, ps, n - 1, &n2) != PARSE_QUERY_TOO_MANY)
            fail("query (n - 1)", input);
    }
}

static int hexv(char c) { return c <= '9' ? c - '0' : c - 'a' + 10; }

static void check_escape(const char *s, const char *input)
{
    static char out[4 * MAX_INPUT + 1], back[MAX_INPUT + 1];
    static const size_t caps[] = {1, 5, 64, sizeof out};
    for (size_t c = 0; c < sizeof caps / sizeof *caps; c++) {
        parse_log_escape(out, caps[c], s);
        size_t n = strlen(out);
        if (n >= caps[c])
            fail("escape (capacity)", input);
        for (size_t i = 0; i < n; i++)
            if ((unsigned char)out[i] <= 0x20 || (unsigned char)out[i] >= 0x7f)
                fail("escape (bytes)", input);
        if (caps[c] < 4 * strlen(s) + 1)
            continue;
        size_t b = 0;
        for (size_t i = 0; i < n; i++)
            if (out[i] == '\\') {
                back[b++] = (char)(hexv(out[i + 2]) << 4 | hexv(out[i + 3]));
                i += 3;
            } else
                back[b++] = out[i];
        back[b] = 0;
        if (strcmp(back, s))
            fail("escape (undone)", input);
    }
}

static void check(const uint8_t *data, size_t n)
{
    static char s[MAX_INPUT + 1];
    if (n > MAX_INPUT)
        n = MAX_INPUT;
    memcpy(s, data, n);
    s[n] = 0; /* the parsers take C strings: the input up to its first NUL */
    check_bearer(s, s);
    check_etags(s, s);
    check_query(s, s);
    check_escape(s, s);
    for (const char *const *p = patterns; *p; p++)
        check_route(*p, s, s);
    char *nl = strchr(s, '\n');
    if (nl) {
        *nl = 0;
        check_route(s, nl + 1, s);
    }
}

static const char *const seeds[] = {
    "Bearer abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQ",
    "bearer   tok  \t",
    "Bearer",
    "Basic dXNlcjpwYXNz",
    "\"7\"",
    "W/\"7\"",
    "\"x\", \"7\" ,W/\"abc\"",
    "*",
    " * ",
    "**",
    "\"7\", *",
    ",,\"7\",,",
    "\"7",
    "format=json&parts=points,curves&slice=0,0,1,0.3&attributes=",
    "format=json%00x",
    "a=%zz&b=%4&c=%41%42+d&&=e&f",
    "x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x"
    "&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x&x",
    "/v1/x\n2026-01-01T00:00:00.000Z error forged",
    "/v1/sessions/0123456789abcdef0123456789abcdef/levels/3",
    "/v1/sessions/0123456789abcdef0123456789abcdef/levels/3/stats",
    "/v1/sessions/{id}/levels/{L}\n/v1/sessions/abc/levels/2",
    "/a/{id}/{id}\n/a/b/c",
    "/{L\n/x",
    "/{id}x\n/ax",
    "\\\x01\x7f\xff caf\xc3\xa9",
};
#define NSEEDS (sizeof seeds / sizeof *seeds)

#ifdef SD_LIBFUZZER
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t n)
{
    check(data, n);
    return 0;
}
#else
static const char *const tokens[] = {"Bearer ", "W/", "\"", ",", "*", " ", "\t", "&", "=", "%",
                                     "%00", "%2f", "+", "/", "{id}", "{L}", "{", "}", "\n",
                                     "\x80", "\\", "7"};
int main(int argc, char **argv)
{
    long iters = 50000;
    int rc = fuzz_plain_args(argc, argv, seeds, NSEEDS, &iters);
    if (rc >= 0)
        return rc;
    static char buf[MAX_INPUT];
    for (size_t i = 0; i < NSEEDS; i++)
        check((const uint8_t *)seeds[i], strlen(seeds[i]));
    for (long it = 0; it < iters; it++) {
        const char *seed = seeds[fuzz_rnd(NSEEDS)];
        size_t n = strlen(seed);
        memcpy(buf, seed, n);
        n = fuzz_mutate(buf, n, sizeof buf, 4, tokens, sizeof tokens / sizeof *tokens, NULL);
        check((const uint8_t *)buf, n);
    }
    printf("fuzz_http: %zu seeds and %ld mutations, every promise of server/parse.h kept\n",
           NSEEDS, iters);
    return 0;
}
#endif
