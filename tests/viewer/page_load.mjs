// The viewer page loads with no console errors, draws a canvas that is not blank, shows the
// server's revision in its HUD, and writes a shareable URL that reproduces the view exactly.
import { check, connect, meanAbsDiff, openViewer, run, screenshot, variance, waitQuiet } from './lib.mjs';
import { readPng } from './png.mjs';

await run('viewer.page_load', async ({ d, browser }) => {
  const c = await connect(d.port);
  const ok = await c.request({ type: 'light.set', light: { id: 'fill', type: 'point', position: [0.278, 0.45, 0.2], intensity: 0.03 } });
  const rev = ok.revision;
  check(rev >= 1, `a change gives the server revision ${rev}`);

  const { page, errors } = await openViewer(browser, d.port, '', { width: 480, height: 360 });
  await waitQuiet(page);
  const shot = await screenshot(page, 'page_load');
  const img = readPng(shot);
  const v = variance(img);
  console.log(`canvas pixel variance ${v.toFixed(1)} (sRGB^2), screenshot ${shot}`);
  check(v > 100, `the canvas is not blank (variance ${v.toFixed(1)} > 100)`);
  const hudRev = await page.textContent('#hud-revision');
  check(Number(hudRev) === rev, `the HUD shows the server's revision (${hudRev} == ${rev})`);
  check(await page.evaluate(() => window.lucentViewer.revision()) === rev, `the lightmap drawn is of revision ${rev}`);
  check(await page.evaluate(() => window.lucentViewer.role()) === 'controller', 'the page is a controller (no tokens)');
  check((await page.textContent('#hud-conn')) === 'open', 'the HUD says the connection is open');

  // The URL the page wrote (history.replaceState) reproduces the view in a fresh page.
  await page.waitForTimeout(400);
  const url = new URL(page.url());
  for (const k of ['camera', 'target', 'fov', 'mode', 'exposure', 'tonemap'])
    check(url.searchParams.has(k), `the URL carries ${k}=${url.searchParams.get(k)}`);
  const cam1 = await page.evaluate(() => window.lucentViewer.camera());
  const first = await openViewer(browser, d.port, `${url.search}&ui=0`, { width: 480, height: 360 });
  const second = await openViewer(browser, d.port, `${url.search}&ui=0`, { width: 480, height: 360 });
  await waitQuiet(second.page);
  await waitQuiet(first.page);
  const cam2 = await second.page.evaluate(() => window.lucentViewer.camera());
  const dc = Math.max(...cam1.camera.map((x, i) => Math.abs(x - cam2.camera[i])), ...cam1.target.map((x, i) => Math.abs(x - cam2.target[i])));
  check(dc < 1e-5 && cam1.fov === cam2.fov, `the URL's camera is the page's (max difference ${dc.toExponential(1)} m)`);
  const a = readPng(await screenshot(first.page, 'page_load_url_a'));
  const b = readPng(await screenshot(second.page, 'page_load_url_b'));
  const mad = meanAbsDiff(a, b, 0);
  check(mad < 0.05, `two pages opened from the URL draw the same image (mean abs difference ${mad.toFixed(3)})`);

  for (const p of [page, first.page, second.page]) await p.close();
  const all = [...errors, ...first.errors, ...second.errors];
  check(all.length === 0, `no console errors (${all.length ? all.join(' | ') : 'none'})`);
  c.close();
});
