/* mr_gl: LightSkin's gather and occlusion (engine/mr.h steps 3, 4) on GL 4.3 compute (EGL),
 * shaders/mr_gather.comp and mr_occlusion.comp.
 * lc_mr_set_gl (mr.h) hands one to an lc_mr; lc_mr_compute then uploads the frame's lights once
 * (lc_mr_gl_set_lights), runs lc_mr_gl_gather for the points and reduces the raw sums on the CPU
 * exactly as its own gather's (double), then lc_mr_gl_occlusion; smoothing, renormalisation and
 * the SH stay the CPU's code.
 *
 * Threads: lc_mr_gl_create makes its own EGL context current on the calling thread (in lucentd
 * the MR worker); every call below re-makes it current on the calling thread, one at a time.
 * Ownership: the caller owns the lc_mr_gl; lc_mr_set_gl does not take it. */
#ifndef LC_MR_GL_H
#define LC_MR_GL_H
#include <stddef.h>
#include <stdint.h>

#include "engine/mr.h"

#define LC_MR_GL_SUMS 20     /* raw sums per point: E_d rgb, W_d, sum W d (3), sum W d^2 (3), then the glossy 10 */
#define LC_MR_GL_CHUNK 16384 /* lights (and occluders) per dispatch: llvmpipe ends loops after 65535 iterations */
#define LC_MR_GL_OCC_POINT 8 /* floats per point and per target for the occlusion */
#define LC_MR_GL_POINT 12    /* floats per point: x, n.v, n, 0, v, 0 (the shader's Point) */

typedef struct lc_mr_gl lc_mr_gl;

/* NULL with err when no EGL display / GL 4.3 context can be had or the shader does not build. */
lc_mr_gl *lc_mr_gl_create(char *err, size_t errlen);
/* The shader variant: shared_tiles 1 = one invocation per point, the workgroup's 64 points sharing
 * tiles of LC_MR_TILE lights in shared memory (the paper's K_cache); 0 = each invocation reads the
 * lights straight from the SSBO. lc_mr_gl_create takes the shared tiles: on llvmpipe the two are
 * within noise of each other (lucent-mr-bench --variant), and on a real GPU tiles are the paper's. */
lc_mr_gl *lc_mr_gl_create_variant(int shared_tiles, char *err, size_t errlen);
void lc_mr_gl_release(lc_mr_gl *g);
/* "mr_gather on <GL_RENDERER (GL_VERSION) via ...>[ (software)]". */
const char *lc_mr_gl_description(const lc_mr_gl *g);
/* 1 when the EGL device is a software rasterizer (llvmpipe): slower than the CPU gather. */
int lc_mr_gl_is_software(const lc_mr_gl *g);

/* Uploads the lights (v.count <= LC_MR_MAX_LIGHTS). 0, or -1 with err. */
int lc_mr_gl_set_lights(lc_mr_gl *g, const lc_mr_lights_view *v, char *err, size_t errlen);
/* The gather at n points (LC_MR_GL_POINT floats each, n <= LC_MR_MAX_POINTS) against the uploaded
 * lights: sums[n][LC_MR_GL_SUMS] (glossy 0: the glossy 10 are 0). eps per light, k the exponent.
 * 0, or -1 with err. */
int lc_mr_gl_gather(lc_mr_gl *g, const float *points, uint32_t n, float k, int glossy, float eps, float *sums,
                    char *err, size_t errlen);
/* Step 4 at n points: points[n][LC_MR_GL_OCC_POINT] = x, disc radius, n, object (its uint32 bits);
 * targets[n][LC_MR_GL_OCC_POINT] = l_d, S_o radius for l_d, l_s, radius for l_s; occ[n][2] = o_d,
 * o_s (o_s = 0 without glossy), clamped to [0, 1]. 0, or -1 with err. */
int lc_mr_gl_occlusion(lc_mr_gl *g, const float *points, const float *targets, uint32_t n, int self_occlusion,
                       int glossy, float *occ, char *err, size_t errlen);
/* Test hook: the next gather or occlusion fails as a GL error would (once). */
void lc_mr_gl_inject_failure(lc_mr_gl *g);

#endif
