/* state: the dynamic scene state and its atomic, validated changes (see state.h). */
#include "state.h"

#include <cjson/cJSON.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"

_Static_assert((int)LC_SOLVER_PIC == (int)LC_PROTO_SOLVER_PIC && (int)LC_SOLVER_PROBES == (int)LC_PROTO_SOLVER_PROBES &&
                   LC_SOLVER_COUNT == (int)LC_PROTO_SOLVER_COUNT,
               "settings.solver maps to lc_engine_settings.solver as is");

static void state_err(lc_proto_error *err, lc_proto_errcode code, int batch, uint32_t op, const char *field,
                      const char *fmt, const char *arg) {
    if (!err) return;
    lc_proto_error_set_code(err, code);
    if (batch) snprintf(err->pointer, sizeof err->pointer, "/ops/%u%s", op, field);
    else snprintf(err->pointer, sizeof err->pointer, "%s", field);
    snprintf(err->message, sizeof err->message, fmt, arg);
}

int lc_state_init(lc_state *s, const lc_lcb *bake, const lc_state_limits *limits) {
    memset(s, 0, sizeof *s);
    s->scene = lc_lcb_get(bake);
    s->limits = *limits;
    uint32_t nm = s->scene->n_materials;
    s->emission = calloc(nm ? nm : 1, sizeof *s->emission);
    if (!s->emission) return -1;
    for (uint32_t m = 0; m < nm; m++) memcpy(s->emission[m], s->scene->materials[m].emission, sizeof s->emission[m]);
    lc_engine_settings d = lc_engine_default_settings(bake);
    s->settings.present = LC_SET_ALL;
    s->settings.bounces = d.bounces;
    s->settings.bands = d.bands;
    s->settings.progressive = d.progressive;
    s->settings.chroma_compression = d.chroma_compression;
    s->settings.chroma_bands = d.chroma_bands;
    s->settings.dnrt = d.dnrt;
    s->settings.dnrt_blockers = d.dnrt_blockers;
    s->settings.solver = (int)d.solver;
    s->backend = LC_BACKEND_AUTO;
    s->environment.kind = 0;
    s->environment.intensity = 1;
    return 0;
}

void lc_state_release(lc_state *s) {
    if (!s) return;
    free(s->lights);
    free(s->objects);
    free(s->emission);
    memset(s, 0, sizeof *s);
}

int lc_state_clone(lc_state *dst, const lc_state *src) {
    *dst = *src;
    dst->lights = NULL;
    dst->objects = NULL;
    dst->emission = NULL;
    uint32_t nm = src->scene->n_materials ? src->scene->n_materials : 1;
    dst->lights = malloc((src->n_lights ? src->n_lights : 1) * sizeof *dst->lights);
    dst->objects = malloc((src->n_objects ? src->n_objects : 1) * sizeof *dst->objects);
    dst->emission = malloc(nm * sizeof *dst->emission);
    if (!dst->lights || !dst->objects || !dst->emission) {
        lc_state_release(dst);
        return -1;
    }
    /* (memcpy from a NULL array is undefined even for 0 bytes) */
    if (src->n_lights) memcpy(dst->lights, src->lights, src->n_lights * sizeof *dst->lights);
    if (src->n_objects) memcpy(dst->objects, src->objects, src->n_objects * sizeof *dst->objects);
    if (src->scene->n_materials) memcpy(dst->emission, src->emission, src->scene->n_materials * sizeof *dst->emission);
    return 0;
}

/* Binary search in an id-sorted array of records whose first member is the id. Returns the
 * index, or -(insertion point) - 1. */
static long state_find(const void *base, uint32_t n, size_t stride, const char *id) {
    long lo = 0, hi = (long)n - 1;
    while (lo <= hi) {
        long mid = (lo + hi) / 2;
        int c = strcmp((const char *)base + (size_t)mid * stride, id);
        if (c == 0) return mid;
        if (c < 0) lo = mid + 1;
        else hi = mid - 1;
    }
    return -lo - 1;
}

/* Inserts or replaces the record (sorted by id). The array has room for one more. */
static void state_upsert(void *base, uint32_t *n, size_t stride, const void *rec) {
    long at = state_find(base, *n, stride, (const char *)rec);
    char *b = base;
    if (at >= 0) {
        memcpy(b + (size_t)at * stride, rec, stride);
        return;
    }
    size_t pos = (size_t)(-at - 1);
    memmove(b + (pos + 1) * stride, b + pos * stride, (*n - pos) * stride);
    memcpy(b + pos * stride, rec, stride);
    (*n)++;
}

static int state_remove(void *base, uint32_t *n, size_t stride, const char *id) {
    long at = state_find(base, *n, stride, id);
    if (at < 0) return -1;
    char *b = base;
    memmove(b + (size_t)at * stride, b + ((size_t)at + 1) * stride, (*n - (size_t)at - 1) * stride);
    (*n)--;
    return 0;
}

static long state_asset(const lc_lcb_view *v, const char *name) {
    for (uint32_t i = 0; i < v->n_assets; i++)
        if (strcmp(v->assets[i].name, name) == 0) return i;
    return -1;
}

static long state_material(const lc_lcb_view *v, const char *name) {
    for (uint32_t i = 0; i < v->n_materials; i++)
        if (strcmp(v->materials[i].name, name) == 0) return i;
    return -1;
}

/* The fields of `n` that it has (present bits) over `cur`: settings.set and a snapshot's
 * settings (an older snapshot lacks the newer fields; they keep their defaults). */
static lc_proto_settings state_merge_settings(lc_proto_settings cur, const lc_proto_settings *n) {
    if (n->present & (1u << LC_SET_BOUNCES)) cur.bounces = n->bounces;
    if (n->present & (1u << LC_SET_BANDS)) cur.bands = n->bands;
    if (n->present & (1u << LC_SET_PROGRESSIVE)) cur.progressive = n->progressive;
    if (n->present & (1u << LC_SET_CHROMA)) cur.chroma_compression = n->chroma_compression;
    if (n->present & (1u << LC_SET_CHROMA_BANDS)) cur.chroma_bands = n->chroma_bands;
    if (n->present & (1u << LC_SET_DNRT)) cur.dnrt = n->dnrt;
    if (n->present & (1u << LC_SET_DNRT_BLOCKERS)) cur.dnrt_blockers = n->dnrt_blockers;
    if (n->present & (1u << LC_SET_SOLVER)) cur.solver = n->solver;
    cur.present = LC_SET_ALL;
    return cur;
}

/* Applies one op to s (which has spare capacity for one more light and object). */
static int state_apply_one(lc_state *s, const lc_proto_op *op, int batch, uint32_t i, lc_proto_error *err) {
    switch (op->type) {
    case LC_REQ_LIGHT_SET: {
        if (state_find(s->lights, s->n_lights, sizeof *s->lights, op->light.id) < 0 &&
            s->n_lights >= s->limits.max_lights) {
            char lim[32];
            snprintf(lim, sizeof lim, "%u", s->limits.max_lights);
            state_err(err, LC_ERR_LIMIT_EXCEEDED, batch, i, "/light/id", "the server holds at most %s lights", lim);
            return -1;
        }
        state_upsert(s->lights, &s->n_lights, sizeof *s->lights, &op->light);
        return 0;
    }
    case LC_REQ_LIGHT_REMOVE:
        if (state_remove(s->lights, &s->n_lights, sizeof *s->lights, op->target) != 0) {
            state_err(err, LC_ERR_UNKNOWN_ID, batch, i, "/light_id", "no light with id '%s'", op->target);
            return -1;
        }
        return 0;
    case LC_REQ_OBJECT_SET: {
        if (state_asset(s->scene, op->object.asset) < 0) {
            state_err(err, LC_ERR_UNKNOWN_ASSET, batch, i, "/object/asset", "the scene has no asset '%s'",
                      op->object.asset);
            return -1;
        }
        if (state_find(s->objects, s->n_objects, sizeof *s->objects, op->object.id) < 0 &&
            s->n_objects >= s->limits.max_objects) {
            char lim[32];
            snprintf(lim, sizeof lim, "%u", s->limits.max_objects);
            state_err(err, LC_ERR_LIMIT_EXCEEDED, batch, i, "/object/id", "the server holds at most %s objects", lim);
            return -1;
        }
        state_upsert(s->objects, &s->n_objects, sizeof *s->objects, &op->object);
        return 0;
    }
    case LC_REQ_OBJECT_REMOVE:
        if (state_remove(s->objects, &s->n_objects, sizeof *s->objects, op->target) != 0) {
            state_err(err, LC_ERR_UNKNOWN_ID, batch, i, "/object_id", "no object with id '%s'", op->target);
            return -1;
        }
        return 0;
    case LC_REQ_MATERIAL_SET: {
        long m = state_material(s->scene, op->target);
        if (m < 0) {
            state_err(err, LC_ERR_UNKNOWN_MATERIAL, batch, i, "/material", "the scene has no material '%s'",
                      op->target);
            return -1;
        }
        memcpy(s->emission[m], op->emission, sizeof s->emission[m]);
        return 0;
    }
    case LC_REQ_ENVIRONMENT_SET: s->environment = op->environment; return 0;
    case LC_REQ_SETTINGS_SET: {
        const lc_proto_settings *n = &op->settings;
        lc_proto_settings next = state_merge_settings(s->settings, n);
        if (!(n->present & (1u << LC_SET_CHROMA_BANDS)) && next.chroma_bands > next.bands)
            next.chroma_bands = next.bands; /* follow a band reduction */
        if (next.chroma_bands < 1 || next.chroma_bands > next.bands) {
            state_err(err, LC_ERR_OUT_OF_RANGE, batch, i, "/settings/chroma_bands", "%s",
                      "chroma_bands must be in 1..bands");
            return -1;
        }
        /* here, not in the whole-state check, so the pointer names the op */
        char why[200];
        if ((n->present & (1u << LC_SET_SOLVER)) &&
            lc_engine_check_solver(s->scene, s->backend, (uint32_t)n->solver, why, sizeof why) != 0) {
            const char *msg = strncmp(why, "/settings/solver: ", 18) == 0 ? why + 18 : why; /* the pointer says it */
            state_err(err, LC_ERR_INVALID, batch, i, "/settings/solver", "%s", msg);
            return -1;
        }
        s->settings = next;
        return 0;
    }
    default: state_err(err, LC_ERR_INVALID, batch, i, "/type", "%s", "not a change operation"); return -1;
    }
}

/* The relight engine's own validation of the whole resulting state, so nothing is
 * acknowledged that the engine would refuse after the `ok`. Its path ("/lights/3/...")
 * names the state's light by index: the message names it by id. */
static int state_engine_check(const lc_state *s, lc_proto_error *err) {
    lc_engine_state es;
    lc_engine_light *lights;
    lc_engine_object *objects;
    float *emission;
    if (lc_state_to_engine(s, &es, &lights, &objects, &emission) != 0) {
        state_err(err, LC_ERR_INTERNAL, 0, 0, "", "%s", "out of memory checking the change");
        return -1;
    }
    char why[200];
    int rc = lc_engine_check_state(s->scene, &es, why, sizeof why);
    if (rc != 0) {
        unsigned idx;
        int used = 0;
        state_err(err, LC_ERR_OUT_OF_RANGE, 0, 0, "", "%s", why);
        if (!err) {
        } else if (sscanf(why, "/lights/%u/%n", &idx, &used) == 1 && used > 0 && idx < s->n_lights)
            snprintf(err->message, sizeof err->message, "light '%.64s': %.150s", s->lights[idx].id, why + used);
        else if (sscanf(why, "/objects/%u/%n", &idx, &used) == 1 && used > 0 && idx < s->n_objects)
            snprintf(err->message, sizeof err->message, "object '%.64s': %.150s", s->objects[idx].id, why + used);
    }
    free(lights);
    free(objects);
    free(emission);
    return rc;
}

int lc_state_seed(lc_state *s, char *err, size_t errlen) {
    int rc = -1;
    char *text = NULL;
    size_t n = 0, cap = 64;
    cJSON *meta = cJSON_ParseWithLength(s->scene->meta_json, s->scene->meta_len);
    const cJSON *lights = meta ? cJSON_GetObjectItemCaseSensitive(meta, "lights") : NULL;
    if (!cJSON_IsArray(lights) || cJSON_GetArraySize(lights) == 0) {
        rc = 0; /* no lights in the bake */
        goto err;
    }
    /* The bake stores lucent/1 light objects: replay them as one batch of light.set, so they
     * pass the same validation (and limits) as a client's change. */
    int count = cJSON_GetArraySize(lights);
    char **parts = calloc((size_t)count, sizeof *parts);
    if (!parts) goto oom;
    int k = 0;
    for (const cJSON *l = lights->child; l; l = l->next, k++) {
        parts[k] = cJSON_PrintUnformatted(l);
        if (!parts[k]) break;
        cap += strlen(parts[k]) + 32;
    }
    text = k == count ? malloc(cap) : NULL;
    if (text) {
        n = (size_t)snprintf(text, cap, "{\"type\":\"batch\",\"ops\":[");
        for (int i = 0; i < count; i++)
            n += (size_t)snprintf(text + n, cap - n, "%s{\"type\":\"light.set\",\"light\":%s}", i ? "," : "", parts[i]);
        n += (size_t)snprintf(text + n, cap - n, "]}");
    }
    for (int i = 0; i < count; i++) cJSON_free(parts[i]);
    free(parts);
    if (!text) goto oom;
    lc_proto_limits lim;
    lc_proto_default_limits(&lim);
    lim.max_message = n + 1;
    lim.max_batch = (uint32_t)count;
    lc_proto_request req;
    lc_proto_error perr;
    if (lc_proto_parse_request(text, n, &lim, &req, &perr) != 0) {
        lc_set_err(err, errlen, "the bake's lights: %s at %s: %s", perr.code, perr.pointer, perr.message);
        goto err;
    }
    uint64_t revision = s->revision;
    int applied = lc_state_apply(s, req.ops, req.n_ops, 1, &perr);
    lc_proto_request_release(&req);
    if (applied != 0) {
        lc_set_err(err, errlen, "the bake's lights: %s at %s: %s (raise --max-lights?)", perr.code, perr.pointer,
                   perr.message);
        goto err;
    }
    s->revision = revision; /* the initial state, not a change */
    rc = 0;
    goto err;
oom:
    lc_set_err(err, errlen, "out of memory reading the bake's lights");
err:
    free(text);
    cJSON_Delete(meta);
    return rc;
}

int lc_state_apply(lc_state *s, const lc_proto_op *ops, uint32_t n_ops, int batch, lc_proto_error *err) {
    lc_state next;
    if (lc_state_clone(&next, s) != 0) goto oom;
    /* Room for every op to insert. */
    lc_proto_light *l = realloc(next.lights, ((size_t)next.n_lights + n_ops + 1) * sizeof *l);
    if (!l) goto oom_next;
    next.lights = l;
    lc_proto_object *o = realloc(next.objects, ((size_t)next.n_objects + n_ops + 1) * sizeof *o);
    if (!o) goto oom_next;
    next.objects = o;
    for (uint32_t i = 0; i < n_ops; i++)
        if (state_apply_one(&next, &ops[i], batch, i, err) != 0) {
            lc_state_release(&next);
            return -1;
        }
    if (state_engine_check(&next, err) != 0) {
        lc_state_release(&next);
        return -1;
    }
    next.revision = s->revision + 1;
    lc_state_release(s);
    *s = next;
    return 0;
oom_next:
    lc_state_release(&next);
oom:
    state_err(err, LC_ERR_INTERNAL, 0, 0, "", "%s", "out of memory applying the change");
    return -1;
}

int lc_state_restore(lc_state *s, const lc_proto_parsed_state *p, lc_proto_error *err) {
    lc_state next;
    if (lc_state_clone(&next, s) != 0) {
        state_err(err, LC_ERR_INTERNAL, 0, 0, "", "%s", "out of memory");
        return -1;
    }
    next.n_lights = next.n_objects = 0;
    if (p->n_lights > s->limits.max_lights || p->n_objects > s->limits.max_objects) {
        lc_state_release(&next);
        state_err(err, LC_ERR_LIMIT_EXCEEDED, 0, 0, "", "%s",
                  "the snapshot holds more lights or objects than the limits");
        return -1;
    }
    lc_proto_light *l = realloc(next.lights, ((size_t)p->n_lights + 1) * sizeof *l);
    lc_proto_object *o = l ? realloc(next.objects, ((size_t)p->n_objects + 1) * sizeof *o) : NULL;
    if (l) next.lights = l;
    if (o) next.objects = o;
    if (!l || !o) {
        lc_state_release(&next);
        state_err(err, LC_ERR_INTERNAL, 0, 0, "", "%s", "out of memory");
        return -1;
    }
    for (uint32_t i = 0; i < p->n_lights; i++) state_upsert(next.lights, &next.n_lights, sizeof *l, &p->lights[i]);
    for (uint32_t i = 0; i < p->n_objects; i++) {
        if (state_asset(next.scene, p->objects[i].asset) < 0) {
            state_err(err, LC_ERR_UNKNOWN_ASSET, 0, 0, "/objects", "the bake has no asset '%s' (was it rebaked?)",
                      p->objects[i].asset);
            lc_state_release(&next);
            return -1;
        }
        state_upsert(next.objects, &next.n_objects, sizeof *o, &p->objects[i]);
    }
    for (uint32_t i = 0; i < p->n_materials; i++) {
        long m = state_material(next.scene, p->material_names[i]);
        if (m >= 0) memcpy(next.emission[m], p->material_emission[i], sizeof next.emission[m]);
        else lc_warn("state", "snapshot material '%s' is not in the bake; ignored", p->material_names[i]);
    }
    next.environment = p->environment;
    lc_proto_settings st = state_merge_settings(next.settings, &p->settings);
    if (st.chroma_bands > st.bands) st.chroma_bands = st.bands;
    char why[200];
    if (lc_engine_check_solver(next.scene, next.backend, (uint32_t)st.solver, why, sizeof why) != 0) {
        lc_warn("state", "snapshot settings.solver '%s' dropped (%s); using the bake's default",
                lc_proto_solver_name(st.solver) ? lc_proto_solver_name(st.solver) : "?", why);
        st.solver = (int)lc_engine_default_solver(next.scene);
    }
    next.settings = st;
    next.revision = p->revision;
    lc_state_release(s);
    *s = next;
    return 0;
}

void lc_state_set_backend(lc_state *s, lc_backend_kind backend) {
    s->backend = backend;
    char why[200];
    if (lc_engine_check_solver(s->scene, backend, (uint32_t)s->settings.solver, why, sizeof why) == 0) return;
    uint32_t d = lc_engine_default_solver(s->scene);
    if (lc_engine_check_solver(s->scene, backend, d, NULL, 0) != 0) return; /* the relights will say why */
    lc_warn("state", "settings.solver '%s' cannot run here (%s); using '%s'", lc_proto_solver_name(s->settings.solver),
            why, lc_proto_solver_name((int)d));
    s->settings.solver = (int)d;
}

uint32_t lc_state_solvers(const lc_state *s) {
    uint32_t bits = 0;
    for (uint32_t k = 0; k < LC_SOLVER_COUNT; k++)
        if (lc_engine_check_solver(s->scene, s->backend, k, NULL, 0) == 0) bits |= 1u << k;
    return bits;
}

int lc_state_to_proto(const lc_state *s, lc_proto_state *out, lc_proto_material_state **mats) {
    uint32_t nm = s->scene->n_materials;
    lc_proto_material_state *m = calloc(nm ? nm : 1, sizeof *m);
    if (!m) return -1;
    for (uint32_t i = 0; i < nm; i++) {
        m[i].name = s->scene->materials[i].name;
        memcpy(m[i].emission, s->emission[i], sizeof m[i].emission);
    }
    memset(out, 0, sizeof *out);
    out->revision = s->revision;
    out->lights = s->lights;
    out->n_lights = s->n_lights;
    out->objects = s->objects;
    out->n_objects = s->n_objects;
    out->materials = m;
    out->n_materials = nm;
    out->environment = s->environment;
    out->settings = s->settings;
    *mats = m;
    return 0;
}

void lc_state_object_to_engine(const lc_state *s, const lc_proto_object *p, lc_engine_object *o) {
    memset(o, 0, sizeof *o);
    snprintf(o->id, sizeof o->id, "%s", p->id);
    o->asset = (uint32_t)state_asset(s->scene, p->asset);
    memcpy(o->translation, p->translation, sizeof o->translation);
    memcpy(o->rotation, p->rotation, sizeof o->rotation);
    memcpy(o->scale, p->scale, sizeof o->scale);
    o->visible = p->visible;
    o->dnrt_off = !p->dnrt;
    o->clutter_off = p->mode == LC_OBJECT_MODE_DYNAMIC;
}

int lc_state_to_engine(const lc_state *s, lc_engine_state *out, lc_engine_light **lights, lc_engine_object **objects,
                       float **emission) {
    const lc_lcb_view *v = s->scene;
    *lights = calloc(s->n_lights ? s->n_lights : 1, sizeof **lights);
    *objects = calloc(s->n_objects ? s->n_objects : 1, sizeof **objects);
    *emission = malloc((v->n_materials ? v->n_materials : 1) * 3 * sizeof **emission);
    if (!*lights || !*objects || !*emission) {
        free(*lights);
        free(*objects);
        free(*emission);
        *lights = NULL;
        *objects = NULL;
        *emission = NULL;
        return -1;
    }
    for (uint32_t i = 0; i < s->n_lights; i++) {
        const lc_proto_light *p = &s->lights[i];
        lc_engine_light *l = &(*lights)[i];
        snprintf(l->id, sizeof l->id, "%s", p->id);
        l->type = (lc_engine_light_type)p->type;
        memcpy(l->color, p->color, sizeof l->color);
        l->intensity = p->intensity;
        l->range = p->range;
        memcpy(l->position, p->position, sizeof l->position);
        memcpy(l->direction, p->direction, sizeof l->direction);
        l->inner_cone = p->inner_cone;
        l->outer_cone = p->outer_cone;
        l->shape = p->shape ? LC_AREA_DISC : LC_AREA_QUAD;
        memcpy(l->size, p->size, sizeof l->size);
        memcpy(l->tangent, p->tangent, sizeof l->tangent);
        if (l->tangent[0] == 0 && l->tangent[1] == 0 && l->tangent[2] == 0) {
            /* Any direction perpendicular to the light's: the engine orthonormalises. */
            l->tangent[0] = fabsf(l->direction[0]) < 0.9f ? 1.0f : 0.0f;
            l->tangent[1] = fabsf(l->direction[0]) < 0.9f ? 0.0f : 1.0f;
        }
    }
    for (uint32_t i = 0; i < s->n_objects; i++) lc_state_object_to_engine(s, &s->objects[i], &(*objects)[i]);
    memcpy(*emission, s->emission, (size_t)v->n_materials * 3 * sizeof **emission);
    memset(out, 0, sizeof *out);
    out->lights = *lights;
    out->n_lights = s->n_lights;
    out->objects = *objects;
    out->n_objects = s->n_objects;
    out->material_emission = *emission;
    out->environment.kind = (lc_engine_env_kind)s->environment.kind;
    memcpy(out->environment.color, s->environment.color, sizeof out->environment.color);
    memcpy(out->environment.sh, s->environment.sh, sizeof out->environment.sh);
    out->environment.intensity = s->environment.intensity;
    out->settings.bounces = s->settings.bounces;
    out->settings.bands = s->settings.bands;
    out->settings.progressive = s->settings.progressive;
    out->settings.chroma_compression = s->settings.chroma_compression;
    out->settings.chroma_bands = s->settings.chroma_bands;
    out->settings.sh_lightmap = 0;
    out->settings.dnrt = s->settings.dnrt;
    out->settings.dnrt_blockers = s->settings.dnrt_blockers;
    out->settings.solver = (uint32_t)s->settings.solver;
    out->revision = s->revision;
    return 0;
}
