/* server_internal: what lucentd's service-thread files share (server.c: the WebSocket glue,
 * sessions and the run loop; server_requests.c: hello, roles and request dispatch;
 * server_http.c: /healthz, /metrics, --www and who may connect; server_frames.c: frame
 * encoding). Private to lc_daemon. Every function declared here runs on the service thread. */
#ifndef LC_SERVER_INTERNAL_H
#define LC_SERVER_INTERNAL_H
#include <libwebsockets.h>

#include "cluster.h"
#include "clutter_worker.h"
#include "compute.h"
#include "config.h"
#include "journal.h"
#include "mr_worker.h"
#include "server_frames.h"
#include "state.h"

#define SERVER_OUTQ \
    1024 /* queued text messages per session (replies to a full request burst fit); past this the client is too slow */
/* What a socket may send before its hello is accepted: a hello is a client name and a token
 * (lucent_proto.h), so an unauthenticated peer never gets the full --max-message buffer. */
#define SERVER_HELLO_MAX 4096

enum { STREAMS = 5 }; /* index = lc_stream (1..4) */

typedef struct lc_server lc_server;
struct server_mr_session; /* server_mr.c */

/* The light one MR session gives one of its objects (the objects and mr.vpl streams). */
typedef struct server_mr_entry {
    char id[LC_PROTO_ID_MAX + 1];
    float sh[27]; /* irradiance SH of the capture at the object's centre */
    int add;      /* 1: added to the object's grid light; 0: replaces it */
    uint32_t slot;
    uint32_t n_points;
    lc_mr_vpl *vpl; /* n_points, malloc'd */
} server_mr_entry;

typedef struct lc_session {
    struct lws *wsi;
    lc_server *srv;
    struct lc_session *next;
    int authed, controller;
    int mr_granted;               /* the "mr" capability was asked for and granted (PROTOCOL.md §8.1) */
    struct server_mr_session *mr; /* the open MR session, or NULL */
    char client[LC_PROTO_NAME_MAX + 1];
    char peer[64]; /* the peer's address, for the failed-hello throttle and the log */
    char *rx;
    size_t rx_len, rx_cap;
    size_t
        rx_limit; /* the bound of the message being received, fixed at its first fragment (SIGHUP may change the live one) */
    int rx_binary, rx_oversize;
    char *outq[SERVER_OUTQ];
    int outq_head, outq_n;
    size_t outq_bytes;       /* bytes in outq: over --max-queue-bytes the client is dropped */
    double stalled_since_ms; /* since when output has waited without the client taking any (0 = none) */
    int closing, close_code;
    char close_reason[64];
    double connected_ms;
    double tokens, refill_ms; /* request rate limit (token bucket) */
    struct {
        int on, force;
        lc_encoding enc;
        int residual;          /* lightmap deltas as compressed residuals (PROTOCOL.md §6.2.1) */
        uint64_t sequence;     /* frames sent on this stream */
        uint64_t sent_pub_seq; /* publication last sent */
        uint64_t sent_mr_seq;  /* MR light last sent (objects, mr.vpl) */
        double max_rate, last_ms;
    } stream[STREAMS];
    lc_frames_copy copy; /* the client's lightmap copy and frame buffer */
    lc_published *frame; /* newest result for this session (a reference) */
    uint64_t frame_seq;
    uint64_t deferred_seq; /* the publication whose residual delta waited once for cheaper frames */
    uint8_t *tx;
    size_t tx_cap;
} lc_session;

/* An object in mode clutter or auto (server_clutter.c). */
typedef struct server_clutter_entry {
    char id[LC_PROTO_ID_MAX + 1];
    lc_engine_object placed; /* its placement when last seen */
    double rested_since_ms;  /* when it got there (auto objects rest from then) */
    int requested;           /* operators for `placed` were asked of the worker */
    int over_limit;          /* --clutter-max-objects kept it dynamic (logged once) */
} server_clutter_entry;

/* Failed hellos per peer address (see server_auth_peer_for). */
#define SERVER_AUTH_PEERS 256
#define SERVER_AUTH_BURST 10.0
#define SERVER_AUTH_PER_S 1.0
typedef struct server_auth_peer {
    char peer[64];
    double tokens, last_ms;
} server_auth_peer;

/* One glTF document served over HTTP (server_geometry.c). */
typedef struct server_glb {
    char path[8 + 3 * 64 + 8]; /* "/scene.glb" or "/assets/NAME.glb" (NAME percent-encoded) */
    unsigned char *data;
    size_t len;
} server_glb;

/* Per HTTP connection ("http" protocol user data): a body being written from memory. */
typedef struct server_http_tx {
    const unsigned char *data; /* NULL when nothing is being written; points into a server_glb */
    size_t len, sent;
} server_http_tx;

struct lc_server {
    lc_config cfg_live;          /* the configuration in force: SIGHUP reloads its reloadable fields */
    lc_config cfg_reload;        /* SIGHUP parses into this, then copies what may change */
    lc_config *cfg;              /* = &cfg_live */
    struct lws_http_mount mount; /* --www (lws keeps a pointer to it) */
    struct lws_http_mount mount_scene, mount_assets; /* /scene.glb, /assets: answered by server_http_callback */
    int argc;
    char **argv;
    const lc_lcb *bake;
    const lc_lcb_view *v;
    lc_state state;
    lc_journal *journal;
    lc_compute *compute;
    struct lws_context *ctx;
    lc_session *sessions;
    uint32_t n_sessions;
    uint64_t pub_seq;  /* compute publications seen */
    int grid_wanted;   /* relights compute the whole SH grid (server_update_grid) */
    uint32_t tile;     /* lightmap delta tile side: --tile, or chosen from the lightmap size */
    lc_frames *frames; /* what sessions' frames share (each lightmap encoded once per encoding) */
    const char **asset_names, **material_names;
    server_glb *glbs; /* [0] /scene.glb, then one per asset; built before the loop, then immutable */
    uint32_t n_glbs;
    const char **asset_paths; /* per asset: its glbs[] path (for welcome) */
    char bake_id[32];         /* lc_lcb_bake_id: names the geometry the lightmap belongs to */
    lc_proto_limits limits;
    lws_sorted_usec_list_t tick;
    int port;
    uint32_t max_clients;        /* --max-clients, lowered to what the descriptor limit allows */
    unsigned fd_budget;          /* descriptors the sockets may use (0 = unlimited) */
    unsigned fd_ceiling;         /* an accepted socket numbered at or above this is closed (0 = none) */
    uint64_t fd_ceiling_refused; /* connections closed at accept for it */
    /* metrics */
    uint64_t frames_sent, bytes_sent, messages_in;
    uint64_t errors[LC_ERR_COUNT]; /* error replies per catalogue code */
    uint64_t origins_refused;      /* handshakes refused for their Origin */
    uint64_t dropped_slow;         /* sessions dropped for not taking their output */
    uint64_t auth_failures;        /* hellos with an unknown token */
    uint64_t reloads;              /* SIGHUPs whose configuration was applied */
    server_auth_peer auth_peers[SERVER_AUTH_PEERS];
    uint64_t relight_failures_reported; /* compute failures already told to clients */
    /* MR sessions (server_mr.c) */
    lc_mrw *mrw; /* NULL: MR off */
    struct server_mr_session *mr_slots[LC_MRW_SLOTS];
    server_mr_entry *mr_entries; /* sorted by id */
    uint32_t n_mr_entries;
    uint64_t mr_seq;   /* changes of mr_entries */
    uint64_t mr_epoch; /* mr.begin count */
    uint64_t mr_frames_in, mr_bytes_in;
    double mr_last_ms;
    lc_mr_timings mr_last_timings;
    /* clutter objects (server_clutter.c) */
    lc_clw *clw; /* NULL: no operators are built (--clutter false, or not the CPU backend) */
    server_clutter_entry *clutter;
    uint32_t n_clutter, cap_clutter;
    uint32_t clutter_waiting;                       /* auto objects resting towards promotion */
    char (*clutter_announced)[LC_PROTO_ID_MAX + 1]; /* objects clients were told are clutter (§5.5) */
    uint32_t n_announced, cap_announced;
    uint64_t clutter_events; /* object.transport broadcasts */
    /* cluster mode (server_cluster.c): NULL without --cluster; then s->journal is NULL */
    lc_cluster *cluster;
    int cluster_ready;                              /* caught up with the log once since the start (/healthz) */
    char cluster_fatal[512];                        /* why this replica cannot join ("" = it can) */
    uint64_t cluster_local;                         /* numbers this replica's appends */
    struct server_cluster_pending *cluster_pending; /* appends waiting to be read back */
    uint32_t n_cluster_pending, cap_cluster_pending;
    uint64_t cluster_applied, cluster_skipped;
};

/* server.c */
void server_count_error(lc_server *s, const char *code);
/* Queues text (takes ownership); a client too far behind is dropped. */
void session_send(lc_session *ss, char *text);
void session_error(lc_server *s, lc_session *ss, const lc_proto_id *id, lc_proto_errcode code, const char *pointer,
                   const char *message);
/* Closes after what is queued has gone out (code and reason of the close frame). */
void session_close(lc_session *ss, int code, const char *reason);
/* 1 when some stream has a newer frame than the client got. */
int session_wants_frame(const lc_session *ss);
/* Relights compute the whole SH grid while some client subscribes to shgrid (or --grid
 * always); call after a subscription changes or a session goes. */
void server_update_grid(lc_server *s);
/* accept() failures seen so far (for /metrics). */
uint64_t server_accept_errors_total(void);

/* server_requests.c: one complete text message from the session. */
void server_request(lc_server *s, lc_session *ss, const char *text, size_t len);

/* server_mr.c */
/* Main thread, before the loop: starts the MR worker when --mr and the bake has sparse points. */
int server_mr_start(lc_server *s, char *err, size_t errlen);
void server_mr_stop(lc_server *s);
/* 1 when MR sessions can be granted. */
int server_mr_available(const lc_server *s);
void server_mr_begin(lc_server *s, lc_session *ss, const lc_proto_request *req);
/* Ends the session's MR session, if any (mr.end, a second mr.begin, the connection closing). */
void server_mr_end(lc_server *s, lc_session *ss);
/* One complete binary message. */
void server_mr_frame(lc_server *s, lc_session *ss, const uint8_t *data, size_t len);
/* On wake: the worker's results become acks and stream content. */
void server_mr_collect(lc_server *s);
/* The stream's frame from the MR light (mr.vpl) into cp; its length, 0 when out of memory. */
size_t server_mr_encode_vpl(lc_server *s, lc_session *ss, lc_encoding enc, uint64_t sequence);

/* server_clutter.c */
/* Main thread, after the compute thread started: the clutter worker (when --clutter and the CPU
 * backend), then builds for the restored state's clutter objects. 0 or -1 with err. */
int server_clutter_start(lc_server *s, char *err, size_t errlen);
/* After lc_compute_stop, before lc_compute_release (the worker delivers to it). */
void server_clutter_stop(lc_server *s);
/* After every change of s->state: asks for, or cancels, operator builds. */
void server_clutter_sync(lc_server *s);
/* Every tick: auto objects that have rested long enough. */
void server_clutter_tick(lc_server *s);
/* On each new publication: object.transport events for what changed. */
void server_clutter_published(lc_server *s, const lc_published *p);
/* 1 when clients were told object_id is clutter (state replies, §5.4). */
int server_clutter_announced(const lc_server *s, const char *object_id);

/* server_cluster.c */
/* Main thread, after the lws context exists: with --cluster, starts the log's threads. 0 or -1. */
int server_cluster_start(lc_server *s, char *err, size_t errlen);
/* After lws_context_destroy (no session is left). NULL-safe in cluster. */
void server_cluster_stop(lc_server *s);
/* A change from a session: validated, appended; `ok` comes when the entry is read back. */
void server_cluster_change(lc_server *s, lc_session *ss, const lc_proto_request *req);
/* On wake: applies what the log delivered, in order; acks, `changed`, one relight. */
void server_cluster_collect(lc_server *s);
/* Every tick: appends not read back in time are reported to their clients. */
void server_cluster_tick(lc_server *s);
/* A session closed: its pending appends lose their recipient. */
void server_cluster_session_gone(lc_server *s, lc_session *ss);
/* /healthz in cluster mode: 0 when healthy (the caller answers), else the body's length. */
int server_cluster_health(lc_server *s, char *body, size_t cap, unsigned *status);

/* server_geometry.c */
/* Main thread, before the loop: builds the scene's and the assets' glTF. 0 or -1 (logged). */
int server_geometry_build(lc_server *s);
void server_geometry_release(lc_server *s);
/* The document a request path names, or NULL. */
const server_glb *server_geometry_find(const lc_server *s, const char *uri);
/* Service thread: sends g's headers and starts the body (1 on failure: close). */
int server_geometry_start(lc_server *s, struct lws *wsi, server_http_tx *tx, const server_glb *g);
/* Service thread, on HTTP_WRITEABLE: the next chunk (-1: close). */
int server_geometry_write(struct lws *wsi, server_http_tx *tx);

/* server_http.c */
/* Answers a WebSocket handshake with an HTTP status and body instead of a silent close.
 * Returns 1 (lws then drops the connection). */
int server_refuse_http(struct lws *wsi, unsigned status, const char *body);
/* 1 when the handshake's Origin may open a session (PROTOCOL.md §1.1); else why. */
int server_origin_allowed(const lc_server *s, struct lws *wsi, char *why, size_t whylen);
/* The "http" protocol's callback: /healthz, /metrics, the --www mount's checks. */
int server_http_callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len);

#endif
