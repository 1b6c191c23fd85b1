/* parallel: a fork-join parallel-for over [0, n) on pthreads.
 * Work is split into chunks of `grain` handed out dynamically; results are deterministic as
 * long as fn writes only to per-index outputs (no order-dependent reductions).
 * There is no process-wide thread count: each loop is given its owner's setting (an engine's,
 * a reference's, a bake's), so several owners in one process never change each other's. */
#ifndef LC_PARALLEL_H
#define LC_PARALLEL_H
#include <stddef.h>

/* Runs on a worker thread; `thread` is in [0, lc_parallel_threads(threads)) for the loop's
 * `threads`, so per-thread scratch sized by lc_parallel_threads is enough. */
typedef void (*lc_parallel_fn)(void *ctx, size_t begin, size_t end, int thread);

/* The workers a loop given `threads` runs on: threads, or all online cores when <= 0, at
 * most 256. */
int lc_parallel_threads(int threads);
/* fn over [0, n) on lc_parallel_threads(threads) threads, the caller's among them. */
void lc_parallel_for(int threads, size_t n, size_t grain, lc_parallel_fn fn, void *ctx);

#endif
