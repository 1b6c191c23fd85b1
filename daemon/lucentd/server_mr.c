/* server_mr: MR sessions on the service thread (PROTOCOL.md §8) — mr.begin / mr.end, upload
 * frames checked and handed to the MR worker (mr_worker.h) with the session's sparse points
 * placed in world space, the worker's results turned into acknowledgements and into the light
 * the objects and mr.vpl streams carry. Upload frames are never journaled, logged or
 * written: the parsed frame moves to the worker, which frees it once decoded (§8.5).
 * Service thread, every function. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "engine/scene_math.h"
#include "server_internal.h"
#include "util/clock.h"
#include "util/log.h"

/* A session's MR state (lc_session.mr while a session is open). */
struct server_mr_session {
    uint32_t slot;  /* in lc_server.mr_slots and the worker */
    uint64_t epoch; /* names this mr.begin: results of an earlier one are dropped */
    lc_proto_mr_session req;
    lc_upload_expect expect;
    uint32_t last_seq;
    double tokens, refill_ms; /* frame rate: a bucket of 2 refilled at the granted rate */
    double rate;
    /* smoothing (§8.2): the previous outputs, per object */
    int have_prev;
    float prev_t[3], prev_q[4];
};

static void mr_wake(void *arg) { lws_cancel_service(((lc_server *)arg)->ctx); }

/* The state's object with this id (objects are sorted by id), or NULL. */
static const lc_proto_object *mr_find_object(const lc_state *st, const char *id) {
    uint32_t lo = 0, hi = st->n_objects;
    while (lo < hi) {
        uint32_t mid = lo + (hi - lo) / 2;
        int c = strcmp(st->objects[mid].id, id);
        if (!c) return &st->objects[mid];
        if (c < 0) lo = mid + 1;
        else hi = mid;
    }
    return NULL;
}

/* The bake's asset index of an object, or -1. */
static int mr_asset_of(const lc_server *s, const lc_proto_object *o) {
    for (uint32_t a = 0; o && a < s->v->n_assets; a++)
        if (!strcmp(s->asset_names[a], o->asset)) return (int)a;
    return -1;
}

/* The sparse points of an object's asset (0 when it has none or is gone). */
static uint32_t mr_object_points(const lc_server *s, const lc_proto_object *o, uint32_t *first) {
    int a = mr_asset_of(s, o);
    uint32_t count = 0;
    *first = 0;
    if (a >= 0) lc_lcb_asset_sparse(s->v, (uint32_t)a, first, &count);
    return count;
}

int server_mr_start(lc_server *s, char *err, size_t errlen) {
    if (!s->cfg->mr) return 0;
    uint32_t points = 0;
    for (uint32_t a = 0; a < s->v->n_assets; a++) {
        uint32_t first = 0, count = 0;
        lc_lcb_asset_sparse(s->v, a, &first, &count);
        points += count;
    }
    if (!points) {
        lc_info("mr", "MR sessions off: the bake has no sparse points (bake with --mr-points, the default 256)");
        return 0;
    }
    s->mrw = lc_mrw_start(s->cfg->threads, s->cfg->backend, mr_wake, s, err, errlen);
    return s->mrw ? 0 : -1;
}

void server_mr_stop(lc_server *s) {
    lc_mrw_stop(s->mrw);
    s->mrw = NULL;
    for (uint32_t i = 0; i < s->n_mr_entries; i++) free(s->mr_entries[i].vpl);
    free(s->mr_entries);
    s->mr_entries = NULL;
    s->n_mr_entries = 0;
}

int server_mr_available(const lc_server *s) { return s->mrw != NULL; }

/* Drops the light of a slot's session from what the streams carry. */
static void mr_entries_drop_slot(lc_server *s, uint32_t slot) {
    uint32_t o = 0;
    for (uint32_t i = 0; i < s->n_mr_entries; i++) {
        if (s->mr_entries[i].slot == slot) {
            free(s->mr_entries[i].vpl);
            continue;
        }
        s->mr_entries[o++] = s->mr_entries[i];
    }
    if (o != s->n_mr_entries) {
        s->n_mr_entries = o;
        s->mr_seq++;
    }
}

void server_mr_end(lc_server *s, lc_session *ss) {
    struct server_mr_session *m = ss->mr;
    if (!m) return;
    lc_mrw_cancel(s->mrw, m->slot);
    mr_entries_drop_slot(s, m->slot);
    s->mr_slots[m->slot] = NULL;
    free(m);
    ss->mr = NULL;
    if (s->mrw) /* not while the server stops: the streams' subscribers see the objects' grid light again */
        for (lc_session *o = s->sessions; o; o = o->next)
            if (o->authed && o != ss) lws_callback_on_writable(o->wsi);
}

/* The session's objects must exist and have sparse points; 0 or the index of the bad one + 1. */
static uint32_t mr_check_objects(const lc_server *s, const lc_proto_mr_session *r, const char **why) {
    for (uint32_t i = 0; i < r->n_objects; i++) {
        const lc_proto_object *o = mr_find_object(&s->state, r->objects[i]);
        if (!o) {
            *why = "no object with this id in the state";
            return i + 1;
        }
        uint32_t first;
        uint32_t count = mr_object_points(s, o, &first);
        if (!count) {
            *why = "the object's asset has no sparse points in this bake";
            return i + 1;
        }
    }
    return 0;
}

void server_mr_begin(lc_server *s, lc_session *ss, const lc_proto_request *req) {
    const lc_proto_mr_session *r = &req->mr;
    if (!ss->mr_granted) {
        session_error(s, ss, &req->id, LC_ERR_MR_NOT_ENABLED, "/type",
                      s->mrw ? "MR sessions need the \"mr\" capability in hello (controllers only)"
                             : "this server has MR sessions off (--no-mr, or a bake without sparse points)");
        return;
    }
    const char *why = NULL;
    uint32_t bad = mr_check_objects(s, r, &why);
    if (bad) {
        char ptr[64];
        snprintf(ptr, sizeof ptr, "/session/objects/%u", bad - 1);
        session_error(s, ss, &req->id, LC_ERR_UNKNOWN_ID, ptr, why);
        return;
    }
    server_mr_end(s, ss); /* a second mr.begin replaces the first */
    uint32_t slot = LC_MRW_SLOTS, used = 0;
    for (uint32_t k = 0; k < LC_MRW_SLOTS; k++) {
        if (s->mr_slots[k]) used++;
        else if (slot == LC_MRW_SLOTS) slot = k;
    }
    if (used >= (uint32_t)s->cfg->mr_max_sessions || slot == LC_MRW_SLOTS) {
        session_error(s, ss, &req->id, LC_ERR_LIMIT_EXCEEDED, "",
                      "too many MR sessions on this server (--mr-max-sessions); try again later");
        return;
    }
    struct server_mr_session *m = calloc(1, sizeof *m);
    if (!m) {
        session_error(s, ss, &req->id, LC_ERR_INTERNAL, "", "out of memory");
        return;
    }
    m->slot = slot;
    m->epoch = ++s->mr_epoch;
    m->req = *r;
    m->expect.width = (uint16_t)r->width;
    m->expect.height = (uint16_t)r->height;
    m->expect.depth_encoding = (uint8_t)r->depth_encoding;
    m->expect.color_encoding = (uint8_t)r->color_encoding;
    m->expect.max_frame = (size_t)s->cfg->mr_max_frame;
    m->rate = fmin(r->max_rate, s->cfg->mr_max_rate);
    m->tokens = 2;
    m->refill_ms = lc_clock_ms();
    s->mr_slots[slot] = m;
    ss->mr = m;
    uint32_t points = 0, first;
    for (uint32_t i = 0; i < r->n_objects; i++)
        points += mr_object_points(s, mr_find_object(&s->state, r->objects[i]), &first);
    lc_info("mr", "client '%s' began MR session %u: %u objects, %ux%u, %.3g frames/s", ss->client, slot, r->n_objects,
            r->width, r->height, m->rate);
    session_send(ss,
                 lc_proto_build_ok_mr(&req->id, s->state.revision, (uint32_t)m->epoch, (uint64_t)s->cfg->mr_max_frame,
                                      m->rate, (uint32_t)s->cfg->mr_max_lights, points));
}

/* World-space sparse points of the session's objects (those still in the state), into job. */
static int mr_place_points(lc_server *s, const struct server_mr_session *m, lc_mrw_job *job) {
    const lc_proto_mr_session *r = &m->req;
    uint32_t total = 0;
    const lc_proto_object *objs[16];
    int assets[16];
    for (uint32_t i = 0; i < r->n_objects; i++) {
        objs[i] = mr_find_object(&s->state, r->objects[i]);
        assets[i] = mr_asset_of(s, objs[i]);
        uint32_t first;
        total += mr_object_points(s, objs[i], &first);
    }
    uint32_t n = r->n_objects;
    job->ids = calloc(n, sizeof *job->ids);
    job->centres = calloc(n, sizeof *job->centres);
    job->first_point = calloc(n + 1, sizeof *job->first_point);
    job->points = calloc(total ? total : 1, sizeof *job->points);
    job->object_of_point = calloc(total ? total : 1, sizeof *job->object_of_point);
    if (!job->ids || !job->centres || !job->first_point || !job->points || !job->object_of_point) return -1;
    uint32_t k = 0;
    for (uint32_t i = 0; i < n; i++) {
        job->first_point[i] = k;
        snprintf(job->ids[i], sizeof job->ids[i], "%s", r->objects[i]);
        if (assets[i] < 0) continue; /* removed since mr.begin: no points, no light */
        lc_engine_object eo = {0};
        memcpy(eo.translation, objs[i]->translation, sizeof eo.translation);
        memcpy(eo.rotation, objs[i]->rotation, sizeof eo.rotation);
        memcpy(eo.scale, objs[i]->scale, sizeof eo.scale);
        float mtx[12];
        lc_sm_object_matrix(&eo, mtx);
        const lc_lcb_asset *as = &s->v->assets[assets[i]];
        float c[3];
        for (int d = 0; d < 3; d++) c[d] = 0.5f * (as->bounds_min[d] + as->bounds_max[d]);
        lc_sm_transform_point(mtx, c, job->centres[i]);
        float smax = fmaxf(fabsf(eo.scale[0]), fmaxf(fabsf(eo.scale[1]), fabsf(eo.scale[2])));
        uint32_t first, count = mr_object_points(s, objs[i], &first);
        for (uint32_t p = 0; p < count; p++, k++) {
            const lc_lcb_sparse_point *sp = &s->v->sparse_points[first + p];
            lc_mr_point *q = &job->points[k];
            lc_sm_transform_point(mtx, sp->position, q->position);
            /* normals by the inverse transpose: R S^-1 n = sum_c M_c n_c / s_c^2 */
            float nn[3] = {0, 0, 0};
            for (int col = 0; col < 3; col++) {
                float f = sp->normal[col] / (eo.scale[col] * eo.scale[col]);
                for (int d = 0; d < 3; d++) nn[d] += mtx[col * 3 + d] * f;
            }
            float len = lc_sm_len(nn);
            for (int d = 0; d < 3; d++) q->normal[d] = len > 0 ? nn[d] / len : 0;
            q->radius = sp->radius * smax;
            job->object_of_point[k] = i;
        }
    }
    job->first_point[n] = k;
    job->n_points = k;
    job->n_objects = n;
    return 0;
}

static void mr_send_ack(lc_session *ss, uint32_t seq, uint64_t capture_us, int replaced, uint32_t lights, double ms) {
    session_send(ss, lc_proto_build_mr_ack(seq, capture_us, replaced, lights, ms));
}

/* One complete binary message from a session (the receive path bounds it by max_frame). */
void server_mr_frame(lc_server *s, lc_session *ss, const uint8_t *data, size_t len) {
    lc_proto_id none = {0};
    struct server_mr_session *m = ss->mr;
    if (!m) {
        session_error(s, ss, &none, LC_ERR_MR_NOT_ENABLED, "",
                      "an upload frame outside an MR session: send mr.begin first (PROTOCOL.md §8.2)");
        return;
    }
    lc_mrw_job *job = calloc(1, sizeof *job);
    if (!job) {
        session_error(s, ss, &none, LC_ERR_INTERNAL, "", "out of memory");
        return;
    }
    lc_proto_error e;
    if (lc_upload_parse(data, len, &m->expect, &job->frame, &e) != 0) {
        lc_mrw_job_free(job);
        server_count_error(s, e.code);
        session_send(ss, lc_proto_build_error(&none, &e));
        return;
    }
    if (job->frame.h.sequence <= m->last_seq) {
        char msg[128];
        snprintf(msg, sizeof msg, "sequence %u does not follow the session's last frame (%u)", job->frame.h.sequence,
                 m->last_seq);
        lc_mrw_job_free(job);
        session_error(s, ss, &none, LC_ERR_FRAME_INVALID, "/header/sequence", msg);
        return;
    }
    /* Only frames that pass the checks count against the rate (a bucket of 2): a malformed
     * one is answered at once and costs no LightSkin work. */
    double now = lc_clock_ms();
    m->tokens = fmin(2.0, m->tokens + (now - m->refill_ms) * 1e-3 * m->rate);
    m->refill_ms = now;
    if (m->tokens < 1) {
        lc_mrw_job_free(job);
        session_error(s, ss, &none, LC_ERR_RATE_LIMITED, "", "upload frames over the session's max_rate; slow down");
        return;
    }
    m->tokens -= 1;
    m->last_seq = job->frame.h.sequence;
    s->mr_frames_in++;
    s->mr_bytes_in += len;
    job->slot = m->slot;
    job->epoch = m->epoch;
    job->params = lc_mr_params_default();
    job->params.max_lights = (uint32_t)s->cfg->mr_max_lights;
    job->params.min_confidence = m->req.min_confidence;
    job->params.spec_exponent = m->req.specular_exponent;
    job->params.glossy = m->req.glossy;
    job->params.smoothing = m->req.smoothing;
    if (mr_place_points(s, m, job) != 0) {
        lc_mrw_job_free(job);
        session_error(s, ss, &none, LC_ERR_INTERNAL, "", "out of memory");
        return;
    }
    uint32_t replaced = 0;
    uint64_t replaced_capture = 0;
    if (lc_mrw_submit(s->mrw, job, &replaced, &replaced_capture) != 0) return;
    if (replaced) mr_send_ack(ss, replaced, replaced_capture, 1, 0, 0);
}

/* Replaces a slot's entries with a result's objects (sorted by id for the mr.vpl stream). */
static int mr_entry_cmp(const void *a, const void *b) {
    return strcmp(((const server_mr_entry *)a)->id, ((const server_mr_entry *)b)->id);
}

static void mr_apply_result(lc_server *s, const struct server_mr_session *m, lc_mrw_result *r) {
    mr_entries_drop_slot(s, m->slot);
    server_mr_entry *grown = realloc(s->mr_entries, (s->n_mr_entries + r->n_objects + 1) * sizeof *grown);
    if (!grown) return;
    s->mr_entries = grown;
    for (uint32_t i = 0; i < r->n_objects; i++) {
        server_mr_entry *e = &s->mr_entries[s->n_mr_entries];
        memset(e, 0, sizeof *e);
        snprintf(e->id, sizeof e->id, "%s", r->ids[i]);
        memcpy(e->sh, r->sh[i], sizeof e->sh);
        e->add = m->req.light_add;
        e->slot = m->slot;
        e->n_points = r->first_point[i + 1] - r->first_point[i];
        e->vpl = malloc((e->n_points ? e->n_points : 1) * sizeof *e->vpl);
        if (!e->vpl) continue;
        memcpy(e->vpl, r->vpl + r->first_point[i], e->n_points * sizeof *e->vpl);
        s->n_mr_entries++;
    }
    qsort(s->mr_entries, s->n_mr_entries, sizeof *s->mr_entries, mr_entry_cmp);
    s->mr_seq++;
}

void server_mr_collect(lc_server *s) {
    if (!s->mrw) return;
    lc_mrw_result *r;
    int changed = 0;
    while ((r = lc_mrw_take(s->mrw))) {
        struct server_mr_session *m = s->mr_slots[r->slot];
        lc_session *owner = NULL;
        for (lc_session *o = s->sessions; o && m; o = o->next)
            if (o->mr == m) owner = o;
        if (!m || !owner || m->epoch != r->epoch) { /* the session ended meanwhile */
            lc_mrw_result_free(r);
            continue;
        }
        if (r->failed) {
            lc_proto_id none = {0};
            session_error(s, owner, &none, LC_ERR_INTERNAL, "", r->why);
        } else {
            mr_apply_result(s, m, r);
            changed = 1;
        }
        mr_send_ack(owner, r->sequence, r->capture_us, 0, r->lights, r->ms);
        s->mr_last_ms = r->ms;
        s->mr_last_timings = r->timings;
        lc_mrw_result_free(r);
    }
    if (changed)
        for (lc_session *o = s->sessions; o; o = o->next)
            if (o->authed) lws_callback_on_writable(o->wsi);
}

size_t server_mr_encode_vpl(lc_server *s, lc_session *ss, lc_encoding enc, uint64_t sequence) {
    lc_frames_vpl_object objs[LC_MRW_SLOTS * 16];
    uint32_t n = 0;
    _Static_assert(sizeof(lc_mr_vpl) == 12 * sizeof(float), "an mr.vpl record is 12 floats");
    for (uint32_t i = 0; i < s->n_mr_entries && n < LC_MRW_SLOTS * 16; i++)
        objs[n++] = (lc_frames_vpl_object){.id = s->mr_entries[i].id,
                                           .n_points = s->mr_entries[i].n_points,
                                           .records = (const float *)s->mr_entries[i].vpl};
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    uint64_t now_us = (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
    return lc_frames_encode_vpl(&ss->copy, objs, n, enc, s->state.revision, sequence, now_us, LWS_PRE);
}
