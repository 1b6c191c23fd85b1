#version 430 core
// feedback: E_ind[s] = irradiance of surfel s's cache for the surfel normal (transport.h;
// mirrors tcpu_feedback_range + tcpu_irradiance). One invocation per surfel.
layout(local_size_x = 64) in;

struct Surfel { float nx, ny, nz, area, ax, ay, az; uint cache; };
struct Cache { float nx, ny, nz; uint flags; uint link_count; uint pad0, pad1, pad2; };
layout(std430, binding = 0) readonly buffer Surfels { Surfel surfels[]; };
layout(std430, binding = 1) readonly buffer Caches { Cache caches[]; };
layout(std430, binding = 2) readonly buffer CacheSH9 { float sh9[]; }; // [cache][9][3]
layout(std430, binding = 3) writeonly buffer EInd { float e_ind[]; };
layout(location = 0) uniform uint u_count;
layout(location = 2) uniform int u_bands;

// tcpu_irradiance: texel caches E = (4pi/3) sum_m L_1m y_1m(n) (2 pi L_00 y_00 with one band);
// grid caches E = sum_{l<=2} A_l sum_m L_lm y_lm(n).
vec3 irradiance(uint c, int bands, bool texel, float x, float y, float z) {
    float yb[9];
    yb[0] = 0.282094791774;
    yb[1] = 0.488602511903 * y;
    yb[2] = 0.488602511903 * z;
    yb[3] = 0.488602511903 * x;
    yb[4] = 1.092548430592 * x * y;
    yb[5] = 1.092548430592 * y * z;
    yb[6] = 0.315391565253 * (3.0 * z * z - 1.0);
    yb[7] = 1.092548430592 * x * z;
    yb[8] = 0.546274215296 * (x * x - y * y);
    uint b = 27u * c;
    precise vec3 e;
    if (texel) {
        if (bands < 2) {
            for (int k = 0; k < 3; k++) e[k] = max(0.0, 6.28318530717959 * sh9[b + uint(k)] * yb[0]);
            return e;
        }
        const float w = 4.18879020478639;
        for (int k = 0; k < 3; k++)
            e[k] = max(0.0, w * (sh9[b + 3u + uint(k)] * yb[1] + sh9[b + 6u + uint(k)] * yb[2] +
                                 sh9[b + 9u + uint(k)] * yb[3]));
        return e;
    }
    int nc = bands >= 3 ? 9 : bands * bands;
    for (int k = 0; k < 3; k++) {
        precise float s = 0.0;
        for (int j = 0; j < nc; j++) {
            float a = j == 0 ? 3.14159265358979 : j < 4 ? 2.09439510239320 : 0.785398163397448;
            s += a * sh9[b + 3u * uint(j) + uint(k)] * yb[j];
        }
        e[k] = max(0.0, s);
    }
    return e;
}

void main() {
    uint s = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (s >= u_count) return;
    Surfel sf = surfels[s];
    vec3 e = vec3(0.0);
    if (sf.cache != 0xFFFFFFFFu)
        e = irradiance(sf.cache, u_bands, (caches[sf.cache].flags & 1u) != 0u, sf.nx, sf.ny, sf.nz);
    e_ind[3u * s + 0u] = e.x;
    e_ind[3u * s + 1u] = e.y;
    e_ind[3u * s + 2u] = e.z;
}
