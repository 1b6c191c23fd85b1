/* Helpers the .lcb reader's tests share (test_lcb.c, test_lcb_probes.c): CRC repair after a
 * deliberate corruption, an exact-size open that also prints info both ways, and a seeded
 * xorshift for mutations. */
#ifndef LC_LCB_TEST_UTIL_H
#define LC_LCB_TEST_UTIL_H
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lcb/lcb.h"
#include "util/crc32.h"

/* Recomputes all CRCs so only the semantic check under test can fire. */
static inline void lcb_test_fix_crcs(uint8_t *buf, size_t len) {
    lc_lcb_header *h = (lc_lcb_header *)buf;
    lc_lcb_section *t = (lc_lcb_section *)(buf + 64);
    uint32_t n = h->section_count <= LC_LCB_MAX_SECTIONS ? h->section_count : 0;
    for (uint32_t i = 0; i < n; i++)
        if (t[i].offset <= len && t[i].size <= len - t[i].offset)
            t[i].crc = lc_crc32(0, buf + t[i].offset, (size_t)t[i].size);
    h->table_crc = lc_crc32(0, buf + 64, (size_t)n * sizeof(lc_lcb_section));
    h->header_crc = lc_crc32(0, buf, 60);
}

/* Opens an exact-size copy (so sanitizers see any over-read) and prints info both ways;
 * returns 0 when it opened. */
static inline int lcb_test_try_open(const void *buf, size_t len, char *err, size_t errlen) {
    void *copy = malloc(len ? len : 1);
    if (len) memcpy(copy, buf, len);
    lc_lcb *f = NULL;
    err[0] = 0;
    int rc = lc_lcb_open_memory(copy, len, &f, err, errlen);
    if (rc == 0) {
        FILE *null = fopen("/dev/null", "w");
        lc_lcb_print_info(f, "mem", 0, null);
        lc_lcb_print_info(f, "mem", 1, null);
        fclose(null);
    }
    lc_lcb_close(f);
    free(copy);
    return rc;
}

/* xorshift64, the same sequence in every run. */
static inline uint64_t lcb_test_rnd(void) {
    static uint64_t state = 0x9E3779B97F4A7C15ull;
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return state;
}

#endif
