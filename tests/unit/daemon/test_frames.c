/* lucentd's frame encoding (server_frames) on fake publications, without a socket: a first
 * lightmap frame is a keyframe that decodes to the publication within the encoding's
 * precision; a change in one tile gives a delta of exactly that tile; a change under the
 * threshold gives an empty delta; every keyframe_interval-th frame is a keyframe; residual
 * deltas applied to the client's words reproduce the new keyframe exactly, and two clients
 * in the same state get the same bytes (the shared memo); the dirty test's floor follows the
 * brightest channel of each publication (NaN ignored); whole-tile deltas are shared by clients
 * holding the same copy and not by one whose copy differs; SH grid and object frames carry
 * the floats. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "server_frames.h"

enum { W = 16, H = 16 };

static lc_published fake_publication(float base) {
    lc_published p;
    memset(&p, 0, sizeof p);
    p.refs = 1;
    p.revision = 1;
    p.lm_w = W;
    p.lm_h = H;
    p.lightmap = malloc(sizeof(float) * 3 * W * H);
    for (int i = 0; i < W * H; i++)
        for (int c = 0; c < 3; c++) p.lightmap[3 * i + c] = base + 0.01f * (float)i + 0.1f * (float)c;
    p.grid_dims[0] = 2;
    p.grid_dims[1] = p.grid_dims[2] = 1;
    p.grid_sh = malloc(sizeof(float) * 27 * 2);
    for (int i = 0; i < 54; i++) p.grid_sh[i] = 0.25f * (float)i;
    return p;
}

static lc_frames_job lightmap_job(const lc_published *p, uint64_t pub_seq, uint64_t sequence, lc_encoding enc,
                                  int residual) {
    lc_frames_job j = {.frame = p,
                       .pub_seq = pub_seq,
                       .stream = LC_STREAM_LIGHTMAP,
                       .enc = enc,
                       .residual = residual,
                       .sequence = sequence,
                       .tile = lc_frames_tile_size(0, W, H),
                       .keyframe_interval = 30,
                       .delta_threshold = 0.01,
                       .pre = 16};
    return j;
}

/* Parses the frame the copy holds; returns its payload (NULL on a bad frame). */
static const uint8_t *parse(const lc_frames_copy *cp, size_t n, size_t pre, lc_frame_header *h, const uint8_t **tiles) {
    const uint8_t *payload = NULL;
    lc_proto_error e;
    if (lc_frame_parse(cp->out + pre, n, h, tiles, &payload, &e) != 0) {
        fprintf(stderr, "frame: %s %s\n", e.code, e.message);
        return NULL;
    }
    return payload;
}

int main(void) {
    CHECK(lc_frames_tile_size(0, 64, 64) == 8 && lc_frames_tile_size(0, 512, 512) == 32 &&
              lc_frames_tile_size(16, 64, 64) == 16,
          "tile size: automatic gives >= 64 tiles, explicit wins");
    lc_frames *f = lc_frames_create();
    lc_published p1 = fake_publication(1.0f);
    lc_frames_copy a, b;
    memset(&a, 0, sizeof a);
    memset(&b, 0, sizeof b);
    lc_frame_header h;
    const uint8_t *tiles;

    /* 1. the first frame is a keyframe that decodes to the publication (RGB9E5: 9 bits of mantissa) */
    lc_frames_job j = lightmap_job(&p1, 1, 1, LC_ENC_RGB9E5, 0);
    size_t n = lc_frames_encode(f, &a, &j);
    const uint8_t *pl = parse(&a, n, j.pre, &h, &tiles);
    CHECK(pl && (h.flags & LC_FRAME_KEYFRAME) && h.width == W && h.height == H && h.sequence == 1 &&
              h.payload_length == 4 * W * H,
          "keyframe header");
    double worst = 0;
    for (int i = 0; pl && i < W * H; i++) {
        uint32_t v;
        memcpy(&v, pl + 4 * i, 4);
        float rgb[3];
        lc_rgb9e5_decode(v, rgb);
        for (int c = 0; c < 3; c++) worst = fmax(worst, fabs(rgb[c] - p1.lightmap[3 * i + c]) / p1.lightmap[3 * i + c]);
    }
    CHECK(worst < 1.0 / 256, "keyframe decodes within RGB9E5's precision (worst %.2e)", worst);

    /* 2. one texel moves by 5% in tile (1,1) -> a delta of that tile only, f32 payload exact */
    lc_frames_copy c;
    memset(&c, 0, sizeof c);
    j = lightmap_job(&p1, 1, 1, LC_ENC_F32, 0);
    n = lc_frames_encode(f, &c, &j);
    lc_published p2 = fake_publication(1.0f);
    p2.revision = 2;
    const uint32_t tile = lc_frames_tile_size(0, W, H), moved = (tile + 1) * W + tile + 1;
    p2.lightmap[3 * moved] *= 1.05f;
    j = lightmap_job(&p2, 2, 2, LC_ENC_F32, 0);
    n = lc_frames_encode(f, &c, &j);
    pl = parse(&c, n, j.pre, &h, &tiles);
    uint32_t t0 = 0;
    if (pl && h.tile_count) memcpy(&t0, tiles, 4);
    const uint32_t tiles_per_row = (W + tile - 1) / tile;
    CHECK(pl && (h.flags & LC_FRAME_DELTA) && h.tile_count == 1 && t0 == tiles_per_row + 1 &&
              h.payload_length == 12 * tile * tile,
          "a 5%% change in one tile gives a delta of that tile (tiles %u, first %u)", h.tile_count, t0);
    if (pl) {
        float got[3];
        uint32_t row = moved / W - tile, col = moved % W - tile; /* inside the tile */
        memcpy(got, pl + 12 * (row * tile + col), 12);
        CHECK(got[0] == p2.lightmap[3 * moved], "the delta carries the new value");
    }
    /* 3. a 0.5% change (under the 1% threshold) -> an empty delta */
    lc_published p3 = fake_publication(1.0f);
    p3.lightmap[3 * moved] = p2.lightmap[3 * moved] * 1.005f;
    j = lightmap_job(&p3, 3, 3, LC_ENC_F32, 0);
    n = lc_frames_encode(f, &c, &j);
    pl = parse(&c, n, j.pre, &h, &tiles);
    CHECK(pl && (h.flags & LC_FRAME_DELTA) && h.tile_count == 0, "a change under the threshold sends no tile");
    /* 4. keyframe_interval: frame 31 is a keyframe */
    j = lightmap_job(&p3, 3, 31, LC_ENC_F32, 0);
    n = lc_frames_encode(f, &c, &j);
    pl = parse(&c, n, j.pre, &h, &tiles);
    CHECK(pl && (h.flags & LC_FRAME_KEYFRAME), "every keyframe_interval-th frame is a keyframe");

    /* 5. residual deltas: two clients in the same state get identical bytes; applied to the
     * client's words they give exactly the words of a keyframe of the new publication. */
    lc_frames_copy r1, r2, key;
    memset(&r1, 0, sizeof r1);
    memset(&r2, 0, sizeof r2);
    memset(&key, 0, sizeof key);
    j = lightmap_job(&p1, 1, 1, LC_ENC_RGB9E5, 1);
    size_t n1 = lc_frames_encode(f, &r1, &j), n2 = lc_frames_encode(f, &r2, &j);
    uint8_t held[4 * W * H];
    pl = parse(&r1, n1, j.pre, &h, &tiles);
    if (pl) memcpy(held, pl, sizeof held);
    CHECK(n1 == n2, "two clients' keyframes have the same length");
    j = lightmap_job(&p2, 2, 2, LC_ENC_RGB9E5, 1);
    /* The server writes cheap frames before residual deltas it must deflate (server.c). */
    CHECK(lc_frames_would_deflate(f, &r1, &j) && lc_frames_would_deflate(f, &r2, &j),
          "a residual delta not computed yet for this state and publication would deflate");
    n1 = lc_frames_encode(f, &r1, &j);
    CHECK(!lc_frames_would_deflate(f, &r2, &j), "a client in the state another's residual delta left reuses it");
    n2 = lc_frames_encode(f, &r2, &j);
    CHECK(n1 == n2 && n1 > 0 && !memcmp(r1.out + j.pre, r2.out + j.pre, n1),
          "clients holding the same copy get the same residual delta");
    {
        lc_frames_job whole = lightmap_job(&p2, 2, 2, LC_ENC_RGB9E5, 0), forced = j, due = j;
        forced.force_key = 1;
        due.sequence = 1 + (uint64_t)j.keyframe_interval; /* the interval's keyframe */
        lc_frames_job later = lightmap_job(&p1, 3, 3, LC_ENC_RGB9E5, 1);
        CHECK(!lc_frames_would_deflate(f, &r1, &whole) && !lc_frames_would_deflate(f, &r1, &forced) &&
                  !lc_frames_would_deflate(f, &r1, &due) && lc_frames_would_deflate(f, &r1, &later),
              "whole-tile deltas and keyframes never deflate; the next publication's residual does");
    }
    pl = parse(&r1, n1, j.pre, &h, &tiles);
    CHECK(pl && (h.flags & LC_FRAME_RESIDUAL) && h.tile_count == 1, "a residual delta of one tile");
    if (pl && (h.flags & LC_FRAME_RESIDUAL)) {
        size_t texels = lc_frame_tile_texels(&h, tiles);
        uint8_t *res = malloc(4 * texels), *tile_words = malloc(4 * texels);
        CHECK(lc_residual_inflate(pl, h.payload_length, res, 4 * texels) == 0, "the residual inflates");
        /* gather the client's words of the tile, apply, scatter back */
        uint32_t tix;
        memcpy(&tix, tiles, 4);
        uint32_t x0, y0, x1, y1;
        lc_tile_rect(W, H, h.tile_size, tix, &x0, &y0, &x1, &y1);
        size_t k = 0;
        for (uint32_t y = y0; y < y1; y++)
            for (uint32_t x = x0; x < x1; x++, k++) memcpy(tile_words + 4 * k, held + 4 * (y * W + x), 4);
        lc_residual_apply(LC_ENC_RGB9E5, tile_words, res, texels);
        k = 0;
        for (uint32_t y = y0; y < y1; y++)
            for (uint32_t x = x0; x < x1; x++, k++) memcpy(held + 4 * (y * W + x), tile_words + 4 * k, 4);
        free(res);
        free(tile_words);
        j = lightmap_job(&p2, 2, 1, LC_ENC_RGB9E5, 0);
        n = lc_frames_encode(f, &key, &j);
        const uint8_t *kp = parse(&key, n, j.pre, &h, &tiles);
        CHECK(kp && !memcmp(kp, held, sizeof held), "keyframe + residual delta == a keyframe of the new publication");
    }

    /* 6. the dirty test's floor (1e-3 of the publication's brightest channel, NaN ignored) is
     * the floor of the publication being sent: a 0.001 -> 0.002 texel next to a 1000 peak is
     * not sent; the same change in the next publication, whose peak is 3.74, is (one tile). */
    const int dim = W * H - 1; /* the last tile */
    lc_published pa = fake_publication(1.0f), pb = fake_publication(1.0f), qa = fake_publication(1.0f),
                 qb = fake_publication(1.0f);
    lc_published *dimmed[] = {&pa, &pb, &qa, &qb};
    for (int k = 0; k < 4; k++)
        for (int ch = 0; ch < 3; ch++) dimmed[k]->lightmap[3 * dim + ch] = k % 2 ? 0.002f : 0.001f;
    for (int k = 0; k < 2; k++) {
        for (int ch = 0; ch < 3; ch++) dimmed[k]->lightmap[ch] = 1000.0f;
        dimmed[k]->lightmap[3] = NAN;
    }
    lc_frames_copy x, y;
    memset(&x, 0, sizeof x);
    memset(&y, 0, sizeof y);
    j = lightmap_job(&pa, 10, 1, LC_ENC_F32, 0);
    n = lc_frames_encode(f, &x, &j);
    j = lightmap_job(&qa, 20, 1, LC_ENC_F32, 0);
    n = lc_frames_encode(f, &y, &j);
    j = lightmap_job(&pb, 11, 2, LC_ENC_F32, 0);
    n = lc_frames_encode(f, &x, &j);
    pl = parse(&x, n, j.pre, &h, &tiles);
    CHECK(pl && (h.flags & LC_FRAME_DELTA) && h.tile_count == 0,
          "a change under 1e-3 of a 1000 peak (a NaN texel beside it) sends no tile (tiles %u)", pl ? h.tile_count : 0);
    j = lightmap_job(&qb, 21, 2, LC_ENC_F32, 0);
    n = lc_frames_encode(f, &y, &j);
    pl = parse(&y, n, j.pre, &h, &tiles);
    t0 = 0;
    if (pl && h.tile_count) memcpy(&t0, tiles, 4);
    CHECK(pl && (h.flags & LC_FRAME_DELTA) && h.tile_count == 1 && t0 == (W / tile) * (H / tile) - 1,
          "the same change under the next publication's own peak (3.74) sends its tile (tiles %u, first %u)",
          pl ? h.tile_count : 0, t0);
    lc_frames_copy_release(&x);
    lc_frames_copy_release(&y);
    for (int k = 0; k < 4; k++) {
        free(dimmed[k]->lightmap);
        free(dimmed[k]->grid_sh);
    }

    /* 6b. whole-tile deltas: clients u and v saw publication 30 only, w also 31 (tile 0
     * changed); 32 reverts tile 0 and changes the last tile. u and v get one shared delta (the
     * same bytes: the memo), w its own with both tiles; every frame passes its CRC. */
    {
        lc_published q30 = fake_publication(1.0f), q31 = fake_publication(1.0f), q32 = fake_publication(1.0f);
        const int last = W * H - 1;
        for (int ch = 0; ch < 3; ch++) {
            q31.lightmap[ch] *= 2.0f;
            q32.lightmap[3 * last + ch] *= 2.0f;
        }
        lc_frames_copy u, v, w;
        memset(&u, 0, sizeof u);
        memset(&v, 0, sizeof v);
        memset(&w, 0, sizeof w);
        lc_frames_copy *all[3] = {&u, &v, &w};
        for (int k = 0; k < 3; k++) {
            j = lightmap_job(&q30, 30, 1, LC_ENC_RGB9E5, 0);
            lc_frames_encode(f, all[k], &j);
        }
        j = lightmap_job(&q31, 31, 2, LC_ENC_RGB9E5, 0);
        n = lc_frames_encode(f, &w, &j);
        pl = parse(&w, n, j.pre, &h, &tiles);
        CHECK(pl && h.tile_count == 1, "w: publication 31 changes one tile");
        size_t nu, nv, nw;
        j = lightmap_job(&q32, 32, 2, LC_ENC_RGB9E5, 0);
        nu = lc_frames_encode(f, &u, &j);
        nw = lc_frames_encode(f, &w, &j); /* between u and v: the memo moves to w's state and back */
        nv = lc_frames_encode(f, &v, &j);
        CHECK(nu == nv && nu > 0 && !memcmp(u.out + j.pre, v.out + j.pre, nu), "u and v get the same delta bytes");
        pl = parse(&u, nu, j.pre, &h, &tiles);
        t0 = 0;
        if (pl && h.tile_count) memcpy(&t0, tiles, 4);
        CHECK(pl && (h.flags & LC_FRAME_DELTA) && h.tile_count == 1 && t0 == (W / tile) * (H / tile) - 1,
              "u (at 30): only the last tile (tiles %u)", pl ? h.tile_count : 0);
        pl = parse(&w, nw, j.pre, &h, &tiles);
        CHECK(pl && (h.flags & LC_FRAME_DELTA) && h.tile_count == 2,
              "w (at 31): tile 0 back and the last tile (tiles %u)", pl ? h.tile_count : 0);
        /* the next publication unchanged: everyone's copy is 32's, so no tile for anyone */
        j = lightmap_job(&q32, 33, 3, LC_ENC_RGB9E5, 0);
        for (int k = 0; k < 3; k++) {
            n = lc_frames_encode(f, all[k], &j);
            pl = parse(all[k], n, j.pre, &h, &tiles);
            CHECK(pl && (h.flags & LC_FRAME_DELTA) && h.tile_count == 0, "client %d is up to date (tiles %u)", k,
                  pl ? h.tile_count : 0);
        }
        for (int k = 0; k < 3; k++) lc_frames_copy_release(all[k]);
        lc_published *qs[] = {&q30, &q31, &q32};
        for (int k = 0; k < 3; k++) {
            free(qs[k]->lightmap);
            free(qs[k]->grid_sh);
        }
    }

    /* 7. the SH grid frame carries the floats (f32) */
    lc_frames_job g = {
        .frame = &p1, .pub_seq = 1, .stream = LC_STREAM_SHGRID, .enc = LC_ENC_F32, .sequence = 1, .pre = 16};
    n = lc_frames_encode(f, &a, &g);
    pl = parse(&a, n, g.pre, &h, &tiles);
    CHECK(pl && h.width == 2 && h.payload_length == 2 * 27 * 4 && !memcmp(pl, p1.grid_sh, 2 * 27 * 4),
          "the SH grid frame carries the coefficients");

    lc_frames_copy_release(&a);
    lc_frames_copy_release(&b);
    lc_frames_copy_release(&c);
    lc_frames_copy_release(&r1);
    lc_frames_copy_release(&r2);
    lc_frames_copy_release(&key);
    lc_frames_release(f);
    lc_published *ps[] = {&p1, &p2, &p3};
    for (int i = 0; i < 3; i++) {
        free(ps[i]->lightmap);
        free(ps[i]->grid_sh);
    }
    CHECK_DONE();
}
