/* mr: the LightSkin computation on the CPU (see mr.h). */
#include "engine/mr.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gpu/mr_gl.h"
#include "util/clock.h"
#include "util/parallel.h"
#include "util/sh.h"

#define MR_LANES 16
#define MR_PI 3.14159265358979f
#define MR_FILTER_MAX_RADIUS 8
#define MR_PIX 10 /* per-pixel light scratch: position, normal, area, radiosity */

/* The gather's AVX2 clone is picked at load time (as transport_cpu.c); the TSan build keeps one
 * plain version (its runtime is not up when the ifunc resolver runs). */
#if defined(__SANITIZE_THREAD__)
#define MR_CLONES
#else
#define MR_CLONES __attribute__((target_clones("avx2", "default")))
#endif
/* clang (the fuzz build) refuses noinline on a multiversioned function. */
#if defined(__clang__)
#define MR_CLONES_NOINLINE MR_CLONES
#else
#define MR_CLONES_NOINLINE MR_CLONES __attribute__((noinline))
#endif

/* Light arrays (structure of arrays), padded with zero lights to a multiple of LC_MR_TILE. */
enum { MR_PX, MR_PY, MR_PZ, MR_NX, MR_NY, MR_NZ, MR_R2, MR_BR, MR_BG, MR_BB, MR_EPS, MR_SOA };

/* Gather accumulators, per lane. */
enum {
    A_EDR,
    A_EDG,
    A_EDB,
    A_WD,
    A_LDX,
    A_LDY,
    A_LDZ,
    A_MDX,
    A_MDY,
    A_MDZ,
    A_ESR,
    A_ESG,
    A_ESB,
    A_WS,
    A_LSX,
    A_LSY,
    A_LSZ,
    A_MSX,
    A_MSY,
    A_MSZ,
    MR_ACC
};

typedef struct {
    float x[3], n[3], v[3], nv; /* position, normal, unit direction to the camera, n.v */
    float radius;
    uint32_t object;
} mr_pt;

typedef struct {
    float e_d[3], l_d[3], rad_d, e_s[3], l_s[3], rad_s;
} mr_gathered;

struct lc_mr {
    int threads;
    lc_mr_params p;
    lc_mr_camera cam;
    float rot[9];
    /* frame scratch, w*h */
    size_t pix_cap;
    float *depth_in, *depth, *pix;
    uint8_t *pvalid;
    /* lights */
    uint32_t n_lights, light_cap;
    float *soa[MR_SOA];
    /* compute scratch */
    uint32_t pt_cap;
    mr_pt *pts;
    mr_gathered *g;
    float *occ; /* 2 per point */
    /* smoothing history */
    int hist_valid, hist_sh_valid;
    uint32_t hist_n, hist_objects, obj_cap;
    float *hist_pt; /* 12 per point: e_d, l_d, e_s, l_s */
    float *hist_sh; /* 27 per object */
    float hist_t[3], hist_q[4];
    lc_mr_timings t;
    /* GL gather (lc_mr_set_gl): not owned; gl_dirty: the lights changed since their upload */
    lc_mr_gl *gl;
    int gl_dirty;
    size_t gl_cap; /* points in gl_buf */
    float *gl_buf; /* LC_MR_GL_POINT + LC_MR_GL_SUMS floats per point */
};

static int mr_fail(char *err, size_t errlen, const char *fmt, ...) {
    if (err && errlen) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err, errlen, fmt, ap);
        va_end(ap);
    }
    return -1;
}

lc_mr_params lc_mr_params_default(void) {
    lc_mr_params p = {.max_lights = LC_MR_DEFAULT_MAX_LIGHTS,
                      .sigma_px = 1.5f,
                      .sigma_depth = 0.03f,
                      .min_confidence = 0.5f,
                      .grazing_cos = 0.0871557427f, /* cos 85 deg */
                      .depth_edge = 0.1f,
                      .spec_exponent = 16.0f,
                      .smoothing = 0.0f,
                      .glossy = 1,
                      .occlusion = 1,
                      .self_occlusion = 1,
                      .filter = 1};
    return p;
}

lc_mr *lc_mr_create(int threads) {
    lc_mr *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    m->threads = threads;
    m->p = lc_mr_params_default();
    return m;
}

void lc_mr_release(lc_mr *m) {
    if (!m) return;
    free(m->depth_in);
    free(m->depth);
    free(m->pix);
    free(m->pvalid);
    free(m->soa[0]);
    free(m->pts);
    free(m->g);
    free(m->occ);
    free(m->hist_pt);
    free(m->hist_sh);
    free(m->gl_buf);
    free(m);
}

void lc_mr_reset_history(lc_mr *m) { m->hist_valid = 0; }

void lc_mr_set_gl(lc_mr *m, lc_mr_gl *g) {
    m->gl = g;
    m->gl_dirty = 1;
}

uint32_t lc_mr_light_count(const lc_mr *m) { return m->n_lights; }

lc_mr_lights_view lc_mr_lights(const lc_mr *m) {
    lc_mr_lights_view v = {.count = m->n_lights};
    if (!m->soa[0]) return v;
    v.px = m->soa[MR_PX], v.py = m->soa[MR_PY], v.pz = m->soa[MR_PZ];
    v.nx = m->soa[MR_NX], v.ny = m->soa[MR_NY], v.nz = m->soa[MR_NZ];
    v.r2 = m->soa[MR_R2], v.br = m->soa[MR_BR], v.bg = m->soa[MR_BG], v.bb = m->soa[MR_BB];
    return v;
}

void lc_mr_stats(const lc_mr *m, lc_mr_timings *out) { *out = m->t; }

float lc_mr_disc_form_factor(const float x[3], const float n[3], const float l[3], const float nl[3], float r2) {
    float d[3] = {l[0] - x[0], l[1] - x[1], l[2] - x[2]};
    float d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    if (!(d2 > 0.0f)) return 0.0f;
    float inv = 1.0f / sqrtf(d2);
    float ci = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]) * inv;
    float cj = -(nl[0] * d[0] + nl[1] * d[1] + nl[2] * d[2]) * inv;
    if (!(ci > 0.0f) || !(cj > 0.0f)) return 0.0f;
    return r2 * cj / (r2 + d2) * ci;
}

/* --- parameters and camera ------------------------------------------------------------ */

static int mr_check_params(const lc_mr_params *p, char *err, size_t errlen) {
    if (p->max_lights < 1 || p->max_lights > LC_MR_MAX_LIGHTS)
        return mr_fail(err, errlen, "params/max_lights: %u not in 1..%u", p->max_lights, LC_MR_MAX_LIGHTS);
    if (!(p->sigma_px > 0.0f && p->sigma_px <= 4.0f))
        return mr_fail(err, errlen, "params/sigma_px: %g not in (0, 4]", p->sigma_px);
    if (!(p->sigma_depth > 0.0f && p->sigma_depth <= 1.0f))
        return mr_fail(err, errlen, "params/sigma_depth: %g not in (0, 1]", p->sigma_depth);
    if (!(p->min_confidence >= 0.0f && p->min_confidence <= 1.0f))
        return mr_fail(err, errlen, "params/min_confidence: %g not in [0, 1]", p->min_confidence);
    if (!(p->grazing_cos >= 0.0f && p->grazing_cos < 1.0f))
        return mr_fail(err, errlen, "params/grazing_cos: %g not in [0, 1)", p->grazing_cos);
    if (!(p->depth_edge > 0.0f && p->depth_edge <= 10.0f))
        return mr_fail(err, errlen, "params/depth_edge: %g not in (0, 10]", p->depth_edge);
    if (!(p->spec_exponent >= 1.0f && p->spec_exponent <= 10000.0f))
        return mr_fail(err, errlen, "params/spec_exponent: %g not in [1, 10000]", p->spec_exponent);
    if (!(p->smoothing >= 0.0f && p->smoothing <= 0.99f))
        return mr_fail(err, errlen, "params/smoothing: %g not in [0, 0.99]", p->smoothing);
    return 0;
}

/* The pose (and, with intrinsics, the rest): checked, the quaternion normalised, m->rot set. */
static int mr_set_camera(lc_mr *m, const lc_mr_camera *c, int intrinsics, char *err, size_t errlen) {
    if (intrinsics) {
        if (c->width < 1 || c->width > LC_MR_MAX_DIM || c->height < 1 || c->height > LC_MR_MAX_DIM ||
            (size_t)c->width * c->height > LC_MR_MAX_PIXELS)
            return mr_fail(err, errlen, "camera/width: %ux%u not within %u per side, %u pixels", c->width, c->height,
                           LC_MR_MAX_DIM, LC_MR_MAX_PIXELS);
        if (!(c->fx > 0.0f && c->fx <= 1e5f)) return mr_fail(err, errlen, "camera/fx: %g not in (0, 1e5]", c->fx);
        if (!(c->fy > 0.0f && c->fy <= 1e5f)) return mr_fail(err, errlen, "camera/fy: %g not in (0, 1e5]", c->fy);
        if (!isfinite(c->cx)) return mr_fail(err, errlen, "camera/cx: not finite");
        if (!isfinite(c->cy)) return mr_fail(err, errlen, "camera/cy: not finite");
    }
    for (int i = 0; i < 3; i++)
        if (!(fabsf(c->translation[i]) <= 1e6f)) return mr_fail(err, errlen, "camera/translation/%d: not finite", i);
    const float *q = c->rotation;
    double nq = sqrt((double)q[0] * q[0] + (double)q[1] * q[1] + (double)q[2] * q[2] + (double)q[3] * q[3]);
    if (!(nq >= 0.5 && nq <= 2.0)) return mr_fail(err, errlen, "camera/rotation: norm %g not in [0.5, 2]", nq);
    m->cam = *c;
    double x = q[0] / nq, y = q[1] / nq, z = q[2] / nq, w = q[3] / nq;
    m->cam.rotation[0] = (float)x, m->cam.rotation[1] = (float)y;
    m->cam.rotation[2] = (float)z, m->cam.rotation[3] = (float)w;
    double r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),     2 * (x * z + y * w),
                   2 * (x * y + z * w),     1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                   2 * (x * z - y * w),     2 * (y * z + x * w),     1 - 2 * (x * x + y * y)};
    for (int i = 0; i < 9; i++) m->rot[i] = (float)r[i];
    return 0;
}

/* Light arrays for n lights (padded); the contents are undefined. */
static int mr_reserve_lights(lc_mr *m, uint32_t n) {
    uint32_t padded = (n + LC_MR_TILE - 1) / LC_MR_TILE * LC_MR_TILE;
    if (padded == 0) padded = LC_MR_TILE;
    if (padded > m->light_cap) {
        float *block = malloc((size_t)padded * MR_SOA * sizeof(float));
        if (!block) return -1;
        free(m->soa[0]);
        for (int k = 0; k < MR_SOA; k++) m->soa[k] = block + (size_t)k * padded;
        m->light_cap = padded;
    }
    return 0;
}

/* Zero lights from n_lights up to the tile boundary (they add nothing, not even eps). */
static void mr_pad_lights(lc_mr *m) {
    uint32_t padded = (m->n_lights + LC_MR_TILE - 1) / LC_MR_TILE * LC_MR_TILE;
    for (int k = 0; k < MR_SOA; k++)
        for (uint32_t j = m->n_lights; j < padded; j++) m->soa[k][j] = 0.0f;
}

static void mr_put_light(lc_mr *m, uint32_t j, const float p[3], const float n[3], float area, const float b[3]) {
    m->soa[MR_PX][j] = p[0], m->soa[MR_PY][j] = p[1], m->soa[MR_PZ][j] = p[2];
    m->soa[MR_NX][j] = n[0], m->soa[MR_NY][j] = n[1], m->soa[MR_NZ][j] = n[2];
    m->soa[MR_R2][j] = area / MR_PI;
    m->soa[MR_BR][j] = b[0], m->soa[MR_BG][j] = b[1], m->soa[MR_BB][j] = b[2];
    m->soa[MR_EPS][j] = LC_MR_EPSILON;
}

/* --- fast powers (vectorisable: no libm calls in the hot loops) ------------------------ */

/* 2^y for y <= 0 (0 below -126); relative error ~2e-7. */
static inline float mr_exp2_neg(float y) {
    float yc = y > -126.0f ? y : -126.0f;
    int32_t ip = (int32_t)(yc - 0.5f); /* about round(yc): f in [-0.5, 0.5] */
    float f = yc - (float)ip;
    float z = f * 0.693147181f;
    float p = 1.0f +
        z * (1.0f + z * (0.5f + z * (0.166666667f + z * (0.0416666667f + z * (0.00833333333f + z * 0.00138888889f)))));
    union {
        float f;
        int32_t i;
    } r;
    r.i = (ip + 127) * (1 << 23);
    return p * r.f * (float)(y >= -126.0f);
}

/* c^k for c in (0, 1], k >= 1: 2^(k log2 c), log2 by its atanh series on [sqrt 1/2, sqrt 2). */
static inline float mr_pow01(float c, float k) {
    union {
        float f;
        int32_t i;
    } u = {c};
    int32_t e = ((u.i >> 23) & 0xff) - 127;
    u.i = (u.i & 0x007fffff) | 0x3f800000;
    float mant = u.f;
    int32_t big = mant > 1.41421356f; /* arithmetic, not selects: those left branches in the AVX2 clone */
    mant *= 1.0f - 0.5f * (float)big;
    e += big;
    float t = (mant - 1.0f) / (mant + 1.0f), t2 = t * t;
    float lg = (float)e +
        t * (2.88539008f + t2 * (0.961796694f + t2 * (0.577078016f + t2 * (0.412198583f + t2 * 0.320598898f))));
    float y = k * lg;
    return mr_exp2_neg(y < 0.0f ? y : 0.0f);
}

/* gc[i] = gc[i]^k over one block of lanes (kept out of line: inlined into the gather, jump
 * threading on the clamp's constants left branches that kept the AVX2 clone scalar). */
MR_CLONES_NOINLINE static void mr_pow_lanes(float *restrict gc, float k) {
    for (size_t i = 0; i < MR_LANES; i++) gc[i] = mr_pow01(gc[i], k);
}

/* --- 1. depth filter --------------------------------------------------------------------- */

typedef struct {
    const lc_mr *m;
    int radius;
    float spatial[(2 * MR_FILTER_MAX_RADIUS + 1) * (2 * MR_FILTER_MAX_RADIUS + 1)];
} mr_filter_job;

static void mr_filter_rows(void *ctx, size_t y0, size_t y1, int thread) {
    (void)thread;
    const mr_filter_job *job = ctx;
    const lc_mr *m = job->m;
    const int w = (int)m->cam.width, h = (int)m->cam.height, r = job->radius, side = 2 * r + 1;
    const float inv_s = 1.0f / (2.0f * m->p.sigma_depth * m->p.sigma_depth);
    for (int y = (int)y0; y < (int)y1; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            float z = m->depth_in[i];
            if (!(z > 0.0f)) {
                m->depth[i] = 0.0f;
                continue;
            }
            float k = -1.44269504f * inv_s / (z * z); /* log2(e) / (2 (s z)^2), negated */
            double ws = 0.0, zs = 0.0;
            for (int dy = -r; dy <= r; dy++) {
                int yy = y + dy;
                if (yy < 0 || yy >= h) continue;
                const float *row = m->depth_in + (size_t)yy * w;
                const float *sp = job->spatial + (size_t)(dy + r) * side + r;
                int xa = x - r < 0 ? -x : -r, xb = x + r >= w ? w - 1 - x : r;
                float wsum = 0.0f, zsum = 0.0f;
                for (int dx = xa; dx <= xb; dx++) {
                    float q = row[x + dx], dz = q - z;
                    float wt = q > 0.0f ? sp[dx] * mr_exp2_neg(k * dz * dz) : 0.0f;
                    wsum += wt;
                    zsum += wt * q;
                }
                ws += wsum;
                zs += zsum;
            }
            m->depth[i] = (float)(zs / ws);
        }
}

/* depth_in (validity applied) -> depth. */
static void mr_filter(lc_mr *m) {
    size_t n = (size_t)m->cam.width * m->cam.height;
    if (!m->p.filter) {
        memcpy(m->depth, m->depth_in, n * sizeof(float));
        return;
    }
    mr_filter_job job = {.m = m};
    int r = (int)ceilf(2.0f * m->p.sigma_px);
    job.radius = r > MR_FILTER_MAX_RADIUS ? MR_FILTER_MAX_RADIUS : r;
    int side = 2 * job.radius + 1;
    for (int dy = -job.radius; dy <= job.radius; dy++)
        for (int dx = -job.radius; dx <= job.radius; dx++)
            job.spatial[(dy + job.radius) * side + dx + job.radius] =
                expf(-(float)(dx * dx + dy * dy) / (2.0f * m->p.sigma_px * m->p.sigma_px));
    lc_parallel_for(m->threads, m->cam.height, 8, mr_filter_rows, &job);
}

/* --- 2. lights --------------------------------------------------------------------------- */

typedef struct {
    lc_mr *m;
    const float *radiance;
} mr_pixel_job;

/* Camera-space position of pixel (x, y) at depth z. */
static inline void mr_unproject(const lc_mr_camera *c, int x, int y, float z, float p[3]) {
    p[0] = ((float)x + 0.5f - c->cx) * z / c->fx;
    p[1] = -((float)y + 0.5f - c->cy) * z / c->fy;
    p[2] = -z;
}

/* The derivative of the camera-space position along one axis at pixel i from its neighbours
 * a (x-1 or y-1) and b (x+1 or y+1), -1 when neither is continuous. */
static int mr_derivative(const lc_mr *m, int x, int y, int ax, int ay, float z, const float p[3], float d[3]) {
    const int w = (int)m->cam.width, h = (int)m->cam.height;
    float pa[3], pb[3];
    int have_a = 0, have_b = 0;
    int xa = x - ax, ya = y - ay, xb = x + ax, yb = y + ay;
    float tol = m->p.depth_edge * z;
    if (xa >= 0 && ya >= 0) {
        float za = m->depth[(size_t)ya * w + xa];
        if (za > 0.0f && fabsf(za - z) <= tol) have_a = 1, mr_unproject(&m->cam, xa, ya, za, pa);
    }
    if (xb < w && yb < h) {
        float zb = m->depth[(size_t)yb * w + xb];
        if (zb > 0.0f && fabsf(zb - z) <= tol) have_b = 1, mr_unproject(&m->cam, xb, yb, zb, pb);
    }
    if (!have_a && !have_b) return -1;
    const float *lo = have_a ? pa : p, *hi = have_b ? pb : p;
    for (int k = 0; k < 3; k++) d[k] = hi[k] - lo[k];
    return 0;
}

static void mr_pixel_rows(void *ctx, size_t y0, size_t y1, int thread) {
    (void)thread;
    const mr_pixel_job *job = ctx;
    lc_mr *m = job->m;
    const lc_mr_camera *c = &m->cam;
    const int w = (int)c->width;
    const float *R = m->rot;
    for (int y = (int)y0; y < (int)y1; y++)
        for (int x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            m->pvalid[i] = 0;
            float z = m->depth[i];
            if (!(z > 0.0f)) continue;
            const float *rad = job->radiance + 3 * i;
            if (!isfinite(rad[0]) || !isfinite(rad[1]) || !isfinite(rad[2])) continue;
            float p[3], dx[3], dy[3];
            mr_unproject(c, x, y, z, p);
            if (mr_derivative(m, x, y, 1, 0, z, p, dx) || mr_derivative(m, x, y, 0, 1, z, p, dy)) continue;
            float n[3] = {dx[1] * dy[2] - dx[2] * dy[1], dx[2] * dy[0] - dx[0] * dy[2], dx[0] * dy[1] - dx[1] * dy[0]};
            float nl = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            if (!(nl > 0.0f)) continue;
            float np = (n[0] * p[0] + n[1] * p[1] + n[2] * p[2]) / nl; /* n . P, n unit */
            float sign = np > 0.0f ? -1.0f : 1.0f;                     /* face the camera: n . P < 0 */
            for (int k = 0; k < 3; k++) n[k] *= sign / nl;
            float plen = sqrtf(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
            float anp = fabsf(np);
            if (anp < m->p.grazing_cos * plen) continue;
            float *o = m->pix + MR_PIX * i;
            for (int k = 0; k < 3; k++) {
                o[k] = R[3 * k] * p[0] + R[3 * k + 1] * p[1] + R[3 * k + 2] * p[2] + c->translation[k];
                o[3 + k] = R[3 * k] * n[0] + R[3 * k + 1] * n[1] + R[3 * k + 2] * n[2];
                o[7 + k] = MR_PI * (rad[k] > 0.0f ? rad[k] : 0.0f);
            }
            o[6] = z * z * z / (c->fx * c->fy * anp);
            m->pvalid[i] = 1;
        }
}

/* Pixels -> lights: one each (b = 1) or area-weighted b x b blocks. */
static void mr_collect_lights(lc_mr *m, uint32_t b) {
    const uint32_t w = m->cam.width, h = m->cam.height;
    uint32_t n = 0, valid = 0;
    for (uint32_t by = 0; by < h; by += b)
        for (uint32_t bx = 0; bx < w; bx += b) {
            double s[MR_PIX] = {0};
            uint32_t cnt = 0;
            for (uint32_t y = by; y < by + b && y < h; y++)
                for (uint32_t x = bx; x < bx + b && x < w; x++) {
                    size_t i = (size_t)y * w + x;
                    if (!m->pvalid[i]) continue;
                    const float *o = m->pix + MR_PIX * i;
                    double a = o[6];
                    for (int k = 0; k < 6; k++) s[k] += a * o[k];
                    s[6] += a;
                    for (int k = 7; k < 10; k++) s[k] += a * o[k];
                    cnt++;
                }
            valid += cnt;
            if (cnt == 0 || !(s[6] > 0.0)) continue;
            double nl = sqrt(s[3] * s[3] + s[4] * s[4] + s[5] * s[5]);
            if (!(nl > 1e-6 * s[6])) continue; /* normals cancelling out: no usable disc */
            float pos[3], nrm[3], rad[3];
            for (int k = 0; k < 3; k++) {
                pos[k] = (float)(s[k] / s[6]);
                nrm[k] = (float)(s[3 + k] / nl);
                rad[k] = (float)(s[7 + k] / s[6]);
            }
            mr_put_light(m, n++, pos, nrm, (float)s[6], rad);
        }
    m->n_lights = n;
    m->t.valid_pixels = valid;
}

static int mr_reserve_pixels(lc_mr *m, size_t n) {
    if (n <= m->pix_cap) return 0;
    float *a = malloc(n * sizeof(float)), *b = malloc(n * sizeof(float)), *c = malloc(n * MR_PIX * sizeof(float));
    uint8_t *v = malloc(n);
    if (!a || !b || !c || !v) goto err;
    free(m->depth_in);
    free(m->depth);
    free(m->pix);
    free(m->pvalid);
    m->depth_in = a, m->depth = b, m->pix = c, m->pvalid = v;
    m->pix_cap = n;
    return 0;
err:
    free(a);
    free(b);
    free(c);
    free(v);
    return -1;
}

int lc_mr_set_frame(lc_mr *m, const lc_mr_camera *cam, const float *depth_m, const float *radiance_rgb,
                    const float *confidence, const lc_mr_params *p, char *err, size_t errlen) {
    m->n_lights = 0;
    m->gl_dirty = 1;
    if (!cam || !depth_m || !radiance_rgb || !p)
        return mr_fail(err, errlen, "frame: missing camera, depth or radiance");
    if (mr_check_params(p, err, errlen) || mr_set_camera(m, cam, 1, err, errlen)) return -1;
    m->p = *p;
    const uint32_t w = cam->width, h = cam->height;
    size_t n = (size_t)w * h;
    if (mr_reserve_pixels(m, n)) return mr_fail(err, errlen, "frame: out of memory for %zu pixels", n);
    double t0 = lc_clock_ms();
    for (size_t i = 0; i < n; i++) {
        float z = depth_m[i];
        int ok = z > 0.0f && z < 1e6f && (!confidence || confidence[i] >= p->min_confidence);
        m->depth_in[i] = ok ? z : 0.0f;
    }
    mr_filter(m);
    double t1 = lc_clock_ms();
    uint32_t b = 1;
    while ((size_t)((w + b - 1) / b) * ((h + b - 1) / b) > p->max_lights) b++;
    uint32_t most = (uint32_t)(((w + b - 1) / b) * ((h + b - 1) / b));
    if (mr_reserve_lights(m, most)) return mr_fail(err, errlen, "frame: out of memory for %u lights", most);
    mr_pixel_job job = {m, radiance_rgb};
    lc_parallel_for(m->threads, h, 8, mr_pixel_rows, &job);
    mr_collect_lights(m, b);
    mr_pad_lights(m);
    m->t.filter_ms = t1 - t0;
    m->t.lights_ms = lc_clock_ms() - t1;
    m->t.lights = m->n_lights;
    m->t.block = b;
    return 0;
}

int lc_mr_set_lights(lc_mr *m, const lc_mr_camera *cam, const lc_mr_light *lights, uint32_t n, const lc_mr_params *p,
                     char *err, size_t errlen) {
    m->n_lights = 0;
    m->gl_dirty = 1;
    if (!cam || !p || (n && !lights)) return mr_fail(err, errlen, "lights: missing camera, params or lights");
    if (mr_check_params(p, err, errlen) || mr_set_camera(m, cam, 0, err, errlen)) return -1;
    if (n > LC_MR_MAX_LIGHTS) return mr_fail(err, errlen, "lights: %u over %u", n, LC_MR_MAX_LIGHTS);
    m->p = *p;
    if (mr_reserve_lights(m, n)) return mr_fail(err, errlen, "lights: out of memory for %u", n);
    for (uint32_t j = 0; j < n; j++) {
        const lc_mr_light *l = &lights[j];
        float nl = sqrtf(l->normal[0] * l->normal[0] + l->normal[1] * l->normal[1] + l->normal[2] * l->normal[2]);
        int finite = 1;
        for (int k = 0; k < 3; k++)
            finite &= fabsf(l->position[k]) <= 1e6f && l->radiosity[k] >= 0.0f && l->radiosity[k] < 1e30f;
        if (!finite) return mr_fail(err, errlen, "lights[%u]: position or radiosity not finite (or negative)", j);
        if (!(nl > 1e-6f && nl < 1e6f)) return mr_fail(err, errlen, "lights[%u]/normal: zero or not finite", j);
        if (!(l->area >= 0.0f && l->area < 1e12f)) return mr_fail(err, errlen, "lights[%u]/area: %g", j, l->area);
        float nrm[3] = {l->normal[0] / nl, l->normal[1] / nl, l->normal[2] / nl};
        mr_put_light(m, j, l->position, nrm, l->area, l->radiosity);
    }
    m->n_lights = n;
    mr_pad_lights(m);
    m->t.filter_ms = 0.0, m->t.lights_ms = 0.0;
    m->t.valid_pixels = 0, m->t.lights = n, m->t.block = 1;
    return 0;
}

/* --- 3. gather ---------------------------------------------------------------------------- */

/* One point against lights [j0, j0 + nj) (nj a multiple of MR_LANES), into per-lane sums. */
static inline __attribute__((always_inline)) void mr_gather_body(float *const *soa, uint32_t j0, uint32_t nj,
                                                                 const mr_pt *p, float k, int glossy,
                                                                 float acc[MR_ACC][MR_LANES]) {
    const float x0 = p->x[0], x1 = p->x[1], x2 = p->x[2], n0 = p->n[0], n1 = p->n[1], n2 = p->n[2];
    const float v0 = p->v[0], v1 = p->v[1], v2 = p->v[2], nv2 = 2.0f * p->nv;
    const float *restrict px = soa[MR_PX] + j0, *restrict py = soa[MR_PY] + j0, *restrict pz = soa[MR_PZ] + j0;
    const float *restrict nx = soa[MR_NX] + j0, *restrict ny = soa[MR_NY] + j0, *restrict nz = soa[MR_NZ] + j0;
    const float *restrict pr2 = soa[MR_R2] + j0, *restrict peps = soa[MR_EPS] + j0;
    const float *restrict br = soa[MR_BR] + j0, *restrict bg = soa[MR_BG] + j0, *restrict bb = soa[MR_BB] + j0;
    float a[MR_ACC][MR_LANES]; /* a local copy: provably apart from the lights */
    memcpy(a, acc, sizeof a);
    float gw[MR_LANES], gc[MR_LANES];
    for (size_t j = 0; j < nj; j += MR_LANES) {
        for (size_t i = 0; i < MR_LANES; i++) {
            size_t q = j + i;
            float dx = px[q] - x0, dy = py[q] - x1, dz = pz[q] - x2;
            float d2 = dx * dx + dy * dy + dz * dz;
            float inv = 1.0f / sqrtf(d2 > 1e-20f ? d2 : 1e-20f);
            float ci = (n0 * dx + n1 * dy + n2 * dz) * inv;
            float cj = -(nx[q] * dx + ny[q] * dy + nz[q] * dz) * inv;
            float r2 = pr2[q];
            float w = r2 * cj / (r2 + d2);
            int ok = (ci > 0.0f) & (cj > 0.0f);
            float wc = ok ? w * ci : 0.0f;
            float e = peps[q];
            float wd = e + wc;
            a[A_EDR][i] += br[q] * wc;
            a[A_EDG][i] += bg[q] * wc;
            a[A_EDB][i] += bb[q] * wc;
            a[A_WD][i] += wd;
            a[A_LDX][i] += wd * dx;
            a[A_LDY][i] += wd * dy;
            a[A_LDZ][i] += wd * dz;
            a[A_MDX][i] += wd * dx * dx;
            a[A_MDY][i] += wd * dy * dy;
            a[A_MDZ][i] += wd * dz * dz;
            /* glossy: the mirror of d/|d| about n is 2 (n.d/|d|) n - d/|d|; cos g = mirror . v */
            float cg = nv2 * ci - (v0 * dx + v1 * dy + v2 * dz) * inv;
            gw[i] = (ok & (cg > 0.0f)) ? w : 0.0f;
            gc[i] = cg > 1e-30f ? (cg < 1.0f ? cg : 1.0f) : 1e-30f;
        }
        if (!glossy) continue;
        mr_pow_lanes(gc, k);
        for (size_t i = 0; i < MR_LANES; i++) {
            size_t q = j + i;
            float dx = px[q] - x0, dy = py[q] - x1, dz = pz[q] - x2;
            float ws = gw[i] * gc[i];
            float wsum = peps[q] + ws;
            a[A_ESR][i] += br[q] * ws;
            a[A_ESG][i] += bg[q] * ws;
            a[A_ESB][i] += bb[q] * ws;
            a[A_WS][i] += wsum;
            a[A_LSX][i] += wsum * dx;
            a[A_LSY][i] += wsum * dy;
            a[A_LSZ][i] += wsum * dz;
            a[A_MSX][i] += wsum * dx * dx;
            a[A_MSY][i] += wsum * dy * dy;
            a[A_MSZ][i] += wsum * dz * dz;
        }
    }
    memcpy(acc, a, sizeof a);
}

MR_CLONES static void mr_gather_tile_d(float *const *soa, uint32_t j0, uint32_t nj, const mr_pt *p, float k,
                                       float acc[MR_ACC][MR_LANES]) {
    mr_gather_body(soa, j0, nj, p, k, 0, acc);
}

MR_CLONES static void mr_gather_tile_s(float *const *soa, uint32_t j0, uint32_t nj, const mr_pt *p, float k,
                                       float acc[MR_ACC][MR_LANES]) {
    mr_gather_body(soa, j0, nj, p, k, 1, acc);
}

/* Sums (E rgb, W, sum W d, sum W d^2) -> the point's E, l and S_o radius. */
static void mr_reduce_sums(const double s[10], const float x[3], float scale, float e[3], float l[3], float *radius) {
    double wsum = s[3] > 0.0 ? s[3] : 1.0, sig = 0.0;
    for (int k = 0; k < 3; k++) {
        e[k] = (float)(s[k] * scale);
        double mean = s[4 + k] / wsum, var = s[7 + k] / wsum - mean * mean;
        l[k] = (float)(x[k] + mean);
        if (var > sig) sig = var;
    }
    *radius = (float)(2.0 * sqrt(sig));
}

/* Lane sums -> the point's E, l and S_o radius (one channel set: base A_EDR or A_ESR). */
static void mr_reduce(const float acc[MR_ACC][MR_LANES], int base, const float x[3], float scale, float e[3],
                      float l[3], float *radius) {
    double s[10] = {0};
    for (int a = 0; a < 10; a++)
        for (int i = 0; i < MR_LANES; i++) s[a] += acc[base + a][i];
    mr_reduce_sums(s, x, scale, e, l, radius);
}

/* gl_buf for n points (LC_MR_GL_POINT + LC_MR_GL_SUMS floats each, which also holds the
 * occlusion's 2 LC_MR_GL_OCC_POINT + 2). */
static int mr_gl_scratch(lc_mr *m, uint32_t n) {
    if (n <= m->gl_cap) return 0;
    float *b = malloc((size_t)n * (LC_MR_GL_POINT + LC_MR_GL_SUMS) * sizeof(float));
    if (!b) return -1;
    free(m->gl_buf);
    m->gl_buf = b, m->gl_cap = n;
    return 0;
}

/* Step 3 on the GL backend: the lights uploaded when they changed, the points packed, the raw
 * sums reduced as mr_reduce does. -1 with err on a GL failure. */
static int mr_gather_gl(lc_mr *m, uint32_t n, char *err, size_t errlen) {
    if (m->gl_dirty) {
        lc_mr_lights_view v = lc_mr_lights(m);
        if (lc_mr_gl_set_lights(m->gl, &v, err, errlen)) return -1;
        m->gl_dirty = 0;
    }
    if (mr_gl_scratch(m, n)) return mr_fail(err, errlen, "points: out of memory for %u (GL gather)", n);
    float *pk = m->gl_buf, *sums = m->gl_buf + (size_t)n * LC_MR_GL_POINT;
    for (uint32_t i = 0; i < n; i++) {
        const mr_pt *p = &m->pts[i];
        float *o = pk + (size_t)i * LC_MR_GL_POINT;
        o[0] = p->x[0], o[1] = p->x[1], o[2] = p->x[2], o[3] = p->nv;
        o[4] = p->n[0], o[5] = p->n[1], o[6] = p->n[2], o[7] = 0.0f;
        o[8] = p->v[0], o[9] = p->v[1], o[10] = p->v[2], o[11] = 0.0f;
    }
    const float k = m->p.spec_exponent, ck = (k + 1.0f) / (2.0f * MR_PI);
    if (lc_mr_gl_gather(m->gl, pk, n, k, m->p.glossy, LC_MR_EPSILON, sums, err, errlen)) {
        m->gl_dirty = 1; /* the context may have lost the lights */
        return -1;
    }
    for (uint32_t i = 0; i < n; i++) {
        const float *f = sums + (size_t)i * LC_MR_GL_SUMS;
        double s[LC_MR_GL_SUMS];
        for (int a = 0; a < LC_MR_GL_SUMS; a++) s[a] = f[a];
        mr_gathered *g = &m->g[i];
        mr_reduce_sums(s, m->pts[i].x, 1.0f, g->e_d, g->l_d, &g->rad_d);
        if (m->p.glossy) {
            mr_reduce_sums(s + 10, m->pts[i].x, ck, g->e_s, g->l_s, &g->rad_s);
        } else {
            memset(g->e_s, 0, sizeof g->e_s);
            memcpy(g->l_s, g->l_d, sizeof g->l_s);
            g->rad_s = g->rad_d;
        }
    }
    return 0;
}

typedef struct {
    const lc_mr *m;
    uint32_t padded;
} mr_gather_job;

static void mr_gather_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const mr_gather_job *job = ctx;
    const lc_mr *m = job->m;
    const float k = m->p.spec_exponent, ck = (k + 1.0f) / (2.0f * MR_PI);
    float acc[LC_MR_POINT_BLOCK][MR_ACC][MR_LANES];
    for (size_t p0 = begin; p0 < end; p0 += LC_MR_POINT_BLOCK) {
        uint32_t np = (uint32_t)(end - p0 < LC_MR_POINT_BLOCK ? end - p0 : LC_MR_POINT_BLOCK);
        memset(acc, 0, sizeof acc);
        for (uint32_t j0 = 0; j0 < job->padded; j0 += LC_MR_TILE) {
            uint32_t nj = job->padded - j0 < LC_MR_TILE ? job->padded - j0 : LC_MR_TILE;
            for (uint32_t q = 0; q < np; q++) {
                if (m->p.glossy) mr_gather_tile_s(m->soa, j0, nj, &m->pts[p0 + q], k, acc[q]);
                else mr_gather_tile_d(m->soa, j0, nj, &m->pts[p0 + q], k, acc[q]);
            }
        }
        for (uint32_t q = 0; q < np; q++) {
            const mr_pt *pt = &m->pts[p0 + q];
            mr_gathered *g = &m->g[p0 + q];
            mr_reduce(acc[q], A_EDR, pt->x, 1.0f, g->e_d, g->l_d, &g->rad_d);
            if (m->p.glossy) {
                mr_reduce(acc[q], A_ESR, pt->x, ck, g->e_s, g->l_s, &g->rad_s);
            } else {
                memset(g->e_s, 0, sizeof g->e_s);
                memcpy(g->l_s, g->l_d, sizeof g->l_s);
                g->rad_s = g->rad_d;
            }
        }
    }
}

/* --- 4. occlusion ------------------------------------------------------------------------- */

/* An orthonormal tangent frame (t, b) of the unit normal n (Duff et al. 2017). */
static void mr_frame(const float n[3], float t[3], float b[3]) {
    float s = n[2] >= 0.0f ? 1.0f : -1.0f;
    float a = -1.0f / (s + n[2]), c = n[0] * n[1] * a;
    t[0] = 1.0f + s * n[0] * n[0] * a, t[1] = s * c, t[2] = -s * n[0];
    b[0] = c, b[1] = s + n[1] * n[1] * a, b[2] = -n[1];
}

/* o for point i toward the sphere S_o (centre l, radius rad), eq. 3 and 14, squares, sum. */
static float mr_occlusion(const lc_mr *m, uint32_t n, uint32_t i, const float l[3], float rad) {
    const mr_pt *x = &m->pts[i];
    float v[3] = {l[0] - x->x[0], l[1] - x->x[1], l[2] - x->x[2]};
    float dd = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!(dd > 1e-6f)) return 0.0f;
    float ci = (x->n[0] * v[0] + x->n[1] * v[1] + x->n[2] * v[2]) / dd;
    if (!(ci > 0.0f)) return 0.0f;
    float R = rad > 1e-3f * dd ? rad : 1e-3f * dd; /* a point-like S_o keeps a small sphere */
    float area_s = MR_PI * R * R / (R * R + dd * dd) * ci;
    float t[3], b[3];
    mr_frame(x->n, t, b);
    float sx = (v[0] * t[0] + v[1] * t[1] + v[2] * t[2]) / dd, sy = (v[0] * b[0] + v[1] * b[1] + v[2] * b[2]) / dd;
    float hs = 0.5f * sqrtf(area_s);
    float near = dd - R > 0.0f ? dd - R : 0.0f, ramp = dd - near;
    double sum = 0.0;
    for (uint32_t k = 0; k < n; k++) {
        const mr_pt *o = &m->pts[k];
        if (k == i || (!m->p.self_occlusion && o->object == x->object)) continue;
        float u[3] = {o->x[0] - x->x[0], o->x[1] - x->x[1], o->x[2] - x->x[2]};
        float d2 = u[0] * u[0] + u[1] * u[1] + u[2] * u[2];
        if (!(d2 < dd * dd) || !(d2 > 1e-12f)) continue;
        float dk = sqrtf(d2);
        float cn = (x->n[0] * u[0] + x->n[1] * u[1] + x->n[2] * u[2]) / dk;
        if (!(cn > 0.0f)) continue;
        float cj = fabsf(o->n[0] * u[0] + o->n[1] * u[1] + o->n[2] * u[2]) / dk, r2 = o->radius * o->radius;
        float hk = 0.5f * sqrtf(MR_PI * r2 * cj / (r2 + d2) * cn);
        float kx = (u[0] * t[0] + u[1] * t[1] + u[2] * t[2]) / dk, ky = (u[0] * b[0] + u[1] * b[1] + u[2] * b[2]) / dk;
        float ox = fminf(sx + hs, kx + hk) - fmaxf(sx - hs, kx - hk);
        float oy = fminf(sy + hs, ky + hk) - fmaxf(sy - hs, ky - hk);
        if (!(ox > 0.0f) || !(oy > 0.0f)) continue;
        float s = dk <= near ? 1.0f : (dd - dk) / ramp;
        sum += (double)s * ox * oy;
    }
    double o = sum / area_s;
    return (float)(o < 1.0 ? o : 1.0);
}

/* Step 4 on the GL backend (mr_occlusion_range's result). -1 with err on a GL failure. */
static int mr_occlusion_gl(lc_mr *m, uint32_t n, char *err, size_t errlen) {
    if (mr_gl_scratch(m, n)) return mr_fail(err, errlen, "points: out of memory for %u (GL occlusion)", n);
    float *pk = m->gl_buf, *tg = pk + (size_t)n * LC_MR_GL_OCC_POINT, *occ = tg + (size_t)n * LC_MR_GL_OCC_POINT;
    for (uint32_t i = 0; i < n; i++) {
        const mr_pt *p = &m->pts[i];
        const mr_gathered *g = &m->g[i];
        float *o = pk + (size_t)i * LC_MR_GL_OCC_POINT, *t = tg + (size_t)i * LC_MR_GL_OCC_POINT;
        union {
            uint32_t u;
            float f;
        } obj = {p->object};
        o[0] = p->x[0], o[1] = p->x[1], o[2] = p->x[2], o[3] = p->radius;
        o[4] = p->n[0], o[5] = p->n[1], o[6] = p->n[2], o[7] = obj.f;
        t[0] = g->l_d[0], t[1] = g->l_d[1], t[2] = g->l_d[2], t[3] = g->rad_d;
        t[4] = g->l_s[0], t[5] = g->l_s[1], t[6] = g->l_s[2], t[7] = g->rad_s;
    }
    if (lc_mr_gl_occlusion(m->gl, pk, tg, n, m->p.self_occlusion, m->p.glossy, occ, err, errlen)) return -1;
    for (uint32_t i = 0; i < n; i++) {
        mr_gathered *g = &m->g[i];
        float od = occ[2 * i], os = occ[2 * i + 1];
        for (int k = 0; k < 3; k++) g->e_d[k] *= 1.0f - od, g->e_s[k] *= 1.0f - os;
        m->occ[2 * i] = od, m->occ[2 * i + 1] = os;
    }
    return 0;
}

static void mr_occlusion_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const mr_gather_job *job = ctx;
    const lc_mr *m = job->m;
    uint32_t n = job->padded; /* the point count here */
    for (size_t i = begin; i < end; i++) {
        mr_gathered *g = &m->g[i];
        float od = mr_occlusion(m, n, (uint32_t)i, g->l_d, g->rad_d);
        float os = m->p.glossy ? mr_occlusion(m, n, (uint32_t)i, g->l_s, g->rad_s) : 0.0f;
        for (int k = 0; k < 3; k++) g->e_d[k] *= 1.0f - od, g->e_s[k] *= 1.0f - os;
        m->occ[2 * i] = od, m->occ[2 * i + 1] = os;
    }
}

/* --- 5-6. smoothing, renormalisation ------------------------------------------------------ */

static int mr_camera_jumped(const lc_mr *m) {
    const float *t = m->cam.translation, *q = m->cam.rotation;
    float dx = t[0] - m->hist_t[0], dy = t[1] - m->hist_t[1], dz = t[2] - m->hist_t[2];
    if (dx * dx + dy * dy + dz * dz > 0.25f) return 1;
    float dot = fabsf(q[0] * m->hist_q[0] + q[1] * m->hist_q[1] + q[2] * m->hist_q[2] + q[3] * m->hist_q[3]);
    return dot < 0.965925826f; /* cos 15 deg: the rotation between them is over 30 deg */
}

static void mr_blend(float *cur, float *hist, int n, float s, int use) {
    for (int k = 0; k < n; k++) {
        if (use) cur[k] = s * hist[k] + (1.0f - s) * cur[k];
        hist[k] = cur[k];
    }
}

/* The record for one point from its final E and l (eq. 11 with the moves of mr.h, step 6). */
static void mr_normalise(const lc_mr *m, const mr_pt *p, mr_gathered *g, lc_mr_vpl *out) {
    float v[3] = {g->l_d[0] - p->x[0], g->l_d[1] - p->x[1], g->l_d[2] - p->x[2]};
    float dist = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    float c = dist > 0.0f ? (p->n[0] * v[0] + p->n[1] * v[1] + p->n[2] * v[2]) / dist : 0.0f;
    int lit = g->e_d[0] > 0.0f || g->e_d[1] > 0.0f || g->e_d[2] > 0.0f;
    if (lit && c <= 1e-3f) {
        if (!(dist > 1e-6f)) dist = 0.01f;
        for (int k = 0; k < 3; k++) g->l_d[k] = p->x[k] + p->n[k] * dist;
        c = 1.0f;
    }
    for (int k = 0; k < 3; k++) {
        out->i_d[k] = lit ? g->e_d[k] * dist * dist / c : 0.0f;
        out->l_d[k] = g->l_d[k];
    }
    const float kx = m->p.spec_exponent;
    float u[3] = {g->l_s[0] - p->x[0], g->l_s[1] - p->x[1], g->l_s[2] - p->x[2]};
    float ds = sqrtf(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    float cg = 0.0f;
    if (ds > 0.0f) { /* mirror of u/|u| about n, against v */
        float nu = (p->n[0] * u[0] + p->n[1] * u[1] + p->n[2] * u[2]) / ds;
        cg = 2.0f * nu * p->nv - (p->v[0] * u[0] + p->v[1] * u[1] + p->v[2] * u[2]) / ds;
    }
    float ck = cg > 0.0f ? powf(fminf(cg, 1.0f), kx) : 0.0f;
    lit = g->e_s[0] > 0.0f || g->e_s[1] > 0.0f || g->e_s[2] > 0.0f;
    if (lit && !(ck >= 1e-6f)) {
        if (!(ds > 1e-6f)) ds = 0.01f;
        for (int k = 0; k < 3; k++) g->l_s[k] = p->x[k] + ds * (2.0f * p->nv * p->n[k] - p->v[k]);
        ck = 1.0f;
    }
    for (int k = 0; k < 3; k++) {
        out->i_s[k] = lit ? g->e_s[k] * ds * ds / ck : 0.0f;
        out->l_s[k] = g->l_s[k];
    }
}

/* --- 7. per-object SH --------------------------------------------------------------------- */

typedef struct {
    const lc_mr *m;
    const float (*centres)[3];
    float (*sh)[27];
} mr_sh_job;

MR_CLONES static void mr_sh_object(float *const *soa, uint32_t padded, const float c[3], float out[27]) {
    float acc[27][MR_LANES];
    memset(acc, 0, sizeof acc);
    for (uint32_t j = 0; j < padded; j += MR_LANES)
        for (int i = 0; i < MR_LANES; i++) {
            uint32_t q = j + (uint32_t)i;
            float dx = soa[MR_PX][q] - c[0], dy = soa[MR_PY][q] - c[1], dz = soa[MR_PZ][q] - c[2];
            float d2 = dx * dx + dy * dy + dz * dz;
            d2 = d2 > 1e-20f ? d2 : 1e-20f;
            float inv = 1.0f / sqrtf(d2);
            dx *= inv, dy *= inv, dz *= inv;
            float cj = -(soa[MR_NX][q] * dx + soa[MR_NY][q] * dy + soa[MR_NZ][q] * dz);
            float om = MR_PI * soa[MR_R2][q] * cj / d2; /* a cos t_j / d^2 */
            om = cj > 0.0f ? (om < 2.0f * MR_PI ? om : 2.0f * MR_PI) : 0.0f;
            float wl = om / MR_PI; /* radiance B / pi times the solid angle */
            float y[9] = {0.282094791774f,
                          0.488602511903f * dy,
                          0.488602511903f * dz,
                          0.488602511903f * dx,
                          1.092548430592f * dx * dy,
                          1.092548430592f * dy * dz,
                          0.315391565253f * (3.0f * dz * dz - 1.0f),
                          1.092548430592f * dx * dz,
                          0.546274215296f * (dx * dx - dy * dy)};
            float br = soa[MR_BR][q] * wl, bg = soa[MR_BG][q] * wl, bb = soa[MR_BB][q] * wl;
            for (int s = 0; s < 9; s++) {
                acc[3 * s][i] += br * y[s];
                acc[3 * s + 1][i] += bg * y[s];
                acc[3 * s + 2][i] += bb * y[s];
            }
        }
    for (int s = 0; s < 27; s++) {
        double sum = 0.0;
        for (int i = 0; i < MR_LANES; i++) sum += acc[s][i];
        int l = s / 3 < 1 ? 0 : s / 3 < 4 ? 1 : 2;
        out[s] = (float)(sum * lc_sh_cosine_factor(l));
    }
}

static void mr_sh_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    const mr_sh_job *job = ctx;
    uint32_t padded = (job->m->n_lights + LC_MR_TILE - 1) / LC_MR_TILE * LC_MR_TILE;
    for (size_t o = begin; o < end; o++) {
        if (padded == 0 || !job->m->soa[0]) {
            memset(job->sh[o], 0, sizeof job->sh[o]);
            continue;
        }
        mr_sh_object(job->m->soa, padded, job->centres[o], job->sh[o]);
    }
}

/* --- compute ------------------------------------------------------------------------------ */

static int mr_reserve_points(lc_mr *m, uint32_t n, uint32_t objects) {
    if (n > m->pt_cap) {
        mr_pt *p = malloc((size_t)n * sizeof *p);
        mr_gathered *g = malloc((size_t)n * sizeof *g);
        float *o = malloc((size_t)n * 2 * sizeof(float)), *h = malloc((size_t)n * 12 * sizeof(float));
        if (!p || !g || !o || !h) {
            free(p), free(g), free(o), free(h);
            return -1;
        }
        free(m->pts), free(m->g), free(m->occ), free(m->hist_pt);
        m->pts = p, m->g = g, m->occ = o, m->hist_pt = h;
        m->pt_cap = n;
        m->hist_valid = 0;
    }
    if (objects > m->obj_cap) {
        float *s = malloc((size_t)objects * 27 * sizeof(float));
        if (!s) return -1;
        free(m->hist_sh);
        m->hist_sh = s;
        m->obj_cap = objects;
        m->hist_valid = 0;
    }
    return 0;
}

/* Checks the points and prepares m->pts (normals normalised, view directions). */
static int mr_prepare_points(lc_mr *m, const lc_mr_point *pts, uint32_t n, const uint32_t *obj, uint32_t n_objects,
                             const float (*centres)[3], char *err, size_t errlen) {
    for (uint32_t o = 0; o < n_objects; o++)
        for (int k = 0; k < 3; k++)
            if (!(fabsf(centres[o][k]) <= 1e6f)) return mr_fail(err, errlen, "centres[%u]: not finite", o);
    const float *cam = m->cam.translation;
    for (uint32_t i = 0; i < n; i++) {
        const lc_mr_point *s = &pts[i];
        mr_pt *p = &m->pts[i];
        for (int k = 0; k < 3; k++)
            if (!(fabsf(s->position[k]) <= 1e6f)) return mr_fail(err, errlen, "points[%u]/position: not finite", i);
        float nl = sqrtf(s->normal[0] * s->normal[0] + s->normal[1] * s->normal[1] + s->normal[2] * s->normal[2]);
        if (!(nl > 1e-6f && nl < 1e6f)) return mr_fail(err, errlen, "points[%u]/normal: zero or not finite", i);
        if (!(s->radius >= 0.0f && s->radius <= 1e6f))
            return mr_fail(err, errlen, "points[%u]/radius: %g not in [0, 1e6]", i, s->radius);
        if (obj[i] >= n_objects)
            return mr_fail(err, errlen, "object_of_point[%u]: %u not below %u", i, obj[i], n_objects);
        float v[3], vl = 0.0f;
        for (int k = 0; k < 3; k++) {
            p->x[k] = s->position[k];
            p->n[k] = s->normal[k] / nl;
            v[k] = cam[k] - s->position[k];
            vl += v[k] * v[k];
        }
        vl = sqrtf(vl);
        for (int k = 0; k < 3; k++) p->v[k] = vl > 1e-6f ? v[k] / vl : p->n[k];
        p->nv = p->n[0] * p->v[0] + p->n[1] * p->v[1] + p->n[2] * p->v[2];
        p->radius = s->radius;
        p->object = obj[i];
    }
    return 0;
}

int lc_mr_compute(lc_mr *m, const lc_mr_point *pts, uint32_t n, const uint32_t *object_of_point, uint32_t n_objects,
                  const float (*centres)[3], lc_mr_vpl *vpl_out, lc_mr_point_out *point_out, float (*sh_out)[27],
                  char *err, size_t errlen) {
    if (n > LC_MR_MAX_POINTS) return mr_fail(err, errlen, "points: %u over %u", n, LC_MR_MAX_POINTS);
    if (n_objects > LC_MR_MAX_OBJECTS) return mr_fail(err, errlen, "objects: %u over %u", n_objects, LC_MR_MAX_OBJECTS);
    if ((n && (!pts || !object_of_point || !vpl_out)) || (n_objects && !centres))
        return mr_fail(err, errlen, "points: missing points, object_of_point, centres or vpl_out");
    if (mr_reserve_points(m, n ? n : 1, n_objects ? n_objects : 1))
        return mr_fail(err, errlen, "points: out of memory for %u", n);
    if (mr_prepare_points(m, pts, n, object_of_point, n_objects, centres, err, errlen)) return -1;
    double t0 = lc_clock_ms();
    mr_gather_job job = {m, (m->n_lights + LC_MR_TILE - 1) / LC_MR_TILE * LC_MR_TILE};
    if (job.padded && m->gl) {
        if (mr_gather_gl(m, n, err, errlen)) return -1;
    } else if (job.padded) lc_parallel_for(m->threads, n, LC_MR_POINT_BLOCK, mr_gather_range, &job);
    else
        for (uint32_t i = 0; i < n; i++) {
            mr_gathered *g = &m->g[i];
            memset(g, 0, sizeof *g);
            memcpy(g->l_d, m->pts[i].x, sizeof g->l_d);
            memcpy(g->l_s, m->pts[i].x, sizeof g->l_s);
        }
    double t1 = lc_clock_ms();
    memset(m->occ, 0, (size_t)n * 2 * sizeof(float));
    if (m->p.occlusion && n > 1 && m->gl) {
        if (mr_occlusion_gl(m, n, err, errlen)) return -1;
    } else if (m->p.occlusion && n > 1) {
        mr_gather_job oj = {m, n};
        lc_parallel_for(m->threads, n, 16, mr_occlusion_range, &oj);
    }
    double t2 = lc_clock_ms();
    int use = m->hist_valid && m->p.smoothing > 0.0f && m->hist_n == n && m->hist_objects == n_objects &&
        !mr_camera_jumped(m);
    for (uint32_t i = 0; i < n; i++) {
        mr_gathered *g = &m->g[i];
        float *h = m->hist_pt + 12 * (size_t)i;
        mr_blend(g->e_d, h, 3, m->p.smoothing, use);
        mr_blend(g->l_d, h + 3, 3, m->p.smoothing, use);
        mr_blend(g->e_s, h + 6, 3, m->p.smoothing, use);
        mr_blend(g->l_s, h + 9, 3, m->p.smoothing, use);
        mr_normalise(m, &m->pts[i], g, &vpl_out[i]);
        if (point_out) {
            lc_mr_point_out *po = &point_out[i];
            memcpy(po->e_d, g->e_d, sizeof po->e_d);
            memcpy(po->e_s, g->e_s, sizeof po->e_s);
            po->occ_d = m->occ[2 * i], po->occ_s = m->occ[2 * i + 1];
            po->radius_d = g->rad_d, po->radius_s = g->rad_s;
        }
    }
    double t3 = lc_clock_ms();
    if (sh_out && n_objects) {
        mr_sh_job sj = {m, centres, sh_out};
        lc_parallel_for(m->threads, n_objects, 1, mr_sh_range, &sj);
        for (uint32_t o = 0; o < n_objects; o++)
            mr_blend(sh_out[o], m->hist_sh + 27 * (size_t)o, 27, m->p.smoothing, use && m->hist_sh_valid);
    }
    m->hist_valid = 1, m->hist_sh_valid = sh_out != NULL, m->hist_n = n, m->hist_objects = n_objects;
    memcpy(m->hist_t, m->cam.translation, sizeof m->hist_t);
    memcpy(m->hist_q, m->cam.rotation, sizeof m->hist_q);
    m->t.gather_ms = t1 - t0, m->t.occlusion_ms = t2 - t1, m->t.normalise_ms = t3 - t2;
    m->t.sh_ms = lc_clock_ms() - t3;
    return 0;
}
