/* lcb_write: lays sections out in the order added, each at a 64-byte aligned offset with
 * zero padding, streams them through an atomic lc_fs_writer and patches header + table in
 * last (their CRCs depend on the section CRCs, known only after streaming). Every padding
 * and reserved byte is zero, so the same input always gives the same bytes. */
#include <stdlib.h>
#include <string.h>

#include "lcb/lcb.h"
#include "util/crc32.h"
#include "util/fsutil.h"
#include "util/log.h"

typedef struct lcb_wsection {
    char id[4];
    uint32_t record_size;
    const void *data;
    uint64_t count;
} lcb_wsection;

struct lc_lcb_writer {
    lcb_wsection sec[LC_LCB_MAX_SECTIONS];
    uint32_t n;
};

static uint64_t lcb_align(uint64_t x) { return (x + (LC_LCB_ALIGN - 1)) & ~(uint64_t)(LC_LCB_ALIGN - 1); }

lc_lcb_writer *lc_lcb_writer_create(void) { return calloc(1, sizeof(lc_lcb_writer)); }

int lc_lcb_writer_add(lc_lcb_writer *w, const char id[4], uint32_t record_size, const void *data, uint64_t count) {
    if (!w || !id || record_size == 0 || w->n >= LC_LCB_MAX_SECTIONS) return -1;
    if (count > 0 && !data) return -1;
    /* size = count * record_size must fit in 64 bits (and in size_t, to write it). */
    if (count > (uint64_t)SIZE_MAX / record_size) return -1;
    for (uint32_t i = 0; i < w->n; i++)
        if (memcmp(w->sec[i].id, id, 4) == 0) return -1;
    lcb_wsection *s = &w->sec[w->n++];
    memcpy(s->id, id, 4);
    s->record_size = record_size;
    s->data = data;
    s->count = count;
    return 0;
}

int lc_lcb_writer_write(lc_lcb_writer *w, const char *path, char *err, size_t errlen) {
    static const uint8_t zeros[LC_LCB_ALIGN];
    lc_lcb_section table[LC_LCB_MAX_SECTIONS];
    lc_lcb_header hdr;
    lc_fs_writer *fw = NULL;
    if (!w || !path) {
        lc_set_err(err, errlen, "lcb writer: invalid arguments");
        return -1;
    }
    memset(table, 0, sizeof table);
    memset(&hdr, 0, sizeof hdr);

    fw = lc_fs_writer_open(path, err, errlen);
    if (!fw) return -1;
    /* Placeholder for header + table; patched once the section CRCs are known. */
    size_t head_len = sizeof(lc_lcb_header) + (size_t)w->n * sizeof(lc_lcb_section);
    uint64_t pos = 0;
    for (size_t left = head_len; left > 0;) {
        size_t k = left < sizeof zeros ? left : sizeof zeros;
        if (lc_fs_writer_write(fw, zeros, k) != 0) goto io_err;
        left -= k;
    }
    pos = head_len;
    for (uint32_t i = 0; i < w->n; i++) {
        const lcb_wsection *s = &w->sec[i];
        uint64_t off = lcb_align(pos);
        if (off > pos && lc_fs_writer_write(fw, zeros, (size_t)(off - pos)) != 0) goto io_err;
        uint64_t size = s->count * s->record_size;
        if (off < pos || off + size < off) { /* sum of huge sections wraps: cannot be written */
            lc_set_err(err, errlen, "'%s': sections too large for one file", path);
            lc_fs_writer_abort(fw);
            return -1;
        }
        if (size > 0 && lc_fs_writer_write(fw, s->data, (size_t)size) != 0) goto io_err;
        lc_lcb_section *t = &table[i];
        memcpy(t->id, s->id, 4);
        t->record_size = s->record_size;
        t->offset = off;
        t->size = size;
        t->count = s->count;
        t->crc = lc_crc32(0, s->data, (size_t)size);
        pos = off + size;
    }
    /* Pad the end to the alignment too, so an empty last section still lies inside the file. */
    uint64_t file_size = lcb_align(pos);
    if (file_size > pos && lc_fs_writer_write(fw, zeros, (size_t)(file_size - pos)) != 0) goto io_err;

    memcpy(hdr.magic, LC_LCB_MAGIC, 8);
    hdr.version_major = LC_LCB_VERSION_MAJOR;
    hdr.version_minor = LC_LCB_VERSION_MINOR;
    hdr.section_count = w->n;
    hdr.file_size = file_size;
    hdr.table_offset = sizeof(lc_lcb_header);
    hdr.table_crc = lc_crc32(0, table, (size_t)w->n * sizeof(lc_lcb_section));
    hdr.header_crc = lc_crc32(0, &hdr, offsetof(lc_lcb_header, header_crc));
    if (lc_fs_writer_pwrite(fw, &hdr, sizeof hdr, 0) != 0) goto io_err;
    if (w->n > 0 && lc_fs_writer_pwrite(fw, table, (size_t)w->n * sizeof(lc_lcb_section), sizeof hdr) != 0) goto io_err;
    /* commit reports a latched write error (with errno) as well, and frees fw. */
    return lc_fs_writer_commit(fw, err, errlen);
io_err:
    /* The fs writer latched the failure: commit turns it into a message (with errno), removes
     * the temp file and leaves the target untouched. */
    lc_fs_writer_commit(fw, err, errlen);
    return -1;
}

void lc_lcb_writer_release(lc_lcb_writer *w) { free(w); }
