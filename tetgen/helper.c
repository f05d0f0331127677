/* helper.c — subdivd-tetgen: runs TetGen once on a closed triangle surface, in its own process.
 *
 * Why a process: Debian's TetGen 1.5 segfaults (rather than throwing) on self-intersecting or
 * coincident input, and it is not thread-safe. The daemon (api/fill.c) spawns this program per
 * fill, writes one request on its stdin and reads one reply from its stdout (tetgen/protocol.h),
 * under a wall deadline; this program sets its own memory and CPU limits first:
 *
 *     subdivd-tetgen [--max-bytes N] [--cpu-seconds S] [--parent PID]   (the protocol on stdio)
 *     subdivd-tetgen --selftest                             (fills a cube, prints a line)
 *
 * The helper dies with the daemon: first thing, it asks the kernel for SIGKILL when its parent
 * goes (prctl PR_SET_PDEATHSIG — posix_spawn cannot set it for the child), then checks that its
 * parent is still the daemon that named itself with --parent, since the daemon may have died
 * before the request was made. Linux sends that signal when the *thread* that spawned the
 * helper ends, not only the process: the daemon spawns and reaps it on one thread
 * (api/fill_helper.c), which lives until then.
 *
 * Steps: read the request; TetGen -d (self-intersection check, which reports instead of
 * crashing); then TetGen -pYz[q][a] (tetrahedralize, keeping the surface triangles as they are).
 * SUBDIVD_TETGEN_NO_DETECT=1 in the environment skips the -d pass: a test hook that lets the
 * tests see Debian's TetGen crash on a self-intersecting surface, and the daemon survive it.
 * TetGen's messages go to stderr: stdout is moved to a private descriptor for the reply, and
 * fd 1 is pointed at stderr, unbuffered, so whatever TetGen printed before a crash is kept.
 */
#include "protocol.h"
#include "shim.h"
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <signal.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <unistd.h>

static int read_full(int fd, void *buf, size_t n)
{
    char *p = buf;
    while (n) {
        ssize_t r = read(fd, p, n > (1u << 30) ? (1u << 30) : n);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0)
            return -1;
        p += r;
        n -= (size_t)r;
    }
    return 0;
}

static int write_full(int fd, const void *buf, size_t n)
{
    const char *p = buf;
    while (n) {
        ssize_t w = write(fd, p, n > (1u << 30) ? (1u << 30) : n);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            return -1;
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

static int reply(int fd, uint32_t status, uint32_t n1, uint32_t n2)
{
    sdtg_reply r = {SDTG_REPLY_MAGIC, status, n1, n2};
    return write_full(fd, &r, sizeof r);
}

static void set_limit(int resource, unsigned long long soft, unsigned long long hard)
{
    struct rlimit rl = {(rlim_t)soft, (rlim_t)hard};
    if (setrlimit(resource, &rl))
        fprintf(stderr, "subdivd-tetgen: setrlimit: %s\n", strerror(errno));
}

/* A unit cube (8 points, 12 triangles) through the whole path: a check that TetGen works. */
static int selftest(void)
{
    static const double xyz[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1};
    static const uint32_t tri[] = {0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4,
                                   1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6, 3, 0, 4, 3, 4, 7};
    double *pts;
    uint32_t *tets, np, nt;
    int rc = sdtg_tetrahedralize(xyz, 8, tri, 12, 0.01, 1.5, 0, &pts, &np, &tets, &nt);
    double vol = 0;
    for (uint32_t t = 0; !rc && t < nt; t++) {
        const double *a = pts + 3 * tets[4 * t], *b = pts + 3 * tets[4 * t + 1],
                     *c = pts + 3 * tets[4 * t + 2], *d = pts + 3 * tets[4 * t + 3];
        double u[3], v[3], w[3];
        for (int k = 0; k < 3; k++)
            u[k] = b[k] - a[k], v[k] = c[k] - a[k], w[k] = d[k] - a[k];
        double det = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
                     u[2] * (v[0] * w[1] - v[1] * w[0]);
        vol += (det < 0 ? -det : det) / 6;
    }
    free(pts);
    free(tets);
    if (rc) {
        fprintf(stderr, "subdivd-tetgen: selftest failed (TetGen code %d)\n", rc);
        return 1;
    }
    printf("subdivd-tetgen: ok, unit cube -> %u points, %u tetrahedra, volume %.15g\n", np, nt, vol);
    return vol > 1 - 1e-12 && vol < 1 + 1e-12 ? 0 : 1;
}

int main(int argc, char **argv)
{
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    unsigned long long max_bytes = 0, cpu = 0, parent = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--selftest"))
            return selftest();
        if (i + 1 < argc && !strcmp(argv[i], "--max-bytes"))
            max_bytes = strtoull(argv[++i], NULL, 10);
        else if (i + 1 < argc && !strcmp(argv[i], "--cpu-seconds"))
            cpu = strtoull(argv[++i], NULL, 10);
        else if (i + 1 < argc && !strcmp(argv[i], "--parent"))
            parent = strtoull(argv[++i], NULL, 10);
        else {
            fprintf(stderr, "usage: subdivd-tetgen [--max-bytes N] [--cpu-seconds S] [--parent PID]"
                            " | --selftest\n"
                            "(spawned by subdivd for TetGen fill; speaks tetgen/protocol.h)\n");
            return 2;
        }
    }
    if (parent && (unsigned long long)getppid() != parent)
        return 2; /* the daemon died before PR_SET_PDEATHSIG took hold */
    if (max_bytes)
        set_limit(RLIMIT_AS, max_bytes, max_bytes);
    if (cpu) /* SIGXCPU at the soft limit, SIGKILL one second later */
        set_limit(RLIMIT_CPU, cpu, cpu + 1);
    set_limit(RLIMIT_CORE, 0, 0); /* a TetGen crash is expected sometimes: no core files */

    int out = dup(1); /* the reply's channel; fd 1 becomes TetGen's message channel (stderr) */
    if (out < 0 || dup2(2, 1) < 0)
        return 2;
    setvbuf(stdout, NULL, _IONBF, 0);

    sdtg_request rq;
    if (read_full(0, &rq, sizeof rq) || rq.magic != SDTG_REQUEST_MAGIC || rq.npoints < 4 ||
        rq.npoints > SDTG_MAX_POINTS || rq.ntriangles < 4 || rq.ntriangles > SDTG_MAX_TRIANGLES)
        return reply(out, SDTG_BAD_REQUEST, 0, 0) ? 2 : 0;
    double *xyz = malloc(3 * (size_t)rq.npoints * sizeof *xyz);
    uint32_t *tri = malloc(3 * (size_t)rq.ntriangles * sizeof *tri);
    if (!xyz || !tri)
        return reply(out, SDTG_NOMEM, 0, 0) ? 2 : 0;
    if (read_full(0, xyz, 3 * (size_t)rq.npoints * sizeof *xyz) ||
        read_full(0, tri, 3 * (size_t)rq.ntriangles * sizeof *tri))
        return reply(out, SDTG_BAD_REQUEST, 0, 0) ? 2 : 0;
    for (size_t i = 0; i < 3 * (size_t)rq.ntriangles; i++)
        if (tri[i] >= rq.npoints) /* TetGen does not check facet indices */
            return reply(out, SDTG_BAD_REQUEST, 0, 0) ? 2 : 0;

    uint32_t *faces = NULL, nfaces = 0;
    const char *skip = getenv("SUBDIVD_TETGEN_NO_DETECT");
    int rc = skip && !strcmp(skip, "1") ? 0
                                        : sdtg_detect(xyz, rq.npoints, tri, rq.ntriangles, &faces, &nfaces);
    if (!rc && nfaces) {
        int w = reply(out, SDTG_INTERSECT, nfaces, 0) ||
                write_full(out, faces, 3 * (size_t)nfaces * sizeof *faces);
        return w ? 2 : 0;
    }
    free(faces);
    double *pts = NULL;
    uint32_t *tets = NULL, np = 0, nt = 0;
    if (!rc)
        rc = sdtg_tetrahedralize(xyz, rq.npoints, tri, rq.ntriangles, rq.max_volume, rq.min_ratio,
                                 (rq.flags & SDTG_VERBOSE) != 0, &pts, &np, &tets, &nt);
    int w;
    if (rc == SDTG_SHIM_NOMEM || rc == 1)
        w = reply(out, SDTG_NOMEM, 0, 0);
    else if (rc)
        w = reply(out, SDTG_TETGEN, (uint32_t)rc, 0);
    else
        w = reply(out, SDTG_OK, np, nt) || write_full(out, pts, 3 * (size_t)np * sizeof *pts) ||
            write_full(out, tets, 4 * (size_t)nt * sizeof *tets);
    return w ? 2 : 0;
}
