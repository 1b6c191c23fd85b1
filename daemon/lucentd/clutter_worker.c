/* clutter_worker: the DRT operator builds (see clutter_worker.h). */
#include "clutter_worker.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>

#include "util/log.h"

#define CLW_NICE 10 /* builds yield the cores to relights */

struct lc_clw {
    lc_drt_builder *builder; /* worker thread (created before it starts) */
    lc_drt_settings settings;
    lc_clw_deliver_fn deliver;
    void *deliver_arg;
    pthread_t thread;
    pthread_mutex_t lock;
    pthread_cond_t cond;
    lc_engine_object *queue; /* guarded by lock: requests in arrival order, one per id */
    uint32_t n_queue, cap_queue;
    lc_engine_object running;          /* guarded by lock: the build in flight (valid while building) */
    int building;                      /* guarded by lock */
    atomic_int cancel;                 /* set under lock; the builder polls it */
    int stop;                          /* guarded by lock */
    uint64_t built, cancelled, failed; /* guarded by lock */
    double last_build_ms;              /* guarded by lock */
};

/* Under w->lock. */
static void clw_unqueue(lc_clw *w, const char *id) {
    for (uint32_t i = 0; i < w->n_queue; i++)
        if (strcmp(w->queue[i].id, id) == 0) {
            memmove(w->queue + i, w->queue + i + 1, (w->n_queue - i - 1) * sizeof *w->queue);
            w->n_queue--;
            return;
        }
}

static void *clw_main(void *arg) {
    lc_clw *w = arg;
    /* Linux: the nice value is per thread and the loops' threads inherit it. */
    if (setpriority(PRIO_PROCESS, (id_t)gettid(), CLW_NICE) != 0)
        lc_warn("clutter", "could not lower the build threads' priority; builds compete with relights");
    char err[256];
    for (;;) {
        pthread_mutex_lock(&w->lock);
        while (!w->stop && w->n_queue == 0) pthread_cond_wait(&w->cond, &w->lock);
        if (w->stop) {
            pthread_mutex_unlock(&w->lock);
            break;
        }
        w->running = w->queue[0];
        memmove(w->queue, w->queue + 1, (w->n_queue - 1) * sizeof *w->queue);
        w->n_queue--;
        w->building = 1;
        atomic_store(&w->cancel, 0);
        lc_engine_object obj = w->running;
        pthread_mutex_unlock(&w->lock);

        lc_drt_ops *ops = NULL;
        int rc = lc_drt_build(w->builder, &obj, &w->settings, &w->cancel, &ops, err, sizeof err);
        pthread_mutex_lock(&w->lock);
        w->building = 0;
        if (rc == 0) {
            w->built++;
            w->last_build_ms = lc_drt_ops_info(ops).build_ms;
        } else if (rc == 1) {
            w->cancelled++;
        } else {
            w->failed++;
        }
        pthread_mutex_unlock(&w->lock);
        if (rc == 0) {
            lc_drt_info in = lc_drt_ops_info(ops);
            lc_info("clutter", "operators for '%s' built in %.0f ms (%u receivers, %.1f MiB)", obj.id, in.build_ms,
                    in.receivers, in.bytes / 1048576.0);
            w->deliver(w->deliver_arg, ops);
        } else if (rc < 0) {
            lc_error("clutter", "building operators for '%s' failed: %s; the object stays dynamic", obj.id, err);
        }
    }
    return NULL;
}

lc_clw *lc_clw_start(const lc_lcb_view *v, int threads, const lc_drt_settings *settings, lc_clw_deliver_fn deliver,
                     void *deliver_arg, char *err, size_t errlen) {
    if (lc_drt_check_settings(settings, err, errlen) != 0) return NULL;
    lc_clw *w = calloc(1, sizeof *w);
    if (!w) {
        lc_set_err(err, errlen, "out of memory");
        return NULL;
    }
    w->builder = lc_drt_builder_create(v, threads, err, errlen);
    if (!w->builder) {
        free(w);
        return NULL;
    }
    w->settings = *settings;
    w->deliver = deliver;
    w->deliver_arg = deliver_arg;
    atomic_init(&w->cancel, 0);
    pthread_mutex_init(&w->lock, NULL);
    pthread_cond_init(&w->cond, NULL);
    if (pthread_create(&w->thread, NULL, clw_main, w) != 0) {
        lc_set_err(err, errlen, "cannot start the clutter build thread");
        pthread_cond_destroy(&w->cond);
        pthread_mutex_destroy(&w->lock);
        lc_drt_builder_release(w->builder);
        free(w);
        return NULL;
    }
    return w;
}

int lc_clw_request(lc_clw *w, const lc_engine_object *obj) {
    pthread_mutex_lock(&w->lock);
    if (w->building && strcmp(w->running.id, obj->id) == 0) {
        if (lc_drt_same_placement(&w->running, obj)) { /* already being built for this placement */
            pthread_mutex_unlock(&w->lock);
            return 0;
        }
        atomic_store(&w->cancel, 1);
    }
    for (uint32_t i = 0; i < w->n_queue; i++)
        if (strcmp(w->queue[i].id, obj->id) == 0) { /* a newer placement replaces the older one */
            w->queue[i] = *obj;
            pthread_mutex_unlock(&w->lock);
            return 0;
        }
    if (w->n_queue == w->cap_queue) {
        uint32_t cap = w->cap_queue ? 2 * w->cap_queue : 8;
        lc_engine_object *q = realloc(w->queue, cap * sizeof *q);
        if (!q) {
            pthread_mutex_unlock(&w->lock);
            lc_error("clutter", "out of memory queueing the build for '%s'; the object stays dynamic", obj->id);
            return -1;
        }
        w->queue = q;
        w->cap_queue = cap;
    }
    w->queue[w->n_queue++] = *obj;
    pthread_cond_signal(&w->cond);
    pthread_mutex_unlock(&w->lock);
    return 0;
}

void lc_clw_cancel(lc_clw *w, const char *object_id) {
    pthread_mutex_lock(&w->lock);
    clw_unqueue(w, object_id);
    if (w->building && strcmp(w->running.id, object_id) == 0) atomic_store(&w->cancel, 1);
    pthread_mutex_unlock(&w->lock);
}

lc_clw_counts lc_clw_counts_get(lc_clw *w) {
    lc_clw_counts c = {0};
    if (!w) return c;
    pthread_mutex_lock(&w->lock);
    c.built = w->built;
    c.cancelled = w->cancelled;
    c.failed = w->failed;
    c.queued = w->n_queue;
    c.building = w->building;
    c.last_build_ms = w->last_build_ms;
    pthread_mutex_unlock(&w->lock);
    return c;
}

void lc_clw_stop(lc_clw *w) {
    if (!w) return;
    pthread_mutex_lock(&w->lock);
    w->stop = 1;
    w->n_queue = 0;
    atomic_store(&w->cancel, 1);
    pthread_cond_signal(&w->cond);
    pthread_mutex_unlock(&w->lock);
    pthread_join(w->thread, NULL);
    pthread_cond_destroy(&w->cond);
    pthread_mutex_destroy(&w->lock);
    lc_drt_builder_release(w->builder);
    free(w->queue);
    free(w);
}
