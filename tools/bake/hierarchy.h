/* hierarchy: a binary tree over the surfels for hierarchical light transport.
 * LC_HIERARCHY_AAC: approximate agglomerative clustering (Gu et al. 2013) with the PIC
 * metric d(a,b) = |x_a - x_b|^2 / extent^2 + C_n (1 - n_a.n_b) + C_b |A_a - A_b| / max(A_a, A_b),
 * C_n = 0.1, C_b = 0.02, plus C_e = 1 unless both clusters are pure and share an emission class
 * (emitters get their own subtrees; lc_hierarchy_quality leaves C_e out). LC_HIERARCHY_KDTREE: median split on the longest axis (reference). */
#ifndef LC_HIERARCHY_H
#define LC_HIERARCHY_H
#include <stddef.h>
#include <stdint.h>

#include "lcb/lcb.h"

typedef enum { LC_HIERARCHY_AAC = 0, LC_HIERARCHY_KDTREE = 1 } lc_hierarchy_method;

typedef struct lc_hierarchy {
    lc_lcb_node *nodes; /* 2n - 1 nodes, BFS order, node 0 = root */
    uint32_t n_nodes;
    uint32_t *levels; /* n_levels + 1 offsets into nodes */
    uint32_t n_levels;
} lc_hierarchy;

/* Builds the tree and REORDERS surfels[] in place into leaf (DFS) order so every node's
 * surfels are the contiguous range [first_surfel, first_surfel + surfel_count).
 * *perm_out (optional, malloc'd) maps new index -> old index. threads: parallel-for workers
 * (0 = all cores). Deterministic, whatever the thread count. Returns 0 or -1 with err set. */
int lc_hierarchy_build(lc_lcb_surfel *surfels, uint32_t n, lc_hierarchy_method method, int threads, lc_hierarchy *out,
                       uint32_t **perm_out, char *err, size_t errlen);
void lc_hierarchy_release(lc_hierarchy *h);

/* Mean PIC-metric cost of the merges (lower = more compact clusters) — used to compare methods. */
double lc_hierarchy_quality(const lc_lcb_surfel *surfels, const lc_hierarchy *h);

#endif
