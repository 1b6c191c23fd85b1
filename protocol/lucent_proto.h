/* liblucent-proto: lucent/1 messages (PROTOCOL.md) for the daemon, the client and tests.
 * Parses and validates client requests into C structs (every field checked, errors carry a
 * stable code and an RFC 6901 pointer), builds server messages as JSON text, encodes and
 * decodes binary frame headers, RGB9E5 and tiles. No I/O, no globals: thread-safe.
 * Builders write valid UTF-8 whatever their input: an ill-formed string (a truncated name,
 * a hand-filled error) is written with U+FFFD in place of the bad bytes.
 * Ownership: builders return malloc'd NUL-terminated text (caller frees with free());
 * parsed requests own their op array (lc_proto_request_release). */
#ifndef LC_PROTO_H
#define LC_PROTO_H
#include <stddef.h>
#include <stdint.h>

#include "lucent_errors.h"

#define LC_PROTO_NAME "lucent/1"
#define LC_PROTO_SUBPROTOCOL "lucent.v1"
/* The lws_protocols tx_packet_size of both ends: lws cuts every send() to it (0: to the rx
 * buffer, 16 or 64 KiB), so a large frame or upload left in pieces, one per service-loop
 * round. With this, one send() takes what the kernel's buffer holds; lws keeps the rest and
 * sends it as the socket drains. */
#define LC_PROTO_WS_TX_PACKET_MAX (64u << 20)
#define LC_PROTO_VERSION "1.1" /* welcome "version" (§8.1); absent = 1.0 */
#define LC_PROTO_ID_MAX 64     /* bytes in a light/object id or request id string */
#define LC_PROTO_NAME_MAX 128  /* client names */
#define LC_PROTO_TOKEN_MAX 256
#define LC_FRAME_MAGIC 0x3146434Cu /* "LCF1" little-endian */
#define LC_FRAME_HEADER_SIZE 64

typedef enum {
    LC_REQ_HELLO = 0,
    LC_REQ_SUBSCRIBE,
    LC_REQ_UNSUBSCRIBE,
    LC_REQ_LIGHT_SET,
    LC_REQ_LIGHT_REMOVE,
    LC_REQ_OBJECT_SET,
    LC_REQ_OBJECT_REMOVE,
    LC_REQ_MATERIAL_SET,
    LC_REQ_ENVIRONMENT_SET,
    LC_REQ_SETTINGS_SET,
    LC_REQ_BATCH,
    LC_REQ_STATE_GET,
    LC_REQ_SNAPSHOT,
    LC_REQ_PING,
    LC_REQ_MR_BEGIN, /* lucent/1.1 (§8.2): not change requests; the server checks the role */
    LC_REQ_MR_END,
    LC_REQ_COUNT
} lc_req_type;

/* "light.set" etc. */
const char *lc_proto_type_name(lc_req_type t);
/* 1 for the change requests (light.set .. settings.set, batch): controller only. 0 for
 * mr.begin / mr.end: they change no state; who may start a session is the server's call
 * (the `mr` capability, §8.1). */
int lc_proto_is_change(lc_req_type t);

/* hello/welcome "capabilities" (§8.1): bit per known name ("mr"). */
#define LC_CAP_MR (1u << 0)
#define LC_CAP_COUNT 1
#define LC_PROTO_CAPS_MAX 8      /* names in hello.capabilities */
#define LC_PROTO_CAP_NAME_MAX 32 /* bytes per name */
/* "mr" for LC_CAP_MR; NULL for a bit without a name. */
const char *lc_proto_capability_name(uint32_t cap_bit);

typedef enum {
    LC_STREAM_LIGHTMAP = 1,
    LC_STREAM_SHGRID = 2,
    LC_STREAM_OBJECTS = 3,
    LC_STREAM_MR_VPL = 4 /* "mr.vpl" (§8.7): per session object its sparse points' two lights */
} lc_stream;
#define LC_STREAM_MAX LC_STREAM_MR_VPL
typedef enum { LC_ENC_RGB9E5 = 1, LC_ENC_RGBA16F = 2, LC_ENC_F32 = 3 } lc_encoding;
const char *lc_proto_stream_name(lc_stream s);
const char *lc_proto_encoding_name(lc_encoding e);

/* Request id: absent, a string (1..64 bytes) or an integer in [0, 2^53). */
typedef struct lc_proto_id {
    int kind; /* 0 none, 1 string, 2 integer */
    char str[LC_PROTO_ID_MAX + 1];
    int64_t num;
} lc_proto_id;

typedef enum { LC_PLIGHT_POINT = 0, LC_PLIGHT_SPOT, LC_PLIGHT_DIRECTIONAL, LC_PLIGHT_AREA } lc_proto_light_type;

/* Fields and ranges as PROTOCOL.md §4.3; defaults filled in by the parser. */
typedef struct lc_proto_light {
    char id[LC_PROTO_ID_MAX + 1];
    lc_proto_light_type type;
    float color[3];
    float intensity, range;
    float position[3], direction[3]; /* direction normalised by the parser */
    float inner_cone, outer_cone;
    int shape; /* 0 quad, 1 disc */
    float size[2];
    float tangent[3]; /* zero when not given */
} lc_proto_light;

typedef struct lc_proto_object {
    char id[LC_PROTO_ID_MAX + 1];
    char asset[LC_PROTO_ID_MAX + 1];
    float translation[3], rotation[4], scale[3]; /* rotation normalised by the parser */
    int visible;
    int dnrt; /* 1 (default): the object affects the indirect light when its asset has transfer data */
    int mode; /* LC_OBJECT_MODE_* (§4.5; default dynamic) */
    /* state replies only (§5.4; never parsed): LC_OBJECT_TRANSPORT_* + 1, 0 = not written */
    int transport;
} lc_proto_object;
enum { LC_OBJECT_MODE_DYNAMIC = 0, LC_OBJECT_MODE_CLUTTER, LC_OBJECT_MODE_AUTO };
enum { LC_OBJECT_TRANSPORT_DYNAMIC = 0, LC_OBJECT_TRANSPORT_CLUTTER };

typedef struct lc_proto_environment {
    int kind; /* 0 none, 1 constant, 2 sh */
    float color[3];
    float sh[27];
    float intensity;
} lc_proto_environment;

/* settings.set: `present` has bit (1 << field) for each field given. */
enum {
    LC_SET_BOUNCES = 0,
    LC_SET_BANDS,
    LC_SET_PROGRESSIVE,
    LC_SET_CHROMA,
    LC_SET_CHROMA_BANDS,
    LC_SET_DNRT,
    LC_SET_DNRT_BLOCKERS,
    LC_SET_SOLVER,
    LC_SET_COUNT
};
#define LC_SET_ALL ((1u << LC_SET_COUNT) - 1u)
typedef struct lc_proto_settings {
    uint32_t present;
    uint32_t bounces, bands, chroma_bands;
    int progressive, chroma_compression;
    int dnrt;          /* placed objects with transfer data affect the indirect light (default 1) */
    int dnrt_blockers; /* static geometry between object and receiver is tested with rays (default 1) */
    int solver;        /* LC_PROTO_SOLVER_* (default: the bake's, the server's choice) */
} lc_proto_settings;
/* settings.solver "pic" | "probes" (§4.9), in the order of welcome.scene.solvers */
enum { LC_PROTO_SOLVER_PIC = 0, LC_PROTO_SOLVER_PROBES, LC_PROTO_SOLVER_COUNT };
/* "pic", "probes"; NULL for an unknown value. */
const char *lc_proto_solver_name(int solver);

/* One change. For removes, `target` holds the id; for material.set, `target` the name. */
typedef struct lc_proto_op {
    lc_req_type type; /* LC_REQ_LIGHT_SET .. LC_REQ_SETTINGS_SET */
    char target[LC_PROTO_ID_MAX + 1];
    lc_proto_light light;
    lc_proto_object object;
    float emission[3];
    lc_proto_environment environment;
    lc_proto_settings settings;
} lc_proto_op;

/* mr.begin "session" (§8.2); defaults filled in by the parser. */
#define LC_PROTO_MR_OBJECTS_MAX 16
#define LC_PROTO_MR_SIDE_MIN 8
#define LC_PROTO_MR_SIDE_MAX 1024
#define LC_PROTO_MR_PIXELS_MAX 1048576u
typedef struct lc_proto_mr_session {
    char objects[LC_PROTO_MR_OBJECTS_MAX][LC_PROTO_ID_MAX + 1]; /* object ids, distinct */
    uint32_t n_objects;                                         /* 1..16 */
    uint32_t width, height;                                     /* 8..1024 each, width*height <= 1048576 */
    int depth_encoding;       /* LC_DEPTH_U16MM | LC_DEPTH_F16M (lucent_upload.h): "u16mm" | "f16m" */
    int color_encoding;       /* LC_COLOR_RGB8_SRGB | LC_COLOR_RGB16F_LINEAR: "rgb8_srgb" | "rgb16f_linear" */
    double max_rate;          /* 0.1..60 frames per second, default 10 */
    int glossy;               /* default 1 */
    double specular_exponent; /* 1..10000, default 16 */
    double min_confidence;    /* 0..1, default 0.5 */
    double smoothing;         /* 0..0.99, default 0 */
    int light_add;            /* "light": "replace" (default, 0) | "add" (1) */
} lc_proto_mr_session;

typedef struct lc_proto_request {
    lc_req_type type;
    lc_proto_id id;
    /* hello */
    char client[LC_PROTO_NAME_MAX + 1];
    char token[LC_PROTO_TOKEN_MAX + 1];
    uint32_t encodings;    /* bit (1 << lc_encoding) per encoding listed */
    uint32_t capabilities; /* LC_CAP_* of the known names listed (unknown names ignored) */
    /* subscribe / unsubscribe */
    lc_stream stream;
    lc_encoding encoding; /* the stream's default when not given */
    double max_rate;      /* 0 = unlimited */
    int residual;         /* subscribe "delta": "residual" (lightmap) */
    /* ping */
    double ping_t;
    /* mr.begin */
    lc_proto_mr_session mr;
    /* change requests: 1 op, or the batch's ops (malloc'd, owned) */
    lc_proto_op *ops;
    uint32_t n_ops;
} lc_proto_request;

typedef struct lc_proto_limits {
    size_t max_message; /* bytes (65536) */
    int max_depth;      /* JSON nesting (16) */
    uint32_t max_batch; /* ops per batch (64) */
} lc_proto_limits;

/* Error: stable code (PROTOCOL.md §5.2), RFC 6901 pointer, human message. */
typedef struct lc_proto_error {
    char code[32]; /* a catalogue code (lucent_errors.h), as on the wire; set with lc_proto_error_set_code */
    char pointer[160];
    char message[256];
} lc_proto_error;

/* err->code = the catalogue entry's name. */
void lc_proto_error_set_code(lc_proto_error *err, lc_proto_errcode code);

void lc_proto_default_limits(lc_proto_limits *lim);

/* --- UTF-8 (every string lucent sends is valid UTF-8; RFC 6455 closes with 1007 otherwise) - */

/* 1 when s[0, len) is well-formed UTF-8: no overlong forms, no surrogates (U+D800..U+DFFF),
 * nothing above U+10FFFF, no truncated sequence. NUL bytes count as characters. */
int lc_proto_utf8_valid(const char *s, size_t len);
/* Length of the longest prefix of s[0, len), at most `max` bytes, that ends on a character
 * boundary: never inside a multi-byte sequence, nor inside one that `len` cuts short. For
 * valid input the prefix is valid. */
size_t lc_proto_utf8_cut(const char *s, size_t len, size_t max);
/* Copies s[0, len) into dst (cap bytes, always NUL-terminated when cap > 0) as valid
 * UTF-8: each maximal ill-formed subsequence becomes U+FFFD, and with
 * LC_PROTO_UTF8_NO_CONTROLS so does each control character (U+0000..U+001F, U+007F..U+009F);
 * stops before the first character that does not fit. Returns the input bytes consumed
 * (len when all of s fit). */
enum { LC_PROTO_UTF8_NO_CONTROLS = 1u << 0 };
size_t lc_proto_utf8_sanitize(char *dst, size_t cap, const char *s, size_t len, unsigned flags);

/* Parses one text message (len bytes, need not be NUL-terminated). Checks size, nesting
 * depth (before building any tree), JSON syntax, type, every field's type and range. On
 * failure returns -1 with err filled, and out->id set whenever the message is a JSON object
 * whose own "id" is valid, whatever else failed (so the error can echo it). err->message
 * quotes client text only cut on a character boundary, so it is valid UTF-8. On success
 * returns 0; release with lc_proto_request_release. */
int lc_proto_parse_request(const char *text, size_t len, const lc_proto_limits *lim, lc_proto_request *out,
                           lc_proto_error *err);
void lc_proto_request_release(lc_proto_request *r);

/* --- server messages ------------------------------------------------------------------------ */

/* welcome.scene.asset_info: per asset, its DNRT transfer grid (§3.4). */
typedef struct lc_proto_asset_info {
    int has_transfer; /* 0: the asset has none (an older bake): sent as {} */
    uint32_t dims, coefficients;
    uint64_t bytes;     /* the grid's quantised values */
    float outer_radius; /* metres (asset-local), where the effect ends */
} lc_proto_asset_info;

typedef struct lc_proto_welcome {
    const char *server; /* "lucentd/0.1.0" */
    const char *role;   /* "viewer" | "controller" */
    uint64_t revision;
    uint32_t lightmap_width, lightmap_height, tile;
    float grid_origin[3], grid_cell;
    uint32_t grid_dims[3];
    uint32_t bands;
    const char *const *assets;
    uint32_t n_assets;
    const char *bake_id;                   /* NULL: not sent */
    const char *geometry;                  /* path of the scene's glTF, e.g. "/scene.glb"; NULL: not sent */
    const char *const *asset_geometry;     /* per asset its glTF's path; NULL: not sent */
    const lc_proto_asset_info *asset_info; /* per asset (n_assets); NULL: not sent */
    double clutter_rest;                   /* scene.clutter (§4.5): rest time in s; 0 = not sent */
    uint32_t solvers;                      /* scene.solvers (§4.9): bit per LC_PROTO_SOLVER_* offered; 0 = not sent */
    uint32_t clutter_max_objects;
    const char *const *materials;
    uint32_t n_materials;
    lc_proto_limits limits;
    uint32_t max_lights, max_objects, rate;
    uint32_t capabilities; /* LC_CAP_* granted (§8.1): always written, with "version": "1.1" */
} lc_proto_welcome;

typedef struct lc_proto_material_state {
    const char *name;
    float emission[3];
} lc_proto_material_state;

/* The whole dynamic state (also the daemon's snapshot file format). */
typedef struct lc_proto_state {
    uint64_t revision;
    const lc_proto_light *lights;
    uint32_t n_lights;
    const lc_proto_object *objects;
    uint32_t n_objects;
    const lc_proto_material_state *materials;
    uint32_t n_materials;
    lc_proto_environment environment;
    lc_proto_settings settings; /* all fields present */
} lc_proto_state;

char *lc_proto_build_welcome(const lc_proto_id *id, const lc_proto_welcome *w);
char *lc_proto_build_ok(const lc_proto_id *id, uint64_t revision);
/* ok for mr.begin (§8.2): the plain ok plus "mr": {session, max_frame, max_rate, max_lights, points}. */
char *lc_proto_build_ok_mr(const lc_proto_id *id, uint64_t revision, uint32_t session, uint64_t max_frame,
                           double max_rate, uint32_t max_lights, uint32_t points);
/* {"type":"mr.ack","seq","capture_us","status":"processed"|"replaced","lights","ms"} (§8.5). */
char *lc_proto_build_mr_ack(uint32_t seq, uint64_t capture_us, int replaced, uint32_t lights, double ms);
char *lc_proto_build_error(const lc_proto_id *id, const lc_proto_error *e);
char *lc_proto_build_changed(uint64_t revision, const char *by, const lc_proto_op *ops, uint32_t n_ops);
/* object.transport (§5.5): transport LC_OBJECT_TRANSPORT_*; build_ms and bytes only with clutter. */
char *lc_proto_build_object_transport(const char *object_id, int transport, uint64_t revision, double build_ms,
                                      uint64_t bytes);
char *lc_proto_build_state(const lc_proto_id *id, const lc_proto_state *st);
char *lc_proto_build_pong(const lc_proto_id *id, double t, uint64_t server_time_us);
/* One op as the JSON request that would make it (journal records). */
char *lc_proto_build_op(const lc_proto_op *op);

/* Parses a `state` message (snapshot file). Arrays are malloc'd into *lights, *objects,
 * *materials (names malloc'd too); free with lc_proto_state_free_parsed. */
typedef struct lc_proto_parsed_state {
    uint64_t revision;
    lc_proto_light *lights;
    uint32_t n_lights;
    lc_proto_object *objects;
    uint32_t n_objects;
    char (*material_names)[LC_PROTO_ID_MAX + 1];
    float (*material_emission)[3];
    uint32_t n_materials;
    lc_proto_environment environment;
    lc_proto_settings settings;
} lc_proto_parsed_state;
int lc_proto_parse_state(const char *text, size_t len, lc_proto_parsed_state *out, lc_proto_error *err);
void lc_proto_parsed_state_free(lc_proto_parsed_state *s);

/* --- binary frames (PROTOCOL.md §6) ------------------------------------------------------- */

enum { LC_FRAME_KEYFRAME = 1u << 0, LC_FRAME_DELTA = 1u << 1, LC_FRAME_RESIDUAL = 1u << 2 };
/* The header's flags word also carries bit 3 "converged" and bits 8-15 the refinement pass;
 * lc_frame_header keeps them apart from the frame kind, so `flags` is only bits 0-2. */
#define LC_FRAME_CONVERGED_BIT (1u << 3)
#define LC_FRAME_PASS_SHIFT 8
#define LC_FRAME_PASS_MAX 255u

typedef struct lc_frame_header {
    uint16_t version; /* 1 */
    uint8_t stream, encoding;
    uint16_t flags;    /* frame kind: LC_FRAME_KEYFRAME, LC_FRAME_DELTA (+ LC_FRAME_RESIDUAL) */
    uint8_t pass;      /* refinement pass of the revision (0 = its first solution), saturating */
    uint8_t converged; /* 1: no further pass of this revision will come */
    uint32_t tile_count;
    uint64_t revision, sequence, timestamp_us;
    uint32_t width, height, depth, tile_size;
    uint32_t payload_length;
    uint32_t crc; /* filled by lc_frame_finish / checked by lc_frame_parse */
} lc_frame_header;

/* Writes header (64 B) + tile table + payload into out (capacity cap). Computes the CRC.
 * Returns the frame length, or 0 if it does not fit. */
size_t lc_frame_write(const lc_frame_header *h, const uint32_t *tiles, const void *payload, uint8_t *out, size_t cap);
/* The CRC-32 of a frame's body (the tile table as written, then the payload): a server sending
 * one body to many clients computes it once and passes it to lc_frame_write_body_crc, which
 * writes the same bytes as lc_frame_write and combines the header's CRC with it. */
uint32_t lc_frame_body_crc(const lc_frame_header *h, const uint32_t *tiles, const void *payload);
size_t lc_frame_write_body_crc(const lc_frame_header *h, const uint32_t *tiles, const void *payload, uint32_t body_crc,
                               uint8_t *out, size_t cap);
/* Parses and checks a frame: magic, version, header size, flags (keyframe, delta, or delta +
 * residual for the lightmap), lengths consistent with len, tile indices ascending and inside
 * the image, CRC. A residual delta's payload is compressed: its inflated size is checked by
 * lc_residual_inflate. Pointers point into data. Returns 0 or -1 with err (code "bad_frame"). */
int lc_frame_parse(const uint8_t *data, size_t len, lc_frame_header *h, const uint8_t **tile_table,
                   const uint8_t **payload, lc_proto_error *err);

/* Texels covered by the tile table of a parsed lightmap delta. */
size_t lc_frame_tile_texels(const lc_frame_header *h, const uint8_t *tile_table);

/* Residual deltas (PROTOCOL.md §6.2.1). `now`, `held`: `texels` encoded texels (as on the
 * wire); out receives their residual (same size): zigzag field differences, so that
 * lc_residual_apply(e, held, residual) turns `held` into `now` bit for bit. Unknown
 * encodings do nothing. */
void lc_residual_make(lc_encoding e, const uint8_t *now, const uint8_t *held, size_t texels, uint8_t *out);
void lc_residual_apply(lc_encoding e, uint8_t *held, const uint8_t *residual, size_t texels);
/* zlib (RFC 1950) compression of the residual bytes: the compressed length, 0 when it does
 * not fit in cap (lc_residual_deflate_bound(n) always fits). Inflate: 0 only when `in` is one
 * complete zlib stream inflating to exactly `expect` bytes. */
size_t lc_residual_deflate_bound(size_t n);
size_t lc_residual_deflate(const uint8_t *in, size_t n, uint8_t *out, size_t cap);
int lc_residual_inflate(const uint8_t *in, size_t n, uint8_t *out, size_t expect);

/* Bytes per lightmap texel / per SH value for an encoding (0 when not allowed). */
size_t lc_frame_texel_bytes(lc_encoding e);
size_t lc_frame_sh_value_bytes(lc_encoding e);

/* mr.vpl payload (§8.7): per session object (sorted by id) a block of 64 bytes of id (zero
 * padded), u32 point count P, u32 reserved (0), then P records of LC_FRAME_MR_VPL_VALUES
 * values (f32, or binary16 with rgba16f): I_d rgb, l_d xyz, I_s rgb, l_s xyz. Header width =
 * the number of objects, height = the sum of P, depth 1, tile_size 0, keyframes only. */
#define LC_FRAME_MR_VPL_VALUES 12
#define LC_FRAME_MR_VPL_BLOCK_HEADER 72 /* id + P + reserved */
/* Bytes of one object's block with `points` records; 0 for an encoding the stream lacks. */
size_t lc_frame_mr_vpl_block_bytes(lc_encoding e, uint32_t points);
/* Writes one object's block at out (cap bytes): the id (at most 64 bytes, cut there), P, 0,
 * then records[0 .. points*12) encoded. Returns the bytes written, 0 when it does not fit
 * or the encoding is not f32 / rgba16f. */
size_t lc_frame_mr_vpl_block(lc_encoding e, const char *id, uint32_t points, const float *records, uint8_t *out,
                             size_t cap);
/* Walks a parsed mr.vpl payload: block `*at` (start 0) -> its id (NUL-terminated copy),
 * point count and records pointer; advances *at. 0, or -1 at the end / on a bad block
 * (lc_frame_parse has checked the layout, so -1 then means the end). */
int lc_frame_mr_vpl_next(const lc_frame_header *h, const uint8_t *payload, size_t *at, char id[LC_PROTO_ID_MAX + 1],
                         uint32_t *points, const uint8_t **records);

/* GL RGB9_E5 (shared exponent) — the same bits a GL upload of GL_RGB9_E5 expects. */
uint32_t lc_rgb9e5_encode(const float rgb[3]);
void lc_rgb9e5_decode(uint32_t v, float rgb[3]);

/* Lightmap tiles: number of tiles for W x H with tile side S; texel rectangle of tile t. */
uint32_t lc_tiles_count(uint32_t w, uint32_t h, uint32_t s);
void lc_tile_rect(uint32_t w, uint32_t h, uint32_t s, uint32_t t, uint32_t *x0, uint32_t *y0, uint32_t *x1,
                  uint32_t *y1);

#endif
