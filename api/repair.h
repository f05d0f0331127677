/* repair.h — PUT /complex "repair" (api/repair.c). */
#ifndef SUBDIVD_API_REPAIR_H
#define SUBDIVD_API_REPAIR_H

#include "handlers.h"

/* Drop the simplices of `in` the core would refuse one by one (repeated vertex, degenerate,
 * duplicate), renumber its diagonals and reoriented flags, and set in->repaired (a new
 * reference the input owns). 0, or 503 for lack of memory. A complex the core refuses as a
 * whole is left as it is (its build answers the same problem as without repair). */
int api_repair(api_input *in, api_problem *p);

/* Add "repaired", "repaired_count" (and "repaired_ignored", "repaired_ignored_count" when
 * diagonals were ignored) to a summary object, when the input was repaired. */
void api_repair_summary(const api_input *in, json_t *summary);

#endif
