/* Fuzz target: liblucent-proto's parsers. The same bytes go through the request parser
 * (default limits), the state (snapshot) parser, the binary frame parser and the UTF-8
 * helpers. Must never crash, leak or read out of bounds; errors are fine. Properties checked
 * (abort on failure): accepted changes survive the journal round trip, accepted states
 * rebuild and reparse, and every reply built from the input — the `error` for a refused
 * request above all, which quotes client text — is valid UTF-8. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "lucent_proto.h"

/* A built reply must be valid UTF-8 (a WebSocket peer closes with 1007 otherwise). */
static void fuzz_check_utf8(char *msg) {
    if (msg && !lc_proto_utf8_valid(msg, strlen(msg))) abort();
    free(msg);
}

/* The helpers on raw bytes: a sanitised copy is valid; a cut of valid text is valid. */
static void fuzz_utf8_helpers(const char *text, size_t size) {
    char out[300];
    size_t n = size < 256 ? size : 256;
    size_t used = lc_proto_utf8_sanitize(out, sizeof out, text, n, n & 1 ? LC_PROTO_UTF8_NO_CONTROLS : 0);
    if (used > n || !lc_proto_utf8_valid(out, strlen(out))) abort();
    int valid = lc_proto_utf8_valid(text, size);
    for (size_t max = 0; max <= 8 && max <= size; max++) {
        size_t cut = lc_proto_utf8_cut(text, size, size - max);
        if (cut > size - max || (valid && !lc_proto_utf8_valid(text, cut))) abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    /* a private copy so that reads past `size` are caught by ASan */
    char *text = malloc(size ? size : 1);
    if (!text) return 0;
    memcpy(text, data, size);
    lc_proto_limits lim;
    lc_proto_default_limits(&lim);
    lc_proto_request req;
    lc_proto_error err;
    fuzz_utf8_helpers(text, size);
    if (lc_proto_parse_request(text, size, &lim, &req, &err) == 0) {
        /* accepted changes must survive the journal round trip */
        for (uint32_t i = 0; i < req.n_ops; i++) {
            char *op = lc_proto_build_op(&req.ops[i]);
            if (op) {
                lc_proto_request again;
                if (lc_proto_parse_request(op, strlen(op), NULL, &again, &err) != 0) abort();
                lc_proto_request_release(&again);
                free(op);
            }
        }
        fuzz_check_utf8(lc_proto_build_ok(&req.id, 1));
        fuzz_check_utf8(lc_proto_build_changed(1, req.type == LC_REQ_HELLO ? req.client : "fuzz", req.ops, req.n_ops));
    } else {
        /* the refusal the daemon sends: echoes the id, quotes client text in the message */
        fuzz_check_utf8(lc_proto_build_error(&req.id, &err));
    }
    lc_proto_request_release(&req);
    lc_proto_parsed_state st;
    if (lc_proto_parse_state(text, size, &st, &err) == 0) {
        lc_proto_material_state *ms = calloc(st.n_materials ? st.n_materials : 1, sizeof *ms);
        if (ms) {
            for (uint32_t i = 0; i < st.n_materials; i++) {
                ms[i].name = st.material_names[i];
                memcpy(ms[i].emission, st.material_emission[i], sizeof ms[i].emission);
            }
            lc_proto_state s = {st.revision, st.lights,      st.n_lights,    st.objects, st.n_objects,
                                ms,          st.n_materials, st.environment, st.settings};
            char *out = lc_proto_build_state(NULL, &s);
            lc_proto_parsed_state again;
            if (out && !lc_proto_utf8_valid(out, strlen(out))) abort();
            if (out && lc_proto_parse_state(out, strlen(out), &again, &err) != 0) abort();
            lc_proto_parsed_state_free(&again);
            free(out);
            free(ms);
        }
    } else {
        fuzz_check_utf8(lc_proto_build_error(NULL, &err));
    }
    lc_proto_parsed_state_free(&st);
    free(text);
    lc_frame_header h;
    const uint8_t *tiles, *payload;
    uint8_t *copy = malloc(size ? size : 1);
    if (!copy) return 0;
    memcpy(copy, data, size);
    lc_frame_parse(copy, size, &h, &tiles, &payload, &err);
    free(copy);
    return 0;
}
