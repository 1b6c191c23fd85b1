/* glb_write: the baked scene as a binary glTF 2.0 file for viewers. One primitive per used
 * material, each with its own compact vertex subset so viewers and importers never see
 * vertices a primitive does not reference. Materials carry factors only (no images): a
 * textured material gets factor x texture mean, which is what a lightmap preview needs. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/scene.h"
#include "util/fsutil.h"
#include "util/log.h"

#define GLB_MAGIC 0x46546C67u       /* "glTF" */
#define GLB_CHUNK_JSON 0x4E4F534Au  /* "JSON" */
#define GLB_CHUNK_BIN 0x004E4942u   /* "BIN\0" */
#define GLB_MAX_BYTES 0xFFFFFF00ull /* the header's length field is 32-bit */

#define GL_FLOAT 5126
#define GL_UNSIGNED_INT 5125
#define GL_ARRAY_BUFFER 34962
#define GL_ELEMENT_ARRAY_BUFFER 34963

typedef struct {
    unsigned char *data;
    size_t len, cap;
} glb_buf;

static int buf_reserve(glb_buf *b, size_t extra) {
    if (extra > GLB_MAX_BYTES || b->len + extra > GLB_MAX_BYTES) return -1;
    if (b->len + extra <= b->cap) return 0;
    size_t cap = b->cap ? b->cap : 4096;
    while (cap < b->len + extra) cap *= 2;
    unsigned char *p = realloc(b->data, cap);
    if (!p) return -1;
    b->data = p, b->cap = cap;
    return 0;
}

static void put_u32(unsigned char *p, uint32_t v) {
    p[0] = (unsigned char)v, p[1] = (unsigned char)(v >> 8), p[2] = (unsigned char)(v >> 16),
    p[3] = (unsigned char)(v >> 24);
}

static void put_f32(unsigned char *p, float f) {
    uint32_t v;
    memcpy(&v, &f, sizeof v);
    put_u32(p, v); /* explicit little-endian: the format is LE whatever the host */
}

/* Adds an accessor (with its own bufferView) over bytes [off, off+len) of the BIN chunk. */
static int add_accessor(cJSON *views, cJSON *accessors, size_t off, size_t len, int target, int ctype, uint32_t count,
                        const char *type) {
    cJSON *v = cJSON_CreateObject();
    if (!v) return -1;
    cJSON_AddItemToArray(views, v);
    if (!cJSON_AddNumberToObject(v, "buffer", 0) || !cJSON_AddNumberToObject(v, "byteOffset", (double)off) ||
        !cJSON_AddNumberToObject(v, "byteLength", (double)len) || !cJSON_AddNumberToObject(v, "target", target))
        return -1;
    cJSON *a = cJSON_CreateObject();
    if (!a) return -1;
    cJSON_AddItemToArray(accessors, a);
    if (!cJSON_AddNumberToObject(a, "bufferView", cJSON_GetArraySize(views) - 1) ||
        !cJSON_AddNumberToObject(a, "componentType", ctype) || !cJSON_AddNumberToObject(a, "count", count) ||
        !cJSON_AddStringToObject(a, "type", type))
        return -1;
    return cJSON_GetArraySize(accessors) - 1;
}

static cJSON *float_array(const float *v, int n) {
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

static float clamp01(float x) { return isfinite(x) ? fminf(fmaxf(x, 0.0f), 1.0f) : 0.0f; }

static cJSON *material_json(const lc_scene *scene, const lc_material *m, int *uses_strength) {
    cJSON *j = cJSON_CreateObject();
    if (!j) return NULL;
    float base[4] = {m->base_color[0], m->base_color[1], m->base_color[2], 1.0f};
    if (m->base_texture >= 0 && (uint32_t)m->base_texture < scene->n_textures) {
        const lc_texture *t = &scene->textures[m->base_texture];
        if (t->rgb && t->width && t->height) {
            double sum[3] = {0, 0, 0};
            size_t np = (size_t)t->width * t->height;
            for (size_t i = 0; i < np; i++)
                for (int c = 0; c < 3; c++) sum[c] += isfinite(t->rgb[3 * i + c]) ? t->rgb[3 * i + c] : 0.0;
            for (int c = 0; c < 3; c++) base[c] *= (float)(sum[c] / (double)np);
        }
    }
    for (int c = 0; c < 3; c++) base[c] = clamp01(base[c]);
    float e[3], emax = 0;
    for (int c = 0; c < 3; c++) {
        e[c] = (isfinite(m->emission[c]) && m->emission[c] > 0) ? m->emission[c] : 0.0f;
        emax = fmaxf(emax, e[c]);
    }
    /* emissiveFactor is limited to [0,1]; brighter emitters move the magnitude into the strength */
    float strength = 1.0f;
    if (emax > 1.0f) {
        for (int c = 0; c < 3; c++) e[c] /= emax;
        strength = emax;
    }
    cJSON *pbr = cJSON_CreateObject();
    if (!pbr) goto err;
    cJSON_AddItemToObject(j, "pbrMetallicRoughness", pbr);
    cJSON *bc = float_array(base, 4), *ef = float_array(e, 3);
    if (!bc || !ef) {
        cJSON_Delete(bc), cJSON_Delete(ef);
        goto err;
    }
    cJSON_AddItemToObject(pbr, "baseColorFactor", bc);
    if (!cJSON_AddNumberToObject(pbr, "metallicFactor", 0) || !cJSON_AddNumberToObject(pbr, "roughnessFactor", 1))
        goto err;
    if (!cJSON_AddStringToObject(j, "name", m->name)) goto err;
    cJSON_AddItemToObject(j, "emissiveFactor", ef);
    if (!cJSON_AddFalseToObject(j, "doubleSided")) goto err;
    if (strength > 1.0f) {
        cJSON *ext = cJSON_AddObjectToObject(j, "extensions");
        cJSON *ks = ext ? cJSON_AddObjectToObject(ext, "KHR_materials_emissive_strength") : NULL;
        if (!ks || !cJSON_AddNumberToObject(ks, "emissiveStrength", strength)) goto err;
        *uses_strength = 1;
    }
    return j;
err:
    cJSON_Delete(j);
    return NULL;
}

/* Writes one primitive's vertex and index data for material mi into bin, adds its accessors
 * and returns the primitive object (NULL on OOM / size overflow). map and stamp are
 * n_vertices scratch arrays. */
static cJSON *write_primitive(const lc_scene *scene, uint32_t mi, uint32_t ntri, glb_buf *bin, cJSON *views,
                              cJSON *accessors, uint32_t *map, uint32_t *stamp) {
    const lc_mesh *m = &scene->mesh;
    uint32_t nv = 0;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        if (m->material[t] != mi) continue;
        for (int k = 0; k < 3; k++) {
            uint32_t v = m->index[3 * (size_t)t + k];
            if (stamp[v] != mi + 1) stamp[v] = mi + 1, map[v] = nv++;
        }
    }
    /* the local vertex order is map order: gather the inverse */
    uint32_t *inv = malloc((size_t)nv * sizeof *inv);
    if (!inv) return NULL;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        if (m->material[t] != mi) continue;
        for (int k = 0; k < 3; k++) inv[map[m->index[3 * (size_t)t + k]]] = m->index[3 * (size_t)t + k];
    }
    cJSON *prim = cJSON_CreateObject();
    cJSON *attrs = prim ? cJSON_AddObjectToObject(prim, "attributes") : NULL;
    if (!attrs) goto err;
    int has_uv1 = m->uv1 != NULL, has_uv0 = m->uv0 != NULL;
    size_t need = (size_t)nv * (12 + 12 + (has_uv0 ? 8 : 0) + (has_uv1 ? 8 : 0)) + (size_t)ntri * 12;
    if (buf_reserve(bin, need) < 0) goto err;

    /* POSITION with the min/max glTF requires */
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    size_t off = bin->len;
    for (uint32_t i = 0; i < nv; i++)
        for (int c = 0; c < 3; c++) {
            float p = m->position[3 * (size_t)inv[i] + c];
            lo[c] = fminf(lo[c], p), hi[c] = fmaxf(hi[c], p);
            put_f32(bin->data + bin->len, p), bin->len += 4;
        }
    int acc = add_accessor(views, accessors, off, bin->len - off, GL_ARRAY_BUFFER, GL_FLOAT, nv, "VEC3");
    cJSON *a = acc >= 0 ? cJSON_GetArrayItem(accessors, acc) : NULL;
    cJSON *jmin = float_array(lo, 3), *jmax = float_array(hi, 3);
    if (!a || !jmin || !jmax) {
        cJSON_Delete(jmin), cJSON_Delete(jmax);
        goto err;
    }
    cJSON_AddItemToObject(a, "min", jmin);
    cJSON_AddItemToObject(a, "max", jmax);
    if (!cJSON_AddNumberToObject(attrs, "POSITION", acc)) goto err;

    /* NORMAL: glTF requires unit length; a broken normal falls back to the face's */
    off = bin->len;
    for (uint32_t i = 0; i < nv; i++) {
        float n[3] = {0, 1, 0};
        if (m->normal) {
            const float *s = m->normal + 3 * (size_t)inv[i];
            float l = sqrtf(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
            if (isfinite(l) && l > 1e-12f)
                for (int c = 0; c < 3; c++) n[c] = s[c] / l;
        }
        for (int c = 0; c < 3; c++) put_f32(bin->data + bin->len, n[c]), bin->len += 4;
    }
    acc = add_accessor(views, accessors, off, bin->len - off, GL_ARRAY_BUFFER, GL_FLOAT, nv, "VEC3");
    if (acc < 0 || !cJSON_AddNumberToObject(attrs, "NORMAL", acc)) goto err;

    if (has_uv0) { /* stored OpenGL-convention: glTF's v runs down */
        off = bin->len;
        for (uint32_t i = 0; i < nv; i++) {
            put_f32(bin->data + bin->len, m->uv0[2 * (size_t)inv[i]]), bin->len += 4;
            put_f32(bin->data + bin->len, 1.0f - m->uv0[2 * (size_t)inv[i] + 1]), bin->len += 4;
        }
        acc = add_accessor(views, accessors, off, bin->len - off, GL_ARRAY_BUFFER, GL_FLOAT, nv, "VEC2");
        if (acc < 0 || !cJSON_AddNumberToObject(attrs, "TEXCOORD_0", acc)) goto err;
    }
    if (has_uv1) { /* already glTF convention */
        off = bin->len;
        for (uint32_t i = 0; i < nv; i++) {
            put_f32(bin->data + bin->len, m->uv1[2 * (size_t)inv[i]]), bin->len += 4;
            put_f32(bin->data + bin->len, m->uv1[2 * (size_t)inv[i] + 1]), bin->len += 4;
        }
        acc = add_accessor(views, accessors, off, bin->len - off, GL_ARRAY_BUFFER, GL_FLOAT, nv, "VEC2");
        if (acc < 0 || !cJSON_AddNumberToObject(attrs, "TEXCOORD_1", acc)) goto err;
    }

    off = bin->len;
    for (uint32_t t = 0; t < m->n_triangles; t++) {
        if (m->material[t] != mi) continue;
        for (int k = 0; k < 3; k++) put_u32(bin->data + bin->len, map[m->index[3 * (size_t)t + k]]), bin->len += 4;
    }
    acc = add_accessor(views, accessors, off, bin->len - off, GL_ELEMENT_ARRAY_BUFFER, GL_UNSIGNED_INT, ntri * 3,
                       "SCALAR");
    if (acc < 0 || !cJSON_AddNumberToObject(prim, "indices", acc) || !cJSON_AddNumberToObject(prim, "material", mi) ||
        !cJSON_AddNumberToObject(prim, "mode", 4))
        goto err;
    free(inv);
    return prim;
err:
    free(inv);
    cJSON_Delete(prim);
    return NULL;
}

/* Refuses what the writer could not index safely: no path or scene, a mesh with arrays
 * missing, indices or materials out of range. -1 with err. */
static int glb_check_scene(const char *path, const lc_scene *scene, char *err, size_t errlen) {
    if (!path || !scene) {
        lc_set_err(err, errlen, "glb write: no output path or scene given");
        return -1;
    }
    const lc_mesh *m = &scene->mesh;
    if (m->n_triangles && (!m->position || !m->index || !m->material || m->n_vertices == 0)) {
        lc_set_err(err, errlen, "%s: the scene mesh is incomplete (positions/indices/materials missing)", path);
        return -1;
    }
    if (scene->n_materials == 0 && m->n_triangles) {
        lc_set_err(err, errlen, "%s: the scene has triangles but no materials", path);
        return -1;
    }
    for (size_t i = 0; i < 3 * (size_t)m->n_triangles; i++)
        if (m->index[i] >= m->n_vertices) {
            lc_set_err(err, errlen, "%s: triangle %zu references vertex %u of %u; the mesh is corrupt", path, i / 3,
                       m->index[i], m->n_vertices);
            return -1;
        }
    for (uint32_t t = 0; t < m->n_triangles; t++)
        if (m->material[t] >= scene->n_materials) {
            lc_set_err(err, errlen, "%s: triangle %u uses material %u of %u; the mesh is corrupt", path, t,
                       m->material[t], scene->n_materials);
            return -1;
        }
    return 0;
}

/* The mesh of the primitives, the node showing it and the scene of that node. prims is
 * always taken (added to root or freed): an empty scene gets neither mesh nor node and is
 * still a valid file. -1 out of memory. */
static int glb_add_mesh(cJSON *root, cJSON *prims) {
    int n_prims = cJSON_GetArraySize(prims);
    if (n_prims > 0) {
        cJSON *meshes = cJSON_AddArrayToObject(root, "meshes");
        cJSON *mesh = cJSON_CreateObject();
        if (!meshes || !mesh) {
            cJSON_Delete(mesh), cJSON_Delete(prims);
            return -1;
        }
        cJSON_AddItemToArray(meshes, mesh);
        cJSON_AddItemToObject(mesh, "primitives", prims);
        cJSON *nodes = cJSON_AddArrayToObject(root, "nodes");
        cJSON *node = cJSON_CreateObject();
        if (!nodes || !node) {
            cJSON_Delete(node);
            return -1;
        }
        cJSON_AddItemToArray(nodes, node);
        if (!cJSON_AddStringToObject(node, "name", "lucent") || !cJSON_AddNumberToObject(node, "mesh", 0)) return -1;
    } else {
        cJSON_Delete(prims);
    }
    cJSON *scenes = cJSON_AddArrayToObject(root, "scenes");
    cJSON *sc = cJSON_CreateObject();
    if (!scenes || !sc) {
        cJSON_Delete(sc);
        return -1;
    }
    cJSON_AddItemToArray(scenes, sc);
    cJSON *sn = cJSON_AddArrayToObject(sc, "nodes");
    if (!sn) return -1;
    if (n_prims > 0) {
        cJSON *zero = cJSON_CreateNumber(0);
        if (!zero) return -1;
        cJSON_AddItemToArray(sn, zero);
    }
    return cJSON_AddNumberToObject(root, "scene", 0) ? 0 : -1;
}

/* What follows the scene: the extension list when an emitter needed its strength, and the
 * BIN chunk's one buffer. -1 out of memory. */
static int glb_add_tail(cJSON *root, int uses_strength, size_t bin_len) {
    if (uses_strength) {
        cJSON *used = cJSON_AddArrayToObject(root, "extensionsUsed");
        cJSON *name = cJSON_CreateString("KHR_materials_emissive_strength");
        if (!used || !name) {
            cJSON_Delete(name);
            return -1;
        }
        cJSON_AddItemToArray(used, name);
    }
    if (bin_len) {
        cJSON *buffers = cJSON_AddArrayToObject(root, "buffers");
        cJSON *b0 = cJSON_CreateObject();
        if (!buffers || !b0) {
            cJSON_Delete(b0);
            return -1;
        }
        cJSON_AddItemToArray(buffers, b0);
        if (!cJSON_AddNumberToObject(b0, "byteLength", (double)bin_len)) return -1;
    }
    return 0;
}

/* The GLB container in *file (*total bytes): header, the JSON chunk padded with spaces (as
 * the spec asks), the BIN chunk padded with zeros. -1 with err. */
static int glb_pack(const char *path, const char *json, const glb_buf *bin, unsigned char **file, size_t *total,
                    char *err, size_t errlen) {
    size_t jlen = strlen(json), jpad = (jlen + 3) & ~(size_t)3, bpad = (bin->len + 3) & ~(size_t)3;
    *total = 12 + 8 + jpad + (bin->len ? 8 + bpad : 0);
    if (*total > GLB_MAX_BYTES) {
        lc_set_err(err, errlen, "%s: the GLB would be %zu bytes, over the format's 4 GiB limit", path, *total);
        return -1;
    }
    unsigned char *p = *file = malloc(*total);
    if (!p) {
        lc_set_err(err, errlen, "%s: out of memory building the glTF", path);
        return -1;
    }
    put_u32(p, GLB_MAGIC), put_u32(p + 4, 2), put_u32(p + 8, (uint32_t)*total), p += 12;
    put_u32(p, (uint32_t)jpad), put_u32(p + 4, GLB_CHUNK_JSON), p += 8;
    memcpy(p, json, jlen);
    memset(p + jlen, ' ', jpad - jlen);
    p += jpad;
    if (bin->len) {
        put_u32(p, (uint32_t)bpad), put_u32(p + 4, GLB_CHUNK_BIN), p += 8;
        memcpy(p, bin->data, bin->len);
        memset(p + bin->len, 0, bpad - bin->len);
    }
    return 0;
}

int lc_glb_write(const char *path, const lc_scene *scene, char *err, size_t errlen) {
    cJSON *root = NULL;
    char *json = NULL;
    unsigned char *file = NULL;
    uint32_t *map = NULL, *stamp = NULL, *per_mat = NULL;
    glb_buf bin = {0};
    int rc = -1;
    if (glb_check_scene(path, scene, err, errlen) != 0) return -1;
    const lc_mesh *m = &scene->mesh;

    per_mat = calloc(scene->n_materials ? scene->n_materials : 1, sizeof *per_mat);
    map = malloc((size_t)(m->n_vertices ? m->n_vertices : 1) * sizeof *map);
    stamp = calloc(m->n_vertices ? m->n_vertices : 1, sizeof *stamp);
    root = cJSON_CreateObject();
    if (!per_mat || !map || !stamp || !root) goto oom;
    for (uint32_t t = 0; t < m->n_triangles; t++) per_mat[m->material[t]]++;

    cJSON *asset = cJSON_AddObjectToObject(root, "asset");
    if (!asset || !cJSON_AddStringToObject(asset, "version", "2.0") ||
        !cJSON_AddStringToObject(asset, "generator", "lucent-bake"))
        goto oom;
    cJSON *views = cJSON_CreateArray(), *accessors = cJSON_CreateArray();
    cJSON *materials = cJSON_CreateArray(), *prims = cJSON_CreateArray();
    if (views) cJSON_AddItemToObject(root, "bufferViews", views);
    if (accessors) cJSON_AddItemToObject(root, "accessors", accessors);
    if (materials) cJSON_AddItemToObject(root, "materials", materials);
    if (!views || !accessors || !materials || !prims) {
        cJSON_Delete(prims);
        goto oom;
    }
    int uses_strength = 0;
    for (uint32_t i = 0; i < scene->n_materials; i++) {
        cJSON *mj = material_json(scene, &scene->materials[i], &uses_strength);
        if (!mj) {
            cJSON_Delete(prims);
            goto oom;
        }
        cJSON_AddItemToArray(materials, mj);
    }
    for (uint32_t i = 0; i < scene->n_materials; i++) {
        if (!per_mat[i]) continue;
        cJSON *p = write_primitive(scene, i, per_mat[i], &bin, views, accessors, map, stamp);
        if (!p) {
            cJSON_Delete(prims);
            lc_set_err(err, errlen, "%s: out of memory, or the binary chunk would exceed 4 GiB", path);
            goto out;
        }
        cJSON_AddItemToArray(prims, p);
    }
    if (glb_add_mesh(root, prims) != 0 || glb_add_tail(root, uses_strength, bin.len) != 0) goto oom;

    json = cJSON_PrintUnformatted(root);
    if (!json) goto oom;
    size_t total;
    if (glb_pack(path, json, &bin, &file, &total, err, errlen) != 0) goto out;
    rc = lc_fs_write_atomic(path, file, total, err, errlen);
    goto out;
oom:
    lc_set_err(err, errlen, "%s: out of memory building the glTF", path);
out:
    cJSON_Delete(root);
    free(json);
    free(file);
    free(bin.data);
    free(map);
    free(stamp);
    free(per_mat);
    return rc;
}
