// Reconnection: lucentd stops (SIGTERM) and starts again on the same port and state
// directory; the client reconnects with back-off, says hello again, resubscribes with the same
// settings and its streams deliver keyframes and deltas again.
import { test, after } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import WebSocket from 'ws';
import { LucentClient } from '../lucent.js';
import * as H from '../harness/lucentd.mjs';

const skip = H.missing() || false;
let dir, srv, c;

after(async () => {
  if (c) c.close();
  if (srv) await srv.stop();
  if (dir) H.cleanup(dir);
});

function light(x) {
  return { type: 'light.set', light: { id: 'rc', type: 'point', position: [x, 0.4, 0.3], intensity: 0.2 } };
}

test('the client reconnects to a restarted lucentd and its subscriptions deliver frames again', { skip }, async () => {
  dir = H.tempDir('reconnect');
  const stateDir = join(dir, 'state');
  srv = await H.startLucentd({ stateDir });
  const port = srv.port;
  c = new LucentClient(srv.url, { token: H.TOKENS.controller, WebSocket, client: 'js-reconnect', reconnect: true,
    backoff: { initialMs: 100, maxMs: 400 } });
  const log = [];
  for (const ev of ['open', 'welcome', 'close', 'reconnecting']) c.on(ev, (x) => log.push(ev));
  await c.connect();
  await c.subscribe('lightmap', { encoding: 'rgba16f', delta: 'residual' });
  await c.subscribe('shgrid', { encoding: 'rgba16f' });
  const rev0 = (await c.request(light(0.2))).revision;
  await H.waitConverged(c, 'lightmap', rev0);

  const closed = H.waitFor(c, 'close');
  const retrying = H.waitFor(c, 'reconnecting', (x) => x.attempt >= 2, 10000, 'a second reconnect attempt');
  assert.equal(await srv.stop('SIGTERM'), 0, 'lucentd exits cleanly on SIGTERM');
  const [ev] = await closed;
  assert.equal(ev.reconnecting, true);
  assert.equal(c.connected, false);
  const down = await c.ping().catch((e) => e);
  assert.equal(down.code, 'disconnected', 'a request while disconnected rejects at once');
  const [r] = await retrying; // the first attempt failed against the closed port
  assert.ok(r.delayMs >= 0.8 * 200 && r.delayMs <= 1.2 * 200, `back-off doubles: ${r.delayMs} ms`);

  const welcomed = H.waitFor(c, 'welcome', () => true, 15000);
  const key = H.waitFor(c, 'lightmap', (copy, h) => h.keyframe && h.sequence === 1, 15000, 'a lightmap keyframe');
  const grid = H.waitFor(c, 'shgrid', (copy, h) => h.sequence === 1, 15000, 'an shgrid keyframe');
  srv = await H.startLucentd({ stateDir, port });
  const [w] = await welcomed;
  assert.equal(w.revision, rev0, 'the state survived the restart');
  const [copy] = await key;
  assert.equal(copy.encoding, 'rgba16f', 'resubscribed with the same settings');
  await grid;
  assert.equal(c.shgrid.data.length, c.welcome.scene.grid.dims.reduce((a, b) => a * b) * 27);

  const residuals = [];
  c.on('lightmap', (cp, h) => h.residual && residuals.push(h.sequence));
  const rev1 = (await c.request(light(0.22))).revision;
  assert.equal(rev1, rev0 + 1);
  await H.waitConverged(c, 'lightmap', rev1);
  assert.ok(residuals.length >= 1, 'residual deltas apply on the new connection');
  assert.equal(c.stats.reconnects, 1);
  assert.deepEqual(log.slice(0, 3), ['open', 'welcome', 'close']);
  assert.equal(log.filter((e) => e === 'welcome').length, 2);
});
