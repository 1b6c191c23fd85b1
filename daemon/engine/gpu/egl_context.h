/* egl_context: a headless EGL display + desktop GL 4.3 core context for compute.
 * Device order: a hardware EGL device (EGL_EXT_device_enumeration + EGL_EXT_platform_device),
 * then Mesa's software device, then EGL_PLATFORM_SURFACELESS_MESA. The context is a debug
 * context when the driver allows it, with GL_KHR_debug messages routed to the lucent log.
 *
 * Threads: a context is current on one thread at a time; every function below runs on the
 * thread that uses the context (the engine's compute thread) and makes it current there.
 * Ownership: lc_egl_create returns a context owned by the caller; lc_egl_release frees it
 * (and terminates the EGL display when no other lucent context still uses it). */
#ifndef LC_EGL_CONTEXT_H
#define LC_EGL_CONTEXT_H
#include <stddef.h>

typedef struct lc_egl_context lc_egl_context;

/* Creates a context and makes it current on the calling thread. NULL with err set when no
 * EGL display / GL 4.3 context can be had. */
lc_egl_context *lc_egl_create(char *err, size_t errlen);
/* Makes it current on the calling thread (a no-op when it already is). 0 or -1 with err. */
int lc_egl_make_current(lc_egl_context *c, char *err, size_t errlen);
/* 1 when the device is a software rasterizer (EGL_MESA_device_software, or GL_RENDERER
 * naming llvmpipe/softpipe). */
int lc_egl_is_software(const lc_egl_context *c);
/* "GL_RENDERER (GL_VERSION) via <device|software device|surfaceless>", for logs. */
const char *lc_egl_description(const lc_egl_context *c);
void lc_egl_release(lc_egl_context *c);

#endif
