/* lucentctl watch / snapshot / latency: the commands that subscribe to data streams.
 *
 * Files written per frame (PREFIX = the stream name, plus "-SEQUENCE" for watch):
 *   lightmap: PREFIX.exr (OpenEXR, half float RGB irradiance, W/m^2, row 0 = top),
 *             PREFIX.png (tone-mapped preview: fixed exposure, sRGB), and with --raw
 *             PREFIX.f32 (W*H*3 little-endian float32: bit-exact for the f32 encoding);
 *   shgrid:   PREFIX.json (dims, origin, cell, layout and the values) and PREFIX.bin
 *             (samples x 27 float32, x fastest, RGB interleaved per coefficient);
 *   objects:  PREFIX.json (id and 27 SH values per object) and PREFIX.bin (as shgrid).
 * watch also appends one JSON line per frame to DIR/frames.jsonl. */
#include <cjson/cJSON.h>
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include "ctl.h"
#include "ctl_image.h"
#include "util/log.h"
#include "util/sigflag.h"

static lc_sigflag stream_stop;

static void stream_on_signal(int sig) {
    (void)sig;
    stream_stop = 1;
}

static void stream_install_signals(void) {
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = stream_on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
}

static int stream_parse_name(const char *s) {
    if (!strcmp(s, "lightmap")) return LC_CLIENT_LIGHTMAP;
    if (!strcmp(s, "shgrid")) return LC_CLIENT_SHGRID;
    if (!strcmp(s, "objects")) return LC_CLIENT_OBJECTS;
    return 0;
}

static const char *stream_name(int s) {
    return s == LC_CLIENT_LIGHTMAP ? "lightmap" : s == LC_CLIENT_SHGRID ? "shgrid" : "objects";
}

static int encoding_parse_name(const char *s) {
    if (!strcmp(s, "rgb9e5")) return LC_CLIENT_RGB9E5;
    if (!strcmp(s, "rgba16f")) return LC_CLIENT_RGBA16F;
    if (!strcmp(s, "f32")) return LC_CLIENT_F32;
    return 0;
}

static const char *encoding_name(int e) {
    return e == LC_CLIENT_RGB9E5 ? "rgb9e5" : e == LC_CLIENT_RGBA16F ? "rgba16f" : "f32";
}

static int parse_positive(const char *s, double *out) {
    char *e;
    errno = 0;
    double v = strtod(s, &e);
    if (e == s || *e || errno || !isfinite(v) || v <= 0) return -1;
    *out = v;
    return 0;
}

static int mkdir_p(const char *dir) {
    char buf[1024];
    if (snprintf(buf, sizeof buf, "%s", dir) >= (int)sizeof buf) return -1;
    for (char *p = buf + 1; *p; p++)
        if (*p == '/') {
            *p = 0;
            if (mkdir(buf, 0777) != 0 && errno != EEXIST) return -1;
            *p = '/';
        }
    return mkdir(buf, 0777) != 0 && errno != EEXIST ? -1 : 0;
}

static int write_file(const char *path, const void *data, size_t len, char *err, size_t errlen) {
    FILE *f = fopen(path, "wb");
    /* len 0 (an objects frame with no objects): data may be NULL, which fwrite must not get */
    if (!f || (len && fwrite(data, 1, len, f) != len) || fclose(f) != 0) {
        /* the path (up to 1200 bytes) may not fit the caller's message buffer: cut to fit */
        lc_set_err(err, errlen, "cannot write %s: %s", path, strerror(errno));
        return -1;
    }
    return 0;
}

static int write_json(const char *path, cJSON *o, char *err, size_t errlen) {
    char *t = cJSON_PrintUnformatted(o);
    int r = t ? write_file(path, t, strlen(t), err, errlen) : -1;
    if (!t) snprintf(err, errlen, "out of memory");
    free(t);
    return r;
}

static double srgb_encode(double v) {
    if (!(v > 0)) return 0; /* also NaN */
    if (v > 1) v = 1;
    return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1 / 2.4) - 0.055;
}

static int cmp_float(const void *a, const void *b) {
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* Exposure that maps the 99th percentile of non-zero luminance to 0.8 (before sRGB). */
static double auto_exposure(const float *rgb, size_t texels) {
    float *lum = malloc((texels ? texels : 1) * sizeof *lum);
    if (!lum) return 1;
    size_t n = 0;
    for (size_t i = 0; i < texels; i++) {
        float l = 0.2126f * rgb[3 * i] + 0.7152f * rgb[3 * i + 1] + 0.0722f * rgb[3 * i + 2];
        if (l > 0 && isfinite(l)) lum[n++] = l;
    }
    double exposure = 1;
    if (n) {
        qsort(lum, n, sizeof *lum, cmp_float);
        float p99 = lum[(size_t)(0.99 * (double)(n - 1))];
        if (p99 > 0) exposure = 0.8 / p99;
    }
    free(lum);
    return exposure;
}

typedef struct stream_out {
    const char *dir;
    int raw;
    double exposure; /* 0 = pick from the first lightmap */
    cJSON *welcome;  /* parsed welcome (grid description) */
} stream_out;

static int write_lightmap(stream_out *so, const char *prefix, const lc_client_frame *f, char *err, size_t errlen) {
    char path[1200];
    size_t texels = (size_t)f->width * f->height;
    snprintf(path, sizeof path, "%s/%s.exr", so->dir, prefix);
    if (ctl_image_write_exr_half(path, f->width, f->height, f->values, err, errlen) != 0) return -1;
    if (so->exposure <= 0) so->exposure = auto_exposure(f->values, texels);
    uint8_t *png = malloc(texels * 3);
    if (!png) {
        snprintf(err, errlen, "out of memory");
        return -1;
    }
    for (size_t i = 0; i < texels * 3; i++) png[i] = (uint8_t)lrint(255.0 * srgb_encode(f->values[i] * so->exposure));
    snprintf(path, sizeof path, "%s/%s.png", so->dir, prefix);
    int r = ctl_image_write_png(path, f->width, f->height, png, err, errlen);
    free(png);
    if (r != 0) return -1;
    if (so->raw) {
        snprintf(path, sizeof path, "%s/%s.f32", so->dir, prefix);
        if (write_file(path, f->values, texels * 3 * sizeof(float), err, errlen) != 0) return -1;
    }
    return 0;
}

static cJSON *float_array(const float *v, size_t n) {
    cJSON *a = cJSON_CreateArray();
    for (size_t i = 0; i < n && a; i++) cJSON_AddItemToArray(a, cJSON_CreateNumber((double)v[i]));
    return a;
}

static int write_sh(stream_out *so, const char *prefix, const lc_client_frame *f, char *err, size_t errlen) {
    char path[1200];
    snprintf(path, sizeof path, "%s/%s.bin", so->dir, prefix);
    if (write_file(path, f->values, f->value_count * sizeof(float), err, errlen) != 0) return -1;
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "stream", stream_name(f->stream));
    cJSON_AddNumberToObject(o, "revision", (double)f->revision);
    cJSON_AddNumberToObject(o, "sequence", (double)f->sequence);
    cJSON_AddStringToObject(o, "quantity", "irradiance_sh");
    cJSON_AddStringToObject(o, "layout",
                            "9 coefficients x RGB interleaved (c0.r c0.g c0.b c1.r ...), "
                            "real orthonormal SH, i = l*l + l + m, E(n) = sum c_i y_i(n)");
    if (f->stream == LC_CLIENT_SHGRID) {
        const cJSON *grid =
            cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(so->welcome, "scene"), "grid");
        const uint32_t dims[3] = {f->width, f->height, f->depth};
        cJSON *d = cJSON_CreateArray();
        for (int k = 0; k < 3; k++) cJSON_AddItemToArray(d, cJSON_CreateNumber(dims[k]));
        cJSON_AddItemToObject(o, "dims", d);
        if (grid) {
            cJSON_AddItemToObject(o, "origin", cJSON_Duplicate(cJSON_GetObjectItemCaseSensitive(grid, "origin"), 1));
            cJSON_AddItemToObject(o, "cell", cJSON_Duplicate(cJSON_GetObjectItemCaseSensitive(grid, "cell"), 1));
        }
        cJSON_AddStringToObject(o, "order", "x fastest, then y, then z; sample (i,j,k) at origin + (i,j,k)*cell");
        cJSON_AddItemToObject(o, "values", float_array(f->values, f->value_count));
    } else {
        cJSON *objs = cJSON_AddArrayToObject(o, "objects");
        for (uint32_t i = 0; i < f->width; i++) {
            cJSON *e = cJSON_CreateObject();
            cJSON_AddStringToObject(e, "id", f->object_ids[i]);
            cJSON_AddItemToObject(e, "sh", float_array(f->values + 27 * (size_t)i, 27));
            cJSON_AddItemToArray(objs, e);
        }
    }
    snprintf(path, sizeof path, "%s/%s.json", so->dir, prefix);
    int r = write_json(path, o, err, errlen);
    cJSON_Delete(o);
    return r;
}

static int write_frame(stream_out *so, const char *prefix, const lc_client_frame *f, char *err, size_t errlen) {
    return f->stream == LC_CLIENT_LIGHTMAP ? write_lightmap(so, prefix, f, err, errlen)
                                           : write_sh(so, prefix, f, err, errlen);
}

/* How old the frame is: from the server finishing the relight to the frame being complete here. */
static double frame_age_ms(const lc_client_frame *f) {
    return ((double)f->client_time_us - (double)f->server_time_us) / 1000.0;
}

/* --- watch ----------------------------------------------------------------------------- */

static void usage_watch(FILE *o) {
    fprintf(o,
            "usage: lucentctl watch --stream lightmap|shgrid|objects --out DIR [options]\n"
            "Subscribes and writes every frame as it arrives (see lucentctl snapshot for the files):\n"
            "  lightmap-SEQ.exr (half float) + lightmap-SEQ.png (tone-mapped) [+ .f32 with --raw],\n"
            "  shgrid-SEQ.json + .bin, objects-SEQ.json + .bin; one JSON line per frame in DIR/frames.jsonl.\n"
            "options:\n"
            "  --encoding rgb9e5|rgba16f|f32  wire encoding (default: the stream's)\n"
            "  --delta tiles|residual  lightmap delta frames: whole tiles (default) or compressed\n"
            "                       residuals (smaller; PROTOCOL.md 6.2.1)\n"
            "  --max-rate HZ        ask the server for at most HZ frames per second\n"
            "  --count N            stop after N frames\n"
            "  --duration SECONDS   stop after this long (default: until Ctrl-C)\n"
            "  --until-revision N   stop once a frame of revision N or later has come and then no\n"
            "                       frame for --settle seconds (the idle refinement passes of that\n"
            "                       revision are over); exit 3 if --duration ends first\n"
            "  --settle SECONDS     quiet time that ends --until-revision (default 1)\n"
            "  --raw                also write the lightmap as raw float32 (.f32)\n"
            "  --exposure X         PNG exposure multiplier (default: from the first frame)\n"
            "  --no-reconnect       exit 3 when the connection drops (default: reconnect with back-off)\n"
            "Once subscribed (the server answered ok: every later change reaches this watch) it prints\n"
            "\"lucentctl: subscribed to STREAM\" on stderr, also with --json; scripts wait for that line.\n");
}

typedef struct watch_ctx {
    stream_out so;
    FILE *index;
    unsigned long written, limit; /* limit: --count, 0 = none */
    int failed;
    char err[512];
    unsigned long long until_rev; /* --until-revision (0 = none) */
    int reached;                  /* a frame of until_rev or later was written */
    double last_frame_s;          /* monotonic time of the last frame written */
} watch_ctx;

static double watch_now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static void watch_on_frame(lc_client *c, const lc_client_frame *f, void *user) {
    (void)c;
    watch_ctx *w = user;
    if (w->failed || (w->limit && w->written >= w->limit)) return; /* --count reached within one poll */
    char prefix[64];
    snprintf(prefix, sizeof prefix, "%s-%06llu", stream_name(f->stream), (unsigned long long)f->sequence);
    if (write_frame(&w->so, prefix, f, w->err, sizeof w->err) != 0) {
        w->failed = 1;
        return;
    }
    w->written++;
    w->last_frame_s = watch_now_s();
    if (w->until_rev && f->revision >= w->until_rev) w->reached = 1;
    double age = frame_age_ms(f);
    fprintf(
        w->index,
        "{\"file\":\"%s\",\"stream\":\"%s\",\"encoding\":\"%s\",\"revision\":%llu,\"sequence\":%llu,"
        "\"keyframe\":%s,\"residual\":%s,\"tiles\":%u,\"bytes\":%zu,\"server_time_us\":%llu,\"client_time_us\":%llu,"
        "\"age_ms\":%.3f,\"pass\":%d,\"converged\":%s}\n",
        prefix, stream_name(f->stream), encoding_name(f->encoding), (unsigned long long)f->revision,
        (unsigned long long)f->sequence, f->keyframe ? "true" : "false", f->residual ? "true" : "false", f->tile_count,
        f->raw_len, (unsigned long long)f->server_time_us, (unsigned long long)f->client_time_us, age, f->pass,
        f->converged ? "true" : "false");
    fflush(w->index);
    if (ctl_json)
        printf(
            "{\"type\":\"frame\",\"file\":\"%s\",\"revision\":%llu,\"sequence\":%llu,\"keyframe\":%s,\"bytes\":%zu}\n",
            prefix, (unsigned long long)f->revision, (unsigned long long)f->sequence, f->keyframe ? "true" : "false",
            f->raw_len);
    else
        printf("%s revision %llu %s %zu B (%u tiles) -> %s/%s.*\n", stream_name(f->stream),
               (unsigned long long)f->revision,
               f->keyframe       ? "keyframe"
                   : f->residual ? "residual delta"
                                 : "delta",
               f->raw_len, f->tile_count, w->so.dir, prefix);
    fflush(stdout);
}

static void watch_on_connection(lc_client *c, int event, const char *reason, void *user) {
    (void)c;
    (void)user;
    if (event == LC_CLIENT_RECONNECTING) fprintf(stderr, "lucentctl: connection lost (%s); reconnecting\n", reason);
    else if (event == LC_CLIENT_CONNECTED) fprintf(stderr, "lucentctl: reconnected, subscriptions renewed\n");
    else fprintf(stderr, "lucentctl: disconnected: %s\n", reason);
}

int ctl_cmd_watch(int argc, char **argv) {
    if (ctl_wants_help(argc, argv)) {
        usage_watch(stdout);
        return CTL_EXIT_OK;
    }
    int stream = 0, encoding = 0, raw = 0, reconnect = 1, residual = 0;
    double max_rate = 0, duration = 0, exposure = 0, count = 0, until_rev = 0, settle = 0;
    const char *dir = NULL;
    for (int i = 1; i < argc; i++) {
        const char *k = argv[i];
        if (!strcmp(k, "--raw")) {
            raw = 1;
            continue;
        }
        if (!strcmp(k, "--no-reconnect")) {
            reconnect = 0;
            continue;
        }
        if (i + 1 >= argc) return ctl_usage_error("watch: %s needs a value", k);
        const char *v = argv[++i];
        if (!strcmp(k, "--stream")) {
            if (!(stream = stream_parse_name(v)))
                return ctl_usage_error("watch: --stream '%s' is not lightmap, shgrid or objects", v);
        } else if (!strcmp(k, "--encoding")) {
            if (!(encoding = encoding_parse_name(v)))
                return ctl_usage_error("watch: --encoding '%s' is not rgb9e5, rgba16f or f32", v);
        } else if (!strcmp(k, "--delta")) {
            if (strcmp(v, "tiles") && strcmp(v, "residual"))
                return ctl_usage_error("watch: --delta '%s' is not tiles or residual", v);
            residual = !strcmp(v, "residual");
        } else if (!strcmp(k, "--out")) dir = v;
        else if (!strcmp(k, "--until-revision")) {
            if (parse_positive(v, &until_rev) != 0 || until_rev != floor(until_rev) || until_rev > 9e15)
                return ctl_usage_error("watch: --until-revision '%s' is not a whole number >= 1", v);
        } else if (!strcmp(k, "--settle")) {
            if (parse_positive(v, &settle) != 0 || settle > 3600)
                return ctl_usage_error("watch: --settle '%s' is not a number of seconds in (0, 3600]", v);
        } else if (!strcmp(k, "--max-rate") || !strcmp(k, "--duration") || !strcmp(k, "--exposure") ||
                   !strcmp(k, "--count")) {
            double x;
            if (parse_positive(v, &x) != 0) return ctl_usage_error("watch: %s '%s' is not a positive number", k, v);
            if (!strcmp(k, "--count") && x != floor(x))
                return ctl_usage_error("watch: --count '%s' is not a whole number", v);
            *(!strcmp(k, "--max-rate")       ? &max_rate
                  : !strcmp(k, "--duration") ? &duration
                  : !strcmp(k, "--exposure") ? &exposure
                                             : &count) = x;
        } else return ctl_usage_error("watch: unknown option '%s'", k);
    }
    if (!stream) return ctl_usage_error("watch: --stream is required");
    if (!dir) return ctl_usage_error("watch: --out DIR is required");
    if (encoding == LC_CLIENT_RGB9E5 && stream != LC_CLIENT_LIGHTMAP)
        return ctl_usage_error("watch: rgb9e5 is for the lightmap only (SH streams: rgba16f or f32)");
    if (residual && stream != LC_CLIENT_LIGHTMAP)
        return ctl_usage_error("watch: --delta is for the lightmap only (SH streams send keyframes)");
    if (settle > 0 && until_rev <= 0) return ctl_usage_error("watch: --settle needs --until-revision");
    if (mkdir_p(dir) != 0) {
        fprintf(stderr, "lucentctl: cannot create %s: %s\n", dir, strerror(errno));
        return CTL_EXIT_USAGE;
    }

    int rc = CTL_EXIT_OK;
    watch_ctx w;
    memset(&w, 0, sizeof w);
    w.so.dir = dir;
    w.so.raw = raw;
    w.so.exposure = exposure;
    w.limit = (unsigned long)count;
    w.until_rev = (unsigned long long)until_rev;
    if (settle <= 0) settle = 1.0;
    char path[1100];
    snprintf(path, sizeof path, "%s/frames.jsonl", dir);
    w.index = fopen(path, "a");
    if (!w.index) {
        fprintf(stderr, "lucentctl: cannot open %s: %s\n", path, strerror(errno));
        return CTL_EXIT_USAGE;
    }
    lc_client_options opts;
    lc_client_options_init(&opts);
    opts.reconnect = reconnect;
    lc_client *c = ctl_connect(&opts, &rc);
    if (!c) goto out;
    w.so.welcome = cJSON_Parse(lc_client_welcome(c));
    lc_client_callbacks cb = {watch_on_frame, NULL, watch_on_connection, &w};
    lc_client_set_callbacks(c, &cb);
    char err[512];
    int r = lc_client_subscribe(c, stream, encoding | (residual ? LC_CLIENT_RESIDUAL : 0), max_rate, err, sizeof err);
    if (r != 0) {
        fprintf(stderr, "lucentctl: subscribe failed: %s\n", err);
        rc = r == 1 ? CTL_EXIT_REFUSED : CTL_EXIT_CONN;
        goto out;
    }
    /* the event scripts wait for instead of sleeping: from here on every change reaches us */
    fprintf(stderr, "lucentctl: subscribed to %s\n", stream_name(stream));
    fflush(stderr);
    stream_install_signals();
    double t0 = watch_now_s();
    while (!stream_stop && !w.failed && (count <= 0 || w.written < (unsigned long)count)) {
        if (lc_client_poll(c, 50) != 0) {
            rc = CTL_EXIT_CONN;
            break;
        }
        double t = watch_now_s();
        if (w.reached && t - w.last_frame_s >= settle) break; /* --until-revision: settled */
        if (duration > 0 && t - t0 >= duration) {
            if (w.until_rev) {
                fprintf(stderr, "lucentctl: watch: %s revision %llu within --duration %g s\n",
                        w.reached ? "frames still coming (no --settle quiet) after" : "no frame of", w.until_rev,
                        duration);
                rc = CTL_EXIT_CONN;
            }
            break;
        }
    }
    if (w.failed) {
        fprintf(stderr, "lucentctl: %s\n", w.err);
        rc = CTL_EXIT_USAGE;
    }
    lc_client_stats st;
    lc_client_get_stats(c, &st);
    if (!ctl_json)
        fprintf(stderr, "lucentctl: %lu frames written (%lu keyframes, %lu deltas, %lu resyncs, %lu reconnects)\n",
                w.written, st.keyframes, st.deltas, st.resyncs, st.reconnects);
out:
    cJSON_Delete(w.so.welcome);
    lc_client_close(c);
    fclose(w.index);
    return rc;
}

/* --- snapshot -------------------------------------------------------------------------- */

static void usage_snapshot(FILE *o) {
    fprintf(o,
            "usage: lucentctl snapshot --out DIR [--stream lightmap,shgrid,objects] [--encoding E] [--raw]\n"
            "Writes the current frame of each stream once (default: all three):\n"
            "  lightmap.exr (half float RGB irradiance, W/m^2, row 0 = top), lightmap.png (tone-mapped),\n"
            "  lightmap.f32 with --raw (W*H*3 float32 LE; bit-exact with --encoding f32),\n"
            "  shgrid.json + shgrid.bin, objects.json + objects.bin (27 float32 per sample: L2\n"
            "  irradiance SH, RGB interleaved), and snapshot.json (revision, sizes, files).\n"
            "  --encoding rgb9e5|rgba16f|f32 applies to the lightmap (SH streams use f32 unless rgba16f).\n");
}

int ctl_cmd_snapshot(int argc, char **argv) {
    if (ctl_wants_help(argc, argv)) {
        usage_snapshot(stdout);
        return CTL_EXIT_OK;
    }
    const char *dir = NULL;
    int want[4] = {0, 1, 1, 1}, encoding = 0, raw = 0;
    for (int i = 1; i < argc; i++) {
        const char *k = argv[i];
        if (!strcmp(k, "--raw")) {
            raw = 1;
            continue;
        }
        if (i + 1 >= argc) return ctl_usage_error("snapshot: %s needs a value", k);
        const char *v = argv[++i];
        if (!strcmp(k, "--out")) dir = v;
        else if (!strcmp(k, "--encoding")) {
            if (!(encoding = encoding_parse_name(v)))
                return ctl_usage_error("snapshot: --encoding '%s' is not rgb9e5, rgba16f or f32", v);
        } else if (!strcmp(k, "--stream")) {
            want[1] = want[2] = want[3] = 0;
            char list[128];
            snprintf(list, sizeof list, "%s", v);
            for (char *save = NULL, *tok = strtok_r(list, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
                int s = stream_parse_name(tok);
                if (!s) return ctl_usage_error("snapshot: --stream '%s' is not lightmap, shgrid or objects", tok);
                want[s] = 1;
            }
        } else return ctl_usage_error("snapshot: unknown option '%s'", k);
    }
    if (!dir) return ctl_usage_error("snapshot: --out DIR is required");
    if (mkdir_p(dir) != 0) {
        fprintf(stderr, "lucentctl: cannot create %s: %s\n", dir, strerror(errno));
        return CTL_EXIT_USAGE;
    }
    int rc = CTL_EXIT_OK;
    stream_out so = {dir, raw, 0, NULL};
    cJSON *index = cJSON_CreateObject();
    lc_client *c = ctl_connect(NULL, &rc);
    if (!c) goto out;
    so.welcome = cJSON_Parse(lc_client_welcome(c));
    /* frames that include every change acknowledged before we connected */
    const cJSON *wrev = cJSON_GetObjectItemCaseSensitive(so.welcome, "revision");
    uint64_t min_rev = cJSON_IsNumber(wrev) ? (uint64_t)wrev->valuedouble : 0;
    char err[512];
    for (int s = 1; s <= 3 && rc == CTL_EXIT_OK; s++) {
        if (!want[s]) continue;
        int enc = s == LC_CLIENT_LIGHTMAP ? encoding : (encoding == LC_CLIENT_RGBA16F ? encoding : LC_CLIENT_F32);
        int r = lc_client_subscribe(c, s, enc, 0, err, sizeof err);
        lc_client_frame f;
        if (r == 0) r = lc_client_wait_frame(c, s, min_rev, 0, CTL_TIMEOUT_MS * 2, &f, err, sizeof err);
        if (r != 0) {
            fprintf(stderr, "lucentctl: %s: %s\n", stream_name(s), err);
            rc = r == 1 ? CTL_EXIT_REFUSED : CTL_EXIT_CONN;
            break;
        }
        if (write_frame(&so, stream_name(s), &f, err, sizeof err) != 0) {
            fprintf(stderr, "lucentctl: %s\n", err);
            rc = CTL_EXIT_USAGE;
            break;
        }
        cJSON *e = cJSON_AddObjectToObject(index, stream_name(s));
        cJSON_AddNumberToObject(e, "revision", (double)f.revision);
        cJSON_AddStringToObject(e, "encoding", encoding_name(f.encoding));
        cJSON_AddNumberToObject(e, "width", f.width);
        cJSON_AddNumberToObject(e, "height", f.height);
        cJSON_AddNumberToObject(e, "depth", f.depth);
        cJSON_AddNumberToObject(e, "last_frame_bytes", (double)f.raw_len); /* the frame that completed the copy */
        cJSON_AddBoolToObject(e, "last_frame_keyframe", f.keyframe);
        if (!ctl_json)
            printf("%s: revision %llu, %ux%ux%u -> %s/%s.%s\n", stream_name(s), (unsigned long long)f.revision, f.width,
                   f.height, f.depth, dir, stream_name(s), s == LC_CLIENT_LIGHTMAP ? "{exr,png}" : "{json,bin}");
    }
    if (rc == CTL_EXIT_OK) {
        char path[1100];
        snprintf(path, sizeof path, "%s/snapshot.json", dir);
        if (write_json(path, index, err, sizeof err) != 0) {
            fprintf(stderr, "lucentctl: %s\n", err);
            rc = CTL_EXIT_USAGE;
        } else if (ctl_json) {
            char *t = cJSON_PrintUnformatted(index);
            printf("%s\n", t ? t : "{}");
            free(t);
        }
    }
out:
    cJSON_Delete(so.welcome);
    cJSON_Delete(index);
    lc_client_close(c);
    return rc;
}

/* --- latency --------------------------------------------------------------------------- */

static void usage_latency(FILE *o) {
    fprintf(o,
            "usage: lucentctl latency [--count N] [--interval SECONDS] [--light ID]\n"
            "Measures ping round trips, then update->frame latency: subscribes to the lightmap,\n"
            "sends N light.set updates for a dim probe point light (ID, default lucentctl-probe;\n"
            "removed afterwards) and times each from sending to the first frame whose revision\n"
            "includes it. Prints min/p50/p90/p99/max. Needs a controller token.\n"
            "  --count N (default 20)   --interval SECONDS between updates (default 0.1)\n"
            "  --clients N (default 1)  subscribers measured: N-1 more connections, one thread each;\n"
            "                           update_to_frame then has count x N samples\n");
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double percentile(const double *sorted, int n, double p) {
    if (n <= 0) return NAN;
    double r = p * (n - 1);
    int i = (int)r;
    return i + 1 < n ? sorted[i] + (r - i) * (sorted[i + 1] - sorted[i]) : sorted[n - 1];
}

static double mono_ms(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1000.0 + (double)t.tv_nsec / 1e6;
}

static void latency_report(const char *name, double *v, int n, cJSON *json) {
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    double st[5] = {n ? v[0] : NAN, percentile(v, n, 0.5), percentile(v, n, 0.9), percentile(v, n, 0.99),
                    n ? v[n - 1] : NAN};
    if (json) {
        cJSON *o = cJSON_AddObjectToObject(json, name);
        cJSON_AddNumberToObject(o, "n", n);
        const char *k[5] = {"min_ms", "p50_ms", "p90_ms", "p99_ms", "max_ms"};
        for (int i = 0; i < 5; i++) cJSON_AddNumberToObject(o, k[i], n ? st[i] : 0);
    } else printf("%-16s %5d %9.2f %9.2f %9.2f %9.2f %9.2f\n", name, n, st[0], st[1], st[2], st[3], st[4]);
}

/* --clients N: N-1 more subscribers, each on its own thread with its own connection (a
 * blocking lc_client per thread), recording when each revision's first frame arrived. */
typedef struct latency_viewer {
    pthread_t thread;
    int started, ok;
    atomic_int ready;
    const atomic_int *stop;
    uint64_t *rev; /* revision of each frame received, with its arrival time (monotonic ms) */
    double *at;
    size_t n, cap;
} latency_viewer;

static void latency_viewer_frame(lc_client *c, const lc_client_frame *f, void *user) {
    (void)c;
    latency_viewer *v = user;
    if (v->n == v->cap) {
        size_t cap = v->cap ? 2 * v->cap : 256;
        uint64_t *r = realloc(v->rev, cap * sizeof *r);
        if (r) v->rev = r;
        double *a = realloc(v->at, cap * sizeof *a);
        if (a) v->at = a;
        if (!r || !a) return;
        v->cap = cap;
    }
    v->rev[v->n] = f->revision;
    v->at[v->n++] = mono_ms();
}

/* Thread: one viewer. */
static void *latency_viewer_main(void *arg) {
    latency_viewer *v = arg;
    int rc = 0;
    char err[256];
    lc_client *c = ctl_connect(NULL, &rc);
    if (c) {
        lc_client_callbacks cb = {latency_viewer_frame, NULL, NULL, v};
        lc_client_set_callbacks(c, &cb);
        v->ok = lc_client_subscribe(c, LC_CLIENT_LIGHTMAP, 0, 0, err, sizeof err) == 0 &&
            lc_client_wait_frame(c, LC_CLIENT_LIGHTMAP, 0, 0, CTL_TIMEOUT_MS * 2, NULL, err, sizeof err) == 0;
        if (!v->ok) fprintf(stderr, "lucentctl: latency viewer: %s\n", err);
    }
    atomic_store(&v->ready, 1);
    while (v->ok && !atomic_load(v->stop))
        if (lc_client_poll(c, 20) != 0) break;
    lc_client_close(c);
    return NULL;
}

/* Milliseconds from t_send to the first frame of revision >= want, or -1. */
static double latency_viewer_delay(const latency_viewer *v, uint64_t want, double t_send) {
    for (size_t i = 0; i < v->n; i++)
        if (v->rev[i] >= want && v->at[i] >= t_send) return v->at[i] - t_send;
    return -1;
}

/* The flags of `lucentctl latency`. */
typedef struct latency_opts {
    double count, interval, clients; /* whole numbers but count and clients, checked */
    const char *light;
} latency_opts;

/* Parses the flags into o: CTL_EXIT_OK, or CTL_EXIT_USAGE with the error printed. */
static int latency_parse(int argc, char **argv, latency_opts *o) {
    o->count = 20, o->interval = 0.1, o->clients = 1;
    o->light = "lucentctl-probe";
    for (int i = 1; i < argc; i++) {
        const char *k = argv[i];
        if (i + 1 >= argc) return ctl_usage_error("latency: %s needs a value", k);
        const char *v = argv[++i];
        if (!strcmp(k, "--count")) {
            if (parse_positive(v, &o->count) != 0 || o->count != floor(o->count) || o->count > 100000)
                return ctl_usage_error("latency: --count '%s' is not a whole number in 1..100000", v);
        } else if (!strcmp(k, "--interval")) {
            if (parse_positive(v, &o->interval) != 0 || o->interval > 60)
                return ctl_usage_error("latency: --interval '%s' is not in (0, 60] seconds", v);
        } else if (!strcmp(k, "--light")) {
            if (!*v || strlen(v) > 64) return ctl_usage_error("latency: --light '%s' must be 1..64 bytes", v);
            o->light = v;
        } else if (!strcmp(k, "--clients")) {
            if (parse_positive(v, &o->clients) != 0 || o->clients != floor(o->clients) || o->clients > 1000)
                return ctl_usage_error("latency: --clients '%s' is not a whole number in 1..1000", v);
        } else return ctl_usage_error("latency: unknown option '%s'", k);
    }
    return CTL_EXIT_OK;
}

/* What one run measures (milliseconds), and what each update waited for. */
typedef struct latency_samples {
    double *ping, *ack, *frame; /* frame: this connection's, then every viewer's */
    double *t_send;             /* when each acknowledged update was sent (monotonic ms) */
    uint64_t *want_rev;         /* the revision each acknowledged update made */
    int n_ping, n_ack, n_frame;
} latency_samples;

/* Round trips of up to 20 pings. CTL_EXIT_OK or CTL_EXIT_CONN (printed). */
static int latency_pings(lc_client *c, int n, latency_samples *ls) {
    char err[512];
    for (int i = 0; i < n && i < 20; i++) {
        double t0 = mono_ms();
        if (lc_client_request(c, "{\"type\":\"ping\",\"t\":0}", NULL, 0, err, sizeof err) != 0) {
            fprintf(stderr, "lucentctl: ping: %s\n", err);
            return CTL_EXIT_CONN;
        }
        ls->ping[ls->n_ping++] = mono_ms() - t0;
    }
    return CTL_EXIT_OK;
}

/* Where the probe light goes: the middle of the welcome's SH grid, which is inside the
 * scene's bounds; (0, 1, 0) without a grid. */
static void latency_probe_position(lc_client *c, double centre[3]) {
    centre[0] = 0, centre[1] = 1, centre[2] = 0;
    const cJSON *pos = NULL;
    cJSON *wel = cJSON_Parse(lc_client_welcome(c));
    const cJSON *grid = cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(wel, "scene"), "grid");
    if ((pos = cJSON_GetObjectItemCaseSensitive(grid, "origin")) && cJSON_GetArraySize(pos) == 3) {
        const cJSON *cell = cJSON_GetObjectItemCaseSensitive(grid, "cell"),
                    *dims = cJSON_GetObjectItemCaseSensitive(grid, "dims");
        for (int k = 0; k < 3; k++)
            centre[k] = cJSON_GetArrayItem(pos, k)->valuedouble +
                0.5 * (cJSON_IsNumber(cell) ? cell->valuedouble : 0) *
                    (cJSON_GetArraySize(dims) == 3 ? cJSON_GetArrayItem(dims, k)->valuedouble - 1 : 0);
    }
    cJSON_Delete(wel);
}

/* The updates, o->interval apart (until the count or a signal): each a light.set of the
 * probe timed to its ok and to this connection's first lightmap frame of its revision.
 * CTL_EXIT_OK, or CTL_EXIT_REFUSED / CTL_EXIT_CONN (printed). */
static int latency_updates(lc_client *c, const latency_opts *o, const double centre[3], latency_samples *ls) {
    char err[512], req[512];
    lc_client_frame f;
    double next = mono_ms();
    for (int i = 0; i < (int)o->count && !stream_stop; i++) {
        while (mono_ms() < next) lc_client_poll(c, (int)fmax(1, next - mono_ms()));
        next += o->interval * 1000.0;
        /* alternate the intensity so every update changes the lightmap */
        snprintf(req, sizeof req,
                 "{\"type\":\"light.set\",\"light\":{\"id\":\"%s\",\"type\":\"point\",\"position\":[%.6g,%.6g,%.6g],"
                 "\"color\":[1,1,1],\"intensity\":%g}}",
                 o->light, centre[0], centre[1], centre[2], (i % 2) ? 0.5 : 1.0);
        double t0 = mono_ms();
        char *reply = NULL;
        int r = lc_client_request(c, req, &reply, 0, err, sizeof err);
        double t_ok = mono_ms();
        if (r != 0) {
            if (r == 1) ctl_print_server_error(reply);
            else fprintf(stderr, "lucentctl: %s\n", err);
            free(reply);
            return r == 1 ? CTL_EXIT_REFUSED : CTL_EXIT_CONN;
        }
        cJSON *rj = cJSON_Parse(reply);
        free(reply);
        const cJSON *rev = cJSON_GetObjectItemCaseSensitive(rj, "revision");
        uint64_t want = cJSON_IsNumber(rev) ? (uint64_t)rev->valuedouble : 0;
        cJSON_Delete(rj);
        ls->t_send[ls->n_ack] = t0;
        ls->want_rev[ls->n_ack] = want;
        ls->ack[ls->n_ack++] = t_ok - t0;
        if (lc_client_wait_frame(c, LC_CLIENT_LIGHTMAP, want, 0, CTL_TIMEOUT_MS, &f, err, sizeof err) == 0)
            ls->frame[ls->n_frame++] = mono_ms() - t0;
        else fprintf(stderr, "lucentctl: no frame for revision %llu: %s\n", (unsigned long long)want, err);
    }
    return CTL_EXIT_OK;
}

/* The viewers' frames of the last update, then the viewers stopped and joined and each one's
 * delay for every update added to the frame samples. */
static void latency_collect_viewers(lc_client *c, latency_viewer *viewers, int n_viewers, atomic_int *stop,
                                    latency_samples *ls) {
    lc_client_poll(c, 1000);
    atomic_store(stop, 1);
    int missing = 0;
    for (int k = 0; k < n_viewers; k++) {
        if (!viewers[k].started) continue;
        pthread_join(viewers[k].thread, NULL);
        viewers[k].started = 0;
        for (int i = 0; i < ls->n_ack; i++) {
            double d = viewers[k].ok ? latency_viewer_delay(&viewers[k], ls->want_rev[i], ls->t_send[i]) : -1;
            if (d >= 0) ls->frame[ls->n_frame++] = d;
            else missing++;
        }
    }
    if (missing) fprintf(stderr, "lucentctl: %d update/viewer pairs saw no frame\n", missing);
}

/* The table, or with --json one object per measure. */
static void latency_print(latency_samples *ls) {
    cJSON *json = ctl_json ? cJSON_CreateObject() : NULL;
    if (!json) printf("%-16s %5s %9s %9s %9s %9s %9s\n", "ms", "n", "min", "p50", "p90", "p99", "max");
    latency_report("ping", ls->ping, ls->n_ping, json);
    latency_report("update_to_ok", ls->ack, ls->n_ack, json);
    latency_report("update_to_frame", ls->frame, ls->n_frame, json);
    if (json) {
        char *t = cJSON_PrintUnformatted(json);
        printf("%s\n", t ? t : "{}");
        free(t);
        cJSON_Delete(json);
    }
}

int ctl_cmd_latency(int argc, char **argv) {
    if (ctl_wants_help(argc, argv)) {
        usage_latency(stdout);
        return CTL_EXIT_OK;
    }
    latency_opts o;
    int rc = latency_parse(argc, argv, &o);
    if (rc != CTL_EXIT_OK) return rc;
    int n = (int)o.count, n_viewers = (int)o.clients - 1;
    latency_samples ls = {0};
    ls.ping = calloc((size_t)n, sizeof *ls.ping);
    ls.ack = calloc((size_t)n, sizeof *ls.ack);
    ls.frame = calloc((size_t)n * (size_t)o.clients, sizeof *ls.frame);
    ls.t_send = calloc((size_t)n, sizeof *ls.t_send);
    ls.want_rev = calloc((size_t)n, sizeof *ls.want_rev);
    latency_viewer *viewers = calloc((size_t)(n_viewers > 0 ? n_viewers : 1), sizeof *viewers);
    atomic_int viewers_stop = 0;
    char err[512], req[512];
    lc_client *c = NULL;
    if (!ls.ping || !ls.ack || !ls.frame || !ls.t_send || !ls.want_rev || !viewers) {
        fprintf(stderr, "lucentctl: out of memory\n");
        rc = CTL_EXIT_CONN;
        goto out;
    }
    c = ctl_connect(NULL, &rc);
    if (!c) goto out;
    if ((rc = latency_pings(c, n, &ls)) != CTL_EXIT_OK) goto out;
    int r = lc_client_subscribe(c, LC_CLIENT_LIGHTMAP, 0, 0, err, sizeof err);
    lc_client_frame f;
    if (r == 0) r = lc_client_wait_frame(c, LC_CLIENT_LIGHTMAP, 0, 0, CTL_TIMEOUT_MS * 2, &f, err, sizeof err);
    if (r != 0) {
        fprintf(stderr, "lucentctl: subscribe: %s\n", err);
        rc = r == 1 ? CTL_EXIT_REFUSED : CTL_EXIT_CONN;
        goto out;
    }
    for (int k = 0; k < n_viewers; k++) {
        viewers[k].stop = &viewers_stop;
        viewers[k].started = pthread_create(&viewers[k].thread, NULL, latency_viewer_main, &viewers[k]) == 0;
    }
    for (int k = 0; k < n_viewers; k++) /* all subscribed (or failed) before the first update */
        while (viewers[k].started && !atomic_load(&viewers[k].ready)) lc_client_poll(c, 5);
    double centre[3];
    latency_probe_position(c, centre);
    if ((rc = latency_updates(c, &o, centre, &ls)) != CTL_EXIT_OK) goto out;
    if (n_viewers > 0) latency_collect_viewers(c, viewers, n_viewers, &viewers_stop, &ls);
    snprintf(req, sizeof req, "{\"type\":\"light.remove\",\"light_id\":\"%s\"}", o.light);
    lc_client_request(c, req, NULL, 0, err, sizeof err);
    latency_print(&ls);
    if (ls.n_frame < ls.n_ack * (int)o.clients) rc = CTL_EXIT_CONN;
out:
    atomic_store(&viewers_stop, 1);
    for (int k = 0; viewers && k < n_viewers; k++) {
        if (viewers[k].started) pthread_join(viewers[k].thread, NULL);
        free(viewers[k].rev);
        free(viewers[k].at);
    }
    lc_client_close(c);
    free(viewers);
    free(ls.want_rev);
    free(ls.t_send);
    free(ls.ping);
    free(ls.ack);
    free(ls.frame);
    return rc;
}
