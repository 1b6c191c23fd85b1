/* clutter_worker: builds clutter objects' DRT operators (engine/drt.h, PROTOCOL.md §4.5) on a
 * thread of its own, so a relight never waits for a build and a build never waits for a
 * relight. The worker and the parallel loops it starts run at a lower priority (nice +10):
 * on a busy machine the relights of other updates take the cores first.
 *
 * The service thread asks for a build of an object as placed (lc_clw_request); a newer
 * request for the same id replaces one not yet started and cancels one in flight for
 * another placement (latest wins), and lc_clw_cancel drops both. Finished operators go to
 * the deliver callback on the worker thread (lucentd's hands them to the compute thread,
 * lc_compute_clutter_give); the engine itself drops operators whose object moved meanwhile,
 * so a late delivery is never applied to the wrong placement.
 *
 * Locking: `clw.lock` guards the queue, the build in flight, the counters and the stop flag;
 * the builder belongs to the worker thread. */
#ifndef LC_CLUTTER_WORKER_H
#define LC_CLUTTER_WORKER_H
#include <stddef.h>
#include <stdint.h>

#include "engine/drt.h"

/* Worker thread: ownership of ops moves to the callee. */
typedef void (*lc_clw_deliver_fn)(void *arg, lc_drt_ops *ops);

typedef struct lc_clw lc_clw;

/* Main thread: creates the builder (its Embree scene of the bake; threads 0 = all cores) and
 * starts the worker. settings are copied. NULL with err. */
lc_clw *lc_clw_start(const lc_lcb_view *v, int threads, const lc_drt_settings *settings, lc_clw_deliver_fn deliver,
                     void *deliver_arg, char *err, size_t errlen);
/* Service thread: build operators for obj as placed. 0, or -1 (out of memory; logged). */
int lc_clw_request(lc_clw *w, const lc_engine_object *obj);
/* Service thread: no operators for object_id after all (pending dropped, in flight cancelled). */
void lc_clw_cancel(lc_clw *w, const char *object_id);

typedef struct lc_clw_counts {
    uint64_t built, cancelled, failed;
    uint32_t queued;      /* requests waiting */
    int building;         /* 1 while a build runs */
    double last_build_ms; /* the last finished build's wall time */
} lc_clw_counts;
/* Any thread (for /metrics). */
lc_clw_counts lc_clw_counts_get(lc_clw *w);
/* Cancels the build in flight, drops the queue and joins the thread. NULL-safe. */
void lc_clw_stop(lc_clw *w);

#endif
