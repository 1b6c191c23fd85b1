/* lcb probes sections (PRBH, PRBP, PRBR, PRCL, PRCP, PRCB, PRRW, PRRU): a small consistent
 * set round-trips through the writer and reader and shows in `info`; a bake without them
 * opens with probe_header NULL; every rule of the reader rejects its corruption with a
 * message naming the section; truncations and mutations of the probe sections (CRCs fixed)
 * never crash. With LUCENT_WRITE_CORPUS=dir it also writes the fuzz seed into dir. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <stdint.h>
#include <unistd.h>

#include "check.h"
#include "lcb_test_util.h"
#include "lcb/lcb.h"
#include "util/crc32.h"
#include "util/fsutil.h"

/* The minimal bake of test_lcb.c (no LKSH, no assets): 5 texel caches, then 8 grid caches. */
enum {
    N_MAT = 2,
    N_VERT = 4,
    N_TRI = 2,
    N_SURF = 4,
    N_NODE = 7,
    N_LEVL = 4,
    N_TEXEL = 5,
    N_CELL = 8,
    N_CACHE = N_TEXEL + N_CELL,
    LM_W = 4,
    LM_H = 4,
    PER_CACHE = 2,
    N_LINK = N_CACHE * PER_CACHE,
    /* the probes: 2 probes x 4 rays, SH bands 2 (4 coefficients), 2 clusters over 3 rows */
    N_PROBE = 2,
    N_RAY = 4,
    N_HIT = N_PROBE * N_RAY,
    N_CLUSTER = 2,
    N_ROW = 3,
    N_CP = 3,
    N_BASIS = 16, /* cluster 0: rank 1 x (2 probes x 4); cluster 1: rank 2 x (1 probe x 4) */
    N_U = 5,      /* cluster 0: 1 row x rank 1; cluster 1: 2 rows x rank 2 */
    N_UNSEEN = 3, /* PRUS: row 0 two surfels, row 1 none, row 2 one */
    N_TSG = 4,    /* TSGW: texel 0 two surfels, 1 none, 2 and 3 one each, 4 none */
    GRID_PER = 4, /* GLNK: links per grid cache (bake_use_grid_links), 3 used */
    N_GLNK = N_CELL * GRID_PER,
    N_PROBE_SECS = 8
};

typedef struct bake {
    lc_lcb_material mat[N_MAT];
    lc_lcb_vertex vert[N_VERT];
    lc_lcb_triangle tri[N_TRI];
    lc_lcb_surfel surf[N_SURF];
    lc_lcb_node node[N_NODE];
    uint32_t levl[N_LEVL];
    lc_lcb_cache cache[N_CACHE];
    uint32_t lmap[LM_W * LM_H];
    uint32_t grid[N_CELL];
    lc_lcb_link link[N_LINK];
    char *meta; /* JSON text (malloc'd) */
    lc_lcb_probe_header prbh[2];
    lc_lcb_probe prbp[N_PROBE];
    uint32_t prbr[N_HIT];
    lc_lcb_probe_cluster prcl[N_CLUSTER];
    uint32_t prcp[N_CP];
    float prcb[N_BASIS];
    lc_lcb_probe_row prrw[N_ROW];
    float prru[N_U];
    uint32_t pruf[N_ROW + 1];
    lc_lcb_probe_unseen prus[N_UNSEEN];
    uint64_t n_pruf, n_prus; /* records written */
    int unseen;              /* bit 0: write PRUF, bit 1: PRUS */
    uint32_t tsgf[N_TEXEL + 1];
    lc_lcb_surfel_weight tsgw[N_TSG];
    uint64_t n_tsgf, n_tsgw;
    int tsg; /* bit 0: write TSGF, bit 1: TSGW (0 by default: a bake gathering by links) */
    lc_lcb_link glnk[N_GLNK];
    uint64_t n_glnk;
    int glnk_parts;  /* bit 0: write GLNK, bit 1: META /links/grid_per_cache (bake_use_grid_links) */
    uint64_t n_link; /* LINK records as written */
    int with_probes;
    int skip_probe;               /* index into probe_order to leave out, or -1 */
    uint64_t count[N_PROBE_SECS]; /* records written per probe section */
    uint32_t prrw_record;         /* PRRW record size as written */
} bake;

static const char *const probe_order[N_PROBE_SECS] = {"PRBH", "PRBP", "PRBR", "PRCL", "PRCP", "PRCB", "PRRW", "PRRU"};
static char tmpdir[256];

static char *bake_meta(int per_cache, int grid_per_cache) {
    cJSON *m = cJSON_CreateObject();
    cJSON_AddStringToObject(m, "format", "lucent-bake");
    cJSON_AddStringToObject(m, "source", "tests/quad.obj");
    cJSON_AddNumberToObject(m, "sh_bands", 2);
    cJSON *lm = cJSON_AddObjectToObject(m, "lightmap");
    cJSON_AddNumberToObject(lm, "width", LM_W);
    cJSON_AddNumberToObject(lm, "height", LM_H);
    cJSON *g = cJSON_AddObjectToObject(m, "grid");
    float origin[3] = {-1, -0.5f, 0.25f};
    int dims[3] = {2, 2, 2};
    cJSON_AddItemToObject(g, "origin", cJSON_CreateFloatArray(origin, 3));
    cJSON_AddNumberToObject(g, "cell", 0.5);
    cJSON_AddItemToObject(g, "dims", cJSON_CreateIntArray(dims, 3));
    cJSON *su = cJSON_AddObjectToObject(m, "surfels");
    cJSON_AddNumberToObject(su, "count", N_SURF);
    cJSON_AddNumberToObject(su, "area", 1.0);
    cJSON *h = cJSON_AddObjectToObject(m, "hierarchy");
    cJSON_AddNumberToObject(h, "nodes", N_NODE);
    cJSON_AddNumberToObject(h, "levels", N_LEVL - 1);
    cJSON *c = cJSON_AddObjectToObject(m, "caches");
    cJSON_AddNumberToObject(c, "count", N_CACHE);
    cJSON_AddNumberToObject(c, "texel", N_TEXEL);
    cJSON *l = cJSON_AddObjectToObject(m, "links");
    cJSON_AddNumberToObject(l, "per_cache", per_cache);
    if (grid_per_cache >= 0) cJSON_AddNumberToObject(l, "grid_per_cache", grid_per_cache);
    cJSON_AddNumberToObject(l, "sh_bands", 0);
    char *text = cJSON_PrintUnformatted(m);
    cJSON_Delete(m);
    return text;
}

/* Geometry, hierarchy, caches and links as in test_lcb.c's bake_init. */
static void bake_init_scene(bake *b) {
    snprintf(b->mat[0].name, sizeof b->mat[0].name, "white");
    snprintf(b->mat[1].name, sizeof b->mat[1].name, "red lamp");
    for (int k = 0; k < 3; k++) b->mat[0].base_color[k] = 0.8f;
    b->mat[1].emission[0] = 10;
    for (int i = 0; i < N_VERT; i++) {
        float x = (float)(i == 1 || i == 2), y = (float)(i >= 2);
        b->vert[i].position[0] = x;
        b->vert[i].position[1] = y;
        b->vert[i].normal[2] = 1;
        b->vert[i].uv1[0] = x;
        b->vert[i].uv1[1] = 1 - y;
    }
    b->tri[0] = (lc_lcb_triangle){{0, 1, 2}, 0};
    b->tri[1] = (lc_lcb_triangle){{0, 2, 3}, 1};
    for (int i = 0; i < N_SURF; i++) {
        lc_lcb_surfel *s = &b->surf[i];
        s->position[0] = 0.25f + 0.5f * (float)(i % 2);
        s->position[1] = 0.25f + 0.5f * (float)(i / 2);
        s->normal[2] = 1;
        for (int k = 0; k < 3; k++) s->albedo[k] = 0.5f;
        s->area = 0.25f;
        s->material = (uint32_t)(i % 2);
        s->cache = i < 3 ? (uint32_t)i : LC_NONE;
    }
    /* BFS: 0 = root [0,4) -> 1 [0,2), 2 [2,4) -> leaves 3..6 = surfels 0..3. */
    static const uint32_t child[N_NODE][2] = {
        {1, 2}, {3, 4}, {5, 6}, {LC_NONE, LC_NONE}, {LC_NONE, LC_NONE}, {LC_NONE, LC_NONE}, {LC_NONE, LC_NONE}};
    static const uint32_t first[N_NODE] = {0, 0, 2, 0, 1, 2, 3}, count[N_NODE] = {4, 2, 2, 1, 1, 1, 1};
    for (int i = 0; i < N_NODE; i++) {
        lc_lcb_node *n = &b->node[i];
        n->child[0] = child[i][0];
        n->child[1] = child[i][1];
        n->first_surfel = first[i];
        n->surfel_count = count[i];
        n->area = 0.25f * (float)count[i];
        n->normal[2] = 1;
        n->radius = count[i] == 1 ? 0.0f : 0.36f * (float)count[i];
    }
    static const uint32_t levl[N_LEVL] = {0, 1, 3, 7};
    memcpy(b->levl, levl, sizeof levl);
    static const uint32_t owned[N_TEXEL] = {0, 1, 5, 6, 10};
    for (int t = 0; t < LM_W * LM_H; t++) b->lmap[t] = LC_NONE;
    for (int i = 0; i < N_TEXEL; i++) {
        b->cache[i].flags = LC_CACHE_TEXEL;
        b->cache[i].index = owned[i];
        b->cache[i].normal[2] = 1;
        b->lmap[owned[i]] = (uint32_t)i;
    }
    for (int i = 0; i < N_CELL; i++) {
        b->cache[N_TEXEL + i].flags = LC_CACHE_GRID;
        b->cache[N_TEXEL + i].index = (uint32_t)i;
        b->grid[i] = (uint32_t)(N_TEXEL + i);
    }
    for (int c = 0; c < N_CACHE; c++) {
        float dir[3] = {0.6f, 0, 0.8f};
        b->link[c * 2] = (lc_lcb_link){(uint32_t)(c % N_NODE), 0.1f, lc_link_pack(dir, 0.3f)};
        b->cache[c].link_count = 1;
    }
}

/* Cluster 0: the texel row (cache 0) over both probes, rank 1; cluster 1: grid cache 5's
 * coefficients 0 and 8 over probe 1, rank 2. */
static void bake_init_probes(bake *b) {
    b->prbh[0] = (lc_lcb_probe_header){.n_probes = N_PROBE,
                                       .n_rays = N_RAY,
                                       .sh_bands = 2,
                                       .n_clusters = N_CLUSTER,
                                       .n_rows = N_ROW,
                                       .max_rank = 2,
                                       .overlaps = 2,
                                       .receiver_rays = 64,
                                       .support_radius = 1.5f,
                                       .svd_error = 0.01f};
    b->prbh[1] = b->prbh[0];
    for (int p = 0; p < N_PROBE; p++) {
        b->prbp[p].position[0] = 0.5f;
        b->prbp[p].position[1] = 0.25f + 0.5f * (float)p;
        b->prbp[p].position[2] = 0.5f;
    }
    for (int i = 0; i < N_HIT; i++) b->prbr[i] = i % 3 == 2 ? LC_NONE : (uint32_t)(i % N_SURF);
    b->prcl[0] = (lc_lcb_probe_cluster){0, 1, 0, 2, 1, 0, 0, 0};
    b->prcl[1] = (lc_lcb_probe_cluster){1, 2, 2, 1, 2, 0, 8, 1};
    b->prcp[0] = 0;
    b->prcp[1] = 1;
    b->prcp[2] = 1;
    for (int i = 0; i < N_BASIS; i++) b->prcb[i] = 0.125f * (float)(i - 8);
    for (int i = 0; i < N_U; i++) b->prru[i] = 1.0f - 0.25f * (float)i;
    b->prrw[0] = (lc_lcb_probe_row){0, 0};
    b->prrw[1] = (lc_lcb_probe_row){N_TEXEL, 0};
    b->prrw[2] = (lc_lcb_probe_row){N_TEXEL, 8};
    static const uint64_t count[N_PROBE_SECS] = {1, N_PROBE, N_HIT, N_CLUSTER, N_CP, N_BASIS, N_ROW, N_U};
    memcpy(b->count, count, sizeof count);
    b->prrw_record = sizeof(lc_lcb_probe_row);
    static const uint32_t first[N_ROW + 1] = {0, 2, 2, N_UNSEEN};
    memcpy(b->pruf, first, sizeof first);
    b->prus[0] = (lc_lcb_probe_unseen){1, 0.25f};
    b->prus[1] = (lc_lcb_probe_unseen){3, 0.125f};
    b->prus[2] = (lc_lcb_probe_unseen){0, -0.5f}; /* a grid row's weight may be negative */
    b->n_pruf = N_ROW + 1, b->n_prus = N_UNSEEN;
    b->unseen = 3;
    static const uint32_t tfirst[N_TEXEL + 1] = {0, 2, 2, 3, N_TSG, N_TSG};
    memcpy(b->tsgf, tfirst, sizeof tfirst);
    b->tsgw[0] = (lc_lcb_surfel_weight){0, 0.5f};
    b->tsgw[1] = (lc_lcb_surfel_weight){2, 0.25f};
    b->tsgw[2] = (lc_lcb_surfel_weight){3, 0.75f};
    b->tsgw[3] = (lc_lcb_surfel_weight){1, 1.0f};
    b->n_tsgf = N_TEXEL + 1, b->n_tsgw = N_TSG;
}

static void bake_init(bake *b) {
    memset(b, 0, sizeof *b);
    b->with_probes = 1;
    b->skip_probe = -1;
    b->n_link = N_LINK;
    bake_init_scene(b);
    bake_init_probes(b);
    b->meta = bake_meta(PER_CACHE, -1);
}

/* Grid caches with their own rows (GLNK, GRID_PER each, 3 used) and padding LINK slots;
 * META says so unless what & 2 is clear, GLNK is written unless what & 1 is. */
static void bake_use_grid_links(bake *b, int what) {
    float dir[3] = {0, 0.6f, 0.8f};
    for (int g = 0; g < N_CELL; g++) {
        uint32_t c = N_TEXEL + (uint32_t)g;
        memset(&b->link[c * PER_CACHE], 0, PER_CACHE * sizeof b->link[0]);
        for (int k = 0; k < 3; k++)
            b->glnk[g * GRID_PER + k] =
                (lc_lcb_link){(uint32_t)((g + k) % N_NODE), 0.05f * (float)(k + 1), lc_link_pack(dir, 0.2f)};
        b->cache[c].link_count = 3;
    }
    b->n_glnk = N_GLNK;
    b->glnk_parts = what;
    free(b->meta);
    b->meta = bake_meta(PER_CACHE, what & 2 ? GRID_PER : -1);
}

static void bake_free(bake *b) {
    free(b->meta);
    b->meta = NULL;
}

static int bake_write(const bake *b, const char *path, char *err, size_t errlen) {
    struct {
        const char *id;
        uint32_t rec;
        const void *data;
        uint64_t n;
    } s[] = {
        {"META", 1, b->meta, strlen(b->meta)},
        {"MATL", sizeof(lc_lcb_material), b->mat, N_MAT},
        {"VERT", sizeof(lc_lcb_vertex), b->vert, N_VERT},
        {"TRIS", sizeof(lc_lcb_triangle), b->tri, N_TRI},
        {"SURF", sizeof(lc_lcb_surfel), b->surf, N_SURF},
        {"NODE", sizeof(lc_lcb_node), b->node, N_NODE},
        {"LEVL", 4, b->levl, N_LEVL},
        {"CACH", sizeof(lc_lcb_cache), b->cache, N_CACHE},
        {"LMAP", 4, b->lmap, LM_W * LM_H},
        {"GRID", 4, b->grid, N_CELL},
        {"LINK", sizeof(lc_lcb_link), b->link, b->n_link},
        {"PRBH", sizeof(lc_lcb_probe_header), b->prbh, b->count[0]},
        {"PRBP", sizeof(lc_lcb_probe), b->prbp, b->count[1]},
        {"PRBR", 4, b->prbr, b->count[2]},
        {"PRCL", sizeof(lc_lcb_probe_cluster), b->prcl, b->count[3]},
        {"PRCP", 4, b->prcp, b->count[4]},
        {"PRCB", 4, b->prcb, b->count[5]},
        {"PRRW", b->prrw_record, b->prrw, b->count[6] * sizeof(lc_lcb_probe_row) / b->prrw_record},
        {"PRRU", 4, b->prru, b->count[7]},
        {"PRUF", 4, b->pruf, b->n_pruf},
        {"PRUS", sizeof(lc_lcb_probe_unseen), b->prus, b->n_prus},
        {"TSGF", 4, b->tsgf, b->n_tsgf},
        {"TSGW", sizeof(lc_lcb_surfel_weight), b->tsgw, b->n_tsgw},
        {"GLNK", sizeof(lc_lcb_link), b->glnk, b->n_glnk},
    };
    const int first_probe = 11;
    lc_lcb_writer *w = lc_lcb_writer_create();
    int rc = -1;
    if (!w) return -1;
    for (int i = 0; i < (int)(sizeof s / sizeof s[0]); i++) {
        int unseen_bit = !strcmp(s[i].id, "PRUF") ? 1 : !strcmp(s[i].id, "PRUS") ? 2 : 0;
        int tsg_bit = !strcmp(s[i].id, "TSGF") ? 1 : !strcmp(s[i].id, "TSGW") ? 2 : 0;
        if (!strcmp(s[i].id, "GLNK") && !(b->glnk_parts & 1)) continue;
        if (tsg_bit          ? !(b->tsg & tsg_bit)
                : unseen_bit ? !(b->unseen & unseen_bit)
                             : i >= first_probe && (!b->with_probes || i - first_probe == b->skip_probe))
            continue;
        if (lc_lcb_writer_add(w, s[i].id, s[i].rec, s[i].data, s[i].n) != 0) goto err;
    }
    rc = lc_lcb_writer_write(w, path, err, errlen);
err:
    lc_lcb_writer_release(w);
    return rc;
}

/* Writes the bake to a temp file and reads the bytes back (malloc'd, so 8-aligned). */
static uint8_t *bake_bytes(const bake *b, size_t *len) {
    char path[512], err[256];
    snprintf(path, sizeof path, "%s/bytes.lcb", tmpdir);
    if (bake_write(b, path, err, sizeof err) != 0) {
        fprintf(stderr, "bake_write: %s\n", err);
        return NULL;
    }
    uint8_t *buf = (uint8_t *)lc_fs_read(path, 1u << 20, len, err, sizeof err);
    unlink(path);
    return buf;
}

static void expect_bake_fail(const char *label, const bake *b, const char *s1, const char *s2) {
    size_t len = 0;
    char err[512];
    uint8_t *buf = bake_bytes(b, &len);
    CHECK(buf != NULL, "%s: could not write", label);
    if (!buf) return;
    int rc = lcb_test_try_open(buf, len, err, sizeof err);
    CHECK(rc != 0, "%s: opened but should have failed", label);
    CHECK(rc != 0 && strstr(err, s1) && (!s2 || strstr(err, s2)) && strstr(err, "re-run lucent-bake"),
          "%s: message '%s' lacks '%s'%s%s", label, err, s1, s2 ? " / " : "", s2 ? s2 : "");
    free(buf);
}

/* The whole of a stream written by lc_lcb_print_info (malloc'd). */
static char *info_text(const lc_lcb *f, int json) {
    FILE *tf = tmpfile();
    if (!tf) return NULL;
    lc_lcb_print_info(f, "mem", json, tf);
    long n = ftell(tf);
    rewind(tf);
    char *text = calloc(1, (size_t)(n > 0 ? n : 0) + 1);
    if (text && n > 0 && fread(text, 1, (size_t)n, tf) != (size_t)n) text[0] = 0;
    fclose(tf);
    return text;
}

static double json_num(const cJSON *o, const char *k) {
    const cJSON *x = cJSON_GetObjectItemCaseSensitive(o, k);
    return cJSON_IsNumber(x) ? x->valuedouble : -1;
}

static void check_info(const lc_lcb *f) {
    char *text = info_text(f, 0);
    CHECK(text &&
              strstr(text, "probes      2 probes x 4 rays, SH bands 2; 2 clusters over 3 rows, rank max 2 mean 1.5") &&
              strstr(text, "overlaps 2, receiver rays 64, support radius 1.5 m") && strstr(text, "PRRU") &&
              strstr(text, "unseen rays gathered from surfels: 3 entries"),
          "human info:\n%s", text ? text : "");
    free(text);
    text = info_text(f, 1);
    cJSON *j = text ? cJSON_Parse(text) : NULL;
    const cJSON *p = cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(j, "counts"), "probes");
    /* the probe sections' bytes: the records, without padding */
    double bytes = sizeof(lc_lcb_probe_header) + N_PROBE * sizeof(lc_lcb_probe) + 4.0 * N_HIT +
        N_CLUSTER * sizeof(lc_lcb_probe_cluster) + 4.0 * N_CP + 4.0 * N_BASIS + N_ROW * sizeof(lc_lcb_probe_row) +
        4.0 * N_U + 4.0 * (N_ROW + 1) + N_UNSEEN * sizeof(lc_lcb_probe_unseen);
    CHECK(p && json_num(p, "probes") == N_PROBE && json_num(p, "rays") == N_RAY && json_num(p, "sh_bands") == 2 &&
              json_num(p, "clusters") == N_CLUSTER && json_num(p, "rows") == N_ROW && json_num(p, "max_rank") == 2 &&
              json_num(p, "mean_rank") == 1.5 && json_num(p, "overlaps") == 2 && json_num(p, "receiver_rays") == 64 &&
              json_num(p, "support_radius") == 1.5 && fabs(json_num(p, "svd_error") - 0.01) < 1e-6 &&
              json_num(p, "bytes") == bytes && json_num(p, "unseen_entries") == N_UNSEEN,
          "JSON info probes:\n%s", text ? text : "");
    cJSON_Delete(j);
    free(text);
}

/* --- the valid bakes ----------------------------------------------------------------------- */

static void test_round_trip(void) {
    bake b;
    bake_init(&b);
    size_t len = 0;
    char err[512] = "";
    uint8_t *buf = bake_bytes(&b, &len);
    lc_lcb *f = NULL;
    CHECK(buf && lc_lcb_open_memory(buf, len, &f, err, sizeof err) == 0, "open: %s", err);
    if (f) {
        const lc_lcb_view *v = lc_lcb_get(f);
        const lc_lcb_probe_header *h = v->probe_header;
        CHECK(h && memcmp(h, &b.prbh[0], sizeof *h) == 0, "probe header differs");
#define SAME(ptr, arr) CHECK((ptr) && memcmp((ptr), (arr), sizeof(arr)) == 0, #arr " differs")
        SAME(v->probes, b.prbp);
        SAME(v->probe_hits, b.prbr);
        SAME(v->probe_clusters, b.prcl);
        SAME(v->probe_cluster_probes, b.prcp);
        SAME(v->probe_basis, b.prcb);
        SAME(v->probe_rows, b.prrw);
        SAME(v->probe_u, b.prru);
        SAME(v->probe_unseen_first, b.pruf);
        SAME(v->probe_unseen, b.prus);
#undef SAME
        CHECK(v->n_probe_cluster_probes == N_CP && v->n_probe_basis == N_BASIS && v->n_probe_u == N_U,
              "counts %llu %llu %llu", (unsigned long long)v->n_probe_cluster_probes,
              (unsigned long long)v->n_probe_basis, (unsigned long long)v->n_probe_u);
        CHECK(v->probe_hits[2] == LC_NONE && v->caches[v->probe_rows[0].cache].flags == LC_CACHE_TEXEL &&
                  v->caches[v->probe_rows[2].cache].flags == LC_CACHE_GRID,
              "rows: one texel and one grid cache");
        check_info(f);
        lc_lcb_close(f);
    }
    free(buf);

    /* without PRUF/PRUS (a bake before them, or --probe-unseen off): valid, no entries */
    b.unseen = 0;
    buf = bake_bytes(&b, &len);
    f = NULL;
    CHECK(buf && lc_lcb_open_memory(buf, len, &f, err, sizeof err) == 0, "open without unseen rays: %s", err);
    if (f) {
        const lc_lcb_view *v = lc_lcb_get(f);
        CHECK(v->probe_header && !v->probe_unseen_first && !v->probe_unseen, "unseen fields set without PRUF/PRUS");
        lc_lcb_close(f);
    }
    free(buf);

    /* without the probe sections: valid, probe_header NULL and every probe field empty */
    b.with_probes = 0;
    buf = bake_bytes(&b, &len);
    f = NULL;
    CHECK(buf && lc_lcb_open_memory(buf, len, &f, err, sizeof err) == 0, "open without probes: %s", err);
    if (f) {
        const lc_lcb_view *v = lc_lcb_get(f);
        CHECK(v->probe_header == NULL && v->probes == NULL && v->probe_hits == NULL && v->probe_clusters == NULL &&
                  v->probe_cluster_probes == NULL && v->probe_basis == NULL && v->probe_rows == NULL &&
                  v->probe_u == NULL && v->n_probe_cluster_probes == 0 && v->n_probe_basis == 0 && v->n_probe_u == 0,
              "probe fields set without probe sections");
        char *text = info_text(f, 0), *json = info_text(f, 1);
        CHECK(text && !strstr(text, "probes  "), "human info shows probes:\n%s", text ? text : "");
        CHECK(json && !strstr(json, "\"probes\""), "JSON info shows probes:\n%s", json ? json : "");
        free(text);
        free(json);
        lc_lcb_close(f);
    }
    free(buf);
    bake_free(&b);
}

/* --solver probes: META /links/per_cache 0, LINK empty, every link_count 0; valid only with
 * the probe sections (a bake keeps a solver). */
static void test_probes_only(void) {
    bake b;
    bake_init(&b);
    free(b.meta);
    b.meta = bake_meta(0, -1);
    b.n_link = 0;
    for (int c = 0; c < N_CACHE; c++) b.cache[c].link_count = 0;
    size_t len = 0;
    char err[512] = "";
    uint8_t *buf = bake_bytes(&b, &len);
    lc_lcb *f = NULL;
    CHECK(buf && lc_lcb_open_memory(buf, len, &f, err, sizeof err) == 0, "probes only: %s", err);
    if (f) {
        const lc_lcb_view *v = lc_lcb_get(f);
        CHECK(v->links_per_cache == 0 && v->probe_header && v->probe_header->n_clusters == N_CLUSTER,
              "probes only: per_cache %u", v->links_per_cache);
        lc_lcb_close(f);
    }
    free(buf);
    b.with_probes = 0;
    expect_bake_fail("no links and no probes", &b, "META", "/links/per_cache must be an integer in 1..1024");
    bake_free(&b);
}

/* --- one corruption per rule ---------------------------------------------------------------- */

#define CASE(label, mutate, s1, s2)          \
    do {                                     \
        bake_init(&b);                       \
        mutate;                              \
        expect_bake_fail(label, &b, s1, s2); \
        bake_free(&b);                       \
    } while (0)

static void test_presence_and_header(void) {
    bake b;
    for (int k = 0; k < N_PROBE_SECS; k++) {
        char label[64];
        snprintf(label, sizeof label, "without %s", probe_order[k]);
        CASE(label, b.skip_probe = k, probe_order[k], "missing (the probe sections");
    }
    CASE("PRBH 2 records", b.count[0] = 2, "PRBH", "exactly 1");
    CASE("PRBH 0 records", b.count[0] = 0, "PRBH", "exactly 1");
    CASE("n_probes 0", b.prbh[0].n_probes = 0, "PRBH", "n_probes 0");
    CASE("n_probes vs PRBP", b.prbh[0].n_probes = 3, "PRBH", "PRBP has 2");
    CASE("PRBP one short", b.count[1] = 1, "PRBH", "PRBP has 1");
    CASE("n_rays 0", b.prbh[0].n_rays = 0, "PRBH", "n_rays 0 is not in 1..65536");
    CASE("n_rays 65537", b.prbh[0].n_rays = 65537, "PRBH", "n_rays 65537");
    CASE("sh_bands 0", b.prbh[0].sh_bands = 0, "PRBH", "sh_bands 0 is not in 1..8");
    CASE("sh_bands 9", b.prbh[0].sh_bands = LC_LCB_PROBE_MAX_BANDS + 1, "PRBH", "sh_bands 9");
    CASE("n_clusters", b.prbh[0].n_clusters = 3, "PRBH", "n_clusters 3, PRCL has 2");
    CASE("n_rows", b.prbh[0].n_rows = 2, "PRBH", "n_rows 2, PRRW has 3");
    CASE("max_rank 0", b.prbh[0].max_rank = 0, "PRBH", "max_rank 0 is not in 1..256");
    CASE("max_rank 257", b.prbh[0].max_rank = LC_LCB_PROBE_MAX_RANK + 1, "PRBH", "max_rank 257");
    CASE("support_radius NaN", b.prbh[0].support_radius = NAN, "PRBH", "support_radius");
    CASE("support_radius < 0", b.prbh[0].support_radius = -1, "PRBH", "support_radius");
    CASE("svd_error inf", b.prbh[0].svd_error = INFINITY, "PRBH", "svd_error");
    CASE("svd_error < 0", b.prbh[0].svd_error = -0.5f, "PRBH", "svd_error");
    CASE("PRBR one short", b.count[2] = N_HIT - 1, "PRBR", "n_probes x n_rays is 2 x 4 = 8");
    CASE("PRBR vs n_rays", b.prbh[0].n_rays = 3, "PRBR", "2 x 3 = 6");
    /* 2^32-1 probes x 65536 rays: the product needs 48 bits (PRBP disagrees first, though) */
    CASE("n_probes huge", (b.prbh[0].n_probes = UINT32_MAX, b.prbh[0].n_rays = 65536), "PRBH", "n_probes");
    CASE("PRRW record size", (b.prrw_record = 4), "PRRW", "record size 4");
}

static void test_arrays(void) {
    bake b;
    CASE("probe position NaN", b.prbp[1].position[2] = NAN, "PRBP", "probe 1 position");
    CASE("probe position inf", b.prbp[0].position[0] = -INFINITY, "PRBP", "probe 0");
    CASE("hit surfel", b.prbr[5] = N_SURF, "PRBR", "probe 1 ray 1 hits surfel 4 >= 4");
    CASE("hit LC_NONE - 1", b.prbr[0] = LC_NONE - 1, "PRBR", "probe 0 ray 0");
    CASE("PRCP probe", b.prcp[2] = N_PROBE, "PRCP", "entry 2 is probe 2 >= 2");
    CASE("PRCP LC_NONE", b.prcp[0] = LC_NONE, "PRCP", "entry 0");
    CASE("row cache", b.prrw[1].cache = N_CACHE, "PRRW", "row 1 cache 13 >= 13");
    CASE("texel row coeff", b.prrw[0].coeff = 1, "PRRW", "texel");
    CASE("grid row coeff", b.prrw[2].coeff = 9, "PRRW", "grid");
    CASE("grid row coeff huge", b.prrw[1].coeff = LC_NONE, "PRRW", "in 0..8");
    CASE("basis NaN", b.prcb[15] = NAN, "PRCB", "value 15 is not finite");
    CASE("basis inf", b.prcb[0] = INFINITY, "PRCB", "value 0");
    CASE("U NaN", b.prru[4] = NAN, "PRRU", "value 4 is not finite");
    CASE("U -inf", b.prru[0] = -INFINITY, "PRRU", "value 0");
}

/* PRUF/PRUS: together, with the probes, offsets that tile PRUS, entries in range. */
static void test_unseen(void) {
    bake b;
    CASE("PRUF alone", b.unseen = 1, "PRUS", "PRUF and PRUS come together");
    CASE("PRUS alone", b.unseen = 2, "PRUF", "PRUF and PRUS come together");
    CASE("unseen rays without probes", b.with_probes = 0, "PRUF", "without the probe sections");
    CASE("PRUF one short", b.n_pruf = N_ROW, "PRUF", "3 offsets, expected PRBH n_rows + 1 = 4");
    CASE("PRUF first", b.pruf[0] = 1, "PRUF", "offset 0 is 1");
    CASE("PRUF decreasing", b.pruf[2] = 1, "PRUF", "row 1 ends at 1 before it starts (2)");
    CASE("PRUF end", b.pruf[3] = 2, "PRUF", "the rows end at entry 2, PRUS has 3 entries");
    CASE("PRUF end huge", b.pruf[3] = UINT32_MAX, "PRUF", "PRUS has 3 entries");
    CASE("PRUS surfel", b.prus[1].surfel = N_SURF, "PRUS", "entry 1 surfel 4 >= 4");
    CASE("PRUS surfel LC_NONE", b.prus[0].surfel = LC_NONE, "PRUS", "entry 0 surfel");
    CASE("PRUS weight NaN", b.prus[2].weight = NAN, "PRUS", "entry 2 weight is not finite");
    CASE("PRUS weight inf", b.prus[0].weight = INFINITY, "PRUS", "entry 0 weight");
}

/* TSGF/TSGW (texel caches gathered per surfel): read back as written, with or without the
 * probes; together, one offset per texel cache plus the end, entries in range. */
static void test_texel_surfels(void) {
    bake b;
    char err[512] = "";
    for (int probes = 0; probes < 2; probes++) {
        bake_init(&b);
        b.tsg = 3;
        b.with_probes = probes;
        b.unseen = probes ? 3 : 0;
        size_t len = 0;
        uint8_t *buf = bake_bytes(&b, &len);
        lc_lcb *f = NULL;
        CHECK(buf && lc_lcb_open_memory(buf, len, &f, err, sizeof err) == 0, "open with texel surfels: %s", err);
        if (f) {
            const lc_lcb_view *v = lc_lcb_get(f);
            CHECK(v->texel_surfels_first && memcmp(v->texel_surfels_first, b.tsgf, sizeof b.tsgf) == 0 &&
                      v->texel_surfels && memcmp(v->texel_surfels, b.tsgw, sizeof b.tsgw) == 0,
                  "texel surfel lists differ (probes %d)", probes);
            lc_lcb_close(f);
        }
        free(buf);
        bake_free(&b);
    }
    bake_init(&b);
    size_t len = 0;
    uint8_t *buf = bake_bytes(&b, &len);
    lc_lcb *f = NULL;
    CHECK(buf && lc_lcb_open_memory(buf, len, &f, err, sizeof err) == 0, "open without texel surfels: %s", err);
    if (f) {
        CHECK(!lc_lcb_get(f)->texel_surfels_first && !lc_lcb_get(f)->texel_surfels, "texel surfels set without TSGF");
        lc_lcb_close(f);
    }
    free(buf);
    bake_free(&b);
    CASE("TSGF alone", b.tsg = 1, "TSGW", "TSGF and TSGW come together");
    CASE("TSGW alone", b.tsg = 2, "TSGF", "TSGF and TSGW come together");
    CASE("TSGF one short", (b.tsg = 3, b.n_tsgf = N_TEXEL), "TSGF", "5 offsets, expected the texel caches + 1 = 6");
    CASE("TSGF first", (b.tsg = 3, b.tsgf[0] = 1), "TSGF", "offset 0 is 1");
    CASE("TSGF decreasing", (b.tsg = 3, b.tsgf[3] = 1), "TSGF", "row 2 ends at 1 before it starts (2)");
    CASE("TSGF end", (b.tsg = 3, b.tsgf[5] = 5), "TSGF", "the rows end at entry 5, TSGW has 4 entries");
    CASE("TSGW surfel", (b.tsg = 3, b.tsgw[2].surfel = N_SURF), "TSGW", "entry 2 surfel 4 >= 4");
    CASE("TSGW weight NaN", (b.tsg = 3, b.tsgw[1].weight = NAN), "TSGW", "entry 1 weight is not finite");
}

/* GLNK (--grid-links): grid caches' rows read back, lc_lcb_cache_links picks them; GLNK and
 * /links/grid_per_cache together, rows padded after link_count, the grid caches' LINK slots
 * all padding. */
static void test_grid_links(void) {
    bake b;
    char err[512] = "";
    bake_init(&b);
    bake_use_grid_links(&b, 3);
    size_t len = 0;
    uint8_t *buf = bake_bytes(&b, &len);
    lc_lcb *f = NULL;
    CHECK(buf && lc_lcb_open_memory(buf, len, &f, err, sizeof err) == 0, "open with grid links: %s", err);
    if (f) {
        const lc_lcb_view *v = lc_lcb_get(f);
        uint32_t per = 0;
        const lc_lcb_link *row = lc_lcb_cache_links(v, N_TEXEL + 2, &per);
        const lc_lcb_link *texel_row = lc_lcb_cache_links(v, 1, NULL);
        CHECK(v->grid_links && v->grid_links_per_cache == GRID_PER && memcmp(v->grid_links, b.glnk, sizeof b.glnk) == 0,
              "GLNK differs as read");
        CHECK(row == v->grid_links + 2 * GRID_PER && per == GRID_PER && texel_row == v->links + PER_CACHE,
              "lc_lcb_cache_links: a grid cache's row in GLNK, a texel cache's in LINK");
        char *info = info_text(f, 1);
        CHECK(info && strstr(info, "\"grid_links_per_cache\":\t4"), "info JSON: grid_links_per_cache (%s)", info);
        free(info);
        lc_lcb_close(f);
    }
    free(buf);
    bake_free(&b);
    CASE("GLNK without META", bake_use_grid_links(&b, 1), "GLNK", "META has no /links/grid_per_cache");
    CASE("META without GLNK", bake_use_grid_links(&b, 2), "GLNK", "required section missing");
    CASE("grid_per_cache 0", (bake_use_grid_links(&b, 3), free(b.meta), b.meta = bake_meta(PER_CACHE, 0)), "META",
         "/links/grid_per_cache must be an integer in 1..4096");
    CASE("GLNK one short", (bake_use_grid_links(&b, 3), b.n_glnk = N_GLNK - 1), "GLNK",
         "31 links, but META (/caches/count - /caches/texel) x /links/grid_per_cache is 32");
    CASE("GLNK node", (bake_use_grid_links(&b, 3), b.glnk[5].node = N_NODE), "GLNK", "link 5 has node 7 (of 7)");
    CASE("GLNK factor NaN", (bake_use_grid_links(&b, 3), b.glnk[1].factor = NAN), "GLNK", "link 1 has node");
    CASE("GLNK past link_count", (bake_use_grid_links(&b, 3), b.glnk[GRID_PER + 3].factor = 0.5f), "GLNK",
         "cache 6 slot 3 lies past its link_count 3");
    CASE("grid link_count", (bake_use_grid_links(&b, 3), b.cache[N_TEXEL].link_count = GRID_PER + 1), "CACH",
         "cache 5 has link_count 5 > /links/grid_per_cache 4");
    CASE("grid cache LINK slot", (bake_use_grid_links(&b, 3), b.link[(N_TEXEL + 1) * PER_CACHE + 1].factor = 0.1f),
         "LINK", "grid cache 6 slot 1 is not padding");
}

static void test_clusters(void) {
    bake b;
    CASE("first cluster not at row 0", b.prcl[0].first_row = 1, "PRCL", "cluster 0 first_row 1, expected 0");
    CASE("gap between clusters", b.prcl[1].first_row = 2, "PRCL", "cluster 1 first_row 2, expected 1");
    CASE("overlapping clusters", b.prcl[1].first_row = 0, "PRCL", "cluster 1 first_row 0");
    CASE("clusters end early", b.prcl[1].n_rows = 1, "PRCL", "end at row 2, PRRW has 3");
    CASE("cluster past PRRW", b.prcl[1].n_rows = 3, "PRCL", "exceed PRRW");
    CASE("cluster rows huge", b.prcl[1].n_rows = UINT32_MAX, "PRCL", "exceed PRRW");
    CASE("cluster no rows", b.prcl[0].n_rows = 0, "PRCL", "cluster 0 has n_rows 0");
    CASE("cluster no probes", b.prcl[1].n_probes = 0, "PRCL", "n_probes 0");
    CASE("cluster probes past PRCP", b.prcl[1].n_probes = 2, "PRCL", "probes [2, +2) exceed PRCP (3");
    CASE("cluster probes wrap", b.prcl[1].first_probe = UINT32_MAX, "PRCL", "exceed PRCP");
    CASE("rank 0", b.prcl[0].rank = 0, "PRCL", "rank 0 is not in 1..2");
    CASE("rank > max_rank", b.prcl[1].rank = 3, "PRCL", "rank 3 is not in 1..2");
    CASE("basis past PRCB", b.prcl[1].basis_offset = 9, "PRCL", "basis [9, +8) exceeds PRCB (16");
    CASE("basis offset wraps", b.prcl[1].basis_offset = UINT64_MAX - 3, "PRCL", "exceeds PRCB");
    CASE("basis too big", (b.prbh[0].max_rank = 256, b.prcl[0].rank = 256), "PRCL", "exceeds PRCB");
    CASE("U past PRRU", b.prcl[1].u_offset = 2, "PRCL", "U [2, +4) exceeds PRRU (5");
    CASE("U offset wraps", b.prcl[0].u_offset = UINT64_MAX, "PRCL", "exceeds PRRU");
    CASE("U one past PRRU", b.prcl[0].u_offset = N_U, "PRCL", "U [5, +1) exceeds PRRU (5");
}
#undef CASE

/* --- robustness: truncations and mutations of the probe sections ----------------------------- */

static void test_robustness(void) {
    bake b;
    bake_init(&b);
    size_t len = 0;
    char err[512];
    uint8_t *buf = bake_bytes(&b, &len);
    CHECK(buf != NULL, "write");
    if (!buf) {
        bake_free(&b);
        return;
    }
    int failed_ok = 1;
    for (size_t cut = 0; cut < len; cut++)
        if (lcb_test_try_open(buf, cut, err, sizeof err) == 0 || !err[0]) failed_ok = 0;
    CHECK(failed_ok, "a truncation opened or failed without a message");
    /* Random values in the probe sections' records (the table's other sections untouched):
     * either it opens or it says why; ASan/UBSan catch any bad read. */
    const lc_lcb_section *t = (const lc_lcb_section *)(buf + 64);
    uint32_t n = ((const lc_lcb_header *)buf)->section_count, first = n - N_PROBE_SECS;
    uint8_t *copy = malloc(len);
    int opened = 0, rejected = 0;
    for (int it = 0; copy && it < 3000; it++) {
        memcpy(copy, buf, len);
        for (int m = 0; m < 1 + (int)(lcb_test_rnd() % 3); m++) {
            const lc_lcb_section *s = &t[first + lcb_test_rnd() % N_PROBE_SECS];
            if (!s->size) continue;
            size_t off = (size_t)(s->offset + lcb_test_rnd() % s->size);
            uint64_t r = lcb_test_rnd();
            if (r % 4 == 0) copy[off] ^= (uint8_t)(1u << ((r >> 8) % 8));
            else if (r % 4 == 1) copy[off] = 0xFF;
            else if (r % 4 == 2) copy[off] = 0;
            else copy[off] = (uint8_t)(r >> 16);
        }
        lcb_test_fix_crcs(copy, len);
        if (lcb_test_try_open(copy, len, err, sizeof err) == 0) opened++;
        else if (err[0] && strstr(err, "PR")) rejected++;
        else CHECK(0, "mutation %d: message '%s' names no probe section", it, err);
    }
    CHECK(opened > 0 && rejected > 0, "mutations: %d opened, %d rejected", opened, rejected);
    free(copy);
    free(buf);
    bake_free(&b);
}

static void write_corpus(const char *dir) {
    bake b;
    bake_init(&b);
    b.tsg = 3;                  /* the texel surfel lists too */
    bake_use_grid_links(&b, 3); /* and the grid caches' own links */
    size_t len = 0;
    uint8_t *buf = bake_bytes(&b, &len);
    char path[1024];
    snprintf(path, sizeof path, "%s/seed-probes-2x4.lcb", dir);
    FILE *f = fopen(path, "wb");
    CHECK(buf && f && fwrite(buf, 1, len, f) == len, "corpus %s", path);
    if (f) fclose(f);
    free(buf);
    bake_free(&b);
    fprintf(stderr, "wrote %s\n", path);
}

int main(void) {
    const char *t = getenv("TMPDIR");
    snprintf(tmpdir, sizeof tmpdir, "%s/lcb-probes-XXXXXX", t && *t ? t : "/tmp");
    if (!mkdtemp(tmpdir)) {
        fprintf(stderr, "mkdtemp: %s\n", strerror(errno));
        return 1;
    }
    test_round_trip();
    test_probes_only();
    test_presence_and_header();
    test_arrays();
    test_unseen();
    test_texel_surfels();
    test_grid_links();
    test_clusters();
    test_robustness();
    const char *corpus = getenv("LUCENT_WRITE_CORPUS");
    if (corpus && *corpus) write_corpus(corpus);
    rmdir(tmpdir);
    CHECK_DONE();
}
