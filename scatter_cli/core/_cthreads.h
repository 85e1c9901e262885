/* The kernels' threads, the only place that starts any. in_pieces(pieces, threads, fn, ctx)
 * runs fn(ctx, k, pieces) once for each piece k = 0 .. pieces - 1 on up to ``threads``
 * threads (the caller one of them), which take the pieces in turn from a shared counter as
 * they finish the last: which thread computes a piece depends on timing, so what a piece
 * computes must depend on k alone (share() cuts 0 .. n - 1 into fixed ranges), and
 * pieces_for() cuts work into many pieces a thread, so that a thread that finishes early
 * takes more instead of waiting for the slowest. in_pieces_by() tells each piece its
 * thread, for work that adds into one accumulator a thread; in_parallel(count, fn, ctx)
 * is one piece a thread, on count threads. The thread count is a run-time number: no
 * cap. */
#ifndef SCATTER_CTHREADS_H
#define SCATTER_CTHREADS_H

#include <limits.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>

#define PIECES_PER_THREAD 8

typedef struct {
    void (*fn)(void *ctx, int k, int count);
    void (*each)(void *ctx, int thread, int k, int count); /* (in_pieces_by) */
    void *ctx;
    int pieces;
    int next; /* the next piece to take (atomic) */
} Pieces;

typedef struct {
    Pieces *p;
    int thread;
} Taker;

static inline void take_pieces(Pieces *p, int thread)
{
    for (;;) {
        int k = __atomic_fetch_add(&p->next, 1, __ATOMIC_RELAXED);
        if (k >= p->pieces)
            return;
        if (p->each)
            p->each(p->ctx, thread, k, p->pieces);
        else
            p->fn(p->ctx, k, p->pieces);
    }
}

static inline void *thread_main(void *arg)
{
    Taker *t = arg;
    take_pieces(t->p, t->thread);
    return NULL;
}

/* The threads in_pieces() runs ``pieces`` pieces on when asked for ``threads``. */
static inline int threads_for(int pieces, int threads)
{
    pieces = pieces < 1 ? 1 : pieces;
    return threads < 1 ? 1 : threads > pieces ? pieces : threads;
}

static inline void run_pieces(Pieces *p, int threads)
{
    threads = threads_for(p->pieces, threads);
    p->pieces = p->pieces < 1 ? 1 : p->pieces;
    pthread_t *id = threads > 1 ? malloc((size_t)(threads - 1) * sizeof *id) : NULL;
    Taker *takers = threads > 1 ? malloc((size_t)(threads - 1) * sizeof *takers) : NULL;
    int started = 0;
    while (id && takers && started < threads - 1) {
        takers[started] = (Taker){p, started + 1};
        if (pthread_create(&id[started], NULL, thread_main, &takers[started]) != 0)
            break;
        started++;
    }
    take_pieces(p, 0);
    for (int k = 0; k < started; k++)
        pthread_join(id[k], NULL);
    free(id), free(takers);
}

/* fn(ctx, k, pieces) for k = 0 .. pieces - 1 (at least one piece), on up to ``threads``
 * threads; the pieces of threads that do not start fall to the others. */
static inline void in_pieces(int pieces, int threads, void (*fn)(void *, int, int), void *ctx)
{
    Pieces p = {fn, NULL, ctx, pieces, 0};
    run_pieces(&p, threads);
}

/* in_pieces() for pieces that add into an accumulator of the thread that takes them:
 * each(ctx, thread, k, pieces), thread 0 .. threads_for(pieces, threads) - 1, so what
 * the accumulators hold in the end must not depend on which of them took which piece. */
static inline void in_pieces_by(int pieces, int threads, void (*each)(void *, int, int, int), void *ctx)
{
    Pieces p = {NULL, each, ctx, pieces, 0};
    run_pieces(&p, threads);
}

/* fn(ctx, k, count) for k = 0 .. count - 1, on count threads */
static inline void in_parallel(int count, void (*fn)(void *, int, int), void *ctx)
{
    in_pieces(count, count, fn, ctx);
}

/* How many pieces to cut n items into for ``threads`` threads: PIECES_PER_THREAD a
 * thread, each of ``least`` items at least; one on one thread. */
static inline int pieces_for(int64_t n, int64_t least, int threads)
{
    if (threads <= 1)
        return 1;
    int64_t most = n / (least > 0 ? least : 1), want = (int64_t)threads * PIECES_PER_THREAD;
    int64_t pieces = want < most ? want : most;
    return pieces < 1 ? 1 : pieces > INT_MAX / 2 ? INT_MAX / 2 : (int)pieces;
}

/* share k of count of 0 .. n - 1: [*i0, *i1) */
static inline void share(int64_t n, int k, int count, int64_t *i0, int64_t *i1)
{
    *i0 = (int64_t)((__int128)n * k / count), *i1 = (int64_t)((__int128)n * (k + 1) / count);
}

#endif
