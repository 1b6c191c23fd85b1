/* test_bake_sparse: LightSkin sparse points through the bake and the bake file. A tiny room
 * baked with two assets (the repository's cube, a UV sphere): ASPT holds 256 points per
 * asset, sorted and contiguous, bit for bit what lc_sparse_points gives for the stored
 * asset geometry and the bake's seed; AVNN one table per asset vertex, bit for bit
 * lc_sparse_vertex_table's; META and `info` report the counts. --mr-points 0 writes neither
 * section and the bake loads as an older one does (also the checked-in valid_full.lcb).
 * Then every reader rule rejects a corrupted copy (CRCs valid) with a message naming the
 * section and the field. */
#include <cjson/cJSON.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bake/bake.h"
#include "bake/sparse.h"
#include "check.h"
#include "lcb/lcb.h"
#include "lcb/lcb_glb.h"
#include "util/fsutil.h"

static char tmp[64];

static int write_text(const char *name, const char *text) {
    char path[160];
    snprintf(path, sizeof path, "%s/%s", tmp, name);
    FILE *fp = fopen(path, "w");
    if (!fp) return -1;
    fputs(text, fp);
    fclose(fp);
    return 0;
}

/* A closed 2 m room (faces inward, emitting ceiling) and a UV sphere asset of radius 0.2. */
static int write_inputs(void) {
    static const char room[] = "mtllib room.mtl\nusemtl wall\n"
                               "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 0 2 0\nv 0 0 2\nv 2 0 2\nv 2 2 2\nv 0 2 2\n"
                               "f 1 2 6 5\nf 2 3 7 6\nf 4 8 7 3\nf 1 5 8 4\nf 1 4 3 2\nusemtl lamp\nf 5 6 7 8\n";
    if (write_text("room.obj", room) ||
        write_text("room.mtl",
                   "newmtl wall\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 "
                   "0\nKe 1 1 1\n"))
        return -1;
    char path[160];
    snprintf(path, sizeof path, "%s/ball.obj", tmp);
    FILE *fp = fopen(path, "w");
    if (!fp) return -1;
    const int nu = 24, nv = 12;
    for (int j = 0; j <= nv; j++)
        for (int i = 0; i < nu; i++) {
            double th = M_PI * j / nv, ph = 2 * M_PI * i / nu;
            fprintf(fp, "v %.6f %.6f %.6f\nvn %.6f %.6f %.6f\n", 0.2 * sin(th) * cos(ph), 0.2 * cos(th),
                    0.2 * sin(th) * sin(ph), sin(th) * cos(ph), cos(th), sin(th) * sin(ph));
        }
    for (int j = 0; j < nv; j++)
        for (int i = 0; i < nu; i++) {
            int a = j * nu + i + 1, b = j * nu + (i + 1) % nu + 1, c = a + nu, d = b + nu;
            if (j > 0) fprintf(fp, "f %d//%d %d//%d %d//%d\n", a, a, b, b, c, c);
            if (j < nv - 1) fprintf(fp, "f %d//%d %d//%d %d//%d\n", b, b, d, d, c, c);
        }
    fclose(fp);
    return 0;
}

/* Bakes room.obj with the assets into tmp/NAME; mr_points NULL = the default. */
static int bake(const char *name, const char *mr_points, char *out, size_t cap) {
    char room[160], cube[600], ball[200], src[512];
    snprintf(room, sizeof room, "%s/room.obj", tmp);
    snprintf(out, cap, "%s/%s", tmp, name);
    snprintf(cube, sizeof cube, "cube=%s", check_source_path("scenes/cornell-box/cube.obj", src, sizeof src));
    snprintf(ball, sizeof ball, "ball=%s/ball.obj", tmp);
    char *argv[40] = {"lucent-bake",
                      "bake",
                      room,
                      "--output",
                      out,
                      "--quiet",
                      "--no-write-glb",
                      "--quality",
                      "draft",
                      "--surfels",
                      "256",
                      "--links",
                      "16",
                      "--atlas-size",
                      "32",
                      "--min-texel-density",
                      "0",
                      "--grid-max-dim",
                      "3",
                      "--no-transfer",
                      "--seed",
                      "3",
                      "--asset",
                      cube,
                      "--asset",
                      ball};
    int argc = 26;
    if (mr_points) argv[argc++] = "--mr-points", argv[argc++] = (char *)mr_points;
    static lc_bake_settings s;
    char err[512] = "";
    char *pos[2];
    if (lc_bake_parse_args(&s, argc, argv, 2, pos, 2, err, sizeof err) != 1) {
        fprintf(stderr, "args: %s\n", err);
        return -1;
    }
    snprintf(s.input, sizeof s.input, "%s", pos[0]);
    if (lc_bake_run(&s, NULL, err, sizeof err) != 0) {
        fprintf(stderr, "bake: %s\n", err);
        return -1;
    }
    return 0;
}

static const lc_lcb_section *section(const lc_lcb *f, const char *id) {
    for (uint32_t i = 0; i < lc_lcb_section_count(f); i++)
        if (!memcmp(lc_lcb_section_at(f, i)->id, id, 4)) return lc_lcb_section_at(f, i);
    return NULL;
}

/* info --json's counts.sparse_points and asset_sparse_points. */
static void check_info(const lc_lcb *f, double total, const double *per_asset, int n) {
    char *text = NULL;
    size_t len = 0;
    FILE *ms = open_memstream(&text, &len);
    lc_lcb_print_info(f, "t", 1, ms);
    fclose(ms);
    cJSON *j = cJSON_Parse(text);
    const cJSON *c = cJSON_GetObjectItem(j, "counts"), *a = cJSON_GetObjectItem(c, "asset_sparse_points");
    CHECK(cJSON_GetNumberValue(cJSON_GetObjectItem(c, "sparse_points")) == total, "info counts.sparse_points");
    CHECK(cJSON_GetArraySize(a) == n, "info asset_sparse_points has %d entries", cJSON_GetArraySize(a));
    for (int i = 0; i < n && i < cJSON_GetArraySize(a); i++)
        CHECK(cJSON_GetArrayItem(a, i)->valuedouble == per_asset[i], "info asset %d: %g points", i,
              cJSON_GetArrayItem(a, i)->valuedouble);
    cJSON_Delete(j);
    free(text);
}

/* The default bake: 256 points per asset, what the functions give, META and info. */
static void check_default(const lc_lcb *f) {
    const lc_lcb_view *v = lc_lcb_get(f);
    CHECK(v->n_assets == 2 && v->sparse_points && v->sparse_vertices, "two assets with sparse points");
    CHECK(v->n_sparse_points == 512, "ASPT: %u points, 2 x 256", v->n_sparse_points);
    if (v->n_assets != 2 || !v->sparse_points) return;
    CHECK(section(f, "AVNN") && section(f, "AVNN")->count == v->n_asset_vertices, "AVNN: one per AVRT vertex");
    char err[256] = "";
    for (uint32_t i = 0; i < 2; i++) {
        const lc_lcb_asset *a = &v->assets[i];
        uint32_t first = 99, count = 99;
        CHECK(lc_lcb_asset_sparse(v, i, &first, &count) == 256 && first == 256 * i, "asset %u: [%u, +%u)", i, first,
              count);
        lc_lcb_sparse_point *p = calloc(256, sizeof *p);
        lc_lcb_sparse_vertex *t = calloc(a->vertex_count, sizeof *t);
        const lc_lcb_asset_vertex *av = v->asset_vertices + a->first_vertex;
        CHECK(lc_sparse_points(av, a->vertex_count, v->asset_indices + 3 * (size_t)a->first_triangle, a->triangle_count,
                               256, 3, i, p, NULL, err, sizeof err) == 0,
              "points: %s", err);
        CHECK(!memcmp(p, v->sparse_points + first, 256 * sizeof *p), "asset %u: ASPT = lc_sparse_points, seed 3", i);
        CHECK(lc_sparse_vertex_table(av, a->vertex_count, p, 256, t, NULL, err, sizeof err) == 0, "table: %s", err);
        CHECK(!memcmp(t, v->sparse_vertices + a->first_vertex, a->vertex_count * sizeof *t),
              "asset %u: AVNN = lc_sparse_vertex_table", i);
        free(p);
        free(t);
    }
    uint32_t none = 5, none_count = 5;
    CHECK(lc_lcb_asset_sparse(v, 2, &none, &none_count) == 0 && none == 512, "past the last asset: none");
    cJSON *meta = cJSON_Parse(v->meta_json);
    const cJSON *assets = cJSON_GetObjectItem(meta, "assets");
    for (int i = 0; i < 2; i++)
        CHECK(cJSON_GetNumberValue(cJSON_GetObjectItem(cJSON_GetArrayItem(assets, i), "sparse_points")) == 256,
              "META assets[%d].sparse_points", i);
    CHECK(cJSON_GetNumberValue(cJSON_GetObjectItem(cJSON_GetObjectItem(meta, "settings"), "mr-points")) == 256,
          "META settings.mr-points");
    cJSON_Delete(meta);
    check_info(f, 512, (const double[]){256, 256}, 2);
}

/* --mr-points 0 (and a bake from before the sections): none, and the asset glTF without tables. */
static void check_without(const lc_lcb *f) {
    const lc_lcb_view *v = lc_lcb_get(f);
    CHECK(!section(f, "ASPT") && !section(f, "AVNN"), "--mr-points 0: no ASPT/AVNN");
    CHECK(!v->sparse_points && !v->sparse_vertices && v->n_sparse_points == 0, "no view fields");
    uint32_t first, count;
    CHECK(lc_lcb_asset_sparse(v, 0, &first, &count) == 0, "no points for asset 0");
    unsigned char *glb = NULL;
    size_t len = 0;
    char err[256] = "";
    CHECK(lc_lcb_asset_glb(f, 0, &glb, &len, err, sizeof err) == 0, "asset glb: %s", err);
    CHECK(glb && !memmem(glb, len, "_LUCENT_SP", 10) && !memmem(glb, len, "sparse_points", 13),
          "no sparse attributes without points");
    free(glb);
    check_info(f, 0, (const double[]){0, 0}, 2);
}

/* --- corrupted copies ---------------------------------------------------------------------- */

typedef struct good {
    char *bytes;
    size_t len;
    lc_lcb *f;
} good;

/* good's sections through the writer, ASPT/AVNN replaced by aspt/avnn (count records; NULL
 * keeps the original), `drop` ids (4 characters each, concatenated) left out; opened from
 * memory. Expects failure with a message holding s1 and s2. */
static void expect_fail(const char *label, const good *g, const void *aspt, uint64_t n_aspt, const void *avnn,
                        uint64_t n_avnn, const char *drop, const char *s1, const char *s2) {
    lc_lcb_writer *w = lc_lcb_writer_create();
    for (uint32_t i = 0; i < lc_lcb_section_count(g->f); i++) {
        const lc_lcb_section *s = lc_lcb_section_at(g->f, i);
        int skip = 0;
        for (const char *d = drop; d && *d; d += 4) skip |= !memcmp(s->id, d, 4);
        if (skip) continue;
        const void *data = g->bytes + s->offset;
        uint64_t count = s->count;
        if (aspt && !memcmp(s->id, "ASPT", 4)) data = aspt, count = n_aspt;
        if (avnn && !memcmp(s->id, "AVNN", 4)) data = avnn, count = n_avnn;
        lc_lcb_writer_add(w, s->id, s->record_size, data, count);
    }
    char path[160], err[512] = "";
    snprintf(path, sizeof path, "%s/corrupt.lcb", tmp);
    int wrc = lc_lcb_writer_write(w, path, err, sizeof err);
    lc_lcb_writer_release(w);
    CHECK(wrc == 0, "%s: write: %s", label, err);
    size_t len = 0;
    char *bytes = lc_fs_read(path, 64u << 20, &len, err, sizeof err);
    lc_lcb *f = NULL;
    err[0] = 0;
    int rc = bytes ? lc_lcb_open_memory(bytes, len, &f, err, sizeof err) : 0;
    CHECK(bytes && rc != 0, "%s: opened but should have failed", label);
    CHECK(strstr(err, s1) && (!s2 || strstr(err, s2)), "%s: message '%s' lacks '%s' / '%s'", label, err, s1,
          s2 ? s2 : "");
    lc_lcb_close(f);
    free(bytes);
    unlink(path);
}

static void corrupt_points(const good *g) {
    const lc_lcb_view *v = lc_lcb_get(g->f);
    uint32_t n = v->n_sparse_points;
    lc_lcb_sparse_point *p = malloc(n * sizeof *p);
#define RESET() memcpy(p, v->sparse_points, n * sizeof *p)
    RESET();
    p[3].asset = 2;
    expect_fail("asset out of range", g, p, n, NULL, 0, NULL, "ASPT: point 3 asset 2 out of range", NULL);
    RESET();
    p[300].asset = 0; /* asset 1's second point names asset 0 */
    expect_fail("not sorted", g, p, n, NULL, 0, NULL, "ASPT: point 300 asset 0 after asset 1", "not sorted");
    RESET();
    p[5].position[1] = NAN;
    expect_fail("position", g, p, n, NULL, 0, NULL, "ASPT: point 5 position", "not finite");
    RESET();
    p[6].normal[0] = INFINITY;
    expect_fail("normal finite", g, p, n, NULL, 0, NULL, "ASPT: point 6 normal", "not finite");
    RESET();
    for (int k = 0; k < 3; k++) p[7].normal[k] *= 1.01f;
    expect_fail("normal unit", g, p, n, NULL, 0, NULL, "ASPT: point 7 normal has length", "not unit");
    float bad_radius[3] = {0, -0.1f, NAN};
    for (int k = 0; k < 3; k++) {
        RESET();
        p[8].radius = bad_radius[k];
        expect_fail("radius", g, p, n, NULL, 0, NULL, "ASPT: point 8 radius", "> 0");
    }
    RESET();
    /* asset 0 with 256 points, asset 1 with 255: AVNN indices of asset 1 up to 255 now out of range */
    expect_fail("fewer points", g, p, n - 1, NULL, 0, NULL, "AVNN: vertex", "has 255 points");
    lc_lcb_sparse_point *big = malloc(65536 * sizeof *big);
    for (uint32_t i = 0; i < 65536; i++) big[i] = p[0];
    expect_fail("over 65535 per asset", g, big, 65536, NULL, 0, NULL, "ASPT: asset 0 has more than 65535 points", NULL);
    free(big);
#undef RESET
    free(p);
}

static void corrupt_tables(const good *g) {
    const lc_lcb_view *v = lc_lcb_get(g->f);
    uint32_t n = v->n_asset_vertices;
    lc_lcb_sparse_vertex *t = malloc(n * sizeof *t);
#define RESET() memcpy(t, v->sparse_vertices, n * sizeof *t)
    RESET();
    t[2].index[3] = 256;
    expect_fail("index", g, NULL, 0, t, n, NULL, "AVNN: vertex 2 index[3] = 256", "asset 0 has 256 points");
    float bad_w[3] = {NAN, 1.5f, -0.25f};
    for (int k = 0; k < 3; k++) {
        RESET();
        t[4].weight[1] = bad_w[k];
        expect_fail("weight", g, NULL, 0, t, n, NULL, "AVNN: vertex 4 weight[1]", "not in [0, 1]");
    }
    RESET();
    t[9].weight[t[9].weight[7] <= 0.99f ? 7 : 6] += 0.01f; /* still in [0, 1], the sum 1.01 */
    expect_fail("sum", g, NULL, 0, t, n, NULL, "AVNN: vertex 9 weights sum to", "not 1");
    RESET();
    expect_fail("count", g, NULL, 0, t, n - 1, NULL, "AVNN:", "records, AVRT has");
    expect_fail("ASPT alone", g, NULL, 0, NULL, 0, "AVNN", "AVNN: missing", "ASPT and AVNN come together");
    expect_fail("AVNN alone", g, NULL, 0, NULL, 0, "ASPT", "ASPT: missing", "ASPT and AVNN come together");
    expect_fail("no assets", g, NULL, 0, NULL, 0, "ASETAVRTAIDX", "ASPT: sparse points but no assets", NULL);
#undef RESET
    free(t);
}

int main(void) {
    snprintf(tmp, sizeof tmp, "/tmp/lc_sparse_XXXXXX");
    if (!mkdtemp(tmp) || write_inputs() != 0) {
        fprintf(stderr, "temp inputs\n");
        return 1;
    }
    char with[200], without[200], err[512] = "";
    good g = {0};
    CHECK(bake("with.lcb", NULL, with, sizeof with) == 0, "default bake");
    CHECK(lc_lcb_open(with, &g.f, err, sizeof err) == 0, "open: %s", err);
    g.bytes = lc_fs_read(with, 64u << 20, &g.len, err, sizeof err);
    if (g.f && g.bytes) {
        check_default(g.f);
        corrupt_points(&g);
        corrupt_tables(&g);
    }
    lc_lcb_close(g.f);
    free(g.bytes);
    lc_lcb *f = NULL;
    CHECK(bake("without.lcb", "0", without, sizeof without) == 0, "--mr-points 0 bake");
    CHECK(lc_lcb_open(without, &f, err, sizeof err) == 0, "open: %s", err);
    if (f) check_without(f);
    lc_lcb_close(f);
    char old[512];
    f = NULL;
    CHECK(lc_lcb_open(check_source_path("tests/fuzz/corpus/lcb/valid_full.lcb", old, sizeof old), &f, err,
                      sizeof err) == 0,
          "an older bake without the sections loads: %s", err);
    CHECK(f && !lc_lcb_get(f)->sparse_points && lc_lcb_get(f)->n_sparse_points == 0, "and has no sparse points");
    lc_lcb_close(f);
    static const char *const files[] = {"with.lcb", "without.lcb", "room.obj", "room.mtl", "ball.obj"};
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        char p[200];
        snprintf(p, sizeof p, "%s/%s", tmp, files[i]);
        unlink(p);
    }
    rmdir(tmp);
    CHECK_DONE();
}
