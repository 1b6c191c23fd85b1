/* Fuzz target: lucentctl's script parser (JSON Lines with "at" times), fed the input as a
 * file. Must never crash or leak; malformed lines are reported, which is fine. stderr goes
 * to /dev/null so the fuzzer's output stays readable. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ctl.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    static int quiet = 0;
    if (!quiet) {
        quiet = 1;
        if (!freopen("/dev/null", "w", stderr)) return 0;
    }
    /* a private copy so that reads past `size` are caught by ASan */
    char *copy = malloc(size ? size : 1);
    if (!copy) return 0;
    memcpy(copy, data, size);
    FILE *f = fmemopen(copy, size ? size : 1, "r");
    if (f) {
        size_t messages = 0;
        long errors = 0;
        if (size == 0) fgetc(f); /* an empty file: fmemopen needs a non-zero size */
        ctl_script_validate(f, "fuzz.jsonl", &messages, &errors);
        fclose(f);
    }
    free(copy);
    return 0;
}
