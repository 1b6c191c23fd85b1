// Editing from the page. A controller page drags a light with the mouse (click its gizmo,
// drag TransformControls' centre handle): the server's state follows. A viewer page is
// read-only: the UI says so and disables editing; an edit sent anyway (the disabled button
// re-enabled in the DOM, as a user could) is refused by the server (`forbidden`), the page
// shows the refusal, and the state is unchanged.
import { check, connect, openViewer, run, screenshot } from './lib.mjs';

const CTL = 'ctl-secret', VIEW = 'view-secret';
const EYE = [0.278, 0.2744, -0.8], TARGET = [0.278, 0.2744, 0.2796], FOV = 40;
const W = 800, H = 600;
const QUERY = `camera=${EYE}&target=${TARGET}&fov=${FOV}&mode=full&tonemap=none&exposure=1`;

// Pixel position of world point p for three.js's PerspectiveCamera (lookAt with +Y up).
function project(p) {
  const sub = (a, b) => a.map((x, i) => x - b[i]);
  const dot = (a, b) => a.reduce((s, x, i) => s + x * b[i], 0);
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => a.map((x) => x / Math.hypot(...a));
  const f = norm(sub(TARGET, EYE)), r = norm(cross(f, [0, 1, 0])), u = cross(r, f);
  const d = sub(p, EYE), z = dot(d, f), t = Math.tan((FOV * Math.PI) / 360);
  return [W / 2 + (dot(d, r) / z / (t * (W / H))) * (W / 2), H / 2 - (dot(d, u) / z / t) * (H / 2)];
}

const light = (st, id) => st.lights.find((l) => l.id === id);

async function until(fn, ms, what) {
  const end = Date.now() + ms;
  for (;;) {
    const v = await fn();
    if (v) return v;
    if (Date.now() > end) throw new Error(`${what} did not happen within ${ms} ms`);
    await new Promise((r) => setTimeout(r, 50));
  }
}

await run('viewer.edit', async ({ d, browser }) => {
  const c = await connect(d.port, CTL);
  const start = [0.25, 0.3, 0.2];
  await c.request({ type: 'light.set', light: { id: 'drag-me', type: 'point', position: start, intensity: 0.04 } });

  // --- controller: select the light by its gizmo, drag it 120 px to the left.
  const ctl = await openViewer(browser, d.port, `?token=${CTL}&${QUERY}`, { width: W, height: H });
  const page = ctl.page;
  check(await page.evaluate(() => window.lucentViewer.role()) === 'controller', 'the controller token gives a controller page');
  const [gx, gy] = project(start);
  await page.mouse.click(gx, gy);
  await page.waitForSelector('#selection:not(.hidden)', { timeout: 5000 });
  check((await page.textContent('#sel-title')).includes('drag-me'), 'clicking the gizmo selects the light');
  await screenshot(page, 'edit_selected');
  await page.mouse.move(gx, gy);
  await page.mouse.down();
  const t0 = Date.now();
  for (let i = 1; i <= 12; i++) await page.mouse.move(gx - 10 * i, gy, { steps: 2 });
  await page.mouse.up();
  const dragMs = Date.now() - t0;
  const moved = await until(async () => {
    const p = light(await c.state(), 'drag-me').position;
    return p[0] > start[0] + 0.05 ? p : null;
  }, 5000, 'the dragged light reaching the server');
  console.log(`dragged 120 px left: server position ${moved.map((x) => x.toFixed(4)).join(', ')} (from ${start.join(', ')})`);
  check(moved[0] > start[0] + 0.05, `the light moved towards +x (image left) on the server (x ${start[0]} -> ${moved[0].toFixed(4)})`);
  check(Math.abs(moved[1] - start[1]) < 0.02, `its height stayed (y ${moved[1].toFixed(4)})`);
  // The centre handle moves the light in the view plane at its depth: 120 px is this far.
  const depth = start[2] - EYE[2], perPx = (2 * depth * Math.tan((FOV * Math.PI) / 360)) / H;
  const expectX = start[0] + 120 * perPx;
  await new Promise((r) => setTimeout(r, 300));
  const final = await c.state();
  const fx = light(final, 'drag-me').position[0];
  check(Math.abs(fx - expectX) < 0.01, `the last position was sent: x ${fx.toFixed(4)} is where the drag ended (${expectX.toFixed(4)})`);
  const sent = final.revision - 1, rate = sent / (dragMs / 1000);
  console.log(`the drag sent ${sent} light.set in ${dragMs} ms (${rate.toFixed(1)}/s)`);
  check(rate <= 31, `light.set during the drag stayed at <= 30/s (${rate.toFixed(1)}/s)`);
  await screenshot(page, 'edit_dragged');

  // --- controller: edit the intensity in the panel.
  await page.fill('#sel-intensity', '0.08');
  await page.dispatchEvent('#sel-intensity', 'change');
  await until(async () => light(await c.state(), 'drag-me').intensity === 0.08, 5000, 'the panel edit reaching the server');
  check(true, 'the panel sets the intensity (0.08 cd on the server)');
  check(ctl.errors.length === 0, `controller page: no console errors (${ctl.errors.join(' | ') || 'none'})`);

  // --- viewer: read-only UI; a forced edit is refused and shown.
  const before = await c.state();
  const vw = await openViewer(browser, d.port, `?token=${VIEW}&${QUERY}`, { width: W, height: H });
  const vp = vw.page;
  check(await vp.evaluate(() => window.lucentViewer.role()) === 'viewer', 'the viewer token gives a viewer page');
  const bannerText = await vp.textContent('#banner');
  check(await vp.isVisible('#banner') && /read-only/.test(bannerText), `the page says it is read-only ("${bannerText}")`);
  check(await vp.isDisabled('#add-point') && await vp.isDisabled('#env-type'), 'the edit controls are disabled');
  await vp.evaluate(() => document.getElementById('add-point').removeAttribute('disabled'));
  await vp.click('#add-point');
  await vp.waitForSelector('#toast:not(.hidden)', { timeout: 5000 });
  const toastText = await vp.textContent('#toast');
  check(/forbidden/.test(toastText), `the refusal is shown ("${toastText}")`);
  const lastError = await vp.evaluate(() => window.lucentViewer.lastError());
  check(/forbidden/.test(lastError || ''), `lastError() says forbidden ("${lastError}")`);
  await screenshot(vp, 'edit_viewer_refused');
  const after = await c.state();
  check(after.revision === before.revision && after.lights.length === before.lights.length,
    `the server's state is unchanged (revision ${after.revision}, ${after.lights.length} lights)`);
  const unexpected = vw.errors.filter((e) => !/forbidden/.test(e));
  check(unexpected.length === 0, `viewer page: no console errors besides the refusal (${unexpected.join(' | ') || 'none'})`);
  c.close();
}, { lucentdArgs: ['--controller-tokens', CTL, '--viewer-tokens', VIEW] });
