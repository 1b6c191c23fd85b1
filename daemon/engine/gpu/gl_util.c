/* gl_util: GL compute helpers (see gl_util.h). Runs on the compute thread with the context
 * current. */
#include "gpu/gl_util.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"

/* Generated from shaders/<name>.comp by shaders/embed.cmake. */
extern const struct lc_gl_shader_entry {
    const char *name;
    const char *src;
} lc_gl_shader_table[];

const char *lc_gl_shader_source(const char *name) {
    for (const struct lc_gl_shader_entry *e = lc_gl_shader_table; e->name; e++)
        if (strcmp(e->name, name) == 0) return e->src;
    return NULL;
}

/* Fetches a shader's or program's info log into a malloc'd string (caller frees); never NULL
 * unless out of memory. */
static char *tgl_info_log(GLuint obj, int is_program) {
    GLint len = 0;
    if (is_program) glGetProgramiv(obj, GL_INFO_LOG_LENGTH, &len);
    else glGetShaderiv(obj, GL_INFO_LOG_LENGTH, &len);
    char *log = malloc((size_t)(len > 0 ? len : 1) + 1);
    if (!log) return NULL;
    log[0] = 0;
    if (len > 0) {
        if (is_program) glGetProgramInfoLog(obj, len, NULL, log);
        else glGetShaderInfoLog(obj, len, NULL, log);
    }
    /* Trailing newlines make ugly one-line errors. */
    for (size_t n = strlen(log); n > 0 && (log[n - 1] == '\n' || log[n - 1] == ' '); n--) log[n - 1] = 0;
    return log;
}

GLuint lc_gl_compile_program_defs(const char *name, const char *src, const char *defines, char *err, size_t errlen) {
    GLuint sh = 0, prog = 0;
    char *log = NULL;
    if (!src) {
        lc_set_err(err, errlen, "%s: no shader source", name);
        return 0;
    }
    /* #version must stay the first line: split there and put the defines after it. */
    const char *nl = strchr(src, '\n');
    size_t head = nl ? (size_t)(nl - src) + 1 : strlen(src);
    const char *parts[3] = {src, defines ? defines : "", src + head};
    GLint lens[3] = {(GLint)head, (GLint)strlen(parts[1]), (GLint)strlen(parts[2])};
    sh = glCreateShader(GL_COMPUTE_SHADER);
    if (!sh) {
        lc_set_err(err, errlen, "%s: glCreateShader failed (0x%x)", name, glGetError());
        goto err;
    }
    glShaderSource(sh, 3, parts, lens);
    glCompileShader(sh);
    GLint ok = 0;
    glGetShaderiv(sh, GL_COMPILE_STATUS, &ok);
    log = tgl_info_log(sh, 0);
    if (!ok) {
        lc_error("gl", "compiling %s failed:\n%s", name, log ? log : "(no log)");
        lc_set_err(err, errlen, "%s: compile failed: %s", name, log ? log : "(no log)");
        goto err;
    }
    if (log && log[0]) lc_debug("gl", "compiling %s: %s", name, log);
    free(log);
    log = NULL;
    prog = glCreateProgram();
    glAttachShader(prog, sh);
    glLinkProgram(prog);
    glGetProgramiv(prog, GL_LINK_STATUS, &ok);
    log = tgl_info_log(prog, 1);
    if (!ok) {
        lc_error("gl", "linking %s failed:\n%s", name, log ? log : "(no log)");
        lc_set_err(err, errlen, "%s: link failed: %s", name, log ? log : "(no log)");
        goto err;
    }
    if (log && log[0]) lc_debug("gl", "linking %s: %s", name, log);
    free(log);
    glDeleteShader(sh); /* flagged; freed with the program */
    return prog;
err:
    free(log);
    if (prog) glDeleteProgram(prog);
    if (sh) glDeleteShader(sh);
    return 0;
}

GLuint lc_gl_compile_program(const char *name, const char *src, char *err, size_t errlen) {
    return lc_gl_compile_program_defs(name, src, NULL, err, errlen);
}

size_t lc_gl_test_window_limit = 0;

GLuint lc_gl_buffer(size_t bytes, const void *data, const char *what, char *err, size_t errlen) {
    GLuint b = 0;
    size_t alloc = bytes < 16 ? 16 : bytes; /* a zero-size range cannot be bound */
    while (glGetError() != GL_NO_ERROR) {   /* errors of earlier calls are not ours */
    }
    glCreateBuffers(1, &b);
    glNamedBufferStorage(b, (GLsizeiptr)alloc, NULL, GL_DYNAMIC_STORAGE_BIT);
    GLenum e = glGetError();
    if (!b || e != GL_NO_ERROR) {
        lc_set_err(err, errlen, "allocating %zu bytes for %s failed (GL error 0x%x)", alloc, what, e);
        if (b) glDeleteBuffers(1, &b);
        return 0;
    }
    /* Zeroed unless fully uploaded: stages may read a buffer before its first write. The
     * finish orders the clear before the caller's uploads: on an H200 (NVIDIA 580.159) a
     * glNamedBufferSubData of the whole buffer issued right after the clear was lost (the
     * links read back as zeros). Buffers are made at create and when they grow, so the wait
     * is rare. */
    if (!data || bytes < alloc) {
        glClearNamedBufferData(b, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, NULL);
        glFinish();
    }
    if (data && bytes) glNamedBufferSubData(b, 0, (GLsizeiptr)bytes, data);
    return b;
}

void lc_gl_read(lc_gl_staging *s, GLuint src, size_t offset, size_t bytes, void *dst) {
    if (!bytes) return;
    if (s->cap < bytes) {
        lc_gl_staging_release(s);
        size_t cap = (bytes + ((size_t)1 << 20) - 1) & ~(((size_t)1 << 20) - 1);
        while (glGetError() != GL_NO_ERROR) {
        }
        glCreateBuffers(1, &s->buf);
        glNamedBufferStorage(s->buf, (GLsizeiptr)cap, NULL, GL_MAP_READ_BIT | GL_CLIENT_STORAGE_BIT);
        if (!s->buf || glGetError() != GL_NO_ERROR) {
            lc_gl_staging_release(s); /* no staging memory: read the source directly */
            glGetNamedBufferSubData(src, (GLintptr)offset, (GLsizeiptr)bytes, dst);
            return;
        }
        s->cap = cap;
    }
    glCopyNamedBufferSubData(src, s->buf, (GLintptr)offset, 0, (GLsizeiptr)bytes);
    glGetNamedBufferSubData(s->buf, 0, (GLsizeiptr)bytes, dst);
}

void lc_gl_staging_release(lc_gl_staging *s) {
    if (s->buf) glDeleteBuffers(1, &s->buf);
    s->buf = 0;
    s->cap = 0;
}

void lc_gl_bind(GLuint index, GLuint buf, size_t offset, size_t size) {
    GLint64 total = 0;
    glGetNamedBufferParameteri64v(buf, GL_BUFFER_SIZE, &total);
    if (offset >= (size_t)total) offset = 0; /* empty window: bind something valid */
    if (size > (size_t)total - offset) size = (size_t)total - offset;
    if (size > LC_GL_MAX_BINDING) size = LC_GL_MAX_BINDING;
    if (size < 16) size = 16 <= (size_t)total - offset ? 16 : (size_t)total - offset;
    glBindBufferRange(GL_SHADER_STORAGE_BUFFER, index, buf, (GLintptr)offset, (GLsizeiptr)size);
}

void lc_gl_dispatch_1d(size_t n, unsigned local) {
    if (n == 0) return;
    size_t groups = (n + local - 1) / local;
    size_t gx = groups < 65535 ? groups : 65535;
    size_t gy = (groups + gx - 1) / gx;
    glDispatchCompute((GLuint)gx, (GLuint)gy, 1);
}

int lc_gl_check(const char *stage, char *err, size_t errlen) {
    GLenum first = GL_NO_ERROR, e;
    int n = 0;
    while ((e = glGetError()) != GL_NO_ERROR && n < 16) { /* bounded: a lost context may repeat */
        if (first == GL_NO_ERROR) first = e;
        n++;
    }
    /* Without robustness (GL < 4.5, no KHR_robustness) only GL_CONTEXT_LOST can tell. */
    GLenum reset = GL_NO_ERROR;
    if (epoxy_gl_version() >= 45 || epoxy_has_gl_extension("GL_KHR_robustness")) reset = glGetGraphicsResetStatus();
    if (first == GL_CONTEXT_LOST || reset != GL_NO_ERROR) {
        lc_set_err(err, errlen, "%s: GL context lost (reset status 0x%x)", stage, reset);
        return -2;
    }
    if (first != GL_NO_ERROR) {
        lc_set_err(err, errlen, "%s: GL error 0x%x", stage, first);
        return -1;
    }
    return 0;
}
