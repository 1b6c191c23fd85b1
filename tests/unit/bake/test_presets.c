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
    CHECK(s.quality == LC_QUALITY_MODERATE && s.surfels == 32768 && s.links == 128 && s.bands == 3 && !s.exposure,
          "default = moderate (32768 surfels, 128 links, 3 bands, no exposure): %d %d %d %d", s.surfels, s.links,
          s.bands, s.exposure);
    const char *high[] = {"scene.obj", "--quality", "high"};
    CHECK(parse(&s, high, 3) == 1, "high");
    CHECK(s.surfels == 131072 && s.links == 254 && s.bands == 4 && !s.exposure, "high preset");
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
