/* journal: append-only change log + atomic snapshots (see journal.h). */
#include "journal.h"

#include <cjson/cJSON.h>
#include <errno.h>
#include <fcntl.h>
#include <libgen.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "util/clock.h"
#include "util/fsutil.h"
#include "util/log.h"

#define JOURNAL_MAX_FILE (1ull << 30) /* refuse to replay more than 1 GiB */
#define JOURNAL_MAX_LINE (4u << 20)   /* one batch line */
#define SNAPSHOT_MAX (64u << 20)

struct lc_journal {
    char *dir, *log_path, *snap_path;
    int fd;
    lc_fsync_mode mode;
    int dirty;
    int broken;           /* a failed fsync: appends refused until a compaction succeeds */
    char broken_why[256]; /* what broke it, for the refusals */
    double last_sync_ms, last_repair_ms;
    uint64_t bytes;    /* the last good length: everything below it is complete, durable records */
    uint64_t failures; /* failed appends and everysec fsyncs (lc_journal_failures) */
};

/* The revision a journal line names, or 0 when it is not a record with one. */
static uint64_t journal_line_revision(const char *line, size_t len) {
    cJSON *root = cJSON_ParseWithLength(line, len);
    const cJSON *rev = root ? cJSON_GetObjectItemCaseSensitive(root, "revision") : NULL;
    uint64_t revision = 0;
    if (cJSON_IsNumber(rev) && rev->valuedouble >= 1 && rev->valuedouble <= 9007199254740992.0)
        revision = (uint64_t)rev->valuedouble;
    cJSON_Delete(root);
    return revision;
}

static int journal_replay_line(const char *path, const char *line, size_t len, size_t lineno, lc_state *state,
                               char *err, size_t errlen) {
    uint64_t revision = journal_line_revision(line, len);
    if (!revision) {
        lc_set_err(err, errlen, "%s line %zu: not a journal record (no revision)", path, lineno);
        return -1;
    }
    if (revision <= state->revision) return 0; /* already in the snapshot */
    lc_proto_limits lim;
    lc_proto_default_limits(&lim);
    lim.max_message = JOURNAL_MAX_LINE;
    lim.max_batch = 1u << 20;
    lc_proto_request req;
    lc_proto_error perr;
    if (lc_proto_parse_request(line, len, &lim, &req, &perr) != 0) {
        lc_set_err(err, errlen, "%s line %zu: %s at %s: %s", path, lineno, perr.code, perr.pointer, perr.message);
        return -1;
    }
    if (req.type != LC_REQ_BATCH) {
        lc_proto_request_release(&req);
        lc_set_err(err, errlen, "%s line %zu: a journal record must be a batch", path, lineno);
        return -1;
    }
    int rc = lc_state_apply(state, req.ops, req.n_ops, 1, &perr);
    lc_proto_request_release(&req);
    if (rc != 0) {
        lc_set_err(err, errlen, "%s line %zu: cannot apply: %s at %s: %s", path, lineno, perr.code, perr.pointer,
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

/* Makes a new entry of `dir` durable: without this a crash can lose journal.log itself
 * (and every change fsync'd into it), since fdatasync on a file does not cover its name. */
static int journal_fsync_dir(const char *dir, char *err, size_t errlen) {
    int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) {
        lc_set_err(err, errlen, "cannot open the directory '%s' to fsync it: %s", dir, strerror(errno));
        return -1;
    }
    int rc = fsync(fd), e = errno;
    close(fd);
    /* EINVAL: a file system that cannot fsync directories; nothing more can be done there. */
    if (rc != 0 && e != EINVAL) {
        lc_set_err(err, errlen, "fsync of the directory '%s' failed: %s (check the disk)", dir, strerror(e));
        return -1;
    }
    return 0;
}

/* A new state dir must survive a crash too: fsync the directory that holds it. */
static int journal_fsync_parent(const char *dir, char *err, size_t errlen) {
    char *copy = strdup(dir);
    if (!copy) {
        lc_set_err(err, errlen, "out of memory");
        return -1;
    }
    int rc = journal_fsync_dir(dirname(copy), err, errlen);
    free(copy);
    return rc;
}

/* Logs once (a broken journal stays broken until a compaction succeeds, however many
 * changes it refuses meanwhile). */
static void journal_break(lc_journal *j, const char *what, int e) {
    if (j->broken) return;
    j->broken = 1;
    snprintf(j->broken_why, sizeof j->broken_why, "%s (%s)", what, strerror(e));
    lc_error("journal",
             "%s: %s: %s; refusing changes until a snapshot of the state succeeds (retried every "
             "second; check the disk and the free space of '%s')",
             j->log_path, what, strerror(e), j->dir);
}

/* Cuts the file back to its last good length and puts the offset there, so a failed
 * append leaves nothing for the next one to land after (a partial line followed by a
 * record would make the journal unreadable at the next start). */
static int journal_rollback(lc_journal *j) {
    if (ftruncate(j->fd, (off_t)j->bytes) != 0 || lseek(j->fd, (off_t)j->bytes, SEEK_SET) < 0) return -1;
    return 0;
}

/* Counts what [from, len) of the journal text holds, for the --recover report. */
static void journal_describe_dropped(const char *text, size_t from, size_t len, lc_journal_dropped *d) {
    d->bytes = len - from;
    for (size_t p = from; p < len;) {
        const char *nl = memchr(text + p, '\n', len - p);
        size_t l = nl ? (size_t)(nl - (text + p)) : len - p;
        uint64_t r = journal_line_revision(text + p, l);
        d->lines++;
        if (!r) {
            d->unreadable++;
        } else {
            if (!d->rev_min || r < d->rev_min) d->rev_min = r;
            if (r > d->rev_max) d->rev_max = r;
        }
        p += l + (nl ? 1 : 0);
    }
}

/* Keeps the dropped bytes in DIR/journal.dropped.<unix time>[.N] (never overwriting an
 * earlier one): --recover sets data aside, it does not destroy it. */
static int journal_save_dropped(lc_journal *j, const char *data, size_t len, lc_journal_dropped *d, char *err,
                                size_t errlen) {
    long long now = (long long)time(NULL);
    for (int n = 0; n < 100; n++) {
        if (n == 0) snprintf(d->saved, sizeof d->saved, "%s/journal.dropped.%lld", j->dir, now);
        else snprintf(d->saved, sizeof d->saved, "%s/journal.dropped.%lld.%d", j->dir, now, n);
        if (access(d->saved, F_OK) != 0) break;
    }
    if (lc_fs_write_atomic(d->saved, data, len, err, errlen) != 0) {
        d->saved[0] = 0;
        return -1;
    }
    return 0;
}

static lc_journal *journal_open(const char *dir, lc_fsync_mode mode, lc_state *state, int recover,
                                lc_journal_dropped *dropped, char *err, size_t errlen) {
    lc_journal *j = calloc(1, sizeof *j);
    char *text = NULL;
    lc_journal_dropped drop;
    memset(&drop, 0, sizeof drop);
    if (!j) goto oom;
    j->fd = -1;
    j->mode = mode;
    j->dir = strdup(dir);
    j->log_path = journal_join(dir, "journal.log");
    j->snap_path = journal_join(dir, "snapshot.json");
    if (!j->dir || !j->log_path || !j->snap_path) goto oom;
    if (mkdir(dir, 0755) == 0) {
        if (journal_fsync_parent(dir, err, errlen) != 0) goto err;
    } else if (errno != EEXIST) {
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
    /* Its directory entry durable before anything goes in it: at every start, which also
     * covers a journal.log created by a start that crashed before this fsync. */
    if (journal_fsync_dir(dir, err, errlen) != 0) goto err;
    text = lc_fs_read(j->log_path, JOURNAL_MAX_FILE, &len, err, errlen);
    if (!text) goto err;
    size_t pos = 0, lineno = 0, good_end = 0;
    while (pos < len) {
        const char *nl = memchr(text + pos, '\n', len - pos);
        lineno++;
        if (!nl) { /* torn final append: the change was never acknowledged */
            lc_warn("journal", "%s: dropping an incomplete last line (%zu bytes) left by a crash", j->log_path,
                    len - pos);
            snprintf(drop.reason, sizeof drop.reason, "%s line %zu: incomplete (a crash during an append)", j->log_path,
                     lineno);
            drop.first_line = lineno;
            break;
        }
        size_t line_len = (size_t)(nl - (text + pos));
        if (line_len > 0 &&
            journal_replay_line(j->log_path, text + pos, line_len, lineno, state, drop.reason, sizeof drop.reason) !=
                0) {
            /* Replaying past a bad line could apply changes that depended on it, so the
             * valid prefix is all that can be restored; the operator decides. */
            if (!recover) {
                lc_set_err(err, errlen,
                           "%s; the lines before it are intact: start lucentd once with --recover to "
                           "restore them and set this line and the rest of the file aside",
                           drop.reason);
                goto err;
            }
            drop.first_line = lineno;
            break;
        }
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
    j->last_sync_ms = lc_clock_ms();
    if (recover && good_end < len) {
        /* Set the rest aside, then make the restored state the whole truth (snapshot +
         * empty journal) so the next start needs no --recover. */
        journal_describe_dropped(text, good_end, len, &drop);
        if (journal_save_dropped(j, text + good_end, len - good_end, &drop, err, errlen) != 0) goto err;
        char cerr[512];
        if (lc_journal_compact(j, state, cerr, sizeof cerr) != 0) {
            lc_set_err(err, errlen, "--recover: cannot write the recovered state: %s (the dropped part is kept in %s)",
                       cerr, drop.saved);
            goto err;
        }
        char revs[96];
        if (drop.rev_max)
            snprintf(revs, sizeof revs, "revisions %llu..%llu", (unsigned long long)drop.rev_min,
                     (unsigned long long)drop.rev_max);
        else snprintf(revs, sizeof revs, "no readable revision");
        lc_warn("journal",
                "--recover: %s; dropped it and the rest of the file: %llu lines (%llu bytes; %s, %llu lines without "
                "one), kept in %s; the state is revision %llu, rewritten as the snapshot (the next start needs no "
                "--recover)",
                drop.reason, (unsigned long long)drop.lines, (unsigned long long)drop.bytes, revs,
                (unsigned long long)drop.unreadable, drop.saved, (unsigned long long)state->revision);
    } else if (recover) {
        memset(&drop, 0, sizeof drop);
        lc_info("journal", "--recover: %s replays completely, nothing to drop", j->log_path);
    }
    free(text);
    if (dropped) *dropped = drop;
    return j;
oom:
    lc_set_err(err, errlen, "out of memory opening the journal");
err:
    free(text);
    lc_journal_close(j);
    return NULL;
}

lc_journal *lc_journal_open(const char *dir, lc_fsync_mode mode, lc_state *state, char *err, size_t errlen) {
    return journal_open(dir, mode, state, 0, NULL, err, errlen);
}

lc_journal *lc_journal_recover(const char *dir, lc_fsync_mode mode, lc_state *state, lc_journal_dropped *dropped,
                               char *err, size_t errlen) {
    return journal_open(dir, mode, state, 1, dropped, err, errlen);
}

static int journal_write_all(int fd, const char *p, size_t n) {
    while (n) {
        ssize_t w = write(fd, p, n);
        if (w < 0 && errno == EINTR) continue;
        if (w == 0) errno = EIO;
        if (w <= 0) return -1;
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

char *lc_journal_record(const lc_proto_op *ops, uint32_t n_ops, uint64_t revision, size_t *out_len) {
    /* {"type":"batch","revision":N,"ops":[op,op]}\n */
    size_t cap = 64, len;
    char **parts = calloc(n_ops ? n_ops : 1, sizeof *parts);
    char *line = NULL;
    if (!parts) goto done;
    for (uint32_t i = 0; i < n_ops; i++) {
        if (!(parts[i] = lc_proto_build_op(&ops[i]))) goto done;
        cap += strlen(parts[i]) + 1;
    }
    if (!(line = malloc(cap))) goto done;
    len = revision
        ? (size_t)snprintf(line, cap, "{\"type\":\"batch\",\"revision\":%llu,\"ops\":[", (unsigned long long)revision)
        : (size_t)snprintf(line, cap, "{\"type\":\"batch\",\"ops\":[");
    for (uint32_t i = 0; i < n_ops; i++) {
        size_t pl = strlen(parts[i]);
        if (i) line[len++] = ',';
        memcpy(line + len, parts[i], pl);
        len += pl;
    }
    line[len++] = ']';
    line[len++] = '}';
    line[len++] = '\n';
    line[len] = 0;
    *out_len = len;
done:
    if (parts)
        for (uint32_t i = 0; i < n_ops; i++) free(parts[i]);
    free(parts);
    return line;
}

int lc_journal_append(lc_journal *j, const lc_proto_op *ops, uint32_t n_ops, uint64_t revision, char *err,
                      size_t errlen) {
    if (j->broken) {
        lc_set_err(err, errlen,
                   "the journal refuses changes since %s; they resume once a snapshot of the state "
                   "succeeds (check the disk of '%s')",
                   j->broken_why, j->dir);
        return -1;
    }
    size_t len = 0;
    int rc = -1;
    char *line = lc_journal_record(ops, n_ops, revision, &len);
    if (!line) {
        lc_set_err(err, errlen, "out of memory writing the journal");
        return -1;
    }
    if (journal_write_all(j->fd, line, len) != 0) {
        int e = errno;
        j->failures++;
        /* A short write left part of the line: cut it off, or the journal ends unreadable. */
        if (journal_rollback(j) != 0) journal_break(j, "a failed append could not be cut off", errno);
        lc_set_err(err, errlen, "journal write failed: %s (disk full? free space in '%s')", strerror(e), j->dir);
        goto done;
    }
    if (j->mode == LC_FSYNC_ALWAYS) {
        if (fdatasync(j->fd) != 0) {
            int e = errno;
            j->failures++;
            /* Whether the line reached the disk is unknown, and so is what the page cache
             * still holds (a later fsync may succeed over pages the kernel dropped): cut
             * the line off and trust only a fresh snapshot from here on. */
            (void)journal_rollback(j);
            journal_break(j, "fdatasync failed", e);
            lc_set_err(err, errlen,
                       "journal fsync failed: %s; changes are refused until a snapshot succeeds "
                       "(check the disk of '%s')",
                       strerror(e), j->dir);
            goto done;
        }
        j->last_sync_ms = lc_clock_ms();
    } else {
        j->dirty = 1;
    }
    j->bytes += len; /* only now: a failed append leaves the last good length */
    rc = 0;
done:
    free(line);
    return rc;
}

void lc_journal_tick(lc_journal *j, const lc_state *state) {
    if (!j) return;
    double now = lc_clock_ms();
    if (j->dirty && !j->broken && now - j->last_sync_ms >= 1000) {
        if (fdatasync(j->fd) != 0) {
            int e = errno;
            j->failures++;
            /* These lines were acknowledged already (everysec): keep them. The state holds
             * them, and the compaction below makes them durable through the snapshot. */
            journal_break(j, "fdatasync of the last second's changes failed", e);
        }
        j->dirty = 0;
        j->last_sync_ms = now;
    }
    if (j->broken && state && now - j->last_repair_ms >= 1000) {
        char err[512];
        j->last_repair_ms = now;
        if (lc_journal_compact(j, state, err, sizeof err) != 0) lc_debug("journal", "snapshot retry: %s", err);
    }
}

char *lc_journal_state_text(const lc_state *state) {
    lc_proto_state ps;
    lc_proto_material_state *mats = NULL;
    if (lc_state_to_proto(state, &ps, &mats) != 0) return NULL;
    char *text = lc_proto_build_state(NULL, &ps);
    free(mats);
    return text;
}

int lc_journal_compact(lc_journal *j, const lc_state *state, char *err, size_t errlen) {
    int rc = -1;
    char *text = lc_journal_state_text(state);
    if (!text) goto oom;
    if (lc_fs_write_atomic(j->snap_path, text, strlen(text), err, errlen) != 0) goto done;
    /* The snapshot now holds everything: empty the journal. */
    if (ftruncate(j->fd, 0) != 0) {
        lc_set_err(err, errlen, "truncating '%s': %s", j->log_path, strerror(errno));
        goto done;
    }
    j->bytes = 0;
    j->dirty = 0;
    if (lseek(j->fd, 0, SEEK_SET) < 0) {
        /* Appends would land past a hole: only a later compaction can fix that. */
        journal_break(j, "cannot seek the emptied journal", errno);
        lc_set_err(err, errlen, "seek '%s': %s", j->log_path, strerror(errno));
        goto done;
    }
    if (fdatasync(j->fd) != 0) {
        int e = errno;
        journal_break(j, "fdatasync of the emptied journal failed", e);
        lc_set_err(err, errlen, "fsync '%s': %s (check the disk)", j->log_path, strerror(e));
        goto done;
    }
    if (j->broken) {
        j->broken = 0;
        lc_warn("journal",
                "%s: recovered: the snapshot holds every acknowledged change and the journal is empty; "
                "accepting changes again",
                j->log_path);
    }
    rc = 0;
    goto done;
oom:
    lc_set_err(err, errlen, "out of memory writing the snapshot");
done:
    free(text);
    return rc;
}

uint64_t lc_journal_bytes(const lc_journal *j) { return j->bytes; }

int lc_journal_broken(const lc_journal *j) { return j ? j->broken : 0; }

uint64_t lc_journal_failures(const lc_journal *j) { return j ? j->failures : 0; }

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
