/* test_lcb_glb: the binary glTF generated from a bake (lc_lcb_scene_glb, lc_lcb_asset_glb,
 * lc_lcb_bake_id) on the build's embedded Cornell bake (LUCENT_BINARY_DIR/cornell.lcb):
 * the container and every accessor checked byte by byte against the glTF 2.0 rules, the
 * geometry against the bake bit for bit, the lamp's emission, the cube asset's bounds; then
 * a copy of the bake with a textured material, a zero normal and a dim emitter, and the
 * error cases. */
#include <cjson/cJSON.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "lcb/lcb.h"
#include "lcb/lcb_glb.h"

typedef struct glb {
    cJSON *json;
    const unsigned char *bin;
    size_t bin_len;
} glb;

static uint32_t rd_u32(const unsigned char *p) { return p[0] | p[1] << 8 | p[2] << 16 | (uint32_t)p[3] << 24; }

static double num(const cJSON *o, const char *key) {
    const cJSON *x = cJSON_GetObjectItem(o, key);
    return cJSON_IsNumber(x) ? x->valuedouble : -1;
}

static const char *str_or(const cJSON *x) { return cJSON_IsString(x) ? x->valuestring : ""; }

static unsigned char *read_all(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *b = n > 0 ? malloc((size_t)n) : NULL;
    if (b && fread(b, 1, (size_t)n, f) != (size_t)n) {
        free(b);
        b = NULL;
    }
    fclose(f);
    *len = b ? (size_t)n : 0;
    return b;
}

static int comps_of(const char *type) {
    if (!strcmp(type, "SCALAR")) return 1;
    if (!strcmp(type, "VEC2")) return 2;
    if (!strcmp(type, "VEC3")) return 3;
    if (!strcmp(type, "VEC4")) return 4;
    return 0;
}

/* Every accessor's count x element size fits its bufferView; every view is 4-aligned and
 * inside buffer 0, which is the BIN chunk less its zero padding. */
static void check_views(const glb *g) {
    const cJSON *buf0 = cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "buffers"), 0);
    double blen = num(buf0, "byteLength");
    CHECK(blen >= 0 && blen <= (double)g->bin_len && g->bin_len - (size_t)blen < 4, "buffer 0 byteLength %g, BIN %zu",
          blen, g->bin_len);
    for (size_t i = blen >= 0 ? (size_t)blen : 0; i < g->bin_len; i++) CHECK(g->bin[i] == 0, "BIN padding byte %zu", i);
    const cJSON *views = cJSON_GetObjectItem(g->json, "bufferViews"), *v;
    cJSON_ArrayForEach(v, views) {
        double off = num(v, "byteOffset"), len = num(v, "byteLength");
        CHECK(num(v, "buffer") == 0 && off >= 0 && len > 0 && off + len <= blen, "view [%g, +%g) in buffer of %g", off,
              len, blen);
        CHECK((size_t)off % 4 == 0, "view offset %g not 4-byte aligned", off);
    }
    const cJSON *a;
    cJSON_ArrayForEach(a, cJSON_GetObjectItem(g->json, "accessors")) {
        const cJSON *view = cJSON_GetArrayItem(views, (int)num(a, "bufferView"));
        int ct = (int)num(a, "componentType");
        const cJSON *type = cJSON_GetObjectItem(a, "type");
        int comps = cJSON_IsString(type) ? comps_of(type->valuestring) : 0;
        /* FLOAT, UNSIGNED_INT, and UNSIGNED_SHORT (the sparse-point indices: VEC4, 8 bytes) */
        CHECK(view && (ct == 5126 || ct == 5125 || (ct == 5123 && comps == 4)) && comps > 0,
              "accessor view/componentType %d/type", ct);
        int bytes = ct == 5123 ? 2 : 4;
        if (view)
            CHECK(num(a, "count") >= 1 && num(a, "count") * comps * bytes <= num(view, "byteLength"),
                  "accessor of %g x %d x %d bytes does not fit its view of %g bytes", num(a, "count"), comps, bytes,
                  num(view, "byteLength"));
    }
}

/* The GLB container: header, a space-padded JSON chunk that parses, a BIN chunk. */
static int parse_glb(const unsigned char *b, size_t len, glb *g) {
    memset(g, 0, sizeof *g);
    CHECK(len >= 28 && len % 4 == 0, "length %zu", len);
    if (len < 28) return -1;
    CHECK(!memcmp(b, "glTF", 4) && rd_u32(b + 4) == 2, "magic/version");
    CHECK(rd_u32(b + 8) == len, "header length %u, buffer %zu", rd_u32(b + 8), len);
    uint32_t jlen = rd_u32(b + 12);
    CHECK(!memcmp(b + 16, "JSON", 4) && jlen % 4 == 0 && 20 + (size_t)jlen + 8 <= len, "JSON chunk of %u", jlen);
    if (jlen % 4 || 20 + (size_t)jlen + 8 > len) return -1;
    const unsigned char *bc = b + 20 + jlen;
    g->bin_len = rd_u32(bc);
    g->bin = bc + 8;
    CHECK(!memcmp(bc + 4, "BIN\0", 4) && g->bin_len % 4 == 0 && 28 + (size_t)jlen + g->bin_len == len,
          "BIN chunk of %zu", g->bin_len);
    size_t end = jlen;
    while (end > 0 && b[20 + end - 1] == ' ') end--;
    CHECK(end > 0 && b[20 + end - 1] == '}' && jlen - end < 4, "JSON padded with %zu spaces", jlen - end);
    g->json = cJSON_ParseWithLength((const char *)b + 20, jlen);
    CHECK(g->json != NULL, "JSON chunk parses");
    if (!g->json || 28 + (size_t)jlen + g->bin_len != len) return -1;
    const cJSON *asset = cJSON_GetObjectItem(g->json, "asset");
    CHECK(!strcmp(str_or(cJSON_GetObjectItem(asset, "version")), "2.0"), "asset.version");
    CHECK(!strcmp(str_or(cJSON_GetObjectItem(asset, "generator")), "lucent"), "asset.generator");
    check_views(g);
    return 0;
}

/* Accessor i's data (floats or uint32), its count and component count. */
static const void *acc_data(const glb *g, int i, uint32_t *count, int *comps) {
    const cJSON *a = cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "accessors"), i);
    const cJSON *v = cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "bufferViews"), (int)num(a, "bufferView"));
    if (!a || !v) return NULL;
    *count = (uint32_t)num(a, "count");
    *comps = comps_of(str_or(cJSON_GetObjectItem(a, "type")));
    return g->bin + (size_t)num(v, "byteOffset");
}

static int attr(const cJSON *prim, const char *name) {
    const cJSON *x = cJSON_GetObjectItem(cJSON_GetObjectItem(prim, "attributes"), name);
    return cJSON_IsNumber(x) ? x->valueint : -1;
}

/* A primitive's common rules: attribute counts agree, indices in range, POSITION min/max is
 * the data's, NORMAL unit. Returns the triangle count; *pos, *idx, *nv for the caller. */
static uint32_t check_primitive(const glb *g, const cJSON *prim, const float **pos, const uint32_t **idx,
                                uint32_t *nv) {
    uint32_t n = 0, ni = 0, cn = 0;
    int comps = 0, ic = 0;
    *pos = acc_data(g, attr(prim, "POSITION"), &n, &comps);
    const float *nrm = acc_data(g, attr(prim, "NORMAL"), &cn, &ic);
    *idx = acc_data(g, (int)num(prim, "indices"), &ni, &ic);
    *nv = n;
    CHECK(*pos && nrm && *idx && cn == n && comps == 3 && ni % 3 == 0, "primitive accessors");
    CHECK(num(prim, "mode") == 4, "mode TRIANGLES");
    if (!*pos || !nrm || !*idx) return 0;
    const cJSON *ia = cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "accessors"), (int)num(prim, "indices"));
    CHECK(num(ia, "componentType") == 5125, "indices UNSIGNED_INT");
    for (uint32_t k = 0; k < ni; k++) CHECK((*idx)[k] < n, "index %u of %u vertices", (*idx)[k], n);
    const cJSON *pa = cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "accessors"), attr(prim, "POSITION"));
    const cJSON *mn = cJSON_GetObjectItem(pa, "min"), *mx = cJSON_GetObjectItem(pa, "max");
    CHECK(cJSON_GetArraySize(mn) == 3 && cJSON_GetArraySize(mx) == 3, "POSITION min/max");
    for (int c = 0; c < 3 && cJSON_GetArraySize(mn) == 3 && cJSON_GetArraySize(mx) == 3; c++) {
        float lo = INFINITY, hi = -INFINITY;
        for (uint32_t i = 0; i < n; i++) lo = fminf(lo, (*pos)[3 * i + c]), hi = fmaxf(hi, (*pos)[3 * i + c]);
        CHECK((float)cJSON_GetArrayItem(mn, c)->valuedouble == lo &&
                  (float)cJSON_GetArrayItem(mx, c)->valuedouble == hi,
              "POSITION min/max[%d] %g/%g, data %g/%g", c, cJSON_GetArrayItem(mn, c)->valuedouble,
              cJSON_GetArrayItem(mx, c)->valuedouble, lo, hi);
    }
    for (uint32_t i = 0; i < n; i++) {
        const float *x = nrm + 3 * i;
        CHECK_NEAR(sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]), 1.0, 1e-6);
    }
    return ni / 3;
}

static const cJSON *material(const glb *g, int i) {
    return cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "materials"), i);
}

static float json_f(const cJSON *arr, int i) { return (float)cJSON_GetArrayItem(arr, i)->valuedouble; }

/* Material i's emission as emissiveFactor x emissiveStrength. */
static void emission_of(const glb *g, int i, double out[3]) {
    const cJSON *m = material(g, i), *ef = cJSON_GetObjectItem(m, "emissiveFactor");
    const cJSON *ks = cJSON_GetObjectItem(cJSON_GetObjectItem(m, "extensions"), "KHR_materials_emissive_strength");
    double strength = ks ? num(ks, "emissiveStrength") : 1.0;
    for (int c = 0; c < 3; c++) {
        out[c] = cJSON_GetArraySize(ef) == 3 ? json_f(ef, c) * strength : -1;
        CHECK(cJSON_GetArraySize(ef) == 3 && json_f(ef, c) >= 0 && json_f(ef, c) <= 1, "emissiveFactor in [0,1]");
    }
}

/* The scene: triangle k of material m's primitive is the bake's k-th triangle of material m,
 * corner for corner, positions and lightmap UVs bit for bit. Returns the triangle total. */
static uint32_t check_scene_geometry(const glb *g, const lc_lcb_view *v) {
    uint32_t total = 0;
    const cJSON *prims =
        cJSON_GetObjectItem(cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "meshes"), 0), "primitives");
    const cJSON *prim;
    cJSON_ArrayForEach(prim, prims) {
        const float *pos, *uv;
        const uint32_t *idx;
        uint32_t nv, nuv = 0, m = (uint32_t)num(prim, "material");
        int comps = 0;
        uint32_t nt = check_primitive(g, prim, &pos, &idx, &nv);
        CHECK(attr(prim, "TEXCOORD_0") >= 0, "TEXCOORD_0 present (indexed semantics start at 0)");
        uv = acc_data(g, attr(prim, "TEXCOORD_1"), &nuv, &comps);
        CHECK(uv && nuv == nv && comps == 2, "TEXCOORD_1 VEC2 over %u vertices", nv);
        CHECK(m < v->n_materials, "primitive material %u", m);
        if (!uv || m >= v->n_materials) continue;
        uint32_t k = 0, bad_pos = 0, bad_uv = 0;
        for (uint32_t t = 0; t < v->n_triangles; t++) {
            if (v->triangles[t].material != m) continue;
            for (int c = 0; c < 3 && k < nt; c++) {
                const lc_lcb_vertex *src = &v->vertices[v->triangles[t].v[c]];
                uint32_t l = idx[3 * k + c];
                bad_pos += memcmp(pos + 3 * l, src->position, 12) != 0;
                bad_uv += memcmp(uv + 2 * l, src->uv1, 8) != 0;
            }
            k++;
        }
        CHECK(k == nt, "material %u: %u triangles in the bake, %u in its primitive", m, k, nt);
        CHECK(bad_pos == 0 && bad_uv == 0, "material %u: %u positions, %u uv1 differ from the bake", m, bad_pos,
              bad_uv);
        total += nt;
    }
    return total;
}

static void check_bake_id(const lc_lcb *f, const char *path, const glb *g) {
    char id[LC_LCB_BAKE_ID_LEN], want[64];
    lc_lcb_bake_id(f, id);
    size_t len = 0;
    unsigned char *raw = read_all(path, &len);
    CHECK(raw && len >= 64, "read %s", path);
    if (!raw || len < 64) return;
    unsigned long long file_size = 0;
    for (int i = 7; i >= 0; i--) file_size = file_size << 8 | raw[16 + i];
    snprintf(want, sizeof want, "%08x%016llx", rd_u32(raw + 32), file_size);
    CHECK(!strcmp(id, want) && strlen(id) == 24, "bake id %s, header table_crc+file_size %s", id, want);
    CHECK(file_size == len, "header file_size %llu, file %zu", file_size, len);
    const cJSON *lucent =
        cJSON_GetObjectItem(cJSON_GetObjectItem(cJSON_GetObjectItem(g->json, "asset"), "extras"), "lucent");
    CHECK(!strcmp(str_or(cJSON_GetObjectItem(lucent, "bake_id")), id), "asset.extras.lucent.bake_id");
    free(raw);
}

static int material_named(const lc_lcb_view *v, const char *name) {
    for (uint32_t i = 0; i < v->n_materials; i++)
        if (!strcmp(v->materials[i].name, name)) return (int)i;
    return -1;
}

static void check_scene(const lc_lcb *f, const char *path) {
    const lc_lcb_view *v = lc_lcb_get(f);
    unsigned char *out = NULL, *again = NULL;
    size_t len = 0, len2 = 0;
    char err[256] = "";
    CHECK(lc_lcb_scene_glb(f, &out, &len, err, sizeof err) == 0, "scene glb: %s", err);
    CHECK(lc_lcb_scene_glb(f, &again, &len2, err, sizeof err) == 0 && len2 == len && !memcmp(out, again, len),
          "two generations give the same bytes");
    glb g;
    if (!out || parse_glb(out, len, &g) != 0) goto out;
    check_bake_id(f, path, &g);
    CHECK(check_scene_geometry(&g, v) == v->n_triangles, "triangle count equals the bake's %u", v->n_triangles);
    CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(g.json, "materials")) == (int)v->n_materials, "materials");
    const cJSON *node = cJSON_GetArrayItem(cJSON_GetObjectItem(g.json, "nodes"), 0);
    CHECK(!strcmp(str_or(cJSON_GetObjectItem(node, "name")), "lucent") && num(node, "mesh") == 0,
          "node \"lucent\" shows mesh 0");
    int lamp = material_named(v, "light"), white = material_named(v, "white");
    CHECK(lamp >= 0 && white >= 0, "Cornell materials light and white");
    if (lamp >= 0) {
        double e[3];
        emission_of(&g, lamp, e);
        for (int c = 0; c < 3; c++) CHECK_NEAR(e[c], v->materials[lamp].emission[c], 1e-6);
        CHECK_NEAR(v->materials[lamp].emission[0], 17.0, 1e-6);
        const cJSON *used = cJSON_GetObjectItem(g.json, "extensionsUsed");
        CHECK(cJSON_GetArraySize(used) == 1 &&
                  !strcmp(str_or(cJSON_GetArrayItem(used, 0)), "KHR_materials_emissive_strength"),
              "extensionsUsed");
    }
    if (white >= 0) {
        const cJSON *pbr = cJSON_GetObjectItem(material(&g, white), "pbrMetallicRoughness");
        const cJSON *bc = cJSON_GetObjectItem(pbr, "baseColorFactor");
        for (int c = 0; c < 3 && cJSON_GetArraySize(bc) == 4; c++)
            CHECK(json_f(bc, c) == v->materials[white].base_color[c], "white base colour[%d]", c);
        CHECK(num(pbr, "metallicFactor") == 0 && num(pbr, "roughnessFactor") == 1, "metallic 0, roughness 1");
    }
    cJSON_Delete(g.json);
out:
    free(out);
    free(again);
}

/* The asset's sparse-point tables (PROTOCOL §8.7): _LUCENT_SP_INDEX0/1 (VEC4 UNSIGNED_SHORT)
 * and _LUCENT_SP_WEIGHT0/1 (VEC4 FLOAT), one element per vertex, bit for bit AVNN's; indices
 * below the asset's point count, weights summing to 1; mesh extras.lucent.sparse_points. */
static void check_asset_sparse(const glb *g, const cJSON *prim, const lc_lcb_view *v, uint32_t asset) {
    const lc_lcb_asset *a = &v->assets[asset];
    uint32_t first = 0, points = 0;
    lc_lcb_asset_sparse(v, asset, &first, &points);
    CHECK(v->sparse_points && points == 256, "the Cornell cube has the default 256 sparse points (%u)", points);
    const cJSON *mesh = cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "meshes"), 0);
    const cJSON *lucent = cJSON_GetObjectItem(cJSON_GetObjectItem(mesh, "extras"), "lucent");
    CHECK(num(lucent, "sparse_points") == points, "mesh extras.lucent.sparse_points %g, bake %u",
          num(lucent, "sparse_points"), points);
    /* the points themselves (asset-local), bit for bit ASPT's */
    const cJSON *spa = cJSON_GetObjectItem(lucent, "sparse_point_accessors");
    static const char *const pkeys[3] = {"position", "normal", "radius"};
    for (int k = 0; k < 3; k++) {
        int acc = (int)num(spa, pkeys[k]);
        uint32_t n = 0;
        int comps = 0;
        const float *pd = acc >= 0 ? acc_data(g, acc, &n, &comps) : NULL;
        CHECK(pd && n == points && comps == (k < 2 ? 3 : 1), "sparse_point_accessors.%s: %u x %d, bake %u points",
              pkeys[k], n, comps, points);
        for (uint32_t i = 0; pd && n == points && i < points; i++) {
            const lc_lcb_sparse_point *sp = &v->sparse_points[first + i];
            const float *want = k == 0 ? sp->position : k == 1 ? sp->normal : &sp->radius;
            CHECK(!memcmp(pd + (size_t)comps * i, want, (size_t)comps * sizeof(float)), "sparse point %u %s = ASPT", i,
                  pkeys[k]);
        }
    }
    static const char *const names[4] = {"_LUCENT_SP_INDEX0", "_LUCENT_SP_INDEX1", "_LUCENT_SP_WEIGHT0",
                                         "_LUCENT_SP_WEIGHT1"};
    const void *data[4] = {NULL, NULL, NULL, NULL};
    for (int k = 0; k < 4; k++) {
        int acc = attr(prim, names[k]);
        const cJSON *ja = cJSON_GetArrayItem(cJSON_GetObjectItem(g->json, "accessors"), acc);
        uint32_t n = 0;
        int comps = 0;
        data[k] = acc >= 0 ? acc_data(g, acc, &n, &comps) : NULL;
        CHECK(data[k] && n == a->vertex_count && comps == 4, "%s: %u x VEC%d, asset %u vertices", names[k], n, comps,
              a->vertex_count);
        CHECK(num(ja, "componentType") == (k < 2 ? 5123 : 5126), "%s componentType %g", names[k],
              num(ja, "componentType"));
    }
    if (!data[0] || !data[1] || !data[2] || !data[3]) return;
    for (uint32_t i = 0; i < a->vertex_count; i++) {
        const lc_lcb_sparse_vertex *r = &v->sparse_vertices[a->first_vertex + i];
        uint16_t ix[8];
        float w[8];
        memcpy(ix, (const uint16_t *)data[0] + 4 * (size_t)i, 8);
        memcpy(ix + 4, (const uint16_t *)data[1] + 4 * (size_t)i, 8);
        memcpy(w, (const float *)data[2] + 4 * (size_t)i, 16);
        memcpy(w + 4, (const float *)data[3] + 4 * (size_t)i, 16);
        CHECK(!memcmp(ix, r->index, sizeof ix) && !memcmp(w, r->weight, sizeof w), "vertex %u: table = AVNN", i);
        double sum = 0;
        for (int k = 0; k < 8; k++) {
            CHECK(ix[k] < points, "vertex %u index[%d] = %u < %u", i, k, ix[k], points);
            sum += w[k];
        }
        CHECK_NEAR(sum, 1.0, 1e-5);
    }
}

/* The cube asset: bounds, positions and albedo bit for bit, 12 triangles, white material. */
static void check_asset(const lc_lcb *f) {
    const lc_lcb_view *v = lc_lcb_get(f);
    CHECK(v->n_assets == 1 && !strcmp(v->assets[0].name, "cube"), "the Cornell bake has the cube asset");
    if (v->n_assets < 1) return;
    const lc_lcb_asset *a = &v->assets[0];
    unsigned char *out = NULL;
    size_t len = 0;
    char err[256] = "";
    CHECK(lc_lcb_asset_glb(f, 0, &out, &len, err, sizeof err) == 0, "asset glb: %s", err);
    glb g;
    if (!out || parse_glb(out, len, &g) != 0) {
        free(out);
        return;
    }
    const cJSON *prim = cJSON_GetArrayItem(
        cJSON_GetObjectItem(cJSON_GetArrayItem(cJSON_GetObjectItem(g.json, "meshes"), 0), "primitives"), 0);
    const float *pos, *col;
    const uint32_t *idx;
    uint32_t nv = 0, nc = 0;
    int comps = 0;
    CHECK(check_primitive(&g, prim, &pos, &idx, &nv) == a->triangle_count && a->triangle_count == 12, "12 triangles");
    CHECK(nv == a->vertex_count, "%u vertices, asset %u", nv, a->vertex_count);
    const cJSON *pa = cJSON_GetArrayItem(cJSON_GetObjectItem(g.json, "accessors"), attr(prim, "POSITION"));
    for (int c = 0; c < 3; c++) {
        CHECK(json_f(cJSON_GetObjectItem(pa, "min"), c) == a->bounds_min[c], "min[%d] = asset bounds", c);
        CHECK(json_f(cJSON_GetObjectItem(pa, "max"), c) == a->bounds_max[c], "max[%d] = asset bounds", c);
        CHECK_NEAR(a->bounds_max[c] - a->bounds_min[c], 0.1, 1e-5);
    }
    col = acc_data(&g, attr(prim, "COLOR_0"), &nc, &comps);
    CHECK(col && nc == nv && comps == 3, "COLOR_0 VEC3");
    for (uint32_t i = 0; col && pos && i < nv && i < a->vertex_count; i++) {
        const lc_lcb_asset_vertex *src = &v->asset_vertices[a->first_vertex + i];
        CHECK(!memcmp(pos + 3 * i, src->position, 12) && !memcmp(col + 3 * i, src->albedo, 12), "asset vertex %u", i);
    }
    for (uint32_t k = 0; idx && k < 3 * a->triangle_count; k++)
        CHECK(idx[k] == v->asset_indices[3 * (size_t)a->first_triangle + k], "asset index %u", k);
    check_asset_sparse(&g, prim, v, 0);
    const cJSON *bc =
        cJSON_GetObjectItem(cJSON_GetObjectItem(material(&g, 0), "pbrMetallicRoughness"), "baseColorFactor");
    CHECK(cJSON_GetArraySize(bc) == 4 && json_f(bc, 0) == 1 && json_f(bc, 1) == 1 && json_f(bc, 2) == 1, "white");
    const cJSON *node = cJSON_GetArrayItem(cJSON_GetObjectItem(g.json, "nodes"), 0);
    CHECK(!strcmp(str_or(cJSON_GetObjectItem(node, "name")), "cube"), "node named cube");
    cJSON_Delete(g.json);
    free(out);
}

/* Out of range and missing arguments fail cleanly, naming the index. */
static void check_errors(const lc_lcb *f) {
    unsigned char *out = (unsigned char *)"x";
    size_t len = 7;
    char err[256] = "";
    uint32_t n = lc_lcb_get(f)->n_assets;
    CHECK(lc_lcb_asset_glb(f, n, &out, &len, err, sizeof err) == -1, "asset %u out of range", n);
    char want[64];
    snprintf(want, sizeof want, "asset index %u", n);
    CHECK(strstr(err, want) != NULL, "error names the asset index: %s", err);
    CHECK(out == NULL && len == 0, "no output on error");
    CHECK(lc_lcb_scene_glb(NULL, &out, &len, err, sizeof err) == -1 && err[0], "NULL bake: %s", err);
    char id[LC_LCB_BAKE_ID_LEN] = "z";
    lc_lcb_bake_id(NULL, id);
    CHECK(id[0] == 0, "bake id of NULL is empty");
}

/* A copy of the bake with material `tex` marked textured, vertex `zv`'s normal zeroed and
 * the lamp dimmed to 0.5 nits: its path in `out`. */
static int write_variant(const lc_lcb *f, const char *src_path, const char *out, uint32_t tex, uint32_t zv,
                         uint32_t lamp) {
    size_t len = 0;
    unsigned char *raw = read_all(src_path, &len);
    const lc_lcb_view *v = lc_lcb_get(f);
    lc_lcb_material *mats = malloc(v->n_materials * sizeof *mats);
    lc_lcb_vertex *verts = malloc(v->n_vertices * sizeof *verts);
    lc_lcb_writer *w = lc_lcb_writer_create();
    char err[256] = "";
    int rc = -1;
    if (!raw || !mats || !verts || !w) goto out;
    memcpy(mats, v->materials, v->n_materials * sizeof *mats);
    memcpy(verts, v->vertices, v->n_vertices * sizeof *verts);
    mats[tex].flags |= 1u;
    mats[lamp].emission[0] = 0.5f, mats[lamp].emission[1] = 0.25f, mats[lamp].emission[2] = 0;
    memset(verts[zv].normal, 0, sizeof verts[zv].normal);
    rc = 0;
    for (uint32_t i = 0; i < lc_lcb_section_count(f); i++) {
        const lc_lcb_section *s = lc_lcb_section_at(f, i);
        const void *data = raw + s->offset;
        if (!memcmp(s->id, "MATL", 4)) data = mats;
        if (!memcmp(s->id, "VERT", 4)) data = verts;
        rc |= lc_lcb_writer_add(w, s->id, s->record_size, data, s->count);
    }
    if (rc == 0) rc = lc_lcb_writer_write(w, out, err, sizeof err);
    CHECK(rc == 0, "write the variant: %s", err);
out:
    lc_lcb_writer_release(w);
    free(raw);
    free(mats);
    free(verts);
    return rc;
}

/* The variant: the textured material's base colour is its surfels' mean albedo, the zeroed
 * normal became its face's, the dim lamp needs no strength extension, and the id changed. */
static void check_variant(const lc_lcb *orig, const char *src_path) {
    const lc_lcb_view *v0 = lc_lcb_get(orig);
    int red = material_named(v0, "red"), lamp = material_named(v0, "light");
    if (red < 0 || lamp < 0) return;
    uint32_t zt = LC_NONE; /* the first red triangle; its first vertex loses its normal */
    for (uint32_t t = 0; t < v0->n_triangles && zt == LC_NONE; t++)
        if (v0->triangles[t].material == (uint32_t)red) zt = t;
    char path[] = "/tmp/lucent_glb_variant_XXXXXX";
    int fd = mkstemp(path);
    CHECK(fd >= 0, "temp file");
    if (fd < 0 || zt == LC_NONE) return;
    close(fd);
    lc_lcb *f = NULL;
    char err[256] = "";
    unsigned char *out = NULL;
    size_t len = 0;
    if (write_variant(orig, src_path, path, (uint32_t)red, v0->triangles[zt].v[0], (uint32_t)lamp) != 0) goto out;
    CHECK(lc_lcb_open(path, &f, err, sizeof err) == 0, "open the variant: %s", err);
    if (!f) goto out;
    char id0[LC_LCB_BAKE_ID_LEN], id1[LC_LCB_BAKE_ID_LEN];
    lc_lcb_bake_id(orig, id0), lc_lcb_bake_id(f, id1);
    CHECK(strcmp(id0, id1) != 0, "another content, another bake id (%s)", id1);
    CHECK(lc_lcb_scene_glb(f, &out, &len, err, sizeof err) == 0, "variant glb: %s", err);
    glb g;
    if (!out || parse_glb(out, len, &g) != 0) goto out;
    double sum[3] = {0, 0, 0};
    uint32_t n = 0;
    for (uint32_t i = 0; i < v0->n_surfels; i++)
        if (v0->surfels[i].material == (uint32_t)red) {
            for (int c = 0; c < 3; c++) sum[c] += v0->surfels[i].albedo[c];
            n++;
        }
    const cJSON *bc =
        cJSON_GetObjectItem(cJSON_GetObjectItem(material(&g, red), "pbrMetallicRoughness"), "baseColorFactor");
    CHECK(n > 0 && cJSON_GetArraySize(bc) == 4, "red surfels %u", n);
    for (int c = 0; c < 3 && n > 0 && cJSON_GetArraySize(bc) == 4; c++) CHECK_NEAR(json_f(bc, c), sum[c] / n, 1e-6);
    double e[3];
    emission_of(&g, lamp, e);
    CHECK(e[0] == 0.5 && e[1] == 0.25 && e[2] == 0, "dim lamp emission %g %g %g", e[0], e[1], e[2]);
    CHECK(cJSON_GetObjectItem(g.json, "extensionsUsed") == NULL, "no emissive strength needed");
    /* the red wall's first corner: its normal is now the face normal of its first triangle */
    const cJSON *prim;
    cJSON_ArrayForEach(
        prim, cJSON_GetObjectItem(cJSON_GetArrayItem(cJSON_GetObjectItem(g.json, "meshes"), 0), "primitives")) {
        if (num(prim, "material") != red) continue;
        uint32_t cnt = 0, ni = 0;
        int comps = 0;
        const float *nrm = acc_data(&g, attr(prim, "NORMAL"), &cnt, &comps);
        const uint32_t *idx = acc_data(&g, (int)num(prim, "indices"), &ni, &comps);
        const float *p0 = v0->vertices[v0->triangles[zt].v[0]].position,
                    *p1 = v0->vertices[v0->triangles[zt].v[1]].position,
                    *p2 = v0->vertices[v0->triangles[zt].v[2]].position;
        double e1[3] = {p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]},
               e2[3] = {p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]};
        double want[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        double wl = sqrt(want[0] * want[0] + want[1] * want[1] + want[2] * want[2]);
        for (int c = 0; c < 3; c++) want[c] /= wl;
        CHECK(fabs(want[0]) > 0.99, "the red wall faces along x (%g)", want[0]);
        CHECK(nrm && idx, "red primitive");
        for (int c = 0; nrm && idx && c < 3; c++) CHECK_NEAR(nrm[3 * idx[0] + c], want[c], 1e-5);
    }
    cJSON_Delete(g.json);
out:
    free(out);
    lc_lcb_close(f);
    unlink(path);
}

int main(void) {
    const char *dir = getenv("LUCENT_BINARY_DIR");
    char path[1024];
    snprintf(path, sizeof path, "%s/cornell.lcb", dir ? dir : ".");
    if (access(path, R_OK) != 0) {
        fprintf(stderr, "skip: %s missing (build the cornell_bake target)\n", path);
        return CHECK_SKIP_RC;
    }
    lc_lcb *f = NULL;
    char err[256] = "";
    CHECK(lc_lcb_open(path, &f, err, sizeof err) == 0, "open %s: %s", path, err);
    if (!f) CHECK_DONE();
    check_scene(f, path);
    check_asset(f);
    check_errors(f);
    check_variant(f, path);
    lc_lcb_close(f);
    CHECK_DONE();
}
