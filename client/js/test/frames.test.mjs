// Data frames from a live lucentd: the JavaScript client's copies against liblucent-client's
// decoding of the very same frames (tests/js/replay_frames.c), for every encoding and delta
// mode, the SH streams, and a corrupted frame.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { join } from 'node:path';
import { readFileSync } from 'node:fs';
import WebSocket from 'ws';
import { LucentClient, lightmapToFloat32, crc32 } from '../lucent.js';
import * as H from '../harness/lucentd.mjs';

const skip = H.missing() || false;
let srv, dir;
const clients = [];

before(async () => {
  if (skip) return;
  dir = H.tempDir('frames');
  srv = await H.startLucentd({ stateDir: join(dir, 'state') });
});

after(async () => {
  for (const c of clients) c.close();
  if (srv) await srv.stop();
  if (dir) H.cleanup(dir);
});

async function connect(name) {
  const c = new LucentClient(srv.url, { token: H.TOKENS.controller, WebSocket, client: name });
  c.errors = [];
  c.on('error', (e) => c.errors.push(e));
  clients.push(c);
  await c.connect();
  return c;
}

// A big move, a small one (tile deltas), a dim spot in a corner (a few tiles), its removal.
const CHANGES = [
  { type: 'light.set', light: { id: 'key', type: 'point', position: [0.28, 0.45, 0.28], intensity: 0.3 } },
  { type: 'light.set', light: { id: 'key', type: 'point', position: [0.3, 0.45, 0.28], intensity: 0.3 } },
  { type: 'light.set', light: { id: 'corner', type: 'spot', position: [0.05, 0.05, 0.05], direction: [0, -1, 0],
    outerConeAngle: 0.3, intensity: 0.05 } },
  { type: 'light.remove', light_id: 'corner' },
];

// What one texel of a copy may differ from the current state: the server's delta threshold
// (relative, with its floor of 1e-3 of the image's peak) plus the encoding's rounding.
const THRESHOLD = 0.01;
const PRECISION = { rgb9e5: 1 / 256, rgba16f: 1 / 1024, f32: 0 };

function maxStaleness(got, ref, encoding) {
  let peak = 0;
  for (const v of ref) peak = Math.max(peak, v);
  let worst = 0;
  for (let i = 0; i < ref.length; i += 3) {
    const m = Math.max(ref[i], ref[i + 1], ref[i + 2], got[i], got[i + 1], got[i + 2]);
    // (+1e-6 m: the server compares in float32)
    const allowed = THRESHOLD * Math.max(m, 1e-3 * peak) + (PRECISION[encoding] + 1e-6) * m + 2 ** -23;
    for (let k = 0; k < 3; k++) worst = Math.max(worst, Math.abs(got[i + k] - ref[i + k]) / allowed);
  }
  return worst;
}

test('every lightmap encoding x delta mode decodes as liblucent-client does, frame by frame', { skip }, async () => {
  const subs = [];
  for (const encoding of ['rgb9e5', 'rgba16f', 'f32'])
    for (const delta of ['tiles', 'residual']) {
      const c = await connect(`js-${encoding}-${delta}`);
      const frames = H.record(c), seen = [];
      c.on('lightmap', (copy, h) => seen.push({ sequence: h.sequence, revision: h.revision, keyframe: h.keyframe,
        residual: h.residual, pass: h.pass, converged: h.converged, crc: crc32(H.floatBytes(lightmapToFloat32(copy))) }));
      await c.subscribe('lightmap', { encoding, delta });
      subs.push({ encoding, delta, c, frames, seen });
    }
  const ctl = subs[0].c;
  let rev = ctl.revision;
  for (const s of subs) await H.waitConverged(s.c, 'lightmap', rev);
  for (const change of CHANGES) {
    rev = (await ctl.request(change)).revision;
    for (const s of subs) await H.waitConverged(s.c, 'lightmap', rev);
  }
  // the current state, decoded by liblucent-client from a fresh f32 keyframe
  const snapDir = join(dir, 'snapshot');
  await H.lucentctl(srv.url, H.TOKENS.viewer, ['snapshot', '--stream', 'lightmap', '--encoding', 'f32', '--raw', '--out', snapDir]);
  const b = readFileSync(join(snapDir, 'lightmap.f32'));
  const ref = new Float32Array(b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength));

  for (const s of subs) {
    const what = `${s.encoding}/${s.delta}`;
    assert.deepEqual(s.c.errors.map((e) => e.message), [], `${what}: no frame errors`);
    assert.equal(s.seen.length, s.frames.length, `${what}: every frame applied`);
    const { results, values } = await H.replay(s.frames.map((f) => f.bytes), dir);
    assert.equal(results.length, s.frames.length);
    for (let i = 0; i < results.length; i++) {
      const r = results[i], j = s.seen[i];
      assert.equal(r.rc, 0, `${what}: liblucent-client applied frame ${i} (${r.error})`);
      assert.deepEqual([r.sequence, r.revision, !!r.keyframe, !!r.residual, r.pass, !!r.converged],
        [j.sequence, j.revision, j.keyframe, j.residual, j.pass, j.converged], `${what}: frame ${i} header`);
      assert.equal(j.crc, r.crc, `${what}: frame ${i} (sequence ${j.sequence}) decodes bit for bit as liblucent-client`);
    }
    const deltas = s.seen.filter((f) => !f.keyframe && (s.delta === 'residual') === f.residual);
    assert.ok(deltas.length >= 3, `${what}: ${deltas.length} ${s.delta} deltas among ${s.seen.length} frames`);
    console.log(`${what}: ${s.seen.length} frames (${deltas.length} ${s.delta} deltas), staleness ${maxStaleness(lightmapToFloat32(s.c.lightmap), ref, s.encoding).toFixed(3)}`);
    const mine = lightmapToFloat32(s.c.lightmap);
    assert.equal(Buffer.compare(Buffer.from(H.floatBytes(mine)), Buffer.from(H.floatBytes(values.lightmap))), 0,
      `${what}: final copy equals liblucent-client's`);
    assert.equal(s.c.lightmap.revision, rev);
    const stale = maxStaleness(mine, ref, s.encoding);
    assert.ok(stale <= 1, `${what}: the copy is within threshold + precision of a fresh keyframe (worst ${stale.toFixed(3)})`);
  }
  // progressive refinement: within a revision the passes rise and the last frame is converged
  const last = subs[5].seen.filter((f) => f.revision === rev);
  assert.ok(last.length >= 2, `${last.length} frames of the last revision`);
  for (let i = 1; i < last.length; i++) assert.ok(last[i].pass > last[i - 1].pass, 'passes rise');
  assert.equal(last[0].pass, 0);
  assert.deepEqual(last.map((f) => f.converged), last.map((_, i) => i === last.length - 1));
});

function objectValues(copy) {
  const out = new Float32Array(copy.ids.length * 27);
  copy.ids.forEach((id, i) => out.set(copy.byId.get(id), 27 * i));
  return out;
}

test('SH grid and object SH frames decode as liblucent-client does, f32 and rgba16f', { skip }, async () => {
  const subs = [];
  for (const encoding of ['f32', 'rgba16f']) {
    const c = await connect(`js-sh-${encoding}`);
    const frames = H.record(c), seen = [];
    c.on('shgrid', (copy) => seen.push({ stream: 'shgrid', crc: crc32(H.floatBytes(copy.data)) }));
    c.on('objects', (copy) => seen.push({ stream: 'objects', crc: crc32(H.floatBytes(objectValues(copy))), ids: copy.ids }));
    await c.subscribe('shgrid', { encoding });
    await c.subscribe('objects', { encoding });
    subs.push({ encoding, c, frames, seen });
  }
  const ctl = subs[0].c;
  const ok = await ctl.request({ type: 'object.set', object: { id: 'js-cube', asset: ctl.welcome.scene.assets[0],
    translation: [0.28, 0.15, 0.28], scale: [0.05, 0.05, 0.05] } });
  for (const s of subs) {
    await H.waitConverged(s.c, 'shgrid', ok.revision);
    await H.waitConverged(s.c, 'objects', ok.revision);
  }
  for (const s of subs) {
    assert.deepEqual(s.c.errors.map((e) => e.message), []);
    const { results } = await H.replay(s.frames.map((f) => f.bytes), dir);
    assert.equal(results.length, s.seen.length);
    results.forEach((r, i) => {
      assert.equal(r.rc, 0, r.error);
      assert.equal(r.stream, s.seen[i].stream);
      assert.equal(s.seen[i].crc, r.crc, `${s.encoding} ${r.stream} frame ${i} decodes bit for bit as liblucent-client`);
      if (r.stream === 'objects') assert.deepEqual(s.seen[i].ids, r.ids);
    });
    const g = s.c.shgrid, dims = ctl.welcome.scene.grid.dims;
    assert.deepEqual(g.dims, dims);
    assert.equal(g.data.length, dims[0] * dims[1] * dims[2] * 27);
    assert.deepEqual(g.origin, ctl.welcome.scene.grid.origin);
    assert.ok(s.c.objects.byId.has('js-cube'));
    const sh = s.c.objects.byId.get('js-cube');
    assert.equal(sh.length, 27);
    assert.ok(sh[0] > 0 && sh[1] > 0 && sh[2] > 0, `the cube is lit: c0 = ${sh.slice(0, 3)}`);
  }
  // half floats are the f32 values rounded to 11 significant bits
  const [f, h] = [subs[0].c, subs[1].c];
  assert.equal(f.shgrid.revision, h.shgrid.revision);
  const pairs = [[f.shgrid.data, h.shgrid.data], [f.objects.byId.get('js-cube'), h.objects.byId.get('js-cube')]];
  for (const [a, b] of pairs)
    for (let i = 0; i < a.length; i++)
      assert.ok(Math.abs(a[i] - b[i]) <= Math.abs(a[i]) * 2 ** -11 + 2 ** -24, `value ${i}: ${a[i]} vs half ${b[i]}`);
  await ctl.request({ type: 'object.remove', object_id: 'js-cube' });
});

test('a frame with a bad CRC is rejected, the copy kept, and a snapshot brings a keyframe', { skip }, async () => {
  const c = await connect('js-crc');
  const frames = H.record(c);
  await c.subscribe('lightmap', { encoding: 'rgb9e5', delta: 'residual' });
  await H.waitConverged(c, 'lightmap', c.revision);
  const good = frames.reduce((a, f) => (f.bytes.length > a.length ? f.bytes : a), new Uint8Array(0));
  const bad = good.slice();
  bad[good.length - 5] ^= 0x10; // one payload bit
  const before = c.lightmap.data.slice(), seq = c.lightmap.sequence, resyncs = c.stats.resyncs;
  const err = H.waitFor(c, 'error', (e) => e.code === 'bad_frame');
  const key = H.waitFor(c, 'lightmap', (copy, h) => h.keyframe && h.sequence > seq, 10000, 'the resync keyframe');
  assert.equal(await c.handleFrame(bad), false);
  assert.deepEqual(c.lightmap.data, before, 'the bad frame left the copy as it was');
  assert.equal(c.lightmap.sequence, seq);
  const [e] = await err;
  assert.match(e.message, /CRC mismatch/);
  assert.equal(e.stream, 'lightmap');
  const [copy, h] = await key;
  assert.equal(h.sequence, seq + 1, 'the next frame is the keyframe the snapshot asked for');
  assert.equal(c.stats.resyncs, resyncs + 1);
  assert.equal(c.stats.badFrames, 1);
  assert.equal(copy.revision, c.revision);
  // the uncorrupted bytes still parse: the CRC caught exactly the flipped bit
  assert.equal(crc32(good.subarray(64), crc32(good.subarray(0, 60))), new DataView(good.buffer, good.byteOffset).getUint32(60, true));
});
