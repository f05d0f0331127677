/* faults — every allocation of the api/ request path failed in turn (api_mem_fail_at, api/mem.h).
 *
 * One scenario runs the entry points a session goes through — parse a body, PUT complex (and a
 * repaired one apart), rules and tags (with a crease angle), open and drain level 1 in every
 * format (with a slice in some), stats, GET complex, an edit (a level-1 move among them) and its
 * deltas, an analysis, a matrix, a refinement — and frees everything. It runs first with no
 * failure, to count, then once for each n with the nth allocation failing, then with every kth
 * failing for a few k. The inputs are valid, so a call may only succeed or refuse with a 5xx
 * problem (a json_t answer may instead be NULL with no problem: the transport answers that with a
 * 500); after each run the bytes in use must be back where they started (api_mem_in_use: a leak of
 * a counted block fails here, under any build; make sanitize adds ASan's leak check for the rest).
 * A last check: a per-thread meter with a limit refuses a body's parse with a 503.
 * usage: api_faults [MAX_N]   (0 or absent: every n up to the scenario's allocation count)
 * Prints one line "api_faults: N runs, F failures injected, no leaks" and exits 0, else 1.
 */
#include "../../api/delta.h"
#include "../../api/embedded.h"
#include "../../api/handlers.h"
#include "../../api/jsonin.h"
#include "../../api/mem.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char COMPLEX[] =
    "{\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[0,0,1],[1,1,0],[0,0,2],[0.5,0,3],[3,3,3]],"
    "\"simplices\":[[0,1,2,3],[1,2,4],[3,5],[5,6],[7]],\"attributes\":{\"h\":[0,0,0,1,0,2,3,3],"
    "\"v\":[[0,1],[1,1],[2,1],[3,1],[4,1],[5,1],[6,1],[7,1]]}}";
static const char RULES[] = "{\"solid_scheme\":\"averaged\",\"overrides\":[{\"simplex\":[1],"
                            "\"rule\":\"G1\"},{\"simplex\":[1,2],\"rule\":\"N1\",\"dimension\":2}]}";
static const char RULES0[] = "{\"solid_scheme\":\"averaged\",\"nonmanifold_default\":\"G1\"}";
static const char TAGS[] = "{\"singular\":[[5],[1,4]],\"crease_angle\":10}";
/* a repair (api/repair.c): a duplicate tetrahedron with a diagonal, a repeated vertex */
static const char REPAIR[] =
    "{\"vertices\":[[0,0,0],[1,0,0],[0,1,0],[0,0,1],[1,1,0]],\"simplices\":[[0,1,2,3],"
    "[3,2,1,0],[1,2,4],[4,4,2]],\"diagonals\":[[1,0]],\"repair\":true}";
static const char EDIT[] = "{\"moves\":[{\"index\":1,\"position\":[1,0.1,0]},{\"level\":1,"
                           "\"index\":9,\"position\":[0.5,0.2,0]}],\"attributes\":"
                           "{\"h\":[{\"index\":2,\"value\":5}]}}";
static const char REFINE[] = "{\"select\":{\"simplices\":[[0,1,2,3]]},\"depth\":2}"; /* a green
                                                                                 * triangle taken back */

static int bad, oks;   /* failed checks; calls that succeeded in this run */
static uint64_t run_n; /* the failing allocation of this run, for messages */

/* A refusal of a valid request: only a 5xx problem may say why. */
/* Under a memory budget (budgets()): refusals before any work because the request could never
 * fit (413 naming max_memory), counted. */
static bool under_budget;
static int budget_413;

static void refused(const api_problem *p, const char *what)
{
    if (p->status >= 500 && p->status <= 599 && p->detail[0])
        return;
    if (under_budget && p->status == 413 && p->limit_name && !strcmp(p->limit_name, "max_memory")) {
        budget_413++;
        return;
    }
    fprintf(stderr, "api_faults: n=%llu: %s refused with status %d (%s)\n",
            (unsigned long long)run_n, what, p->status, p->detail);
    bad++;
}

/* A failed edit leaves the session's complex as its input says (or the model restored in its
 * place): level 0's positions are the input's, bit for bit. */
static void same_as_input(api_model *m, const char *what)
{
    sd_error e;
    const sd_level *l0 = m->c ? sd_complex_level(m->c, 0, &e) : NULL;
    const double *x = l0 ? sd_level_channel(l0, 0, NULL) : NULL;
    if (!m->c || (x && !memcmp(x, m->in->xyz, 3 * sizeof *x * m->in->nv)))
        return;
    fprintf(stderr, "api_faults: n=%llu: %s left positions the input does not have\n",
            (unsigned long long)run_n, what);
    bad++;
}

static json_t *body(const char *text, api_problem *p)
{
    json_t *b = api_parse_body(text, strlen(text), 0, p);
    if (!b)
        refused(p, "api_parse_body");
    return b;
}

/* A change handler from *m; *m becomes the new model on success. */
static void change(api_model **m, const char *text, change_fn_t fn, const char *what)
{
    api_problem p = {0};
    api_limits lim = api_default_limits();
    json_t *b = body(text, &p);
    api_model *next = NULL;
    if (b && fn(*m, b, &lim, &next, &p))
        refused(&p, what);
    json_decref(b);
    if (next) {
        oks++;
        api_model_unref(*m);
        *m = next;
    }
}

static void drain(out_stream *os)
{
    static char buf[8192];
    while (out_read(os, buf, sizeof buf) > 0)
        ;
}

/* An embedded model (a triangle and a point inside the tetrahedron, bound to level 1), then the
 * level's GLB with it (parts=solids,embedded). */
static void embedded(api_model *m)
{
    static const char MODEL[] = "{\"vertices\":[[0.2,0.2,0.2],[0.3,0.2,0.2],[0.2,0.3,0.2],"
                                "[0.25,0.25,0.3]],\"triangles\":[[0,1,2]],\"level\":1,"
                                "\"outside\":\"fixed\"}";
    api_limits lim = api_default_limits();
    api_problem p = {0};
    json_t *b = body(MODEL, &p), *summary = NULL;
    api_embed_def *d = NULL;
    if (b && api_embed_parse(b, "model", &lim, &d, &p))
        refused(&p, "api_embed_parse");
    json_decref(b);
    if (!d)
        return;
    if (api_embed_put(m, d, atomic_load(&m->version) + 1, &lim, NULL, NULL, &summary, &p))
        refused(&p, "api_embed_put");
    else
        oks++;
    json_decref(summary);
    api_embed_def_unref(d);
    api_level_query q = {.format = "glb", .parts = "solids,embedded"};
    out_stream *os = NULL;
    const out_format *fmt;
    uint64_t version;
    memset(&p, 0, sizeof p);
    if (api_level_open(m, 1, &q, &lim, NULL, &os, &fmt, &version, &p))
        refused(&p, "api_level_open (embedded)");
    else {
        drain(os);
        out_close(os);
        oks++;
    }
}

static void levels(api_model *m)
{
    api_limits lim = api_default_limits();
    for (const out_format *f = out_formats; f->name; f++) {
        api_level_query q = {.format = f->name, .slice = f == out_formats ? "0,0,1,0.3" : NULL};
        api_problem p = {0};
        out_stream *os = NULL;
        const out_format *fmt;
        uint64_t version;
        if (api_level_open(m, 1, &q, &lim, NULL, &os, &fmt, &version, &p)) {
            refused(&p, "api_level_open");
            continue;
        }
        drain(os);
        out_close(os);
        oks++;
    }
    api_problem p = {0};
    json_t *j = api_level_stats(m, 1, &lim, NULL, &p);
    if (!j && p.status)
        refused(&p, "api_level_stats");
    oks += j != NULL;
    json_decref(j);
}

static void views(api_model *m)
{
    api_limits lim = api_default_limits();
    api_problem p = {0};
    json_t *j = api_get_complex(m, &p);
    if (!j && p.status)
        refused(&p, "api_get_complex");
    oks += j != NULL;
    json_decref(j);
    memset(&p, 0, sizeof p);
    if (!(j = api_analysis(m, "0", NULL, &lim, NULL, &p)) && p.status)
        refused(&p, "api_analysis");
    oks += j != NULL;
    json_decref(j);
    memset(&p, 0, sizeof p);
    out_stream *os = NULL;
    const char *ctype;
    if (api_matrix_open(m, 1, "0", "json", &lim, NULL, &os, &ctype, &p))
        refused(&p, "api_matrix_open");
    else {
        drain(os);
        out_close(os);
        oks++;
    }
}

static void edit_and_refine(api_model **m)
{
    api_problem p = {0};
    json_t *b = body(EDIT, &p);
    uint64_t counts[SD_MAX_LEVEL + 1];
    api_refined refined;
    int nlev;
    api_limits lim = api_default_limits();
    api_model *rebuilt = NULL;
    if (b && api_edit(*m, b, 2, &lim, NULL, counts, &nlev, &rebuilt, &p)) {
        refused(&p, "api_edit");
        same_as_input(rebuilt ? rebuilt : *m, "a failed api_edit");
    } else if (b) {
        oks++;
        for (int k = 0; k < 3; k++) { /* the edit's delta of the level the streams computed */
            api_delta_query q = {"1", k == 1 ? "json" : "bin", "h,v", k == 2 ? "solids" : NULL};
            char *text = NULL, comp[64];
            size_t len;
            const char *ctype;
            uint64_t v;
            memset(&p, 0, sizeof p);
            /* 410 too: a failure that left the stamps out (or the level uncomputed) makes the
             * delta unavailable for good, which is what 410 says */
            if (api_level_delta(*m, 1, &q, &text, &len, &ctype, comp, sizeof comp, &v, &p)) {
                if (p.status != 410 || !p.detail[0])
                    refused(&p, "api_level_delta");
            }
            else
                oks++;
            api_free(text);
        }
    }
    if (rebuilt) {
        api_model_unref(*m);
        *m = rebuilt;
    }
    json_decref(b);
    memset(&p, 0, sizeof p);
    api_model *next = NULL;
    if ((b = body(REFINE, &p)) && api_refine(*m, b, &lim, &next, &refined, &p))
        refused(&p, "api_refine");
    json_decref(b);
    if (next) {
        oks++;
        api_model_unref(*m);
        *m = next;
    }
}

static void scenario(void)
{
    sd_error e = {0};
    api_model *m = api_model_new(NULL, NULL, 0, false, &e);
    if (!m)
        return;
    change(&m, RULES0, api_put_rules, "api_put_rules (no complex)");
    api_model *r = api_model_new(NULL, NULL, 0, false, &e); /* a repair, on a model of its own */
    if (r) {
        change(&r, REPAIR, api_put_complex, "api_put_complex (repair)");
        api_model_unref(r);
    }
    change(&m, COMPLEX, api_put_complex, "api_put_complex");
    if (m->c) {
        change(&m, RULES, api_put_rules, "api_put_rules");
        change(&m, TAGS, api_put_tags, "api_put_tags");
        levels(m);
        embedded(m);
        views(m);
        edit_and_refine(&m);
    }
    api_model_unref(m);
}

/* One run failing the nth allocation, then every `every`-th; checks the bytes came back. */
static void run(uint64_t n, uint64_t every)
{
    size_t before = api_mem_in_use(), counted = api_mem_budget_used();
    run_n = n;
    api_mem_fail_at(n, every);
    scenario();
    api_mem_fail_at(0, 0);
    if (api_mem_in_use() != before) {
        fprintf(stderr, "api_faults: n=%llu every=%llu: %zu bytes not freed\n",
                (unsigned long long)n, (unsigned long long)every, api_mem_in_use() - before);
        bad++;
    }
    if (api_mem_budget_used() != counted) { /* core blocks and input reservations too */
        fprintf(stderr, "api_faults: n=%llu every=%llu: %zd bytes left counted in the budget\n",
                (unsigned long long)n, (unsigned long long)every,
                (ssize_t)(api_mem_budget_used() - counted));
        bad++;
    }
}

/* Budgets from nothing up: whatever the scenario cannot get is refused cleanly (a 5xx problem,
 * counted as over budget, or a 413 naming max_memory for what could never fit, before any work),
 * and everything counted is given back. */
static void budgets(void)
{
    for (size_t b = 1; b <= (64u << 20); b *= 4) {
        api_mem_meter meter = {0}, *prev = api_mem_meter_set(&meter);
        api_mem_set_budget(b);
        under_budget = true;
        budget_413 = 0;
        run(0, 0);
        under_budget = false;
        api_mem_set_budget(0);
        api_mem_meter_set(prev);
        if (b < (1u << 16) && !meter.over_budget && !budget_413) {
            fprintf(stderr, "api_faults: a budget of %zu bytes refused nothing\n", b);
            bad++;
        }
    }
}

/* A meter's limit refuses what would take the thread past it. */
static void meter_limit(void)
{
    api_mem_meter meter = {.limit = 4096}, *prev = api_mem_meter_set(&meter);
    api_problem p = {0};
    json_t *b = api_parse_body(COMPLEX, strlen(COMPLEX), 0, &p);
    api_mem_meter_set(prev);
    if (b || p.status != 503 || !meter.refused || meter.peak > 4096) {
        fprintf(stderr, "api_faults: a 4096-byte meter let the body through (status %d, peak %lld)\n",
                p.status, (long long)meter.peak);
        bad++;
    }
    json_decref(b);
    meter = (api_mem_meter){0};
    prev = api_mem_meter_set(&meter);
    b = api_parse_body(COMPLEX, strlen(COMPLEX), 0, &p);
    json_decref(b);
    api_mem_meter_set(prev);
    if (!b || meter.net != 0 || meter.peak <= 0) {
        fprintf(stderr, "api_faults: the meter saw net %lld, peak %lld for a parse and its free\n",
                (long long)meter.net, (long long)meter.peak);
        bad++;
    }
}

int main(int argc, char **argv)
{
    uint64_t max = argc > 1 ? strtoull(argv[1], NULL, 10) : 0, runs = 0;
    int want = 5 + 1 + 3 + 2 + 3 + 2; /* changes (a repair among them), stats, views, edit
                                       * and refine, the edit's three deltas (one of one kind
                                       * of parts), the embedded model and its GLB; and a
                                       * level per format */
    for (const out_format *f = out_formats; f->name; f++)
        want++;
    run(0, 0); /* the scenario must pass as it is */
    runs++;
    if (oks != want) {
        fprintf(stderr, "api_faults: without failures %d calls succeeded, not %d\n", oks, want);
        bad++;
    }
    for (uint64_t n = 1; !max || n <= max; n++) {
        uint64_t injected = api_mem_failures();
        run(n, 0);
        runs++;
        if (api_mem_failures() == injected) /* n is past the scenario's last allocation */
            break;
    }
    /* from the nth allocation on, every one fails: a call that fails half-way cannot allocate
     * its way back (an edit's undo) */
    for (uint64_t n = 1; n < runs; n++)
        run(n, 1);
    runs += runs - 1;
    static const uint64_t every[] = {3, 7, 31};
    for (size_t k = 0; k < sizeof every / sizeof *every; k++)
        for (uint64_t n = 1; n <= every[k]; n++, runs++)
            run(n, every[k]);
    meter_limit();
    budgets();
    if (bad) {
        fprintf(stderr, "api_faults: %d checks failed\n", bad);
        return 1;
    }
    printf("api_faults: %llu runs, %llu failures injected, no leaks\n", (unsigned long long)runs,
           (unsigned long long)api_mem_failures());
    return 0;
}
