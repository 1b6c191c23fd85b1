/* parallel: a fork-join parallel-for over [0, n) on pthreads.
 * Work is split into chunks of `grain` handed out dynamically; results are deterministic as
 * long as fn writes only to per-index outputs (no order-dependent reductions). */
#ifndef LC_PARALLEL_H
#define LC_PARALLEL_H
#include <stddef.h>

/* Runs on a worker thread; `thread` is in [0, lc_parallel_threads()). */
typedef void (*lc_parallel_fn)(void *ctx, size_t begin, size_t end, int thread);

/* 0 = all online cores (the default). */
void lc_parallel_set_threads(int threads);
int lc_parallel_threads(void);
void lc_parallel_for(size_t n, size_t grain, lc_parallel_fn fn, void *ctx);

#endif
