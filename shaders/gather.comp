#version 430 core
// gather: each cache's incident radiance SH from its links,
//   L_lm += flux[node] * factor * h_l(cos alpha) * y_lm(dir),
// one invocation per cache, links summed in order so the float sums round like the C code's
// (tcpu_gather_range). The host prepends (after #version) the compile-time constants
//   BANDS (1..8), NC = BANDS^2, NCC = coefficients carried for channels 1 and 2
//   (chroma_bands^2 when compressing, else NC), CHROMA (0/1: flux is Y, Co, Cg)
// so the per-cache accumulators are fixed-size arrays the compiler can keep in registers.
layout(local_size_x = 64) in;

struct Link { uint node; float factor; uint dir_cone; };
struct Cache { float nx, ny, nz; uint flags; uint link_count; uint pad0, pad1, pad2; };
// links and cache_sh are bound as windows starting at cache u_base (<= 128 MiB each); the links
// are link-major within their window (link k of window cache i at k * u_window + i: the
// invocations of a subgroup read consecutive links).
layout(std430, binding = 0) readonly buffer Links { Link links[]; };
layout(std430, binding = 1) readonly buffer Caches { Cache caches[]; };
layout(std430, binding = 2) readonly buffer Flux { float flux[]; };
layout(std430, binding = 3) readonly buffer Cone { float cone[]; };     // [256][8] h_l
layout(std430, binding = 4) writeonly buffer CacheSH { float cache_sh[]; }; // [cache][NC][3]
layout(std430, binding = 5) writeonly buffer CacheSH9 { float sh9[]; };     // [cache][9][3]
layout(std430, binding = 6) readonly buffer List { uint list[]; };
layout(std430, binding = 7) readonly buffer ShK { double shk[]; }; // K_l0, sqrt(2) K_lm (m > 0)
layout(location = 0) uniform uint u_count;
layout(location = 1) uniform uint u_base;
layout(location = 3) uniform uint u_use_list; // 1: caches are list[idx] (single window)
layout(location = 4) uniform int u_texel_nc;   // coefficients gathered at texel caches (lc_transport_texel_bands^2)
layout(location = 5) uniform int u_texel_band1; // 1: texel caches carry band 1 only (lc_transport_texel_band1)
layout(location = 6) uniform uint u_window;     // caches in the bound links window
layout(location = 7) uniform int u_texel_surfels; // 1: texel caches from their surfel lists (lc_transport_texel_surfels)
layout(location = 8) uniform uint u_n_texel;      // texel caches are [0, u_n_texel)
layout(location = 9) uniform uint u_grid_rows;    // > 0: grid caches' links are in grid_links (GLNK), this many rows

// The bake's texel surfel lists (TSGF/TSGW; one-entry dummies without them) and the radiosity.
struct SurfelWeight { uint surfel; float weight; };
layout(std430, binding = 8) readonly buffer TexelFirst { uint texel_first[]; };
layout(std430, binding = 9) readonly buffer TexelSurfels { SurfelWeight texel_surfels[]; };
layout(std430, binding = 10) readonly buffer Radiosity { float radiosity[]; };
// GLNK, link-major over the grid caches (link k of grid cache g at k * u_grid_rows + g), bound whole.
layout(std430, binding = 11) readonly buffer GridLinks { Link grid_links[]; };

const int BAND_OF[64] = int[64](0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4, 5, 5, 5, 5, 5, 5, 5, 5,
                                5, 5, 5, 6, 6, 6, 6, 6, 6, 6, 6, 6, 6, 6, 6, 6, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7);

// Exactly tcpu_oct_decode: 12+12 bit octahedral direction.
vec3 oct_decode(uint code) {
    float u = float(code & 0xFFFu) * (2.0 / 4095.0) - 1.0;
    float w = float((code >> 12) & 0xFFFu) * (2.0 / 4095.0) - 1.0;
    float z = 1.0 - abs(u) - abs(w);
    if (z < 0.0) {
        float uu = (1.0 - abs(w)) * (u >= 0.0 ? 1.0 : -1.0);
        float ww = (1.0 - abs(u)) * (w >= 0.0 ? 1.0 : -1.0);
        u = uu;
        w = ww;
    }
    float inv = 1.0 / sqrt(u * u + w * w + z * z);
    return vec3(u * inv, w * inv, z * inv);
}

#if BANDS <= 4
// lc_sh_eval_fast's closed forms (no Condon-Shortley phase; band 1 = (y, z, x) sqrt(3/4pi)).
void sh_eval(float x, float y, float z, out float o[NC]) {
    o[0] = 0.282094791774;
#if BANDS >= 2
    o[1] = 0.488602511903 * y;
    o[2] = 0.488602511903 * z;
    o[3] = 0.488602511903 * x;
#endif
#if BANDS >= 3
    o[4] = 1.092548430592 * x * y;
    o[5] = 1.092548430592 * y * z;
    o[6] = 0.315391565253 * (3.0 * z * z - 1.0);
    o[7] = 1.092548430592 * x * z;
    o[8] = 0.546274215296 * (x * x - y * y);
#endif
#if BANDS >= 4
    float z2 = z * z;
    o[9] = 0.590043589927 * y * (3.0 * x * x - y * y);
    o[10] = 2.890611442641 * x * y * z;
    o[11] = 0.457045799464 * y * (5.0 * z2 - 1.0);
    o[12] = 0.373176332590 * z * (5.0 * z2 - 3.0);
    o[13] = 0.457045799464 * x * (5.0 * z2 - 1.0);
    o[14] = 1.445305721321 * z * (x * x - y * y);
    o[15] = 0.590043589927 * x * (x * x - 3.0 * y * y);
#endif
}
#else
// lc_sh_eval's generic recurrence, in double like the C code: Q[l][m] is P_l^m(z) without the
// sin^m factor, (re, im) = (x + i y)^m; the normalisation K comes from the host (shk).
void sh_eval(float x, float y, float z, out float o[NC]) {
    double dx = double(x), dy = double(y), dz = double(z);
    double q[NC];
    double re[BANDS], im[BANDS];
    re[0] = 1.0LF;
    im[0] = 0.0LF;
    for (int m = 1; m < BANDS; m++) {
        re[m] = re[m - 1] * dx - im[m - 1] * dy;
        im[m] = re[m - 1] * dy + im[m - 1] * dx;
    }
    for (int m = 0; m < BANDS; m++) {
        double pmm = 1.0LF;
        for (int k = 1; k <= m; k++) pmm *= double(2 * k - 1);
        q[m * BANDS + m] = pmm;
        if (m + 1 < BANDS) q[(m + 1) * BANDS + m] = dz * double(2 * m + 1) * pmm;
        for (int l = m + 2; l < BANDS; l++)
            q[l * BANDS + m] = (double(2 * l - 1) * dz * q[(l - 1) * BANDS + m] -
                                double(l + m - 1) * q[(l - 2) * BANDS + m]) / double(l - m);
    }
    for (int l = 0; l < BANDS; l++) {
        o[l * l + l] = float(shk[l * l + l] * q[l * BANDS]);
        for (int m = 1; m <= l; m++) {
            double s = shk[l * l + l + m] * q[l * BANDS + m];
            o[l * l + l + m] = float(s * re[m]);
            o[l * l + l - m] = float(s * im[m]);
        }
    }
}
#endif

void store_coeff(uint c, uint local, int j, vec3 o) {
    uint ob = local * uint(NC * 3);
    cache_sh[ob + 3u * uint(j) + 0u] = o.x;
    cache_sh[ob + 3u * uint(j) + 1u] = o.y;
    cache_sh[ob + 3u * uint(j) + 2u] = o.z;
    // The irradiance stages read only bands <= 2, at random caches: a compact copy that
    // is never windowed.
    if (j < 9) {
        sh9[27u * c + 3u * uint(j) + 0u] = o.x;
        sh9[27u * c + 3u * uint(j) + 1u] = o.y;
        sh9[27u * c + 3u * uint(j) + 2u] = o.z;
    }
}

// A texel cache from its surfel list, E = sum weight B in list order (tcpu_gather_texel_surfels),
// stored as lc_transport_texel_store: band 1 a cosine lobe about the normal, band 0 with one band.
void texel_from_surfels(uint c, uint local) {
    precise vec3 e = vec3(0.0);
    for (uint k = texel_first[c]; k < texel_first[c + 1u]; k++) {
        SurfelWeight w = texel_surfels[k];
        uint b = 3u * w.surfel;
        precise vec3 add = w.weight * vec3(radiosity[b], radiosity[b + 1u], radiosity[b + 2u]);
        e += add;
    }
    for (int j = 0; j < NC; j++) store_coeff(c, local, j, vec3(0.0));
#if BANDS < 2
    store_coeff(c, local, 0, e * (1.0 / (2.0 * 3.14159265358979323846 * 0.282094791774)));
#else
    vec3 n = vec3(caches[c].nx, caches[c].ny, caches[c].nz);
    store_coeff(c, local, 1, e * (0.488602511903 * n.y));
    store_coeff(c, local, 2, e * (0.488602511903 * n.z));
    store_coeff(c, local, 3, e * (0.488602511903 * n.x));
#endif
}

void main() {
    uint idx = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x;
    if (idx >= u_count) return;
    uint c = u_use_list != 0u ? list[idx] : u_base + idx;
    uint local = c - u_base;
    if (u_texel_surfels != 0 && c < u_n_texel) {
        texel_from_surfels(c, local);
        return;
    }
    precise float acc0[NC], acc1[NC], acc2[NC];
    for (int j = 0; j < NC; j++) {
        acc0[j] = 0.0;
        acc1[j] = 0.0;
        acc2[j] = 0.0;
    }
    uint used = caches[c].link_count;
    int nc_here = (caches[c].flags & 1u) != 0u ? min(u_texel_nc, NC) : NC; // 1 = LC_CACHE_TEXEL
    bool grid_row = u_grid_rows != 0u && c >= u_n_texel;
    for (uint k = 0u; k < used; k++) {
        Link lk = grid_row ? grid_links[k * u_grid_rows + (c - u_n_texel)] : links[k * u_window + local];
        vec3 d = oct_decode(lk.dir_cone);
        float y[NC];
        sh_eval(d.x, d.y, d.z, y);
        uint hb = (lk.dir_cone >> 24) * 8u;
        float f = lk.factor;
        precise float p0 = flux[3u * lk.node + 0u] * f;
        precise float p1 = flux[3u * lk.node + 1u] * f;
        precise float p2 = flux[3u * lk.node + 2u] * f;
        for (int j = 0; j < NC; j++) {
            if (j >= nc_here) break;
            precise float w = cone[hb + uint(BAND_OF[j])] * y[j];
            acc0[j] += w * p0;
            if (j < NCC) {
                acc1[j] += w * p1;
                acc2[j] += w * p2;
            }
        }
    }
    // Band 0 of a band-1-only texel cache is zero, as the CPU backend's. (Cleared here, not
    // skipped in the loop: a variable start index keeps the accumulators out of registers.)
    if (u_texel_band1 != 0 && (caches[c].flags & 1u) != 0u) {
        acc0[0] = 0.0;
        acc1[0] = 0.0;
        acc2[0] = 0.0;
    }
    for (int j = 0; j < NC; j++) {
        float a = acc0[j], b = acc1[j], g = acc2[j];
        precise vec3 o;
#if CHROMA
        // Y, Co, Cg -> RGB (Malvar-Sullivan YCoCg-R, linear), as tcpu_gather_range.
        precise float tt = a - g;
        o = vec3(tt + b, a + g, tt - b);
#else
        o = vec3(a, b, g);
#endif
        store_coeff(c, local, j, o);
    }
}
