/* CRC-32, binary16, the option table, parallel-for and atomic file writes. */
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>
#include <unistd.h>

#include "check.h"
#include "util/crc32.h"
#include "util/fsutil.h"
#include "util/half.h"
#include "util/opt.h"
#include "util/parallel.h"

typedef struct {
    int n;
    double x;
    int flag;
    char name[8];
    int mode;
} test_settings;

static const lc_opt test_opts[] = {
    {"n", LC_OPT_INT, offsetof(test_settings, n), 1, 10, "5", NULL, "a count", NULL, NULL},
    {"x", LC_OPT_FLOAT, offsetof(test_settings, x), -1, 1, "0.5", NULL, "a ratio", NULL, NULL},
    {"flag", LC_OPT_BOOL, offsetof(test_settings, flag), 0, 1, "false", NULL, "a switch", NULL, NULL},
    {"name", LC_OPT_STRING, offsetof(test_settings, name), 1, 8, "abc", NULL, "a name", NULL, NULL},
    {"mode", LC_OPT_ENUM, offsetof(test_settings, mode), 0, 0, "b", "a|b|c", "a mode", NULL, NULL},
    {NULL, 0, 0, 0, 0, NULL, NULL, NULL, NULL, NULL},
};

static _Atomic long parallel_sum;
static _Atomic int parallel_max_thread; /* the largest worker index a loop handed out */
static void sum_range(void *ctx, size_t b, size_t e, int t) {
    int seen = atomic_load(&parallel_max_thread);
    while (t > seen && !atomic_compare_exchange_weak(&parallel_max_thread, &seen, t)) {
    }
    int *hits = ctx;
    for (size_t i = b; i < e; i++) {
        hits[i]++;
        atomic_fetch_add(&parallel_sum, (long)i);
    }
}

int main(void) {
    CHECK(lc_crc32(0, "123456789", 9) == 0xCBF43926u, "crc32 check value");
    CHECK(lc_crc32(lc_crc32(0, "1234", 4), "56789", 5) == 0xCBF43926u, "crc32 incremental");
    CHECK(lc_crc32(0, "", 0) == 0, "crc32 empty");

    float vals[] = {0.0f, 1.0f, -2.5f, 65504.0f, 6.1035156e-05f, 5.9604645e-08f, 0.1f, 3.14159f};
    for (int i = 0; i < 8; i++) {
        float back = lc_half_to_float(lc_half_from_float(vals[i]));
        CHECK(fabsf(back - vals[i]) <= fabsf(vals[i]) * 1e-3f, "half round trip %g -> %g", vals[i], back);
    }
    CHECK(lc_half_from_float(1.0f) == 0x3C00, "half(1) bits");
    CHECK(lc_half_from_float(1e6f) == 0x7C00, "half overflow is inf");
    CHECK(isnan(lc_half_to_float(lc_half_from_float(NAN))), "half NaN");
    for (uint32_t h = 0; h < 0x7C00; h++) { /* every finite positive half round-trips exactly */
        if (lc_half_from_float(lc_half_to_float((uint16_t)h)) != h) {
            CHECK(0, "half bits 0x%04x do not round-trip", h);
            break;
        }
    }

    test_settings s;
    char err[256];
    CHECK(lc_opt_defaults(test_opts, &s, err, sizeof err) == 0, "defaults: %s", err);
    CHECK(s.n == 5 && s.x == 0.5 && !s.flag && !strcmp(s.name, "abc") && s.mode == 1, "default values");
    char *argv[] = {"prog", "--n", "7", "pos1", "--x=-0.25", "--flag", "--mode", "c", "--", "--pos2"};
    char *pos[4];
    int np = lc_opt_parse(test_opts, &s, 10, argv, 1, pos, 4, err, sizeof err);
    CHECK(np == 2 && !strcmp(pos[0], "pos1") && !strcmp(pos[1], "--pos2"), "positional: %d", np);
    CHECK(s.n == 7 && s.x == -0.25 && s.flag && s.mode == 2, "parsed values");
    CHECK(lc_opt_set(test_opts, &s, "n", "11", err, sizeof err) == -1 && strstr(err, "--n"), "bounds: %s", err);
    CHECK(lc_opt_set(test_opts, &s, "x", "inf", err, sizeof err) == -1, "non-finite rejected");
    CHECK(lc_opt_set(test_opts, &s, "x", "0.1junk", err, sizeof err) == -1, "trailing junk rejected");
    CHECK(lc_opt_set(test_opts, &s, "name", "12345678", err, sizeof err) == -1, "string cap");
    CHECK(lc_opt_set(test_opts, &s, "mode", "d", err, sizeof err) == -1 && strstr(err, "a|b|c"), "enum");
    CHECK(lc_opt_set(test_opts, &s, "nope", "1", err, sizeof err) == -1 && strstr(err, "unknown"), "unknown");
    char *argv2[] = {"prog", "--no-flag", "--n"};
    CHECK(lc_opt_parse(test_opts, &s, 2, argv2, 1, pos, 4, err, sizeof err) == 0 && !s.flag, "--no-flag");
    CHECK(lc_opt_parse(test_opts, &s, 3, argv2, 1, pos, 4, err, sizeof err) == -1 && strstr(err, "needs a value"),
          "missing value: %s", err);

    enum { N = 100003 };
    static int hits[N];
    lc_parallel_for(3, N, 1000, sum_range, hits);
    int once = 1;
    for (int i = 0; i < N; i++) once &= hits[i] == 1;
    CHECK(once, "parallel_for visits every index exactly once");
    CHECK(parallel_sum == (long)N * (N - 1) / 2, "parallel sum");
    CHECK(parallel_max_thread < 3, "3 threads: worker index %d", parallel_max_thread);
    /* Each loop takes its own count: nothing carries over from the previous one. */
    atomic_store(&parallel_max_thread, 0);
    lc_parallel_for(1, N, 1000, sum_range, hits);
    CHECK(parallel_max_thread == 0, "1 thread: worker index %d", parallel_max_thread);
    for (int i = 0; i < N; i++) once &= hits[i] == 2;
    CHECK(once, "parallel_for(1) visits every index exactly once");
    CHECK(lc_parallel_threads(3) == 3 && lc_parallel_threads(0) >= 1 &&
              lc_parallel_threads(-1) == lc_parallel_threads(0) && lc_parallel_threads(100000) == 256,
          "lc_parallel_threads: 3 -> %d, 0 -> %d, 1e5 -> %d", lc_parallel_threads(3), lc_parallel_threads(0),
          lc_parallel_threads(100000));

    char dir[] = "/tmp/lc_fs_XXXXXX";
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    char path[256];
    snprintf(path, sizeof path, "%s/f.txt", dir);
    CHECK(lc_fs_write_atomic(path, "old", 3, err, sizeof err) == 0, "write: %s", err);
    lc_fs_writer *w = lc_fs_writer_open(path, err, sizeof err);
    lc_fs_writer_write(w, "new-partial", 11);
    lc_fs_writer_abort(w); /* a crash mid-write: the old file stays */
    size_t len = 0;
    char *got = lc_fs_read(path, 100, &len, err, sizeof err);
    CHECK(got && len == 3 && !memcmp(got, "old", 3), "abort keeps the previous file");
    free(got);
    CHECK(lc_fs_read(path, 2, &len, err, sizeof err) == NULL && strstr(err, "limit"), "read cap");
    unlink(path);
    rmdir(dir);
    CHECK_DONE();
}
