/* camera: the reference's view through a pinhole camera (`lucent-ref camera`), the image a
 * viewer's screenshot of the same view is compared with. The camera is three.js's
 * PerspectiveCamera; each pixel averages lc_ref_radiance over stratified positions inside it;
 * the PNG goes through the viewer's tone map and the sRGB transfer. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/image.h"
#include "ref/ref.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/progress.h"

/* --- the camera ---------------------------------------------------------------------------------- */

static double cam_dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static void cam_cross(const double a[3], const double b[3], double o[3]) {
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}
static int cam_finite3(const float v[3]) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

int lc_ref_camera_setup(const lc_ref_camera *cam, lc_ref_camera_basis *b, char *err, size_t errlen) {
    if (!(cam->fov_deg > 0 && cam->fov_deg < 180)) {
        lc_set_err(err, errlen, "--fov: %g is not a vertical field of view in (0, 180) degrees", cam->fov_deg);
        return -1;
    }
    if (cam->width < 1 || cam->width > LC_REF_CAMERA_MAX_SIDE) {
        lc_set_err(err, errlen, "--width: %u is out of range [1, %u]", cam->width, LC_REF_CAMERA_MAX_SIDE);
        return -1;
    }
    if (cam->height < 1 || cam->height > LC_REF_CAMERA_MAX_SIDE) {
        lc_set_err(err, errlen, "--height: %u is out of range [1, %u]", cam->height, LC_REF_CAMERA_MAX_SIDE);
        return -1;
    }
    const char *bad = !cam_finite3(cam->eye) ? "--eye"
        : !cam_finite3(cam->target)          ? "--target"
        : !cam_finite3(cam->up)              ? "--up"
                                             : NULL;
    if (bad) {
        lc_set_err(err, errlen, "%s: not three finite numbers", bad);
        return -1;
    }
    double f[3], len;
    for (int k = 0; k < 3; k++) f[k] = (double)cam->target[k] - cam->eye[k];
    len = sqrt(cam_dot(f, f));
    if (!(len > 0)) {
        lc_set_err(err, errlen, "--target: equals --eye (no view direction)");
        return -1;
    }
    for (int k = 0; k < 3; k++) b->forward[k] = f[k] / len;
    double up[3] = {cam->up[0], cam->up[1], cam->up[2]}, r[3];
    cam_cross(b->forward, up, r);
    len = sqrt(cam_dot(r, r));
    /* three.js's lookAt nudges a parallel up; a reference must not guess the viewer's fix. */
    if (!(len > 1e-6 * sqrt(cam_dot(up, up)))) {
        lc_set_err(err, errlen, "--up: zero or parallel to the view direction (--target - --eye)");
        return -1;
    }
    for (int k = 0; k < 3; k++) b->right[k] = r[k] / len;
    cam_cross(b->right, b->forward, b->up);
    b->tan_y = tan(cam->fov_deg * M_PI / 360.0);
    b->tan_x = b->tan_y * (double)cam->width / cam->height;
    return 0;
}

void lc_ref_camera_ray(const lc_ref_camera_basis *b, uint32_t width, uint32_t height, double px, double py,
                       float dir[3]) {
    double x = 2.0 * px / width - 1.0, y = 1.0 - 2.0 * py / height, d[3];
    for (int k = 0; k < 3; k++) d[k] = b->forward[k] + x * b->tan_x * b->right[k] + y * b->tan_y * b->up[k];
    double len = sqrt(cam_dot(d, d));
    for (int k = 0; k < 3; k++) dir[k] = (float)(d[k] / len);
}

/* --- render -------------------------------------------------------------------------------------- */

typedef struct {
    lc_ref *r;
    const lc_ref_camera *cam;
    const lc_ref_camera_basis *basis;
    const lc_ref_camera_settings *s;
    lc_ref_image *out;
    uint64_t *row_rays; /* per row: summed after the loop, so the total does not race */
    lc_progress *progress;
} cam_ctx;

/* Sample k of n inside a pixel: the centre for one sample, else jittered on the largest m x m
 * grid that fits (m = floor(sqrt(n))), the samples beyond m^2 uniform. */
static void cam_subpixel(uint32_t k, uint32_t n, uint32_t m, lc_rng *rng, double *u, double *v) {
    if (n == 1) {
        *u = *v = 0.5;
        return;
    }
    double ju = lc_rng_float(rng), jv = lc_rng_float(rng);
    if (k < m * m) {
        *u = ((k % m) + ju) / m;
        *v = ((k / m) + jv) / m;
    } else {
        *u = ju;
        *v = jv;
    }
}

static void cam_rows(void *vctx, size_t begin, size_t end, int thread) {
    (void)thread;
    cam_ctx *c = vctx;
    const lc_ref_camera_settings *s = c->s;
    uint32_t w = c->cam->width, h = c->cam->height, m = (uint32_t)floor(sqrt((double)s->spp));
    while ((m + 1) * (m + 1) <= s->spp) m++;
    while (m * m > s->spp) m--;
    for (size_t j = begin; j < end; j++) {
        uint64_t rays = 0;
        for (uint32_t i = 0; i < w; i++) {
            size_t px = j * w + i;
            lc_rng rng = lc_rng_seed(s->seed, 0xCA3E000000000000ull ^ (uint64_t)px);
            double sum[3] = {0, 0, 0}, sq = 0;
            for (uint32_t k = 0; k < s->spp; k++) {
                double u, v;
                float dir[3], L[3];
                cam_subpixel(k, s->spp, m, &rng, &u, &v);
                lc_ref_camera_ray(c->basis, w, h, i + u, j + v, dir);
                lc_ref_radiance(c->r, c->cam->eye, dir, s->max_depth, s->rr_depth, &rng, L, &rays);
                for (int q = 0; q < 3; q++) sum[q] += L[q];
                double y = lc_ref_luminance(L);
                sq += y * y;
            }
            double n = s->spp, my = (0.2126 * sum[0] + 0.7152 * sum[1] + 0.0722 * sum[2]) / n;
            double var = n > 1 ? (sq - n * my * my) / (n - 1) : 0;
            for (int q = 0; q < 3; q++) c->out->rgb[3 * px + q] = (float)(sum[q] / n);
            c->out->stderr_y[px] = (float)sqrt(fmax(var, 0) / n);
        }
        c->row_rays[j] = rays;
        lc_progress_add(c->progress, 1);
    }
}

void lc_ref_image_free(lc_ref_image *img) {
    if (!img) return;
    free(img->rgb);
    free(img->stderr_y);
    memset(img, 0, sizeof *img);
}

/* The image's noise: mean stderr(Y) / Y over the pixels brighter than 5% of the mean
 * luminance (relative to the mean, not the brightest: an emitter in view would leave out
 * most of the image). */
static void cam_noise(lc_ref_image *img) {
    size_t n = (size_t)img->width * img->height;
    double ymean = 0, sum = 0;
    uint32_t count = 0;
    for (size_t i = 0; i < n; i++) ymean += lc_ref_luminance(img->rgb + 3 * i);
    ymean /= (double)n;
    for (size_t i = 0; i < n; i++) {
        double y = lc_ref_luminance(img->rgb + 3 * i);
        if (!(y > 0.05 * ymean)) continue;
        sum += img->stderr_y[i] / y;
        count++;
    }
    img->n_bright = count;
    img->mean_rel_stderr = count ? sum / count : 0;
}

int lc_ref_camera_render(lc_ref *r, const lc_ref_camera *cam, const lc_ref_camera_settings *s, lc_ref_image *out,
                         char *err, size_t errlen) {
    memset(out, 0, sizeof *out);
    lc_ref_camera_basis basis;
    uint64_t *row_rays = NULL;
    if (lc_ref_camera_setup(cam, &basis, err, errlen) != 0) return -1;
    if (s->spp < 1) {
        lc_set_err(err, errlen, "--spp: must be >= 1");
        return -1;
    }
    double t0 = lc_clock_ms();
    size_t n = (size_t)cam->width * cam->height;
    out->width = cam->width;
    out->height = cam->height;
    out->rgb = malloc(n * 3 * sizeof(float));
    out->stderr_y = malloc(n * sizeof(float));
    row_rays = calloc(cam->height, sizeof *row_rays);
    if (!out->rgb || !out->stderr_y || !row_rays) {
        lc_set_err(err, errlen, "out of memory for a %ux%u image", cam->width, cam->height);
        goto err;
    }
    cam_ctx ctx = {r, cam, &basis, s, out, row_rays, NULL};
    if (!s->quiet) ctx.progress = lc_progress_begin("camera rows", cam->height);
    lc_parallel_for(lc_ref_threads(r), cam->height, 1, cam_rows, &ctx);
    lc_progress_end(ctx.progress);
    for (uint32_t j = 0; j < cam->height; j++) out->rays += row_rays[j];
    free(row_rays);
    cam_noise(out);
    out->seconds = (lc_clock_ms() - t0) / 1000.0;
    return 0;
err:
    free(row_rays);
    lc_ref_image_free(out);
    return -1;
}

/* --- tone map and output ------------------------------------------------------------------------- */

void lc_ref_tonemap(lc_ref_tonemap_kind kind, double exposure, const float in[3], double out[3]) {
    double c[3] = {exposure * in[0], exposure * in[1], exposure * in[2]};
    if (kind == LC_REF_TONEMAP_NEUTRAL) {
        /* Khronos PBR Neutral, as three.js's NeutralToneMapping (StartCompression 0.8 - 0.04,
         * Desaturation 0.15). */
        const double start = 0.8 - 0.04, desat = 0.15;
        double x = fmin(c[0], fmin(c[1], c[2]));
        double offset = x < 0.08 ? x - 6.25 * x * x : 0.04;
        for (int k = 0; k < 3; k++) c[k] -= offset;
        double peak = fmax(c[0], fmax(c[1], c[2]));
        if (peak >= start) {
            double d = 1.0 - start, new_peak = 1.0 - d * d / (peak + d - start);
            for (int k = 0; k < 3; k++) c[k] *= new_peak / peak;
            double g = 1.0 - 1.0 / (desat * (peak - new_peak) + 1.0);
            for (int k = 0; k < 3; k++) c[k] = c[k] * (1.0 - g) + new_peak * g;
        }
    }
    /* Linear clamps here; the neutral curve stays within [0, 1] but the framebuffer clamps too. */
    for (int k = 0; k < 3; k++) out[k] = isnan(c[k]) ? 0.0 : fmin(fmax(c[k], 0.0), 1.0);
}

uint8_t lc_ref_srgb8(double v) {
    v = isnan(v) ? 0.0 : fmin(fmax(v, 0.0), 1.0);
    double e = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
    return (uint8_t)lround(fmin(fmax(255.0 * e, 0.0), 255.0));
}

int lc_ref_image_write_png(const char *path, const lc_ref_image *img, lc_ref_tonemap_kind kind, double exposure,
                           char *err, size_t errlen) {
    size_t n = (size_t)img->width * img->height;
    float *px = malloc(n * 3 * sizeof(float) + 1);
    if (!px) {
        lc_set_err(err, errlen, "%s: out of memory", path);
        return -1;
    }
    /* The 8-bit codes as floats k / 255: the 8-bit writer maps them back to exactly k. */
    for (size_t i = 0; i < n; i++) {
        double c[3];
        lc_ref_tonemap(kind, exposure, img->rgb + 3 * i, c);
        for (int k = 0; k < 3; k++) px[3 * i + k] = (float)lc_ref_srgb8(c[k]) / 255.0f;
    }
    int rc = lc_image_write(path, img->width, img->height, 3, px, err, errlen);
    free(px);
    return rc;
}
