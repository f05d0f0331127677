/* carry.c — the tags and per-simplex rules of a complex carried through one refinement step
 * (sd_refine), so that the children of tagged simplices stay tagged and keep their rules (000 Sec. 4.2;
 * docs/RULES.md "Priority").
 *
 * What a step did is read off the refinement alone: the new vertex splitting each edge (the
 * refinement's `split`, new vertices numbered after the old ones) and the triangles of the
 * refined complex (every listed triangle and the faces of every tetrahedron), both sorted for
 * binary search. Then:
 *   a vertex                stays itself;
 *   an edge                 stays, or becomes its two halves when split; its N1 / N2 / G2 choice
 *                           also goes to the vertex splitting it (a G1 edge's midpoint lies on
 *                           its crease, which the halves carry);
 *   a triangle              becomes its children in the refined complex (1, 2 or 4);
 *   a petal tag             keeps its vertex and names the child of its triangle at it;
 *   an N2 pair              each of its two simplices is replaced by its child holding the new
 *                           simplex (a curve segment by its half at the vertex); a choice whose
 *                           triangle has no such child is dropped.
 * Like sd_refine this allocates with the C library (the caller owns the result), so the
 * arrays move straight into the next step's input. Nothing here knows positions: whether a
 * carried override still fits the refined complex is for sd_complex_set_overrides to say.
 */
#include "hash.h" /* sdi_key */
#include <stdlib.h>
#include <string.h>

/* What one refinement step did. */
typedef struct step {
    size_t nsplit;
    uint32_t (*split)[3];     /* (a < b, new vertex), sorted */
    size_t nface;
    uint32_t (*face)[3];      /* sorted triples of every triangle of the refined complex */
} step;

static int cmp_ids(const uint32_t *a, const uint32_t *b, int n)
{
    for (int i = 0; i < n; i++)
        if (a[i] != b[i])
            return a[i] < b[i] ? -1 : 1;
    return 0;
}
static int cmp_pair(const void *x, const void *y) { return cmp_ids(x, y, 2); }
static int cmp_tri(const void *x, const void *y) { return cmp_ids(x, y, 3); }

static void step_free(step *s)
{
    free(s->split);
    free(s->face);
}

static bool step_build(const sd_refinement *r, step *s)
{
    const uint32_t nold = (uint32_t)(r->nv - r->nsplit);
    memset(s, 0, sizeof *s);
    s->nsplit = r->nsplit;
    size_t nf = 0;
    for (size_t i = 0; i < r->ns; i++)
        nf += r->size[i] == 3 ? 1 : r->size[i] == 4 ? 4 : 0;
    s->split = malloc((r->nsplit + 1) * sizeof *s->split);
    s->face = malloc((nf + 1) * sizeof *s->face);
    if (!s->split || !s->face) {
        step_free(s);
        return false;
    }
    for (size_t i = 0; i < r->nsplit; i++) {
        uint32_t a = r->split[i][0], b = r->split[i][1];
        s->split[i][0] = a < b ? a : b;
        s->split[i][1] = a < b ? b : a;
        s->split[i][2] = (uint32_t)(nold + i);
    }
    qsort(s->split, s->nsplit, sizeof *s->split, cmp_pair);
    size_t off = 0;
    for (size_t i = 0; i < r->ns; off += r->size[i++]) {
        const uint32_t *v = r->idx + off;
        int nk = r->size[i] == 4 ? 4 : r->size[i] == 3 ? 1 : 0; /* a tet's faces skip a vertex */
        for (int skip = 0; skip < nk; skip++) {
            uint32_t k[4], n = 0;
            for (int j = 0; j < r->size[i]; j++)
                if (r->size[i] == 3 || j != skip)
                    k[n++] = v[j];
            sdi_key(k, k, 3);
            memcpy(s->face[s->nface++], k, 3 * sizeof *k);
        }
    }
    qsort(s->face, s->nface, sizeof *s->face, cmp_tri);
    return true;
}

/* The new vertex splitting edge a-b, or UINT32_MAX. */
static uint32_t step_mid(const step *s, uint32_t a, uint32_t b)
{
    uint32_t k[3] = {a < b ? a : b, a < b ? b : a, 0};
    uint32_t (*hit)[3] = bsearch(k, s->split, s->nsplit, sizeof *s->split, cmp_pair);
    return hit ? (*hit)[2] : UINT32_MAX;
}

static bool step_is_face(const step *s, const uint32_t *v)
{
    uint32_t k[4];
    sdi_key(k, v, 3);
    return bsearch(k, s->face, s->nface, sizeof *s->face, cmp_tri) != NULL;
}

/* The children of triangle t in the refined complex (at most 4), the ones containing all of
 * `must` (n_must ids) only. Returns their number. */
static int step_tri_children(const step *s, const uint32_t t[3], const uint32_t *must,
                             int n_must, uint32_t out[4][3])
{
    uint32_t pts[6] = {t[0], t[1], t[2]}, np = 3, mid[3];
    for (int j = 0; j < 3; j++)
        if ((mid[j] = step_mid(s, t[j], t[(j + 1) % 3])) != UINT32_MAX)
            pts[np++] = mid[j];
    int n = 0;
    for (uint32_t i = 0; i < np; i++)
        for (uint32_t j = i + 1; j < np; j++)
            for (uint32_t k = j + 1; k < np && n < 4; k++) {
                uint32_t c[3] = {pts[i], pts[j], pts[k]};
                if (!step_is_face(s, c))
                    continue;
                bool ok = true;
                for (int u = 0; u < n_must; u++)
                    ok &= c[0] == must[u] || c[1] == must[u] || c[2] == must[u];
                if (ok)
                    memcpy(out[n++], c, sizeof c);
            }
    return n;
}

/* Singular tags and petal tags; out's arrays allocated (room for the most children). */
static void carry_tags(const step *s, const sd_tag_set *in, sd_tag_set *out)
{
    size_t off = 0, at = 0;
    for (size_t i = 0; i < in->ntags; off += in->size[i++]) {
        const uint32_t *v = in->idx + off;
        uint32_t mid;
        if (in->size[i] == 2 && (mid = step_mid(s, v[0], v[1])) != UINT32_MAX) {
            for (int h = 0; h < 2; h++) {
                out->from[out->ntags] = (uint32_t)i;
                out->size[out->ntags++] = 2;
                out->idx[at++] = v[h];
                out->idx[at++] = mid;
            }
        } else if (in->size[i] == 3) {
            uint32_t ch[4][3];
            int n = step_tri_children(s, v, NULL, 0, ch);
            for (int c = 0; c < n; c++) {
                out->from[out->ntags] = (uint32_t)i;
                out->size[out->ntags++] = 3;
                memcpy(out->idx + at, ch[c], sizeof ch[c]);
                at += 3;
            }
        } else {
            out->from[out->ntags] = (uint32_t)i;
            out->size[out->ntags++] = in->size[i];
            memcpy(out->idx + at, v, in->size[i] * sizeof *v);
            at += in->size[i];
        }
    }
    for (size_t i = 0; i < in->npetals; i++) { /* the vertex stays; its triangle's child at it */
        sd_petal_tag q = in->petals[i];
        uint32_t ch[4][3];
        if (step_tri_children(s, q.triangle, &q.vertex, 1, ch))
            memcpy(q.triangle, ch[0], sizeof ch[0]);
        out->petals[out->npetals++] = q;
    }
}

/* An N2 choice's pair, carried to the children holding its (new) simplex; false if a triangle of
 * the pair has none. */
static bool carry_pair(const step *s, sd_override *o)
{
    for (int j = 0; j < 2; j++) {
        uint32_t *q = o->pair[j];
        if (o->pair_size == 2) { /* a curve segment [x, y] holding the vertex */
            uint32_t qm = step_mid(s, q[0], q[1]);
            if (qm != UINT32_MAX) {
                q[0] = o->simplex[0];
                q[1] = qm;
            }
        } else {
            uint32_t ch[4][3];
            if (!step_tri_children(s, q, o->simplex, o->nverts, ch))
                return false;
            memcpy(q, ch[0], sizeof ch[0]);
        }
    }
    return true;
}

static void carry_overrides(const step *s, const sd_tag_set *in, sd_tag_set *out)
{
    for (size_t i = 0; i < in->noverrides; i++) {
        const sd_override *o = &in->overrides[i];
        uint32_t mid = o->nverts == 2 ? step_mid(s, o->simplex[0], o->simplex[1]) : UINT32_MAX;
        /* the new simplices: the vertex or unsplit edge itself, or both halves and the midpoint */
        sd_override c[3];
        int nc = 0;
        if (mid == UINT32_MAX) {
            c[nc++] = *o;
        } else {
            for (int h = 0; h < 2; h++) {
                c[nc] = *o;
                c[nc].simplex[0] = o->simplex[h];
                c[nc].simplex[1] = mid;
                nc++;
            }
            if (o->rule != SD_RULE_G1) { /* a G1 edge's midpoint lies on its crease */
                c[nc] = *o;
                c[nc].nverts = 1;
                c[nc].simplex[0] = mid;
                nc++;
            }
        }
        for (int k = 0; k < nc; k++)
            if (c[k].rule != SD_RULE_N2 || carry_pair(s, &c[k]))
                out->overrides[out->noverrides++] = c[k];
    }
}

sd_result sd_refine_carry(const sd_refinement *r, const sd_tag_set *in, sd_tag_set *out,
                          sd_error *err)
{
    memset(out, 0, sizeof *out);
    step s = {0}; /* nothing to carry (the usual refinement): no faces to sort */
    if ((in->ntags || in->npetals || in->noverrides) && !step_build(r, &s))
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory carrying tags and rules");
    /* room for the most each can become: an edge 2 halves, a triangle 4 children (12 ids); an
     * override its 2 halves and the midpoint */
    out->size = malloc(4 * in->ntags + 1);
    out->idx = malloc((12 * in->ntags + 1) * sizeof *out->idx);
    out->petals = malloc((in->npetals + 1) * sizeof *out->petals);
    out->overrides = malloc((3 * in->noverrides + 1) * sizeof *out->overrides);
    out->from = malloc((4 * in->ntags + 1) * sizeof *out->from);
    if (!out->size || !out->idx || !out->petals || !out->overrides || !out->from) {
        step_free(&s);
        sd_tag_set_free(out);
        return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory carrying tags and rules");
    }
    carry_tags(&s, in, out);
    carry_overrides(&s, in, out);
    step_free(&s);
    return SD_OK;
}

void sd_tag_set_free(sd_tag_set *t)
{
    if (!t)
        return;
    free(t->idx);
    free(t->size);
    free(t->petals);
    free(t->overrides);
    free(t->from);
    memset(t, 0, sizeof *t);
}
