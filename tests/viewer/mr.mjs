// The viewer's MR panel (client/viewer/src/mr.js, PROTOCOL.md §8) against a live lucentd:
// ?mr= a synthetic lucent-rgbd/1 recording this test writes (a wall, 64x48, 3 frames; 16-bit
// depth PNGs, 8-bit sRGB colour PNGs, confidence PNGs) served to the page. The page is the MR client: hello
// with capabilities ['mr'], mr.begin with every object in the state (one cube placed here),
// uploads the frames at their timestamps. Checks: the point cloud has W*H points at the
// positions §8.4's camera model gives, an mr.ack arrives, the mr.vpl stream delivers records
// for the cube with light in them; a screenshot to build/viewer-screenshots/mr.png.
// Skips (77) when the server does not grant "mr".
import { mkdtempSync, readFileSync, rmSync, writeFileSync, mkdirSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { deflateSync } from 'node:zlib';
import { createRequire } from 'node:module';
import { check, run, screenshot, skip, requirePrereqs, startLucentd, LUCENTD, SOURCE } from './lib.mjs';
import { readPng } from './png.mjs';
import { crc32, LucentClient } from '../../client/js/lucent.js';

const W = 64, H = 48, FRAMES = 3, DEPTH_MM = 450;
const CAM = { fx: 50, fy: 50, cx: 32, cy: 24, t: [0.278, 0.25, 0.5] };

function chunk(type, body) {
  const out = Buffer.alloc(12 + body.length);
  out.writeUInt32BE(body.length, 0);
  out.write(type, 4, 'latin1');
  Buffer.from(body).copy(out, 8);
  out.writeUInt32BE(crc32(out.subarray(4, 8 + body.length)), 8 + body.length);
  return out;
}

// A PNG of `channels` samples of `bits` per pixel; each row gets filter (row mod 5), so the
// page's decoder meets all five filters.
function png(width, height, channels, bits, sample) {
  const bpp = channels * bits / 8, stride = width * bpp, raw = Buffer.alloc(height * (stride + 1));
  const px = Buffer.alloc(height * stride);
  for (let y = 0; y < height; y++) for (let x = 0; x < width; x++) for (let c = 0; c < channels; c++) {
    const v = sample(x, y, c), at = y * stride + (x * channels + c) * (bits / 8);
    if (bits === 16) px.writeUInt16BE(v, at);
    else px[at] = v;
  }
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
  ihdr[9] = channels === 1 ? 0 : 2;
  return Buffer.concat([Buffer.from([137, 80, 78, 71, 13, 10, 26, 10]), chunk('IHDR', ihdr), chunk('IDAT', deflateSync(raw)),
    chunk('IEND', Buffer.alloc(0))]);
}

function writeRecording(dir) {
  mkdirSync(dir, { recursive: true });
  writeFileSync(join(dir, 'capture.json'), JSON.stringify({ format: 'lucent-rgbd/1', width: W, height: H, frames: FRAMES }));
  for (let k = 1; k <= FRAMES; k++) {
    const n = String(k).padStart(5, '0');
    writeFileSync(join(dir, `frame_${n}.json`), JSON.stringify({ sequence: k, time_us: (k - 1) * 150000,
      intrinsics: { fx: CAM.fx, fy: CAM.fy, cx: CAM.cx, cy: CAM.cy }, pose: { translation: CAM.t, rotation: [0, 0, 0, 1] },
      exposure: 20, color: 'srgb8' }));
    // depth: the wall at 450 mm, and the pixel (0, 0) without a measurement in frame 2 only
    writeFileSync(join(dir, `depth_${n}.png`), png(W, H, 1, 16, (x, y) => (k === 2 && x === 0 && y === 0 ? 0 : DEPTH_MM + (x === 63 && y === 47 ? 300 : 0))));
    writeFileSync(join(dir, `color_${n}.png`), png(W, H, 3, 8, (x, y, c) => [255, 40 + 3 * x, 60 + 4 * y][c]));
    writeFileSync(join(dir, `confidence_${n}.png`), png(W, H, 1, 8, () => 255));
  }
}

const require = createRequire(join(SOURCE, 'client', 'node_modules', 'x.js'));
const WebSocket = require('ws');

async function mrClient(port) {
  const c = new LucentClient(`ws://127.0.0.1:${port}/`, { WebSocket, capabilities: ['mr'], timeout: 15000 });
  await c.connect();
  return c;
}

// Does this lucentd grant "mr"? (one without MR, or a bake without sparse points, does not)
requirePrereqs();
{
  const d = await startLucentd();
  let why = null;
  try {
    const c = await mrClient(d.port);
    if (!c.capabilities.includes('mr')) why = `lucentd (${LUCENTD}) does not grant "mr" (protocol ${c.protocolVersion})`;
    c.close();
  } finally {
    await d.stop();
  }
  if (why) skip(why);
}

const dir = mkdtempSync(join(tmpdir(), 'lucent-viewer-mr-'));
writeRecording(join(dir, 'wall'));

await run('viewer.mr', async ({ d, browser }) => {
  const mrc = await mrClient(d.port);
  await mrc.request({ type: 'object.set', object: { id: 'mrcube', asset: 'cube', translation: [0.278, 0.12, 0.25], scale: [1.5, 1.5, 1.5] } });
  mrc.close();

  const page = await browser.newPage({ viewport: { width: 480, height: 360 }, deviceScaleFactor: 1 });
  const errors = [];
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  page.on('pageerror', (e) => errors.push(`pageerror: ${e.message}`));
  await page.route((u) => u.pathname.startsWith('/mrtest/'), (route) => {
    const name = new URL(route.request().url()).pathname.replace(/^\/mrtest\//, '');
    try {
      route.fulfill({ status: 200, body: readFileSync(join(dir, name)) });
    } catch (e) {
      route.fulfill({ status: 404, body: 'no' });
    }
  });
  await page.goto(`http://127.0.0.1:${d.port}/?mr=/mrtest/wall/&camera=0.278,0.3,1.4&target=0.278,0.25,0.1&fov=45`);
  await page.evaluate(() => window.lucentViewer.ready);
  await page.waitForFunction(() => { const m = window.lucentViewer.mr(); return m && m.acks >= 1 && m.vplFrames >= 1; }, null,
    { timeout: 30000, polling: 50 }).catch(() => {});
  const m = await page.evaluate(() => window.lucentViewer.mr());
  console.log(`mr panel: ${JSON.stringify(m)}`);
  check(m.recording && m.recording.width === W && m.recording.height === H && m.recording.frames === FRAMES, 'the recording loaded: 64x48, 3 frames');
  check(m.grant && m.grant.points > 0, `mr.begin granted a session with ${m.grant && m.grant.points} sparse points`);
  check(JSON.stringify(m.sessionObjects) === '["mrcube"]', 'the session lights every object in the state (mrcube)');
  check(m.acks >= 1, `an mr.ack arrived (${m.acks}; ${m.processed} processed, lights ${m.lights}, ${m.ms} ms)`);
  check(m.vplFrames >= 1 && m.vplObjects.some((o) => o.id === 'mrcube' && o.count > 0), `mr.vpl delivered records for mrcube (${JSON.stringify(m.vplObjects)})`);
  check(m.lights > 0, `the server made area lights from the wall (${m.lights})`);
  // every VPL's line starts at its sparse point, from the asset glTF's sparse_point_accessors
  await page.waitForFunction(() => window.lucentViewer.mr().vplLines === 256, null, { timeout: 10000, polling: 50 }).catch(() => {});
  const lines = await page.evaluate(() => window.lucentViewer.mr().vplLines);
  check(lines === 256, `a line from each of the cube's 256 sparse points to its l_d (${lines})`);

  // The cloud of frame 1 or 3 has W*H points; frame 2 one fewer (its pixel (0, 0) has no
  // depth, so its first point is pixel (1, 0)). Positions per §8.4. One evaluate: the shown
  // frame changes as the recording plays.
  const cloud = await page.evaluate(() => {
    const v = window.lucentViewer, s = v.mr();
    return { shown: s.shownFrame, points: s.cloudPoints, first: v.mrPoint && v.mrPoint(0) };
  });
  check(cloud.points === (cloud.shown === 2 ? W * H - 1 : W * H), `the point cloud has ${cloud.points} points for frame ${cloud.shown} (W*H = ${W * H}${cloud.shown === 2 ? ' less the one without depth' : ''})`);
  const lucentd = cloud.first;
  if (lucentd) {
    const u = cloud.shown === 2 ? 1.5 : 0.5;
    const z = DEPTH_MM / 1000, x = (u - CAM.cx) * z / CAM.fx + CAM.t[0], y = -(0.5 - CAM.cy) * z / CAM.fy + CAM.t[1];
    const dz = Math.max(Math.abs(lucentd[0] - x), Math.abs(lucentd[1] - y), Math.abs(lucentd[2] - (CAM.t[2] - z)));
    check(dz < 1e-5, `frame ${cloud.shown}'s first pixel unprojects to (${lucentd.map((v) => v.toFixed(4))}) = §8.4's (${[x, y, CAM.t[2] - z].map((v) => v.toFixed(4))})`);
  }
  const shot = await screenshot(page, 'mr');
  const img = readPng(shot);
  console.log(`screenshot ${shot} (${img.width}x${img.height})`);
  await page.evaluate(() => document.getElementById('mr-lines').click());
  await screenshot(page, 'mr_lines');
  // Per-vertex shading from the VPLs (§8.7's glTF tables): the cube's vertices get I_d and l_d.
  await page.evaluate(() => document.getElementById('mr-shade').click());
  await page.waitForFunction(() => window.lucentViewer.mr().shadedVertices > 0, null, { timeout: 10000, polling: 50 }).catch(() => {});
  const sv = await page.evaluate(() => window.lucentViewer.mr().shadedVertices);
  check(sv > 0, `per-vertex VPL shading set I_d and l_d on ${sv} vertices of the cube`);
  await page.waitForTimeout(300);
  await screenshot(page, 'mr_shaded');
  const bad = errors.filter((e) => !/favicon/.test(e));
  check(bad.length === 0, `no console errors (${bad.length ? bad.join(' | ') : 'none'})`);
  await page.close();
}).finally(() => rmSync(dir, { recursive: true, force: true }));
