// lucent.js in a real browser (headless Chromium through playwright-core): the page's own
// WebSocket and DecompressionStream. The page comes from lucentd's --www (same origin), takes
// residual deltas with the delta threshold at 0 and must end with the copy a Node client of
// the same server ends with, and equal, bit for bit, to a snapshot keyframe.
// Skips without Chromium (CHROMIUM, or chromium / chromium-browser / google-chrome on PATH).
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { join, delimiter } from 'node:path';
import { copyFileSync, existsSync, mkdirSync, writeFileSync } from 'node:fs';
import WebSocket from 'ws';
import { LucentClient, crc32 } from '../lucent.js';
import * as H from '../harness/lucentd.mjs';

function findChromium() {
  if (process.env.CHROMIUM) return existsSync(process.env.CHROMIUM) ? process.env.CHROMIUM : null;
  for (const d of (process.env.PATH || '').split(delimiter))
    for (const n of ['chromium', 'chromium-browser', 'google-chrome'])
      if (existsSync(join(d, n))) return join(d, n);
  return null;
}

let playwright = null;
try {
  playwright = await import('playwright-core');
} catch (e) {
  /* reported as the skip reason */
}
const chromiumPath = findChromium();
const skip = H.missing() || (!playwright && 'playwright-core is missing (npm ci in client/)') ||
  (!chromiumPath && 'no Chromium (set CHROMIUM)') || false;
let srv, dir, browser, node;

before(async () => {
  if (skip) return;
  dir = H.tempDir('browser');
  const www = join(dir, 'www');
  mkdirSync(www);
  copyFileSync(new URL('../lucent.js', import.meta.url), join(www, 'lucent.js'));
  writeFileSync(join(www, 'index.html'), '<!doctype html><title>lucent.js</title>\n');
  srv = await H.startLucentd({ stateDir: join(dir, 'state'), args: ['--www', www, '--delta-threshold', '0',
    '--keyframe-interval', '100000'] });
  browser = await playwright.chromium.launch({ executablePath: chromiumPath, args: ['--no-sandbox'] });
});

after(async () => {
  if (node) node.close();
  if (browser) await browser.close();
  if (srv) await srv.stop();
  if (dir) H.cleanup(dir);
});

// Runs in the page: connects with the browser's WebSocket, subscribes to residual rgb9e5
// deltas, waits for a converged frame of `rev`, then compares its copy with a snapshot keyframe.
async function inPage({ url, token, positions }) {
  const { LucentClient: Client, crc32: crc, lightmapToFloat32, inflateExact } = await import('/lucent.js');
  // the browser's inflate: exact sizes, and nothing after the stream's end
  const raw = new Uint8Array(500).map((_, i) => i % 13);
  const z = new Uint8Array(await new Response(new Blob([raw]).stream().pipeThrough(new CompressionStream('deflate'))).arrayBuffer());
  const outcome = (p) => p.then(() => 'ok', (e) => e.message);
  const inflate = [await outcome(inflateExact(z, 500)), await outcome(inflateExact(z, 499)),
    await outcome(inflateExact(new Uint8Array([...z, 7, 7]), 500))];
  const c = new Client(url, { token, client: 'js-browser' });
  const errors = [], kinds = [];
  c.on('error', (e) => errors.push(e.message));
  c.on('lightmap', (copy, h) => kinds.push(h.keyframe ? 'K' : h.residual ? 'R' : 'D'));
  const converged = (rev) => new Promise((res) => {
    const check = () => c.lightmap && c.lightmap.revision >= rev && c.lightmap.converged;
    if (check()) return res();
    const fn = () => check() && (c.off('lightmap', fn), res());
    c.on('lightmap', fn);
  });
  await c.connect();
  await c.subscribe('lightmap', { encoding: 'rgb9e5', delta: 'residual' });
  await converged(c.revision);
  let rev;
  for (const x of positions) {
    rev = (await c.request({ type: 'light.set', light: { id: 'web', type: 'point', position: [x, 0.4, 0.3], intensity: 0.2 } })).revision;
    await converged(rev);
  }
  const held = c.lightmap.data.slice();
  const rgb = lightmapToFloat32(c.lightmap);
  const key = new Promise((res) => c.on('lightmap', (copy, h) => h.keyframe && res(copy)));
  await c.snapshot();
  const copy = await key;
  const same = copy.data.length === held.length && copy.data.every((w, i) => w === held[i]);
  c.close();
  return { rev, errors, kinds: kinds.join(''), same, inflate, crc: crc(new Uint8Array(rgb.buffer)),
    decompressionStream: typeof DecompressionStream, userAgent: navigator.userAgent };
}

test('in Chromium: residual deltas through DecompressionStream, same copy as Node, bit-exact with a keyframe', { skip }, async () => {
  node = new LucentClient(srv.url, { token: H.TOKENS.viewer, WebSocket, client: 'js-node-peer' });
  await node.connect();
  await node.subscribe('lightmap', { encoding: 'rgb9e5', delta: 'residual' });
  const page = await browser.newPage();
  const logs = [];
  page.on('console', (m) => logs.push(m.text()));
  await page.goto(`http://127.0.0.1:${srv.port}/index.html`);
  const r = await page.evaluate(inPage, { url: srv.url, token: H.TOKENS.controller, positions: [0.2, 0.23] });
  assert.equal(r.decompressionStream, 'function');
  assert.equal(r.inflate[0], 'ok');
  assert.match(r.inflate[1], /more than 499/);
  assert.notEqual(r.inflate[2], 'ok', 'Chromium refuses bytes after the zlib stream');
  assert.deepEqual(r.errors, [], logs.join('\n'));
  assert.ok((r.kinds.match(/R/g) || []).length >= 5, `residual deltas applied in the browser: ${r.kinds}`);
  assert.ok(r.same, 'the browser\'s residual copy equals the snapshot keyframe, word for word');
  await H.waitConverged(node, 'lightmap', r.rev);
  const { lightmapToFloat32 } = await import('../lucent.js');
  assert.equal(r.crc, crc32(H.floatBytes(lightmapToFloat32(node.lightmap))), 'the browser and Node hold the same lightmap');
});
