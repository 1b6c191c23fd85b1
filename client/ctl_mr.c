/* lucentctl mr: MR sessions (PROTOCOL.md §8). `mr replay DIR` plays a recorded RGB-D capture
 * (the lucent-rgbd/1 directory format of client/README.md, which `lucent-ref capture`
 * writes) to a server as an MR session: hello with the "mr" capability, mr.begin, one
 * upload frame per recorded frame at its time (at most 2 unacknowledged, never faster than
 * the rate the server granted), then mr.end and a JSON summary of what the server answered.
 * Main thread only. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "ctl.h"
#include "ctl_image.h"
#include "lucent_upload.h"
#include "util/half.h"

#define MR_MAX_JSON (1u << 20) /* capture.json / frame_NNNNN.json */
#define MR_MAX_FRAMES 100000u  /* frames of one recording */
#define MR_MAX_SIDE 1024u      /* PROTOCOL §8.2 */
#define MR_IN_FLIGHT 2         /* unacknowledged frames a client keeps (§8.5) */
#define MR_ACK_TIMEOUT_MS 10000.0
#define MR_PATH 1024 /* a capture file name; DIR is checked to fit */
#define MR_ERR 2048

typedef struct mr_opts {
    const char *dir;
    cJSON *session; /* mr.begin's session object */
    double speed;   /* --rate: 1 = recorded times, 2 = twice as fast, 0 = as fast as granted */
    long loops;
    int zlib, half_depth;
    const char *vpl_out; /* --vpl-out: every mr.vpl frame as a JSON line */
} mr_opts;

/* One recorded frame, ready to encode. */
typedef struct mr_frame {
    lc_upload_header h;
    void *depth, *confidence, *color; /* planes in the session's encodings */
    size_t raw_bytes;
} mr_frame;

/* What the server answered (filled by the on_message callback). */
typedef struct mr_tally {
    uint32_t sent, processed, replaced, errors;
    int in_flight;
    double *sent_ms; /* per sequence (1-based), when it went out */
    double *ack_ms;  /* latencies of processed frames */
    double lights, server_ms;
    uint64_t bytes_raw, bytes_sent;
    int quiet;
    uint32_t last_processed; /* the latest processed sequence (an mr.vpl frame follows its ack) */
    FILE *vpl;               /* --vpl-out */
    uint32_t vpl_after;      /* after_seq of the latest mr.vpl frame written */
    int vpl_done;            /* set before mr.end: its empty frame is not written */
} mr_tally;

static double mr_now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

/* The whole file as a parsed JSON object, or NULL with err naming the file. */
static cJSON *mr_read_json(const char *path, char *err, size_t errlen) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(err, errlen, "cannot read %s: %s", path, strerror(errno));
        return NULL;
    }
    char *buf = malloc(MR_MAX_JSON + 1);
    size_t n = buf ? fread(buf, 1, MR_MAX_JSON + 1, f) : 0;
    fclose(f);
    cJSON *o = NULL;
    if (!buf) snprintf(err, errlen, "%s: out of memory", path);
    else if (n > MR_MAX_JSON) snprintf(err, errlen, "%s: over %u bytes", path, MR_MAX_JSON);
    else if (!(o = cJSON_ParseWithLength(buf, n)) || !cJSON_IsObject(o)) {
        snprintf(err, errlen, "%s: not a JSON object", path);
        cJSON_Delete(o);
        o = NULL;
    }
    free(buf);
    return o;
}

/* A number field in [lo, hi]; -1 with err naming file and field. */
static int mr_num(const cJSON *o, const char *key, double lo, double hi, double *out, const char *file, char *err,
                  size_t errlen) {
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble) || v->valuedouble < lo || v->valuedouble > hi) {
        snprintf(err, errlen, "%s: \"%s\" must be a number in [%g, %g]", file, key, lo, hi);
        return -1;
    }
    *out = v->valuedouble;
    return 0;
}

/* A list of n numbers; -1 with err naming file and field. */
static int mr_nums(const cJSON *o, const char *key, int n, float *out, const char *file, char *err, size_t errlen) {
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(o, key);
    if (!cJSON_IsArray(a) || cJSON_GetArraySize(a) != n) goto bad;
    for (int i = 0; i < n; i++) {
        const cJSON *v = cJSON_GetArrayItem(a, i);
        if (!cJSON_IsNumber(v) || !isfinite(v->valuedouble) || fabs(v->valuedouble) > 1e6) goto bad;
        out[i] = (float)v->valuedouble;
    }
    return 0;
bad:
    snprintf(err, errlen, "%s: \"%s\" must be %d finite numbers", file, key, n);
    return -1;
}

/* DIR/capture.json: the format, size and frame count. */
static int mr_read_capture(const char *dir, uint32_t *w, uint32_t *h, uint32_t *frames, char *err, size_t errlen) {
    char path[MR_PATH];
    snprintf(path, sizeof path, "%s/capture.json", dir);
    cJSON *c = mr_read_json(path, err, errlen);
    if (!c) return -1;
    const cJSON *fmt = cJSON_GetObjectItemCaseSensitive(c, "format");
    double dw, dh, dn;
    int rc = -1;
    if (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, "lucent-rgbd/1") != 0)
        snprintf(err, errlen, "%s: \"format\" must be \"lucent-rgbd/1\"", path);
    else if (mr_num(c, "width", 8, MR_MAX_SIDE, &dw, path, err, errlen) == 0 &&
             mr_num(c, "height", 8, MR_MAX_SIDE, &dh, path, err, errlen) == 0 &&
             mr_num(c, "frames", 1, MR_MAX_FRAMES, &dn, path, err, errlen) == 0) {
        *w = (uint32_t)dw;
        *h = (uint32_t)dh;
        *frames = (uint32_t)dn;
        rc = 0;
    }
    cJSON_Delete(c);
    return rc;
}

/* frame_NNNNN.json into the header (sequence and sizes are the caller's); *srgb8 from "color". */
static int mr_read_frame_json(const char *path, lc_upload_header *h, int *srgb8, char *err, size_t errlen) {
    cJSON *o = mr_read_json(path, err, errlen);
    if (!o) return -1;
    const cJSON *in = cJSON_GetObjectItemCaseSensitive(o, "intrinsics");
    const cJSON *pose = cJSON_GetObjectItemCaseSensitive(o, "pose");
    const cJSON *col = cJSON_GetObjectItemCaseSensitive(o, "color");
    double t, fx, fy, cx, cy, e;
    int rc = -1;
    if (mr_num(o, "time_us", 0, 9e15, &t, path, err, errlen) ||
        mr_num(o, "exposure", 1e-30, 1e7, &e, path, err, errlen))
        goto out;
    if (!cJSON_IsObject(in) || !cJSON_IsObject(pose)) {
        snprintf(err, errlen, "%s: \"intrinsics\" and \"pose\" must be objects", path);
        goto out;
    }
    if (mr_num(in, "fx", 1e-6, 1e5, &fx, path, err, errlen) || mr_num(in, "fy", 1e-6, 1e5, &fy, path, err, errlen) ||
        mr_num(in, "cx", -1e5, 1e5, &cx, path, err, errlen) || mr_num(in, "cy", -1e5, 1e5, &cy, path, err, errlen) ||
        mr_nums(pose, "translation", 3, h->translation, path, err, errlen) ||
        mr_nums(pose, "rotation", 4, h->rotation, path, err, errlen))
        goto out;
    if (!cJSON_IsString(col) || (strcmp(col->valuestring, "srgb8") && strcmp(col->valuestring, "linear16"))) {
        snprintf(err, errlen, "%s: \"color\" must be \"srgb8\" or \"linear16\"", path);
        goto out;
    }
    *srgb8 = !strcmp(col->valuestring, "srgb8");
    h->capture_us = (uint64_t)t;
    h->fx = (float)fx;
    h->fy = (float)fy;
    h->cx = (float)cx;
    h->cy = (float)cy;
    h->exposure = (float)e;
    rc = 0;
out:
    cJSON_Delete(o);
    return rc;
}

/* One PNG that must be w x h with `channels` channels of `bits` bits. */
static uint16_t *mr_read_plane(const char *path, uint32_t w, uint32_t h, int channels, int bits, char *err,
                               size_t errlen) {
    uint32_t pw, ph;
    int ch, bd;
    uint16_t *px = NULL;
    if (ctl_image_read_png(path, MR_MAX_SIDE, &pw, &ph, &ch, &bd, &px, err, errlen) != 0) return NULL;
    if (pw != w || ph != h || ch != channels || bd != bits) {
        snprintf(err, errlen,
                 "%s: %ux%u with %d channel(s) of %d bits; the capture needs %ux%u, %d channel(s) of %d bits", path, pw,
                 ph, ch, bd, w, h, channels, bits);
        free(px);
        return NULL;
    }
    return px;
}

static void mr_frame_free(mr_frame *f) {
    free(f->depth);
    free(f->confidence);
    free(f->color);
    memset(f, 0, sizeof *f);
}

/* Frame k (1-based) of the recording, converted to the session's encodings. */
static int mr_load_frame(const mr_opts *o, uint32_t k, uint32_t w, uint32_t h, int *srgb8, mr_frame *f, char *err,
                         size_t errlen) {
    char path[MR_PATH];
    size_t n = (size_t)w * h;
    uint16_t *depth = NULL, *color = NULL, *conf = NULL;
    memset(f, 0, sizeof *f);
    snprintf(path, sizeof path, "%s/frame_%05u.json", o->dir, k);
    if (mr_read_frame_json(path, &f->h, srgb8, err, errlen) != 0) goto err;
    snprintf(path, sizeof path, "%s/depth_%05u.png", o->dir, k);
    if (!(depth = mr_read_plane(path, w, h, 1, 16, err, errlen))) goto err;
    snprintf(path, sizeof path, "%s/color_%05u.png", o->dir, k);
    if (!(color = mr_read_plane(path, w, h, 3, *srgb8 ? 8 : 16, err, errlen))) goto err;
    snprintf(path, sizeof path, "%s/confidence_%05u.png", o->dir, k);
    FILE *probe = fopen(path, "rb");
    if (probe) {
        fclose(probe);
        if (!(conf = mr_read_plane(path, w, h, 1, 8, err, errlen))) goto err;
    }
    f->depth = malloc(n * 2);
    f->color = malloc(n * (*srgb8 ? 3 : 6));
    f->confidence = conf ? malloc(n) : NULL;
    if (!f->depth || !f->color || (conf && !f->confidence)) {
        snprintf(err, errlen, "frame %u: out of memory", k);
        goto err;
    }
    uint16_t *d = f->depth, *c16 = f->color;
    uint8_t *c8 = f->color, *q = f->confidence;
    for (size_t i = 0; i < n; i++) /* millimetres as recorded, or binary16 metres */
        d[i] = o->half_depth ? lc_half_from_float(depth[i] * 1e-3f) : depth[i];
    for (size_t i = 0; i < 3 * n; i++) {
        if (*srgb8) c8[i] = (uint8_t)color[i];
        else c16[i] = lc_half_from_float(color[i] / 65535.0f);
    }
    for (size_t i = 0; conf && i < n; i++) q[i] = (uint8_t)conf[i];
    f->h.width = (uint16_t)w;
    f->h.height = (uint16_t)h;
    f->h.depth_encoding = o->half_depth ? LC_DEPTH_F16M : LC_DEPTH_U16MM;
    f->h.color_encoding = *srgb8 ? LC_COLOR_RGB8_SRGB : LC_COLOR_RGB16F_LINEAR;
    f->h.has_confidence = conf != NULL;
    f->h.depth_zlib = f->h.color_zlib = (uint8_t)o->zlib;
    f->h.confidence_zlib = (uint8_t)(o->zlib && conf);
    f->raw_bytes = LC_UPLOAD_HEADER_SIZE + n * 2 + (conf ? n : 0) + n * (*srgb8 ? 3 : 6);
    free(depth);
    free(color);
    free(conf);
    return 0;
err:
    free(depth);
    free(color);
    free(conf);
    mr_frame_free(f);
    return -1;
}

/* on_message: mr.ack and the errors an upload frame gets (neither has an id). */
static void mr_on_message(lc_client *c, const char *json, void *user) {
    (void)c;
    mr_tally *t = user;
    cJSON *o = cJSON_Parse(json);
    const cJSON *type = cJSON_GetObjectItemCaseSensitive(o, "type");
    if (cJSON_IsString(type) && !strcmp(type->valuestring, "mr.ack")) {
        const cJSON *seq = cJSON_GetObjectItemCaseSensitive(o, "seq");
        const cJSON *st = cJSON_GetObjectItemCaseSensitive(o, "status");
        const cJSON *lights = cJSON_GetObjectItemCaseSensitive(o, "lights");
        const cJSON *ms = cJSON_GetObjectItemCaseSensitive(o, "ms");
        uint32_t k = cJSON_IsNumber(seq) && seq->valuedouble >= 1 && seq->valuedouble <= t->sent
            ? (uint32_t)seq->valuedouble
            : 0;
        int replaced = cJSON_IsString(st) && !strcmp(st->valuestring, "replaced");
        double lat = k ? mr_now_ms() - t->sent_ms[k] : NAN;
        t->in_flight--;
        if (replaced) {
            t->replaced++;
        } else {
            t->ack_ms[t->processed++] = lat;
            if (k > t->last_processed) t->last_processed = k;
            t->lights += cJSON_IsNumber(lights) ? lights->valuedouble : 0;
            t->server_ms += cJSON_IsNumber(ms) ? ms->valuedouble : 0;
        }
        if (!t->quiet)
            printf("frame %u %s: %d lights, server %.1f ms, ack after %.1f ms\n", k,
                   replaced ? "replaced" : "processed", cJSON_IsNumber(lights) ? lights->valueint : 0,
                   cJSON_IsNumber(ms) ? ms->valuedouble : 0, lat);
    } else if (cJSON_IsString(type) && !strcmp(type->valuestring, "error") &&
               !cJSON_GetObjectItemCaseSensitive(o, "id")) {
        t->errors++;
        t->in_flight--;
        ctl_print_server_error(json);
    }
    cJSON_Delete(o);
}

/* on_frame: an mr.vpl frame as one JSON line {"after_seq": the upload frame it follows,
 * "revision", "objects": [{"id", "points", "records": [12 values per point]}]}. */
static void mr_on_frame(lc_client *c, const lc_client_frame *f, void *user) {
    (void)c;
    mr_tally *t = user;
    if (f->stream != LC_CLIENT_MR_VPL || !t->vpl || t->vpl_done) return;
    fprintf(t->vpl, "{\"after_seq\":%u,\"revision\":%llu,\"objects\":[", t->last_processed,
            (unsigned long long)f->revision);
    size_t at = 0;
    for (uint32_t i = 0; i < f->width; i++) {
        fprintf(t->vpl, "%s{\"id\":\"%s\",\"points\":%u,\"records\":[", i ? "," : "", f->object_ids[i],
                f->object_points[i]);
        for (size_t v = 0; v < (size_t)f->object_points[i] * 12 && at < f->value_count; v++, at++)
            fprintf(t->vpl, "%s%.9g", v ? "," : "", f->values[at]);
        fputs("]}", t->vpl);
    }
    fputs("]}\n", t->vpl);
    t->vpl_after = t->last_processed;
}

/* hello with "mr" must have been granted; then mr.begin. *granted_rate from the reply. */
static int mr_begin(lc_client *c, const mr_opts *o, double *granted_rate) {
    const char *w = lc_client_welcome(c);
    cJSON *wj = w ? cJSON_Parse(w) : NULL;
    const cJSON *caps = cJSON_GetObjectItemCaseSensitive(wj, "capabilities"), *it;
    int have = 0;
    cJSON_ArrayForEach(it, caps) have |= cJSON_IsString(it) && !strcmp(it->valuestring, "mr");
    cJSON_Delete(wj);
    if (!have) {
        fprintf(stderr, "lucentctl: %s did not grant the \"mr\" capability (hint: %s)\n", ctl_url,
                ctl_error_hint("mr_not_enabled"));
        return CTL_EXIT_REFUSED;
    }
    cJSON *req = cJSON_CreateObject();
    cJSON_AddStringToObject(req, "type", "mr.begin");
    cJSON_AddItemToObject(req, "session", cJSON_Duplicate(o->session, 1));
    char *text = cJSON_PrintUnformatted(req), *reply = NULL;
    cJSON_Delete(req);
    int rc = text ? ctl_request(c, text, &reply) : CTL_EXIT_CONN;
    free(text);
    if (rc != CTL_EXIT_OK) return rc;
    cJSON *r = cJSON_Parse(reply);
    const cJSON *mr = cJSON_GetObjectItemCaseSensitive(r, "mr");
    const cJSON *rate = cJSON_GetObjectItemCaseSensitive(mr, "max_rate");
    *granted_rate = cJSON_IsNumber(rate) && rate->valuedouble > 0 ? rate->valuedouble : 1;
    if (!ctl_json) printf("MR session: %s\n", reply);
    cJSON_Delete(r);
    free(reply);
    return CTL_EXIT_OK;
}

static int mr_cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static void mr_print_summary(mr_tally *t, double seconds) {
    qsort(t->ack_ms, t->processed, sizeof *t->ack_ms, mr_cmp_double);
    double mean = 0;
    for (uint32_t i = 0; i < t->processed; i++) mean += t->ack_ms[i] / t->processed;
    uint32_t n = t->processed ? t->processed : 1;
    cJSON *s = cJSON_CreateObject();
    cJSON_AddNumberToObject(s, "frames_sent", t->sent);
    cJSON_AddNumberToObject(s, "processed", t->processed);
    cJSON_AddNumberToObject(s, "replaced", t->replaced);
    cJSON_AddNumberToObject(s, "errors", t->errors);
    cJSON_AddNumberToObject(s, "bytes_raw_per_frame", t->sent ? (double)t->bytes_raw / t->sent : 0);
    cJSON_AddNumberToObject(s, "bytes_sent_per_frame", t->sent ? (double)t->bytes_sent / t->sent : 0);
    cJSON *a = cJSON_AddObjectToObject(s, "ack_ms");
    cJSON_AddNumberToObject(a, "mean", t->processed ? mean : 0);
    cJSON_AddNumberToObject(a, "p50", t->processed ? t->ack_ms[(n - 1) / 2] : 0);
    cJSON_AddNumberToObject(a, "p95", t->processed ? t->ack_ms[(uint32_t)ceil(0.95 * n) - 1] : 0);
    cJSON_AddNumberToObject(s, "server_ms_mean", t->server_ms / n);
    cJSON_AddNumberToObject(s, "lights_mean", t->lights / n);
    cJSON_AddNumberToObject(s, "seconds", seconds);
    char *text = cJSON_PrintUnformatted(s);
    if (text) printf("%s\n", text);
    free(text);
    cJSON_Delete(s);
}

/* Polls until fewer than `limit` frames are unacknowledged; -1 on timeout or a lost connection. */
static int mr_wait_acks(lc_client *c, mr_tally *t, int limit) {
    double start = mr_now_ms();
    while (t->in_flight >= limit) {
        if (lc_client_poll(c, 5) != 0) return -1;
        if (mr_now_ms() - start > MR_ACK_TIMEOUT_MS) return -1;
    }
    return 0;
}

/* Sends one frame once it is due: its recorded time, the granted rate, at most 2 unacked. */
static int mr_send(lc_client *c, mr_frame *f, double due, double granted, mr_tally *t) {
    char err[MR_ERR] = "";
    uint8_t *buf = NULL;
    size_t len = 0;
    if (lc_upload_encode(&f->h, f->depth, f->confidence, f->color, &buf, &len, err, sizeof err) != 0) {
        fprintf(stderr, "lucentctl: frame %u: %s\n", f->h.sequence, err);
        return CTL_EXIT_USAGE;
    }
    double last = t->sent ? t->sent_ms[t->sent] : -1e12;
    while (mr_now_ms() < due || mr_now_ms() - last < 1000.0 / granted)
        if (lc_client_poll(c, 2) != 0) break;
    if (mr_wait_acks(c, t, MR_IN_FLIGHT) != 0 || lc_client_send_binary(c, buf, len, err, sizeof err) != 0) {
        free(buf);
        fprintf(stderr, "lucentctl: frame %u: no acknowledgement in %.0f s, or the connection was lost %s\n",
                f->h.sequence, MR_ACK_TIMEOUT_MS / 1000, err);
        return CTL_EXIT_CONN;
    }
    free(buf);
    t->sent_ms[++t->sent] = mr_now_ms();
    t->in_flight++;
    t->bytes_raw += f->raw_bytes;
    t->bytes_sent += len;
    return CTL_EXIT_OK;
}

/* Sends every frame, o->loops times over (a loop lasts the recording plus one frame period;
 * sequences and capture times keep increasing), then waits for the last acknowledgements. */
static int mr_stream(lc_client *c, const mr_opts *o, uint32_t w, uint32_t h, uint32_t frames, double granted,
                     int session_srgb8, mr_tally *t) {
    char err[MR_ERR];
    double t0 = mr_now_ms();
    uint64_t first_us = 0, loop_us = 0;
    for (long loop = 0; loop < o->loops; loop++) {
        for (uint32_t k = 1; k <= frames; k++) {
            mr_frame f;
            int srgb8, rc;
            if (mr_load_frame(o, k, w, h, &srgb8, &f, err, sizeof err) != 0) {
                fprintf(stderr, "lucentctl: %s\n", err);
                return CTL_EXIT_USAGE;
            }
            if (srgb8 != session_srgb8) {
                fprintf(stderr, "lucentctl: %s/frame_%05u.json: \"color\" differs from frame 1's\n", o->dir, k);
                mr_frame_free(&f);
                return CTL_EXIT_USAGE;
            }
            if (loop == 0 && k == 1) first_us = f.h.capture_us;
            uint64_t rel_us = f.h.capture_us > first_us ? f.h.capture_us - first_us : 0;
            if (loop == 0 && k == frames) loop_us = frames > 1 ? rel_us + rel_us / (frames - 1) : 100000;
            f.h.sequence = t->sent + 1;
            f.h.capture_us = first_us + (uint64_t)loop * loop_us + rel_us;
            double due = o->speed > 0 ? t0 + ((uint64_t)loop * loop_us + rel_us) * 1e-3 / o->speed : 0;
            rc = mr_send(c, &f, due, granted, t);
            mr_frame_free(&f);
            if (rc != CTL_EXIT_OK) return rc;
        }
    }
    if (mr_wait_acks(c, t, 1) != 0) {
        fprintf(stderr, "lucentctl: %d frame(s) still unacknowledged after %.0f s\n", t->in_flight,
                MR_ACK_TIMEOUT_MS / 1000);
        return CTL_EXIT_CONN;
    }
    return CTL_EXIT_OK;
}

/* Session fields go straight into mr.begin's "session" (the server checks the ranges and
 * names the field); the keys starting with '_' are the replay's own. */
static const ctl_flag mr_replay_flags[] = {
    {"--objects", "_objects", CTL_FLAG_STRING, 0, 0, NULL, "ID[,ID...]", "required: the 1..16 objects to light"},
    {"--rate", "_rate", CTL_FLAG_NUM, 0, 0, NULL, "X",
     "play at X times the recorded speed (default 1; 0 = as fast as the server grants)"},
    {"--loop", "_loop", CTL_FLAG_INT, 0, 0, NULL, "N", "play the recording N times (default 1)"},
    {"--zlib", "_zlib", CTL_FLAG_SWITCH, 0, 0, NULL, NULL, "zlib-compress the planes"},
    {"--half-depth", "_half", CTL_FLAG_SWITCH, 0, 0, NULL, NULL, "send depth as binary16 metres (f16m), not u16mm"},
    {"--quiet", "_quiet", CTL_FLAG_SWITCH, 0, 0, NULL, NULL, "no line per acknowledgement, only the summary"},
    {"--vpl-out", "_vpl", CTL_FLAG_STRING, 0, 0, NULL, "FILE",
     "subscribe to mr.vpl (f32) and write every frame as a JSON line (after_seq, revision, objects' records)"},
    {"--max-rate", "max_rate", CTL_FLAG_NUM, 0, 0, NULL, "F", "frames per second to ask for (0.1..60, default 10)"},
    {"--glossy", "glossy", CTL_FLAG_BOOL, 0, 0, NULL, "true|false", "glossy VPLs (default true)"},
    {"--specular-exponent", "specular_exponent", CTL_FLAG_NUM, 0, 0, NULL, "K", "Phong exponent (default 16)"},
    {"--min-confidence", "min_confidence", CTL_FLAG_NUM, 0, 0, NULL, "C", "0..1 (default 0.5)"},
    {"--smoothing", "smoothing", CTL_FLAG_NUM, 0, 0, NULL, "S", "0..0.99 (default 0)"},
    {"--light", "light", CTL_FLAG_CHOICE, 0, 0, "replace|add", "replace|add", "default replace"},
    {NULL, NULL, 0, 0, 0, NULL, NULL, NULL},
};

static void mr_usage(FILE *out) {
    fprintf(out,
            "usage: lucentctl mr replay DIR --objects ID[,ID...] [options]\n\n"
            "Plays a recorded RGB-D capture (DIR/capture.json, frame_NNNNN.json, depth_/color_/confidence_\n"
            "NNNNN.png: the lucent-rgbd/1 format of client/README.md, as `lucent-ref capture` writes) to the\n"
            "server as an MR session (PROTOCOL.md §8), then prints a JSON summary. Needs a controller token.\n\n");
    ctl_print_flags(mr_replay_flags, out);
}

/* Takes the '_' keys out of the parsed flags into o and builds the session object. */
static int mr_take_options(cJSON *flags, mr_opts *o) {
    const cJSON *v;
    o->speed = 1;
    o->loops = 1;
    if ((v = cJSON_GetObjectItemCaseSensitive(flags, "_rate"))) o->speed = v->valuedouble;
    if ((v = cJSON_GetObjectItemCaseSensitive(flags, "_loop"))) o->loops = (long)v->valuedouble;
    o->zlib = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(flags, "_zlib"));
    o->half_depth = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(flags, "_half"));
    if (o->speed < 0 || o->speed > 1000) return ctl_usage_error("mr replay: --rate %g is outside 0..1000", o->speed);
    if (o->loops < 1 || o->loops > 1000000)
        return ctl_usage_error("mr replay: --loop %ld is outside 1..1000000", o->loops);
    const cJSON *ids = cJSON_GetObjectItemCaseSensitive(flags, "_objects");
    if (!cJSON_IsString(ids)) return ctl_usage_error("mr replay: --objects ID[,ID...] is required");
    cJSON *list = cJSON_AddArrayToObject(flags, "objects");
    char buf[2048];
    snprintf(buf, sizeof buf, "%s", ids->valuestring);
    for (char *save = NULL, *id = strtok_r(buf, ",", &save); id; id = strtok_r(NULL, ",", &save))
        cJSON_AddItemToArray(list, cJSON_CreateString(id));
    if ((v = cJSON_GetObjectItemCaseSensitive(flags, "_vpl"))) o->vpl_out = strdup(v->valuestring);
    static const char *const mine[] = {"_objects", "_rate", "_loop", "_zlib", "_half", "_quiet", "_vpl"};
    for (size_t i = 0; i < sizeof mine / sizeof mine[0]; i++) cJSON_DeleteItemFromObjectCaseSensitive(flags, mine[i]);
    o->session = flags;
    return CTL_EXIT_OK;
}

/* Lucentctl mr replay DIR ...: the session's encodings come from the recording (frame 1). */
int ctl_cmd_mr(int argc, char **argv) {
    if (ctl_wants_help(argc, argv) || argc < 2) {
        mr_usage(argc < 2 ? stderr : stdout);
        return argc < 2 ? CTL_EXIT_USAGE : CTL_EXIT_OK;
    }
    if (strcmp(argv[1], "replay") != 0) return ctl_usage_error("mr: unknown subcommand '%s' (replay)", argv[1]);
    cJSON *flags = cJSON_CreateObject();
    char *pos[2], err[MR_ERR];
    int npos = 0, rc, srgb8 = 0;
    mr_opts o = {0};
    mr_tally t = {0};
    lc_client *c = NULL;
    uint32_t w, h, frames;
    rc = ctl_parse_flags("mr replay", mr_replay_flags, argc, argv, 2, flags, pos, 2, &npos);
    if (rc != CTL_EXIT_OK) goto out;
    t.quiet = ctl_json || cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(flags, "_quiet"));
    if (npos != 1) {
        rc = ctl_usage_error("mr replay: give exactly one capture directory");
        goto out;
    }
    o.dir = pos[0];
    if (strlen(o.dir) > MR_PATH - 32) {
        rc = ctl_usage_error("mr replay: the directory name is over %d bytes", MR_PATH - 32);
        goto out;
    }
    if ((rc = mr_take_options(flags, &o)) != CTL_EXIT_OK) goto out;
    mr_frame first;
    if (mr_read_capture(o.dir, &w, &h, &frames, err, sizeof err) != 0 ||
        mr_load_frame(&o, 1, w, h, &srgb8, &first, err, sizeof err) != 0) {
        fprintf(stderr, "lucentctl: %s\n", err);
        rc = CTL_EXIT_USAGE;
        goto out;
    }
    mr_frame_free(&first);
    cJSON_AddNumberToObject(o.session, "width", w);
    cJSON_AddNumberToObject(o.session, "height", h);
    cJSON_AddStringToObject(o.session, "depth", o.half_depth ? "f16m" : "u16mm");
    cJSON_AddStringToObject(o.session, "color", srgb8 ? "rgb8_srgb" : "rgb16f_linear");
    size_t total = (size_t)frames * (size_t)o.loops + 1;
    t.sent_ms = calloc(total, sizeof *t.sent_ms);
    t.ack_ms = calloc(total, sizeof *t.ack_ms);
    if (!t.sent_ms || !t.ack_ms) {
        fprintf(stderr, "lucentctl: out of memory for %zu frames\n", total);
        rc = CTL_EXIT_USAGE;
        goto out;
    }
    lc_client_options co;
    lc_client_options_init(&co);
    co.timeout_ms = CTL_TIMEOUT_MS;
    co.capabilities = "mr";
    if (!(c = ctl_connect(&co, &rc))) goto out;
    lc_client_set_callbacks(c,
                            &(lc_client_callbacks){.on_message = mr_on_message, .on_frame = mr_on_frame, .user = &t});
    double granted = 1, start = mr_now_ms();
    if ((rc = mr_begin(c, &o, &granted)) != CTL_EXIT_OK) goto out;
    if (o.vpl_out) {
        if (!(t.vpl = fopen(o.vpl_out, "w"))) {
            fprintf(stderr, "lucentctl: --vpl-out %s: %s\n", o.vpl_out, strerror(errno));
            rc = CTL_EXIT_USAGE;
            goto out;
        }
        if (lc_client_subscribe(c, LC_CLIENT_MR_VPL, LC_CLIENT_F32, 0, err, sizeof err) != 0) {
            fprintf(stderr, "lucentctl: subscribe mr.vpl: %s\n", err);
            rc = CTL_EXIT_REFUSED;
            goto out;
        }
    }
    rc = mr_stream(c, &o, w, h, frames, granted, srgb8, &t);
    if (t.vpl) /* the last result's mr.vpl frame follows its ack */
        for (double until = mr_now_ms() + 2000; t.vpl_after < t.last_processed && mr_now_ms() < until;)
            if (lc_client_poll(c, 10) != 0) break;
    t.vpl_done = 1;
    int end_rc = ctl_request(c, "{\"type\":\"mr.end\"}", NULL);
    mr_print_summary(&t, (mr_now_ms() - start) * 1e-3);
    if (rc == CTL_EXIT_OK) rc = end_rc != CTL_EXIT_OK ? end_rc : t.errors ? CTL_EXIT_REFUSED : CTL_EXIT_OK;
out:
    lc_client_close(c);
    if (t.vpl && fclose(t.vpl) != 0 && rc == CTL_EXIT_OK) rc = CTL_EXIT_USAGE;
    free((char *)o.vpl_out);
    cJSON_Delete(flags);
    free(t.sent_ms);
    free(t.ack_ms);
    return rc;
}
