/* texels: lightmap texel caches. Rasterizes every triangle in lightmap UV space; each texel
 * centre inside a triangle becomes one cache (world position, shading normal, albedo);
 * then seams are dilated so bilinear filtering never reads an empty texel. */
#ifndef LC_TEXELS_H
#define LC_TEXELS_H
#include <stddef.h>
#include <stdint.h>

#include "bake/scene.h"
#include "lcb/lcb.h"

typedef struct lc_lightmap {
    uint32_t width, height;
    uint32_t *texel_cache; /* width*height; cache index or LC_NONE; row 0 = top (v = 0) */
    uint32_t n_covered;    /* texels owning a cache */
    uint32_t n_dilated;    /* texels filled by dilation */
} lc_lightmap;

/* Rasterizes scene->mesh (uv1 required) into a width x height lightmap. Texel (x, y) has its
 * centre at uv ((x + 0.5) / W, (y + 0.5) / H). A top-left fill rule makes each centre belong
 * to at most one triangle. Appends one lc_lcb_cache per covered texel (flags LC_CACHE_TEXEL,
 * index = y*W + x) to *caches (malloc'd, caller frees). Texel centres are tested exactly on
 * the float uv1. Every texel whose square overlaps a triangle (its footprint), and the ring one
 * texel around the footprint, that owns no centre takes the cache of the nearest covered
 * texel, reached through footprint texels; these count in n_dilated. Bilinear reads anywhere
 * inside a triangle then never touch an empty texel, unless the triangle's chart owns no
 * texel centre at all. Returns 0 or -1 with err set. */
int lc_texels_rasterize(const lc_scene *scene, uint32_t width, uint32_t height, int threads, lc_lightmap *lm,
                        lc_lcb_cache **caches, uint32_t *n_caches, char *err, size_t errlen);

/* Dilation: `passes` rounds over the 8 neighbours; an empty texel takes the cache of its
 * first covered neighbour in a fixed order (deterministic). Adds `passes` further rings
 * around what rasterize filled. threads (here and in rasterize): parallel-for workers, 0 =
 * all cores; the result does not depend on it. */
void lc_texels_dilate(lc_lightmap *lm, uint32_t passes, int threads);

void lc_lightmap_release(lc_lightmap *lm);

#endif
