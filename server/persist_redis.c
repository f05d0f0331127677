/* persist_redis.c — the redis back end of persist.h ("redis://HOST:PORT"): one redis server
 * shared by several daemons, each session stored under three keys.
 *
 * Data model (every key of a session carries the same EXPIREAT = expires_at, so redis forgets an
 * expired session by itself; the braces are a Redis Cluster hash tag: a session's three keys are
 * in one slot, as a multi-key script needs):
 *   subdivd:s:{ID}     hash   token_hash (32 raw bytes), ttl_s, created, expires_at, version,
 *                             snapshot_version (decimal integers), owner (the client that
 *                             created it, hex; absent when unknown), counted_until (with an
 *                             owner: the id's score in its client's set, never before expires_at)
 *   subdivd:snap:{ID}  string the snapshot document (absent while snapshot_version is 0 and no
 *                             snapshot was written)
 *   subdivd:j:{ID}     list   the journal after the snapshot, oldest first, each entry
 *                             "<version> <text>" (decimal version, one space, the edit's body)
 *
 * and per client that created sessions (its own slot, so never inside a session's script):
 *   subdivd:o:{OWNER}  zset   the ids of its sessions, each scored with a time its record does
 *                             not outlive (counted_until), EXPIREAT the highest score: the set
 *                             outlives every session it names. A write that takes expires_at past
 *                             counted_until gives the record a new one, the expiry plus its TTL
 *                             (at least a minute: a session in use raises it about once a TTL),
 *                             which its script answers ({owner, counted_until}, not 1) and the
 *                             caller then writes to the set (LUA_INDEX). A member whose score is
 *                             past is an expired session and is dropped whenever the set is
 *                             written or counted; r_owned also checks each remaining member
 *                             against its record (deleted without the set being told, or a TTL
 *                             PATCHed shorter), so the count is exact.
 *   subdivd:a:{OWNER}  string held (SET NX PX ADMIT_HOLD_MS, a random value) while one daemon
 *                             counts the client's sessions and creates the one the count admits,
 *                             so that creates of one client through several daemons are counted one
 *                             after the other (r_admit); a holder that dies lets go when it expires.
 *
 * Every write that depends on the stored version is one Lua script (atomic on the server): it
 * reads the hash's version, answers -1 when the hash is gone (PERSIST_ABSENT), 0 when the version
 * is not `expect` (PERSIST_CONFLICT), else writes and answers 1 (or {owner, counted_until}, as
 * above). Versions are compared as the decimal strings this file writes, never as Lua numbers
 * (doubles: exact only up to 2^53; an expiry is a Lua number, exact). The
 * scripts are loaded (SCRIPT LOAD) at every connect and called by EVALSHA; a NOSCRIPT answer
 * (SCRIPT FLUSH, a failover to a replica that never saw them) falls back to EVAL, which also
 * caches the script again. Loading is one script too, so the record, the snapshot and the journal
 * are read at one instant.
 *
 * Connection: one redisContext guarded by a mutex, with a 1 s connect timeout and a 2 s command
 * timeout. An I/O error drops the connection; the call is retried once on a fresh connection when
 * the failed one was an older, reused one (redis restarted meanwhile: the command never reached
 * it), but never after a timeout (the command may have run: a retried compare-and-set would then
 * see its own write as a conflict). Otherwise the call answers PERSIST_UNAVAILABLE and the next
 * call connects again, so the daemon recovers by itself when redis comes back. Opening does not
 * need redis to be up: the first calls answer PERSIST_UNAVAILABLE until it is. last_error is kept
 * per thread ("redis 127.0.0.1:6379: Connection refused"), so it describes the caller's own
 * failure even when other threads fail meanwhile.
 */
#include "persist_impl.h"
#include <errno.h>
#include <hiredis/hiredis.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/time.h>
#include <time.h>

#define CONNECT_TIMEOUT_S 1
#define COMMAND_TIMEOUT_S 2
#define KEY_CAP 64          /* "subdivd:snap:{" + 32 + "}", "subdivd:o:{" + 39 + "}" */

/* The end of a script that wrote expires_at = X on success: {owner, counted_until} when the
 * record has an owner and X passed its counted_until (raised here to X + max(ttl_s, 60); the
 * caller writes it to the client's set), else 1. */
#define LUA_RECOUNT(X)                                                                            \
    "local o = redis.call('HGET', KEYS[1], 'owner')\n"                                            \
    "if not o then return 1 end\n"                                                                \
    "local x = tonumber(" X ")\n"                                                                 \
    "if x <= tonumber(redis.call('HGET', KEYS[1], 'counted_until') or '0') then return 1 end\n"   \
    "local u = string.format('%d', x + math.max(tonumber(redis.call('HGET', KEYS[1], 'ttl_s')), 60))\n" \
    "redis.call('HSET', KEYS[1], 'counted_until', u)\n"                                           \
    "return {o, u}\n"

/* KEYS: hash, snapshot, journal. ARGV: token_hash, ttl_s, created, expires_at, version, owner
 * ("" when none), counted_until (with an owner). */
static const char LUA_CREATE[] =
    "if redis.call('EXISTS', KEYS[1]) == 1 then return 0 end\n"
    "redis.call('DEL', KEYS[2], KEYS[3])\n"
    "redis.call('HSET', KEYS[1], 'token_hash', ARGV[1], 'ttl_s', ARGV[2], 'created', ARGV[3],\n"
    "           'expires_at', ARGV[4], 'version', ARGV[5], 'snapshot_version', '0')\n"
    "if ARGV[6] ~= '' then redis.call('HSET', KEYS[1], 'owner', ARGV[6], 'counted_until', ARGV[7]) end\n"
    "redis.call('EXPIREAT', KEYS[1], ARGV[4])\n"
    "return 1\n";

/* KEYS: hash, snapshot, journal. ARGV: expect, version, expires_at, document. */
static const char LUA_SNAPSHOT[] =
    "local v = redis.call('HGET', KEYS[1], 'version')\n"
    "if not v then return -1 end\n"
    "if v ~= ARGV[1] then return 0 end\n"
    "redis.call('SET', KEYS[2], ARGV[4])\n"
    "redis.call('DEL', KEYS[3])\n"
    "redis.call('HSET', KEYS[1], 'version', ARGV[2], 'snapshot_version', ARGV[2],\n"
    "           'expires_at', ARGV[3])\n"
    "redis.call('EXPIREAT', KEYS[1], ARGV[3])\n"
    "redis.call('EXPIREAT', KEYS[2], ARGV[3])\n"
    LUA_RECOUNT("ARGV[3]");

/* KEYS: hash, snapshot, journal. ARGV: expect, version, expires_at, entry. */
static const char LUA_APPEND[] =
    "local v = redis.call('HGET', KEYS[1], 'version')\n"
    "if not v then return -1 end\n"
    "if v ~= ARGV[1] then return 0 end\n"
    "redis.call('RPUSH', KEYS[3], ARGV[2] .. ' ' .. ARGV[4])\n"
    "redis.call('HSET', KEYS[1], 'version', ARGV[2], 'expires_at', ARGV[3])\n"
    "for i = 1, 3 do redis.call('EXPIREAT', KEYS[i], ARGV[3]) end\n"
    LUA_RECOUNT("ARGV[3]");

/* KEYS: hash, snapshot, journal. ARGV: expires_at[, ttl_s]. */
static const char LUA_TOUCH[] =
    "if redis.call('EXISTS', KEYS[1]) == 0 then return -1 end\n"
    "redis.call('HSET', KEYS[1], 'expires_at', ARGV[1])\n"
    "if ARGV[2] then redis.call('HSET', KEYS[1], 'ttl_s', ARGV[2]) end\n"
    "for i = 1, 3 do redis.call('EXPIREAT', KEYS[i], ARGV[1]) end\n"
    LUA_RECOUNT("ARGV[1]");

/* KEYS: hash, snapshot, journal. */
static const char LUA_DELETE[] =
    "local n = redis.call('DEL', KEYS[1])\n"
    "redis.call('DEL', KEYS[2], KEYS[3])\n"
    "if n == 0 then return -1 end\n"
    "return 1\n";

/* KEYS: hash, snapshot, journal. Answers -1 (no record) or {fields, snapshot or nil, journal}. */
static const char LUA_LOAD[] =
    "local h = redis.call('HMGET', KEYS[1], 'token_hash', 'ttl_s', 'created', 'expires_at',\n"
    "                     'version', 'snapshot_version', 'owner')\n"
    "if not h[5] then return -1 end\n"
    "return {h, redis.call('GET', KEYS[2]), redis.call('LRANGE', KEYS[3], 0, -1)}\n";

/* KEYS: a client's set. ARGV: id, counted_until, now. Drops the members whose score is before
 * now (their sessions expired), scores id with counted_until unless it has a later score (two
 * daemons' writes may arrive in either order), and lets the set expire with its highest score. */
static const char LUA_INDEX[] =
    "redis.call('ZREMRANGEBYSCORE', KEYS[1], '-inf', '(' .. ARGV[3])\n"
    "local s = redis.call('ZSCORE', KEYS[1], ARGV[1])\n"
    "if not s or tonumber(s) < tonumber(ARGV[2]) then\n"
    "  redis.call('ZADD', KEYS[1], ARGV[2], ARGV[1])\n"
    "end\n"
    "local top = redis.call('ZRANGE', KEYS[1], -1, -1, 'WITHSCORES')\n"
    "redis.call('EXPIREAT', KEYS[1], top[2])\n"
    "return 1\n";

/* KEYS: the admission key. ARGV: the value its holder set. Lets go only of one's own hold. */
static const char LUA_UNADMIT[] =
    "if redis.call('GET', KEYS[1]) == ARGV[1] then redis.call('DEL', KEYS[1]) end\n"
    "return 1\n";

enum { S_CREATE, S_SNAPSHOT, S_APPEND, S_TOUCH, S_DELETE, S_LOAD, S_INDEX, S_UNADMIT, NSCRIPTS };
static const char *const SCRIPTS[NSCRIPTS] = {LUA_CREATE, LUA_SNAPSHOT, LUA_APPEND, LUA_TOUCH,
                                              LUA_DELETE, LUA_LOAD,   LUA_INDEX,  LUA_UNADMIT};

typedef struct redis_backend {
    pthread_mutex_t mu;
    redisContext *c;          /* NULL while disconnected */
    bool fresh;               /* c was opened by the current call (a failure on it is not a
                                 stale connection: no retry) */
    char host[256];
    int port;
    char sha[NSCRIPTS][41];   /* SHA-1 of each script (the same on every server) */
} redis_backend;

static _Thread_local char last_err[320];

static void set_err(const redis_backend *b, const char *fmt, ...)
{
    int n = snprintf(last_err, sizeof last_err, "redis %s:%d: ", b->host, b->port);
    if (n < 0 || (size_t)n >= sizeof last_err)
        return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(last_err + n, sizeof last_err - (size_t)n, fmt, ap);
    va_end(ap);
}

/* hiredis reports a read timeout as the EAGAIN of the blocking socket. */
static bool is_timeout(const redisContext *c)
{
    return c->err == REDIS_ERR_IO && (strstr(c->errstr, "temporarily unavailable") ||
                                      strstr(c->errstr, "timed out"));
}

static void disconnect(redis_backend *b)
{
    if (b->c)
        redisFree(b->c);
    b->c = NULL;
}

static int connect_locked(redis_backend *b)
{
    struct timeval ct = {CONNECT_TIMEOUT_S, 0}, cmd = {COMMAND_TIMEOUT_S, 0};
    redisContext *c = redisConnectWithTimeout(b->host, b->port, ct);
    if (!c) {
        set_err(b, "out of memory");
        return -1;
    }
    if (c->err) {
        set_err(b, "%s", c->errstr);
        redisFree(c);
        return -1;
    }
    if (redisSetTimeout(c, cmd) != REDIS_OK || redisEnableKeepAlive(c) != REDIS_OK) {
        set_err(b, "%s", c->errstr[0] ? c->errstr : "cannot set socket options");
        redisFree(c);
        return -1;
    }
    for (int i = 0; i < NSCRIPTS; i++) {
        redisReply *r = redisCommand(c, "SCRIPT LOAD %s", SCRIPTS[i]);
        if (!r || r->type != REDIS_REPLY_STRING || r->len != 40) {
            if (!r)
                set_err(b, "%s", is_timeout(c) ? "command timed out" : c->errstr);
            else
                set_err(b, "SCRIPT LOAD: %.200s", r->type == REDIS_REPLY_ERROR ? r->str
                                                                               : "unexpected reply");
            if (r)
                freeReplyObject(r);
            redisFree(c);
            return -1;
        }
        memcpy(b->sha[i], r->str, 40);
        b->sha[i][40] = '\0';
        freeReplyObject(r);
    }
    b->c = c;
    b->fresh = true;
    return 0;
}

/* One command, with the reconnect policy of the header comment. NULL: unavailable (last_err). */
static redisReply *exec_locked(redis_backend *b, int argc, const char **argv, const size_t *len)
{
    for (int attempt = 0;; attempt++) {
        if (!b->c && connect_locked(b) < 0)
            return NULL;
        bool fresh = b->fresh;
        b->fresh = false;
        redisReply *r = redisCommandArgv(b->c, argc, argv, len);
        if (r)
            return r;
        bool timeout = is_timeout(b->c);
        set_err(b, "%s", timeout ? "command timed out" : b->c->errstr[0] ? b->c->errstr
                                                                         : "I/O error");
        disconnect(b);
        if (fresh || timeout || attempt > 0)
            return NULL;
    }
}

/* An error reply as a persist_rc: a value of the wrong type is damage, anything else (OOM,
 * LOADING, READONLY, a script error) means the store cannot be written now. */
static persist_rc error_reply(const redis_backend *b, const char *id, const redisReply *r)
{
    if (id)
        set_err(b, "session %s: %.200s", id, r->str ? r->str : "error reply");
    else
        set_err(b, "%.200s", r->str ? r->str : "error reply");
    return r->str && strstr(r->str, "WRONGTYPE") ? PERSIST_CORRUPT : PERSIST_UNAVAILABLE;
}

/* EVALSHA script (EVAL on NOSCRIPT) with nkeys (1 to 3) keys and nargs arguments. */
static redisReply *eval_keys_locked(redis_backend *b, int script, int nkeys, const char **keys,
                                    int nargs, const char **args, const size_t *lens)
{
    const char *argv[14];
    size_t len[14];
    if (!b->c && connect_locked(b) < 0)
        return NULL;
    char nk[2] = {(char)('0' + nkeys), 0};
    argv[0] = "EVALSHA";
    argv[1] = b->sha[script];
    argv[2] = nk;
    for (int i = 0; i < nkeys; i++)
        argv[3 + i] = keys[i];
    for (int i = 0; i < 3 + nkeys; i++)
        len[i] = strlen(argv[i]);
    for (int i = 0; i < nargs; i++) {
        argv[3 + nkeys + i] = args[i];
        len[3 + nkeys + i] = lens ? lens[i] : strlen(args[i]);
    }
    int argc = 3 + nkeys + nargs;
    redisReply *r = exec_locked(b, argc, argv, len);
    if (r && r->type == REDIS_REPLY_ERROR && r->str && !strncmp(r->str, "NOSCRIPT", 8)) {
        freeReplyObject(r);
        argv[0] = "EVAL";
        argv[1] = SCRIPTS[script];
        len[0] = 4;
        len[1] = strlen(SCRIPTS[script]);
        r = exec_locked(b, argc, argv, len);
    }
    return r;
}

/* The same with the session's three keys. */
static redisReply *eval_locked(redis_backend *b, int script, const char *id, int nargs,
                               const char **args, const size_t *lens)
{
    char kh[KEY_CAP], ks[KEY_CAP], kj[KEY_CAP];
    snprintf(kh, sizeof kh, "subdivd:s:{%s}", id);
    snprintf(ks, sizeof ks, "subdivd:snap:{%s}", id);
    snprintf(kj, sizeof kj, "subdivd:j:{%s}", id);
    const char *keys[3] = {kh, ks, kj};
    return eval_keys_locked(b, script, 3, keys, nargs, args, lens);
}

/* The answer of a compare-and-set script: 1 written, 0 conflict, -1 absent. */
static persist_rc cas_rc(const redis_backend *b, redisReply *r)
{
    persist_rc rc;
    if (!r)
        return PERSIST_UNAVAILABLE;
    if (r->type == REDIS_REPLY_ERROR)
        rc = error_reply(b, NULL, r);
    else if (r->type != REDIS_REPLY_INTEGER) {
        set_err(b, "unexpected reply type %d", r->type);
        rc = PERSIST_UNAVAILABLE;
    } else if (r->integer == 1)
        rc = PERSIST_OK;
    else if (r->integer == 0) {
        set_err(b, "version conflict");
        rc = PERSIST_CONFLICT;
    } else {
        set_err(b, "no such session");
        rc = PERSIST_ABSENT;
    }
    freeReplyObject(r);
    return rc;
}

static bool id_ok(const redis_backend *b, const char *id)
{
    size_t n = id ? strlen(id) : 0;
    if (n == 0 || n > 32) {
        set_err(b, "bad session id");
        return false;
    }
    return true;
}

/* ---- the operations ---- */

static bool parse_i64(const redisReply *r, int64_t *out);

/* The key of a client's set of session ids; false (last_err) for an owner too long for it. */
static bool owner_key(const redis_backend *b, const char *owner, char ko[KEY_CAP])
{
    if (strlen(owner) + 12 >= KEY_CAP) {
        set_err(b, "bad client key");
        return false;
    }
    snprintf(ko, KEY_CAP, "subdivd:o:{%s}", owner);
    return true;
}

/* Score id in its client's set with `until` (LUA_INDEX, which answers 1). Caller holds b->mu. */
static persist_rc index_locked(redis_backend *b, const char *owner, const char *id,
                               const char *until)
{
    char ko[KEY_CAP], now[24];
    if (!owner_key(b, owner, ko))
        return PERSIST_UNAVAILABLE;
    snprintf(now, sizeof now, "%" PRId64, (int64_t)time(NULL));
    const char *keys[1] = {ko}, *args[3] = {id, until, now};
    return cas_rc(b, eval_keys_locked(b, S_INDEX, 1, keys, 3, args, NULL));
}

/* The answer of a script ending in LUA_RECOUNT: {owner, counted_until} is success, and the id's
 * score in its client's set is raised to it here. Should that fail, the write stands (it is
 * made) and the record forgets its counted_until (when redis still answers), so that its next
 * write raises it again. Caller holds b->mu. */
static persist_rc recount_rc(redis_backend *b, const char *id, redisReply *r)
{
    if (!r || r->type != REDIS_REPLY_ARRAY)
        return cas_rc(b, r);
    char owner[PERSIST_OWNER_CAP], until[24];
    bool ok = r->elements == 2 && r->element[0]->type == REDIS_REPLY_STRING
              && r->element[0]->len > 0 && r->element[0]->len < sizeof owner
              && r->element[1]->type == REDIS_REPLY_STRING && r->element[1]->len > 0
              && r->element[1]->len < sizeof until;
    if (ok) {
        memcpy(owner, r->element[0]->str, r->element[0]->len);
        owner[r->element[0]->len] = '\0';
        memcpy(until, r->element[1]->str, r->element[1]->len);
        until[r->element[1]->len] = '\0';
    }
    freeReplyObject(r);
    if (ok && index_locked(b, owner, id, until) == PERSIST_OK)
        return PERSIST_OK;
    char kh[KEY_CAP];
    snprintf(kh, sizeof kh, "subdivd:s:{%s}", id);
    const char *argv[3] = {"HDEL", kh, "counted_until"};
    size_t len[3] = {4, strlen(kh), 13};
    if ((r = exec_locked(b, 3, argv, len)))
        freeReplyObject(r);
    set_err(b, "session %s: written, not yet counted for its client", id);
    return PERSIST_OK;
}

static persist_rc r_create(void *vb, const persist_meta *m)
{
    redis_backend *b = vb;
    if (!id_ok(b, m->id))
        return PERSIST_ABSENT;
    char ttl[24], created[24], exp[24], ver[24], until[24];
    snprintf(ttl, sizeof ttl, "%d", m->ttl_s);
    snprintf(created, sizeof created, "%" PRId64, m->created);
    snprintf(exp, sizeof exp, "%" PRId64, m->expires_at);
    snprintf(ver, sizeof ver, "%" PRIu64, m->version);
    snprintf(until, sizeof until, "%" PRId64, m->expires_at + (m->ttl_s > 60 ? m->ttl_s : 60));
    const char *args[7] = {(const char *)m->token_hash, ttl, created, exp, ver, m->owner, until};
    size_t lens[7] = {32, strlen(ttl), strlen(created), strlen(exp), strlen(ver), strlen(m->owner),
                      strlen(until)};
    pthread_mutex_lock(&b->mu);
    persist_rc rc = cas_rc(b, eval_locked(b, S_CREATE, m->id, 7, args, lens));
    if (rc == PERSIST_OK && m->owner[0]) /* counted for its client, or not created */
        rc = index_locked(b, m->owner, m->id, until);
    if (rc != PERSIST_OK && rc != PERSIST_CONFLICT && m->owner[0]) {
        char keep[sizeof last_err];
        memcpy(keep, last_err, sizeof keep);
        redisReply *r = eval_locked(b, S_DELETE, m->id, 0, NULL, NULL);
        if (r)
            freeReplyObject(r);
        memcpy(last_err, keep, sizeof keep);
    }
    pthread_mutex_unlock(&b->mu);
    if (rc == PERSIST_CONFLICT)
        set_err(b, "session %s exists", m->id);
    return rc;
}

static persist_rc write_cas(redis_backend *b, int script, const char *id, uint64_t expect,
                            uint64_t version, int64_t expires_at, const char *data, size_t len)
{
    if (!id_ok(b, id))
        return PERSIST_ABSENT;
    char e[24], v[24], x[24];
    snprintf(e, sizeof e, "%" PRIu64, expect);
    snprintf(v, sizeof v, "%" PRIu64, version);
    snprintf(x, sizeof x, "%" PRId64, expires_at);
    const char *args[4] = {e, v, x, data ? data : ""};
    size_t lens[4] = {strlen(e), strlen(v), strlen(x), data ? len : 0};
    pthread_mutex_lock(&b->mu);
    persist_rc rc = recount_rc(b, id, eval_locked(b, script, id, 4, args, lens));
    pthread_mutex_unlock(&b->mu);
    return rc;
}

static persist_rc r_snapshot(void *vb, const char *id, uint64_t expect, uint64_t version,
                             int64_t expires_at, const char *doc, size_t len)
{
    redis_backend *b = vb;
    if (version < expect) {
        set_err(b, "snapshot at version %" PRIu64 " after %" PRIu64, version, expect);
        return PERSIST_UNAVAILABLE;
    }
    return write_cas(b, S_SNAPSHOT, id, expect, version, expires_at, doc, len);
}

/* A journal must stay consecutive (persist_load checks it): an append that would break that is
 * refused here rather than found corrupt later. */
static persist_rc r_append(void *vb, const char *id, uint64_t expect, uint64_t version,
                           int64_t expires_at, const char *entry, size_t len)
{
    redis_backend *b = vb;
    if (version != expect + 1) {
        set_err(b, "journal entry for version %" PRIu64 " after %" PRIu64, version, expect);
        return PERSIST_UNAVAILABLE;
    }
    return write_cas(b, S_APPEND, id, expect, version, expires_at, entry, len);
}

static persist_rc r_touch(void *vb, const char *id, int ttl_s, int64_t expires_at)
{
    redis_backend *b = vb;
    if (!id_ok(b, id))
        return PERSIST_ABSENT;
    char x[24], t[16];
    snprintf(x, sizeof x, "%" PRId64, expires_at);
    snprintf(t, sizeof t, "%d", ttl_s);
    const char *args[2] = {x, t};
    pthread_mutex_lock(&b->mu);
    persist_rc rc = recount_rc(b, id, eval_locked(b, S_TOUCH, id, ttl_s > 0 ? 2 : 1, args, NULL));
    pthread_mutex_unlock(&b->mu);
    return rc;
}

/* The record's owner field into owner (cap bytes; "" when none or unreadable). Caller holds
 * b->mu. */
static void owner_locked(redis_backend *b, const char *id, char *owner, size_t cap)
{
    char kh[KEY_CAP];
    snprintf(kh, sizeof kh, "subdivd:s:{%s}", id);
    const char *argv[3] = {"HGET", kh, "owner"};
    size_t len[3] = {4, strlen(kh), 5};
    redisReply *r = exec_locked(b, 3, argv, len);
    owner[0] = '\0';
    if (r && r->type == REDIS_REPLY_STRING && r->len < cap) {
        memcpy(owner, r->str, r->len);
        owner[r->len] = '\0';
    }
    if (r)
        freeReplyObject(r);
}

/* Take id out of its client's set (a failure leaves it to r_owned, which finds it gone). */
static void unindex_locked(redis_backend *b, const char *owner, const char *id)
{
    char ko[KEY_CAP];
    if (!owner_key(b, owner, ko))
        return;
    const char *argv[3] = {"ZREM", ko, id};
    size_t len[3] = {4, strlen(ko), strlen(id)};
    redisReply *r = exec_locked(b, 3, argv, len);
    if (r)
        freeReplyObject(r);
}

static persist_rc r_delete(void *vb, const char *id)
{
    redis_backend *b = vb;
    if (!id_ok(b, id))
        return PERSIST_ABSENT;
    char owner[PERSIST_OWNER_CAP];
    pthread_mutex_lock(&b->mu);
    owner_locked(b, id, owner, sizeof owner);
    persist_rc rc = cas_rc(b, eval_locked(b, S_DELETE, id, 0, NULL, NULL));
    if (rc == PERSIST_OK && owner[0]) {
        char keep[sizeof last_err];
        memcpy(keep, last_err, sizeof keep);
        unindex_locked(b, owner, id);
        memcpy(last_err, keep, sizeof keep);
    }
    pthread_mutex_unlock(&b->mu);
    return rc;
}

/* HGET `field` of each of n hashes in one round trip (pipelined), the replies into out[]; false
 * when the store cannot be read (last_err; out[] then holds nothing). The reconnect policy of
 * exec_locked, but these are reads: retried after any failure on a reused connection. Caller
 * holds b->mu. */
static bool hget_many_locked(redis_backend *b, size_t n, char (*keys)[KEY_CAP], const char *field,
                             redisReply **out)
{
    for (int attempt = 0;; attempt++) {
        if (!b->c && connect_locked(b) < 0)
            return false;
        bool fresh = b->fresh;
        b->fresh = false;
        size_t got = 0;
        bool ok = true;
        for (size_t i = 0; ok && i < n; i++) {
            const char *argv[3] = {"HGET", keys[i], field};
            size_t len[3] = {4, strlen(keys[i]), strlen(field)};
            ok = redisAppendCommandArgv(b->c, 3, argv, len) == REDIS_OK;
        }
        while (ok && got < n) {
            void *r = NULL;
            if ((ok = redisGetReply(b->c, &r) == REDIS_OK && r))
                out[got++] = r;
        }
        if (ok)
            return true;
        for (size_t i = 0; i < got; i++)
            freeReplyObject(out[i]);
        set_err(b, "%s", is_timeout(b->c) ? "command timed out" : b->c->errstr[0] ? b->c->errstr
                                                                                : "I/O error");
        disconnect(b);
        if (fresh || attempt > 0)
            return false;
    }
}

/* One command whose answer is only checked for an error. Caller holds b->mu. */
static persist_rc command_locked(redis_backend *b, int argc, const char **argv, const size_t *len)
{
    redisReply *r = exec_locked(b, argc, argv, len);
    if (!r)
        return PERSIST_UNAVAILABLE;
    persist_rc rc = r->type == REDIS_REPLY_ERROR ? error_reply(b, NULL, r) : PERSIST_OK;
    freeReplyObject(r);
    return rc;
}

/* How long one admission may be held (a daemon that dies holding it blocks its client's creates
 * this long), and how long another waits for it: longer, so a dead holder's expires first. */
#define ADMIT_HOLD_MS 5000
#define ADMIT_WAIT_MS 7000
static _Thread_local char admit_value[33]; /* this thread's hold (the caller holds and lets go) */

/* Hold (or let go of) the admission of owner's new sessions among every daemon on this redis. */
static persist_rc r_admit(void *vb, const char *owner, bool hold)
{
    redis_backend *b = vb;
    char ka[KEY_CAP];
    if (strlen(owner) + 12 >= KEY_CAP) {
        set_err(b, "bad client key");
        return PERSIST_UNAVAILABLE;
    }
    snprintf(ka, KEY_CAP, "subdivd:a:{%s}", owner);
    if (!hold) {
        const char *keys[1] = {ka}, *args[1] = {admit_value};
        pthread_mutex_lock(&b->mu);
        redisReply *r = eval_keys_locked(b, S_UNADMIT, 1, keys, 1, args, NULL);
        pthread_mutex_unlock(&b->mu);
        persist_rc rc = !r ? PERSIST_UNAVAILABLE
                           : r->type == REDIS_REPLY_ERROR ? error_reply(b, NULL, r) : PERSIST_OK;
        if (r)
            freeReplyObject(r);
        return rc; /* a hold not let go expires by itself */
    }
    unsigned char rnd[16];
    if (getrandom(rnd, sizeof rnd, 0) != (ssize_t)sizeof rnd) {
        set_err(b, "no random bytes for the admission of a session");
        return PERSIST_UNAVAILABLE;
    }
    for (int i = 0; i < 16; i++)
        sprintf(admit_value + 2 * i, "%02x", rnd[i]);
    char px[16];
    snprintf(px, sizeof px, "%d", ADMIT_HOLD_MS);
    const char *argv[6] = {"SET", ka, admit_value, "NX", "PX", px};
    size_t len[6] = {3, strlen(ka), strlen(admit_value), 2, 2, strlen(px)};
    struct timespec pause = {0, 5 * 1000 * 1000};
    for (int waited_ms = 0;; waited_ms += 5) {
        pthread_mutex_lock(&b->mu);
        redisReply *r = exec_locked(b, 6, argv, len);
        pthread_mutex_unlock(&b->mu);
        if (!r)
            return PERSIST_UNAVAILABLE;
        int type = r->type;
        persist_rc rc = type == REDIS_REPLY_ERROR ? error_reply(b, NULL, r) : PERSIST_OK;
        freeReplyObject(r);
        if (type != REDIS_REPLY_NIL) /* OK: held (or an error) */
            return rc;
        if (waited_ms >= ADMIT_WAIT_MS) {
            set_err(b, "the admission of a new session of this client stayed held");
            return PERSIST_UNAVAILABLE;
        }
        nanosleep(&pause, NULL); /* another daemon is admitting one of this client's */
    }
}

#define OWNED_BATCH 64

/* The client's set without the members whose score is past (expired sessions), the others each
 * checked against its record, OWNED_BATCH records a round trip: a gone or expired one (deleted
 * without the set being told, or its TTL PATCHed shorter) is dropped, a live one counted, until
 * `enough`. */
static persist_rc r_owned(void *vb, const char *owner, int64_t now, long enough, long *n,
                          int64_t *soonest)
{
    redis_backend *b = vb;
    char ko[KEY_CAP], before[24];
    if (!owner_key(b, owner, ko))
        return PERSIST_UNAVAILABLE;
    snprintf(before, sizeof before, "(%" PRId64, now);
    const char *prune[4] = {"ZREMRANGEBYSCORE", ko, "-inf", before};
    size_t prl[4] = {16, strlen(ko), 4, strlen(before)};
    const char *argv[4] = {"ZRANGE", ko, "0", "-1"};
    size_t len[4] = {6, strlen(ko), 1, 2};
    pthread_mutex_lock(&b->mu);
    redisReply *ids = NULL;
    persist_rc rc = command_locked(b, 4, prune, prl);
    if (rc == PERSIST_OK && !(ids = exec_locked(b, 4, argv, len)))
        rc = PERSIST_UNAVAILABLE;
    else if (ids && ids->type == REDIS_REPLY_ERROR)
        rc = error_reply(b, NULL, ids);
    else if (ids && ids->type != REDIS_REPLY_ARRAY) {
        set_err(b, "unexpected ZRANGE reply");
        rc = PERSIST_UNAVAILABLE;
    }
    for (size_t at = 0; rc == PERSIST_OK && at < ids->elements && (enough <= 0 || *n < enough);) {
        char keys[OWNED_BATCH][KEY_CAP];
        const redisReply *member[OWNED_BATCH];
        const char *gone[2 + OWNED_BATCH] = {"ZREM", ko};
        size_t gl[2 + OWNED_BATCH] = {4, strlen(ko)}, k = 0;
        int ngone = 0;
        redisReply *r[OWNED_BATCH];
        for (; at < ids->elements && k < OWNED_BATCH; at++) {
            const redisReply *e = ids->element[at];
            if (e->type == REDIS_REPLY_STRING && e->len > 0 && e->len <= 32) {
                member[k] = e;
                snprintf(keys[k++], KEY_CAP, "subdivd:s:{%.*s}", (int)e->len, e->str);
            }
        }
        if (!hget_many_locked(b, k, keys, "expires_at", r)) {
            rc = PERSIST_UNAVAILABLE;
            break;
        }
        for (size_t i = 0; i < k; i++) {
            int64_t exp = 0;
            if (r[i]->type == REDIS_REPLY_ERROR && rc == PERSIST_OK)
                rc = error_reply(b, NULL, r[i]);
            else if (r[i]->type != REDIS_REPLY_STRING || !parse_i64(r[i], &exp) || exp < now) {
                gone[2 + ngone] = member[i]->str;
                gl[2 + ngone++] = member[i]->len;
            } else if (enough <= 0 || *n < enough) {
                ++*n;
                if (!*soonest || exp < *soonest)
                    *soonest = exp;
            }
            freeReplyObject(r[i]);
        }
        if (rc == PERSIST_OK && ngone) {
            char keep[sizeof last_err]; /* a failure leaves them to the next count */
            memcpy(keep, last_err, sizeof keep);
            redisReply *z = exec_locked(b, 2 + ngone, gone, gl);
            if (z)
                freeReplyObject(z);
            memcpy(last_err, keep, sizeof keep);
        }
    }
    if (ids)
        freeReplyObject(ids);
    pthread_mutex_unlock(&b->mu);
    return rc;
}

/* A decimal integer that is the whole of [s, s+n). */
static bool parse_u64(const char *s, size_t n, uint64_t *out)
{
    uint64_t v = 0;
    if (n == 0 || n > 20)
        return false;
    for (size_t i = 0; i < n; i++) {
        if (s[i] < '0' || s[i] > '9')
            return false;
        unsigned d = (unsigned)(s[i] - '0');
        if (v > (UINT64_MAX - d) / 10)
            return false;
        v = v * 10 + d;
    }
    *out = v;
    return true;
}

static bool parse_i64(const redisReply *r, int64_t *out)
{
    uint64_t v;
    if (!r || r->type != REDIS_REPLY_STRING)
        return false;
    bool neg = r->len > 0 && r->str[0] == '-';
    if (!parse_u64(r->str + neg, r->len - neg, &v) || v > (uint64_t)INT64_MAX)
        return false;
    *out = neg ? -(int64_t)v : (int64_t)v;
    return true;
}

static bool parse_version(const redisReply *r, uint64_t *out)
{
    return r && r->type == REDIS_REPLY_STRING && parse_u64(r->str, r->len, out);
}

static char *copy_text(const char *s, size_t n)
{
    char *t = malloc(n + 1);
    if (t) {
        memcpy(t, s, n);
        t[n] = '\0';
    }
    return t;
}

/* Free what was read of the content; the record (meta, record_ok) stays. */
static void free_partial(persist_loaded *l)
{
    free(l->snapshot);
    for (size_t i = 0; i < l->njournal; i++)
        free(l->journal[i].text);
    free(l->journal);
    l->snapshot = NULL;
    l->journal = NULL;
    l->snapshot_len = l->njournal = 0;
    l->snapshot_version = 0;
}

static persist_rc corrupt(const redis_backend *b, persist_loaded *out, const char *id,
                          const char *what)
{
    set_err(b, "session %s: %s", id, what);
    free_partial(out);
    return PERSIST_CORRUPT;
}

/* The reply of LUA_LOAD into out (the caller holds no lock: the reply is ours alone). */
static persist_rc parse_loaded(const redis_backend *b, const char *id, const redisReply *r,
                               persist_loaded *out)
{
    if (r->type == REDIS_REPLY_INTEGER) {
        set_err(b, "no such session");
        return PERSIST_ABSENT;
    }
    if (r->type != REDIS_REPLY_ARRAY || r->elements != 3 || r->element[0]->type != REDIS_REPLY_ARRAY
        || r->element[0]->elements != 7 || r->element[2]->type != REDIS_REPLY_ARRAY)
        return corrupt(b, out, id, "unexpected reply shape");
    redisReply **h = r->element[0]->element;
    const redisReply *snap = r->element[1], *j = r->element[2];
    persist_meta *m = &out->meta;
    int64_t ttl;
    snprintf(m->id, sizeof m->id, "%s", id);
    if (h[0]->type != REDIS_REPLY_STRING || h[0]->len != 32)
        return corrupt(b, out, id, "token_hash is not 32 bytes");
    memcpy(m->token_hash, h[0]->str, 32);
    if (!parse_i64(h[1], &ttl) || ttl < 0 || ttl > INT32_MAX || !parse_i64(h[2], &m->created)
        || !parse_i64(h[3], &m->expires_at) || !parse_version(h[4], &m->version)
        || !parse_version(h[5], &out->snapshot_version))
        return corrupt(b, out, id, "unreadable record field");
    m->ttl_s = (int)ttl;
    if (h[6]->type == REDIS_REPLY_STRING && h[6]->len < sizeof m->owner) {
        memcpy(m->owner, h[6]->str, h[6]->len);
        m->owner[h[6]->len] = '\0';
    }
    if (m->expires_at < (int64_t)time(NULL)) {
        memset(out, 0, sizeof *out);
        set_err(b, "session %s expired", id);
        return PERSIST_ABSENT;
    }
    out->record_ok = true; /* what follows is the content */
    if (out->snapshot_version > m->version)
        return corrupt(b, out, id, "snapshot_version after version");
    if (snap->type == REDIS_REPLY_STRING) {
        if (!(out->snapshot = copy_text(snap->str, snap->len)))
            goto oom;
        out->snapshot_len = snap->len;
    } else if (snap->type != REDIS_REPLY_NIL)
        return corrupt(b, out, id, "snapshot is not a string");
    else if (out->snapshot_version > 0)
        return corrupt(b, out, id, "snapshot missing");
    if (j->elements != m->version - out->snapshot_version)
        return corrupt(b, out, id, "journal length does not match the version");
    if (j->elements && !(out->journal = calloc(j->elements, sizeof *out->journal)))
        goto oom;
    for (size_t i = 0; i < j->elements; i++) {
        const redisReply *e = j->element[i];
        const char *sp = e->type == REDIS_REPLY_STRING ? memchr(e->str, ' ', e->len) : NULL;
        uint64_t v;
        if (!sp || !parse_u64(e->str, (size_t)(sp - e->str), &v))
            return corrupt(b, out, id, "unreadable journal entry");
        if (v != out->snapshot_version + 1 + i)
            return corrupt(b, out, id, "journal versions not consecutive");
        size_t n = e->len - (size_t)(sp + 1 - e->str);
        persist_entry *pe = &out->journal[out->njournal];
        if (!(pe->text = copy_text(sp + 1, n)))
            goto oom;
        pe->version = v;
        pe->len = n;
        out->njournal++;
    }
    return PERSIST_OK;
oom:
    free_partial(out);
    set_err(b, "out of memory reading session %s", id);
    return PERSIST_UNAVAILABLE;
}

static persist_rc r_load(void *vb, const char *id, persist_loaded *out)
{
    redis_backend *b = vb;
    memset(out, 0, sizeof *out);
    if (!id_ok(b, id))
        return PERSIST_ABSENT;
    pthread_mutex_lock(&b->mu);
    redisReply *r = eval_locked(b, S_LOAD, id, 0, NULL, NULL);
    pthread_mutex_unlock(&b->mu);
    if (!r)
        return PERSIST_UNAVAILABLE;
    persist_rc rc = r->type == REDIS_REPLY_ERROR ? error_reply(b, id, r) : parse_loaded(b, id, r, out);
    freeReplyObject(r);
    return rc;
}

static persist_rc r_version(void *vb, const char *id, uint64_t *version, int *ttl_s)
{
    redis_backend *b = vb;
    if (!id_ok(b, id))
        return PERSIST_ABSENT;
    char kh[KEY_CAP];
    snprintf(kh, sizeof kh, "subdivd:s:{%s}", id);
    const char *argv[5] = {"HMGET", kh, "version", "expires_at", "ttl_s"};
    size_t len[5] = {5, strlen(kh), 7, 10, 5};
    pthread_mutex_lock(&b->mu);
    redisReply *r = exec_locked(b, 5, argv, len);
    pthread_mutex_unlock(&b->mu);
    if (!r)
        return PERSIST_UNAVAILABLE;
    persist_rc rc;
    int64_t exp, ttl = 0;
    if (r->type == REDIS_REPLY_ERROR)
        rc = error_reply(b, id, r);
    else if (r->type != REDIS_REPLY_ARRAY || r->elements != 3) {
        set_err(b, "unexpected reply type %d", r->type);
        rc = PERSIST_UNAVAILABLE;
    } else if (r->element[0]->type == REDIS_REPLY_NIL) {
        set_err(b, "no such session");
        rc = PERSIST_ABSENT;
    } else if (!parse_version(r->element[0], version) || !parse_i64(r->element[1], &exp) ||
               !parse_i64(r->element[2], &ttl) || ttl < 0 || ttl > INT32_MAX) {
        set_err(b, "session %s: unreadable record field", id);
        rc = PERSIST_CORRUPT;
    } else if (exp < (int64_t)time(NULL)) {
        set_err(b, "session %s expired", id);
        rc = PERSIST_ABSENT;
    } else {
        rc = PERSIST_OK;
        if (ttl_s)
            *ttl_s = (int)ttl;
    }
    freeReplyObject(r);
    return rc;
}

/* A write of a short-lived key (OOM, READONLY, MISCONF and a lost connection all refuse it). */
static persist_rc r_probe(void *vb)
{
    redis_backend *b = vb;
    const char *argv[5] = {"SET", "subdivd:probe", "1", "PX", "10000"};
    size_t len[5] = {3, 13, 1, 2, 5};
    pthread_mutex_lock(&b->mu);
    persist_rc rc = command_locked(b, 5, argv, len);
    pthread_mutex_unlock(&b->mu);
    return rc;
}

/* Redis expires the keys itself (EXPIREAT on every key). */
static long r_expire(void *vb, int64_t now)
{
    (void)vb;
    (void)now;
    return 0;
}

/* SCAN over the records: O(n) in the keys of the database. SCAN may return a key twice while the
 * table is resized, so the count is exact only on a quiet store (it is for /metrics). */
static long r_count(void *vb, int64_t now)
{
    redis_backend *b = vb;
    (void)now;
    char cursor[24] = "0";
    long n = 0;
    pthread_mutex_lock(&b->mu);
    do {
        const char *argv[6] = {"SCAN", cursor, "MATCH", "subdivd:s:*", "COUNT", "1000"};
        size_t len[6] = {4, strlen(cursor), 5, 11, 5, 4};
        redisReply *r = exec_locked(b, 6, argv, len);
        if (!r) {
            n = -1;
            break;
        }
        if (r->type != REDIS_REPLY_ARRAY || r->elements != 2
            || r->element[0]->type != REDIS_REPLY_STRING || r->element[0]->len >= sizeof cursor
            || r->element[1]->type != REDIS_REPLY_ARRAY) {
            if (r->type == REDIS_REPLY_ERROR)
                error_reply(b, NULL, r);
            else
                set_err(b, "unexpected SCAN reply");
            freeReplyObject(r);
            n = -1;
            break;
        }
        memcpy(cursor, r->element[0]->str, r->element[0]->len);
        cursor[r->element[0]->len] = '\0';
        n += (long)r->element[1]->elements;
        freeReplyObject(r);
    } while (strcmp(cursor, "0") != 0);
    pthread_mutex_unlock(&b->mu);
    return n;
}

static const char *r_last_error(void *vb)
{
    (void)vb;
    return last_err;
}

/* Every message starts "redis HOST:PORT: " (set_err). */
static const char *r_last_what(void *vb)
{
    const redis_backend *b = vb;
    int at = snprintf(NULL, 0, "redis %s:%d: ", b->host, b->port);
    return at > 0 && (size_t)at <= strlen(last_err) ? last_err + at : last_err;
}

static void r_close(void *vb)
{
    redis_backend *b = vb;
    if (!b)
        return;
    disconnect(b);
    pthread_mutex_destroy(&b->mu);
    free(b);
}

void *persist_redis_open(const char *host, int port, char *err, size_t cap)
{
    if (!host || !*host || strlen(host) >= sizeof ((redis_backend *)0)->host || port <= 0
        || port > 65535) {
        snprintf(err, cap, "redis: bad address %s:%d", host ? host : "", port);
        return NULL;
    }
    redis_backend *b = calloc(1, sizeof *b);
    if (!b) {
        snprintf(err, cap, "redis: out of memory");
        return NULL;
    }
    pthread_mutex_init(&b->mu, NULL);
    snprintf(b->host, sizeof b->host, "%s", host);
    b->port = port;
    /* a first connection now, so a reachable server is ready for the first request; an
     * unreachable one is not an error here (see the header comment) */
    pthread_mutex_lock(&b->mu);
    connect_locked(b);
    b->fresh = false;   /* the first call may find it stale */
    pthread_mutex_unlock(&b->mu);
    return b;
}

const persist_ops persist_redis_ops = {
    .create = r_create,
    .snapshot = r_snapshot,
    .append = r_append,
    .touch = r_touch,
    .del = r_delete,
    .version = r_version,
    .load = r_load,
    .expire = r_expire,
    .count = r_count,
    .owned = r_owned,
    .admit = r_admit,
    .probe = r_probe,
    .last_error = r_last_error,
    .last_what = r_last_what,
    .close = r_close,
};
