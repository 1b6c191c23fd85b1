/* server_frames: the lucent/1 binary frames (PROTOCOL.md §6) lucentd sends one client —
 * lightmap keyframes, tile deltas and residual deltas, SH grid and object SH — from a
 * published relight. What the client holds is an lc_frames_copy (deltas compare against
 * it); what many clients can share (each publication's lightmap encoded once per encoding,
 * the last residual delta per encoding) lives in one lc_frames per server.
 * Thread: the service thread (one lc_frames and its copies are used from one thread). */
#ifndef LC_SERVER_FRAMES_H
#define LC_SERVER_FRAMES_H
#include <stddef.h>
#include <stdint.h>

#include "compute.h"
#include "lucent_proto.h"

typedef struct lc_frames lc_frames;

/* One client's copy of the lightmap and its frame buffer. Zero-initialise; the frames
 * module owns the arrays (free with lc_frames_copy_release). */
typedef struct lc_frames_copy {
    float *lm_sent; /* per texel, the value the client's copy was encoded from */
    size_t lm_sent_texels;
    uint64_t lm_sent_state; /* names lm_sent's content for whole-tile deltas (0: shared with none) */
    uint8_t *lm_held;       /* residual subscribers: the encoded texels the client holds */
    size_t lm_held_bytes;
    uint64_t lm_held_state; /* names lm_held's content: equal ids, bit-identical copies */
    uint8_t *out;           /* the last frame, at out + job.pre */
    size_t out_cap;
} lc_frames_copy;

/* What to encode. */
typedef struct lc_frames_job {
    const lc_published *frame; /* borrowed for the call */
    uint64_t pub_seq;          /* the publication's sequence number (names it in the caches) */
    int stream;                /* lc_stream */
    lc_encoding enc;
    int residual;           /* lightmap deltas as compressed residuals (§6.2.1) */
    uint64_t sequence;      /* this frame's sequence number in its stream (1 = first) */
    int force_key;          /* a keyframe whatever the delta would be */
    uint32_t tile;          /* delta tile side (lc_frames_tile_size) */
    int keyframe_interval;  /* a lightmap keyframe every this many frames */
    double delta_threshold; /* relative texel change that puts a tile in a delta */
    size_t pre;             /* bytes kept free before the frame (LWS_PRE) */
    /* objects stream: an MR session's light for an object (PROTOCOL.md §8.6), or NULL; *add
     * says whether it adds to the published SH or replaces it. NULL function: none. */
    const float *(*mr_light)(void *ctx, const char *id, int *add);
    void *mr_ctx;
} lc_frames_job;

lc_frames *lc_frames_create(void);
void lc_frames_release(lc_frames *f);
void lc_frames_copy_release(lc_frames_copy *cp);

/* The delta tile side: the configured one, or (0 = auto) the largest of 32, 16, 8 that still
 * cuts the lightmap into at least 64 tiles. */
uint32_t lc_frames_tile_size(int configured, uint32_t w, uint32_t h);

/* The mr.vpl stream (PROTOCOL.md §8.7): per object, its id, point count and the points'
 * 12-value records, as one keyframe into cp->out + pre. Returns the length, 0 out of memory. */
typedef struct lc_frames_vpl_object {
    const char *id;
    uint32_t n_points;
    const float *records; /* n_points * 12 */
} lc_frames_vpl_object;
size_t lc_frames_encode_vpl(lc_frames_copy *cp, const lc_frames_vpl_object *objects, uint32_t n_objects,
                            lc_encoding enc, uint64_t revision, uint64_t sequence, uint64_t timestamp_us, size_t pre);

/* 1 when lc_frames_encode of j for this copy would compute a residual delta (deflate the
 * dirty tiles: milliseconds on a large lightmap) instead of a keyframe or a delta another
 * client in the same state already had computed. The server writes cheap frames first. */
int lc_frames_would_deflate(const lc_frames *f, const lc_frames_copy *cp, const lc_frames_job *j);

/* Encodes job's frame into cp->out + job->pre and updates what the copy holds (a lightmap
 * keyframe or delta is assumed delivered). Returns the frame's length, 0 when out of memory. */
size_t lc_frames_encode(lc_frames *f, lc_frames_copy *cp, const lc_frames_job *j);

#endif
