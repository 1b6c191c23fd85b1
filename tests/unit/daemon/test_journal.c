/* Journal failure paths (issue 13, item 3). A failed append — a short write (RLIMIT_FSIZE:
 * part of the line, then EFBIG, as on a full disk) or an fdatasync error — leaves the file at
 * its last good length and advances nothing, so the retried change (same revision) replays
 * exactly once; a failed fsync breaks the journal: changes are refused until a compaction
 * succeeds (lc_journal_compact, or lc_journal_tick's once-a-second retry), in always and
 * everysec mode, with lc_journal_broken / lc_journal_failures telling /metrics; creating
 * journal.log fsyncs the state dir; a corrupt complete line in the middle refuses the start
 * naming the file, the line and --recover, and lc_journal_recover restores the valid prefix,
 * reports and keeps what it dropped and leaves a journal that opens cleanly. */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include "../engine/engine_fixture.h"
#include "check.h"
#include "journal.h"
#include "state.h"

/* Test hooks: lc_daemon is linked in statically, so these definitions take the place of
 * libc's for the journal. fdatasync fails with EIO while hook_fdatasync_fail > 0 (one per
 * call); fsync counts the calls on the directory whose inode is hook_dir_ino. */
static int hook_fdatasync_fail;
static ino_t hook_dir_ino;
static int hook_dir_fsyncs;

int fdatasync(int fd) {
    if (hook_fdatasync_fail > 0) {
        hook_fdatasync_fail--;
        errno = EIO;
        return -1;
    }
    return (int)syscall(SYS_fdatasync, fd);
}

int fsync(int fd) {
    struct stat st;
    if (hook_dir_ino && fstat(fd, &st) == 0 && S_ISDIR(st.st_mode) && st.st_ino == hook_dir_ino) hook_dir_fsyncs++;
    return (int)syscall(SYS_fsync, fd);
}

static const lc_lcb *test_bake;
static const lc_state_limits test_limits = {.max_lights = 64, .max_objects = 4};

static lc_proto_op light_op(const char *id) {
    lc_proto_op op;
    memset(&op, 0, sizeof op);
    op.type = LC_REQ_LIGHT_SET;
    snprintf(op.light.id, sizeof op.light.id, "%s", id);
    op.light.type = LC_PLIGHT_POINT;
    op.light.color[0] = op.light.color[1] = op.light.color[2] = 1;
    op.light.intensity = 1;
    op.light.position[1] = 0.5f;
    return op;
}

/* What server_change does: apply on the state, journal it, undo the state when the
 * journal refuses (the next change then gets the same revision). 0 ok, -1 refused. */
static int change(lc_journal *j, lc_state *s, const char *light_id, char *err, size_t errlen) {
    lc_state before;
    lc_proto_error e;
    lc_proto_op op = light_op(light_id);
    if (lc_state_clone(&before, s) != 0) return -2;
    if (lc_state_apply(s, &op, 1, 1, &e) != 0) {
        lc_state_release(&before);
        snprintf(err, errlen, "apply: %s", e.message);
        return -2;
    }
    if (lc_journal_append(j, &op, 1, s->revision, err, errlen) != 0) {
        lc_state_release(s);
        *s = before;
        return -1;
    }
    lc_state_release(&before);
    return 0;
}

static int has_light(const lc_state *s, const char *id) {
    for (uint32_t i = 0; i < s->n_lights; i++)
        if (!strcmp(s->lights[i].id, id)) return 1;
    return 0;
}

static long long file_size(const char *dir, const char *name) {
    char path[256];
    struct stat st;
    snprintf(path, sizeof path, "%s/%s", dir, name);
    return stat(path, &st) == 0 ? (long long)st.st_size : -1;
}

static char *slurp(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    char *buf = malloc(1 << 20);
    *len = buf ? fread(buf, 1, (1 << 20) - 1, f) : 0;
    fclose(f);
    if (buf) buf[*len] = 0;
    return buf;
}

/* The revisions of journal.log's lines, comma-separated ("?" for a line that is not a
 * record), e.g. "1,2,3". */
static const char *journal_revs(const char *dir, char *out, size_t cap) {
    char path[256];
    size_t len, n = 0;
    snprintf(path, sizeof path, "%s/journal.log", dir);
    char *text = slurp(path, &len);
    out[0] = 0;
    for (char *line = text; text && line < text + len;) {
        char *nl = memchr(line, '\n', (size_t)(text + len - line));
        if (nl) *nl = 0;
        const char *r = strncmp(line, "{\"type\":\"batch\",\"revision\":", 27) == 0 ? line + 27 : NULL;
        n += (size_t)snprintf(out + n, cap - n, "%s", n ? "," : "");
        if (r) n += (size_t)snprintf(out + n, cap - n, "%llu", strtoull(r, NULL, 10));
        else n += (size_t)snprintf(out + n, cap - n, "?");
        if (!nl || n >= cap) break;
        line = nl + 1;
    }
    free(text);
    return out;
}

/* Restores a fresh state from dir with a plain open, as the next start would. */
static lc_journal *reopen(const char *dir, lc_fsync_mode mode, lc_state *s, char *err, size_t errlen) {
    lc_state_init(s, test_bake, &test_limits);
    return lc_journal_open(dir, mode, s, err, errlen);
}

static void remove_dir(const char *dir) {
    DIR *d = opendir(dir);
    struct dirent *e;
    char path[512];
    while (d && (e = readdir(d))) {
        if (!strcmp(e->d_name, ".") || !strcmp(e->d_name, "..")) continue;
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        unlink(path);
    }
    if (d) closedir(d);
    rmdir(dir);
}

/* A short write (the file size limit cuts the line, then EFBIG) leaves nothing behind. */
static void test_short_write(void) {
    char dir[] = "/tmp/lc_journal_short_XXXXXX", err[512] = "", revs[256];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    struct stat st;
    CHECK(stat(dir, &st) == 0, "stat dir");
    hook_dir_ino = st.st_ino;
    hook_dir_fsyncs = 0;
    lc_state s;
    lc_state_init(&s, test_bake, &test_limits);
    lc_journal *j = lc_journal_open(dir, LC_FSYNC_ALWAYS, &s, err, sizeof err);
    CHECK(j != NULL, "open: %s", err);
    if (!j) return;
    /* Without the directory's fsync a crash can lose the new journal.log with its changes. */
    CHECK(hook_dir_fsyncs >= 1, "creating journal.log fsyncs the state dir (%d fsyncs of it)", hook_dir_fsyncs);
    hook_dir_ino = 0;
    CHECK(change(j, &s, "a1", err, sizeof err) == 0 && change(j, &s, "a2", err, sizeof err) == 0 &&
              change(j, &s, "a3", err, sizeof err) == 0,
          "three appends: %s", err);
    long long good = (long long)lc_journal_bytes(j);
    CHECK(good > 0 && file_size(dir, "journal.log") == good, "bytes %lld = file size %lld", good,
          file_size(dir, "journal.log"));

    /* Nothing may print between the two setrlimit calls: stderr may be a file too. */
    struct rlimit rl, low;
    getrlimit(RLIMIT_FSIZE, &rl);
    low = rl;
    low.rlim_cur = (rlim_t)good + 16;
    signal(SIGXFSZ, SIG_IGN);
    int lim_rc = setrlimit(RLIMIT_FSIZE, &low);
    int rc = change(j, &s, "b-refused-with-a-long-id", err, sizeof err);
    setrlimit(RLIMIT_FSIZE, &rl);
    CHECK(lim_rc == 0, "setrlimit");
    CHECK(rc == -1 && strstr(err, "write failed"), "a short write is refused: rc %d, %s", rc, err);
    CHECK(file_size(dir, "journal.log") == good, "the partial line is cut off: %lld bytes, expected %lld",
          file_size(dir, "journal.log"), good);
    CHECK((long long)lc_journal_bytes(j) == good, "bytes not advanced: %llu", (unsigned long long)lc_journal_bytes(j));
    CHECK(!lc_journal_broken(j), "a failed write (no fsync failed) does not break the journal");
    CHECK(lc_journal_failures(j) == 1, "one failure counted: %llu", (unsigned long long)lc_journal_failures(j));
    CHECK(s.revision == 3, "state undone: revision %llu", (unsigned long long)s.revision);

    CHECK(change(j, &s, "a4", err, sizeof err) == 0 && s.revision == 4, "the next change reuses revision 4: %s", err);
    lc_journal_close(j);
    CHECK(!strcmp(journal_revs(dir, revs, sizeof revs), "1,2,3,4"), "journal revisions %s, expected 1,2,3,4", revs);
    lc_state r;
    j = reopen(dir, LC_FSYNC_ALWAYS, &r, err, sizeof err);
    CHECK(j != NULL, "restart after a short write: %s", err);
    CHECK(r.revision == 4 && r.n_lights == 4 && has_light(&r, "a4") && !has_light(&r, "b-refused-with-a-long-id"),
          "replay: revision %llu, %u lights (the refused one absent)", (unsigned long long)r.revision, r.n_lights);
    lc_journal_close(j);
    lc_state_release(&r);
    lc_state_release(&s);
    remove_dir(dir);
}

/* A failed fdatasync: cut off, broken, refused until a compaction succeeds. */
static void test_fsync_failure(void) {
    char dir[] = "/tmp/lc_journal_fsync_XXXXXX", err[512] = "", revs[256];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    lc_state s;
    lc_state_init(&s, test_bake, &test_limits);
    lc_journal *j = lc_journal_open(dir, LC_FSYNC_ALWAYS, &s, err, sizeof err);
    CHECK(j != NULL, "open: %s", err);
    if (!j) return;
    CHECK(change(j, &s, "c1", err, sizeof err) == 0 && change(j, &s, "c2", err, sizeof err) == 0, "appends: %s", err);
    long long good = (long long)lc_journal_bytes(j);
    CHECK(!lc_journal_broken(j) && lc_journal_failures(j) == 0, "healthy before the failure");

    hook_fdatasync_fail = 1;
    int rc = change(j, &s, "r3", err, sizeof err);
    CHECK(rc == -1 && strstr(err, "fsync"), "a failed fsync refuses the change: rc %d, %s", rc, err);
    CHECK(file_size(dir, "journal.log") == good && (long long)lc_journal_bytes(j) == good,
          "the unsynced line is cut off: file %lld, bytes %llu, expected %lld", file_size(dir, "journal.log"),
          (unsigned long long)lc_journal_bytes(j), good);
    CHECK(lc_journal_broken(j) == 1, "a failed fsync breaks the journal");
    CHECK(lc_journal_failures(j) == 1, "failures %llu", (unsigned long long)lc_journal_failures(j));

    /* The page cache is not trusted any more: even a healthy fsync is not enough. */
    rc = change(j, &s, "r4", err, sizeof err);
    CHECK(rc == -1 && strstr(err, "snapshot"), "refused while broken: rc %d, %s", rc, err);
    CHECK(lc_journal_failures(j) == 1, "a refusal is no new failure: %llu", (unsigned long long)lc_journal_failures(j));
    CHECK(file_size(dir, "journal.log") == good, "nothing written while broken");

    hook_fdatasync_fail = 1;
    CHECK(lc_journal_compact(j, &s, err, sizeof err) != 0 && lc_journal_broken(j), "a failed compaction: still broken");
    CHECK(change(j, &s, "r5", err, sizeof err) == -1, "still refused");
    lc_journal_tick(j, &s); /* the once-a-second retry */
    CHECK(!lc_journal_broken(j), "the tick's compaction repairs it");
    CHECK(change(j, &s, "c3", err, sizeof err) == 0 && s.revision == 3, "accepting again, revision 3: %s", err);
    lc_journal_close(j);

    CHECK(!strcmp(journal_revs(dir, revs, sizeof revs), "3"), "journal revisions %s, expected 3 (1-2 in the snapshot)",
          revs);
    lc_state r;
    j = reopen(dir, LC_FSYNC_ALWAYS, &r, err, sizeof err);
    CHECK(j != NULL, "restart after a failed fsync: %s", err);
    CHECK(r.revision == 3 && r.n_lights == 3 && has_light(&r, "c1") && has_light(&r, "c2") && has_light(&r, "c3") &&
              !has_light(&r, "r3") && !has_light(&r, "r4") && !has_light(&r, "r5"),
          "replay: revision %llu, %u lights: every acknowledged change, no refused one", (unsigned long long)r.revision,
          r.n_lights);
    lc_journal_close(j);
    lc_state_release(&r);
    lc_state_release(&s);
    remove_dir(dir);
}

static void sleep_ms(long ms) {
    struct timespec ts = {ms / 1000, (ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

/* everysec: the tick's failed fsync breaks the journal; the acknowledged lines survive
 * through the snapshot. */
static void test_everysec_failure(void) {
    char dir[] = "/tmp/lc_journal_esec_XXXXXX", err[512] = "";
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    lc_state s;
    lc_state_init(&s, test_bake, &test_limits);
    lc_journal *j = lc_journal_open(dir, LC_FSYNC_EVERYSEC, &s, err, sizeof err);
    CHECK(j != NULL, "open: %s", err);
    if (!j) return;
    CHECK(change(j, &s, "e1", err, sizeof err) == 0, "append: %s", err);
    sleep_ms(1100);
    hook_fdatasync_fail = 2; /* the tick's fsync, then its compaction's */
    lc_journal_tick(j, &s);
    CHECK(lc_journal_broken(j) && lc_journal_failures(j) == 1, "failed tick fsync: broken %d, failures %llu",
          lc_journal_broken(j), (unsigned long long)lc_journal_failures(j));
    CHECK(change(j, &s, "x2", err, sizeof err) == -1, "refused while broken");
    lc_journal_tick(j, &s);
    CHECK(lc_journal_broken(j), "the retry waits a second");
    sleep_ms(1100);
    lc_journal_tick(j, &s);
    CHECK(!lc_journal_broken(j), "repaired by the tick a second later");
    CHECK(change(j, &s, "e2", err, sizeof err) == 0 && s.revision == 2, "accepting again: %s", err);
    lc_journal_close(j);
    lc_state r;
    j = reopen(dir, LC_FSYNC_EVERYSEC, &r, err, sizeof err);
    CHECK(j && r.revision == 2 && has_light(&r, "e1") && has_light(&r, "e2") && !has_light(&r, "x2"),
          "the acknowledged e1 survives its failed fsync: revision %llu: %s", (unsigned long long)r.revision, err);
    lc_journal_close(j);
    lc_state_release(&r);
    lc_state_release(&s);
    remove_dir(dir);
}

/* A corrupt complete line in the middle: a plain start refuses, naming file, line and
 * --recover; lc_journal_recover keeps the prefix and sets the rest aside. */
static void test_corrupt_middle(void) {
    char dir[] = "/tmp/lc_journal_corrupt_XXXXXX", err[1024] = "", path[256], revs[256];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    lc_state s;
    lc_state_init(&s, test_bake, &test_limits);
    lc_journal *j = lc_journal_open(dir, LC_FSYNC_ALWAYS, &s, err, sizeof err);
    CHECK(j != NULL, "open: %s", err);
    if (!j) return;
    CHECK(change(j, &s, "m1", err, sizeof err) == 0 && change(j, &s, "m2", err, sizeof err) == 0 &&
              change(j, &s, "m3", err, sizeof err) == 0 && change(j, &s, "m4", err, sizeof err) == 0,
          "appends: %s", err);
    lc_journal_close(j);
    lc_state_release(&s);

    /* Line 2 becomes x's (a complete line: its newline stays). */
    snprintf(path, sizeof path, "%s/journal.log", dir);
    size_t len;
    char *text = slurp(path, &len);
    CHECK(text != NULL, "read journal");
    if (!text) return;
    char *l2 = strchr(text, '\n') + 1, *l2_end = strchr(l2, '\n');
    size_t line1 = (size_t)(l2 - text);
    memset(l2, 'x', (size_t)(l2_end - l2));
    FILE *f = fopen(path, "wb");
    CHECK(f && fwrite(text, 1, len, f) == len, "rewrite journal");
    if (f) fclose(f);

    lc_state r;
    j = reopen(dir, LC_FSYNC_ALWAYS, &r, err, sizeof err);
    CHECK(!j, "a corrupt middle line refuses a plain start");
    CHECK(strstr(err, path) && strstr(err, "line 2") && strstr(err, "--recover"),
          "the error names the file, the line and --recover: %s", err);
    lc_journal_close(j);
    lc_state_release(&r);

    lc_journal_dropped d;
    memset(&d, 0, sizeof d);
    lc_state_init(&r, test_bake, &test_limits);
    j = lc_journal_recover(dir, LC_FSYNC_ALWAYS, &r, &d, err, sizeof err);
    CHECK(j != NULL, "recover opens: %s", err);
    CHECK(r.revision == 1 && r.n_lights == 1 && has_light(&r, "m1"), "the valid prefix: revision %llu, %u lights",
          (unsigned long long)r.revision, r.n_lights);
    CHECK(d.first_line == 2 && d.lines == 3 && d.bytes == len - line1 && d.unreadable == 1 && d.rev_min == 3 &&
              d.rev_max == 4,
          "dropped: from line %llu, %llu lines, %llu bytes (expected %zu), %llu unreadable, revisions %llu..%llu",
          (unsigned long long)d.first_line, (unsigned long long)d.lines, (unsigned long long)d.bytes, len - line1,
          (unsigned long long)d.unreadable, (unsigned long long)d.rev_min, (unsigned long long)d.rev_max);
    CHECK(strstr(d.reason, "line 2") != NULL, "reason: %s", d.reason);
    size_t saved_len = 0;
    char *saved = d.saved[0] ? slurp(d.saved, &saved_len) : NULL;
    CHECK(saved && saved_len == len - line1 && !memcmp(saved, text + line1, saved_len),
          "the dropped bytes are kept in '%s'", d.saved);
    if (saved) unlink(d.saved);
    free(saved);
    free(text);
    CHECK(j && change(j, &r, "m5", err, sizeof err) == 0 && r.revision == 2, "changes after recovery: %s", err);
    lc_journal_close(j);
    lc_state_release(&r);

    CHECK(!strcmp(journal_revs(dir, revs, sizeof revs), "2"), "journal revisions %s, expected 2", revs);
    j = reopen(dir, LC_FSYNC_ALWAYS, &r, err, sizeof err);
    CHECK(j && r.revision == 2 && has_light(&r, "m1") && has_light(&r, "m5") && !has_light(&r, "m3"),
          "the next plain start is clean: revision %llu: %s", (unsigned long long)r.revision, err);
    lc_journal_close(j);
    lc_state_release(&r);

    /* A clean journal: recover drops nothing and reports zeros. */
    lc_state_init(&r, test_bake, &test_limits);
    memset(&d, 0xff, sizeof d);
    j = lc_journal_recover(dir, LC_FSYNC_ALWAYS, &r, &d, err, sizeof err);
    CHECK(j && r.revision == 2 && d.lines == 0 && d.bytes == 0 && d.first_line == 0, "recover on a clean journal: %s",
          err);
    lc_journal_close(j);
    lc_state_release(&r);
    remove_dir(dir);
}

int main(void) {
    const char *obj = "usemtl white\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 4 3 2\n"
                      "usemtl lamp\nv 0 1 0\nv 1 1 0\nv 1 1 1\nv 0 1 1\nf 5 6 7 8\n";
    const char *mtl = "newmtl white\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 2 2 2\n";
    const char *flags[] = {"--quality", "draft", "--surfels", "256", "--links", "16", NULL};
    fixture f;
    if (fixture_bake(&f, obj, mtl, flags) != 0) {
        CHECK(0, "bake failed");
        CHECK_DONE();
    }
    test_bake = f.bake;
    test_short_write();
    test_fsync_failure();
    test_everysec_failure();
    test_corrupt_middle();
    fixture_release(&f);
    CHECK_DONE();
}
