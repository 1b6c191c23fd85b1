/* bake options: the option table, the quality presets and argument parsing (any thread). */
#include "bake/options.h"

#include <stdio.h>
#include <string.h>

#include "util/log.h"

/* --- options ---------------------------------------------------------------------------- */

static int bake_add_asset(void *settings, const char *value, char *err, size_t errlen) {
    lc_bake_settings *s = settings;
    const char *eq = strchr(value, '=');
    if (!eq || eq == value || !eq[1]) {
        lc_set_err(err, errlen, "--asset: expected NAME=PATH, got '%s'", value);
        return -1;
    }
    size_t nlen = (size_t)(eq - value);
    if (nlen >= sizeof s->assets[0].name || strlen(eq + 1) >= sizeof s->assets[0].path) {
        lc_set_err(err, errlen, "--asset: name (max 63) or path (max %d) too long", LC_BAKE_PATH_MAX - 1);
        return -1;
    }
    for (size_t i = 0; i < nlen; i++) {
        char c = value[i];
        if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-' ||
              c == '.')) {
            lc_set_err(err, errlen, "--asset: name '%.*s' may only use letters, digits, '_', '-', '.'", (int)nlen,
                       value);
            return -1;
        }
    }
    if (s->n_assets >= LC_BAKE_MAX_ASSETS) {
        lc_set_err(err, errlen, "--asset: at most %d assets", LC_BAKE_MAX_ASSETS);
        return -1;
    }
    for (int i = 0; i < s->n_assets; i++)
        if (strlen(s->assets[i].name) == nlen && strncmp(s->assets[i].name, value, nlen) == 0) {
            lc_set_err(err, errlen, "--asset: name '%.*s' given twice", (int)nlen, value);
            return -1;
        }
    lc_bake_asset_arg *a = &s->assets[s->n_assets++];
    memcpy(a->name, value, nlen);
    a->name[nlen] = 0;
    snprintf(a->path, sizeof a->path, "%s", eq + 1);
    return 0;
}

#define OFF(f) offsetof(lc_bake_settings, f)
static const lc_opt bake_options[] = {
    {"output", LC_OPT_STRING, OFF(output), 1, LC_BAKE_PATH_MAX, NULL, NULL,
     "output bake file (default: input name with .lcb)", "PATH", NULL},
    {"glb", LC_OPT_STRING, OFF(glb), 0, LC_BAKE_PATH_MAX, NULL, NULL,
     "where to write the scene with lightmap UVs (TEXCOORD_1) as binary glTF for viewers (default: OUT.glb)", "PATH",
     NULL},
    {"write-glb", LC_OPT_BOOL, OFF(write_glb), 0, 1, "true", NULL, "write the .glb (--no-write-glb to skip)", NULL,
     NULL},
    {"quality", LC_OPT_ENUM, OFF(quality), 0, 0, "moderate", "draft|moderate|high|ultra",
     "preset for every parameter below (flags given explicitly win)", NULL, NULL},
    {"scale", LC_OPT_FLOAT, OFF(scale), 1e-9, 1e6, "1", NULL, "multiply positions (scene units -> metres)", NULL, NULL},
    {"flip-winding", LC_OPT_BOOL, OFF(flip_winding), 0, 1, "false", NULL, "treat clockwise faces as front faces", NULL,
     NULL},
    {"texel-density", LC_OPT_FLOAT, OFF(texel_density), 0, 10000, "0", NULL,
     "lightmap texels per metre (0 = fit --atlas-size)", NULL, NULL},
    {"atlas-size", LC_OPT_INT, OFF(atlas_size), 16, 8192, "128", NULL, "lightmap atlas width and height in texels",
     NULL, NULL},
    {"min-texel-density", LC_OPT_FLOAT, OFF(min_texel_density), 0, 10000, "2", NULL,
     "fitting --atlas-size never gives fewer lightmap texels per metre than this: a larger scene gets a larger "
     "atlas (0 = exactly --atlas-size)",
     NULL, NULL},
    {"padding", LC_OPT_INT, OFF(padding), 2, 16, "2", NULL, "empty texels between lightmap charts", NULL, NULL},
    {"chart-angle", LC_OPT_FLOAT, OFF(chart_angle), 1, 89, "45", NULL, "max normal deviation inside a chart (degrees)",
     NULL, NULL},
    {"dilate", LC_OPT_INT, OFF(dilate), 0, 16, "2", NULL, "lightmap seam dilation passes", NULL, NULL},
    {"surfels", LC_OPT_INT, OFF(surfels), 16, 4194304, "32768", NULL, "number of surfels", NULL, NULL},
    {"relax", LC_OPT_INT, OFF(relax), 0, 64, "4", NULL, "surfel relaxation iterations", NULL, NULL},
    {"drop-buried", LC_OPT_BOOL, OFF(drop_buried), 0, 1, "false", NULL,
     "drop surfels inside geometry (fewer than --surfels remain; on in moderate, high and ultra: a hit beside a "
     "column base is otherwise given the dark buried surfel under it)",
     NULL, NULL},
    {"surfel-refine", LC_OPT_FLOAT, OFF(surfel_refine), 0, 0.75, "0", NULL,
     "share of --surfels placed where caches see surfaces without a surfel of their own; surfel areas then follow "
     "the surface each covers (see bake/surfel_refine.h)",
     NULL, NULL},
    {"list-refine", LC_OPT_FLOAT, OFF(list_refine), 0, 1, "0", NULL,
     "when texel caches gather per surfel (--texel-gather), add this x --surfels surfels by refinement on top "
     "(moderate: 0.25; a hit is given to its nearest surfel, so a surface without its own reads another's light)",
     NULL, NULL},
    {"exposure", LC_OPT_BOOL, OFF(exposure), 0, 1, "false", NULL,
     "weigh surfels by how many caches see them (see bake/exposure.h; on in moderate, high and ultra)", NULL, NULL},
    {"hierarchy", LC_OPT_ENUM, OFF(hierarchy), 0, 0, "aac", "aac|kdtree",
     "surfel hierarchy: agglomerative clustering (PIC metric) or kd-tree", NULL, NULL},
    {"links", LC_OPT_INT, OFF(links), 1, 1024, "128", NULL, "links per cache (n_L)", NULL, NULL},
    {"grid-links", LC_OPT_INT, OFF(grid_links), 0, 4096, "0", NULL,
     "links per grid cache, when more than --links (moderate: 256; --link-sh keeps --links): grid "
     "caches are few, and the SH grid, objects and DNRT read them (bench/fidelity.md)",
     NULL, NULL},
    {"texel-gather", LC_OPT_ENUM, OFF(texel_gather), 0, 0, "auto", "auto|links|surfels",
     "PIC: how texel caches gather. surfels: each from the surfels its --texel-gather-rays rays hit (a list per "
     "texel; grid caches keep their links); links: through the links; auto: surfels where the probe-ray budget "
     "leaves the links at --probe-rays (a large scene), links where it raises them (bench/fidelity.md)",
     NULL, NULL},
    {"texel-gather-rays", LC_OPT_INT, OFF(texel_gather_rays), 16, 8192, "256", NULL,
     "PIC with texel lists: hemisphere rays per texel cache, at least (raised in powers of two within "
     "--probe-ray-budget, as the links' rays; a list holds at most this many surfels)",
     NULL, NULL},
    {"node-samples", LC_OPT_INT, OFF(node_samples), 1, 256, "16", NULL,
     "visibility rays per node while refining the cut", NULL, NULL},
    {"final-samples", LC_OPT_INT, OFF(final_samples), 1, 1024, "32", NULL,
     "visibility rays per linked node for its final factor", NULL, NULL},
    {"probe-rays", LC_OPT_INT, OFF(probe_rays), 0, 65536, "1024", NULL,
     "near-field probe rays per cache for link solid angles, at least (0 = surfel sampling only)", NULL, NULL},
    {"probe-ray-budget", LC_OPT_INT, OFF(probe_ray_budget), 0, 1 << 30, "33554432", NULL,
     "probe rays over all caches: a scene with few caches gets more per cache, up to 8192 (0 = --probe-rays "
     "exactly; the draft preset's)",
     NULL, NULL},
    {"bands", LC_OPT_INT, OFF(bands), 1, 8, "3", NULL, "SH bands of the output caches", NULL, NULL},
    {"link-sh", LC_OPT_BOOL, OFF(link_sh), 0, 1, "false", NULL,
     "also store each link's transport projected into --bands SH (LKSH)", NULL, NULL},
    {"grid-cell", LC_OPT_FLOAT, OFF(grid_cell), 0, 1e4, "0", NULL,
     "SH grid spacing in metres (0 = from --grid-max-dim)", NULL, NULL},
    {"grid-max-dim", LC_OPT_INT, OFF(grid_max_dim), 3, 512, "24", NULL, "SH grid samples along the longest axis", NULL,
     NULL},
    {"grid-max-samples", LC_OPT_INT, OFF(grid_max_samples), 8, 4194304, "4096", NULL, "cap on SH grid samples", NULL,
     NULL},
    {"reloc-rays", LC_OPT_INT, OFF(reloc_rays), 4, 1024, "32", NULL,
     "test rays per cache for moving caches out of geometry", NULL, NULL},
    {"reloc-offset", LC_OPT_FLOAT, OFF(reloc_offset), 0, 1, "0.005", NULL,
     "metres past the back face a moved cache ends", NULL, NULL},
    {"grid-clearance", LC_OPT_FLOAT, OFF(grid_clearance), 0, 0.5, "0.25", NULL,
     "a moved grid cache then steps this fraction of a grid cell off that face (at most half the free space)", NULL,
     NULL},
    {"asset", LC_OPT_CALLBACK, 0, 0, 0, NULL, NULL, "bake a dynamic-object asset (repeatable)", "NAME=PATH",
     bake_add_asset},
    {"transfer", LC_OPT_BOOL, OFF(transfer), 0, 1, "true", NULL,
     "bake each asset's DNRT transfer grid: placed objects then shadow and colour the indirect light", NULL, NULL},
    {"transfer-dims", LC_OPT_INT, OFF(transfer_dims), 2, 64, "32", NULL, "transfer grid vertices per axis", NULL, NULL},
    {"transfer-sh", LC_OPT_ENUM, OFF(transfer_sh), 0, 0, "4", "4|9", "SH coefficients per transfer term", NULL, NULL},
    {"transfer-rays", LC_OPT_INT, OFF(transfer_rays), 1, 65536, "512", NULL,
     "rays per transfer grid vertex (aimed at the asset's bounding sphere)", NULL, NULL},
    {"transfer-extent", LC_OPT_FLOAT, OFF(transfer_extent), 1, 100, "3", NULL,
     "transfer grid half side in bounding-sphere radii (the inner volume)", NULL, NULL},
    {"transfer-outer", LC_OPT_FLOAT, OFF(transfer_outer), 1, 100, "2", NULL,
     "outer volume radius / inner half side: beyond the grid the effect falls off as 1/d^2 up to here", NULL, NULL},
    {"mr-points", LC_OPT_INT, OFF(mr_points), 0, 65535, "256", NULL,
     "LightSkin sparse points per asset, with each vertex's 8 nearest (mixed-reality light; 0 = none)", NULL, NULL},
    {"solver", LC_OPT_ENUM, OFF(solver), 0, 0, "pic", "pic|probes|both",
     "light transport the bake holds: PIC links, sparse radiance probes, or both (lucentd's settings.solver picks)",
     NULL, NULL},
    {"probes", LC_OPT_INT, OFF(probes), 0, 4096, "0", NULL,
     "probes solver: radiance probes (0 = --probe-density x the scene's bounding volume, at least one per 400 "
     "lightmap texels and 8)",
     NULL, NULL},
    {"probe-density", LC_OPT_FLOAT, OFF(probe_density), 1e-6, 1e6, "0.02", NULL,
     "probes solver: probes per cubic metre when --probes is 0", NULL, NULL},
    {"probe-relight-rays", LC_OPT_INT, OFF(probe_relight_rays), 1, 65536, "512", NULL,
     "probes solver: rays per probe that relight it", NULL, NULL},
    {"probe-bands", LC_OPT_INT, OFF(probe_bands), 1, 8, "8", NULL, "probes solver: SH bands of a probe", NULL, NULL},
    {"probe-overlaps", LC_OPT_INT, OFF(probe_overlaps), 1, 64, "10", NULL,
     "probes solver: probes a receiver reconstructs from, at most", NULL, NULL},
    {"probe-receiver-rays", LC_OPT_INT, OFF(probe_receiver_rays), 1, 65536, "256", NULL,
     "probes solver: rays per receiver for its transport", NULL, NULL},
    {"probe-cluster", LC_OPT_INT, OFF(probe_cluster), 1, 8192, "1024", NULL,
     "probes solver: receivers per compressed cluster, at most", NULL, NULL},
    {"probe-rank", LC_OPT_INT, OFF(probe_rank), 1, 256, "32", NULL, "probes solver: SVD rank per cluster, at most",
     NULL, NULL},
    {"probe-svd-error", LC_OPT_FLOAT, OFF(probe_svd_error), 0, 0.999, "0.05", NULL,
     "probes solver: relative Frobenius truncation error per cluster (larger clusters split until met)", NULL, NULL},
    {"probe-band-weight", LC_OPT_FLOAT, OFF(probe_band_weight), 0, 8, "0", NULL,
     "probes solver: the SVD error weighs SH band l by (l + 1)^-W (0: every coefficient alike)", NULL, NULL},
    {"probe-visibility", LC_OPT_BOOL, OFF(probe_visibility), 0, 1, "true", NULL,
     "probes solver: a probe lights only the points it sees (off: the naive weights that leak through walls)", NULL,
     NULL},
    {"probe-unseen", LC_OPT_ENUM, OFF(probe_unseen), 0, 0, "grid", "off|grid|all",
     "probes solver: which receivers' rays whose hit no supporting probe sees gather from the surfel they hit (off: "
     "they add nothing, as the thesis; grid: SH grid cells only, measured best in bench/RESULTS.md)",
     NULL, NULL},
    {"seed", LC_OPT_INT, OFF(seed), 0, 2147483647, "1", NULL, "random seed (same seed, same bytes)", NULL, NULL},
    {"threads", LC_OPT_INT, OFF(threads), 0, 256, "0", NULL, "worker threads (0 = all cores)", NULL, NULL},
    {"stats-json", LC_OPT_STRING, OFF(stats_json), 0, LC_BAKE_PATH_MAX, NULL, NULL,
     "write per-stage timings, peak memory and sizes as JSON", "PATH", NULL},
    {"quiet", LC_OPT_BOOL, OFF(quiet), 0, 1, "false", NULL, "no progress output", NULL, NULL},
    {NULL, 0, 0, 0, 0, NULL, NULL, NULL, NULL, NULL},
};
#undef OFF

const lc_opt *lc_bake_options(void) { return bake_options; }

void lc_bake_apply_preset(lc_bake_settings *s, lc_bake_quality q) {
    /* moderate and high follow the paper's settings; caches stay the same, as in the paper,
     * so the two differ in transport detail, not lightmap resolution. ultra (not in the
     * paper) is the cheapest setting found that meets the 15% target on sunlit Sponza
     * (docs/ARCHITECTURE.md, Decisions: "Quality presets"). */
    typedef struct {
        int atlas, surfels, links, bands, node_samples, final_samples, probe_rays, grid_max_dim, grid_max_samples,
            relax, reloc_rays, exposure, probe_ray_budget, grid_links, drop_buried;
        double list_refine;
    } bake_preset;
    /* Buried surfels dropped past draft: with the texel lists (each hit given its nearest
     * surfel) they took 0.4-1.1 points of mean error and 0.7-2.7 of dark bias on the interiors
     * (bench/fidelity.md, "Buried surfels dropped by default").
     * moderate's grid caches get 256 links: twice its cut takes the interiors' SH grid from
     * 11.8-15% to 10.4-11.3%; 512 gains another 0.5-1 point but its deep cuts' directional noise
     * breaks the DNRT closed form (1.1% -> 4.9%), and 1024 is worse on Sponza (bench/fidelity.md,
     * "Grid caches with their own links"). high and ultra already give every cache 254 / 512.
     * moderate's texel lists get a quarter more surfels, placed by refinement where the caches
     * see a surface without its own: Sponza's bias -6.4% -> -4.9%, its relight unchanged; not
     * as a share of the equal-area budget (that starves the large surfaces: grid 11.5 -> 13.1%),
     * nor with links (Cornell's bias -1.8 -> -2.0%) (bench/fidelity.md, "Refined surfels for
     * the texel lists"). high and ultra are unchanged (not measured with it).
     * Grid: 24 samples along the longest axis as the paper's Sponza grid (24x8x12), capped
     * so a cube-shaped room does not get 24^3 grid caches (more than its texel caches). */
    static const bake_preset presets[] = {
        {64, 8192, 64, 2, 4, 8, 256, 16, 1024, 2, 16, 0, 0, 0, 0, 0}, /* draft: previews, bake time first */
        {128, 32768, 128, 3, 16, 32, 1024, 24, 4096, 4, 32, 1, 1 << 25, 256, 1, 0.25},
        {128, 131072, 254, 4, 16, 32, 2048, 24, 8192, 4, 32, 1, 1 << 25, 0, 1, 0},
        {128, 131072, 512, 3, 16, 32, 2048, 24, 8192, 4, 32, 1, 1 << 25, 0, 1, 0},
    };
    const bake_preset *p = &presets[q];
    s->quality = (int)q;
    s->atlas_size = p->atlas;
    s->surfels = p->surfels;
    s->links = p->links;
    s->bands = p->bands;
    s->node_samples = p->node_samples;
    s->final_samples = p->final_samples;
    s->probe_rays = p->probe_rays;
    s->grid_max_dim = p->grid_max_dim;
    s->grid_max_samples = p->grid_max_samples;
    s->relax = p->relax;
    s->reloc_rays = p->reloc_rays;
    s->exposure = p->exposure;
    s->probe_ray_budget = p->probe_ray_budget;
    s->grid_links = p->grid_links;
    s->drop_buried = p->drop_buried;
    s->list_refine = p->list_refine;
}

uint32_t lc_bake_probe_rays(const lc_bake_settings *s, uint32_t n_caches) {
    uint32_t rays = (uint32_t)s->probe_rays;
    if (!rays || !s->probe_ray_budget || !n_caches) return rays;
    while (rays * 2 <= LC_BAKE_PROBE_RAYS_MAX && (uint64_t)n_caches * rays * 2 <= (uint64_t)s->probe_ray_budget)
        rays *= 2;
    return rays;
}

uint32_t lc_bake_grid_links(const lc_bake_settings *s, uint32_t n_grid_caches) {
    /* A cut holds at most the hierarchy's nodes (as --links is checked against): a small scene
     * under the moderate preset just gets them all. */
    int grid_links = s->grid_links < 2 * s->surfels - 1 ? s->grid_links : 2 * s->surfels - 1;
    if (s->solver == LC_BAKE_SOLVER_PROBES || s->link_sh || !n_grid_caches || grid_links <= s->links) return 0;
    return (uint32_t)grid_links;
}

uint32_t lc_bake_texel_gather_rays(const lc_bake_settings *s, uint32_t n_texel_caches) {
    uint32_t rays = (uint32_t)s->texel_gather_rays;
    if (!s->probe_ray_budget || !n_texel_caches) return rays;
    while (rays * 2 <= LC_BAKE_PROBE_RAYS_MAX && (uint64_t)n_texel_caches * rays * 2 <= (uint64_t)s->probe_ray_budget)
        rays *= 2;
    return rays;
}

/* auto: a scene the budget gives many rays per cache is small, and there the links' rays beat
 * short lists (the Cornell box: links 3.0%, 256-ray lists 13.8%, 8192-ray lists 2.6% at 8x
 * the file); where the budget leaves --probe-rays, the links' node averages cost 4-5 points
 * of bias that the lists recover (Sibenik 14.8% -> 10.5%). */
int lc_bake_texel_surfels(const lc_bake_settings *s, uint32_t probe_rays) {
    if (s->solver == LC_BAKE_SOLVER_PROBES || s->texel_gather == LC_BAKE_TEXEL_GATHER_LINKS) return 0;
    if (s->texel_gather == LC_BAKE_TEXEL_GATHER_SURFELS) return 1;
    return s->probe_ray_budget > 0 && probe_rays <= (uint32_t)s->probe_rays;
}

int lc_bake_parse_args(lc_bake_settings *s, int argc, char **argv, int start, char **positional, int max_pos, char *err,
                       size_t errlen) {
    memset(s, 0, sizeof *s);
    if (lc_opt_defaults(bake_options, s, err, errlen) != 0) return -1;
    /* First pass: only --quality, so the preset sits under every explicit flag. */
    lc_bake_settings probe;
    memset(&probe, 0, sizeof probe);
    if (lc_opt_defaults(bake_options, &probe, err, errlen) != 0) return -1;
    char *scratch[256];
    int n = lc_opt_parse(bake_options, &probe, argc, argv, start, scratch, 256, err, errlen);
    if (n < 0) return -1;
    lc_bake_apply_preset(s, (lc_bake_quality)probe.quality);
    int npos = lc_opt_parse(bake_options, s, argc, argv, start, positional, max_pos, err, errlen);
    if (npos < 0) return -1;
    if (s->probe_cluster < s->probe_rank) {
        lc_set_err(err, errlen, "--probe-cluster %d is below --probe-rank %d", s->probe_cluster, s->probe_rank);
        return -1;
    }
    if ((double)s->links > 2.0 * s->surfels - 1) {
        lc_set_err(err, errlen, "--links %d exceeds the hierarchy's %d nodes (raise --surfels)", s->links,
                   2 * s->surfels - 1);
        return -1;
    }
    return npos;
}
