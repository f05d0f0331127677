/* error.c — filling the caller's sd_error, and the names of result codes. */
#include "internal.h"
#include <stdarg.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

const char *sd_shortest(double x, char out[32])
{
    for (int prec = 6; prec <= 17; prec++) {
        snprintf(out, 32, "%.*g", prec, x);
        if (!isfinite(x) || strtod(out, NULL) == x)
            break;
    }
    return out;
}

sd_result sdi_fail(sd_error *err, sd_result code, long item, int field, const char *fmt, ...)
{
    if (err) {
        err->code = code;
        err->item = item;
        err->field = field;
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err->message, sizeof err->message, fmt, ap);
        va_end(ap);
    }
    return code;
}

sd_result sdi_fail_nomem(sd_error *err, const sd_mem *m)
{
    if (m->failed_limit)
        return sdi_fail(err, SD_ERR_LIMIT, -1, -1,
                       "memory limit of %zu bytes reached (%zu in use)", m->limit, m->used);
    return sdi_fail(err, SD_ERR_NOMEM, -1, -1, "out of memory (%zu bytes in use)", m->used);
}

const char *sd_result_name(sd_result r)
{
    static const char *const names[] = {
        "ok", "out-of-memory", "limit", "empty", "value", "arity", "index",
        "repeated-vertex", "duplicate-simplex", "degenerate-simplex", "argument",
    };
    return (unsigned)r < sizeof names / sizeof *names ? names[r] : "unknown";
}
