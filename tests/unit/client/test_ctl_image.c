/* lucentctl's own EXR (half) and PNG writers, read back through OpenImageIO: the EXR holds
 * exactly the half-rounded values (including 0, tiny, large and negative ones) at the right
 * pixels; the PNG holds the bytes given. */
#include <stdint.h>
#include <unistd.h>

#include "bake/image.h"
#include "check.h"
#include "ctl_image.h"
#include "util/half.h"

int main(void) {
    char dir[] = "/tmp/lc_ctlimage_XXXXXX";
    if (!mkdtemp(dir)) return 1;
    const uint32_t w = 7, h = 5;
    float rgb[7 * 5 * 3];
    for (uint32_t i = 0; i < w * h * 3; i++) rgb[i] = (float)(i % 11) * 0.37f - 0.5f + (float)(i / 33) * 100.0f;
    rgb[0] = 0.0f;
    rgb[1] = 1e-6f;    /* a half subnormal */
    rgb[2] = 60000.0f; /* near the half maximum */
    char path[128], err[256];
    snprintf(path, sizeof path, "%s/a.exr", dir);
    CHECK(ctl_image_write_exr_half(path, w, h, rgb, err, sizeof err) == 0, "write exr: %s", err);
    uint32_t rw = 0, rh = 0;
    float *back = NULL;
    CHECK(lc_image_read_rgb(path, 1 << 20, &rw, &rh, &back, err, sizeof err) == 0, "read exr: %s", err);
    CHECK(rw == w && rh == h, "size %ux%u", rw, rh);
    int bad = 0;
    for (uint32_t i = 0; back && i < w * h * 3; i++) {
        float want = lc_half_to_float(lc_half_from_float(rgb[i]));
        if (back[i] != want) {
            if (bad++ < 5) fprintf(stderr, "value %u: %g, expected %g\n", i, back[i], want);
        }
    }
    CHECK(bad == 0, "%d EXR values differ", bad);
    free(back);

    uint8_t px[7 * 5 * 3];
    for (uint32_t i = 0; i < sizeof px; i++) px[i] = (uint8_t)(i * 37);
    snprintf(path, sizeof path, "%s/a.png", dir);
    CHECK(ctl_image_write_png(path, w, h, px, err, sizeof err) == 0, "write png: %s", err);
    back = NULL;
    CHECK(lc_image_read_rgb(path, 1 << 20, &rw, &rh, &back, err, sizeof err) == 0, "read png: %s", err);
    bad = 0;
    for (uint32_t i = 0; back && i < sizeof px; i++)
        if (lrintf(back[i] * 255.0f) != px[i]) bad++;
    CHECK(bad == 0 && rw == w && rh == h, "%d PNG values differ", bad);
    free(back);
    /* errors name the file */
    CHECK(ctl_image_write_exr_half("/nonexistent-dir/x.exr", w, h, rgb, err, sizeof err) == -1 &&
              strstr(err, "/nonexistent-dir/x.exr"),
          "unwritable: %s", err);
    CHECK(ctl_image_write_exr_half(path, 0, h, rgb, err, sizeof err) == -1, "zero width");
    snprintf(path, sizeof path, "rm -rf %s", dir);
    if (system(path) != 0) fprintf(stderr, "cleanup failed\n");
    CHECK_DONE();
}
