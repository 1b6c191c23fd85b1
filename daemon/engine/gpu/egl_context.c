/* egl_context: headless EGL display + GL 4.3 core context (see egl_context.h). */
#include "gpu/egl_context.h"

#include <dlfcn.h>
#include <epoxy/egl.h>
#include <link.h>
#include <epoxy/gl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"

struct lc_egl_context {
    EGLDisplay dpy;
    EGLContext ctx;
    EGLSurface surf; /* EGL_NO_SURFACE unless the driver lacks surfaceless contexts */
    int software;
    char desc[256];
};

/* EGL displays are per-process singletons per (platform, device): two lucent contexts on
 * one display share it, and eglTerminate would pull it from under the other. Refcount. */
#define TGL_MAX_DISPLAYS 8
static pthread_mutex_t tgl_dpy_lock = PTHREAD_MUTEX_INITIALIZER;
static struct {
    EGLDisplay dpy;
    int refs;
} tgl_dpys[TGL_MAX_DISPLAYS];

static int tgl_display_ref(EGLDisplay dpy) {
    pthread_mutex_lock(&tgl_dpy_lock);
    int slot = -1;
    for (int i = 0; i < TGL_MAX_DISPLAYS; i++) {
        if (tgl_dpys[i].dpy == dpy && tgl_dpys[i].refs > 0) {
            slot = i;
            break;
        }
        if (slot < 0 && tgl_dpys[i].refs == 0) slot = i;
    }
    int ok = slot >= 0;
    if (ok) {
        if (tgl_dpys[slot].refs == 0) tgl_dpys[slot].dpy = dpy;
        tgl_dpys[slot].refs++;
    }
    pthread_mutex_unlock(&tgl_dpy_lock);
    return ok ? 0 : -1;
}

/* Drops one reference; terminates the display with the last one. */
static void tgl_display_unref(EGLDisplay dpy) {
    int last = 0;
    pthread_mutex_lock(&tgl_dpy_lock);
    for (int i = 0; i < TGL_MAX_DISPLAYS; i++)
        if (tgl_dpys[i].dpy == dpy && tgl_dpys[i].refs > 0) {
            last = --tgl_dpys[i].refs == 0;
            break;
        }
    pthread_mutex_unlock(&tgl_dpy_lock);
    if (last) eglTerminate(dpy);
}

/* GL_KHR_debug callback: runs on the thread issuing the GL call (synchronous output). */
static void GLAPIENTRY tgl_debug_cb(GLenum source, GLenum type, GLuint id, GLenum severity, GLsizei length,
                                    const GLchar *msg, const void *user) {
    (void)source;
    (void)length;
    (void)user;
    if (severity == GL_DEBUG_SEVERITY_NOTIFICATION) {
        lc_debug("gl", "debug 0x%x id %u: %s", type, id, msg);
    } else if (type == GL_DEBUG_TYPE_ERROR || severity == GL_DEBUG_SEVERITY_HIGH) {
        lc_error("gl", "debug 0x%x id %u: %s", type, id, msg);
    } else {
        lc_warn("gl", "debug 0x%x id %u: %s", type, id, msg);
    }
}

/* Tries to initialise dpy and create a current GL 4.3 core context on it. 0 or -1 with err;
 * on success c owns one display reference. */
static int tgl_try_display(lc_egl_context *c, EGLDisplay dpy, const char *how, int device_software, char *err,
                           size_t errlen) {
    EGLint major = 0, minor = 0;
    if (dpy == EGL_NO_DISPLAY) {
        lc_set_err(err, errlen, "%s: no EGL display (0x%x)", how, eglGetError());
        return -1;
    }
    if (!eglInitialize(dpy, &major, &minor)) {
        lc_set_err(err, errlen, "%s: eglInitialize failed (0x%x)", how, eglGetError());
        return -1;
    }
    if (tgl_display_ref(dpy) != 0) {
        lc_set_err(err, errlen, "%s: too many EGL displays in use", how);
        return -1; /* not terminated: another context may use it */
    }
    c->dpy = dpy;
    if (!eglBindAPI(EGL_OPENGL_API)) {
        lc_set_err(err, errlen, "%s: desktop OpenGL is not supported (eglBindAPI 0x%x)", how, eglGetError());
        goto err;
    }
    /* Configless + surfaceless is the normal path; old drivers get a config and a pbuffer. */
    EGLConfig cfg = EGL_NO_CONFIG_KHR;
    int configless = epoxy_has_egl_extension(dpy, "EGL_KHR_no_config_context") ||
        epoxy_has_egl_extension(dpy, "EGL_MESA_configless_context");
    int surfaceless = epoxy_has_egl_extension(dpy, "EGL_KHR_surfaceless_context");
    if (!configless || !surfaceless) {
        const EGLint want[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
        EGLint n = 0;
        if (!eglChooseConfig(dpy, want, &cfg, 1, &n) || n < 1) {
            lc_set_err(err, errlen, "%s: no EGL config for desktop GL pbuffers (0x%x)", how, eglGetError());
            goto err;
        }
    }
    const int use_debug = epoxy_egl_version(dpy) >= 15;
    EGLint attrs[] = {EGL_CONTEXT_MAJOR_VERSION,
                      4,
                      EGL_CONTEXT_MINOR_VERSION,
                      3,
                      EGL_CONTEXT_OPENGL_PROFILE_MASK,
                      EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                      use_debug ? EGL_CONTEXT_OPENGL_DEBUG : EGL_NONE,
                      EGL_TRUE,
                      EGL_NONE};
    c->ctx = eglCreateContext(dpy, cfg, EGL_NO_CONTEXT, attrs);
    if (c->ctx == EGL_NO_CONTEXT && use_debug) { /* some drivers refuse debug contexts */
        attrs[6] = EGL_NONE;
        c->ctx = eglCreateContext(dpy, cfg, EGL_NO_CONTEXT, attrs);
    }
    if (c->ctx == EGL_NO_CONTEXT) {
        lc_set_err(err, errlen, "%s: no OpenGL 4.3 core context (eglCreateContext 0x%x)", how, eglGetError());
        goto err;
    }
    if (!surfaceless) {
        const EGLint pb[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
        c->surf = eglCreatePbufferSurface(dpy, cfg, pb);
        if (c->surf == EGL_NO_SURFACE) {
            lc_set_err(err, errlen, "%s: eglCreatePbufferSurface failed (0x%x)", how, eglGetError());
            goto err;
        }
    }
    if (!eglMakeCurrent(dpy, c->surf, c->surf, c->ctx)) {
        lc_set_err(err, errlen, "%s: eglMakeCurrent failed (0x%x)", how, eglGetError());
        goto err;
    }
    if (epoxy_gl_version() < 43) { /* 4.3 requested; drivers may return more, never less */
        lc_set_err(err, errlen, "%s: OpenGL %d.%d < 4.3", how, epoxy_gl_version() / 10, epoxy_gl_version() % 10);
        goto err;
    }
    GLint flags = 0;
    glGetIntegerv(GL_CONTEXT_FLAGS, &flags);
    if ((flags & GL_CONTEXT_FLAG_DEBUG_BIT) && epoxy_has_gl_extension("GL_KHR_debug")) {
        glEnable(GL_DEBUG_OUTPUT);
        glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS); /* the callback runs on this thread, in the call */
        glDebugMessageCallback(tgl_debug_cb, NULL);
    }
    const char *renderer = (const char *)glGetString(GL_RENDERER);
    const char *version = (const char *)glGetString(GL_VERSION);
    if (!renderer) renderer = "?";
    c->software = device_software || strstr(renderer, "llvmpipe") || strstr(renderer, "softpipe");
    snprintf(c->desc, sizeof c->desc, "%s (%s) via %s", renderer, version ? version : "?", how);
    return 0;
err:
    eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (c->surf != EGL_NO_SURFACE) eglDestroySurface(dpy, c->surf);
    if (c->ctx != EGL_NO_CONTEXT) eglDestroyContext(dpy, c->ctx);
    c->surf = EGL_NO_SURFACE;
    c->ctx = EGL_NO_CONTEXT;
    c->dpy = EGL_NO_DISPLAY;
    tgl_display_unref(dpy);
    return -1;
}

static int tgl_count_module(struct dl_phdr_info *info, size_t size, void *arg) {
    (void)info, (void)size;
    ++*(size_t *)arg;
    return 0;
}

typedef struct {
    size_t index, first;
} tgl_pin_walk;

static int tgl_pin_module(struct dl_phdr_info *info, size_t size, void *arg) {
    (void)size;
    tgl_pin_walk *w = arg;
    if (w->index++ < w->first || !info->dlpi_name[0]) return 0;
    void *h = dlopen(info->dlpi_name, RTLD_LAZY | RTLD_NOLOAD | RTLD_NODELETE);
    if (h) dlclose(h); /* the NODELETE flag stays */
    return 0;
}

/* Keeps the libraries EGL loaded (libEGL, the vendor library, Mesa's driver) mapped until the
 * process exits: eglTerminate unloads the driver, and Mesa 22.3.6-1+deb12u2 then leaves
 * allocations only its globals pointed to, which LeakSanitizer reports as leaks of an
 * unknown module (no symbols to suppress them by). Mapped, they stay reachable. */
static void tgl_pin_modules_since(size_t first) {
    tgl_pin_walk w = {0, first};
    dl_iterate_phdr(tgl_pin_module, &w);
}

lc_egl_context *lc_egl_create(char *err, size_t errlen) {
    size_t modules_before = 0;
    dl_iterate_phdr(tgl_count_module, &modules_before);
    lc_egl_context *c = calloc(1, sizeof *c);
    EGLDeviceEXT *devs = NULL;
    char why[512] = "", one[256];
    if (!c) {
        lc_set_err(err, errlen, "out of memory");
        return NULL;
    }
    c->dpy = EGL_NO_DISPLAY;
    c->ctx = EGL_NO_CONTEXT;
    c->surf = EGL_NO_SURFACE;
    /* epoxy dlopens libEGL lazily; without it every EGL call would abort the process. */
    if (!epoxy_has_egl()) {
        lc_set_err(err, errlen, "libEGL is not available");
        goto err;
    }
    if (epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_EXT_device_enumeration") &&
        epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_EXT_platform_device")) {
        EGLint n = 0;
        if (eglQueryDevicesEXT(0, NULL, &n) && n > 0) {
            devs = calloc((size_t)n, sizeof *devs);
            if (!devs || !eglQueryDevicesEXT(n, devs, &n)) n = 0;
        }
        /* Two rounds: hardware devices first, then software ones. */
        for (int round = 0; round < 2; round++)
            for (EGLint i = 0; i < n; i++) {
                const char *ext = eglQueryDeviceStringEXT(devs[i], EGL_EXTENSIONS);
                int sw = ext && strstr(ext, "EGL_MESA_device_software") != NULL;
                if (sw != round) continue;
                EGLDisplay dpy = eglGetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT, devs[i], NULL);
                char how[64];
                snprintf(how, sizeof how, "%s EGL device %d", sw ? "software" : "hardware", (int)i);
                if (tgl_try_display(c, dpy, how, sw, one, sizeof one) == 0) goto done;
                lc_debug("egl", "%s", one);
                snprintf(why, sizeof why, "%s", one);
            }
    }
    if (epoxy_has_egl_extension(EGL_NO_DISPLAY, "EGL_MESA_platform_surfaceless")) {
        EGLDisplay dpy = eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL);
        if (tgl_try_display(c, dpy, "surfaceless platform", 0, one, sizeof one) == 0) goto done;
        snprintf(why, sizeof why, "%s", one);
    }
    lc_set_err(err, errlen, "no usable EGL display%s%s", why[0] ? ": " : "", why);
    goto err;
done:
    free(devs);
    tgl_pin_modules_since(modules_before);
    lc_info("egl", "context: %s%s", c->desc, c->software ? " [software rasterizer]" : "");
    return c;
err:
    free(devs);
    free(c);
    tgl_pin_modules_since(modules_before);
    return NULL;
}

int lc_egl_make_current(lc_egl_context *c, char *err, size_t errlen) {
    if (eglGetCurrentContext() == c->ctx) return 0;
    if (!eglMakeCurrent(c->dpy, c->surf, c->surf, c->ctx)) {
        lc_set_err(err, errlen, "eglMakeCurrent failed (0x%x)", eglGetError());
        return -1;
    }
    return 0;
}

int lc_egl_is_software(const lc_egl_context *c) { return c->software; }

const char *lc_egl_description(const lc_egl_context *c) { return c->desc; }

void lc_egl_release(lc_egl_context *c) {
    if (!c) return;
    eglMakeCurrent(c->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (c->surf != EGL_NO_SURFACE) eglDestroySurface(c->dpy, c->surf);
    eglDestroyContext(c->dpy, c->ctx);
    /* The thread's EGL state (bound API, last error) is per-thread and freed with it. */
    tgl_display_unref(c->dpy);
    free(c);
}
