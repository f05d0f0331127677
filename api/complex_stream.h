/* complex_stream.h — GET /complex streamed in bounded memory (complex_stream.c). */
#ifndef SUBDIVD_COMPLEX_STREAM_H
#define SUBDIVD_COMPLEX_STREAM_H

#include "model.h"
#include <stddef.h>

typedef struct api_cstream api_cstream;

/* A stream of m's GET /complex document. The caller holds m's data lock for reading during
 * this call (positions and attributes are copied here) and keeps a reference on m until
 * api_cstream_free. `tail` (an api_malloc block, taken over even on failure) is the text that
 * ends the document after the classes: ,"tags":…,"rules":…,"summary":…,"version":…}. NULL for
 * lack of memory. */
api_cstream *api_cstream_new(const api_model *m, char *tail, size_t tail_len);
/* Up to max bytes of the document into out; 0 at its end. */
size_t api_cstream_read(api_cstream *s, char *out, size_t max);
void api_cstream_free(api_cstream *s);

#endif
