/* server_geometry: the geometry the lightmap belongs to, over HTTP — GET /scene.glb and
 * GET /assets/NAME.glb, binary glTF built once from the loaded bake (lc_lcb_scene_glb,
 * lc_lcb_asset_glb), so what a client renders is exactly what was baked. Built on the main
 * thread before the service loop starts; served on the service thread; immutable between. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lcb/lcb_glb.h"
#include "server_internal.h"
#include "util/log.h"

#define GEOMETRY_CHUNK 65536 /* bytes written per writeable callback */

/* "/assets/" + NAME percent-encoded (every byte outside [A-Za-z0-9._-]) + ".glb". */
static void geometry_asset_path(const char *name, char *out, size_t cap) {
    static const char hex[] = "0123456789ABCDEF";
    size_t n = (size_t)snprintf(out, cap, "/assets/");
    for (const unsigned char *p = (const unsigned char *)name; *p && n + 8 < cap; p++) {
        int plain = (*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z') || (*p >= '0' && *p <= '9') || *p == '.' ||
            *p == '_' || *p == '-';
        if (plain) {
            out[n++] = (char)*p;
        } else {
            out[n++] = '%';
            out[n++] = hex[*p >> 4];
            out[n++] = hex[*p & 15];
        }
    }
    snprintf(out + n, cap - n, ".glb");
}

int server_geometry_build(lc_server *s) {
    char err[256];
    lc_lcb_bake_id(s->bake, s->bake_id);
    s->n_glbs = 1 + s->v->n_assets;
    s->glbs = calloc(s->n_glbs, sizeof *s->glbs);
    s->asset_paths = calloc(s->v->n_assets + 1, sizeof *s->asset_paths);
    if (!s->glbs || !s->asset_paths) {
        lc_error("server", "out of memory building the scene's glTF");
        return -1;
    }
    snprintf(s->glbs[0].path, sizeof s->glbs[0].path, "/scene.glb");
    if (lc_lcb_scene_glb(s->bake, &s->glbs[0].data, &s->glbs[0].len, err, sizeof err) != 0) {
        lc_error("server", "cannot build /scene.glb from the bake: %s", err);
        return -1;
    }
    for (uint32_t a = 0; a < s->v->n_assets; a++) {
        server_glb *g = &s->glbs[1 + a];
        geometry_asset_path(s->v->assets[a].name, g->path, sizeof g->path);
        s->asset_paths[a] = g->path;
        if (lc_lcb_asset_glb(s->bake, a, &g->data, &g->len, err, sizeof err) != 0) {
            lc_error("server", "cannot build %s from the bake: %s", g->path, err);
            return -1;
        }
    }
    return 0;
}

void server_geometry_release(lc_server *s) {
    for (uint32_t i = 0; s->glbs && i < s->n_glbs; i++) free(s->glbs[i].data);
    free(s->glbs);
    free(s->asset_paths);
    s->glbs = NULL;
    s->asset_paths = NULL;
    s->n_glbs = 0;
}

const server_glb *server_geometry_find(const lc_server *s, const char *uri) {
    for (uint32_t i = 0; i < s->n_glbs; i++)
        if (!strcmp(uri, s->glbs[i].path)) return &s->glbs[i];
    /* lws may hand the path over percent-decoded: match the asset's own name too */
    if (!strncmp(uri, "/assets/", 8))
        for (uint32_t a = 0; a < s->v->n_assets; a++) {
            const char *name = s->v->assets[a].name;
            size_t n = strlen(name);
            if (!strncmp(uri + 8, name, n) && !strcmp(uri + 8 + n, ".glb")) return &s->glbs[1 + a];
        }
    return NULL;
}

/* Service thread: headers of a GET for g; the body follows in server_geometry_write. */
int server_geometry_start(lc_server *s, struct lws *wsi, server_http_tx *tx, const server_glb *g) {
    unsigned char buf[LWS_PRE + 1024], *start = buf + LWS_PRE, *p = start, *end = buf + sizeof buf;
    char etag[48];
    snprintf(etag, sizeof etag, "\"%s\"", s->bake_id);
    if (lws_add_http_common_headers(wsi, HTTP_STATUS_OK, "model/gltf-binary", (lws_filepos_t)g->len, &p, end) ||
        lws_add_http_header_by_name(wsi, (const unsigned char *)"etag:", (const unsigned char *)etag, (int)strlen(etag),
                                    &p, end) ||
        lws_add_http_header_by_name(wsi, (const unsigned char *)"cache-control:", (const unsigned char *)"no-cache", 8,
                                    &p, end) ||
        lws_finalize_write_http_header(wsi, start, &p, end))
        return 1;
    tx->data = g->data;
    tx->len = g->len;
    tx->sent = 0;
    lws_callback_on_writable(wsi);
    return 0;
}

/* Service thread: the next chunk of the body; -1 closes (lws), 0 goes on. */
int server_geometry_write(struct lws *wsi, server_http_tx *tx) {
    static unsigned char chunk[LWS_PRE + GEOMETRY_CHUNK]; /* service thread only */
    if (!tx->data) return 0;
    size_t n = tx->len - tx->sent < GEOMETRY_CHUNK ? tx->len - tx->sent : GEOMETRY_CHUNK;
    int last = tx->sent + n == tx->len;
    memcpy(chunk + LWS_PRE, tx->data + tx->sent, n);
    if (lws_write(wsi, chunk + LWS_PRE, n, last ? LWS_WRITE_HTTP_FINAL : LWS_WRITE_HTTP) != (int)n) return -1;
    tx->sent += n;
    if (!last) {
        lws_callback_on_writable(wsi);
        return 0;
    }
    tx->data = NULL;
    return lws_http_transaction_completed(wsi) ? -1 : 0;
}
