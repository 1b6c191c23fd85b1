/* import: lc_scene_import() through Assimp (glTF 2.0, OBJ+MTL, PLY). The node tree is
 * flattened into one world-space triangle mesh; textures are decoded to linear RGB through
 * the OIIO shim. Assimp 5.2 gaps are filled here: KHR_materials_emissive_strength is read
 * from the glTF JSON directly, and texture names are resolved case-insensitively because
 * OBJ assets authored on Windows rarely match the case of the files on disk. */
#include <assimp/cimport.h>
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <cjson/cJSON.h>
#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bake/image.h"
#include "bake/scene.h"
#include "util/log.h"
#include "util/utf8.h"

#define IMPORT_MAX_TEX_PIXELS (8192ull * 8192ull) /* larger textures are rejected with a warning */
#define IMPORT_MAX_DEPTH 512                      /* node nesting; deeper means a broken file */
#define IMPORT_MAX_VERTICES (1u << 30)
#define IMPORT_MAX_TRIANGLES (1u << 30)
#define IMPORT_MIN_AREA 1e-12             /* m^2, after scaling */
#define IMPORT_MAX_GLTF_JSON (256u << 20) /* .gltf (may embed base64 buffers) / .glb JSON chunk */
#define IMPORT_PATH_MAX 512

/* Row-major 4x4 like aiMatrix4x4 (a1..a4 is the first row; translation in column 4). */
typedef struct {
    double m[4][4];
} imp_mat4;

static imp_mat4 mat_identity(void) {
    imp_mat4 r;
    memset(&r, 0, sizeof r);
    for (int i = 0; i < 4; i++) r.m[i][i] = 1.0;
    return r;
}

static imp_mat4 mat_from_ai(const struct aiMatrix4x4 *a) {
    imp_mat4 r = {{{a->a1, a->a2, a->a3, a->a4},
                   {a->b1, a->b2, a->b3, a->b4},
                   {a->c1, a->c2, a->c3, a->c4},
                   {a->d1, a->d2, a->d3, a->d4}}};
    return r;
}

static imp_mat4 mat_mul(const imp_mat4 *a, const imp_mat4 *b) {
    imp_mat4 r;
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) {
            double s = 0;
            for (int k = 0; k < 4; k++) s += a->m[i][k] * b->m[k][j];
            r.m[i][j] = s;
        }
    return r;
}

static void mat_point(const imp_mat4 *a, double x, double y, double z, double out[3]) {
    for (int i = 0; i < 3; i++) out[i] = a->m[i][0] * x + a->m[i][1] * y + a->m[i][2] * z + a->m[i][3];
}

static void mat_dir(const imp_mat4 *a, double x, double y, double z, double out[3]) {
    for (int i = 0; i < 3; i++) out[i] = a->m[i][0] * x + a->m[i][1] * y + a->m[i][2] * z;
}

static double mat_det3(const imp_mat4 *a) {
    const double(*m)[4] = a->m;
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
        m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

/* Inverse transpose of the upper 3x3 up to a positive factor (cofactor matrix times sign(det)):
 * normals are renormalised afterwards, so the 1/|det| scale does not matter. */
static void mat_normal_matrix(const imp_mat4 *a, double n[3][3]) {
    const double(*m)[4] = a->m;
    double s = mat_det3(a) < 0 ? -1.0 : 1.0;
    n[0][0] = s * (m[1][1] * m[2][2] - m[1][2] * m[2][1]);
    n[0][1] = s * (m[1][2] * m[2][0] - m[1][0] * m[2][2]);
    n[0][2] = s * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    n[1][0] = s * (m[0][2] * m[2][1] - m[0][1] * m[2][2]);
    n[1][1] = s * (m[0][0] * m[2][2] - m[0][2] * m[2][0]);
    n[1][2] = s * (m[0][1] * m[2][0] - m[0][0] * m[2][1]);
    n[2][0] = s * (m[0][1] * m[1][2] - m[0][2] * m[1][1]);
    n[2][1] = s * (m[0][2] * m[1][0] - m[0][0] * m[1][2]);
    n[2][2] = s * (m[0][0] * m[1][1] - m[0][1] * m[1][0]);
}

static int finite3f(const float *v) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

/* Truncating byte copy (names longer than the field are cut, not rejected): for matching
 * against other raw names from the same file. */
static void copy_name(char *dst, size_t dstlen, const char *src) {
    if (!dstlen) return;
    size_t n = src ? strnlen(src, dstlen - 1) : 0;
    if (n) memcpy(dst, src, n);
    dst[n] = '\0';
}

/* A material or light name as it goes into the bake (and to every client): UTF-8, cut on a
 * character boundary. Bytes that are not UTF-8 (a Latin-1 .mtl, say) become U+FFFD, with a
 * warning naming the material/light and the bytes. */
static void copy_scene_name(char *dst, size_t dstlen, const char *src, const char *model, const char *what,
                            uint32_t index) {
    size_t n = src ? strlen(src) : 0;
    if (!dstlen) return;
    lc_utf8_sanitize(dst, dstlen, src ? src : "", n, 0);
    if (lc_utf8_valid(src, n)) return;
    char raw[4 * 64 + 1];
    size_t o = 0;
    for (size_t i = 0; i < n && i < 64; i++) {
        unsigned char ch = (unsigned char)src[i];
        if (ch >= 0x20 && ch < 0x7f && ch != '\\') raw[o++] = (char)ch;
        else o += (size_t)snprintf(raw + o, 5, "\\x%02x", ch);
    }
    raw[o] = 0;
    lc_warn("import",
            "%s: %s %u name \"%s\" is not valid UTF-8 (another encoding?); bad bytes replaced with "
            "U+FFFD: '%s'",
            model, what, index, raw, dst);
}

static const char *path_ext(const char *path) {
    const char *slash = strrchr(path, '/');
    const char *dot = strrchr(path, '.');
    if (!dot || (slash && dot < slash)) return "";
    return dot + 1;
}

/* ---- geometry: walking the node tree ------------------------------------------------------ */

typedef struct {
    const struct aiScene *ai;
    const char *path;
    double scale;
    int flip_winding;
    /* counting pass */
    uint64_t count_v, count_t;
    uint32_t tri_meshes, tri_meshes_with_uv1;
    /* fill pass */
    int want_uv1;
    uint32_t nv, nt;
    float *pos, *nrm, *uv0, *uv1;
    uint32_t *idx, *mat;
    uint32_t n_materials;
} imp_geo;

static int mesh_is_triangles(const struct aiMesh *m) {
    /* bit test: a triangulated OBJ quad reports TRIANGLE | NGONEncodingFlag (0x14) */
    return m && (m->mPrimitiveTypes & aiPrimitiveType_TRIANGLE) && m->mVertices && m->mNumVertices > 0;
}

static void emit_mesh(imp_geo *g, const struct aiMesh *m, const imp_mat4 *world) {
    double nm[3][3];
    mat_normal_matrix(world, nm);
    int mirrored = mat_det3(world) < 0; /* a mirroring transform reverses the winding (glTF rule) */
    int flip = g->flip_winding ^ mirrored;
    uint32_t base = g->nv;
    for (uint32_t v = 0; v < m->mNumVertices; v++) {
        uint32_t o = base + v;
        double p[3];
        const struct aiVector3D *sv = &m->mVertices[v];
        mat_point(world, sv->x, sv->y, sv->z, p);
        for (int c = 0; c < 3; c++) g->pos[3 * (size_t)o + c] = (float)(p[c] * g->scale);
        double n[3] = {NAN, NAN, NAN};
        if (m->mNormals) {
            const struct aiVector3D *sn = &m->mNormals[v];
            for (int c = 0; c < 3; c++) n[c] = nm[c][0] * sn->x + nm[c][1] * sn->y + nm[c][2] * sn->z;
            double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            /* NaN / zero normals are recomputed from the geometry after compaction */
            for (int c = 0; c < 3; c++) n[c] = (isfinite(len) && len > 1e-20) ? n[c] / len : NAN;
        }
        for (int c = 0; c < 3; c++) g->nrm[3 * (size_t)o + c] = (float)n[c];
        float u = 0, w = 0;
        if (m->mTextureCoords[0]) u = m->mTextureCoords[0][v].x, w = m->mTextureCoords[0][v].y;
        g->uv0[2 * (size_t)o] = isfinite(u) ? u : 0.0f;
        g->uv0[2 * (size_t)o + 1] = isfinite(w) ? w : 0.0f;
        if (g->want_uv1) {
            /* Assimp hands every set over in OpenGL convention; the lightmap set is kept in glTF's */
            u = m->mTextureCoords[1][v].x, w = 1.0f - m->mTextureCoords[1][v].y;
            g->uv1[2 * (size_t)o] = isfinite(u) ? u : 0.0f;
            g->uv1[2 * (size_t)o + 1] = isfinite(w) ? w : 0.0f;
        }
    }
    g->nv += m->mNumVertices;
    uint32_t mi = m->mMaterialIndex < g->n_materials ? m->mMaterialIndex : 0;
    for (uint32_t f = 0; f < m->mNumFaces; f++) {
        const struct aiFace *face = &m->mFaces[f];
        if (face->mNumIndices != 3 || !face->mIndices) continue;
        uint32_t a = face->mIndices[0], b = face->mIndices[1], c = face->mIndices[2];
        if (a >= m->mNumVertices || b >= m->mNumVertices || c >= m->mNumVertices) continue;
        uint32_t *t = g->idx + 3 * (size_t)g->nt;
        t[0] = base + a;
        t[1] = base + (flip ? c : b);
        t[2] = base + (flip ? b : c);
        g->mat[g->nt++] = mi;
    }
}

/* Pass 1 (g->pos == NULL) counts, pass 2 fills; both visit the same instances in order. */
static int walk_nodes(imp_geo *g, const struct aiNode *node, const imp_mat4 *parent, int depth, char *err,
                      size_t errlen) {
    if (depth > IMPORT_MAX_DEPTH) {
        lc_set_err(err, errlen, "%s: node tree deeper than %d levels; the file is malformed", g->path,
                   IMPORT_MAX_DEPTH);
        return -1;
    }
    imp_mat4 local = mat_from_ai(&node->mTransformation);
    imp_mat4 world = mat_mul(parent, &local);
    for (uint32_t i = 0; i < node->mNumMeshes; i++) {
        if (!node->mMeshes || node->mMeshes[i] >= g->ai->mNumMeshes) continue;
        const struct aiMesh *m = g->ai->mMeshes[node->mMeshes[i]];
        if (!mesh_is_triangles(m)) continue; /* points and lines carry no surface */
        if (!g->pos) {
            uint32_t nf = 0;
            for (uint32_t f = 0; f < m->mNumFaces; f++) nf += m->mFaces[f].mNumIndices == 3;
            g->count_v += m->mNumVertices;
            g->count_t += nf;
            g->tri_meshes++;
            if (m->mTextureCoords[1]) g->tri_meshes_with_uv1++;
            if (g->count_v > IMPORT_MAX_VERTICES || g->count_t > IMPORT_MAX_TRIANGLES) {
                lc_set_err(err, errlen, "%s: more than %u vertices or %u triangles; split or decimate the scene",
                           g->path, IMPORT_MAX_VERTICES, IMPORT_MAX_TRIANGLES);
                return -1;
            }
        } else {
            emit_mesh(g, m, &world);
        }
    }
    for (uint32_t i = 0; i < node->mNumChildren; i++) {
        if (!node->mChildren || !node->mChildren[i]) continue;
        if (walk_nodes(g, node->mChildren[i], &world, depth + 1, err, errlen) < 0) return -1;
    }
    return 0;
}

/* Drops degenerate / non-finite triangles, then unused vertices (order preserved). */
static uint32_t compact_mesh(imp_geo *g, uint32_t *dropped) {
    uint32_t nt = 0;
    for (uint32_t t = 0; t < g->nt; t++) {
        const uint32_t *ix = g->idx + 3 * (size_t)t;
        const float *a = g->pos + 3 * (size_t)ix[0], *b = g->pos + 3 * (size_t)ix[1], *c = g->pos + 3 * (size_t)ix[2];
        int ok = finite3f(a) && finite3f(b) && finite3f(c);
        if (ok) {
            double e1[3] = {(double)b[0] - a[0], (double)b[1] - a[1], (double)b[2] - a[2]};
            double e2[3] = {(double)c[0] - a[0], (double)c[1] - a[1], (double)c[2] - a[2]};
            double cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2],
                   cz = e1[0] * e2[1] - e1[1] * e2[0];
            double area = 0.5 * sqrt(cx * cx + cy * cy + cz * cz);
            ok = isfinite(area) && area >= IMPORT_MIN_AREA;
        }
        if (!ok) continue;
        if (nt != t) {
            memmove(g->idx + 3 * (size_t)nt, ix, 3 * sizeof(uint32_t));
            g->mat[nt] = g->mat[t];
        }
        nt++;
    }
    *dropped = g->nt - nt;
    g->nt = nt;
    return nt;
}

static int compact_vertices(imp_geo *g) {
    uint32_t *remap = malloc((size_t)(g->nv ? g->nv : 1) * sizeof *remap);
    if (!remap) return -1;
    for (uint32_t v = 0; v < g->nv; v++) remap[v] = LC_NONE;
    for (size_t i = 0; i < 3 * (size_t)g->nt; i++) remap[g->idx[i]] = 0;
    uint32_t nv = 0;
    for (uint32_t v = 0; v < g->nv; v++) {
        if (remap[v] == LC_NONE) continue;
        remap[v] = nv;
        if (nv != v) { /* nv < v: moving forward in place is safe */
            memcpy(g->pos + 3 * (size_t)nv, g->pos + 3 * (size_t)v, 3 * sizeof(float));
            memcpy(g->nrm + 3 * (size_t)nv, g->nrm + 3 * (size_t)v, 3 * sizeof(float));
            memcpy(g->uv0 + 2 * (size_t)nv, g->uv0 + 2 * (size_t)v, 2 * sizeof(float));
            if (g->uv1) memcpy(g->uv1 + 2 * (size_t)nv, g->uv1 + 2 * (size_t)v, 2 * sizeof(float));
        }
        nv++;
    }
    for (size_t i = 0; i < 3 * (size_t)g->nt; i++) g->idx[i] = remap[g->idx[i]];
    g->nv = nv;
    free(remap);
    return 0;
}

/* Recomputes missing/NaN normals from adjacent faces (area weighted). With flip_winding, a
 * normal that opposes its faces was generated from the original winding and is turned over. */
static int fix_normals(imp_geo *g) {
    double *acc = calloc((size_t)(g->nv ? g->nv : 1) * 3, sizeof *acc);
    if (!acc) return -1;
    for (uint32_t t = 0; t < g->nt; t++) {
        const uint32_t *ix = g->idx + 3 * (size_t)t;
        const float *a = g->pos + 3 * (size_t)ix[0], *b = g->pos + 3 * (size_t)ix[1], *c = g->pos + 3 * (size_t)ix[2];
        double e1[3] = {(double)b[0] - a[0], (double)b[1] - a[1], (double)b[2] - a[2]};
        double e2[3] = {(double)c[0] - a[0], (double)c[1] - a[1], (double)c[2] - a[2]};
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        for (int k = 0; k < 3; k++)
            for (int c2 = 0; c2 < 3; c2++) acc[3 * (size_t)ix[k] + c2] += n[c2];
    }
    int orphan = 0;
    for (uint32_t v = 0; v < g->nv; v++) {
        float *n = g->nrm + 3 * (size_t)v;
        double *s = acc + 3 * (size_t)v;
        double len = sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
        if (!finite3f(n)) {
            if (len > 0 && isfinite(len)) {
                for (int c = 0; c < 3; c++) n[c] = (float)(s[c] / len);
            } else {
                n[0] = NAN; /* faces cancel out: resolved below from one face */
                orphan = 1;
            }
        } else if (g->flip_winding && n[0] * s[0] + n[1] * s[1] + n[2] * s[2] < 0) {
            for (int c = 0; c < 3; c++) n[c] = -n[c];
        }
    }
    if (orphan) {
        for (uint32_t t = 0; t < g->nt; t++) {
            const uint32_t *ix = g->idx + 3 * (size_t)t;
            const float *a = g->pos + 3 * (size_t)ix[0], *b = g->pos + 3 * (size_t)ix[1],
                        *c = g->pos + 3 * (size_t)ix[2];
            double e1[3] = {(double)b[0] - a[0], (double)b[1] - a[1], (double)b[2] - a[2]};
            double e2[3] = {(double)c[0] - a[0], (double)c[1] - a[1], (double)c[2] - a[2]};
            double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
            double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            for (int k = 0; k < 3; k++) {
                float *vn = g->nrm + 3 * (size_t)ix[k];
                if (!finite3f(vn))
                    for (int c2 = 0; c2 < 3; c2++) vn[c2] = (float)(n[c2] / len);
            }
        }
    }
    free(acc);
    return 0;
}

/* ---- textures ---------------------------------------------------------------------------- */

static double srgb_to_linear(double c) {
    /* IEC 61966-2-1 EOTF (exact piecewise form, not a 2.2 gamma) */
    if (!(c > 0.04045)) return c / 12.92;
    return pow((c + 0.055) / 1.055, 2.4);
}

static int ext_is_linear(const char *ext) {
    return !strcasecmp(ext, "exr") || !strcasecmp(ext, "hdr") || !strcasecmp(ext, "pfm");
}

static void decode_srgb(float *rgb, size_t n) {
    for (size_t i = 0; i < n; i++) rgb[i] = (float)srgb_to_linear(rgb[i]);
}

static int is_regular_file(const char *p) {
    struct stat st;
    return stat(p, &st) == 0 && S_ISREG(st.st_mode);
}

static int append_component(char *cur, size_t curlen, const char *comp) {
    size_t l = strlen(cur);
    int n = snprintf(cur + l, curlen - l, "%s%s", (l && cur[l - 1] != '/') ? "/" : "", comp);
    return (n < 0 || (size_t)n >= curlen - l) ? -1 : 0;
}

/* Resolves rel (already '/'-separated) against dir: the exact name first, then each path
 * component case-insensitively. Returns 0 with out filled, or -1. */
static int resolve_texture_path(const char *dir, const char *rel, char *out, size_t outlen) {
    char exact[IMPORT_PATH_MAX * 2];
    int n = rel[0] == '/' ? snprintf(exact, sizeof exact, "%s", rel) : snprintf(exact, sizeof exact, "%s/%s", dir, rel);
    if (n < 0 || (size_t)n >= sizeof exact) return -1;
    if (is_regular_file(exact)) {
        if ((size_t)n >= outlen) return -1;
        memcpy(out, exact, (size_t)n + 1);
        return 0;
    }
    char cur[IMPORT_PATH_MAX * 2], comps[IMPORT_PATH_MAX];
    if (snprintf(cur, sizeof cur, "%s", rel[0] == '/' ? "/" : dir) >= (int)sizeof cur) return -1;
    if (snprintf(comps, sizeof comps, "%s", rel) >= (int)sizeof comps) return -1;
    char *save = NULL;
    for (char *c = strtok_r(comps, "/", &save); c; c = strtok_r(NULL, "/", &save)) {
        if (!strcmp(c, ".")) continue;
        size_t l0 = strlen(cur);
        if (append_component(cur, sizeof cur, c) < 0) return -1;
        struct stat st;
        if (!strcmp(c, "..") || stat(cur, &st) == 0) continue;
        cur[l0] = '\0';
        DIR *d = opendir(l0 ? cur : "/");
        if (!d) return -1;
        const struct dirent *e;
        int found = 0;
        while ((e = readdir(d)) != NULL) {
            if (!strcasecmp(e->d_name, c)) {
                found = append_component(cur, sizeof cur, e->d_name) == 0;
                break;
            }
        }
        closedir(d);
        if (!found) return -1;
    }
    if (!is_regular_file(cur) || strlen(cur) >= outlen) return -1;
    snprintf(out, outlen, "%s", cur);
    return 0;
}

static int load_texture_file(const char *file, lc_texture *tex, char *msg, size_t msglen) {
    uint32_t w = 0, h = 0;
    float *rgb = NULL;
    if (lc_image_read_rgb(file, IMPORT_MAX_TEX_PIXELS, &w, &h, &rgb, msg, msglen) < 0) return -1;
    if (!ext_is_linear(path_ext(file))) decode_srgb(rgb, (size_t)w * h * 3);
    tex->width = w, tex->height = h, tex->rgb = rgb;
    return 0;
}

/* Embedded ("*N") textures: raw BGRA8 texels are converted directly; compressed bytes go
 * through a temp file because the image shim reads from paths only. */
static int load_texture_embedded(const struct aiTexture *t, lc_texture *tex, char *msg, size_t msglen) {
    if (!t || !t->pcData) {
        lc_set_err(msg, msglen, "embedded texture has no data");
        return -1;
    }
    if (t->mHeight > 0) {
        uint64_t np = (uint64_t)t->mWidth * t->mHeight;
        if (np > IMPORT_MAX_TEX_PIXELS) {
            lc_set_err(msg, msglen, "embedded texture %ux%u exceeds the 8192x8192 limit", t->mWidth, t->mHeight);
            return -1;
        }
        float *rgb = malloc((size_t)np * 3 * sizeof(float));
        if (!rgb) {
            lc_set_err(msg, msglen, "out of memory for an embedded %ux%u texture", t->mWidth, t->mHeight);
            return -1;
        }
        for (uint64_t i = 0; i < np; i++) {
            rgb[3 * i] = (float)srgb_to_linear(t->pcData[i].r / 255.0);
            rgb[3 * i + 1] = (float)srgb_to_linear(t->pcData[i].g / 255.0);
            rgb[3 * i + 2] = (float)srgb_to_linear(t->pcData[i].b / 255.0);
        }
        tex->width = t->mWidth, tex->height = t->mHeight, tex->rgb = rgb;
        return 0;
    }
    char hint[16] = "img";
    size_t hl = 0;
    for (size_t i = 0; i < sizeof t->achFormatHint && t->achFormatHint[i] && hl < sizeof hint - 1; i++)
        if (isalnum((unsigned char)t->achFormatHint[i])) hint[hl++] = (char)tolower((unsigned char)t->achFormatHint[i]);
    if (hl) hint[hl] = '\0';
    if (!strcmp(hint, "jpeg")) snprintf(hint, sizeof hint, "jpg");
    const char *tmpdir = getenv("TMPDIR");
    char tmp[IMPORT_PATH_MAX];
    int n = snprintf(tmp, sizeof tmp, "%s/lucent-tex-XXXXXX.%s", (tmpdir && *tmpdir) ? tmpdir : "/tmp", hint);
    if (n < 0 || (size_t)n >= sizeof tmp) {
        lc_set_err(msg, msglen, "temp path too long (TMPDIR)");
        return -1;
    }
    int fd = mkstemps(tmp, (int)strlen(hint) + 1);
    if (fd < 0) {
        lc_set_err(msg, msglen, "cannot create a temp file for an embedded texture: %s", strerror(errno));
        return -1;
    }
    const unsigned char *bytes = (const unsigned char *)t->pcData;
    size_t len = t->mWidth, off = 0;
    while (off < len) {
        ssize_t w = write(fd, bytes + off, len - off);
        if (w <= 0) break;
        off += (size_t)w;
    }
    close(fd);
    int rc = -1;
    if (off != len) lc_set_err(msg, msglen, "cannot write the embedded texture to %s", tmp);
    else rc = load_texture_file(tmp, tex, msg, msglen);
    unlink(tmp);
    return rc;
}

typedef struct {
    char key[IMPORT_PATH_MAX]; /* resolved file path or "*N" */
    int32_t index;             /* scene texture, -1 = failed (warned once) */
} imp_tex_key;

typedef struct {
    const struct aiScene *ai;
    const char *model;
    char dir[IMPORT_PATH_MAX];
    lc_scene *s;
    imp_tex_key *keys;
    uint32_t n_keys;
} imp_tex_ctx;

static int32_t texture_for(imp_tex_ctx *tc, const char *raw, const char *matname) {
    char rel[IMPORT_PATH_MAX], key[IMPORT_PATH_MAX], msg[768];
    copy_name(rel, sizeof rel, raw);
    for (char *p = rel; *p; p++)
        if (*p == '\\') *p = '/';
    int embedded = rel[0] == '*';
    long emb_index = -1;
    if (embedded) {
        char *end = NULL;
        emb_index = strtol(rel + 1, &end, 10);
        if (!end || *end || emb_index < 0 || (unsigned long)emb_index >= tc->ai->mNumTextures) {
            lc_warn("import",
                    "%s: material '%s' names embedded texture '%s', which the file lacks; using the base colour factor",
                    tc->model, matname, rel);
            return -1;
        }
        snprintf(key, sizeof key, "%s", rel);
    } else if (resolve_texture_path(tc->dir, rel, key, sizeof key) < 0) {
        /* a texture embedded by file name (some glTF exporters) is matched before giving up */
        for (uint32_t i = 0; i < tc->ai->mNumTextures; i++) {
            const struct aiTexture *t = tc->ai->mTextures[i];
            if (t && t->mFilename.length && !strcmp(t->mFilename.data, raw)) {
                embedded = 1, emb_index = (long)i;
                snprintf(key, sizeof key, "*%u", i);
                break;
            }
        }
        if (!embedded) {
            snprintf(key, sizeof key, "%s", rel);
            for (uint32_t i = 0; i < tc->n_keys; i++)
                if (!strcmp(tc->keys[i].key, key)) return tc->keys[i].index;
            lc_warn(
                "import",
                "%s: texture '%s' of material '%s' not found (also tried case-insensitively under %s); using the base colour factor",
                tc->model, rel, matname, tc->dir);
            goto remember_fail;
        }
    }
    for (uint32_t i = 0; i < tc->n_keys; i++)
        if (!strcmp(tc->keys[i].key, key)) return tc->keys[i].index;
    {
        lc_texture tex;
        memset(&tex, 0, sizeof tex);
        int rc;
        if (embedded) {
            snprintf(tex.path, sizeof tex.path, "%s", key);
            rc = load_texture_embedded(tc->ai->mTextures[emb_index], &tex, msg, sizeof msg);
        } else {
            snprintf(tex.path, sizeof tex.path, "%s", key);
            rc = load_texture_file(key, &tex, msg, sizeof msg);
        }
        if (rc < 0) {
            lc_warn("import", "%s: texture '%s' of material '%s' unreadable (%s); using the base colour factor",
                    tc->model, key, matname, msg);
            goto remember_fail;
        }
        lc_texture *grown = realloc(tc->s->textures, ((size_t)tc->s->n_textures + 1) * sizeof *grown);
        if (!grown) {
            free(tex.rgb);
            lc_warn("import", "%s: out of memory storing texture '%s'", tc->model, key);
            goto remember_fail;
        }
        tc->s->textures = grown;
        grown[tc->s->n_textures] = tex;
        int32_t index = (int32_t)tc->s->n_textures++;
        imp_tex_key *k = realloc(tc->keys, ((size_t)tc->n_keys + 1) * sizeof *k);
        if (k) {
            tc->keys = k;
            snprintf(k[tc->n_keys].key, sizeof k[tc->n_keys].key, "%s", key);
            k[tc->n_keys++].index = index;
        }
        return index;
    }
remember_fail : {
    /* remembered so a texture shared by many materials warns once */
    imp_tex_key *k = realloc(tc->keys, ((size_t)tc->n_keys + 1) * sizeof *k);
    if (k) {
        tc->keys = k;
        snprintf(k[tc->n_keys].key, sizeof k[tc->n_keys].key, "%s", key);
        k[tc->n_keys++].index = -1;
    }
    return -1;
}
}

/* ---- materials --------------------------------------------------------------------------- */

/* KHR_materials_emissive_strength, read from the glTF JSON because Assimp 5.2 ignores the
 * extension. Assimp's glTF loader is lazy (materials arrive in first-use order and unused ones
 * are dropped), so materials are matched by name + emissiveFactor, not by index. */
typedef struct {
    char name[256];
    float emissive[3];
    float strength;
} imp_gltf_strength;

static imp_gltf_strength *gltf_emissive_strengths(const char *path, int is_glb, uint32_t *n_out) {
    *n_out = 0;
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    char *json = NULL;
    size_t json_len = 0;
    imp_gltf_strength *out = NULL;
    cJSON *root = NULL;
    if (is_glb) {
        unsigned char hdr[20];
        if (fread(hdr, 1, sizeof hdr, f) != sizeof hdr) goto done;
        uint32_t magic = hdr[0] | hdr[1] << 8 | hdr[2] << 16 | (uint32_t)hdr[3] << 24;
        uint32_t clen = hdr[12] | hdr[13] << 8 | hdr[14] << 16 | (uint32_t)hdr[15] << 24;
        uint32_t ctype = hdr[16] | hdr[17] << 8 | hdr[18] << 16 | (uint32_t)hdr[19] << 24;
        if (magic != 0x46546C67u || ctype != 0x4E4F534Au || clen == 0 || clen > IMPORT_MAX_GLTF_JSON) goto done;
        json_len = clen;
    } else {
        if (fseek(f, 0, SEEK_END) != 0) goto done;
        long sz = ftell(f);
        if (sz <= 0 || (unsigned long)sz > IMPORT_MAX_GLTF_JSON || fseek(f, 0, SEEK_SET) != 0) goto done;
        json_len = (size_t)sz;
    }
    json = malloc(json_len);
    if (!json || fread(json, 1, json_len, f) != json_len) goto done;
    root = cJSON_ParseWithLength(json, json_len);
    const cJSON *mats = cJSON_GetObjectItemCaseSensitive(root, "materials");
    int n = cJSON_IsArray(mats) ? cJSON_GetArraySize(mats) : 0;
    if (n <= 0) goto done;
    out = calloc((size_t)n, sizeof *out);
    if (!out) goto done;
    uint32_t k = 0;
    const cJSON *m;
    cJSON_ArrayForEach(m, mats) {
        const cJSON *ext = cJSON_GetObjectItemCaseSensitive(m, "extensions");
        const cJSON *es = cJSON_GetObjectItemCaseSensitive(ext, "KHR_materials_emissive_strength");
        const cJSON *v = cJSON_GetObjectItemCaseSensitive(es, "emissiveStrength");
        if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble) || v->valuedouble < 0) continue;
        imp_gltf_strength *o = &out[k++];
        const cJSON *name = cJSON_GetObjectItemCaseSensitive(m, "name");
        copy_name(o->name, sizeof o->name, cJSON_IsString(name) ? name->valuestring : "");
        const cJSON *ef = cJSON_GetObjectItemCaseSensitive(m, "emissiveFactor");
        for (int c = 0; c < 3; c++) {
            const cJSON *x = cJSON_GetArrayItem(ef, c);
            o->emissive[c] = cJSON_IsNumber(x) ? (float)x->valuedouble : 0.0f;
        }
        o->strength = (float)v->valuedouble;
    }
    *n_out = k;
done:
    cJSON_Delete(root);
    free(json);
    fclose(f);
    return out;
}

static int strength_matches(const imp_gltf_strength *g, const char *name, const float e[3]) {
    if (strncmp(g->name, name, sizeof g->name - 1)) return 0;
    for (int c = 0; c < 3; c++)
        if (fabsf(g->emissive[c] - e[c]) > 1e-6f * fmaxf(1.0f, fabsf(e[c]))) return 0;
    return 1;
}

/* Strength for Assimp material ai_index: the k-th glTF material with its name and emissive
 * factor, where k counts earlier Assimp materials with the same signature. */
static float gltf_strength_for(const struct aiScene *ai, uint32_t ai_index, const imp_gltf_strength *gs,
                               uint32_t n_gs) {
    if (!gs || !n_gs) return 1.0f;
    struct aiString name;
    struct aiColor4D c;
    const struct aiMaterial *am = ai->mMaterials[ai_index];
    if (aiGetMaterialColor(am, AI_MATKEY_COLOR_EMISSIVE, &c) != AI_SUCCESS) return 1.0f;
    if (aiGetMaterialString(am, AI_MATKEY_NAME, &name) != AI_SUCCESS) name.data[0] = '\0';
    float e[3] = {c.r, c.g, c.b};
    uint32_t k = 0;
    for (uint32_t i = 0; i < ai_index; i++) {
        struct aiString n2;
        struct aiColor4D c2;
        if (!ai->mMaterials[i] || aiGetMaterialColor(ai->mMaterials[i], AI_MATKEY_COLOR_EMISSIVE, &c2) != AI_SUCCESS)
            continue;
        if (aiGetMaterialString(ai->mMaterials[i], AI_MATKEY_NAME, &n2) != AI_SUCCESS) n2.data[0] = '\0';
        float e2[3] = {c2.r, c2.g, c2.b};
        int same = !strcmp(n2.data, name.data);
        for (int ch = 0; ch < 3; ch++) same = same && e2[ch] == e[ch];
        k += same;
    }
    float first = 1.0f;
    uint32_t seen = 0;
    for (uint32_t j = 0; j < n_gs; j++) {
        if (!strength_matches(&gs[j], name.data, e)) continue;
        if (seen == 0) first = gs[j].strength;
        if (seen++ == k) return gs[j].strength;
    }
    return first;
}

static void convert_material(imp_tex_ctx *tc, const struct aiMaterial *am, uint32_t index, lc_material *m,
                             float gltf_strength) {
    struct aiString name;
    if (aiGetMaterialString(am, AI_MATKEY_NAME, &name) == AI_SUCCESS && name.length) /* unnamed keeps "material<i>" */
        copy_scene_name(m->name, sizeof m->name, name.data, tc->model, "material", index);
    struct aiColor4D c;
    m->base_color[0] = m->base_color[1] = m->base_color[2] = 0.8f;
    if (aiGetMaterialColor(am, AI_MATKEY_BASE_COLOR, &c) == AI_SUCCESS ||
        aiGetMaterialColor(am, AI_MATKEY_COLOR_DIFFUSE, &c) == AI_SUCCESS) {
        float v[3] = {c.r, c.g, c.b};
        for (int k = 0; k < 3; k++) m->base_color[k] = isfinite(v[k]) ? fmaxf(v[k], 0.0f) : 0.8f;
    }
    memset(m->emission, 0, sizeof m->emission);
    if (aiGetMaterialColor(am, AI_MATKEY_COLOR_EMISSIVE, &c) == AI_SUCCESS) {
        float strength = gltf_strength, fi = 0;
        unsigned int one = 1;
        if (aiGetMaterialFloatArray(am, AI_MATKEY_EMISSIVE_INTENSITY, &fi, &one) == AI_SUCCESS && isfinite(fi) &&
            fi >= 0)
            strength = fi; /* a newer Assimp reads the extension itself */
        float v[3] = {c.r, c.g, c.b};
        for (int k = 0; k < 3; k++) m->emission[k] = (isfinite(v[k]) && v[k] > 0) ? v[k] * strength : 0.0f;
    }
    m->base_texture = -1;
    /* BASE_COLOR first (glTF), DIFFUSE for OBJ map_Kd; never LIGHTMAP (glTF occlusion) */
    static const enum aiTextureType kinds[2] = {aiTextureType_BASE_COLOR, aiTextureType_DIFFUSE};
    for (int k = 0; k < 2 && m->base_texture < 0; k++) {
        struct aiString tp;
        if (aiGetMaterialTextureCount(am, kinds[k]) == 0) continue;
        if (aiGetMaterialTexture(am, kinds[k], 0, &tp, NULL, NULL, NULL, NULL, NULL, NULL) != AI_SUCCESS ||
            tp.length == 0)
            continue;
        m->base_texture = texture_for(tc, tp.data, m->name);
        break; /* the texture was named: a failure already warned, the factor stays */
    }
}

/* ---- lights ------------------------------------------------------------------------------ */

static const struct aiNode *find_node(const struct aiNode *node, const char *name, const imp_mat4 *parent, int depth,
                                      imp_mat4 *world_out) {
    if (!node || depth > IMPORT_MAX_DEPTH) return NULL;
    imp_mat4 local = mat_from_ai(&node->mTransformation);
    imp_mat4 world = mat_mul(parent, &local);
    if (!strcmp(node->mName.data, name)) {
        *world_out = world;
        return node;
    }
    for (uint32_t i = 0; i < node->mNumChildren; i++) {
        const struct aiNode *r =
            node->mChildren ? find_node(node->mChildren[i], name, &world, depth + 1, world_out) : NULL;
        if (r) return r;
    }
    return NULL;
}

static float node_light_range(const struct aiNode *node) {
    const struct aiMetadata *md = node ? node->mMetaData : NULL;
    if (!md || !md->mKeys || !md->mValues) return 0.0f;
    for (uint32_t i = 0; i < md->mNumProperties; i++) {
        if (strcmp(md->mKeys[i].data, "PBR_LightRange") || !md->mValues[i].mData) continue;
        double r = md->mValues[i].mType == AI_FLOAT ? *(const float *)md->mValues[i].mData
            : md->mValues[i].mType == AI_DOUBLE     ? *(const double *)md->mValues[i].mData
                                                    : 0.0;
        return (isfinite(r) && r > 0) ? (float)r : 0.0f;
    }
    return 0.0f;
}

static int convert_lights(const struct aiScene *ai, const char *path, double scale, lc_scene *s, char *err,
                          size_t errlen) {
    if (ai->mNumLights == 0 || !ai->mLights) return 0;
    s->lights = calloc(ai->mNumLights, sizeof *s->lights);
    if (!s->lights) {
        lc_set_err(err, errlen, "%s: out of memory for %u lights", path, ai->mNumLights);
        return -1;
    }
    for (uint32_t i = 0; i < ai->mNumLights; i++) {
        const struct aiLight *al = ai->mLights[i];
        if (!al) continue;
        lc_light *l = &s->lights[s->n_lights];
        memset(l, 0, sizeof *l);
        switch (al->mType) {
        case aiLightSource_POINT: l->type = LC_LIGHT_POINT; break;
        case aiLightSource_SPOT: l->type = LC_LIGHT_SPOT; break;
        case aiLightSource_DIRECTIONAL: l->type = LC_LIGHT_DIRECTIONAL; break;
        default:
            lc_warn("import", "%s: light '%s' has an unsupported type (%d); ignored", path, al->mName.data,
                    (int)al->mType);
            continue;
        }
        copy_scene_name(l->name, sizeof l->name, al->mName.data, path, "light", i);
        imp_mat4 id = mat_identity(), world = id;
        const struct aiNode *node = find_node(ai->mRootNode, al->mName.data, &id, 0, &world);
        if (!node)
            lc_warn("import", "%s: light '%s' has no node of that name; placed at the origin", path, al->mName.data);
        double p[3], d[3];
        mat_point(&world, al->mPosition.x, al->mPosition.y, al->mPosition.z, p);
        double lx = al->mDirection.x, ly = al->mDirection.y, lz = al->mDirection.z;
        if (!(lx * lx + ly * ly + lz * lz > 1e-20)) lx = 0, ly = 0, lz = -1; /* glTF: lights point down -Z */
        mat_dir(&world, lx, ly, lz, d);
        double dl = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        if (!(dl > 1e-20) || !isfinite(dl)) d[0] = 0, d[1] = 0, d[2] = -1, dl = 1;
        for (int c = 0; c < 3; c++) {
            l->position[c] = (float)(p[c] * scale);
            l->direction[c] = (float)(d[c] / dl);
        }
        /* Assimp's glTF2 importer stores colour x intensity; split it back (max component = 1) */
        float col[3] = {al->mColorDiffuse.r, al->mColorDiffuse.g, al->mColorDiffuse.b};
        if (!finite3f(col) || !finite3f(l->position)) {
            lc_warn("import", "%s: light '%s' has a non-finite colour or position; ignored", path, al->mName.data);
            continue;
        }
        float mx = fmaxf(col[0], fmaxf(col[1], col[2]));
        if (mx > 0) {
            for (int c = 0; c < 3; c++) l->color[c] = fmaxf(col[c], 0.0f) / mx;
            l->intensity = mx;
        } else {
            l->color[0] = l->color[1] = l->color[2] = 1.0f;
            l->intensity = 0.0f;
        }
        l->range = (float)(node_light_range(node) * scale);
        if (l->type == LC_LIGHT_SPOT) {
            /* glTF cone angles are half angles from the axis and Assimp passes them through as is */
            float outer = al->mAngleOuterCone, inner = al->mAngleInnerCone;
            if (!(outer > 0) || !(outer <= (float)M_PI_2)) outer = (float)M_PI_4;
            if (!(inner >= 0) || inner > outer) inner = 0;
            l->inner_cone = inner, l->outer_cone = outer;
        }
        s->n_lights++;
    }
    return 0;
}

/* ---- entry point ------------------------------------------------------------------------- */

/* What is checked before Assimp sees the file: a valid scale, a supported extension, a
 * non-empty regular file. Sets *is_gltf / *is_glb. -1 with err. */
static int imp_check_input(const char *path, double scale, int *is_gltf, int *is_glb, char *err, size_t errlen) {
    if (!isfinite(scale) || !(scale > 0)) {
        lc_set_err(err, errlen,
                   "%s: scale %g is invalid; give a finite scale > 0 (e.g. 0.003 for millimetre-ish units)", path,
                   scale);
        return -1;
    }
    const char *ext = path_ext(path);
    *is_gltf = !strcasecmp(ext, "gltf"), *is_glb = !strcasecmp(ext, "glb");
    if (!*is_gltf && !*is_glb && strcasecmp(ext, "obj") && strcasecmp(ext, "ply")) {
        lc_set_err(err, errlen, "%s: unsupported format '.%s'; convert it to glTF 2.0 (.gltf/.glb), OBJ or PLY", path,
                   ext);
        return -1;
    }
    struct stat st;
    if (stat(path, &st) != 0) {
        lc_set_err(err, errlen, "%s: cannot open: %s", path, strerror(errno));
        return -1;
    }
    if (!S_ISREG(st.st_mode)) {
        lc_set_err(err, errlen, "%s: not a regular file", path);
        return -1;
    }
    if (st.st_size == 0) {
        lc_set_err(err, errlen, "%s: the file is empty", path);
        return -1;
    }
    return 0;
}

/* Assimp's import of path: triangulated, identical vertices joined, normals generated where
 * the file has none. NULL with err. */
static const struct aiScene *imp_read(const char *path, char *err, size_t errlen) {
    /* Generated normals smooth only across edges flatter than 60 degrees: Assimp's default
     * (175) rounds the corners of boxes, tilting texel and surfel normals at hard edges. */
    struct aiPropertyStore *props = aiCreatePropertyStore();
    if (!props) {
        lc_set_err(err, errlen, "%s: out of memory", path);
        return NULL;
    }
    aiSetImportPropertyFloat(props, AI_CONFIG_PP_GSN_MAX_SMOOTHING_ANGLE, 60.0f);
    const struct aiScene *ai = aiImportFileExWithProperties(path,
                                                            aiProcess_Triangulate | aiProcess_GenSmoothNormals |
                                                                aiProcess_JoinIdenticalVertices |
                                                                aiProcess_SortByPType | aiProcess_ValidateDataStructure,
                                                            NULL, props);
    aiReleasePropertyStore(props);
    if (!ai) {
        lc_set_err(err, errlen, "%s: Assimp could not import it: %s", path, aiGetErrorString());
        return NULL;
    }
    if ((ai->mFlags & AI_SCENE_FLAGS_INCOMPLETE) || !ai->mRootNode) {
        lc_set_err(err, errlen, "%s: Assimp returned an incomplete scene (no geometry tree); check the file", path);
        aiReleaseImport(ai);
        return NULL;
    }
    return ai;
}

/* The scene's materials, first because triangles index them (at least one: a file without
 * any gets a default), their textures loaded through tc (relative to the model's
 * directory). -1 with err. */
static int imp_materials(const struct aiScene *ai, const char *path, int is_gltf, int is_glb, lc_scene *s,
                         imp_tex_ctx *tc, char *err, size_t errlen) {
    s->n_materials = ai->mNumMaterials ? ai->mNumMaterials : 1;
    s->materials = calloc(s->n_materials, sizeof *s->materials);
    if (!s->materials) {
        lc_set_err(err, errlen, "%s: out of memory for %u materials", path, s->n_materials);
        return -1;
    }
    tc->ai = ai, tc->model = path, tc->s = s;
    const char *slash = strrchr(path, '/');
    if (!slash) snprintf(tc->dir, sizeof tc->dir, ".");
    else if (slash == path) snprintf(tc->dir, sizeof tc->dir, "/");
    else if ((size_t)(slash - path) >= sizeof tc->dir) {
        lc_set_err(err, errlen, "%s: directory path longer than %d bytes", path, IMPORT_PATH_MAX - 1);
        return -1;
    } else snprintf(tc->dir, sizeof tc->dir, "%.*s", (int)(slash - path), path);
    uint32_t n_strengths = 0;
    imp_gltf_strength *strengths = is_gltf || is_glb ? gltf_emissive_strengths(path, is_glb, &n_strengths) : NULL;
    for (uint32_t i = 0; i < s->n_materials; i++) {
        lc_material *m = &s->materials[i];
        snprintf(m->name, sizeof m->name, "material%u", i);
        m->base_color[0] = m->base_color[1] = m->base_color[2] = 0.8f;
        m->base_texture = -1;
        if (i < ai->mNumMaterials && ai->mMaterials && ai->mMaterials[i])
            convert_material(tc, ai->mMaterials[i], i, m, gltf_strength_for(ai, i, strengths, n_strengths));
    }
    free(strengths);
    return 0;
}

/* The mesh: the node tree walked twice (count, allocate, fill), then degenerate and
 * non-finite triangles dropped, unused vertices compacted, broken normals fixed. The scene
 * takes the arrays. -1 with err. */
static int imp_geometry(const struct aiScene *ai, const char *path, double scale, int flip_winding, lc_scene *s,
                        char *err, size_t errlen) {
    imp_geo g;
    memset(&g, 0, sizeof g);
    g.ai = ai, g.path = path, g.scale = scale, g.flip_winding = flip_winding;
    g.n_materials = s->n_materials;
    imp_mat4 id = mat_identity();
    if (walk_nodes(&g, ai->mRootNode, &id, 0, err, errlen) < 0) goto err;
    if (g.count_t == 0) {
        lc_set_err(err, errlen, "%s: no triangles (the file has no surface geometry)", path);
        goto err;
    }
    g.want_uv1 = g.tri_meshes > 0 && g.tri_meshes_with_uv1 == g.tri_meshes;
    g.pos = malloc((size_t)g.count_v * 3 * sizeof(float));
    g.nrm = malloc((size_t)g.count_v * 3 * sizeof(float));
    g.uv0 = malloc((size_t)g.count_v * 2 * sizeof(float));
    g.uv1 = g.want_uv1 ? malloc((size_t)g.count_v * 2 * sizeof(float)) : NULL;
    g.idx = malloc((size_t)g.count_t * 3 * sizeof(uint32_t));
    g.mat = malloc((size_t)g.count_t * sizeof(uint32_t));
    if (!g.pos || !g.nrm || !g.uv0 || (g.want_uv1 && !g.uv1) || !g.idx || !g.mat) {
        lc_set_err(err, errlen, "%s: out of memory for %llu vertices / %llu triangles", path,
                   (unsigned long long)g.count_v, (unsigned long long)g.count_t);
        goto err;
    }
    if (walk_nodes(&g, ai->mRootNode, &id, 0, err, errlen) < 0) goto err;
    uint32_t dropped = 0;
    if (compact_mesh(&g, &dropped) == 0) {
        lc_set_err(
            err, errlen,
            "%s: no triangles left after dropping %u degenerate or non-finite ones; check the geometry and the scale",
            path, dropped);
        goto err;
    }
    if (dropped) lc_info("import", "%s: dropped %u degenerate or non-finite triangles", path, dropped);
    if (compact_vertices(&g) < 0 || fix_normals(&g) < 0) {
        lc_set_err(err, errlen, "%s: out of memory while cleaning the mesh", path);
        goto err;
    }
    s->mesh.n_vertices = g.nv, s->mesh.n_triangles = g.nt;
    s->mesh.position = g.pos, s->mesh.normal = g.nrm, s->mesh.uv0 = g.uv0, s->mesh.uv1 = g.uv1;
    s->mesh.index = g.idx, s->mesh.material = g.mat;
    s->has_lightmap_uv = s->mesh.uv1 != NULL;
    s->n_degenerate_dropped = dropped;
    return 0;
err:
    free(g.pos), free(g.nrm), free(g.uv0), free(g.uv1), free(g.idx), free(g.mat);
    return -1;
}

int lc_scene_import(const char *path, const lc_import_params *params, lc_scene *out, char *err, size_t errlen) {
    const struct aiScene *ai = NULL;
    imp_tex_ctx tc;
    lc_scene s;
    memset(&tc, 0, sizeof tc);
    memset(&s, 0, sizeof s);
    if (out) memset(out, 0, sizeof *out);
    if (!path || !*path || !out) {
        lc_set_err(err, errlen, "scene import: no input path or output given");
        return -1;
    }
    double scale = params ? params->scale : 1.0;
    int is_gltf = 0, is_glb = 0;
    if (imp_check_input(path, scale, &is_gltf, &is_glb, err, errlen) != 0) return -1;
    if (!(ai = imp_read(path, err, errlen))) goto err;
    if (imp_materials(ai, path, is_gltf, is_glb, &s, &tc, err, errlen) != 0) goto err;
    if (imp_geometry(ai, path, scale, params ? params->flip_winding != 0 : 0, &s, err, errlen) != 0) goto err;
    if (convert_lights(ai, path, scale, &s, err, errlen) < 0) goto err;
    lc_scene_update_bounds(&s);
    snprintf(s.source, sizeof s.source, "%s", path);
    free(tc.keys);
    aiReleaseImport(ai);
    *out = s;
    return 0;
err:
    free(tc.keys);
    lc_scene_release(&s);
    if (ai) aiReleaseImport(ai);
    return -1;
}
