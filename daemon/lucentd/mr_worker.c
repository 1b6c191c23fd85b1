/* mr_worker: see mr_worker.h. */
#include "mr_worker.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gpu/mr_gl.h"
#include "util/clock.h"
#include "util/log.h"

#define MRW_RESULTS_MAX 64 /* unconsumed results kept; past it the oldest goes (the service thread is stuck) */

struct lc_mrw {
    pthread_t thread;
    int started;
    pthread_mutex_t lock; /* mrw.lock: everything below */
    pthread_cond_t cond;
    int stop;
    lc_mrw_job *pending[LC_MRW_SLOTS];
    uint32_t next_slot; /* round robin over the slots */
    lc_mrw_result *results[MRW_RESULTS_MAX];
    uint32_t results_head, results_n;
    uint64_t processed, replaced;
    /* the worker thread's own: one LightSkin state per slot (its smoothing history belongs to
     * that slot's session; a new epoch starts it afresh), created on the slot's first frame */
    lc_mr *mr[LC_MRW_SLOTS];
    uint64_t mr_epoch[LC_MRW_SLOTS];
    lc_mr_gl *gl; /* the gather on GL compute (NULL: CPU); its EGL context is the worker's */
    int backend;  /* 0 auto (EGL on a hardware device only), 1 cpu, 2 egl */
    int gl_ready; /* mrw.lock: 0 while the worker sets up its backend, 1 done, -1 failed (gl_err) */
    char gl_err[256];
    int threads;
    lc_mrw_wake_fn wake;
    void *wake_arg;
};

void lc_mrw_job_free(lc_mrw_job *job) {
    if (!job) return;
    lc_upload_frame_release(&job->frame);
    free(job->ids);
    free(job->centres);
    free(job->first_point);
    free(job->points);
    free(job->object_of_point);
    free(job);
}

void lc_mrw_result_free(lc_mrw_result *r) {
    if (!r) return;
    free(r->ids);
    free(r->sh);
    free(r->first_point);
    free(r->vpl);
    free(r);
}

static void mrw_drop_gl(lc_mrw *w);

/* Worker thread: one frame through the LightSkin stages. The job's frame is released here,
 * whatever happens. */
static lc_mrw_result *mrw_process(lc_mrw *w, lc_mrw_job *job) {
    double t0 = lc_clock_ms();
    lc_mrw_result *r = calloc(1, sizeof *r);
    if (!r) goto done;
    r->slot = job->slot;
    r->epoch = job->epoch;
    r->sequence = job->frame.h.sequence;
    r->capture_us = job->frame.h.capture_us;
    const lc_upload_header *h = &job->frame.h;
    size_t px = (size_t)h->width * h->height;
    float *depth = malloc(px * sizeof *depth), *rad = malloc(px * 3 * sizeof *rad), *conf = NULL;
    if (job->frame.confidence) conf = malloc(px * sizeof *conf);
    if (!depth || !rad || (job->frame.confidence && !conf)) {
        snprintf(r->why, sizeof r->why, "out of memory decoding the frame");
        r->failed = 1;
        goto decoded;
    }
    lc_upload_depth_metres(&job->frame, depth);
    lc_upload_radiance(&job->frame, rad);
    if (conf) lc_upload_confidence(&job->frame, conf);
    lc_upload_frame_release(&job->frame); /* privacy: the frame is gone before the light is computed */
    lc_mr_camera cam = {.width = h->width, .height = h->height, .fx = h->fx, .fy = h->fy, .cx = h->cx, .cy = h->cy};
    memcpy(cam.translation, h->translation, sizeof cam.translation);
    memcpy(cam.rotation, h->rotation, sizeof cam.rotation);
    if (!w->mr[job->slot] && !(w->mr[job->slot] = lc_mr_create(w->threads))) {
        snprintf(r->why, sizeof r->why, "out of memory for the LightSkin state");
        r->failed = 1;
        goto decoded;
    }
    lc_mr *mr = w->mr[job->slot];
    lc_mr_set_gl(mr, w->gl);
    if (w->mr_epoch[job->slot] != job->epoch) lc_mr_reset_history(mr);
    w->mr_epoch[job->slot] = job->epoch;
    if (lc_mr_set_frame(mr, &cam, depth, rad, conf, &job->params, r->why, sizeof r->why) != 0) {
        r->failed = 1;
        goto decoded;
    }
    r->lights = lc_mr_light_count(mr);
    r->n_objects = job->n_objects;
    r->n_points = job->n_points;
    r->sh = calloc(job->n_objects ? job->n_objects : 1, sizeof *r->sh);
    r->vpl = calloc(job->n_points ? job->n_points : 1, sizeof *r->vpl);
    if (!r->sh || !r->vpl) {
        snprintf(r->why, sizeof r->why, "out of memory for the results");
        r->failed = 1;
        goto decoded;
    }
    char why[200];
    int rc = lc_mr_compute(mr, job->points, job->n_points, job->object_of_point, job->n_objects,
                           (const float(*)[3])job->centres, r->vpl, NULL, r->sh, why, sizeof why);
    if (rc != 0 && w->gl) { /* GL failed: the CPU from now on, this frame included */
        lc_warn("mr", "the GL gather failed (%s): MR sessions use the CPU from now on", why);
        mrw_drop_gl(w);
        rc = lc_mr_compute(mr, job->points, job->n_points, job->object_of_point, job->n_objects,
                           (const float(*)[3])job->centres, r->vpl, NULL, r->sh, why, sizeof why);
    }
    if (rc != 0) {
        snprintf(r->why, sizeof r->why, "the LightSkin computation failed: %s", why);
        r->failed = 1;
        goto decoded;
    }
    lc_mr_stats(mr, &r->timings);
    /* The ids and the point ranges travel on to the result (the service thread matches them). */
    r->ids = job->ids;
    r->first_point = job->first_point;
    job->ids = NULL;
    job->first_point = NULL;
decoded:
    free(depth);
    free(rad);
    free(conf);
    r->ms = lc_clock_ms() - t0;
done:
    lc_mrw_job_free(job);
    return r;
}

static void mrw_push_result(lc_mrw *w, lc_mrw_result *r) {
    if (w->results_n == MRW_RESULTS_MAX) {
        lc_mrw_result_free(w->results[w->results_head]);
        w->results_head = (w->results_head + 1) % MRW_RESULTS_MAX;
        w->results_n--;
    }
    w->results[(w->results_head + w->results_n) % MRW_RESULTS_MAX] = r;
    w->results_n++;
}

/* Worker thread: the next pending job, round robin over the slots (mrw.lock held). */
static lc_mrw_job *mrw_next_job(lc_mrw *w) {
    for (uint32_t k = 0; k < LC_MRW_SLOTS; k++) {
        uint32_t slot = (w->next_slot + k) % LC_MRW_SLOTS;
        if (!w->pending[slot]) continue;
        lc_mrw_job *job = w->pending[slot];
        w->pending[slot] = NULL;
        w->next_slot = (slot + 1) % LC_MRW_SLOTS;
        return job;
    }
    return NULL;
}

/* Worker thread: detaches the GL gather from every slot's state and frees it (its context is
 * current on this thread). */
static void mrw_drop_gl(lc_mrw *w) {
    for (uint32_t k = 0; k < LC_MRW_SLOTS; k++)
        if (w->mr[k]) lc_mr_set_gl(w->mr[k], NULL);
    lc_mr_gl_release(w->gl);
    w->gl = NULL;
}

/* Worker thread: the backend, as the relight's --backend (auto: EGL on a hardware device only,
 * llvmpipe being slower than the CPU). 0, or -1 with w->gl_err (egl asked for and not had). */
static int mrw_setup_backend(lc_mrw *w) {
    if (w->backend == 1) return 0;
    w->gl = lc_mr_gl_create(w->gl_err, sizeof w->gl_err);
    if (!w->gl) {
        if (w->backend == 2) return -1;
        lc_info("mr", "MR gather: cpu (auto: %s)", w->gl_err);
        return 0;
    }
    if (w->backend == 0 && lc_mr_gl_is_software(w->gl)) {
        lc_info("mr", "MR gather: cpu (auto: %s is a software rasterizer)", lc_mr_gl_description(w->gl));
        mrw_drop_gl(w);
        return 0;
    }
    lc_info("mr", "MR gather: %s", lc_mr_gl_description(w->gl));
    return 0;
}

static void *mrw_main(void *arg) {
    lc_mrw *w = arg;
    int ok = mrw_setup_backend(w) == 0;
    pthread_mutex_lock(&w->lock);
    w->gl_ready = ok ? 1 : -1;
    pthread_cond_broadcast(&w->cond);
    if (!ok) {
        pthread_mutex_unlock(&w->lock);
        return NULL;
    }
    for (;;) {
        lc_mrw_job *job = NULL;
        while (!w->stop && !(job = mrw_next_job(w))) pthread_cond_wait(&w->cond, &w->lock);
        if (w->stop) {
            lc_mrw_job_free(job);
            break;
        }
        pthread_mutex_unlock(&w->lock);
        lc_mrw_result *r = mrw_process(w, job);
        pthread_mutex_lock(&w->lock);
        if (r) {
            if (r->failed) lc_warn("mr", "frame %u of MR slot %u: %s", r->sequence, r->slot, r->why);
            mrw_push_result(w, r);
            w->processed++;
        }
        pthread_mutex_unlock(&w->lock);
        w->wake(w->wake_arg);
        pthread_mutex_lock(&w->lock);
    }
    pthread_mutex_unlock(&w->lock);
    mrw_drop_gl(w);
    return NULL;
}

lc_mrw *lc_mrw_start(int threads, int backend, lc_mrw_wake_fn wake, void *wake_arg, char *err, size_t errlen) {
    lc_mrw *w = calloc(1, sizeof *w);
    if (!w) {
        snprintf(err, errlen, "out of memory");
        return NULL;
    }
    pthread_mutex_init(&w->lock, NULL);
    pthread_cond_init(&w->cond, NULL);
    w->threads = threads;
    w->backend = backend;
    w->wake = wake;
    w->wake_arg = wake_arg;
    if (pthread_create(&w->thread, NULL, mrw_main, w) != 0) {
        snprintf(err, errlen, "cannot start the MR worker thread");
        goto err;
    }
    w->started = 1;
    pthread_mutex_lock(&w->lock); /* the worker's backend is set up before the first frame */
    while (!w->gl_ready) pthread_cond_wait(&w->cond, &w->lock);
    int failed = w->gl_ready < 0;
    pthread_mutex_unlock(&w->lock);
    if (failed) {
        snprintf(err, errlen, "MR sessions with --backend egl: %s", w->gl_err);
        goto err;
    }
    return w;
err:
    lc_mrw_stop(w);
    return NULL;
}

int lc_mrw_submit(lc_mrw *w, lc_mrw_job *job, uint32_t *replaced_seq, uint64_t *replaced_capture) {
    *replaced_seq = 0;
    *replaced_capture = 0;
    if (job->slot >= LC_MRW_SLOTS) {
        lc_mrw_job_free(job);
        return -1;
    }
    lc_mrw_job *old = NULL;
    pthread_mutex_lock(&w->lock);
    int stopping = w->stop;
    if (!stopping) {
        old = w->pending[job->slot];
        w->pending[job->slot] = job;
        if (old) w->replaced++;
        pthread_cond_signal(&w->cond);
    }
    pthread_mutex_unlock(&w->lock);
    if (stopping) {
        lc_mrw_job_free(job);
        return -1;
    }
    if (old) {
        *replaced_seq = old->frame.h.sequence;
        *replaced_capture = old->frame.h.capture_us;
        lc_mrw_job_free(old);
    }
    return 0;
}

void lc_mrw_cancel(lc_mrw *w, uint32_t slot) {
    if (!w || slot >= LC_MRW_SLOTS) return;
    pthread_mutex_lock(&w->lock);
    lc_mrw_job *old = w->pending[slot];
    w->pending[slot] = NULL;
    pthread_mutex_unlock(&w->lock);
    lc_mrw_job_free(old);
}

lc_mrw_result *lc_mrw_take(lc_mrw *w) {
    lc_mrw_result *r = NULL;
    pthread_mutex_lock(&w->lock);
    if (w->results_n) {
        r = w->results[w->results_head];
        w->results_head = (w->results_head + 1) % MRW_RESULTS_MAX;
        w->results_n--;
    }
    pthread_mutex_unlock(&w->lock);
    return r;
}

void lc_mrw_counts(lc_mrw *w, uint64_t *processed, uint64_t *replaced) {
    pthread_mutex_lock(&w->lock);
    *processed = w->processed;
    *replaced = w->replaced;
    pthread_mutex_unlock(&w->lock);
}

void lc_mrw_stop(lc_mrw *w) {
    if (!w) return;
    if (w->started) {
        pthread_mutex_lock(&w->lock);
        w->stop = 1;
        pthread_cond_signal(&w->cond);
        pthread_mutex_unlock(&w->lock);
        pthread_join(w->thread, NULL);
    }
    for (uint32_t k = 0; k < LC_MRW_SLOTS; k++) lc_mrw_job_free(w->pending[k]);
    while (w->results_n) {
        lc_mrw_result_free(w->results[w->results_head]);
        w->results_head = (w->results_head + 1) % MRW_RESULTS_MAX;
        w->results_n--;
    }
    for (uint32_t k = 0; k < LC_MRW_SLOTS; k++) lc_mr_release(w->mr[k]);
    pthread_cond_destroy(&w->cond);
    pthread_mutex_destroy(&w->lock);
    free(w);
}
