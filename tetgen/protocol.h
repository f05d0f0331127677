/* protocol.h — the pipe protocol between subdivd (api/fill.c) and its TetGen helper
 * (tetgen/helper.c, the executable subdivd-tetgen).
 *
 * One request and one reply per process, binary, in the machine's own byte order (the helper
 * is built with the daemon and runs on the same machine):
 *
 *   request on the helper's stdin:   sdtg_request, then npoints * 3 doubles (x y z), then
 *                                    ntriangles * 3 uint32 (0-based indices into the points)
 *   reply on the helper's stdout:    sdtg_reply, then by status
 *     SDTG_OK          n1 points (3 doubles each: the request's points first, unchanged, then the
 *                      Steiner points TetGen added) and n2 tetrahedra (4 uint32 each)
 *     SDTG_INTERSECT   n1 triangles (3 uint32 each) that intersect another triangle (TetGen -d)
 *     SDTG_TETGEN      n1 = the code TetGen threw (see tetgen/shim.h)
 *     SDTG_NOMEM       the helper ran out of memory (its RLIMIT_AS)
 *     SDTG_BAD_REQUEST the request was malformed (a bug in the daemon, never the user's input)
 *
 * The helper prints TetGen's own messages on stderr. It exits 0 after a reply; a crash (Debian's
 * TetGen 1.5 segfaults on some bad surfaces) or a limit (SIGXCPU, SIGKILL) ends it without one.
 */
#ifndef SUBDIVD_TETGEN_PROTOCOL_H
#define SUBDIVD_TETGEN_PROTOCOL_H

#include <stdint.h>

#define SDTG_REQUEST_MAGIC 0x31515453u   /* "STQ1" */
#define SDTG_REPLY_MAGIC 0x31525453u     /* "STR1" */
#define SDTG_MAX_POINTS (1u << 26)       /* sanity bounds of a request */
#define SDTG_MAX_TRIANGLES (1u << 27)

enum { SDTG_OK = 0, SDTG_INTERSECT = 1, SDTG_TETGEN = 2, SDTG_NOMEM = 3, SDTG_BAD_REQUEST = 4 };

typedef struct sdtg_request {
    uint32_t magic, npoints, ntriangles, flags; /* flags: SDTG_VERBOSE */
    double max_volume;                          /* TetGen -a; 0 = no bound */
    double min_ratio;                           /* TetGen -q radius-edge ratio; 0 = no quality */
} sdtg_request;

#define SDTG_VERBOSE 1u                         /* let TetGen print its progress on stderr */

typedef struct sdtg_reply {
    uint32_t magic, status, n1, n2;
} sdtg_reply;

#endif
