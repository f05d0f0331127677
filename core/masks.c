/* masks.c — the weights of the rules: pure functions of a neighbourhood's sizes, one per rule
 * family, each with the equation it implements (docs/RULES.md has the table).
 *
 * A vertex mask gives the weights of the centre, of each point of rho (class A) and of each
 * octahedral opposite (class B, the averaged solid scheme); an edge mask those of the two ends,
 * of each ring point and of each diagonal-class ring point (averaged). Masks see sizes and the
 * options, never the topology (rings.c says who the neighbours are, stencil.c puts masks and
 * neighbours into rows), so they are memoized by rule and size; every mask sums to 1 over its
 * neighbourhood. The expressions are the ones the golden outputs were made with: the stencils are
 * compared byte for byte, so a change of evaluation order here is a change of output.
 *
 * rule_table.h names each rule's masks (vmask_<name>, emask_<name> below); sdi_vertex_mask and
 * sdi_edge_mask dispatch through it. The Ying-Zorin masks (003) and the cell point are called
 * directly where their rows are made.
 */
#include "internal.h"
#include <math.h>

/* ---- vertex masks ---------------------------------------------------------------------- */

/* The 0-mask: the vertex stays (000 Sec. 4.1; docs/RULES.md "Fixed points": curve ends, junctions, corners). */
static sdi_vmask vmask_fixed(const sdi_vnb *n)
{
    (void)n;
    return (sdi_vmask){1, 0, 0};
}

/* The cubic B-spline along a curve or a boundary (000 eqs. 13-14 with k = 1): (6x + a + b)/8. */
static sdi_vmask vmask_bspline(const sdi_vnb *n)
{
    (void)n;
    return (sdi_vmask){6.0 / 8.0, 1.0 / 8.0, 0};
}

double sdi_loop_weight(int weights, uint32_t m)
{
    if (weights == SD_WEIGHTS_LOOP) { /* Loop 1987's beta(m) / m (docs/RULES.md) */
        double x = 3.0 / 8.0 + cos(2 * M_PI / m) / 4;
        return (5.0 / 8.0 - x * x) / m;
    }
    return m == 3 ? 3.0 / 16.0 : 3.0 / (8.0 * m); /* Warren's c */
}

/* Loop's vertex rule (000 eq. 16): (1 - m c) x + c sum rho, on a surface or on the boundary
 * surface of a solid (001 Sec. 3.6). */
static sdi_vmask vmask_loop(const sdi_vnb *n)
{
    uint32_t na = n->na;
    double c = na < SDI_LOOP_CACHE ? n->loopc[na] : sdi_loop_weight(n->weights, na);
    return (sdi_vmask){1 - na * c, c, 0};
}

/* The box-spline solid's vertex rule (001 eq. 3.3): 9/16 x + 7/(16k) sum rho; also the 3-simplex
 * rule of G2 on its relieved ring (000 Sec. 3.5). */
static sdi_vmask box_vertex(uint32_t na)
{
    return (sdi_vmask){9.0 / 16.0, 7.0 / (16.0 * na), 0};
}

static sdi_vmask vmask_box(const sdi_vnb *n)
{
    return box_vertex(n->na);
}

/* The solid's vertex rule: the box spline, or the averaged scheme (001 App. A; docs/RULES.md "Averaged scheme"):
 * 9/16 x + 7/16 (3 sum edge neighbours + sum octahedral opposites) / (3 n_e + n_o). */
static sdi_vmask vmask_solid(const sdi_vnb *n)
{
    if (n->scheme != SD_SOLID_AVERAGED)
        return box_vertex(n->na);
    double d = 3.0 * n->na + n->nb;
    return (sdi_vmask){9.0 / 16.0, 7.0 / 16.0 * 3.0 / d, 7.0 / 16.0 / d};
}

/* ---- edge masks ------------------------------------------------------------------------ */

/* The midpoint: curves (000 eq. 14), boundaries, degenerate neighbourhoods. */
static sdi_emask emask_midpoint(const sdi_enb *n)
{
    (void)n;
    return (sdi_emask){{0.5, 0.5}, 0, 0};
}

/* Loop's edge rule (000 eq. 16; Loop 1987): 3/8 (a + b) + 1/8 (c + d); the midpoint without the
 * two opposite vertices. */
static sdi_emask emask_loop(const sdi_enb *n)
{
    if (n->k != 2)
        return emask_midpoint(n);
    return (sdi_emask){{3.0 / 8.0, 3.0 / 8.0}, 1.0 / 8.0, 0};
}

/* The 3-simplex edge rule for a ring of k (001 eqs. 3.4, 3.5, 3.8): k = 6: 10/32, 2/32; k = 4:
 * 8/32, 4/32; else 5/16 (a + b) + 3/(8k) sum ring. */
static sdi_emask box_edge(uint32_t k)
{
    if (k == 6)
        return (sdi_emask){{10.0 / 32.0, 10.0 / 32.0}, 2.0 / 32.0, 0};
    if (k == 4)
        return (sdi_emask){{8.0 / 32.0, 8.0 / 32.0}, 4.0 / 32.0, 0};
    double end = 5.0 / 16.0;
    return (sdi_emask){{end, end}, 3.0 / (8.0 * k), 0};
}

/* The solid's edge rule: the box spline, or the averaged scheme (001 App. A; docs/RULES.md "Averaged scheme"):
 * 7/24 (a + b) + 5/12 (4 sum face-ring + sum diagonal-ring) / (4 n_f + n_d). */
static sdi_emask emask_solid(const sdi_enb *n)
{
    if (!n->cls)
        return box_edge(n->k);
    uint32_t nf = 0, nd = 0;
    for (uint32_t i = 0; i < n->k; i++)
        n->cls[i] ? nd++ : nf++;
    double d = 4.0 * nf + nd;
    return (sdi_emask){{7.0 / 24.0, 7.0 / 24.0}, 5.0 / 12.0 * 4.0 / d, 5.0 / 12.0 / d};
}

/* G2's edge rule (000 Sec. 3.5, Fig. 14): the 3-simplex rule over the common neighbours of its
 * ends; with none, the midpoint. */
static sdi_emask emask_g2(const sdi_enb *n)
{
    return n->k ? box_edge(n->k) : emask_midpoint(n);
}

/* ---- dispatch through the rule table ------------------------------------------------------ */

#define VMASK_OF(id, name, rho, vmask, ring, emask, ...) [id] = vmask_##vmask,
#define EMASK_OF(id, name, rho, vmask, ring, emask, ...) [id] = emask_##emask,
static sdi_vmask (*const vmask_of[SD_RULE_COUNT])(const sdi_vnb *) = {SD_RULE_TABLE(VMASK_OF)};
static sdi_emask (*const emask_of[SD_RULE_COUNT])(const sdi_enb *) = {SD_RULE_TABLE(EMASK_OF)};
#undef VMASK_OF
#undef EMASK_OF

sdi_vmask sdi_vertex_mask(uint8_t rule, const sdi_vnb *n)
{
    return vmask_of[rule](n);
}

sdi_emask sdi_edge_mask(uint8_t rule, const sdi_enb *n)
{
    return emask_of[rule](n);
}

/* ---- cells and Ying-Zorin ------------------------------------------------------------------ */

double sdi_mask_cell(int scheme, int i)
{
    /* 001 eq. 3.6: 1/4 on the major diagonal's ends, 1/8 on the others; averaged: the centroid */
    return scheme == SD_SOLID_AVERAGED ? 1.0 / 6.0 : (i < 2 ? 0.25 : 0.125);
}

double sdi_mask_yz_gamma(double theta)
{
    return 0.5 - cos(theta) / 4; /* 003 Fig. 4f */
}

sdi_yzmask sdi_mask_yz_petal(double g)
{
    /* 003 Fig. 4f: (3/4 - g) v + g w + 1/8 (c + d) */
    return (sdi_yzmask){0.75 - g, g, 1.0 / 8.0};
}

sdi_emask sdi_mask_yz_petal_edge(const sd_yzend end[2])
{
    /* each singular end's rule from its side, averaged where both are (003: "the average of the
     * conflicting positions") */
    double w0 = 0, w1 = 0;
    int sides = 0;
    for (int i = 0; i < 2; i++)
        if (end[i].kind == SD_YZ_FIRST) {
            sdi_yzmask y = sdi_mask_yz_petal(end[i].g);
            w0 += i == 0 ? y.centre : y.far;
            w1 += i == 0 ? y.far : y.centre;
            sides++;
        }
    return (sdi_emask){{w0 / sides, w1 / sides}, 1.0 / 8.0, 0};
}

double sdi_mask_yz_flat(const sd_yzend *x, uint32_t k, uint32_t i, uint32_t j)
{
    /* on q = p - v: (1 - s) T_ij + s P_ij (yz.c's header derives P) */
    const bool open = x->kind == SD_YZ_CONCAVE;
    const double s = x->s, c = 2 * M_PI / k, lam = 3.0 / 8.0 + cos(c) / 4;
    const double d = 2 * sin(k * x->theta);
    bool nb = open ? j == i + 1 || j + 1 == i : j == (i + 1) % k || j == (i + k - 1) % k;
    double tij = j == i ? x->g : nb ? 1.0 / 8.0 : 0.0, pij;
    if (x->kind == SD_YZ_DISK) /* 003 App. A */
        pij = 2.0 / k * lam * cos(c * ((double)i - j));
    else if (x->kind == SD_YZ_DART) /* DECISIONS 28 */
        pij = (j == 0 ? cos(c * i) / 2 : 0) + sin(c * i) * sin(c * j) / k;
    else /* concave corner, DECISIONS 28 */
        pij = ((j == 0 ? sin((k - i) * x->theta) : 0) + (j == k ? sin(i * x->theta) : 0)) / d;
    return (1 - s) * tij + s * pij;
}
