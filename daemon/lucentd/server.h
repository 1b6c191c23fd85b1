/* server: lucentd's WebSocket/HTTP service on one libwebsockets thread (see server.c). */
#ifndef LC_SERVER_H
#define LC_SERVER_H

#include "config.h"
#include "lcb/lcb.h"

#define LUCENTD_VERSION "0.1.0"

/* Called once the socket listens, with the actual port (for --port 0). */
typedef void (*lc_server_ready_fn)(void *arg, int port);

/* Runs until SIGTERM/SIGINT: finishes the relight in flight, closes clients with 1001,
 * writes a final snapshot. SIGHUP reloads the configuration (argv is parsed again, so flags
 * still override the file) and applies what can change live. Returns the process exit code
 * (0 clean, 1 failure). */
int lc_server_run(const lc_config *cfg, int argc, char **argv, const lc_lcb *bake, lc_server_ready_fn ready,
                  void *ready_arg);

#endif
