/* lcb: the bake file (.lcb) — a versioned, checksummed, mmap-able container.
 *
 * Layout (all little-endian):
 *   [0, 64)            lc_lcb_header
 *   [64, 64+48*n)      section table, n = header.section_count
 *   sections           each at a 64-byte aligned offset, covered by its CRC-32
 * A reader rejects: wrong magic, another major version, a header/table CRC mismatch, a
 * section outside the file or misaligned or overlapping, a section CRC mismatch (named),
 * a record size or count that disagrees with the metadata, and any index that points
 * outside its target array. After lc_lcb_open() succeeds every index in the view is valid
 * and every float is finite, so consumers need no further checks.
 *
 * Sections (fourcc, record):
 *   META  JSON text: settings, statistics, lightmap/grid dimensions, initial lights, assets
 *   MATL  lc_lcb_material      per material
 *   VERT  lc_lcb_vertex        static geometry vertices (with lightmap UV)
 *   TRIS  lc_lcb_triangle      static geometry triangles
 *   SURF  lc_lcb_surfel        surfels, in hierarchy leaf order
 *   NODE  lc_lcb_node          hierarchy, BFS order: node 0 = root, children after parents
 *   LEVL  uint32_t             BFS level start offsets into NODE (n_levels + 1 entries)
 *   CACH  lc_lcb_cache         caches: texel caches first, then grid caches
 *   LMAP  uint32_t             lightmap W*H, row 0 = top (v = 0): cache index or LC_NONE;
 *                              a texel owns its cache when cache.index == texel index,
 *                              otherwise it is a dilated copy of a neighbour
 *   GRID  uint32_t             grid samples dims[0]*dims[1]*dims[2] (x fastest): cache index
 *   LINK  lc_lcb_link          links_per_cache per cache, cache-major
 *   LKSH  uint16_t (half)      optional: per link, bands^2 projected SH transport
 *   GLNK  lc_lcb_link          optional (--grid-links): META /links/grid_per_cache links per grid
 *                              cache, grid-cache-major; grid caches then gather from these (their
 *                              link_count counts them) and their LINK slots are all padding
 *                              (a reader without GLNK refuses it where link_count > per_cache)
 *   ASET  lc_lcb_asset         dynamic-object assets
 *   AVRT  lc_lcb_asset_vertex  asset vertices (asset-local, metres)
 *   AIDX  uint32_t[3]          asset triangles (indices relative to the asset's first vertex)
 *   ATRN  lc_lcb_transfer      optional: per asset with DNRT transfer data, its grid's header
 *   ATRD  int8_t               the transfer grids' quantised values (ATRN says where each starts)
 *   ASPT  lc_lcb_sparse_point  optional: LightSkin sparse points, asset-local, sorted by asset
 *   AVNN  lc_lcb_sparse_vertex per AVRT vertex, its 8 nearest sparse points (iff ASPT)
 *   PRBH  lc_lcb_probe_header  optional (the probes solver, --solver probes|both): 1 record
 *   PRBP  lc_lcb_probe         radiance probes in free space
 *   PRBR  uint32_t             per probe and relight ray (probe-major): the surfel hit, LC_NONE
 *   PRCL  lc_lcb_probe_cluster receiver clusters with their truncated SVD
 *   PRCP  uint32_t             each cluster's probes (the column order of its basis)
 *   PRCB  float                each cluster's basis S V^T: rank x (probes x coefficients)
 *   PRRW  lc_lcb_probe_row     receiver rows, cluster by cluster
 *   PRRU  float                each cluster's U: rows x rank, row-major
 *   PRUF  uint32_t             optional with the probes: per PRRW row, its first PRUS entry, and
 *                              one more (the end); PRUF and PRUS come together
 *   PRUS  lc_lcb_surfel_weight per row, the surfels its unseen rays hit (rows in PRRW order)
 *   TSGF  uint32_t             optional (--texel-gather surfels): per texel cache, its first TSGW
 *                              entry, and one more (the end); TSGF and TSGW come together
 *   TSGW  lc_lcb_surfel_weight per texel cache, the surfels its gather rays hit: the PIC solver
 *                              then gathers texel caches per surfel, E = sum weight B, not by links
 * PIC (links) and probes are two solvers of the same quantities; a bake may carry both
 * (LINK is then present but may hold zero links per cache for --solver probes).
 * Optional sections were added without a version change (the minor stays 0): a reader that
 * does not know one skips it, and a bake without one stays valid.
 */
#ifndef LC_LCB_H
#define LC_LCB_H
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#define LC_LCB_MAGIC "LUCENTB\x1a"
#define LC_LCB_VERSION_MAJOR 1
#define LC_LCB_VERSION_MINOR 0
#define LC_LCB_ALIGN 64
#define LC_LCB_MAX_SECTIONS 64
#ifndef LC_NONE
#define LC_NONE 0xFFFFFFFFu
#endif

typedef struct lc_lcb_header {
    char magic[8];
    uint16_t version_major, version_minor;
    uint32_t section_count;
    uint64_t file_size;
    uint64_t table_offset; /* 64 */
    uint32_t table_crc;    /* CRC-32 of the section table */
    uint32_t flags;        /* 0 */
    uint8_t reserved[20];
    uint32_t header_crc; /* CRC-32 of bytes [0, 60) */
} lc_lcb_header;

typedef struct lc_lcb_section {
    char id[4];
    uint32_t record_size; /* bytes per record; 1 for text */
    uint64_t offset;      /* from file start, multiple of LC_LCB_ALIGN */
    uint64_t size;        /* bytes = count * record_size */
    uint64_t count;
    uint32_t crc; /* CRC-32 of the section bytes */
    uint32_t flags;
    uint8_t reserved[8];
} lc_lcb_section;

typedef struct lc_lcb_material {
    char name[64];       /* NUL-terminated */
    float base_color[3]; /* linear */
    float emission[3];   /* nits */
    uint32_t flags;      /* bit 0: textured base colour */
    uint32_t reserved;
} lc_lcb_material;

typedef struct lc_lcb_vertex {
    float position[3];
    float normal[3];
    float uv1[2]; /* lightmap UV, glTF convention */
} lc_lcb_vertex;

typedef struct lc_lcb_triangle {
    uint32_t v[3];
    uint32_t material;
} lc_lcb_triangle;

typedef struct lc_lcb_surfel {
    float position[3];
    float normal[3];
    float albedo[3];
    float emission[3]; /* nits, as baked (material emission x texture) */
    float area;        /* m^2; with --exposure the effective area (exposure.h), same total */
    uint32_t material;
    uint32_t cache; /* nearest cache (for multi-bounce feedback), LC_NONE if none */
    uint32_t reserved;
} lc_lcb_surfel;

typedef struct lc_lcb_node {
    float center[3];       /* area-weighted centroid */
    float area;            /* sum of surfel areas below */
    float normal[3];       /* area-weighted mean normal, NOT renormalised: length = coherence */
    float radius;          /* bounding sphere radius around center */
    uint32_t child[2];     /* LC_NONE for leaves */
    uint32_t first_surfel; /* subtree surfels are [first_surfel, first_surfel + surfel_count) */
    uint32_t surfel_count;
} lc_lcb_node;

enum {
    LC_CACHE_TEXEL = 1u << 0,
    LC_CACHE_GRID = 1u << 1,
    LC_CACHE_MOVED = 1u << 2,  /* relocated out of geometry */
    LC_CACHE_INSIDE = 1u << 3, /* inside geometry and could not be moved: no links */
};

typedef struct lc_lcb_cache {
    float position[3];
    float normal[3]; /* texel caches: surface normal; grid caches: zero (full sphere) */
    float albedo[3]; /* texel caches: surface albedo; grid: zero */
    uint32_t flags;
    uint32_t index;      /* texel index (y*W + x) or grid sample index */
    uint32_t link_count; /* links in use (lc_lcb_cache_links): the row's slots from link_count on are padding */
} lc_lcb_cache;

/* A link for runtime projection: cache radiance SH gains
 *   L_lm += flux(node) * factor * h_l(cos alpha) * y_lm(dir)
 * with h_l from lc_sh_cone_ratio(). factor = visible solid angle / (pi * node area).
 * Padding links (when fewer visible nodes than links_per_cache) have factor 0, node 0, and
 * come after the cache's link_count used links, so a runtime may stop at link_count. */
typedef struct lc_lcb_link {
    uint32_t node;
    float factor;
    uint32_t dir_cone; /* bits 0-11, 12-23: octahedral direction; bits 24-31: alpha/pi*255 */
} lc_lcb_link;

/* Links per grid cache in GLNK, at most (LINK's per cache: 1024). */
#define LC_LCB_GRID_LINKS_MAX 4096u

typedef struct lc_lcb_asset {
    char name[64];
    uint32_t first_vertex, vertex_count;
    uint32_t first_triangle, triangle_count;
    float bounds_min[3], bounds_max[3];
    float albedo[3]; /* area-weighted mean */
    uint32_t reserved;
} lc_lcb_asset;

typedef struct lc_lcb_asset_vertex {
    float position[3];
    float normal[3];
    float albedo[3];
} lc_lcb_asset_vertex;

/* An asset's DNRT transfer grid (daemon/engine/dnrt.h uses it; tools/bake/transfer.h makes it):
 * dims^3 vertices on a cube of half side half_extent about center, in asset-local metres,
 * vertex (i, j, k) at center - half_extent + 2 half_extent (i, j, k) / (dims - 1), x fastest.
 * Each vertex holds, for the SH basis y_0..y_{coeffs-1} (lucent convention, util/sh.h),
 *   T_j (RGB) = int_D rho(s)/pi * y_j(n_s) (w.n_o) dw    light the object reflects, per unit
 *                                                        of its irradiance SH coefficient j
 *   K_j       = int_D y_j(w)/pi (w.n_o) dw               light it blocks (A6: L = I(w)/pi)
 * over D, the directions from the vertex that hit the asset; n_o points from the vertex to
 * center and s is the hit, n_s its normal facing the vertex. The irradiance change at a
 * receiver with normal n is (n_o.n)+ [sum_j c_tot_j T_j - sum_j c_j K_j] (c: the object's
 * incident irradiance SH, c_tot with its direct light, both in the asset's frame).
 * Stored values are multiplied by g = (max(|p - center|, radius) / radius)^2, which takes the
 * 1/d^2 falloff out (better use of 8 bits, and the outer volume's falloff is the division),
 * quantised as value = q / 127 * scale, q in [-127, 127]; vertices inside the asset are
 * filled from their outside neighbours. A record: coeffs*3 T values (RGB per coefficient),
 * then coeffs K values. */
typedef struct lc_lcb_transfer {
    uint32_t asset;       /* index into ASET; at most one record per asset */
    uint32_t dims;        /* vertices per axis, 2..64 */
    uint32_t coeffs;      /* SH coefficients per term: 4 or 9 */
    uint32_t rays;        /* rays per vertex the bake traced (information) */
    float center[3];      /* the bounding sphere's centre, asset-local */
    float radius;         /* its radius (> 0) */
    float half_extent;    /* the inner volume: the grid's cube, half side (> 0) */
    float outer_radius;   /* the effect ends at this distance from center (>= half_extent) */
    float t_scale[27];    /* per coefficient and channel: T = q / 127 * t_scale[3 j + ch] */
    float k_scale[9];     /* K = q / 127 * k_scale[j] */
    uint64_t data_offset; /* byte offset of vertex 0 in ATRD */
} lc_lcb_transfer;

/* A LightSkin sparse scene point (Lensing & Broll 2013 §3.2; tools/bake/sparse.h makes them):
 * on the asset's surface, in asset-local metres, with the geometric normal of the triangle it
 * lies on (unit) and its occluder-disc radius (§3.3: the largest distance to an asset vertex
 * whose nearest point it is, or sqrt(asset area / (pi N)) when no vertex is). ASPT is sorted
 * by asset; an asset's points are contiguous (lc_lcb_asset_sparse finds them), at most 65535. */
typedef struct lc_lcb_sparse_point {
    uint32_t asset; /* index into ASET */
    float position[3];
    float normal[3];
    float radius; /* > 0 */
} lc_lcb_sparse_point;

/* Per asset vertex (AVNN, in AVRT order): its 8 nearest sparse points, nearest first, as
 * indices among the asset's points, with the weights of §3.2 eq. 12
 *   w_j = (1 - d_j / d_max) * clamp(n_v . n_j, 0, 1),  d_max = max_j d_j,
 * normalised to sum 1 (all zero: the nearest point alone, weight 1). Fewer than 8 points:
 * the nearest repeated with weight 0. An asset without points has all-zero records. */
typedef struct lc_lcb_sparse_vertex {
    uint16_t index[8];
    float weight[8];
} lc_lcb_sparse_vertex;

/* The probes solver (Silvennoinen & Lehtinen 2017; tools/bake/probes.h bakes it,
 * daemon/engine/probes.h runs it). A pass, from the surfels' radiosity B:
 *   probe SH   lambda[p][j] = (4 pi / n_rays) sum_k B[hit(p,k)] / pi * y_j(dir_k)
 *              (dir_k = lc_probe_ray_dir(k, n_rays), the same for every probe; a miss adds 0)
 *   basis      b[c][r] = sum_col PRCB[c][r][col] lambda[PRCP[c][col / coeffs]][col % coeffs]
 *   receivers  value[row] = sum_r PRRU[c][row][r] b[c][r]
 *              + sum_{e in PRUF[row]..PRUF[row+1]} PRUS[e].weight B[PRUS[e].surfel]
 * The second sum gathers a receiver's unseen rays: those whose hit point none of its supporting
 * probes sees (under a table, behind a pillar), which the probes cannot reconstruct; each goes
 * straight to the surfel it hit (weight: the ray's share of the row / pi, summed per surfel).
 * A row of a texel cache (coeff 0) is the irradiance E for the cache normal; a grid cache has
 * 9 rows, coeff j the cosine-convolved L2 irradiance SH coefficient E_j = A_l L_j. RGB
 * throughout (the matrices are shared by the channels). */
typedef struct lc_lcb_probe_header {
    uint32_t n_probes;      /* PRBP records, >= 1 */
    uint32_t n_rays;        /* relight rays per probe, 1..65536 */
    uint32_t sh_bands;      /* the probes' SH bands, 1..LC_LCB_PROBE_MAX_BANDS; coeffs = bands^2 */
    uint32_t n_clusters;    /* PRCL records */
    uint32_t n_rows;        /* PRRW records */
    uint32_t max_rank;      /* the largest cluster rank, 1..LC_LCB_PROBE_MAX_RANK */
    uint32_t overlaps;      /* the most probes one receiver uses (information) */
    uint32_t receiver_rays; /* rays per receiver the bake traced (information) */
    float support_radius;   /* metres (information) */
    float svd_error;        /* the truncation error each cluster met, relative Frobenius (information) */
    uint32_t reserved[6];
} lc_lcb_probe_header;

#define LC_LCB_PROBE_MAX_BANDS 8
#define LC_LCB_PROBE_MAX_RANK 256

typedef struct lc_lcb_probe {
    float position[3];
    uint32_t reserved;
} lc_lcb_probe;

typedef struct lc_lcb_probe_cluster {
    uint32_t first_row, n_rows;     /* its rows in PRRW, >= 1 */
    uint32_t first_probe, n_probes; /* its probes in PRCP, >= 1 */
    uint32_t rank;                  /* 1..max_rank */
    uint32_t reserved;
    uint64_t basis_offset; /* floats into PRCB: rank x (n_probes x coeffs) */
    uint64_t u_offset;     /* floats into PRRU: n_rows x rank */
} lc_lcb_probe_cluster;

/* One surfel of a gather list (PRUS, TSGW): the value it adds per unit of its radiosity. */
typedef struct lc_lcb_surfel_weight {
    uint32_t surfel; /* SURF index */
    float weight;    /* the row's value per unit of the surfel's radiosity B */
} lc_lcb_surfel_weight;
typedef lc_lcb_surfel_weight lc_lcb_probe_unseen;

typedef struct lc_lcb_probe_row {
    uint32_t cache; /* CACH index */
    uint32_t coeff; /* texel cache: 0; grid cache: 0..8 */
} lc_lcb_probe_row;

/* Relight ray k of n (the same set for every probe): a spherical Fibonacci point, so the
 * directions cover the sphere evenly and need not be stored. */
static inline void lc_probe_ray_dir(uint32_t k, uint32_t n, float d[3]) {
    const double golden = 2.399963229728653; /* pi (3 - sqrt 5) */
    double z = 1.0 - (2.0 * k + 1.0) / (double)n, r = sqrt(fmax(0.0, 1.0 - z * z)), phi = golden * (double)k;
    d[0] = (float)(r * cos(phi));
    d[1] = (float)(r * sin(phi));
    d[2] = (float)z;
}

static inline uint64_t lc_lcb_transfer_bytes(const lc_lcb_transfer *t) {
    return (uint64_t)t->dims * t->dims * t->dims * t->coeffs * 4u;
}

_Static_assert(sizeof(lc_lcb_header) == 64, "header layout");
_Static_assert(sizeof(lc_lcb_section) == 48, "section layout");
_Static_assert(sizeof(lc_lcb_material) == 96, "material layout");
_Static_assert(sizeof(lc_lcb_vertex) == 32, "vertex layout");
_Static_assert(sizeof(lc_lcb_triangle) == 16, "triangle layout");
_Static_assert(sizeof(lc_lcb_surfel) == 64, "surfel layout");
_Static_assert(sizeof(lc_lcb_node) == 48, "node layout");
_Static_assert(sizeof(lc_lcb_cache) == 48, "cache layout");
_Static_assert(sizeof(lc_lcb_link) == 12, "link layout");
_Static_assert(sizeof(lc_lcb_asset) == 120, "asset layout");
_Static_assert(sizeof(lc_lcb_asset_vertex) == 36, "asset vertex layout");
_Static_assert(sizeof(lc_lcb_transfer) == 192, "transfer layout");
_Static_assert(sizeof(lc_lcb_sparse_point) == 32, "sparse point layout");
_Static_assert(sizeof(lc_lcb_sparse_vertex) == 48, "sparse vertex layout");
_Static_assert(sizeof(lc_lcb_probe_header) == 64, "probe header layout");
_Static_assert(sizeof(lc_lcb_probe) == 16, "probe layout");
_Static_assert(sizeof(lc_lcb_probe_cluster) == 40, "probe cluster layout");
_Static_assert(sizeof(lc_lcb_probe_row) == 8, "probe row layout");
_Static_assert(sizeof(lc_lcb_surfel_weight) == 8, "surfel weight layout");

/* --- link direction/cone packing ------------------------------------------------------- */

/* Octahedral encoding of a unit vector to two 12-bit values. */
static inline uint32_t lc_link_pack(const float dir[3], float alpha) {
    float ax = fabsf(dir[0]), ay = fabsf(dir[1]), az = fabsf(dir[2]);
    float s = ax + ay + az;
    float u = s > 0 ? dir[0] / s : 0, v = s > 0 ? dir[1] / s : 0;
    if (dir[2] < 0) {
        float uu = (1 - fabsf(v)) * (u >= 0 ? 1 : -1);
        float vv = (1 - fabsf(u)) * (v >= 0 ? 1 : -1);
        u = uu;
        v = vv;
    }
    uint32_t qu = (uint32_t)lrintf((u * 0.5f + 0.5f) * 4095.0f);
    uint32_t qv = (uint32_t)lrintf((v * 0.5f + 0.5f) * 4095.0f);
    if (alpha < 0) alpha = 0;
    if (alpha > (float)M_PI) alpha = (float)M_PI;
    uint32_t qa = (uint32_t)lrintf(alpha / (float)M_PI * 255.0f);
    return (qu & 0xFFFu) | (qv & 0xFFFu) << 12 | qa << 24;
}

static inline void lc_link_unpack(uint32_t packed, float dir[3], float *cos_alpha) {
    float u = (float)(packed & 0xFFFu) / 4095.0f * 2.0f - 1.0f;
    float v = (float)((packed >> 12) & 0xFFFu) / 4095.0f * 2.0f - 1.0f;
    float z = 1.0f - fabsf(u) - fabsf(v);
    if (z < 0) {
        float uu = (1 - fabsf(v)) * (u >= 0 ? 1 : -1);
        float vv = (1 - fabsf(u)) * (v >= 0 ? 1 : -1);
        u = uu;
        v = vv;
    }
    float len = sqrtf(u * u + v * v + z * z);
    dir[0] = u / len;
    dir[1] = v / len;
    dir[2] = z / len;
    *cos_alpha = cosf((float)(packed >> 24) / 255.0f * (float)M_PI);
}

/* --- writer ------------------------------------------------------------------------------ */

typedef struct lc_lcb_writer lc_lcb_writer;

lc_lcb_writer *lc_lcb_writer_create(void);
/* Adds a section. `data` is borrowed until lc_lcb_writer_write() returns. size must equal
 * count * record_size. Returns 0, or -1 (too many sections, duplicate id). */
int lc_lcb_writer_add(lc_lcb_writer *w, const char id[4], uint32_t record_size, const void *data, uint64_t count);
/* Writes the file atomically (temp + fsync + rename). Returns 0 or -1 with err set. */
int lc_lcb_writer_write(lc_lcb_writer *w, const char *path, char *err, size_t errlen);
void lc_lcb_writer_release(lc_lcb_writer *w);

/* --- reader ------------------------------------------------------------------------------ */

typedef struct lc_lcb lc_lcb; /* owns the mapping and the parsed metadata */

typedef struct lc_lcb_view {
    uint16_t version_major, version_minor;
    const char *meta_json; /* NUL-terminated copy of META */
    size_t meta_len;
    uint32_t sh_bands; /* default output bands from the bake settings */
    const lc_lcb_material *materials;
    uint32_t n_materials;
    const lc_lcb_vertex *vertices;
    uint32_t n_vertices;
    const lc_lcb_triangle *triangles;
    uint32_t n_triangles;
    const lc_lcb_surfel *surfels;
    uint32_t n_surfels;
    const lc_lcb_node *nodes;
    uint32_t n_nodes;
    const uint32_t *levels; /* n_levels + 1 offsets */
    uint32_t n_levels;
    const lc_lcb_cache *caches;
    uint32_t n_caches, n_texel_caches; /* texel caches are [0, n_texel_caches) */
    const uint32_t *lightmap;
    uint32_t lightmap_width, lightmap_height;
    const uint32_t *grid;
    uint32_t grid_dims[3];
    float grid_origin[3]; /* position of sample (0,0,0); sample i at origin + i * cell */
    float grid_cell;
    const lc_lcb_link *links;
    uint32_t links_per_cache;
    const lc_lcb_link *grid_links; /* GLNK: NULL when grid caches use their LINK slots */
    uint32_t grid_links_per_cache; /* 0 without GLNK */
    const uint16_t *link_sh;       /* NULL when absent */
    uint32_t link_sh_bands;
    const lc_lcb_asset *assets;
    uint32_t n_assets;
    const lc_lcb_asset_vertex *asset_vertices;
    uint32_t n_asset_vertices;
    const uint32_t *asset_indices; /* 3 per asset triangle */
    uint32_t n_asset_triangles;
    const lc_lcb_transfer *transfers; /* NULL when no asset has transfer data */
    uint32_t n_transfers;
    const int8_t *transfer_data;
    uint64_t transfer_data_size;
    const lc_lcb_sparse_point *sparse_points; /* NULL when the bake has none (ASPT) */
    uint32_t n_sparse_points;
    const lc_lcb_sparse_vertex *sparse_vertices; /* n_asset_vertices records when sparse_points */
    /* the probes solver (PRB*, PRC*, PRR*): probe_header NULL when the bake has none */
    const lc_lcb_probe_header *probe_header;
    const lc_lcb_probe *probes;
    const uint32_t *probe_hits; /* n_probes * n_rays */
    const lc_lcb_probe_cluster *probe_clusters;
    const uint32_t *probe_cluster_probes;
    uint64_t n_probe_cluster_probes;
    const float *probe_basis;
    uint64_t n_probe_basis;
    const lc_lcb_probe_row *probe_rows;
    const float *probe_u;
    uint64_t n_probe_u;
    const uint32_t *probe_unseen_first;      /* n_rows + 1, or NULL (a bake without PRUF/PRUS) */
    const lc_lcb_probe_unseen *probe_unseen; /* probe_unseen_first[n_rows] entries */
    /* texel caches gathered per surfel (TSGF/TSGW), NULL when the bake gathers them by links */
    const uint32_t *texel_surfels_first;       /* n_texel_caches + 1 */
    const lc_lcb_surfel_weight *texel_surfels; /* texel_surfels_first[n_texel_caches] entries */
} lc_lcb_view;

/* Cache c's links (LINK, or GLNK for a grid cache when the bake has it): link_count of them
 * are used; *per_cache (optional) gets the row's length. */
static inline const lc_lcb_link *lc_lcb_cache_links(const lc_lcb_view *v, uint32_t c, uint32_t *per_cache) {
    if (v->grid_links && c >= v->n_texel_caches) {
        if (per_cache) *per_cache = v->grid_links_per_cache;
        return v->grid_links + (size_t)(c - v->n_texel_caches) * v->grid_links_per_cache;
    }
    if (per_cache) *per_cache = v->links_per_cache;
    return v->links + (size_t)c * v->links_per_cache;
}

/* The asset's DNRT transfer grid, or NULL (no data: an older bake, or baked without). */
static inline const lc_lcb_transfer *lc_lcb_asset_transfer(const lc_lcb_view *v, uint32_t asset) {
    for (uint32_t i = 0; i < v->n_transfers; i++)
        if (v->transfers[i].asset == asset) return &v->transfers[i];
    return NULL;
}

/* The asset's sparse points: sets [*first, *first + *count) in v->sparse_points and returns
 * *count (0: none, an older bake or --mr-points 0). AVNN indices are relative to *first. */
static inline uint32_t lc_lcb_asset_sparse(const lc_lcb_view *v, uint32_t asset, uint32_t *first, uint32_t *count) {
    uint32_t b[2];
    for (int k = 0; k < 2; k++) { /* the first point of an asset >= asset, resp. > asset */
        uint32_t lo = 0, hi = v->n_sparse_points;
        while (lo < hi) {
            uint32_t mid = lo + (hi - lo) / 2;
            uint32_t a = v->sparse_points[mid].asset;
            if (k ? a <= asset : a < asset) lo = mid + 1;
            else hi = mid;
        }
        b[k] = lo;
    }
    *first = b[0];
    *count = b[1] - b[0];
    return *count;
}

/* Maps and validates a bake file. Errors name the section and the check that failed, e.g.
 * "LINK: CRC mismatch (file corrupted?)". Returns 0 or -1 with err set; never crashes on
 * any input. */
int lc_lcb_open(const char *path, lc_lcb **out, char *err, size_t errlen);
/* Same, over a caller buffer that must outlive the handle (used by fuzzing and tests). */
int lc_lcb_open_memory(const void *data, size_t len, lc_lcb **out, char *err, size_t errlen);
const lc_lcb_view *lc_lcb_get(const lc_lcb *f);
/* Section table access for `info`. */
uint32_t lc_lcb_section_count(const lc_lcb *f);
const lc_lcb_section *lc_lcb_section_at(const lc_lcb *f, uint32_t i);
void lc_lcb_close(lc_lcb *f);

/* `lucent-bake info`: prints counts, sizes per section and settings (human or JSON). */
#include <stdio.h>
void lc_lcb_print_info(const lc_lcb *f, const char *path, int json, FILE *out);

#endif
