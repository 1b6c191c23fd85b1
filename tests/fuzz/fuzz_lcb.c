/* Fuzz target for the .lcb reader. Each input is opened twice: as is, and with every CRC
 * (and file_size) recomputed, because random mutations almost never survive the CRCs and
 * the semantic validation behind them would otherwise go unexplored. On success every
 * array of the view is walked, following each index the reader promises is valid, info is
 * printed in both modes, and the glTF of the scene and of every asset is generated (what
 * lucentd serves from a bake it opened). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lcb/lcb.h"
#include "lcb/lcb_glb.h"
#include "util/crc32.h"

static volatile uint64_t sink;

static uint64_t fuzz_bytes(const void *p, size_t n) {
    const uint8_t *b = p;
    uint64_t s = 0;
    for (size_t i = 0; i < n; i++) s = s * 31 + b[i];
    return s;
}

/* The probes solver's arrays, every index followed as the runtime (engine/probes.c) does. */
static uint64_t fuzz_probes(const lc_lcb_view *v) {
    const lc_lcb_probe_header *h = v->probe_header;
    if (!h) return 0;
    uint64_t s = 0;
    const uint32_t nc = h->sh_bands * h->sh_bands;
    for (uint64_t i = 0; i < (uint64_t)h->n_probes * h->n_rays; i++)
        if (v->probe_hits[i] != LC_NONE) s += v->surfels[v->probe_hits[i]].material;
    for (uint32_t c = 0; c < h->n_clusters; c++) {
        const lc_lcb_probe_cluster *cl = &v->probe_clusters[c];
        for (uint32_t q = 0; q < cl->n_probes; q++) {
            const lc_lcb_probe *p = &v->probes[v->probe_cluster_probes[cl->first_probe + q]];
            s += fuzz_bytes(p, sizeof *p);
        }
        s += fuzz_bytes(v->probe_basis + cl->basis_offset, (size_t)cl->rank * cl->n_probes * nc * sizeof(float));
        s += fuzz_bytes(v->probe_u + cl->u_offset, (size_t)cl->n_rows * cl->rank * sizeof(float));
        for (uint32_t r = 0; r < cl->n_rows; r++) {
            const lc_lcb_probe_row *row = &v->probe_rows[cl->first_row + r];
            s += v->caches[row->cache].flags + row->coeff;
        }
    }
    return s;
}

static void fuzz_touch(const lc_lcb *f) {
    const lc_lcb_view *v = lc_lcb_get(f);
    uint64_t s = fuzz_bytes(v->meta_json, v->meta_len + 1);
    s += fuzz_bytes(v->materials, (size_t)v->n_materials * sizeof *v->materials);
    for (uint32_t i = 0; i < v->n_triangles; i++)
        for (int k = 0; k < 3; k++)
            s += fuzz_bytes(&v->vertices[v->triangles[i].v[k]], sizeof *v->vertices) +
                (uint64_t)v->materials[v->triangles[i].material].flags;
    for (uint32_t i = 0; i < v->n_surfels; i++) {
        const lc_lcb_surfel *su = &v->surfels[i];
        s += v->materials[su->material].flags + fuzz_bytes(su, sizeof *su);
        if (su->cache != LC_NONE) s += v->caches[su->cache].flags;
    }
    for (uint32_t i = 0; i < v->n_nodes; i++) {
        const lc_lcb_node *n = &v->nodes[i];
        if (n->child[0] != LC_NONE) s += v->nodes[n->child[0]].surfel_count + v->nodes[n->child[1]].surfel_count;
        for (uint32_t k = 0; k < n->surfel_count; k++) s += v->surfels[n->first_surfel + k].material;
    }
    for (uint32_t l = 0; l < v->n_levels; l++)
        for (uint32_t i = v->levels[l]; i < v->levels[l + 1]; i++) s += v->nodes[i].first_surfel;
    for (uint32_t i = 0; i < v->n_caches; i++) {
        const lc_lcb_cache *c = &v->caches[i];
        s += i < v->n_texel_caches ? v->lightmap[c->index] : v->grid[c->index];
        for (uint32_t k = 0; k < v->links_per_cache; k++) {
            size_t li = (size_t)i * v->links_per_cache + k;
            s += v->nodes[v->links[li].node].surfel_count;
            for (uint32_t h = 0; v->link_sh && h < v->link_sh_bands * v->link_sh_bands; h++)
                s += v->link_sh[li * v->link_sh_bands * v->link_sh_bands + h];
        }
    }
    for (uint64_t t = 0; t < (uint64_t)v->lightmap_width * v->lightmap_height; t++)
        if (v->lightmap[t] != LC_NONE) s += v->caches[v->lightmap[t]].index;
    for (uint64_t g = 0; g < (uint64_t)v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2]; g++)
        s += v->caches[v->grid[g]].index;
    for (uint32_t a = 0; a < v->n_assets; a++) {
        const lc_lcb_asset *as = &v->assets[a];
        s += strlen(as->name);
        for (uint64_t t = 0; t < (uint64_t)as->triangle_count * 3; t++) {
            uint32_t vi = v->asset_indices[(size_t)as->first_triangle * 3 + t];
            s += fuzz_bytes(&v->asset_vertices[as->first_vertex + vi], sizeof *v->asset_vertices);
        }
    }
    for (uint32_t i = 0; i < v->n_materials; i++) s += strlen(v->materials[i].name);
    s += fuzz_probes(v);
    for (uint32_t i = 0; i < lc_lcb_section_count(f); i++) s += lc_lcb_section_at(f, i)->crc;
    sink += s;

    static FILE *null;
    if (!null) null = fopen("/dev/null", "w");
    if (null) {
        lc_lcb_print_info(f, "fuzz", 0, null);
        lc_lcb_print_info(f, "fuzz", 1, null);
    }
    unsigned char *glb = NULL;
    size_t len = 0;
    char err[256];
    if (lc_lcb_scene_glb(f, &glb, &len, err, sizeof err) == 0) sink += fuzz_bytes(glb, len < 64 ? len : 64);
    free(glb);
    for (uint32_t a = 0; a < v->n_assets; a++) {
        glb = NULL;
        if (lc_lcb_asset_glb(f, a, &glb, &len, err, sizeof err) == 0) sink += len;
        free(glb);
    }
}

static void fuzz_open(const uint8_t *data, size_t size) {
    lc_lcb *f = NULL;
    char err[512];
    if (lc_lcb_open_memory(data, size, &f, err, sizeof err) == 0) {
        fuzz_touch(f);
        lc_lcb_close(f);
    } else if (!err[0]) {
        abort(); /* every failure must explain itself */
    }
}

/* Makes CRCs and file_size agree with the bytes, leaving every other field as mutated. */
static void fuzz_fix(uint8_t *buf, size_t len) {
    lc_lcb_header h;
    memcpy(&h, buf, sizeof h);
    if (h.section_count > LC_LCB_MAX_SECTIONS || 64 + (size_t)h.section_count * 48 > len) return;
    for (uint32_t i = 0; i < h.section_count; i++) {
        lc_lcb_section s;
        memcpy(&s, buf + 64 + (size_t)i * 48, sizeof s);
        if (s.offset <= len && s.size <= len - s.offset) {
            s.crc = lc_crc32(0, buf + s.offset, (size_t)s.size);
            memcpy(buf + 64 + (size_t)i * 48, &s, sizeof s);
        }
    }
    h.file_size = len;
    h.table_crc = lc_crc32(0, buf + 64, (size_t)h.section_count * 48);
    memcpy(buf, &h, sizeof h);
    h.header_crc = lc_crc32(0, buf, 60);
    memcpy(buf, &h, sizeof h);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    fuzz_open(data, size);
    if (size < sizeof(lc_lcb_header)) return 0;
    uint8_t *copy = malloc(size);
    if (!copy) return 0;
    memcpy(copy, data, size);
    fuzz_fix(copy, size);
    fuzz_open(copy, size);
    /* And once misaligned, to exercise the copy path of lc_lcb_open_memory. */
    uint8_t *odd = malloc(size + 1);
    if (odd) {
        memcpy(odd + 1, copy, size);
        fuzz_open(odd + 1, size);
        free(odd);
    }
    free(copy);
    return 0;
}
