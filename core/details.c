/* details.c — detail offsets (004 Sec. 5.2; docs/API.md "Live edits"): control points at finer
 * levels.
 *
 * A point of level l >= 1 may carry an offset d: the level is then p^l = S_{l-1} p^{l-1} + d^l,
 * the offsets added to the rows the matrix gives (levels.c, after sdi_csr_apply; edits add them
 * to the rows they recompute, edit.c). So an edit at a coarser level moves such a point and keeps
 * its offset, and every build of the level — after a drop, a rebuild, or from a complex given the
 * same offsets — gives the same bytes. Offsets are few (points someone dragged), so each channel
 * and level keeps a sorted list of them, not a dense array; the lists belong to the complex, not
 * to its levels, so dropping a level (a tag change, a new channel) keeps them. They are made by
 * moves at levels >= 1 (sd_complex_move) or given back as they were listed
 * (sd_complex_set_details, for a stored session); both are edits (edit.c). Only a change of a
 * tetrahedron's diagonal drops some (sd_complex_set_diagonal): it renumbers the points of levels
 * 3 and finer (docs/DECISIONS.md).
 */
#include "internal.h"
#include <math.h>
#include <string.h>

#define NLIST (SD_MAX_CHANNELS * (SD_MAX_LEVEL + 1))

static sdi_dlist *slot_of(const sd_complex *c, int channel, int level)
{
    return c->det ? &c->det[channel * (SD_MAX_LEVEL + 1) + level] : NULL;
}

const sdi_dlist *sdi_det(const sd_complex *c, int channel, int level)
{
    const sdi_dlist *L = slot_of(c, channel, level);
    return L && L->n ? L : NULL;
}

const double *sdi_det_find(const sdi_dlist *L, uint32_t i, int nc)
{
    if (!L)
        return NULL;
    uint32_t lo = 0, hi = L->n;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        if (L->idx[mid] < i)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo < L->n && L->idx[lo] == i ? L->d + (size_t)lo * nc : NULL;
}

void sdi_det_add(const sd_complex *c, int channel, int level, double *data, int nc)
{
    const sdi_dlist *L = sdi_det(c, channel, level);
    for (uint32_t k = 0; L && k < L->n; k++) {
        double *p = data + (size_t)L->idx[k] * nc;
        for (int q = 0; q < nc; q++)
            p[q] += L->d[(size_t)k * nc + q];
    }
}

bool sdi_det_ready(sd_complex *c)
{
    return c->det || (c->det = sdi_calloc(&c->mem, NLIST, sizeof *c->det));
}

void sdi_det_swap(sd_complex *c, int channel, int level, sdi_dlist *L)
{
    sdi_dlist *at = slot_of(c, channel, level), t = *at;
    *at = *L;
    *L = t;
}

void sdi_dlist_free(sd_mem *m, sdi_dlist *L)
{
    sdi_free(m, L->idx);
    sdi_free(m, L->d);
    memset(L, 0, sizeof *L);
}

void sdi_det_drop(sd_complex *c, int from)
{
    if (!c->det)
        return;
    for (int ch = 0; ch < SD_MAX_CHANNELS; ch++)
        for (int l = from; l <= SD_MAX_LEVEL; l++)
            sdi_dlist_free(&c->mem, slot_of(c, ch, l));
    if (from == 0) {
        sdi_free(&c->mem, c->det);
        c->det = NULL;
    }
}

size_t sd_complex_details(const sd_complex *c, int channel, int level, const uint32_t **idx,
                          const double **offsets)
{
    const sdi_dlist *L = channel >= 0 && channel < c->lv[0]->nch && level >= 1 &&
                                 level <= SD_MAX_LEVEL
                             ? sdi_det(c, channel, level)
                             : NULL;
    if (idx)
        *idx = L ? L->idx : NULL;
    if (offsets)
        *offsets = L ? L->d : NULL;
    return L ? L->n : 0;
}
