/* drt_gl: clutter operators on GL compute (see drt_gl.h). */
#include "gpu/drt_gl.h"

#include <stdlib.h>
#include <string.h>

#include "gpu/gl_util.h"
#include "util/log.h"

#define DRT_GL_LOCAL 64 /* drt.comp's local_size_x */

typedef struct { /* drt.comp's Patch (std430, 32 bytes) */
    float albedo[3], area;
    uint32_t gather_first, gather_count, pad[2];
} drt_gl_patch;
_Static_assert(sizeof(drt_gl_patch) == 32, "std430 layout");

enum {
    DRT_GL_PATCHES,
    DRT_GL_EDIRECT,
    DRT_GL_GATHER,
    DRT_GL_PB,
    DRT_GL_PFLUX,
    DRT_GL_RECV,
    DRT_GL_ENTRIES,
    DRT_GL_INPAINT,
    DRT_GL_FROM,
    DRT_GL_NBUF
};

struct lc_drt_gl {
    GLuint prog[4]; /* DRT_STAGE 0..3 */
    GLuint buf[DRT_GL_NBUF];
    size_t bytes[DRT_GL_NBUF];
    uint64_t *serials; /* what the buffers hold */
    uint32_t n_ops, cap_ops;
    uint32_t *patch_first, *recv_first, *recv_count, *inpaint_first, *inpaint_count; /* per object */
    uint32_t n_patches;
    float *e_direct;       /* host staging of the patches' direct light */
    lc_gl_staging staging; /* the patches' B and flux read back (gl_util.h) */
};

lc_drt_gl *lc_drt_gl_create(char *err, size_t errlen) {
    lc_drt_gl *g = calloc(1, sizeof *g);
    if (!g) {
        lc_set_err(err, errlen, "drt (egl): out of memory");
        return NULL;
    }
    const char *src = lc_gl_shader_source("drt");
    for (int s = 0; s < 4; s++) {
        char defs[32], name[32];
        snprintf(defs, sizeof defs, "#define DRT_STAGE %d\n", s);
        snprintf(name, sizeof name, "drt.comp (stage %d)", s);
        if (!(g->prog[s] = lc_gl_compile_program_defs(name, src, defs, err, errlen))) {
            lc_drt_gl_release(g);
            return NULL;
        }
    }
    return g;
}

static void drt_gl_free_layout(lc_drt_gl *g) {
    free(g->serials);
    free(g->patch_first);
    free(g->recv_first);
    free(g->recv_count);
    free(g->inpaint_first);
    free(g->inpaint_count);
    free(g->e_direct);
    g->serials = NULL;
    g->patch_first = g->recv_first = g->recv_count = g->inpaint_first = g->inpaint_count = NULL;
    g->e_direct = NULL;
    g->n_ops = g->cap_ops = g->n_patches = 0;
}

void lc_drt_gl_release(lc_drt_gl *g) {
    if (!g) return;
    for (int s = 0; s < 4; s++)
        if (g->prog[s]) glDeleteProgram(g->prog[s]);
    glDeleteBuffers(DRT_GL_NBUF, g->buf); /* 0 names are ignored */
    lc_gl_staging_release(&g->staging);
    drt_gl_free_layout(g);
    free(g);
}

static int drt_gl_same(const lc_drt_gl *g, lc_drt_ops *const *ops, uint32_t n) {
    if (n != g->n_ops) return 0;
    for (uint32_t i = 0; i < n; i++)
        if (lc_drt_arrays_get(ops[i]).serial != g->serials[i]) return 0;
    return 1;
}

/* A patch source with the object's own patch index made global. */
static uint32_t drt_gl_source(uint32_t source, uint32_t patch_base) {
    return (source & LC_DRT_PATCH) ? LC_DRT_PATCH | ((source & ~LC_DRT_PATCH) + patch_base) : source;
}

/* The entries of one receiver as drt.comp reads them: e4 (source + 4 w) for a texel cache, e9
 * (source + 9 w) for a grid cache, patch sources global. Returns the floats written. */
static size_t drt_gl_entries(const lc_drt_arrays *a, const lc_drt_receiver *rc, int texel, uint32_t patch_base,
                             float *out) {
    size_t n = 0;
    for (uint32_t k = 0; k < rc->count; k++) {
        uint32_t src = texel ? a->e4[rc->first + k].source : a->e9[rc->first + k].source;
        src = drt_gl_source(src, patch_base);
        memcpy(&out[n++], &src, 4);
        if (texel) memcpy(&out[n], a->e4[rc->first + k].w, 4 * sizeof(float)), n += 4;
        else memcpy(&out[n], a->e9[rc->first + k].w, 9 * sizeof(float)), n += 9;
    }
    return n;
}

/* The host arrays of every buffer, concatenated over the objects (the caller frees host[]). */
static int drt_gl_pack(lc_drt_gl *g, lc_drt_ops *const *ops, uint32_t n, uint32_t n_texel, void *host[DRT_GL_NBUF]) {
    size_t np = 0, ng = 0, nr = 0, ne = 0, ni = 0, nf = 0;
    for (uint32_t i = 0; i < n; i++) {
        lc_drt_arrays a = lc_drt_arrays_get(ops[i]);
        np += a.n_patches;
        ng += a.patch_gather_first[a.n_patches];
        nr += a.n_receivers;
        for (uint32_t r = 0; r < a.n_receivers; r++)
            ne += (size_t)a.receivers[r].count * (a.receivers[r].cache < n_texel ? 5 : 10);
        ni += a.n_inpaint;
        nf += a.n_inpaint_from;
    }
    size_t sizes[DRT_GL_NBUF] = {
        np * sizeof(drt_gl_patch), np * 12, ng * 8, np * 12, np * 12, nr * 16, ne * 4, ni * 16, nf * 4};
    for (int b = 0; b < DRT_GL_NBUF; b++) {
        g->bytes[b] = sizes[b];
        if (!(host[b] = calloc(sizes[b] ? sizes[b] : 16, 1))) return -1;
    }
    drt_gl_patch *pt = host[DRT_GL_PATCHES];
    uint32_t *ga = host[DRT_GL_GATHER], *rv = host[DRT_GL_RECV], *ip = host[DRT_GL_INPAINT], *from = host[DRT_GL_FROM];
    float *pb = host[DRT_GL_PB], *pf = host[DRT_GL_PFLUX], *en = host[DRT_GL_ENTRIES];
    uint32_t p0 = 0, g0 = 0, r0 = 0, i0 = 0, f0 = 0;
    size_t e0 = 0;
    for (uint32_t i = 0; i < n; i++) {
        lc_drt_arrays a = lc_drt_arrays_get(ops[i]);
        g->serials[i] = a.serial;
        g->patch_first[i] = p0;
        for (uint32_t p = 0; p < a.n_patches; p++) {
            drt_gl_patch *q = &pt[p0 + p];
            memcpy(q->albedo, a.patch_albedo + 3 * (size_t)p, sizeof q->albedo);
            q->area = a.patch_area[p];
            q->gather_first = g0 + a.patch_gather_first[p];
            q->gather_count = a.patch_gather_first[p + 1] - a.patch_gather_first[p];
        }
        for (uint32_t k = 0; k < a.patch_gather_first[a.n_patches]; k++) {
            ga[2 * (size_t)(g0 + k)] = drt_gl_source(a.gather[k].source, p0);
            memcpy(&ga[2 * (size_t)(g0 + k) + 1], &a.gather[k].w, 4);
        }
        memcpy(pb + 3 * (size_t)p0, a.patch_b, (size_t)a.n_patches * 12);
        memcpy(pf + 3 * (size_t)p0, a.patch_flux, (size_t)a.n_patches * 12);
        g->recv_first[i] = r0;
        g->recv_count[i] = a.n_receivers;
        for (uint32_t r = 0; r < a.n_receivers; r++) {
            const lc_drt_receiver *rc = &a.receivers[r];
            uint32_t *rec = &rv[4 * (size_t)(r0 + r)];
            rec[0] = rc->cache;
            rec[1] = (uint32_t)e0;
            rec[2] = rc->count;
            e0 += drt_gl_entries(&a, rc, rc->cache < n_texel, p0, en + e0);
        }
        g->inpaint_first[i] = i0;
        g->inpaint_count[i] = a.n_inpaint;
        for (uint32_t k = 0; k < a.n_inpaint; k++) {
            uint32_t *rec = &ip[4 * (size_t)(i0 + k)];
            rec[0] = a.inpaint[k].cache;
            rec[1] = f0 + a.inpaint[k].first;
            rec[2] = a.inpaint[k].count;
        }
        memcpy(from + f0, a.inpaint_from, (size_t)a.n_inpaint_from * 4);
        p0 += a.n_patches;
        g0 += a.patch_gather_first[a.n_patches];
        r0 += a.n_receivers;
        i0 += a.n_inpaint;
        f0 += a.n_inpaint_from;
    }
    g->n_patches = p0;
    return e0 <= 0xFFFFFFFFu ? 0 : -1;
}

static int drt_gl_layout(lc_drt_gl *g, uint32_t n) {
    drt_gl_free_layout(g);
    size_t k = n ? n : 1;
    g->serials = calloc(k, sizeof *g->serials);
    g->patch_first = calloc(k, 4);
    g->recv_first = calloc(k, 4);
    g->recv_count = calloc(k, 4);
    g->inpaint_first = calloc(k, 4);
    g->inpaint_count = calloc(k, 4);
    g->n_ops = n;
    return g->serials && g->patch_first && g->recv_first && g->recv_count && g->inpaint_first && g->inpaint_count ? 0
                                                                                                                  : -1;
}

int lc_drt_gl_upload(lc_drt_gl *g, lc_drt_ops *const *ops, uint32_t n, uint32_t n_texel, size_t bind_limit, char *err,
                     size_t errlen) {
    static const char *const what[DRT_GL_NBUF] = {"patches",        "patch direct light", "patch gathers", "patch B",
                                                  "patch flux",     "receivers",          "entries",       "inpaint",
                                                  "inpaint sources"};
    if (!drt_gl_same(g, ops, n)) {
        void *host[DRT_GL_NBUF] = {0};
        int rc = -1;
        glDeleteBuffers(DRT_GL_NBUF, g->buf);
        memset(g->buf, 0, sizeof g->buf);
        if (drt_gl_layout(g, n) != 0 || drt_gl_pack(g, ops, n, n_texel, host) != 0) {
            lc_set_err(err, errlen, "drt (egl): out of memory packing the clutter operators");
            goto done;
        }
        for (int b = 0; b < DRT_GL_NBUF; b++) {
            if (g->bytes[b] > bind_limit) {
                lc_set_err(err, errlen,
                           "drt (egl): the clutter operators' %s take %zu MiB, over the %zu MiB binding limit", what[b],
                           g->bytes[b] >> 20, bind_limit >> 20);
                goto done;
            }
            if (!(g->buf[b] = lc_gl_buffer(g->bytes[b], host[b], what[b], err, errlen))) goto done;
        }
        if (!(g->e_direct = malloc(((size_t)g->n_patches + 1) * 12))) {
            lc_set_err(err, errlen, "drt (egl): out of memory");
            goto done;
        }
        rc = 0;
    done:
        for (int b = 0; b < DRT_GL_NBUF; b++) free(host[b]);
        if (rc != 0) {
            drt_gl_free_layout(g); /* the next run packs again */
            return -1;
        }
    }
    for (uint32_t i = 0; i < n; i++) {
        lc_drt_arrays a = lc_drt_arrays_get(ops[i]);
        memcpy(g->e_direct + 3 * (size_t)g->patch_first[i], a.patch_e_direct, (size_t)a.n_patches * 12);
    }
    if (g->n_patches)
        glNamedBufferSubData(g->buf[DRT_GL_EDIRECT], 0, (GLsizeiptr)((size_t)g->n_patches * 12), g->e_direct);
    return 0;
}

static void drt_gl_bind(const lc_drt_gl *g, GLuint index, int b) { lc_gl_bind(index, g->buf[b], 0, g->bytes[b]); }

void lc_drt_gl_apply(lc_drt_gl *g, const lc_drt_gl_pass *p) {
    if (!g->n_ops) return;
    /* 0: the patches' B from the direct light and this pass's gather; 1: their flux */
    GLuint s0 = g->prog[0], s1 = g->prog[1], s2 = g->prog[2], s3 = g->prog[3];
    glUseProgram(s0);
    drt_gl_bind(g, 0, DRT_GL_PATCHES);
    drt_gl_bind(g, 1, DRT_GL_EDIRECT);
    drt_gl_bind(g, 2, DRT_GL_GATHER);
    lc_gl_bind(3, p->node_flux, 0, (size_t)p->n_nodes * 12);
    drt_gl_bind(g, 4, DRT_GL_PB);
    drt_gl_bind(g, 5, DRT_GL_PFLUX);
    glProgramUniform1ui(s0, 0, g->n_patches);
    glProgramUniform1i(s0, 1, p->ycocg);
    lc_gl_dispatch_1d(g->n_patches, DRT_GL_LOCAL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    glUseProgram(s1);
    glProgramUniform1ui(s1, 0, g->n_patches);
    lc_gl_dispatch_1d(g->n_patches, DRT_GL_LOCAL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    /* 2: the receivers, 3: the covered caches; object by object, window by window */
    const size_t sh_bytes = (size_t)p->nc * 12;
    for (int stage = 2; stage <= 3; stage++) {
        GLuint s = stage == 2 ? s2 : s3;
        glUseProgram(s);
        lc_gl_bind(0, p->caches, 0, (size_t)p->n_caches * 32);
        lc_gl_bind(2, p->sh9, 0, (size_t)p->n_caches * 108);
        if (stage == 2) {
            lc_gl_bind(3, p->node_flux, 0, (size_t)p->n_nodes * 12);
            drt_gl_bind(g, 4, DRT_GL_RECV);
            drt_gl_bind(g, 5, DRT_GL_PFLUX);
            drt_gl_bind(g, 6, DRT_GL_ENTRIES);
            glProgramUniform1i(s, 1, p->ycocg);
        } else {
            drt_gl_bind(g, 4, DRT_GL_INPAINT);
            drt_gl_bind(g, 5, DRT_GL_FROM);
        }
        glProgramUniform1ui(s, 5, p->nc);
        glProgramUniform1ui(s, 6, p->n_texel_caches);
        glProgramUniform1i(s, 7, p->texel_lo);
        glProgramUniform1i(s, 8, p->texel_nc);
        glProgramUniform1i(s, 9, p->grid_nc);
        glProgramUniform1i(s, 10, p->last);
        for (uint32_t c0 = 0; c0 < p->n_caches; c0 += p->chunk) {
            uint32_t cnt = p->n_caches - c0 < p->chunk ? p->n_caches - c0 : p->chunk;
            lc_gl_bind(1, p->cache_sh, c0 * sh_bytes, cnt * sh_bytes);
            glProgramUniform1ui(s, 3, c0);
            glProgramUniform1ui(s, 4, cnt);
            for (uint32_t i = 0; i < g->n_ops; i++) {
                uint32_t first = stage == 2 ? g->recv_first[i] : g->inpaint_first[i],
                         count = stage == 2 ? g->recv_count[i] : g->inpaint_count[i];
                if (!count) continue;
                glProgramUniform1ui(s, 0, count);
                glProgramUniform1ui(s, 2, first);
                lc_gl_dispatch_1d(count, DRT_GL_LOCAL);
                glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
            }
        }
    }
}

void lc_drt_gl_read_back(lc_drt_gl *g, lc_drt_ops *const *ops, uint32_t n) {
    if (!g->n_ops || !drt_gl_same(g, ops, n)) return;
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    for (uint32_t i = 0; i < n; i++) {
        lc_drt_arrays a = lc_drt_arrays_get(ops[i]);
        size_t off = (size_t)g->patch_first[i] * 12;
        lc_gl_read(&g->staging, g->buf[DRT_GL_PB], off, (size_t)a.n_patches * 12, a.patch_b);
        lc_gl_read(&g->staging, g->buf[DRT_GL_PFLUX], off, (size_t)a.n_patches * 12, a.patch_flux);
    }
}
