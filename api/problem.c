/* problem.c — filling api_problem and rendering it as problem+json (RFC 9457).
 *
 * Filling never allocates (fixed-size buffers, at most API_MAX_FIELD_ERRORS pointers), so a
 * handler can report running out of memory; only api_problem_json builds JSON, and may return
 * NULL, which the transport answers with a bare 500. The core's result codes map to statuses in
 * one place, api_fail_core: NOMEM 503, LIMIT 413, ARG 422, the rest 422 with a pointer.
 */
#include "problem.h"
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static void vset(api_problem *p, int status, const char *slug, const char *fmt, va_list ap)
{
    p->status = status;
    p->slug = slug;
    vsnprintf(p->detail, sizeof p->detail, fmt, ap);
}

int api_fail(api_problem *p, int status, const char *slug, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vset(p, status, slug, fmt, ap);
    va_end(ap);
    return status;
}

static void add_error(api_problem *p, const char *pointer, const char *message)
{
    if (p->nerrors >= API_MAX_FIELD_ERRORS)
        return;
    api_field_error *e = &p->errors[p->nerrors++];
    snprintf(e->pointer, sizeof e->pointer, "%s", pointer ? pointer : "");
    snprintf(e->message, sizeof e->message, "%s", message);
}

int api_fail_at(api_problem *p, int status, const char *slug, const char *pointer,
                const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vset(p, status, slug, fmt, ap);
    va_end(ap);
    p->nerrors = 0;
    add_error(p, pointer, p->detail);
    return status;
}

void api_add_error(api_problem *p, const char *pointer, const char *fmt, ...)
{
    char msg[sizeof p->errors[0].message];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    add_error(p, pointer, msg);
}

int api_fail_limit(api_problem *p, const char *limit_name, uint64_t limit, uint64_t requested,
                   const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vset(p, 413, "limit-exceeded", fmt, ap);
    va_end(ap);
    p->has_limit = 1;
    p->limit_name = limit_name;
    p->limit = limit;
    p->requested = requested;
    return 413;
}

int api_fail_core(api_problem *p, const sd_error *e, const char *item_base, const char *value_base)
{
    char ptr[96] = "";
    switch (e->code) {
    case SD_ERR_NOMEM:
        return api_fail(p, 503, "out-of-memory", "the server ran out of memory: %s; retry later",
                        e->message);
    case SD_ERR_LIMIT:
        return api_fail(p, 413, "limit-exceeded",
                        "%s; raise the daemon's --max-session-bytes or ask for a lower level",
                        e->message);
    case SD_ERR_ARG:
        return api_fail(p, 422, "invalid-argument", "%s", e->message);
    case SD_ERR_EMPTY:
        return api_fail_at(p, 422, "invalid-complex", item_base, "%s", e->message);
    default: {
        /* a bad coordinate or attribute value points into the value array, the rest into the
         * simplex array */
        const char *base = e->code == SD_ERR_VALUE ? value_base : item_base;
        if (base && e->item >= 0) {
            if (e->field >= 0)
                snprintf(ptr, sizeof ptr, "%s/%ld/%d", base, e->item, e->field);
            else
                snprintf(ptr, sizeof ptr, "%s/%ld", base, e->item);
        }
        break;
    }
    }
    return api_fail_at(p, 422, "invalid-complex", ptr, "%s", e->message);
}

const char *api_status_title(int status)
{
    switch (status) {
    case 400: return "Bad Request";
    case 401: return "Unauthorized";
    case 403: return "Forbidden";
    case 404: return "Not Found";
    case 405: return "Method Not Allowed";
    case 406: return "Not Acceptable";
    case 409: return "Conflict";
    case 410: return "Gone";
    case 412: return "Precondition Failed";
    case 413: return "Content Too Large";
    case 414: return "URI Too Long";
    case 415: return "Unsupported Media Type";
    case 422: return "Unprocessable Content";
    case 428: return "Precondition Required";
    case 429: return "Too Many Requests";
    case 500: return "Internal Server Error";
    case 501: return "Not Implemented";
    case 503: return "Service Unavailable";
    default: return "Error";
    }
}

/* A JSON string of s, which may quote what a client sent (a path, a header, a key cut at a
 * fixed length): bytes that are not valid UTF-8 become '?' instead of failing the whole
 * problem. */
static json_t *text(const char *s)
{
    json_t *j = json_string(s);
    if (j)
        return j;
    char buf[sizeof ((api_problem *)0)->detail];
    size_t n = 0;
    for (; *s && n + 1 < sizeof buf; s++)
        buf[n++] = (unsigned char)*s < 0x80 ? *s : '?';
    buf[n] = 0;
    return json_string(buf);
}

json_t *api_problem_json(const api_problem *p)
{
    char type[96];
    snprintf(type, sizeof type, "/errors/%s", p->slug ? p->slug : "error");
    json_t *o = json_pack("{s:s, s:s, s:i, s:o}", "type", type, "title",
                          api_status_title(p->status), "status", p->status, "detail",
                          text(p->detail));
    if (!o)
        return NULL;
    if (p->nerrors) {
        json_t *a = json_array();
        for (int i = 0; i < p->nerrors; i++)
            json_array_append_new(a, json_pack("{s:o, s:o}", "pointer", text(p->errors[i].pointer),
                                               "message", text(p->errors[i].message)));
        json_object_set_new(o, "errors", a);
    }
    if (p->has_limit) {
        json_object_set_new(o, "limit_name", json_string(p->limit_name ? p->limit_name : ""));
        json_object_set_new(o, "limit", json_integer((json_int_t)p->limit));
        json_object_set_new(o, "requested", json_integer((json_int_t)p->requested));
    }
    return o;
}
