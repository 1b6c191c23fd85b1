/* lucent-ref: the ground-truth reference and the comparison tool.
 *   lucent-ref render BAKE.lcb --out DIR [--state STATE.json] [--spp N] [--target-stderr F]
 *                     [--texel-at surface|cache] ...
 *   lucent-ref compare --reference DIR --lightmap EXR_OR_F32 [--grid F32] [--out DIR]
 * Texels are evaluated at their own surface points (found from the mesh's uv1, ref.h), not at
 * the caches the bake may have moved; compare and fidelity report the lightmap over all texels,
 * the texels whose cache the bake moved and the rest, the blotch metric (neighbour-to-neighbour
 * variation), the texel spacing, and write error_lightmap_uv.png (the lightmap's layout).
 *   lucent-ref fidelity BAKE.lcb [--state STATE.json] [--reference DIR] [--backend cpu] [--out DIR]
 *   lucent-ref camera BAKE.lcb [--state STATE.json] --eye X,Y,Z --target X,Y,Z [--exr F] [--png F] ...
 *   lucent-ref capture BAKE.lcb --out DIR (--path PATH.json | --eye X,Y,Z --target X,Y,Z) ...
 *   lucent-ref mr-truth BAKE.lcb --capture DIR --frame K --points POINTS.json --out TRUTH.json ...
 * Exit codes: 0 ok, 1 failure, 2 usage error. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "bake/image.h"
#include "ref/ref.h"
#include "util/fsutil.h"
#include "util/log.h"
#include "util/opt.h"
#include "util/progress.h"

enum { EXIT_OK = 0, EXIT_FAIL = 1, EXIT_USAGE = 2 };
#define REF_PATH_MAX 1024

typedef struct ref_opts {
    char state[REF_PATH_MAX], out[REF_PATH_MAX], reference[REF_PATH_MAX], lightmap[REF_PATH_MAX], grid[REF_PATH_MAX];
    char reference_with[REF_PATH_MAX], lightmap_with[REF_PATH_MAX];
    double k_sigma, delta_floor;
    int spp, batch, max_bounces, rr_depth, seed, threads, texels, grid_on, quiet;
    double target_stderr, floor_frac, threshold, max_err, tol;
    int zoom, max_relights, backend, bounce_limit, bound_rays, texel_at;
    /* camera */
    char exr[REF_PATH_MAX], png[REF_PATH_MAX];
    int width, height, max_depth, tonemap;
    double fov, exposure;
    float eye[3], target[3], up[3];
    int have_eye, have_target, have_up;
    /* capture, mr-truth */
    char path[REF_PATH_MAX], capture[REF_PATH_MAX], points[REF_PATH_MAX];
    int frames, frame, color;
    double jitter_mm, jitter_deg;
} ref_opts;

/* X,Y,Z: three finite numbers, the flag named in the error. */
static int ref_opt_vec3(const char *flag, const char *value, float out[3], char *err, size_t errlen) {
    const char *p = value;
    for (int k = 0; k < 3; k++) {
        char *end = NULL;
        double v = strtod(p, &end);
        if (end == p || !isfinite(v) || fabs(v) > 1e9 || *end != (k < 2 ? ',' : '\0')) {
            lc_set_err(err, errlen, "--%s: '%s' is not three finite numbers X,Y,Z", flag, value);
            return -1;
        }
        out[k] = (float)v;
        p = end + 1;
    }
    return 0;
}
static int ref_opt_eye(void *o, const char *v, char *err, size_t errlen) {
    ((ref_opts *)o)->have_eye = 1;
    return ref_opt_vec3("eye", v, ((ref_opts *)o)->eye, err, errlen);
}
static int ref_opt_target(void *o, const char *v, char *err, size_t errlen) {
    ((ref_opts *)o)->have_target = 1;
    return ref_opt_vec3("target", v, ((ref_opts *)o)->target, err, errlen);
}
static int ref_opt_up(void *o, const char *v, char *err, size_t errlen) {
    ((ref_opts *)o)->have_up = 1;
    return ref_opt_vec3("up", v, ((ref_opts *)o)->up, err, errlen);
}

#define OFF(f) offsetof(ref_opts, f)
static const lc_opt ref_options[] = {
    {"state", LC_OPT_STRING, OFF(state), 0, REF_PATH_MAX, NULL, NULL,
     "[render, fidelity, camera, capture, mr-truth] daemon state JSON (`lucentctl state --json`, a snapshot); "
     "default: the daemon's initial state (render, fidelity: the bake's emission, no lights; camera, capture, "
     "mr-truth: with the bake's own lights, as a fresh lucentd starts)",
     "PATH", NULL},
    {"out", LC_OPT_STRING, OFF(out), 0, REF_PATH_MAX, NULL, NULL,
     "output (render, capture: a directory, required; mr-truth: TRUTH.json, required; compare/fidelity: default "
     "none / fidelity-out)",
     "DIR", NULL},
    {"spp", LC_OPT_INT, OFF(spp), 1, 1 << 24, NULL, NULL,
     "[render] paths per cache, default 4096 (the cap with --target-stderr); [camera] paths per pixel, default 64; "
     "[capture] per pixel, default 16; [mr-truth] samples per point (each a light and a cosine sample), default "
     "4096",
     "N", NULL},
    {"batch", LC_OPT_INT, OFF(batch), 1, 1 << 20, "256", NULL, "[render] paths per cache per pass", "N", NULL},
    {"target-stderr", LC_OPT_FLOAT, OFF(target_stderr), 0, 1, "0", NULL,
     "[render] stop a cache when its relative standard error is below F (0 = fixed --spp)", "F", NULL},
    {"floor", LC_OPT_FLOAT, OFF(floor_frac), 0, 1, "0.05", NULL,
     "[render] adaptive: caches darker than this fraction of the brightest need only the brightest x floor x F", "F",
     NULL},
    {"max-bounces", LC_OPT_INT, OFF(max_bounces), 8, 1024, "32", NULL,
     "[render] surface reflections per path (Russian roulette cuts most paths earlier)", "N", NULL},
    {"rr-depth", LC_OPT_INT, OFF(rr_depth), 1, 1024, "3", NULL,
     "[render, camera, capture, mr-truth] Russian roulette from this bounce on", "N", NULL},
    {"seed", LC_OPT_INT, OFF(seed), 0, 2147483647, "1", NULL,
     "[render, camera, capture, mr-truth] random seed (same seed, same result; capture: also the jitter)", "S", NULL},
    {"threads", LC_OPT_INT, OFF(threads), 0, 256, "0", NULL, "worker threads (0 = all cores)", "N", NULL},
    {"texels", LC_OPT_BOOL, OFF(texels), 0, 1, "true", NULL, "[render] compute the lightmap texels (--no-texels)", NULL,
     NULL},
    {"cells", LC_OPT_BOOL, OFF(grid_on), 0, 1, "true", NULL, "[render] compute the SH grid cells (--no-cells)", NULL,
     NULL},
    {"texel-at", LC_OPT_ENUM, OFF(texel_at), 0, 0, "surface", "surface|cache",
     "[render, fidelity] where each texel is evaluated: surface = its own surface point, found from the mesh's uv1 "
     "(what a user sees drawn there); cache = the bake's cache position, which the bake moves out of geometry "
     "(LC_CACHE_MOVED)",
     NULL, NULL},
    {"reference", LC_OPT_STRING, OFF(reference), 0, REF_PATH_MAX, NULL, NULL,
     "[compare, fidelity] reference directory from `render` (fidelity: rendered into OUT/reference when absent)", "DIR",
     NULL},
    {"lightmap", LC_OPT_STRING, OFF(lightmap), 0, REF_PATH_MAX, NULL, NULL,
     "[compare] lightmap to judge: an image (EXR...) or raw float32 RGB W*H (.f32/.bin)", "PATH", NULL},
    {"grid", LC_OPT_STRING, OFF(grid), 0, REF_PATH_MAX, NULL, NULL,
     "[compare] SH grid to judge: raw float32, cells x 9 x RGB irradiance SH", "PATH", NULL},
    {"reference-with", LC_OPT_STRING, OFF(reference_with), 0, REF_PATH_MAX, NULL, NULL,
     "[delta] reference of the same bake with the object placed (--reference: without it)", "DIR", NULL},
    {"lightmap-with", LC_OPT_STRING, OFF(lightmap_with), 0, REF_PATH_MAX, NULL, NULL,
     "[delta] the approximation's lightmap with the object (--lightmap: without it)", "PATH", NULL},
    {"k-sigma", LC_OPT_FLOAT, OFF(k_sigma), 0, 100, "3", NULL,
     "[delta] compare texels whose reference change exceeds this many standard errors", "K", NULL},
    {"delta-floor", LC_OPT_FLOAT, OFF(delta_floor), 0, 1, "0.005", NULL,
     "[delta] ... and this fraction of the mean reference luminance", "F", NULL},
    {"threshold", LC_OPT_FLOAT, OFF(threshold), 0, 1, "0.01", NULL,
     "[compare, fidelity] compare texels/cells brighter than this fraction of the brightest", "F", NULL},
    {"max-err", LC_OPT_FLOAT, OFF(max_err), 0.001, 100, "0.5", NULL, "[compare, fidelity] heat map: red at this error",
     "F", NULL},
    {"zoom", LC_OPT_INT, OFF(zoom), 1, 64, "4", NULL, "[compare, fidelity] heat map pixels per texel", "N", NULL},
    {"backend", LC_OPT_ENUM, OFF(backend), 0, 0, "cpu", "auto|cpu|egl", "[fidelity] engine backend", NULL, NULL},
    {"tol", LC_OPT_FLOAT, OFF(tol), 0, 1, "1e-4", NULL,
     "[fidelity] relight progressively until no bright texel changes by more than this", "F", NULL},
    {"max-relights", LC_OPT_INT, OFF(max_relights), 1, 100000, "500", NULL, "[fidelity] cap on relights", "N", NULL},
    {"bounce-limit", LC_OPT_INT, OFF(bounce_limit), -1, 16, "-1", NULL,
     "[render, fidelity] diagnostics: truncate both solutions at N reflections (reference paths; the engine runs one "
     "non-progressive relight with N bounces); -1 = off (converged)",
     "N", NULL},
    {"bound-rays", LC_OPT_INT, OFF(bound_rays), 0, 1 << 20, "4096", NULL,
     "[fidelity] also report the lossless-transport bound: each texel gathered from the surfels its N probe rays "
     "hit (the engine's B, no links); 0 = off",
     "N", NULL},
    {"eye", LC_OPT_CALLBACK, 0, 0, 0, NULL, NULL, "[camera] camera position (required)", "X,Y,Z", ref_opt_eye},
    {"target", LC_OPT_CALLBACK, 0, 0, 0, NULL, NULL, "[camera] the point looked at (required)", "X,Y,Z",
     ref_opt_target},
    {"up", LC_OPT_CALLBACK, 0, 0, 0, NULL, NULL, "[camera] up vector, as three.js's camera.up (default 0,1,0)", "X,Y,Z",
     ref_opt_up},
    {"fov", LC_OPT_FLOAT, OFF(fov), 0, 180, "50", NULL,
     "[camera, capture] vertical field of view in degrees, as three.js's PerspectiveCamera (0 and 180 excluded); "
     "default camera 50, capture 60",
     "DEG", NULL},
    {"width", LC_OPT_INT, OFF(width), 1, LC_REF_CAMERA_MAX_SIDE, "640", NULL,
     "[camera, capture] image width, default camera 640, capture 256 (capture: 8..1024)", "N", NULL},
    {"height", LC_OPT_INT, OFF(height), 1, LC_REF_CAMERA_MAX_SIDE, "480", NULL,
     "[camera, capture] image height, default camera 480, capture 192 (capture: 8..1024)", "N", NULL},
    {"max-depth", LC_OPT_INT, OFF(max_depth), 0, 1024, "8", NULL,
     "[camera, capture, mr-truth] reflections per path (0 = emitters and the environment seen directly, 1 = direct "
     "light); default camera 8, capture and mr-truth 32 (Russian roulette from --rr-depth)",
     "N", NULL},
    {"path", LC_OPT_STRING, OFF(path), 1, REF_PATH_MAX, NULL, NULL,
     "[capture] camera path JSON {\"frames\": [{\"eye\": [3], \"target\": [3], \"up\": [3]?, \"time_us\": T?}...]} "
     "(instead of --eye/--target)",
     "PATH.json", NULL},
    {"frames", LC_OPT_INT, OFF(frames), 1, (int)LC_REF_CAPTURE_MAX_FRAMES, "1", NULL,
     "[capture] frames of the --eye/--target pose, each jittered by --jitter-mm/--jitter-deg", "N", NULL},
    {"jitter-mm", LC_OPT_FLOAT, OFF(jitter_mm), 0, 10000, "0", NULL,
     "[capture] per frame, move the camera by a uniform +-J mm along each axis", "J", NULL},
    {"jitter-deg", LC_OPT_FLOAT, OFF(jitter_deg), 0, 180, "0", NULL,
     "[capture] per frame, turn the camera by a uniform +-A degrees about a random axis", "A", NULL},
    {"color", LC_OPT_ENUM, OFF(color), 0, 0, "linear16", "linear16|srgb8",
     "[capture] colour PNGs: linear16 = 16-bit linear (radiance = v / 65535 x exposure), srgb8 = 8-bit sRGB", NULL,
     NULL},
    {"capture", LC_OPT_STRING, OFF(capture), 1, REF_PATH_MAX, NULL, NULL,
     "[mr-truth] capture directory (`lucent-ref capture`, or a recording in its format)", "DIR", NULL},
    {"frame", LC_OPT_INT, OFF(frame), 1, (int)LC_REF_CAPTURE_MAX_FRAMES, "1", NULL,
     "[mr-truth] the capture's frame whose patches are the visible emitters", "K", NULL},
    {"points", LC_OPT_STRING, OFF(points), 1, REF_PATH_MAX, NULL, NULL,
     "[mr-truth] {\"points\": [{\"position\": [3], \"normal\": [3]}...], \"occluders\": {\"objects\": [{\"asset\": "
     "NAME, \"translation\", \"rotation\", \"scale\"}...]}}",
     "POINTS.json", NULL},
    {"exposure", LC_OPT_FLOAT, OFF(exposure), 0, 1e6, "1", NULL,
     "[camera] PNG: radiance scale before the tone map (three.js toneMappingExposure)", "X", NULL},
    {"tonemap", LC_OPT_ENUM, OFF(tonemap), 0, 0, "none", "none|neutral",
     "[camera] PNG tone map: none = three.js LinearToneMapping, neutral = NeutralToneMapping (Khronos PBR "
     "Neutral); then the sRGB transfer",
     NULL, NULL},
    {"exr", LC_OPT_STRING, OFF(exr), 1, REF_PATH_MAX, NULL, NULL, "[camera] write float32 RGB linear radiance (nits)",
     "OUT.exr", NULL},
    {"png", LC_OPT_STRING, OFF(png), 1, REF_PATH_MAX, NULL, NULL,
     "[camera] write 8-bit sRGB after --exposure and --tonemap", "OUT.png", NULL},
    {"quiet", LC_OPT_BOOL, OFF(quiet), 0, 1, "false", NULL, "no progress output", NULL, NULL},
    {NULL, 0, 0, 0, 0, NULL, NULL, NULL, NULL, NULL},
};

static void usage(FILE *out) {
    fprintf(
        out,
        "usage: lucent-ref render BAKE.lcb --out DIR [--state STATE.json] [--spp N | --target-stderr F]\n"
        "                         [--texel-at surface|cache] ...\n"
        "         path-trace the engine's indirect irradiance at every texel (its own surface point) and SH grid "
        "cell\n"
        "       lucent-ref compare --reference DIR --lightmap EXR_OR_F32 [--grid F32] [--out DIR]\n"
        "         relative error of a lightmap / SH grid against a reference\n"
        "       lucent-ref fidelity BAKE.lcb [--state STATE.json] [--reference DIR] [--out DIR]\n"
        "         relight with the engine to convergence and compare (renders the reference if absent)\n"
        "       lucent-ref delta --reference DIR --reference-with DIR --lightmap A --lightmap-with B [--out DIR]\n"
        "         the change an object makes, dE = E(with) - E(without) per texel, against the references'\n"
        "       lucent-ref camera BAKE.lcb [--state STATE.json] --eye X,Y,Z --target X,Y,Z [--up 0,1,0] [--fov 50]\n"
        "                         [--width 640] [--height 480] [--spp 64] [--max-depth 8] [--exposure 1]\n"
        "                         [--tonemap none|neutral] [--exr OUT.exr] [--png OUT.png] [--seed 1] [--threads 0]\n"
        "         path-trace the full illumination (direct + indirect) seen by a pinhole camera\n"
        "       lucent-ref capture BAKE.lcb [--state STATE.json] --out DIR (--path PATH.json | --eye X,Y,Z\n"
        "                         --target X,Y,Z [--up ..] [--frames N --jitter-mm J --jitter-deg A])\n"
        "                         [--width 256 --height 192 --fov 60] [--spp 16] [--color linear16|srgb8] [--seed S]\n"
        "         record the scene as an RGB-D camera: DIR/capture.json, frame_K.json, depth_K.png (16-bit mm),\n"
        "         color_K.png (the replay format of `lucentctl mr replay`; camera model PROTOCOL.md 8.4)\n"
        "       lucent-ref mr-truth BAKE.lcb [--state STATE.json] --capture DIR [--frame K] --points POINTS.json\n"
        "                         --out TRUTH.json [--spp 4096] [--seed S]\n"
        "         irradiance at MR points from the real room: full (the scene) and visible (frame K's patches),\n"
        "         the virtual occluders blocking\n\n"
        "options:\n");
    lc_opt_help(ref_options, out);
    fprintf(out,
            "\nerrors are |Y_a - Y_r| / Y_r on luminance per texel that owns its cache, over texels above\n"
            "--threshold x the brightest (rows: all texels, lm_moved = texels whose cache the bake moved,\n"
            "lm_unmoved = the rest; `moved` also counts the moved texels dark in the reference that the\n"
            "engine lights); grid cells: sum over 14 directions of |dE| / sum of E. blotch: mean\n"
            "|Y_a - Y_b| / ((Y_a + Y_b) / 2) over 4-adjacent compared texels on one surface, engine and\n"
            "reference (its noise raises it). spacing: world distance between texel centres.\n"
            "compare/fidelity --out: compare.json/fidelity.json, error_lightmap.png (zoomed |error|),\n"
            "error_lightmap_uv.png (W x H signed: blue too dark, white right, red too bright, at +-max-err).\n"
            "exit codes: 0 ok, 1 failure, 2 usage error\n");
}

static int parse(ref_opts *o, int argc, char **argv, char **pos, int max_pos) {
    char err[512];
    for (int i = 2; i < argc; i++)
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            usage(stdout);
            exit(EXIT_OK);
        }
    if (lc_opt_defaults(ref_options, o, err, sizeof err) != 0) {
        fprintf(stderr, "lucent-ref: %s\n", err);
        return -1;
    }
    int n = lc_opt_parse(ref_options, o, argc, argv, 2, pos, max_pos, err, sizeof err);
    if (n < 0) fprintf(stderr, "lucent-ref: %s\n", err);
    lc_progress_set_enabled(n >= 0 && !o->quiet);
    return n;
}

static lc_ref_settings settings_from(const ref_opts *o) {
    lc_ref_settings s = lc_ref_default_settings();
    s.spp = (uint32_t)(o->spp ? o->spp : 4096);
    s.batch_spp = (uint32_t)o->batch;
    s.target_stderr = o->target_stderr;
    s.floor_frac = o->floor_frac;
    s.max_bounces = (uint32_t)(o->bounce_limit >= 0 ? o->bounce_limit : o->max_bounces);
    s.rr_depth = (uint32_t)o->rr_depth;
    s.seed = (uint64_t)o->seed;
    s.threads = o->threads;
    s.texels = o->texels;
    s.grid = o->grid_on;
    s.quiet = o->quiet;
    s.texel_at = o->texel_at == 1 ? LC_REF_TEXEL_AT_CACHE : LC_REF_TEXEL_AT_SURFACE;
    return s;
}

/* Renders the reference of bake into dir. */
static int do_render(const char *bake_path, const lc_lcb *bake, const lc_ref_state *st, const ref_opts *o,
                     const char *dir, lc_ref_result *res, char *err, size_t errlen) {
    lc_ref_settings s = settings_from(o);
    lc_ref *r = lc_ref_create(bake, &st->st, o->threads, err, errlen);
    if (!r) return -1;
    int rc = lc_ref_render(r, &s, res, err, errlen);
    lc_ref_release(r);
    if (rc != 0) return -1;
    cJSON *run = cJSON_CreateObject();
    cJSON_AddStringToObject(run, "bake", bake_path);
    cJSON_AddStringToObject(run, "state", o->state[0] ? o->state : "(daemon initial state)");
    cJSON_AddNumberToObject(run, "spp", s.spp);
    cJSON_AddNumberToObject(run, "batch_spp", s.batch_spp);
    cJSON_AddNumberToObject(run, "target_stderr", s.target_stderr);
    cJSON_AddNumberToObject(run, "floor", s.floor_frac);
    cJSON_AddNumberToObject(run, "max_bounces", s.max_bounces);
    cJSON_AddNumberToObject(run, "bounce_limit", o->bounce_limit);
    cJSON_AddNumberToObject(run, "rr_depth", s.rr_depth);
    cJSON_AddNumberToObject(run, "seed", (double)s.seed);
    cJSON_AddNumberToObject(run, "threads", o->threads);
    cJSON_AddStringToObject(run, "texel_at", lc_ref_texel_at_name(s.texel_at));
    char *extra = cJSON_PrintUnformatted(run);
    cJSON_Delete(run);
    rc = lc_ref_write(dir, res, extra, err, errlen);
    cJSON_free(extra);
    if (rc != 0) return -1;
    if (res->texel_surface)
        fprintf(stderr,
                "lucent-ref: texels evaluated at their %s points; surface points of %u texels from the mesh (%u "
                "centres outside every triangle's uv: nearest triangle; %u without one), unmoved caches within %.3g m "
                "of them\n",
                lc_ref_texel_at_name(res->texel_at), res->surface_stats.texels, res->surface_stats.outside,
                res->surface_stats.missing, res->unmoved_offset_max);
    fprintf(stderr,
            "lucent-ref: %s: %u texel caches, %.0f spp mean, relative stderr mean %.4f p95 %.4f max %.4f; "
            "%u grid cells, stderr mean %.4f max %.4f; %.1f s, %.2f Mrays/s\n",
            dir, res->texel_stats.n, res->texel_stats.spp_mean, res->texel_stats.mean_rel_stderr,
            res->texel_stats.p95_rel_stderr, res->texel_stats.max_rel_stderr, res->grid_stats.n,
            res->grid_stats.mean_rel_stderr, res->grid_stats.max_rel_stderr, res->seconds,
            res->seconds > 0 ? res->rays / res->seconds / 1e6 : 0);
    return 0;
}

static int cmd_render(int argc, char **argv) {
    static ref_opts o;
    char *pos[2];
    char err[1024] = "";
    int n = parse(&o, argc, argv, pos, 2);
    if (n < 0) return EXIT_USAGE;
    if (n != 1 || !o.out[0]) {
        fprintf(stderr, "lucent-ref: render needs one BAKE.lcb and --out DIR (see --help)\n");
        return EXIT_USAGE;
    }
    lc_lcb *bake = NULL;
    lc_ref_state st;
    memset(&st, 0, sizeof st);
    lc_ref_result res;
    memset(&res, 0, sizeof res);
    int rc = EXIT_FAIL;
    if (lc_lcb_open(pos[0], &bake, err, sizeof err) != 0) goto done;
    if (lc_ref_state_load(bake, o.state[0] ? o.state : NULL, 0, &st, err, sizeof err) != 0) goto done;
    if (do_render(pos[0], bake, &st, &o, o.out, &res, err, sizeof err) != 0) goto done;
    rc = EXIT_OK;
done:
    if (rc != EXIT_OK) fprintf(stderr, "lucent-ref: %s\n", err);
    lc_ref_result_free(&res);
    lc_ref_state_free(&st);
    lc_lcb_close(bake);
    return rc;
}

/* Loads a lightmap: raw float32 (.f32/.bin, W*H*3) or any image OIIO reads. */
static float *load_lightmap(const char *path, uint32_t w, uint32_t h, char *err, size_t errlen) {
    const char *dot = strrchr(path, '.');
    if (dot && (!strcmp(dot, ".f32") || !strcmp(dot, ".bin"))) {
        size_t len = 0, expect = (size_t)w * h * 3 * sizeof(float);
        char *data = lc_fs_read(path, expect + 1, &len, err, errlen);
        if (data && len != expect) {
            lc_set_err(err, errlen, "%s: %zu bytes, expected %ux%u float32 RGB (%zu)", path, len, w, h, expect);
            free(data);
            return NULL;
        }
        return (float *)data;
    }
    uint32_t iw, ih;
    float *img = NULL;
    if (lc_image_read_rgb(path, (uint64_t)w * h, &iw, &ih, &img, err, errlen) != 0) return NULL;
    if (iw != w || ih != h) {
        lc_set_err(err, errlen, "%s: %ux%u, the reference is %ux%u", path, iw, ih, w, h);
        free(img);
        return NULL;
    }
    return img;
}

static void print_row(const char *what, const lc_ref_errstats *s) {
    printf("%-10s %8u %8.2f%% %8.2f%% %8.2f%% %8.2f%% %+8.2f%% %8.2f%%\n", what, s->n, 100 * s->mean, 100 * s->p50,
           100 * s->p95, 100 * s->max, 100 * s->bias, 100 * s->ref_noise);
}

/* The lightmap's rows and texel metrics of one comparison. */
typedef struct ref_lm_report {
    lc_ref_errstats all, moved, unmoved;
    int have_all, have_moved; /* moved/unmoved: the reference knows which caches the bake moved */
    lc_ref_blotch blotch;
    int have_blotch;
    lc_ref_spacing spacing;
    int have_spacing;
} ref_lm_report;

#define REF_SPACING_LIMIT_M 0.5 /* issue 16: texels no more than 0.5 m apart */

/* Fills rep and err_img (W*H signed errors, NAN where not compared). Returns -1 when out of memory. */
static int compare_lightmap(const lc_ref_result *ref, const float *lightmap, const ref_opts *o, float *err_img,
                            ref_lm_report *rep) {
    memset(rep, 0, sizeof *rep);
    rep->have_all = lc_ref_compare_lightmap(lightmap, ref->lightmap, ref->lightmap_stderr, ref->texel_mask, ref->width,
                                            ref->height, o->threshold, &rep->all, err_img) == 0;
    if (!rep->have_all) return 0;
    if (ref->texel_moved) {
        rep->have_moved = 1;
        lc_ref_compare_lightmap_subset(lightmap, ref->lightmap, ref->lightmap_stderr, ref->texel_mask, ref->texel_moved,
                                       1, ref->width, ref->height, o->threshold, &rep->moved, NULL);
        lc_ref_compare_lightmap_subset(lightmap, ref->lightmap, ref->lightmap_stderr, ref->texel_mask, ref->texel_moved,
                                       0, ref->width, ref->height, o->threshold, &rep->unmoved, NULL);
    }
    if (ref->texel_surface) {
        rep->have_blotch =
            lc_ref_blotch_metric(lightmap, ref->lightmap, ref->lightmap_stderr, ref->texel_mask, ref->texel_surface,
                                 ref->width, ref->height, rep->all.threshold, &rep->blotch) == 0;
        rep->have_spacing =
            lc_ref_spacing_stats(ref->texel_surface, ref->width, ref->height, REF_SPACING_LIMIT_M, &rep->spacing) == 0;
    }
    return 0;
}

static void print_lightmap_report(const lc_ref_result *ref, const ref_lm_report *rep) {
    if (rep->have_moved)
        printf(
            "moved      %u of %u texels' caches moved by the bake; in the reference %u of them are dark (at or below "
            "the threshold), %u of those lit by the engine; |Y_a - Y_r| / mean Y_r over all of them %.2f%% "
            "(unmoved %.2f%%)\n",
            rep->moved.n_total, rep->all.n_total, rep->moved.n_dark, rep->moved.n_dark_lit,
            100 * rep->moved.abs_err_vs_mean, 100 * rep->unmoved.abs_err_vs_mean);
    if (rep->have_blotch)
        printf("blotch     %u pairs: neighbour variation engine %.2f%%, reference %.2f%% (its noise %.2f%%), ratio "
               "%.3f\n",
               rep->blotch.pairs, 100 * rep->blotch.approx, 100 * rep->blotch.reference, 100 * rep->blotch.ref_noise,
               rep->blotch.ratio);
    if (rep->have_spacing)
        printf("spacing    %u texels: mean %.4f m, p50 %.4f m, p95 %.4f m, max %.4f m; %.2f%% above %.2g m\n",
               rep->spacing.n, rep->spacing.mean, rep->spacing.p50, rep->spacing.p95, rep->spacing.max,
               100 * rep->spacing.share_over, rep->spacing.over_m);
    printf("texels evaluated at their %s points (moved caches: %s)\n", lc_ref_texel_at_name(ref->texel_at),
           ref->texel_moved ? "known" : "unknown, the reference predates them");
}

/* Adds "name": the malloc'd JSON object text (freed). */
static void json_add_text(cJSON *root, const char *name, char *text) {
    cJSON *item = text ? cJSON_Parse(text) : NULL;
    free(text);
    if (item) cJSON_AddItemToObject(root, name, item);
}

static void json_add_lightmap_report(cJSON *root, const lc_ref_result *ref, const ref_lm_report *rep) {
    json_add_text(root, "lightmap", lc_ref_errstats_json(&rep->all));
    if (rep->have_moved) {
        json_add_text(root, "lightmap_moved", lc_ref_errstats_json(&rep->moved));
        json_add_text(root, "lightmap_unmoved", lc_ref_errstats_json(&rep->unmoved));
    }
    if (rep->have_blotch) json_add_text(root, "blotch", lc_ref_blotch_json(&rep->blotch));
    if (rep->have_spacing) json_add_text(root, "texel_spacing_m", lc_ref_spacing_json(&rep->spacing));
    cJSON_AddStringToObject(root, "texel_at", lc_ref_texel_at_name(ref->texel_at));
    if (ref->texel_surface) {
        cJSON *ss = cJSON_AddObjectToObject(root, "texel_surfaces");
        cJSON_AddNumberToObject(ss, "texels", ref->surface_stats.texels);
        cJSON_AddNumberToObject(ss, "outside_triangles", ref->surface_stats.outside);
        cJSON_AddNumberToObject(ss, "missing", ref->surface_stats.missing);
        cJSON_AddNumberToObject(ss, "unmoved_cache_offset_max_m", ref->unmoved_offset_max);
    }
}

static const char REF_METRIC_TEXT[] =
    "relative error |Y_a - Y_r| / Y_r of luminance per texel owning its cache, over texels whose reference exceeds "
    "threshold x the brightest; lightmap_moved / lightmap_unmoved: the same over the texels whose cache the bake "
    "moved out of geometry (LC_CACHE_MOVED) / the rest, with the same threshold; the reference evaluates each texel "
    "at texel_at (surface: its own surface point from the mesh, what a user sees drawn there); grid: sum_d |dE(d)| / "
    "sum_d E(d) over 14 directions per cell; p50/p95 nearest rank; bias = sum(a - r) / sum(r); ref_noise = mean "
    "relative standard error of the reference over the same set; blotch: mean over pairs of 4-adjacent compared "
    "texels on the same surface (points within 2x the larger texel spacing, normals within 25 degrees) of |Y_a - "
    "Y_b| / ((Y_a + Y_b) / 2), for the engine (approx) and the reference, ratio = approx / reference; the "
    "reference's own noise (blotch.ref_noise, its mean relative standard error over those texels) raises its "
    "value; texel_spacing_m: sqrt(world area / (uv area x W x H)) of each cache-owning texel's triangle";

/* Writes DIR/compare.json and the heat maps. Takes root (extra, or NULL). */
static int compare_write(const lc_ref_result *ref, const float *lightmap, const ref_opts *o, const char *dir,
                         cJSON *root, const ref_lm_report *rep, const lc_ref_errstats *gr, int have_grid,
                         float *err_img, const float *cell_err, char *err, size_t errlen) {
    char path[REF_PATH_MAX + 64];
    size_t texels = (size_t)ref->width * ref->height;
    int rc = -1;
    if (!root) root = cJSON_CreateObject();
    mkdir(dir, 0755);
    if (rep->have_all) {
        snprintf(path, sizeof path, "%s/error_lightmap.png", dir);
        if (lc_ref_write_heatmap(path, err_img, ref->width, ref->height, o->max_err, (uint32_t)o->zoom, err, errlen) !=
            0)
            goto done;
        /* The uv map marks light where the reference is dark (a buried texel the engine lights) as
         * too bright; they are NAN (not compared) in err_img. Then err_img's NANs become 0 for the EXR. */
        for (size_t i = 0; i < texels; i++)
            if (ref->texel_mask[i] == 1 && isnan(err_img[i]) &&
                !(lc_ref_luminance(ref->lightmap + 3 * i) > rep->all.threshold) &&
                lc_ref_luminance(lightmap + 3 * i) > rep->all.threshold)
                err_img[i] = INFINITY;
        snprintf(path, sizeof path, "%s/error_lightmap_uv.png", dir);
        if (lc_ref_write_heatmap_uv(path, err_img, ref->texel_mask, ref->width, ref->height, o->max_err, err, errlen) !=
            0)
            goto done;
        for (size_t i = 0; i < texels; i++)
            if (isnan(err_img[i]) || isinf(err_img[i])) err_img[i] = 0;
        snprintf(path, sizeof path, "%s/error_lightmap.exr", dir);
        if (lc_image_write_float(path, ref->width, ref->height, 1, err_img, err, errlen) != 0) goto done;
    }
    if (have_grid) {
        snprintf(path, sizeof path, "%s/error_grid.bin", dir);
        if (lc_fs_write_atomic(path, cell_err, (size_t)ref->n_cells * sizeof(float), err, errlen) != 0) goto done;
    }
    cJSON_AddStringToObject(root, "metric", REF_METRIC_TEXT);
    cJSON_AddNumberToObject(root, "threshold_frac", o->threshold);
    cJSON_AddNumberToObject(root, "heatmap_max_err", o->max_err);
    if (rep->have_all) json_add_lightmap_report(root, ref, rep);
    if (have_grid) json_add_text(root, "grid", lc_ref_errstats_json(gr));
    cJSON *rs = cJSON_AddObjectToObject(root, "reference");
    cJSON_AddNumberToObject(rs, "texel_mean_rel_stderr", ref->texel_stats.mean_rel_stderr);
    cJSON_AddNumberToObject(rs, "texel_max_rel_stderr", ref->texel_stats.max_rel_stderr);
    cJSON_AddNumberToObject(rs, "texel_spp_mean", ref->texel_stats.spp_mean);
    cJSON_AddNumberToObject(rs, "grid_mean_rel_stderr", ref->grid_stats.mean_rel_stderr);
    cJSON_AddNumberToObject(rs, "seconds", ref->seconds);
    char *text = cJSON_Print(root);
    snprintf(path, sizeof path, "%s/compare.json", dir);
    int wrc = text ? lc_fs_write_atomic(path, text, strlen(text), err, errlen) : -1;
    if (!text) lc_set_err(err, errlen, "out of memory");
    cJSON_free(text);
    if (wrc != 0) goto done;
    fprintf(stderr, "lucent-ref: wrote %s (and error_lightmap.png/_uv.png/.exr)\n", path);
    rc = 0;
done:
    cJSON_Delete(root);
    return rc;
}

/* Compares and reports; writes DIR/compare.json (+ heat maps) when dir is set. extra may be NULL
 * (taken: freed here); bound (may be NULL) is printed as a row of the table. */
static int do_compare(const lc_ref_result *ref, const float *lightmap, const float *grid, const ref_opts *o,
                      const char *dir, cJSON *extra, const lc_ref_errstats *bound, char *err, size_t errlen) {
    ref_lm_report rep;
    memset(&rep, 0, sizeof rep);
    lc_ref_errstats gr = {0};
    float *err_img = NULL, *cell_err = NULL;
    int have_grid = 0, rc = -1;
    size_t texels = (size_t)ref->width * ref->height;
    if (lightmap && texels) {
        err_img = malloc(texels * sizeof(float));
        if (!err_img || compare_lightmap(ref, lightmap, o, err_img, &rep) != 0) goto oom;
    }
    if (grid && ref->n_cells) {
        cell_err = malloc((size_t)ref->n_cells * sizeof(float));
        if (!cell_err) goto oom;
        have_grid = lc_ref_compare_grid(grid, ref->grid_sh, ref->grid_sh_stderr, ref->grid_mask, ref->n_cells,
                                        o->threshold, &gr, cell_err) == 0;
    }
    if (!rep.have_all && !have_grid) {
        lc_set_err(err, errlen, "nothing to compare (no lightmap/grid given, or no texel above the threshold)");
        goto done;
    }
    printf("%-10s %8s %9s %9s %9s %9s %9s %9s\n", "", "n", "mean", "p50", "p95", "max", "bias", "ref-noise");
    if (rep.have_all) print_row("lightmap", &rep.all);
    if (rep.have_moved) {
        print_row("lm_moved", &rep.moved);
        print_row("lm_unmoved", &rep.unmoved);
    }
    if (bound) print_row("bound", bound); /* the same texels gathered from the surfels, no links */
    if (have_grid) print_row("grid", &gr);
    if (rep.have_all) print_lightmap_report(ref, &rep);
    fflush(stdout);
    if (dir && dir[0]) {
        rc = compare_write(ref, lightmap, o, dir, extra, &rep, &gr, have_grid, err_img, cell_err, err, errlen);
        extra = NULL;
        goto done;
    }
    rc = 0;
    goto done;
oom:
    lc_set_err(err, errlen, "out of memory");
done:
    cJSON_Delete(extra);
    free(err_img);
    free(cell_err);
    return rc;
}

static int cmd_compare(int argc, char **argv) {
    static ref_opts o;
    char *pos[2];
    char err[1024] = "";
    int n = parse(&o, argc, argv, pos, 2);
    if (n < 0) return EXIT_USAGE;
    if (n != 0 || !o.reference[0] || (!o.lightmap[0] && !o.grid[0])) {
        fprintf(stderr, "lucent-ref: compare needs --reference DIR and --lightmap and/or --grid (see --help)\n");
        return EXIT_USAGE;
    }
    lc_ref_result ref;
    float *lm = NULL, *grid = NULL;
    int rc = EXIT_FAIL;
    if (lc_ref_read(o.reference, &ref, err, sizeof err) != 0) goto done;
    if (o.lightmap[0] && !(lm = load_lightmap(o.lightmap, ref.width, ref.height, err, sizeof err))) goto done;
    if (o.grid[0]) {
        size_t len = 0, expect = (size_t)ref.n_cells * 27 * sizeof(float);
        grid = (float *)lc_fs_read(o.grid, expect + 1, &len, err, sizeof err);
        if (!grid) goto done;
        if (len != expect) {
            lc_set_err(err, sizeof err, "%s: %zu bytes, the reference grid needs %zu", o.grid, len, expect);
            goto done;
        }
    }
    if (do_compare(&ref, lm, grid, &o, o.out, NULL, NULL, err, sizeof err) != 0) goto done;
    rc = EXIT_OK;
done:
    if (rc != EXIT_OK) fprintf(stderr, "lucent-ref: %s\n", err);
    lc_ref_result_free(&ref);
    free(lm);
    free(grid);
    return rc;
}

/* `delta`: the object's change against the references' (delta.c). */
static int cmd_delta(int argc, char **argv) {
    static ref_opts o;
    char *pos[2];
    char err[1024] = "";
    int n = parse(&o, argc, argv, pos, 2);
    if (n < 0) return EXIT_USAGE;
    if (n != 0 || !o.reference[0] || !o.reference_with[0] || !o.lightmap[0] || !o.lightmap_with[0]) {
        fprintf(stderr,
                "lucent-ref: delta needs --reference, --reference-with, --lightmap and --lightmap-with (see "
                "--help)\n");
        return EXIT_USAGE;
    }
    lc_ref_result r0, r1;
    memset(&r1, 0, sizeof r1);
    float *a0 = NULL, *a1 = NULL, *img = NULL;
    char *json = NULL;
    int rc = EXIT_FAIL;
    if (lc_ref_read(o.reference, &r0, err, sizeof err) != 0) {
        memset(&r0, 0, sizeof r0);
        goto done;
    }
    if (lc_ref_read(o.reference_with, &r1, err, sizeof err) != 0) {
        memset(&r1, 0, sizeof r1);
        goto done;
    }
    if (r0.cache_crc != r1.cache_crc || r0.width != r1.width || r0.height != r1.height) {
        lc_set_err(err, sizeof err, "%s and %s are references of different bakes", o.reference, o.reference_with);
        goto done;
    }
    if (!(a0 = load_lightmap(o.lightmap, r0.width, r0.height, err, sizeof err)) ||
        !(a1 = load_lightmap(o.lightmap_with, r0.width, r0.height, err, sizeof err)))
        goto done;
    img = malloc((size_t)r0.width * r0.height * 3 * sizeof *img + 1);
    lc_ref_delta_stats ds;
    if (!img || lc_ref_delta_lightmap(a0, a1, &r0, &r1, o.k_sigma, o.delta_floor, &ds, img) != 0) {
        lc_set_err(err, sizeof err, img ? "no texel changes by more than the references' noise" : "out of memory");
        goto done;
    }
    printf("delta      %u texels (%u darker, %u brighter, %u under the object): error %.2f%% of |dE| (%.2f%% without "
           "those under it), bias %+.2f%%, sign right %.1f%%, darker sum ratio %.3f, brighter %.3f, reference noise "
           "%.2f%%, largest change %.1f%% of E\n",
           ds.n, ds.n_neg, ds.n_pos, ds.n_buried, 100 * ds.error, 100 * ds.error_unburied, 100 * ds.bias,
           100 * ds.sign_agree, ds.neg_ratio, ds.pos_ratio, 100 * ds.ref_noise, 100 * ds.max_rel_change);
    printf("colour     sum dRGB approx (%.4g, %.4g, %.4g), reference (%.4g, %.4g, %.4g)\n", ds.rgb_approx[0],
           ds.rgb_approx[1], ds.rgb_approx[2], ds.rgb_ref[0], ds.rgb_ref[1], ds.rgb_ref[2]);
    if (o.out[0]) {
        char path[REF_PATH_MAX + 64];
        mkdir(o.out, 0755);
        snprintf(path, sizeof path, "%s/delta_lightmap.exr", o.out);
        for (size_t i = 0; i < (size_t)r0.width * r0.height * 3; i++)
            if (isnan(img[i])) img[i] = 0;
        if (lc_image_write_float(path, r0.width, r0.height, 3, img, err, sizeof err) != 0) goto done;
        if (!(json = lc_ref_delta_json(&ds))) {
            lc_set_err(err, sizeof err, "out of memory");
            goto done;
        }
        snprintf(path, sizeof path, "%s/delta.json", o.out);
        if (lc_fs_write_atomic(path, json, strlen(json), err, sizeof err) != 0) goto done;
        fprintf(stderr,
                "lucent-ref: wrote %s and delta_lightmap.exr (R = dE reference, G = dE approx, B = their "
                "difference)\n",
                path);
    }
    rc = EXIT_OK;
done:
    if (rc != EXIT_OK) fprintf(stderr, "lucent-ref: %s\n", err);
    lc_ref_result_free(&r0);
    lc_ref_result_free(&r1);
    free(a0);
    free(a1);
    free(img);
    free(json);
    return rc;
}

/* The gather bound of the engine's solution: writes DIR/bound_lightmap.exr and, when any texel
 * is compared, its error statistics (*have = 1). Returns 0 or -1 with err set. */
static int fidelity_bound(const lc_lcb *bake, const lc_ref_engine_run *run, const lc_ref_result *ref, const ref_opts *o,
                          const char *dir, lc_ref_errstats *stats, int *have, char *err, size_t errlen) {
    const lc_lcb_view *v = lc_lcb_get(bake);
    float *bound = malloc((size_t)v->lightmap_width * v->lightmap_height * 3 * sizeof(float) + 1);
    char path[REF_PATH_MAX + 64];
    int rc = -1;
    if (!bound) {
        lc_set_err(err, errlen, "out of memory for the gather bound");
        return -1;
    }
    if (lc_ref_gather_bound(bake, run->surfel_radiosity, (uint32_t)o->bound_rays, (uint64_t)o->seed, o->threads, bound,
                            err, errlen) != 0)
        goto done;
    snprintf(path, sizeof path, "%s/bound_lightmap.exr", dir);
    if (lc_image_write_float(path, v->lightmap_width, v->lightmap_height, 3, bound, err, errlen) != 0) goto done;
    *have = lc_ref_compare_lightmap(bound, ref->lightmap, ref->lightmap_stderr, ref->texel_mask, ref->width,
                                    ref->height, o->threshold, stats, NULL) == 0;
    rc = 0;
done:
    free(bound);
    return rc;
}

/* The reference's texel surfaces (computed from the bake when the reference has none) and the
 * moved mask, from the bake's cache flags. Returns 0 or -1 with err set. */
static int fidelity_texels(const lc_lcb_view *v, lc_ref_result *ref, char *err, size_t errlen) {
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    int have = ref->texel_surface != NULL;
    float *surface = have ? NULL : malloc((texels * LC_REF_SURFACE_STRIDE + 1) * sizeof(float));
    uint8_t *moved = malloc(texels + 1);
    lc_ref_surface_stats st;
    if ((!have && !surface) || !moved) {
        lc_set_err(err, errlen, "out of memory for %zu texels", texels);
        goto err;
    }
    if (have) {
        memset(moved, 0, texels);
        for (uint32_t c = 0; c < v->n_texel_caches; c++)
            if ((v->caches[c].flags & LC_CACHE_TEXEL) && v->caches[c].index < texels)
                moved[v->caches[c].index] = (v->caches[c].flags & LC_CACHE_MOVED) != 0;
    } else {
        if (lc_ref_bake_texels(v, surface, moved, &st, err, errlen) != 0) goto err;
        ref->texel_surface = surface;
        ref->surface_stats = st;
    }
    free(ref->texel_moved);
    ref->texel_moved = moved;
    return 0;
err:
    free(surface);
    free(moved);
    return -1;
}

/* DIR/texels.csv: one row per texel cache (best effort: a file that cannot be opened is skipped). */
static void fidelity_csv(const char *path, const lc_lcb_view *v, const lc_ref_result *ref, const float *lightmap) {
    FILE *csv = fopen(path, "w");
    if (!csv) return;
    fprintf(csv, "cache,x,y,px,py,pz,nx,ny,nz,moved,ref_y,ref_stderr_y,engine_y,rel_err,sx,sy,sz,spacing\n");
    size_t texels = (size_t)v->lightmap_width * v->lightmap_height;
    for (uint32_t c = 0; c < v->n_texel_caches; c++) {
        const lc_lcb_cache *ca = &v->caches[c];
        uint32_t i = ca->index;
        if (i >= texels) continue;
        double yr = lc_ref_luminance(ref->lightmap + 3 * (size_t)i), ya = lc_ref_luminance(lightmap + 3 * (size_t)i);
        const float nan3[LC_REF_SURFACE_STRIDE] = {NAN, NAN, NAN, NAN, NAN, NAN, NAN};
        const float *sf = ref->texel_surface ? ref->texel_surface + LC_REF_SURFACE_STRIDE * (size_t)i : nan3;
        fprintf(csv, "%u,%u,%u,%.5f,%.5f,%.5f,%.4f,%.4f,%.4f,%d,%.6g,%.6g,%.6g,%.6g,%.5f,%.5f,%.5f,%.5g\n", c,
                i % v->lightmap_width, i / v->lightmap_width, ca->position[0], ca->position[1], ca->position[2],
                ca->normal[0], ca->normal[1], ca->normal[2], (ca->flags & LC_CACHE_MOVED) != 0, yr,
                lc_ref_luminance(ref->lightmap_stderr + 3 * (size_t)i), ya, yr > 0 ? (ya - yr) / yr : 0, sf[0], sf[1],
                sf[2], sf[6]);
    }
    fclose(csv);
}

static int cmd_fidelity(int argc, char **argv) {
    static ref_opts o;
    char *pos[2];
    char err[1024] = "";
    int n = parse(&o, argc, argv, pos, 2);
    if (n < 0) return EXIT_USAGE;
    if (n != 1) {
        fprintf(stderr, "lucent-ref: fidelity needs one BAKE.lcb (see --help)\n");
        return EXIT_USAGE;
    }
    const char *dir = o.out[0] ? o.out : "fidelity-out";
    lc_lcb *bake = NULL;
    lc_ref_state st;
    memset(&st, 0, sizeof st);
    lc_ref_result ref;
    memset(&ref, 0, sizeof ref);
    lc_ref_engine_run run;
    memset(&run, 0, sizeof run);
    int rc = EXIT_FAIL;
    char path[REF_PATH_MAX + 64];
    if (lc_lcb_open(pos[0], &bake, err, sizeof err) != 0) goto done;
    const lc_lcb_view *v = lc_lcb_get(bake);
    if (lc_ref_state_load(bake, o.state[0] ? o.state : NULL, 0, &st, err, sizeof err) != 0) goto done;
    mkdir(dir, 0755);
    if (o.reference[0]) {
        if (lc_ref_read(o.reference, &ref, err, sizeof err) != 0) goto done;
        if (ref.width != v->lightmap_width || ref.height != v->lightmap_height ||
            ref.cache_crc != lc_ref_cache_crc(v)) {
            lc_set_err(err, sizeof err,
                       "%s was rendered for other caches (lightmap %ux%u, cache CRC %08x; this bake %ux%u, %08x)",
                       o.reference, ref.width, ref.height, ref.cache_crc, v->lightmap_width, v->lightmap_height,
                       lc_ref_cache_crc(v));
            goto done;
        }
        if (o.bounce_limit >= 0 && ref.max_bounces != (uint32_t)o.bounce_limit) {
            lc_set_err(err, sizeof err, "--bounce-limit %d needs a reference rendered with it (%s has %u)",
                       o.bounce_limit, o.reference, ref.max_bounces);
            goto done;
        }
    } else {
        snprintf(path, sizeof path, "%s/reference", dir);
        if (do_render(pos[0], bake, &st, &o, path, &ref, err, sizeof err) != 0) goto done;
    }
    if (ref.width && fidelity_texels(v, &ref, err, sizeof err) != 0) goto done;
    static const lc_backend_kind kinds[3] = {LC_BACKEND_AUTO, LC_BACKEND_CPU, LC_BACKEND_EGL};
    if (lc_ref_engine_converge(bake, &st.st, kinds[o.backend], o.threads, o.tol, (uint32_t)o.max_relights,
                               o.bounce_limit, &run, err, sizeof err) != 0)
        goto done;
    printf("engine (%s): %u relights to converge (last change %.2e), first relight %.1f ms\n", run.backend,
           run.relights, run.last_change, run.ms_first);
    if (run.clutter_objects)
        printf("clutter: DRT operators for %u object(s) built in %.0f ms, %.1f MiB\n", run.clutter_objects,
               run.clutter_build_ms, run.clutter_bytes / 1048576.0);
    /* Where the light starts: the surfels' B0 against the exact surface integral. */
    double pw[3], pw_se[3];
    {
        lc_ref *r = lc_ref_create(bake, &st.st, o.threads, err, sizeof err);
        if (!r) goto done;
        lc_ref_b0_power(r, 1u << 20, (uint64_t)o.seed, pw, pw_se);
        lc_ref_release(r);
    }
    double pw_y = lc_ref_luminance((float[3]){(float)pw[0], (float)pw[1], (float)pw[2]});
    double eng_y = lc_ref_luminance((float[3]){(float)run.b0_power[0], (float)run.b0_power[1], (float)run.b0_power[2]});
    double pw_se_y = lc_ref_luminance((float[3]){(float)pw_se[0], (float)pw_se[1], (float)pw_se[2]});
    printf("B0 power (luminance W): engine surfels %.6g, exact surfaces %.6g +- %.2g: %+.2f%%\n", eng_y, pw_y, pw_se_y,
           pw_y > 0 ? 100 * (eng_y / pw_y - 1) : 0);
    snprintf(path, sizeof path, "%s/engine_lightmap.exr", dir);
    if (lc_image_write_float(path, v->lightmap_width, v->lightmap_height, 3, run.lightmap, err, sizeof err) != 0)
        goto done;
    snprintf(path, sizeof path, "%s/engine_grid.bin", dir);
    if (lc_fs_write_atomic(path, run.grid_sh, (size_t)ref.n_cells * 27 * sizeof(float), err, sizeof err) != 0)
        goto done;
    /* Per texel cache, for digging into where the error is. */
    snprintf(path, sizeof path, "%s/texels.csv", dir);
    fidelity_csv(path, v, &ref, run.lightmap);
    fflush(stdout);
    /* How close any link budget could get with these surfels (see lc_ref_gather_bound). */
    lc_ref_errstats bs = {0};
    int have_bound = 0;
    if (o.bound_rays > 0 && ref.lightmap &&
        fidelity_bound(bake, &run, &ref, &o, dir, &bs, &have_bound, err, sizeof err) != 0)
        goto done;
    cJSON *extra = cJSON_CreateObject();
    cJSON_AddStringToObject(extra, "bake", pos[0]);
    cJSON_AddStringToObject(extra, "state", o.state[0] ? o.state : "(daemon initial state)");
    cJSON_AddStringToObject(extra, "backend", run.backend);
    cJSON_AddNumberToObject(extra, "relights", run.relights);
    cJSON_AddNumberToObject(extra, "last_change", run.last_change);
    cJSON_AddNumberToObject(extra, "bounce_limit", o.bounce_limit);
    cJSON_AddStringToObject(extra, "reference_texel_at", lc_ref_texel_at_name(ref.texel_at));
    cJSON_AddNumberToObject(extra, "bounces_per_relight", st.st.settings.bounces);
    cJSON_AddNumberToObject(extra, "bands", st.st.settings.bands);
    cJSON_AddNumberToObject(extra, "surfels", v->n_surfels);
    cJSON_AddNumberToObject(extra, "links_per_cache", v->links_per_cache);
    cJSON_AddNumberToObject(extra, "texel_caches", v->n_texel_caches);
    cJSON_AddNumberToObject(extra, "ms_first_relight", run.ms_first);
    cJSON_AddNumberToObject(extra, "b0_power_engine", eng_y);
    cJSON_AddNumberToObject(extra, "b0_power_reference", pw_y);
    cJSON_AddNumberToObject(extra, "b0_power_reference_stderr", pw_se_y);
    if (have_bound) {
        char *t = lc_ref_errstats_json(&bs);
        cJSON *b = t ? cJSON_Parse(t) : NULL;
        free(t);
        if (b) {
            cJSON_AddNumberToObject(b, "rays", o.bound_rays);
            cJSON_AddItemToObject(extra, "bound", b);
        }
    }
    if (do_compare(&ref, run.lightmap, run.grid_sh, &o, dir, extra, have_bound ? &bs : NULL, err, sizeof err) != 0)
        goto done;
    snprintf(path, sizeof path, "%s/compare.json", dir);
    char dst[REF_PATH_MAX + 64];
    snprintf(dst, sizeof dst, "%s/fidelity.json", dir);
    if (rename(path, dst) != 0) {
        lc_set_err(err, sizeof err, "cannot rename %s to %s", path, dst);
        goto done;
    }
    fprintf(stderr, "lucent-ref: wrote %s\n", dst);
    rc = EXIT_OK;
done:
    if (rc != EXIT_OK) fprintf(stderr, "lucent-ref: %s\n", err);
    lc_ref_engine_run_free(&run);
    lc_ref_result_free(&ref);
    lc_ref_state_free(&st);
    lc_lcb_close(bake);
    return rc;
}

/* A file name ending in ext (case-insensitive), for the flag's error. */
static int ends_with(const char *path, const char *ext) {
    size_t n = strlen(path), e = strlen(ext);
    return n > e && !strcasecmp(path + n - e, ext);
}

/* The camera's flags beyond what the option table checks. Returns 0, or -1 with err naming
 * the flag. */
static int camera_check(const ref_opts *o, int n_pos, lc_ref_camera *cam, char *err, size_t errlen) {
    if (n_pos != 1) {
        lc_set_err(err, errlen, "camera needs one BAKE.lcb (see --help)");
        return -1;
    }
    if (!o->have_eye || !o->have_target) {
        lc_set_err(err, errlen, "%s: required (camera position and the point it looks at)",
                   !o->have_eye ? "--eye" : "--target");
        return -1;
    }
    if (!o->exr[0] && !o->png[0]) {
        lc_set_err(err, errlen, "--exr/--png: camera needs at least one output file");
        return -1;
    }
    const char *bad_name = o->exr[0] && !ends_with(o->exr, ".exr") ? "--exr: the file name must end in .exr"
        : o->png[0] && !ends_with(o->png, ".png")                  ? "--png: the file name must end in .png"
                                                                   : NULL;
    if (bad_name) {
        lc_set_err(err, errlen, "%s", bad_name);
        return -1;
    }
    memset(cam, 0, sizeof *cam);
    memcpy(cam->eye, o->eye, sizeof cam->eye);
    memcpy(cam->target, o->target, sizeof cam->target);
    if (o->have_up) memcpy(cam->up, o->up, sizeof cam->up);
    else cam->up[1] = 1;
    cam->fov_deg = o->fov;
    cam->width = (uint32_t)o->width;
    cam->height = (uint32_t)o->height;
    lc_ref_camera_basis b;
    return lc_ref_camera_setup(cam, &b, err, errlen);
}

static int cmd_camera(int argc, char **argv) {
    static ref_opts o;
    char *pos[2];
    char err[1024] = "";
    int n = parse(&o, argc, argv, pos, 2);
    if (n < 0) return EXIT_USAGE;
    lc_ref_camera cam;
    if (camera_check(&o, n, &cam, err, sizeof err) != 0) {
        fprintf(stderr, "lucent-ref: %s\n", err);
        return EXIT_USAGE;
    }
    lc_ref_camera_settings cs = {(uint32_t)(o.spp ? o.spp : 64), (uint32_t)o.max_depth, (uint32_t)o.rr_depth,
                                 (uint64_t)o.seed, o.quiet};
    lc_lcb *bake = NULL;
    lc_ref *r = NULL;
    lc_ref_state st;
    memset(&st, 0, sizeof st);
    lc_ref_image img;
    memset(&img, 0, sizeof img);
    int rc = EXIT_FAIL;
    if (lc_lcb_open(pos[0], &bake, err, sizeof err) != 0) goto done;
    if (lc_ref_state_load(bake, o.state[0] ? o.state : NULL, 1, &st, err, sizeof err) != 0) goto done;
    if (!(r = lc_ref_create(bake, &st.st, o.threads, err, sizeof err))) goto done;
    if (lc_ref_camera_render(r, &cam, &cs, &img, err, sizeof err) != 0) goto done;
    if (o.exr[0] && lc_image_write_float(o.exr, img.width, img.height, 3, img.rgb, err, sizeof err) != 0) goto done;
    if (o.png[0] &&
        lc_ref_image_write_png(o.png, &img, (lc_ref_tonemap_kind)o.tonemap, o.exposure, err, sizeof err) != 0)
        goto done;
    fprintf(stderr,
            "lucent-ref: camera %ux%u, %u spp, max depth %u: %.2f s, %.2f Mrays/s; noise: mean relative "
            "stderr %.4f over the %u pixels above 5%% of the mean luminance\n",
            img.width, img.height, cs.spp, cs.max_depth, img.seconds,
            img.seconds > 0 ? img.rays / img.seconds / 1e6 : 0, img.mean_rel_stderr, img.n_bright);
    rc = EXIT_OK;
done:
    if (rc != EXIT_OK) fprintf(stderr, "lucent-ref: %s\n", err);
    lc_ref_image_free(&img);
    lc_ref_release(r);
    lc_ref_state_free(&st);
    lc_lcb_close(bake);
    return rc;
}

/* 1 when argv holds --name or --name=... (a flag whose default differs per command). */
static int flag_given(int argc, char **argv, const char *name) {
    size_t n = strlen(name);
    for (int i = 2; i < argc; i++) {
        if (!strcmp(argv[i], "--")) return 0;
        if (!strncmp(argv[i], "--", 2) && !strncmp(argv[i] + 2, name, n) &&
            (argv[i][2 + n] == 0 || argv[i][2 + n] == '='))
            return 1;
    }
    return 0;
}

/* The capture's poses from --path, or --frames jittered copies of --eye/--target. */
static int capture_poses(const ref_opts *o, int argc, char **argv, lc_ref_capture_pose **poses, uint32_t *n, char *err,
                         size_t errlen) {
    lc_ref_camera cam;
    memset(&cam, 0, sizeof cam);
    if (o->have_up) memcpy(cam.up, o->up, sizeof cam.up);
    else cam.up[1] = 1;
    cam.fov_deg = flag_given(argc, argv, "fov") ? o->fov : 60;
    cam.width = (uint32_t)(flag_given(argc, argv, "width") ? o->width : 256);
    cam.height = (uint32_t)(flag_given(argc, argv, "height") ? o->height : 192);
    if (cam.width < LC_REF_CAPTURE_MIN_SIDE || cam.height < LC_REF_CAPTURE_MIN_SIDE ||
        cam.width > LC_REF_CAPTURE_MAX_SIDE || cam.height > LC_REF_CAPTURE_MAX_SIDE) {
        lc_set_err(err, errlen, "--width/--height: %ux%u is outside the replay format's %u..%u (PROTOCOL.md 8.2)",
                   cam.width, cam.height, LC_REF_CAPTURE_MIN_SIDE, LC_REF_CAPTURE_MAX_SIDE);
        return -1;
    }
    if (o->path[0]) {
        if (o->have_eye || o->have_target || flag_given(argc, argv, "frames") || flag_given(argc, argv, "jitter-mm") ||
            flag_given(argc, argv, "jitter-deg")) {
            lc_set_err(err, errlen,
                       "--path: not with --eye/--target/--frames/--jitter-mm/--jitter-deg (the path gives every pose)");
            return -1;
        }
        return lc_ref_capture_path_load(o->path, &cam, poses, n, err, errlen);
    }
    if (!o->have_eye || !o->have_target) {
        lc_set_err(err, errlen, "%s: required without --path (camera position and the point it looks at)",
                   !o->have_eye ? "--eye" : "--target");
        return -1;
    }
    memcpy(cam.eye, o->eye, sizeof cam.eye);
    memcpy(cam.target, o->target, sizeof cam.target);
    lc_ref_rgbd_view base;
    if (lc_ref_rgbd_lookat(&cam, &base, err, errlen) != 0) return -1;
    *poses = calloc((size_t)o->frames, sizeof **poses);
    if (!*poses) {
        lc_set_err(err, errlen, "--frames: out of memory for %d poses", o->frames);
        return -1;
    }
    *n = (uint32_t)o->frames;
    lc_ref_capture_jitter(&base, *n, o->jitter_mm, o->jitter_deg, (uint64_t)o->seed, *poses);
    return 0;
}

static int cmd_capture(int argc, char **argv) {
    static ref_opts o;
    char *pos[2];
    char err[1024] = "";
    int n = parse(&o, argc, argv, pos, 2);
    if (n < 0) return EXIT_USAGE;
    lc_ref_capture_pose *poses = NULL;
    uint32_t n_poses = 0;
    if (n != 1 || !o.out[0]) {
        fprintf(stderr, "lucent-ref: %s\n", n != 1 ? "capture needs one BAKE.lcb (see --help)" : "--out: required");
        return EXIT_USAGE;
    }
    if (capture_poses(&o, argc, argv, &poses, &n_poses, err, sizeof err) != 0) {
        fprintf(stderr, "lucent-ref: %s\n", err);
        return EXIT_USAGE;
    }
    lc_ref_capture_settings cs = {(uint32_t)(o.spp ? o.spp : 16),
                                  (uint32_t)(flag_given(argc, argv, "max-depth") ? o.max_depth : 32),
                                  (uint32_t)o.rr_depth,
                                  (uint64_t)o.seed,
                                  o.color == 1,
                                  o.quiet};
    lc_lcb *bake = NULL;
    lc_ref *r = NULL;
    lc_ref_state st;
    memset(&st, 0, sizeof st);
    int rc = EXIT_FAIL;
    if (lc_lcb_open(pos[0], &bake, err, sizeof err) != 0) goto done;
    if (lc_ref_state_load(bake, o.state[0] ? o.state : NULL, 1, &st, err, sizeof err) != 0) goto done;
    if (!(r = lc_ref_create(bake, &st.st, o.threads, err, sizeof err))) goto done;
    if (lc_ref_capture_run(r, o.out, poses, n_poses, &cs, pos[0], o.state[0] ? o.state : NULL, err, sizeof err) != 0)
        goto done;
    fprintf(stderr, "lucent-ref: capture %ux%u, %u frames, %u spp -> %s\n", poses[0].view.width, poses[0].view.height,
            n_poses, cs.spp, o.out);
    rc = EXIT_OK;
done:
    if (rc != EXIT_OK) fprintf(stderr, "lucent-ref: %s\n", err);
    free(poses);
    lc_ref_release(r);
    lc_ref_state_free(&st);
    lc_lcb_close(bake);
    return rc;
}

static int cmd_mr_truth(int argc, char **argv) {
    static ref_opts o;
    char *pos[2];
    char err[1024] = "";
    int n = parse(&o, argc, argv, pos, 2);
    if (n < 0) return EXIT_USAGE;
    const char *missing = n != 1 ? "mr-truth needs one BAKE.lcb (see --help)"
        : !o.capture[0]          ? "--capture: required"
        : !o.points[0]           ? "--points: required"
        : !o.out[0]              ? "--out: required (TRUTH.json)"
                                 : NULL;
    if (missing) {
        fprintf(stderr, "lucent-ref: %s\n", missing);
        return EXIT_USAGE;
    }
    lc_ref_mr_settings ms = {(uint32_t)(o.spp ? o.spp : 4096),
                             (uint32_t)(flag_given(argc, argv, "max-depth") ? o.max_depth : 32), (uint32_t)o.rr_depth,
                             (uint64_t)o.seed, o.quiet};
    lc_lcb *bake = NULL;
    lc_ref *r = NULL;
    lc_ref_state st;
    memset(&st, 0, sizeof st);
    lc_ref_capture_frame frame;
    memset(&frame, 0, sizeof frame);
    lc_ref_mr_input in;
    memset(&in, 0, sizeof in);
    lc_ref_mr_value *values = NULL;
    char *text = NULL;
    uint32_t tris = 0;
    int rc = EXIT_FAIL;
    if (lc_lcb_open(pos[0], &bake, err, sizeof err) != 0) goto done;
    if (lc_ref_mr_points_load(o.points, lc_lcb_get(bake), &in, err, sizeof err) != 0) goto done;
    if (lc_ref_capture_read_frame(o.capture, (uint32_t)o.frame, &frame, err, sizeof err) != 0) goto done;
    if (lc_ref_state_load(bake, o.state[0] ? o.state : NULL, 1, &st, err, sizeof err) != 0) goto done;
    if (!(r = lc_ref_create(bake, &st.st, o.threads, err, sizeof err))) goto done;
    if (!(values = calloc(in.n_points, sizeof *values))) {
        lc_set_err(err, sizeof err, "out of memory for %u points", in.n_points);
        goto done;
    }
    if (lc_ref_mr_truth(r, lc_lcb_get(bake), &frame, &in, &ms, values, &tris, err, sizeof err) != 0) goto done;
    if (!(text = lc_ref_mr_json(in.points, values, in.n_points, ms.spp))) {
        lc_set_err(err, sizeof err, "out of memory writing %s", o.out);
        goto done;
    }
    if (lc_fs_write_atomic(o.out, text, strlen(text), err, sizeof err) != 0) goto done;
    fprintf(stderr, "lucent-ref: mr-truth %u points, %u spp, %u occluders, frame %d: %u visible triangles -> %s\n",
            in.n_points, ms.spp, in.n_occluders, o.frame, tris, o.out);
    rc = EXIT_OK;
done:
    if (rc != EXIT_OK) fprintf(stderr, "lucent-ref: %s\n", err);
    free(text);
    free(values);
    lc_ref_mr_input_free(&in);
    lc_ref_capture_frame_free(&frame);
    lc_ref_release(r);
    lc_ref_state_free(&st);
    lc_lcb_close(bake);
    return rc;
}

int main(int argc, char **argv) {
    if (argc < 2 || !strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
        usage(argc < 2 ? stderr : stdout);
        return argc < 2 ? EXIT_USAGE : EXIT_OK;
    }
    if (!strcmp(argv[1], "render")) return cmd_render(argc, argv);
    if (!strcmp(argv[1], "compare")) return cmd_compare(argc, argv);
    if (!strcmp(argv[1], "delta")) return cmd_delta(argc, argv);
    if (!strcmp(argv[1], "fidelity")) return cmd_fidelity(argc, argv);
    if (!strcmp(argv[1], "camera")) return cmd_camera(argc, argv);
    if (!strcmp(argv[1], "capture")) return cmd_capture(argc, argv);
    if (!strcmp(argv[1], "mr-truth")) return cmd_mr_truth(argc, argv);
    fprintf(
        stderr,
        "lucent-ref: unknown command '%s' (render, compare, delta, fidelity, camera, capture, mr-truth; see --help)\n",
        argv[1]);
    return EXIT_USAGE;
}
