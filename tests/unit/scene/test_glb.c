/* test_glb: lc_glb_write round trip. Cornell box + synthetic planar lightmap UVs (+ a texture on
 * one material) -> .glb -> checked byte-level (header, chunks, JSON) and re-imported. */
#include <cjson/cJSON.h>
#include <ftw.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "bake/scene.h"
#include "check.h"

static int rm_entry(const char *p, const struct stat *st, int flag, struct FTW *ftw) {
    (void)st, (void)flag, (void)ftw;
    return remove(p);
}

static uint32_t rd_u32(const unsigned char *p) { return p[0] | p[1] << 8 | p[2] << 16 | (uint32_t)p[3] << 24; }

static const lc_material *find_material(const lc_scene *s, const char *name) {
    for (uint32_t i = 0; i < s->n_materials; i++)
        if (!strcmp(s->materials[i].name, name)) return &s->materials[i];
    return NULL;
}

static void planar_uv1(const float *p, float out[2]) {
    out[0] = p[0] / 0.556f;
    out[1] = p[2] / 0.5592f;
}

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

/* Byte-level checks of the container and its JSON. */
static void check_container(const char *path, const lc_scene *src) {
    size_t len = 0;
    unsigned char *b = read_all(path, &len);
    CHECK(b && len >= 28, "read %s (%zu bytes)", path, len);
    if (!b || len < 28) {
        free(b);
        return;
    }
    CHECK(!memcmp(b, "glTF", 4), "magic %.4s", (const char *)b);
    CHECK(rd_u32(b + 4) == 2, "version %u", rd_u32(b + 4));
    CHECK(rd_u32(b + 8) == len, "header length %u, file %zu", rd_u32(b + 8), len);
    CHECK(len % 4 == 0, "file length %zu not 4-aligned", len);
    uint32_t jlen = rd_u32(b + 12);
    CHECK(!memcmp(b + 16, "JSON", 4), "chunk 0 type %.4s", (const char *)b + 16);
    CHECK(jlen % 4 == 0 && 20 + (size_t)jlen + 8 <= len, "json chunk length %u", jlen);
    if (jlen % 4 || 20 + (size_t)jlen + 8 > len) {
        free(b);
        return;
    }
    const unsigned char *bc = b + 20 + jlen;
    uint32_t blen = rd_u32(bc);
    CHECK(!memcmp(bc + 4, "BIN\0", 4), "chunk 1 type");
    CHECK(blen % 4 == 0 && 20 + (size_t)jlen + 8 + blen == len, "bin chunk length %u", blen);
    cJSON *j = cJSON_ParseWithLength((const char *)b + 20, jlen);
    CHECK(j != NULL, "JSON chunk does not parse");
    if (j) {
        const cJSON *asset = cJSON_GetObjectItem(j, "asset");
        CHECK(cJSON_IsString(cJSON_GetObjectItem(asset, "version")) &&
                  !strcmp(cJSON_GetObjectItem(asset, "version")->valuestring, "2.0"),
              "asset.version");
        const cJSON *buffers = cJSON_GetObjectItem(j, "buffers");
        CHECK(cJSON_GetArraySize(buffers) == 1 &&
                  cJSON_GetObjectItem(cJSON_GetArrayItem(buffers, 0), "byteLength")->valuedouble <= blen,
              "buffers[0].byteLength");
        const cJSON *accessors = cJSON_GetObjectItem(j, "accessors");
        const cJSON *prims = cJSON_GetObjectItem(cJSON_GetArrayItem(cJSON_GetObjectItem(j, "meshes"), 0), "primitives");
        CHECK(cJSON_GetArraySize(prims) == 4, "%d primitives (one per used material)", cJSON_GetArraySize(prims));
        /* the union of POSITION min/max is the scene bounds; each accessor is exact for its data */
        float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        uint32_t tris = 0;
        const cJSON *prim;
        cJSON_ArrayForEach(prim, prims) {
            const cJSON *attrs = cJSON_GetObjectItem(prim, "attributes");
            int pa = cJSON_GetObjectItem(attrs, "POSITION")->valueint;
            CHECK(cJSON_GetObjectItem(attrs, "NORMAL") && cJSON_GetObjectItem(attrs, "TEXCOORD_0") &&
                      cJSON_GetObjectItem(attrs, "TEXCOORD_1"),
                  "attributes NORMAL/TEXCOORD_0/TEXCOORD_1");
            const cJSON *acc = cJSON_GetArrayItem(accessors, pa);
            const cJSON *mn = cJSON_GetObjectItem(acc, "min"), *mx = cJSON_GetObjectItem(acc, "max");
            CHECK(cJSON_GetArraySize(mn) == 3 && cJSON_GetArraySize(mx) == 3, "POSITION min/max");
            /* verify min/max against the actual data in the BIN chunk */
            const cJSON *view = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "bufferViews"),
                                                   cJSON_GetObjectItem(acc, "bufferView")->valueint);
            size_t off = (size_t)cJSON_GetObjectItem(view, "byteOffset")->valuedouble;
            int count = cJSON_GetObjectItem(acc, "count")->valueint;
            float dlo[3] = {INFINITY, INFINITY, INFINITY}, dhi[3] = {-INFINITY, -INFINITY, -INFINITY};
            for (int i = 0; i < count && off + 12 * (size_t)count <= blen; i++)
                for (int c = 0; c < 3; c++) {
                    float v;
                    memcpy(&v, bc + 8 + off + 12 * (size_t)i + 4 * c, 4);
                    dlo[c] = fminf(dlo[c], v), dhi[c] = fmaxf(dhi[c], v);
                }
            for (int c = 0; c < 3; c++) {
                CHECK((float)cJSON_GetArrayItem(mn, c)->valuedouble == dlo[c], "min[%d] %g vs data %g", c,
                      cJSON_GetArrayItem(mn, c)->valuedouble, dlo[c]);
                CHECK((float)cJSON_GetArrayItem(mx, c)->valuedouble == dhi[c], "max[%d]", c);
                lo[c] = fminf(lo[c], dlo[c]), hi[c] = fmaxf(hi[c], dhi[c]);
            }
            const cJSON *ia = cJSON_GetArrayItem(accessors, cJSON_GetObjectItem(prim, "indices")->valueint);
            CHECK(cJSON_GetObjectItem(ia, "componentType")->valueint == 5125, "indices UNSIGNED_INT");
            tris += (uint32_t)cJSON_GetObjectItem(ia, "count")->valueint / 3;
        }
        CHECK(tris == src->mesh.n_triangles, "%u triangles in JSON", tris);
        for (int c = 0; c < 3; c++) {
            CHECK(lo[c] == src->bounds_min[c], "bounds min[%d]", c);
            CHECK(hi[c] == src->bounds_max[c], "bounds max[%d]", c);
        }
        /* the light (Ke 17,12,4) needs the emissive strength extension */
        const cJSON *mats = cJSON_GetObjectItem(j, "materials"), *mat;
        int found_light = 0;
        cJSON_ArrayForEach(mat, mats) {
            const cJSON *name = cJSON_GetObjectItem(mat, "name");
            const cJSON *pbr = cJSON_GetObjectItem(mat, "pbrMetallicRoughness");
            CHECK(cJSON_GetObjectItem(pbr, "metallicFactor")->valuedouble == 0, "metallic 0");
            CHECK(cJSON_GetObjectItem(pbr, "roughnessFactor")->valuedouble == 1, "roughness 1");
            CHECK(cJSON_IsFalse(cJSON_GetObjectItem(mat, "doubleSided")), "doubleSided false");
            if (!cJSON_IsString(name) || strcmp(name->valuestring, "light")) continue;
            found_light = 1;
            const cJSON *ef = cJSON_GetObjectItem(mat, "emissiveFactor");
            CHECK_NEAR(cJSON_GetArrayItem(ef, 0)->valuedouble, 1.0, 1e-6);
            CHECK_NEAR(cJSON_GetArrayItem(ef, 1)->valuedouble, 12.0 / 17.0, 1e-6);
            const cJSON *es = cJSON_GetObjectItem(
                cJSON_GetObjectItem(cJSON_GetObjectItem(mat, "extensions"), "KHR_materials_emissive_strength"),
                "emissiveStrength");
            CHECK(cJSON_IsNumber(es) && fabs(es->valuedouble - 17) < 1e-5, "emissiveStrength");
        }
        CHECK(found_light, "light material in JSON");
        const cJSON *used = cJSON_GetObjectItem(j, "extensionsUsed");
        CHECK(cJSON_GetArraySize(used) == 1 &&
                  !strcmp(cJSON_GetArrayItem(used, 0)->valuestring, "KHR_materials_emissive_strength"),
              "extensionsUsed");
        cJSON_Delete(j);
    }
    free(b);
}

int main(void) {
    char cornell[512], err[512] = "";
    check_source_path("scenes/cornell-box/cornell-box.obj", cornell, sizeof cornell);
    lc_import_params prm = {1.0, 0};
    lc_scene s;
    if (lc_scene_import(cornell, &prm, &s, err, sizeof err) != 0) {
        fprintf(stderr, "FAIL cornell import: %s\n", err);
        return 1;
    }
    /* synthetic planar lightmap UVs (glTF convention) */
    s.mesh.uv1 = malloc((size_t)s.mesh.n_vertices * 2 * sizeof(float));
    if (!s.mesh.uv1) return 1;
    for (uint32_t v = 0; v < s.mesh.n_vertices; v++) planar_uv1(s.mesh.position + 3 * v, s.mesh.uv1 + 2 * v);
    s.has_lightmap_uv = 1;
    /* a 2x1 texture on "red": the GLB carries factor x texture mean (0.3, 0.5, 0.7) */
    lc_material *red = (lc_material *)find_material(&s, "red");
    CHECK(red != NULL && s.n_textures == 0, "red material");
    if (!red) return 1;
    s.textures = calloc(1, sizeof *s.textures);
    s.textures[0].width = 2, s.textures[0].height = 1;
    s.textures[0].rgb = malloc(6 * sizeof(float));
    const float texels[6] = {0.2f, 0.4f, 0.6f, 0.4f, 0.6f, 0.8f};
    memcpy(s.textures[0].rgb, texels, sizeof texels);
    snprintf(s.textures[0].path, sizeof s.textures[0].path, "synthetic");
    s.n_textures = 1;
    red->base_texture = 0;

    char dir[256], path[512];
    const char *base = getenv("TMPDIR");
    snprintf(dir, sizeof dir, "%s/lucent-test-glb-XXXXXX", base && *base ? base : "/tmp");
    if (!mkdtemp(dir)) {
        perror("mkdtemp");
        return 1;
    }
    snprintf(path, sizeof path, "%s/cornell.glb", dir);
    int rc = lc_glb_write(path, &s, err, sizeof err);
    CHECK(rc == 0, "glb write failed: %s", err);
    if (rc == 0) check_container(path, &s);

    lc_scene r;
    rc = rc ? -1 : lc_scene_import(path, &prm, &r, err, sizeof err);
    CHECK(rc == 0, "glb re-import failed: %s", err);
    if (rc == 0) {
        CHECK(r.mesh.n_triangles == s.mesh.n_triangles, "%u triangles, want %u", r.mesh.n_triangles,
              s.mesh.n_triangles);
        CHECK(r.has_lightmap_uv == 1 && r.mesh.uv1, "re-imported has_lightmap_uv %d", r.has_lightmap_uv);
        CHECK_NEAR(lc_mesh_total_area(&r.mesh), lc_mesh_total_area(&s.mesh), 1e-6);
        for (int c = 0; c < 3; c++) {
            CHECK_NEAR(r.bounds_min[c], s.bounds_min[c], 1e-7);
            CHECK_NEAR(r.bounds_max[c], s.bounds_max[c], 1e-7);
        }
        int bad_uv1 = 0, bad_uv0 = 0;
        for (uint32_t v = 0; r.mesh.uv1 && v < r.mesh.n_vertices; v++) {
            float want[2];
            planar_uv1(r.mesh.position + 3 * v, want);
            if (fabsf(r.mesh.uv1[2 * v] - want[0]) > 1e-6f || fabsf(r.mesh.uv1[2 * v + 1] - want[1]) > 1e-6f) {
                if (bad_uv1++ < 3)
                    fprintf(stderr, "uv1 of vertex %u: (%g, %g), want (%g, %g)\n", v, r.mesh.uv1[2 * v],
                            r.mesh.uv1[2 * v + 1], want[0], want[1]);
            }
            if (fabsf(r.mesh.uv0[2 * v]) > 1e-6f || fabsf(r.mesh.uv0[2 * v + 1]) > 1e-6f) bad_uv0++;
        }
        CHECK(bad_uv1 == 0, "%d vertices with wrong uv1", bad_uv1);
        CHECK(bad_uv0 == 0, "%d vertices with uv0 not preserved (OBJ had none: 0,0)", bad_uv0);
        /* normals survive: every re-imported triangle's shading normal agrees with its winding */
        int bad_n = 0;
        for (uint32_t t = 0; t < r.mesh.n_triangles; t++) {
            float g[3];
            lc_mesh_triangle_normal(&r.mesh, t, g);
            const float *n = r.mesh.normal + 3 * r.mesh.index[3 * t];
            bad_n += n[0] * g[0] + n[1] * g[1] + n[2] * g[2] < 0.999f;
        }
        CHECK(bad_n == 0, "%d triangles with normals against the winding", bad_n);
        CHECK(r.n_materials >= s.n_materials, "%u materials, want at least %u", r.n_materials, s.n_materials);
        const char *names[4] = {"white", "red", "green", "light"};
        for (int i = 0; i < 4; i++) {
            const lc_material *a = find_material(&s, names[i]), *b = find_material(&r, names[i]);
            CHECK(a && b, "material %s round trip", names[i]);
            if (!a || !b) continue;
            float want[3] = {a->base_color[0], a->base_color[1], a->base_color[2]};
            if (a == red)
                for (int c = 0; c < 3; c++) want[c] *= (texels[c] + texels[3 + c]) / 2;
            for (int c = 0; c < 3; c++) {
                CHECK_NEAR(b->base_color[c], want[c], 1e-6);
                CHECK_NEAR(b->emission[c], a->emission[c], 1e-5);
            }
            CHECK(b->base_texture == -1, "%s: no embedded image", names[i]);
        }
        /* per-triangle material assignment survives: emitted area is the light quad's */
        double light_area = 0;
        for (uint32_t t = 0; t < r.mesh.n_triangles; t++) {
            float e[3];
            lc_scene_emission(&r, t, e);
            if (e[0] > 0) light_area += lc_mesh_triangle_area(&r.mesh, t);
        }
        CHECK_NEAR(light_area, 0.13 * 0.105, 1e-6);
        lc_scene_release(&r);
    }

    /* failure path: an unwritable destination reports, does not crash */
    char bad[600];
    snprintf(bad, sizeof bad, "%s/no/such/dir/x.glb", dir);
    err[0] = '\0';
    CHECK(lc_glb_write(bad, &s, err, sizeof err) == -1 && err[0], "write to a missing directory must fail");
    lc_scene_release(&s);
    nftw(dir, rm_entry, 8, FTW_DEPTH | FTW_PHYS);
    CHECK_DONE();
}
