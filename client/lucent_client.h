/* liblucent-client: a C client for lucent/1 (protocol/PROTOCOL.md) over WebSockets.
 *
 * What it does: connects over ws:// or wss:// with subprotocol "lucent.v1", sends `hello`,
 * waits for `welcome`; sends requests and matches replies by id; receives `changed` events
 * and binary data frames, checks each frame's CRC and layout, decodes RGB9E5 / RGBA16F / f32
 * and applies keyframes and tile deltas onto the client's own copy of every subscribed
 * stream; on a sequence gap or a bad frame it asks the server for a fresh keyframe
 * (`snapshot`). Optionally reconnects with exponential back-off, then re-sends `hello` and
 * every subscription.
 *
 * Threads: an lc_client is single-threaded. Every call runs on the caller's thread and all
 * network work happens inside the blocking calls (connect, request, subscribe, poll,
 * wait_frame), which is also where callbacks run. Callbacks must not call back into the
 * same lc_client except lc_client_frame_*() getters and lc_client_welcome(); copy what you
 * need and act after the call returns. Different lc_clients may live on different threads.
 *
 * Ownership: strings and frames passed to callbacks are borrowed for the duration of the
 * callback. Pointers returned by getters stay valid until the next call that services the
 * connection (request, subscribe, poll, wait_frame, close). Text returned through a
 * `char **` out-parameter is malloc'd: the caller frees it with free().
 *
 * Errors: functions return 0 on success, 1 when the server refused (an `error` reply; the
 * reply text says which code and field), -1 on connection failure, timeout or bad
 * arguments; `err` (may be NULL) receives a one-line reason.
 *
 * MR sessions (PROTOCOL.md §8, lucentctl's ctl_mr.c does all of it): open with
 * options.capabilities = "mr" and check the welcome's "capabilities"; lc_client_request an
 * `mr.begin`; encode each RGB-D frame with lc_upload_encode (lucent_upload.h) and queue it with
 * lc_client_send_binary, keeping at most 2 unacknowledged; `mr.ack` and the frames' errors
 * (no id) arrive through on_message; the per-point VPLs through LC_CLIENT_MR_VPL frames. */
#ifndef LUCENT_CLIENT_H
#define LUCENT_CLIENT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct lc_client lc_client;

/* Streams and encodings, numbered as in the frame header (PROTOCOL.md §6.1). mr.vpl (§8.7)
 * carries an MR session's lights; the server sends it only with the `mr` capability. */
enum { LC_CLIENT_LIGHTMAP = 1, LC_CLIENT_SHGRID = 2, LC_CLIENT_OBJECTS = 3, LC_CLIENT_MR_VPL = 4 };
enum { LC_CLIENT_RGB9E5 = 1, LC_CLIENT_RGBA16F = 2, LC_CLIENT_F32 = 3 };
/* OR'd into a lightmap subscription's encoding: delta frames as compressed residuals
 * (PROTOCOL.md §6.2.1; smaller for small changes, applied to the view's encoded copy). */
enum { LC_CLIENT_RESIDUAL = 0x100 };

/* Connection events for the on_connection callback. */
enum { LC_CLIENT_DISCONNECTED = 0, LC_CLIENT_CONNECTED = 1, LC_CLIENT_RECONNECTING = 2 };

typedef struct lc_client_options {
    const char *url;          /* ws://host[:port][/path] or wss://…; required */
    const char *token;        /* access token ("" = none) */
    const char *name;         /* client name shown in `changed` (default "liblucent-client") */
    int timeout_ms;           /* connect / request timeout (default 5000) */
    int insecure;             /* wss: accept self-signed certificates and any host name */
    const char *ca_file;      /* wss: PEM CA bundle (NULL = system store) */
    int reconnect;            /* 1: on connection loss reconnect with back-off and resubscribe */
    int backoff_min_ms;       /* first retry delay (default 100); doubles up to backoff_max_ms */
    int backoff_max_ms;       /* default 5000 */
    int max_retries;          /* consecutive failed attempts before giving up, 0 = forever */
    const char *capabilities; /* hello's capabilities, comma-separated ("mr"; NULL = none, §8.1) */
} lc_client_options;

/* Fills defaults (everything zero/NULL except the defaults above). */
void lc_client_options_init(lc_client_options *o);

/* One received data frame, after it was applied to the client's copy of its stream.
 * `values` is the whole current stream content as float32, NOT just this frame:
 *   lightmap: width*height texels x 3 (RGB irradiance, W/m^2), row 0 = top;
 *   shgrid:   width*height*depth samples (x fastest) x 27 (9 SH coefficients x RGB);
 *   objects:  width objects x 27, in the order of `object_ids` (sorted by id);
 *   mr.vpl:   height records x 12 (I_d rgb, l_d xyz, I_s rgb, l_s xyz; PROTOCOL.md §8.7):
 *             object_points[i] records of object_ids[i], object after object (width).
 * For f32 frames the values are bit-identical to the server's. For a delta frame, `tiles`
 * lists the tiles it replaced (tile_count of them); for keyframes tile_count is 0. */
typedef struct lc_client_frame {
    int stream, encoding, keyframe;
    int residual;  /* a residual delta (PROTOCOL.md §6.2.1) */
    int pass;      /* refinement pass of the revision (0 = its first solution; §6.1) */
    int converged; /* 1: the server plans no further pass of this revision */
    uint64_t revision, sequence;
    uint64_t server_time_us; /* server clock when the frame was built, µs since the epoch */
    uint64_t client_time_us; /* local clock (CLOCK_REALTIME) when the frame was complete */
    uint32_t width, height, depth, tile_size;
    uint32_t tile_count;
    const uint32_t *tiles;
    const float *values;
    size_t value_count;
    const char *const *object_ids; /* objects and mr.vpl streams: width ids; NULL otherwise */
    const uint32_t *object_points; /* mr.vpl: width point counts; NULL otherwise */
    const uint8_t *raw;            /* the frame as received (header, tile table, payload) */
    size_t raw_len;
} lc_client_frame;

typedef struct lc_client_callbacks {
    /* A frame was received and applied. */
    void (*on_frame)(lc_client *c, const lc_client_frame *f, void *user);
    /* Any text message that is not the reply to a pending request: `changed` broadcasts,
     * unsolicited errors (e.g. a refused frame resync). */
    void (*on_message)(lc_client *c, const char *json, void *user);
    /* Connected (after welcome and resubscription), disconnected, or waiting to reconnect;
     * reason is a short human text. */
    void (*on_connection)(lc_client *c, int event, const char *reason, void *user);
    void *user;
} lc_client_callbacks;

/* Connects and completes hello/welcome. Returns NULL with err set on failure; when the
 * server refused the hello (e.g. unauthorized), err starts with "server error ". */
lc_client *lc_client_open(const lc_client_options *o, char *err, size_t errlen);

/* Shorthand for lc_client_open with defaults (no reconnect). */
lc_client *lc_client_connect(const char *url, const char *token, const char *name, int timeout_ms, char *err,
                             size_t errlen);

/* Installs callbacks (copied). May be called at any time; NULL clears them. */
void lc_client_set_callbacks(lc_client *c, const lc_client_callbacks *cb);

/* Sends one JSON request and waits for its reply, matched on "id" (an integer id is added
 * when the request has none). *reply_json receives the reply text (malloc'd; may be NULL
 * when the caller does not want it). Frames and other messages received meanwhile go to
 * the callbacks. Returns 0 (ok/state/pong/welcome), 1 (error reply), -1 (connection/timeout).
 * A text that is not a JSON object is sent as is and matched with the next reply. */
int lc_client_request(lc_client *c, const char *json_request, char **reply_json, int timeout_ms, char *err,
                      size_t errlen);

/* Queues one binary message (an MR upload frame, PROTOCOL.md §8.4; lc_upload_encode makes
 * one) and returns; it goes out in the next servicing call. The data is copied. Returns 0,
 * or -1 when not connected or out of memory. Replies (mr.ack, error) reach on_message. */
int lc_client_send_binary(lc_client *c, const void *data, size_t len, char *err, size_t errlen);

/* Subscribes to a stream (LC_CLIENT_LIGHTMAP…) in an encoding (LC_CLIENT_RGB9E5…; 0 = the
 * stream's default; lightmap: | LC_CLIENT_RESIDUAL for residual deltas) with an optional
 * maximum rate in frames/s (0 = unlimited), and waits for the server's ok. The subscription
 * is remembered and renewed after a reconnect. */
int lc_client_subscribe(lc_client *c, int stream, int encoding, double max_rate, char *err, size_t errlen);
int lc_client_unsubscribe(lc_client *c, int stream, char *err, size_t errlen);

/* Services the connection for up to timeout_ms (0 = one pass of the event loop, which may
 * wait up to its 20 ms tick), running callbacks.
 * Returns 0, or -1 when the connection is closed for good (no reconnect, or retries spent). */
int lc_client_poll(lc_client *c, int timeout_ms);

/* Waits until the stream holds a frame with revision >= min_revision received after this
 * call started (fresh_only) or at any time. Returns 0 and the latest frame in *out (pointers
 * valid until the next servicing call), or -1 on timeout / closed connection (err says). */
int lc_client_wait_frame(lc_client *c, int stream, uint64_t min_revision, int fresh_only, int timeout_ms,
                         lc_client_frame *out, char *err, size_t errlen);

/* Latest applied frame of a stream (0), or -1 when none has arrived yet. */
int lc_client_latest_frame(const lc_client *c, int stream, lc_client_frame *out);

/* The welcome message text of the current connection. */
const char *lc_client_welcome(const lc_client *c);
/* 1 while connected (welcome received). */
int lc_client_connected(const lc_client *c);
/* Counters since lc_client_open. */
typedef struct lc_client_stats {
    unsigned long frames, keyframes, deltas, bad_frames, resyncs, reconnects;
    unsigned long long bytes;
} lc_client_stats;
void lc_client_get_stats(const lc_client *c, lc_client_stats *out);

/* Closes the connection and frees everything. NULL is allowed. */
void lc_client_close(lc_client *c);

/* --- frames without a connection (tests, recorded streams, other transports) ----------- */

/* A client-side copy of one stream, built from frames. Ownership: the caller creates and
 * releases it; frames are read, not kept (except the applied values). */
typedef struct lc_client_view lc_client_view;
lc_client_view *lc_client_view_create(void);
void lc_client_view_release(lc_client_view *v);
/* Resets to "no keyframe yet" (after a reconnect or resubscribe). */
void lc_client_view_reset(lc_client_view *v);
/* Checks (magic, version, CRC, lengths, tiles) and applies one frame. Returns 0 and fills
 * *out (pointers into the view / data, valid until the next apply or release); -1 for a
 * malformed frame (the view is unchanged); -2 when the frame is valid but cannot be applied
 * (a delta without a preceding keyframe, a sequence gap, a stream/size change in a delta):
 * the caller should request a keyframe. err gets the reason. */
int lc_client_view_apply(lc_client_view *v, const uint8_t *frame, size_t len, lc_client_frame *out, char *err,
                         size_t errlen);

/* --- SH helpers (PROTOCOL.md §2.3) ---------------------------------------------------- */

/* Irradiance E(n) (W/m^2, RGB) from cosine-convolved L2 SH, 27 values interleaved per
 * coefficient (c0.r c0.g c0.b c1.r …) as the shgrid and objects streams carry them. n need
 * not be normalised (it is). Negative results (ringing) are clamped to 0. */
void lc_sh9_irradiance(const float sh[27], const float normal[3], float rgb_out[3]);
/* Interleaved <-> planar (all red, then green, then blue). Same basis and scale; only the
 * order changes (for Unity and ARCore use lc_sh9_to_unity / lc_sh9_to_arcore, which also
 * change basis, scale and axes). in and out must not overlap. */
void lc_sh9_to_planar(const float interleaved[27], float planar[27]);
void lc_sh9_to_interleaved(const float planar[27], float interleaved[27]);
/* Cosine-convolved irradiance SH -> radiance SH (divides band l by pi, 2pi/3, pi/4), same
 * basis, order and axes. */
void lc_sh9_irradiance_to_radiance(const float irradiance[27], float radiance[27]);

/* Engine layouts. Each takes the 27 values of the shgrid / objects streams (cosine-convolved
 * irradiance, interleaved, glTF axes: right-handed, +Y up) and writes what the platform's own
 * SH evaluation takes, so that it gives the irradiance lc_sh9_irradiance() gives at the same
 * physical normal (times 1/pi where the platform folds the Lambert 1/pi into its SH, as noted).
 * tests/unit/client/test_sh_layouts.c checks each one against the platform's published
 * formula. in and out must not overlap. Grid sample positions map by the same axis change. */

/* Unity: `SphericalHarmonicsL2` (`LightProbes`, `RenderSettings.ambientProbe`), planar:
 * `sh[c, i] = unity[9 * c + i]`. Matches Unity's premultiplied convention (HDRP
 * `SphericalHarmonicMath.UndoCosineRescaling` / `PremultiplyCoefficients`: each coefficient
 * carries A_l, its basis constant and 1/pi) and its evaluation, `ShadeSH9` =
 * `SHEvalLinearL0L1` + `SHEvalLinearL2` over `unity_SHAr`..`unity_SHC` packed as in HDRP
 * `SphericalHarmonicMath.PackCoefficients`, which returns E/pi (Unity multiplies it by the
 * albedo). Handedness: Unity is left-handed, +Y up, +Z forward; glTF importers (UnityGLTF
 * `CoordinateSpaceConversionScale` (-1, 1, 1), glTFast) map glTF (x, y, z) to Unity
 * (-x, y, z), so the coefficients odd in x (x, xy, xz) change sign. */
void lc_sh9_to_unity(const float irradiance[27], float unity[27]);
/* ARCore: the convention of `LightEstimate.getEnvironmentalHdrAmbientSphericalHarmonics()`
 * (`ArLightEstimate_getEnvironmentalHdrAmbientSphericalHarmonics`), interleaved: radiance SH
 * (band l divided by A_l) in a basis whose y, x, yz, xz functions carry a minus sign
 * (coefficients 1, 3, 5, 7 negated). For shaders written for ARCore's SH, e.g. hello_ar_java
 * (`updateSphericalHarmonicsCoefficients` with `sphericalHarmonicFactors`, then
 * `environmental_hdr.frag` `Pbr_CalculateDiffuseEnvironmentalRadiance`), which return E/pi.
 * Axes: ARCore's world space is right-handed, +Y up, like glTF: no axis change (a scene placed
 * at a rotated anchor needs its SH rotated too). */
void lc_sh9_to_arcore(const float irradiance[27], float arcore[27]);
/* three.js: `LightProbe.sh` / `SphericalHarmonics3`, interleaved (`sh.fromArray(out)`):
 * radiance SH (= lc_sh9_irradiance_to_radiance); three.js convolves it back in
 * `SphericalHarmonics3.getIrradianceAt` and the light-probe shader (`shGetIrradianceAt`),
 * which return E. Axes: three.js is right-handed, +Y up, like glTF: no axis change. */
void lc_sh9_to_threejs(const float irradiance[27], float threejs[27]);
/* ARKit: the layout of `ARDirectionalLightEstimate.sphericalHarmonicsCoefficients` (27 floats,
 * separate red, green and blue planes of 9) = lc_sh9_to_planar: lucent's basis and scale
 * (Apple publishes the layout, not a basis or an evaluation formula). Axes: ARKit's world
 * (`ARConfiguration.WorldAlignment.gravity`) is right-handed, +Y up, like glTF: no axis
 * change. */
void lc_sh9_to_arkit(const float irradiance[27], float arkit[27]);

#ifdef __cplusplus
}
#endif

#endif
