/* mr_gl: LightSkin's gather on GL compute (see mr_gl.h). */
#include "gpu/mr_gl.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gpu/egl_context.h"
#include "gpu/gl_util.h"

#define MR_GL_LOCAL 64         /* the shader's local_size_x */
#define MR_GL_DEFAULT_SHARED 1 /* see mr_gl.h */

struct lc_mr_gl {
    lc_egl_context *ctx;
    GLuint prog, occ_prog, lights_buf, points_buf, sums_buf, opts_buf, targets_buf, occ_buf;
    size_t lights_cap, points_cap, sums_cap, opts_cap, targets_cap, occ_cap; /* bytes */
    lc_gl_staging staging; /* sums and occlusion read back (gl_util.h) */
    uint32_t n_lights;
    int fail_next;
    char desc[512];
};

static int mr_gl_fail(char *err, size_t errlen, const char *fmt, ...) {
    if (err && errlen) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err, errlen, fmt, ap);
        va_end(ap);
    }
    return -1;
}

lc_mr_gl *lc_mr_gl_create_variant(int shared_tiles, char *err, size_t errlen) {
    lc_mr_gl *g = calloc(1, sizeof *g);
    if (!g) {
        mr_gl_fail(err, errlen, "mr_gl: out of memory");
        return NULL;
    }
    g->ctx = lc_egl_create(err, errlen);
    if (!g->ctx) goto err;
    const char *src = lc_gl_shader_source("mr_gather");
    if (!src) {
        mr_gl_fail(err, errlen, "mr_gather: shader not embedded");
        goto err;
    }
    char defs[64];
    snprintf(defs, sizeof defs, "#define TILE %d\n#define SHARED %d\n", LC_MR_TILE, shared_tiles ? 1 : 0);
    g->prog = lc_gl_compile_program_defs("mr_gather.comp", src, defs, err, errlen);
    if (!g->prog) goto err;
    const char *osrc = lc_gl_shader_source("mr_occlusion");
    if (!osrc) {
        mr_gl_fail(err, errlen, "mr_occlusion: shader not embedded");
        goto err;
    }
    g->occ_prog = lc_gl_compile_program("mr_occlusion.comp", osrc, err, errlen);
    if (!g->occ_prog) goto err;
    snprintf(g->desc, sizeof g->desc, "mr_gather (%s) on %s%s", shared_tiles ? "shared-memory tiles" : "direct",
             lc_egl_description(g->ctx), lc_egl_is_software(g->ctx) ? " (software)" : "");
    return g;
err:
    lc_mr_gl_release(g);
    return NULL;
}

lc_mr_gl *lc_mr_gl_create(char *err, size_t errlen) {
    return lc_mr_gl_create_variant(MR_GL_DEFAULT_SHARED, err, errlen);
}

void lc_mr_gl_release(lc_mr_gl *g) {
    if (!g) return;
    if (g->ctx && lc_egl_make_current(g->ctx, NULL, 0) == 0) {
        if (g->prog) glDeleteProgram(g->prog);
        if (g->occ_prog) glDeleteProgram(g->occ_prog);
        GLuint bufs[6] = {g->lights_buf, g->points_buf, g->sums_buf, g->opts_buf, g->targets_buf, g->occ_buf};
        for (int i = 0; i < 6; i++)
            if (bufs[i]) glDeleteBuffers(1, &bufs[i]);
        lc_gl_staging_release(&g->staging);
    }
    if (g->ctx) lc_egl_release(g->ctx);
    free(g);
}

const char *lc_mr_gl_description(const lc_mr_gl *g) { return g->desc; }

void lc_mr_gl_inject_failure(lc_mr_gl *g) { g->fail_next = 1; }

/* buf holds at least bytes (grown, contents lost); 0 or -1 with err. */
static int mr_gl_reserve(GLuint *buf, size_t *cap, size_t bytes, const char *what, char *err, size_t errlen) {
    if (*buf && bytes <= *cap) return 0;
    if (*buf) glDeleteBuffers(1, buf);
    *buf = 0, *cap = 0;
    size_t want = bytes < 16 ? 16 : bytes;
    *buf = lc_gl_buffer(want, NULL, what, err, errlen);
    if (!*buf) return -1;
    *cap = want;
    return 0;
}

int lc_mr_gl_set_lights(lc_mr_gl *g, const lc_mr_lights_view *v, char *err, size_t errlen) {
    if (v->count > LC_MR_MAX_LIGHTS)
        return mr_gl_fail(err, errlen, "mr_gl/lights: %u over %u", v->count, LC_MR_MAX_LIGHTS);
    if (lc_egl_make_current(g->ctx, err, errlen)) return -1;
    g->n_lights = 0;
    if (v->count == 0) return 0;
    size_t bytes = (size_t)v->count * 12 * sizeof(float);
    float *host = malloc(bytes);
    if (!host) return mr_gl_fail(err, errlen, "mr_gl/lights: out of memory for %u", v->count);
    for (uint32_t j = 0; j < v->count; j++) {
        float *o = host + 12 * (size_t)j;
        o[0] = v->px[j], o[1] = v->py[j], o[2] = v->pz[j], o[3] = v->r2[j];
        o[4] = v->nx[j], o[5] = v->ny[j], o[6] = v->nz[j], o[7] = 0.0f;
        o[8] = v->br[j], o[9] = v->bg[j], o[10] = v->bb[j], o[11] = 0.0f;
    }
    int rc = -1;
    if (mr_gl_reserve(&g->lights_buf, &g->lights_cap, bytes, "mr_gl/lights", err, errlen)) goto err;
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, g->lights_buf);
    glBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)bytes, host);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    if (lc_gl_check("mr_gl/lights upload", err, errlen)) goto err;
    g->n_lights = v->count;
    rc = 0;
err:
    free(host);
    return rc;
}

int lc_mr_gl_gather(lc_mr_gl *g, const float *points, uint32_t n, float k, int glossy, float eps, float *sums,
                    char *err, size_t errlen) {
    if (n > LC_MR_MAX_POINTS) return mr_gl_fail(err, errlen, "mr_gl/points: %u over %u", n, LC_MR_MAX_POINTS);
    if (g->fail_next) {
        g->fail_next = 0;
        return mr_gl_fail(err, errlen, "mr_gl/gather: injected GL failure");
    }
    if (n == 0) return 0;
    if (lc_egl_make_current(g->ctx, err, errlen)) return -1;
    size_t pbytes = (size_t)n * LC_MR_GL_POINT * sizeof(float), sbytes = (size_t)n * LC_MR_GL_SUMS * sizeof(float);
    if (mr_gl_reserve(&g->points_buf, &g->points_cap, pbytes, "mr_gl/points", err, errlen)) return -1;
    if (mr_gl_reserve(&g->sums_buf, &g->sums_cap, sbytes, "mr_gl/sums", err, errlen)) return -1;
    if (mr_gl_reserve(&g->lights_buf, &g->lights_cap, 16, "mr_gl/lights", err, errlen)) return -1;
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, g->points_buf);
    glBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, (GLsizeiptr)pbytes, points);
    glUseProgram(g->prog);
    lc_gl_bind(0, g->lights_buf, 0, (size_t)g->n_lights * 12 * sizeof(float));
    lc_gl_bind(1, g->points_buf, 0, pbytes);
    lc_gl_bind(2, g->sums_buf, 0, sbytes);
    glUniform1ui(0, n);
    glUniform1f(2, k);
    glUniform1i(3, glossy ? 1 : 0);
    glUniform1f(4, eps);
    uint32_t base = 0;
    do { /* chunks of lights (see mr_gather.comp); with no lights one dispatch writes zeros */
        uint32_t count = g->n_lights - base < LC_MR_GL_CHUNK ? g->n_lights - base : LC_MR_GL_CHUNK;
        glUniform1ui(1, count);
        glUniform1ui(5, base);
        glUniform1i(6, base > 0);
        lc_gl_dispatch_1d(n, MR_GL_LOCAL);
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
        base += count;
    } while (base < g->n_lights);
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    lc_gl_read(&g->staging, g->sums_buf, 0, sbytes, sums);
    glUseProgram(0);
    return lc_gl_check("mr_gl/gather", err, errlen);
}

int lc_mr_gl_is_software(const lc_mr_gl *g) { return g && g->ctx && lc_egl_is_software(g->ctx); }

int lc_mr_gl_occlusion(lc_mr_gl *g, const float *points, const float *targets, uint32_t n, int self_occlusion,
                       int glossy, float *occ, char *err, size_t errlen) {
    if (n > LC_MR_MAX_POINTS) return mr_gl_fail(err, errlen, "mr_gl/points: %u over %u", n, LC_MR_MAX_POINTS);
    if (g->fail_next) {
        g->fail_next = 0;
        return mr_gl_fail(err, errlen, "mr_gl/occlusion: injected GL failure");
    }
    if (n == 0) return 0;
    if (lc_egl_make_current(g->ctx, err, errlen)) return -1;
    size_t pbytes = (size_t)n * LC_MR_GL_OCC_POINT * sizeof(float), obytes = (size_t)n * 2 * sizeof(float);
    if (mr_gl_reserve(&g->opts_buf, &g->opts_cap, pbytes, "mr_gl/occluders", err, errlen) ||
        mr_gl_reserve(&g->targets_buf, &g->targets_cap, pbytes, "mr_gl/targets", err, errlen) ||
        mr_gl_reserve(&g->occ_buf, &g->occ_cap, obytes, "mr_gl/occ", err, errlen))
        return -1;
    glNamedBufferSubData(g->opts_buf, 0, (GLsizeiptr)pbytes, points);
    glNamedBufferSubData(g->targets_buf, 0, (GLsizeiptr)pbytes, targets);
    glUseProgram(g->occ_prog);
    lc_gl_bind(0, g->opts_buf, 0, pbytes);
    lc_gl_bind(1, g->targets_buf, 0, pbytes);
    lc_gl_bind(2, g->occ_buf, 0, obytes);
    glUniform1ui(0, n);
    glUniform1i(1, self_occlusion ? 1 : 0);
    glUniform1i(2, glossy ? 1 : 0);
    for (uint32_t base = 0; base < n; base += LC_MR_GL_CHUNK) { /* occluder chunks (mr_occlusion.comp) */
        glUniform1ui(3, base);
        glUniform1ui(4, n - base < LC_MR_GL_CHUNK ? n - base : LC_MR_GL_CHUNK);
        glUniform1i(5, base > 0);
        lc_gl_dispatch_1d(n, MR_GL_LOCAL);
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    }
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    lc_gl_read(&g->staging, g->occ_buf, 0, obytes, occ);
    glUseProgram(0);
    for (uint32_t i = 0; i < 2 * n; i++) occ[i] = occ[i] < 1.0f ? occ[i] : 1.0f;
    return lc_gl_check("mr_gl/occlusion", err, errlen);
}
