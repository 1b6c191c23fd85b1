/* lucentd: the lucent lighting service.
 *   lucentd [--bake FILE] [--port N] [--config FILE] [options]   (see --help)
 * Exit codes: 0 clean shutdown, 1 runtime failure, 2 invalid configuration or bake. */
#include <stdio.h>
#include <string.h>

#include "config.h"
#include "lcb/lcb.h"
#include "server.h"
#include "util/log.h"

static void main_ready(void *arg, int port) {
    (void)arg;
    /* A machine-readable line for scripts and tests that start lucentd on --port 0. */
    printf("lucentd listening port=%d\n", port);
    fflush(stdout);
}

int main(int argc, char **argv) {
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) {
            printf(
                "usage: lucentd [options]\n\nWith no options it serves the embedded Cornell box on 127.0.0.1:7700.\n\n");
            lc_opt_help(lc_config_options(), stdout);
            printf("\nexit codes: 0 clean shutdown, 1 runtime failure, 2 invalid configuration or bake\n");
            return 0;
        }
        if (!strcmp(argv[i], "--version")) {
            printf("lucentd %s (protocol %s)\n", LUCENTD_VERSION, "lucent/1");
            return 0;
        }
    }
    static lc_config cfg;
    char err[1024];
    if (lc_config_load(&cfg, argc, argv, err, sizeof err) != 0) {
        fprintf(stderr, "lucentd: %s\n", err);
        return 2;
    }
    lc_log_set_level((lc_log_level)cfg.log_level);
    lc_lcb *bake = NULL;
    if (lc_lcb_open(cfg.bake, &bake, err, sizeof err) != 0) {
        fprintf(stderr, "lucentd: %s: %s\n", cfg.bake, err);
        return 2;
    }
    if (cfg.check_config) {
        printf("configuration valid; bake %s valid\n", cfg.bake);
        lc_lcb_close(bake);
        return 0;
    }
    int rc = lc_server_run(&cfg, argc, argv, bake, main_ready, NULL);
    lc_lcb_close(bake);
    return rc;
}
