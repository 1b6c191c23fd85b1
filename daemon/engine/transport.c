/* transport: what both backends of the transport interface share (transport.h): the cone
 * table, the host output arrays and how a run publishes them in the frame. Runs on the
 * engine's (compute) thread, like the backends. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "engine/transport.h"
#include "util/log.h"
#include "util/sh.h"

void lc_transport_cone_table(float table[256][8]) {
    for (int q = 0; q < 256; q++) {
        double alpha = q / 255.0 * M_PI;
        for (int l = 0; l < 8; l++) table[q][l] = (float)lc_sh_cone_ratio(l, cos(alpha));
    }
}

int lc_transport_check_settings(const lc_engine_settings *st, char *err, size_t errlen) {
    if (st->bands < 1 || st->bands > LC_SH_MAX_BANDS) {
        lc_set_err(err, errlen, "/settings/bands: %d is outside 1..%d", (int)st->bands, LC_SH_MAX_BANDS);
        return -1;
    }
    return 0;
}

int lc_transport_outputs_alloc(lc_transport_outputs *o, const lc_lcb_view *v) {
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    size_t cells = (size_t)v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2];
    memset(o, 0, sizeof *o);
    /* One spare element each: an empty array still gets a pointer, so NULL means out of memory. */
    o->radiosity = calloc((size_t)v->n_surfels * 3 + 1, sizeof(float));
    o->flux = calloc((size_t)v->n_nodes * 3 + 1, sizeof(float));
    o->cache_sh = calloc((size_t)v->n_caches * LC_SH_MAX_COEFFS * 3 + 1, sizeof(float));
    o->lightmap = calloc(texels * 3 + 1, sizeof(float));
    o->grid_sh = calloc(cells * 27 + 1, sizeof(float));
    if (!o->radiosity || !o->flux || !o->cache_sh || !o->lightmap || !o->grid_sh) {
        lc_transport_outputs_release(o);
        return -1;
    }
    return 0;
}

void lc_transport_outputs_release(lc_transport_outputs *o) {
    free(o->radiosity);
    free(o->flux);
    free(o->cache_sh);
    free(o->lightmap);
    free(o->lightmap_sh);
    free(o->grid_sh);
    free(o->object_sh);
    memset(o, 0, sizeof *o);
}

int lc_transport_reserve_objects(lc_transport_outputs *o, uint32_t n_objects, const char *backend, char *err,
                                 size_t errlen) {
    if (n_objects <= o->object_cap) return 0;
    float *grown = realloc(o->object_sh, (size_t)n_objects * 27 * sizeof(float));
    if (!grown) {
        lc_set_err(err, errlen, "%s transport: out of memory for %u objects", backend, n_objects);
        return -1;
    }
    o->object_sh = grown;
    o->object_cap = n_objects;
    return 0;
}

int lc_transport_fill_lightmap_sh(lc_transport_outputs *o, const lc_lcb_view *v, const char *backend, char *err,
                                  size_t errlen) {
    const size_t texels = (size_t)v->lightmap_width * v->lightmap_height, rec = (size_t)LC_SH_MAX_COEFFS * 3;
    if (!o->lightmap_sh) o->lightmap_sh = calloc(texels * rec + 1, sizeof(float));
    if (!o->lightmap_sh) {
        lc_set_err(err, errlen, "%s transport: out of memory for the SH lightmap", backend);
        return -1;
    }
    for (size_t i = 0; i < texels; i++) {
        uint32_t c = v->lightmap[i];
        float *dst = o->lightmap_sh + i * rec;
        if (c == LC_NONE) memset(dst, 0, rec * sizeof(float));
        else memcpy(dst, o->cache_sh + (size_t)c * rec, rec * sizeof(float));
    }
    return 0;
}

uint32_t lc_transport_needed(const lc_lcb_view *v, const uint8_t *feedback, const lc_transport_input *in, int last,
                             uint8_t *need) {
    if (last && in->settings.grid_cells == LC_GRID_ALL) {
        memset(need, 1, v->n_caches);
        return v->n_caches;
    }
    memcpy(need, feedback, v->n_caches);
    if (last) memset(need, 1, v->n_texel_caches);
    for (uint32_t i = 0; in->dnrt && i < in->dnrt->n_objects; i++)
        for (int k = 0; k < 8; k++) need[in->dnrt->objects[i].corner[k]] = 1;
    for (uint32_t i = 0; last && i < in->n_objects; i++) {
        uint32_t corner[8];
        float w[8];
        lc_dnrt_grid_corners(v, in->object_pos + 3 * (size_t)i, corner, w);
        for (int k = 0; k < 8; k++) need[corner[k]] = 1;
    }
    uint32_t n = 0;
    for (uint32_t c = 0; c < v->n_caches; c++) n += need[c];
    return n;
}

void lc_transport_clear_unneeded_cells(lc_transport_outputs *o, const lc_lcb_view *v, const uint8_t *need) {
    const size_t cells = (size_t)v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2];
    for (size_t i = 0; i < cells; i++)
        if (!need[v->grid[i]]) memset(o->grid_sh + i * 27, 0, 27 * sizeof(float));
}

void lc_transport_publish(const lc_transport_outputs *o, const lc_engine_settings *st, lc_engine_frame *fr) {
    /* Arrays only: the engine front fills the dimensions from the bake and the settings. */
    fr->lightmap = o->lightmap;
    fr->lightmap_sh = st->sh_lightmap ? o->lightmap_sh : NULL;
    fr->cache_sh = o->cache_sh;
    fr->grid_sh = o->grid_sh;
    fr->object_sh = o->object_sh;
    fr->surfel_radiosity = o->radiosity;
    fr->node_flux = lc_transport_chroma(st) ? NULL : o->flux; /* YCoCg when compressing */
}
