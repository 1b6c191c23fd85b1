/* bake: the lucent-bake pipeline — import → lightmap UVs → texel caches → grid caches →
 * relocation → surfels → hierarchy → links → assets → .lcb (+ scene.glb).
 * Settings come from the option table in bake/options.h. */
#ifndef LC_BAKE_H
#define LC_BAKE_H
#include <stddef.h>
#include <stdio.h>

#include "bake/options.h"

/* Per-stage measurements of one bake. */
#define LC_BAKE_MAX_STAGES 16
typedef struct lc_bake_report {
    int n_stages;
    struct {
        const char *name;
        double seconds;
        double peak_mib; /* the process's peak resident memory when the stage ended */
    } stages[LC_BAKE_MAX_STAGES];
    double total_seconds;
    long peak_rss_kib;
    unsigned long long file_bytes;
    unsigned triangles, surfels, caches, texel_caches, grid_caches, links_per_cache, charts;
    unsigned lightmap_width, lightmap_height;
    double atlas_usage, texel_density;
} lc_bake_report;

/* Runs the whole bake. Returns 0, 1 (bad input / bake failure) or 3 (cannot write output),
 * with err set. */
int lc_bake_run(const lc_bake_settings *s, lc_bake_report *report, char *err, size_t errlen);

void lc_bake_report_print(const lc_bake_report *r, FILE *out);
/* Writes the report as JSON (atomic). */
int lc_bake_report_write_json(const lc_bake_report *r, const lc_bake_settings *s, const char *path, char *err,
                              size_t errlen);

#endif
