/* hierarchy: binary trees over surfels (see hierarchy.h).
 *
 * Both methods build an intermediate tree over "node ids": ids [0, n) are leaves (a leaf id
 * is a position in a method-specific surfel order, leaf_surfel[] maps it to the original
 * surfel), ids [n, 2n-1) are internal nodes with two children. A shared finishing pass turns
 * that into the file layout: DFS leaf order (surfels reordered), BFS node order, levels,
 * node attributes and bounding radii.
 *
 * AAC (Gu, He, Fatahalian, Blelloch 2013), AAC-HQ settings: delta = 20, epsilon = 0.1, so the
 * cluster-count reduction is f(x) = (delta^(0.5+eps) / 2) * x^(0.5-eps). Surfels are sorted
 * by 30-bit Morton code (tie: index), split on Morton bits down to groups < delta, and each
 * recursion level greedily merges the closest pair (PIC metric, cached distance matrix)
 * until f(size) clusters remain; the root level merges down to one. Internal node ids are
 * n - 1 + max(rep_a, rep_b) where a cluster's rep is its smallest sorted position: every
 * merge retires a distinct rep, so ids are unique without coordination and independent of
 * the thread that made them (the result does not depend on the thread count).
 *
 * Quality (lc_hierarchy_quality): area-weighted mean over internal nodes of the PIC metric
 * d(child0, child1). Weighting by area gives every tree level roughly the same total weight
 * (each level's areas sum to the scene area), so top merges count as much as the many
 * small bottom ones. */
#include "bake/hierarchy.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "util/parallel.h"

#define HIER_CN 0.1
#define HIER_CB 0.02
/* Emission term C_e: added to d(a, b) unless both clusters are pure and share an emission
 * class (each emissive material is its own class, all non-emissive surfels one class).
 * It exceeds the largest geometric distance (1 + 2 C_n + C_b), so inside every AAC merge
 * step an emitter joins a non-emitter (or another emitter's material) only after every
 * same-class pair: emitters get their own subtrees and links can point at lamp-only nodes.
 * Without it a lamp flush with a ceiling was clustered with the ceiling and no link ever
 * saw the lamp alone. Material boundaries in general (not only emitters) made Sponza worse
 * and are not used (docs/ARCHITECTURE.md, Decisions: "Emitters get their own subtrees"). */
#define HIER_CE 1.0
#define HIER_MIXED UINT32_MAX /* cluster of several classes */
#define HIER_NONEMISSIVE (UINT32_MAX - 1)
#define HIER_AAC_DELTA 20u
#define HIER_AAC_EPS 0.1
#define HIER_AAC_MIN_TASK 2048u
/* Exact radii cost sum(subtree sizes); above this average depth fall back to child bounds
 * for big nodes (only reachable with pathologically unbalanced trees). */
#define HIER_EXACT_DEPTH 256u
#define HIER_EXACT_BIG 1024u

typedef struct {
    uint32_t n;            /* leaves */
    uint32_t *child;       /* 2 per internal node, indexed by 2 * (id - n) */
    uint32_t *leaf_surfel; /* leaf id -> original surfel index */
    double *cen, *nrm;     /* 3 per node id: area-weighted centroid and mean normal */
    double *area;          /* per node id */
    uint32_t *cls;         /* per node id: emission class of every surfel below, or HIER_MIXED */
    double ce;             /* emission term weight (0: the plain PIC metric) */
    double inv_extent2;    /* 1 / (largest bounding-box side)^2 */
    int threads;           /* parallel-for workers (0 = all cores), the caller's setting */
} hier_tree;

static int hier_is_leaf(const hier_tree *t, uint32_t id) { return id < t->n; }

static void hier_leaf_attr(hier_tree *t, const lc_lcb_surfel *s, uint32_t id) {
    const lc_lcb_surfel *x = &s[t->leaf_surfel[id]];
    for (int k = 0; k < 3; k++) {
        t->cen[3 * (size_t)id + k] = x->position[k];
        t->nrm[3 * (size_t)id + k] = x->normal[k];
    }
    t->area[id] = x->area;
    int emissive = x->emission[0] > 0 || x->emission[1] > 0 || x->emission[2] > 0;
    t->cls[id] = !emissive ? HIER_NONEMISSIVE : x->material >= HIER_NONEMISSIVE ? 0 : x->material;
}

static void hier_merge_attr(hier_tree *t, uint32_t id, uint32_t a, uint32_t b) {
    double aa = t->area[a], ab = t->area[b], sum = aa + ab;
    /* zero-area inputs: fall back to equal weights so the centroid stays defined */
    double wa = sum > 0 ? aa / sum : 0.5, wb = sum > 0 ? ab / sum : 0.5;
    for (int k = 0; k < 3; k++) {
        t->cen[3 * (size_t)id + k] = wa * t->cen[3 * (size_t)a + k] + wb * t->cen[3 * (size_t)b + k];
        t->nrm[3 * (size_t)id + k] = wa * t->nrm[3 * (size_t)a + k] + wb * t->nrm[3 * (size_t)b + k];
    }
    t->area[id] = sum;
    t->cls[id] = t->cls[a] == t->cls[b] ? t->cls[a] : HIER_MIXED;
}

/* The PIC metric on raw cluster data (shared by the build and the quality measure). */
static double hier_metric(const double xa[3], const double na[3], double aa, const double xb[3], const double nb[3],
                          double ab, double inv_extent2) {
    double dx = xa[0] - xb[0], dy = xa[1] - xb[1], dz = xa[2] - xb[2];
    double la = sqrt(na[0] * na[0] + na[1] * na[1] + na[2] * na[2]);
    double lb = sqrt(nb[0] * nb[0] + nb[1] * nb[1] + nb[2] * nb[2]);
    double dot = la > 0 && lb > 0 ? (na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]) / (la * lb) : 0;
    double amax = aa > ab ? aa : ab;
    double bal = amax > 0 ? fabs(aa - ab) / amax : 0;
    return (dx * dx + dy * dy + dz * dz) * inv_extent2 + HIER_CN * (1 - dot) + HIER_CB * bal;
}

static double hier_dist(const hier_tree *t, uint32_t a, uint32_t b) {
    double d = hier_metric(t->cen + 3 * (size_t)a, t->nrm + 3 * (size_t)a, t->area[a], t->cen + 3 * (size_t)b,
                           t->nrm + 3 * (size_t)b, t->area[b], t->inv_extent2);
    if (t->cls[a] == HIER_MIXED || t->cls[a] != t->cls[b]) d += t->ce;
    return d;
}

/* --- finishing: DFS leaf order, BFS node order, attributes, radii ------------------------ */

typedef struct {
    const lc_lcb_surfel *s; /* reordered */
    lc_lcb_node *nodes;
    const uint32_t *skip; /* nonzero: radius done later from the children */
} hier_radius_ctx;

static float hier_round_up(double r) {
    float f = (float)r;
    if ((double)f < r) f = nextafterf(f, INFINITY);
    return f;
}

static void hier_radius_range(void *ctx, size_t begin, size_t end, int thread) {
    (void)thread;
    hier_radius_ctx *c = ctx;
    for (size_t i = begin; i < end; i++) {
        lc_lcb_node *nd = &c->nodes[i];
        if (c->skip && c->skip[i]) continue;
        double cx = nd->center[0], cy = nd->center[1], cz = nd->center[2], r = 0;
        for (uint32_t j = nd->first_surfel; j < nd->first_surfel + nd->surfel_count; j++) {
            const lc_lcb_surfel *x = &c->s[j];
            double dx = x->position[0] - cx, dy = x->position[1] - cy, dz = x->position[2] - cz;
            double d = sqrt(dx * dx + dy * dy + dz * dz) + sqrt(fmax(x->area, 0.0f) / M_PI);
            if (d > r) r = d;
        }
        nd->radius = hier_round_up(r);
    }
}

/* Pre-order DFS, left child first: a node's first leaf is the next free leaf slot when it is
 * visited, because its whole subtree follows it in pre-order. Fills pre (node ids in
 * pre-order), first (each node's first leaf slot) and perm (leaf slot -> surfel); stack is
 * scratch. -1 with err if the tree does not have its 2n - 1 nodes and n leaves. */
static int hier_preorder(const hier_tree *t, uint32_t root, uint32_t *pre, uint32_t *stack, uint32_t *first,
                         uint32_t *perm, char *err, size_t errlen) {
    uint32_t n = t->n, total = 2 * n - 1;
    uint32_t sp = 0, k = 0, pos = 0;
    stack[sp++] = root;
    while (sp > 0) {
        uint32_t id = stack[--sp];
        pre[k++] = id;
        first[id] = pos;
        if (hier_is_leaf(t, id)) {
            perm[pos++] = t->leaf_surfel[id];
        } else {
            stack[sp++] = t->child[2 * (size_t)(id - n) + 1];
            stack[sp++] = t->child[2 * (size_t)(id - n)];
        }
    }
    if (k != total || pos != n) {
        lc_set_err(err, errlen, "hierarchy: internal error (tree has %u nodes, %u leaves)", k, pos);
        return -1;
    }
    return 0;
}

/* Reverse pre-order visits children before parents: surfel counts and attributes bottom-up. */
static void hier_bottom_up(hier_tree *t, const lc_lcb_surfel *surfels, const uint32_t *pre, uint32_t *count) {
    uint32_t n = t->n, total = 2 * n - 1;
    for (uint32_t i = total; i-- > 0;) {
        uint32_t id = pre[i];
        if (hier_is_leaf(t, id)) {
            count[id] = 1;
            hier_leaf_attr(t, surfels, id);
        } else {
            uint32_t a = t->child[2 * (size_t)(id - n)], b = t->child[2 * (size_t)(id - n) + 1];
            count[id] = count[a] + count[b];
            hier_merge_attr(t, id, a, b);
        }
    }
}

/* BFS, level by level; siblings end up adjacent (child[1] = child[0] + 1). Fills order (BFS
 * position -> node id), out_index (node id -> BFS position) and levels (each level's first
 * position, then the node count); returns the number of levels. */
static uint32_t hier_bfs(const hier_tree *t, uint32_t root, uint32_t *order, uint32_t *out_index, uint32_t *levels) {
    uint32_t n = t->n, total = 2 * n - 1;
    uint32_t tail = 1, level_start = 0, n_levels = 0;
    order[0] = root;
    while (level_start < tail) {
        uint32_t level_end = tail;
        levels[n_levels++] = level_start;
        for (uint32_t i = level_start; i < level_end; i++) {
            uint32_t id = order[i];
            out_index[id] = i;
            if (!hier_is_leaf(t, id)) {
                order[tail++] = t->child[2 * (size_t)(id - n)];
                order[tail++] = t->child[2 * (size_t)(id - n) + 1];
            }
        }
        level_start = level_end;
    }
    levels[n_levels] = total;
    return n_levels;
}

/* The nodes in BFS order: attributes, children by BFS position, surfel ranges. Returns the
 * sum of their surfel counts (what exact radii would cost). */
static uint64_t hier_fill_nodes(const hier_tree *t, const uint32_t *order, const uint32_t *out_index,
                                const uint32_t *first, const uint32_t *count, lc_lcb_node *nodes) {
    uint32_t n = t->n, total = 2 * n - 1;
    uint64_t work = 0;
    for (uint32_t i = 0; i < total; i++) {
        uint32_t id = order[i];
        lc_lcb_node *nd = &nodes[i];
        for (int c = 0; c < 3; c++) {
            nd->center[c] = (float)t->cen[3 * (size_t)id + c];
            nd->normal[c] = (float)t->nrm[3 * (size_t)id + c];
        }
        nd->area = (float)t->area[id];
        if (hier_is_leaf(t, id)) {
            nd->child[0] = nd->child[1] = LC_NONE;
        } else {
            nd->child[0] = out_index[t->child[2 * (size_t)(id - n)]];
            nd->child[1] = out_index[t->child[2 * (size_t)(id - n) + 1]];
        }
        nd->first_surfel = first[id];
        nd->surfel_count = count[id];
        work += count[id];
    }
    return work;
}

/* Radii: exact over the node's (reordered) surfels; if the tree is so unbalanced that this
 * would be quadratic (work: the nodes' surfel counts summed), big nodes take the (looser)
 * bound from their children instead. -1 with err out of memory. */
static int hier_radii(const hier_tree *t, const lc_lcb_surfel *surfels, lc_lcb_node *nodes, uint64_t work, char *err,
                      size_t errlen) {
    uint32_t total = 2 * t->n - 1, *skip = NULL;
    if (work > (uint64_t)HIER_EXACT_DEPTH * t->n) {
        skip = calloc(total, sizeof *skip);
        if (!skip) {
            lc_set_err(err, errlen, "hierarchy: out of memory for %u nodes", total);
            return -1;
        }
        for (uint32_t i = 0; i < total; i++) skip[i] = nodes[i].surfel_count > HIER_EXACT_BIG;
    }
    hier_radius_ctx rc = {surfels, nodes, skip};
    lc_parallel_for(t->threads, total, 256, hier_radius_range, &rc);
    if (skip) {
        for (uint32_t i = total; i-- > 0;) {
            if (!skip[i]) continue;
            lc_lcb_node *nd = &nodes[i];
            double r = 0;
            for (int c = 0; c < 2; c++) {
                const lc_lcb_node *ch = &nodes[nd->child[c]];
                double dx = (double)ch->center[0] - nd->center[0], dy = (double)ch->center[1] - nd->center[1],
                       dz = (double)ch->center[2] - nd->center[2];
                double d = sqrt(dx * dx + dy * dy + dz * dz) + ch->radius;
                if (d > r) r = d;
            }
            nd->radius = hier_round_up(r);
        }
    }
    free(skip);
    return 0;
}

/* The finished hierarchy from the built tree: surfels reordered so each node covers a
 * contiguous range (perm: new position -> old index), nodes in BFS order with their levels. */
static int hier_finish(hier_tree *t, uint32_t root, lc_lcb_surfel *surfels, lc_hierarchy *out, uint32_t **perm_out,
                       char *err, size_t errlen) {
    uint32_t n = t->n, total = 2 * n - 1;
    uint32_t *pre = NULL, *stack = NULL, *first = NULL, *count = NULL, *order = NULL, *out_index = NULL;
    uint32_t *perm = NULL, *levels = NULL;
    lc_lcb_surfel *tmp = NULL;
    lc_lcb_node *nodes = NULL;
    int rc = -1;
    pre = malloc(sizeof *pre * total);
    stack = malloc(sizeof *stack * total);
    first = malloc(sizeof *first * total);
    count = malloc(sizeof *count * total);
    order = malloc(sizeof *order * total);
    out_index = malloc(sizeof *out_index * total);
    perm = malloc(sizeof *perm * n);
    levels = malloc(sizeof *levels * ((size_t)total + 1));
    tmp = malloc(sizeof *tmp * n);
    nodes = calloc(total, sizeof *nodes);
    if (!pre || !stack || !first || !count || !order || !out_index || !perm || !levels || !tmp || !nodes) {
        lc_set_err(err, errlen, "hierarchy: out of memory for %u nodes", total);
        goto err;
    }
    if (hier_preorder(t, root, pre, stack, first, perm, err, errlen) != 0) goto err;
    hier_bottom_up(t, surfels, pre, count);
    uint32_t n_levels = hier_bfs(t, root, order, out_index, levels);
    uint32_t *shrunk = realloc(levels, sizeof *levels * ((size_t)n_levels + 1));
    if (shrunk) levels = shrunk;
    memcpy(tmp, surfels, sizeof *tmp * n);
    for (uint32_t i = 0; i < n; i++) surfels[i] = tmp[perm[i]];
    uint64_t work = hier_fill_nodes(t, order, out_index, first, count, nodes);
    if (hier_radii(t, surfels, nodes, work, err, errlen) != 0) goto err;

    out->nodes = nodes;
    out->n_nodes = total;
    out->levels = levels;
    out->n_levels = n_levels;
    if (perm_out) *perm_out = perm;
    else free(perm);
    nodes = NULL, levels = NULL, perm = NULL;
    rc = 0;
err:
    free(pre);
    free(stack);
    free(first);
    free(count);
    free(order);
    free(out_index);
    free(perm);
    free(levels);
    free(tmp);
    free(nodes);
    return rc;
}

/* --- kd-tree ------------------------------------------------------------------------------ */

typedef struct {
    hier_tree *t;
    const lc_lcb_surfel *s;
    uint32_t *idx; /* surfel indices; ends as the leaf order */
    uint32_t next; /* next internal id */
} hier_kd;

static int hier_kd_less(const lc_lcb_surfel *s, int axis, uint32_t a, uint32_t b) {
    float pa = s[a].position[axis], pb = s[b].position[axis];
    return pa < pb || (pa == pb && a < b); /* index tie-break: a strict total order */
}

/* Quickselect: afterwards idx[k] is the k-th element of [lo, hi) in (coordinate, index)
 * order, smaller ones before it. Deterministic (median-of-three pivot, no randomness). */
static void hier_kd_select(const lc_lcb_surfel *s, int axis, uint32_t *idx, uint32_t lo, uint32_t hi, uint32_t k) {
    while (hi - lo > 1) {
        uint32_t mid = lo + (hi - lo) / 2, a = idx[lo], b = idx[mid], c = idx[hi - 1];
        uint32_t piv_pos;
        if (hier_kd_less(s, axis, a, b))
            piv_pos = hier_kd_less(s, axis, b, c) ? mid : (hier_kd_less(s, axis, a, c) ? hi - 1 : lo);
        else piv_pos = hier_kd_less(s, axis, a, c) ? lo : (hier_kd_less(s, axis, b, c) ? hi - 1 : mid);
        uint32_t pivot = idx[piv_pos], t;
        idx[piv_pos] = idx[hi - 1];
        idx[hi - 1] = pivot;
        uint32_t store = lo;
        for (uint32_t i = lo; i < hi - 1; i++) {
            if (hier_kd_less(s, axis, idx[i], pivot)) {
                t = idx[i];
                idx[i] = idx[store];
                idx[store++] = t;
            }
        }
        idx[hi - 1] = idx[store];
        idx[store] = pivot;
        if (k == store) return;
        if (k < store) hi = store;
        else lo = store + 1;
    }
}

static uint32_t hier_kd_build(hier_kd *kd, uint32_t lo, uint32_t hi) {
    if (hi - lo == 1) return lo; /* leaf id = final position */
    float bmin[3] = {INFINITY, INFINITY, INFINITY}, bmax[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = lo; i < hi; i++) {
        const float *p = kd->s[kd->idx[i]].position;
        for (int c = 0; c < 3; c++) {
            if (p[c] < bmin[c]) bmin[c] = p[c];
            if (p[c] > bmax[c]) bmax[c] = p[c];
        }
    }
    int axis = 0;
    for (int c = 1; c < 3; c++)
        if (bmax[c] - bmin[c] > bmax[axis] - bmin[axis]) axis = c;
    uint32_t mid = lo + (hi - lo) / 2;
    hier_kd_select(kd->s, axis, kd->idx, lo, hi, mid);
    uint32_t id = kd->next++;
    uint32_t a = hier_kd_build(kd, lo, mid);
    uint32_t b = hier_kd_build(kd, mid, hi);
    kd->t->child[2 * (size_t)(id - kd->t->n)] = a;
    kd->t->child[2 * (size_t)(id - kd->t->n) + 1] = b;
    return id;
}

/* --- AAC ---------------------------------------------------------------------------------- */

typedef struct {
    double *d; /* k x k distance matrix */
    double *dmin;
    uint32_t *closest;
    uint8_t *need;
    size_t cap; /* clusters */
    int failed;
} hier_scratch;

typedef struct {
    hier_tree *t;
    const uint64_t *keys; /* sorted: morton << 32 | surfel index */
    uint32_t *clus;       /* cluster slots; a range [lo, hi) keeps its clusters at [lo, lo + k) */
    uint32_t *rep;        /* per node id: smallest leaf id below */
    double fc;            /* f(x) = fc * x^(0.5 - eps) */
    uint32_t task_max;
    uint32_t *task;   /* 3 per task: lo, hi, bit */
    uint32_t *task_k; /* clusters each task left */
    uint32_t n_tasks, next_task;
    hier_scratch *scratch;
} hier_aac;

static uint32_t hier_aac_f(const hier_aac *ac, uint32_t x) {
    double f = ac->fc * pow((double)x, 0.5 - HIER_AAC_EPS);
    return f < 1 ? 1 : (uint32_t)f;
}

static int hier_scratch_reserve(hier_scratch *s, size_t k) {
    if (k <= s->cap) return 0;
    double *d = realloc(s->d, sizeof *d * k * k);
    if (d) s->d = d;
    double *dmin = realloc(s->dmin, sizeof *dmin * k);
    if (dmin) s->dmin = dmin;
    uint32_t *cl = realloc(s->closest, sizeof *cl * k);
    if (cl) s->closest = cl;
    uint8_t *need = realloc(s->need, k);
    if (need) s->need = need;
    if (!d || !dmin || !cl || !need) return -1;
    s->cap = k;
    return 0;
}

static void hier_aac_rescan(const double *d, size_t stride, uint32_t cnt, uint32_t x, double *dmin, uint32_t *closest) {
    double best = INFINITY;
    uint32_t bj = x;
    for (uint32_t j = 0; j < cnt; j++) {
        if (j == x) continue;
        double v = d[x * stride + j];
        if (v < best) {
            best = v;
            bj = j;
        }
    }
    dmin[x] = best;
    closest[x] = bj;
}

/* Greedy closest-pair merging of clus[base, base + k) down to m clusters. */
static uint32_t hier_aac_combine(hier_aac *ac, hier_scratch *s, uint32_t base, uint32_t k, uint32_t m) {
    if (k <= m || s->failed) return k;
    if (hier_scratch_reserve(s, k) != 0) {
        s->failed = 1;
        return k;
    }
    hier_tree *t = ac->t;
    uint32_t *c = ac->clus + base;
    double *d = s->d, *dmin = s->dmin;
    uint32_t *closest = s->closest;
    uint8_t *need = s->need;
    size_t st = k;
    for (uint32_t i = 0; i < k; i++)
        for (uint32_t j = i + 1; j < k; j++) d[i * st + j] = d[j * st + i] = hier_dist(t, c[i], c[j]);
    for (uint32_t i = 0; i < k; i++) hier_aac_rescan(d, st, k, i, dmin, closest);
    uint32_t cnt = k;
    while (cnt > m) {
        uint32_t a = 0;
        for (uint32_t i = 1; i < cnt; i++)
            if (dmin[i] < dmin[a]) a = i;
        uint32_t b = closest[a];
        if (a > b) {
            uint32_t x = a;
            a = b;
            b = x;
        }
        for (uint32_t x = 0; x < cnt; x++) need[x] = x == a || closest[x] == a || closest[x] == b;
        uint32_t ca = c[a], cb = c[b];
        uint32_t ra = ac->rep[ca], rb = ac->rep[cb];
        uint32_t id = t->n - 1 + (ra > rb ? ra : rb);
        ac->rep[id] = ra < rb ? ra : rb;
        t->child[2 * (size_t)(id - t->n)] = ca;
        t->child[2 * (size_t)(id - t->n) + 1] = cb;
        hier_merge_attr(t, id, ca, cb);
        c[a] = id;
        uint32_t last = cnt - 1;
        if (b != last) { /* the last slot fills the hole */
            c[b] = c[last];
            for (uint32_t j = 0; j < cnt; j++) {
                d[b * st + j] = d[last * st + j];
                d[j * st + b] = d[j * st + last];
            }
            dmin[b] = dmin[last];
            closest[b] = closest[last];
            need[b] = need[last];
            for (uint32_t x = 0; x < last; x++)
                if (closest[x] == last) closest[x] = b;
        }
        cnt--;
        for (uint32_t j = 0; j < cnt; j++)
            if (j != a) d[a * st + j] = d[j * st + a] = hier_dist(t, c[a], c[j]);
        for (uint32_t x = 0; x < cnt; x++) {
            if (need[x]) {
                hier_aac_rescan(d, st, cnt, x, dmin, closest);
            } else if (d[x * st + a] < dmin[x]) {
                dmin[x] = d[x * st + a];
                closest[x] = a;
            }
        }
    }
    return cnt;
}

/* Morton split of [lo, hi): codes there share all bits above *bit, so the first code with
 * the highest differing bit set is the split. Identical codes: split in the middle. */
static uint32_t hier_aac_split(const uint64_t *keys, uint32_t lo, uint32_t hi, int *bit) {
    while (*bit >= 0) {
        uint64_t mask = 1ull << (32 + *bit);
        (*bit)--;
        if ((keys[lo] & mask) == (keys[hi - 1] & mask)) continue;
        uint32_t l = lo, h = hi - 1; /* keys[l] lacks the bit, keys[h] has it */
        while (h - l > 1) {
            uint32_t m = l + (h - l) / 2;
            if (keys[m] & mask) h = m;
            else l = m;
        }
        return h;
    }
    return lo + (hi - lo) / 2;
}

static int hier_aac_is_task(const hier_aac *ac, uint32_t lo, uint32_t hi) {
    return hi - lo <= ac->task_max || hi - lo < HIER_AAC_DELTA;
}

static uint32_t hier_aac_build(hier_aac *ac, hier_scratch *s, uint32_t lo, uint32_t hi, int bit) {
    if (hi - lo < HIER_AAC_DELTA) {
        for (uint32_t p = lo; p < hi; p++) ac->clus[p] = p;
        return hier_aac_combine(ac, s, lo, hi - lo, hier_aac_f(ac, HIER_AAC_DELTA));
    }
    uint32_t mid = hier_aac_split(ac->keys, lo, hi, &bit);
    uint32_t kl = hier_aac_build(ac, s, lo, mid, bit);
    uint32_t kr = hier_aac_build(ac, s, mid, hi, bit);
    memmove(ac->clus + lo + kl, ac->clus + mid, sizeof *ac->clus * kr);
    return hier_aac_combine(ac, s, lo, kl + kr, hier_aac_f(ac, hi - lo));
}

/* The top of the recursion is cut into independent tasks (a rule depending on n only). */
static int hier_aac_collect(hier_aac *ac, uint32_t lo, uint32_t hi, int bit, uint32_t cap) {
    if (hier_aac_is_task(ac, lo, hi)) {
        if (ac->n_tasks >= cap) return -1;
        uint32_t *tk = ac->task + 3 * (size_t)ac->n_tasks++;
        tk[0] = lo;
        tk[1] = hi;
        tk[2] = (uint32_t)(bit + 1); /* bit may be -1 */
        return 0;
    }
    uint32_t mid = hier_aac_split(ac->keys, lo, hi, &bit);
    if (hier_aac_collect(ac, lo, mid, bit, cap) != 0) return -1;
    return hier_aac_collect(ac, mid, hi, bit, cap);
}

static void hier_aac_task_run(void *ctx, size_t begin, size_t end, int thread) {
    hier_aac *ac = ctx;
    for (size_t i = begin; i < end; i++) {
        const uint32_t *tk = ac->task + 3 * i;
        ac->task_k[i] = hier_aac_build(ac, &ac->scratch[thread], tk[0], tk[1], (int)tk[2] - 1);
    }
}

static uint32_t hier_aac_upper(hier_aac *ac, uint32_t lo, uint32_t hi, int bit) {
    if (hier_aac_is_task(ac, lo, hi)) return ac->task_k[ac->next_task++];
    uint32_t mid = hier_aac_split(ac->keys, lo, hi, &bit);
    uint32_t kl = hier_aac_upper(ac, lo, mid, bit);
    uint32_t kr = hier_aac_upper(ac, mid, hi, bit);
    memmove(ac->clus + lo + kl, ac->clus + mid, sizeof *ac->clus * kr);
    return hier_aac_combine(ac, &ac->scratch[0], lo, kl + kr, hier_aac_f(ac, hi - lo));
}

static uint32_t hier_morton_spread(uint32_t v) { /* 10 bits -> every third bit */
    v &= 0x3FFu;
    v = (v | (v << 16)) & 0x030000FFu;
    v = (v | (v << 8)) & 0x0300F00Fu;
    v = (v | (v << 4)) & 0x030C30C3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
}

static int hier_key_cmp(const void *a, const void *b) {
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

static int hier_aac_tree(hier_tree *t, const lc_lcb_surfel *s, const float bmin[3], const float bmax[3], uint32_t *root,
                         char *err, size_t errlen) {
    uint32_t n = t->n, total = 2 * n - 1;
    int threads = lc_parallel_threads(t->threads), rc = -1;
    hier_aac ac = {.t = t};
    uint64_t *keys = malloc(sizeof *keys * n);
    ac.clus = malloc(sizeof *ac.clus * n);
    ac.rep = malloc(sizeof *ac.rep * total);
    ac.scratch = calloc((size_t)threads, sizeof *ac.scratch);
    uint32_t task_cap = 4096;
    ac.task = malloc(sizeof *ac.task * 3 * task_cap);
    ac.task_k = malloc(sizeof *ac.task_k * task_cap);
    if (!keys || !ac.clus || !ac.rep || !ac.scratch || !ac.task || !ac.task_k) {
        lc_set_err(err, errlen, "hierarchy: out of memory for %u surfels", n);
        goto err;
    }
    for (uint32_t i = 0; i < n; i++) {
        uint32_t q[3];
        for (int c = 0; c < 3; c++) {
            float ext = bmax[c] - bmin[c];
            float u = ext > 0 ? (s[i].position[c] - bmin[c]) / ext : 0;
            int v = (int)(u * 1024.0f);
            q[c] = (uint32_t)(v < 0 ? 0 : v > 1023 ? 1023 : v);
        }
        uint32_t code = hier_morton_spread(q[0]) << 2 | hier_morton_spread(q[1]) << 1 | hier_morton_spread(q[2]);
        keys[i] = (uint64_t)code << 32 | i;
    }
    qsort(keys, n, sizeof *keys, hier_key_cmp);
    ac.keys = keys;
    for (uint32_t p = 0; p < n; p++) {
        t->leaf_surfel[p] = (uint32_t)keys[p];
        ac.rep[p] = p;
        hier_leaf_attr(t, s, p);
    }
    ac.fc = pow((double)HIER_AAC_DELTA, 0.5 + HIER_AAC_EPS) / 2;
    /* ~32 tasks whatever the core count: enough for load balance, independent of threads */
    ac.task_max = n / 32 > HIER_AAC_MIN_TASK ? n / 32 : HIER_AAC_MIN_TASK;
    if (hier_aac_collect(&ac, 0, n, 29, task_cap) != 0) {
        lc_set_err(err, errlen, "hierarchy: too many AAC tasks (degenerate Morton split)");
        goto err;
    }
    lc_parallel_for(threads, ac.n_tasks, 1, hier_aac_task_run, &ac);
    for (int i = 1; i < threads; i++) ac.scratch[0].failed |= ac.scratch[i].failed;
    uint32_t k = hier_aac_upper(&ac, 0, n, 29);
    k = hier_aac_combine(&ac, &ac.scratch[0], 0, k, 1);
    for (int i = 0; i < threads; i++)
        if (ac.scratch[i].failed) {
            lc_set_err(err, errlen, "hierarchy: out of memory for the AAC distance matrix");
            goto err;
        }
    if (k != 1) {
        lc_set_err(err, errlen, "hierarchy: internal error (AAC left %u clusters)", k);
        goto err;
    }
    *root = ac.clus[0];
    rc = 0;
err:
    if (ac.scratch)
        for (int i = 0; i < threads; i++) {
            free(ac.scratch[i].d);
            free(ac.scratch[i].dmin);
            free(ac.scratch[i].closest);
            free(ac.scratch[i].need);
        }
    free(ac.scratch);
    free(keys);
    free(ac.clus);
    free(ac.rep);
    free(ac.task);
    free(ac.task_k);
    return rc;
}

/* --- public -------------------------------------------------------------------------------- */

int lc_hierarchy_build(lc_lcb_surfel *surfels, uint32_t n, lc_hierarchy_method method, int threads, lc_hierarchy *out,
                       uint32_t **perm_out, char *err, size_t errlen) {
    hier_tree t = {.n = n, .threads = threads};
    uint32_t *idx = NULL;
    if (perm_out) *perm_out = NULL;
    if (!out) {
        lc_set_err(err, errlen, "hierarchy: out is NULL");
        return -1;
    }
    memset(out, 0, sizeof *out);
    if (n == 0 || !surfels) {
        lc_set_err(err, errlen, "hierarchy: n = %u surfels (need at least one)", n);
        return -1;
    }
    if (n > 0x7FFFFFFFu) {
        lc_set_err(err, errlen, "hierarchy: n = %u surfels is too many (2n-1 nodes must fit 32 bits)", n);
        return -1;
    }
    if (method != LC_HIERARCHY_AAC && method != LC_HIERARCHY_KDTREE) {
        lc_set_err(err, errlen, "hierarchy: unknown method %d", (int)method);
        return -1;
    }
    float bmin[3] = {INFINITY, INFINITY, INFINITY}, bmax[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = 0; i < n; i++) {
        const float *p = surfels[i].position;
        if (!isfinite(p[0]) || !isfinite(p[1]) || !isfinite(p[2]) || !isfinite(surfels[i].area)) {
            lc_set_err(err, errlen, "hierarchy: surfels[%u] has a non-finite position or area", i);
            return -1;
        }
        for (int c = 0; c < 3; c++) {
            if (p[c] < bmin[c]) bmin[c] = p[c];
            if (p[c] > bmax[c]) bmax[c] = p[c];
        }
    }
    double extent = 0;
    for (int c = 0; c < 3; c++)
        if (bmax[c] - bmin[c] > extent) extent = bmax[c] - bmin[c];
    t.inv_extent2 = extent > 0 ? 1.0 / (extent * extent) : 1.0;

    size_t total = 2 * (size_t)n - 1;
    t.child = malloc(sizeof *t.child * 2 * (n > 1 ? n - 1 : 1));
    t.leaf_surfel = malloc(sizeof *t.leaf_surfel * n);
    t.cen = malloc(sizeof *t.cen * 3 * total);
    t.nrm = malloc(sizeof *t.nrm * 3 * total);
    t.area = malloc(sizeof *t.area * total);
    t.cls = malloc(sizeof *t.cls * total);
    t.ce = HIER_CE;
    if (!t.child || !t.leaf_surfel || !t.cen || !t.nrm || !t.area || !t.cls) {
        lc_set_err(err, errlen, "hierarchy: out of memory for %u surfels", n);
        goto err;
    }
    uint32_t root;
    if (method == LC_HIERARCHY_KDTREE) {
        idx = malloc(sizeof *idx * n);
        if (!idx) {
            lc_set_err(err, errlen, "hierarchy: out of memory for %u surfels", n);
            goto err;
        }
        for (uint32_t i = 0; i < n; i++) idx[i] = i;
        hier_kd kd = {&t, surfels, idx, n};
        root = hier_kd_build(&kd, 0, n);
        memcpy(t.leaf_surfel, idx, sizeof *idx * n);
    } else {
        if (hier_aac_tree(&t, surfels, bmin, bmax, &root, err, errlen) != 0) goto err;
    }
    if (hier_finish(&t, root, surfels, out, perm_out, err, errlen) != 0) goto err;
    free(idx);
    free(t.child);
    free(t.leaf_surfel);
    free(t.cen);
    free(t.nrm);
    free(t.area);
    free(t.cls);
    return 0;
err:
    free(idx);
    free(t.child);
    free(t.leaf_surfel);
    free(t.cen);
    free(t.nrm);
    free(t.area);
    free(t.cls);
    return -1;
}

void lc_hierarchy_release(lc_hierarchy *h) {
    if (!h) return;
    free(h->nodes);
    free(h->levels);
    memset(h, 0, sizeof *h);
}

double lc_hierarchy_quality(const lc_lcb_surfel *surfels, const lc_hierarchy *h) {
    if (!h || !h->nodes || h->n_nodes < 3) return 0;
    const lc_lcb_node *root = &h->nodes[0];
    double bmin[3] = {INFINITY, INFINITY, INFINITY}, bmax[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (uint32_t i = root->first_surfel; i < root->first_surfel + root->surfel_count; i++)
        for (int c = 0; c < 3; c++) {
            bmin[c] = fmin(bmin[c], surfels[i].position[c]);
            bmax[c] = fmax(bmax[c], surfels[i].position[c]);
        }
    double extent = fmax(bmax[0] - bmin[0], fmax(bmax[1] - bmin[1], bmax[2] - bmin[2]));
    double inv_e2 = extent > 0 ? 1.0 / (extent * extent) : 1.0;
    double sum = 0, wsum = 0;
    for (uint32_t i = 0; i < h->n_nodes; i++) {
        const lc_lcb_node *nd = &h->nodes[i];
        if (nd->child[0] == LC_NONE) continue;
        const lc_lcb_node *a = &h->nodes[nd->child[0]], *b = &h->nodes[nd->child[1]];
        double xa[3], na[3], xb[3], nb[3];
        for (int c = 0; c < 3; c++) {
            xa[c] = a->center[c];
            na[c] = a->normal[c];
            xb[c] = b->center[c];
            nb[c] = b->normal[c];
        }
        sum += nd->area * hier_metric(xa, na, a->area, xb, nb, b->area, inv_e2);
        wsum += nd->area;
    }
    return wsum > 0 ? sum / wsum : 0;
}
