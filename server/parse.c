/* parse.c — pure parsers of the request's text (see parse.h): route patterns, bearer
 * credentials, entity-tag lists, the query string, log escaping.
 *
 * Each function reads a NUL-terminated string of any content and writes only within the
 * capacities it is given; a malformed input is an answer (no match, NULL, an error code), never
 * a crash. tests/fuzz/fuzz_http.c holds them to that under ASan and UBSan.
 */
#include "parse.h"
#include <string.h>
#include <strings.h>

int parse_route(const char *pattern, const char *path, char *id, size_t id_cap, char *level,
                size_t level_cap)
{
    const char *p = pattern, *s = path;
    while (*p && *s) {
        if (*p == '{') {
            const char *pe = strchr(p, '}');
            size_t n = strcspn(s, "/");
            if (!pe || n == 0)
                return 0;
            int is_id = p[1] == 'i' || p[1] == 's'; /* {id}, {slug}; {L} and {name}: the other */
            char *dst = is_id ? id : level;
            size_t cap = is_id ? id_cap : level_cap;
            if (n >= cap && (is_id || cap < sizeof ROUTE_TOO_LONG))
                return 0;
            if (n >= cap)
                memcpy(dst, ROUTE_TOO_LONG, sizeof ROUTE_TOO_LONG);
            else {
                memcpy(dst, s, n);
                dst[n] = 0;
            }
            p = pe + 1;
            s += n;
            continue;
        }
        if (*p != *s)
            return 0;
        p++;
        s++;
    }
    return !*p && !*s;
}

const char *parse_bearer(const char *h, char *buf, size_t cap)
{
    if (!h || strncasecmp(h, "Bearer ", 7))
        return NULL;
    const char *t = h + 7;
    while (*t == ' ')
        t++;
    size_t n = strlen(t);
    while (n && (t[n - 1] == ' ' || t[n - 1] == '\t'))
        n--;
    if (n >= cap)
        return NULL;
    memcpy(buf, t, n);
    buf[n] = 0;
    return buf;
}

static int ows(char c) { return c == ' ' || c == '\t'; }

/* etagc = %x21 / %x23-7E / obs-text (RFC 9110 8.8.3) */
static int etagc(char ch)
{
    unsigned char c = (unsigned char)ch;
    return c == 0x21 || (c >= 0x23 && c <= 0x7e) || c >= 0x80;
}

int parse_etag_match(const char *h, const char *etag, int weak)
{
    if (!h || !etag)
        return 0;
    const char *s = h;
    while (ows(*s))
        s++;
    if (*s == '*') { /* "*" alone: any current representation */
        s++;
        while (ows(*s))
            s++;
        return *s == 0;
    }
    size_t elen = strlen(etag);
    int hit = 0, any = 0;
    for (;;) {
        while (ows(*s) || *s == ',') /* empty list elements are allowed (RFC 9110 5.6.1) */
            s++;
        if (!*s)
            break;
        int is_weak = s[0] == 'W' && s[1] == '/';
        if (is_weak)
            s += 2;
        if (*s != '"')
            return 0;
        const char *t = s++;
        while (etagc(*s))
            s++;
        if (*s != '"')
            return 0;
        s++;
        size_t n = (size_t)(s - t);
        if ((weak || !is_weak) && n == elen && !memcmp(t, etag, n))
            hit = 1;
        any = 1;
        while (ows(*s))
            s++;
        if (*s && *s != ',')
            return 0;
    }
    return any && hit;
}

static int hexval(char ch)
{
    return ch >= '0' && ch <= '9'   ? ch - '0'
           : ch >= 'a' && ch <= 'f' ? ch - 'a' + 10
           : ch >= 'A' && ch <= 'F' ? ch - 'A' + 10
                                    : -1;
}

/* Decode s in place ('+' as a space, %XX as a byte); the decoded length (strlen is shorter when
 * a %00 was decoded). */
static size_t decode(char *s)
{
    char *o = s;
    for (const char *i = s; *i; i++) {
        int hi, lo;
        if (*i == '+')
            *o++ = ' ';
        else if (*i == '%' && (hi = hexval(i[1])) >= 0 && (lo = hexval(i[2])) >= 0) {
            *o++ = (char)(hi << 4 | lo);
            i += 2;
        } else
            *o++ = *i;
    }
    *o = 0;
    return (size_t)(o - s);
}

int parse_query(char *q, parse_param *out, size_t max, size_t *n)
{
    static const char empty[] = "";
    *n = 0;
    for (char *s = q; s && *s;) {
        char *amp = strchr(s, '&');
        if (amp)
            *amp = 0;
        if (*s) {
            if (*n == max)
                return PARSE_QUERY_TOO_MANY;
            char *eq = strchr(s, '=');
            const char *value = empty;
            if (eq) {
                *eq = 0;
                value = eq + 1;
                size_t vn = decode(eq + 1);
                if (vn != strlen(value))
                    return PARSE_QUERY_NUL;
            }
            size_t kn = decode(s);
            if (kn != strlen(s))
                return PARSE_QUERY_NUL;
            out[*n].key = s;
            out[*n].value = value;
            (*n)++;
        }
        s = amp ? amp + 1 : NULL;
    }
    return PARSE_QUERY_OK;
}

char *parse_log_escape(char *dst, size_t cap, const char *s)
{
    static const char hex[] = "0123456789abcdef";
    size_t o = 0;
    for (; *s; s++) {
        unsigned char c = (unsigned char)*s;
        int esc = c <= 0x20 || c >= 0x7f || c == '\\';
        if (o + (esc ? 4 : 1) >= cap)
            break;
        if (esc) {
            dst[o++] = '\\';
            dst[o++] = 'x';
            dst[o++] = hex[c >> 4];
            dst[o++] = hex[c & 15];
        } else
            dst[o++] = (char)c;
    }
    dst[o] = 0;
    return dst;
}
