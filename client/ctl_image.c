/* lucentctl's image writers (see ctl_image.h). The EXR is written in one buffer: magic and
 * version, header attributes, the offset table (one u64 per scanline), then each scanline
 * as (int y, int byte count, B row, G row, R row) — channels in the alphabetical order the
 * channel list requires. All integers little-endian. */
#include "ctl_image.h"

#include <errno.h>
#include <png.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/half.h"

typedef struct exr_buf {
    uint8_t *p;
    size_t n, cap;
    int oom;
} exr_buf;

static void put(exr_buf *b, const void *data, size_t n) {
    if (b->oom) return;
    if (b->n + n > b->cap) {
        size_t cap = b->cap ? b->cap : 4096;
        while (cap < b->n + n) cap *= 2;
        uint8_t *q = realloc(b->p, cap);
        if (!q) {
            b->oom = 1;
            return;
        }
        b->p = q;
        b->cap = cap;
    }
    memcpy(b->p + b->n, data, n);
    b->n += n;
}

static void put_u32(exr_buf *b, uint32_t v) {
    uint8_t x[4] = {(uint8_t)v, (uint8_t)(v >> 8), (uint8_t)(v >> 16), (uint8_t)(v >> 24)};
    put(b, x, 4);
}

static void put_u64(exr_buf *b, uint64_t v) {
    put_u32(b, (uint32_t)v);
    put_u32(b, (uint32_t)(v >> 32));
}

static void put_f32(exr_buf *b, float f) {
    uint32_t u;
    memcpy(&u, &f, 4);
    put_u32(b, u);
}

/* An attribute header: name, type, value size. */
static void put_attr(exr_buf *b, const char *name, const char *type, uint32_t size) {
    put(b, name, strlen(name) + 1);
    put(b, type, strlen(type) + 1);
    put_u32(b, size);
}

int ctl_image_write_exr_half(const char *path, uint32_t width, uint32_t height, const float *rgb, char *err,
                             size_t errlen) {
    if (!width || !height || width > (1u << 20) || height > (1u << 20)) {
        snprintf(err, errlen, "%s: bad image size %ux%u", path, width, height);
        return -1;
    }
    exr_buf b = {0};
    put_u32(&b, 20000630); /* magic */
    put_u32(&b, 2);        /* version 2, single-part scanline, short names */
    static const char *const channels[3] = {"B", "G", "R"};
    put_attr(&b, "channels", "chlist", 3 * (2 + 16) + 1);
    for (int c = 0; c < 3; c++) {
        put(&b, channels[c], 2);
        put_u32(&b, 1);         /* pixel type HALF */
        put(&b, "\0\0\0\0", 4); /* pLinear + reserved */
        put_u32(&b, 1);         /* x sampling */
        put_u32(&b, 1);         /* y sampling */
    }
    put(&b, "", 1);
    put_attr(&b, "compression", "compression", 1);
    put(&b, "", 1); /* NO_COMPRESSION */
    const uint32_t box[4] = {0, 0, width - 1, height - 1};
    put_attr(&b, "dataWindow", "box2i", 16);
    for (int i = 0; i < 4; i++) put_u32(&b, box[i]);
    put_attr(&b, "displayWindow", "box2i", 16);
    for (int i = 0; i < 4; i++) put_u32(&b, box[i]);
    put_attr(&b, "lineOrder", "lineOrder", 1);
    put(&b, "", 1); /* INCREASING_Y */
    put_attr(&b, "pixelAspectRatio", "float", 4);
    put_f32(&b, 1.0f);
    put_attr(&b, "screenWindowCenter", "v2f", 8);
    put_f32(&b, 0.0f);
    put_f32(&b, 0.0f);
    put_attr(&b, "screenWindowWidth", "float", 4);
    put_f32(&b, 1.0f);
    put(&b, "", 1); /* end of header */

    uint32_t line_bytes = width * 3 * 2;
    uint64_t first = b.n + (uint64_t)height * 8;
    for (uint32_t y = 0; y < height; y++) put_u64(&b, first + (uint64_t)y * (8 + line_bytes));
    uint16_t *row = malloc((size_t)width * sizeof *row);
    if (!row) b.oom = 1;
    for (uint32_t y = 0; y < height && !b.oom; y++) {
        put_u32(&b, y);
        put_u32(&b, line_bytes);
        for (int c = 0; c < 3; c++) {
            int ch = 2 - c; /* B, G, R */
            for (uint32_t x = 0; x < width; x++) {
                uint16_t h = lc_half_from_float(rgb[3 * ((size_t)y * width + x) + (size_t)ch]);
                uint8_t le[2] = {(uint8_t)h, (uint8_t)(h >> 8)};
                memcpy(&row[x], le, 2);
            }
            put(&b, row, (size_t)width * 2);
        }
    }
    free(row);
    int rc = -1;
    if (b.oom) {
        snprintf(err, errlen, "%s: out of memory", path);
        goto out;
    }
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(b.p, 1, b.n, f) != b.n || fclose(f) != 0) {
        snprintf(err, errlen, "cannot write %s: %s", path, strerror(errno));
        goto out;
    }
    rc = 0;
out:
    free(b.p);
    return rc;
}

int ctl_image_write_png(const char *path, uint32_t width, uint32_t height, const uint8_t *rgb8, char *err,
                        size_t errlen) {
    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    img.width = width;
    img.height = height;
    img.format = PNG_FORMAT_RGB;
    if (!png_image_write_to_file(&img, path, 0, rgb8, 0, NULL)) {
        snprintf(err, errlen, "cannot write %s: %s", path, img.message[0] ? img.message : strerror(errno));
        png_image_free(&img);
        return -1;
    }
    return 0;
}

/* libpng reports errors by longjmp; the message is kept for the caller. */
typedef struct png_read_ctx {
    jmp_buf jmp;
    char msg[160];
} png_read_ctx;

static void png_read_on_error(png_structp png, png_const_charp msg) {
    png_read_ctx *ctx = png_get_error_ptr(png);
    snprintf(ctx->msg, sizeof ctx->msg, "%s", msg);
    longjmp(ctx->jmp, 1);
}

static void png_read_on_warning(png_structp png, png_const_charp msg) {
    (void)png;
    (void)msg;
}

int ctl_image_read_png(const char *path, uint32_t max_side, uint32_t *width, uint32_t *height, int *channels,
                       int *bit_depth, uint16_t **pixels, char *err, size_t errlen) {
    *pixels = NULL;
    png_read_ctx ctx = {.msg = ""};
    png_structp png = NULL;
    png_infop info = NULL;
    uint8_t *volatile raw = NULL;
    uint16_t *volatile out = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) {
        snprintf(err, errlen, "cannot read %s: %s", path, strerror(errno));
        return -1;
    }
    png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &ctx, png_read_on_error, png_read_on_warning);
    info = png ? png_create_info_struct(png) : NULL;
    if (!info) {
        snprintf(ctx.msg, sizeof ctx.msg, "out of memory");
        goto err;
    }
    if (setjmp(ctx.jmp)) goto err;
    png_init_io(png, f);
    png_read_info(png, info);
    uint32_t w = png_get_image_width(png, info), h = png_get_image_height(png, info);
    int type = png_get_color_type(png, info), depth = png_get_bit_depth(png, info);
    if (!w || !h || w > max_side || h > max_side) {
        snprintf(ctx.msg, sizeof ctx.msg, "size %ux%u is outside 1..%u", w, h, max_side);
        goto err;
    }
    if (type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
    if (type == PNG_COLOR_TYPE_GRAY && depth < 8) png_set_expand_gray_1_2_4_to_8(png);
    if (type & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
    if (depth == 16) png_set_swap(png); /* host (little-endian) order */
    png_read_update_info(png, info);
    int ch = png_get_channels(png, info), bd = png_get_bit_depth(png, info);
    if ((ch != 1 && ch != 3) || (bd != 8 && bd != 16)) {
        snprintf(ctx.msg, sizeof ctx.msg, "unsupported layout (%d channels of %d bits)", ch, bd);
        goto err;
    }
    size_t row_bytes = png_get_rowbytes(png, info), n = (size_t)w * h * (size_t)ch;
    raw = malloc(row_bytes * h);
    out = malloc(n * sizeof *out);
    if (!raw || !out) {
        snprintf(ctx.msg, sizeof ctx.msg, "out of memory");
        goto err;
    }
    for (uint32_t y = 0; y < h; y++) png_read_row(png, raw + (size_t)y * row_bytes, NULL);
    for (uint32_t y = 0; y < h; y++) {
        const uint8_t *r = raw + (size_t)y * row_bytes;
        for (size_t i = 0; i < (size_t)w * (size_t)ch; i++) {
            uint16_t v = r[i];
            if (bd == 16) memcpy(&v, r + 2 * i, 2);
            out[(size_t)y * w * (size_t)ch + i] = v;
        }
    }
    png_destroy_read_struct(&png, &info, NULL);
    fclose(f);
    free(raw);
    *width = w;
    *height = h;
    *channels = ch;
    *bit_depth = bd;
    *pixels = out;
    return 0;
err:
    snprintf(err, errlen, "%s: not a readable PNG: %s", path, ctx.msg);
    png_destroy_read_struct(&png, info ? &info : NULL, NULL);
    fclose(f);
    free(raw);
    free(out);
    return -1;
}
