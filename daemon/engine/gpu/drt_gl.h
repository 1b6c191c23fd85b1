/* drt_gl: clutter operators (engine/drt.h) applied on GL 4.3 compute, shaders/drt.comp, for the
 * EGL transport (transport_gl.c), stage for stage as lc_drt_apply. Every attached object's arrays
 * are concatenated into one set of buffers, uploaded when the set of operators changes (their
 * serials); each relight uploads only the patches' direct light. The patches' radiosity and flux
 * stay on the GPU between passes and relights and are read back into the operators after each
 * run, so lc_drt_patch_radiosity and a CPU run see them.
 *
 * Threads: the engine's compute thread, with the transport's context current.
 * Ownership: the transport owns the lc_drt_gl; operators stay the engine's. */
#ifndef LC_DRT_GL_H
#define LC_DRT_GL_H
#include <epoxy/gl.h>
#include <stddef.h>
#include <stdint.h>

#include "engine/drt.h"

typedef struct lc_drt_gl lc_drt_gl;

/* Compiles the four stages. NULL with err (the shader log is logged too). */
lc_drt_gl *lc_drt_gl_create(char *err, size_t errlen);
void lc_drt_gl_release(lc_drt_gl *g);

/* Before a run's passes: the operators into the buffers (when they changed) and their patches'
 * direct light. Every buffer must fit one binding (bind_limit). -1 with err. */
int lc_drt_gl_upload(lc_drt_gl *g, lc_drt_ops *const *ops, uint32_t n, uint32_t n_texel_caches, size_t bind_limit,
                     char *err, size_t errlen);

/* What one pass applies to: the transport's buffers and the SH layout (lc_drt_target's). */
typedef struct lc_drt_gl_pass {
    GLuint node_flux, caches, cache_sh, sh9; /* the transport's (see transport_gl.c) */
    uint32_t n_nodes, n_caches, n_texel_caches;
    uint32_t chunk; /* caches per cache SH window */
    uint32_t nc;    /* the cache SH's stride (bands^2) */
    int ycocg, texel_lo, texel_nc, grid_nc;
    int last; /* 0: only the caches some surfel reads */
} lc_drt_gl_pass;
void lc_drt_gl_apply(lc_drt_gl *g, const lc_drt_gl_pass *p);

/* After a run: the patches' B and flux back into the operators it uploaded. */
void lc_drt_gl_read_back(lc_drt_gl *g, lc_drt_ops *const *ops, uint32_t n);

#endif
