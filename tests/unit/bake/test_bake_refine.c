/* --surfel-refine end to end: the Cornell box baked with a quarter of its surfels refined keeps
 * the surfel count and the surface area, records the refined surfels in META (the rest of the
 * quarter goes by area), and its surfel areas follow the surface each covers; the equal-area
 * bake records none. --list-refine adds its surfels on top, only when the texel caches gather
 * per surfel. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cjson/cJSON.h>

#include "bake/bake.h"
#include "check.h"
#include "lcb/lcb.h"

static char tmp[64];

/* Bakes the Cornell box (draft, 2048 surfels) into tmp/NAME with --surfel-refine refine,
 * --list-refine list_refine and --texel-gather gather. */
static int bake(const char *name, const char *refine, const char *list_refine, const char *gather, char *out,
                size_t cap) {
    char src[512];
    snprintf(out, cap, "%s/%s", tmp, name);
    char *argv[] = {"lucent-bake",
                    "bake",
                    (char *)check_source_path("scenes/cornell-box/cornell-box.obj", src, sizeof src),
                    "--output",
                    out,
                    "--quiet",
                    "--no-write-glb",
                    "--quality",
                    "draft",
                    "--surfels",
                    "2048",
                    "--atlas-size",
                    "32",
                    "--min-texel-density",
                    "0",
                    "--no-transfer",
                    "--surfel-refine",
                    (char *)refine,
                    "--list-refine",
                    (char *)list_refine,
                    "--texel-gather",
                    (char *)gather};
    static lc_bake_settings s;
    char err[512] = "", *pos[2];
    if (lc_bake_parse_args(&s, (int)(sizeof argv / sizeof *argv), argv, 2, pos, 2, err, sizeof err) != 1) {
        fprintf(stderr, "args: %s\n", err);
        return -1;
    }
    snprintf(s.input, sizeof s.input, "%s", pos[0]);
    if (lc_bake_run(&s, NULL, err, sizeof err) != 0) {
        fprintf(stderr, "bake: %s\n", err);
        return -1;
    }
    return 0;
}

typedef struct {
    uint32_t n;
    double area_sum, area_min, area_max, refined;
} surfel_summary;

static int summarise(const char *path, surfel_summary *out) {
    lc_lcb *f = NULL;
    char err[256];
    if (lc_lcb_open(path, &f, err, sizeof err) != 0) {
        fprintf(stderr, "open %s: %s\n", path, err);
        return -1;
    }
    const lc_lcb_view *v = lc_lcb_get(f);
    *out = (surfel_summary){.n = v->n_surfels, .area_min = INFINITY};
    for (uint32_t i = 0; i < v->n_surfels; i++) {
        out->area_sum += v->surfels[i].area;
        out->area_min = fmin(out->area_min, v->surfels[i].area);
        out->area_max = fmax(out->area_max, v->surfels[i].area);
    }
    cJSON *meta = cJSON_Parse(v->meta_json);
    out->refined = cJSON_GetNumberValue(cJSON_GetObjectItem(cJSON_GetObjectItem(meta, "surfels"), "refined"));
    cJSON_Delete(meta);
    lc_lcb_close(f);
    return 0;
}

int main(void) {
    snprintf(tmp, sizeof tmp, "/tmp/lucent-refine-XXXXXX");
    if (!mkdtemp(tmp)) return 1;
    char plain_path[128], refined_path[128];
    surfel_summary plain, refined;
    char lists_path[128], links_path[128];
    surfel_summary lists, links;
    CHECK(bake("plain.lcb", "0", "0", "links", plain_path, sizeof plain_path) == 0 &&
              bake("refined.lcb", "0.25", "0", "links", refined_path, sizeof refined_path) == 0 &&
              bake("lists.lcb", "0", "0.25", "surfels", lists_path, sizeof lists_path) == 0 &&
              bake("links.lcb", "0", "0.25", "links", links_path, sizeof links_path) == 0,
          "bakes");
    CHECK(summarise(plain_path, &plain) == 0 && summarise(refined_path, &refined) == 0 &&
              summarise(lists_path, &lists) == 0 && summarise(links_path, &links) == 0,
          "read back");
    fprintf(stderr, "plain: %u surfels, area %.4f; refined: %u surfels (%g refined), area %.4f, %.4f-%.4f\n", plain.n,
            plain.area_sum, refined.n, refined.refined, refined.area_sum, refined.area_min, refined.area_max);
    CHECK(plain.refined == 0 && plain.area_max == plain.area_min, "equal-area bake: equal areas, none refined");
    /* the Cornell box's surfaces all have surfels at this density: what refinement does not
     * place on misplaced hits goes by area, and the count stays --surfels */
    CHECK(refined.refined >= 0 && refined.refined <= 512, "META surfels.refined: %g of at most 512", refined.refined);
    CHECK(refined.n == 2048, "the count stays --surfels (%u)", refined.n);
    CHECK(fabs(refined.area_sum - plain.area_sum) < 1e-4 * plain.area_sum, "the surface area kept (%.6f vs %.6f)",
          refined.area_sum, plain.area_sum);
    CHECK(refined.area_max > refined.area_min, "areas follow the surface each surfel covers");
    /* --list-refine: a quarter more surfels, on top of the equal-area 2048, with texel lists only */
    fprintf(stderr, "lists: %u surfels (%g refined), area %.4f; links: %u surfels (%g refined)\n", lists.n,
            lists.refined, lists.area_sum, links.n, links.refined);
    CHECK(lists.n == 2048 + 512 && lists.refined <= 512 && lists.area_max > lists.area_min,
          "texel lists: 2048 + 512 surfels, unequal areas (%u, %g refined)", lists.n, lists.refined);
    CHECK(fabs(lists.area_sum - plain.area_sum) < 1e-4 * plain.area_sum, "the surface area kept (%.6f vs %.6f)",
          lists.area_sum, plain.area_sum);
    CHECK(links.n == 2048 && links.refined == 0 && links.area_max == links.area_min,
          "links: --list-refine adds nothing (%u, %g refined)", links.n, links.refined);
    unlink(lists_path);
    unlink(links_path);
    unlink(plain_path);
    unlink(refined_path);
    rmdir(tmp);
    CHECK_DONE();
}
