/* Fuzz target: lucent-bake's command line (the option table parser). Input bytes are split
 * on NUL/newline into argv words. Must never crash; errors are fine. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "bake/bake.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size > 4096) return 0;
    char *buf = malloc(size + 1);
    if (!buf) return 0;
    memcpy(buf, data, size);
    buf[size] = 0;
    char *argv[66];
    int argc = 0;
    argv[argc++] = "lucent-bake";
    argv[argc++] = "bake";
    char *p = buf;
    while (argc < 64 && p < buf + size) {
        argv[argc++] = p;
        size_t len = strcspn(p, "\n");
        p[len] = 0;
        p += len + 1;
    }
    argv[argc] = NULL;
    static lc_bake_settings s;
    char *pos[4];
    char err[256];
    lc_bake_parse_args(&s, argc, argv, 2, pos, 4, err, sizeof err);
    free(buf);
    return 0;
}
