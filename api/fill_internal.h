/* fill_internal.h — what the three files of the TetGen fill share: one fill entry as parsed
 * (`surface`), what the helper process sent back (`helper_out`), and the small geometric helpers.
 *
 *   fill.c         parsing, the order of the steps, appending the tetrahedra (fill.h's contract)
 *   fill_check.c   the checks of a surface before TetGen, and of TetGen's tetrahedra after it
 *   fill_helper.c  the helper process: spawn, pipes, deadline, and its end mapped to a problem
 */
#ifndef SUBDIVD_FILL_INTERNAL_H
#define SUBDIVD_FILL_INTERNAL_H

#include "fill.h"
#include "../tetgen/protocol.h"
#include <stddef.h>
#include <stdint.h>

#define FILL_TOL 1e-12          /* degeneracy, as the core's (docs/DECISIONS.md 7) */
#define FILL_MAX_COORD 1e15

/* One entry, as parsed and checked. Triangles in local numbering: the surface's vertices are
 * renumbered 0..nloc-1 in order of their global index. */
typedef struct surface {
    uint32_t nt, nloc;
    uint32_t *tri;          /* 3 nt, global indices as posted */
    uint32_t *ltri;         /* 3 nt, local */
    uint32_t *glob;         /* nloc: local -> global */
    double *xyz;            /* 3 nloc */
    double max_volume, min_ratio, volume;
} surface;

void api_fill_surface_free(surface *s);

/* What the helper process sent: the reply header and payload, the tail of its stderr, how it
 * ended, and why it was stopped early. */
typedef struct helper_out {
    sdtg_reply rep;
    size_t hdr_got;
    unsigned char *payload;
    size_t payload_len, payload_got;
    char err[1024];         /* the tail of the helper's stderr */
    size_t err_len;
    int wstatus;
    int timed_out, too_big, protocol, merged;
    uint32_t too_big_n, room_vertices, room_simplices, nloc, ntri;
} helper_out;

/* fill_check.c: local numbering, coordinates and every check of fill.h for entry k;
 * s->volume = the enclosed volume. 0 or the problem's status. */
int api_fill_check_surface(surface *s, size_t k, const api_input *in, api_problem *p);
/* fill_check.c: the boundary of TetGen's nt4 tetrahedra (local ids) is the surface. */
int api_fill_check_boundary(const surface *s, const uint32_t *tets, uint32_t nt4, size_t k,
                            api_problem *p);

/* fill_helper.c: the deadline of a fill starting now (monotonic seconds): --fill-timeout for all
 * of its entries together. */
double api_fill_deadline(const api_limits *lim);
/* fill_helper.c: spawn the helper, send the request, collect the reply and stderr until both
 * close or `deadline` passes (h->timed_out, without a helper if it has passed already), then
 * reap the child. 0, or -1 with `why` when it could not be started. h->nloc, ntri, room_* are
 * set by the caller. */
int api_fill_run_helper(const api_limits *lim, const surface *s, double deadline, helper_out *h,
                        char *why, size_t cap);
/* fill_helper.c: the helper's end as a problem, or 0 when its tetrahedra can be checked. */
int api_fill_judge(const helper_out *h, const surface *s, size_t k, const api_limits *lim,
                   api_problem *p);

/* fill_check.c: small helpers. */
void api_fill_sort3(uint32_t v[3]);
int api_fill_cmp_u32x3(const void *x, const void *y);
/* The determinant of (a-o, b-o, c-o): six times the signed volume of the tetrahedron. */
double api_fill_det3(const double *a, const double *b, const double *c, const double *o);
/* "/fill/<k>/surface/<j>" */
void api_fill_tri_ptr(char *dst, size_t cap, size_t k, size_t j);

#endif
