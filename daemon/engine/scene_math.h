/* scene_math: what the scene state means, typed once for everything that evaluates it — the
 * relight engine's direct light (engine.c) and the reference path tracer (ref/ref.c) — so a
 * fix in one cannot silently change what the fidelity numbers measure. Object transforms,
 * the glTF KHR_lights_punctual range window and spot cone, area-light frames and points.
 *
 * Conventions as glTF: metres, right-handed, +Y up; quaternions (x, y, z, w); a light's
 * `direction` is the way its light travels; cone angles are half angles in radians. Units of
 * the intensities are in engine.h (candela, lux, nits). Only the geometry of a light lives
 * here: which points are sampled, how many and with which estimator stays with each caller.
 * Static inline, float throughout, so each caller compiles the same operations it had. */
#ifndef LC_SCENE_MATH_H
#define LC_SCENE_MATH_H
#include <math.h>

#include "engine/engine.h"

static inline float lc_sm_dot(const float a[3], const float b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static inline float lc_sm_len(const float a[3]) { return sqrtf(lc_sm_dot(a, a)); }
static inline void lc_sm_cross(const float a[3], const float b[3], float o[3]) {
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}

/* --- objects ------------------------------------------------------------------------------- */

/* The object's placement T * R * S as a column-major 3x4 (Embree's FLOAT3X4_COLUMN_MAJOR: the
 * three basis columns, then the translation), glTF node order: scale, rotate, translate. The
 * quaternion is normalised here because the state may hold any non-zero one. */
static inline void lc_sm_object_matrix(const lc_engine_object *o, float m[12]) {
    float x = o->rotation[0], y = o->rotation[1], z = o->rotation[2], w = o->rotation[3];
    float len = sqrtf(x * x + y * y + z * z + w * w);
    x /= len, y /= len, z /= len, w /= len;
    float r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                     {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                     {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
    for (int col = 0; col < 3; col++)
        for (int row = 0; row < 3; row++) m[col * 3 + row] = r[row][col] * o->scale[col];
    m[9] = o->translation[0];
    m[10] = o->translation[1];
    m[11] = o->translation[2];
}

/* A point through that matrix: out = M p + t (out must not alias p). */
static inline void lc_sm_transform_point(const float m[12], const float p[3], float out[3]) {
    for (int k = 0; k < 3; k++) out[k] = m[k] * p[0] + m[3 + k] * p[1] + m[6 + k] * p[2] + m[9 + k];
}

/* --- punctual lights (KHR_lights_punctual) ------------------------------------------------- */

/* The range window for squared distance d2 (m^2): clamp(1 - (d / range)^4, 0, 1)^2, the
 * spec's recommended smooth cut to zero at `range`; 1 when range <= 0 (infinite). It
 * multiplies the inverse-square law (and, as lucent's extension, an area light's samples). */
static inline float lc_sm_range_window(float d2, float range) {
    if (range <= 0) return 1.0f;
    float q = d2 / (range * range);
    float w = 1.0f - q * q;
    w = w < 0 ? 0 : w > 1 ? 1 : w;
    return w * w;
}

/* The spot cone for the unit vector `to_light` from the shaded point toward the light: the
 * spec's linear step in cos(angle) from the outer cone (0) to the inner cone (1), squared.
 * The 0.001 floor on cos(inner) - cos(outer) is the spec's: inner == outer stays finite. */
static inline float lc_sm_spot_cone(const lc_engine_light *l, const float to_light[3]) {
    float cd = -lc_sm_dot(to_light, l->direction) / lc_sm_len(l->direction);
    float co = cosf(l->outer_cone), ci = cosf(l->inner_cone);
    float sc = 1.0f / fmaxf(0.001f, ci - co);
    float t = (cd - co) * sc;
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return t * t;
}

/* --- area lights ---------------------------------------------------------------------------- */

/* An area light's frame: n the unit normal it emits along (one-sided), tx the quad's width
 * axis (`tangent` made perpendicular to n; a disc takes a fixed perpendicular), ty = n x tx
 * its height axis, and the emitting area (m^2: width x height, or pi r^2). A tangent
 * parallel to n leaves tx = ty = 0 (the emitter collapses to its centre) rather than NaN. */
typedef struct lc_sm_area_frame {
    float n[3], tx[3], ty[3];
    float area;
} lc_sm_area_frame;

static inline lc_sm_area_frame lc_sm_area_frame_of(const lc_engine_light *l) {
    lc_sm_area_frame f;
    float dl = lc_sm_len(l->direction);
    for (int k = 0; k < 3; k++) f.n[k] = l->direction[k] / dl;
    float t0[3];
    if (l->shape == LC_AREA_QUAD) {
        float tl = lc_sm_len(l->tangent);
        for (int k = 0; k < 3; k++) t0[k] = l->tangent[k] / tl;
        f.area = l->size[0] * l->size[1];
    } else { /* x, or y when n is near x */
        t0[0] = fabsf(f.n[0]) < 0.9f ? 1.0f : 0.0f;
        t0[1] = fabsf(f.n[0]) < 0.9f ? 0.0f : 1.0f;
        t0[2] = 0;
        f.area = (float)M_PI * l->size[0] * l->size[0];
    }
    float dp = lc_sm_dot(t0, f.n);
    for (int k = 0; k < 3; k++) f.tx[k] = t0[k] - dp * f.n[k];
    float txl = lc_sm_len(f.tx);
    if (txl > 0)
        for (int k = 0; k < 3; k++) f.tx[k] /= txl;
    lc_sm_cross(f.n, f.tx, f.ty);
    return f;
}

/* The emitter's point for (u, w) in [0, 1)^2, uniform in area: the quad centred on
 * `position` (u along tx, w along ty); the disc by radius size[0] sqrt(u) and angle 2 pi w. */
static inline void lc_sm_area_point(const lc_engine_light *l, const lc_sm_area_frame *f, float u, float w, float p[3]) {
    float a, b;
    if (l->shape == LC_AREA_QUAD) {
        a = (u - 0.5f) * l->size[0];
        b = (w - 0.5f) * l->size[1];
    } else {
        float r = l->size[0] * sqrtf(u), phi = 2.0f * (float)M_PI * w;
        a = r * cosf(phi);
        b = r * sinf(phi);
    }
    for (int k = 0; k < 3; k++) p[k] = l->position[k] + a * f->tx[k] + b * f->ty[k];
}

#endif
