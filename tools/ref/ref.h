/* ref: the ground-truth reference for the relight engine, and the tools that compare the
 * engine against it.
 *
 * WHAT IS COMPUTED (the engine's definition, verified in engine.c / transport_cpu.c):
 *   lightmap texel  E(p, n) = integral over the hemisphere of n of L_s(p, w) cos(n, w) dw
 *   grid cell       L_lm(p) = integral over the sphere of L_s(p, w) y_lm(w) dw, output as the
 *                   cosine-convolved irradiance SH c_lm = A_l L_lm (A = pi, 2pi/3, pi/4), the
 *                   layout of lc_engine_frame.grid_sh (cells x 9 coefficients x RGB)
 * where, for a lightmap texel, p is the texel's own surface point and n its surface normal,
 * found by the reference from the mesh (below, "texel surface points"; `--texel-at cache`
 * instead takes the bake's cache position, which the bake may have moved out of geometry,
 * and normal), lifted by eps n; for a grid cell p is the cell's cache position from the bake.
 * L_s(p, w) is the radiance leaving the FIRST SURFACE seen from p along w, toward p:
 *   - only front faces count: a back face is black (the bake's links drop back-face hits);
 *   - L_s = L_e + (albedo / pi) * E_all(x): the surface's emission (the state's material
 *     emission, nits, one-sided) plus everything it reflects: direct light from the point,
 *     spot, directional and area lights (the engine's formulas: candela with the glTF range
 *     window and spot t^2 falloff, lux, one-sided area lights in nits with the range window),
 *     the environment (sky) it sees, and light from other surfaces, to any number of bounces;
 *   - rays that leave p and escape see NOTHING: direct light from lights and the directly seen
 *     sky are not part of the lightmap / grid (the client adds direct light itself); the sky
 *     does light surfaces (it enters through their reflection).
 * So the lightmap holds "indirect" irradiance in the engine's sense: light arriving from
 * surfaces, emissive surfaces included (the Cornell box's ceiling lamp is a surface).
 *
 * MATERIALS as the engine sees them: Lambertian, albedo clamped to [0, 0.99] like the bake;
 * a textured material takes the albedo of the nearest surfel of that material (facing the
 * same way), which is exactly the albedo the engine uses there (the .lcb keeps no texture);
 * a textured triangle smaller than 4 surfels takes one albedo, the surfel nearest its centroid.
 * Dynamic objects are real geometry here: they occlude every ray and reflect with their
 * baked per-vertex albedo (the engine only lets them shadow direct light — that difference
 * is part of the engine's error, as it should be).
 *
 * ESTIMATOR: path tracing with Embree, unbiased up to max_bounces bounces counted as the
 * engine counts its passes (light from emitters after at most N reflections, light from the
 * lights and the sky, which the engine puts in B0, after N + 1; longer paths are cut: relative
 * bias below albedo^(N+1), 3e-5 for a 0.73 albedo at the default 32), with Russian roulette
 * after rr_depth bounces. Next-event
 * estimation to every analytic light (one area-light sample per vertex) and to emissive
 * triangles (picked by power, uniform on the triangle), combined with the BSDF-sampled hits of
 * emissive triangles by multiple importance sampling (balance heuristic). Samples are iid, so
 * the reported standard error (sample standard deviation / sqrt(n)) is honest. Every cache
 * draws from its own random stream (seed, cache, pass): results are identical for any thread
 * count.
 *
 * TEXEL SURFACE POINTS (surface.c): the reference does not trust the bake's texel caches'
 * positions (lucent-bake moves caches that sit inside or behind geometry, LC_CACHE_MOVED: e.g.
 * the Cornell floor under the blocks, where the engine then shows light the floor never gets).
 * From the .lcb's static triangles and their uv1 (glTF convention: texel (x, y)'s centre is
 * uv ((x + 0.5) / W, (y + 0.5) / H), row 0 = top = v 0, as the bake rasterizes) it finds, for
 * every texel owning a cache, a triangle whose uv contains the centre (several: any; none:
 * the triangle with the nearest uv point, clamped barycentrics, counted as "outside"), and
 * takes the barycentric point, the interpolated vertex normal normalised (the winding normal
 * when that is degenerate or on the other side, the bake's rule for its caches) and the texel
 * spacing sqrt(world area / (uv area x W x H)) of that triangle. eps: ONE offset for every
 * texel and every path vertex, lc_ray_lift_scene of the scene's largest |coordinate| (0.1 mm
 * plus ~17 ulps; util/ray_offset.h), the same as the engine's runtime rays.
 *
 * THE CAMERA VIEW (camera.c, lc_ref_radiance) is another quantity over the same scene: the
 * full illumination a pinhole camera sees (emitters and the environment seen directly, direct
 * light from every light, indirect light), for comparing a viewer's screenshot.
 *
 * Ownership: lc_ref borrows the bake (it must outlive the handle) and copies the state.
 * Results (lc_ref_result) own their arrays; free with lc_ref_result_free. */
#ifndef LC_REF_H
#define LC_REF_H
#include <stddef.h>
#include <stdint.h>

#include "engine/engine.h"
#include "lcb/lcb.h"
#include "util/rng.h"

/* --- state ----------------------------------------------------------------------------------- */

/* An engine state with its own arrays, loaded from a daemon state JSON (`lucentctl state
 * --json`, the snapshot file) or the daemon's initial state (the bake's emission, no lights). */
typedef struct lc_ref_state {
    lc_engine_state st;
    lc_engine_light *lights;
    lc_engine_object *objects;
    float *emission;
} lc_ref_state;

/* path NULL: the daemon's initial state for this bake; bake_lights adds the bake's own lights
 * (its META lights, as a fresh lucentd starts with; `render` and `fidelity` leave them out, so
 * their references stay the indirect light of the bake's emission). Returns 0 or -1 with err
 * set (the JSON pointer of a bad field, an unknown asset...). */
int lc_ref_state_load(const lc_lcb *bake, const char *path, int bake_lights, lc_ref_state *out, char *err,
                      size_t errlen);
void lc_ref_state_free(lc_ref_state *s);

/* --- texel surface points (surface.c) ---------------------------------------------------------- */

/* Per texel: surface point xyz, unit normal xyz, texel spacing (m). */
#define LC_REF_SURFACE_STRIDE 7

typedef struct lc_ref_surface_stats {
    uint32_t texels;  /* texels asked for */
    uint32_t outside; /* of those, centres no triangle's uv contains (the nearest triangle taken) */
    uint32_t missing; /* no triangle with a valid uv at all (left NAN) */
} lc_ref_surface_stats;

/* The texel surface points (ref.h, "texel surface points") of the texels with want[i] != 0
 * (want NULL: every texel) into out (W*H*LC_REF_SURFACE_STRIDE floats, NAN for the others).
 * Triangles with non-finite or zero-area uv are ignored. Returns 0 or -1 with err set (a
 * vertex index out of range, the lightmap or uv grid over its cap, out of memory). */
int lc_ref_texel_surfaces(const lc_lcb_vertex *vertices, uint32_t n_vertices, const lc_lcb_triangle *triangles,
                          uint32_t n_triangles, uint32_t width, uint32_t height, const uint8_t *want, float *out,
                          lc_ref_surface_stats *stats, char *err, size_t errlen);

/* The same for the bake's texel caches (want = the texels owning a cache), and the moved
 * mask (W*H, may be NULL): 1 where the texel's cache has LC_CACHE_MOVED. */
int lc_ref_bake_texels(const lc_lcb_view *v, float *surface, uint8_t *moved, lc_ref_surface_stats *stats, char *err,
                       size_t errlen);

/* Texel spacing over the texels with a surface point (surface: LC_REF_SURFACE_STRIDE per texel,
 * spacing = element 6): mean, nearest-rank p50/p95, max, and the share above over_m metres.
 * Returns 0, or -1 when no texel has one. */
typedef struct lc_ref_spacing {
    uint32_t n;
    double mean, p50, p95, max;
    double over_m, share_over; /* the limit and the fraction of texels above it */
} lc_ref_spacing;
int lc_ref_spacing_stats(const float *surface, uint32_t width, uint32_t height, double over_m, lc_ref_spacing *out);
char *lc_ref_spacing_json(const lc_ref_spacing *s);

/* --- the reference renderer -------------------------------------------------------------------- */

typedef struct lc_ref_settings {
    uint32_t spp;         /* samples per cache: fixed, or the cap when target_stderr > 0 */
    uint32_t batch_spp;   /* samples per cache per pass (adaptive: convergence is checked per pass) */
    double target_stderr; /* relative standard error to reach per cache (0 = fixed spp) */
    double floor_frac;    /* a cache darker than floor_frac x the brightest counts as converged
                               when its stderr is below target x floor_frac x brightest */
    uint32_t max_bounces; /* bounces as the engine's settings.bounces counts them (default 32; 0 = emitters
                               seen directly and light-source light reflected once, i.e. B0) */
    uint32_t rr_depth;    /* Russian roulette after this many bounces (default 3) */
    uint64_t seed;
    int threads;      /* 0 = all cores */
    int texels, grid; /* which outputs to compute */
    int quiet;        /* no progress bars */
    int texel_at;     /* LC_REF_TEXEL_AT_SURFACE (default) or LC_REF_TEXEL_AT_CACHE */
} lc_ref_settings;

/* Where a texel's irradiance is evaluated: its own surface point (the default, what a user
 * sees drawn there) or the bake's cache position (moved caches stay where the bake put them:
 * the engine's own evaluation point). */
enum { LC_REF_TEXEL_AT_SURFACE = 0, LC_REF_TEXEL_AT_CACHE = 1, LC_REF_TEXEL_AT_UNKNOWN = -1 };
/* "surface", "cache" or "unknown" (a reference written before texel_at existed). */
const char *lc_ref_texel_at_name(int texel_at);

lc_ref_settings lc_ref_default_settings(void);

typedef struct lc_ref_stats {
    uint32_t n;       /* caches (texel caches or valid grid cells) */
    uint64_t samples; /* paths traced */
    double spp_mean;
    uint32_t spp_min, spp_max;
    uint32_t n_bright;      /* caches above 1% of the brightest (the set compare uses) */
    double mean_rel_stderr; /* over n_bright: stderr(luminance) / luminance */
    double p95_rel_stderr, max_rel_stderr;
} lc_ref_stats;

typedef struct lc_ref_result {
    uint32_t width, height;
    float *lightmap;        /* W*H*3 irradiance; dilated texels copy their cache (as the engine) */
    float *lightmap_stderr; /* W*H*3 standard error per channel */
    uint8_t *texel_mask;    /* W*H: 0 empty, 1 owns its cache, 2 dilated copy */
    uint32_t grid_dims[3];
    float grid_origin[3], grid_cell;
    uint32_t n_cells;
    float *grid_sh;        /* cells*27: irradiance SH (cosine-convolved), engine layout */
    float *grid_sh_stderr; /* cells*27 */
    uint8_t *grid_mask;    /* cells: 1 valid, 0 inside geometry (the engine outputs zero) */
    lc_ref_stats texel_stats, grid_stats;
    double seconds;
    uint64_t rays;
    uint32_t cache_crc;   /* CRC-32 of the bake's caches (position, normal, flags, index) */
    uint32_t max_bounces; /* the paths' reflection limit it was rendered with */
    int texel_at;         /* LC_REF_TEXEL_AT_*: where the texels were evaluated */
    /* Per texel owning a cache (NULL when the reference has none: written before they existed). */
    float *texel_surface; /* W*H*LC_REF_SURFACE_STRIDE (lc_ref_texel_surfaces), NAN elsewhere */
    uint8_t *texel_moved; /* W*H: 1 = the bake moved this texel's cache (LC_CACHE_MOVED) */
    lc_ref_surface_stats surface_stats;
    double unmoved_offset_max; /* max distance surface point - cache position over unmoved caches (m; -1 unknown) */
} lc_ref_result;

typedef struct lc_ref lc_ref;

/* Builds the ray-tracing scene (static mesh + placed objects), the emitter table and the
 * textured-albedo lookup. Returns NULL with err set. */
lc_ref *lc_ref_create(const lc_lcb *bake, const lc_engine_state *state, int threads, char *err, size_t errlen);
void lc_ref_release(lc_ref *r);
/* The worker threads it was created with (0 = all cores). */
int lc_ref_threads(const lc_ref *r);

/* Renders the reference for every texel cache and grid cell. Returns 0 or -1 with err set;
 * on success *out owns its arrays. */
int lc_ref_render(lc_ref *r, const lc_ref_settings *s, lc_ref_result *out, char *err, size_t errlen);
void lc_ref_result_free(lc_ref_result *res);

/* One point, for tests and probes: irradiance for normal n at p (n != NULL; mean and stderr
 * RGB), with spp samples. */
void lc_ref_irradiance(lc_ref *r, const float p[3], const float n[3], uint32_t spp, uint64_t seed, double mean[3],
                       double stderr_out[3]);

/* The radiance a camera sees along a ray (unit dir) from org: full illumination, emission and
 * the environment seen directly, everything after at most max_depth reflections (0: emitters
 * and the environment only; 1: direct light), Russian roulette from rr_depth reflections on.
 * One sample; *rays counts the rays cast. */
void lc_ref_radiance(const lc_ref *r, const float org[3], const float dir[3], uint32_t max_depth, uint32_t rr_depth,
                     lc_rng *rng, float L[3], uint64_t *rays);

/* The same with sky_first = 0: a first ray that escapes sees nothing (the environment still
 * lights surfaces, through every later ray): what an RGB-D capture records, where a pixel
 * without a surface has no colour. lc_ref_radiance is sky_first = 1. */
void lc_ref_radiance_ex(const lc_ref *r, const float org[3], const float dir[3], uint32_t max_depth, uint32_t rr_depth,
                        int sky_first, lc_rng *rng, float L[3], uint64_t *rays);

/* Something other than the scene on the segment from org along unit dir up to tfar (INFINITY:
 * the whole ray): 1 blocks it. */
typedef int (*lc_ref_block_fn)(void *ctx, const float org[3], const float dir[3], float tfar);

/* One sample of the lightmap's irradiance E(org, n) (ref.h, "WHAT IS COMPUTED"; org already
 * lifted, n unit): a light sample toward the emissive triangles and a cosine-sampled path
 * (max_bounces as lc_ref_settings counts them, Russian roulette from rr_depth), combined by
 * MIS; lc_ref_irradiance averages these. block (may be NULL) tests the first segment of both
 * (the light sample up to the emitter, the first ray up to its first hit): where it blocks, the
 * sample gets nothing along it (`mr-truth`'s virtual occluders). */
void lc_ref_irradiance_sample(const lc_ref *r, const float org[3], const float n[3], uint32_t max_bounces,
                              uint32_t rr_depth, lc_ref_block_fn block, void *block_ctx, lc_rng *rng, float E[3],
                              uint64_t *rays);

/* The first surface along a ray (unit dir) from org, any side: 1 with its distance *t and the
 * triangle's winding normal ng (unit; a ray with dot(dir, ng) > 0 sees its back), 0 when the
 * ray escapes. */
int lc_ref_first_hit(const lc_ref *r, const float org[3], const float dir[3], float *t, float ng[3]);

/* The ray offset (m) the reference lifts every path vertex by (ref.h, "eps"). */
float lc_ref_eps(const lc_ref *r);

/* Total power leaving the static surfaces before any transport (W, RGB): the integral over
 * every triangle's front of pi L_e + albedo (direct + sky) irradiance — the engine's
 * sum of B0 x surfel area. Estimated from `samples` points spread by area; stderr may be NULL. */
void lc_ref_b0_power(lc_ref *r, uint32_t samples, uint64_t seed, double power[3], double stderr_out[3]);

/* CRC-32 identifying the bake's caches (a reference only compares with bakes that share it). */
uint32_t lc_ref_cache_crc(const lc_lcb_view *v);

/* Writes DIR/reference.json, reference_lightmap.exr (+ _stderr.exr, float32), reference_texels.u8,
 * reference_grid.f32 (+ _stderr.f32), reference_grid_mask.u8. `extra_json` (may be NULL) is
 * an object text merged under "run" (settings, scene). Returns 0 or -1 with err set. */
int lc_ref_write(const char *dir, const lc_ref_result *res, const char *extra_json, char *err, size_t errlen);
/* Reads what lc_ref_write wrote. */
int lc_ref_read(const char *dir, lc_ref_result *res, char *err, size_t errlen);

/* --- the camera view (camera.c, `lucent-ref camera`) ------------------------------------------ */

/* A pinhole camera exactly as three.js's PerspectiveCamera + lookAt: fov_deg the vertical field
 * of view, aspect width / height, forward = normalize(target - eye), right = normalize(forward x
 * up), true up = right x forward. */
typedef struct lc_ref_camera {
    float eye[3], target[3], up[3];
    double fov_deg;
    uint32_t width, height;
} lc_ref_camera;

/* Largest image side (a cap on the image buffers). */
#define LC_REF_CAMERA_MAX_SIDE 8192u

typedef struct lc_ref_camera_basis {
    double forward[3], right[3], up[3];
    double tan_y, tan_x; /* tan(fov / 2), times the aspect */
} lc_ref_camera_basis;

/* Checks the camera and computes its basis. Returns 0 or -1 with err naming the CLI flag
 * (--fov outside (0, 180), --width/--height outside 1..LC_REF_CAMERA_MAX_SIDE, --target equal
 * to --eye, --up parallel to the view direction, non-finite --eye/--target/--up). */
int lc_ref_camera_setup(const lc_ref_camera *cam, lc_ref_camera_basis *b, char *err, size_t errlen);

/* The unit ray direction through image point (px, py), in pixels from the top-left corner
 * (pixel (i, j)'s centre is (i + 0.5, j + 0.5)): NDC x = 2 px / W - 1, y = 1 - 2 py / H,
 * dir = normalize(forward + x tan_x right + y tan_y up). */
void lc_ref_camera_ray(const lc_ref_camera_basis *b, uint32_t width, uint32_t height, double px, double py,
                       float dir[3]);

typedef struct lc_ref_camera_settings {
    uint32_t spp;       /* samples per pixel: stratified over the pixel; 1 = its centre */
    uint32_t max_depth; /* reflections per path (lc_ref_radiance) */
    uint32_t rr_depth;
    uint64_t seed;
    int quiet; /* no progress bar */
} lc_ref_camera_settings;

typedef struct lc_ref_image {
    uint32_t width, height;
    float *rgb;             /* W*H*3 linear radiance (nits), row 0 = top */
    float *stderr_y;        /* W*H standard error of each pixel's luminance */
    double mean_rel_stderr; /* stderr(Y) / Y over the pixels above 5% of the mean luminance */
    uint32_t n_bright;
    double seconds;
    uint64_t rays;
} lc_ref_image;

/* Path-traces the camera's view. Every pixel draws from its own random stream (seed, pixel):
 * the same seed gives the same image on any thread count. Returns 0 or -1 with err set; on
 * success *out owns its arrays (lc_ref_image_free). */
int lc_ref_camera_render(lc_ref *r, const lc_ref_camera *cam, const lc_ref_camera_settings *s, lc_ref_image *out,
                         char *err, size_t errlen);
void lc_ref_image_free(lc_ref_image *img);

/* The viewer's tone maps (three.js): NONE = LinearToneMapping, clamp(exposure L, 0, 1);
 * NEUTRAL = NeutralToneMapping (Khronos PBR Neutral) of exposure L. */
typedef enum { LC_REF_TONEMAP_NONE = 0, LC_REF_TONEMAP_NEUTRAL = 1 } lc_ref_tonemap_kind;

/* Linear radiance -> display-linear colour in [0, 1] (before the sRGB transfer). */
void lc_ref_tonemap(lc_ref_tonemap_kind kind, double exposure, const float in[3], double out[3]);
/* The sRGB OETF of v in [0, 1] (clamped), rounded to 8 bits: round(255 sRGB(v)). */
uint8_t lc_ref_srgb8(double v);

/* Writes the image as an 8-bit sRGB PNG after the tone map (the EXR of the linear radiance is
 * lc_image_write_float of img->rgb). Returns 0 or -1 with err set. */
int lc_ref_image_write_png(const char *path, const lc_ref_image *img, lc_ref_tonemap_kind kind, double exposure,
                           char *err, size_t errlen);

/* --- RGB-D capture (capture.c, `lucent-ref capture`) ------------------------------------------ */

/* The baked scene as an RGB-D camera records it: the replay format `lucentctl mr replay` reads.
 *   DIR/capture.json   {"format": "lucent-rgbd/1", "width", "height", "frames", "source": {"bake", "state"}}
 *   DIR/frame_00001.json {"sequence": k, "time_us", "intrinsics": {"fx", "fy", "cx", "cy"},
 *                       "pose": {"translation": [3], "rotation": [x, y, z, w]}, "exposure": E,
 *                       "color": "linear16" | "srgb8"}
 *   DIR/depth_00001.png 16-bit grey, millimetres along the view axis, rounded; 0 = no surface or
 *                       beyond 65.535 m
 *   DIR/color_00001.png RGB: linear16 = 16-bit, radiance (nits) = v / 65535 x E; srgb8 = 8-bit,
 *                       radiance = sRGB EOTF(v / 255) x E. E is the frame's brightest channel
 *                       value (nothing clips; 1 for a black frame).
 * The camera is PROTOCOL.md §8.4's: glTF (+X right, +Y up, looking along -Z), pixel (x, y)'s
 * centre at (u, v) = (x + 0.5, y + 0.5), depth z its distance along the view axis, camera-space
 * point ((u - cx) z / fx, -(v - cy) z / fy, -z), world point R p + t. A look-at camera
 * (lc_ref_camera) has fx = fy = (H / 2) / tan(fov / 2), cx = W / 2, cy = H / 2 and R's columns
 * right, up, -forward: exactly lc_ref_camera_ray's rays. Colour is lc_ref_radiance_ex with
 * sky_first = 0 (emitters seen directly, direct and indirect light; a pixel without a surface is
 * black), averaged over spp stratified positions in the pixel; depth is the pixel centre's ray's
 * first hit (front or back). */
#define LC_REF_CAPTURE_FORMAT "lucent-rgbd/1"
#define LC_REF_CAPTURE_MAX_FRAMES 99999u /* five digits in the file names */
/* Image sides a capture is written with: an MR session's (PROTOCOL.md 8.2, client/README.md). */
#define LC_REF_CAPTURE_MIN_SIDE 8u
#define LC_REF_CAPTURE_MAX_SIDE 1024u

typedef struct lc_ref_rgbd_view {
    uint32_t width, height;
    double fx, fy, cx, cy;
    double rotation[4];    /* camera-to-world unit quaternion x, y, z, w */
    double translation[3]; /* camera position, world metres */
} lc_ref_rgbd_view;

/* Unit quaternion (normalised here) -> row-major 3x3 rotation, and back (m orthonormal). */
void lc_ref_quat_matrix(const double q[4], double m[9]);
void lc_ref_matrix_quat(const double m[9], double q[4]);

/* The look-at camera's view (lc_ref_camera_setup's checks and errors). */
int lc_ref_rgbd_lookat(const lc_ref_camera *cam, lc_ref_rgbd_view *out, char *err, size_t errlen);
/* The ray through image point (u, v): origin = the camera position, unit world direction;
 * *z_per_t (may be NULL) = depth per unit of ray distance (z = t x z_per_t). */
void lc_ref_rgbd_ray(const lc_ref_rgbd_view *view, double u, double v, float org[3], float dir[3], double *z_per_t);
/* The world point at image point (u, v) with depth z (metres). */
void lc_ref_rgbd_unproject(const lc_ref_rgbd_view *view, double u, double v, double z, double out[3]);

typedef struct lc_ref_capture_settings {
    uint32_t spp;       /* colour samples per pixel (stratified; 1 = the centre) */
    uint32_t max_depth; /* reflections per path (lc_ref_radiance) */
    uint32_t rr_depth;
    uint64_t seed;
    int srgb8; /* colour PNG: 0 linear16, 1 srgb8 */
    int quiet; /* no progress on stderr */
} lc_ref_capture_settings;

/* One frame (index `frame`, for its random streams): rgb W*H*3 linear radiance, depth W*H metres
 * along the view axis (0: the centre ray escapes), row 0 = top. *rays (may be NULL) counts the
 * rays. Same seed and frame, same images on any thread count. Returns 0 or -1 with err set. */
int lc_ref_rgbd_render(lc_ref *r, const lc_ref_rgbd_view *view, const lc_ref_capture_settings *s, uint32_t frame,
                       float *rgb, float *depth, uint64_t *rays, char *err, size_t errlen);

/* A frame's pose and time. */
typedef struct lc_ref_capture_pose {
    lc_ref_rgbd_view view;
    uint64_t time_us;
} lc_ref_capture_pose;

/* PATH.json {"frames": [{"eye": [3], "target": [3], "up": [3]?, "time_us": T?}...]} (1 to
 * LC_REF_CAPTURE_MAX_FRAMES frames) with the camera's size and fov from tmpl (up default: tmpl's);
 * time_us defaults to (k - 1) x 100000. *out is malloc'd. Errors name the file and the JSON pointer. */
int lc_ref_capture_path_load(const char *path, const lc_ref_camera *tmpl, lc_ref_capture_pose **out, uint32_t *n,
                             char *err, size_t errlen);
/* n poses of base, each moved by a uniform +-jitter_mm millimetres per axis and turned by a
 * uniform +-jitter_deg degrees about a uniformly random axis (through the camera), seeded;
 * time_us = (k - 1) x 100000. */
void lc_ref_capture_jitter(const lc_ref_rgbd_view *base, uint32_t n, double jitter_mm, double jitter_deg, uint64_t seed,
                           lc_ref_capture_pose *out);

/* Renders and writes every frame to dir (created), and capture.json with bake and state (NULL:
 * JSON null) as its source. Progress per frame on stderr unless s->quiet. */
int lc_ref_capture_run(lc_ref *r, const char *dir, const lc_ref_capture_pose *poses, uint32_t n,
                       const lc_ref_capture_settings *s, const char *bake, const char *state, char *err, size_t errlen);
/* The files of frame k (1-based) from its images; *exposure_out (may be NULL) gets E. */
int lc_ref_capture_write_frame(const char *dir, uint32_t k, const lc_ref_capture_pose *pose, const float *rgb,
                               const float *depth, int srgb8, double *exposure_out, char *err, size_t errlen);

/* Frame k of a capture directory, decoded. */
typedef struct lc_ref_capture_frame {
    lc_ref_rgbd_view view;
    uint32_t sequence;
    uint64_t time_us;
    double exposure;
    int srgb8;
    uint16_t *depth_mm; /* W*H */
    float *rgb;         /* W*H*3 linear radiance, nits (decoded colour x exposure) */
} lc_ref_capture_frame;
/* Reads DIR/capture.json (format, size, frame count) and frame k's three files; errors name the
 * file and the field. */
int lc_ref_capture_read_frame(const char *dir, uint32_t k, lc_ref_capture_frame *out, char *err, size_t errlen);
void lc_ref_capture_frame_free(lc_ref_capture_frame *f);

/* PNG without colour management (libpng): channels 1 (grey) or 3 (RGB), bits 8 or 16, samples
 * W*H*channels (8-bit: 0..255). Read accepts grey and RGB, 8 or 16 bits, sides up to max_side. */
int lc_ref_png_write(const char *path, uint32_t width, uint32_t height, int channels, int bits, const uint16_t *samples,
                     char *err, size_t errlen);
int lc_ref_png_read(const char *path, uint32_t max_side, uint32_t *width, uint32_t *height, int *channels, int *bits,
                    uint16_t **samples, char *err, size_t errlen);
/* The sRGB EOTF (IEC 61966-2-1) of v in [0, 1]. */
double lc_ref_srgb_eotf(double v);

/* --- MR truths (mr_truth.c, `lucent-ref mr-truth`) ------------------------------------------- */

/* At points x (normal n) near virtual objects, the irradiance from the real room two ways,
 * E = integral over the hemisphere of n of L(x, w) cos dw, estimated from x + eps n:
 *   full:    the real scene (the bake's static geometry and the state's objects with the state's
 *            light): L = the radiance leaving the first surface toward x, all bounces, the sky
 *            not seen directly: what a camera pixel shows of that surface, i.e. the lightmap's
 *            E (lc_ref_irradiance_sample: a light sample toward the emissive triangles and a
 *            cosine-sampled path per sample, MIS);
 *   visible: only the patches the camera saw in one frame: a mesh from its depth map (two
 *            triangles per 2x2 block of valid depths, none whose depths differ by more than 5% of
 *            the nearest), one-sided facing the camera, each triangle's radiance the mean linear
 *            colour of its three pixels; its back and everything else are black. Per sample a
 *            light sample (a triangle by power, a uniform point on it) and a cosine ray, MIS.
 * In both the virtual objects (occluders: the bake's assets, placed) block the rays (a hit on
 * them gives 0; they are not real, so they change nothing else). visible isolates LightSkin's own
 * error (the server sees exactly those patches); full - visible is what the capture cannot see.
 * The samples are iid: the standard errors are honest. Note the 5% rule is relative to depth,
 * not to the pixel footprint: at low resolutions it drops surfaces seen at grazing angles
 * (floors, ceilings, side walls), whose neighbouring pixels differ by more than 5% in depth. */
typedef struct lc_ref_mr_point {
    float position[3], normal[3]; /* normal: unit (normalised on load) */
} lc_ref_mr_point;

typedef struct lc_ref_mr_input {
    lc_ref_mr_point *points;
    uint32_t n_points;
    lc_engine_object *occluders; /* asset indices into the bake */
    uint32_t n_occluders;
} lc_ref_mr_input;

#define LC_REF_MR_MAX_POINTS 1000000u
#define LC_REF_MR_MAX_OCCLUDERS 1024u

/* POINTS.json {"points": [{"position": [3], "normal": [3]}...], "occluders": {"objects": [{"asset":
 * NAME, "translation"?, "rotation"?, "scale"?, "sparse_points"?}...]}?}. An occluder with
 * "sparse_points": true adds its asset's LightSkin sparse points (lcb ASPT), placed as lucentd
 * places them for an MR session, after the listed points ("points" is then optional): the
 * truth at exactly the points a session gathers at. Errors name the file and JSON pointer. */
int lc_ref_mr_points_load(const char *path, const lc_lcb_view *v, lc_ref_mr_input *out, char *err, size_t errlen);
void lc_ref_mr_input_free(lc_ref_mr_input *in);

typedef struct lc_ref_mr_settings {
    uint32_t spp;       /* samples per point (each: a light sample and a cosine sample per integral) */
    uint32_t max_depth; /* full's bounce limit (lc_ref_settings.max_bounces) */
    uint32_t rr_depth;
    uint64_t seed;
    int quiet;
} lc_ref_mr_settings;

typedef struct lc_ref_mr_value {
    double full[3], full_stderr[3], visible[3], visible_stderr[3];
} lc_ref_mr_value;

/* frame NULL: visible is 0 (only full). Per point its own random stream: same result on any
 * thread count. *visible_triangles (may be NULL) gets the mesh's size. Returns 0 or -1. */
int lc_ref_mr_truth(lc_ref *r, const lc_lcb_view *v, const lc_ref_capture_frame *frame, const lc_ref_mr_input *in,
                    const lc_ref_mr_settings *s, lc_ref_mr_value *out, uint32_t *visible_triangles, char *err,
                    size_t errlen);
/* {"points": [{"position", "normal", "full", "full_stderr", "visible", "visible_stderr"}...], "spp": N}
 * (malloc'd). */
char *lc_ref_mr_json(const lc_ref_mr_point *points, const lc_ref_mr_value *values, uint32_t n, uint32_t spp);

/* --- comparison ------------------------------------------------------------------------------ */

/* Relative error statistics over the compared set. */
typedef struct lc_ref_errstats {
    uint32_t n;                 /* texels / cells compared */
    uint32_t n_total;           /* candidates before the brightness threshold */
    double threshold;           /* absolute luminance threshold used (threshold_frac x the brightest) */
    double mean, p50, p95, max; /* of |a - r| / r (luminance) */
    double bias;                /* sum(a - r) / sum(r): the luminance-weighted signed error */
    double mean_signed;         /* mean of (a - r) / r */
    double ref_noise;           /* mean relative standard error of the reference over the same set (0 if unknown) */
    /* Lightmap rows only, over ALL candidates (dark ones too, which the relative error cannot judge: a
     * texel buried in a contact is black in the reference, and the engine's light there is a leak). */
    uint32_t n_dark;        /* candidates with the reference at or below the threshold */
    uint32_t n_dark_lit;    /* of those, texels where the approximation is above the threshold */
    double ref_mean;        /* mean reference luminance over the WHOLE lightmap's compared texels (the scale) */
    double abs_err_vs_mean; /* mean over the candidates of |Y_a - Y_r| / ref_mean */
} lc_ref_errstats;

/* Luminance (Rec. 709) of linear RGB. */
static inline double lc_ref_luminance(const float *c) { return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]; }

/* Per texel, on luminance: err = |Y_a - Y_r| / Y_r over texels whose mask is 1 (owners; dilated
 * copies would count a cache twice) and Y_r > threshold_frac x max Y_r. p95 and p50 are
 * nearest-rank percentiles. ref_stderr may be NULL. err_image (W*H, may be NULL) receives the
 * signed relative error (a - r) / r of compared texels and NAN elsewhere. Returns 0, or -1
 * when nothing is compared. */
int lc_ref_compare_lightmap(const float *approx, const float *ref, const float *ref_stderr, const uint8_t *mask,
                            uint32_t width, uint32_t height, double threshold_frac, lc_ref_errstats *out,
                            float *err_image);

/* The same over a subset: texels with select[i] == want (select NULL: all, which is
 * lc_ref_compare_lightmap). The threshold and ref_mean stay those of the WHOLE lightmap, so the
 * rows of one comparison (all, moved, unmoved) share them. Returns -1 also when the subset has
 * candidates but none above the threshold (n_total, n_dark, abs_err_vs_mean are still set). */
int lc_ref_compare_lightmap_subset(const float *approx, const float *ref, const float *ref_stderr, const uint8_t *mask,
                                   const uint8_t *select, uint8_t want, uint32_t width, uint32_t height,
                                   double threshold_frac, lc_ref_errstats *out, float *err_image);

/* Neighbour-to-neighbour variation ("blotches"). Pairs of 4-adjacent texels that both own their
 * cache (mask 1), both have a reference luminance above `threshold` (absolute: the compared set)
 * and lie on the same surface: surface points (surface, LC_REF_SURFACE_STRIDE per texel) within
 * 2x the larger of the two texel spacings and normals within 25 degrees, so pairs across chart
 * seams and creases do not count (surface NULL: every pair counts, for synthetic images). Per
 * image: the mean over the pairs of |Y_a - Y_b| / ((Y_a + Y_b) / 2) (a pair of zeros counts 0).
 * The reference's own noise raises its value: ref_noise is its mean relative standard error over
 * the pairs' texels (ref_stderr NULL: 0). */
typedef struct lc_ref_blotch {
    uint32_t pairs;
    double approx, reference; /* the mean relative neighbour difference of each image */
    double ratio;             /* approx / reference (0 when the reference's is 0) */
    double ref_noise;
} lc_ref_blotch;
int lc_ref_blotch_metric(const float *approx, const float *ref, const float *ref_stderr, const uint8_t *mask,
                         const float *surface, uint32_t width, uint32_t height, double threshold, lc_ref_blotch *out);
char *lc_ref_blotch_json(const lc_ref_blotch *b);

/* Per grid cell: both SH evaluated as irradiance E(d) = sum c_i y_i(d) at 14 directions (the 6
 * axes and the 8 cube diagonals); err = sum_d |Y_a(d) - Y_r(d)| / sum_d max(Y_r(d), 0). Cells
 * with mask 1 whose mean reference irradiance exceeds threshold_frac x the brightest cell's.
 * ref_stderr may be NULL (else ref_noise = mean stderr(c_0) / c_0). cell_err may be NULL. */
int lc_ref_compare_grid(const float *approx_sh, const float *ref_sh, const float *ref_stderr, const uint8_t *mask,
                        uint32_t cells, double threshold_frac, lc_ref_errstats *out, float *cell_err);

/* Heat map of |relative error| (0 black-blue ... max_err red, NAN texels dark grey), 8-bit
 * PNG, each texel scaled up `zoom` times. Returns 0 or -1 with err set. */
int lc_ref_write_heatmap(const char *path, const float *err_image, uint32_t width, uint32_t height, double max_err,
                         uint32_t zoom, char *err, size_t errlen);

/* The lightmap's own layout (W x H, row 0 = top = v 0, so it maps onto uv1 like the lightmap;
 * the viewer loads it as a heat map), 8-bit RGBA: the SIGNED error err_image (a - r) / r on a
 * diverging scale, t = clamp(e / max_err, -1, 1): t < 0 is (1 + t, 1 + t, 1) (blue at -max_err:
 * the engine too dark), t = 0 white (right), t > 0 is (1, 1 - t, 1 - t) (red at +max_err: too
 * bright), byte = round(255 x value), alpha 255. Covered texels (mask 1 or 2) without an error
 * (not compared: dark, or dilated copies) take the colour of the nearest compared texel reached
 * through covered texels (8-neighbour breadth-first, ties to the first in row order), so bilinear
 * filtering across chart edges stays sane; covered texels that reach none are grey (128), alpha
 * 255; empty texels (mask 0) are transparent black. An infinite error saturates: `compare` and
 * `fidelity` pass +INFINITY for texels dark in the reference (not compared) that the engine
 * lights above the threshold (a buried texel's leak), so they show red, not a neighbour's colour.
 * lc_ref_heatmap_uv fills rgba (W*H*4); returns 0 or -1 (out of memory). */
int lc_ref_heatmap_uv(const float *err_image, const uint8_t *mask, uint32_t width, uint32_t height, double max_err,
                      uint8_t *rgba);
int lc_ref_write_heatmap_uv(const char *path, const float *err_image, const uint8_t *mask, uint32_t width,
                            uint32_t height, double max_err, char *err, size_t errlen);

/* JSON object text for stats (malloc'd). */
char *lc_ref_errstats_json(const lc_ref_errstats *s);

/* --- the change an object makes (delta.c, `lucent-ref delta`) ------------------------------------ */

/* dY = Y(with) - Y(without) per texel owning its cache in both references, over texels whose
 * reference change exceeds k_sigma x its standard error (both renders' errors combined) and
 * floor_frac x the mean reference luminance. */
typedef struct lc_ref_delta_stats {
    uint32_t n, n_neg, n_pos;         /* compared; of them darker / brighter in the reference */
    uint32_t n_buried;                /* of them black (<= 2% of before) in the reference with the object: under it */
    double error_unburied;            /* the error over the others, the texels a user can see */
    double error;                     /* sum |dY_a - dY_r| / sum |dY_r| */
    double bias;                      /* sum (dY_a - dY_r) / sum |dY_r| */
    double sign_agree;                /* share of compared texels whose change is non-zero with the reference's sign */
    double neg_ratio;                 /* sum dY_a / sum dY_r over the darker texels (1 = the right shadow) */
    double pos_ratio;                 /* ... over the brighter texels (the bounced light) */
    double rgb_approx[3], rgb_ref[3]; /* summed dRGB over the compared set: the colour of the change */
    double ref_noise;                 /* sum sigma / sum |dY_r| */
    double mean_abs_ref;              /* mean |dY_r| */
    double max_rel_change;            /* largest |dY_r| / Y_r(without) */
    double floor;                     /* the absolute floor used */
} lc_ref_delta_stats;

/* a0/a1: the approximation's lightmaps without/with (W*H*3, the references' size); r0/r1 the
 * references. delta_img (W*H*3 or NULL): dY_r, dY_a, dY_a - dY_r per compared texel, NAN
 * elsewhere. -1 when nothing is compared. */
int lc_ref_delta_lightmap(const float *a0, const float *a1, const lc_ref_result *r0, const lc_ref_result *r1,
                          double k_sigma, double floor_frac, lc_ref_delta_stats *out, float *delta_img);
char *lc_ref_delta_json(const lc_ref_delta_stats *s);

/* --- the engine side of a fidelity run --------------------------------------------------------- */

typedef struct lc_ref_engine_run {
    float *lightmap;    /* W*H*3 */
    float *grid_sh;     /* cells*27 */
    uint32_t relights;  /* progressive relights until converged */
    double last_change; /* max relative texel change of the last relight */
    double ms_first, ms_total;
    double b0_power[3];      /* sum of B0 x area over the surfels (one extra relight, bounces 0) */
    float *surfel_radiosity; /* n_surfels*3: the converged B, for the gather bound */
    char backend[16];
    uint32_t clutter_objects; /* objects in mode clutter / auto whose DRT operators were built and applied */
    double clutter_build_ms;  /* their build time, summed */
    size_t clutter_bytes;     /* their memory, summed */
} lc_ref_engine_run;

/* Relights `state` with the engine (progressive on, the state's bounces per relight) until the
 * largest relative change of a bright texel's luminance between two relights is below tol
 * (or max_relights). bounce_limit >= 0 instead runs ONE relight with progressive off and
 * settings.bounces = bounce_limit: exactly that many reflections, for comparing with a
 * reference rendered with max_bounces = bounce_limit. Objects in mode clutter or auto
 * (!clutter_off) get their DRT operators (engine/drt.h, default settings) built and attached
 * first, as lucentd does once they rest (CPU backend only). Returns 0 or -1 with err set. */
int lc_ref_engine_converge(const lc_lcb *bake, const lc_engine_state *state, lc_backend_kind backend, int threads,
                           double tol, uint32_t max_relights, int bounce_limit, lc_ref_engine_run *out, char *err,
                           size_t errlen);
void lc_ref_engine_run_free(lc_ref_engine_run *run);

/* The lossless-transport bound of a solution (lc_links_gather_bound over the bake's static
 * mesh): fills lightmap (W*H*3; texels read their cache, as the engine's do) with each texel
 * cache's irradiance gathered from the surfels its probe_rays hemisphere rays hit, with surfel
 * radiosity B (n_surfels*3). Comparing it with the reference says how much of the engine's
 * error is the surfels (what no link budget can remove) and how much is the links.
 * Returns 0 or -1 with err set. */
int lc_ref_gather_bound(const lc_lcb *bake, const float *radiosity, uint32_t probe_rays, uint64_t seed, int threads,
                        float *lightmap, char *err, size_t errlen);

#endif
