// Without a server: the decoding helpers, the SH helpers against closed forms and three.js,
// frame checks, and the client's frame and connection handling over a scripted WebSocket.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { deflateSync } from 'node:zlib';
import { readFileSync } from 'node:fs';
import { SphericalHarmonics3, Vector3 } from 'three';
import { transform } from 'esbuild';
import * as lucent from '../lucent.js';
import {
  LucentClient, LucentError, crc32, decodeRGB9E5, halfToFloat, lightmapToFloat32, parseFrame, shIrradiance,
  shToThreeCoefficients, inflateExact,
} from '../lucent.js';

// --- helpers ----------------------------------------------------------------------------

function rng(seed) {
  let s = seed >>> 0;
  return () => {
    s = (Math.imul(s, 1664525) + 1013904223) >>> 0;
    return s / 4294967296;
  };
}

const STREAM = { lightmap: 1, shgrid: 2, objects: 3 };
const W = 10, H = 6; // the scripted lightmap: tiles of 4 clipped at the right and bottom edges
const ENC = { rgb9e5: 1, rgba16f: 2, f32: 3 };

// A lucent/1 frame (PROTOCOL.md §6.1) with a correct CRC unless `crc` is given.
function frame({ stream = 'lightmap', encoding = 'rgb9e5', flags = 1, tiles = [], revision = 1, sequence = 1, width = W,
  height = H, depth = 1, tile = 4, payload = new Uint8Array(0), version = 1, magic = 0x3146434c, headerSize = 64,
  payloadLength, crc } = {}) {
  const b = new Uint8Array(64 + 4 * tiles.length + payload.length), dv = new DataView(b.buffer);
  dv.setUint32(0, magic, true);
  dv.setUint16(4, version, true);
  b[6] = typeof stream === 'number' ? stream : STREAM[stream];
  b[7] = typeof encoding === 'number' ? encoding : ENC[encoding];
  dv.setUint16(8, flags, true);
  dv.setUint16(10, headerSize, true);
  dv.setUint32(12, tiles.length, true);
  dv.setUint32(16, revision, true);
  dv.setUint32(24, sequence, true);
  dv.setUint32(32, 123456, true);
  dv.setUint32(40, width, true);
  dv.setUint32(44, height, true);
  dv.setUint32(48, depth, true);
  dv.setUint32(52, tile, true);
  dv.setUint32(56, payloadLength ?? payload.length, true);
  tiles.forEach((t, i) => dv.setUint32(64 + 4 * i, t, true));
  b.set(payload, 64 + 4 * tiles.length);
  dv.setUint32(60, crc ?? crc32(b.subarray(64), crc32(b.subarray(0, 60))), true);
  return b;
}

function bytes(typed) {
  return new Uint8Array(typed.buffer, typed.byteOffset, typed.byteLength);
}

// Texels of tile t of a W x H image with tile size S, row-major (§6.2).
function tileTexels(W, H, S, t) {
  const tw = Math.ceil(W / S), x0 = (t % tw) * S, y0 = Math.floor(t / tw) * S, out = [];
  for (let y = y0; y < Math.min(y0 + S, H); y++) for (let x = x0; x < Math.min(x0 + S, W); x++) out.push(y * W + x);
  return out;
}

// The residual the server sends (lc_residual_make): zigzag(new - old) per w-bit field.
function residualWord(now, held, fields) {
  let r = 0;
  for (const [off, w] of fields) {
    const mask = 2 ** w - 1;
    let d = (Math.floor(now / 2 ** off) % 2 ** w) - (Math.floor(held / 2 ** off) % 2 ** w);
    d = ((d % 2 ** w) + 2 ** w) % 2 ** w; // d mod 2^w
    const neg = d >= 2 ** (w - 1), zz = neg ? ((2 ** w - d) * 2 - 1) : d * 2; // zigzag of the signed value
    r += (zz & mask) * 2 ** off;
  }
  return r;
}

const FIELDS = { rgb9e5: [[0, 9], [9, 9], [18, 9], [27, 5]], rgba16f: [[0, 16]], f32: [[0, 32]] };
const WORD = { rgb9e5: Uint32Array, rgba16f: Uint16Array, f32: Uint32Array };
const PER_TEXEL = { rgb9e5: 1, rgba16f: 4, f32: 3 };

// A scripted server: every socket the client opens, what it sent, and replies.
function scripted(welcomeOverride = {}) {
  const server = { sockets: [], refuse: false, replies: true };
  server.welcome = { type: 'welcome', server: 'fake/1', protocol: 'lucent/1', role: 'controller', revision: 5,
    scene: { lightmap: { width: W, height: H, tile: 4, quantity: 'irradiance' },
      grid: { origin: [0, 0, 0], cell: 1, dims: [2, 2, 2], quantity: 'irradiance_sh', coefficients: 9 }, bands: 3,
      assets: [], materials: [] },
    limits: { max_message: 1024, max_lights: 8, max_objects: 4, max_batch: 4, rate: 100 }, ...welcomeOverride };
  class FakeWS {
    constructor(url, protocol) {
      Object.assign(this, { url, protocol, sent: [], listeners: {}, readyState: 0 });
      server.sockets.push(this);
      setTimeout(() => {
        if (server.refuse) return this._closeNow(1006, 'connection refused');
        this.readyState = 1;
        this._fire('open', {});
      }, 1);
    }
    addEventListener(t, fn) {
      (this.listeners[t] ||= []).push(fn);
    }
    send(text) {
      const msg = JSON.parse(text);
      this.sent.push(msg);
      if (msg.type === 'hello') {
        if (server.helloError) this.text({ type: 'error', id: msg.id, code: server.helloError, message: 'no' });
        else this.text({ ...server.welcome, id: msg.id });
      } else if (server.replies && msg.type !== 'ping') {
        this.text({ type: 'ok', id: msg.id, revision: server.welcome.revision });
      }
    }
    close(code = 1000, reason = '') {
      if (this.readyState !== 3) setTimeout(() => this._closeNow(code, reason), 1);
    }
    _closeNow(code, reason) {
      if (this.readyState === 3) return;
      this.readyState = 3;
      this._fire('close', { code, reason });
    }
    _fire(t, ev) {
      for (const fn of this.listeners[t] || []) fn(ev);
    }
    text(obj) {
      setTimeout(() => this._fire('message', { data: typeof obj === 'string' ? obj : JSON.stringify(obj) }), 0);
    }
  }
  server.WebSocket = FakeWS;
  server.last = () => server.sockets[server.sockets.length - 1];
  return server;
}

async function fakeClient(options = {}, welcome = {}) {
  const server = scripted(welcome);
  const c = new LucentClient('ws://fake:1/', { WebSocket: server.WebSocket, timeout: 500, ...options });
  c.errors = [];
  c.on('error', (e) => c.errors.push(e));
  await c.connect();
  return { c, server };
}

async function rejection(promise) {
  try {
    await promise;
  } catch (e) {
    return e;
  }
  assert.fail('expected a rejection');
}

const tick = (ms = 5) => new Promise((r) => setTimeout(r, ms));

// --- decoding ---------------------------------------------------------------------------

test('crc32 is zlib\'s CRC-32', () => {
  assert.equal(crc32(new TextEncoder().encode('123456789')), 0xcbf43926);
  assert.equal(crc32(new Uint8Array(0)), 0);
  const a = new TextEncoder().encode('hello '), b = new TextEncoder().encode('world');
  assert.equal(crc32(b, crc32(a)), crc32(new TextEncoder().encode('hello world')));
});

test('decodeRGB9E5 is GL RGB9_E5: 9-bit mantissas, shared exponent, bias 15', () => {
  const w = (r, g, b, e) => (r | (g << 9) | (b << 18) | (e << 27)) >>> 0;
  assert.deepEqual(decodeRGB9E5(w(256, 128, 0, 16)), [1, 0.5, 0]); // 256 * 2^(16-24)
  assert.deepEqual(decodeRGB9E5(w(1, 0, 0, 0)), [2 ** -24, 0, 0]);
  assert.deepEqual(decodeRGB9E5(w(511, 511, 511, 31)), [65408, 65408, 65408]);
  assert.deepEqual(decodeRGB9E5(0), [0, 0, 0]);
  const r = rng(1);
  for (let i = 0; i < 1000; i++) {
    const word = Math.floor(r() * 2 ** 32), e = word >>> 27;
    const want = [word & 511, (word >>> 9) & 511, (word >>> 18) & 511].map((m) => m * 2 ** (e - 15 - 9));
    assert.deepEqual(decodeRGB9E5(word), want);
  }
});

test('halfToFloat covers normals, subnormals, zeros, infinities and NaN', () => {
  const cases = [[0x3c00, 1], [0xc000, -2], [0x7bff, 65504], [0x0001, 2 ** -24], [0x03ff, 1023 * 2 ** -24],
    [0x0400, 2 ** -14], [0x3555, 0.333251953125], [0x7c00, Infinity], [0xfc00, -Infinity], [0x0000, 0]];
  for (const [h, v] of cases) assert.equal(halfToFloat(h), v, `0x${h.toString(16)}`);
  assert.ok(Object.is(halfToFloat(0x8000), -0));
  assert.ok(Number.isNaN(halfToFloat(0x7e00)));
  // every finite half: the value Float32 -> half rounding would give back
  for (let h = 0; h < 0x7c00; h += 7) assert.equal(Math.fround(halfToFloat(h)), halfToFloat(h));
});

test('lightmapToFloat32 decodes every encoding of a copy', () => {
  const rgb9e5 = { width: 2, height: 1, encoding: 'rgb9e5', data: new Uint32Array([(256 | (128 << 9)) + 16 * 2 ** 27, 0]) };
  assert.deepEqual([...lightmapToFloat32(rgb9e5)], [1, 0.5, 0, 0, 0, 0]);
  const half = { width: 1, height: 2, encoding: 'rgba16f', data: new Uint16Array([0x3c00, 0x4000, 0x3800, 0x3c00, 0, 0xc000, 0x7bff, 0x3c00]) };
  assert.deepEqual([...lightmapToFloat32(half)], [1, 2, 0.5, 0, -2, 65504]);
  const f = { width: 1, height: 1, encoding: 'f32', data: new Float32Array([0.25, 1.5, 3]) };
  const out = new Float32Array(3);
  assert.equal(lightmapToFloat32(f, out), out, 'a matching out array is reused');
  assert.deepEqual([...out], [0.25, 1.5, 3]);
  assert.throws(() => lightmapToFloat32({ width: 1, height: 1, encoding: 'x', data: [] }), LucentError);
});

// --- SH ---------------------------------------------------------------------------------

// y_i(d) of the real orthonormal basis, written out independently of the library.
function basis([x, y, z]) {
  const c1 = Math.sqrt(3 / (4 * Math.PI)), c2 = Math.sqrt(15 / (4 * Math.PI));
  return [1 / Math.sqrt(4 * Math.PI), c1 * y, c1 * z, c1 * x, c2 * x * y, c2 * y * z,
    Math.sqrt(5 / (16 * Math.PI)) * (3 * z * z - 1), c2 * x * z, Math.sqrt(15 / (16 * Math.PI)) * (x * x - y * y)];
}

function unit(r) {
  const z = 2 * r() - 1, a = 2 * Math.PI * r(), s = Math.sqrt(1 - z * z);
  return [s * Math.cos(a), s * Math.sin(a), z];
}

test('shIrradiance: a constant radiance L gives E = pi L for every normal', () => {
  const L = [0.7, 1.3, 2.5];
  const c = new Array(27).fill(0);
  // radiance SH of a constant: L * sqrt(4 pi) in y_0; cosine convolution multiplies band 0 by pi
  for (let ch = 0; ch < 3; ch++) c[ch] = Math.PI * L[ch] * Math.sqrt(4 * Math.PI);
  const r = rng(2);
  for (let i = 0; i < 50; i++) {
    const n = unit(r).map((v) => v * (0.5 + 2 * r())); // not unit length: normalised
    shIrradiance(c, n).forEach((e, ch) => assert.ok(Math.abs(e - Math.PI * L[ch]) < 1e-12, `${e} vs ${Math.PI * L[ch]}`));
  }
});

test('shIrradiance: a distant light gives the L2 clamped-cosine closed form, in the §2.3 order', () => {
  // radiance SH of a delta of irradiance E0 from d: E0 y_i(d); convolved: A_l E0 y_i(d). By the
  // addition theorem E(n) = E0 (1/4 + cos/2 + 5/16 (3 cos^2 - 1) / 2): only the angle matters,
  // which holds only with the right basis constants and the (y, z, x) band-1 order.
  const A = [Math.PI, 2 * Math.PI / 3, 2 * Math.PI / 3, 2 * Math.PI / 3, Math.PI / 4, Math.PI / 4, Math.PI / 4, Math.PI / 4, Math.PI / 4];
  const r = rng(3), E0 = 2;
  for (let k = 0; k < 20; k++) {
    const d = unit(r), yd = basis(d), c = [];
    for (let i = 0; i < 9; i++) c.push(A[i] * E0 * yd[i], A[i] * E0 * yd[i] * 0.5, 0);
    const n = unit(r), cos = n[0] * d[0] + n[1] * d[1] + n[2] * d[2];
    const want = Math.max(0, E0 * (0.25 + cos / 2 + (5 / 16) * (3 * cos * cos - 1) / 2));
    const [er, eg, eb] = shIrradiance(c, n);
    assert.ok(Math.abs(er - want) < 1e-9, `E(${cos.toFixed(3)}) = ${er}, closed form ${want}`);
    assert.ok(Math.abs(eg - want / 2) < 1e-9);
    assert.equal(eb, 0);
  }
  const c = new Array(27).fill(0);
  c[0] = -1; // negative irradiance (ringing) is clamped like lc_sh9_irradiance
  assert.deepEqual(shIrradiance(c, [0, 1, 0]), [0, 0, 0]);
});

test('shToThreeCoefficients: three.js getIrradianceAt gives the irradiance shIrradiance gives', () => {
  const r = rng(4);
  for (let k = 0; k < 20; k++) {
    const c = Array.from({ length: 27 }, (_, i) => (i < 3 ? 5 + r() : r() - 0.5));
    const three = shToThreeCoefficients(c);
    assert.equal(three.length, 9);
    three.forEach((v) => assert.equal(v.length, 3));
    const sh = new SphericalHarmonics3().fromArray(three.flat());
    for (let j = 0; j < 10; j++) {
      const n = unit(r), got = sh.getIrradianceAt(new Vector3(...n), new Vector3());
      const want = shIrradiance(c, n);
      [got.x, got.y, got.z].forEach((g, ch) => assert.ok(Math.abs(g - want[ch]) <= 1e-5 * Math.abs(want[ch]) + 1e-6,
        `three.js ${g} vs ${want[ch]}`));
    }
    // and its radiance: band l divided by pi, 2pi/3, pi/4
    assert.ok(Math.abs(three[0][0] - c[0] / Math.PI) < 1e-15);
    assert.ok(Math.abs(three[2][1] - c[7] / (2 * Math.PI / 3)) < 1e-15);
    assert.ok(Math.abs(three[8][2] - c[26] / (Math.PI / 4)) < 1e-15);
  }
});

// --- frame checks -----------------------------------------------------------------------

test('parseFrame rejects what lc_frame_parse rejects, naming it', () => {
  const key = { payload: new Uint8Array(W * H * 4) };
  assert.doesNotThrow(() => parseFrame(frame(key)));
  const bad = (opts, re) => assert.throws(() => parseFrame(opts instanceof Uint8Array ? opts : frame({ ...key, ...opts })),
    (e) => e instanceof LucentError && e.code === 'bad_frame' && re.test(e.message), String(re));
  bad(new Uint8Array(63), /shorter than the 64-byte header/);
  bad({ magic: 0x3146434d }, /bad magic/);
  bad({ version: 2 }, /unsupported version 2/);
  bad({ headerSize: 60 }, /header size is not 64/);
  bad({ payloadLength: 255 }, /length does not match/);
  bad({ crc: 1 }, /CRC mismatch/);
  const flipped = frame(key);
  flipped[64 + 17] ^= 1;
  bad(flipped, /CRC mismatch/);
  bad({ flags: 3 }, /flags must be keyframe, delta or delta \+ residual/);
  bad({ flags: 5 }, /flags must be/);
  bad({ tiles: [0] }, /a keyframe has no tile table/);
  bad({ encoding: 0 }, /bad lightmap encoding/);
  bad({ depth: 2 }, /bad lightmap dimensions/);
  bad({ payload: new Uint8Array(W * H * 4 - 4) }, /payload length does not match the stream/);
  const tile = new Uint8Array(4 * 4 * 4);
  bad({ flags: 2, tiles: [6], payload: tile }, /tile index outside the image/);
  bad({ flags: 2, tiles: [1, 0], payload: new Uint8Array(2 * tile.length) }, /not strictly ascending/);
  bad({ flags: 2, tiles: [0], payload: new Uint8Array(4) }, /payload length does not match the tiles/);
  bad({ flags: 2, tiles: [0], tile: 0, payload: tile }, /a delta needs a tile size/);
  bad({ flags: 6, tiles: [], payload: new Uint8Array(0) }, /an empty residual delta/);
  bad({ stream: 'shgrid', encoding: 'f32', flags: 6, tiles: [0], tile: 0, payload: new Uint8Array(4) }, /residual deltas are lightmap only/);
  bad({ stream: 'shgrid', encoding: 'rgb9e5', tile: 0, width: 1, height: 1, payload: new Uint8Array(27 * 4) }, /bad SH encoding/);
  bad({ stream: 'shgrid', encoding: 'f32', flags: 2, tile: 0, width: 1, height: 1, payload: new Uint8Array(27 * 4) }, /keyframes only/);
  bad({ stream: 'shgrid', encoding: 'f32', tile: 4, width: 1, height: 1, payload: new Uint8Array(27 * 4) }, /tile size must be 0/);
  bad({ stream: 'objects', encoding: 'f32', tile: 0, width: 1, height: 2, payload: new Uint8Array(64 + 27 * 4) }, /height and depth must be 1/);
  bad({ stream: 5, payload: new Uint8Array(W * H * 4) }, /unknown stream 5/);
});

test('parseFrame reads the pass (bits 8-15) and converged (bit 3), ignoring reserved bits 4-7', () => {
  const payload = new Uint8Array(W * H * 4);
  let h = parseFrame(frame({ payload, flags: 1 | 8 | 0x70 | (3 << 8) })).header;
  assert.deepEqual([h.keyframe, h.delta, h.residual, h.converged, h.pass], [true, false, false, true, 3]);
  h = parseFrame(frame({ payload })).header;
  assert.deepEqual([h.converged, h.pass], [false, 0], 'a server that does not set them: 0 and false');
  h = parseFrame(frame({ payload, flags: 1 | (255 << 8) })).header;
  assert.equal(h.pass, 255);
  assert.deepEqual([h.stream, h.encoding, h.revision, h.sequence, h.timestamp_us, h.width, h.tileSize],
    ['lightmap', 'rgb9e5', 1, 1, 123456, W, 4]);
});

test('inflateExact takes exactly the expected size and nothing after the stream', async () => {
  const raw = new Uint8Array(1000).map((_, i) => i * 7);
  const z = new Uint8Array(deflateSync(raw));
  assert.deepEqual(await inflateExact(z, 1000), raw);
  await assert.rejects(inflateExact(z, 999), /more than 999/);
  await assert.rejects(inflateExact(z, 1001), /not 1001/);
  const trailing = new Uint8Array(z.length + 2);
  trailing.set(z);
  await assert.rejects(inflateExact(trailing, 1000), /2 bytes after the zlib stream/);
  await assert.rejects(inflateExact(new Uint8Array([1, 2, 3]), 3));
  const stream = { decompressionStream: true }; // the browsers' path
  assert.deepEqual(await inflateExact(z, 1000, stream), raw);
  await assert.rejects(inflateExact(z, 999, stream), /more than 999/);
  await assert.rejects(inflateExact(z, 1001, stream), /not 1001/);
  await assert.rejects(inflateExact(new Uint8Array([1, 2, 3]), 3, stream));
});

// --- the client over a scripted socket --------------------------------------------------

function lightmapWords(encoding, r) {
  const n = W * H * PER_TEXEL[encoding], w = new WORD[encoding](n);
  for (let i = 0; i < n; i++) w[i] = Math.floor(r() * 2 ** (encoding === 'rgba16f' ? 16 : 32));
  return w;
}

async function sendFrame(c, f) {
  return c.handleFrame(f);
}

for (const encoding of ['rgb9e5', 'rgba16f', 'f32']) {
  test(`${encoding}: keyframe, tile delta and residual delta give the server's words`, async () => {
    const { c, server } = await fakeClient();
    const r = rng(10 + ENC[encoding]);
    const held = lightmapWords(encoding, r);
    const seen = [];
    c.on('lightmap', (copy, h) => seen.push(h.sequence));
    assert.equal(await sendFrame(c, frame({ encoding, payload: bytes(held), revision: 6, flags: 1 | (2 << 8) })), true);
    assert.equal(c.lightmap.encoding, encoding);
    assert.deepEqual(bytes(c.lightmap.data), bytes(held));
    assert.deepEqual([c.lightmap.pass, c.lightmap.converged, c.lightmap.tile, c.revision], [2, false, 4, 6]);
    const first = c.lightmap;
    // tile delta: tiles 1 and 3 get new words
    const now = held.slice(), per = PER_TEXEL[encoding];
    const tilePayload = [];
    for (const t of [1, 3])
      for (const i of tileTexels(W, H, 4, t))
        for (let k = 0; k < per; k++) {
          now[i * per + k] = Math.floor(r() * 2 ** (encoding === 'rgba16f' ? 16 : 32));
          tilePayload.push(now[i * per + k]);
        }
    const tp = bytes(new WORD[encoding](tilePayload));
    assert.equal(await sendFrame(c, frame({ encoding, flags: 2 | 8, tiles: [1, 3], payload: tp, sequence: 2, revision: 6 })), true);
    assert.equal(c.lightmap, first, 'a delta applies onto the same copy');
    assert.deepEqual(bytes(c.lightmap.data), bytes(now));
    assert.deepEqual([...c.lightmap.tiles], [1, 3]);
    assert.equal(c.lightmap.converged, true);
    // residual delta on tiles 0 and 2: some texels move, others keep (residual 0)
    const next = now.slice(), res = [];
    for (const t of [0, 2])
      for (const i of tileTexels(W, H, 4, t))
        for (let k = 0; k < per; k++) {
          const at = i * per + k, moved = r() < 0.7;
          if (moved) next[at] = Math.floor(r() * 2 ** (encoding === 'rgba16f' ? 16 : 32));
          res.push(residualWord(next[at], now[at], FIELDS[encoding]));
        }
    const z = new Uint8Array(deflateSync(bytes(new WORD[encoding](res))));
    assert.equal(await sendFrame(c, frame({ encoding, flags: 6, tiles: [0, 2], payload: z, sequence: 3, revision: 7 })), true);
    assert.deepEqual(bytes(c.lightmap.data), bytes(next), 'residuals add field by field, modulo 2^w');
    assert.deepEqual(seen, [1, 2, 3]);
    assert.equal(c.revision, 7);
    assert.deepEqual(c.errors, []);
    assert.equal(server.last().sent.filter((m) => m.type === 'snapshot').length, 0);
    c.close();
  });
}

test('a sequence gap, a delta without a copy and bad residuals are not applied and ask for a snapshot', async () => {
  const { c, server } = await fakeClient();
  const ws = server.last(), tile = bytes(new Uint32Array(16));
  const snapshots = () => ws.sent.filter((m) => m.type === 'snapshot' && String(m.id).startsWith('lc~resync-')).length;
  assert.equal(await c.handleFrame(frame({ flags: 2, tiles: [0], payload: tile })), false);
  assert.match(c.errors[0].message, /without a keyframe/);
  assert.equal(c.errors[0].code, 'resync');
  assert.equal(snapshots(), 1);
  await tick(); // the scripted server answers the snapshot: the next resync may go out
  assert.equal(await c.handleFrame(frame({ payload: new Uint8Array(W * H * 4), sequence: 1 })), true);
  const before = c.lightmap.data.slice();
  assert.equal(await c.handleFrame(frame({ flags: 2, tiles: [0], payload: tile.map(() => 9), sequence: 3 })), false);
  assert.match(c.errors[1].message, /sequence gap: 3 after 1/);
  assert.deepEqual(c.lightmap.data, before);
  await tick();
  assert.equal(snapshots(), 2);
  // still stale: the next delta in sequence is refused too, until a keyframe comes
  assert.equal(await c.handleFrame(frame({ flags: 2, tiles: [0], payload: tile, sequence: 2 })), false);
  await tick();
  assert.equal(await c.handleFrame(frame({ payload: new Uint8Array(W * H * 4), sequence: 4 })), true);
  const z = (n) => new Uint8Array(deflateSync(new Uint8Array(n)));
  for (const [payload, re] of [[z(60), /not 64/], [z(68), /more than 64/], [new Uint8Array([...z(64), 0]), /after the zlib stream/]]) {
    await tick();
    assert.equal(await c.handleFrame(frame({ flags: 6, tiles: [0], payload, sequence: c.lightmap.sequence + 1 })), false);
    assert.match(c.errors[c.errors.length - 1].message, re);
    assert.equal(c.errors[c.errors.length - 1].code, 'bad_frame');
    assert.deepEqual(c.lightmap.data, new Uint32Array(W * H), 'the copy is unchanged');
    await tick();
    assert.equal(await c.handleFrame(frame({ payload: new Uint8Array(W * H * 4), sequence: c.lightmap.sequence + 1 })), true);
  }
  assert.equal(c.stats.badFrames, 3);
  assert.ok(c.stats.resyncs >= 5);
  c.close();
});

test('frames that break the welcome\'s sizes are dropped without a snapshot loop', async () => {
  const { c, server } = await fakeClient();
  assert.equal(await c.handleFrame(frame({ width: 16, height: 16, payload: new Uint8Array(16 * 16 * 4) })), false);
  assert.match(c.errors[0].message, /lightmap 16x16 is not the welcome's 10x6/);
  assert.equal(c.lightmap, null);
  const sh = (dims) => frame({ stream: 'shgrid', encoding: 'f32', tile: 0, width: dims[0], height: dims[1], depth: dims[2],
    payload: new Uint8Array(dims[0] * dims[1] * dims[2] * 27 * 4) });
  assert.equal(await c.handleFrame(sh([2, 2, 3])), false);
  assert.match(c.errors[1].message, /grid 2x2x3 is not the welcome's 2x2x2/);
  assert.equal(await c.handleFrame(sh([2, 2, 2])), true);
  assert.equal(c.shgrid.data.length, 8 * 27);
  const objs = frame({ stream: 'objects', encoding: 'rgba16f', tile: 0, width: 5, height: 1, payload: new Uint8Array(5 * (64 + 54)) });
  assert.equal(await c.handleFrame(objs), false);
  assert.match(c.errors[2].message, /5 objects, over the welcome's max_objects 4/);
  assert.equal(server.last().sent.filter((m) => m.type === 'snapshot').length, 0);
  c.close();
});

test('object SH frames: ids up to their NUL, values as half floats', async () => {
  const { c } = await fakeClient();
  const rec = 64 + 27 * 2, payload = new Uint8Array(2 * rec);
  payload.set(new TextEncoder().encode('a-chair'), 0);
  payload.set(new TextEncoder().encode('b-lamp\u00e9'), rec);
  const dv = new DataView(payload.buffer);
  dv.setUint16(64, 0x3c00, true);
  dv.setUint16(rec + 64 + 2 * 26, 0xc000, true);
  assert.equal(await c.handleFrame(frame({ stream: 'objects', encoding: 'rgba16f', tile: 0, width: 2, height: 1, payload, flags: 1 | 8 })), true);
  assert.deepEqual(c.objects.ids, ['a-chair', 'b-lamp\u00e9']);
  assert.equal(c.objects.byId.get('a-chair')[0], 1);
  assert.equal(c.objects.byId.get('b-lamp\u00e9')[26], -2);
  assert.equal(c.objects.converged, true);
  c.close();
});

test('request: a timeout, a disconnect in flight, a server text over max_message', async () => {
  const { c, server } = await fakeClient();
  const ws = server.last();
  const t = await rejection(c.ping(1));
  assert.deepEqual([t.code, typeof t.id], ['timeout', 'number']); // the scripted server never answers pings
  server.replies = false;
  ws.text({ type: 'changed', revision: 9, pad: 'y'.repeat(1100) });
  await tick();
  assert.equal(c.errors[0].code, 'too_large', 'over the welcome\'s max_message (1024)');
  assert.equal(c.revision, 5, 'and not read');
  const p = c.ping(2), s = c.request({ type: 'state.get' });
  const closed = new Promise((r) => c.on('close', r));
  const p2 = c.request({ type: 'snapshot' });
  ws.text({ type: 'changed', revision: 10, pad: 'y'.repeat(1100) });
  await tick();
  assert.equal(c.revision, 10, 'a state reply may be larger: with one awaited, so may every message');
  ws._closeNow(1006, 'gone');
  for (const e of await Promise.all([p, s, p2].map(rejection))) assert.equal(e.code, 'disconnected');
  const ev = await closed;
  assert.deepEqual([ev.code, ev.reconnecting], [1006, false]);
  assert.equal((await rejection(c.ping())).code, 'disconnected');
});

test('reconnect: back-off with jitter, then hello again and every subscription with its settings', async () => {
  const { c, server } = await fakeClient({ reconnect: true, backoff: { initialMs: 20, maxMs: 40 }, client: 'js-unit' });
  await c.subscribe('lightmap', { encoding: 'rgba16f', delta: 'residual', max_rate: 30 });
  await c.subscribe('shgrid', { encoding: 'f32' });
  await c.subscribe('objects');
  await c.unsubscribe('objects');
  assert.equal(await c.handleFrame(frame({ payload: new Uint8Array(W * H * 4), sequence: 1 })), true);
  const delays = [];
  c.on('reconnecting', (x) => delays.push(x.delayMs));
  server.refuse = true;
  server.last()._closeNow(1006, 'gone');
  await tick(150);
  assert.ok(delays.length >= 3, `${delays.length} attempts`);
  assert.ok(delays[0] >= 16 && delays[0] <= 24 && delays[1] >= 32 && delays[2] <= 48, `delays ${delays}`);
  server.refuse = false;
  const welcomed = new Promise((r) => c.on('welcome', r));
  await welcomed;
  const ws = server.last();
  assert.deepEqual(ws.sent.map((m) => m.type), ['hello', 'subscribe', 'subscribe']);
  assert.deepEqual(ws.sent[0].client, 'js-unit');
  const subs = ws.sent.slice(1).map(({ id, ...rest }) => rest);
  assert.deepEqual(subs, [{ type: 'subscribe', stream: 'lightmap', encoding: 'rgba16f', delta: 'residual', max_rate: 30 },
    { type: 'subscribe', stream: 'shgrid', encoding: 'f32' }]);
  // the copy waits for a keyframe: a delta continuing the old sequence is refused
  assert.equal(await c.handleFrame(frame({ flags: 2, tiles: [0], payload: new Uint8Array(64), sequence: 2 })), false);
  assert.equal(c.stats.reconnects, 1);
  c.close();
});

test('reconnect gives up after maxRetries, and a refused hello is final', async () => {
  const { c, server } = await fakeClient({ reconnect: true, maxRetries: 2, backoff: { initialMs: 5, maxMs: 5 } });
  const closes = [];
  c.on('close', (x) => closes.push(x.reconnecting));
  server.refuse = true;
  server.last()._closeNow(1006, 'gone');
  await tick(100);
  assert.deepEqual(closes, [true, false]);
  assert.match(c.errors[c.errors.length - 1].message, /gave up reconnecting after 2 attempts/);
  const refused = scripted();
  refused.helloError = 'unauthorized';
  const d = new LucentClient('ws://fake:1/', { WebSocket: refused.WebSocket, reconnect: true });
  const e = await rejection(d.connect());
  assert.deepEqual([e.code, e.message], ['unauthorized', 'no']);
  assert.throws(() => new LucentClient('http://x/', { WebSocket: refused.WebSocket }), /not a ws:\/\/ or wss:\/\/ URL/);
  const first = scripted();
  first.refuse = true;
  const f = new LucentClient('ws://fake:1/', { WebSocket: first.WebSocket, reconnect: true });
  assert.equal((await rejection(f.connect())).code, 'connect_failed', 'a failed first connection rejects');
  await tick(50);
  assert.equal(first.sockets.length, 1, 'and is not retried');
});

test('lucent.d.ts parses and declares exactly what lucent.js exports', async () => {
  const dts = readFileSync(new URL('../lucent.d.ts', import.meta.url), 'utf8');
  await transform(dts, { loader: 'ts' }); // throws on a syntax error
  const declared = [...dts.matchAll(/^export declare (?:const|function|class) (\w+)/gm)].map((m) => m[1]).sort();
  assert.deepEqual(declared, Object.keys(lucent).sort());
  const body = dts.slice(dts.indexOf('export declare class LucentClient'));
  const methods = [...body.slice(0, body.indexOf('\n}')).matchAll(/^  (\w+)(?:<[^>]*>)?\(/gm)].map((m) => m[1]).filter((n) => n !== 'constructor').sort();
  const proto = Object.getOwnPropertyNames(LucentClient.prototype).filter((n) => n !== 'constructor' && !n.startsWith('_') && n !== 'connected');
  assert.deepEqual(methods, proto.sort());
  for (const f of ['connected', 'welcome', 'role', 'revision', 'lightmap', 'shgrid', 'objects', 'stats', 'url'])
    assert.match(body, new RegExp(`^  (readonly )?${f}:`, 'm'), f);
});
