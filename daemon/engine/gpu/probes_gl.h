/* probes_gl: the probes solver's gather (engine/probes.h) on GL 4.3 compute, shaders/probes.comp,
 * for the EGL transport (transport_gl.c): probe SH, the clusters' basis rows, the receivers,
 * written into the transport's cache SH buffers as lc_probes_gather writes the CPU's. The bake's
 * arrays are uploaded once at create; the basis and U (which may exceed one binding: Sponza's
 * bases are 143 MiB) are bound as windows of whole rows.
 *
 * Threads: the engine's compute thread, with the transport's context current.
 * Ownership: the transport owns the lc_probes_gl; it borrows the view. */
#ifndef LC_PROBES_GL_H
#define LC_PROBES_GL_H
#include <epoxy/gl.h>
#include <stddef.h>
#include <stdint.h>

#include "lcb/lcb.h"

typedef struct lc_probes_gl lc_probes_gl;

/* Compiles the three stages and uploads the bake's probe data. NULL with err. */
lc_probes_gl *lc_probes_gl_create(const lc_lcb_view *v, size_t bind_limit, size_t align, char *err, size_t errlen);
void lc_probes_gl_release(lc_probes_gl *g);

/* What one pass reads and writes: the transport's buffers. */
typedef struct lc_probes_gl_pass {
    GLuint radiosity, caches, cache_sh, sh9;
    uint32_t nc;         /* the cache SH's stride (bands^2) */
    const uint8_t *need; /* per cache, as lc_probes_gather's (NULL = every cluster) */
} lc_probes_gl_pass;
/* One gather (ends with its writes visible). -1 with err when the cache SH does not fit one
 * binding. */
int lc_probes_gl_gather(lc_probes_gl *g, const lc_probes_gl_pass *p, char *err, size_t errlen);

#endif
