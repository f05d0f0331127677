/* fill.c — TetGen fill of closed surfaces (see fill.h for the contract).
 *
 * Per entry of "fill": parse (400/422 with pointers), check the surface (422 with pointers),
 * estimate the work against the limits (413), run the helper process (tetgen/helper.c) through
 * the pipe protocol of tetgen/protocol.h under a wall deadline, check what came back (points
 * unchanged, indices in range, boundary = the surface), then append. Nothing here knows HTTP:
 * the same code serves the daemon and `subdivd refine`.
 *
 * Why this lives in api/ and not server/: a fill is part of building a complex from a request
 * body, like parsing it; the offline mode needs it too. The process handling is local to this
 * file: posix_spawn with every descriptor but the three pipes closed, a socket for the request
 * (send with MSG_NOSIGNAL: a helper that died early must not SIGPIPE the daemon), poll() until the
 * deadline, SIGKILL and waitpid for that child only.
 *
 * How the helper's end maps to answers:
 *   reply OK                      -> the tetrahedra (500 if they are inconsistent)
 *   reply INTERSECT               -> 422 naming the triangles TetGen -d found intersecting
 *   reply TETGEN code             -> 422 with TetGen's meaning of the code
 *   reply NOMEM, SIGXCPU, deadline -> 413 (fill_memory_bytes, fill_seconds)
 *   SIGSEGV/SIGABRT/SIGBUS/SIGFPE -> 422: Debian's TetGen crashes on some bad surfaces
 *   cannot start, bad reply        -> 500
 */
#include "fill.h"
#include "jsonin.h"
#include "../tetgen/protocol.h"
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

#define FILL_TOL 1e-12          /* degeneracy, as the core's (docs/DECISIONS.md 7) */
#define FILL_MAX_COORD 1e15
#define MIN_RATIO_LO 1.0
#define MIN_RATIO_HI 100.0

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

static void surface_free(surface *s)
{
    free(s->tri);
    free(s->ltri);
    free(s->glob);
    free(s->xyz);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + t.tv_nsec * 1e-9;
}

/* ---- parsing ------------------------------------------------------------------------------ */

static int parse_entry(json_t *e, size_t k, const api_input *in, const api_limits *lim,
                       surface *s, api_problem *p)
{
    static const char *const keys[] = {"surface", "max_volume", "min_ratio", NULL};
    char ptr[96], sp[96], at[96], ix[96];
    api_ptr_index(ptr, sizeof ptr, "/fill", k);
    if (!json_is_object(e))
        return api_fail_at(p, 400, "wrong-type", ptr,
                           "a fill entry is an object {\"surface\", \"max_volume\", \"min_ratio\"}");
    if (api_only_keys(e, ptr, keys, p))
        return p->status;
    api_ptr_key(sp, sizeof sp, ptr, "surface");
    json_t *tris = json_object_get(e, "surface");
    if (!tris)
        return api_fail_at(p, 400, "missing-field", sp, "\"surface\" is required: the closed "
                           "surface's triangles as [i, j, k] indices into \"vertices\"");
    if (!json_is_array(tris))
        return api_fail_at(p, 400, "wrong-type", sp, "must be an array of triangles [i, j, k]");
    size_t n = json_array_size(tris);
    if (n > lim->max_simplices)
        return api_fail_limit(p, "max_simplices", lim->max_simplices, n,
                              "the surface has %zu triangles, over the limit of %u simplices", n,
                              lim->max_simplices);
    if (n < 4)
        return api_fail_at(p, 422, "invalid-surface", sp,
                           "%zu triangles cannot close a surface; a closed surface has at least 4", n);
    s->nt = (uint32_t)n;
    s->tri = malloc(3 * n * sizeof *s->tri);
    if (!s->tri)
        return api_fail(p, 503, "out-of-memory", "out of memory reading the surface");
    for (size_t j = 0; j < n; j++) {
        json_t *t = json_array_get(tris, j);
        api_ptr_index(at, sizeof at, sp, j);
        if (!json_is_array(t))
            return api_fail_at(p, 400, "wrong-type", at, "a triangle is an array of 3 vertex indices");
        if (json_array_size(t) != 3)
            return api_fail_at(p, 422, "invalid-surface", at,
                               "a surface triangle has 3 vertex indices, not %zu", json_array_size(t));
        for (size_t m = 0; m < 3; m++) {
            long long x;
            api_ptr_index(ix, sizeof ix, at, m);
            if (!in->nv)
                return api_fail_at(p, 422, "out-of-range", ix, "there are no vertices to index");
            if (api_get_int(json_array_get(t, m), ix, 0, (long long)in->nv - 1, &x, p))
                return p->status;
            for (size_t q = 0; q < m; q++)
                if (s->tri[3 * j + q] == (uint32_t)x)
                    return api_fail_at(p, 422, "invalid-surface", ix,
                                       "vertex %lld appears twice in triangle %zu", x, j);
            s->tri[3 * j + m] = (uint32_t)x;
        }
    }
    json_t *v;
    api_ptr_key(at, sizeof at, ptr, "max_volume");
    if ((v = json_object_get(e, "max_volume"))) {
        if (api_get_number(v, at, 1e300, &s->max_volume, p))
            return p->status;
        if (!(s->max_volume > 0))
            return api_fail_at(p, 422, "out-of-range", at,
                               "max_volume is the largest tetrahedron volume TetGen may make; it "
                               "must be positive");
    }
    api_ptr_key(at, sizeof at, ptr, "min_ratio");
    if ((v = json_object_get(e, "min_ratio"))) {
        if (api_get_number(v, at, 1e300, &s->min_ratio, p))
            return p->status;
        if (!(s->min_ratio >= MIN_RATIO_LO && s->min_ratio <= MIN_RATIO_HI))
            return api_fail_at(p, 422, "out-of-range", at,
                               "min_ratio is TetGen's radius-edge ratio bound (-q): %g is outside "
                               "%g..%g (1.414 is a good choice; smaller is slower)", s->min_ratio,
                               MIN_RATIO_LO, MIN_RATIO_HI);
    }
    return 0;
}

/* ---- checking the surface ------------------------------------------------------------------ */

typedef struct edge_rec {
    uint32_t a, b;      /* a < b, local */
    uint32_t tri;
    uint32_t forward;   /* the triangle runs a -> b */
} edge_rec;

static int cmp_edge(const void *x, const void *y)
{
    const edge_rec *e = x, *f = y;
    if (e->a != f->a)
        return e->a < f->a ? -1 : 1;
    if (e->b != f->b)
        return e->b < f->b ? -1 : 1;
    return e->tri < f->tri ? -1 : e->tri > f->tri;
}

typedef struct tri_key {
    uint32_t v[3];
    uint32_t tri;
} tri_key;

static int cmp_tri_key(const void *x, const void *y)
{
    const tri_key *e = x, *f = y;
    int c = memcmp(e->v, f->v, sizeof e->v);
    return c ? c : (e->tri < f->tri ? -1 : e->tri > f->tri);
}

static void sort3(uint32_t v[3])
{
    uint32_t t;
    if (v[0] > v[1]) t = v[0], v[0] = v[1], v[1] = t;
    if (v[1] > v[2]) t = v[1], v[1] = v[2], v[2] = t;
    if (v[0] > v[1]) t = v[0], v[0] = v[1], v[1] = t;
}

static int by_x(const void *x, const void *y, void *xyz)
{
    const double *c = xyz;
    double a = c[3 * (size_t)*(const uint32_t *)x], b = c[3 * (size_t)*(const uint32_t *)y];
    return a < b ? -1 : a > b;
}

static double det3(const double *a, const double *b, const double *c, const double *o)
{
    double u[3], v[3], w[3];
    for (int k = 0; k < 3; k++)
        u[k] = a[k] - o[k], v[k] = b[k] - o[k], w[k] = c[k] - o[k];
    return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
           u[2] * (v[0] * w[1] - v[1] * w[0]);
}

static void tri_ptr(char *dst, size_t cap, size_t k, size_t j)
{
    snprintf(dst, cap, "/fill/%zu/surface/%zu", k, j);
}

/* Local numbering, coordinates, and every check of fill.h; s->volume = the enclosed volume. */
static int check_surface(surface *s, size_t k, const api_input *in, api_problem *p)
{
    char ptr[96];
    uint32_t nt = s->nt;
    uint32_t *map = malloc(((size_t)in->nv + 1) * sizeof *map);
    uint32_t *first = malloc(((size_t)in->nv + 1) * sizeof *first);
    s->ltri = malloc(3 * (size_t)nt * sizeof *s->ltri);
    edge_rec *er = malloc(3 * (size_t)nt * sizeof *er);
    tri_key *tk = malloc((size_t)nt * sizeof *tk);
    int rc = 0;
    if (!map || !first || !s->ltri || !er || !tk) {
        rc = api_fail(p, 503, "out-of-memory", "out of memory checking the surface");
        goto done;
    }
    /* local numbering in order of global index; first[g] = first slot (3 j + m) using g */
    memset(map, 0xff, (size_t)in->nv * sizeof *map);
    for (size_t i = 0; i < 3 * (size_t)nt; i++)
        if (map[s->tri[i]] == UINT32_MAX) {
            map[s->tri[i]] = 0;
            first[s->tri[i]] = (uint32_t)i;
        }
    s->nloc = 0;
    for (uint32_t g = 0; g < in->nv; g++)
        if (map[g] != UINT32_MAX)
            map[g] = s->nloc++;
    s->glob = malloc((size_t)s->nloc * sizeof *s->glob);
    s->xyz = malloc(3 * (size_t)s->nloc * sizeof *s->xyz);
    if (!s->glob || !s->xyz) {
        rc = api_fail(p, 503, "out-of-memory", "out of memory checking the surface");
        goto done;
    }
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t g = 0; g < in->nv; g++) {
        if (map[g] == UINT32_MAX)
            continue;
        s->glob[map[g]] = g;
        for (int c = 0; c < 3; c++) {
            double x = in->xyz[3 * (size_t)g + c];
            if (!isfinite(x) || fabs(x) > FILL_MAX_COORD) {
                snprintf(ptr, sizeof ptr, "/vertices/%u/%d", g, c);
                rc = api_fail_at(p, 422, "invalid-complex", ptr,
                                 "coordinate %g of vertex %u is beyond +-1e15", x, g);
                goto done;
            }
            s->xyz[3 * (size_t)map[g] + c] = x;
            lo[c] = fmin(lo[c], x);
            hi[c] = fmax(hi[c], x);
        }
    }
    for (size_t i = 0; i < 3 * (size_t)nt; i++)
        s->ltri[i] = map[s->tri[i]];
    double ext[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
    double diag = sqrt(ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]);
    double tol = FILL_TOL * diag;
    snprintf(ptr, sizeof ptr, "/fill/%zu/surface", k);
    if (!(diag > 0) || fmin(ext[0], fmin(ext[1], ext[2])) <= tol) {
        rc = api_fail_at(p, 422, "invalid-surface", ptr,
                         "the surface is flat: its bounding box (%g x %g x %g) has no volume, so "
                         "there is nothing to fill", ext[0], ext[1], ext[2]);
        goto done;
    }
    /* degenerate triangles, as the core judges them */
    for (uint32_t j = 0; j < nt; j++) {
        const uint32_t *t = s->ltri + 3 * (size_t)j;
        double lmax = 0, e[3][3];
        for (int m = 0; m < 3; m++) {
            const double *a = s->xyz + 3 * (size_t)t[m], *b = s->xyz + 3 * (size_t)t[(m + 1) % 3];
            for (int c = 0; c < 3; c++)
                e[m][c] = b[c] - a[c];
            lmax = fmax(lmax, sqrt(e[m][0] * e[m][0] + e[m][1] * e[m][1] + e[m][2] * e[m][2]));
        }
        double cr[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1], e[0][2] * e[1][0] - e[0][0] * e[1][2],
                        e[0][0] * e[1][1] - e[0][1] * e[1][0]};
        double area = 0.5 * sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        double emin = INFINITY;
        for (int m = 0; m < 3; m++)
            emin = fmin(emin, sqrt(e[m][0] * e[m][0] + e[m][1] * e[m][1] + e[m][2] * e[m][2]));
        if (emin <= tol || area <= FILL_TOL * lmax * lmax) {
            tri_ptr(ptr, sizeof ptr, k, j);
            rc = api_fail_at(p, 422, "invalid-surface", ptr,
                             "triangle %u (%u, %u, %u) is degenerate (area %g, shortest edge %g)", j,
                             s->tri[3 * j], s->tri[3 * j + 1], s->tri[3 * j + 2], area, emin);
            goto done;
        }
    }
    /* the same triangle twice */
    for (uint32_t j = 0; j < nt; j++) {
        memcpy(tk[j].v, s->ltri + 3 * (size_t)j, sizeof tk[j].v);
        sort3(tk[j].v);
        tk[j].tri = j;
    }
    qsort(tk, nt, sizeof *tk, cmp_tri_key);
    for (uint32_t j = 1; j < nt; j++)
        if (!memcmp(tk[j].v, tk[j - 1].v, sizeof tk[j].v)) {
            tri_ptr(ptr, sizeof ptr, k, tk[j].tri);
            rc = api_fail_at(p, 422, "invalid-surface", ptr, "triangle %u repeats triangle %u",
                             tk[j].tri, tk[j - 1].tri);
            goto done;
        }
    /* closed: every edge in exactly two triangles (reports up to API_MAX_FIELD_ERRORS edges) */
    for (uint32_t j = 0; j < nt; j++)
        for (int m = 0; m < 3; m++) {
            uint32_t a = s->ltri[3 * (size_t)j + m], b = s->ltri[3 * (size_t)j + (m + 1) % 3];
            edge_rec *r = &er[3 * (size_t)j + m];
            r->a = a < b ? a : b;
            r->b = a < b ? b : a;
            r->tri = j;
            r->forward = a < b;
        }
    qsort(er, 3 * (size_t)nt, sizeof *er, cmp_edge);
    size_t ne = 3 * (size_t)nt;
    int nbad = 0;
    for (size_t i = 0; i < ne;) {
        size_t e = i + 1;
        while (e < ne && er[e].a == er[i].a && er[e].b == er[i].b)
            e++;
        if (e - i != 2) {
            char msg[200];
            if (e - i == 1)
                snprintf(msg, sizeof msg, "edge (%u, %u) of triangle %u has no other triangle: the "
                         "surface is not closed", s->glob[er[i].a], s->glob[er[i].b], er[i].tri);
            else
                snprintf(msg, sizeof msg, "edge (%u, %u) is shared by %zu triangles (%u, %u, %u...); "
                         "a closed surface has exactly 2 at every edge", s->glob[er[i].a],
                         s->glob[er[i].b], e - i, er[i].tri, er[i + 1].tri, er[i + 2].tri);
            tri_ptr(ptr, sizeof ptr, k, er[e - i == 1 ? i : i + 2].tri);
            if (!nbad++)
                api_fail_at(p, 422, "invalid-surface", ptr, "%s", msg);
            else
                api_add_error(p, ptr, "%s", msg);
        }
        i = e;
    }
    if (nbad) {
        if (nbad > 1)
            snprintf(p->detail, sizeof p->detail, "the surface of /fill/%zu is not closed: %d edges "
                     "do not have exactly two triangles (the first %d are listed)", k, nbad,
                     nbad < API_MAX_FIELD_ERRORS ? nbad : API_MAX_FIELD_ERRORS);
        rc = 422;
        goto done;
    }
    /* orientable: walk the triangles across edges, flipping where a neighbour runs the shared
     * edge the same way; a contradiction means no consistent orientation exists */
    {
        uint32_t *nb = malloc(3 * (size_t)nt * sizeof *nb), *queue = malloc((size_t)nt * sizeof *queue);
        uint8_t *deg = calloc(nt, 1), *flip = malloc(3 * (size_t)nt), *orient = malloc(nt);
        double *cvol = calloc(nt, sizeof *cvol);
        if (!nb || !queue || !deg || !flip || !orient || !cvol) {
            rc = api_fail(p, 503, "out-of-memory", "out of memory checking the surface");
        } else {
            for (size_t i = 0; i < ne; i += 2) {
                uint32_t t1 = er[i].tri, t2 = er[i + 1].tri;
                uint8_t f = er[i].forward == er[i + 1].forward;
                nb[3 * (size_t)t1 + deg[t1]] = t2, flip[3 * (size_t)t1 + deg[t1]++] = f;
                nb[3 * (size_t)t2 + deg[t2]] = t1, flip[3 * (size_t)t2 + deg[t2]++] = f;
            }
            memset(orient, 2, nt);
            double o[3] = {(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2};
            uint32_t ncomp = 0;
            for (uint32_t seed = 0; seed < nt && !rc; seed++) {
                if (orient[seed] != 2)
                    continue;
                size_t head = 0, tail = 0;
                orient[seed] = 0;
                queue[tail++] = seed;
                double v = 0;
                while (head < tail && !rc) {
                    uint32_t t = queue[head++];
                    const uint32_t *q = s->ltri + 3 * (size_t)t;
                    double d = det3(s->xyz + 3 * (size_t)q[0], s->xyz + 3 * (size_t)q[1],
                                    s->xyz + 3 * (size_t)q[2], o) / 6;
                    v += orient[t] ? -d : d;
                    for (int m = 0; m < 3; m++) {
                        uint32_t u = nb[3 * (size_t)t + m];
                        uint8_t want = orient[t] ^ flip[3 * (size_t)t + m];
                        if (orient[u] == 2) {
                            orient[u] = want;
                            queue[tail++] = u;
                        } else if (orient[u] != want) {
                            tri_ptr(ptr, sizeof ptr, k, u);
                            rc = api_fail_at(p, 422, "invalid-surface", ptr,
                                             "the surface is not orientable (like a Moebius strip): "
                                             "triangle %u cannot be oriented consistently with its "
                                             "neighbours", u);
                        }
                    }
                }
                cvol[ncomp++] = fabs(v);
            }
            s->volume = 0;
            for (uint32_t c = 0; c < ncomp; c++)
                s->volume += cvol[c];
            if (!rc && s->volume <= FILL_TOL * diag * diag * diag) {
                snprintf(ptr, sizeof ptr, "/fill/%zu/surface", k);
                rc = api_fail_at(p, 422, "invalid-surface", ptr, "the surface encloses no volume");
            }
        }
        free(nb);
        free(queue);
        free(deg);
        free(flip);
        free(orient);
        free(cvol);
        if (rc)
            goto done;
    }
    /* coincident points (TetGen crashes on them): sort by x, compare within the tolerance */
    {
        uint32_t *ord = malloc((size_t)s->nloc * sizeof *ord);
        if (!ord) {
            rc = api_fail(p, 503, "out-of-memory", "out of memory checking the surface");
            goto done;
        }
        for (uint32_t i = 0; i < s->nloc; i++)
            ord[i] = i;
        qsort_r(ord, s->nloc, sizeof *ord, by_x, s->xyz);
        for (uint32_t i = 0; i < s->nloc && !rc; i++)
            for (uint32_t j = i + 1; j < s->nloc && !rc; j++) {
                const double *a = s->xyz + 3 * (size_t)ord[i], *b = s->xyz + 3 * (size_t)ord[j];
                if (b[0] - a[0] > tol)
                    break;
                double d = sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                                (a[2] - b[2]) * (a[2] - b[2]));
                if (d <= tol) {
                    uint32_t ga = s->glob[ord[i]], gb = s->glob[ord[j]];
                    if (ga > gb) {
                        uint32_t t = ga;
                        ga = gb;
                        gb = t;
                    }
                    snprintf(ptr, sizeof ptr, "/fill/%zu/surface/%u/%u", k, first[gb] / 3, first[gb] % 3);
                    rc = api_fail_at(p, 422, "invalid-surface", ptr,
                                     "vertices %u and %u coincide (%g apart); TetGen needs distinct "
                                     "points", ga, gb, d);
                }
            }
        free(ord);
    }
done:
    free(map);
    free(first);
    free(er);
    free(tk);
    return rc;
}

/* ---- the helper process -------------------------------------------------------------------- */

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
    h->payload = malloc(n ? n : 1);
    return h->payload ? 0 : (h->too_big = 3, -1);
}

/* Spawn the helper, send the request, collect the reply and stderr until both close or the
 * deadline passes, then reap the child. 0, or -1 with `why` when it could not be started. */
static int run_helper(const api_limits *lim, const surface *s, helper_out *h, char *why, size_t cap)
{
    char path[PATH_MAX], mem[32], cpu[32];
    int search;
    helper_path(lim, path, sizeof path, &search);
    snprintf(mem, sizeof mem, "%llu", (unsigned long long)lim->fill_memory_bytes);
    snprintf(cpu, sizeof cpu, "%u", lim->fill_seconds ? lim->fill_seconds : API_DEFAULT_FILL_SECONDS);
    char *argv[] = {path, "--max-bytes", mem, "--cpu-seconds", cpu, NULL};

    /* the request in one buffer: header, points, triangles */
    sdtg_request rq = {SDTG_REQUEST_MAGIC, s->nloc, s->nt, 0, s->max_volume, s->min_ratio};
    size_t len = sizeof rq + 3 * (size_t)s->nloc * sizeof(double) + 3 * (size_t)s->nt * sizeof(uint32_t);
    unsigned char *req = malloc(len);
    if (!req) {
        snprintf(why, cap, "out of memory");
        return -1;
    }
    memcpy(req, &rq, sizeof rq);
    memcpy(req + sizeof rq, s->xyz, 3 * (size_t)s->nloc * sizeof(double));
    memcpy(req + sizeof rq + 3 * (size_t)s->nloc * sizeof(double), s->ltri,
           3 * (size_t)s->nt * sizeof(uint32_t));

    int sv[2] = {-1, -1}, po[2] = {-1, -1}, pe[2] = {-1, -1};
    if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) || pipe2(po, O_CLOEXEC) ||
        pipe2(pe, O_CLOEXEC)) {
        snprintf(why, cap, "cannot create pipes: %s", strerror(errno));
        for (int i = 0; i < 2; i++) {
            if (sv[i] >= 0) close(sv[i]);
            if (po[i] >= 0) close(po[i]);
            if (pe[i] >= 0) close(pe[i]);
        }
        free(req);
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
    pid_t pid;
    int err = search ? posix_spawnp(&pid, path, &fa, &at, argv, environ)
                     : posix_spawn(&pid, path, &fa, &at, argv, environ);
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
        free(req);
        return -1;
    }
    int fin = sv[0], fout = po[0], ferr = pe[0];
    fcntl(fout, F_SETFL, O_NONBLOCK);
    fcntl(ferr, F_SETFL, O_NONBLOCK);
    size_t off = 0;
    double deadline = now_s() + (lim->fill_seconds ? lim->fill_seconds : API_DEFAULT_FILL_SECONDS);
    int killed = 0;
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
        if (iout >= 0 && pf[iout].revents) {
            ssize_t got;
            if (h->hdr_got < sizeof h->rep)
                got = read(fout, (char *)&h->rep + h->hdr_got, sizeof h->rep - h->hdr_got);
            else if (h->payload_got < h->payload_len)
                got = read(fout, h->payload + h->payload_got, h->payload_len - h->payload_got);
            else if ((got = read(fout, buf, sizeof buf)) > 0) {
                h->protocol = 1; /* more than the reply announced */
                break;
            }
            if (got > 0) {
                if (h->hdr_got < sizeof h->rep) {
                    h->hdr_got += (size_t)got;
                    if (h->hdr_got == sizeof h->rep && size_payload(h))
                        break;
                } else
                    h->payload_got += (size_t)got;
            } else if (got == 0 || (errno != EAGAIN && errno != EINTR)) {
                close(fout);
                fout = -1;
            }
        }
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
    free(req);
    /* reap: the child has closed its output (or we gave up on it); wait until the deadline */
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

static int cmp_u32x3(const void *x, const void *y) { return memcmp(x, y, 3 * sizeof(uint32_t)); }

/* Map the helper's end to a problem, or check its tetrahedra (0). */
static int judge(const helper_out *h, const surface *s, size_t k, const api_limits *lim,
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
                              "TetGen did not finish within %u s; ask for fewer tetrahedra (a "
                              "larger max_volume or min_ratio) or raise --fill-timeout", secs);
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
        uint32_t *keys = malloc(4 * (size_t)s->nt * sizeof *keys);
        if (!keys)
            return api_fail(p, 503, "out-of-memory", "out of memory");
        for (uint32_t j = 0; j < s->nt; j++) {
            memcpy(keys + 4 * (size_t)j, s->ltri + 3 * (size_t)j, 3 * sizeof *keys);
            sort3(keys + 4 * (size_t)j);
            keys[4 * (size_t)j + 3] = j;
        }
        qsort(keys, s->nt, 4 * sizeof *keys, cmp_u32x3);
        const uint32_t *f = (const uint32_t *)h->payload;
        api_fail_at(p, 422, "invalid-surface", ptr,
                    "TetGen found %u triangles of the surface intersecting other triangles; a "
                    "fill surface must not intersect itself", r->n1);
        p->nerrors = 0;
        for (uint32_t i = 0; i < r->n1; i++) {
            uint32_t key[4] = {f[3 * i], f[3 * i + 1], f[3 * i + 2], 0};
            sort3(key);
            const uint32_t *hit = bsearch(key, keys, s->nt, 4 * sizeof *keys, cmp_u32x3);
            if (!hit)
                continue;
            char tp[96];
            const uint32_t *g = s->tri + 3 * (size_t)hit[3];
            tri_ptr(tp, sizeof tp, k, hit[3]);
            api_add_error(p, tp, "triangle %u (%u, %u, %u) intersects another triangle of the "
                          "surface", hit[3], g[0], g[1], g[2]);
        }
        if (!p->nerrors)
            api_add_error(p, ptr, "%s", p->detail);
        free(keys);
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

/* The boundary of the tetrahedra is the surface: every face used once is a surface triangle,
 * and every surface triangle is a face (used twice when it lies inside, e.g. nested shells). */
static int check_boundary(const surface *s, const uint32_t *tets, uint32_t nt4, size_t k,
                          api_problem *p)
{
    static const int F[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
    uint32_t *faces = malloc(12 * (size_t)nt4 * sizeof *faces);
    uint32_t *sf = malloc(3 * (size_t)s->nt * sizeof *sf);
    int rc = 0;
    if (!faces || !sf) {
        rc = api_fail(p, 503, "out-of-memory", "out of memory checking TetGen's result");
        goto out;
    }
    for (size_t t = 0; t < nt4; t++)
        for (int f = 0; f < 4; f++) {
            uint32_t *d = faces + 12 * t + 3 * (size_t)f;
            for (int m = 0; m < 3; m++)
                d[m] = tets[4 * t + (size_t)F[f][m]];
            sort3(d);
        }
    qsort(faces, 4 * (size_t)nt4, 3 * sizeof *faces, cmp_u32x3);
    for (uint32_t j = 0; j < s->nt; j++) {
        memcpy(sf + 3 * (size_t)j, s->ltri + 3 * (size_t)j, 3 * sizeof *sf);
        sort3(sf + 3 * (size_t)j);
        if (!bsearch(sf + 3 * (size_t)j, faces, 4 * (size_t)nt4, 3 * sizeof *faces, cmp_u32x3)) {
            char ptr[96];
            tri_ptr(ptr, sizeof ptr, k, j);
            rc = api_fail_at(p, 500, "fill-failed", ptr, "TetGen did not keep triangle %u of "
                             "/fill/%zu", j, k);
            goto out;
        }
    }
    qsort(sf, s->nt, 3 * sizeof *sf, cmp_u32x3);
    for (size_t i = 0, n = 4 * (size_t)nt4; i < n;) {
        size_t e = i + 1;
        while (e < n && !cmp_u32x3(faces + 3 * i, faces + 3 * e))
            e++;
        if (e - i == 1 && !bsearch(faces + 3 * i, sf, s->nt, 3 * sizeof *sf, cmp_u32x3)) {
            rc = api_fail(p, 500, "fill-failed", "the boundary of TetGen's tetrahedra for /fill/%zu "
                          "is not the surface", k);
            goto out;
        }
        if (e - i > 2) {
            rc = api_fail(p, 500, "fill-failed", "TetGen's tetrahedra for /fill/%zu overlap", k);
            goto out;
        }
        i = e;
    }
out:
    free(faces);
    free(sf);
    return rc;
}

/* ---- appending ------------------------------------------------------------------------------ */

/* Values of attribute `a` at the new points: the discrete harmonic extension of the surface
 * values over the new tetrahedra's edges (each edge weighted by the tetrahedra that share it),
 * solved by Jacobi-preconditioned conjugate gradients per component. */
static int harmonic(api_attribute *a, uint32_t nv0, const surface *s, uint32_t np,
                    const uint32_t *tets, uint32_t ntets)
{
    uint32_t m = np - s->nloc; /* unknowns: local ids nloc.. */
    if (!m)
        return 0;
    uint32_t *rp = calloc((size_t)m + 1, sizeof *rp), *col = NULL;
    double *x = NULL;
    int rc = -1;
    if (!rp)
        return -1;
    for (size_t t = 0; t < ntets; t++)
        for (int i = 0; i < 4; i++)
            if (tets[4 * t + i] >= s->nloc)
                rp[tets[4 * t + i] - s->nloc + 1] += 3;
    for (uint32_t i = 0; i < m; i++)
        rp[i + 1] += rp[i];
    col = malloc(((size_t)rp[m] + 1) * sizeof *col);
    uint32_t *fillp = malloc(((size_t)m + 1) * sizeof *fillp);
    double *b = malloc(((size_t)m + 1) * sizeof *b), *r = malloc(((size_t)m + 1) * sizeof *r),
           *z = malloc(((size_t)m + 1) * sizeof *z), *pv = malloc(((size_t)m + 1) * sizeof *pv),
           *q = malloc(((size_t)m + 1) * sizeof *q);
    x = malloc(((size_t)m + 1) * sizeof *x);
    if (!col || !fillp || !b || !r || !z || !pv || !q || !x)
        goto out;
    memcpy(fillp, rp, (size_t)m * sizeof *fillp);
    for (size_t t = 0; t < ntets; t++)
        for (int i = 0; i < 4; i++) {
            uint32_t u = tets[4 * t + i];
            if (u < s->nloc)
                continue;
            for (int j = 0; j < 4; j++)
                if (j != i)
                    col[fillp[u - s->nloc]++] = tets[4 * t + j];
        }
    for (int c = 0; c < a->ncomp; c++) {
        /* L x = b: diag = degree, off-diagonal -1 per unknown neighbour, b = sum of known values */
        for (uint32_t i = 0; i < m; i++) {
            double bi = 0;
            for (uint32_t e = rp[i]; e < rp[i + 1]; e++)
                if (col[e] < s->nloc)
                    bi += a->data[(size_t)s->glob[col[e]] * a->ncomp + c];
            b[i] = bi;
            x[i] = 0;
        }
        double rr = 0, rz = 0, bb = 0;
        for (uint32_t i = 0; i < m; i++) {
            r[i] = b[i];
            z[i] = r[i] / (rp[i + 1] - rp[i]);
            pv[i] = z[i];
            rz += r[i] * z[i];
            bb += b[i] * b[i];
        }
        rr = bb;
        for (int it = 0; it < 20000 && rr > 1e-28 * bb && bb > 0; it++) {
            double pq = 0;
            for (uint32_t i = 0; i < m; i++) {
                double v = (rp[i + 1] - rp[i]) * pv[i];
                for (uint32_t e = rp[i]; e < rp[i + 1]; e++)
                    if (col[e] >= s->nloc)
                        v -= pv[col[e] - s->nloc];
                q[i] = v;
                pq += pv[i] * v;
            }
            double alpha = rz / pq, rz2 = 0;
            rr = 0;
            for (uint32_t i = 0; i < m; i++) {
                x[i] += alpha * pv[i];
                r[i] -= alpha * q[i];
                z[i] = r[i] / (rp[i + 1] - rp[i]);
                rz2 += r[i] * z[i];
                rr += r[i] * r[i];
            }
            double beta = rz2 / rz;
            rz = rz2;
            for (uint32_t i = 0; i < m; i++)
                pv[i] = z[i] + beta * pv[i];
        }
        for (uint32_t i = 0; i < m; i++)
            a->data[(size_t)(nv0 + i) * a->ncomp + c] = x[i];
    }
    rc = 0;
out:
    free(rp);
    free(col);
    free(fillp);
    free(b);
    free(r);
    free(z);
    free(pv);
    free(q);
    free(x);
    return rc;
}

static int append(api_input *in, const surface *s, const helper_out *h, api_problem *p)
{
    uint32_t np = h->rep.n1, nt = h->rep.n2, added = np - s->nloc;
    const double *pts = (const double *)h->payload;
    const uint32_t *tets = (const uint32_t *)(h->payload + (size_t)np * 3 * sizeof(double));
    uint32_t nv0 = in->nv, ns0 = in->ns;
    size_t nidx = 0;
    for (uint32_t i = 0; i < in->ns; i++)
        nidx += in->size[i];
    double *xyz = realloc(in->xyz, 3 * ((size_t)nv0 + added + 1) * sizeof *xyz);
    if (xyz)
        in->xyz = xyz;
    uint8_t *size = realloc(in->size, (size_t)ns0 + nt + 1);
    if (size)
        in->size = size;
    uint32_t *idx = realloc(in->idx, (nidx + 4 * (size_t)nt + 1) * sizeof *idx);
    if (idx)
        in->idx = idx;
    api_fill_stats *st = realloc(in->fill, (in->nfill + 1) * sizeof *st);
    if (st)
        in->fill = st;
    if (!xyz || !size || !idx || !st)
        return api_fail(p, 503, "out-of-memory", "out of memory adding TetGen's tetrahedra");
    memcpy(in->xyz + 3 * (size_t)nv0, pts + 3 * (size_t)s->nloc, 3 * (size_t)added * sizeof *pts);
    double vol = 0, largest = 0;
    for (size_t t = 0; t < nt; t++) {
        in->size[ns0 + t] = 4;
        for (int i = 0; i < 4; i++) {
            uint32_t l = tets[4 * t + i];
            in->idx[nidx + 4 * t + i] = l < s->nloc ? s->glob[l] : nv0 + (l - s->nloc);
        }
        const double *q[4];
        for (int i = 0; i < 4; i++)
            q[i] = pts + 3 * (size_t)tets[4 * t + i];
        double v = fabs(det3(q[1], q[2], q[3], q[0])) / 6;
        vol += v;
        largest = v > largest ? v : largest;
    }
    for (int a = 0; a < in->nattrs; a++) {
        api_attribute *at = &in->attrs[a];
        double *d = realloc(at->data, ((size_t)nv0 + added + 1) * at->ncomp * sizeof *d);
        if (!d)
            return api_fail(p, 503, "out-of-memory", "out of memory extending attribute %s", at->name);
        at->data = d;
        if (harmonic(at, nv0, s, np, tets, nt))
            return api_fail(p, 503, "out-of-memory", "out of memory extending attribute %s", at->name);
    }
    in->nv = nv0 + added;
    in->ns = ns0 + nt;
    in->fill[in->nfill++] =
        (api_fill_stats){s->nt, nt, added, nv0, ns0, vol, largest, s->max_volume};
    return 0;
}

/* ---- entry points ------------------------------------------------------------------------- */

int api_fill(json_t *fill, api_input *in, const api_limits *lim, api_problem *p)
{
    if (!json_is_array(fill))
        return api_fail_at(p, 400, "wrong-type", "/fill",
                           "must be an array of {\"surface\", \"max_volume\", \"min_ratio\"}");
    size_t n = json_array_size(fill);
    if (n > API_MAX_FILL_SURFACES)
        return api_fail_at(p, 422, "invalid-surface", "/fill", "%zu fill entries; at most %d per "
                           "request (one surface may have several components)", n,
                           API_MAX_FILL_SURFACES);
    /* parse and check every entry before any process is started */
    surface *s = calloc(n ? n : 1, sizeof *s);
    if (!s)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    int rc = 0;
    uint64_t tri_total = 0;
    for (size_t k = 0; k < n && !rc; k++) {
        rc = parse_entry(json_array_get(fill, k), k, in, lim, &s[k], p);
        tri_total += s[k].nt;
    }
    if (!rc && tri_total > lim->max_simplices)
        rc = api_fail_limit(p, "max_simplices", lim->max_simplices, tri_total,
                            "the fill surfaces have %llu triangles, over the limit of %u simplices",
                            (unsigned long long)tri_total, lim->max_simplices);
    for (size_t k = 0; k < n && !rc; k++) {
        rc = check_surface(&s[k], k, in, p);
        /* TetGen makes at least volume / max_volume tetrahedra: refuse before running it */
        double est = s[k].max_volume > 0 ? ceil(s[k].volume / s[k].max_volume) : 0;
        if (!rc && est > (double)lim->max_simplices - in->ns) {
            char at[96];
            snprintf(at, sizeof at, "/fill/%zu/max_volume", k);
            rc = api_fail_limit(p, "max_simplices", lim->max_simplices,
                                (uint64_t)fmin(est + in->ns, 1e18),
                                "the surface encloses %g; with max_volume %g TetGen would make at "
                                "least %.0f tetrahedra, over the limit of %u simplices; use a larger "
                                "max_volume", s[k].volume, s[k].max_volume, est, lim->max_simplices);
            api_add_error(p, at, "%s", p->detail);
        }
    }
    for (size_t k = 0; k < n && !rc; k++) {
        helper_out h = {0};
        h.nloc = s[k].nloc;
        h.ntri = s[k].nt;
        h.room_vertices = lim->max_vertices > in->nv ? lim->max_vertices - in->nv : 0;
        h.room_simplices = lim->max_simplices > in->ns ? lim->max_simplices - in->ns : 0;
        char why[PATH_MAX + 128];
        if (run_helper(lim, &s[k], &h, why, sizeof why))
            rc = api_fail(p, 500, "fill-failed", "%s; install subdivd-tetgen beside subdivd or "
                          "name it with --tetgen", why);
        if (!rc)
            rc = judge(&h, &s[k], k, lim, p);
        if (!rc)
            rc = check_boundary(&s[k], (const uint32_t *)(h.payload + (size_t)h.rep.n1 * 3 *
                                                          sizeof(double)), h.rep.n2, k, p);
        if (!rc)
            rc = append(in, &s[k], &h, p);
        free(h.payload);
    }
    for (size_t k = 0; k < n; k++)
        surface_free(&s[k]);
    free(s);
    return rc;
}

void api_fill_blame(const api_input *in, uint32_t nv_posted, uint32_t ns_posted, api_problem *p)
{
    for (int e = 0; e < p->nerrors; e++) {
        api_field_error *fe = &p->errors[e];
        unsigned long idx;
        int vert = !strncmp(fe->pointer, "/vertices/", 10);
        if (!vert && strncmp(fe->pointer, "/simplices/", 11))
            continue;
        idx = strtoul(fe->pointer + (vert ? 10 : 11), NULL, 10);
        if (idx < (vert ? nv_posted : ns_posted))
            continue;
        for (uint32_t k = 0; k < in->nfill; k++) {
            const api_fill_stats *f = &in->fill[k];
            uint32_t lo = vert ? f->first_vertex : f->first_simplex;
            uint32_t cnt = vert ? f->added_vertices : f->tets;
            if (idx >= lo && idx - lo < cnt) {
                char msg[sizeof fe->message];
                snprintf(msg, sizeof msg, "%s %lu, made by TetGen for /fill/%u: %s",
                         vert ? "point" : "tetrahedron", idx, k, fe->message);
                snprintf(fe->message, sizeof fe->message, "%s", msg);
                snprintf(fe->pointer, sizeof fe->pointer, "/fill/%u", k);
                break;
            }
        }
    }
}

json_t *api_fill_summary(const api_input *in)
{
    if (!in || !in->nfill)
        return NULL;
    json_t *a = json_array();
    for (uint32_t k = 0; k < in->nfill; k++) {
        const api_fill_stats *f = &in->fill[k];
        json_t *o = json_pack("{s:I, s:I, s:I, s:f, s:f, s:I, s:I}", "surface_triangles",
                              (json_int_t)f->surface_triangles, "tets", (json_int_t)f->tets,
                              "added_vertices", (json_int_t)f->added_vertices, "volume", f->volume,
                              "largest_tet_volume", f->largest,
                              "first_vertex", (json_int_t)f->first_vertex,
                              "first_simplex", (json_int_t)f->first_simplex);
        /* the surface is kept (no points on it), so TetGen may not reach max_volume: say so */
        if (f->max_volume > 0 && f->largest > f->max_volume * (1 + 1e-9))
            json_object_set_new(o, "warning", json_string(
                "max_volume is not met: the surface is kept as posted (no points are added on "
                "it), and TetGen could not split the largest tetrahedra further; refine the "
                "surface's triangles to get smaller tetrahedra"));
        json_array_append_new(a, o);
    }
    return a;
}
