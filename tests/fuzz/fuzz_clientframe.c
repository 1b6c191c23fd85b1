/* Fuzz target: liblucent-client's frame decoder (lc_client_view_apply), the parser every
 * client runs on server bytes. Input: byte 0 = mode (bit 0: fix each frame's CRC so the
 * fuzzer reaches the layout and delta logic), then frames as [u32 LE length][bytes]...,
 * applied in order to one view. Must never crash, leak or read out of bounds. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "lucent_client.h"
#include "util/crc32.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size < 1) return 0;
    int fix_crc = data[0] & 1;
    size_t off = 1;
    lc_client_view *v = lc_client_view_create();
    if (!v) return 0;
    while (off + 4 <= size) {
        uint32_t len = (uint32_t)data[off] | (uint32_t)data[off + 1] << 8 | (uint32_t)data[off + 2] << 16 |
            (uint32_t)data[off + 3] << 24;
        off += 4;
        if (len > size - off) len = (uint32_t)(size - off);
        /* a private copy so that reads past the frame are caught by ASan */
        uint8_t *f = malloc(len ? len : 1);
        if (!f) break;
        memcpy(f, data + off, len);
        off += len;
        if (fix_crc && len >= 64) {
            uint32_t crc = lc_crc32(0, f, 60);
            crc = lc_crc32(crc, f + 64, len - 64);
            memcpy(f + 60, &crc, 4);
        }
        lc_client_frame out;
        char err[128];
        if (lc_client_view_apply(v, f, len, &out, err, sizeof err) == 0) {
            /* everything the frame points to must be readable */
            volatile float sink = 0;
            for (size_t i = 0; i < out.value_count; i += 97) sink += out.values[i];
            if (out.object_ids)
                for (uint32_t i = 0; i < out.width; i++) sink += (float)strlen(out.object_ids[i]);
            (void)sink;
        }
        free(f);
    }
    lc_client_view_release(v);
    return 0;
}
