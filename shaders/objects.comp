#version 430 core
// objects: trilinear sample of the grid's irradiance SH at each object position, clamped to
// the lattice. Mirrors tcpu_grid_sample. One invocation per object.
layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer Positions { float pos[]; };
layout(std430, binding = 1) readonly buffer GridSH { float grid_sh[]; };
layout(std430, binding = 2) writeonly buffer ObjectSH { float object_sh[]; };
layout(location = 0) uniform uint u_count;
layout(location = 2) uniform vec3 u_origin;
layout(location = 3) uniform float u_cell;
layout(location = 4) uniform uvec3 u_dims;

void main() {
    uint i = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (i >= u_count) return;
    float f[3];
    int i0[3];
    for (int k = 0; k < 3; k++) {
        float g = (pos[3u * i + uint(k)] - u_origin[k]) / u_cell;
        float maxg = float(u_dims[k] - 1u);
        if (!(g > 0.0)) g = 0.0;
        if (g > maxg) g = maxg;
        i0[k] = int(floor(g));
        if (i0[k] > int(u_dims[k]) - 2) i0[k] = int(u_dims[k]) - 2;
        if (i0[k] < 0) i0[k] = 0;
        f[k] = u_dims[k] > 1u ? g - float(i0[k]) : 0.0;
    }
    precise float acc[27];
    for (int j = 0; j < 27; j++) acc[j] = 0.0;
    for (int corner = 0; corner < 8; corner++) {
        int idx[3];
        precise float w = 1.0;
        for (int k = 0; k < 3; k++) {
            int bit = (corner >> k) & 1;
            idx[k] = i0[k] + bit;
            if (idx[k] >= int(u_dims[k])) idx[k] = int(u_dims[k]) - 1;
            w *= bit != 0 ? f[k] : 1.0 - f[k];
        }
        if (w == 0.0) continue;
        uint cell = uint(idx[0]) + u_dims[0] * (uint(idx[1]) + u_dims[1] * uint(idx[2]));
        for (int j = 0; j < 27; j++) acc[j] += w * grid_sh[27u * cell + uint(j)];
    }
    for (int j = 0; j < 27; j++) object_sh[27u * i + uint(j)] = acc[j];
}
