/* errors.h — the problem types of the daemon, one page each at GET /errors/<slug> (the `type`
 * URI of every problem+json answer resolves). The table is generated at build time from the one
 * list of them, docs/SERVICE.md "Errors" (tools/errors.awk -> build/errors.c). */
#ifndef SUBDIVD_ERRORS_H
#define SUBDIVD_ERRORS_H

typedef struct error_page {
    const char *slug;   /* the type is "/errors/" slug */
    int status;
    const char *when;   /* the table's "when" text (Markdown) */
    const char *row;    /* every slug of its row, comma-separated (types that share the text) */
} error_page;

/* Ends with a zeroed entry. */
extern const error_page error_pages[];

#endif
