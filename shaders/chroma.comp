#version 430 core
// chroma: node flux RGB -> Y, Co, Cg in place (the pull is linear, so once at the nodes).
// Mirrors the conversion loop in tcpu_run.
layout(local_size_x = 64) in;

layout(std430, binding = 0) buffer Flux { float flux[]; };
layout(location = 0) uniform uint u_count;

void main() {
    uint i = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (i >= u_count) return;
    float r = flux[3u * i + 0u], g = flux[3u * i + 1u], b = flux[3u * i + 2u];
    precise float co = (r - b) * 0.5;
    precise float tt = b + co;
    precise float cg = (g - tt) * 0.5;
    precise float y = tt + cg;
    flux[3u * i + 0u] = y;
    flux[3u * i + 1u] = co;
    flux[3u * i + 2u] = cg;
}
