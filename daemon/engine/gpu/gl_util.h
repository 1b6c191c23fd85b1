/* gl_util: GL compute helpers for the EGL backend: program compile/link with the status
 * always checked and the info log logged, SSBO creation and windowed bindings, 2-D dispatch,
 * error checks, and the shaders embedded at build time (shaders/<name>.comp).
 *
 * Threads: every function needs a current GL context, i.e. runs on the engine's compute
 * thread that made it current. */
#ifndef LC_GL_UTIL_H
#define LC_GL_UTIL_H
#include <epoxy/gl.h>
#include <stddef.h>

/* Largest SSBO range bound at once: llvmpipe's MAX_SHADER_STORAGE_BLOCK_SIZE and GL's
 * guaranteed minimum-ish; larger buffers are bound as windows. */
#define LC_GL_MAX_BINDING ((size_t)128 << 20)
/* Tests only: caps the bytes of one window of the per-cache arrays (links, full cache SH) an
 * engine created afterwards uses, so a small bake runs the many-window paths. 0: the device's. */
extern size_t lc_gl_test_window_limit;

/* The embedded source of shaders/<name>.comp, or NULL. */
const char *lc_gl_shader_source(const char *name);

/* Compiles one compute shader and links it into a program. `defines` (may be NULL) is
 * inserted after the #version line. Returns the program, or 0 with err = "<name>: <info log>"
 * (the log is also logged with lc_error). */
GLuint lc_gl_compile_program_defs(const char *name, const char *src, const char *defines, char *err, size_t errlen);
/* Same without defines; also the test hook for broken sources. */
GLuint lc_gl_compile_program(const char *name, const char *src, char *err, size_t errlen);

/* An immutable-size SSBO of `bytes` (at least 16 so it can always be bound) with optional
 * initial data; 0 with err on failure (out of memory). */
GLuint lc_gl_buffer(size_t bytes, const void *data, const char *what, char *err, size_t errlen);

/* Binds [offset, offset + size) of buf to SSBO binding `index`, clamped to the buffer's end
 * and to the binding limit (at least 16 bytes so empty arrays still bind). */
void lc_gl_bind(GLuint index, GLuint buf, size_t offset, size_t size);

/* glDispatchCompute over n invocations of a local_size_x = `local` shader: groups spread
 * over x and y so no axis exceeds 65535. Shaders rebuild the index as
 * gid.y * num_groups.x * local + gid.x and must bounds-check it. */
void lc_gl_dispatch_1d(size_t n, unsigned local);

/* Read-back through a staging buffer. Reading a shader-written buffer straight back with
 * glGetBufferSubData every relight makes NVIDIA's driver move that buffer from video to host
 * memory ("Buffer performance warning ... copied/moved from VIDEO memory to HOST memory",
 * measured on an H200: every shader access then crosses PCIe). The copy into a
 * client-storage buffer keeps the source in video memory; on llvmpipe it is one memcpy more.
 * One staging buffer per module (reads are sequential); it grows to the largest read. */
typedef struct lc_gl_staging {
    GLuint buf;
    size_t cap;
} lc_gl_staging;
/* Copies [offset, offset + bytes) of src into dst through s. */
void lc_gl_read(lc_gl_staging *s, GLuint src, size_t offset, size_t bytes, void *dst);
void lc_gl_staging_release(lc_gl_staging *s);

/* Drains glGetError; 0 when clean, -1 with err = "<stage>: GL error 0x..", or -2 when the
 * context was lost (GL_CONTEXT_LOST or a graphics reset status). */
int lc_gl_check(const char *stage, char *err, size_t errlen);

#endif
