// The overlay: an image laid on the lightmap's UVs and drawn in place of the light, e.g. the
// heat map of a fidelity run (lucent-ref writes error_lightmap_uv.png: the lightmap's W x H,
// blue = engine too dark, white = right, red = too bright, alpha 0 on empty texels).
//
// Layout: exactly the streamed lightmap's (PROTOCOL.md §2.4): texel (x, y) covers UV
// [(x, y), (x+1, y+1)] / (W, H) of TEXCOORD_1, row 0 = the top of the image = v 0. Like the
// lightmap (lightmap.js) it is uploaded as a DataTexture with rows in file order and
// flipY = false, sampled on texture.channel = 1. An image of another size is refused (it
// would not land on the texels it describes), except an integer zoom of the lightmap (k·W x k·H,
// what lucent-ref's --zoom writes), whose k x k blocks cover the same texels.
//
// Drawing (heat map mode): the image's own colour, unlit, no albedo, no tone map, no exposure
// (MeshBasicMaterial, toneMapped false: an 8-bit sRGB PNG shows its own pixel values). Empty
// texels (alpha 0) are drawn dark grey. A one-channel EXR (lucent-ref's signed relative error,
// error_lightmap.exr) is coloured by the legend's scale: -max blue, 0 white, +max red.
import * as THREE from 'three';
import { EXRLoader } from 'three/addons/loaders/EXRLoader.js';

export const OVERLAY_MAX_BYTES = 256 * 1024 * 1024;
export const OVERLAY_MAX_SIDE = 16384;
const EMPTY_LINEAR = 0.05; // alpha-0 texels: sRGB ~63, darker than any colour of the scale

const isPng = (b) => b.length >= 8 && b[0] === 0x89 && b[1] === 0x50 && b[2] === 0x4e && b[3] === 0x47;
const isExr = (b) => b.length >= 4 && b[0] === 0x76 && b[1] === 0x2f && b[2] === 0x31 && b[3] === 0x01;

/** The bytes of an overlay named by a URL (relative to the page, or absolute http/https). */
export async function fetchOverlay(url) {
  let u;
  try {
    u = new URL(url, location.href);
  } catch {
    throw new Error(`overlay URL '${url.slice(0, 120)}' is not a URL`);
  }
  if (u.protocol !== 'http:' && u.protocol !== 'https:') throw new Error(`overlay URL '${url.slice(0, 120)}': only http(s) URLs are loaded`);
  let r;
  try {
    r = await fetch(u.href);
  } catch (e) {
    const other = u.origin !== location.origin;
    throw new Error(`overlay ${u.href.slice(0, 120)} did not load${other
      ? ` (another origin: lucentd's Content-Security-Policy lets the page fetch only from ${location.origin}; put the file under its --www)`
      : `: ${e.message}`}`);
  }
  if (!r.ok) {
    throw new Error(`overlay ${u.href.slice(0, 120)}: HTTP ${r.status}${r.status === 415
      ? ' (the server does not serve this file type; drop the file on the page instead)' : ''}`);
  }
  const len = Number(r.headers.get('content-length') || 0);
  if (len > OVERLAY_MAX_BYTES) throw new Error(`overlay ${u.href.slice(0, 120)}: ${len} bytes, more than ${OVERLAY_MAX_BYTES}`);
  const name = decodeURIComponent(u.pathname.split('/').pop() || u.href);
  return { name, bytes: new Uint8Array(await r.arrayBuffer()) };
}

/** The bytes of a file dropped on the page or chosen in the panel. */
export async function readOverlayFile(file) {
  if (file.size > OVERLAY_MAX_BYTES) throw new Error(`overlay ${file.name}: ${file.size} bytes, more than ${OVERLAY_MAX_BYTES}`);
  return { name: file.name, bytes: new Uint8Array(await file.arrayBuffer()) };
}

/** Decodes PNG (or any image the browser decodes) or EXR bytes into {name, kind, width,
 *  height, scalar, data}: RGBA rows, row 0 = the top of the image; 8-bit sRGB (Uint8Array,
 *  alpha-0 texels with RGB 0) or half floats (Uint16Array, linear). */
export async function decodeOverlay({ name, bytes }) {
  if (isExr(bytes)) return decodeExr(name, bytes);
  let bmp;
  try {
    bmp = await createImageBitmap(new Blob([bytes], { type: isPng(bytes) ? 'image/png' : '' }),
      { premultiplyAlpha: 'none', colorSpaceConversion: 'none' });
  } catch {
    throw new Error(`overlay ${name}: not a PNG or EXR image the browser can decode`);
  }
  const { width, height } = bmp;
  checkSide(name, width, height);
  const cv = new OffscreenCanvas(width, height);
  const g = cv.getContext('2d', { willReadFrequently: true });
  g.drawImage(bmp, 0, 0);
  bmp.close();
  const data = new Uint8Array(g.getImageData(0, 0, width, height).data.buffer);
  for (let i = 3; i < data.length; i += 4) if (data[i] === 0) data[i - 3] = data[i - 2] = data[i - 1] = 0;
  return { name, kind: 'png', width, height, scalar: false, data };
}

function decodeExr(name, bytes) {
  let r;
  try {
    r = new EXRLoader().setDataType(THREE.HalfFloatType).parse(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength));
  } catch (e) {
    throw new Error(`overlay ${name}: EXR not readable (${e.message})`);
  }
  const { width, height } = r;
  checkSide(name, width, height);
  // EXRLoader writes the bottom row first (OpenGL's convention); the lightmap's row 0 is the top.
  const data = new Uint16Array(r.data.length);
  const row = width * 4;
  for (let y = 0; y < height; y++) data.set(r.data.subarray((height - 1 - y) * row, (height - y) * row), y * row);
  for (let i = 3; i < data.length; i += 4) if ((data[i] & 0x7fff) === 0) data[i - 3] = data[i - 2] = data[i - 1] = 0;
  const names = (r.header.channels || []).map((c) => c.name);
  const scalar = !(names.includes('R') && names.includes('G') && names.includes('B')) && !names.includes('RY');
  return { name, kind: 'exr', width, height, scalar, data };
}

function checkSide(name, w, h) {
  if (!(w >= 1 && h >= 1 && w <= OVERLAY_MAX_SIDE && h <= OVERLAY_MAX_SIDE))
    throw new Error(`overlay ${name}: ${w}x${h} is outside 1..${OVERLAY_MAX_SIDE} per side`);
}

/** null when the overlay maps onto a W x H lightmap, else the message that says why not. */
export function overlaySizeError(ov, lmWidth, lmHeight) {
  const k = ov.width / lmWidth;
  if (Number.isInteger(k) && k >= 1 && ov.height === k * lmHeight) return null;
  return `overlay ${ov.name} is ${ov.width}x${ov.height} but the lightmap is ${lmWidth}x${lmHeight}: ` +
    'refused, it would not map onto the lightmap\'s texels (write it at the lightmap\'s size)';
}

// The diverging scale in sRGB (as the legend's CSS gradient), converted to linear for output.
const OVERLAY_GLSL = /* glsl */ `
uniform float lucentScalar;
uniform float lucentMax;
vec3 lucentSrgbToLinear( const in vec3 s ) {
  return mix( pow( s * 0.9478672986 + vec3( 0.0521327014 ), vec3( 2.4 ) ), s * 0.0773993808,
    vec3( lessThanEqual( s, vec3( 0.04045 ) ) ) );
}
vec3 lucentDiverging( float t ) {
  t = clamp( t, -1.0, 1.0 );
  vec3 s = t < 0.0 ? mix( vec3( 1.0 ), vec3( 0.0, 0.0, 1.0 ), -t ) : mix( vec3( 1.0 ), vec3( 1.0, 0.0, 0.0 ), t );
  return lucentSrgbToLinear( s );
}
`;

/** The unlit material of heat map mode, shared by every static surface with TEXCOORD_1. */
export function overlayMaterial() {
  const m = new THREE.MeshBasicMaterial({ color: 0xffffff, toneMapped: false });
  const scalar = { value: 0 }, max = { value: 1 };
  m.userData.scalar = scalar;
  m.userData.max = max;
  m.onBeforeCompile = (shader) => {
    shader.uniforms.lucentScalar = scalar;
    shader.uniforms.lucentMax = max;
    shader.fragmentShader = shader.fragmentShader
      .replace('#include <common>', `#include <common>\n${OVERLAY_GLSL}`)
      .replace('#include <map_fragment>', `#include <map_fragment>
  {
    // Alpha-0 texels hold RGB 0, so filtered RGB / alpha is the covered texels' colour.
    float lucentA = clamp( diffuseColor.a, 0.0, 1.0 );
    vec3 lucentC = lucentA > 0.0 ? diffuseColor.rgb / lucentA : vec3( 0.0 );
    if ( lucentScalar > 0.5 ) lucentC = lucentDiverging( lucentC.r / lucentMax );
    diffuseColor = vec4( mix( vec3( ${EMPTY_LINEAR.toFixed(3)} ), lucentC, lucentA ), 1.0 );
  }`);
  };
  m.customProgramCacheKey = () => 'lucent-overlay';
  return m;
}

/** A texture of a decoded overlay on TEXCOORD_1, as the lightmap: rows in order, flipY false. */
export function overlayTexture(ov, nearest) {
  const exr = ov.kind === 'exr';
  const t = new THREE.DataTexture(ov.data, ov.width, ov.height, THREE.RGBAFormat,
    exr ? THREE.HalfFloatType : THREE.UnsignedByteType);
  t.flipY = false;
  t.generateMipmaps = false;
  t.channel = 1;
  t.colorSpace = exr ? THREE.NoColorSpace : THREE.SRGBColorSpace;
  t.wrapS = t.wrapT = THREE.ClampToEdgeWrapping;
  setOverlayNearest(t, nearest);
  t.needsUpdate = true;
  return t;
}

export function setOverlayNearest(t, on) {
  const f = on ? THREE.NearestFilter : THREE.LinearFilter;
  if (t.magFilter !== f || t.minFilter !== f) {
    t.magFilter = t.minFilter = f;
    t.needsUpdate = true;
  }
}
