#version 430 core
// pull: one BFS level of the node tree. Leaves hold B * area of their surfel; internal nodes
// the sum of their two children (a deeper level, written by the previous dispatch).
// Mirrors tcpu_pull, which sweeps the nodes in reverse order.
layout(local_size_x = 64) in;

struct Node { uint c0, c1, first_surfel, area_bits; }; // area_bits: the leaf surfel's area
layout(std430, binding = 0) readonly buffer Nodes { Node nodes[]; };
layout(std430, binding = 1) readonly buffer Radiosity { float radiosity[]; };
layout(std430, binding = 2) buffer Flux { float flux[]; };
layout(location = 0) uniform uint u_count; // nodes in this level
layout(location = 1) uniform uint u_base;  // first node of this level

void main() {
    uint idx = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (idx >= u_count) return;
    uint i = u_base + idx;
    Node nd = nodes[i];
    if (nd.c0 == 0xFFFFFFFFu) {
        float a = uintBitsToFloat(nd.area_bits);
        for (uint k = 0u; k < 3u; k++) flux[3u * i + k] = radiosity[3u * nd.first_surfel + k] * a;
    } else {
        for (uint k = 0u; k < 3u; k++) flux[3u * i + k] = flux[3u * nd.c0 + k] + flux[3u * nd.c1 + k];
    }
}
