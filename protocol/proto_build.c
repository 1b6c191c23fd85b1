/* proto_build: server messages (PROTOCOL.md §3.4, §5) and journal ops as JSON text.
 * Numbers are written as raw text: floats in the shortest form that reads back to the same
 * float, 64-bit integers exactly (cJSON would go through double). Non-finite values cannot
 * be JSON and are written as 0. Strings are written as valid UTF-8 whatever they hold (cJSON
 * copies bytes as they are; a WebSocket peer closes on a text frame that is not UTF-8). */
#include <cjson/cJSON.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lucent_proto.h"

static const char *const proto_light_types[] = {"point", "spot", "directional", "area"};
static const char *const proto_env_kinds[] = {"none", "constant", "sh"};

/* Builder: every add goes through these so one flag catches any allocation failure. */
typedef struct {
    int oom;
} proto_b;

static cJSON *proto_chk(proto_b *b, cJSON *it) {
    if (!it) b->oom = 1;
    return it;
}

static void proto_fmt_float(char *buf, size_t cap, float f) {
    if (!isfinite(f)) f = 0;
    for (int prec = 1; prec <= 9; prec++) {
        if (snprintf(buf, cap, "%.*g", prec, (double)f) < 0) break;
        if (strtof(buf, NULL) == f) return;
    }
}

static void proto_fmt_double(char *buf, size_t cap, double d) {
    if (!isfinite(d)) d = 0;
    for (int prec = 1; prec <= 17; prec++) {
        if (snprintf(buf, cap, "%.*g", prec, d) < 0) break;
        if (strtod(buf, NULL) == d) return;
    }
}

static cJSON *proto_float(proto_b *b, float f) {
    char buf[40];
    proto_fmt_float(buf, sizeof buf, f);
    return proto_chk(b, cJSON_CreateRaw(buf));
}

static void proto_add(proto_b *b, cJSON *obj, const char *key, cJSON *it) {
    if (!it || !obj) {
        b->oom = 1;
        cJSON_Delete(it);
        return;
    }
    cJSON_AddItemToObject(obj, key, it);
}

static void proto_add_float(proto_b *b, cJSON *obj, const char *key, float f) {
    proto_add(b, obj, key, proto_float(b, f));
}

static void proto_add_double(proto_b *b, cJSON *obj, const char *key, double d) {
    char buf[40];
    proto_fmt_double(buf, sizeof buf, d);
    proto_add(b, obj, key, cJSON_CreateRaw(buf));
}

static void proto_add_u64(proto_b *b, cJSON *obj, const char *key, uint64_t v) {
    char buf[32];
    snprintf(buf, sizeof buf, "%" PRIu64, v);
    proto_add(b, obj, key, cJSON_CreateRaw(buf));
}

/* A JSON string of s with each ill-formed UTF-8 subsequence replaced by U+FFFD. */
static cJSON *proto_string(const char *s) {
    if (!s) s = "";
    size_t n = strlen(s);
    if (lc_proto_utf8_valid(s, n)) return cJSON_CreateString(s);
    if (n > (SIZE_MAX - 1) / 3) return NULL;
    char *buf = malloc(3 * n + 1); /* a replaced subsequence is >= 1 byte in, 3 out */
    if (!buf) return NULL;
    lc_proto_utf8_sanitize(buf, 3 * n + 1, s, n, 0);
    cJSON *it = cJSON_CreateString(buf);
    free(buf);
    return it;
}

static void proto_add_str(proto_b *b, cJSON *obj, const char *key, const char *s) {
    proto_add(b, obj, key, proto_string(s));
}

static void proto_add_bool(proto_b *b, cJSON *obj, const char *key, int v) {
    proto_add(b, obj, key, cJSON_CreateBool(v != 0));
}

static void proto_add_floats(proto_b *b, cJSON *obj, const char *key, const float *v, int n) {
    cJSON *arr = proto_chk(b, cJSON_CreateArray());
    for (int i = 0; arr && i < n; i++) {
        cJSON *it = proto_float(b, v[i]);
        if (it) cJSON_AddItemToArray(arr, it);
    }
    proto_add(b, obj, key, arr);
}

static void proto_add_u32s(proto_b *b, cJSON *obj, const char *key, const uint32_t *v, int n) {
    cJSON *arr = proto_chk(b, cJSON_CreateArray());
    for (int i = 0; arr && i < n; i++) {
        char buf[16];
        snprintf(buf, sizeof buf, "%" PRIu32, v[i]);
        cJSON *it = proto_chk(b, cJSON_CreateRaw(buf));
        if (it) cJSON_AddItemToArray(arr, it);
    }
    proto_add(b, obj, key, arr);
}

static void proto_add_strs(proto_b *b, cJSON *obj, const char *key, const char *const *v, uint32_t n) {
    cJSON *arr = proto_chk(b, cJSON_CreateArray());
    for (uint32_t i = 0; arr && i < n; i++) {
        cJSON *it = proto_chk(b, proto_string(v ? v[i] : NULL));
        if (it) cJSON_AddItemToArray(arr, it);
    }
    proto_add(b, obj, key, arr);
}

/* {"type": t[, "id": …]} */
static cJSON *proto_msg(proto_b *b, const char *type, const lc_proto_id *id) {
    cJSON *m = proto_chk(b, cJSON_CreateObject());
    proto_add_str(b, m, "type", type);
    if (id && id->kind == 1) {
        char s[LC_PROTO_ID_MAX + 1];
        size_t n = strnlen(id->str, LC_PROTO_ID_MAX);
        memcpy(s, id->str, n);
        s[n] = 0;
        proto_add_str(b, m, "id", s);
    } else if (id && id->kind == 2) {
        proto_add_u64(b, m, "id", id->num > 0 ? (uint64_t)id->num : 0);
    }
    return m;
}

/* Text of m (consumed); NULL on any failure. */
static char *proto_finish(proto_b *b, cJSON *m) {
    char *s = NULL;
    if (m && !b->oom) s = cJSON_PrintUnformatted(m);
    cJSON_Delete(m);
    return s;
}

static int proto_nonzero(const float *v, int n) {
    for (int i = 0; i < n; i++)
        if (v[i] != 0) return 1;
    return 0;
}

/* Light in its §4.3 form: the fields that matter for its type (and any other non-default
 * position/direction), so the parser's defaults give the same struct back. */
static cJSON *proto_light_json(proto_b *b, const lc_proto_light *L) {
    cJSON *o = proto_chk(b, cJSON_CreateObject());
    unsigned t = (unsigned)L->type < 4 ? (unsigned)L->type : 0;
    proto_add_str(b, o, "id", L->id);
    proto_add_str(b, o, "type", proto_light_types[t]);
    proto_add_floats(b, o, "color", L->color, 3);
    proto_add_float(b, o, "intensity", L->intensity);
    proto_add_float(b, o, "range", L->range);
    if (t != LC_PLIGHT_DIRECTIONAL || proto_nonzero(L->position, 3)) proto_add_floats(b, o, "position", L->position, 3);
    if (t != LC_PLIGHT_POINT || proto_nonzero(L->direction, 3)) proto_add_floats(b, o, "direction", L->direction, 3);
    if (t == LC_PLIGHT_SPOT) {
        proto_add_float(b, o, "innerConeAngle", L->inner_cone);
        proto_add_float(b, o, "outerConeAngle", L->outer_cone);
    }
    if (t == LC_PLIGHT_AREA) {
        proto_add_str(b, o, "shape", L->shape == 1 ? "disc" : "quad");
        proto_add_floats(b, o, "size", L->size, L->shape == 1 ? 1 : 2);
    }
    if (proto_nonzero(L->tangent, 3)) proto_add_floats(b, o, "tangent", L->tangent, 3);
    return o;
}

static cJSON *proto_object_json(proto_b *b, const lc_proto_object *O) {
    cJSON *o = proto_chk(b, cJSON_CreateObject());
    proto_add_str(b, o, "id", O->id);
    proto_add_str(b, o, "asset", O->asset);
    proto_add_floats(b, o, "translation", O->translation, 3);
    proto_add_floats(b, o, "rotation", O->rotation, 4);
    proto_add_floats(b, o, "scale", O->scale, 3);
    proto_add_bool(b, o, "visible", O->visible);
    proto_add_bool(b, o, "dnrt", O->dnrt);
    static const char *const modes[] = {"dynamic", "clutter", "auto"};
    proto_add_str(b, o, "mode", modes[O->mode >= 0 && O->mode <= 2 ? O->mode : 0]);
    if (O->transport)
        proto_add_str(b, o, "transport", O->transport == LC_OBJECT_TRANSPORT_CLUTTER + 1 ? "clutter" : "dynamic");
    return o;
}

static cJSON *proto_env_json(proto_b *b, const lc_proto_environment *E) {
    cJSON *o = proto_chk(b, cJSON_CreateObject());
    int k = E->kind >= 0 && E->kind <= 2 ? E->kind : 0;
    proto_add_str(b, o, "type", proto_env_kinds[k]);
    proto_add_floats(b, o, "color", E->color, 3);
    if (k == 2) proto_add_floats(b, o, "sh", E->sh, 27);
    proto_add_float(b, o, "intensity", E->intensity);
    return o;
}

static cJSON *proto_settings_json(proto_b *b, const lc_proto_settings *S) {
    cJSON *o = proto_chk(b, cJSON_CreateObject());
    if (S->present & (1u << LC_SET_BOUNCES)) proto_add_u64(b, o, "bounces", S->bounces);
    if (S->present & (1u << LC_SET_BANDS)) proto_add_u64(b, o, "bands", S->bands);
    if (S->present & (1u << LC_SET_PROGRESSIVE)) proto_add_bool(b, o, "progressive", S->progressive);
    if (S->present & (1u << LC_SET_CHROMA)) proto_add_bool(b, o, "chroma_compression", S->chroma_compression);
    if (S->present & (1u << LC_SET_CHROMA_BANDS)) proto_add_u64(b, o, "chroma_bands", S->chroma_bands);
    if (S->present & (1u << LC_SET_DNRT)) proto_add_bool(b, o, "dnrt", S->dnrt);
    if (S->present & (1u << LC_SET_DNRT_BLOCKERS)) proto_add_bool(b, o, "dnrt_blockers", S->dnrt_blockers);
    const char *solver = lc_proto_solver_name(S->solver);
    if ((S->present & (1u << LC_SET_SOLVER)) && solver) proto_add_str(b, o, "solver", solver);
    return o;
}

/* The key an op changes, for `changed.ids`. */
static const char *proto_op_key(const lc_proto_op *op) {
    switch (op->type) {
    case LC_REQ_LIGHT_SET: return op->light.id;
    case LC_REQ_OBJECT_SET: return op->object.id;
    case LC_REQ_ENVIRONMENT_SET: return "environment";
    case LC_REQ_SETTINGS_SET: return "settings";
    default: return op->target;
    }
}

/* Copy of a possibly unterminated fixed-size id. */
static void proto_idcpy(char dst[LC_PROTO_ID_MAX + 1], const char *src) {
    size_t n = strnlen(src, LC_PROTO_ID_MAX);
    memcpy(dst, src, n);
    dst[n] = 0;
}

char *lc_proto_build_op(const lc_proto_op *op) {
    proto_b b = {0};
    char s[LC_PROTO_ID_MAX + 1];
    if (!op || op->type < LC_REQ_LIGHT_SET || op->type > LC_REQ_SETTINGS_SET) return NULL;
    cJSON *m = proto_msg(&b, lc_proto_type_name(op->type), NULL);
    proto_idcpy(s, op->target);
    switch (op->type) {
    case LC_REQ_LIGHT_SET: proto_add(&b, m, "light", proto_light_json(&b, &op->light)); break;
    case LC_REQ_LIGHT_REMOVE: proto_add_str(&b, m, "light_id", s); break;
    case LC_REQ_OBJECT_SET: proto_add(&b, m, "object", proto_object_json(&b, &op->object)); break;
    case LC_REQ_OBJECT_REMOVE: proto_add_str(&b, m, "object_id", s); break;
    case LC_REQ_MATERIAL_SET:
        proto_add_str(&b, m, "material", s);
        proto_add_floats(&b, m, "emission", op->emission, 3);
        break;
    case LC_REQ_ENVIRONMENT_SET: proto_add(&b, m, "environment", proto_env_json(&b, &op->environment)); break;
    default: proto_add(&b, m, "settings", proto_settings_json(&b, &op->settings)); break;
    }
    return proto_finish(&b, m);
}

/* welcome.scene.asset_info (§3.4): per asset name {"transfer": {...}} or {} without transfer data. */
static cJSON *proto_asset_info_json(proto_b *b, const lc_proto_welcome *w) {
    cJSON *all = proto_chk(b, cJSON_CreateObject());
    for (uint32_t i = 0; all && i < w->n_assets; i++) {
        const lc_proto_asset_info *ai = &w->asset_info[i];
        cJSON *o = proto_chk(b, cJSON_CreateObject());
        if (ai->has_transfer) {
            cJSON *t = proto_chk(b, cJSON_CreateObject());
            proto_add_u64(b, t, "dims", ai->dims);
            proto_add_u64(b, t, "coefficients", ai->coefficients);
            proto_add_u64(b, t, "bytes", ai->bytes);
            proto_add_float(b, t, "outer_radius", ai->outer_radius);
            proto_add(b, o, "transfer", t);
        }
        /* the name as a JSON key: valid UTF-8 like every string the builders write */
        char key[LC_PROTO_ID_MAX * 3 + 1];
        const char *name = w->assets && w->assets[i] ? w->assets[i] : "";
        lc_proto_utf8_sanitize(key, sizeof key, name, strnlen(name, LC_PROTO_ID_MAX), 0);
        proto_add(b, all, key, o);
    }
    return all;
}

/* §8.1: the names of the granted capability bits (unnamed bits are not written). */
static cJSON *proto_caps_json(proto_b *b, uint32_t caps) {
    cJSON *arr = proto_chk(b, cJSON_CreateArray());
    for (uint32_t k = 0; arr && k < 32; k++) {
        const char *name = (caps >> k) & 1u ? lc_proto_capability_name(1u << k) : NULL;
        cJSON *it = name ? proto_chk(b, cJSON_CreateString(name)) : NULL;
        if (it) cJSON_AddItemToArray(arr, it);
    }
    return arr;
}

char *lc_proto_build_welcome(const lc_proto_id *id, const lc_proto_welcome *w) {
    proto_b b = {0};
    if (!w) return NULL;
    cJSON *m = proto_msg(&b, "welcome", id);
    proto_add_str(&b, m, "server", w->server);
    proto_add_str(&b, m, "protocol", LC_PROTO_NAME);
    proto_add_str(&b, m, "version", LC_PROTO_VERSION);
    proto_add(&b, m, "capabilities", proto_caps_json(&b, w->capabilities));
    proto_add_str(&b, m, "role", w->role);
    proto_add_u64(&b, m, "revision", w->revision);
    cJSON *scene = proto_chk(&b, cJSON_CreateObject());
    cJSON *lm = proto_chk(&b, cJSON_CreateObject());
    proto_add_u64(&b, lm, "width", w->lightmap_width);
    proto_add_u64(&b, lm, "height", w->lightmap_height);
    proto_add_u64(&b, lm, "tile", w->tile);
    proto_add_str(&b, lm, "quantity", "irradiance");
    proto_add(&b, scene, "lightmap", lm);
    cJSON *grid = proto_chk(&b, cJSON_CreateObject());
    proto_add_floats(&b, grid, "origin", w->grid_origin, 3);
    proto_add_float(&b, grid, "cell", w->grid_cell);
    proto_add_u32s(&b, grid, "dims", w->grid_dims, 3);
    proto_add_str(&b, grid, "quantity", "irradiance_sh");
    proto_add_u64(&b, grid, "coefficients", 9);
    proto_add(&b, scene, "grid", grid);
    proto_add_u64(&b, scene, "bands", w->bands);
    proto_add_strs(&b, scene, "assets", w->assets, w->n_assets);
    if (w->bake_id) proto_add_str(&b, scene, "bake_id", w->bake_id);
    if (w->geometry) proto_add_str(&b, scene, "geometry", w->geometry);
    if (w->asset_geometry) {
        cJSON *ag = proto_chk(&b, cJSON_CreateObject());
        for (uint32_t i = 0; i < w->n_assets; i++) proto_add_str(&b, ag, w->assets[i], w->asset_geometry[i]);
        proto_add(&b, scene, "asset_geometry", ag);
    }
    if (w->asset_info) proto_add(&b, scene, "asset_info", proto_asset_info_json(&b, w));
    if (w->clutter_rest > 0) {
        cJSON *cl = proto_chk(&b, cJSON_CreateObject());
        proto_add_float(&b, cl, "rest", (float)w->clutter_rest);
        proto_add_u64(&b, cl, "max_objects", w->clutter_max_objects);
        proto_add(&b, scene, "clutter", cl);
    }
    if (w->solvers) {
        const char *names[LC_PROTO_SOLVER_COUNT];
        uint32_t n = 0;
        for (int k = 0; k < LC_PROTO_SOLVER_COUNT; k++)
            if (w->solvers & (1u << k)) names[n++] = lc_proto_solver_name(k);
        proto_add_strs(&b, scene, "solvers", names, n);
    }
    proto_add_strs(&b, scene, "materials", w->materials, w->n_materials);
    proto_add(&b, m, "scene", scene);
    cJSON *lim = proto_chk(&b, cJSON_CreateObject());
    proto_add_u64(&b, lim, "max_message", w->limits.max_message);
    proto_add_u64(&b, lim, "max_lights", w->max_lights);
    proto_add_u64(&b, lim, "max_objects", w->max_objects);
    proto_add_u64(&b, lim, "max_batch", w->limits.max_batch);
    proto_add_u64(&b, lim, "rate", w->rate);
    proto_add(&b, m, "limits", lim);
    return proto_finish(&b, m);
}

char *lc_proto_build_ok(const lc_proto_id *id, uint64_t revision) {
    proto_b b = {0};
    cJSON *m = proto_msg(&b, "ok", id);
    proto_add_u64(&b, m, "revision", revision);
    return proto_finish(&b, m);
}

char *lc_proto_build_ok_mr(const lc_proto_id *id, uint64_t revision, uint32_t session, uint64_t max_frame,
                           double max_rate, uint32_t max_lights, uint32_t points) {
    proto_b b = {0};
    cJSON *m = proto_msg(&b, "ok", id);
    proto_add_u64(&b, m, "revision", revision);
    cJSON *mr = proto_chk(&b, cJSON_CreateObject());
    proto_add_u64(&b, mr, "session", session);
    proto_add_u64(&b, mr, "max_frame", max_frame);
    proto_add_double(&b, mr, "max_rate", max_rate);
    proto_add_u64(&b, mr, "max_lights", max_lights);
    proto_add_u64(&b, mr, "points", points);
    proto_add(&b, m, "mr", mr);
    return proto_finish(&b, m);
}

char *lc_proto_build_mr_ack(uint32_t seq, uint64_t capture_us, int replaced, uint32_t lights, double ms) {
    proto_b b = {0};
    cJSON *m = proto_msg(&b, "mr.ack", NULL);
    proto_add_u64(&b, m, "seq", seq);
    proto_add_u64(&b, m, "capture_us", capture_us);
    proto_add_str(&b, m, "status", replaced ? "replaced" : "processed");
    proto_add_u64(&b, m, "lights", lights);
    proto_add_double(&b, m, "ms", ms >= 0 ? ms : 0);
    return proto_finish(&b, m);
}

char *lc_proto_build_error(const lc_proto_id *id, const lc_proto_error *e) {
    proto_b b = {0};
    char code[sizeof e->code + 1], ptr[sizeof e->pointer + 1], msg[sizeof e->message + 1];
    if (!e) return NULL;
    /* the struct's arrays may be unterminated when filled by hand */
    memcpy(code, e->code, sizeof e->code);
    code[sizeof e->code] = 0;
    memcpy(ptr, e->pointer, sizeof e->pointer);
    ptr[sizeof e->pointer] = 0;
    memcpy(msg, e->message, sizeof e->message);
    msg[sizeof e->message] = 0;
    /* a message cut by its buffer loses the cut character rather than showing U+FFFD */
    msg[lc_proto_utf8_cut(msg, strlen(msg), sizeof msg)] = 0;
    cJSON *m = proto_msg(&b, "error", id);
    proto_add_str(&b, m, "code", code[0] ? code : "internal");
    proto_add_str(&b, m, "message", msg);
    proto_add_str(&b, m, "pointer", ptr);
    return proto_finish(&b, m);
}

char *lc_proto_build_changed(uint64_t revision, const char *by, const lc_proto_op *ops, uint32_t n_ops) {
    proto_b b = {0};
    cJSON *m = proto_msg(&b, "changed", NULL);
    proto_add_u64(&b, m, "revision", revision);
    proto_add_str(&b, m, "by", by);
    cJSON *types = proto_chk(&b, cJSON_CreateArray());
    cJSON *ids = proto_chk(&b, cJSON_CreateArray());
    for (uint32_t i = 0; ops && types && ids && i < n_ops; i++) {
        char key[LC_PROTO_ID_MAX + 1];
        proto_idcpy(key, proto_op_key(&ops[i]));
        cJSON *t = proto_chk(&b, cJSON_CreateString(lc_proto_type_name(ops[i].type)));
        cJSON *k = proto_chk(&b, proto_string(key));
        if (t) cJSON_AddItemToArray(types, t);
        if (k) cJSON_AddItemToArray(ids, k);
    }
    proto_add(&b, m, "ops", types);
    proto_add(&b, m, "ids", ids);
    return proto_finish(&b, m);
}

char *lc_proto_build_object_transport(const char *object_id, int transport, uint64_t revision, double build_ms,
                                      uint64_t bytes) {
    proto_b b = {0};
    cJSON *m = proto_msg(&b, "object.transport", NULL);
    char key[LC_PROTO_ID_MAX + 1];
    proto_idcpy(key, object_id);
    proto_add(&b, m, "object_id", proto_chk(&b, proto_string(key)));
    int clutter = transport == LC_OBJECT_TRANSPORT_CLUTTER;
    proto_add_str(&b, m, "transport", clutter ? "clutter" : "dynamic");
    proto_add_u64(&b, m, "revision", revision);
    if (clutter) {
        proto_add_float(&b, m, "build_ms", (float)(build_ms > 0 ? build_ms : 0));
        proto_add_u64(&b, m, "bytes", bytes);
    }
    return proto_finish(&b, m);
}

static int proto_cmp_light(const void *a, const void *b) {
    const lc_proto_light *x = *(const lc_proto_light *const *)a, *y = *(const lc_proto_light *const *)b;
    return strncmp(x->id, y->id, sizeof x->id);
}

static int proto_cmp_object(const void *a, const void *b) {
    const lc_proto_object *x = *(const lc_proto_object *const *)a, *y = *(const lc_proto_object *const *)b;
    return strncmp(x->id, y->id, sizeof x->id);
}

char *lc_proto_build_state(const lc_proto_id *id, const lc_proto_state *st) {
    proto_b b = {0};
    const lc_proto_light **lights = NULL;
    const lc_proto_object **objects = NULL;
    cJSON *m = NULL;
    char *out = NULL;
    if (!st) return NULL;
    /* sorted by id (§5.4) without touching the caller's arrays */
    if (st->n_lights && !(lights = malloc(st->n_lights * sizeof *lights))) goto err;
    if (st->n_objects && !(objects = malloc(st->n_objects * sizeof *objects))) goto err;
    for (uint32_t i = 0; i < st->n_lights; i++) lights[i] = &st->lights[i];
    for (uint32_t i = 0; i < st->n_objects; i++) objects[i] = &st->objects[i];
    if (lights) qsort(lights, st->n_lights, sizeof *lights, proto_cmp_light);
    if (objects) qsort(objects, st->n_objects, sizeof *objects, proto_cmp_object);

    m = proto_msg(&b, "state", id);
    proto_add_u64(&b, m, "revision", st->revision);
    cJSON *arr = proto_chk(&b, cJSON_CreateArray());
    for (uint32_t i = 0; arr && i < st->n_lights; i++) {
        cJSON *it = proto_light_json(&b, lights[i]);
        if (it) cJSON_AddItemToArray(arr, it);
    }
    proto_add(&b, m, "lights", arr);
    arr = proto_chk(&b, cJSON_CreateArray());
    for (uint32_t i = 0; arr && i < st->n_objects; i++) {
        cJSON *it = proto_object_json(&b, objects[i]);
        if (it) cJSON_AddItemToArray(arr, it);
    }
    proto_add(&b, m, "objects", arr);
    arr = proto_chk(&b, cJSON_CreateArray());
    for (uint32_t i = 0; arr && i < st->n_materials; i++) {
        cJSON *it = proto_chk(&b, cJSON_CreateObject());
        proto_add_str(&b, it, "name", st->materials[i].name);
        proto_add_floats(&b, it, "emission", st->materials[i].emission, 3);
        if (it) cJSON_AddItemToArray(arr, it);
    }
    proto_add(&b, m, "materials", arr);
    proto_add(&b, m, "environment", proto_env_json(&b, &st->environment));
    proto_add(&b, m, "settings", proto_settings_json(&b, &st->settings));
    out = proto_finish(&b, m);
    m = NULL;
err:
    cJSON_Delete(m);
    free(lights);
    free(objects);
    return out;
}

char *lc_proto_build_pong(const lc_proto_id *id, double t, uint64_t server_time_us) {
    proto_b b = {0};
    cJSON *m = proto_msg(&b, "pong", id);
    proto_add_double(&b, m, "t", t);
    proto_add_u64(&b, m, "server_time_us", server_time_us);
    return proto_finish(&b, m);
}
