/* buf.h — a growing byte buffer for answers made whole before they are sent (deltas, embedded
 * models): appends that remember a failed allocation instead of checking each one, so a writer
 * tests `failed` once at the end. Blocks are api_malloc'd (the memory budget); the text is kept
 * NUL-terminated. Numbers in JSON are written as the levels' format=json writes them
 * (api/out_json.c: "%.17g"). */
#ifndef SUBDIVD_API_BUF_H
#define SUBDIVD_API_BUF_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef struct api_buf {
    char *b;
    size_t n, cap;
    bool failed;
} api_buf;

void api_buf_put(api_buf *o, const void *x, size_t n);
/* Room for n bytes at once, before the first put (the answer's size is known or guessed). */
void api_buf_reserve(api_buf *o, size_t n);
void api_buf_printf(api_buf *o, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
void api_buf_u32(api_buf *o, uint32_t x);  /* little endian, as the GLB */
void api_buf_f32(api_buf *o, double x);    /* as float32, little endian */
/* n reals as JSON: one number, or [x,y,...] for n > 1. */
void api_buf_reals(api_buf *o, const double *x, int n);

/* The whole of a file (the offline modes' inputs), api_malloc'd and NUL-terminated, *len its
 * bytes; NULL after a line on stderr starting with `who` when it cannot be opened or read, is
 * larger than max bytes, or memory ran out. */
char *api_read_file(const char *who, const char *path, size_t max, size_t *len);

#endif
