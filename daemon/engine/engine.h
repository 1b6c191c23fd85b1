/* engine: the relight engine. Given a bake (.lcb, mapped by the caller) and the current
 * state (lights, emissive materials, environment, dynamic-object instances, settings), it
 * recomputes surfel radiosity, cache SH, lightmap irradiance, the SH grid and per-object SH.
 *
 * Backends behind one interface: "cpu" (C11, threads) and "egl" (GL 4.3 compute on a
 * headless EGL display). Nothing here knows about sockets; outputs are plain arrays.
 *
 * Threads: an lc_engine is used from one thread at a time (the daemon's compute thread).
 * Ownership: the engine borrows the lc_lcb (it must outlive the engine); frames returned by
 * lc_engine_relight() point into engine memory valid until the next relight or release. */
#ifndef LC_ENGINE_H
#define LC_ENGINE_H
#include <stddef.h>
#include <stdint.h>

#include "lcb/lcb.h"
#include "util/limits.h"

#define LC_ENGINE_ID_MAX 65 /* ids up to 64 bytes, as lucent/1 allows */
#define LC_ENGINE_MAX_LIGHTS LC_LIMIT_LIGHTS
#define LC_ENGINE_MAX_OBJECTS LC_LIMIT_OBJECTS

typedef enum { LC_BACKEND_AUTO = 0, LC_BACKEND_CPU, LC_BACKEND_EGL } lc_backend_kind;

typedef enum {
    LC_ENGINE_LIGHT_POINT = 0,   /* intensity: candela */
    LC_ENGINE_LIGHT_SPOT,        /* candela, cone angles as glTF (half angles, radians) */
    LC_ENGINE_LIGHT_DIRECTIONAL, /* lux */
    LC_ENGINE_LIGHT_AREA,        /* nits (emitted radiance), one-sided toward `direction` */
} lc_engine_light_type;

typedef enum { LC_AREA_QUAD = 0, LC_AREA_DISC = 1 } lc_engine_area_shape;

typedef struct lc_engine_light {
    char id[LC_ENGINE_ID_MAX];
    lc_engine_light_type type;
    float color[3]; /* linear RGB */
    float intensity;
    float range; /* 0 = infinite (glTF range window otherwise) */
    float position[3];
    float direction[3]; /* unit: the way the light travels (spot axis, sun direction, area normal) */
    float inner_cone, outer_cone;
    lc_engine_area_shape shape;
    float size[2];    /* quad: width along `tangent`, height along direction x tangent; disc: radius in [0] */
    float tangent[3]; /* quad orientation, unit, perpendicular to direction */
} lc_engine_light;

typedef struct lc_engine_object {
    char id[LC_ENGINE_ID_MAX];
    uint32_t asset; /* index into the bake's assets */
    float translation[3];
    float rotation[4]; /* unit quaternion x, y, z, w */
    float scale[3];
    int visible;
    int dnrt_off;    /* 1: no effect on the indirect light even if the asset has transfer data (engine/dnrt.h) */
    int clutter_off; /* 1: clutter operators attached for it are dropped (lc_engine_clutter_attach) */
} lc_engine_object;

typedef enum { LC_ENV_NONE = 0, LC_ENV_CONSTANT, LC_ENV_SH } lc_engine_env_kind;

typedef struct lc_engine_environment {
    lc_engine_env_kind kind;
    float color[3];  /* constant sky radiance (nits) */
    float sh[9][3];  /* L2 radiance SH (RGB per coefficient), lucent SH convention */
    float intensity; /* multiplies either */
} lc_engine_environment;

/* The light-transport solver: PIC (the bake's cache -> node links, LINK) or sparse radiance
 * probes (engine/probes.h; the bake's PRB* sections). Both compute the same quantities. */
typedef enum { LC_SOLVER_PIC = 0, LC_SOLVER_PROBES = 1 } lc_engine_solver;
#define LC_SOLVER_COUNT 2

/* Which SH grid cells (the spatial receivers) a relight computes. NEEDED is the sparse
 * radiance probes thesis's §4.1: only the cells something else reads — the 8 corners each
 * object's SH is sampled from, DNRT objects' corners, and the caches surfels read for the
 * next bounce — so the lightmap, the objects' SH and the surfels' feedback are the same as
 * with ALL, bit for bit, while the grid output holds zeros elsewhere (frame.grid_complete 0).
 * Under the probes solver the grid receivers own most of the cluster bases, so this is most
 * of its gather. */
typedef enum { LC_GRID_ALL = 0, LC_GRID_NEEDED = 1 } lc_engine_grid_cells;

typedef struct lc_engine_settings {
    uint32_t bounces;       /* indirect feedback passes per relight, 0..16 (see lc_engine_relight) */
    uint32_t bands;         /* SH bands of the cache / SH-lightmap output, 1..8 (the grid is always L2) */
    int progressive;        /* carry the indirect light of the previous relight (converges across relights) */
    int chroma_compression; /* store caches as YCoCg with fewer bands for Co/Cg */
    uint32_t chroma_bands;  /* bands for Co/Cg when compressing, 1..bands */
    int sh_lightmap;        /* also output the per-texel radiance SH lightmap */
    int dnrt;               /* placed objects shadow and colour the indirect light (engine/dnrt.h) */
    int dnrt_blockers;      /* ... tested for static geometry between object and receiver with rays */
    uint32_t solver;        /* LC_SOLVER_PIC or LC_SOLVER_PROBES (engine/probes.h) */
    uint32_t grid_cells;    /* LC_GRID_ALL (the default) or LC_GRID_NEEDED */
} lc_engine_settings;

typedef struct lc_engine_state {
    const lc_engine_light *lights;
    uint32_t n_lights;
    const lc_engine_object *objects;
    uint32_t n_objects;
    const float *material_emission; /* n_materials x 3 nits, or NULL = the baked emission */
    lc_engine_environment environment;
    lc_engine_settings settings;
    uint64_t revision; /* echoed in the frame */
} lc_engine_state;

/* Stage timings of the last relight (milliseconds; 0 when a stage was skipped). */
typedef enum {
    LC_STAGE_DIRECT = 0,
    LC_STAGE_BOUNCE,
    LC_STAGE_PULL,
    LC_STAGE_GATHER,
    LC_STAGE_LIGHTMAP,
    LC_STAGE_GRID,
    LC_STAGE_OBJECTS,
    LC_STAGE_CHROMA,
    LC_STAGE_DNRT, /* placing objects' receivers, their direct light, and the per-pass sums */
    LC_STAGE_DRT,  /* clutter operators: their patches' direct light and the per-pass deltas */
    LC_STAGE_COUNT
} lc_engine_stage;

typedef struct lc_engine_frame {
    uint64_t revision;
    uint32_t lightmap_width, lightmap_height;
    const float *lightmap;    /* W*H*3: irradiance E (W/m^2, RGB) for the texel normal; empty texels 0 */
    uint32_t sh_bands;        /* bands of cache_sh / lightmap_sh */
    uint32_t sh_stride;       /* coefficients per record in cache_sh / lightmap_sh (>= bands^2; the
                                 first bands^2 are set) */
    const float *lightmap_sh; /* W*H*sh_stride*3 radiance SH (RGB interleaved per coefficient), or NULL */
    uint32_t n_caches;
    const float *cache_sh; /* n_caches*sh_stride*3 incident radiance SH at each cache (texel
                                 caches: bands 0-1 only, zeros above, unless sh_lightmap) */
    uint32_t grid_dims[3];
    float grid_origin[3], grid_cell;
    const float *grid_sh; /* cells*9*3: L2 irradiance SH (cosine-convolved: E(n) = sum c_i y_i(n)) */
    int grid_complete;    /* 1: every cell computed; 0: settings.grid_cells NEEDED, only the cells
                             the objects and surfels read (the rest zero) */
    uint32_t n_objects;
    const float *object_sh;        /* n_objects*9*3: L2 irradiance SH at each object's position */
    const float *surfel_radiosity; /* n_surfels*3: final B (W/m^2) per surfel, for tests/debug */
    const float *node_flux;        /* n_nodes*3: pulled flux (W) of the last pass, for tests/debug */
    uint32_t dnrt_objects;         /* objects with an effect on the indirect light (engine/dnrt.h) */
    uint32_t dnrt_receivers;       /* caches and objects they change */
    uint32_t drt_objects;          /* clutter objects whose operators applied (engine/drt.h) */
    uint32_t drt_receivers;        /* caches their operators change */
    double stage_ms[LC_STAGE_COUNT];
    double total_ms;
    uint32_t stages_run; /* bit per lc_engine_stage that ran (skipped stages: inputs unchanged) */
} lc_engine_frame;

typedef struct lc_engine lc_engine;
typedef struct lc_drt_ops lc_drt_ops;   /* engine/drt.h */
typedef struct lc_drt_info lc_drt_info; /* engine/drt.h */

/* Creates an engine over a validated bake. AUTO picks EGL on a hardware GPU and the CPU
 * backend when EGL only offers a software rasterizer, and logs the choice; if EGL creation
 * fails (no device, shader compile error), AUTO falls back to CPU and says so, while an
 * explicit EGL request fails. threads 0 = all cores. Returns NULL with err set. */
lc_engine *lc_engine_create(const lc_lcb *bake, lc_backend_kind kind, int threads, char *err, size_t errlen);
void lc_engine_release(lc_engine *e);
const char *lc_engine_backend_name(const lc_engine *e);
/* The backend the engine runs on: LC_BACKEND_CPU or LC_BACKEND_EGL. */
lc_backend_kind lc_engine_backend(const lc_engine *e);

/* Validates state (finite numbers, ranges, asset indices; err names the field as a JSON
 * pointer-like path, e.g. "/lights/3/intensity") without relighting. */
int lc_engine_validate_state(const lc_engine *e, const lc_engine_state *state, char *err, size_t errlen);
/* The same checks against a bake alone (no engine): the daemon runs them before it
 * acknowledges a change, on the service thread. */
int lc_engine_check_state(const lc_lcb_view *bake, const lc_engine_state *state, char *err, size_t errlen);
/* Whether settings.solver `solver` runs for this bake on `backend` (probes needs the bake's
 * probe data, PIC its links; both backends run both, so `backend` is there for one that may
 * not). 0, or -1 with err naming /settings/solver. */
int lc_engine_check_solver(const lc_lcb_view *bake, lc_backend_kind backend, uint32_t solver, char *err, size_t errlen);
/* The solver a fresh state uses: PIC when the bake has links (links_per_cache > 0), else probes. */
uint32_t lc_engine_default_solver(const lc_lcb_view *bake);

/* The next relight starts from no carried indirect light, as the first does: its result (and
 * its progressive successors') then depends only on the state, not on what was relit before
 * (lucentd --cluster: every replica gives the same frames for a revision). */
void lc_engine_reset_feedback(lc_engine *e);

/* Relights for `state`. Work whose inputs did not change is skipped (e.g. moving an
 * object redoes direct light but not the sky's per-surfel rays unless the environment is
 * visible through the moved object... in practice: lights/objects/emission -> direct; env
 * or objects -> sky visibility; settings.bands -> gather). Returns 0 and a frame, or -1
 * with err set (invalid state; the engine keeps its previous state). */
int lc_engine_relight(lc_engine *e, const lc_engine_state *state, const lc_engine_frame **frame, char *err,
                      size_t errlen);

/* What lc_engine_relight returns when the interrupt (below) stopped it: no frame, err untouched. */
#define LC_ENGINE_INTERRUPTED 1
/* Asked during a relight whether to stop it (lucentd: a progressive refinement pass that a
 * new update makes moot). It may be called from the relight's worker threads at once, so it
 * must be thread-safe and cheap (an atomic load). When it returns nonzero the relight stops
 * before the feedback of the pass it is in and returns LC_ENGINE_INTERRUPTED: the engine
 * keeps its previous state for change detection, and the carried indirect light is that of
 * the last completed feedback pass (with settings.bounces 0: the previous relight's), so the
 * next relight is what it would have been had the interrupted one not started. The CPU
 * backend asks within the gather (every 64 caches) and between passes; the EGL backend's
 * relight is one submission and never asks. NULL (the default) = never interrupted. */
typedef int (*lc_engine_interrupt_fn)(void *arg);
void lc_engine_set_interrupt(lc_engine *e, lc_engine_interrupt_fn fn, void *arg);

/* Clutter operators (engine/drt.h) built for one object's placement. The engine takes
 * ownership of `ops` (on failure too) and replaces any it holds for the same object id.
 * They apply from the next relight while the state holds that object, visible, with the
 * placement they were built for (the object is then out of DNRT); a relight that finds it
 * moved, hidden, gone or clutter_off releases them, so stale operators never apply. Both
 * backends apply them. -1 with err out of memory. */
int lc_engine_clutter_attach(lc_engine *e, lc_drt_ops *ops, char *err, size_t errlen);
/* Releases the operators held for object_id, if any (the next relight runs without them). */
void lc_engine_clutter_detach(lc_engine *e, const char *object_id);
/* 1 when operators for object_id applied in the last relight. */
int lc_engine_clutter_active(const lc_engine *e, const char *object_id);
/* The same, and then *info (may be NULL) describes those operators. */
int lc_engine_clutter_info(const lc_engine *e, const char *object_id, lc_drt_info *info);

/* Default settings: bounces 1 (two passes) with progressive on, so further bounces
 * accumulate over successive relights; bands = the bake's; no chroma compression; DNRT on,
 * with blocker rays; the bake's default solver (lc_engine_default_solver). */
lc_engine_settings lc_engine_default_settings(const lc_lcb *bake);

#endif
