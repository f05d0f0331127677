/* fill_helper.c — the TetGen helper process (tetgen/helper.c) as seen from the daemon: spawn it,
 * send one surface through the pipe protocol of tetgen/protocol.h, collect its reply and stderr
 * under a wall deadline, reap it, and turn how it ended into a problem.
 *
 * TetGen runs out of process because Debian's TetGen 1.5 crashes on some bad surfaces and is not
 * thread-safe. posix_spawn with every descriptor but the three pipes closed (no listening socket or
 * client leaks in), default signal dispositions and an empty mask; a socket for the request, sent
 * with MSG_NOSIGNAL (a helper that died early must not SIGPIPE the daemon); poll() until the
 * deadline; SIGKILL and waitpid for that child only. The reply's size is checked against the
 * limits from its header before the payload is allocated.
 *
 * The deadline is the whole fill's: every entry of one request shares --fill-timeout (the
 * caller passes one absolute deadline; each helper's CPU limit is what is left of it). The
 * helper dies with the daemon (PR_SET_PDEATHSIG, tetgen/helper.c, told our pid with --parent):
 * Linux delivers that when the spawning *thread* ends, so one thread spawns, pumps and reaps the
 * helper, as api_fill_run_helper does — it must never hand a running helper to another thread.
 *
 * How the helper's end maps to answers:
 *   reply OK                      -> 0: the tetrahedra, checked by fill_check.c (500 if bad)
 *   reply INTERSECT               -> 422 naming the triangles TetGen -d found intersecting
 *   reply TETGEN code             -> 422 with TetGen's meaning of the code
 *   reply NOMEM, SIGXCPU, deadline -> 413 (fill_memory_bytes, fill_seconds)
 *   SIGSEGV/SIGABRT/SIGBUS/SIGFPE -> 422: Debian's TetGen crashes on some bad surfaces
 *   cannot start, bad reply        -> 500
 */
#include "fill_internal.h"
#include "mem.h"
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

extern char **environ;

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + t.tv_nsec * 1e-9;
}

double api_fill_deadline(const api_limits *lim)
{
    return now_s() + (lim->fill_seconds ? lim->fill_seconds : API_DEFAULT_FILL_SECONDS);
}

static void helper_path(const api_limits *lim, char *buf, size_t cap, int *search)
{
    *search = 0;
    if (lim->tetgen_helper[0]) {
        snprintf(buf, cap, "%s", lim->tetgen_helper);
        *search = !strchr(buf, '/');
        return;
    }
    char exe[PATH_MAX - 32];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (n > 0) {
        exe[n] = 0;
        char *slash = strrchr(exe, '/');
        if (slash) {
            *slash = 0;
            snprintf(buf, cap, "%s/subdivd-tetgen", exe);
            if (!access(buf, X_OK))
                return;
        }
    }
    snprintf(buf, cap, "subdivd-tetgen");
    *search = 1;
}

static void keep_err(helper_out *h, const char *b, size_t n)
{
    size_t cap = sizeof h->err - 1;
    if (n >= cap) {
        memcpy(h->err, b + n - cap, cap);
        h->err_len = cap;
    } else {
        if (h->err_len + n > cap) {
            size_t drop = h->err_len + n - cap;
            memmove(h->err, h->err + drop, h->err_len - drop);
            h->err_len -= drop;
        }
        memcpy(h->err + h->err_len, b, n);
        h->err_len += n;
    }
    h->err[h->err_len] = 0;
}

/* The reply header arrived: size the payload, refusing what the limits cannot take. */
static int size_payload(helper_out *h)
{
    const sdtg_reply *r = &h->rep;
    if (r->magic != SDTG_REPLY_MAGIC)
        return h->protocol = 1, -1;
    uint64_t n = 0;
    if (r->status == SDTG_OK) {
        if (r->n1 < h->nloc) /* TetGen merged points it found coincident */
            return h->merged = 1, -1;
        if (r->n1 - h->nloc > h->room_vertices)
            return h->too_big = 1, h->too_big_n = r->n1 - h->nloc, -1;
        if (r->n2 > h->room_simplices)
            return h->too_big = 2, h->too_big_n = r->n2, -1;
        n = (uint64_t)r->n1 * 3 * sizeof(double) + (uint64_t)r->n2 * 4 * sizeof(uint32_t);
    } else if (r->status == SDTG_INTERSECT) {
        if (r->n1 > h->ntri)
            return h->protocol = 1, -1;
        n = (uint64_t)r->n1 * 3 * sizeof(uint32_t);
    } else if (r->status > SDTG_BAD_REQUEST)
        return h->protocol = 1, -1;
    h->payload_len = (size_t)n;
    h->payload = api_malloc(n ? n : 1);
    return h->payload ? 0 : (h->too_big = 3, -1);
}

/* The request in one buffer: header, points, triangles. NULL when out of memory. */
static unsigned char *request(const surface *s, size_t *len)
{
    sdtg_request rq = {SDTG_REQUEST_MAGIC, s->nloc, s->nt, 0, s->max_volume, s->min_ratio};
    *len = sizeof rq + 3 * (size_t)s->nloc * sizeof(double) + 3 * (size_t)s->nt * sizeof(uint32_t);
    unsigned char *req = api_malloc(*len);
    if (!req)
        return NULL;
    memcpy(req, &rq, sizeof rq);
    memcpy(req + sizeof rq, s->xyz, 3 * (size_t)s->nloc * sizeof(double));
    memcpy(req + sizeof rq + 3 * (size_t)s->nloc * sizeof(double), s->ltri,
           3 * (size_t)s->nt * sizeof(uint32_t));
    return req;
}

/* Start the helper on a request socket and two pipes; fd[0..2] get our ends of its stdin,
 * stdout and stderr. 0, or -1 with `why`. */
static int spawn(const api_limits *lim, double deadline, pid_t *pid, int fd[3], char *why,
                 size_t cap)
{
    char path[PATH_MAX], mem[32], cpu[32], parent[32];
    int search;
    helper_path(lim, path, sizeof path, &search);
    snprintf(mem, sizeof mem, "%llu", (unsigned long long)lim->fill_memory_bytes);
    snprintf(cpu, sizeof cpu, "%.0f", fmax(1, ceil(deadline - now_s())));
    snprintf(parent, sizeof parent, "%ld", (long)getpid());
    char *argv[] = {path, "--max-bytes", mem, "--cpu-seconds", cpu, "--parent", parent, NULL};
    int sv[2] = {-1, -1}, po[2] = {-1, -1}, pe[2] = {-1, -1};
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) || pipe2(po, O_CLOEXEC) ||
        pipe2(pe, O_CLOEXEC)) {
        snprintf(why, cap, "cannot create pipes: %s", strerror(errno));
        for (int i = 0; i < 2; i++) {
            if (sv[i] >= 0) close(sv[i]);
            if (po[i] >= 0) close(po[i]);
            if (pe[i] >= 0) close(pe[i]);
        }
        return -1;
    }
    posix_spawn_file_actions_t fa;
    posix_spawnattr_t at;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, sv[1], 0);
    posix_spawn_file_actions_adddup2(&fa, po[1], 1);
    posix_spawn_file_actions_adddup2(&fa, pe[1], 2);
    posix_spawn_file_actions_addclosefrom_np(&fa, 3); /* no listening socket or client leaks in */
    posix_spawnattr_init(&at);
    sigset_t none, all;
    sigemptyset(&none);
    sigfillset(&all);
    posix_spawnattr_setsigmask(&at, &none);
    posix_spawnattr_setsigdefault(&at, &all); /* the daemon ignores SIGPIPE; the helper must not */
    posix_spawnattr_setflags(&at, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
    int err = search ? posix_spawnp(pid, path, &fa, &at, argv, environ)
                     : posix_spawn(pid, path, &fa, &at, argv, environ);
    posix_spawn_file_actions_destroy(&fa);
    posix_spawnattr_destroy(&at);
    close(sv[1]);
    close(po[1]);
    close(pe[1]);
    if (err) {
        snprintf(why, cap, "cannot start the TetGen helper \"%s\": %s", path, strerror(err));
        close(sv[0]);
        close(po[0]);
        close(pe[0]);
        return -1;
    }
    fd[0] = sv[0];
    fd[1] = po[0];
    fd[2] = pe[0];
    return 0;
}

/* One read from the helper's stdout: the reply header, then exactly the payload it announced.
 * Returns 1 to stop reading (the descriptor closed: *fd = -1), -1 to give up on the helper. */
static int read_reply(helper_out *h, int *fd, char *buf, size_t cap)
{
    ssize_t got;
    if (h->hdr_got < sizeof h->rep)
        got = read(*fd, (char *)&h->rep + h->hdr_got, sizeof h->rep - h->hdr_got);
    else if (h->payload_got < h->payload_len)
        got = read(*fd, h->payload + h->payload_got, h->payload_len - h->payload_got);
    else if ((got = read(*fd, buf, cap)) > 0) {
        h->protocol = 1; /* more than the reply announced */
        return -1;
    }
    if (got > 0) {
        if (h->hdr_got < sizeof h->rep) {
            h->hdr_got += (size_t)got;
            if (h->hdr_got == sizeof h->rep && size_payload(h))
                return -1;
        } else
            h->payload_got += (size_t)got;
    } else if (got == 0 || (errno != EAGAIN && errno != EINTR)) {
        close(*fd);
        *fd = -1;
        return 1;
    }
    return 0;
}

/* Send the request and read the reply and stderr until both close, the deadline passes
 * (h->timed_out) or the reply is refused. Closes the three descriptors. */
static void pump(helper_out *h, int fd[3], const unsigned char *req, size_t len, double deadline)
{
    int fin = fd[0], fout = fd[1], ferr = fd[2];
    fcntl(fout, F_SETFL, O_NONBLOCK);
    fcntl(ferr, F_SETFL, O_NONBLOCK);
    size_t off = 0;
    char buf[1 << 16];
    while (fout >= 0 || ferr >= 0) {
        double left = deadline - now_s();
        if (left <= 0) {
            h->timed_out = 1;
            break;
        }
        struct pollfd pf[3];
        int n = 0, iin = -1, iout = -1, ierr = -1;
        if (fin >= 0)
            iin = n, pf[n++] = (struct pollfd){fin, POLLOUT, 0};
        if (fout >= 0)
            iout = n, pf[n++] = (struct pollfd){fout, POLLIN, 0};
        if (ferr >= 0)
            ierr = n, pf[n++] = (struct pollfd){ferr, POLLIN, 0};
        int r = poll(pf, (nfds_t)n, (int)(left * 1000) + 1);
        if (r < 0 && errno == EINTR)
            continue;
        if (r < 0)
            break;
        if (iin >= 0 && pf[iin].revents) {
            ssize_t w = send(fin, req + off, len - off > (1u << 20) ? (1u << 20) : len - off,
                             MSG_NOSIGNAL | MSG_DONTWAIT);
            if (w > 0)
                off += (size_t)w;
            if ((w < 0 && errno != EAGAIN && errno != EINTR) || off == len) {
                close(fin); /* done, or the helper stopped reading: it will say why */
                fin = -1;
            }
        }
        if (iout >= 0 && pf[iout].revents && read_reply(h, &fout, buf, sizeof buf) < 0)
            break;
        if (ierr >= 0 && pf[ierr].revents) {
            ssize_t got = read(ferr, buf, sizeof buf);
            if (got > 0)
                keep_err(h, buf, (size_t)got);
            else if (got == 0 || (errno != EAGAIN && errno != EINTR)) {
                close(ferr);
                ferr = -1;
            }
        }
    }
    if (fin >= 0) close(fin);
    if (fout >= 0) close(fout);
    if (ferr >= 0) close(ferr);
}

/* Reap the child: it has closed its output (or we gave up on it); wait until the deadline, then
 * SIGKILL it. */
static void reap(helper_out *h, pid_t pid, double deadline)
{
    int killed = 0;
    for (;;) {
        pid_t w = waitpid(pid, &h->wstatus, killed ? 0 : WNOHANG);
        if (w == pid)
            break;
        if (w < 0 && errno != EINTR) {
            h->wstatus = 0;
            break;
        }
        if (w == 0 && (h->timed_out || h->too_big || h->protocol || h->merged ||
                       now_s() >= deadline)) {
            if (!h->too_big && !h->protocol && !h->merged)
                h->timed_out = 1;
            kill(pid, SIGKILL);
            killed = 1;
        } else if (w == 0) {
            struct timespec ts = {0, 1000000};
            nanosleep(&ts, NULL);
        }
    }
}

int api_fill_run_helper(const api_limits *lim, const surface *s, double deadline, helper_out *h,
                        char *why, size_t cap)
{
    if (now_s() >= deadline) { /* the entries before this one took the fill's time */
        h->timed_out = 1;
        return 0;
    }
    size_t len;
    unsigned char *req = request(s, &len);
    if (!req) {
        snprintf(why, cap, "out of memory");
        return -1;
    }
    pid_t pid;
    int fd[3];
    if (spawn(lim, deadline, &pid, fd, why, cap)) {
        api_free(req);
        return -1;
    }
    pump(h, fd, req, len, deadline);
    api_free(req);
    reap(h, pid, deadline);
    return 0;
}

static const char *tetgen_code_text(uint32_t code)
{
    switch (code) {
    case 2: return "TetGen stopped with an internal error on this surface";
    case 3: return "TetGen found a self-intersection";
    case 4: return "TetGen found a very small input feature (points or edges almost touching)";
    case 5: return "TetGen found two very close facets";
    case 10: return "TetGen found an input error";
    default: return "TetGen stopped";
    }
}

/* The helper's stderr as one line for a detail (or ""). */
static void err_line(const helper_out *h, char *dst, size_t cap)
{
    size_t n = 0;
    for (size_t i = 0; i < h->err_len && n + 1 < cap; i++)
        dst[n++] = h->err[i] == '\n' || h->err[i] == '\r' ? ' ' : h->err[i];
    while (n && dst[n - 1] == ' ')
        n--;
    dst[n] = 0;
}

int api_fill_judge(const helper_out *h, const surface *s, size_t k, const api_limits *lim,
                   api_problem *p)
{
    char ptr[96], tail[400];
    snprintf(ptr, sizeof ptr, "/fill/%zu/surface", k);
    err_line(h, tail, sizeof tail);
    unsigned secs = lim->fill_seconds ? lim->fill_seconds : API_DEFAULT_FILL_SECONDS;
    if (h->too_big == 1 || h->too_big == 2)
        return api_fail_limit(p, h->too_big == 1 ? "max_vertices" : "max_simplices",
                              h->too_big == 1 ? lim->max_vertices : lim->max_simplices,
                              h->too_big_n, "TetGen made %u %s, more than the complex may hold; ask "
                              "for fewer (a larger max_volume)", h->too_big_n,
                              h->too_big == 1 ? "new points" : "tetrahedra");
    if (h->too_big == 3)
        return api_fail(p, 503, "out-of-memory", "out of memory reading TetGen's result");
    if (h->merged)
        return api_fail_at(p, 422, "invalid-surface", ptr,
                           "TetGen found points of the surface closer than its tolerance (1e-8 of "
                           "the surface's size) and merged them; move them apart or merge them in "
                           "the posted surface");
    if (h->protocol)
        return api_fail(p, 500, "fill-failed", "the TetGen helper sent a malformed reply%s%s",
                        tail[0] ? ": " : "", tail);
    int sig = WIFSIGNALED(h->wstatus) ? WTERMSIG(h->wstatus) : 0;
    if (h->timed_out || sig == SIGXCPU || (sig == SIGKILL && !h->hdr_got))
        return api_fail_limit(p, "fill_seconds", secs, secs + 1,
                              "TetGen did not finish within %u s (the time of all fill entries "
                              "together); ask for fewer tetrahedra (a larger max_volume or "
                              "min_ratio) or raise --fill-timeout", secs);
    if (sig)
        return api_fail_at(p, 422, "invalid-surface", ptr,
                           "TetGen crashed on this surface (signal %d, %s). Debian's TetGen 1.5 "
                           "does so on surfaces that intersect themselves or have (nearly) "
                           "coincident points or tiny features; the surface passed the checks for "
                           "closed, orientable and non-degenerate triangles%s%s", sig,
                           strsignal(sig), tail[0] ? ". TetGen said: " : "", tail);
    if (h->hdr_got < sizeof h->rep || h->payload_got < h->payload_len)
        return api_fail(p, 500, "fill-failed", "the TetGen helper ended without a proper reply "
                        "(exit %d)%s%s", WIFEXITED(h->wstatus) ? WEXITSTATUS(h->wstatus) : -1,
                        tail[0] ? ": " : "", tail);
    const sdtg_reply *r = &h->rep;
    if (r->status == SDTG_NOMEM)
        return api_fail_limit(p, "fill_memory_bytes", lim->fill_memory_bytes,
                              lim->fill_memory_bytes + 1,
                              "TetGen ran out of its %llu bytes of memory; ask for fewer tetrahedra "
                              "(a larger max_volume) or raise --fill-memory",
                              (unsigned long long)lim->fill_memory_bytes);
    if (r->status == SDTG_BAD_REQUEST)
        return api_fail(p, 500, "fill-failed", "the TetGen helper refused its request%s%s",
                        tail[0] ? ": " : "", tail);
    if (r->status == SDTG_TETGEN)
        return api_fail_at(p, 422, "invalid-surface", ptr, "%s (TetGen code %u)%s%s",
                           tetgen_code_text(r->n1), r->n1, tail[0] ? ": " : "", tail);
    if (r->status == SDTG_INTERSECT) {
        /* name the triangles: look each reported vertex triple up among the surface's */
        uint32_t *keys = api_malloc(4 * (size_t)s->nt * sizeof *keys);
        if (!keys)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        for (uint32_t j = 0; j < s->nt; j++) {
            memcpy(keys + 4 * (size_t)j, s->ltri + 3 * (size_t)j, 3 * sizeof *keys);
            api_fill_sort3(keys + 4 * (size_t)j);
            keys[4 * (size_t)j + 3] = j;
        }
        qsort(keys, s->nt, 4 * sizeof *keys, api_fill_cmp_u32x3);
        const uint32_t *f = (const uint32_t *)h->payload;
        api_fail_at(p, 422, "invalid-surface", ptr,
                    "TetGen found %u triangles of the surface intersecting other triangles; a "
                    "fill surface must not intersect itself", r->n1);
        p->nerrors = 0;
        for (uint32_t i = 0; i < r->n1; i++) {
            uint32_t key[4] = {f[3 * i], f[3 * i + 1], f[3 * i + 2], 0};
            api_fill_sort3(key);
            const uint32_t *hit = bsearch(key, keys, s->nt, 4 * sizeof *keys, api_fill_cmp_u32x3);
            if (!hit)
                continue;
            char tp[96];
            const uint32_t *g = s->tri + 3 * (size_t)hit[3];
            api_fill_tri_ptr(tp, sizeof tp, k, hit[3]);
            api_add_error(p, tp, "triangle %u (%u, %u, %u) intersects another triangle of the "
                          "surface", hit[3], g[0], g[1], g[2]);
        }
        if (!p->nerrors)
            api_add_error(p, ptr, "%s", p->detail);
        api_free(keys);
        return 422;
    }
    /* SDTG_OK: the input points come back first and unchanged, indices are in range */
    const double *pts = (const double *)h->payload;
    const uint32_t *tets = (const uint32_t *)(h->payload + (size_t)r->n1 * 3 * sizeof(double));
    if (!r->n2)
        return api_fail_at(p, 422, "invalid-surface", ptr, "TetGen made no tetrahedra from this "
                           "surface%s%s", tail[0] ? ": " : "", tail);
    if (memcmp(pts, s->xyz, 3 * (size_t)s->nloc * sizeof *pts))
        return api_fail(p, 500, "fill-failed", "TetGen moved points of the surface");
    for (size_t i = 3 * (size_t)s->nloc; i < 3 * (size_t)r->n1; i++)
        if (!isfinite(pts[i]))
            return api_fail(p, 500, "fill-failed", "TetGen made a point with a non-finite coordinate");
    for (size_t i = 0; i < 4 * (size_t)r->n2; i++)
        if (tets[i] >= r->n1)
            return api_fail(p, 500, "fill-failed", "TetGen made a tetrahedron with a bad index");
    return 0;
}
