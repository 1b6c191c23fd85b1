/* lcb_read: maps a bake file and validates it completely before handing out a view, so the
 * daemon can index every array without further checks (see lcb.h for the guarantees).
 *
 * Order: header -> section table -> each section's placement and CRC -> required sections
 * and record sizes -> META (JSON) and its counts against the sections -> referential
 * integrity of every index and finiteness of every float. Every error names the section
 * (or "header") and says what to do.
 *
 * Alignment: the file variant is mmapped (page-aligned) and sections sit at 64-byte offsets,
 * so every record is naturally aligned. lc_lcb_open_memory() borrows the caller's buffer when
 * it is 8-byte aligned (malloc'd buffers always are) and otherwise validates an aligned copy,
 * so no record is ever read through a misaligned pointer. */
#include <errno.h>
#include <fcntl.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cjson/cJSON.h>

#include "lcb/lcb.h"
#include "util/crc32.h"
#include "util/log.h"
#include "util/utf8.h"

#define LCB_CORRUPT " — the file is corrupted; re-run lucent-bake"
#define LCB_INCONSISTENT " — the bake is inconsistent; re-run lucent-bake"
#define LCB_META_MAX (16u << 20)
#define LCB_JSON_DEPTH_MAX 64
#define LCB_GRID_CELLS_MAX (1u << 26)

struct lc_lcb {
    void *map; /* file variant: the mapping */
    size_t map_len;
    void *copy; /* memory variant with a misaligned buffer: our aligned copy */
    const uint8_t *base;
    size_t size;
    lc_lcb_section table[LC_LCB_MAX_SECTIONS];
    uint32_t n_sections;
    char *meta_text; /* NUL-terminated copy of META */
    lc_lcb_view view;
};

/* Sections this reader knows; anything else is skipped (forward compatibility). */
enum {
    S_META,
    S_MATL,
    S_VERT,
    S_TRIS,
    S_SURF,
    S_NODE,
    S_LEVL,
    S_CACH,
    S_LMAP,
    S_GRID,
    S_LINK,
    S_LKSH,
    S_ASET,
    S_AVRT,
    S_AIDX,
    S_ATRN,
    S_ATRD,
    S_ASPT,
    S_AVNN,
    S_PRBH,
    S_PRBP,
    S_PRBR,
    S_PRCL,
    S_PRCP,
    S_PRCB,
    S_PRRW,
    S_PRRU,
    S_PRUF,
    S_PRUS,
    S_TSGF,
    S_TSGW,
    S_GLNK,
    S_COUNT
};
static const struct {
    char id[5];
    uint32_t record;
    int required;
    const char *what; /* the record type, for the record-size message */
} lcb_known[S_COUNT] = {
    {"META", 1, 1, "JSON text"},
    {"MATL", sizeof(lc_lcb_material), 1, "lc_lcb_material"},
    {"VERT", sizeof(lc_lcb_vertex), 1, "lc_lcb_vertex"},
    {"TRIS", sizeof(lc_lcb_triangle), 1, "lc_lcb_triangle"},
    {"SURF", sizeof(lc_lcb_surfel), 1, "lc_lcb_surfel"},
    {"NODE", sizeof(lc_lcb_node), 1, "lc_lcb_node"},
    {"LEVL", sizeof(uint32_t), 1, "uint32_t"},
    {"CACH", sizeof(lc_lcb_cache), 1, "lc_lcb_cache"},
    {"LMAP", sizeof(uint32_t), 1, "uint32_t"},
    {"GRID", sizeof(uint32_t), 1, "uint32_t"},
    {"LINK", sizeof(lc_lcb_link), 1, "lc_lcb_link"},
    {"LKSH", sizeof(uint16_t), 0, "half"},
    {"ASET", sizeof(lc_lcb_asset), 0, "lc_lcb_asset"},
    {"AVRT", sizeof(lc_lcb_asset_vertex), 0, "lc_lcb_asset_vertex"},
    {"AIDX", 3 * sizeof(uint32_t), 0, "uint32_t[3]"},
    {"ATRN", sizeof(lc_lcb_transfer), 0, "lc_lcb_transfer"},
    {"ATRD", 1, 0, "int8_t"},
    {"ASPT", sizeof(lc_lcb_sparse_point), 0, "lc_lcb_sparse_point"},
    {"AVNN", sizeof(lc_lcb_sparse_vertex), 0, "lc_lcb_sparse_vertex"},
    {"PRBH", sizeof(lc_lcb_probe_header), 0, "lc_lcb_probe_header"},
    {"PRBP", sizeof(lc_lcb_probe), 0, "lc_lcb_probe"},
    {"PRBR", sizeof(uint32_t), 0, "uint32_t"},
    {"PRCL", sizeof(lc_lcb_probe_cluster), 0, "lc_lcb_probe_cluster"},
    {"PRCP", sizeof(uint32_t), 0, "uint32_t"},
    {"PRCB", sizeof(float), 0, "float"},
    {"PRRW", sizeof(lc_lcb_probe_row), 0, "lc_lcb_probe_row"},
    {"PRRU", sizeof(float), 0, "float"},
    {"PRUF", sizeof(uint32_t), 0, "uint32_t"},
    {"PRUS", sizeof(lc_lcb_surfel_weight), 0, "lc_lcb_surfel_weight"},
    {"TSGF", sizeof(uint32_t), 0, "uint32_t"},
    {"TSGW", sizeof(lc_lcb_surfel_weight), 0, "lc_lcb_surfel_weight"},
    {"GLNK", sizeof(lc_lcb_link), 0, "lc_lcb_link"},
};

/* What META says; the sections are checked against it. */
typedef struct lcb_meta {
    uint32_t sh_bands;
    uint32_t lm_w, lm_h;
    float origin[3], cell;
    uint32_t dims[3];
    uint64_t surfels, nodes, levels, caches, texel, per_cache, grid_per_cache, link_sh;
} lcb_meta;

typedef struct lcb_ctx {
    const uint8_t *base;
    size_t size;
    const lc_lcb_section *sec[S_COUNT];
    lcb_meta m;
    char *err;
    size_t errlen;
} lcb_ctx;

__attribute__((format(printf, 2, 3))) static int lcb_fail(lcb_ctx *c, const char *fmt, ...) {
    if (c->err && c->errlen) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(c->err, c->errlen, fmt, ap);
        va_end(ap);
    }
    return -1;
}

/* Section ids come from the file: print non-printable bytes as '?'. */
static const char *lcb_idstr(const char id[4], char buf[5]) {
    for (int i = 0; i < 4; i++) buf[i] = (id[i] >= 0x20 && id[i] < 0x7f) ? id[i] : '?';
    buf[4] = 0;
    return buf;
}

/* A name from the file for a message: printable ASCII as is, other bytes as \xNN, at most
 * 64 bytes of it (buf: 4 x 64 + 1). */
static const char *lcb_namestr(const char *name, size_t cap, char buf[257]) {
    size_t o = 0;
    for (size_t i = 0; i < cap && i < 64 && name[i]; i++) {
        unsigned char ch = (unsigned char)name[i];
        if (ch >= 0x20 && ch < 0x7f && ch != '\\') buf[o++] = (char)ch;
        else o += (size_t)snprintf(buf + o, 5, "\\x%02x", ch);
    }
    buf[o] = 0;
    return buf;
}

/* Names reach every client (`welcome`, `state`, the snapshot file): they must be UTF-8.
 * name is NUL-terminated within cap (checked first). */
static int lcb_name_ok(const char *name, size_t cap) { return lc_utf8_valid(name, strnlen(name, cap)); }

static const void *lcb_data(const lcb_ctx *c, int k) { return c->base + c->sec[k]->offset; }
static uint64_t lcb_count(const lcb_ctx *c, int k) { return c->sec[k] ? c->sec[k]->count : 0; }

static int lcb_finite(const float *v, int n) {
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* --- 1 + 2: header, table, section placement ------------------------------------------- */

static int lcb_check_header(lcb_ctx *c, lc_lcb *f) {
    if (c->size < sizeof(lc_lcb_header))
        return lcb_fail(c,
                        "header: truncated: file is %zu bytes, smaller than the 64-byte header — not a complete "
                        "lucent bake; re-run lucent-bake",
                        c->size);
    lc_lcb_header h;
    memcpy(&h, c->base, sizeof h);
    if (memcmp(h.magic, LC_LCB_MAGIC, 8) != 0) return lcb_fail(c, "header: bad magic — not a lucent bake (.lcb) file");
    if (h.version_major != LC_LCB_VERSION_MAJOR) {
        if (h.version_major > LC_LCB_VERSION_MAJOR)
            return lcb_fail(c, "header: format version %u.%u is newer than this build supports (%d.x); upgrade lucent",
                            h.version_major, h.version_minor, LC_LCB_VERSION_MAJOR);
        return lcb_fail(c, "header: format version %u.%u is older than this build supports (%d.x); re-run lucent-bake",
                        h.version_major, h.version_minor, LC_LCB_VERSION_MAJOR);
    }
    if (lc_crc32(0, c->base, offsetof(lc_lcb_header, header_crc)) != h.header_crc)
        return lcb_fail(c, "header: CRC mismatch" LCB_CORRUPT);
    if (h.table_offset != sizeof(lc_lcb_header))
        return lcb_fail(c, "header: table_offset is %llu, expected 64" LCB_CORRUPT, (unsigned long long)h.table_offset);
    if (h.section_count > LC_LCB_MAX_SECTIONS)
        return lcb_fail(c, "header: section_count %u exceeds the limit of %d" LCB_CORRUPT, h.section_count,
                        LC_LCB_MAX_SECTIONS);
    size_t table_len = (size_t)h.section_count * sizeof(lc_lcb_section);
    if (table_len > c->size - sizeof h)
        return lcb_fail(c,
                        "section table: truncated: file is %zu bytes, the table of %u sections ends at %zu — "
                        "re-run lucent-bake",
                        c->size, h.section_count, sizeof h + table_len);
    if (lc_crc32(0, c->base + sizeof h, table_len) != h.table_crc)
        return lcb_fail(c, "section table: CRC mismatch" LCB_CORRUPT);
    memcpy(f->table, c->base + sizeof h, table_len);
    f->n_sections = h.section_count;
    f->view.version_major = h.version_major;
    f->view.version_minor = h.version_minor;
    if (h.file_size > c->size) {
        /* Name the first section that is cut off, so the message says what is missing. */
        char b[5];
        for (uint32_t i = 0; i < f->n_sections; i++) {
            const lc_lcb_section *s = &f->table[i];
            if (s->offset > c->size || s->size > c->size - s->offset)
                return lcb_fail(c,
                                "truncated: file is %zu bytes, header says %llu (section %s and later are "
                                "missing) — re-run lucent-bake",
                                c->size, (unsigned long long)h.file_size, lcb_idstr(s->id, b));
        }
        return lcb_fail(c,
                        "truncated: file is %zu bytes, header says %llu (end padding missing) — re-run "
                        "lucent-bake",
                        c->size, (unsigned long long)h.file_size);
    }
    if (h.file_size < c->size)
        return lcb_fail(c, "header: file is %zu bytes, header says %llu (trailing data)" LCB_CORRUPT, c->size,
                        (unsigned long long)h.file_size);
    return 0;
}

static int lcb_check_sections(lcb_ctx *c, const lc_lcb *f) {
    const uint64_t table_end = sizeof(lc_lcb_header) + (uint64_t)f->n_sections * sizeof(lc_lcb_section);
    for (uint32_t i = 0; i < f->n_sections; i++) {
        const lc_lcb_section *s = &f->table[i];
        char b[5], b2[5];
        const char *id = lcb_idstr(s->id, b);
        if (s->offset % LC_LCB_ALIGN != 0)
            return lcb_fail(c, "%s: offset %llu is not a multiple of %d" LCB_CORRUPT, id, (unsigned long long)s->offset,
                            LC_LCB_ALIGN);
        if (s->offset > c->size || s->size > c->size - s->offset)
            return lcb_fail(c, "%s: bytes [%llu, %llu + %llu) lie outside the file (%zu bytes)" LCB_CORRUPT, id,
                            (unsigned long long)s->offset, (unsigned long long)s->offset, (unsigned long long)s->size,
                            c->size);
        if (s->record_size == 0) return lcb_fail(c, "%s: record size is 0" LCB_CORRUPT, id);
        if (s->count > UINT64_MAX / s->record_size || s->count * s->record_size != s->size)
            return lcb_fail(c, "%s: size %llu bytes is not %llu records x %u bytes" LCB_CORRUPT, id,
                            (unsigned long long)s->size, (unsigned long long)s->count, s->record_size);
        if (s->offset < table_end) return lcb_fail(c, "%s: overlaps the header/section table" LCB_CORRUPT, id);
        for (uint32_t j = 0; j < i; j++) {
            const lc_lcb_section *o = &f->table[j];
            /* Both ranges are inside the file, so the sums cannot overflow. */
            if (s->size > 0 && o->size > 0 && s->offset < o->offset + o->size && o->offset < s->offset + s->size)
                return lcb_fail(c, "%s: overlaps section %s" LCB_CORRUPT, id, lcb_idstr(o->id, b2));
        }
        for (uint32_t j = 0; j < i; j++)
            if (memcmp(f->table[j].id, s->id, 4) == 0) return lcb_fail(c, "%s: duplicate section" LCB_CORRUPT, id);
        if (lc_crc32(0, c->base + s->offset, (size_t)s->size) != s->crc)
            return lcb_fail(c, "%s: CRC mismatch" LCB_CORRUPT, id);
    }
    return 0;
}

/* --- 3: required sections, record sizes -------------------------------------------------- */

static int lcb_find_sections(lcb_ctx *c, const lc_lcb *f) {
    for (uint32_t i = 0; i < f->n_sections; i++)
        for (int k = 0; k < S_COUNT; k++)
            if (memcmp(f->table[i].id, lcb_known[k].id, 4) == 0) c->sec[k] = &f->table[i];
    for (int k = 0; k < S_COUNT; k++) {
        const lc_lcb_section *s = c->sec[k];
        if (!s) {
            if (lcb_known[k].required)
                return lcb_fail(c, "%s: required section missing — the file is incomplete; re-run lucent-bake",
                                lcb_known[k].id);
            continue;
        }
        if (s->record_size != lcb_known[k].record)
            return lcb_fail(c,
                            "%s: record size %u, expected %u (%s) — written by an incompatible lucent-bake; "
                            "re-run lucent-bake",
                            lcb_known[k].id, s->record_size, lcb_known[k].record, lcb_known[k].what);
        /* The view counts in 32 bits; LINK/LKSH/PRBR have no count field there, and
         * PRCP/PRCB/PRRU count in 64 bits. */
        int wide =
            k == S_LINK || k == S_GLNK || k == S_LKSH || k == S_PRBR || k == S_PRCP || k == S_PRCB || k == S_PRRU;
        if (!wide && s->count > UINT32_MAX)
            return lcb_fail(c, "%s: %llu records, more than this reader supports (2^32-1)", lcb_known[k].id,
                            (unsigned long long)s->count);
    }
    int assets = !!c->sec[S_ASET] + !!c->sec[S_AVRT] + !!c->sec[S_AIDX];
    if (assets != 0 && assets != 3) {
        int k = !c->sec[S_ASET] ? S_ASET : !c->sec[S_AVRT] ? S_AVRT : S_AIDX;
        return lcb_fail(c, "%s: missing (ASET, AVRT and AIDX come together)" LCB_INCONSISTENT, lcb_known[k].id);
    }
    if (c->sec[S_META]->count > LCB_META_MAX)
        return lcb_fail(c, "META: %llu bytes, more than the 16 MiB limit" LCB_CORRUPT,
                        (unsigned long long)c->sec[S_META]->count);
    return 0;
}

/* --- 4: META ----------------------------------------------------------------------------- */

/* Nesting depth of JSON text, ignoring brackets inside strings; checked before cJSON so a
 * deeply nested META can neither exhaust the stack here nor in later cJSON walks. */
static int lcb_json_depth_ok(const char *s, size_t n) {
    int depth = 0, in_str = 0;
    for (size_t i = 0; i < n; i++) {
        char ch = s[i];
        if (in_str) {
            if (ch == '\\') i++;
            else if (ch == '"') in_str = 0;
        } else if (ch == '"') {
            in_str = 1;
        } else if (ch == '[' || ch == '{') {
            if (++depth > LCB_JSON_DEPTH_MAX) return 0;
        } else if (ch == ']' || ch == '}') {
            depth--;
        }
    }
    return 1;
}

/* JSON-pointer-like lookup of "/a/b" through objects. */
static const cJSON *lcb_json_at(const cJSON *root, const char *path) {
    const cJSON *cur = root;
    const char *p = path;
    while (*p == '/') {
        p++;
        size_t n = strcspn(p, "/");
        char key[32];
        if (n >= sizeof key || !cJSON_IsObject(cur)) return NULL;
        memcpy(key, p, n);
        key[n] = 0;
        cur = cJSON_GetObjectItemCaseSensitive(cur, key);
        if (!cur) return NULL;
        p += n;
    }
    return cur;
}

static int lcb_json_uint(const cJSON *j, uint64_t lo, uint64_t hi, uint64_t *out) {
    if (!cJSON_IsNumber(j)) return 0;
    double v = j->valuedouble;
    if (!isfinite(v) || v != floor(v) || v < (double)lo || v > (double)hi) return 0;
    *out = (uint64_t)v;
    return 1;
}

static int lcb_meta_uint(lcb_ctx *c, const cJSON *root, const char *path, uint64_t lo, uint64_t hi, uint64_t *out) {
    if (!lcb_json_uint(lcb_json_at(root, path), lo, hi, out))
        return lcb_fail(c, "META: %s must be an integer in %llu..%llu" LCB_INCONSISTENT, path, (unsigned long long)lo,
                        (unsigned long long)hi);
    return 0;
}

/* Finite and representable as a finite float (an out-of-range double->float cast is UB). */
static int lcb_float_ok(double v) { return isfinite(v) && fabs(v) <= FLT_MAX; }

static int lcb_meta_fields(lcb_ctx *c, const cJSON *root) {
    lcb_meta *m = &c->m;
    uint64_t v;
    if (!cJSON_IsObject(root)) return lcb_fail(c, "META: must be a JSON object" LCB_INCONSISTENT);
    const cJSON *fmt = lcb_json_at(root, "/format");
    if (!cJSON_IsString(fmt) || strcmp(fmt->valuestring, "lucent-bake") != 0)
        return lcb_fail(c, "META: /format must be \"lucent-bake\"" LCB_INCONSISTENT);
    if (lcb_meta_uint(c, root, "/sh_bands", 1, 8, &v)) return -1;
    m->sh_bands = (uint32_t)v;
    if (lcb_meta_uint(c, root, "/lightmap/width", 1, 16384, &v)) return -1;
    m->lm_w = (uint32_t)v;
    if (lcb_meta_uint(c, root, "/lightmap/height", 1, 16384, &v)) return -1;
    m->lm_h = (uint32_t)v;

    const cJSON *origin = lcb_json_at(root, "/grid/origin");
    if (!cJSON_IsArray(origin) || cJSON_GetArraySize(origin) != 3)
        return lcb_fail(c, "META: /grid/origin must be an array of 3 finite numbers" LCB_INCONSISTENT);
    for (int i = 0; i < 3; i++) {
        const cJSON *e = cJSON_GetArrayItem(origin, i);
        if (!cJSON_IsNumber(e) || !lcb_float_ok(e->valuedouble))
            return lcb_fail(c, "META: /grid/origin must be an array of 3 finite numbers" LCB_INCONSISTENT);
        m->origin[i] = (float)e->valuedouble;
    }
    const cJSON *cell = lcb_json_at(root, "/grid/cell");
    if (!cJSON_IsNumber(cell) || !lcb_float_ok(cell->valuedouble) || !((float)cell->valuedouble > 0))
        return lcb_fail(c, "META: /grid/cell must be a finite number > 0" LCB_INCONSISTENT);
    m->cell = (float)cell->valuedouble;
    const cJSON *dims = lcb_json_at(root, "/grid/dims");
    if (!cJSON_IsArray(dims) || cJSON_GetArraySize(dims) != 3)
        return lcb_fail(c, "META: /grid/dims must be an array of 3 integers in 1..1024" LCB_INCONSISTENT);
    for (int i = 0; i < 3; i++) {
        if (!lcb_json_uint(cJSON_GetArrayItem(dims, i), 1, 1024, &v))
            return lcb_fail(c, "META: /grid/dims must be an array of 3 integers in 1..1024" LCB_INCONSISTENT);
        m->dims[i] = (uint32_t)v;
    }
    if (lcb_meta_uint(c, root, "/surfels/count", 1, UINT32_MAX, &m->surfels)) return -1;
    const cJSON *area = lcb_json_at(root, "/surfels/area");
    if (!cJSON_IsNumber(area) || !isfinite(area->valuedouble) || area->valuedouble < 0)
        return lcb_fail(c, "META: /surfels/area must be a finite number >= 0" LCB_INCONSISTENT);
    if (lcb_meta_uint(c, root, "/hierarchy/nodes", 1, UINT32_MAX, &m->nodes)) return -1;
    if (lcb_meta_uint(c, root, "/hierarchy/levels", 1, UINT32_MAX - 1, &m->levels)) return -1;
    if (lcb_meta_uint(c, root, "/caches/count", 0, UINT32_MAX, &m->caches)) return -1;
    if (lcb_meta_uint(c, root, "/caches/texel", 0, m->caches, &m->texel)) return -1;
    /* --solver probes writes no links (per_cache 0): allowed only with the probe sections,
     * so every bake keeps a solver. */
    if (lcb_meta_uint(c, root, "/links/per_cache", c->sec[S_PRBH] ? 0 : 1, 1024, &m->per_cache)) return -1;
    if (lcb_meta_uint(c, root, "/links/sh_bands", 0, 8, &m->link_sh)) return -1;
    /* GLNK and /links/grid_per_cache come together (--grid-links). */
    if ((lcb_json_at(root, "/links/grid_per_cache") != NULL) != (c->sec[S_GLNK] != NULL))
        return lcb_fail(c, "%s" LCB_INCONSISTENT,
                        c->sec[S_GLNK] ? "GLNK: present, but META has no /links/grid_per_cache"
                                       : "GLNK: required section missing (META has /links/grid_per_cache)");
    if (c->sec[S_GLNK] && lcb_meta_uint(c, root, "/links/grid_per_cache", 1, LC_LCB_GRID_LINKS_MAX, &m->grid_per_cache))
        return -1;
    /* the scene's lights (optional): their ids become protocol light ids, so UTF-8 */
    const cJSON *lights = lcb_json_at(root, "/lights");
    int i = 0;
    for (const cJSON *l = cJSON_IsArray(lights) ? lights->child : NULL; l; l = l->next, i++) {
        const cJSON *id = cJSON_GetObjectItemCaseSensitive(l, "id");
        if (cJSON_IsString(id) && id->valuestring && !lc_utf8_valid(id->valuestring, strlen(id->valuestring))) {
            char b[257];
            return lcb_fail(c,
                            "META: /lights/%d/id \"%s\" is not valid UTF-8 — re-run lucent-bake (it replaces "
                            "invalid bytes with U+FFFD)",
                            i, lcb_namestr(id->valuestring, 64, b));
        }
    }
    return 0;
}

/* Counts in META against the section record counts. */
static int lcb_meta_counts(lcb_ctx *c) {
    const lcb_meta *m = &c->m;
    uint64_t texels = (uint64_t)m->lm_w * m->lm_h;
    if (lcb_count(c, S_LMAP) != texels)
        return lcb_fail(c, "LMAP: %llu entries, but META /lightmap is %ux%u = %llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_LMAP), m->lm_w, m->lm_h, (unsigned long long)texels);
    uint64_t cells = (uint64_t)m->dims[0] * m->dims[1] * m->dims[2];
    if (cells > LCB_GRID_CELLS_MAX)
        return lcb_fail(c, "META: /grid/dims %ux%ux%u exceed 2^26 samples" LCB_INCONSISTENT, m->dims[0], m->dims[1],
                        m->dims[2]);
    if (lcb_count(c, S_GRID) != cells)
        return lcb_fail(c, "GRID: %llu entries, but META /grid/dims is %ux%ux%u = %llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_GRID), m->dims[0], m->dims[1], m->dims[2],
                        (unsigned long long)cells);
    if (lcb_count(c, S_SURF) != m->surfels)
        return lcb_fail(c, "SURF: %llu surfels, but META /surfels/count is %llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_SURF), (unsigned long long)m->surfels);
    if (m->nodes != 2 * m->surfels - 1)
        return lcb_fail(c, "META: /hierarchy/nodes is %llu, expected 2 x /surfels/count - 1 = %llu" LCB_INCONSISTENT,
                        (unsigned long long)m->nodes, (unsigned long long)(2 * m->surfels - 1));
    if (lcb_count(c, S_NODE) != m->nodes)
        return lcb_fail(c, "NODE: %llu nodes, but META /hierarchy/nodes is %llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_NODE), (unsigned long long)m->nodes);
    if (lcb_count(c, S_LEVL) != m->levels + 1)
        return lcb_fail(c, "LEVL: %llu entries, but META /hierarchy/levels + 1 is %llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_LEVL), (unsigned long long)(m->levels + 1));
    if (lcb_count(c, S_CACH) != m->caches)
        return lcb_fail(c, "CACH: %llu caches, but META /caches/count is %llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_CACH), (unsigned long long)m->caches);
    /* caches <= 2^32-1 and per_cache <= 1024: the product fits 64 bits, and so does x 64. */
    uint64_t links = m->caches * m->per_cache;
    if (lcb_count(c, S_LINK) != links)
        return lcb_fail(c, "LINK: %llu links, but META /caches/count x /links/per_cache is %llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_LINK), (unsigned long long)links);
    uint64_t grid_links = (m->caches - m->texel) * m->grid_per_cache;
    if (c->sec[S_GLNK] && lcb_count(c, S_GLNK) != grid_links)
        return lcb_fail(c,
                        "GLNK: %llu links, but META (/caches/count - /caches/texel) x /links/grid_per_cache is "
                        "%llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_GLNK), (unsigned long long)grid_links);
    if (c->sec[S_GLNK] && m->link_sh)
        return lcb_fail(c, "GLNK: present with LKSH (per-link SH transport covers LINK only)" LCB_INCONSISTENT);
    if (m->link_sh == 0) {
        if (c->sec[S_LKSH]) return lcb_fail(c, "LKSH: present, but META /links/sh_bands is 0" LCB_INCONSISTENT);
    } else {
        uint64_t halves = links * m->link_sh * m->link_sh;
        if (!c->sec[S_LKSH])
            return lcb_fail(c, "LKSH: required section missing (META /links/sh_bands is %llu)" LCB_INCONSISTENT,
                            (unsigned long long)m->link_sh);
        if (lcb_count(c, S_LKSH) != halves)
            return lcb_fail(c, "LKSH: %llu values, but LINK count x /links/sh_bands^2 is %llu" LCB_INCONSISTENT,
                            (unsigned long long)lcb_count(c, S_LKSH), (unsigned long long)halves);
    }
    return 0;
}

static int lcb_check_meta(lcb_ctx *c, lc_lcb *f) {
    const lc_lcb_section *s = c->sec[S_META];
    size_t len = (size_t)s->size;
    const char *text = (const char *)lcb_data(c, S_META);
    if (memchr(text, 0, len)) return lcb_fail(c, "META: contains a NUL byte (must be JSON text)" LCB_CORRUPT);
    f->meta_text = malloc(len + 1);
    if (!f->meta_text) return lcb_fail(c, "META: out of memory");
    memcpy(f->meta_text, text, len);
    f->meta_text[len] = 0;
    if (!lcb_json_depth_ok(f->meta_text, len))
        return lcb_fail(c, "META: JSON nested deeper than %d levels" LCB_CORRUPT, LCB_JSON_DEPTH_MAX);
    cJSON *root = cJSON_ParseWithOpts(f->meta_text, NULL, 1);
    if (!root) return lcb_fail(c, "META: not valid JSON" LCB_CORRUPT);
    int rc = lcb_meta_fields(c, root);
    cJSON_Delete(root);
    if (rc) return -1;
    return lcb_meta_counts(c);
}

/* --- 5: referential integrity ------------------------------------------------------------ */

static int lcb_check_geometry(lcb_ctx *c) {
    const lc_lcb_material *mat = lcb_data(c, S_MATL);
    uint64_t n_mat = lcb_count(c, S_MATL), n_vert = lcb_count(c, S_VERT);
    for (uint64_t i = 0; i < n_mat; i++) {
        if (!memchr(mat[i].name, 0, sizeof mat[i].name))
            return lcb_fail(c, "MATL: material %llu name is not NUL-terminated" LCB_CORRUPT, (unsigned long long)i);
        if (!lcb_name_ok(mat[i].name, sizeof mat[i].name)) {
            char b[257];
            return lcb_fail(c,
                            "MATL: material %llu name \"%s\" is not valid UTF-8 — re-run lucent-bake (it replaces "
                            "invalid bytes with U+FFFD)",
                            (unsigned long long)i, lcb_namestr(mat[i].name, sizeof mat[i].name, b));
        }
        if (!lcb_finite(mat[i].base_color, 3) || !lcb_finite(mat[i].emission, 3))
            return lcb_fail(c, "MATL: material %llu has a non-finite colour" LCB_INCONSISTENT, (unsigned long long)i);
    }
    const lc_lcb_vertex *vert = lcb_data(c, S_VERT);
    for (uint64_t i = 0; i < n_vert; i++)
        if (!lcb_finite(vert[i].position, 3) || !lcb_finite(vert[i].normal, 3) || !lcb_finite(vert[i].uv1, 2))
            return lcb_fail(c, "VERT: vertex %llu has a non-finite value" LCB_INCONSISTENT, (unsigned long long)i);
    const lc_lcb_triangle *tri = lcb_data(c, S_TRIS);
    for (uint64_t i = 0; i < lcb_count(c, S_TRIS); i++) {
        if (tri[i].v[0] >= n_vert || tri[i].v[1] >= n_vert || tri[i].v[2] >= n_vert)
            return lcb_fail(c, "TRIS: triangle %llu has a vertex index >= %llu vertices" LCB_INCONSISTENT,
                            (unsigned long long)i, (unsigned long long)n_vert);
        if (tri[i].material >= n_mat)
            return lcb_fail(c, "TRIS: triangle %llu has material %u >= %llu materials" LCB_INCONSISTENT,
                            (unsigned long long)i, tri[i].material, (unsigned long long)n_mat);
    }
    return 0;
}

static int lcb_check_surfels(lcb_ctx *c) {
    const lc_lcb_surfel *s = lcb_data(c, S_SURF);
    uint64_t n_mat = lcb_count(c, S_MATL), n_cache = lcb_count(c, S_CACH);
    for (uint64_t i = 0; i < lcb_count(c, S_SURF); i++) {
        if (!lcb_finite(s[i].position, 3) || !lcb_finite(s[i].normal, 3) || !lcb_finite(s[i].albedo, 3) ||
            !lcb_finite(s[i].emission, 3) || !isfinite(s[i].area))
            return lcb_fail(c, "SURF: surfel %llu has a non-finite value" LCB_INCONSISTENT, (unsigned long long)i);
        if (!(s[i].area > 0))
            return lcb_fail(c, "SURF: surfel %llu has area <= 0" LCB_INCONSISTENT, (unsigned long long)i);
        if (s[i].material >= n_mat)
            return lcb_fail(c, "SURF: surfel %llu has material %u >= %llu materials" LCB_INCONSISTENT,
                            (unsigned long long)i, s[i].material, (unsigned long long)n_mat);
        if (s[i].cache != LC_NONE && s[i].cache >= n_cache)
            return lcb_fail(c, "SURF: surfel %llu has cache %u >= %llu caches" LCB_INCONSISTENT, (unsigned long long)i,
                            s[i].cache, (unsigned long long)n_cache);
    }
    return 0;
}

static int lcb_check_levels(lcb_ctx *c) {
    const uint32_t *L = lcb_data(c, S_LEVL);
    uint64_t n = lcb_count(c, S_LEVL), n_nodes = lcb_count(c, S_NODE);
    /* META guarantees n = levels + 1 >= 2. */
    if (L[0] != 0) return lcb_fail(c, "LEVL: first offset is %u, must be 0" LCB_INCONSISTENT, L[0]);
    if (L[1] != 1) return lcb_fail(c, "LEVL: level 0 must hold only the root (offset[1] = %u)" LCB_INCONSISTENT, L[1]);
    for (uint64_t i = 1; i < n; i++)
        if (L[i] <= L[i - 1])
            return lcb_fail(c, "LEVL: offsets not strictly increasing at level %llu" LCB_INCONSISTENT,
                            (unsigned long long)i);
    if (L[n - 1] != n_nodes)
        return lcb_fail(c, "LEVL: last offset is %u, must be the node count %llu" LCB_INCONSISTENT, L[n - 1],
                        (unsigned long long)n_nodes);
    return 0;
}

/* The hierarchy is a full binary tree in BFS order: node 0 is the root over all surfels,
 * children of a level-k node lie in level k+1, the two children partition the parent's
 * surfel range (left first), leaves hold exactly one surfel, and every node but the root
 * has exactly one parent. LEVL must be validated first. */
static int lcb_check_nodes(lcb_ctx *c) {
    const lc_lcb_node *nd = lcb_data(c, S_NODE);
    const uint32_t *L = lcb_data(c, S_LEVL);
    uint64_t n = lcb_count(c, S_NODE), n_levels = lcb_count(c, S_LEVL) - 1, n_surf = lcb_count(c, S_SURF);
    uint8_t *has_parent = calloc((size_t)n, 1);
    int rc = -1;
    if (!has_parent) return lcb_fail(c, "NODE: out of memory");
    if (nd[0].first_surfel != 0 || nd[0].surfel_count != n_surf) {
        lcb_fail(c, "NODE: root covers [%u, +%u), must cover all %llu surfels" LCB_INCONSISTENT, nd[0].first_surfel,
                 nd[0].surfel_count, (unsigned long long)n_surf);
        goto err;
    }
    uint64_t lev = 0;
    for (uint64_t i = 0; i < n; i++) {
        const lc_lcb_node *p = &nd[i];
        unsigned long long ui = (unsigned long long)i;
        while (i >= L[lev + 1]) lev++; /* L[n_levels] == n, so lev < n_levels here */
        if (!lcb_finite(p->center, 3) || !isfinite(p->area) || !lcb_finite(p->normal, 3) || !isfinite(p->radius)) {
            lcb_fail(c, "NODE: node %llu has a non-finite value" LCB_INCONSISTENT, ui);
            goto err;
        }
        if (!(p->area > 0) || !(p->radius >= 0)) {
            lcb_fail(c, "NODE: node %llu has area <= 0 or radius < 0" LCB_INCONSISTENT, ui);
            goto err;
        }
        if (p->child[0] == LC_NONE && p->child[1] == LC_NONE) {
            if (p->surfel_count != 1 || p->first_surfel >= n_surf) {
                lcb_fail(c, "NODE: leaf %llu must hold one surfel below %llu (has [%u, +%u))" LCB_INCONSISTENT, ui,
                         (unsigned long long)n_surf, p->first_surfel, p->surfel_count);
                goto err;
            }
            continue;
        }
        for (int k = 0; k < 2; k++) {
            uint32_t ch = p->child[k];
            if (ch == LC_NONE || ch >= n) {
                lcb_fail(c, "NODE: node %llu child %d is %u, out of range (%llu nodes)" LCB_INCONSISTENT, ui, k, ch,
                         (unsigned long long)n);
                goto err;
            }
            if (lev + 1 >= n_levels || ch < L[lev + 1] || ch >= L[lev + 2]) {
                lcb_fail(c,
                         "NODE: node %llu (level %llu) has child %u outside the next level — not in BFS "
                         "order" LCB_INCONSISTENT,
                         ui, (unsigned long long)lev, ch);
                goto err;
            }
            if (has_parent[ch]) {
                lcb_fail(c, "NODE: node %u has more than one parent" LCB_INCONSISTENT, ch);
                goto err;
            }
            has_parent[ch] = 1;
        }
        const lc_lcb_node *a = &nd[p->child[0]], *b = &nd[p->child[1]];
        if (a->first_surfel != p->first_surfel || (uint64_t)a->first_surfel + a->surfel_count != b->first_surfel ||
            (uint64_t)a->surfel_count + b->surfel_count != p->surfel_count) {
            lcb_fail(c, "NODE: children of node %llu do not partition its surfel range" LCB_INCONSISTENT, ui);
            goto err;
        }
    }
    for (uint64_t i = 1; i < n; i++)
        if (!has_parent[i]) {
            lcb_fail(c, "NODE: node %llu has no parent" LCB_INCONSISTENT, (unsigned long long)i);
            goto err;
        }
    rc = 0;
err:
    free(has_parent);
    return rc;
}

static int lcb_check_caches(lcb_ctx *c) {
    const lc_lcb_cache *ca = lcb_data(c, S_CACH);
    uint64_t n = lcb_count(c, S_CACH), texels = (uint64_t)c->m.lm_w * c->m.lm_h, cells = lcb_count(c, S_GRID);
    for (uint64_t i = 0; i < n; i++) {
        unsigned long long ui = (unsigned long long)i;
        if (!lcb_finite(ca[i].position, 3) || !lcb_finite(ca[i].normal, 3) || !lcb_finite(ca[i].albedo, 3))
            return lcb_fail(c, "CACH: cache %llu has a non-finite value" LCB_INCONSISTENT, ui);
        uint32_t kind = ca[i].flags & (LC_CACHE_TEXEL | LC_CACHE_GRID);
        if (i < c->m.texel) {
            if (kind != LC_CACHE_TEXEL || ca[i].index >= texels)
                return lcb_fail(
                    c, "CACH: cache %llu must be a texel cache with index < %llu (META /caches/texel)" LCB_INCONSISTENT,
                    ui, (unsigned long long)texels);
        } else if (kind != LC_CACHE_GRID || ca[i].index >= cells) {
            return lcb_fail(c, "CACH: cache %llu must be a grid cache with index < %llu" LCB_INCONSISTENT, ui,
                            (unsigned long long)cells);
        }
    }
    const uint32_t *lm = lcb_data(c, S_LMAP);
    for (uint64_t i = 0; i < lcb_count(c, S_LMAP); i++)
        if (lm[i] != LC_NONE && lm[i] >= n)
            return lcb_fail(c, "LMAP: texel %llu refers to cache %u >= %llu caches" LCB_INCONSISTENT,
                            (unsigned long long)i, lm[i], (unsigned long long)n);
    const uint32_t *g = lcb_data(c, S_GRID);
    for (uint64_t i = 0; i < cells; i++)
        if (g[i] >= n)
            return lcb_fail(c, "GRID: sample %llu refers to cache %u >= %llu caches" LCB_INCONSISTENT,
                            (unsigned long long)i, g[i], (unsigned long long)n);
    return 0;
}

/* Every link of section k: its node in range, its factor finite and >= 0. */
static int lcb_check_link_records(lcb_ctx *c, int k) {
    const lc_lcb_link *l = lcb_data(c, k);
    uint64_t n_nodes = lcb_count(c, S_NODE);
    for (uint64_t i = 0; i < lcb_count(c, k); i++)
        if (l[i].node >= n_nodes || !isfinite(l[i].factor) || !(l[i].factor >= 0))
            return lcb_fail(
                c, "%s: link %llu has node %u (of %llu) or a factor that is not finite and >= 0" LCB_INCONSISTENT,
                lcb_known[k].id, (unsigned long long)i, l[i].node, (unsigned long long)n_nodes);
    return 0;
}

static int lcb_check_links(lcb_ctx *c) {
    if (lcb_check_link_records(c, S_LINK) || (c->sec[S_GLNK] && lcb_check_link_records(c, S_GLNK))) return -1;
    /* Used links first, padding after: runtimes stop at link_count. With GLNK a grid cache's
     * row is there and its LINK slots are all padding. */
    const lc_lcb_link *l = lcb_data(c, S_LINK), *gl = c->sec[S_GLNK] ? lcb_data(c, S_GLNK) : NULL;
    const lc_lcb_cache *ca = lcb_data(c, S_CACH);
    for (uint64_t i = 0; i < lcb_count(c, S_CACH); i++) {
        int grid_row = gl && i >= c->m.texel;
        const char *sec = grid_row ? "GLNK" : "LINK", *per = grid_row ? "grid_per_cache" : "per_cache";
        uint64_t n = grid_row ? c->m.grid_per_cache : c->m.per_cache;
        const lc_lcb_link *row = grid_row ? gl + (i - c->m.texel) * n : l + i * n;
        if (ca[i].link_count > n)
            return lcb_fail(c, "CACH: cache %llu has link_count %u > /links/%s %llu" LCB_INCONSISTENT,
                            (unsigned long long)i, ca[i].link_count, per, (unsigned long long)n);
        for (uint64_t j = ca[i].link_count; j < n; j++)
            if (row[j].factor != 0)
                return lcb_fail(
                    c, "%s: cache %llu slot %llu lies past its link_count %u but is not padding" LCB_INCONSISTENT, sec,
                    (unsigned long long)i, (unsigned long long)j, ca[i].link_count);
        for (uint64_t j = 0; grid_row && j < c->m.per_cache; j++)
            if (l[i * c->m.per_cache + j].factor != 0)
                return lcb_fail(
                    c, "LINK: grid cache %llu slot %llu is not padding (its links are in GLNK)" LCB_INCONSISTENT,
                    (unsigned long long)i, (unsigned long long)j);
    }
    if (c->sec[S_LKSH]) {
        const uint16_t *h = lcb_data(c, S_LKSH);
        for (uint64_t i = 0; i < lcb_count(c, S_LKSH); i++)
            if ((h[i] & 0x7C00u) == 0x7C00u) /* exponent all ones: inf or NaN */
                return lcb_fail(c, "LKSH: value %llu is inf/NaN" LCB_INCONSISTENT, (unsigned long long)i);
    }
    return 0;
}

static int lcb_check_assets(lcb_ctx *c) {
    if (!c->sec[S_ASET]) return 0;
    const lc_lcb_asset *a = lcb_data(c, S_ASET);
    const lc_lcb_asset_vertex *v = lcb_data(c, S_AVRT);
    const uint32_t *idx = lcb_data(c, S_AIDX);
    uint64_t n_v = lcb_count(c, S_AVRT), n_t = lcb_count(c, S_AIDX);
    for (uint64_t i = 0; i < n_v; i++)
        if (!lcb_finite(v[i].position, 3) || !lcb_finite(v[i].normal, 3) || !lcb_finite(v[i].albedo, 3))
            return lcb_fail(c, "AVRT: vertex %llu has a non-finite value" LCB_INCONSISTENT, (unsigned long long)i);
    for (uint64_t i = 0; i < lcb_count(c, S_ASET); i++) {
        unsigned long long ui = (unsigned long long)i;
        if (!memchr(a[i].name, 0, sizeof a[i].name))
            return lcb_fail(c, "ASET: asset %llu name is not NUL-terminated" LCB_CORRUPT, ui);
        if (!lcb_name_ok(a[i].name, sizeof a[i].name)) {
            char b[257];
            return lcb_fail(c,
                            "ASET: asset %llu name \"%s\" is not valid UTF-8 — re-run lucent-bake with another "
                            "--asset name",
                            ui, lcb_namestr(a[i].name, sizeof a[i].name, b));
        }
        if ((uint64_t)a[i].first_vertex + a[i].vertex_count > n_v)
            return lcb_fail(c, "ASET: asset %llu vertices [%u, +%u) exceed AVRT (%llu)" LCB_INCONSISTENT, ui,
                            a[i].first_vertex, a[i].vertex_count, (unsigned long long)n_v);
        if ((uint64_t)a[i].first_triangle + a[i].triangle_count > n_t)
            return lcb_fail(c, "ASET: asset %llu triangles [%u, +%u) exceed AIDX (%llu)" LCB_INCONSISTENT, ui,
                            a[i].first_triangle, a[i].triangle_count, (unsigned long long)n_t);
        if (!lcb_finite(a[i].bounds_min, 3) || !lcb_finite(a[i].bounds_max, 3) || !lcb_finite(a[i].albedo, 3))
            return lcb_fail(c, "ASET: asset %llu has a non-finite value" LCB_INCONSISTENT, ui);
        const uint32_t *t = idx + (size_t)a[i].first_triangle * 3;
        for (uint64_t k = 0; k < (uint64_t)a[i].triangle_count * 3; k++)
            if (t[k] >= a[i].vertex_count)
                return lcb_fail(c, "AIDX: asset %llu triangle index %u >= its %u vertices" LCB_INCONSISTENT, ui, t[k],
                                a[i].vertex_count);
    }
    return 0;
}

/* DNRT transfer grids: each names a distinct asset, its sizes are in range, its floats
 * finite and positive where they divide, and its values lie inside ATRD. */
static int lcb_check_transfers(lcb_ctx *c) {
    if (!!c->sec[S_ATRN] != !!c->sec[S_ATRD])
        return lcb_fail(c, "%s: missing (ATRN and ATRD come together)" LCB_INCONSISTENT,
                        c->sec[S_ATRN] ? "ATRD" : "ATRN");
    if (!c->sec[S_ATRN]) return 0;
    const lc_lcb_transfer *t = lcb_data(c, S_ATRN);
    uint64_t n = lcb_count(c, S_ATRN), n_assets = c->sec[S_ASET] ? lcb_count(c, S_ASET) : 0;
    uint64_t data = lcb_count(c, S_ATRD);
    for (uint64_t i = 0; i < n; i++) {
        unsigned long long ui = (unsigned long long)i;
        if (t[i].asset >= n_assets)
            return lcb_fail(c, "ATRN: transfer %llu names asset %u, the bake has %llu" LCB_INCONSISTENT, ui, t[i].asset,
                            (unsigned long long)n_assets);
        for (uint64_t k = 0; k < i; k++)
            if (t[k].asset == t[i].asset)
                return lcb_fail(c, "ATRN: transfers %llu and %llu both name asset %u" LCB_INCONSISTENT,
                                (unsigned long long)k, ui, t[i].asset);
        if (t[i].dims < 2 || t[i].dims > 64 || (t[i].coeffs != 4 && t[i].coeffs != 9))
            return lcb_fail(c, "ATRN: transfer %llu has dims %u (2..64) or coeffs %u (4 or 9)" LCB_INCONSISTENT, ui,
                            t[i].dims, t[i].coeffs);
        if (!lcb_finite(t[i].center, 3) || !lcb_finite(t[i].t_scale, 27) || !lcb_finite(t[i].k_scale, 9) ||
            !(t[i].radius > 0 && t[i].radius < 1e7f) || !(t[i].half_extent > 0 && t[i].half_extent < 1e7f) ||
            !(t[i].outer_radius >= t[i].half_extent && t[i].outer_radius < 1e7f))
            return lcb_fail(c, "ATRN: transfer %llu has a non-finite or non-positive size or scale" LCB_INCONSISTENT,
                            ui);
        uint64_t bytes = lc_lcb_transfer_bytes(&t[i]);
        if (t[i].data_offset > data || bytes > data - t[i].data_offset)
            return lcb_fail(c, "ATRN: transfer %llu values [%llu, +%llu) exceed ATRD (%llu bytes)" LCB_INCONSISTENT, ui,
                            (unsigned long long)t[i].data_offset, (unsigned long long)bytes, (unsigned long long)data);
    }
    return 0;
}

/* LightSkin sparse points: ASPT and AVNN together and only with assets; points name an asset,
 * sorted (so each asset's are contiguous), at most 65535 per asset, finite, unit normals and
 * a positive radius; one AVNN record per AVRT vertex, its indices inside its asset's points
 * and its weights in [0, 1] summing to 1 (all zero for an asset without points). */
#define LCB_SPARSE_UNIT_TOL 1e-3f
#define LCB_SPARSE_SUM_TOL 1e-3f
#define LCB_SPARSE_MAX_PER_ASSET 65535u

static int lcb_check_sparse_points(lcb_ctx *c, uint64_t n_assets) {
    const lc_lcb_sparse_point *p = lcb_data(c, S_ASPT);
    uint64_t n = lcb_count(c, S_ASPT), run = 0;
    for (uint64_t i = 0; i < n; i++) {
        unsigned long long ui = (unsigned long long)i;
        if (p[i].asset >= n_assets)
            return lcb_fail(c, "ASPT: point %llu asset %u out of range (the bake has %llu assets)" LCB_INCONSISTENT, ui,
                            p[i].asset, (unsigned long long)n_assets);
        if (i > 0 && p[i].asset < p[i - 1].asset)
            return lcb_fail(c, "ASPT: point %llu asset %u after asset %u — not sorted by asset" LCB_INCONSISTENT, ui,
                            p[i].asset, p[i - 1].asset);
        run = i > 0 && p[i].asset == p[i - 1].asset ? run + 1 : 1;
        if (run > LCB_SPARSE_MAX_PER_ASSET)
            return lcb_fail(c, "ASPT: asset %u has more than %u points" LCB_INCONSISTENT, p[i].asset,
                            LCB_SPARSE_MAX_PER_ASSET);
        if (!lcb_finite(p[i].position, 3))
            return lcb_fail(c, "ASPT: point %llu position is not finite" LCB_INCONSISTENT, ui);
        if (!lcb_finite(p[i].normal, 3))
            return lcb_fail(c, "ASPT: point %llu normal is not finite" LCB_INCONSISTENT, ui);
        const float *nn = p[i].normal;
        float len = sqrtf(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2]);
        if (!(fabsf(len - 1.0f) <= LCB_SPARSE_UNIT_TOL))
            return lcb_fail(c, "ASPT: point %llu normal has length %g, not unit (within %g)" LCB_INCONSISTENT, ui,
                            (double)len, (double)LCB_SPARSE_UNIT_TOL);
        if (!(isfinite(p[i].radius) && p[i].radius > 0))
            return lcb_fail(c, "ASPT: point %llu radius %g is not finite and > 0" LCB_INCONSISTENT, ui,
                            (double)p[i].radius);
    }
    return 0;
}

/* One AVNN record of a vertex whose asset has `points` points. */
static int lcb_check_sparse_vertex(lcb_ctx *c, const lc_lcb_sparse_vertex *r, uint64_t vi, uint32_t asset,
                                   uint32_t points) {
    unsigned long long uv = (unsigned long long)vi;
    float sum = 0;
    for (int k = 0; k < 8; k++) {
        if (points ? r->index[k] >= points : r->index[k] != 0)
            return lcb_fail(c, "AVNN: vertex %llu index[%d] = %u, asset %u has %u points" LCB_INCONSISTENT, uv, k,
                            r->index[k], asset, points);
        float w = r->weight[k];
        if (!(isfinite(w) && w >= 0 && w <= 1) || (!points && w != 0))
            return lcb_fail(c, "AVNN: vertex %llu weight[%d] = %g is not in [0, 1]%s" LCB_INCONSISTENT, uv, k,
                            (double)w, points ? "" : " (0: its asset has no points)");
        sum += w;
    }
    if (points && !(fabsf(sum - 1.0f) <= LCB_SPARSE_SUM_TOL))
        return lcb_fail(c, "AVNN: vertex %llu weights sum to %g, not 1 (within %g)" LCB_INCONSISTENT, uv, (double)sum,
                        (double)LCB_SPARSE_SUM_TOL);
    return 0;
}

static int lcb_check_sparse(lcb_ctx *c) {
    if (!!c->sec[S_ASPT] != !!c->sec[S_AVNN])
        return lcb_fail(c, "%s: missing (ASPT and AVNN come together)" LCB_INCONSISTENT,
                        c->sec[S_ASPT] ? "AVNN" : "ASPT");
    if (!c->sec[S_ASPT]) return 0;
    if (!c->sec[S_ASET]) return lcb_fail(c, "ASPT: sparse points but no assets (ASET)" LCB_INCONSISTENT);
    uint64_t n_assets = lcb_count(c, S_ASET), n_v = lcb_count(c, S_AVRT);
    if (lcb_check_sparse_points(c, n_assets)) return -1;
    if (lcb_count(c, S_AVNN) != n_v)
        return lcb_fail(c, "AVNN: %llu records, AVRT has %llu vertices (one each)" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_AVNN), (unsigned long long)n_v);
    const lc_lcb_asset *a = lcb_data(c, S_ASET);
    const lc_lcb_sparse_point *p = lcb_data(c, S_ASPT);
    const lc_lcb_sparse_vertex *r = lcb_data(c, S_AVNN);
    uint64_t n = lcb_count(c, S_ASPT), at = 0;
    for (uint32_t i = 0; i < (uint32_t)n_assets; i++) {
        uint64_t first = at; /* sorted: asset i's points start where asset i-1's end */
        while (at < n && p[at].asset == i) at++;
        uint32_t points = (uint32_t)(at - first);
        for (uint64_t v = a[i].first_vertex; v < (uint64_t)a[i].first_vertex + a[i].vertex_count; v++)
            if (lcb_check_sparse_vertex(c, &r[v], v, i, points)) return -1;
    }
    return 0;
}

/* The probes solver: the eight sections together or none; the header's sizes agree with the
 * sections; clusters tile PRRW in order and their probes, basis and U lie inside PRCP, PRCB
 * and PRRU; every index in range and every float finite, so the engine needs no checks. */
static const int lcb_probe_secs[] = {S_PRBH, S_PRBP, S_PRBR, S_PRCL, S_PRCP, S_PRCB, S_PRRW, S_PRRU};
#define LCB_PROBE_MAX_RAYS 65536u

/* The one PRBH record (its count is checked first). */
static int lcb_check_probe_header(lcb_ctx *c, const lc_lcb_probe_header *h) {
    if (h->n_probes < 1 || h->n_probes != lcb_count(c, S_PRBP))
        return lcb_fail(c, "PRBH: n_probes %u, PRBP has %llu probes (must be equal and >= 1)" LCB_INCONSISTENT,
                        h->n_probes, (unsigned long long)lcb_count(c, S_PRBP));
    if (h->n_rays < 1 || h->n_rays > LCB_PROBE_MAX_RAYS)
        return lcb_fail(c, "PRBH: n_rays %u is not in 1..%u" LCB_INCONSISTENT, h->n_rays, LCB_PROBE_MAX_RAYS);
    if (h->sh_bands < 1 || h->sh_bands > LC_LCB_PROBE_MAX_BANDS)
        return lcb_fail(c, "PRBH: sh_bands %u is not in 1..%d" LCB_INCONSISTENT, h->sh_bands, LC_LCB_PROBE_MAX_BANDS);
    if (h->n_clusters != lcb_count(c, S_PRCL))
        return lcb_fail(c, "PRBH: n_clusters %u, PRCL has %llu clusters" LCB_INCONSISTENT, h->n_clusters,
                        (unsigned long long)lcb_count(c, S_PRCL));
    if (h->n_rows != lcb_count(c, S_PRRW))
        return lcb_fail(c, "PRBH: n_rows %u, PRRW has %llu rows" LCB_INCONSISTENT, h->n_rows,
                        (unsigned long long)lcb_count(c, S_PRRW));
    if (h->max_rank < 1 || h->max_rank > LC_LCB_PROBE_MAX_RANK)
        return lcb_fail(c, "PRBH: max_rank %u is not in 1..%d" LCB_INCONSISTENT, h->max_rank, LC_LCB_PROBE_MAX_RANK);
    if (!(isfinite(h->support_radius) && h->support_radius >= 0))
        return lcb_fail(c, "PRBH: support_radius %g is not finite and >= 0" LCB_INCONSISTENT,
                        (double)h->support_radius);
    if (!(isfinite(h->svd_error) && h->svd_error >= 0))
        return lcb_fail(c, "PRBH: svd_error %g is not finite and >= 0" LCB_INCONSISTENT, (double)h->svd_error);
    /* n_probes < 2^32 and n_rays <= 2^16 (checked above): the product fits 64 bits. */
    uint64_t hits = (uint64_t)h->n_probes * h->n_rays;
    if (lcb_count(c, S_PRBR) != hits)
        return lcb_fail(c, "PRBR: %llu entries, but PRBH n_probes x n_rays is %u x %u = %llu" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_PRBR), h->n_probes, h->n_rays, (unsigned long long)hits);
    return 0;
}

/* Clusters: in order over PRRW (cluster 0 at row 0, each starting where the last ended, the
 * last ending at n_rows), each with rows and probes, rank 1..max_rank, and its basis and U
 * inside PRCB and PRRU. Reads only PRCL, so it may run before the arrays it points into. */
static int lcb_check_probe_clusters(lcb_ctx *c, const lc_lcb_probe_header *h) {
    const lc_lcb_probe_cluster *cl = lcb_data(c, S_PRCL);
    uint64_t n = lcb_count(c, S_PRCL), n_rows = lcb_count(c, S_PRRW), n_cp = lcb_count(c, S_PRCP);
    uint64_t n_basis = lcb_count(c, S_PRCB), n_u = lcb_count(c, S_PRRU), coeffs = (uint64_t)h->sh_bands * h->sh_bands;
    uint64_t row = 0; /* n <= 2^32-1 clusters of < 2^32 rows each: no overflow */
    for (uint64_t i = 0; i < n; i++) {
        const lc_lcb_probe_cluster *k = &cl[i];
        unsigned long long ui = (unsigned long long)i;
        if (k->first_row != row)
            return lcb_fail(
                c, "PRCL: cluster %llu first_row %u, expected %llu (clusters tile PRRW in order)" LCB_INCONSISTENT, ui,
                k->first_row, (unsigned long long)row);
        if (k->n_rows < 1 || k->n_probes < 1)
            return lcb_fail(c, "PRCL: cluster %llu has n_rows %u, n_probes %u (both must be >= 1)" LCB_INCONSISTENT, ui,
                            k->n_rows, k->n_probes);
        if (row + k->n_rows > n_rows)
            return lcb_fail(c, "PRCL: cluster %llu rows [%u, +%u) exceed PRRW (%llu rows)" LCB_INCONSISTENT, ui,
                            k->first_row, k->n_rows, (unsigned long long)n_rows);
        if ((uint64_t)k->first_probe + k->n_probes > n_cp)
            return lcb_fail(c, "PRCL: cluster %llu probes [%u, +%u) exceed PRCP (%llu entries)" LCB_INCONSISTENT, ui,
                            k->first_probe, k->n_probes, (unsigned long long)n_cp);
        if (k->rank < 1 || k->rank > h->max_rank)
            return lcb_fail(c, "PRCL: cluster %llu rank %u is not in 1..%u (PRBH max_rank)" LCB_INCONSISTENT, ui,
                            k->rank, h->max_rank);
        /* rank <= 256, n_probes < 2^32, coeffs <= 64, n_rows < 2^32: both sizes fit 64 bits;
         * the offsets come from the file, so compare them without adding. */
        uint64_t basis = (uint64_t)k->rank * k->n_probes * coeffs, u = (uint64_t)k->n_rows * k->rank;
        if (k->basis_offset > n_basis || basis > n_basis - k->basis_offset)
            return lcb_fail(c, "PRCL: cluster %llu basis [%llu, +%llu) exceeds PRCB (%llu floats)" LCB_INCONSISTENT, ui,
                            (unsigned long long)k->basis_offset, (unsigned long long)basis,
                            (unsigned long long)n_basis);
        if (k->u_offset > n_u || u > n_u - k->u_offset)
            return lcb_fail(c, "PRCL: cluster %llu U [%llu, +%llu) exceeds PRRU (%llu floats)" LCB_INCONSISTENT, ui,
                            (unsigned long long)k->u_offset, (unsigned long long)u, (unsigned long long)n_u);
        row += k->n_rows;
    }
    if (row != n_rows)
        return lcb_fail(c, "PRCL: clusters end at row %llu, PRRW has %llu rows (they must tile it)" LCB_INCONSISTENT,
                        (unsigned long long)row, (unsigned long long)n_rows);
    return 0;
}

static int lcb_check_floats(lcb_ctx *c, int k) {
    const float *x = lcb_data(c, k);
    for (uint64_t i = 0; i < lcb_count(c, k); i++)
        if (!isfinite(x[i]))
            return lcb_fail(c, "%s: value %llu is not finite" LCB_INCONSISTENT, lcb_known[k].id, (unsigned long long)i);
    return 0;
}

/* PRBP, PRBR, PRCP, PRRW, PRCB, PRRU: positions and values finite, indices in range. */
static int lcb_check_probe_arrays(lcb_ctx *c, const lc_lcb_probe_header *h) {
    const lc_lcb_probe *p = lcb_data(c, S_PRBP);
    for (uint64_t i = 0; i < lcb_count(c, S_PRBP); i++)
        if (!lcb_finite(p[i].position, 3))
            return lcb_fail(c, "PRBP: probe %llu position is not finite" LCB_INCONSISTENT, (unsigned long long)i);
    const uint32_t *hit = lcb_data(c, S_PRBR);
    uint64_t n_surf = lcb_count(c, S_SURF);
    for (uint64_t i = 0; i < lcb_count(c, S_PRBR); i++)
        if (hit[i] != LC_NONE && hit[i] >= n_surf)
            return lcb_fail(c,
                            "PRBR: probe %llu ray %llu hits surfel %u >= %llu surfels (nor LC_NONE)" LCB_INCONSISTENT,
                            (unsigned long long)(i / h->n_rays), (unsigned long long)(i % h->n_rays), hit[i],
                            (unsigned long long)n_surf);
    const uint32_t *cp = lcb_data(c, S_PRCP);
    for (uint64_t i = 0; i < lcb_count(c, S_PRCP); i++)
        if (cp[i] >= h->n_probes)
            return lcb_fail(c, "PRCP: entry %llu is probe %u >= %u probes (PRBH n_probes)" LCB_INCONSISTENT,
                            (unsigned long long)i, cp[i], h->n_probes);
    const lc_lcb_probe_row *r = lcb_data(c, S_PRRW);
    const lc_lcb_cache *ca = lcb_data(c, S_CACH);
    uint64_t n_cache = lcb_count(c, S_CACH);
    for (uint64_t i = 0; i < lcb_count(c, S_PRRW); i++) {
        unsigned long long ui = (unsigned long long)i;
        if (r[i].cache >= n_cache)
            return lcb_fail(c, "PRRW: row %llu cache %u >= %llu caches" LCB_INCONSISTENT, ui, r[i].cache,
                            (unsigned long long)n_cache);
        /* CACH is validated: a cache is exactly a texel or a grid cache. */
        if ((ca[r[i].cache].flags & LC_CACHE_TEXEL) ? r[i].coeff != 0 : r[i].coeff > 8)
            return lcb_fail(c, "PRRW: row %llu coeff %u for %s cache %u, must be %s" LCB_INCONSISTENT, ui, r[i].coeff,
                            (ca[r[i].cache].flags & LC_CACHE_TEXEL) ? "texel" : "grid", r[i].cache,
                            (ca[r[i].cache].flags & LC_CACHE_TEXEL) ? "0" : "in 0..8");
    }
    return lcb_check_floats(c, S_PRCB) || lcb_check_floats(c, S_PRRU) ? -1 : 0;
}

/* An offsets/entries pair of (surfel, weight) lists (PRUF/PRUS, TSGF/TSGW), optional and
 * together: OFFS holds n_rows + 1 offsets (ROWS names what counts them) from 0, never
 * decreasing, ending at ENTS's count; each entry's surfel in range and its weight finite. */
static int lcb_check_surfel_weights(lcb_ctx *c, int offs, int ents, uint64_t n_rows, const char *rows) {
    const char *fo = lcb_known[offs].id, *fe = lcb_known[ents].id;
    if (!c->sec[offs] && !c->sec[ents]) return 0;
    if (!c->sec[offs] || !c->sec[ents])
        return lcb_fail(c, "%s: missing (%s and %s come together)" LCB_INCONSISTENT, c->sec[offs] ? fe : fo, fo, fe);
    if (lcb_count(c, offs) != n_rows + 1)
        return lcb_fail(c, "%s: %llu offsets, expected %s + 1 = %llu" LCB_INCONSISTENT, fo,
                        (unsigned long long)lcb_count(c, offs), rows, (unsigned long long)n_rows + 1);
    const uint32_t *first = lcb_data(c, offs);
    if (first[0] != 0) return lcb_fail(c, "%s: offset 0 is %u, must be 0" LCB_INCONSISTENT, fo, first[0]);
    for (uint64_t r = 0; r < n_rows; r++)
        if (first[r + 1] < first[r])
            return lcb_fail(c, "%s: row %llu ends at %u before it starts (%u)" LCB_INCONSISTENT, fo,
                            (unsigned long long)r, first[r + 1], first[r]);
    if (first[n_rows] != lcb_count(c, ents))
        return lcb_fail(c, "%s: the rows end at entry %u, %s has %llu entries" LCB_INCONSISTENT, fo, first[n_rows], fe,
                        (unsigned long long)lcb_count(c, ents));
    const lc_lcb_surfel_weight *e = lcb_data(c, ents);
    uint64_t n_surf = lcb_count(c, S_SURF);
    for (uint64_t i = 0; i < lcb_count(c, ents); i++) {
        if (e[i].surfel >= n_surf)
            return lcb_fail(c, "%s: entry %llu surfel %u >= %llu surfels" LCB_INCONSISTENT, fe, (unsigned long long)i,
                            e[i].surfel, (unsigned long long)n_surf);
        if (!isfinite(e[i].weight))
            return lcb_fail(c, "%s: entry %llu weight is not finite" LCB_INCONSISTENT, fe, (unsigned long long)i);
    }
    return 0;
}

static int lcb_check_probes(lcb_ctx *c) {
    const int n_secs = (int)(sizeof lcb_probe_secs / sizeof lcb_probe_secs[0]);
    int present = 0;
    for (int i = 0; i < n_secs; i++) present += !!c->sec[lcb_probe_secs[i]];
    if (present == 0) {
        if (c->sec[S_PRUF] || c->sec[S_PRUS])
            return lcb_fail(c, "%s: present without the probe sections it belongs to" LCB_INCONSISTENT,
                            c->sec[S_PRUF] ? "PRUF" : "PRUS");
        return 0;
    }
    for (int i = 0; i < n_secs; i++)
        if (!c->sec[lcb_probe_secs[i]])
            return lcb_fail(c,
                            "%s: missing (the probe sections PRBH, PRBP, PRBR, PRCL, PRCP, PRCB, PRRW and PRRU come "
                            "together)" LCB_INCONSISTENT,
                            lcb_known[lcb_probe_secs[i]].id);
    if (lcb_count(c, S_PRBH) != 1)
        return lcb_fail(c, "PRBH: %llu records, expected exactly 1" LCB_INCONSISTENT,
                        (unsigned long long)lcb_count(c, S_PRBH));
    const lc_lcb_probe_header *h = lcb_data(c, S_PRBH);
    if (lcb_check_probe_header(c, h) || lcb_check_probe_clusters(c, h) || lcb_check_probe_arrays(c, h) ||
        lcb_check_surfel_weights(c, S_PRUF, S_PRUS, h->n_rows, "PRBH n_rows"))
        return -1;
    return 0;
}

/* --- load ------------------------------------------------------------------------------ */

static int lcb_load(lc_lcb *f, char *err, size_t errlen) {
    lcb_ctx c;
    memset(&c, 0, sizeof c);
    c.base = f->base;
    c.size = f->size;
    c.err = err;
    c.errlen = errlen;
    if (lcb_check_header(&c, f) || lcb_check_sections(&c, f) || lcb_find_sections(&c, f) || lcb_check_meta(&c, f) ||
        lcb_check_geometry(&c) || lcb_check_surfels(&c) || lcb_check_levels(&c) || lcb_check_nodes(&c) ||
        lcb_check_caches(&c) || lcb_check_links(&c) || lcb_check_assets(&c) || lcb_check_transfers(&c) ||
        lcb_check_sparse(&c) || lcb_check_probes(&c) ||
        lcb_check_surfel_weights(&c, S_TSGF, S_TSGW, c.m.texel, "the texel caches"))
        return -1;

    lc_lcb_view *v = &f->view;
    v->meta_json = f->meta_text;
    v->meta_len = (size_t)c.sec[S_META]->size;
    v->sh_bands = c.m.sh_bands;
#define LCB_ARR(k) ((const void *)(c.sec[k] ? f->base + c.sec[k]->offset : NULL))
    v->materials = LCB_ARR(S_MATL);
    v->n_materials = (uint32_t)lcb_count(&c, S_MATL);
    v->vertices = LCB_ARR(S_VERT);
    v->n_vertices = (uint32_t)lcb_count(&c, S_VERT);
    v->triangles = LCB_ARR(S_TRIS);
    v->n_triangles = (uint32_t)lcb_count(&c, S_TRIS);
    v->surfels = LCB_ARR(S_SURF);
    v->n_surfels = (uint32_t)lcb_count(&c, S_SURF);
    v->nodes = LCB_ARR(S_NODE);
    v->n_nodes = (uint32_t)lcb_count(&c, S_NODE);
    v->levels = LCB_ARR(S_LEVL);
    v->n_levels = (uint32_t)(lcb_count(&c, S_LEVL) - 1);
    v->caches = LCB_ARR(S_CACH);
    v->n_caches = (uint32_t)lcb_count(&c, S_CACH);
    v->n_texel_caches = (uint32_t)c.m.texel;
    v->lightmap = LCB_ARR(S_LMAP);
    v->lightmap_width = c.m.lm_w;
    v->lightmap_height = c.m.lm_h;
    v->grid = LCB_ARR(S_GRID);
    memcpy(v->grid_dims, c.m.dims, sizeof v->grid_dims);
    memcpy(v->grid_origin, c.m.origin, sizeof v->grid_origin);
    v->grid_cell = c.m.cell;
    v->links = LCB_ARR(S_LINK);
    v->links_per_cache = (uint32_t)c.m.per_cache;
    v->grid_links = LCB_ARR(S_GLNK);
    v->grid_links_per_cache = (uint32_t)c.m.grid_per_cache;
    v->link_sh = LCB_ARR(S_LKSH);
    v->link_sh_bands = (uint32_t)c.m.link_sh;
    v->assets = LCB_ARR(S_ASET);
    v->n_assets = (uint32_t)lcb_count(&c, S_ASET);
    v->asset_vertices = LCB_ARR(S_AVRT);
    v->n_asset_vertices = (uint32_t)lcb_count(&c, S_AVRT);
    v->asset_indices = LCB_ARR(S_AIDX);
    v->n_asset_triangles = (uint32_t)lcb_count(&c, S_AIDX);
    v->transfers = LCB_ARR(S_ATRN);
    v->n_transfers = (uint32_t)lcb_count(&c, S_ATRN);
    v->transfer_data = LCB_ARR(S_ATRD);
    v->transfer_data_size = lcb_count(&c, S_ATRD);
    v->sparse_points = LCB_ARR(S_ASPT);
    v->n_sparse_points = (uint32_t)lcb_count(&c, S_ASPT);
    v->sparse_vertices = LCB_ARR(S_AVNN);
    v->probe_header = LCB_ARR(S_PRBH);
    v->probes = LCB_ARR(S_PRBP);
    v->probe_hits = LCB_ARR(S_PRBR);
    v->probe_clusters = LCB_ARR(S_PRCL);
    v->probe_cluster_probes = LCB_ARR(S_PRCP);
    v->n_probe_cluster_probes = lcb_count(&c, S_PRCP);
    v->probe_basis = LCB_ARR(S_PRCB);
    v->n_probe_basis = lcb_count(&c, S_PRCB);
    v->probe_rows = LCB_ARR(S_PRRW);
    v->probe_u = LCB_ARR(S_PRRU);
    v->n_probe_u = lcb_count(&c, S_PRRU);
    v->probe_unseen_first = LCB_ARR(S_PRUF);
    v->probe_unseen = LCB_ARR(S_PRUS);
    v->texel_surfels_first = LCB_ARR(S_TSGF);
    v->texel_surfels = LCB_ARR(S_TSGW);
#undef LCB_ARR
    return 0;
}

int lc_lcb_open(const char *path, lc_lcb **out, char *err, size_t errlen) {
    lc_lcb *f = NULL;
    int fd = -1;
    if (!out || !path) {
        lc_set_err(err, errlen, "lc_lcb_open: invalid arguments");
        return -1;
    }
    *out = NULL;
    fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        lc_set_err(err, errlen, "cannot open '%s': %s — check the path or re-run lucent-bake", path, strerror(errno));
        goto err;
    }
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        lc_set_err(err, errlen, "'%s' is not a regular file — pass a .lcb written by lucent-bake", path);
        goto err;
    }
    f = calloc(1, sizeof *f);
    if (!f) {
        lc_set_err(err, errlen, "out of memory");
        goto err;
    }
    f->size = (size_t)st.st_size;
    /* A file shorter than the header cannot be mapped usefully (size 0 cannot be mapped at
     * all); the header check rejects it without touching base. */
    if (f->size >= sizeof(lc_lcb_header)) {
        void *m = mmap(NULL, f->size, PROT_READ, MAP_PRIVATE, fd, 0);
        if (m == MAP_FAILED) {
            lc_set_err(err, errlen, "cannot map '%s': %s", path, strerror(errno));
            goto err;
        }
        f->map = m;
        f->map_len = f->size;
        f->base = m;
    }
    close(fd);
    fd = -1;
    if (lcb_load(f, err, errlen) != 0) goto err;
    *out = f;
    return 0;
err:
    if (fd >= 0) close(fd);
    lc_lcb_close(f);
    return -1;
}

int lc_lcb_open_memory(const void *data, size_t len, lc_lcb **out, char *err, size_t errlen) {
    lc_lcb *f = NULL;
    if (!out || (!data && len > 0)) {
        lc_set_err(err, errlen, "lc_lcb_open_memory: invalid arguments");
        return -1;
    }
    *out = NULL;
    f = calloc(1, sizeof *f);
    if (!f) {
        lc_set_err(err, errlen, "out of memory");
        goto err;
    }
    f->size = len;
    f->base = data;
    /* Records are read in place: need 8-byte alignment (uint64 in the table); copy otherwise. */
    if (len > 0 && ((uintptr_t)data % 8) != 0) {
        f->copy = malloc(len);
        if (!f->copy) {
            lc_set_err(err, errlen, "out of memory");
            goto err;
        }
        memcpy(f->copy, data, len);
        f->base = f->copy;
    }
    if (lcb_load(f, err, errlen) != 0) goto err;
    *out = f;
    return 0;
err:
    lc_lcb_close(f);
    return -1;
}

const lc_lcb_view *lc_lcb_get(const lc_lcb *f) { return f ? &f->view : NULL; }

uint32_t lc_lcb_section_count(const lc_lcb *f) { return f ? f->n_sections : 0; }

const lc_lcb_section *lc_lcb_section_at(const lc_lcb *f, uint32_t i) {
    return f && i < f->n_sections ? &f->table[i] : NULL;
}

void lc_lcb_close(lc_lcb *f) {
    if (!f) return;
    if (f->map) munmap(f->map, f->map_len);
    free(f->copy);
    free(f->meta_text);
    free(f);
}
