/* image: the C face of the OpenImageIO shim (image_oiio.cpp). All functions catch every
 * C++ exception and report through err. */
#ifndef LC_IMAGE_H
#define LC_IMAGE_H
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Reads an image as float RGB (channels beyond 3 dropped, grey replicated), row 0 = top.
 * Values as stored in the file (no colour-space conversion). *pixels is malloc'd (caller frees).
 * Refuses images larger than max_pixels. Returns 0 or -1 with err set. */
int lc_image_read_rgb(const char *path, uint64_t max_pixels, uint32_t *width, uint32_t *height, float **pixels,
                      char *err, size_t errlen);

/* Writes float pixels (nch channels, row 0 = top) to path; the format follows the extension
 * (.exr written as half float with zip compression; .png as 8-bit, clamped, no transfer curve).
 * Returns 0 or -1 with err set. */
int lc_image_write(const char *path, uint32_t width, uint32_t height, int nch, const float *pixels, char *err,
                   size_t errlen);

/* Same, but .exr is written as 32-bit float (for data that must round-trip exactly, e.g. the
 * reference lightmaps of lucent-ref); other formats as lc_image_write. */
int lc_image_write_float(const char *path, uint32_t width, uint32_t height, int nch, const float *pixels, char *err,
                         size_t errlen);

#ifdef __cplusplus
}
#endif

#endif
