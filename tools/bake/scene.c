/* scene: in-memory scene helpers shared by every bake stage (geometry queries and material
 * lookups). Import lives in import.c. */
#include "bake/scene.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/vec.h"

void lc_mesh_release(lc_mesh *mesh) {
    free(mesh->position);
    free(mesh->normal);
    free(mesh->uv0);
    free(mesh->uv1);
    free(mesh->index);
    free(mesh->material);
    memset(mesh, 0, sizeof *mesh);
}

void lc_scene_release(lc_scene *scene) {
    if (!scene) return;
    lc_mesh_release(&scene->mesh);
    for (uint32_t i = 0; i < scene->n_textures; i++) free(scene->textures[i].rgb);
    free(scene->textures);
    free(scene->materials);
    free(scene->lights);
    memset(scene, 0, sizeof *scene);
}

void lc_scene_update_bounds(lc_scene *scene) {
    const lc_mesh *m = &scene->mesh;
    lc_vec3 lo = lc_v3(INFINITY, INFINITY, INFINITY), hi = lc_v3(-INFINITY, -INFINITY, -INFINITY);
    for (uint32_t i = 0; i < m->n_vertices; i++) {
        lc_vec3 p = lc_v3_load(m->position + 3 * i);
        lo = lc_v3_min(lo, p);
        hi = lc_v3_max(hi, p);
    }
    if (m->n_vertices == 0) lo = hi = lc_v3(0, 0, 0);
    lc_v3_store(scene->bounds_min, lo);
    lc_v3_store(scene->bounds_max, hi);
}

static void mesh_corners(const lc_mesh *m, uint32_t tri, lc_vec3 *a, lc_vec3 *b, lc_vec3 *c) {
    const uint32_t *ix = m->index + 3 * (size_t)tri;
    *a = lc_v3_load(m->position + 3 * (size_t)ix[0]);
    *b = lc_v3_load(m->position + 3 * (size_t)ix[1]);
    *c = lc_v3_load(m->position + 3 * (size_t)ix[2]);
}

double lc_mesh_triangle_area(const lc_mesh *m, uint32_t tri) {
    lc_vec3 a, b, c;
    mesh_corners(m, tri, &a, &b, &c);
    /* double precision: tiny triangles far from the origin lose too much in float */
    double e1[3] = {(double)b.x - a.x, (double)b.y - a.y, (double)b.z - a.z};
    double e2[3] = {(double)c.x - a.x, (double)c.y - a.y, (double)c.z - a.z};
    double cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2], cz = e1[0] * e2[1] - e1[1] * e2[0];
    return 0.5 * sqrt(cx * cx + cy * cy + cz * cz);
}

void lc_mesh_triangle_normal(const lc_mesh *m, uint32_t tri, float out[3]) {
    lc_vec3 a, b, c;
    mesh_corners(m, tri, &a, &b, &c);
    lc_v3_store(out, lc_v3_norm(lc_v3_cross(lc_v3_sub(b, a), lc_v3_sub(c, a))));
}

void lc_mesh_interpolate(const lc_mesh *m, uint32_t tri, float b1, float b2, float pos[3], float nrm[3]) {
    const uint32_t *ix = m->index + 3 * (size_t)tri;
    float b0 = 1.0f - b1 - b2;
    lc_vec3 p = lc_v3_add(lc_v3_add(lc_v3_scale(lc_v3_load(m->position + 3 * (size_t)ix[0]), b0),
                                    lc_v3_scale(lc_v3_load(m->position + 3 * (size_t)ix[1]), b1)),
                          lc_v3_scale(lc_v3_load(m->position + 3 * (size_t)ix[2]), b2));
    if (pos) lc_v3_store(pos, p);
    if (!nrm) return;
    lc_vec3 n = lc_v3(0, 0, 0);
    if (m->normal)
        n = lc_v3_add(lc_v3_add(lc_v3_scale(lc_v3_load(m->normal + 3 * (size_t)ix[0]), b0),
                                lc_v3_scale(lc_v3_load(m->normal + 3 * (size_t)ix[1]), b1)),
                      lc_v3_scale(lc_v3_load(m->normal + 3 * (size_t)ix[2]), b2));
    float geo[3];
    lc_mesh_triangle_normal(m, tri, geo);
    lc_vec3 g = lc_v3_load(geo);
    n = lc_v3_norm(n);
    /* Shading normals that disagree with the winding (or are missing) fall back to it. */
    if (lc_v3_dot(n, n) < 0.5f || lc_v3_dot(n, g) <= 0.0f) n = g;
    lc_v3_store(nrm, n);
}

double lc_mesh_total_area(const lc_mesh *m) {
    double sum = 0;
    for (uint32_t t = 0; t < m->n_triangles; t++) sum += lc_mesh_triangle_area(m, t);
    return sum;
}

static void texture_sample_bilinear(const lc_texture *tex, float u, float v, float out[3]) {
    /* uv0 is OpenGL convention (v up); image row 0 is the top. Repeat wrap. */
    float x = (u - floorf(u)) * (float)tex->width - 0.5f;
    float y = ((1.0f - v) - floorf(1.0f - v)) * (float)tex->height - 0.5f;
    float fx = floorf(x), fy = floorf(y);
    float tx = x - fx, ty = y - fy;
    int32_t w = (int32_t)tex->width, h = (int32_t)tex->height;
    int32_t x0 = ((int32_t)fx % w + w) % w, y0 = ((int32_t)fy % h + h) % h;
    int32_t x1 = (x0 + 1) % w, y1 = (y0 + 1) % h;
    const float *p00 = tex->rgb + 3 * ((size_t)y0 * w + x0), *p10 = tex->rgb + 3 * ((size_t)y0 * w + x1);
    const float *p01 = tex->rgb + 3 * ((size_t)y1 * w + x0), *p11 = tex->rgb + 3 * ((size_t)y1 * w + x1);
    for (int c = 0; c < 3; c++)
        out[c] = (p00[c] * (1 - tx) + p10[c] * tx) * (1 - ty) + (p01[c] * (1 - tx) + p11[c] * tx) * ty;
}

void lc_scene_albedo(const lc_scene *scene, uint32_t tri, float b1, float b2, float out[3]) {
    const lc_mesh *m = &scene->mesh;
    uint32_t mi = m->material ? m->material[tri] : 0;
    if (mi >= scene->n_materials) {
        out[0] = out[1] = out[2] = 0.8f; /* unreachable after import validation; a sane grey */
        return;
    }
    const lc_material *mat = &scene->materials[mi];
    memcpy(out, mat->base_color, sizeof(float) * 3);
    if (mat->base_texture >= 0 && (uint32_t)mat->base_texture < scene->n_textures && m->uv0) {
        const lc_texture *tex = &scene->textures[mat->base_texture];
        if (tex->rgb && tex->width && tex->height) {
            const uint32_t *ix = m->index + 3 * (size_t)tri;
            float b0 = 1.0f - b1 - b2;
            float u = m->uv0[2 * ix[0]] * b0 + m->uv0[2 * ix[1]] * b1 + m->uv0[2 * ix[2]] * b2;
            float v = m->uv0[2 * ix[0] + 1] * b0 + m->uv0[2 * ix[1] + 1] * b1 + m->uv0[2 * ix[2] + 1] * b2;
            float t[3];
            if (isfinite(u) && isfinite(v) && fabsf(u) < 1e6f && fabsf(v) < 1e6f) {
                texture_sample_bilinear(tex, u, v, t);
                for (int c = 0; c < 3; c++) out[c] *= t[c];
            }
        }
    }
    /* Energy conservation: an albedo >= 1 would make multi-bounce diverge. */
    for (int c = 0; c < 3; c++) out[c] = fminf(fmaxf(out[c], 0.0f), 0.99f);
}

void lc_scene_emission(const lc_scene *scene, uint32_t tri, float out[3]) {
    const lc_mesh *m = &scene->mesh;
    uint32_t mi = m->material ? m->material[tri] : 0;
    if (mi >= scene->n_materials) {
        out[0] = out[1] = out[2] = 0;
        return;
    }
    memcpy(out, scene->materials[mi].emission, sizeof(float) * 3);
}
