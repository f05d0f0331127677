/* internal.h — what the handler files of api/ share (not for the transport: see handlers.h).
 *
 * complex.c builds every model and renders numbers as JSON; levels.c checks a level against the
 * limits before anything computes it. Each of these has one definition, used by the handlers of
 * several resources.
 */
#ifndef SUBDIVD_API_INTERNAL_H
#define SUBDIVD_API_INTERNAL_H

#include "handlers.h"

/* Build the model of `in` (borrowed; NULL: no complex) with the rules and tags (either may be
 * NULL), mapping the core's refusals to problems with pointers (/simplices/…, /overrides/…,
 * /singular/…, /petals/…, /attributes/…). 0 and *out (a new reference), or the problem's status.
 * Overrides name simplices: callers pass them with a change of tags or rules, not with a new
 * complex. */
int api_build_model(api_input *in, const api_rules *rules, const api_tags *tags,
                    const api_limits *lim, api_model **out, api_problem *p);

/* A JSON array of n reals (new reference). */
json_t *api_json_doubles(const double *x, size_t n);

/* Level L of the model's complex within max_cells and (with the levels still to compute)
 * max_session_bytes: 0, or the status of a 413 problem naming the limit. */
int api_check_level_limits(api_model *m, int level, const api_limits *lim, api_problem *p);

/* Compute level L of m (and the missing ones below) unless it is cached, taking the model's
 * lock and only then a compute slot from `slot` (NULL: none), so requests that wait for their
 * own session's computation hold no slot. 0 or the problem's status (429, 503). Callers check
 * the query and the limits first. */
int api_level_compute(api_model *m, int level, const api_slot *slot, api_problem *p);

#endif
