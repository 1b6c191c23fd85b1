/* journal: durability of the dynamic state. Every accepted change is appended to
 * DIR/journal.log as one JSON line {"type":"batch","revision":N,"ops":[...]} and fsync'd
 * before the client's `ok` (mode always) or within a second (everysec). Compaction writes
 * DIR/snapshot.json (a `state` message, atomically: temp + fsync + rename) and then empties
 * the journal; a crash between the two only leaves journal lines the snapshot already
 * holds, which replay skips by revision. A torn last line (crash mid-append) is cut off.
 * A failed append (short write, ENOSPC, EIO) is cut off too: the file goes back to its last
 * good length, so a refused change never reaches the disk and the next change may reuse
 * its revision. After a failed fsync the kernel's page cache can no longer be trusted
 * (a later fsync may report success for pages it dropped), so the journal turns *broken*:
 * it refuses appends until a compaction succeeds (the snapshot then holds every
 * acknowledged change on its own).
 * Thread: the service thread only. */
#ifndef LC_JOURNAL_H
#define LC_JOURNAL_H
#include <stddef.h>
#include <stdint.h>

#include "state.h"

typedef enum { LC_FSYNC_ALWAYS = 0, LC_FSYNC_EVERYSEC = 1 } lc_fsync_mode;

typedef struct lc_journal lc_journal;

/* What lc_journal_recover set aside (all zero when the journal was clean). */
typedef struct lc_journal_dropped {
    uint64_t first_line;       /* 1-based line of journal.log where the dropped part starts */
    uint64_t lines, bytes;     /* the dropped part: from that line to the end of the file */
    uint64_t rev_min, rev_max; /* revisions named by the dropped lines (0 when none had one) */
    uint64_t unreadable;       /* dropped lines without a readable revision */
    char reason[1280];         /* why the first dropped line was refused (names the file and line) */
    char saved[1024];          /* the file that keeps the dropped bytes ("" if it could not be written) */
} lc_journal_dropped;

/* Opens DIR (created if missing) and restores *state (already initialised from the bake):
 * the snapshot, then every journal line newer than it. Returns NULL with err naming the
 * file and line on a corrupt snapshot or journal (the daemon then refuses to start rather
 * than lose acknowledged changes; the message points at lc_journal_recover / --recover). */
lc_journal *lc_journal_open(const char *dir, lc_fsync_mode mode, lc_state *state, char *err, size_t errlen);
/* lucentd --recover: like lc_journal_open, but a journal line that cannot be replayed ends
 * the replay instead of the start: the state is the snapshot plus the valid prefix, the
 * rest of the file is copied to DIR/journal.dropped.<time>, logged (lines, bytes,
 * revisions) and described in *dropped (may be NULL), and the state is compacted (snapshot
 * + empty journal) so the next plain start is clean. A corrupt snapshot still fails. */
lc_journal *lc_journal_recover(const char *dir, lc_fsync_mode mode, lc_state *state, lc_journal_dropped *dropped,
                               char *err, size_t errlen);
/* One change as a journal line (with its newline; revision 0: without "revision", the
 * cluster log's entry): malloc'd, NUL-terminated, *len bytes; NULL when out of memory. */
char *lc_journal_record(const lc_proto_op *ops, uint32_t n_ops, uint64_t revision, size_t *len);
/* The state as a `state` message (what snapshot.json holds); malloc'd, NULL when out of memory. */
char *lc_journal_state_text(const lc_state *state);
/* Appends one accepted change with its revision. Returns 0 when durable per the mode; on
 * failure the file is back at its last good length and nothing of the change remains.
 * Refused (-1) while the journal is broken (see lc_journal_broken). */
int lc_journal_append(lc_journal *j, const lc_proto_op *ops, uint32_t n_ops, uint64_t revision, char *err,
                      size_t errlen);
/* Call from the loop (at least once a second) with the acknowledged state: everysec mode
 * fsyncs pending appends once a second has passed; a broken journal retries the
 * compaction of `state` once a second (NULL: no retry). */
void lc_journal_tick(lc_journal *j, const lc_state *state);
/* Snapshot + truncate + fsync. On success a broken journal works again. A failed fsync of
 * the emptied journal breaks it. */
int lc_journal_compact(lc_journal *j, const lc_state *state, char *err, size_t errlen);
/* Bytes in journal.log (the daemon compacts past a threshold). */
uint64_t lc_journal_bytes(const lc_journal *j);
/* For /metrics: 1 while the journal refuses changes after a failed fsync (until a
 * compaction succeeds), else 0. */
int lc_journal_broken(const lc_journal *j);
/* For /metrics: journal appends that failed (write or fsync) plus failed everysec fsyncs
 * since the start. Refusals while broken and failed compaction retries do not count. */
uint64_t lc_journal_failures(const lc_journal *j);
/* Flushes and closes. NULL-safe. */
void lc_journal_close(lc_journal *j);

#endif
