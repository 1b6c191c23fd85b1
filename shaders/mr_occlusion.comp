#version 430 core
// mr_occlusion: LightSkin's occlusion (engine/mr.h step 4, §3.3, eqs. 3 and 14) at each sparse
// point, in float, the formulas of mr.c's mr_occlusion: the other points as two-sided discs in
// front of x's tangent plane and nearer than S_o's centre, projected (Nusselt) to squares in the
// (t, b) frame of n, summed over their overlap with S_o's square, ramped to 0 inside S_o.
// One invocation per point (o_d, then o_s when glossy); the occluders stream from the SSBO in
// chunks the host dispatches one by one (u_kbase, u_kcount: llvmpipe ends any loop after 65535
// iterations), each adding its sum / area_S; the host clamps the total to [0, 1].
layout(local_size_x = 64) in;

struct OPoint { vec4 x_r; vec4 n_obj; }; // position, disc radius; unit normal, object (uint bits)
struct Target { vec4 ld_r; vec4 ls_r; }; // l_d, S_o radius for l_d; l_s, radius for l_s
layout(std430, binding = 0) readonly buffer Points { OPoint pts[]; };
layout(std430, binding = 1) readonly buffer Targets { Target targets[]; };
layout(std430, binding = 2) buffer Occ { float occ[]; }; // [point][2], unclamped
layout(location = 0) uniform uint u_points;
layout(location = 1) uniform int u_self;   // self_occlusion
layout(location = 2) uniform int u_glossy;
layout(location = 3) uniform uint u_kbase;  // the chunk's first occluder
layout(location = 4) uniform uint u_kcount; // occluders in the chunk
layout(location = 5) uniform int u_accumulate; // 0: the first chunk writes, 1: later ones add

const float PI = 3.14159265358979;

// mr_frame: an orthonormal tangent frame of the unit normal n (Duff et al. 2017).
void frame(vec3 n, out vec3 t, out vec3 b) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z), c = n.x * n.y * a;
    t = vec3(1.0 + s * n.x * n.x * a, s * c, -s * n.x);
    b = vec3(c, s + n.y * n.y * a, -n.y);
}

float occlusion(uint i, vec3 x, vec3 n, uint obj, vec3 l, float rad) {
    vec3 v = l - x;
    float dd = sqrt(dot(v, v));
    if (!(dd > 1e-6)) return 0.0;
    float ci = dot(n, v) / dd;
    if (!(ci > 0.0)) return 0.0;
    float R = rad > 1e-3 * dd ? rad : 1e-3 * dd;
    float area_s = PI * R * R / (R * R + dd * dd) * ci;
    vec3 t, b;
    frame(n, t, b);
    float sx = dot(v, t) / dd, sy = dot(v, b) / dd;
    float hs = 0.5 * sqrt(area_s);
    float near = dd - R > 0.0 ? dd - R : 0.0, ramp = dd - near;
    float sum = 0.0;
    for (uint k = u_kbase; k < u_kbase + u_kcount; k++) {
        OPoint o = pts[k];
        if (k == i || (u_self == 0 && floatBitsToUint(o.n_obj.w) == obj)) continue;
        vec3 u = o.x_r.xyz - x;
        float d2 = dot(u, u);
        if (!(d2 < dd * dd) || !(d2 > 1e-12)) continue;
        float dk = sqrt(d2);
        float cn = dot(n, u) / dk;
        if (!(cn > 0.0)) continue;
        float cj = abs(dot(o.n_obj.xyz, u)) / dk, r2 = o.x_r.w * o.x_r.w;
        float hk = 0.5 * sqrt(PI * r2 * cj / (r2 + d2) * cn);
        float kx = dot(u, t) / dk, ky = dot(u, b) / dk;
        float ox = min(sx + hs, kx + hk) - max(sx - hs, kx - hk);
        float oy = min(sy + hs, ky + hk) - max(sy - hs, ky - hk);
        if (!(ox > 0.0) || !(oy > 0.0)) continue;
        float s = dk <= near ? 1.0 : (dd - dk) / ramp;
        sum += s * ox * oy;
    }
    return sum / area_s;
}

void main() {
    uint i = gl_WorkGroupID.y * gl_NumWorkGroups.x * 64u + gl_WorkGroupID.x * 64u + gl_LocalInvocationID.x;
    if (i >= u_points) return;
    OPoint p = pts[i];
    Target g = targets[i];
    uint obj = floatBitsToUint(p.n_obj.w);
    float od = occlusion(i, p.x_r.xyz, p.n_obj.xyz, obj, g.ld_r.xyz, g.ld_r.w);
    float os = u_glossy != 0 ? occlusion(i, p.x_r.xyz, p.n_obj.xyz, obj, g.ls_r.xyz, g.ls_r.w) : 0.0;
    occ[2u * i] = u_accumulate != 0 ? occ[2u * i] + od : od;
    occ[2u * i + 1u] = u_accumulate != 0 ? occ[2u * i + 1u] + os : os;
}
