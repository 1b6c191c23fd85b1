/* uvgen: lightmap UVs. Splits the mesh into charts (by normal and connectivity), projects
 * each chart to its plane, packs all charts into one atlas with padding, and rewrites the
 * mesh with vertices split along chart seams and mesh.uv1 filled. */
#ifndef LC_UVGEN_H
#define LC_UVGEN_H
#include <stddef.h>
#include <stdint.h>

#include "bake/scene.h"

typedef struct lc_uv_params {
    double texels_per_metre;     /* > 0: density mode; the atlas grows to fit */
    uint32_t atlas_size;         /* > 0 (and density 0): fit into atlas_size x atlas_size, density chosen;
                                when the charts cannot fit even at the minimum density the atlas grows
                                (x1.25 steps, warned) up to 8192 */
    double min_texels_per_metre; /* > 0 (fit mode): when fitting atlas_size would give a lower density,
                                    use this density instead (the atlas grows) */
    uint32_t padding;            /* empty texels between charts and at the border, >= 2 */
    double chart_angle_deg;      /* max normal deviation from the chart's projection normal, (0, 90);
                                sub-texel bevels merged into a neighbour may exceed it (up to 88) */
    int threads;                 /* parallel-for workers, 0 = all cores (the result does not depend on it) */
} lc_uv_params;

typedef struct lc_uv_stats {
    uint32_t n_charts;
    uint32_t width, height;  /* atlas in texels */
    double texels_per_metre; /* the density used */
    double usage;            /* texels covered by charts' footprints / atlas texels, in (0, 1] */
    /* World distance between neighbouring texel centres, sqrt(world area / texel area) of each
     * triangle, weighted by its texel area (what a texel-by-texel measure sees): mean, p95 and
     * max in metres (lc_uv_texel_spacing; both functions below fill them). */
    double spacing_mean, spacing_p95, spacing_max;
} lc_uv_stats;

/* Generates lightmap UVs (replacing any existing uv1). Returns 0 or -1 with err set (e.g.
 * the charts cannot fit even an 8192 atlas). */
int lc_uvgen(lc_mesh *mesh, const lc_uv_params *params, lc_uv_stats *stats, char *err, size_t errlen);

/* For meshes that already have uv1 from the asset: chooses the atlas size for the density or
 * takes atlas_size, and fills stats (usage from rasterized coverage). */
int lc_uvgen_measure(const lc_mesh *mesh, const lc_uv_params *params, lc_uv_stats *stats, char *err, size_t errlen);

/* Fills stats' spacing_* from mesh.uv1 in a W x H atlas. -1 out of memory. */
int lc_uv_texel_spacing(const lc_mesh *mesh, uint32_t W, uint32_t H, lc_uv_stats *stats);

#endif
