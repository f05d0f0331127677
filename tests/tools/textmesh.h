/* textmesh.h — reader of the text format of docs/TEXT_FORMAT.md, shared by sdlevel and bench. */
#ifndef SD_TEXTMESH_H
#define SD_TEXTMESH_H
#include <stddef.h>
#include <stdint.h>

typedef struct textmesh {
    double *xyz;       /* 3 per vertex */
    uint32_t *idx;     /* simplex vertex ids, consecutive */
    uint8_t *size;     /* per simplex */
    long *diag;        /* pairs (t, k) of `d` lines */
    uint32_t *crv;     /* `c` lines: 3 vertex ids each (those past crn unused) */
    uint8_t *crn;      /* 1 vertex, 2 edge, 3 triangle */
    double *crs;       /* the sharpness */
    size_t nv, ns, ndiag, ncr;
} textmesh;

/* Read `path` ("-" = stdin). Returns 0, or -1 with a message in err. Free with textmesh_free. */
int textmesh_read(const char *path, textmesh *m, char *err, size_t errlen);
void textmesh_free(textmesh *m);
#endif
