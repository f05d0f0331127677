/* test_main.c — runs every registered core test. */
#include "test.h"

#define MAX_TESTS 512
static struct {
    const char *name;
    void (*fn)(void);
} tests[MAX_TESTS];
static int ntests;
int test_failed_now;
static const char *current;

void test_register(const char *name, void (*fn)(void))
{
    if (ntests < MAX_TESTS) {
        tests[ntests].name = name;
        tests[ntests].fn = fn;
        ntests++;
    }
}

void test_fail(const char *file, int line, const char *msg)
{
    printf("FAIL %s (%s:%d): %s\n", current, file, line, msg);
    test_failed_now = 1;
}

int main(int argc, char **argv)
{
    int passed = 0, failed = 0;
    for (int i = 0; i < ntests; i++) {
        if (argc > 1 && !strstr(tests[i].name, argv[1]))
            continue;
        current = tests[i].name;
        test_failed_now = 0;
        tests[i].fn();
        if (test_failed_now)
            failed++;
        else {
            passed++;
            if (getenv("VERBOSE"))
                printf("ok   %s\n", tests[i].name);
        }
    }
    printf("core: %d passed, %d failed\n", passed, failed);
    return failed != 0;
}
