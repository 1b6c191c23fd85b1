/* liblucent-client: blocking lucent/1 client over libwebsockets. All lws calls happen on the
 * caller's thread, inside the blocking calls, which run the service loop until their condition or
 * deadline. A 20 ms sul tick bounds each lws_service() wait. */
#include "lucent_client.h"

#include <cjson/cJSON.h>
#include <libwebsockets.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define LC_CLIENT_TICK_US (20 * LWS_US_PER_MS)

typedef struct lc_msg {
    struct lc_msg *next;
    char *text;
} lc_msg;

enum { ST_CONNECTING = 0, ST_OPEN = 1, ST_CLOSED = 2 };

struct lc_client {
    struct lws_context *ctx;
    struct lws *wsi;
    lws_sorted_usec_list_t tick;
    int state;
    char cerr[256]; /* connection error / close reason */
    /* one outgoing message at a time (blocking API) */
    unsigned char *tx; /* LWS_PRE + txlen */
    size_t txlen;
    int tx_pending;
    /* reassembly of the current incoming message */
    char *rx;
    size_t rxlen, rxcap;
    int rx_binary, rx_overflow;
    /* completed text messages, FIFO */
    lc_msg *head, *tail;
    unsigned long binary_frames;
    char *welcome;
    long long next_id;
    char host[256];
    char path[512];
    char origin[300];
    int port;
};

static void set_err(char *err, size_t errlen, const char *fmt, ...) {
    if (!err || !errlen) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, errlen, fmt, ap);
    va_end(ap);
}

static long long now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

static void tick_cb(lws_sorted_usec_list_t *sul) {
    lc_client *c = lws_container_of(sul, lc_client, tick);
    lws_sul_schedule(c->ctx, 0, &c->tick, tick_cb, LC_CLIENT_TICK_US);
}

static void push_msg(lc_client *c, char *text) {
    lc_msg *m = malloc(sizeof *m);
    if (!m) {
        free(text);
        return;
    }
    m->next = NULL;
    m->text = text;
    if (c->tail) c->tail->next = m;
    else c->head = m;
    c->tail = m;
}

static char *pop_msg(lc_client *c) {
    lc_msg *m = c->head;
    if (!m) return NULL;
    c->head = m->next;
    if (!c->head) c->tail = NULL;
    char *t = m->text;
    free(m);
    return t;
}

static int callback(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len) {
    (void)user;
    struct lws_context *ctx = lws_get_context(wsi);
    lc_client *c = ctx ? lws_context_user(ctx) : NULL;
    if (!c) return lws_callback_http_dummy(wsi, reason, user, in, len);
    switch (reason) {
    case LWS_CALLBACK_CLIENT_CONNECTION_ERROR:
        snprintf(c->cerr, sizeof c->cerr, "connection failed: %s", in ? (const char *)in : "(unknown)");
        c->state = ST_CLOSED;
        c->wsi = NULL;
        break;
    case LWS_CALLBACK_CLIENT_ESTABLISHED:
        c->state = ST_OPEN;
        if (c->tx_pending) lws_callback_on_writable(wsi);
        break;
    case LWS_CALLBACK_CLIENT_WRITEABLE:
        if (c->tx_pending && c->state == ST_OPEN) {
            int n = lws_write(wsi, c->tx + LWS_PRE, c->txlen, LWS_WRITE_TEXT);
            c->tx_pending = 0;
            if (n < (int)c->txlen) {
                snprintf(c->cerr, sizeof c->cerr, "write failed");
                return -1;
            }
        }
        break;
    case LWS_CALLBACK_CLIENT_RECEIVE:
        if (lws_is_first_fragment(wsi)) {
            c->rxlen = 0;
            c->rx_overflow = 0;
            c->rx_binary = lws_frame_is_binary(wsi);
        }
        if (!c->rx_binary && !c->rx_overflow) {
            if (c->rxlen + len + 1 > c->rxcap) {
                size_t cap = c->rxcap ? c->rxcap : 4096;
                while (cap < c->rxlen + len + 1) cap *= 2;
                if (cap > (64u << 20)) {
                    c->rx_overflow = 1;
                } else {
                    char *r = realloc(c->rx, cap);
                    if (!r) c->rx_overflow = 1;
                    else {
                        c->rx = r;
                        c->rxcap = cap;
                    }
                }
            }
            if (!c->rx_overflow) {
                memcpy(c->rx + c->rxlen, in, len);
                c->rxlen += len;
            }
        }
        if (lws_is_final_fragment(wsi)) {
            if (c->rx_binary) c->binary_frames++;
            else if (!c->rx_overflow) {
                char *t = malloc(c->rxlen + 1);
                if (t) {
                    memcpy(t, c->rx, c->rxlen);
                    t[c->rxlen] = 0;
                    push_msg(c, t);
                }
            }
            c->rxlen = 0;
        }
        break;
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE:
        if (in && len >= 2) {
            const unsigned char *p = in;
            snprintf(c->cerr, sizeof c->cerr, "server closed the connection (%d%s%.*s)", (p[0] << 8) | p[1],
                     len > 2 ? ": " : "", (int)(len - 2), (const char *)p + 2);
        } else
            snprintf(c->cerr, sizeof c->cerr, "server closed the connection");
        break;
    case LWS_CALLBACK_CLIENT_CLOSED:
        if (!c->cerr[0]) snprintf(c->cerr, sizeof c->cerr, "connection closed");
        c->state = ST_CLOSED;
        c->wsi = NULL;
        break;
    default:
        break;
    }
    return lws_callback_http_dummy(wsi, reason, user, in, len);
}

static const struct lws_protocols protocols[] = {
    {"lucent.v1", callback, 0, 65536, 0, NULL, 0},
    {NULL, NULL, 0, 0, 0, NULL, 0},
};

/* Runs the service loop until *flag differs from `until_not`-style predicate via callback. */
static int service_until(lc_client *c, int (*done)(lc_client *, void *), void *arg, long long deadline) {
    while (!done(c, arg)) {
        if (now_ms() >= deadline) return -1;
        if (lws_service(c->ctx, 0) < 0) return -2;
    }
    return 0;
}

static int queue_text(lc_client *c, const char *text, size_t n) {
    unsigned char *b = realloc(c->tx, LWS_PRE + n + 1);
    if (!b) return -1;
    c->tx = b;
    memcpy(b + LWS_PRE, text, n);
    c->txlen = n;
    c->tx_pending = 1;
    if (c->wsi && c->state == ST_OPEN) lws_callback_on_writable(c->wsi);
    return 0;
}

static int parse_url(lc_client *c, const char *url, char *err, size_t errlen) {
    const char *p = url;
    if (strncmp(p, "ws://", 5) == 0) p += 5;
    else {
        set_err(err, errlen, "unsupported URL '%s' (expected ws://host:port/)", url);
        return -1;
    }
    const char *hend = p;
    if (*hend == '[') { /* [v6]:port */
        while (*hend && *hend != ']') hend++;
        if (*hend) hend++;
    } else
        while (*hend && *hend != ':' && *hend != '/') hend++;
    size_t hl = (size_t)(hend - p);
    if (hl == 0 || hl >= sizeof c->host) {
        set_err(err, errlen, "bad host in URL '%s'", url);
        return -1;
    }
    memcpy(c->host, p, hl);
    c->host[hl] = 0;
    c->port = 80;
    p = hend;
    if (*p == ':') {
        char *e;
        long port = strtol(p + 1, &e, 10);
        if (e == p + 1 || port <= 0 || port > 65535) {
            set_err(err, errlen, "bad port in URL '%s'", url);
            return -1;
        }
        c->port = (int)port;
        p = e;
    }
    if (*p && *p != '/') {
        set_err(err, errlen, "bad URL '%s'", url);
        return -1;
    }
    snprintf(c->path, sizeof c->path, "%s", *p ? p : "/");
    snprintf(c->origin, sizeof c->origin, "%s:%d", c->host, c->port);
    return 0;
}

static int have_msg_or_closed(lc_client *c, void *arg) {
    (void)arg;
    return c->head != NULL || c->state == ST_CLOSED;
}

/* Waits for the next text message; returns it (malloc'd) or NULL on close/timeout. */
static char *next_message(lc_client *c, long long deadline, char *err, size_t errlen) {
    char *m = pop_msg(c);
    if (m) return m;
    int r = service_until(c, have_msg_or_closed, NULL, deadline);
    m = pop_msg(c);
    if (m) return m;
    if (r == -1) set_err(err, errlen, "timed out waiting for the server");
    else set_err(err, errlen, "%s", c->cerr[0] ? c->cerr : "connection lost");
    return NULL;
}

static const char *msg_type(const cJSON *o) {
    const cJSON *t = cJSON_GetObjectItemCaseSensitive(o, "type");
    return cJSON_IsString(t) ? t->valuestring : "";
}

lc_client *lc_client_connect(const char *url, const char *token, const char *name, int timeout_ms, char *err,
                             size_t errlen) {
    lc_client *c = calloc(1, sizeof *c);
    if (!c) {
        set_err(err, errlen, "out of memory");
        return NULL;
    }
    if (parse_url(c, url, err, errlen) != 0) {
        free(c);
        return NULL;
    }
    lws_set_log_level(LLL_ERR, NULL);
    lws_set_log_level(0, NULL);
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = CONTEXT_PORT_NO_LISTEN;
    info.protocols = protocols;
    info.user = c;
    info.timeout_secs = (unsigned)(timeout_ms > 1000 ? (timeout_ms + 999) / 1000 : 1);
    info.gid = -1;
    info.uid = -1;
    c->ctx = lws_create_context(&info);
    if (!c->ctx) {
        set_err(err, errlen, "cannot create the lws context");
        free(c);
        return NULL;
    }
    lws_sul_schedule(c->ctx, 0, &c->tick, tick_cb, LC_CLIENT_TICK_US);
    c->next_id = 1;

    /* hello, queued before the connection so ESTABLISHED asks for WRITEABLE */
    cJSON *h = cJSON_CreateObject();
    cJSON_AddStringToObject(h, "type", "hello");
    cJSON_AddNumberToObject(h, "id", (double)c->next_id++);
    cJSON_AddStringToObject(h, "client", name && *name ? name : "liblucent-client");
    cJSON_AddStringToObject(h, "token", token ? token : "");
    char *ht = cJSON_PrintUnformatted(h);
    cJSON_Delete(h);
    if (!ht || queue_text(c, ht, strlen(ht)) != 0) {
        free(ht);
        set_err(err, errlen, "out of memory");
        lc_client_close(c);
        return NULL;
    }
    free(ht);

    struct lws_client_connect_info ci;
    memset(&ci, 0, sizeof ci);
    ci.context = c->ctx;
    ci.address = c->host;
    ci.port = c->port;
    ci.path = c->path;
    ci.host = c->origin;
    ci.origin = c->origin;
    ci.protocol = "lucent.v1";
    ci.pwsi = &c->wsi;
    long long deadline = now_ms() + (timeout_ms > 0 ? timeout_ms : 5000);
    if (!lws_client_connect_via_info(&ci) && !c->cerr[0]) {
        set_err(err, errlen, "cannot connect to %s", url);
        lc_client_close(c);
        return NULL;
    }
    for (;;) {
        char e2[256];
        char *m = next_message(c, deadline, e2, sizeof e2);
        if (!m) {
            set_err(err, errlen, "%s: %s", url, e2);
            lc_client_close(c);
            return NULL;
        }
        cJSON *o = cJSON_Parse(m);
        const char *t = o ? msg_type(o) : "";
        if (strcmp(t, "welcome") == 0) {
            cJSON_Delete(o);
            c->welcome = m;
            return c;
        }
        if (strcmp(t, "error") == 0) {
            const cJSON *code = cJSON_GetObjectItemCaseSensitive(o, "code");
            const cJSON *msg = cJSON_GetObjectItemCaseSensitive(o, "message");
            set_err(err, errlen, "server error %s: %s", cJSON_IsString(code) ? code->valuestring : "?",
                    cJSON_IsString(msg) ? msg->valuestring : "");
            cJSON_Delete(o);
            free(m);
            lc_client_close(c);
            return NULL;
        }
        cJSON_Delete(o);
        free(m);
    }
}

static int ids_equal(const cJSON *a, const cJSON *b) {
    if (!a || !b) return 0;
    if (cJSON_IsNumber(a) && cJSON_IsNumber(b)) return a->valuedouble == b->valuedouble;
    if (cJSON_IsString(a) && cJSON_IsString(b)) return strcmp(a->valuestring, b->valuestring) == 0;
    return 0;
}

int lc_client_request(lc_client *c, const char *json_request, char **reply_json, int timeout_ms, char *err,
                      size_t errlen) {
    if (reply_json) *reply_json = NULL;
    if (!c || !json_request) {
        set_err(err, errlen, "bad arguments");
        return -1;
    }
    if (c->state != ST_OPEN) {
        set_err(err, errlen, "%s", c->cerr[0] ? c->cerr : "not connected");
        return -1;
    }
    cJSON *req = cJSON_Parse(json_request);
    cJSON *want = NULL; /* the id to match; NULL = take the next reply */
    char *text = NULL;
    if (cJSON_IsObject(req)) {
        cJSON *id = cJSON_GetObjectItemCaseSensitive(req, "id");
        if (!id) {
            id = cJSON_AddNumberToObject(req, "id", (double)c->next_id++);
            text = cJSON_PrintUnformatted(req);
        }
        want = cJSON_Duplicate(id, 0);
    }
    cJSON_Delete(req);
    const char *send = text ? text : json_request;
    if (queue_text(c, send, strlen(send)) != 0) {
        free(text);
        cJSON_Delete(want);
        set_err(err, errlen, "out of memory");
        return -1;
    }
    free(text);
    long long deadline = now_ms() + (timeout_ms > 0 ? timeout_ms : 5000);
    for (;;) {
        char *m = next_message(c, deadline, err, errlen);
        if (!m) {
            cJSON_Delete(want);
            return -1;
        }
        cJSON *o = cJSON_Parse(m);
        const char *t = o ? msg_type(o) : "";
        const cJSON *id = o ? cJSON_GetObjectItemCaseSensitive(o, "id") : NULL;
        int is_error = strcmp(t, "error") == 0;
        int is_reply = is_error || !strcmp(t, "ok") || !strcmp(t, "state") || !strcmp(t, "pong");
        /* a matching id, or any reply when we have none to match, or an error without an id
         * (the server could not read ours, e.g. bad_json) */
        int match = is_reply && (want ? (ids_equal(id, want) || (is_error && !id)) : 1);
        cJSON_Delete(o);
        if (match) {
            cJSON_Delete(want);
            if (reply_json) *reply_json = m;
            else free(m);
            if (is_error) set_err(err, errlen, "server error");
            return is_error ? 1 : 0;
        }
        free(m); /* changed broadcasts, stale replies */
    }
}

const char *lc_client_welcome(const lc_client *c) { return c ? c->welcome : NULL; }

unsigned long lc_client_binary_frames(const lc_client *c) { return c ? c->binary_frames : 0; }

void lc_client_close(lc_client *c) {
    if (!c) return;
    if (c->ctx) {
        lws_sul_cancel(&c->tick);
        lws_context_destroy(c->ctx); /* closes the connection */
    }
    char *m;
    while ((m = pop_msg(c))) free(m);
    free(c->tx);
    free(c->rx);
    free(c->welcome);
    free(c);
}
