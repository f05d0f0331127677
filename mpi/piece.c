/* piece.c — what every rank does with its piece: build, refine, number as the one process does.
 *
 * The sub-complex is built by the same api/ code as a session's complex (api_build_model: the
 * posted arrays, the rule preferences, the restricted overrides and tags), with each
 * tetrahedron's orientation and diagonal pair given as the whole complex chose them, and refined
 * by the same core.
 *
 * Global ids. core/split.c numbers level l+1 in closed form from level l: vertices [vertex
 * points | one per edge | one per octahedron], edges [2 per edge | 3 per face | 12 per
 * octahedron], faces [4 per face | 4 per tetrahedron | 24 per octahedron], tetrahedra [4 per
 * tetrahedron | 8 per octahedron], octahedra [1 per tetrahedron | 6 per octahedron], curves
 * [2 per curve], triangles [4 per triangle], and within one parent the children follow the
 * parent's stored vertex order (an edge's first half starts at its first vertex). So once every
 * level-0 entity of the piece is mapped to its one-process id, the map of level l+1 follows
 * from level l's by the same formulas with the one-process counts — provided the parent is
 * stored in the same order in both. Level 0's edges and faces get that order from the first
 * simplex (tetrahedra first, in input order) that meets them (core/complex.c); the piece keeps
 * the input order and takes every simplex around an owned vertex, so every edge and face of an
 * owned simplex is met first by the same simplex in the same slots: the same order. That is
 * checked here for every edge and face of the owned simplices (a mismatch is an error, not a
 * wrong id); entities of the halo's rim may differ, and only their descendants — never written —
 * would get wrong ids.
 */
#include "../api/internal.h"
#include "../api/mem.h"
#include "../core/internal.h"
#include "mp.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

double mp_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

void mp_buf_put(mp_buf *b, const void *d, size_t n)
{
    if (b->failed)
        return;
    if (b->len + n > b->cap) {
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->len + n)
            cap *= 2;
        unsigned char *nd = realloc(b->data, cap);
        if (!nd) {
            b->failed = 1;
            return;
        }
        b->data = nd;
        b->cap = cap;
    }
    if (n)
        memcpy(b->data + b->len, d, n);
    b->len += n;
}

void mp_piece_free(mp_piece *p)
{
    free(p->vg);
    free(p->vfull);
    free(p->xyz);
    for (int a = 0; a < p->nattrs; a++)
        free(p->attrs[a].data);
    free(p->sg);
    free(p->ssize);
    free(p->sidx);
    free(p->spart);
    free(p->sreor);
    free(p->sdiag);
    free(p->scell);
    free(p->e0);
    free(p->e0g);
    free(p->f0);
    free(p->f0g);
    free(p->vcls);
    free(p->ecls);
    free(p->fcls);
    free(p->vrule);
    free(p->erule);
    free(p->vval);
    free(p->eval);
    free(p->tags.size);
    free(p->tags.idx);
    free(p->tags.pet);
    free(p->tags.sh);
    free(p->ov);
    memset(p, 0, sizeof *p);
}

/* ---- the flat form: the struct itself (pointers dropped), then each array with its length */

static void put_arr(mp_buf *b, const void *d, uint64_t n)
{
    mp_buf_put(b, &n, sizeof n);
    mp_buf_put(b, d, (size_t)n);
}

static uint64_t sidx_len(const mp_piece *p)
{
    uint64_t n = 0;
    for (uint32_t s = 0; s < p->ns; s++)
        n += p->ssize[s];
    return n;
}

static uint64_t tidx_len(const api_tags *t)
{
    uint64_t n = 0;
    for (uint32_t i = 0; i < t->n; i++)
        n += t->size[i];
    return n;
}

void mp_pack(const mp_piece *p, mp_buf *b)
{
    mp_buf_put(b, p, sizeof *p);
    uint64_t nv = p->nv, ns = p->ns;
    put_arr(b, p->vg, nv * 4);
    put_arr(b, p->vfull, nv);
    put_arr(b, p->xyz, nv * 24);
    for (int a = 0; a < p->nattrs; a++)
        put_arr(b, p->attrs[a].data, nv * (uint64_t)p->attrs[a].ncomp * 8);
    put_arr(b, p->sg, ns * 4);
    put_arr(b, p->ssize, ns);
    put_arr(b, p->sidx, sidx_len(p) * 4);
    put_arr(b, p->spart, ns * 4);
    put_arr(b, p->sreor, ns);
    put_arr(b, p->sdiag, ns);
    put_arr(b, p->scell, ns * 4);
    put_arr(b, p->e0, (uint64_t)p->ne0 * 8);
    put_arr(b, p->e0g, (uint64_t)p->ne0 * 4);
    put_arr(b, p->f0, (uint64_t)p->nf0 * 12);
    put_arr(b, p->f0g, (uint64_t)p->nf0 * 4);
    put_arr(b, p->vcls, nv * 2);
    put_arr(b, p->ecls, (uint64_t)p->ne0 * 2);
    put_arr(b, p->fcls, (uint64_t)p->nf0 * 2);
    put_arr(b, p->vrule, nv);
    put_arr(b, p->erule, p->ne0);
    put_arr(b, p->vval, nv * 4);
    put_arr(b, p->eval, (uint64_t)p->ne0 * 4);
    put_arr(b, p->tags.size, p->tags.n);
    put_arr(b, p->tags.idx, tidx_len(&p->tags) * 4);
    put_arr(b, p->tags.pet, (uint64_t)p->tags.npet * sizeof *p->tags.pet);
    put_arr(b, p->tags.sh, (uint64_t)p->tags.nsh * sizeof *p->tags.sh);
    put_arr(b, p->ov, (uint64_t)p->nov * sizeof *p->ov);
}

typedef struct cursor {
    const unsigned char *d;
    size_t len, at;
    int bad;
} cursor;

/* The next array, copied into a new block of at least one byte; `want` bytes or bad. */
static void *get_arr(cursor *c, uint64_t want)
{
    uint64_t n;
    if (c->bad || c->len - c->at < sizeof n) {
        c->bad = 1;
        return NULL;
    }
    memcpy(&n, c->d + c->at, sizeof n);
    c->at += sizeof n;
    if (n != want || c->len - c->at < n) {
        c->bad = 1;
        return NULL;
    }
    void *q = malloc((size_t)n + 1);
    if (!q) {
        c->bad = 1;
        return NULL;
    }
    memcpy(q, c->d + c->at, (size_t)n);
    c->at += (size_t)n;
    return q;
}

int mp_unpack(const unsigned char *data, size_t len, mp_piece *p)
{
    memset(p, 0, sizeof *p);
    if (len < sizeof *p)
        return -1;
    mp_piece h;
    memcpy(&h, data, sizeof h);
    if (h.nattrs < 0 || h.nattrs > API_MAX_ATTRIBUTES || h.level < 0 || h.level > SD_MAX_LEVEL)
        return -1;
    cursor c = {data, len, sizeof h, 0};
    *p = h;
    uint64_t nv = h.nv, ns = h.ns;
    p->vg = get_arr(&c, nv * 4);
    p->vfull = get_arr(&c, nv);
    p->xyz = get_arr(&c, nv * 24);
    for (int a = 0; a < h.nattrs; a++)
        p->attrs[a].data = get_arr(&c, nv * (uint64_t)h.attrs[a].ncomp * 8);
    p->sg = get_arr(&c, ns * 4);
    p->ssize = get_arr(&c, ns);
    uint64_t ni = 0;
    for (uint64_t s = 0; p->ssize && s < ns; s++)
        ni += p->ssize[s];
    p->sidx = get_arr(&c, ni * 4);
    p->spart = get_arr(&c, ns * 4);
    p->sreor = get_arr(&c, ns);
    p->sdiag = get_arr(&c, ns);
    p->scell = get_arr(&c, ns * 4);
    p->e0 = get_arr(&c, (uint64_t)h.ne0 * 8);
    p->e0g = get_arr(&c, (uint64_t)h.ne0 * 4);
    p->f0 = get_arr(&c, (uint64_t)h.nf0 * 12);
    p->f0g = get_arr(&c, (uint64_t)h.nf0 * 4);
    p->vcls = get_arr(&c, nv * 2);
    p->ecls = get_arr(&c, (uint64_t)h.ne0 * 2);
    p->fcls = get_arr(&c, (uint64_t)h.nf0 * 2);
    p->vrule = get_arr(&c, nv);
    p->erule = get_arr(&c, h.ne0);
    p->vval = get_arr(&c, nv * 4);
    p->eval = get_arr(&c, (uint64_t)h.ne0 * 4);
    p->tags.size = get_arr(&c, h.tags.n);
    ni = 0;
    for (uint32_t i = 0; p->tags.size && i < h.tags.n; i++)
        ni += p->tags.size[i];
    p->tags.idx = get_arr(&c, ni * 4);
    p->tags.pet = get_arr(&c, (uint64_t)h.tags.npet * sizeof *p->tags.pet);
    p->tags.sh = get_arr(&c, (uint64_t)h.tags.nsh * sizeof *p->tags.sh);
    p->ov = get_arr(&c, (uint64_t)h.nov * sizeof *p->ov);
    if (c.bad || c.at != len) {
        mp_piece_free(p);
        return -1;
    }
    return 0;
}

/* ---- build and refine ---------------------------------------------------------------------- */

static api_input *piece_input(const mp_piece *p, sd_level0_classes *K)
{
    api_input *in = api_input_new();
    if (!in)
        return NULL;
    uint64_t ni = sidx_len(p);
    uint32_t ntet = 0;
    for (uint32_t s = 0; s < p->ns; s++)
        ntet += p->ssize[s] == 4;
    in->nv = p->nv;
    in->ns = p->ns;
    in->xyz = api_plain_malloc((size_t)p->nv * 3 * sizeof(double) + 1);
    in->size = api_plain_malloc((size_t)p->ns + 1);
    in->idx = api_plain_malloc((size_t)ni * sizeof(uint32_t) + 1);
    in->reoriented = api_malloc((size_t)p->ns + 1);
    in->diag = api_malloc(((size_t)ntet + 1) * sizeof *in->diag);
    if (!in->xyz || !in->size || !in->idx || !in->reoriented || !in->diag) {
        api_input_unref(in);
        return NULL;
    }
    memcpy(in->xyz, p->xyz, (size_t)p->nv * 3 * sizeof(double));
    memcpy(in->size, p->ssize, p->ns);
    memcpy(in->idx, p->sidx, (size_t)ni * sizeof(uint32_t));
    memcpy(in->reoriented, p->sreor, p->ns);
    in->reoriented[p->ns] = 0;
    *K = (sd_level0_classes){.nv = p->nv, .vertex = p->vcls, .ne = p->ne0, .edge_v = p->e0,
                             .edge = p->ecls, .nf = p->nf0, .face_v = p->f0, .face = p->fcls,
                             .differing = K->differing};
    in->classes = K;
    for (uint32_t s = 0; s < p->ns; s++)
        if (p->ssize[s] == 4 && p->sdiag[s] >= 0) {
            in->diag[in->ndiag][0] = s;
            in->diag[in->ndiag++][1] = (uint32_t)p->sdiag[s];
        }
    for (int a = 0; a < p->nattrs; a++) {
        in->attrs[a] = p->attrs[a];
        size_t n = (size_t)p->nv * (size_t)p->attrs[a].ncomp * sizeof(double);
        in->attrs[a].data = api_plain_malloc(n + 1);
        if (!in->attrs[a].data) {
            in->nattrs = a;
            api_input_unref(in);
            return NULL;
        }
        memcpy(in->attrs[a].data, p->attrs[a].data, n);
        in->nattrs = a + 1;
    }
    return in;
}

static uint64_t mix(uint64_t x)
{
    x ^= x >> 33;
    x *= 0xff51afd7ed558ccdULL;
    x ^= x >> 33;
    x *= 0xc4ceb9fe1a85ec53ULL;
    return x ^ (x >> 33);
}

/* Keys: 21 bits per id would not do for big pieces, so the key is the sorted ids packed into
 * two words hashed together, stored as (a << 32 | b) and c beside it. */
typedef struct key3 {
    uint64_t ab;
    uint32_t c;
} key3;

static key3 mkkey(const uint32_t *v, int n)
{
    uint32_t s[3] = {v[0], n > 1 ? v[1] : 0, n > 2 ? v[2] : 0};
    for (int i = 1; i < n; i++)
        for (int j = i; j > 0 && s[j - 1] > s[j]; j--) {
            uint32_t x = s[j];
            s[j] = s[j - 1];
            s[j - 1] = x;
        }
    return (key3){(uint64_t)(s[0] + 1) << 32 | (uint64_t)(n > 1 ? s[1] + 1 : 0), n > 2 ? s[2] + 1 : 0};
}

typedef struct kmap {
    uint64_t cap;
    key3 *k;
    uint32_t *val;
} kmap;

static int kmap_init(kmap *m, uint64_t n)
{
    m->cap = 16;
    while (m->cap < 2 * n + 16)
        m->cap *= 2;
    m->k = calloc(m->cap, sizeof *m->k);
    m->val = malloc(m->cap * sizeof *m->val);
    return m->k && m->val ? 0 : -1;
}

static void kmap_free(kmap *m)
{
    free(m->k);
    free(m->val);
}

static void kmap_put(kmap *m, key3 k, uint32_t v)
{
    uint64_t h = mix(k.ab ^ mix(k.c)) & (m->cap - 1);
    while (m->k[h].ab && (m->k[h].ab != k.ab || m->k[h].c != k.c))
        h = (h + 1) & (m->cap - 1);
    m->k[h] = k;
    m->val[h] = v;
}

static uint32_t kmap_get(const kmap *m, key3 k)
{
    uint64_t h = mix(k.ab ^ mix(k.c)) & (m->cap - 1);
    while (m->k[h].ab) {
        if (m->k[h].ab == k.ab && m->k[h].c == k.c)
            return m->val[h];
        h = (h + 1) & (m->cap - 1);
    }
    return UINT32_MAX;
}

/* The maps of one level: local entity -> one-process id, and each cell's simplex of the piece
 * (the local input index it descends from). Cells by sd_cell_kind. */
struct mp_maps {
    uint64_t *v, *e, *f;
    uint64_t *c[5];
    uint32_t *s[5];
    sd_counts n;                  /* the piece's counts of the level */
    sd_counts G;                  /* the one-process counts of the level */
    int top;                      /* these are level L's own maps (L = 0) */
};

static void maps_free(mp_maps *g)
{
    if (!g)
        return;
    free(g->v);
    free(g->e);
    free(g->f);
    for (int k = 0; k < 5; k++) {
        free(g->c[k]);
        free(g->s[k]);
    }
    memset(g, 0, sizeof *g);
}

void mp_result_free(mp_result *r)
{
    if (r->m)
        api_model_unref(r->m);
    maps_free(r->g);
    free(r->g);
    free(r->vowner);
    memset(r, 0, sizeof *r);
}

static uint64_t *alloc64(uint64_t n) { return malloc((size_t)(n ? n : 1) * sizeof(uint64_t)); }
static uint32_t *alloc32(uint64_t n) { return malloc((size_t)(n ? n : 1) * sizeof(uint32_t)); }

static uint64_t kcount(const sd_counts *n, int k)
{
    return k == SD_CELL_POINT ? n->points : k == SD_CELL_CURVE ? n->curves
           : k == SD_CELL_TRIANGLE ? n->triangles : k == SD_CELL_TETRA ? n->tetrahedra
                                                                        : n->octahedra;
}

/* One step of the closed forms (core/split.c): the level-(l+1) id of a vertex or cell from
 * level l's maps `a` (local counts a->n, one-process counts a->G). */
static inline uint64_t next_vertex(const mp_maps *a, uint64_t i)
{
    const sd_counts *n = &a->n, *G = &a->G;
    return i < n->vertices              ? a->v[i]
           : i < n->vertices + n->edges ? G->vertices + a->e[i - n->vertices]
                                        : G->vertices + G->edges + a->c[SD_CELL_OCTA][i - n->vertices - n->edges];
}

static inline uint64_t next_cell(const mp_maps *a, int k, uint64_t i)
{
    uint64_t nt = a->n.tetrahedra;
    switch (k) {
    case SD_CELL_POINT: return a->c[k][i];
    case SD_CELL_CURVE: return 2 * a->c[k][i / 2] + i % 2;
    case SD_CELL_TRIANGLE: return 4 * a->c[k][i / 4] + i % 4;
    case SD_CELL_TETRA:
        return i < 4 * nt ? 4 * a->c[SD_CELL_TETRA][i / 4] + i % 4
                          : 4 * a->G.tetrahedra + 8 * a->c[SD_CELL_OCTA][(i - 4 * nt) / 8] + (i - 4 * nt) % 8;
    default:
        return i < nt ? a->c[SD_CELL_TETRA][i]
                      : a->G.tetrahedra + 6 * a->c[SD_CELL_OCTA][(i - nt) / 6] + (i - nt) % 6;
    }
}

static inline uint32_t next_src(const mp_maps *a, int k, uint64_t i)
{
    uint64_t nt = a->n.tetrahedra;
    switch (k) {
    case SD_CELL_POINT: return a->s[k][i];
    case SD_CELL_CURVE: return a->s[k][i / 2];
    case SD_CELL_TRIANGLE: return a->s[k][i / 4];
    case SD_CELL_TETRA: return i < 4 * nt ? a->s[SD_CELL_TETRA][i / 4] : a->s[SD_CELL_OCTA][(i - 4 * nt) / 8];
    default: return i < nt ? a->s[SD_CELL_TETRA][i] : a->s[SD_CELL_OCTA][(i - nt) / 6];
    }
}

uint64_t mp_vgid(const mp_result *r, uint32_t v) { return r->g->top ? r->g->v[v] : next_vertex(r->g, v); }
uint64_t mp_cgid(const mp_result *r, int k, uint32_t i)
{
    return r->g->top ? r->g->c[k][i] : next_cell(r->g, k, i);
}
uint32_t mp_csrc(const mp_result *r, int k, uint32_t i)
{
    return r->g->top ? r->g->s[k][i] : next_src(r->g, k, i);
}

/* Level l+1's maps from level l's. Edges only when `with_e`, faces only when `with_f` (level
 * L's vertices need level L-1's edges, and those level L-2's faces: nothing finer). */
static int maps_next(const mp_maps *a, const sd_counts *n1, const sd_counts *G1, int with_e,
                     int with_f, mp_maps *b)
{
    memset(b, 0, sizeof *b);
    b->n = *n1;
    b->G = *G1;
    const sd_counts *n = &a->n, *G = &a->G;
    int ok = (b->v = alloc64(n1->vertices)) != NULL;
    for (int k = 0; k < 5; k++)
        ok = ok && (b->c[k] = alloc64(kcount(n1, k))) && (b->s[k] = alloc32(kcount(n1, k)));
    if (with_e)
        ok = ok && (b->e = alloc64(n1->edges));
    if (with_f)
        ok = ok && (b->f = alloc64(n1->faces));
    if (!ok)
        return -1;
    for (uint64_t i = 0; i < n1->vertices; i++)
        b->v[i] = next_vertex(a, i);
    if (with_e) {
        uint64_t h = 2 * n->edges, fi = h + 3 * n->faces;
        for (uint64_t i = 0; i < n1->edges; i++)
            b->e[i] = i < h    ? 2 * a->e[i / 2] + i % 2
                      : i < fi ? 2 * G->edges + 3 * a->f[(i - h) / 3] + (i - h) % 3
                               : 2 * G->edges + 3 * G->faces + 12 * a->c[SD_CELL_OCTA][(i - fi) / 12] +
                                     (i - fi) % 12;
    }
    if (with_f) {
        uint64_t h = 4 * n->faces, ti = h + 4 * n->tetrahedra;
        for (uint64_t i = 0; i < n1->faces; i++)
            b->f[i] = i < h    ? 4 * a->f[i / 4] + i % 4
                      : i < ti ? 4 * G->faces + 4 * a->c[SD_CELL_TETRA][(i - h) / 4] + (i - h) % 4
                               : 4 * G->faces + 4 * G->tetrahedra +
                                     24 * a->c[SD_CELL_OCTA][(i - ti) / 24] + (i - ti) % 24;
    }
    for (int k = 0; k < 5; k++)
        for (uint64_t i = 0; i < kcount(n1, k); i++) {
            b->c[k][i] = next_cell(a, k, i);
            b->s[k][i] = next_src(a, k, i);
        }
    return 0;
}

/* Level 0's maps: vertices and cells from the piece, edges and faces by their vertices. The
 * edges and faces of owned simplices must be stored in the one-process order (see the top). */
/* Whether the piece's level-0 vertex or edge (local vertex ids v, n of them) follows the whole
 * complex's rule and valence. They differ only where the piece lacks something the rule reads
 * (DECISIONS 44): then the owned points would be wrong, and the run stops. */
static int same_rule(const mp_piece *p, const sd_class *k, int rule, uint32_t valence,
                     const uint32_t *v, int n, char *err, size_t errlen)
{
    if (k->rule == rule && k->valence == valence)
        return 1;
    char at[64];
    if (n == 1)
        snprintf(at, sizeof at, "vertex %u", p->vg[v[0]]);
    else
        snprintf(at, sizeof at, "edge %u-%u", p->vg[v[0]], p->vg[v[1]]);
    snprintf(err, errlen,
             "the rules of piece %d are not the whole complex's at %s: %s (valence %u) there, %s "
             "(valence %u) in the whole complex; a halo of %d ring%s is too thin for this mesh "
             "(--halo)",
             p->rank, at, sd_rule_name((sd_rule)k->rule), k->valence, sd_rule_name((sd_rule)rule),
             valence, p->halo, p->halo == 1 ? "" : "s");
    return 0;
}

static int maps_level0(const mp_piece *p, const sd_level *lv0, mp_maps *g, uint64_t *checked,
                       char *err, size_t errlen)
{
    const sd_topo *t = &lv0->t;
    memset(g, 0, sizeof *g);
    sd_complex_counts(lv0->cx, 0, &g->n);
    g->G = p->global[0];
    if (!t->faces) {
        snprintf(err, errlen, "internal: level 0 has no faces");
        return -1;
    }
    int ok = (g->v = alloc64(t->nv)) && (g->e = alloc64(t->ne)) && (g->f = alloc64(t->nf));
    for (int k = 0; k < 5; k++)
        ok = ok && (g->c[k] = alloc64(kcount(&g->n, k))) && (g->s[k] = alloc32(kcount(&g->n, k)));
    uint8_t *vown = calloc((size_t)p->nv + 1, 1);
    kmap km = {0};
    int rc = -1;
    if (!ok || !vown || kmap_init(&km, (uint64_t)p->ne0 + p->nf0)) {
        snprintf(err, errlen, "out of memory numbering level 0");
        goto out;
    }
    for (uint32_t i = 0; i < t->nv; i++) {
        g->v[i] = p->vg[i];
        sd_class k;
        if (p->vrule[i] != MP_UNCHECKED) {
            if (sd_level_vertex_class(lv0, i, &k) ||
                !same_rule(p, &k, p->vrule[i], p->vval[i], &i, 1, err, errlen))
                goto out;
            ++*checked;
        }
    }
    uint64_t off = 0;
    for (uint32_t s = 0; s < p->ns; s++) {
        if (p->spart[s] == p->rank)
            for (int j = 0; j < p->ssize[s]; j++)
                vown[p->sidx[off + j]] = 1;
        off += p->ssize[s];
    }
    for (int k = 0; k < 4; k++)
        for (uint32_t i = 0; i < sd_level_num_cells(lv0, (sd_cell_kind)k); i++) {
            uint32_t s = sd_level_control_cell(lv0, (sd_cell_kind)k, i);
            g->s[k][i] = s;
            g->c[k][i] = p->scell[s];
        }
    for (uint32_t e = 0; e < p->ne0; e++)
        kmap_put(&km, mkkey(p->e0 + 2 * (size_t)e, 2), e);
    for (uint32_t f = 0; f < p->nf0; f++)
        kmap_put(&km, mkkey(p->f0 + 3 * (size_t)f, 3), p->ne0 + f);
    for (uint32_t e = 0; e < t->ne; e++) {
        uint32_t q = kmap_get(&km, mkkey(t->ev[e], 2));
        if (q == UINT32_MAX || q >= p->ne0) {
            snprintf(err, errlen, "internal: level-0 edge %u-%u of the piece is not in the mesh",
                     p->vg[t->ev[e][0]], p->vg[t->ev[e][1]]);
            goto out;
        }
        g->e[e] = p->e0g[q];
        sd_class k;
        if (p->erule[q] != MP_UNCHECKED) {
            if (sd_level_edge_class(lv0, e, &k) ||
                !same_rule(p, &k, p->erule[q], p->eval[q], t->ev[e], 2, err, errlen))
                goto out;
            ++*checked;
        }
        if ((vown[t->ev[e][0]] && vown[t->ev[e][1]]) &&
            (p->e0[2 * q] != t->ev[e][0] || p->e0[2 * q + 1] != t->ev[e][1])) {
            snprintf(err, errlen, "internal: edge %u-%u is stored reversed in the piece",
                     p->vg[t->ev[e][0]], p->vg[t->ev[e][1]]);
            goto out;
        }
    }
    for (uint32_t f = 0; f < t->nf; f++) {
        uint32_t q = kmap_get(&km, mkkey(t->fv[f], 3));
        if (q == UINT32_MAX || q < p->ne0) {
            snprintf(err, errlen, "internal: a level-0 face of the piece is not in the mesh");
            goto out;
        }
        q -= p->ne0;
        g->f[f] = p->f0g[q];
        if (vown[t->fv[f][0]] && vown[t->fv[f][1]] && vown[t->fv[f][2]] &&
            memcmp(p->f0 + 3 * (size_t)q, t->fv[f], 3 * sizeof(uint32_t))) {
            snprintf(err, errlen, "internal: face %u-%u-%u is stored in another order in the piece",
                     p->vg[t->fv[f][0]], p->vg[t->fv[f][1]], p->vg[t->fv[f][2]]);
            goto out;
        }
    }
    rc = 0;
out:
    free(vown);
    kmap_free(&km);
    return rc;
}

int mp_refine(const mp_piece *p, uint64_t max_bytes, int quiet, const char *tag, mp_result *r,
              char *err, size_t errlen)
{
    memset(r, 0, sizeof *r);
    r->p = p;
    if (!p->ns)
        return 0;
    double t0 = mp_now();
    size_t differing = 0;
    sd_level0_classes K = {.differing = &differing};
    api_input *in = piece_input(p, &K);
    if (!in) {
        snprintf(err, errlen, "out of memory building the piece's input");
        return -1;
    }
    api_rules rules = p->rules;
    rules.overrides = p->ov;
    rules.noverrides = p->nov;
    api_limits lim = api_default_limits();
    lim.max_session_bytes = max_bytes;
    lim.batch = true; /* written out, never edited: no edit index (DECISIONS 46) */
    api_problem prob = {0};
    int st = api_build_model(in, &rules, &p->tags, &lim, &r->m, &prob);
    in->classes = NULL; /* K is this call's; the core has taken the classes */
    api_input_unref(in);
    if (st) {
        snprintf(err, errlen, "the piece's complex was refused (%d %s): %s", prob.status,
                 prob.slug ? prob.slug : "", prob.detail);
        r->m = NULL;
        return -1;
    }
    r->seconds_build = mp_now() - t0;
    r->classes_differing = differing;
    for (uint32_t i = 0; i < p->nv; i++)
        r->classes_shipped += p->vcls[i] != 0;
    for (uint32_t i = 0; i < p->ne0; i++)
        r->classes_shipped += p->ecls[i] != 0;
    for (uint32_t i = 0; i < p->nf0; i++)
        r->classes_shipped += p->fcls[i] != 0;
    sd_error e = {0};
    const sd_level *lv0 = sd_complex_level(r->m->c, 0, &e);
    sd_class k0; /* level 0's rules, which the level-0 map checks (built anyway for level 1) */
    if (lv0 && p->nv && sd_complex_vertex_class(r->m->c, 0, 0, &k0, &e))
        lv0 = NULL;
    const sd_level *lv = lv0;
    double t1 = mp_now();
    for (int l = 1; lv && l <= p->level; l++) {
        double tl = mp_now();
        lv = sd_complex_level(r->m->c, l, &e);
        if (lv && !quiet) {
            uint64_t cells = 0;
            for (int k = 0; k < 5; k++)
                cells += sd_level_num_cells(lv, (sd_cell_kind)k);
            fprintf(stderr, "%s: level %d: %llu cells (%.2f s)\n", tag, l,
                    (unsigned long long)cells, mp_now() - tl);
        }
    }
    if (!lv) {
        snprintf(err, errlen, "level %d failed: %s (%s)", p->level, e.message,
                 sd_result_name(e.code));
        return -1;
    }
    r->lv = lv;
    r->seconds_refine = mp_now() - t1;
    double t2 = mp_now();
    /* the maps of level L-1 (level L's ids follow from them when asked), or level 0's */
    r->g = calloc(1, sizeof *r->g);
    if (!r->g || maps_level0(p, lv0, r->g, &r->rules_checked, err, errlen)) {
        if (!r->g)
            snprintf(err, errlen, "out of memory");
        return -1;
    }
    r->g->top = p->level == 0;
    for (int l = 0; l + 1 < p->level; l++) {
        sd_counts n1;
        sd_complex_counts(r->m->c, l + 1, &n1);
        mp_maps h;
        int rc = maps_next(r->g, &n1, &p->global[l + 1], 1, l + 3 <= p->level, &h);
        maps_free(r->g);
        *r->g = h;
        if (rc) {
            snprintf(err, errlen, "out of memory numbering level %d", l + 1);
            return -1;
        }
    }
    /* owner of each point: the lowest owner among the cells around it (all of them are in the
     * piece for the points of owned cells) */
    uint32_t nv = sd_level_num_vertices(lv);
    r->vowner = malloc(((size_t)nv + 1) * sizeof *r->vowner);
    if (!r->vowner) {
        snprintf(err, errlen, "out of memory");
        return -1;
    }
    for (uint32_t v = 0; v < nv; v++)
        r->vowner[v] = INT32_MAX;
    for (int k = 0; k < 5; k++) {
        uint32_t n = sd_level_num_cells(lv, (sd_cell_kind)k);
        int sz = sd_cell_size((sd_cell_kind)k);
        r->ncell[k] = n;
        for (uint32_t i = 0; i < n; i++) {
            int32_t owner = p->spart[mp_csrc(r, k, i)];
            r->owned_cells += owner == p->rank;
            uint32_t v[6];
            sd_level_cell(lv, (sd_cell_kind)k, i, v);
            for (int j = 0; j < sz; j++)
                if (owner < r->vowner[v[j]])
                    r->vowner[v[j]] = owner;
        }
        r->local_cells += n;
    }
    r->seconds_ids = mp_now() - t2;
    return 0;
}
