/* stencil.c — assembling S_l, the matrix from a level's points to the next level's, from the
 * rules (rules.c), the neighbourhoods (rings.c) and the masks (masks.c).
 *
 * One builder for every rule family (OpenSubdiv's Far stencil tables in spirit): per row a
 * weight pattern and the columns that are not implicit (csr.c). The steps:
 *   1. rules: every edge's, then every vertex's with the sizes of its rho, the edges' opposite
 *      vertices, then the rings of solid and G2 edges and the Ying-Zorin rules and rows of the
 *      edges at singular vertices (yz.c);
 *   2. patterns: each row's weights from its rule's mask, interned (the same weights bit for bit
 *      are one pattern) and memoized by rule and size, so a level costs a few mask evaluations;
 *   3. columns: vertex rows (rho in edge order, then diagonals and opposites), then edge rows
 *      (the ring), into their places counted in step 2.
 * With sd_options.threads each step runs in parallel parts (par.c) cut by fixed rules, and what
 * depends on order — pattern ids, the order of rho — is merged in part order, so S is the same
 * bytes for any number of threads (tests/core/test_threads.c).
 * Where every edge row's ring is two opposite vertices (a pure surface, no G2 or flattened rows)
 * those are kept as they are (S.eopp) instead of being copied. No adjacency list is built for
 * the common cases, so the memory is the matrix itself. Every row sums to 1 (tests/core).
 *
 * The rules and stencils of a level are built all-or-nothing: on failure the level has neither.
 */
#include "internal.h"
#include <stddef.h>
#include <string.h>

/* The state of one build, shared by the steps that may run in parallel (each writes only its own
 * arrays or its own rows of col). */
typedef struct build {
    sd_mem *m;
    const sd_topo *t;
    int weights, scheme, threads;
    uint8_t *vr, *er;                /* the level's rules (vrule, erule) */
    uint8_t *take;                   /* per edge: which end reads the other through it */
    uint32_t *cnt_a, *cnt_b;         /* rho sizes (rings.c); cnt_a then becomes cur */
    uint32_t (*opp)[2];              /* opposite vertices of edges (rings.c) */
    uint8_t *nopp;
    sd_yzend (*gam)[2];              /* Ying-Zorin rules per edge end (rules.c) */
    sdi_rings sr, gr;                /* rings of solid and G2 edges */
    sd_yzrows yz;                    /* flattened Ying-Zorin rows (yz.c) */
    sdi_rels rel;                    /* the level's incidence relations, if a ring needs them */
    bool stride;                     /* edge rings stay in opp (S.eopp): no solid or G2 rings */
    sd_pats pats;
    uint64_t nexp, nring, ebase;     /* explicit columns; ring entries; where edge rows start */
    uint32_t *cur, *col;             /* where each vertex's rho goes in col; col */
    const size_t *S_kchk;            /* S's kchk (where chunks of rows start in col) */
    double loopc[SDI_LOOP_CACHE];    /* Loop weights by valence */
    sdi_sharp_rows_t sh;             /* rows a semi-sharp crease reaches (sharp.c) */
} build;

/* The explicit columns of edge e's row: its ring. */
static inline uint32_t ring_len(const build *B, uint32_t e)
{
    switch (SDI_RULE_RING[B->er[e]]) {
    case SDI_RING_OPPOSITE:
    case SDI_RING_BOUNDARY_OPPOSITE:
        return sdi_opp_ring_len(B->er[e], B->nopp[e]);
    case SDI_RING_SOLID:
        return B->sr.len[e];
    case SDI_RING_G2:
        return B->gr.len[e];
    case SDI_RING_FLAT:
        return B->yz.off[e + 1] - B->yz.off[e];
    default:
        return 0;
    }
}
static inline const uint32_t *ring_of(const build *B, uint32_t e)
{
    switch (SDI_RULE_RING[B->er[e]]) {
    case SDI_RING_OPPOSITE:
    case SDI_RING_BOUNDARY_OPPOSITE:
        return B->opp[e];
    case SDI_RING_SOLID:
        return B->sr.v + B->sr.off[e];
    case SDI_RING_FLAT:
        return B->yz.col + B->yz.off[e];
    default:
        return B->gr.v + B->gr.off[e];
    }
}

/* ---- 1. rules and neighbourhoods ---------------------------------------------------------- */

static bool choose(build *B, sd_complex *cx, sd_level *lv)
{
    sd_mem *m = B->m;
    const sd_topo *t = B->t;
    const uint32_t nv = t->nv, ne = t->ne;
    const bool solids = t->ntet || t->noct;
    B->vr = lv->vrule = sdi_alloc(m, (size_t)nv + 1);
    B->er = lv->erule = sdi_alloc(m, (size_t)ne + 1);
    B->cnt_a = sdi_calloc(m, nv, sizeof *B->cnt_a);
    if (B->scheme == SD_SOLID_AVERAGED && solids)
        B->cnt_b = sdi_calloc(m, nv, sizeof *B->cnt_b);
    B->take = sdi_alloc(m, (size_t)ne + 1);
    if (!B->vr || !B->er || !B->cnt_a || (!B->cnt_b && B->scheme == SD_SOLID_AVERAGED && solids) ||
        !B->take)
        return false;
    bool any_g2e, any_opp;
    sdi_edge_rules(t, B->threads, B->er, &any_g2e, &any_opp);
    if (any_opp) {
        B->opp = sdi_alloc(m, (size_t)ne * sizeof *B->opp);
        B->nopp = sdi_alloc(m, (size_t)ne + 1);
        if (!B->opp || !B->nopp)
            return false;
    }
    /* vertex rules and rho sizes, and the edges' opposite vertices, each in parallel parts */
    if (!sdi_vertex_rules(m, t, B->scheme, B->threads, B->vr, B->cnt_a, B->cnt_b, B->take))
        return false;
    if (B->nopp)
        sdi_edge_opposites(t, B->threads, B->er, B->opp, B->nopp);
    if (solids && !sdi_solid_rings(m, t, B->er, B->scheme, B->threads, &B->sr))
        return false;
    if (any_g2e && !sdi_g2_rings(m, &B->rel, B->er, &B->gr))
        return false;
    B->stride = any_opp && !solids && !any_g2e;
    if (t->ovmask & OVM_YZ) { /* Ying-Zorin petal rules for the edges at singular vertices */
        B->gam = sdi_alloc(m, ((size_t)ne + 1) * sizeof *B->gam);
        if (!B->gam || !sdi_rels_need(m, &B->rel, SDI_REL(SDI_VF) | SDI_REL(SDI_EF)) ||
            !sdi_yz_rules(m, cx, lv->index, t, &B->rel, lv->ch[0].data, B->gam, &lv->geo) ||
            !sdi_yz_flat_rows(m, t, &B->rel.r[SDI_EF], (const sd_yzend(*)[2])B->gam, B->er, &B->yz))
            return false;
        if (B->yz.n) /* flattened rows are wider than two opposite vertices */
            B->stride = false;
    }
    return true;
}

/* ---- 2. patterns ------------------------------------------------------------------------- */

enum { MEMO = 64 }; /* rows memoized by rule and size up to this size */

/* Step 2 runs over ranges of rows. With one part it is one pass (ROWS_SERIAL: each row's pattern
 * interned into the level's table as it comes, cur and kchk written). With several, pattern ids
 * must still be those of the serial pass — the order in which rows first use each set of
 * weights: each part (ROWS_LOCAL) interns its rows' weights into its own table, in the order its
 * rows first use them, and writes those local ids (one byte) and its edge rows' kchk from its own
 * first column; the parts' tables are then interned into the level's one in part order, which is
 * the serial order, and a light pass per part turns local ids into the level's (widening them if
 * need be), writes cur and the vertex rows' kchk and moves the edge rows' kchk by the explicit
 * columns of the parts before. A part whose rows use more than 256 patterns leaves it to the
 * serial pass. A part's table and buffers come from its own sd_mem (plain malloc: the core's
 * counter is not shared between threads); they are scratch, freed before the build returns. */
enum { ROWS_SERIAL, ROWS_LOCAL };

typedef struct rows {
    sd_mem *m;                       /* allocates wbuf, stmp and pats */
    sd_pats *pats;                   /* interned into */
    int mode;
    uint32_t lo, hi;                 /* the rows, vertex or edge ids */
    double *wbuf;                    /* one row's weights */
    uint32_t wcap;
    double *stmp;                    /* the sharp rows' scratch: 2 wcap doubles */
    uint64_t nexp, nring;            /* explicit columns (from the rows' first) and ring entries */
    bool ok, full;                   /* full: more local patterns than a byte holds */
} rows;

/* Room for a row of n weights. */
static bool wbuf_fit(rows *X, uint32_t n)
{
    if (n <= X->wcap && X->wbuf)
        return true;
    uint32_t cap = n < 64 ? 64 : n;
    double *w = sdi_realloc(X->m, X->wbuf, (size_t)cap * sizeof *w);
    if (!w)
        return false;
    X->wbuf = w;
    X->wcap = cap;
    return true;
}

/* Room for the sharp rows' scratch (2 n doubles), after wbuf_fit(n). */
static bool stmp_fit(rows *X, uint32_t n)
{
    double *t = sdi_realloc(X->m, X->stmp, 2 * (size_t)n * sizeof *t);
    if (!t)
        return false;
    X->stmp = t;
    return true;
}

/* The id of the weights in wbuf (UINT32_MAX: no memory, or ROWS_LOCAL and not a byte). */
static uint32_t row_id(rows *X, uint32_t len)
{
    uint32_t id = sdi_pats_intern(X->m, X->pats, X->wbuf, len);
    if (X->mode == ROWS_LOCAL && id != UINT32_MAX && id > 255) {
        X->full = true;
        return UINT32_MAX;
    }
    return id;
}

/* Where the entries of a list of sharp.c (n entries of `size` bytes, sorted by the id each
 * starts with) reach id x: the first entry whose id is at least x. */
static size_t first_at(const void *list, size_t n, size_t size, uint32_t x)
{
    _Static_assert(offsetof(sdi_sharp_vertex, v) == 0 && offsetof(sdi_surf_vertex, v) == 0 &&
                   offsetof(sdi_sharp_edge, e) == 0 && offsetof(sdi_surf_edge, e) == 0,
                   "sharp.c's lists start with their ids");
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = (lo + hi) / 2;
        uint32_t id;
        memcpy(&id, (const char *)list + mid * size, sizeof id);
        if (id < x)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}
#define FIRST_AT(list, n, x) ((list) + first_at((list), (n), sizeof *(list), (x)))

/* A vertex row is [self, a x |rho|, b x octahedral opposites]; cur[v]: where v's rho goes. */
static inline __attribute__((always_inline)) bool
vertex_patterns(const build *B, rows *X, sd_csrb *S)
{
    /* B's and X's fields in locals: the stores below could alias them, so they would be read
     * again for every row */
    const uint32_t lo = X->lo, hi = X->hi, *cnt_b = B->cnt_b;
    const uint8_t *vr = B->vr;
    uint32_t *cnt_a = B->cnt_a, *cur = B->cnt_a;
    const bool serial = X->mode == ROWS_SERIAL; /* else cur and kchk come in the remap */
    uint32_t vmemo[SD_RULE_COUNT][MEMO];
    memset(vmemo, 0xff, sizeof vmemo);
    uint64_t nexp = X->nexp;
    const sdi_sharp_vertex *sv_end = B->sh.vert + B->sh.nvert;
    const sdi_surf_vertex *uv_end = B->sh.svert + B->sh.nsvert;
    const sdi_sharp_vertex *sv = FIRST_AT(B->sh.vert, B->sh.nvert, lo);
    const sdi_surf_vertex *uv = FIRST_AT(B->sh.svert, B->sh.nsvert, lo);
    for (uint32_t v = lo; v < hi; v++) {
        uint8_t r = vr[v];
        uint32_t na = cnt_a[v], nb = cnt_b ? cnt_b[v] : 0, id = UINT32_MAX;
        if (serial) {
            if (v % SD_CHK == 0)
                S->kchk[v / SD_CHK] = nexp;
            cur[v] = (uint32_t)nexp;
        }
        nexp += na + nb;
        const sdi_sharp_vertex *sharp = sv < sv_end && sv->v == v ? sv++ : NULL;
        const sdi_surf_vertex *surf = uv < uv_end && uv->v == v ? uv++ : NULL;
        bool memo = nb == 0 && na < MEMO && !sharp && !surf;
        if (memo)
            id = vmemo[r][na];
        if (id == UINT32_MAX) {
            sdi_vnb nbh = {na, nb, B->weights, B->scheme, B->loopc};
            sdi_vmask w = sdi_vertex_mask(r, &nbh);
            if (!wbuf_fit(X, 1 + na + nb))
                return false;
            double *wbuf = X->wbuf;
            wbuf[0] = w.self;
            for (uint32_t i = 0; i < na; i++)
                wbuf[1 + i] = w.a;
            for (uint32_t i = 0; i < nb; i++)
                wbuf[1 + na + i] = w.b;
            if ((sharp || surf) && !stmp_fit(X, 1 + na + nb))
                return false;
            if (surf) /* the sharp embedded surface first, a vertex sharpness on top */
                sdi_surf_vertex_row(&B->sh, surf, B->weights, wbuf, 1 + na + nb, X->stmp);
            if (sharp)
                sdi_sharp_vertex_row(sharp, wbuf, 1 + na + nb, X->stmp);
            if ((id = row_id(X, 1 + na + nb)) == UINT32_MAX)
                return false;
            if (memo)
                vmemo[r][na] = id;
        }
        if (!sdi_csrb_set_pat(B->m, S, v, id))
            return false;
    }
    X->nexp = nexp;
    return true;
}

/* The pattern of an edge row that is not its rule's mask over its ring: a flattened row (yz.c)
 * or 003 Fig. 4f from its singular ends (masks.c); UINT32_MAX: no memory. */
static uint32_t yz_pattern(const build *B, rows *X, uint32_t e, uint32_t k, bool flat)
{
    double *wbuf;
    if (flat) {
        if (!wbuf_fit(X, 2 + k))
            return UINT32_MAX;
        wbuf = X->wbuf;
        wbuf[0] = B->yz.ends[e][0];
        wbuf[1] = B->yz.ends[e][1];
        memcpy(wbuf + 2, B->yz.w + B->yz.off[e], k * sizeof *wbuf);
        return row_id(X, 2 + k);
    }
    sdi_emask w = sdi_mask_yz_petal_edge(B->gam[e]);
    if (!wbuf_fit(X, 4))
        return UINT32_MAX;
    wbuf = X->wbuf;
    wbuf[0] = w.end[0];
    wbuf[1] = w.end[1];
    wbuf[2] = wbuf[3] = w.ring;
    return row_id(X, 4);
}

/* An edge row is [end, end, ring...]. */
static inline __attribute__((always_inline)) bool
edge_patterns(const build *B, rows *X, sd_csrb *S)
{
    const uint32_t nv = B->t->nv, lo = X->lo, hi = X->hi;
    const uint8_t *er = B->er;
    uint32_t ememo[SD_RULE_COUNT][MEMO];
    memset(ememo, 0xff, sizeof ememo);
    uint64_t nexp = X->nexp, nring = 0;
    const sdi_sharp_edge *se_end = B->sh.edge + B->sh.nedge;
    const sdi_surf_edge *ue_end = B->sh.sedge + B->sh.nsedge;
    const sdi_sharp_edge *se = FIRST_AT(B->sh.edge, B->sh.nedge, lo);
    const sdi_surf_edge *ue = FIRST_AT(B->sh.sedge, B->sh.nsedge, lo);
    for (uint32_t e = lo; e < hi; e++) {
        uint32_t k = ring_len(B, e), r = nv + e;
        if (r % SD_CHK == 0)
            S->kchk[r / SD_CHK] = nexp;
        nring += k;
        if (!B->stride)
            nexp += k;
        uint8_t ring = SDI_RULE_RING[er[e]];
        const uint8_t *cls = ring == SDI_RING_SOLID && B->scheme == SD_SOLID_AVERAGED
                             ? B->sr.cls + B->sr.off[e] : NULL;
        bool petal = B->gam && er[e] == SD_RULE_LOOP && k == 2 &&
                     (B->gam[e][0].kind == SD_YZ_FIRST || B->gam[e][1].kind == SD_YZ_FIRST);
        bool flat = ring == SDI_RING_FLAT;
        /* a semi-sharp edge whose rule is a surface's (Loop, on a surface or the solids'
         * boundary): the blend of sharp.c */
        const sdi_sharp_edge *sharp = se < se_end && se->e == e ? se++ : NULL;
        if (sharp && er[e] != SD_RULE_LOOP && er[e] != SD_RULE_SOLID_BOUNDARY)
            sharp = NULL;
        if (sharp && (petal || flat))
            sharp = NULL; /* Ying-Zorin's rows at singular vertices win (DECISIONS 43) */
        const sdi_surf_edge *surf = ue < ue_end && ue->e == e ? ue++ : NULL;
        if (surf && er[e] != SD_RULE_SOLID)
            surf = NULL;
        bool memo = !cls && k < MEMO && !petal && !flat && !sharp && !surf;
        uint32_t id = memo ? ememo[er[e]][k] : UINT32_MAX;
        if ((flat || petal) && (id = yz_pattern(B, X, e, k, flat)) == UINT32_MAX)
            return false;
        if (id == UINT32_MAX) {
            sdi_enb nbh = {k, cls};
            sdi_emask w = sdi_edge_mask(er[e], &nbh);
            if (!wbuf_fit(X, 2 + k))
                return false;
            double *wbuf = X->wbuf;
            wbuf[0] = w.end[0];
            wbuf[1] = w.end[1];
            for (uint32_t i = 0; i < k; i++)
                wbuf[2 + i] = cls && cls[i] ? w.diag : w.ring;
            if (sharp)
                sdi_sharp_edge_row(sharp, wbuf, 2 + k);
            if (surf)
                sdi_surf_edge_row(surf, ring_of(B, e), wbuf, 2 + k);
            if ((id = row_id(X, 2 + k)) == UINT32_MAX)
                return false;
            if (memo)
                ememo[er[e]][k] = id;
        }
        if (!sdi_csrb_set_pat(B->m, S, nv + e, id))
            return false;
    }
    X->nexp = nexp;
    X->nring = nring;
    return true;
}

/* The parts of step 2: per part its vertex rows and its edge rows, each with its own table,
 * then what its local ids are in the level's table. The parts are PCHUNK chunks per thread,
 * taken in turn (sdi_par_dyn): what a part writes depends on its rows only, not on who runs it. */
enum { PCHUNK = 4 };
typedef struct pjob {
    const build *B;
    sd_csrb *S;
    const uint8_t *lid;              /* the local ids (S's pattern ids before the remap) */
    rows v[PCHUNK * SD_PAR_MAXT], e[PCHUNK * SD_PAR_MAXT];
    sd_mem mem[PCHUNK * SD_PAR_MAXT];
    sd_pats vpats[PCHUNK * SD_PAR_MAXT], epats[PCHUNK * SD_PAR_MAXT];
    uint32_t *vmap[PCHUNK * SD_PAR_MAXT], *emap[PCHUNK * SD_PAR_MAXT]; /* local id -> the level's */
    uint64_t ebase[PCHUNK * SD_PAR_MAXT]; /* the first explicit column of the part's edge rows */
} pjob;

static void patterns_part(void *arg, uint32_t part, uint32_t nparts)
{
    pjob *J = arg;
    (void)nparts;
    rows *v = &J->v[part], *e = &J->e[part];
    v->ok = vertex_patterns(J->B, v, J->S);
    e->wbuf = v->wbuf; /* one part's buffers, handed from its vertex rows to its edge rows */
    e->wcap = v->wcap;
    e->stmp = v->stmp;
    v->wbuf = v->stmp = NULL;
    e->ok = v->ok && edge_patterns(J->B, e, J->S);
}

/* Set row r's pattern id at S's width (known to hold it). */
static inline void put_pat(sd_csrb *S, uint32_t r, uint32_t id)
{
    if (S->pw == 1)
        ((uint8_t *)S->pat)[r] = (uint8_t)id;
    else if (S->pw == 2)
        ((uint16_t *)S->pat)[r] = (uint16_t)id;
    else
        ((uint32_t *)S->pat)[r] = id;
}

static void remap_part(void *arg, uint32_t part, uint32_t nparts)
{
    const pjob *J = arg;
    const build *B = J->B;
    sd_csrb *S = J->S;
    const uint32_t nv = B->t->nv, *vmap = J->vmap[part], *emap = J->emap[part];
    const uint32_t *cnt_b = B->cnt_b;
    uint32_t *cur = B->cnt_a;
    (void)nparts;
    uint64_t nexp = J->v[part].nexp;
    for (uint32_t v = J->v[part].lo; v < J->v[part].hi; v++) {
        if (v % SD_CHK == 0)
            S->kchk[v / SD_CHK] = nexp;
        uint32_t n = cur[v] + (cnt_b ? cnt_b[v] : 0); /* (cnt_a becomes cur) */
        cur[v] = (uint32_t)nexp;
        nexp += n;
        put_pat(S, v, vmap[J->lid[v]]);
    }
    const uint32_t e0 = J->e[part].lo, e1 = J->e[part].hi;
    for (uint64_t r = ((uint64_t)nv + e0 + SD_CHK - 1) / SD_CHK * SD_CHK; r < (uint64_t)nv + e1;
         r += SD_CHK)
        S->kchk[r / SD_CHK] += J->ebase[part];
    for (uint32_t e = e0; e < e1; e++)
        put_pat(S, nv + e, emap[J->lid[nv + e]]);
}

/* Step 2 for the vertex and edge rows: each row's pattern, cur, kchk, B->nexp, B->nring and
 * B->ebase. */
static bool serial_patterns(build *B, sd_csrb *S)
{
    const sd_topo *t = B->t;
    rows X = {.m = B->m, .pats = &B->pats, .mode = ROWS_SERIAL, .lo = 0, .hi = t->nv};
    bool ok = vertex_patterns(B, &X, S);
    B->ebase = X.nexp;
    X.lo = 0;
    X.hi = t->ne;
    ok = ok && edge_patterns(B, &X, S);
    B->nexp = X.nexp;
    B->nring = X.nring;
    sdi_free(B->m, X.wbuf);
    sdi_free(B->m, X.stmp);
    return ok;
}

static bool row_patterns(build *B, sd_csrb *S)
{
    const sd_topo *t = B->t;
    const uint64_t work = (uint64_t)t->nv + t->ne;
    const uint32_t nparts = PCHUNK * sdi_par_parts(B->threads, work); /* sdi_par_dyn's chunks */
    if (nparts == PCHUNK || S->pw != 1)
        return serial_patterns(B, S);
    pjob *J = sdi_calloc(B->m, 1, sizeof *J);
    if (!J)
        return false;
    J->B = B;
    J->S = S;
    for (uint32_t p = 0; p < nparts; p++) {
        uint64_t lo, hi;
        sdi_mem_init(&J->mem[p], NULL, 0);
        sdi_range(t->nv, p, nparts, &lo, &hi);
        J->v[p] = (rows){.m = &J->mem[p], .pats = &J->vpats[p], .mode = ROWS_LOCAL,
                         .lo = (uint32_t)lo, .hi = (uint32_t)hi};
        sdi_range(t->ne, p, nparts, &lo, &hi);
        J->e[p] = (rows){.m = &J->mem[p], .pats = &J->epats[p], .mode = ROWS_LOCAL,
                         .lo = (uint32_t)lo, .hi = (uint32_t)hi};
    }
    sdi_par_dyn(B->threads, work, PCHUNK, patterns_part, J);
    bool ok = true, full = false;
    for (uint32_t p = 0; p < nparts; p++) {
        ok = ok && J->e[p].ok;
        full = full || J->v[p].full || J->e[p].full;
    }
    /* the level's table: the parts' patterns in part order, vertex rows' before edge rows' */
    for (int blk = 0; blk < 2 && ok; blk++)
        for (uint32_t p = 0; p < nparts && ok; p++) {
            const sd_pats *q = blk ? &J->epats[p] : &J->vpats[p];
            uint32_t *map = sdi_alloc(&J->mem[p], ((size_t)q->n + 1) * sizeof *map);
            *(blk ? &J->emap[p] : &J->vmap[p]) = map;
            ok = map != NULL;
            for (uint32_t id = 0; id < q->n && ok; id++)
                ok = (map[id] = sdi_pats_intern(B->m, &B->pats, q->w + q->off[id],
                                                q->off[id + 1] - q->off[id])) != UINT32_MAX;
        }
    /* each part's first explicit column, from the counts of the parts before it */
    uint64_t at = 0;
    for (uint32_t p = 0; p < nparts; p++) {
        uint64_t n = J->v[p].nexp;
        J->v[p].nexp = at;
        at += n;
    }
    B->ebase = at;
    B->nring = 0;
    for (uint32_t p = 0; p < nparts; p++) {
        J->ebase[p] = at;
        at += J->e[p].nexp;
        B->nring += J->e[p].nring;
    }
    B->nexp = at;
    if (ok) { /* the level's ids, as wide as their number needs */
        uint8_t pw = B->pats.n <= 256 ? 1 : B->pats.n <= 65536 ? 2 : 4;
        J->lid = S->pat;
        if (pw > 1 && !(S->pat = sdi_alloc(B->m, ((size_t)S->nrows + 1) * pw))) {
            S->pat = (void *)J->lid;
            ok = false;
        } else {
            S->pw = pw;
            sdi_par_dyn(B->threads, work, PCHUNK, remap_part, J);
            if ((void *)J->lid != S->pat)
                sdi_free(B->m, (void *)J->lid);
        }
    }
    for (uint32_t p = 0; p < nparts; p++) {
        sdi_free(&J->mem[p], J->v[p].wbuf);
        sdi_free(&J->mem[p], J->v[p].stmp);
        sdi_free(&J->mem[p], J->e[p].wbuf);
        sdi_free(&J->mem[p], J->e[p].stmp);
        sdi_free(&J->mem[p], J->vmap[p]);
        sdi_free(&J->mem[p], J->emap[p]);
        sdi_pats_free(&J->mem[p], &J->vpats[p]);
        sdi_pats_free(&J->mem[p], &J->epats[p]);
    }
    sdi_free(B->m, J);
    if (full) /* more patterns in a part than its byte ids hold: the serial pass */
        return serial_patterns(B, S);
    return ok;
}

/* Cell points of octahedra: all their columns implicit. */
static bool cell_patterns(build *B, sd_csrb *S)
{
    const sd_topo *t = B->t;
    const uint64_t first = (uint64_t)t->nv + t->ne, nrows = first + t->noct;
    for (uint64_t r = first; r < nrows; r++)
        if (r % SD_CHK == 0)
            S->kchk[r / SD_CHK] = B->nexp;
    S->kchk[(nrows + SD_CHK - 1) / SD_CHK] = B->nexp;
    if (!t->noct)
        return true;
    double w[6];
    for (int i = 0; i < 6; i++)
        w[i] = sdi_mask_cell(B->scheme, i);
    uint32_t id = sdi_pats_intern(B->m, &B->pats, w, 6);
    if (id == UINT32_MAX)
        return false;
    for (uint32_t o = 0; o < t->noct; o++)
        if (!sdi_csrb_set_pat(B->m, S, (uint32_t)first + o, id))
            return false;
    return true;
}

/* ---- 3. columns -------------------------------------------------------------------------- */

/* Edge rows' explicit columns (their rings) in parts: whole chunks of SD_CHK rows, each starting
 * at the column kchk gives it (the first chunk of edge rows at ebase), as apply_part cuts S. */
static void erows_part(void *arg, uint32_t part, uint32_t nparts)
{
    const build *B = arg;
    const uint32_t nv = B->t->nv, ne = B->t->ne;
    const uint64_t c_lo = nv / SD_CHK, c_hi = ((uint64_t)nv + ne + SD_CHK - 1) / SD_CHK;
    uint64_t c0, c1;
    sdi_range(c_hi - c_lo, part, nparts, &c0, &c1);
    uint64_t r0 = (c_lo + c0) * SD_CHK, r1 = (c_lo + c1) * SD_CHK;
    if (r0 < nv)
        r0 = nv;
    if (r1 > (uint64_t)nv + ne)
        r1 = (uint64_t)nv + ne;
    if (r0 >= r1)
        return;
    uint64_t at = r0 == nv ? B->ebase : B->S_kchk[r0 / SD_CHK];
    for (uint32_t e = (uint32_t)(r0 - nv); e < r1 - nv; e++) {
        uint32_t k = ring_len(B, e);
        if (k) {
            memcpy(B->col + at, ring_of(B, e), k * sizeof *B->col);
            at += k;
        }
    }
}

sd_result sdi_build_rules(sd_complex *cx, sd_level *lv, sd_error *err)
{
    sd_mem *m = &cx->mem;
    const sd_topo *t = &lv->t;
    const uint32_t nv = t->nv, ne = t->ne, no = t->noct;
    build B = {.m = m, .t = t, .weights = cx->opt.surface_weights, .scheme = cx->opt.solid_scheme,
               .threads = cx->opt.threads, .rel = {.t = t}};
    sd_result rc = SD_OK;
    for (uint32_t k = 1; k < SDI_LOOP_CACHE; k++)
        B.loopc[k] = sdi_loop_weight(B.weights, k);
    B.loopc[0] = 0;

    uint64_t nrows = (uint64_t)nv + ne + no;
    if (nrows >= UINT32_MAX)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1, "too many points for 32-bit ids");
    if (!choose(&B, cx, lv))
        goto nomem;
    if (cx->sh.ne || cx->sh.nv || cx->sh.nf) { /* semi-sharp creases reaching this level */
        sdi_sharp lsh;
        if (!sdi_sharp_level(cx, lv->index, &lsh))
            goto nomem;
        bool ok = sdi_sharp_rows(m, t, &lsh, cx->sh_method, B.vr, B.take, &B.sh);
        sdi_sharp_free(m, &lsh);
        if (!ok)
            goto nomem;
    }
    if (!sdi_csrb_init(m, &lv->S, nv, ne, no, nv, t->ev, t->oct) || !row_patterns(&B, &lv->S) ||
        !cell_patterns(&B, &lv->S))
        goto nomem;
    B.cur = B.cnt_a;
    uint64_t nnz = (B.nexp - (B.stride ? 0 : B.nring)) + B.nring + nv + 2ull * ne + 6ull * no;
    if (nnz >= UINT32_MAX) {
        rc = sdi_fail(err, SD_ERR_LIMIT, -1, -1, "subdivision matrix too large for 32-bit offsets");
        goto fail;
    }
    lv->S.nexp = B.nexp;
    B.col = lv->S.col = sdi_alloc(m, (B.nexp + 1) * sizeof *lv->S.col);
    if (!lv->S.col || !sdi_csrb_finish(m, &lv->S, &B.pats, nnz))
        goto nomem;
    if (B.stride) { /* the opposite vertices are the edge rows' explicit columns as they are */
        lv->S.eopp = B.opp;
        B.opp = NULL;
    }
    /* the columns: vertex rows, then edge rows, each in parallel parts */
    sdi_vertex_rho_cols(t, B.scheme, B.threads, B.vr, B.take, B.cur, B.col);
    if (!B.stride) {
        B.S_kchk = lv->S.kchk;
        sdi_par(B.threads, B.nexp - B.ebase, erows_part, &B);
    }

    lv->have_rules = true;
    goto out;

nomem:
    rc = sdi_fail_nomem(err, m);
fail:
    sdi_free(m, lv->vrule);
    sdi_free(m, lv->erule);
    sdi_free(m, lv->geo);
    lv->vrule = lv->erule = lv->geo = NULL;
    sdi_csrb_free(m, &lv->S);
out:
    sdi_pats_free(m, &B.pats);
    sdi_free(m, B.take);
    sdi_free(m, B.gam);
    sdi_sharp_rows_free(m, &B.sh);
    sdi_free(m, B.cnt_a);
    sdi_free(m, B.cnt_b);
    sdi_free(m, B.opp);
    sdi_free(m, B.nopp);
    sdi_rings_free(m, &B.sr);
    sdi_rings_free(m, &B.gr);
    sdi_yzrows_free(m, &B.yz);
    sdi_rels_free(m, &B.rel);
    return rc;
}
