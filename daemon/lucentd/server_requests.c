/* server_requests: a session's text messages — hello (tokens, roles, the failed-hello
 * throttle), subscriptions, state changes (validated, journaled, acknowledged, broadcast,
 * relit) and queries. Service thread. */
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

#include "server.h"
#include "server_internal.h"
#include "util/clock.h"
#include "util/log.h"

/* The failed-hello budget of the peer address (a token bucket of SERVER_AUTH_BURST, refilled
 * SERVER_AUTH_PER_S a second), kept for the SERVER_AUTH_PEERS most recent addresses. */
static server_auth_peer *server_auth_peer_for(lc_server *s, const char *peer) {
    double now = lc_clock_ms();
    server_auth_peer *oldest = &s->auth_peers[0];
    for (int i = 0; i < SERVER_AUTH_PEERS; i++) {
        server_auth_peer *a = &s->auth_peers[i];
        if (a->peer[0] && !strcmp(a->peer, peer)) {
            a->tokens = fmin(SERVER_AUTH_BURST, a->tokens + (now - a->last_ms) * 1e-3 * SERVER_AUTH_PER_S);
            a->last_ms = now;
            return a;
        }
        if (a->last_ms < oldest->last_ms) oldest = a;
    }
    snprintf(oldest->peer, sizeof oldest->peer, "%s", peer);
    oldest->tokens = SERVER_AUTH_BURST;
    oldest->last_ms = now;
    return oldest;
}

/* A session that joined after the last publication has no frame yet: give it the newest
 * result so subscribe/snapshot can send a keyframe on an idle server (PROTOCOL.md §4.1). */
static void session_take_latest(lc_server *s, lc_session *ss) {
    if (ss->frame) return;
    uint64_t seq = 0;
    ss->frame = lc_compute_take_newer(s->compute, &seq);
    ss->frame_seq = seq;
}

/* welcome.scene.asset_info: per asset, its DNRT transfer grid from the bake (lcb.h ATRN), or
 * none. malloc'd (caller frees; {} without assets); NULL without memory (the field is then
 * not sent: it is optional). */
static lc_proto_asset_info *server_asset_info(const lc_lcb_view *v) {
    lc_proto_asset_info *info = calloc(v->n_assets ? v->n_assets : 1, sizeof *info);
    for (uint32_t a = 0; info && a < v->n_assets; a++) {
        const lc_lcb_transfer *t = lc_lcb_asset_transfer(v, a);
        if (!t) continue;
        info[a].has_transfer = 1;
        info[a].dims = t->dims;
        info[a].coefficients = t->coeffs;
        info[a].bytes = lc_lcb_transfer_bytes(t);
        info[a].outer_radius = t->outer_radius;
    }
    return info;
}

static void server_welcome(lc_server *s, lc_session *ss, const lc_proto_id *id) {
    lc_proto_welcome w;
    memset(&w, 0, sizeof w);
    lc_proto_asset_info *info = server_asset_info(s->v);
    w.server = "lucentd/" LUCENTD_VERSION;
    w.role = ss->controller ? "controller" : "viewer";
    w.revision = s->state.revision;
    w.lightmap_width = s->v->lightmap_width;
    w.lightmap_height = s->v->lightmap_height;
    w.tile = s->tile;
    memcpy(w.grid_origin, s->v->grid_origin, sizeof w.grid_origin);
    w.grid_cell = s->v->grid_cell;
    memcpy(w.grid_dims, s->v->grid_dims, sizeof w.grid_dims);
    w.bands = s->state.settings.bands;
    w.assets = s->asset_names;
    w.n_assets = s->v->n_assets;
    w.bake_id = s->bake_id;
    w.geometry = s->n_glbs ? s->glbs[0].path : NULL;
    w.asset_geometry = s->n_glbs ? s->asset_paths : NULL;
    w.asset_info = info;
    if (s->clw) {
        w.clutter_rest = s->cfg->clutter_rest;
        w.clutter_max_objects = (uint32_t)s->cfg->clutter_max_objects;
    }
    w.solvers = lc_state_solvers(&s->state);
    w.materials = s->material_names;
    w.n_materials = s->v->n_materials;
    w.limits = s->limits;
    w.max_lights = (uint32_t)s->cfg->max_lights;
    w.max_objects = (uint32_t)s->cfg->max_objects;
    w.rate = (uint32_t)s->cfg->rate;
    w.capabilities = ss->mr_granted ? LC_CAP_MR : 0;
    session_send(ss, lc_proto_build_welcome(id, &w));
    free(info);
}

static void server_change(lc_server *s, lc_session *ss, const lc_proto_request *req) {
    lc_state before;
    lc_proto_error e;
    char jerr[512];
    /* After a failed fsync the journal takes nothing until a snapshot succeeds: retry it
     * now (the tick retries once a second too); logged once by the journal, not per refusal. */
    if (lc_journal_broken(s->journal) && lc_journal_compact(s->journal, &s->state, jerr, sizeof jerr) != 0) {
        session_error(s, ss, &req->id, LC_ERR_INTERNAL, "",
                      "changes are refused: the journal's disk failed (the lucentd log says why); retry later");
        return;
    }
    if (lc_state_clone(&before, &s->state) != 0) {
        session_error(s, ss, &req->id, LC_ERR_INTERNAL, "", "out of memory");
        return;
    }
    if (lc_state_apply(&s->state, req->ops, req->n_ops, req->type == LC_REQ_BATCH, &e) != 0) {
        lc_state_release(&before);
        server_count_error(s, e.code);
        session_send(ss, lc_proto_build_error(&req->id, &e));
        return;
    }
    /* Relight while the journal fsyncs (~4 ms on a plain disk): the frames of this change
     * can only be sent after this function returns, i.e. after the change is durable. */
    uint64_t job = 0;
    if (lc_compute_submit(s->compute, &s->state, &job) != 0) lc_error("server", "out of memory submitting a relight");
    /* Durable before acknowledged: a failed append undoes the change and its relight. */
    if (lc_journal_append(s->journal, req->ops, req->n_ops, s->state.revision, jerr, sizeof jerr) != 0) {
        lc_error("server", "journal: %s; change refused", jerr);
        if (job) lc_compute_discard(s->compute, job);
        lc_state_release(&s->state);
        s->state = before;
        lc_compute_submit(s->compute, &s->state, NULL);
        server_clutter_sync(s);
        session_error(s, ss, &req->id, LC_ERR_INTERNAL, "",
                      lc_journal_broken(s->journal)
                          ? "the change could not be stored, and the journal refuses changes until it recovers "
                            "(the lucentd log says why)"
                          : "the change could not be stored (journal write failed: disk full?); try again");
        return;
    }
    lc_state_release(&before);
    server_clutter_sync(s);
    session_send(ss, lc_proto_build_ok(&req->id, s->state.revision));
    for (lc_session *o = s->sessions; o; o = o->next)
        if (o != ss && o->authed)
            session_send(o, lc_proto_build_changed(s->state.revision, ss->client, req->ops, req->n_ops));
    if (lc_journal_bytes(s->journal) > (uint64_t)s->cfg->compact_bytes &&
        lc_journal_compact(s->journal, &s->state, jerr, sizeof jerr) != 0)
        lc_error("server", "journal compaction failed: %s (will retry)", jerr);
}

void server_request(lc_server *s, lc_session *ss, const char *text, size_t len) {
    s->messages_in++;
    lc_proto_request req;
    lc_proto_error e;
    if (lc_proto_parse_request(text, len, &s->limits, &req, &e) != 0) {
        server_count_error(s, e.code);
        session_send(ss, lc_proto_build_error(&req.id, &e));
        if (!ss->authed) session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "hello required");
        return;
    }
    if (!ss->authed) {
        if (req.type != LC_REQ_HELLO) {
            session_error(s, ss, &req.id, LC_ERR_HELLO_REQUIRED, "/type", "the first message must be hello");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "hello required");
            goto done;
        }
        const lc_config *c = s->cfg;
        server_auth_peer *ap = c->controller_tokens[0] ? server_auth_peer_for(s, ss->peer) : NULL;
        if (ap && ap->tokens < 1) {
            /* Refused before the token is looked at, so guessing from this address is useless. */
            session_error(s, ss, &req.id, LC_ERR_RATE_LIMITED, "/token",
                          "too many failed hellos from this address; wait and retry");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "rate limited");
            goto done;
        }
        if (!c->controller_tokens[0]) ss->controller = 1; /* no tokens configured: local, open server */
        else if (lc_config_has_token(c->controller_tokens, req.token)) ss->controller = 1;
        else if (lc_config_has_token(c->viewer_tokens, req.token)) ss->controller = 0;
        else {
            ap->tokens -= 1;
            s->auth_failures++;
            session_error(s, ss, &req.id, LC_ERR_UNAUTHORIZED, "/token", "unknown token");
            session_close(ss, LWS_CLOSE_STATUS_POLICY_VIOLATION, "unauthorized");
            lc_info("server", "refused client '%s' from %s: unknown token", req.client, ss->peer);
            goto done;
        }
        ss->authed = 1;
        ss->mr_granted = (req.capabilities & LC_CAP_MR) && ss->controller && server_mr_available(s);
        snprintf(ss->client, sizeof ss->client, "%s", req.client);
        lc_info("server", "client '%s' connected as %s", ss->client, ss->controller ? "controller" : "viewer");
        server_welcome(s, ss, &req.id);
        goto done;
    }
    /* Token bucket: rate per second, burst 2x. */
    double now = lc_clock_ms();
    ss->tokens = fmin(2.0 * s->cfg->rate, ss->tokens + (now - ss->refill_ms) * 1e-3 * s->cfg->rate);
    ss->refill_ms = now;
    if (ss->tokens < 1) {
        session_error(s, ss, &req.id, LC_ERR_RATE_LIMITED, "", "too many requests; slow down");
        goto done;
    }
    ss->tokens -= 1;
    if (lc_proto_is_change(req.type) && !ss->controller) {
        session_error(s, ss, &req.id, LC_ERR_FORBIDDEN, "/type", "viewers cannot change the state");
        goto done;
    }
    switch (req.type) {
    case LC_REQ_HELLO: session_error(s, ss, &req.id, LC_ERR_INVALID, "/type", "hello was already received"); break;
    case LC_REQ_SUBSCRIBE: {
        if (req.stream == LC_STREAM_LIGHTMAP ? !lc_frame_texel_bytes(req.encoding)
                                             : !lc_frame_sh_value_bytes(req.encoding)) {
            session_error(s, ss, &req.id, LC_ERR_INVALID, "/encoding", "this encoding is not available for the stream");
            break;
        }
        session_take_latest(s, ss);
        ss->stream[req.stream].on = 1;
        ss->stream[req.stream].force = 1;
        ss->stream[req.stream].enc = req.encoding;
        ss->stream[req.stream].max_rate = req.max_rate;
        ss->stream[req.stream].residual = req.residual;
        server_update_grid(s);
        session_send(ss, lc_proto_build_ok(&req.id, s->state.revision));
        break;
    }
    case LC_REQ_UNSUBSCRIBE:
        ss->stream[req.stream].on = 0;
        server_update_grid(s);
        session_send(ss, lc_proto_build_ok(&req.id, s->state.revision));
        break;
    case LC_REQ_SNAPSHOT:
        session_take_latest(s, ss);
        for (int k = 1; k < STREAMS; k++)
            if (ss->stream[k].on) ss->stream[k].force = 1;
        session_send(ss, lc_proto_build_ok(&req.id, s->state.revision));
        break;
    case LC_REQ_STATE_GET: {
        lc_proto_state ps;
        lc_proto_material_state *mats = NULL;
        lc_proto_object *objs = NULL;
        if (lc_state_to_proto(&s->state, &ps, &mats) == 0 &&
            (objs = malloc((ps.n_objects ? ps.n_objects : 1) * sizeof *objs))) {
            /* §5.4: each object with its transport, as the clients were told (§5.5) */
            if (ps.n_objects) memcpy(objs, ps.objects, ps.n_objects * sizeof *objs);
            for (uint32_t i = 0; i < ps.n_objects; i++)
                objs[i].transport = 1 +
                    (server_clutter_announced(s, objs[i].id) ? LC_OBJECT_TRANSPORT_CLUTTER
                                                             : LC_OBJECT_TRANSPORT_DYNAMIC);
            ps.objects = objs;
            session_send(ss, lc_proto_build_state(&req.id, &ps));
        } else {
            session_error(s, ss, &req.id, LC_ERR_INTERNAL, "", "out of memory");
        }
        free(objs);
        free(mats);
        break;
    }
    case LC_REQ_PING: {
        struct timespec ts;
        clock_gettime(CLOCK_REALTIME, &ts);
        session_send(
            ss,
            lc_proto_build_pong(&req.id, req.ping_t, (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u));
        break;
    }
    case LC_REQ_MR_BEGIN: server_mr_begin(s, ss, &req); break;
    case LC_REQ_MR_END:
        server_mr_end(s, ss);
        session_send(ss, lc_proto_build_ok(&req.id, s->state.revision));
        break;
    default:
        if (s->cluster) server_cluster_change(s, ss, &req);
        else server_change(s, ss, &req);
        break;
    }
done:
    lc_proto_request_release(&req);
}
