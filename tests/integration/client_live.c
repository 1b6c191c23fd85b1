/* liblucent-client against a real lucentd (driven by client_live.sh):
 *   client_live basic URL       two clients: requests, subscriptions in every encoding,
 *                               a change reaches the subscriber as a frame of that revision,
 *                               `changed` reaches the other client's callback, deltas keep
 *                               the copy equal to a fresh keyframe, unsubscribe stops frames
 *   client_live refused URL TOK hello with a wrong token fails with "server error unauthorized"
 *   client_live tls URL         wss:// with a self-signed certificate (insecure) works, and
 *                               fails without --insecure
 *   client_live reconnect URL   prints READY once subscribed; the script then restarts the
 *                               daemon; the client must reconnect, resubscribe and receive a
 *                               new keyframe within 30 s
 * Exit 0 = pass. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "lucent_client.h"

static int failures = 0;
#define EXPECT(cond, ...)                                                   \
    do {                                                                    \
        if (!(cond)) {                                                      \
            failures++;                                                     \
            fprintf(stderr, "FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                   \
            fputc('\n', stderr);                                            \
        }                                                                   \
    } while (0)

typedef struct counters {
    int frames, changed, connected, reconnecting;
    uint64_t last_revision;
    int after_reconnect; /* frames since the last CONNECTED event */
    int first_key;       /* that first frame was a keyframe with sequence 1 */
} counters;

static void on_frame(lc_client *c, const lc_client_frame *f, void *user) {
    (void)c;
    counters *n = user;
    n->frames++;
    n->last_revision = f->revision;
    if (n->after_reconnect++ == 0) n->first_key = f->keyframe && f->sequence == 1;
}

static void on_message(lc_client *c, const char *json, void *user) {
    (void)c;
    counters *n = user;
    if (strstr(json, "\"changed\"")) n->changed++;
}

static void on_connection(lc_client *c, int event, const char *reason, void *user) {
    (void)c;
    counters *n = user;
    fprintf(stderr, "connection event %d: %s\n", event, reason);
    if (event == LC_CLIENT_CONNECTED) {
        n->connected++;
        n->after_reconnect = 0;
    }
    if (event == LC_CLIENT_RECONNECTING) n->reconnecting++;
}

static double now_ms(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec * 1e3 + (double)t.tv_nsec / 1e6;
}

/* Services `c` until no frame has come for quiet_ms (the idle refinement passes of the last
 * change are over): 0, or -1 when frames still come after limit_ms. */
static int settle(lc_client *c, const counters *n, double quiet_ms, double limit_ms) {
    double start = now_ms(), last = start;
    int seen = n->frames;
    while (now_ms() - start < limit_ms) {
        lc_client_poll(c, 20);
        if (n->frames != seen) {
            seen = n->frames;
            last = now_ms();
        } else if (now_ms() - last >= quiet_ms) {
            return 0;
        }
    }
    return -1;
}

static uint64_t revision_of(const char *reply) {
    const char *p = reply ? strstr(reply, "\"revision\":") : NULL;
    return p ? strtoull(p + 11, NULL, 10) : 0;
}

static int set_light(lc_client *c, double x, double intensity, uint64_t *rev) {
    char req[256], err[256], *reply = NULL;
    snprintf(req, sizeof req,
             "{\"type\":\"light.set\",\"light\":{\"id\":\"live\",\"type\":\"point\",\"position\":[%g,0.3,0.0],"
             "\"intensity\":%g}}",
             x, intensity);
    int r = lc_client_request(c, req, &reply, 5000, err, sizeof err);
    if (rev) *rev = revision_of(reply);
    if (r != 0) fprintf(stderr, "light.set: %s (%s)\n", err, reply ? reply : "");
    free(reply);
    return r;
}

static int test_basic(const char *url) {
    char err[512];
    counters a = {0}, b = {0};
    lc_client *ctl = lc_client_connect(url, "", "live-controller", 5000, err, sizeof err);
    EXPECT(ctl != NULL, "connect: %s", err);
    lc_client_options o;
    lc_client_options_init(&o);
    o.url = url;
    o.name = "live-viewer";
    lc_client *view = lc_client_open(&o, err, sizeof err);
    EXPECT(view != NULL, "open: %s", err);
    if (!ctl || !view) return 1;
    EXPECT(strstr(lc_client_welcome(ctl), "\"welcome\"") != NULL, "welcome text");
    EXPECT(lc_client_connected(view), "connected");
    lc_client_callbacks cb = {on_frame, on_message, on_connection, &b};
    lc_client_set_callbacks(view, &cb);
    lc_client_callbacks cba = {on_frame, on_message, on_connection, &a};
    lc_client_set_callbacks(ctl, &cba);

    /* requests: ok/error return codes, reply text */
    char *reply = NULL;
    EXPECT(lc_client_request(ctl, "{\"type\":\"ping\",\"t\":7}", &reply, 5000, err, sizeof err) == 0, "ping: %s", err);
    EXPECT(reply && strstr(reply, "\"pong\""), "pong reply: %s", reply ? reply : "(null)");
    free(reply);
    reply = NULL;
    EXPECT(lc_client_request(ctl, "{\"type\":\"light.remove\",\"light_id\":\"nope\"}", &reply, 5000, err, sizeof err) ==
               1,
           "unknown id refused");
    EXPECT(reply && strstr(reply, "unknown_id"), "error reply: %s", reply ? reply : "(null)");
    free(reply);

    /* every lightmap encoding decodes to nearly the same image */
    const int encs[3] = {LC_CLIENT_F32, LC_CLIENT_RGBA16F, LC_CLIENT_RGB9E5};
    uint64_t rev = 0;
    EXPECT(set_light(ctl, 0.1, 2.0, &rev) == 0, "light set");
    float *ref = NULL;
    size_t nref = 0;
    for (int e = 0; e < 3; e++) {
        lc_client_frame f;
        EXPECT(lc_client_subscribe(view, LC_CLIENT_LIGHTMAP, encs[e], 0, err, sizeof err) == 0, "subscribe %d: %s",
               encs[e], err);
        /* idle refinement may send further frames of the same revision: take a fresh keyframe */
        int ok = lc_client_wait_frame(view, LC_CLIENT_LIGHTMAP, rev, 1, 10000, &f, err, sizeof err) == 0;
        EXPECT(ok, "frame enc %d: %s", encs[e], err);
        if (!ok) continue;
        EXPECT(f.encoding == encs[e] && f.revision >= rev, "frame header enc %d rev %llu", f.encoding,
               (unsigned long long)f.revision);
        /* let refinement settle, then snapshot to compare like with like */
        EXPECT(settle(view, &b, 500, 20000) == 0, "enc %d: frames still coming 20 s after the change", encs[e]);
        EXPECT(lc_client_request(view, "{\"type\":\"snapshot\"}", NULL, 5000, err, sizeof err) == 0, "snapshot");
        ok = lc_client_wait_frame(view, LC_CLIENT_LIGHTMAP, rev, 1, 10000, &f, err, sizeof err) == 0;
        EXPECT(ok && f.keyframe, "snapshot keyframe: %s", err);
        if (!ok) continue;
        if (!ref) {
            nref = f.value_count;
            ref = malloc(nref * sizeof *ref);
            memcpy(ref, f.values, nref * sizeof *ref);
            double sum = 0;
            for (size_t i = 0; i < nref; i++) sum += ref[i];
            EXPECT(sum > 0, "lightmap not black");
        } else {
            EXPECT(f.value_count == nref, "same size");
            double worst = 0;
            for (size_t i = 0; i < nref && i < f.value_count; i++) {
                double d = fabs(f.values[i] - ref[i]) / fmax(fabs(ref[i]), 1e-2);
                if (d > worst) worst = d;
            }
            EXPECT(worst < 0.02, "encoding %d differs from f32 by %g", encs[e], worst);
        }
    }
    /* a change reaches the subscriber; deltas keep the copy equal to a keyframe */
    EXPECT(lc_client_subscribe(view, LC_CLIENT_LIGHTMAP, LC_CLIENT_F32, 0, err, sizeof err) == 0, "resubscribe f32");
    int changed0 = b.changed;
    for (int i = 0; i < 6; i++) {
        EXPECT(set_light(ctl, 0.1 + 0.01 * i, 2.0, &rev) == 0, "move %d", i);
        lc_client_frame f;
        EXPECT(lc_client_wait_frame(view, LC_CLIENT_LIGHTMAP, rev, 0, 10000, &f, err, sizeof err) == 0,
               "frame for revision %llu: %s", (unsigned long long)rev, err);
    }
    /* a change far below the delta threshold: a delta frame (with no tiles or few) */
    EXPECT(settle(view, &b, 500, 20000) == 0, "frames still coming 20 s after the moves");
    EXPECT(set_light(ctl, 0.15, 2.002, &rev) == 0, "tiny change");
    lc_client_frame tiny;
    EXPECT(lc_client_wait_frame(view, LC_CLIENT_LIGHTMAP, rev, 0, 10000, &tiny, err, sizeof err) == 0, "tiny frame: %s",
           err);
    /* `changed` goes out with each ok, before that change's frame: all 7 are here by now */
    for (double t0 = now_ms(); b.changed < changed0 + 7 && now_ms() - t0 < 5000;) lc_client_poll(view, 20);
    EXPECT(b.changed >= changed0 + 7, "changed callbacks %d -> %d", changed0, b.changed);
    lc_client_stats st;
    lc_client_get_stats(view, &st);
    EXPECT(st.deltas > 0 && st.bad_frames == 0, "deltas %lu bad %lu", st.deltas, st.bad_frames);
    EXPECT(settle(view, &b, 500, 20000) == 0, "frames still coming 20 s after the tiny change"); /* refinement over */
    lc_client_frame f;
    EXPECT(lc_client_latest_frame(view, LC_CLIENT_LIGHTMAP, &f) == 0, "latest frame");
    float *copy = malloc(f.value_count * sizeof *copy);
    size_t ncopy = f.value_count;
    memcpy(copy, f.values, ncopy * sizeof *copy);
    uint64_t crev = f.revision;
    /* a fresh client's keyframe must equal the delta-built copy within the delta threshold */
    lc_client *fresh = lc_client_connect(url, "", "live-fresh", 5000, err, sizeof err);
    EXPECT(fresh && lc_client_subscribe(fresh, LC_CLIENT_LIGHTMAP, LC_CLIENT_F32, 0, err, sizeof err) == 0,
           "fresh subscribe");
    if (fresh && lc_client_wait_frame(fresh, LC_CLIENT_LIGHTMAP, crev, 0, 10000, &f, err, sizeof err) == 0) {
        double worst = 0, maxv = 0;
        for (size_t i = 0; i < ncopy; i++) maxv = fmax(maxv, fabs(f.values[i]));
        for (size_t i = 0; i < ncopy && i < f.value_count; i++) worst = fmax(worst, fabs(f.values[i] - copy[i]));
        EXPECT(f.revision == crev, "same revision %llu %llu", (unsigned long long)f.revision, (unsigned long long)crev);
        EXPECT(worst <= 0.02 * maxv, "delta-built copy off by %g (max %g)", worst, maxv);
    }
    lc_client_close(fresh);
    free(copy);
    /* SH streams */
    EXPECT(lc_client_subscribe(view, LC_CLIENT_SHGRID, LC_CLIENT_F32, 0, err, sizeof err) == 0, "shgrid: %s", err);
    EXPECT(lc_client_wait_frame(view, LC_CLIENT_SHGRID, rev, 0, 10000, &f, err, sizeof err) == 0, "shgrid frame: %s",
           err);
    EXPECT(f.value_count == (size_t)f.width * f.height * f.depth * 27 && f.width > 0, "shgrid size");
    float e[3];
    size_t mid = (size_t)f.width * f.height * f.depth / 2;
    const float up[3] = {0, 1, 0};
    lc_sh9_irradiance(f.values + 27 * mid, up, e);
    EXPECT(isfinite(e[0]) && e[0] >= 0, "grid irradiance %g", e[0]);
    EXPECT(lc_client_subscribe(view, LC_CLIENT_OBJECTS, LC_CLIENT_RGBA16F, 0, err, sizeof err) == 0, "objects: %s",
           err);
    EXPECT(lc_client_wait_frame(view, LC_CLIENT_OBJECTS, 0, 0, 10000, &f, err, sizeof err) == 0, "objects frame: %s",
           err);
    /* unsubscribe stops frames */
    /* unsubscribe returns with its ok: every lightmap frame sent before it has been taken */
    EXPECT(lc_client_unsubscribe(view, LC_CLIENT_LIGHTMAP, err, sizeof err) == 0, "unsubscribe");
    int frames_before = b.frames;
    uint64_t last_lm = 0;
    if (lc_client_latest_frame(view, LC_CLIENT_LIGHTMAP, &f) == 0) last_lm = f.sequence;
    EXPECT(set_light(ctl, 0.2, 1.0, &rev) == 0, "move after unsubscribe");
    /* wait for the move's shgrid frame (a fixed 500 ms poll raced the relight under load), then
     * no lightmap frame may have come with it */
    EXPECT(lc_client_wait_frame(view, LC_CLIENT_SHGRID, rev, 0, 10000, &f, err, sizeof err) == 0,
           "shgrid frame of the move: %s", err);
    EXPECT(lc_client_latest_frame(view, LC_CLIENT_LIGHTMAP, &f) == 0 && f.sequence == last_lm,
           "no lightmap frames after unsubscribe");
    EXPECT(b.frames > frames_before, "shgrid/objects frames still arrive (%d -> %d)", frames_before, b.frames);
    lc_client_close(ctl);
    lc_client_close(view);
    free(ref);
    return failures ? 1 : 0;
}

static int test_refused(const char *url, const char *token) {
    char err[512];
    lc_client *c = lc_client_connect(url, token, "bad-token", 5000, err, sizeof err);
    EXPECT(c == NULL, "connected with a wrong token");
    EXPECT(strncmp(err, "server error unauthorized", 25) == 0, "err: %s", err);
    lc_client_close(c);
    c = lc_client_connect("ws://127.0.0.1:1/", "", "nobody", 3000, err, sizeof err);
    EXPECT(c == NULL && strstr(err, "server error") == NULL, "no server: %s", err);
    c = lc_client_connect("http://x/", "", "x", 1000, err, sizeof err);
    EXPECT(c == NULL && strstr(err, "unsupported URL"), "bad scheme: %s", err);
    return failures ? 1 : 0;
}

static int test_tls(const char *url) {
    char err[512];
    lc_client_options o;
    lc_client_options_init(&o);
    o.url = url;
    lc_client *c = lc_client_open(&o, err, sizeof err);
    EXPECT(c == NULL, "self-signed certificate accepted without insecure");
    fprintf(stderr, "(expected) %s\n", err);
    o.insecure = 1;
    c = lc_client_open(&o, err, sizeof err);
    EXPECT(c != NULL, "wss insecure: %s", err);
    if (c) {
        lc_client_frame f;
        EXPECT(lc_client_subscribe(c, LC_CLIENT_LIGHTMAP, 0, 0, err, sizeof err) == 0, "wss subscribe: %s", err);
        EXPECT(lc_client_wait_frame(c, LC_CLIENT_LIGHTMAP, 0, 0, 10000, &f, err, sizeof err) == 0 &&
                   f.encoding == LC_CLIENT_RGB9E5,
               "wss keyframe: %s", err);
    }
    lc_client_close(c);
    return failures ? 1 : 0;
}

static int test_reconnect(const char *url) {
    char err[512];
    counters n = {0};
    lc_client_options o;
    lc_client_options_init(&o);
    o.url = url;
    o.reconnect = 1;
    o.backoff_min_ms = 50;
    o.backoff_max_ms = 400;
    lc_client *c = lc_client_open(&o, err, sizeof err);
    EXPECT(c != NULL, "open: %s", err);
    if (!c) return 1;
    lc_client_callbacks cb = {on_frame, on_message, on_connection, &n};
    lc_client_set_callbacks(c, &cb);
    lc_client_frame f;
    EXPECT(lc_client_subscribe(c, LC_CLIENT_LIGHTMAP, LC_CLIENT_F32, 0, err, sizeof err) == 0, "subscribe");
    EXPECT(lc_client_wait_frame(c, LC_CLIENT_LIGHTMAP, 0, 0, 10000, &f, err, sizeof err) == 0, "first frame");
    int frames = n.frames;
    printf("READY\n");
    fflush(stdout);
    /* the script restarts the daemon now */
    for (int i = 0; i < 600 && !(n.reconnecting && n.connected); i++) lc_client_poll(c, 50);
    EXPECT(n.reconnecting >= 1 && n.connected >= 1, "reconnecting %d connected %d", n.reconnecting, n.connected);
    /* the copy was reset at the new welcome: the first frame is the new connection's keyframe */
    EXPECT(lc_client_wait_frame(c, LC_CLIENT_LIGHTMAP, 0, 0, 10000, &f, err, sizeof err) == 0,
           "frame after reconnect: %s", err);
    EXPECT(n.after_reconnect > 0 && n.first_key, "first frame after reconnect: keyframe with sequence 1");
    EXPECT(n.frames > frames, "frames after reconnect");
    /* requests work on the new connection */
    EXPECT(lc_client_request(c, "{\"type\":\"state.get\"}", NULL, 5000, err, sizeof err) == 0, "state after reconnect");
    lc_client_stats st;
    lc_client_get_stats(c, &st);
    EXPECT(st.reconnects == 1, "reconnects %lu", st.reconnects);
    lc_client_close(c);
    return failures ? 1 : 0;
}

int main(int argc, char **argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: client_live basic|refused|tls|reconnect URL [TOKEN]\n");
        return 2;
    }
    int r;
    if (!strcmp(argv[1], "basic")) r = test_basic(argv[2]);
    else if (!strcmp(argv[1], "refused")) r = test_refused(argv[2], argc > 3 ? argv[3] : "wrong");
    else if (!strcmp(argv[1], "tls")) r = test_tls(argv[2]);
    else if (!strcmp(argv[1], "reconnect")) r = test_reconnect(argv[2]);
    else return 2;
    fprintf(stderr, "client_live %s: %s\n", argv[1], r ? "FAILED" : "ok");
    return r;
}
