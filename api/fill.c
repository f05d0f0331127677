/* fill.c — TetGen fill of closed surfaces (see fill.h for the contract): the steps in order.
 *
 * Per entry of "fill": parse (400/422 with pointers), check the surface (fill_check.c: 422 with
 * pointers), estimate the work against the limits (413), run the helper process (fill_helper.c)
 * under a wall deadline, check what came back (points unchanged, indices in range, boundary = the
 * surface), then append the Steiner points and tetrahedra to the input, with the attributes of the
 * new points harmonically interpolated. Every entry is parsed and checked before any process
 * starts. Nothing here knows HTTP: the same code serves the daemon and `subdivd refine`.
 *
 * Why this lives in api/ and not server/: a fill is part of building a complex from a request
 * body, like parsing it; the offline mode needs it too.
 */
#include "fill_internal.h"
#include "mem.h"
#include "jsonin.h"
#include "rows.h"
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MIN_RATIO_LO 1.0
#define MIN_RATIO_HI 100.0

/* One entry, as parsed and checked. Triangles in local numbering: the surface's vertices are
 * renumbered 0..nloc-1 in order of their global index. */
/* ---- parsing ------------------------------------------------------------------------------ */

static int parse_entry(json_t *e, size_t k, const api_packs *packs, const api_input *in,
                       const api_limits *lim, surface *s, api_problem *p)
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
    api_rows rows;
    if (!api_rows_open(&rows, tris, packs, sp))
        return api_fail_at(p, 400, "wrong-type", sp, "must be an array of triangles [i, j, k]");
    size_t n = api_rows_count(&rows);
    if (n > lim->max_simplices)
        return api_fail_limit(p, "max_simplices", lim->max_simplices, n,
                              "the surface has %zu triangles, over the limit of %u simplices", n,
                              lim->max_simplices);
    if (n < 4)
        return api_fail_at(p, 422, "invalid-surface", sp,
                           "%zu triangles cannot close a surface; a closed surface has at least 4", n);
    s->nt = (uint32_t)n;
    s->tri = api_malloc(3 * n * sizeof *s->tri);
    if (!s->tri)
        return api_fail(p, 503, "out-of-memory", "out of memory reading the surface");
    api_row t;
    for (size_t j = 0; api_rows_next(&rows, &t); j++) {
        api_ptr_index(at, sizeof at, sp, j);
        if (!api_row_is_array(&t))
            return api_fail_at(p, 400, "wrong-type", at, "a triangle is an array of 3 vertex indices");
        if (api_row_size(&t) != 3)
            return api_fail_at(p, 422, "invalid-surface", at,
                               "a surface triangle has 3 vertex indices, not %zu", api_row_size(&t));
        for (size_t m = 0; m < 3; m++) {
            long long x;
            api_ptr_index(ix, sizeof ix, at, m);
            if (!in->nv)
                return api_fail_at(p, 422, "out-of-range", ix, "there are no vertices to index");
            if (api_num_get_int(api_row_get(&t, m), ix, 0, (long long)in->nv - 1, &x, p))
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

/* TetGen's quality measure of a tetrahedron (-q): its circumradius over its shortest edge. */
static double radius_edge_ratio(const double *const q[4])
{
    double a[3], b[3], c[3], bc[3], ca[3], ab[3], x[3];
    for (int k = 0; k < 3; k++) {
        a[k] = q[1][k] - q[0][k];
        b[k] = q[2][k] - q[0][k];
        c[k] = q[3][k] - q[0][k];
    }
#define CROSS(r, u, v)                                                                            \
    (r[0] = u[1] * v[2] - u[2] * v[1], r[1] = u[2] * v[0] - u[0] * v[2], r[2] = u[0] * v[1] - u[1] * v[0])
    CROSS(bc, b, c);
    CROSS(ca, c, a);
    CROSS(ab, a, b);
#undef CROSS
    double aa = a[0] * a[0] + a[1] * a[1] + a[2] * a[2], bb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2],
           cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
    double d = 2 * (a[0] * bc[0] + a[1] * bc[1] + a[2] * bc[2]);
    for (int k = 0; k < 3; k++) /* the circumcentre relative to q[0] */
        x[k] = (aa * bc[k] + bb * ca[k] + cc * ab[k]) / d;
    double shortest = INFINITY;
    for (int i = 0; i < 4; i++)
        for (int j = i + 1; j < 4; j++) {
            double e = 0;
            for (int k = 0; k < 3; k++)
                e += (q[j][k] - q[i][k]) * (q[j][k] - q[i][k]);
            shortest = e < shortest ? e : shortest;
        }
    double r = sqrt((x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) / shortest);
    return isfinite(r) ? r : INFINITY; /* a flat tetrahedron: no finite ratio */
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
    uint32_t *rp = api_calloc((size_t)m + 1, sizeof *rp), *col = NULL;
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
    col = api_malloc(((size_t)rp[m] + 1) * sizeof *col);
    uint32_t *fillp = api_malloc(((size_t)m + 1) * sizeof *fillp);
    double *b = api_malloc(((size_t)m + 1) * sizeof *b), *r = api_malloc(((size_t)m + 1) * sizeof *r),
           *z = api_malloc(((size_t)m + 1) * sizeof *z), *pv = api_malloc(((size_t)m + 1) * sizeof *pv),
           *q = api_malloc(((size_t)m + 1) * sizeof *q);
    x = api_malloc(((size_t)m + 1) * sizeof *x);
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
    api_free(rp);
    api_free(col);
    api_free(fillp);
    api_free(b);
    api_free(r);
    api_free(z);
    api_free(pv);
    api_free(q);
    api_free(x);
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
    double *xyz = api_plain_realloc(in->xyz, 3 * ((size_t)nv0 + added + 1) * sizeof *xyz);
    if (xyz)
        in->xyz = xyz;
    uint8_t *size = api_plain_realloc(in->size, (size_t)ns0 + nt + 1);
    if (size)
        in->size = size;
    uint32_t *idx = api_plain_realloc(in->idx, (nidx + 4 * (size_t)nt + 1) * sizeof *idx);
    if (idx)
        in->idx = idx;
    api_fill_stats *st = api_realloc(in->fill, (in->nfill + 1) * sizeof *st);
    if (st)
        in->fill = st;
    if (!xyz || !size || !idx || !st)
        return api_fail(p, 503, "out-of-memory", "out of memory adding TetGen's tetrahedra");
    memcpy(in->xyz + 3 * (size_t)nv0, pts + 3 * (size_t)s->nloc, 3 * (size_t)added * sizeof *pts);
    double vol = 0, largest = 0, worst = 0;
    for (size_t t = 0; t < nt; t++) {
        in->size[ns0 + t] = 4;
        for (int i = 0; i < 4; i++) {
            uint32_t l = tets[4 * t + i];
            in->idx[nidx + 4 * t + i] = l < s->nloc ? s->glob[l] : nv0 + (l - s->nloc);
        }
        const double *q[4];
        for (int i = 0; i < 4; i++)
            q[i] = pts + 3 * (size_t)tets[4 * t + i];
        double v = fabs(api_fill_det3(q[1], q[2], q[3], q[0])) / 6;
        vol += v;
        largest = v > largest ? v : largest;
        double r = radius_edge_ratio(q);
        worst = r > worst ? r : worst;
    }
    for (int a = 0; a < in->nattrs; a++) {
        api_attribute *at = &in->attrs[a];
        double *d = api_plain_realloc(at->data, ((size_t)nv0 + added + 1) * at->ncomp * sizeof *d);
        if (!d)
            return api_fail(p, 503, "out-of-memory", "out of memory extending attribute %s", at->name);
        at->data = d;
        if (harmonic(at, nv0, s, np, tets, nt))
            return api_fail(p, 503, "out-of-memory", "out of memory extending attribute %s", at->name);
    }
    in->nv = nv0 + added;
    in->ns = ns0 + nt;
    if (!api_input_account(in)) /* the grown arrays count against the memory budget */
        return api_fail(p, 503, "out-of-memory", "out of memory adding TetGen's tetrahedra");
    in->fill[in->nfill++] =
        (api_fill_stats){s->nt, nt, added, nv0, ns0, vol, largest, s->max_volume, worst, s->min_ratio};
    return 0;
}

/* ---- entry points ------------------------------------------------------------------------- */

int api_fill(json_t *fill, const api_packs *packs, api_input *in, const api_limits *lim,
             api_problem *p)
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
    surface *s = api_calloc(n ? n : 1, sizeof *s);
    if (!s)
        return api_fail(p, 503, "out-of-memory", "out of memory");
    int rc = 0;
    uint64_t tri_total = 0;
    for (size_t k = 0; k < n && !rc; k++) {
        rc = parse_entry(json_array_get(fill, k), k, packs, in, lim, &s[k], p);
        tri_total += s[k].nt;
    }
    if (!rc && tri_total > lim->max_simplices)
        rc = api_fail_limit(p, "max_simplices", lim->max_simplices, tri_total,
                            "the fill surfaces have %llu triangles, over the limit of %u simplices",
                            (unsigned long long)tri_total, lim->max_simplices);
    for (size_t k = 0; k < n && !rc; k++) {
        rc = api_fill_check_surface(&s[k], k, in, p);
        /* TetGen makes at least volume / max_volume tetrahedra: refuse before running it */
        double est = s[k].max_volume > 0 ? ceil(s[k].volume / s[k].max_volume) : 0;
        if (!rc && est > (double)lim->max_simplices - in->ns) {
            char at[96];
            snprintf(at, sizeof at, "/fill/%zu/max_volume", k);
            rc = api_fail_limit(p, "max_simplices", lim->max_simplices,
                                (uint64_t)fmin(est + in->ns, 1e18),
                                "the surface encloses %g; with max_volume %g TetGen would make at "
                                "least %.15g tetrahedra, over the limit of %u simplices; use a larger "
                                "max_volume", s[k].volume, s[k].max_volume, est, lim->max_simplices);
            api_add_error(p, at, "%s", p->detail);
        }
    }
    double deadline = api_fill_deadline(lim); /* one for all entries */
    for (size_t k = 0; k < n && !rc; k++) {
        helper_out h = {0};
        h.nloc = s[k].nloc;
        h.ntri = s[k].nt;
        h.room_vertices = lim->max_vertices > in->nv ? lim->max_vertices - in->nv : 0;
        h.room_simplices = lim->max_simplices > in->ns ? lim->max_simplices - in->ns : 0;
        char why[PATH_MAX + 128];
        if (api_fill_run_helper(lim, &s[k], deadline, &h, why, sizeof why))
            rc = api_fail(p, 500, "fill-failed", "%s; install subdivd-tetgen beside subdivd or "
                          "name it with --tetgen", why);
        if (!rc)
            rc = api_fill_judge(&h, &s[k], k, lim, p);
        if (!rc)
            rc = api_fill_check_boundary(&s[k], (const uint32_t *)(h.payload + (size_t)h.rep.n1 * 3 *
                                                          sizeof(double)), h.rep.n2, k, p);
        if (!rc)
            rc = append(in, &s[k], &h, p);
        api_free(h.payload);
    }
    for (size_t k = 0; k < n; k++)
        api_fill_surface_free(&s[k]);
    api_free(s);
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
        /* JSON has no infinity: a flat tetrahedron (none from TetGen) leaves the ratio out */
        if (isfinite(f->largest_ratio))
            json_object_set_new(o, "largest_ratio", json_real(f->largest_ratio));
        /* the surface is kept (no points on it), so TetGen may reach neither max_volume nor
         * min_ratio: say which was not met */
        int vol_unmet = f->max_volume > 0 && f->largest > f->max_volume * (1 + 1e-9);
        int ratio_unmet = f->min_ratio > 0 && !(f->largest_ratio <= f->min_ratio * (1 + 1e-9));
        if (vol_unmet || ratio_unmet) {
            char w[512];
            snprintf(w, sizeof w,
                     "%s not met: the surface is kept as posted (no points are added on it), and "
                     "TetGen could not %s further; refine the surface's triangles to get %s "
                     "tetrahedra",
                     vol_unmet && ratio_unmet ? "max_volume and min_ratio are"
                     : vol_unmet              ? "max_volume is"
                                              : "min_ratio is",
                     vol_unmet && ratio_unmet ? "split the largest and the worst-shaped tetrahedra"
                     : vol_unmet              ? "split the largest tetrahedra"
                                              : "split the worst-shaped tetrahedra",
                     vol_unmet && ratio_unmet ? "smaller and better-shaped"
                     : vol_unmet              ? "smaller"
                                              : "better-shaped");
            json_object_set_new(o, "warning", json_string(w));
        }
        json_array_append_new(a, o);
    }
    return a;
}
