/* complex_stream.c — GET /complex as a stream: the same bytes as json_dumps(JSON_COMPACT) of
 * the whole document, without the document.
 *
 * A complex of a million points is some 60 MB of JSON points and simplices, and several hundred
 * MB with the classes of its vertices and edges; as a jansson tree it took 1.4 GB and 25 s per
 * request. Here the big arrays (vertices, simplices, attributes, diagonals, reoriented tetrahedra, the classes of
 * vertices and edges) are written element by element into a 64 KiB buffer as the client reads,
 * and only the small members (tags, rules, summary) go through jansson, as a prepared text.
 * Positions and attributes are copied when the stream opens (edits change them in place), so
 * the stream holds no lock while the client reads, and its content is that of one version.
 * Numbers are formatted as jansson does (jsonp_dtostr: "%.17g", ".0" appended to integral
 * values, the exponent without '+' or leading zeros), so a client cannot tell the two apart.
 */
#include "complex_stream.h"
#include "mem.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CS_BUF (64 * 1024)
#define CS_ROW_MAX 1024 /* the longest element: an attribute row of 16 reals */

enum { S_VERTICES, S_SIMPLICES, S_ATTR, S_DIAG, S_REOR, S_VCLASS, S_ECLASS, S_TAIL, S_END };

struct api_cstream {
    const api_model *m;
    double *xyz;                      /* copies, taken under the data lock */
    double *adata[API_MAX_ATTRIBUTES];
    int nattrs;
    uint32_t nv, ns, ne;
    const uint32_t *ev;
    char *tail;                       /* ,"tags":…,"rules":…,"summary":…,"version":…} */
    size_t tail_len, tail_at;
    int section, attr;                /* where the writer is */
    size_t item, off;                 /* element within the section; simplex index offset */
    char buf[CS_BUF];
    size_t len, at;                   /* buf[at, len) not yet read */
};

/* jansson's rendering of a real (jsonp_dtostr with precision 17). */
static int put_real(char *out, double v)
{
    int n = snprintf(out, 32, "%.17g", v);
    if (!strchr(out, '.') && !strchr(out, 'e')) {
        out[n++] = '.';
        out[n++] = '0';
        out[n] = 0;
    }
    char *e = strchr(out, 'e');
    if (e) {
        char *start = e + 1, *end = start + 1;
        if (*start == '-')
            start++;
        while (*end == '0')
            end++;
        if (end != start) {
            memmove(start, end, (size_t)(out + n - end) + 1);
            n -= (int)(end - start);
        }
    }
    return n;
}

static size_t put_reals(char *o, const double *v, int n)
{
    size_t k = 0;
    o[k++] = '[';
    for (int i = 0; i < n; i++) {
        if (i)
            o[k++] = ',';
        k += (size_t)put_real(o + k, v[i]);
    }
    o[k++] = ']';
    return k;
}

static size_t put_class(char *o, const sd_class *c, int singular)
{
    size_t k = (size_t)sprintf(o, "{\"family\":[");
    int first = 1;
    for (int d = 0; d < 4; d++)
        if (c->family & (1u << d)) {
            k += (size_t)sprintf(o + k, first ? "%d" : ",%d", d);
            first = 0;
        }
    k += (size_t)sprintf(o + k,
                         "],\"boundary\":%s,\"nonmanifold\":%d,\"singular\":%s,\"rule\":\"%s\","
                         "\"valence\":%d,\"extraordinary\":%s",
                         c->boundary ? "true" : "false", c->nonmanifold, singular ? "true" : "false",
                         sd_rule_name((sd_rule)c->rule), (int)c->valence,
                         c->extraordinary ? "true" : "false");
    return k;
}

/* One element of the current section into o (at most CS_ROW_MAX bytes, a leading comma
 * included); 0 when the section is over. */
static size_t element(api_cstream *s, char *o)
{
    const api_input *in = s->m->in;
    size_t k = 0, i = s->item;
    if (i)
        o[k++] = ',';
    sd_class c;
    switch (s->section) {
    case S_VERTICES:
        if (i >= s->nv)
            return 0;
        return k + put_reals(o + k, s->xyz + 3 * i, 3);
    case S_SIMPLICES:
        if (i >= s->ns)
            return 0;
        o[k++] = '[';
        for (int j = 0; j < in->size[i]; j++)
            k += (size_t)sprintf(o + k, j ? ",%u" : "%u", in->idx[s->off++]);
        o[k++] = ']';
        return k;
    case S_ATTR: {
        const api_attribute *t = &in->attrs[s->attr];
        if (i >= s->nv)
            return 0;
        const double *v = s->adata[s->attr] + i * (size_t)t->ncomp;
        if (t->scalar_form)
            return k + (size_t)put_real(o + k, v[0]);
        return k + put_reals(o + k, v, t->ncomp);
    }
    case S_DIAG:
        while (s->off < s->ns && in->size[s->off] != 4)
            s->off++;
        if (s->off >= s->ns)
            return 0;
        k += (size_t)sprintf(o + k, "[%zu,%d]", s->off, sd_complex_diagonal(s->m->c, s->off));
        s->off++;
        return k;
    case S_REOR:
        while (s->off < s->ns && sd_complex_reoriented(s->m->c, s->off) != 1)
            s->off++;
        if (s->off >= s->ns)
            return 0;
        k += (size_t)sprintf(o + k, "%zu", s->off);
        s->off++;
        return k;
    case S_VCLASS:
        for (; s->off < s->nv; s->off++)
            if (!sd_level_vertex_class(s->m->level0, (uint32_t)s->off, &c)) {
                k += put_class(o + k, &c, sd_level_vertex_singular(s->m->level0, (uint32_t)s->off));
                o[k++] = '}';
                s->off++;
                return k;
            }
        return 0;
    case S_ECLASS:
        for (; s->off < s->ne; s->off++)
            if (!sd_level_edge_class(s->m->level0, (uint32_t)s->off, &c)) {
                uint32_t e = (uint32_t)s->off;
                k += put_class(o + k, &c, sd_level_edge_singular(s->m->level0, e));
                k += (size_t)sprintf(o + k, ",\"vertices\":[%u,%u]}", s->ev[2 * e], s->ev[2 * e + 1]);
                s->off++;
                return k;
            }
        return 0;
    default:
        return 0;
    }
}

/* The text between sections: before section `next` begins (after the previous one ended). */
static const char *opening(const api_cstream *s, int next)
{
    switch (next) {
    case S_VERTICES:
        return "{\"vertices\":[";
    case S_SIMPLICES:
        return "],\"simplices\":[";
    case S_ATTR:
        return "],\"attributes\":{";
    case S_DIAG:
        return s->nattrs ? "]},\"diagonals\":[" : "},\"diagonals\":[";
    case S_REOR:
        return "],\"reoriented\":[";
    case S_VCLASS:
        return "],\"classes\":{\"vertices\":[";
    case S_ECLASS:
        return "],\"edges\":[";
    default:
        return "]}";
    }
}

static void fill(api_cstream *s)
{
    s->len = s->at = 0;
    while (s->section < S_TAIL && s->len + CS_ROW_MAX + 128 < CS_BUF) {
        size_t n = element(s, s->buf + s->len);
        if (n) {
            s->len += n;
            s->item++;
            continue;
        }
        /* the section (or one attribute) is over */
        if (s->section == S_ATTR && s->attr + 1 < s->nattrs) {
            s->attr++;
            s->item = 0;
            s->len += (size_t)sprintf(s->buf + s->len, "],\"%s\":[", s->m->in->attrs[s->attr].name);
            continue;
        }
        int next = s->section + 1;
        if (next == S_ATTR && !s->nattrs) { /* "attributes":{} */
            const char *t = opening(s, S_ATTR);
            memcpy(s->buf + s->len, t, strlen(t));
            s->len += strlen(t);
            next = S_DIAG;
        }
        const char *t = opening(s, next);
        memcpy(s->buf + s->len, t, strlen(t));
        s->len += strlen(t);
        if (next == S_ATTR)
            s->len += (size_t)sprintf(s->buf + s->len, "\"%s\":[", s->m->in->attrs[0].name);
        s->section = next;
        s->item = s->off = 0;
        s->attr = 0;
    }
}

api_cstream *api_cstream_new(const api_model *m, char *tail, size_t tail_len)
{
    const api_input *in = m->in;
    api_cstream *s = api_calloc(1, sizeof *s);
    if (!s) {
        api_free(tail);
        return NULL;
    }
    s->tail = tail;
    s->tail_len = tail_len;
    s->m = m;
    s->nv = in->nv;
    s->ns = in->ns;
    s->nattrs = in->nattrs;
    s->xyz = api_malloc((size_t)in->nv * 3 * sizeof *s->xyz + 1);
    int ok = s->xyz != NULL;
    for (int a = 0; ok && a < in->nattrs; a++)
        ok = (s->adata[a] = api_malloc((size_t)in->nv * in->attrs[a].ncomp * sizeof(double) + 1)) != NULL;
    if (!ok) {
        api_cstream_free(s);
        return NULL;
    }
    memcpy(s->xyz, in->xyz, (size_t)in->nv * 3 * sizeof *s->xyz);
    for (int a = 0; a < in->nattrs; a++)
        memcpy(s->adata[a], in->attrs[a].data, (size_t)in->nv * in->attrs[a].ncomp * sizeof(double));
    s->ev = sd_level_edges(m->level0, &s->ne);
    s->section = S_VERTICES;
    memcpy(s->buf, "{\"vertices\":[", 13);
    s->len = 13;
    return s;
}

size_t api_cstream_read(api_cstream *s, char *out, size_t max)
{
    size_t done = 0;
    while (done < max) {
        if (s->at == s->len) {
            if (s->section < S_TAIL)
                fill(s);
            if (s->at == s->len) {
                if (s->section == S_TAIL && s->tail_at < s->tail_len) {
                    size_t n = s->tail_len - s->tail_at < max - done ? s->tail_len - s->tail_at
                                                                      : max - done;
                    memcpy(out + done, s->tail + s->tail_at, n);
                    s->tail_at += n;
                    done += n;
                    continue;
                }
                break;
            }
        }
        size_t n = s->len - s->at < max - done ? s->len - s->at : max - done;
        memcpy(out + done, s->buf + s->at, n);
        s->at += n;
        done += n;
    }
    return done;
}

void api_cstream_free(api_cstream *s)
{
    if (!s)
        return;
    api_free(s->xyz);
    for (int a = 0; a < API_MAX_ATTRIBUTES; a++)
        api_free(s->adata[a]);
    api_free(s->tail);
    api_free(s);
}
