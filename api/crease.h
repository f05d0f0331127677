/* crease.h — PUT /tags "crease_angle" (api/crease.c). */
#ifndef SUBDIVD_API_CREASE_H
#define SUBDIVD_API_CREASE_H

#include "handlers.h"

/* Validate "crease_angle" (`v`, at /crease_angle: a number, 0..180 degrees) and append to
 * `tags` (C-library arrays, grown here) every surface edge of cur's level 0 whose dihedral
 * angle is greater, and record it in tags->crease. 0, or the problem's status (400, 409, 422,
 * 503); on failure the tags' arrays are still the caller's to free. */
int api_crease_tags(const api_model *cur, json_t *v, api_tags *tags, api_problem *p);

/* {"degrees", "tagged"} of the crease angle behind the tags (a new reference), or NULL. */
json_t *api_crease_json(const api_tags *tags);

#endif
