/* Fuzz target: lucentd's --cluster URL (lc_cluster_parse_url). Must never crash or read past
 * the input (it takes a length, no NUL); on success every field is NUL-terminated and the key
 * is non-empty. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "cluster.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    if (size > 4096) return 0;
    char *buf = malloc(size ? size : 1); /* exactly size bytes: ASan sees any overread */
    if (!buf) return 0;
    memcpy(buf, data, size);
    lc_cluster_url u;
    char err[256];
    if (lc_cluster_parse_url(buf, size, &u, err, sizeof err) == 0) {
        if (!u.key[0] || !u.host[0] || u.port < 1 || u.port > 65535) abort();
        if (strlen(u.key) > LC_CLUSTER_KEY_MAX || strlen(u.password) >= sizeof u.password) abort();
    }
    free(buf);
    return 0;
}
