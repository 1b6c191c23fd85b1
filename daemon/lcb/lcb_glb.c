/* lcb_glb: binary glTF 2.0 of a bake's scene and assets, from the mapped .lcb (lcb_glb.h
 * says what is written and why). The BIN chunk is sized exactly before anything is written,
 * so the 4 GiB cap is checked once and no buffer grows. */
#include "lcb/lcb_glb.h"

#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/crc32.h"
#include "util/log.h"

#define GLB_MAGIC 0x46546C67u       /* "glTF" */
#define GLB_CHUNK_JSON 0x4E4F534Au  /* "JSON" */
#define GLB_CHUNK_BIN 0x004E4942u   /* "BIN\0" */
#define GLB_MAX_BYTES 0xFFFFFFFCull /* the header's length is 32-bit and a multiple of 4 */

#define GL_FLOAT 5126
#define GL_UNSIGNED_SHORT 5123
#define GL_UNSIGNED_INT 5125
#define GL_ARRAY_BUFFER 34962
#define GL_ELEMENT_ARRAY_BUFFER 34963
#define GL_TRIANGLES 4

/* Scene vertices: POSITION + NORMAL + one UV accessor (TEXCOORD_0 and _1 share it). */
#define GLB_SCENE_VERTEX_BYTES (12 + 12 + 8)
/* Asset vertices: POSITION + NORMAL + COLOR_0. */
#define GLB_ASSET_VERTEX_BYTES (12 + 12 + 12)
#define GLB_TRIANGLE_BYTES 12
/* With LightSkin sparse points: _LUCENT_SP_INDEX0/1 (VEC4 u16) + _LUCENT_SP_WEIGHT0/1 (VEC4 f32). */
#define GLB_ASSET_SPARSE_BYTES (8 + 8 + 16 + 16)
#define GLB_SPARSE_POINT_BYTES (12 + 12 + 4) /* per sparse point: position, normal, radius */

typedef struct glb_doc {
    cJSON *root, *views, *accessors, *materials;
    unsigned char *bin; /* bin_cap bytes, sized before anything is written */
    size_t bin_len, bin_cap;
    int overflow; /* a write past bin_cap was refused: an internal sizing error */
} glb_doc;

static void glb_put_u32(unsigned char *p, uint32_t v) {
    p[0] = (unsigned char)v, p[1] = (unsigned char)(v >> 8), p[2] = (unsigned char)(v >> 16),
    p[3] = (unsigned char)(v >> 24);
}

/* Appends a little-endian word to the BIN chunk (the format is LE whatever the host). */
static void glb_u32(glb_doc *d, uint32_t v) {
    if (d->bin_len + 4 > d->bin_cap) {
        d->overflow = 1;
        return;
    }
    glb_put_u32(d->bin + d->bin_len, v);
    d->bin_len += 4;
}

static void glb_f32(glb_doc *d, float f) {
    uint32_t v;
    memcpy(&v, &f, sizeof v);
    glb_u32(d, v);
}

static cJSON *glb_floats(const float *v, int n) {
    cJSON *a = cJSON_CreateArray();
    for (int i = 0; a && i < n; i++) {
        cJSON *x = cJSON_CreateNumber((double)v[i]);
        if (!x) {
            cJSON_Delete(a);
            return NULL;
        }
        cJSON_AddItemToArray(a, x);
    }
    return a;
}

static void glb_doc_free(glb_doc *d) {
    cJSON_Delete(d->root);
    free(d->bin);
    memset(d, 0, sizeof *d);
}

/* The document's skeleton (asset with the bake id, the arrays every file has) and a BIN
 * buffer of exactly bin_bytes. extras_asset names the asset in extras (NULL for the scene). */
static int glb_doc_open(glb_doc *d, const lc_lcb *f, uint64_t bin_bytes, const char *extras_asset, char *err,
                        size_t errlen) {
    memset(d, 0, sizeof *d);
    if (bin_bytes > GLB_MAX_BYTES - 28) {
        lc_set_err(err, errlen, "glTF: the binary chunk would be %llu bytes, over the GLB format's 4 GiB limit",
                   (unsigned long long)bin_bytes);
        return -1;
    }
    char id[LC_LCB_BAKE_ID_LEN];
    lc_lcb_bake_id(f, id);
    d->bin_cap = (size_t)bin_bytes;
    d->bin = malloc(d->bin_cap ? d->bin_cap : 1);
    d->root = cJSON_CreateObject();
    if (!d->bin || !d->root) goto oom;
    cJSON *asset = cJSON_AddObjectToObject(d->root, "asset");
    cJSON *extras = asset ? cJSON_AddObjectToObject(asset, "extras") : NULL;
    cJSON *lucent = extras ? cJSON_AddObjectToObject(extras, "lucent") : NULL;
    if (!lucent || !cJSON_AddStringToObject(asset, "version", "2.0") ||
        !cJSON_AddStringToObject(asset, "generator", "lucent") || !cJSON_AddStringToObject(lucent, "bake_id", id) ||
        (extras_asset && !cJSON_AddStringToObject(lucent, "asset", extras_asset)))
        goto oom;
    d->views = cJSON_AddArrayToObject(d->root, "bufferViews");
    d->accessors = cJSON_AddArrayToObject(d->root, "accessors");
    d->materials = cJSON_AddArrayToObject(d->root, "materials");
    if (!d->views || !d->accessors || !d->materials) goto oom;
    return 0;
oom:
    glb_doc_free(d);
    lc_set_err(err, errlen, "glTF: out of memory building the document");
    return -1;
}

/* An accessor over BIN bytes [off, bin_len) with its own bufferView (every view starts on a
 * 4-byte boundary: everything written is 4-byte words). Returns its index or -1. */
static int glb_accessor(glb_doc *d, size_t off, int target, int ctype, uint32_t count, const char *type) {
    cJSON *v = cJSON_CreateObject();
    if (!v) return -1;
    cJSON_AddItemToArray(d->views, v);
    if (!cJSON_AddNumberToObject(v, "buffer", 0) || !cJSON_AddNumberToObject(v, "byteOffset", (double)off) ||
        !cJSON_AddNumberToObject(v, "byteLength", (double)(d->bin_len - off)) ||
        !cJSON_AddNumberToObject(v, "target", target))
        return -1;
    cJSON *a = cJSON_CreateObject();
    if (!a) return -1;
    cJSON_AddItemToArray(d->accessors, a);
    if (!cJSON_AddNumberToObject(a, "bufferView", cJSON_GetArraySize(d->views) - 1) ||
        !cJSON_AddNumberToObject(a, "componentType", ctype) || !cJSON_AddNumberToObject(a, "count", count) ||
        !cJSON_AddStringToObject(a, "type", type))
        return -1;
    return cJSON_GetArraySize(d->accessors) - 1;
}

/* A float vertex attribute of `comps` components: element i is read at
 * base + stride * (idx ? idx[i] : i). POSITION gets the min/max glTF requires; colours are
 * clamped to [0,1]. Returns the accessor index or -1. */
static int glb_attr(glb_doc *d, const void *base, size_t stride, const uint32_t *idx, uint32_t n, int comps, int minmax,
                    int clamp01) {
    static const char *types[] = {"", "SCALAR", "VEC2", "VEC3"};
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    size_t off = d->bin_len;
    for (uint32_t i = 0; i < n; i++) {
        float x[3];
        memcpy(x, (const unsigned char *)base + stride * (idx ? idx[i] : i), (size_t)comps * sizeof(float));
        for (int c = 0; c < comps; c++) {
            if (clamp01) x[c] = fminf(fmaxf(x[c], 0.0f), 1.0f);
            lo[c] = fminf(lo[c], x[c]), hi[c] = fmaxf(hi[c], x[c]);
            glb_f32(d, x[c]);
        }
    }
    int acc = glb_accessor(d, off, GL_ARRAY_BUFFER, GL_FLOAT, n, types[comps]);
    if (acc < 0 || !minmax) return acc;
    cJSON *a = cJSON_GetArrayItem(d->accessors, acc), *jmin = glb_floats(lo, comps), *jmax = glb_floats(hi, comps);
    if (!jmin || !jmax) {
        cJSON_Delete(jmin), cJSON_Delete(jmax);
        return -1;
    }
    cJSON_AddItemToObject(a, "min", jmin);
    cJSON_AddItemToObject(a, "max", jmax);
    return acc;
}

static int glb_unit(const float v[3], float out[3]) {
    float l = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (!isfinite(l) || l < 1e-20f) return -1;
    for (int c = 0; c < 3; c++) out[c] = v[c] / l;
    return 0;
}

/* A unit normal for glTF: the vertex normal normalised, else the face normal of corners
 * (a, b, c) (NULL when no triangle uses the vertex), else +Y. */
static void glb_normal(const float n[3], const float *a, const float *b, const float *c, float out[3]) {
    if (glb_unit(n, out) == 0) return;
    if (a && b && c) {
        float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        float x[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        if (glb_unit(x, out) == 0) return;
    }
    out[0] = 0, out[1] = 1, out[2] = 0;
}

/* A material: base colour, metallic 0, roughness 1, emission in nits split so that
 * emissiveFactor stays in [0,1] and KHR_materials_emissive_strength carries the magnitude. */
static int glb_material(glb_doc *d, const char *name, const float base_rgb[3], const float emission[3],
                        int *uses_strength) {
    cJSON *j = cJSON_CreateObject();
    if (!j) return -1;
    cJSON_AddItemToArray(d->materials, j);
    float base[4] = {1, 1, 1, 1}, e[3], emax = 0, strength = 1;
    for (int c = 0; c < 3; c++) {
        base[c] = fminf(fmaxf(base_rgb[c], 0.0f), 1.0f);
        e[c] = emission[c] > 0 ? emission[c] : 0.0f;
        emax = fmaxf(emax, e[c]);
    }
    if (emax > 1.0f) {
        for (int c = 0; c < 3; c++) e[c] /= emax;
        strength = emax;
    }
    cJSON *pbr = cJSON_AddObjectToObject(j, "pbrMetallicRoughness");
    cJSON *bc = glb_floats(base, 4), *ef = glb_floats(e, 3);
    if (!pbr || !bc || !ef) {
        cJSON_Delete(bc), cJSON_Delete(ef);
        return -1;
    }
    cJSON_AddItemToObject(pbr, "baseColorFactor", bc);
    cJSON_AddItemToObject(j, "emissiveFactor", ef);
    if (!cJSON_AddNumberToObject(pbr, "metallicFactor", 0) || !cJSON_AddNumberToObject(pbr, "roughnessFactor", 1) ||
        !cJSON_AddStringToObject(j, "name", name) || !cJSON_AddFalseToObject(j, "doubleSided"))
        return -1;
    if (strength > 1.0f) {
        cJSON *ext = cJSON_AddObjectToObject(j, "extensions");
        cJSON *ks = ext ? cJSON_AddObjectToObject(ext, "KHR_materials_emissive_strength") : NULL;
        if (!ks || !cJSON_AddNumberToObject(ks, "emissiveStrength", strength)) return -1;
        *uses_strength = 1;
    }
    return 0;
}

/* One node named `name` showing mesh 0 (or no mesh when there is none), and the scene of it. */
static int glb_node(glb_doc *d, const char *name, cJSON *prims) {
    int has_mesh = prims && cJSON_GetArraySize(prims) > 0;
    if (has_mesh) {
        cJSON *meshes = cJSON_AddArrayToObject(d->root, "meshes"), *mesh = cJSON_CreateObject();
        if (!meshes || !mesh) {
            cJSON_Delete(mesh), cJSON_Delete(prims);
            return -1;
        }
        cJSON_AddItemToArray(meshes, mesh);
        cJSON_AddItemToObject(mesh, "primitives", prims);
        if (!cJSON_AddStringToObject(mesh, "name", name)) return -1;
    } else {
        cJSON_Delete(prims);
    }
    cJSON *nodes = cJSON_AddArrayToObject(d->root, "nodes"), *node = cJSON_CreateObject();
    if (!nodes || !node) {
        cJSON_Delete(node);
        return -1;
    }
    cJSON_AddItemToArray(nodes, node);
    if (!cJSON_AddStringToObject(node, "name", name) || (has_mesh && !cJSON_AddNumberToObject(node, "mesh", 0)))
        return -1;
    cJSON *scenes = cJSON_AddArrayToObject(d->root, "scenes"), *sc = cJSON_CreateObject();
    if (!scenes || !sc) {
        cJSON_Delete(sc);
        return -1;
    }
    cJSON_AddItemToArray(scenes, sc);
    cJSON *sn = cJSON_AddArrayToObject(sc, "nodes"), *zero = cJSON_CreateNumber(0);
    if (!sn || !zero) {
        cJSON_Delete(zero);
        return -1;
    }
    cJSON_AddItemToArray(sn, zero);
    return cJSON_AddNumberToObject(d->root, "scene", 0) ? 0 : -1;
}

/* The extension list, the one buffer, and the GLB container: header, the JSON chunk padded
 * with spaces, the BIN chunk padded with zeros (the spec's padding bytes). Frees d. */
static int glb_finish(glb_doc *d, int uses_strength, unsigned char **out, size_t *len, char *err, size_t errlen) {
    char *json = NULL;
    int rc = -1;
    if (d->overflow || d->bin_len != d->bin_cap) {
        lc_set_err(err, errlen, "glTF: internal error: %zu of %zu binary bytes written", d->bin_len, d->bin_cap);
        goto out;
    }
    if (uses_strength) {
        cJSON *used = cJSON_AddArrayToObject(d->root, "extensionsUsed");
        cJSON *name = cJSON_CreateString("KHR_materials_emissive_strength");
        if (!used || !name) {
            cJSON_Delete(name);
            goto oom;
        }
        cJSON_AddItemToArray(used, name);
    }
    if (d->bin_len) {
        cJSON *buffers = cJSON_AddArrayToObject(d->root, "buffers"), *b0 = cJSON_CreateObject();
        if (!buffers || !b0) {
            cJSON_Delete(b0);
            goto oom;
        }
        cJSON_AddItemToArray(buffers, b0);
        if (!cJSON_AddNumberToObject(b0, "byteLength", (double)d->bin_len)) goto oom;
    }
    /* glTF's arrays may not be empty: an empty scene has no views, accessors or materials */
    static const char *const arrays[] = {"bufferViews", "accessors", "materials"};
    for (int i = 0; i < 3; i++)
        if (cJSON_GetArraySize(cJSON_GetObjectItem(d->root, arrays[i])) == 0)
            cJSON_DeleteItemFromObject(d->root, arrays[i]);
    json = cJSON_PrintUnformatted(d->root);
    if (!json) goto oom;
    size_t jlen = strlen(json), jpad = (jlen + 3) & ~(size_t)3, bpad = (d->bin_len + 3) & ~(size_t)3;
    uint64_t total = 12 + 8 + (uint64_t)jpad + (d->bin_len ? 8 + (uint64_t)bpad : 0);
    if (total > GLB_MAX_BYTES) {
        lc_set_err(err, errlen, "glTF: the file would be %llu bytes, over the GLB format's 4 GiB limit",
                   (unsigned long long)total);
        goto out;
    }
    unsigned char *p = *out = malloc((size_t)total);
    if (!p) goto oom;
    *len = (size_t)total;
    glb_put_u32(p, GLB_MAGIC), glb_put_u32(p + 4, 2), glb_put_u32(p + 8, (uint32_t)total), p += 12;
    glb_put_u32(p, (uint32_t)jpad), glb_put_u32(p + 4, GLB_CHUNK_JSON), p += 8;
    memcpy(p, json, jlen);
    memset(p + jlen, ' ', jpad - jlen);
    p += jpad;
    if (d->bin_len) {
        glb_put_u32(p, (uint32_t)bpad), glb_put_u32(p + 4, GLB_CHUNK_BIN), p += 8;
        memcpy(p, d->bin, d->bin_len);
        memset(p + d->bin_len, 0, bpad - d->bin_len);
    }
    rc = 0;
    goto out;
oom:
    lc_set_err(err, errlen, "glTF: out of memory building the document");
out:
    free(json);
    glb_doc_free(d);
    return rc;
}

/* --- the scene ------------------------------------------------------------------------------ */

/* Scratch of the scene writer: triangles bucketed by material, a vertex stamp/map. */
typedef struct glb_scene {
    const lc_lcb_view *v;
    uint32_t *tri_start; /* n_materials + 1: material m's triangles are order[tri_start[m], tri_start[m+1]) */
    uint32_t *order;     /* triangle indices by material */
    uint32_t *stamp;     /* per vertex: the epoch that last mapped it */
    uint32_t *map;       /* per vertex: its local index in the primitive being written */
    uint32_t *nv;        /* per material: local vertex count */
    uint32_t *inv;       /* local -> global vertex, for the primitive being written */
    uint32_t *inv_tri;   /* local vertex -> a triangle using it (its face normal is the fallback) */
    float *normals;      /* 3 per local vertex */
    float (*base)[3];    /* per material: the base colour written */
    uint32_t max_nv;
} glb_scene;

static void glb_scene_free(glb_scene *s) {
    free(s->tri_start), free(s->order), free(s->stamp), free(s->map), free(s->nv);
    free(s->inv), free(s->inv_tri), free(s->normals), free(s->base);
}

/* Maps material mi's vertices to local indices 0..n-1 in first-use order (epoch tags this
 * pass in stamp). Fills inv/inv_tri when asked. Returns the count. */
static uint32_t glb_scene_map(glb_scene *s, uint32_t mi, uint32_t epoch, int fill) {
    uint32_t n = 0;
    for (uint32_t k = s->tri_start[mi]; k < s->tri_start[mi + 1]; k++) {
        const lc_lcb_triangle *t = &s->v->triangles[s->order[k]];
        for (int c = 0; c < 3; c++) {
            uint32_t g = t->v[c];
            if (s->stamp[g] == epoch) continue;
            s->stamp[g] = epoch, s->map[g] = n;
            if (fill) s->inv[n] = g, s->inv_tri[n] = s->order[k];
            n++;
        }
    }
    return n;
}

/* Buckets the triangles, counts each primitive's vertices and sizes the BIN chunk; the base
 * colours: a textured material's is the mean albedo of its surfels (equal-area, so the plain
 * mean is the surface mean of factor x texture), every other material's its factor. */
static int glb_scene_plan(glb_scene *s, uint64_t *bin_bytes, char *err, size_t errlen) {
    const lc_lcb_view *v = s->v;
    uint32_t nm = v->n_materials;
    double(*sum)[3] = calloc(nm ? nm : 1, sizeof *sum);
    uint32_t *cnt = calloc(nm ? nm : 1, sizeof *cnt);
    s->tri_start = calloc((size_t)nm + 1, sizeof *s->tri_start);
    s->order = malloc((v->n_triangles ? v->n_triangles : 1) * sizeof *s->order);
    s->stamp = calloc(v->n_vertices ? v->n_vertices : 1, sizeof *s->stamp);
    s->map = malloc((v->n_vertices ? v->n_vertices : 1) * sizeof *s->map);
    s->nv = calloc(nm ? nm : 1, sizeof *s->nv);
    s->base = calloc(nm ? nm : 1, sizeof *s->base);
    int rc = -1;
    if (!sum || !cnt || !s->tri_start || !s->order || !s->stamp || !s->map || !s->nv || !s->base) {
        lc_set_err(err, errlen, "glTF: out of memory planning the scene");
        goto out;
    }
    for (uint32_t t = 0; t < v->n_triangles; t++) s->tri_start[v->triangles[t].material + 1]++;
    for (uint32_t m = 0; m < nm; m++) s->tri_start[m + 1] += s->tri_start[m];
    for (uint32_t t = 0; t < v->n_triangles; t++)
        s->order[cnt[v->triangles[t].material]++ + s->tri_start[v->triangles[t].material]] = t;
    uint64_t bytes = 0;
    for (uint32_t m = 0; m < nm; m++) {
        s->nv[m] = glb_scene_map(s, m, m + 1, 0);
        if (s->nv[m] > s->max_nv) s->max_nv = s->nv[m];
        bytes += (uint64_t)s->nv[m] * GLB_SCENE_VERTEX_BYTES +
            (uint64_t)(s->tri_start[m + 1] - s->tri_start[m]) * GLB_TRIANGLE_BYTES;
    }
    memset(cnt, 0, (nm ? nm : 1) * sizeof *cnt);
    for (uint32_t i = 0; i < v->n_surfels; i++) {
        const lc_lcb_surfel *sf = &v->surfels[i];
        for (int c = 0; c < 3; c++) sum[sf->material][c] += sf->albedo[c];
        cnt[sf->material]++;
    }
    for (uint32_t m = 0; m < nm; m++)
        for (int c = 0; c < 3; c++)
            s->base[m][c] =
                (v->materials[m].flags & 1u) && cnt[m] ? (float)(sum[m][c] / cnt[m]) : v->materials[m].base_color[c];
    *bin_bytes = bytes;
    rc = 0;
out:
    free(sum);
    free(cnt);
    return rc;
}

/* Material mi's primitive: its vertices (POSITION, NORMAL, the lightmap UV as TEXCOORD_0
 * and TEXCOORD_1), its triangles in local indices. NULL out of memory. */
static cJSON *glb_scene_primitive(glb_doc *d, glb_scene *s, uint32_t mi, uint32_t epoch) {
    const lc_lcb_view *v = s->v;
    uint32_t n = glb_scene_map(s, mi, epoch, 1);
    for (uint32_t i = 0; i < n; i++) {
        const lc_lcb_triangle *t = &v->triangles[s->inv_tri[i]];
        glb_normal(v->vertices[s->inv[i]].normal, v->vertices[t->v[0]].position, v->vertices[t->v[1]].position,
                   v->vertices[t->v[2]].position, s->normals + 3 * (size_t)i);
    }
    cJSON *prim = cJSON_CreateObject();
    cJSON *attrs = prim ? cJSON_AddObjectToObject(prim, "attributes") : NULL;
    if (!attrs) goto err;
    const size_t vs = sizeof(lc_lcb_vertex);
    int pos = glb_attr(d, v->vertices[0].position, vs, s->inv, n, 3, 1, 0);
    int nrm = glb_attr(d, s->normals, 3 * sizeof(float), NULL, n, 3, 0, 0);
    int uv = glb_attr(d, v->vertices[0].uv1, vs, s->inv, n, 2, 0, 0);
    if (pos < 0 || nrm < 0 || uv < 0 || !cJSON_AddNumberToObject(attrs, "POSITION", pos) ||
        !cJSON_AddNumberToObject(attrs, "NORMAL", nrm) || !cJSON_AddNumberToObject(attrs, "TEXCOORD_0", uv) ||
        !cJSON_AddNumberToObject(attrs, "TEXCOORD_1", uv))
        goto err;
    size_t off = d->bin_len;
    uint32_t ntri = s->tri_start[mi + 1] - s->tri_start[mi];
    for (uint32_t k = s->tri_start[mi]; k < s->tri_start[mi + 1]; k++)
        for (int c = 0; c < 3; c++) glb_u32(d, s->map[v->triangles[s->order[k]].v[c]]);
    int idx = glb_accessor(d, off, GL_ELEMENT_ARRAY_BUFFER, GL_UNSIGNED_INT, 3 * ntri, "SCALAR");
    if (idx < 0 || !cJSON_AddNumberToObject(prim, "indices", idx) || !cJSON_AddNumberToObject(prim, "material", mi) ||
        !cJSON_AddNumberToObject(prim, "mode", GL_TRIANGLES))
        goto err;
    return prim;
err:
    cJSON_Delete(prim);
    return NULL;
}

int lc_lcb_scene_glb(const lc_lcb *f, unsigned char **out, size_t *len, char *err, size_t errlen) {
    glb_scene s = {0};
    glb_doc d = {0};
    cJSON *prims = NULL;
    uint64_t bin_bytes = 0;
    int uses_strength = 0, rc = -1;
    if (!f || !out || !len) {
        lc_set_err(err, errlen, "scene glTF: no bake file or output given");
        return -1;
    }
    *out = NULL, *len = 0;
    s.v = lc_lcb_get(f);
    if (glb_scene_plan(&s, &bin_bytes, err, errlen) != 0) goto out;
    if (glb_doc_open(&d, f, bin_bytes, NULL, err, errlen) != 0) goto out;
    s.inv = malloc((s.max_nv ? s.max_nv : 1) * sizeof *s.inv);
    s.inv_tri = malloc((s.max_nv ? s.max_nv : 1) * sizeof *s.inv_tri);
    s.normals = malloc((s.max_nv ? s.max_nv : 1) * 3 * sizeof *s.normals);
    prims = cJSON_CreateArray();
    if (!s.inv || !s.inv_tri || !s.normals || !prims) goto oom;
    for (uint32_t m = 0; m < s.v->n_materials; m++)
        if (glb_material(&d, s.v->materials[m].name, s.base[m], s.v->materials[m].emission, &uses_strength) != 0)
            goto oom;
    for (uint32_t m = 0; m < s.v->n_materials; m++) {
        if (s.tri_start[m + 1] == s.tri_start[m]) continue;
        /* epochs after the planning pass's 1..n_materials, so every vertex maps afresh */
        cJSON *p = glb_scene_primitive(&d, &s, m, s.v->n_materials + 1 + m);
        if (!p) goto oom;
        cJSON_AddItemToArray(prims, p);
    }
    rc = glb_node(&d, "lucent", prims);
    prims = NULL;
    if (rc != 0) goto oom;
    rc = glb_finish(&d, uses_strength, out, len, err, errlen);
    goto out;
oom:
    rc = -1;
    lc_set_err(err, errlen, "scene glTF: out of memory building the document");
out:
    cJSON_Delete(prims);
    glb_doc_free(&d);
    glb_scene_free(&s);
    return rc;
}

/* --- an asset ------------------------------------------------------------------------------- */

/* The vertices' sparse-point tables (AVNN, PROTOCOL §8.7) as four attributes of attrs:
 * _LUCENT_SP_INDEX0/1 = indices 0-3 / 4-7 among the asset's points (VEC4 UNSIGNED_SHORT, two
 * per 4-byte word, little-endian), _LUCENT_SP_WEIGHT0/1 = their weights (VEC4 FLOAT, the
 * eq. 12 weights normalised to sum 1). Returns 0 or -1 (out of memory). */
static int glb_asset_sparse(glb_doc *d, const lc_lcb_sparse_vertex *r, uint32_t n, cJSON *attrs) {
    static const char *const names[4] = {"_LUCENT_SP_INDEX0", "_LUCENT_SP_INDEX1", "_LUCENT_SP_WEIGHT0",
                                         "_LUCENT_SP_WEIGHT1"};
    for (int a = 0; a < 4; a++) {
        size_t off = d->bin_len;
        int half = 4 * (a & 1);
        for (uint32_t i = 0; i < n; i++)
            for (int k = half; k < half + 4; k += a < 2 ? 2 : 1) {
                if (a < 2) glb_u32(d, (uint32_t)r[i].index[k] | (uint32_t)r[i].index[k + 1] << 16);
                else glb_f32(d, r[i].weight[k]);
            }
        int acc = glb_accessor(d, off, GL_ARRAY_BUFFER, a < 2 ? GL_UNSIGNED_SHORT : GL_FLOAT, n, "VEC4");
        if (acc < 0 || !cJSON_AddNumberToObject(attrs, names[a], acc)) return -1;
    }
    return 0;
}

/* The asset's one primitive: POSITION, NORMAL, COLOR_0 over all its vertices, its triangles.
 * vtri is a scratch of vertex_count entries, normals of 3 x vertex_count. NULL out of memory. */
static cJSON *glb_asset_primitive(glb_doc *d, const lc_lcb_view *v, const lc_lcb_asset *a, uint32_t *vtri,
                                  float *normals) {
    const lc_lcb_asset_vertex *av = v->asset_vertices + a->first_vertex;
    const uint32_t *ix = v->asset_indices + 3 * (size_t)a->first_triangle;
    for (uint32_t i = 0; i < a->vertex_count; i++) vtri[i] = LC_NONE;
    for (uint32_t t = 0; t < a->triangle_count; t++)
        for (int c = 0; c < 3; c++)
            if (vtri[ix[3 * (size_t)t + c]] == LC_NONE) vtri[ix[3 * (size_t)t + c]] = t;
    for (uint32_t i = 0; i < a->vertex_count; i++) {
        const uint32_t *t = vtri[i] != LC_NONE ? ix + 3 * (size_t)vtri[i] : NULL;
        glb_normal(av[i].normal, t ? av[t[0]].position : NULL, t ? av[t[1]].position : NULL,
                   t ? av[t[2]].position : NULL, normals + 3 * (size_t)i);
    }
    cJSON *prim = cJSON_CreateObject();
    cJSON *attrs = prim ? cJSON_AddObjectToObject(prim, "attributes") : NULL;
    if (!attrs) goto err;
    const size_t vs = sizeof(lc_lcb_asset_vertex);
    int pos = glb_attr(d, av[0].position, vs, NULL, a->vertex_count, 3, 1, 0);
    int nrm = glb_attr(d, normals, 3 * sizeof(float), NULL, a->vertex_count, 3, 0, 0);
    int col = glb_attr(d, av[0].albedo, vs, NULL, a->vertex_count, 3, 0, 1);
    if (pos < 0 || nrm < 0 || col < 0 || !cJSON_AddNumberToObject(attrs, "POSITION", pos) ||
        !cJSON_AddNumberToObject(attrs, "NORMAL", nrm) || !cJSON_AddNumberToObject(attrs, "COLOR_0", col))
        goto err;
    uint32_t first, points;
    if (lc_lcb_asset_sparse(v, (uint32_t)(a - v->assets), &first, &points) &&
        glb_asset_sparse(d, v->sparse_vertices + a->first_vertex, a->vertex_count, attrs) != 0)
        goto err;
    size_t off = d->bin_len;
    for (size_t k = 0; k < 3 * (size_t)a->triangle_count; k++) glb_u32(d, ix[k]);
    int idx = glb_accessor(d, off, GL_ELEMENT_ARRAY_BUFFER, GL_UNSIGNED_INT, 3 * a->triangle_count, "SCALAR");
    if (idx < 0 || !cJSON_AddNumberToObject(prim, "indices", idx) || !cJSON_AddNumberToObject(prim, "material", 0) ||
        !cJSON_AddNumberToObject(prim, "mode", GL_TRIANGLES))
        goto err;
    return prim;
err:
    cJSON_Delete(prim);
    return NULL;
}

/* mesh 0's extras.lucent (PROTOCOL §8.7): "sparse_points" = n, the points its tables refer to,
 * and "sparse_point_accessors" {"position", "normal", "radius"}: accessors (VEC3, VEC3, SCALAR
 * float, asset-local) of the points themselves, which no primitive uses (a viewer draws them). */
static int glb_mesh_sparse_extras(glb_doc *d, const lc_lcb_sparse_point *sp, uint32_t n) {
    cJSON *mesh = cJSON_GetArrayItem(cJSON_GetObjectItem(d->root, "meshes"), 0);
    cJSON *extras = mesh ? cJSON_AddObjectToObject(mesh, "extras") : NULL;
    cJSON *lucent = extras ? cJSON_AddObjectToObject(extras, "lucent") : NULL;
    cJSON *accs = lucent ? cJSON_AddObjectToObject(lucent, "sparse_point_accessors") : NULL;
    if (!accs || !cJSON_AddNumberToObject(lucent, "sparse_points", n)) return -1;
    int pos = glb_attr(d, sp[0].position, sizeof *sp, NULL, n, 3, 1, 0);
    int nrm = glb_attr(d, sp[0].normal, sizeof *sp, NULL, n, 3, 0, 0);
    int rad = glb_attr(d, &sp[0].radius, sizeof *sp, NULL, n, 1, 0, 0);
    return pos >= 0 && nrm >= 0 && rad >= 0 && cJSON_AddNumberToObject(accs, "position", pos) &&
            cJSON_AddNumberToObject(accs, "normal", nrm) && cJSON_AddNumberToObject(accs, "radius", rad)
        ? 0
        : -1;
}

int lc_lcb_asset_glb(const lc_lcb *f, uint32_t asset, unsigned char **out, size_t *len, char *err, size_t errlen) {
    static const float white[3] = {1, 1, 1}, black[3] = {0, 0, 0};
    glb_doc d = {0};
    cJSON *prims = NULL;
    uint32_t *vtri = NULL;
    float *normals = NULL;
    int uses_strength = 0, rc = -1;
    if (!f || !out || !len) {
        lc_set_err(err, errlen, "asset glTF: no bake file or output given");
        return -1;
    }
    *out = NULL, *len = 0;
    const lc_lcb_view *v = lc_lcb_get(f);
    if (asset >= v->n_assets) {
        lc_set_err(err, errlen, "asset glTF: asset index %u out of range (the bake has %u assets)", asset, v->n_assets);
        return -1;
    }
    const lc_lcb_asset *a = &v->assets[asset];
    /* a mesh needs vertices and triangles; an empty asset is a node alone */
    int has_mesh = a->vertex_count > 0 && a->triangle_count > 0;
    uint32_t sp_first, sp_count;
    lc_lcb_asset_sparse(v, asset, &sp_first, &sp_count);
    uint64_t vertex_bytes = GLB_ASSET_VERTEX_BYTES + (sp_count ? GLB_ASSET_SPARSE_BYTES : 0);
    uint64_t bin_bytes = has_mesh ? (uint64_t)a->vertex_count * vertex_bytes +
            (uint64_t)a->triangle_count * GLB_TRIANGLE_BYTES + (uint64_t)sp_count * GLB_SPARSE_POINT_BYTES
                                  : 0;
    if (glb_doc_open(&d, f, bin_bytes, a->name, err, errlen) != 0) return -1;
    vtri = malloc((a->vertex_count ? a->vertex_count : 1) * sizeof *vtri);
    normals = malloc((a->vertex_count ? a->vertex_count : 1) * 3 * sizeof *normals);
    prims = cJSON_CreateArray();
    if (!vtri || !normals || !prims || glb_material(&d, a->name, white, black, &uses_strength) != 0) goto oom;
    if (has_mesh) {
        cJSON *p = glb_asset_primitive(&d, v, a, vtri, normals);
        if (!p) goto oom;
        cJSON_AddItemToArray(prims, p);
    }
    rc = glb_node(&d, a->name, prims);
    prims = NULL;
    if (rc != 0 || (has_mesh && sp_count && glb_mesh_sparse_extras(&d, v->sparse_points + sp_first, sp_count) != 0))
        goto oom;
    rc = glb_finish(&d, uses_strength, out, len, err, errlen);
    goto out;
oom:
    rc = -1;
    lc_set_err(err, errlen, "asset glTF: asset %u (\"%s\"): out of memory building the document", asset, a->name);
out:
    cJSON_Delete(prims);
    glb_doc_free(&d);
    free(vtri);
    free(normals);
    return rc;
}

/* --- the bake id ---------------------------------------------------------------------------- */

void lc_lcb_bake_id(const lc_lcb *f, char out[LC_LCB_BAKE_ID_LEN]) {
    lc_lcb_section table[LC_LCB_MAX_SECTIONS];
    out[0] = 0;
    if (!f) return;
    uint32_t n = lc_lcb_section_count(f);
    if (n > LC_LCB_MAX_SECTIONS) n = LC_LCB_MAX_SECTIONS;
    uint64_t end = sizeof(lc_lcb_header) + (uint64_t)n * sizeof(lc_lcb_section);
    for (uint32_t i = 0; i < n; i++) {
        table[i] = *lc_lcb_section_at(f, i);
        if (table[i].offset + table[i].size > end) end = table[i].offset + table[i].size;
    }
    uint64_t file_size = (end + LC_LCB_ALIGN - 1) / LC_LCB_ALIGN * LC_LCB_ALIGN;
    snprintf(out, LC_LCB_BAKE_ID_LEN, "%08x%016llx", (unsigned)lc_crc32(0, table, (size_t)n * sizeof *table),
             (unsigned long long)file_size);
}
