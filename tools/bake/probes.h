/* probes: the bake half of the probes solver (Silvennoinen & Lehtinen 2017, "Real-time
 * global illumination by precomputed local reconstruction from sparse radiance probes", as
 * the thesis in ../shared/papers/sparse-radiance-probes-thesis.txt describes it; the file
 * format and the runtime's equations are in lcb/lcb.h, "The probes solver").
 *
 *   1. placement: free-space voxels near surfaces (no back face seen), thinned to the
 *      target count by removing the densest candidate (kernel 2t^3 - 3t^2 + 1), so the
 *      probes spread evenly (thesis 3.2.2.1);
 *   2. relight rays: per probe the surfel each of n_rays spherical-Fibonacci rays hits;
 *   3. support: one radius r, the mean distance from a receiver to its overlaps-th nearest
 *      probe (thesis 3.2.2.2); a receiver uses the probes within r that see any of its hit
 *      points, then (up to overlaps, from its 2 x overlaps nearest) those that see most of
 *      the hits no chosen probe sees (under a table the probes above it see nothing), at
 *      least 4, weighted w(d / r_x);
 *   4. transport (thesis eqs 4-7, with the cosine the thesis's estimator drops): per
 *      receiver, rays (cosine-weighted hemisphere for texel caches, the sphere for grid
 *      caches); at each hit y the probes that see y share it by weight,
 *        row[i][j] += ray weight * w_i V_i(y) / sum_k w_k V_k(y) * y_j(direction p_i -> y),
 *      a ray no supporting probe sees adds nothing (thesis 5.1.3.1);
 *   5. compression (CPCA, thesis 3.2.4): rows split by the widest axis of their bounding box
 *      until at most cluster_rows; per cluster the truncated SVD (eigenvectors of the Gram
 *      matrix A A^T, LAPACKE_dsyevr) with the smallest rank whose relative Frobenius error
 *      sqrt(sum of the dropped s_i^2 / sum of all s_i^2) is below svd_error (the thesis sums
 *      s_i, not their squares), else the cluster splits again.
 * Texel caches have one row (irradiance for their normal); grid caches nine (the L2
 * irradiance SH), clustered per coefficient. Caches flagged inside geometry get none.
 *
 * Deterministic for a seed whatever the thread count (every item seeded by its index;
 * clusters are compressed independently and kept in the order of their rows).
 * Threads: lc_probebake_run runs on the caller's thread with lc_parallel_for inside; the
 * ray structure is read-only. Ownership: the result owns its arrays (lc_probebake_release). */
#ifndef LC_PROBES_BAKE_H
#define LC_PROBES_BAKE_H
#include <stddef.h>
#include <stdint.h>

#include "bake/rt.h"
#include "lcb/lcb.h"

/* Which receivers gather their unseen rays (the order of --probe-unseen off|grid|all). */
typedef enum { LC_PROBE_UNSEEN_OFF = 0, LC_PROBE_UNSEEN_GRID, LC_PROBE_UNSEEN_ALL } lc_probe_unseen;

typedef struct lc_probebake_params {
    uint32_t count;         /* target probes; 0: density x the scene's bounding volume, at least
                               one per 400 texel caches and 8 */
    double density;         /* probes per m^3 when count is 0 (thesis 3.1.1: about 0.02) */
    uint32_t relight_rays;  /* per probe (thesis: 512) */
    uint32_t sh_bands;      /* probe SH bands (thesis: order 7 = 8 bands) */
    uint32_t overlaps;      /* probes per receiver (thesis: N_OVERLAPS = 10) */
    uint32_t receiver_rays; /* per receiver */
    uint32_t cluster_rows;  /* rows per cluster at most (thesis: 1024) */
    uint32_t max_rank;      /* SVD rank at most (thesis: 32) */
    double svd_error;       /* relative Frobenius truncation error per cluster (band-weighted) */
    double band_weight;     /* the SVD weighs SH band l by (l + 1)^-band_weight; 0: plain Frobenius */
    int visibility;         /* 1: V_i as the thesis; 0: V_i = 1 (naive weights, for the leak test) */
    int unseen;             /* LC_PROBE_UNSEEN_*: whose rays no supporting probe sees gather from
                               their surfel (PRUF/PRUS); OFF: they add nothing (the thesis) */
    uint64_t seed;
    int threads;
} lc_probebake_params;

typedef struct lc_probebake {
    lc_lcb_probe_header header;
    lc_lcb_probe *probes;
    uint32_t *hits; /* n_probes * n_rays */
    lc_lcb_probe_cluster *clusters;
    uint32_t *cluster_probes;
    uint64_t n_cluster_probes;
    float *basis;
    uint64_t n_basis;
    lc_lcb_probe_row *rows;
    float *u;
    uint64_t n_u;
    uint32_t *unseen_first; /* n_rows + 1 (NULL when params.unseen is 0) */
    lc_lcb_probe_unseen *unseen;
    uint64_t n_unseen;
    /* what the bake reports */
    uint32_t n_candidates;     /* free-space voxels before thinning */
    double seconds[4];         /* placement, relight rays, transport, compression */
    uint64_t rays;             /* every ray traced (primary and visibility) */
    double orphan_fraction[2]; /* receiver rays that hit a surface no supporting probe sees: texel, grid */
    double mean_rank;          /* over clusters */
    double worst_error;        /* the largest cluster truncation error */
    double mean_probes_used;   /* supporting probes per receiver */
} lc_probebake;

/* Bakes the probes solver for the caches (positions already relocated) of a scene with
 * bounds [bmin, bmax]. 0, or -1 with err set (bad parameters, no free space, out of memory). */
int lc_probebake_run(const lc_rt *rt, const float bmin[3], const float bmax[3], const lc_lcb_surfel *surfels,
                     uint32_t n_surfels, const lc_lcb_cache *caches, uint32_t n_caches, const lc_probebake_params *prm,
                     lc_probebake *out, char *err, size_t errlen);
void lc_probebake_release(lc_probebake *b);

/* One receiver's exact transport (stage 4 alone; for tests): the cache against the given
 * probes with the support radius given, its rays that no probe sees dropped. rows: 1 (texel
 * cache) or 9 (grid cache) rows of prm->overlaps x sh_bands^2 floats, the support's probe
 * indices in sup (prm->overlaps). Returns the support's size, or -1 (bad parameters, no
 * memory). */
int lc_probebake_transport(const lc_rt *rt, const lc_lcb_probe *probes, uint32_t n_probes, float radius,
                           const lc_lcb_cache *cache, const lc_probebake_params *prm, float *rows, uint32_t *sup);

#endif
