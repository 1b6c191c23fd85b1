/* image_oiio: the OpenImageIO shim behind image.h. C callers never see C++: every entry point
 * catches all exceptions and reports them through err, because an exception crossing into C
 * is undefined behaviour. */
#include "bake/image.h"

#include <OpenImageIO/imageio.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <string>
#include <vector>

namespace {

void set_err(char *err, size_t errlen, const std::string &msg) {
    if (!err || errlen == 0) return;
    std::snprintf(err, errlen, "%s", msg.c_str());
}

std::string lower_ext(const char *path) {
    const char *dot = std::strrchr(path, '.');
    const char *slash = std::strrchr(path, '/');
    if (!dot || (slash && dot < slash)) return std::string();
    std::string e(dot + 1);
    for (char &c : e) c = (char)((c >= 'A' && c <= 'Z') ? c - 'A' + 'a' : c);
    return e;
}

/* OIIO's error strings can carry a trailing newline; messages here are one line. */
std::string one_line(std::string s) {
    while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
    for (char &c : s)
        if (c == '\n') c = ' ';
    return s.empty() ? std::string("unknown OpenImageIO error") : s;
}

} // namespace

extern "C" int lc_image_read_rgb(const char *path, uint64_t max_pixels, uint32_t *width, uint32_t *height,
                                 float **pixels, char *err, size_t errlen) {
    if (pixels) *pixels = nullptr;
    if (!path || !width || !height || !pixels) {
        set_err(err, errlen, "image read: missing argument");
        return -1;
    }
    try {
        auto in = OIIO::ImageInput::open(path);
        if (!in) {
            set_err(err, errlen, std::string(path) + ": cannot read image: " + one_line(OIIO::geterror()));
            return -1;
        }
        const OIIO::ImageSpec &spec = in->spec();
        if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 || spec.depth > 1 || spec.deep) {
            set_err(err, errlen, std::string(path) + ": unsupported image layout (need a flat 2D image)");
            return -1;
        }
        uint64_t w = (uint64_t)spec.width, h = (uint64_t)spec.height, nch = (uint64_t)spec.nchannels;
        if (w * h > max_pixels) {
            set_err(err, errlen,
                    std::string(path) + ": image is " + std::to_string(w) + "x" + std::to_string(h) +
                        ", larger than the " + std::to_string(max_pixels) + "-pixel limit; downsize the texture");
            return -1;
        }
        if (nch > 64) {
            set_err(err, errlen, std::string(path) + ": too many channels (" + std::to_string(nch) + ")");
            return -1;
        }
        std::vector<float> buf((size_t)(w * h * nch));
        if (!in->read_image(0, 0, 0, (int)nch, OIIO::TypeDesc::FLOAT, buf.data())) {
            set_err(err, errlen, std::string(path) + ": cannot decode image: " + one_line(in->geterror()));
            return -1;
        }
        in->close();
        float *out = (float *)std::malloc((size_t)(w * h * 3) * sizeof(float));
        if (!out) {
            set_err(err, errlen,
                    std::string(path) + ": out of memory for " + std::to_string(w) + "x" + std::to_string(h) +
                        " pixels");
            return -1;
        }
        for (uint64_t i = 0; i < w * h; i++) {
            const float *s = buf.data() + i * nch;
            float *d = out + i * 3;
            if (nch >= 3) {
                d[0] = s[0], d[1] = s[1], d[2] = s[2];
            } else { /* grey (+ alpha): replicate the grey */
                d[0] = d[1] = d[2] = s[0];
            }
        }
        *width = (uint32_t)w;
        *height = (uint32_t)h;
        *pixels = out;
        return 0;
    } catch (const std::exception &e) {
        set_err(err, errlen, std::string(path) + ": image read failed: " + e.what());
    } catch (...) {
        set_err(err, errlen, std::string(path) + ": image read failed: unknown exception");
    }
    return -1;
}

namespace {

int image_write(const char *path, uint32_t width, uint32_t height, int nch, const float *pixels, bool exr_float,
                char *err, size_t errlen) {
    if (!path || !pixels || width == 0 || height == 0 || nch < 1 || nch > 4 || width > (1u << 20) ||
        height > (1u << 20)) {
        set_err(err, errlen,
                std::string("image write ") + (path ? path : "(null)") +
                    ": invalid arguments (need 1..4 channels, non-empty size)");
        return -1;
    }
    try {
        std::string ext = lower_ext(path);
        auto out = OIIO::ImageOutput::create(path);
        if (!out) {
            set_err(err, errlen, std::string(path) + ": cannot write this format: " + one_line(OIIO::geterror()));
            return -1;
        }
        OIIO::TypeDesc fmt = OIIO::TypeDesc::UINT8;
        if (ext == "exr") fmt = exr_float ? OIIO::TypeDesc::FLOAT : OIIO::TypeDesc::HALF;
        else if (ext == "hdr" || ext == "tif" || ext == "tiff" || ext == "pfm") fmt = OIIO::TypeDesc::FLOAT;
        OIIO::ImageSpec spec((int)width, (int)height, nch, fmt);
        if (ext == "exr") spec.attribute("compression", "zip");
        if (!out->open(path, spec)) {
            set_err(err, errlen, std::string(path) + ": cannot open for writing: " + one_line(out->geterror()));
            return -1;
        }
        if (!out->write_image(OIIO::TypeDesc::FLOAT, pixels)) {
            set_err(err, errlen, std::string(path) + ": write failed: " + one_line(out->geterror()));
            out->close();
            std::remove(path);
            return -1;
        }
        if (!out->close()) {
            set_err(err, errlen, std::string(path) + ": close failed: " + one_line(out->geterror()));
            std::remove(path);
            return -1;
        }
        return 0;
    } catch (const std::exception &e) {
        set_err(err, errlen, std::string(path) + ": image write failed: " + e.what());
    } catch (...) {
        set_err(err, errlen, std::string(path) + ": image write failed: unknown exception");
    }
    return -1;
}

} // namespace

extern "C" int lc_image_write(const char *path, uint32_t width, uint32_t height, int nch, const float *pixels,
                              char *err, size_t errlen) {
    return image_write(path, width, height, nch, pixels, false, err, errlen);
}

extern "C" int lc_image_write_float(const char *path, uint32_t width, uint32_t height, int nch, const float *pixels,
                                    char *err, size_t errlen) {
    return image_write(path, width, height, nch, pixels, true, err, errlen);
}
