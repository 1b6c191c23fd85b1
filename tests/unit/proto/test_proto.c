/* liblucent-proto: request parsing (valid forms, defaults, every error code with its
 * pointer), builders, state round trip, binary frames, RGB9E5 and tiles. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "check.h"
#include "lucent_proto.h"
#include "lucent_upload.h"
#include "util/crc32.h"
#include "util/half.h"

static int parse(const char *s, lc_proto_request *r, lc_proto_error *e) {
    return lc_proto_parse_request(s, strlen(s), NULL, r, e);
}

/* Parses a valid message; the caller releases r. */
#define PARSE_OK(json, r)                                                       \
    do {                                                                        \
        lc_proto_error e_;                                                      \
        int rc_ = parse(json, r, &e_);                                          \
        CHECK(rc_ == 0, "%s: %s %s %s", json, e_.code, e_.pointer, e_.message); \
    } while (0)

static void expect_err_len(int line, const char *json, size_t len, const char *code, const char *ptr) {
    lc_proto_request r;
    lc_proto_error e;
    int rc = lc_proto_parse_request(json, len, NULL, &r, &e);
    CHECK(rc == -1, "line %d: %.80s: parsed but should fail", line, json);
    CHECK(!strcmp(e.code, code), "line %d: %.80s: code %s, expected %s (%s)", line, json, e.code, code, e.message);
    CHECK(!strcmp(e.pointer, ptr), "line %d: %.80s: pointer '%s', expected '%s'", line, json, e.pointer, ptr);
    CHECK(r.ops == NULL && r.n_ops == 0, "line %d: ops left after failure", line);
    lc_proto_request_release(&r);
}
#define EXPECT_ERR(json, code, ptr) expect_err_len(__LINE__, json, strlen(json), code, ptr)

static int n_invalid_cases = 0;
#define INVALID(json, code, ptr) (n_invalid_cases++, EXPECT_ERR(json, code, ptr))

#define LIGHT_PT "\"position\":[0,1,0]"

static void test_valid(void) {
    lc_proto_request r;

    PARSE_OK(
        "{\"type\":\"hello\",\"id\":1,\"client\":\"my-viewer/2.0\",\"token\":\"tok\",\"encodings\":[\"rgb9e5\",\"f32\",\"future\"]}",
        &r);
    CHECK(r.type == LC_REQ_HELLO && r.id.kind == 2 && r.id.num == 1, "hello id");
    CHECK(!strcmp(r.client, "my-viewer/2.0") && !strcmp(r.token, "tok"), "hello strings");
    CHECK(r.encodings == ((1u << LC_ENC_RGB9E5) | (1u << LC_ENC_F32)), "encodings %x", r.encodings);
    CHECK(!lc_proto_is_change(r.type), "hello is not a change");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"hello\",\"client\":\"c\"}", &r);
    CHECK(r.token[0] == 0 && r.encodings == 0 && r.id.kind == 0, "hello defaults");
    lc_proto_request_release(&r);

    PARSE_OK("{\"type\":\"subscribe\",\"id\":\"s1\",\"stream\":\"lightmap\"}", &r);
    CHECK(r.type == LC_REQ_SUBSCRIBE && r.stream == LC_STREAM_LIGHTMAP && r.encoding == LC_ENC_RGB9E5, "sub lm");
    CHECK(r.max_rate == 0 && r.id.kind == 1 && !strcmp(r.id.str, "s1") && !r.residual, "sub defaults");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"subscribe\",\"stream\":\"lightmap\",\"delta\":\"residual\"}", &r);
    CHECK(r.residual, "residual deltas");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"subscribe\",\"stream\":\"lightmap\",\"delta\":\"tiles\"}", &r);
    CHECK(!r.residual, "tile deltas");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"subscribe\",\"stream\":\"shgrid\"}", &r);
    CHECK(r.stream == LC_STREAM_SHGRID && r.encoding == LC_ENC_F32, "shgrid default f32");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"subscribe\",\"stream\":\"objects\",\"encoding\":\"rgba16f\",\"max_rate\":30.5}", &r);
    CHECK(r.stream == LC_STREAM_OBJECTS && r.encoding == LC_ENC_RGBA16F && r.max_rate == 30.5, "objects");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"unsubscribe\",\"stream\":\"objects\"}", &r);
    CHECK(r.type == LC_REQ_UNSUBSCRIBE && r.stream == LC_STREAM_OBJECTS, "unsub");
    lc_proto_request_release(&r);

    /* point light: defaults */
    PARSE_OK("{\"type\":\"light.set\",\"light\":{\"id\":\"l1\",\"type\":\"point\",\"position\":[1,2,3]}}", &r);
    CHECK(r.type == LC_REQ_LIGHT_SET && r.n_ops == 1 && r.ops[0].type == LC_REQ_LIGHT_SET, "light.set");
    if (r.n_ops == 1) {
        const lc_proto_light *L = &r.ops[0].light;
        CHECK(!strcmp(L->id, "l1") && !strcmp(r.ops[0].target, "l1") && L->type == LC_PLIGHT_POINT, "ids");
        CHECK(L->color[0] == 1 && L->color[1] == 1 && L->color[2] == 1, "default colour");
        CHECK(L->intensity == 1 && L->range == 0, "default intensity/range");
        CHECK(L->position[0] == 1 && L->position[1] == 2 && L->position[2] == 3, "position");
        CHECK_NEAR(L->inner_cone, 0, 1e-7);
        CHECK_NEAR(L->outer_cone, M_PI / 4, 1e-7);
        CHECK(L->shape == 0 && L->size[0] == 1 && L->size[1] == 1, "default shape/size");
        CHECK(L->tangent[0] == 0 && L->tangent[1] == 0 && L->tangent[2] == 0, "tangent zero");
    }
    CHECK(lc_proto_is_change(r.type), "light.set is a change");
    lc_proto_request_release(&r);

    /* spot: direction normalised, cones */
    PARSE_OK(
        "{\"type\":\"light.set\",\"light\":{\"id\":\"s\",\"type\":\"spot\",\"position\":[0,3,0],\"direction\":[0,-2,0],"
        "\"color\":[1,0.5,0.25],\"intensity\":800,\"range\":20,\"innerConeAngle\":0.2,\"outerConeAngle\":0.5,\"extra\":{\"x\":1}}}",
        &r);
    if (r.n_ops == 1) {
        const lc_proto_light *L = &r.ops[0].light;
        CHECK(L->type == LC_PLIGHT_SPOT && L->direction[1] == -1 && L->direction[0] == 0, "spot dir");
        CHECK(L->color[1] == 0.5f && L->intensity == 800 && L->range == 20, "spot values");
        CHECK(L->inner_cone == 0.2f && L->outer_cone == 0.5f, "cones");
    }
    lc_proto_request_release(&r);
    /* inner wider than the default outer: outer follows */
    PARSE_OK(
        "{\"type\":\"light.set\",\"light\":{\"id\":\"s\",\"type\":\"spot\",\"position\":[0,3,0],\"direction\":[1,1,0],\"innerConeAngle\":1.2}}",
        &r);
    if (r.n_ops == 1) {
        CHECK(r.ops[0].light.outer_cone == 1.2f, "outer = inner");
        CHECK_NEAR(r.ops[0].light.direction[0], sqrt(0.5), 1e-6);
    }
    lc_proto_request_release(&r);
    /* outer exactly π/2 as a float prints a bit above π/2: still accepted */
    PARSE_OK(
        "{\"type\":\"light.set\",\"light\":{\"id\":\"s\",\"type\":\"spot\",\"position\":[0,3,0],\"direction\":[1,0,0],\"outerConeAngle\":1.57079637}}",
        &r);
    lc_proto_request_release(&r);

    PARSE_OK(
        "{\"type\":\"light.set\",\"light\":{\"id\":\"sun\",\"type\":\"directional\",\"direction\":[0,0,-1e-300],\"intensity\":1e5}}",
        &r);
    if (r.n_ops == 1)
        CHECK(r.ops[0].light.direction[2] == -1 && r.ops[0].light.intensity == 1e5f, "tiny direction normalised");
    lc_proto_request_release(&r);

    PARSE_OK(
        "{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\",\"position\":[0,2,0],\"direction\":[0,-1,0],"
        "\"size\":[0.5,2],\"tangent\":[3,0,0]}}",
        &r);
    if (r.n_ops == 1) {
        const lc_proto_light *L = &r.ops[0].light;
        CHECK(L->shape == 0 && L->size[0] == 0.5f && L->size[1] == 2 && L->tangent[0] == 1, "area quad");
    }
    lc_proto_request_release(&r);
    PARSE_OK(
        "{\"type\":\"light.set\",\"light\":{\"id\":\"d\",\"type\":\"area\",\"shape\":\"disc\",\"position\":[0,2,0],\"direction\":[0,-1,0],\"size\":[0.3]}}",
        &r);
    if (r.n_ops == 1) CHECK(r.ops[0].light.shape == 1 && r.ops[0].light.size[0] == 0.3f, "disc");
    lc_proto_request_release(&r);

    PARSE_OK("{\"type\":\"light.remove\",\"id\":7,\"light_id\":\"l1\"}", &r);
    CHECK(r.type == LC_REQ_LIGHT_REMOVE && r.n_ops == 1 && !strcmp(r.ops[0].target, "l1"), "light.remove");
    lc_proto_request_release(&r);

    PARSE_OK("{\"type\":\"object.set\",\"object\":{\"id\":\"chair-1\",\"asset\":\"chair\"}}", &r);
    if (r.n_ops == 1) {
        const lc_proto_object *O = &r.ops[0].object;
        CHECK(!strcmp(O->id, "chair-1") && !strcmp(O->asset, "chair") && O->visible == 1, "object");
        CHECK(O->rotation[3] == 1 && O->rotation[0] == 0 && O->scale[0] == 1 && O->scale[2] == 1, "defaults");
        CHECK(O->translation[0] == 0 && O->translation[1] == 0, "translation default");
    }
    lc_proto_request_release(&r);
    PARSE_OK(
        "{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"translation\":[1,2,3],\"rotation\":[0,0,2,0],"
        "\"scale\":[-1,2,0.5],\"visible\":false}}",
        &r);
    if (r.n_ops == 1) {
        const lc_proto_object *O = &r.ops[0].object;
        CHECK(O->rotation[2] == 1 && O->rotation[3] == 0 && O->scale[0] == -1 && O->visible == 0, "object values");
        CHECK(O->translation[2] == 3, "translation");
    }
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"object.remove\",\"object_id\":\"o\"}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].type == LC_REQ_OBJECT_REMOVE && !strcmp(r.ops[0].target, "o"), "object.remove");
    lc_proto_request_release(&r);

    PARSE_OK("{\"type\":\"material.set\",\"material\":\"light\",\"emission\":[10,20,30]}", &r);
    CHECK(r.n_ops == 1 && !strcmp(r.ops[0].target, "light") && r.ops[0].emission[2] == 30, "material.set");
    lc_proto_request_release(&r);

    PARSE_OK(
        "{\"type\":\"environment.set\",\"environment\":{\"type\":\"constant\",\"color\":[0.1,0.2,0.3],\"intensity\":2}}",
        &r);
    if (r.n_ops == 1) {
        const lc_proto_environment *E = &r.ops[0].environment;
        CHECK(E->kind == 1 && E->color[2] == 0.3f && E->intensity == 2, "env constant");
    }
    lc_proto_request_release(&r);
    {
        char buf[512] = "{\"type\":\"environment.set\",\"environment\":{\"type\":\"sh\",\"sh\":[";
        for (int i = 0; i < 27; i++) snprintf(buf + strlen(buf), sizeof buf - strlen(buf), "%s%d", i ? "," : "", i - 5);
        strcat(buf, "]}}");
        PARSE_OK(buf, &r);
        if (r.n_ops == 1) {
            const lc_proto_environment *E = &r.ops[0].environment;
            CHECK(E->kind == 2 && E->sh[0] == -5 && E->sh[26] == 21 && E->intensity == 1 && E->color[0] == 1, "env sh");
        }
        lc_proto_request_release(&r);
    }
    PARSE_OK("{\"type\":\"environment.set\",\"environment\":{\"type\":\"none\"}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].environment.kind == 0, "env none");
    lc_proto_request_release(&r);

    PARSE_OK(
        "{\"type\":\"settings.set\",\"settings\":{\"bounces\":3,\"bands\":4,\"progressive\":true,\"chroma_compression\":false,\"chroma_bands\":2}}",
        &r);
    if (r.n_ops == 1) {
        const lc_proto_settings *S = &r.ops[0].settings;
        CHECK(S->present == 0x1F && S->bounces == 3 && S->bands == 4 && S->progressive == 1 &&
                  S->chroma_compression == 0 && S->chroma_bands == 2,
              "settings");
    }
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"settings.set\",\"settings\":{\"bounces\":2.0}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].settings.present == 1u << LC_SET_BOUNCES && r.ops[0].settings.bounces == 2,
          "subset");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"settings.set\",\"settings\":{}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].settings.present == 0, "empty settings");
    lc_proto_request_release(&r);

    PARSE_OK(
        "{\"type\":\"batch\",\"id\":\"b\",\"ops\":[{\"type\":\"light.set\",\"light\":{\"id\":\"x\",\"type\":\"point\"," LIGHT_PT
        "}},"
        "{\"type\":\"object.remove\",\"object_id\":\"o\"},{\"type\":\"settings.set\",\"settings\":{\"bounces\":1}}]}",
        &r);
    CHECK(r.type == LC_REQ_BATCH && r.n_ops == 3 && r.ops && r.ops[1].type == LC_REQ_OBJECT_REMOVE &&
              r.ops[2].settings.bounces == 1 && !strcmp(r.ops[0].light.id, "x"),
          "batch");
    lc_proto_request_release(&r);
    { /* exactly max_batch ops */
        static char buf[8192];
        strcpy(buf, "{\"type\":\"batch\",\"ops\":[");
        for (int i = 0; i < 64; i++)
            strcat(buf,
                   i ? ",{\"type\":\"light.remove\",\"light_id\":\"a\"}"
                     : "{\"type\":\"light.remove\",\"light_id\":\"a\"}");
        strcat(buf, "]}");
        PARSE_OK(buf, &r);
        CHECK(r.n_ops == 64, "64 ops");
        lc_proto_request_release(&r);
    }

    PARSE_OK("{\"type\":\"state.get\",\"id\":9007199254740991}", &r);
    CHECK(r.type == LC_REQ_STATE_GET && r.id.kind == 2 && r.id.num == 9007199254740991LL, "state.get id max");
    lc_proto_request_release(&r);
    PARSE_OK(" {\"type\":\"snapshot\"}\r\n", &r);
    CHECK(r.type == LC_REQ_SNAPSHOT && r.n_ops == 0, "snapshot");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"ping\",\"t\":-12.5e3}", &r);
    CHECK(r.type == LC_REQ_PING && r.ping_t == -12500, "ping");
    lc_proto_request_release(&r);
    /* UTF-8 and escapes in strings */
    PARSE_OK("{\"type\":\"light.remove\",\"light_id\":\"l\\u00e9\xc3\xa9\xf0\x9f\x92\xa1\\ud83d\\udca1\"}", &r);
    CHECK(r.n_ops == 1 && !strcmp(r.ops[0].target, "l\xc3\xa9\xc3\xa9\xf0\x9f\x92\xa1\xf0\x9f\x92\xa1"), "utf-8 id");
    lc_proto_request_release(&r);
    /* 64-byte id is fine */
    PARSE_OK(
        "{\"type\":\"light.remove\",\"light_id\":\"aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\"}",
        &r);
    CHECK(r.n_ops == 1 && strlen(r.ops[0].target) == 64, "64-byte id");
    lc_proto_request_release(&r);

    /* names */
    CHECK(!strcmp(lc_proto_type_name(LC_REQ_ENVIRONMENT_SET), "environment.set"), "type name");
    CHECK(!strcmp(lc_proto_stream_name(LC_STREAM_SHGRID), "shgrid"), "stream name");
    CHECK(!strcmp(lc_proto_encoding_name(LC_ENC_RGBA16F), "rgba16f"), "encoding name");
    for (int t = 0; t < LC_REQ_COUNT; t++)
        CHECK(lc_proto_is_change((lc_req_type)t) == (t >= LC_REQ_LIGHT_SET && t <= LC_REQ_BATCH), "is_change %d", t);
}

static void test_limits(void) {
    /* depth: 16 levels parse, 17 do not */
    char buf[256];
    strcpy(buf, "{\"type\":\"ping\",\"t\":1,\"x\":");
    for (int i = 0; i < 15; i++) strcat(buf, "[");
    for (int i = 0; i < 15; i++) strcat(buf, "]");
    strcat(buf, "}");
    lc_proto_request r;
    PARSE_OK(buf, &r);
    lc_proto_request_release(&r);
    strcpy(buf, "{\"type\":\"ping\",\"t\":1,\"x\":");
    for (int i = 0; i < 16; i++) strcat(buf, "[");
    for (int i = 0; i < 16; i++) strcat(buf, "]");
    strcat(buf, "}");
    INVALID(buf, "too_deep", "");
    /* brackets inside strings do not count */
    PARSE_OK("{\"type\":\"ping\",\"t\":1,\"x\":\"[[[[[[[[[[[[[[[[[[[[{{{{{{{{{{{{{{{{{{\\\"[[[[[[[[[[[[[\"}", &r);
    lc_proto_request_release(&r);
    /* 17 levels of objects, unbalanced garbage after: depth is reported first */
    INVALID(
        "{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":{\"a\":",
        "too_deep", "");

    /* size: 65536 parses, 65537 does not */
    size_t n = 65536;
    char *big = malloc(n + 2);
    strcpy(big, "{\"type\":\"ping\",\"t\":1,\"pad\":\"");
    size_t k = strlen(big);
    memset(big + k, 'x', n - k - 2);
    memcpy(big + n - 2, "\"}", 3);
    CHECK(strlen(big) == n, "big size");
    PARSE_OK(big, &r);
    lc_proto_request_release(&r);
    memmove(big + k + 1, big + k, n - k + 1);
    big[k] = 'x';
    n_invalid_cases++;
    expect_err_len(__LINE__, big, n + 1, "too_large", "");
    free(big);

    /* configurable limits */
    lc_proto_limits lim;
    lc_proto_default_limits(&lim);
    CHECK(lim.max_message == 65536 && lim.max_depth == 16 && lim.max_batch == 64, "defaults");
    lim.max_batch = 2;
    const char *b3 =
        "{\"type\":\"batch\",\"ops\":[{\"type\":\"light.remove\",\"light_id\":\"a\"},{\"type\":\"light.remove\",\"light_id\":\"a\"},"
        "{\"type\":\"light.remove\",\"light_id\":\"a\"}]}";
    lc_proto_error e;
    CHECK(lc_proto_parse_request(b3, strlen(b3), &lim, &r, &e) == -1 && !strcmp(e.code, "limit_exceeded"),
          "max_batch 2");
    lc_proto_request_release(&r);
    /* not NUL-terminated: only len bytes are read */
    const char *pfx = "{\"type\":\"snapshot\"}GARBAGE";
    CHECK(lc_proto_parse_request(pfx, 19, NULL, &r, &e) == 0 && r.type == LC_REQ_SNAPSHOT, "length respected");
    lc_proto_request_release(&r);
}

static void test_invalid(void) {
    INVALID("", "bad_json", "");
    INVALID("not json", "bad_json", "");
    INVALID("[1,2]", "bad_json", "");
    INVALID("\"ping\"", "bad_json", "");
    INVALID("null", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":1} x", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":1}{}", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":1,}", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":NaN}", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":Infinity}", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":-Infinity}", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":01}", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":.5}", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":0x10}", "bad_json", "");
    INVALID("{'type':'ping'}", "bad_json", "");
    INVALID("{\"type\":\"ping\",\"t\":1,\"s\":\"a\tb\"}", "bad_json", "");    /* raw control character */
    INVALID("{\"type\":\"ping\",\"t\":1,\"s\":\"\\ud800\"}", "bad_json", ""); /* lone surrogate */
    INVALID("{\"type\":\"ping\",\"t\":1,\"s\":\"\\x\"}", "bad_json", "");     /* bad escape */
    INVALID("\xef\xbb\xbf{\"type\":\"snapshot\"}", "bad_json", "");           /* BOM */
    INVALID("{\"type\":\"ping\",\"t\":1e400}", "out_of_range", "/t");
    INVALID("{\"type\":\"ping\",\"t\":-1e400}", "out_of_range", "/t");
    INVALID("{\"type\":\"ping\",\"t\":\"NaN\"}", "invalid", "/t");
    INVALID("{\"type\":\"ping\"}", "invalid", "/t");
    INVALID("{\"t\":1}", "unknown_type", "/type");
    INVALID("{\"type\":\"fly\"}", "unknown_type", "/type");
    INVALID("{\"type\":5}", "unknown_type", "/type");
    INVALID("{\"type\":\"Ping\",\"t\":1}", "unknown_type", "/type");

    INVALID("{\"type\":\"hello\",\"token\":\"x\"}", "invalid", "/client");
    INVALID("{\"type\":\"hello\",\"client\":\"\"}", "invalid", "/client");
    INVALID(
        "{\"type\":\"hello\",\"client\":\"xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx\"}",
        "invalid", "/client");
    INVALID("{\"type\":\"hello\",\"client\":\"c\",\"token\":7}", "invalid", "/token");
    INVALID("{\"type\":\"hello\",\"client\":\"c\",\"encodings\":\"rgb9e5\"}", "invalid", "/encodings");
    INVALID("{\"type\":\"hello\",\"client\":\"c\",\"encodings\":[\"f32\",1]}", "invalid", "/encodings/1");
    INVALID("{\"type\":\"hello\",\"client\":\"\xc0\xaf\"}", "invalid", "/client"); /* overlong UTF-8 */

    INVALID("{\"type\":\"subscribe\"}", "invalid", "/stream");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"video\"}", "invalid", "/stream");
    INVALID("{\"type\":\"subscribe\",\"stream\":[\"lightmap\"]}", "invalid", "/stream");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"shgrid\",\"encoding\":\"rgb9e5\"}", "invalid", "/encoding");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"lightmap\",\"encoding\":\"png\"}", "invalid", "/encoding");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"lightmap\",\"max_rate\":0}", "out_of_range", "/max_rate");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"lightmap\",\"delta\":\"xor\"}", "invalid", "/delta");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"lightmap\",\"delta\":1}", "invalid", "/delta");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"shgrid\",\"delta\":\"residual\"}", "invalid", "/delta");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"lightmap\",\"max_rate\":121}", "out_of_range", "/max_rate");
    INVALID("{\"type\":\"unsubscribe\",\"stream\":null}", "invalid", "/stream");

    INVALID("{\"type\":\"light.set\"}", "invalid", "/light");
    INVALID("{\"type\":\"light.set\",\"light\":[]}", "invalid", "/light");
    INVALID("{\"type\":\"light.set\",\"light\":{\"type\":\"point\"," LIGHT_PT "}}", "invalid", "/light/id");
    INVALID(
        "{\"type\":\"light.set\",\"light\":{\"id\":\"aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\",\"type\":\"point\"," LIGHT_PT
        "}}",
        "invalid", "/light/id");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\xff\",\"type\":\"point\"," LIGHT_PT "}}", "invalid",
            "/light/id");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\xed\xa0\x80\",\"type\":\"point\"," LIGHT_PT "}}", "invalid",
            "/light/id"); /* UTF-8 surrogate */
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"laser\"," LIGHT_PT "}}", "invalid",
            "/light/type");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\"," LIGHT_PT "}}", "invalid", "/light/type");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\"," LIGHT_PT ",\"intensity\":-1}}",
            "out_of_range", "/light/intensity");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\"," LIGHT_PT ",\"intensity\":\"1\"}}",
            "invalid", "/light/intensity");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\"," LIGHT_PT ",\"intensity\":\"NaN\"}}",
            "invalid", "/light/intensity");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\"," LIGHT_PT ",\"intensity\":1e400}}",
            "out_of_range", "/light/intensity");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\"," LIGHT_PT ",\"intensity\":1.5e9}}",
            "out_of_range", "/light/intensity");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\"," LIGHT_PT ",\"range\":-0.5}}",
            "out_of_range", "/light/range");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\"}}", "invalid", "/light/position");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\",\"position\":[0,0]}}", "invalid",
            "/light/position");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\",\"position\":[0,\"x\",0]}}", "invalid",
            "/light/position/1");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\",\"position\":[0,2e6,0]}}",
            "out_of_range", "/light/position/1");
    INVALID(
        "{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\",\"position\":[0,0,0],\"color\":[1,1,-1]}}",
        "out_of_range", "/light/color/2");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"spot\"," LIGHT_PT "}}", "invalid",
            "/light/direction");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"directional\",\"direction\":[0,0,0]}}",
            "out_of_range", "/light/direction");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"spot\"," LIGHT_PT
            ",\"direction\":[0,-1,0],\"innerConeAngle\":2}}",
            "out_of_range", "/light/innerConeAngle");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"spot\"," LIGHT_PT
            ",\"direction\":[0,-1,0],\"innerConeAngle\":0.5,\"outerConeAngle\":0.4}}",
            "out_of_range", "/light/outerConeAngle");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\"," LIGHT_PT ",\"direction\":[0,-1,0]}}",
            "invalid", "/light/size");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\"," LIGHT_PT
            ",\"direction\":[0,-1,0],\"shape\":\"disc\",\"size\":[1,2]}}",
            "invalid", "/light/size");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\"," LIGHT_PT
            ",\"direction\":[0,-1,0],\"size\":[0,1]}}",
            "out_of_range", "/light/size/0");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\"," LIGHT_PT
            ",\"direction\":[0,-1,0],\"size\":[1,2e4]}}",
            "out_of_range", "/light/size/1");
    INVALID("{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\"," LIGHT_PT
            ",\"direction\":[0,-1,0],\"size\":[1,1],\"shape\":\"triangle\"}}",
            "invalid", "/light/shape");

    INVALID("{\"type\":\"light.remove\"}", "invalid", "/light_id");
    INVALID("{\"type\":\"light.remove\",\"light_id\":7}", "invalid", "/light_id");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\"}}", "invalid", "/object/asset");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"rotation\":[0,0,0,0]}}",
            "out_of_range", "/object/rotation");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"rotation\":[0,0,1]}}", "invalid",
            "/object/rotation");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"scale\":[1,0,1]}}", "out_of_range",
            "/object/scale/1");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"scale\":[1,1,-2e4]}}",
            "out_of_range", "/object/scale/2");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"visible\":\"yes\"}}", "invalid",
            "/object/visible");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"translation\":[1,2,3e7]}}",
            "out_of_range", "/object/translation/2");
    INVALID("{\"type\":\"object.remove\",\"object_id\":\"\"}", "invalid", "/object_id");
    INVALID("{\"type\":\"material.set\",\"material\":\"m\"}", "invalid", "/emission");
    INVALID("{\"type\":\"material.set\",\"emission\":[1,1,1]}", "invalid", "/material");
    INVALID("{\"type\":\"material.set\",\"material\":\"m\",\"emission\":[0,0,2e7]}", "out_of_range", "/emission/2");
    INVALID("{\"type\":\"environment.set\",\"environment\":{\"type\":\"hdr\"}}", "invalid", "/environment/type");
    INVALID("{\"type\":\"environment.set\",\"environment\":{\"type\":\"sh\"}}", "invalid", "/environment/sh");
    INVALID("{\"type\":\"environment.set\",\"environment\":{\"type\":\"sh\",\"sh\":[1,2,3]}}", "invalid",
            "/environment/sh");
    INVALID("{\"type\":\"environment.set\",\"environment\":{\"type\":\"none\",\"intensity\":-1}}", "out_of_range",
            "/environment/intensity");
    INVALID("{\"type\":\"environment.set\",\"environment\":\"none\"}", "invalid", "/environment");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"bounces\":17}}", "out_of_range", "/settings/bounces");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"bands\":1.5}}", "invalid", "/settings/bands");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"bands\":0}}", "out_of_range", "/settings/bands");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"bands\":2,\"chroma_bands\":3}}", "out_of_range",
            "/settings/chroma_bands");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"progressive\":1}}", "invalid", "/settings/progressive");

    INVALID("{\"type\":\"batch\"}", "invalid", "/ops");
    INVALID("{\"type\":\"batch\",\"ops\":[]}", "invalid", "/ops");
    INVALID("{\"type\":\"batch\",\"ops\":{}}", "invalid", "/ops");
    INVALID(
        "{\"type\":\"batch\",\"ops\":[{\"type\":\"light.remove\",\"light_id\":\"a\"},{\"type\":\"object.remove\",\"object_id\":\"b\"},"
        "{\"type\":\"light.set\",\"light\":{\"id\":\"x\",\"type\":\"point\"," LIGHT_PT ",\"intensity\":-3}}]}",
        "out_of_range", "/ops/2/light/intensity");
    INVALID(
        "{\"type\":\"batch\",\"ops\":[{\"type\":\"light.remove\",\"light_id\":\"a\"},{\"type\":\"light.remove\",\"light_id\":\"a\"},"
        "{\"type\":\"light.set\",\"light\":{\"id\":\"x\",\"type\":\"point\",\"position\":[0,1,\"z\"]}}]}",
        "invalid", "/ops/2/light/position/2");
    INVALID(
        "{\"type\":\"batch\",\"ops\":[{\"type\":\"light.remove\",\"light_id\":\"a\"},{\"type\":\"batch\",\"ops\":[{\"type\":\"light.remove\",\"light_id\":\"a\"}]}]}",
        "invalid", "/ops/1/type");
    INVALID("{\"type\":\"batch\",\"ops\":[{\"type\":\"ping\",\"t\":1}]}", "invalid", "/ops/0/type");
    INVALID("{\"type\":\"batch\",\"ops\":[{\"type\":\"hello\",\"client\":\"c\"}]}", "invalid", "/ops/0/type");
    INVALID("{\"type\":\"batch\",\"ops\":[1]}", "invalid", "/ops/0");
    INVALID("{\"type\":\"batch\",\"ops\":[{\"type\":\"teleport\"}]}", "unknown_type", "/ops/0/type");
    INVALID("{\"type\":\"batch\",\"ops\":[{\"light_id\":\"a\"}]}", "unknown_type", "/ops/0/type");
    {
        static char buf[8192];
        strcpy(buf, "{\"type\":\"batch\",\"ops\":[");
        for (int i = 0; i < 65; i++)
            strcat(buf,
                   i ? ",{\"type\":\"light.remove\",\"light_id\":\"a\"}"
                     : "{\"type\":\"light.remove\",\"light_id\":\"a\"}");
        strcat(buf, "]}");
        INVALID(buf, "limit_exceeded", "/ops");
    }

    INVALID("{\"type\":\"snapshot\",\"id\":\"aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\"}",
            "invalid", "/id");
    INVALID("{\"type\":\"snapshot\",\"id\":\"\"}", "invalid", "/id");
    INVALID("{\"type\":\"snapshot\",\"id\":-1}", "out_of_range", "/id");
    INVALID("{\"type\":\"snapshot\",\"id\":1.5}", "invalid", "/id");
    INVALID("{\"type\":\"snapshot\",\"id\":9007199254740992}", "out_of_range", "/id");
    INVALID("{\"type\":\"snapshot\",\"id\":true}", "invalid", "/id");
    INVALID("{\"type\":\"snapshot\",\"id\":{}}", "invalid", "/id");
    INVALID("{\"type\":\"snapshot\",\"x\":\"\xe2\x82\"}", "invalid", ""); /* truncated UTF-8 elsewhere */
    INVALID("{\"type\":\"snapshot\",\"\xff\":1}", "invalid", "");         /* in a key */
    INVALID("{\"type\":\"light.remove\",\"light_id\":\"a\\u0000b\"}", "invalid", "");

    /* the error echoes the request id when it was readable */
    lc_proto_request r;
    lc_proto_error e;
    CHECK(parse("{\"id\":\"abc\",\"type\":\"light.set\",\"light\":{}}", &r, &e) == -1 && r.id.kind == 1 &&
              !strcmp(r.id.str, "abc") && !strcmp(e.pointer, "/light/id"),
          "id echoed");
    lc_proto_request_release(&r);
    CHECK(parse("{\"type\":\"nope\",\"id\":42}", &r, &e) == -1 && r.id.kind == 2 && r.id.num == 42,
          "id echoed, unknown type");
    lc_proto_request_release(&r);
    CHECK(e.message[0] != 0, "message filled");
    /* NULL err is allowed */
    CHECK(lc_proto_parse_request("{}", 2, NULL, &r, NULL) == -1, "NULL err");
    lc_proto_request_release(&r);
    fprintf(stderr, "%d invalid forms checked\n", n_invalid_cases);
    CHECK(n_invalid_cases >= 40, "at least 40 invalid forms");
}

/* --- builders ---------------------------------------------------------------------------- */

static cJSON *reparse(char *s) {
    CHECK(s != NULL, "builder returned NULL");
    if (!s) return NULL;
    cJSON *j = cJSON_Parse(s);
    CHECK(j != NULL, "builder output is not JSON: %s", s);
    free(s);
    return j;
}

static double num(const cJSON *o, const char *k) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(o, k);
    return cJSON_IsNumber(it) ? it->valuedouble : NAN;
}

static const char *str(const cJSON *o, const char *k) {
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(o, k);
    return cJSON_IsString(it) ? it->valuestring : "";
}

static void test_builders(void) {
    lc_proto_id sid = {1, "req-1", 0}, nid = {2, "", 9007199254740991LL}, none = {0, "", 0};
    cJSON *j = reparse(lc_proto_build_ok(&sid, 42));
    CHECK(j && !strcmp(str(j, "type"), "ok") && !strcmp(str(j, "id"), "req-1") && num(j, "revision") == 42, "ok");
    CHECK(cJSON_GetArraySize(j) == 3, "ok has 3 keys");
    cJSON_Delete(j);
    char *s = lc_proto_build_ok(&nid, 18446744073709551615ULL);
    CHECK(s && strstr(s, "\"id\":9007199254740991") && strstr(s, "\"revision\":18446744073709551615"),
          "exact integers: %s", s);
    free(s);
    j = reparse(lc_proto_build_ok(&none, 0));
    CHECK(j && !cJSON_GetObjectItem(j, "id") && num(j, "revision") == 0, "ok without id");
    cJSON_Delete(j);
    j = reparse(lc_proto_build_ok(NULL, 1));
    CHECK(j && !cJSON_GetObjectItem(j, "id"), "ok NULL id");
    cJSON_Delete(j);

    lc_proto_error e = {"out_of_range", "/light/intensity", "intensity \"must\" be\n in range"};
    j = reparse(lc_proto_build_error(&sid, &e));
    CHECK(j && !strcmp(str(j, "type"), "error") && !strcmp(str(j, "code"), "out_of_range") &&
              !strcmp(str(j, "pointer"), "/light/intensity") && !strcmp(str(j, "message"), e.message) &&
              !strcmp(str(j, "id"), "req-1"),
          "error");
    cJSON_Delete(j);
    lc_proto_error e2 = {"bad_json", "", "x"};
    j = reparse(lc_proto_build_error(NULL, &e2));
    CHECK(j && cJSON_IsString(cJSON_GetObjectItem(j, "pointer")) && !strcmp(str(j, "pointer"), ""),
          "error empty pointer");
    cJSON_Delete(j);

    j = reparse(lc_proto_build_pong(&nid, 1234.5678901234567, 1700000000123456ULL));
    CHECK(j && !strcmp(str(j, "type"), "pong") && num(j, "t") == 1234.5678901234567 &&
              num(j, "server_time_us") == 1700000000123456.0,
          "pong");
    cJSON_Delete(j);

    const char *assets[] = {"chair", "table"}, *mats[] = {"white", "light", "red \"q\""};
    lc_proto_welcome w = {0};
    w.server = "lucentd/0.1.0";
    w.role = "controller";
    w.revision = 42;
    w.lightmap_width = 128;
    w.lightmap_height = 64;
    w.tile = 32;
    w.grid_origin[0] = -1.5f;
    w.grid_cell = 0.5f;
    w.grid_dims[0] = 24, w.grid_dims[1] = 8, w.grid_dims[2] = 12;
    w.bands = 3;
    w.assets = assets;
    w.n_assets = 2;
    w.materials = mats;
    w.n_materials = 3;
    lc_proto_default_limits(&w.limits);
    w.max_lights = w.max_objects = 4096;
    w.rate = 100;
    j = reparse(lc_proto_build_welcome(&nid, &w));
    if (j) {
        const cJSON *sc = cJSON_GetObjectItem(j, "scene"), *lm = cJSON_GetObjectItem(sc, "lightmap"),
                    *gr = cJSON_GetObjectItem(sc, "grid"), *li = cJSON_GetObjectItem(j, "limits");
        CHECK(!strcmp(str(j, "type"), "welcome") && !strcmp(str(j, "protocol"), "lucent/1") &&
                  !strcmp(str(j, "server"), "lucentd/0.1.0") && !strcmp(str(j, "role"), "controller") &&
                  num(j, "revision") == 42,
              "welcome top");
        CHECK(num(lm, "width") == 128 && num(lm, "height") == 64 && num(lm, "tile") == 32 &&
                  !strcmp(str(lm, "quantity"), "irradiance"),
              "welcome lightmap");
        CHECK(num(gr, "cell") == 0.5 && cJSON_GetArrayItem(cJSON_GetObjectItem(gr, "origin"), 0)->valuedouble == -1.5 &&
                  cJSON_GetArrayItem(cJSON_GetObjectItem(gr, "dims"), 2)->valuedouble == 12 &&
                  num(gr, "coefficients") == 9 && !strcmp(str(gr, "quantity"), "irradiance_sh"),
              "welcome grid");
        CHECK(num(sc, "bands") == 3 && cJSON_GetArraySize(cJSON_GetObjectItem(sc, "assets")) == 2 &&
                  !strcmp(cJSON_GetArrayItem(cJSON_GetObjectItem(sc, "materials"), 2)->valuestring, "red \"q\""),
              "welcome names");
        CHECK(num(li, "max_message") == 65536 && num(li, "max_lights") == 4096 && num(li, "max_objects") == 4096 &&
                  num(li, "max_batch") == 64 && num(li, "rate") == 100,
              "welcome limits");
    }
    cJSON_Delete(j);

    lc_proto_op ops[4];
    memset(ops, 0, sizeof ops);
    ops[0].type = LC_REQ_LIGHT_SET;
    strcpy(ops[0].light.id, "key");
    ops[1].type = LC_REQ_OBJECT_REMOVE;
    strcpy(ops[1].target, "chair-1");
    ops[2].type = LC_REQ_ENVIRONMENT_SET;
    ops[3].type = LC_REQ_MATERIAL_SET;
    strcpy(ops[3].target, "white");
    j = reparse(lc_proto_build_changed(43, "my-viewer/2.0", ops, 4));
    if (j) {
        const cJSON *o = cJSON_GetObjectItem(j, "ops"), *ids = cJSON_GetObjectItem(j, "ids");
        CHECK(!strcmp(str(j, "type"), "changed") && num(j, "revision") == 43 && !strcmp(str(j, "by"), "my-viewer/2.0"),
              "changed");
        CHECK(cJSON_GetArraySize(o) == 4 && !strcmp(cJSON_GetArrayItem(o, 0)->valuestring, "light.set") &&
                  !strcmp(cJSON_GetArrayItem(o, 2)->valuestring, "environment.set"),
              "changed ops");
        CHECK(cJSON_GetArraySize(ids) == 4 && !strcmp(cJSON_GetArrayItem(ids, 0)->valuestring, "key") &&
                  !strcmp(cJSON_GetArrayItem(ids, 1)->valuestring, "chair-1") &&
                  !strcmp(cJSON_GetArrayItem(ids, 3)->valuestring, "white"),
              "changed ids");
    }
    cJSON_Delete(j);

    /* floats are written in their shortest round-trip form */
    memset(ops, 0, sizeof ops);
    ops[0].type = LC_REQ_MATERIAL_SET;
    strcpy(ops[0].target, "m");
    ops[0].emission[0] = 0.1f;
    ops[0].emission[1] = 1e7f;
    ops[0].emission[2] = 3.14159274f;
    s = lc_proto_build_op(&ops[0]);
    CHECK(s && strstr(s, "[0.1,1e+07,3.1415927]"), "short floats: %s", s);
    free(s);
}

/* Journal: build_op -> parse_request gives the op back, for every op type. */
static void test_op_roundtrip(void) {
    const char *msgs[] = {
        ("{\"type\":\"light.set\",\"light\":{\"id\":\"s\",\"type\":\"spot\",\"position\":[0.1,3,-7.25],\"direction\":[0.3,-2,0.1],"
         "\"color\":[1,0.3,0.1],\"intensity\":812.7,\"range\":20,\"innerConeAngle\":0.2,\"outerConeAngle\":1.5707963267948966}}"),
        "{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\",\"position\":[0,2,0],\"direction\":[0,-1,0],\"size\":[0.5,2],\"tangent\":[1,0,1]}}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"d\",\"type\":\"area\",\"shape\":\"disc\",\"position\":[0,2,0],\"direction\":[0,-1,0],\"size\":[0.3]}}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"sun\",\"type\":\"directional\",\"direction\":[1,-3,0.5],\"intensity\":1e5}}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"p\",\"type\":\"point\",\"position\":[1e6,-1e6,0.333]}}",
        "{\"type\":\"light.remove\",\"light_id\":\"l1\"}",
        "{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"translation\":[1,2,3],\"rotation\":[0.1,0.2,0.3,0.9],\"scale\":[-1,2,0.5],\"visible\":false}}",
        "{\"type\":\"object.remove\",\"object_id\":\"o\"}",
        "{\"type\":\"material.set\",\"material\":\"light\",\"emission\":[10,20,30]}",
        "{\"type\":\"environment.set\",\"environment\":{\"type\":\"constant\",\"color\":[0.1,0.2,0.3],\"intensity\":2}}",
        "{\"type\":\"environment.set\",\"environment\":{\"type\":\"sh\",\"sh\":[1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16,17,18,19,20,21,22,23,24,25,26,-27.5]}}",
        "{\"type\":\"settings.set\",\"settings\":{\"bounces\":3,\"chroma_bands\":2}}",
    };
    for (size_t i = 0; i < sizeof msgs / sizeof msgs[0]; i++) {
        lc_proto_request a, b;
        PARSE_OK(msgs[i], &a);
        if (a.n_ops != 1) continue;
        char *s = lc_proto_build_op(&a.ops[0]);
        CHECK(s != NULL, "build_op %zu", i);
        if (s) {
            PARSE_OK(s, &b);
            CHECK(b.n_ops == 1 && !memcmp(&a.ops[0], &b.ops[0], sizeof a.ops[0]), "op round trip %zu: %s", i, s);
            lc_proto_request_release(&b);
            free(s);
        }
        lc_proto_request_release(&a);
    }
    lc_proto_op bad = {0};
    bad.type = LC_REQ_PING;
    CHECK(lc_proto_build_op(&bad) == NULL, "build_op refuses non-change");
}

static void test_state_roundtrip(void) {
    lc_proto_light lights[3];
    lc_proto_object objects[2];
    memset(lights, 0, sizeof lights);
    memset(objects, 0, sizeof objects);
    const char *lj[] = {
        "{\"type\":\"light.set\",\"light\":{\"id\":\"zeta\",\"type\":\"spot\",\"position\":[0.1,3,-7.25],\"direction\":[0.3,-2,0.1],\"color\":[1,0.3,0.1],\"intensity\":812.7,\"innerConeAngle\":0.2,\"outerConeAngle\":0.7}}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"alpha\",\"type\":\"area\",\"shape\":\"disc\",\"position\":[0,2,0],\"direction\":[0,-1,0],\"size\":[0.3],\"range\":5}}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"mid\",\"type\":\"directional\",\"direction\":[1,-3,0.5],\"intensity\":1e5}}",
    };
    for (int i = 0; i < 3; i++) {
        lc_proto_request r;
        PARSE_OK(lj[i], &r);
        if (r.n_ops == 1) lights[i] = r.ops[0].light;
        lc_proto_request_release(&r);
    }
    const char *oj[] = {
        "{\"type\":\"object.set\",\"object\":{\"id\":\"o2\",\"asset\":\"chair\",\"translation\":[1,2,3],\"rotation\":[0.1,0.2,0.3,0.9],\"scale\":[-1,2,0.5],\"visible\":false}}",
        "{\"type\":\"object.set\",\"object\":{\"id\":\"o1\",\"asset\":\"table\"}}",
    };
    for (int i = 0; i < 2; i++) {
        lc_proto_request r;
        PARSE_OK(oj[i], &r);
        if (r.n_ops == 1) objects[i] = r.ops[0].object;
        lc_proto_request_release(&r);
    }
    lc_proto_material_state mats[2] = {{"white", {0, 0, 0}}, {"light", {17, 12, 4.5f}}};
    lc_proto_state st = {0};
    st.revision = 123456789;
    st.lights = lights;
    st.n_lights = 3;
    st.objects = objects;
    st.n_objects = 2;
    st.materials = mats;
    st.n_materials = 2;
    st.environment.kind = 2;
    for (int i = 0; i < 27; i++) st.environment.sh[i] = 0.01f * (float)(i - 13);
    st.environment.color[0] = st.environment.color[1] = st.environment.color[2] = 1;
    st.environment.intensity = 0.7f;
    st.settings.present = 0x1F;
    st.settings.bounces = 2;
    st.settings.bands = 3;
    st.settings.progressive = 1;
    st.settings.chroma_compression = 1;
    st.settings.chroma_bands = 2;
    lc_proto_id id = {2, "", 5};
    char *s = lc_proto_build_state(&id, &st);
    CHECK(s != NULL, "build_state");
    if (!s) return;
    lc_proto_parsed_state p;
    lc_proto_error e;
    int rc = lc_proto_parse_state(s, strlen(s), &p, &e);
    CHECK(rc == 0, "parse_state: %s %s %s", e.code, e.pointer, e.message);
    if (rc == 0) {
        CHECK(p.revision == 123456789 && p.n_lights == 3 && p.n_objects == 2 && p.n_materials == 2, "counts");
        /* sorted by id */
        CHECK(p.n_lights == 3 && !memcmp(&p.lights[0], &lights[1], sizeof lights[0]) &&
                  !memcmp(&p.lights[1], &lights[2], sizeof lights[0]) &&
                  !memcmp(&p.lights[2], &lights[0], sizeof lights[0]),
              "lights round trip, sorted");
        CHECK(p.n_objects == 2 && !memcmp(&p.objects[0], &objects[1], sizeof objects[0]) &&
                  !memcmp(&p.objects[1], &objects[0], sizeof objects[0]),
              "objects round trip, sorted");
        CHECK(p.n_materials == 2 && !strcmp(p.material_names[1], "light") && p.material_emission[1][2] == 4.5f,
              "materials");
        CHECK(!memcmp(&p.environment, &st.environment, sizeof st.environment), "environment");
        CHECK(!memcmp(&p.settings, &st.settings, sizeof st.settings), "settings");
        /* fixed point: building the parsed state gives the same text */
        lc_proto_state st2 = st;
        lc_proto_material_state m2[2] = {{p.material_names[0], {0}}, {p.material_names[1], {0}}};
        memcpy(m2[0].emission, p.material_emission[0], 12);
        memcpy(m2[1].emission, p.material_emission[1], 12);
        st2.lights = p.lights;
        st2.objects = p.objects;
        st2.materials = m2;
        st2.environment = p.environment;
        st2.settings = p.settings;
        char *s2 = lc_proto_build_state(&id, &st2);
        CHECK(s2 && !strcmp(s, s2), "state text is a fixed point");
        free(s2);
    }
    lc_proto_parsed_state_free(&p);

    /* empty state */
    lc_proto_state empty = {0};
    char *s3 = lc_proto_build_state(NULL, &empty);
    CHECK(s3 && lc_proto_parse_state(s3, strlen(s3), &p, &e) == 0 && p.n_lights == 0 && p.lights == NULL,
          "empty state: %s", s3);
    lc_proto_parsed_state_free(&p);
    free(s3);

    /* corrupt snapshots are refused with a pointer */
    const char *bad[][2] = {
        {"{\"type\":\"ok\",\"revision\":1}", "/type"},
        {"{\"type\":\"state\",\"revision\":1,\"lights\":[],\"objects\":[],\"materials\":[],\"environment\":{\"type\":\"none\"}}",
         "/settings"},
        {"{\"type\":\"state\",\"revision\":-1,\"lights\":[],\"objects\":[],\"materials\":[],\"environment\":{\"type\":\"none\"},\"settings\":{}}",
         "/revision"},
        {"{\"type\":\"state\",\"revision\":1,\"lights\":[{\"id\":\"b\",\"type\":\"directional\",\"direction\":[0,1,0]},{\"id\":\"a\",\"type\":\"directional\",\"direction\":[0,1,0]}],"
         "\"objects\":[],\"materials\":[],\"environment\":{\"type\":\"none\"},\"settings\":{}}",
         "/lights/1/id"},
        {"{\"type\":\"state\",\"revision\":1,\"lights\":[],\"objects\":[{\"id\":\"o\"}],\"materials\":[],\"environment\":{\"type\":\"none\"},\"settings\":{}}",
         "/objects/0/asset"},
        {"{\"type\":\"state\",\"revision\":1,\"lights\":[],\"objects\":[],\"materials\":[{\"name\":\"m\",\"emission\":[1,1]}],\"environment\":{\"type\":\"none\"},\"settings\":{}}",
         "/materials/0/emission"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        rc = lc_proto_parse_state(bad[i][0], strlen(bad[i][0]), &p, &e);
        CHECK(rc == -1 && !strcmp(e.pointer, bad[i][1]), "bad state %zu: rc %d pointer %s (%s)", i, rc, e.pointer,
              e.message);
        CHECK(p.lights == NULL && p.n_lights == 0, "freed after failure");
        lc_proto_parsed_state_free(&p);
    }
    free(s);
}

/* --- frames -------------------------------------------------------------------------------- */

static uint8_t frame_buf[1 << 16];

static size_t make_frame(lc_frame_header *h, int stream, int enc, int flags, uint32_t w, uint32_t hh, uint32_t d,
                         uint32_t s, const uint32_t *tiles, uint32_t ntiles, uint32_t payload_len) {
    static uint8_t payload[1 << 15];
    for (uint32_t i = 0; i < payload_len; i++) payload[i] = (uint8_t)(i * 7 + 3);
    memset(h, 0, sizeof *h);
    h->version = 1;
    h->stream = (uint8_t)stream;
    h->encoding = (uint8_t)enc;
    h->flags = (uint16_t)flags;
    h->tile_count = ntiles;
    h->revision = 0x0102030405060708ULL;
    h->sequence = 77;
    h->timestamp_us = 1700000000000000ULL;
    h->width = w;
    h->height = hh;
    h->depth = d;
    h->tile_size = s;
    h->payload_length = payload_len;
    return lc_frame_write(h, tiles, payload, frame_buf, sizeof frame_buf);
}

static int frame_ok(size_t n, const lc_frame_header *want) {
    lc_frame_header h;
    const uint8_t *tt, *pl;
    lc_proto_error e;
    if (lc_frame_parse(frame_buf, n, &h, &tt, &pl, &e) != 0) {
        fprintf(stderr, "  frame_parse: %s %s\n", e.code, e.message);
        return 0;
    }
    if (want) {
        CHECK(h.version == 1 && h.stream == want->stream && h.encoding == want->encoding && h.flags == want->flags &&
                  h.tile_count == want->tile_count && h.revision == want->revision && h.sequence == want->sequence &&
                  h.timestamp_us == want->timestamp_us && h.width == want->width && h.height == want->height &&
                  h.depth == want->depth && h.tile_size == want->tile_size && h.payload_length == want->payload_length,
              "header fields round trip");
        CHECK(tt == frame_buf + 64 && pl == frame_buf + 64 + 4 * (size_t)h.tile_count, "pointers into data");
        for (uint32_t i = 0; i < h.payload_length; i++)
            if (pl[i] != (uint8_t)(i * 7 + 3)) {
                CHECK(0, "payload byte %u", i);
                break;
            }
    }
    return 1;
}

static int frame_bad(size_t n, const char *why) {
    lc_proto_error e;
    lc_frame_header h;
    int rc = lc_frame_parse(frame_buf, n, &h, NULL, NULL, &e);
    if (rc == 0) return 0;
    CHECK(!strcmp(e.code, "bad_frame"), "code %s", e.code);
    if (why && !strstr(e.message, why)) fprintf(stderr, "  note: rejected for '%s', expected '%s'\n", e.message, why);
    return 1;
}

static void test_frames(void) {
    lc_frame_header h;
    /* keyframe lightmap 5x3 rgb9e5 */
    size_t n = make_frame(&h, 1, 1, LC_FRAME_KEYFRAME, 5, 3, 1, 4, NULL, 0, 5 * 3 * 4);
    CHECK(n == 64 + 60, "keyframe size %zu", n);
    CHECK(!memcmp(frame_buf, "LCF1", 4) && frame_buf[4] == 1 && frame_buf[5] == 0 && frame_buf[6] == 1 &&
              frame_buf[10] == 64,
          "little-endian header");
    CHECK(frame_buf[16] == 8 && frame_buf[23] == 1 && frame_buf[40] == 5 && frame_buf[44] == 3 && frame_buf[56] == 60,
          "LE fields");
    uint32_t crc = lc_crc32(lc_crc32(0, frame_buf, 60), frame_buf + 64, n - 64);
    CHECK(frame_buf[60] == (crc & 0xFF) && frame_buf[63] == crc >> 24, "CRC stored LE");
    CHECK(frame_ok(n, &h), "keyframe parses");

    /* every single-byte corruption of this small frame is rejected */
    int missed = 0;
    for (size_t i = 0; i < n; i++)
        for (int x = 1; x < 256; x++) {
            frame_buf[i] ^= (uint8_t)x;
            if (!frame_bad(n, NULL)) missed++;
            frame_buf[i] ^= (uint8_t)x;
        }
    CHECK(missed == 0, "%d single-byte corruptions accepted", missed);
    int trunc_missed = 0;
    for (size_t k = 0; k < n; k++)
        if (!frame_bad(k, NULL)) trunc_missed++;
    CHECK(trunc_missed == 0, "%d truncations accepted", trunc_missed);
    frame_buf[n] = 0;
    CHECK(frame_bad(n + 1, "length"), "trailing byte rejected");
    CHECK(frame_ok(n, NULL), "still fine");

    /* delta: 10x7, tile 4 -> 3x2 tiles; tile 1 = 4x4 texels, tile 5 = 2x3 (clipped) */
    CHECK(lc_tiles_count(10, 7, 4) == 6 && lc_tiles_count(8, 8, 4) == 4 && lc_tiles_count(8, 8, 0) == 0 &&
              lc_tiles_count(1, 1, 32) == 1,
          "tiles_count");
    uint32_t x0, y0, x1, y1;
    lc_tile_rect(10, 7, 4, 5, &x0, &y0, &x1, &y1);
    CHECK(x0 == 8 && y0 == 4 && x1 == 10 && y1 == 7, "tile 5 rect %u %u %u %u", x0, y0, x1, y1);
    lc_tile_rect(10, 7, 4, 1, &x0, &y0, &x1, &y1);
    CHECK(x0 == 4 && y0 == 0 && x1 == 8 && y1 == 4, "tile 1 rect");
    lc_tile_rect(10, 7, 4, 9, &x0, &y0, &x1, &y1);
    CHECK(x1 == x0 || y1 == y0, "tile outside: empty");
    uint32_t tiles[2] = {1, 5};
    n = make_frame(&h, 1, 3, LC_FRAME_DELTA, 10, 7, 1, 4, tiles, 2, (16 + 6) * 12);
    CHECK(n == 64 + 8 + 264, "delta size");
    CHECK(frame_ok(n, &h), "delta parses");
    n = make_frame(&h, 1, 2, LC_FRAME_DELTA, 10, 7, 1, 4, tiles, 2, (16 + 6) * 8);
    CHECK(frame_ok(n, &h), "delta rgba16f parses");
    n = make_frame(&h, 1, 3, LC_FRAME_DELTA, 10, 7, 1, 4, tiles, 2, (16 + 6) * 12 - 12);
    CHECK(frame_bad(n, "payload"), "delta payload short");
    uint32_t bad_order[2] = {5, 1}, dup[2] = {1, 1}, out_of_range[2] = {1, 6};
    n = make_frame(&h, 1, 3, LC_FRAME_DELTA, 10, 7, 1, 4, bad_order, 2, (16 + 6) * 12);
    CHECK(n && frame_bad(n, "ascending"), "tiles not ascending");
    n = make_frame(&h, 1, 3, LC_FRAME_DELTA, 10, 7, 1, 4, dup, 2, 32 * 12);
    CHECK(n && frame_bad(n, "ascending"), "duplicate tile");
    n = make_frame(&h, 1, 3, LC_FRAME_DELTA, 10, 7, 1, 4, out_of_range, 2, (16 + 6) * 12);
    CHECK(n && frame_bad(n, "outside"), "tile out of range");
    n = make_frame(&h, 1, 3, LC_FRAME_DELTA, 10, 7, 1, 0, tiles, 2, (16 + 6) * 12);
    CHECK(n && frame_bad(n, "tile size"), "delta without tile size");

    /* shgrid 2x2x2 rgba16f, objects 3 f32 */
    n = make_frame(&h, 2, 2, LC_FRAME_KEYFRAME, 2, 2, 2, 0, NULL, 0, 8 * 27 * 2);
    CHECK(frame_ok(n, &h), "shgrid parses");
    n = make_frame(&h, 2, 3, LC_FRAME_KEYFRAME, 3, 1, 2, 0, NULL, 0, 6 * 27 * 4);
    CHECK(frame_ok(n, &h), "shgrid f32 parses");
    n = make_frame(&h, 3, 3, LC_FRAME_KEYFRAME, 3, 1, 1, 0, NULL, 0, 3 * (64 + 27 * 4));
    CHECK(frame_ok(n, &h), "objects parse");
    n = make_frame(&h, 3, 2, LC_FRAME_KEYFRAME, 0, 1, 1, 0, NULL, 0, 0);
    CHECK(frame_ok(n, &h), "zero objects parse");

    /* §6.1.1: the pass (bits 8-15) and converged (bit 3) travel beside the kind bits */
    {
        lc_frame_header in, out;
        memset(&in, 0, sizeof in);
        in.version = 1;
        in.stream = LC_STREAM_OBJECTS;
        in.encoding = LC_ENC_F32;
        in.flags = LC_FRAME_KEYFRAME;
        in.pass = 7;
        in.converged = 1;
        in.height = in.depth = 1; /* no objects: a header-only frame */
        size_t len = lc_frame_write(&in, NULL, NULL, frame_buf, sizeof frame_buf);
        CHECK(len == LC_FRAME_HEADER_SIZE && frame_buf[8] == (LC_FRAME_KEYFRAME | LC_FRAME_CONVERGED_BIT) &&
                  frame_buf[9] == 7,
              "pass/converged bytes %02x %02x", frame_buf[8], frame_buf[9]);
        const uint8_t *tt, *pl;
        lc_proto_error e;
        CHECK(lc_frame_parse(frame_buf, len, &out, &tt, &pl, &e) == 0 && out.flags == LC_FRAME_KEYFRAME &&
                  out.pass == 7 && out.converged == 1,
              "pass/converged parse: %s flags %u pass %u conv %u", e.message, out.flags, out.pass, out.converged);
        in.pass = 0;
        in.converged = 0;
        lc_frame_write(&in, NULL, NULL, frame_buf, sizeof frame_buf);
        frame_buf[8] |= 0x10; /* a reserved bit (bits 4-7): ignored, for forward compatibility */
        uint32_t crc = lc_crc32(0, frame_buf, 60);
        memcpy(frame_buf + 60, &crc, 4);
        CHECK(lc_frame_parse(frame_buf, len, &out, &tt, &pl, &e) == 0 && out.flags == LC_FRAME_KEYFRAME &&
                  out.pass == 0 && !out.converged,
              "reserved flag bits ignored: %s", e.message);
    }

    /* semantic rejections (CRC valid) */
    n = make_frame(&h, 2, 1, LC_FRAME_KEYFRAME, 2, 2, 2, 0, NULL, 0, 8 * 27 * 4);
    CHECK(frame_bad(n, "encoding"), "rgb9e5 shgrid");
    n = make_frame(&h, 2, 3, LC_FRAME_DELTA, 2, 2, 2, 0, NULL, 0, 8 * 27 * 4);
    CHECK(frame_bad(n, "keyframes"), "shgrid delta");
    n = make_frame(&h, 1, 1, LC_FRAME_KEYFRAME | LC_FRAME_DELTA, 5, 3, 1, 4, NULL, 0, 60);
    CHECK(frame_bad(n, "flags"), "both flags");
    n = make_frame(&h, 1, 1, 0, 5, 3, 1, 4, NULL, 0, 60);
    CHECK(frame_bad(n, "flags"), "no flags");
    n = make_frame(&h, 1, 1, LC_FRAME_KEYFRAME | 4, 5, 3, 1, 4, NULL, 0, 60);
    CHECK(frame_bad(n, "flags"), "unknown flag");
    n = make_frame(&h, 1, 1, LC_FRAME_KEYFRAME, 5, 3, 1, 4, tiles, 2, 60);
    CHECK(frame_bad(n, "tile table"), "keyframe with tiles");
    n = make_frame(&h, 1, 1, LC_FRAME_KEYFRAME, 5, 3, 1, 4, NULL, 0, 56);
    CHECK(frame_bad(n, "payload"), "keyframe payload short");
    n = make_frame(&h, 5, 3, LC_FRAME_KEYFRAME, 1, 1, 1, 0, NULL, 0, 12);
    CHECK(frame_bad(n, "stream"), "unknown stream");
    n = make_frame(&h, 1, 4, LC_FRAME_KEYFRAME, 1, 1, 1, 0, NULL, 0, 12);
    CHECK(frame_bad(n, "encoding"), "unknown encoding");
    n = make_frame(&h, 1, 3, LC_FRAME_KEYFRAME, 1, 1, 2, 0, NULL, 0, 24);
    CHECK(frame_bad(n, "dimensions"), "lightmap depth 2");
    n = make_frame(&h, 3, 3, LC_FRAME_KEYFRAME, 3, 2, 1, 0, NULL, 0, 6 * (64 + 27 * 4));
    CHECK(frame_bad(n, "height"), "objects height 2");
    n = make_frame(&h, 1, 3, LC_FRAME_KEYFRAME, 0xFFFFFFFFu, 0xFFFFFFFFu, 1, 0, NULL, 0, 12);
    CHECK(frame_bad(n, "payload"), "huge dims");
    h.version = 2;
    n = lc_frame_write(&h, NULL, frame_buf + 1000, frame_buf, sizeof frame_buf);
    CHECK(frame_bad(n, "version"), "version 2");
    /* writer refuses what does not fit */
    make_frame(&h, 1, 1, LC_FRAME_KEYFRAME, 5, 3, 1, 4, NULL, 0, 60);
    uint8_t small[100];
    CHECK(lc_frame_write(&h, NULL, frame_buf, small, sizeof small) == 0, "cap respected");
    CHECK(lc_frame_texel_bytes(LC_ENC_RGB9E5) == 4 && lc_frame_texel_bytes(LC_ENC_RGBA16F) == 8 &&
              lc_frame_texel_bytes(LC_ENC_F32) == 12,
          "texel bytes");
    CHECK(lc_frame_sh_value_bytes(LC_ENC_RGB9E5) == 0 && lc_frame_sh_value_bytes(LC_ENC_RGBA16F) == 2 &&
              lc_frame_sh_value_bytes(LC_ENC_F32) == 4,
          "sh bytes");
}

/* --- residual deltas (§6.2.1) ------------------------------------------------------------- */

static uint32_t pack9e5(uint32_t r, uint32_t g, uint32_t b, uint32_t e) { return r | g << 9 | b << 18 | e << 27; }

static void put_u32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static uint32_t get_u32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint64_t rng_state;
static double rnd(void);

static void test_residual(void) {
    /* closed forms: zigzag of each field's difference, in the field's own bits */
    uint8_t held[4 * 4], now[4 * 4], res[4 * 4];
    const uint32_t cases[][3] = {
        /* held, now, expected residual */
        {pack9e5(100, 200, 300, 15), pack9e5(101, 198, 300, 16), pack9e5(2, 3, 0, 2)},
        {pack9e5(511, 0, 7, 31), pack9e5(0, 511, 7, 0), pack9e5(2, 1, 0, 2)},      /* wraps: +1, -1, 0, +1 */
        {pack9e5(0, 0, 0, 0), pack9e5(256, 255, 0, 16), pack9e5(511, 510, 0, 31)}, /* -256 -> 511, +255 -> 510 */
        {pack9e5(5, 6, 7, 8), pack9e5(5, 6, 7, 8), 0},
    };
    for (int i = 0; i < 4; i++) {
        put_u32(held + 4 * i, cases[i][0]);
        put_u32(now + 4 * i, cases[i][1]);
    }
    lc_residual_make(LC_ENC_RGB9E5, now, held, 4, res);
    for (int i = 0; i < 4; i++)
        CHECK(get_u32(res + 4 * i) == cases[i][2], "rgb9e5 residual %d: %08x, expected %08x", i, get_u32(res + 4 * i),
              cases[i][2]);
    lc_residual_apply(LC_ENC_RGB9E5, held, res, 4);
    CHECK(!memcmp(held, now, sizeof now), "rgb9e5 residual applies to the new words");
    /* f32: one 32-bit field per channel (the bit pattern); +1 ulp -> 2, -1 ulp -> 1 */
    uint8_t hf[12], nf[12], rf[12];
    put_u32(hf, 0x3F800000u), put_u32(nf, 0x3F800001u);
    put_u32(hf + 4, 0x3F800000u), put_u32(nf + 4, 0x3F7FFFFFu);
    put_u32(hf + 8, 0u), put_u32(nf + 8, 0xFFFFFFFFu);
    lc_residual_make(LC_ENC_F32, nf, hf, 1, rf);
    CHECK(get_u32(rf) == 2 && get_u32(rf + 4) == 1 && get_u32(rf + 8) == 1, "f32 residual %u %u %u", get_u32(rf),
          get_u32(rf + 4), get_u32(rf + 8));
    /* half: one 16-bit field per u16 (A included) */
    uint8_t hh[8] = {0x00, 0x3C, 0x00, 0x3C, 0xFF, 0xFF, 0x00, 0x3C},
            nh[8] = {0x03, 0x3C, 0xFE, 0x3B, 0x00, 0x00, 0x00, 0x3C}, rh[8];
    lc_residual_make(LC_ENC_RGBA16F, nh, hh, 1, rh);
    CHECK(rh[0] == 6 && rh[1] == 0 && rh[2] == 3 && rh[3] == 0 && rh[4] == 2 && rh[5] == 0 && rh[6] == 0 && rh[7] == 0,
          "half residual %u %u %u %u", rh[0] | rh[1] << 8, rh[2] | rh[3] << 8, rh[4] | rh[5] << 8, rh[6] | rh[7] << 8);

    /* random words round trip in every encoding */
    static uint8_t a[12 * 1000], b[12 * 1000], r[12 * 1000];
    rng_state = 12345;
    for (int enc = LC_ENC_RGB9E5; enc <= LC_ENC_F32; enc++) {
        size_t bytes = lc_frame_texel_bytes((lc_encoding)enc) * 1000;
        for (size_t i = 0; i < bytes; i++) a[i] = (uint8_t)(rnd() * 256), b[i] = (uint8_t)(rnd() * 256);
        lc_residual_make((lc_encoding)enc, a, b, 1000, r);
        lc_residual_apply((lc_encoding)enc, b, r, 1000);
        CHECK(!memcmp(a, b, bytes), "random round trip, encoding %d", enc);
    }

    /* zlib: exact length only, one complete stream */
    static uint8_t raw[4000], z[8000], back[4001];
    for (size_t i = 0; i < sizeof raw; i++) raw[i] = (uint8_t)(i % 13 == 0 ? i / 13 : 0);
    size_t zn = lc_residual_deflate(raw, sizeof raw, z, lc_residual_deflate_bound(sizeof raw));
    CHECK(zn > 0 && zn < sizeof raw / 4, "deflate %zu bytes", zn);
    CHECK(lc_residual_deflate(raw, sizeof raw, z, 10) == 0, "deflate respects its cap");
    zn = lc_residual_deflate(raw, sizeof raw, z, lc_residual_deflate_bound(sizeof raw));
    CHECK(lc_residual_inflate(z, zn, back, sizeof raw) == 0 && !memcmp(back, raw, sizeof raw), "inflate round trip");
    CHECK(lc_residual_inflate(z, zn, back, sizeof raw - 1) != 0, "inflates to more than expected");
    CHECK(lc_residual_inflate(z, zn, back, sizeof raw + 1) != 0, "inflates to less than expected");
    CHECK(lc_residual_inflate(z, zn - 1, back, sizeof raw) != 0, "truncated stream");
    z[zn] = 0;
    CHECK(lc_residual_inflate(z, zn + 1, back, sizeof raw) != 0, "bytes after the stream");
    z[zn / 2] ^= 0x10;
    CHECK(lc_residual_inflate(z, zn, back, sizeof raw) != 0, "corrupted stream (adler32)");
    CHECK(lc_residual_inflate(raw, 100, back, 100) != 0, "not a zlib stream");

    /* frames: delta + residual (lightmap only, needs tiles and a payload) */
    lc_frame_header h;
    uint32_t tiles[2] = {1, 5};
    size_t n = make_frame(&h, 1, 1, LC_FRAME_DELTA | LC_FRAME_RESIDUAL, 10, 7, 1, 4, tiles, 2, 37);
    CHECK(frame_ok(n, &h), "residual delta parses (compressed payload of any length)");
    const uint8_t *tt = NULL;
    CHECK(lc_frame_parse(frame_buf, n, &h, &tt, NULL, NULL) == 0 && lc_frame_tile_texels(&h, tt) == 16 + 6,
          "tile texels");
    n = make_frame(&h, 1, 1, LC_FRAME_RESIDUAL, 10, 7, 1, 4, tiles, 2, 37);
    CHECK(frame_bad(n, "flags"), "residual without delta");
    n = make_frame(&h, 1, 1, LC_FRAME_KEYFRAME | LC_FRAME_RESIDUAL, 10, 7, 1, 4, NULL, 0, 10 * 7 * 4);
    CHECK(frame_bad(n, "flags"), "residual keyframe");
    n = make_frame(&h, 1, 1, LC_FRAME_DELTA | LC_FRAME_RESIDUAL, 10, 7, 1, 4, NULL, 0, 37);
    CHECK(frame_bad(n, "empty"), "residual without tiles");
    n = make_frame(&h, 1, 1, LC_FRAME_DELTA | LC_FRAME_RESIDUAL, 10, 7, 1, 4, tiles, 2, 0);
    CHECK(frame_bad(n, "empty"), "residual without payload");
    n = make_frame(&h, 2, 3, LC_FRAME_DELTA | LC_FRAME_RESIDUAL, 2, 2, 2, 0, NULL, 0, 37);
    CHECK(frame_bad(n, "lightmap"), "residual shgrid");
    uint32_t bad_tiles[2] = {5, 1};
    n = make_frame(&h, 1, 1, LC_FRAME_DELTA | LC_FRAME_RESIDUAL, 10, 7, 1, 4, bad_tiles, 2, 37);
    CHECK(frame_bad(n, "ascending"), "residual tiles still checked");
}

/* --- RGB9E5 -------------------------------------------------------------------------------- */

static uint64_t rng_state = 0x9E3779B97F4A7C15ULL;
static double rnd(void) {
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return (double)(rng_state >> 11) / 9007199254740992.0;
}

/* The shared-exponent encoding as EXT_texture_shared_exponent states it (frexp, ldexp, floor):
 * lc_rgb9e5_encode builds its powers of two from bits and must give the same words. */
static uint32_t rgb9e5_spec(const float rgb[3]) {
    double c[3], m = 0;
    for (int k = 0; k < 3; k++) {
        c[k] = !(rgb[k] > 0) ? 0 : rgb[k] > 65408.0f ? 65408.0 : (double)rgb[k];
        m = fmax(m, c[k]);
    }
    int fl = -16, e;
    if (m > 0) {
        frexp(m, &e);
        if (e - 1 > fl) fl = e - 1;
    }
    int exp = fl + 16;
    if (floor(m / ldexp(1.0, exp - 24) + 0.5) >= 512) exp++;
    double scale = ldexp(1.0, exp - 24);
    return (uint32_t)floor(c[0] / scale + 0.5) | (uint32_t)floor(c[1] / scale + 0.5) << 9 |
        (uint32_t)floor(c[2] / scale + 0.5) << 18 | (uint32_t)exp << 27;
}

static void test_rgb9e5(void) {
    float z[3] = {0, 0, 0}, one[3] = {1, 1, 1}, mx[3] = {65408, 65408, 65408}, big[3] = {1e9f, INFINITY, 70000};
    float out[3];
    CHECK(lc_rgb9e5_encode(z) == 0, "zero");
    CHECK(lc_rgb9e5_encode(one) == 0x84020100u, "one: %08x", lc_rgb9e5_encode(one));
    lc_rgb9e5_decode(0x84020100u, out);
    CHECK(out[0] == 1 && out[1] == 1 && out[2] == 1, "decode one");
    CHECK(lc_rgb9e5_encode(mx) == 0xFFFFFFFFu, "max: %08x", lc_rgb9e5_encode(mx));
    lc_rgb9e5_decode(0xFFFFFFFFu, out);
    CHECK(out[0] == 65408 && out[2] == 65408, "decode max");
    CHECK(lc_rgb9e5_encode(big) == 0xFFFFFFFFu, "clamped to max");
    float tiny[3] = {0x1p-24f, 0, 0}, tinier[3] = {0x1p-26f, 0, 0}, half_tiny[3] = {0x1p-25f, 0, 0};
    CHECK(lc_rgb9e5_encode(tiny) == 1, "smallest: %08x", lc_rgb9e5_encode(tiny));
    lc_rgb9e5_decode(1, out);
    CHECK(out[0] == 0x1p-24f, "decode smallest");
    CHECK(lc_rgb9e5_encode(tinier) == 0, "below smallest rounds to 0");
    CHECK(lc_rgb9e5_encode(half_tiny) == 1, "half of smallest rounds up");
    float neg[3] = {-1, NAN, -INFINITY};
    CHECK(lc_rgb9e5_encode(neg) == 0, "negative/NaN -> 0");
    float mixed[3] = {-5, 2, NAN};
    lc_rgb9e5_decode(lc_rgb9e5_encode(mixed), out);
    CHECK(out[0] == 0 && out[1] == 2 && out[2] == 0, "mixed: %g %g %g", out[0], out[1], out[2]);
    /* rounding up to the next exponent: 511.75/512 */
    float up[3] = {0.9995f, 0.5f, 0};
    lc_rgb9e5_decode(lc_rgb9e5_encode(up), out);
    CHECK(out[0] == 1 && out[1] == 0.5f, "carry into exponent: %g %g", out[0], out[1]);

    int differ = 0;
    for (int i = 0; i < 1000000; i++) {
        float c[3];
        for (int k = 0; k < 3; k++) {
            uint32_t bits = (uint32_t)(rnd() * 4294967296.0); /* any float: NaN, inf, subnormal, negative */
            if (i % 2) bits = (bits & 0x807FFFFFu) | (uint32_t)(96 + (int)(rnd() * 50)) << 23; /* the 9e5 range */
            memcpy(&c[k], &bits, sizeof bits);
        }
        differ += lc_rgb9e5_encode(c) != rgb9e5_spec(c);
    }
    CHECK(differ == 0, "rgb9e5: %d of 1e6 random texels differ from the specification's formula", differ);

    int bad = 0, unstable = 0;
    double worst = 0;
    for (int i = 0; i < 200000; i++) {
        float c[3];
        double scale = ldexp(1.0, (int)(rnd() * 40) - 24);
        for (int k = 0; k < 3; k++) c[k] = (float)(rnd() * scale);
        if (i % 7 == 0) c[i % 3] = 0;
        uint32_t v = lc_rgb9e5_encode(c);
        lc_rgb9e5_decode(v, out);
        double m = fmax(c[0], fmax(c[1], c[2]));
        if (m > 65408) m = 65408;
        /* half a quantum: 2^-9 of the max channel (of the decoded max when rounding carried
         * into the next exponent), never below half the smallest step 2^-24 */
        double mo = fmax(m, fmax(out[0], fmax(out[1], out[2])));
        for (int k = 0; k < 3; k++) {
            double want = fmin(c[k], 65408);
            double errk = fabs(out[k] - want);
            double tol = fmax(mo * 0x1p-9, 0x1p-25);
            if (errk > tol * (1 + 1e-9)) {
                bad++;
                fprintf(stderr, "  rgb9e5 %a %a %a ch %d -> %a\n", c[0], c[1], c[2], k, out[k]);
            }
            if (m > 0x1p-15) worst = fmax(worst, errk / mo);
        }
        if (lc_rgb9e5_encode(out) != v) unstable++;
    }
    CHECK(bad == 0, "%d channels outside 2^-9 of max", bad);
    CHECK(unstable == 0, "%d decoded colours re-encode differently", unstable);
    fprintf(stderr, "rgb9e5: worst relative error %.3g (bound %.3g)\n", worst, 0x1p-9);
}

/* --- UTF-8: the helpers, and every reply built from client text --------------------------- */

typedef struct {
    const char *s;
    size_t n;
    int ok;
} utf8_case;
#define U8(lit, ok) \
    { lit, sizeof lit - 1, ok }

static void test_utf8_valid(void) {
    static const utf8_case cases[] = {
        U8("", 1),
        U8("abc", 1),
        U8("a\0b", 1), /* NUL is a character; the length decides */
        U8("\xc2\x80", 1),
        U8("\xc3\xa9", 1),
        U8("\xdf\xbf", 1), /* 2 bytes: U+0080, é, U+07FF */
        U8("\xe0\xa0\x80", 1),
        U8("\xe2\x82\xac", 1),
        U8("\xef\xbf\xbf", 1), /* 3 bytes: U+0800, €, U+FFFF */
        U8("\xed\x9f\xbf", 1),
        U8("\xee\x80\x80", 1), /* around the surrogates */
        U8("\xf0\x90\x80\x80", 1),
        U8("\xf0\x9f\x92\xa1", 1),
        U8("\xf4\x8f\xbf\xbf", 1), /* 4 bytes .. U+10FFFF */
        U8("l\xc3\xa9\xe2\x82\xac\xf0\x9f\x92\xa1!", 1),
        /* overlong forms */
        U8("\xc0\x80", 0),
        U8("\xc0\xaf", 0),
        U8("\xc1\xbf", 0),
        U8("\xe0\x80\xaf", 0),
        U8("\xe0\x9f\xbf", 0),
        U8("\xf0\x80\x80\xaf", 0),
        U8("\xf0\x8f\xbf\xbf", 0),
        /* surrogates, alone and paired (CESU-8) */
        U8("\xed\xa0\x80", 0),
        U8("\xed\xad\xbf", 0),
        U8("\xed\xb0\x80", 0),
        U8("\xed\xbf\xbf", 0),
        U8("\xed\xa0\xbd\xed\xb2\xa1", 0),
        /* above U+10FFFF, 5/6-byte forms, bytes never used */
        U8("\xf4\x90\x80\x80", 0),
        U8("\xf5\x80\x80\x80", 0),
        U8("\xf7\xbf\xbf\xbf", 0),
        U8("\xf8\x88\x80\x80\x80", 0),
        U8("\xfc\x84\x80\x80\x80\x80", 0),
        U8("\xfe", 0),
        U8("\xff", 0),
        /* lone continuation bytes */
        U8("\x80", 0),
        U8("\xbf", 0),
        U8("a\x80z", 0),
        /* truncated sequences */
        U8("\xc3", 0),
        U8("\xe2\x82", 0),
        U8("\xf0\x9f\x92", 0),
        U8("ab\xe2", 0),
        U8("caf\xe9", 0),
        /* a bad continuation */
        U8("\xc3\x28", 0),
        U8("\xe2\x28\xa1", 0),
        U8("\xe2\x82\x28", 0),
        U8("\xf0\x9f\x28\xa1", 0),
        U8("\xf0\x9f\x92\x28", 0),
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
        CHECK(lc_proto_utf8_valid(cases[i].s, cases[i].n) == cases[i].ok, "utf8_valid case %zu (%zu bytes): want %d", i,
              cases[i].n, cases[i].ok);
    CHECK(!lc_proto_utf8_valid("\xc3\xa9", 1), "the length cuts a sequence");
    CHECK(lc_proto_utf8_valid(NULL, 0), "NULL, 0 is the empty string");
}

static void test_utf8_cut(void) {
    static const struct {
        const char *s;
        size_t len, max, want;
    } cases[] = {
        {"abc", 3, 0, 0},
        {"abc", 3, 2, 2},
        {"abc", 3, 3, 3},
        {"abc", 3, 99, 3},
        /* a 2-, 3- and 4-byte character across the cut */
        {"a\xc3\xa9", 3, 1, 1},
        {"a\xc3\xa9", 3, 2, 1},
        {"a\xc3\xa9", 3, 3, 3},
        {"a\xe2\x82\xac", 4, 2, 1},
        {"a\xe2\x82\xac", 4, 3, 1},
        {"a\xe2\x82\xac", 4, 4, 4},
        {"a\xf0\x9f\x92\xa1", 5, 2, 1},
        {"a\xf0\x9f\x92\xa1", 5, 3, 1},
        {"a\xf0\x9f\x92\xa1", 5, 4, 1},
        {"a\xf0\x9f\x92\xa1", 5, 5, 5},
        {"\xf0\x9f\x92\xa1\xf0\x9f\x92\xa1", 8, 7, 4},
        {"\xc3\xa9", 2, 1, 0},
        /* a sequence the length cuts short is not a character either */
        {"ab\xe2\x82", 4, 10, 2},
        {"ab\xf0\x9f\x92", 5, 5, 2},
        {"\xc3", 1, 1, 0},
        {"a\xc3\xa9", 2, 9, 1},
        /* ill-formed bytes elsewhere are units of their own (not repaired by a cut) */
        {"a\xffz", 3, 3, 3},
        {"a\xffz", 3, 2, 2},
        {"a\xc0\xafz", 4, 3, 3},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        size_t got = lc_proto_utf8_cut(cases[i].s, cases[i].len, cases[i].max);
        CHECK(got == cases[i].want, "utf8_cut case %zu: max %zu -> %zu, want %zu", i, cases[i].max, got, cases[i].want);
    }
    /* every max over a mixed string: the longest valid prefix that fits */
    static const char mixed[] = "a\xc3\xa9\xe2\x82\xac\xf0\x9f\x92\xa1z"; /* a é € 💡 z */
    static const size_t ends[] = {0, 1, 3, 6, 10, 11};
    for (size_t max = 0; max <= sizeof mixed; max++) {
        size_t want = 0;
        for (size_t k = 0; k < sizeof ends / sizeof ends[0]; k++)
            if (ends[k] <= max) want = ends[k];
        size_t got = lc_proto_utf8_cut(mixed, sizeof mixed - 1, max);
        CHECK(got == want && lc_proto_utf8_valid(mixed, got), "mixed: max %zu -> %zu, want %zu", max, got, want);
    }
}

static void test_utf8_sanitize(void) {
    static const struct {
        const char *s;
        size_t n;
        unsigned flags;
        const char *want;
    } cases[] = {
        {"caf\xe9", 4, 0, "caf\xef\xbf\xbd"},                           /* Latin-1 é */
        {"\xe2\x82x", 3, 0, "\xef\xbf\xbdx"},                           /* one U+FFFD per truncated sequence */
        {"\xed\xa0\x80", 3, 0, "\xef\xbf\xbd\xef\xbf\xbd\xef\xbf\xbd"}, /* surrogate: ED, A0, 80 */
        {"\xc0\xaf", 2, 0, "\xef\xbf\xbd\xef\xbf\xbd"},                 /* overlong */
        {"\xf4\x90\x80\x80", 4, 0, "\xef\xbf\xbd\xef\xbf\xbd\xef\xbf\xbd\xef\xbf\xbd"},
        {"l\xc3\xa9\xe2\x82\xac\xf0\x9f\x92\xa1", 10, 0, "l\xc3\xa9\xe2\x82\xac\xf0\x9f\x92\xa1"}, /* valid: as is */
        {"a\nb\x7f\xc2\x85z", 7, 0, "a\nb\x7f\xc2\x85z"},
        {"a\nb\x7f\xc2\x85\xc2\xa0z", 9, LC_PROTO_UTF8_NO_CONTROLS,
         "a\xef\xbf\xbd"
         "b\xef\xbf\xbd\xef\xbf\xbd\xc2\xa0z"}, /* C0, DEL, C1 go; U+00A0 stays */
    };
    char out[64];
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        size_t used = lc_proto_utf8_sanitize(out, sizeof out, cases[i].s, cases[i].n, cases[i].flags);
        CHECK(used == cases[i].n && !strcmp(out, cases[i].want), "sanitize case %zu: used %zu, '%s'", i, used, out);
    }
    /* the output stops before a character that does not fit */
    CHECK(lc_proto_utf8_sanitize(out, 4, "ab\xe2\x82\xac", 5, 0) == 2 && !strcmp(out, "ab"), "cap 4: '%s'", out);
    CHECK(lc_proto_utf8_sanitize(out, 6, "ab\xe2\x82\xac", 5, 0) == 5 && !strcmp(out, "ab\xe2\x82\xac"), "cap 6");
    CHECK(lc_proto_utf8_sanitize(out, 5, "ab\xff", 3, 0) == 2 && !strcmp(out, "ab"), "no room for U+FFFD");
    CHECK(lc_proto_utf8_sanitize(out, 1, "ab", 2, 0) == 0 && out[0] == 0, "cap 1");
    out[0] = 'x';
    CHECK(lc_proto_utf8_sanitize(out, 0, "ab", 2, 0) == 0 && out[0] == 'x', "cap 0 writes nothing");
    /* random bytes: the output is always valid, and valid input comes back unchanged */
    static const unsigned char pool[] = {'a',  0x00, 0x0a, 0x7f, 0x80, 0x9f, 0xa0, 0xbf, 0xc0, 0xc2, 0xc3, 0xdf,
                                         0xe0, 0xe2, 0xed, 0xef, 0xf0, 0xf4, 0xf5, 0xff, 0x82, 0xac, 0x90, 0x8f};
    uint64_t x = 0x2545F4914F6CDD1DULL;
    int bad = 0;
    for (int it = 0; it < 20000; it++) {
        char in[12], big[12 * 3 + 1], small[9];
        size_t n = (size_t)(it % 12);
        for (size_t k = 0; k < n; k++) {
            x ^= x << 13, x ^= x >> 7, x ^= x << 17;
            in[k] = (char)pool[x % sizeof pool];
        }
        size_t used = lc_proto_utf8_sanitize(big, sizeof big, in, n, (unsigned)(it & 1));
        if (used != n || !lc_proto_utf8_valid(big, strlen(big))) bad++;
        if (!(it & 1) && lc_proto_utf8_valid(in, n) && !memchr(in, 0, n) && (strlen(big) != n || memcmp(big, in, n)))
            bad++;
        lc_proto_utf8_sanitize(small, sizeof small, in, n, (unsigned)(it & 1));
        if (!lc_proto_utf8_valid(small, strlen(small))) bad++;
        if (lc_proto_utf8_valid(in, n) && !lc_proto_utf8_valid(in, lc_proto_utf8_cut(in, n, (size_t)it % 7))) bad++;
    }
    CHECK(bad == 0, "%d random inputs broke a UTF-8 property", bad);
}

/* Error replies quote the client's `type`: cut on a character boundary, no control characters. */
static void test_utf8_replies(void) {
    lc_proto_request r;
    lc_proto_error e;
    char msg[256];
    /* 63 ASCII bytes, then é across the 64-byte cut */
    char type[64 + 16];
    memset(type, 'x', 63);
    strcpy(type + 63, "\xc3\xa9tail");
    snprintf(msg, sizeof msg, "{\"type\":\"%s\",\"id\":3}", type);
    CHECK(parse(msg, &r, &e) == -1 && !strcmp(e.code, "unknown_type") && r.id.kind == 2, "long type");
    CHECK(lc_proto_utf8_valid(e.message, strlen(e.message)), "unknown_type message is not UTF-8: %s", e.message);
    CHECK(strstr(e.message, "xxx\"") == NULL && strstr(e.message, "xxx...\"") != NULL, "cut shown: %s", e.message);
    char *reply = lc_proto_build_error(&r.id, &e);
    CHECK(reply && lc_proto_utf8_valid(reply, strlen(reply)), "error reply is not UTF-8: %s", reply ? reply : "NULL");
    free(reply);
    lc_proto_request_release(&r);
    /* a 2-byte é entirely within the cut stays */
    memset(type, 'x', 62);
    strcpy(type + 62, "\xc3\xa9");
    snprintf(msg, sizeof msg, "{\"type\":\"%s\"}", type);
    CHECK(parse(msg, &r, &e) == -1 && strstr(e.message, "xx\xc3\xa9\"") != NULL, "whole é kept: %s", e.message);
    lc_proto_request_release(&r);
    /* 3- and 4-byte characters across the cut */
    const char *wide[] = {"\xe2\x82\xac", "\xf0\x9f\x92\xa1"};
    for (int w = 0; w < 2; w++)
        for (int lead = 61; lead <= 63; lead++) {
            memset(type, 'x', (size_t)lead);
            strcpy(type + lead, wide[w]);
            snprintf(msg, sizeof msg, "{\"type\":\"%s\"}", type);
            CHECK(parse(msg, &r, &e) == -1 && lc_proto_utf8_valid(e.message, strlen(e.message)),
                  "%d-byte character after %d bytes: %s", 3 + w, lead, e.message);
            lc_proto_request_release(&r);
        }
    /* ill-formed bytes and control characters in the type are not copied */
    CHECK(parse("{\"type\":\"caf\xe9\",\"id\":\"q\"}", &r, &e) == -1 && !strcmp(e.code, "unknown_type") &&
              lc_proto_utf8_valid(e.message, strlen(e.message)) && strstr(e.message, "caf\xef\xbf\xbd") &&
              r.id.kind == 1,
          "Latin-1 type: %s", e.message);
    lc_proto_request_release(&r);
    CHECK(parse("{\"type\":\"a\\nb\\u001b[2J\"}", &r, &e) == -1 && !strpbrk(e.message, "\n\x1b"),
          "control characters in the message: %s", e.message);
    lc_proto_request_release(&r);
}

/* Builders write valid UTF-8 whatever strings they are handed. */
static void test_utf8_builders(void) {
    lc_proto_id sid = {1, "r", 0};
    const char *mats[] = {"caf\xe9", "ok"}, *assets[] = {"\xff"};
    lc_proto_welcome w = {0};
    w.server = "lucentd/0.1.0";
    w.role = "controller";
    w.materials = mats;
    w.n_materials = 2;
    w.assets = assets;
    w.n_assets = 1;
    lc_proto_default_limits(&w.limits);
    char *s = lc_proto_build_welcome(&sid, &w);
    CHECK(s && lc_proto_utf8_valid(s, strlen(s)) && strstr(s, "\"caf\xef\xbf\xbd\""), "welcome: %s", s ? s : "NULL");
    free(s);
    /* a message cut by its buffer inside é: the cut character is dropped */
    lc_proto_error e;
    memset(&e, 0, sizeof e);
    strcpy(e.code, "invalid");
    memset(e.message, 'm', sizeof e.message - 2);
    e.message[sizeof e.message - 2] = (char)0xc3;
    s = lc_proto_build_error(&sid, &e);
    CHECK(s && lc_proto_utf8_valid(s, strlen(s)), "error with a cut message: %.40s", s ? s : "NULL");
    cJSON *j = s ? cJSON_Parse(s) : NULL;
    CHECK(j && strlen(str(j, "message")) == sizeof e.message - 2, "cut character dropped");
    cJSON_Delete(j);
    free(s);
    strcpy(e.message, "bad \xed\xa0\x80 surrogate");
    strcpy(e.pointer, "/x\xff");
    s = lc_proto_build_error(NULL, &e);
    CHECK(s && lc_proto_utf8_valid(s, strlen(s)), "error with ill-formed message and pointer: %s", s ? s : "NULL");
    free(s);
    lc_proto_op op;
    memset(&op, 0, sizeof op);
    op.type = LC_REQ_MATERIAL_SET;
    strcpy(op.target, "caf\xe9");
    s = lc_proto_build_changed(1, "client\xc0\xaf", &op, 1);
    CHECK(s && lc_proto_utf8_valid(s, strlen(s)), "changed: %s", s ? s : "NULL");
    free(s);
    s = lc_proto_build_op(&op);
    CHECK(s && lc_proto_utf8_valid(s, strlen(s)), "op: %s", s ? s : "NULL");
    free(s);
    lc_proto_material_state ms = {"caf\xe9", {0, 0, 0}};
    lc_proto_state st;
    memset(&st, 0, sizeof st);
    st.materials = &ms;
    st.n_materials = 1;
    s = lc_proto_build_state(&sid, &st);
    CHECK(s && lc_proto_utf8_valid(s, strlen(s)), "state: %s", s ? s : "NULL");
    free(s);
}

/* A \u0000 anywhere but in the id itself keeps the id in the error (issue 13). */
static void test_nul_escape(void) {
    lc_proto_request r;
    lc_proto_error e;
    CHECK(parse("{\"id\":\"abc\",\"type\":\"light.remove\",\"light_id\":\"a\\u0000b\"}", &r, &e) == -1 &&
              !strcmp(e.code, "invalid") && r.id.kind == 1 && !strcmp(r.id.str, "abc"),
          "string id kept: kind %d '%s' (%s)", r.id.kind, r.id.str, e.message);
    lc_proto_request_release(&r);
    CHECK(parse("{\"type\":\"light.remove\",\"light_id\":\"\\u0000\",\"id\":7}", &r, &e) == -1 && r.id.kind == 2 &&
              r.id.num == 7,
          "integer id after the NUL kept");
    lc_proto_request_release(&r);
    CHECK(parse("{\"id\":5,\"type\":\"light.set\",\"light\":{\"id\":\"a\\u0000\",\"type\":\"point\"," LIGHT_PT "}}", &r,
                &e) == -1 &&
              r.id.kind == 2 && r.id.num == 5,
          "a nested \"id\" is not the request id");
    lc_proto_request_release(&r);
    CHECK(parse("{\"id\":\"q\",\"type\":\"snapshot\",\"x\\u0000\":1}", &r, &e) == -1 && r.id.kind == 1 &&
              !strcmp(r.id.str, "q"),
          "NUL in another key");
    lc_proto_request_release(&r);
    /* the id itself: not echoed (cJSON would cut it at the NUL), pointer /id */
    CHECK(parse("{\"id\":\"ab\\u0000c\",\"type\":\"snapshot\"}", &r, &e) == -1 && r.id.kind == 0 &&
              !strcmp(e.code, "invalid") && !strcmp(e.pointer, "/id"),
          "NUL in the id: kind %d, %s", r.id.kind, e.pointer);
    lc_proto_request_release(&r);
    CHECK(parse("{\"\\u0069d\":\"\\u0000\",\"type\":\"snapshot\"}", &r, &e) == -1 && r.id.kind == 0 &&
              !strcmp(e.pointer, "/id"),
          "escaped member name");
    lc_proto_request_release(&r);
    CHECK(parse("{\"id\\u0000\":\"x\",\"type\":\"snapshot\"}", &r, &e) == -1 && r.id.kind == 0 &&
              !strcmp(e.pointer, "/id"),
          "NUL in the id's member name");
    lc_proto_request_release(&r);
    /* the first "id" member is the one cJSON reads */
    CHECK(parse("{\"id\":\"one\",\"id\":\"t\\u0000\",\"type\":\"snapshot\"}", &r, &e) == -1 && r.id.kind == 1 &&
              !strcmp(r.id.str, "one"),
          "duplicate id: the first counts");
    lc_proto_request_release(&r);
    CHECK(parse("{\"id\":\"o\\u0000\",\"id\":\"two\",\"type\":\"snapshot\"}", &r, &e) == -1 && r.id.kind == 0,
          "duplicate id with the NUL in the first");
    lc_proto_request_release(&r);
    /* an invalid id is still not echoed */
    CHECK(parse("{\"id\":-1,\"type\":\"snapshot\",\"s\":\"\\u0000\"}", &r, &e) == -1 && r.id.kind == 0 &&
              !strcmp(e.pointer, "/id"),
          "invalid id");
    lc_proto_request_release(&r);
    /* snapshot files still refuse it */
    lc_proto_parsed_state ps;
    const char *st =
        "{\"type\":\"state\",\"revision\":1,\"lights\":[],\"objects\":[],\"materials\":[{\"name\":\"a\\u0000\","
        "\"emission\":[0,0,0]}],\"environment\":{\"type\":\"none\"},\"settings\":{}}";
    CHECK(lc_proto_parse_state(st, strlen(st), &ps, &e) == -1 && !strcmp(e.code, "invalid"), "state with NUL");
}

/* Issue 19: object.set "mode" (§4.5), state objects' "transport" (§5.4), object.transport (§5.5),
 * welcome.scene.clutter. */
static void test_clutter_fields(void) {
    lc_proto_request r;
    PARSE_OK("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\"}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].object.mode == LC_OBJECT_MODE_DYNAMIC && r.ops[0].object.transport == 0,
          "mode defaults to dynamic");
    lc_proto_request_release(&r);
    const char *modes[] = {"dynamic", "clutter", "auto"};
    for (int m = 0; m < 3; m++) {
        char msg[160];
        snprintf(msg, sizeof msg, "{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"c\",\"mode\":\"%s\"}}",
                 modes[m]);
        PARSE_OK(msg, &r);
        CHECK(r.n_ops == 1 && r.ops[0].object.mode == m, "mode %s", modes[m]);
        char *s = r.n_ops == 1 ? lc_proto_build_op(&r.ops[0]) : NULL;
        char want[32];
        snprintf(want, sizeof want, "\"mode\":\"%s\"", modes[m]);
        CHECK(s && strstr(s, want) && !strstr(s, "transport"), "journal op keeps the mode, no transport: %s",
              s ? s : "NULL");
        lc_proto_request b;
        if (s) {
            PARSE_OK(s, &b);
            CHECK(b.n_ops == 1 && !memcmp(&r.ops[0], &b.ops[0], sizeof b.ops[0]), "mode op round trip: %s", s);
            lc_proto_request_release(&b);
        }
        free(s);
        lc_proto_request_release(&r);
    }
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"c\",\"mode\":\"static\"}}", "invalid",
            "/object/mode");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"c\",\"mode\":3}}", "invalid",
            "/object/mode");
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"c\",\"mode\":\"\"}}", "invalid",
            "/object/mode");
    INVALID("{\"type\":\"batch\",\"ops\":[{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"c\",\"mode\":"
            "null}}]}",
            "invalid", "/ops/0/object/mode");
    /* transport is the server's: a client's is ignored */
    PARSE_OK("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"c\",\"transport\":\"clutter\"}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].object.transport == 0, "transport in object.set is ignored");
    lc_proto_request_release(&r);

    /* state: transport written only when set; an older snapshot (no mode) reads as dynamic */
    lc_proto_object objs[2] = {{.id = "a",
                                .asset = "c",
                                .rotation = {0, 0, 0, 1},
                                .scale = {1, 1, 1},
                                .visible = 1,
                                .dnrt = 1,
                                .mode = LC_OBJECT_MODE_AUTO,
                                .transport = 1 + LC_OBJECT_TRANSPORT_CLUTTER},
                               {.id = "b",
                                .asset = "c",
                                .rotation = {0, 0, 0, 1},
                                .scale = {1, 1, 1},
                                .visible = 1,
                                .dnrt = 1,
                                .mode = LC_OBJECT_MODE_CLUTTER}};
    lc_proto_state st = {0};
    st.objects = objs;
    st.n_objects = 2;
    st.settings.present = LC_SET_ALL;
    st.settings.bounces = 1;
    st.settings.bands = st.settings.chroma_bands = 3;
    char *text = lc_proto_build_state(NULL, &st);
    cJSON *j = text ? cJSON_Parse(text) : NULL;
    const cJSON *ja = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "objects"), 0),
                *jb = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "objects"), 1);
    CHECK(cJSON_IsString(cJSON_GetObjectItem(ja, "mode")) &&
              !strcmp(cJSON_GetObjectItem(ja, "mode")->valuestring, "auto") &&
              cJSON_IsString(cJSON_GetObjectItem(ja, "transport")) &&
              !strcmp(cJSON_GetObjectItem(ja, "transport")->valuestring, "clutter") &&
              !cJSON_GetObjectItem(jb, "transport"),
          "state objects: mode, and transport only when the server set it: %s", text ? text : "NULL");
    cJSON_Delete(j);
    lc_proto_parsed_state p;
    lc_proto_error e;
    int rc = text ? lc_proto_parse_state(text, strlen(text), &p, &e) : -1;
    CHECK(rc == 0 && p.n_objects == 2 && p.objects[0].mode == LC_OBJECT_MODE_AUTO &&
              p.objects[1].mode == LC_OBJECT_MODE_CLUTTER && p.objects[0].transport == 0,
          "state mode round trip (transport not read back)");
    if (rc == 0) lc_proto_parsed_state_free(&p);
    free(text);

    /* object.transport */
    char *ev = lc_proto_build_object_transport("box", LC_OBJECT_TRANSPORT_CLUTTER, 12, 812.5, 6332416);
    CHECK(ev &&
              !strcmp(ev,
                      "{\"type\":\"object.transport\",\"object_id\":\"box\",\"transport\":\"clutter\",\"revision\":"
                      "12,\"build_ms\":812.5,\"bytes\":6332416}"),
          "object.transport clutter: %s", ev ? ev : "NULL");
    free(ev);
    ev = lc_proto_build_object_transport("box", LC_OBJECT_TRANSPORT_DYNAMIC, 13, 812.5, 6332416);
    CHECK(ev &&
              !strcmp(ev,
                      "{\"type\":\"object.transport\",\"object_id\":\"box\",\"transport\":\"dynamic\",\"revision\":"
                      "13}"),
          "object.transport dynamic: no build fields: %s", ev ? ev : "NULL");
    free(ev);
    ev = lc_proto_build_object_transport("bad\xff", LC_OBJECT_TRANSPORT_DYNAMIC, 1, 0, 0);
    CHECK(ev && lc_proto_utf8_valid(ev, strlen(ev)), "object.transport is valid UTF-8 for any id");
    free(ev);
}

/* Issue 17: object.set "dnrt", settings.set "dnrt" / "dnrt_blockers" (defaults, type errors
 * naming the field, journal and snapshot round trips, older snapshots without them) and
 * welcome.scene.asset_info. */
static void test_dnrt_fields(void) {
    lc_proto_request r;
    PARSE_OK("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\"}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].object.dnrt == 1, "object dnrt defaults to true");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"dnrt\":false}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].object.dnrt == 0 && r.ops[0].object.visible == 1, "object dnrt false");
    lc_proto_request_release(&r);
    INVALID("{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"dnrt\":5}}", "invalid",
            "/object/dnrt");
    INVALID(
        "{\"type\":\"batch\",\"ops\":[{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"c\",\"dnrt\":\"no\"}}]}",
        "invalid", "/ops/0/object/dnrt");

    PARSE_OK("{\"type\":\"settings.set\",\"settings\":{\"dnrt\":false}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].settings.present == 1u << LC_SET_DNRT && r.ops[0].settings.dnrt == 0,
          "settings dnrt alone: present %x", r.n_ops ? r.ops[0].settings.present : 0);
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"settings.set\",\"settings\":{\"dnrt\":true,\"dnrt_blockers\":false,\"bounces\":2}}", &r);
    CHECK(r.n_ops == 1 &&
              r.ops[0].settings.present ==
                  ((1u << LC_SET_DNRT) | (1u << LC_SET_DNRT_BLOCKERS) | (1u << LC_SET_BOUNCES)) &&
              r.ops[0].settings.dnrt == 1 && r.ops[0].settings.dnrt_blockers == 0 && r.ops[0].settings.bounces == 2,
          "settings dnrt + dnrt_blockers");
    lc_proto_request_release(&r);
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"dnrt\":1}}", "invalid", "/settings/dnrt");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"dnrt_blockers\":null}}", "invalid", "/settings/dnrt_blockers");
    CHECK(LC_SET_ALL == 0xFF, "eight settings fields (solver the eighth): %x", LC_SET_ALL);

    /* journal records: build_op -> parse gives the same op, the new fields included */
    const char *msgs[] = {
        "{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"dnrt\":false}}",
        "{\"type\":\"settings.set\",\"settings\":{\"dnrt\":false,\"dnrt_blockers\":true}}",
    };
    for (int i = 0; i < 2; i++) {
        lc_proto_request a, b;
        PARSE_OK(msgs[i], &a);
        char *s = a.n_ops == 1 ? lc_proto_build_op(&a.ops[0]) : NULL;
        CHECK(s != NULL, "build_op dnrt %d", i);
        if (s) {
            CHECK(strstr(s, "\"dnrt\":false") != NULL, "the op says dnrt false: %s", s);
            PARSE_OK(s, &b);
            CHECK(b.n_ops == 1 && !memcmp(&a.ops[0], &b.ops[0], sizeof a.ops[0]), "dnrt op round trip %d: %s", i, s);
            lc_proto_request_release(&b);
            free(s);
        }
        lc_proto_request_release(&a);
    }

    /* A snapshot written before issue 17 (no dnrt anywhere) reads with the defaults. */
    const char *old =
        "{\"type\":\"state\",\"revision\":7,\"lights\":[],\"objects\":[{\"id\":\"o\",\"asset\":\"chair\","
        "\"translation\":[0,0,0],\"rotation\":[0,0,0,1],\"scale\":[1,1,1],\"visible\":true}],\"materials\":[],"
        "\"environment\":{\"type\":\"none\"},\"settings\":{\"bounces\":1,\"bands\":3,\"progressive\":true,"
        "\"chroma_compression\":false,\"chroma_bands\":3}}";
    lc_proto_parsed_state p;
    lc_proto_error e;
    int rc = lc_proto_parse_state(old, strlen(old), &p, &e);
    CHECK(rc == 0 && p.n_objects == 1 && p.objects[0].dnrt == 1, "old snapshot: object dnrt true (%s)", e.message);
    CHECK(rc == 0 && p.settings.present == 0x1F, "old snapshot: dnrt settings absent (present %x)", p.settings.present);
    lc_proto_parsed_state_free(&p);

    /* state text carries them, and reads back to the same values */
    lc_proto_object obj;
    PARSE_OK(msgs[0], &r);
    if (r.n_ops == 1) obj = r.ops[0].object;
    else memset(&obj, 0, sizeof obj);
    lc_proto_request_release(&r);
    lc_proto_state st = {0};
    st.objects = &obj;
    st.n_objects = 1;
    st.settings.present = LC_SET_ALL;
    st.settings.bounces = 1;
    st.settings.bands = st.settings.chroma_bands = 3;
    st.settings.dnrt = 1;
    st.settings.dnrt_blockers = 0;
    char *text = lc_proto_build_state(NULL, &st);
    cJSON *j = text ? cJSON_Parse(text) : NULL;
    const cJSON *js = cJSON_GetObjectItem(j, "settings");
    const cJSON *jo = cJSON_GetArrayItem(cJSON_GetObjectItem(j, "objects"), 0);
    CHECK(cJSON_IsTrue(cJSON_GetObjectItem(js, "dnrt")) && cJSON_IsFalse(cJSON_GetObjectItem(js, "dnrt_blockers")) &&
              cJSON_IsFalse(cJSON_GetObjectItem(jo, "dnrt")),
          "state reports dnrt: %s", text ? text : "NULL");
    cJSON_Delete(j);
    rc = text ? lc_proto_parse_state(text, strlen(text), &p, &e) : -1;
    CHECK(rc == 0 && p.n_objects == 1 && p.objects[0].dnrt == 0 && p.settings.present == LC_SET_ALL &&
              p.settings.dnrt == 1 && p.settings.dnrt_blockers == 0,
          "state dnrt round trip");
    lc_proto_parsed_state_free(&p);
    free(text);

    /* welcome.scene.asset_info: per asset, transfer or {} */
    const char *assets[] = {"cube", "old\xff"}, *mats[] = {"white"};
    lc_proto_asset_info info[2] = {{1, 32, 4, 524288, 0.5196152f}, {0, 0, 0, 0, 0}};
    lc_proto_welcome w = {0};
    w.server = "lucentd/0.1.0";
    w.role = "viewer";
    w.lightmap_width = w.lightmap_height = 64;
    w.tile = 32;
    w.grid_cell = 0.5f;
    w.grid_dims[0] = w.grid_dims[1] = w.grid_dims[2] = 2;
    w.bands = 3;
    w.assets = assets;
    w.n_assets = 2;
    w.materials = mats;
    w.n_materials = 1;
    lc_proto_default_limits(&w.limits);
    j = reparse(lc_proto_build_welcome(NULL, &w));
    CHECK(j && !cJSON_GetObjectItem(cJSON_GetObjectItem(j, "scene"), "asset_info"), "no asset_info when not given");
    cJSON_Delete(j);
    w.asset_info = info;
    j = reparse(lc_proto_build_welcome(NULL, &w));
    const cJSON *ai = cJSON_GetObjectItem(cJSON_GetObjectItem(j, "scene"), "asset_info");
    const cJSON *tr = cJSON_GetObjectItem(cJSON_GetObjectItem(ai, "cube"), "transfer");
    const cJSON *o2 = cJSON_GetObjectItem(ai, "old\xef\xbf\xbd");
    CHECK(cJSON_GetArraySize(ai) == 2 && num(tr, "dims") == 32 && num(tr, "coefficients") == 4 &&
              num(tr, "bytes") == 524288 && (float)num(tr, "outer_radius") == 0.5196152f,
          "asset_info transfer");
    CHECK(cJSON_IsObject(o2) && o2->child == NULL, "an asset without transfer data is {} (key made valid UTF-8)");
    cJSON_Delete(j);
}

/* settings.solver "pic" | "probes": parsed like an enum (the server checks which the bake
 * offers), refused with /settings/solver otherwise, carried by journal records and state
 * text; an older snapshot lacks it; welcome.scene.solvers lists the offered ones. */
static void test_solver_fields(void) {
    lc_proto_request r;
    PARSE_OK("{\"type\":\"settings.set\",\"settings\":{\"solver\":\"probes\"}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].settings.present == 1u << LC_SET_SOLVER &&
              r.ops[0].settings.solver == LC_PROTO_SOLVER_PROBES,
          "solver probes alone: present %x", r.n_ops ? r.ops[0].settings.present : 0);
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"settings.set\",\"settings\":{\"solver\":\"pic\",\"bounces\":3}}", &r);
    CHECK(r.n_ops == 1 && r.ops[0].settings.present == ((1u << LC_SET_SOLVER) | (1u << LC_SET_BOUNCES)) &&
              r.ops[0].settings.solver == LC_PROTO_SOLVER_PIC && r.ops[0].settings.bounces == 3,
          "solver pic + bounces");
    lc_proto_request_release(&r);
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"solver\":\"radiosity\"}}", "invalid", "/settings/solver");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"solver\":\"PIC\"}}", "invalid", "/settings/solver");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"solver\":1}}", "invalid", "/settings/solver");
    INVALID("{\"type\":\"settings.set\",\"settings\":{\"solver\":null}}", "invalid", "/settings/solver");
    INVALID("{\"type\":\"batch\",\"ops\":[{\"type\":\"settings.set\",\"settings\":{\"solver\":\"\"}}]}", "invalid",
            "/ops/0/settings/solver");
    lc_proto_error e;
    const char *bad = "{\"type\":\"settings.set\",\"settings\":{\"solver\":\"x\"}}";
    CHECK(parse(bad, &r, &e) != 0 && strstr(e.message, "pic, probes") != NULL, "the error lists the solvers: %s",
          e.message);
    lc_proto_request_release(&r);
    CHECK(!strcmp(lc_proto_solver_name(LC_PROTO_SOLVER_PIC), "pic") &&
              !strcmp(lc_proto_solver_name(LC_PROTO_SOLVER_PROBES), "probes") && !lc_proto_solver_name(2) &&
              !lc_proto_solver_name(-1),
          "solver names");

    /* journal record round trip */
    lc_proto_request a, b;
    PARSE_OK("{\"type\":\"settings.set\",\"settings\":{\"solver\":\"probes\"}}", &a);
    char *s = a.n_ops == 1 ? lc_proto_build_op(&a.ops[0]) : NULL;
    CHECK(s && strstr(s, "\"solver\":\"probes\"") != NULL, "the op says solver probes: %s", s ? s : "NULL");
    if (s) {
        PARSE_OK(s, &b);
        CHECK(b.n_ops == 1 && !memcmp(&a.ops[0], &b.ops[0], sizeof a.ops[0]), "solver op round trip: %s", s);
        lc_proto_request_release(&b);
    }
    free(s);
    lc_proto_request_release(&a);

    /* state text: solver written, read back; a snapshot without it parses without the bit */
    lc_proto_state st = {0};
    st.settings.present = LC_SET_ALL;
    st.settings.bounces = 1;
    st.settings.bands = st.settings.chroma_bands = 3;
    st.settings.solver = LC_PROTO_SOLVER_PROBES;
    char *text = lc_proto_build_state(NULL, &st);
    lc_proto_parsed_state p;
    int rc = text ? lc_proto_parse_state(text, strlen(text), &p, &e) : -1;
    CHECK(rc == 0 && strstr(text, "\"solver\":\"probes\"") && p.settings.present == LC_SET_ALL &&
              p.settings.solver == LC_PROTO_SOLVER_PROBES,
          "state solver round trip: %s", text ? text : "NULL");
    if (rc == 0) lc_proto_parsed_state_free(&p);
    free(text);
    const char *old = "{\"type\":\"state\",\"revision\":7,\"lights\":[],\"objects\":[],\"materials\":[],"
                      "\"environment\":{\"type\":\"none\"},\"settings\":{\"bounces\":1,\"dnrt\":true}}";
    rc = lc_proto_parse_state(old, strlen(old), &p, &e);
    CHECK(rc == 0 && !(p.settings.present & (1u << LC_SET_SOLVER)), "old snapshot: no solver (present %x)",
          rc == 0 ? p.settings.present : 0);
    if (rc == 0) lc_proto_parsed_state_free(&p);

    /* welcome.scene.solvers: only when given, in protocol order */
    const char *mats[] = {"white"};
    lc_proto_welcome w = {0};
    w.server = "lucentd/0.1.0";
    w.role = "viewer";
    w.lightmap_width = w.lightmap_height = w.tile = 32;
    w.grid_cell = 0.5f;
    w.grid_dims[0] = w.grid_dims[1] = w.grid_dims[2] = 2;
    w.bands = 3;
    w.materials = mats;
    w.n_materials = 1;
    lc_proto_default_limits(&w.limits);
    cJSON *j = reparse(lc_proto_build_welcome(NULL, &w));
    CHECK(j && !cJSON_GetObjectItem(cJSON_GetObjectItem(j, "scene"), "solvers"), "no solvers when not given");
    cJSON_Delete(j);
    static const struct {
        uint32_t bits;
        const char *want;
    } cases[] = {{1u << LC_PROTO_SOLVER_PIC, "[\"pic\"]"},
                 {1u << LC_PROTO_SOLVER_PROBES, "[\"probes\"]"},
                 {(1u << LC_PROTO_SOLVER_PIC) | (1u << LC_PROTO_SOLVER_PROBES), "[\"pic\",\"probes\"]"}};
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        w.solvers = cases[i].bits;
        j = reparse(lc_proto_build_welcome(NULL, &w));
        char *got = cJSON_PrintUnformatted(cJSON_GetObjectItem(cJSON_GetObjectItem(j, "scene"), "solvers"));
        CHECK(got && !strcmp(got, cases[i].want), "welcome solvers %x: %s, expected %s", cases[i].bits,
              got ? got : "NULL", cases[i].want);
        cJSON_free(got);
        cJSON_Delete(j);
    }
}

/* --- lucent/1.1 MR messages (§8.1-8.3, 8.5, 8.7) -------------------------------------------- */

static void test_mr_hello(void) {
    lc_proto_request r;
    PARSE_OK("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"mr\",\"future\"]}", &r);
    CHECK(r.capabilities == LC_CAP_MR, "capabilities %u", r.capabilities);
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"future\"]}", &r);
    CHECK(r.capabilities == 0, "unknown names only: %u", r.capabilities);
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[]}", &r);
    CHECK(r.capabilities == 0, "empty list");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"hello\",\"client\":\"ar\"}", &r);
    CHECK(r.capabilities == 0, "no list");
    lc_proto_request_release(&r);
    /* 8 names of 32 bytes: the limits themselves */
    PARSE_OK("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"a\",\"b\",\"c\",\"d\",\"e\",\"f\","
             "\"gggggggggggggggggggggggggggggggg\",\"mr\"]}",
             &r);
    CHECK(r.capabilities == LC_CAP_MR, "8 names, one of 32 bytes");
    lc_proto_request_release(&r);
    INVALID("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"a\",\"b\",\"c\",\"d\",\"e\",\"f\",\"g\",\"h\","
            "\"mr\"]}",
            "invalid", "/capabilities");
    INVALID("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"mr\",\"a\",\"b\",\"\"]}", "invalid",
            "/capabilities/3");
    INVALID("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"mr\",\"a\",\"b\","
            "\"ggggggggggggggggggggggggggggggggg\"]}",
            "invalid", "/capabilities/3");
    INVALID("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"mr\",\"a\",\"b\",3]}", "invalid",
            "/capabilities/3");
    INVALID("{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":\"mr\"}", "invalid", "/capabilities");
    CHECK(!strcmp(lc_proto_capability_name(LC_CAP_MR), "mr") && lc_proto_capability_name(1u << 5) == NULL &&
              lc_proto_capability_name(0) == NULL,
          "capability names");
}

#define MR_BEGIN(fields) "{\"type\":\"mr.begin\",\"id\":5,\"session\":{" fields "}}"
#define MR_MIN "\"objects\":[\"chair-1\"],\"width\":256,\"height\":192,\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\""
#define MR_BASE "\"objects\":[\"a\"],\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\""

/* mr.begin with the given width/height over MR_BASE: 1 when it parses. */
static int mr_size_ok(unsigned w, unsigned h, const char *code, const char *ptr) {
    char buf[256];
    snprintf(buf, sizeof buf, MR_BEGIN(MR_BASE ",\"width\":%u,\"height\":%u"), w, h);
    lc_proto_request r;
    lc_proto_error e;
    int rc = parse(buf, &r, &e);
    lc_proto_request_release(&r);
    if (rc == 0) return 1;
    CHECK(!strcmp(e.code, code) && !strcmp(e.pointer, ptr), "%ux%u: %s %s, expected %s %s", w, h, e.code, e.pointer,
          code, ptr);
    return 0;
}

static void test_mr_begin(void) {
    lc_proto_request r;
    PARSE_OK(MR_BEGIN(MR_MIN), &r);
    const lc_proto_mr_session *S = &r.mr;
    CHECK(r.type == LC_REQ_MR_BEGIN && r.id.kind == 2 && r.id.num == 5 && r.ops == NULL, "mr.begin type");
    CHECK(S->n_objects == 1 && !strcmp(S->objects[0], "chair-1") && S->width == 256 && S->height == 192 &&
              S->depth_encoding == LC_DEPTH_U16MM && S->color_encoding == LC_COLOR_RGB8_SRGB,
          "minimal session fields");
    CHECK(S->max_rate == 10 && S->glossy == 1 && S->specular_exponent == 16 && S->min_confidence == 0.5 &&
              S->smoothing == 0 && S->light_add == 0,
          "defaults: rate %g glossy %d k %g conf %g s %g add %d", S->max_rate, S->glossy, S->specular_exponent,
          S->min_confidence, S->smoothing, S->light_add);
    lc_proto_request_release(&r);
    PARSE_OK(MR_BEGIN("\"objects\":[\"b\",\"a\",\"c\"],\"width\":1024,\"height\":1024,\"depth\":\"f16m\","
                      "\"color\":\"rgb16f_linear\",\"max_rate\":30,\"glossy\":false,\"specular_exponent\":64.5,"
                      "\"min_confidence\":0.25,\"smoothing\":0.75,\"light\":\"add\",\"future\":{\"x\":1}"),
             &r);
    CHECK(S->n_objects == 3 && !strcmp(S->objects[0], "b") && !strcmp(S->objects[1], "a") &&
              !strcmp(S->objects[2], "c") && S->width == 1024 && S->height == 1024 &&
              S->depth_encoding == LC_DEPTH_F16M && S->color_encoding == LC_COLOR_RGB16F_LINEAR && S->max_rate == 30 &&
              S->glossy == 0 && S->specular_exponent == 64.5 && S->min_confidence == 0.25 && S->smoothing == 0.75 &&
              S->light_add == 1,
          "full session (unknown field ignored)");
    lc_proto_request_release(&r);
    /* range edges: accepted */
    PARSE_OK(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"max_rate\":0.1,\"specular_exponent\":1,"
                              "\"min_confidence\":0,\"smoothing\":0.99"),
             &r);
    CHECK(S->width == 8 && S->height == 8 && S->max_rate == 0.1 && S->specular_exponent == 1 &&
              S->min_confidence == 0 && S->smoothing == 0.99,
          "lower edges");
    lc_proto_request_release(&r);
    PARSE_OK(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"max_rate\":60,\"specular_exponent\":10000,"
                              "\"min_confidence\":1,\"light\":\"replace\""),
             &r);
    CHECK(S->max_rate == 60 && S->specular_exponent == 10000 && S->min_confidence == 1 && S->light_add == 0,
          "upper edges");
    lc_proto_request_release(&r);
    PARSE_OK(MR_BEGIN("\"objects\":[\"o0\",\"o1\",\"o2\",\"o3\",\"o4\",\"o5\",\"o6\",\"o7\",\"o8\",\"o9\",\"oa\","
                      "\"ob\",\"oc\",\"od\",\"oe\",\"of\"],\"width\":8,\"height\":8,\"depth\":\"u16mm\","
                      "\"color\":\"rgb8_srgb\""),
             &r);
    CHECK(S->n_objects == 16 && !strcmp(S->objects[15], "of"), "16 objects");
    lc_proto_request_release(&r);
    CHECK(mr_size_ok(8, 1024, "", ""), "8x1024");
    CHECK(mr_size_ok(1024, 1024, "", ""), "1024x1024 = 2^20");
    CHECK(!mr_size_ok(7, 8, "out_of_range", "/session/width"), "width 7");
    CHECK(!mr_size_ok(1025, 8, "out_of_range", "/session/width"), "width 1025");
    CHECK(!mr_size_ok(8, 7, "out_of_range", "/session/height"), "height 7");
    CHECK(!mr_size_ok(1024, 1025, "out_of_range", "/session/height"), "1024x1025");
    /* rejected */
    INVALID(MR_BEGIN("\"objects\":[\"o0\",\"o1\",\"o2\",\"o3\",\"o4\",\"o5\",\"o6\",\"o7\",\"o8\",\"o9\",\"oa\","
                     "\"ob\",\"oc\",\"od\",\"oe\",\"of\",\"og\"],\"width\":8,\"height\":8,\"depth\":\"u16mm\","
                     "\"color\":\"rgb8_srgb\""),
            "invalid", "/session/objects");
    INVALID(MR_BEGIN("\"objects\":[],\"width\":8,\"height\":8,\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\""), "invalid",
            "/session/objects");
    INVALID(MR_BEGIN("\"objects\":[\"a\",\"b\",\"c\",\"b\"],\"width\":8,\"height\":8,\"depth\":\"u16mm\","
                     "\"color\":\"rgb8_srgb\""),
            "invalid", "/session/objects/3");
    INVALID(MR_BEGIN("\"objects\":[\"a\",\"b\",\"c\",\"\"],\"width\":8,\"height\":8,\"depth\":\"u16mm\","
                     "\"color\":\"rgb8_srgb\""),
            "invalid", "/session/objects/3");
    INVALID(MR_BEGIN("\"objects\":[\"a\",\"b\",\"c\",7],\"width\":8,\"height\":8,\"depth\":\"u16mm\","
                     "\"color\":\"rgb8_srgb\""),
            "invalid", "/session/objects/3");
    INVALID(MR_BEGIN(
                "\"objects\":[\"a\",\"b\",\"c\",\"aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\"],"
                "\"width\":8,\"height\":8,\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\""),
            "invalid", "/session/objects/3");
    INVALID(MR_BEGIN("\"objects\":\"a\",\"width\":8,\"height\":8,\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\""),
            "invalid", "/session/objects");
    INVALID(MR_BEGIN("\"width\":8,\"height\":8,\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\""), "invalid",
            "/session/objects");
    INVALID(MR_BEGIN(MR_BASE ",\"height\":8"), "invalid", "/session/width");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8.5,\"height\":8"), "invalid", "/session/width");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"max_rate\":0.05"), "out_of_range", "/session/max_rate");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"max_rate\":60.1"), "out_of_range", "/session/max_rate");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"specular_exponent\":0.5"), "out_of_range",
            "/session/specular_exponent");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"specular_exponent\":10001"), "out_of_range",
            "/session/specular_exponent");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"smoothing\":0.995"), "out_of_range", "/session/smoothing");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"min_confidence\":1.5"), "out_of_range",
            "/session/min_confidence");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"min_confidence\":-0.1"), "out_of_range",
            "/session/min_confidence");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"glossy\":1"), "invalid", "/session/glossy");
    INVALID(MR_BEGIN(MR_BASE ",\"width\":8,\"height\":8,\"light\":\"x\""), "invalid", "/session/light");
    INVALID(MR_BEGIN("\"objects\":[\"a\"],\"width\":8,\"height\":8,\"depth\":\"u8\",\"color\":\"rgb8_srgb\""),
            "invalid", "/session/depth");
    INVALID(MR_BEGIN("\"objects\":[\"a\"],\"width\":8,\"height\":8,\"color\":\"rgb8_srgb\""), "invalid",
            "/session/depth");
    INVALID(MR_BEGIN("\"objects\":[\"a\"],\"width\":8,\"height\":8,\"depth\":\"u16mm\",\"color\":\"rgb8\""), "invalid",
            "/session/color");
    INVALID("{\"type\":\"mr.begin\",\"id\":5}", "invalid", "/session");
    INVALID("{\"type\":\"mr.begin\",\"session\":[]}", "invalid", "/session");
    INVALID("{\"type\":\"batch\",\"ops\":[{\"type\":\"mr.end\"}]}", "invalid", "/ops/0/type");
    /* mr.end: no fields */
    PARSE_OK("{\"type\":\"mr.end\",\"id\":\"e\"}", &r);
    CHECK(r.type == LC_REQ_MR_END && r.id.kind == 1 && !strcmp(r.id.str, "e") && r.ops == NULL && r.n_ops == 0,
          "mr.end");
    lc_proto_request_release(&r);
    CHECK(!lc_proto_is_change(LC_REQ_MR_BEGIN) && !lc_proto_is_change(LC_REQ_MR_END), "MR requests are no changes");
    CHECK(!strcmp(lc_proto_type_name(LC_REQ_MR_BEGIN), "mr.begin") &&
              !strcmp(lc_proto_type_name(LC_REQ_MR_END), "mr.end"),
          "MR type names");
    /* subscribe mr.vpl */
    PARSE_OK("{\"type\":\"subscribe\",\"stream\":\"mr.vpl\"}", &r);
    CHECK(r.stream == LC_STREAM_MR_VPL && r.encoding == LC_ENC_F32, "mr.vpl default f32");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"subscribe\",\"stream\":\"mr.vpl\",\"encoding\":\"rgba16f\",\"max_rate\":30}", &r);
    CHECK(r.stream == LC_STREAM_MR_VPL && r.encoding == LC_ENC_RGBA16F && r.max_rate == 30, "mr.vpl rgba16f");
    lc_proto_request_release(&r);
    PARSE_OK("{\"type\":\"unsubscribe\",\"stream\":\"mr.vpl\"}", &r);
    CHECK(r.type == LC_REQ_UNSUBSCRIBE && r.stream == LC_STREAM_MR_VPL, "unsubscribe mr.vpl");
    lc_proto_request_release(&r);
    INVALID("{\"type\":\"subscribe\",\"stream\":\"mr.vpl\",\"encoding\":\"rgb9e5\"}", "invalid", "/encoding");
    INVALID("{\"type\":\"subscribe\",\"stream\":\"mr.vpl\",\"delta\":\"tiles\"}", "invalid", "/delta");
    CHECK(!strcmp(lc_proto_stream_name(LC_STREAM_MR_VPL), "mr.vpl") && !strcmp(lc_proto_stream_name(5), "unknown"),
          "stream names");
}

static void test_mr_builders(void) {
    lc_proto_id sid = {1, "mr-1", 0};
    cJSON *j = reparse(lc_proto_build_ok_mr(&sid, 77, 3, 4194304, 7.5, 4096, 1234));
    const cJSON *mr = cJSON_GetObjectItemCaseSensitive(j, "mr");
    CHECK(j && !strcmp(str(j, "type"), "ok") && !strcmp(str(j, "id"), "mr-1") && num(j, "revision") == 77 &&
              cJSON_GetArraySize(j) == 4,
          "ok_mr top level");
    CHECK(cJSON_IsObject(mr) && cJSON_GetArraySize(mr) == 5 && num(mr, "session") == 3 &&
              num(mr, "max_frame") == 4194304 && num(mr, "max_rate") == 7.5 && num(mr, "max_lights") == 4096 &&
              num(mr, "points") == 1234,
          "ok_mr.mr fields");
    cJSON_Delete(j);
    char *s = lc_proto_build_ok_mr(NULL, 0, 4294967295u, 18446744073709551615ULL, 0.1, 0, 0);
    CHECK(s && strstr(s, "\"session\":4294967295") && strstr(s, "\"max_frame\":18446744073709551615") &&
              strstr(s, "\"max_rate\":0.1") && !strstr(s, "\"id\""),
          "ok_mr exact integers, no id: %s", s);
    free(s);
    j = reparse(lc_proto_build_mr_ack(17, 1700000000123456ULL, 0, 812, 3.25));
    CHECK(j && !strcmp(str(j, "type"), "mr.ack") && num(j, "seq") == 17 && num(j, "capture_us") == 1700000000123456.0 &&
              !strcmp(str(j, "status"), "processed") && num(j, "lights") == 812 && num(j, "ms") == 3.25 &&
              cJSON_GetArraySize(j) == 6 && !cJSON_GetObjectItem(j, "id"),
          "mr.ack processed");
    cJSON_Delete(j);
    s = lc_proto_build_mr_ack(4294967295u, 18446744073709551615ULL, 1, 0, NAN);
    CHECK(s && strstr(s, "\"seq\":4294967295") && strstr(s, "\"capture_us\":18446744073709551615") &&
              strstr(s, "\"status\":\"replaced\"") && strstr(s, "\"ms\":0"),
          "mr.ack replaced, exact integers, NaN ms as 0: %s", s);
    free(s);
    /* welcome: always version 1.1 and the granted names */
    const char *assets[] = {"chair"};
    lc_proto_welcome w;
    memset(&w, 0, sizeof w);
    w.server = "lucentd/0.1.0";
    w.role = "controller";
    w.assets = assets;
    w.n_assets = 1;
    w.bands = 3;
    lc_proto_default_limits(&w.limits);
    for (int granted = 0; granted < 2; granted++) {
        w.capabilities = granted ? LC_CAP_MR | (1u << 7) : 0; /* an unnamed bit is not written */
        j = reparse(lc_proto_build_welcome(NULL, &w));
        const cJSON *caps = cJSON_GetObjectItemCaseSensitive(j, "capabilities");
        CHECK(j && !strcmp(str(j, "version"), "1.1") && !strcmp(str(j, "protocol"), "lucent/1"), "welcome version");
        CHECK(cJSON_IsArray(caps) && cJSON_GetArraySize(caps) == granted, "welcome capabilities size");
        if (granted && cJSON_IsArray(caps))
            CHECK(cJSON_IsString(caps->child) && !strcmp(caps->child->valuestring, "mr"), "welcome grants mr");
        cJSON_Delete(j);
    }
}

/* An mr.vpl frame: objects ids[n] with counts[n] points; record k's value c = k * 12 + c + 0.5. */
static size_t make_vpl(lc_encoding enc, const char *const *ids, const uint32_t *counts, uint32_t n, uint32_t height,
                       uint16_t flags, lc_frame_header *h) {
    static uint8_t payload[1 << 14];
    float rec[64 * LC_FRAME_MR_VPL_VALUES];
    size_t at = 0;
    for (uint32_t i = 0; i < n; i++) {
        for (uint32_t k = 0; k < counts[i] * LC_FRAME_MR_VPL_VALUES; k++) rec[k] = (float)(i * 1000 + k) + 0.5f;
        size_t b = lc_frame_mr_vpl_block(enc, ids[i], counts[i], rec, payload + at, sizeof payload - at);
        CHECK(b == lc_frame_mr_vpl_block_bytes(enc, counts[i]) && b > 0, "block %u: %zu bytes", i, b);
        at += b;
    }
    memset(h, 0, sizeof *h);
    h->version = 1;
    h->stream = LC_STREAM_MR_VPL;
    h->encoding = (uint8_t)enc;
    h->flags = flags;
    h->width = n;
    h->height = height;
    h->depth = 1;
    h->payload_length = (uint32_t)at;
    return lc_frame_write(h, NULL, payload, frame_buf, sizeof frame_buf);
}

/* Re-frames the payload now in frame_buf after a header change (new CRC). */
static size_t rewrite_vpl(const lc_frame_header *h) {
    static uint8_t copy[1 << 14];
    memcpy(copy, frame_buf + 64, sizeof copy);
    return lc_frame_write(h, NULL, copy, frame_buf, sizeof frame_buf);
}

static void test_mr_vpl_frames(void) {
    const char *ids[] = {"lamp", "chair-1", "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa"};
    const uint32_t counts[] = {2, 0, 3};
    lc_frame_header h, out;
    const uint8_t *tt, *pl;
    lc_proto_error e;
    for (int pass = 0; pass < 2; pass++) {
        lc_encoding enc = pass ? LC_ENC_RGBA16F : LC_ENC_F32;
        size_t vb = pass ? 2 : 4;
        size_t n = make_vpl(enc, ids, counts, 3, 5, LC_FRAME_KEYFRAME, &h);
        CHECK(n == 64 + 3 * 72 + 5 * 12 * vb, "frame size %zu", n);
        int rc = lc_frame_parse(frame_buf, n, &out, &tt, &pl, &e);
        CHECK(rc == 0 && out.stream == LC_STREAM_MR_VPL && out.width == 3 && out.height == 5 &&
                  out.payload_length == 3 * 72 + 5 * 12 * vb,
              "%s frame parses: %s", lc_proto_encoding_name(enc), e.message);
        if (rc != 0) continue;
        /* bytes on the wire, then the walker */
        CHECK(!memcmp(pl, "lamp", 5) && pl[64] == 2 && pl[65] == 0 && !memcmp(pl + 68, "\0\0\0\0", 4),
              "first block header bytes");
        size_t at = 0;
        char id[LC_PROTO_ID_MAX + 1];
        uint32_t p, total = 0;
        const uint8_t *recs;
        for (uint32_t i = 0; i < 3; i++) {
            CHECK(lc_frame_mr_vpl_next(&out, pl, &at, id, &p, &recs) == 0, "block %u", i);
            CHECK(!strcmp(id, ids[i]) && p == counts[i], "block %u: id %s P %u", i, id, p);
            for (uint32_t k = 0; k < p * LC_FRAME_MR_VPL_VALUES; k++) {
                float v, want = (float)(i * 1000 + k) + 0.5f;
                if (vb == 2) {
                    v = lc_half_to_float((uint16_t)(recs[2 * k] | recs[2 * k + 1] << 8));
                    want = lc_half_to_float(lc_half_from_float(want));
                } else {
                    uint32_t bits = (uint32_t)recs[4 * k] | (uint32_t)recs[4 * k + 1] << 8 |
                        (uint32_t)recs[4 * k + 2] << 16 | (uint32_t)recs[4 * k + 3] << 24;
                    memcpy(&v, &bits, 4);
                }
                if (v != want) {
                    CHECK(0, "block %u value %u: %g, expected %g", i, k, v, want);
                    break;
                }
            }
            total += p;
        }
        CHECK(total == 5 && at == out.payload_length && lc_frame_mr_vpl_next(&out, pl, &at, id, &p, &recs) == -1,
              "walker ends at the payload's end");
        /* bad frames (CRC valid) */
        n = make_vpl(enc, ids, counts, 3, 4, LC_FRAME_KEYFRAME, &h);
        CHECK(frame_bad(n, "sum to the height"), "P sum 5 != height 4");
        n = make_vpl(enc, ids, counts, 3, 6, LC_FRAME_KEYFRAME, &h);
        CHECK(frame_bad(n, "sum to the height"), "P sum 5 != height 6");
        n = make_vpl(enc, ids, counts, 3, 5, LC_FRAME_DELTA, &h);
        CHECK(frame_bad(n, "keyframes"), "delta flag");
        n = make_vpl(enc, ids, counts, 3, 5, LC_FRAME_KEYFRAME, &h);
        h.payload_length -= (uint32_t)vb; /* the last record cut short */
        n = rewrite_vpl(&h);
        CHECK(frame_bad(n, "point counts"), "payload one value short");
        n = make_vpl(enc, ids, counts, 3, 5, LC_FRAME_KEYFRAME, &h);
        h.width = 4; /* a fourth block announced, none there */
        n = rewrite_vpl(&h);
        CHECK(frame_bad(n, "objects"), "width over the blocks");
        n = make_vpl(enc, ids, counts, 3, 5, LC_FRAME_KEYFRAME, &h);
        h.width = 2; /* bytes left after the blocks */
        h.height = 2;
        n = rewrite_vpl(&h);
        CHECK(frame_bad(n, "payload length"), "trailing bytes");
        n = make_vpl(enc, ids, counts, 3, 5, LC_FRAME_KEYFRAME, &h);
        h.tile_size = 16;
        n = rewrite_vpl(&h);
        CHECK(frame_bad(n, "tile size"), "tile size");
        n = make_vpl(enc, ids, counts, 3, 5, LC_FRAME_KEYFRAME, &h);
        frame_buf[64 + 68] = 1; /* block 0's reserved word */
        uint32_t crc = lc_crc32(0, frame_buf, 60);
        crc = lc_crc32(crc, frame_buf + 64, n - 64);
        memcpy(frame_buf + 60, &crc, 4);
        CHECK(frame_bad(n, "reserved"), "reserved word");
        n = make_vpl(enc, ids, counts, 3, 5, LC_FRAME_KEYFRAME, &h);
        size_t b2 = 64 + 2 * 72 + 2 * 12 * vb + 64; /* block 2's P = 0xFF0000FF: far past the payload */
        frame_buf[b2] = 0xFF;
        frame_buf[b2 + 3] = 0xFF;
        crc = lc_crc32(0, frame_buf, 60);
        crc = lc_crc32(crc, frame_buf + 64, n - 64);
        memcpy(frame_buf + 60, &crc, 4);
        CHECK(frame_bad(n, "point counts"), "huge P");
    }
    lc_frame_header hh;
    size_t n = make_vpl(LC_ENC_F32, ids, counts, 0, 0, LC_FRAME_KEYFRAME, &hh);
    CHECK(frame_ok(n, NULL), "no objects: an empty mr.vpl frame");
    hh.encoding = LC_ENC_RGB9E5;
    n = lc_frame_write(&hh, NULL, NULL, frame_buf, sizeof frame_buf);
    CHECK(frame_bad(n, "encoding"), "rgb9e5 mr.vpl");
    uint8_t small[71];
    float rec[12] = {0};
    CHECK(lc_frame_mr_vpl_block(LC_ENC_F32, "a", 0, rec, small, sizeof small) == 0 &&
              lc_frame_mr_vpl_block(LC_ENC_RGB9E5, "a", 0, rec, frame_buf, sizeof frame_buf) == 0 &&
              lc_frame_mr_vpl_block_bytes(LC_ENC_RGB9E5, 1) == 0 &&
              lc_frame_mr_vpl_block_bytes(LC_ENC_F32, 2) == 72 + 96,
          "block writer refuses what does not fit or has no encoding");
}

int main(void) {
    test_valid();
    test_limits();
    test_invalid();
    test_builders();
    test_op_roundtrip();
    test_state_roundtrip();
    test_frames();
    test_residual();
    test_rgb9e5();
    test_utf8_valid();
    test_utf8_cut();
    test_utf8_sanitize();
    test_utf8_replies();
    test_utf8_builders();
    test_nul_escape();
    test_dnrt_fields();
    test_solver_fields();
    test_clutter_fields();
    test_mr_hello();
    test_mr_begin();
    test_mr_builders();
    test_mr_vpl_frames();
    CHECK_DONE();
}
