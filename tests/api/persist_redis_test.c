/* persist_redis_test — the redis back end (server/persist_redis.c) against a real redis-server
 * (run by tests/python/test_persist_redis.py, which starts one on a free port).
 *
 *   persist_redis_test HOST PORT DEAD_PORT          every check below, then "ok"
 *   persist_redis_test HOST PORT DEAD_PORT recover  the reconnects: prints RESTART, STOP and
 *                                                   START and waits for a line on stdin after
 *                                                   each, while the caller does just that
 *
 * Checks: create, create twice (CONFLICT), snapshot compare-and-set, three appends and a load
 * that returns them in order, a compaction, touch (every key's expiry moves), delete (ABSENT
 * after), damaged journals and a missing snapshot written with hiredis directly (CORRUPT),
 * sessions expired in the record or by redis (ABSENT), a script flush (EVAL fallback), count,
 * a server that does not answer (UNAVAILABLE after the 2 s command timeout, then a reconnect),
 * a server nobody listens on (UNAVAILABLE within 3 s) and two connections racing the same
 * snapshot 50 times (exactly one winner per round).
 *
 * The back end is called through persist_redis_ops, without the dispatcher of persist.c: the
 * loaded session is freed by loaded_free below, a stand-in for persist_loaded_free.
 */
#include "../../server/persist_impl.h"
#include <hiredis/hiredis.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static const persist_ops *ops = &persist_redis_ops;
static const char *host;
static int port, dead_port;
static int failures, checks;
static redisContext *raw;   /* for writing damage directly */

#define CHECK(cond, ...)                                                                      \
    do {                                                                                      \
        checks++;                                                                             \
        if (!(cond)) {                                                                        \
            failures++;                                                                       \
            printf("FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond);                            \
            printf(__VA_ARGS__);                                                              \
            printf("\n");                                                                     \
        }                                                                                     \
    } while (0)

static const char *rc_name(persist_rc rc)
{
    static const char *const names[] = {"OK", "CONFLICT", "ABSENT", "UNAVAILABLE", "CORRUPT"};
    return rc <= PERSIST_CORRUPT ? names[rc] : "?";
}

#define CHECK_RC(b, got, want)                                                                \
    do {                                                                                      \
        persist_rc got_ = (got);                                                              \
        CHECK(got_ == (want), "%s, wanted %s (%s)", rc_name(got_), rc_name(want),             \
              got_ == PERSIST_OK ? "" : ops->last_error(b));                                  \
    } while (0)

static void loaded_free(persist_loaded *l)
{
    free(l->snapshot);
    for (size_t i = 0; i < l->njournal; i++)
        free(l->journal[i].text);
    free(l->journal);
    memset(l, 0, sizeof *l);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + t.tv_nsec / 1e9;
}

static void new_meta(persist_meta *m, int64_t expires_at)
{
    static unsigned serial;
    snprintf(m->id, sizeof m->id, "%08x%08x%08x%08x", (unsigned)time(NULL), (unsigned)getpid(),
             ++serial, (unsigned)rand());
    for (int i = 0; i < 32; i++)
        m->token_hash[i] = (unsigned char)(i * 37 + serial);   /* NUL bytes included */
    m->token_hash[5] = 0;
    m->ttl_s = 3600;
    m->created = (int64_t)time(NULL);
    m->expires_at = expires_at;
    m->version = 0;
}

static redisReply *rawcmd(const char *fmt, const char *id, const char *arg)
{
    redisReply *r = redisCommand(raw, fmt, id, arg);
    if (!r) {
        printf("FAIL raw redis command: %s\n", raw->errstr);
        exit(1);
    }
    return r;
}

static long long raw_ttl(const char *fmt, const char *id)
{
    redisReply *r = rawcmd(fmt, id, NULL);
    long long t = r->type == REDIS_REPLY_INTEGER ? r->integer : -3;
    freeReplyObject(r);
    return t;
}

static void test_lifecycle(void *b)
{
    int64_t t = (int64_t)time(NULL);
    persist_meta m;
    persist_loaded l;
    uint64_t v = 99;
    new_meta(&m, t + 3600);

    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    CHECK_RC(b, ops->create(b, &m), PERSIST_CONFLICT);
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_OK);
    CHECK(v == 0, "version %" PRIu64, v);

    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_OK);
    CHECK(l.snapshot == NULL && l.njournal == 0 && l.snapshot_version == 0, "empty session");
    CHECK(!memcmp(l.meta.token_hash, m.token_hash, 32), "token hash round trip");
    CHECK(!strcmp(l.meta.id, m.id) && l.meta.ttl_s == 3600 && l.meta.created == m.created
              && l.meta.expires_at == m.expires_at && l.meta.version == 0, "record round trip");
    loaded_free(&l);

    const char doc1[] = "{\"vertices\":[[0,0,0]],\"n\":1}";
    CHECK_RC(b, ops->snapshot(b, m.id, 0, 1, t + 3600, doc1, strlen(doc1)), PERSIST_OK);
    CHECK_RC(b, ops->snapshot(b, m.id, 0, 2, t + 3600, doc1, strlen(doc1)), PERSIST_CONFLICT);
    CHECK_RC(b, ops->snapshot(b, m.id, 5, 6, t + 3600, doc1, strlen(doc1)), PERSIST_CONFLICT);

    const char *edits[3] = {"{\"moves\":[{\"index\":0,\"position\":[1,2,3]}]}",
                            "{\"moves\":[{\"index\":0,\"position\":[4,5,6]}]}",
                            "second line\nwith a space and a newline"};
    for (int i = 0; i < 3; i++)
        CHECK_RC(b, ops->append(b, m.id, 1 + i, 2 + i, t + 3600, edits[i], strlen(edits[i])),
                 PERSIST_OK);
    CHECK_RC(b, ops->append(b, m.id, 3, 4, t + 3600, "late", 4), PERSIST_CONFLICT);
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_OK);
    CHECK(v == 4, "version %" PRIu64 " after three appends", v);

    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_OK);
    CHECK(l.snapshot && l.snapshot_len == strlen(doc1) && !strcmp(l.snapshot, doc1),
          "snapshot %s", l.snapshot ? l.snapshot : "(null)");
    CHECK(l.snapshot_version == 1 && l.meta.version == 4 && l.njournal == 3,
          "snapshot_version %" PRIu64 " version %" PRIu64 " njournal %zu", l.snapshot_version,
          l.meta.version, l.njournal);
    for (size_t i = 0; i < l.njournal && i < 3; i++)
        CHECK(l.journal[i].version == 2 + i && l.journal[i].len == strlen(edits[i])
                  && !strcmp(l.journal[i].text, edits[i]),
              "entry %zu: %" PRIu64 " %s", i, l.journal[i].version, l.journal[i].text);
    loaded_free(&l);

    /* compaction: expect == version, the journal goes */
    const char doc4[] = "{\"n\":4}";
    CHECK_RC(b, ops->snapshot(b, m.id, 4, 4, t + 3600, doc4, strlen(doc4)), PERSIST_OK);
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_OK);
    CHECK(l.snapshot && !strcmp(l.snapshot, doc4) && l.snapshot_version == 4 && l.njournal == 0
              && l.meta.version == 4, "after compaction: njournal %zu", l.njournal);
    loaded_free(&l);
    CHECK(raw_ttl("EXISTS subdivd:j:{%s}", m.id) == 0, "journal key gone after compaction");

    /* touch moves the expiry of all three keys */
    CHECK_RC(b, ops->append(b, m.id, 4, 5, t + 3600, "e5", 2), PERSIST_OK);
    CHECK_RC(b, ops->touch(b, m.id, 0, t + 7200), PERSIST_OK);
    CHECK(raw_ttl("TTL subdivd:s:{%s}", m.id) > 7000, "record TTL after touch");
    CHECK(raw_ttl("TTL subdivd:snap:{%s}", m.id) > 7000, "snapshot TTL after touch");
    CHECK(raw_ttl("TTL subdivd:j:{%s}", m.id) > 7000, "journal TTL after touch");
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_OK);
    CHECK(l.meta.expires_at == t + 7200 && l.njournal == 1, "expires_at after touch");
    loaded_free(&l);

    /* a script flush: EVALSHA answers NOSCRIPT, EVAL takes over */
    freeReplyObject(rawcmd("SCRIPT FLUSH", NULL, NULL));
    CHECK_RC(b, ops->append(b, m.id, 5, 6, t + 7200, "e6", 2), PERSIST_OK);
    CHECK_RC(b, ops->append(b, m.id, 6, 7, t + 7200, "e7", 2), PERSIST_OK);
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_OK);
    CHECK(l.njournal == 3 && l.meta.version == 7, "after SCRIPT FLUSH: %zu entries", l.njournal);
    loaded_free(&l);

    /* a large snapshot */
    size_t big = 3 << 20;
    char *doc = malloc(big + 1);
    for (size_t i = 0; i < big; i++)
        doc[i] = (char)('a' + i % 26);
    doc[big] = '\0';
    CHECK_RC(b, ops->snapshot(b, m.id, 7, 8, t + 7200, doc, big), PERSIST_OK);
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_OK);
    CHECK(l.meta.ttl_s == m.ttl_s, "a touch without a TTL keeps it: %d", l.meta.ttl_s);
    loaded_free(&l);
    CHECK_RC(b, ops->touch(b, m.id, 90, t + 7300), PERSIST_OK); /* PATCH /v1/sessions/{id} */
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_OK);
    CHECK(l.meta.ttl_s == 90 && l.meta.expires_at == t + 7300, "retimed: ttl %d, expiry %lld",
          l.meta.ttl_s, (long long)(l.meta.expires_at - t));
    int vttl = 0;
    CHECK_RC(b, ops->version(b, m.id, &v, &vttl), PERSIST_OK);
    CHECK(vttl == 90, "the version read gives the TTL too: %d", vttl);
    CHECK(l.snapshot_len == big && !memcmp(l.snapshot, doc, big), "3 MiB snapshot round trip");
    loaded_free(&l);
    free(doc);

    CHECK_RC(b, ops->touch(b, "00000000000000000000000000000000", 0, t + 60), PERSIST_ABSENT);

    /* delete: everything is ABSENT after */
    CHECK_RC(b, ops->del(b, m.id), PERSIST_OK);
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_ABSENT);
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_ABSENT);
    CHECK_RC(b, ops->snapshot(b, m.id, 8, 9, t + 60, "x", 1), PERSIST_ABSENT);
    CHECK_RC(b, ops->append(b, m.id, 8, 9, t + 60, "x", 1), PERSIST_ABSENT);
    CHECK_RC(b, ops->touch(b, m.id, 0, t + 60), PERSIST_ABSENT);
    CHECK_RC(b, ops->del(b, m.id), PERSIST_ABSENT);
    CHECK(raw_ttl("EXISTS subdivd:snap:{%s}", m.id) == 0, "snapshot key gone after delete");
}

/* A session at version 2 (snapshot at 1, one entry), then `damage` applied with hiredis. */
static void expect_corrupt(void *b, const char *what, const char *damage, const char *arg)
{
    int64_t t = (int64_t)time(NULL);
    persist_meta m;
    persist_loaded l;
    new_meta(&m, t + 600);
    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    CHECK_RC(b, ops->snapshot(b, m.id, 0, 1, t + 600, "{}", 2), PERSIST_OK);
    CHECK_RC(b, ops->append(b, m.id, 1, 2, t + 600, "{\"moves\":[]}", 12), PERSIST_OK);
    freeReplyObject(rawcmd(damage, m.id, arg));
    persist_rc rc = ops->load(b, m.id, &l);
    CHECK(rc == PERSIST_CORRUPT, "%s: load gave %s", what, rc_name(rc));
    CHECK(l.snapshot == NULL && l.journal == NULL && l.njournal == 0, "%s: nothing handed out", what);
    if (rc == PERSIST_CORRUPT)
        CHECK(strstr(ops->last_error(b), m.id) != NULL, "%s: last_error %s", what,
              ops->last_error(b));
    loaded_free(&l);
    ops->del(b, m.id);
}

static void test_corrupt(void *b)
{
    expect_corrupt(b, "unparsable prefix", "RPUSH subdivd:j:{%s} %s", "x3 {}");
    expect_corrupt(b, "no prefix at all", "LSET subdivd:j:{%s} 0 %s", "{\"moves\":[]}");
    expect_corrupt(b, "version gap", "LSET subdivd:j:{%s} 0 %s", "3 {}");
    expect_corrupt(b, "entry after the version", "RPUSH subdivd:j:{%s} %s", "3 {}");
    expect_corrupt(b, "snapshot missing", "DEL subdivd:snap:{%s}", NULL);
    expect_corrupt(b, "bad token hash", "HSET subdivd:s:{%s} token_hash %s", "short");
    expect_corrupt(b, "bad version field", "HSET subdivd:s:{%s} version %s", "two");
    expect_corrupt(b, "journal lost", "DEL subdivd:j:{%s}", NULL);
    expect_corrupt(b, "journal of the wrong type", "SET subdivd:j:{%s} %s", "2 {}");
}

static void test_expired(void *b)
{
    int64_t t = (int64_t)time(NULL);
    persist_meta m;
    persist_loaded l;
    uint64_t v;
    /* already past at creation: redis drops the keys at once */
    new_meta(&m, t - 10);
    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_ABSENT);
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_ABSENT);
    /* the record says it is past although redis still holds the keys */
    new_meta(&m, t + 600);
    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    char past[24];
    snprintf(past, sizeof past, "%" PRId64, t - 5);
    freeReplyObject(rawcmd("HSET subdivd:s:{%s} expires_at %s", m.id, past));
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_ABSENT);
    CHECK(l.snapshot == NULL && l.njournal == 0, "expired: nothing handed out");
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_ABSENT);
    ops->del(b, m.id);
    /* touched into the past */
    new_meta(&m, t + 600);
    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    CHECK_RC(b, ops->touch(b, m.id, 0, t - 1), PERSIST_OK);
    CHECK_RC(b, ops->load(b, m.id, &l), PERSIST_ABSENT);
}

static void test_count(void *b)
{
    int64_t t = (int64_t)time(NULL);
    long before = ops->count(b, t);
    CHECK(before >= 0, "count %ld", before);
    persist_meta m[3];
    for (int i = 0; i < 3; i++) {
        new_meta(&m[i], t + 600);
        CHECK_RC(b, ops->create(b, &m[i]), PERSIST_OK);
    }
    long after = ops->count(b, t);
    CHECK(after == before + 3, "count %ld then %ld", before, after);
    for (int i = 0; i < 3; i++)
        ops->del(b, m[i].id);
    CHECK(ops->count(b, t) == before, "count after deletes");
    CHECK(ops->expire(b, t) == 0, "expire is redis's own");
}

static void test_unavailable(void)
{
    char err[256] = "";
    double t0 = now_s();
    void *d = persist_redis_open(host, dead_port, err, sizeof err);
    CHECK(d != NULL, "open without a server: %s", err);
    if (!d)
        return;
    persist_meta m;
    persist_loaded l;
    uint64_t v;
    new_meta(&m, (int64_t)time(NULL) + 60);
    CHECK_RC(d, ops->create(d, &m), PERSIST_UNAVAILABLE);
    char want[64];
    snprintf(want, sizeof want, "redis %s:%d: ", host, dead_port);
    const char *e = ops->last_error(d);
    CHECK(!strncmp(e, want, strlen(want)) && strstr(e, "Connection refused"), "last_error %s", e);
    CHECK_RC(d, ops->load(d, m.id, &l), PERSIST_UNAVAILABLE);
    CHECK_RC(d, ops->version(d, m.id, &v, NULL), PERSIST_UNAVAILABLE);
    CHECK_RC(d, ops->snapshot(d, m.id, 0, 1, 0, "{}", 2), PERSIST_UNAVAILABLE);
    CHECK_RC(d, ops->append(d, m.id, 0, 1, 0, "{}", 2), PERSIST_UNAVAILABLE);
    CHECK(ops->count(d, 0) == -1, "count without a server");
    double dt = now_s() - t0;
    CHECK(dt < 3.0, "UNAVAILABLE took %.2f s", dt);
    printf("unavailable: open and 6 calls in %.3f s: %s\n", dt, e);
    ops->close(d);
}

/* A server that does not answer (CLIENT PAUSE): the command times out after 2 s, the next call
 * after the pause works on a new connection. */
static void test_timeout(void *b)
{
    persist_meta m;
    uint64_t v;
    new_meta(&m, (int64_t)time(NULL) + 600);
    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    freeReplyObject(rawcmd("CLIENT PAUSE 2600 ALL", NULL, NULL));
    double t0 = now_s();
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_UNAVAILABLE);
    double dt = now_s() - t0;
    CHECK(dt > 1.5 && dt < 2.6, "timed out after %.2f s", dt);
    CHECK(strstr(ops->last_error(b), "timed out") != NULL, "last_error %s", ops->last_error(b));
    printf("timeout: %.2f s: %s\n", dt, ops->last_error(b));
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_OK);
    CHECK(v == 0, "version %" PRIu64 " after the pause", v);
    ops->del(b, m.id);
}

/* Two connections (two daemons) race the same compare-and-set: exactly one wins per round. */
#define ROUNDS 50
static pthread_barrier_t start_line;
static const char *race_id;
static persist_rc race_rc[2][ROUNDS];
static void *race_handle[2];

static void *racer(void *arg)
{
    int k = (int)(intptr_t)arg;
    char doc[64];
    for (int r = 0; r < ROUNDS; r++) {
        snprintf(doc, sizeof doc, "{\"round\":%d,\"racer\":%d}", r, k);
        pthread_barrier_wait(&start_line);
        race_rc[k][r] = ops->snapshot(race_handle[k], race_id, (uint64_t)r, (uint64_t)r + 1,
                                      (int64_t)time(NULL) + 600, doc, strlen(doc));
        pthread_barrier_wait(&start_line);
    }
    return NULL;
}

static void test_race(void *b)
{
    char err[256];
    persist_meta m;
    new_meta(&m, (int64_t)time(NULL) + 600);
    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    race_id = m.id;
    race_handle[0] = b;
    race_handle[1] = persist_redis_open(host, port, err, sizeof err);
    CHECK(race_handle[1] != NULL, "second handle: %s", err);
    if (!race_handle[1])
        return;
    pthread_barrier_init(&start_line, NULL, 2);
    pthread_t th[2];
    for (int k = 0; k < 2; k++)
        pthread_create(&th[k], NULL, racer, (void *)(intptr_t)k);
    for (int k = 0; k < 2; k++)
        pthread_join(th[k], NULL);
    pthread_barrier_destroy(&start_line);
    int wins[2] = {0, 0}, bad = 0;
    for (int r = 0; r < ROUNDS; r++) {
        int ok = (race_rc[0][r] == PERSIST_OK) + (race_rc[1][r] == PERSIST_OK);
        int conflict = (race_rc[0][r] == PERSIST_CONFLICT) + (race_rc[1][r] == PERSIST_CONFLICT);
        if (ok != 1 || conflict != 1) {
            bad++;
            printf("round %d: %s and %s\n", r, rc_name(race_rc[0][r]), rc_name(race_rc[1][r]));
        }
        wins[0] += race_rc[0][r] == PERSIST_OK;
        wins[1] += race_rc[1][r] == PERSIST_OK;
    }
    CHECK(bad == 0, "%d of %d rounds without exactly one winner", bad, ROUNDS);
    uint64_t v = 0;
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_OK);
    CHECK(v == ROUNDS, "version %" PRIu64 " after the race", v);
    printf("race: %d rounds, one winner each (connection 1 won %d, connection 2 won %d)\n",
           ROUNDS - bad, wins[0], wins[1]);
    ops->close(race_handle[1]);
    ops->del(b, m.id);
}

static void wait_line(const char *say)
{
    char line[64];
    printf("%s\n", say);
    fflush(stdout);
    if (!fgets(line, sizeof line, stdin)) {
        printf("FAIL no answer to %s\n", say);
        exit(1);
    }
}

/* redis restarted under an idle connection (the one open made, then a used one): the call is
 * retried on a new one; redis down: the call is refused quickly; redis back: the next call
 * works again. */
static void test_recover(void *b)
{
    persist_meta m;
    uint64_t v;
    new_meta(&m, (int64_t)time(NULL) + 600);
    wait_line("RESTART");   /* under the connection persist_redis_open made */
    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    wait_line("RESTART");
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_ABSENT);   /* a new, empty server */
    wait_line("STOP");
    double t0 = now_s();
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_UNAVAILABLE);
    CHECK(now_s() - t0 < 3.0, "refused after %.2f s", now_s() - t0);
    printf("down: %s\n", ops->last_error(b));
    wait_line("START");
    CHECK_RC(b, ops->create(b, &m), PERSIST_OK);
    CHECK_RC(b, ops->version(b, m.id, &v, NULL), PERSIST_OK);
}

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: %s HOST PORT DEAD_PORT [recover]\n", argv[0]);
        return 2;
    }
    host = argv[1];
    port = atoi(argv[2]);
    dead_port = atoi(argv[3]);
    srand((unsigned)time(NULL) ^ (unsigned)getpid());
    char err[256];
    void *b = persist_redis_open(host, port, err, sizeof err);
    if (!b) {
        printf("FAIL open: %s\n", err);
        return 1;
    }
    if (argc > 4 && !strcmp(argv[4], "recover")) {
        test_recover(b);
    } else {
        struct timeval tv = {5, 0};
        raw = redisConnectWithTimeout(host, port, tv);
        if (!raw || raw->err) {
            printf("FAIL raw connection: %s\n", raw ? raw->errstr : "out of memory");
            return 1;
        }
        test_lifecycle(b);
        test_corrupt(b);
        test_expired(b);
        test_count(b);
        test_race(b);
        test_timeout(b);
        test_unavailable();
        redisFree(raw);
    }
    ops->close(b);
    printf("%d checks, %d failed\n", checks, failures);
    if (failures)
        return 1;
    printf("ok\n");
    return 0;
}
