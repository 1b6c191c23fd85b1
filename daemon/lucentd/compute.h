/* compute: the relight engine on its own thread. The service thread submits state copies
 * (latest wins: a submission replaces one not yet started, so a burst of updates costs one
 * relight); the compute thread relights, publishes an immutable, refcounted result under
 * `compute.lock`, and wakes the service thread through the wake callback (lucentd passes
 * one that calls lws_cancel_service(); this module knows nothing of sockets). */
#ifndef LC_COMPUTE_H
#define LC_COMPUTE_H
#include <stdint.h>

#include "engine/drt.h"
#include "lcb/lcb.h"
#include "state.h"

/* Called on the compute thread after each publication or failed relight; it must be safe
 * to call from another thread (lws_cancel_service is). */
typedef void (*lc_compute_wake_fn)(void *arg);

/* Per object of a result: whether its clutter operators applied (PROTOCOL.md §5.5). */
typedef struct lc_published_clutter {
    int on;
    double build_ms;
    uint64_t bytes;
} lc_published_clutter;

/* One relight's outputs. Immutable once published; free with lc_published_release. */
typedef struct lc_published {
    int refs;     /* guarded by compute.lock */
    uint64_t job; /* the submission it came from (lc_compute_submit) */
    uint64_t revision;
    uint64_t timestamp_us; /* when the relight finished (µs since the epoch) */
    double relight_ms;
    uint8_t pass;  /* refinement passes of this revision before it (0 = its first solution), saturating */
    int converged; /* 1: the last frame of this revision unless an update interrupts (no pass is planned) */
    uint32_t lm_w, lm_h;
    float *lightmap; /* W*H*3 irradiance */
    uint32_t grid_dims[3];
    float *grid_sh;    /* cells*27 */
    int grid_complete; /* 0: only the cells the objects read were computed (lc_compute_want_grid) */
    uint32_t n_objects;
    char (*object_ids)[LC_PROTO_ID_MAX + 1];
    float *object_sh;                     /* n_objects*27 */
    lc_published_clutter *object_clutter; /* n_objects: the clutter operators that applied */
} lc_published;

typedef struct lc_compute lc_compute;

/* Progressive refinement while no update waits: extra relights of the same state, each adding a
 * bounce (frames of the same revision). The first waits delay_ms after the update's own frame,
 * so that frame goes out first; the rest run back to back, so they end long before a next
 * update is due. They stop after max_passes, or earlier once the change per pass says the light
 * still to come is below `tolerance` (a share of the lightmap's luminance; 0 = always
 * max_passes); the last frame is marked converged. */
typedef struct lc_compute_refinement {
    int max_passes, delay_ms;
    double tolerance;
    int restart; /* 1: every new solution starts without carried light (lc_engine_reset_feedback), so a
                    revision's frames depend on its state alone (lucentd --cluster) */
} lc_compute_refinement;

/* Starts the thread and creates the engine on it (the EGL context belongs to that thread).
 * Returns NULL with err when the engine cannot start. */
lc_compute *lc_compute_start(const lc_lcb *bake, int backend, int threads, const lc_compute_refinement *refinement,
                             lc_compute_wake_fn wake, void *wake_arg, char *err, size_t errlen);
/* Service thread: submit the state to relight (copied). *job (may be NULL) receives the
 * submission's id, increasing from 1. The server submits before its journal fsync so the
 * relight overlaps the disk write; frames still go out only after the fsync, because the
 * service thread sends them. */
int lc_compute_submit(lc_compute *c, const lc_state *state, uint64_t *job);
/* Service thread: the submission `job` must never be published (its change could not be
 * stored): dropped if pending, its results discarded if in flight, withdrawn if already
 * published (the service thread cannot have taken it: it calls this within the request).
 * Remembers the last LC_COMPUTE_DISCARDS ids. */
#define LC_COMPUTE_DISCARDS 8
void lc_compute_discard(lc_compute *c, uint64_t job);
/* Service thread: a new reference to the newest result (NULL before the first), or NULL if
 * its revision/sequence is not newer than *seen (then *seen is unchanged). */
lc_published *lc_compute_take_newer(lc_compute *c, uint64_t *seen);
void lc_published_release(lc_compute *c, lc_published *p);
/* Service thread: another reference to p (which the caller holds). */
lc_published *lc_published_ref(lc_compute *c, lc_published *p);
/* Any thread: hands clutter operators (engine/drt.h; ownership moves, also when stopping) to
 * the compute thread, which attaches them to the engine and relights the last state, so the
 * next publication applies them if the object is still where they were built for. A CPU
 * backend only: with another, they are released and logged. */
void lc_compute_clutter_give(lc_compute *c, lc_drt_ops *ops);
/* Service thread: whether relights compute the whole SH grid (engine settings.grid_cells ALL)
 * or only the cells the objects and surfels read (NEEDED, the default until this is called):
 * lucentd wants it whole while a client subscribes to the shgrid stream. Turning it on when
 * the newest result lacks the grid relights the last state, so the grid follows soon. */
void lc_compute_want_grid(lc_compute *c, int whole);
/* Relights finished so far (for /metrics). */
uint64_t lc_compute_count(lc_compute *c);

/* Relight-time histogram for /metrics: cumulative counts per upper bound (ms), the last
 * bound +Inf, plus the sum of milliseconds. */
#define LC_COMPUTE_BUCKETS 11
extern const double lc_compute_bucket_ms[LC_COMPUTE_BUCKETS];
void lc_compute_histogram(lc_compute *c, uint64_t counts[LC_COMPUTE_BUCKETS], double *sum_ms);
/* Finishes the relight in flight and joins the thread; after it returns the wake callback
 * is not called again (lucentd may then destroy its lws context). References to results stay valid
 * (release them, then lc_compute_release). NULL-safe. */
void lc_compute_stop(lc_compute *c);
/* Frees the compute object (stops it first if needed). Every lc_published reference must
 * have been released. NULL-safe. */
void lc_compute_release(lc_compute *c);
/* The revision whose last relight failed (0 when the newest relight succeeded), the total
 * count of failed relights in *failures and the cause in why. Any thread. */
uint64_t lc_compute_failure(lc_compute *c, uint64_t *failures, char *why, size_t whylen);
const char *lc_compute_backend(lc_compute *c);
/* The same as LC_BACKEND_CPU or LC_BACKEND_EGL (which solvers the state may pick). */
lc_backend_kind lc_compute_backend_kind(lc_compute *c);

#endif
