/* petals.c — the petals of a vertex: its maximal triangles, joined across some of the edges at
 * it, walked in order around it.
 *
 * Two kinds of joining edge make two kinds of petal (sdi_petal_mode):
 *   SDI_PETAL_FAN  edges between exactly two maximal triangles and in nothing else maximal (not
 *                  NM_C2B): the fans of N2 choices and of N1 with dimension 2 (overrides.c);
 *   SDI_PETAL_YZ   edges Ying-Zorin's rules treat as non-singular (sdi_yz_singular_edge): the
 *                  petals of 003 Sec. 2, for the rules of singular vertices (rules.c), their
 *                  flattened rows (yz.c) and the validation of petal tags (below).
 * Either way a joining edge has exactly two maximal triangles and a triangle two edges at the
 * vertex, so a petal is a path of triangles (open, or a dart when both ends are the same edge) or
 * a cycle (closed), and walking it needs no marks: from an edge into a triangle, out through the
 * triangle's other edge at the vertex, into the triangle across it, until an edge that does not
 * join (the petal's end) or the first edge again (closed). Every walk is in a fixed order, which
 * the Ying-Zorin rows depend on: their weights follow the ring's order.
 *
 * Petal tags (sd_complex_set_petals): which corner an open petal of a complex singular vertex
 * makes; validated here (one walk per tag's petal) and stored per level-0 triangle.
 */
#include "internal.h"
#include <stdlib.h>
#include <string.h>

static inline bool joins(const sd_topo *t, uint32_t e, int mode)
{
    return mode == SDI_PETAL_FAN ? !(t->enm[e] & NM_C2B) : !sdi_yz_singular_edge(t, e);
}

static inline uint32_t other_end(const sd_topo *t, uint32_t e, uint32_t v)
{
    return t->ev[e][0] == v ? t->ev[e][1] : t->ev[e][0];
}

uint32_t sdi_max_faces(const sd_topo *t, const sdi_rel *ef, uint32_t e, uint32_t two[2])
{
    uint32_t n = 0;
    for (uint32_t k = ef->off[e]; k < ef->off[e + 1]; k++)
        if (t->fflag[ef->item[k]] & FF_MAX) {
            if (n < 2)
                two[n] = ef->item[k];
            n++;
        }
    return n;
}

uint32_t sdi_petal_walk(const sd_topo *t, const sdi_rel *ef, int mode, uint32_t v, uint32_t e0,
                        uint32_t f, sdi_walk *w)
{
    uint32_t e = e0;
    w->n = 0;
    for (;;) {
        uint32_t next = UINT32_MAX;
        for (int j = 0; j < 3; j++) { /* f's other edge at v */
            uint32_t x = t->fe[f][j];
            if (x != e && (t->ev[x][0] == v || t->ev[x][1] == v))
                next = x;
        }
        if (next == UINT32_MAX)
            return UINT32_MAX;
        if (next == e0 || !joins(t, next, mode))
            return next;
        uint32_t two[2];
        if (w->n == w->cap || sdi_max_faces(t, ef, next, two) != 2)
            return UINT32_MAX;
        f = two[0] == f ? two[1] : two[0];
        if (w->edge)
            w->edge[w->n] = next;
        w->face[w->n++] = f;
        e = next;
    }
}

bool sdi_petal_of(const sd_topo *t, const sdi_rel *ef, int mode, uint32_t v, uint32_t f0,
                  sdi_petal *p)
{
    uint32_t at[2], na = 0; /* f0's two edges at v */
    for (int j = 0; j < 3; j++) {
        uint32_t e = t->fe[f0][j];
        if (t->ev[e][0] == v || t->ev[e][1] == v) {
            if (na < 2)
                at[na] = e;
            na++;
        }
    }
    if (na != 2 || p->cap < 2)
        return false;
    /* one way round from f0 (out through at[1]), then the other (out through at[0]) unless the
     * first came back to at[0] */
    p->face[0] = f0;
    p->nf = 1;
    p->ninner = p->nsing = 0;
    for (int side = 0; side < 2; side++) {
        sdi_walk w = {p->face + p->nf, p->inner ? p->inner + p->ninner : NULL, 0, p->cap - 1 - p->nf};
        uint32_t end = sdi_petal_walk(t, ef, mode, v, at[side], f0, &w);
        if (end == UINT32_MAX)
            return false;
        p->nf += w.n;
        p->ninner += w.n;
        if (end == at[side] && joins(t, end, mode)) { /* closed: the first edge is inner too */
            if (p->inner)
                p->inner[p->ninner] = end;
            p->ninner++;
            return true;
        }
        if (p->nsing == 0 || p->sing[0] != end) /* a dart ends at the same edge both ways */
            p->sing[p->nsing++] = end;
    }
    return true;
}
/* ---- petal tags (003 Sec. 2: convex, concave or smooth corner) ---------------------------- */

/* The petal of v holding maximal triangle f0: its triangles (out, returns their number; room for
 * nf + 1) and its distinct singular edges at v (sing, *ns). */
static uint32_t petal_faces(const sd_topo *t, const sdi_rels *R, uint32_t v, uint32_t f0,
                            uint32_t *out, uint32_t sing[2], uint32_t *ns)
{
    sdi_petal p = {.face = out, .cap = t->nf + 1};
    sdi_petal_of(t, &R->r[SDI_EF], SDI_PETAL_YZ, v, f0, &p);
    sing[0] = p.sing[0];
    sing[1] = p.sing[1];
    *ns = p.nsing;
    return p.nf;
}

static int cmp_petal_at(const void *a, const void *b)
{
    const sd_petal_at *p = a, *q = b;
    return p->v != q->v ? (p->v > q->v) - (p->v < q->v) : (p->f > q->f) - (p->f < q->f);
}

/* The (unordered) pair of singular edges bounding an open petal, as one key. */
static uint64_t pair_key(const uint32_t s[2])
{
    uint32_t a = s[0] < s[1] ? s[0] : s[1], b = s[0] < s[1] ? s[1] : s[0];
    return (uint64_t)a << 32 | b;
}

/* A smooth tag: its vertex, index and pair of singular edges. */
typedef struct smooth_at {
    uint32_t v, tag;
    uint64_t key;
} smooth_at;

static int cmp_smooth_at(const void *a, const void *b)
{
    const smooth_at *p = a, *q = b;
    return p->v != q->v ? (p->v > q->v) - (p->v < q->v) : (p->key > q->key) - (p->key < q->key);
}

/* A validation of petal tags: the tags, level 0 and its relations, and what the walks found. */
typedef struct ptcheck {
    const sd_topo *t;
    const sdi_rels *R;
    const sd_petal_tag *pt;
    uint32_t *faces;     /* a petal's triangles */
    uint32_t *owner;     /* per face: the tag whose petal holds it, or UINT32_MAX */
    uint8_t *tagv;       /* per vertex: 1 tagged singular, 2 on a tagged edge or triangle */
    uint64_t *pairs;     /* per tag: its petal's pair of singular edges */
    sd_petal_at *at;     /* the stored form, one entry per triangle of a tagged petal */
    size_t nat, cap;
} ptcheck;

/* Ids and kinds, before anything reads them. */
static sd_result check_ids(const sd_topo *t, const sd_petal_tag *pt, size_t n, sd_error *err)
{
    for (size_t i = 0; i < n; i++) {
        const sd_petal_tag *p = &pt[i];
        if (p->vertex >= t->nv)
            return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_PT_FIELD_VERTEX,
                           "petal tag %zu: vertex %u out of range", i, p->vertex);
        for (int j = 0; j < 3; j++)
            if (p->triangle[j] >= t->nv)
                return sdi_fail(err, SD_ERR_INDEX, (long)i, SD_PT_FIELD_TRIANGLE,
                               "petal tag %zu: vertex %u out of range", i, p->triangle[j]);
        if (p->kind < SD_PETAL_CONVEX || p->kind > SD_PETAL_SMOOTH)
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_KIND,
                           "petal tag %zu: the kind is convex, concave or smooth", i);
    }
    return SD_OK;
}

void sdi_tagged_vertices(const sd_complex *c, const sd_topo *t, uint8_t *tagv)
{
    /* vertices of the singular tags (1: tagged, 2: on a tagged edge or triangle): they follow
     * the tags whatever the rule preferences, so a petal tag there would never act. (A rule
     * choice of the vertex's own, or the G1 default, can also make a tag idle; those come from
     * PUT /rules and are not refused here: the tag waits, like under chang-qin.) */
    for (size_t k = 0; k < c->ntags; k++) {
        uint32_t id = c->tag_at[k];
        if (c->tag_k[k] == 1)
            tagv[id] = 1;
        else
            for (int j = 0; j < c->tag_k[k]; j++) {
                uint32_t w = c->tag_k[k] == 2 ? t->ev[id][j] : t->fv[id][j];
                if (!tagv[w])
                    tagv[w] = 2;
            }
    }
}

/* Tag i: its triangle, vertex and petal, which no earlier tag may name; its petal's triangles
 * go into P->at. */
static sd_result check_tag(ptcheck *P, sd_mem *m, size_t i, sd_error *err)
{
    const sd_topo *t = P->t;
    const sdi_rel *ve = &P->R->r[SDI_VE];
    const sd_petal_tag *p = &P->pt[i];
    uint32_t *faces = P->faces, *owner = P->owner;
    uint32_t v = p->vertex;
    uint32_t f = sdi_rels_face(P->R, p->triangle);
    if (f == UINT32_MAX || !(t->fflag[f] & FF_MAX))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                        "petal tag %zu: [%u, %u, %u] is not a surface triangle of the complex "
                        "(a maximal triangle, not a face of a tetrahedron)", i, p->triangle[0],
                        p->triangle[1], p->triangle[2]);
    if (!sdi_face_has(t, f, v))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                        "petal tag %zu: the triangle does not hold vertex %u", i, v);
    /* a complex singular vertex of triangles only (003 Sec. 2): non-manifold, and not simple
     * (one flower with exactly two singular edges: boundary or non-manifold ones) */
    uint32_t nsing = 0;
    for (uint32_t k = ve->off[v]; k < ve->off[v + 1]; k++)
        nsing += sdi_yz_counts_singular(t, ve->item[k]);
    if (t->vfam[v] != FAM2 || !nm_type(t->vnm[v]) || sdi_yz_simple(nm_type(t->vnm[v]), nsing))
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_VERTEX,
                        "petal tag %zu: vertex %u is not a complex singular vertex of a "
                        "triangle mesh (a non-manifold vertex where only triangles meet, not "
                        "one flower with exactly two singular edges): corner kinds do not "
                        "apply there", i, v);
    if (P->tagv[v]) /* as rules.c (yz_vertex): the singular tags win */
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_VERTEX,
                        "petal tag %zu: vertex %u %s, so its petals have no corner rule", i, v,
                        P->tagv[v] == 1 ? "is tagged singular (fixed with plain edge rules)"
                                        : "lies on a tagged crease or embedded surface (it "
                                          "follows that)");
    if (owner[f] != UINT32_MAX)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                        "petal tag %zu: tag %u already names this petal of vertex %u", i,
                        owner[f], v);
    uint32_t sing[2], ns, nf = petal_faces(t, P->R, v, f, faces, sing, &ns);
    if (ns != 2)
        return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                        "petal tag %zu: the petal of vertex %u holding this triangle is %s; "
                        "corner kinds apply to open petals, bounded by two singular edges", i, v,
                        ns == 0 ? "closed (no singular edge)"
                        : ns == 1 ? "a dart (one singular edge)" : "not a fan");
    for (uint32_t k = 0; k < nf; k++)
        if (owner[faces[k]] != UINT32_MAX) /* a triangle of the petal, but not f */
            return sdi_fail(err, SD_ERR_ARG, (long)i, SD_PT_FIELD_TRIANGLE,
                            "petal tag %zu: tag %u already names this petal of vertex %u", i,
                            owner[faces[k]], v);
    /* a triangle holds v once, so owner[] marks (v, petal) */
    for (uint32_t k = 0; k < nf; k++)
        owner[faces[k]] = (uint32_t)i;
    P->pairs[i] = pair_key(sing);
    if (P->nat + nf > P->cap) {
        size_t nc = P->cap ? 2 * P->cap : 64;
        while (nc < P->nat + nf)
            nc *= 2;
        sd_petal_at *na = sdi_realloc(m, P->at, nc * sizeof *na);
        if (!na)
            return sdi_fail_nomem(err, m);
        P->at = na;
        P->cap = nc;
    }
    for (uint32_t k = 0; k < nf; k++)
        P->at[P->nat++] = (sd_petal_at){v, faces[k], (uint8_t)p->kind};
    return SD_OK;
}

/* 003: petals sharing both singular edges are both corners or both smooth. The smooth tags
 * sorted by (vertex, pair); per such vertex, every petal between a smooth tag's two edges must be
 * tagged smooth (each petal walked once: `walked`, cleared per vertex). */
static sd_result check_smooth(ptcheck *P, sd_mem *m, size_t n, sd_error *err)
{
    const sd_topo *t = P->t;
    const sdi_rels *R = P->R;
    const sdi_rel *vf = &R->r[SDI_VF];
    const sd_petal_tag *pt = P->pt;
    uint32_t *faces = P->faces, *owner = P->owner;
    const uint64_t *pairs = P->pairs;
    sd_result rc = SD_OK;
    size_t nsm = 0;
    smooth_at *sm = sdi_alloc(m, n * sizeof *sm);
    uint8_t *walked = sdi_calloc(m, (size_t)t->nf + 1, 1);
    if (!sm || !walked) {
        rc = sdi_fail_nomem(err, m);
        goto out;
    }
    for (size_t i = 0; i < n; i++)
        if (pt[i].kind == SD_PETAL_SMOOTH)
            sm[nsm++] = (smooth_at){pt[i].vertex, (uint32_t)i, pairs[i]};
    qsort(sm, nsm, sizeof *sm, cmp_smooth_at);
    for (size_t a = 0, b; a < nsm; a = b) {
        uint32_t v = sm[a].v;
        for (b = a; b < nsm && sm[b].v == v; b++)
            ;
        for (uint32_t k = vf->off[v]; k < vf->off[v + 1] && !rc; k++) {
            uint32_t g = vf->item[k], s2[2], ns2;
            if (!(t->fflag[g] & FF_MAX) || walked[g])
                continue;
            uint32_t tag = owner[g];
            bool tagged = tag != UINT32_MAX && pt[tag].vertex == v;
            uint64_t key;
            if (tagged) { /* its key is known; its triangles need no walk */
                if (pt[tag].kind == SD_PETAL_SMOOTH)
                    continue;
                key = pairs[tag];
                ns2 = 2;
            } else {
                uint32_t ng = petal_faces(t, R, v, g, faces, s2, &ns2);
                for (uint32_t q = 0; q < ng; q++)
                    walked[faces[q]] = 1;
                key = pair_key(s2);
            }
            smooth_at want = {v, 0, key};
            const smooth_at *hit = ns2 == 2 ? bsearch(&want, sm + a, b - a, sizeof *sm,
                                                      cmp_smooth_at) : NULL;
            if (hit) {
                const uint32_t *gv = t->fv[g];
                rc = sdi_fail(err, SD_ERR_ARG, (long)hit->tag, SD_PT_FIELD_KIND,
                             "petal tag %u: a smooth petal needs every petal of vertex %u "
                             "between the same two singular edges smooth too (003 Sec. 2), "
                             "and the one holding [%u, %u, %u] is not tagged smooth",
                             hit->tag, v, gv[0], gv[1], gv[2]);
            }
        }
        for (uint32_t k = vf->off[v]; k < vf->off[v + 1]; k++)
            walked[vf->item[k]] = 0;
        if (rc)
            goto out;
    }
out:
    sdi_free(m, sm);
    sdi_free(m, walked);
    return rc;
}

/* Validation in O(tags + triangles at the tagged vertices): each tag's petal is walked once
 * (a triangle already claimed by an earlier tag is a duplicate, found before the walk), and
 * the smooth rule walks each vertex with a smooth tag once. */
sd_result sd_complex_set_petals(sd_complex *c, const sd_petal_tag *pt, size_t n, sd_error *err)
{
    sd_topo *t = &c->lv[0]->t;
    sd_mem *m = &c->mem;
    sdi_rels R = {.t = t};
    ptcheck P = {.t = t, .R = &R, .pt = pt};
    sd_result rc = check_ids(t, pt, n, err);
    if (rc)
        return rc;
    if (n && (!sdi_rels_need(m, &R, SDI_TAG_RELS) ||
              !(P.faces = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *P.faces)) ||
              !(P.owner = sdi_alloc(m, ((size_t)t->nf + 1) * sizeof *P.owner)) ||
              !(P.tagv = sdi_calloc(m, (size_t)t->nv + 1, 1)) ||
              !(P.pairs = sdi_alloc(m, n * sizeof *P.pairs)))) {
        rc = sdi_fail_nomem(err, m);
        goto out;
    }
    if (n) {
        for (uint32_t f = 0; f < t->nf; f++)
            P.owner[f] = UINT32_MAX;
        sdi_tagged_vertices(c, t, P.tagv);
    }
    bool any_smooth = false;
    for (size_t i = 0; i < n && !rc; i++) {
        rc = check_tag(&P, m, i, err);
        any_smooth |= pt[i].kind == SD_PETAL_SMOOTH;
    }
    if (!rc && any_smooth)
        rc = check_smooth(&P, m, n, err);
    if (rc)
        goto out;
    if (P.nat)
        qsort(P.at, P.nat, sizeof *P.at, cmp_petal_at);
    sdi_free(m, c->pet);
    c->pet = P.at;
    c->npet = P.nat;
    P.at = NULL;
    sdi_drop_rules(c, c->lv[0]); /* level 0's rules change; every finer level follows */
out:
    sdi_free(m, P.at);
    sdi_free(m, P.faces);
    sdi_free(m, P.owner);
    sdi_free(m, P.tagv);
    sdi_free(m, P.pairs);
    sdi_rels_free(m, &R);
    return rc;
}
