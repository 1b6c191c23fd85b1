/* compare: relative error of an approximation (the engine's lightmap / SH grid) against the
 * reference, the error heat map, and the engine side of a fidelity run. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/image.h"
#include "engine/drt.h"
#include "ref/ref.h"
#include "util/log.h"
#include "util/sh.h"

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* Nearest-rank percentile of sorted x[0..n). */
static double cmp_rank(const double *x, uint32_t n, double q) {
    if (!n) return 0;
    uint32_t k = (uint32_t)ceil(q * n);
    return x[k ? k - 1 : 0];
}

/* Fills the summary from the relative errors (unsorted on entry). */
static void cmp_finish(double *rel, uint32_t n, double sum_signed, double sum_diff, double sum_ref, double noise,
                       lc_ref_errstats *out) {
    double sum = 0;
    for (uint32_t i = 0; i < n; i++) sum += rel[i];
    qsort(rel, n, sizeof *rel, cmp_double);
    out->n = n;
    out->mean = n ? sum / n : 0;
    out->p50 = cmp_rank(rel, n, 0.50);
    out->p95 = cmp_rank(rel, n, 0.95);
    out->max = n ? rel[n - 1] : 0;
    out->mean_signed = n ? sum_signed / n : 0;
    out->bias = sum_ref > 0 ? sum_diff / sum_ref : 0;
    out->ref_noise = n ? noise / n : 0;
}

int lc_ref_compare_lightmap_subset(const float *approx, const float *ref, const float *ref_stderr, const uint8_t *mask,
                                   const uint8_t *select, uint8_t want, uint32_t width, uint32_t height,
                                   double threshold_frac, lc_ref_errstats *out, float *err_image) {
    memset(out, 0, sizeof *out);
    size_t texels = (size_t)width * height;
    double ymax = 0;
    for (size_t i = 0; i < texels; i++) {
        if (err_image) err_image[i] = NAN;
        if (mask && mask[i] != 1) continue;
        ymax = fmax(ymax, lc_ref_luminance(ref + 3 * i));
        if (!select || select[i] == want) out->n_total++;
    }
    out->threshold = threshold_frac * ymax;
    double bright_sum = 0, bright_n = 0, abs_sum = 0;
    for (size_t i = 0; i < texels; i++) {
        double yr = lc_ref_luminance(ref + 3 * i);
        if ((mask && mask[i] != 1) || !(yr > out->threshold) || !(yr > 0)) continue;
        bright_sum += yr, bright_n++;
    }
    out->ref_mean = bright_n ? bright_sum / bright_n : 0;
    double *rel = malloc((texels ? texels : 1) * sizeof *rel);
    if (!rel) return -1;
    uint32_t n = 0;
    double sum_signed = 0, sum_diff = 0, sum_ref = 0, noise = 0;
    for (size_t i = 0; i < texels; i++) {
        if ((mask && mask[i] != 1) || (select && select[i] != want)) continue;
        double yr = lc_ref_luminance(ref + 3 * i), ya = lc_ref_luminance(approx + 3 * i);
        if (out->ref_mean > 0 && isfinite(ya)) abs_sum += fabs(ya - yr) / out->ref_mean;
        if (!(yr > out->threshold) || !(yr > 0)) {
            out->n_dark++;
            out->n_dark_lit += ya > out->threshold;
            continue;
        }
        if (!isfinite(ya)) continue;
        double s = (ya - yr) / yr;
        rel[n++] = fabs(s);
        sum_signed += s;
        sum_diff += ya - yr;
        sum_ref += yr;
        if (ref_stderr) noise += lc_ref_luminance(ref_stderr + 3 * i) / yr; /* an upper bound for correlated channels */
        if (err_image) err_image[i] = (float)s;
    }
    cmp_finish(rel, n, sum_signed, sum_diff, sum_ref, noise, out);
    out->abs_err_vs_mean = out->n_total ? abs_sum / out->n_total : 0;
    free(rel);
    return n ? 0 : -1;
}

int lc_ref_compare_lightmap(const float *approx, const float *ref, const float *ref_stderr, const uint8_t *mask,
                            uint32_t width, uint32_t height, double threshold_frac, lc_ref_errstats *out,
                            float *err_image) {
    return lc_ref_compare_lightmap_subset(approx, ref, ref_stderr, mask, NULL, 0, width, height, threshold_frac, out,
                                          err_image);
}

/* --- blotches ------------------------------------------------------------------------ */

/* Texels a and b lie on one surface: points within 2x the larger spacing, normals within 25 degrees. */
static int cmp_same_surface(const float *sa, const float *sb) {
    static const double cos_max = 0.90630778703665; /* cos 25 degrees */
    double d2 = 0, dot = 0, lim = 2.0 * fmax(sa[6], sb[6]);
    for (int k = 0; k < 3; k++) {
        double d = (double)sa[k] - sb[k];
        d2 += d * d;
        dot += (double)sa[3 + k] * sb[3 + k];
    }
    return isfinite(d2) && d2 <= lim * lim && dot >= cos_max;
}

static double cmp_rel_diff(double a, double b) { return a + b > 0 ? fabs(a - b) / (0.5 * (a + b)) : 0; }

int lc_ref_blotch_metric(const float *approx, const float *ref, const float *ref_stderr, const uint8_t *mask,
                         const float *surface, uint32_t width, uint32_t height, double threshold, lc_ref_blotch *out) {
    memset(out, 0, sizeof *out);
    double sum_a = 0, sum_r = 0, noise = 0;
    for (uint32_t y = 0; y < height; y++)
        for (uint32_t x = 0; x < width; x++) {
            size_t i = (size_t)y * width + x;
            for (int dir = 0; dir < 2; dir++) { /* right and down neighbours: each pair once */
                if ((dir == 0 && x + 1 >= width) || (dir == 1 && y + 1 >= height)) continue;
                size_t j = dir == 0 ? i + 1 : i + width;
                if (mask && (mask[i] != 1 || mask[j] != 1)) continue;
                double ri = lc_ref_luminance(ref + 3 * i), rj = lc_ref_luminance(ref + 3 * j);
                double ai = lc_ref_luminance(approx + 3 * i), aj = lc_ref_luminance(approx + 3 * j);
                if (!(ri > threshold) || !(rj > threshold) || !(ri > 0) || !(rj > 0) || !isfinite(ai) || !isfinite(aj))
                    continue;
                if (surface &&
                    !cmp_same_surface(surface + LC_REF_SURFACE_STRIDE * i, surface + LC_REF_SURFACE_STRIDE * j))
                    continue;
                out->pairs++;
                sum_a += cmp_rel_diff(ai, aj);
                sum_r += cmp_rel_diff(ri, rj);
                if (ref_stderr)
                    noise +=
                        0.5 * (lc_ref_luminance(ref_stderr + 3 * i) / ri + lc_ref_luminance(ref_stderr + 3 * j) / rj);
            }
        }
    if (!out->pairs) return -1;
    out->approx = sum_a / out->pairs;
    out->reference = sum_r / out->pairs;
    out->ratio = out->reference > 0 ? out->approx / out->reference : 0;
    out->ref_noise = noise / out->pairs;
    return 0;
}

char *lc_ref_blotch_json(const lc_ref_blotch *b) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "pairs", b->pairs);
    cJSON_AddNumberToObject(o, "approx", b->approx);
    cJSON_AddNumberToObject(o, "reference", b->reference);
    cJSON_AddNumberToObject(o, "ratio", b->ratio);
    cJSON_AddNumberToObject(o, "ref_noise", b->ref_noise);
    char *text = cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    return text;
}

/* The 6 axes and the 8 cube diagonals. */
static void cmp_dirs(float d[14][3]) {
    int k = 0;
    for (int a = 0; a < 3; a++)
        for (int s = -1; s <= 1; s += 2, k++) {
            d[k][0] = d[k][1] = d[k][2] = 0;
            d[k][a] = (float)s;
        }
    const float q = 0.57735026919f;
    for (int i = 0; i < 8; i++, k++) {
        d[k][0] = (i & 1) ? q : -q;
        d[k][1] = (i & 2) ? q : -q;
        d[k][2] = (i & 4) ? q : -q;
    }
}

static double cmp_eval_y(const float *sh, const float y[9]) {
    float e[3] = {0, 0, 0};
    for (int j = 0; j < 9; j++)
        for (int k = 0; k < 3; k++) e[k] += sh[3 * j + k] * y[j];
    return lc_ref_luminance(e);
}

int lc_ref_compare_grid(const float *approx_sh, const float *ref_sh, const float *ref_stderr, const uint8_t *mask,
                        uint32_t cells, double threshold_frac, lc_ref_errstats *out, float *cell_err) {
    memset(out, 0, sizeof *out);
    float dirs[14][3], ys[14][9];
    cmp_dirs(dirs);
    for (int d = 0; d < 14; d++) lc_sh_eval(3, dirs[d], ys[d]);
    double *mean_ref = malloc((cells ? cells : 1) * sizeof *mean_ref);
    double *rel = malloc((cells ? cells : 1) * sizeof *rel);
    if (!mean_ref || !rel) {
        free(mean_ref);
        free(rel);
        return -1;
    }
    double ymax = 0;
    for (uint32_t c = 0; c < cells; c++) {
        if (cell_err) cell_err[c] = NAN;
        mean_ref[c] = 0;
        if (mask && mask[c] != 1) continue;
        out->n_total++;
        double s = 0;
        for (int d = 0; d < 14; d++) s += fmax(cmp_eval_y(ref_sh + 27 * (size_t)c, ys[d]), 0.0);
        mean_ref[c] = s / 14;
        ymax = fmax(ymax, mean_ref[c]);
    }
    out->threshold = threshold_frac * ymax;
    uint32_t n = 0;
    double sum_signed = 0, sum_diff = 0, sum_ref = 0, noise = 0;
    for (uint32_t c = 0; c < cells; c++) {
        if ((mask && mask[c] != 1) || !(mean_ref[c] > out->threshold) || !(mean_ref[c] > 0)) continue;
        const float *a = approx_sh + 27 * (size_t)c, *r = ref_sh + 27 * (size_t)c;
        double num = 0, den = 0, sgn = 0;
        for (int d = 0; d < 14; d++) {
            double ya = cmp_eval_y(a, ys[d]), yr = cmp_eval_y(r, ys[d]);
            num += fabs(ya - yr);
            sgn += ya - yr;
            den += fmax(yr, 0.0);
        }
        if (!isfinite(num)) continue;
        rel[n++] = num / den;
        sum_signed += sgn / den;
        sum_diff += sgn;
        sum_ref += den;
        if (ref_stderr) {
            double c0 = lc_ref_luminance(r);
            if (c0 > 0) noise += lc_ref_luminance(ref_stderr + 27 * (size_t)c) / c0;
        }
        if (cell_err) cell_err[c] = (float)(num / den);
    }
    cmp_finish(rel, n, sum_signed, sum_diff, sum_ref, noise, out);
    free(mean_ref);
    free(rel);
    return n ? 0 : -1;
}

/* Black -> blue -> cyan -> green -> yellow -> red over t in [0, 1]. */
static void cmp_ramp(double t, float rgb[3]) {
    static const float stops[6][3] = {{0, 0, 0}, {0, 0, 1}, {0, 1, 1}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}};
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    double x = t * 5;
    int i = (int)x;
    if (i >= 5) i = 4;
    double f = x - i;
    for (int k = 0; k < 3; k++) rgb[k] = (float)(stops[i][k] * (1 - f) + stops[i + 1][k] * f);
}

int lc_ref_write_heatmap(const char *path, const float *err_image, uint32_t width, uint32_t height, double max_err,
                         uint32_t zoom, char *err, size_t errlen) {
    if (zoom < 1) zoom = 1;
    if (!(max_err > 0)) max_err = 0.5;
    uint64_t w = (uint64_t)width * zoom, h = (uint64_t)height * zoom;
    if (!w || !h || w > 16384 || h > 16384) {
        lc_set_err(err, errlen, "%s: heat map size %llux%llu out of range", path, (unsigned long long)w,
                   (unsigned long long)h);
        return -1;
    }
    float *img = malloc((size_t)(w * h * 3) * sizeof(float));
    if (!img) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    for (uint64_t y = 0; y < h; y++)
        for (uint64_t x = 0; x < w; x++) {
            float e = err_image[(y / zoom) * width + x / zoom], *o = img + 3 * (y * w + x);
            if (isnan(e)) o[0] = o[1] = o[2] = 0.2f;
            else cmp_ramp(fabs(e) / max_err, o);
        }
    int rc = lc_image_write(path, (uint32_t)w, (uint32_t)h, 3, img, err, errlen);
    free(img);
    return rc;
}

/* The signed scale of lc_ref_heatmap_uv (ref.h). */
static void cmp_signed_colour(double e, double max_err, uint8_t *o) {
    double t = e / max_err;
    t = t < -1 ? -1 : t > 1 ? 1 : t;
    double rgb[3] = {t < 0 ? 1 + t : 1, 1 - fabs(t), t > 0 ? 1 - t : 1};
    for (int k = 0; k < 3; k++) o[k] = (uint8_t)lround(255.0 * rgb[k]);
    o[3] = 255;
}

int lc_ref_heatmap_uv(const float *err_image, const uint8_t *mask, uint32_t width, uint32_t height, double max_err,
                      uint8_t *rgba) {
    if (!(max_err > 0)) max_err = 0.5;
    size_t texels = (size_t)width * height;
    uint32_t *queue = malloc((texels ? texels : 1) * sizeof *queue);
    uint8_t *done = calloc(texels ? texels : 1, 1);
    if (!queue || !done) {
        free(queue);
        free(done);
        return -1;
    }
    size_t head = 0, tail = 0;
    memset(rgba, 0, texels * 4);
    for (size_t i = 0; i < texels; i++)
        if (mask[i] != 0 && !isnan(err_image[i])) {
            cmp_signed_colour(err_image[i], max_err, rgba + 4 * i);
            done[i] = 1;
            queue[tail++] = (uint32_t)i;
        }
    /* Breadth-first from the compared texels through covered ones: each copies its parent's colour. */
    while (head < tail) {
        uint32_t i = queue[head++], x = i % width, y = i / width;
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int64_t nx = (int64_t)x + dx, ny = (int64_t)y + dy;
                if ((!dx && !dy) || nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
                size_t j = (size_t)ny * width + (size_t)nx;
                if (done[j] || mask[j] == 0) continue;
                memcpy(rgba + 4 * j, rgba + 4 * (size_t)i, 4);
                done[j] = 1;
                queue[tail++] = (uint32_t)j;
            }
    }
    for (size_t i = 0; i < texels; i++)
        if (mask[i] != 0 && !done[i]) rgba[4 * i] = rgba[4 * i + 1] = rgba[4 * i + 2] = 128, rgba[4 * i + 3] = 255;
    free(queue);
    free(done);
    return 0;
}

int lc_ref_write_heatmap_uv(const char *path, const float *err_image, const uint8_t *mask, uint32_t width,
                            uint32_t height, double max_err, char *err, size_t errlen) {
    size_t texels = (size_t)width * height;
    if (!width || !height || width > 16384 || height > 16384) {
        lc_set_err(err, errlen, "%s: heat map size %ux%u out of range", path, width, height);
        return -1;
    }
    uint8_t *rgba = malloc(texels * 4);
    float *img = malloc(texels * 4 * sizeof *img);
    int rc = -1;
    if (!rgba || !img || lc_ref_heatmap_uv(err_image, mask, width, height, max_err, rgba) != 0) {
        lc_set_err(err, errlen, "out of memory");
        goto done;
    }
    for (size_t i = 0; i < texels * 4; i++) img[i] = rgba[i] / 255.0f;
    rc = lc_image_write(path, width, height, 4, img, err, errlen);
done:
    free(rgba);
    free(img);
    return rc;
}

char *lc_ref_errstats_json(const lc_ref_errstats *s) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "compared", s->n);
    cJSON_AddNumberToObject(o, "candidates", s->n_total);
    cJSON_AddNumberToObject(o, "threshold", s->threshold);
    cJSON_AddNumberToObject(o, "mean", s->mean);
    cJSON_AddNumberToObject(o, "p50", s->p50);
    cJSON_AddNumberToObject(o, "p95", s->p95);
    cJSON_AddNumberToObject(o, "max", s->max);
    cJSON_AddNumberToObject(o, "bias", s->bias);
    cJSON_AddNumberToObject(o, "mean_signed", s->mean_signed);
    cJSON_AddNumberToObject(o, "ref_noise", s->ref_noise);
    if (s->ref_mean > 0) { /* lightmap rows */
        cJSON_AddNumberToObject(o, "dark", s->n_dark);
        cJSON_AddNumberToObject(o, "dark_lit", s->n_dark_lit);
        cJSON_AddNumberToObject(o, "ref_mean", s->ref_mean);
        cJSON_AddNumberToObject(o, "abs_err_vs_mean", s->abs_err_vs_mean);
    }
    char *text = cJSON_PrintUnformatted(o);
    cJSON_Delete(o);
    return text;
}

/* --- the engine side ---------------------------------------------------------------------------- */

void lc_ref_engine_run_free(lc_ref_engine_run *run) {
    if (!run) return;
    free(run->lightmap);
    free(run->grid_sh);
    free(run->surfel_radiosity);
    memset(run, 0, sizeof *run);
}

/* DRT operators for the state's clutter objects, attached to e (see lc_ref_engine_converge). */
static int engine_attach_clutter(lc_engine *e, const lc_lcb_view *v, const lc_engine_state *st, int threads,
                                 lc_ref_engine_run *out, char *err, size_t errlen) {
    lc_drt_builder *b = NULL;
    lc_drt_settings ds = lc_drt_default_settings();
    for (uint32_t i = 0; i < st->n_objects; i++) {
        const lc_engine_object *o = &st->objects[i];
        if (o->clutter_off || !o->visible) continue;
        if (!b && !(b = lc_drt_builder_create(v, threads, err, errlen))) return -1;
        lc_drt_ops *ops = NULL;
        if (lc_drt_build(b, o, &ds, NULL, &ops, err, errlen) != 0) goto err;
        lc_drt_info in = lc_drt_ops_info(ops);
        if (lc_engine_clutter_attach(e, ops, err, errlen) != 0) goto err;
        out->clutter_objects++;
        out->clutter_build_ms += in.build_ms;
        out->clutter_bytes += in.bytes;
    }
    lc_drt_builder_release(b);
    return 0;
err:
    lc_drt_builder_release(b);
    return -1;
}

int lc_ref_engine_converge(const lc_lcb *bake, const lc_engine_state *state, lc_backend_kind backend, int threads,
                           double tol, uint32_t max_relights, int bounce_limit, lc_ref_engine_run *out, char *err,
                           size_t errlen) {
    memset(out, 0, sizeof *out);
    const lc_lcb_view *v = lc_lcb_get(bake);
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    size_t cells = (size_t)v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2];
    lc_engine *e = lc_engine_create(bake, backend, threads, err, errlen);
    if (!e) return -1;
    out->lightmap = calloc(texels * 3 + 1, sizeof(float));
    out->grid_sh = calloc(cells * 27 + 1, sizeof(float));
    out->surfel_radiosity = calloc((size_t)v->n_surfels * 3 + 1, sizeof(float));
    if (!out->lightmap || !out->grid_sh || !out->surfel_radiosity) {
        lc_set_err(err, errlen, "out of memory");
        goto err;
    }
    snprintf(out->backend, sizeof out->backend, "%s", lc_engine_backend_name(e));
    if (engine_attach_clutter(e, v, state, threads, out, err, errlen) != 0) goto err;
    lc_engine_state st = *state;
    st.settings.progressive = 1;
    if (bounce_limit >= 0) {
        st.settings.progressive = 0;
        st.settings.bounces = (uint32_t)bounce_limit;
        max_relights = 1;
    }
    const lc_engine_frame *fr = NULL;
    double t0 = 0;
    out->last_change = INFINITY;
    for (uint32_t i = 0; i < max_relights; i++) {
        if (lc_engine_relight(e, &st, &fr, err, errlen) != 0) goto err;
        if (i == 0) out->ms_first = fr->total_ms;
        t0 += fr->total_ms;
        double ymax = 0, change = 0;
        for (size_t t = 0; t < texels; t++) ymax = fmax(ymax, lc_ref_luminance(fr->lightmap + 3 * t));
        for (size_t t = 0; t < texels; t++) {
            double y1 = lc_ref_luminance(fr->lightmap + 3 * t), y0 = lc_ref_luminance(out->lightmap + 3 * t);
            if (y1 > 0.01 * ymax) change = fmax(change, fabs(y1 - y0) / y1);
        }
        memcpy(out->lightmap, fr->lightmap, texels * 3 * sizeof(float));
        out->relights = i + 1;
        out->last_change = change;
        if (bounce_limit >= 0 || (i > 0 && change < tol)) break;
    }
    memcpy(out->grid_sh, fr->grid_sh, cells * 27 * sizeof(float));
    memcpy(out->surfel_radiosity, fr->surfel_radiosity, (size_t)v->n_surfels * 3 * sizeof(float));
    out->ms_total = t0;
    /* B0 alone: one pass, no feedback (the radiosity of the first pass is B0). */
    st.settings.progressive = 0;
    st.settings.bounces = 0;
    if (lc_engine_relight(e, &st, &fr, err, errlen) != 0) goto err;
    for (uint32_t s = 0; s < v->n_surfels; s++)
        for (int k = 0; k < 3; k++) out->b0_power[k] += (double)fr->surfel_radiosity[3 * s + k] * v->surfels[s].area;
    lc_engine_release(e);
    return 0;
err:
    lc_engine_release(e);
    lc_ref_engine_run_free(out);
    return -1;
}
