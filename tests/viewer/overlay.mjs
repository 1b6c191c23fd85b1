// The overlay (heat map mode): an image on the lightmap's UVs drawn in place of the light.
// lucentd serves a --www folder holding this build's viewer and PNGs the test writes at the
// embedded Cornell bake's lightmap size (from welcome), and the page is checked for:
//  - ?overlay=halves.png (left half of the texels red, right half blue): the scene is drawn in
//    those two colours only (no lit-scene colour, none of the box's white or green light);
//  - the toggle (key o) goes back to the live light and returns to the same overlay image;
//  - the mapping is exactly the lightmap's: a PNG made of the streamed lightmap's own texels
//    (sRGB of k·E/π), dropped on the page (drag and drop), draws the image that "lightmap
//    texels" mode draws at exposure k, and the same PNG upside down does not;
//  - EXR (dropped: lucentd serves no .exr): the same texels as linear float RGB draw texels
//    mode's image too, and a one-channel EXR of signed values (+1 left, -1 right) is coloured
//    by the legend's scale, giving the halves' red and blue;
//  - an integer zoom (2W x 2H, as lucent-ref --zoom writes) draws the same image;
//  - texels with alpha 0 (and RGB yellow) are drawn dark grey;
//  - with the UI: the legend's scale follows ?overlay_max (a screenshot for people to look at);
//    a PNG of another size, dropped, is refused with a visible message naming both sizes, and
//    the overlay shown before stays.
import { copyFileSync, mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { pathToFileURL } from 'node:url';
import { SOURCE, WWW, check, connect, meanAbsDiff, openViewer, requirePrereqs, run, screenshot, waitQuiet } from './lib.mjs';
import { readPng, writePng } from './png.mjs';
import { writeExr } from './exr.mjs';

const { lightmapToFloat32 } = await import(pathToFileURL(join(SOURCE, 'client', 'js', 'lucent.js')).href);
const W = 480, H = 360;

requirePrereqs();
const www = mkdtempSync(join(tmpdir(), 'lucent-overlay-www-'));
for (const f of ['index.html', 'viewer.js', 'viewer.css']) copyFileSync(join(WWW, f), join(www, f));

const srgb8 = (x) => {
  const v = Math.min(Math.max(x, 0), 1);
  return Math.round(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * v ** (1 / 2.4) - 0.055));
};

function image(w, h, fn) {
  const data = new Uint8Array(w * h * 4);
  for (let y = 0; y < h; y++) for (let x = 0; x < w; x++) data.set(fn(x, y), 4 * (y * w + x));
  return { width: w, height: h, data };
}

/** Pixel classes of a screenshot: strongly red, strongly blue, lit (any green light), black. */
function classify(img) {
  let red = 0, blue = 0, lit = 0, dark = 0;
  const n = img.width * img.height;
  for (let i = 0; i < n; i++) {
    const r = img.data[4 * i], g = img.data[4 * i + 1], b = img.data[4 * i + 2];
    if (r > 200 && g < 40 && b < 40) red++;
    else if (b > 200 && r < 40 && g < 40) blue++;
    if (g > 60) lit++;
    if (r + g + b < 24) dark++;
  }
  return { red: red / n, blue: blue / n, lit: lit / n, dark: dark / n };
}

const pct = (x) => `${(100 * x).toFixed(2)}%`;

/** Drops a file on the page as a user's drag and drop does (a DataTransfer with one File). */
async function drop(page, path, name) {
  const b64 = readFileSync(path).toString('base64');
  await page.evaluate(({ b64, name }) => {
    const bytes = Uint8Array.from(atob(b64), (ch) => ch.charCodeAt(0));
    const dt = new DataTransfer();
    dt.items.add(new File([bytes], name, { type: 'image/png' }));
    document.body.dispatchEvent(new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
  }, { b64, name });
}

const overlayName = (page) => page.evaluate(() => window.lucentViewer.overlay().image?.name ?? null);

/** Returns after the page's next two animation frames: the viewer draws in the first one
 *  requested after a change (requestRender), so the canvas shows the change. */
async function settle(page) {
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
}

async function setSelect(page, id, value) {
  await page.evaluate(({ id, value }) => {
    const el = document.getElementById(id);
    el.value = String(value);
    el.dispatchEvent(new Event('change'));
  }, { id, value });
  await settle(page);
}

try {
  await run('viewer.overlay', async ({ d, browser }) => {
    // The lightmap as the server streams it, once refinement has stopped.
    const c = await connect(d.port);
    const { width: LW, height: LH } = c.welcome.scene.lightmap;
    check(LW > 1 && LH > 1, `welcome gives the lightmap's size ${LW}x${LH}`);
    let last = Date.now();
    c.on('lightmap', () => { last = Date.now(); });
    await c.subscribe('lightmap', { encoding: 'rgb9e5', delta: 'residual' });
    const t0 = Date.now();
    while ((Date.now() - last < 1500 || !c.lightmap) && Date.now() - t0 < 20000) await new Promise((r) => setTimeout(r, 100));
    const E = lightmapToFloat32(c.lightmap);
    console.log(`lightmap ${LW}x${LH} revision ${c.lightmap.revision} pass ${c.lightmap.pass}${c.lightmap.converged ? ' (converged)' : ''}`);

    writePng(join(www, 'halves.png'), image(LW, LH, (x) => (x < LW / 2 ? [255, 0, 0, 255] : [0, 0, 255, 255])));
    writePng(join(www, 'halves_zoom2.png'), image(2 * LW, 2 * LH, (x) => (x < LW ? [255, 0, 0, 255] : [0, 0, 255, 255])));
    writePng(join(www, 'empty.png'), image(LW, LH, () => [255, 255, 0, 0]), { alpha: true });
    writePng(join(www, 'wrong.png'), image(LW - 1, LH, () => [0, 255, 0, 255]));
    // The lightmap's own texels as an image: exposure k puts the 98th percentile of E/π at 0.8.
    const vals = Array.from(E).map((v) => v / Math.PI).filter((v) => v > 0).sort((a, b) => a - b);
    check(vals.length > LW * LH * 0.3, `the lightmap has light (${vals.length} of ${3 * LW * LH} channels > 0)`);
    const k = 0.8 / vals[Math.floor(0.98 * (vals.length - 1))];
    const lmPix = (x, y) => [0, 1, 2].map((ch) => srgb8((k * E[3 * (y * LW + x) + ch]) / Math.PI)).concat(255);
    writePng(join(www, 'lightmap.png'), image(LW, LH, lmPix));
    writePng(join(www, 'lightmap_flipped.png'), image(LW, LH, (x, y) => lmPix(x, LH - 1 - y)));
    const rgb = [0, 1, 2].map((ch) => Float32Array.from({ length: LW * LH }, (_, i) => (k * E[3 * i + ch]) / Math.PI));
    writeExr(join(www, 'lightmap.exr'), { width: LW, height: LH, channels: { R: rgb[0], G: rgb[1], B: rgb[2] } });
    writeExr(join(www, 'halves.exr'), { width: LW, height: LH,
      channels: { Y: Float32Array.from({ length: LW * LH }, (_, i) => (i % LW < LW / 2 ? 1 : -1)) } });
    // A heat map as lucent-ref draws one (signed error -> blue/white/red, alpha 0 where no
    // texel): here each texel's luminance against the median, for the screenshot people look at.
    const lum = (i) => 0.2126 * E[3 * i] + 0.7152 * E[3 * i + 1] + 0.0722 * E[3 * i + 2];
    const lums = Array.from({ length: LW * LH }, (_, i) => lum(i)).filter((v) => v > 0).sort((a, b) => a - b);
    const med = lums[Math.floor(lums.length / 2)];
    writePng(join(www, 'heat.png'), image(LW, LH, (x, y) => {
      const l = lum(y * LW + x);
      if (!(l > 0)) return [0, 0, 0, 0];
      const t = Math.max(-1, Math.min(1, (l - med) / med / 0.5)), w = Math.round(255 * (1 - Math.abs(t)));
      return t < 0 ? [w, w, 255, 255] : [255, w, w, 255];
    }), { alpha: true });

    // --- ?overlay=URL: the two halves, and nothing of the lit scene.
    const { page, errors } = await openViewer(browser, d.port, '?overlay=halves.png&ui=0', { width: W, height: H });
    await waitQuiet(page);
    const ov = await page.evaluate(() => window.lucentViewer.overlay());
    check(ov.shown && ov.image && ov.image.width === LW && ov.image.height === LH && ov.nearest,
      `?overlay= loads halves.png (${LW}x${LH}) and shows it with crisp texels: ${JSON.stringify(ov)}`);
    const a = readPng(await screenshot(page, 'overlay_halves'));
    const ca = classify(a);
    console.log(`halves: red ${pct(ca.red)}, blue ${pct(ca.blue)}, lit ${pct(ca.lit)}, black ${pct(ca.dark)}`);
    check(ca.red > 0.03 && ca.blue > 0.03, `the scene shows both halves: red ${pct(ca.red)} and blue ${pct(ca.blue)} of the pixels (> 3% each)`);
    check(ca.lit < 0.001, `no lit-scene colour in overlay mode (pixels with green > 60: ${pct(ca.lit)} < 0.1%)`);
    check(ca.red + ca.blue + ca.dark > 0.97, `every pixel is red, blue or background (${pct(ca.red + ca.blue + ca.dark)})`);

    // --- the toggle: live light and back.
    await page.keyboard.press('o');
    await settle(page);
    check(!(await page.evaluate(() => window.lucentViewer.overlay().shown)), 'key o switches to the live light');
    const live = classify(readPng(await screenshot(page, 'overlay_toggled_live')));
    check(live.lit > 0.2, `the live light is drawn again (pixels with green > 60: ${pct(live.lit)} > 20%)`);
    await page.keyboard.press('o');
    await settle(page);
    const back = readPng(await screenshot(page, 'overlay_toggled_back'));
    const dBack = meanAbsDiff(a, back, 0);
    check(dBack < 0.5, `key o again shows the same overlay (mean abs difference ${dBack.toFixed(3)})`);

    // --- the mapping: the lightmap's texels as an overlay = "lightmap texels" mode.
    await drop(page, join(www, 'lightmap.png'), 'lightmap.png');
    await page.waitForFunction(() => window.lucentViewer.overlay().image?.name === 'lightmap.png', null, { timeout: 5000 });
    await settle(page);
    const s1 = readPng(await screenshot(page, 'overlay_lightmap_png'));
    await setSelect(page, 'tonemap', 'none');
    await page.evaluate((kk) => {
      const el = document.getElementById('exposure');
      el.value = String(kk);
      el.dispatchEvent(new Event('change'));
    }, k);
    await setSelect(page, 'mode', 'texels');
    const s2 = readPng(await screenshot(page, 'overlay_lightmap_texels_mode'));
    const dSame = meanAbsDiff(s1, s2, 0);
    await drop(page, join(www, 'lightmap_flipped.png'), 'lightmap_flipped.png');
    await page.waitForFunction(() => window.lucentViewer.overlay().image?.name === 'lightmap_flipped.png', null, { timeout: 5000 });
    await settle(page);
    const s3 = readPng(await screenshot(page, 'overlay_lightmap_flipped'));
    const dFlip = meanAbsDiff(s3, s2, 0);
    console.log(`lightmap as overlay vs texels mode (exposure ${k.toPrecision(4)}): ${dSame.toFixed(3)}; upside down: ${dFlip.toFixed(3)}`);
    check(dSame < 1.0, `the overlay lands on the lightmap's texels: same image as texels mode (mean abs difference ${dSame.toFixed(3)} < 1 of 255)`);
    check(dFlip > 8 * Math.max(dSame, 0.25), `the test sees a wrong mapping: upside down differs by ${dFlip.toFixed(3)}`);

    // --- EXR: colour (linear) and one channel (coloured by the scale, max 100%).
    await drop(page, join(www, 'lightmap.exr'), 'lightmap.exr');
    await page.waitForFunction(() => window.lucentViewer.overlay().image?.name === 'lightmap.exr', null, { timeout: 5000 });
    await settle(page);
    const dExr = meanAbsDiff(readPng(await screenshot(page, 'overlay_lightmap_exr')), s2, 0);
    check(dExr < 1.0, `the lightmap as a float RGB EXR draws texels mode's image (mean abs difference ${dExr.toFixed(3)} < 1)`);
    await drop(page, join(www, 'halves.exr'), 'halves.exr');
    await page.waitForFunction(() => window.lucentViewer.overlay().image?.scalar === true, null, { timeout: 5000 });
    await settle(page);
    const dHalves = meanAbsDiff(readPng(await screenshot(page, 'overlay_halves_exr')), a, 0);
    check(dHalves < 1.0, `a one-channel EXR of +1 / -1 is coloured red / blue by the scale: the halves' image (mean abs difference ${dHalves.toFixed(3)} < 1)`);

    // --- an integer zoom of the lightmap (lucent-ref --zoom) covers the same texels.
    await drop(page, join(www, 'halves_zoom2.png'), 'halves_zoom2.png');
    await page.waitForFunction(() => window.lucentViewer.overlay().image?.name === 'halves_zoom2.png', null, { timeout: 5000 });
    await settle(page);
    const dZoom = meanAbsDiff(readPng(await screenshot(page, 'overlay_halves_zoom2')), a, 0);
    check(dZoom < 1.0, `a ${2 * LW}x${2 * LH} zoom of the halves is taken and draws the halves' image (mean abs difference ${dZoom.toFixed(3)} < 1)`);

    // --- empty texels (alpha 0, whatever their RGB) are drawn dark grey.
    await drop(page, join(www, 'empty.png'), 'empty.png');
    await page.waitForFunction(() => window.lucentViewer.overlay().image?.name === 'empty.png', null, { timeout: 5000 });
    await settle(page);
    const e = readPng(await screenshot(page, 'overlay_empty'));
    let grey = 0;
    for (let i = 0; i < e.width * e.height; i++) {
      const [r, g, b] = [e.data[4 * i], e.data[4 * i + 1], e.data[4 * i + 2]];
      if (Math.abs(r - 63) <= 3 && Math.abs(g - 63) <= 3 && Math.abs(b - 63) <= 3) grey++;
    }
    const fGrey = grey / (e.width * e.height);
    check(Math.abs(fGrey - (ca.red + ca.blue)) < 0.02,
      `alpha-0 texels are dark grey, not their RGB: ${pct(fGrey)} grey pixels where the halves had ${pct(ca.red + ca.blue)} red or blue`);

    await page.close();

    // --- with the UI: legend, panel (the screenshot for people).
    const ui = await openViewer(browser, d.port, '?overlay=heat.png&overlay_max=50', { width: 960, height: 640 });
    await waitQuiet(ui.page);
    check(await ui.page.isVisible('#legend'), 'the legend is shown with the overlay');
    const lo = await ui.page.textContent('#legend-min'), hi = await ui.page.textContent('#legend-max');
    check(lo === '−50%' && hi === '+50%', `the legend's scale follows overlay_max=50: ${lo} .. ${hi}`);
    check((await ui.page.textContent('#legend-title')).includes(`heat.png (${LW}x${LH})`), 'the legend names the image and its size');
    check(await ui.page.isChecked('#overlay-show') && await ui.page.isChecked('#overlay-crisp'), 'the panel shows the overlay toggle on and crisp texels on');
    const shot = await screenshot(ui.page, 'overlay_ui');
    console.log(`UI screenshot: ${shot}`);
    // --- a wrong size is refused, visibly, naming both sizes; the overlay shown stays.
    await drop(ui.page, join(www, 'wrong.png'), 'wrong.png');
    await ui.page.waitForSelector('#toast:not(.hidden)', { timeout: 5000 });
    const msg = await ui.page.textContent('#toast');
    console.log(`refusal: ${msg} (screenshot ${await screenshot(ui.page, 'overlay_refused')})`);
    check(msg.includes(`${LW - 1}x${LH}`) && msg.includes(`${LW}x${LH}`) && msg.includes('wrong.png'),
      'a PNG of another size is refused with a message naming both sizes');
    check(await overlayName(ui.page) === 'heat.png', 'the overlay shown before stays');
    check((await ui.page.evaluate(() => window.lucentViewer.lastError())) === msg, 'the refusal is the page\'s last error');
    await ui.page.uncheck('#overlay-show');
    check(!(await ui.page.isVisible('#legend')), 'the panel toggle switches back to the live light (legend hidden)');
    await ui.page.close();

    const all = [...errors, ...ui.errors];
    check(all.length === 0, `no console errors (${all.length ? all.join(' | ') : 'none'})`);
    c.close();
  }, { lucentdArgs: ['--www', www] });
} finally {
  rmSync(www, { recursive: true, force: true });
}
