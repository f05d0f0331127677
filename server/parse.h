/* parse.h — the request's text, read by pure functions: route patterns, bearer credentials,
 * entity-tag lists (If-Match, If-None-Match), the query string, and the escaping of request text
 * written into logs.
 *
 * Nothing here knows libmicrohttpd, a connection or the server: strings in, values out, no
 * allocation, no global state. That keeps every parser of what a client sends in one file,
 * testable and fuzzed alone (tests/fuzz/fuzz_http.c runs them under libFuzzer with ASan and
 * UBSan). Inputs are NUL-terminated strings of any content; outputs are written only within the
 * capacities given.
 */
#ifndef SUBDIVD_PARSE_H
#define SUBDIVD_PARSE_H

#include <stddef.h>

/* Match `path` against a route pattern whose segments are literal or a capture ("{id}", "{L}",
 * "{slug}", "{name}": one non-empty segment). "{id}" and "{slug}" go into id, only if it fits its
 * capacity with its NUL (else no match: no such session or page); any other capture ("{L}", an
 * embedded model's "{name}") into level — one too long for it matches as ROUTE_TOO_LONG, which
 * is neither a number nor a name, so that the handler's own check refuses it naming the
 * parameter. 1 on a match. */
#define ROUTE_TOO_LONG "\x01"
int parse_route(const char *pattern, const char *path, char *id, size_t id_cap, char *level,
                size_t level_cap);

/* The token of an Authorization field value, into buf; NULL unless it is "Bearer <token>" that
 * fits. credentials = auth-scheme 1*SP token68 (RFC 9110 11.4): the scheme is case-insensitive,
 * and trailing whitespace is not part of the field value. */
const char *parse_bearer(const char *h, char *buf, size_t cap);

/* Whether the If-Match or If-None-Match field value `h` matches our entity tag `etag` (a quoted
 * strong tag as sent in ETag, "\"7\""): "*" alone matches any; otherwise h must be a
 * comma-separated list of entity-tags (RFC 9110 8.8.3: [W/] DQUOTE *etagc DQUOTE, optional
 * whitespace and empty elements between them), compared strongly (weak = 0, If-Match: a weak tag
 * never matches) or weakly (weak = 1, If-None-Match: W/ is ignored). The opaque tags are compared
 * exactly, never by substring. A malformed value ("**", an unquoted tag, "*" inside a list)
 * matches nothing. */
int parse_etag_match(const char *h, const char *etag, int weak);

/* One query parameter: key and value point into the decoded query. value is "" for a key
 * without '='. */
typedef struct parse_param {
    const char *key, *value;
} parse_param;

enum { PARSE_QUERY_OK = 0, PARSE_QUERY_TOO_MANY, PARSE_QUERY_NUL };

/* Split the query string q (what follows '?', modified in place) into at most `max` parameters:
 * pairs separated by '&' (empty ones skipped), key and value split at the first '=', each
 * decoded ('+' is a space, %XX a byte; a '%' not followed by two hex digits stays as it is).
 * PARSE_QUERY_TOO_MANY when there are more than max, PARSE_QUERY_NUL when a key or value
 * decodes to a NUL byte; *n is the number of parameters filled in. */
int parse_query(char *q, parse_param *out, size_t max, size_t *n);

/* s as one log-safe word into dst (cap >= 1; truncated to fit, always terminated): bytes up to
 * the space, DEL, bytes of 0x80 and above and the backslash itself are written as \xNN, so a
 * logged path can neither start a new line nor forge a field. Returns dst. */
char *parse_log_escape(char *dst, size_t cap, const char *s);

#endif
