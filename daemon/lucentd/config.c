/* config: the option table and the JSON config file (see config.h). */
#include "config.h"

#include "cluster.h"

#include <cjson/cJSON.h>
#include <ctype.h>
#include <errno.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "util/fsutil.h"
#include "util/limits.h"
#include "util/log.h"

/* The default bake is found relative to the running executable (bin/lucentd ->
 * ../share/lucent/cornell.lcb, lc_fs_beside_exe); LUCENT_DEFAULT_BAKE, the configured install
 * path, when the executable's path cannot be read. */
#ifndef LUCENT_DEFAULT_BAKE_REL
#define LUCENT_DEFAULT_BAKE_REL "../share/lucent/cornell.lcb"
#endif
#ifndef LUCENT_DEFAULT_BAKE
#define LUCENT_DEFAULT_BAKE "/usr/local/share/lucent/cornell.lcb"
#endif
/* The viewer's bundle, found the same way; served at / unless --www names another folder. */
#ifndef LUCENT_DEFAULT_WWW_REL
#define LUCENT_DEFAULT_WWW_REL "../share/lucent/www"
#endif
#ifndef LUCENT_DEFAULT_WWW
#define LUCENT_DEFAULT_WWW "/usr/local/share/lucent/www"
#endif
static char config_default_bake[LC_CONFIG_PATH_MAX]; /* the "bake" option's default */
static char config_default_www[LC_CONFIG_PATH_MAX];  /* the "www" option's default */

static int config_is_dir(const char *path) {
    struct stat st;
    return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

static void config_resolve_default_bake(void) {
    if (!config_default_bake[0])
        lc_fs_beside_exe(LUCENT_DEFAULT_BAKE_REL, LUCENT_DEFAULT_BAKE, config_default_bake, sizeof config_default_bake);
    if (!config_default_www[0])
        lc_fs_beside_exe(LUCENT_DEFAULT_WWW_REL, LUCENT_DEFAULT_WWW, config_default_www, sizeof config_default_www);
}

#define OFF(f) offsetof(lc_config, f)
static const lc_opt config_options[] = {
    {"config", LC_OPT_STRING, OFF(config_file), 0, LC_CONFIG_PATH_MAX, NULL, NULL,
     "JSON config file (keys are these option names; flags override it)", "FILE", NULL},
    {"bake", LC_OPT_STRING, OFF(bake), 1, LC_CONFIG_PATH_MAX, config_default_bake, NULL,
     "bake file to serve (by default the Cornell box in ../share/lucent/ from lucentd's directory)", "FILE", NULL},
    {"listen", LC_OPT_STRING, OFF(listen), 1, 128, "127.0.0.1", NULL, "interface address to listen on", "ADDR", NULL},
    {"port", LC_OPT_INT, OFF(port), 0, 65535, LC_LIMIT_STR(LC_DEFAULT_PORT), NULL,
     "TCP port (0 = any free port, logged)", NULL, NULL},
    {"state-dir", LC_OPT_STRING, OFF(state_dir), 1, LC_CONFIG_PATH_MAX, "lucent-state", NULL,
     "directory of the journal and snapshot", "DIR", NULL},
    {"fsync", LC_OPT_ENUM, OFF(fsync_mode), 0, 0, "always", "always|everysec",
     "journal durability: fsync before every ok, or once a second", NULL, NULL},
    {"controller-tokens", LC_OPT_STRING, OFF(controller_tokens), 0, LC_CONFIG_TOKENS_MAX, NULL, NULL,
     "comma-separated tokens with the controller role (none = no authentication: every client controls)", "LIST", NULL},
    {"viewer-tokens", LC_OPT_STRING, OFF(viewer_tokens), 0, LC_CONFIG_TOKENS_MAX, NULL, NULL,
     "comma-separated tokens with the viewer role", "LIST", NULL},
    {"origins", LC_OPT_STRING, OFF(origins), 0, LC_CONFIG_TOKENS_MAX, NULL, NULL,
     "comma-separated Origins (e.g. https://app.example) whose pages may connect; lucentd's own --www pages "
     "always may. None = only pages served from localhost/127.0.0.1/[::1]; others get HTTP 403. Clients "
     "without an Origin header (native, lucentctl) always pass",
     "LIST", NULL},
    {"www", LC_OPT_STRING, OFF(www), 0, LC_CONFIG_PATH_MAX, config_default_www, NULL,
     "directory of static files served at / (by default the viewer in ../share/lucent/www from lucentd's directory, "
     "when built; \"\" serves none)",
     "DIR", NULL},
    {"tls-cert", LC_OPT_STRING, OFF(tls_cert), 0, LC_CONFIG_PATH_MAX, NULL, NULL,
     "TLS certificate (PEM); with --tls-key the port serves wss:// and https://", "FILE", NULL},
    {"tls-key", LC_OPT_STRING, OFF(tls_key), 0, LC_CONFIG_PATH_MAX, NULL, NULL, "TLS private key (PEM)", "FILE", NULL},
    {"max-message", LC_OPT_INT, OFF(max_message), 1024, LC_LIMIT_MESSAGE_MAX, LC_LIMIT_STR(LC_LIMIT_MESSAGE), NULL,
     "largest text message (bytes)", NULL, NULL},
    {"max-depth", LC_OPT_INT, OFF(max_depth), 4, 64, LC_LIMIT_STR(LC_LIMIT_DEPTH), NULL, "deepest JSON nesting", NULL,
     NULL},
    {"max-batch", LC_OPT_INT, OFF(max_batch), 1, LC_LIMIT_BATCH_MAX, LC_LIMIT_STR(LC_LIMIT_BATCH), NULL,
     "ops per batch", NULL, NULL},
    {"max-lights", LC_OPT_INT, OFF(max_lights), 1, LC_LIMIT_LIGHTS, LC_LIMIT_STR(LC_LIMIT_LIGHTS), NULL, "lights held",
     NULL, NULL},
    {"max-objects", LC_OPT_INT, OFF(max_objects), 1, LC_LIMIT_OBJECTS, LC_LIMIT_STR(LC_LIMIT_OBJECTS), NULL,
     "object instances held", NULL, NULL},
    {"max-clients", LC_OPT_INT, OFF(max_clients), 1, 100000, "1000", NULL,
     "connected clients (lowered, with a warning, to what the open-files limit allows)", NULL, NULL},
    {"max-queue-bytes", LC_OPT_INT, OFF(max_queue_bytes), 65536, 1073741824, "8388608", NULL,
     "replies queued for one client that does not read; past it the client is dropped (1008)", "BYTES", NULL},
    {"rate", LC_OPT_INT, OFF(rate), 1, 100000, LC_LIMIT_STR(LC_LIMIT_RATE), NULL,
     "requests per second per connection (burst 2x)", NULL, NULL},
    {"hello-timeout", LC_OPT_INT, OFF(hello_timeout), 1, 600, "5", NULL, "seconds a client has to send hello", NULL,
     NULL},
    {"slow-timeout", LC_OPT_INT, OFF(slow_timeout), 1, 3600, "10", NULL,
     "seconds a client may take none of its output (replies or frames) before it is dropped (1008)", NULL, NULL},
    {"backend", LC_OPT_ENUM, OFF(backend), 0, 0, "auto", "auto|cpu|egl", "relight backend", NULL, NULL},
    {"threads", LC_OPT_INT, OFF(threads), 0, 256, "0", NULL, "relight threads (0 = all cores)", NULL, NULL},
    {"refine-delay", LC_OPT_INT, OFF(refine_delay), 0, 10000, "20", NULL,
     "milliseconds after an update's frame before the idle refinement passes (lets the frame reach clients first)",
     "MS", NULL},
    {"refine-passes", LC_OPT_INT, OFF(refine_passes), 0, 64, "48", NULL,
     "at most this many extra progressive relights while no update waits (each adds a bounce)", NULL, NULL},
    {"refine-tolerance", LC_OPT_FLOAT, OFF(refine_tolerance), 0, 1, "0.001", NULL,
     "refinement stops once the light still to come is estimated below this share of the lightmap (0 = run all "
     "--refine-passes)",
     NULL, NULL},
    {"bounces", LC_OPT_INT, OFF(bounces), 0, 16, "0", NULL,
     "initial feedback bounces per relight (updates stay fast; refinement adds the rest)", NULL, NULL},
    {"grid", LC_OPT_ENUM, OFF(grid), 0, 0, "subscribed", "subscribed|always",
     "when relights compute the whole SH grid: while a client subscribes to the shgrid stream, else only the cells "
     "the objects and surfels read (subscribed), or every relight (always)",
     NULL, NULL},
    {"tile", LC_OPT_INT, OFF(tile), 0, 256, "0", NULL,
     "lightmap tile size for delta frames (texels, >= 8; 0 = 32, 16 or 8: at least 64 tiles)", NULL, NULL},
    {"keyframe-interval", LC_OPT_INT, OFF(keyframe_interval), 1, 100000, "30", NULL,
     "frames between lightmap keyframes", NULL, NULL},
    {"delta-threshold", LC_OPT_FLOAT, OFF(delta_threshold), 0, 1, "0.01", NULL,
     "relative texel change that puts a tile in a delta frame", NULL, NULL},
    {"compact-bytes", LC_OPT_INT, OFF(compact_bytes), 4096, 1073741824, "1048576", NULL,
     "journal size that triggers a snapshot", NULL, NULL},
    {"mr", LC_OPT_BOOL, OFF(mr), 0, 1, "true", NULL,
     "accept MR sessions (PROTOCOL.md §8): controllers may upload RGB-D frames that light the session's objects", NULL,
     NULL},
    {"mr-max-frame", LC_OPT_INT, OFF(mr_max_frame), 65536, 67108864, "4194304", NULL,
     "largest MR upload frame (bytes, as sent)", "BYTES", NULL},
    {"mr-max-lights", LC_OPT_INT, OFF(mr_max_lights), 64, 1048576, "12288", NULL,
     "area lights made from one MR frame; pixels are merged in blocks above it (the CPU cost is lights x points)", NULL,
     NULL},
    {"mr-max-sessions", LC_OPT_INT, OFF(mr_max_sessions), 1, 16, "4", NULL, "concurrent MR sessions", NULL, NULL},
    {"mr-max-rate", LC_OPT_FLOAT, OFF(mr_max_rate), 0.1, 60, "30", NULL,
     "MR upload frames per second a session may send (a session asks for at most this)", NULL, NULL},
    {"clutter", LC_OPT_BOOL, OFF(clutter), 0, 1, "true", NULL,
     "build DRT operators for objects in mode clutter or auto (PROTOCOL.md §4.5), in the background", NULL, NULL},
    {"clutter-rest", LC_OPT_FLOAT, OFF(clutter_rest), 0.1, 3600, "2", NULL,
     "seconds an object in mode auto must rest before its operators are built", "S", NULL},
    {"clutter-max-objects", LC_OPT_INT, OFF(clutter_max_objects), 1, 4096, "64", NULL,
     "objects that may hold clutter operators at once (a few MiB each); further ones stay dynamic", NULL, NULL},
    {"cluster", LC_OPT_STRING, OFF(cluster), 0, 1024, NULL, NULL,
     "run as one replica of a cluster whose change log is the Redis stream KEY: every replica applies the same "
     "changes in the same order (PROTOCOL.md §9, deploy/OPERATING.md); the state then lives in Redis, not in "
     "--state-dir. A password in the URL is better kept in the --config file",
     "redis://[[USER]:PASSWORD@]HOST[:PORT]/KEY", NULL},
    {"cluster-timeout", LC_OPT_INT, OFF(cluster_timeout), 100, 60000, "2000", NULL,
     "milliseconds to connect to Redis or get an answer before the replica turns read-only and reconnects", "MS", NULL},
    {"cluster-snapshot-every", LC_OPT_INT, OFF(cluster_snapshot_every), 10, 100000000, "1000", NULL,
     "log entries between snapshots of the state in Redis (the log is trimmed behind the one before)", NULL, NULL},
    {"log-level", LC_OPT_ENUM, OFF(log_level), 0, 0, "info", "debug|info|warn|error", "log level", NULL, NULL},
    {"check-config", LC_OPT_BOOL, OFF(check_config), 0, 1, "false", NULL,
     "validate the configuration and the bake file, then exit (0 valid, 2 invalid)", NULL, NULL},
    {"recover", LC_OPT_BOOL, OFF(recover), 0, 1, "false", NULL,
     "start even if a journal line is corrupt: restore the snapshot and the lines before it, keep the rest in "
     "STATE-DIR/journal.dropped.* (logged) and rewrite the state so the next start is clean",
     NULL, NULL},
    {NULL, 0, 0, 0, 0, NULL, NULL, NULL, NULL, NULL},
};
#undef OFF

const lc_opt *lc_config_options(void) {
    config_resolve_default_bake();
    return config_options;
}

/* Applies a JSON object of option names to values (strings, numbers, booleans). */
static int config_apply_json(lc_config *c, const char *path, char *err, size_t errlen) {
    size_t len;
    char *text = lc_fs_read(path, 1 << 20, &len, err, errlen);
    if (!text) return -1;
    cJSON *root = cJSON_ParseWithLength(text, len);
    free(text);
    if (!cJSON_IsObject(root)) {
        lc_set_err(err, errlen, "%s: not a JSON object (check the syntax)", path);
        cJSON_Delete(root);
        return -1;
    }
    int rc = 0;
    for (const cJSON *it = root->child; it; it = it->next) {
        char value[LC_CONFIG_TOKENS_MAX];
        if (cJSON_IsString(it)) snprintf(value, sizeof value, "%s", it->valuestring);
        else if (cJSON_IsBool(it)) snprintf(value, sizeof value, "%s", cJSON_IsTrue(it) ? "true" : "false");
        else if (cJSON_IsNumber(it)) snprintf(value, sizeof value, "%.17g", it->valuedouble);
        else if (cJSON_IsArray(it)) { /* token lists may be arrays of strings */ size_t n = 0;
            value[0] = 0;
            for (const cJSON *e = it->child; e; e = e->next) {
                if (!cJSON_IsString(e)) {
                    lc_set_err(err, errlen, "%s: \"%s\" must hold strings", path, it->string);
                    rc = -1;
                    break;
                }
                n += (size_t)snprintf(value + n, sizeof value - n, "%s%s", n ? "," : "", e->valuestring);
                if (n >= sizeof value) {
                    lc_set_err(err, errlen, "%s: \"%s\" is too long", path, it->string);
                    rc = -1;
                    break;
                }
            }
            if (rc) break;
        } else {
            lc_set_err(err, errlen, "%s: \"%s\" must be a string, number or boolean", path, it->string);
            rc = -1;
            break;
        }
        if (!strcmp(it->string, "config")) {
            lc_set_err(err, errlen, "%s: \"config\" cannot be set inside a config file", path);
            rc = -1;
            break;
        }
        char oerr[512];
        if (lc_opt_set(config_options, c, it->string, value, oerr, sizeof oerr) != 0) {
            lc_set_err(err, errlen, "%s: %s", path, oerr);
            rc = -1;
            break;
        }
    }
    cJSON_Delete(root);
    return rc;
}

int lc_config_load(lc_config *c, int argc, char **argv, char *err, size_t errlen) {
    memset(c, 0, sizeof *c);
    config_resolve_default_bake();
    if (lc_opt_defaults(config_options, c, err, errlen) != 0) return -1;
    /* First pass only to find --config; the file sits under the flags. */
    lc_config probe;
    memset(&probe, 0, sizeof probe);
    char *pos[1];
    if (lc_opt_parse(config_options, &probe, argc, argv, 1, pos, 0, err, errlen) < 0) return -1;
    if (probe.config_file[0] && config_apply_json(c, probe.config_file, err, errlen) != 0) return -1;
    if (lc_opt_parse(config_options, c, argc, argv, 1, pos, 0, err, errlen) < 0) return -1;
    /* A build without node has no viewer: the default folder is then simply absent. */
    if (!strcmp(c->www, config_default_www) && !config_is_dir(c->www)) c->www[0] = 0;
    return lc_config_validate(c, err, errlen);
}

int lc_config_has_token(const char *list, const char *token) {
    /* Constant time in the token's content: every element is compared over its whole length
     * and nothing returns early, so response timing does not reveal a matching prefix. */
    const size_t tl = strlen(token);
    unsigned found = 0;
    for (const char *p = list; *p;) {
        const char *comma = strchr(p, ',');
        size_t len = comma ? (size_t)(comma - p) : strlen(p);
        unsigned diff = len != tl || len == 0;
        for (size_t i = 0; i < len; i++) diff |= (unsigned char)p[i] ^ (unsigned char)(i < tl ? token[i] : 0);
        found |= diff == 0;
        if (!comma) break;
        p = comma + 1;
    }
    return (int)found;
}

void lc_config_apply_reloadable(lc_config *dst, const lc_config *src, char *restart_needed, size_t len) {
    size_t n = 0;
    restart_needed[0] = 0;
#define RESTART_IF(field, name)                                              \
    if (memcmp(&dst->field, &src->field, sizeof dst->field) != 0 && n < len) \
        n += (size_t)snprintf(restart_needed + n, len - n, "%s" name, n ? ", " : "");
    RESTART_IF(bake, "bake")
    RESTART_IF(listen, "listen")
    RESTART_IF(port, "port")
    RESTART_IF(state_dir, "state-dir")
    RESTART_IF(fsync_mode, "fsync")
    RESTART_IF(cluster, "cluster")
    RESTART_IF(cluster_timeout, "cluster-timeout")
    RESTART_IF(cluster_snapshot_every, "cluster-snapshot-every")
    RESTART_IF(www, "www")
    RESTART_IF(tls_cert, "tls-cert")
    RESTART_IF(tls_key, "tls-key")
    RESTART_IF(backend, "backend")
    RESTART_IF(threads, "threads")
    RESTART_IF(refine_passes, "refine-passes")
    RESTART_IF(refine_tolerance, "refine-tolerance")
    RESTART_IF(refine_delay, "refine-delay")
    RESTART_IF(bounces, "bounces")
    RESTART_IF(grid, "grid")
    RESTART_IF(max_lights, "max-lights")
    RESTART_IF(max_objects, "max-objects")
    RESTART_IF(tile, "tile")
    RESTART_IF(recover, "recover")
    RESTART_IF(clutter, "clutter")
    RESTART_IF(clutter_max_objects, "clutter-max-objects")
#undef RESTART_IF
    memcpy(dst->controller_tokens, src->controller_tokens, sizeof dst->controller_tokens);
    memcpy(dst->viewer_tokens, src->viewer_tokens, sizeof dst->viewer_tokens);
    memcpy(dst->origins, src->origins, sizeof dst->origins);
    dst->max_message = src->max_message;
    dst->max_depth = src->max_depth;
    dst->max_batch = src->max_batch;
    dst->max_clients = src->max_clients;
    dst->rate = src->rate;
    dst->hello_timeout = src->hello_timeout;
    dst->slow_timeout = src->slow_timeout;
    dst->keyframe_interval = src->keyframe_interval;
    dst->delta_threshold = src->delta_threshold;
    dst->compact_bytes = src->compact_bytes;
    dst->log_level = src->log_level;
    dst->clutter_rest = src->clutter_rest;
}

/* 1 when a token is a placeholder left from an example config ("CHANGE-ME", "<token>", ...). */
static int config_is_placeholder(const char *tok, size_t len) {
    char folded[LC_CONFIG_TOKENS_MAX];
    size_t n = 0, xs = 0;
    for (size_t i = 0; i < len; i++) {
        char ch = (char)tolower((unsigned char)tok[i]);
        if (ch == '<' || ch == '>' || ch == '{' || ch == '}') return 1;
        if (ch == '-' || ch == '_' || ch == ' ' || ch == '.') continue;
        xs += ch == 'x' || ch == '*';
        folded[n++] = ch;
    }
    folded[n] = 0;
    static const char *const words[] = {"changeme", "replaceme", "placeholder", "yourtoken", "yoursecret",
                                        "todo",     "fixme",     "example",     NULL};
    for (int i = 0; words[i]; i++)
        if (strstr(folded, words[i])) return 1;
    return n > 0 && xs == n; /* "xxxx" */
}

/* A comma-separated list: no empty element ("a,,b", ",x" or a trailing comma would be a token
 * that an absent token matches), no placeholder token (tokens = 1). */
static int config_check_list(const char *flag, const char *list, int tokens, char *err, size_t errlen) {
    if (!list[0]) return 0;
    int index = 0;
    for (const char *p = list;; index++) {
        const char *comma = strchr(p, ',');
        size_t len = comma ? (size_t)(comma - p) : strlen(p);
        if (len == 0) {
            lc_set_err(err, errlen, "--%s: element %d of the list is empty (remove the extra comma)", flag, index + 1);
            return -1;
        }
        if (tokens && config_is_placeholder(p, len)) {
            lc_set_err(err, errlen, "--%s: element %d ('%.*s') is a placeholder; set a real secret", flag, index + 1,
                       (int)(len > 40 ? 40 : len), p);
            return -1;
        }
        if (!comma) break;
        p = comma + 1;
    }
    return 0;
}

/* Loads the TLS certificate and key as the server will, so --check-config and start-up name
 * the file and the cause (missing file, not PEM, key not matching the certificate). */
static int config_check_tls(const lc_config *c, char *err, size_t errlen) {
    int rc = -1;
    X509 *cert = NULL;
    EVP_PKEY *key = NULL;
    FILE *f = fopen(c->tls_cert, "r");
    if (!f) {
        lc_set_err(err, errlen, "--tls-cert '%s': %s", c->tls_cert, strerror(errno));
        goto err;
    }
    cert = PEM_read_X509(f, NULL, NULL, NULL);
    fclose(f);
    if (!cert) {
        lc_set_err(err, errlen, "--tls-cert '%s': not a PEM certificate (expected -----BEGIN CERTIFICATE-----)",
                   c->tls_cert);
        goto err;
    }
    f = fopen(c->tls_key, "r");
    if (!f) {
        lc_set_err(err, errlen, "--tls-key '%s': %s", c->tls_key, strerror(errno));
        goto err;
    }
    key = PEM_read_PrivateKey(f, NULL, NULL, NULL);
    fclose(f);
    if (!key) {
        lc_set_err(err, errlen, "--tls-key '%s': not a PEM private key (or it needs a passphrase)", c->tls_key);
        goto err;
    }
    if (X509_check_private_key(cert, key) != 1) {
        lc_set_err(err, errlen, "--tls-key '%s' does not match the certificate --tls-cert '%s'", c->tls_key,
                   c->tls_cert);
        goto err;
    }
    rc = 0;
err:
    ERR_clear_error();
    X509_free(cert);
    EVP_PKEY_free(key);
    return rc;
}

int lc_config_validate(const lc_config *c, char *err, size_t errlen) {
    if (!c->tls_cert[0] != !c->tls_key[0]) {
        lc_set_err(err, errlen, "--tls-cert and --tls-key go together (give both or neither)");
        return -1;
    }
    if (c->tls_cert[0] && config_check_tls(c, err, errlen) != 0) return -1;
    if (c->www[0] && !config_is_dir(c->www)) {
        lc_set_err(err, errlen, "--www %s: not a directory (give the folder of the pages to serve, or \"\" for none)",
                   c->www);
        return -1;
    }
    if (c->tile > 0 && c->tile < 8) {
        lc_set_err(err, errlen, "--tile %d: give 0 (automatic) or at least 8 texels", c->tile);
        return -1;
    }
    if (c->cluster[0]) {
        lc_cluster_url u;
        char why[400];
        if (lc_cluster_parse_url(c->cluster, strlen(c->cluster), &u, why, sizeof why) != 0) {
            lc_set_err(err, errlen, "--%s", why);
            return -1;
        }
        if (u.password[0] && config_is_placeholder(u.password, strlen(u.password))) {
            lc_set_err(err, errlen, "--cluster: the Redis password is a placeholder; set the real one");
            return -1;
        }
    }
    if (config_check_list("controller-tokens", c->controller_tokens, 1, err, errlen) != 0 ||
        config_check_list("viewer-tokens", c->viewer_tokens, 1, err, errlen) != 0 ||
        config_check_list("origins", c->origins, 0, err, errlen) != 0)
        return -1;
    /* A token in both lists would make the role ambiguous. */
    for (const char *p = c->viewer_tokens; *p;) {
        const char *comma = strchr(p, ',');
        char tok[LC_CONFIG_TOKENS_MAX];
        size_t len = comma ? (size_t)(comma - p) : strlen(p);
        memcpy(tok, p, len);
        tok[len] = 0;
        if (lc_config_has_token(c->controller_tokens, tok)) {
            lc_set_err(err, errlen, "--viewer-tokens: token '%s' is also a controller token", tok);
            return -1;
        }
        if (!comma) break;
        p = comma + 1;
    }
    if (c->viewer_tokens[0] && !c->controller_tokens[0]) {
        lc_set_err(err, errlen, "--viewer-tokens without --controller-tokens would let anyone control; set both");
        return -1;
    }
    return 0;
}
