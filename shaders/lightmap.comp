#version 430 core
// lightmap: each texel shows its cache's irradiance for the cache normal (texel formula of
// transport.h; mirrors the lightmap loop of tcpu_run). One invocation per texel.
layout(local_size_x = 64) in;

struct Cache { float nx, ny, nz; uint flags; uint link_count; uint pad0, pad1, pad2; };
layout(std430, binding = 0) readonly buffer Index { uint texel_cache[]; };
layout(std430, binding = 1) readonly buffer Caches { Cache caches[]; };
layout(std430, binding = 2) readonly buffer CacheSH9 { float sh9[]; };
layout(std430, binding = 3) writeonly buffer Lightmap { float lightmap[]; };
layout(location = 0) uniform uint u_count;
layout(location = 2) uniform int u_bands;

void main() {
    uint i = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (i >= u_count) return;
    uint c = texel_cache[i];
    precise vec3 e = vec3(0.0);
    if (c != 0xFFFFFFFFu) {
        Cache cc = caches[c];
        float x = cc.nx, y = cc.ny, z = cc.nz;
        uint b = 27u * c;
        if (u_bands < 2) {
            for (int k = 0; k < 3; k++) e[k] = max(0.0, 6.28318530717959 * sh9[b + uint(k)] * 0.282094791774);
        } else {
            float y1 = 0.488602511903 * y, y2 = 0.488602511903 * z, y3 = 0.488602511903 * x;
            const float w = 4.18879020478639;
            for (int k = 0; k < 3; k++)
                e[k] = max(0.0, w * (sh9[b + 3u + uint(k)] * y1 + sh9[b + 6u + uint(k)] * y2 +
                                     sh9[b + 9u + uint(k)] * y3));
        }
    }
    lightmap[3u * i + 0u] = e.x;
    lightmap[3u * i + 1u] = e.y;
    lightmap[3u * i + 2u] = e.z;
}
