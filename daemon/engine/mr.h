/* mr: the LightSkin computation (Lensing & Broll 2013, ../shared/papers/lightskin-mixed-reality-gi.txt)
 * for MR sessions, PROTOCOL.md §8.6, on the CPU. Pure computation: arrays in, arrays out.
 *
 * Per frame (lc_mr_set_frame):
 *  1. Depth filter (optional): the paper's bilateral filter, weight
 *     exp(-|dp|^2 / 2 sigma_px^2) * exp(-(z_q - z_p)^2 / 2 (sigma_depth z_p)^2) over a
 *     (2 ceil(2 sigma_px) + 1)^2 window (radius at most 8). Pixels with no measurement
 *     (depth 0, negative or non-finite) or with confidence < min_confidence neither contribute
 *     nor get filled: a low-confidence pixel counts as no measurement everywhere, not only as
 *     "not a light".
 *  2. Lights: each valid pixel (x, y) with depth z unprojects as PROTOCOL §8.4 (glTF camera,
 *     -Z forward, row 0 top, centre (x + 0.5, y + 0.5)) to P = ((u - cx) z / fx, -(v - cy) z / fy, -z).
 *     Its normal is dP/dx x dP/dy from the neighbours (central differences where both are
 *     continuous, one-sided where one is; a neighbour is continuous when valid and its depth
 *     within depth_edge * z), turned to face the camera. Rejected: no continuous neighbour
 *     along x or along y (depth discontinuities, isolated pixels), |cos(ray, n)| < grazing_cos,
 *     non-finite radiance. Area: the pixel's exact footprint on the plane through P with normal
 *     n: solid angle cos^3(alpha) / (fx fy) (alpha the ray's off-axis angle) times rho^2 / |cos(ray, n)|
 *     (rho = z / cos alpha the ray length), so
 *         a = z^2 cos(alpha) / (fx fy |cos(ray, n)|) = z^3 / (fx fy |n . P|)
 *     (a fronto-parallel plane gives exactly (z / fx)(z / fy)). Radiosity B = pi L (L the linear
 *     radiance in nits, RGB); disc radius r^2 = a / pi.
 *     Budget: when the valid pixels exceed max_lights the image is cut into b x b blocks, b the
 *     smallest with ceil(w/b) ceil(h/b) <= max_lights; a block's light has the area-weighted
 *     mean position, normal (renormalised) and radiosity of its lights and the sum of their areas
 *     (area weights keep the block's flux B a).
 * Per point set (lc_mr_compute), at each sparse point x (world position, unit normal n):
 *  3. Gather (eqs. 3, 4, 5, 7): w_j = r_j^2 cos t_j / (r_j^2 + d^2) for lights facing x (cos t_j > 0)
 *     and in front of it (cos t_i > 0), else 0;
 *       E_d = sum B_j w_j cos t_i,  l_d = sum l_j (eps + w_j cos t_i) / sum (eps + w_j cos t_i),
 *       E_s = sum B_j w_j c_k cos^k g,  l_s = sum l_j (eps + w_j cos^k g) / sum (eps + w_j cos^k g),
 *     c_k = (k + 1) / 2 pi, g the angle between the mirror of (l_j - x) about n and (camera - x),
 *     eps = LC_MR_EPSILON for every light (so l_d, l_s are defined where no light reaches).
 *     Also the weighted second moments of l_d and l_s per axis (their sigma boxes). Lights are
 *     structure-of-arrays, points in parallel (one lc_parallel_for per stage), lights in tiles of
 *     LC_MR_TILE (the paper's K_cache = 128) shared by LC_MR_POINT_BLOCK points.
 *  4. Occlusion (§3.3, optional): S_o = a sphere at l_d with radius 2 max(sigma_x, sigma_y, sigma_z):
 *     the box spans +-sigma per axis and the paper takes "max(box.width, box.height, box.depth)",
 *     the literal reading (a box side, 2 sigma, not sigma). Occluders: the other sparse points as
 *     two-sided discs (their normal and radius; with self_occlusion 0 only other objects' points),
 *     those in front of x's tangent plane. Each projects (Nusselt) to area pi F (eq. 3, with
 *     |cos| at the disc), S_o to pi R^2 / (R^2 + D^2) cos t_i (eq. 3 with cos t_j = 1, D = |l_d - x|),
 *     centred by eq. 14 in the (t, b) frame of n; both become squares of side sqrt(area), and
 *       o = clamp(sum_k s_k overlap(square_k, square_S) / area_S, 0, 1),
 *     s_k = 1 for an occluder nearer than D - R, falling linearly to 0 at distance D, 0 beyond
 *     (the paper's "scale the amount linearly to zero if the occluder lies in S_o"). The sum over
 *     occluders is the paper's "double occlusion" (§6): discs in line darken more than the
 *     nearest one would. E_d *= (1 - o_d); the same with l_s and its box for E_s.
 *  5. Smoothing (optional, s = smoothing): E_d, l_d, E_s, l_s and the SH become
 *     s * previous + (1 - s) * new; reset (new values as they are) when the camera moved more than
 *     0.5 m or turned more than 30 degrees since the previous compute, or the point set changed size.
 *  6. Renormalisation (eq. 11): I_d = E_d |x - l_d|^2 / cos t_d (cos t_d = n . dir(l_d - x)), so
 *     a point light I_d at l_d gives E_d at x again. When cos t_d <= 1e-3 (l_d in or behind the
 *     tangent plane), l_d moves to x + n |x - l_d| (the same distance, along the normal; 1 cm when
 *     the distance is below 1e-6 m) and I_d = E_d |x - l_d|^2. Glossy: I_s = E_s |x - l_s|^2 / cos^k g_s;
 *     when cos^k g_s < 1e-6 (or cos g_s <= 0) l_s moves to x + |x - l_s| mirror(dir(camera - x)), so
 *     cos g_s = 1. The client's Phong term (§8.7) at x then reproduces E_d and E_s exactly. With
 *     E = 0 the record has I = 0 and l where it was. Without glossy: E_s = I_s = 0, l_s = l_d.
 *  7. Per-object irradiance SH (L2, 27 floats, common/sh.h and PROTOCOL §2.3): every light facing
 *     the object's centre c adds radiance B_j / pi over the solid angle min(a_j cos t_j / d^2, 2 pi)
 *     in direction (l_j - c) / d, projected to radiance SH and convolved with the clamped cosine
 *     (lc_sh_cosine_factor: pi, 2 pi / 3, pi / 4) to irradiance SH. No occlusion.
 *
 * Threads: an lc_mr is used by one thread at a time; the stages run on lc_parallel_threads(threads)
 * workers. Ownership: set_frame / set_lights copy what they need; compute writes only its outputs. */
#ifndef LC_MR_H
#define LC_MR_H
#include <stddef.h>
#include <stdint.h>

#define LC_MR_MAX_DIM 4096          /* width and height each */
#define LC_MR_MAX_PIXELS (1u << 20) /* width * height (PROTOCOL §8.2) */
#define LC_MR_MAX_LIGHTS (1u << 20) /* max_lights and lc_mr_set_lights' count */
#define LC_MR_MAX_POINTS (1u << 16) /* sparse points per compute */
#define LC_MR_MAX_OBJECTS 1024      /* objects per compute */
#define LC_MR_EPSILON 1e-10f        /* eq. 7's eps_l, per light */
#define LC_MR_TILE 128              /* lights per tile (K_cache) */
#define LC_MR_POINT_BLOCK 8         /* points sharing a tile */
#define LC_MR_DEFAULT_MAX_LIGHTS 12288

typedef struct lc_mr lc_mr;

/* The depth image's camera (PROTOCOL §8.4): intrinsics in pixels, camera-to-world pose
 * (translation in metres, unit quaternion x, y, z, w; normalised here, norm in [0.5, 2]). */
typedef struct lc_mr_camera {
    uint32_t width, height;
    float fx, fy, cx, cy;
    float translation[3], rotation[4];
} lc_mr_camera;

typedef struct lc_mr_params {
    uint32_t max_lights;  /* 1..LC_MR_MAX_LIGHTS (default LC_MR_DEFAULT_MAX_LIGHTS) */
    float sigma_px;       /* bilateral spatial sigma, pixels, (0, 4] (default 1.5) */
    float sigma_depth;    /* bilateral range sigma relative to depth, (0, 1] (default 0.03) */
    float min_confidence; /* [0, 1] (default 0.5) */
    float grazing_cos;    /* [0, 1): pixels seen with |cos(ray, n)| below are rejected (default cos 85 deg) */
    float depth_edge; /* (0, 10]: a neighbour whose depth differs more than this * z is across an edge (default 0.1) */
    float spec_exponent; /* Phong k, [1, 10000] (default 16) */
    float smoothing;     /* [0, 0.99] (default 0) */
    int glossy;          /* compute E_s, l_s for the camera's position (default 1) */
    int occlusion;       /* the sparse points' disc occlusion (default 1) */
    int self_occlusion;  /* an object's own points occlude it (default 1, the paper) */
    int filter;          /* bilateral depth filter (default 1) */
} lc_mr_params;

typedef struct lc_mr_point {
    float position[3], normal[3], radius; /* world space; normal unit (normalised here); occluder disc radius */
} lc_mr_point;

typedef struct lc_mr_vpl {
    float i_d[3], l_d[3], i_s[3], l_s[3]; /* the §8.7 record */
} lc_mr_vpl;

/* Per point, for tests, logs and the viewer (optional output of lc_mr_compute). */
typedef struct lc_mr_point_out {
    float e_d[3], e_s[3];     /* final irradiance at x: after occlusion and smoothing */
    float occ_d, occ_s;       /* occlusion amounts o in [0, 1] */
    float radius_d, radius_s; /* S_o's radius for l_d, l_s */
} lc_mr_point_out;

/* A disc light, for lc_mr_set_lights (world space). */
typedef struct lc_mr_light {
    float position[3], normal[3], area, radiosity[3]; /* normal unit (normalised here); B in W/m^2 */
} lc_mr_light;

/* Read-only view of the frame's lights (structure of arrays, count entries each). */
typedef struct lc_mr_lights_view {
    uint32_t count;
    const float *px, *py, *pz, *nx, *ny, *nz, *r2, *br, *bg, *bb; /* r2 = area / pi */
} lc_mr_lights_view;

typedef struct lc_mr_timings {
    double filter_ms, lights_ms, gather_ms, occlusion_ms, normalise_ms, sh_ms; /* the latest frame / compute */
    uint32_t valid_pixels, lights, block;                                      /* block: the merge size b */
} lc_mr_timings;

lc_mr_params lc_mr_params_default(void);
/* threads <= 0: all online cores. NULL on out of memory. */
lc_mr *lc_mr_create(int threads);
void lc_mr_release(lc_mr *m);

/* A frame: depth in metres (w*h), radiance linear RGB nits (w*h*3), confidence in [0, 1] (w*h,
 * NULL = all 1); row-major, row 0 at the top. Builds the lights. 0 ok, -1 with err naming the
 * field (camera/fx, params/max_lights, ...) or out of memory; the previous lights are then gone. */
int lc_mr_set_frame(lc_mr *m, const lc_mr_camera *cam, const float *depth_m, const float *radiance_rgb,
                    const float *confidence, const lc_mr_params *p, char *err, size_t errlen);
/* Lights given directly (tests, or VALs from elsewhere); cam gives the observer (translation)
 * and the pose for the smoothing's reset (width, height and intrinsics are not used). */
int lc_mr_set_lights(lc_mr *m, const lc_mr_camera *cam, const lc_mr_light *lights, uint32_t n, const lc_mr_params *p,
                     char *err, size_t errlen);
uint32_t lc_mr_light_count(const lc_mr *m);
lc_mr_lights_view lc_mr_lights(const lc_mr *m);

/* Steps 3-7 at n sparse points (object_of_point[i] < n_objects; centres[n_objects]).
 * vpl_out[n] required; point_out[n] and sh_out[n_objects] optional (NULL). 0 ok, -1 with err
 * naming the field (points[3]/normal, object_of_point[7], ...) or out of memory. */
int lc_mr_compute(lc_mr *m, const lc_mr_point *pts, uint32_t n, const uint32_t *object_of_point, uint32_t n_objects,
                  const float (*centres)[3], lc_mr_vpl *vpl_out, lc_mr_point_out *point_out, float (*sh_out)[27],
                  char *err, size_t errlen);
/* The GL backend for steps 3 and 4 (gpu/mr_gl.h; NULL = the CPU, the default; not owned, and it
 * must outlive its use here): lc_mr_compute then runs the gather (uploading the lights once after
 * each set_frame / set_lights) and the occlusion on it, and everything else on the CPU as before. Called on the
 * thread that computes. A GL failure makes lc_mr_compute return -1 with err ("mr_gl/...");
 * the caller may set NULL and compute again on the CPU. */
typedef struct lc_mr_gl lc_mr_gl;
void lc_mr_set_gl(lc_mr *m, lc_mr_gl *g);
/* Forgets the smoothing history (the next compute starts afresh). */
void lc_mr_reset_history(lc_mr *m);
void lc_mr_stats(const lc_mr *m, lc_mr_timings *out);

/* Eq. 3: the form factor from the receiver (x, unit normal n) to a disc (centre l, unit normal
 * nl, radius^2 r2), w cos t_i = r2 cos t_j / (r2 + d^2) cos t_i; 0 unless both cosines > 0. */
float lc_mr_disc_form_factor(const float x[3], const float n[3], const float l[3], const float nl[3], float r2);

#endif
