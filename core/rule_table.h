/* rule_table.h — the subdivision rules, one line each (included by sd.h).
 *
 * SD_RULE_TABLE(X) calls X(id, name, rho, vmask, ring, emask, vregular, eregular) once per rule,
 * in the order of their numbers (outputs write a rule as its number, so a new rule goes at the
 * end). It makes the enum sd_rule (sd.h), sd_rule_name and the "extraordinary" flag of sd_class
 * (core/rules.c), and tells the core how to compute the rule:
 *   name      the rule as reported (JSON, the web front end's colours, docs/RULES.md)
 *   rho       the edges through which a vertex following it reads its neighbours (core/rings.c):
 *             CURVE (curve segments), SURFACE (edges of triangles), SURFACE_BOUNDARY (edges of one
 *             triangle only), SOLID (edges of solids), SOLID_BOUNDARY (their boundary's edges), G2
 *             (every edge and major diagonal, relieved: 000 Fig. 14), NONE
 *   vmask     its vertex mask, core/masks.c's vmask_<vmask> (weights of the centre and of rho)
 *   ring      the ring of an edge following it (core/rings.c): NONE (its two ends only),
 *             OPPOSITE (the far vertices of its two triangles), BOUNDARY_OPPOSITE (of its two
 *             faces on the solids' boundary), SOLID (001 Sec. 3's rho(e)), G2 (the common
 *             neighbours of its ends), FLAT (a Ying-Zorin row of core/yz.c)
 *   emask     its edge mask, core/masks.c's emask_<emask> (weights of the ends and of the ring)
 *   vregular  the regular sizes of a vertex's rho under it, bit k for |rho| = k: any other size is
 *             extraordinary (0: never)
 *   eregular  the same for the ring of an edge
 * Some rules are only reported, never computed (N1, N2, G1, the Ying-Zorin crease, corner and
 * petal): the vertex or edge follows another rule of the table (core/rules.c,
 * sdi_reported_*_rule), so their masks are never asked for.
 */
#ifndef SD_RULE_TABLE_H
#define SD_RULE_TABLE_H

#define SD_RULE_BIT(k) (1u << (k))

/* clang-format off */
#define SD_RULE_TABLE(X)                                                                          \
    /* the rules of one dimension (000 Sec. 3; 001 Sec. 3) */                                    \
    X(SD_RULE_CORNER,         "corner",         NONE,             fixed,   NONE,              midpoint, 0, 0) \
    X(SD_RULE_CURVE,          "curve",          CURVE,            bspline, NONE,              midpoint, 0, 0) \
    X(SD_RULE_LOOP,           "loop",           SURFACE,          loop,    OPPOSITE,          loop,     SD_RULE_BIT(6), 0) \
    X(SD_RULE_LOOP_BOUNDARY,  "loop-boundary",  SURFACE_BOUNDARY, bspline, NONE,              midpoint, 0, 0) \
    X(SD_RULE_SOLID,          "solid",          SOLID,            solid,   SOLID,             solid,    SD_RULE_BIT(14), SD_RULE_BIT(4) | SD_RULE_BIT(6)) \
    X(SD_RULE_SOLID_BOUNDARY, "solid-boundary", SOLID_BOUNDARY,   loop,    BOUNDARY_OPPOSITE, loop,     SD_RULE_BIT(6), 0) \
    /* per-simplex non-manifold rules (000 Sec. 3.5): N1, N2 and G1 are reported only */         \
    X(SD_RULE_N1,             "N1",             NONE,             fixed,   NONE,              midpoint, 0, 0) \
    X(SD_RULE_N2,             "N2",             NONE,             fixed,   NONE,              midpoint, 0, 0) \
    X(SD_RULE_G1,             "G1",             NONE,             fixed,   NONE,              midpoint, 0, 0) \
    X(SD_RULE_G2,             "G2",             G2,               box,     G2,                g2,       0, 0) \
    /* Ying-Zorin (003 Sec. 2): reported for non-manifold edges and simple singular vertices     \
     * (crease: cubic B-spline along the singular edges), complex singular vertices (corner:     \
     * fixed) and edges of petals at singular vertices (petal: 003 Fig. 4f); computed for edges  \
     * of closed petals (fixed disk), darts and concave corners at fixed vertices (the first     \
     * stage, then the flatness modification) */                                                 \
    X(SD_RULE_YZ_CREASE,      "ying-zorin-crease",     NONE, fixed, NONE, midpoint, 0, 0)        \
    X(SD_RULE_YZ_CORNER,      "ying-zorin-corner",     NONE, fixed, NONE, midpoint, 0, 0)        \
    X(SD_RULE_YZ_PETAL,       "ying-zorin-petal",      NONE, fixed, NONE, midpoint, 0, 0)        \
    X(SD_RULE_YZ_FIXED_DISK,  "ying-zorin-fixed-disk", NONE, fixed, FLAT, midpoint, 0, 0)        \
    X(SD_RULE_YZ_DART,        "ying-zorin-dart",       NONE, fixed, FLAT, midpoint, 0, 0)        \
    X(SD_RULE_YZ_CONCAVE,     "ying-zorin-concave",    NONE, fixed, FLAT, midpoint, 0, 0)
/* clang-format on */

#endif
