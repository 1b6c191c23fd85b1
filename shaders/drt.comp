#version 430 core
// drt: clutter operators (engine/drt.h) after a pass's gather and DNRT, the GL twin of tcpu_drt +
// lc_drt_apply. Every attached object's arrays are concatenated (transport_gl.c, tgl_drt_upload);
// patch sources in the entries carry the global patch index. The host prepends DRT_STAGE:
//   0 patches   (one invocation per patch): B = albedo max(0, E_direct + sum_g w_g flux(source_g))
//               with flux(patch) the previous pass's (PatchFlux), as drt_patches_pass.
//   1 flux      (one invocation per patch): PatchFlux = B area, once every B of this pass is in.
//   2 receivers (one invocation per receiver of ONE object; the host dispatches object by object
//               with a barrier between, so two objects' receivers of one cache never race and the
//               sums are added in the CPU's order): L_c += sum_e w_e,c flux(source_e), texel caches
//               [u_texel_lo, min(u_texel_nc, 4)), grid caches [0, min(u_grid_nc, 9)), the windowed
//               full SH and the L2 copy alike.
//   3 inpaint   (one invocation per covered cache of ONE object): the mean of its sources (never
//               covered by the same object), read from the L2 copy (bound whole; texel caches
//               carry <= 4 coefficients), written to both.
// Intermediate passes (u_last 0) change only the caches some surfel reads (Cache.fresh).
layout(local_size_x = 64) in;

layout(location = 0) uniform uint u_count;

struct Patch { float albedo[3]; float area; uint gather_first, gather_count, pad0, pad1; };

#if DRT_STAGE == 0 || DRT_STAGE == 2
layout(std430, binding = 3) readonly buffer NodeFlux { float node_flux[]; }; // [node][3], RGB or YCoCg
layout(location = 1) uniform int u_ycocg;
vec3 node_rgb(uint n) {
    vec3 x = vec3(node_flux[3u * n], node_flux[3u * n + 1u], node_flux[3u * n + 2u]);
    if (u_ycocg == 0) return x;
    float t = x.x - x.z; // Y, Co, Cg -> RGB (drt_source_flux)
    return vec3(t + x.y, x.x + x.z, t - x.y);
}
#endif

#if DRT_STAGE == 0
layout(std430, binding = 0) readonly buffer Patches { Patch patches[]; };
layout(std430, binding = 1) readonly buffer EDirect { float e_direct[]; }; // [patch][3]
layout(std430, binding = 2) readonly buffer Gather { uvec2 gather[]; };     // source, w bits
layout(std430, binding = 4) writeonly buffer PatchB { float patch_b[]; };
layout(std430, binding = 5) readonly buffer PatchFlux { float patch_flux[]; };
void main() {
    uint p = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (p >= u_count) return;
    precise vec3 e = vec3(e_direct[3u * p], e_direct[3u * p + 1u], e_direct[3u * p + 2u]);
    uint g0 = patches[p].gather_first;
    for (uint g = g0; g < g0 + patches[p].gather_count; g++) {
        uint src = gather[g].x;
        float w = uintBitsToFloat(gather[g].y);
        vec3 f;
        if ((src & 0x80000000u) != 0u) {
            uint q = 3u * (src & 0x7FFFFFFFu);
            f = vec3(patch_flux[q], patch_flux[q + 1u], patch_flux[q + 2u]);
        } else {
            f = node_rgb(src);
        }
        for (int k = 0; k < 3; k++) e[k] += w * f[k];
    }
    for (int k = 0; k < 3; k++) patch_b[3u * p + uint(k)] = patches[p].albedo[k] * max(0.0, e[k]);
}

#elif DRT_STAGE == 1
layout(std430, binding = 0) readonly buffer Patches { Patch patches[]; };
layout(std430, binding = 4) readonly buffer PatchB { float patch_b[]; };
layout(std430, binding = 5) writeonly buffer PatchFlux { float patch_flux[]; };
void main() {
    uint p = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (p >= u_count) return;
    for (uint k = 0u; k < 3u; k++) patch_flux[3u * p + k] = patch_b[3u * p + k] * patches[p].area;
}

#else
struct Cache { float nx, ny, nz; uint flags; uint link_count; uint fresh, pad1, pad2; };
layout(std430, binding = 0) readonly buffer Caches { Cache caches[]; };
layout(std430, binding = 1) buffer CacheSH { float cache_sh[]; }; // window from cache u_cbase, [cache][u_nc][3]
layout(std430, binding = 2) buffer CacheSH9 { float sh9[]; };     // [cache][9][3]
layout(location = 2) uniform uint u_first;  // this object's first record
layout(location = 3) uniform uint u_cbase;  // caches in the bound cache SH window
layout(location = 4) uniform uint u_ccount;
layout(location = 5) uniform uint u_nc;     // the cache SH's stride (bands^2)
layout(location = 6) uniform uint u_n_texel;
layout(location = 7) uniform int u_texel_lo;
layout(location = 8) uniform int u_texel_nc;
layout(location = 9) uniform int u_grid_nc;
layout(location = 10) uniform int u_last;

// Not this window's cache, or not gathered this pass: left alone.
bool skip(uint c) { return c < u_cbase || c - u_cbase >= u_ccount || (u_last == 0 && caches[c].fresh == 0u); }

#if DRT_STAGE == 2
layout(std430, binding = 4) readonly buffer Receivers { uvec4 receivers[]; }; // cache, first, count, -
layout(std430, binding = 5) readonly buffer PatchFlux { float patch_flux[]; };
layout(std430, binding = 6) readonly buffer Entries { float entries[]; }; // e4: source + 4 w; e9: source + 9 w
void main() {
    uint r = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (r >= u_count) return;
    uvec4 rc = receivers[u_first + r];
    uint c = rc.x;
    if (skip(c)) return;
    bool texel = c < u_n_texel;
    int lo = texel ? u_texel_lo : 0, hi = texel ? min(u_texel_nc, 4) : min(u_grid_nc, 9);
    uint stride = texel ? 5u : 10u;
    // The cache's coefficients are loaded once, summed in registers in entry order and stored
    // once: the same roundings as adding every entry into memory (the CPU's order), without a
    // read-modify-write of global memory per entry (7 ms per object on an H200 that way).
    // The full SH and its L2 copy hold the same values but are summed apart, as the CPU does.
    uint base = (c - u_cbase) * u_nc * 3u;
    precise float acc[27], acc9[27];
    for (int j = lo; j < hi; j++)
        for (int k = 0; k < 3; k++) {
            acc[3 * j + k] = cache_sh[base + uint(3 * j + k)];
            acc9[3 * j + k] = sh9[27u * c + uint(3 * j + k)];
        }
    for (uint i = 0u; i < rc.z; i++) {
        uint e = rc.y + i * stride;
        uint src = floatBitsToUint(entries[e]);
        vec3 f;
        if ((src & 0x80000000u) != 0u) {
            uint q = 3u * (src & 0x7FFFFFFFu);
            f = vec3(patch_flux[q], patch_flux[q + 1u], patch_flux[q + 2u]);
        } else {
            f = node_rgb(src);
        }
        for (int j = lo; j < hi; j++)
            for (int k = 0; k < 3; k++) {
                precise float v = entries[e + 1u + uint(j)] * f[k];
                acc[3 * j + k] += v;
                acc9[3 * j + k] += v;
            }
    }
    for (int j = lo; j < hi; j++)
        for (int k = 0; k < 3; k++) {
            cache_sh[base + uint(3 * j + k)] = acc[3 * j + k];
            sh9[27u * c + uint(3 * j + k)] = acc9[3 * j + k];
        }
}

#else
layout(std430, binding = 4) readonly buffer Inpaint { uvec4 inpaint[]; }; // cache, first, count, -
layout(std430, binding = 5) readonly buffer From { uint from_cache[]; };
void main() {
    uint i = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (i >= u_count) return;
    uvec4 ip = inpaint[u_first + i];
    uint c = ip.x;
    if (skip(c)) return;
    float w = 1.0 / float(ip.z);
    int n = min(u_texel_nc, 9);
    for (int j = 0; j < n; j++)
        for (int k = 0; k < 3; k++) {
            precise float s = 0.0;
            for (uint q = 0u; q < ip.z; q++) s += w * sh9[27u * from_cache[ip.y + q] + uint(3 * j + k)];
            cache_sh[(c - u_cbase) * u_nc * 3u + uint(3 * j + k)] = s;
            if (j < 9) sh9[27u * c + uint(3 * j + k)] = s;
        }
}
#endif
#endif
