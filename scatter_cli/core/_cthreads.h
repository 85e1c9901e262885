/* The kernels' threads, the only place that starts any: in_parallel() runs fn(ctx, k,
 * count) for k = 0 .. count - 1 on up to MAX_THREADS threads, and share() cuts 0 .. n - 1
 * into count fixed ranges, so that which thread computes what never depends on timing. */
#ifndef SCATTER_CTHREADS_H
#define SCATTER_CTHREADS_H

#include <pthread.h>
#include <stdint.h>

#define MAX_THREADS 16

typedef struct {
    void (*fn)(void *ctx, int k, int count);
    void *ctx;
    int k, count;
} ThreadCall;

static void *thread_main(void *arg)
{
    ThreadCall *j = arg;
    j->fn(j->ctx, j->k, j->count);
    return NULL;
}

/* fn(ctx, k, count) for k = 0 .. count - 1, on count threads (at most MAX_THREADS; k = 0
 * on the caller; a share whose thread does not start runs on the caller) */
static void in_parallel(int count, void (*fn)(void *, int, int), void *ctx)
{
    count = count < 1 ? 1 : count > MAX_THREADS ? MAX_THREADS : count;
    ThreadCall job[MAX_THREADS];
    pthread_t id[MAX_THREADS];
    int started[MAX_THREADS] = {0};
    for (int k = 0; k < count; k++)
        job[k] = (ThreadCall){fn, ctx, k, count};
    for (int k = 1; k < count; k++)
        started[k] = pthread_create(&id[k], NULL, thread_main, &job[k]) == 0;
    fn(ctx, 0, count);
    for (int k = 1; k < count; k++)
        if (started[k])
            pthread_join(id[k], NULL);
        else
            fn(ctx, k, count);
}

/* share k of count of 0 .. n - 1: [*i0, *i1) */
static inline void share(int64_t n, int k, int count, int64_t *i0, int64_t *i1)
{
    *i0 = n * k / count, *i1 = n * (k + 1) / count;
}

#endif
