#version 430 core
// dnrt: placed objects in the indirect light (engine/dnrt.h) after a pass's gather, the GL twin
// of tcpu_dnrt + lc_dnrt_apply. The host prepends (after #version) DNRT_PREP 1 or 0:
//   prep  (one invocation per DNRT object): its incident irradiance SH c from its 8 corner
//         caches, cosine-convolved and trilinear as tcpu_grid_sample, rotated into the asset's
//         frame (to_local): c and c_tot = c + c_dir, 9 x RGB each, into Incident.
//   apply (one invocation per receiver of ONE object; the host dispatches object by object with
//         a barrier between, so receivers of different objects that hit the same cache or
//         object never race, and every sum is added in the CPU's order):
//           X = sum_j c_tot_j T_j - sum_j c_j K_j, then L_lm += X y_lm(d) at a cache
//         (texel caches [u_texel_lo, u_texel_nc), grid caches [0, u_grid_nc); the windowed
//         full SH and the L2 copy alike), or E_lm += A_l X y_lm(d) at an object's SH.
layout(local_size_x = 64) in;

// std430 mirror of tgl_dnrt_object (transport_gl.c): 512 bytes.
struct Obj {
    uint coeffs, pad0, pad1, pad2;
    uint corner[8];
    float corner_w[8];
    float to_local[81]; // row-major 9x9: c_local[i] = sum_j to_local[9 i + j] c_world[j]
    float c_dir[27];    // the direct light's irradiance SH at the object (world)
};
layout(std430, binding = 0) readonly buffer Objects { Obj objs[]; };

float cosine_a(int j) { return j == 0 ? 3.14159265358979 : j < 4 ? 2.09439510239320 : 0.785398163397448; }

#if DNRT_PREP
layout(std430, binding = 1) writeonly buffer Incident { float inc[]; }; // [object][c, c_tot][9][3]
layout(std430, binding = 2) readonly buffer CacheSH9 { float sh9[]; };  // [cache][9][3]
layout(location = 0) uniform uint u_count;
layout(location = 1) uniform int u_bands;

void main() {
    uint o = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (o >= u_count) return;
    int nc9 = u_bands >= 3 ? 9 : u_bands * u_bands;
    precise float cw[27];
    for (int j = 0; j < 27; j++) cw[j] = 0.0;
    for (int c = 0; c < 8; c++) {
        float w = objs[o].corner_w[c];
        if (w == 0.0) continue;
        uint b = 27u * objs[o].corner[c];
        for (int j = 0; j < nc9; j++)
            for (int k = 0; k < 3; k++) {
                precise float g = cosine_a(j) * sh9[b + uint(3 * j + k)];
                cw[3 * j + k] += w * g;
            }
    }
    int nc = int(objs[o].coeffs);
    uint ob = 54u * o;
    for (int i = 0; i < 9; i++)
        for (int ch = 0; ch < 3; ch++) {
            precise float s = 0.0, sd = 0.0;
            if (i < nc)
                for (int j = 0; j < 9; j++) {
                    s += objs[o].to_local[9 * i + j] * cw[3 * j + ch];
                    sd += objs[o].to_local[9 * i + j] * objs[o].c_dir[3 * j + ch];
                }
            inc[ob + uint(3 * i + ch)] = s;
            inc[ob + 27u + uint(3 * i + ch)] = s + sd;
        }
}

#else
struct Cache { float nx, ny, nz; uint flags; uint link_count; uint fresh, pad1, pad2; }; // fresh: some surfel reads it
layout(std430, binding = 1) readonly buffer Incident { float inc[]; };
layout(std430, binding = 2) readonly buffer Receivers { float rec[]; }; // [receiver][40]: target bits, d, T, K
layout(std430, binding = 3) readonly buffer Caches { Cache caches[]; };
layout(std430, binding = 4) buffer CacheSH { float cache_sh[]; }; // window from cache u_cbase, [cache][u_nc][3]
layout(std430, binding = 5) buffer CacheSH9 { float sh9[]; };     // [cache][9][3]
layout(std430, binding = 6) buffer ObjectSH { float object_sh[]; }; // [state object][9][3]
layout(std430, binding = 7) readonly buffer ShK { double shk[]; }; // K_l0, sqrt(2) K_lm (m > 0)
layout(location = 0) uniform uint u_count;    // receivers of this object
layout(location = 1) uniform uint u_first;    // its first record in the bound window
layout(location = 2) uniform uint u_object;   // frame index of the object
layout(location = 3) uniform uint u_cbase;    // caches in the bound cache SH window
layout(location = 4) uniform uint u_ccount;
layout(location = 5) uniform uint u_nc;       // the cache SH's stride (bands^2)
layout(location = 6) uniform uint u_n_texel;  // caches [0, u_n_texel) are texel caches
layout(location = 7) uniform int u_texel_lo;
layout(location = 8) uniform int u_texel_nc;
layout(location = 9) uniform int u_grid_nc;
layout(location = 10) uniform int u_bands;    // bands of y(d): the smallest with bands^2 >= both nc
layout(location = 11) uniform int u_last;     // 1: every cache is fresh
layout(location = 12) uniform int u_objects;  // 1: this dispatch also does the object receivers

// lc_sh_eval_fast: closed forms up to 4 bands, lc_sh_eval's recurrence in double above.
void sh_eval(int bands, float x, float y, float z, out float o[64]) {
    if (bands <= 4) {
        o[0] = 0.282094791774;
        o[1] = 0.488602511903 * y;
        o[2] = 0.488602511903 * z;
        o[3] = 0.488602511903 * x;
        o[4] = 1.092548430592 * x * y;
        o[5] = 1.092548430592 * y * z;
        o[6] = 0.315391565253 * (3.0 * z * z - 1.0);
        o[7] = 1.092548430592 * x * z;
        o[8] = 0.546274215296 * (x * x - y * y);
        float z2 = z * z;
        o[9] = 0.590043589927 * y * (3.0 * x * x - y * y);
        o[10] = 2.890611442641 * x * y * z;
        o[11] = 0.457045799464 * y * (5.0 * z2 - 1.0);
        o[12] = 0.373176332590 * z * (5.0 * z2 - 3.0);
        o[13] = 0.457045799464 * x * (5.0 * z2 - 1.0);
        o[14] = 1.445305721321 * z * (x * x - y * y);
        o[15] = 0.590043589927 * x * (x * x - 3.0 * y * y);
        return;
    }
    double dx = double(x), dy = double(y), dz = double(z);
    double q[64];
    double re[8], im[8];
    re[0] = 1.0LF;
    im[0] = 0.0LF;
    for (int m = 1; m < bands; m++) {
        re[m] = re[m - 1] * dx - im[m - 1] * dy;
        im[m] = re[m - 1] * dy + im[m - 1] * dx;
    }
    for (int m = 0; m < bands; m++) {
        double pmm = 1.0LF;
        for (int k = 1; k <= m; k++) pmm *= double(2 * k - 1);
        q[m * 8 + m] = pmm;
        if (m + 1 < bands) q[(m + 1) * 8 + m] = dz * double(2 * m + 1) * pmm;
        for (int l = m + 2; l < bands; l++)
            q[l * 8 + m] = (double(2 * l - 1) * dz * q[(l - 1) * 8 + m] - double(l + m - 1) * q[(l - 2) * 8 + m]) /
                double(l - m);
    }
    for (int l = 0; l < bands; l++) {
        o[l * l + l] = float(shk[l * l + l] * q[l * 8]);
        for (int m = 1; m <= l; m++) {
            double s = shk[l * l + l + m] * q[l * 8 + m];
            o[l * l + l + m] = float(s * re[m]);
            o[l * l + l - m] = float(s * im[m]);
        }
    }
}

void main() {
    uint idx = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (idx >= u_count) return;
    uint r = 40u * (u_first + idx);
    uint target = floatBitsToUint(rec[r]);
    bool is_object = (target & 0x80000000u) != 0u;
    if (is_object) {
        if (u_objects == 0) return;
    } else {
        if (target < u_cbase || target - u_cbase >= u_ccount) return; // another window's
        if (u_last == 0 && caches[target].fresh == 0u) return;       // not gathered this pass
    }
    int nc = int(objs[u_object].coeffs);
    uint ib = 54u * u_object;
    precise vec3 x;
    for (int ch = 0; ch < 3; ch++) {
        precise float s = 0.0;
        for (int i = 0; i < nc; i++)
            s += inc[ib + 27u + uint(3 * i + ch)] * rec[r + 4u + uint(3 * i + ch)] -
                inc[ib + uint(3 * i + ch)] * rec[r + 31u + uint(i)];
        x[ch] = s;
    }
    float d0 = rec[r + 1u], d1 = rec[r + 2u], d2 = rec[r + 3u];
    float y[64];
    if (is_object) {
        sh_eval(3, d0, d1, d2, y);
        uint ob = 27u * (target & 0x7FFFFFFFu);
        for (int j = 0; j < 9; j++)
            for (int ch = 0; ch < 3; ch++) {
                precise float v = cosine_a(j) * y[j] * x[ch];
                object_sh[ob + uint(3 * j + ch)] += v;
            }
        return;
    }
    bool texel = target < u_n_texel;
    int lo = texel ? u_texel_lo : 0, hi = texel ? u_texel_nc : u_grid_nc;
    sh_eval(u_bands, d0, d1, d2, y);
    uint lb = (target - u_cbase) * u_nc * 3u, b9 = 27u * target;
    for (int j = lo; j < hi; j++)
        for (int ch = 0; ch < 3; ch++) {
            precise float v = y[j] * x[ch];
            cache_sh[lb + uint(3 * j + ch)] += v;
            if (j < 9) sh9[b9 + uint(3 * j + ch)] += v;
        }
}
#endif
