/* lucent-bake: the command-line front of the bake pipeline.
 *   lucent-bake bake SCENE [options]    bake SCENE (glTF/OBJ/PLY) into a .lcb file
 *   lucent-bake info FILE [--json]      validate a .lcb and print its contents
 *   lucent-bake verify FILE             validate only (exit 0 valid, 1 invalid)
 * Exit codes: 0 ok, 1 bad input or bake failure, 2 usage error, 3 cannot write output.
 * This front links only the bake file reader; `bake` runs in lucent-bake-run (bake_run.c). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bake/options.h"
#include "lcb/lcb.h"
#include "util/fsutil.h"
#include "util/log.h"

/* The worker, relative to this executable (build tree and install prefix alike); the
 * configured install path when /proc/self/exe cannot be read. */
#ifndef LUCENT_BAKE_WORKER_REL
#define LUCENT_BAKE_WORKER_REL "../libexec/lucent/lucent-bake-run"
#endif
#ifndef LUCENT_BAKE_WORKER
#define LUCENT_BAKE_WORKER "/usr/local/libexec/lucent/lucent-bake-run"
#endif

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

/* Runs the bake itself: the worker binary linking the bake's dependencies (OIIO, Assimp,
 * Embree, ~260 shared libraries) so info, verify and --help start without loading them. */
static int cmd_bake(char **argv) {
    char worker[4096];
    lc_fs_beside_exe(LUCENT_BAKE_WORKER_REL, LUCENT_BAKE_WORKER, worker, sizeof worker);
    argv[0] = worker;
    execv(worker, argv);
    fprintf(stderr, "lucent-bake: cannot run the bake worker %s: %s (reinstall lucent: it belongs in %s from bin/)\n",
            worker, strerror(errno), LUCENT_BAKE_WORKER_REL);
    return EXIT_FAIL;
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
    if (!strcmp(cmd, "bake")) return cmd_bake(argv);
    if (!strcmp(cmd, "info")) return cmd_info(argc, argv, 0);
    if (!strcmp(cmd, "verify")) return cmd_info(argc, argv, 1);
    fprintf(stderr, "lucent-bake: unknown command '%s' (bake, info, verify; see --help)\n", cmd);
    return EXIT_USAGE;
}
