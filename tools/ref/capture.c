/* capture: `lucent-ref capture`, the baked scene recorded as an RGB-D camera would (the replay
 * format, ref.h "RGB-D capture"), and its reader for `mr-truth`. PNGs go through libpng without
 * colour management: the samples are data (millimetres, linear radiance codes). */
#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "ref/ref.h"
#include "util/clock.h"
#include "util/fsutil.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/progress.h"
#include "util/rng.h"

#define CAP_PATH_MAX 1200
#define CAP_JSON_MAX (1u << 20)

/* --- the camera model ------------------------------------------------------------------------- */

void lc_ref_quat_matrix(const double q_in[4], double m[9]) {
    double len = sqrt(q_in[0] * q_in[0] + q_in[1] * q_in[1] + q_in[2] * q_in[2] + q_in[3] * q_in[3]);
    double x = q_in[0] / len, y = q_in[1] / len, z = q_in[2] / len, w = q_in[3] / len;
    m[0] = 1 - 2 * (y * y + z * z), m[1] = 2 * (x * y - z * w), m[2] = 2 * (x * z + y * w);
    m[3] = 2 * (x * y + z * w), m[4] = 1 - 2 * (x * x + z * z), m[5] = 2 * (y * z - x * w);
    m[6] = 2 * (x * z - y * w), m[7] = 2 * (y * z + x * w), m[8] = 1 - 2 * (x * x + y * y);
}

/* Shepperd's method: the largest of w, x, y, z first, so no division by a small number. */
void lc_ref_matrix_quat(const double m[9], double q[4]) {
    double tr = m[0] + m[4] + m[8];
    if (tr > 0) {
        double s = 2 * sqrt(1 + tr);
        q[3] = s / 4, q[0] = (m[7] - m[5]) / s, q[1] = (m[2] - m[6]) / s, q[2] = (m[3] - m[1]) / s;
    } else if (m[0] > m[4] && m[0] > m[8]) {
        double s = 2 * sqrt(1 + m[0] - m[4] - m[8]);
        q[3] = (m[7] - m[5]) / s, q[0] = s / 4, q[1] = (m[1] + m[3]) / s, q[2] = (m[2] + m[6]) / s;
    } else if (m[4] > m[8]) {
        double s = 2 * sqrt(1 + m[4] - m[0] - m[8]);
        q[3] = (m[2] - m[6]) / s, q[0] = (m[1] + m[3]) / s, q[1] = s / 4, q[2] = (m[5] + m[7]) / s;
    } else {
        double s = 2 * sqrt(1 + m[8] - m[0] - m[4]);
        q[3] = (m[3] - m[1]) / s, q[0] = (m[2] + m[6]) / s, q[1] = (m[5] + m[7]) / s, q[2] = s / 4;
    }
    double len = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    double sign = q[3] < 0 ? -1 : 1; /* w >= 0: one spelling per rotation */
    for (int k = 0; k < 4; k++) q[k] *= sign / len;
}

int lc_ref_rgbd_lookat(const lc_ref_camera *cam, lc_ref_rgbd_view *out, char *err, size_t errlen) {
    lc_ref_camera_basis b;
    if (lc_ref_camera_setup(cam, &b, err, errlen) != 0) return -1;
    memset(out, 0, sizeof *out);
    out->width = cam->width;
    out->height = cam->height;
    out->fx = out->fy = (cam->height / 2.0) / b.tan_y;
    out->cx = cam->width / 2.0;
    out->cy = cam->height / 2.0;
    double m[9];
    for (int k = 0; k < 3; k++) {
        m[3 * k + 0] = b.right[k];
        m[3 * k + 1] = b.up[k];
        m[3 * k + 2] = -b.forward[k];
    }
    lc_ref_matrix_quat(m, out->rotation);
    for (int k = 0; k < 3; k++) out->translation[k] = cam->eye[k];
    return 0;
}

void lc_ref_rgbd_ray(const lc_ref_rgbd_view *view, double u, double v, float org[3], float dir[3], double *z_per_t) {
    double m[9], c[3] = {(u - view->cx) / view->fx, -(v - view->cy) / view->fy, -1.0}, d[3];
    lc_ref_quat_matrix(view->rotation, m);
    double len = sqrt(c[0] * c[0] + c[1] * c[1] + 1.0);
    for (int k = 0; k < 3; k++) d[k] = m[3 * k] * c[0] + m[3 * k + 1] * c[1] + m[3 * k + 2] * c[2];
    for (int k = 0; k < 3; k++) {
        org[k] = (float)view->translation[k];
        dir[k] = (float)(d[k] / len);
    }
    if (z_per_t) *z_per_t = 1.0 / len;
}

void lc_ref_rgbd_unproject(const lc_ref_rgbd_view *view, double u, double v, double z, double out[3]) {
    double m[9], p[3] = {(u - view->cx) * z / view->fx, -(v - view->cy) * z / view->fy, -z};
    lc_ref_quat_matrix(view->rotation, m);
    for (int k = 0; k < 3; k++)
        out[k] = m[3 * k] * p[0] + m[3 * k + 1] * p[1] + m[3 * k + 2] * p[2] + view->translation[k];
}

/* --- rendering -------------------------------------------------------------------------------- */

typedef struct {
    lc_ref *r;
    const lc_ref_rgbd_view *view;
    const lc_ref_capture_settings *s;
    uint32_t frame;
    float *rgb, *depth;
    uint64_t *row_rays;
    lc_progress *progress;
} cap_ctx;

/* Sample k of n in a pixel: the centre for one sample, else jittered on the largest m x m grid
 * that fits, the samples beyond m^2 uniform (as the camera's). */
static void cap_subpixel(uint32_t k, uint32_t n, uint32_t m, lc_rng *rng, double *u, double *v) {
    if (n == 1) {
        *u = *v = 0.5;
        return;
    }
    double ju = lc_rng_float(rng), jv = lc_rng_float(rng);
    *u = k < m * m ? ((k % m) + ju) / m : ju;
    *v = k < m * m ? ((k / m) + jv) / m : jv;
}

static void cap_rows(void *vctx, size_t begin, size_t end, int thread) {
    (void)thread;
    cap_ctx *c = vctx;
    const lc_ref_capture_settings *s = c->s;
    uint32_t w = c->view->width, m = 1;
    while ((m + 1) * (m + 1) <= s->spp) m++;
    for (size_t j = begin; j < end; j++) {
        uint64_t rays = 0;
        for (uint32_t i = 0; i < w; i++) {
            size_t px = j * w + i;
            lc_rng rng = lc_rng_seed(s->seed, 0xCA97000000000000ull ^ ((uint64_t)c->frame << 32) ^ (uint64_t)px);
            float org[3], dir[3], ng[3], t;
            double zt;
            lc_ref_rgbd_ray(c->view, i + 0.5, j + 0.5, org, dir, &zt);
            rays++;
            c->depth[px] = lc_ref_first_hit(c->r, org, dir, &t, ng) ? (float)(t * zt) : 0.0f;
            double sum[3] = {0, 0, 0};
            for (uint32_t k = 0; k < s->spp; k++) {
                double u, v;
                float L[3];
                cap_subpixel(k, s->spp, m, &rng, &u, &v);
                lc_ref_rgbd_ray(c->view, i + u, j + v, org, dir, NULL);
                lc_ref_radiance_ex(c->r, org, dir, s->max_depth, s->rr_depth, 0, &rng, L, &rays);
                for (int q = 0; q < 3; q++) sum[q] += L[q];
            }
            for (int q = 0; q < 3; q++) c->rgb[3 * px + q] = (float)(sum[q] / s->spp);
        }
        c->row_rays[j] = rays;
        lc_progress_add(c->progress, 1);
    }
}

int lc_ref_rgbd_render(lc_ref *r, const lc_ref_rgbd_view *view, const lc_ref_capture_settings *s, uint32_t frame,
                       float *rgb, float *depth, uint64_t *rays, char *err, size_t errlen) {
    if (s->spp < 1) {
        lc_set_err(err, errlen, "--spp: must be >= 1");
        return -1;
    }
    if (view->width < 1 || view->height < 1 || view->width > LC_REF_CAMERA_MAX_SIDE ||
        view->height > LC_REF_CAMERA_MAX_SIDE) {
        lc_set_err(err, errlen, "--width/--height: %ux%u is out of range [1, %u]", view->width, view->height,
                   LC_REF_CAMERA_MAX_SIDE);
        return -1;
    }
    uint64_t *row_rays = calloc(view->height, sizeof *row_rays);
    if (!row_rays) {
        lc_set_err(err, errlen, "out of memory for a %ux%u frame", view->width, view->height);
        return -1;
    }
    cap_ctx ctx = {r, view, s, frame, rgb, depth, row_rays, NULL};
    /* A bar within the frame only for big ones (over 16M paths); each frame also gets a line. */
    if (!s->quiet && (uint64_t)view->width * view->height * s->spp > (16u << 20))
        ctx.progress = lc_progress_begin("capture rows", view->height);
    lc_parallel_for(lc_ref_threads(r), view->height, 1, cap_rows, &ctx);
    lc_progress_end(ctx.progress);
    if (rays) {
        *rays = 0;
        for (uint32_t j = 0; j < view->height; j++) *rays += row_rays[j];
    }
    free(row_rays);
    return 0;
}

/* --- PNG ----------------------------------------------------------------------------------------- */

int lc_ref_png_write(const char *path, uint32_t width, uint32_t height, int channels, int bits, const uint16_t *samples,
                     char *err, size_t errlen) {
    if ((channels != 1 && channels != 3) || (bits != 8 && bits != 16) || width < 1 || height < 1 ||
        width > LC_REF_CAMERA_MAX_SIDE || height > LC_REF_CAMERA_MAX_SIDE) {
        lc_set_err(err, errlen, "%s: cannot write a %ux%u PNG of %d channels, %d bits", path, width, height, channels,
                   bits);
        return -1;
    }
    size_t row_bytes = (size_t)width * channels * (bits / 8);
    png_bytep row = malloc(row_bytes);
    FILE *f = fopen(path, "wb");
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    if (!row || !f || !png || !info) {
        lc_set_err(err, errlen, "%s: %s", path, !f ? strerror(errno) : "out of memory");
        goto err;
    }
    if (setjmp(png_jmpbuf(png))) {
        lc_set_err(err, errlen, "%s: libpng failed writing", path);
        goto err;
    }
    png_init_io(png, f);
    png_set_IHDR(png, info, width, height, bits, channels == 1 ? PNG_COLOR_TYPE_GRAY : PNG_COLOR_TYPE_RGB,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_write_info(png, info);
    for (uint32_t y = 0; y < height; y++) {
        const uint16_t *src = samples + (size_t)y * width * channels;
        for (size_t i = 0; i < (size_t)width * channels; i++) {
            if (bits == 8) row[i] = (png_byte)(src[i] > 255 ? 255 : src[i]);
            else row[2 * i] = (png_byte)(src[i] >> 8), row[2 * i + 1] = (png_byte)(src[i] & 0xFF);
        }
        png_write_row(png, row);
    }
    png_write_end(png, NULL);
    png_destroy_write_struct(&png, &info);
    free(row);
    if (fclose(f) != 0) {
        lc_set_err(err, errlen, "%s: %s", path, strerror(errno));
        return -1;
    }
    return 0;
err:
    if (png) png_destroy_write_struct(&png, info ? &info : NULL);
    free(row);
    if (f) fclose(f);
    return -1;
}

/* The decoded rows (big-endian for 16 bits) into samples. */
static void cap_png_unpack(const png_bytep data, size_t n, int bits, uint16_t *samples) {
    for (size_t i = 0; i < n; i++)
        samples[i] = bits == 8 ? data[i] : (uint16_t)((uint16_t)data[2 * i] << 8 | data[2 * i + 1]);
}

int lc_ref_png_read(const char *path, uint32_t max_side, uint32_t *width, uint32_t *height, int *channels, int *bits,
                    uint16_t **samples, char *err, size_t errlen) {
    *samples = NULL;
    FILE *f = fopen(path, "rb");
    png_structp png = NULL;
    png_infop info = NULL;
    png_bytep volatile data = NULL; /* volatile: set after setjmp, freed after a longjmp */
    png_bytepp volatile rows = NULL;
    if (!f) {
        lc_set_err(err, errlen, "%s: %s", path, strerror(errno));
        return -1;
    }
    png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    info = png ? png_create_info_struct(png) : NULL;
    if (!png || !info) {
        lc_set_err(err, errlen, "%s: out of memory", path);
        goto err;
    }
    if (setjmp(png_jmpbuf(png))) {
        lc_set_err(err, errlen, "%s: not a readable PNG", path);
        goto err;
    }
    png_init_io(png, f);
    png_read_info(png, info);
    png_uint_32 w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    int depth = png_get_bit_depth(png, info), type = png_get_color_type(png, info);
    int ch = type == PNG_COLOR_TYPE_GRAY ? 1 : type == PNG_COLOR_TYPE_RGB ? 3 : 0;
    if (!ch || (depth != 8 && depth != 16) || w < 1 || h < 1 || w > max_side || h > max_side) {
        lc_set_err(err, errlen,
                   "%s: a %ux%u PNG of colour type %d, %d bits (want grey or RGB, 8 or 16 bits, sides <= %u)", path,
                   (unsigned)w, (unsigned)h, type, depth, max_side);
        goto err;
    }
    png_set_interlace_handling(png);
    png_read_update_info(png, info);
    size_t row_bytes = png_get_rowbytes(png, info), n = (size_t)w * h * ch;
    data = malloc(row_bytes * h);
    rows = malloc(h * sizeof *rows);
    *samples = malloc(n * sizeof **samples);
    if (!data || !rows || !*samples || row_bytes != (size_t)w * ch * (depth / 8)) {
        lc_set_err(err, errlen, "%s: out of memory", path);
        goto err;
    }
    for (png_uint_32 y = 0; y < h; y++) rows[y] = data + y * row_bytes;
    png_read_image(png, rows);
    png_read_end(png, NULL);
    cap_png_unpack(data, n, depth, *samples);
    *width = w, *height = h, *channels = ch, *bits = depth;
    png_destroy_read_struct(&png, &info, NULL);
    free(data);
    free(rows);
    fclose(f);
    return 0;
err:
    if (png) png_destroy_read_struct(&png, info ? &info : NULL, NULL);
    free(data);
    free(rows);
    free(*samples);
    *samples = NULL;
    fclose(f);
    return -1;
}

double lc_ref_srgb_eotf(double v) {
    v = isnan(v) ? 0.0 : fmin(fmax(v, 0.0), 1.0);
    return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

/* --- writing ------------------------------------------------------------------------------------ */

static int cap_write_json(const char *path, cJSON *j, char *err, size_t errlen) {
    char *text = j ? cJSON_Print(j) : NULL;
    cJSON_Delete(j);
    if (!text) {
        lc_set_err(err, errlen, "%s: out of memory", path);
        return -1;
    }
    size_t len = strlen(text);
    int rc = lc_fs_write_atomic(path, text, len, err, errlen);
    free(text);
    return rc;
}

static cJSON *cap_array(const double *v, int n) {
    cJSON *a = cJSON_CreateArray();
    for (int k = 0; k < n; k++) cJSON_AddItemToArray(a, cJSON_CreateNumber(v[k]));
    return a;
}

static cJSON *cap_frame_json(uint32_t k, const lc_ref_capture_pose *pose, double exposure, int srgb8) {
    const lc_ref_rgbd_view *v = &pose->view;
    cJSON *j = cJSON_CreateObject(), *in = cJSON_CreateObject(), *po = cJSON_CreateObject();
    cJSON_AddNumberToObject(j, "sequence", k);
    cJSON_AddNumberToObject(j, "time_us", (double)pose->time_us);
    cJSON_AddNumberToObject(in, "fx", v->fx);
    cJSON_AddNumberToObject(in, "fy", v->fy);
    cJSON_AddNumberToObject(in, "cx", v->cx);
    cJSON_AddNumberToObject(in, "cy", v->cy);
    cJSON_AddItemToObject(j, "intrinsics", in);
    cJSON_AddItemToObject(po, "translation", cap_array(v->translation, 3));
    cJSON_AddItemToObject(po, "rotation", cap_array(v->rotation, 4));
    cJSON_AddItemToObject(j, "pose", po);
    cJSON_AddNumberToObject(j, "exposure", exposure);
    cJSON_AddStringToObject(j, "color", srgb8 ? "srgb8" : "linear16");
    return j;
}

int lc_ref_capture_write_frame(const char *dir, uint32_t k, const lc_ref_capture_pose *pose, const float *rgb,
                               const float *depth, int srgb8, double *exposure_out, char *err, size_t errlen) {
    uint32_t w = pose->view.width, h = pose->view.height;
    size_t n = (size_t)w * h;
    char path[CAP_PATH_MAX];
    uint16_t *px = malloc(n * 3 * sizeof *px + 1);
    if (!px) {
        lc_set_err(err, errlen, "out of memory for frame %u", k);
        return -1;
    }
    for (size_t i = 0; i < n; i++) {
        double mm = depth[i] * 1000.0;
        px[i] = mm > 0 && mm < 65535.5 ? (uint16_t)lround(mm) : 0;
    }
    snprintf(path, sizeof path, "%s/depth_%05u.png", dir, k);
    if (lc_ref_png_write(path, w, h, 1, 16, px, err, errlen) != 0) goto err;
    double e = 0;
    for (size_t i = 0; i < 3 * n; i++)
        if (rgb[i] > e) e = rgb[i];
    if (!(e > 0) || !isfinite(e)) e = 1.0;
    for (size_t i = 0; i < 3 * n; i++) {
        double x = fmin(fmax(rgb[i] / e, 0.0), 1.0);
        px[i] = srgb8 ? lc_ref_srgb8(x) : (uint16_t)lround(x * 65535.0);
    }
    snprintf(path, sizeof path, "%s/color_%05u.png", dir, k);
    if (lc_ref_png_write(path, w, h, 3, srgb8 ? 8 : 16, px, err, errlen) != 0) goto err;
    free(px);
    px = NULL;
    snprintf(path, sizeof path, "%s/frame_%05u.json", dir, k);
    if (cap_write_json(path, cap_frame_json(k, pose, e, srgb8), err, errlen) != 0) goto err;
    if (exposure_out) *exposure_out = e;
    return 0;
err:
    free(px);
    return -1;
}

int lc_ref_capture_run(lc_ref *r, const char *dir, const lc_ref_capture_pose *poses, uint32_t n,
                       const lc_ref_capture_settings *s, const char *bake, const char *state, char *err,
                       size_t errlen) {
    if (n < 1 || n > LC_REF_CAPTURE_MAX_FRAMES) {
        lc_set_err(err, errlen, "--frames: %u is out of range [1, %u]", n, LC_REF_CAPTURE_MAX_FRAMES);
        return -1;
    }
    if (mkdir(dir, 0755) != 0 && errno != EEXIST) {
        lc_set_err(err, errlen, "--out: cannot create %s: %s", dir, strerror(errno));
        return -1;
    }
    uint32_t w = poses[0].view.width, h = poses[0].view.height;
    if (w < LC_REF_CAPTURE_MIN_SIDE || h < LC_REF_CAPTURE_MIN_SIDE || w > LC_REF_CAPTURE_MAX_SIDE ||
        h > LC_REF_CAPTURE_MAX_SIDE) {
        lc_set_err(err, errlen, "--width/--height: %ux%u is outside the replay format's %u..%u (PROTOCOL.md 8.2)", w, h,
                   LC_REF_CAPTURE_MIN_SIDE, LC_REF_CAPTURE_MAX_SIDE);
        return -1;
    }
    size_t px = (size_t)w * h;
    float *rgb = malloc(px * 3 * sizeof *rgb + 1), *depth = malloc(px * sizeof *depth + 1);
    char path[CAP_PATH_MAX];
    if (!rgb || !depth) {
        lc_set_err(err, errlen, "out of memory for a %ux%u frame", w, h);
        goto err;
    }
    cJSON *j = cJSON_CreateObject(), *src = cJSON_CreateObject();
    cJSON_AddStringToObject(j, "format", LC_REF_CAPTURE_FORMAT);
    cJSON_AddNumberToObject(j, "width", w);
    cJSON_AddNumberToObject(j, "height", h);
    cJSON_AddNumberToObject(j, "frames", n);
    cJSON_AddStringToObject(src, "bake", bake ? bake : "");
    if (state) cJSON_AddStringToObject(src, "state", state);
    else cJSON_AddNullToObject(src, "state");
    cJSON_AddItemToObject(j, "source", src);
    snprintf(path, sizeof path, "%s/capture.json", dir);
    if (cap_write_json(path, j, err, errlen) != 0) goto err;
    double t0 = lc_clock_ms();
    for (uint32_t k = 0; k < n; k++) {
        uint64_t rays = 0;
        double e = 0, t1 = lc_clock_ms();
        if (poses[k].view.width != w || poses[k].view.height != h) {
            lc_set_err(err, errlen, "frame %u: %ux%u, the capture is %ux%u", k + 1, poses[k].view.width,
                       poses[k].view.height, w, h);
            goto err;
        }
        if (lc_ref_rgbd_render(r, &poses[k].view, s, k, rgb, depth, &rays, err, errlen) != 0) goto err;
        if (lc_ref_capture_write_frame(dir, k + 1, &poses[k], rgb, depth, s->srgb8, &e, err, errlen) != 0) goto err;
        if (!s->quiet) {
            double ms = lc_clock_ms() - t1, all = lc_clock_ms() - t0;
            fprintf(stderr, "lucent-ref: capture frame %u/%u: %.2f s, %.2f Mrays/s, exposure %.5g; %.0f s left\n",
                    k + 1, n, ms / 1000, ms > 0 ? rays / ms / 1000 : 0, e, all / (k + 1) * (n - k - 1) / 1000);
        }
    }
    free(rgb);
    free(depth);
    return 0;
err:
    free(rgb);
    free(depth);
    return -1;
}

/* --- poses ---------------------------------------------------------------------------------------- */

/* A JSON array of exactly n finite numbers into out; returns 0 or -1. */
static int cap_json_vec(const cJSON *a, int n, double *out) {
    if (!cJSON_IsArray(a) || cJSON_GetArraySize(a) != n) return -1;
    for (int k = 0; k < n; k++) {
        const cJSON *e = cJSON_GetArrayItem(a, k);
        if (!cJSON_IsNumber(e) || !isfinite(e->valuedouble) || fabs(e->valuedouble) > 1e9) return -1;
        out[k] = e->valuedouble;
    }
    return 0;
}

/* One PATH.json frame into *pose. */
static int cap_path_frame(const char *path, uint32_t k, const cJSON *fr, const lc_ref_camera *tmpl,
                          lc_ref_capture_pose *pose, char *err, size_t errlen) {
    lc_ref_camera cam = *tmpl;
    const char *names[3] = {"eye", "target", "up"};
    float *dst[3] = {cam.eye, cam.target, cam.up};
    for (int f = 0; f < 3; f++) {
        const cJSON *a = cJSON_GetObjectItemCaseSensitive(fr, names[f]);
        double v[3];
        if (!a && f == 2) continue;
        if (cap_json_vec(a, 3, v) != 0) {
            lc_set_err(err, errlen, "%s: /frames/%u/%s: %s", path, k, names[f],
                       a ? "not an array of 3 finite numbers" : "required");
            return -1;
        }
        for (int q = 0; q < 3; q++) dst[f][q] = (float)v[q];
    }
    char e2[256];
    if (lc_ref_rgbd_lookat(&cam, &pose->view, e2, sizeof e2) != 0) {
        lc_set_err(err, errlen, "%s: /frames/%u: %s", path, k, e2);
        return -1;
    }
    pose->time_us = (uint64_t)k * 100000u;
    const cJSON *t = cJSON_GetObjectItemCaseSensitive(fr, "time_us");
    if (t) {
        if (!cJSON_IsNumber(t) || !(t->valuedouble >= 0) || t->valuedouble > 9e15 ||
            t->valuedouble != floor(t->valuedouble)) {
            lc_set_err(err, errlen, "%s: /frames/%u/time_us: not an integer >= 0", path, k);
            return -1;
        }
        pose->time_us = (uint64_t)t->valuedouble;
    }
    return 0;
}

int lc_ref_capture_path_load(const char *path, const lc_ref_camera *tmpl, lc_ref_capture_pose **out, uint32_t *n,
                             char *err, size_t errlen) {
    *out = NULL;
    *n = 0;
    size_t len = 0;
    char *text = lc_fs_read(path, CAP_JSON_MAX * 16, &len, err, errlen);
    if (!text) return -1;
    cJSON *root = cJSON_ParseWithLength(text, len);
    free(text);
    const cJSON *frames = root ? cJSON_GetObjectItemCaseSensitive(root, "frames") : NULL;
    int count = cJSON_IsArray(frames) ? cJSON_GetArraySize(frames) : -1;
    if (!root || count < 1 || count > (int)LC_REF_CAPTURE_MAX_FRAMES) {
        lc_set_err(err, errlen, "%s: %s", path,
                   !root ? "not JSON"
                         : "/frames: required, an array of 1 to 99999 frames {\"eye\", \"target\", \"up\"?, "
                           "\"time_us\"?}");
        cJSON_Delete(root);
        return -1;
    }
    *out = calloc((size_t)count, sizeof **out);
    if (!*out) {
        lc_set_err(err, errlen, "%s: out of memory", path);
        cJSON_Delete(root);
        return -1;
    }
    for (int k = 0; k < count; k++)
        if (cap_path_frame(path, (uint32_t)k, cJSON_GetArrayItem(frames, k), tmpl, *out + k, err, errlen) != 0) {
            free(*out);
            *out = NULL;
            cJSON_Delete(root);
            return -1;
        }
    cJSON_Delete(root);
    *n = (uint32_t)count;
    return 0;
}

/* Quaternion product a * b (x, y, z, w). */
static void cap_qmul(const double a[4], const double b[4], double o[4]) {
    o[0] = a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1];
    o[1] = a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0];
    o[2] = a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3];
    o[3] = a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2];
}

void lc_ref_capture_jitter(const lc_ref_rgbd_view *base, uint32_t n, double jitter_mm, double jitter_deg, uint64_t seed,
                           lc_ref_capture_pose *out) {
    lc_rng rng = lc_rng_seed(seed, 0x717E500000000000ull);
    for (uint32_t k = 0; k < n; k++) {
        lc_ref_capture_pose *p = &out[k];
        p->view = *base;
        p->time_us = (uint64_t)k * 100000u;
        for (int q = 0; q < 3; q++) p->view.translation[q] += (2.0 * lc_rng_float(&rng) - 1.0) * jitter_mm * 1e-3;
        double z = 2.0 * lc_rng_float(&rng) - 1.0, phi = 2.0 * M_PI * lc_rng_float(&rng), s = sqrt(fmax(0, 1 - z * z));
        double angle = (2.0 * lc_rng_float(&rng) - 1.0) * jitter_deg * M_PI / 180.0;
        double h = sin(angle / 2), turn[4] = {s * cos(phi) * h, s * sin(phi) * h, z * h, cos(angle / 2)}, q[4], m[9];
        cap_qmul(turn, base->rotation, q); /* turned in world space, about the camera's position */
        lc_ref_quat_matrix(q, m);
        lc_ref_matrix_quat(m, p->view.rotation);
    }
}

/* --- reading ------------------------------------------------------------------------------------- */

static cJSON *cap_read_json(const char *path, char *err, size_t errlen) {
    size_t len = 0;
    char *text = lc_fs_read(path, CAP_JSON_MAX, &len, err, errlen);
    if (!text) return NULL;
    cJSON *j = cJSON_ParseWithLength(text, len);
    free(text);
    if (!j || !cJSON_IsObject(j)) {
        lc_set_err(err, errlen, "%s: not a JSON object", path);
        cJSON_Delete(j);
        return NULL;
    }
    return j;
}

/* A number field (by JSON pointer parts) within [lo, hi]; -1 with err naming it. */
static int cap_num(const char *path, const cJSON *obj, const char *parent, const char *name, double lo, double hi,
                   double *out, char *err, size_t errlen) {
    const cJSON *e = obj ? cJSON_GetObjectItemCaseSensitive(obj, name) : NULL;
    if (!cJSON_IsNumber(e) || !(e->valuedouble >= lo && e->valuedouble <= hi)) {
        lc_set_err(err, errlen, "%s: %s/%s: %s", path, parent, name, e ? "not a number in range" : "required");
        return -1;
    }
    *out = e->valuedouble;
    return 0;
}

/* capture.json: the format, size and frame count; k must be one of the frames. */
static int cap_read_header(const char *dir, uint32_t k, uint32_t *w, uint32_t *h, char *err, size_t errlen) {
    char path[CAP_PATH_MAX];
    snprintf(path, sizeof path, "%s/capture.json", dir);
    cJSON *j = cap_read_json(path, err, errlen);
    if (!j) return -1;
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(j, "format");
    double dw, dh, df;
    int rc = -1;
    if (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, LC_REF_CAPTURE_FORMAT) != 0) {
        lc_set_err(err, errlen, "%s: /format: not \"%s\"", path, LC_REF_CAPTURE_FORMAT);
        goto done;
    }
    if (cap_num(path, j, "", "width", 1, LC_REF_CAMERA_MAX_SIDE, &dw, err, errlen) != 0 ||
        cap_num(path, j, "", "height", 1, LC_REF_CAMERA_MAX_SIDE, &dh, err, errlen) != 0 ||
        cap_num(path, j, "", "frames", 1, LC_REF_CAPTURE_MAX_FRAMES, &df, err, errlen) != 0)
        goto done;
    if (k < 1 || k > (uint32_t)df) {
        lc_set_err(err, errlen, "--frame: %u is not a frame of %s (1..%u)", k, dir, (uint32_t)df);
        goto done;
    }
    *w = (uint32_t)dw, *h = (uint32_t)dh;
    rc = 0;
done:
    cJSON_Delete(j);
    return rc;
}

/* frame_K.json into out (no images). */
static int cap_read_frame_json(const char *path, lc_ref_capture_frame *out, char *err, size_t errlen) {
    cJSON *j = cap_read_json(path, err, errlen);
    if (!j) return -1;
    lc_ref_rgbd_view *v = &out->view;
    const cJSON *in = cJSON_GetObjectItemCaseSensitive(j, "intrinsics");
    const cJSON *po = cJSON_GetObjectItemCaseSensitive(j, "pose");
    const cJSON *col = cJSON_GetObjectItemCaseSensitive(j, "color");
    double seq, t;
    int rc = -1;
    if (cap_num(path, j, "", "sequence", 1, 4294967295.0, &seq, err, errlen) != 0 ||
        cap_num(path, j, "", "time_us", 0, 9e15, &t, err, errlen) != 0 ||
        cap_num(path, in, "/intrinsics", "fx", 1e-9, 1e5, &v->fx, err, errlen) != 0 ||
        cap_num(path, in, "/intrinsics", "fy", 1e-9, 1e5, &v->fy, err, errlen) != 0 ||
        cap_num(path, in, "/intrinsics", "cx", -2.0 * v->width, 2.0 * v->width, &v->cx, err, errlen) != 0 ||
        cap_num(path, in, "/intrinsics", "cy", -2.0 * v->height, 2.0 * v->height, &v->cy, err, errlen) != 0 ||
        cap_num(path, j, "", "exposure", 1e-30, 1e7, &out->exposure, err, errlen) != 0)
        goto done;
    if (cap_json_vec(po ? cJSON_GetObjectItemCaseSensitive(po, "translation") : NULL, 3, v->translation) != 0 ||
        cap_json_vec(po ? cJSON_GetObjectItemCaseSensitive(po, "rotation") : NULL, 4, v->rotation) != 0) {
        lc_set_err(err, errlen, "%s: /pose: needs translation [3] and rotation [x, y, z, w], finite numbers", path);
        goto done;
    }
    double qn = sqrt(v->rotation[0] * v->rotation[0] + v->rotation[1] * v->rotation[1] +
                     v->rotation[2] * v->rotation[2] + v->rotation[3] * v->rotation[3]);
    if (!(qn >= 0.9 && qn <= 1.1)) {
        lc_set_err(err, errlen, "%s: /pose/rotation: norm %g is not a unit quaternion", path, qn);
        goto done;
    }
    if (!cJSON_IsString(col) || (strcmp(col->valuestring, "linear16") && strcmp(col->valuestring, "srgb8"))) {
        lc_set_err(err, errlen, "%s: /color: not \"linear16\" or \"srgb8\"", path);
        goto done;
    }
    out->srgb8 = !strcmp(col->valuestring, "srgb8");
    out->sequence = (uint32_t)seq;
    out->time_us = (uint64_t)t;
    rc = 0;
done:
    cJSON_Delete(j);
    return rc;
}

int lc_ref_capture_read_frame(const char *dir, uint32_t k, lc_ref_capture_frame *out, char *err, size_t errlen) {
    memset(out, 0, sizeof *out);
    char path[CAP_PATH_MAX];
    uint16_t *px = NULL;
    uint32_t w, h, pw, ph;
    int ch, bits;
    if (cap_read_header(dir, k, &w, &h, err, errlen) != 0) return -1;
    out->view.width = w, out->view.height = h;
    snprintf(path, sizeof path, "%s/frame_%05u.json", dir, k);
    if (cap_read_frame_json(path, out, err, errlen) != 0) goto err;
    snprintf(path, sizeof path, "%s/depth_%05u.png", dir, k);
    if (lc_ref_png_read(path, LC_REF_CAMERA_MAX_SIDE, &pw, &ph, &ch, &bits, &out->depth_mm, err, errlen) != 0) goto err;
    if (pw != w || ph != h || ch != 1 || bits != 16) {
        lc_set_err(err, errlen, "%s: %ux%u, %d channels, %d bits; want %ux%u 16-bit grey", path, pw, ph, ch, bits, w,
                   h);
        goto err;
    }
    snprintf(path, sizeof path, "%s/color_%05u.png", dir, k);
    if (lc_ref_png_read(path, LC_REF_CAMERA_MAX_SIDE, &pw, &ph, &ch, &bits, &px, err, errlen) != 0) goto err;
    if (pw != w || ph != h || ch != 3 || bits != (out->srgb8 ? 8 : 16)) {
        lc_set_err(err, errlen, "%s: %ux%u, %d channels, %d bits; want %ux%u RGB, %d bits (\"color\": %s)", path, pw,
                   ph, ch, bits, w, h, out->srgb8 ? 8 : 16, out->srgb8 ? "srgb8" : "linear16");
        goto err;
    }
    size_t n = (size_t)w * h * 3;
    out->rgb = malloc(n * sizeof *out->rgb);
    if (!out->rgb) {
        lc_set_err(err, errlen, "%s: out of memory", path);
        goto err;
    }
    for (size_t i = 0; i < n; i++)
        out->rgb[i] = (float)((out->srgb8 ? lc_ref_srgb_eotf(px[i] / 255.0) : px[i] / 65535.0) * out->exposure);
    free(px);
    return 0;
err:
    free(px);
    lc_ref_capture_frame_free(out);
    return -1;
}

void lc_ref_capture_frame_free(lc_ref_capture_frame *f) {
    if (!f) return;
    free(f->depth_mm);
    free(f->rgb);
    f->depth_mm = NULL;
    f->rgb = NULL;
}
