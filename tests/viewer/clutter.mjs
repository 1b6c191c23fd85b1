// The viewer shows a clutter object's promotion (issue 19, PROTOCOL.md §4.5, §5.5): a red cube
// placed on the Cornell floor in mode `auto` is first carried by DNRT (its transfer grid),
// then, once it has rested and its DRT operators are built, by them (object.transport
// "clutter"). The test takes the viewer's indirect-only image without the cube, with it
// before promotion and after, and back in mode dynamic: the floor around the cube is darker
// than without it in both, promotion changes the image there, and demotion gives the first
// image back. The screenshots (clutter_none, clutter_before, clutter_after) are what
// bench/RESULTS.md shows.
import { spawnSync } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { BINARY, SOURCE, check, connect, openViewer, run, screenshot, skip, waitConverged, differenceFromSame } from './lib.mjs';
import { readPng } from './png.mjs';

const VIEW = '?ui=0&camera=0.36,0.52,-0.28&target=0.40,0,0.16&fov=55&mode=indirect&tonemap=none&exposure=2';
const BAKE = join(BINARY, 'bin', 'lucent-bake');

const tmp = mkdtempSync(join(tmpdir(), 'lucent-clutter-'));
process.on('exit', () => rmSync(tmp, { recursive: true, force: true }));
writeFileSync(join(tmp, 'red.mtl'), 'newmtl red\nKd 0.63 0.065 0.05\n');
writeFileSync(join(tmp, 'red.obj'), 'mtllib red.mtl\nusemtl red\n' +
  'v -0.05 0 -0.05\nv 0.05 0 -0.05\nv 0.05 0.1 -0.05\nv -0.05 0.1 -0.05\n' +
  'v -0.05 0 0.05\nv 0.05 0 0.05\nv 0.05 0.1 0.05\nv -0.05 0.1 0.05\n' +
  'f 1 4 3 2\nf 5 6 7 8\nf 1 5 8 4\nf 2 3 7 6\nf 4 8 7 3\nf 1 2 6 5\n');
const lcb = join(tmp, 'cornell-red.lcb');
const bake = spawnSync(BAKE, ['bake', join(SOURCE, 'scenes', 'cornell-box', 'cornell-box.obj'), '-o', lcb, '--quality', 'draft',
  '--no-write-glb', '--quiet', '--asset', `red=${join(tmp, 'red.obj')}`], { encoding: 'utf8' });
if (bake.error) skip(`cannot run ${BAKE}: ${bake.error.message}`);
check(bake.status === 0, `baked the Cornell box with a red cube asset (${(bake.stderr || '').slice(-300)})`);

// Mean per-channel difference a - b (sRGB levels) over the pixels where they differ; with
// `neutral`, only where b is the white floor or blocks (as in dnrt.mjs).
function difference(a, b, neutral = false) {
  let n = 0, r = 0, g = 0, bl = 0;
  for (let i = 0; i < a.width * a.height; i++) {
    if (neutral) {
      const R = b.data[4 * i], G = b.data[4 * i + 1], B = b.data[4 * i + 2];
      if (G < 20 || R > 1.5 * G || G > 1.1 * R || B > 1.1 * G) continue;
    }
    const dr = a.data[4 * i] - b.data[4 * i], dg = a.data[4 * i + 1] - b.data[4 * i + 1], db = a.data[4 * i + 2] - b.data[4 * i + 2];
    if (Math.abs(dr) + Math.abs(dg) + Math.abs(db) < 3) continue;
    n++; r += dr; g += dg; bl += db;
  }
  return { share: n / (a.width * a.height), r: n ? r / n : 0, g: n ? g / n : 0, b: n ? bl / n : 0 };
}
const show = (x) => `${(100 * x.share).toFixed(1)}% of the pixels; mean there R ${x.r.toFixed(2)}, G ${x.g.toFixed(2)}, ` +
  `B ${x.b.toFixed(2)} (sRGB levels)`;

/** The next object.transport for `id` with `transport`, within `ms`. */
function transportEvent(c, id, transport, ms = 30000) {
  return new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`no object.transport ${transport} for ${id} within ${ms} ms`)), ms);
    c.on('object.transport', (m) => {
      if (m.object_id === id && m.transport === transport) { clearTimeout(timer); resolve(m); }
    });
  });
}

// --clutter-rest 3: the DNRT image must converge before the cube is promoted, so that it can
// be the reference for the image after demotion (0.2-0.3 s under ASan; 3 s leaves room on a
// loaded machine).
await run('viewer.clutter', async ({ d, browser }) => {
  const c = await connect(d.port);
  check(c.welcome.scene.clutter && c.welcome.scene.clutter.rest === 3, `welcome.scene.clutter (${JSON.stringify(c.welcome.scene.clutter)})`);
  const { page, errors } = await openViewer(browser, d.port, VIEW);
  await waitConverged(page, 0);
  const none = readPng(await screenshot(page, 'clutter_none'));
  const cube = { id: 'cube', asset: 'red', translation: [0.42, 0, 0.12], scale: [1.5, 1.5, 1.5], mode: 'auto' };
  let promotedYet = false;
  const promoted = transportEvent(c, 'cube', 'clutter').then((m) => { promotedYet = true; return m; });
  let ok = await c.request({ type: 'object.set', object: cube });
  const placed = Date.now();
  await waitConverged(page, ok.revision);
  const before = readPng(await screenshot(page, 'clutter_before'));
  check(!promotedYet, `the DNRT image converged before promotion (in ${Date.now() - placed} ms)`);
  const ev = await promoted;
  console.log(`promoted: operators built in ${ev.build_ms.toFixed(0)} ms, ${(ev.bytes / 1048576).toFixed(1)} MiB`);
  // Promotion is a new solution of the same revision (a new series of passes, PROTOCOL.md
  // §6.1.1): its first frame follows the event; then wait for the series' last.
  await page.waitForFunction(() => !window.lucentViewer.converged(), null, { timeout: 5000, polling: 10 }).catch(() => {});
  await waitConverged(page, ok.revision);
  const after = readPng(await screenshot(page, 'clutter_after'));
  const dnrt = difference(before, none, true), drt = difference(after, none, true), change = difference(after, before);
  console.log(`on the white surfaces, DNRT - none: ${show(dnrt)}; DRT - none: ${show(drt)}; DRT - DNRT everywhere: ${show(change)}`);
  check(dnrt.share > 0.02 && dnrt.g < -1, `before promotion the floor around the cube is darker (DNRT, green ${dnrt.g.toFixed(2)})`);
  check(drt.share > 0.02 && drt.g < -1, `after promotion too (DRT, green ${drt.g.toFixed(2)})`);
  check(change.share > 0.005, `promotion changes the image (${(100 * change.share).toFixed(2)}% of the pixels)`);
  const demoted = transportEvent(c, 'cube', 'dynamic');
  ok = await c.request({ type: 'object.set', object: { ...cube, mode: 'dynamic' } });
  await demoted;
  await waitConverged(page, ok.revision);
  const back = differenceFromSame(before, readPng(await screenshot(page, 'clutter_demoted')));
  check(back.same, `in mode dynamic again, the image before promotion (${back.text})`);
  check(errors.length === 0, `no console errors (${errors.join(' | ') || 'none'})`);
  c.close();
}, { lucentdArgs: ['--bake', lcb, '--clutter-rest', '3'] });
