/* crease.c — PUT /tags "crease_angle" (docs/API.md "Tags", docs/DECISIONS.md 42): every surface
 * edge whose dihedral angle exceeds the threshold becomes a singular tag (an infinitely sharp
 * crease), evaluated once, when PUT /tags is answered, on the positions of that moment; what it
 * added is then ordinary tags (edits do not re-evaluate it).
 *
 * Surface faces are level 0's maximal triangles and the boundary faces of its solids
 * (sd_level_solid_boundary). An edge with exactly two of them, both of the same kind, is a
 * candidate; its angle is the one between the two faces' normals with the faces oriented
 * consistently across the edge (0 = flat, 180 = folded onto itself), so it needs no consistent
 * orientation of the posted triangles. Edges of one face (open boundaries) are already sharp,
 * and edges of three or more faces, or of a triangle meeting a solid, are non-manifold: both
 * follow their own rules and are left alone. The edges found are appended to the posted
 * singular list (those already in it not twice), ordered by their vertex ids.
 */
#include "crease.h"
#include "mem.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct side {
    uint32_t a, b;   /* the edge, a < b */
    uint32_t c;      /* the face's third vertex */
    uint32_t kind;   /* 0 maximal triangle, 1 solid boundary face */
} side;

static int side_cmp(const void *x, const void *y)
{
    const side *p = x, *q = y;
    if (p->a != q->a)
        return p->a < q->a ? -1 : 1;
    return p->b < q->b ? -1 : p->b > q->b;
}

static int key_cmp(const void *x, const void *y)
{
    const uint64_t *p = x, *q = y;
    return *p < *q ? -1 : *p > *q;
}

/* The angle in degrees between the normals of triangles (a,b,c) and (b,a,d): the two faces of
 * edge ab oriented consistently across it. */
static double dihedral(const double *x, uint32_t a, uint32_t b, uint32_t c, uint32_t d)
{
    const double *A = x + 3 * (size_t)a, *B = x + 3 * (size_t)b, *C = x + 3 * (size_t)c,
                 *D = x + 3 * (size_t)d;
    double u[3], v[3], w[3], n1[3], n2[3], k[3];
    for (int i = 0; i < 3; i++) {
        u[i] = B[i] - A[i];
        v[i] = C[i] - A[i];
        w[i] = D[i] - B[i];
    }
    n1[0] = u[1] * v[2] - u[2] * v[1];
    n1[1] = u[2] * v[0] - u[0] * v[2];
    n1[2] = u[0] * v[1] - u[1] * v[0];
    /* (A - B) x (D - B) = -u x w */
    n2[0] = -(u[1] * w[2] - u[2] * w[1]);
    n2[1] = -(u[2] * w[0] - u[0] * w[2]);
    n2[2] = -(u[0] * w[1] - u[1] * w[0]);
    k[0] = n1[1] * n2[2] - n1[2] * n2[1];
    k[1] = n1[2] * n2[0] - n1[0] * n2[2];
    k[2] = n1[0] * n2[1] - n1[1] * n2[0];
    double s = sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2]);
    double c0 = n1[0] * n2[0] + n1[1] * n2[1] + n1[2] * n2[2];
    return atan2(s, c0) * (45.0 / atan(1.0));
}

static void add_face(side *sd, size_t *n, const uint32_t t[3], uint32_t kind)
{
    for (int j = 0; j < 3; j++) {
        uint32_t a = t[j], b = t[(j + 1) % 3];
        sd[*n] = (side){a < b ? a : b, a < b ? b : a, t[(j + 2) % 3], kind};
        (*n)++;
    }
}

/* The edges over `degrees` into *edges (2 ids each, api_malloc; caller frees), their number in
 * *ne; false for lack of memory. */
static bool crease_edges(const sd_level *lv, double degrees, uint32_t **edges, uint32_t *ne)
{
    *edges = NULL;
    *ne = 0;
    int nc;
    const double *x = sd_level_channel(lv, 0, &nc);
    uint32_t ntr = sd_level_num_cells(lv, SD_CELL_TRIANGLE), nb = sd_level_solid_boundary(lv, NULL);
    size_t nf = (size_t)ntr + nb;
    uint32_t *bnd = api_malloc(((size_t)nb * 3 + 1) * sizeof *bnd);
    side *sd = api_malloc((3 * nf + 1) * sizeof *sd);
    uint32_t *out = api_malloc((3 * nf + 1) * sizeof *out);
    if (!bnd || !sd || !out) {
        api_free(bnd);
        api_free(sd);
        api_free(out);
        return false;
    }
    sd_level_solid_boundary(lv, bnd);
    size_t n = 0;
    for (uint32_t i = 0; i < ntr; i++) {
        uint32_t t[3];
        sd_level_cell(lv, SD_CELL_TRIANGLE, i, t);
        add_face(sd, &n, t, 0);
    }
    for (uint32_t i = 0; i < nb; i++)
        add_face(sd, &n, bnd + 3 * (size_t)i, 1);
    qsort(sd, n, sizeof *sd, side_cmp);
    for (size_t i = 0, j; i < n; i = j) {
        for (j = i + 1; j < n && !side_cmp(&sd[i], &sd[j]); j++)
            ;
        if (j - i != 2 || sd[i].kind != sd[i + 1].kind)
            continue; /* open boundary or non-manifold: their own rules */
        if (dihedral(x, sd[i].a, sd[i].b, sd[i].c, sd[i + 1].c) > degrees) {
            out[2 * *ne] = sd[i].a;
            out[2 * *ne + 1] = sd[i].b;
            (*ne)++;
        }
    }
    api_free(bnd);
    api_free(sd);
    *edges = out;
    return true;
}

int api_crease_tags(const api_model *cur, json_t *v, api_tags *tags, api_problem *p)
{
    if (!json_is_number(v))
        return api_fail_at(p, 400, "wrong-type", "/crease_angle", "must be a number of degrees");
    double d = json_number_value(v);
    if (!(d >= 0 && d <= 180)) {
        char num[32];
        return api_fail_at(p, 422, "out-of-range", "/crease_angle",
                           "the crease angle is between 0 and 180 degrees, not %s",
                           sd_shortest(d, num));
    }
    if (!cur->in || !cur->level0)
        return api_fail_at(p, 409, "no-complex", "/crease_angle",
                           "the crease angle tags edges of the complex; PUT the complex first");
    uint32_t *e, ne;
    api_model *m = (api_model *)cur; /* the lock edits take: positions are read */
    pthread_rwlock_rdlock(&m->data);
    bool ok = crease_edges(cur->level0, d, &e, &ne);
    pthread_rwlock_unlock(&m->data);
    if (!ok)
        return api_fail(p, 503, "out-of-memory", "out of memory finding creases");
    /* the posted edge tags, as sorted keys, so that none is added twice */
    size_t nidx = 0, nk = 0;
    for (uint32_t i = 0; i < tags->n; i++)
        nidx += tags->size[i];
    uint64_t *keys = api_malloc(((size_t)tags->n + 1) * sizeof *keys);
    uint8_t *size = api_plain_realloc(tags->size, (size_t)tags->n + ne + 1);
    if (size)
        tags->size = size;
    uint32_t *idx = api_plain_realloc(tags->idx, (nidx + 2 * (size_t)ne + 1) * sizeof *idx);
    if (idx)
        tags->idx = idx;
    if (!keys || !size || !idx) {
        api_free(keys);
        api_free(e);
        return api_fail(p, 503, "out-of-memory", "out of memory finding creases");
    }
    for (uint32_t i = 0, off = 0; i < tags->n; off += tags->size[i++])
        if (tags->size[i] == 2) {
            uint32_t a = tags->idx[off], b = tags->idx[off + 1];
            keys[nk++] = a < b ? (uint64_t)a << 32 | b : (uint64_t)b << 32 | a;
        }
    qsort(keys, nk, sizeof *keys, key_cmp);
    for (uint32_t i = 0; i < ne; i++) {
        uint64_t k = (uint64_t)e[2 * i] << 32 | e[2 * i + 1];
        if (bsearch(&k, keys, nk, sizeof *keys, key_cmp))
            continue;
        tags->size[tags->n++] = 2;
        tags->idx[nidx++] = e[2 * i];
        tags->idx[nidx++] = e[2 * i + 1];
    }
    tags->crease = (api_crease){.set = true, .degrees = d, .tagged = ne};
    api_free(keys);
    api_free(e);
    return 0;
}

json_t *api_crease_json(const api_tags *tags)
{
    if (!tags->crease.set)
        return NULL;
    return json_pack("{s:f, s:I}", "degrees", tags->crease.degrees, "tagged",
                     (json_int_t)tags->crease.tagged);
}
