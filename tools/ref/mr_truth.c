/* mr_truth: `lucent-ref mr-truth`, the irradiance from the real room at points near virtual
 * objects, full (the real scene) and visible (only the patches one captured frame saw), the
 * truths LightSkin's result is compared with (ref.h, "MR truths"). Two Embree scenes of its
 * own: the occluders alone (tested against the real scene's first hit) and the frame's mesh
 * with the occluders. */
#include <cjson/cJSON.h>
#include <embree3/rtcore.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine/embree_device.h"
#include "engine/scene_math.h"
#include "ref/ref.h"
#include "util/fsutil.h"
#include "util/log.h"
#include "util/parallel.h"
#include "util/progress.h"
#include "util/ray_offset.h"
#include "util/rng.h"

#define MR_GEOM_MESH 0u
#define MR_GEOM_OCCLUDERS 1u
#define MR_JSON_MAX (256u << 20)

/* --- POINTS.json --------------------------------------------------------------------------------- */

void lc_ref_mr_input_free(lc_ref_mr_input *in) {
    if (!in) return;
    free(in->points);
    free(in->occluders);
    memset(in, 0, sizeof *in);
}

/* An optional array of n finite numbers (absent: out untouched). */
static int mr_vec(const cJSON *obj, const char *name, int n, float *out) {
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(obj, name);
    if (!a) return 0;
    if (!cJSON_IsArray(a) || cJSON_GetArraySize(a) != n) return -1;
    for (int k = 0; k < n; k++) {
        const cJSON *e = cJSON_GetArrayItem(a, k);
        if (!cJSON_IsNumber(e) || !isfinite(e->valuedouble) || fabs(e->valuedouble) > 1e9) return -1;
        out[k] = (float)e->valuedouble;
    }
    return 0;
}

/* reserve: room for that many more points (an occluder's sparse points come after). */
static int mr_load_points(const char *path, const cJSON *root, uint32_t reserve, lc_ref_mr_input *out, char *err,
                          size_t errlen) {
    const cJSON *pts = cJSON_GetObjectItemCaseSensitive(root, "points");
    int n = cJSON_IsArray(pts) ? cJSON_GetArraySize(pts) : pts || !reserve ? -1 : 0;
    if (n < (reserve ? 0 : 1) || n > (int)LC_REF_MR_MAX_POINTS - (int)reserve) {
        lc_set_err(err, errlen,
                   "%s: /points: an array of 1 to %u {\"position\", \"normal\"} (required unless an occluder has "
                   "\"sparse_points\": true)",
                   path, LC_REF_MR_MAX_POINTS - reserve);
        return -1;
    }
    out->points = calloc((size_t)n + reserve + 1, sizeof *out->points);
    if (!out->points) {
        lc_set_err(err, errlen, "%s: out of memory for %d points", path, n);
        return -1;
    }
    for (int i = 0; i < n; i++) {
        const cJSON *p = cJSON_GetArrayItem(pts, i);
        lc_ref_mr_point *q = &out->points[i];
        q->normal[0] = NAN;
        q->position[0] = NAN;
        const char *bad = !cJSON_IsObject(p)                                      ? ""
            : mr_vec(p, "position", 3, q->position) != 0 || isnan(q->position[0]) ? "/position"
            : mr_vec(p, "normal", 3, q->normal) != 0 || isnan(q->normal[0])       ? "/normal"
                                                                                  : NULL;
        float len = bad ? 0 : lc_sm_len(q->normal);
        if (bad || !(len > 0)) {
            lc_set_err(err, errlen, "%s: /points/%d%s: %s", path, i, bad ? bad : "/normal",
                       bad ? "required, 3 finite numbers" : "zero vector");
            return -1;
        }
        for (int k = 0; k < 3; k++) q->normal[k] /= len;
    }
    out->n_points = (uint32_t)n;
    return 0;
}

/* One occluder object: the asset by name, the placement (defaults: identity). */
static int mr_load_object(const char *path, int i, const cJSON *o, const lc_lcb_view *v, lc_engine_object *dst,
                          char *err, size_t errlen) {
    memset(dst, 0, sizeof *dst);
    dst->rotation[3] = 1;
    dst->scale[0] = dst->scale[1] = dst->scale[2] = 1;
    dst->visible = 1;
    const cJSON *name = cJSON_IsObject(o) ? cJSON_GetObjectItemCaseSensitive(o, "asset") : NULL;
    if (!cJSON_IsString(name)) {
        lc_set_err(err, errlen, "%s: /occluders/objects/%d/asset: required, an asset name of the bake", path, i);
        return -1;
    }
    uint32_t a = 0;
    while (a < v->n_assets && strncmp(v->assets[a].name, name->valuestring, sizeof v->assets[a].name) != 0) a++;
    if (a == v->n_assets) {
        lc_set_err(err, errlen, "%s: /occluders/objects/%d/asset: the bake has no asset '%s' (%u assets%s%.64s)", path,
                   i, name->valuestring, v->n_assets, v->n_assets ? ", the first: " : "",
                   v->n_assets ? v->assets[0].name : "");
        return -1;
    }
    dst->asset = a;
    snprintf(dst->id, sizeof dst->id, "occluder%d", i);
    const cJSON *sc = cJSON_GetObjectItemCaseSensitive(o, "scale");
    if (cJSON_IsNumber(sc) && isfinite(sc->valuedouble) && sc->valuedouble != 0)
        dst->scale[0] = dst->scale[1] = dst->scale[2] = (float)sc->valuedouble;
    else if (sc && mr_vec(o, "scale", 3, dst->scale) != 0) {
        lc_set_err(err, errlen, "%s: /occluders/objects/%d/scale: a number or 3 finite numbers", path, i);
        return -1;
    }
    const char *bad = mr_vec(o, "translation", 3, dst->translation) != 0 ? "translation"
        : mr_vec(o, "rotation", 4, dst->rotation) != 0                   ? "rotation"
                                                                         : NULL;
    float qn = sqrtf(dst->rotation[0] * dst->rotation[0] + dst->rotation[1] * dst->rotation[1] +
                     dst->rotation[2] * dst->rotation[2] + dst->rotation[3] * dst->rotation[3]);
    if (bad || !(qn > 1e-6f)) {
        lc_set_err(err, errlen, "%s: /occluders/objects/%d/%s: %s", path, i, bad ? bad : "rotation",
                   bad ? "finite numbers (translation [3], rotation [x, y, z, w])" : "zero quaternion");
        return -1;
    }
    return 0;
}

/* The sparse points (lcb ASPT) of the occluders marked "sparse_points": true. */
static uint32_t mr_sparse_count(const cJSON *objs, const lc_lcb_view *v) {
    uint32_t total = 0;
    const cJSON *o;
    cJSON_ArrayForEach(o, objs) {
        const cJSON *name = cJSON_GetObjectItemCaseSensitive(o, "asset");
        if (!cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(o, "sparse_points")) || !cJSON_IsString(name)) continue;
        for (uint32_t a = 0; a < v->n_assets; a++) {
            uint32_t first, count = 0;
            if (!strncmp(v->assets[a].name, name->valuestring, sizeof v->assets[a].name))
                total += lc_lcb_asset_sparse(v, a, &first, &count);
        }
    }
    return total > LC_REF_MR_MAX_POINTS ? LC_REF_MR_MAX_POINTS : total;
}

/* Appends an object's sparse points placed in the world as lucentd places them for an MR
 * session (PROTOCOL §8.6): positions by the object's matrix, normals by its inverse transpose. */
static void mr_add_sparse_points(const lc_lcb_view *v, const lc_engine_object *o, lc_ref_mr_input *out) {
    uint32_t first, count = 0;
    lc_lcb_asset_sparse(v, o->asset, &first, &count);
    float mtx[12];
    lc_sm_object_matrix(o, mtx);
    for (uint32_t p = 0; p < count && out->n_points < LC_REF_MR_MAX_POINTS; p++) {
        const lc_lcb_sparse_point *sp = &v->sparse_points[first + p];
        lc_ref_mr_point *q = &out->points[out->n_points++];
        lc_sm_transform_point(mtx, sp->position, q->position);
        float nn[3] = {0, 0, 0};
        for (int col = 0; col < 3; col++)
            for (int d = 0; d < 3; d++) nn[d] += mtx[col * 3 + d] * sp->normal[col] / (o->scale[col] * o->scale[col]);
        float len = lc_sm_len(nn);
        for (int d = 0; d < 3; d++) q->normal[d] = len > 0 ? nn[d] / len : 0;
    }
}

int lc_ref_mr_points_load(const char *path, const lc_lcb_view *v, lc_ref_mr_input *out, char *err, size_t errlen) {
    memset(out, 0, sizeof *out);
    size_t len = 0;
    char *text = lc_fs_read(path, MR_JSON_MAX, &len, err, errlen);
    if (!text) return -1;
    cJSON *root = cJSON_ParseWithLength(text, len);
    free(text);
    if (!cJSON_IsObject(root)) {
        lc_set_err(err, errlen, "%s: not a JSON object", path);
        goto err;
    }
    const cJSON *occ = cJSON_GetObjectItemCaseSensitive(root, "occluders");
    const cJSON *objs = occ ? cJSON_GetObjectItemCaseSensitive(occ, "objects") : NULL;
    int n = cJSON_IsArray(objs) ? cJSON_GetArraySize(objs) : -1;
    if (occ && (n < 0 || n > (int)LC_REF_MR_MAX_OCCLUDERS)) {
        lc_set_err(err, errlen, "%s: /occluders/objects: an array of 0 to %u objects", path, LC_REF_MR_MAX_OCCLUDERS);
        goto err;
    }
    if (mr_load_points(path, root, mr_sparse_count(objs, v), out, err, errlen) != 0) goto err;
    if (n > 0) {
        out->occluders = calloc((size_t)n, sizeof *out->occluders);
        if (!out->occluders) {
            lc_set_err(err, errlen, "%s: out of memory", path);
            goto err;
        }
        for (int i = 0; i < n; i++)
            if (mr_load_object(path, i, cJSON_GetArrayItem(objs, i), v, &out->occluders[i], err, errlen) != 0) goto err;
        out->n_occluders = (uint32_t)n;
        for (int i = 0; i < n; i++)
            if (cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(cJSON_GetArrayItem(objs, i), "sparse_points")))
                mr_add_sparse_points(v, &out->occluders[i], out);
    }
    cJSON_Delete(root);
    return 0;
err:
    cJSON_Delete(root);
    lc_ref_mr_input_free(out);
    return -1;
}

/* --- geometry ----------------------------------------------------------------------------------- */

typedef struct {
    float *pos; /* 4 floats per vertex (Embree reads 16 bytes) */
    uint32_t *idx;
    uint32_t n_vertices, n_tris;
    float *normal;   /* mesh: per triangle, unit, facing the camera */
    float *radiance; /* mesh: per triangle RGB */
    double *cdf;     /* mesh: n_tris + 1, by power (radiance summed over RGB x area) */
    float *area_pdf; /* mesh: per triangle, the light sample's density on it per m^2 */
} mr_mesh;

static void mr_mesh_free(mr_mesh *m) {
    free(m->pos);
    free(m->idx);
    free(m->normal);
    free(m->radiance);
    free(m->cdf);
    free(m->area_pdf);
    memset(m, 0, sizeof *m);
}

/* The occluders' triangles in world space (as lc_ref places state objects). */
static int mr_build_occluders(const lc_lcb_view *v, const lc_ref_mr_input *in, mr_mesh *m) {
    uint64_t nv = 0, nt = 0;
    for (uint32_t i = 0; i < in->n_occluders; i++) {
        nv += v->assets[in->occluders[i].asset].vertex_count;
        nt += v->assets[in->occluders[i].asset].triangle_count;
    }
    if (nt == 0) return 0;
    if (nv > UINT32_MAX / 4 || nt > UINT32_MAX / 3) return -1;
    m->pos = malloc((size_t)(nv + 1) * 4 * sizeof(float));
    m->idx = malloc((size_t)nt * 3 * sizeof(uint32_t));
    if (!m->pos || !m->idx) return -1;
    for (uint32_t i = 0; i < in->n_occluders; i++) {
        const lc_lcb_asset *a = &v->assets[in->occluders[i].asset];
        float mat[12];
        lc_sm_object_matrix(&in->occluders[i], mat);
        for (uint32_t k = 0; k < a->vertex_count; k++) {
            float *p = m->pos + 4 * (size_t)(m->n_vertices + k);
            lc_sm_transform_point(mat, v->asset_vertices[a->first_vertex + k].position, p);
            p[3] = 0;
        }
        for (uint32_t k = 0; k < 3 * a->triangle_count; k++)
            m->idx[3 * (size_t)m->n_tris + k] = m->n_vertices + v->asset_indices[3 * (size_t)a->first_triangle + k];
        m->n_vertices += a->vertex_count;
        m->n_tris += a->triangle_count;
    }
    return 0;
}

/* One triangle of the frame's mesh (pixel indices a, b, c) unless its depths differ by more than
 * 5% of the nearest; wound so its normal faces the camera, radiance the mean of its pixels. */
static void mr_mesh_tri(const lc_ref_capture_frame *f, const uint32_t *vid, size_t a, size_t b, size_t c, mr_mesh *m) {
    const uint16_t *d = f->depth_mm;
    uint16_t lo = d[a] < d[b] ? d[a] : d[b], hi = d[a] > d[b] ? d[a] : d[b];
    lo = d[c] < lo ? d[c] : lo;
    hi = d[c] > hi ? d[c] : hi;
    if ((double)(hi - lo) > 0.05 * lo) return;
    uint32_t t = m->n_tris, ia = vid[a], ib = vid[b], ic = vid[c];
    const float *pa = m->pos + 4 * (size_t)ia, *pb = m->pos + 4 * (size_t)ib, *pc = m->pos + 4 * (size_t)ic;
    float e1[3], e2[3], n[3], to_cam[3];
    for (int k = 0; k < 3; k++) {
        e1[k] = pb[k] - pa[k], e2[k] = pc[k] - pa[k];
        to_cam[k] = (float)f->view.translation[k] - (pa[k] + pb[k] + pc[k]) / 3.0f;
    }
    lc_sm_cross(e1, e2, n);
    float len = lc_sm_len(n);
    if (!(len > 0)) return;
    float sign = lc_sm_dot(n, to_cam) < 0 ? -1.0f : 1.0f;
    for (int k = 0; k < 3; k++) m->normal[3 * (size_t)t + k] = sign * n[k] / len;
    m->idx[3 * (size_t)t] = ia, m->idx[3 * (size_t)t + 1] = ib, m->idx[3 * (size_t)t + 2] = ic;
    for (int k = 0; k < 3; k++)
        m->radiance[3 * (size_t)t + k] = (f->rgb[3 * a + k] + f->rgb[3 * b + k] + f->rgb[3 * c + k]) / 3.0f;
    m->n_tris++;
}

/* The mesh's power CDF and per-triangle area densities (light sampling). */
static int mr_mesh_lights(mr_mesh *m) {
    m->cdf = malloc(((size_t)m->n_tris + 1) * sizeof *m->cdf);
    m->area_pdf = malloc(((size_t)m->n_tris + 1) * sizeof *m->area_pdf);
    if (!m->cdf || !m->area_pdf) return -1;
    m->cdf[0] = 0;
    for (uint32_t t = 0; t < m->n_tris; t++) {
        const float *a = m->pos + 4 * (size_t)m->idx[3 * t], *b = m->pos + 4 * (size_t)m->idx[3 * t + 1];
        const float *c = m->pos + 4 * (size_t)m->idx[3 * t + 2];
        float e1[3], e2[3], n[3];
        for (int k = 0; k < 3; k++) e1[k] = b[k] - a[k], e2[k] = c[k] - a[k];
        lc_sm_cross(e1, e2, n);
        double area = 0.5 * lc_sm_len(n), L = 0;
        for (int k = 0; k < 3; k++) L += fmax(m->radiance[3 * (size_t)t + k], 0.0f);
        m->cdf[t + 1] = m->cdf[t] + L * area;
        m->area_pdf[t] = (float)(L * area > 0 ? L : 0); /* x 1 / total below */
    }
    double total = m->cdf[m->n_tris];
    for (uint32_t t = 0; t < m->n_tris; t++) m->area_pdf[t] = total > 0 ? (float)(m->area_pdf[t] / total) : 0.0f;
    return 0;
}

/* The frame's depth map as triangles: a vertex per valid pixel at its centre, unprojected. */
static int mr_build_mesh(const lc_ref_capture_frame *f, mr_mesh *m) {
    uint32_t w = f->view.width, h = f->view.height;
    size_t n = (size_t)w * h, max_tris = 2 * (size_t)(w ? w - 1 : 0) * (h ? h - 1 : 0) + 1;
    uint32_t *vid = malloc(n * sizeof *vid);
    m->pos = malloc((n + 1) * 4 * sizeof(float));
    m->idx = malloc(max_tris * 3 * sizeof(uint32_t));
    m->normal = malloc(max_tris * 3 * sizeof(float));
    m->radiance = malloc(max_tris * 3 * sizeof(float));
    if (!vid || !m->pos || !m->idx || !m->normal || !m->radiance) {
        free(vid);
        return -1;
    }
    for (uint32_t y = 0; y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            size_t i = (size_t)y * w + x;
            vid[i] = UINT32_MAX;
            if (!f->depth_mm[i]) continue;
            double p[3];
            lc_ref_rgbd_unproject(&f->view, x + 0.5, y + 0.5, f->depth_mm[i] / 1000.0, p);
            float *dst = m->pos + 4 * (size_t)m->n_vertices;
            dst[0] = (float)p[0], dst[1] = (float)p[1], dst[2] = (float)p[2], dst[3] = 0;
            vid[i] = m->n_vertices++;
        }
    for (uint32_t y = 0; y + 1 < h; y++)
        for (uint32_t x = 0; x + 1 < w; x++) {
            size_t a = (size_t)y * w + x, b = a + 1, c = a + w, d = c + 1;
            if (vid[a] == UINT32_MAX || vid[b] == UINT32_MAX || vid[c] == UINT32_MAX || vid[d] == UINT32_MAX) continue;
            mr_mesh_tri(f, vid, a, c, b, m);
            mr_mesh_tri(f, vid, b, c, d, m);
        }
    free(vid);
    return mr_mesh_lights(m);
}

static void mr_attach(RTCDevice dev, RTCScene sc, const mr_mesh *m, uint32_t id) {
    if (!m->n_tris) return;
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m->pos, 0, 4 * sizeof(float),
                               m->n_vertices);
    rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, m->idx, 0, 3 * sizeof(uint32_t),
                               m->n_tris);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(sc, g, id);
    rtcReleaseGeometry(g);
}

/* First hit in sc: 1 with t, geometry and primitive. */
static int mr_intersect(RTCScene sc, const float org[3], const float dir[3], float *t, uint32_t *geom, uint32_t *prim) {
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    struct RTCRayHit rh;
    rh.ray.org_x = org[0], rh.ray.org_y = org[1], rh.ray.org_z = org[2];
    rh.ray.dir_x = dir[0], rh.ray.dir_y = dir[1], rh.ray.dir_z = dir[2];
    rh.ray.tnear = 0, rh.ray.tfar = INFINITY, rh.ray.time = 0, rh.ray.mask = ~0u, rh.ray.id = 0, rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(sc, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return 0;
    *t = rh.ray.tfar, *geom = rh.hit.geomID, *prim = rh.hit.primID;
    return 1;
}

/* --- the integrals --------------------------------------------------------------------------------- */

typedef struct {
    lc_ref *r;
    const lc_ref_mr_input *in;
    const lc_ref_mr_settings *s;
    RTCScene occ, vis; /* occ NULL: no occluders; vis NULL: no frame */
    const mr_mesh *mesh;
    lc_ref_mr_value *out;
    lc_progress *progress;
} mr_ctx;

/* A cosine-distributed unit direction about unit n; *cos_out its cosine. */
static void mr_cosine_dir(const float n[3], lc_rng *rng, float d[3], float *cos_out) {
    float u = lc_rng_float(rng), w = lc_rng_float(rng);
    float r = sqrtf(u), phi = 2.0f * (float)M_PI * w, z = sqrtf(fmaxf(0.0f, 1.0f - u));
    float s = copysignf(1.0f, n[2]), a = -1.0f / (s + n[2]), c = n[0] * n[1] * a;
    float t[3] = {1.0f + s * n[0] * n[0] * a, s * c, -s * n[0]}, b[3] = {c, s + n[1] * n[1] * a, -n[1]};
    float x = r * cosf(phi), y = r * sinf(phi);
    for (int k = 0; k < 3; k++) d[k] = x * t[k] + y * b[k] + z * n[k];
    float len = lc_sm_len(d);
    for (int k = 0; k < 3; k++) d[k] /= len;
    *cos_out = lc_sm_dot(d, n);
}

/* The occluders block the segment (full's blocker). */
static int mr_block(void *ctx, const float org[3], const float dir[3], float tfar) {
    return lc_embree_occluded((RTCScene)ctx, org, dir, tfar);
}

/* One light sample of the frame's mesh from org (unit normal n): a triangle by power, a uniform
 * point on it; its radiance x cos / (pdf_light + pdf_cosine) when its front is unblocked. */
static void mr_vis_light(const mr_ctx *c, const float org[3], const float n[3], float eps, lc_rng *rng, double E[3],
                         uint64_t *rays) {
    const mr_mesh *m = c->mesh;
    double total = m->n_tris ? m->cdf[m->n_tris] : 0, u = lc_rng_float(rng) * total;
    if (!(total > 0)) return;
    uint32_t lo = 0, hi = m->n_tris - 1;
    while (lo < hi) { /* first t with cdf[t + 1] > u */
        uint32_t mid = (lo + hi) / 2;
        if (m->cdf[mid + 1] > u) hi = mid;
        else lo = mid + 1;
    }
    const float *a = m->pos + 4 * (size_t)m->idx[3 * lo], *b = m->pos + 4 * (size_t)m->idx[3 * lo + 1];
    const float *cc = m->pos + 4 * (size_t)m->idx[3 * lo + 2], *ln = m->normal + 3 * (size_t)lo;
    float su = sqrtf(lc_rng_float(rng)), w = lc_rng_float(rng), d[3];
    float b1 = su * (1.0f - w), b2 = su * w, b0 = 1.0f - b1 - b2;
    for (int k = 0; k < 3; k++) d[k] = b0 * a[k] + b1 * b[k] + b2 * cc[k] - org[k];
    float d2 = lc_sm_dot(d, d), dist = sqrtf(d2);
    if (!(d2 > 1e-12f)) return;
    for (int k = 0; k < 3; k++) d[k] /= dist;
    float cos_l = -lc_sm_dot(ln, d), cos_x = lc_sm_dot(n, d);
    if (cos_l <= 1e-6f || cos_x <= 0) return;
    (*rays)++;
    if (lc_embree_occluded(c->vis, org, d, lc_ray_shadow_tfar(dist, eps))) return;
    double pl = m->area_pdf[lo] * (double)d2 / cos_l, g = cos_x / (pl + cos_x / M_PI);
    for (int k = 0; k < 3; k++) E[k] += m->radiance[3 * (size_t)lo + k] * g;
}

/* One sample of visible: the light sample and a cosine ray, combined by MIS (balance). */
static void mr_vis_sample(const mr_ctx *c, const float org[3], const float n[3], float eps, lc_rng *rng, double E[3],
                          uint64_t *rays) {
    E[0] = E[1] = E[2] = 0;
    mr_vis_light(c, org, n, eps, rng, E, rays);
    float d[3], cs, t;
    uint32_t geom, prim;
    mr_cosine_dir(n, rng, d, &cs);
    (*rays)++;
    if (!(cs > 0) || !mr_intersect(c->vis, org, d, &t, &geom, &prim) || geom != MR_GEOM_MESH) return;
    float cos_l = -lc_sm_dot(d, c->mesh->normal + 3 * (size_t)prim);
    if (cos_l <= 0) return; /* one-sided: the back of the captured surface is black */
    double pb = cs / M_PI, pl = cos_l > 1e-6f ? c->mesh->area_pdf[prim] * (double)t * t / cos_l : INFINITY;
    double g = cs / (pb + pl);
    for (int k = 0; k < 3; k++) E[k] += c->mesh->radiance[3 * (size_t)prim + k] * g;
}

/* Mean and standard error of n samples from their sums. */
static void mr_moments(const double s[3], const double q[3], double n, double mean[3], double se[3]) {
    for (int k = 0; k < 3; k++) {
        mean[k] = s[k] / n;
        double var = n > 1 ? (q[k] - n * mean[k] * mean[k]) / (n - 1) : 0;
        se[k] = sqrt(fmax(var, 0) / n);
    }
}

static void mr_points(void *vctx, size_t begin, size_t end, int thread) {
    (void)thread;
    mr_ctx *c = vctx;
    float eps = lc_ref_eps(c->r);
    for (size_t i = begin; i < end; i++) {
        const lc_ref_mr_point *p = &c->in->points[i];
        lc_rng rf = lc_rng_seed(c->s->seed, 0x3D77000000000000ull ^ (uint64_t)i);
        lc_rng rv = lc_rng_seed(c->s->seed, 0x3D78000000000000ull ^ (uint64_t)i);
        float org[3];
        for (int k = 0; k < 3; k++) org[k] = p->position[k] + p->normal[k] * eps;
        double sf[3] = {0}, qf[3] = {0}, sv[3] = {0}, qv[3] = {0};
        uint64_t rays = 0;
        for (uint32_t j = 0; j < c->s->spp; j++) {
            float ef[3];
            double ev[3] = {0, 0, 0};
            lc_ref_irradiance_sample(c->r, org, p->normal, c->s->max_depth, c->s->rr_depth, c->occ ? mr_block : NULL,
                                     c->occ, &rf, ef, &rays);
            if (c->vis) mr_vis_sample(c, org, p->normal, eps, &rv, ev, &rays);
            for (int k = 0; k < 3; k++) {
                sf[k] += ef[k], qf[k] += (double)ef[k] * ef[k];
                sv[k] += ev[k], qv[k] += ev[k] * ev[k];
            }
        }
        lc_ref_mr_value *o = &c->out[i];
        mr_moments(sf, qf, c->s->spp, o->full, o->full_stderr);
        mr_moments(sv, qv, c->s->spp, o->visible, o->visible_stderr);
        lc_progress_add(c->progress, 1);
    }
}

int lc_ref_mr_truth(lc_ref *r, const lc_lcb_view *v, const lc_ref_capture_frame *frame, const lc_ref_mr_input *in,
                    const lc_ref_mr_settings *s, lc_ref_mr_value *out, uint32_t *visible_triangles, char *err,
                    size_t errlen) {
    mr_mesh occ = {0}, mesh = {0};
    RTCDevice dev = NULL;
    RTCScene sc_occ = NULL, sc_vis = NULL;
    if (s->spp < 1) {
        lc_set_err(err, errlen, "--spp: must be >= 1");
        return -1;
    }
    for (uint32_t i = 0; i < in->n_occluders; i++)
        if (in->occluders[i].asset >= v->n_assets) {
            lc_set_err(err, errlen, "/occluders/objects/%u/asset: index %u, the bake has %u assets", i,
                       in->occluders[i].asset, v->n_assets);
            return -1;
        }
    if (mr_build_occluders(v, in, &occ) != 0 || (frame && mr_build_mesh(frame, &mesh) != 0)) {
        lc_set_err(err, errlen, "out of memory building the occluders and the frame's mesh");
        goto err;
    }
    if (!(dev = lc_embree_device_new(lc_ref_threads(r), "ref-mr", err, errlen))) goto err;
    if (occ.n_tris) {
        sc_occ = rtcNewScene(dev);
        rtcSetSceneFlags(sc_occ, RTC_SCENE_FLAG_ROBUST);
        mr_attach(dev, sc_occ, &occ, MR_GEOM_OCCLUDERS);
        rtcCommitScene(sc_occ);
    }
    if (frame) {
        sc_vis = rtcNewScene(dev);
        rtcSetSceneFlags(sc_vis, RTC_SCENE_FLAG_ROBUST);
        mr_attach(dev, sc_vis, &mesh, MR_GEOM_MESH);
        mr_attach(dev, sc_vis, &occ, MR_GEOM_OCCLUDERS);
        rtcCommitScene(sc_vis);
    }
    if (rtcGetDeviceError(dev) != RTC_ERROR_NONE) {
        lc_set_err(err, errlen, "embree: building the occluder / capture scenes failed");
        goto err;
    }
    if (visible_triangles) *visible_triangles = mesh.n_tris;
    mr_ctx ctx = {r, in, s, sc_occ, sc_vis, &mesh, out, NULL};
    if (!s->quiet) ctx.progress = lc_progress_begin("mr-truth points", in->n_points);
    lc_parallel_for(lc_ref_threads(r), in->n_points, 1, mr_points, &ctx);
    lc_progress_end(ctx.progress);
    if (sc_vis) rtcReleaseScene(sc_vis);
    if (sc_occ) rtcReleaseScene(sc_occ);
    rtcReleaseDevice(dev);
    mr_mesh_free(&occ);
    mr_mesh_free(&mesh);
    return 0;
err:
    if (sc_vis) rtcReleaseScene(sc_vis);
    if (sc_occ) rtcReleaseScene(sc_occ);
    if (dev) rtcReleaseDevice(dev);
    mr_mesh_free(&occ);
    mr_mesh_free(&mesh);
    return -1;
}

static cJSON *mr_rgb(const double v[3]) {
    cJSON *a = cJSON_CreateArray();
    for (int k = 0; k < 3; k++) cJSON_AddItemToArray(a, cJSON_CreateNumber(v[k]));
    return a;
}

char *lc_ref_mr_json(const lc_ref_mr_point *points, const lc_ref_mr_value *values, uint32_t n, uint32_t spp) {
    cJSON *root = cJSON_CreateObject(), *pts = cJSON_CreateArray();
    for (uint32_t i = 0; i < n; i++) {
        cJSON *p = cJSON_CreateObject();
        double pos[3], nrm[3];
        for (int k = 0; k < 3; k++) pos[k] = points[i].position[k], nrm[k] = points[i].normal[k];
        cJSON_AddItemToObject(p, "position", mr_rgb(pos));
        cJSON_AddItemToObject(p, "normal", mr_rgb(nrm));
        cJSON_AddItemToObject(p, "full", mr_rgb(values[i].full));
        cJSON_AddItemToObject(p, "full_stderr", mr_rgb(values[i].full_stderr));
        cJSON_AddItemToObject(p, "visible", mr_rgb(values[i].visible));
        cJSON_AddItemToObject(p, "visible_stderr", mr_rgb(values[i].visible_stderr));
        cJSON_AddItemToArray(pts, p);
    }
    cJSON_AddItemToObject(root, "points", pts);
    cJSON_AddNumberToObject(root, "spp", spp);
    char *text = cJSON_Print(root);
    cJSON_Delete(root);
    return text;
}
