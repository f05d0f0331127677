/* edit.c — control-point edits and detail offsets, recomputed through the cached matrices
 * (004 Sec. 4.1 and 5.2; docs/API.md "Control-point edits", "Live edits").
 *
 * An edit recomputes, it does not accumulate: level l+1 is S_l p^l (+ its detail offsets), so a
 * change at a few points of level l changes the rows of S_l that read them, and each such row is
 * summed again from its whole stencil by the function the level build sums it with (csr.c
 * row_sum), plus the point's offset. After any number of edits every cached level is the bytes a
 * new complex built from the edited control points and the same offsets gives — no drift. The
 * rows that read a point come from S's column index (csr.c), built with each level, so the first
 * edit costs what later ones do; its cost follows the edited region, not the mesh.
 *
 * One engine (run, below) serves every kind of change: a move of a control point (level 0),
 * a move at level l >= 1, which stores the offset d = position - (S_{l-1} p^{l-1}) at that point
 * (computed after the coarser moves of the same call, so the point ends at the position), and an
 * offset set or cleared directly (sd_complex_set_details). The changes are taken level by level,
 * coarse to fine: level l's recomputed points are its moved points and the rows of S_{l-1} that
 * read a recomputed point of level l-1 — each point once, through the level's scratch (`slot`
 * or a bitmap, and the lists, kept between edits so that they cost no allocation, left clean),
 * then taken in increasing order so that the rows and points are read in order; their new values
 * go into the lists, and a row reads the new value of a point it uses from the list, so nothing
 * is written yet.
 *
 * All-or-nothing: the lists and the new offset lists are complete before anything is written;
 * only then are they copied into the levels. A failure (no memory, an offset out of range) leaves
 * the complex as it was, including the levels the call computed for its moves (dropped again).
 *
 * Rules that read positions: Ying-Zorin's corner petals measure the angle alpha between their
 * singular edges (rules.c marks the points in the level's `geo`). A change of such a point at
 * level s makes S_s stale, so the lists stop at level s: levels 0..s are written, s's rules built
 * again from the new positions (the old ones kept aside), and the finer levels recomputed whole
 * beside the old ones (kept until the new ones are complete, so a failure can put everything
 * back); moves at those finer levels take their offsets as each level is made. The result is the
 * one a new complex with the moved points gives. Tangent-plane constraints (tangent.c) read every
 * position after S, so on a complex with them every change of positions takes this path, from
 * the level coarser than the first changed one when that is 1 or finer: a level's points are then
 * S p plus their modifications, and a move there takes its offset against those.
 */
#include "internal.h"
#include <math.h>
#include <stdlib.h>
#include <stdio.h>
#include <string.h>

/* ---- the engine's input: operations at points of levels ---------------------------------------- */

enum { OP_MOVE, OP_OFFSET, OP_CLEAR };
typedef struct op {
    uint32_t level, index, kind;
    uint32_t item; /* where its values are (values + nc item) and what an error names */
    uint32_t pos;  /* its entry in the level's new offset list (UINT32_MAX: none) */
} op;

static int op_cmp(const void *a, const void *b)
{
    const op *x = a, *y = b;
    if (x->level != y->level)
        return x->level < y->level ? -1 : 1;
    if (x->index != y->index)
        return x->index < y->index ? -1 : 1;
    return (x->item > y->item) - (x->item < y->item);
}

/* Sort ops by (level, index, item) and refuse a point named twice (item: the first op, in the
 * caller's order, that repeats an earlier one). */
static sd_result sort_ops(op *ops, size_t n, sd_error *err)
{
    qsort(ops, n, sizeof *ops, op_cmp);
    size_t worst = SIZE_MAX; /* the op whose item that is */
    for (size_t i = 1; i < n; i++) /* the second of each group of equal points */
        if (ops[i].level == ops[i - 1].level && ops[i].index == ops[i - 1].index &&
            (i < 2 || ops[i - 2].level != ops[i].level || ops[i - 2].index != ops[i].index) &&
            (worst == SIZE_MAX || ops[i].item < ops[worst].item))
            worst = i;
    if (worst == SIZE_MAX)
        return SD_OK;
    return sdi_fail(err, SD_ERR_REPEATED, (long)ops[worst].item, -1,
                    "point %u of level %u is edited twice", ops[worst].index, ops[worst].level);
}

/* ---- the recomputed points of one level ------------------------------------------------------ */

/* The lists (id, new and old values nc each, chg: 1 where the new value differs from the old,
 * bit for bit) are the level's scratch, kept between edits (sdi_escratch); entries [0, nops) are
 * the level's ops, in op order. */
typedef struct pset {
    uint32_t n, nops;
    const op *ops;
    sdi_escratch *s;
} pset;

void sdi_escratch_free(sd_mem *m, sdi_escratch *s)
{
    if (!s)
        return;
    sdi_free(m, s->mark);
    sdi_free(m, s->id);
    sdi_free(m, s->nv);
    sdi_free(m, s->ov);
    sdi_free(m, s->chg);
    sdi_free(m, s);
}

static inline void copy_nc(double *d, const double *x, int nc)
{
    if (nc == 3) {
        d[0] = x[0];
        d[1] = x[1];
        d[2] = x[2];
    } else
        for (int q = 0; q < nc; q++)
            d[q] = x[q];
}

static inline bool same_bits(const double *a, const double *b, int nc)
{
    return nc == 3 ? !memcmp(a, b, 3 * sizeof *a) : !memcmp(a, b, (size_t)nc * sizeof *a);
}

/* One edit: its levels' point sets and scratch maps, and the new offset lists. */
typedef struct edit {
    sd_complex *c;
    sd_mem *m;
    int ch, nc, top;               /* channel, its components, the finest computed level */
    const double *values;
    pset set[SD_MAX_LEVEL + 1];
    int done;                      /* levels whose sets were gathered (their maps to clean) */
    sdi_dlist nl[SD_MAX_LEVEL + 1];/* new offset lists of the levels with ops (then the old ones) */
    bool has_nl[SD_MAX_LEVEL + 1];
    double *nd[SD_MAX_LEVEL + 1];  /* the new lists' offsets, wherever the lists are */
} edit;

/* Lists with room for at least cap points and dcap values (never smaller than they are: so a
 * failure half-way leaves every list at least as long as s->cap and s->dcap say). */
static bool resize_lists(sd_mem *m, sdi_escratch *s, uint32_t cap, size_t dcap)
{
    cap = cap > s->cap ? cap : s->cap;
    dcap = dcap > s->dcap ? dcap : s->dcap;
    if (cap == s->cap && dcap == s->dcap && s->id)
        return true;
    uint32_t *id = sdi_realloc(m, s->id, (size_t)cap * sizeof *id);
    if (id)
        s->id = id;
    double *nv = id ? sdi_realloc(m, s->nv, dcap * sizeof *nv) : NULL;
    if (nv)
        s->nv = nv;
    double *ov = nv ? sdi_realloc(m, s->ov, dcap * sizeof *ov) : NULL;
    if (ov)
        s->ov = ov;
    uint8_t *chg = ov ? sdi_realloc(m, s->chg, cap) : NULL;
    if (!chg)
        return false;
    s->chg = chg;
    s->cap = cap;
    s->dcap = dcap;
    return true;
}

/* Make room for one more point in p (false: no memory). */
static __attribute__((noinline)) bool grow(sd_mem *m, pset *p, int nc)
{
    sdi_escratch *s = p->s;
    uint32_t cap = p->n < s->cap ? s->cap : s->cap ? 2 * s->cap : 256;
    return resize_lists(m, s, cap, (size_t)cap * nc);
}

/* Add point r to level l's set unless it is there (false: no memory). */
static inline bool add_point(edit *E, int l, uint32_t r)
{
    sd_level *lv = E->c->lv[l];
    pset *p = &E->set[l];
    sdi_escratch *s = p->s;
    if (l < E->top) {
        if (lv->slot[r] >= 0)
            return true;
    } else if (s->mark[r >> 6] >> (r & 63) & 1)
        return true;
    if ((p->n == s->cap || (size_t)(p->n + 1) * E->nc > s->dcap) && !grow(E->m, p, E->nc))
        return false;
    if (l < E->top)
        lv->slot[r] = (int32_t)p->n;
    else
        s->mark[r >> 6] |= 1ull << (r & 63);
    s->id[p->n++] = r;
    return true;
}

/* Leave the scratch maps of the gathered levels clean for the next edit. */
static void clean_maps(edit *E)
{
    for (int l = 0; l < E->done; l++) {
        sd_level *lv = E->c->lv[l];
        const sdi_escratch *s = E->set[l].s;
        for (uint32_t i = 0; i < E->set[l].n; i++) {
            uint32_t r = s->id[i];
            if (l < E->top)
                lv->slot[r] = -1;
            else
                s->mark[r >> 6] &= ~(1ull << (r & 63));
        }
    }
    E->done = 0;
}

/* The scratch of levels 0..top (made by the first edit: a slot map where a finer level reads the
 * level, a bitmap on the finest, and the lists). */
static bool ensure_maps(edit *E)
{
    for (int l = 0; l <= E->top; l++) {
        sd_level *lv = E->c->lv[l];
        const uint32_t nv = lv->t.nv;
        if (l < E->top && !lv->slot) {
            if (!(lv->slot = sdi_alloc(E->m, ((size_t)nv + 1) * sizeof *lv->slot)))
                return false;
            for (uint32_t v = 0; v < nv; v++)
                lv->slot[v] = -1;
        }
        if (!lv->es && !(lv->es = sdi_calloc(E->m, 1, sizeof *lv->es)))
            return false;
        if (l == E->top && !lv->es->mark &&
            !(lv->es->mark = sdi_calloc(E->m, nv / 64 + 1, sizeof *lv->es->mark)))
            return false;
        E->set[l].s = lv->es;
    }
    return true;
}

/* Lists with room for cap points of nc components, their pages written (a fresh page costs a
 * fault when first touched, which the first edit would pay while it grows them; what they hold
 * between edits is scratch). */
static bool reserve_lists(sd_mem *m, sdi_escratch *s, uint32_t cap, int nc)
{
    if (s->cap >= cap && s->dcap >= (size_t)cap * nc)
        return true;
    if (!resize_lists(m, s, cap, (size_t)cap * nc))
        return false;
    memset(s->id, 0, (size_t)s->cap * sizeof *s->id);
    memset(s->nv, 0, s->dcap * sizeof *s->nv);
    memset(s->ov, 0, s->dcap * sizeof *s->ov);
    memset(s->chg, 0, s->cap);
    return true;
}

/* The maps, and lists with room for what a one-point move recomputes at each level: about
 * (2^(l+1) + 1)^d points at level l for cells of dimension d (at most the level's points, at
 * most 2^16): later edits grow them as needed. */
/* The by-column index of every computed level's S (sd_options.edit_index LAZY leaves it to here). */
static sd_result ensure_index(sd_complex *c, sd_error *err)
{
    /* (S made first where direct.c did without) */
    sd_result r = sdi_ensure_rules_below(c, c->nlevels - 1, err);
    for (int l = 0; !r && l + 1 < c->nlevels; l++)
        r = sdi_csrb_index(&c->mem, &c->lv[l]->S, err);
    if (!r)
        c->edit_indexed = true; /* and levels made from now on index theirs (levels.c) */
    return r;
}

sd_result sd_complex_prepare_edits(sd_complex *c, sd_error *err)
{
    edit E = {.c = c, .m = &c->mem, .top = c->nlevels - 1};
    sd_result r = ensure_index(c, err);
    if (r)
        return r;
    if (!ensure_maps(&E))
        return sdi_fail_nomem(err, &c->mem);
    const sd_topo *t0 = &c->lv[0]->t;
    int dim = t0->ntet || t0->noct ? 3 : t0->ntr ? 2 : t0->ncu ? 1 : 0;
    for (int l = 0; l <= E.top; l++) {
        uint64_t side = (2u << l) + 1, want = 1;
        for (int k = 0; k < dim && want < (1u << 16); k++)
            want *= side;
        want = want < (1u << 16) ? want : 1u << 16;
        uint32_t nv = c->lv[l]->t.nv + 1, cap = want < nv ? (uint32_t)want : nv;
        if (!reserve_lists(&c->mem, c->lv[l]->es, cap, 3))
            return sdi_fail_nomem(err, &c->mem);
    }
    return SD_OK;
}

/* ---- offsets ------------------------------------------------------------------------------------ */

/* The offset that puts sum s at value v: v - s. fl(s + fl(v - s)) is v whenever v and s are
 * within a factor 2 of each other (then v - s is exact, Sterbenz), and otherwise the double
 * nearest v that s plus any offset reaches. false where it is not finite or beyond
 * SD_MAX_OFFSET (*bad: the component). */
static bool offset_for(const double *v, const double *s, double *d, int nc, int *bad)
{
    for (int q = 0; q < nc; q++) {
        double x = v[q] - s[q];
        if (!isfinite(x) || fabs(x) > SD_MAX_OFFSET) {
            *bad = q;
            return false;
        }
        d[q] = x;
    }
    return true;
}

/* The new offset list of each level with ops at levels >= 1: the old list with the ops merged
 * in (a move's offset left 0 until it is known); each op's entry in op->pos. */
static bool new_lists(edit *E, op *ops, size_t n)
{
    const int nc = E->nc;
    for (size_t a = 0, b; a < n; a = b) {
        const uint32_t l = ops[a].level;
        for (b = a; b < n && ops[b].level == l; b++)
            ops[b].pos = UINT32_MAX;
        if (l == 0)
            continue;
        const sdi_dlist *old = sdi_det(E->c, E->ch, (int)l);
        const uint32_t no = old ? old->n : 0;
        sdi_dlist *L = &E->nl[l];
        E->has_nl[l] = true;
        size_t cap = no + (b - a);
        L->idx = sdi_alloc(E->m, (cap ? cap : 1) * sizeof *L->idx);
        L->d = sdi_calloc(E->m, (cap ? cap : 1) * nc, sizeof *L->d);
        if (!L->idx || !L->d)
            return false;
        E->nd[l] = L->d;
        uint32_t i = 0, k = 0;
        for (size_t o = a; o < b || i < no;) {
            if (o == b || (i < no && old->idx[i] < ops[o].index)) { /* an offset the call keeps */
                L->idx[k] = old->idx[i];
                memcpy(L->d + (size_t)k * nc, old->d + (size_t)i * nc, nc * sizeof *L->d);
                k++, i++;
                continue;
            }
            if (i < no && old->idx[i] == ops[o].index)
                i++; /* replaced or cleared */
            if (ops[o].kind != OP_CLEAR) {
                ops[o].pos = k;
                L->idx[k] = ops[o].index;
                if (ops[o].kind == OP_OFFSET)
                    memcpy(L->d + (size_t)k * nc, E->values + (size_t)ops[o].item * nc,
                           nc * sizeof *L->d);
                k++;
            }
            o++;
        }
        L->n = k;
    }
    return true;
}

/* ---- the lists ------------------------------------------------------------------------------- */

/* Sort a[0..n) ascending (LSD radix, 11 bits a pass; tmp: n entries). */
static void radix_sort(uint32_t *a, uint32_t *tmp, uint32_t n, uint32_t maxv)
{
    uint32_t cnt[2048];
    for (int sh = 0; sh < 32 && (maxv >> sh); sh += 11) {
        memset(cnt, 0, sizeof cnt);
        for (uint32_t i = 0; i < n; i++)
            cnt[(a[i] >> sh) & 2047]++;
        for (uint32_t i = 0, t = 0; i < 2048; i++) {
            uint32_t x = cnt[i];
            cnt[i] = t;
            t += x;
        }
        for (uint32_t i = 0; i < n; i++)
            tmp[cnt[(a[i] >> sh) & 2047]++] = a[i];
        memcpy(a, tmp, n * sizeof *a);
    }
}

/* Gather and compute level l's set: its ops, then the rows of S_{l-1} that read a point of
 * level l-1's set. SD_OK, a failure, or SD_ERR_VALUE for a move whose offset is out of range. */
static sd_result gather(edit *E, int l, sd_error *err)
{
    sd_complex *c = E->c;
    const int nc = E->nc;
    pset *s = &E->set[l];
    E->done = l + 1;
    for (uint32_t o = 0; o < s->nops; o++)
        if (!add_point(E, l, s->ops[o].index))
            return sdi_fail_nomem(err, E->m);
    if (l > 0) {
        const pset *up = &E->set[l - 1];
        const sd_csrb *S = &c->lv[l - 1]->S;
        const uint32_t *ids = up->s->id;
        for (uint32_t i = 0; i < up->n; i++) {
            if (i + 16 < up->n) /* in order too: ask for the lists ahead */
                __builtin_prefetch(&S->urel[ids[i + 16]]);
            if (i + 8 < up->n)
                __builtin_prefetch(S->ub + S->ubase[ids[i + 8] >> SDI_UBLK] + S->urel[ids[i + 8]]);
            sdi_users u = sdi_csrb_users(S, ids[i]);
            for (uint32_t r; sdi_users_next(&u, &r);)
                if (!add_point(E, l, r))
                    return sdi_fail_nomem(err, E->m);
        }
    }
    /* the points in increasing order (after the ops), so that their rows of S, their values and
     * their offsets are read in order rather than scattered: twice as fast on large levels */
    sdi_escratch *L = s->s;
    if (s->n - s->nops > 1) {
        radix_sort(L->id + s->nops, (uint32_t *)L->nv, s->n - s->nops, c->lv[l]->t.nv);
        if (l < E->top) /* (nv, not yet written, holds n * nc >= n doubles) */
            for (uint32_t e = s->nops; e < s->n; e++)
                c->lv[l]->slot[L->id[e]] = (int32_t)e;
    }
    const double *cur = c->lv[l]->ch[E->ch].data;
    const sdi_dlist *old = sdi_det(c, E->ch, l);
    sdi_rowpos at = {UINT32_MAX, 0};
    for (uint32_t e = 0; e < s->n; e++) {
        const uint32_t r = L->id[e];
        if (l > 0) { /* the points come in order: ask for the rows a few points ahead */
            if (e + 16 < s->n) {
                sdi_csrb_prefetch(&c->lv[l - 1]->S, L->id[e + 16], 0);
                __builtin_prefetch(cur + (size_t)L->id[e + 16] * nc);
            }
            if (e + 8 < s->n)
                sdi_csrb_prefetch(&c->lv[l - 1]->S, L->id[e + 8], 1);
        }
        double *nv = L->nv + (size_t)e * nc;
        const op *o = e < s->nops ? &s->ops[e] : NULL;
        copy_nc(L->ov + (size_t)e * nc, cur + (size_t)r * nc, nc);
        if (l == 0) { /* a control point: its value */
            copy_nc(nv, E->values + (size_t)o->item * nc, nc);
        } else {
            const sd_level *up = c->lv[l - 1];
            sdi_csrb_eval(&up->S, r, up->ch[E->ch].data, up->slot, E->set[l - 1].s->nv, nc, nv,
                          &at);
            const double *d = NULL;
            if (o && o->kind != OP_CLEAR) {
                double *nd = E->nd[l] + (size_t)o->pos * nc;
                int bad;
                if (o->kind == OP_MOVE &&
                    !offset_for(E->values + (size_t)o->item * nc, nv, nd, nc, &bad))
                    return sdi_fail(err, SD_ERR_VALUE, (long)o->item, bad,
                                    "point %u of level %d: the offset to value %d is not finite "
                                    "or beyond %g", r, l, bad, SD_MAX_OFFSET);
                d = nd;
            } else if (!o)
                d = sdi_det_find(old, r, nc);
            for (int q = 0; d && q < nc; q++)
                nv[q] += d[q];
        }
        L->chg[e] = !same_bits(nv, cur + (size_t)r * nc, nc);
    }
    return SD_OK;
}

/* Whether channel ch's levels take tangent-plane modifications after S (tangent.c). */
static bool tp_active(const sd_complex *c, int ch)
{
    return ch == 0 && c->ntt && c->opt.nonmanifold_surface == SD_NMSURF_YING_ZORIN;
}

/* Does a changed point of level l's set move a position its rules read? With tangent-plane
 * constraints every position does: the modifications after S read them (tangent.c). */
static bool stale_at(const edit *E, int l)
{
    const uint8_t *geo = E->c->lv[l]->geo;
    const pset *s = &E->set[l];
    const bool tp = tp_active(E->c, E->ch);
    for (uint32_t e = 0; tp && e < s->n; e++)
        if (s->s->chg[e])
            return true;
    for (uint32_t e = 0; E->ch == 0 && geo && e < s->n; e++)
        if (s->s->chg[e] && geo[s->s->id[e]])
            return true;
    return false;
}

/* Write the new (dir 1) or the old (dir 0) values of levels 0..top. */
static void write_sets(edit *E, int top, int dir)
{
    const int nc = E->nc;
    for (int l = 0; l <= top; l++) {
        const pset *s = &E->set[l];
        const double *x = dir ? s->s->nv : s->s->ov;
        double *p = E->c->lv[l]->ch[E->ch].data;
        for (uint32_t e = 0; e < s->n; e++)
            copy_nc(p + (size_t)s->s->id[e] * nc, x + (size_t)e * nc, nc);
    }
}

/* Install the new offset lists (the old ones then sit in E->nl, to free or to put back). */
static void swap_lists(edit *E)
{
    for (int l = 1; l <= SD_MAX_LEVEL; l++)
        if (E->has_nl[l])
            sdi_det_swap(E->c, E->ch, l, &E->nl[l]); /* the table exists: made before */
}

/* ---- the rebuild of rules that read moved positions ------------------------------------------- */

/* Move the rules part of level `from` (see sdi_level_free_rules) to `to`, leaving none in `from`. */
static void move_rules(sd_level *to, sd_level *from)
{
    to->have_rules = from->have_rules;
    to->vrule = from->vrule;
    to->erule = from->erule;
    to->vrule_only = from->vrule_only;
    to->geo = from->geo;
    to->S = from->S;
    from->have_rules = false;
    from->vrule = from->erule = from->vrule_only = from->geo = NULL;
    memset(&from->S, 0, sizeof from->S);
}

/* The points of level lv whose values differ from old's in any channel, into *out (n of them). */
static bool diff_level(sd_mem *m, const sd_level *lv, const sd_level *old, uint32_t **out,
                       uint32_t *n)
{
    uint32_t k = 0, cap = 0;
    uint32_t *ids = NULL;
    for (uint32_t v = 0; v < lv->t.nv; v++) {
        bool differs = false;
        for (int i = 0; i < lv->nch && !differs; i++) {
            const int nc = lv->ch[i].ncomp;
            differs = memcmp(lv->ch[i].data + (size_t)v * nc, old->ch[i].data + (size_t)v * nc,
                             nc * sizeof(double)) != 0;
        }
        if (!differs)
            continue;
        if (k == cap) {
            cap = cap ? 2 * cap : 256;
            uint32_t *x = sdi_realloc(m, ids, (size_t)cap * sizeof *x);
            if (!x) {
                sdi_free(m, ids);
                return false;
            }
            ids = x;
        }
        ids[k++] = v;
    }
    *out = ids;
    *n = k;
    return true;
}

/* Level s's positions changed where its rules read them (the sets of levels 0..s are known):
 * write them, build s's rules again beside the old ones, recompute the finer levels beside the
 * old ones, taking the offsets of the moves at those levels as each is made, and list what
 * changed there. On failure everything is put back. */
static sd_result rebuild(edit *E, int s, op *ops, size_t nops, uint32_t **diff, uint32_t *ndiff,
                         sd_error *err)
{
    sd_complex *c = E->c;
    const int nl = c->nlevels, nc = E->nc;
    sd_level *lv = c->lv[s], oldr = {0}, *saved[SD_MAX_LEVEL + 1] = {0};
    write_sets(E, s, 1);
    swap_lists(E);
    move_rules(&oldr, lv);
    sd_result r = sdi_ensure_rules(c, s, err);
    if (r)
        goto undo_rules;
    for (int l = s + 1; l < nl; l++) {
        saved[l] = c->lv[l];
        c->lv[l] = NULL;
    }
    c->nlevels = s + 1;
    const bool tp = tp_active(c, E->ch);
    for (size_t i = 0; tp && i < nops; i++) /* the moves' offsets, made below */
        if (ops[i].kind == OP_MOVE && (int)ops[i].level > s)
            memset(E->nd[ops[i].level] + (size_t)ops[i].pos * nc, 0, nc * sizeof(double));
    for (int l = s + 1; l < nl && !r; l++) {
        if (!sd_complex_level(c, l, err)) {
            r = err->code;
            break;
        }
        const sd_level *up = c->lv[l - 1];
        double *p = c->lv[l]->ch[E->ch].data;
        for (size_t i = 0; i < nops && !r; i++) {
            const op *o = &ops[i];
            if (o->level != (uint32_t)l || o->kind != OP_MOVE)
                continue;
            double *nv = p + (size_t)o->index * nc;
            double *d = E->nd[l] + (size_t)o->pos * nc; /* in the installed list */
            int bad;
            /* the point before its offset: S's row, or with tangent-plane constraints the level
             * build's value (its offset 0 in the installed list, below: the modifications of
             * tangent.c come between the two) */
            if (!tp)
                sdi_csrb_eval(&up->S, o->index, up->ch[E->ch].data, NULL, NULL, nc, nv, NULL);
            if (!offset_for(E->values + (size_t)o->item * nc, nv, d, nc, &bad)) {
                r = sdi_fail(err, SD_ERR_VALUE, (long)o->item, bad,
                             "point %u of level %d: the offset to value %d is not finite or "
                             "beyond %g", o->index, l, bad, SD_MAX_OFFSET);
                break;
            }
            for (int q = 0; q < nc; q++)
                nv[q] += d[q];
        }
    }
    for (int l = s + 1; l < nl && !r; l++)
        if (!diff_level(E->m, c->lv[l], saved[l], &diff[l], &ndiff[l]))
            r = sdi_fail_nomem(err, E->m);
    if (!r) {
        for (int l = s + 1; l < nl; l++)
            sdi_level_free(E->m, saved[l]);
        sdi_level_free_rules(E->m, &oldr);
        return SD_OK;
    }
    for (int l = s + 1; l < nl; l++) {
        sdi_free(E->m, diff[l]);
        diff[l] = NULL;
    }
    sdi_drop_levels(c, s + 1);
    for (int l = s + 1; l < nl; l++)
        c->lv[l] = saved[l];
    c->nlevels = nl;
    sdi_level_free_rules(E->m, lv);
undo_rules:
    move_rules(lv, &oldr);
    swap_lists(E);
    write_sets(E, s, 0);
    return r;
}

/* ---- the engine ------------------------------------------------------------------------------- */

/* Apply ops (validated: levels, indices, values; sorted here) to channel ch. Moves need their
 * levels computed (done here first); offsets and clears at levels not computed only change the
 * lists. rep and counts (the points recomputed per level) are optional. */
static sd_result run(sd_complex *c, int ch, op *ops, size_t n, const double *values,
                     sd_edit_report *rep, uint64_t *counts, sd_error *err)
{
    sd_mem *m = &c->mem;
    if (rep)
        rep->rules_rebuilt = -1;
    sd_result rc = sort_ops(ops, n, err);
    if (rc)
        return rc;
    const int old_nl = c->nlevels;
    int need = 0;
    bool lists = false;
    for (size_t i = 0; i < n; i++) {
        if (ops[i].kind == OP_MOVE && (int)ops[i].level > need)
            need = (int)ops[i].level;
        lists |= ops[i].level > 0;
    }
    if (need >= c->nlevels && !sd_complex_level(c, need, err)) {
        sdi_drop_levels(c, old_nl);
        return err->code;
    }
    if ((rc = ensure_index(c, err))) { /* nothing changed yet: all or nothing */
        sdi_drop_levels(c, old_nl);
        return rc;
    }
    edit E = {.c = c, .m = m, .ch = ch, .nc = c->lv[0]->ch[ch].ncomp, .top = c->nlevels - 1,
              .values = values};
    uint32_t *diff[SD_MAX_LEVEL + 1] = {0}, ndiff[SD_MAX_LEVEL + 1] = {0};
    int stale = -1;
    if (!ensure_maps(&E) || !new_lists(&E, ops, n) || (lists && !sdi_det_ready(c))) {
        rc = sdi_fail_nomem(err, m);
        goto fail;
    }
    for (size_t a = 0, b; a < n; a = b) { /* each level's ops */
        for (b = a; b < n && ops[b].level == ops[a].level; b++)
            ;
        if ((int)ops[a].level <= E.top) {
            E.set[ops[a].level].ops = ops + a;
            E.set[ops[a].level].nops = (uint32_t)(b - a);
        }
    }
    for (int l = 0; l <= E.top && stale < 0; l++) {
        if ((rc = gather(&E, l, err)))
            goto fail;
        if (stale_at(&E, l))
            stale = l;
    }
    clean_maps(&E);
    if (stale > 0 && tp_active(c, ch))
        stale--; /* level stale is S p + modifications: made again, its moves' offsets against it */
    const int last = stale < 0 ? E.top : stale;
    if (rep)
        rep->rules_rebuilt = stale;
    const bool apply = !(stale >= 0 && rep && rep->in_place); /* else the caller builds anew */
    if (!apply)
        ; /* nothing written: the report says what would have been recomputed, nothing changed */
    else if (stale >= 0) {
        if ((rc = rebuild(&E, stale, ops, n, diff, ndiff, err)))
            goto fail;
    } else {
        write_sets(&E, E.top, 1);
        swap_lists(&E);
    }
    /* done: report */
    for (int l = 0; l <= SD_MAX_LEVEL; l++) {
        uint64_t rec = l <= last ? E.set[l].n : l < c->nlevels ? c->lv[l]->t.nv : 0, chg = 0;
        uint32_t *ids = l <= last ? E.set[l].s->id : diff[l];
        if (l <= last && apply) { /* the changed points first */
            sdi_escratch *s = E.set[l].s;
            for (uint32_t e = 0; e < E.set[l].n; e++)
                if (s->chg[e]) {
                    uint32_t t = s->id[chg];
                    s->id[chg++] = s->id[e];
                    s->id[e] = t;
                }
        } else if (l > last)
            chg = ndiff[l];
        if (counts)
            counts[l] = rec;
        if (rep) {
            rep->recomputed[l] = rec;
            rep->nchanged[l] = chg;
            if (chg && rep->changed)
                rep->changed(rep->ud, l, ids, chg);
        }
    }
    goto out;
fail:
    clean_maps(&E);
    sdi_drop_levels(c, old_nl);
out:
    for (int l = 0; l <= SD_MAX_LEVEL; l++) {
        sdi_dlist_free(m, &E.nl[l]);
        sdi_free(m, diff[l]);
    }
    return rc;
}

/* ---- the calls ---------------------------------------------------------------------------------- */

static sd_result check_channel(const sd_complex *c, int channel, sd_error *err)
{
    if (channel < 0 || channel >= c->lv[0]->nch)
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "no channel %d", channel);
    return SD_OK;
}

/* A point and its values: level lo..SD_MAX_LEVEL, index below the level's vertex count, values
 * finite and, for positions or offsets (lim), at most SD_MAX_OFFSET in magnitude. */
static sd_result check_point(const sd_complex *c, size_t i, int level, int lo, uint32_t index,
                             const double *v, int nc, bool lim, sd_error *err)
{
    if (level < lo || level > SD_MAX_LEVEL)
        return sdi_fail(err, SD_ERR_ARG, (long)i, -1, "level %d out of range %d..%d", level, lo,
                        SD_MAX_LEVEL);
    sd_counts k;
    sd_complex_counts(c, level, &k);
    if (index >= k.vertices)
        return sdi_fail(err, SD_ERR_INDEX, (long)i, -1, "point %u out of range (%llu points)",
                        index, (unsigned long long)k.vertices);
    for (int q = 0; q < nc; q++)
        if (!isfinite(v[q]) || (lim && fabs(v[q]) > SD_MAX_OFFSET))
            return sdi_fail(err, SD_ERR_VALUE, (long)i, q, "point %u: value %d is not finite "
                            "or too large", index, q);
    return SD_OK;
}

/* Check a call's points (at[i], or control points idx[i]) and values, and make its ops of `kind`
 * with room for `extra` more; the caller frees *ops. */
static sd_result make_ops(sd_complex *c, int channel, size_t n, const sd_vertex_at *at,
                          const uint32_t *idx, const double *values, uint32_t kind, size_t extra,
                          op **ops, sd_error *err)
{
    *ops = NULL;
    sd_result r = check_channel(c, channel, err);
    if (r)
        return r;
    const int nc = c->lv[0]->ch[channel].ncomp;
    const bool offsets = kind == OP_OFFSET;
    for (size_t i = 0; i < n; i++)
        if ((r = check_point(c, i, at ? at[i].level : 0, offsets, at ? at[i].index : idx[i],
                             values + i * nc, nc, offsets || channel == 0, err)))
            return r;
    if (!(*ops = sdi_alloc(&c->mem, (n + extra ? n + extra : 1) * sizeof **ops)))
        return sdi_fail_nomem(err, &c->mem);
    for (size_t i = 0; i < n; i++)
        (*ops)[i] = (op){at ? (uint32_t)at[i].level : 0, at ? at[i].index : idx[i], kind,
                         (uint32_t)i, UINT32_MAX};
    return SD_OK;
}

/* Moves to at[i] (or control points idx[i]); rep and counts optional. */
static sd_result moves(sd_complex *c, int channel, size_t n, const sd_vertex_at *at,
                       const uint32_t *idx, const double *values, sd_edit_report *rep,
                       uint64_t *counts, sd_error *err)
{
    sd_error local;
    op *ops;
    sd_result r = make_ops(c, channel, n, at, idx, values, OP_MOVE, 0, &ops, err ? err : &local);
    if (!r)
        r = run(c, channel, ops, n, values, rep, counts, err ? err : &local);
    sdi_free(&c->mem, ops);
    return r;
}

sd_result sd_complex_move(sd_complex *c, int channel, size_t n, const sd_vertex_at *at,
                          const double *values, sd_edit_report *rep, sd_error *err)
{
    return moves(c, channel, n, at, NULL, values, rep, NULL, err);
}

sd_result sd_complex_edit(sd_complex *c, int channel, size_t n, const uint32_t *idx,
                          const double *values, uint64_t *counts, sd_error *err)
{
    return moves(c, channel, n, NULL, idx, values, NULL, counts, err);
}

sd_result sd_complex_set_details(sd_complex *c, int channel, size_t n, const sd_vertex_at *at,
                                 const double *offsets, sd_edit_report *rep, sd_error *err)
{
    sd_error local;
    if (!err)
        err = &local;
    size_t nold = 0; /* room for their clears */
    for (int l = 1; l <= SD_MAX_LEVEL; l++)
        nold += sd_complex_details(c, channel, l, NULL, NULL);
    op *ops;
    sd_result r = make_ops(c, channel, n, at, NULL, offsets, OP_OFFSET, nold, &ops, err);
    if (r) {
        sdi_free(&c->mem, ops);
        return r;
    }
    /* the given offsets, and a clear for each offset held now (dropped where one is given) */
    size_t k = n;
    if ((r = sort_ops(ops, n, err))) { /* a point given twice, before the clears join */
        sdi_free(&c->mem, ops);
        return r;
    }
    for (int l = 1; l <= SD_MAX_LEVEL; l++) {
        const uint32_t *idx;
        size_t m = sd_complex_details(c, channel, l, &idx, NULL);
        for (size_t j = 0, i = 0; j < m; j++) {
            while (i < n && (ops[i].level < (uint32_t)l ||
                             (ops[i].level == (uint32_t)l && ops[i].index < idx[j])))
                i++;
            if (i < n && ops[i].level == (uint32_t)l && ops[i].index == idx[j])
                continue;
            ops[k++] = (op){(uint32_t)l, idx[j], OP_CLEAR, UINT32_MAX, UINT32_MAX};
        }
    }
    r = run(c, channel, ops, k, offsets, rep, NULL, err);
    sdi_free(&c->mem, ops);
    return r;
}

sd_result sd_complex_edit_in_place(sd_complex *c, int channel, size_t n, const uint32_t *idx,
                                   const double *values, uint64_t *counts, int *rebuild,
                                   sd_error *err)
{
    sd_edit_report rep = {.in_place = 1};
    sd_result r = moves(c, channel, n, NULL, idx, values, &rep, counts, err);
    *rebuild = r ? -1 : rep.rules_rebuilt;
    return r;
}

/* Whether moving points idx[0..n) to xyz (3 each) leaves every maximal simplex of level 0 that
 * holds one of them non-degenerate under sd_complex_new's test, with the bounding box of the
 * moved complex (see sd.h). A scan of level 0's cells and points, with one mark per point. */
sd_result sd_complex_check_moves(sd_complex *c, size_t n, const uint32_t *idx, const double *xyz,
                                 sd_error *err)
{
    sd_level *l0 = c->lv[0];
    const uint32_t nv = l0->t.nv;
    const double *p = l0->ch[0].data;
    int32_t *mark = sdi_alloc(&c->mem, ((size_t)nv + 1) * sizeof *mark); /* move + 1, or 0 */
    if (!mark)
        return sdi_fail_nomem(err, &c->mem);
    memset(mark, 0, ((size_t)nv + 1) * sizeof *mark);
    for (size_t i = 0; i < n; i++)
        if (idx[i] < nv)
            mark[idx[i]] = (int32_t)i + 1;
    /* the bounding boxes of the moved complex and of the complex as it is */
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    double lo0[3] = {INFINITY, INFINITY, INFINITY}, hi0[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t v = 0; v < nv; v++) {
        const double *x = mark[v] ? xyz + 3 * (size_t)(mark[v] - 1) : p + 3 * (size_t)v;
        const double *x0 = p + 3 * (size_t)v;
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], x[k]);
            hi[k] = fmax(hi[k], x[k]);
            lo0[k] = fmin(lo0[k], x0[k]);
            hi0[k] = fmax(hi0[k], x0[k]);
        }
    }
    double diag = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                       (hi[2] - lo[2]) * (hi[2] - lo[2]));
    double diag0 = sqrt((hi0[0] - lo0[0]) * (hi0[0] - lo0[0]) + (hi0[1] - lo0[1]) * (hi0[1] - lo0[1]) +
                        (hi0[2] - lo0[2]) * (hi0[2] - lo0[2]));
    /* a larger box makes the edge test stricter for every simplex, moved or not (the test of
     * sd_complex_new, which an import of the session makes): those without a moved point are
     * then tested too, and blamed on the first move out of the box as it was */
    int grew = 0;
    for (size_t i = 0; diag > diag0 && i < n && !grew; i++)
        for (int k = 0; k < 3 && !grew; k++)
            if (idx[i] < nv && (xyz[3 * i + k] < lo0[k] || xyz[3 * i + k] > hi0[k]))
                grew = (int)i + 1;
    static const char *const kind[] = {"", "", "edge", "triangle", "tetrahedron"};
    sd_result rc = SD_OK;
    for (int k = SD_CELL_CURVE; k <= SD_CELL_TETRA && !rc; k++) {
        int size = sd_cell_size((sd_cell_kind)k);
        uint32_t nc = sd_level_num_cells(l0, (sd_cell_kind)k);
        for (uint32_t i = 0; i < nc && !rc; i++) {
            uint32_t v[6], local[4] = {0, 1, 2, 3};
            sd_level_cell(l0, (sd_cell_kind)k, i, v);
            int last = 0; /* the latest move among the simplex's points (+1) */
            double at[12];
            for (int j = 0; j < size; j++) {
                last = mark[v[j]] > last ? mark[v[j]] : last;
                const double *x = mark[v[j]] ? xyz + 3 * (size_t)(mark[v[j]] - 1) : p + 3 * (size_t)v[j];
                memcpy(at + 3 * j, x, 3 * sizeof *x);
            }
            int flat = last || grew ? sdi_simplex_degenerate(at, local, size, diag) : 0;
            if (flat) {
                char vs[64];
                int w = 0;
                for (int j = 0; j < size; j++)
                    w += snprintf(vs + w, sizeof vs - (size_t)w, j ? ", %u" : "%u", v[j]);
                if (last)
                    rc = sdi_fail(err, SD_ERR_DEGENERATE, last - 1, -1,
                                  "moving point %u there makes the %s [%s] degenerate (%s)",
                                  idx[last - 1], kind[size], vs, sdi_degenerate_why(flat, size));
                else
                    rc = sdi_fail(err, SD_ERR_DEGENERATE, grew - 1, -1,
                                  "moving point %u there makes the bounding box so large that the "
                                  "%s [%s] is degenerate beside it (its %s below 1e-12 of the "
                                  "box's diagonal)", idx[grew - 1], kind[size], vs,
                                  size == 2 ? "length" : "shortest edge");
            }
        }
    }
    sdi_free(&c->mem, mark);
    return rc;
}
