/* replay_frames FRAMES [PREFIX]: applies recorded lucent/1 data frames with liblucent-client's
 * lc_client_view_apply, one view per stream, so client/js/test can compare the JavaScript
 * client's decoding with the C library's on the very same bytes.
 *
 * FRAMES: records of a u32 little-endian length and that many bytes (one frame each), at most
 * REPLAY_MAX_FRAME bytes a frame. Prints one JSON line per frame: the apply result, the header
 * fields it reports and the CRC-32 (IEEE) of the view's float32 values after the frame; with
 * PREFIX, also writes each stream's final values to PREFIX-STREAM.f32 (float32, as the view).
 * Exit 0 when every record was read (whatever the apply results), 2 usage, 3 I/O. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lucent_client.h"

#define REPLAY_MAX_FRAME (64u << 20) /* above any test lightmap frame; a cap on the read buffer */

static const char *const replay_streams[4] = {"none", "lightmap", "shgrid", "objects"};

/* The CRC-32 zlib computes, bitwise: a few hundred kilobytes per frame. */
static uint32_t replay_crc32(const void *data, size_t n) {
    const uint8_t *p = data;
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        c ^= p[i];
        for (int k = 0; k < 8; k++) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
    }
    return c ^ 0xFFFFFFFFu;
}

static int replay_read_u32(FILE *f, uint32_t *out) {
    uint8_t b[4];
    if (fread(b, 1, 4, f) != 4) return -1;
    *out = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
    return 0;
}

static void replay_print(int rc, const lc_client_frame *f, const char *err) {
    if (rc != 0) {
        char safe[256];
        size_t i = 0;
        for (; err[i] && i + 1 < sizeof safe; i++) /* the reason as a JSON string without escapes */
            safe[i] = err[i] == '"' || err[i] == '\\' || (unsigned char)err[i] < 0x20 ? '?' : err[i];
        safe[i] = 0;
        printf("{\"rc\":%d,\"error\":\"%s\"}\n", rc, safe);
        return;
    }
    /* pass (flags bits 8-15) and converged (bit 3) from the header as received: this program
     * builds against liblucent-client versions from before lc_client_frame had them */
    const unsigned flags = (unsigned)f->raw[8] | (unsigned)f->raw[9] << 8;
    printf("{\"rc\":0,\"stream\":\"%s\",\"sequence\":%llu,\"revision\":%llu,\"keyframe\":%d,\"residual\":%d,"
           "\"pass\":%u,\"converged\":%u,\"values\":%zu,\"crc\":%lu",
           replay_streams[f->stream], (unsigned long long)f->sequence, (unsigned long long)f->revision, f->keyframe,
           f->residual, flags >> 8, (flags >> 3) & 1u, f->value_count,
           (unsigned long)replay_crc32(f->values, f->value_count * sizeof(float)));
    if (f->object_ids) {
        printf(",\"ids\":[");
        for (uint32_t i = 0; i < f->width; i++) printf("%s\"%s\"", i ? "," : "", f->object_ids[i]);
        printf("]");
    }
    printf("}\n");
}

static int replay_write_values(const char *prefix, int stream, const lc_client_frame *f) {
    char path[1024];
    if (snprintf(path, sizeof path, "%s-%s.f32", prefix, replay_streams[stream]) >= (int)sizeof path) return -1;
    FILE *o = fopen(path, "wb");
    size_t n = f->value_count;
    int ok = o && (!n || fwrite(f->values, sizeof(float), n, o) == n);
    if (o && fclose(o) != 0) ok = 0;
    if (!ok) fprintf(stderr, "replay_frames: cannot write %s\n", path);
    return ok ? 0 : -1;
}

int main(int argc, char **argv) {
    if (argc < 2 || argc > 3) {
        fprintf(stderr, "usage: replay_frames FRAMES [PREFIX]\n");
        return 2;
    }
    int rc = 3;
    FILE *in = fopen(argv[1], "rb");
    uint8_t *buf = NULL;
    lc_client_view *views[4] = {NULL, lc_client_view_create(), lc_client_view_create(), lc_client_view_create()};
    lc_client_frame last[4]; /* each view's state after its last successful apply */
    int have[4] = {0, 0, 0, 0};
    if (!in) {
        fprintf(stderr, "replay_frames: cannot open %s\n", argv[1]);
        goto err;
    }
    if (!views[1] || !views[2] || !views[3]) goto err;
    uint32_t len;
    while (replay_read_u32(in, &len) == 0) {
        uint8_t *n = len <= REPLAY_MAX_FRAME ? realloc(buf, len ? len : 1) : NULL;
        if (!n || fread(n, 1, len, in) != len) {
            fprintf(stderr, "replay_frames: a record of %u bytes is cut short or over %u\n", len, REPLAY_MAX_FRAME);
            if (n) buf = n;
            goto err;
        }
        buf = n;
        int stream = len > 6 && buf[6] >= 1 && buf[6] <= 3 ? buf[6] : 1;
        char msg[256] = "";
        lc_client_frame f;
        int r = lc_client_view_apply(views[stream], buf, len, &f, msg, sizeof msg);
        replay_print(r, &f, msg);
        have[stream] = r == 0; /* a failed apply may have moved the view's buffers */
        if (r == 0) last[stream] = f;
    }
    rc = 0;
    for (int s = 1; s <= 3 && argc == 3; s++)
        if (have[s] && replay_write_values(argv[2], s, &last[s]) != 0) rc = 3;
err:
    free(buf);
    for (int s = 1; s <= 3; s++) lc_client_view_release(views[s]);
    if (in) fclose(in);
    return rc;
}
