/* exposure: surfel areas become a_i * max(u_i / mean u, floor), renormalised to the same
 * total (mean u scaled to each surfel's area when areas differ); node areas are the sums of their surfels; every link keeps its solid angle
 * (factor * node area) and its LKSH record scales with it; nothing seen is an error. */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "bake/exposure.h"
#include "check.h"
#include "util/half.h"

static int near(double a, double b, double rel) { return fabs(a - b) <= rel * fmax(fabs(a), fabs(b)); }

/* 4 surfels of area 1 under a balanced tree in BFS order: root 0, internal 1 [0,2) and 2
 * [2,4), leaves 3..6. */
static void tree(lc_lcb_surfel s[4], lc_lcb_node nd[7], lc_hierarchy *h, uint32_t levels[4]) {
    memset(s, 0, 4 * sizeof *s);
    memset(nd, 0, 7 * sizeof *nd);
    for (int i = 0; i < 4; i++) s[i].area = 1.0f;
    nd[0] = (lc_lcb_node){.area = 4, .child = {1, 2}, .first_surfel = 0, .surfel_count = 4};
    nd[1] = (lc_lcb_node){.area = 2, .child = {3, 4}, .first_surfel = 0, .surfel_count = 2};
    nd[2] = (lc_lcb_node){.area = 2, .child = {5, 6}, .first_surfel = 2, .surfel_count = 2};
    for (uint32_t i = 0; i < 4; i++)
        nd[3 + i] = (lc_lcb_node){.area = 1, .child = {LC_NONE, LC_NONE}, .first_surfel = i, .surfel_count = 1};
    levels[0] = 0, levels[1] = 1, levels[2] = 3, levels[3] = 7;
    *h = (lc_hierarchy){.nodes = nd, .n_nodes = 7, .levels = levels, .n_levels = 3};
}

int main(void) {
    lc_lcb_surfel s[4];
    lc_lcb_node nd[7];
    lc_hierarchy h;
    uint32_t levels[4];
    tree(s, nd, &h, levels);
    const uint32_t seen[4] = {0, 2, 4, 2}; /* mean 2: u = 0 (floored), 1, 2, 1 */
    lc_lcb_link links[4] = {{0, 0.5f, 0}, {1, 0.25f, 0}, {5, 2.0f, 0}, {0, 0.0f, 0} /* padding */};
    uint16_t sh[4 * 4];
    for (int i = 0; i < 16; i++) sh[i] = lc_half_from_float(1.0f);
    double omega_before[3];
    for (int j = 0; j < 3; j++) omega_before[j] = (double)links[j].factor * M_PI * nd[links[j].node].area;

    lc_exposure_stats st;
    CHECK(lc_exposure_apply(seen, s, 4, &h, links, 4, sh, 4, &st) == 0, "apply");
    CHECK(st.unseen == 1 && st.unseen_area == 1.0, "one unseen surfel of area 1 (got %u, %g)", st.unseen,
          st.unseen_area);
    double norm = 4.0 / (LC_EXPOSURE_FLOOR + 1 + 2 + 1);
    const double want[4] = {LC_EXPOSURE_FLOOR * norm, norm, 2 * norm, norm};
    double sum = 0;
    for (int i = 0; i < 4; i++) {
        CHECK(near(s[i].area, want[i], 1e-6), "surfel %d area %g, want %g", i, s[i].area, want[i]);
        sum += s[i].area;
    }
    CHECK(near(sum, 4.0, 1e-6), "total area kept (%g)", sum);
    CHECK(near(nd[0].area, sum, 1e-6) && near(nd[1].area, want[0] + want[1], 1e-6) &&
              near(nd[2].area, want[2] + want[3], 1e-6) && near(nd[5].area, want[2], 1e-6),
          "node areas are their surfels' sums");
    for (int j = 0; j < 3; j++) {
        double omega = (double)links[j].factor * M_PI * nd[links[j].node].area;
        CHECK(near(omega, omega_before[j], 1e-6), "link %d keeps its solid angle (%g vs %g)", j, omega,
              omega_before[j]);
    }
    CHECK(links[3].factor == 0.0f, "padding link untouched");
    /* LKSH of link 1 (node 1: area 2 -> want[0] + want[1]) scales by the same ratio */
    double ratio1 = 2.0 / (want[0] + want[1]);
    CHECK(near(lc_half_to_float(sh[4]), ratio1, 2e-3), "LKSH scaled by the area ratio (%g vs %g)",
          lc_half_to_float(sh[4]), ratio1);
    CHECK(lc_half_to_float(sh[12]) == 1.0f, "padding LKSH untouched");

    /* Unequal areas (--surfel-refine): a surfel three times larger that three times as many
     * caches see is seen as widely per area, so the areas stay (a_i * u_i would give 1 : 9). */
    tree(s, nd, &h, levels);
    const uint32_t by_area[4] = {1, 3, 1, 3};
    for (int i = 0; i < 4; i++) s[i].area = (float)by_area[i];
    CHECK(lc_exposure_apply(by_area, s, 4, &h, links, 4, NULL, 0, &st) == 0, "apply");
    for (int i = 0; i < 4; i++)
        CHECK(near(s[i].area, by_area[i], 1e-6), "surfel %d of area %u seen by %u caches keeps its area (%g)", i,
              by_area[i], by_area[i], s[i].area);

    tree(s, nd, &h, levels);
    const uint32_t none[4] = {0, 0, 0, 0};
    CHECK(lc_exposure_apply(none, s, 4, &h, links, 4, NULL, 0, &st) == -1, "nothing seen is an error");
    CHECK(st.unseen == 4 && s[0].area == 1.0f, "and leaves the surfels alone");
    CHECK_DONE();
}
