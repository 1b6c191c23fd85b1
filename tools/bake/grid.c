#include "bake/grid.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"

/* Samples along one axis for extent e: the lattice spans [bmin - cell/2, bmax + cell/2] at
 * least, centred on the bounds, so interpolation at the scene boundary never extrapolates. */
static uint32_t grid_axis_dim(double e, double cell) {
    double k = ceil(e / cell - 1e-6); /* tolerance: e an exact multiple of cell must not gain a sample */
    if (k < 0) k = 0;
    if (k > 4e9) k = 4e9;
    return (uint32_t)k + 2;
}

static uint64_t grid_dims_for(const double ext[3], double cell, uint32_t dims[3]) {
    uint64_t total = 1;
    for (int i = 0; i < 3; i++) {
        dims[i] = grid_axis_dim(ext[i], cell);
        total *= dims[i];
    }
    return total;
}

int lc_grid_layout(const float bmin[3], const float bmax[3], double cell, uint32_t max_dim, uint32_t max_samples,
                   lc_grid *grid, char *err, size_t errlen) {
    double ext[3], emax = 0;
    for (int i = 0; i < 3; i++) {
        if (!isfinite(bmin[i]) || !isfinite(bmax[i]) || bmax[i] < bmin[i]) {
            lc_set_err(err, errlen, "grid: invalid bounds (axis %d: %g .. %g)", i, (double)bmin[i], (double)bmax[i]);
            return -1;
        }
        ext[i] = (double)bmax[i] - (double)bmin[i];
        if (ext[i] > emax) emax = ext[i];
    }
    if (!isfinite(cell) || cell < 0) {
        lc_set_err(err, errlen, "grid: cell must be >= 0 (got %g)", cell);
        return -1;
    }
    if (max_samples != 0 && max_samples < 8) {
        lc_set_err(err, errlen, "grid: max_samples must be 0 (no cap) or >= 8 (got %u)", max_samples);
        return -1;
    }
    if (cell == 0) {
        if (max_dim < 3) {
            lc_set_err(err, errlen, "grid: max_dim must be >= 3 when cell is 0 (got %u)", max_dim);
            return -1;
        }
        /* max_dim samples span emax plus the two half-cell pads: (max_dim - 1) cell = emax + cell. */
        cell = emax > 0 ? emax / (double)(max_dim - 2) : 1.0;
    }
    uint32_t dims[3];
    uint64_t total = grid_dims_for(ext, cell, dims);
    /* Grow the cell until the cap holds; the cube root gets close in one step, the 1% keeps
     * the loop finite when rounding lands exactly on the cap. */
    while (max_samples != 0 && total > max_samples) {
        double g = cbrt((double)total / (double)max_samples);
        cell *= g > 1.01 ? g : 1.01;
        total = grid_dims_for(ext, cell, dims);
    }
    memset(grid, 0, sizeof *grid);
    grid->cell = (float)cell;
    for (int i = 0; i < 3; i++) {
        grid->dims[i] = dims[i];
        double centre = 0.5 * ((double)bmin[i] + (double)bmax[i]);
        grid->origin[i] = (float)(centre - 0.5 * (double)(dims[i] - 1) * cell);
    }
    return 0;
}

int lc_grid_place(const lc_grid *grid, lc_lcb_cache **caches, uint32_t *n_caches, uint32_t **cell_cache, char *err,
                  size_t errlen) {
    uint64_t total = (uint64_t)grid->dims[0] * grid->dims[1] * grid->dims[2];
    uint32_t *map = NULL;
    if (total == 0 || (uint64_t)*n_caches + total >= LC_NONE) {
        lc_set_err(err, errlen, "grid: dims %ux%ux%u give an invalid cache count", grid->dims[0], grid->dims[1],
                   grid->dims[2]);
        goto err;
    }
    map = malloc((size_t)total * sizeof *map);
    if (!map) {
        lc_set_err(err, errlen, "grid: out of memory for the %llu-entry cell map", (unsigned long long)total);
        goto err;
    }
    lc_lcb_cache *grown = realloc(*caches, (size_t)(*n_caches + total) * sizeof *grown);
    if (!grown) { /* *caches is still valid and unchanged */
        lc_set_err(err, errlen, "grid: out of memory for %llu caches", (unsigned long long)total);
        goto err;
    }
    *caches = grown;
    uint32_t base = *n_caches;
    uint32_t i = 0;
    for (uint32_t z = 0; z < grid->dims[2]; z++)
        for (uint32_t y = 0; y < grid->dims[1]; y++)
            for (uint32_t x = 0; x < grid->dims[0]; x++, i++) {
                lc_lcb_cache *c = &grown[base + i];
                memset(c, 0, sizeof *c);
                c->position[0] = grid->origin[0] + (float)x * grid->cell;
                c->position[1] = grid->origin[1] + (float)y * grid->cell;
                c->position[2] = grid->origin[2] + (float)z * grid->cell;
                c->flags = LC_CACHE_GRID;
                c->index = i;
                map[i] = base + i;
            }
    *n_caches = base + (uint32_t)total;
    *cell_cache = map;
    return 0;
err:
    free(map);
    return -1;
}
