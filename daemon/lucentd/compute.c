/* compute: the relight thread (see compute.h). Locks: `lock` guards pending, latest,
 * sequence, stop, count, the clutter operators handed over and every lc_published refcount. */
#include "compute.h"

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "engine/engine.h"
#include "util/clock.h"
#include "util/log.h"

typedef struct compute_job {
    uint64_t id;
    lc_engine_state st;
    lc_engine_light *lights;
    lc_engine_object *objects;
    float *emission;
    char (*object_ids)[LC_PROTO_ID_MAX + 1];
} compute_job;

struct lc_compute {
    const lc_lcb *bake;
    lc_compute_wake_fn wake; /* read-only after start */
    void *wake_arg;
    int backend, threads, refine_passes, refine_delay_ms, refine_restart;
    double refine_tolerance;
    pthread_t thread;
    pthread_mutex_t lock;
    pthread_cond_t cond;
    compute_job *pending;                    /* guarded by lock: newest unstarted submission */
    lc_published *latest;                    /* guarded by lock */
    uint64_t sequence;                       /* guarded by lock: publications so far */
    uint64_t count;                          /* guarded by lock */
    uint64_t hist[LC_COMPUTE_BUCKETS];       /* guarded by lock: relights per bucket (not cumulative) */
    double hist_sum_ms;                      /* guarded by lock */
    int stop;                                /* guarded by lock */
    uint64_t submitted;                      /* guarded by lock: last job id handed out */
    uint64_t discarded[LC_COMPUTE_DISCARDS]; /* guarded by lock: ring of job ids never to publish */
    unsigned discard_next;                   /* guarded by lock */
    int ready;                               /* guarded by lock: 1 engine up, -1 failed */
    char start_err[512];
    char backend_name[16];
    lc_backend_kind backend_kind; /* set before ready = 1, read only after */
    int joined;                   /* service thread only: lc_compute_stop has joined the thread */
    uint64_t failures;            /* guarded by lock: relights that failed */
    uint64_t failed_revision; /* guarded by lock: revision of the last failed relight (0 = the last one succeeded) */
    char failure[256];        /* guarded by lock: why it failed */
    lc_drt_ops **clutter_in;  /* guarded by lock: operators handed over, not yet attached */
    uint32_t n_clutter_in, clutter_in_cap; /* guarded by lock */
    int grid_whole;                        /* guarded by lock: relight with settings.grid_cells ALL */
    int regrid;                            /* guarded by lock: relight the last state for the whole grid */
    /* Set under lock with any of pending, stop, clutter_in or regrid; cleared under lock when the
     * compute thread takes that work; read without the lock to interrupt a refinement pass. */
    atomic_int work_waiting;
    uint64_t interrupted; /* compute thread only: refinement passes an update interrupted */
};

/* Compute thread and its relight workers (lc_engine_set_interrupt): a refinement pass stops
 * once an update (or other work) waits, so the update's frame need not wait for the pass. */
static int compute_work_waiting(void *arg) {
    lc_compute *c = arg;
    return atomic_load_explicit(&c->work_waiting, memory_order_relaxed);
}

static void compute_job_free(compute_job *j) {
    if (!j) return;
    free(j->lights);
    free(j->objects);
    free(j->emission);
    free(j->object_ids);
    free(j);
}

static void published_free(lc_published *p) {
    if (!p) return;
    free(p->lightmap);
    free(p->grid_sh);
    free(p->object_ids);
    free(p->object_sh);
    free(p->object_clutter);
    free(p);
}

/* Any thread, under c->lock. */
static int compute_is_discarded(const lc_compute *c, uint64_t job) {
    for (int i = 0; i < LC_COMPUTE_DISCARDS; i++)
        if (c->discarded[i] == job) return 1;
    return 0;
}

/* Compute thread. */
static lc_published *compute_publish(lc_engine *e, const lc_engine_frame *fr, compute_job *job) {
    lc_published *p = calloc(1, sizeof *p);
    if (!p) return NULL;
    size_t texels = (size_t)fr->lightmap_width * fr->lightmap_height;
    size_t cells = (size_t)fr->grid_dims[0] * fr->grid_dims[1] * fr->grid_dims[2];
    p->lightmap = malloc(texels * 3 * sizeof(float));
    p->grid_sh = malloc(cells * 27 * sizeof(float));
    p->object_sh = malloc(((size_t)fr->n_objects + 1) * 27 * sizeof(float));
    p->object_ids = malloc(((size_t)fr->n_objects + 1) * sizeof *p->object_ids);
    p->object_clutter = calloc((size_t)fr->n_objects + 1, sizeof *p->object_clutter);
    if (!p->lightmap || !p->grid_sh || !p->object_sh || !p->object_ids || !p->object_clutter) {
        published_free(p);
        return NULL;
    }
    memcpy(p->lightmap, fr->lightmap, texels * 3 * sizeof(float));
    memcpy(p->grid_sh, fr->grid_sh, cells * 27 * sizeof(float));
    if (fr->n_objects) {
        memcpy(p->object_sh, fr->object_sh, (size_t)fr->n_objects * 27 * sizeof(float));
        memcpy(p->object_ids, job->object_ids, (size_t)fr->n_objects * sizeof *p->object_ids);
    }
    for (uint32_t i = 0; i < fr->n_objects; i++) {
        lc_drt_info in;
        if (!lc_engine_clutter_info(e, job->st.objects[i].id, &in)) continue;
        p->object_clutter[i] = (lc_published_clutter){1, in.build_ms, in.bytes};
    }
    p->refs = 1;
    p->job = job->id;
    p->revision = fr->revision;
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    p->timestamp_us = (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
    p->relight_ms = fr->total_ms;
    p->lm_w = fr->lightmap_width;
    p->lm_h = fr->lightmap_height;
    memcpy(p->grid_dims, fr->grid_dims, sizeof p->grid_dims);
    p->grid_complete = fr->grid_complete;
    p->n_objects = fr->n_objects;
    return p;
}

/* Compute thread: what the refinement's stopping rule remembers of the passes so far. */
typedef struct compute_refine {
    float *luma;        /* W*H luminance of the last frame, NULL before one (or out of memory) */
    size_t texels;      /* entries of luma */
    double last_change; /* change of the previous refinement pass; < 0 before one */
} compute_refine;

/* Compute thread: sum |Y - Y_prev| / sum Y of fr's lightmap against the previous frame's (-1
 * when there is none to compare), then remembers fr's luminance. */
static double compute_frame_change(compute_refine *r, const lc_engine_frame *fr) {
    size_t texels = (size_t)fr->lightmap_width * fr->lightmap_height;
    int comparable = r->luma && r->texels == texels;
    if (!comparable) {
        free(r->luma);
        r->luma = malloc((texels ? texels : 1) * sizeof *r->luma);
        r->texels = r->luma ? texels : 0;
    }
    if (!r->luma) return -1;
    double diff = 0, sum = 0;
    for (size_t i = 0; i < texels; i++) {
        const float *c = fr->lightmap + 3 * i;
        float y = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
        if (comparable) diff += fabs((double)y - r->luma[i]);
        sum += y;
        r->luma[i] = y;
    }
    return comparable ? (sum > 0 ? diff / sum : 0) : -1;
}

/* Compute thread: after refinement pass `pass` (>= 1) changed the lightmap by `change`, is the
 * light still to come below tolerance? Each pass adds a bounce, so the changes fall roughly
 * geometrically (ratio q = change / last change, the scene's effective albedo): what the
 * passes left would add is about change * q / (1 - q). */
static int compute_refine_done(compute_refine *r, double change, double tolerance) {
    double last = r->last_change;
    r->last_change = change;
    if (tolerance <= 0 || change < 0) return 0;
    if (change == 0) return 1;
    if (last <= 0) return 0; /* one change says nothing about the rate */
    double q = change / last;
    double to_come = q < 1 ? change * q / (1 - q) : -1; /* -1: the changes are not falling */
    lc_debug("compute", "refinement: change %.6f ratio %.4f light to come %.6f", change, q, to_come);
    return to_come >= 0 && to_come <= tolerance;
}

static void *compute_main(void *arg) {
    lc_compute *c = arg;
    char err[512];
    lc_engine *e = lc_engine_create(c->bake, (lc_backend_kind)c->backend, c->threads, err, sizeof err);
    pthread_mutex_lock(&c->lock);
    if (!e) {
        snprintf(c->start_err, sizeof c->start_err, "%s", err);
        c->ready = -1;
    } else {
        snprintf(c->backend_name, sizeof c->backend_name, "%s", lc_engine_backend_name(e));
        c->backend_kind = lc_engine_backend(e);
        c->ready = 1;
    }
    pthread_cond_broadcast(&c->cond);
    pthread_mutex_unlock(&c->lock);
    if (!e) return NULL;
    /* The last state relit, kept for progressive refinement while no update is waiting:
     * each extra pass adds a bounce (same revision, a newer frame). */
    compute_job *last = NULL;
    compute_refine refine = {NULL, 0, -1};
    int refine_left = 0, pass = 0;
    struct timespec refine_due = {0, 0}; /* CLOCK_MONOTONIC: no refinement pass before this */
    for (;;) {
        pthread_mutex_lock(&c->lock);
        for (;;) {
            if (c->pending || c->stop || c->n_clutter_in || c->regrid) break;
            if (last && refine_left > 0) {
                /* The first refinement pass waits a moment after an update's frame, so
                 * that frame reaches the clients before the passes take the cores. */
                struct timespec now;
                clock_gettime(CLOCK_MONOTONIC, &now);
                if (now.tv_sec > refine_due.tv_sec ||
                    (now.tv_sec == refine_due.tv_sec && now.tv_nsec >= refine_due.tv_nsec))
                    break;
                pthread_cond_timedwait(&c->cond, &c->lock, &refine_due);
                continue;
            }
            pthread_cond_wait(&c->cond, &c->lock);
        }
        if (c->stop && !c->pending) { /* nothing left in flight */
            pthread_mutex_unlock(&c->lock);
            break;
        }
        compute_job *job = c->pending;
        c->pending = NULL;
        lc_drt_ops **clutter = c->clutter_in;
        uint32_t n_clutter = c->n_clutter_in;
        c->clutter_in = NULL;
        c->n_clutter_in = c->clutter_in_cap = 0;
        const int regrid = c->regrid, grid_whole = c->grid_whole;
        c->regrid = 0;
        atomic_store(&c->work_waiting, 0);
        pthread_mutex_unlock(&c->lock);
        for (uint32_t i = 0; i < n_clutter; i++)
            if (lc_engine_clutter_attach(e, clutter[i], err, sizeof err) != 0)
                lc_warn("compute", "clutter operators not applied: %s", err);
        free(clutter);
        if (!job && !last) continue;            /* operators before any state: the first relight applies them */
        int fresh = job || n_clutter || regrid; /* a new solution: its own series of refinement passes */
        if (fresh) {
            if (job) {
                compute_job_free(last);
                last = job;
            }
            refine_left = last->st.settings.progressive ? c->refine_passes : 0;
            pass = 0;
            if (c->refine_restart) lc_engine_reset_feedback(e);
        } else {
            refine_left--;
            pass++;
        }

        const lc_engine_frame *fr;
        lc_published *p = NULL;
        last->st.settings.grid_cells = grid_whole ? LC_GRID_ALL : LC_GRID_NEEDED;
        lc_engine_set_interrupt(e, fresh ? NULL : compute_work_waiting, c); /* a new solution always finishes */
        int rc = lc_engine_relight(e, &last->st, &fr, err, sizeof err);
        if (rc == LC_ENGINE_INTERRUPTED) { /* the work waiting comes first; the pass is redone after */
            refine_left++;
            pass--;
            c->interrupted++;
            lc_debug("compute", "refinement pass %d interrupted (%llu so far)", pass + 1,
                     (unsigned long long)c->interrupted);
            continue;
        }
        if (rc != 0) {
            lc_error("compute", "relight of revision %llu failed: %s", (unsigned long long)last->st.revision, err);
            refine_left = 0;
        } else {
            double change = compute_frame_change(&refine, fr);
            if (fresh) refine.last_change = -1; /* a new solution: its passes start a new series */
            else if (compute_refine_done(&refine, change, c->refine_tolerance)) refine_left = 0;
            p = compute_publish(e, fr, last);
            if (!p) {
                snprintf(err, sizeof err, "out of memory publishing the frame");
            } else {
                p->pass = (uint8_t)(pass < 255 ? pass : 255);
                p->converged = refine_left == 0;
            }
        }
        if (!p) {
            /* Clients were told `ok` for this revision: the service thread reports it
             * (an `error` event and /healthz), so the failure is not only in the log. */
            pthread_mutex_lock(&c->lock);
            c->failures++;
            c->failed_revision = last->st.revision ? last->st.revision : 1;
            snprintf(c->failure, sizeof c->failure, "%.255s", err);
            pthread_mutex_unlock(&c->lock);
            c->wake(c->wake_arg);
            continue;
        }
        pthread_mutex_lock(&c->lock);
        if (compute_is_discarded(c, p->job)) {
            pthread_mutex_unlock(&c->lock);
            published_free(p);
            refine_left = 0;
            continue;
        }
        lc_published *old = c->latest;
        c->latest = p;
        c->failed_revision = 0;
        if (c->grid_whole && !p->grid_complete) c->regrid = 1; /* wanted while this relight ran */
        c->sequence++;
        c->count++;
        int b = 0;
        while (b < LC_COMPUTE_BUCKETS - 1 && p->relight_ms > lc_compute_bucket_ms[b]) b++;
        c->hist[b]++;
        c->hist_sum_ms += p->relight_ms;
        if (old && --old->refs == 0) published_free(old);
        pthread_mutex_unlock(&c->lock);
        c->wake(c->wake_arg); /* lucentd: lws_cancel_service(), the only lws call made off the service thread */
        clock_gettime(CLOCK_MONOTONIC, &refine_due);
        if (fresh) refine_due.tv_nsec += (long)c->refine_delay_ms * 1000000L; /* later passes: back to back */
        refine_due.tv_sec += refine_due.tv_nsec / 1000000000L;
        refine_due.tv_nsec %= 1000000000L;
    }
    compute_job_free(last);
    free(refine.luma);
    lc_engine_release(e);
    return NULL;
}

lc_compute *lc_compute_start(const lc_lcb *bake, int backend, int threads, const lc_compute_refinement *refinement,
                             lc_compute_wake_fn wake, void *wake_arg, char *err, size_t errlen) {
    lc_compute *c = calloc(1, sizeof *c);
    if (!c) {
        lc_set_err(err, errlen, "out of memory");
        return NULL;
    }
    c->bake = bake;
    c->wake = wake;
    c->wake_arg = wake_arg;
    c->backend = backend;
    c->threads = threads;
    c->refine_passes = refinement->max_passes;
    c->refine_delay_ms = refinement->delay_ms;
    c->refine_tolerance = refinement->tolerance;
    c->refine_restart = refinement->restart;
    pthread_mutex_init(&c->lock, NULL);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC); /* refine_due is monotonic */
    pthread_cond_init(&c->cond, &ca);
    pthread_condattr_destroy(&ca);
    if (pthread_create(&c->thread, NULL, compute_main, c) != 0) {
        lc_set_err(err, errlen, "cannot start the compute thread");
        free(c);
        return NULL;
    }
    pthread_mutex_lock(&c->lock);
    while (c->ready == 0) pthread_cond_wait(&c->cond, &c->lock);
    int ok = c->ready == 1;
    pthread_mutex_unlock(&c->lock);
    if (!ok) {
        lc_set_err(err, errlen, "relight engine: %s", c->start_err);
        pthread_join(c->thread, NULL);
        free(c);
        return NULL;
    }
    return c;
}

int lc_compute_submit(lc_compute *c, const lc_state *state, uint64_t *job) {
    compute_job *j = calloc(1, sizeof *j);
    if (!j) return -1;
    if (lc_state_to_engine(state, &j->st, &j->lights, &j->objects, &j->emission) != 0) {
        free(j);
        return -1;
    }
    j->object_ids = calloc(state->n_objects ? state->n_objects : 1, sizeof *j->object_ids);
    if (!j->object_ids) {
        compute_job_free(j);
        return -1;
    }
    for (uint32_t i = 0; i < state->n_objects; i++)
        memcpy(j->object_ids[i], state->objects[i].id, sizeof j->object_ids[i]);
    pthread_mutex_lock(&c->lock);
    j->id = ++c->submitted;
    if (job) *job = j->id;
    compute_job *old = c->pending; /* latest wins */
    c->pending = j;
    pthread_cond_signal(&c->cond);
    atomic_store(&c->work_waiting, 1);
    pthread_mutex_unlock(&c->lock);
    compute_job_free(old);
    return 0;
}

void lc_compute_discard(lc_compute *c, uint64_t job) {
    compute_job *drop = NULL;
    lc_published *unpublish = NULL;
    pthread_mutex_lock(&c->lock);
    c->discarded[c->discard_next++ % LC_COMPUTE_DISCARDS] = job;
    if (c->pending && c->pending->id == job) {
        drop = c->pending;
        c->pending = NULL;
    }
    /* A fast relight may already have published it: the service thread (the caller) has not
     * taken it yet, since it only takes results between requests, so withdraw it. */
    if (c->latest && c->latest->job == job) {
        unpublish = c->latest;
        c->latest = NULL;
        if (--unpublish->refs > 0) unpublish = NULL;
    }
    pthread_mutex_unlock(&c->lock);
    compute_job_free(drop);
    published_free(unpublish);
}

lc_published *lc_compute_take_newer(lc_compute *c, uint64_t *seen) {
    lc_published *p = NULL;
    pthread_mutex_lock(&c->lock);
    if (c->latest && c->sequence > *seen) {
        p = c->latest;
        p->refs++;
        *seen = c->sequence;
    }
    pthread_mutex_unlock(&c->lock);
    return p;
}

void lc_published_release(lc_compute *c, lc_published *p) {
    if (!p) return;
    pthread_mutex_lock(&c->lock);
    int last = --p->refs == 0;
    pthread_mutex_unlock(&c->lock);
    if (last) published_free(p);
}

const double lc_compute_bucket_ms[LC_COMPUTE_BUCKETS] = {1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, INFINITY};

void lc_compute_histogram(lc_compute *c, uint64_t counts[LC_COMPUTE_BUCKETS], double *sum_ms) {
    pthread_mutex_lock(&c->lock);
    uint64_t acc = 0;
    for (int b = 0; b < LC_COMPUTE_BUCKETS; b++) counts[b] = acc += c->hist[b];
    *sum_ms = c->hist_sum_ms;
    pthread_mutex_unlock(&c->lock);
}

lc_published *lc_published_ref(lc_compute *c, lc_published *p) {
    pthread_mutex_lock(&c->lock);
    p->refs++;
    pthread_mutex_unlock(&c->lock);
    return p;
}

void lc_compute_want_grid(lc_compute *c, int whole) {
    pthread_mutex_lock(&c->lock);
    c->grid_whole = whole != 0;
    if (whole && c->latest && !c->latest->grid_complete) {
        c->regrid = 1;
        pthread_cond_signal(&c->cond);
        atomic_store(&c->work_waiting, 1);
    }
    pthread_mutex_unlock(&c->lock);
}

uint64_t lc_compute_count(lc_compute *c) {
    pthread_mutex_lock(&c->lock);
    uint64_t n = c->count;
    pthread_mutex_unlock(&c->lock);
    return n;
}

const char *lc_compute_backend(lc_compute *c) { return c->backend_name; }

lc_backend_kind lc_compute_backend_kind(lc_compute *c) { return c->backend_kind; }

void lc_compute_clutter_give(lc_compute *c, lc_drt_ops *ops) {
    if (!ops) return;
    pthread_mutex_lock(&c->lock);
    if (!c->stop && c->n_clutter_in == c->clutter_in_cap) {
        uint32_t cap = c->clutter_in_cap ? 2 * c->clutter_in_cap : 4;
        lc_drt_ops **grown = realloc(c->clutter_in, cap * sizeof *grown);
        if (grown) c->clutter_in = grown, c->clutter_in_cap = cap;
    }
    int stopping = c->stop;
    if (stopping || c->n_clutter_in == c->clutter_in_cap) {
        pthread_mutex_unlock(&c->lock);
        if (!stopping) lc_warn("compute", "out of memory handing over clutter operators; the object stays dynamic");
        lc_drt_ops_release(ops);
        return;
    }
    c->clutter_in[c->n_clutter_in++] = ops;
    pthread_cond_broadcast(&c->cond);
    atomic_store(&c->work_waiting, 1);
    pthread_mutex_unlock(&c->lock);
}

void lc_compute_stop(lc_compute *c) {
    if (!c) return;
    pthread_mutex_lock(&c->lock);
    c->stop = 1;
    compute_job *pending = c->pending; /* not started: dropped; a relight in flight finishes, a refinement pass stops */
    c->pending = NULL;
    pthread_cond_broadcast(&c->cond);
    atomic_store(&c->work_waiting, 1);
    pthread_mutex_unlock(&c->lock);
    compute_job_free(pending);
    pthread_join(c->thread, NULL);
    c->joined = 1;
}

void lc_compute_release(lc_compute *c) {
    if (!c) return;
    if (!c->joined) lc_compute_stop(c);
    lc_published_release(c, c->latest); /* sessions released theirs before (lc_compute_stop's contract) */
    for (uint32_t i = 0; i < c->n_clutter_in; i++) lc_drt_ops_release(c->clutter_in[i]); /* given while stopping */
    free(c->clutter_in);
    pthread_mutex_destroy(&c->lock);
    pthread_cond_destroy(&c->cond);
    free(c);
}

uint64_t lc_compute_failure(lc_compute *c, uint64_t *failures, char *why, size_t whylen) {
    pthread_mutex_lock(&c->lock);
    uint64_t rev = c->failed_revision;
    if (failures) *failures = c->failures;
    if (why && whylen) snprintf(why, whylen, "%s", c->failure);
    pthread_mutex_unlock(&c->lock);
    return rev;
}
