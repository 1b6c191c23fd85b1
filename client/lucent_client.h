/* liblucent-client: a small blocking lucent/1 WebSocket client (libwebsockets). */
#ifndef LUCENT_CLIENT_H
#define LUCENT_CLIENT_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct lc_client lc_client;

/* Connects to url (ws://host:port/path), offers subprotocol lucent.v1, sends hello with token and
 * client name and waits for welcome. Returns NULL on failure with a message in err. When the server
 * refused the hello (e.g. unauthorized), err starts with "server error ". */
lc_client *lc_client_connect(const char *url, const char *token, const char *name, int timeout_ms, char *err,
                             size_t errlen);

/* Sends one JSON request and waits for its reply (matched on "id"; an integer id is injected when
 * the request has none). *reply_json (malloc'd, caller frees) receives the reply text.
 * Returns 0 on ok/state/pong/other replies, 1 on a server error (reply holds it), -1 on
 * connection failure or timeout (err says which). A request that is not a JSON object is sent as
 * is and matched with the next reply. */
int lc_client_request(lc_client *c, const char *json_request, char **reply_json, int timeout_ms, char *err,
                      size_t errlen);

/* The welcome message text received at connect. */
const char *lc_client_welcome(const lc_client *c);

/* Number of binary data frames received (and ignored) so far. */
unsigned long lc_client_binary_frames(const lc_client *c);

void lc_client_close(lc_client *c);

#ifdef __cplusplus
}
#endif

#endif
