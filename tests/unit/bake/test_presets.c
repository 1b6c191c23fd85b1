/* Bake presets: --quality picks every parameter a preset controls, explicit flags win over it. */
#include <string.h>

#include "bake/bake.h"
#include "check.h"

static int parse(lc_bake_settings *s, const char *const *args, int n) {
    char *argv[16], *pos[2], err[256] = "";
    argv[0] = "lucent-bake";
    argv[1] = "bake";
    for (int i = 0; i < n; i++) argv[2 + i] = (char *)args[i];
    int rc = lc_bake_parse_args(s, 2 + n, argv, 2, pos, 2, err, sizeof err);
    CHECK(rc >= 0 || err[0], "a failed parse says why");
    return rc;
}

int main(void) {
    static lc_bake_settings s;
    const char *moderate[] = {"scene.obj"};
    CHECK(parse(&s, moderate, 1) == 1, "default parse");
    CHECK(s.quality == LC_QUALITY_MODERATE && s.surfels == 32768 && s.links == 128 && s.bands == 3 && s.exposure &&
              s.probe_rays == 1024 && s.probe_ray_budget == 1 << 25,
          "default = moderate (32768 surfels, 128 links, 3 bands, exposure, 1024+ probe rays): %d %d %d %d %d %d",
          s.surfels, s.links, s.bands, s.exposure, s.probe_rays, s.probe_ray_budget);
    /* probe rays per cache: the floor, doubled while the bake's total stays within the budget */
    CHECK(lc_bake_probe_rays(&s, 35000) == 1024, "Sponza's 35 000 caches keep 1024 rays: %u",
          lc_bake_probe_rays(&s, 35000));
    CHECK(lc_bake_probe_rays(&s, 16384) == 2048, "16 384 caches: 2048 rays (exactly the budget): %u",
          lc_bake_probe_rays(&s, 16384));
    CHECK(lc_bake_probe_rays(&s, 3181) == 8192, "the Cornell box's 3 181 caches: the 8192 cap: %u",
          lc_bake_probe_rays(&s, 3181));
    CHECK(lc_bake_probe_rays(&s, 1) == LC_BAKE_PROBE_RAYS_MAX, "never above the cap");
    s.probe_ray_budget = 0;
    CHECK(lc_bake_probe_rays(&s, 100) == 1024, "budget 0: --probe-rays exactly");
    s.probe_ray_budget = 1 << 25;
    s.probe_rays = 0;
    CHECK(lc_bake_probe_rays(&s, 100) == 0, "--probe-rays 0 (surfel sampling only) stays 0");
    CHECK(s.list_refine == 0.25, "moderate: texel lists get a quarter more surfels by refinement (%g)", s.list_refine);
    const char *draft[] = {"scene.obj", "--quality", "draft"};
    CHECK(parse(&s, draft, 3) == 1 && s.probe_rays == 256 && s.probe_ray_budget == 0 && !s.exposure,
          "draft: 256 probe rays exactly, no exposure (previews: bake time first)");
    const char *high[] = {"scene.obj", "--quality", "high"};
    CHECK(parse(&s, high, 3) == 1, "high");
    CHECK(s.surfels == 131072 && s.links == 254 && s.bands == 4 && s.exposure && s.list_refine == 0, "high preset");
    const char *ultra[] = {"scene.obj", "--quality", "ultra"};
    CHECK(parse(&s, ultra, 3) == 1, "ultra");
    CHECK(s.quality == LC_QUALITY_ULTRA && s.surfels == 131072 && s.links == 512 && s.bands == 3 && s.exposure &&
              s.probe_rays == 2048,
          "ultra preset: %d %d %d %d %d", s.surfels, s.links, s.bands, s.exposure, s.probe_rays);
    /* flags win, wherever they stand relative to --quality */
    const char *ultra_flags[] = {"--links", "300", "scene.obj", "--no-exposure", "--quality", "ultra"};
    CHECK(parse(&s, ultra_flags, 6) == 1, "ultra with flags");
    CHECK(s.links == 300 && !s.exposure && s.surfels == 131072, "explicit flags over ultra: %d %d %d", s.links,
          s.exposure, s.surfels);
    const char *twice[] = {"scene.obj", "--quality", "moderate", "--quality", "ultra"};
    CHECK(parse(&s, twice, 5) == 1 && s.links == 512, "the last --quality wins");
    const char *moderate_exposure[] = {"scene.obj", "--exposure"};
    CHECK(parse(&s, moderate_exposure, 2) == 1 && s.exposure && s.links == 128, "--exposure on moderate");
    const char *bad[] = {"scene.obj", "--quality", "extreme"};
    CHECK(parse(&s, bad, 3) < 0, "unknown preset is an error");
    CHECK_DONE();
}
