// Update->frame latency measured in the page: for the page's own change, from sending the
// request to the first drawn lightmap frame whose revision is at least the ok's revision; for
// another client's change, from its `changed` message to that frame (the part the page sees).
export class Latency {
  constructor(report) {
    this.report = report;
    this.last = null;
    this.waiting = []; // {t0, revision, what}
  }

  /** promise: the request's reply; shownRevision(): the revision drawn now. */
  own(t0, promise, shownRevision) {
    const entry = { t0, revision: null, what: 'own change' };
    this.waiting.push(entry);
    promise.then((ok) => {
      if (typeof ok.revision !== 'number') return this.drop(entry);
      entry.revision = ok.revision;
      const shown = shownRevision();
      if (shown !== null && shown >= ok.revision) this.done(entry, performance.now());
    }, () => this.drop(entry));
  }

  external(revision, shown) {
    if (shown !== null && shown >= revision) return;
    if (this.waiting.some((w) => w.revision === revision)) return;
    this.waiting.push({ t0: performance.now(), revision, what: 'changed by another client' });
  }

  /** A lightmap frame of `revision` has just been drawn. */
  shown(revision) {
    const now = performance.now();
    for (const w of [...this.waiting]) if (w.revision !== null && revision >= w.revision) this.done(w, now);
  }

  done(entry, now) {
    this.drop(entry);
    this.last = now - entry.t0;
    this.report(this.last, entry.what);
  }

  drop(entry) {
    const i = this.waiting.indexOf(entry);
    if (i >= 0) this.waiting.splice(i, 1);
  }
}
