/* lucent-bench: relight-engine benchmark. For each bake file given, and each backend
 * available, times a relight after one light change (median of --runs), per stage, and
 * prints a table beside the PIC paper's figures plus a JSON document.
 *   lucent-bench [--runs N] [--backend cpu|egl|both] [--grid all|needed] [--json FILE] BAKE.lcb...
 * Exit codes: 0 ok, 1 a bake or engine failed, 2 usage. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#include "engine/drt.h"
#include "engine/engine.h"
#include "lcb/lcb.h"
#include "util/log.h"

static const char *stage_names[LC_STAGE_COUNT] = {"direct", "bounce",  "pull",   "gather", "lightmap",
                                                  "grid",   "objects", "chroma", "dnrt",   "drt"};

/* --grid: settings.grid_cells of every relight (all: the whole SH grid, as lucentd computes
 * while a client takes the shgrid stream; needed: the cells objects and surfels read). */
static uint32_t bench_grid_cells = LC_GRID_ALL;

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

typedef struct {
    char file[512], backend[16], solver[8];
    uint32_t surfels, caches, links, bands, nodes;
    double stage_ms[LC_STAGE_COUNT], total_ms, peak_mib;
    double gather_links; /* links (or texel list entries) evaluated per relight (all passes) */
    double gather_bytes, gather_flops, pull_bytes;
    float *lightmap; /* W*H*3 of the last run (owned; the same state on every backend) */
    size_t lm_floats;
    float *radiosity, *cache_sh; /* the last run's surfel B and cache SH (owned), for --check */
    size_t n_radiosity, n_cache_sh;
    double vs_cpu; /* sum|E - E_cpu| / sum E_cpu over the lightmap, the CPU row of the same
                         bake and solver; -1 where there is none (CPU rows, no CPU run) */
} bench_row;

/* Memory bandwidth of this machine for a large copy (GB/s, read + write counted), the
 * yardstick for the per-stage byte counts. */
static double bench_copy_bandwidth(void) {
    size_t n = (size_t)256 << 20;
    char *a = malloc(n), *b = malloc(n);
    if (!a || !b) {
        free(a);
        free(b);
        return 0;
    }
    memset(a, 1, n);
    memset(b, 2, n);
    double best = 0;
    for (int r = 0; r < 3; r++) {
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        memcpy(b, a, n);
        clock_gettime(CLOCK_MONOTONIC, &t1);
        double s = (double)(t1.tv_sec - t0.tv_sec) + (t1.tv_nsec - t0.tv_nsec) * 1e-9;
        if (s > 0 && 2.0 * n / s / 1e9 > best) best = 2.0 * n / s / 1e9;
    }
    free(a);
    free(b);
    return best;
}

/* A light that moves a little every run, so direct light and the transport really rerun. */
static void bench_state(const lc_lcb_view *v, int run, lc_engine_light *light, lc_engine_state *st,
                        const lc_engine_settings *settings) {
    memset(light, 0, sizeof *light);
    float mid[3], ext[3];
    const float *bmin = v->grid_origin;
    for (int k = 0; k < 3; k++) {
        ext[k] = v->grid_cell * (float)(v->grid_dims[k] - 1);
        mid[k] = bmin[k] + 0.5f * ext[k];
    }
    light->type = LC_ENGINE_LIGHT_POINT;
    light->color[0] = light->color[1] = light->color[2] = 1;
    light->intensity = 50.0f * ext[1] * ext[1];
    light->position[0] = mid[0] + 0.05f * ext[0] * (float)((run % 7) - 3);
    light->position[1] = mid[1] + 0.25f * ext[1];
    light->position[2] = mid[2];
    memset(st, 0, sizeof *st);
    st->lights = light;
    st->n_lights = 1;
    st->settings = *settings;
    st->revision = (uint64_t)run + 1;
}

/* One bake, backend and solver: 0, 1 (failed), 3 (no such backend here), 4 (the solver does
 * not run on this bake or backend: skipped). */
/* A copy of the frame's lightmap (NULL when out of memory) and vs_cpu = -1 until compared. */
static void bench_keep_lightmap(const lc_engine_frame *fr, float **lm, size_t *n, double *vs_cpu) {
    *n = (size_t)fr->lightmap_width * fr->lightmap_height * 3;
    *lm = malloc(*n * sizeof **lm);
    if (*lm) memcpy(*lm, fr->lightmap, *n * sizeof **lm);
    *vs_cpu = -1;
}

static int bench_one(const char *path, lc_backend_kind kind, uint32_t solver, int runs, int bounces, bench_row *row) {
    char err[512];
    lc_lcb *bake = NULL;
    lc_engine *e = NULL;
    int rc = 1;
    double *samples = calloc((size_t)runs * (LC_STAGE_COUNT + 1), sizeof *samples);
    if (!samples) return 1;
    if (lc_lcb_open(path, &bake, err, sizeof err) != 0) {
        fprintf(stderr, "lucent-bench: %s: %s\n", path, err);
        goto done;
    }
    e = lc_engine_create(bake, kind, 0, err, sizeof err);
    if (!e) {
        fprintf(stderr, "lucent-bench: %s: %s backend: %s\n", path, kind == LC_BACKEND_EGL ? "egl" : "cpu", err);
        rc = 3;
        goto done;
    }
    const lc_lcb_view *v = lc_lcb_get(bake);
    if (lc_engine_check_solver(v, lc_engine_backend(e), solver, err, sizeof err) != 0) {
        rc = 4;
        goto done;
    }
    lc_engine_settings settings = lc_engine_default_settings(bake);
    settings.bounces = (uint32_t)bounces;
    settings.solver = solver;
    settings.grid_cells = bench_grid_cells;
    lc_engine_light light;
    lc_engine_state st;
    const lc_engine_frame *fr;
    /* Warm-up relight: first-time work (sky, allocations) is not what an update costs. */
    bench_state(v, 0, &light, &st, &settings);
    if (lc_engine_relight(e, &st, &fr, err, sizeof err) != 0) {
        fprintf(stderr, "lucent-bench: %s: %s\n", path, err);
        goto done;
    }
    for (int r = 0; r < runs; r++) {
        bench_state(v, r + 1, &light, &st, &settings);
        if (lc_engine_relight(e, &st, &fr, err, sizeof err) != 0) {
            fprintf(stderr, "lucent-bench: %s: %s\n", path, err);
            goto done;
        }
        for (int s = 0; s < LC_STAGE_COUNT; s++) samples[(size_t)s * runs + r] = fr->stage_ms[s];
        samples[(size_t)LC_STAGE_COUNT * runs + r] = fr->total_ms;
        fprintf(stderr, "\r%s %s: run %d/%d", path, lc_engine_backend_name(e), r + 1, runs);
    }
    fprintf(stderr, "\n");
    memset(row, 0, sizeof *row);
    snprintf(row->file, sizeof row->file, "%s", path);
    snprintf(row->backend, sizeof row->backend, "%s", lc_engine_backend_name(e));
    snprintf(row->solver, sizeof row->solver, "%s", solver == LC_SOLVER_PROBES ? "probes" : "pic");
    row->surfels = v->n_surfels;
    row->caches = v->n_caches;
    row->links = v->links_per_cache;
    row->bands = settings.bands;
    row->nodes = v->n_nodes;
    bench_keep_lightmap(fr, &row->lightmap, &row->lm_floats, &row->vs_cpu);
    row->n_radiosity = (size_t)v->n_surfels * 3;
    row->n_cache_sh = (size_t)fr->n_caches * fr->sh_stride * 3;
    row->radiosity = malloc(row->n_radiosity * sizeof(float));
    row->cache_sh = malloc(row->n_cache_sh * sizeof(float));
    if (row->radiosity && fr->surfel_radiosity)
        memcpy(row->radiosity, fr->surfel_radiosity, row->n_radiosity * sizeof(float));
    if (row->cache_sh && fr->cache_sh) memcpy(row->cache_sh, fr->cache_sh, row->n_cache_sh * sizeof(float));
    /* Work model of the gather (runtime projection): per used link 12 B link + 12 B node flux
     * read; ~20 flops decode + bands^2 * (basis ~3 + weight 1 + 3 FMAs = 10). A texel cache
     * gathered per surfel (TSGF/TSGW) reads its list instead: per entry 8 B + 12 B radiosity,
     * 6 flops. Earlier feedback passes gather only the caches surfels read. */
    {
        const int lists = solver == LC_SOLVER_PIC && v->texel_surfels_first != NULL;
        const double nc = (double)settings.bands * settings.bands;
        double reads = 0, bytes = 0, flops = 0;
        unsigned char *fb = calloc(v->n_caches ? v->n_caches : 1, 1);
        for (uint32_t s = 0; fb && s < v->n_surfels; s++)
            if (v->surfels[s].cache != LC_NONE) fb[v->surfels[s].cache] = 1;
        for (uint32_t c = 0; c < v->n_caches; c++) {
            const int list = lists && c < v->n_texel_caches;
            const double k = list ? v->texel_surfels_first[c + 1] - v->texel_surfels_first[c] : v->caches[c].link_count;
            const double passes = 1.0 + (fb && fb[c] ? bounces : 0);
            reads += k * passes;
            bytes += k * passes * (list ? 20.0 : 24.0);
            flops += k * passes * (list ? 6.0 : 20.0 + 10.0 * nc);
        }
        free(fb);
        row->gather_links = reads;
        row->gather_bytes = bytes + (double)v->n_caches * nc * 12.0 * (bounces + 1);
        row->gather_flops = flops;
        row->pull_bytes = (double)v->n_nodes * 36.0 * (bounces + 1);
    }
    for (int s = 0; s <= LC_STAGE_COUNT; s++) {
        double *x = samples + (size_t)s * runs;
        qsort(x, (size_t)runs, sizeof *x, cmp_double);
        double med = x[runs / 2];
        if (s < LC_STAGE_COUNT) row->stage_ms[s] = med;
        else row->total_ms = med;
    }
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    row->peak_mib = ru.ru_maxrss / 1024.0;
    rc = 0;
done:
    lc_engine_release(e);
    lc_lcb_close(bake);
    free(samples);
    return rc;
}

/* sum |a - b| / sum |b| (-1 when either is missing). */
static double bench_rel_diff(const float *a, const float *b, size_t n) {
    if (!a || !b) return -1;
    double num = 0, den = 0;
    for (size_t k = 0; k < n; k++) {
        num += fabs((double)a[k] - b[k]);
        den += fabs((double)b[k]);
    }
    return den > 0 ? num / den : (num > 0 ? 1 : 0);
}

/* Each EGL row's lightmap against the CPU row of the same bake and solver: on a new driver the
 * timings mean nothing unless the light is the same. */
static void bench_compare_backends(bench_row *rows, int n) {
    for (int i = 0; i < n; i++) {
        if (strcmp(rows[i].backend, "egl") || !rows[i].lightmap) continue;
        for (int j = 0; j < n; j++) {
            if (strcmp(rows[j].backend, "cpu") || strcmp(rows[j].file, rows[i].file) ||
                strcmp(rows[j].solver, rows[i].solver) || !rows[j].lightmap || rows[j].lm_floats != rows[i].lm_floats)
                continue;
            rows[i].vs_cpu = bench_rel_diff(rows[i].lightmap, rows[j].lightmap, rows[i].lm_floats);
            if (rows[i].vs_cpu > 1e-3)
                fprintf(stderr,
                        "lucent-bench: %s %s: EGL differs from CPU: lightmap %.3g, surfel B %.3g, cache SH %.3g\n",
                        rows[i].file, rows[i].solver, rows[i].vs_cpu,
                        bench_rel_diff(rows[i].radiosity, rows[j].radiosity, rows[i].n_radiosity),
                        bench_rel_diff(rows[i].cache_sh, rows[j].cache_sh, rows[i].n_cache_sh));
        }
    }
}

/* --- DNRT: what placed objects cost (engine/dnrt.h) ---------------------------------------- */

typedef struct {
    char file[512], backend[16];
    int objects, blockers;
    double size_m;
    double light_ms;   /* DNRT stage of a relight after a light change (objects resting) */
    double move_ms;    /* ... after one object moved (its receivers found again) */
    double relight_ms; /* whole relight after a light change with the objects */
    double receivers;  /* per object */
    double grid_kib;   /* transfer grid of the asset */
    float *lightmap;   /* the last relight's (owned), for the EGL rows' vs_cpu */
    size_t lm_floats;
    double vs_cpu; /* as bench_row's; -1 where there is none */
} bench_dnrt_row;

/* n objects of the first asset with a transfer grid, scaled to size_m (largest extent), on
 * upward-facing texel caches spread through the cache list. 0 placed, -1 none possible. */
static int bench_place_objects(const lc_lcb_view *v, int n, double size_m, lc_engine_object *objs) {
    if (!v->n_transfers) return -1;
    const lc_lcb_transfer *t = &v->transfers[0];
    const lc_lcb_asset *a = &v->assets[t->asset];
    float ext = 0;
    for (int k = 0; k < 3; k++) ext = fmaxf(ext, a->bounds_max[k] - a->bounds_min[k]);
    uint32_t up = 0;
    for (uint32_t c = 0; c < v->n_texel_caches; c++) up += v->caches[c].normal[1] > 0.9f;
    if (up < (uint32_t)n || !(ext > 0)) return -1;
    uint32_t stride = up / (uint32_t)n, seen = 0;
    int placed = 0;
    for (uint32_t c = 0; c < v->n_texel_caches && placed < n; c++) {
        if (!(v->caches[c].normal[1] > 0.9f) || seen++ % stride != stride / 2) continue;
        lc_engine_object *o = &objs[placed];
        memset(o, 0, sizeof *o);
        snprintf(o->id, sizeof o->id, "bench%d", placed);
        o->asset = t->asset;
        memcpy(o->translation, v->caches[c].position, sizeof o->translation);
        o->translation[1] -= a->bounds_min[1] * (float)(size_m / ext);
        o->rotation[3] = 1;
        o->scale[0] = o->scale[1] = o->scale[2] = (float)(size_m / ext);
        o->visible = 1;
        placed++;
    }
    return placed == n ? 0 : -1;
}

static int bench_dnrt(const char *path, lc_backend_kind kind, int runs, int n_objects, double size_m, int blockers,
                      bench_dnrt_row *row) {
    char err[512];
    lc_lcb *bake = NULL;
    lc_engine *e = NULL;
    lc_engine_object objs[64];
    double *ms = calloc((size_t)runs * 3, sizeof *ms);
    int rc = 1;
    if (!ms || lc_lcb_open(path, &bake, err, sizeof err) != 0 ||
        !(e = lc_engine_create(bake, kind, 0, err, sizeof err)))
        goto done;
    const lc_lcb_view *v = lc_lcb_get(bake);
    if (!(size_m > 0)) { /* auto: 1 m, or a quarter of a small room (the 0.55 m Cornell box: 0.15 m) */
        float ex = v->grid_cell * (float)(v->grid_dims[0] - 1), ez = v->grid_cell * (float)(v->grid_dims[2] - 1);
        size_m = fmin(1.0, 0.27 * fmin(ex, ez));
    }
    if (bench_place_objects(v, n_objects, size_m, objs) != 0) {
        rc = 4; /* no asset with a transfer grid, or no floor */
        goto done;
    }
    lc_engine_settings settings = lc_engine_default_settings(bake);
    settings.dnrt_blockers = blockers;
    settings.grid_cells = bench_grid_cells;
    lc_engine_light light;
    lc_engine_state st;
    const lc_engine_frame *fr;
    memset(row, 0, sizeof *row);
    for (int r = 0; r <= runs; r++) { /* run 0 warms up */
        bench_state(v, r, &light, &st, &settings);
        st.objects = objs;
        st.n_objects = (uint32_t)n_objects;
        if (lc_engine_relight(e, &st, &fr, err, sizeof err) != 0) goto done;
        if (r) ms[r - 1] = fr->stage_ms[LC_STAGE_DNRT], ms[runs + r - 1] = fr->total_ms;
        row->receivers = (double)fr->dnrt_receivers / n_objects;
        objs[0].translation[0] += (r & 1) ? 0.01f : -0.01f; /* the next relight: one object moved */
        if (lc_engine_relight(e, &st, &fr, err, sizeof err) != 0) goto done;
        if (r) ms[2 * runs + r - 1] = fr->stage_ms[LC_STAGE_DNRT];
        fprintf(stderr, "\r%s %s: %d objects, run %d/%d", path, lc_engine_backend_name(e), n_objects, r, runs);
    }
    fprintf(stderr, "\n");
    for (int k = 0; k < 3; k++) qsort(ms + (size_t)k * runs, (size_t)runs, sizeof *ms, cmp_double);
    snprintf(row->file, sizeof row->file, "%s", path);
    snprintf(row->backend, sizeof row->backend, "%s", lc_engine_backend_name(e));
    row->objects = n_objects;
    row->blockers = blockers;
    row->size_m = size_m;
    row->light_ms = ms[runs / 2];
    row->relight_ms = ms[runs + runs / 2];
    row->move_ms = ms[2 * runs + runs / 2];
    row->grid_kib = (double)lc_lcb_transfer_bytes(&v->transfers[0]) / 1024.0;
    bench_keep_lightmap(fr, &row->lightmap, &row->lm_floats, &row->vs_cpu);
    rc = 0;
done:
    if (rc == 1) fprintf(stderr, "lucent-bench: %s: %s\n", path, err);
    lc_engine_release(e);
    lc_lcb_close(bake);
    free(ms);
    return rc;
}

static void bench_dnrt_print(const bench_dnrt_row *rows, int n) {
    if (!n) return;
    printf("\nDNRT: placed objects in the indirect light (objects resting: a light change; move: one object moved), "
           "median ms\n");
    printf("%-28s %-4s %7s %6s %8s %9s %10s %10s %9s %10s %8s %8s\n", "bake", "bk", "objects", "size", "blockers",
           "recv/obj", "light", "per obj", "move", "relight", "grid KiB", "vs cpu");
    for (int i = 0; i < n; i++) {
        const char *base = strrchr(rows[i].file, '/');
        printf("%-28.28s %-4s %7d %5.2fm %8s %9.0f %10.3f %10.4f %9.3f %10.2f %8.0f", base ? base + 1 : rows[i].file,
               rows[i].backend, rows[i].objects, rows[i].size_m, rows[i].blockers ? "rays" : "off", rows[i].receivers,
               rows[i].light_ms, rows[i].light_ms / rows[i].objects, rows[i].move_ms, rows[i].relight_ms,
               rows[i].grid_kib);
        if (rows[i].vs_cpu >= 0) printf(" %8.1e\n", rows[i].vs_cpu);
        else printf(" %8s\n", "-");
    }
    printf("paper (DNRT, 32^3 x 4 SH, screen space, per object): GTX 970 0.077 ms (1 object), 0.800 ms (10); "
           "HD 4600 2.708 / 29.712 ms\n"
           "targets here (CPU backend): <= 0.2 ms per object per relight, 10 objects <= 2 ms\n");
}

/* --backend cpu|egl|both: whether backend k (0 cpu, 1 egl) is measured. */
static int bench_backend_wanted(const char *backend, int k) { return strcmp(backend, k ? "cpu" : "egl") != 0; }

/* --- DRT: what clutter objects cost (engine/drt.h) ------------------------------------------ */

typedef struct {
    char file[512];
    const char *backend; /* "cpu" or "egl" */
    int objects;
    double size_m;
    double build_ms, build_max_ms; /* per object: mean and the slowest */
    double mib;                    /* operators' memory per object */
    double receivers;              /* per object */
    double light_ms;               /* DRT stage of a relight after a light change (median) */
    double relight_ms;             /* whole relight after a light change with the clutter */
    float *lightmap;               /* the last relight's (owned), for the EGL rows' vs_cpu */
    size_t lm_floats;
    double vs_cpu; /* as bench_row's; -1 where there is none */
} bench_drt_row;

/* n clutter objects (placed like the DNRT rows), their operators built one by one, then the
 * relight after a light change timed with them applied on `backend`. 0: a row; 4: no room to
 * place them; 5: the EGL device refuses that many (its buffer limit); 1: a failure. */
static int bench_drt(const char *path, lc_backend_kind backend, int runs, int n_objects, double size_m,
                     bench_drt_row *row) {
    char err[512];
    lc_lcb *bake = NULL;
    lc_engine *e = NULL;
    lc_drt_builder *b = NULL;
    lc_engine_object objs[64];
    double *ms = calloc((size_t)runs * 2, sizeof *ms);
    int rc = 1;
    if (!ms || lc_lcb_open(path, &bake, err, sizeof err) != 0 ||
        !(e = lc_engine_create(bake, backend, 0, err, sizeof err)))
        goto done;
    const char *bk = backend == LC_BACKEND_EGL ? "egl" : "cpu";
    const lc_lcb_view *v = lc_lcb_get(bake);
    if (!(size_m > 0)) {
        float ex = v->grid_cell * (float)(v->grid_dims[0] - 1), ez = v->grid_cell * (float)(v->grid_dims[2] - 1);
        size_m = fmin(1.0, 0.27 * fmin(ex, ez));
    }
    if (bench_place_objects(v, n_objects, size_m, objs) != 0) {
        rc = 4;
        goto done;
    }
    if (!(b = lc_drt_builder_create(v, 0, err, sizeof err))) goto done;
    memset(row, 0, sizeof *row);
    lc_drt_settings ds = lc_drt_default_settings();
    for (int i = 0; i < n_objects; i++) {
        lc_drt_ops *ops = NULL;
        if (lc_drt_build(b, &objs[i], &ds, NULL, &ops, err, sizeof err) != 0) goto done;
        lc_drt_info in = lc_drt_ops_info(ops);
        row->build_ms += in.build_ms / n_objects;
        row->build_max_ms = fmax(row->build_max_ms, in.build_ms);
        row->mib += in.bytes / 1048576.0 / n_objects;
        row->receivers += (double)in.receivers / n_objects;
        if (lc_engine_clutter_attach(e, ops, err, sizeof err) != 0) goto done;
        fprintf(stderr, "\r%s: clutter %d/%d built", path, i + 1, n_objects);
    }
    lc_engine_settings settings = lc_engine_default_settings(bake);
    settings.grid_cells = bench_grid_cells;
    lc_engine_light light;
    lc_engine_state st;
    const lc_engine_frame *fr;
    for (int r = 0; r <= runs; r++) { /* run 0 warms up */
        bench_state(v, r, &light, &st, &settings);
        st.objects = objs;
        st.n_objects = (uint32_t)n_objects;
        if (lc_engine_relight(e, &st, &fr, err, sizeof err) != 0) {
            /* drt_gl.c's refusal ("... binding limit": llvmpipe binds 128 MiB) is a property of
             * the device, reported, not a failure of the benchmark */
            if (backend == LC_BACKEND_EGL && strstr(err, "binding limit")) {
                fprintf(stderr, "\nlucent-bench: %s: %d clutter objects not run on this EGL device: %s\n", path,
                        n_objects, err);
                rc = 5;
            }
            goto done;
        }
        if (fr->drt_objects != (uint32_t)n_objects) {
            snprintf(err, sizeof err, "%u of %d clutter objects applied", fr->drt_objects, n_objects);
            goto done;
        }
        if (r) ms[r - 1] = fr->stage_ms[LC_STAGE_DRT], ms[runs + r - 1] = fr->total_ms;
        fprintf(stderr, "\r%s %s: %d clutter objects, run %d/%d", path, bk, n_objects, r, runs);
    }
    fprintf(stderr, "\n");
    for (int k = 0; k < 2; k++) qsort(ms + (size_t)k * runs, (size_t)runs, sizeof *ms, cmp_double);
    snprintf(row->file, sizeof row->file, "%s", path);
    row->backend = bk;
    row->objects = n_objects;
    row->size_m = size_m;
    row->light_ms = ms[runs / 2];
    row->relight_ms = ms[runs + runs / 2];
    bench_keep_lightmap(fr, &row->lightmap, &row->lm_floats, &row->vs_cpu);
    rc = 0;
done:
    if (rc == 1) fprintf(stderr, "\nlucent-bench: %s: %s\n", path, err);
    lc_drt_builder_release(b);
    lc_engine_release(e);
    lc_lcb_close(bake);
    free(ms);
    return rc;
}

static void bench_drt_print(const bench_drt_row *rows, int n) {
    if (!n) return;
    printf("\nDRT: clutter objects (operators built once per placement, applied at every relight)\n");
    printf("%-28s %-4s %7s %6s %9s %9s %8s %9s %10s %10s %10s %8s\n", "bake", "bk", "objects", "size", "build ms",
           "max ms", "MiB/obj", "recv/obj", "light", "per obj", "relight", "vs cpu");
    for (int i = 0; i < n; i++) {
        const char *base = strrchr(rows[i].file, '/');
        printf("%-28.28s %-4s %7d %5.2fm %9.0f %9.0f %8.1f %9.0f %10.3f %10.4f %10.2f", base ? base + 1 : rows[i].file,
               rows[i].backend, rows[i].objects, rows[i].size_m, rows[i].build_ms, rows[i].build_max_ms, rows[i].mib,
               rows[i].receivers, rows[i].light_ms, rows[i].light_ms / rows[i].objects, rows[i].relight_ms);
        if (rows[i].vs_cpu >= 0) printf(" %8.1e\n", rows[i].vs_cpu);
        else printf(" %8s\n", "-");
    }
    printf("paper (DRT, 12 cores, GTX 580): about 5 s to build per object, a few ms per update; "
           "target here: <= 5 s per 1 m object on 2 cores\n");
}

/* The DNRT and DRT rows' EGL lightmaps against the CPU row with the same objects (the same
 * sequence of states ran on both, so their last frames are comparable). */
static void bench_compare_object_rows(bench_dnrt_row *d, int nd, bench_drt_row *c, int nc) {
    for (int i = 0; i < nd; i++)
        for (int j = 0; j < nd && !strcmp(d[i].backend, "egl"); j++)
            if (!strcmp(d[j].backend, "cpu") && !strcmp(d[j].file, d[i].file) && d[j].objects == d[i].objects &&
                d[j].blockers == d[i].blockers && d[j].lm_floats == d[i].lm_floats)
                d[i].vs_cpu = bench_rel_diff(d[i].lightmap, d[j].lightmap, d[i].lm_floats);
    for (int i = 0; i < nc; i++)
        for (int j = 0; j < nc && !strcmp(c[i].backend, "egl"); j++)
            if (!strcmp(c[j].backend, "cpu") && !strcmp(c[j].file, c[i].file) && c[j].objects == c[i].objects &&
                c[j].lm_floats == c[i].lm_floats)
                c[i].vs_cpu = bench_rel_diff(c[i].lightmap, c[j].lightmap, c[i].lm_floats);
}

/* x as a JSON number, or null when negative (no comparison was made). */
static const char *bench_json_number(double x, char *buf, size_t len) {
    if (x < 0) return "null";
    snprintf(buf, len, "%.3e", x);
    return buf;
}

/* The JSON document of every row (--json). -1 when it cannot be written. */
static int bench_write_json(const char *json, int runs, int bounces, double bw, const bench_row *rows, int nrows,
                            const bench_dnrt_row *drows, int ndrows, const bench_drt_row *crows, int ncrows) {
    FILE *out = fopen(json, "w");
    if (!out) {
        fprintf(stderr, "lucent-bench: cannot write %s\n", json);
        return -1;
    }
    fprintf(out, "{\"runs\": %d, \"bounces\": %d, \"grid_cells\": \"%s\", \"memcpy_gbps\": %.2f, \"results\": [", runs,
            bounces, bench_grid_cells == LC_GRID_ALL ? "all" : "needed", bw);
    for (int i = 0; i < nrows; i++) {
        fprintf(out,
                "%s\n  {\"bake\": \"%s\", \"backend\": \"%s\", \"solver\": \"%s\", \"surfels\": %u, "
                "\"caches\": %u, \"links\": %u, \"bands\": %u, \"stages_ms\": {",
                i ? "," : "", rows[i].file, rows[i].backend, rows[i].solver, rows[i].surfels, rows[i].caches,
                rows[i].links, rows[i].bands);
        for (int s = 0; s < LC_STAGE_COUNT; s++)
            fprintf(out, "%s\"%s\": %.4f", s ? ", " : "", stage_names[s], rows[i].stage_ms[s]);
        fprintf(out,
                "}, \"total_ms\": %.4f, \"peak_rss_mib\": %.1f, \"gather_links\": %.0f, "
                "\"gather_bytes\": %.0f, \"gather_flops\": %.0f, \"pull_bytes\": %.0f",
                rows[i].total_ms, rows[i].peak_mib, rows[i].gather_links, rows[i].gather_bytes, rows[i].gather_flops,
                rows[i].pull_bytes);
        if (rows[i].vs_cpu >= 0) fprintf(out, ", \"lightmap_vs_cpu\": %.3e", rows[i].vs_cpu);
        fprintf(out, "}");
    }
    char num[32];
    fprintf(out, "\n], \"dnrt\": [");
    for (int i = 0; i < ndrows; i++)
        fprintf(out,
                "%s\n  {\"bake\": \"%s\", \"backend\": \"%s\", \"objects\": %d, \"object_size_m\": %.3f, "
                "\"blockers\": %s, \"receivers_per_object\": %.0f, \"light_change_ms\": %.4f, "
                "\"per_object_ms\": %.5f, \"move_ms\": %.4f, \"relight_ms\": %.4f, \"grid_kib\": %.1f, "
                "\"lightmap_vs_cpu\": %s}",
                i ? "," : "", drows[i].file, drows[i].backend, drows[i].objects, drows[i].size_m,
                drows[i].blockers ? "true" : "false", drows[i].receivers, drows[i].light_ms,
                drows[i].light_ms / drows[i].objects, drows[i].move_ms, drows[i].relight_ms, drows[i].grid_kib,
                bench_json_number(drows[i].vs_cpu, num, sizeof num));
    fprintf(out, "\n], \"drt\": [");
    for (int i = 0; i < ncrows; i++)
        fprintf(out,
                "%s\n  {\"bake\": \"%s\", \"backend\": \"%s\", \"objects\": %d, \"object_size_m\": %.3f, "
                "\"build_ms\": %.1f, \"build_max_ms\": %.1f, \"mib_per_object\": %.2f, "
                "\"receivers_per_object\": %.0f, \"light_change_ms\": %.4f, \"per_object_ms\": %.5f, "
                "\"relight_ms\": %.4f, \"lightmap_vs_cpu\": %s}",
                i ? "," : "", crows[i].file, crows[i].backend, crows[i].objects, crows[i].size_m, crows[i].build_ms,
                crows[i].build_max_ms, crows[i].mib, crows[i].receivers, crows[i].light_ms,
                crows[i].light_ms / crows[i].objects, crows[i].relight_ms,
                bench_json_number(crows[i].vs_cpu, num, sizeof num));
    fprintf(out, "\n]}\n");
    fclose(out);
    return 0;
}

int main(int argc, char **argv) {
    int runs = 15, bounces = 1, dnrt = 1;
    double object_size = 0; /* auto */
    const char *json = NULL, *backend = "both";
    const char *files[64];
    int nfiles = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc) runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--bounces") && i + 1 < argc) bounces = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--json") && i + 1 < argc) json = argv[++i];
        else if (!strcmp(argv[i], "--backend") && i + 1 < argc) backend = argv[++i];
        else if (!strcmp(argv[i], "--object-size") && i + 1 < argc) object_size = atof(argv[++i]);
        else if (!strcmp(argv[i], "--no-dnrt")) dnrt = 0;
        else if (!strcmp(argv[i], "--grid") && i + 1 < argc) {
            const char *g = argv[++i];
            if (strcmp(g, "all") && strcmp(g, "needed")) {
                fprintf(stderr, "lucent-bench: --grid '%s' is not all or needed\n", g);
                return 2;
            }
            bench_grid_cells = strcmp(g, "all") ? LC_GRID_NEEDED : LC_GRID_ALL;
        } else if (!strcmp(argv[i], "--help")) {
            printf("usage: lucent-bench [--runs N] [--bounces N] [--backend cpu|egl|both] [--json FILE]\n"
                   "                    [--object-size METRES] [--no-dnrt] [--grid all|needed] BAKE.lcb...\n"
                   "  --grid needed: relights compute only the SH grid cells objects and surfels read, as lucentd\n"
                   "  does while no client takes the shgrid stream (default all: the whole grid)\n"
                   "  bakes with an asset transfer grid also get the DNRT rows: 1 and 10 objects of --object-size\n"
                   "  (default: 1 m, or 0.27 x the room's smaller horizontal extent when that is less) on the\n"
                   "  floor, with and without blocker rays; and the DRT rows: the same objects as clutter,\n"
                   "  their operators' build time and memory and their cost per relight (--no-dnrt: neither)\n");
            return 0;
        } else if (argv[i][0] == '-') {
            fprintf(stderr, "lucent-bench: unknown option %s (see --help)\n", argv[i]);
            return 2;
        } else if (nfiles < 64) files[nfiles++] = argv[i];
    }
    if (nfiles == 0 || runs < 1 || runs > 10000 || bounces < 0 || bounces > 16 || !(object_size >= 0) ||
        (strcmp(backend, "cpu") && strcmp(backend, "egl") && strcmp(backend, "both"))) {
        fprintf(stderr, "lucent-bench: need BAKE files; --runs 1..10000, --bounces 0..16, --backend cpu|egl|both\n");
        return 2;
    }
    lc_log_set_level(LC_LOG_WARN);
    bench_row rows[128];
    int nrows = 0, failed = 0;
    for (int f = 0; f < nfiles; f++) {
        lc_backend_kind kinds[2] = {LC_BACKEND_CPU, LC_BACKEND_EGL};
        for (int k = 0; k < 2; k++)
            for (uint32_t sv = 0; sv < LC_SOLVER_COUNT && bench_backend_wanted(backend, k) && nrows < 127; sv++) {
                int rc = bench_one(files[f], kinds[k], sv, runs, bounces, &rows[nrows]);
                if (rc == 0) nrows++;
                else if (rc == 3 && !strcmp(backend, "both")) break; /* an absent EGL is not a failure in "both" */
                else if (rc != 4) failed = 1;
            }
    }
    bench_dnrt_row drows[128];
    int ndrows = 0;
    for (int f = 0; f < nfiles && dnrt; f++) {
        static const int counts[2] = {1, 10};
        for (int k = 0; k < 2; k++) {
            if (!bench_backend_wanted(backend, k)) continue;
            for (int c = 0; c < 2; c++)
                for (int b = 1; b >= 0; b--) {
                    int rc = bench_dnrt(files[f], k ? LC_BACKEND_EGL : LC_BACKEND_CPU, runs, counts[c], object_size, b,
                                        &drows[ndrows]);
                    if (rc == 0 && ndrows < 127) ndrows++;
                    else if (rc == 1) failed = 1;
                }
        }
    }
    bench_drt_row crows[16];
    int ncrows = 0;
    for (int f = 0; f < nfiles && dnrt; f++) {
        static const int counts[2] = {1, 10};
        for (int k = 0; k < 2; k++) {
            if (!bench_backend_wanted(backend, k)) continue;
            for (int c = 0; c < 2 && ncrows < 16; c++) {
                int rc = bench_drt(files[f], k ? LC_BACKEND_EGL : LC_BACKEND_CPU, runs, counts[c], object_size,
                                   &crows[ncrows]);
                if (rc == 0) ncrows++;
                else if (rc == 1) failed = 1;
            }
        }
    }
    bench_compare_backends(rows, nrows);
    bench_compare_object_rows(drows, ndrows, crows, ncrows);
    printf("\nrelight after one light change, median of %d runs, %d feedback bounce(s), %s, ms\n", runs, bounces,
           bench_grid_cells == LC_GRID_ALL ? "the whole SH grid" : "only the grid cells objects and surfels read");
    printf("%-28s %-4s %-6s %7s %7s %5s", "bake", "bk", "solver", "surfels", "caches", "links");
    for (int s = 0; s < LC_STAGE_COUNT; s++) printf(" %8s", stage_names[s]);
    printf(" %8s %8s %8s\n", "total", "peakMiB", "vs cpu");
    for (int i = 0; i < nrows; i++) {
        const char *base = strrchr(rows[i].file, '/');
        printf("%-28.28s %-4s %-6s %7u %7u %5u", base ? base + 1 : rows[i].file, rows[i].backend, rows[i].solver,
               rows[i].surfels, rows[i].caches, rows[i].links);
        for (int s = 0; s < LC_STAGE_COUNT; s++) printf(" %8.2f", rows[i].stage_ms[s]);
        printf(" %8.2f %8.0f", rows[i].total_ms, rows[i].peak_mib);
        if (rows[i].vs_cpu >= 0) printf(" %7.1e\n", rows[i].vs_cpu);
        else printf(" %8s\n", "-");
    }
    bench_dnrt_print(drows, ndrows);
    bench_drt_print(crows, ncrows);
    double bw = bench_copy_bandwidth();
    printf("\nwhere the time goes (this machine: memcpy %.1f GB/s read+write):\n", bw);
    printf("%-28s %-4s %12s %10s %10s %10s %10s\n", "bake", "bk", "reads/relight", "gather MB", "GB/s", "GFLOP/s",
           "pull GB/s");
    for (int i = 0; i < nrows; i++) {
        const char *base = strrchr(rows[i].file, '/');
        double gs = rows[i].stage_ms[LC_STAGE_GATHER] * 1e-3, ps = rows[i].stage_ms[LC_STAGE_PULL] * 1e-3;
        printf("%-28.28s %-4s %12.0f %10.1f %10.2f %10.2f %10.2f\n", base ? base + 1 : rows[i].file, rows[i].backend,
               rows[i].gather_links, rows[i].gather_bytes / 1e6, gs > 0 ? rows[i].gather_bytes / gs / 1e9 : 0,
               gs > 0 ? rows[i].gather_flops / gs / 1e9 : 0, ps > 0 ? rows[i].pull_bytes / ps / 1e9 : 0);
    }
    printf("\npaper (PIC, Sponza, 10585 caches; surfel light + pull + cache light, ms):\n"
           "  moderate (3 bands, 128 links, 32k surfels): CPU i7-4510U 2 cores 33.8, i7-4790S 21.1; GTX 980 3.65\n"
           "  high     (4 bands, 254 links, 128k surfels): CPU i7-4510U 198, i7-4790S 131; GTX 980 7.17\n"
           "targets here (2 cores): sponza moderate <= 15 ms, high <= 60 ms (CPU backend)\n");
    if (json && bench_write_json(json, runs, bounces, bw, rows, nrows, drows, ndrows, crows, ncrows) != 0) failed = 1;
    for (int i = 0; i < nrows; i++) free(rows[i].lightmap), free(rows[i].radiosity), free(rows[i].cache_sh);
    for (int i = 0; i < ndrows; i++) free(drows[i].lightmap);
    for (int i = 0; i < ncrows; i++) free(crows[i].lightmap);
    return failed;
}
