/* edit.c — control-point and attribute edits pushed through the cached subdivision matrices.
 *
 * Positions and attributes of level l+1 are S_l times those of level l, so a change dp^0 on a
 * few control points changes level l+1 by S_l dp^l, which is non-zero only on the rows that use
 * a changed point. With S_l stored by columns as well (built once per level on the first edit:
 * for each point, the rows that use it), an edit walks down the levels touching just those rows:
 * its cost follows the edited region. The per-level `slot` array (one int per point, kept
 * between edits and reset after use) gathers the changes of a level without a search.
 *
 * All-or-nothing: the whole cascade of changes is computed into temporary lists first; only when
 * every allocation has succeeded are they added to the levels' arrays.
 *
 * Rules that read positions: Ying-Zorin's corner petals measure the angle alpha between their
 * singular edges (rules.c marks the points in the level's `geo`). A move of such a point makes
 * that level's S stale, so the changes are applied down to that level, its rules are built
 * again from the new positions and the finer levels recomputed (rebuild_from) — the result is
 * the one a new complex with the moved points would give, at the cost of those levels.
 */
#include "internal.h"
#include <math.h>
#include <stdio.h>
#include <string.h>

/* S_l by columns: tcol[j]..tcol[j+1]-1 index trow (row) and tpos (the entry's weight in S.wt). */
static bool build_columns(sd_mem *m, sd_level *lv)
{
    const sd_csrb *S = &lv->S;
    uint32_t nc = S->ncols;
    uint32_t *col = sdi_calloc(m, (size_t)nc + 1, sizeof *col);
    uint32_t *row = sdi_alloc(m, (S->nnz ? S->nnz : 1) * sizeof *row);
    uint32_t *pos = sdi_alloc(m, (S->nnz ? S->nnz : 1) * sizeof *pos);
    uint32_t *cols = sdi_alloc(m, ((size_t)S->maxlen + 1) * sizeof *cols);
    /* the level may have been the finest at an earlier edit: its scratch map exists already */
    int32_t *slot = lv->slot ? lv->slot : sdi_alloc(m, ((size_t)nc + 1) * sizeof *slot);
    if (!col || !row || !pos || !cols || !slot) {
        sdi_free(m, col);
        sdi_free(m, row);
        sdi_free(m, pos);
        sdi_free(m, cols);
        if (slot != lv->slot)
            sdi_free(m, slot);
        return false;
    }
    size_t k = 0;
    for (uint32_t r = 0; r < S->nrows; r++) {
        uint32_t n = sdi_csrb_len(S, r);
        sdi_csrb_row(S, r, &k, cols);
        for (uint32_t i = 0; i < n; i++)
            col[cols[i] + 1]++;
    }
    for (uint32_t j = 0; j < nc; j++)
        col[j + 1] += col[j];
    k = 0;
    for (uint32_t r = 0; r < S->nrows; r++) {
        uint32_t n = sdi_csrb_len(S, r);
        uint32_t w = (uint32_t)(sdi_csrb_row(S, r, &k, cols) - S->wt);
        for (uint32_t i = 0; i < n; i++) {
            uint32_t at = col[cols[i]]++;
            row[at] = r;
            pos[at] = w + i;
        }
    }
    sdi_free(m, cols);
    for (uint32_t j = nc; j > 0; j--) /* shift back: col[j] is the start of column j again */
        col[j] = col[j - 1];
    col[0] = 0;
    for (uint32_t j = 0; j < nc; j++)
        slot[j] = -1;
    lv->tcol = col;
    lv->trow = row;
    lv->tpos = pos;
    lv->slot = slot;
    return true;
}

/* The changed points of one level: ids and their deltas (nc values each). */
typedef struct change {
    uint32_t n, cap;
    uint32_t *id;
    double *d;
} change;

static void change_free(sd_mem *m, change *c)
{
    sdi_free(m, c->id);
    sdi_free(m, c->d);
}

/* Add (sign 1) or take back (-1) the changes of levels 0 .. top-1. */
static void apply(sd_complex *c, int channel, int nc, const change *ch, int top, int sign)
{
    for (int l = 0; l < top; l++) {
        double *p = c->lv[l]->ch[channel].data;
        for (uint32_t i = 0; i < ch[l].n; i++)
            for (int k = 0; k < nc; k++)
                p[(size_t)ch[l].id[i] * nc + k] += sign * ch[l].d[(size_t)i * nc + k];
    }
}

/* Move the rules part of level `from` (see sdi_level_free_rules) to `to`, leaving none in `from`. */
static void move_rules(sd_level *to, sd_level *from)
{
    to->have_rules = from->have_rules;
    to->vrule = from->vrule;
    to->erule = from->erule;
    to->vrule_only = from->vrule_only;
    to->geo = from->geo;
    to->S = from->S;
    to->tcol = from->tcol;
    to->trow = from->trow;
    to->tpos = from->tpos;
    from->have_rules = false;
    from->vrule = from->erule = from->vrule_only = from->geo = NULL;
    memset(&from->S, 0, sizeof from->S);
    from->tcol = from->trow = from->tpos = NULL;
}

/* Level l's positions changed where its rules read them: build its rules again beside the old
 * ones (kept until the new ones are complete, so a failure leaves the level as it was), then
 * recompute the finer levels that were computed. Those are plain caches: if recomputing them
 * runs out of memory they are dropped and computed again on demand, and the edit stands. */
static sd_result rebuild_from(sd_complex *c, int l, sd_error *err)
{
    sd_level *lv = c->lv[l], old = {0};
    const int nl = c->nlevels;
    move_rules(&old, lv);
    sd_result r = sdi_ensure_rules(c, l, err);
    if (r) {
        move_rules(lv, &old);
        return r;
    }
    sdi_level_free_rules(&c->mem, &old);
    sdi_drop_levels(c, l + 1);
    sd_error ignored;
    if (!sd_complex_level(c, nl - 1, &ignored))
        sdi_drop_levels(c, l + 1);
    return SD_OK;
}

/* The edit; with `in_place`, one that would rebuild a level stops before changing anything and
 * says which level in *rebuild (-1: applied through the matrices). */
static sd_result edit(sd_complex *c, int channel, size_t n, const uint32_t *idx,
                      const double *values, bool in_place, uint64_t *counts, int *rebuild,
                      sd_error *err)
{
    if (rebuild)
        *rebuild = -1;
    sd_mem *m = &c->mem;
    sd_level *l0 = c->lv[0];
    if (channel < 0 || channel >= l0->nch)
        return sdi_fail(err, SD_ERR_ARG, -1, -1, "no channel %d", channel);
    const int nc = l0->ch[channel].ncomp;
    const uint32_t nv = l0->t.nv;
    for (size_t i = 0; i < n; i++) {
        if (idx[i] >= nv)
            return sdi_fail(err, SD_ERR_INDEX, (long)i, -1, "point %u out of range (%u points)",
                           idx[i], nv);
        for (int k = 0; k < nc; k++) {
            double x = values[i * nc + k];
            if (!isfinite(x) || (channel == 0 && fabs(x) > 1e15))
                return sdi_fail(err, SD_ERR_VALUE, (long)i, k, "point %u: value %d is not finite "
                               "or too large", idx[i], k);
        }
    }
    int nl = c->nlevels;
    for (int l = 0; l + 1 < nl; l++) /* every level that feeds a computed one has its S */
        if (!c->lv[l]->tcol && !build_columns(m, c->lv[l]))
            return sdi_fail_nomem(err, m);
    sd_level *fin = c->lv[nl - 1];
    if (!fin->slot) { /* the finest level needs only the scratch map, kept like the others */
        if (!(fin->slot = sdi_alloc(m, ((size_t)fin->t.nv + 1) * sizeof *fin->slot)))
            return sdi_fail_nomem(err, m);
        for (uint32_t v = 0; v < fin->t.nv; v++)
            fin->slot[v] = -1;
    }
    if (l0->slot)
        for (size_t i = 0; i < n; i++) /* repeated points make an edit ambiguous */
            if (l0->slot[idx[i]] != -1 || (l0->slot[idx[i]] = (int32_t)i, false)) {
                for (size_t j = 0; j < i; j++)
                    l0->slot[idx[j]] = -1;
                return sdi_fail(err, SD_ERR_REPEATED, (long)i, -1, "point %u is edited twice",
                               idx[i]);
            }
    if (l0->slot)
        for (size_t i = 0; i < n; i++)
            l0->slot[idx[i]] = -1;
    else
        for (size_t i = 0; i < n; i++)
            for (size_t j = 0; j < i; j++)
                if (idx[j] == idx[i])
                    return sdi_fail(err, SD_ERR_REPEATED, (long)i, -1, "point %u is edited twice",
                                   idx[i]);

    change ch[SD_MAX_LEVEL + 1];
    memset(ch, 0, sizeof ch);
    sd_result rc = SD_OK;
    /* level 0: the deltas themselves */
    ch[0].id = sdi_alloc(m, (n ? n : 1) * sizeof *ch[0].id);
    ch[0].d = sdi_alloc(m, (n ? n : 1) * nc * sizeof *ch[0].d);
    if (!ch[0].id || !ch[0].d)
        goto nomem;
    const double *p0 = l0->ch[channel].data;
    for (size_t i = 0; i < n; i++) {
        ch[0].id[i] = idx[i];
        for (int k = 0; k < nc; k++)
            ch[0].d[i * nc + k] = values[i * nc + k] - p0[(size_t)idx[i] * nc + k];
    }
    ch[0].n = (uint32_t)n;
    /* push down: rows of level l+1 that use a changed point of level l, up to the first level
     * whose rules read a moved point's position (Ying-Zorin's alpha, `geo`): its S is stale, so
     * its rules and the finer levels are rebuilt instead (rebuild_from) */
    int stale = nl;
    for (int l = 0; l + 1 < nl; l++) {
        sd_level *lv = c->lv[l], *next = c->lv[l + 1];
        for (uint32_t i = 0; channel == 0 && lv->geo && i < ch[l].n && stale == nl; i++)
            if (lv->geo[ch[l].id[i]])
                stale = l;
        if (stale < nl)
            break;
        int32_t *slot = next->slot;
        change *in = &ch[l], *out = &ch[l + 1];
        bool ok = true;
        for (uint32_t i = 0; i < in->n && ok; i++) {
            uint32_t j = in->id[i];
            for (uint32_t k = lv->tcol[j]; k < lv->tcol[j + 1]; k++) {
                uint32_t r = lv->trow[k];
                double w = lv->S.wt[lv->tpos[k]];
                if (slot[r] < 0) {
                    if (out->n == out->cap) {
                        uint32_t cap = out->cap ? 2 * out->cap : 64;
                        uint32_t *id = sdi_realloc(m, out->id, (size_t)cap * sizeof *id);
                        if (id)
                            out->id = id;
                        double *d = sdi_realloc(m, out->d, (size_t)cap * nc * sizeof *d);
                        if (d)
                            out->d = d;
                        if (!id || !d) {
                            ok = false;
                            break;
                        }
                        out->cap = cap;
                    }
                    slot[r] = (int32_t)out->n;
                    out->id[out->n] = r;
                    memset(out->d + (size_t)out->n * nc, 0, nc * sizeof *out->d);
                    out->n++;
                }
                double *d = out->d + (size_t)slot[r] * nc;
                for (int q = 0; q < nc; q++)
                    d[q] += w * in->d[(size_t)i * nc + q];
            }
        }
        for (uint32_t i = 0; i < out->n; i++) /* leave the map clean for the next edit */
            slot[out->id[i]] = -1;
        if (!ok)
            goto nomem;
    }
    int top = stale < nl ? stale + 1 : nl;
    if (counts) {
        for (int l = 0; l <= SD_MAX_LEVEL; l++)
            counts[l] = l < top ? ch[l].n : l < c->nlevels ? c->lv[l]->t.nv : 0;
    }
    if (in_place && stale < nl) { /* the caller rebuilds instead */
        *rebuild = stale;
        goto done;
    }
    /* every change is known: apply them */
    apply(c, channel, nc, ch, top, 1);
    if (stale < nl && (rc = rebuild_from(c, stale, err))) {
        apply(c, channel, nc, ch, top, -1); /* out of memory: as it was */
        goto done;
    }
    goto done;
nomem:
    rc = sdi_fail_nomem(err, m);
done:
    for (int l = 0; l <= SD_MAX_LEVEL; l++)
        change_free(m, &ch[l]);
    return rc;
}

sd_result sd_complex_edit(sd_complex *c, int channel, size_t n, const uint32_t *idx,
                          const double *values, uint64_t *counts, sd_error *err)
{
    return edit(c, channel, n, idx, values, false, counts, NULL, err);
}

sd_result sd_complex_edit_in_place(sd_complex *c, int channel, size_t n, const uint32_t *idx,
                                   const double *values, uint64_t *counts, int *rebuild,
                                   sd_error *err)
{
    return edit(c, channel, n, idx, values, true, counts, rebuild, err);
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
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t v = 0; v < nv; v++) {
        const double *x = mark[v] ? xyz + 3 * (size_t)(mark[v] - 1) : p + 3 * (size_t)v;
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(lo[k], x[k]);
            hi[k] = fmax(hi[k], x[k]);
        }
    }
    double diag = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                       (hi[2] - lo[2]) * (hi[2] - lo[2]));
    static const char *const kind[] = {"", "", "edge", "triangle", "tetrahedron"};
    static const char *const measure[] = {"", "", "length", "area", "volume"};
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
            if (last && sdi_simplex_degenerate(at, local, size, diag)) {
                char vs[64];
                int w = 0;
                for (int j = 0; j < size; j++)
                    w += snprintf(vs + w, sizeof vs - (size_t)w, j ? ", %u" : "%u", v[j]);
                rc = sdi_fail(err, SD_ERR_DEGENERATE, last - 1, -1,
                              "moving point %u there makes the %s [%s] degenerate (zero or "
                              "near-zero %s)", idx[last - 1], kind[size], vs, measure[size]);
            }
        }
    }
    sdi_free(&c->mem, mark);
    return rc;
}
