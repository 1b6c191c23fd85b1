/* ref_io: the reference directory (reference.json + float32 EXR + raw little-endian arrays)
 * and the state loader. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "bake/image.h"
#include "ref/ref.h"
#include "state.h"
#include "util/fsutil.h"
#include "util/log.h"

#define REF_FORMAT "lucent-ref/1"

/* --- state ------------------------------------------------------------------------------------- */

void lc_ref_state_free(lc_ref_state *s) {
    if (!s) return;
    free(s->lights);
    free(s->objects);
    free(s->emission);
    memset(s, 0, sizeof *s);
}

int lc_ref_state_load(const lc_lcb *bake, const char *path, int bake_lights, lc_ref_state *out, char *err,
                      size_t errlen) {
    memset(out, 0, sizeof *out);
    lc_state state;
    lc_state_limits limits = {LC_ENGINE_MAX_LIGHTS, LC_ENGINE_MAX_OBJECTS};
    lc_proto_parsed_state parsed;
    memset(&parsed, 0, sizeof parsed);
    char *text = NULL;
    if (lc_state_init(&state, bake, &limits) != 0) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    if (bake_lights && !path && lc_state_seed(&state, err, errlen) != 0) goto err;
    if (path) {
        size_t len = 0;
        text = lc_fs_read(path, 64u << 20, &len, err, errlen);
        if (!text) goto err;
        lc_proto_error pe;
        if (lc_proto_parse_state(text, len, &parsed, &pe) != 0) {
            lc_set_err(err, errlen, "%s: %s at '%s': %s", path, pe.code, pe.pointer, pe.message);
            goto err;
        }
        if (lc_state_restore(&state, &parsed, &pe) != 0) {
            lc_set_err(err, errlen, "%s: %s at '%s': %s", path, pe.code, pe.pointer, pe.message);
            goto err;
        }
    }
    if (lc_state_to_engine(&state, &out->st, &out->lights, &out->objects, &out->emission) != 0) {
        lc_set_err(err, errlen, "out of memory");
        goto err;
    }
    lc_proto_parsed_state_free(&parsed);
    lc_state_release(&state);
    free(text);
    return 0;
err:
    lc_proto_parsed_state_free(&parsed);
    lc_state_release(&state);
    free(text);
    lc_ref_state_free(out);
    return -1;
}

/* --- writing ----------------------------------------------------------------------------------- */

static int ref_mkdir(const char *dir, char *err, size_t errlen) {
    if (mkdir(dir, 0755) == 0 || errno == EEXIST) return 0;
    lc_set_err(err, errlen, "%s: cannot create directory: %s", dir, strerror(errno));
    return -1;
}

static int ref_write_raw(const char *dir, const char *name, const void *data, size_t len, char *err, size_t errlen) {
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    return lc_fs_write_atomic(path, data, len, err, errlen);
}

static cJSON *ref_stats_json(const lc_ref_stats *s) {
    cJSON *o = cJSON_CreateObject();
    cJSON_AddNumberToObject(o, "caches", s->n);
    cJSON_AddNumberToObject(o, "samples", (double)s->samples);
    cJSON_AddNumberToObject(o, "spp_mean", s->spp_mean);
    cJSON_AddNumberToObject(o, "spp_min", s->spp_min);
    cJSON_AddNumberToObject(o, "spp_max", s->spp_max);
    cJSON_AddNumberToObject(o, "bright_caches", s->n_bright);
    cJSON_AddNumberToObject(o, "mean_rel_stderr", s->mean_rel_stderr);
    cJSON_AddNumberToObject(o, "p95_rel_stderr", s->p95_rel_stderr);
    cJSON_AddNumberToObject(o, "max_rel_stderr", s->max_rel_stderr);
    return o;
}

static void ref_stats_parse(const cJSON *o, lc_ref_stats *s) {
    memset(s, 0, sizeof *s);
    if (!cJSON_IsObject(o)) return;
    const cJSON *it;
#define REF_NUM(key, field, type) \
    if (cJSON_IsNumber(it = cJSON_GetObjectItemCaseSensitive(o, key))) s->field = (type)it->valuedouble
    REF_NUM("caches", n, uint32_t);
    REF_NUM("samples", samples, uint64_t);
    REF_NUM("spp_mean", spp_mean, double);
    REF_NUM("spp_min", spp_min, uint32_t);
    REF_NUM("spp_max", spp_max, uint32_t);
    REF_NUM("bright_caches", n_bright, uint32_t);
    REF_NUM("mean_rel_stderr", mean_rel_stderr, double);
    REF_NUM("p95_rel_stderr", p95_rel_stderr, double);
    REF_NUM("max_rel_stderr", max_rel_stderr, double);
#undef REF_NUM
}

int lc_ref_write(const char *dir, const lc_ref_result *res, const char *extra_json, char *err, size_t errlen) {
    char path[4096];
    char *text = NULL;
    cJSON *root = NULL;
    if (ref_mkdir(dir, err, errlen) != 0) goto err;
    size_t texels = (size_t)res->width * res->height;
    if (texels) {
        snprintf(path, sizeof path, "%s/reference_lightmap.exr", dir);
        if (lc_image_write_float(path, res->width, res->height, 3, res->lightmap, err, errlen) != 0) goto err;
        snprintf(path, sizeof path, "%s/reference_lightmap_stderr.exr", dir);
        if (lc_image_write_float(path, res->width, res->height, 3, res->lightmap_stderr, err, errlen) != 0) goto err;
        if (ref_write_raw(dir, "reference_texels.bin", res->texel_mask, texels, err, errlen) != 0) goto err;
        if (res->texel_surface &&
            (ref_write_raw(dir, "reference_surface.bin", res->texel_surface,
                           texels * LC_REF_SURFACE_STRIDE * sizeof(float), err, errlen) != 0 ||
             ref_write_raw(dir, "reference_moved.bin", res->texel_moved, texels, err, errlen) != 0))
            goto err;
    }
    if (res->n_cells) {
        if (ref_write_raw(dir, "reference_grid.bin", res->grid_sh, (size_t)res->n_cells * 27 * sizeof(float), err,
                          errlen) != 0 ||
            ref_write_raw(dir, "reference_grid_stderr.bin", res->grid_sh_stderr,
                          (size_t)res->n_cells * 27 * sizeof(float), err, errlen) != 0 ||
            ref_write_raw(dir, "reference_grid_mask.bin", res->grid_mask, res->n_cells, err, errlen) != 0)
            goto err;
    }
    root = cJSON_CreateObject();
    cJSON_AddStringToObject(root, "format", REF_FORMAT);
    cJSON_AddStringToObject(root, "quantity",
                            "indirect irradiance as the lucent engine defines it: light arriving from surfaces "
                            "(emission + everything they reflect, any number of bounces), one-sided surfaces, "
                            "no direct light from lights or the directly seen sky (see tools/ref/ref.h)");
    cJSON *lm = cJSON_AddObjectToObject(root, "lightmap");
    cJSON_AddNumberToObject(lm, "width", res->width);
    cJSON_AddNumberToObject(lm, "height", res->height);
    cJSON_AddStringToObject(lm, "file", "reference_lightmap.exr");
    cJSON_AddStringToObject(lm, "stderr_file", "reference_lightmap_stderr.exr");
    cJSON_AddStringToObject(lm, "mask_file", "reference_texels.bin");
    cJSON_AddStringToObject(lm, "layout",
                            "float32 RGB irradiance W/m^2, row 0 = top; mask u8 per texel: 0 empty, "
                            "1 owns its cache, 2 dilated copy of a neighbour's cache");
    cJSON_AddStringToObject(lm, "texel_at", lc_ref_texel_at_name(res->texel_at));
    if (res->texel_surface) {
        cJSON_AddStringToObject(lm, "surface_file", "reference_surface.bin");
        cJSON_AddStringToObject(lm, "moved_file", "reference_moved.bin");
        cJSON_AddStringToObject(lm, "surface_layout",
                                "float32 little-endian per texel: surface point xyz (m), unit normal xyz, texel "
                                "spacing (m), found by lucent-ref from the mesh's uv1; NAN for texels owning no "
                                "cache. moved: u8 per texel, 1 = the bake moved the texel's cache (LC_CACHE_MOVED)");
        cJSON *ss = cJSON_AddObjectToObject(lm, "surface");
        cJSON_AddNumberToObject(ss, "texels", res->surface_stats.texels);
        cJSON_AddNumberToObject(ss, "outside_triangles", res->surface_stats.outside);
        cJSON_AddNumberToObject(ss, "missing", res->surface_stats.missing);
        cJSON_AddNumberToObject(ss, "unmoved_cache_offset_max_m", res->unmoved_offset_max);
    }
    cJSON_AddItemToObject(lm, "stats", ref_stats_json(&res->texel_stats));
    cJSON *gr = cJSON_AddObjectToObject(root, "grid");
    cJSON *dims = cJSON_AddArrayToObject(gr, "dims");
    cJSON *orig = cJSON_AddArrayToObject(gr, "origin");
    for (int k = 0; k < 3; k++) {
        cJSON_AddItemToArray(dims, cJSON_CreateNumber(res->grid_dims[k]));
        cJSON_AddItemToArray(orig, cJSON_CreateNumber(res->grid_origin[k]));
    }
    cJSON_AddNumberToObject(gr, "cell", res->grid_cell);
    cJSON_AddNumberToObject(gr, "cells", res->n_cells);
    cJSON_AddStringToObject(gr, "file", "reference_grid.bin");
    cJSON_AddStringToObject(gr, "stderr_file", "reference_grid_stderr.bin");
    cJSON_AddStringToObject(gr, "mask_file", "reference_grid_mask.bin");
    cJSON_AddStringToObject(gr, "layout",
                            "float32 little-endian, cells (x fastest) x 9 SH coefficients x RGB: "
                            "cosine-convolved irradiance SH, E(n) = sum c_i y_i(n) (lc_engine_frame."
                            "grid_sh); mask u8 per cell: 1 valid, 0 inside geometry");
    cJSON_AddItemToObject(gr, "stats", ref_stats_json(&res->grid_stats));
    cJSON_AddNumberToObject(root, "seconds", res->seconds);
    cJSON_AddNumberToObject(root, "rays", (double)res->rays);
    cJSON_AddNumberToObject(root, "max_bounces", res->max_bounces);
    char crc[16];
    snprintf(crc, sizeof crc, "%08x", res->cache_crc);
    cJSON_AddStringToObject(root, "cache_crc", crc);
    if (extra_json) {
        cJSON *extra = cJSON_Parse(extra_json);
        if (extra) cJSON_AddItemToObject(root, "run", extra);
    }
    text = cJSON_Print(root);
    if (!text) {
        lc_set_err(err, errlen, "out of memory");
        goto err;
    }
    if (ref_write_raw(dir, "reference.json", text, strlen(text), err, errlen) != 0) goto err;
    cJSON_free(text);
    cJSON_Delete(root);
    return 0;
err:
    if (text) cJSON_free(text);
    cJSON_Delete(root);
    return -1;
}

/* --- reading ----------------------------------------------------------------------------------- */

static void *ref_read_raw(const char *dir, const char *name, size_t expect, char *err, size_t errlen) {
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    size_t len = 0;
    char *data = lc_fs_read(path, expect + 1, &len, err, errlen);
    if (!data) return NULL;
    if (len != expect) {
        lc_set_err(err, errlen, "%s: %zu bytes, expected %zu", path, len, expect);
        free(data);
        return NULL;
    }
    return data;
}

int lc_ref_read(const char *dir, lc_ref_result *res, char *err, size_t errlen) {
    memset(res, 0, sizeof *res);
    char path[4096];
    snprintf(path, sizeof path, "%s/reference.json", dir);
    size_t len = 0;
    cJSON *root = NULL;
    float *img = NULL;
    char *text = lc_fs_read(path, 16u << 20, &len, err, errlen);
    if (!text) goto err;
    root = cJSON_ParseWithLength(text, len);
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(root, "format");
    if (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, REF_FORMAT) != 0) {
        lc_set_err(err, errlen, "%s: not a %s reference", path, REF_FORMAT);
        goto err;
    }
    const cJSON *lm = cJSON_GetObjectItemCaseSensitive(root, "lightmap");
    const cJSON *gr = cJSON_GetObjectItemCaseSensitive(root, "grid");
    const cJSON *w = cJSON_GetObjectItemCaseSensitive(lm, "width"), *h = cJSON_GetObjectItemCaseSensitive(lm, "height");
    const cJSON *cells = cJSON_GetObjectItemCaseSensitive(gr, "cells");
    const cJSON *dims = cJSON_GetObjectItemCaseSensitive(gr, "dims");
    const cJSON *orig = cJSON_GetObjectItemCaseSensitive(gr, "origin");
    const cJSON *cell = cJSON_GetObjectItemCaseSensitive(gr, "cell");
    if (!cJSON_IsNumber(w) || !cJSON_IsNumber(h) || !cJSON_IsNumber(cells) || cJSON_GetArraySize(dims) != 3 ||
        cJSON_GetArraySize(orig) != 3 || !cJSON_IsNumber(cell) || w->valuedouble < 0 || h->valuedouble < 0 ||
        w->valuedouble > 65536 || h->valuedouble > 65536 || cells->valuedouble < 0 || cells->valuedouble > 1e8) {
        lc_set_err(err, errlen, "%s: lightmap/grid description missing or out of range", path);
        goto err;
    }
    res->width = (uint32_t)w->valuedouble;
    res->height = (uint32_t)h->valuedouble;
    res->n_cells = (uint32_t)cells->valuedouble;
    for (int k = 0; k < 3; k++) {
        res->grid_dims[k] = (uint32_t)cJSON_GetArrayItem(dims, k)->valuedouble;
        res->grid_origin[k] = (float)cJSON_GetArrayItem(orig, k)->valuedouble;
    }
    res->grid_cell = (float)cell->valuedouble;
    ref_stats_parse(cJSON_GetObjectItemCaseSensitive(lm, "stats"), &res->texel_stats);
    /* Written before texel_at existed: the texels were evaluated at their caches. */
    const cJSON *at = cJSON_GetObjectItemCaseSensitive(lm, "texel_at");
    res->texel_at = !cJSON_IsString(at)       ? LC_REF_TEXEL_AT_CACHE
        : !strcmp(at->valuestring, "surface") ? LC_REF_TEXEL_AT_SURFACE
        : !strcmp(at->valuestring, "cache")   ? LC_REF_TEXEL_AT_CACHE
                                              : LC_REF_TEXEL_AT_UNKNOWN;
    const cJSON *ss = cJSON_GetObjectItemCaseSensitive(lm, "surface"), *it;
    res->unmoved_offset_max = -1;
    if (cJSON_IsNumber(it = cJSON_GetObjectItemCaseSensitive(ss, "texels")))
        res->surface_stats.texels = (uint32_t)it->valuedouble;
    if (cJSON_IsNumber(it = cJSON_GetObjectItemCaseSensitive(ss, "outside_triangles")))
        res->surface_stats.outside = (uint32_t)it->valuedouble;
    if (cJSON_IsNumber(it = cJSON_GetObjectItemCaseSensitive(ss, "missing")))
        res->surface_stats.missing = (uint32_t)it->valuedouble;
    if (cJSON_IsNumber(it = cJSON_GetObjectItemCaseSensitive(ss, "unmoved_cache_offset_max_m")))
        res->unmoved_offset_max = it->valuedouble;
    int have_surface = cJSON_IsString(cJSON_GetObjectItemCaseSensitive(lm, "surface_file"));
    ref_stats_parse(cJSON_GetObjectItemCaseSensitive(gr, "stats"), &res->grid_stats);
    const cJSON *crc = cJSON_GetObjectItemCaseSensitive(root, "cache_crc");
    if (cJSON_IsString(crc)) res->cache_crc = (uint32_t)strtoul(crc->valuestring, NULL, 16);
    const cJSON *mb = cJSON_GetObjectItemCaseSensitive(root, "max_bounces");
    if (cJSON_IsNumber(mb) && mb->valuedouble >= 0 && mb->valuedouble < 1e9)
        res->max_bounces = (uint32_t)mb->valuedouble;
    const cJSON *secs = cJSON_GetObjectItemCaseSensitive(root, "seconds");
    if (cJSON_IsNumber(secs)) res->seconds = secs->valuedouble;
    size_t texels = (size_t)res->width * res->height;
    if (texels) {
        const char *files[2] = {"reference_lightmap.exr", "reference_lightmap_stderr.exr"};
        float **dst[2] = {&res->lightmap, &res->lightmap_stderr};
        for (int f = 0; f < 2; f++) {
            uint32_t iw, ih;
            snprintf(path, sizeof path, "%s/%s", dir, files[f]);
            if (lc_image_read_rgb(path, texels, &iw, &ih, &img, err, errlen) != 0) goto err;
            if (iw != res->width || ih != res->height) {
                lc_set_err(err, errlen, "%s: %ux%u, reference.json says %ux%u", path, iw, ih, res->width, res->height);
                goto err;
            }
            *dst[f] = img;
            img = NULL;
        }
        if (!(res->texel_mask = ref_read_raw(dir, "reference_texels.bin", texels, err, errlen))) goto err;
        if (have_surface &&
            (!(res->texel_surface = ref_read_raw(dir, "reference_surface.bin",
                                                 texels * LC_REF_SURFACE_STRIDE * sizeof(float), err, errlen)) ||
             !(res->texel_moved = ref_read_raw(dir, "reference_moved.bin", texels, err, errlen))))
            goto err;
    }
    if (res->n_cells) {
        size_t bytes = (size_t)res->n_cells * 27 * sizeof(float);
        if (!(res->grid_sh = ref_read_raw(dir, "reference_grid.bin", bytes, err, errlen)) ||
            !(res->grid_sh_stderr = ref_read_raw(dir, "reference_grid_stderr.bin", bytes, err, errlen)) ||
            !(res->grid_mask = ref_read_raw(dir, "reference_grid_mask.bin", res->n_cells, err, errlen)))
            goto err;
    }
    cJSON_Delete(root);
    free(text);
    return 0;
err:
    free(img);
    cJSON_Delete(root);
    free(text);
    lc_ref_result_free(res);
    return -1;
}
