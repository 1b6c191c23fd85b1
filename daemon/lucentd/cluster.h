/* cluster: lucentd's replicated change log in a Redis stream (lucentd --cluster, PROTOCOL.md
 * §9, deploy/OPERATING.md). Every replica appends the changes its clients make to one stream
 * and applies every entry of it in stream order, so all replicas hold the same state; an
 * entry's position is the state's revision (IDs 0-1, 0-2, ... : XADD KEY 0-*). Snapshots of
 * the state (KEY:snapshot, and the one before it in KEY:snapshot:previous) let a new replica
 * start without the whole log, and the stream is trimmed behind the older one. KEY:bake names
 * the bake the cluster serves and KEY:limits the state's limits; a replica with another bake
 * or other limits refuses to join.
 *
 * This module only moves text between Redis and the service thread: it knows nothing of the
 * state. Two threads, each with its own Redis connection (hiredis contexts are not shared):
 *   reader: on (re)connect checks KEY:bake and loads a newer snapshot, then XREAD from the
 *     last entry it delivered: without blocking until the stream's end (then "caught up"),
 *     then BLOCK. A gap (entries trimmed behind a snapshot) loads the snapshot again.
 *   writer: XADD of the appends the service thread queues, the snapshots it hands over
 *     (a script stores one only when newer, and trims), reconnects.
 * Both report to the service thread through one item queue under `cluster.lock`, and wake it
 * with the wake callback (lws_cancel_service). On a lost connection the thread retries with
 * back-off (100 ms doubling to 5 s); lc_cluster_writable is 0 meanwhile.
 *
 * Ownership: items returned by lc_cluster_take belong to the caller (lc_cluster_item_free);
 * texts passed to lc_cluster_append / lc_cluster_snapshot are copied. */
#ifndef LC_CLUSTER_H
#define LC_CLUSTER_H
#include <stddef.h>
#include <stdint.h>

#define LC_CLUSTER_KEY_MAX 200
#define LC_CLUSTER_ID_LEN 16 /* a replica's id: 16 hex digits, new at every start */

/* A parsed --cluster URL: redis://[[USER]:PASSWORD@]HOST[:PORT]/KEY */
typedef struct lc_cluster_url {
    char host[256];
    int port;
    char user[128], password[256];
    char key[LC_CLUSTER_KEY_MAX + 1];
} lc_cluster_url;

/* Parses `len` bytes of url. 0, or -1 with err naming what is wrong (rediss:// is refused:
 * Debian 12's hiredis 0.14 has no TLS; the message says how to tunnel). */
int lc_cluster_parse_url(const char *url, size_t len, lc_cluster_url *out, char *err, size_t errlen);

typedef struct lc_cluster_config {
    lc_cluster_url url;
    int timeout_ms;                   /* connect and command timeout */
    const char *bake_id;              /* lc_lcb_bake_id of this replica's bake (copied) */
    uint32_t max_lights, max_objects; /* the state's limits: every replica must have the same */
} lc_cluster_config;

typedef enum {
    LC_CLUSTER_ENTRY = 1,     /* one log entry, in stream order */
    LC_CLUSTER_SNAPSHOT,      /* replace the state by `text` (a `state` message) at `seq` */
    LC_CLUSTER_CAUGHT_UP,     /* every entry up to the stream's end at (re)connect was delivered */
    LC_CLUSTER_APPEND_FAILED, /* the append `local` could not be confirmed: `text` says why */
    LC_CLUSTER_FATAL,         /* this replica cannot join (another bake, a log behind it): `text` */
} lc_cluster_item_kind;

typedef struct lc_cluster_item {
    struct lc_cluster_item *next;
    lc_cluster_item_kind kind;
    uint64_t seq;   /* ENTRY, SNAPSHOT: the revision */
    uint64_t local; /* ENTRY, APPEND_FAILED: the submitting replica's number for it */
    int batch;      /* ENTRY: the change was a `batch` (else one op) */
    char origin[LC_CLUSTER_ID_LEN + 1];
    char client[128]; /* ENTRY: who made it (for `changed`) */
    char *text;       /* ENTRY: {"type":"batch","ops":[...]}; SNAPSHOT: the state; else a reason */
    size_t len;
} lc_cluster_item;

typedef struct lc_cluster lc_cluster;
typedef void (*lc_cluster_wake_fn)(void *arg);

/* Main thread: starts both threads; entries after `from_revision` will be delivered (0: the
 * whole log, after the newest snapshot). NULL with err when out of memory or threads fail;
 * an unreachable Redis is not an error (the threads keep trying). */
lc_cluster *lc_cluster_start(const lc_cluster_config *cfg, uint64_t from_revision, lc_cluster_wake_fn wake,
                             void *wake_arg, char *err, size_t errlen);
/* Main thread: stops and joins both threads, frees what is queued. NULL-safe. */
void lc_cluster_stop(lc_cluster *c);

/* Service thread: queues the change (copied) for XADD with this replica's id and `local`.
 * It comes back as an ENTRY (then it is in Redis: with appendfsync always, durable) or as
 * APPEND_FAILED. -1 when out of memory. */
int lc_cluster_append(lc_cluster *c, uint64_t local, int batch, const char *client, const char *ops_json);
/* Service thread: a snapshot of the state at `revision` (copied), stored if newer than the
 * cluster's; the stream is then trimmed behind the previous snapshot. */
void lc_cluster_snapshot(lc_cluster *c, uint64_t revision, const char *state_json);
/* Service thread: everything delivered since the last call, oldest first (NULL: none). */
lc_cluster_item *lc_cluster_take(lc_cluster *c);
void lc_cluster_item_free(lc_cluster_item *it); /* the whole list from `it` */

/* Any thread: 1 when both connections are up and the reader has caught up since it last
 * (re)connected: appends can then be confirmed. */
int lc_cluster_writable(lc_cluster *c);
/* Any thread: why it is not writable ("" when it is). */
void lc_cluster_status(lc_cluster *c, char *why, size_t len);
const char *lc_cluster_replica_id(const lc_cluster *c);

/* For /metrics (any thread). */
typedef struct lc_cluster_stats {
    uint64_t appended, append_failures, entries_read, snapshots_loaded, snapshots_written, snapshot_failures,
        reconnects;
    double last_append_ms; /* XADD round trip of the last append */
} lc_cluster_stats;
void lc_cluster_get_stats(lc_cluster *c, lc_cluster_stats *out);

#endif
