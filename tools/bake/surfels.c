/* surfels: equal-area surface samples (PIC section 4.2, see surfels.h).
 *
 * Placement: with a = total_area / N, triangles are walked in index order and triangle t
 * spawns floor(C_t / a) - floor(C_{t-1} / a) surfels, C_t being the running area sum — the
 * same as carrying the fractional remainder from triangle to triangle, so tiny triangles
 * accumulate until one of them spawns a surfel (which then lies in that triangle). The last
 * triangle with area is forced to end the walk at exactly N. Positions come from a 2D Halton
 * sequence (bases 2, 3) indexed by the surfel number (consecutive points within a triangle
 * are stratified), offset and rotated per seed, warped to uniform barycentrics.
 *
 * Relaxation (Jacobi, so deterministic and parallel): each surfel is pushed away from its
 * up to 6 nearest neighbours within r = 2 sqrt(a / pi) whose normals agree (dot > 0.5),
 * moved on its triangle's plane in barycentric coordinates and clamped to the triangle. */
#include "bake/surfels.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "util/parallel.h"
#include "util/rng.h"
#include "util/vec.h"

#define SURFELS_KNN 6
#define SURFELS_NORMAL_AGREE 0.5f
#define SURFELS_STEP 0.5f /* damping of the per-iteration displacement */

typedef struct {
    const lc_scene *scene;
    lc_lcb_surfel *s;
    const uint32_t *tri;
    float *bary;      /* 2 per surfel: current (b1, b2) */
    float *bary_next; /* Jacobi target */
    uint64_t halton_offset;
    float rot[2]; /* Cranley-Patterson rotation */
    float area;
    /* neighbour grid */
    float radius, inv_cell, origin[3];
    uint32_t mask;        /* hash table size - 1 */
    uint32_t *cell_start; /* mask + 2 entries */
    uint32_t *cell_items; /* surfel indices grouped by bucket */
} surfels_ctx;

static uint32_t surfels_material(const lc_mesh *m, uint32_t tri) { return m->material ? m->material[tri] : 0; }

void lc_surfel_init(const lc_scene *scene, uint32_t tri, float b1, float b2, float area, lc_lcb_surfel *out) {
    memset(out, 0, sizeof *out);
    lc_mesh_interpolate(&scene->mesh, tri, b1, b2, out->position, out->normal);
    lc_scene_albedo(scene, tri, b1, b2, out->albedo);
    lc_scene_emission(scene, tri, out->emission);
    out->area = area;
    out->material = surfels_material(&scene->mesh, tri);
    out->cache = LC_NONE;
}

void lc_surfel_halton_bary(uint64_t i, const float rot[2], float *b1, float *b2) {
    double u = lc_halton(i, 2) + rot[0], v = lc_halton(i, 3) + rot[1];
    u -= floor(u);
    v -= floor(v);
    /* uniform on the triangle: b0 = 1 - sqrt(u), b1 = sqrt(u)(1 - v), b2 = sqrt(u) v */
    double su = sqrt(u);
    *b1 = (float)(su * (1 - v));
    *b2 = (float)(su * v);
}

/* Moves surfel i to its current barycentrics (position, normal, albedo). */
static void surfels_place(const surfels_ctx *c, uint32_t i) {
    lc_lcb_surfel *x = &c->s[i];
    float b1 = c->bary[2 * (size_t)i], b2 = c->bary[2 * (size_t)i + 1];
    lc_mesh_interpolate(&c->scene->mesh, c->tri[i], b1, b2, x->position, x->normal);
    lc_scene_albedo(c->scene, c->tri[i], b1, b2, x->albedo);
}

static void surfels_init_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    surfels_ctx *c = ctx;
    for (size_t i = begin; i < end; i++) {
        lc_surfel_halton_bary(i + c->halton_offset, c->rot, &c->bary[2 * i], &c->bary[2 * i + 1]);
        lc_surfel_init(c->scene, c->tri[i], c->bary[2 * i], c->bary[2 * i + 1], c->area, &c->s[i]);
    }
}

/* --- neighbour grid (hashed uniform grid, cell = search radius) ---------------------------- */

static void surfels_cell(const surfels_ctx *c, const float p[3], int64_t q[3]) {
    for (int k = 0; k < 3; k++) q[k] = (int64_t)floorf((p[k] - c->origin[k]) * c->inv_cell);
}

static uint32_t surfels_bucket(const surfels_ctx *c, int64_t x, int64_t y, int64_t z) {
    uint64_t h = lc_mix64((uint64_t)x * 0x9E3779B1ull ^ (uint64_t)y * 0x85EBCA77ull ^ (uint64_t)z * 0xC2B2AE3Dull);
    return (uint32_t)h & c->mask;
}

static void surfels_grid_build(surfels_ctx *c, uint32_t n) {
    memset(c->cell_start, 0, sizeof *c->cell_start * ((size_t)c->mask + 2));
    for (uint32_t i = 0; i < n; i++) {
        int64_t q[3];
        surfels_cell(c, c->s[i].position, q);
        c->cell_start[surfels_bucket(c, q[0], q[1], q[2]) + 1]++;
    }
    for (uint32_t b = 0; b <= c->mask; b++) c->cell_start[b + 1] += c->cell_start[b];
    /* counting sort, stable in surfel order (deterministic) */
    uint32_t *fill = c->cell_start; /* reuse: advance starts, then shift back */
    for (uint32_t i = 0; i < n; i++) {
        int64_t q[3];
        surfels_cell(c, c->s[i].position, q);
        c->cell_items[fill[surfels_bucket(c, q[0], q[1], q[2])]++] = i;
    }
    for (uint32_t b = c->mask + 1; b > 0; b--) c->cell_start[b] = c->cell_start[b - 1];
    c->cell_start[0] = 0;
}

static void surfels_relax_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    surfels_ctx *c = ctx;
    const lc_mesh *m = &c->scene->mesh;
    float r = c->radius, r2 = r * r;
    for (size_t i = begin; i < end; i++) {
        const lc_lcb_surfel *x = &c->s[i];
        lc_vec3 p = lc_v3_load(x->position), nx = lc_v3_load(x->normal);
        c->bary_next[2 * i] = c->bary[2 * i];
        c->bary_next[2 * i + 1] = c->bary[2 * i + 1];
        int64_t q[3];
        surfels_cell(c, x->position, q);
        uint32_t buckets[27], nb = 0;
        for (int dz = -1; dz <= 1; dz++)
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) {
                    uint32_t b = surfels_bucket(c, q[0] + dx, q[1] + dy, q[2] + dz), k = 0;
                    while (k < nb && buckets[k] != b) k++; /* hash collisions: scan each bucket once */
                    if (k == nb) buckets[nb++] = b;
                }
        float best_d2[SURFELS_KNN];
        uint32_t best_j[SURFELS_KNN], nbest = 0;
        for (uint32_t bi = 0; bi < nb; bi++) {
            for (uint32_t k = c->cell_start[buckets[bi]]; k < c->cell_start[buckets[bi] + 1]; k++) {
                uint32_t j = c->cell_items[k];
                if (j == i) continue;
                lc_vec3 d = lc_v3_sub(p, lc_v3_load(c->s[j].position));
                float d2 = lc_v3_dot(d, d);
                if (d2 >= r2 || lc_v3_dot(nx, lc_v3_load(c->s[j].normal)) <= SURFELS_NORMAL_AGREE) continue;
                /* insert into the sorted k-nearest list; (distance, index) keeps ties ordered */
                uint32_t pos = nbest;
                while (pos > 0 && (best_d2[pos - 1] > d2 || (best_d2[pos - 1] == d2 && best_j[pos - 1] > j))) pos--;
                if (pos >= SURFELS_KNN) continue;
                uint32_t last = nbest < SURFELS_KNN ? nbest : SURFELS_KNN - 1;
                for (uint32_t s = last; s > pos; s--) {
                    best_d2[s] = best_d2[s - 1];
                    best_j[s] = best_j[s - 1];
                }
                best_d2[pos] = d2;
                best_j[pos] = j;
                if (nbest < SURFELS_KNN) nbest++;
            }
        }
        if (nbest == 0) continue;
        /* push: each neighbour closer than r contributes (r - d) along the separation */
        lc_vec3 push = lc_v3(0, 0, 0);
        for (uint32_t k = 0; k < nbest; k++) {
            lc_vec3 d = lc_v3_sub(p, lc_v3_load(c->s[best_j[k]].position));
            float dist = sqrtf(best_d2[k]);
            if (dist <= 1e-12f * r) continue; /* coincident: no direction; the other pushes */
            push = lc_v3_add(push, lc_v3_scale(d, (r - dist) / dist));
        }
        push = lc_v3_scale(push, SURFELS_STEP / (float)nbest);
        /* at most half the radius per iteration: no jumping over neighbours */
        float pl = lc_v3_len(push);
        if (pl > 0.5f * r) push = lc_v3_scale(push, 0.5f * r / pl);
        /* displacement in barycentrics of the source triangle (least squares = tangent plane) */
        const uint32_t *ix = m->index + 3 * (size_t)c->tri[i];
        lc_vec3 v0 = lc_v3_load(m->position + 3 * (size_t)ix[0]);
        lc_vec3 e1 = lc_v3_sub(lc_v3_load(m->position + 3 * (size_t)ix[1]), v0);
        lc_vec3 e2 = lc_v3_sub(lc_v3_load(m->position + 3 * (size_t)ix[2]), v0);
        double g11 = lc_v3_dot(e1, e1), g12 = lc_v3_dot(e1, e2), g22 = lc_v3_dot(e2, e2);
        double det = g11 * g22 - g12 * g12;
        if (!(det > 1e-20 * g11 * g22)) continue; /* degenerate sliver: stay put */
        double r1 = lc_v3_dot(push, e1), r2b = lc_v3_dot(push, e2);
        double db1 = (g22 * r1 - g12 * r2b) / det, db2 = (g11 * r2b - g12 * r1) / det;
        double b1 = c->bary[2 * i] + db1, b2 = c->bary[2 * i + 1] + db2;
        if (b1 < 0) b1 = 0;
        if (b2 < 0) b2 = 0;
        if (b1 + b2 > 1) {
            double s = b1 + b2;
            b1 /= s;
            b2 /= s;
        }
        c->bary_next[2 * i] = (float)b1;
        c->bary_next[2 * i + 1] = (float)b2;
    }
}

static void surfels_replace_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    surfels_ctx *c = ctx;
    for (size_t i = begin; i < end; i++) surfels_place(c, (uint32_t)i);
}

int lc_surfels_generate(const lc_scene *scene, const lc_surfel_params *params, lc_lcb_surfel **out,
                        uint32_t **triangle_out, uint32_t *n_out, char *err, size_t errlen) {
    lc_lcb_surfel *s = NULL;
    uint32_t *tri = NULL;
    float *bary = NULL, *bary_next = NULL;
    uint32_t *cell_start = NULL, *cell_items = NULL;
    if (out) *out = NULL;
    if (triangle_out) *triangle_out = NULL;
    if (n_out) *n_out = 0;
    if (!scene || !params || !out || !n_out) {
        lc_set_err(err, errlen, "surfels: %s is NULL", !scene ? "scene" : !params ? "params" : !out ? "out" : "n_out");
        return -1;
    }
    const lc_mesh *m = &scene->mesh;
    uint32_t n = params->target_count;
    if (n == 0) {
        lc_set_err(err, errlen, "surfels: params->target_count must be > 0");
        return -1;
    }
    if (m->n_triangles == 0 || !m->index || !m->position) {
        lc_set_err(err, errlen, "surfels: scene mesh has no triangles");
        return -1;
    }
    double total = 0;
    uint32_t last_tri = LC_NONE;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        double a = lc_mesh_triangle_area(m, t);
        if (isfinite(a) && a > 0) {
            total += a;
            last_tri = t;
        }
    }
    if (!(total > 0) || !isfinite(total)) {
        lc_set_err(err, errlen, "surfels: scene surface area is %g (need a positive finite area)", total);
        return -1;
    }
    s = calloc(n, sizeof *s);
    tri = malloc(sizeof *tri * n);
    bary = malloc(sizeof *bary * 2 * (size_t)n);
    if (!s || !tri || !bary) {
        lc_set_err(err, errlen, "surfels: out of memory for %u surfels", n);
        goto err;
    }

    /* The walk: running sum in surfel units; the carry lives in the fractional part. */
    double a = total / n, cum = 0;
    uint32_t spawned = 0;
    for (uint32_t t = 0; t < m->n_triangles && spawned < n; t++) {
        double at = lc_mesh_triangle_area(m, t);
        if (!(isfinite(at) && at > 0)) continue;
        cum += at;
        double f = floor(cum / a);
        uint32_t upto = t == last_tri ? n : f >= n ? n : (uint32_t)f;
        while (spawned < upto) tri[spawned++] = t;
    }
    if (spawned != n) { /* unreachable: the last triangle with area closes the walk */
        lc_set_err(err, errlen, "surfels: internal error (%u of %u surfels spawned)", spawned, n);
        goto err;
    }

    surfels_ctx c = {.scene = scene, .s = s, .tri = tri, .bary = bary, .area = (float)a};
    lc_rng rng = lc_rng_seed(params->seed, 0x5u);
    c.halton_offset = lc_rng_next(&rng) & 0xFFFFFu; /* <= 1M: radical inverses stay exact */
    c.rot[0] = lc_rng_float(&rng);
    c.rot[1] = lc_rng_float(&rng);
    lc_parallel_for(params->threads, n, 1024, surfels_init_range, &c);

    if (params->relax_iterations > 0 && n > 1) {
        bary_next = malloc(sizeof *bary_next * 2 * (size_t)n);
        uint32_t size = 1;
        while (size < n && size < 0x80000000u) size <<= 1;
        cell_start = malloc(sizeof *cell_start * ((size_t)size + 1));
        cell_items = malloc(sizeof *cell_items * n);
        if (!bary_next || !cell_start || !cell_items) {
            lc_set_err(err, errlen, "surfels: out of memory for relaxing %u surfels", n);
            goto err;
        }
        c.mask = size - 1;
        c.cell_start = cell_start;
        c.cell_items = cell_items;
        c.radius = 2.0f * sqrtf(c.area / (float)M_PI);
        c.inv_cell = 1.0f / c.radius;
        memcpy(c.origin, scene->bounds_min, sizeof c.origin);
        for (uint32_t it = 0; it < params->relax_iterations; it++) {
            surfels_grid_build(&c, n);
            c.bary_next = bary_next;
            lc_parallel_for(params->threads, n, 1024, surfels_relax_range, &c);
            float *swap = c.bary;
            c.bary = bary_next;
            bary_next = swap;
            lc_parallel_for(params->threads, n, 1024, surfels_replace_range, &c);
        }
        bary = c.bary; /* whichever buffer is current; the other is bary_next */
    }

    free(bary);
    free(bary_next);
    free(cell_start);
    free(cell_items);
    *out = s;
    if (triangle_out) *triangle_out = tri;
    else free(tri);
    *n_out = n;
    return 0;
err:
    free(s);
    free(tri);
    free(bary);
    free(bary_next);
    free(cell_start);
    free(cell_items);
    return -1;
}
