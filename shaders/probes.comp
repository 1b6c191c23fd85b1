#version 430 core
// probes: the probes solver's gather (engine/probes.h) on GL compute, the twin of lc_probes_gather.
// The host prepends PROBES_STAGE:
//   0 probe SH   (one invocation per probe and coefficient): lambda[p][ch][j] = sum over the
//                relight rays of ray_sh[k][j] * B[hit(p, k)] (ray_sh holds y_j(dir_k) 4/n_rays)
//   1 basis      (one invocation per cluster basis row, all clusters' rows in order): b = its
//                row of S V^T (bound as a window from float u_base) dotted with the cluster's
//                probes' lambda; rows of clusters not active this pass (lc_probes_active_clusters)
//                do nothing, in this stage and the next
//   2 receivers  (one invocation per receiver row): e = U row . b, written into the cache SH
//                (the full one, stride u_nc, bound whole, and the L2 copy) as probes_store: a
//                texel cache's cosine lobe about its normal, a grid cache's E_j / A_l. The host
//                clears both buffers first. Each row also adds its unseen rays (lcb.h PRUF/PRUS:
//                sum of weight x B over the surfels they hit; no entries when the bake has none).
layout(local_size_x = 64) in;

layout(location = 0) uniform uint u_count;

uint gid() { return gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x + gl_GlobalInvocationID.x; }

#if PROBES_STAGE == 0
layout(std430, binding = 0) readonly buffer Hits { uint hits[]; };        // [probe][ray]: surfel or ~0
layout(std430, binding = 1) readonly buffer RaySH { float ray_sh[]; };    // [ray][nc]
layout(std430, binding = 2) readonly buffer Radiosity { float rad[]; };   // [surfel][3]
layout(std430, binding = 3) writeonly buffer Lambda { float lambda[]; };  // [probe][3][nc]
layout(location = 1) uniform uint u_nc;
layout(location = 2) uniform uint u_rays;
void main() {
    uint i = gid();
    if (i >= u_count) return;
    uint p = i / u_nc, j = i % u_nc;
    vec3 acc = vec3(0.0);
    for (uint k = 0u; k < u_rays; k++) {
        uint s = hits[p * u_rays + k];
        if (s == 0xFFFFFFFFu) continue;
        acc += ray_sh[k * u_nc + j] * vec3(rad[3u * s], rad[3u * s + 1u], rad[3u * s + 2u]);
    }
    lambda[(p * 3u + 0u) * u_nc + j] = acc.x;
    lambda[(p * 3u + 1u) * u_nc + j] = acc.y;
    lambda[(p * 3u + 2u) * u_nc + j] = acc.z;
}

#elif PROBES_STAGE == 1
layout(std430, binding = 0) readonly buffer BasisRows { uvec4 rows[]; };  // basis offset, first probe, probes, cluster
layout(std430, binding = 1) readonly buffer Basis { float basis[]; };     // window from float u_base
layout(std430, binding = 2) readonly buffer Probes { uint probes[]; };    // the clusters' probes
layout(std430, binding = 3) readonly buffer Lambda { float lambda[]; };
layout(std430, binding = 4) writeonly buffer B { float b[]; };            // [basis row][3]
layout(std430, binding = 7) readonly buffer Active { uint cluster_on[]; };   // [cluster]
layout(location = 1) uniform uint u_nc;
layout(location = 2) uniform uint u_first; // this window's first basis row
layout(location = 3) uniform uint u_base;
void main() {
    uint i = gid();
    if (i >= u_count) return;
    uvec4 r = rows[u_first + i];
    if (cluster_on[r.w] == 0u) return;
    uint w0 = r.x - u_base;
    vec3 acc = vec3(0.0);
    for (uint q = 0u; q < r.z; q++) {
        uint lp = probes[r.y + q] * 3u * u_nc;
        uint wq = w0 + q * u_nc;
        for (uint j = 0u; j < u_nc; j++) {
            float w = basis[wq + j];
            acc += w * vec3(lambda[lp + j], lambda[lp + u_nc + j], lambda[lp + 2u * u_nc + j]);
        }
    }
    b[3u * (u_first + i)] = acc.x;
    b[3u * (u_first + i) + 1u] = acc.y;
    b[3u * (u_first + i) + 2u] = acc.z;
}

#else
struct Cache { float nx, ny, nz; uint flags; uint link_count; uint fresh, pad1, pad2; };
layout(std430, binding = 0) readonly buffer Rows { uvec4 rows[]; };      // cache, coeff, U offset, cluster
layout(std430, binding = 1) readonly buffer U { float u[]; };            // window from float u_base
layout(std430, binding = 2) readonly buffer B { float b[]; };
layout(std430, binding = 3) readonly buffer Caches { Cache caches[]; };
layout(std430, binding = 4) buffer CacheSH { float cache_sh[]; };         // [cache][u_nc][3], whole
layout(std430, binding = 5) buffer CacheSH9 { float sh9[]; };             // [cache][9][3]
layout(std430, binding = 6) readonly buffer RowB { uvec2 row_b[]; };     // rank, first basis row
layout(std430, binding = 7) readonly buffer Active { uint cluster_on[]; };   // [cluster]
layout(std430, binding = 8) readonly buffer UnseenFirst { uint unseen_first[]; }; // [row + 1]
layout(std430, binding = 9) readonly buffer Unseen { uvec2 unseen[]; };       // surfel, weight bits
layout(std430, binding = 10) readonly buffer Radiosity { float rad[]; };      // [surfel][3]
layout(location = 1) uniform uint u_nc;   // the cache SH's stride (bands^2)
layout(location = 2) uniform uint u_first;
layout(location = 3) uniform uint u_base;
const float A[3] = float[3](3.14159265358979, 2.09439510239320, 0.785398163397448);
void put(uint c, uint j, vec3 v) {
    for (uint k = 0u; k < 3u; k++) {
        cache_sh[c * u_nc * 3u + 3u * j + k] = v[k];
        if (j < 9u) sh9[27u * c + 3u * j + k] = v[k];
    }
}
void main() {
    uint i = gid();
    if (i >= u_count) return;
    uvec4 r = rows[u_first + i];
    if (cluster_on[r.w] == 0u) return;
    uvec2 rb = row_b[u_first + i];
    vec3 e = vec3(0.0);
    for (uint s = 0u; s < rb.x; s++) {
        uint bi = 3u * (rb.y + s);
        e += u[r.z - u_base + s] * vec3(b[bi], b[bi + 1u], b[bi + 2u]);
    }
    for (uint k = unseen_first[u_first + i]; k < unseen_first[u_first + i + 1u]; k++) {
        uvec2 un = unseen[k];
        e += uintBitsToFloat(un.y) * vec3(rad[3u * un.x], rad[3u * un.x + 1u], rad[3u * un.x + 2u]);
    }
    Cache c = caches[r.x];
    if ((c.flags & 1u) != 0u) {
        if (u_nc < 4u) {
            put(r.x, 0u, e * (1.0 / (2.0 * 3.14159265358979 * 0.282094791774)));
        } else {
            put(r.x, 1u, e * (0.488602511903 * c.ny));
            put(r.x, 2u, e * (0.488602511903 * c.nz));
            put(r.x, 3u, e * (0.488602511903 * c.nx));
        }
    } else if (r.y < u_nc) {
        put(r.x, r.y, e / A[r.y == 0u ? 0 : r.y < 4u ? 1 : 2]);
    }
}
#endif
