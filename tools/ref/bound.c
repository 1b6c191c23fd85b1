/* The lossless-transport bound for lucent-ref fidelity (see lc_links_gather_bound). */
#include <stdlib.h>

#include "bake/links.h"
#include "bake/rt.h"
#include "ref/ref.h"
#include "util/log.h"

int lc_ref_gather_bound(const lc_lcb *bake, const float *radiosity, uint32_t probe_rays, uint64_t seed, int threads,
                        float *lightmap, char *err, size_t errlen) {
    const lc_lcb_view *v = lc_lcb_get(bake);
    int rc = -1;
    lc_rt *rt = NULL;
    lc_mesh mesh = {.n_vertices = v->n_vertices, .n_triangles = v->n_triangles};
    mesh.position = malloc((size_t)v->n_vertices * 3 * sizeof(float) + 1);
    mesh.index = malloc((size_t)v->n_triangles * 3 * sizeof(uint32_t) + 1);
    float *cache_e = malloc((size_t)v->n_caches * 3 * sizeof(float) + 1);
    if (!mesh.position || !mesh.index || !cache_e) {
        lc_set_err(err, errlen, "out of memory for the gather bound (%u triangles, %u caches)", v->n_triangles,
                   v->n_caches);
        goto done;
    }
    for (uint32_t i = 0; i < v->n_vertices; i++)
        for (int k = 0; k < 3; k++) mesh.position[3 * i + k] = v->vertices[i].position[k];
    for (uint32_t i = 0; i < v->n_triangles; i++)
        for (int k = 0; k < 3; k++) mesh.index[3 * i + k] = v->triangles[i].v[k];
    rt = lc_rt_create(&mesh, threads, err, errlen);
    if (!rt) goto done;
    if (lc_links_gather_bound(rt, v->surfels, v->n_surfels, v->caches, v->n_caches, probe_rays, seed, threads,
                              radiosity, cache_e) != 0) {
        lc_set_err(err, errlen, "the gather bound failed (see the log)");
        goto done;
    }
    for (size_t t = 0; t < (size_t)v->lightmap_width * v->lightmap_height; t++) {
        uint32_t c = v->lightmap[t]; /* texels read their cache, as the engine's do */
        for (int k = 0; k < 3; k++) lightmap[3 * t + k] = c == LC_NONE ? 0.0f : cache_e[3 * (size_t)c + k];
    }
    rc = 0;
done:
    lc_rt_release(rt);
    free(mesh.position);
    free(mesh.index);
    free(cache_e);
    return rc;
}
