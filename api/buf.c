/* buf.c — see buf.h. */
#include "buf.h"
#include "mem.h"
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

void api_buf_put(api_buf *o, const void *x, size_t n)
{
    if (o->failed || (!n && o->b)) /* x may be NULL when n is 0 (an empty delta) */
        return;
    if (o->n + n + 1 > o->cap) {
        size_t cap = o->cap ? o->cap : 4096;
        while (cap < o->n + n + 1)
            cap *= 2;
        char *b = api_realloc(o->b, cap);
        if (!b) {
            o->failed = true;
            return;
        }
        o->b = b;
        o->cap = cap;
    }
    if (n)
        memcpy(o->b + o->n, x, n);
    o->n += n;
    o->b[o->n] = 0;
}

void api_buf_reserve(api_buf *o, size_t n)
{
    if (o->b || !(o->b = api_malloc(n + 1)))
        return;
    o->cap = n + 1;
    o->b[0] = 0;
}

void api_buf_printf(api_buf *o, const char *fmt, ...)
{
    char t[160];
    va_list ap;
    va_start(ap, fmt);
    int k = vsnprintf(t, sizeof t, fmt, ap);
    va_end(ap);
    api_buf_put(o, t, (size_t)(k < 0 ? 0 : k < (int)sizeof t ? k : (int)sizeof t - 1));
}

void api_buf_u32(api_buf *o, uint32_t x)
{
    unsigned char b[4] = {(unsigned char)x, (unsigned char)(x >> 8), (unsigned char)(x >> 16),
                          (unsigned char)(x >> 24)};
    api_buf_put(o, b, 4);
}

void api_buf_f32(api_buf *o, double x)
{
    float f = (float)x;
    uint32_t u;
    memcpy(&u, &f, 4);
    api_buf_u32(o, u);
}

void api_buf_reals(api_buf *o, const double *x, int n)
{
    if (n > 1)
        api_buf_put(o, "[", 1);
    for (int k = 0; k < n; k++)
        api_buf_printf(o, k ? ",%.17g" : "%.17g", x[k]);
    if (n > 1)
        api_buf_put(o, "]", 1);
}

char *api_read_file(const char *who, const char *path, size_t max, size_t *len)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "%s: cannot open %s: %s\n", who, path, strerror(errno));
        return NULL;
    }
    api_buf o = {0};
    char chunk[1 << 16];
    size_t r;
    while (!o.failed && (r = fread(chunk, 1, sizeof chunk, f)) > 0) {
        if (o.n + r > max) {
            fprintf(stderr, "%s: %s is larger than %zu bytes\n", who, path, max);
            fclose(f);
            api_free(o.b);
            return NULL;
        }
        api_buf_put(&o, chunk, r);
    }
    bool bad = ferror(f);
    fclose(f);
    if (bad || o.failed) {
        fprintf(stderr, "%s: %s reading %s\n", who, bad ? "an error" : "out of memory", path);
        api_free(o.b);
        return NULL;
    }
    if (!o.b) /* an empty file: still a string */
        api_buf_put(&o, "", 0);
    if (o.failed) {
        fprintf(stderr, "%s: out of memory reading %s\n", who, path);
        return NULL;
    }
    *len = o.n;
    return o.b;
}
