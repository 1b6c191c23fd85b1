/* lucent-bake-run: the bake worker behind `lucent-bake bake` (bake_main.c execs it with
 * its own argv, so argv[1] is "bake"). It links the whole pipeline and its dependencies.
 * Exit codes as lucent-bake's: 0 ok, 1 bad input or bake failure, 2 usage, 3 cannot write. */
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bake/bake.h"
#include "util/log.h"

enum { EXIT_OK = 0, EXIT_FAIL = 1, EXIT_USAGE = 2, EXIT_OUTPUT = 3 };

static void usage(FILE *out) {
    fprintf(out, "usage: lucent-bake bake SCENE [-o OUT.lcb] [options]   bake a glTF/OBJ/PLY scene\n\noptions:\n");
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

int main(int argc, char **argv) {
    const char *level = getenv("LUCENT_LOG_LEVEL");
    if (level && lc_log_parse_level(level) >= 0) lc_log_set_level((lc_log_level)lc_log_parse_level(level));
    if (argc < 2 || strcmp(argv[1], "bake") != 0) {
        fprintf(stderr, "lucent-bake-run: run through lucent-bake (lucent-bake bake SCENE ...)\n");
        return EXIT_USAGE;
    }
    return cmd_bake(argc, argv);
}
