/* transport_gl: the EGL/GL 4.3 compute implementation of the transport pipeline
 * (transport.h), stage for stage the same as the CPU reference (cpu/transport_cpu.c):
 *
 *   per pass: radiosity.comp (B = B0 + albedo E_ind), pull.comp once per BFS level bottom-up,
 *             chroma.comp (RGB -> YCoCg at the nodes, when compressing), gather.comp (cache
 *             SH; compiled per band count; with settings.solver probes, probes.comp in its place:
 *             gpu/probes_gl.h), dnrt.comp (placed objects, engine/dnrt.h: prep,
 *             then apply once per object), feedback.comp (E_ind per surfel)
 *   then:     lightmap.comp, grid.comp, objects.comp
 *
 * DNRT, as tcpu_run: intermediate passes also gather the objects' corner caches that no
 * surfel reads and change only the caches some surfel reads; the last pass samples the
 * objects' SH (grid.comp + objects.comp) before DNRT changes the caches, then adds the other
 * objects' changes to it. The frame's objects and receivers are uploaded when its generation
 * changes (placement or lights); receivers are bound per object as a window, so only one
 * object's receivers need fit a binding.
 *
 * The static bake data is uploaded once at create; B0 and the object positions each run.
 * E_ind stays on the GPU across runs (progressive mode). Outputs are read back into host
 * arrays owned by the impl, laid out exactly as the CPU backend's (cache SH at a stride of
 * LC_SH_MAX_COEFFS coefficients).
 *
 * Buffer limits: random-access buffers must fit one SSBO binding (<= 128 MiB, llvmpipe's
 * MAX_SHADER_STORAGE_BLOCK_SIZE); the two big per-cache arrays (links, full cache SH) are
 * bound as windows of whole caches, one gather dispatch per window. Dispatches are 2-D so
 * no axis exceeds 65535 groups.
 *
 * Stage timings: GL timestamp queries (glQueryCounter) at each stage boundary, resolved
 * after the read-back (no extra stalls); the read-back of each output is timed on the CPU
 * clock and added to the stage that produced it.
 *
 * Threads: everything runs on the engine's compute thread; run() re-makes the context
 * current if the engine moved to another thread. */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "engine/transport.h"
#include "gpu/drt_gl.h"
#include "gpu/egl_context.h"
#include "gpu/gl_util.h"
#include "gpu/probes_gl.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/sh.h"

#define TGL_LOCAL 64 /* local_size_x of every shader */
#define TGL_CAP LC_SH_MAX_COEFFS
#define TGL_MAX_STAMPS 160 /* 6 per pass x 17 passes, 2 more in the last, + 4 */
#define TGL_MAX_BOUNCES 16

/* std430 mirrors of the shader structs (see shaders/<name>.comp). */
typedef struct {
    float normal[3], area, albedo[3];
    uint32_t cache;
} tgl_surfel;
typedef struct {
    uint32_t child[2], first_surfel, area_bits; /* area_bits: the leaf surfel's area */
} tgl_node;
typedef struct {
    float normal[3];
    uint32_t flags, link_count, fresh, pad[2]; /* fresh: some surfel reads it (intermediate passes gather it) */
} tgl_cache;
typedef struct { /* dnrt.comp's Obj */
    uint32_t coeffs, pad[3];
    uint32_t corner[8];
    float corner_w[8];
    float to_local[81];
    float c_dir[27];
} tgl_dnrt_object;
#define TGL_DNRT_RECORD 40 /* floats per receiver: target bits, direction, T (27), K (9) */
_Static_assert(sizeof(tgl_surfel) == 32 && sizeof(tgl_node) == 16 && sizeof(tgl_cache) == 32 &&
                   sizeof(tgl_dnrt_object) == 512,
               "std430 layout");
_Static_assert(sizeof(lc_lcb_link) == 12, "links are uploaded as mapped");

enum { TGL_RADIOSITY, TGL_PULL, TGL_CHROMA, TGL_FEEDBACK, TGL_LIGHTMAP, TGL_GRID, TGL_OBJECTS, TGL_N_PROGS };
static const char *const tgl_prog_names[TGL_N_PROGS] = {"radiosity", "pull", "chroma", "feedback",
                                                        "lightmap",  "grid", "objects"};

typedef struct tgl {
    const lc_lcb_view *v;
    lc_egl_context *egl; /* owned */
    int lost;            /* a run saw a lost context: every later run fails fast */
    uint32_t cells;
    size_t texels;
    uint32_t chunk;    /* caches per gather window */
    size_t bind_limit; /* bytes one SSBO binding may span */
    size_t ssbo_align; /* binding offset alignment */
    GLuint prog[TGL_N_PROGS];
    GLuint dnrt_prep, dnrt_apply; /* dnrt.comp, both stages */
    lc_drt_gl *drt;               /* drt.comp: clutter operators (owned) */
    lc_probes_gl *probes;         /* probes.comp: the probes solver's gather, made on first use (owned) */
    GLuint gather[LC_SH_MAX_BANDS + 1][LC_SH_MAX_BANDS + 1]; /* [bands][Co/Cg bands], compiled on first use */
    /* Static (create): */
    GLuint b_surfels, b_nodes, b_links, b_caches, b_lm_index, b_grid_index, b_cone, b_shk, b_list;
    GLuint b_tsg_first, b_tsg;         /* the texel surfel lists (TSGF/TSGW), or one-entry dummies */
    size_t tsg_first_bytes, tsg_bytes; /* ... their sizes as uploaded */
    GLuint b_grid_links;               /* GLNK link-major (tgl_upload_grid_links), or a one-link dummy */
    size_t grid_links_bytes;
    uint32_t n_feedback;
    /* Per run: */
    GLuint b_b0, b_radiosity, b_e_ind, b_flux, b_cache_sh, b_sh9, b_lightmap, b_grid_sh, b_obj_pos, b_obj_sh;
    uint32_t gpu_object_cap;
    GLuint queries[TGL_MAX_STAMPS];
    lc_gl_staging staging; /* every output's read-back (gl_util.h: keeps them in video memory) */
    /* DNRT (engine/dnrt.h), uploaded when the frame changes: */
    uint8_t *feedback_cache; /* per cache: some surfel reads it */
    uint8_t *need;           /* per cache: this pass computes it (lc_transport_needed) */
    uint32_t *need_list;     /* those caches, for a last PIC pass under grid_cells NEEDED */
    GLuint b_need_list;      /* ... uploaded */
    GLuint b_dn_obj, b_dn_inc, b_dn_rec, b_dn_list;
    size_t dn_obj_bytes, dn_inc_bytes, dn_rec_bytes, dn_list_bytes; /* their sizes */
    uint32_t n_dn_list;                                             /* corner caches no surfel reads */
    const lc_dnrt_frame *dn_frame; /* what the buffers hold: this frame at dn_generation */
    uint64_t dn_generation;
    uint64_t dn_placement; /* ... and its receivers at this placement */
    void *dn_stage;        /* host staging for the uploads */
    size_t dn_stage_cap;
    /* Host outputs (owned; the frame points here until the next run): */
    lc_transport_outputs out;
    float *cache_tmp; /* the cache SH as read back, at the GPU's stride of bands^2 */
} tgl;

/* Runs on the compute thread; frees everything, tolerating a half-built impl. */
static void tgl_release(void *impl) {
    tgl *t = impl;
    if (!t) return;
    if (t->egl && lc_egl_make_current(t->egl, NULL, 0) == 0) {
        for (int i = 0; i < TGL_N_PROGS; i++)
            if (t->prog[i]) glDeleteProgram(t->prog[i]);
        for (int b = 0; b <= LC_SH_MAX_BANDS; b++)
            for (int c = 0; c <= LC_SH_MAX_BANDS; c++)
                if (t->gather[b][c]) glDeleteProgram(t->gather[b][c]);
        if (t->dnrt_prep) glDeleteProgram(t->dnrt_prep);
        if (t->dnrt_apply) glDeleteProgram(t->dnrt_apply);
        lc_drt_gl_release(t->drt);
        lc_probes_gl_release(t->probes);
        GLuint bufs[] = {t->b_surfels,   t->b_nodes,    t->b_links,     t->b_caches,   t->b_lm_index,  t->b_grid_index,
                         t->b_cone,      t->b_shk,      t->b_list,      t->b_b0,       t->b_radiosity, t->b_e_ind,
                         t->b_flux,      t->b_cache_sh, t->b_sh9,       t->b_lightmap, t->b_grid_sh,   t->b_obj_pos,
                         t->b_obj_sh,    t->b_dn_obj,   t->b_dn_inc,    t->b_dn_rec,   t->b_dn_list,   t->b_need_list,
                         t->b_tsg_first, t->b_tsg,      t->b_grid_links};
        glDeleteBuffers((GLsizei)(sizeof bufs / sizeof bufs[0]), bufs); /* 0 names are ignored */
        if (t->queries[0]) glDeleteQueries(TGL_MAX_STAMPS, t->queries);
        lc_gl_staging_release(&t->staging);
    }
    lc_egl_release(t->egl);
    lc_transport_outputs_release(&t->out);
    free(t->cache_tmp);
    free(t->feedback_cache);
    free(t->need);
    free(t->need_list);
    free(t->dn_stage);
    free(t);
}

/* The gather program for (bands, Co/Cg bands); compiled on first use because the
 * accumulators are sized at compile time. 0 with err on a compile failure. */
static GLuint tgl_gather_program(tgl *t, int bands, int ncc_bands, char *err, size_t errlen) {
    GLuint *slot = &t->gather[bands][ncc_bands];
    if (*slot) return *slot;
    char defs[160], name[48];
    snprintf(defs, sizeof defs, "#define BANDS %d\n#define NC %d\n#define NCC %d\n#define CHROMA %d\n", bands,
             bands * bands, ncc_bands * ncc_bands, ncc_bands < bands);
    snprintf(name, sizeof name, "gather.comp (bands %d, chroma bands %d)", bands, ncc_bands);
    double t0 = lc_clock_ms();
    *slot = lc_gl_compile_program_defs(name, lc_gl_shader_source("gather"), defs, err, errlen);
    if (*slot) lc_debug("egl", "compiled %s in %.1f ms", name, lc_clock_ms() - t0);
    return *slot;
}

/* Drivers (llvmpipe among them) translate a program to machine code at its first dispatch:
 * one empty dispatch each (count 0: every invocation returns at once) moves that cost from
 * the first relight to create. Any valid buffer will do at each binding. Compute thread. */
static void tgl_warm_up(tgl *t, GLuint prog) {
    glUseProgram(prog);
    for (GLuint b = 0; b < 11; b++) lc_gl_bind(b, t->b_cone, 0, 256 * 8 * 4);
    glProgramUniform1ui(prog, 0, 0);
    glDispatchCompute(1, 1, 1);
    glUseProgram(0);
}

/* Caches per gather window (t->chunk): everything read at random must fit one binding; links
 * and the full cache SH are bound as windows of whole caches. -1 with err when the bake does
 * not fit this device. */
static int tgl_fit_limits(tgl *t, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    GLint64 max_block = 0;
    GLint align = 16;
    glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &max_block);
    glGetIntegerv(GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT, &align);
    size_t limit = (size_t)max_block < LC_GL_MAX_BINDING ? (size_t)max_block : LC_GL_MAX_BINDING;
    struct {
        const char *what;
        size_t bytes;
    } need[] = {{"surfels", (size_t)v->n_surfels * sizeof(tgl_surfel)},
                {"nodes", (size_t)v->n_nodes * sizeof(tgl_node)},
                {"node flux", (size_t)v->n_nodes * 12},
                {"caches", (size_t)v->n_caches * sizeof(tgl_cache)},
                {"cache L2 SH", (size_t)v->n_caches * 108},
                {"surfel radiosity", (size_t)v->n_surfels * 12},
                {"lightmap", t->texels * 12},
                {"grid SH", (size_t)t->cells * 108}};
    for (size_t i = 0; i < sizeof need / sizeof need[0]; i++)
        if (need[i].bytes > limit) {
            lc_set_err(err, errlen, "%s needs %zu MiB, over the %zu MiB shader storage block limit", need[i].what,
                       need[i].bytes >> 20, limit >> 20);
            return -1;
        }
    size_t per_cache = (size_t)v->links_per_cache * sizeof(lc_lcb_link);
    if (per_cache < TGL_CAP * 12) per_cache = TGL_CAP * 12;
    size_t window = lc_gl_test_window_limit && lc_gl_test_window_limit < limit ? lc_gl_test_window_limit : limit;
    size_t chunk = window / per_cache;
    /* Whole multiples of 256 caches keep every window offset aligned (256 * 12 * k bytes). */
    chunk -= chunk % 256;
    if (align > 3072) {
        lc_set_err(err, errlen, "SSBO offset alignment %d is not supported", align);
        return -1;
    }
    if (chunk == 0) {
        lc_set_err(err, errlen, "%u links per cache do not fit a shader storage window", v->links_per_cache);
        return -1;
    }
    t->chunk = chunk > v->n_caches ? (v->n_caches ? v->n_caches : 1) : (uint32_t)chunk;
    t->bind_limit = limit;
    t->ssbo_align = align > 0 ? (size_t)align : 1;
    return 0;
}

/* Programs: all fixed ones now (a broken shader fails creation), gather for the bake's
 * default bands now and the others on first use. */
static int tgl_compile(tgl *t, int def_bands, char *err, size_t errlen) {
    for (int i = 0; i < TGL_N_PROGS; i++) {
        t->prog[i] = lc_gl_compile_program(tgl_prog_names[i], lc_gl_shader_source(tgl_prog_names[i]), err, errlen);
        if (!t->prog[i]) return -1;
    }
    const char *dnrt = lc_gl_shader_source("dnrt");
    if (!(t->dnrt_prep = lc_gl_compile_program_defs("dnrt.comp (prep)", dnrt, "#define DNRT_PREP 1\n", err, errlen)))
        return -1;
    if (!(t->dnrt_apply = lc_gl_compile_program_defs("dnrt.comp (apply)", dnrt, "#define DNRT_PREP 0\n", err, errlen)))
        return -1;
    if (!(t->drt = lc_drt_gl_create(err, errlen))) return -1;
    return tgl_gather_program(t, def_bands, def_bands, err, errlen) ? 0 : -1;
}

/* Surfels, nodes and caches, packed into the std430 structs through one staging allocation. */
static int tgl_upload_structs(tgl *t, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    size_t stage_bytes = (size_t)v->n_surfels * sizeof(tgl_surfel);
    if ((size_t)v->n_nodes * sizeof(tgl_node) > stage_bytes) stage_bytes = (size_t)v->n_nodes * sizeof(tgl_node);
    if ((size_t)v->n_caches * sizeof(tgl_cache) > stage_bytes) stage_bytes = (size_t)v->n_caches * sizeof(tgl_cache);
    int rc = -1;
    void *host = malloc(stage_bytes ? stage_bytes : 16);
    if (!host) {
        lc_set_err(err, errlen, "egl transport: out of memory");
        return -1;
    }
    tgl_surfel *sf = host;
    for (uint32_t s = 0; s < v->n_surfels; s++) {
        memcpy(sf[s].normal, v->surfels[s].normal, sizeof sf[s].normal);
        sf[s].area = v->surfels[s].area;
        memcpy(sf[s].albedo, v->surfels[s].albedo, sizeof sf[s].albedo);
        sf[s].cache = v->surfels[s].cache;
    }
    if (!(t->b_surfels = lc_gl_buffer((size_t)v->n_surfels * sizeof *sf, sf, "surfels", err, errlen))) goto err;
    tgl_node *nd = host;
    for (uint32_t i = 0; i < v->n_nodes; i++) {
        const lc_lcb_node *n = &v->nodes[i];
        nd[i].child[0] = n->child[0];
        nd[i].child[1] = n->child[1];
        nd[i].first_surfel = n->first_surfel;
        float area = n->child[0] == LC_NONE ? v->surfels[n->first_surfel].area : 0.0f;
        memcpy(&nd[i].area_bits, &area, sizeof area);
    }
    if (!(t->b_nodes = lc_gl_buffer((size_t)v->n_nodes * sizeof *nd, nd, "nodes", err, errlen))) goto err;
    tgl_cache *cc = host;
    for (uint32_t c = 0; c < v->n_caches; c++) {
        memset(&cc[c], 0, sizeof cc[c]);
        memcpy(cc[c].normal, v->caches[c].normal, sizeof cc[c].normal);
        cc[c].flags = v->caches[c].flags;
        cc[c].link_count = v->caches[c].link_count;
        cc[c].fresh = t->feedback_cache[c];
    }
    if (!(t->b_caches = lc_gl_buffer((size_t)v->n_caches * sizeof *cc, cc, "caches", err, errlen))) goto err;
    rc = 0;
err:
    free(host);
    return rc;
}

/* Which caches some surfel reads (t->feedback_cache, and their list): the only ones
 * intermediate passes need. */
static int tgl_upload_feedback_list(tgl *t, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    uint8_t *used = t->feedback_cache = calloc(v->n_caches ? v->n_caches : 1, 1);
    uint32_t *list = calloc(v->n_caches ? v->n_caches : 1, sizeof *list);
    t->need = calloc(v->n_caches ? v->n_caches : 1, 1);
    t->need_list = calloc(v->n_caches ? v->n_caches : 1, sizeof *t->need_list);
    int rc = -1;
    if (!used || !list || !t->need || !t->need_list) {
        lc_set_err(err, errlen, "egl transport: out of memory");
        goto err;
    }
    for (uint32_t s = 0; s < v->n_surfels; s++)
        if (v->surfels[s].cache != LC_NONE) used[v->surfels[s].cache] = 1;
    for (uint32_t c = 0; c < v->n_caches; c++)
        if (used[c]) list[t->n_feedback++] = c;
    if (!(t->b_list = lc_gl_buffer((size_t)t->n_feedback * 4, list, "feedback cache list", err, errlen)) ||
        !(t->b_need_list = lc_gl_buffer((size_t)v->n_caches * 4, NULL, "needed cache list", err, errlen)))
        goto err;
    rc = 0;
err:
    free(list);
    return rc;
}

/* The links link-major within each gather window: link k of the window's cache i at
 * k * (caches in the window) + i, so the invocations of a subgroup (consecutive caches) read
 * consecutive links; in the bake's cache-major order they read 1.5 KiB apart (128 links) and
 * the gather ran at PCIe-like rates on an H200. A window keeps its byte range, so the
 * bindings do not change. One window of host memory at a time. */
static int tgl_upload_links(tgl *t, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    const size_t per = v->links_per_cache;
    if (!(t->b_links = lc_gl_buffer((size_t)v->n_caches * per * sizeof(lc_lcb_link), NULL, "links", err, errlen)))
        return -1;
    uint32_t win = t->chunk < v->n_caches ? t->chunk : v->n_caches;
    lc_lcb_link *tmp = malloc((size_t)(win ? win : 1) * per * sizeof *tmp);
    if (!tmp) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    for (uint32_t c0 = 0; c0 < v->n_caches; c0 += t->chunk) {
        uint32_t cnt = v->n_caches - c0 < t->chunk ? v->n_caches - c0 : t->chunk;
        for (uint32_t i = 0; i < cnt; i++)
            for (size_t k = 0; k < per; k++) tmp[k * cnt + i] = v->links[((size_t)c0 + i) * per + k];
        glNamedBufferSubData(t->b_links, (GLintptr)((size_t)c0 * per * sizeof *tmp),
                             (GLsizeiptr)((size_t)cnt * per * sizeof *tmp), tmp);
    }
    free(tmp);
    return 0;
}

/* TSGF/TSGW as they are (gather.comp reads them for texel caches); a bake without them gets
 * one-entry dummies, never read. */
static int tgl_upload_texel_surfels(tgl *t, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    static const uint32_t none[2] = {0, 0};
    const uint32_t n = v->texel_surfels_first ? v->texel_surfels_first[v->n_texel_caches] : 0;
    if ((size_t)n * sizeof(lc_lcb_surfel_weight) > t->bind_limit) {
        lc_set_err(err, errlen,
                   "egl transport: %u texel surfel entries are over one binding (%zu bytes); rebake with fewer "
                   "--texel-gather-rays",
                   n, t->bind_limit);
        return -1;
    }
    const int lists = v->texel_surfels_first != NULL;
    t->tsg_first_bytes = lists ? ((size_t)v->n_texel_caches + 1) * 4 : sizeof none;
    t->tsg_bytes = n ? (size_t)n * sizeof(lc_lcb_surfel_weight) : sizeof none;
    if (!(t->b_tsg_first = lc_gl_buffer(t->tsg_first_bytes, lists ? (const void *)v->texel_surfels_first : none,
                                        "texel surfel offsets", err, errlen)))
        return -1;
    t->b_tsg = lc_gl_buffer(t->tsg_bytes, n ? (const void *)v->texel_surfels : none, "texel surfel lists", err, errlen);
    return t->b_tsg ? 0 : -1;
}

/* GLNK link-major over the grid caches (link k of grid cache g at k * n_grid + g, as the
 * windows' links), bound whole; a bake without it gets a one-link dummy, never read. */
static int tgl_upload_grid_links(tgl *t, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    static const lc_lcb_link none = {0, 0, 0};
    const size_t n_grid = v->n_caches - v->n_texel_caches, per = v->grid_links_per_cache;
    const size_t n = v->grid_links ? n_grid * per : 0;
    t->grid_links_bytes = n ? n * sizeof(lc_lcb_link) : sizeof none;
    if (t->grid_links_bytes > t->bind_limit) {
        lc_set_err(err, errlen,
                   "egl transport: %zu grid-cache links are over one binding (%zu bytes); rebake with fewer "
                   "--grid-links",
                   n, t->bind_limit);
        return -1;
    }
    lc_lcb_link *tmp = n ? malloc(t->grid_links_bytes) : NULL;
    if (n && !tmp) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    for (size_t g = 0; g < n_grid && n; g++)
        for (size_t k = 0; k < per; k++) tmp[k * n_grid + g] = v->grid_links[g * per + k];
    t->b_grid_links = lc_gl_buffer(t->grid_links_bytes, n ? (const void *)tmp : &none, "grid links", err, errlen);
    free(tmp);
    return t->b_grid_links ? 0 : -1;
}

/* The links (tgl_upload_links and tgl_upload_grid_links), the lightmap and grid indices and the cone table. */
static int tgl_upload_tables(tgl *t, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    if (tgl_upload_links(t, err, errlen) != 0 || tgl_upload_grid_links(t, err, errlen) != 0) return -1;
    if (!(t->b_lm_index = lc_gl_buffer(t->texels * 4, v->lightmap, "lightmap index", err, errlen))) return -1;
    if (!(t->b_grid_index = lc_gl_buffer((size_t)t->cells * 4, v->grid, "grid index", err, errlen))) return -1;
    float cone[256][8];
    lc_transport_cone_table(cone);
    if (!(t->b_cone = lc_gl_buffer(sizeof cone, cone, "cone table", err, errlen))) return -1;
    return tgl_upload_texel_surfels(t, err, errlen);
}

/* SH normalisation for the generic (> 4 bands) gather, computed as lc_sh_eval does. */
static int tgl_upload_sh_norm(tgl *t, char *err, size_t errlen) {
    double shk[TGL_CAP];
    for (int l = 0; l < LC_SH_MAX_BANDS; l++)
        for (int m = 0; m <= l; m++) {
            double ratio = 1.0;
            for (int k = l - m + 1; k <= l + m; k++) ratio /= (double)k;
            double k_lm = sqrt((2 * l + 1) / (4.0 * M_PI) * ratio);
            shk[l * l + l + m] = m == 0 ? k_lm : M_SQRT2 * k_lm;
            if (m) shk[l * l + l - m] = 0;
        }
    return (t->b_shk = lc_gl_buffer(sizeof shk, shk, "SH normalisation", err, errlen)) ? 0 : -1;
}

/* Per-run GPU buffers (zeroed), the timestamp queries and the host outputs, sized as the CPU
 * backend's. */
static int tgl_create_run_buffers(tgl *t, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    size_t s12 = (size_t)v->n_surfels * 12;
    if (!(t->b_b0 = lc_gl_buffer(s12, NULL, "B0", err, errlen))) return -1;
    if (!(t->b_radiosity = lc_gl_buffer(s12, NULL, "radiosity", err, errlen))) return -1;
    if (!(t->b_e_ind = lc_gl_buffer(s12, NULL, "E_ind", err, errlen))) return -1;
    if (!(t->b_flux = lc_gl_buffer((size_t)v->n_nodes * 12, NULL, "node flux", err, errlen))) return -1;
    if (!(t->b_cache_sh = lc_gl_buffer((size_t)v->n_caches * TGL_CAP * 12, NULL, "cache SH", err, errlen))) return -1;
    if (!(t->b_sh9 = lc_gl_buffer((size_t)v->n_caches * 108, NULL, "cache L2 SH", err, errlen))) return -1;
    if (!(t->b_lightmap = lc_gl_buffer(t->texels * 12, NULL, "lightmap", err, errlen))) return -1;
    if (!(t->b_grid_sh = lc_gl_buffer((size_t)t->cells * 108, NULL, "grid SH", err, errlen))) return -1;
    glGenQueries(TGL_MAX_STAMPS, t->queries);
    t->cache_tmp = calloc((size_t)v->n_caches * TGL_CAP * 3 + 1, sizeof(float));
    if (lc_transport_outputs_alloc(&t->out, v) != 0 || !t->cache_tmp) {
        lc_set_err(err, errlen, "egl transport: out of memory");
        return -1;
    }
    return 0;
}

/* Runs on the compute thread. threads == -1: called by AUTO, which wants a hardware GPU. */
static void *tgl_create(const lc_lcb_view *v, int threads, char *err, size_t errlen) {
    tgl *t = calloc(1, sizeof *t);
    if (!t) {
        lc_set_err(err, errlen, "out of memory");
        return NULL;
    }
    t->v = v;
    t->cells = v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2];
    t->texels = (size_t)v->lightmap_width * v->lightmap_height;
    t->egl = lc_egl_create(err, errlen);
    if (!t->egl) goto err;
    if (threads == -1 && lc_egl_is_software(t->egl)) {
        lc_set_err(err, errlen, "EGL device is a software rasterizer (llvmpipe); the CPU backend is faster here");
        goto err;
    }
    if (tgl_fit_limits(t, err, errlen) != 0) goto err;
    int def_bands = v->sh_bands >= 1 && v->sh_bands <= LC_SH_MAX_BANDS ? (int)v->sh_bands : 3;
    if (tgl_compile(t, def_bands, err, errlen) != 0) goto err;
    if (tgl_upload_feedback_list(t, err, errlen) != 0 || tgl_upload_structs(t, err, errlen) != 0 ||
        tgl_upload_tables(t, err, errlen) != 0)
        goto err;
    for (int i = 0; i < TGL_N_PROGS; i++) tgl_warm_up(t, t->prog[i]);
    tgl_warm_up(t, t->dnrt_prep);
    tgl_warm_up(t, t->dnrt_apply);
    tgl_warm_up(t, t->gather[def_bands][def_bands]);
    if (tgl_upload_sh_norm(t, err, errlen) != 0 || tgl_create_run_buffers(t, err, errlen) != 0) goto err;
    if (lc_gl_check("egl transport: create", err, errlen) != 0) goto err;
    lc_info("egl", "transport ready: %s; %u surfels, %u nodes in %u levels, %u caches x %u links (%u per window)",
            lc_egl_description(t->egl), v->n_surfels, v->n_nodes, v->n_levels, v->n_caches, v->links_per_cache,
            t->chunk);
    return t;
err:
    tgl_release(t);
    return NULL;
}

/* --- run ------------------------------------------------------------------------------------- */

typedef struct {
    int n;
    int stage[TGL_MAX_STAMPS]; /* the stage the interval ending at stamp i belongs to */
} tgl_stamps;

/* Marks the end of a `stage` interval (the first call marks the start). Compute thread. */
static void tgl_stamp(tgl *t, tgl_stamps *s, int stage) {
    if (s->n >= TGL_MAX_STAMPS) return; /* bounded by TGL_MAX_BOUNCES; never expected */
    s->stage[s->n] = stage;
    glQueryCounter(t->queries[s->n++], GL_TIMESTAMP);
}

static void tgl_uniform_count(GLuint prog, size_t n) { glProgramUniform1ui(prog, 0, (GLuint)n); }

/* Reads bytes of buf into dst, timing it into ms. */
static void tgl_read(tgl *t, GLuint buf, size_t bytes, void *dst, double *ms) {
    double t0 = lc_clock_ms();
    lc_gl_read(&t->staging, buf, 0, bytes, dst);
    *ms += lc_clock_ms() - t0;
}

/* The gather program for these settings, after the checks a run makes first (a lost context,
 * the settings' ranges) and making the context current; 0 with err set on failure. */
static GLuint tgl_prepare(tgl *t, const lc_engine_settings *st, char *err, size_t errlen) {
    if (t->lost) {
        lc_set_err(err, errlen, "egl transport: the GL context was lost; recreate the engine");
        return 0;
    }
    if (lc_transport_check_settings(st, err, errlen) != 0) return 0;
    if (st->bounces > TGL_MAX_BOUNCES) {
        lc_set_err(err, errlen, "/settings/bounces: %u is over %d", st->bounces, TGL_MAX_BOUNCES);
        return 0;
    }
    if (lc_egl_make_current(t->egl, err, errlen) != 0) return 0;
    int bands = (int)st->bands, ncc_bands = lc_transport_chroma(st) ? (int)st->chroma_bands : bands;
    GLuint gather = t->gather[bands][ncc_bands];
    if (!gather) { /* first use of this band count */
        if (!(gather = tgl_gather_program(t, bands, ncc_bands, err, errlen))) return 0;
        tgl_warm_up(t, gather);
    }
    return gather;
}

/* --- passes (each the GL twin of the CPU backend's; every one ends with its writes visible) --- */

/* B = B0 + albedo E_ind (radiosity.comp). */
static void tgl_radiosity(tgl *t) {
    const lc_lcb_view *v = t->v;
    glUseProgram(t->prog[TGL_RADIOSITY]);
    lc_gl_bind(0, t->b_surfels, 0, (size_t)v->n_surfels * sizeof(tgl_surfel));
    lc_gl_bind(1, t->b_b0, 0, (size_t)v->n_surfels * 12);
    lc_gl_bind(2, t->b_e_ind, 0, (size_t)v->n_surfels * 12);
    lc_gl_bind(3, t->b_radiosity, 0, (size_t)v->n_surfels * 12);
    tgl_uniform_count(t->prog[TGL_RADIOSITY], v->n_surfels);
    lc_gl_dispatch_1d(v->n_surfels, TGL_LOCAL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

/* Pull, deepest level first: each level reads the one below (pull.comp once per level). */
static void tgl_pull(tgl *t) {
    const lc_lcb_view *v = t->v;
    glUseProgram(t->prog[TGL_PULL]);
    lc_gl_bind(0, t->b_nodes, 0, (size_t)v->n_nodes * sizeof(tgl_node));
    lc_gl_bind(1, t->b_radiosity, 0, (size_t)v->n_surfels * 12);
    lc_gl_bind(2, t->b_flux, 0, (size_t)v->n_nodes * 12);
    for (uint32_t lv = v->n_levels; lv-- > 0;) {
        uint32_t begin = v->levels[lv], count = v->levels[lv + 1] - begin;
        glProgramUniform1ui(t->prog[TGL_PULL], 1, begin);
        tgl_uniform_count(t->prog[TGL_PULL], count);
        lc_gl_dispatch_1d(count, TGL_LOCAL);
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    }
}

/* RGB -> Y, Co, Cg at the nodes when compressing (chroma.comp), as tcpu_to_ycocg. */
static void tgl_to_ycocg(tgl *t) {
    glUseProgram(t->prog[TGL_CHROMA]);
    lc_gl_bind(0, t->b_flux, 0, (size_t)t->v->n_nodes * 12);
    tgl_uniform_count(t->prog[TGL_CHROMA], t->v->n_nodes);
    lc_gl_dispatch_1d(t->v->n_nodes, TGL_LOCAL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

/* Whether an intermediate pass gathers only the caches some surfel reads: with one window
 * (the usual case) and some caches no surfel reads. */
static int tgl_gather_uses_list(const tgl *t, int last) {
    return !last && t->chunk >= t->v->n_caches && t->n_feedback < t->v->n_caches;
}

/* The gather's bindings and uniforms but the windows and the list (gather.comp). */
static void tgl_gather_setup(tgl *t, GLuint gather, const lc_engine_settings *st) {
    const lc_lcb_view *v = t->v;
    glUseProgram(gather);
    lc_gl_bind(1, t->b_caches, 0, (size_t)v->n_caches * sizeof(tgl_cache));
    lc_gl_bind(2, t->b_flux, 0, (size_t)v->n_nodes * 12);
    lc_gl_bind(3, t->b_cone, 0, 256 * 8 * 4);
    lc_gl_bind(5, t->b_sh9, 0, (size_t)v->n_caches * 108);
    lc_gl_bind(6, t->b_list, 0, (size_t)t->n_feedback * 4);
    lc_gl_bind(7, t->b_shk, 0, TGL_CAP * 8);
    glProgramUniform1i(gather, 4, lc_transport_texel_bands(st) * lc_transport_texel_bands(st));
    glProgramUniform1i(gather, 5, lc_transport_texel_band1(st));
    lc_gl_bind(8, t->b_tsg_first, 0, t->tsg_first_bytes);
    lc_gl_bind(9, t->b_tsg, 0, t->tsg_bytes);
    lc_gl_bind(10, t->b_radiosity, 0, (size_t)v->n_surfels * 12);
    glProgramUniform1i(gather, 7, lc_transport_texel_surfels(v, st));
    glProgramUniform1ui(gather, 8, v->n_texel_caches);
    lc_gl_bind(11, t->b_grid_links, 0, t->grid_links_bytes);
    glProgramUniform1ui(gather, 9, v->grid_links ? v->n_caches - v->n_texel_caches : 0);
}

/* The caches in `list` (n of them; one window only). */
static void tgl_gather_list(tgl *t, GLuint gather, const lc_engine_settings *st, GLuint list, uint32_t n) {
    const lc_lcb_view *v = t->v;
    lc_gl_bind(0, t->b_links, 0, (size_t)v->n_caches * v->links_per_cache * sizeof(lc_lcb_link));
    lc_gl_bind(4, t->b_cache_sh, 0, (size_t)v->n_caches * st->bands * st->bands * 12);
    lc_gl_bind(6, list, 0, (size_t)n * 4);
    glProgramUniform1ui(gather, 1, 0);
    glProgramUniform1ui(gather, 3, 1);
    glProgramUniform1ui(gather, 6, v->n_caches); /* the one window holds every cache */
    tgl_uniform_count(gather, n);
    lc_gl_dispatch_1d(n, TGL_LOCAL);
}

/* Cache SH from the links (gather.comp). One window (the usual case) lets an intermediate
 * pass gather only the caches some surfel reads; else every window of `chunk` caches. */
static void tgl_gather(tgl *t, GLuint gather, const lc_engine_settings *st, int last) {
    const lc_lcb_view *v = t->v;
    const int nc = (int)(st->bands * st->bands);
    tgl_gather_setup(t, gather, st);
    const size_t link_bytes = (size_t)v->links_per_cache * sizeof(lc_lcb_link), sh_bytes = (size_t)nc * 12;
    if (tgl_gather_uses_list(t, last)) {
        tgl_gather_list(t, gather, st, t->b_list, t->n_feedback);
    } else {
        glProgramUniform1ui(gather, 3, 0);
        for (uint32_t c0 = 0; c0 < v->n_caches; c0 += t->chunk) {
            uint32_t cnt = v->n_caches - c0 < t->chunk ? v->n_caches - c0 : t->chunk;
            lc_gl_bind(0, t->b_links, c0 * link_bytes, cnt * link_bytes);
            lc_gl_bind(4, t->b_cache_sh, c0 * sh_bytes, cnt * sh_bytes);
            glProgramUniform1ui(gather, 1, c0);
            glProgramUniform1ui(gather, 6, cnt);
            tgl_uniform_count(gather, cnt);
            lc_gl_dispatch_1d(cnt, TGL_LOCAL);
        }
    }
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

/* Feedback for the next pass (and, progressive, for the next relight): E_ind per surfel
 * (feedback.comp). */
static void tgl_feedback(tgl *t, int bands) {
    const lc_lcb_view *v = t->v;
    glUseProgram(t->prog[TGL_FEEDBACK]);
    lc_gl_bind(0, t->b_surfels, 0, (size_t)v->n_surfels * sizeof(tgl_surfel));
    lc_gl_bind(1, t->b_caches, 0, (size_t)v->n_caches * sizeof(tgl_cache));
    lc_gl_bind(2, t->b_sh9, 0, (size_t)v->n_caches * 108);
    lc_gl_bind(3, t->b_e_ind, 0, (size_t)v->n_surfels * 12);
    tgl_uniform_count(t->prog[TGL_FEEDBACK], v->n_surfels);
    glProgramUniform1i(t->prog[TGL_FEEDBACK], 2, bands);
    lc_gl_dispatch_1d(v->n_surfels, TGL_LOCAL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

/* Lightmap: irradiance of each texel's cache for the cache normal (lightmap.comp). No barrier:
 * the grid pass after it reads the cache SH, not the lightmap. */
static void tgl_lightmap(tgl *t, int bands) {
    const lc_lcb_view *v = t->v;
    glUseProgram(t->prog[TGL_LIGHTMAP]);
    lc_gl_bind(0, t->b_lm_index, 0, t->texels * 4);
    lc_gl_bind(1, t->b_caches, 0, (size_t)v->n_caches * sizeof(tgl_cache));
    lc_gl_bind(2, t->b_sh9, 0, (size_t)v->n_caches * 108);
    lc_gl_bind(3, t->b_lightmap, 0, t->texels * 12);
    tgl_uniform_count(t->prog[TGL_LIGHTMAP], t->texels);
    glProgramUniform1i(t->prog[TGL_LIGHTMAP], 2, bands);
    lc_gl_dispatch_1d(t->texels, TGL_LOCAL);
}

/* Grid: cosine-convolved L2 SH per sample (grid.comp). */
static void tgl_grid(tgl *t, int bands) {
    glUseProgram(t->prog[TGL_GRID]);
    lc_gl_bind(0, t->b_grid_index, 0, (size_t)t->cells * 4);
    lc_gl_bind(1, t->b_sh9, 0, (size_t)t->v->n_caches * 108);
    lc_gl_bind(2, t->b_grid_sh, 0, (size_t)t->cells * 108);
    tgl_uniform_count(t->prog[TGL_GRID], t->cells);
    glProgramUniform1i(t->prog[TGL_GRID], 2, bands);
    lc_gl_dispatch_1d(t->cells, TGL_LOCAL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

/* Objects: positions uploaded each run (the buffers grow with the object count), each one's
 * SH trilinear in the grid (objects.comp). -1 with err out of memory. */
static int tgl_objects(tgl *t, const lc_transport_input *in, char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    if (in->n_objects > t->gpu_object_cap) {
        GLuint old[2] = {t->b_obj_pos, t->b_obj_sh};
        glDeleteBuffers(2, old);
        t->b_obj_pos = t->b_obj_sh = 0;
        t->gpu_object_cap = 0;
        if (!(t->b_obj_pos = lc_gl_buffer((size_t)in->n_objects * 12, NULL, "object positions", err, errlen)))
            return -1;
        if (!(t->b_obj_sh = lc_gl_buffer((size_t)in->n_objects * 108, NULL, "object SH", err, errlen))) return -1;
        t->gpu_object_cap = in->n_objects;
    }
    if (lc_transport_reserve_objects(&t->out, in->n_objects, "egl", err, errlen) != 0) return -1;
    if (in->n_objects) {
        glNamedBufferSubData(t->b_obj_pos, 0, (GLsizeiptr)((size_t)in->n_objects * 12), in->object_pos);
        GLuint p = t->prog[TGL_OBJECTS];
        glUseProgram(p);
        lc_gl_bind(0, t->b_obj_pos, 0, (size_t)in->n_objects * 12);
        lc_gl_bind(1, t->b_grid_sh, 0, (size_t)t->cells * 108);
        lc_gl_bind(2, t->b_obj_sh, 0, (size_t)in->n_objects * 108);
        tgl_uniform_count(p, in->n_objects);
        glProgramUniform3fv(p, 2, 1, v->grid_origin);
        glProgramUniform1f(p, 3, v->grid_cell);
        glProgramUniform3ui(p, 4, v->grid_dims[0], v->grid_dims[1], v->grid_dims[2]);
        lc_gl_dispatch_1d(in->n_objects, TGL_LOCAL);
    }
    return 0;
}

/* --- DNRT (engine/dnrt.h; the CPU's tcpu_dnrt) ------------------------------------------------ */

/* *buf holds at least `bytes` (a new, larger buffer when not; contents lost). -1 with err. */
static int tgl_ensure(GLuint *buf, size_t *have, size_t bytes, const char *what, char *err, size_t errlen) {
    if (*buf && bytes <= *have) return 0;
    size_t cap = *have > 4096 ? *have : 4096;
    while (cap < bytes) cap *= 2;
    if (*buf) glDeleteBuffers(1, buf);
    *buf = 0;
    *have = 0;
    if (!(*buf = lc_gl_buffer(cap, NULL, what, err, errlen))) return -1;
    *have = cap;
    return 0;
}

/* Receiver records per aligned binding start: a window over one object's receivers starts
 * at a multiple of this. */
static size_t tgl_dnrt_step(const tgl *t) {
    size_t a = t->ssbo_align, b = TGL_DNRT_RECORD * 4;
    while (b) {
        size_t r = a % b;
        a = b;
        b = r;
    }
    return t->ssbo_align / a;
}

/* The objects' corner caches no surfel reads, once each (tcpu_dnrt_corner_list), into list
 * (8 per object at most); returns their count. */
static uint32_t tgl_dnrt_corner_list(const tgl *t, const lc_dnrt_frame *f, uint32_t *list) {
    uint32_t n = 0;
    for (uint32_t i = 0; i < f->n_objects; i++)
        for (int k = 0; k < 8; k++) {
            uint32_t c = f->objects[i].corner[k];
            int seen = t->feedback_cache[c];
            for (uint32_t j = 0; j < n && !seen; j++) seen = list[j] == c;
            if (!seen) list[n++] = c;
        }
    return n;
}

/* Host staging of at least `bytes`, or NULL with err. */
static void *tgl_dnrt_staging(tgl *t, size_t bytes, char *err, size_t errlen) {
    if (bytes <= t->dn_stage_cap) return t->dn_stage;
    void *p = realloc(t->dn_stage, bytes);
    if (!p) {
        lc_set_err(err, errlen, "egl transport: out of memory for %zu bytes of DNRT uploads", bytes);
        return NULL;
    }
    t->dn_stage = p;
    t->dn_stage_cap = bytes;
    return p;
}

/* The objects (dnrt.comp's Obj) and their corner list into their buffers. */
static int tgl_dnrt_upload_objects(tgl *t, const lc_dnrt_frame *f, char *err, size_t errlen) {
    size_t bytes = (size_t)f->n_objects * sizeof(tgl_dnrt_object);
    tgl_dnrt_object *o = tgl_dnrt_staging(t, bytes, err, errlen);
    if (!o) return -1;
    for (uint32_t i = 0; i < f->n_objects; i++) {
        const lc_dnrt_object *d = &f->objects[i];
        memset(&o[i], 0, sizeof o[i]);
        o[i].coeffs = d->coeffs;
        memcpy(o[i].corner, d->corner, sizeof o[i].corner);
        memcpy(o[i].corner_w, d->corner_w, sizeof o[i].corner_w);
        memcpy(o[i].to_local, d->to_local, sizeof o[i].to_local);
        memcpy(o[i].c_dir, d->c_dir, sizeof o[i].c_dir);
    }
    if (tgl_ensure(&t->b_dn_obj, &t->dn_obj_bytes, bytes, "DNRT objects", err, errlen) != 0 ||
        tgl_ensure(&t->b_dn_inc, &t->dn_inc_bytes, (size_t)f->n_objects * 54 * 4, "DNRT incident SH", err, errlen) != 0)
        return -1;
    glNamedBufferSubData(t->b_dn_obj, 0, (GLsizeiptr)bytes, o);
    uint32_t *list = tgl_dnrt_staging(t, (size_t)f->n_objects * 8 * 4, err, errlen);
    if (!list) return -1;
    t->n_dn_list = tgl_dnrt_corner_list(t, f, list);
    if (tgl_ensure(&t->b_dn_list, &t->dn_list_bytes, (size_t)t->n_dn_list * 4, "DNRT corner list", err, errlen) != 0)
        return -1;
    glNamedBufferSubData(t->b_dn_list, 0, (GLsizeiptr)((size_t)t->n_dn_list * 4), list);
    return 0;
}

/* The frame into the GPU buffers when it changed since the last upload (its generation):
 * objects and corner list, and the receivers as records of TGL_DNRT_RECORD floats only when
 * they changed (its placement: a light change leaves them). -1 with err when one object's
 * receivers do not fit a binding or out of memory. */
static int tgl_dnrt_upload(tgl *t, const lc_dnrt_frame *f, char *err, size_t errlen) {
    if (f == t->dn_frame && f->generation == t->dn_generation) return 0;
    int receivers_kept = f == t->dn_frame && f->placement == t->dn_placement;
    t->dn_frame = NULL;
    const size_t rec = TGL_DNRT_RECORD * 4, step = tgl_dnrt_step(t);
    for (uint32_t i = 0; i < f->n_objects; i++)
        if (((size_t)f->objects[i].count + step) * rec > t->bind_limit) {
            lc_set_err(err, errlen, "dnrt: object %u has %u receivers (%zu MiB), over the %zu MiB storage block limit",
                       f->objects[i].object, f->objects[i].count, ((size_t)f->objects[i].count * rec) >> 20,
                       t->bind_limit >> 20);
            return -1;
        }
    if (tgl_dnrt_upload_objects(t, f, err, errlen) != 0) return -1;
    if (receivers_kept) {
        t->dn_frame = f;
        t->dn_generation = f->generation;
        return 0;
    }
    size_t bytes = (size_t)f->n_receivers * rec;
    float *r = tgl_dnrt_staging(t, bytes, err, errlen);
    if (!r) return -1;
    for (uint32_t i = 0; i < f->n_receivers; i++) {
        float *o = r + (size_t)i * TGL_DNRT_RECORD;
        memcpy(&o[0], &f->targets[i], 4);
        memcpy(&o[1], f->dirs + 3 * (size_t)i, 3 * sizeof(float));
        memcpy(&o[4], f->values + 36 * (size_t)i, 36 * sizeof(float));
    }
    if (tgl_ensure(&t->b_dn_rec, &t->dn_rec_bytes, bytes, "DNRT receivers", err, errlen) != 0) return -1;
    glNamedBufferSubData(t->b_dn_rec, 0, (GLsizeiptr)bytes, r);
    t->dn_frame = f;
    t->dn_generation = f->generation;
    t->dn_placement = f->placement;
    return 0;
}

/* Each object's incident SH from its corner caches, rotated (dnrt.comp, prep). */
static void tgl_dnrt_prep(tgl *t, const lc_dnrt_frame *f, int bands) {
    GLuint p = t->dnrt_prep;
    glUseProgram(p);
    lc_gl_bind(0, t->b_dn_obj, 0, (size_t)f->n_objects * sizeof(tgl_dnrt_object));
    lc_gl_bind(1, t->b_dn_inc, 0, (size_t)f->n_objects * 54 * 4);
    lc_gl_bind(2, t->b_sh9, 0, (size_t)t->v->n_caches * 108);
    tgl_uniform_count(p, f->n_objects);
    glProgramUniform1i(p, 1, bands);
    lc_gl_dispatch_1d(f->n_objects, TGL_LOCAL);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
}

/* The receivers' sums (dnrt.comp, apply): per cache SH window, one dispatch per object in
 * frame order with a barrier after each (no two invocations of a dispatch share a target:
 * an object lists each cache and each other object once). */
static void tgl_dnrt_apply(tgl *t, const lc_dnrt_frame *f, const lc_engine_settings *st, int last) {
    const lc_lcb_view *v = t->v;
    const GLuint p = t->dnrt_apply;
    const int tb = lc_transport_texel_bands(st), nc = (int)(st->bands * st->bands);
    const size_t rec = TGL_DNRT_RECORD * 4, step = tgl_dnrt_step(t), sh_bytes = (size_t)nc * 12;
    glUseProgram(p);
    lc_gl_bind(0, t->b_dn_obj, 0, (size_t)f->n_objects * sizeof(tgl_dnrt_object));
    lc_gl_bind(1, t->b_dn_inc, 0, (size_t)f->n_objects * 54 * 4);
    lc_gl_bind(3, t->b_caches, 0, (size_t)v->n_caches * sizeof(tgl_cache));
    lc_gl_bind(5, t->b_sh9, 0, (size_t)v->n_caches * 108);
    lc_gl_bind(6, t->b_obj_sh ? t->b_obj_sh : t->b_dn_inc, 0, (size_t)t->gpu_object_cap * 108);
    lc_gl_bind(7, t->b_shk, 0, TGL_CAP * 8);
    glProgramUniform1ui(p, 5, (GLuint)nc);
    glProgramUniform1ui(p, 6, v->n_texel_caches);
    glProgramUniform1i(p, 7, lc_transport_texel_band1(st) ? 1 : 0);
    glProgramUniform1i(p, 8, tb * tb);
    glProgramUniform1i(p, 9, nc);
    glProgramUniform1i(p, 10, (int)st->bands);
    glProgramUniform1i(p, 11, last);
    for (uint32_t c0 = 0; c0 < v->n_caches; c0 += t->chunk) {
        uint32_t cnt = v->n_caches - c0 < t->chunk ? v->n_caches - c0 : t->chunk;
        lc_gl_bind(4, t->b_cache_sh, c0 * sh_bytes, cnt * sh_bytes);
        glProgramUniform1ui(p, 3, c0);
        glProgramUniform1ui(p, 4, cnt);
        glProgramUniform1i(p, 12, last && c0 == 0); /* the objects' SH: once */
        for (uint32_t i = 0; i < f->n_objects; i++) {
            const lc_dnrt_object *o = &f->objects[i];
            if (!o->count) continue;
            size_t base = o->first - o->first % step; /* an aligned window over its receivers */
            lc_gl_bind(2, t->b_dn_rec, base * rec, (o->first + o->count - base) * rec);
            glProgramUniform1ui(p, 1, (GLuint)(o->first - base));
            glProgramUniform1ui(p, 2, i);
            tgl_uniform_count(p, o->count);
            lc_gl_dispatch_1d(o->count, TGL_LOCAL);
            glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
        }
    }
}

/* DNRT after a pass's gather, as tcpu_dnrt: intermediate passes first gather the corner
 * caches the list skipped; then the objects' incident SH and the receivers' sums. */
static void tgl_dnrt(tgl *t, GLuint gather, const lc_transport_input *in, int last) {
    const lc_engine_settings *st = &in->settings;
    if (tgl_gather_uses_list(t, last) && t->n_dn_list && st->solver != LC_SOLVER_PROBES) {
        tgl_gather_setup(t, gather, st);
        tgl_gather_list(t, gather, st, t->b_dn_list, t->n_dn_list);
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    }
    tgl_dnrt_prep(t, in->dnrt, (int)st->bands);
    tgl_dnrt_apply(t, in->dnrt, st, last);
}

/* Reads every output back into the host arrays, each read timed into its stage's rb[]; the
 * cache SH goes from the GPU's stride of bands^2 to the frame's LC_SH_MAX_COEFFS (as the CPU
 * backend's). -1 with err out of memory for the SH lightmap. */
static int tgl_read_back(tgl *t, const lc_transport_input *in, double rb[LC_STAGE_COUNT], char *err, size_t errlen) {
    const lc_lcb_view *v = t->v;
    const size_t nc = (size_t)in->settings.bands * in->settings.bands;
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT); /* shader writes must be visible to buffer reads */
    tgl_read(t, t->b_radiosity, (size_t)v->n_surfels * 12, t->out.radiosity, &rb[LC_STAGE_BOUNCE]);
    tgl_read(t, t->b_flux, (size_t)v->n_nodes * 12, t->out.flux, &rb[LC_STAGE_PULL]);
    tgl_read(t, t->b_cache_sh, (size_t)v->n_caches * nc * 12, t->cache_tmp, &rb[LC_STAGE_GATHER]);
    double t0 = lc_clock_ms();
    for (uint32_t c = 0; c < v->n_caches; c++)
        memcpy(t->out.cache_sh + (size_t)c * TGL_CAP * 3, t->cache_tmp + (size_t)c * nc * 3, nc * 3 * sizeof(float));
    rb[LC_STAGE_GATHER] += lc_clock_ms() - t0;
    tgl_read(t, t->b_lightmap, t->texels * 12, t->out.lightmap, &rb[LC_STAGE_LIGHTMAP]);
    t0 = lc_clock_ms();
    if (in->settings.sh_lightmap && lc_transport_fill_lightmap_sh(&t->out, v, "egl", err, errlen) != 0) return -1;
    rb[LC_STAGE_LIGHTMAP] += lc_clock_ms() - t0;
    tgl_read(t, t->b_grid_sh, (size_t)t->cells * 108, t->out.grid_sh, &rb[LC_STAGE_GRID]);
    if (in->settings.grid_cells == LC_GRID_NEEDED) lc_transport_clear_unneeded_cells(&t->out, v, t->need);
    tgl_read(t, t->b_obj_sh, (size_t)in->n_objects * 108, t->out.object_sh, &rb[LC_STAGE_OBJECTS]);
    return 0;
}

/* Stage times from the timestamps (all available: the read-back waited for the GPU) plus
 * each stage's read-back. */
static void tgl_stage_times(tgl *t, const tgl_stamps *ts, const double rb[LC_STAGE_COUNT], lc_engine_frame *fr) {
    double ms[LC_STAGE_COUNT] = {0};
    GLuint64 prev = 0;
    for (int i = 0; i < ts->n; i++) {
        GLuint64 now = 0;
        glGetQueryObjectui64v(t->queries[i], GL_QUERY_RESULT, &now);
        if (i > 0 && now >= prev) ms[ts->stage[i]] += (double)(now - prev) * 1e-6;
        prev = now;
    }
    for (int s = LC_STAGE_BOUNCE; s <= LC_STAGE_DRT; s++) fr->stage_ms[s] = ms[s] + rb[s];
}

/* One transport pass (tcpu_run's loop body): with DNRT the last one samples the objects' SH
 * (grid + objects) before DNRT changes the caches. -1 with err out of memory. */
static int tgl_pass(tgl *t, GLuint gather, const lc_transport_input *in, int last, tgl_stamps *ts, char *err,
                    size_t errlen) {
    const lc_engine_settings *st = &in->settings;
    tgl_radiosity(t);
    tgl_stamp(t, ts, LC_STAGE_BOUNCE);
    tgl_pull(t);
    tgl_stamp(t, ts, LC_STAGE_PULL);
    if (lc_transport_chroma(st)) tgl_to_ycocg(t);
    tgl_stamp(t, ts, LC_STAGE_CHROMA);
    const int probes = st->solver == LC_SOLVER_PROBES, sparse_grid = last && st->grid_cells == LC_GRID_NEEDED;
    uint32_t n_need = probes || sparse_grid ? lc_transport_needed(t->v, t->feedback_cache, in, last, t->need) : 0;
    if (probes) { /* the clusters holding a needed row, as the CPU backend */
        lc_probes_gl_pass pp = {.radiosity = t->b_radiosity,
                                .caches = t->b_caches,
                                .cache_sh = t->b_cache_sh,
                                .sh9 = t->b_sh9,
                                .nc = st->bands * st->bands,
                                .need = t->need};
        if (lc_probes_gl_gather(t->probes, &pp, err, errlen) != 0) return -1;
    } else if (sparse_grid && t->chunk >= t->v->n_caches) { /* the texel caches and the grid's readers */
        for (uint32_t c = 0, n = 0; c < t->v->n_caches; c++)
            if (t->need[c]) t->need_list[n++] = c;
        glNamedBufferSubData(t->b_need_list, 0, (GLsizeiptr)((size_t)n_need * 4), t->need_list);
        tgl_gather_setup(t, gather, st);
        tgl_gather_list(t, gather, st, t->b_need_list, n_need);
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    } else {
        tgl_gather(t, gather, st, last);
    }
    tgl_stamp(t, ts, LC_STAGE_GATHER);
    if (last && (in->dnrt || in->n_drt)) { /* the objects' SH before any object changes the caches */
        tgl_grid(t, (int)st->bands);
        tgl_stamp(t, ts, LC_STAGE_GRID);
        if (tgl_objects(t, in, err, errlen) != 0) return -1;
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
        tgl_stamp(t, ts, LC_STAGE_OBJECTS);
    }
    if (in->dnrt) {
        tgl_dnrt(t, gather, in, last);
        tgl_stamp(t, ts, LC_STAGE_DNRT);
    }
    if (in->n_drt) { /* clutter operators after DNRT, as tcpu_drt */
        int tb = lc_transport_texel_bands(st);
        lc_drt_gl_pass dp = {.node_flux = t->b_flux,
                             .caches = t->b_caches,
                             .cache_sh = t->b_cache_sh,
                             .sh9 = t->b_sh9,
                             .n_nodes = t->v->n_nodes,
                             .n_caches = t->v->n_caches,
                             .n_texel_caches = t->v->n_texel_caches,
                             .chunk = t->chunk,
                             .nc = st->bands * st->bands,
                             .ycocg = lc_transport_chroma(st),
                             .texel_lo = lc_transport_texel_band1(st) ? 1 : 0,
                             .texel_nc = tb * tb,
                             .grid_nc = (int)(st->bands * st->bands),
                             .last = last};
        lc_drt_gl_apply(t->drt, &dp);
        tgl_stamp(t, ts, LC_STAGE_DRT);
    }
    tgl_feedback(t, (int)st->bands);
    tgl_stamp(t, ts, LC_STAGE_BOUNCE);
    return 0;
}

/* Runs on the compute thread: the passes of transport.h in the CPU backend's order, one
 * timestamp after each, then the read-back. */
static int tgl_run(void *impl, const lc_transport_input *in, lc_engine_frame *fr, char *err, size_t errlen) {
    tgl *t = impl;
    const lc_lcb_view *v = t->v;
    const lc_engine_settings *st = &in->settings;
    GLuint gather = tgl_prepare(t, st, err, errlen);
    if (!gather) return -1;
    if (st->solver == LC_SOLVER_PROBES && !t->probes &&
        !(t->probes = lc_probes_gl_create(v, t->bind_limit, t->ssbo_align, err, errlen)))
        return -1;
    tgl_stamps ts = {0};
    int rc = 0;
    double rb[LC_STAGE_COUNT] = {0};
    if (in->dnrt) {
        double t0 = lc_clock_ms();
        if (tgl_dnrt_upload(t, in->dnrt, err, errlen) != 0) return -1;
        rb[LC_STAGE_DNRT] += lc_clock_ms() - t0;
    }
    if (in->n_drt) {
        double t0 = lc_clock_ms();
        if (lc_drt_gl_upload(t->drt, in->drt, in->n_drt, v->n_texel_caches, t->bind_limit, err, errlen) != 0) return -1;
        rb[LC_STAGE_DRT] += lc_clock_ms() - t0;
    }
    tgl_stamp(t, &ts, 0);

    glNamedBufferSubData(t->b_b0, 0, (GLsizeiptr)((size_t)v->n_surfels * 12), in->b0);
    if (in->reset_feedback) glClearNamedBufferData(t->b_e_ind, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, NULL);
    for (uint32_t pass = 0; pass <= st->bounces; pass++) {
        if (tgl_pass(t, gather, in, pass == st->bounces, &ts, err, errlen) != 0) return -1;
        if ((rc = lc_gl_check("egl transport: bounce pass", err, errlen)) != 0) goto gl_err;
    }
    tgl_lightmap(t, (int)st->bands);
    tgl_stamp(t, &ts, LC_STAGE_LIGHTMAP);
    tgl_grid(t, (int)st->bands);
    tgl_stamp(t, &ts, LC_STAGE_GRID);
    if (!in->dnrt && !in->n_drt) { /* else sampled in the last pass */
        if (tgl_objects(t, in, err, errlen) != 0) return -1;
        tgl_stamp(t, &ts, LC_STAGE_OBJECTS);
    }
    glUseProgram(0);
    if ((rc = lc_gl_check("egl transport: outputs", err, errlen)) != 0) goto gl_err;

    if (tgl_read_back(t, in, rb, err, errlen) != 0) return -1;
    double t0 = lc_clock_ms();
    lc_drt_gl_read_back(t->drt, in->drt, in->n_drt);
    rb[LC_STAGE_DRT] += lc_clock_ms() - t0;
    if ((rc = lc_gl_check("egl transport: read-back", err, errlen)) != 0) goto gl_err;
    tgl_stage_times(t, &ts, rb, fr);
    lc_transport_publish(&t->out, st, fr);
    return 0;
gl_err:
    glUseProgram(0);
    if (rc == -2) t->lost = 1;
    return -1;
}

const lc_transport_ops lc_transport_egl = {"egl", tgl_create, tgl_release, tgl_run};
