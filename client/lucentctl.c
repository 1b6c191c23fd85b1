/* lucentctl: command-line control of a running lucentd over lucent/1. This file: global
 * options, the command table (dispatch and the global --help); the commands live in
 * ctl_scene.c, ctl_script.c, ctl_stream.c, ctl_mr.c and ctl_load.c (see ctl.h). */
#include <stdlib.h>
#include <string.h>

#include "ctl.h"

typedef struct ctl_command {
    const char *name;
    const char *args;    /* shown after the name in --help */
    const char *summary; /* one line */
    int (*fn)(int argc, char **argv);
    int own_json; /* takes --json FILE itself: a --json after the command is the command's */
} ctl_command;

static const ctl_command ctl_commands[] = {
    {"ping", "[--count N]", "round trip to the server in ms", ctl_cmd_ping, 0},
    {"state", "", "print the scene state (JSON)", ctl_cmd_state, 0},
    {"send", "JSON... | -", "send raw messages (arguments, or JSON lines on stdin)", ctl_cmd_send, 0},
    {"light", "set|rm ID ...", "create/replace or remove a light", ctl_cmd_light, 0},
    {"object", "set|rm ID ...", "place/replace or remove an object instance of an asset", ctl_cmd_object, 0},
    {"material", "set NAME ...", "set a material's emission", ctl_cmd_material, 0},
    {"env", "set ...", "set the environment light (none, constant colour, SH)", ctl_cmd_env, 0},
    {"settings", "set ...", "change relight settings (bounces, bands, ...)", ctl_cmd_settings, 0},
    {"script", "FILE|-", "replay timed JSON Lines messages (animations)", ctl_cmd_script, 0},
    {"watch", "...", "subscribe to streams and report frames", ctl_cmd_watch, 0},
    {"snapshot", "...", "save the current lightmap / SH data to files", ctl_cmd_snapshot, 0},
    {"latency", "...", "measure change-to-frame latency", ctl_cmd_latency, 0},
    {"mr", "replay DIR ...", "play a recorded RGB-D capture as an MR session", ctl_cmd_mr, 0},
    {"load", "--clients N ...", "load test: N viewers in one process, update latency", ctl_cmd_load, 1},
};
#define CTL_N_COMMANDS (sizeof ctl_commands / sizeof ctl_commands[0])

static void ctl_usage(FILE *f) {
    fprintf(f, "usage: lucentctl [--url URL] [--token TOKEN] [--json] COMMAND [ARGS]\n\ncommands:\n");
    for (size_t i = 0; i < CTL_N_COMMANDS; i++) {
        char left[48];
        snprintf(left, sizeof left, "%s %s", ctl_commands[i].name, ctl_commands[i].args);
        fprintf(f, "  %-24s %s\n", left, ctl_commands[i].summary);
    }
    fprintf(f,
            "\n"
            "global options (before or after COMMAND):\n"
            "  --url URL                server (default ws://127.0.0.1:7700/, env LUCENT_URL)\n"
            "  --token TOKEN            access token (env LUCENT_TOKEN)\n"
            "  --ca-file FILE           wss: trust the CA certificates in FILE (env LUCENT_CA_FILE)\n"
            "  --insecure               wss: accept self-signed certificates and any host name\n"
            "  --json                   machine-readable output (server replies as JSON lines)\n"
            "  --help                   this help; 'lucentctl COMMAND --help' for a command\n"
            "\n"
            "exit codes: 0 ok, 1 server refused, 2 usage, 3 connection (cannot connect, lost, timeout)\n");
}

/* Takes a global option at argv[*i] (advancing *i past a separate value). Returns 1 when
 * it was one, 0 when not, -1 on a usage error (already printed). */
static int ctl_global_option(int argc, char **argv, int *i) {
    const char *a = argv[*i];
    if (strcmp(a, "--json") == 0) {
        ctl_json = 1;
        return 1;
    }
    if (strcmp(a, "--insecure") == 0) {
        ctl_insecure = 1;
        return 1;
    }
    if (strcmp(a, "--ca-file") == 0) {
        if (*i + 1 >= argc) {
            ctl_usage_error("%s needs a value", a);
            return -1;
        }
        ctl_ca_file = argv[++*i];
        return 1;
    }
    if (strncmp(a, "--url=", 6) == 0 || strncmp(a, "--token=", 8) == 0) {
        const char *v = strchr(a, '=') + 1;
        if (a[2] == 'u') ctl_url = v;
        else ctl_token = v;
        return 1;
    }
    if (strcmp(a, "--url") == 0 || strcmp(a, "--token") == 0) {
        if (*i + 1 >= argc) {
            ctl_usage_error("%s needs a value", a);
            return -1;
        }
        if (a[2] == 'u') ctl_url = argv[++*i];
        else ctl_token = argv[++*i];
        return 1;
    }
    return 0;
}

int main(int argc, char **argv) {
    const char *env = getenv("LUCENT_URL");
    if (env && *env) ctl_url = env;
    env = getenv("LUCENT_TOKEN");
    if (env) ctl_token = env;
    env = getenv("LUCENT_CA_FILE");
    if (env && *env) ctl_ca_file = env;
    int i = 1;
    for (; i < argc && argv[i][0] == '-'; i++) {
        int r = ctl_global_option(argc, argv, &i);
        if (r < 0) return CTL_EXIT_USAGE;
        if (r) continue;
        if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
            ctl_usage(stdout);
            return CTL_EXIT_OK;
        }
        return ctl_usage_error("unknown option '%s'", argv[i]);
    }
    if (i >= argc) {
        ctl_usage(stderr);
        return CTL_EXIT_USAGE;
    }
    /* Global options after the command too: compact them out of its argv (up to "--",
     * after which everything belongs to the command). */
    int n = 1, own_json = 0;
    for (size_t k = 0; k < CTL_N_COMMANDS; k++)
        if (strcmp(argv[i], ctl_commands[k].name) == 0) own_json = ctl_commands[k].own_json;
    for (int j = i + 1; j < argc; j++) {
        if (strcmp(argv[j], "--") == 0) {
            while (j < argc) argv[i + n++] = argv[j++];
            break;
        }
        if (own_json && strncmp(argv[j], "--json", 6) == 0 && (argv[j][6] == 0 || argv[j][6] == '=')) {
            argv[i + n++] = argv[j];
            if (argv[j][6] == 0 && j + 1 < argc) argv[i + n++] = argv[++j]; /* its FILE */
            continue;
        }
        int r = ctl_global_option(argc, argv, &j);
        if (r < 0) return CTL_EXIT_USAGE;
        if (!r) argv[i + n++] = argv[j];
    }
    const char *cmd = argv[i];
    if (strcmp(cmd, "help") == 0) {
        if (n < 2) {
            ctl_usage(stdout);
            return CTL_EXIT_OK;
        }
        /* "help CMD" = "CMD --help" */
        cmd = argv[i + 1];
        for (size_t k = 0; k < CTL_N_COMMANDS; k++)
            if (strcmp(cmd, ctl_commands[k].name) == 0) {
                char *hv[] = {argv[i + 1], "--help", NULL};
                return ctl_commands[k].fn(2, hv);
            }
        return ctl_usage_error("help: unknown command '%s'", cmd);
    }
    for (size_t k = 0; k < CTL_N_COMMANDS; k++)
        if (strcmp(cmd, ctl_commands[k].name) == 0) return ctl_commands[k].fn(n, argv + i);
    return ctl_usage_error("unknown command '%s'", cmd);
}
