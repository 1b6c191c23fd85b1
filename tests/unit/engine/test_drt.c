/* DRT clutter operators (engine/drt.h) against closed forms, CPU backend.
 *
 * R1: a 1 m cube of albedo rho resting on the floor of a closed 4 m box whose walls (floor
 * included) all emit L_e = 1 with albedo 0: a uniform radiance field. Every face of the cube
 * is lit by pi L_e, so it shines with rho L_e; a floor point loses L_e and gains rho L_e over
 * the faces it sees:
 *   dE = -pi L_e (1 - rho) sum_faces F(dA -> face)
 * with F the point-to-polygon form factor (Lambert's contour formula). DRT's per-patch
 * constant basis is exact here, so the operators reproduce it up to their sampling. DNRT on
 * the same resting cube (its transfer grid) is the comparison: DRT must be closer.
 * R4: the texels under the cube are filled from their neighbours (no halo at the footprint).
 * R5: a moved, hidden or removed cube drops its operators: the lightmap is then bit for bit
 * the one without them; re-attaching gives the same lightmap again (idempotent).
 * R6: build time, rays, entries, memory (printed); a cancelled build returns nothing. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "engine/drt.h"
#include "engine_fixture.h"
#include "util/clock.h"

#define CUBE_RHO 0.5f

/* A cube [-0.5, 0.5]^3, faces wound counter-clockwise seen from outside. */
static int write_cube(const char *dir, char *path, size_t cap) {
    char mtl[160];
    snprintf(mtl, sizeof mtl, "%s/cube.mtl", dir);
    FILE *fp = fopen(mtl, "w");
    if (!fp) return -1;
    fprintf(fp, "newmtl cube\nKd %g %g %g\n", CUBE_RHO, CUBE_RHO, CUBE_RHO);
    fclose(fp);
    snprintf(path, cap, "%s/cube.obj", dir);
    fp = fopen(path, "w");
    if (!fp) return -1;
    fprintf(fp, "mtllib cube.mtl\nusemtl cube\n");
    for (int i = 0; i < 8; i++) fprintf(fp, "v %g %g %g\n", i & 1 ? 0.5 : -0.5, i & 2 ? 0.5 : -0.5, i & 4 ? 0.5 : -0.5);
    /* vertex i+1: x = bit 0, y = bit 1, z = bit 2 */
    fprintf(fp, "f 2 4 8 6\nf 1 5 7 3\nf 3 7 8 4\nf 1 2 6 5\nf 5 6 8 7\nf 1 3 4 2\n");
    fclose(fp);
    return 0;
}

typedef struct {
    fixture f;
    char tmp[64], asset[200];
} drt_scene;

static int drt_scene_bake(drt_scene *s) {
    static char obj[1 << 17];
    obj[0] = 0;
    fixture_inward_box(obj, sizeof obj, 4.0f, 8, "wall", 1);
    snprintf(s->tmp, sizeof s->tmp, "/tmp/lc_drt_XXXXXX");
    if (!mkdtemp(s->tmp) || write_cube(s->tmp, s->asset + 5, sizeof s->asset - 5) != 0) return -1;
    memcpy(s->asset, "cube=", 5);
    const char *flags[] = {"--surfels",
                           "4096",
                           "--links",
                           "128",
                           "--atlas-size",
                           "64",
                           "--min-texel-density",
                           "0",
                           "--grid-max-dim",
                           "9",
                           "--asset",
                           s->asset,
                           "--transfer-sh",
                           "4",
                           NULL};
    return fixture_bake(&s->f, obj, "newmtl wall\nKd 0 0 0\nKe 1 1 1\n", flags);
}

static void drt_scene_release(drt_scene *s) {
    fixture_release(&s->f);
    char p[160];
    snprintf(p, sizeof p, "%s/cube.obj", s->tmp);
    unlink(p);
    snprintf(p, sizeof p, "%s/cube.mtl", s->tmp);
    unlink(p);
    rmdir(s->tmp);
}

/* Lambert's form factor from a point with normal n to a planar polygon (vertices in order). */
static double polygon_form_factor(const double p[3], const double n[3], const double (*q)[3], int nq) {
    double sum = 0;
    for (int i = 0; i < nq; i++) {
        double a[3], b[3], c[3];
        for (int k = 0; k < 3; k++) a[k] = q[i][k] - p[k], b[k] = q[(i + 1) % nq][k] - p[k];
        double la = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]), lb = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
        c[0] = a[1] * b[2] - a[2] * b[1], c[1] = a[2] * b[0] - a[0] * b[2], c[2] = a[0] * b[1] - a[1] * b[0];
        double lc = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
        if (lc < 1e-12) continue;
        double cosg = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (la * lb);
        double gamma = acos(fmax(-1.0, fmin(1.0, cosg)));
        sum += gamma * (c[0] * n[0] + c[1] * n[1] + c[2] * n[2]) / lc;
    }
    return fabs(sum) / (2 * M_PI);
}

/* The closed-form dE at floor point p (y = 0, normal +y) for the cube centred at c. */
static double r1_expected(const double p[3], const float c[3]) {
    const double n[3] = {0, 1, 0};
    double sum = 0;
    for (int axis = 0; axis < 3; axis += 2) /* the four vertical faces: x = cx +-0.5, z = cz +-0.5 */
        for (int side = -1; side <= 1; side += 2) {
            double f = c[axis] + 0.5 * side;
            if ((p[axis] - f) * side <= 0) continue; /* the point is behind this face */
            int other = axis == 0 ? 2 : 0;
            double q[4][3];
            for (int i = 0; i < 4; i++) {
                q[i][axis] = f;
                q[i][1] = (i == 1 || i == 2) ? c[1] + 0.5 : c[1] - 0.5;
                q[i][other] = c[other] + (i >= 2 ? 0.5 : -0.5);
            }
            sum += polygon_form_factor(p, n, (const double(*)[3])q, 4);
        }
    return -M_PI * 1.0 * (1 - CUBE_RHO) * sum;
}

typedef struct {
    double mean, worst, ratio; /* |error| / |expected| summed; the worst texel; sum engine / sum exact */
    int n;
} r1_stats;

/* Floor texels between `near` and `far` metres outside the cube's footprint. */
static r1_stats r1_compare(const lc_lcb_view *v, const float *got, const float *base, const float c[3], double near,
                           double far) {
    r1_stats r = {0, 0, 0, 0};
    double sum_err = 0, sum_ref = 0, sum_eng = 0;
    for (uint32_t i = 0; i < v->n_texel_caches; i++) {
        const lc_lcb_cache *cc = &v->caches[i];
        if (cc->normal[1] < 0.99f || cc->position[1] > 0.05f) continue;
        double dx = fabs(cc->position[0] - c[0]) - 0.5, dz = fabs(cc->position[2] - c[2]) - 0.5;
        if (fmax(dx, dz) < near || fmax(dx, dz) > far) continue;
        double p[3] = {cc->position[0], 0, cc->position[2]};
        double expect = r1_expected(p, c);
        if (fabs(expect) < 0.02) continue; /* far texels: the relative error means nothing */
        size_t t = cc->index;
        double d = got[3 * t + 1] - base[3 * t + 1];
        r.worst = fmax(r.worst, fabs(d - expect) / fabs(expect));
        sum_err += fabs(d - expect);
        sum_ref += fabs(expect);
        sum_eng += d;
        r.n++;
    }
    r.mean = sum_ref > 0 ? sum_err / sum_ref : 1;
    r.ratio = sum_ref > 0 ? -sum_eng / sum_ref : 0;
    return r;
}

/* E at each texel straight from its cache's SH (before the lightmap filter). */
static float *cache_lightmap(const lc_lcb_view *v, const lc_engine_frame *fr) {
    size_t n = (size_t)fr->lightmap_width * fr->lightmap_height * 3;
    float *c = calloc(n, sizeof *c);
    const float k1 = 0.488602511903f;
    for (uint32_t i = 0; c && i < v->n_texel_caches; i++) {
        const float *sh = fr->cache_sh + (size_t)i * fr->sh_stride * 3, *nn = v->caches[i].normal;
        for (int k = 0; k < 3; k++)
            c[3 * (size_t)v->caches[i].index + k] =
                (float)(4 * M_PI / 3) * k1 * (sh[3 + k] * nn[1] + sh[6 + k] * nn[2] + sh[9 + k] * nn[0]);
    }
    return c;
}

static float *lightmap_copy(const lc_engine_frame *fr) {
    size_t n = (size_t)fr->lightmap_width * fr->lightmap_height * 3;
    float *c = malloc(n * sizeof *c);
    if (c) memcpy(c, fr->lightmap, n * sizeof *c);
    return c;
}

static int same_lightmap(const lc_engine_frame *fr, const float *ref) {
    return memcmp(fr->lightmap, ref, (size_t)fr->lightmap_width * fr->lightmap_height * 3 * sizeof(float)) == 0;
}

static lc_drt_ops *build(lc_drt_builder *b, const lc_engine_object *o) {
    lc_drt_settings ds = lc_drt_default_settings();
    lc_drt_ops *ops = NULL;
    char err[256];
    CHECK(lc_drt_build(b, o, &ds, NULL, &ops, err, sizeof err) == 0 && ops, "build: %s", err);
    return ops;
}

static void test_cube_on_floor(void) {
    drt_scene s;
    if (drt_scene_bake(&s) != 0) {
        CHECK(0, "DRT scene bake failed");
        return;
    }
    const lc_lcb_view *v = s.f.v;
    lc_engine *e = s.f.engine;
    char err[256];
    lc_engine_state st;
    memset(&st, 0, sizeof st);
    st.settings = lc_engine_default_settings(s.f.bake);
    st.settings.bounces = 0;
    st.settings.progressive = 0;
    const lc_engine_frame *fr;
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    float *base = lightmap_copy(fr), *base_c = cache_lightmap(v, fr);

    lc_engine_object cube = {.id = "box",
                             .asset = 0,
                             .translation = {2, 0.5f, 2},
                             .rotation = {0, 0, 0, 1},
                             .scale = {1, 1, 1},
                             .visible = 1};
    st.objects = &cube;
    st.n_objects = 1;
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight (DNRT): %s", err);
    CHECK(fr->dnrt_objects == 1 && fr->drt_objects == 0, "without operators the cube is in DNRT");
    float *dnrt = lightmap_copy(fr), *dnrt_c = cache_lightmap(v, fr);

    lc_drt_builder *b = lc_drt_builder_create(v, 0, err, sizeof err);
    CHECK(b != NULL, "builder: %s", err);
    if (!b) goto out;
    double t0 = lc_clock_ms();
    lc_drt_ops *ops = build(b, &cube);
    double ms = lc_clock_ms() - t0;
    if (!ops) goto out;
    lc_drt_info in = lc_drt_ops_info(ops);
    fprintf(stderr,
            "R6 build: %.0f ms, %u patches, %u elements, %u receivers (%u texel, %u grid), %u inpainted, %llu entries, "
            "%llu rays, %.2f MiB\n",
            ms, in.patches, in.elements, in.receivers, in.texel_receivers, in.grid_receivers, in.inpainted,
            (unsigned long long)in.entries, (unsigned long long)in.rays, in.bytes / 1048576.0);
    CHECK(in.patches >= 64 && in.patches <= 256, "about 128 patches (%u)", in.patches);
    CHECK(in.texel_receivers > 500 && in.grid_receivers > 0, "receivers (%u texel, %u grid)", in.texel_receivers,
          in.grid_receivers);
    CHECK(in.inpainted > 4, "texels under the cube are inpainted (%u)", in.inpainted);
    CHECK(lc_engine_clutter_attach(e, ops, err, sizeof err) == 0, "attach: %s", err);
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight (DRT): %s", err);
    CHECK(fr->drt_objects == 1 && fr->dnrt_objects == 0 && lc_engine_clutter_active(e, "box"),
          "with operators the cube is clutter, out of DNRT");
    float *drt = lightmap_copy(fr), *drt_c = cache_lightmap(v, fr);
    uint32_t np;
    const float *pb = lc_drt_patch_radiosity(ops, &np);
    double bmin = INFINITY, bmax = 0;
    for (uint32_t p = 0; p < np; p++) {
        /* the bottom face rests on the emitting floor: it sees the floor only */
        bmin = fmin(bmin, pb[3 * p + 1]);
        bmax = fmax(bmax, pb[3 * p + 1]);
    }
    CHECK(fabs(bmax / (CUBE_RHO * M_PI) - 1) < 0.01, "patch radiosity rho pi L_e (max %.4f, expected %.4f)", bmax,
          CUBE_RHO * M_PI);

    /* R1/R7 on the caches' own irradiance (what the operators change); the lightmap's 3x3 filter then blurs the
     * steep gradient at the faces the same way with and without clutter. */
    r1_stats rd = r1_compare(v, drt_c, base_c, cube.translation, 0.1, 1e9),
             rn = r1_compare(v, dnrt_c, base_c, cube.translation, 0.1, 1e9),
             ld = r1_compare(v, drt, base, cube.translation, 0.1, 1e9);
    fprintf(stderr,
            "R1 cube on the floor, %d floor caches >= 0.1 m from it: DRT |dE| error %.2f%% (worst %.2f%%, sum "
            "engine/exact %.4f); DNRT %.2f%% (worst %.2f%%, %.4f); DRT in the filtered lightmap %.2f%%\n",
            rd.n, 100 * rd.mean, 100 * rd.worst, rd.ratio, 100 * rn.mean, 100 * rn.worst, rn.ratio, 100 * ld.mean);
    CHECK(rd.n > 200, "enough floor caches (%d)", rd.n);
    CHECK(rd.mean < 0.02, "R1: DRT mean |dE| error %.2f%% (tolerance 2%%)", 100 * rd.mean);
    CHECK(rd.worst < 0.05, "R1: DRT worst cache %.2f%% (tolerance 5%%)", 100 * rd.worst);
    CHECK(fabs(rd.ratio - 1) < 0.01, "R1: DRT total dE within 1%% (%.4f)", rd.ratio);
    CHECK(rd.mean < 0.5 * rn.mean, "R7: DRT (%.2f%%) at least twice as close as DNRT (%.2f%%)", 100 * rd.mean,
          100 * rn.mean);
    CHECK(ld.mean < 0.08, "R1: the served lightmap's dE within 8%% (%.2f%%)", 100 * ld.mean);
    /* R4: texels within 0.25 m of the footprint, whose lightmap filter taps reach the inpainted texels under it: a
     * halo would read brighter than the closed form (dE less negative; 78% of it with inpainting off). */
    r1_stats ring = r1_compare(v, drt, base, cube.translation, 0.0, 0.25);
    fprintf(stderr,
            "R4 ring 0-0.25 m from the footprint: %d texels, mean %.2f%%, worst %.2f%%, sum engine/exact %.4f\n",
            ring.n, 100 * ring.mean, 100 * ring.worst, ring.ratio);
    CHECK(ring.n > 8, "R4: texels next to the footprint (%d)", ring.n);
    CHECK(ring.ratio > 0.87, "R4: no halo next to the footprint (dE %.1f%% of the closed form)", 100 * ring.ratio);

    /* R5: moved, the operators drop (the cube is DNRT again); re-attached, the same light. */
    lc_engine_object moved = cube;
    moved.translation[0] = 1.5f;
    st.objects = &moved;
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight moved: %s", err);
    CHECK(fr->drt_objects == 0 && fr->dnrt_objects == 1 && !lc_engine_clutter_active(e, "box"),
          "R5: a move drops the operators");
    float *moved_dnrt = lightmap_copy(fr);
    st.objects = &cube;
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight back: %s", err);
    CHECK(same_lightmap(fr, dnrt), "R5: back in place without operators: the DNRT lightmap, bit for bit");
    CHECK(lc_engine_clutter_attach(e, build(b, &cube), err, sizeof err) == 0, "attach again: %s", err);
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    CHECK(same_lightmap(fr, drt), "R5: rebuilt and re-attached: the same lightmap (deterministic)");
    CHECK(lc_engine_clutter_attach(e, build(b, &cube), err, sizeof err) == 0, "attach a third time: %s", err);
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    CHECK(same_lightmap(fr, drt), "R5: attaching twice replaces, never adds");
    /* operators built for another placement never apply */
    CHECK(lc_engine_clutter_attach(e, build(b, &moved), err, sizeof err) == 0, "attach stale: %s", err);
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    CHECK(fr->drt_objects == 0 && same_lightmap(fr, dnrt), "R5: operators for another placement are dropped");
    st.objects = &moved;
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    CHECK(same_lightmap(fr, moved_dnrt), "R5: and do not come back when the object gets there");
    st.objects = &cube;
    CHECK(lc_engine_clutter_attach(e, build(b, &cube), err, sizeof err) == 0, "attach: %s", err);
    cube.visible = 0;
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight hidden: %s", err);
    CHECK(fr->drt_objects == 0, "R5: hiding drops the operators");
    cube.visible = 1;
    CHECK(lc_engine_clutter_attach(e, build(b, &cube), err, sizeof err) == 0, "attach: %s", err);
    st.n_objects = 0;
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight removed: %s", err);
    CHECK(fr->drt_objects == 0 && same_lightmap(fr, base), "R5: removing restores the base lightmap bit for bit");
    st.n_objects = 1;
    CHECK(lc_engine_clutter_attach(e, build(b, &cube), err, sizeof err) == 0, "attach: %s", err);
    lc_engine_clutter_detach(e, "box");
    CHECK(lc_engine_relight(e, &st, &fr, err, sizeof err) == 0, "relight detached: %s", err);
    CHECK(fr->drt_objects == 0 && same_lightmap(fr, dnrt), "R5: detaching gives the DNRT lightmap");

    /* A cancelled build returns nothing. */
    atomic_int cancel = 1;
    lc_drt_settings ds = lc_drt_default_settings();
    lc_drt_ops *none = (lc_drt_ops *)1;
    CHECK(lc_drt_build(b, &cube, &ds, &cancel, &none, err, sizeof err) == 1 && none == NULL,
          "a cancelled build returns 1 and no operators");
    ds.rays = 3;
    CHECK(lc_drt_build(b, &cube, &ds, NULL, &none, err, sizeof err) == -1 && strstr(err, "clutter_rays"),
          "bad settings name the field: %s", err);
    free(moved_dnrt);
    free(drt);
    free(drt_c);
out:
    lc_drt_builder_release(b);
    free(dnrt);
    free(dnrt_c);
    free(base);
    free(base_c);
    drt_scene_release(&s);
}

int main(void) {
    test_cube_on_floor();
    CHECK_DONE();
}
