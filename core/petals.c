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
