/* Fuzz target: liblucent-proto's parsers. The same bytes go through the request parser
 * (default limits), the state (snapshot) parser and the binary frame parser. Must never
 * crash, leak or read out of bounds; errors are fine. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "lucent_proto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    /* a private copy so that reads past `size` are caught by ASan */
    char *text = malloc(size ? size : 1);
    if (!text) return 0;
    memcpy(text, data, size);
    lc_proto_limits lim;
    lc_proto_default_limits(&lim);
    lc_proto_request req;
    lc_proto_error err;
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
        char *e = lc_proto_build_error(&req.id, &err);
        free(e);
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
            lc_proto_state s = {st.revision, st.lights, st.n_lights, st.objects, st.n_objects, ms,
                                st.n_materials, st.environment, st.settings};
            char *out = lc_proto_build_state(NULL, &s);
            lc_proto_parsed_state again;
            if (out && lc_proto_parse_state(out, strlen(out), &again, &err) != 0) abort();
            lc_proto_parsed_state_free(&again);
            free(out);
            free(ms);
        }
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
