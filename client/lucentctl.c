/* lucentctl: command-line control of a running lucentd over lucent/1. */
#include "lucent_client.h"

#include <cjson/cJSON.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { EXIT_OK = 0, EXIT_REFUSED = 1, EXIT_USAGE = 2, EXIT_CONN = 3 };
#define TIMEOUT_MS 5000

static const char *g_url = "ws://127.0.0.1:7700/";
static const char *g_token = "";
static int g_json = 0;

static void usage_global(FILE *f) {
    fprintf(f,
            "usage: lucentctl [--url URL] [--token TOKEN] [--json] COMMAND [ARGS]\n"
            "\n"
            "commands:\n"
            "  ping                      round trip to the server\n"
            "  state                     print the scene state (JSON)\n"
            "  send JSON... | send -     send raw messages (one per argument, or JSON lines on stdin)\n"
            "  light set ID [options]    create or update a light (lucentctl light set --help)\n"
            "  light rm ID               remove a light\n"
            "\n"
            "global options:\n"
            "  --url URL      server (default ws://127.0.0.1:7700/, env LUCENT_URL)\n"
            "  --token TOKEN  access token (env LUCENT_TOKEN)\n"
            "  --json         machine-readable output\n"
            "  --help         this help\n"
            "\n"
            "exit codes: 0 ok, 1 server refused, 2 usage, 3 connection\n");
}

static void usage_light_set(FILE *f) {
    fprintf(f, "usage: lucentctl light set ID --type point|spot|directional|area [--position x,y,z]\n"
               "         [--direction x,y,z] [--color r,g,b] [--intensity N] [--range R]\n");
}

static int usage_err(const char *fmt, const char *arg) {
    fprintf(stderr, "lucentctl: ");
    fprintf(stderr, fmt, arg);
    fprintf(stderr, "\n(see lucentctl --help)\n");
    return EXIT_USAGE;
}

static lc_client *connect_or_die(int *rc) {
    char err[512];
    lc_client *c = lc_client_connect(g_url, g_token, "lucentctl", TIMEOUT_MS, err, sizeof err);
    if (!c) {
        fprintf(stderr, "lucentctl: %s\n", err);
        *rc = strncmp(err, "server error", 12) == 0 ? EXIT_REFUSED : EXIT_CONN;
    }
    return c;
}

static void print_error(const char *reply) {
    cJSON *o = cJSON_Parse(reply);
    const cJSON *code = cJSON_GetObjectItemCaseSensitive(o, "code");
    const cJSON *ptr = cJSON_GetObjectItemCaseSensitive(o, "pointer");
    const cJSON *msg = cJSON_GetObjectItemCaseSensitive(o, "message");
    fprintf(stderr, "lucentctl: server error %s at '%s': %s\n", cJSON_IsString(code) ? code->valuestring : "?",
            cJSON_IsString(ptr) ? ptr->valuestring : "", cJSON_IsString(msg) ? msg->valuestring : "");
    cJSON_Delete(o);
}

/* Sends one request; prints the reply (pretty unless --json, or raw when raw_out). Returns an exit code. */
static int do_request(lc_client *c, const char *req, int print_reply) {
    char err[512];
    char *reply = NULL;
    int r = lc_client_request(c, req, &reply, TIMEOUT_MS, err, sizeof err);
    int rc;
    if (r < 0) {
        fprintf(stderr, "lucentctl: %s\n", err);
        rc = EXIT_CONN;
    } else if (r == 1) {
        print_error(reply);
        if (g_json) printf("%s\n", reply);
        rc = EXIT_REFUSED;
    } else {
        if (print_reply) {
            if (g_json) printf("%s\n", reply);
            else {
                cJSON *o = cJSON_Parse(reply);
                char *p = o ? cJSON_Print(o) : NULL;
                printf("%s\n", p ? p : reply);
                free(p);
                cJSON_Delete(o);
            }
        }
        rc = EXIT_OK;
    }
    free(reply);
    return rc;
}

static int run_json(cJSON *req, int print_reply) {
    char *text = cJSON_PrintUnformatted(req);
    cJSON_Delete(req);
    if (!text) return EXIT_CONN;
    int rc = EXIT_OK;
    lc_client *c = connect_or_die(&rc);
    if (c) {
        rc = do_request(c, text, print_reply);
        lc_client_close(c);
    }
    free(text);
    return rc;
}

static int cmd_ping(int argc, char **argv) {
    if (argc > 1 && strcmp(argv[1], "--help") == 0) {
        printf("usage: lucentctl ping\n");
        return EXIT_OK;
    }
    if (argc > 1) return usage_err("ping: unexpected argument '%s'", argv[1]);
    cJSON *req = cJSON_CreateObject();
    cJSON_AddStringToObject(req, "type", "ping");
    cJSON_AddNumberToObject(req, "t", 0);
    int rc = EXIT_OK;
    lc_client *c = connect_or_die(&rc);
    if (!c) {
        cJSON_Delete(req);
        return rc;
    }
    char *text = cJSON_PrintUnformatted(req);
    cJSON_Delete(req);
    if (g_json) rc = do_request(c, text, 1);
    else {
        rc = do_request(c, text, 0);
        if (rc == EXIT_OK) printf("pong from %s\n", g_url);
    }
    free(text);
    lc_client_close(c);
    return rc;
}

static int cmd_state(int argc, char **argv) {
    if (argc > 1 && strcmp(argv[1], "--help") == 0) {
        printf("usage: lucentctl [--json] state\n");
        return EXIT_OK;
    }
    if (argc > 1) return usage_err("state: unexpected argument '%s'", argv[1]);
    cJSON *req = cJSON_CreateObject();
    cJSON_AddStringToObject(req, "type", "state.get");
    return run_json(req, 1);
}

static int cmd_send(int argc, char **argv) {
    if (argc < 2 || strcmp(argv[1], "--help") == 0) {
        printf("usage: lucentctl send JSON...   (or: lucentctl send - < lines.jsonl)\n");
        return argc < 2 ? EXIT_USAGE : EXIT_OK;
    }
    int rc = EXIT_OK;
    lc_client *c = connect_or_die(&rc);
    if (!c) return rc;
    int worst = EXIT_OK;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "-") == 0) {
            char *line = NULL;
            size_t cap = 0;
            ssize_t n;
            while ((n = getline(&line, &cap, stdin)) >= 0) {
                while (n > 0 && (line[n - 1] == '\n' || line[n - 1] == '\r')) line[--n] = 0;
                if (n == 0) continue;
                rc = do_request(c, line, 1);
                if (rc > worst) worst = rc;
                if (rc == EXIT_CONN) break;
            }
            free(line);
        } else {
            rc = do_request(c, argv[i], 1);
            if (rc > worst) worst = rc;
        }
        if (rc == EXIT_CONN) break;
    }
    lc_client_close(c);
    return worst;
}

static int parse_vec3(const char *s, double v[3]) {
    char *e;
    for (int i = 0; i < 3; i++) {
        v[i] = strtod(s, &e);
        if (e == s) return -1;
        if (i < 2) {
            if (*e != ',') return -1;
            s = e + 1;
        }
    }
    return *e ? -1 : 0;
}

static int parse_num(const char *s, double *v) {
    char *e;
    *v = strtod(s, &e);
    return (e == s || *e) ? -1 : 0;
}

static void add_vec3(cJSON *o, const char *k, const double v[3]) {
    cJSON_AddItemToObject(o, k, cJSON_CreateDoubleArray(v, 3));
}

static int cmd_light(int argc, char **argv) {
    if (argc < 2 || strcmp(argv[1], "--help") == 0) {
        printf("usage: lucentctl light set ID [options] | lucentctl light rm ID\n");
        return argc < 2 ? EXIT_USAGE : EXIT_OK;
    }
    if (strcmp(argv[1], "rm") == 0) {
        if (argc > 2 && strcmp(argv[2], "--help") == 0) {
            printf("usage: lucentctl light rm ID\n");
            return EXIT_OK;
        }
        if (argc != 3) return usage_err("%s", "light rm: expected exactly one ID");
        cJSON *req = cJSON_CreateObject();
        cJSON_AddStringToObject(req, "type", "light.remove");
        cJSON_AddStringToObject(req, "light_id", argv[2]);
        return run_json(req, g_json);
    }
    if (strcmp(argv[1], "set") != 0) return usage_err("light: unknown subcommand '%s'", argv[1]);
    if (argc > 2 && strcmp(argv[2], "--help") == 0) {
        usage_light_set(stdout);
        return EXIT_OK;
    }
    if (argc < 3 || argv[2][0] == '-') {
        usage_light_set(stderr);
        return EXIT_USAGE;
    }
    cJSON *light = cJSON_CreateObject();
    cJSON_AddStringToObject(light, "id", argv[2]);
    for (int i = 3; i < argc; i++) {
        const char *k = argv[i];
        if (strcmp(k, "--help") == 0) {
            usage_light_set(stdout);
            cJSON_Delete(light);
            return EXIT_OK;
        }
        if (i + 1 >= argc) {
            cJSON_Delete(light);
            return usage_err("light set: %s needs a value", k);
        }
        const char *val = argv[++i];
        double v3[3], v;
        int bad = 0;
        if (strcmp(k, "--type") == 0) cJSON_AddStringToObject(light, "type", val);
        else if (strcmp(k, "--position") == 0 || strcmp(k, "--direction") == 0 || strcmp(k, "--color") == 0) {
            if (parse_vec3(val, v3) != 0) bad = 1;
            else add_vec3(light, k + 2, v3);
        } else if (strcmp(k, "--intensity") == 0 || strcmp(k, "--range") == 0) {
            if (parse_num(val, &v) != 0) bad = 1;
            else cJSON_AddNumberToObject(light, k + 2, v);
        } else {
            cJSON_Delete(light);
            return usage_err("light set: unknown option '%s'", k);
        }
        if (bad) {
            cJSON_Delete(light);
            return usage_err("light set: bad value '%s'", val);
        }
    }
    if (!cJSON_GetObjectItemCaseSensitive(light, "type")) {
        cJSON_Delete(light);
        return usage_err("%s", "light set: --type is required");
    }
    cJSON *req = cJSON_CreateObject();
    cJSON_AddStringToObject(req, "type", "light.set");
    cJSON_AddItemToObject(req, "light", light);
    return run_json(req, g_json);
}

int main(int argc, char **argv) {
    const char *env = getenv("LUCENT_URL");
    if (env && *env) g_url = env;
    env = getenv("LUCENT_TOKEN");
    if (env) g_token = env;
    int i = 1;
    for (; i < argc && argv[i][0] == '-' && argv[i][1] == '-'; i++) {
        const char *a = argv[i];
        if (strcmp(a, "--help") == 0) {
            usage_global(stdout);
            return EXIT_OK;
        } else if (strcmp(a, "--json") == 0) g_json = 1;
        else if (strcmp(a, "--url") == 0 || strcmp(a, "--token") == 0) {
            if (i + 1 >= argc) return usage_err("%s needs a value", a);
            if (a[2] == 'u') g_url = argv[++i];
            else g_token = argv[++i];
        } else if (strncmp(a, "--url=", 6) == 0) g_url = a + 6;
        else if (strncmp(a, "--token=", 8) == 0) g_token = a + 8;
        else return usage_err("unknown option '%s'", a);
    }
    if (i >= argc) {
        usage_global(stderr);
        return EXIT_USAGE;
    }
    /* --json is also accepted after the subcommand */
    int n = 0;
    for (int j = i; j < argc; j++) {
        if (strcmp(argv[j], "--json") == 0 && j > i) g_json = 1;
        else argv[i + n++] = argv[j];
    }
    const char *cmd = argv[i];
    if (strcmp(cmd, "ping") == 0) return cmd_ping(n, argv + i);
    if (strcmp(cmd, "state") == 0) return cmd_state(n, argv + i);
    if (strcmp(cmd, "send") == 0) return cmd_send(n, argv + i);
    if (strcmp(cmd, "light") == 0) return cmd_light(n, argv + i);
    if (strcmp(cmd, "help") == 0) {
        usage_global(stdout);
        return EXIT_OK;
    }
    return usage_err("unknown command '%s'", cmd);
}
