#version 430 core
// grid: cosine-convolved L2 irradiance SH per grid sample, c_lm = A_l L_lm (bands above the
// cache's are 0). Mirrors the grid loop of tcpu_run. One invocation per sample.
layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer Index { uint grid_cache[]; };
layout(std430, binding = 1) readonly buffer CacheSH9 { float sh9[]; };
layout(std430, binding = 2) writeonly buffer GridSH { float grid_sh[]; };
layout(location = 0) uniform uint u_count;
layout(location = 2) uniform int u_bands;

void main() {
    uint i = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (i >= u_count) return;
    uint c = grid_cache[i];
    int nc9 = u_bands >= 3 ? 9 : u_bands * u_bands;
    for (int j = 0; j < 9; j++) {
        float a = j == 0 ? 3.14159265358979 : j < 4 ? 2.09439510239320 : 0.785398163397448;
        for (int k = 0; k < 3; k++)
            grid_sh[27u * i + 3u * uint(j) + uint(k)] = j < nc9 ? a * sh9[27u * c + 3u * uint(j) + uint(k)] : 0.0;
    }
}
