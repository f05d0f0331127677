/* slots — the compute slots of server/slots.c hand a free slot to the waiter whose session
 * holds the fewest, then to the earliest, and time out waiters (run by
 * tests/python/test_slots.py).
 *
 * Two slots, both held by session A; then A's third request, B's request and A's fourth wait,
 * in that order. A gives one back: B's request gets it although A's third came first (A holds
 * one, B none). The next slot given back goes to A's third, then A's fourth. A waiter with a
 * 1 s deadline and no slot coming free is refused after about 1 s.
 */
#include "../../server/slots.h"
#include <pthread.h>
#include <stdio.h>
#include <time.h>
#include <unistd.h>

static slots *S;
static const char A = 'A', B = 'B';
static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static char order[8];
static int norder;

typedef struct job {
    const char *owner;
    char name;
} job;

static void *wait_for_slot(void *arg)
{
    job *j = arg;
    if (slots_take(S, j->owner, 10))
        return NULL;
    pthread_mutex_lock(&mu);
    order[norder++] = j->name;
    pthread_mutex_unlock(&mu);
    return NULL;
}

static int got(int n)
{
    for (int i = 0; i < 200; i++) {
        pthread_mutex_lock(&mu);
        int k = norder;
        pthread_mutex_unlock(&mu);
        if (k >= n)
            return 1;
        usleep(10000);
    }
    return 0;
}

int main(void)
{
    S = slots_new(2);
    int bad = 0;
    slots_take(S, &A, 1);
    slots_take(S, &A, 1);
    job jobs[3] = {{&A, '3'}, {&B, 'b'}, {&A, '4'}};
    pthread_t t[3];
    for (int i = 0; i < 3; i++) {
        pthread_create(&t[i], NULL, wait_for_slot, &jobs[i]);
        usleep(50000); /* arrive in this order */
    }
    slots_give(S, &A);
    bad += !got(1);
    slots_give(S, &A);
    bad += !got(2);
    slots_give(S, &B);
    bad += !got(3);
    for (int i = 0; i < 3; i++)
        pthread_join(t[i], NULL);
    order[norder] = 0;
    if (bad || norder != 3 || order[0] != 'b' || order[1] != '3' || order[2] != '4') {
        printf("slots: served in the order \"%s\", not \"b34\"\n", order);
        return 1;
    }
    if (slots_held(S, &A) != 2 || slots_held(S, &B) != 0) {
        printf("slots: A holds %d, B %d (want 2, 0)\n", slots_held(S, &A), slots_held(S, &B));
        return 1;
    }
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    int refused = slots_take(S, &B, 1);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    double dt = (double)(t1.tv_sec - t0.tv_sec) + (t1.tv_nsec - t0.tv_nsec) * 1e-9;
    if (!refused || dt < 0.9 || dt > 3) {
        printf("slots: a waiter with no slot coming free got %s after %.2f s\n",
               refused ? "refused" : "a slot", dt);
        return 1;
    }
    slots_give(S, &A);
    slots_give(S, &A);
    slots_free(S);
    printf("slots: fair hand-over and timeouts ok\n");
    return 0;
}
