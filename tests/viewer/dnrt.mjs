// The viewer shows what DNRT does: a red cube placed on the Cornell floor darkens the floor
// around its base (the contact shadow) and tints it red (its bounced light). The test bakes
// the Cornell box with a red cube asset (draft quality), places the cube, and compares the
// viewer's indirect-only image with DNRT on against the same view with `settings.set
// {"dnrt": false}`: the cube itself is drawn the same in both (an object never shadows its
// own SH), so every pixel that differs is the static scene's indirect light.
import { spawnSync } from 'node:child_process';
import { mkdtempSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { BINARY, SOURCE, check, connect, openViewer, run, screenshot, skip, waitConverged, differenceFromSame } from './lib.mjs';
import { readPng } from './png.mjs';

const VIEW = '?ui=0&camera=0.36,0.52,-0.28&target=0.40,0,0.16&fov=55&mode=indirect&tonemap=none&exposure=2';
const BAKE = join(BINARY, 'bin', 'lucent-bake');

const tmp = mkdtempSync(join(tmpdir(), 'lucent-dnrt-'));
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
// `neutral`, only where b is the white floor or blocks (not the red and green walls, not the
// red cube).
function difference(a, b, neutral = false) {
  let n = 0, r = 0, g = 0, bl = 0;
  for (let i = 0; i < a.width * a.height; i++) {
    if (neutral) {
      const R = b.data[4 * i], G = b.data[4 * i + 1], B = b.data[4 * i + 2];
      if (G < 20 || R > 1.5 * G || G > 1.1 * R) continue; /* the lamp is warm: the floor has R/G ~ 1.2 */
    }
    const dr = a.data[4 * i] - b.data[4 * i], dg = a.data[4 * i + 1] - b.data[4 * i + 1], db = a.data[4 * i + 2] - b.data[4 * i + 2];
    if (Math.abs(dr) + Math.abs(dg) + Math.abs(db) < 3) continue;
    n++; r += dr; g += dg; bl += db;
  }
  return { share: n / (a.width * a.height), r: n ? r / n : 0, g: n ? g / n : 0, b: n ? bl / n : 0 };
}

await run('viewer.dnrt', async ({ d, browser }) => {
  const c = await connect(d.port);
  const { welcome } = c;
  const info = welcome.scene.asset_info && welcome.scene.asset_info.red;
  check(info && info.transfer && info.transfer.coefficients === 4, `welcome says the red cube has a transfer grid (${JSON.stringify(info)})`);
  let ok = await c.request({ type: 'object.set', object: { id: 'cube', asset: 'red', translation: [0.42, 0, 0.12], scale: [1.5, 1.5, 1.5] } });
  const { page, errors } = await openViewer(browser, d.port, VIEW);
  await waitConverged(page, ok.revision);
  const on = readPng(await screenshot(page, 'dnrt_on'));
  ok = await c.request({ type: 'settings.set', settings: { dnrt: false } });
  await waitConverged(page, ok.revision);
  const off = readPng(await screenshot(page, 'dnrt_off'));
  const diff = difference(on, off), floor = difference(on, off, true);
  const show = (x) => `${(100 * x.share).toFixed(1)}% of the pixels; mean there R ${x.r.toFixed(2)}, G ${x.g.toFixed(2)}, ` +
    `B ${x.b.toFixed(2)} (sRGB levels)`;
  console.log(`DNRT on - off: everywhere ${show(diff)}; on the white surfaces ${show(floor)}`);
  check(diff.share > 0.02, `the cube changes the indirect light of a visible part of the image (${(100 * diff.share).toFixed(1)}%)`);
  check(floor.share > 0.02 && floor.g < -1, `the white floor around it is darker with DNRT (green ${floor.g.toFixed(2)})`);
  check(floor.r - floor.g > 1, `and redder: red falls less than green there (R ${floor.r.toFixed(2)}, G ${floor.g.toFixed(2)})`);
  ok = await c.request({ type: 'settings.set', settings: { dnrt: true } });
  await waitConverged(page, ok.revision);
  const again = readPng(await screenshot(page, 'dnrt_on_again'));
  const back = differenceFromSame(on, again);
  check(back.same, `switched back on, the image is the first one again (${back.text})`);
  check(errors.length === 0, `no console errors (${errors.join(' | ') || 'none'})`);
  c.close();
}, { lucentdArgs: ['--bake', lcb] });
