/* packed.c — the big numeric arrays of a request body, read without a JSON tree (packed.h).
 *
 * One pass over the body with a small recursive scanner that tracks the JSON pointer of every
 * value. At an array whose pointer matches a pattern, pack_array() tries the fast grammar
 *     [ (number | [ number, … ]) , … ]
 * and, when the whole array fits it, keeps the numbers and blanks the text. Numbers follow
 * jansson's reading exactly, so an answer cannot tell the two paths apart: an integer literal
 * (no '.', no exponent) is strtoll'd then converted to double (so "-0" is +0.0, as json_integer
 * gives), a real is strtod'd; an integer that strtoll cannot hold or a real that overflows makes
 * the array unpackable, and jansson then reports it as before. The scanner gives up (packing
 * nothing further) at the first syntax error or beyond its recursion limit: jansson will refuse
 * that body anyway, at the same line and column, since blanking keeps every byte offset.
 */
#include "packed.h"
#include "mem.h"
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#define SCAN_MAX_DEPTH 64

typedef struct scan {
    char *s, *end;
    const char *const *pat;
    size_t min_bytes;
    int max_depth;
    api_packs *out;
    bool failed;    /* syntax error or too deep: stop */
    bool nomem;
} scan;

static void skip_ws(scan *st)
{
    while (st->s < st->end && (*st->s == ' ' || *st->s == '\t' || *st->s == '\n' || *st->s == '\r'))
        st->s++;
}

static bool is_digit(char c) { return c >= '0' && c <= '9'; }

/* The end of the number token at p (JSON grammar), or NULL; *isint: no fraction or exponent. */
static char *number_end(char *p, char *end, bool *isint)
{
    *isint = true;
    if (p < end && *p == '-')
        p++;
    if (p >= end || !is_digit(*p))
        return NULL;
    if (*p == '0')
        p++;
    else
        while (p < end && is_digit(*p))
            p++;
    if (p < end && *p == '.') {
        *isint = false;
        p++;
        if (p >= end || !is_digit(*p))
            return NULL;
        while (p < end && is_digit(*p))
            p++;
    }
    if (p < end && (*p == 'e' || *p == 'E')) {
        *isint = false;
        p++;
        if (p < end && (*p == '+' || *p == '-'))
            p++;
        if (p >= end || !is_digit(*p))
            return NULL;
        while (p < end && is_digit(*p))
            p++;
    }
    return p;
}

/* The value of a number token as jansson gives it (json_number_value); false where jansson
 * refuses it (overflow) or where a double would not hold the integer exactly. */
static bool number_value(const char *p, const char *q, bool isint, double *out)
{
    char buf[64];
    size_t n = (size_t)(q - p);
    if (n >= sizeof buf)
        return false;
    memcpy(buf, p, n);
    buf[n] = 0;
    errno = 0;
    if (isint) {
        long long v = strtoll(buf, NULL, 10);
        if (errno == ERANGE || v > (1LL << 53) || v < -(1LL << 53))
            return false;
        *out = (double)v;
        return true;
    }
    double v = strtod(buf, NULL);
    if (errno == ERANGE && (v == HUGE_VAL || v == -HUGE_VAL))
        return false;
    *out = v;
    return true;
}

/* Growable arrays of one packed array. */
typedef struct builder {
    api_packed a;
    size_t caprows, capval;
} builder;

static bool grow(void **p, size_t *cap, size_t need, size_t elem)
{
    if (need <= *cap)
        return true;
    size_t c = *cap ? *cap : 1024;
    while (c < need)
        c *= 2;
    void *q = api_realloc(*p, c * elem);
    if (!q)
        return false;
    *p = q;
    *cap = c;
    return true;
}

static bool push_value(builder *b, double v, bool isint)
{
    size_t i = b->a.nval, capbits = b->capval;
    if (!grow((void **)&b->a.val, &b->capval, i + 1, sizeof *b->a.val))
        return false;
    if (b->capval != capbits) { /* the bit set follows the value array's capacity */
        uint8_t *bits = api_realloc(b->a.isint, (b->capval + 7) / 8);
        if (!bits)
            return false;
        memset(bits + (capbits + 7) / 8, 0, (b->capval + 7) / 8 - (capbits + 7) / 8);
        b->a.isint = bits;
    }
    b->a.val[i] = v;
    if (isint)
        b->a.isint[i >> 3] |= (uint8_t)(1u << (i & 7));
    b->a.nval = i + 1;
    return true;
}

static bool push_row(builder *b, uint8_t len)
{
    if (!grow((void **)&b->a.len, &b->caprows, b->a.nrows + 1, 1))
        return false;
    b->a.len[b->a.nrows++] = len;
    return true;
}

static void packed_free(api_packed *a)
{
    api_free(a->len);
    api_free(a->val);
    api_free(a->isint);
    memset(a, 0, sizeof *a);
}

/* One number at st->s into b; false (st->s unchanged) if it is not one or not packable. */
static bool pack_number(scan *st, builder *b)
{
    bool isint;
    char *q = number_end(st->s, st->end, &isint);
    double v;
    if (!q || !number_value(st->s, q, isint, &v))
        return false;
    if (!push_value(b, v, isint)) {
        st->nomem = true;
        return false;
    }
    st->s = q;
    return true;
}

/* Try the fast grammar at st->s (an '['). On success st->s is past the array and *b holds it;
 * on failure st->s is back at the '[' (b's contents are then to be dropped). */
static bool pack_array(scan *st, builder *b)
{
    char *start = st->s;
    st->s++;
    skip_ws(st);
    if (st->s < st->end && *st->s == ']') {
        st->s++;
        return true;
    }
    for (;;) {
        skip_ws(st);
        if (st->s >= st->end)
            goto fail;
        if (*st->s == '[') {
            st->s++;
            size_t n = 0;
            skip_ws(st);
            if (st->s < st->end && *st->s == ']')
                st->s++;
            else
                for (;;) {
                    skip_ws(st);
                    if (!pack_number(st, b) || ++n > API_PACKED_MAX_ROW)
                        goto fail;
                    skip_ws(st);
                    if (st->s < st->end && *st->s == ',') {
                        st->s++;
                        continue;
                    }
                    if (st->s < st->end && *st->s == ']') {
                        st->s++;
                        break;
                    }
                    goto fail;
                }
            if (!push_row(b, (uint8_t)n)) {
                st->nomem = true;
                goto fail;
            }
        } else {
            if (!pack_number(st, b))
                goto fail;
            if (!push_row(b, API_PACKED_BARE)) {
                st->nomem = true;
                goto fail;
            }
        }
        skip_ws(st);
        if (st->s < st->end && *st->s == ',') {
            st->s++;
            continue;
        }
        if (st->s < st->end && *st->s == ']') {
            st->s++;
            return true;
        }
        goto fail;
    }
fail:
    st->s = start;
    return false;
}

/* Pattern matching of JSON pointers: does `ptr` equal a pattern (*full) or begin one? */
static bool seg_match(const char *pat, size_t plen, const char *seg, size_t slen)
{
    return (plen == 1 && pat[0] == '*') || (plen == slen && !memcmp(pat, seg, slen));
}

static void match(const char *const *pats, const char *ptr, bool *full, bool *prefix)
{
    *full = *prefix = false;
    for (int i = 0; pats[i]; i++) {
        const char *p = pats[i], *q = ptr;
        for (;;) {
            if (!*q) {
                if (!*p)
                    *full = true;
                else
                    *prefix = true;
                break;
            }
            if (*p != '/' || *q != '/')
                break;
            const char *pe = strchr(p + 1, '/'), *qe = strchr(q + 1, '/');
            size_t pl = pe ? (size_t)(pe - p - 1) : strlen(p + 1);
            size_t ql = qe ? (size_t)(qe - q - 1) : strlen(q + 1);
            if (!seg_match(p + 1, pl, q + 1, ql))
                break;
            p += 1 + pl;
            q += 1 + ql;
        }
    }
}

/* A string at st->s (a '"'): past it. *plain: no escapes and no '~' or '/' (usable as a pointer
 * segment as written). */
static bool skip_string(scan *st, bool *plain)
{
    *plain = true;
    for (st->s++; st->s < st->end; st->s++) {
        char c = *st->s;
        if (c == '"') {
            st->s++;
            return true;
        }
        if (c == '\\') {
            *plain = false;
            st->s++;
        } else if (c == '~' || c == '/' || (unsigned char)c < 0x20)
            *plain = false;
    }
    return false;
}

static bool literal(scan *st, const char *w)
{
    size_t n = strlen(w);
    if ((size_t)(st->end - st->s) < n || memcmp(st->s, w, n))
        return false;
    st->s += n;
    return true;
}

static void scan_value(scan *st, int depth, char *ptr, size_t plen);

/* Blank the packed text [a, b) (b - 1 is its ']'), keeping newlines and byte offsets. */
static void blank(char *a, char *b)
{
    for (char *p = a + 1; p < b - 1; p++)
        if (*p != '\n')
            *p = ' ';
    a[0] = '[';
    b[-1] = ']';
}

/* After a member of an array or object: 1 at a ',' (another follows), 0 at `close` (the end)
 * or at anything else (failed). */
static int next_member(scan *st, char close)
{
    skip_ws(st);
    if (st->s < st->end && *st->s == ',') {
        st->s++;
        return 1;
    }
    if (st->s < st->end && *st->s == close)
        st->s++;
    else
        st->failed = true;
    return 0;
}

static void scan_array(scan *st, int depth, char *ptr, size_t plen)
{
    bool full, prefix;
    match(st->pat, ptr, &full, &prefix);
    if (full && st->out->n < (int)(sizeof st->out->a / sizeof st->out->a[0]) &&
        depth + 1 <= st->max_depth) {
        builder b = {0};
        char *start = st->s;
        if (pack_array(st, &b)) {
            if ((size_t)(st->s - start) >= st->min_bytes) {
                snprintf(b.a.ptr, sizeof b.a.ptr, "%s", ptr);
                st->out->a[st->out->n++] = b.a;
                blank(start, st->s);
            } else
                packed_free(&b.a);
            return;
        }
        packed_free(&b.a);
        if (st->nomem)
            return;
    }
    st->s++; /* '[' */
    size_t i = 0;
    skip_ws(st);
    if (st->s < st->end && *st->s == ']') {
        st->s++;
        return;
    }
    for (;; i++) {
        int w = snprintf(ptr + plen, 128 - plen, "/%zu", i);
        if (w < 0 || plen + (size_t)w >= 128) {
            st->failed = true;
            return;
        }
        scan_value(st, depth + 1, ptr, plen + (size_t)w);
        ptr[plen] = 0;
        if (st->failed || st->nomem)
            return;
        if (!next_member(st, ']'))
            return;
    }
}

static void scan_object(scan *st, int depth, char *ptr, size_t plen)
{
    st->s++; /* '{' */
    skip_ws(st);
    if (st->s < st->end && *st->s == '}') {
        st->s++;
        return;
    }
    for (;;) {
        skip_ws(st);
        if (st->s >= st->end || *st->s != '"') {
            st->failed = true;
            return;
        }
        char *k = st->s + 1;
        bool plain;
        if (!skip_string(st, &plain)) {
            st->failed = true;
            return;
        }
        size_t klen = (size_t)(st->s - 1 - k);
        skip_ws(st);
        if (st->s >= st->end || *st->s != ':') {
            st->failed = true;
            return;
        }
        st->s++;
        if (plain && plen + 1 + klen < 128) {
            ptr[plen] = '/';
            memcpy(ptr + plen + 1, k, klen);
            ptr[plen + 1 + klen] = 0;
            scan_value(st, depth + 1, ptr, plen + 1 + klen);
        } else { /* a key we cannot name: nothing below it is packed */
            const char *const none[] = {NULL};
            const char *const *pat = st->pat;
            st->pat = none;
            scan_value(st, depth + 1, ptr, plen);
            st->pat = pat;
        }
        ptr[plen] = 0;
        if (st->failed || st->nomem)
            return;
        if (!next_member(st, '}'))
            return;
    }
}

static void scan_value(scan *st, int depth, char *ptr, size_t plen)
{
    skip_ws(st);
    if (depth > SCAN_MAX_DEPTH || st->s >= st->end) {
        st->failed = true;
        return;
    }
    bool isint, plain;
    char *q;
    switch (*st->s) {
    case '{':
        scan_object(st, depth, ptr, plen);
        return;
    case '[':
        scan_array(st, depth, ptr, plen);
        return;
    case '"':
        if (!skip_string(st, &plain))
            st->failed = true;
        return;
    case 't':
        st->failed = !literal(st, "true");
        return;
    case 'f':
        st->failed = !literal(st, "false");
        return;
    case 'n':
        st->failed = !literal(st, "null");
        return;
    default:
        q = number_end(st->s, st->end, &isint);
        if (!q)
            st->failed = true;
        else
            st->s = q;
        return;
    }
}

int api_pack_body(char *body, size_t len, const char *const *patterns, size_t min_bytes,
                  int max_depth, api_packs *out)
{
    memset(out, 0, sizeof *out);
    scan st = {body, body + len, patterns, min_bytes ? min_bytes : 1, max_depth, out, false, false};
    char ptr[128] = "";
    scan_value(&st, 1, ptr, 0);
    if (st.nomem) {
        /* put the text back: re-serialising is not possible, so packing is all-or-nothing only
         * up to the array that failed; the caller answers 503 and discards the body */
        api_packs_free(out);
        return -1;
    }
    return 0;
}

void api_packs_free(api_packs *p)
{
    for (int i = 0; i < p->n; i++)
        packed_free(&p->a[i]);
    p->n = 0;
}

const api_packed *api_packed_find(const api_packs *p, const char *ptr)
{
    for (int i = 0; i < p->n; i++)
        if (!strcmp(p->a[i].ptr, ptr))
            return &p->a[i];
    return NULL;
}
