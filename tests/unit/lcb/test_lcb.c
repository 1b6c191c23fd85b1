/* lcb writer/reader/info: a tiny but fully consistent bake round-trips exactly; every
 * truncation, every byte flip outside padding and a catalogue of semantic corruptions are
 * rejected with a message naming the section. With LUCENT_WRITE_CORPUS=dir it also writes
 * the fuzz seed corpus (valid and broken files) into dir. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <stdint.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "lcb_test_util.h"
#include "lcb/lcb.h"
#include "util/crc32.h"
#include "util/fsutil.h"
#include "util/half.h"

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
    LSH = 2,
    N_LKSH = N_LINK * LSH * LSH,
    N_AVRT = 3,
    N_ATRI = 1
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
    uint16_t lksh[N_LKSH];
    lc_lcb_asset asset[1];
    lc_lcb_asset_vertex avrt[N_AVRT];
    uint32_t aidx[3 * N_ATRI];
    char *meta; /* JSON text (malloc'd) */
    int with_lksh, with_assets;
    int skip;  /* index into section order to leave out, or -1 */
    int extra; /* add an unknown "XTRA" section */
} bake;

static char tmpdir[256];

static void bake_set_meta(bake *b, cJSON *m) {
    free(b->meta);
    b->meta = cJSON_PrintUnformatted(m);
    cJSON_Delete(m);
}

static cJSON *bake_meta(int link_sh) {
    cJSON *m = cJSON_CreateObject();
    cJSON_AddStringToObject(m, "format", "lucent-bake");
    cJSON_AddStringToObject(m, "source", "tests/quad.obj");
    cJSON *s = cJSON_AddObjectToObject(m, "settings");
    cJSON_AddStringToObject(s, "quality", "test");
    cJSON_AddNumberToObject(s, "seed", 1);
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
    cJSON_AddNumberToObject(l, "per_cache", PER_CACHE);
    cJSON_AddNumberToObject(l, "sh_bands", link_sh);
    return m;
}

static void bake_init(bake *b) {
    memset(b, 0, sizeof *b);
    b->with_lksh = b->with_assets = 1;
    b->skip = -1;
    snprintf(b->mat[0].name, sizeof b->mat[0].name, "white");
    snprintf(b->mat[1].name, sizeof b->mat[1].name, "red lamp");
    for (int k = 0; k < 3; k++) b->mat[0].base_color[k] = 0.8f;
    b->mat[1].base_color[0] = 0.9f;
    b->mat[1].emission[0] = 10;
    b->mat[1].flags = 1;
    for (int i = 0; i < N_VERT; i++) {
        float x = (float)(i == 1 || i == 2), y = (float)(i >= 2);
        lc_lcb_vertex *v = &b->vert[i];
        v->position[0] = x;
        v->position[1] = y;
        v->normal[2] = 1;
        v->uv1[0] = x;
        v->uv1[1] = 1 - y;
    }
    b->tri[0] = (lc_lcb_triangle){{0, 1, 2}, 0};
    b->tri[1] = (lc_lcb_triangle){{0, 2, 3}, 1};
    for (int i = 0; i < N_SURF; i++) {
        lc_lcb_surfel *s = &b->surf[i];
        s->position[0] = 0.25f + 0.5f * (float)(i % 2);
        s->position[1] = 0.25f + 0.5f * (float)(i / 2);
        s->normal[2] = 1;
        for (int k = 0; k < 3; k++) s->albedo[k] = 0.5f + 0.1f * (float)i;
        s->emission[0] = i == 3 ? 10.0f : 0.0f;
        s->area = 0.25f;
        s->material = (uint32_t)(i % 2);
        s->cache = i < 3 ? (uint32_t)i : LC_NONE;
        s->reserved = 0;
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
        for (uint32_t s = first[i]; s < first[i] + count[i]; s++)
            for (int k = 0; k < 3; k++) n->center[k] += b->surf[s].position[k] / (float)count[i];
        n->normal[2] = 1;
        n->radius = count[i] == 1 ? 0.0f : 0.36f * (float)count[i];
    }
    static const uint32_t levl[N_LEVL] = {0, 1, 3, 7};
    memcpy(b->levl, levl, sizeof levl);
    /* Texel caches own texels 0,1,5,6,10; 2,4,9,11 are dilated copies; the rest empty. */
    static const uint32_t owned[N_TEXEL] = {0, 1, 5, 6, 10};
    for (int t = 0; t < LM_W * LM_H; t++) b->lmap[t] = LC_NONE;
    for (int i = 0; i < N_TEXEL; i++) {
        lc_lcb_cache *c = &b->cache[i];
        c->flags = LC_CACHE_TEXEL;
        c->index = owned[i];
        c->position[0] = ((float)(owned[i] % LM_W) + 0.5f) / LM_W;
        c->position[1] = ((float)(owned[i] / LM_W) + 0.5f) / LM_H;
        c->normal[2] = 1;
        for (int k = 0; k < 3; k++) c->albedo[k] = 0.7f;
        b->lmap[owned[i]] = (uint32_t)i;
    }
    b->lmap[2] = 1;
    b->lmap[4] = 0;
    b->lmap[9] = 2;
    b->lmap[11] = 4;
    for (int i = 0; i < N_CELL; i++) {
        lc_lcb_cache *c = &b->cache[N_TEXEL + i];
        c->flags = LC_CACHE_GRID | (i == 1 ? LC_CACHE_MOVED : 0) | (i == 2 ? LC_CACHE_INSIDE : 0);
        c->index = (uint32_t)i;
        c->position[0] = -1 + 0.5f * (float)(i % 2);
        c->position[1] = -0.5f + 0.5f * (float)((i / 2) % 2);
        c->position[2] = 0.25f + 0.5f * (float)(i / 4);
        b->grid[i] = (uint32_t)(N_TEXEL + i);
    }
    for (int c = 0; c < N_CACHE; c++) {
        float dir[3] = {0.6f, 0, 0.8f};
        b->link[c * 2] = (lc_lcb_link){(uint32_t)(c % N_NODE), 0.1f * (float)(c + 1), lc_link_pack(dir, 0.3f)};
        b->link[c * 2 + 1] = (lc_lcb_link){0, 0, 0}; /* padding link */
        b->cache[c].link_count = 1;
    }
    for (int i = 0; i < N_LKSH; i++) b->lksh[i] = lc_half_from_float(0.01f * (float)i - 0.2f);
    lc_lcb_asset *a = &b->asset[0];
    snprintf(a->name, sizeof a->name, "ball");
    a->vertex_count = N_AVRT;
    a->triangle_count = N_ATRI;
    a->bounds_max[0] = a->bounds_max[1] = 1;
    for (int k = 0; k < 3; k++) a->albedo[k] = 0.5f;
    for (int i = 0; i < N_AVRT; i++) {
        b->avrt[i].position[0] = (float)(i == 1);
        b->avrt[i].position[1] = (float)(i == 2);
        b->avrt[i].normal[2] = 1;
        for (int k = 0; k < 3; k++) b->avrt[i].albedo[k] = 0.5f;
    }
    b->aidx[0] = 0;
    b->aidx[1] = 1;
    b->aidx[2] = 2;
    bake_set_meta(b, bake_meta(LSH));
}

static void bake_free(bake *b) {
    free(b->meta);
    b->meta = NULL;
}

/* Section order of the writer, as the real bake writes them. */
static const char *const order[] = {"META", "MATL", "VERT", "TRIS", "SURF", "NODE", "LEVL", "CACH",
                                    "LMAP", "GRID", "LINK", "LKSH", "ASET", "AVRT", "AIDX"};

static int bake_write(const bake *b, const char *path, char *err, size_t errlen) {
    struct {
        uint32_t rec;
        const void *data;
        uint64_t n;
    } s[] = {
        {1, b->meta, strlen(b->meta)},
        {sizeof(lc_lcb_material), b->mat, N_MAT},
        {sizeof(lc_lcb_vertex), b->vert, N_VERT},
        {sizeof(lc_lcb_triangle), b->tri, N_TRI},
        {sizeof(lc_lcb_surfel), b->surf, N_SURF},
        {sizeof(lc_lcb_node), b->node, N_NODE},
        {4, b->levl, N_LEVL},
        {sizeof(lc_lcb_cache), b->cache, N_CACHE},
        {4, b->lmap, LM_W * LM_H},
        {4, b->grid, N_CELL},
        {sizeof(lc_lcb_link), b->link, N_LINK},
        {2, b->lksh, N_LKSH},
        {sizeof(lc_lcb_asset), b->asset, 1},
        {sizeof(lc_lcb_asset_vertex), b->avrt, N_AVRT},
        {12, b->aidx, N_ATRI},
    };
    lc_lcb_writer *w = lc_lcb_writer_create();
    int rc = -1;
    if (!w) return -1;
    for (int i = 0; i < (int)(sizeof s / sizeof s[0]); i++) {
        if (i == b->skip || (i == 11 && !b->with_lksh) || (i >= 12 && !b->with_assets)) continue;
        if (lc_lcb_writer_add(w, order[i], s[i].rec, s[i].data, s[i].n) != 0) goto err;
    }
    static const char extra[40] = "an unknown future section";
    if (b->extra && lc_lcb_writer_add(w, "XTRA", 8, extra, 5) != 0) goto err;
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

static lc_lcb_header *hdr_of(uint8_t *buf) { return (lc_lcb_header *)buf; }
static lc_lcb_section *table_of(uint8_t *buf) { return (lc_lcb_section *)(buf + 64); }

static int section_index(uint8_t *buf, const char *id) {
    for (uint32_t i = 0; i < hdr_of(buf)->section_count; i++)
        if (memcmp(table_of(buf)[i].id, id, 4) == 0) return (int)i;
    return -1;
}

static void expect_fail(const char *label, const void *buf, size_t len, const char *s1, const char *s2) {
    char err[512];
    int rc = lcb_test_try_open(buf, len, err, sizeof err);
    CHECK(rc != 0, "%s: opened but should have failed", label);
    CHECK(err[0] && strstr(err, s1) && (!s2 || strstr(err, s2)), "%s: message '%s' lacks '%s'%s%s", label, err, s1,
          s2 ? " / " : "", s2 ? s2 : "");
}

static void expect_bake_fail(const char *label, const bake *b, const char *s1, const char *s2) {
    size_t len = 0;
    uint8_t *buf = bake_bytes(b, &len);
    CHECK(buf != NULL, "%s: could not write", label);
    if (buf) expect_fail(label, buf, len, s1, s2);
    free(buf);
}

static void expect_bake_ok(const char *label, const bake *b) {
    size_t len = 0;
    char err[512] = "";
    uint8_t *buf = bake_bytes(b, &len);
    CHECK(buf && lcb_test_try_open(buf, len, err, sizeof err) == 0, "%s: failed: %s", label, err);
    free(buf);
}

/* --- round trip ------------------------------------------------------------------------ */

static void test_round_trip(void) {
    bake b;
    bake_init(&b);
    char path[512], err[512] = "";
    snprintf(path, sizeof path, "%s/rt.lcb", tmpdir);
    CHECK(bake_write(&b, path, err, sizeof err) == 0, "write: %s", err);
    lc_lcb *f = NULL;
    CHECK(lc_lcb_open(path, &f, err, sizeof err) == 0, "open: %s", err);
    if (!f) {
        bake_free(&b);
        return;
    }
    const lc_lcb_view *v = lc_lcb_get(f);
    CHECK(v->version_major == 1 && v->version_minor == 0, "version %u.%u", v->version_major, v->version_minor);
    CHECK(v->meta_len == strlen(b.meta) && strcmp(v->meta_json, b.meta) == 0, "META text differs");
    CHECK(v->sh_bands == 2, "sh_bands %u", v->sh_bands);
#define SAME(ptr, n, arr, cnt) \
    CHECK((n) == (cnt) && (ptr) && memcmp((ptr), (arr), sizeof(arr)) == 0, #arr " differs (count %u)", (unsigned)(n))
    SAME(v->materials, v->n_materials, b.mat, N_MAT);
    SAME(v->vertices, v->n_vertices, b.vert, N_VERT);
    SAME(v->triangles, v->n_triangles, b.tri, N_TRI);
    SAME(v->surfels, v->n_surfels, b.surf, N_SURF);
    SAME(v->nodes, v->n_nodes, b.node, N_NODE);
    SAME(v->levels, v->n_levels + 1, b.levl, N_LEVL);
    SAME(v->caches, v->n_caches, b.cache, N_CACHE);
    SAME(v->lightmap, v->lightmap_width * v->lightmap_height, b.lmap, LM_W * LM_H);
    SAME(v->grid, v->grid_dims[0] * v->grid_dims[1] * v->grid_dims[2], b.grid, N_CELL);
    SAME(v->links, v->n_caches * v->links_per_cache, b.link, N_LINK);
    SAME(v->link_sh, v->n_caches * v->links_per_cache * v->link_sh_bands * v->link_sh_bands, b.lksh, N_LKSH);
    SAME(v->assets, v->n_assets, b.asset, 1);
    SAME(v->asset_vertices, v->n_asset_vertices, b.avrt, N_AVRT);
    SAME(v->asset_indices, v->n_asset_triangles, b.aidx, N_ATRI);
#undef SAME
    CHECK(v->n_levels == 3, "n_levels %u", v->n_levels);
    CHECK(v->n_texel_caches == N_TEXEL, "texel caches %u", v->n_texel_caches);
    CHECK(v->lightmap_width == LM_W && v->lightmap_height == LM_H, "lightmap %ux%u", v->lightmap_width,
          v->lightmap_height);
    CHECK(v->grid_dims[0] == 2 && v->grid_dims[1] == 2 && v->grid_dims[2] == 2, "grid dims");
    CHECK(v->grid_origin[0] == -1 && v->grid_origin[1] == -0.5f && v->grid_origin[2] == 0.25f, "grid origin");
    CHECK(v->grid_cell == 0.5f, "grid cell %g", v->grid_cell);
    CHECK(v->links_per_cache == PER_CACHE && v->link_sh_bands == LSH, "links %u/%u", v->links_per_cache,
          v->link_sh_bands);
    CHECK(lc_lcb_section_count(f) == 15, "section count %u", lc_lcb_section_count(f));
    for (uint32_t i = 0; i < lc_lcb_section_count(f); i++) {
        const lc_lcb_section *s = lc_lcb_section_at(f, i);
        CHECK(memcmp(s->id, order[i], 4) == 0 && s->offset % 64 == 0, "section %u", i);
    }
    CHECK(lc_lcb_section_at(f, 15) == NULL, "section_at out of range");

    /* info, both modes */
    FILE *tf = tmpfile();
    lc_lcb_print_info(f, path, 0, tf);
    long n = ftell(tf);
    rewind(tf);
    char *text = calloc(1, (size_t)n + 1);
    CHECK(fread(text, 1, (size_t)n, tf) == (size_t)n, "read info");
    fclose(tf);
    CHECK(strstr(text, "1.0") && strstr(text, "tests/quad.obj") && strstr(text, "quality") &&
              strstr(text, "13: 5 texel, 8 grid, 1 moved, 1 inside") && strstr(text, "4x4") && strstr(text, "LKSH") &&
              strstr(text, "2x2x2"),
          "human info:\n%s", text);
    free(text);
    tf = tmpfile();
    lc_lcb_print_info(f, path, 1, tf);
    n = ftell(tf);
    rewind(tf);
    text = calloc(1, (size_t)n + 1);
    CHECK(fread(text, 1, (size_t)n, tf) == (size_t)n, "read info");
    fclose(tf);
    cJSON *j = cJSON_Parse(text);
    CHECK(j != NULL, "JSON info does not parse:\n%s", text);
    const cJSON *secs = cJSON_GetObjectItem(j, "sections"), *meta = cJSON_GetObjectItem(j, "meta");
    const cJSON *counts = cJSON_GetObjectItem(j, "counts");
    CHECK(cJSON_GetArraySize(secs) == 15, "JSON sections");
    CHECK(cJSON_IsString(cJSON_GetObjectItem(meta, "format")), "JSON meta copy");
    CHECK(cJSON_GetObjectItem(counts, "caches") && cJSON_GetObjectItem(counts, "caches")->valuedouble == N_CACHE &&
              cJSON_GetObjectItem(counts, "moved_caches")->valuedouble == 1,
          "JSON counts");
    const cJSON *lm = cJSON_GetObjectItem(counts, "lightmap");
    CHECK(lm && cJSON_GetObjectItem(lm, "owned")->valuedouble == 5 &&
              cJSON_GetObjectItem(lm, "dilated")->valuedouble == 4,
          "JSON lightmap usage");
    cJSON_Delete(j);
    free(text);
    lc_lcb_close(f);
    lc_lcb_close(NULL);
    unlink(path);

    /* Misaligned caller buffer: validated on an aligned copy, same content. */
    size_t len;
    uint8_t *buf = bake_bytes(&b, &len);
    uint8_t *odd = malloc(len + 1);
    memcpy(odd + 1, buf, len);
    CHECK(lc_lcb_open_memory(odd + 1, len, &f, err, sizeof err) == 0, "misaligned open: %s", err);
    if (f) {
        CHECK(((uintptr_t)lc_lcb_get(f)->nodes % 8) == 0 && lc_lcb_get(f)->nodes[0].surfel_count == 4,
              "misaligned view");
        lc_lcb_close(f);
    }
    free(odd);
    free(buf);
    bake_free(&b);
}

static void test_determinism_and_api(void) {
    bake b;
    bake_init(&b);
    size_t l1, l2;
    uint8_t *a = bake_bytes(&b, &l1), *c = bake_bytes(&b, &l2);
    CHECK(a && c && l1 == l2 && memcmp(a, c, l1) == 0, "two writes differ");
    CHECK(l1 % 64 == 0, "file size %zu not 64-aligned", l1);
    free(a);
    free(c);

    lc_lcb_writer *w = lc_lcb_writer_create();
    uint32_t x[4] = {0};
    CHECK(lc_lcb_writer_add(w, "ABCD", 4, x, 4) == 0, "add");
    CHECK(lc_lcb_writer_add(w, "ABCD", 4, x, 4) != 0, "duplicate id accepted");
    CHECK(lc_lcb_writer_add(w, "EFGH", 0, x, 4) != 0, "record size 0 accepted");
    CHECK(lc_lcb_writer_add(w, "EFGH", 4, NULL, 4) != 0, "NULL data accepted");
    CHECK(lc_lcb_writer_add(w, "EFGH", 1u << 31, x, UINT64_MAX / 2) != 0, "overflowing size accepted");
    int added = 1;
    for (int i = 0; i < 100; i++) {
        char id[4] = {'S', (char)('0' + i / 10), (char)('0' + i % 10), 'x'};
        if (lc_lcb_writer_add(w, id, 4, x, 1) == 0) added++;
    }
    CHECK(added == LC_LCB_MAX_SECTIONS, "added %d sections", added);
    char err[512], path[512];
    snprintf(path, sizeof path, "%s/nodir/x.lcb", tmpdir);
    CHECK(lc_lcb_writer_write(w, path, err, sizeof err) != 0 && err[0], "write into a missing dir");
    lc_lcb_writer_release(w);
    lc_lcb_writer_release(NULL);

    lc_lcb *f = NULL;
    CHECK(lc_lcb_open(path, &f, err, sizeof err) != 0 && strstr(err, "nodir"), "missing file: '%s'", err);
    CHECK(lc_lcb_open(tmpdir, &f, err, sizeof err) != 0 && strstr(err, "regular"), "directory: '%s'", err);
    snprintf(path, sizeof path, "%s/empty.lcb", tmpdir);
    FILE *e = fopen(path, "wb");
    fclose(e);
    CHECK(lc_lcb_open(path, &f, err, sizeof err) != 0 && strstr(err, "header"), "empty file: '%s'", err);
    unlink(path);
    CHECK(f == NULL, "handle set on failure");
    bake_free(&b);
}

/* --- truncation and byte flips ---------------------------------------------------------- */

static void test_truncation(void) {
    bake b;
    bake_init(&b);
    size_t len;
    uint8_t *buf = bake_bytes(&b, &len);
    uint32_t n = hdr_of(buf)->section_count;
    size_t table_end = 64 + 48 * (size_t)n;
    /* every length short of the whole file: the header, the table, each section's first,
     * middle and last byte, and the padding between sections */
    int tested = 0;
    for (size_t cut = 0; cut < len; cut++) {
        char label[64], want[8] = "";
        snprintf(label, sizeof label, "truncated at %zu of %zu", cut, len);
        const char *expect = "truncated";
        if (cut < 64) {
            expect = "header";
        } else if (cut < table_end) {
            expect = "section table";
        } else {
            for (uint32_t i = 0; i < n; i++) {
                const lc_lcb_section *s = &table_of(buf)[i];
                if (s->offset + s->size > cut) {
                    memcpy(want, s->id, 4);
                    break;
                }
            }
        }
        expect_fail(label, buf, cut, expect, want[0] ? want : NULL);
        tested++;
    }
    CHECK(tested == (int)len && len > 1000, "%d truncations of a %zu-byte file", tested, len);
    free(buf);
    bake_free(&b);
}

/* The same on a real bake (the build's cornell.lcb, from lucent-bake: every section kind a
 * bake writes, at its real sizes), in place of one `lucent-bake verify` per case: truncated
 * at 0, 1, the header and table ends and around every section's start and end, and 300 bit
 * flips inside the header, the table and the sections, each rejected with a message naming
 * where. Skipped (noted) when the build has no cornell.lcb. */
static void test_real_bake(void) {
    const char *bin = getenv("LUCENT_BINARY_DIR");
    char path[1024];
    snprintf(path, sizeof path, "%s/cornell.lcb", bin && *bin ? bin : ".");
    FILE *fh = fopen(path, "rb");
    if (!fh) {
        fprintf(stderr, "note: %s not built; the real-bake truncations and flips are skipped\n", path);
        return;
    }
    fseek(fh, 0, SEEK_END);
    long flen = ftell(fh);
    fseek(fh, 0, SEEK_SET);
    size_t len = flen > 0 ? (size_t)flen : 0;
    uint8_t *buf = malloc(len ? len : 1);
    CHECK(buf && len > 4096 && fread(buf, 1, len, fh) == len, "read %s (%zu bytes)", path, len);
    fclose(fh);
    char err[512];
    if (!buf || len <= 4096 || lcb_test_try_open(buf, len, err, sizeof err) != 0) {
        CHECK(0, "%s does not open: %s", path, buf ? err : "");
        free(buf);
        return;
    }
    uint32_t n = hdr_of(buf)->section_count;
    size_t table_end = 64 + 48 * (size_t)n;
    size_t cuts[64 + 8 * LC_LCB_MAX_SECTIONS];
    int nc = 0;
    size_t fixed[] = {0, 1, 40, 63, 64, 65, table_end - 1, table_end, table_end + 1, len / 2, len - 1};
    for (size_t k = 0; k < sizeof fixed / sizeof fixed[0]; k++) cuts[nc++] = fixed[k];
    for (uint32_t i = 0; i < n && i < LC_LCB_MAX_SECTIONS; i++) {
        const lc_lcb_section *s = &table_of(buf)[i];
        size_t ends[2] = {(size_t)s->offset, (size_t)(s->offset + s->size)};
        for (int k = 0; k < 2; k++)
            for (int d = -1; d <= 1; d++) cuts[nc++] = ends[k] + (size_t)d;
    }
    int tested = 0;
    for (int k = 0; k < nc; k++) {
        size_t cut = cuts[k];
        if (cut >= len) continue;
        char label[80], want[8] = "";
        snprintf(label, sizeof label, "cornell.lcb truncated at %zu of %zu", cut, len);
        const char *expect = cut < 64 ? "header" : cut < table_end ? "section table" : "truncated";
        for (uint32_t i = 0; cut >= table_end && i < n; i++) {
            const lc_lcb_section *s = &table_of(buf)[i];
            if (s->offset + s->size > cut) {
                memcpy(want, s->id, 4);
                break;
            }
        }
        expect_fail(label, buf, cut, expect, want[0] ? want : NULL);
        tested++;
    }
    CHECK(tested >= 6 * (int)n, "only %d truncations of %s", tested, path);
    /* flips inside what the CRCs cover: the header, the table, the sections */
    uint8_t *copy = malloc(len);
    int flips = 0;
    for (int it = 0; copy && it < 300; it++) {
        uint32_t pick = (uint32_t)(lcb_test_rnd() % (n + 1));
        size_t lo = 0, hi = table_end;
        char id[5] = "";
        if (pick < n) {
            const lc_lcb_section *s = &table_of(buf)[pick];
            lo = (size_t)s->offset;
            hi = (size_t)(s->offset + s->size);
            memcpy(id, s->id, 4);
        }
        if (hi <= lo) continue;
        size_t off = lo + (size_t)(lcb_test_rnd() % (hi - lo));
        uint8_t x = (uint8_t)(1u << (lcb_test_rnd() % 8));
        memcpy(copy, buf, len);
        copy[off] ^= x;
        char label[80];
        snprintf(label, sizeof label, "cornell.lcb flip 0x%02x at %zu", x, off);
        if (id[0]) expect_fail(label, copy, len, id, "CRC");
        else expect_fail(label, copy, len, off < 64 ? "header" : "section table", NULL);
        flips++;
    }
    CHECK(flips > 250, "only %d flips of %s", flips, path);
    free(copy);
    free(buf);
}

static void test_flips(void) {
    bake b;
    bake_init(&b);
    size_t len;
    uint8_t *buf = bake_bytes(&b, &len);
    uint8_t *copy = malloc(len);
    uint32_t n = hdr_of(buf)->section_count;
    size_t table_end = 64 + 48 * (size_t)n;
    int covered = 0, padding = 0;
    for (int it = 0; it < 2000; it++) {
        size_t off = (size_t)(lcb_test_rnd() % len);
        uint8_t x = (uint8_t)(1 + lcb_test_rnd() % 255);
        memcpy(copy, buf, len);
        copy[off] ^= x;
        const char *want = off < 64 ? "header" : off < table_end ? "section table" : NULL;
        char id[5] = "";
        for (uint32_t i = 0; !want && i < n; i++) {
            const lc_lcb_section *s = &table_of(buf)[i];
            if (off >= s->offset && off < s->offset + s->size) {
                memcpy(id, s->id, 4);
                want = id;
            }
        }
        char label[64], err[512];
        snprintf(label, sizeof label, "flip 0x%02x at %zu", x, off);
        if (want) {
            covered++;
            expect_fail(label, copy, len, want, off >= table_end ? "CRC" : NULL);
        } else {
            padding++;
            CHECK(lcb_test_try_open(copy, len, err, sizeof err) == 0, "%s (padding) rejected: %s", label, err);
        }
    }
    CHECK(covered > 1500 && padding > 0, "flips: %d covered, %d in padding", covered, padding);
    free(copy);
    free(buf);
    bake_free(&b);
}

/* --- header/table corruptions (CRCs recomputed) --------------------------------------------- */

static void test_structure(void) {
    bake b;
    bake_init(&b);
    size_t len;
    uint8_t *buf = bake_bytes(&b, &len);
    uint8_t *c = malloc(len + 64);
    char err[512];
#define RESET() memcpy(c, buf, len)
    RESET();
    c[0] ^= 0x20;
    expect_fail("magic", c, len, "header", "magic");
    RESET();
    hdr_of(c)->version_major = 2;
    lcb_test_fix_crcs(c, len);
    expect_fail("version 2", c, len, "version 2.0 is newer", "upgrade lucent");
    RESET();
    hdr_of(c)->version_major = 0;
    lcb_test_fix_crcs(c, len);
    expect_fail("version 0", c, len, "header", "older");
    RESET();
    hdr_of(c)->version_minor = 7;
    lcb_test_fix_crcs(c, len);
    CHECK(lcb_test_try_open(c, len, err, sizeof err) == 0, "minor version 7 rejected: %s", err);
    RESET();
    hdr_of(c)->header_crc ^= 1;
    expect_fail("header crc", c, len, "header", "CRC");
    RESET();
    hdr_of(c)->table_offset = 128;
    lcb_test_fix_crcs(c, len);
    expect_fail("table offset", c, len, "header", "table_offset");
    RESET();
    hdr_of(c)->section_count = 65;
    lcb_test_fix_crcs(c, len);
    expect_fail("section count", c, len, "header", "section_count");
    RESET();
    hdr_of(c)->section_count = 200000; /* table would be far outside: count check first */
    hdr_of(c)->header_crc = lc_crc32(0, c, 60);
    expect_fail("huge section count", c, len, "header", "section_count");
    RESET();
    table_of(c)[3].count ^= 1;
    expect_fail("table crc", c, len, "section table", "CRC");
    RESET();
    memset(c + len, 0, 64);
    expect_fail("trailing data", c, len + 64, "header", "trailing");
    RESET();
    hdr_of(c)->file_size += 64;
    lcb_test_fix_crcs(c, len);
    expect_fail("file_size too big", c, len, "truncated", NULL);

    int surf = section_index(c, "SURF"), node = section_index(c, "NODE"), last = (int)hdr_of(c)->section_count - 1;
    RESET();
    table_of(c)[node].offset = table_of(c)[surf].offset;
    lcb_test_fix_crcs(c, len);
    expect_fail("overlap", c, len, "NODE", "overlaps section SURF");
    RESET();
    table_of(c)[surf].offset = 128; /* inside the table */
    lcb_test_fix_crcs(c, len);
    expect_fail("overlap table", c, len, "SURF", "header/section table");
    RESET();
    table_of(c)[surf].offset += 4;
    lcb_test_fix_crcs(c, len);
    expect_fail("misaligned", c, len, "SURF", "not a multiple of 64");
    RESET();
    table_of(c)[last].offset = len;
    lcb_test_fix_crcs(c, len);
    expect_fail("outside", c, len, "AIDX", "outside the file");
    RESET();
    table_of(c)[last].size = UINT64_MAX - 8; /* offset + size would wrap */
    lcb_test_fix_crcs(c, len);
    expect_fail("wrapping size", c, len, "AIDX", "outside the file");
    RESET();
    table_of(c)[surf].count += 1;
    lcb_test_fix_crcs(c, len);
    expect_fail("size vs count", c, len, "SURF", "records");
    RESET();
    table_of(c)[surf].record_size = 0;
    lcb_test_fix_crcs(c, len);
    expect_fail("record size 0", c, len, "SURF", "record size");
    RESET();
    memcpy(table_of(c)[node].id, "SURF", 4);
    lcb_test_fix_crcs(c, len);
    expect_fail("duplicate", c, len, "SURF", "duplicate");
    RESET();
    c[table_of(c)[node].offset + 5] ^= 0x40;
    expect_fail("section crc", c, len, "NODE", "CRC mismatch");
    RESET();
    memcpy(table_of(c)[node].id, "NODX", 4); /* unknown id: ignored, so NODE is missing */
    lcb_test_fix_crcs(c, len);
    expect_fail("renamed", c, len, "NODE", "missing");
    RESET();
    table_of(c)[section_index(c, "LEVL")].record_size = 8;
    table_of(c)[section_index(c, "LEVL")].count = 2;
    lcb_test_fix_crcs(c, len);
    expect_fail("record size", c, len, "LEVL", "record size 8");
    RESET();
    uint64_t meta_off = table_of(c)[0].offset;
    c[meta_off + 3] = 0;
    lcb_test_fix_crcs(c, len);
    expect_fail("meta NUL", c, len, "META", "NUL");
#undef RESET
    free(c);
    free(buf);
    bake_free(&b);
}

/* --- semantic corruptions via the writer ----------------------------------------------- */

static cJSON *meta_at(cJSON *m, const char *obj) { return cJSON_GetObjectItem(m, obj); }

static void test_semantic(void) {
    bake b;
#define CASE(label, mutate, s1, s2)          \
    do {                                     \
        bake_init(&b);                       \
        mutate;                              \
        expect_bake_fail(label, &b, s1, s2); \
        bake_free(&b);                       \
    } while (0)
    /* sanity: the base bake and its variants open */
    bake_init(&b);
    expect_bake_ok("base", &b);
    b.extra = 1;
    expect_bake_ok("unknown section", &b);
    b.with_assets = 0;
    b.with_lksh = 0;
    bake_set_meta(&b, bake_meta(0));
    expect_bake_ok("minimal", &b);
    bake_free(&b);

    CASE("node child out of range", b.node[1].child[1] = 99, "NODE", "out of range");
    CASE("node one child", b.node[1].child[1] = LC_NONE, "NODE", "out of range");
    CASE("node child not in next level", (b.node[0].child[1] = 3), "NODE", "BFS");
    CASE("node children swapped", (b.node[0].child[0] = 2, b.node[0].child[1] = 1), "NODE", "partition");
    CASE("node two parents", (b.node[2].child[0] = 4), "NODE", "parent");
    CASE("leaf with 2 surfels", b.node[6].surfel_count = 2, "NODE", "partition");
    CASE("inner node as leaf", (b.node[1].child[0] = b.node[1].child[1] = LC_NONE), "NODE", "leaf");
    CASE("root range", b.node[0].first_surfel = 1, "NODE", "root");
    CASE("node radius", b.node[2].radius = -1, "NODE", "radius");
    CASE("node NaN", b.node[4].normal[0] = NAN, "NODE", "non-finite");
    CASE("levels not increasing", b.levl[2] = 1, "LEVL", "increasing");
    CASE("levels root", (b.levl[1] = 2, b.levl[2] = 3), "LEVL", "root");
    CASE("levels end", b.levl[3] = 6, "LEVL", "node count");
    CASE("LMAP entry", b.lmap[3] = N_CACHE, "LMAP", "cache 13");
    CASE("GRID entry", b.grid[7] = LC_NONE, "GRID", NULL);
    CASE("surfel NaN", b.surf[2].normal[1] = NAN, "SURF", "non-finite");
    CASE("surfel inf", b.surf[1].area = INFINITY, "SURF", "non-finite");
    CASE("surfel area 0", b.surf[0].area = 0, "SURF", "area");
    CASE("surfel material", b.surf[0].material = 2, "SURF", "material");
    CASE("surfel cache", b.surf[0].cache = N_CACHE, "SURF", "cache");
    CASE("triangle vertex", b.tri[1].v[2] = N_VERT, "TRIS", "vertex");
    CASE("triangle material", b.tri[0].material = N_MAT, "TRIS", "material");
    CASE("vertex NaN", b.vert[3].uv1[1] = NAN, "VERT", NULL);
    CASE("material name", memset(b.mat[1].name, 'x', sizeof b.mat[1].name), "MATL", "NUL");
    CASE("cache kind", b.cache[2].flags = LC_CACHE_GRID, "CACH", "texel");
    CASE("texel cache index", b.cache[4].index = LM_W * LM_H, "CACH", "texel");
    CASE("grid cache index", b.cache[N_CACHE - 1].index = N_CELL, "CACH", "grid");
    CASE("cache NaN", b.cache[7].albedo[2] = NAN, "CACH", "non-finite");
    CASE("link node", b.link[5].node = N_NODE, "LINK", NULL);
    CASE("link factor", b.link[5].factor = -0.5f, "LINK", NULL);
    CASE("link factor NaN", b.link[0].factor = NAN, "LINK", NULL);
    CASE("link past link_count", b.link[3].factor = 0.5f, "LINK", NULL);
    CASE("link_count too large", b.cache[1].link_count = 3, "CACH", NULL);
    CASE("LKSH inf", b.lksh[17] = 0x7C00, "LKSH", "inf");
    CASE("LKSH NaN", b.lksh[0] = 0xFE01, "LKSH", NULL);
    CASE("asset index", b.aidx[2] = N_AVRT, "AIDX", NULL);
    CASE("asset vertices", b.asset[0].vertex_count = N_AVRT + 1, "ASET", "AVRT");
    CASE("asset triangles", b.asset[0].first_triangle = 1, "ASET", "AIDX");
    CASE("asset name", memset(b.asset[0].name, 'a', sizeof b.asset[0].name), "ASET", "NUL");
    /* names reach every client (welcome, state, the snapshot file): UTF-8 only (issue 13) */
    CASE("material name Latin-1", strcpy(b.mat[1].name, "caf\xe9"), "MATL: material 1 name \"caf\\xe9\"",
         "not valid UTF-8");
    CASE("material name overlong", strcpy(b.mat[0].name, "a\xc0\xaf"), "MATL: material 0 name", "not valid UTF-8");
    CASE("material name surrogate", strcpy(b.mat[1].name, "\xed\xa0\x80"), "MATL: material 1 name", "not valid UTF-8");
    CASE("material name cut", strcpy(b.mat[1].name, "lamp \xe2\x82"), "MATL: material 1 name", "not valid UTF-8");
    CASE("asset name not UTF-8", strcpy(b.asset[0].name, "chair\xff"), "ASET: asset 0 name", "not valid UTF-8");
    bake_init(&b);
    strcpy(b.mat[0].name, "caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x92\xa1");
    strcpy(b.asset[0].name, "st\xc3\xbchl");
    expect_bake_ok("UTF-8 names", &b);
    bake_free(&b);
    CASE("asset vertex NaN", b.avrt[1].normal[0] = NAN, "AVRT", NULL);
    CASE("missing NODE", b.skip = 5, "NODE", "missing");
    CASE("missing META", b.skip = 0, "META", "missing");
    CASE("ASET without the others", b.skip = 13, "AVRT", "missing");
    CASE("LKSH missing", b.with_lksh = 0, "LKSH", "missing");
    CASE("LKSH present with sh_bands 0", bake_set_meta(&b, bake_meta(0)), "LKSH", "present");

    /* META field checks */
    cJSON *m;
#define META_CASE(label, edit, s1, s2) CASE(label, (m = bake_meta(LSH), (edit), bake_set_meta(&b, m)), s1, s2)
    META_CASE("sh_bands string", cJSON_ReplaceItemInObject(m, "sh_bands", cJSON_CreateString("2")), "META",
              "/sh_bands must be an integer in 1..8");
    META_CASE("sh_bands 9", cJSON_ReplaceItemInObject(m, "sh_bands", cJSON_CreateNumber(9)), "META", "/sh_bands");
    META_CASE("format", cJSON_ReplaceItemInObject(m, "format", cJSON_CreateString("other")), "META", "/format");
    META_CASE("no format", cJSON_DeleteItemFromObject(m, "format"), "META", "/format");
    META_CASE("width 0", cJSON_ReplaceItemInObject(meta_at(m, "lightmap"), "width", cJSON_CreateNumber(0)), "META",
              "/lightmap/width must be an integer in 1..16384");
    META_CASE("width 4.5", cJSON_ReplaceItemInObject(meta_at(m, "lightmap"), "width", cJSON_CreateNumber(4.5)), "META",
              "/lightmap/width");
    META_CASE("lightmap not object", cJSON_ReplaceItemInObject(m, "lightmap", cJSON_CreateTrue()), "META",
              "/lightmap/width");
    META_CASE("width mismatch", cJSON_ReplaceItemInObject(meta_at(m, "lightmap"), "width", cJSON_CreateNumber(5)),
              "LMAP", "5x4");
    META_CASE("origin 2", cJSON_DeleteItemFromArray(cJSON_GetObjectItem(meta_at(m, "grid"), "origin"), 0), "META",
              "/grid/origin");
    META_CASE("origin 1e300",
              cJSON_ReplaceItemInArray(cJSON_GetObjectItem(meta_at(m, "grid"), "origin"), 2, cJSON_CreateNumber(1e300)),
              "META", "/grid/origin");
    META_CASE("cell 0", cJSON_ReplaceItemInObject(meta_at(m, "grid"), "cell", cJSON_CreateNumber(0)), "META",
              "/grid/cell");
    META_CASE("dims 0",
              cJSON_ReplaceItemInArray(cJSON_GetObjectItem(meta_at(m, "grid"), "dims"), 1, cJSON_CreateNumber(0)),
              "META", "/grid/dims");
    META_CASE("dims mismatch",
              cJSON_ReplaceItemInArray(cJSON_GetObjectItem(meta_at(m, "grid"), "dims"), 1, cJSON_CreateNumber(3)),
              "GRID", NULL);
    META_CASE("dims too many cells",
              (cJSON_ReplaceItemInArray(cJSON_GetObjectItem(meta_at(m, "grid"), "dims"), 0, cJSON_CreateNumber(1024)),
               cJSON_ReplaceItemInArray(cJSON_GetObjectItem(meta_at(m, "grid"), "dims"), 1, cJSON_CreateNumber(1024)),
               cJSON_ReplaceItemInArray(cJSON_GetObjectItem(meta_at(m, "grid"), "dims"), 2, cJSON_CreateNumber(1024))),
              "META", "2^26");
    META_CASE("surfel count", cJSON_ReplaceItemInObject(meta_at(m, "surfels"), "count", cJSON_CreateNumber(5)), "SURF",
              "/surfels/count");
    META_CASE("surfel area", cJSON_ReplaceItemInObject(meta_at(m, "surfels"), "area", cJSON_CreateString("x")), "META",
              "/surfels/area");
    META_CASE("nodes", cJSON_ReplaceItemInObject(meta_at(m, "hierarchy"), "nodes", cJSON_CreateNumber(8)), "META",
              "/hierarchy/nodes");
    META_CASE("levels", cJSON_ReplaceItemInObject(meta_at(m, "hierarchy"), "levels", cJSON_CreateNumber(2)), "LEVL",
              NULL);
    META_CASE("cache count", cJSON_ReplaceItemInObject(meta_at(m, "caches"), "count", cJSON_CreateNumber(14)), "CACH",
              "/caches/count");
    META_CASE("texel > count", cJSON_ReplaceItemInObject(meta_at(m, "caches"), "texel", cJSON_CreateNumber(14)), "META",
              "/caches/texel");
    META_CASE("texel count", cJSON_ReplaceItemInObject(meta_at(m, "caches"), "texel", cJSON_CreateNumber(6)), "CACH",
              NULL);
    META_CASE("per_cache", cJSON_ReplaceItemInObject(meta_at(m, "links"), "per_cache", cJSON_CreateNumber(3)), "LINK",
              NULL);
    META_CASE("per_cache 0", cJSON_ReplaceItemInObject(meta_at(m, "links"), "per_cache", cJSON_CreateNumber(0)), "META",
              "/links/per_cache");
    META_CASE("link sh_bands", cJSON_ReplaceItemInObject(meta_at(m, "links"), "sh_bands", cJSON_CreateNumber(3)),
              "LKSH", NULL);
    META_CASE("link sh_bands -1", cJSON_ReplaceItemInObject(meta_at(m, "links"), "sh_bands", cJSON_CreateNumber(-1)),
              "META", "/links/sh_bands");
    META_CASE("light id not UTF-8",
              (cJSON_AddItemToObject(m, "lights", cJSON_CreateArray()),
               cJSON_AddItemToArray(cJSON_GetObjectItem(m, "lights"), cJSON_CreateObject()),
               cJSON_AddItemToArray(cJSON_GetObjectItem(m, "lights"), cJSON_CreateObject()),
               cJSON_AddStringToObject(cJSON_GetArrayItem(cJSON_GetObjectItem(m, "lights"), 0), "id", "lamp"),
               cJSON_AddStringToObject(cJSON_GetArrayItem(cJSON_GetObjectItem(m, "lights"), 1), "id", "l\xe9mpara")),
              "META: /lights/1/id", "not valid UTF-8");
#undef META_CASE
    /* raw text */
    CASE("not JSON", (free(b.meta), b.meta = strdup("{\"format\": \"lucent-bake\",")), "META", "JSON");
    CASE("not an object", (free(b.meta), b.meta = strdup("[1, 2]")), "META", "object");
    char *deep = malloc(400);
    strcpy(deep, "{\"x\":");
    for (int i = 0; i < 100; i++) strcat(deep, "[");
    for (int i = 0; i < 100; i++) strcat(deep, "]");
    strcat(deep, "}");
    CASE("deep nesting", (free(b.meta), b.meta = strdup(deep)), "META", "nested");
    free(deep);
    /* brackets inside strings do not count as nesting */
    bake_init(&b);
    m = bake_meta(LSH);
    cJSON_AddStringToObject(m, "note",
                            "[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[\\\"[[[[");
    bake_set_meta(&b, m);
    expect_bake_ok("brackets in strings", &b);
    bake_free(&b);
#undef CASE
}

/* --- seed corpus --------------------------------------------------------------------------- */

static void put(const char *dir, const char *name, const void *data, size_t len) {
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *f = fopen(path, "wb");
    CHECK(f && fwrite(data, 1, len, f) == len, "corpus %s", path);
    CHECK(len < 16384, "corpus file %s is %zu bytes", name, len);
    if (f) fclose(f);
}

static void write_corpus(const char *dir) {
    bake b;
    size_t len;
    uint8_t *buf;
    mkdir(dir, 0755);
    bake_init(&b);
    buf = bake_bytes(&b, &len);
    put(dir, "valid_full.lcb", buf, len);
    put(dir, "trunc_header.lcb", buf, 40);
    put(dir, "trunc_table.lcb", buf, 64 + 48 * 5);
    put(dir, "trunc_sections.lcb", buf, len / 2);
    uint8_t *c = malloc(len);
    memcpy(c, buf, len);
    c[table_of(c)[section_index(c, "SURF")].offset + 9] ^= 0x10;
    put(dir, "flip_surf_crc.lcb", c, len);
    memcpy(c, buf, len);
    hdr_of(c)->version_major = 2;
    lcb_test_fix_crcs(c, len);
    put(dir, "version2.lcb", c, len);
    memcpy(c, buf, len);
    table_of(c)[section_index(c, "NODE")].offset = table_of(c)[section_index(c, "SURF")].offset;
    lcb_test_fix_crcs(c, len);
    put(dir, "overlap.lcb", c, len);
    free(c);
    free(buf);
    b.node[1].child[1] = 99;
    buf = bake_bytes(&b, &len);
    put(dir, "bad_node_child.lcb", buf, len);
    free(buf);
    bake_free(&b);

    bake_init(&b);
    b.lmap[7] = 200;
    buf = bake_bytes(&b, &len);
    put(dir, "bad_lmap.lcb", buf, len);
    free(buf);
    bake_free(&b);

    bake_init(&b);
    cJSON *m = bake_meta(LSH);
    cJSON_ReplaceItemInObject(m, "sh_bands", cJSON_CreateString("2"));
    bake_set_meta(&b, m);
    buf = bake_bytes(&b, &len);
    put(dir, "bad_meta_type.lcb", buf, len);
    free(buf);
    bake_free(&b);

    bake_init(&b);
    b.with_assets = b.with_lksh = 0;
    b.extra = 1;
    bake_set_meta(&b, bake_meta(0));
    buf = bake_bytes(&b, &len);
    put(dir, "valid_minimal_unknown.lcb", buf, len);
    free(buf);
    bake_free(&b);
    fprintf(stderr, "wrote the seed corpus to %s\n", dir);
}

int main(void) {
    const char *t = getenv("TMPDIR");
    snprintf(tmpdir, sizeof tmpdir, "%s/lcb-test-XXXXXX", t && *t ? t : "/tmp");
    if (!mkdtemp(tmpdir)) {
        fprintf(stderr, "mkdtemp: %s\n", strerror(errno));
        return 1;
    }
    test_round_trip();
    test_determinism_and_api();
    test_truncation();
    test_real_bake();
    test_flips();
    test_structure();
    test_semantic();
    const char *corpus = getenv("LUCENT_WRITE_CORPUS");
    if (corpus && *corpus) write_corpus(corpus);
    rmdir(tmpdir);
    CHECK_DONE();
}
