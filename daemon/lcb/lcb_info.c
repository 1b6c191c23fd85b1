/* lcb_info: `lucent-bake info` — what is in a validated bake file: version, source,
 * settings, counts and the section table, as text for people or one JSON object. Works
 * only from the view and the section table (the file is already validated), re-parsing
 * META (bounded in size and depth by the reader) for settings and the verbatim copy. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "lcb/lcb.h"

typedef struct lcb_stats {
    uint32_t texel, grid, moved, inside;
    uint64_t owned, dilated, empty; /* lightmap texels */
    uint64_t file_size;
    double surfel_area;
    uint64_t probe_bytes; /* the probe sections together */
    double probe_mean_rank;
} lcb_stats;

/* The probes solver's sections (lcb.h), for their size in `info`. */
static const char lcb_probe_ids[][5] = {"PRBH", "PRBP", "PRBR", "PRCL", "PRCP", "PRCB", "PRRW", "PRRU", "PRUF", "PRUS"};
#define LCB_PROBE_IDS (sizeof lcb_probe_ids / sizeof lcb_probe_ids[0])

static void lcb_gather(const lc_lcb *f, const lc_lcb_view *v, const cJSON *meta, lcb_stats *st) {
    memset(st, 0, sizeof *st);
    for (uint32_t i = 0; i < v->n_caches; i++) {
        uint32_t fl = v->caches[i].flags;
        st->texel += !!(fl & LC_CACHE_TEXEL);
        st->grid += !!(fl & LC_CACHE_GRID);
        st->moved += !!(fl & LC_CACHE_MOVED);
        st->inside += !!(fl & LC_CACHE_INSIDE);
    }
    uint64_t texels = (uint64_t)v->lightmap_width * v->lightmap_height;
    for (uint64_t t = 0; t < texels; t++) {
        uint32_t ci = v->lightmap[t];
        if (ci == LC_NONE) st->empty++;
        else if (v->caches[ci].index == t) st->owned++;
        else st->dilated++;
    }
    /* The file is 64-aligned at the end; the table alone when there are no sections. */
    uint64_t end = sizeof(lc_lcb_header) + (uint64_t)lc_lcb_section_count(f) * sizeof(lc_lcb_section);
    for (uint32_t i = 0; i < lc_lcb_section_count(f); i++) {
        const lc_lcb_section *s = lc_lcb_section_at(f, i);
        if (s->offset + s->size > end) end = s->offset + s->size;
        for (size_t k = 0; v->probe_header && k < LCB_PROBE_IDS; k++)
            if (memcmp(s->id, lcb_probe_ids[k], 4) == 0) st->probe_bytes += s->size;
    }
    if (v->probe_header && v->probe_header->n_clusters) {
        double sum = 0;
        for (uint32_t i = 0; i < v->probe_header->n_clusters; i++) sum += v->probe_clusters[i].rank;
        st->probe_mean_rank = sum / v->probe_header->n_clusters;
    }
    st->file_size = (end + LC_LCB_ALIGN - 1) / LC_LCB_ALIGN * LC_LCB_ALIGN;
    const cJSON *surf = cJSON_GetObjectItemCaseSensitive(meta, "surfels");
    const cJSON *area = cJSON_GetObjectItemCaseSensitive(surf, "area");
    st->surfel_area = cJSON_IsNumber(area) ? area->valuedouble : 0;
}

static void lcb_human_bytes(uint64_t n, char *buf, size_t len) {
    static const char *unit[] = {"B", "KiB", "MiB", "GiB", "TiB"};
    double x = (double)n;
    int u = 0;
    while (x >= 1024 && u < 4) {
        x /= 1024;
        u++;
    }
    if (u == 0) snprintf(buf, len, "%llu B", (unsigned long long)n);
    else snprintf(buf, len, "%.1f %s", x, unit[u]);
}

static void lcb_id(const char id[4], char buf[5]) {
    for (int i = 0; i < 4; i++) buf[i] = (id[i] >= 0x20 && id[i] < 0x7f) ? id[i] : '?';
    buf[4] = 0;
}

/* A JSON value on one line: strings bare, everything else as compact JSON. */
static void lcb_print_value(const cJSON *j, FILE *out) {
    if (cJSON_IsString(j)) {
        fputs(j->valuestring, out);
        return;
    }
    char *s = cJSON_PrintUnformatted(j);
    fputs(s ? s : "?", out);
    free(s);
}

/* LightSkin sparse points (ASPT): the total and each asset's count, or that the bake has none. */
static void lcb_print_sparse(const lc_lcb_view *v, FILE *out) {
    if (!v->sparse_points) {
        if (v->n_assets) fputs("  sparse pts  none (baked without --mr-points)\n", out);
        return;
    }
    fprintf(out, "  sparse pts  %u:", v->n_sparse_points);
    for (uint32_t i = 0; i < v->n_assets; i++) {
        uint32_t first, count;
        lc_lcb_asset_sparse(v, i, &first, &count);
        fprintf(out, "%s %s %u", i ? "," : "", v->assets[i].name, count);
    }
    fputc('\n', out);
}

/* The probes solver (PRB*, PRC*, PRR*), when the bake has it. */
static void lcb_print_probes(const lc_lcb_view *v, const lcb_stats *st, FILE *out) {
    const lc_lcb_probe_header *h = v->probe_header;
    if (!h) return;
    char b[32];
    lcb_human_bytes(st->probe_bytes, b, sizeof b);
    fprintf(out, "  probes      %u probes x %u rays, SH bands %u; %u clusters over %u rows, rank max %u mean %.1f\n",
            h->n_probes, h->n_rays, h->sh_bands, h->n_clusters, h->n_rows, h->max_rank, st->probe_mean_rank);
    fprintf(
        out,
        "              overlaps %u, receiver rays %u, support radius %.4g m, SVD error %.3g; %s in the probe sections\n",
        h->overlaps, h->receiver_rays, h->support_radius, h->svd_error, b);
    if (v->probe_unseen_first)
        fprintf(out, "              unseen rays gathered from surfels: %u entries\n", v->probe_unseen_first[h->n_rows]);
}

static void lcb_print_human(const lc_lcb *f, const lc_lcb_view *v, const cJSON *meta, const lcb_stats *st,
                            const char *path, FILE *out) {
    char b[32];
    fprintf(out, "lucent bake: %s\n", path ? path : "(memory)");
    fprintf(out, "  format      %u.%u (this build reads %d.x)\n", v->version_major, v->version_minor,
            LC_LCB_VERSION_MAJOR);
    fputs("  source      ", out);
    const cJSON *src = cJSON_GetObjectItemCaseSensitive(meta, "source");
    if (src) lcb_print_value(src, out);
    else fputs("-", out);
    lcb_human_bytes(st->file_size, b, sizeof b);
    fprintf(out, "\n  file size   %s\n", b);

    fputs("settings\n", out);
    const cJSON *settings = cJSON_GetObjectItemCaseSensitive(meta, "settings");
    if (cJSON_IsObject(settings) && settings->child) {
        for (const cJSON *e = settings->child; e; e = e->next) {
            fprintf(out, "  %-22s ", e->string ? e->string : "?");
            lcb_print_value(e, out);
            fputc('\n', out);
        }
    } else {
        fputs("  (none recorded)\n", out);
    }

    uint64_t texels = (uint64_t)v->lightmap_width * v->lightmap_height;
    fputs("counts\n", out);
    fprintf(out, "  geometry    %u materials, %u vertices, %u triangles\n", v->n_materials, v->n_vertices,
            v->n_triangles);
    fprintf(out, "  surfels     %u (area %.4g m^2)\n", v->n_surfels, st->surfel_area);
    fprintf(out, "  hierarchy   %u nodes, %u levels\n", v->n_nodes, v->n_levels);
    fprintf(out, "  caches      %u: %u texel, %u grid, %u moved, %u inside\n", v->n_caches, st->texel, st->grid,
            st->moved, st->inside);
    fprintf(out, "  links       %u per cache (%llu total), link SH bands %u, output SH bands %u\n", v->links_per_cache,
            (unsigned long long)v->n_caches * v->links_per_cache, v->link_sh_bands, v->sh_bands);
    if (v->grid_links)
        fprintf(out, "              grid caches: %u links each (GLNK, %llu total)\n", v->grid_links_per_cache,
                (unsigned long long)(v->n_caches - v->n_texel_caches) * v->grid_links_per_cache);
    if (v->texel_surfels_first) {
        uint32_t n = v->texel_surfels_first[v->n_texel_caches];
        fprintf(out, "              texel caches gather per surfel: %u entries, %.1f per texel cache\n", n,
                v->n_texel_caches ? (double)n / v->n_texel_caches : 0.0);
    }
    fprintf(out, "  lightmap    %ux%u: %llu texels own a cache (%.1f%%), %llu dilated, %llu empty\n", v->lightmap_width,
            v->lightmap_height, (unsigned long long)st->owned, texels ? 100.0 * (double)st->owned / (double)texels : 0,
            (unsigned long long)st->dilated, (unsigned long long)st->empty);
    fprintf(out, "  grid        %ux%ux%u, cell %.4g m, origin (%.4g, %.4g, %.4g)\n", v->grid_dims[0], v->grid_dims[1],
            v->grid_dims[2], v->grid_cell, v->grid_origin[0], v->grid_origin[1], v->grid_origin[2]);
    fprintf(out, "  assets      %u (%u vertices, %u triangles)\n", v->n_assets, v->n_asset_vertices,
            v->n_asset_triangles);
    lcb_print_sparse(v, out);
    lcb_print_probes(v, st, out);

    fputs("sections\n", out);
    fprintf(out, "  %-4s  %12s  %10s  %12s  %s\n", "id", "records", "record", "bytes", "crc");
    for (uint32_t i = 0; i < lc_lcb_section_count(f); i++) {
        const lc_lcb_section *s = lc_lcb_section_at(f, i);
        char id[5];
        lcb_id(s->id, id);
        lcb_human_bytes(s->size, b, sizeof b);
        fprintf(out, "  %-4s  %12llu  %10u  %12s  %08x\n", id, (unsigned long long)s->count, s->record_size, b, s->crc);
    }
}

/* Adds n to obj; returns 0 when cJSON ran out of memory. */
static int lcb_add_num(cJSON *obj, const char *key, double n) { return cJSON_AddNumberToObject(obj, key, n) != NULL; }

/* counts.probes, when the bake has the probes solver; returns 0 when cJSON ran out of memory. */
static int lcb_json_probes(cJSON *cnt, const lc_lcb_view *v, const lcb_stats *st) {
    const lc_lcb_probe_header *h = v->probe_header;
    if (!h) return 1;
    cJSON *p = cJSON_AddObjectToObject(cnt, "probes");
    if (!p) return 0;
    struct {
        const char *k;
        double v;
    } nums[] = {
        {"probes", h->n_probes},
        {"rays", h->n_rays},
        {"sh_bands", h->sh_bands},
        {"clusters", h->n_clusters},
        {"rows", h->n_rows},
        {"max_rank", h->max_rank},
        {"mean_rank", st->probe_mean_rank},
        {"overlaps", h->overlaps},
        {"receiver_rays", h->receiver_rays},
        {"support_radius", h->support_radius},
        {"svd_error", h->svd_error},
        {"bytes", (double)st->probe_bytes},
        {"unseen_entries", v->probe_unseen_first ? v->probe_unseen_first[h->n_rows] : 0},
    };
    for (size_t i = 0; i < sizeof nums / sizeof nums[0]; i++)
        if (!lcb_add_num(p, nums[i].k, nums[i].v)) return 0;
    return 1;
}

static int lcb_print_json(const lc_lcb *f, const lc_lcb_view *v, const cJSON *meta, const lcb_stats *st,
                          const char *path, FILE *out) {
    int rc = -1;
    char *text = NULL;
    cJSON *root = cJSON_CreateObject();
    if (!root) goto err;
    if (!cJSON_AddStringToObject(root, "path", path ? path : "")) goto err;
    cJSON *ver = cJSON_AddObjectToObject(root, "version");
    if (!ver || !lcb_add_num(ver, "major", v->version_major) || !lcb_add_num(ver, "minor", v->version_minor)) goto err;
    const cJSON *src = cJSON_GetObjectItemCaseSensitive(meta, "source");
    cJSON *dup = src ? cJSON_Duplicate(src, 1) : cJSON_CreateNull();
    if (!dup) goto err;
    cJSON_AddItemToObject(root, "source", dup);
    if (!lcb_add_num(root, "file_size", (double)st->file_size)) goto err;
    const cJSON *settings = cJSON_GetObjectItemCaseSensitive(meta, "settings");
    dup = settings ? cJSON_Duplicate(settings, 1) : cJSON_CreateNull();
    if (!dup) goto err;
    cJSON_AddItemToObject(root, "settings", dup);

    cJSON *cnt = cJSON_AddObjectToObject(root, "counts");
    if (!cnt) goto err;
    struct {
        const char *k;
        double v;
    } nums[] = {
        {"materials", v->n_materials},
        {"vertices", v->n_vertices},
        {"triangles", v->n_triangles},
        {"surfels", v->n_surfels},
        {"surfel_area", st->surfel_area},
        {"nodes", v->n_nodes},
        {"levels", v->n_levels},
        {"caches", v->n_caches},
        {"texel_caches", st->texel},
        {"grid_caches", st->grid},
        {"moved_caches", st->moved},
        {"inside_caches", st->inside},
        {"links_per_cache", v->links_per_cache},
        {"links", (double)v->n_caches * v->links_per_cache},
        {"grid_links_per_cache", v->grid_links_per_cache},
        {"link_sh_bands", v->link_sh_bands},
        {"texel_surfel_entries", v->texel_surfels_first ? v->texel_surfels_first[v->n_texel_caches] : 0},
        {"sh_bands", v->sh_bands},
        {"assets", v->n_assets},
        {"asset_vertices", v->n_asset_vertices},
        {"asset_triangles", v->n_asset_triangles},
    };
    for (size_t i = 0; i < sizeof nums / sizeof nums[0]; i++)
        if (!lcb_add_num(cnt, nums[i].k, nums[i].v)) goto err;
    if (!lcb_add_num(cnt, "sparse_points", v->n_sparse_points)) goto err;
    cJSON *asp = cJSON_AddArrayToObject(cnt, "asset_sparse_points"); /* per asset, ASET order */
    for (uint32_t i = 0; asp && i < v->n_assets; i++) {
        uint32_t first, count;
        cJSON *x = cJSON_CreateNumber(lc_lcb_asset_sparse(v, i, &first, &count));
        if (!x) goto err;
        cJSON_AddItemToArray(asp, x);
    }
    if (!asp) goto err;
    if (!lcb_json_probes(cnt, v, st)) goto err;
    cJSON *lm = cJSON_AddObjectToObject(cnt, "lightmap");
    uint64_t texels = (uint64_t)v->lightmap_width * v->lightmap_height;
    if (!lm || !lcb_add_num(lm, "width", v->lightmap_width) || !lcb_add_num(lm, "height", v->lightmap_height) ||
        !lcb_add_num(lm, "owned", (double)st->owned) || !lcb_add_num(lm, "dilated", (double)st->dilated) ||
        !lcb_add_num(lm, "empty", (double)st->empty) ||
        !lcb_add_num(lm, "usage", texels ? (double)st->owned / (double)texels : 0))
        goto err;
    cJSON *grid = cJSON_AddObjectToObject(cnt, "grid");
    if (!grid) goto err;
    int dims[3] = {(int)v->grid_dims[0], (int)v->grid_dims[1], (int)v->grid_dims[2]};
    float origin[3] = {v->grid_origin[0], v->grid_origin[1], v->grid_origin[2]};
    cJSON *a = cJSON_CreateIntArray(dims, 3);
    if (!a) goto err;
    cJSON_AddItemToObject(grid, "dims", a);
    a = cJSON_CreateFloatArray(origin, 3);
    if (!a) goto err;
    cJSON_AddItemToObject(grid, "origin", a);
    if (!lcb_add_num(grid, "cell", v->grid_cell)) goto err;

    dup = cJSON_Duplicate(meta, 1);
    if (!dup) goto err;
    cJSON_AddItemToObject(root, "meta", dup);

    cJSON *secs = cJSON_AddArrayToObject(root, "sections");
    if (!secs) goto err;
    for (uint32_t i = 0; i < lc_lcb_section_count(f); i++) {
        const lc_lcb_section *s = lc_lcb_section_at(f, i);
        char id[5], crc[16], hb[32];
        lcb_id(s->id, id);
        snprintf(crc, sizeof crc, "%08x", s->crc);
        lcb_human_bytes(s->size, hb, sizeof hb);
        cJSON *o = cJSON_CreateObject();
        if (!o) goto err;
        cJSON_AddItemToArray(secs, o);
        if (!cJSON_AddStringToObject(o, "id", id) || !lcb_add_num(o, "record_size", s->record_size) ||
            !lcb_add_num(o, "records", (double)s->count) || !lcb_add_num(o, "offset", (double)s->offset) ||
            !lcb_add_num(o, "bytes", (double)s->size) || !cJSON_AddStringToObject(o, "size", hb) ||
            !cJSON_AddStringToObject(o, "crc", crc))
            goto err;
    }
    text = cJSON_Print(root);
    if (!text) goto err;
    fputs(text, out);
    fputc('\n', out);
    rc = 0;
err:
    free(text);
    cJSON_Delete(root);
    return rc;
}

void lc_lcb_print_info(const lc_lcb *f, const char *path, int json, FILE *out) {
    const lc_lcb_view *v = lc_lcb_get(f);
    if (!v || !out) return;
    /* META was validated (bounded size and depth, an object) when the file was opened. */
    cJSON *meta = cJSON_Parse(v->meta_json);
    if (!meta) {
        fputs(json ? "{\"error\": \"out of memory\"}\n" : "lucent bake: out of memory\n", out);
        return;
    }
    lcb_stats st;
    lcb_gather(f, v, meta, &st);
    if (json) {
        if (lcb_print_json(f, v, meta, &st, path, out) != 0) fputs("{\"error\": \"out of memory\"}\n", out);
    } else {
        lcb_print_human(f, v, meta, &st, path, out);
    }
    cJSON_Delete(meta);
}
