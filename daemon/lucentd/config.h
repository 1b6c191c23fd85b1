/* config: lucentd's settings. One option table (name, type, bounds, default, help) drives
 * the JSON config file, the command-line flags (which override the file), --help and
 * --check-config. */
#ifndef LC_CONFIG_H
#define LC_CONFIG_H
#include <stddef.h>

#include "util/opt.h"

#define LC_CONFIG_PATH_MAX 1024
#define LC_CONFIG_TOKENS_MAX 2048

typedef struct lc_config {
    char config_file[LC_CONFIG_PATH_MAX];
    char bake[LC_CONFIG_PATH_MAX];
    char listen[128];
    int port;
    char state_dir[LC_CONFIG_PATH_MAX];
    int fsync_mode;                               /* 0 always, 1 everysec */
    char controller_tokens[LC_CONFIG_TOKENS_MAX]; /* comma-separated; empty = no auth, everyone controls */
    char viewer_tokens[LC_CONFIG_TOKENS_MAX];
    char origins[LC_CONFIG_TOKENS_MAX]; /* comma-separated allow-list; empty = any */
    char www[LC_CONFIG_PATH_MAX];
    char tls_cert[LC_CONFIG_PATH_MAX]; /* PEM; with tls_key: serve wss:// and https:// */
    char tls_key[LC_CONFIG_PATH_MAX];
    int max_message;
    int max_depth;
    int max_batch;
    int max_lights;
    int max_objects;
    int max_clients;
    int max_queue_bytes; /* bytes of replies queued per client before it is dropped */
    int rate;            /* requests per second per connection */
    int hello_timeout;   /* seconds */
    int slow_timeout;    /* seconds a client may leave a frame unread before it is dropped */
    int backend;         /* 0 auto, 1 cpu, 2 egl */
    int threads;
    int refine_passes;       /* at most this many extra progressive relights while idle */
    double refine_tolerance; /* stop refining once the estimated remaining change is below this */
    int refine_delay;        /* ms after an update's frame before the refinement passes */
    int bounces;             /* initial feedback bounces per relight (a snapshot's settings win) */
    int grid;                /* 0 subscribed: the whole SH grid only while a client takes it; 1 always */
    int tile;                /* lightmap tile size for delta frames */
    int keyframe_interval;
    double delta_threshold;     /* relative change that marks a tile dirty */
    int compact_bytes;          /* journal size that triggers a snapshot */
    int mr;                     /* MR sessions accepted (PROTOCOL.md §8) */
    int mr_max_frame;           /* bytes per upload frame */
    int mr_max_lights;          /* area lights per MR frame */
    int mr_max_sessions;        /* concurrent MR sessions */
    double mr_max_rate;         /* upload frames per second per session */
    int clutter;                /* clutter operators built for objects in mode clutter / auto (PROTOCOL.md §4.5) */
    double clutter_rest;        /* seconds an auto object rests before its operators are built */
    int clutter_max_objects;    /* objects that may hold operators at once */
    char cluster[1024];         /* redis://… URL of the change log ("" = a single lucentd with its journal) */
    int cluster_timeout;        /* ms for connecting to and answering from Redis */
    int cluster_snapshot_every; /* log entries between snapshots */
    int log_level;
    int check_config;
    int recover; /* start from the snapshot + the journal's valid prefix, setting the rest aside */
} lc_config;

const lc_opt *lc_config_options(void);
/* Defaults, then --config FILE (found in argv), then the flags. Returns 0 or -1 with err. */
int lc_config_load(lc_config *c, int argc, char **argv, char *err, size_t errlen);
/* Copies the settings a running server can change on SIGHUP (tokens, origins, limits,
 * timeouts, frame tuning, log level) from src to dst; returns a mask of the options that
 * differ but need a restart (for the log: names in `restart_needed`). */
void lc_config_apply_reloadable(lc_config *dst, const lc_config *src, char *restart_needed, size_t len);
/* Cross-field checks (tokens, paths). */
int lc_config_validate(const lc_config *c, char *err, size_t errlen);
/* 1 if token is in the comma-separated list; constant time in the token's content (the
 * lists hold secrets), and an empty token matches nothing. */
int lc_config_has_token(const char *list, const char *token);

#endif
