// Shared pieces of the viewer's browser tests: skip rules (exit 77), lucentd on a free port,
// headless chromium (Debian's /usr/bin/chromium, WebGL2 on SwiftShader) through playwright-core,
// a protocol client (client/js/lucent.js over the ws package), and image statistics.
import { existsSync, mkdirSync, mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { createRequire } from 'node:module';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { pathToFileURL } from 'node:url';

export const SOURCE = process.env.LUCENT_SOURCE_DIR || resolve(new URL('../..', import.meta.url).pathname);
export const BINARY = process.env.LUCENT_BINARY_DIR || join(SOURCE, 'build');
export const LUCENTD = join(BINARY, 'bin', 'lucentd');
export const LUCENT_REF = join(BINARY, 'bin', 'lucent-ref');
export const CORNELL = join(BINARY, 'cornell.lcb');
export const WWW = join(BINARY, 'share', 'lucent', 'www');
export const CHROMIUM = process.env.LUCENT_CHROMIUM || '/usr/bin/chromium';
export const SHOTS = join(BINARY, 'viewer-screenshots');
const NODE_MODULES = join(SOURCE, 'client', 'node_modules');

export function skip(reason) {
  console.log(`SKIP: ${reason}`);
  process.exit(77);
}

export function fail(message) {
  console.error(`FAIL: ${message}`);
  process.exitCode = 1;
  throw new Error(message);
}

export function check(cond, message) {
  if (!cond) fail(message);
  console.log(`ok: ${message}`);
}

/** Exits 77 naming what is missing: client/node_modules, chromium, lucentd, the bake, the bundle. */
export function requirePrereqs() {
  if (!existsSync(join(NODE_MODULES, 'playwright-core')) || !existsSync(join(NODE_MODULES, 'ws')))
    skip(`client/node_modules lacks playwright-core or ws (cd client && npm ci): ${NODE_MODULES}`);
  if (!existsSync(CHROMIUM)) skip(`no chromium at ${CHROMIUM} (apt-get install chromium, or set LUCENT_CHROMIUM)`);
  if (!existsSync(LUCENTD)) skip(`no lucentd at ${LUCENTD} (build the lucentd target)`);
  if (!existsSync(CORNELL)) skip(`no Cornell bake at ${CORNELL} (build the cornell_bake target)`);
  if (!existsSync(join(WWW, 'viewer.js'))) skip(`no viewer bundle in ${WWW} (build the viewer_bundle target)`);
}

const require = createRequire(join(NODE_MODULES, 'x.js'));
export const { chromium } = require('playwright-core');
const WebSocket = require('ws');
const { LucentClient } = await import(pathToFileURL(join(SOURCE, 'client', 'js', 'lucent.js')).href);
const harness = await import(pathToFileURL(join(SOURCE, 'client', 'js', 'harness', 'lucentd.mjs')).href);

/** Starts lucentd through the JS client's test harness (--port 0, cpu backend, no tokens, this
 *  build's viewer as --www, its state in a fresh temporary directory) and waits
 *  for its `lucentd listening port=N` line. Returns {port, proc, stop(), log()}. */
export async function startLucentd(args = []) {
  const dir = mkdtempSync(join(tmpdir(), 'lucent-viewer-'));
  const d = await harness.startLucentd({ stateDir: join(dir, 'state'), tokens: false, args: ['--www', WWW, ...args] });
  return {
    ...d, dir,
    stop: async () => {
      await d.stop();
      rmSync(dir, { recursive: true, force: true });
    },
  };
}

/** A protocol client of the test itself (the JS client in Node). */
export async function connect(port, token = '', name = 'viewer-test') {
  const c = new LucentClient(`ws://127.0.0.1:${port}/`, { WebSocket, token, client: name, timeout: 15000 });
  await c.connect();
  return c;
}

export async function launch() {
  return chromium.launch({ executablePath: CHROMIUM, headless: true,
    args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--disable-gpu-sandbox'] });
}

/** Opens the viewer at `query`, collecting console errors and page errors; waits for its
 *  ready promise (welcome, geometry, state, the first lightmap frame drawn). */
export async function openViewer(browser, port, query, { width = 320, height = 240 } = {}) {
  const page = await browser.newPage({ viewport: { width, height }, deviceScaleFactor: 1 });
  const errors = [];
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  page.on('pageerror', (e) => errors.push(`pageerror: ${e.message}`));
  const t0 = Date.now();
  await page.goto(`http://127.0.0.1:${port}/${query}`);
  await page.evaluate(() => window.lucentViewer.ready);
  console.log(`viewer ready in ${Date.now() - t0} ms (${query})`);
  return { page, errors };
}

/** Waits until the page has drawn a lightmap frame of revision >= rev; returns the ms waited. */
export async function waitShown(page, rev, timeoutMs = 15000) {
  const t0 = Date.now();
  // revision() changes in draw() after the render that used the frame: the canvas has it.
  await page.waitForFunction((r) => window.lucentViewer.revision() >= r, rev, { timeout: timeoutMs, polling: 20 });
  return Date.now() - t0;
}

/** Waits until the page has drawn its revision's last lightmap frame (converged, PROTOCOL.md
 *  §6.1.1) of revision >= rev; returns the ms waited. Unlike waitQuiet it cannot return between
 *  two refinement passes that are slower than the quiet time (as they are under ASan). */
export async function waitConverged(page, rev, timeoutMs = 30000) {
  const t0 = Date.now();
  await page.waitForFunction((r) => window.lucentViewer.revision() >= r && window.lucentViewer.converged(), rev,
    { timeout: timeoutMs, polling: 20 }).catch((e) => fail(`no converged frame of revision >= ${rev} shown within ` +
      `${timeoutMs} ms (${e.message.split('\n')[0]})`));
  return Date.now() - t0;
}

/** Waits until the lightmap the page shows stops changing (the idle refinement converged or
 *  the server sends nothing more for `quietMs`). */
export async function waitQuiet(page, quietMs = 800, timeoutMs = 20000) {
  const end = Date.now() + timeoutMs;
  let last = await page.evaluate(() => window.lucentViewer.frameCount()), since = Date.now();
  while (Date.now() < end) {
    await page.waitForTimeout(100);
    const n = await page.evaluate(() => window.lucentViewer.frameCount());
    if (n !== last) { last = n; since = Date.now(); } else if (Date.now() - since >= quietMs) return;
  }
}

export async function screenshot(page, name) {
  mkdirSync(SHOTS, { recursive: true });
  const path = join(SHOTS, `${name}.png`);
  await page.screenshot({ path });
  return path;
}

/** Mean sRGB value (0..255, over R, G, B) of an RGBA image inside [x0, x1) x [y0, y1). */
export function meanRegion(img, x0, y0, x1, y1) {
  let s = 0, n = 0;
  for (let y = y0; y < y1; y++) for (let x = x0; x < x1; x++) {
    const i = 4 * (y * img.width + x);
    s += img.data[i] + img.data[i + 1] + img.data[i + 2];
    n += 3;
  }
  return s / n;
}

export function variance(img) {
  let s = 0, s2 = 0, n = 0;
  for (let i = 0; i < img.width * img.height; i++) for (let k = 0; k < 3; k++) {
    const v = img.data[4 * i + k];
    s += v; s2 += v * v; n++;
  }
  return s2 / n - (s / n) ** 2;
}

/** Mean absolute difference (sRGB 0..255, over R, G, B) excluding `margin` pixels at the edges. */
export function meanAbsDiff(a, b, margin) {
  if (a.width !== b.width || a.height !== b.height) fail(`image sizes differ: ${a.width}x${a.height} vs ${b.width}x${b.height}`);
  let s = 0, n = 0;
  for (let y = margin; y < a.height - margin; y++) for (let x = margin; x < a.width - margin; x++) {
    const i = 4 * (y * a.width + x);
    for (let k = 0; k < 3; k++) s += Math.abs(a.data[i + k] - b.data[i + k]);
    n += 3;
  }
  return s / n;
}

/** How far b is from being a again: the share of pixels whose R+G+B differ by 3 levels or
 *  more, and the largest such difference. lucentd's refinement of a new solution starts from
 *  the light of the one before (warm, outside --cluster) and stops at --refine-tolerance, so
 *  the same state reached from another state converges to light a little different: in the
 *  Cornell box ~0.5% of the pixels by 3-8 levels (summed). A real difference (an object's
 *  shadow, a light) moves ~20% of the pixels by up to ~250. */
export function differenceFromSame(a, b) {
  if (a.width !== b.width || a.height !== b.height) fail(`image sizes differ: ${a.width}x${a.height} vs ${b.width}x${b.height}`);
  let n = 0, max = 0;
  for (let i = 0; i < a.width * a.height; i++) {
    let d = 0;
    for (let k = 0; k < 3; k++) d += Math.abs(a.data[4 * i + k] - b.data[4 * i + k]);
    if (d >= 3) n++;
    max = Math.max(max, d);
  }
  const share = n / (a.width * a.height);
  return { share, max, same: share < 0.02 && max <= 24,
    text: `${(100 * share).toFixed(2)}% of the pixels differ by 3+ levels (R+G+B), at most ${max}; same: < 2%, <= 24` };
}

export function readText(path) {
  return readFileSync(path, 'utf8');
}

/** Runs `body` with lucentd and a browser, always cleaning both up; exit code 1 on failure. */
export async function run(name, body, { lucentdArgs = [] } = {}) {
  requirePrereqs();
  const t0 = Date.now();
  const d = await startLucentd(lucentdArgs);
  let browser = null;
  try {
    browser = await launch();
    await body({ d, browser });
    console.log(`${name}: passed in ${((Date.now() - t0) / 1000).toFixed(1)} s`);
  } catch (e) {
    console.error(`${name}: ${e.stack || e}`);
    const tail = d.log().slice(-600);
    if (tail) console.error(`lucentd stderr: ${tail}`);
    process.exitCode = 1;
  } finally {
    if (browser) await browser.close().catch(() => {});
    await d.stop();
  }
}
