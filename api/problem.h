/* problem.h — RFC 9457 problem details, the one error value of the api/ layer.
 *
 * Handlers fill a caller-owned api_problem (status, slug, detail and up to API_MAX_FIELD_ERRORS
 * field errors, each a JSON pointer into the request plus a message) and the transport turns it
 * into an `application/problem+json` body with api_problem_json(). No allocation happens while
 * a problem is being filled, so reporting never fails.
 */
#ifndef SUBDIVD_PROBLEM_H
#define SUBDIVD_PROBLEM_H

#include "../core/sd.h"
#include <jansson.h>
#include <stdint.h>

#define API_MAX_FIELD_ERRORS 8

typedef struct api_field_error {
    char pointer[96];   /* JSON pointer (RFC 6901) into the request body, or "" */
    char message[320];
} api_field_error;

typedef struct api_problem {
    int status;             /* 0 = no problem */
    const char *slug;       /* type is "/errors/<slug>" (the slugs: docs/SERVICE.md "Errors") */
    char detail[320];
    int nerrors;
    api_field_error errors[API_MAX_FIELD_ERRORS];
    /* optional extension members for limits (RFC 9457 sec. 3.2): set has_limit */
    int has_limit;
    const char *limit_name;
    uint64_t limit, requested;
    int retry_after;        /* seconds, 0 = none (429/503) */
} api_problem;

/* Set status, slug and a printf-style detail; returns the status. Later calls overwrite. */
int api_fail(api_problem *p, int status, const char *slug, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* Same, and add one field error at `pointer` whose message is the detail. */
int api_fail_at(api_problem *p, int status, const char *slug, const char *pointer,
                const char *fmt, ...) __attribute__((format(printf, 5, 6)));
/* Add one more field error (after api_fail_at; ignored beyond API_MAX_FIELD_ERRORS). */
void api_add_error(api_problem *p, const char *pointer, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
/* A limit refusal (413): names the limit, the configured value and what was asked. */
int api_fail_limit(api_problem *p, const char *limit_name, uint64_t limit, uint64_t requested,
                   const char *fmt, ...) __attribute__((format(printf, 5, 6)));
/* Map a core error to a problem: `base` is the JSON pointer of the array the core's `item`
 * indexes (e.g. "/simplices"); `field_base` of the array `field` indexes within it. */
int api_fail_core(api_problem *p, const sd_error *e, const char *item_base, const char *value_base);

/* Human title of a status ("Unprocessable Content", ...). */
const char *api_status_title(int status);
/* New reference: the problem+json object. */
json_t *api_problem_json(const api_problem *p);

#endif
