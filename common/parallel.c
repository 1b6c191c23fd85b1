#include "util/parallel.h"

#include <pthread.h>
#include <stdatomic.h>
#include <unistd.h>

#define LC_PARALLEL_MAX_THREADS 256

int lc_parallel_threads(int threads) {
    int n = threads;
    if (n <= 0) {
        long c = sysconf(_SC_NPROCESSORS_ONLN);
        n = c > 0 ? (int)c : 1;
    }
    return n > LC_PARALLEL_MAX_THREADS ? LC_PARALLEL_MAX_THREADS : n;
}

typedef struct {
    size_t n, grain;
    _Atomic size_t next;
    lc_parallel_fn fn;
    void *ctx;
} parallel_job;

typedef struct {
    parallel_job *job;
    int thread;
} parallel_worker;

static void *parallel_run(void *arg) {
    parallel_worker *w = arg;
    parallel_job *job = w->job;
    for (;;) {
        size_t begin = atomic_fetch_add(&job->next, job->grain);
        if (begin >= job->n) break;
        size_t end = begin + job->grain < job->n ? begin + job->grain : job->n;
        job->fn(job->ctx, begin, end, w->thread);
    }
    return NULL;
}

void lc_parallel_for(int want, size_t n, size_t grain, lc_parallel_fn fn, void *ctx) {
    if (n == 0) return;
    if (grain == 0) grain = 1;
    int threads = lc_parallel_threads(want);
    size_t chunks = (n + grain - 1) / grain;
    if ((size_t)threads > chunks) threads = (int)chunks;
    parallel_job job = {.n = n, .grain = grain, .fn = fn, .ctx = ctx};
    atomic_init(&job.next, 0);
    parallel_worker workers[LC_PARALLEL_MAX_THREADS];
    pthread_t tids[LC_PARALLEL_MAX_THREADS];
    int started = 0;
    for (int t = 1; t < threads; t++) {
        workers[t] = (parallel_worker){&job, t};
        if (pthread_create(&tids[t], NULL, parallel_run, &workers[t]) != 0) break;
        started = t;
    }
    workers[0] = (parallel_worker){&job, 0};
    parallel_run(&workers[0]); /* the caller works too; if thread creation failed it does it all */
    for (int t = 1; t <= started; t++) pthread_join(tids[t], NULL);
}
