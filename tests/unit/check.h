/* check.h: a minimal assertion harness for lucent unit tests.
 * CHECK(cond, fmt, ...) records a failure and continues; tests end with CHECK_DONE(). */
#ifndef LC_CHECK_H
#define LC_CHECK_H
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int check_failures = 0;
static int check_count = 0;

#define CHECK(cond, ...)                                                    \
    do {                                                                    \
        check_count++;                                                      \
        if (!(cond)) {                                                      \
            check_failures++;                                               \
            fprintf(stderr, "FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                                   \
            fputc('\n', stderr);                                            \
        }                                                                   \
    } while (0)

/* |a - b| <= tol * max(1, |b|) */
#define CHECK_NEAR(a, b, tol)                                                                                         \
    CHECK(fabs((double)(a) - (double)(b)) <= (tol)*fmax(1.0, fabs((double)(b))), "%s = %.9g, expected %.9g (tol %g)", \
          #a, (double)(a), (double)(b), (double)(tol))

#define CHECK_DONE()                                                            \
    do {                                                                        \
        fprintf(stderr, "%d checks, %d failed\n", check_count, check_failures); \
        return check_failures ? 1 : 0;                                          \
    } while (0)

#define CHECK_SKIP_RC 77

/* Path under ../shared (from LUCENT_SHARED_DIR), or NULL when it does not exist. */
static inline const char *check_shared_path(const char *rel, char *buf, size_t len) {
    const char *dir = getenv("LUCENT_SHARED_DIR");
    if (!dir) dir = "../shared";
    snprintf(buf, len, "%s/%s", dir, rel);
    FILE *f = fopen(buf, "rb");
    if (!f) return NULL;
    fclose(f);
    return buf;
}

/* Path of a file in the source tree (LUCENT_SOURCE_DIR). */
static inline const char *check_source_path(const char *rel, char *buf, size_t len) {
    const char *dir = getenv("LUCENT_SOURCE_DIR");
    snprintf(buf, len, "%s/%s", dir ? dir : ".", rel);
    return buf;
}

#endif
