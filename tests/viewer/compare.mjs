// The viewer's screenshot against lucent-ref's path-traced image of the same view (the same
// camera in the URL, tone map none, exposure 1) on the embedded Cornell box: with its ceiling
// lamp alone, and with a point light added. Mean absolute difference in sRGB (0..255) over
// R, G, B, leaving out MARGIN pixels at the image edges.
import { execFileSync } from 'node:child_process';
import { writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { CORNELL, LUCENT_REF, SHOTS, check, connect, meanAbsDiff, openViewer, requirePrereqs, run, screenshot, skip,
  waitConverged } from './lib.mjs';
import { readPng, writePng } from './png.mjs';

const W = 320, H = 240, MARGIN = 3, SPP = 128;
const EYE = '0.278,0.2744,-0.8', TARGET = '0.278,0.2744,0.2796', FOV = '40';
const VIEW = `?ui=0&camera=${EYE}&target=${TARGET}&fov=${FOV}&mode=full&tonemap=none&exposure=1`;
// Measured 2.3 (lamp) and 2.1 (lamp + point light) at 128 spp; the path tracer's noise is
// part of it. Tolerances a little above.
const TOLERANCE = { lamp: 3.0, point: 3.0 };

requirePrereqs();
try {
  execFileSync(LUCENT_REF, ['camera', '--help'], { stdio: 'ignore' });
} catch (e) {
  skip(`${LUCENT_REF} camera --help failed: lucent-ref has no camera render`);
}

function diffImage(a, b) {
  const out = { width: a.width, height: a.height, data: new Uint8Array(a.data.length) };
  for (let i = 0; i < a.data.length; i += 4)
    for (let k = 0; k < 3; k++) out.data[i + k] = Math.max(0, Math.min(255, 128 + 2 * (a.data[i + k] - b.data[i + k])));
  return out;
}

await run('viewer.compare', async ({ d, browser }) => {
  const c = await connect(d.port);
  const { page, errors } = await openViewer(browser, d.port, VIEW, { width: W, height: H });
  const cases = [
    ['lamp', null],
    ['point', { type: 'light.set', light: { id: 'p1', type: 'point', position: [0.2, 0.42, 0.15], intensity: 0.05 } }],
  ];
  for (const [name, op] of cases) {
    const waited = await waitConverged(page, op ? (await c.request(op)).revision : 0);
    console.log(`${name}: the converged frame shown after ${waited} ms`);
    const shotPath = await screenshot(page, `compare_${name}_viewer`);
    const state = await c.state();
    const statePath = join(d.dir, `${name}.state.json`);
    writeFileSync(statePath, JSON.stringify(state));
    const refPath = join(SHOTS, `compare_${name}_pathtraced.png`);
    const t0 = Date.now();
    execFileSync(LUCENT_REF, ['camera', CORNELL, '--state', statePath, '--eye', EYE, '--target', TARGET, '--fov', FOV,
      '--width', String(W), '--height', String(H), '--spp', String(SPP), '--threads', '2', '--tonemap', 'none',
      '--exposure', '1', '--png', refPath], { stdio: ['ignore', 'ignore', 'pipe'] });
    const shot = readPng(shotPath), ref = readPng(refPath);
    const mad = meanAbsDiff(shot, ref, MARGIN);
    writePng(join(SHOTS, `compare_${name}_diff.png`), diffImage(shot, ref));
    console.log(`${name}: path-traced ${W}x${H} at ${SPP} spp in ${Date.now() - t0} ms; mean |viewer - path traced| = ` +
      `${mad.toFixed(3)} (sRGB 0..255, ${MARGIN}-pixel margin left out); ${shotPath} vs ${refPath}`);
    check(mad <= TOLERANCE[name], `${name}: the viewer matches the path tracer (mean abs difference ${mad.toFixed(3)} <= ${TOLERANCE[name]})`);
  }
  check(errors.length === 0, `no console errors (${errors.join(' | ') || 'none'})`);
  c.close();
});
