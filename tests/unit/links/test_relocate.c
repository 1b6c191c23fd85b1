/* relocate: caches buried in geometry move out into free space, caches in the open stay,
 * a grid cache that cannot get out is flagged inside, results do not depend on threads. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/relocate.h"
#include "bake/rt.h"
#include "check.h"
#include "util/parallel.h"
#include "util/vec.h"

typedef struct {
    lc_mesh mesh;
    uint32_t cap_v, cap_t;
} world;

static void world_free(world *w) {
    free(w->mesh.position);
    free(w->mesh.normal);
    free(w->mesh.index);
    free(w->mesh.material);
    memset(w, 0, sizeof *w);
}

static void frame(lc_vec3 n, lc_vec3 *t, lc_vec3 *b) {
    lc_v3_basis(n, t, b);
    if (lc_v3_dot(lc_v3_cross(*t, *b), n) < 0) {
        lc_vec3 x = *t;
        *t = *b;
        *b = x;
    }
}

/* Rectangle centred at c facing n (front side = n), size su x sv along the frame axes. */
static void add_quad(world *w, lc_vec3 c, lc_vec3 n, float su, float sv) {
    lc_vec3 t, b;
    frame(n, &t, &b);
    lc_mesh *m = &w->mesh;
    if (m->n_vertices + 4 > w->cap_v) {
        w->cap_v = (m->n_vertices + 4) * 2;
        m->position = realloc(m->position, (size_t)w->cap_v * 3 * sizeof(float));
        m->normal = realloc(m->normal, (size_t)w->cap_v * 3 * sizeof(float));
    }
    if (m->n_triangles + 2 > w->cap_t) {
        w->cap_t = (m->n_triangles + 2) * 2;
        m->index = realloc(m->index, (size_t)w->cap_t * 3 * sizeof(uint32_t));
        m->material = realloc(m->material, (size_t)w->cap_t * sizeof(uint32_t));
    }
    uint32_t base = m->n_vertices;
    const float cu[4] = {-0.5f, 0.5f, 0.5f, -0.5f}, cv[4] = {-0.5f, -0.5f, 0.5f, 0.5f};
    for (int k = 0; k < 4; k++) {
        lc_vec3 p = lc_v3_add(c, lc_v3_add(lc_v3_scale(t, cu[k] * su), lc_v3_scale(b, cv[k] * sv)));
        lc_v3_store(&m->position[3 * m->n_vertices], p);
        lc_v3_store(&m->normal[3 * m->n_vertices], n);
        m->n_vertices++;
    }
    uint32_t *ix = &m->index[3 * m->n_triangles];
    ix[0] = base, ix[1] = base + 1, ix[2] = base + 2;
    ix[3] = base, ix[4] = base + 2, ix[5] = base + 3;
    m->material[m->n_triangles] = m->material[m->n_triangles + 1] = 0;
    m->n_triangles += 2;
}

/* Solid box [lo, hi] with outward-facing walls. The quad frame may swap u/v, so each wall is
 * sized by the extents of the two axes it spans (a square-agnostic fit below). */
static void add_box(world *w, lc_vec3 lo, lc_vec3 hi) {
    float l[3] = {lo.x, lo.y, lo.z}, h[3] = {hi.x, hi.y, hi.z};
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++) {
            float c[3], n[3] = {0, 0, 0};
            for (int a = 0; a < 3; a++) c[a] = 0.5f * (l[a] + h[a]);
            c[axis] = side ? h[axis] : l[axis];
            n[axis] = side ? 1.0f : -1.0f;
            lc_vec3 nn = lc_v3_load(n), t, b;
            frame(nn, &t, &b);
            /* Extent along t and b: the frame of an axis normal is axis-aligned. */
            float ext[3] = {h[0] - l[0], h[1] - l[1], h[2] - l[2]};
            float su = fabsf(t.x) * ext[0] + fabsf(t.y) * ext[1] + fabsf(t.z) * ext[2];
            float sv = fabsf(b.x) * ext[0] + fabsf(b.y) * ext[1] + fabsf(b.z) * ext[2];
            add_quad(w, lc_v3_load(c), nn, su, sv);
        }
}

static int in_box(const float p[3], lc_vec3 lo, lc_vec3 hi) {
    return p[0] > lo.x && p[0] < hi.x && p[1] > lo.y && p[1] < hi.y && p[2] > lo.z && p[2] < hi.z;
}

static lc_lcb_cache make_cache(lc_vec3 p, lc_vec3 n, uint32_t flags) {
    lc_lcb_cache c;
    memset(&c, 0, sizeof c);
    lc_v3_store(c.position, p);
    lc_v3_store(c.normal, n);
    c.flags = flags;
    return c;
}

static const lc_relocate_params params = {
    .rays = 64, .texel_fraction = 0.6, .grid_fraction = 0.8, .offset = 0.01, .seed = 11, .threads = 0};

static void test_buried_texel(void) {
    world w = {0};
    /* An open floor (a large quad facing up) with a thick box standing on it. */
    add_quad(&w, lc_v3(0, 0, 0), lc_v3(0, 1, 0), 20, 20);
    lc_vec3 lo = lc_v3(-1, 0, -1), hi = lc_v3(1, 0.5f, 1);
    add_box(&w, lo, hi);
    char err[256];
    lc_rt *rt = lc_rt_create(&w.mesh, 2, err, sizeof err);
    CHECK(rt != NULL, "rt: %s", err);
    if (!rt) return;
    lc_lcb_cache caches[4] = {
        /* floor texel under the box: buried, its hemisphere sees the box from inside */
        make_cache(lc_v3(0.2f, 0, 0.1f), lc_v3(0, 1, 0), LC_CACHE_TEXEL),
        /* a texel inside the wall just below the top face */
        make_cache(lc_v3(-0.3f, 0.45f, 0.4f), lc_v3(0, 1, 0), LC_CACHE_TEXEL),
        /* open floor, far from the box: stays */
        make_cache(lc_v3(5, 0, 5), lc_v3(0, 1, 0), LC_CACHE_TEXEL),
        /* open floor right next to the box: sees the box's front faces, stays */
        make_cache(lc_v3(1.05f, 0, 0), lc_v3(0, 1, 0), LC_CACHE_TEXEL),
    };
    lc_lcb_cache orig[4];
    memcpy(orig, caches, sizeof caches);
    lc_relocate_stats st;
    lc_relocate_caches(rt, caches, 4, &params, &st);
    for (int i = 0; i < 2; i++) {
        fprintf(stderr, "buried texel %d: (%.3f %.3f %.3f) -> (%.3f %.3f %.3f) flags %x\n", i,
                (double)orig[i].position[0], (double)orig[i].position[1], (double)orig[i].position[2],
                (double)caches[i].position[0], (double)caches[i].position[1], (double)caches[i].position[2],
                caches[i].flags);
        CHECK(caches[i].flags & LC_CACHE_MOVED, "buried texel %d moved", i);
        CHECK(!in_box(caches[i].position, lo, hi), "buried texel %d ends outside the box", i);
        CHECK(!(caches[i].flags & LC_CACHE_INSIDE), "texel caches are never flagged inside");
    }
    /* The nearest way out of cache 1 is up through the top face. */
    CHECK(caches[1].position[1] > 0.5f && caches[1].position[1] < 0.5f + 0.05f, "cache 1 y %.4f",
          (double)caches[1].position[1]);
    for (int i = 2; i < 4; i++) {
        CHECK(caches[i].flags == LC_CACHE_TEXEL, "open texel %d keeps its flags (%x)", i, caches[i].flags);
        CHECK(memcmp(caches[i].position, orig[i].position, sizeof orig[i].position) == 0, "open texel %d stays", i);
    }
    CHECK(st.moved == 2 && st.inside == 0, "stats moved %u inside %u", st.moved, st.inside);
    /* Grid clearance leaves texel caches where the plain move puts them. */
    lc_lcb_cache cleared[4];
    memcpy(cleared, orig, sizeof orig);
    lc_relocate_params clear = params;
    clear.grid_clearance = 0.3;
    lc_relocate_caches(rt, cleared, 4, &clear, NULL);
    CHECK(memcmp(cleared, caches, sizeof caches) == 0, "grid clearance does not move texel caches");
    lc_rt_release(rt);
    world_free(&w);
}

static void test_grid_caches(void) {
    world w = {0};
    lc_vec3 lo = lc_v3(-1, -1, -1), hi = lc_v3(1, 1, 1);
    add_box(&w, lo, hi);                                                          /* solid box A */
    lc_vec3 lo2 = lc_v3(4.98f, -0.02f, -0.02f), hi2 = lc_v3(5.02f, 0.02f, 0.02f); /* tiny box inside box B */
    add_box(&w, lc_v3(3, -2, -2), lc_v3(7, 2, 2));                                /* solid box B */
    add_box(&w, lo2, hi2);
    char err[256];
    lc_rt *rt = lc_rt_create(&w.mesh, 2, err, sizeof err);
    CHECK(rt != NULL, "rt: %s", err);
    if (!rt) return;
    lc_vec3 zero = lc_v3(0, 0, 0);
    lc_lcb_cache caches[4] = {
        make_cache(lc_v3(0.1f, -0.6f, 0.2f), zero, LC_CACHE_GRID), /* inside A: moves out */
        make_cache(lc_v3(5, 0, 0), zero, LC_CACHE_GRID),           /* inside tiny box inside B: stuck */
        make_cache(lc_v3(0, 3, 0), zero, LC_CACHE_GRID),           /* free space above A: stays */
        make_cache(lc_v3(-20, 0, 0), zero, LC_CACHE_GRID),         /* nothing around: stays */
    };
    lc_lcb_cache orig[4];
    memcpy(orig, caches, sizeof caches);
    /* Offset 0.2: past the tiny box's face the box covers only a sliver of the sphere, so the
     * re-test sees box B from inside again. */
    lc_relocate_params far = params;
    far.offset = 0.2;
    lc_relocate_stats st;
    lc_relocate_caches(rt, caches, 4, &far, &st);
    fprintf(stderr, "grid 0: -> (%.3f %.3f %.3f) flags %x; grid 1 flags %x\n", (double)caches[0].position[0],
            (double)caches[0].position[1], (double)caches[0].position[2], caches[0].flags, caches[1].flags);
    CHECK(caches[0].flags == (LC_CACHE_GRID | LC_CACHE_MOVED), "grid 0 flags %x", caches[0].flags);
    CHECK(!in_box(caches[0].position, lo, hi), "grid 0 ends outside box A");
    /* Nearest face of A from (0.1, -0.6, 0.2) is the bottom (0.4 away). */
    CHECK(caches[0].position[1] < -1.0f && caches[0].position[1] > -1.25f, "grid 0 leaves through the bottom");
    CHECK(caches[1].flags == (LC_CACHE_GRID | LC_CACHE_INSIDE), "grid 1 flags %x", caches[1].flags);
    CHECK(memcmp(caches[1].position, orig[1].position, sizeof orig[1].position) == 0, "inside: position restored");
    for (int i = 2; i < 4; i++)
        CHECK(memcmp(&caches[i], &orig[i], sizeof orig[i]) == 0, "free grid cache %d untouched", i);
    CHECK(st.moved == 1 && st.inside == 1, "stats moved %u inside %u", st.moved, st.inside);

    /* Flagged caches are left alone on a second pass; the result is thread-independent. */
    lc_lcb_cache again[4];
    memcpy(again, caches, sizeof caches);
    lc_relocate_caches(rt, again, 4, &far, &st);
    CHECK(memcmp(&again[1], &caches[1], sizeof caches[1]) == 0, "inside cache left alone");
    enum { N = 300 };
    lc_lcb_cache *a = malloc(N * sizeof *a), *b = malloc(N * sizeof *b);
    for (int i = 0; i < N; i++) {
        float f = (float)i / N;
        a[i] = make_cache(lc_v3(-1.5f + 8 * f, sinf(37 * f) * 1.5f, cosf(23 * f) * 1.5f), zero, LC_CACHE_GRID);
        if (i % 3 == 0) {
            a[i].normal[1] = 1;
            a[i].flags = LC_CACHE_TEXEL;
        }
    }
    memcpy(b, a, N * sizeof *a);
    lc_relocate_params one = params, two = params;
    one.threads = 1;
    two.threads = 2;
    lc_relocate_caches(rt, a, N, &one, NULL);
    lc_relocate_caches(rt, b, N, &two, &st);
    CHECK(memcmp(a, b, N * sizeof *a) == 0, "relocation identical for 1 and 2 threads");
    fprintf(stderr, "determinism set: moved %u inside %u of %d\n", st.moved, st.inside, N);
    CHECK(st.moved > 0, "some of the determinism set moved");
    free(a);
    free(b);
    lc_rt_release(rt);
    world_free(&w);
}

/* A grid cache buried in a slab leaves through its top face, then keeps grid_clearance from
 * it along the face's normal, or half the free space when a ceiling is nearer. */
static void test_grid_clearance(void) {
    for (int ceiling = 0; ceiling < 2; ceiling++) {
        world w = {0};
        add_box(&w, lc_v3(-5, -1, -5), lc_v3(5, 0, 5));
        if (ceiling) add_quad(&w, lc_v3(0, 0.4f, 0), lc_v3(0, -1, 0), 20, 20);
        char err[256];
        lc_rt *rt = lc_rt_create(&w.mesh, 2, err, sizeof err);
        CHECK(rt != NULL, "rt: %s", err);
        if (!rt) return;
        const double clearances[2] = {0, 0.3};
        for (int k = 0; k < 2; k++) {
            lc_lcb_cache c = make_cache(lc_v3(0.3f, -0.1f, 0.2f), lc_v3(0, 0, 0), LC_CACHE_GRID);
            lc_relocate_params prm = params;
            prm.grid_clearance = clearances[k];
            lc_relocate_caches(rt, &c, 1, &prm, NULL);
            /* the top face is 0.1 away, the other faces 0.9 or more: out through the top, plus the offset */
            double want = params.offset + (k == 0 ? 0 : ceiling ? 0.5 * (0.4 - params.offset) : 0.3);
            fprintf(stderr, "grid clearance %.1f, ceiling %d: y %.4f (want %.4f)\n", clearances[k], ceiling,
                    (double)c.position[1], want);
            CHECK(c.flags == (LC_CACHE_GRID | LC_CACHE_MOVED), "clearance case flags %x", c.flags);
            CHECK(fabs(c.position[1] - want) < 0.004, "clearance %.1f ceiling %d: y %.4f, want %.4f", clearances[k],
                  ceiling, (double)c.position[1], want);
        }
        lc_rt_release(rt);
        world_free(&w);
    }
}

int main(void) {
    test_buried_texel();
    test_grid_caches();
    test_grid_clearance();
    CHECK_DONE();
}
