// MR sessions (PROTOCOL.md §8): the upload frame encoder byte by byte and against frames the
// C encoder made (tests/fuzz/corpus/upload/), the mr.vpl stream parser, capabilities,
// mr.begin / mr.end and the upload window against a scripted server, and a live lucentd
// (skipped when it does not grant "mr").
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { readdirSync, readFileSync, existsSync } from 'node:fs';
import { join } from 'node:path';
import { inflateSync } from 'node:zlib';
import WebSocket from 'ws';
import { LucentClient, LucentError, crc32, encodeUploadFrame, decodeUploadHeader, parseFrame, halfToFloat } from '../lucent.js';
import * as H from '../harness/lucentd.mjs';

const CORPUS = join(H.SOURCE_DIR, 'tests', 'fuzz', 'corpus', 'upload');

function baseFrame(extra = {}) {
  const width = 8, height = 8, n = width * height;
  const depth = new Uint16Array(n), color = new Uint8Array(3 * n);
  for (let i = 0; i < n; i++) depth[i] = 1000 + i;
  for (let i = 0; i < 3 * n; i++) color[i] = (i * 7) & 255;
  return { sequence: 3, captureUs: 2 ** 40 + 12345, width, height, depthEncoding: 'u16mm', depth, colorEncoding: 'rgb8_srgb',
    color, fx: 6, fy: 6.5, cx: 4, cy: 4.25, translation: [0.5, 1.25, -2], rotation: [0, 0.6, 0, 0.8], exposure: 100, ...extra };
}

async function rejection(promise) {
  try {
    await promise;
  } catch (e) {
    return e;
  }
  assert.fail('expected a rejection');
}

// --- the encoder --------------------------------------------------------------------------

test('encodeUploadFrame writes every §8.4 field at its offset, reserved bytes 0, CRC over header 0..123 + planes', async () => {
  const f = baseFrame({ confidence: new Uint8Array(64).fill(200) });
  const b = await encodeUploadFrame(f), dv = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const n = 64;
  assert.equal(b.length, 128 + 2 * n + n + 3 * n, 'length = 128 + planes');
  assert.equal(dv.getUint32(0, true), 0x3155434c);
  assert.deepEqual([...b.subarray(0, 4)], [0x4c, 0x43, 0x55, 0x31], '"LCU1"');
  assert.equal(dv.getUint16(4, true), 1, 'version');
  assert.equal(b[6], 1, 'kind rgbd');
  assert.equal(b[7], 1, 'flag bit 0: confidence');
  assert.equal(dv.getUint16(8, true), 128);
  assert.equal(dv.getUint16(10, true), 0);
  assert.equal(dv.getUint32(12, true), 3);
  assert.equal(dv.getUint32(16, true), 12345, 'capture µs low word');
  assert.equal(dv.getUint32(20, true), 256, 'capture µs high word (2^40)');
  assert.deepEqual([dv.getUint16(24, true), dv.getUint16(26, true)], [8, 8]);
  assert.deepEqual([...b.subarray(28, 36)], [1, 1, 0, 0, 0, 0, 0, 0], 'encodings, no compression, reserved');
  const f32 = Array.from({ length: 12 }, (_, i) => dv.getFloat32(36 + 4 * i, true));
  assert.deepEqual(f32, [6, 6.5, 4, 4.25, 0.5, 1.25, -2, 0, Math.fround(0.6), 0, Math.fround(0.8), 100]);
  assert.deepEqual([dv.getUint32(84, true), dv.getUint32(88, true), dv.getUint32(92, true)], [2 * n, n, 3 * n]);
  assert.ok(b.subarray(96, 124).every((v) => v === 0), 'reserved 96..123');
  assert.equal(dv.getUint32(124, true), crc32(b.subarray(128), crc32(b.subarray(0, 124))));
  assert.equal(dv.getUint16(128, true), 1000, 'depth plane first');
  assert.equal(dv.getUint16(128 + 2 * 63, true), 1063);
  assert.equal(b[128 + 2 * n], 200, 'confidence after depth');
  assert.deepEqual([...b.subarray(128 + 3 * n, 128 + 3 * n + 3)], [0, 7, 14], 'colour last');
  const h = decodeUploadHeader(b);
  assert.equal(h.captureUs, 2 ** 40 + 12345);
});

test('compressed planes are zlib streams inflating to the raw planes; no confidence means flag 0 and size 0', async () => {
  const f = baseFrame({ compress: true, colorEncoding: 'rgb16f_linear', color: new Uint16Array(192).fill(0x3c00) });
  const b = await encodeUploadFrame(f), h = decodeUploadHeader(b);
  assert.equal(h.flags, 0);
  assert.deepEqual(h.compression, [1, 0, 1]);
  assert.equal(h.planeBytes[1], 0);
  assert.equal(b.length, 128 + h.planeBytes[0] + h.planeBytes[2]);
  assert.equal(b[128], 0x78, 'zlib header');
  const depth = inflateSync(b.subarray(128, 128 + h.planeBytes[0])), color = inflateSync(b.subarray(128 + h.planeBytes[0]));
  assert.deepEqual(new Uint16Array(depth.buffer, depth.byteOffset, 64), f.depth);
  assert.equal(color.length, 384);
  assert.equal(halfToFloat(color[0] | (color[1] << 8)), 1);
  const dv = new DataView(b.buffer, b.byteOffset);
  assert.equal(dv.getUint32(124, true), crc32(b.subarray(128), crc32(b.subarray(0, 124))));
});

test('encodeUploadFrame rejects bad inputs naming the field', async () => {
  const cases = [
    [{ sequence: 0 }, '/sequence'], [{ width: 7 }, '/width'], [{ depthEncoding: 'mm' }, '/depthEncoding'],
    [{ depth: new Uint16Array(3) }, '/depth'], [{ color: new Uint16Array(192) }, '/color'], [{ fx: 0 }, '/fx'],
    [{ fy: 2e5 }, '/fy'], [{ cx: 17 }, '/cx'], [{ cy: -9 }, '/cy'], [{ exposure: 0 }, '/exposure'],
    [{ translation: [0, 0] }, '/translation'], [{ rotation: [0, 0, 0, 2] }, '/rotation'],
    [{ confidence: new Uint8Array(5) }, '/confidence'], [{ captureUs: -1 }, '/captureUs'],
  ];
  for (const [bad, pointer] of cases) {
    const e = await rejection(encodeUploadFrame(baseFrame(bad)));
    assert.ok(e instanceof LucentError);
    assert.equal(e.code, 'invalid');
    assert.equal(e.pointer, pointer, JSON.stringify(bad));
  }
});

// Valid frames from the C encoder in the fuzz corpus: length, CRC and plane sizes consistent.
function corpusFrames() {
  if (!existsSync(CORPUS)) return [];
  const out = [];
  for (const name of readdirSync(CORPUS)) {
    const b = new Uint8Array(readFileSync(join(CORPUS, name)));
    if (b.length < 128) continue;
    const h = decodeUploadHeader(b), dv = new DataView(b.buffer, b.byteOffset);
    if (h.magic !== 0x3155434c || h.version !== 1 || h.headerSize !== 128 || h.kind !== 1) continue;
    if (b.length !== 128 + h.planeBytes[0] + h.planeBytes[1] + h.planeBytes[2]) continue;
    if (dv.getUint32(124, true) !== crc32(b.subarray(128), crc32(b.subarray(0, 124)))) continue;
    if (!h.depthEncoding || !h.colorEncoding || h.width < 8 || h.height < 8) continue;
    // valid as the C parser defines it: each plane is, or inflates to, exactly its raw size (the
    // fuzz runs add CRC-valid frames whose zlib streams are broken or the wrong size)
    const n = h.width * h.height;
    const raw = [2 * n, h.flags & 1 ? n : 0, (h.colorEncoding === 'rgb8_srgb' ? 3 : 6) * n];
    let at = 128, planesOk = true;
    for (let i = 0; i < 3 && planesOk; i++) {
      const p = b.subarray(at, (at += h.planeBytes[i]));
      if (h.compression[i] !== 1) planesOk = p.length === raw[i];
      else try { planesOk = raw[i] > 0 && inflateSync(p).length === raw[i]; } catch { planesOk = false; }
    }
    if (!planesOk) continue;
    out.push({ name, b, h });
  }
  return out;
}

test('re-encoding a C-encoded corpus frame from its decoded fields gives identical bytes', async (t) => {
  const frames = corpusFrames().filter(({ h }) => h.compression.every((c) => c === 0));
  if (!frames.length) return t.skip(`no valid uncompressed frame in ${CORPUS}`);
  for (const { name, b, h } of frames) {
    const n = h.width * h.height;
    let at = 128;
    const take = (len) => b.slice(at, (at += len));
    const depthBytes = take(h.planeBytes[0]), conf = h.flags & 1 ? take(h.planeBytes[1]) : null, colorBytes = take(h.planeBytes[2]);
    const depth = new Uint16Array(depthBytes.buffer, 0, n);
    const color = h.colorEncoding === 'rgb8_srgb' ? colorBytes : new Uint16Array(colorBytes.buffer, 0, 3 * n);
    const re = await encodeUploadFrame({ sequence: h.sequence, captureUs: h.captureUs, width: h.width, height: h.height,
      depthEncoding: h.depthEncoding, depth, colorEncoding: h.colorEncoding, color, confidence: conf,
      fx: h.fx, fy: h.fy, cx: h.cx, cy: h.cy, translation: h.translation, rotation: h.rotation, exposure: h.exposure });
    assert.deepEqual(re, b, `corpus ${name}`);
  }
});

test('a C-encoded compressed corpus frame decodes to planes our zlib-compressed re-encoding inflates to', async (t) => {
  const frames = corpusFrames().filter(({ h }) => h.compression.some((c) => c === 1));
  if (!frames.length) return t.skip('no valid compressed frame in the corpus');
  for (const { b, h } of frames) {
    let at = 128;
    const planes = h.planeBytes.map((len, i) => {
      const p = b.subarray(at, (at += len));
      return len && h.compression[i] === 1 ? new Uint8Array(inflateSync(p)) : p.slice();
    });
    const n = h.width * h.height;
    assert.equal(planes[0].length, 2 * n);
    const re = await encodeUploadFrame({ sequence: h.sequence, captureUs: h.captureUs, width: h.width, height: h.height,
      depthEncoding: h.depthEncoding, depth: new Uint16Array(planes[0].buffer, 0, n), colorEncoding: h.colorEncoding,
      color: h.colorEncoding === 'rgb8_srgb' ? planes[2] : new Uint16Array(planes[2].buffer, 0, 3 * n),
      confidence: h.flags & 1 ? planes[1] : null, fx: h.fx, fy: h.fy, cx: h.cx, cy: h.cy,
      translation: h.translation, rotation: h.rotation, exposure: h.exposure, compress: true });
    assert.deepEqual(re.subarray(0, 30), b.subarray(0, 30), 'header fields up to the compression bytes');
    assert.deepEqual(re.subarray(36, 84), b.subarray(36, 84), 'camera and exposure');
  }
});

// --- mr.vpl -------------------------------------------------------------------------------

// An LCF1 frame of stream 4 (§6.1 header, §8.7 payload).
function vplFrame(objects, { encoding = 3, height, badCount = null, rev = 9 } = {}) {
  const vb = encoding === 3 ? 4 : 2;
  const parts = [];
  let total = 0;
  for (const [i, o] of objects.entries()) {
    const rec = new Uint8Array(72 + o.values.length * vb), dv = new DataView(rec.buffer);
    rec.set(new TextEncoder().encode(o.id));
    dv.setUint32(64, badCount !== null && i === 0 ? badCount : o.values.length / 12, true);
    o.values.forEach((v, k) => (vb === 4 ? dv.setFloat32(72 + 4 * k, v, true) : dv.setUint16(72 + 2 * k, v, true)));
    parts.push(rec);
    total += o.values.length / 12;
  }
  const plen = parts.reduce((s, p) => s + p.length, 0), b = new Uint8Array(64 + plen), dv = new DataView(b.buffer);
  dv.setUint32(0, 0x3146434c, true);
  dv.setUint16(4, 1, true);
  b[6] = 4;
  b[7] = encoding;
  dv.setUint16(8, 1, true);
  dv.setUint16(10, 64, true);
  dv.setUint32(16, rev, true);
  dv.setUint32(24, 1, true);
  dv.setUint32(40, objects.length, true);
  dv.setUint32(44, height ?? total, true);
  dv.setUint32(48, 1, true);
  dv.setUint32(56, plen, true);
  let at = 64;
  for (const p of parts) b.set(p, at), (at += p.length);
  dv.setUint32(60, crc32(b.subarray(64), crc32(b.subarray(0, 60))), true);
  return b;
}

const rec12 = (base) => Array.from({ length: 12 }, (_, k) => base + k);

test('mr.vpl f32 frames parse into per-object records and the client copy', async () => {
  const { c } = await fakeClient();
  const frame = vplFrame([{ id: 'cube', values: [...rec12(1), ...rec12(100)] }, { id: 'sphere', values: rec12(-5) }]);
  const hd = parseFrame(frame).header;
  assert.deepEqual([hd.stream, hd.width, hd.height, hd.encoding], ['mr.vpl', 2, 3, 'f32']);
  const seen = [];
  c.on('mr.vpl', (copy) => seen.push(copy));
  assert.equal(await c.handleFrame(frame), true);
  const v = c.mrVpl;
  assert.equal(seen[0], v);
  assert.deepEqual(v.objects.map((o) => [o.id, o.count]), [['cube', 2], ['sphere', 1]]);
  assert.ok(v.byId.get('cube').records instanceof Float32Array);
  assert.deepEqual([...v.byId.get('cube').records], [...rec12(1), ...rec12(100)]);
  assert.deepEqual([...v.byId.get('sphere').records], rec12(-5));
  assert.equal(v.revision, 9);
  c.close();
});

test('mr.vpl rgba16f records decode from binary16', async () => {
  const { c } = await fakeClient();
  const halves = [0x3c00, 0x4000, 0x3800, 0xc000, 0, 0x7bff, 0x3555, 0x4200, 0x4400, 0x4500, 0x4600, 0x4700];
  assert.equal(await c.handleFrame(vplFrame([{ id: 'o', values: halves }], { encoding: 2 })), true);
  const r = c.mrVpl.byId.get('o').records;
  assert.deepEqual([...r.subarray(0, 6)], [1, 2, 0.5, -2, 0, 65504]);
  assert.ok(Math.abs(r[6] - 1 / 3) < 1e-3);
  assert.deepEqual([...r.subarray(7)], [3, 4, 5, 6, 7]);
  c.close();
});

test('mr.vpl frames with inconsistent lengths are rejected', async () => {
  const objs = [{ id: 'a', values: rec12(0) }, { id: 'b', values: rec12(0) }];
  assert.throws(() => parseFrame(vplFrame(objs, { height: 3 })), /payload length/);
  const { c } = await fakeClient();
  assert.equal(await c.handleFrame(vplFrame(objs, { badCount: 2 })), false, 'count past the payload');
  assert.equal(await c.handleFrame(vplFrame(objs, { badCount: 0 })), false, 'counts do not sum to height');
  assert.equal(c.mrVpl, null);
  assert.equal(c.errors.filter((e) => e.code === 'bad_frame').length, 2);
  const rgb9 = vplFrame([{ id: 'a', values: rec12(0) }], { encoding: 1 });
  assert.throws(() => parseFrame(rgb9), /encoding/);
  c.close();
});

// --- a scripted server --------------------------------------------------------------------

function scripted(welcome, onMessage) {
  const server = { sockets: [] };
  class FakeWS {
    constructor() {
      Object.assign(this, { sent: [], binary: [], listeners: {}, readyState: 0 });
      server.sockets.push(this);
      setTimeout(() => (this.readyState = 1, this._fire('open', {})), 1);
    }
    addEventListener(t, fn) {
      (this.listeners[t] ||= []).push(fn);
    }
    send(data) {
      if (typeof data !== 'string') return void (this.binary.push(data), onMessage(this, null, data));
      const msg = JSON.parse(data);
      this.sent.push(msg);
      if (msg.type === 'hello') this.text({ type: 'welcome', role: 'controller', revision: 1, limits: { max_message: 65536 }, ...welcome, id: msg.id });
      else onMessage(this, msg, null);
    }
    close() {
      if (this.readyState === 3) return;
      this.readyState = 3;
      setTimeout(() => this._fire('close', { code: 1000, reason: '' }), 1);
    }
    _fire(t, ev) {
      for (const fn of this.listeners[t] || []) fn(ev);
    }
    text(obj) {
      setTimeout(() => this._fire('message', { data: JSON.stringify(obj) }), 0);
    }
  }
  server.WebSocket = FakeWS;
  return server;
}

async function fakeClient(options = {}, welcome = {}, onMessage = (ws, msg) => msg && ws.text({ type: 'ok', id: msg.id })) {
  const server = scripted(welcome, onMessage);
  const c = new LucentClient('ws://fake:1/', { WebSocket: server.WebSocket, timeout: 500, ...options });
  c.errors = [];
  c.on('error', (e) => c.errors.push(e));
  await c.connect();
  return { c, server, ws: server.sockets[0] };
}

const tick = (ms = 5) => new Promise((r) => setTimeout(r, ms));

test('capabilities go in hello; the welcome\'s grant and version are read, 1.0 without them', async () => {
  const a = await fakeClient({ capabilities: ['mr'] }, { version: '1.1', capabilities: ['mr'] });
  assert.deepEqual(a.ws.sent[0].capabilities, ['mr']);
  assert.deepEqual(a.c.capabilities, ['mr']);
  assert.equal(a.c.protocolVersion, '1.1');
  a.c.close();
  const b = await fakeClient();
  assert.equal('capabilities' in b.ws.sent[0], false, 'no capabilities field unless asked');
  assert.deepEqual(b.c.capabilities, []);
  assert.equal(b.c.protocolVersion, '1.0');
  b.c.close();
  assert.throws(() => new LucentClient('ws://x/', { WebSocket: class {}, capabilities: [''] }), LucentError);
});

test('mrBegin resolves ok.mr and rejects the server\'s error with its pointer; mrEnd sends mr.end', async () => {
  const { c, ws } = await fakeClient({}, {}, (w, msg) => {
    if (!msg) return;
    if (msg.type === 'mr.begin' && msg.session.width === 7)
      w.text({ type: 'error', id: msg.id, code: 'out_of_range', message: 'width', pointer: '/session/width' });
    else if (msg.type === 'mr.begin') w.text({ type: 'ok', id: msg.id, mr: { session: 1, max_frame: 4194304, max_rate: 10, max_lights: 4096, points: 64 } });
    else w.text({ type: 'ok', id: msg.id });
  });
  const mr = await c.mrBegin({ objects: ['cube'], width: 64, height: 48, depth: 'u16mm', color: 'rgb8_srgb' });
  assert.deepEqual(mr, { session: 1, max_frame: 4194304, max_rate: 10, max_lights: 4096, points: 64 });
  assert.deepEqual(ws.sent[1].session.objects, ['cube']);
  const e = await rejection(c.mrBegin({ objects: ['cube'], width: 7, height: 48 }));
  assert.deepEqual([e.code, e.pointer], ['out_of_range', '/session/width']);
  await c.mrEnd();
  assert.equal(ws.sent[ws.sent.length - 1].type, 'mr.end');
  c.close();
});

test('sendUploadFrame keeps at most 2 unacknowledged, resolves each ack, and an upload error rejects the oldest', async () => {
  const { c, ws } = await fakeClient();
  const acks = [];
  c.on('mr.ack', (a) => acks.push(a));
  const frames = await Promise.all([1, 2, 3, 4].map((s) => encodeUploadFrame(baseFrame({ sequence: s }))));
  const p = frames.map((f) => c.sendUploadFrame(f));
  await tick();
  assert.equal(ws.binary.length, 2, 'a third waits');
  ws.text({ type: 'mr.ack', seq: 1, capture_us: 5, status: 'processed', lights: 10, ms: 1.5 });
  assert.deepEqual(await p[0], { type: 'mr.ack', seq: 1, capture_us: 5, status: 'processed', lights: 10, ms: 1.5 });
  await tick();
  assert.equal(ws.binary.length, 3, 'the ack freed a slot');
  assert.deepEqual(ws.binary[2], frames[2]);
  ws.text({ type: 'error', code: 'rate_limited', message: 'slow down' });
  const e = await rejection(p[1]);
  assert.equal(e.code, 'rate_limited');
  await tick();
  assert.equal(ws.binary.length, 4);
  ws.text({ type: 'mr.ack', seq: 4, capture_us: 5, status: 'replaced', lights: 0, ms: 0 });
  ws.text({ type: 'mr.ack', seq: 3, capture_us: 5, status: 'processed', lights: 3, ms: 2 });
  assert.equal((await p[3]).status, 'replaced');
  assert.equal((await p[2]).lights, 3);
  assert.deepEqual(acks.map((a) => a.seq), [1, 4, 3]);
  const q = c.sendUploadFrame(frames[0]);
  c.close();
  assert.equal((await rejection(q)).code, 'disconnected');
  assert.equal((await rejection(c.sendUploadFrame(new Uint8Array(10)))).code, 'invalid');
});

// --- live ---------------------------------------------------------------------------------

const skipLive = H.missing() || false;
let srv, dir;

before(async () => {
  if (skipLive) return;
  dir = H.tempDir('mr');
  srv = await H.startLucentd({ stateDir: join(dir, 'state') });
});

after(async () => {
  if (srv) await srv.stop();
  if (dir) H.cleanup(dir);
});

test('live: mr.begin, an uploaded wall frame is acknowledged and mr.vpl delivers records for the object', { skip: skipLive }, async (t) => {
  const c = new LucentClient(srv.url, { token: H.TOKENS.controller, WebSocket, capabilities: ['mr'], timeout: 10000 });
  await c.connect();
  try {
    if (!c.capabilities.includes('mr')) return t.skip(`the server does not grant "mr" (version ${c.protocolVersion})`);
    await c.request({ type: 'object.set', object: { id: 'mrcube', asset: 'cube', translation: [0.42, 0.1, 0.12], scale: [1.5, 1.5, 1.5] } });
    const objects = ['mrcube'];
    const width = 64, height = 48;
    const mr = await c.mrBegin({ objects, width, height, depth: 'u16mm', color: 'rgb8_srgb' });
    assert.ok(mr.points > 0 && mr.max_frame > 0, JSON.stringify(mr));
    await c.subscribe('mr.vpl', { encoding: 'f32' });
    const vpl = H.waitFor(c, 'mr.vpl', (v) => v.objects.some((o) => o.count > 0), 15000);
    const n = width * height, depth = new Uint16Array(n).fill(1500), color = new Uint8Array(3 * n).fill(200);
    const bytes = await encodeUploadFrame({ sequence: 1, captureUs: 1000, width, height, depthEncoding: 'u16mm', depth,
      colorEncoding: 'rgb8_srgb', color, fx: 50, fy: 50, cx: 32, cy: 24, translation: [0, 0.5, 1.5], rotation: [0, 0, 0, 1],
      exposure: 1, compress: true });
    const ack = await c.sendUploadFrame(bytes);
    assert.equal(ack.seq, 1);
    assert.equal(ack.capture_us, 1000);
    assert.ok(ack.status === 'processed' || ack.status === 'replaced');
    const [v] = await vpl;
    const o = v.objects.find((x) => x.count > 0);
    assert.equal(o.records.length, 12 * o.count);
    assert.ok(o.records.every(Number.isFinite));
    await c.mrEnd();
  } finally {
    c.close();
  }
});
