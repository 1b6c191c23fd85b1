/* lucent-mr-bench: one LightSkin frame (engine/mr.h) per stage, CPU and EGL (gpu/mr_gl.h), with
 * the paper's Table 2 beside (Lensing & Broll 2013, AMD 7870, 4k sparse points):
 *   frame:  a synthetic 256x192 RGB-D frame (a room's back wall with a bump), 12 288 lights, 1 024 points
 *   paper:  16k and 64k random VALs x 4k sparse points (lc_mr_set_lights); --big adds 512k x 16k (EGL only)
 *   lucent-mr-bench [--runs N] [--backend cpu|egl|both] [--big] [--json FILE]
 * Times are medians over N runs (default 3) of set_frame/set_lights + compute; the EGL gather
 * includes the lights' upload (once per frame) and the read-back. Exit 0 ok, 1 a failure, 2 usage. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine/mr.h"
#include "gpu/mr_gl.h"

#define MB_MAX_ROWS 16
#define MB_MAX_RUNS 32

typedef struct {
    char name[48], backend[8];
    uint32_t lights, points;
    double filter, lights_ms, gather, occlusion, normalise, sh; /* medians, ms */
} mb_row;

static double mb_rnd(unsigned *s) {
    *s = *s * 1664525u + 1013904223u;
    return (*s >> 8) / 16777216.0;
}

static int mb_cmp(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static double mb_median(double *v, int n) {
    qsort(v, (size_t)n, sizeof *v, mb_cmp);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/* Points on 4 spheres of 10 cm radius in front of the camera (object = sphere). */
static void mb_points(uint32_t n, lc_mr_point *p, uint32_t *obj, float (*centres)[3]) {
    unsigned s = 11;
    for (int o = 0; o < 4; o++) centres[o][0] = -0.6f + 0.4f * (float)o, centres[o][1] = 0, centres[o][2] = -1.5f;
    for (uint32_t i = 0; i < n; i++) {
        float d[3], len = 0;
        for (int k = 0; k < 3; k++) d[k] = (float)(2 * mb_rnd(&s) - 1), len += d[k] * d[k];
        len = sqrtf(len) + 1e-6f;
        obj[i] = i % 4;
        for (int k = 0; k < 3; k++)
            p[i].normal[k] = d[k] / len, p[i].position[k] = centres[obj[i]][k] + 0.1f * d[k] / len;
        p[i].radius = 0.1f * sqrtf(4.0f / (float)(n / 4 + 1));
    }
}

/* n random lights on a 4 m x 3 m wall at z = -3 and the floor, facing the room. */
static lc_mr_light *mb_lights(uint32_t n) {
    lc_mr_light *l = malloc((size_t)n * sizeof *l);
    unsigned s = 5;
    for (uint32_t j = 0; l && j < n; j++) {
        int floor = j % 4 == 0;
        float u = (float)(4 * mb_rnd(&s) - 2), v = (float)(3 * mb_rnd(&s) - 1.5);
        lc_mr_light *q = &l[j];
        memset(q, 0, sizeof *q);
        q->position[0] = u, q->position[1] = floor ? -1.5f : v, q->position[2] = floor ? -1.5f + v * 0.5f : -3.0f;
        q->normal[floor ? 1 : 2] = 1.0f;
        q->area = 12.0f / (float)n;
        for (int k = 0; k < 3; k++) q->radiosity[k] = (float)(5 + 20 * mb_rnd(&s));
    }
    return l;
}

typedef struct {
    int synthetic; /* 1: a depth frame, else random lights */
    uint32_t lights, points;
    const char *name;
} mb_case;

static int mb_run_case(const mb_case *c, lc_mr_gl *gl, int runs, mb_row *row) {
    const uint32_t w = 256, h = 192;
    int rc = 1;
    char err[512] = "";
    lc_mr *m = lc_mr_create(0);
    lc_mr_point *p = malloc((size_t)c->points * sizeof *p);
    uint32_t *obj = malloc((size_t)c->points * sizeof *obj);
    lc_mr_vpl *v = malloc((size_t)c->points * sizeof *v);
    float *depth = malloc((size_t)w * h * sizeof *depth), *rad = malloc((size_t)w * h * 3 * sizeof *rad);
    float centres[4][3], sh[4][27];
    lc_mr_light *lights = c->synthetic ? NULL : mb_lights(c->lights);
    double t[6][MB_MAX_RUNS];
    if (!m || !p || !obj || !v || !depth || !rad || (!c->synthetic && !lights)) goto err;
    mb_points(c->points, p, obj, centres);
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            float dx = ((float)x - w / 2.0f) / w, dy = ((float)y - h / 2.0f) / h;
            size_t i = (size_t)y * w + x;
            depth[i] = 3.0f - 0.5f * expf(-(dx * dx + dy * dy) * 20.0f);
            for (int k = 0; k < 3; k++)
                rad[3 * i + k] = 5.0f + 3.0f * (float)k + 10.0f * (float)((x / 16 + y / 16) % 2);
        }
    lc_mr_camera cam = {
        .width = w, .height = h, .fx = 200, .fy = 200, .cx = w / 2.0f, .cy = h / 2.0f, .rotation = {0, 0, 0, 1}};
    lc_mr_params prm = lc_mr_params_default();
    prm.max_lights = c->synthetic ? c->lights : LC_MR_MAX_LIGHTS;
    lc_mr_set_gl(m, gl);
    for (int r = 0; r < runs; r++) {
        int e = c->synthetic ? lc_mr_set_frame(m, &cam, depth, rad, NULL, &prm, err, sizeof err)
                             : lc_mr_set_lights(m, &cam, lights, c->lights, &prm, err, sizeof err);
        if (!e) e = lc_mr_compute(m, p, c->points, obj, 4, (const float(*)[3])centres, v, NULL, sh, err, sizeof err);
        if (e) {
            fprintf(stderr, "lucent-mr-bench: %s (%s): %s\n", c->name, gl ? "egl" : "cpu", err);
            goto err;
        }
        lc_mr_timings tm;
        lc_mr_stats(m, &tm);
        t[0][r] = tm.filter_ms, t[1][r] = tm.lights_ms, t[2][r] = tm.gather_ms;
        t[3][r] = tm.occlusion_ms, t[4][r] = tm.normalise_ms, t[5][r] = tm.sh_ms;
        row->lights = tm.lights;
    }
    snprintf(row->name, sizeof row->name, "%s", c->name);
    snprintf(row->backend, sizeof row->backend, "%s", gl ? "egl" : "cpu");
    row->points = c->points;
    row->filter = mb_median(t[0], runs), row->lights_ms = mb_median(t[1], runs), row->gather = mb_median(t[2], runs);
    row->occlusion = mb_median(t[3], runs), row->normalise = mb_median(t[4], runs), row->sh = mb_median(t[5], runs);
    rc = 0;
err:
    lc_mr_release(m);
    free(p), free(obj), free(v), free(depth), free(rad), free(lights);
    return rc;
}

static void mb_print(const mb_row *rows, int n, const char *device) {
    printf("LightSkin per stage, ms (median); EGL device: %s\n", device);
    printf("%-22s %-4s %7s %6s %8s %8s %8s %9s %8s %6s\n", "case", "back", "lights", "points", "filter", "lights",
           "gather", "occlusion", "normal.", "sh");
    for (int i = 0; i < n; i++) {
        const mb_row *r = &rows[i];
        printf("%-22s %-4s %7u %6u %8.2f %8.2f %8.2f %9.2f %8.2f %6.2f\n", r->name, r->backend, r->lights, r->points,
               r->filter, r->lights_ms, r->gather, r->occlusion, r->normalise, r->sh);
    }
    printf("%-22s %-4s %7s %6u %8s %8s %8.2f %9.2f %8.2f %6s\n", "paper Table 2", "7870", "-", 4096, "-", "-", 4.02,
           3.98, 0.10, "-");
}

static int mb_json(const char *path, const mb_row *rows, int n, const char *device) {
    FILE *f = fopen(path, "w");
    if (!f) return -1;
    fprintf(f, "{\"egl_device\": \"");
    for (const char *c = device; *c; c++)
        if (*c != '"' && *c != '\\') fputc(*c, f);
    fprintf(f, "\",\n \"paper_table2_4k_sp_ms\": {\"gather\": 4.02, \"occlusion\": 3.98, \"normalisation\": 0.10},\n");
    fprintf(f, " \"rows\": [\n");
    for (int i = 0; i < n; i++) {
        const mb_row *r = &rows[i];
        fprintf(f,
                "  {\"case\": \"%s\", \"backend\": \"%s\", \"lights\": %u, \"points\": %u, \"filter_ms\": %.4f, "
                "\"lights_ms\": %.4f, \"gather_ms\": %.4f, \"occlusion_ms\": %.4f, \"normalise_ms\": %.4f, "
                "\"sh_ms\": %.4f}%s\n",
                r->name, r->backend, r->lights, r->points, r->filter, r->lights_ms, r->gather, r->occlusion,
                r->normalise, r->sh, i + 1 < n ? "," : "");
    }
    fprintf(f, " ]}\n");
    return fclose(f) ? -1 : 0;
}

int main(int argc, char **argv) {
    int runs = 3, big = 0, variant = -1;
    const char *json = NULL, *backend = "both";
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc) runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--backend") && i + 1 < argc) backend = argv[++i];
        else if (!strcmp(argv[i], "--json") && i + 1 < argc) json = argv[++i];
        else if (!strcmp(argv[i], "--variant") && i + 1 < argc) variant = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--big")) big = 1;
        else {
            fprintf(stderr,
                    "usage: lucent-mr-bench [--runs N] [--backend cpu|egl|both] [--variant 0|1] [--big] "
                    "[--json FILE]\n");
            return 2;
        }
    }
    if (runs < 1 || runs > MB_MAX_RUNS) return fprintf(stderr, "lucent-mr-bench: --runs 1..%d\n", MB_MAX_RUNS), 2;
    int cpu = strcmp(backend, "egl") != 0, egl = strcmp(backend, "cpu") != 0;
    char err[512] = "", device[600] = "none";
    lc_mr_gl *gl = NULL;
    if (egl) {
        gl = variant < 0 ? lc_mr_gl_create(err, sizeof err) : lc_mr_gl_create_variant(variant, err, sizeof err);
        if (!gl) fprintf(stderr, "lucent-mr-bench: no EGL: %s\n", err);
        else snprintf(device, sizeof device, "%s", lc_mr_gl_description(gl));
    }
    const mb_case cases[4] = {{1, 12288, 1024, "frame 256x192"},
                              {0, 16384, 4096, "paper 16k x 4k"},
                              {0, 65536, 4096, "paper 64k x 4k"},
                              {0, 524288, 16384, "paper 512k x 16k"}};
    mb_row rows[MB_MAX_ROWS];
    int n = 0, rc = 0;
    for (int c = 0; c < (big ? 4 : 3); c++)
        for (int b = 0; b < 2; b++) {
            if ((b == 0 && (!cpu || c == 3)) || (b == 1 && !gl)) continue;
            if (mb_run_case(&cases[c], b ? gl : NULL, c == 3 ? 1 : runs, &rows[n]) == 0) n++;
            else rc = 1;
        }
    mb_print(rows, n, device);
    if (json && mb_json(json, rows, n, device)) fprintf(stderr, "lucent-mr-bench: cannot write %s\n", json), rc = 1;
    lc_mr_gl_release(gl);
    return rc;
}
