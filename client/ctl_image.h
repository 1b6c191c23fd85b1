/* lucentctl's image files, without OpenImageIO (which costs ~0.3 s of start-up for every
 * lucentctl run): OpenEXR scanline files with half-float R, G, B channels (uncompressed,
 * the layout of the OpenEXR 2 file format spec) and 8-bit RGB PNG through libpng. */
#ifndef LC_CTL_IMAGE_H
#define LC_CTL_IMAGE_H
#include <stddef.h>
#include <stdint.h>

/* rgb: width*height*3 floats, row 0 = top. Returns 0 or -1 with err set. */
int ctl_image_write_exr_half(const char *path, uint32_t width, uint32_t height, const float *rgb, char *err,
                             size_t errlen);
/* rgb8: width*height*3 bytes (already tone-mapped and encoded). */
int ctl_image_write_png(const char *path, uint32_t width, uint32_t height, const uint8_t *rgb8, char *err,
                        size_t errlen);

/* Reads a PNG of at most max_side pixels a side: grey (1 channel) or RGB (3; palettes are
 * expanded, alpha is dropped), 8 or 16 bits. *pixels (malloc'd, the caller frees) gets
 * width*height*channels values as read (0..255 or 0..65535), row 0 = top. Returns 0, or -1
 * with err naming the file and what is wrong. */
int ctl_image_read_png(const char *path, uint32_t max_side, uint32_t *width, uint32_t *height, int *channels,
                       int *bit_depth, uint16_t **pixels, char *err, size_t errlen);

#endif
