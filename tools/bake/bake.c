/* bake: the lucent-bake pipeline and its option table. Runs on the main thread; the stages
 * parallelise internally (lc_parallel_for, each given --threads; Embree's TBB pool). */
#include "bake/bake.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>

#include "bake/exposure.h"
#include "bake/grid.h"
#include "bake/hierarchy.h"
#include "bake/probes.h"
#include "bake/links.h"
#include "bake/relocate.h"
#include "bake/rt.h"
#include "bake/scene.h"
#include "bake/surfel_refine.h"
#include "bake/surfels.h"
#include "bake/texels.h"
#include "bake/sparse.h"
#include "bake/transfer.h"
#include "bake/uvgen.h"
#include "lcb/lcb.h"
#include "lcb/lcb_glb.h"
#include "util/clock.h"
#include "util/fsutil.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/progress.h"
#include "util/ray_offset.h"
#include "util/vec.h"

#define LC_BAKE_VERSION "0.1.0"

/* --- helpers ------------------------------------------------------------------------------ */

#define BAKE_N_STAGES 12

/* Records a finished stage and, unless quiet, says so (one line per stage: the long ones
 * also draw their own progress). */
static void bake_stage(lc_bake_report *r, const char *name, double *t0, int quiet) {
    double t = (lc_clock_ms() * 1e-3);
    if (r->n_stages < LC_BAKE_MAX_STAGES) {
        r->stages[r->n_stages].name = name;
        r->stages[r->n_stages].seconds = t - *t0;
        struct rusage ru;
        r->stages[r->n_stages].peak_mib = getrusage(RUSAGE_SELF, &ru) == 0 ? ru.ru_maxrss / 1024.0 : 0;
        r->n_stages++;
    }
    if (!quiet) lc_info("bake", "[%d/%d] %s done in %.3f s", r->n_stages, BAKE_N_STAGES, name, t - *t0);
    *t0 = t;
}

static cJSON *bake_vec3(const float v[3]) {
    double d[3] = {v[0], v[1], v[2]};
    return cJSON_CreateDoubleArray(d, 3);
}

/* Barycentrics of p projected onto triangle tri (clamped inside). */
static void bake_barycentric(const lc_mesh *m, uint32_t tri, const float p[3], float *b1, float *b2) {
    const uint32_t *ix = m->index + 3 * (size_t)tri;
    lc_vec3 a = lc_v3_load(m->position + 3 * (size_t)ix[0]);
    lc_vec3 e1 = lc_v3_sub(lc_v3_load(m->position + 3 * (size_t)ix[1]), a);
    lc_vec3 e2 = lc_v3_sub(lc_v3_load(m->position + 3 * (size_t)ix[2]), a);
    lc_vec3 d = lc_v3_sub(lc_v3_load(p), a);
    double d11 = lc_v3_dot(e1, e1), d12 = lc_v3_dot(e1, e2), d22 = lc_v3_dot(e2, e2);
    double d1 = lc_v3_dot(d, e1), d2 = lc_v3_dot(d, e2);
    double den = d11 * d22 - d12 * d12;
    double u = den > 0 ? (d22 * d1 - d12 * d2) / den : 0, v = den > 0 ? (d11 * d2 - d12 * d1) / den : 0;
    if (u < 0) u = 0;
    if (v < 0) v = 0;
    if (u + v > 1) {
        double s = u + v;
        u /= s;
        v /= s;
    }
    *b1 = (float)u;
    *b2 = (float)v;
}

/* Each surfel's nearest cache: the lightmap texel under it (after dilation) when that texel's
 * normal is within ~26 degrees of the surfel's, else the nearest grid sample that is not inside
 * geometry. Used by multi-bounce feedback: a texel cache holds the irradiance for its own normal
 * only, so a surfel tilted from it (a dilated texel of another chart, a crease) read about that
 * times the cosine, and one facing away nothing (the conference room: 6% of the surfel area,
 * converged bias -4.8% -> -1.4%). */
static void bake_surfel_caches(const lc_scene *scene, const lc_lightmap *lm, const lc_grid *grid,
                               const uint32_t *cell_cache, const lc_lcb_cache *caches, lc_lcb_surfel *surfels,
                               const uint32_t *surfel_tri, uint32_t n_surfels) {
    const lc_mesh *m = &scene->mesh;
    for (uint32_t i = 0; i < n_surfels; i++) {
        lc_lcb_surfel *s = &surfels[i];
        uint32_t tri = surfel_tri[i];
        float b1, b2;
        bake_barycentric(m, tri, s->position, &b1, &b2);
        const uint32_t *ix = m->index + 3 * (size_t)tri;
        float b0 = 1 - b1 - b2;
        float u = m->uv1[2 * ix[0]] * b0 + m->uv1[2 * ix[1]] * b1 + m->uv1[2 * ix[2]] * b2;
        float v = m->uv1[2 * ix[0] + 1] * b0 + m->uv1[2 * ix[1] + 1] * b1 + m->uv1[2 * ix[2] + 1] * b2;
        long x = lrintf(u * lm->width - 0.5f), y = lrintf(v * lm->height - 0.5f);
        if (x < 0) x = 0;
        if (y < 0) y = 0;
        if (x >= (long)lm->width) x = lm->width - 1;
        if (y >= (long)lm->height) y = lm->height - 1;
        s->cache = lm->texel_cache[(size_t)y * lm->width + x];
        if (s->cache != LC_NONE) {
            const float *cn = caches[s->cache].normal;
            if (cn[0] * s->normal[0] + cn[1] * s->normal[1] + cn[2] * s->normal[2] >= 0.9f) continue;
        } /* no texel, or one facing elsewhere: the grid's full-sphere SH */
        long g[3];
        for (int k = 0; k < 3; k++) {
            g[k] = lrintf((s->position[k] - grid->origin[k]) / grid->cell);
            if (g[k] < 0) g[k] = 0;
            if (g[k] >= (long)grid->dims[k]) g[k] = grid->dims[k] - 1;
        }
        uint32_t c = cell_cache[(size_t)g[0] + grid->dims[0] * ((size_t)g[1] + grid->dims[1] * (size_t)g[2])];
        s->cache = (caches[c].flags & LC_CACHE_INSIDE) ? LC_NONE : c;
    }
}

/* Dynamic-object assets: geometry in asset space (scaled like the scene), per-vertex albedo. */
typedef struct bake_assets {
    lc_lcb_asset *assets;
    lc_lcb_asset_vertex *vertices;
    uint32_t *indices;
    uint32_t n_assets, n_vertices, n_triangles;
    lc_lcb_transfer *transfers; /* DNRT transfer grids (ATRN), one per asset with --transfer */
    int8_t *transfer_data;      /* their values (ATRD) */
    uint32_t n_transfers;
    uint64_t transfer_bytes;
    lc_lcb_sparse_point *sparse;           /* LightSkin sparse points (ASPT), sorted by asset */
    lc_lcb_sparse_vertex *sparse_vertices; /* per asset vertex, its 8 nearest (AVNN); NULL: none */
    uint32_t n_sparse;
} bake_assets;

static void bake_assets_release(bake_assets *a) {
    free(a->assets);
    free(a->vertices);
    free(a->indices);
    free(a->transfers);
    free(a->transfer_data);
    free(a->sparse);
    free(a->sparse_vertices);
    memset(a, 0, sizeof *a);
}

/* The asset's DNRT transfer grid (bake/transfer.h), appended to out's ATRN/ATRD. */
static int bake_asset_transfer(const lc_bake_settings *s, const lc_scene *sc, uint32_t asset, bake_assets *out,
                               char *err, size_t errlen) {
    lc_transfer_params tp = {.dims = s->transfer_dims,
                             .coeffs = s->transfer_sh ? 9 : 4,
                             .rays = s->transfer_rays,
                             .extent = (float)s->transfer_extent,
                             .outer = (float)s->transfer_outer,
                             .threads = s->threads,
                             .seed = (uint32_t)s->seed};
    lc_lcb_transfer hdr;
    int8_t *values = NULL;
    lc_transfer_stats st;
    char terr[256];
    if (lc_transfer_bake(sc, &tp, &hdr, &values, &st, terr, sizeof terr) != 0) {
        lc_set_err(err, errlen, "--asset %s: %s", s->assets[asset].name, terr);
        return -1;
    }
    hdr.asset = asset;
    hdr.data_offset = out->transfer_bytes;
    lc_lcb_transfer *nt = realloc(out->transfers, (out->n_transfers + 1) * sizeof *nt);
    if (nt) out->transfers = nt;
    int8_t *nd = nt ? realloc(out->transfer_data, out->transfer_bytes + st.bytes) : NULL;
    if (!nt || !nd) {
        free(values);
        lc_set_err(err, errlen, "out of memory for the transfer grid of asset %s", s->assets[asset].name);
        return -1;
    }
    out->transfer_data = nd;
    memcpy(nd + out->transfer_bytes, values, st.bytes);
    free(values);
    out->transfers[out->n_transfers++] = hdr;
    out->transfer_bytes += st.bytes;
    if (!s->quiet)
        lc_info("bake", "asset %s: DNRT transfer grid %d^3 x %d SH, %.0f KiB, %u vertices inside filled, %.2f s",
                s->assets[asset].name, tp.dims, tp.coeffs, (double)st.bytes / 1024.0, st.inside_vertices, st.seconds);
    return 0;
}

/* The asset's LightSkin sparse points and its vertices' tables (bake/sparse.h), appended to
 * out's ASPT; its AVNN records (out->sparse_vertices, already sized for its vertices and
 * zeroed) are filled. An asset without triangles gets no points (all-zero records). */
static int bake_asset_sparse(const lc_bake_settings *s, uint32_t asset, bake_assets *out, char *err, size_t errlen) {
    const lc_lcb_asset *a = &out->assets[asset];
    if (a->triangle_count == 0) {
        if (!s->quiet) lc_info("bake", "asset %s: no triangles, no sparse points", a->name);
        return 0;
    }
    uint32_t n = (uint32_t)s->mr_points;
    lc_lcb_sparse_point *np = realloc(out->sparse, ((size_t)out->n_sparse + n) * sizeof *np);
    if (!np) {
        lc_set_err(err, errlen, "out of memory for the sparse points of asset %s", a->name);
        return -1;
    }
    out->sparse = np;
    lc_lcb_sparse_point *pts = np + out->n_sparse;
    const lc_lcb_asset_vertex *v = out->vertices + a->first_vertex;
    lc_sparse_stats ps, ts;
    char serr[256];
    if (lc_sparse_points(v, a->vertex_count, out->indices + 3 * (size_t)a->first_triangle, a->triangle_count, n,
                         (uint32_t)s->seed, asset, pts, &ps, serr, sizeof serr) != 0 ||
        lc_sparse_vertex_table(v, a->vertex_count, pts, n, out->sparse_vertices + a->first_vertex, &ts, serr,
                               sizeof serr) != 0) {
        lc_set_err(err, errlen, "--asset %s: %s", a->name, serr);
        return -1;
    }
    out->n_sparse += n;
    if (!s->quiet)
        lc_info("bake",
                "asset %s: %u sparse points (spacing min/mean %.3f, %u with the area radius) in %.3f s, tables for %u "
                "vertices (%u fall back to the nearest) in %.3f s",
                a->name, n, ps.mean_spacing > 0 ? ps.min_spacing / ps.mean_spacing : 0, ps.empty_regions, ps.seconds,
                a->vertex_count, ts.fallback_vertices, ts.seconds);
    return 0;
}

static int bake_assets_import(const lc_bake_settings *s, bake_assets *out, char *err, size_t errlen) {
    memset(out, 0, sizeof *out);
    if (s->n_assets == 0) return 0;
    out->assets = calloc((size_t)s->n_assets, sizeof *out->assets);
    if (!out->assets) goto oom;
    for (int i = 0; i < s->n_assets; i++) {
        lc_scene sc;
        lc_import_params ip = {.scale = s->scale, .flip_winding = s->flip_winding};
        char ierr[512];
        if (lc_scene_import(s->assets[i].path, &ip, &sc, ierr, sizeof ierr) != 0) {
            lc_set_err(err, errlen, "--asset %s: %s", s->assets[i].name, ierr);
            goto err;
        }
        const lc_mesh *m = &sc.mesh;
        uint64_t nv = (uint64_t)out->n_vertices + m->n_vertices, nt = (uint64_t)out->n_triangles + m->n_triangles;
        if (nv > 16u << 20 || nt > 16u << 20) {
            lc_scene_release(&sc);
            lc_set_err(err, errlen, "--asset %s: assets exceed 16M vertices/triangles in total", s->assets[i].name);
            goto err;
        }
        lc_lcb_asset_vertex *nvb = realloc(out->vertices, nv * sizeof *nvb);
        uint32_t *nib = nvb ? realloc(out->indices, nt * 3 * sizeof *nib) : NULL;
        if (nvb) out->vertices = nvb;
        if (nib) out->indices = nib;
        lc_lcb_sparse_vertex *nsv =
            nib && s->mr_points > 0 ? realloc(out->sparse_vertices, (nv ? nv : 1) * sizeof *nsv) : NULL;
        if (nsv) {
            out->sparse_vertices = nsv;
            memset(nsv + out->n_vertices, 0, (size_t)m->n_vertices * sizeof *nsv);
        }
        if (!nvb || !nib || (s->mr_points > 0 && !nsv)) {
            lc_scene_release(&sc);
            goto oom;
        }
        lc_lcb_asset *a = &out->assets[i];
        snprintf(a->name, sizeof a->name, "%s", s->assets[i].name);
        a->first_vertex = out->n_vertices;
        a->vertex_count = m->n_vertices;
        a->first_triangle = out->n_triangles;
        a->triangle_count = m->n_triangles;
        memcpy(a->bounds_min, sc.bounds_min, sizeof a->bounds_min);
        memcpy(a->bounds_max, sc.bounds_max, sizeof a->bounds_max);
        for (uint32_t v = 0; v < m->n_vertices; v++) {
            lc_lcb_asset_vertex *dst = &out->vertices[a->first_vertex + v];
            memcpy(dst->position, m->position + 3 * (size_t)v, sizeof dst->position);
            memcpy(dst->normal, m->normal + 3 * (size_t)v, sizeof dst->normal);
            dst->albedo[0] = dst->albedo[1] = dst->albedo[2] = 0;
        }
        double albedo_sum[3] = {0, 0, 0}, area_sum = 0;
        for (uint32_t t = 0; t < m->n_triangles; t++) {
            static const float corner_b[3][2] = {{0, 0}, {1, 0}, {0, 1}};
            for (int k = 0; k < 3; k++) {
                uint32_t v = m->index[3 * (size_t)t + k];
                out->indices[3 * ((size_t)a->first_triangle + t) + k] = v;
                lc_scene_albedo(&sc, t, corner_b[k][0], corner_b[k][1], out->vertices[a->first_vertex + v].albedo);
            }
            float c[3];
            double area = lc_mesh_triangle_area(m, t);
            lc_scene_albedo(&sc, t, 1.0f / 3, 1.0f / 3, c);
            for (int k = 0; k < 3; k++) albedo_sum[k] += c[k] * area;
            area_sum += area;
        }
        for (int k = 0; k < 3; k++) a->albedo[k] = area_sum > 0 ? (float)(albedo_sum[k] / area_sum) : 0;
        if ((s->transfer && bake_asset_transfer(s, &sc, (uint32_t)i, out, err, errlen) != 0) ||
            (s->mr_points > 0 && bake_asset_sparse(s, (uint32_t)i, out, err, errlen) != 0)) {
            lc_scene_release(&sc);
            goto err;
        }
        out->n_vertices = (uint32_t)nv;
        out->n_triangles = (uint32_t)nt;
        out->n_assets = (uint32_t)i + 1;
        lc_scene_release(&sc);
    }
    return 0;
oom:
    lc_set_err(err, errlen, "out of memory importing assets");
err:
    bake_assets_release(out);
    return -1;
}

static const char *bake_light_type_name(lc_light_type t) {
    switch (t) {
    case LC_LIGHT_POINT: return "point";
    case LC_LIGHT_SPOT: return "spot";
    case LC_LIGHT_DIRECTIONAL: return "directional";
    case LC_LIGHT_AREA: return "area";
    }
    return "point";
}

/* Buried surfels: a surfel whose hemisphere mostly sees back faces lies inside closed
 * geometry (the floor under a column base, faces covered by other faces). No cache can see
 * it and no light reaches it, but in the hierarchy it shares nodes with visible surfels, so
 * it pulls every node average down, and a texel list gives it the hits beside the column
 * (docs/ARCHITECTURE.md, Decisions). --drop-buried, on past draft: fewer surfels than
 * --surfels remain. BAKE_BURIED_RAYS fixed directions (a spherical
 * Fibonacci hemisphere in the surfel's frame): deterministic for any thread count. */
#define BAKE_BURIED_RAYS 32u
#define BAKE_BURIED_FRACTION 0.5f

typedef struct {
    const lc_rt *rt;
    const lc_lcb_surfel *s;
    uint8_t *buried;
} bake_buried_ctx;

static void bake_buried_range(void *arg, size_t begin, size_t end, int thread) {
    (void)thread;
    bake_buried_ctx *c = arg;
    const uint32_t R = BAKE_BURIED_RAYS;
    for (size_t i = begin; i < end; i++) {
        const lc_lcb_surfel *x = &c->s[i];
        lc_vec3 n = lc_v3_load(x->normal), t, b;
        lc_v3_basis(n, &t, &b);
        float pm = fmaxf(fabsf(x->position[0]), fmaxf(fabsf(x->position[1]), fabsf(x->position[2])));
        float org[3];
        lc_v3_store(org, lc_v3_add(lc_v3_load(x->position), lc_v3_scale(n, lc_ray_lift_point(pm))));
        uint32_t back = 0;
        for (uint32_t j = 0; j < R; j++) {
            float z = 1.0f - ((float)j + 0.5f) / (float)R, r = sqrtf(fmaxf(0.0f, 1 - z * z));
            float phi = 2.0f * (float)M_PI * (float)j * 0.6180339887f;
            float dir[3];
            lc_v3_store(
                dir,
                lc_v3_add(lc_v3_add(lc_v3_scale(t, r * cosf(phi)), lc_v3_scale(b, r * sinf(phi))), lc_v3_scale(n, z)));
            lc_hit h;
            if (lc_rt_intersect(c->rt, org, dir, 0.0f, INFINITY, &h) && h.backface) back++;
        }
        c->buried[i] = (float)back >= BAKE_BURIED_FRACTION * (float)R;
    }
}

/* Drops buried surfels in place (surfels and their triangles stay paired, order kept).
 * Keeps everything when all would go. Returns the number dropped, or -1 (out of memory). */
static int64_t bake_drop_buried(const lc_rt *rt, lc_lcb_surfel *surfels, uint32_t *tri, uint32_t *n, int threads) {
    uint8_t *bur = malloc(*n ? *n : 1);
    if (!bur) return -1;
    bake_buried_ctx bc = {rt, surfels, bur};
    lc_parallel_for(threads, *n, 256, bake_buried_range, &bc);
    uint32_t k = 0;
    for (uint32_t i = 0; i < *n; i++) k += !bur[i];
    if (k > 0 && k < *n) {
        k = 0;
        for (uint32_t i = 0; i < *n; i++) {
            if (bur[i]) continue;
            surfels[k] = surfels[i];
            tri[k++] = tri[i];
        }
    } else {
        k = *n;
    }
    free(bur);
    int64_t dropped = (int64_t)*n - k;
    *n = k;
    return dropped;
}

/* Initial state for the daemon: the scene's lights and emissive materials. */
static cJSON *bake_lights_json(const lc_scene *scene) {
    cJSON *arr = cJSON_CreateArray();
    for (uint32_t i = 0; i < scene->n_lights; i++) {
        const lc_light *l = &scene->lights[i];
        cJSON *o = cJSON_CreateObject();
        char id[80];
        if (l->name[0]) snprintf(id, sizeof id, "%s", l->name);
        else snprintf(id, sizeof id, "light%u", i);
        cJSON_AddStringToObject(o, "id", id);
        cJSON_AddStringToObject(o, "type", bake_light_type_name(l->type));
        cJSON_AddItemToObject(o, "color", bake_vec3(l->color));
        cJSON_AddNumberToObject(o, "intensity", l->intensity);
        if (l->range > 0) cJSON_AddNumberToObject(o, "range", l->range);
        if (l->type != LC_LIGHT_DIRECTIONAL) cJSON_AddItemToObject(o, "position", bake_vec3(l->position));
        if (l->type != LC_LIGHT_POINT) cJSON_AddItemToObject(o, "direction", bake_vec3(l->direction));
        if (l->type == LC_LIGHT_SPOT) {
            cJSON_AddNumberToObject(o, "innerConeAngle", l->inner_cone);
            cJSON_AddNumberToObject(o, "outerConeAngle", l->outer_cone);
        }
        cJSON_AddItemToArray(arr, o);
    }
    return arr;
}

static cJSON *bake_settings_json(const lc_bake_settings *s) {
    cJSON *o = cJSON_CreateObject();
    for (const lc_opt *opt = lc_bake_options(); opt->name; opt++) {
        const char *field = (const char *)s + opt->offset;
        /* Output paths and run-time knobs do not describe the bake's content. */
        if (!strcmp(opt->name, "output") || !strcmp(opt->name, "glb") || !strcmp(opt->name, "write-glb") ||
            !strcmp(opt->name, "stats-json") || !strcmp(opt->name, "threads") || !strcmp(opt->name, "quiet"))
            continue;
        switch (opt->type) {
        case LC_OPT_INT: cJSON_AddNumberToObject(o, opt->name, *(const int *)field); break;
        case LC_OPT_FLOAT: cJSON_AddNumberToObject(o, opt->name, *(const double *)field); break;
        case LC_OPT_BOOL: cJSON_AddBoolToObject(o, opt->name, *(const int *)field); break;
        case LC_OPT_STRING: cJSON_AddStringToObject(o, opt->name, field); break;
        case LC_OPT_ENUM: {
            int idx = *(const int *)field;
            const char *p = opt->choices;
            for (int k = 0; k < idx && p; k++) {
                p = strchr(p, '|');
                if (p) p++;
            }
            char buf[64];
            size_t len = p ? strcspn(p, "|") : 0;
            if (len >= sizeof buf) len = sizeof buf - 1;
            memcpy(buf, p ? p : "", len);
            buf[len] = 0;
            cJSON_AddStringToObject(o, opt->name, buf);
            break;
        }
        case LC_OPT_CALLBACK: break;
        }
    }
    cJSON *assets = cJSON_CreateArray();
    for (int i = 0; i < s->n_assets; i++) {
        cJSON *a = cJSON_CreateObject();
        cJSON_AddStringToObject(a, "name", s->assets[i].name);
        cJSON_AddStringToObject(a, "path", s->assets[i].path);
        cJSON_AddItemToArray(assets, a);
    }
    cJSON_AddItemToObject(o, "asset", assets);
    return o;
}

/* --- the pipeline --------------------------------------------------------------------------- */

/* Everything one bake builds, stage by stage (ARCHITECTURE.md, "The bake pipeline"); each
 * stage reads what the ones before it left here. bake_job_release frees it all. */
typedef struct bake_job {
    const lc_bake_settings *s;
    lc_scene scene;       /* 1. import */
    lc_uv_stats uvs;      /* 2. lightmap UVs */
    lc_rt *rt;            /* 3. ray tracing structure */
    lc_lightmap lm;       /* 4. texel caches ... */
    lc_lcb_cache *caches; /* ... then the grid caches after them (5) */
    uint32_t n_caches, n_texel_caches;
    uint32_t probe_rays; /* per cache, as used (lc_bake_probe_rays) */
    lc_grid grid;        /* 5. grid caches */
    uint32_t *cell_cache;
    lc_relocate_stats rs;   /* 6. relocation */
    lc_lcb_surfel *surfels; /* 7. surfels (8 reorders them) */
    uint32_t *surfel_tri, n_surfels;
    uint32_t surfels_refined; /* of them placed by --surfel-refine */
    lc_hierarchy hier;        /* 8. hierarchy */
    uint32_t *perm, *tri_sorted;
    lc_lcb_link *links; /* 9. links: LINK's n_caches x --links, then GLNK's grid rows */
    uint16_t *link_sh;
    uint64_t n_links;              /* LINK's and GLNK's */
    uint32_t grid_links_per_cache; /* GLNK's row (lc_bake_grid_links; 0: none) */
    uint32_t *seen;                /* per surfel: caches that see it (--exposure only) */
    lc_link_stats ls;
    lc_exposure_stats es;
    uint32_t *texel_surfels_first;       /* 9. --texel-gather surfels: per texel cache (TSGF) */
    lc_lcb_surfel_weight *texel_surfels; /* its (surfel, weight) list (TSGW) */
    uint64_t n_texel_surfels;
    uint32_t texel_gather_rays; /* per texel cache, as used (lc_bake_texel_gather_rays) */
    lc_probebake probes;        /* 10. the probes solver (--solver probes|both) */
    bake_assets assets;         /* 11. dynamic-object assets */
    lc_lcb_material *mats;      /* 12. the file's sections */
    lc_lcb_vertex *verts;
    lc_lcb_triangle *tris;
    cJSON *meta;
    char *meta_text;
    lc_lcb_writer *w;
} bake_job;

static void bake_job_release(bake_job *b) {
    lc_lcb_writer_release(b->w);
    cJSON_free(b->meta_text);
    cJSON_Delete(b->meta);
    bake_assets_release(&b->assets);
    lc_probebake_release(&b->probes);
    free(b->mats);
    free(b->verts);
    free(b->tris);
    free(b->links);
    free(b->link_sh);
    free(b->texel_surfels_first);
    free(b->texel_surfels);
    lc_hierarchy_release(&b->hier);
    free(b->perm);
    free(b->tri_sorted);
    free(b->seen);
    free(b->surfel_tri);
    free(b->surfels);
    free(b->cell_cache);
    free(b->caches);
    lc_lightmap_release(&b->lm);
    lc_rt_release(b->rt);
    lc_scene_release(&b->scene);
}

/* The message of every allocation failure in the pipeline; returns the bake's failure code. */
static int bake_oom(char *err, size_t errlen) {
    lc_set_err(err, errlen, "out of memory (lower --surfels, --links or --atlas-size)");
    return 1;
}

/* Each stage returns 0, 1 (bad input / failure) or 3 (cannot write output), with err set. */

static int bake_import_scene(bake_job *b, char *err, size_t errlen) {
    const lc_bake_settings *s = b->s;
    lc_import_params ip = {.scale = s->scale, .flip_winding = s->flip_winding};
    if (lc_scene_import(s->input, &ip, &b->scene, err, errlen) != 0) return 1;
    if (b->scene.n_degenerate_dropped)
        lc_warn("bake", "%u degenerate or non-finite triangles dropped", b->scene.n_degenerate_dropped);
    if (!s->quiet)
        lc_info("bake", "imported %s: %u triangles, %u materials, %u textures, %u lights", s->input,
                b->scene.mesh.n_triangles, b->scene.n_materials, b->scene.n_textures, b->scene.n_lights);
    return 0;
}

/* Generated charts, or the asset's own second UV set measured. */
static int bake_lightmap_uv(bake_job *b, char *err, size_t errlen) {
    const lc_bake_settings *s = b->s;
    lc_uv_params uvp = {.texels_per_metre = s->texel_density,
                        .atlas_size = s->texel_density > 0 ? 0 : (uint32_t)s->atlas_size,
                        .min_texels_per_metre = s->min_texel_density,
                        .padding = (uint32_t)s->padding,
                        .chart_angle_deg = s->chart_angle,
                        .threads = s->threads};
    if (b->scene.has_lightmap_uv) {
        if (lc_uvgen_measure(&b->scene.mesh, &uvp, &b->uvs, err, errlen) != 0) return 1;
    } else if (lc_uvgen(&b->scene.mesh, &uvp, &b->uvs, err, errlen) != 0) {
        return 1;
    }
    if (!s->quiet)
        lc_info("bake",
                "lightmap %ux%u, %u charts, %.1f texels/m, atlas usage %.1f%%, texels %.4f m apart (p95 %.4f m)",
                b->uvs.width, b->uvs.height, b->uvs.n_charts, b->uvs.texels_per_metre, b->uvs.usage * 100,
                b->uvs.spacing_mean, b->uvs.spacing_p95);
    return 0;
}

static int bake_bvh(bake_job *b, char *err, size_t errlen) {
    b->rt = lc_rt_create(&b->scene.mesh, b->s->threads, err, errlen);
    return b->rt ? 0 : 1;
}

/* Texel caches, then seam dilation. */
static int bake_texel_caches(bake_job *b, char *err, size_t errlen) {
    if (lc_texels_rasterize(&b->scene, b->uvs.width, b->uvs.height, b->s->threads, &b->lm, &b->caches, &b->n_caches,
                            err, errlen) != 0)
        return 1;
    if (b->n_caches == 0) {
        lc_set_err(err, errlen, "no lightmap texel is covered; raise --atlas-size or --texel-density");
        return 1;
    }
    lc_texels_dilate(&b->lm, (uint32_t)b->s->dilate, b->s->threads);
    b->n_texel_caches = b->n_caches;
    return 0;
}

static int bake_grid_caches(bake_job *b, char *err, size_t errlen) {
    const lc_bake_settings *s = b->s;
    if (lc_grid_layout(b->scene.bounds_min, b->scene.bounds_max, s->grid_cell, (uint32_t)s->grid_max_dim,
                       (uint32_t)s->grid_max_samples, &b->grid, err, errlen) != 0)
        return 1;
    return lc_grid_place(&b->grid, &b->caches, &b->n_caches, &b->cell_cache, err, errlen) != 0 ? 1 : 0;
}

/* Moves caches out of geometry. */
static int bake_relocate(bake_job *b, char *err, size_t errlen) {
    (void)err, (void)errlen;
    lc_relocate_params rp = {.rays = (uint32_t)b->s->reloc_rays,
                             .texel_fraction = 0.6,
                             .grid_fraction = 0.8,
                             .offset = b->s->reloc_offset,
                             .grid_clearance = b->s->grid_clearance * b->grid.cell,
                             .seed = (uint64_t)b->s->seed,
                             .threads = b->s->threads};
    lc_relocate_caches(b->rt, b->caches, b->n_caches, &rp, &b->rs);
    return 0;
}

static int bake_surfels(bake_job *b, char *err, size_t errlen) {
    const lc_bake_settings *s = b->s;
    const uint32_t share = (uint32_t)floor(s->surfel_refine * s->surfels);
    /* The caches are placed, so whether the texel caches will gather per surfel is known. */
    const int lists = lc_bake_texel_surfels(s, lc_bake_probe_rays(s, b->n_caches));
    const uint32_t extra = share + (lists ? (uint32_t)floor(s->list_refine * s->surfels) : 0);
    lc_surfel_params sp = {.target_count = (uint32_t)s->surfels - share,
                           .relax_iterations = (uint32_t)s->relax,
                           .seed = (uint64_t)s->seed,
                           .threads = s->threads};
    if (lc_surfels_generate(&b->scene, &sp, &b->surfels, &b->surfel_tri, &b->n_surfels, err, errlen) != 0) return 1;
    if (extra > 0) {
        lc_surfel_refine_params rp = {.extra = extra,
                                      .rounds = 2,
                                      .pilot_rays = 32,
                                      .area_samples = 64,
                                      .seed = (uint64_t)s->seed,
                                      .threads = s->threads};
        lc_surfel_refine_stats rs;
        if (lc_surfels_refine(b->rt, &b->scene, b->caches, b->n_caches, &rp, &b->surfels, &b->surfel_tri, &b->n_surfels,
                              &rs, err, errlen) != 0)
            return 1;
        b->surfels_refined = rs.added;
        if (!s->quiet)
            lc_info("bake",
                    "surfel refinement: %u surfels where caches see a surface without its own, %u more by area; "
                    "pilot hits on such surfaces %.1f%% -> %.1f%%; areas %.2f-%.2f x the mean",
                    rs.added, rs.filled, 100 * rs.misplaced_before, 100 * rs.misplaced_after, rs.area_min, rs.area_max);
    }
    int64_t n_buried =
        s->drop_buried ? bake_drop_buried(b->rt, b->surfels, b->surfel_tri, &b->n_surfels, s->threads) : 0;
    if (n_buried < 0) return bake_oom(err, errlen);
    if (!s->quiet && n_buried > 0)
        lc_info("bake", "dropped %lld buried surfels (inside geometry), %u left", (long long)n_buried, b->n_surfels);
    return 0;
}

/* The surfel tree (it reorders the surfels; their triangles follow), then each surfel's
 * nearest cache. */
static int bake_hierarchy(bake_job *b, char *err, size_t errlen) {
    if (lc_hierarchy_build(b->surfels, b->n_surfels, (lc_hierarchy_method)b->s->hierarchy, b->s->threads, &b->hier,
                           &b->perm, err, errlen) != 0)
        return 1;
    b->tri_sorted = malloc((size_t)b->n_surfels * sizeof *b->tri_sorted);
    if (!b->tri_sorted) return bake_oom(err, errlen);
    for (uint32_t i = 0; i < b->n_surfels; i++) b->tri_sorted[i] = b->surfel_tri[b->perm[i]];
    bake_surfel_caches(&b->scene, &b->lm, &b->grid, b->cell_cache, b->caches, b->surfels, b->tri_sorted, b->n_surfels);
    return 0;
}

/* Cache c's row of links: LINK's, or GLNK's for a grid cache when the bake has it. */
static lc_lcb_link *bake_cache_links(const bake_job *b, uint32_t c, uint32_t *per_cache) {
    const uint32_t per = (uint32_t)b->s->links;
    if (b->grid_links_per_cache && c >= b->n_texel_caches) {
        *per_cache = b->grid_links_per_cache;
        return b->links + (size_t)b->n_caches * per + (size_t)(c - b->n_texel_caches) * b->grid_links_per_cache;
    }
    *per_cache = per;
    return b->links + (size_t)c * per;
}

/* Links come used-first, padding after; records each cache's count so runtimes can stop
 * early. 1 with err if a used link follows padding. */
static int bake_link_counts(bake_job *b, char *err, size_t errlen) {
    for (uint32_t c = 0; c < b->n_caches; c++) {
        uint32_t per_cache;
        const lc_lcb_link *cl = bake_cache_links(b, c, &per_cache);
        uint32_t used = 0;
        while (used < per_cache && cl[used].factor > 0) used++;
        for (uint32_t j = used; j < per_cache; j++)
            if (cl[j].factor > 0) {
                lc_set_err(err, errlen, "internal error: cache %u has a used link after padding", c);
                return 1;
            }
        b->caches[c].link_count = used;
    }
    return 0;
}

/* The cut for every cache; with GLNK, texel caches' rows in LINK and grid caches' in GLNK
 * (their LINK slots stay padding), the stats as means over all caches. */
static int bake_link_cuts(bake_job *b, lc_link_params *lp) {
    if (!b->grid_links_per_cache)
        return lc_links_build(b->rt, b->surfels, b->n_surfels, &b->hier, b->caches, b->n_caches, lp, b->links,
                              b->link_sh, &b->ls);
    const uint32_t n_texel = b->n_texel_caches, n_grid = b->n_caches - n_texel;
    lc_link_stats ts = {0}, gs = {0};
    if (lc_links_build(b->rt, b->surfels, b->n_surfels, &b->hier, b->caches, n_texel, lp, b->links, NULL, &ts) != 0)
        return -1;
    uint32_t per_cache;
    lc_lcb_link *grid_rows = bake_cache_links(b, n_texel, &per_cache);
    lp->links_per_cache = per_cache;
    if (lc_links_build(b->rt, b->surfels, b->n_surfels, &b->hier, b->caches + n_texel, n_grid, lp, grid_rows, NULL,
                       &gs) != 0)
        return -1;
    b->ls.mean_links_used = (ts.mean_links_used * n_texel + gs.mean_links_used * n_grid) / b->n_caches;
    b->ls.mean_solid_angle = (ts.mean_solid_angle * n_texel + gs.mean_solid_angle * n_grid) / b->n_caches;
    b->ls.rays = ts.rays + gs.rays;
    return 0;
}

/* Per cache, a cut of the tree by visible solid angle; then, with --exposure, the surfel
 * areas weighed by how many caches see them. */
static int bake_links(bake_job *b, char *err, size_t errlen) {
    const lc_bake_settings *s = b->s;
    if (s->solver == LC_BAKE_SOLVER_PROBES) return 0; /* no PIC: LINK stays empty, every link_count 0 */
    b->grid_links_per_cache = lc_bake_grid_links(s, b->n_caches - b->n_texel_caches);
    b->n_links = (uint64_t)b->n_caches * (uint64_t)s->links +
        (uint64_t)(b->n_caches - b->n_texel_caches) * b->grid_links_per_cache;
    if (b->n_links > (1ull << 31) / sizeof(lc_lcb_link)) {
        lc_set_err(err, errlen, "%u caches x %d links is over 2 GiB of links; lower --links or --atlas-size",
                   b->n_caches, s->links);
        return 1;
    }
    b->links = calloc(b->n_links, sizeof *b->links);
    if (!b->links) return bake_oom(err, errlen);
    if (s->link_sh) {
        b->link_sh = calloc(b->n_links * (uint64_t)s->bands * s->bands, sizeof *b->link_sh);
        if (!b->link_sh) return bake_oom(err, errlen);
    }
    b->probe_rays = lc_bake_probe_rays(s, b->n_caches);
    lc_link_params lp = {.links_per_cache = (uint32_t)s->links,
                         .node_samples = (uint32_t)s->node_samples,
                         .final_samples = (uint32_t)s->final_samples,
                         .sh_bands = s->link_sh ? (uint32_t)s->bands : 0,
                         .seed = (uint64_t)s->seed,
                         .probe_rays = b->probe_rays,
                         .threads = s->threads};
    if (s->exposure) {
        b->seen = calloc(b->n_surfels ? b->n_surfels : 1, sizeof *b->seen);
        if (!b->seen) return bake_oom(err, errlen);
        lp.surfel_seen = b->seen;
    }
    if (bake_link_cuts(b, &lp) != 0) {
        lc_set_err(err, errlen, "link generation failed (out of memory?)");
        return 1;
    }
    if (bake_link_counts(b, err, errlen) != 0) return 1;
    if (b->seen &&
        lc_exposure_apply(b->seen, b->surfels, b->n_surfels, &b->hier, b->links, b->n_links, b->link_sh,
                          b->link_sh ? (uint32_t)(s->bands * s->bands) : 0, &b->es) != 0) {
        lc_set_err(err, errlen, "exposure: no cache sees any surfel (or out of memory); bake with --exposure false");
        return 1;
    }
    if (!s->quiet && b->seen)
        lc_info("bake", "exposure: %u surfels (%.2f%% of the area) seen by no cache", b->es.unseen,
                100.0 * b->es.unseen_area / lc_mesh_total_area(&b->scene.mesh));
    if (lc_bake_texel_surfels(s, b->probe_rays)) {
        b->texel_gather_rays = lc_bake_texel_gather_rays(s, b->n_texel_caches);
        if (lc_links_texel_surfels(b->rt, b->surfels, b->n_surfels, b->caches, b->n_texel_caches, b->texel_gather_rays,
                                   (uint64_t)s->seed, s->threads, &b->texel_surfels_first, &b->texel_surfels,
                                   &b->n_texel_surfels) != 0) {
            lc_set_err(err, errlen, "texel surfel lists failed (out of memory? lower --texel-gather-rays)");
            return 1;
        }
        if (!s->quiet)
            lc_info("bake", "texel surfel lists: %u rays, %llu entries, %.1f per texel cache (%.1f MiB)",
                    b->texel_gather_rays, (unsigned long long)b->n_texel_surfels,
                    b->n_texel_caches ? (double)b->n_texel_surfels / b->n_texel_caches : 0.0,
                    (double)b->n_texel_surfels * sizeof(lc_lcb_surfel_weight) / (1 << 20));
    }
    return 0;
}

/* The probes solver's data (bake/probes.h), unless the bake is PIC only. */
static int bake_probes(bake_job *b, char *err, size_t errlen) {
    const lc_bake_settings *s = b->s;
    if (s->solver == LC_BAKE_SOLVER_PIC) return 0;
    lc_probebake_params pp = {.count = (uint32_t)s->probes,
                              .density = s->probe_density,
                              .relight_rays = (uint32_t)s->probe_relight_rays,
                              .sh_bands = (uint32_t)s->probe_bands,
                              .overlaps = (uint32_t)s->probe_overlaps,
                              .receiver_rays = (uint32_t)s->probe_receiver_rays,
                              .cluster_rows = (uint32_t)s->probe_cluster,
                              .max_rank = (uint32_t)s->probe_rank,
                              .svd_error = s->probe_svd_error,
                              .band_weight = s->probe_band_weight,
                              .visibility = s->probe_visibility,
                              .unseen = s->probe_unseen,
                              .seed = (uint64_t)s->seed,
                              .threads = s->threads};
    if (lc_probebake_run(b->rt, b->scene.bounds_min, b->scene.bounds_max, b->surfels, b->n_surfels, b->caches,
                         b->n_caches, &pp, &b->probes, err, errlen) != 0)
        return 1;
    const lc_probebake *pb = &b->probes;
    if (!s->quiet)
        lc_info("bake",
                "probes: %u (of %u free voxels), support radius %.3f m, %.1f probes per receiver, %u clusters of "
                "mean rank %.1f (worst error %.4f); receiver rays that hit a point no probe sees: %.1f%% (texels), "
                "%.1f%% (grid); %.2f + %.2f + %.2f + %.2f s",
                pb->header.n_probes, pb->n_candidates, pb->header.support_radius, pb->mean_probes_used,
                pb->header.n_clusters, pb->mean_rank, pb->worst_error, 100 * pb->orphan_fraction[0],
                100 * pb->orphan_fraction[1], pb->seconds[0], pb->seconds[1], pb->seconds[2], pb->seconds[3]);
    return 0;
}

static int bake_dynamic_assets(bake_job *b, char *err, size_t errlen) {
    return bake_assets_import(b->s, &b->assets, err, errlen) != 0 ? 1 : 0;
}

/* The mesh and materials in the file's record layouts. */
static int bake_geometry_sections(bake_job *b, char *err, size_t errlen) {
    const lc_scene *scene = &b->scene;
    const lc_mesh *m = &scene->mesh;
    b->mats = calloc(scene->n_materials ? scene->n_materials : 1, sizeof *b->mats);
    b->verts = calloc(m->n_vertices, sizeof *b->verts);
    b->tris = calloc(m->n_triangles, sizeof *b->tris);
    if (!b->mats || !b->verts || !b->tris) return bake_oom(err, errlen);
    for (uint32_t i = 0; i < scene->n_materials; i++) {
        lc_lcb_material *mt = &b->mats[i];
        snprintf(mt->name, sizeof mt->name, "%s", scene->materials[i].name);
        memcpy(mt->base_color, scene->materials[i].base_color, sizeof mt->base_color);
        memcpy(mt->emission, scene->materials[i].emission, sizeof mt->emission);
        mt->flags = scene->materials[i].base_texture >= 0 ? 1u : 0u;
    }
    for (uint32_t i = 0; i < m->n_vertices; i++) {
        memcpy(b->verts[i].position, m->position + 3 * (size_t)i, sizeof b->verts[i].position);
        memcpy(b->verts[i].normal, m->normal + 3 * (size_t)i, sizeof b->verts[i].normal);
        memcpy(b->verts[i].uv1, m->uv1 + 2 * (size_t)i, sizeof b->verts[i].uv1);
    }
    for (uint32_t i = 0; i < m->n_triangles; i++) {
        memcpy(b->tris[i].v, m->index + 3 * (size_t)i, sizeof b->tris[i].v);
        b->tris[i].material = m->material[i];
    }
    return 0;
}

/* META's lists: the scene's lights (the daemon's initial state), emitters and assets. */
static void bake_meta_lists(const bake_job *b, cJSON *meta) {
    const lc_scene *scene = &b->scene;
    cJSON_AddItemToObject(meta, "lights", bake_lights_json(scene));
    cJSON *jem = cJSON_AddArrayToObject(meta, "emitters");
    for (uint32_t i = 0; i < scene->n_materials; i++) {
        const float *e = scene->materials[i].emission;
        if (e[0] <= 0 && e[1] <= 0 && e[2] <= 0) continue;
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "material", scene->materials[i].name);
        cJSON_AddItemToObject(o, "emission", bake_vec3(e));
        cJSON_AddItemToArray(jem, o);
    }
    cJSON *ja = cJSON_AddArrayToObject(meta, "assets");
    for (uint32_t i = 0; i < b->assets.n_assets; i++) {
        const lc_lcb_asset *a = &b->assets.assets[i];
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "name", a->name);
        cJSON_AddNumberToObject(o, "triangles", a->triangle_count);
        cJSON_AddItemToObject(o, "bounds_min", bake_vec3(a->bounds_min));
        cJSON_AddItemToObject(o, "bounds_max", bake_vec3(a->bounds_max));
        for (uint32_t t = 0; t < b->assets.n_transfers; t++) {
            const lc_lcb_transfer *tr = &b->assets.transfers[t];
            if (tr->asset != i) continue;
            cJSON *jt = cJSON_AddObjectToObject(o, "transfer");
            cJSON_AddNumberToObject(jt, "dims", tr->dims);
            cJSON_AddNumberToObject(jt, "coefficients", tr->coeffs);
            cJSON_AddNumberToObject(jt, "rays", tr->rays);
            cJSON_AddNumberToObject(jt, "half_extent", tr->half_extent);
            cJSON_AddNumberToObject(jt, "outer_radius", tr->outer_radius);
            cJSON_AddNumberToObject(jt, "bytes", (double)lc_lcb_transfer_bytes(tr));
        }
        uint32_t sp = 0;
        for (uint32_t p = 0; p < b->assets.n_sparse; p++) sp += b->assets.sparse[p].asset == i;
        cJSON_AddNumberToObject(o, "sparse_points", sp);
        cJSON_AddItemToArray(ja, o);
    }
}

/* META: what was baked from what, with which settings, and what came out of each stage. */
static int bake_meta(bake_job *b, char *err, size_t errlen) {
    const lc_bake_settings *s = b->s;
    const lc_scene *scene = &b->scene;
    const lc_mesh *m = &scene->mesh;
    cJSON *meta = b->meta = cJSON_CreateObject();
    if (!meta) return bake_oom(err, errlen);
    cJSON_AddStringToObject(meta, "format", "lucent-bake");
    cJSON_AddStringToObject(meta, "generator", "lucent-bake " LC_BAKE_VERSION);
    cJSON_AddStringToObject(meta, "source", s->input);
    cJSON_AddItemToObject(meta, "settings", bake_settings_json(s));
    cJSON_AddNumberToObject(meta, "sh_bands", s->bands);
    double area = lc_mesh_total_area(m);
    cJSON *js = cJSON_AddObjectToObject(meta, "scene");
    cJSON_AddNumberToObject(js, "triangles", m->n_triangles);
    cJSON_AddNumberToObject(js, "vertices", m->n_vertices);
    cJSON_AddNumberToObject(js, "materials", scene->n_materials);
    cJSON_AddNumberToObject(js, "textures", scene->n_textures);
    cJSON_AddNumberToObject(js, "degenerate_dropped", scene->n_degenerate_dropped);
    cJSON_AddNumberToObject(js, "area", area);
    cJSON_AddItemToObject(js, "bounds_min", bake_vec3(scene->bounds_min));
    cJSON_AddItemToObject(js, "bounds_max", bake_vec3(scene->bounds_max));
    cJSON *jl = cJSON_AddObjectToObject(meta, "lightmap");
    cJSON_AddNumberToObject(jl, "width", b->lm.width);
    cJSON_AddNumberToObject(jl, "height", b->lm.height);
    cJSON_AddNumberToObject(jl, "texels_per_metre", b->uvs.texels_per_metre);
    cJSON_AddNumberToObject(jl, "usage", b->uvs.usage);
    cJSON_AddNumberToObject(jl, "charts", b->uvs.n_charts);
    cJSON_AddNumberToObject(jl, "texel_spacing_mean", b->uvs.spacing_mean);
    cJSON_AddNumberToObject(jl, "texel_spacing_p95", b->uvs.spacing_p95);
    cJSON_AddNumberToObject(jl, "texel_spacing_max", b->uvs.spacing_max);
    cJSON_AddNumberToObject(jl, "covered", b->lm.n_covered);
    cJSON_AddNumberToObject(jl, "dilated", b->lm.n_dilated);
    cJSON_AddStringToObject(jl, "uv_source", scene->has_lightmap_uv ? "asset" : "generated");
    cJSON *jg = cJSON_AddObjectToObject(meta, "grid");
    cJSON_AddItemToObject(jg, "origin", bake_vec3(b->grid.origin));
    cJSON_AddNumberToObject(jg, "cell", b->grid.cell);
    cJSON_AddNumberToObject(jg, "clearance", b->s->grid_clearance * b->grid.cell); /* metres, moved caches */
    double dims[3] = {b->grid.dims[0], b->grid.dims[1], b->grid.dims[2]};
    cJSON_AddItemToObject(jg, "dims", cJSON_CreateDoubleArray(dims, 3));
    cJSON *jsu = cJSON_AddObjectToObject(meta, "surfels");
    cJSON_AddNumberToObject(jsu, "count", b->n_surfels);
    double surfel_area = 0; /* exposure keeps the sum */
    for (uint32_t i = 0; i < b->n_surfels; i++) surfel_area += b->surfels[i].area;
    cJSON_AddNumberToObject(jsu, "area", b->n_surfels ? surfel_area / b->n_surfels : 0); /* mean: the nominal area */
    cJSON_AddBoolToObject(jsu, "exposure", b->seen != NULL);
    cJSON_AddNumberToObject(jsu, "unseen", b->es.unseen);
    cJSON_AddNumberToObject(jsu, "refined", b->surfels_refined); /* placed by --surfel-refine */
    cJSON *jh = cJSON_AddObjectToObject(meta, "hierarchy");
    cJSON_AddStringToObject(jh, "method", s->hierarchy == LC_HIERARCHY_AAC ? "aac" : "kdtree");
    cJSON_AddNumberToObject(jh, "nodes", b->hier.n_nodes);
    cJSON_AddNumberToObject(jh, "levels", b->hier.n_levels);
    cJSON_AddNumberToObject(jh, "quality", lc_hierarchy_quality(b->surfels, &b->hier));
    cJSON *jc = cJSON_AddObjectToObject(meta, "caches");
    cJSON_AddNumberToObject(jc, "count", b->n_caches);
    cJSON_AddNumberToObject(jc, "texel", b->n_texel_caches);
    cJSON_AddNumberToObject(jc, "grid", b->n_caches - b->n_texel_caches);
    cJSON_AddNumberToObject(jc, "moved", b->rs.moved);
    cJSON_AddNumberToObject(jc, "inside", b->rs.inside);
    cJSON *jk = cJSON_AddObjectToObject(meta, "links");
    cJSON_AddNumberToObject(jk, "per_cache", s->solver == LC_BAKE_SOLVER_PROBES ? 0 : s->links);
    if (b->grid_links_per_cache) cJSON_AddNumberToObject(jk, "grid_per_cache", b->grid_links_per_cache);
    cJSON_AddNumberToObject(jk, "sh_bands", s->link_sh ? s->bands : 0);
    cJSON_AddNumberToObject(jk, "mean_used", b->ls.mean_links_used);
    cJSON_AddNumberToObject(jk, "mean_solid_angle", b->ls.mean_solid_angle);
    cJSON_AddNumberToObject(jk, "rays", (double)b->ls.rays);
    cJSON_AddNumberToObject(jk, "probe_rays", b->probe_rays);
    cJSON_AddStringToObject(jk, "texel_gather", b->texel_surfels_first ? "surfels" : "links");
    cJSON_AddNumberToObject(jk, "texel_surfel_entries", (double)b->n_texel_surfels);
    cJSON_AddNumberToObject(jk, "texel_gather_rays", b->texel_gather_rays);
    cJSON *jsv = cJSON_AddArrayToObject(meta, "solvers");
    if (s->solver != LC_BAKE_SOLVER_PROBES) cJSON_AddItemToArray(jsv, cJSON_CreateString("pic"));
    if (s->solver != LC_BAKE_SOLVER_PIC) {
        cJSON_AddItemToArray(jsv, cJSON_CreateString("probes"));
        const lc_probebake *pb = &b->probes;
        cJSON *jp = cJSON_AddObjectToObject(meta, "probes");
        cJSON_AddNumberToObject(jp, "count", pb->header.n_probes);
        cJSON_AddNumberToObject(jp, "candidates", pb->n_candidates);
        cJSON_AddNumberToObject(jp, "support_radius", pb->header.support_radius);
        cJSON_AddNumberToObject(jp, "probes_per_receiver", pb->mean_probes_used);
        cJSON_AddNumberToObject(jp, "clusters", pb->header.n_clusters);
        cJSON_AddNumberToObject(jp, "rows", pb->header.n_rows);
        cJSON_AddNumberToObject(jp, "mean_rank", pb->mean_rank);
        cJSON_AddNumberToObject(jp, "worst_error", pb->worst_error);
        cJSON_AddNumberToObject(jp, "orphan_rays_texel", pb->orphan_fraction[0]);
        cJSON_AddNumberToObject(jp, "orphan_rays_grid", pb->orphan_fraction[1]);
        cJSON_AddNumberToObject(jp, "unseen_entries", (double)pb->n_unseen);
        cJSON_AddNumberToObject(jp, "rays", (double)pb->rays);
        double st[4] = {pb->seconds[0], pb->seconds[1], pb->seconds[2], pb->seconds[3]};
        cJSON_AddItemToObject(jp, "stage_seconds", cJSON_CreateDoubleArray(st, 4));
    }
    bake_meta_lists(b, meta);
    b->meta_text = cJSON_PrintUnformatted(meta);
    return b->meta_text ? 0 : bake_oom(err, errlen);
}

/* The .lcb's sections (borrowed from the job until the write returns). */
static int bake_add_sections(bake_job *b, char *err, size_t errlen) {
    const lc_bake_settings *s = b->s;
    const lc_mesh *m = &b->scene.mesh;
    lc_lcb_writer *w = b->w = lc_lcb_writer_create();
    if (!w) return bake_oom(err, errlen);
    int add_rc = 0;
    add_rc |= lc_lcb_writer_add(w, "META", 1, b->meta_text, strlen(b->meta_text));
    add_rc |= lc_lcb_writer_add(w, "MATL", sizeof(lc_lcb_material), b->mats, b->scene.n_materials);
    add_rc |= lc_lcb_writer_add(w, "VERT", sizeof(lc_lcb_vertex), b->verts, m->n_vertices);
    add_rc |= lc_lcb_writer_add(w, "TRIS", sizeof(lc_lcb_triangle), b->tris, m->n_triangles);
    add_rc |= lc_lcb_writer_add(w, "SURF", sizeof(lc_lcb_surfel), b->surfels, b->n_surfels);
    add_rc |= lc_lcb_writer_add(w, "NODE", sizeof(lc_lcb_node), b->hier.nodes, b->hier.n_nodes);
    add_rc |= lc_lcb_writer_add(w, "LEVL", sizeof(uint32_t), b->hier.levels, (uint64_t)b->hier.n_levels + 1);
    add_rc |= lc_lcb_writer_add(w, "CACH", sizeof(lc_lcb_cache), b->caches, b->n_caches);
    add_rc |= lc_lcb_writer_add(w, "LMAP", sizeof(uint32_t), b->lm.texel_cache, (uint64_t)b->lm.width * b->lm.height);
    add_rc |= lc_lcb_writer_add(w, "GRID", sizeof(uint32_t), b->cell_cache,
                                (uint64_t)b->grid.dims[0] * b->grid.dims[1] * b->grid.dims[2]);
    const uint64_t n_glnk = (uint64_t)(b->n_caches - b->n_texel_caches) * b->grid_links_per_cache;
    add_rc |= lc_lcb_writer_add(w, "LINK", sizeof(lc_lcb_link), b->links, b->n_links - n_glnk);
    if (n_glnk) add_rc |= lc_lcb_writer_add(w, "GLNK", sizeof(lc_lcb_link), b->links + b->n_links - n_glnk, n_glnk);
    if (b->link_sh)
        add_rc |= lc_lcb_writer_add(w, "LKSH", sizeof(uint16_t), b->link_sh, b->n_links * s->bands * s->bands);
    if (b->texel_surfels_first) {
        add_rc |=
            lc_lcb_writer_add(w, "TSGF", sizeof(uint32_t), b->texel_surfels_first, (uint64_t)b->n_texel_caches + 1);
        add_rc |= lc_lcb_writer_add(w, "TSGW", sizeof(lc_lcb_surfel_weight), b->texel_surfels, b->n_texel_surfels);
    }
    const lc_probebake *pb = &b->probes;
    if (pb->probes) {
        add_rc |= lc_lcb_writer_add(w, "PRBH", sizeof(lc_lcb_probe_header), &pb->header, 1);
        add_rc |= lc_lcb_writer_add(w, "PRBP", sizeof(lc_lcb_probe), pb->probes, pb->header.n_probes);
        add_rc |=
            lc_lcb_writer_add(w, "PRBR", sizeof(uint32_t), pb->hits, (uint64_t)pb->header.n_probes * pb->header.n_rays);
        add_rc |= lc_lcb_writer_add(w, "PRCL", sizeof(lc_lcb_probe_cluster), pb->clusters, pb->header.n_clusters);
        add_rc |= lc_lcb_writer_add(w, "PRCP", sizeof(uint32_t), pb->cluster_probes, pb->n_cluster_probes);
        add_rc |= lc_lcb_writer_add(w, "PRCB", sizeof(float), pb->basis, pb->n_basis);
        add_rc |= lc_lcb_writer_add(w, "PRRW", sizeof(lc_lcb_probe_row), pb->rows, pb->header.n_rows);
        add_rc |= lc_lcb_writer_add(w, "PRRU", sizeof(float), pb->u, pb->n_u);
        if (pb->unseen_first) {
            add_rc |= lc_lcb_writer_add(w, "PRUF", sizeof(uint32_t), pb->unseen_first, (uint64_t)pb->header.n_rows + 1);
            add_rc |= lc_lcb_writer_add(w, "PRUS", sizeof(lc_lcb_probe_unseen), pb->unseen, pb->n_unseen);
        }
    }
    if (b->assets.n_assets) {
        add_rc |= lc_lcb_writer_add(w, "ASET", sizeof(lc_lcb_asset), b->assets.assets, b->assets.n_assets);
        add_rc |= lc_lcb_writer_add(w, "AVRT", sizeof(lc_lcb_asset_vertex), b->assets.vertices, b->assets.n_vertices);
        add_rc |= lc_lcb_writer_add(w, "AIDX", 3 * sizeof(uint32_t), b->assets.indices, b->assets.n_triangles);
        if (b->assets.n_transfers) {
            add_rc |= lc_lcb_writer_add(w, "ATRN", sizeof(lc_lcb_transfer), b->assets.transfers, b->assets.n_transfers);
            add_rc |= lc_lcb_writer_add(w, "ATRD", 1, b->assets.transfer_data, b->assets.transfer_bytes);
        }
        if (b->assets.sparse_vertices) { /* ASPT and AVNN together (an empty ASPT: no asset had triangles) */
            add_rc |= lc_lcb_writer_add(w, "ASPT", sizeof(lc_lcb_sparse_point), b->assets.sparse, b->assets.n_sparse);
            add_rc |= lc_lcb_writer_add(w, "AVNN", sizeof(lc_lcb_sparse_vertex), b->assets.sparse_vertices,
                                        b->assets.n_vertices);
        }
    }
    if (add_rc) {
        lc_set_err(err, errlen, "internal error assembling the bake file sections");
        return 1;
    }
    return 0;
}

/* The viewers' .glb, generated from the .lcb just written (not from the scene in memory), so
 * it is byte for byte what lucentd serves as /scene.glb for this bake. */
static int bake_write_glb(const char *lcb_path, const char *glb_path, char *err, size_t errlen) {
    lc_lcb *f = NULL;
    unsigned char *glb = NULL;
    size_t len = 0;
    char e[512];
    int rc = -1;
    if (lc_lcb_open(lcb_path, &f, e, sizeof e) != 0) {
        lc_set_err(err, errlen, "--glb %s: cannot reopen %s: %s", glb_path, lcb_path, e);
        goto out;
    }
    if (lc_lcb_scene_glb(f, &glb, &len, e, sizeof e) != 0) {
        lc_set_err(err, errlen, "--glb %s: %s", glb_path, e);
        goto out;
    }
    rc = lc_fs_write_atomic(glb_path, glb, len, err, errlen);
out:
    free(glb);
    lc_lcb_close(f);
    return rc;
}

/* The .lcb (atomic) and, unless turned off, the .glb. */
static int bake_write(bake_job *b, char *err, size_t errlen) {
    int rc;
    if ((rc = bake_geometry_sections(b, err, errlen)) != 0 || (rc = bake_meta(b, err, errlen)) != 0 ||
        (rc = bake_add_sections(b, err, errlen)) != 0)
        return rc;
    if (lc_lcb_writer_write(b->w, b->s->output, err, errlen) != 0) return 3;
    if (b->s->glb[0] && bake_write_glb(b->s->output, b->s->glb, err, errlen) != 0) return 3;
    return 0;
}

/* The pipeline, in order; each stage's time goes into the report under its name. */
static const struct {
    const char *name;
    int (*run)(bake_job *b, char *err, size_t errlen);
} bake_stages[] = {
    {"import", bake_import_scene}, {"lightmap-uv", bake_lightmap_uv}, {"bvh", bake_bvh},
    {"texels", bake_texel_caches}, {"grid", bake_grid_caches},        {"relocate", bake_relocate},
    {"surfels", bake_surfels},     {"hierarchy", bake_hierarchy},     {"links", bake_links},
    {"probes", bake_probes},       {"assets", bake_dynamic_assets},   {"write", bake_write},
};
_Static_assert(sizeof bake_stages / sizeof bake_stages[0] == BAKE_N_STAGES, "BAKE_N_STAGES counts the stages");

/* What a finished bake reports besides its stage times. */
static void bake_report_totals(const bake_job *b, lc_bake_report *r, double t_start) {
    const lc_bake_settings *s = b->s;
    struct stat st;
    r->file_bytes = stat(s->output, &st) == 0 ? (unsigned long long)st.st_size : 0;
    r->total_seconds = (lc_clock_ms() * 1e-3) - t_start;
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    r->peak_rss_kib = ru.ru_maxrss;
    r->triangles = b->scene.mesh.n_triangles;
    r->surfels = b->n_surfels;
    r->caches = b->n_caches;
    r->texel_caches = b->n_texel_caches;
    r->grid_caches = b->n_caches - b->n_texel_caches;
    r->links_per_cache = (unsigned)s->links;
    r->charts = b->uvs.n_charts;
    r->lightmap_width = b->lm.width;
    r->lightmap_height = b->lm.height;
    r->atlas_usage = b->uvs.usage;
    r->texel_density = b->uvs.texels_per_metre;
}

int lc_bake_run(const lc_bake_settings *s, lc_bake_report *report, char *err, size_t errlen) {
    bake_job b;
    memset(&b, 0, sizeof b);
    b.s = s;
    lc_bake_report local_report;
    lc_bake_report *r = report ? report : &local_report;
    memset(r, 0, sizeof *r);

    lc_progress_set_enabled(!s->quiet);
    double t_start = (lc_clock_ms() * 1e-3), t0 = t_start;
    int rc = 0;
    for (size_t i = 0; i < BAKE_N_STAGES && rc == 0; i++) {
        rc = bake_stages[i].run(&b, err, errlen);
        if (rc == 0) bake_stage(r, bake_stages[i].name, &t0, s->quiet);
    }
    if (rc == 0) bake_report_totals(&b, r, t_start);
    bake_job_release(&b);
    return rc;
}

/* --- report --------------------------------------------------------------------------------- */

void lc_bake_report_print(const lc_bake_report *r, FILE *out) {
    fprintf(out, "%-14s %10s %12s\n", "stage", "seconds", "peak MiB");
    for (int i = 0; i < r->n_stages; i++)
        fprintf(out, "%-14s %10.3f %12.1f\n", r->stages[i].name, r->stages[i].seconds, r->stages[i].peak_mib);
    fprintf(out, "%-14s %10.3f\n", "total", r->total_seconds);
    fprintf(out, "peak memory    %10.1f MiB\n", r->peak_rss_kib / 1024.0);
    fprintf(out, "file size      %10.1f MiB\n", r->file_bytes / (1024.0 * 1024.0));
    fprintf(out, "triangles %u, surfels %u, caches %u (%u texel, %u grid), links/cache %u\n", r->triangles, r->surfels,
            r->caches, r->texel_caches, r->grid_caches, r->links_per_cache);
    fprintf(out, "lightmap %ux%u, %u charts, %.1f texels/m, atlas usage %.1f%%\n", r->lightmap_width,
            r->lightmap_height, r->charts, r->texel_density, r->atlas_usage * 100);
}

int lc_bake_report_write_json(const lc_bake_report *r, const lc_bake_settings *s, const char *path, char *err,
                              size_t errlen) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "input", s->input);
    cJSON_AddStringToObject(o, "output", s->output);
    static const char *qualities[] = {"draft", "moderate", "high", "ultra"};
    cJSON_AddStringToObject(o, "quality", qualities[s->quality]);
    cJSON *st = cJSON_AddObjectToObject(o, "stages_s");
    for (int i = 0; i < r->n_stages; i++) cJSON_AddNumberToObject(st, r->stages[i].name, r->stages[i].seconds);
    cJSON *sm = cJSON_AddObjectToObject(o, "stages_peak_mib"); /* the high-water mark as each stage ended */
    for (int i = 0; i < r->n_stages; i++) cJSON_AddNumberToObject(sm, r->stages[i].name, r->stages[i].peak_mib);
    cJSON_AddNumberToObject(o, "total_s", r->total_seconds);
    cJSON_AddNumberToObject(o, "peak_rss_mib", r->peak_rss_kib / 1024.0);
    cJSON_AddNumberToObject(o, "file_bytes", (double)r->file_bytes);
    cJSON_AddNumberToObject(o, "triangles", r->triangles);
    cJSON_AddNumberToObject(o, "surfels", r->surfels);
    cJSON_AddNumberToObject(o, "caches", r->caches);
    cJSON_AddNumberToObject(o, "texel_caches", r->texel_caches);
    cJSON_AddNumberToObject(o, "grid_caches", r->grid_caches);
    cJSON_AddNumberToObject(o, "links_per_cache", r->links_per_cache);
    cJSON_AddNumberToObject(o, "charts", r->charts);
    cJSON_AddNumberToObject(o, "lightmap_width", r->lightmap_width);
    cJSON_AddNumberToObject(o, "lightmap_height", r->lightmap_height);
    cJSON_AddNumberToObject(o, "atlas_usage", r->atlas_usage);
    cJSON_AddNumberToObject(o, "texels_per_metre", r->texel_density);
    char *text = cJSON_Print(o);
    cJSON_Delete(o);
    if (!text) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    int rc = lc_fs_write_atomic(path, text, strlen(text), err, errlen);
    cJSON_free(text);
    return rc;
}
