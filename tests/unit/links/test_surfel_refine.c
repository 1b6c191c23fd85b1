/* surfel_refine: a small post on a large floor gets no equal-area surfel of its own; caches
 * around it see it, so refinement puts surfels on every face they see, the pilot hits on a
 * surface without its own surfel drop, the areas are the surface each surfel covers (total
 * exact, a post face's surfels together its own area), and the result does not depend on
 * the thread count. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/rt.h"
#include "bake/surfel_refine.h"
#include "bake/surfels.h"
#include "check.h"

typedef struct {
    lc_mesh m;
    uint32_t cap_v, cap_t;
} builder;

/* Quad a, b, c, d (counter-clockwise seen from its front), face normals, material 0. */
static void add_quad(builder *bd, const float q[4][3]) {
    if (bd->m.n_vertices + 4 > bd->cap_v) {
        bd->cap_v = 2 * (bd->m.n_vertices + 4);
        bd->m.position = realloc(bd->m.position, sizeof(float) * 3 * bd->cap_v);
        bd->m.normal = realloc(bd->m.normal, sizeof(float) * 3 * bd->cap_v);
    }
    if (bd->m.n_triangles + 2 > bd->cap_t) {
        bd->cap_t = 2 * (bd->m.n_triangles + 2);
        bd->m.index = realloc(bd->m.index, sizeof(uint32_t) * 3 * bd->cap_t);
        bd->m.material = realloc(bd->m.material, sizeof(uint32_t) * bd->cap_t);
    }
    float e1[3], e2[3], n[3];
    for (int c = 0; c < 3; c++) e1[c] = q[1][c] - q[0][c], e2[c] = q[2][c] - q[0][c];
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    float l = sqrtf(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    uint32_t v = bd->m.n_vertices, t = bd->m.n_triangles;
    for (int k = 0; k < 4; k++)
        for (int c = 0; c < 3; c++) {
            bd->m.position[3 * (v + k) + c] = q[k][c];
            bd->m.normal[3 * (v + k) + c] = n[c] / l;
        }
    const uint32_t ix[6] = {v, v + 1, v + 2, v, v + 2, v + 3};
    memcpy(bd->m.index + 3 * t, ix, sizeof ix);
    bd->m.material[t] = bd->m.material[t + 1] = 0;
    bd->m.n_vertices += 4;
    bd->m.n_triangles += 2;
}

#define POST_HALF 0.1f
#define POST_HEIGHT 0.5f

/* A 0.2 x 0.5 x 0.2 m post: top (triangles 0-1), then the four sides (2-9), standing on a
 * 10 x 10 m floor at y = 0 facing up (10-11; last, so the equal-area walk ends on it). */
static void make_scene(lc_scene *sc) {
    memset(sc, 0, sizeof *sc);
    builder bd = {0};
    const float F = 5, h = POST_HALF, H = POST_HEIGHT;
    add_quad(&bd, (const float[4][3]){{-h, H, h}, {h, H, h}, {h, H, -h}, {-h, H, -h}});
    add_quad(&bd, (const float[4][3]){{-h, 0, h}, {h, 0, h}, {h, H, h}, {-h, H, h}});     /* +z */
    add_quad(&bd, (const float[4][3]){{h, 0, -h}, {-h, 0, -h}, {-h, H, -h}, {h, H, -h}}); /* -z */
    add_quad(&bd, (const float[4][3]){{h, 0, h}, {h, 0, -h}, {h, H, -h}, {h, H, h}});     /* +x */
    add_quad(&bd, (const float[4][3]){{-h, 0, -h}, {-h, 0, h}, {-h, H, h}, {-h, H, -h}}); /* -x */
    add_quad(&bd, (const float[4][3]){{-F, 0, F}, {F, 0, F}, {F, 0, -F}, {-F, 0, -F}});
    sc->mesh = bd.m;
    sc->n_materials = 1;
    sc->materials = calloc(1, sizeof *sc->materials);
    snprintf(sc->materials[0].name, LC_NAME_MAX, "grey");
    for (int c = 0; c < 3; c++) sc->materials[0].base_color[c] = 0.5f;
    sc->materials[0].base_texture = -1;
    lc_scene_update_bounds(sc);
}

/* Eight sphere (grid) caches in a ring 0.8 m around the post at half its height, one above. */
static void make_caches(lc_lcb_cache c[9]) {
    memset(c, 0, 9 * sizeof *c);
    for (int i = 0; i < 8; i++) {
        double a = 2 * M_PI * (i + 0.5) / 8;
        c[i].position[0] = (float)(0.8 * cos(a));
        c[i].position[1] = 0.25f;
        c[i].position[2] = (float)(0.8 * sin(a));
        c[i].flags = LC_CACHE_GRID;
    }
    c[8].position[1] = 1.5f;
    c[8].flags = LC_CACHE_GRID;
}

typedef struct {
    lc_lcb_surfel *s;
    uint32_t *tri, n;
    lc_surfel_refine_stats st;
} refined;

static int refine(const lc_scene *sc, const lc_rt *rt, const lc_lcb_cache *caches, int threads, refined *out) {
    char err[256];
    lc_surfel_params sp = {.target_count = 48, .relax_iterations = 4, .seed = 7, .threads = threads};
    if (lc_surfels_generate(sc, &sp, &out->s, &out->tri, &out->n, err, sizeof err) != 0) {
        fprintf(stderr, "generate: %s\n", err);
        return -1;
    }
    lc_surfel_refine_params rp = {
        .extra = 16, .rounds = 2, .pilot_rays = 2048, .area_samples = 64, .seed = 7, .threads = threads};
    if (lc_surfels_refine(rt, sc, caches, 9, &rp, &out->s, &out->tri, &out->n, &out->st, err, sizeof err) != 0) {
        fprintf(stderr, "refine: %s\n", err);
        return -1;
    }
    return 0;
}

int main(void) {
    lc_scene sc;
    make_scene(&sc);
    char err[256];
    lc_rt *rt = lc_rt_create(&sc.mesh, 2, err, sizeof err);
    CHECK(rt != NULL, "rt: %s", err);
    if (!rt) return 1;
    lc_lcb_cache caches[9];
    make_caches(caches);

    /* Equal-area surfels alone: 48 over 100.44 m^2 leave the 0.44 m^2 post without any. */
    lc_lcb_surfel *s0 = NULL;
    uint32_t *t0 = NULL, n0 = 0, on_post0 = 0;
    lc_surfel_params sp = {.target_count = 48, .relax_iterations = 4, .seed = 7, .threads = 1};
    CHECK(lc_surfels_generate(&sc, &sp, &s0, &t0, &n0, err, sizeof err) == 0, "generate: %s", err);
    for (uint32_t i = 0; i < n0; i++) on_post0 += t0[i] < 10;
    CHECK(on_post0 == 0, "no equal-area surfel on the post (%u)", on_post0);
    free(s0);
    free(t0);

    refined a = {0}, b = {0};
    CHECK(refine(&sc, rt, caches, 1, &a) == 0 && refine(&sc, rt, caches, 2, &b) == 0, "refine");
    fprintf(stderr, "added %u, misplaced pilot hits %.3f -> %.3f of %llu, areas %.3f-%.3f x the mean\n", a.st.added,
            a.st.misplaced_before, a.st.misplaced_after, (unsigned long long)a.st.pilot_hits, a.st.area_min,
            a.st.area_max);
    CHECK(a.n == 64 && a.st.added > 0 && a.st.added + a.st.filled == 16,
          "16 added: %u on misplaced hits' triangles, %u by area (n %u)", a.st.added, a.st.filled, a.n);
    CHECK(a.st.misplaced_before > 0.01 && a.st.misplaced_after < 0.25 * a.st.misplaced_before,
          "the pilot hits on a surface without its own surfel drop (%.3f -> %.3f)", a.st.misplaced_before,
          a.st.misplaced_after);

    /* Every face the caches see (top, four sides) has a surfel; its surfels cover its area. */
    const double floor_area = 100, top_area = 4 * POST_HALF * POST_HALF, side_area = 2 * POST_HALF * POST_HEIGHT;
    double face_area[5] = {0}, total = 0;
    int face_surfels[5] = {0};
    for (uint32_t i = 0; i < a.n; i++) {
        total += a.s[i].area;
        if (a.tri[i] >= 10) continue;
        uint32_t f = a.tri[i] / 2;
        face_surfels[f]++;
        face_area[f] += a.s[i].area;
    }
    const double surface = floor_area + top_area + 4 * side_area;
    CHECK(fabs(total - surface) < 1e-4 * surface, "areas sum to the surface area (%.6f vs %.6f)", total, surface);
    for (int f = 0; f < 5; f++) {
        double want = f == 0 ? top_area : side_area;
        CHECK(face_surfels[f] > 0, "post face %d has a surfel", f);
        CHECK(fabs(face_area[f] - want) < 0.15 * want, "post face %d: its surfels cover %.4f m^2 of its %.4f", f,
              face_area[f], want);
    }

    CHECK(a.n == b.n && !memcmp(a.s, b.s, a.n * sizeof *a.s) && !memcmp(a.tri, b.tri, a.n * sizeof *a.tri),
          "1 and 2 threads give the same surfels");
    free(a.s);
    free(a.tri);
    free(b.s);
    free(b.tri);
    lc_rt_release(rt);
    lc_scene_release(&sc);
    CHECK_DONE();
}
