/* routes.c — the daemon's route table and each route's handler: the thin glue from a request to
 * an api/ call and back to one response (docs/API.md is the contract, api/openapi.json its
 * description; a test compares that document with `subdivd --list-routes`).
 *
 * A handler runs after http.c has matched the route, checked the session and its token,
 * collected the body and refused query parameters the route's row does not list. Changes of a session (PUT complex, tags, rules, POST refine) go through
 * change(): parse, If-Match, build the next model in a compute slot, publish it under the
 * session's write lock, so concurrent changes of one session are sequential and a refused one
 * leaves it as it was. Reads take the current model by reference and never block a change. A
 * handler computes a level only inside a compute slot (slot_for_level), so /healthz, /readyz and
 * /metrics never queue behind work. Nothing here includes libmicrohttpd (see request.h).
 */
#include "request.h"
#include "../api/delta.h"
#include "../api/details.h"
#include "../api/complex_stream.h"
#include "../api/crease.h"
#include "../api/embedded.h"
#include "../api/handlers.h"
#include "../api/jsonin.h"
#include "../api/mem.h"
#include "errors.h"
#include "events.h"
#include "metrics.h"
#include "parse.h"
#include "rate.h"
#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* ---- handlers: service ------------------------------------------------------------------- */

static void h_healthz(req *r) { http_reply_json(r, 200, json_pack("{s:s}", "status", "ok"), 0); }

/* Ready unless starting, stopping or with its memory budget spent (then a load balancer sends
 * new work elsewhere until requests and sessions give some back); the budget in both answers. */
static void h_readyz(req *r)
{
    size_t budget = api_mem_budget(), used = api_mem_budget_used(), kept = api_mem_kept();
    used = used > kept ? used - kept : 0; /* kept blocks give way to any request (api/mem.h) */
    api_problem p = {0};
    char why[256];
    if (atomic_load(&r->srv->draining)) {
        p.retry_after = 5;
        api_fail(&p, 503, "not-ready", "the daemon is starting or shutting down");
    } else if (budget && used >= budget) {
        p.retry_after = 5;
        api_fail(&p, 503, "memory-budget", "the memory budget is in use: %zu of %zu bytes "
                 "(--max-memory)", used, budget);
    } else if (!persist_healthy(store_persist(r->srv->st), why, sizeof why)) {
        p.retry_after = 5;
        api_fail(&p, 503, "store-unavailable", "the session store (%s) cannot be written: %s",
                 persist_kind_name(store_persist(r->srv->st)), why);
    }
    if (p.status) {
        http_reply_problem(r, &p);
        return;
    }
    http_reply_json(r, 200, json_pack("{s:s, s:{s:I, s:I}, s:s}", "status", "ready", "memory",
                                      "budget_bytes", (json_int_t)budget, "used_bytes",
                                      (json_int_t)used, "store", persist_kind_name(store_persist(r->srv->st))), 0);
}

typedef struct gauges {
    uint64_t cells, bytes;
} gauges;

static void add_gauges(session *s, void *ud)
{
    gauges *g = ud;
    api_model *m = session_model(s, NULL);
    if (m->c) {
        int n = atomic_load(&m->levels_cached);
        for (int l = 0; l < n; l++) {
            sd_counts c;
            sd_complex_counts(m->c, l, &c);
            g->cells += c.points + c.curves + c.triangles + c.tetrahedra + c.octahedra;
        }
        g->bytes += atomic_load(&m->memory_bytes);
    }
    api_model_unref(m);
}


/* A response holding a copy of an open_memstream buffer (which belongs to the C library and is
 * freed here); NULL for lack of memory. */
static struct MHD_Response *memstream_response(req *r, char *text, size_t n, const char *ctype)
{
    char *body = api_memdup(text, n);
    free(text);
    if (!body)
        return NULL;
    atomic_store(&r->bytes, n);
    return http_buffer_response(ctype, body, n);
}

static void h_metrics(req *r)
{
    char *text = NULL;
    size_t n = 0;
    FILE *f = open_memstream(&text, &n);
    if (!f) {
        http_fail(r, 500, "internal", "could not render metrics");
        return;
    }
    gauges g = {0};
    store_foreach(r->srv->st, add_gauges, &g);
    metrics_write(f, store_count(r->srv->st), g.cells, g.bytes, api_mem_in_use());
    http_write_connection_metrics(r->srv, f);
    unsigned listeners;
    uint64_t dropped;
    ev_stats(&listeners, &dropped);
    metrics_write_events(f, listeners, dropped);
    metrics_write_budget(f, api_mem_budget(), api_mem_budget_used(), api_mem_budget_refusals());
    fclose(f);
    struct MHD_Response *resp = memstream_response(r, text, n,
                                                   "text/plain; version=0.0.4; charset=utf-8");
    if (!resp) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    http_queue(r, 200, resp);
}

static void h_asset(req *r)
{
    const asset *a = asset_find(r->path);
    if (!a) {
        http_fail(r, 404, "not-found", "no resource at %.100s", r->path);
        return;
    }
    /* The web front end's bundles have content-hashed names and are immutable; index.html and
     * the OpenAPI document are revalidated (no-cache) against the ETag: 304 while unchanged. */
    int fresh = parse_etag_match(http_header(r, "If-None-Match"), a->etag, 1);
    struct MHD_Response *resp =
        fresh ? http_empty()
              : http_static_response(a->data, a->size);
    if (!fresh)
        http_add_header(resp, "Content-Type", a->content_type);
    http_add_header(resp, "Cache-Control", a->cache_control);
    http_add_header(resp, "ETag", a->etag);
    atomic_store(&r->bytes, fresh ? 0 : a->size);
    http_queue(r, fresh ? 304 : 200, resp);
}

/* GET /errors/<slug>: the page of a problem type (errors.h), so that every `type` resolves. */
static void h_error_page(req *r)
{
    const error_page *e = error_pages;
    while (e->slug && strcmp(e->slug, r->seg_id))
        e++;
    if (!e->slug) {
        http_fail(r, 404, "not-found", "no problem type %.60s (docs/SERVICE.md, \"Errors\")",
                  r->seg_id);
        return;
    }
    char *text = NULL;
    size_t n = 0;
    FILE *f = open_memstream(&text, &n);
    if (!f) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    fprintf(f, "# %s\n\n**%d %s**: an `application/problem+json` answer with\n"
               "`\"type\": \"/errors/%s\"`.\n\nWhen: %s.\n", e->slug, e->status,
            api_status_title(e->status), e->slug, e->when);
    if (strchr(e->row, ','))
        fprintf(f, "\nThe same text describes: %s.\n", e->row);
    fprintf(f, "\n`detail` says what was wrong; `errors[]` (JSON pointers into the request body "
               "or query parameter names) says where. All types: docs/SERVICE.md, \"Errors\".\n");
    fclose(f);
    struct MHD_Response *resp = memstream_response(r, text, n, "text/markdown; charset=utf-8");
    if (!resp) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    http_add_header(resp, "Cache-Control", "public, max-age=3600");
    http_queue(r, 200, resp);
}

/* ---- handlers: sessions ------------------------------------------------------------------ */

static json_t *parse_body(req *r, int empty_ok, api_problem *p)
{
    return api_parse_body(r->body ? r->body : "", r->len, empty_ok, p);
}

/* The JSON body of a change, or NULL once its problem is answered. With `packed` (patterns of
 * api/packed.h) the big arrays are packed into *packs instead of the tree. The body's text is
 * freed once parsed: nothing reads it afterwards, and a large one is the biggest block of the
 * request. */
static json_t *body_or_answer(req *r, const char *const *packed, api_packs *packs)
{
    api_problem p = {0};
    json_t *b;
    if (packed && r->body)
        b = api_parse_body_packed(r->body, r->len, 0, packed, API_PACK_MIN_BYTES, packs, &p);
    else
        b = parse_body(r, 0, &p);
    api_free(r->body);
    r->body = NULL;
    r->len = r->cap = 0;
    if (!b)
        http_reply_problem(r, &p);
    return b;
}

static void iso_time(char *buf, size_t cap, time_t t)
{
    struct tm tm;
    gmtime_r(&t, &tm);
    strftime(buf, cap, "%Y-%m-%dT%H:%M:%SZ", &tm);
}

/* ---- the durable store ---------------------------------------------------------------------- */

/* The problem of a write the durable store refused (nothing of the change is kept: the resident
 * copy is dropped when it may differ from the store, and the next request loads it again). */
static int store_refused(req *r, persist_rc rc, bool drop, api_problem *p)
{
    char why[256] = "";
    persist *ps = store_persist(r->srv->st);
    if (drop)
        store_drop(r->srv->st, r->s, rc == PERSIST_ABSENT);
    switch (rc) {
    case PERSIST_CONFLICT:
        return api_fail(p, 412, "stale-version", "another daemon changed this session first; "
                        "GET it again");
    case PERSIST_ABSENT:
        return api_fail(p, 404, "no-session", "session %s was deleted or expired meanwhile", r->s->id);
    default:
        persist_last_failure(ps, why, sizeof why);
        log_line(r->srv, LOG_ERROR, "session %s: the store refused a change (%s): %s", r->s->id,
                 persist_rc_name(rc), why);
        persist_last_failure_what(ps, why, sizeof why); /* the file or server stays in the log */
        p->retry_after = 5;
        return api_fail(p, 503, "store-unavailable", "the change could not be stored, so it was "
                        "not made: %s", why);
    }
}

/* Store model m as the session's content at `version` (the stored one is `expect`): its export
 * document as the snapshot. 0 or the status of the problem; *stored what the store said. */
static int store_snapshot_rc(req *r, api_model *m, uint64_t expect, uint64_t version,
                             persist_rc *stored, api_problem *p)
{
    persist *ps = store_persist(r->srv->st);
    *stored = PERSIST_OK;
    if (!persist_durable(ps))
        return 0;
    json_t *doc = api_export(m, version);
    char *text = doc ? json_dumps(doc, JSON_COMPACT) : NULL;
    json_decref(doc);
    if (!text)
        return api_fail(p, 503, "out-of-memory", "out of memory (the change was not made)");
    persist_rc rc = persist_snapshot(ps, r->s->id, expect, version, session_stored_expiry(r->s),
                                     text, strlen(text));
    api_free(text);
    *stored = rc;
    if (rc == PERSIST_OK)
        r->s->journal_len = 0;
    return rc == PERSIST_OK ? 0 : store_refused(r, rc, rc == PERSIST_CONFLICT || rc == PERSIST_ABSENT, p);
}

static int store_snapshot(req *r, api_model *m, uint64_t expect, uint64_t version, api_problem *p)
{
    persist_rc stored;
    return store_snapshot_rc(r, m, expect, version, &stored, p);
}

/* A journal this long is folded into a snapshot after the next edit. */
#define JOURNAL_COMPACT 256

/* Store the edit `body` that made `version` in the journal (0, or the status of the problem:
 * the edit is then not made). A store that holds another version, or none, means the resident
 * copy is stale: it is dropped, and the next request loads the stored one. */
static int store_journal(req *r, json_t *body, uint64_t version, persist_rc *stored,
                         api_problem *p)
{
    persist *ps = store_persist(r->srv->st);
    if (!persist_durable(ps))
        return 0;
    char *text = json_dumps(body, JSON_COMPACT);
    persist_rc rc = text ? persist_append(ps, r->s->id, version - 1, version,
                                          session_stored_expiry(r->s), text, strlen(text))
                         : PERSIST_UNAVAILABLE;
    api_free(text);
    if (stored)
        *stored = rc;
    if (rc != PERSIST_OK)
        return store_refused(r, rc, rc == PERSIST_CONFLICT || rc == PERSIST_ABSENT, p);
    r->s->journal_len++;
    return 0;
}

/* The commit of an edit applied in place (api_edit_commit_by): its journal entry. */
typedef struct edit_commit {
    req *r;
    json_t *body;
    uint64_t version;
    persist_rc stored;        /* what the store said */
} edit_commit;

static int commit_edit(void *ud, api_problem *p)
{
    edit_commit *c = ud;
    return store_journal(c->r, c->body, c->version, &c->stored, p);
}

/* After JOURNAL_COMPACT edits the journal becomes a snapshot of the published model (under the
 * write lock, after the publish). A failure loses nothing — the journal still holds every edit
 * — and is tried again 64 edits later. */
static void store_compact(req *r, uint64_t version)
{
    if (r->s->journal_len < JOURNAL_COMPACT || !persist_durable(store_persist(r->srv->st)))
        return;
    api_model *m = session_model(r->s, NULL);
    api_problem ignored = {0};
    if (store_snapshot(r, m, version, version, &ignored)) {
        log_line(r->srv, LOG_WARN, "session %s: compacting the journal failed: %s", r->s->id,
                 ignored.detail);
        r->s->journal_len = JOURNAL_COMPACT - 64;
    }
    api_model_unref(m);
}

/* POST /v1/sessions: anyone may ask, so each client address has a rate (--session-rate, 429
 * with the seconds until its next token), the TTL is capped (--max-ttl: the answer says what
 * was granted), and a full table first lets an empty idle session go (sessions.c); otherwise
 * 429 with the seconds until the soonest expiry. */
static void h_create_session(req *r)
{
    api_problem p = {0};
    rate_key key = rate_key_of(http_client_address(r));
    int wait = rate_take(r->srv->session_rate, &key, mono_now());
    if (wait) {
        p.retry_after = wait;
        api_fail(&p, 429, "session-rate",
                 "this client may create %d sessions a minute; retry in %d s", r->srv->cfg.session_rate,
                 wait);
        http_reply_problem(r, &p);
        return;
    }
    json_t *b = parse_body(r, 1, &p);
    static const char *const keys[] = {"ttl_s", "import", NULL};
    long long ttl = r->srv->cfg.ttl_s;
    json_t *t, *imp;
    if (!b || api_only_keys(b, "", keys, &p) ||
        ((t = json_object_get(b, "ttl_s")) && api_get_int(t, "/ttl_s", 1, API_MAX_TTL_S, &ttl, &p))) {
        json_decref(b);
        http_reply_problem(r, &p);
        return;
    }
    api_model *imported = NULL; /* {"import": <GET /export>}: built before the session exists */
    uint64_t imported_version = 0;
    if ((imp = json_object_get(b, "import"))) {
        int rc = http_take_slot(r, &p);
        if (!rc) {
            rc = api_import(imp, "/import", &r->srv->cfg.limits, API_IMPORT_MAX_VERSION, &imported,
                            &imported_version, &p);
            http_give_slot(r);
        }
        if (rc) {
            json_decref(b);
            http_reply_problem(r, &p);
            return;
        }
    }
    json_decref(b);
    if (ttl > r->srv->cfg.max_ttl_s)
        ttl = r->srv->cfg.max_ttl_s;
    store_admission adm;
    session *s = store_create(r->srv->st, (int)ttl, &key, r->srv->cfg.max_sessions_per_client,
                              r->srv->cfg.max_stored_sessions_per_client, &adm);
    if (adm.evicted)
        log_line(r->srv, LOG_INFO, "%s: an idle session went",
                 adm.evicted_own ? "the client held its share of the sessions"
                                 : "the session table was full");
    if (s && imported) {
        session_adopt(s, imported, imported_version);
        r->s = s; /* the snapshot is the new session's (a create request has no session) */
        int rc = store_snapshot(r, s->model, 0, imported_version, &p);
        r->s = NULL;
        if (rc) {
            persist_delete(store_persist(r->srv->st), s->id);
            store_remove(r->srv->st, s);
            session_unref(s);
            http_reply_problem(r, &p);
            return;
        }
    } else
        api_model_unref(imported);
    if (!s && adm.stored != PERSIST_OK) {
        p.retry_after = 5;
        char why[256] = "";
        persist_last_failure(store_persist(r->srv->st), why, sizeof why);
        log_line(r->srv, LOG_ERROR, "a new session could not be stored: %s", why);
        persist_last_failure_what(store_persist(r->srv->st), why, sizeof why);
        api_fail(&p, 503, "store-unavailable", "the session could not be stored: %s", why);
        http_reply_problem(r, &p);
        return;
    }
    if (!s && !adm.retry_after_s) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    if (!s) { /* the client's share of the table, or the table, is full */
        p.retry_after = adm.retry_after_s;
        if (adm.client_stored_full)
            api_fail(&p, 429, "client-sessions",
                     "this client address has %d unexpired sessions in the store, its maximum "
                     "(--max-stored-sessions-per-client); delete one, or retry in %d s when the "
                     "first expires", r->srv->cfg.max_stored_sessions_per_client,
                     adm.retry_after_s);
        else if (adm.client_full)
            api_fail(&p, 429, "client-sessions",
                     "this client address holds %d sessions, its maximum (--max-sessions-per-client), "
                     "each with a complex or in use; delete one, or retry in %d s when the first "
                     "expires", r->srv->cfg.max_sessions_per_client, adm.retry_after_s);
        else
            api_fail(&p, 429, "too-many-sessions",
                     "the daemon holds its maximum of %d sessions, each with a complex or in use; "
                     "delete unused sessions, or retry in %d s when the first expires",
                     r->srv->cfg.max_sessions, adm.retry_after_s);
        http_reply_problem(r, &p);
        return;
    }
    char exp[32], loc[64];
    iso_time(exp, sizeof exp, session_expires_at(s));
    snprintf(loc, sizeof loc, "/v1/sessions/%s", s->id);
    json_t *j = json_pack("{s:s, s:s, s:s, s:I, s:I}", "id", s->id, "token", s->token, "expires_at",
                          exp, "ttl_s", (json_int_t)ttl, "version", (json_int_t)imported_version);
    session_unref(s);
    char *text = j ? json_dumps(j, JSON_COMPACT) : NULL;
    json_decref(j);
    if (!text) { /* the session stays; an idle one expires */
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    size_t n = strlen(text);
    atomic_store(&r->bytes, n);
    struct MHD_Response *resp = http_buffer_response("application/json", text, n);
    http_add_header(resp, "Location", loc);
    http_set_etag(resp, imported_version); /* "0", or the version an import continues from */
    http_queue(r, 201, resp);
}

static void h_get_session(req *r)
{
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    char exp[32];
    iso_time(exp, sizeof exp, session_expires_at(r->s));
    json_t *progress = json_null();
    int busy = atomic_load(&r->s->busy_level);
    double fraction = atomic_load(&m->progress);
    if (busy >= 0) {
        progress = json_pack("{s:s, s:i, s:f}", "state", "computing", "level", busy, "seconds",
                             mono_now() - atomic_load(&r->s->busy_since));
        if (progress && fraction >= 0) /* levels of the current model: how far, by their bytes */
            json_object_set_new(progress, "fraction", json_real(fraction));
    }
    json_t *summary = m->summary ? json_incref(m->summary) : json_object();
    json_t *j = json_pack("{s:s, s:I, s:i, s:I, s:o, s:s, s:o}", "id", r->s->id, "version",
                          (json_int_t)version, "levels_cached", atomic_load(&m->levels_cached),
                          "memory_bytes", (json_int_t)atomic_load(&m->memory_bytes), "summary",
                          summary, "expires_at", exp, "progress", progress);
    api_model_unref(m);
    http_reply_session_json(r, 200, j, version);
}

/* PATCH /v1/sessions/{id} {"ttl_s": n}: a new idle TTL, counted from now and capped at --max-ttl
 * as at creation (the web front end shortens its session's when its page goes, so that a reload
 * finds the session and a closed tab frees it soon). Not a change of the session's content: no
 * version, no If-Match, no event. With a durable store the record is changed first: a refusal
 * changes nothing. */
static void h_patch_session(req *r)
{
    api_problem p = {0};
    json_t *b = body_or_answer(r, NULL, NULL), *t;
    if (!b)
        return;
    static const char *const keys[] = {"ttl_s", NULL};
    long long ttl = 0;
    if (!api_only_keys(b, "", keys, &p)) {
        if (!(t = json_object_get(b, "ttl_s")))
            api_fail_at(&p, 400, "missing-field", "/ttl_s", "give \"ttl_s\": the new idle TTL in seconds");
        else
            api_get_int(t, "/ttl_s", 1, API_MAX_TTL_S, &ttl, &p);
    }
    json_decref(b);
    if (!p.status) {
        if (ttl > r->srv->cfg.max_ttl_s)
            ttl = r->srv->cfg.max_ttl_s;
        persist_rc rc = store_retime(r->srv->st, r->s, (int)ttl);
        if (rc != PERSIST_OK) /* gone from the store meanwhile: the resident copy goes too */
            store_refused(r, rc, rc == PERSIST_ABSENT, &p);
    }
    if (p.status) {
        http_reply_problem(r, &p);
        return;
    }
    uint64_t version;
    api_model_unref(session_model(r->s, &version));
    char exp[32];
    iso_time(exp, sizeof exp, session_expires_at(r->s));
    json_t *j = json_pack("{s:s, s:s, s:I, s:I}", "id", r->s->id, "expires_at", exp, "ttl_s",
                          (json_int_t)ttl, "version", (json_int_t)version);
    http_reply_session_json(r, 200, j, version);
}

/* GET /export: the session's control data as one document (api/export.c), under the write lock
 * so that its content and version are those of one moment between changes. */
static void h_export(req *r)
{
    pthread_mutex_lock(&r->s->write);
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    json_t *j = api_export(m, version);
    pthread_mutex_unlock(&r->s->write);
    api_model_unref(m);
    if (!j) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    http_reply_session_json(r, 200, j, version);
}

static void h_delete_session(req *r)
{
    persist *ps = store_persist(r->srv->st);
    persist_rc rc = persist_durable(ps) ? persist_delete(ps, r->s->id) : PERSIST_OK;
    if (rc != PERSIST_OK && rc != PERSIST_ABSENT) {
        api_problem p = {0};
        store_refused(r, rc, false, &p);
        http_reply_problem(r, &p);
        return;
    }
    store_remove(r->srv->st, r->s);
    http_queue(r, 204, http_empty());
}

/* The entity tag of a session version, as sent in ETag. */
static void version_etag(char *buf, size_t cap, uint64_t version)
{
    snprintf(buf, cap, "\"%llu\"", (unsigned long long)version);
}

/* If-Match on a change: absent is fine (except where a route requires it), "*" matches any
 * version, otherwise one of the listed entity tags must equal the current version's, compared
 * strongly (parse_etag_match: a weak or malformed tag matches nothing). */
static int if_match_ok(req *r, uint64_t version)
{
    const char *h = http_header(r, "If-Match");
    char want[32];
    version_etag(want, sizeof want, version);
    return !h || parse_etag_match(h, want, 0);
}

/* 0 when If-Match allows a change of this version, else the status of a 412 problem. */
static int if_match(req *r, uint64_t version, api_problem *p)
{
    if (if_match_ok(r, version))
        return 0;
    return api_fail(p, 412, "stale-version",
                    "If-Match does not match the current version \"%llu\"; GET the session "
                    "again", (unsigned long long)version);
}

/* Tell the session's event listeners about its new version: {"version", "kind"} and, for an
 * edit, "updated_points" (its text, as in the PATCH answer). Called under the session's write
 * lock, so events go out in version order; the hub copies and never waits for a client. */
static void notify(req *r, uint64_t version, const char *kind, const char *updated)
{
    char data[640];
    snprintf(data, sizeof data, "{\"version\":%llu,\"kind\":\"%s\"%s%s}",
             (unsigned long long)version, kind, updated ? ",\"updated_points\":" : "",
             updated ? updated : "");
    ev_publish(r->s->events, version, "version", data);
}

/* The compute slots of the daemon as api/ takes them (api_slot): only once the model's lock is
 * held, and shown as the session's progress while held. */
static int slot_take(void *ud, int level, api_problem *p)
{
    req *r = ud;
    if (http_take_slot(r, p))
        return p->status;
    atomic_store(&r->s->busy_level, level);
    return 0;
}

static void slot_give(void *ud) { http_give_slot(ud); }

static api_slot slot_of(req *r)
{
    api_slot s = {slot_take, slot_give, r};
    return s;
}

/* A change builds the session's next model from the current one and may add members to the
 * answer (the summary, what was refined). */
typedef int (*change_op)(const api_model *cur, json_t *body, const api_packs *packs,
                         const api_limits *lim, api_model **next, json_t *answer, api_problem *p);

/* Whether the request's If-Match names no version: absent, or "*" (any). */
static bool unconditional(req *r)
{
    const char *h = http_header(r, "If-Match");
    while (h && (*h == ' ' || *h == '\t'))
        h++;
    return !h || (h[0] == '*' && !h[1 + strspn(h + 1, " \t")]);
}

/* How many times a change that named no version is made again after losing a compare-and-set
 * to other daemons' changes (each attempt reads the stored session anew, so only a session
 * changed elsewhere that often meanwhile gets the 412). */
#define RELOAD_TRIES 8

/* After the store refused a change because another daemon's came first (the resident copy is
 * dropped): for a change that named no version, the session as stored takes the request's
 * reference and true is returned (make the change again); else false. */
static bool reload_unconditional(req *r, int attempt)
{
    if (!unconditional(r))
        return false;
    /* the daemons that lost the same race would all try again at once and collide again: wait
     * a random 0 .. 2^attempt ms first (1, 2, 4 ... at most 64 ms) */
    static _Thread_local unsigned short seed[3];
    if (!seed[0] && !seed[1] && !seed[2]) {
        uint64_t t = (uint64_t)(mono_now() * 1e9) ^ (uint64_t)(uintptr_t)&seed;
        seed[0] = (unsigned short)t, seed[1] = (unsigned short)(t >> 16), seed[2] = (unsigned short)(t >> 32);
    }
    long span = 1L << (attempt < 6 ? attempt : 6);
    struct timespec ts = {0, (nrand48(seed) % (span * 1000 + 1)) * 1000};
    nanosleep(&ts, NULL);
    store_miss miss;
    session *again = store_get(r->srv->st, r->s->id, NULL, &miss, NULL, 0);
    if (!again)
        return false;
    http_session_done(r);
    r->s = again;
    session_use(again);
    r->using = 1;
    return true;
}

/* PUT complex / tags / rules, POST refine: parse, check If-Match, build the new model in a
 * compute slot, publish, tell the listeners (`kind`). The session's write lock makes concurrent
 * changes of one session sequential. With several daemons on one store, another daemon's change
 * can come first: the store refuses ours (the resident copy is dropped); a change that named no
 * version is then made again on the session as stored, up to RELOAD_TRIES times (one that did
 * is a 412). */
static void change(req *r, change_op op, const char *const *packed, const char *kind)
{
    api_problem p = {0};
    api_packs packs = {0};
    json_t *b = body_or_answer(r, packed, &packs);
    if (!b)
        return;
    json_t *answer = NULL;
    api_model *next = NULL;
    uint64_t version;
    int rc;
    for (int attempt = 0;; attempt++) {
        pthread_mutex_lock(&r->s->write);
        api_model *cur = session_model(r->s, &version);
        answer = json_object();
        next = NULL;
        if (!(rc = if_match(r, version, &p)) && !(rc = http_take_slot(r, &p))) {
            rc = op(cur, b, &packs, &r->srv->cfg.limits, &next, answer, &p);
            /* the embedded models, their rest shapes bound to the new model (all or nothing) */
            if (!rc && (rc = api_embed_rebind(cur, next, &r->srv->cfg.limits, NULL, &p))) {
                api_model_unref(next);
                next = NULL;
            }
            http_give_slot(r);
        }
        api_model_unref(cur);
        persist_rc stored = PERSIST_OK;
        if (!rc && (rc = store_snapshot_rc(r, next, version, version + 1, &stored, &p))) {
            api_model_unref(next);
            next = NULL;
        }
        if (!rc)
            break;
        pthread_mutex_unlock(&r->s->write);
        json_decref(answer);
        if (!(stored == PERSIST_CONFLICT && attempt < RELOAD_TRIES && reload_unconditional(r, attempt))) {
            json_decref(b);
            api_packs_free(&packs);
            http_reply_problem(r, &p);
            return;
        }
        memset(&p, 0, sizeof p);
    }
    json_decref(b);
    api_packs_free(&packs);
    version = session_publish(r->s, next);
    notify(r, version, kind, NULL);
    pthread_mutex_unlock(&r->s->write);
    json_object_set_new(answer, "version", json_integer((json_int_t)version));
    http_reply_json(r, 200, answer, version);
}

static int op_complex(const api_model *cur, json_t *body, const api_packs *packs,
                      const api_limits *lim, api_model **next, json_t *answer, api_problem *p)
{
    size_t dropped = json_object_get(body, "details") ? 0 : api_details_count(cur);
    int rc = api_put_complex_packed(cur, body, packs, lim, next, p);
    if (!rc && (*next)->summary)
        json_object_set(answer, "summary", (*next)->summary);
    if (!rc && dropped) /* the offsets named points of the old complex */
        json_object_set_new(answer, "details_dropped", json_integer((json_int_t)dropped));
    return rc;
}

static int op_tags(const api_model *cur, json_t *body, const api_packs *packs,
                   const api_limits *lim, api_model **next, json_t *answer, api_problem *p)
{
    int rc = api_put_tags_packed(cur, body, packs, lim, next, p);
    json_t *ca = rc ? NULL : api_crease_json(&(*next)->tags);
    if (ca) /* what "crease_angle" tagged */
        json_object_set_new(answer, "crease_angle", ca);
    return rc;
}

static int op_rules(const api_model *cur, json_t *body, const api_packs *packs,
                    const api_limits *lim, api_model **next, json_t *answer, api_problem *p)
{
    (void)answer;
    (void)packs;
    return api_put_rules(cur, body, lim, next, p);
}

static int op_refine(const api_model *cur, json_t *body, const api_packs *packs,
                     const api_limits *lim, api_model **next, json_t *answer, api_problem *p)
{
    (void)packs;
    api_refined done;
    size_t dropped = api_details_count(cur); /* their points do not exist in the refined complex */
    size_t tangents = 0;                      /* not carried (DECISIONS 47 (f)): the entries */
    if (cur->tags.ntt) {                      /* of the three lists, as GET /complex echoes them */
        json_t *echo = json_object();
        api_tangents_json(&cur->tags, echo);
        const char *key;
        json_t *list;
        json_object_foreach(echo, key, list)
            tangents += json_array_size(list);
        json_decref(echo);
    }
    int rc = api_refine(cur, body, lim, next, &done, p);
    if (!rc && dropped)
        json_object_set_new(answer, "details_dropped", json_integer((json_int_t)dropped));
    if (!rc && tangents)
        json_object_set_new(answer, "tangent_tags_dropped", json_integer((json_int_t)tangents));
    if (!rc) {
        if ((*next)->summary)
            json_object_set(answer, "summary", (*next)->summary);
        json_object_set_new(answer, "refined",
                            json_pack("{s:I, s:I, s:i, s:b}", "red", (json_int_t)done.red, "green",
                                      (json_int_t)done.green, "steps", done.steps, "capped",
                                      done.capped));
    }
    return rc;
}

static void h_put_complex(req *r) { change(r, op_complex, api_complex_packed, "complex"); }
static void h_put_tags(req *r) { change(r, op_tags, api_tags_packed, "tags"); }
static void h_put_rules(req *r) { change(r, op_rules, NULL, "rules"); }
static void h_refine(req *r) { change(r, op_refine, NULL, "refine"); }

static const char *const EDIT_KEYS[] = {"delta", "format", "attributes", "parts", NULL};

/* PATCH ?delta=L (docs/API.md "Live edits", DECISIONS 38): the edit answers with the delta of
 * level L it made, so a dragging client needs one round trip, not two. */
typedef struct edit_delta {
    int level;                /* -1: not asked */
    api_delta_query q;
    char since[24];
    char *body;
    size_t len;
    const char *ctype;
    char comp[1024];
    api_problem p;            /* why there is no delta (410, 503) */
} edit_delta;

/* The query of a PATCH: 0, or the status of the problem (nothing applied yet). */
static int edit_query(req *r, edit_delta *d, api_problem *p)
{
    const char *lv = http_arg(r, "delta");
    d->level = -1;
    d->q = (api_delta_query){d->since, http_arg(r, "format"), http_arg(r, "attributes"),
                             http_arg(r, "parts")};
    if (!lv) {
        if (d->q.format || d->q.attributes || d->q.parts)
            return api_fail_at(p, 400, "bad-parameter",
                               d->q.format ? "format" : d->q.attributes ? "attributes" : "parts",
                               "format, attributes and parts of a PATCH go with delta=<level>");
        return 0;
    }
    api_problem lp = {0};
    int level = api_parse_level(lv, &lp);
    if (level < 0)
        return api_fail_at(p, lp.status, lp.slug, "delta", "delta: %s", lp.detail);
    d->level = level;
    return 0;
}

/* The answer of an edit with ?delta=: the delta itself (bin: its body; json: inside the
 * summary), or the summary with "delta": the problem that kept it from being made. */
static void reply_edit_delta(req *r, edit_delta *d, uint64_t version, const char *up)
{
    struct MHD_Response *resp = NULL;
    char *text = NULL;
    size_t n = 0;
    const bool bin = d->body && !strcmp(d->ctype, "application/octet-stream");
    if (bin) {
        resp = http_buffer_response(d->ctype, d->body, d->len);
        n = d->len;
    } else {
        char head[640];
        int k = snprintf(head, sizeof head, "{\"version\":%llu,\"updated_points\":%s,\"delta\":",
                         (unsigned long long)version, up);
        json_t *pj = d->body ? NULL : api_problem_json(&d->p);
        char *pt = pj ? json_dumps(pj, JSON_COMPACT) : NULL;
        json_decref(pj);
        const char *tail = d->body ? d->body : pt ? pt : "null";
        size_t tl = d->body ? d->len : strlen(tail);
        if ((text = api_malloc((size_t)k + tl + 2))) {
            memcpy(text, head, (size_t)k);
            memcpy(text + k, tail, tl);
            memcpy(text + k + tl, "}", 2);
            n = (size_t)k + tl + 1;
            resp = http_buffer_response("application/json", text, n);
        }
        api_free(pt); /* jansson allocates with api_malloc */
        api_free(d->body);
    }
    d->body = NULL;
    if (!resp) {
        http_fail(r, 503, "out-of-memory", "out of memory (the edit was applied)");
        return;
    }
    atomic_store(&r->bytes, n);
    http_set_etag(resp, version);
    http_add_header(resp, "X-Updated-Points", up);
    if (d->comp[0]) /* the binary layout's, and a JSON delta's shapes (an empty one has none) */
        http_add_header(resp, "X-Attribute-Components", d->comp);
    http_queue(r, 200, resp);
}

/* PATCH control-points: If-Match is required (428 without, 412 when stale); the model is changed
 * in place (streams in flight read their own snapshots), or replaced by a new one where the
 * edit moves what a level's rules read (api_edit). The changed points are stamped with the new
 * version (api/delta.h), and the listeners told; with ?delta=L the answer is the edit's delta of
 * level L, made under the write lock (nothing else between). */
static void h_edit(req *r)
{
    api_problem p = {0};
    edit_delta d = {0};
    if (!http_header(r, "If-Match")) {
        api_fail(&p, 428, "precondition-required",
                 "send If-Match: \"<version>\" (the session's ETag) with an edit");
        http_reply_problem(r, &p);
        return;
    }
    if (edit_query(r, &d, &p)) {
        http_reply_problem(r, &p);
        return;
    }
    json_t *b = body_or_answer(r, NULL, NULL);
    if (!b)
        return;
    uint64_t version;
    int rc;
    char up[512];
    /* again on a compare-and-set lost to another daemon when If-Match is "*" (change()) */
    for (int attempt = 0;; attempt++) {
        pthread_mutex_lock(&r->s->write);
        api_model *m = session_model(r->s, &version), *rebuilt = NULL;
        uint64_t counts[SD_MAX_LEVEL + 1];
        int levels = 0;
        api_slot slot = slot_of(r);
        edit_commit ec = {r, b, version + 1, PERSIST_OK};
        snprintf(d.since, sizeof d.since, "%llu", (unsigned long long)version);
        /* changes are sequential (the write lock): the edit's version is the next one */
        if (!(rc = if_match(r, version, &p)) && (d.level < 0 || !(rc = api_delta_check(m, &d.q, &p))))
        {
            api_edit_commit commit = {commit_edit, &ec};
            rc = api_edit_commit_by(m, b, version + 1, &r->srv->cfg.limits, &slot, &commit, counts,
                                    &levels, &rebuilt, &p);
        }
        snprintf(up, sizeof up, "{");
        for (int l = 0; !rc && l < levels; l++) {
            size_t u = strlen(up);
            snprintf(up + u, sizeof up - u, "%s\"%d\":%llu", l ? "," : "", l,
                     (unsigned long long)counts[l]);
        }
        strcat(up, "}");
        if (!rc && rebuilt && (rc = api_embed_carry(m, rebuilt, &r->srv->cfg.limits, &p))) {
            api_model_unref(rebuilt);
            rebuilt = NULL;
        }
        if (!rc && rebuilt && (rc = store_journal(r, b, version + 1, &ec.stored, &p))) {
            api_model_unref(rebuilt); /* a new model (nothing changed in place): not published */
            rebuilt = NULL;
        }
        if (!rc) { /* the version api_edit stamped: the write lock is held */
            version = rebuilt ? session_publish(r->s, rebuilt) : session_bump(r->s);
            store_compact(r, version);
            notify(r, version, "edit", up);
            if (d.level >= 0) {
                api_model *now = session_model(r->s, NULL);
                uint64_t dv;
                api_level_delta(now, d.level, &d.q, &d.body, &d.len, &d.ctype, d.comp,
                                sizeof d.comp, &dv, &d.p);
                api_model_unref(now);
            }
        } else if (rebuilt && persist_durable(store_persist(r->srv->st))) {
            api_model_unref(rebuilt); /* a failed edit whose undo failed: the store has the content */
            store_drop(r->srv->st, r->s, false);
        } else if (rebuilt) { /* a failed edit whose undo failed: the content before it, rebuilt */
            api_problem q = {0};
            api_embed_carry(m, rebuilt, &r->srv->cfg.limits, &q); /* what fits goes on */
            notify(r, session_publish(r->s, rebuilt), "complex", NULL);
        }
        pthread_mutex_unlock(&r->s->write);
        api_model_unref(m);
        if (!rc || !(ec.stored == PERSIST_CONFLICT && attempt < RELOAD_TRIES && reload_unconditional(r, attempt)))
            break;
        memset(&p, 0, sizeof p);
    }
    json_decref(b);
    if (rc) {
        http_reply_problem(r, &p);
        return;
    }
    if (d.level >= 0) {
        reply_edit_delta(r, &d, version, up);
        return;
    }
    json_error_t je;
    json_t *j = json_loads(up, 0, &je);
    http_reply_json(r, 200, json_pack("{s:I, s:o*}", "version", (json_int_t)version,
                                      "updated_points", j), version);
}

static ssize_t cstream_read(void *ctx, char *buf, size_t max)
{
    return (ssize_t)api_cstream_read(ctx, buf, max);
}

static void cstream_close(void *ctx) { api_cstream_free(ctx); }

/* GET /complex streams (chunked): a complex of a million points is some 60 MB of JSON, which a
 * jansson tree would hold many times over. */
static void h_get_complex(req *r)
{
    uint64_t version;
    api_model *m = session_model(r->s, NULL);
    api_problem p = {0};
    api_cstream *cs = api_get_complex_stream(m, &version, &p);
    if (!cs) {
        api_model_unref(m);
        http_reply_problem(r, &p);
        return;
    }
    http_source src = {cs, cstream_read, cstream_close};
    http_reply_stream(r, m, src, UINT64_MAX, "application/json", NULL, version);
}


/* ---- handlers: levels ------------------------------------------------------------------- */

/* If-None-Match on a read: "*" or one of the listed entity tags, compared weakly. */
static int if_none_match_hit(req *r, uint64_t version)
{
    char want[32];
    version_etag(want, sizeof want, version);
    return parse_etag_match(http_header(r, "If-None-Match"), want, 1);
}

/* The level of a /levels/{L} or /matrices/{L} request; -1 when a problem was answered. */
static int level_of(req *r)
{
    api_problem p = {0};
    int level = api_parse_level(r->seg_level, &p);
    if (level < 0)
        http_reply_problem(r, &p);
    return level;
}

/* The handlers of /levels/{L}, /levels/{L}/stats and /matrices/{L}: called with the level and
 * the session's model (a reference they own) once the query and the level are checked. */
typedef void (*level_fn)(req *r, api_model *m, int level);

static void with_level(req *r, level_fn fn)
{
    int level = level_of(r);
    if (level < 0)
        return;
    fn(r, session_model(r->s, NULL), level);
}

/* A stream of the writers of api/out.h as the source of a response. */
static ssize_t out_source_read(void *ctx, char *buf, size_t max) { return out_read(ctx, buf, max); }
static void out_source_close(void *ctx) { out_close(ctx); }

static http_source out_source(out_stream *os)
{
    http_source src = {os, out_source_read, out_source_close};
    return src;
}

/* A refused stream: drop the model and answer the problem. */
static void stream_refused(req *r, api_model *m, const api_problem *p)
{
    api_model_unref(m);
    http_reply_problem(r, p);
}

static const char *const LEVEL_KEYS[] = {"format", "parts", "slice", "attributes", "colormap",
                                         "octahedra", "names", "compress", "limit", NULL};

static void get_level(req *r, api_model *m, int level)
{
    api_problem p = {0};
    uint64_t version = atomic_load(&m->version);
    if (m->c && if_none_match_hit(r, version)) {
        api_model_unref(m);
        struct MHD_Response *resp = http_empty();
        http_set_etag(resp, version);
        http_queue(r, 304, resp);
        return;
    }
#define Q(k) http_arg(r, k)
    api_level_query q = {Q("format"), Q("parts"), Q("slice"), Q("attributes"), Q("colormap"),
                         Q("octahedra"), Q("names"), Q("compress"), Q("limit")};
#undef Q
    out_stream *os = NULL;
    const out_format *fmt;
    api_slot slot = slot_of(r);
    if (api_level_open(m, level, &q, &r->srv->cfg.limits, &slot, &os, &fmt, &version, &p)) {
        stream_refused(r, m, &p);
        return;
    }
    char disp[96];
    snprintf(disp, sizeof disp, "%s; filename=\"level-%d%s\"", fmt->disposition, level,
             fmt->extension);
    http_reply_stream(r, m, out_source(os), out_size(os), fmt->mime, disp, version);
}

static void h_get_level(req *r) { with_level(r, get_level); }

static void level_stats(req *r, api_model *m, int level)
{
    api_problem p = {0};
    api_slot slot = slot_of(r);
    json_t *j = api_level_stats(m, level, &r->srv->cfg.limits, &slot, &p);
    uint64_t version = atomic_load(&m->version);
    api_model_unref(m);
    http_reply_versioned(r, j, version, &p);
}

static void h_level_stats(req *r) { with_level(r, level_stats); }

static const char *const MATRIX_KEYS[] = {"from", "format", NULL};

static void matrix(req *r, api_model *m, int level)
{
    api_problem p = {0};
    out_stream *os = NULL;
    const char *ctype = NULL;
    const char *from = http_arg(r, "from");
    const char *fmt = http_arg(r, "format");
    api_slot slot = slot_of(r);
    if (api_matrix_open(m, level, from, fmt, &r->srv->cfg.limits, &slot, &os, &ctype, &p)) {
        stream_refused(r, m, &p);
        return;
    }
    /* The from-level as parsed (api_matrix_open accepted only digits below the level), not the
     * query text: "from=01" names S_1_2, and a long run of zeros cannot cut the header short. */
    char disp[96];
    snprintf(disp, sizeof disp, "attachment; filename=\"S_%ld_%d.%s\"",
             from ? strtol(from, NULL, 10) : 0L, level,
             fmt && !strcmp(fmt, "json") ? "json" : "mtx");
    http_reply_stream(r, m, out_source(os), UINT64_MAX, ctype, disp, atomic_load(&m->version));
}

static void h_matrix(req *r) { with_level(r, matrix); }

/* an embedded model has no attributes: its delta takes since and format alone */
static const char *const EMBED_DELTA_KEYS[] = {"since", "format", NULL};
static const char *const LEVEL_DELTA_KEYS[] = {"since", "format", "attributes", "parts", NULL};

/* GET /levels/{L}/delta: the points of a level the client holds that changed since a version
 * (api/delta.h), a body of its own; no compute slot (a level not computed is a 410). */
static void delta(req *r, api_model *m, int level)
{
    api_problem p = {0};
    api_delta_query q = {http_arg(r, "since"), http_arg(r, "format"), http_arg(r, "attributes"),
                         http_arg(r, "parts")};
    char *body, comp[1024];
    size_t len;
    const char *ctype;
    uint64_t v;
    int rc = api_level_delta(m, level, &q, &body, &len, &ctype, comp, sizeof comp, &v, &p);
    api_model_unref(m);
    if (rc) {
        http_reply_problem(r, &p);
        return;
    }
    struct MHD_Response *resp = http_buffer_response(ctype, body, len);
    if (!resp) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    atomic_store(&r->bytes, len);
    http_set_etag(resp, v);
    if (comp[0]) /* the components of each attribute of the binary layout */
        http_add_header(resp, "X-Attribute-Components", comp);
    http_queue(r, 200, resp);
}

static void h_delta(req *r) { with_level(r, delta); }

/* ---- handlers: embedded models (api/embedded.h) ------------------------------------------- */

static const char *const EMBED_PUT_KEYS[] = {"level", "outside", NULL};
static const char *const EMBED_GET_KEYS[] = {"format", NULL};

/* The commit of an in-place change of the model's embedded list: the model's snapshot. */
typedef struct embed_commit {
    req *r;
    api_model *m;
    uint64_t version;
    persist_rc stored;        /* what the store said */
} embed_commit;

static int commit_embed(void *ud, api_problem *p)
{
    embed_commit *c = ud;
    return store_snapshot_rc(c->r, c->m, c->version - 1, c->version, &c->stored, p);
}

/* PUT or DELETE of an embedded model: a change of the current model in place (api/embedded.h)
 * under the session's write lock, If-Match checked, stored by its commit, then a new version
 * told to the listeners. 0 (*version the new one) or the problem's status. */
typedef struct embed_op {
    enum { EMBED_PUT, EMBED_DELETE } kind;
    api_embed_def *def;       /* PUT */
    const char *name;         /* DELETE */
    json_t *summary;          /* PUT's answer */
} embed_op;

static int embed_change(req *r, embed_op *op, uint64_t *version, api_problem *p)
{
    for (int attempt = 0;; attempt++) { /* again on a compare-and-set lost (change()) */
        pthread_mutex_lock(&r->s->write);
        api_model *m = session_model(r->s, version);
        api_slot slot = slot_of(r);
        embed_commit ec = {r, m, *version + 1, PERSIST_OK};
        api_edit_commit commit = {commit_embed, &ec};
        int rc = if_match(r, *version, p);
        if (!rc && op->kind == EMBED_PUT)
            rc = api_embed_put(m, op->def, *version + 1, &r->srv->cfg.limits, &slot, &commit,
                               &op->summary, p);
        else if (!rc)
            rc = api_embed_delete(m, op->name, *version + 1, &commit, p);
        if (!rc) {
            *version = session_bump(r->s);
            notify(r, *version, "embedded", NULL);
        }
        pthread_mutex_unlock(&r->s->write);
        api_model_unref(m);
        if (!rc || !(ec.stored == PERSIST_CONFLICT && attempt < RELOAD_TRIES && reload_unconditional(r, attempt)))
            return rc;
        json_decref(op->summary);
        op->summary = NULL;
        memset(p, 0, sizeof *p);
    }
}

/* A body the handler answers itself (api_malloc'd), with the version as ETag. */
static void reply_body(req *r, char *body, size_t len, const char *ctype, uint64_t version)
{
    struct MHD_Response *resp = http_buffer_response(ctype, body, len);
    if (!resp) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    atomic_store(&r->bytes, len);
    http_set_etag(resp, version);
    http_queue(r, 200, resp);
}

/* PUT /embedded/{name}: JSON {"vertices", "triangles", "level", "outside"}, or the binary layout
 * (application/octet-stream, level and outside in the query). Bound in a compute slot, stored,
 * published in place with a new version, told to the listeners (kind "embedded"). */
static void h_put_embedded(req *r)
{
    api_problem p = {0};
    api_embed_def *d = NULL;
    const char *ct = http_header(r, "Content-Type");
    int rc;
    if (ct && !strncasecmp(ct, "application/octet-stream", 24)) {
        rc = api_embed_parse_binary(r->body ? r->body : "", r->len, r->seg_level,
                                    http_arg(r, "level"), http_arg(r, "outside"),
                                    &r->srv->cfg.limits, &d, &p);
    } else {
        if (http_arg(r, "level") || http_arg(r, "outside")) {
            api_fail_at(&p, 400, "bad-parameter", http_arg(r, "level") ? "level" : "outside",
                        "level and outside go in the JSON body (the query is for binary bodies)");
            http_reply_problem(r, &p);
            return;
        }
        json_t *b = body_or_answer(r, NULL, NULL);
        if (!b)
            return;
        rc = api_embed_parse(b, r->seg_level, &r->srv->cfg.limits, &d, &p);
        json_decref(b);
    }
    if (rc) {
        http_reply_problem(r, &p);
        return;
    }
    embed_op op = {EMBED_PUT, d, NULL, NULL};
    uint64_t version;
    rc = embed_change(r, &op, &version, &p);
    api_embed_def_unref(d);
    if (rc) {
        http_reply_problem(r, &p);
        return;
    }
    http_reply_json(r, 200, json_pack("{s:I, s:o}", "version", (json_int_t)version, "embedded",
                                      op.summary ? op.summary : json_object()), version);
}

static void h_delete_embedded(req *r)
{
    api_problem p = {0};
    embed_op op = {EMBED_DELETE, NULL, r->seg_level, NULL};
    uint64_t version;
    if (embed_change(r, &op, &version, &p)) {
        http_reply_problem(r, &p);
        return;
    }
    struct MHD_Response *resp = http_empty();
    http_set_etag(resp, version);
    http_queue(r, 204, resp);
}

static void h_list_embedded(req *r)
{
    uint64_t version;
    api_model *m = session_model(r->s, &version);
    json_t *j = api_embed_list(m);
    api_model_unref(m);
    if (!j) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    http_reply_json(r, 200, json_pack("{s:I, s:o}", "version", (json_int_t)version, "embedded", j),
                    version);
}

static void h_get_embedded(req *r)
{
    api_problem p = {0};
    api_model *m = session_model(r->s, NULL);
    char *body;
    size_t len;
    const char *ctype;
    uint64_t v;
    int rc = api_embed_get(m, r->seg_level, http_arg(r, "format"), &body, &len, &ctype, &v, &p);
    api_model_unref(m);
    if (rc) {
        http_reply_problem(r, &p);
        return;
    }
    reply_body(r, body, len, ctype, v);
}

static void h_embedded_delta(req *r)
{
    api_problem p = {0};
    api_model *m = session_model(r->s, NULL);
    char *body;
    size_t len;
    const char *ctype;
    uint64_t v;
    int rc = api_embed_delta(m, r->seg_level, http_arg(r, "since"), http_arg(r, "format"), &body,
                             &len, &ctype, &v, &p);
    api_model_unref(m);
    if (rc) {
        http_reply_problem(r, &p);
        return;
    }
    reply_body(r, body, len, ctype, v);
}

/* ---- handlers: events ------------------------------------------------------------------- */

static const char *const EVENTS_KEYS[] = {"access_token", NULL};

/* GET /events: a text/event-stream of the session's versions (server/events.h), at most
 * --max-listeners per session (429). Last-Event-ID replays what the client missed; one that is
 * not a version gets `event: resync`. The stream holds no lock: a client that does not read is
 * dropped by the hub and never slows a change. */
static void h_events(req *r)
{
    /* a listener does not keep its session: it expires idle as without one (`event: deleted`,
     * reason expired, ends the stream) */
    store_unuse(r->srv->st, r->s);
    r->using = 0;
    uint64_t version, last = 0;
    api_model_unref(session_model(r->s, &version));
    const char *lei = http_header(r, "Last-Event-ID");
    if (lei) {
        char *end;
        errno = 0;
        last = strtoull(lei, &end, 10);
        if (!isdigit((unsigned char)*lei) || *end || errno)
            last = UINT64_MAX; /* ahead of every version: resync */
    }
    int full;
    struct ev_listener *l = ev_listen(r->s->events, lei != NULL, last, version,
                                      (unsigned)r->srv->cfg.max_listeners, &full);
    if (!l && full) {
        api_problem p = {0};
        p.retry_after = 5;
        api_fail(&p, 429, "too-many-listeners",
                 "this session has %d event streams open, its maximum; close one or retry later",
                 r->srv->cfg.max_listeners);
        http_reply_problem(r, &p);
        return;
    }
    if (!l) {
        http_fail(r, 503, "out-of-memory", "out of memory");
        return;
    }
    http_reply_events(r, l);
}

static const char *const ANALYSIS_KEYS[] = {"vertex", "edge", NULL};

static void h_analysis(req *r)
{
    api_model *m = session_model(r->s, NULL);
    api_problem p = {0};
    api_slot slot = slot_of(r);
    json_t *j = api_analysis(m, http_arg(r, "vertex"), http_arg(r, "edge"),
                             &r->srv->cfg.limits, &slot, &p);
    uint64_t version = atomic_load(&m->version);
    api_model_unref(m);
    http_reply_versioned(r, j, version, &p);
}

/* ---- routing ---------------------------------------------------------------------------- */

static const route ROUTES[] = {
    {"POST", "/v1/sessions", h_create_session, 0, 1, NULL},
    {"GET", "/v1/sessions/{id}", h_get_session, 1, 0, NULL},
    {"PATCH", "/v1/sessions/{id}", h_patch_session, 1, 1, NULL},
    {"DELETE", "/v1/sessions/{id}", h_delete_session, 1, 0, NULL},
    {"PUT", "/v1/sessions/{id}/complex", h_put_complex, 1, 1, NULL},
    {"GET", "/v1/sessions/{id}/complex", h_get_complex, 1, 0, NULL},
    {"GET", "/v1/sessions/{id}/export", h_export, 1, 0, NULL},
    {"PATCH", "/v1/sessions/{id}/control-points", h_edit, 1, 1, EDIT_KEYS},
    {"POST", "/v1/sessions/{id}/refine", h_refine, 1, 1, NULL},
    {"PUT", "/v1/sessions/{id}/tags", h_put_tags, 1, 1, NULL},
    {"PUT", "/v1/sessions/{id}/rules", h_put_rules, 1, 1, NULL},
    {"GET", "/v1/sessions/{id}/levels/{L}", h_get_level, 1, 0, LEVEL_KEYS},
    {"GET", "/v1/sessions/{id}/levels/{L}/stats", h_level_stats, 1, 0, NULL},
    {"GET", "/v1/sessions/{id}/levels/{L}/delta", h_delta, 1, 0, LEVEL_DELTA_KEYS},
    {"GET", "/v1/sessions/{id}/events", h_events, 1, 0, EVENTS_KEYS},
    {"GET", "/v1/sessions/{id}/embedded", h_list_embedded, 1, 0, NULL},
    {"PUT", "/v1/sessions/{id}/embedded/{name}", h_put_embedded, 1, 2, EMBED_PUT_KEYS},
    {"GET", "/v1/sessions/{id}/embedded/{name}", h_get_embedded, 1, 0, EMBED_GET_KEYS},
    {"DELETE", "/v1/sessions/{id}/embedded/{name}", h_delete_embedded, 1, 0, NULL},
    {"GET", "/v1/sessions/{id}/embedded/{name}/delta", h_embedded_delta, 1, 0, EMBED_DELTA_KEYS},
    {"GET", "/v1/sessions/{id}/analysis", h_analysis, 1, 0, ANALYSIS_KEYS},
    {"GET", "/v1/sessions/{id}/matrices/{L}", h_matrix, 1, 0, MATRIX_KEYS},
    {"GET", "/healthz", h_healthz, 0, 0, NULL},
    {"GET", "/livez", h_healthz, 0, 0, NULL},
    {"GET", "/readyz", h_readyz, 0, 0, NULL},
    {"GET", "/metrics", h_metrics, 0, 0, NULL},
    {"GET", "/v1/openapi.json", h_asset, 0, 0, NULL},
    {"GET", "/errors/{slug}", h_error_page, 0, 0, NULL},
};
#define NROUTES (sizeof ROUTES / sizeof *ROUTES)

void route_list(FILE *f)
{
    for (size_t i = 0; i < NROUTES; i++)
        fprintf(f, "%s %s\n", ROUTES[i].method, ROUTES[i].pattern);
}

int route_match(const char *pattern, const char *path, req *r)
{
    return parse_route(pattern, path, r->seg_id, sizeof r->seg_id, r->seg_level,
                       sizeof r->seg_level);
}

int route_methods(const char *path, req *r, char *allow, size_t cap)
{
    int n = 0;
    allow[0] = 0;
    for (size_t i = 0; i < NROUTES; i++)
        if (route_match(ROUTES[i].pattern, path, r)) {
            snprintf(allow + strlen(allow), cap - strlen(allow), "%s%s", n ? ", " : "",
                     ROUTES[i].method);
            n++;
            if (!strcmp(ROUTES[i].method, "GET")) {
                snprintf(allow + strlen(allow), cap - strlen(allow), ", HEAD");
            }
        }
    return n;
}

const route *route_find(const char *method, const char *path, req *r)
{
    const char *want = !strcmp(method, "HEAD") ? "GET" : method;
    for (size_t i = 0; i < NROUTES; i++)
        if (!strcmp(ROUTES[i].method, want) && route_match(ROUTES[i].pattern, path, r))
            return &ROUTES[i];
    return NULL;
}

const char *route_name_of(const char *path, req *r)
{
    const char *name = "unknown";
    for (size_t i = 0; i < NROUTES; i++)
        if (route_match(ROUTES[i].pattern, path, r))
            name = ROUTES[i].pattern;
    return name;
}

const char *route_kind(const route *rt)
{
    static const struct { const char *tail, *kind; } K[] = {
        {"/complex", "complex"}, {"/tags", "tags"},           {"/rules", "rules"},
        {"/refine", "refine"},   {"/control-points", "edit"}, {"/levels/{L}", "level"},
        {"/stats", "stats"},     {"/delta", "delta"},         {"/analysis", "analysis"},
        {"/matrices/{L}", "matrix"},
    };
    size_t n = rt ? strlen(rt->pattern) : 0;
    for (size_t i = 0; i < sizeof K / sizeof *K; i++) {
        size_t t = strlen(K[i].tail);
        if (n >= t && !strcmp(rt->pattern + n - t, K[i].tail))
            return K[i].kind;
    }
    return "other";
}

int route_is_static(const char *path)
{
    return !strncmp(path, "/v1/", 4) ? 0 : asset_find(path) != NULL;
}

const route *route_static(void)
{
    static const char *const any[] = {"*", NULL}; /* a page's links may carry queries */
    static const route asset_route = {"GET", "static", h_asset, 0, 0, any};
    return &asset_route;
}
