// Residual deltas (PROTOCOL.md §6.2.1) keep a copy bit-exact: with lucentd's delta threshold
// at 0 every moved texel is sent, so after a run of residual deltas the copy must equal, word
// for word, the keyframe a snapshot of the same revision brings.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import WebSocket from 'ws';
import { LucentClient } from '../lucent.js';
import * as H from '../harness/lucentd.mjs';

const skip = H.missing() || false;
let srv, dir;
const clients = [];

before(async () => {
  if (skip) return;
  dir = H.tempDir('residual');
  srv = await H.startLucentd({ stateDir: join(dir, 'state'), args: ['--delta-threshold', '0', '--keyframe-interval', '100000'] });
});

after(async () => {
  for (const c of clients) c.close();
  if (srv) await srv.stop();
  if (dir) H.cleanup(dir);
});

function bytesOf(a) {
  return Buffer.from(a.buffer, a.byteOffset, a.byteLength);
}

test('residual deltas give copies bit-exact with a keyframe of the same revision, every encoding', { skip }, async () => {
  const subs = [];
  for (const encoding of ['rgb9e5', 'rgba16f', 'f32']) {
    const c = new LucentClient(srv.url, { token: H.TOKENS.controller, WebSocket, client: `js-exact-${encoding}` });
    clients.push(c);
    c.errors = [];
    c.on('error', (e) => c.errors.push(e));
    await c.connect();
    const kinds = [];
    c.on('lightmap', (copy, h) => kinds.push(h.keyframe ? 'K' : h.residual ? 'R' : 'D'));
    await c.subscribe('lightmap', { encoding, delta: 'residual' });
    subs.push({ encoding, c, kinds });
  }
  const ctl = subs[0].c;
  await Promise.all(subs.map((s) => H.waitConverged(s.c, 'lightmap', ctl.revision)));
  let rev;
  for (const [i, x] of [0.2, 0.22, 0.25].entries()) {
    rev = (await ctl.request({ type: 'light.set', light: { id: 'exact', type: 'point', position: [x, 0.4, 0.3 - 0.02 * i],
      intensity: 0.2 } })).revision;
    await Promise.all(subs.map((s) => H.waitConverged(s.c, 'lightmap', rev)));
  }
  for (const s of subs) {
    const residuals = s.kinds.slice(s.kinds.lastIndexOf('K') + 1).filter((k) => k === 'R').length;
    assert.ok(residuals >= 5, `${s.encoding}: the copy is built by ${residuals} residual deltas since its keyframe (${s.kinds.join('')})`);
    const held = s.c.lightmap.data.slice();
    const key = H.waitFor(s.c, 'lightmap', (copy, h) => h.keyframe, 10000, `${s.encoding} snapshot keyframe`);
    await s.c.snapshot();
    const [copy, h] = await key;
    assert.equal(h.revision, rev);
    assert.ok(h.converged);
    assert.equal(copy.data.constructor, held.constructor);
    assert.equal(bytesOf(copy.data).compare(bytesOf(held)), 0, `${s.encoding}: residual copy == keyframe, bit for bit`);
    assert.deepEqual(s.c.errors, []);
  }
});
