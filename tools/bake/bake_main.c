/* lucent-bake: the command-line front of the bake pipeline.
 *   lucent-bake bake SCENE [options]    bake SCENE (glTF/OBJ/PLY) into a .lcb file
 *   lucent-bake info FILE [--json]      validate a .lcb and print its contents
 *   lucent-bake verify FILE             validate only (exit 0 valid, 1 invalid)
 * Exit codes: 0 ok, 1 bad input or bake failure, 2 usage error, 3 cannot write output. */
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/bake.h"
#include "lcb/lcb.h"
#include "util/log.h"

enum { EXIT_OK = 0, EXIT_FAIL = 1, EXIT_USAGE = 2, EXIT_OUTPUT = 3 };

static void usage(FILE *out) {
    fprintf(out,
            "usage: lucent-bake bake SCENE [-o OUT.lcb] [options]   bake a glTF/OBJ/PLY scene\n"
            "       lucent-bake info FILE [--json]     validate a bake file and print its contents\n"
            "       lucent-bake verify FILE            validate a bake file (exit 0 valid, 1 invalid)\n"
            "       lucent-bake --version\n\n"
            "bake options:\n");
    lc_opt_help(lc_bake_options(), out);
    fprintf(out, "\nexit codes: 0 ok, 1 bad input or bake failure, 2 usage error, 3 cannot write output\n");
}

static int cmd_bake(int argc, char **argv) {
    static lc_bake_settings s; /* large (asset paths); static keeps it off the stack */
    char err[1024] = "";
    char *pos[2];
    for (int i = 2; i < argc; i++) {
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            usage(stdout);
            return EXIT_OK;
        }
        if (!strcmp(argv[i], "-o")) argv[i] = "--output"; /* the one short flag, by habit */
    }
    int npos = lc_bake_parse_args(&s, argc, argv, 2, pos, 2, err, sizeof err);
    if (npos < 0) {
        fprintf(stderr, "lucent-bake: %s\n", err);
        return EXIT_USAGE;
    }
    if (npos != 1) {
        fprintf(stderr, "lucent-bake: bake needs exactly one SCENE file (see --help)\n");
        return EXIT_USAGE;
    }
    if (strlen(pos[0]) >= sizeof s.input) {
        fprintf(stderr, "lucent-bake: SCENE path too long\n");
        return EXIT_USAGE;
    }
    snprintf(s.input, sizeof s.input, "%s", pos[0]);
    if (!s.output[0]) {
        /* Default output: the scene's base name with .lcb, in the current directory (the
         * scene's own folder may be read-only). */
        char tmp[LC_BAKE_PATH_MAX];
        snprintf(tmp, sizeof tmp, "%s", s.input);
        char *base = basename(tmp);
        char *dot = strrchr(base, '.');
        if (dot && dot != base) *dot = 0;
        snprintf(s.output, sizeof s.output, "%.1000s.lcb", base);
    }
    if (!s.glb[0] && s.write_glb) {
        /* The viewers' copy of the scene sits next to the bake: OUT.lcb -> OUT.glb. */
        snprintf(s.glb, sizeof s.glb, "%s", s.output);
        char *dot = strrchr(s.glb, '.'), *slash = strrchr(s.glb, '/');
        if (dot && (!slash || dot > slash)) *dot = 0;
        if (strlen(s.glb) + 5 > sizeof s.glb) {
            fprintf(stderr, "lucent-bake: output path too long to derive the .glb name; pass --glb\n");
            return EXIT_USAGE;
        }
        strcat(s.glb, ".glb");
    }
    lc_bake_report report;
    int rc = lc_bake_run(&s, &report, err, sizeof err);
    if (rc != 0) {
        fprintf(stderr, "lucent-bake: %s\n", err);
        return rc == 3 ? EXIT_OUTPUT : EXIT_FAIL;
    }
    if (!s.quiet) {
        lc_bake_report_print(&report, stderr);
        fprintf(stderr, "wrote %s\n", s.output);
    }
    if (s.stats_json[0] && lc_bake_report_write_json(&report, &s, s.stats_json, err, sizeof err) != 0) {
        fprintf(stderr, "lucent-bake: --stats-json: %s\n", err);
        return EXIT_OUTPUT;
    }
    return EXIT_OK;
}

static int cmd_info(int argc, char **argv, int verify_only) {
    const char *path = NULL;
    int json = 0;
    for (int i = 2; i < argc; i++) {
        if (!strcmp(argv[i], "--json") && !verify_only) {
            json = 1;
        } else if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            usage(stdout);
            return EXIT_OK;
        } else if (argv[i][0] == '-' && argv[i][1]) {
            fprintf(stderr, "lucent-bake: unknown option '%s' for %s\n", argv[i], argv[1]);
            return EXIT_USAGE;
        } else if (path) {
            fprintf(stderr, "lucent-bake: %s takes one FILE\n", argv[1]);
            return EXIT_USAGE;
        } else {
            path = argv[i];
        }
    }
    if (!path) {
        fprintf(stderr, "lucent-bake: %s needs a FILE (see --help)\n", argv[1]);
        return EXIT_USAGE;
    }
    lc_lcb *f = NULL;
    char err[1024];
    if (lc_lcb_open(path, &f, err, sizeof err) != 0) {
        fprintf(stderr, "lucent-bake: %s: %s\n", path, err);
        return EXIT_FAIL;
    }
    if (verify_only) printf("%s: valid lucent bake file\n", path);
    else lc_lcb_print_info(f, path, json, stdout);
    lc_lcb_close(f);
    return EXIT_OK;
}

int main(int argc, char **argv) {
    const char *level = getenv("LUCENT_LOG_LEVEL");
    if (level && lc_log_parse_level(level) >= 0) lc_log_set_level((lc_log_level)lc_log_parse_level(level));
    if (argc < 2) {
        usage(stderr);
        return EXIT_USAGE;
    }
    const char *cmd = argv[1];
    if (!strcmp(cmd, "--help") || !strcmp(cmd, "-h") || !strcmp(cmd, "help")) {
        usage(stdout);
        return EXIT_OK;
    }
    if (!strcmp(cmd, "--version")) {
        printf("lucent-bake 0.1.0 (bake format %d.%d)\n", LC_LCB_VERSION_MAJOR, LC_LCB_VERSION_MINOR);
        return EXIT_OK;
    }
    if (!strcmp(cmd, "bake")) return cmd_bake(argc, argv);
    if (!strcmp(cmd, "info")) return cmd_info(argc, argv, 0);
    if (!strcmp(cmd, "verify")) return cmd_info(argc, argv, 1);
    fprintf(stderr, "lucent-bake: unknown command '%s' (bake, info, verify; see --help)\n", cmd);
    return EXIT_USAGE;
}
