// Shareable views: the query string carries the camera, the mode, the exposure and the tone map
// (?camera=x,y,z&target=x,y,z&fov=DEG&mode=full&exposure=1&tonemap=none), plus token= for the
// role and ui=0 for a clean canvas (no HUD, panel or light gizmos: screenshots, comparisons),
// overlay=URL (heatmap=URL, the older name) for an image on the lightmap's UVs (overlay.js)
// and overlay_max=PERCENT for its legend's scale (-max..0..+max; default 100).
// mr=URL plays an RGB-D recording (lucent-rgbd/1 directory) as the page's MR session (mr.js;
// read there, not here: it is not part of the view and stays in the URL as it was).
// Reading the URL back reproduces the view exactly: the numbers are written with enough digits.

export const MODES = ['full', 'direct', 'indirect', 'texels', 'probes', 'heatmap'];
export const TONEMAPS = ['none', 'neutral', 'aces'];

function vec3(text) {
  if (!text) return null;
  const v = text.split(',').map(Number);
  return v.length === 3 && v.every(Number.isFinite) ? v : null;
}

/** A percentage ("50", "50%") as a fraction, or null. */
function percent(text) {
  if (text === null || text === '') return null;
  const v = num(text.replace(/%$/, ''), 1e-6, 1e6);
  return v === null || v <= 0 ? null : v / 100;
}

function num(text, lo, hi) {
  if (text === null || text === '') return null;
  const v = Number(text);
  return Number.isFinite(v) && v >= lo && v <= hi ? v : null;
}

/** The view the URL asks for; fields it lacks or gets wrong are null (the caller's defaults). */
export function readView(search) {
  const q = new URLSearchParams(search);
  const mode = q.get('mode');
  const tonemap = q.get('tonemap');
  return {
    camera: vec3(q.get('camera')),
    target: vec3(q.get('target')),
    fov: num(q.get('fov'), 1, 179),
    mode: MODES.includes(mode) ? mode : null,
    exposure: num(q.get('exposure'), 1e-6, 1e6),
    tonemap: TONEMAPS.includes(tonemap) ? tonemap : null,
    token: q.get('token'),
    overlay: q.get('overlay') || q.get('heatmap'),
    overlayMax: percent(q.get('overlay_max')),
    clean: q.get('ui') === '0',
  };
}

const fmt = (x) => String(Number(x.toPrecision(7)));

/** Writes the view into the current URL (history.replaceState: no history entry per move). */
export function writeView(view) {
  const q = new URLSearchParams(location.search);
  q.set('camera', view.camera.map(fmt).join(','));
  q.set('target', view.target.map(fmt).join(','));
  q.set('fov', fmt(view.fov));
  q.set('mode', view.mode);
  q.set('exposure', fmt(view.exposure));
  q.set('tonemap', view.tonemap);
  const text = q.toString().replace(/%2C/g, ',');
  if (`?${text}` !== location.search) history.replaceState(null, '', `${location.pathname}?${text}`);
}
