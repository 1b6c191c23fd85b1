/* test_lcb_glb_import: the glTF generated from the embedded Cornell bake
 * (LUCENT_BINARY_DIR/cornell.lcb) read back through Assimp (lc_scene_import, what
 * lucent-bake reads scenes with): the same triangles, bounds, area, lightmap UVs and lamp
 * emission; the cube asset's 12 triangles and bounds. In the bake module because it needs
 * both the bake file (lc_lcb) and the importer (lc_scene). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bake/scene.h"
#include "check.h"
#include "lcb/lcb.h"
#include "lcb/lcb_glb.h"
#include "util/fsutil.h"

/* Writes the GLB to a temp file and imports it into *sc. */
static int import_glb(const unsigned char *glb, size_t len, lc_scene *sc) {
    char path[] = "/tmp/lucent_glb_import_XXXXXX.glb", err[512] = "";
    int fd = mkstemps(path, 4);
    CHECK(fd >= 0, "temp file");
    if (fd < 0) return -1;
    close(fd);
    int rc = lc_fs_write_atomic(path, glb, len, err, sizeof err);
    CHECK(rc == 0, "write %s: %s", path, err);
    lc_import_params prm = {1.0, 0};
    if (rc == 0) rc = lc_scene_import(path, &prm, sc, err, sizeof err);
    CHECK(rc == 0, "import %s: %s", path, err);
    unlink(path);
    return rc;
}

static void check_scene(const lc_lcb *f) {
    const lc_lcb_view *v = lc_lcb_get(f);
    unsigned char *glb = NULL;
    size_t len = 0;
    char err[256] = "";
    lc_scene sc;
    CHECK(lc_lcb_scene_glb(f, &glb, &len, err, sizeof err) == 0, "scene glb: %s", err);
    if (!glb || import_glb(glb, len, &sc) != 0) {
        free(glb);
        return;
    }
    CHECK(sc.mesh.n_triangles == v->n_triangles, "re-imported %u triangles, bake %u", sc.mesh.n_triangles,
          v->n_triangles);
    CHECK(sc.has_lightmap_uv && sc.mesh.uv1, "TEXCOORD_1 read back as the lightmap UV");
    /* order-free sums over every triangle corner: area, position and lightmap UV */
    double area = 0, ps[3] = {0, 0, 0}, us[2] = {0, 0}, ps0[3] = {0, 0, 0}, us0[2] = {0, 0};
    for (uint32_t t = 0; t < v->n_triangles; t++)
        for (int c = 0; c < 3; c++) {
            const lc_lcb_vertex *x = &v->vertices[v->triangles[t].v[c]];
            for (int k = 0; k < 3; k++) ps0[k] += x->position[k];
            for (int k = 0; k < 2; k++) us0[k] += x->uv1[k];
        }
    for (uint32_t t = 0; t < sc.mesh.n_triangles; t++) {
        area += lc_mesh_triangle_area(&sc.mesh, t);
        for (int c = 0; c < 3; c++) {
            uint32_t i = sc.mesh.index[3 * (size_t)t + c];
            for (int k = 0; k < 3; k++) ps[k] += sc.mesh.position[3 * (size_t)i + k];
            for (int k = 0; sc.mesh.uv1 && k < 2; k++) us[k] += sc.mesh.uv1[2 * (size_t)i + k];
        }
    }
    for (int k = 0; k < 3; k++) CHECK_NEAR(ps[k], ps0[k], 1e-6);
    for (int k = 0; k < 2; k++) CHECK_NEAR(us[k], us0[k], 1e-5);
    double area0 = 0;
    for (uint32_t t = 0; t < v->n_triangles; t++) {
        const float *a = v->vertices[v->triangles[t].v[0]].position, *b = v->vertices[v->triangles[t].v[1]].position,
                    *c = v->vertices[v->triangles[t].v[2]].position;
        double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double x = e1[1] * e2[2] - e1[2] * e2[1], y = e1[2] * e2[0] - e1[0] * e2[2], z = e1[0] * e2[1] - e1[1] * e2[0];
        area0 += 0.5 * sqrt(x * x + y * y + z * z);
    }
    CHECK_NEAR(area, area0, 1e-6);
    int lamp = 0;
    for (uint32_t i = 0; i < sc.n_materials; i++)
        if (!strcmp(sc.materials[i].name, "light")) {
            lamp = 1;
            CHECK_NEAR(sc.materials[i].emission[0], 17.0, 1e-5);
            CHECK_NEAR(sc.materials[i].emission[1], 12.0, 1e-5);
            CHECK_NEAR(sc.materials[i].emission[2], 4.0, 1e-5);
        }
    CHECK(lamp, "the lamp material read back");
    lc_scene_release(&sc);
    free(glb);
}

static void check_asset(const lc_lcb *f) {
    const lc_lcb_view *v = lc_lcb_get(f);
    CHECK(v->n_assets == 1, "the Cornell bake has one asset");
    if (v->n_assets < 1) return;
    unsigned char *glb = NULL;
    size_t len = 0;
    char err[256] = "";
    lc_scene sc;
    CHECK(lc_lcb_asset_glb(f, 0, &glb, &len, err, sizeof err) == 0, "asset glb: %s", err);
    if (!glb || import_glb(glb, len, &sc) != 0) {
        free(glb);
        return;
    }
    CHECK(sc.mesh.n_triangles == v->assets[0].triangle_count && sc.mesh.n_triangles == 12, "cube: %u triangles",
          sc.mesh.n_triangles);
    for (int c = 0; c < 3; c++) {
        CHECK_NEAR(sc.bounds_min[c], v->assets[0].bounds_min[c], 1e-7);
        CHECK_NEAR(sc.bounds_max[c], v->assets[0].bounds_max[c], 1e-7);
    }
    lc_scene_release(&sc);
    free(glb);
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
    check_scene(f);
    check_asset(f);
    lc_lcb_close(f);
    CHECK_DONE();
}
