/* server_clutter: objects in mode clutter / auto (PROTOCOL.md §4.5, §5.5) on the service
 * thread. After every state change (and on the tick, for auto objects coming to rest) it
 * decides which objects want operators and asks the clutter worker for them; the worker
 * hands finished operators to the compute thread, whose publications say per object whether
 * they applied. Each publication is compared with what clients were told, and the
 * differences go out as object.transport events. */
#include <stdlib.h>
#include <string.h>

#include "server_internal.h"
#include "util/clock.h"
#include "util/log.h"

/* Worker thread: finished operators go to the compute thread. */
static void server_clutter_deliver(void *arg, lc_drt_ops *ops) { lc_compute_clutter_give(arg, ops); }

int server_clutter_start(lc_server *s, char *err, size_t errlen) {
    if (!s->cfg->clutter) return 0;
    lc_drt_settings ds = lc_drt_default_settings();
    s->clw = lc_clw_start(s->v, s->cfg->threads, &ds, server_clutter_deliver, s->compute, err, errlen);
    if (!s->clw) return -1;
    server_clutter_sync(s);
    return 0;
}

void server_clutter_stop(lc_server *s) {
    lc_clw_stop(s->clw);
    s->clw = NULL;
    free(s->clutter);
    free(s->clutter_announced);
    s->clutter = NULL;
    s->clutter_announced = NULL;
    s->n_clutter = s->cap_clutter = s->n_announced = s->cap_announced = 0;
}

static server_clutter_entry *server_clutter_find(lc_server *s, const char *id) {
    for (uint32_t i = 0; i < s->n_clutter; i++)
        if (strcmp(s->clutter[i].id, id) == 0) return &s->clutter[i];
    return NULL;
}

static server_clutter_entry *server_clutter_add(lc_server *s, const lc_engine_object *o, double now) {
    if (s->n_clutter == s->cap_clutter) {
        uint32_t cap = s->cap_clutter ? 2 * s->cap_clutter : 8;
        server_clutter_entry *grown = realloc(s->clutter, cap * sizeof *grown);
        if (!grown) return NULL;
        s->clutter = grown;
        s->cap_clutter = cap;
    }
    server_clutter_entry *c = &s->clutter[s->n_clutter++];
    memset(c, 0, sizeof *c);
    snprintf(c->id, sizeof c->id, "%s", o->id);
    c->placed = *o;
    c->rested_since_ms = now;
    return c;
}

/* 1 when the state holds object_id in mode clutter or auto. */
static int server_clutter_wanted(const lc_server *s, const char *id) {
    for (uint32_t k = 0; k < s->state.n_objects; k++)
        if (strcmp(s->state.objects[k].id, id) == 0) return s->state.objects[k].mode != LC_OBJECT_MODE_DYNAMIC;
    return 0;
}

void server_clutter_sync(lc_server *s) {
    if (!s->clw) return;
    double now = lc_clock_ms(), rest_ms = s->cfg->clutter_rest * 1000.0;
    /* Removed, or back to mode dynamic: first, so their places under the limit are free. */
    uint32_t requested = 0, waiting = 0;
    for (uint32_t i = 0; i < s->n_clutter;) {
        if (server_clutter_wanted(s, s->clutter[i].id)) {
            requested += s->clutter[i].requested;
            i++;
            continue;
        }
        if (s->clutter[i].requested) lc_clw_cancel(s->clw, s->clutter[i].id);
        s->clutter[i] = s->clutter[--s->n_clutter];
    }
    for (uint32_t k = 0; k < s->state.n_objects; k++) {
        const lc_proto_object *p = &s->state.objects[k];
        if (p->mode == LC_OBJECT_MODE_DYNAMIC) continue;
        lc_engine_object o;
        lc_state_object_to_engine(&s->state, p, &o);
        server_clutter_entry *c = server_clutter_find(s, p->id);
        if (!c && !(c = server_clutter_add(s, &o, now))) {
            lc_error("clutter", "out of memory tracking '%s'; it stays dynamic", p->id);
            continue;
        }
        if (!lc_drt_same_placement(&c->placed, &o) || c->placed.visible != o.visible) {
            if (c->requested) lc_clw_cancel(s->clw, c->id), requested--;
            c->requested = 0;
            c->placed = o;
            c->rested_since_ms = now; /* it moved: auto starts resting again */
        }
        if (!o.visible || c->requested) continue;
        int due = p->mode == LC_OBJECT_MODE_CLUTTER || now - c->rested_since_ms >= rest_ms;
        if (!due || requested >= (uint32_t)s->cfg->clutter_max_objects) {
            waiting++; /* the tick looks again: at rest, or once a place under the limit is free */
            if (due && !c->over_limit)
                lc_warn("clutter", "'%s' stays dynamic while %d objects hold operators (--clutter-max-objects)", c->id,
                        s->cfg->clutter_max_objects);
            c->over_limit = due;
            continue;
        }
        c->over_limit = 0;
        if (lc_clw_request(s->clw, &o) == 0) c->requested = 1, requested++;
    }
    s->clutter_waiting = waiting;
}

void server_clutter_tick(lc_server *s) {
    if (s->clutter_waiting) server_clutter_sync(s);
}

int server_clutter_announced(const lc_server *s, const char *object_id) {
    for (uint32_t i = 0; i < s->n_announced; i++)
        if (strcmp(s->clutter_announced[i], object_id) == 0) return 1;
    return 0;
}

static void server_clutter_broadcast(lc_server *s, const char *id, int transport, uint64_t revision,
                                     const lc_published_clutter *pc) {
    for (lc_session *o = s->sessions; o; o = o->next)
        if (o->authed)
            session_send(
                o, lc_proto_build_object_transport(id, transport, revision, pc ? pc->build_ms : 0, pc ? pc->bytes : 0));
    s->clutter_events++;
}

void server_clutter_published(lc_server *s, const lc_published *p) {
    /* Operators that stopped applying: dynamic again, unless the object left the state. */
    for (uint32_t i = 0; i < s->n_announced;) {
        const char *id = s->clutter_announced[i];
        int present = 0, on = 0;
        for (uint32_t k = 0; k < p->n_objects && !present; k++)
            if (strcmp(p->object_ids[k], id) == 0) present = 1, on = p->object_clutter[k].on;
        if (on) {
            i++;
            continue;
        }
        if (present) server_clutter_broadcast(s, id, LC_OBJECT_TRANSPORT_DYNAMIC, p->revision, NULL);
        memmove(s->clutter_announced[i], s->clutter_announced[--s->n_announced], sizeof s->clutter_announced[i]);
    }
    for (uint32_t k = 0; k < p->n_objects; k++) {
        if (!p->object_clutter[k].on || server_clutter_announced(s, p->object_ids[k])) continue;
        if (s->n_announced == s->cap_announced) {
            uint32_t cap = s->cap_announced ? 2 * s->cap_announced : 8;
            char(*grown)[LC_PROTO_ID_MAX + 1] = realloc(s->clutter_announced, cap * sizeof *grown);
            if (!grown) {
                lc_error("clutter", "out of memory: object.transport for '%s' not sent", p->object_ids[k]);
                continue;
            }
            s->clutter_announced = grown;
            s->cap_announced = cap;
        }
        memcpy(s->clutter_announced[s->n_announced++], p->object_ids[k], sizeof s->clutter_announced[0]);
        server_clutter_broadcast(s, p->object_ids[k], LC_OBJECT_TRANSPORT_CLUTTER, p->revision, &p->object_clutter[k]);
    }
}
