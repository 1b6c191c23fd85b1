/* dump_samples: sample lucent/1 messages for the schema check (check_schemas.py).
 * Prints one line per message, "valid\t<json>" or "invalid\t<json>": every server message
 * as the builders write it, and client messages that the C parser accepts (valid) or
 * refuses (invalid). Exits 1 when the C parser disagrees with a sample's label, so the
 * schemas and the parser are checked against the same examples. */
#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lucent_proto.h"

static int failures = 0;

static void emit(const char *label, char *json) {
    if (!json) {
        fprintf(stderr, "dump_samples: a builder returned NULL\n");
        failures++;
        return;
    }
    printf("%s\t%s\n", label, json);
    free(json);
}

static void client(int valid, const char *json) {
    lc_proto_request r;
    lc_proto_error e;
    int rc = lc_proto_parse_request(json, strlen(json), NULL, &r, &e);
    lc_proto_request_release(&r);
    if ((rc == 0) != valid) {
        fprintf(stderr, "dump_samples: C parser %s %s (%s %s %s)\n", rc == 0 ? "accepts" : "refuses", json, e.code,
                e.pointer, e.message);
        failures++;
    }
    printf("%s\t%s\n", valid ? "valid" : "invalid", json);
}

#define L_POINT "{\"id\":\"key\",\"type\":\"point\",\"position\":[0,2.5,0],\"color\":[1,0.9,0.8],\"intensity\":120}"

/* --errors: the error catalogue as JSON lines {"code", "meaning", "connection"} (for
 * check_error_catalogue.py). */
static int dump_errors(void) {
    for (int i = 0; i < LC_ERR_COUNT; i++) {
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "code", lc_proto_errcode_name((lc_proto_errcode)i));
        cJSON_AddStringToObject(o, "meaning", lc_proto_errcode_meaning((lc_proto_errcode)i));
        cJSON_AddStringToObject(o, "connection", lc_proto_errcode_connection((lc_proto_errcode)i));
        char *t = cJSON_PrintUnformatted(o);
        printf("%s\n", t);
        cJSON_free(t);
        cJSON_Delete(o);
    }
    return 0;
}

int main(int argc, char **argv) {
    if (argc > 1 && !strcmp(argv[1], "--errors")) return dump_errors();
    /* --- client -> server, valid --- */
    client(
        1,
        "{\"type\":\"hello\",\"id\":1,\"client\":\"my-viewer/2.0\",\"token\":\"secret\",\"encodings\":[\"rgb9e5\"]}");
    client(1, "{\"type\":\"subscribe\",\"id\":\"s\",\"stream\":\"lightmap\",\"encoding\":\"rgb9e5\",\"max_rate\":30}");
    client(1, "{\"type\":\"subscribe\",\"stream\":\"shgrid\",\"encoding\":\"rgba16f\"}");
    client(1, "{\"type\":\"unsubscribe\",\"stream\":\"objects\"}");
    client(1, "{\"type\":\"light.set\",\"id\":2,\"light\":" L_POINT "}");
    client(
        1,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"spot\",\"type\":\"spot\",\"position\":[0,3,0],\"direction\":[0,-1,0],"
        "\"innerConeAngle\":0.2,\"outerConeAngle\":0.6,\"range\":10}}");
    client(
        1,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"sun\",\"type\":\"directional\",\"direction\":[0.3,-1,0.2],\"intensity\":1e5}}");
    client(
        1,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"panel\",\"type\":\"area\",\"position\":[0,2,0],\"direction\":[0,-1,0],"
        "\"shape\":\"quad\",\"size\":[1,0.5],\"tangent\":[1,0,0]}}");
    client(
        1,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"disc\",\"type\":\"area\",\"position\":[0,2,0],\"direction\":[0,-1,0],"
        "\"shape\":\"disc\",\"size\":[0.25]}}");
    client(1, "{\"type\":\"light.remove\",\"light_id\":\"key\"}");
    client(1,
           "{\"type\":\"object.set\",\"object\":{\"id\":\"chair-1\",\"asset\":\"chair\",\"translation\":[1,0,2],"
           "\"rotation\":[0,0.7071068,0,0.7071068],\"scale\":[1,1,-1],\"visible\":true}}");
    client(1, "{\"type\":\"object.set\",\"object\":{\"id\":\"chair-2\",\"asset\":\"chair\",\"dnrt\":false}}");
    client(1, "{\"type\":\"object.remove\",\"object_id\":\"chair-1\"}");
    client(1, "{\"type\":\"material.set\",\"material\":\"light\",\"emission\":[17,12,4]}");
    client(
        1,
        "{\"type\":\"environment.set\",\"environment\":{\"type\":\"constant\",\"color\":[0.5,0.6,0.7],\"intensity\":2}}");
    client(
        1,
        "{\"type\":\"environment.set\",\"environment\":{\"type\":\"sh\",\"sh\":[1,1,1,0,0,0,0.5,0.5,0.5,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0]}}");
    client(
        1,
        "{\"type\":\"settings.set\",\"settings\":{\"bounces\":2,\"bands\":3,\"progressive\":true,\"chroma_compression\":true,\"chroma_bands\":2}}");
    client(1, "{\"type\":\"settings.set\",\"settings\":{\"dnrt\":false,\"dnrt_blockers\":true}}");
    client(1, "{\"type\":\"settings.set\",\"settings\":{\"solver\":\"probes\",\"bounces\":1}}");
    client(
        1,
        "{\"type\":\"batch\",\"id\":\"b1\",\"ops\":[{\"type\":\"light.set\",\"light\":" L_POINT "},"
        "{\"type\":\"object.remove\",\"object_id\":\"chair-1\"},{\"type\":\"settings.set\",\"settings\":{\"bounces\":1}}]}");
    client(1, "{\"type\":\"state.get\",\"id\":3}");
    client(1, "{\"type\":\"snapshot\"}");
    client(1, "{\"type\":\"ping\",\"t\":12345.678}");
    /* lucent/1.1 (§8) */
    client(1, "{\"type\":\"hello\",\"client\":\"ar/1\",\"capabilities\":[\"mr\",\"future\"]}");
    client(1, "{\"type\":\"subscribe\",\"stream\":\"mr.vpl\",\"encoding\":\"rgba16f\"}");
    client(1,
           "{\"type\":\"mr.begin\",\"id\":4,\"session\":{\"objects\":[\"chair-1\"],\"width\":256,\"height\":192,"
           "\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\"}}");
    client(1,
           "{\"type\":\"mr.begin\",\"session\":{\"objects\":[\"a\",\"b\"],\"width\":1024,\"height\":1024,"
           "\"depth\":\"f16m\",\"color\":\"rgb16f_linear\",\"max_rate\":60,\"glossy\":false,\"specular_exponent\":1e4,"
           "\"min_confidence\":1,\"smoothing\":0.99,\"light\":\"add\"}}");
    client(1, "{\"type\":\"mr.end\",\"id\":\"e\"}");

    /* --- client -> server, invalid (schema and parser must both refuse) --- */
    client(0, "{\"type\":\"hello\",\"token\":\"x\"}");
    client(0, "{\"type\":\"subscribe\",\"stream\":\"video\"}");
    client(0, "{\"type\":\"subscribe\",\"stream\":\"shgrid\",\"encoding\":\"rgb9e5\"}");
    client(0, "{\"type\":\"subscribe\",\"stream\":\"lightmap\",\"max_rate\":500}");
    client(0, "{\"type\":\"light.set\",\"light\":{\"type\":\"point\",\"position\":[0,0,0]}}");
    client(
        0,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\",\"position\":[0,0,0],\"intensity\":-1}}");
    client(0, "{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"point\"}}");
    client(
        0,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"spot\",\"position\":[0,0,0],\"direction\":[0,0,0]}}");
    client(
        0,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\",\"position\":[0,0,0],\"direction\":[0,-1,0]}}");
    client(
        0,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"a\",\"type\":\"area\",\"position\":[0,0,0],\"direction\":[0,-1,0],\"shape\":\"disc\",\"size\":[1,1]}}");
    client(
        0,
        "{\"type\":\"light.set\",\"light\":{\"id\":\"aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\",\"type\":\"point\",\"position\":[0,0,0]}}");
    client(0, "{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"scale\":[1,0,1]}}");
    client(0, "{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"rotation\":[0,0,0,0]}}");
    client(0, "{\"type\":\"material.set\",\"material\":\"m\",\"emission\":[1,1]}");
    client(0, "{\"type\":\"environment.set\",\"environment\":{\"type\":\"sh\"}}");
    client(0, "{\"type\":\"settings.set\",\"settings\":{\"bounces\":17}}");
    client(0, "{\"type\":\"settings.set\",\"settings\":{\"bands\":2.5}}");
    client(0, "{\"type\":\"settings.set\",\"settings\":{\"dnrt\":\"yes\"}}");
    client(0, "{\"type\":\"settings.set\",\"settings\":{\"dnrt_blockers\":0}}");
    client(0, "{\"type\":\"settings.set\",\"settings\":{\"solver\":\"radiosity\"}}");
    client(0, "{\"type\":\"settings.set\",\"settings\":{\"solver\":1}}");
    client(0, "{\"type\":\"object.set\",\"object\":{\"id\":\"o\",\"asset\":\"chair\",\"dnrt\":5}}");
    client(0, "{\"type\":\"batch\",\"ops\":[]}");
    client(0, "{\"type\":\"batch\",\"ops\":[{\"type\":\"batch\",\"ops\":[{\"type\":\"snapshot\"}]}]}");
    client(0, "{\"type\":\"batch\",\"ops\":[{\"type\":\"ping\",\"t\":1}]}");
    client(0, "{\"type\":\"ping\"}");
    client(0, "{\"type\":\"ping\",\"t\":\"NaN\"}");
    client(0, "{\"type\":\"snapshot\",\"id\":9007199254740992}");
    client(0, "{\"type\":\"snapshot\",\"id\":\"\"}");
    client(0, "{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"mr\",\"\"]}");
    client(
        0,
        "{\"type\":\"hello\",\"client\":\"ar\",\"capabilities\":[\"1\",\"2\",\"3\",\"4\",\"5\",\"6\",\"7\",\"8\",\"9\"]}");
    client(0, "{\"type\":\"subscribe\",\"stream\":\"mr.vpl\",\"encoding\":\"rgb9e5\"}");
    client(0, "{\"type\":\"mr.begin\"}");
    client(0,
           "{\"type\":\"mr.begin\",\"session\":{\"objects\":[\"a\",\"a\"],\"width\":8,\"height\":8,"
           "\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\"}}");
    client(0,
           "{\"type\":\"mr.begin\",\"session\":{\"objects\":[\"a\"],\"width\":7,\"height\":8,"
           "\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\"}}");
    client(0,
           "{\"type\":\"mr.begin\",\"session\":{\"objects\":[\"a\"],\"width\":8,\"height\":8,"
           "\"depth\":\"u8\",\"color\":\"rgb8_srgb\"}}");
    client(0,
           "{\"type\":\"mr.begin\",\"session\":{\"objects\":[\"a\"],\"width\":8,\"height\":8,"
           "\"depth\":\"u16mm\",\"color\":\"rgb8_srgb\",\"smoothing\":0.995}}");

    /* --- server -> client, as built --- */
    lc_proto_id nid = {2, "", 1}, sid = {1, "req-7", 0};
    const char *assets[] = {"chair"}, *mats[] = {"white", "light"};
    lc_proto_welcome w = {0};
    w.server = "lucentd/0.1.0";
    w.role = "controller";
    w.revision = 42;
    w.lightmap_width = w.lightmap_height = 128;
    w.tile = 32;
    w.grid_cell = 0.5f;
    w.grid_dims[0] = 24, w.grid_dims[1] = 8, w.grid_dims[2] = 12;
    w.bands = 3;
    w.assets = assets;
    w.n_assets = 1;
    w.materials = mats;
    w.n_materials = 2;
    lc_proto_default_limits(&w.limits);
    w.max_lights = w.max_objects = 4096;
    w.rate = 100;
    emit("valid", lc_proto_build_welcome(&nid, &w));
    /* with asset_info: one asset with a transfer grid, one without (an older bake) */
    const char *assets2[] = {"chair", "lamp"};
    lc_proto_asset_info info[2] = {{1, 32, 4, 524288, 1.8f}, {0, 0, 0, 0, 0}};
    w.assets = assets2;
    w.n_assets = 2;
    w.asset_info = info;
    emit("valid", lc_proto_build_welcome(NULL, &w));
    /* with scene.solvers (a --solver both bake) */
    w.solvers = (1u << LC_PROTO_SOLVER_PIC) | (1u << LC_PROTO_SOLVER_PROBES);
    emit("valid", lc_proto_build_welcome(NULL, &w));
    w.solvers = 0;
    emit("valid", lc_proto_build_ok(&sid, 43));
    emit("valid", lc_proto_build_ok(NULL, 0));
    lc_proto_error e = {"out_of_range", "/ops/3/light/intensity", "intensity must be in [0, 1e9]"};
    emit("valid", lc_proto_build_error(&nid, &e));
    lc_proto_error e2 = {"bad_json", "", "not valid JSON"};
    emit("valid", lc_proto_build_error(NULL, &e2));
    /* §1.2: sent before the 1007 close, never with an id */
    lc_proto_error e3 = {"bad_utf8", "", "text frame is not valid UTF-8"};
    emit("valid", lc_proto_build_error(NULL, &e3));
    emit("valid", lc_proto_build_pong(&nid, 12345.678, 1700000000000000ULL));
    /* lucent/1.1 (§8): a welcome granting mr, ok for mr.begin, both mr.ack kinds */
    w.capabilities = LC_CAP_MR;
    emit("valid", lc_proto_build_welcome(&nid, &w));
    w.capabilities = 0;
    emit("valid", lc_proto_build_ok_mr(&nid, 43, 1, 4194304, 10, 16384, 2048));
    emit("valid", lc_proto_build_mr_ack(1, 1700000000123456ULL, 0, 49152, 4.75));
    emit("valid", lc_proto_build_mr_ack(2, 1700000000223456ULL, 1, 0, 0));

    /* state and changed from parsed requests, so every light kind appears */
    const char *sets[] = {
        "{\"type\":\"light.set\",\"light\":" L_POINT "}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"spot\",\"type\":\"spot\",\"position\":[0,3,0],\"direction\":[0,-1,0],\"innerConeAngle\":0.2}}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"sun\",\"type\":\"directional\",\"direction\":[0.3,-1,0.2]}}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"disc\",\"type\":\"area\",\"shape\":\"disc\",\"position\":[0,2,0],\"direction\":[0,-1,0],\"size\":[0.25]}}",
        "{\"type\":\"light.set\",\"light\":{\"id\":\"panel\",\"type\":\"area\",\"position\":[0,2,0],\"direction\":[0,-1,0],\"size\":[1,0.5],\"tangent\":[0,0,1]}}",
        "{\"type\":\"object.set\",\"object\":{\"id\":\"chair-1\",\"asset\":\"chair\",\"rotation\":[0,1,0,1]}}",
        "{\"type\":\"environment.set\",\"environment\":{\"type\":\"sh\",\"sh\":[1,1,1,0,0,0,0.5,0.5,0.5,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0]}}",
    };
    lc_proto_light lights[5];
    lc_proto_object obj;
    lc_proto_op ops[7];
    memset(&obj, 0, sizeof obj);
    memset(ops, 0, sizeof ops);
    for (int i = 0; i < 7; i++) {
        lc_proto_request r;
        if (lc_proto_parse_request(sets[i], strlen(sets[i]), NULL, &r, &e) == 0 && r.n_ops == 1) {
            ops[i] = r.ops[0];
            if (i < 5) lights[i] = r.ops[0].light;
        } else {
            fprintf(stderr, "dump_samples: %s refused\n", sets[i]);
            failures++;
        }
        lc_proto_request_release(&r);
    }
    obj = ops[5].object;
    lc_proto_material_state ms[2] = {{"white", {0, 0, 0}}, {"light", {17, 12, 4}}};
    lc_proto_state st = {0};
    st.revision = 44;
    st.lights = lights;
    st.n_lights = 5;
    st.objects = &obj;
    st.n_objects = 1;
    st.materials = ms;
    st.n_materials = 2;
    st.environment = ops[6].environment;
    st.settings.present = LC_SET_ALL;
    st.settings.dnrt = 1;
    st.settings.bounces = 1;
    st.settings.bands = 3;
    st.settings.progressive = 1;
    st.settings.chroma_bands = 2;
    emit("valid", lc_proto_build_state(&nid, &st));
    ops[1].type = LC_REQ_LIGHT_REMOVE;
    strcpy(ops[1].target, "spot");
    ops[2].type = LC_REQ_SETTINGS_SET;
    emit("valid", lc_proto_build_changed(45, "my-viewer/2.0", ops, 7));

    /* --- server -> client, invalid --- */
    puts("invalid\t{\"type\":\"ok\",\"id\":1}");
    puts("invalid\t{\"type\":\"ok\",\"revision\":-1}");
    puts("invalid\t{\"type\":\"error\",\"code\":\"oops\",\"message\":\"\",\"pointer\":\"\"}");
    puts("invalid\t{\"type\":\"error\",\"code\":\"invalid\",\"message\":\"\",\"pointer\":\"light\"}");
    puts("invalid\t{\"type\":\"pong\",\"t\":1}");
    puts("invalid\t{\"type\":\"mr.ack\",\"seq\":1,\"capture_us\":0,\"status\":\"dropped\",\"lights\":0,\"ms\":1}");
    puts("invalid\t{\"type\":\"mr.ack\",\"seq\":0,\"capture_us\":0,\"status\":\"processed\",\"lights\":0,\"ms\":1}");
    puts("invalid\t{\"type\":\"ok\",\"revision\":1,\"mr\":{\"session\":1,\"max_frame\":1,\"max_rate\":10}}");
    puts("invalid\t{\"type\":\"ok\",\"revision\":1,\"mr\":{\"session\":1,\"max_frame\":1,\"max_rate\":0,"
         "\"max_lights\":1,\"points\":1}}");
    puts(
        "invalid\t{\"type\":\"welcome\",\"server\":\"s\",\"protocol\":\"lucent/1\",\"version\":\"2.0\",\"role\":\"viewer\","
        "\"revision\":0,\"scene\":{\"lightmap\":{\"width\":1,\"height\":1,\"tile\":1,\"quantity\":\"irradiance\"},"
        "\"grid\":{\"origin\":[0,0,0],\"cell\":1,\"dims\":[1,1,1],\"quantity\":\"irradiance_sh\",\"coefficients\":9},"
        "\"bands\":3,\"assets\":[],\"materials\":[]},"
        "\"limits\":{\"max_message\":1,\"max_lights\":1,\"max_objects\":1,\"max_batch\":1,\"rate\":1}}");
    puts("invalid\t{\"type\":\"changed\",\"revision\":1,\"by\":\"x\",\"ops\":[\"batch\"],\"ids\":[\"a\"]}");
    puts(
        "invalid\t{\"type\":\"welcome\",\"server\":\"s\",\"protocol\":\"lucent/2\",\"role\":\"controller\",\"revision\":0,\"scene\":{},\"limits\":{}}");
    puts(
        "invalid\t{\"type\":\"welcome\",\"server\":\"s\",\"protocol\":\"lucent/1\",\"role\":\"viewer\",\"revision\":0,"
        "\"scene\":{\"lightmap\":{\"width\":1,\"height\":1,\"tile\":1,\"quantity\":\"irradiance\"},\"grid\":{\"origin\":[0,0,0],"
        "\"cell\":1,\"dims\":[1,1,1],\"quantity\":\"irradiance_sh\",\"coefficients\":9},\"bands\":3,\"assets\":[\"a\"],"
        "\"materials\":[],\"asset_info\":{\"a\":{\"transfer\":{\"dims\":32,\"coefficients\":5,\"bytes\":1,\"outer_radius\":1}}}},"
        "\"limits\":{\"max_message\":1,\"max_lights\":1,\"max_objects\":1,\"max_batch\":1,\"rate\":1}}");
    puts(
        "invalid\t{\"type\":\"state\",\"revision\":1,\"lights\":[{\"id\":\"a\",\"type\":\"point\"}],\"objects\":[],\"materials\":[],"
        "\"environment\":{\"type\":\"none\"},\"settings\":{}}");
    return failures ? 1 : 0;
}
