/* bake options: the bake's settings and the option table that drives their flags, --help,
 * validation and the quality presets. Its own library (lc_bake_options, needing only
 * lc_util) so the lucent-bake front prints --help without loading the bake's dependencies. */
#ifndef LC_BAKE_OPTIONS_H
#define LC_BAKE_OPTIONS_H
#include <stddef.h>
#include <stdint.h>

#include "util/opt.h"

#define LC_BAKE_MAX_ASSETS 64
#define LC_BAKE_PATH_MAX 1024

typedef enum { LC_BAKE_SOLVER_PIC = 0, LC_BAKE_SOLVER_PROBES, LC_BAKE_SOLVER_BOTH } lc_bake_solver;

typedef enum { LC_QUALITY_DRAFT = 0, LC_QUALITY_MODERATE, LC_QUALITY_HIGH, LC_QUALITY_ULTRA } lc_bake_quality;

typedef struct lc_bake_asset_arg {
    char name[64];
    char path[LC_BAKE_PATH_MAX];
} lc_bake_asset_arg;

typedef struct lc_bake_settings {
    char input[LC_BAKE_PATH_MAX];
    char output[LC_BAKE_PATH_MAX];
    char glb[LC_BAKE_PATH_MAX];
    int write_glb;
    char stats_json[LC_BAKE_PATH_MAX];
    int quality;
    double scale;
    int flip_winding;
    double texel_density;
    double min_texel_density; /* fit mode: the atlas grows rather than go below this */
    int atlas_size;
    int padding;
    double chart_angle;
    int dilate;
    int surfels;
    int relax;
    int drop_buried;      /* drop surfels inside geometry (changes the surfel count) */
    double surfel_refine; /* share of the surfels placed by bake/surfel_refine.h (0 = equal-area only) */
    double list_refine;   /* with texel surfel lists: this x --surfels more, placed by refinement */
    int exposure;         /* surfel areas weighted by how many caches see them (bake/exposure.h) */
    int hierarchy;
    int links;
    int grid_links;        /* links per grid cache in GLNK when above --links (lc_bake_grid_links) */
    int texel_gather;      /* LC_BAKE_TEXEL_GATHER_*: how PIC's texel caches gather */
    int texel_gather_rays; /* hemisphere rays per texel cache for its surfel list */
    int node_samples;
    int final_samples;
    int probe_rays;       /* per cache, at least (the budget below may raise it) */
    int probe_ray_budget; /* rays over all caches that small scenes may spend (0: exactly probe_rays) */
    int bands;
    int link_sh;
    double grid_cell;
    int grid_max_dim;
    int grid_max_samples;
    int reloc_rays;
    double reloc_offset;
    double grid_clearance; /* fraction of a grid cell */
    int seed;
    int threads;
    int quiet;
    int n_assets;
    lc_bake_asset_arg assets[LC_BAKE_MAX_ASSETS];
    int transfer;           /* bake each asset's DNRT transfer grid (bake/transfer.h) */
    int transfer_dims;      /* its vertices per axis */
    int transfer_sh;        /* 0: 4 SH coefficients, 1: 9 */
    int transfer_rays;      /* rays per vertex */
    double transfer_extent; /* inner half side in bounding radii */
    double transfer_outer;  /* outer radius / inner half side */
    int mr_points;          /* LightSkin sparse points per asset (bake/sparse.h), 0 = none */
    int solver;             /* LC_BAKE_SOLVER_*: which solvers' data the bake holds */
    int probes;             /* the probes solver (bake/probes.h): target count, 0 = from the density */
    double probe_density;   /* probes per m^3 of the scene's bounds when probes is 0 */
    int probe_relight_rays; /* per probe */
    int probe_bands;        /* the probes' SH bands */
    int probe_overlaps;     /* probes per receiver at most */
    int probe_receiver_rays;
    int probe_cluster; /* rows per cluster at most */
    int probe_rank;    /* SVD rank at most */
    double probe_svd_error;
    double probe_band_weight;
    int probe_visibility; /* the thesis's visibility match (off: the naive, leaking weights) */
    int probe_unseen;     /* LC_PROBE_UNSEEN_*: unseen receiver rays gathered from their surfels */
} lc_bake_settings;

/* --texel-gather, in the option's order. */
enum { LC_BAKE_TEXEL_GATHER_AUTO = 0, LC_BAKE_TEXEL_GATHER_LINKS, LC_BAKE_TEXEL_GATHER_SURFELS };
/* Whether texel caches get surfel lists (TSGF/TSGW): surfels, or auto when the probe-ray budget
 * is in force and did not raise the links' rays above --probe-rays (probe_rays: as used). */
int lc_bake_texel_surfels(const lc_bake_settings *s, uint32_t probe_rays);

/* Links per grid cache in their own section (GLNK), or 0 when grid caches keep --links in LINK
 * (--grid-links not above --links, --link-sh, the probes solver alone, no grid caches). */
uint32_t lc_bake_grid_links(const lc_bake_settings *s, uint32_t n_grid_caches);

/* Rays per texel cache for its surfel list: --texel-gather-rays, raised like the links' probe
 * rays (lc_bake_probe_rays) while n_texel_caches x rays stays within --probe-ray-budget. A sunlit
 * floor's texels see a few bright surfels that 256 rays hit unevenly (Sponza 17.2% at 256, 13.4%
 * at 1024 rays); Sibenik under point lights gains 0.3 points (bench/fidelity.md). */
uint32_t lc_bake_texel_gather_rays(const lc_bake_settings *s, uint32_t n_texel_caches);

/* The option table (NULL-terminated). */
const lc_opt *lc_bake_options(void);
/* Defaults, then the preset named by --quality (found in argv), then the flags.
 * Returns the number of positional arguments or -1 with err set. */
int lc_bake_parse_args(lc_bake_settings *s, int argc, char **argv, int start, char **positional, int max_pos, char *err,
                       size_t errlen);
/* Applies the preset's values (every field a preset controls). */
void lc_bake_apply_preset(lc_bake_settings *s, lc_bake_quality q);
/* Probe rays per cache for a bake of n_caches: --probe-rays, raised to the largest power of two
 * that keeps n_caches x rays within --probe-ray-budget (never above LC_BAKE_PROBE_RAYS_MAX).
 * The link solid angles near a cache come from its probe rays; their noise is what a small
 * scene's error is made of (the Cornell box: 1024 rays 5.9%, 8192 rays 2.9%; bench/fidelity.md),
 * while a large scene's stays with its surfels, so the bake time goes where it pays. */
#define LC_BAKE_PROBE_RAYS_MAX 8192
uint32_t lc_bake_probe_rays(const lc_bake_settings *s, uint32_t n_caches);

#endif
