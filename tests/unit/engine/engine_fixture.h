/* Test fixture: bakes a small OBJ scene written by the test into a temp .lcb with the real
 * pipeline, opens it, and creates a CPU engine over it. */
#ifndef LC_ENGINE_FIXTURE_H
#define LC_ENGINE_FIXTURE_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bake/bake.h"
#include "engine/engine.h"
#include "lcb/lcb.h"

typedef struct fixture {
    char dir[64];
    char lcb_path[128];
    lc_lcb *bake;
    const lc_lcb_view *v;
    lc_engine *engine;
} fixture;

/* Writes obj/mtl text, bakes with the given extra flags (NULL-terminated), opens it. */
static inline int fixture_bake(fixture *f, const char *obj, const char *mtl, const char **flags) {
    memset(f, 0, sizeof *f);
    snprintf(f->dir, sizeof f->dir, "/tmp/lc_engine_XXXXXX");
    if (!mkdtemp(f->dir)) return -1;
    char path[160];
    snprintf(path, sizeof path, "%s/scene.mtl", f->dir);
    FILE *fp = fopen(path, "w");
    fputs(mtl, fp);
    fclose(fp);
    snprintf(path, sizeof path, "%s/scene.obj", f->dir);
    fp = fopen(path, "w");
    fputs("mtllib scene.mtl\n", fp);
    fputs(obj, fp);
    fclose(fp);
    snprintf(f->lcb_path, sizeof f->lcb_path, "%s/scene.lcb", f->dir);
    /* --probe-ray-budget 0: a small scene would get 8x the probe rays by default (bake time,
     * not what these tests check; under AddressSanitizer test_dnrt took 468 s with them). A
     * test's own flags come later and win. */
    char *argv[64] = {"lucent-bake",        "bake", path, "--output", f->lcb_path, "--quiet", "--no-write-glb",
                      "--probe-ray-budget", "0"};
    int argc = 9;
    for (int i = 0; flags && flags[i] && argc < 63; i++) argv[argc++] = (char *)flags[i];
    static lc_bake_settings s;
    char err[512];
    char *pos[2];
    if (lc_bake_parse_args(&s, argc, argv, 2, pos, 2, err, sizeof err) != 1) {
        fprintf(stderr, "fixture args: %s\n", err);
        return -1;
    }
    snprintf(s.input, sizeof s.input, "%s", pos[0]);
    if (lc_bake_run(&s, NULL, err, sizeof err) != 0) {
        fprintf(stderr, "fixture bake: %s\n", err);
        return -1;
    }
    if (lc_lcb_open(f->lcb_path, &f->bake, err, sizeof err) != 0) {
        fprintf(stderr, "fixture open: %s\n", err);
        return -1;
    }
    f->v = lc_lcb_get(f->bake);
    f->engine = lc_engine_create(f->bake, LC_BACKEND_CPU, 0, err, sizeof err);
    if (!f->engine) {
        fprintf(stderr, "fixture engine: %s\n", err);
        return -1;
    }
    return 0;
}

static inline void fixture_release(fixture *f) {
    lc_engine_release(f->engine);
    lc_lcb_close(f->bake);
    unlink(f->lcb_path);
    char path[160];
    snprintf(path, sizeof path, "%s/scene.obj", f->dir);
    unlink(path);
    snprintf(path, sizeof path, "%s/scene.mtl", f->dir);
    unlink(path);
    rmdir(f->dir);
}

/* An axis-aligned box [0,s]^3 with faces subdivided n x n, wound inward (front faces
 * toward the inside). Appends to buf; base = the OBJ index its first vertex gets. */
static inline void fixture_inward_box(char *buf, size_t cap, float s, int n, const char *mtl, int base) {
    size_t len = strlen(buf);
    len += (size_t)snprintf(buf + len, cap - len, "usemtl %s\n", mtl);
    /* Each face: origin o, axes u, w; normal = u x w must point inward. */
    const float faces[6][9] = {
        {0, 0, 0, 0, 0, 1, 1, 0, 0}, /* floor y=0: u=z, w=x -> z x x = +y */
        {0, 1, 0, 1, 0, 0, 0, 0, 1}, /* ceiling y=s: u=x, w=z -> x x z = -y */
        {0, 0, 0, 1, 0, 0, 0, 1, 0}, /* back z=0: u=x, w=y -> +z */
        {0, 0, 1, 0, 1, 0, 1, 0, 0}, /* front z=s: u=y, w=x -> -z */
        {0, 0, 0, 0, 1, 0, 0, 0, 1}, /* left x=0: u=y, w=z -> +x */
        {1, 0, 0, 0, 0, 1, 0, 1, 0}, /* right x=s: u=z, w=y -> -x */
    };
    for (int f = 0; f < 6; f++) {
        const float *o = faces[f], *u = faces[f] + 3, *w = faces[f] + 6;
        for (int j = 0; j <= n; j++)
            for (int i = 0; i <= n; i++) {
                float a = (float)i / n, b = (float)j / n;
                len += (size_t)snprintf(buf + len, cap - len, "v %g %g %g\n", s * (o[0] + a * u[0] + b * w[0]),
                                        s * (o[1] + a * u[1] + b * w[1]), s * (o[2] + a * u[2] + b * w[2]));
            }
        for (int j = 0; j < n; j++)
            for (int i = 0; i < n; i++) {
                int v00 = base + j * (n + 1) + i, v10 = v00 + 1, v01 = v00 + n + 1, v11 = v01 + 1;
                len += (size_t)snprintf(buf + len, cap - len, "f %d %d %d %d\n", v00, v10, v11, v01);
            }
        base += (n + 1) * (n + 1);
    }
}

#endif
