/* lucentctl scene commands: ping, state, send, light, object, material, env, settings.
 * Flags map onto the lucent/1 fields of PROTOCOL.md §4; the server checks the ranges (its
 * error names the field), lucentctl checks only that each value is well formed. */
#include "ctl.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#define CTL_MAX_POS 4
#define CTL_PING_MAX 100000
#define CTL_SEND_LINE_MAX (1u << 20)

static double ctl_now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec / 1e6;
}

/* Connects, sends req (consumed) and prints the outcome: the reply with --json, else
 * "ok: <what> (revision N)". Returns an exit code. */
static int ctl_change(cJSON *req, const char *what) {
    char *text = cJSON_PrintUnformatted(req);
    char *reply = NULL;
    lc_client *c = NULL;
    int rc = CTL_EXIT_OK;
    cJSON_Delete(req);
    if (!text) {
        fprintf(stderr, "lucentctl: out of memory\n");
        return CTL_EXIT_CONN;
    }
    c = ctl_connect(NULL, &rc);
    if (!c) goto done;
    rc = ctl_request(c, text, &reply);
    if (rc != CTL_EXIT_OK) goto done;
    if (ctl_json) {
        printf("%s\n", reply);
    } else {
        long long rev = ctl_reply_revision(reply);
        if (rev >= 0) printf("ok: %s (revision %lld)\n", what, rev);
        else printf("ok: %s\n", what);
    }
done:
    free(reply);
    free(text);
    lc_client_close(c);
    return rc;
}

/* --- ping -------------------------------------------------------------------------------- */

static void ctl_usage_ping(FILE *f) {
    fprintf(f,
            "usage: lucentctl ping [--count N] [--interval SECONDS]\n"
            "\n"
            "Sends ping and prints the round trip in milliseconds (with --json: each pong, plus\n"
            "\"rtt_ms\"). With --count N > 1, a min/avg/max summary follows.\n"
            "\n"
            "  --count N            pings to send (default 1, at most 100000)\n"
            "  --interval SECONDS   pause between pings (default 0.2)\n");
}

int ctl_cmd_ping(int argc, char **argv) {
    static const ctl_flag flags[] = {
        {"--count", "count", CTL_FLAG_INT, 0, 0, NULL, "N", "pings to send"},
        {"--interval", "interval", CTL_FLAG_NUM, 0, 0, NULL, "SECONDS", "pause between pings"},
        {NULL, NULL, 0, 0, 0, NULL, NULL, NULL},
    };
    if (ctl_wants_help(argc, argv)) {
        ctl_usage_ping(stdout);
        return CTL_EXIT_OK;
    }
    cJSON *opt = cJSON_CreateObject();
    char *pos[CTL_MAX_POS];
    int npos = 0, rc;
    lc_client *c = NULL;
    if (!opt) return CTL_EXIT_CONN;
    rc = ctl_parse_flags("ping", flags, argc, argv, 1, opt, pos, 0, &npos);
    if (rc != 0) goto done;
    const cJSON *jc = cJSON_GetObjectItemCaseSensitive(opt, "count");
    const cJSON *ji = cJSON_GetObjectItemCaseSensitive(opt, "interval");
    double count = jc ? jc->valuedouble : 1, interval = ji ? ji->valuedouble : 0.2;
    if (count < 1 || count > CTL_PING_MAX) {
        rc = ctl_usage_error("ping: --count %.0f: expected 1..%d", count, CTL_PING_MAX);
        goto done;
    }
    if (interval < 0 || interval > 3600) {
        rc = ctl_usage_error("ping: --interval %g: expected 0..3600 seconds", interval);
        goto done;
    }
    c = ctl_connect(NULL, &rc);
    if (!c) goto done;
    double lo = 1e300, hi = 0, sum = 0;
    int n = (int)count;
    for (int i = 0; i < n; i++) {
        char req[96], *reply = NULL;
        if (i > 0 && interval > 0) {
            struct timespec pause = {(time_t)interval, (long)((interval - (double)(time_t)interval) * 1e9)};
            nanosleep(&pause, NULL);
        }
        snprintf(req, sizeof req, "{\"type\":\"ping\",\"t\":%d}", i);
        double t0 = ctl_now_ms();
        rc = ctl_request(c, req, &reply);
        double ms = ctl_now_ms() - t0;
        if (rc != CTL_EXIT_OK) goto done;
        if (ctl_json) {
            cJSON *o = cJSON_Parse(reply);
            if (o) cJSON_AddNumberToObject(o, "rtt_ms", ms);
            char *p = o ? cJSON_PrintUnformatted(o) : NULL;
            printf("%s\n", p ? p : reply);
            free(p);
            cJSON_Delete(o);
        } else {
            printf("pong from %s: %.3f ms\n", ctl_url, ms);
        }
        fflush(stdout);
        free(reply);
        lo = ms < lo ? ms : lo;
        hi = ms > hi ? ms : hi;
        sum += ms;
    }
    if (n > 1 && !ctl_json) printf("%d pings: min/avg/max = %.3f/%.3f/%.3f ms\n", n, lo, sum / n, hi);
done:
    lc_client_close(c);
    cJSON_Delete(opt);
    return rc;
}

/* --- state, send ------------------------------------------------------------------------- */

int ctl_cmd_state(int argc, char **argv) {
    if (ctl_wants_help(argc, argv)) {
        printf("usage: lucentctl state [--json]\n"
               "\n"
               "Prints the scene state (state.get: revision, lights, objects, materials,\n"
               "environment, settings) as indented JSON, or compact JSON with --json.\n");
        return CTL_EXIT_OK;
    }
    if (argc > 1) return ctl_usage_error("state: unexpected argument '%s'", argv[1]);
    int rc = CTL_EXIT_OK;
    char *reply = NULL;
    lc_client *c = ctl_connect(NULL, &rc);
    if (!c) return rc;
    rc = ctl_request(c, "{\"type\":\"state.get\"}", &reply);
    if (rc == CTL_EXIT_OK) ctl_print_json(reply, 0);
    free(reply);
    lc_client_close(c);
    return rc;
}

/* Sends one raw message and prints its reply; returns an exit code. */
static int ctl_send_one(lc_client *c, const char *text) {
    char *reply = NULL;
    int rc = ctl_request(c, text, &reply);
    if (rc == CTL_EXIT_OK) ctl_print_json(reply, 0);
    free(reply);
    fflush(stdout);
    return rc;
}

int ctl_cmd_send(int argc, char **argv) {
    if (argc < 2) return ctl_usage_error("send: expected JSON messages or '-' (see 'lucentctl send --help')");
    if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
        printf("usage: lucentctl send JSON...   |   lucentctl send - < messages.jsonl\n"
               "\n"
               "Sends raw lucent/1 messages, one per argument, or one per line of stdin with '-'\n"
               "(blank lines skipped), and prints each reply (indented; compact with --json).\n"
               "A message without \"id\" gets one. Exit status: the worst of the replies.\n");
        return CTL_EXIT_OK;
    }
    int rc = CTL_EXIT_OK, worst = CTL_EXIT_OK;
    lc_client *c = ctl_connect(NULL, &rc);
    if (!c) return rc;
    for (int i = 1; i < argc && rc != CTL_EXIT_CONN; i++) {
        if (strcmp(argv[i], "-") != 0) {
            rc = ctl_send_one(c, argv[i]);
            if (rc > worst) worst = rc;
            continue;
        }
        char *line = NULL;
        size_t cap = 0;
        ssize_t n;
        while ((n = getline(&line, &cap, stdin)) >= 0) {
            while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r')) line[--n] = 0;
            if (n == 0) continue;
            if ((size_t)n > CTL_SEND_LINE_MAX) { /* no server takes it; do not ship megabytes */
                fprintf(stderr, "lucentctl: send: a line of %zd bytes is over %u; skipped\n", n, CTL_SEND_LINE_MAX);
                rc = CTL_EXIT_USAGE;
            } else {
                rc = ctl_send_one(c, line);
            }
            if (rc > worst) worst = rc;
            if (rc == CTL_EXIT_CONN) break;
        }
        free(line);
    }
    lc_client_close(c);
    return worst;
}

/* --- light, object ----------------------------------------------------------------------- */

static const ctl_flag ctl_light_flags[] = {
    {"--type", "type", CTL_FLAG_CHOICE, 0, 0, "point|spot|directional|area", "point|spot|directional|area", "required"},
    {"--position", "position", CTL_FLAG_LIST, 1ul << 3, 0, NULL, "x,y,z", "metres (point, spot, area: required)"},
    {"--direction", "direction", CTL_FLAG_LIST, 1ul << 3, 0, NULL, "x,y,z",
     "the way light travels (spot, directional, area: required)"},
    {"--color", "color", CTL_FLAG_LIST, 1ul << 3, 0, NULL, "r,g,b", "linear RGB, each 0..1e6 (default 1,1,1)"},
    {"--intensity", "intensity", CTL_FLAG_NUM, 0, 0, NULL, "N",
     "0..1e9: candela (point, spot), lux (directional), nits (area); default 1"},
    {"--range", "range", CTL_FLAG_NUM, 0, 0, NULL, "R", "metres, 0..1e6 (0 = infinite, the default)"},
    {"--inner-cone", "innerConeAngle", CTL_FLAG_NUM, 0, 0, NULL, "RAD", "spot: 0..pi/2 (default 0)"},
    {"--outer-cone", "outerConeAngle", CTL_FLAG_NUM, 0, 0, NULL, "RAD", "spot: inner..pi/2 (default pi/4)"},
    {"--shape", "shape", CTL_FLAG_CHOICE, 0, 0, "quad|disc", "quad|disc", "area: default quad"},
    {"--size", "size", CTL_FLAG_LIST, (1ul << 1) | (1ul << 2), 0, NULL, "w[,h]",
     "area: quad w,h or disc radius, metres, each (0, 1e4]"},
    {"--tangent", "tangent", CTL_FLAG_LIST, 1ul << 3, 0, NULL, "x,y,z",
     "area quad: the width direction (default: any perpendicular)"},
    {NULL, NULL, 0, 0, 0, NULL, NULL, NULL},
};

static const ctl_flag ctl_object_flags[] = {
    {"--asset", "asset", CTL_FLAG_STRING, 0, 0, NULL, "NAME", "required: an asset of the scene (welcome scene.assets)"},
    {"--position", "translation", CTL_FLAG_LIST, 1ul << 3, 0, NULL, "x,y,z", "translation in metres (default 0,0,0)"},
    {"--rotation", "rotation", CTL_FLAG_LIST, 1ul << 4, 0, NULL, "x,y,z,w",
     "unit quaternion, normalised by the server (default 0,0,0,1)"},
    {"--scale", "scale", CTL_FLAG_LIST, (1ul << 1) | (1ul << 3), 1, NULL, "s|x,y,z",
     "uniform or per axis, each |s| in [1e-6, 1e4] (default 1)"},
    {"--visible", "visible", CTL_FLAG_BOOL, 0, 0, NULL, "true|false", "default true"},
    {"--dnrt", "dnrt", CTL_FLAG_BOOL, 0, 0, NULL, "true|false",
     "shadow and colour the indirect light if its asset has transfer data (default true)"},
    {"--mode", "mode", CTL_FLAG_CHOICE, 0, 0, "dynamic|clutter|auto", "dynamic|clutter|auto",
     "clutter: the server builds exact operators for where it stands; auto: once it rests (default dynamic)"},
    {NULL, NULL, 0, 0, 0, NULL, NULL, NULL},
};

static void ctl_usage_light(FILE *f) {
    fprintf(f,
            "usage: lucentctl light set ID --type TYPE [options]\n"
            "       lucentctl light rm ID\n"
            "\n"
            "light set creates or replaces light ID (light.set, PROTOCOL.md §4.3): fields not\n"
            "given take their defaults. Options:\n");
    ctl_print_flags(ctl_light_flags, f);
    fprintf(f,
            "\nexample: lucentctl light set key --type spot --position 0.28,0.5,0.28 \\\n"
            "           --direction 0,-1,0 --intensity 2 --outer-cone 0.6\n");
}

static void ctl_usage_object(FILE *f) {
    fprintf(f,
            "usage: lucentctl object set ID --asset NAME [options]\n"
            "       lucentctl object rm ID\n"
            "\n"
            "object set creates or replaces object instance ID of a baked asset (object.set,\n"
            "PROTOCOL.md §4.5): fields not given take their defaults. Options:\n");
    ctl_print_flags(ctl_object_flags, f);
    fprintf(f, "\nexample: lucentctl object set box1 --asset cube --position 0.2,0,0.15 --scale 0.5\n");
}

/* `light set` / `object set`: ID, then flags into the `field` object of a `type` message. */
static int ctl_set_entity(int argc, char **argv, const char *noun, const char *type, const char *field,
                          const ctl_flag *flags, const char *required) {
    char cmd[32], what[128];
    char *pos[CTL_MAX_POS];
    int npos = 0, rc;
    snprintf(cmd, sizeof cmd, "%s set", noun);
    cJSON *req = cJSON_CreateObject();
    cJSON *body = cJSON_CreateObject();
    if (!req || !body) goto oom;
    rc = ctl_parse_flags(cmd, flags, argc, argv, 2, body, pos, CTL_MAX_POS, &npos);
    if (rc != 0) goto fail;
    if (npos != 1) {
        rc = npos ? ctl_usage_error("%s: expected one ID, got '%s' and '%s'", cmd, pos[0], pos[1])
                  : ctl_usage_error("%s: missing the %s ID", cmd, noun);
        goto fail;
    }
    if (!*pos[0] || strlen(pos[0]) > 64) {
        rc = ctl_usage_error("%s: ID '%.64s…' must be 1..64 bytes", cmd, pos[0]);
        goto fail;
    }
    if (!cJSON_GetObjectItemCaseSensitive(body, required)) {
        rc = ctl_usage_error("%s: --%s is required", cmd, required);
        goto fail;
    }
    if (!cJSON_AddStringToObject(body, "id", pos[0]) || !cJSON_AddStringToObject(req, "type", type)) goto oom;
    cJSON_AddItemToObject(req, field, body);
    snprintf(what, sizeof what, "%s '%s' set", noun, pos[0]);
    return ctl_change(req, what);
oom:
    fprintf(stderr, "lucentctl: out of memory\n");
    rc = CTL_EXIT_CONN;
fail:
    cJSON_Delete(req);
    cJSON_Delete(body);
    return rc;
}

/* `light rm ID` / `object rm ID`. */
static int ctl_rm_entity(int argc, char **argv, const char *noun, const char *type, const char *key) {
    if (argc != 3) return ctl_usage_error("%s rm: expected exactly one ID", noun);
    if (!*argv[2] || strlen(argv[2]) > 64) return ctl_usage_error("%s rm: ID must be 1..64 bytes", noun);
    char what[128];
    cJSON *req = cJSON_CreateObject();
    if (!req) return CTL_EXIT_CONN;
    cJSON_AddStringToObject(req, "type", type);
    cJSON_AddStringToObject(req, key, argv[2]);
    snprintf(what, sizeof what, "%s '%s' removed", noun, argv[2]);
    return ctl_change(req, what);
}

static int ctl_entity(int argc, char **argv, const char *noun, void (*usage)(FILE *), const char *set_type,
                      const char *field, const ctl_flag *flags, const char *required, const char *rm_type,
                      const char *rm_key) {
    if (argc < 2) return ctl_usage_error("%s: expected a subcommand: set | rm", noun);
    const char *sub = argv[1];
    int is_set = strcmp(sub, "set") == 0, is_rm = strcmp(sub, "rm") == 0 || strcmp(sub, "remove") == 0;
    if (!is_set && !is_rm) {
        if (strcmp(sub, "--help") == 0 || strcmp(sub, "-h") == 0) {
            usage(stdout);
            return CTL_EXIT_OK;
        }
        return ctl_usage_error("%s: unknown subcommand '%s' (expected set | rm)", noun, sub);
    }
    if (ctl_wants_help(argc - 1, argv + 1)) {
        if (is_set) usage(stdout);
        else printf("usage: lucentctl %s rm ID\n\nRemoves %s ID (%s).\n", noun, noun, rm_type);
        return CTL_EXIT_OK;
    }
    if (is_rm) return ctl_rm_entity(argc, argv, noun, rm_type, rm_key);
    return ctl_set_entity(argc, argv, noun, set_type, field, flags, required);
}

int ctl_cmd_light(int argc, char **argv) {
    return ctl_entity(argc, argv, "light", ctl_usage_light, "light.set", "light", ctl_light_flags, "type",
                      "light.remove", "light_id");
}

int ctl_cmd_object(int argc, char **argv) {
    return ctl_entity(argc, argv, "object", ctl_usage_object, "object.set", "object", ctl_object_flags, "asset",
                      "object.remove", "object_id");
}

/* --- material, env, settings --------------------------------------------------------------- */

static const ctl_flag ctl_material_flags[] = {
    {"--emission", "emission", CTL_FLAG_LIST, 1ul << 3, 0, NULL, "r,g,b",
     "required: emitted radiance, nits, each 0..1e7"},
    {NULL, NULL, 0, 0, 0, NULL, NULL, NULL},
};

static void ctl_usage_material(FILE *f) {
    fprintf(f,
            "usage: lucentctl material set NAME --emission r,g,b\n"
            "\n"
            "Sets the emission of a scene material (material.set, PROTOCOL.md §4.7); 'lucentctl\n"
            "state' lists the materials. Options:\n");
    ctl_print_flags(ctl_material_flags, f);
    fprintf(f, "\nexample: lucentctl material set light --emission 34,24,8\n");
}

int ctl_cmd_material(int argc, char **argv) {
    if (argc < 2) return ctl_usage_error("material: expected a subcommand: set");
    if (strcmp(argv[1], "set") != 0) {
        if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
            ctl_usage_material(stdout);
            return CTL_EXIT_OK;
        }
        return ctl_usage_error("material: unknown subcommand '%s' (expected set)", argv[1]);
    }
    if (ctl_wants_help(argc - 1, argv + 1)) {
        ctl_usage_material(stdout);
        return CTL_EXIT_OK;
    }
    char *pos[CTL_MAX_POS], what[128];
    int npos = 0, rc;
    cJSON *req = cJSON_CreateObject();
    cJSON *body = cJSON_CreateObject();
    if (!req || !body) {
        rc = CTL_EXIT_CONN;
        goto fail;
    }
    rc = ctl_parse_flags("material set", ctl_material_flags, argc, argv, 2, body, pos, CTL_MAX_POS, &npos);
    if (rc != 0) goto fail;
    if (npos != 1) {
        rc = ctl_usage_error("material set: expected one material NAME");
        goto fail;
    }
    cJSON *em = cJSON_DetachItemFromObjectCaseSensitive(body, "emission");
    if (!em) {
        rc = ctl_usage_error("material set: --emission is required");
        goto fail;
    }
    cJSON_AddStringToObject(req, "type", "material.set");
    cJSON_AddStringToObject(req, "material", pos[0]);
    cJSON_AddItemToObject(req, "emission", em);
    cJSON_Delete(body);
    snprintf(what, sizeof what, "material '%.64s' emission set", pos[0]);
    return ctl_change(req, what);
fail:
    cJSON_Delete(req);
    cJSON_Delete(body);
    return rc;
}

static const ctl_flag ctl_env_flags[] = {
    {"--none", "none", CTL_FLAG_SWITCH, 0, 0, NULL, NULL, "no environment light"},
    {"--color", "color", CTL_FLAG_LIST, 1ul << 3, 0, NULL, "r,g,b", "constant radiance from every direction"},
    {"--sh", "sh", CTL_FLAG_LIST, 1ul << 27, 0, NULL, "c0.r,c0.g,...",
     "27 numbers: radiance SH L2, RGB interleaved per coefficient (§2.3)"},
    {"--intensity", "intensity", CTL_FLAG_NUM, 0, 0, NULL, "N", "scale, 0..1e7 (default 1)"},
    {NULL, NULL, 0, 0, 0, NULL, NULL, NULL},
};

static void ctl_usage_env(FILE *f) {
    fprintf(f,
            "usage: lucentctl env set --none | --color r,g,b | --sh 27,NUMBERS [--intensity N]\n"
            "\n"
            "Sets the environment (sky) light (environment.set, PROTOCOL.md §4.8); exactly one\n"
            "of --none, --color, --sh. Options:\n");
    ctl_print_flags(ctl_env_flags, f);
    fprintf(f, "\nexample: lucentctl env set --color 0.4,0.5,0.7 --intensity 0.5\n");
}

int ctl_cmd_env(int argc, char **argv) {
    if (argc < 2) return ctl_usage_error("env: expected a subcommand: set");
    if (strcmp(argv[1], "set") != 0) {
        if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
            ctl_usage_env(stdout);
            return CTL_EXIT_OK;
        }
        return ctl_usage_error("env: unknown subcommand '%s' (expected set)", argv[1]);
    }
    if (ctl_wants_help(argc - 1, argv + 1)) {
        ctl_usage_env(stdout);
        return CTL_EXIT_OK;
    }
    char *pos[CTL_MAX_POS];
    int npos = 0, rc;
    cJSON *req = NULL;
    cJSON *env = cJSON_CreateObject();
    if (!env) return CTL_EXIT_CONN;
    rc = ctl_parse_flags("env set", ctl_env_flags, argc, argv, 2, env, pos, 0, &npos);
    if (rc != 0) goto fail;
    int none = cJSON_GetObjectItemCaseSensitive(env, "none") != NULL;
    int color = cJSON_GetObjectItemCaseSensitive(env, "color") != NULL;
    int sh = cJSON_GetObjectItemCaseSensitive(env, "sh") != NULL;
    if (none + color + sh != 1) {
        rc = ctl_usage_error("env set: give exactly one of --none, --color, --sh");
        goto fail;
    }
    cJSON_DeleteItemFromObjectCaseSensitive(env, "none");
    if (!cJSON_AddStringToObject(env, "type", none ? "none" : color ? "constant" : "sh")) {
        rc = CTL_EXIT_CONN;
        goto fail;
    }
    req = cJSON_CreateObject();
    if (!req) {
        rc = CTL_EXIT_CONN;
        goto fail;
    }
    cJSON_AddStringToObject(req, "type", "environment.set");
    cJSON_AddItemToObject(req, "environment", env);
    return ctl_change(req, none ? "environment off" : color ? "environment set (constant)" : "environment set (sh)");
fail:
    cJSON_Delete(env);
    cJSON_Delete(req);
    return rc;
}

static const ctl_flag ctl_settings_flags[] = {
    {"--bounces", "bounces", CTL_FLAG_INT, 0, 0, NULL, "N", "transport passes per relight after the first, 0..16"},
    {"--bands", "bands", CTL_FLAG_INT, 0, 0, NULL, "N", "SH bands of the transport, 1..8"},
    {"--progressive", "progressive", CTL_FLAG_BOOL, 0, 0, NULL, "true|false",
     "carry indirect light into the next relight"},
    {"--chroma-compression", "chroma_compression", CTL_FLAG_BOOL, 0, 0, NULL, "true|false",
     "fewer SH bands for chroma than for luma"},
    {"--chroma-bands", "chroma_bands", CTL_FLAG_INT, 0, 0, NULL, "N", "SH bands for chroma, 1..bands"},
    {"--dnrt", "dnrt", CTL_FLAG_BOOL, 0, 0, NULL, "true|false",
     "placed objects shadow and colour the indirect light (default true)"},
    {"--dnrt-blockers", "dnrt_blockers", CTL_FLAG_BOOL, 0, 0, NULL, "true|false",
     "ray-test static geometry between an object and what it shades (default true)"},
    {"--solver", "solver", CTL_FLAG_CHOICE, 0, 0, "pic|probes", "pic|probes",
     "light-transport solver, one the bake offers (welcome.scene.solvers; default the bake's)"},
    {NULL, NULL, 0, 0, 0, NULL, NULL, NULL},
};

static void ctl_usage_settings(FILE *f) {
    fprintf(f,
            "usage: lucentctl settings set [options]\n"
            "\n"
            "Changes relight settings (settings.set, PROTOCOL.md §4.9); only the options given\n"
            "are sent, at least one. Options:\n");
    ctl_print_flags(ctl_settings_flags, f);
    fprintf(f,
            "\nexamples: lucentctl settings set --bounces 2 --progressive true\n"
            "          lucentctl settings set --solver probes   (a bake made with --solver probes or both)\n");
}

int ctl_cmd_settings(int argc, char **argv) {
    if (argc < 2) return ctl_usage_error("settings: expected a subcommand: set");
    if (strcmp(argv[1], "set") != 0) {
        if (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0) {
            ctl_usage_settings(stdout);
            return CTL_EXIT_OK;
        }
        return ctl_usage_error("settings: unknown subcommand '%s' (expected set)", argv[1]);
    }
    if (ctl_wants_help(argc - 1, argv + 1)) {
        ctl_usage_settings(stdout);
        return CTL_EXIT_OK;
    }
    char *pos[CTL_MAX_POS];
    int npos = 0, rc;
    cJSON *s = cJSON_CreateObject();
    cJSON *req = cJSON_CreateObject();
    if (!s || !req) {
        rc = CTL_EXIT_CONN;
        goto fail;
    }
    rc = ctl_parse_flags("settings set", ctl_settings_flags, argc, argv, 2, s, pos, 0, &npos);
    if (rc != 0) goto fail;
    if (!s->child) {
        rc = ctl_usage_error("settings set: give at least one option (see 'lucentctl settings set --help')");
        goto fail;
    }
    cJSON_AddStringToObject(req, "type", "settings.set");
    cJSON_AddItemToObject(req, "settings", s);
    return ctl_change(req, "settings set");
fail:
    cJSON_Delete(s);
    cJSON_Delete(req);
    return rc;
}
