/* Relight engine (CPU backend) against closed forms: a closed emitting box converges to
 * pi*Le/(1-rho); a small emitting patch gives the analytic form factor on a floor; a light
 * hidden by an occluder contributes nothing; the pull conserves energy; a point light and a
 * constant sky light the surfels as I cos/d^2 and pi*L; bad state is refused by field; an
 * interrupted progressive relight leaves no trace. */
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "engine_fixture.h"

static double median_of(double *x, int n) {
    for (int i = 1; i < n; i++) /* insertion sort: n is small */
        for (int j = i; j > 0 && x[j - 1] > x[j]; j--) {
            double t = x[j];
            x[j] = x[j - 1];
            x[j - 1] = t;
        }
    return n ? x[n / 2] : 0;
}

/* The closed emitting box (albedo 0.5, emission 1: E = pi L_e / (1 - rho) everywhere), baked
 * with FLAGS after the common ones (NULL-terminated, at most 8). */
static int closed_box_bake(fixture *f, const char *const *extra) {
    static char obj[1 << 16];
    obj[0] = 0;
    fixture_inward_box(obj, sizeof obj, 1.0f, 4, "wall", 1);
    const char *mtl = "newmtl wall\nKd 0.5 0.5 0.5\nKe 1 1 1\n";
    const char *flags[32] = {"--surfels",      "4096", "--links",         "160", "--atlas-size",   "64",
                             "--node-samples", "32",   "--final-samples", "64",  "--grid-max-dim", "5",
                             "--bands",        "3"};
    int n = 14;
    for (int i = 0; extra && extra[i] && n < 30; i++) flags[n++] = extra[i];
    flags[n] = NULL;
    int rc = fixture_bake(f, obj, mtl, flags);
    CHECK(rc == 0, "closed box bake failed");
    return rc;
}

/* Mean irradiance for +y (E(n) = sum c_i y_i(n)) over the grid samples inside the 1 m box
 * away from its walls (not inside geometry); *n gets their count, *worst (optional) the
 * largest relative deviation from expect. */
static double closed_box_grid_irradiance(const lc_lcb_view *v, const lc_engine_frame *fr, double expect, int *n,
                                         double *worst) {
    double sum = 0;
    *n = 0;
    if (worst) *worst = 0;
    for (uint32_t i = 0; i < fr->grid_dims[0] * fr->grid_dims[1] * fr->grid_dims[2]; i++) {
        uint32_t c = v->grid[i];
        const float *p = v->caches[c].position;
        if (v->caches[c].flags & LC_CACHE_INSIDE) continue;
        if (p[0] < 0.1f || p[0] > 0.9f || p[1] < 0.1f || p[1] > 0.9f || p[2] < 0.1f || p[2] > 0.9f) continue;
        const float *g = fr->grid_sh + 27 * (size_t)i;
        double e = g[0 * 3 + 1] * 0.282094791774 + g[2 * 3 + 1] * 0.488602511903 + g[6 * 3 + 1] * 0.315391565253 * 2.0;
        sum += e;
        if (worst) *worst = fmax(*worst, fabs(e / expect - 1));
        (*n)++;
    }
    return *n ? sum / *n : 0.0;
}

static void test_closed_box(void) {
    fixture f;
    if (closed_box_bake(&f, NULL) != 0) return;
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    st.settings.bounces = 10;
    st.settings.progressive = 0;
    const lc_engine_frame *fr;
    char err[256];
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    const double expect = M_PI * 1.0 / (1.0 - 0.5);
    /* Lightmap: every owned texel's irradiance. */
    double sum = 0, worst = 0;
    int n = 0;
    for (uint32_t c = 0; c < f.v->n_texel_caches; c++) {
        const float *e = fr->lightmap + 3 * (size_t)f.v->caches[c].index;
        double rel = e[1] / expect - 1;
        sum += e[1];
        worst = fmax(worst, fabs(rel));
        n++;
    }
    double mean = sum / n;
    CHECK(fabs(mean / expect - 1) < 0.02, "closed box: mean texel irradiance %.4f, expected %.4f (2%%)", mean, expect);
    CHECK(worst < 0.03, "closed box: worst texel off by %.1f%%", worst * 100);
    /* Texel caches gather bands 0-1 only (all their irradiance needs), grid caches all three;
     * with the SH lightmap requested, texel caches carry every band again. */
    {
        const uint32_t stride = fr->sh_stride * 3, tc = 0, gc = f.v->n_texel_caches;
        int zero_texel = 1, band1 = 0, band2_grid = 0;
        for (int j = 4; j < 9; j++)
            for (int k = 0; k < 3; k++) {
                zero_texel &= fr->cache_sh[tc * stride + 3 * j + k] == 0.0f;
                for (uint32_t g = gc; g < f.v->n_caches; g++)
                    band2_grid |= fr->cache_sh[(size_t)g * stride + 3 * j + k] != 0.0f;
            }
        for (int j = 1; j < 4; j++) band1 |= fr->cache_sh[tc * stride + 3 * j] != 0.0f;
        CHECK(zero_texel && band1 && band2_grid, "texel band limit: zeros above band 1 %d, band 1 %d, grid band 2 %d",
              zero_texel, band1, band2_grid);
        lc_engine_state st2 = st;
        st2.settings.sh_lightmap = 1;
        const lc_engine_frame *fr2;
        CHECK(lc_engine_relight(f.engine, &st2, &fr2, err, sizeof err) == 0, "relight with sh_lightmap: %s", err);
        int band2 = 0;
        for (int j = 4; j < 9; j++) band2 |= fr2->cache_sh[tc * stride + 3 * j] != 0.0f;
        CHECK(band2, "with the SH lightmap, texel caches carry band 2");
        /* Without the SH lightmap, texel caches gather band 1 from precomputed weights
         * (transport.h); with feedback bounces both paths must give the same lightmap. */
        lc_engine_state s0 = st, s1 = st2;
        s0.settings.bounces = s1.settings.bounces = 2;
        size_t texels = (size_t)fr->lightmap_width * fr->lightmap_height;
        float *band1_lm = malloc(texels * 3 * sizeof *band1_lm);
        CHECK(lc_engine_relight(f.engine, &s0, &fr, err, sizeof err) == 0, "relight band 1: %s", err);
        if (band1_lm) memcpy(band1_lm, fr->lightmap, texels * 3 * sizeof *band1_lm);
        CHECK(fr->cache_sh[tc * stride] == 0.0f, "band-1 texel cache: band 0 is zero");
        CHECK(lc_engine_relight(f.engine, &s1, &fr2, err, sizeof err) == 0, "relight SH: %s", err);
        double peak = 0, diff = 0;
        for (size_t i = 0; band1_lm && i < texels * 3; i++) {
            peak = fmax(peak, fr2->lightmap[i]);
            diff = fmax(diff, fabs((double)band1_lm[i] - fr2->lightmap[i]));
        }
        CHECK(band1_lm && peak > 0 && diff < 1e-5 * peak, "band-1 texel gather = SH gather: worst %.3g of peak %.3g",
              diff, peak);
        free(band1_lm);
        CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight again: %s", err);
    }
    /* Surfel radiosity. */
    double bsum = 0;
    for (uint32_t s = 0; s < f.v->n_surfels; s++) bsum += fr->surfel_radiosity[3 * s];
    CHECK(fabs(bsum / f.v->n_surfels / expect - 1) < 0.02, "closed box: mean surfel radiosity %.4f vs %.4f",
          bsum / f.v->n_surfels, expect);
    /* Grid: irradiance for +y at interior samples. */
    int ng;
    double grid_e = closed_box_grid_irradiance(f.v, fr, expect, &ng, NULL);
    CHECK(ng > 0, "closed box: no interior grid samples");
    if (ng) CHECK(fabs(grid_e / expect - 1) < 0.03, "closed box: grid irradiance %.4f vs %.4f", grid_e, expect);
    /* Energy through the pull: root flux = sum of leaf flux. */
    double leaves = 0;
    for (uint32_t s = 0; s < f.v->n_surfels; s++) leaves += fr->surfel_radiosity[3 * s] * f.v->surfels[s].area;
    CHECK(fabs(fr->node_flux[0] / leaves - 1) < 1e-4, "pull: root flux %.6f vs leaves %.6f", fr->node_flux[0], leaves);
    /* Progressive mode converges across relights with one pass each. */
    st.settings.bounces = 0;
    st.settings.progressive = 1;
    for (int i = 0; i < 12; i++) lc_engine_relight(f.engine, &st, &fr, err, sizeof err);
    sum = 0;
    for (uint32_t c = 0; c < f.v->n_texel_caches; c++) sum += fr->lightmap[3 * (size_t)f.v->caches[c].index + 1];
    CHECK(fabs(sum / n / expect - 1) < 0.02, "progressive: mean %.4f vs %.4f", sum / n, expect);
    fixture_release(&f);
}

/* Irradiance at p (normal +y) from a downward-facing square patch of radiance L, side a,
 * centred at (cx, h, cz), by fine numeric integration. */
static double patch_irradiance(const float p[3], double L, double a, double cx, double h, double cz) {
    const int N = 600;
    double sum = 0, da = (a / N) * (a / N);
    for (int j = 0; j < N; j++)
        for (int i = 0; i < N; i++) {
            double x = cx - a / 2 + (i + 0.5) * a / N - p[0], z = cz - a / 2 + (j + 0.5) * a / N - p[2];
            double y = h - p[1];
            double d2 = x * x + y * y + z * z;
            sum += (y / sqrt(d2)) * (y / sqrt(d2)) / d2 * da;
        }
    return L * sum;
}

static void test_patch_form_factor(void) {
    const char *obj = "usemtl floor\nv -2 0 -2\nv -2 0 2\nv 2 0 2\nv 2 0 -2\nf 1 2 3 4\n"
                      "usemtl lamp\nv -0.15 1 -0.15\nv 0.15 1 -0.15\nv 0.15 1 0.15\nv -0.15 1 0.15\nf 5 6 7 8\n";
    const char *mtl = "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 10 10 10\n";
    /* The patch is "near" for most floor texels (its bounding sphere spans > 8 probe rays),
     * so its solid angle comes from probe-ray counts: per-texel noise falls as 1/sqrt(rays). */
    const char *flags[] = {"--surfels",
                           "8192",
                           "--links",
                           "128",
                           "--atlas-size",
                           "64",
                           "--node-samples",
                           "16",
                           "--final-samples",
                           "64",
                           "--grid-max-dim",
                           "4",
                           "--probe-rays",
                           "4096",
                           NULL};
    fixture f;
    if (fixture_bake(&f, obj, mtl, flags) != 0) {
        CHECK(0, "patch bake failed");
        return;
    }
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    st.settings.bounces = 0;
    st.settings.progressive = 0;
    const lc_engine_frame *fr;
    char err[256];
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    /* Floor texel caches within 1 m of the centre, away from the edges. */
    double ratios[4096];
    int n = 0;
    for (uint32_t c = 0; c < f.v->n_texel_caches && n < 4096; c++) {
        const lc_lcb_cache *ca = &f.v->caches[c];
        if (ca->normal[1] < 0.99f || fabsf(ca->position[0]) > 1 || fabsf(ca->position[2]) > 1) continue;
        double ref = patch_irradiance(ca->position, 10.0, 0.3, 0, 1, 0);
        ratios[n++] = fr->lightmap[3 * (size_t)ca->index] / ref;
    }
    CHECK(n > 20, "patch: only %d floor texels", n);
    double med = median_of(ratios, n);
    CHECK(fabs(med - 1) < 0.03, "patch: median E/E_exact %.4f (3%%)", med);
    CHECK(ratios[n / 20] > 0.88 && ratios[n - 1 - n / 20] < 1.12, "patch: 5-95%% ratio range [%.3f, %.3f]",
          ratios[n / 20], ratios[n - 1 - n / 20]);
    fixture_release(&f);
}

static void test_lights_and_occlusion(void) {
    /* Floor plus a closed, outward-facing box (0.4 m) standing on it at the origin. */
    static char obj[1 << 14];
    int len =
        snprintf(obj, sizeof obj, "usemtl floor\nv -2 0 -2\nv -2 0 2\nv 2 0 2\nv 2 0 -2\nf 1 2 3 4\nusemtl box\n");
    const float b = 0.2f, h = 0.4f;
    float cv[8][3] = {{-b, 0.01f, -b}, {b, 0.01f, -b}, {b, h, -b}, {-b, h, -b},
                      {-b, 0.01f, b},  {b, 0.01f, b},  {b, h, b},  {-b, h, b}};
    for (int i = 0; i < 8; i++)
        len += snprintf(obj + len, sizeof obj - len, "v %g %g %g\n", cv[i][0], cv[i][1], cv[i][2]);
    /* outward CCW faces (vertices 5..12) */
    len += snprintf(obj + len, sizeof obj - len,
                    "f 5 8 7 6\nf 9 10 11 12\nf 5 6 10 9\nf 8 12 11 7\nf 5 9 12 8\nf 6 7 11 10\n");
    const char *mtl = "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl box\nKd 0.5 0.5 0.5\n";
    const char *flags[] = {"--quality", "draft", "--surfels", "4096", NULL};
    fixture f;
    if (fixture_bake(&f, obj, mtl, flags) != 0) {
        CHECK(0, "occluder bake failed");
        return;
    }
    lc_engine_light light = {
        .type = LC_ENGINE_LIGHT_POINT, .color = {1, 1, 1}, .intensity = 5, .position = {0, 0.2f, 0}};
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    st.settings.bounces = 0;
    st.settings.progressive = 0;
    st.lights = &light;
    st.n_lights = 1;
    const lc_engine_frame *fr;
    char err[256];
    /* Inside the closed box: nothing reaches any surfel outside it or the floor. */
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    double lit = 0;
    for (uint32_t s = 0; s < f.v->n_surfels; s++) {
        const lc_lcb_surfel *sf = &f.v->surfels[s];
        int inside_box_wall =
            fabsf(sf->position[0]) <= b + 1e-3f && fabsf(sf->position[2]) <= b + 1e-3f && sf->position[1] <= h + 1e-3f;
        if (!inside_box_wall) lit += fr->surfel_radiosity[3 * s];
    }
    CHECK(lit == 0, "hidden light: surfels outside the box got radiosity %g", lit);
    size_t texels = (size_t)fr->lightmap_width * fr->lightmap_height;
    double lm = 0;
    for (size_t i = 0; i < texels; i++) lm += fr->lightmap[3 * i];
    CHECK(lm == 0, "hidden light: lightmap sum %g", lm);

    /* Above the box: floor surfels get I cos / d^2 (times albedo), unshadowed ones exactly. */
    light.position[1] = 1.5f;
    light.position[0] = 1.0f;
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    int checked = 0, bad = 0;
    for (uint32_t s = 0; s < f.v->n_surfels; s++) {
        const lc_lcb_surfel *sf = &f.v->surfels[s];
        if (sf->normal[1] < 0.99f || sf->position[1] > 0.001f || sf->position[0] < 0.5f) continue;
        double dx = light.position[0] - sf->position[0], dy = light.position[1] - sf->position[1],
               dz = light.position[2] - sf->position[2];
        double d2 = dx * dx + dy * dy + dz * dz;
        double ref = 0.5 * 5.0 * (dy / sqrt(d2)) / d2;
        checked++;
        if (fabs(fr->surfel_radiosity[3 * s] / ref - 1) > 2e-3) bad++;
    }
    CHECK(checked > 50 && bad == 0, "point light: %d of %d surfels differ from I cos/d^2", bad, checked);

    /* Constant sky over the open floor: unoccluded floor surfels get albedo * pi * L. */
    st.n_lights = 0;
    st.environment.kind = LC_ENV_CONSTANT;
    st.environment.color[0] = st.environment.color[1] = st.environment.color[2] = 2.0f;
    st.environment.intensity = 1;
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    checked = bad = 0;
    for (uint32_t s = 0; s < f.v->n_surfels; s++) {
        const lc_lcb_surfel *sf = &f.v->surfels[s];
        if (sf->normal[1] < 0.99f || sf->position[1] > 0.001f) continue;
        if (fabsf(sf->position[0]) < 1.8f && fabsf(sf->position[2]) < 1.8f) continue; /* far from the box */
        checked++;
        if (fabs(fr->surfel_radiosity[3 * s] / (0.5 * M_PI * 2.0) - 1) > 0.03) bad++;
    }
    CHECK(checked > 20 && bad == 0, "sky: %d of %d open floor surfels differ from rho*pi*L", bad, checked);

    /* Incremental work: only what a change touches reruns. */
    lc_engine_light moving = {.type = LC_ENGINE_LIGHT_POINT, .color = {1, 1, 1}, .intensity = 5, .position = {1, 1, 0}};
    st.environment.kind = LC_ENV_NONE;
    st.lights = &moving;
    st.n_lights = 1;
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    CHECK(fr->stages_run & (1u << LC_STAGE_DIRECT), "a light change reruns direct light");
    st.settings.bounces = 1; /* settings only: direct light is reused */
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    CHECK(!(fr->stages_run & (1u << LC_STAGE_DIRECT)) && (fr->stages_run & (1u << LC_STAGE_GATHER)),
          "a settings change skips direct light, reruns the transport (stages 0x%x)", fr->stages_run);
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0 && fr->stages_run == 0,
          "an unchanged state without progressive refinement does nothing (stages 0x%x)", fr->stages_run);
    st.settings.bounces = 0;

    /* Bad state is refused with the field named, and the engine keeps working. */
    light.intensity = NAN;
    st.lights = &light;
    st.n_lights = 1;
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == -1 && strstr(err, "/lights/0/intensity"),
          "NaN intensity: %s", err);
    light.intensity = 1;
    lc_engine_object obj1 = {.asset = 7, .rotation = {0, 0, 0, 1}, .scale = {1, 1, 1}, .visible = 1};
    st.objects = &obj1;
    st.n_objects = 1;
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == -1 && strstr(err, "/objects/0/asset"),
          "bad asset: %s", err);
    st.n_objects = 0;
    st.settings.bands = 9;
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == -1 && strstr(err, "/settings/bands"),
          "bad bands: %s", err);
    st.settings.bands = 3;
    st.settings.grid_cells = 2;
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == -1 && strstr(err, "/settings/grid_cells"),
          "bad grid_cells: %s", err);
    st.settings.grid_cells = LC_GRID_ALL;
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight after errors: %s", err);
    fixture_release(&f);
}

/* Texel caches gathered per surfel (--texel-gather surfels, TSGF/TSGW): the closed box's
 * lightmap converges to pi L_e / (1 - rho) as through the links; band 1 a cosine lobe (band 0
 * and band 2 zero at texel caches); with the SH lightmap asked for, texel caches gather by
 * links again (band 2 set) and give the same light within the links' error. */
static void test_closed_box_texel_surfels(void) {
    const char *extra[] = {"--texel-gather", "surfels", "--texel-gather-rays", "256", NULL};
    fixture f;
    if (closed_box_bake(&f, extra) != 0) return;
    CHECK(f.v->texel_surfels_first && f.v->texel_surfels_first[f.v->n_texel_caches] > 0, "the bake has lists");
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    st.settings.bounces = 10;
    st.settings.progressive = 0;
    const double expect = M_PI * 1.0 / (1.0 - 0.5);
    for (int sh = 0; sh < 2; sh++) {
        st.settings.sh_lightmap = sh;
        const lc_engine_frame *fr;
        char err[256];
        CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
        if (!fr) break;
        double sum = 0, worst = 0;
        for (uint32_t c = 0; c < f.v->n_texel_caches; c++) {
            double e = fr->lightmap[3 * (size_t)f.v->caches[c].index + 1];
            sum += e;
            worst = fmax(worst, fabs(e / expect - 1));
        }
        double mean = sum / f.v->n_texel_caches;
        CHECK(fabs(mean / expect - 1) < 0.02 && worst < 0.03,
              "texel surfels, SH lightmap %d: mean texel irradiance %.4f (worst %.1f%%), expected %.4f", sh, mean,
              worst * 100, expect);
        const float *t0 = fr->cache_sh; /* texel cache 0 */
        int band0 = t0[1] != 0.0f, band1 = t0[3 + 1] != 0.0f || t0[6 + 1] != 0.0f || t0[9 + 1] != 0.0f, band2 = 0;
        for (int j = 4; j < 9; j++) band2 |= t0[3 * j + 1] != 0.0f;
        if (sh) CHECK(band2, "texel surfels with the SH lightmap: the links' band 2 is back");
        else
            CHECK(!band0 && band1 && !band2, "texel surfels: a band-1 lobe only (band 0 %d, 1 %d, 2 %d)", band0, band1,
                  band2);
    }
    fixture_release(&f);
}

/* Grid caches with their own rows of links (--grid-links, GLNK): in the closed box every
 * interior grid sample still reads pi L_e / (1 - rho); the grid caches' LINK slots are padding
 * and some grid cache uses more links than LINK's row holds. */
static void test_closed_box_grid_links(void) {
    const char *extra[] = {"--grid-links", "480", NULL};
    fixture f;
    if (closed_box_bake(&f, extra) != 0) return;
    const lc_lcb_view *v = f.v;
    CHECK(v->grid_links && v->grid_links_per_cache == 480, "the bake has GLNK with 480 links per grid cache");
    uint32_t longest = 0, link_slots_used = 0;
    for (uint32_t c = v->n_texel_caches; c < v->n_caches; c++) {
        longest = v->caches[c].link_count > longest ? v->caches[c].link_count : longest;
        for (uint32_t k = 0; k < v->links_per_cache; k++)
            link_slots_used += v->links[(size_t)c * v->links_per_cache + k].factor != 0;
    }
    CHECK(longest > v->links_per_cache && link_slots_used == 0,
          "grid caches: longest row %u (LINK holds %u), %u used LINK slots (want 0)", longest, v->links_per_cache,
          link_slots_used);
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    st.settings.bounces = 10;
    st.settings.progressive = 0;
    const lc_engine_frame *fr;
    char err[256];
    CHECK(lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0, "relight: %s", err);
    const double expect = M_PI * 1.0 / (1.0 - 0.5);
    int ng = 0;
    double worst = 0, grid_e = fr ? closed_box_grid_irradiance(v, fr, expect, &ng, &worst) : 0.0;
    CHECK(ng > 0 && fabs(grid_e / expect - 1) < 0.02 && worst < 0.04,
          "grid links: %d interior samples, mean irradiance %.4f (worst %.1f%%), expected %.4f", ng, grid_e,
          worst * 100, expect);
    fixture_release(&f);
}

/* lc_engine_set_interrupt: interrupt_at returns nonzero from its `interrupt_after`-th call on. */
static atomic_int interrupt_calls;
static int interrupt_after;
static int interrupt_at(void *arg) {
    (void)arg;
    return atomic_fetch_add(&interrupt_calls, 1) + 1 >= interrupt_after;
}

/* A progressive relight interrupted before its gather or in the middle of it returns
 * LC_ENGINE_INTERRUPTED and leaves no trace: the relights after it give, bit for bit, what an
 * engine that never saw it gives (lucentd interrupts refinement passes this way). */
static void test_interrupted_relight(void) {
    fixture f;
    if (closed_box_bake(&f, NULL) != 0) return;
    char err[256];
    lc_engine *plain = lc_engine_create(f.bake, LC_BACKEND_CPU, 0, err, sizeof err);
    CHECK(plain != NULL, "second engine: %s", err);
    if (!plain) {
        fixture_release(&f);
        return;
    }
    lc_engine_state st = {0};
    st.settings = lc_engine_default_settings(f.bake);
    st.settings.bounces = 0;
    st.settings.progressive = 1;
    const lc_engine_frame *fr;
    const size_t texels = (size_t)f.v->lightmap_width * f.v->lightmap_height * 3;
    float *two = malloc(texels * sizeof *two), *three = malloc(texels * sizeof *three);
    int ok = two && three;
    for (int i = 0; ok && i < 3; i++) {
        ok = lc_engine_relight(plain, &st, &fr, err, sizeof err) == 0;
        if (ok) memcpy(i == 1 ? two : three, fr->lightmap, texels * sizeof *two);
    }
    CHECK(ok, "plain relights: %s", err);
    /* The check can fail: a pass more or less changes the light. */
    CHECK(ok && memcmp(two, three, texels * sizeof *two) != 0, "the third pass changes the lightmap");
    ok = ok && lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0;
    lc_engine_set_interrupt(f.engine, interrupt_at, NULL);
    const int after[] = {1, 5}; /* the first ask is before the pass; the 5th is within the gather */
    for (int k = 0; ok && k < 2; k++) {
        interrupt_after = after[k];
        atomic_store(&interrupt_calls, 0);
        int rc = lc_engine_relight(f.engine, &st, &fr, err, sizeof err);
        CHECK(rc == LC_ENGINE_INTERRUPTED && atomic_load(&interrupt_calls) >= after[k],
              "interrupt at ask %d: relight returned %d after %d asks", after[k], rc, atomic_load(&interrupt_calls));
    }
    CHECK(f.v->n_caches / 64 > 5, "the gather has more than 5 ranges (%u caches)", f.v->n_caches);
    lc_engine_set_interrupt(f.engine, NULL, NULL);
    for (int i = 0; ok && i < 2; i++) ok = lc_engine_relight(f.engine, &st, &fr, err, sizeof err) == 0;
    CHECK(ok && memcmp(fr->lightmap, three, texels * sizeof *three) == 0,
          "after two interrupted relights the engine's third pass equals the plain engine's");
    free(two);
    free(three);
    lc_engine_release(plain);
    fixture_release(&f);
}

int main(void) {
    test_closed_box();
    test_closed_box_texel_surfels();
    test_closed_box_grid_links();
    test_patch_form_factor();
    test_lights_and_occlusion();
    test_interrupted_relight();
    CHECK_DONE();
}
