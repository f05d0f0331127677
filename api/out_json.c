/* out_json.c — the `json` format of docs/API.md, generated section by section.
 *
 * {"level","version","vertices":[[x,y,z]…],"cells":{"points","edges","triangles","tetrahedra",
 *  "octahedra"},"attributes":{name:[…]},"rules":[name…],"origin":{"vertex_of","edge_of",
 *  "cell_of"}[,"slice":{"vertices","triangles"}]}
 * Numbers are printed with 17 significant digits, so doubles round-trip exactly. At level 0
 * every vertex is its own origin: vertex_of[i] = i, edge_of[i] = null, cell_of[i] = -1.
 * The size is not known in advance (chunked transfer over HTTP).
 *
 * The document is a list of sections, each an opening string, `count` items separated by
 * commas, and a closing string; the generator resumes inside a section at any item.
 */
#include "out_internal.h"
#include "mem.h"
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ROOM(s) ((s)->len < OUT_BUF_CAP / 2)

typedef enum { K_VERT, K_CELL, K_ATTR, K_RULE, K_VOF, K_EOF, K_COF, K_SV, K_ST } kind;

/* Sections (out_section): id a kind, arg the cell kind or attribute, head the opening text,
 * tail the closing one; items are separated by commas. */
typedef out_section section;

typedef struct jstate {
    bool opened;
    out_sections sec;
} jstate;

static void num(out_stream *s, double x)
{
    if (isfinite(x))
        out_printf(s, "%.17g", x);
    else /* JSON has no NaN or infinity (the core refuses them in input; never invalid JSON) */
        out_put(s, "null", 4);
}

static void vec(out_stream *s, const double *x, int n)
{
    out_put(s, "[", 1);
    for (int k = 0; k < n; k++) {
        if (k)
            out_put(s, ",", 1);
        num(s, x[k]);
    }
    out_put(s, "]", 1);
}

static void item(out_stream *s, const section *c, uint64_t i)
{
    uint32_t v[6], a, b;
    switch (c->id) {
    case K_VERT: vec(s, s->xyz + 3 * i, 3); break;
    case K_CELL: {
        sd_cell_kind k = (sd_cell_kind)c->arg;
        sd_level_cell(s->lv, k, (uint32_t)i, v);
        if (k == SD_CELL_POINT) {
            out_printf(s, "%u", v[0]);
            break;
        }
        out_put(s, "[", 1);
        for (int j = 0; j < sd_cell_size(k); j++)
            out_printf(s, j ? ",%u" : "%u", v[j]);
        out_put(s, "]", 1);
        break;
    }
    case K_ATTR: {
        int nc = s->rq.attrs[c->arg].ncomp;
        const double *x = s->attr[c->arg] + i * nc;
        nc == 1 ? num(s, *x) : vec(s, x, nc);
        break;
    }
    case K_RULE: out_printf(s, "\"%s\"", sd_rule_name(sd_level_vertex_rule(s->lv, (uint32_t)i))); break;
    case K_VOF:
    case K_EOF:
    case K_COF: {
        sd_origin_kind o = sd_level_origin(s->lv, (uint32_t)i, &a, &b);
        if (c->id == K_VOF)
            out_printf(s, "%ld", o == SD_ORIGIN_VERTEX || o == SD_ORIGIN_INPUT ? (long)a : -1L);
        else if (c->id == K_EOF)
            o == SD_ORIGIN_EDGE ? out_printf(s, "[%u,%u]", a, b) : out_printf(s, "null");
        else
            out_printf(s, "%ld", o == SD_ORIGIN_CELL ? (long)a : -1L);
        break;
    }
    case K_SV: vec(s, s->slice.xyz + 3 * i, 3); break;
    case K_ST:
        out_printf(s, "[%llu,%llu,%llu]", (unsigned long long)(3 * i),
                   (unsigned long long)(3 * i + 1), (unsigned long long)(3 * i + 2));
        break;
    }
}

static int produce(out_stream *s)
{
    jstate *j = s->fmt_state;
    while (ROOM(s) && s->section < j->sec.n) {
        section *c = &j->sec.s[s->section];
        if (!j->opened) {
            out_printf(s, "%s", c->head);
            j->opened = true;
        }
        uint64_t i = s->item;
        for (; i < c->count && ROOM(s); i++) {
            if (i)
                out_put(s, ",", 1);
            item(s, c, i);
        }
        s->item = i;
        if (i < c->count)
            return 1;
        out_printf(s, "%s", c->tail);
        s->section++;
        s->item = 0;
        j->opened = false;
    }
    return s->section < j->sec.n;
}

static section *add(jstate *j, kind k, int arg, uint64_t count, const char *close, const char *fmt,
                    ...) __attribute__((format(printf, 6, 7)));
static section *add(jstate *j, kind k, int arg, uint64_t count, const char *close, const char *fmt,
                    ...)
{
    section *c = out_section_add(&j->sec, k, arg, 0, 0, count);
    c->tail = close;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(c->head, sizeof c->head, fmt, ap);
    va_end(ap);
    return c;
}

int out_json_init(out_stream *s, sd_error *err)
{
    jstate *j = out_state_new(s, sizeof *j, api_free, produce);
    if (!j)
        return out_nomem(err);
    static const char *const cell_names[] = {"points", "edges", "triangles", "tetrahedra", "octahedra"};
    add(j, K_VERT, 0, s->nv, "]", "{\"level\":%d,\"version\":%llu,\"vertices\":[", s->rq.level,
        (unsigned long long)s->rq.version);
    for (int k = 0; k < 5; k++)
        add(j, K_CELL, k, s->ncells[k], k == 4 ? "]}" : "]", "%s\"%s\":[", k ? "," : ",\"cells\":{",
            cell_names[k]);
    for (int a = 0; a < s->rq.nattrs; a++)
        add(j, K_ATTR, a, s->nv, "]", "%s\"%s\":[", a ? "," : ",\"attributes\":{",
            s->rq.attrs[a].name);
    if (!s->rq.nattrs)
        add(j, K_VERT, 0, 0, "", ",\"attributes\":{");
    add(j, K_RULE, 0, s->nv, "]", "},\"rules\":[");
    add(j, K_VOF, 0, s->nv, "]", ",\"origin\":{\"vertex_of\":[");
    add(j, K_EOF, 0, s->nv, "]", ",\"edge_of\":[");
    add(j, K_COF, 0, s->nv, "]}", ",\"cell_of\":[");
    if (s->rq.has_slice) {
        add(j, K_SV, 0, 3ull * s->slice.ntri, "]", ",\"slice\":{\"vertices\":[");
        add(j, K_ST, 0, s->slice.ntri, "]}", ",\"triangles\":[");
    }
    add(j, K_VERT, 0, 0, "}", "%s", "");
    s->size = UINT64_MAX;
    return 0;
}
