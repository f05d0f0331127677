/* fill.h — the "fill" member of PUT /complex: TetGen tetrahedralizes closed triangle surfaces and
 * the tetrahedra join the complex (docs/API.md "Control complex", docs/SERVICE.md "Fill").
 *
 * Each entry {"surface": [[i,j,k]...], "max_volume": v, "min_ratio": r} names triangles by indices
 * into the posted vertices. The surface is checked first (closed, consistently orientable, no
 * repeated, degenerate or duplicate triangles, no coincident points, a non-flat bounding box), so
 * that most bad surfaces get a 422 pointing at the triangle (/fill/0/surface/7) without TetGen.
 * Then TetGen runs in the helper process subdivd-tetgen (tetgen/helper.c), one process per entry,
 * with a memory limit, a CPU limit and a wall deadline, because Debian's TetGen 1.5 crashes on
 * some bad surfaces and is not thread-safe: what it finds (intersecting triangles, a crash, a
 * limit) becomes a 422, a 413 or a 500, and never reaches the daemon.
 *
 * The surface is kept as posted (TetGen -Y: no Steiner points on it), so the tetrahedra share the
 * surface's vertices and triangles with the rest of the complex. Steiner points inside are
 * appended to the vertices and the tetrahedra to the simplices; attributes of the new points are
 * the harmonic interpolation of the surface values over the new tetrahedra's edges.
 */
#ifndef SUBDIVD_FILL_H
#define SUBDIVD_FILL_H

#include "limits.h"
#include "model.h"
#include "packed.h"
#include "problem.h"
#include <jansson.h>

/* Validate and run every entry of `fill` (the JSON value of the member) against `in`, whose
 * vertices, simplices and attributes are parsed already; appends the results to `in` and records
 * in->fill. The surfaces are read packed where `packs` (may be NULL) holds them
 * (/fill/k/surface, api/rows.h). 0, or the problem's status (in may then hold part of the
 * results: drop it). */
int api_fill(json_t *fill, const api_packs *packs, api_input *in, const api_limits *lim,
             api_problem *p);

/* After the core refused the filled complex: point errors that name a generated vertex or
 * tetrahedron (index >= nv_posted / ns_posted) at the "fill" entry that made it. */
void api_fill_blame(const api_input *in, uint32_t nv_posted, uint32_t ns_posted, api_problem *p);

/* summary.fill: one object per entry (new reference; NULL when nothing was filled). */
json_t *api_fill_summary(const api_input *in);

#endif
