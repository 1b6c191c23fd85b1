/* grid: SH grid caches on a regular lattice over the scene bounds (the irradiance volume
 * for dynamic objects). Sample i sits at origin + i * cell. */
#ifndef LC_GRID_H
#define LC_GRID_H
#include <stddef.h>
#include <stdint.h>

#include "lcb/lcb.h"

typedef struct lc_grid {
    float origin[3];
    float cell;
    uint32_t dims[3];
} lc_grid;

/* Chooses the lattice: cell > 0 uses that spacing; otherwise max_dim samples along the
 * longest axis. The lattice covers [bmin, bmax] (padded by half a cell). Caps total samples
 * at max_samples. Returns 0 or -1 with err set. */
int lc_grid_layout(const float bmin[3], const float bmax[3], double cell, uint32_t max_dim, uint32_t max_samples,
                   lc_grid *grid, char *err, size_t errlen);

/* Appends one grid cache per sample to *caches (realloc'd) and fills cell_cache
 * (malloc'd, dims product entries) with their indices. */
int lc_grid_place(const lc_grid *grid, lc_lcb_cache **caches, uint32_t *n_caches, uint32_t **cell_cache, char *err,
                  size_t errlen);

#endif
