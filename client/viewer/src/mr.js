// The MR panel (PROTOCOL.md §8): plays an RGB-D recording (lucent-rgbd/1: capture.json,
// frame_NNNNN.json, depth_NNNNN.png 16-bit mm, color_NNNNN.png, optional confidence_NNNNN.png)
// to lucentd as this page's MR session, and shows in the 3D view what it sends and gets back:
// the uploaded point cloud (every valid depth pixel unprojected by §8.4's camera model,
// coloured by its pixel), the camera frustum, and the VPLs of mr.vpl (§8.7: per sparse point a
// marker at l_d coloured by I_d, optionally a line from the sparse point to l_d). The objects
// themselves are lit by the objects stream's SH, which a session with light 'replace' makes
// the capture's light. Sources: ?mr=URL of the recording's directory, or a folder picked in
// the panel. Needs a controller token and a server that grants "mr".
import * as THREE from 'three';
import { encodeUploadFrame, inflateExact } from '../../js/lucent.js';

const $ = (id) => document.getElementById(id);
const MAX_SIDE = 1024;
const VPL_VALUES = 12;

// ------------------------------------------------------------------------------ PNG (16-bit)

const PNG_SIG = [137, 80, 78, 71, 13, 10, 26, 10];
const CHANNELS = { 0: 1, 2: 3, 4: 2, 6: 4 };

function paeth(a, b, c) {
  const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
  return pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
}

/**
 * Decodes a non-interlaced grey / grey+alpha / RGB / RGBA PNG of 8 or 16 bits, keeping 16 bits
 * (canvas decoding would round to 8). Returns {width, height, channels, bits, data}: data is a
 * Uint8Array (8 bits) or Uint16Array (16 bits) of width·height·channels samples, row 0 on top.
 * @param {Uint8Array} bytes
 */
export async function decodePng(bytes, name = 'png') {
  if (bytes.length < 33 || PNG_SIG.some((v, i) => bytes[i] !== v)) throw new Error(`${name}: not a PNG`);
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  let at = 8, width = 0, height = 0, bits = 0, ctype = -1;
  const idat = [];
  while (at + 12 <= bytes.length) {
    const len = dv.getUint32(at), type = String.fromCharCode(...bytes.subarray(at + 4, at + 8));
    if (at + 12 + len > bytes.length) throw new Error(`${name}: chunk ${type} runs past the file`);
    const body = bytes.subarray(at + 8, at + 8 + len);
    if (type === 'IHDR') {
      const h = new DataView(body.buffer, body.byteOffset, body.byteLength);
      width = h.getUint32(0);
      height = h.getUint32(4);
      bits = body[8];
      ctype = body[9];
      if (body[12] !== 0) throw new Error(`${name}: interlaced PNGs are not supported`);
    } else if (type === 'IDAT') idat.push(body);
    else if (type === 'IEND') break;
    at += 12 + len;
  }
  const ch = CHANNELS[ctype];
  if (!ch || (bits !== 8 && bits !== 16)) throw new Error(`${name}: colour type ${ctype} / ${bits} bits is not supported`);
  if (!(width >= 1 && width <= MAX_SIDE && height >= 1 && height <= MAX_SIDE)) throw new Error(`${name}: ${width}x${height} is over ${MAX_SIDE}`);
  const z = new Uint8Array(idat.reduce((s, c) => s + c.length, 0));
  let o = 0;
  for (const c of idat) z.set(c, o), (o += c.length);
  const bpp = ch * bits / 8, stride = width * bpp;
  const raw = await inflateExact(z, height * (stride + 1));
  const px = new Uint8Array(height * stride);
  for (let y = 0; y < height; y++) {
    const f = raw[y * (stride + 1)], src = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    const row = y * stride, prev = y ? row - stride : -1;
    for (let x = 0; x < stride; x++) {
      const a = x >= bpp ? px[row + x - bpp] : 0, b = prev >= 0 ? px[prev + x] : 0, c = x >= bpp && prev >= 0 ? px[prev + x - bpp] : 0;
      const v = src[x];
      px[row + x] = f === 0 ? v : f === 1 ? v + a : f === 2 ? v + b : f === 3 ? v + ((a + b) >> 1) : f === 4 ? v + paeth(a, b, c) : -1;
      if (f > 4) throw new Error(`${name}: bad filter ${f} in row ${y}`);
    }
  }
  if (bits === 8) return { width, height, channels: ch, bits, data: px };
  const data = new Uint16Array(width * height * ch);
  for (let i = 0; i < data.length; i++) data[i] = (px[2 * i] << 8) | px[2 * i + 1];
  return { width, height, channels: ch, bits, data };
}

// ------------------------------------------------------------------------------ recordings

function floatToHalf(v) {
  const f = new Float32Array([v]), u = new Uint32Array(f.buffer)[0];
  const s = (u >>> 16) & 0x8000, e = ((u >>> 23) & 0xff) - 127 + 15, m = u & 0x7fffff;
  if (e <= 0) return s | (e < -10 ? 0 : ((m | 0x800000) >> (1 - e + 13)));
  if (e >= 31) return s | 0x7c00;
  return s | (e << 10) | (m >> 13);
}

const srgbEotf = (c) => (c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4));

/** A recording source: get(name) → Uint8Array (fetch under a base URL, or a picked folder). */
export function urlSource(base) {
  const root = base.endsWith('/') ? base : `${base}/`;
  return {
    name: base,
    async get(name) {
      const r = await fetch(new URL(name, new URL(root, location.href)));
      if (!r.ok) throw new Error(`${root}${name}: HTTP ${r.status}`);
      return new Uint8Array(await r.arrayBuffer());
    },
    async has(name) {
      const r = await fetch(new URL(name, new URL(root, location.href)), { method: 'HEAD' });
      return r.ok;
    },
  };
}

export function filesSource(files) {
  const byName = new Map();
  for (const f of files) byName.set(f.name, f);
  const dir = files.length && files[0].webkitRelativePath ? files[0].webkitRelativePath.split('/')[0] : 'folder';
  return {
    name: dir,
    async get(name) {
      const f = byName.get(name);
      if (!f) throw new Error(`${dir}: no ${name}`);
      return new Uint8Array(await f.arrayBuffer());
    },
    async has(name) {
      return byName.has(name);
    },
  };
}

const pad5 = (k) => String(k).padStart(5, '0');
const json = async (src, name) => JSON.parse(new TextDecoder().decode(await src.get(name)));

async function loadFrame(src, cap, k) {
  const fj = await json(src, `frame_${pad5(k)}.json`);
  const W = cap.width, H = cap.height, n = W * H;
  const depth = await decodePng(await src.get(`depth_${pad5(k)}.png`), `depth_${pad5(k)}.png`);
  if (depth.width !== W || depth.height !== H || depth.channels !== 1 || depth.bits !== 16)
    throw new Error(`depth_${pad5(k)}.png: want ${W}x${H} 16-bit grey`);
  const color = await decodePng(await src.get(`color_${pad5(k)}.png`), `color_${pad5(k)}.png`);
  const srgb = fj.color !== 'linear16';
  if (color.width !== W || color.height !== H || color.channels < 3 || color.bits !== (srgb ? 8 : 16))
    throw new Error(`color_${pad5(k)}.png: want ${W}x${H} RGB of ${srgb ? 8 : 16} bits`);
  const rgb = srgb ? new Uint8Array(3 * n) : new Uint16Array(3 * n), lin = new Float32Array(3 * n);
  for (let i = 0; i < n; i++) {
    for (let c = 0; c < 3; c++) {
      const v = color.data[i * color.channels + c], l = srgb ? srgbEotf(v / 255) : v / 65535;
      lin[3 * i + c] = l;
      rgb[3 * i + c] = srgb ? v : floatToHalf(l);
    }
  }
  let confidence = null;
  if (await src.has(`confidence_${pad5(k)}.png`).catch(() => false)) {
    const c = await decodePng(await src.get(`confidence_${pad5(k)}.png`), `confidence_${pad5(k)}.png`);
    if (c.width === W && c.height === H && c.channels === 1 && c.bits === 8) confidence = c.data;
  }
  const I = fj.intrinsics, P = fj.pose;
  return { k, sequence: fj.sequence, timeUs: fj.time_us, exposure: fj.exposure, srgb, depth: depth.data, rgb, lin, confidence,
    fx: I.fx, fy: I.fy, cx: I.cx, cy: I.cy, translation: P.translation, rotation: P.rotation };
}

/** Loads a whole recording: {name, width, height, frames: [...]} (frames in order). */
export async function loadRecording(src) {
  const cap = await json(src, 'capture.json');
  if (cap.format !== 'lucent-rgbd/1') throw new Error(`${src.name}: capture.json format ${cap.format}, not lucent-rgbd/1`);
  if (!(cap.width >= 8 && cap.width <= MAX_SIDE && cap.height >= 8 && cap.height <= MAX_SIDE && cap.frames >= 1 && cap.frames <= 100000))
    throw new Error(`${src.name}: capture.json width/height/frames out of range`);
  const frames = [];
  for (let k = 1; k <= cap.frames; k++) frames.push(await loadFrame(src, cap, k));
  return { name: src.name, width: cap.width, height: cap.height, frames };
}

/**
 * The frame's valid pixels in world space (§8.4 camera model), coloured by their pixel (the
 * decoded linear colour, before exposure, as three.js vertex colours): {positions, colors, count}.
 */
export function unproject(f, W, H) {
  const n = W * H, pos = new Float32Array(3 * n), col = new Float32Array(3 * n);
  const q = new THREE.Quaternion(...f.rotation).normalize(), t = new THREE.Vector3(...f.translation), p = new THREE.Vector3();
  let m = 0;
  for (let y = 0; y < H; y++) {
    for (let x = 0; x < W; x++) {
      const i = y * W + x, d = f.depth[i];
      if (!d) continue;
      const z = d / 1000;
      p.set((x + 0.5 - f.cx) * z / f.fx, -(y + 0.5 - f.cy) * z / f.fy, -z).applyQuaternion(q).add(t);
      pos.set([p.x, p.y, p.z], 3 * m);
      for (let c = 0; c < 3; c++) col[3 * m + c] = f.lin[3 * i + c];
      m++;
    }
  }
  return { positions: pos.subarray(0, 3 * m), colors: col.subarray(0, 3 * m), count: m };
}

// ------------------------------------------------------------------------------ the panel

export class MrPanel {
  /**
   * @param {{client, scene: THREE.Scene, objects, render: Function, errors: string[], size: number}} ctx
   */
  constructor(ctx) {
    Object.assign(this, ctx);
    this.group = new THREE.Group();
    this.group.name = 'mr';
    this.scene.add(this.group);
    this.recording = null;
    this.playing = false;
    this.runId = 0;
    this.seq = 0;
    this.stats = { sent: 0, acks: 0, processed: 0, replaced: 0, lights: 0, ms: 0, errors: 0, points: 0, vplFrames: 0, vplPoints: 0 };
    this.showCloud = true;
    this.showVpl = true;
    this.showLines = false;
    this.cloud = new THREE.Points(new THREE.BufferGeometry(), new THREE.PointsMaterial({ size: 2, sizeAttenuation: false, vertexColors: true }));
    this.cloud.name = 'mr-cloud';
    this.frustum = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0xffd040 }));
    this.vpl = new THREE.Points(new THREE.BufferGeometry(), new THREE.PointsMaterial({ size: 7, sizeAttenuation: false, vertexColors: true }));
    this.lines = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ vertexColors: true, transparent: true, opacity: 0.6 }));
    this.group.add(this.cloud, this.frustum, this.vpl, this.lines);
    this.lines.visible = false;
    this.client.on('mr.ack', (a) => this.onAck(a));
    this.client.on('mr.vpl', (v) => this.onVpl(v));
    // Sessions end with the connection (§8.2): after a reconnect, begin again and go on playing.
    this.client.on('welcome', () => {
      if (!this.playing) return;
      this.playing = false;
      this.runId++;
      this.play();
    });
    this.bind();
  }

  bind() {
    $('mr-folder').addEventListener('change', (e) => {
      if (e.target.files.length) this.open(filesSource([...e.target.files]));
    });
    $('mr-play').addEventListener('click', () => (this.playing ? this.stop() : this.play()));
    $('mr-cloud').addEventListener('change', (e) => { this.cloud.visible = this.frustum.visible = e.target.checked; this.render(); });
    $('mr-vpl').addEventListener('change', (e) => { this.vpl.visible = e.target.checked; this.render(); });
    $('mr-lines').addEventListener('change', (e) => { this.lines.visible = e.target.checked; this.render(); });
    $('mr-shade').addEventListener('change', (e) => this.setVertexShading(e.target.checked));
  }

  status(text) {
    $('mr-status').textContent = text;
  }

  fail(text) {
    this.errors.push(text);
    this.status(text);
  }

  /** Loads a recording from a source and starts playing it. Resolves true when it plays. */
  async open(src) {
    this.stop();
    this.status(`loading ${src.name} …`);
    try {
      this.recording = await loadRecording(src);
    } catch (e) {
      this.fail(`mr: ${e.message}`);
      return false;
    }
    const r = this.recording;
    this.status(`${r.name}: ${r.width}x${r.height}, ${r.frames.length} frames`);
    this.showFrame(r.frames[0]);
    return this.play();
  }

  /** mr.begin with the picked objects (default every object in the state), then plays in a loop. */
  async play() {
    const r = this.recording, c = this.client;
    if (!r) return false;
    if (!c.capabilities.includes('mr')) {
      this.fail(`mr: the server does not grant "mr" (protocol ${c.protocolVersion}, role ${c.role}): a controller token and lucentd --mr are needed`);
      return false;
    }
    const picked = $('mr-objects').value.split(',').map((s) => s.trim()).filter(Boolean);
    const objects = (picked.length ? picked : [...this.objects.items.keys()]).slice(0, 16);
    if (!objects.length) {
      this.fail('mr: no objects to light (place one, or name them in the panel)');
      return false;
    }
    try {
      this.grant = await c.mrBegin({ objects, width: r.width, height: r.height, depth: 'u16mm',
        color: r.frames[0].srgb ? 'rgb8_srgb' : 'rgb16f_linear' });
      await c.subscribe('mr.vpl', { encoding: 'f32' });
    } catch (e) {
      this.fail(`mr.begin: ${e.code || 'error'} — ${e.message}`);
      return false;
    }
    this.sessionObjects = objects;
    this.playing = true;
    $('mr-play').textContent = 'stop';
    this.loop(++this.runId);
    return true;
  }

  stop() {
    if (!this.playing) return;
    this.playing = false;
    this.runId++;
    $('mr-play').textContent = 'play';
    this.client.mrEnd().catch(() => {});
  }

  // Plays the frames at their timestamps, looping; frames closer than the granted rate allows
  // are skipped (the server would answer rate_limited).
  async loop(run) {
    const r = this.recording, frames = r.frames, minGapMs = 1000 / (this.grant.max_rate || 10);
    const t0 = frames[0].timeUs, span = Math.max(1, (frames[frames.length - 1].timeUs - t0) / 1000 + minGapMs);
    let start = performance.now(), lastSent = -Infinity, lap = 0;
    for (let i = 0; this.playing && run === this.runId; i++) {
      if (i === frames.length) { i = 0; lap++; }
      const f = frames[i], at = start + lap * span + (f.timeUs - t0) / 1000;
      const wait = Math.max(at, lastSent + minGapMs) - performance.now();
      if (wait > 0) await new Promise((res) => setTimeout(res, wait));
      if (!this.playing || run !== this.runId) break;
      lastSent = performance.now();
      this.showFrame(f);
      this.send(f);
    }
  }

  async send(f) {
    const r = this.recording;
    try {
      const bytes = await encodeUploadFrame({ sequence: ++this.seq, captureUs: Math.round(performance.now() * 1000), width: r.width,
        height: r.height, depthEncoding: 'u16mm', depth: f.depth, colorEncoding: f.srgb ? 'rgb8_srgb' : 'rgb16f_linear',
        color: f.rgb, confidence: f.confidence, fx: f.fx, fy: f.fy, cx: f.cx, cy: f.cy, translation: f.translation,
        rotation: f.rotation, exposure: f.exposure, compress: true });
      this.stats.sent++;
      this.stats.bytes = bytes.length;
      await this.client.sendUploadFrame(bytes);
    } catch (e) {
      this.stats.errors++;
      this.errors.push(`mr upload: ${e.code || 'error'} — ${e.message}`);
    }
    this.hud();
  }

  onAck(a) {
    const s = this.stats;
    s.acks++;
    if (a.status === 'processed') s.processed++;
    else s.replaced++;
    s.lights = a.lights;
    s.ms = a.ms;
    s.lastSeq = a.seq;
    this.hud();
  }

  hud() {
    const s = this.stats;
    $('hud-mr').textContent = `mr sent ${s.sent} · ack ${s.acks} (${s.replaced} replaced) · lights ${s.lights} · ${Number(s.ms).toFixed(1)} ms` +
      (s.errors ? ` · ${s.errors} errors` : '');
  }

  showFrame(f) {
    const r = this.recording, pc = unproject(f, r.width, r.height), g = this.cloud.geometry;
    g.setAttribute('position', new THREE.BufferAttribute(pc.positions, 3));
    g.setAttribute('color', new THREE.BufferAttribute(pc.colors, 3));
    g.computeBoundingSphere();
    this.stats.points = pc.count;
    this.frustum.geometry.setAttribute('position', new THREE.BufferAttribute(this.frustumLines(f), 3));
    this.frustum.geometry.computeBoundingSphere();
    this.shownFrame = f.k;
    this.render();
  }

  frustumLines(f) {
    const r = this.recording, z = Math.max(0.05, (this.size || 1) * 0.05), q = new THREE.Quaternion(...f.rotation).normalize();
    const t = new THREE.Vector3(...f.translation);
    const c = [[0, 0], [r.width, 0], [r.width, r.height], [0, r.height]].map(([u, v]) =>
      new THREE.Vector3((u - f.cx) * z / f.fx, -(v - f.cy) * z / f.fy, -z).applyQuaternion(q).add(t));
    const out = [];
    for (let i = 0; i < 4; i++) out.push(t, c[i], c[i], c[(i + 1) % 4]);
    return new Float32Array(out.flatMap((v) => [v.x, v.y, v.z]));
  }

  // The sparse points in world space: the asset glTF's sparse_point_accessors (PROTOCOL §8.7)
  // placed with the object; for an asset glTF without them, each is estimated as the mean of
  // the vertices whose nearest sparse point (_LUCENT_SP_INDEX0.x) it is.
  sparsePoints(id, count) {
    const it = this.objects.get(id);
    if (!it) return null;
    const sum = new Float64Array(3 * count), num = new Uint32Array(count), v = new THREE.Vector3();
    let any = false, exact = null;
    it.root.updateMatrixWorld(true);
    it.root.traverse((o) => {
      const sp = o.isMesh && o.geometry.userData.sparsePoints;
      if (!sp || sp.length !== 3 * count || exact) return;
      exact = new Float32Array(3 * count);
      for (let j = 0; j < count; j++) v.fromArray(sp, 3 * j).applyMatrix4(o.matrixWorld).toArray(exact, 3 * j);
    });
    if (exact) return exact;
    it.root.traverse((o) => {
      const g = o.isMesh && o.geometry, idx = g && (g.attributes._lucent_sp_index0 || g.attributes._LUCENT_SP_INDEX0);
      if (!idx) return;
      const pos = g.attributes.position;
      for (let i = 0; i < pos.count; i++) {
        const j = idx.getX(i);
        if (j >= count) continue;
        v.fromBufferAttribute(pos, i).applyMatrix4(o.matrixWorld);
        sum[3 * j] += v.x, sum[3 * j + 1] += v.y, sum[3 * j + 2] += v.z;
        num[j]++;
        any = true;
      }
    });
    if (!any) return null;
    const out = new Float32Array(3 * count).fill(NaN);
    for (let j = 0; j < count; j++) if (num[j]) for (let c = 0; c < 3; c++) out[3 * j + c] = sum[3 * j + c] / num[j];
    return out;
  }

  onVpl(v) {
    let total = 0;
    for (const o of v.objects) total += o.count;
    const pos = new Float32Array(3 * total), col = new Float32Array(3 * total), lp = [], lc = [];
    let m = 0, maxI = 0;
    for (const o of v.objects) for (let j = 0; j < o.count; j++) maxI = Math.max(maxI, o.records[VPL_VALUES * j], o.records[VPL_VALUES * j + 1], o.records[VPL_VALUES * j + 2]);
    const scale = maxI > 0 ? 1 / maxI : 1;
    for (const o of v.objects) {
      const sp = this.sparsePoints(o.id, o.count);
      for (let j = 0; j < o.count; j++, m++) {
        const r = o.records.subarray(VPL_VALUES * j, VPL_VALUES * (j + 1));
        pos.set(r.subarray(3, 6), 3 * m);
        for (let c = 0; c < 3; c++) col[3 * m + c] = Math.min(1, Math.sqrt(Math.max(0, r[c] * scale)));
        if (sp && Number.isFinite(sp[3 * j])) {
          lp.push(sp[3 * j], sp[3 * j + 1], sp[3 * j + 2], r[3], r[4], r[5]);
          lc.push(...col.subarray(3 * m, 3 * m + 3), ...col.subarray(3 * m, 3 * m + 3));
        }
      }
    }
    const g = this.vpl.geometry;
    g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    g.setAttribute('color', new THREE.BufferAttribute(col, 3));
    g.computeBoundingSphere();
    const lg = this.lines.geometry;
    lg.setAttribute('position', new THREE.BufferAttribute(new Float32Array(lp), 3));
    lg.setAttribute('color', new THREE.BufferAttribute(new Float32Array(lc), 3));
    lg.computeBoundingSphere();
    this.stats.vplFrames++;
    this.stats.vplPoints = total;
    this.stats.vplLines = lp.length / 6;
    this.stats.vplObjects = v.objects.map((o) => ({ id: o.id, count: o.count }));
    this.lastVpl = v;
    if (this.vertexShading) this.shadeVertices(v);
    this.render();
  }

  /** Per-vertex VPL shading on (the objects' SH is then off for the session's objects) or off. */
  setVertexShading(on) {
    this.vertexShading = on;
    if (on && this.lastVpl) this.shadeVertices(this.lastVpl);
    for (const id of this.sessionObjects || []) {
      const it = this.objects.get(id);
      if (!it) continue;
      for (const m of it.materials) {
        if (m.userData.mrGain) m.userData.mrGain.value = on ? 1 : 0;
        m.userData.shGain.value = on ? 0 : this.objects.shGain;
      }
    }
    this.render();
  }

  // Each vertex's I_d and l_d: its 8 sparse points' records averaged with the glTF's weights
  // (_LUCENT_SP_INDEX0/1, _LUCENT_SP_WEIGHT0/1; three's loader lower-cases the names).
  shadeVertices(v) {
    let shaded = 0;
    for (const o of v.objects) {
      const it = this.objects.get(o.id);
      if (!it) continue;
      it.root.traverse((mesh) => {
        if (!mesh.isMesh) return;
        // Instances of one asset share its geometry: each object gets its own copy first.
        if (mesh.geometry.userData.mrOwner !== o.id) {
          mesh.geometry = mesh.geometry.clone();
          mesh.geometry.userData.mrOwner = o.id;
        }
        const g = mesh.geometry, a = g.attributes;
        const idx = a && [a._lucent_sp_index0, a._lucent_sp_index1], w = a && [a._lucent_sp_weight0, a._lucent_sp_weight1];
        if (!idx || !idx[0] || !idx[1] || !w[0] || !w[1]) return;
        const n = a.position.count, I = new Float32Array(3 * n), L = new Float32Array(3 * n);
        for (let i = 0; i < n; i++) {
          let sw = 0;
          for (let k = 0; k < 8; k++) {
            const j = idx[k >> 2].getComponent(i, k & 3), wt = w[k >> 2].getComponent(i, k & 3);
            if (!(wt > 0) || j >= o.count) continue;
            const r = VPL_VALUES * j;
            for (let c = 0; c < 3; c++) {
              I[3 * i + c] += wt * o.records[r + c];
              L[3 * i + c] += wt * o.records[r + 3 + c];
            }
            sw += wt;
          }
          if (sw > 0) for (let c = 0; c < 3; c++) L[3 * i + c] /= sw, I[3 * i + c] /= sw;
        }
        g.setAttribute('lucentMrI', new THREE.BufferAttribute(I, 3));
        g.setAttribute('lucentMrL', new THREE.BufferAttribute(L, 3));
        shaded += n;
      });
    }
    this.stats.shadedVertices = shaded;
  }

  /** For tests: the cloud's point i (world space), or null. */
  point(i) {
    const a = this.cloud.geometry.attributes.position;
    return a && i < a.count ? [a.getX(i), a.getY(i), a.getZ(i)] : null;
  }

  /** For tests: what is shown. */
  snapshot() {
    const s = this.stats;
    return { ...s, playing: this.playing, grant: this.grant || null, shownFrame: this.shownFrame || null,
      cloudPoints: this.cloud.geometry.attributes.position ? this.cloud.geometry.attributes.position.count : 0,
      recording: this.recording ? { name: this.recording.name, width: this.recording.width, height: this.recording.height,
        frames: this.recording.frames.length } : null, sessionObjects: this.sessionObjects || null };
  }
}
