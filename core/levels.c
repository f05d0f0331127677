/* levels.c — the subdivision hierarchy of a complex: a level's lifecycle and the public
 * accessors of levels.
 *
 * Levels are computed one from the previous, on demand, and kept: level l+1's topology comes from
 * the split (split.c, topology only), its points from S_l (stencil.c) applied to every channel of
 * level l. A failed step leaves the hierarchy as it was (all-or-nothing per level). A level is
 * freed whole (sdi_level_free), or just its rules part (sdi_level_free_rules: what a change of
 * tags or a moved corner makes stale), or with every finer one (sdi_drop_levels).
 *
 * The parts of a level's topology (sd_topo, internal.h) are built when needed, in the order
 * edges, then faces (each needs the parent's faces); faces are dropped again at levels >= 1 once
 * the rules and the next split are made, so the lock-free readers of sd.h only ever meet arrays
 * that stay.
 */
#include "internal.h"
#include <string.h>

void sdi_level_free(sd_mem *m, sd_level *lv)
{
    if (!lv)
        return;
    sdi_topo_free(m, &lv->t);
    sdi_level_free_rules(m, lv);
    sdi_tp_free(m, lv->tp);
    sdi_free(m, lv->slot);
    sdi_escratch_free(m, lv->es);
    for (int i = 0; i < lv->nch; i++)
        sdi_free(m, lv->ch[i].data);
    sdi_free(m, lv);
}

void sdi_drop_levels(sd_complex *c, int from)
{
    for (int l = from; l < c->nlevels; l++) {
        sdi_level_free(&c->mem, c->lv[l]);
        c->lv[l] = NULL;
    }
    if (c->nlevels > from)
        c->nlevels = from;
}

void sdi_level_free_rules(sd_mem *m, sd_level *lv)
{
    sdi_free(m, lv->vrule);
    sdi_free(m, lv->erule);
    sdi_csrb_free(m, &lv->S);
    sdi_free(m, lv->vrule_only);
    sdi_free(m, lv->geo);
    lv->vrule = lv->erule = lv->vrule_only = lv->geo = NULL;
    lv->have_rules = false;
}

/* Forget level lv's rules and stencils (with their column index), edits' scratch and every
 * finer level (tags changed). */
void sdi_drop_rules(sd_complex *c, sd_level *lv)
{
    sdi_drop_levels(c, lv->index + 1);
    sdi_level_free_rules(&c->mem, lv);
    sdi_free(&c->mem, lv->slot);
    sdi_escratch_free(&c->mem, lv->es);
    lv->slot = NULL;
    lv->es = NULL;
}

/* The parts of a level's topology (see sd_topo): edges need the parent's faces; faces need the
 * level's edges and the parent's faces; level 0 has all of them. */
static sd_result ensure_faces(sd_complex *c, int l, sd_error *err);

static sd_result ensure_edges(sd_complex *c, int l, sd_error *err)
{
    sd_level *lv = c->lv[l];
    if (lv->t.derived)
        return SD_OK;
    sd_result r = ensure_faces(c, l - 1, err);
    return r ? r : sdi_split_edges(&c->mem, lv->parent, &lv->t, c->opt.threads, err);
}

static sd_result ensure_faces(sd_complex *c, int l, sd_error *err)
{
    sd_level *lv = c->lv[l];
    if (lv->t.faces)
        return SD_OK;
    sd_result r = ensure_edges(c, l, err);
    if (!r)
        r = ensure_faces(c, l - 1, err);
    return r ? r : sdi_split_faces(&c->mem, lv->parent, &lv->t, c->opt.threads, err);
}

/* Faces are only needed while rules or the next level are made: drop them at levels >= 1. */
static void drop_faces(sd_complex *c)
{
    for (int l = 1; l < c->nlevels; l++)
        sdi_topo_free_faces(&c->mem, &c->lv[l]->t);
}

static sd_result rules_keep_faces(sd_complex *c, int level, sd_error *err)
{
    sd_level *lv = c->lv[level];
    if (lv->have_rules)
        return SD_OK;
    sd_result r = ensure_faces(c, level, err);
    return r ? r : sdi_build_rules(c, lv, err);
}

sd_result sdi_ensure_derived(sd_complex *c, int level, sd_error *err)
{
    sd_result r = ensure_edges(c, level, err);
    drop_faces(c);
    return r;
}

sd_result sdi_ensure_rules(sd_complex *c, int level, sd_error *err)
{
    sd_result r = rules_keep_faces(c, level, err);
    drop_faces(c);
    return r;
}

sd_result sdi_ensure_rules_below(sd_complex *c, int n, sd_error *err)
{
    sd_result r = SD_OK;
    for (int l = 0; !r && l < n; l++)
        r = rules_keep_faces(c, l, err);
    drop_faces(c);
    return r;
}

/* Compute level l+1 from level l: its topology, then every channel as S_l p^l plus the channel's
 * detail offsets at level l+1 (details.c), and S_l's column index for later edits (csr.c). The
 * positions take the tangent-plane constraints' modifications (tangent.c) between the two.
 * Batch refinement of a level whose rows are plain masks applies S without making it
 * (direct.c). */
/* S_l, and its column index unless batch refinement leaves it to edits (DECISIONS 46). */
static sd_result make_S(sd_complex *c, int l, sd_error *err)
{
    sd_result r = rules_keep_faces(c, l, err);
    if (!r && (c->opt.edit_index != SD_EDIT_INDEX_LAZY || c->edit_indexed))
        r = sdi_csrb_index(&c->mem, &c->lv[l]->S, err); /* kept with S, so it may exist from before */
    return r;
}

static sd_result next_level(sd_complex *c, int l, sdi_plain *pl, sd_error *err)
{
    sd_mem *m = &c->mem;
    sd_level *p = c->lv[l];
    const bool direct = sdi_direct_ok(c, p);
    sd_result r = direct ? SD_OK : make_S(c, l, err); /* (its scratch freed before the split) */
    if (!r)
        r = ensure_faces(c, l, err); /* the rules may have been built before, the faces dropped */
    if (r)
        return r;
    sd_level *lv = sdi_calloc(m, 1, sizeof *lv);
    if (!lv)
        return sdi_fail_nomem(err, m);
    lv->index = l + 1;
    lv->parent_nv = p->t.nv;
    lv->parent_ne = p->t.ne;
    lv->cx = c;
    lv->parent = &p->t;
    if ((r = sdi_split_cells(m, &p->t, &lv->t, c->opt.threads, err))) {
        sdi_free(m, lv);
        return r;
    }
    lv->nch = p->nch;
    for (int i = 0; i < p->nch; i++) {
        int nc = p->ch[i].ncomp;
        lv->ch[i].ncomp = nc;
        lv->ch[i].data = sdi_alloc(m, (size_t)lv->t.nv * nc * sizeof(double));
        if (!lv->ch[i].data) {
            sdi_level_free(m, lv);
            return sdi_fail_nomem(err, m);
        }
    }
    bool summed = false; /* by direct.c, unless it declines: then through S after all */
    if (direct && !(r = sdi_direct_apply(c, p, lv, pl, &summed, err)) && !summed)
        r = make_S(c, l, err);
    if (r) {
        sdi_level_free(m, lv);
        return r;
    }
    for (int i = 0; i < p->nch; i++) {
        int nc = p->ch[i].ncomp;
        if (!summed)
            sdi_csr_apply(&p->S, p->ch[i].data, lv->ch[i].data, nc, c->opt.threads);
        /* the tangent-plane constraints move positions after S, before the offsets (003 Sec. 3) */
        if (i == 0 && c->ntt && (r = sdi_tp_step(c, l, lv, lv->ch[0].data, err))) {
            sdi_level_free(m, lv);
            return r;
        }
        sdi_det_add(c, i, l + 1, lv->ch[i].data, nc);
    }
    c->lv[l + 1] = lv;
    c->nlevels = l + 2;
    return SD_OK;
}

const sd_level *sd_complex_level(sd_complex *c, int level, sd_error *err)
{
    if (level < 0 || level > SD_MAX_LEVEL) {
        sdi_fail(err, SD_ERR_ARG, level, -1, "level %d out of range 0..%d", level, SD_MAX_LEVEL);
        return NULL;
    }
    sdi_plain pl = {.top = level}; /* direct.c's, from one level to the next */
    sd_result r = SD_OK;
    if (c->nlevels <= level) {
        sdi_pool_begin(c->opt.threads); /* the levels' regions share their helper threads */
        while (!r && c->nlevels <= level)
            r = next_level(c, c->nlevels - 1, &pl, err);
        sdi_pool_end();
    }
    sdi_plain_free(&c->mem, &pl);
    drop_faces(c);
    return r ? NULL : c->lv[level];
}

uint32_t sd_level_index(const sd_level *lv) { return (uint32_t)lv->index; }
uint32_t sd_level_num_vertices(const sd_level *lv) { return lv->t.nv; }

const double *sd_level_channel(const sd_level *lv, int channel, int *ncomp)
{
    if (channel < 0 || channel >= lv->nch)
        return NULL;
    if (ncomp)
        *ncomp = lv->ch[channel].ncomp;
    return lv->ch[channel].data;
}

void sd_octa_tet(const uint32_t o[6], int k, uint32_t t[4])
{
    static const int eq[4] = {2, 4, 3, 5}; /* the equator cycle a, b, a2, b2 */
    t[0] = o[1];
    t[1] = o[0];
    t[2] = o[eq[k & 3]];
    t[3] = o[eq[(k + 1) & 3]];
}

int sd_cell_size(sd_cell_kind k)
{
    static const int n[] = {1, 2, 3, 4, 6};
    return (unsigned)k < 5 ? n[k] : 0;
}

uint32_t sd_level_num_cells(const sd_level *lv, sd_cell_kind k)
{
    const sd_topo *t = &lv->t;
    switch (k) {
    case SD_CELL_POINT: return t->npt;
    case SD_CELL_CURVE: return t->ncu;
    case SD_CELL_TRIANGLE: return t->ntr;
    case SD_CELL_TETRA: return t->ntet;
    case SD_CELL_OCTA: return t->noct;
    }
    return 0;
}

void sd_level_cell(const sd_level *lv, sd_cell_kind k, uint32_t i, uint32_t *v)
{
    const sd_topo *t = &lv->t;
    switch (k) {
    case SD_CELL_POINT: v[0] = t->pt[i]; break;
    case SD_CELL_CURVE: memcpy(v, t->cuv ? t->cuv[i] : t->ev[t->cu[i]], 2 * sizeof *v); break;
    case SD_CELL_TRIANGLE: memcpy(v, t->trv ? t->trv[i] : t->fv[t->tr[i]], 3 * sizeof *v); break;
    case SD_CELL_TETRA: memcpy(v, t->tet[i], 4 * sizeof *v); break;
    case SD_CELL_OCTA: memcpy(v, t->oct[i], 6 * sizeof *v); break;
    }
}

/* Accessors of the derived topology build it the first time (under the caller's lock, see
 * sd.h); false if that failed. */
bool sdi_need_derived(const sd_level *lv)
{
    return lv->t.derived || sdi_ensure_derived(lv->cx, lv->index, NULL) == SD_OK;
}

const uint32_t *sd_level_edges(const sd_level *lv, uint32_t *n)
{
    if (!sdi_need_derived(lv)) {
        *n = 0;
        return NULL;
    }
    *n = lv->t.ne;
    return &lv->t.ev[0][0];
}

uint32_t sd_level_control_cell(const sd_level *lv, sd_cell_kind k, uint32_t i)
{
    const sd_complex *c = lv->cx;
    for (uint32_t l = lv->index; l > 0; l--) {
        uint32_t T = c->lv[l - 1]->t.ntet; /* the parent level's tetrahedra */
        switch (k) {
        case SD_CELL_POINT: break;
        case SD_CELL_CURVE: i /= 2; break;
        case SD_CELL_TRIANGLE: i /= 4; break;
        case SD_CELL_TETRA:
            if (i < 4 * T)
                i /= 4;
            else
                i = (i - 4 * T) / 8, k = SD_CELL_OCTA;
            break;
        case SD_CELL_OCTA:
            if (i < T)
                k = SD_CELL_TETRA;
            else
                i = (i - T) / 6;
            break;
        }
    }
    return k == SD_CELL_OCTA ? UINT32_MAX : c->in_src[k][i]; /* level 0 has no octahedra */
}

sd_origin_kind sd_level_origin(const sd_level *lv, uint32_t i, uint32_t *a, uint32_t *b)
{
    *a = *b = UINT32_MAX;
    if (lv->index == 0) {
        *a = i;
        return SD_ORIGIN_INPUT;
    }
    if (i < lv->parent_nv) {
        *a = i;
        return SD_ORIGIN_VERTEX;
    }
    if (i < lv->parent_nv + lv->parent_ne) {
        uint32_t e = i - lv->parent_nv; /* the parent's edge (its halves run from end to end) */
        *a = lv->parent->ev[e][0];
        *b = lv->parent->ev[e][1];
        return SD_ORIGIN_EDGE;
    }
    *a = i - lv->parent_nv - lv->parent_ne;
    return SD_ORIGIN_CELL;
}

uint32_t sd_level_find_edge(const sd_level *lv, uint32_t a, uint32_t b)
{
    return sdi_need_derived(lv) ? sdi_topo_find_edge(&lv->t, a, b) : UINT32_MAX;
}

static sd_result class_of(sd_complex *c, int level, sd_error *err, sd_level **out)
{
    sd_error local;
    if (!err)
        err = &local;
    *out = NULL;
    if (!sd_complex_level(c, level, err))
        return err->code;
    sd_result r = sdi_ensure_rules(c, level, err);
    *out = c->lv[level];
    return r;
}

sd_result sd_level_vertex_class(const sd_level *lv, uint32_t i, sd_class *o)
{
    const sd_topo *t = &lv->t;
    if (!lv->have_rules || i >= t->nv)
        return SD_ERR_ARG;
    o->family = t->vfam[i];
    o->boundary = (t->vflag[i] & VF_DC) != 0;
    o->nonmanifold = (uint8_t)nm_type(t->vnm[i]);
    o->rule = lv->vrule[i];
    o->valence = sdi_csrb_len(&lv->S, i) - 1;
    o->extraordinary = sdi_rule_extraordinary(o->rule, o->valence, false);
    o->rule = (uint8_t)sdi_reported_vertex_rule(t, i, lv->vrule[i]);
    return SD_OK;
}

sd_result sd_level_edge_class(const sd_level *lv, uint32_t e, sd_class *o)
{
    const sd_topo *t = &lv->t;
    if (!lv->have_rules || e >= t->ne)
        return SD_ERR_ARG;
    o->family = t->efam[e];
    o->boundary = (t->eflag[e] & EF_DC) != 0;
    o->nonmanifold = (uint8_t)nm_type(t->enm[e]);
    o->rule = lv->erule[e];
    o->valence = sdi_csrb_len(&lv->S, t->nv + e) - 2;
    o->extraordinary = sdi_rule_extraordinary(o->rule, o->valence, true);
    o->rule = (uint8_t)sdi_reported_edge_rule(t, e, lv->erule[e]);
    return SD_OK;
}

sd_result sd_complex_vertex_class(sd_complex *c, int level, uint32_t i, sd_class *o, sd_error *err)
{
    sd_level *lv = NULL;
    sd_result r = class_of(c, level, err, &lv);
    if (r)
        return r;
    if (i >= lv->t.nv)
        return sdi_fail(err, SD_ERR_ARG, i, -1, "vertex %u out of range (%u vertices)", i, lv->t.nv);
    return sd_level_vertex_class(lv, i, o);
}

sd_result sd_complex_edge_class(sd_complex *c, int level, uint32_t e, sd_class *o, sd_error *err)
{
    sd_level *lv = NULL;
    sd_result r = class_of(c, level, err, &lv);
    if (r)
        return r;
    if (e >= lv->t.ne)
        return sdi_fail(err, SD_ERR_ARG, e, -1, "edge %u out of range (%u edges)", e, lv->t.ne);
    return sd_level_edge_class(lv, e, o);
}

sd_rule sd_level_vertex_rule(const sd_level *lv, uint32_t i)
{
    /* vrule_only first: once set it never changes, while a later computation of the next level
     * may build vrule (same values) concurrently with a reader of this one */
    if (lv->vrule_only)
        return sdi_reported_vertex_rule(&lv->t, i, lv->vrule_only[i]);
    if (lv->have_rules)
        return sdi_reported_vertex_rule(&lv->t, i, lv->vrule[i]);
    /* the classification's (see sd.h) */
    return sdi_reported_vertex_rule(&lv->t, i, sdi_vertex_rule(&lv->t, i));
}

sd_result sd_complex_prepare_vertex_rules(sd_complex *c, int level, sd_error *err)
{
    const sd_level *l = sd_complex_level(c, level, err);
    if (!l)
        return err ? err->code : SD_ERR_ARG;
    sd_level *lv = c->lv[level];
    if (lv->have_rules || lv->vrule_only)
        return SD_OK;
    sd_result r = sdi_ensure_derived(c, level, err);
    if (r)
        return r;
    uint8_t *vr = sdi_alloc(&c->mem, (size_t)lv->t.nv + 1);
    if (!vr || sdi_vertex_rules_only(&c->mem, &lv->t, c->opt.solid_scheme, vr)) {
        sdi_free(&c->mem, vr);
        return sdi_fail_nomem(err, &c->mem);
    }
    lv->vrule_only = vr;
    return SD_OK;
}

uint32_t sd_level_solid_boundary(const sd_level *lv, uint32_t *tri)
{
    const sd_topo *t = &lv->t; /* the cells' boundary masks: no derived topology needed */
    uint32_t n = 0;
    if (!tri) {
        for (uint32_t c = 0; c < t->ntet; c++)
            n += (uint32_t)__builtin_popcount(t->tet_b[c]);
        for (uint32_t c = 0; c < t->noct; c++)
            n += (uint32_t)__builtin_popcount(t->oct_b[c]);
        return n;
    }
    for (uint32_t c = 0; c < t->ntet; c++)
        for (int i = 0; t->tet_b[c] && i < 4; i++)
            if (t->tet_b[c] >> i & 1) {
                for (int k = 0; k < 3; k++)
                    tri[3 * n + k] = t->tet[c][SDI_TET_F[i][k]];
                n++;
            }
    for (uint32_t c = 0; c < t->noct; c++)
        for (int i = 0; t->oct_b[c] && i < 8; i++)
            if (t->oct_b[c] >> i & 1) {
                for (int k = 0; k < 3; k++)
                    tri[3 * n + k] = t->oct[c][SDI_OCT_F[i][k]];
                n++;
            }
    return n;
}

sd_result sd_complex_matrix(sd_complex *c, int level, sd_csr *out, sd_error *err)
{
    sd_error local;
    if (!err)
        err = &local;
    if (!sd_complex_level(c, level, err))
        return err->code;
    sd_result r = sdi_ensure_rules(c, level, err);
    if (r)
        return r;
    sd_csrb *s = &c->lv[level]->S;
    if (!sdi_csrb_view(&c->mem, s)) /* the plain CSR view, made once and kept */
        return sdi_fail_nomem(err, &c->mem);
    out->nrows = s->nrows;
    out->ncols = s->ncols;
    out->rowptr = s->vrowptr;
    out->col = s->vcol;
    out->val = s->vval;
    return SD_OK;
}
