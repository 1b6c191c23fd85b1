#version 430 core
// mr_gather: LightSkin's gather (engine/mr.h step 3, eqs. 3, 4, 5, 7) at each sparse point,
// in float, the formulas of mr.c's mr_gather_body: per light j
//   w = r2 cos t_j / (r2 + d^2) (cos t_i > 0 and cos t_j > 0, else 0), wc = w cos t_i,
//   wd = eps + wc; glossy: ws = w cos^k g (cos g > 0, else 0), wsum = eps + ws,
// and writes the 20 raw sums per point (E_d rgb, sum wd, sum wd d, sum wd d^2 per axis, the
// same for the glossy channel); the host reduces them as mr.c's mr_reduce. One invocation
// per point; the lights are read through shared memory in tiles of TILE (K_cache = 128),
// each invocation of the workgroup loading TILE / 64 of them (SHARED 1), or straight from the
// SSBO (SHARED 0: the lights stream through the caches). The host prepends TILE and SHARED.
// The host dispatches the lights in chunks (LC_MR_GL_CHUNK, from u_base), each adding to the
// sums: llvmpipe stops any loop after 65535 iterations per invocation (Mesa's loop limiter,
// counted over all iterations of an inner loop), which silently dropped the lights past ~64k.
layout(local_size_x = 64) in;

struct Light { vec4 p_r2; vec4 n; vec4 b; }; // position, r2 = area / pi; normal; radiosity
struct Point { vec4 x_nv; vec4 n; vec4 v; }; // position, n.v; unit normal; unit direction to the camera
layout(std430, binding = 0) readonly buffer Lights { Light lights[]; };
layout(std430, binding = 1) readonly buffer Points { Point points[]; };
layout(std430, binding = 2) buffer Sums { float sums[]; }; // [point][20]
layout(location = 0) uniform uint u_points;
layout(location = 1) uniform uint u_lights; // lights in this chunk, from u_base
layout(location = 2) uniform float u_k;     // Phong exponent
layout(location = 3) uniform int u_glossy;
layout(location = 4) uniform float u_eps;   // LC_MR_EPSILON
layout(location = 5) uniform uint u_base;   // the chunk's first light
layout(location = 6) uniform int u_accumulate; // 0: the first chunk writes the sums, 1: later ones add

#if SHARED
shared vec4 s_p[TILE];
shared vec4 s_n[TILE];
shared vec4 s_b[TILE];
#endif

// mr.c's mr_exp2_neg and mr_pow01, operation for operation (GLSL's pow differs by ~1e-4 at
// k = 16 on llvmpipe, which the glossy sums then carry).
float exp2_neg(float y) {
    float yc = y > -126.0 ? y : -126.0;
    int ip = int(yc - 0.5);
    float f = yc - float(ip);
    float z = f * 0.693147181;
    float p = 1.0 + z * (1.0 + z * (0.5 + z * (0.166666667 + z * (0.0416666667 + z * (0.00833333333 + z * 0.00138888889)))));
    return p * intBitsToFloat((ip + 127) * (1 << 23)) * (y >= -126.0 ? 1.0 : 0.0);
}

float pow01(float c, float k) {
    int u = floatBitsToInt(c);
    int e = ((u >> 23) & 0xff) - 127;
    float mant = intBitsToFloat((u & 0x007fffff) | 0x3f800000);
    int big = mant > 1.41421356 ? 1 : 0;
    mant *= 1.0 - 0.5 * float(big);
    e += big;
    float t = (mant - 1.0) / (mant + 1.0), t2 = t * t;
    float lg = float(e) + t * (2.88539008 + t2 * (0.961796694 + t2 * (0.577078016 + t2 * (0.412198583 + t2 * 0.320598898))));
    float y = k * lg;
    return exp2_neg(y < 0.0 ? y : 0.0);
}

void main() {
    uint idx = gl_WorkGroupID.y * gl_NumWorkGroups.x * 64u + gl_WorkGroupID.x * 64u + gl_LocalInvocationID.x;
    bool live = idx < u_points;
    Point pt = points[live ? idx : 0u];
    vec3 x = pt.x_nv.xyz, n = pt.n.xyz, v = pt.v.xyz;
    float nv2 = 2.0 * pt.x_nv.w;
    vec3 ed = vec3(0.0), ld = vec3(0.0), md = vec3(0.0), es = vec3(0.0), ls = vec3(0.0), ms = vec3(0.0);
    float wd_sum = 0.0, ws_sum = 0.0;
#if SHARED
    for (uint j0 = 0u; j0 < u_lights; j0 += uint(TILE)) {
        barrier();
        for (uint t = gl_LocalInvocationID.x; t < uint(TILE); t += 64u) {
            uint j = j0 + t;
            vec4 p = vec4(0.0), nn = vec4(0.0), b = vec4(0.0);
            if (j < u_lights) p = lights[u_base + j].p_r2, nn = lights[u_base + j].n, b = lights[u_base + j].b;
            s_p[t] = p;
            s_n[t] = nn;
            s_b[t] = b;
        }
        barrier();
        uint nj = min(uint(TILE), u_lights - j0);
        for (uint t = 0u; t < nj; t++) {
            vec4 lp = s_p[t], ln = s_n[t], lb = s_b[t];
#else
    if (live) {
        for (uint t = 0u; t < u_lights; t++) {
            vec4 lp = lights[u_base + t].p_r2, ln = lights[u_base + t].n, lb = lights[u_base + t].b;
#endif
            vec3 d = lp.xyz - x;
            float d2 = dot(d, d);
            float inv = 1.0 / sqrt(max(d2, 1e-20));
            float ci = dot(n, d) * inv;
            float cj = -dot(ln.xyz, d) * inv;
            float r2 = lp.w;
            float w = r2 * cj / (r2 + d2);
            bool ok = ci > 0.0 && cj > 0.0;
            float wc = ok ? w * ci : 0.0;
            float wd = u_eps + wc;
            vec3 b = lb.xyz;
            ed += b * wc;
            wd_sum += wd;
            ld += wd * d;
            md += wd * d * d;
            if (u_glossy != 0) {
                float cg = nv2 * ci - dot(v, d) * inv;
                float gw = ok && cg > 0.0 ? w : 0.0;
                float ws = gw * pow01(cg > 1e-30 ? (cg < 1.0 ? cg : 1.0) : 1e-30, u_k);
                float wsum = u_eps + ws;
                es += b * ws;
                ws_sum += wsum;
                ls += wsum * d;
                ms += wsum * d * d;
            }
        }
    }
    if (!live) return;
    uint o = idx * 20u;
    float r[20] = float[20](ed.x, ed.y, ed.z, wd_sum, ld.x, ld.y, ld.z, md.x, md.y, md.z, es.x, es.y, es.z, ws_sum, ls.x,
                            ls.y, ls.z, ms.x, ms.y, ms.z);
    for (uint k = 0u; k < 20u; k++) sums[o + k] = u_accumulate != 0 ? sums[o + k] + r[k] : r[k];
}
