// Requests against a live lucentd: id matching with many requests in flight, error replies,
// roles, refused hellos and `changed` broadcasts.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import WebSocket from 'ws';
import { LucentClient, LucentError } from '../lucent.js';
import * as H from '../harness/lucentd.mjs';

const skip = H.missing() || false;
let srv, dir;
const clients = [];

before(async () => {
  if (skip) return;
  dir = H.tempDir('requests');
  srv = await H.startLucentd({ stateDir: join(dir, 'state') });
});

after(async () => {
  for (const c of clients) c.close();
  if (srv) await srv.stop();
  if (dir) H.cleanup(dir);
});

async function connect(token, name, extra = {}) {
  const c = new LucentClient(srv.url, { token, WebSocket, client: name, ...extra });
  clients.push(c);
  await c.connect();
  return c;
}

async function rejection(promise) {
  try {
    await promise;
  } catch (e) {
    return e;
  }
  assert.fail('expected a rejection');
}

test('concurrent requests each resolve with their own reply', { skip }, async () => {
  const c = await connect(H.TOKENS.controller, 'js-concurrent');
  const before = c.revision;
  const sets = Array.from({ length: 20 }, (_, i) => c.request({ type: 'light.set',
    light: { id: `conc-${i}`, type: 'point', position: [0.1 + 0.01 * i, 0.4, 0.2], intensity: 0.01 } }));
  const pings = Array.from({ length: 10 }, (_, i) => c.ping(1000 + i));
  const named = c.request({ type: 'ping', id: 'my-ping', t: 7 });
  const state = c.state();
  const [oks, pongs, mine, st] = await Promise.all([Promise.all(sets), Promise.all(pings), named, state]);
  oks.forEach((ok) => assert.equal(ok.type, 'ok'));
  assert.equal(new Set(oks.map((ok) => ok.id)).size, 20, 'distinct ids');
  const revs = oks.map((ok) => ok.revision).sort((a, b) => a - b);
  assert.deepEqual(revs, Array.from({ length: 20 }, (_, i) => before + 1 + i), 'one revision per change');
  pongs.forEach((p, i) => {
    assert.equal(p.type, 'pong');
    assert.equal(p.t, 1000 + i, 'each pong answers its own ping');
    assert.ok(p.rtt_ms >= 0);
  });
  assert.deepEqual([mine.type, mine.id, mine.t], ['pong', 'my-ping', 7]);
  assert.equal(st.type, 'state');
  assert.ok(c.revision >= before + 20, 'revision follows the oks');
  const full = await c.state();
  assert.equal(full.revision, before + 20);
  const ids = full.lights.map((l) => l.id).filter((id) => id.startsWith('conc-'));
  assert.equal(ids.length, 20);
  await c.request({ type: 'batch', ops: ids.map((id) => ({ type: 'light.remove', light_id: id })) });
});

test('error replies reject with the code, pointer and id', { skip }, async () => {
  const c = await connect(H.TOKENS.controller, 'js-errors');
  const e = await rejection(c.request({ type: 'light.set', light: { id: 'bad', type: 'point', position: [0, 0, 0], intensity: -1 } }));
  assert.ok(e instanceof LucentError);
  assert.equal(e.code, 'out_of_range');
  assert.equal(e.pointer, '/light/intensity');
  assert.equal(typeof e.id, 'number');
  assert.equal(e.reply.type, 'error');
  const b = await rejection(c.request({ type: 'batch', ops: [
    { type: 'light.set', light: { id: 'ok', type: 'point', position: [0, 0, 0] } },
    { type: 'light.set', light: { id: 'no', type: 'point', position: [0, 0, 0], intensity: 1e12 } }] }));
  assert.deepEqual([b.code, b.pointer], ['out_of_range', '/ops/1/light/intensity']);
  const u = await rejection(c.request({ type: 'light.remove', light_id: 'never-there', id: 'rm-1' }));
  assert.deepEqual([u.code, u.id], ['unknown_id', 'rm-1']);
  const t = await rejection(c.request({ type: 'no.such' }));
  assert.equal(t.code, 'unknown_type');
  const big = await rejection(c.request({ type: 'ping', t: 1, pad: 'x'.repeat(70000) }));
  assert.equal(big.code, 'too_large', 'a request over max_message is refused here, not sent');
  assert.equal((await c.ping(5)).t, 5, 'the connection is still usable');
  const st = await c.state();
  assert.ok(!st.lights.some((l) => l.id === 'ok'), 'the failed batch changed nothing');
});

test('a viewer gets forbidden for changes and may subscribe; changed reaches it', { skip }, async () => {
  const v = await connect(H.TOKENS.viewer, 'js-viewer');
  const ctl = await connect(H.TOKENS.controller, 'js-controller');
  assert.equal(v.role, 'viewer');
  assert.equal(ctl.role, 'controller');
  const e = await rejection(v.request({ type: 'light.set', light: { id: 'v', type: 'point', position: [0, 0, 0] } }));
  assert.equal(e.code, 'forbidden');
  assert.equal((await v.subscribe('shgrid')).type, 'ok');
  const changed = H.waitFor(v, 'changed');
  const ok = await ctl.request({ type: 'material.set', material: ctl.welcome.scene.materials[0], emission: [0, 0, 0] });
  const [msg] = await changed;
  assert.equal(msg.revision, ok.revision);
  assert.equal(msg.by, 'js-controller');
  assert.deepEqual(msg.ops, ['material.set']);
  assert.ok(v.revision >= ok.revision);
});

test('an unknown token rejects connect with unauthorized and is not retried', { skip }, async () => {
  const c = new LucentClient(srv.url, { token: 'wrong', WebSocket, reconnect: true, backoff: { initialMs: 50, maxMs: 100 } });
  let retries = 0;
  c.on('reconnecting', () => retries++);
  const e = await rejection(c.connect());
  assert.ok(e instanceof LucentError);
  assert.equal(e.code, 'unauthorized');
  await new Promise((r) => setTimeout(r, 300));
  assert.equal(retries, 0);
  assert.equal(c.connected, false);
  const d = await rejection(c.ping());
  assert.equal(d.code, 'disconnected');
});
