/* transport_gl: the EGL/GL 4.3 compute implementation of the transport pipeline.
 * Not built yet: creation fails cleanly so AUTO falls back to the CPU backend. */
#include <stdlib.h>

#include "engine/transport.h"
#include "util/log.h"

static void *tgl_create(const lc_lcb_view *v, int threads, char *err, size_t errlen) {
    (void)v;
    (void)threads;
    lc_set_err(err, errlen, "the EGL backend is not implemented in this build");
    return NULL;
}

static void tgl_release(void *impl) { (void)impl; }

static int tgl_run(void *impl, const lc_transport_input *in, lc_engine_frame *frame, char *err, size_t errlen) {
    (void)impl;
    (void)in;
    (void)frame;
    lc_set_err(err, errlen, "the EGL backend is not implemented in this build");
    return -1;
}

const lc_transport_ops lc_transport_egl = {"egl", tgl_create, tgl_release, tgl_run};
