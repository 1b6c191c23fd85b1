/* state: the daemon's dynamic scene state — lights, object instances, material emission,
 * environment, settings — and its revision. Changes are validated against the bake (asset
 * and material names) and the limits, then applied atomically: a batch either applies
 * entirely (one revision) or not at all.
 * Thread: owned by the service (event-loop) thread; the compute thread gets copies
 * (lc_state_clone) handed over under the compute lock. */
#ifndef LC_STATE_H
#define LC_STATE_H
#include <stdint.h>

#include "engine/engine.h"
#include "lcb/lcb.h"
#include "lucent_proto.h"

typedef struct lc_state_limits {
    uint32_t max_lights, max_objects;
} lc_state_limits;

typedef struct lc_state {
    const lc_lcb_view *scene; /* borrowed: asset and material names */
    lc_state_limits limits;
    uint64_t revision;
    lc_proto_light *lights; /* sorted by id */
    uint32_t n_lights;
    lc_proto_object *objects; /* sorted by id */
    uint32_t n_objects;
    float (*emission)[3]; /* per bake material */
    lc_proto_environment environment;
    lc_proto_settings settings; /* every field present */
    /* The relight engine's backend, once lucentd knows it (lc_state_set_backend): which
     * solvers settings.solver may pick. LC_BACKEND_AUTO: the bake's alone. */
    lc_backend_kind backend;
} lc_state;

/* Initial state: no lights or objects (the bake's own lights are added by lc_state_seed),
 * the bake's material emission, no environment, engine default settings (settings.solver:
 * the bake's default, lc_engine_default_solver). */
int lc_state_init(lc_state *s, const lc_lcb *bake, const lc_state_limits *limits);
/* Adds the bake's own lights (KHR_lights_punctual, in META "lights") to a fresh state, as
 * validated as a client's light.set; the revision stays. Returns 0 or -1 with err (a light
 * the limits or the validation refuse). */
int lc_state_seed(lc_state *s, char *err, size_t errlen);
void lc_state_release(lc_state *s);
/* Deep copy (dst uninitialised). Returns 0 or -1 (out of memory). */
int lc_state_clone(lc_state *dst, const lc_state *src);

/* Validates and applies ops atomically. On success increments the revision once and returns
 * 0; on failure returns -1, fills err (the pointer is into the request: "/light/id" for a
 * single change, "/ops/2/light/id" inside a batch) and leaves the state untouched. */
int lc_state_apply(lc_state *s, const lc_proto_op *ops, uint32_t n_ops, int batch, lc_proto_error *err);

/* Replaces the whole state (restore from a snapshot); validates names and limits. A
 * snapshot without settings.solver (older), or with one the bake no longer offers (logged),
 * keeps the bake's default. */
int lc_state_restore(lc_state *s, const lc_proto_parsed_state *p, lc_proto_error *err);

/* Narrows settings.solver to what the engine's backend runs (today both run both solvers).
 * A state whose solver it cannot run falls back to the bake's default if that runs (logged;
 * not a change: the revision stays). */
void lc_state_set_backend(lc_state *s, lc_backend_kind backend);
/* welcome.scene.solvers: bit per LC_PROTO_SOLVER_* that settings.set may pick. */
uint32_t lc_state_solvers(const lc_state *s);

/* Views for messages / the snapshot file (pointers into s; materials array malloc'd into
 * *mats, caller frees). */
int lc_state_to_proto(const lc_state *s, lc_proto_state *out, lc_proto_material_state **mats);

/* Engine input: fills *out with arrays malloc'd into *lights / *objects / *emission
 * (caller frees). */
int lc_state_to_engine(const lc_state *s, lc_engine_state *out, lc_engine_light **lights, lc_engine_object **objects,
                       float **emission);
/* One object of s (its asset validated) in the engine's form. */
void lc_state_object_to_engine(const lc_state *s, const lc_proto_object *p, lc_engine_object *o);

#endif
