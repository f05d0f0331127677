/* shim.h — the C face of TetGen 1.5 (Debian libtet1.5), used only by the helper subdivd-tetgen.
 *
 * No C++ type crosses this header: points are xyz triples of doubles, triangles and tetrahedra
 * index triples/quadruples of uint32 (0-based). Output arrays are malloc'ed and owned by the
 * caller (free()). TetGen is not thread-safe (its exact predicates keep file-static state reset
 * per input) and Debian's build crashes on some bad inputs instead of throwing, which is why it
 * runs in its own process: see tetgen/helper.c and api/fill.c.
 */
#ifndef SUBDIVD_TETGEN_SHIM_H
#define SUBDIVD_TETGEN_SHIM_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Results: 0 = done; > 0 = the code TetGen threw (1 out of memory, 2 internal error,
 * 3 self-intersection, 4 very small input feature, 5 two very close facets, 10 input error);
 * SDTG_SHIM_NOMEM = std::bad_alloc (the helper's memory limit). */
#define SDTG_SHIM_NOMEM (-1)

/* TetGen's -d check of the closed surface (xyz: np points; tri: nt triangles): on return
 * *faces lists *nfaces triangles (vertex triples) that intersect some other triangle. */
int sdtg_detect(const double *xyz, uint32_t np, const uint32_t *tri, uint32_t nt,
                uint32_t **faces, uint32_t *nfaces);

/* Tetrahedralize the inside of the closed surface: switches -pYz (PLC, surface kept as is,
 * 0-based), plus -q<min_ratio> when min_ratio > 0 and -a<max_volume> when max_volume > 0.
 * *points: *npoints xyz triples, the input points first and unchanged, then Steiner points;
 * *tets: *ntets quadruples. `verbose` lets TetGen print its progress on stdout. */
int sdtg_tetrahedralize(const double *xyz, uint32_t np, const uint32_t *tri, uint32_t nt,
                        double max_volume, double min_ratio, int verbose, double **points,
                        uint32_t *npoints, uint32_t **tets, uint32_t *ntets);

#ifdef __cplusplus
}
#endif

#endif
