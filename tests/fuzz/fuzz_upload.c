/* Fuzz target: MR upload frames (lc_upload_parse, PROTOCOL.md §8.4), with and without a
 * session's expectations; a parsed frame is decoded in full. */
#include <stdint.h>
#include <stdlib.h>

#include "lucent_upload.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    for (int k = 0; k < 2; k++) {
        lc_upload_expect ex = {16, 12, 1, 2, 1 << 20};
        lc_upload_frame f;
        lc_proto_error e;
        if (lc_upload_parse(data, size, k ? &ex : NULL, &f, &e) != 0) continue;
        size_t px = (size_t)f.h.width * f.h.height;
        float *buf = malloc(px * 3 * sizeof *buf);
        if (buf) {
            lc_upload_depth_metres(&f, buf);
            lc_upload_radiance(&f, buf);
            lc_upload_confidence(&f, buf);
        }
        free(buf);
        lc_upload_frame_release(&f);
    }
    return 0;
}
