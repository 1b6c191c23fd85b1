/* journal: append-only change log + atomic snapshots (see journal.h). */
#include "journal.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "util/clock.h"
#include "util/fsutil.h"
#include "util/log.h"

#define JOURNAL_MAX_FILE (1ull << 30)   /* refuse to replay more than 1 GiB */
#define JOURNAL_MAX_LINE (4u << 20)     /* one batch line */
#define SNAPSHOT_MAX (64u << 20)

struct lc_journal {
    char *dir, *log_path, *snap_path;
    int fd;
    lc_fsync_mode mode;
    int dirty;
    double last_sync_ms;
    uint64_t bytes;
};

static int journal_replay_line(const char *line, size_t len, size_t lineno, lc_state *state, char *err,
                               size_t errlen) {
    cJSON *root = cJSON_ParseWithLength(line, len);
    const cJSON *rev = root ? cJSON_GetObjectItemCaseSensitive(root, "revision") : NULL;
    if (!cJSON_IsNumber(rev) || rev->valuedouble < 1 || rev->valuedouble > 9007199254740992.0) {
        cJSON_Delete(root);
        lc_set_err(err, errlen, "journal.log line %zu: not a journal record (no revision)", lineno);
        return -1;
    }
    uint64_t revision = (uint64_t)rev->valuedouble;
    cJSON_Delete(root);
    if (revision <= state->revision) return 0; /* already in the snapshot */
    lc_proto_limits lim;
    lc_proto_default_limits(&lim);
    lim.max_message = JOURNAL_MAX_LINE;
    lim.max_batch = 1u << 20;
    lc_proto_request req;
    lc_proto_error perr;
    if (lc_proto_parse_request(line, len, &lim, &req, &perr) != 0) {
        lc_set_err(err, errlen, "journal.log line %zu: %s at %s: %s", lineno, perr.code, perr.pointer, perr.message);
        return -1;
    }
    if (req.type != LC_REQ_BATCH) {
        lc_proto_request_release(&req);
        lc_set_err(err, errlen, "journal.log line %zu: a journal record must be a batch", lineno);
        return -1;
    }
    int rc = lc_state_apply(state, req.ops, req.n_ops, 1, &perr);
    lc_proto_request_release(&req);
    if (rc != 0) {
        lc_set_err(err, errlen, "journal.log line %zu: cannot apply: %s at %s: %s", lineno, perr.code, perr.pointer,
                   perr.message);
        return -1;
    }
    state->revision = revision;
    return 0;
}

static char *journal_join(const char *dir, const char *name) {
    size_t n = strlen(dir) + strlen(name) + 2;
    char *p = malloc(n);
    if (p) snprintf(p, n, "%s/%s", dir, name);
    return p;
}

lc_journal *lc_journal_open(const char *dir, lc_fsync_mode mode, lc_state *state, char *err, size_t errlen) {
    lc_journal *j = calloc(1, sizeof *j);
    char *text = NULL;
    if (!j) goto oom;
    j->fd = -1;
    j->mode = mode;
    j->dir = strdup(dir);
    j->log_path = journal_join(dir, "journal.log");
    j->snap_path = journal_join(dir, "snapshot.json");
    if (!j->dir || !j->log_path || !j->snap_path) goto oom;
    if (mkdir(dir, 0755) != 0 && errno != EEXIST) {
        lc_set_err(err, errlen, "state dir '%s': %s", dir, strerror(errno));
        goto err;
    }
    /* 1. snapshot */
    size_t len = 0;
    if (access(j->snap_path, F_OK) == 0) {
        text = lc_fs_read(j->snap_path, SNAPSHOT_MAX, &len, err, errlen);
        if (!text) goto err;
        lc_proto_parsed_state ps;
        lc_proto_error perr;
        if (lc_proto_parse_state(text, len, &ps, &perr) != 0) {
            lc_set_err(err, errlen, "%s: %s at %s: %s (move the file away to start empty)", j->snap_path, perr.code,
                       perr.pointer, perr.message);
            goto err;
        }
        int rc = lc_state_restore(state, &ps, &perr);
        lc_proto_parsed_state_free(&ps);
        if (rc != 0) {
            lc_set_err(err, errlen, "%s: %s", j->snap_path, perr.message);
            goto err;
        }
        free(text);
        text = NULL;
    }
    /* 2. journal */
    j->fd = open(j->log_path, O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (j->fd < 0) {
        lc_set_err(err, errlen, "cannot open '%s': %s", j->log_path, strerror(errno));
        goto err;
    }
    text = lc_fs_read(j->log_path, JOURNAL_MAX_FILE, &len, err, errlen);
    if (!text) goto err;
    size_t pos = 0, lineno = 0, good_end = 0;
    while (pos < len) {
        const char *nl = memchr(text + pos, '\n', len - pos);
        lineno++;
        if (!nl) { /* torn final append: the change was never acknowledged */
            lc_warn("journal", "%s: dropping an incomplete last line (%zu bytes) left by a crash", j->log_path,
                    len - pos);
            break;
        }
        size_t line_len = (size_t)(nl - (text + pos));
        if (line_len > 0 && journal_replay_line(text + pos, line_len, lineno, state, err, errlen) != 0) goto err;
        pos += line_len + 1;
        good_end = pos;
    }
    if (good_end < len && ftruncate(j->fd, (off_t)good_end) != 0) {
        lc_set_err(err, errlen, "cannot truncate '%s': %s", j->log_path, strerror(errno));
        goto err;
    }
    j->bytes = good_end;
    if (lseek(j->fd, (off_t)good_end, SEEK_SET) < 0) {
        lc_set_err(err, errlen, "seek '%s': %s", j->log_path, strerror(errno));
        goto err;
    }
    free(text);
    j->last_sync_ms = lc_clock_ms();
    return j;
oom:
    lc_set_err(err, errlen, "out of memory opening the journal");
err:
    free(text);
    lc_journal_close(j);
    return NULL;
}

static int journal_write_all(int fd, const char *p, size_t n) {
    while (n) {
        ssize_t w = write(fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return -1;
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

int lc_journal_append(lc_journal *j, const lc_proto_op *ops, uint32_t n_ops, uint64_t revision, char *err,
                      size_t errlen) {
    /* {"type":"batch","revision":N,"ops":[op,op]}\n */
    size_t cap = 64, len;
    char **parts = calloc(n_ops ? n_ops : 1, sizeof *parts);
    char *line = NULL;
    int rc = -1;
    if (!parts) goto oom;
    for (uint32_t i = 0; i < n_ops; i++) {
        parts[i] = lc_proto_build_op(&ops[i]);
        if (!parts[i]) goto oom;
        cap += strlen(parts[i]) + 1;
    }
    line = malloc(cap);
    if (!line) goto oom;
    len = (size_t)snprintf(line, cap, "{\"type\":\"batch\",\"revision\":%llu,\"ops\":[", (unsigned long long)revision);
    for (uint32_t i = 0; i < n_ops; i++) {
        size_t pl = strlen(parts[i]);
        if (i) line[len++] = ',';
        memcpy(line + len, parts[i], pl);
        len += pl;
    }
    line[len++] = ']';
    line[len++] = '}';
    line[len++] = '\n';
    if (journal_write_all(j->fd, line, len) != 0) {
        lc_set_err(err, errlen, "journal write failed: %s (disk full?)", strerror(errno));
        goto done;
    }
    j->bytes += len;
    if (j->mode == LC_FSYNC_ALWAYS) {
        if (fdatasync(j->fd) != 0) {
            lc_set_err(err, errlen, "journal fsync failed: %s", strerror(errno));
            goto done;
        }
        j->last_sync_ms = lc_clock_ms();
    } else {
        j->dirty = 1;
    }
    rc = 0;
    goto done;
oom:
    lc_set_err(err, errlen, "out of memory writing the journal");
done:
    if (parts)
        for (uint32_t i = 0; i < n_ops; i++) free(parts[i]);
    free(parts);
    free(line);
    return rc;
}

void lc_journal_tick(lc_journal *j) {
    if (!j || !j->dirty) return;
    double now = lc_clock_ms();
    if (now - j->last_sync_ms < 1000) return;
    if (fdatasync(j->fd) != 0) lc_error("journal", "fsync failed: %s", strerror(errno));
    j->dirty = 0;
    j->last_sync_ms = now;
}

int lc_journal_compact(lc_journal *j, const lc_state *state, char *err, size_t errlen) {
    lc_proto_state ps;
    lc_proto_material_state *mats = NULL;
    if (lc_state_to_proto(state, &ps, &mats) != 0) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    char *text = lc_proto_build_state(NULL, &ps);
    free(mats);
    if (!text) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    int rc = lc_fs_write_atomic(j->snap_path, text, strlen(text), err, errlen);
    free(text);
    if (rc != 0) return -1;
    /* The snapshot now holds everything: empty the journal. */
    if (ftruncate(j->fd, 0) != 0 || lseek(j->fd, 0, SEEK_SET) < 0 || fdatasync(j->fd) != 0) {
        lc_set_err(err, errlen, "truncating '%s': %s", j->log_path, strerror(errno));
        return -1;
    }
    j->bytes = 0;
    j->dirty = 0;
    return 0;
}

uint64_t lc_journal_bytes(const lc_journal *j) { return j->bytes; }

void lc_journal_close(lc_journal *j) {
    if (!j) return;
    if (j->fd >= 0) {
        if (j->dirty) fdatasync(j->fd);
        close(j->fd);
    }
    free(j->dir);
    free(j->log_path);
    free(j->snap_path);
    free(j);
}
