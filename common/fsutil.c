#include "util/fsutil.h"

#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "util/log.h"

struct lc_fs_writer {
    int fd;
    size_t offset;
    int failed_errno;
    char *path, *tmp_path;
};

char *lc_fs_read(const char *path, size_t max_bytes, size_t *len_out, char *err, size_t errlen) {
    char *buf = NULL;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        lc_set_err(err, errlen, "cannot open '%s': %s", path, strerror(errno));
        return NULL;
    }
    struct stat st;
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        lc_set_err(err, errlen, "'%s' is not a regular file", path);
        goto err;
    }
    if ((size_t)st.st_size > max_bytes) {
        lc_set_err(err, errlen, "'%s' is %lld bytes, the limit is %zu", path, (long long)st.st_size, max_bytes);
        goto err;
    }
    buf = malloc((size_t)st.st_size + 1);
    if (!buf) {
        lc_set_err(err, errlen, "out of memory reading '%s'", path);
        goto err;
    }
    size_t got = 0;
    while (got < (size_t)st.st_size) {
        ssize_t n = read(fd, buf + got, (size_t)st.st_size - got);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            lc_set_err(err, errlen, "read error on '%s': %s", path, n < 0 ? strerror(errno) : "short file");
            goto err;
        }
        got += (size_t)n;
    }
    buf[got] = 0;
    close(fd);
    if (len_out) *len_out = got;
    return buf;
err:
    free(buf);
    close(fd);
    return NULL;
}

lc_fs_writer *lc_fs_writer_open(const char *path, char *err, size_t errlen) {
    lc_fs_writer *w = calloc(1, sizeof *w);
    if (!w) goto oom;
    w->path = strdup(path);
    size_t n = strlen(path) + 32;
    w->tmp_path = malloc(n);
    if (!w->path || !w->tmp_path) goto oom;
    snprintf(w->tmp_path, n, "%s.tmp.%ld", path, (long)getpid());
    w->fd = open(w->tmp_path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (w->fd < 0) {
        lc_set_err(err, errlen, "cannot create '%s': %s", w->tmp_path, strerror(errno));
        free(w->path);
        free(w->tmp_path);
        free(w);
        return NULL;
    }
    return w;
oom:
    if (w) {
        free(w->path);
        free(w->tmp_path);
        free(w);
    }
    lc_set_err(err, errlen, "out of memory");
    return NULL;
}

static int fs_pwrite_all(int fd, const void *data, size_t len, size_t offset) {
    const char *p = data;
    while (len) {
        ssize_t n = pwrite(fd, p, len, (off_t)offset);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return n < 0 ? errno : EIO;
        p += n;
        len -= (size_t)n;
        offset += (size_t)n;
    }
    return 0;
}

int lc_fs_writer_write(lc_fs_writer *w, const void *data, size_t len) {
    if (w->failed_errno) return -1;
    int e = fs_pwrite_all(w->fd, data, len, w->offset);
    if (e) {
        w->failed_errno = e;
        return -1;
    }
    w->offset += len;
    return 0;
}

size_t lc_fs_writer_tell(const lc_fs_writer *w) { return w->offset; }

int lc_fs_writer_pwrite(lc_fs_writer *w, const void *data, size_t len, size_t offset) {
    if (w->failed_errno) return -1;
    int e = fs_pwrite_all(w->fd, data, len, offset);
    if (e) w->failed_errno = e;
    return e ? -1 : 0;
}

static void fs_writer_free(lc_fs_writer *w) {
    free(w->path);
    free(w->tmp_path);
    free(w);
}

int lc_fs_writer_commit(lc_fs_writer *w, char *err, size_t errlen) {
    int rc = -1;
    if (w->failed_errno) {
        lc_set_err(err, errlen, "write to '%s' failed: %s", w->tmp_path, strerror(w->failed_errno));
        goto err;
    }
    if (fsync(w->fd) != 0) {
        lc_set_err(err, errlen, "fsync '%s' failed: %s", w->tmp_path, strerror(errno));
        goto err;
    }
    if (close(w->fd) != 0) {
        w->fd = -1;
        lc_set_err(err, errlen, "close '%s' failed: %s", w->tmp_path, strerror(errno));
        goto err;
    }
    w->fd = -1;
    if (rename(w->tmp_path, w->path) != 0) {
        lc_set_err(err, errlen, "rename to '%s' failed: %s", w->path, strerror(errno));
        goto err;
    }
    /* Make the rename itself durable. */
    char *dir_copy = strdup(w->path);
    if (dir_copy) {
        int dfd = open(dirname(dir_copy), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (dfd >= 0) {
            fsync(dfd);
            close(dfd);
        }
        free(dir_copy);
    }
    fs_writer_free(w);
    return 0;
err:
    if (w->fd >= 0) close(w->fd);
    unlink(w->tmp_path);
    fs_writer_free(w);
    return rc;
}

void lc_fs_writer_abort(lc_fs_writer *w) {
    if (!w) return;
    if (w->fd >= 0) close(w->fd);
    unlink(w->tmp_path);
    fs_writer_free(w);
}

int lc_fs_write_atomic(const char *path, const void *data, size_t len, char *err, size_t errlen) {
    lc_fs_writer *w = lc_fs_writer_open(path, err, errlen);
    if (!w) return -1;
    if (lc_fs_writer_write(w, data, len) != 0) {
        /* commit reports the stored errno */
    }
    return lc_fs_writer_commit(w, err, errlen);
}

void lc_fs_beside_exe(const char *rel, const char *fallback, char *out, size_t outlen) {
    char exe[4096];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof exe);
    char *slash = NULL;
    if (n > 0 && (size_t)n < sizeof exe) { /* else unreadable or cut */
        exe[n] = 0;
        slash = strrchr(exe, '/');
    }
    if (slash) {
        /* the link is canonical (no symlinks, no ..): each leading ../ drops one directory */
        size_t dir = (size_t)(slash - exe);
        for (char *up; !strncmp(rel, "../", 3) && (up = memrchr(exe, '/', dir)); rel += 3) dir = (size_t)(up - exe);
        int len = snprintf(out, outlen, "%.*s/%s", (int)dir, exe, rel);
        if (len >= 0 && (size_t)len < outlen) return;
    }
    snprintf(out, outlen, "%s", fallback);
}
