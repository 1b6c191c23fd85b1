#version 430 core
// radiosity: B[s] = B0[s] + albedo[s] * E_ind[s] for every surfel (the feedback step of
// transport.h), one invocation per surfel. Mirrors tcpu_run's first loop.
layout(local_size_x = 64) in;

struct Surfel { float nx, ny, nz, area, ax, ay, az; uint cache; };
layout(std430, binding = 0) readonly buffer Surfels { Surfel surfels[]; };
layout(std430, binding = 1) readonly buffer B0 { float b0[]; };
layout(std430, binding = 2) readonly buffer EInd { float e_ind[]; };
layout(std430, binding = 3) writeonly buffer Radiosity { float radiosity[]; };
layout(location = 0) uniform uint u_count;

void main() {
    // 2-D dispatch: at most 65535 groups per axis.
    uint s = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (s >= u_count) return;
    Surfel sf = surfels[s];
    // precise: no fused multiply-add, so the sum rounds like the C code's.
    precise float r0 = b0[3u * s + 0u] + sf.ax * e_ind[3u * s + 0u];
    precise float r1 = b0[3u * s + 1u] + sf.ay * e_ind[3u * s + 1u];
    precise float r2 = b0[3u * s + 2u] + sf.az * e_ind[3u * s + 2u];
    radiosity[3u * s + 0u] = r0;
    radiosity[3u * s + 1u] = r1;
    radiosity[3u * s + 2u] = r2;
}
