/* probes_gl: the probes solver on GL compute (probes_gl.h). Compute thread. */
#include "gpu/probes_gl.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine/probes.h"
#include "gpu/gl_util.h"
#include "util/log.h"

#define PGL_LOCAL 64

enum {
    PGL_HITS,
    PGL_RAY_SH,
    PGL_LAMBDA,
    PGL_BASIS_ROWS,
    PGL_BASIS,
    PGL_PROBES,
    PGL_B,
    PGL_ROWS,
    PGL_ROW_B,
    PGL_U,
    PGL_ACTIVE,
    PGL_UNSEEN_FIRST,
    PGL_UNSEEN,
    PGL_NBUF
};

struct lc_probes_gl {
    const lc_lcb_view *v;
    GLuint prog[3];
    GLuint buf[PGL_NBUF];
    uint32_t nc, n_basis_rows;
    size_t bind_limit, align;
    uint64_t *basis_start, *u_start; /* per basis row / receiver row: its first float */
    uint32_t *basis_len, *u_len;     /* ... and its floats */
    uint32_t *active;                /* per cluster, uploaded each gather (lc_probes_active_clusters) */
};

void lc_probes_gl_release(lc_probes_gl *g) {
    if (!g) return;
    for (int s = 0; s < 3; s++)
        if (g->prog[s]) glDeleteProgram(g->prog[s]);
    glDeleteBuffers(PGL_NBUF, g->buf); /* 0 names are ignored */
    free(g->basis_start);
    free(g->u_start);
    free(g->basis_len);
    free(g->u_len);
    free(g->active);
    free(g);
}

/* PRUF/PRUS as they are; a bake without them gets rows of no entries (stage 2 reads the same). */
static int pgl_upload_unseen(lc_probes_gl *g, char *err, size_t errlen) {
    const lc_lcb_view *v = g->v;
    const uint32_t n_rows = v->probe_header->n_rows;
    const size_t first_bytes = ((size_t)n_rows + 1) * 4;
    const uint32_t n = v->probe_unseen_first ? v->probe_unseen_first[n_rows] : 0;
    if (first_bytes > g->bind_limit || (size_t)n * 8 > g->bind_limit) {
        lc_set_err(err, errlen, "probes (egl): %u unseen-ray entries over %u rows are over one binding (%zu bytes)", n,
                   n_rows, g->bind_limit);
        return -1;
    }
    uint32_t *zeros = v->probe_unseen_first ? NULL : calloc((size_t)n_rows + 1, 4);
    if (!v->probe_unseen_first && !zeros) {
        lc_set_err(err, errlen, "probes (egl): out of memory");
        return -1;
    }
    const uint32_t *first = v->probe_unseen_first ? v->probe_unseen_first : zeros;
    const uint64_t none = 0;
    g->buf[PGL_UNSEEN_FIRST] = lc_gl_buffer(first_bytes, first, "probe unseen rows", err, errlen);
    g->buf[PGL_UNSEEN] = g->buf[PGL_UNSEEN_FIRST]
        ? lc_gl_buffer(n ? (size_t)n * 8 : 8, n ? (const void *)v->probe_unseen : &none, "probe unseen rays", err,
                       errlen)
        : 0;
    free(zeros);
    return g->buf[PGL_UNSEEN] ? 0 : -1;
}

/* The per-row records the stages index: basis rows (offset, first probe, probes) and receiver
 * rows (cache, coeff, U offset; rank, first basis row). -1 out of memory or GL. */
static int pgl_upload_rows(lc_probes_gl *g, char *err, size_t errlen) {
    const lc_lcb_view *v = g->v;
    const lc_lcb_probe_header *h = v->probe_header;
    uint32_t nb = 0;
    for (uint32_t c = 0; c < h->n_clusters; c++) nb += v->probe_clusters[c].rank;
    g->n_basis_rows = nb;
    uint32_t(*brow)[4] = calloc((size_t)nb + 1, sizeof *brow);
    uint32_t(*rows)[4] = calloc((size_t)h->n_rows + 1, sizeof *rows);
    uint32_t(*row_b)[2] = calloc((size_t)h->n_rows + 1, sizeof *row_b);
    g->basis_start = calloc((size_t)nb + 1, sizeof *g->basis_start);
    g->basis_len = calloc((size_t)nb + 1, sizeof *g->basis_len);
    g->u_start = calloc((size_t)h->n_rows + 1, sizeof *g->u_start);
    g->u_len = calloc((size_t)h->n_rows + 1, sizeof *g->u_len);
    g->active = calloc((size_t)h->n_clusters + 1, sizeof *g->active);
    int rc = -1;
    if (!brow || !rows || !row_b || !g->basis_start || !g->basis_len || !g->u_start || !g->u_len || !g->active) {
        lc_set_err(err, errlen, "probes (egl): out of memory");
        goto out;
    }
    for (uint32_t c = 0, at = 0; c < h->n_clusters; c++) {
        const lc_lcb_probe_cluster *cl = &v->probe_clusters[c];
        const uint32_t cols = cl->n_probes * g->nc, first = at;
        for (uint32_t r = 0; r < cl->rank; r++, at++) {
            g->basis_start[at] = cl->basis_offset + (uint64_t)r * cols;
            g->basis_len[at] = cols;
            brow[at][0] = (uint32_t)g->basis_start[at];
            brow[at][1] = cl->first_probe;
            brow[at][2] = cl->n_probes;
            brow[at][3] = c;
        }
        for (uint32_t i = 0; i < cl->n_rows; i++) {
            uint32_t row = cl->first_row + i;
            g->u_start[row] = cl->u_offset + (uint64_t)i * cl->rank;
            g->u_len[row] = cl->rank;
            rows[row][0] = v->probe_rows[row].cache;
            rows[row][1] = v->probe_rows[row].coeff;
            rows[row][2] = (uint32_t)g->u_start[row];
            rows[row][3] = c;
            row_b[row][0] = cl->rank;
            row_b[row][1] = first;
        }
    }
    if (v->n_probe_basis > UINT32_MAX || v->n_probe_u > UINT32_MAX) {
        lc_set_err(err, errlen, "probes (egl): more than 2^32 basis or U floats");
        goto out;
    }
    if (pgl_upload_unseen(g, err, errlen) != 0) goto out;
    if (!(g->buf[PGL_BASIS_ROWS] = lc_gl_buffer((size_t)nb * 16, brow, "probe basis rows", err, errlen)) ||
        !(g->buf[PGL_ROWS] = lc_gl_buffer((size_t)h->n_rows * 16, rows, "probe rows", err, errlen)) ||
        !(g->buf[PGL_ROW_B] = lc_gl_buffer((size_t)h->n_rows * 8, row_b, "probe row clusters", err, errlen)) ||
        !(g->buf[PGL_B] = lc_gl_buffer((size_t)nb * 12, NULL, "probe cluster basis", err, errlen)) ||
        !(g->buf[PGL_ACTIVE] = lc_gl_buffer((size_t)h->n_clusters * 4, NULL, "active clusters", err, errlen)))
        goto out;
    rc = 0;
out:
    free(brow);
    free(rows);
    free(row_b);
    return rc;
}

lc_probes_gl *lc_probes_gl_create(const lc_lcb_view *v, size_t bind_limit, size_t align, char *err, size_t errlen) {
    const lc_lcb_probe_header *h = v->probe_header;
    if (!h) {
        lc_set_err(err, errlen, "probes (egl): the bake has no probes solver");
        return NULL;
    }
    lc_probes_gl *g = calloc(1, sizeof *g);
    float *ray_sh = NULL;
    if (!g) goto oom;
    g->v = v;
    g->nc = h->sh_bands * h->sh_bands;
    g->bind_limit = bind_limit;
    g->align = align ? align : 1;
    const char *src = lc_gl_shader_source("probes");
    for (int s = 0; s < 3; s++) {
        char defs[40], name[40];
        snprintf(defs, sizeof defs, "#define PROBES_STAGE %d\n", s);
        snprintf(name, sizeof name, "probes.comp (stage %d)", s);
        if (!(g->prog[s] = lc_gl_compile_program_defs(name, src, defs, err, errlen))) goto fail;
    }
    ray_sh = malloc((size_t)h->n_rays * g->nc * sizeof *ray_sh);
    if (!ray_sh) goto oom;
    lc_probes_ray_sh(h, ray_sh); /* the CPU backend's table */
    const size_t hits = (size_t)h->n_probes * h->n_rays * 4, lambda = (size_t)h->n_probes * 3 * g->nc * 4;
    if (hits > bind_limit || lambda > bind_limit || v->n_probe_cluster_probes * 4 > bind_limit) {
        lc_set_err(err, errlen, "probes (egl): %u probes x %u rays are over one binding (%zu bytes)", h->n_probes,
                   h->n_rays, bind_limit);
        goto fail;
    }
    if (!(g->buf[PGL_HITS] = lc_gl_buffer(hits, v->probe_hits, "probe hits", err, errlen)) ||
        !(g->buf[PGL_RAY_SH] = lc_gl_buffer((size_t)h->n_rays * g->nc * 4, ray_sh, "probe ray SH", err, errlen)) ||
        !(g->buf[PGL_LAMBDA] = lc_gl_buffer(lambda, NULL, "probe SH", err, errlen)) ||
        !(g->buf[PGL_BASIS] = lc_gl_buffer(v->n_probe_basis * 4, v->probe_basis, "probe bases", err, errlen)) ||
        !(g->buf[PGL_PROBES] =
              lc_gl_buffer(v->n_probe_cluster_probes * 4, v->probe_cluster_probes, "cluster probes", err, errlen)) ||
        !(g->buf[PGL_U] = lc_gl_buffer(v->n_probe_u * 4, v->probe_u, "probe U", err, errlen)))
        goto fail;
    if (pgl_upload_rows(g, err, errlen) != 0) goto fail;
    free(ray_sh);
    return g;
oom:
    lc_set_err(err, errlen, "probes (egl): out of memory");
fail:
    free(ray_sh);
    lc_probes_gl_release(g);
    return NULL;
}

/* Dispatches `prog` over items [0, n) in windows of `buf` (bound at `binding`): each window
 * starts at an aligned float offset (uniform 3) and holds whole items (start[i], len[i]
 * floats); uniform 2 = the window's first item. */
static void pgl_windows(const lc_probes_gl *g, GLuint prog, GLuint buf, GLuint binding, uint32_t n,
                        const uint64_t *start, const uint32_t *len) {
    const size_t per_align = g->align % 4 == 0 ? g->align / 4 : g->align; /* floats per alignment step */
    for (uint32_t i0 = 0; i0 < n;) {
        uint64_t base = start[i0] / per_align * per_align, end = start[i0] + len[i0];
        uint32_t i1 = i0 + 1;
        while (i1 < n && (start[i1] + len[i1] - base) * 4 <= g->bind_limit) {
            if (start[i1] + len[i1] > end) end = start[i1] + len[i1];
            i1++;
        }
        lc_gl_bind(binding, buf, (size_t)base * 4, (size_t)(end - base) * 4);
        glProgramUniform1ui(prog, 0, i1 - i0);
        glProgramUniform1ui(prog, 2, i0);
        glProgramUniform1ui(prog, 3, (GLuint)base);
        lc_gl_dispatch_1d(i1 - i0, PGL_LOCAL);
        i0 = i1;
    }
}

int lc_probes_gl_gather(lc_probes_gl *g, const lc_probes_gl_pass *p, char *err, size_t errlen) {
    const lc_lcb_view *v = g->v;
    const lc_lcb_probe_header *h = v->probe_header;
    const size_t sh_bytes = (size_t)v->n_caches * p->nc * 12;
    if (sh_bytes > g->bind_limit) {
        lc_set_err(err, errlen, "probes (egl): the cache SH (%zu bytes) is over one binding; lower /settings/bands",
                   sh_bytes);
        return -1;
    }
    if (p->need) {
        lc_probes_active_clusters(v, p->need, g->active);
    } else {
        for (uint32_t c = 0; c < h->n_clusters; c++) g->active[c] = 1;
    }
    glNamedBufferSubData(g->buf[PGL_ACTIVE], 0, (GLsizeiptr)((size_t)h->n_clusters * 4), g->active);
    GLuint s0 = g->prog[0], s1 = g->prog[1], s2 = g->prog[2];
    glUseProgram(s0); /* probe SH */
    lc_gl_bind(0, g->buf[PGL_HITS], 0, (size_t)h->n_probes * h->n_rays * 4);
    lc_gl_bind(1, g->buf[PGL_RAY_SH], 0, (size_t)h->n_rays * g->nc * 4);
    lc_gl_bind(2, p->radiosity, 0, (size_t)v->n_surfels * 12);
    lc_gl_bind(3, g->buf[PGL_LAMBDA], 0, (size_t)h->n_probes * 3 * g->nc * 4);
    glProgramUniform1ui(s0, 0, h->n_probes * g->nc);
    glProgramUniform1ui(s0, 1, g->nc);
    glProgramUniform1ui(s0, 2, h->n_rays);
    lc_gl_dispatch_1d((size_t)h->n_probes * g->nc, PGL_LOCAL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    glUseProgram(s1); /* the clusters' basis rows */
    lc_gl_bind(0, g->buf[PGL_BASIS_ROWS], 0, (size_t)g->n_basis_rows * 16);
    lc_gl_bind(2, g->buf[PGL_PROBES], 0, v->n_probe_cluster_probes * 4);
    lc_gl_bind(3, g->buf[PGL_LAMBDA], 0, (size_t)h->n_probes * 3 * g->nc * 4);
    lc_gl_bind(4, g->buf[PGL_B], 0, (size_t)g->n_basis_rows * 12);
    lc_gl_bind(7, g->buf[PGL_ACTIVE], 0, (size_t)h->n_clusters * 4);
    glProgramUniform1ui(s1, 1, g->nc);
    pgl_windows(g, s1, g->buf[PGL_BASIS], 1, g->n_basis_rows, g->basis_start, g->basis_len);
    glClearNamedBufferData(p->cache_sh, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, NULL);
    glClearNamedBufferData(p->sh9, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, NULL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
    glUseProgram(s2); /* receivers */
    lc_gl_bind(0, g->buf[PGL_ROWS], 0, (size_t)h->n_rows * 16);
    lc_gl_bind(2, g->buf[PGL_B], 0, (size_t)g->n_basis_rows * 12);
    lc_gl_bind(3, p->caches, 0, (size_t)v->n_caches * 32);
    lc_gl_bind(4, p->cache_sh, 0, sh_bytes);
    lc_gl_bind(5, p->sh9, 0, (size_t)v->n_caches * 108);
    lc_gl_bind(6, g->buf[PGL_ROW_B], 0, (size_t)h->n_rows * 8);
    lc_gl_bind(7, g->buf[PGL_ACTIVE], 0, (size_t)h->n_clusters * 4);
    lc_gl_bind(8, g->buf[PGL_UNSEEN_FIRST], 0, ((size_t)h->n_rows + 1) * 4);
    lc_gl_bind(9, g->buf[PGL_UNSEEN], 0,
               v->probe_unseen_first && v->probe_unseen_first[h->n_rows] ? (size_t)v->probe_unseen_first[h->n_rows] * 8
                                                                         : 8);
    lc_gl_bind(10, p->radiosity, 0, (size_t)v->n_surfels * 12);
    glProgramUniform1ui(s2, 1, p->nc);
    pgl_windows(g, s2, g->buf[PGL_U], 1, h->n_rows, g->u_start, g->u_len);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    return 0;
}
