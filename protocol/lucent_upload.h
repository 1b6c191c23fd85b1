/* lucent_upload: MR upload frames (PROTOCOL.md §8.4, "LCU1"): the parser every server-side
 * frame goes through, the encoder clients and tests use, and the plane decoders.
 * No I/O, no globals: thread-safe. The parser checks every header field, the plane sizes and
 * the CRC before it allocates, and inflates each zlib plane with its exact size as the cap. */
#ifndef LC_UPLOAD_H
#define LC_UPLOAD_H
#include <stddef.h>
#include <stdint.h>

#include "lucent_proto.h"

#define LC_UPLOAD_MAGIC 0x3155434Cu /* "LCU1" little-endian */
#define LC_UPLOAD_HEADER_SIZE 128
#define LC_UPLOAD_MAX_FRAME_DEFAULT (4u << 20)
#define LC_UPLOAD_MAX_PIXELS (1u << 20) /* width * height (§8.2) */

typedef enum { LC_DEPTH_U16MM = 1, LC_DEPTH_F16M = 2 } lc_depth_encoding;
typedef enum { LC_COLOR_RGB8_SRGB = 1, LC_COLOR_RGB16F_LINEAR = 2 } lc_color_encoding;

typedef struct lc_upload_header {
    uint32_t sequence;
    uint64_t capture_us;
    uint16_t width, height;
    uint8_t depth_encoding, color_encoding;          /* lc_depth_encoding, lc_color_encoding */
    uint8_t depth_zlib, confidence_zlib, color_zlib; /* 1: that plane is (to be) zlib-compressed */
    uint8_t has_confidence;
    float fx, fy, cx, cy, translation[3], rotation[4] /* x y z w */, exposure;
} lc_upload_header;

/* What the session expects (§8.2); the parser checks the frame against it. */
typedef struct lc_upload_expect {
    uint16_t width, height;
    uint8_t depth_encoding, color_encoding;
    size_t max_frame;
} lc_upload_expect;

/* A parsed frame: the header (rotation normalised) and the raw, inflated planes, malloc'd
 * and owned by the frame (confidence NULL when there is none). */
typedef struct lc_upload_frame {
    lc_upload_header h;
    uint8_t *depth, *confidence, *color;
} lc_upload_frame;

/* 0, or -1 with err: code frame_invalid (pointer /header/FIELD, /frame/length, /depth/zlib,
 * /confidence/zlib, /color/zlib) or frame_too_large (over exp->max_frame, checked first).
 * exp NULL: only the format is checked (max_frame LC_UPLOAD_MAX_FRAME_DEFAULT). On failure
 * *out holds nothing to release. */
int lc_upload_parse(const uint8_t *buf, size_t len, const lc_upload_expect *exp, lc_upload_frame *out,
                    lc_proto_error *err);
/* Frees the planes; idempotent (pointers are cleared). */
void lc_upload_frame_release(lc_upload_frame *f);

/* Raw plane sizes (bytes) for a header's width, height and encodings. */
size_t lc_upload_depth_bytes(const lc_upload_header *h);
size_t lc_upload_color_bytes(const lc_upload_header *h);

/* Encodes a frame from raw planes (confidence NULL iff !h->has_confidence), compressing the
 * planes whose *_zlib is set, with the CRC. *out malloc'd (caller frees). 0, or -1 with err. */
int lc_upload_encode(const lc_upload_header *h, const void *depth, const void *confidence, const void *color,
                     uint8_t **out, size_t *out_len, char *err, size_t errlen);

/* What the server computes with: depth in metres (0 = no measurement; for f16m also negative
 * or non-finite values), linear radiance in nits (sRGB EOTF for rgb8_srgb) times exposure,
 * confidence in [0, 1] (1 everywhere without a plane). Arrays of w*h (radiance w*h*3). */
void lc_upload_depth_metres(const lc_upload_frame *f, float *out);
void lc_upload_radiance(const lc_upload_frame *f, float *rgb_out);
void lc_upload_confidence(const lc_upload_frame *f, float *out);

#endif
