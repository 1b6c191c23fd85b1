/* liblucent-client: an mr.vpl frame (stream 4, PROTOCOL.md §8.7) is accepted and decoded by
 * a view: records in object order, ids and point counts; bad mr.vpl frames are refused and
 * leave the view as it was. */
#include <stdint.h>
#include <string.h>

#include "check.h"
#include "lucent_client.h"
#include "lucent_proto.h"
#include "util/half.h"

static uint8_t payload_buf[1 << 14], frame_buf[1 << 15];

/* Value c of record k of object i. */
static float vpl_value(uint32_t i, uint32_t k, uint32_t c) { return (float)(i * 100 + k) + (float)c * 0.25f; }

/* Frame with objects ids[n] of counts[n] points at revision rev; height = their sum + skew. */
static size_t vpl_frame(lc_encoding enc, const char *const *ids, const uint32_t *counts, uint32_t n, uint64_t rev,
                        int skew) {
    float rec[8 * LC_FRAME_MR_VPL_VALUES];
    size_t at = 0;
    uint32_t total = 0;
    for (uint32_t i = 0; i < n; i++) {
        for (uint32_t k = 0; k < counts[i]; k++)
            for (uint32_t c = 0; c < LC_FRAME_MR_VPL_VALUES; c++)
                rec[k * LC_FRAME_MR_VPL_VALUES + c] = vpl_value(i, k, c);
        at += lc_frame_mr_vpl_block(enc, ids[i], counts[i], rec, payload_buf + at, sizeof payload_buf - at);
        total += counts[i];
    }
    lc_frame_header h;
    memset(&h, 0, sizeof h);
    h.version = 1;
    h.stream = LC_STREAM_MR_VPL;
    h.encoding = (uint8_t)enc;
    h.flags = LC_FRAME_KEYFRAME;
    h.revision = rev;
    h.sequence = rev;
    h.width = n;
    h.height = (uint32_t)((int)total + skew);
    h.depth = 1;
    h.payload_length = (uint32_t)at;
    return lc_frame_write(&h, NULL, payload_buf, frame_buf, sizeof frame_buf);
}

static void check_view(lc_encoding enc) {
    const char *ids[] = {"chair-1", "lamp", "table"};
    const uint32_t counts[] = {3, 0, 2};
    char err[256] = "";
    lc_client_frame f;
    lc_client_view *v = lc_client_view_create();
    size_t n = vpl_frame(enc, ids, counts, 3, 7, 0);
    CHECK(n > 0, "frame written");
    int rc = lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err);
    CHECK(rc == 0, "%s mr.vpl frame applied: %s", lc_proto_encoding_name(enc), err);
    if (rc == 0) {
        CHECK(f.stream == LC_CLIENT_MR_VPL && f.keyframe && f.revision == 7 && f.width == 3 && f.height == 5 &&
                  f.value_count == 5 * 12,
              "frame fields: stream %d width %u height %u values %zu", f.stream, f.width, f.height, f.value_count);
        CHECK(f.object_ids && f.object_points, "ids and point counts given");
        uint32_t rec = 0;
        for (uint32_t i = 0; f.object_ids && f.object_points && i < 3; i++) {
            CHECK(!strcmp(f.object_ids[i], ids[i]) && f.object_points[i] == counts[i], "object %u: %s %u", i,
                  f.object_ids[i], f.object_points[i]);
            for (uint32_t k = 0; k < counts[i]; k++, rec++)
                for (uint32_t c = 0; c < 12; c++) {
                    float want = vpl_value(i, k, c);
                    if (enc == LC_ENC_RGBA16F) want = lc_half_to_float(lc_half_from_float(want));
                    if (f.values[rec * 12 + c] != want) {
                        CHECK(0, "object %u record %u value %u: %g, expected %g", i, k, c, f.values[rec * 12 + c],
                              want);
                        k = counts[i];
                        break;
                    }
                }
        }
    }
    /* frames whose point counts do not sum to the height (CRC valid): refused */
    n = vpl_frame(enc, ids, counts, 3, 8, -1);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -1, "height 4 for 5 points refused");
    n = vpl_frame(enc, ids, counts, 3, 8, 1);
    CHECK(lc_client_view_apply(v, frame_buf, n, &f, err, sizeof err) == -1, "height 6 for 5 points refused");
    lc_client_frame last;
    memset(&last, 0, sizeof last);
    /* a second, valid frame with fewer objects replaces the first */
    n = vpl_frame(enc, ids + 2, counts + 2, 1, 9, 0);
    rc = lc_client_view_apply(v, frame_buf, n, &last, err, sizeof err);
    CHECK(rc == 0 && last.revision == 9 && last.width == 1 && last.height == 2 && last.value_count == 24 &&
              last.object_ids && !strcmp(last.object_ids[0], "table") && last.object_points &&
              last.object_points[0] == 2 && last.values[0] == vpl_value(0, 0, 0),
          "second frame: %s", err);
    lc_client_view_release(v);
}

int main(void) {
    check_view(LC_ENC_F32);
    check_view(LC_ENC_RGBA16F);
    CHECK((int)LC_CLIENT_MR_VPL == (int)LC_STREAM_MR_VPL, "client stream number = frame stream number");
    CHECK_DONE();
}
