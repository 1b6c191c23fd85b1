// The viewer's MR panel helpers (client/viewer/src/mr.js) in Node: the 16-bit PNG decoder
// against PNGs written here with every filter type, and the point cloud's unprojection
// against §8.4's camera model in closed form.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { deflateSync } from 'node:zlib';
import { crc32 } from '../lucent.js';

let mr = null, why = '';
try {
  mr = await import('../../viewer/src/mr.js');
} catch (e) {
  why = `client/viewer/src/mr.js does not load (three.js missing? cd client && npm ci): ${e.message}`;
}
const skip = mr ? false : why;

function chunk(type, body) {
  const out = Buffer.alloc(12 + body.length);
  out.writeUInt32BE(body.length, 0);
  out.write(type, 4, 'latin1');
  Buffer.from(body).copy(out, 8);
  out.writeUInt32BE(crc32(out.subarray(4, 8 + body.length)), 8 + body.length);
  return out;
}

// Row y uses filter y mod 5 (None, Sub, Up, Average, Paeth), encoded as the PNG spec says.
function png(width, height, channels, bits, px) {
  const bpp = channels * bits / 8, stride = width * bpp, raw = Buffer.alloc(height * (stride + 1));
  for (let y = 0; y < height; y++) {
    const f = y % 5, row = y * stride;
    raw[y * (stride + 1)] = f;
    for (let i = 0; i < stride; i++) {
      const a = i >= bpp ? px[row + i - bpp] : 0, b = y ? px[row - stride + i] : 0, c = i >= bpp && y ? px[row - stride + i - bpp] : 0;
      const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
      const pred = [0, a, b, (a + b) >> 1, pa <= pb && pa <= pc ? a : pb <= pc ? b : c][f];
      raw[y * (stride + 1) + 1 + i] = (px[row + i] - pred) & 255;
    }
  }
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(width, 0);
  ihdr.writeUInt32BE(height, 4);
  ihdr[8] = bits;
  ihdr[9] = { 1: 0, 2: 4, 3: 2, 4: 6 }[channels];
  return new Uint8Array(Buffer.concat([Buffer.from([137, 80, 78, 71, 13, 10, 26, 10]), chunk('IHDR', ihdr),
    chunk('IDAT', deflateSync(raw)), chunk('IEND', Buffer.alloc(0))]));
}

test('decodePng keeps 16 bits (grey) through all five filters', { skip }, async () => {
  const W = 13, H = 11, vals = new Uint16Array(W * H), px = Buffer.alloc(2 * W * H);
  for (let i = 0; i < W * H; i++) {
    vals[i] = (i * 40503 + 7) & 0xffff; // every bit pattern, high bytes varying
    px.writeUInt16BE(vals[i], 2 * i);
  }
  const img = await mr.decodePng(png(W, H, 1, 16, px));
  assert.deepEqual([img.width, img.height, img.channels, img.bits], [W, H, 1, 16]);
  assert.ok(img.data instanceof Uint16Array);
  assert.deepEqual(img.data, vals);
});

test('decodePng reads 8-bit RGB and RGBA; refuses what it cannot read', { skip }, async () => {
  const W = 9, H = 7;
  for (const ch of [3, 4]) {
    const px = Buffer.alloc(ch * W * H);
    for (let i = 0; i < px.length; i++) px[i] = (i * 37 + 11) & 255;
    const img = await mr.decodePng(png(W, H, ch, 8, px));
    assert.equal(img.channels, ch);
    assert.deepEqual(Buffer.from(img.data), px);
  }
  await assert.rejects(mr.decodePng(new Uint8Array(40)), /not a PNG/);
  const bad = png(W, H, 1, 8, Buffer.alloc(W * H));
  bad[8 + 8 + 12] = 1; // interlace byte of IHDR (CRC not checked by the decoder)
  await assert.rejects(mr.decodePng(bad), /interlaced/);
});

test('unproject places each valid pixel per §8.4 (R·p + t) and drops depth 0', { skip }, () => {
  const W = 8, H = 8, depth = new Uint16Array(W * H).fill(2000), lin = new Float32Array(3 * W * H).fill(0.25);
  depth[9] = 0;
  const s = Math.SQRT1_2, f = { depth, lin, exposure: 4, fx: 10, fy: 12, cx: 3.5, cy: 4.25, translation: [1, 2, 3],
    rotation: [0, s, 0, s] }; // 90° about +Y: camera x -> world -z, camera -z -> world -x
  const pc = mr.unproject(f, W, H);
  assert.equal(pc.count, W * H - 1);
  const [x, y, z] = [2, 5, 2]; // pixel (2, 5), camera space
  const u = x + 0.5, v = y + 0.5, cam = [(u - 3.5) * z / 10, -(v - 4.25) * z / 12, -z];
  const world = [cam[2] + 1, cam[1] + 2, -cam[0] + 3];
  const k = y * W + x - 1; // one pixel (index 9) before it was dropped
  for (let c = 0; c < 3; c++) assert.ok(Math.abs(pc.positions[3 * k + c] - world[c]) < 1e-5, `coordinate ${c}`);
  assert.equal(pc.colors[3 * k], 0.25);
});

test('per-vertex shading averages the 8 sparse points\' records with the glTF weights (§8.7)', { skip }, async () => {
  const THREE = await import('three');
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6), 3));
  // vertex 0: points 0 and 2 with weights 0.25 / 0.75; vertex 1: point 1 (and an index past the
  // object's points, weight 0.5, which is ignored and renormalised away)
  g.setAttribute('_lucent_sp_index0', new THREE.BufferAttribute(new Uint16Array([0, 2, 0, 0, 1, 9, 0, 0]), 4));
  g.setAttribute('_lucent_sp_index1', new THREE.BufferAttribute(new Uint16Array(8), 4));
  g.setAttribute('_lucent_sp_weight0', new THREE.BufferAttribute(new Float32Array([0.25, 0.75, 0, 0, 0.5, 0.5, 0, 0]), 4));
  g.setAttribute('_lucent_sp_weight1', new THREE.BufferAttribute(new Float32Array(8), 4));
  const mesh = new THREE.Mesh(g), root = new THREE.Group();
  root.add(mesh);
  const rec = (I, l) => [...I, ...l, 0, 0, 0, 0, 0, 0];
  const records = new Float32Array([...rec([4, 0, 0], [1, 0, 0]), ...rec([0, 2, 0], [0, 5, 0]), ...rec([8, 4, 0], [0, 0, 1])]);
  const ctx = { objects: { get: (id) => (id === 'a' ? { root } : null) }, stats: {} };
  mr.MrPanel.prototype.shadeVertices.call(ctx, { objects: [{ id: 'a', count: 3, records }] });
  const m = root.children[0].geometry, I = m.attributes.lucentMrI.array, L = m.attributes.lucentMrL.array;
  assert.notEqual(m, g, 'the object got its own copy of the shared geometry');
  assert.deepEqual([...I.subarray(0, 3)], [0.25 * 4 + 0.75 * 8, 0.75 * 4, 0]);
  assert.deepEqual([...L.subarray(0, 3)], [0.25, 0, 0.75]);
  assert.deepEqual([...I.subarray(3, 6)], [0, 2, 0]);
  assert.deepEqual([...L.subarray(3, 6)], [0, 5, 0]);
  assert.equal(ctx.stats.shadedVertices, 2);
});
