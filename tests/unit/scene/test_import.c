/* test_import: lc_scene_import on the Cornell box, generated glTF / PLY / OBJ+texture files,
 * Sponza (when ../shared has it) and malformed inputs. */
#include <ftw.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bake/image.h"
#include "bake/scene.h"
#include "check.h"

static char tmpdir[256];

static int rm_entry(const char *p, const struct stat *st, int flag, struct FTW *ftw) {
    (void)st, (void)flag, (void)ftw;
    return remove(p);
}

static const char *tmp_path(const char *name, char *buf, size_t len) {
    snprintf(buf, len, "%s/%s", tmpdir, name);
    return buf;
}

static int write_file(const char *name, const void *data, size_t len) {
    char p[512];
    FILE *f = fopen(tmp_path(name, p, sizeof p), "wb");
    if (!f) return -1;
    size_t w = len ? fwrite(data, 1, len, f) : 0;
    fclose(f);
    return w == len ? 0 : -1;
}

static int write_text(const char *name, const char *text) { return write_file(name, text, strlen(text)); }

static const lc_material *find_material(const lc_scene *s, const char *name) {
    for (uint32_t i = 0; i < s->n_materials; i++)
        if (!strcmp(s->materials[i].name, name)) return &s->materials[i];
    return NULL;
}

static const lc_light *find_light(const lc_scene *s, const char *name) {
    for (uint32_t i = 0; i < s->n_lights; i++)
        if (!strcmp(s->lights[i].name, name)) return &s->lights[i];
    return NULL;
}

static double srgb_decode(double c) { return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4); }

/* Sum of the OBJ's polygon areas (Newell's formula: independent of how it is triangulated). */
static double obj_polygon_area(const char *path, int *n_faces) {
    FILE *f = fopen(path, "r");
    if (!f) return -1;
    static double v[1024][3];
    int nv = 0;
    double total = 0;
    *n_faces = 0;
    char line[512];
    while (fgets(line, sizeof line, f)) {
        if (line[0] == 'v' && line[1] == ' ' && nv < 1024) {
            sscanf(line + 2, "%lf %lf %lf", &v[nv][0], &v[nv][1], &v[nv][2]);
            nv++;
        } else if (line[0] == 'f' && line[1] == ' ') {
            int idx[16], n = 0, off = 2, used;
            while (n < 16 && sscanf(line + off, "%d%n", &idx[n], &used) == 1) n++, off += used;
            double s[3] = {0, 0, 0};
            for (int i = 0; i < n; i++) {
                const double *a = v[idx[i] - 1], *b = v[idx[(i + 1) % n] - 1];
                s[0] += a[1] * b[2] - a[2] * b[1];
                s[1] += a[2] * b[0] - a[0] * b[2];
                s[2] += a[0] * b[1] - a[1] * b[0];
            }
            total += 0.5 * sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
            (*n_faces)++;
        }
    }
    fclose(f);
    return total;
}

static void test_cornell(void) {
    char path[512], err[512] = "";
    check_source_path("scenes/cornell-box/cornell-box.obj", path, sizeof path);
    lc_import_params prm = {1.0, 0};
    lc_scene s;
    int rc = lc_scene_import(path, &prm, &s, err, sizeof err);
    CHECK(rc == 0, "cornell import failed: %s", err);
    if (rc) return;
    int quads = 0;
    double area = obj_polygon_area(path, &quads);
    CHECK(quads == 19, "OBJ has %d faces", quads);
    CHECK(s.mesh.n_triangles == 38, "%u triangles", s.mesh.n_triangles);
    CHECK(s.n_degenerate_dropped == 0, "%u dropped", s.n_degenerate_dropped);
    CHECK(s.n_materials == 5, "%u materials", s.n_materials);
    CHECK(!s.has_lightmap_uv && s.mesh.uv1 == NULL, "OBJ has no second UV set");
    CHECK(s.n_lights == 0, "%u lights", s.n_lights);
    CHECK(!strcmp(s.source, path), "source '%s'", s.source);
    const lc_material *light = find_material(&s, "light"), *white = find_material(&s, "white");
    const lc_material *red = find_material(&s, "red");
    CHECK(light && white && red, "materials light/white/red present");
    if (light) {
        CHECK_NEAR(light->emission[0], 17, 1e-6);
        CHECK_NEAR(light->emission[1], 12, 1e-6);
        CHECK_NEAR(light->emission[2], 4, 1e-6);
        CHECK(light->base_texture == -1, "light has no texture");
    }
    if (white) {
        CHECK_NEAR(white->base_color[0], 0.725, 1e-6);
        CHECK_NEAR(white->base_color[2], 0.68, 1e-6);
        CHECK(white->emission[0] == 0 && white->emission[1] == 0 && white->emission[2] == 0, "white emits");
    }
    if (red) CHECK_NEAR(red->base_color[1], 0.065, 1e-6);
    float lo[3] = {0, 0, 0}, hi[3] = {0.556f, 0.5488f, 0.5592f};
    for (int c = 0; c < 3; c++) {
        CHECK_NEAR(s.bounds_min[c], lo[c], 1e-6);
        CHECK_NEAR(s.bounds_max[c], hi[c], 1e-6);
    }
    double got = lc_mesh_total_area(&s.mesh);
    CHECK(fabs(got - area) <= 1e-4 * area, "area %.9g vs analytic %.9g", got, area);

    /* normals: unit, agreeing with the winding, and facing the room's air */
    const double blocks[2][6] = {{0.265, 0, 0.247, 0.472, 0.33, 0.456}, {0.082, 0, 0.065, 0.29, 0.165, 0.272}};
    int bad_unit = 0, bad_dir = 0, floor_tris = 0;
    for (uint32_t t = 0; t < s.mesh.n_triangles; t++) {
        double c[3] = {0, 0, 0}, n[3] = {0, 0, 0};
        float g[3];
        lc_mesh_triangle_normal(&s.mesh, t, g);
        for (int k = 0; k < 3; k++) {
            uint32_t v = s.mesh.index[3 * t + k];
            const float *vn = s.mesh.normal + 3 * v;
            double len = sqrt(vn[0] * vn[0] + vn[1] * vn[1] + vn[2] * vn[2]);
            if (fabs(len - 1) > 1e-4) bad_unit++;
            if (vn[0] * g[0] + vn[1] * g[1] + vn[2] * g[2] < 0.99) bad_dir++;
            for (int a = 0; a < 3; a++) c[a] += s.mesh.position[3 * v + a] / 3.0, n[a] += vn[a];
        }
        double ref[3] = {0.278 - c[0], 0.2744 - c[1], 0.2796 - c[2]}; /* towards the room centre */
        for (int b = 0; b < 2; b++) {
            const double *bb = blocks[b];
            if (c[0] > bb[0] - 1e-4 && c[0] < bb[3] + 1e-4 && c[1] > bb[1] + 1e-4 && c[1] < bb[4] + 1e-4 &&
                c[2] > bb[2] - 1e-4 && c[2] < bb[5] + 1e-4) {
                /* a block face: away from the block's centre */
                ref[0] = c[0] - 0.5 * (bb[0] + bb[3]);
                ref[1] = c[1] - 0.5 * (bb[1] + bb[4]);
                ref[2] = c[2] - 0.5 * (bb[2] + bb[5]);
                break;
            }
        }
        if (n[0] * ref[0] + n[1] * ref[1] + n[2] * ref[2] <= 0) bad_dir++;
        if (fabs(c[1]) < 1e-9) {
            floor_tris++;
            CHECK(n[1] / 3 > 0.9999, "floor triangle %u normal y %g", t, n[1] / 3);
        }
    }
    CHECK(bad_unit == 0, "%d non-unit normals", bad_unit);
    CHECK(bad_dir == 0, "%d normals facing away from the room / against the winding", bad_dir);
    CHECK(floor_tris == 2, "%d floor triangles", floor_tris);
    for (uint32_t t = 0; t < s.mesh.n_triangles; t++)
        CHECK(s.mesh.material[t] < s.n_materials, "triangle %u material %u", t, s.mesh.material[t]);

    /* scale multiplies positions; flip_winding reverses triangles and their normals */
    lc_scene s2;
    prm.scale = 2.0;
    prm.flip_winding = 1;
    rc = lc_scene_import(path, &prm, &s2, err, sizeof err);
    CHECK(rc == 0, "scaled import failed: %s", err);
    if (rc == 0) {
        CHECK_NEAR(s2.bounds_max[0], 2 * 0.556, 1e-6);
        CHECK_NEAR(lc_mesh_total_area(&s2.mesh), 4 * got, 1e-6);
        int agree = 0;
        for (uint32_t t = 0; t < s2.mesh.n_triangles; t++) {
            float g[3];
            lc_mesh_triangle_normal(&s2.mesh, t, g);
            const float *vn = s2.mesh.normal + 3 * s2.mesh.index[3 * t];
            agree += vn[0] * g[0] + vn[1] * g[1] + vn[2] * g[2] > 0.99f;
            if (fabs(s2.mesh.position[3 * s2.mesh.index[3 * t] + 1]) < 1e-9 &&
                fabs(s2.mesh.position[3 * s2.mesh.index[3 * t + 1] + 1]) < 1e-9 &&
                fabs(s2.mesh.position[3 * s2.mesh.index[3 * t + 2] + 1]) < 1e-9)
                CHECK(g[1] < -0.999f && vn[1] < -0.999f, "flipped floor normal %g / %g", g[1], vn[1]);
        }
        CHECK(agree == (int)s2.mesh.n_triangles, "%d of %u flipped normals agree with the winding", agree,
              s2.mesh.n_triangles);
        lc_scene_release(&s2);
    }
    lc_scene_release(&s);
}

/* ---- glTF with KHR_lights_punctual, emissive strength and a second UV set ---- */
static const float quad_pos[4][3] = {{0, 0, 0}, {0, 0, 1}, {1, 0, 1}, {1, 0, 0}};
static const float quad_uv0[4][2] = {{0, 0}, {0, 1}, {1, 1}, {1, 0}};
static const float quad_uv1[4][2] = {{0.1f, 0.2f}, {0.1f, 0.7f}, {0.6f, 0.7f}, {0.6f, 0.2f}};

static char *base64(const unsigned char *d, size_t n) {
    static const char t[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    char *o = malloc(4 * ((n + 2) / 3) + 1), *p = o;
    if (!o) return NULL;
    for (size_t i = 0; i < n; i += 3) {
        uint32_t v = (uint32_t)d[i] << 16 | (i + 1 < n ? (uint32_t)d[i + 1] << 8 : 0) | (i + 2 < n ? d[i + 2] : 0);
        *p++ = t[v >> 18 & 63], *p++ = t[v >> 12 & 63];
        *p++ = i + 1 < n ? t[v >> 6 & 63] : '=';
        *p++ = i + 2 < n ? t[v & 63] : '=';
    }
    *p = '\0';
    return o;
}

/* A 1x1 PNG (200,100,50) as base64, for a glTF data-URI image (Assimp embeds it as "*0"). */
static char *embedded_png_b64(void) {
    char p[512], err[256];
    const float px[3] = {200 / 255.0f, 100 / 255.0f, 50 / 255.0f};
    if (lc_image_write(tmp_path("embed.png", p, sizeof p), 1, 1, 3, px, err, sizeof err) < 0) return NULL;
    FILE *f = fopen(p, "rb");
    if (!f) return NULL;
    unsigned char buf[4096];
    size_t n = fread(buf, 1, sizeof buf, f);
    fclose(f);
    remove(p);
    return base64(buf, n);
}

static void test_gltf(void) {
    unsigned char bin[184];
    size_t o = 0;
    const float nrm[3] = {0, 1, 0};
    const uint32_t idx[6] = {0, 1, 2, 0, 2, 3};
    for (int i = 0; i < 4; i++) memcpy(bin + o, quad_pos[i], 12), o += 12;
    for (int i = 0; i < 4; i++) memcpy(bin + o, nrm, 12), o += 12;
    for (int i = 0; i < 4; i++) memcpy(bin + o, quad_uv0[i], 8), o += 8;
    for (int i = 0; i < 4; i++) memcpy(bin + o, quad_uv1[i], 8), o += 8;
    memcpy(bin + o, idx, 24), o += 24;
    CHECK(o == sizeof bin, "bin size %zu", o);
    CHECK(write_file("quad.bin", bin, o) == 0, "write quad.bin");
    const char *gltf =
        "{\"asset\":{\"version\":\"2.0\"},"
        "\"extensionsUsed\":[\"KHR_lights_punctual\",\"KHR_materials_emissive_strength\"],"
        "\"extensions\":{\"KHR_lights_punctual\":{\"lights\":["
        "{\"type\":\"point\",\"color\":[1,0.5,0.25],\"intensity\":10,\"range\":7},"
        "{\"type\":\"spot\",\"intensity\":50,\"spot\":{\"innerConeAngle\":0.3,\"outerConeAngle\":0.6}},"
        "{\"type\":\"directional\",\"color\":[0.5,0.5,0.4],\"intensity\":6}]}},"
        "\"scene\":0,\"scenes\":[{\"nodes\":[0,1,2,3]}],"
        "\"nodes\":[{\"name\":\"quadnode\",\"mesh\":0,\"translation\":[0,2,0]},"
        "{\"name\":\"PointNode\",\"translation\":[1,2,3],\"extensions\":{\"KHR_lights_punctual\":{\"light\":0}}},"
        "{\"name\":\"SpotNode\",\"translation\":[0,3,0],\"rotation\":[-0.70710678,0,0,0.70710678],"
        "\"extensions\":{\"KHR_lights_punctual\":{\"light\":1}}},"
        "{\"name\":\"SunNode\",\"rotation\":[-0.38268343,0,0,0.92387953],"
        "\"extensions\":{\"KHR_lights_punctual\":{\"light\":2}}}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"NORMAL\":1,\"TEXCOORD_0\":2,\"TEXCOORD_1\":3},"
        "\"indices\":4,\"material\":1}]}],"
        /* materials[0] is unused: Assimp drops it, so matching strength by index would be wrong */
        "\"materials\":[{\"name\":\"dim\",\"emissiveFactor\":[1,0.5,0.25],"
        "\"extensions\":{\"KHR_materials_emissive_strength\":{\"emissiveStrength\":9}}},"
        "{\"name\":\"glow\",\"pbrMetallicRoughness\":{\"baseColorFactor\":[0.5,0.25,0.125,1],"
        "\"baseColorTexture\":{\"index\":0}},"
        "\"emissiveFactor\":[1,0.5,0.25],\"extensions\":{\"KHR_materials_emissive_strength\":{\"emissiveStrength\":4}}}],"
        "\"buffers\":[{\"uri\":\"quad.bin\",\"byteLength\":184}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":0,\"byteLength\":48},{\"buffer\":0,\"byteOffset\":48,\"byteLength\":48},"
        "{\"buffer\":0,\"byteOffset\":96,\"byteLength\":32},{\"buffer\":0,\"byteOffset\":128,\"byteLength\":32},"
        "{\"buffer\":0,\"byteOffset\":160,\"byteLength\":24}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[1,0,1]},"
        "{\"bufferView\":1,\"componentType\":5126,\"count\":4,\"type\":\"VEC3\"},"
        "{\"bufferView\":2,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"},"
        "{\"bufferView\":3,\"componentType\":5126,\"count\":4,\"type\":\"VEC2\"},"
        "{\"bufferView\":4,\"componentType\":5125,\"count\":6,\"type\":\"SCALAR\"}]}";
    /* the material gets an embedded base colour texture: splice textures/images in */
    char *b64 = embedded_png_b64();
    CHECK(b64 != NULL, "embedded png");
    size_t cap = strlen(gltf) + (b64 ? strlen(b64) : 0) + 256;
    char *doc = malloc(cap);
    const char *tail = strrchr(gltf, '}');
    snprintf(doc, cap, "%.*s,\"textures\":[{\"source\":0}],\"images\":[{\"uri\":\"data:image/png;base64,%s\"}]}",
             (int)(tail - gltf), gltf, b64 ? b64 : "");
    CHECK(write_text("quad.gltf", doc) == 0, "write quad.gltf");
    free(doc);
    free(b64);
    char path[512], err[512] = "";
    lc_import_params prm = {2.0, 0};
    lc_scene s;
    int rc = lc_scene_import(tmp_path("quad.gltf", path, sizeof path), &prm, &s, err, sizeof err);
    CHECK(rc == 0, "gltf import failed: %s", err);
    if (rc) return;
    CHECK(s.mesh.n_triangles == 2 && s.mesh.n_vertices == 4, "%u tris %u verts", s.mesh.n_triangles, s.mesh.n_vertices);
    CHECK(s.has_lightmap_uv == 1 && s.mesh.uv1, "has_lightmap_uv %d", s.has_lightmap_uv);
    int matched = 0;
    for (uint32_t v = 0; v < s.mesh.n_vertices; v++) {
        const float *p = s.mesh.position + 3 * v;
        CHECK_NEAR(p[1], 4.0, 1e-6); /* node translation 2, scale 2 */
        CHECK_NEAR(s.mesh.normal[3 * v + 1], 1.0, 1e-6);
        for (int i = 0; i < 4; i++) {
            if (fabsf(p[0] - 2 * quad_pos[i][0]) > 1e-5f || fabsf(p[2] - 2 * quad_pos[i][2]) > 1e-5f) continue;
            matched++;
            CHECK_NEAR(s.mesh.uv0[2 * v], quad_uv0[i][0], 1e-6);
            CHECK_NEAR(s.mesh.uv0[2 * v + 1], 1.0 - quad_uv0[i][1], 1e-6); /* OpenGL convention */
            if (s.mesh.uv1) {
                CHECK_NEAR(s.mesh.uv1[2 * v], quad_uv1[i][0], 1e-6);
                CHECK_NEAR(s.mesh.uv1[2 * v + 1], quad_uv1[i][1], 1e-6); /* glTF convention, as written */
            }
        }
    }
    CHECK(matched == 4, "%d vertices matched", matched);
    for (uint32_t t = 0; t < s.mesh.n_triangles; t++) {
        float g[3];
        lc_mesh_triangle_normal(&s.mesh, t, g);
        CHECK(g[1] > 0.999f, "winding normal y %g", g[1]);
    }
    CHECK_NEAR(s.bounds_min[1], 4.0, 1e-6);
    CHECK_NEAR(s.bounds_max[0], 2.0, 1e-6);
    const lc_material *glow = find_material(&s, "glow");
    CHECK(glow != NULL, "material glow");
    if (glow) {
        CHECK_NEAR(glow->base_color[0], 0.5, 1e-6);
        CHECK_NEAR(glow->base_color[1], 0.25, 1e-6);
        CHECK_NEAR(glow->emission[0], 4.0, 1e-6);
        CHECK_NEAR(glow->emission[1], 2.0, 1e-6);
        CHECK_NEAR(glow->emission[2], 1.0, 1e-6);
        float e[3];
        lc_scene_emission(&s, 0, e);
        CHECK_NEAR(e[0], 4.0, 1e-6);
        /* embedded texture decoded (sRGB -> linear) and multiplied by the factor */
        CHECK(glow->base_texture >= 0 && s.n_textures == 1, "embedded texture %d (%u)", glow->base_texture,
              s.n_textures);
        float a[3];
        lc_scene_albedo(&s, 0, 0.3f, 0.3f, a);
        CHECK_NEAR(a[0], 0.5 * srgb_decode(200 / 255.0), 2e-5);
        CHECK_NEAR(a[1], 0.25 * srgb_decode(100 / 255.0), 2e-5);
        CHECK_NEAR(a[2], 0.125 * srgb_decode(50 / 255.0), 2e-5);
    }
    CHECK(s.n_lights == 3, "%u lights", s.n_lights);
    const lc_light *pt = find_light(&s, "PointNode"), *spot = find_light(&s, "SpotNode"),
                   *sun = find_light(&s, "SunNode");
    CHECK(pt && spot && sun, "lights found by node name");
    if (pt) {
        CHECK(pt->type == LC_LIGHT_POINT, "point type %d", pt->type);
        CHECK_NEAR(pt->position[0], 2, 1e-5);
        CHECK_NEAR(pt->position[1], 4, 1e-5);
        CHECK_NEAR(pt->position[2], 6, 1e-5);
        CHECK_NEAR(pt->intensity, 10, 1e-5);
        CHECK_NEAR(pt->color[0], 1, 1e-6);
        CHECK_NEAR(pt->color[1], 0.5, 1e-6);
        CHECK_NEAR(pt->color[2], 0.25, 1e-6);
        CHECK_NEAR(pt->range, 14, 1e-5);
    }
    if (spot) {
        CHECK(spot->type == LC_LIGHT_SPOT, "spot type %d", spot->type);
        CHECK_NEAR(spot->position[1], 6, 1e-5);
        CHECK_NEAR(spot->direction[0], 0, 1e-5);
        CHECK_NEAR(spot->direction[1], -1, 1e-5);
        CHECK_NEAR(spot->direction[2], 0, 1e-5);
        CHECK_NEAR(spot->inner_cone, 0.3, 1e-6);
        CHECK_NEAR(spot->outer_cone, 0.6, 1e-6);
        CHECK_NEAR(spot->intensity, 50, 1e-5);
        CHECK_NEAR(spot->color[1], 1, 1e-6);
        CHECK(spot->range == 0, "spot range %g", spot->range);
    }
    if (sun) {
        CHECK(sun->type == LC_LIGHT_DIRECTIONAL, "sun type %d", sun->type);
        CHECK_NEAR(sun->direction[0], 0, 1e-5);
        CHECK_NEAR(sun->direction[1], -0.70710678, 1e-5);
        CHECK_NEAR(sun->direction[2], -0.70710678, 1e-5);
        CHECK_NEAR(sun->intensity, 3, 1e-5); /* colour (0.5,0.5,0.4) x 6 = (1,1,0.8) x 3 */
        CHECK_NEAR(sun->color[2], 0.8, 1e-6);
    }
    lc_scene_release(&s);
}

static void test_ply(void) {
    const char *ply = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
                      "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
    CHECK(write_text("quad.ply", ply) == 0, "write quad.ply");
    char path[512], err[512] = "";
    lc_import_params prm = {1.0, 0};
    lc_scene s;
    int rc = lc_scene_import(tmp_path("quad.ply", path, sizeof path), &prm, &s, err, sizeof err);
    CHECK(rc == 0, "ply import failed: %s", err);
    if (rc) return;
    CHECK(s.mesh.n_triangles == 2 && s.mesh.n_vertices == 4, "%u tris %u verts", s.mesh.n_triangles, s.mesh.n_vertices);
    CHECK_NEAR(lc_mesh_total_area(&s.mesh), 1.0, 1e-6);
    CHECK(s.n_materials >= 1 && !s.has_lightmap_uv, "materials %u", s.n_materials);
    for (uint32_t v = 0; v < s.mesh.n_vertices; v++) CHECK_NEAR(s.mesh.normal[3 * v + 2], 1.0, 1e-5);
    lc_scene_release(&s);
    /* flip_winding turns the faces and their (generated) normals over */
    prm.flip_winding = 1;
    rc = lc_scene_import(path, &prm, &s, err, sizeof err);
    CHECK(rc == 0, "flipped ply import failed: %s", err);
    if (rc) return;
    float g[3];
    lc_mesh_triangle_normal(&s.mesh, 0, g);
    CHECK(g[2] < -0.999f, "flipped winding normal z %g", g[2]);
    for (uint32_t v = 0; v < s.mesh.n_vertices; v++) CHECK_NEAR(s.mesh.normal[3 * v + 2], -1.0, 1e-5);
    lc_scene_release(&s);
}

/* Finds barycentrics of uv0 target inside some triangle; returns the triangle or -1. */
static int64_t locate_uv(const lc_mesh *m, float tu, float tv, float *b1, float *b2) {
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        const uint32_t *ix = m->index + 3 * t;
        double u0 = m->uv0[2 * ix[0]], v0 = m->uv0[2 * ix[0] + 1];
        double e1u = m->uv0[2 * ix[1]] - u0, e1v = m->uv0[2 * ix[1] + 1] - v0;
        double e2u = m->uv0[2 * ix[2]] - u0, e2v = m->uv0[2 * ix[2] + 1] - v0;
        double det = e1u * e2v - e2u * e1v;
        if (fabs(det) < 1e-12) continue;
        double x = ((tu - u0) * e2v - e2u * (tv - v0)) / det, y = (e1u * (tv - v0) - (tu - u0) * e1v) / det;
        if (x >= -1e-9 && y >= -1e-9 && x + y <= 1 + 1e-9) {
            *b1 = (float)x, *b2 = (float)y;
            return t;
        }
    }
    return -1;
}

static void test_texture(void) {
    char dir[512], path[512], err[512] = "";
    CHECK(mkdir(tmp_path("Textures", dir, sizeof dir), 0755) == 0, "mkdir Textures");
    /* 2x2: row 0 is the top of the image (v = 1 in OpenGL convention) */
    const int k[4][3] = {{200, 100, 50}, {10, 20, 30}, {255, 128, 0}, {60, 180, 240}};
    float px[12];
    for (int i = 0; i < 4; i++)
        for (int c = 0; c < 3; c++) px[3 * i + c] = k[i][c] / 255.0f;
    int rc = lc_image_write(tmp_path("Textures/TEX.PNG", path, sizeof path), 2, 2, 3, px, err, sizeof err);
    CHECK(rc == 0, "png write failed: %s", err);
    CHECK(write_text("tex.mtl",
                     "newmtl tex\nKd 0.5 0.8 1.0\nmap_Kd textures\\tex.png\n"
                     "newmtl gone\nKd 0.3 0.3 0.3\nmap_Kd missing.png\n") == 0,
          "write mtl");
    CHECK(write_text("tex.obj",
                     "mtllib tex.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                     "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl tex\nf 1/1 2/2 3/3 4/4\n"
                     "v 0 0 1\nv 1 0 1\nv 1 1 1\nusemtl gone\nf 5/1 6/2 7/3\n") == 0,
          "write obj");
    lc_import_params prm = {1.0, 0};
    lc_scene s;
    rc = lc_scene_import(tmp_path("tex.obj", path, sizeof path), &prm, &s, err, sizeof err);
    CHECK(rc == 0, "textured import failed: %s", err);
    if (rc) return;
    const lc_material *tex = find_material(&s, "tex"), *gone = find_material(&s, "gone");
    CHECK(tex && gone, "materials tex/gone");
    CHECK(s.n_textures == 1, "%u textures", s.n_textures);
    if (!tex || !gone || s.n_textures != 1) goto done;
    CHECK(tex->base_texture == 0, "tex texture %d", tex->base_texture);
    CHECK(gone->base_texture == -1, "missing texture keeps the factor only (%d)", gone->base_texture);
    CHECK(strstr(s.textures[0].path, "Textures/TEX.PNG") != NULL, "resolved path '%s'", s.textures[0].path);
    CHECK(s.textures[0].width == 2 && s.textures[0].height == 2, "%ux%u", s.textures[0].width, s.textures[0].height);
    /* texel centres: (u, v) = ((col + 0.5) / 2, 1 - (row + 0.5) / 2) */
    const float kd[3] = {0.5f, 0.8f, 1.0f};
    for (int i = 0; i < 4; i++) {
        int row = i / 2, col = i % 2;
        float b1 = 0, b2 = 0;
        int64_t t = locate_uv(&s.mesh, (col + 0.5f) / 2, 1.0f - (row + 0.5f) / 2, &b1, &b2);
        CHECK(t >= 0, "uv of texel %d not found", i);
        if (t < 0 || s.mesh.material[t] != (uint32_t)(tex - s.materials)) continue;
        float a[3];
        lc_scene_albedo(&s, (uint32_t)t, b1, b2, a);
        for (int c = 0; c < 3; c++) {
            double want = fmin(kd[c] * srgb_decode(k[i][c] / 255.0), 0.99);
            CHECK(fabs(a[c] - want) < 2e-5, "texel %d channel %d: albedo %.7f, want %.7f", i, c, a[c], want);
        }
    }
done:
    lc_scene_release(&s);
}

/* Material names go to every client: a Latin-1 .mtl name gets U+FFFD for its bad bytes, a
 * long name is cut on a character boundary, UTF-8 names stay as they are (issue 13). */
static void test_names(void) {
    char path[512], err[512] = "", longname[80];
    memset(longname, 'a', 62);
    strcpy(longname + 62, "\xc3\xa9"); /* 64 bytes: é straddles the 63-byte field */
    char mtl[512];
    snprintf(mtl, sizeof mtl,
             "newmtl caf\xe9\nKd 0.5 0.5 0.5\n"
             "newmtl %s\nKd 0.2 0.2 0.2\n"
             "newmtl caf\xc3\xa9\nKd 0.7 0.7 0.7\n",
             longname);
    CHECK(write_text("names.mtl", mtl) == 0, "write mtl");
    char obj[1024];
    snprintf(obj, sizeof obj,
             "mtllib names.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\n"
             "usemtl caf\xe9\nf 1 2 3\nusemtl %s\nf 1 3 4\nusemtl caf\xc3\xa9\nf 5 6 7\n",
             longname);
    CHECK(write_text("names.obj", obj) == 0, "write obj");
    lc_import_params prm = {1.0, 0};
    lc_scene s;
    int rc = lc_scene_import(tmp_path("names.obj", path, sizeof path), &prm, &s, err, sizeof err);
    CHECK(rc == 0, "names import failed: %s", err);
    if (rc) return;
    CHECK(find_material(&s, "caf\xef\xbf\xbd") != NULL, "Latin-1 name with U+FFFD");
    CHECK(find_material(&s, "caf\xc3\xa9") != NULL, "UTF-8 name kept");
    char cut[64];
    memset(cut, 'a', 62);
    cut[62] = 0;
    CHECK(find_material(&s, cut) != NULL, "long name cut before the é");
    for (uint32_t i = 0; i < s.n_materials; i++) {
        const unsigned char *n = (const unsigned char *)s.materials[i].name;
        int ascii_or_known = 1;
        for (size_t k = 0; n[k]; k++) /* only ASCII, é and U+FFFD here */
            if (n[k] >= 0x80 && !(n[k] == 0xc3 && n[k + 1] == 0xa9) &&
                !(n[k] == 0xef && n[k + 1] == 0xbf && n[k + 2] == 0xbd))
                ascii_or_known = 0;
            else if (n[k] >= 0x80) k += n[k] == 0xc3 ? 1 : 2;
        CHECK(ascii_or_known, "material %u name '%s' has stray bytes", i, s.materials[i].name);
    }
    lc_scene_release(&s);
}

static void test_sponza(int *skipped) {
    char path[512], mtl[512], err[512] = "";
    if (!check_shared_path("scenes/sponza-dabrovic/sponza.obj", path, sizeof path)) {
        fprintf(stderr, "SKIP sponza: ../shared/scenes/sponza-dabrovic/sponza.obj absent\n");
        *skipped = 1;
        return;
    }
    check_shared_path("scenes/sponza-dabrovic/sponza.mtl", mtl, sizeof mtl);
    lc_import_params prm = {1.0, 0};
    lc_scene s;
    int rc = lc_scene_import(path, &prm, &s, err, sizeof err);
    CHECK(rc == 0, "sponza import failed: %s", err);
    if (rc) return;
    CHECK(s.mesh.n_triangles > 65000 && s.mesh.n_triangles <= 66450, "sponza %u triangles (dropped %u)",
          s.mesh.n_triangles, s.n_degenerate_dropped);
    /* every material with map_Kd in the MTL must have its texture loaded */
    FILE *f = fopen(mtl, "r");
    CHECK(f != NULL, "open %s", mtl);
    char line[512], cur[128] = "";
    int want = 0, have = 0;
    while (f && fgets(line, sizeof line, f)) {
        char *p = line;
        while (*p == ' ' || *p == '\t') p++;
        if (!strncmp(p, "newmtl", 6)) sscanf(p + 6, "%127s", cur);
        if (!strncmp(p, "map_Kd", 6)) {
            want++;
            const lc_material *m = find_material(&s, cur);
            int ok = m && m->base_texture >= 0 && (uint32_t)m->base_texture < s.n_textures &&
                s.textures[m->base_texture].rgb;
            have += ok;
            CHECK(ok, "sponza material '%s' texture not loaded", cur);
        }
    }
    if (f) fclose(f);
    CHECK(want > 0 && have == want, "%d of %d textured materials loaded", have, want);
    fprintf(stderr, "sponza: %u triangles, %u materials, %u textures, %d/%d textured\n", s.mesh.n_triangles,
            s.n_materials, s.n_textures, have, want);
    lc_scene_release(&s);
}

static void expect_fail(const char *what, const char *path, double scale, const char *mention) {
    char err[512] = "";
    lc_import_params prm = {scale, 0};
    lc_scene s;
    memset(&s, 0xAB, sizeof s);
    int rc = lc_scene_import(path, &prm, &s, err, sizeof err);
    CHECK(rc == -1, "%s: rc %d", what, rc);
    CHECK(err[0] != '\0', "%s: empty message", what);
    if (mention) CHECK(strstr(err, mention) != NULL, "%s: message '%s' lacks '%s'", what, err, mention);
    CHECK(s.mesh.n_triangles == 0 && s.materials == NULL, "%s: output not cleared", what);
    if (rc == 0) lc_scene_release(&s);
    fprintf(stderr, "  %s -> %s\n", what, err);
}

static void test_bad_inputs(void) {
    char p[512], cornell[512];
    expect_fail("missing file", tmp_path("nothere.obj", p, sizeof p), 1.0, "nothere.obj");
    CHECK(write_text("scene.txt", "v 0 0 0\n") == 0, "write txt");
    expect_fail("unsupported extension", tmp_path("scene.txt", p, sizeof p), 1.0, "scene.txt");
    CHECK(write_text("empty.obj", "# nothing here\n") == 0, "write empty obj");
    expect_fail("empty obj", tmp_path("empty.obj", p, sizeof p), 1.0, "empty.obj");
    CHECK(write_text("degen.obj", "v 0 0 0\nv 1 1 1\nv 2 2 2\nf 1 2 3\n") == 0, "write degenerate obj");
    expect_fail("degenerate only", tmp_path("degen.obj", p, sizeof p), 1.0, "degen.obj");
    CHECK(write_text("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n") == 0, "write nan obj");
    expect_fail("nan vertex", tmp_path("nan.obj", p, sizeof p), 1.0, "nan.obj");
    CHECK(write_file("zero.obj", "", 0) == 0, "write zero-byte obj");
    expect_fail("zero-byte file", tmp_path("zero.obj", p, sizeof p), 1.0, "zero.obj");
    CHECK(write_text("garbage.glb", "this is not a binary gltf file at all") == 0, "write garbage glb");
    expect_fail("garbage glb", tmp_path("garbage.glb", p, sizeof p), 1.0, "garbage.glb");
    check_source_path("scenes/cornell-box/cornell-box.obj", cornell, sizeof cornell);
    expect_fail("scale NaN", cornell, NAN, "scale");
    expect_fail("scale 0", cornell, 0.0, "scale");
    expect_fail("scale negative", cornell, -1.0, "scale");
    expect_fail("scale inf", cornell, INFINITY, "scale");
    /* a tiny scale makes every triangle degenerate */
    expect_fail("scale too small", cornell, 1e-9, "no triangles");

    /* one good triangle + one degenerate: the bad one is dropped and counted, its vertices too */
    CHECK(write_text("mixed.obj",
                     "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nv 6 6 6\nv 7 7 7\n"
                     "v 0 0 3\nv 1e-7 0 3\nv 0 1e-7 3\nf 1 2 3\nf 4 5 6\nf 7 8 9\n") == 0,
          "write mixed obj");
    char err[512] = "";
    lc_import_params prm = {1.0, 0};
    lc_scene s;
    int rc = lc_scene_import(tmp_path("mixed.obj", p, sizeof p), &prm, &s, err, sizeof err);
    CHECK(rc == 0, "mixed import failed: %s", err);
    if (rc == 0) {
        CHECK(s.mesh.n_triangles == 1 && s.mesh.n_vertices == 3, "%u tris %u verts", s.mesh.n_triangles,
              s.mesh.n_vertices);
        CHECK(s.n_degenerate_dropped == 2, "dropped %u", s.n_degenerate_dropped);
        lc_scene_release(&s);
    }
    /* NaN normals in the file are recomputed from the geometry */
    CHECK(write_text("nannorm.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn nan nan nan\nf 1//1 2//1 3//1\n") == 0,
          "write nan-normal obj");
    rc = lc_scene_import(tmp_path("nannorm.obj", p, sizeof p), &prm, &s, err, sizeof err);
    CHECK(rc == 0, "nan-normal import failed: %s", err);
    if (rc == 0) {
        for (uint32_t v = 0; v < s.mesh.n_vertices; v++) CHECK_NEAR(s.mesh.normal[3 * v + 2], 1.0, 1e-6);
        lc_scene_release(&s);
    }
}

int main(void) {
    const char *base = getenv("TMPDIR");
    snprintf(tmpdir, sizeof tmpdir, "%s/lucent-test-import-XXXXXX", base && *base ? base : "/tmp");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 1;
    }
    int sponza_skipped = 0;
    test_cornell();
    test_gltf();
    test_ply();
    test_texture();
    test_bad_inputs();
    test_names();
    test_sponza(&sponza_skipped);
    nftw(tmpdir, rm_entry, 16, FTW_DEPTH | FTW_PHYS);
    if (sponza_skipped && check_failures == 0) {
        fprintf(stderr, "%d checks passed; Sponza part skipped\n", check_count);
        return CHECK_SKIP_RC;
    }
    CHECK_DONE();
}
