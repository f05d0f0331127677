/* textmesh.c — see textmesh.h. */
#define _POSIX_C_SOURCE 200809L
#include "textmesh.h"
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int grow(void **p, size_t *cap, size_t need, size_t elt)
{
    if (need <= *cap)
        return 0;
    size_t c = *cap ? *cap : 64;
    while (c < need)
        c *= 2;
    void *q = realloc(*p, c * elt);
    if (!q)
        return -1;
    *p = q;
    *cap = c;
    return 0;
}

int textmesh_read(const char *path, textmesh *m, char *err, size_t errlen)
{
    memset(m, 0, sizeof *m);
    FILE *f = strcmp(path, "-") ? fopen(path, "r") : stdin;
    if (!f) {
        snprintf(err, errlen, "%s: %s", path, strerror(errno));
        return -1;
    }
    size_t cx = 0, ci = 0, cs = 0, cd = 0, ni = 0, cc1 = 0, cc2 = 0, cc3 = 0;
    char line[4096];
    long lineno = 0;
    while (fgets(line, sizeof line, f)) {
        lineno++;
        char *p = line;
        while (*p == ' ' || *p == '\t')
            p++;
        if (*p == '#' || *p == '\n' || *p == '\r' || *p == 0)
            continue;
        int ok = 0;
        if (p[0] == 'v' && (p[1] == ' ' || p[1] == '\t')) {
            double x, y, z;
            if (sscanf(p + 1, "%lf %lf %lf", &x, &y, &z) == 3 &&
                !grow((void **)&m->xyz, &cx, 3 * (m->nv + 1), sizeof *m->xyz)) {
                m->xyz[3 * m->nv] = x, m->xyz[3 * m->nv + 1] = y, m->xyz[3 * m->nv + 2] = z;
                m->nv++;
                ok = 1;
            }
        } else if (p[0] == 's' && (p[1] == ' ' || p[1] == '\t')) {
            char *q = p + 1, *end;
            int n = 0;
            ok = 1;
            for (;;) {
                long v = strtol(q, &end, 10);
                if (end == q)
                    break;
                if (v < 0 || v > (long)UINT32_MAX || grow((void **)&m->idx, &ci, ni + 1, sizeof *m->idx)) {
                    ok = 0;
                    break;
                }
                m->idx[ni++] = (uint32_t)v;
                n++;
                q = end;
            }
            if (ok && (n == 0 || n > 255 || grow((void **)&m->size, &cs, m->ns + 1, 1)))
                ok = 0;
            if (ok)
                m->size[m->ns++] = (uint8_t)n;
        } else if (p[0] == 'd' && (p[1] == ' ' || p[1] == '\t')) {
            long t, k;
            if (sscanf(p + 1, "%ld %ld", &t, &k) == 2 &&
                !grow((void **)&m->diag, &cd, 2 * (m->ndiag + 1), sizeof *m->diag)) {
                m->diag[2 * m->ndiag] = t, m->diag[2 * m->ndiag + 1] = k;
                m->ndiag++;
                ok = 1;
            }
        } else if (p[0] == 'c' && (p[1] == ' ' || p[1] == '\t')) {
            /* c i S (vertex), c i j S (edge) or c i j k S (triangle): ids, then the sharpness */
            double x[4];
            int n = 0;
            char *q = p + 1, *end;
            while (n < 4) {
                double d = strtod(q, &end);
                if (end == q)
                    break;
                x[n++] = d;
                q = end;
            }
            while (*q == ' ' || *q == '\t' || *q == '\n' || *q == '\r')
                q++;
            int ids_ok = n >= 2 && !*q;
            for (int k = 0; k + 1 < n; k++)
                ids_ok &= x[k] >= 0 && x[k] <= UINT32_MAX;
            if (ids_ok && !grow((void **)&m->crv, &cc1, 3 * (m->ncr + 1), sizeof *m->crv) &&
                !grow((void **)&m->crn, &cc2, m->ncr + 1, 1) &&
                !grow((void **)&m->crs, &cc3, m->ncr + 1, sizeof *m->crs)) {
                for (int k = 0; k < 3; k++)
                    m->crv[3 * m->ncr + k] = k + 1 < n ? (uint32_t)x[k] : 0;
                m->crn[m->ncr] = (uint8_t)(n - 1);
                m->crs[m->ncr++] = x[n - 1];
                ok = 1;
            }
        }
        if (!ok) {
            snprintf(err, errlen, "%s:%ld: cannot parse line", path, lineno);
            if (f != stdin)
                fclose(f);
            textmesh_free(m);
            return -1;
        }
    }
    if (f != stdin)
        fclose(f);
    return 0;
}

void textmesh_free(textmesh *m)
{
    free(m->xyz);
    free(m->idx);
    free(m->size);
    free(m->diag);
    free(m->crv);
    free(m->crn);
    free(m->crs);
    memset(m, 0, sizeof *m);
}
