/* persist_sqlite.c — the SQLite back end of persist.h: one file, WAL mode, for one daemon.
 *
 *   sessions(id PRIMARY KEY, token_hash, ttl_s, created, expires_at, version,
 *            snapshot_version, snapshot, snapshot_crc, owner)
 *   journal(id, version, entry, crc; PRIMARY KEY (id, version))
 *
 * A write is one transaction (BEGIN IMMEDIATE … COMMIT) whose first statement is the
 * compare-and-set: UPDATE sessions … WHERE id = ? AND version = expect; no row changed means the
 * session is gone or another writer got there first, and the transaction is rolled back. With
 * `synchronous=NORMAL` a commit is an append to the write-ahead log, not an fsync: it survives
 * the daemon's crash (kill -9), not a power cut (that is `--sync full`). Every snapshot and
 * journal entry carries its CRC-32 (zlib), so damaged bytes are found when the session is loaded
 * (PERSIST_CORRUPT) instead of being replayed.
 *
 * `owner` (the client that created the session, NULL when unknown) came later: a file written
 * before has the column added when it is opened (its sessions count for nobody).
 *
 * One connection, serialised by a mutex: the statements are prepared once and each write is tens
 * of microseconds. SUBDIVD_SQLITE_MAX_PAGES (a test hook) caps the file at its size when opened
 * plus that many pages, so a test can fill "the disk" (SQLITE_FULL) without filling one.
 */
#include "persist_impl.h"
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <time.h>
#include <unistd.h>
#include <zlib.h>

enum {
    Q_BEGIN, Q_COMMIT, Q_ROLLBACK, Q_BEGIN_READ, Q_CREATE, Q_CAS_SNAP, Q_CAS_APPEND, Q_DEL_JOURNAL,
    Q_ADD_ENTRY, Q_VERSION, Q_TOUCH, Q_DELETE, Q_LOAD, Q_LOAD_JOURNAL, Q_EXPIRE_J, Q_EXPIRE_S,
    Q_COUNT, Q_OWNED, Q_PROBE_PUT, Q_PROBE_DEL, NQ
};

static const char *const SQL[NQ] = {
    [Q_BEGIN] = "BEGIN IMMEDIATE",
    [Q_COMMIT] = "COMMIT",
    [Q_ROLLBACK] = "ROLLBACK",
    [Q_BEGIN_READ] = "BEGIN",
    [Q_CREATE] = "INSERT INTO sessions(id, token_hash, ttl_s, created, expires_at, version, "
                 "snapshot_version, owner) VALUES (?1, ?2, ?3, ?4, ?5, ?6, 0, ?7)",
    [Q_CAS_SNAP] = "UPDATE sessions SET version = ?3, snapshot_version = ?3, snapshot = ?4, "
                   "snapshot_crc = ?5, expires_at = ?6 WHERE id = ?1 AND version = ?2",
    [Q_CAS_APPEND] = "UPDATE sessions SET version = ?3, expires_at = ?4 WHERE id = ?1 AND version = ?2",
    [Q_DEL_JOURNAL] = "DELETE FROM journal WHERE id = ?1",
    [Q_ADD_ENTRY] = "INSERT INTO journal(id, version, entry, crc) VALUES (?1, ?2, ?3, ?4)",
    [Q_VERSION] = "SELECT version, expires_at, ttl_s FROM sessions WHERE id = ?1",
    [Q_TOUCH] = "UPDATE sessions SET expires_at = ?2, ttl_s = coalesce(?3, ttl_s) WHERE id = ?1",
    [Q_DELETE] = "DELETE FROM sessions WHERE id = ?1",
    [Q_LOAD] = "SELECT token_hash, ttl_s, created, expires_at, version, snapshot_version, snapshot, "
               "snapshot_crc, owner FROM sessions WHERE id = ?1",
    [Q_LOAD_JOURNAL] = "SELECT version, entry, crc FROM journal WHERE id = ?1 AND version > ?2 "
                       "ORDER BY version",
    [Q_EXPIRE_J] = "DELETE FROM journal WHERE id IN (SELECT id FROM sessions WHERE expires_at < ?1)",
    [Q_EXPIRE_S] = "DELETE FROM sessions WHERE expires_at < ?1",
    [Q_COUNT] = "SELECT count(*) FROM sessions WHERE expires_at >= ?1",
    [Q_OWNED] = "SELECT count(*), min(expires_at) FROM sessions WHERE owner = ?1 AND expires_at >= ?2",
    [Q_PROBE_PUT] = "INSERT OR REPLACE INTO probe(k, v) VALUES (1, zeroblob(65536))",
    [Q_PROBE_DEL] = "DELETE FROM probe",
};

static const char SCHEMA[] =
    "CREATE TABLE IF NOT EXISTS sessions(id TEXT PRIMARY KEY, token_hash BLOB NOT NULL, "
    "ttl_s INTEGER NOT NULL, created INTEGER NOT NULL, expires_at INTEGER NOT NULL, "
    "version INTEGER NOT NULL, snapshot_version INTEGER NOT NULL, snapshot BLOB, "
    "snapshot_crc INTEGER, owner TEXT);"
    "CREATE TABLE IF NOT EXISTS journal(id TEXT NOT NULL, version INTEGER NOT NULL, "
    "entry BLOB NOT NULL, crc INTEGER NOT NULL, PRIMARY KEY (id, version)) WITHOUT ROWID;"
    "CREATE INDEX IF NOT EXISTS sessions_expiry ON sessions(expires_at);"
    "CREATE TABLE IF NOT EXISTS probe(k INTEGER PRIMARY KEY, v BLOB);";

typedef struct sqlite_store {
    pthread_mutex_t mu;
    sqlite3 *db;
    sqlite3_stmt *q[NQ];
    char path[512];
    char err[640];
    int lock_fd;              /* the file, flock()ed: one daemon per SQLite file */
} sqlite_store;

static void note(sqlite_store *s, const char *what)
{
    snprintf(s->err, sizeof s->err, "sqlite %.200s: %s: %s", s->path, what, sqlite3_errmsg(s->db));
}

void *persist_sqlite_open(const char *path, bool sync_full, char *err, size_t cap)
{
    sqlite_store *s = calloc(1, sizeof *s);
    if (!s) {
        snprintf(err, cap, "out of memory");
        return NULL;
    }
    snprintf(s->path, sizeof s->path, "%s", path);
    /* Only a shared store (redis) tells a daemon that another one changed a session; two daemons
     * on one SQLite file would each serve their own resident copies, so the second is refused,
     * before it touches the file (an flock, which the kernel drops with the process, kill -9
     * included; SQLite's own locks are POSIX ones, which an flock does not meet). */
    s->lock_fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    bool busy = s->lock_fd < 0 || flock(s->lock_fd, LOCK_EX | LOCK_NB) != 0;
    if (busy) {
        int e = errno;
        snprintf(err, cap, "sqlite %.200s: %s", path, e == EWOULDBLOCK
                 ? "in use by another daemon (one daemon per SQLite file; several daemons share "
                   "a redis store, docs/DEPLOY.md)" : strerror(e));
        if (s->lock_fd >= 0)
            close(s->lock_fd);
        free(s);
        return NULL;
    }
    int rc = sqlite3_open_v2(path, &s->db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE |
                                               SQLITE_OPEN_NOMUTEX, NULL);
    char pragmas[160];
    snprintf(pragmas, sizeof pragmas,
             "PRAGMA journal_mode=WAL; PRAGMA synchronous=%s; PRAGMA busy_timeout=2000;",
             sync_full ? "FULL" : "NORMAL");
    char *msg = NULL;
    if (rc == SQLITE_OK && (rc = sqlite3_exec(s->db, pragmas, NULL, NULL, &msg)) == SQLITE_OK)
        rc = sqlite3_exec(s->db, SCHEMA, NULL, NULL, &msg);
    if (rc == SQLITE_OK) { /* a file from before owners were kept */
        sqlite3_stmt *probe = NULL;
        if (sqlite3_prepare_v2(s->db, "SELECT owner FROM sessions LIMIT 0", -1, &probe, NULL))
            rc = sqlite3_exec(s->db, "ALTER TABLE sessions ADD COLUMN owner TEXT", NULL, NULL, &msg);
        sqlite3_finalize(probe);
    }
    if (rc == SQLITE_OK)
        rc = sqlite3_exec(s->db, "CREATE INDEX IF NOT EXISTS sessions_owner ON "
                                 "sessions(owner, expires_at)", NULL, NULL, &msg);
    for (int i = 0; rc == SQLITE_OK && i < NQ; i++)
        rc = sqlite3_prepare_v3(s->db, SQL[i], -1, SQLITE_PREPARE_PERSISTENT, &s->q[i], NULL);
    const char *cap_pages = getenv("SUBDIVD_SQLITE_MAX_PAGES");
    if (rc == SQLITE_OK && cap_pages && *cap_pages) {
        sqlite3_stmt *st;
        long long have = 0;
        if (sqlite3_prepare_v2(s->db, "PRAGMA page_count", -1, &st, NULL) == SQLITE_OK) {
            if (sqlite3_step(st) == SQLITE_ROW)
                have = sqlite3_column_int64(st, 0);
            sqlite3_finalize(st);
        }
        char q[96];
        snprintf(q, sizeof q, "PRAGMA max_page_count=%lld", have + atoll(cap_pages));
        rc = sqlite3_exec(s->db, q, NULL, NULL, &msg);
    }
    if (rc != SQLITE_OK) {
        snprintf(err, cap, "sqlite %.200s: %s", path, msg ? msg : s->db ? sqlite3_errmsg(s->db) : "cannot open");
        sqlite3_free(msg);
        for (int i = 0; i < NQ; i++)
            sqlite3_finalize(s->q[i]);
        sqlite3_close(s->db);
        close(s->lock_fd);
        free(s);
        return NULL;
    }
    pthread_mutex_init(&s->mu, NULL);
    return s;
}

static void sq_close(void *b)
{
    sqlite_store *s = b;
    for (int i = 0; i < NQ; i++)
        sqlite3_finalize(s->q[i]);
    sqlite3_close(s->db);
    if (s->lock_fd >= 0)
        close(s->lock_fd); /* the flock goes with it */
    pthread_mutex_destroy(&s->mu);
    free(s);
}

static const char *sq_last_error(void *b) { return ((sqlite_store *)b)->err; }

/* Every message starts "sqlite PATH: ". */
static const char *sq_last_what(void *b)
{
    sqlite_store *s = b;
    int at = snprintf(NULL, 0, "sqlite %.200s: ", s->path);
    return at > 0 && (size_t)at <= strlen(s->err) ? s->err + at : s->err;
}

/* Step a statement that returns no rows, then reset it; the sqlite result code. */
static int run(sqlite_store *s, int q)
{
    int rc = sqlite3_step(s->q[q]);
    sqlite3_reset(s->q[q]);
    sqlite3_clear_bindings(s->q[q]);
    return rc == SQLITE_ROW ? SQLITE_DONE : rc;
}

static persist_rc failed(sqlite_store *s, const char *what, int rc)
{
    note(s, what);
    return rc == SQLITE_CORRUPT || rc == SQLITE_NOTADB ? PERSIST_CORRUPT : PERSIST_UNAVAILABLE;
}

static uint32_t crc_of(const char *p, size_t n)
{
    return (uint32_t)crc32(crc32(0L, Z_NULL, 0), (const Bytef *)p, (uInt)n);
}

/* After a compare-and-set changed no row: is the session gone, or at another version? */
static persist_rc why_not(sqlite_store *s, const char *id)
{
    sqlite3_stmt *q = s->q[Q_VERSION];
    sqlite3_bind_text(q, 1, id, -1, SQLITE_STATIC);
    int rc = sqlite3_step(q);
    sqlite3_reset(q);
    sqlite3_clear_bindings(q);
    return rc == SQLITE_ROW ? PERSIST_CONFLICT : rc == SQLITE_DONE ? PERSIST_ABSENT
                                                                  : failed(s, "reading a version", rc);
}

static persist_rc sq_create(void *b, const persist_meta *m)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    sqlite3_stmt *q = s->q[Q_CREATE];
    sqlite3_bind_text(q, 1, m->id, -1, SQLITE_STATIC);
    sqlite3_bind_blob(q, 2, m->token_hash, sizeof m->token_hash, SQLITE_STATIC);
    sqlite3_bind_int(q, 3, m->ttl_s);
    sqlite3_bind_int64(q, 4, m->created);
    sqlite3_bind_int64(q, 5, m->expires_at);
    sqlite3_bind_int64(q, 6, (sqlite3_int64)m->version);
    if (m->owner[0])
        sqlite3_bind_text(q, 7, m->owner, -1, SQLITE_STATIC);
    int rc = run(s, Q_CREATE);
    persist_rc r = rc == SQLITE_DONE ? PERSIST_OK
                   : (rc & 0xff) == SQLITE_CONSTRAINT ? PERSIST_CONFLICT
                                                      : failed(s, "creating a session", rc);
    pthread_mutex_unlock(&s->mu);
    return r;
}

/* One compare-and-set write: the CAS update (bound by the caller), then `then` (or none). */
static persist_rc cas_write(sqlite_store *s, const char *id, int cas, int then, const char *what)
{
    int rc = run(s, Q_BEGIN);
    if (rc != SQLITE_DONE) {
        sqlite3_reset(s->q[cas]);
        sqlite3_clear_bindings(s->q[cas]);
        if (then >= 0) {
            sqlite3_reset(s->q[then]);
            sqlite3_clear_bindings(s->q[then]);
        }
        return failed(s, what, rc);
    }
    persist_rc r = PERSIST_OK;
    rc = run(s, cas);
    if (rc != SQLITE_DONE)
        r = failed(s, what, rc);
    else if (sqlite3_changes(s->db) == 0)
        r = why_not(s, id);
    if (then >= 0) {
        if (r == PERSIST_OK && (rc = run(s, then)) != SQLITE_DONE)
            r = failed(s, what, rc);
        sqlite3_reset(s->q[then]);
        sqlite3_clear_bindings(s->q[then]);
    }
    if (r == PERSIST_OK && (rc = run(s, Q_COMMIT)) != SQLITE_DONE)
        r = failed(s, what, rc);
    if (r != PERSIST_OK && !sqlite3_get_autocommit(s->db))
        run(s, Q_ROLLBACK);
    return r;
}

static persist_rc sq_snapshot(void *b, const char *id, uint64_t expect, uint64_t version,
                              int64_t expires_at, const char *doc, size_t len)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    sqlite3_stmt *q = s->q[Q_CAS_SNAP];
    sqlite3_bind_text(q, 1, id, -1, SQLITE_STATIC);
    sqlite3_bind_int64(q, 2, (sqlite3_int64)expect);
    sqlite3_bind_int64(q, 3, (sqlite3_int64)version);
    sqlite3_bind_blob64(q, 4, doc, len, SQLITE_STATIC);
    sqlite3_bind_int64(q, 5, crc_of(doc, len));
    sqlite3_bind_int64(q, 6, expires_at);
    sqlite3_bind_text(s->q[Q_DEL_JOURNAL], 1, id, -1, SQLITE_STATIC);
    persist_rc r = cas_write(s, id, Q_CAS_SNAP, Q_DEL_JOURNAL, "writing a snapshot");
    pthread_mutex_unlock(&s->mu);
    return r;
}

static persist_rc sq_append(void *b, const char *id, uint64_t expect, uint64_t version,
                            int64_t expires_at, const char *entry, size_t len)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    sqlite3_stmt *q = s->q[Q_CAS_APPEND], *a = s->q[Q_ADD_ENTRY];
    sqlite3_bind_text(q, 1, id, -1, SQLITE_STATIC);
    sqlite3_bind_int64(q, 2, (sqlite3_int64)expect);
    sqlite3_bind_int64(q, 3, (sqlite3_int64)version);
    sqlite3_bind_int64(q, 4, expires_at);
    sqlite3_bind_text(a, 1, id, -1, SQLITE_STATIC);
    sqlite3_bind_int64(a, 2, (sqlite3_int64)version);
    sqlite3_bind_blob64(a, 3, entry, len, SQLITE_STATIC);
    sqlite3_bind_int64(a, 4, crc_of(entry, len));
    persist_rc r = cas_write(s, id, Q_CAS_APPEND, Q_ADD_ENTRY, "appending to the journal");
    pthread_mutex_unlock(&s->mu);
    return r;
}

static persist_rc sq_touch(void *b, const char *id, int ttl_s, int64_t expires_at)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    sqlite3_stmt *q = s->q[Q_TOUCH];
    sqlite3_bind_text(q, 1, id, -1, SQLITE_STATIC);
    sqlite3_bind_int64(q, 2, expires_at);
    if (ttl_s > 0)
        sqlite3_bind_int(q, 3, ttl_s);
    else
        sqlite3_bind_null(q, 3);
    int rc = run(s, Q_TOUCH);
    persist_rc r = rc != SQLITE_DONE ? failed(s, "moving an expiry", rc)
                   : sqlite3_changes(s->db) ? PERSIST_OK : PERSIST_ABSENT;
    pthread_mutex_unlock(&s->mu);
    return r;
}

static persist_rc sq_delete(void *b, const char *id)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    sqlite3_bind_text(s->q[Q_DELETE], 1, id, -1, SQLITE_STATIC);
    sqlite3_bind_text(s->q[Q_DEL_JOURNAL], 1, id, -1, SQLITE_STATIC);
    persist_rc r = cas_write(s, id, Q_DELETE, Q_DEL_JOURNAL, "deleting a session");
    pthread_mutex_unlock(&s->mu);
    return r;
}

static persist_rc sq_version(void *b, const char *id, uint64_t *version, int *ttl_s)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    sqlite3_stmt *q = s->q[Q_VERSION];
    sqlite3_bind_text(q, 1, id, -1, SQLITE_STATIC);
    int rc = sqlite3_step(q);
    persist_rc r = PERSIST_ABSENT;
    if (rc == SQLITE_ROW && sqlite3_column_int64(q, 1) >= (sqlite3_int64)time(NULL)) {
        *version = (uint64_t)sqlite3_column_int64(q, 0);
        if (ttl_s)
            *ttl_s = sqlite3_column_int(q, 2);
        r = PERSIST_OK;
    } else if (rc != SQLITE_ROW && rc != SQLITE_DONE)
        r = failed(s, "reading a version", rc);
    sqlite3_reset(q);
    sqlite3_clear_bindings(q);
    pthread_mutex_unlock(&s->mu);
    return r;
}

static char *copy_text(const void *p, size_t n)
{
    char *t = malloc(n + 1);
    if (t) {
        if (n)
            memcpy(t, p, n);
        t[n] = 0;
    }
    return t;
}

/* The session's row and journal, read in one transaction. Caller holds s->mu. */
static persist_rc load_locked(sqlite_store *s, const char *id, persist_loaded *out)
{
    sqlite3_stmt *q = s->q[Q_LOAD];
    sqlite3_bind_text(q, 1, id, -1, SQLITE_STATIC);
    int rc = sqlite3_step(q);
    if (rc != SQLITE_ROW) {
        persist_rc r = rc == SQLITE_DONE ? PERSIST_ABSENT : failed(s, "loading a session", rc);
        sqlite3_reset(q);
        return r;
    }
    persist_meta *m = &out->meta;
    snprintf(m->id, sizeof m->id, "%s", id);
    persist_rc r = PERSIST_OK;
    if (sqlite3_column_bytes(q, 0) != (int)sizeof m->token_hash)
        r = PERSIST_CORRUPT;
    else
        memcpy(m->token_hash, sqlite3_column_blob(q, 0), sizeof m->token_hash);
    m->ttl_s = sqlite3_column_int(q, 1);
    m->created = sqlite3_column_int64(q, 2);
    m->expires_at = sqlite3_column_int64(q, 3);
    m->version = (uint64_t)sqlite3_column_int64(q, 4);
    out->snapshot_version = (uint64_t)sqlite3_column_int64(q, 5);
    const unsigned char *owner = sqlite3_column_text(q, 8);
    if (owner && strlen((const char *)owner) < sizeof m->owner)
        strcpy(m->owner, (const char *)owner);
    if (r == PERSIST_OK && m->expires_at < (int64_t)time(NULL))
        r = PERSIST_ABSENT;
    out->record_ok = r == PERSIST_OK; /* what follows is the content */
    if (r == PERSIST_OK && sqlite3_column_type(q, 6) != SQLITE_NULL) {
        size_t n = (size_t)sqlite3_column_bytes(q, 6);
        const void *doc = sqlite3_column_blob(q, 6);
        if (!(out->snapshot = copy_text(doc, n)))
            r = PERSIST_UNAVAILABLE;
        else if (crc_of(out->snapshot, n) != (uint32_t)sqlite3_column_int64(q, 7))
            r = PERSIST_CORRUPT;
        out->snapshot_len = n;
    } else if (r == PERSIST_OK && out->snapshot_version)
        r = PERSIST_CORRUPT;
    sqlite3_reset(q);
    if (r != PERSIST_OK) {
        if (r == PERSIST_CORRUPT)
            snprintf(s->err, sizeof s->err, "sqlite %.200s: session %s: a damaged snapshot", s->path, id);
        return r;
    }
    q = s->q[Q_LOAD_JOURNAL];
    sqlite3_bind_text(q, 1, id, -1, SQLITE_STATIC);
    sqlite3_bind_int64(q, 2, (sqlite3_int64)out->snapshot_version);
    size_t cap = 0;
    uint64_t want = out->snapshot_version + 1;
    while (r == PERSIST_OK && (rc = sqlite3_step(q)) == SQLITE_ROW) {
        uint64_t v = (uint64_t)sqlite3_column_int64(q, 0);
        size_t n = (size_t)sqlite3_column_bytes(q, 1);
        const void *t = sqlite3_column_blob(q, 1);
        if (out->njournal == cap) {
            size_t nc = cap ? 2 * cap : 16;
            persist_entry *e = realloc(out->journal, nc * sizeof *e);
            if (!e) {
                r = PERSIST_UNAVAILABLE;
                break;
            }
            out->journal = e;
            cap = nc;
        }
        persist_entry *e = &out->journal[out->njournal];
        if (!(e->text = copy_text(t, n))) {
            r = PERSIST_UNAVAILABLE;
            break;
        }
        e->len = n;
        e->version = v;
        out->njournal++;
        if (v != want++ || crc_of(e->text, n) != (uint32_t)sqlite3_column_int64(q, 2)) {
            snprintf(s->err, sizeof s->err, "sqlite %.200s: session %s: journal entry of version %llu "
                     "is damaged", s->path, id, (unsigned long long)v);
            r = PERSIST_CORRUPT;
        }
    }
    if (r == PERSIST_OK && rc != SQLITE_DONE)
        r = failed(s, "loading a journal", rc);
    if (r == PERSIST_OK && want - 1 != m->version) {
        snprintf(s->err, sizeof s->err, "sqlite %.200s: session %s: the journal ends at version %llu, "
                 "the session is at %llu", s->path, id, (unsigned long long)(want - 1),
                 (unsigned long long)m->version);
        r = PERSIST_CORRUPT;
    }
    sqlite3_reset(q);
    sqlite3_clear_bindings(q);
    return r;
}

static persist_rc sq_load(void *b, const char *id, persist_loaded *out)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    int rc = run(s, Q_BEGIN_READ);
    persist_rc r = rc == SQLITE_DONE ? load_locked(s, id, out) : failed(s, "loading a session", rc);
    sqlite3_clear_bindings(s->q[Q_LOAD]);
    if (!sqlite3_get_autocommit(s->db))
        run(s, Q_COMMIT);
    pthread_mutex_unlock(&s->mu);
    if (r != PERSIST_OK)
        persist_loaded_free(out);
    return r;
}

static long sq_expire(void *b, int64_t now)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    long gone = -1;
    if (run(s, Q_BEGIN) == SQLITE_DONE) {
        sqlite3_bind_int64(s->q[Q_EXPIRE_J], 1, now);
        sqlite3_bind_int64(s->q[Q_EXPIRE_S], 1, now);
        if (run(s, Q_EXPIRE_J) == SQLITE_DONE && run(s, Q_EXPIRE_S) == SQLITE_DONE) {
            gone = sqlite3_changes(s->db);
            if (run(s, Q_COMMIT) != SQLITE_DONE)
                gone = -1;
        }
        if (!sqlite3_get_autocommit(s->db))
            run(s, Q_ROLLBACK);
    }
    pthread_mutex_unlock(&s->mu);
    return gone;
}

static long sq_count(void *b, int64_t now)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    sqlite3_stmt *q = s->q[Q_COUNT];
    sqlite3_bind_int64(q, 1, now);
    long n = sqlite3_step(q) == SQLITE_ROW ? (long)sqlite3_column_int64(q, 0) : -1;
    sqlite3_reset(q);
    sqlite3_clear_bindings(q);
    pthread_mutex_unlock(&s->mu);
    return n;
}

static persist_rc sq_owned(void *b, const char *owner, int64_t now, long enough, long *n,
                           int64_t *soonest)
{
    (void)enough; /* one indexed query counts them all */
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    sqlite3_stmt *q = s->q[Q_OWNED];
    sqlite3_bind_text(q, 1, owner, -1, SQLITE_STATIC);
    sqlite3_bind_int64(q, 2, now);
    int rc = sqlite3_step(q);
    persist_rc r = PERSIST_OK;
    if (rc == SQLITE_ROW) {
        *n = (long)sqlite3_column_int64(q, 0);
        *soonest = sqlite3_column_int64(q, 1); /* NULL (none) reads as 0 */
    } else
        r = failed(s, "counting a client's sessions", rc);
    sqlite3_reset(q);
    sqlite3_clear_bindings(q);
    pthread_mutex_unlock(&s->mu);
    return r;
}

/* 64 KiB written and committed, then deleted: a full disk (or a file at its page cap) refuses it. */
static persist_rc sq_probe(void *b)
{
    sqlite_store *s = b;
    pthread_mutex_lock(&s->mu);
    int rc = run(s, Q_PROBE_PUT);
    persist_rc r = rc == SQLITE_DONE ? PERSIST_OK : failed(s, "writing (a probe)", rc);
    rc = run(s, Q_PROBE_DEL);
    if (r == PERSIST_OK && rc != SQLITE_DONE)
        r = failed(s, "writing (a probe)", rc);
    pthread_mutex_unlock(&s->mu);
    return r;
}

const persist_ops persist_sqlite_ops = {
    .create = sq_create,
    .snapshot = sq_snapshot,
    .append = sq_append,
    .touch = sq_touch,
    .del = sq_delete,
    .version = sq_version,
    .load = sq_load,
    .expire = sq_expire,
    .count = sq_count,
    .owned = sq_owned,
    .probe = sq_probe,
    .last_error = sq_last_error,
    .last_what = sq_last_what,
    .close = sq_close,
};
