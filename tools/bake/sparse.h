/* sparse: LightSkin's sparse scene points of a dynamic-object asset and each vertex's table of
 * its 8 nearest ones (Lensing & Broll 2013, ../shared/papers/lightskin-mixed-reality-gi.txt
 * §3.2, §3.3; what is stored: lc_lcb_sparse_point / lc_lcb_sparse_vertex in lcb/lcb.h).
 *
 * Points (lc_sparse_points): N per asset, evenly spread over its surface. 5 N candidates are
 * drawn area-weighted (triangle by area, uniform inside it; deterministic for the seed and
 * the asset index), then thinned to N by weighted sample elimination (Yuksel 2015, "Sample
 * Elimination for Generating Poisson Disk Sample Sets": weights (1 - d/2r_max)^8 over
 * Euclidean distance, r_max = sqrt(A / (2 sqrt(3) N)), weight limiting with beta 0.65,
 * gamma 1.5), so the spacing is nearly even whatever the tessellation; assets with fewer
 * vertices or triangles than N still get N points. A point's normal is the geometric normal
 * of the triangle it lies on (counter-clockwise front, as imported), not the interpolated
 * vertex normal: smoothed normals of a coarse mesh (a cube's corners) would tilt the
 * occluder discs. The occluder-disc radius (§3.3) is the largest distance from the point to
 * an asset vertex whose nearest point it is (its Voronoi region among the vertices); a point
 * whose region holds no vertex (or only vertices at the point itself) gets sqrt(A / (pi N)),
 * the radius of N discs that together have the asset's area.
 *
 * Tables (lc_sparse_vertex_table): per vertex its 8 nearest points, nearest first (ties by
 * index), weighted by eq. 12 w_j = (1 - d_j/d_max) clamp(n_v . n_j, 0, 1), d_max the largest
 * of the 8 distances, normalised to sum 1. When every weight is 0 (each of the 8 faces away,
 * or fewer than 2 distinct distances) the nearest point gets weight 1. With fewer than 8
 * points the nearest is repeated with weight 0.
 *
 * Nearest-point queries use a hashed uniform grid with ring search (exact; a query that finds
 * too little within 8 rings falls back to a scan). Single-threaded: 100k vertices x 256
 * points take tens of milliseconds. */
#ifndef LC_SPARSE_H
#define LC_SPARSE_H
#include <stddef.h>
#include <stdint.h>

#include "lcb/lcb.h"

#define LC_SPARSE_MAX_POINTS 65535u /* per asset: AVNN indices are u16 */
#define LC_SPARSE_NEIGHBOURS 8
#define LC_SPARSE_CANDIDATES 5 /* candidates per point before elimination */

typedef struct lc_sparse_stats {
    double seconds;                   /* lc_sparse_points, resp. lc_sparse_vertex_table */
    double area;                      /* the asset's surface area, m^2 (lc_sparse_points) */
    uint32_t candidates;              /* area-weighted candidates thinned to the points */
    uint32_t empty_regions;           /* points with the area radius (no vertex nearest to them) */
    uint32_t fallback_vertices;       /* table: vertices whose eq. 12 weights were all zero */
    double min_spacing, mean_spacing; /* nearest-neighbour distances among the points */
} lc_sparse_stats;

/* n (1..65535) points on the asset's triangles (idx: 3 per triangle, indices < nv) into out
 * (n records, asset set to `asset`). Returns 0, or -1 with err set: bad arguments, no
 * triangle with area, a non-finite vertex, out of memory. */
int lc_sparse_points(const lc_lcb_asset_vertex *v, uint32_t nv, const uint32_t *idx, uint32_t nt, uint32_t n,
                     uint32_t seed, uint32_t asset, lc_lcb_sparse_point *out, lc_sparse_stats *st, char *err,
                     size_t errlen);

/* The nv vertices' tables over np (1..65535) points into out (nv records). Vertex normals are
 * normalised here (a zero normal faces nothing: the nearest point alone). Returns 0, or -1
 * with err set. */
int lc_sparse_vertex_table(const lc_lcb_asset_vertex *v, uint32_t nv, const lc_lcb_sparse_point *pts, uint32_t np,
                           lc_lcb_sparse_vertex *out, lc_sparse_stats *st, char *err, size_t errlen);

#endif
