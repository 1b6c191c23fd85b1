/* EGL/GL compute transport against the CPU reference: the same bake relit by one engine per
 * backend must give the same frame (every output) within 1e-3, on the Cornell box (draft) and
 * on 20 seeded random light/settings states of a small box scene with a dynamic object; AUTO
 * must pick the CPU backend on a software rasterizer; a broken shader must fail to compile
 * with its info log in the error. Skips (77) only when no EGL display exists at all.
 *
 * DNRT (engine/dnrt.h) is on in the random states (blockers random, objects scaled, rotated,
 * some with dnrt_off) and in bands 6..8; on the Cornell box two cubes (one on the floor, one
 * above it) must agree too, and the EGL lightmap under the floor cube must differ from the one
 * with DNRT off by more than the tolerance (so the agreement cannot come from both lacking it).
 * A clutter cube's DRT operators (engine/drt.h), attached to both, must agree the same way,
 * their patches' radiosity included, and change the lightmap by the cube.
 *
 * Agreement metric, per output array (b = CPU, a = EGL):
 *   max_i |a_i - b_i| / max(|b_i|, 1e-3 * max_i |b_i|)  <=  1e-3
 * i.e. relative where values are not tiny next to the array's largest, absolute (1e-6 of the
 * array's range) where they are. SH arrays compare the first bands^2 coefficients of each
 * LC_SH_MAX_COEFFS-strided record (the rest are unspecified). */
#include <math.h>
#include <stdint.h>

#include "check.h"
#include "engine/dnrt.h"
#include "engine/drt.h"
#include "engine_fixture.h"
#include "gpu/egl_context.h"
#include "gpu/gl_util.h"
#include "util/log.h"
#include "util/rng.h"
#include "util/sh.h"

#define TOL 1e-3

/* Worst metric over an array of `records` records of `stride` floats, of which the first
 * `used` are compared. Returns the metric; *where gets the worst index. */
static double compare(const float *a, const float *b, size_t records, size_t stride, size_t used, size_t *where) {
    double maxb = 0, worst = 0;
    *where = 0;
    for (size_t r = 0; r < records; r++)
        for (size_t j = 0; j < used; j++) maxb = fmax(maxb, fabs((double)b[r * stride + j]));
    double floor_ = 1e-3 * maxb;
    if (floor_ == 0) floor_ = 1e-30;
    for (size_t r = 0; r < records; r++)
        for (size_t j = 0; j < used; j++) {
            size_t i = r * stride + j;
            double d = fabs((double)a[i] - (double)b[i]);
            double m = d / fmax(fabs((double)b[i]), floor_);
            if (!(m <= worst)) { /* NaN counts as worst */
                worst = isnan(m) ? INFINITY : m;
                *where = i;
            }
        }
    return worst;
}

/* Compares every output of two frames; returns the worst metric and names the array. */
static double compare_frames(const lc_engine_frame *g, const lc_engine_frame *c, const lc_lcb_view *v,
                             const char *label) {
    size_t w;
    double worst = 0, m;
    const char *worst_name = "-";
    size_t nc = (size_t)c->sh_bands * c->sh_bands;
    size_t texels = (size_t)c->lightmap_width * c->lightmap_height;
    size_t cells = (size_t)c->grid_dims[0] * c->grid_dims[1] * c->grid_dims[2];
#define CMP(name, A, B, rec, stride, used)                                                                           \
    do {                                                                                                             \
        m = compare(A, B, rec, stride, used, &w);                                                                    \
        if (m > TOL)                                                                                                 \
            fprintf(stderr, "  %s: %s off by %.3g at %zu (egl %.9g, cpu %.9g)\n", label, name, m, w, (double)(A)[w], \
                    (double)(B)[w]);                                                                                 \
        if (m > worst) {                                                                                             \
            worst = m;                                                                                               \
            worst_name = name;                                                                                       \
        }                                                                                                            \
    } while (0)
    CHECK(g->sh_bands == c->sh_bands && g->n_caches == c->n_caches && g->lightmap_width == c->lightmap_width &&
              g->n_objects == c->n_objects && memcmp(g->grid_dims, c->grid_dims, sizeof g->grid_dims) == 0,
          "%s: frame shapes differ", label);
    CHECK((g->lightmap_sh == NULL) == (c->lightmap_sh == NULL), "%s: lightmap_sh presence differs", label);
    CHECK((g->node_flux == NULL) == (c->node_flux == NULL), "%s: node_flux presence differs", label);
    CMP("surfel_radiosity", g->surfel_radiosity, c->surfel_radiosity, v->n_surfels, 3, 3);
    if (g->node_flux && c->node_flux) CMP("node_flux", g->node_flux, c->node_flux, v->n_nodes, 3, 3);
    CMP("cache_sh", g->cache_sh, c->cache_sh, c->n_caches, LC_SH_MAX_COEFFS * 3, nc * 3);
    CMP("lightmap", g->lightmap, c->lightmap, texels, 3, 3);
    if (g->lightmap_sh && c->lightmap_sh)
        CMP("lightmap_sh", g->lightmap_sh, c->lightmap_sh, texels, LC_SH_MAX_COEFFS * 3, nc * 3);
    CMP("grid_sh", g->grid_sh, c->grid_sh, cells, 27, 27);
    if (c->n_objects) CMP("object_sh", g->object_sh, c->object_sh, c->n_objects, 27, 27);
#undef CMP
    CHECK(worst <= TOL, "%s: EGL vs CPU worst %.3g in %s (tol %g)", label, worst, worst_name, TOL);
    return worst;
}

static void print_stages(const char *label, const lc_engine_frame *fr) {
    static const char *names[LC_STAGE_COUNT] = {"direct", "bounce",  "pull",   "gather", "lightmap",
                                                "grid",   "objects", "chroma", "dnrt",   "drt"};
    fprintf(stderr, "  %-14s", label);
    for (int i = 0; i < LC_STAGE_COUNT; i++) fprintf(stderr, " %s %.2f", names[i], fr->stage_ms[i]);
    fprintf(stderr, " | total %.2f ms\n", fr->total_ms);
}

/* Relights both engines with st and compares; optionally prints timings and returns the
 * EGL frame (*gpu_frame, when not NULL; NULL if a relight failed). */
static double relight_both_frame(lc_engine *gpu, lc_engine *cpu, const lc_lcb_view *v, const lc_engine_state *st,
                                 const char *label, int timings, const lc_engine_frame **gpu_frame) {
    const lc_engine_frame *fg, *fc;
    char err[512];
    if (gpu_frame) *gpu_frame = NULL;
    int rg = lc_engine_relight(gpu, st, &fg, err, sizeof err);
    CHECK(rg == 0, "%s: egl relight: %s", label, err);
    int rc = lc_engine_relight(cpu, st, &fc, err, sizeof err);
    CHECK(rc == 0, "%s: cpu relight: %s", label, err);
    if (rg || rc) return INFINITY;
    CHECK(fg->dnrt_objects == fc->dnrt_objects && fg->dnrt_receivers == fc->dnrt_receivers,
          "%s: DNRT placements differ (egl %u objects %u receivers, cpu %u/%u)", label, fg->dnrt_objects,
          fg->dnrt_receivers, fc->dnrt_objects, fc->dnrt_receivers);
    CHECK(fg->drt_objects == fc->drt_objects, "%s: clutter objects differ (egl %u, cpu %u)", label, fg->drt_objects,
          fc->drt_objects);
    if (gpu_frame) *gpu_frame = fg;
    if (timings) {
        print_stages("cpu", fc);
        print_stages("egl", fg);
    }
    return compare_frames(fg, fc, v, label);
}

static double relight_both(lc_engine *gpu, lc_engine *cpu, const lc_lcb_view *v, const lc_engine_state *st,
                           const char *label, int timings) {
    return relight_both_frame(gpu, cpu, v, st, label, timings, NULL);
}

/* Reads a whole file (NUL-terminated, caller frees) or NULL. */
static char *slurp(const char *path) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *s = malloc((size_t)n + 1);
    if (s && fread(s, 1, (size_t)n, f) != (size_t)n) {
        free(s);
        s = NULL;
    }
    if (s) s[n] = 0;
    fclose(f);
    return s;
}

/* The lightmap texels whose cache is on the floor (normal up) within `radius` of (x, z) in
 * plan: their indices into idx (cap entries); returns the count. */
static size_t floor_texels(const lc_lcb_view *v, float x, float z, float radius, size_t *idx, size_t cap) {
    size_t n = 0, texels = (size_t)v->lightmap_width * v->lightmap_height;
    for (size_t i = 0; i < texels && n < cap; i++) {
        uint32_t c = v->lightmap[i];
        if (c == LC_NONE) continue;
        const lc_lcb_cache *cc = &v->caches[c];
        float dx = cc->position[0] - x, dz = cc->position[2] - z;
        if (cc->normal[1] > 0.9f && cc->position[1] < 0.01f && dx * dx + dz * dz < radius * radius) idx[n++] = i;
    }
    return n;
}

/* How much `on` differs from `off` (lightmaps) on the floor texels within radius of (x, z):
 * the compare metric over them; *n gets their count. */
static double floor_effect(const lc_lcb_view *v, const float *on, const float *off, float x, float z, float radius,
                           size_t *n) {
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height, w;
    size_t *idx = malloc(texels * sizeof *idx);
    float *a = idx ? calloc(texels * 6, sizeof *a) : NULL;
    double effect = 0;
    *n = 0;
    CHECK(a != NULL, "out of memory");
    if (a) {
        *n = floor_texels(v, x, z, radius, idx, texels);
        for (size_t i = 0; i < *n; i++)
            for (int k = 0; k < 3; k++) {
                a[3 * i + k] = on[3 * idx[i] + k];
                a[3 * (*n + i) + k] = off[3 * idx[i] + k];
            }
        effect = compare(a, a + 3 * *n, *n, 3, 3, &w);
    }
    free(a);
    free(idx);
    return effect;
}

/* Two cubes in the Cornell box, DNRT on (bounces 2: intermediate passes too): one on the
 * floor in the free corner by the short block, scaled 1.5, one above it (an object receiver
 * of the first). EGL must match CPU within TOL (lightmap, cache, grid and object SH), and
 * the EGL lightmap under the floor cube must differ from EGL with DNRT off by more than TOL;
 * then the floor cube moves and both must agree again (the re-placed frame re-uploaded). */
static void test_cornell_dnrt(lc_engine *gpu, const fixture *f, const char *quality) {
    const lc_lcb_view *v = f->v;
    CHECK(v->n_assets == 1 && v->n_transfers == 1, "cornell %s: the cube asset with transfer data (%u assets, %u)",
          quality, v->n_assets, v->n_transfers);
    if (v->n_transfers != 1) return;
    lc_engine_object cubes[2] = {{.id = "floor",
                                  .translation = {0.12f, 0, 0.45f},
                                  .rotation = {0, 0.2588190f, 0, 0.9659258f},
                                  .scale = {1.5f, 1.5f, 1.5f},
                                  .visible = 1},
                                 {.id = "above",
                                  .translation = {0.14f, 0.2f, 0.43f},
                                  .rotation = {0, 0, 0, 1},
                                  .scale = {1, 1, 1},
                                  .visible = 1}};
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f->bake);
    st.settings.bounces = 2;
    st.settings.bands = 3;
    st.settings.progressive = 0;
    st.objects = cubes;
    st.n_objects = 2;
    char label[96], err[512];
    /* Without DNRT first (EGL only): the reference the effect must stand out from. */
    st.settings.dnrt = 0;
    const lc_engine_frame *fr;
    int rc = lc_engine_relight(gpu, &st, &fr, err, sizeof err);
    CHECK(rc == 0, "cornell %s: egl relight without DNRT: %s", quality, err);
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    float *off = malloc(texels * 3 * sizeof *off), *on = malloc(texels * 3 * sizeof *on);
    CHECK(off && on, "out of memory");
    if (rc != 0 || !off || !on) goto done;
    CHECK(fr->dnrt_objects == 0, "cornell %s: DNRT off, yet %u objects", quality, fr->dnrt_objects);
    memcpy(off, fr->lightmap, texels * 3 * sizeof *off);
    st.settings.dnrt = 1;
    snprintf(label, sizeof label, "cornell %s DNRT", quality);
    double m = relight_both_frame(gpu, f->engine, v, &st, label, 1, &fr);
    if (!fr) goto done;
    CHECK(fr->dnrt_objects == 2 && fr->dnrt_receivers > 20, "cornell %s: DNRT has %u objects, %u receivers", quality,
          fr->dnrt_objects, fr->dnrt_receivers);
    memcpy(on, fr->lightmap, texels * 3 * sizeof *on);
    /* Under the floor cube: its footprint and a little around (the outer volume is ~0.26 m). */
    size_t n;
    double effect = floor_effect(v, on, off, 0.12f, 0.45f, 0.15f, &n);
    fprintf(stderr,
            "cornell %s DNRT: %u receivers, EGL/CPU worst %.3g; %zu floor texels under the cube, EGL with/without "
            "DNRT %.3g\n",
            quality, fr->dnrt_receivers, m, n, effect);
    CHECK(n >= 4, "cornell %s: %zu floor texels under the cube", quality, n);
    CHECK(effect > TOL, "cornell %s: DNRT changes the EGL lightmap under the cube by %.3g only (tol %g)", quality,
          effect, TOL);
    /* Again, progressive (nothing re-placed: the dnrt stage is the transport's own). */
    st.settings.progressive = 1;
    snprintf(label, sizeof label, "cornell %s DNRT progressive", quality);
    relight_both(gpu, f->engine, v, &st, label, 1);
    st.settings.progressive = 0;
    /* Moved: re-placed receivers. */
    cubes[0].translation[0] = 0.42f;
    cubes[0].translation[2] = 0.12f;
    snprintf(label, sizeof label, "cornell %s DNRT moved", quality);
    relight_both(gpu, f->engine, v, &st, label, 0);
done:
    free(off);
    free(on);
}

/* A clutter cube (engine/drt.h) on the Cornell floor: operators built once per engine (the
 * builds are deterministic) and attached to both; bounces 2, then progressive, then chroma on.
 * EGL must match CPU within TOL on every output and on the patches' radiosity read back, both
 * must apply the operators (and drop DNRT for the cube), and the EGL lightmap under the cube
 * must differ from EGL without the operators by more than TOL. */
static void test_cornell_drt(lc_engine *gpu, const fixture *f, const char *quality) {
    const lc_lcb_view *v = f->v;
    lc_engine_object cube = {.id = "clutter",
                             .translation = {0.12f, 0, 0.45f},
                             .rotation = {0, 0.2588190f, 0, 0.9659258f},
                             .scale = {1.5f, 1.5f, 1.5f},
                             .visible = 1};
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f->bake);
    st.settings.bounces = 2;
    st.settings.bands = 3;
    st.settings.progressive = 0;
    st.objects = &cube;
    st.n_objects = 1;
    char label[96], err[512];
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    float *dnrt = malloc(texels * 3 * sizeof *dnrt);
    lc_drt_builder *b = lc_drt_builder_create(v, 0, err, sizeof err);
    CHECK(dnrt && b, "drt setup: %s", b ? "out of memory" : err);
    if (!dnrt || !b) goto done;
    const lc_engine_frame *fr;
    int rc = lc_engine_relight(gpu, &st, &fr, err, sizeof err);
    CHECK(rc == 0 && fr->dnrt_objects == 1, "cornell %s: egl relight with the cube in DNRT: %s", quality, err);
    if (rc != 0) goto done;
    memcpy(dnrt, fr->lightmap, texels * 3 * sizeof *dnrt);
    lc_drt_settings ds = lc_drt_default_settings();
    lc_drt_ops *ops[2] = {NULL, NULL};
    for (int i = 0; i < 2; i++) {
        CHECK(lc_drt_build(b, &cube, &ds, NULL, &ops[i], err, sizeof err) == 0 && ops[i], "drt build: %s", err);
        if (!ops[i]) {
            lc_drt_ops_release(ops[0]);
            goto done;
        }
    }
    CHECK(lc_engine_clutter_attach(gpu, ops[0], err, sizeof err) == 0, "egl attach: %s", err);
    CHECK(lc_engine_clutter_attach(f->engine, ops[1], err, sizeof err) == 0, "cpu attach: %s", err);
    snprintf(label, sizeof label, "cornell %s DRT", quality);
    double m = relight_both_frame(gpu, f->engine, v, &st, label, 1, &fr);
    if (!fr) goto done;
    CHECK(fr->drt_objects == 1 && fr->dnrt_objects == 0 && lc_engine_clutter_active(gpu, "clutter") &&
              lc_engine_clutter_active(f->engine, "clutter"),
          "cornell %s: both engines apply the operators (egl drt %u dnrt %u)", quality, fr->drt_objects,
          fr->dnrt_objects);
    size_t n, w;
    double effect = floor_effect(v, fr->lightmap, dnrt, 0.12f, 0.45f, 0.25f, &n);
    fprintf(stderr, "cornell %s DRT: EGL/CPU worst %.3g; %zu floor texels by the cube, EGL DRT against DNRT %.3g\n",
            quality, m, n, effect);
    CHECK(n >= 4 && effect > TOL, "cornell %s: DRT changes the EGL lightmap by the cube by %.3g only (%zu texels)",
          quality, effect, n);
    /* The patches' radiosity each backend left in its operators. */
    uint32_t npg = 0, npc = 0;
    const float *pg = lc_drt_patch_radiosity(ops[0], &npg), *pc = lc_drt_patch_radiosity(ops[1], &npc);
    CHECK(pg && pc && npg == npc && npg > 0, "patches: egl %u, cpu %u", npg, npc);
    if (pg && pc && npg == npc && npg > 0) {
        double pm = compare(pg, pc, npg, 3, 3, &w);
        CHECK(pm <= TOL, "cornell %s: patch radiosity EGL/CPU %.3g at %zu (%g vs %g)", quality, pm, w, (double)pg[w],
              (double)pc[w]);
    }
    st.settings.progressive = 1;
    snprintf(label, sizeof label, "cornell %s DRT progressive", quality);
    relight_both(gpu, f->engine, v, &st, label, 1);
    relight_both(gpu, f->engine, v, &st, label, 0);
    st.settings.progressive = 0;
    st.settings.chroma_compression = 1;
    st.settings.chroma_bands = 1;
    snprintf(label, sizeof label, "cornell %s DRT chroma", quality);
    relight_both(gpu, f->engine, v, &st, label, 0);
    /* Moved: both drop the operators (DNRT again) and agree. */
    cube.translation[0] = 0.42f;
    snprintf(label, sizeof label, "cornell %s DRT moved", quality);
    relight_both_frame(gpu, f->engine, v, &st, label, 0, &fr);
    CHECK(fr && fr->drt_objects == 0 && fr->dnrt_objects == 1, "cornell %s: moved clutter is back in DNRT", quality);
done:
    lc_drt_builder_release(b);
    free(dnrt);
}

/* Bakes scenes/cornell-box with the given quality and compares EGL with CPU (bounces 2,
 * bands 3), printing per-stage times of a few relights. */
/* The probes solver (engine/probes.h) on EGL against the CPU: cache SH, lightmap, grid, objects
 * for 3 and 1 output bands, progressive, with a DNRT object in the box (its intermediate passes
 * gather no corner list: the probes compute every receiver). The bake's rows gather their
 * unseen rays (PRUF/PRUS: the blocks hide points from the probes), so both backends add them. */
static void test_cornell_probes(lc_engine *gpu, const fixture *f, const char *quality) {
    const lc_lcb_probe_header *ph = f->v->probe_header;
    CHECK(f->v->probe_unseen_first && f->v->probe_unseen_first[ph->n_rows] > 0,
          "cornell %s probes: the bake has unseen-ray entries", quality);
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f->bake);
    st.settings.solver = LC_SOLVER_PROBES;
    st.settings.bounces = 2;
    st.settings.progressive = 1;
    lc_engine_object obj = {.asset = 0, .scale = {1.5f, 1.5f, 1.5f}, .rotation = {0, 0, 0, 1}, .visible = 1};
    snprintf(obj.id, sizeof obj.id, "cube");
    obj.translation[0] = 0.3f, obj.translation[2] = 0.3f;
    char label[96];
    double worst = 0;
    for (int i = 0; i < 4; i++) {
        st.settings.bands = i < 2 ? 3 : 1;
        st.objects = i % 2 ? &obj : NULL;
        st.n_objects = i % 2 ? 1 : 0;
        st.revision = (uint64_t)(100 + i);
        snprintf(label, sizeof label, "cornell %s probes, bands %u%s", quality, st.settings.bands,
                 st.n_objects ? ", a DNRT cube" : "");
        const lc_engine_frame *fg;
        worst = fmax(worst, relight_both_frame(gpu, f->engine, f->v, &st, label, i == 0, &fg));
        if (fg && i == 0) {
            double sum = 0;
            for (size_t k = 0; k < (size_t)fg->lightmap_width * fg->lightmap_height * 3; k++) sum += fg->lightmap[k];
            CHECK(sum > 0, "%s: the probes' lightmap is black", label);
        }
    }
    fprintf(stderr, "cornell %s probes: worst EGL/CPU difference %.3g\n", quality, worst);
}

/* settings.grid_cells NEEDED (engine.h) against ALL, per backend and solver: the lightmap, the
 * objects' SH and the surfels' radiosity must be the same bits; the grid only at the cells the
 * objects are sampled from, zero elsewhere, and the frame says it is incomplete. A DNRT cube
 * and a second object out of DNRT (its SH is read from its own corners) are in the box. */
static void test_grid_needed(lc_engine *e, const fixture *f, const char *label) {
    lc_engine_object obj[2] = {{.asset = 0, .scale = {1.5f, 1.5f, 1.5f}, .rotation = {0, 0, 0, 1}, .visible = 1},
                               {.asset = 0, .scale = {1, 1, 1}, .rotation = {0, 0, 0, 1}, .visible = 1, .dnrt_off = 1}};
    snprintf(obj[0].id, sizeof obj[0].id, "a");
    snprintf(obj[1].id, sizeof obj[1].id, "b");
    obj[0].translation[0] = 0.3f, obj[0].translation[2] = 0.3f;
    obj[1].translation[0] = -0.5f, obj[1].translation[1] = 1.2f, obj[1].translation[2] = -0.4f;
    const lc_lcb_view *v = f->v;
    const size_t texels = (size_t)v->lightmap_width * v->lightmap_height,
                 cells = (size_t)v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2];
    float *lm = malloc(texels * 3 * 4), *grid = malloc(cells * 27 * 4), *rad = malloc((size_t)v->n_surfels * 12);
    float objs[54];
    uint8_t *corner = calloc(v->n_caches, 1);
    if (!lm || !grid || !rad || !corner) goto out;
    for (int i = 0; i < 2; i++) { /* sampled at the asset's centre, placed (no rotation here) */
        uint32_t c[8];
        float w[8], p[3];
        for (int k = 0; k < 3; k++)
            p[k] = obj[i].translation[k] +
                obj[i].scale[k] * 0.5f * (v->assets[0].bounds_min[k] + v->assets[0].bounds_max[k]);
        lc_dnrt_grid_corners(v, p, c, w);
        for (int k = 0; k < 8; k++) corner[c[k]] = 1;
    }
    for (uint32_t solver = 0; solver < LC_SOLVER_COUNT; solver++) {
        lc_engine_state st = {.objects = obj, .n_objects = 2};
        st.settings = lc_engine_default_settings(f->bake);
        st.settings.solver = solver;
        st.settings.bounces = 2;
        st.settings.progressive = 0;
        const lc_engine_frame *fr;
        char err[512];
        double ms[2];
        for (uint32_t g = LC_GRID_ALL; g <= LC_GRID_NEEDED; g++) {
            st.settings.grid_cells = g;
            st.revision = 300 + g;
            if (lc_engine_relight(e, &st, &fr, err, sizeof err) != 0) {
                CHECK(0, "%s, solver %u, grid_cells %u: %s", label, solver, g, err);
                goto out;
            }
            ms[g] = fr->stage_ms[LC_STAGE_GATHER];
            CHECK(fr->grid_complete == (g == LC_GRID_ALL), "%s: grid_complete %d with grid_cells %u", label,
                  fr->grid_complete, g);
            if (g == LC_GRID_ALL) {
                memcpy(lm, fr->lightmap, texels * 12);
                memcpy(grid, fr->grid_sh, cells * 108);
                memcpy(rad, fr->surfel_radiosity, (size_t)v->n_surfels * 12);
                memcpy(objs, fr->object_sh, sizeof objs);
                continue;
            }
            CHECK(!memcmp(lm, fr->lightmap, texels * 12), "%s, solver %u: the lightmap changed with NEEDED", label,
                  solver);
            CHECK(!memcmp(rad, fr->surfel_radiosity, (size_t)v->n_surfels * 12),
                  "%s, solver %u: the surfels' radiosity changed with NEEDED", label, solver);
            CHECK(!memcmp(objs, fr->object_sh, sizeof objs), "%s, solver %u: the objects' SH changed with NEEDED",
                  label, solver);
            size_t kept = 0, wrong = 0;
            for (size_t i = 0; i < cells; i++) {
                const float *a = grid + 27 * i, *b = fr->grid_sh + 27 * i;
                int zero = 1;
                for (int k = 0; k < 27; k++) zero &= b[k] == 0;
                if (corner[v->grid[i]]) wrong += memcmp(a, b, 108) != 0;
                kept += !zero;
            }
            CHECK(wrong == 0, "%s, solver %u: %zu cells the objects read differ with NEEDED", label, solver, wrong);
            CHECK(kept >= 8 && kept < cells, "%s, solver %u: %zu of %zu cells computed with NEEDED", label, solver,
                  kept, cells);
            fprintf(stderr, "%s, solver %u: grid NEEDED keeps %zu of %zu cells; gather %.2f -> %.2f ms\n", label,
                    solver, kept, cells, ms[0], ms[1]);
        }
    }
out:
    free(lm);
    free(grid);
    free(rad);
    free(corner);
}

/* Bakes scenes/cornell-box with the cube asset (and its DNRT transfer grid) and FLAGS
 * (NULL-terminated, at most 16). Returns fixture_bake's result; fails the test when it fails. */
static int cornell_fixture(fixture *f, const char *const *flags) {
    char path[512];
    char *obj = slurp(check_source_path("scenes/cornell-box/cornell-box.obj", path, sizeof path));
    char *mtl = slurp(check_source_path("scenes/cornell-box/cornell-box.mtl", path, sizeof path));
    CHECK(obj && mtl, "cornell box sources missing");
    if (!obj || !mtl) {
        free(obj);
        free(mtl);
        return -1;
    }
    /* The fixture writes its own mtllib line: blank out the scene's. */
    for (char *p = strstr(obj, "mtllib"); p && *p && *p != '\n'; p++) *p = ' ';
    char cube_arg[600];
    snprintf(cube_arg, sizeof cube_arg, "cube=%s", check_source_path("scenes/cornell-box/cube.obj", path, sizeof path));
    const char *all[20] = {"--asset", cube_arg};
    int n = 2;
    for (int i = 0; flags[i] && n < 18; i++) all[n++] = flags[i];
    all[n] = NULL;
    int rc = fixture_bake(f, obj, mtl, all);
    free(obj);
    free(mtl);
    CHECK(rc == 0, "cornell bake failed");
    return rc;
}

static void test_cornell(const char *quality, int runs) {
    /* With the probes solver's data too (both solvers on one bake: PIC's data is the same). */
    const char *flags[] = {"--quality",     quality, "--solver",          "both", "--probes", "8",
                           "--probe-bands", "4",     "--probe-svd-error", "0.05", NULL};
    fixture f;
    if (cornell_fixture(&f, flags) != 0) return;
    char err[512];
    lc_engine *gpu = lc_engine_create(f.bake, LC_BACKEND_EGL, 0, err, sizeof err);
    CHECK(gpu != NULL, "egl engine: %s", err);
    if (gpu) {
        fprintf(stderr, "cornell %s: %u surfels, %u nodes, %u caches x %u links, lightmap %ux%u\n", quality,
                f.v->n_surfels, f.v->n_nodes, f.v->n_caches, f.v->links_per_cache, f.v->lightmap_width,
                f.v->lightmap_height);
        lc_engine_state st = {0};
        st.settings = lc_engine_default_settings(f.bake);
        st.settings.bounces = 2;
        st.settings.bands = 3;
        st.settings.progressive = 1; /* relights are never skipped, so they can be timed */
        double worst = 0;
        char label[64];
        for (int i = 0; i < runs; i++) {
            st.revision = (uint64_t)i;
            snprintf(label, sizeof label, "cornell %s relight %d", quality, i);
            worst = fmax(worst, relight_both(gpu, f.engine, f.v, &st, label, 1));
        }
        /* The light must actually light the box, or agreement means little. */
        const lc_engine_frame *fr;
        if (lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0) {
            double sum = 0;
            for (size_t i = 0; i < (size_t)fr->lightmap_width * fr->lightmap_height * 3; i++) sum += fr->lightmap[i];
            CHECK(sum > 0, "cornell %s: the lightmap is black", quality);
        }
        fprintf(stderr, "cornell %s: worst EGL/CPU difference %.3g\n", quality, worst);
        test_cornell_dnrt(gpu, &f, quality);
        test_cornell_drt(gpu, &f, quality);
        test_cornell_probes(gpu, &f, quality);
        snprintf(label, sizeof label, "cornell %s, cpu", quality);
        test_grid_needed(f.engine, &f, label);
        snprintf(label, sizeof label, "cornell %s, egl", quality);
        test_grid_needed(gpu, &f, label);
        lc_engine_release(gpu);
        /* Many windows, as a bake larger than one SSBO binding gets them: the links (laid out
         * link-major per window), the cache SH, DNRT and DRT windows give the same light. */
        lc_gl_test_window_limit = (size_t)256 << 10;
        lc_engine *win = lc_engine_create(f.bake, LC_BACKEND_EGL, 0, err, sizeof err);
        lc_gl_test_window_limit = 0;
        CHECK(win != NULL, "egl engine in small windows: %s", err);
        if (win) {
            double w = 0;
            st.settings.progressive = 0; /* the CPU engine's feedback is from the tests above */
            for (int i = 0; i < 2; i++) {
                st.revision = (uint64_t)(100 + i);
                snprintf(label, sizeof label, "cornell %s in windows, relight %d", quality, i);
                w = fmax(w, relight_both(win, f.engine, f.v, &st, label, 1));
            }
            fprintf(stderr, "cornell %s in 256 KiB windows: worst EGL/CPU difference %.3g\n", quality, w);
            test_cornell_dnrt(win, &f, quality);
            test_cornell_drt(win, &f, quality);
            lc_engine_release(win);
        }
    }
    fixture_release(&f);
}

/* Texel caches gathered per surfel (--texel-gather surfels: TSGF/TSGW, gather.comp's
 * texel_from_surfels) against the CPU: 3 and 1 bands, a DNRT cube, progressive, and in
 * 256 KiB windows. */
/* Texel caches from their surfel lists and grid caches from their own, longer rows of links
 * (GLNK): the same light on both backends. */
static void test_cornell_texel_surfels(void) {
    const char *flags[] = {
        "--quality", "draft", "--texel-gather", "surfels", "--texel-gather-rays", "64", "--grid-links", "160", NULL};
    fixture f;
    if (cornell_fixture(&f, flags) != 0) return;
    CHECK(f.v->texel_surfels_first && f.v->texel_surfels_first[f.v->n_texel_caches] > 0,
          "texel surfels: the bake has list entries");
    uint32_t longest = 0;
    for (uint32_t c = f.v->n_texel_caches; c < f.v->n_caches; c++)
        longest = f.v->caches[c].link_count > longest ? f.v->caches[c].link_count : longest;
    CHECK(f.v->grid_links && f.v->grid_links_per_cache == 160 && longest > f.v->links_per_cache,
          "grid links: GLNK with 160 per grid cache, some grid cache using more than LINK's %u (longest %u)",
          f.v->links_per_cache, longest);
    lc_engine_object obj = {.asset = 0, .scale = {1.5f, 1.5f, 1.5f}, .rotation = {0, 0, 0, 1}, .visible = 1};
    snprintf(obj.id, sizeof obj.id, "cube");
    obj.translation[0] = 0.3f, obj.translation[2] = 0.3f;
    char err[512], label[96];
    for (int windows = 0; windows < 2; windows++) {
        lc_gl_test_window_limit = windows ? (size_t)256 << 10 : 0;
        lc_engine *gpu = lc_engine_create(f.bake, LC_BACKEND_EGL, 0, err, sizeof err);
        lc_gl_test_window_limit = 0;
        CHECK(gpu != NULL, "egl engine: %s", err);
        if (!gpu) break;
        lc_engine_state st = {0};
        st.settings = lc_engine_default_settings(f.bake);
        st.settings.bounces = 2;
        st.settings.progressive = !windows; /* a fresh engine in windows: the CPU's feedback is older */
        double worst = 0;
        for (int i = 0; i < 4; i++) {
            st.settings.bands = i < 2 ? 3 : 1;
            st.objects = i % 2 ? &obj : NULL;
            st.n_objects = i % 2 ? 1 : 0;
            st.revision = (uint64_t)(200 + 10 * windows + i);
            snprintf(label, sizeof label, "texel surfels%s, bands %u%s", windows ? " in windows" : "",
                     st.settings.bands, st.n_objects ? ", a DNRT cube" : "");
            const lc_engine_frame *fg;
            worst = fmax(worst, relight_both_frame(gpu, f.engine, f.v, &st, label, 0, &fg));
            if (fg && i == 0) {
                double sum = 0;
                for (size_t k = 0; k < (size_t)fg->lightmap_width * fg->lightmap_height * 3; k++)
                    sum += fg->lightmap[k];
                CHECK(sum > 0, "%s: the lightmap is black", label);
            }
        }
        fprintf(stderr, "texel surfels%s: worst EGL/CPU difference %.3g\n", windows ? " in windows" : "", worst);
        lc_engine_release(gpu);
    }
    fixture_release(&f);
}

static float frand(lc_rng *r, float lo, float hi) { return lo + (hi - lo) * lc_rng_float(r); }

static void random_unit(lc_rng *r, float d[3]) {
    float n;
    do {
        for (int k = 0; k < 3; k++) d[k] = frand(r, -1, 1);
        n = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    } while (n < 0.1f || n > 1);
    for (int k = 0; k < 3; k++) d[k] /= n;
}

/* 20 seeded random states on a box with an inner block and a dynamic-object asset. */
static void test_fuzz(void) {
    static char obj[1 << 17];
    obj[0] = 0;
    fixture_inward_box(obj, sizeof obj, 1.0f, 3, "wall", 1);
    size_t len = strlen(obj);
    /* A red block on the floor (outward faces) for occlusion and colour bleeding. */
    int base = 6 * 16 + 1;
    const float lo[3] = {0.3f, 0.0f, 0.3f}, hi[3] = {0.6f, 0.4f, 0.55f};
    len += (size_t)snprintf(obj + len, sizeof obj - len, "usemtl block\n");
    for (int i = 0; i < 8; i++)
        len += (size_t)snprintf(obj + len, sizeof obj - len, "v %g %g %g\n", (i & 1) ? hi[0] : lo[0],
                                (i & 2) ? hi[1] : lo[1] + 0.001f, (i & 4) ? hi[2] : lo[2]);
    /* corners: bit0 x, bit1 y, bit2 z; CCW seen from outside */
    static const int quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
    for (int q = 0; q < 6; q++)
        len += (size_t)snprintf(obj + len, sizeof obj - len, "f %d %d %d %d\n", base + quads[q][0], base + quads[q][1],
                                base + quads[q][2], base + quads[q][3]);
    const char *mtl = "newmtl wall\nKd 0.7 0.7 0.7\nnewmtl block\nKd 0.8 0.2 0.1\nKe 0.2 0.05 0\n";
    /* The dynamic-object asset: a small cube. */
    char asset_path[] = "/tmp/lc_egl_asset_XXXXXX.obj";
    int fd = mkstemps(asset_path, 4);
    CHECK(fd >= 0, "asset temp file");
    if (fd < 0) return;
    FILE *af = fdopen(fd, "w");
    fputs("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0.1 0.1 0\nv 0 0 0.1\nv 0.1 0 0.1\nv 0 0.1 0.1\nv 0.1 0.1 0.1\n"
          "f 1 5 7 3\nf 2 4 8 6\nf 1 2 6 5\nf 3 7 8 4\nf 1 3 4 2\nf 5 6 8 7\n",
          af);
    fclose(af);
    char asset_arg[128];
    snprintf(asset_arg, sizeof asset_arg, "cube=%s", asset_path);
    const char *flags[] = {"--quality",      "draft", "--surfels", "2048",    "--links", "64",
                           "--grid-max-dim", "5",     "--asset",   asset_arg, NULL};
    fixture f;
    int rc = fixture_bake(&f, obj, mtl, flags);
    unlink(asset_path);
    if (rc != 0) {
        CHECK(0, "fuzz scene bake failed");
        return;
    }
    char err[512];
    lc_engine *gpu = lc_engine_create(f.bake, LC_BACKEND_EGL, 0, err, sizeof err);
    CHECK(gpu != NULL, "egl engine: %s", err);
    if (!gpu) {
        fixture_release(&f);
        return;
    }
    fprintf(stderr, "fuzz scene: %u surfels, %u caches, %u assets, grid %ux%ux%u\n", f.v->n_surfels, f.v->n_caches,
            f.v->n_assets, f.v->grid_dims[0], f.v->grid_dims[1], f.v->grid_dims[2]);
    CHECK(f.v->n_transfers == 1, "fuzz scene: the cube's transfer grid (%u)", f.v->n_transfers);
    lc_rng rng = lc_rng_seed(20240611u, 7);
    double worst = 0;
    int dnrt_states = 0;
    for (int it = 0; it < 20; it++) {
        lc_engine_light lights[4];
        memset(lights, 0, sizeof lights);
        int nl = 1 + (int)(lc_rng_float(&rng) * 4) % 4;
        for (int i = 0; i < nl; i++) {
            lc_engine_light *l = &lights[i];
            snprintf(l->id, sizeof l->id, "l%d", i);
            l->type = (lc_engine_light_type)((int)(lc_rng_float(&rng) * 4) % 4);
            for (int k = 0; k < 3; k++) {
                l->color[k] = frand(&rng, 0.1f, 1.0f);
                l->position[k] = frand(&rng, 0.15f, 0.85f);
            }
            l->position[1] = frand(&rng, 0.5f, 0.85f); /* above the block */
            l->intensity = frand(&rng, 0.5f, 20.0f);
            random_unit(&rng, l->direction);
            l->outer_cone = frand(&rng, 0.3f, 1.2f);
            l->inner_cone = l->outer_cone * frand(&rng, 0.0f, 0.9f);
            l->shape = lc_rng_float(&rng) < 0.5f ? LC_AREA_QUAD : LC_AREA_DISC;
            l->size[0] = frand(&rng, 0.05f, 0.2f);
            l->size[1] = frand(&rng, 0.05f, 0.2f);
            /* tangent: any unit vector perpendicular to the direction */
            float a[3] = {1, 0, 0};
            if (fabsf(l->direction[0]) > 0.8f) a[0] = 0, a[1] = 1;
            float tn[3] = {l->direction[1] * a[2] - l->direction[2] * a[1],
                           l->direction[2] * a[0] - l->direction[0] * a[2],
                           l->direction[0] * a[1] - l->direction[1] * a[0]};
            float n = sqrtf(tn[0] * tn[0] + tn[1] * tn[1] + tn[2] * tn[2]);
            for (int k = 0; k < 3; k++) l->tangent[k] = tn[k] / n;
        }
        lc_engine_object objs[3];
        memset(objs, 0, sizeof objs);
        int no = (int)(lc_rng_float(&rng) * 4) % 4;
        for (int i = 0; i < no; i++) {
            snprintf(objs[i].id, sizeof objs[i].id, "o%d", i);
            objs[i].asset = 0;
            float sc = frand(&rng, 1.0f, 3.0f); /* outer volumes up to ~0.5 m: caches and each other */
            for (int k = 0; k < 3; k++) {
                objs[i].translation[k] = frand(&rng, -0.1f, 1.0f); /* some outside the grid: clamped */
                objs[i].scale[k] = sc;
            }
            if (lc_rng_float(&rng) < 0.5f) objs[i].translation[1] = frand(&rng, 0.0f, 0.1f); /* near the floor */
            random_unit(&rng, objs[i].rotation);                                             /* axis */
            float ang = frand(&rng, 0.0f, 3.14159265f), sn = sinf(0.5f * ang);
            for (int k = 0; k < 3; k++) objs[i].rotation[k] *= sn;
            objs[i].rotation[3] = cosf(0.5f * ang);
            objs[i].visible = 1;
            objs[i].dnrt_off = lc_rng_float(&rng) < 0.15f;
        }
        lc_engine_state st = {0};
        st.lights = lights;
        st.n_lights = (uint32_t)nl;
        st.objects = objs;
        st.n_objects = f.v->n_assets ? (uint32_t)no : 0;
        st.settings.bounces = (uint32_t)((int)(lc_rng_float(&rng) * 5) % 5);
        st.settings.bands = 1 + (uint32_t)((int)(lc_rng_float(&rng) * 5) % 5);
        st.settings.chroma_compression = lc_rng_float(&rng) < 0.5f;
        st.settings.chroma_bands = 1 + (uint32_t)((int)(lc_rng_float(&rng) * st.settings.bands) % st.settings.bands);
        st.settings.progressive = lc_rng_float(&rng) < 0.5f;
        st.settings.sh_lightmap = lc_rng_float(&rng) < 0.5f;
        st.settings.dnrt = 1;
        st.settings.dnrt_blockers = lc_rng_float(&rng) < 0.5f;
        if (lc_rng_float(&rng) < 0.3f) {
            st.environment.kind = LC_ENV_CONSTANT;
            st.environment.intensity = 1;
            for (int k = 0; k < 3; k++) st.environment.color[k] = frand(&rng, 0.0f, 0.5f);
        }
        st.revision = (uint64_t)it;
        char label[160];
        snprintf(label, sizeof label,
                 "fuzz %d (%d lights, %d objects, bounces %u, bands %u, chroma %d/%u, progressive %d, sh_lightmap %d, "
                 "blockers %d)",
                 it, nl, (int)st.n_objects, st.settings.bounces, st.settings.bands, st.settings.chroma_compression,
                 st.settings.chroma_bands, st.settings.progressive, st.settings.sh_lightmap, st.settings.dnrt_blockers);
        CHECK(lc_engine_validate_state(f.engine, &st, err, sizeof err) == 0, "%s: invalid state: %s", label, err);
        const lc_engine_frame *fg;
        double m = relight_both_frame(gpu, f.engine, f.v, &st, label, 0, &fg);
        uint32_t nr = fg ? fg->dnrt_receivers : 0;
        fprintf(stderr, "%s: DNRT %u objects %u receivers, worst %.3g\n", label, fg ? fg->dnrt_objects : 0, nr, m);
        dnrt_states += nr > 0;
        worst = fmax(worst, m);
    }
    CHECK(dnrt_states >= 8, "fuzz: only %d of 20 states have DNRT receivers", dnrt_states);
    /* Bands above 5 (generic SH recurrence in the shader) once each. */
    for (uint32_t b = 6; b <= LC_SH_MAX_BANDS; b++) {
        lc_engine_light l = {
            .type = LC_ENGINE_LIGHT_POINT, .color = {1, 0.8f, 0.6f}, .intensity = 5, .position = {0.5f, 0.8f, 0.5f}};
        lc_engine_object ob = {.id = "o",
                               .translation = {0.75f, 0, 0.7f},
                               .rotation = {0, 0, 0, 1},
                               .scale = {2.5f, 2.5f, 2.5f},
                               .visible = 1};
        lc_engine_state st = {0};
        st.lights = &l;
        st.n_lights = 1;
        st.objects = &ob; /* DNRT into caches of 6..8 bands */
        st.n_objects = 1;
        st.settings = lc_engine_default_settings(f.bake);
        st.settings.bands = b;
        st.settings.chroma_compression = b == 7;
        st.settings.chroma_bands = 2;
        st.settings.sh_lightmap = 1;
        st.settings.progressive = 0;
        char label[64];
        snprintf(label, sizeof label, "bands %u", b);
        const lc_engine_frame *fg;
        double m = relight_both_frame(gpu, f.engine, f.v, &st, label, 0, &fg);
        CHECK(fg && fg->dnrt_receivers > 0, "%s: the object has DNRT receivers", label);
        fprintf(stderr, "%s: DNRT %u receivers, worst %.3g\n", label, fg ? fg->dnrt_receivers : 0, m);
        worst = fmax(worst, m);
    }
    fprintf(stderr, "fuzz: worst EGL/CPU difference %.3g\n", worst);
    lc_engine_release(gpu);
    fixture_release(&f);
}

/* AUTO on a software rasterizer picks the CPU backend (and the engine logs why). */
static void test_auto(int software) {
    static char obj[1 << 15];
    obj[0] = 0;
    fixture_inward_box(obj, sizeof obj, 1.0f, 2, "wall", 1);
    const char *flags[] = {"--quality", "draft", "--surfels", "512", NULL};
    fixture f;
    if (fixture_bake(&f, obj, "newmtl wall\nKd 0.5 0.5 0.5\nKe 1 1 1\n", flags) != 0) {
        CHECK(0, "auto scene bake failed");
        return;
    }
    char err[512];
    lc_engine *e = lc_engine_create(f.bake, LC_BACKEND_AUTO, 0, err, sizeof err);
    CHECK(e != NULL, "auto engine: %s", err);
    if (e) {
        const char *want = software ? "cpu" : "egl";
        CHECK(strcmp(lc_engine_backend_name(e), want) == 0, "AUTO picked %s, expected %s (software device: %d)",
              lc_engine_backend_name(e), want, software);
        lc_engine_release(e);
    }
    fixture_release(&f);
}

/* A broken shader fails with the compiler's info log in the error; a good one compiles. */
static void test_compile_errors(void) {
    char err[1024] = "";
    lc_egl_context *c = lc_egl_create(err, sizeof err);
    CHECK(c != NULL, "context: %s", err);
    if (!c) return;
    const char *bad = "#version 430 core\nlayout(local_size_x = 1) in;\nvoid main() { undeclared_thing = 1; }\n";
    GLuint p = lc_gl_compile_program("broken.comp", bad, err, sizeof err);
    CHECK(p == 0, "a broken shader compiled");
    CHECK(strstr(err, "broken.comp") && strstr(err, "undeclared_thing"), "error lacks the info log: %s", err);
    fprintf(stderr, "broken shader error: %s\n", err);
    const char *good = "#version 430 core\nlayout(local_size_x = 1) in;\n"
                       "layout(std430, binding = 0) buffer B { float x[]; };\nvoid main() { x[0] = 1.0; }\n";
    p = lc_gl_compile_program("good.comp", good, err, sizeof err);
    CHECK(p != 0, "a good shader failed: %s", err);
    if (p) glDeleteProgram(p);
    CHECK(lc_gl_shader_source("gather") != NULL && lc_gl_shader_source("nope") == NULL, "embedded shader table");
    lc_egl_release(c);
}

int main(void) {
    char err[512] = "";
    /* Probe: no EGL display at all is a skip, not a failure. */
    lc_egl_context *probe = lc_egl_create(err, sizeof err);
    if (!probe) {
        fprintf(stderr, "SKIP: no EGL display: %s\n", err);
        return CHECK_SKIP_RC;
    }
    int software = lc_egl_is_software(probe);
    fprintf(stderr, "EGL: %s%s\n", lc_egl_description(probe), software ? " (software)" : "");
    lc_egl_release(probe);

    test_compile_errors();
    test_auto(software);
    test_cornell("draft", 3);
    test_cornell_texel_surfels();
    test_fuzz();
    if (getenv("LUCENT_EGL_BENCH")) test_cornell("moderate", 3); /* timings for the report */
    CHECK_DONE();
}
