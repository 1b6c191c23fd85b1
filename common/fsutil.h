/* fsutil: whole-file reads with a size cap, crash-safe writes (temp file, fsync, rename,
 * fsync of the directory), so a crash mid-write leaves the previous file intact. */
#ifndef LC_FSUTIL_H
#define LC_FSUTIL_H
#include <stddef.h>

/* Reads path into a malloc'd, NUL-terminated buffer (caller frees). Refuses files larger
 * than max_bytes. Returns NULL with err set. */
char *lc_fs_read(const char *path, size_t max_bytes, size_t *len_out, char *err, size_t errlen);

/* Streaming atomic writer. */
typedef struct lc_fs_writer lc_fs_writer;
lc_fs_writer *lc_fs_writer_open(const char *path, char *err, size_t errlen);
int lc_fs_writer_write(lc_fs_writer *w, const void *data, size_t len);
/* Current write offset. */
size_t lc_fs_writer_tell(const lc_fs_writer *w);
/* Writes at an absolute offset already written (to patch a header). */
int lc_fs_writer_pwrite(lc_fs_writer *w, const void *data, size_t len, size_t offset);
/* fsync + rename into place. Frees w. Returns 0 or -1 with err set (the target is untouched). */
int lc_fs_writer_commit(lc_fs_writer *w, char *err, size_t errlen);
/* Drops the temp file. Frees w. NULL-safe. */
void lc_fs_writer_abort(lc_fs_writer *w);

/* Writes a whole buffer atomically. */
int lc_fs_write_atomic(const char *path, const void *data, size_t len, char *err, size_t errlen);

/* Resolves rel (e.g. "../share/lucent/cornell.lcb") against the directory of the running
 * executable (/proc/self/exe), so an installed prefix, a relocated copy of one and the build
 * tree (which mirrors the install layout) each find their own files. Writes fallback when
 * the executable's path cannot be read or the result does not fit. */
void lc_fs_beside_exe(const char *rel, const char *fallback, char *out, size_t outlen);

#endif
