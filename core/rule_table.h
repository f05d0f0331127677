/* rule_table.h — the subdivision rules, one line each (included by sd.h).
 *
 * SD_RULE_TABLE(X) calls X(id, name, vregular, eregular) once per rule, in the order of their
 * numbers: outputs write a rule as its number, so a new rule goes at the end. From it come the
 * enum sd_rule (sd.h), sd_rule_name and the "extraordinary" flag of sd_class (rules.c).
 *   name      the rule as reported (JSON, the web front end's colours, docs/RULES.md)
 *   vregular  the regular sizes of a vertex's rho under the rule, bit k for |rho| = k: any other
 *             size is extraordinary (0: never extraordinary)
 *   eregular  the same for the ring of an edge
 * Some rules are only reported (N1, N2, G1, the Ying-Zorin crease, corner and petal): the
 * vertex or edge computes with another rule of the table (rules.c, sd_reported_*_rule).
 */
#ifndef SD_RULE_TABLE_H
#define SD_RULE_TABLE_H

#define SD_RULE_BIT(k) (1u << (k))

#define SD_RULE_TABLE(X)                                                                         \
    X(SD_RULE_CORNER, "corner", 0, 0)                    /* fixed: 0-mask */                      \
    X(SD_RULE_CURVE, "curve", 0, 0)                      /* cubic B-spline */                     \
    X(SD_RULE_LOOP, "loop", SD_RULE_BIT(6), 0)           /* Loop surface */                       \
    X(SD_RULE_LOOP_BOUNDARY, "loop-boundary", 0, 0)      /* boundary of a surface: cubic          \
                                                          * B-spline along it */                  \
    X(SD_RULE_SOLID, "solid", SD_RULE_BIT(14),           /* box-spline (or averaged) solid */     \
      SD_RULE_BIT(4) | SD_RULE_BIT(6))                                                           \
    X(SD_RULE_SOLID_BOUNDARY, "solid-boundary", SD_RULE_BIT(6), 0) /* boundary of a solid:       \
                                                          * Loop on the boundary surface */       \
    X(SD_RULE_N1, "N1", 0, 0)                            /* per-simplex choices (000 Sec. 3.5) */ \
    X(SD_RULE_N2, "N2", 0, 0)                                                                    \
    X(SD_RULE_G1, "G1", 0, 0)                                                                    \
    X(SD_RULE_G2, "G2", 0, 0)                                                                    \
    X(SD_RULE_YZ_CREASE, "ying-zorin-crease", 0, 0)      /* Ying-Zorin (003): a non-manifold      \
                                                          * edge, or a simple singular vertex:    \
                                                          * cubic B-spline along the singular    \
                                                          * edges */                              \
    X(SD_RULE_YZ_CORNER, "ying-zorin-corner", 0, 0)      /* ... a complex singular vertex: fixed  \
                                                          * (convex corner) */                    \
    X(SD_RULE_YZ_PETAL, "ying-zorin-petal", 0, 0)        /* ... an edge of a petal at a singular  \
                                                          * vertex: the piecewise smooth rule of  \
                                                          * its petal (003 Fig. 4f) */            \
    X(SD_RULE_YZ_FIXED_DISK, "ying-zorin-fixed-disk", 0, 0) /* ... an edge of a closed petal at a \
                                                          * non-manifold vertex: 003's fixed-disk \
                                                          * rule (Loop, then the flatness         \
                                                          * modification) */                      \
    X(SD_RULE_YZ_DART, "ying-zorin-dart", 0, 0)          /* ... an edge of a dart petal at a      \
                                                          * complex singular vertex: the dart     \
                                                          * rule, then the flatness modification */ \
    X(SD_RULE_YZ_CONCAVE, "ying-zorin-concave", 0, 0)    /* ... an edge of a petal tagged a       \
                                                          * concave corner: its rule, then the    \
                                                          * flatness modification */

#endif
