/* vec: small inline 3-vector helpers on float[3]-compatible structs. */
#ifndef LC_VEC_H
#define LC_VEC_H
#include <math.h>

typedef struct {
    float x, y, z;
} lc_vec3;

static inline lc_vec3 lc_v3(float x, float y, float z) { return (lc_vec3){x, y, z}; }
static inline lc_vec3 lc_v3_load(const float *p) { return (lc_vec3){p[0], p[1], p[2]}; }
static inline void lc_v3_store(float *p, lc_vec3 a) {
    p[0] = a.x;
    p[1] = a.y;
    p[2] = a.z;
}
static inline lc_vec3 lc_v3_add(lc_vec3 a, lc_vec3 b) { return (lc_vec3){a.x + b.x, a.y + b.y, a.z + b.z}; }
static inline lc_vec3 lc_v3_sub(lc_vec3 a, lc_vec3 b) { return (lc_vec3){a.x - b.x, a.y - b.y, a.z - b.z}; }
static inline lc_vec3 lc_v3_scale(lc_vec3 a, float s) { return (lc_vec3){a.x * s, a.y * s, a.z * s}; }
static inline lc_vec3 lc_v3_mul(lc_vec3 a, lc_vec3 b) { return (lc_vec3){a.x * b.x, a.y * b.y, a.z * b.z}; }
static inline float lc_v3_dot(lc_vec3 a, lc_vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static inline lc_vec3 lc_v3_cross(lc_vec3 a, lc_vec3 b) {
    return (lc_vec3){a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
static inline float lc_v3_len(lc_vec3 a) { return sqrtf(lc_v3_dot(a, a)); }
static inline lc_vec3 lc_v3_norm(lc_vec3 a) {
    float l = lc_v3_len(a);
    return l > 0 ? lc_v3_scale(a, 1.0f / l) : (lc_vec3){0, 0, 0};
}
static inline lc_vec3 lc_v3_min(lc_vec3 a, lc_vec3 b) {
    return (lc_vec3){fminf(a.x, b.x), fminf(a.y, b.y), fminf(a.z, b.z)};
}
static inline lc_vec3 lc_v3_max(lc_vec3 a, lc_vec3 b) {
    return (lc_vec3){fmaxf(a.x, b.x), fmaxf(a.y, b.y), fmaxf(a.z, b.z)};
}
static inline int lc_v3_finite(lc_vec3 a) { return isfinite(a.x) && isfinite(a.y) && isfinite(a.z); }

/* Orthonormal basis (t, b) around unit n (Duff et al. 2017, branchless). */
static inline void lc_v3_basis(lc_vec3 n, lc_vec3 *t, lc_vec3 *b) {
    float s = copysignf(1.0f, n.z);
    float a = -1.0f / (s + n.z);
    float c = n.x * n.y * a;
    *t = (lc_vec3){1.0f + s * n.x * n.x * a, s * c, -s * n.x};
    *b = (lc_vec3){c, s + n.y * n.y * a, -n.y};
}

#endif
