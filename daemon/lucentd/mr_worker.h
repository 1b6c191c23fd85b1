/* mr_worker: the MR sessions' LightSkin computation (PROTOCOL.md §8.6) on its own thread, so
 * an upload frame never waits for a relight and a relight never waits for a frame.
 *
 * The service thread hands over parsed upload frames with the session's sparse points
 * already placed in world space (lc_mrw_submit); each session has one pending slot, and a
 * newer frame replaces one not yet started (latest wins: the replaced frame's sequence is
 * returned so the server acknowledges it as replaced). The worker decodes the frame, runs
 * engine/mr.h, frees the frame at once (frames are never kept past their processing: the
 * privacy rule of §8.5) and queues a result, then wakes the service thread through the wake
 * callback (lucentd's calls lws_cancel_service()). This module knows nothing of sockets.
 *
 * Locking: `mrw.lock` guards the pending slots, the result queue and the stop flag; the
 * engine handle belongs to the worker thread. */
#ifndef LC_MR_WORKER_H
#define LC_MR_WORKER_H
#include <stdint.h>

#include "engine/mr.h"
#include "lucent_proto.h"
#include "lucent_upload.h"

#define LC_MRW_SLOTS 16 /* concurrent MR sessions a server can hold (--mr-max-sessions is at most this) */

typedef void (*lc_mrw_wake_fn)(void *arg);

/* One frame to process. Ownership of every pointer moves to the worker with lc_mrw_submit. */
typedef struct lc_mrw_job {
    uint32_t slot;  /* the session's slot, < LC_MRW_SLOTS */
    uint64_t epoch; /* which mr.begin of that slot (results of an older one are dropped) */
    lc_upload_frame frame;
    lc_mr_params params;
    uint32_t n_objects;
    char (*ids)[LC_PROTO_ID_MAX + 1]; /* n_objects */
    float (*centres)[3];              /* n_objects, world */
    uint32_t *first_point;            /* n_objects + 1: object k's points are [first[k], first[k+1]) */
    lc_mr_point *points;              /* world space */
    uint32_t *object_of_point;        /* per point */
    uint32_t n_points;
} lc_mrw_job;

/* What one processed frame gives. Owned by whoever took it; free with lc_mrw_result_free. */
typedef struct lc_mrw_result {
    uint32_t slot;
    uint64_t epoch;
    uint32_t sequence;
    uint64_t capture_us;
    uint32_t lights; /* area lights made from the frame */
    double ms;       /* the worker's time for it */
    lc_mr_timings timings;
    int failed; /* 1: `why` says what went wrong (nothing else is set) */
    char why[256];
    uint32_t n_objects;
    char (*ids)[LC_PROTO_ID_MAX + 1];
    float (*sh)[27]; /* per object: the irradiance SH of the capture's light at its centre */
    uint32_t *first_point;
    lc_mr_vpl *vpl; /* per point (§8.7 records) */
    uint32_t n_points;
} lc_mrw_result;

typedef struct lc_mrw lc_mrw;

/* Starts the worker (threads: the parallel loops' thread count, 0 = all cores; backend as the
 * relight's: 0 auto = the GL gather on a hardware EGL device, else the CPU; 1 cpu; 2 egl, where
 * no GL is an error). Returns once the worker has its backend; NULL + err. */
lc_mrw *lc_mrw_start(int threads, int backend, lc_mrw_wake_fn wake, void *wake_arg, char *err, size_t errlen);
/* Service thread: queues the job (ownership moves, also on failure). When a job of the same
 * slot was still pending it is dropped and its sequence/capture time returned in *replaced_seq
 * / *replaced_capture (0 when none). Returns 0, or -1 when stopping. */
int lc_mrw_submit(lc_mrw *w, lc_mrw_job *job, uint32_t *replaced_seq, uint64_t *replaced_capture);
/* Service thread: drops the slot's pending job (its session ended). */
void lc_mrw_cancel(lc_mrw *w, uint32_t slot);
/* Service thread: the oldest finished result, or NULL. */
lc_mrw_result *lc_mrw_take(lc_mrw *w);
void lc_mrw_result_free(lc_mrw_result *r);
/* Frames dropped because a newer one replaced them, and processed, so far (for /metrics). */
void lc_mrw_counts(lc_mrw *w, uint64_t *processed, uint64_t *replaced);
/* Service thread: frees a job that was never submitted. */
void lc_mrw_job_free(lc_mrw_job *job);
/* Finishes the frame in flight and joins the thread; no wake after it returns. NULL-safe. */
void lc_mrw_stop(lc_mrw *w);

#endif
