/* repair.c — PUT /complex {"repair": true} (docs/API.md "Control complex", DECISIONS 41): the
 * posted simplices the core would refuse one at a time — a vertex twice ("repeated-vertex"),
 * zero or near-zero length, area or volume by the core's own tolerance ("degenerate"), the
 * vertices of an earlier kept simplex in any order ("duplicate", e.g. an OBJ's two faces on the
 * same three vertices) — are dropped before the model is built; the rest keep their order.
 *
 * The test is the core's (sd_complex_check: the validation pass of sd_complex_new recording
 * instead of failing), so a repaired complex is exactly one the core accepts, and what the core
 * refuses as a whole (a coordinate, an index out of range, no simplices) stays a 422 with or
 * without repair. The input then holds the repaired simplices: GET /complex, the export and the
 * store see the cleaned complex, which posted again without "repair" builds the same levels.
 * Diagonals name posted simplices: they are renumbered, and those of dropped simplices ignored
 * and listed. The report (at most API_MAX_REPAIRED_LISTED entries of each list, all counted) is
 * kept with the input for the summary.
 */
#include "repair.h"
#include "mem.h"
#include <stdio.h>
#include <string.h>

static const char *reason_name(uint8_t why)
{
    return why == SD_ERR_REPEATED ? "repeated-vertex" : why == SD_ERR_DEGENERATE ? "degenerate"
                                                                                  : "duplicate";
}

/* Drop what sd_complex_check names from in's simplices (in place), renumber the diagonals and
 * reoriented flags, and record the report in in->repaired. */
static int compact(api_input *in, const uint8_t *why, const uint32_t *of, uint32_t *to,
                   api_problem *p)
{
    json_t *dropped = json_array(), *ignored = json_array();
    uint32_t count = 0, kept = 0, nign = 0;
    size_t src = 0, dst = 0;
    for (uint32_t s = 0; s < in->ns; src += in->size[s++]) {
        uint8_t k = in->size[s];
        if (why[s]) {
            to[s] = UINT32_MAX;
            if (count++ < API_MAX_REPAIRED_LISTED) {
                json_t *d = json_pack("{s:I, s:s}", "index", (json_int_t)s, "reason",
                                      reason_name(why[s]));
                if (why[s] == SD_ERR_DUPLICATE && d)
                    json_object_set_new(d, "of", json_integer((json_int_t)of[s]));
                json_array_append_new(dropped, d);
            }
            continue;
        }
        to[s] = kept;
        memmove(in->idx + dst, in->idx + src, k * sizeof *in->idx);
        in->size[kept] = k;
        if (in->reoriented)
            in->reoriented[kept] = in->reoriented[s];
        kept++;
        dst += k;
    }
    in->ns = kept;
    uint32_t nd = 0;
    for (uint32_t i = 0; i < in->ndiag; i++) {
        uint32_t s = to[in->diag[i][0]];
        if (s == UINT32_MAX) {
            if (nign++ < API_MAX_REPAIRED_LISTED) {
                char at[64];
                snprintf(at, sizeof at, "/diagonals/%u", i);
                json_array_append_new(ignored, json_string(at));
            }
            continue;
        }
        in->diag[nd][0] = s;
        in->diag[nd++][1] = in->diag[i][1];
    }
    in->ndiag = nd;
    in->repaired = json_pack("{s:o, s:I, s:o, s:I}", "dropped", dropped, "count",
                             (json_int_t)count, "ignored", ignored, "ignored_count",
                             (json_int_t)nign);
    return in->repaired ? 0 : api_fail(p, 503, "out-of-memory", "out of memory");
}

int api_repair(api_input *in, api_problem *p)
{
    size_t ns = in->ns;
    uint8_t *why = api_malloc(ns + 1);
    uint32_t *of = api_malloc((ns + 1) * sizeof *of), *to = api_malloc((ns + 1) * sizeof *to);
    int rc = 0;
    if (!why || !of || !to)
        rc = api_fail(p, 503, "out-of-memory", "out of memory repairing %zu simplices", ns);
    sd_allocator a = api_mem_core_allocator();
    sd_error e = {0};
    sd_result r = rc ? SD_OK
                     : sd_complex_check(in->xyz, in->nv, in->idx, in->size, ns, &a, why, of, &e);
    if (r == SD_ERR_NOMEM)
        rc = api_fail(p, 503, "out-of-memory", "out of memory repairing %zu simplices", ns);
    else if (!rc && r == SD_OK)
        rc = compact(in, why, of, to, p);
    /* any other refusal is the complex's as a whole: the build answers it as without repair */
    api_free(why);
    api_free(of);
    api_free(to);
    return rc;
}

void api_repair_summary(const api_input *in, json_t *summary)
{
    if (!in || !in->repaired || !summary)
        return;
    json_t *r = in->repaired;
    json_object_set(summary, "repaired", json_object_get(r, "dropped"));
    json_object_set(summary, "repaired_count", json_object_get(r, "count"));
    if (json_integer_value(json_object_get(r, "ignored_count"))) {
        json_object_set(summary, "repaired_ignored", json_object_get(r, "ignored"));
        json_object_set(summary, "repaired_ignored_count", json_object_get(r, "ignored_count"));
    }
}
