// After a light.set sent by the test over the protocol, the viewer's image changes where it
// must: a point light moved next to the left (red, +x) wall brightens the left half of the
// image more than the right, and moved to the right (green) wall the other way round, each
// within a bounded time; the page's own update->frame latency is printed.
import { check, connect, meanRegion, openViewer, run, screenshot, waitQuiet, waitShown } from './lib.mjs';
import { readPng } from './png.mjs';

const VIEW = '?ui=0&camera=0.278,0.2744,-0.8&target=0.278,0.2744,0.2796&fov=40&mode=full&tonemap=none&exposure=1';
const BOUND_MS = 10000; // the change must be on screen within this

await run('viewer.light_move', async ({ d, browser }) => {
  const c = await connect(d.port);
  const { page, errors } = await openViewer(browser, d.port, VIEW);
  await waitQuiet(page);
  const halves = (img) => [meanRegion(img, 0, 0, img.width / 2, img.height), meanRegion(img, img.width / 2, 0, img.width, img.height)];
  const base = halves(readPng(await screenshot(page, 'light_move_0_lamp')));
  console.log(`lamp only: left ${base[0].toFixed(2)}, right ${base[1].toFixed(2)}`);

  const move = async (name, position) => {
    const t0 = Date.now();
    const ok = await c.request({ type: 'light.set', light: { id: 'mover', type: 'point', position, intensity: 0.04 } });
    const waited = await waitShown(page, ok.revision, BOUND_MS);
    const total = Date.now() - t0;
    const latency = await page.evaluate(() => window.lucentViewer.lastLatencyMs());
    console.log(`${name}: revision ${ok.revision} on screen ${total} ms after the test sent light.set; ` +
      `the page measured ${latency === null ? 'nothing' : `${latency.toFixed(1)} ms`} from its changed message to the frame drawn`);
    check(total < BOUND_MS, `${name}: the image of revision ${ok.revision} was drawn within ${BOUND_MS} ms (${total} ms)`);
    check(latency !== null && latency >= 0 && latency < BOUND_MS, `${name}: the page measured its latency (${latency} ms)`);
    await waitQuiet(page);
    return halves(readPng(await screenshot(page, `light_move_${name}`)));
  };

  const left = await move('left', [0.5, 0.3, 0.25]);
  const dl = [left[0] - base[0], left[1] - base[1]];
  console.log(`light at the left wall: left half +${dl[0].toFixed(2)}, right half +${dl[1].toFixed(2)}`);
  check(dl[0] > 2 && dl[0] > 1.5 * dl[1], `a light at the left wall brightens the left half more (${dl[0].toFixed(2)} vs ${dl[1].toFixed(2)})`);

  const right = await move('right', [0.056, 0.3, 0.25]);
  const dr = [right[0] - base[0], right[1] - base[1]];
  console.log(`light at the right wall: left half +${dr[0].toFixed(2)}, right half +${dr[1].toFixed(2)}`);
  check(dr[1] > 2 && dr[1] > 1.5 * dr[0], `a light at the right wall brightens the right half more (${dr[1].toFixed(2)} vs ${dr[0].toFixed(2)})`);
  check(right[0] < left[0] && right[1] > left[1], 'moving the light from left to right darkens the left half and brightens the right');

  const hud = await page.textContent('#hud-changed');
  check(hud.includes('light.set') && hud.includes('viewer-test'), `the HUD lists the other client's changes ("${hud.slice(0, 80)}")`);
  check(errors.length === 0, `no console errors (${errors.join(' | ') || 'none'})`);
  c.close();
});
