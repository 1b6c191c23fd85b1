/* exposure: see exposure.h. */
#include "bake/exposure.h"

#include <stdlib.h>

#include "util/half.h"

int lc_exposure_apply(const uint32_t *seen, lc_lcb_surfel *surfels, uint32_t n_surfels, lc_hierarchy *h,
                      lc_lcb_link *links, uint64_t n_links, uint16_t *link_sh, uint32_t nsh, lc_exposure_stats *stats) {
    lc_exposure_stats st = {0};
    double area_sum = 0, seen_sum = 0;
    for (uint32_t i = 0; i < n_surfels; i++) {
        area_sum += surfels[i].area;
        seen_sum += (double)surfels[i].area * seen[i];
        if (!seen[i]) {
            st.unseen++;
            st.unseen_area += surfels[i].area;
        }
    }
    if (stats) *stats = st;
    if (!(seen_sum > 0) || !(area_sum > 0)) return -1;

    double *prefix = malloc(((size_t)n_surfels + 1) * sizeof *prefix);
    float *ratio = malloc((size_t)(h->n_nodes ? h->n_nodes : 1) * sizeof *ratio);
    if (!prefix || !ratio) {
        free(prefix);
        free(ratio);
        return -1;
    }
    /* a_i * u_i / mean(u), u floored; then renormalised so the total area is kept. u_i grows
     * with the surfel's own area (a larger surfel catches more caches' rays), so with unequal
     * areas (--surfel-refine) u_i is compared with the mean scaled to that area: the weight is
     * how widely the caches see the surface, not its size twice. */
    double mean = seen_sum / area_sum, mean_area = area_sum / n_surfels, weighted = 0;
    for (uint32_t i = 0; i < n_surfels; i++) {
        double u = seen[i] / (mean * (surfels[i].area / mean_area));
        if (u < LC_EXPOSURE_FLOOR) u = LC_EXPOSURE_FLOOR;
        surfels[i].area = (float)(surfels[i].area * u);
        weighted += surfels[i].area;
    }
    double norm = area_sum / weighted;
    prefix[0] = 0;
    for (uint32_t i = 0; i < n_surfels; i++) {
        surfels[i].area = (float)(surfels[i].area * norm);
        prefix[i + 1] = prefix[i] + surfels[i].area;
    }
    /* node areas from the surfel ranges; links keep their solid angle: factor * area fixed */
    for (uint32_t k = 0; k < h->n_nodes; k++) {
        lc_lcb_node *nd = &h->nodes[k];
        double a = prefix[nd->first_surfel + nd->surfel_count] - prefix[nd->first_surfel];
        ratio[k] = (float)(nd->area / a);
        nd->area = (float)a;
    }
    for (uint64_t j = 0; j < n_links; j++) {
        if (!(links[j].factor > 0)) continue;
        float r = ratio[links[j].node];
        links[j].factor *= r;
        if (link_sh)
            for (uint32_t c = 0; c < nsh; c++) {
                uint16_t *x = &link_sh[j * nsh + c];
                *x = lc_half_from_float(lc_half_to_float(*x) * r);
            }
    }
    free(prefix);
    free(ratio);
    return 0;
}
