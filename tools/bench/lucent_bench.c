/* lucent-bench: relight-engine benchmark. For each bake file given, and each backend
 * available, times a relight after one light change (median of --runs), per stage, and
 * prints a table beside the PIC paper's figures plus a JSON document.
 *   lucent-bench [--runs N] [--backend cpu|egl|both] [--json FILE] BAKE.lcb...
 * Exit codes: 0 ok, 1 a bake or engine failed, 2 usage. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#include "engine/engine.h"
#include "lcb/lcb.h"
#include "util/log.h"

static const char *stage_names[LC_STAGE_COUNT] = {"direct", "bounce",  "pull",   "gather", "lightmap",
                                                  "grid",   "objects", "chroma", "dnrt"};

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

typedef struct {
    char file[512], backend[16];
    uint32_t surfels, caches, links, bands, nodes;
    double stage_ms[LC_STAGE_COUNT], total_ms, peak_mib;
    double gather_links; /* links evaluated per relight (all passes) */
    double gather_bytes, gather_flops, pull_bytes;
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

static int bench_one(const char *path, lc_backend_kind kind, int runs, int bounces, bench_row *row) {
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
    lc_engine_settings settings = lc_engine_default_settings(bake);
    settings.bounces = (uint32_t)bounces;
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
    row->surfels = v->n_surfels;
    row->caches = v->n_caches;
    row->links = v->links_per_cache;
    row->bands = settings.bands;
    row->nodes = v->n_nodes;
    /* Work model of the gather (runtime projection): per used link 12 B link + 12 B node flux
     * read; ~20 flops decode + bands^2 * (basis ~3 + weight 1 + 3 FMAs = 10). Earlier
     * feedback passes gather only the caches surfels read. */
    {
        double all = 0, feedback = 0;
        unsigned char *fb = calloc(v->n_caches ? v->n_caches : 1, 1);
        for (uint32_t s = 0; fb && s < v->n_surfels; s++)
            if (v->surfels[s].cache != LC_NONE) fb[v->surfels[s].cache] = 1;
        for (uint32_t c = 0; c < v->n_caches; c++) {
            all += v->caches[c].link_count;
            if (fb && fb[c]) feedback += v->caches[c].link_count;
        }
        free(fb);
        double nc = (double)settings.bands * settings.bands;
        row->gather_links = all + bounces * feedback;
        row->gather_bytes = row->gather_links * 24.0 + (double)v->n_caches * nc * 12.0 * (bounces + 1);
        row->gather_flops = row->gather_links * (20.0 + 10.0 * nc);
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

int main(int argc, char **argv) {
    int runs = 15, bounces = 1;
    const char *json = NULL, *backend = "both";
    const char *files[64];
    int nfiles = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc) runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--bounces") && i + 1 < argc) bounces = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--json") && i + 1 < argc) json = argv[++i];
        else if (!strcmp(argv[i], "--backend") && i + 1 < argc) backend = argv[++i];
        else if (!strcmp(argv[i], "--help")) {
            printf("usage: lucent-bench [--runs N] [--bounces N] [--backend cpu|egl|both] [--json FILE] BAKE.lcb...\n");
            return 0;
        } else if (argv[i][0] == '-') {
            fprintf(stderr, "lucent-bench: unknown option %s (see --help)\n", argv[i]);
            return 2;
        } else if (nfiles < 64) files[nfiles++] = argv[i];
    }
    if (nfiles == 0 || runs < 1 || runs > 10000 || bounces < 0 || bounces > 16 ||
        (strcmp(backend, "cpu") && strcmp(backend, "egl") && strcmp(backend, "both"))) {
        fprintf(stderr, "lucent-bench: need BAKE files; --runs 1..10000, --bounces 0..16, --backend cpu|egl|both\n");
        return 2;
    }
    lc_log_set_level(LC_LOG_WARN);
    bench_row rows[128];
    int nrows = 0, failed = 0;
    for (int f = 0; f < nfiles; f++) {
        lc_backend_kind kinds[2] = {LC_BACKEND_CPU, LC_BACKEND_EGL};
        for (int k = 0; k < 2; k++) {
            if (k == 0 && !strcmp(backend, "egl")) continue;
            if (k == 1 && !strcmp(backend, "cpu")) continue;
            int rc = bench_one(files[f], kinds[k], runs, bounces, &rows[nrows]);
            if (rc == 0) nrows++;
            else if (!(rc == 3 && !strcmp(backend, "both"))) failed = 1; /* an absent EGL is not a failure in "both" */
        }
    }
    printf("\nrelight after one light change, median of %d runs, %d feedback bounce(s), ms\n", runs, bounces);
    printf("%-28s %-4s %7s %7s %5s", "bake", "bk", "surfels", "caches", "links");
    for (int s = 0; s < LC_STAGE_COUNT; s++) printf(" %8s", stage_names[s]);
    printf(" %8s %8s\n", "total", "peakMiB");
    for (int i = 0; i < nrows; i++) {
        const char *base = strrchr(rows[i].file, '/');
        printf("%-28.28s %-4s %7u %7u %5u", base ? base + 1 : rows[i].file, rows[i].backend, rows[i].surfels,
               rows[i].caches, rows[i].links);
        for (int s = 0; s < LC_STAGE_COUNT; s++) printf(" %8.2f", rows[i].stage_ms[s]);
        printf(" %8.2f %8.0f\n", rows[i].total_ms, rows[i].peak_mib);
    }
    double bw = bench_copy_bandwidth();
    printf("\nwhere the time goes (this machine: memcpy %.1f GB/s read+write):\n", bw);
    printf("%-28s %-4s %12s %10s %10s %10s %10s\n", "bake", "bk", "links/relight", "gather MB", "GB/s", "GFLOP/s",
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
    if (json) {
        FILE *out = fopen(json, "w");
        if (!out) {
            fprintf(stderr, "lucent-bench: cannot write %s\n", json);
            return 1;
        }
        fprintf(out, "{\"runs\": %d, \"bounces\": %d, \"memcpy_gbps\": %.2f, \"results\": [", runs, bounces, bw);
        for (int i = 0; i < nrows; i++) {
            fprintf(out,
                    "%s\n  {\"bake\": \"%s\", \"backend\": \"%s\", \"surfels\": %u, \"caches\": %u, \"links\": %u, "
                    "\"bands\": %u, \"stages_ms\": {",
                    i ? "," : "", rows[i].file, rows[i].backend, rows[i].surfels, rows[i].caches, rows[i].links,
                    rows[i].bands);
            for (int s = 0; s < LC_STAGE_COUNT; s++)
                fprintf(out, "%s\"%s\": %.4f", s ? ", " : "", stage_names[s], rows[i].stage_ms[s]);
            fprintf(out,
                    "}, \"total_ms\": %.4f, \"peak_rss_mib\": %.1f, \"gather_links\": %.0f, "
                    "\"gather_bytes\": %.0f, \"gather_flops\": %.0f, \"pull_bytes\": %.0f}",
                    rows[i].total_ms, rows[i].peak_mib, rows[i].gather_links, rows[i].gather_bytes,
                    rows[i].gather_flops, rows[i].pull_bytes);
        }
        fprintf(out, "\n]}\n");
        fclose(out);
    }
    return failed;
}
