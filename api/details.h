/* details.h — a session's detail offsets in the JSON of GET and PUT /complex (api/details.c). */
#ifndef SUBDIVD_API_DETAILS_H
#define SUBDIVD_API_DETAILS_H

#include "model.h"
#include "problem.h"
#include <jansson.h>

/* The offsets of the positions over all levels (0 without a complex). */
size_t api_details_count(const api_model *m);
/* [{"level", "index", "offset": [x, y, z]}…], by level then index (new reference). */
json_t *api_details_json(const api_model *m);
/* PUT /complex's "details" onto the model just built for it (levels 1..SD_MAX_LEVEL, indices
 * below the level's point count, offsets finite and within 1e15, no point twice; pointers
 * /details/i/...). 0 or the problem's status. */
int api_details_put(api_model *m, json_t *details, api_problem *p);
/* The offsets of `from` onto `to`, a model of the same complex (PUT /tags, PUT /rules). */
int api_details_carry(const api_model *from, api_model *to, api_problem *p);

/* A point of a level with its place in a request, and the order that finds a point named twice
 * (level, then index, then place): PUT /complex's details and PATCH's finer moves. */
typedef struct api_ptkey {
    uint32_t level, index;
    size_t k;
} api_ptkey;
int api_ptkey_cmp(const void *x, const void *y);

#endif
