/* utf8: strict UTF-8 (RFC 3629: no overlong forms, no surrogates, nothing above U+10FFFF)
 * — a check, a cut on a character boundary and a sanitising copy. Header-only so that the
 * protocol library (lc_proto_utf8_*), the .lcb reader and the importer share one
 * definition without a link dependency between them. Every function takes a length; none
 * reads past it. */
#ifndef LC_UTF8_H
#define LC_UTF8_H
#include <stddef.h>
#include <string.h>

/* Length (1..4) of the well-formed sequence at s (n > 0 bytes left), or 0. */
static inline size_t lc_utf8_seq(const unsigned char *s, size_t n) {
    unsigned c = s[0];
    if (c < 0x80) return 1;
    size_t len;
    unsigned lo = 0x80, hi = 0xBF; /* allowed range of the second byte (Unicode table 3-7) */
    if (c >= 0xC2 && c <= 0xDF) {
        len = 2;
    } else if (c >= 0xE0 && c <= 0xEF) {
        len = 3;
        if (c == 0xE0) lo = 0xA0; /* overlong */
        if (c == 0xED) hi = 0x9F; /* surrogates U+D800..U+DFFF */
    } else if (c >= 0xF0 && c <= 0xF4) {
        len = 4;
        if (c == 0xF0) lo = 0x90; /* overlong */
        if (c == 0xF4) hi = 0x8F; /* above U+10FFFF */
    } else {
        return 0; /* continuation byte, C0/C1 (overlong), F5..FF */
    }
    if (n < len || s[1] < lo || s[1] > hi) return 0;
    for (size_t k = 2; k < len; k++)
        if (s[k] < 0x80 || s[k] > 0xBF) return 0;
    return len;
}

/* At an ill-formed position (lc_utf8_seq() == 0): the length of its maximal subpart (the
 * longest prefix of a well-formed sequence, at least 1 byte: one U+FFFD each, as Unicode
 * §3.9 recommends). *at_end = 1 when that prefix was cut short by the end of the input (a
 * sequence truncated by `n`, not by a bad byte). */
static inline size_t lc_utf8_subpart(const unsigned char *s, size_t n, int *at_end) {
    unsigned c = s[0];
    size_t len;
    unsigned lo = 0x80, hi = 0xBF;
    *at_end = 0;
    if (c >= 0xC2 && c <= 0xDF) {
        len = 2;
    } else if (c >= 0xE0 && c <= 0xEF) {
        len = 3;
        if (c == 0xE0) lo = 0xA0;
        if (c == 0xED) hi = 0x9F;
    } else if (c >= 0xF0 && c <= 0xF4) {
        len = 4;
        if (c == 0xF0) lo = 0x90;
        if (c == 0xF4) hi = 0x8F;
    } else {
        return 1;
    }
    size_t k = 1;
    while (k < len && k < n && s[k] >= (k == 1 ? lo : 0x80) && s[k] <= (k == 1 ? hi : 0xBF)) k++;
    if (k < len && k == n) *at_end = 1;
    return k;
}

/* 1 when s[0, len) is well-formed UTF-8 (NUL bytes are characters like any other). */
static inline int lc_utf8_valid(const char *s, size_t len) {
    const unsigned char *u = (const unsigned char *)s;
    for (size_t i = 0; i < len;) {
        size_t k = lc_utf8_seq(u + i, len - i);
        if (!k) return 0;
        i += k;
    }
    return 1;
}

/* The longest prefix of s[0, len) of at most `max` bytes that ends on a character boundary:
 * never inside a multi-byte sequence, and never inside one that `len` cuts short. For
 * well-formed input the prefix is well-formed; ill-formed bytes elsewhere count as units of
 * their own (they are not repaired here: see lc_utf8_sanitize). */
static inline size_t lc_utf8_cut(const char *s, size_t len, size_t max) {
    const unsigned char *u = (const unsigned char *)s;
    size_t i = 0;
    while (i < len) {
        size_t k = lc_utf8_seq(u + i, len - i);
        if (!k) {
            int at_end;
            k = lc_utf8_subpart(u + i, len - i, &at_end);
            if (at_end) break;
        }
        if (k > max - i) break;
        i += k;
    }
    return i;
}

enum { LC_UTF8_NO_CONTROLS = 1u << 0 }; /* lc_utf8_sanitize: also replace C0, DEL and C1 */

/* Copies s[0, len) into dst (cap bytes, NUL-terminated when cap > 0) as well-formed UTF-8:
 * each maximal ill-formed subpart becomes U+FFFD, and with LC_UTF8_NO_CONTROLS so does each
 * control character (U+0000..U+001F, U+007F..U+009F). Stops before the first character that
 * does not fit, so the output never ends inside a character. Returns the number of input
 * bytes consumed (len when everything fit). */
static inline size_t lc_utf8_sanitize(char *dst, size_t cap, const char *s, size_t len, unsigned flags) {
    static const char repl[3] = {(char)0xEF, (char)0xBF, (char)0xBD};
    const unsigned char *u = (const unsigned char *)s;
    size_t i = 0, o = 0;
    if (!cap) return 0;
    while (i < len) {
        const char *src = s + i;
        size_t k = lc_utf8_seq(u + i, len - i), w = k;
        if (!k) {
            int at_end;
            k = lc_utf8_subpart(u + i, len - i, &at_end);
            src = repl, w = 3;
        } else if ((flags & LC_UTF8_NO_CONTROLS) &&
                   (u[i] < 0x20 || u[i] == 0x7F || (u[i] == 0xC2 && u[i + 1] < 0xA0))) {
            src = repl, w = 3;
        }
        if (w > cap - 1 - o) break;
        memcpy(dst + o, src, w);
        o += w;
        i += k;
    }
    dst[o] = 0;
    return i;
}

#endif
