// lucent's browser viewer: connects to the lucentd that served the page, loads the bake's
// geometry (welcome.scene.geometry), streams the lightmap, the objects' SH and (for the probe
// view) the SH grid, and renders in physical units (see shading.js for the formula).
// Test hook: window.lucentViewer = { ready, revision(), converged(), lastLatencyMs(), role(),
// lastError(), camera(), frameCount(), overlay() } — the only global.
import * as THREE from 'three';
import { LucentClient } from '../../js/lucent.js';
import { readView, writeView } from './urlstate.js';
import { loadGlb, StaticScene } from './scene.js';
import { LightmapTexture } from './lightmap.js';
import { LightSet } from './lights.js';
import { ObjectSet } from './objects.js';
import { ProbeGrid } from './probes.js';
import { decodeOverlay, fetchOverlay, overlaySizeError, overlayTexture, readOverlayFile, setOverlayNearest } from './overlay.js';
import { Environment } from './environment.js';
import { Hud, toast, banner } from './hud.js';
import { CameraRig } from './camera.js';
import { Editor } from './edit.js';
import { Latency } from './latency.js';
import { MrPanel, urlSource } from './mr.js';

const TONEMAPS = { none: THREE.LinearToneMapping, neutral: THREE.NeutralToneMapping, aces: THREE.ACESFilmicToneMapping };
const $ = (id) => document.getElementById(id);

class Viewer {
  constructor() {
    this.url = readView(location.search);
    this.mode = this.url.mode || 'full';
    this.tonemap = this.url.tonemap || 'none';
    this.exposure = this.url.exposure ?? 1;
    this.liveMode = this.mode === 'heatmap' ? 'full' : this.mode; // what the overlay toggle returns to
    this.overlay = null; // {name, kind, width, height, scalar, texture}
    this.overlayMax = this.url.overlayMax ?? 1;
    this.overlayNearest = true;
    this.errors = [];
    this.frames = 0;
    this.shownRevision = null;
    this.shownConverged = false; // the shown lightmap frame is its revision's last (PROTOCOL.md §6.1.1)
    this.serverRevision = 0;
    this.renderQueued = false;
    this.hud = new Hud();
    this.latency = new Latency((ms, what) => this.hud.latency(ms, what));
    if (this.url.clean) document.body.classList.add('clean');
  }

  fail(message) {
    this.errors.push(message);
    toast(message, 0);
  }

  async start() {
    this.initRenderer();
    const wsUrl = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/`;
    this.client = new LucentClient(wsUrl, { token: this.url.token || '', client: 'lucent-viewer/0.1', reconnect: true,
      capabilities: ['mr'] });
    this.bindClient();
    this.hud.connection('connecting');
    const welcome = await this.client.connect();
    this.welcome = welcome;
    this.serverRevision = welcome.revision;
    this.hud.connection('open', welcome.role);
    this.hud.revision(welcome.revision);
    const scene = welcome.scene || {};
    const gltf = await loadGlb(scene.geometry || '/scene.glb');
    this.buildScene(gltf, scene);
    if (welcome.role !== 'controller') {
      this.editor.setReadOnly(true);
      banner(`read-only: this page's token has the ${welcome.role} role`);
    }
    await this.refreshState();
    await this.client.subscribe('lightmap', { encoding: 'rgb9e5', delta: 'residual' });
    const hasAssets = (this.objects.assetNames().length || (scene.assets || []).length) > 0;
    if (hasAssets) await this.client.subscribe('objects', { encoding: 'f32' });
    if (this.mode === 'probes') await this.subscribeGrid();
    if (this.url.overlay) await this.loadOverlay(() => fetchOverlay(this.url.overlay), !this.url.mode);
    this.applyMode();
    this.mr = new MrPanel({ client: this.client, scene: this.scene, objects: this.objects, errors: this.errors,
      size: this.staticScene.size, render: () => this.requestRender() });
    const mrUrl = new URLSearchParams(location.search).get('mr');
    if (mrUrl) this.mr.open(urlSource(mrUrl));
    await this.firstFrame;
  }

  initRenderer() {
    const canvas = $('view');
    const r = new THREE.WebGLRenderer({ canvas, antialias: true });
    r.setPixelRatio(window.devicePixelRatio || 1);
    r.setSize(window.innerWidth, window.innerHeight, false);
    r.outputColorSpace = THREE.SRGBColorSpace;
    r.shadowMap.enabled = true;
    r.shadowMap.type = THREE.PCFShadowMap; // r187's PCF is the soft one (PCFSoftShadowMap was folded into it)
    r.shadowMap.autoUpdate = false; // redrawn when lights or objects change, not on every camera move
    this.renderer = r;
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, window.innerWidth / window.innerHeight, 0.01, 1000);
    window.addEventListener('resize', () => {
      r.setSize(window.innerWidth, window.innerHeight, false);
      this.camera.aspect = window.innerWidth / window.innerHeight;
      this.camera.updateProjectionMatrix();
      this.requestRender();
    });
    this.applyToneMap();
    let resolveFirst;
    this.firstFrame = new Promise((res) => { resolveFirst = res; });
    this.resolveFirst = resolveFirst;
  }

  buildScene(gltf, sceneInfo) {
    const st = new StaticScene(gltf);
    this.staticScene = st;
    this.scene.add(st.group);
    this.camera.near = st.size * 1e-3;
    this.camera.far = st.size * 100;
    this.lightmap = new LightmapTexture();
    this.lightmap.onReplace((t) => st.setLightmap(t));
    this.lights = new LightSet(this.scene, st);
    this.lights.setGizmosVisible(!this.url.clean);
    const assetPaths = sceneInfo.asset_geometry || Object.fromEntries((sceneInfo.assets || []).map((a) => [a, `/assets/${a}.glb`]));
    this.objects = new ObjectSet(this.scene, assetPaths, () => this.requestRender(true));
    this.probes = new ProbeGrid(this.scene, st.size);
    this.environment = new Environment(this.scene, st.size);
    this.rig = new CameraRig(this.camera, this.renderer.domElement, st.size, () => this.onCamera());
    const def = st.defaultView(this.url.fov ?? 40);
    this.rig.set({ camera: this.url.camera || def.camera, target: this.url.target || def.target, fov: this.url.fov ?? def.fov });
    this.editor = new Editor({ client: this.client, camera: this.camera, scene: this.scene, dom: this.renderer.domElement,
      lights: this.lights, objects: this.objects, staticScene: st, rig: this.rig,
      send: (m) => this.send(m), render: (scene) => this.requestRender(scene) });
    this.bindPanel();
  }

  bindClient() {
    const c = this.client;
    c.on('lightmap', (lm, h) => this.onLightmap(lm, h));
    c.on('objects', (o) => { this.objects.setSH(o.byId); this.requestRender(); });
    c.on('shgrid', (g) => { this.probes.update(g); this.requestRender(); });
    c.on('frame', (h) => this.onFrameHeader(h));
    c.on('changed', (m) => this.onChanged(m));
    c.on('close', (e) => this.hud.connection(e && e.reconnecting ? 'reconnecting' : 'closed'));
    c.on('reconnecting', () => this.hud.connection('reconnecting'));
    c.on('welcome', (w) => {
      this.hud.connection('open', w.role);
      if (this.staticScene) this.refreshState();
    });
    c.on('error', (e) => this.errors.push(`${e.code || 'error'}: ${e.message}`));
  }

  onFrameHeader(h) {
    this.hud.frame(h.stream, h.byteLength);
    if (h.revision > this.serverRevision) { this.serverRevision = h.revision; this.hud.revision(this.serverRevision); }
  }

  onLightmap(lm, h) {
    this.lightmap.update(lm);
    this.pendingShown = { revision: h.revision, pass: h.pass, converged: h.converged };
    this.requestRender();
  }

  onChanged(m) {
    this.hud.changed(m);
    if (m.revision > this.serverRevision) { this.serverRevision = m.revision; this.hud.revision(this.serverRevision); }
    this.latency.external(m.revision, this.shownRevision);
    this.refreshState();
  }

  /** One state.get at a time; a refresh asked for meanwhile runs once after it. */
  async refreshState() {
    if (this.stateBusy) { this.stateAgain = true; return; }
    this.stateBusy = true;
    try {
      do {
        this.stateAgain = false;
        this.applyState(await this.client.state());
      } while (this.stateAgain);
    } catch (e) {
      this.errors.push(`state.get: ${e.message}`);
    } finally {
      this.stateBusy = false;
    }
  }

  applyState(s) {
    this.state = s;
    if (s.revision > this.serverRevision) { this.serverRevision = s.revision; this.hud.revision(this.serverRevision); }
    this.lights.sync(s.lights || [], this.editor.draggedId('light'));
    this.objects.sync(s.objects || [], this.editor.draggedId('object'));
    this.staticScene.setEmission(s.materials);
    this.environment.set(s.environment);
    this.editor.fillEnvironment(s.environment);
    if (this.editor.selected && !this.editor.spec()) this.editor.select(null);
    this.requestRender(true);
  }

  /** Every edit goes through here: an ordinary request; refusals are shown. */
  send(msg) {
    const t0 = performance.now();
    const p = this.client.request(msg);
    this.latency.own(t0, p, () => this.shownRevision);
    p.then((ok) => {
      if (ok.revision > this.serverRevision) { this.serverRevision = ok.revision; this.hud.revision(ok.revision); }
      // Lights and objects were applied here before sending; anything else comes from the state.
      if (msg.type !== 'light.set' && msg.type !== 'object.set') this.refreshState();
    }).catch((e) => {
      const text = `${msg.type} refused: ${e.code || 'error'}${e.message ? ` — ${e.message}` : ''}`;
      this.errors.push(text);
      toast(text);
      if (e.code === 'forbidden') {
        this.editor.setReadOnly(true);
        banner('read-only: the server refused an edit (forbidden) — this token has the viewer role');
      }
      this.refreshState();
    });
    return p;
  }

  async subscribeGrid() {
    if (this.gridSubscribed) return;
    this.gridSubscribed = true;
    await this.client.subscribe('shgrid', { encoding: 'f32', max_rate: 10 });
  }

  // ----------------------------------------------------------------- modes, view, panel

  applyMode() {
    const m = this.mode;
    if (!this.staticScene) return;
    this.staticScene.applyMode(m);
    this.lights.setEnabled(m === 'full' || m === 'direct' || m === 'probes');
    this.objects.setGain(m === 'direct' ? 0 : 1);
    this.lightmap.setNearest(m === 'texels');
    if (m !== 'heatmap') this.liveMode = m;
    this.drawLegend();
    this.probes.setVisible(m === 'probes');
    this.renderer.shadowMap.needsUpdate = true;
    if (m === 'probes') this.subscribeGrid().catch((e) => this.errors.push(e.message));
    $('mode').value = m;
    this.onCamera();
  }

  applyToneMap() {
    this.renderer.toneMapping = TONEMAPS[this.tonemap];
    this.renderer.toneMappingExposure = this.exposure;
    $('tonemap').value = this.tonemap;
    $('exposure').value = this.exposure;
    this.requestRender();
  }

  // ----------------------------------------------------------------- the overlay (overlay.js)

  /** Loads an overlay from `source()` ({name, bytes}); shown at once unless `show` is false
   *  (the URL asked for a mode). Refusals (size, format, fetch) are shown and kept as the
   *  last error; the previous overlay, if any, stays. Resolves true when it was taken. */
  async loadOverlay(source, show = true) {
    let ov;
    try {
      ov = await decodeOverlay(await source());
      const lm = (this.welcome && this.welcome.scene && this.welcome.scene.lightmap) || this.lightmap.texture?.image;
      if (!lm || !lm.width) throw new Error(`overlay ${ov.name}: the lightmap's size is not known yet`);
      const why = overlaySizeError(ov, lm.width, lm.height);
      if (why) throw new Error(why);
    } catch (e) {
      this.fail(e.message || String(e));
      return false;
    }
    if (this.overlay) this.overlay.texture.dispose();
    ov.texture = overlayTexture(ov, this.overlayNearest);
    delete ov.data;
    this.overlay = ov;
    this.staticScene.setOverlay(ov.texture, ov.scalar, this.overlayMax);
    $('overlay-status').textContent = `${ov.name}: ${ov.width}x${ov.height} ${ov.kind.toUpperCase()}${ov.scalar ? ', one channel (coloured by the scale)' : ''}`;
    $('toast').classList.add('hidden');
    if (show) this.mode = 'heatmap';
    this.applyMode();
    return true;
  }

  /** The overlay toggle: heat map mode, or back to the mode before it. */
  showOverlay(on) {
    this.mode = on ? 'heatmap' : this.liveMode;
    this.applyMode();
  }

  drawLegend() {
    const shown = this.mode === 'heatmap';
    $('legend').classList.toggle('hidden', !shown);
    document.body.classList.toggle('legend', shown); // messages move up, above the legend
    $('overlay-show').checked = shown;
    if (!shown) return;
    const pct = `${Number((this.overlayMax * 100).toPrecision(4))}%`;
    $('legend-min').textContent = `−${pct}`;
    $('legend-max').textContent = `+${pct}`;
    const o = this.overlay;
    $('legend-title').textContent = o ? `${o.name} (${o.width}x${o.height})` : 'no overlay loaded';
  }

  bindOverlay() {
    const fromFile = (f) => { if (f) this.loadOverlay(() => readOverlayFile(f)); };
    $('overlay-file').addEventListener('change', (e) => { fromFile(e.target.files[0]); e.target.value = ''; });
    $('overlay-show').addEventListener('change', (e) => this.showOverlay(e.target.checked));
    $('overlay-crisp').addEventListener('change', (e) => {
      this.overlayNearest = e.target.checked;
      if (this.overlay) setOverlayNearest(this.overlay.texture, this.overlayNearest);
      this.requestRender();
    });
    $('overlay-max').value = Number((this.overlayMax * 100).toPrecision(6));
    $('overlay-max').addEventListener('change', (e) => {
      const v = Number(e.target.value);
      if (!(Number.isFinite(v) && v > 0)) return;
      this.overlayMax = v / 100;
      this.staticScene.setOverlay(this.overlay ? this.overlay.texture : null, !!this.overlay?.scalar, this.overlayMax);
      this.drawLegend();
      this.requestRender();
    });
    // Drag and drop anywhere on the page (files only; the drop zone shows while dragging).
    const drop = $('drop');
    let depth = 0;
    const hasFiles = (e) => e.dataTransfer && Array.from(e.dataTransfer.types || []).includes('Files');
    window.addEventListener('dragenter', (e) => { if (hasFiles(e)) { depth++; drop.classList.remove('hidden'); } });
    window.addEventListener('dragleave', () => { if (--depth <= 0) { depth = 0; drop.classList.add('hidden'); } });
    window.addEventListener('dragover', (e) => { if (hasFiles(e)) { e.preventDefault(); e.dataTransfer.dropEffect = 'copy'; } });
    window.addEventListener('drop', (e) => {
      depth = 0;
      drop.classList.add('hidden');
      if (!e.dataTransfer || !e.dataTransfer.files.length) return;
      e.preventDefault();
      fromFile(e.dataTransfer.files[0]);
    });
  }

  bindPanel() {
    const panel = $('panel');
    if (window.innerWidth < 700) panel.classList.add('collapsed'); // small windows: the canvas first
    $('panel-toggle').addEventListener('click', () => panel.classList.toggle('collapsed'));
    window.addEventListener('keydown', (e) => {
      if (['INPUT', 'SELECT'].includes(e.target.tagName)) return;
      if (e.key === 'h') panel.classList.toggle('collapsed');
      if (e.key === 'o') this.showOverlay(this.mode !== 'heatmap');
    });
    $('mode').addEventListener('change', (e) => { this.mode = e.target.value; this.applyMode(); });
    $('tonemap').addEventListener('change', (e) => { this.tonemap = e.target.value; this.applyToneMap(); this.onCamera(); });
    $('exposure').addEventListener('change', (e) => {
      const v = Number(e.target.value);
      if (Number.isFinite(v) && v > 0) { this.exposure = v; this.applyToneMap(); this.onCamera(); }
    });
    $('sky-surfaces').addEventListener('change', (e) => { this.environment.setSkyOnSurfaces(e.target.checked); this.requestRender(); });
    $('fly').addEventListener('change', (e) => { this.rig.setFly(e.target.checked); this.onCamera(); });
    this.bindOverlay();
  }

  onCamera() {
    this.requestRender();
    clearTimeout(this.urlTimer);
    this.urlTimer = setTimeout(() => writeView({ ...this.rig.view(), mode: this.mode, exposure: this.exposure, tonemap: this.tonemap }), 200);
  }

  /** Schedules a draw; `scene` says lights or objects changed (the shadow maps are redrawn). */
  requestRender(scene = false) {
    if (scene) this.renderer.shadowMap.needsUpdate = true;
    if (this.renderQueued) return;
    this.renderQueued = true;
    requestAnimationFrame(() => this.draw());
  }

  draw() {
    this.renderQueued = false;
    if (!this.staticScene) return;
    this.environment.follow(this.camera);
    this.renderer.render(this.scene, this.camera);
    this.frames++;
    const p = this.pendingShown;
    if (p) {
      this.pendingShown = null;
      this.shownRevision = p.revision;
      this.shownConverged = p.converged;
      this.hud.revision(this.serverRevision, p.revision);
      this.hud.pass(p.pass, p.converged);
      this.latency.shown(p.revision);
      this.resolveFirst();
    }
  }

  hook() {
    const v = this;
    return {
      ready: null,
      revision: () => v.shownRevision,
      converged: () => v.shownConverged,
      lastLatencyMs: () => v.latency.last,
      role: () => (v.client ? v.client.role : null),
      lastError: () => (v.errors.length ? v.errors[v.errors.length - 1] : null),
      camera: () => (v.rig ? { ...v.rig.view(), aspect: v.camera.aspect, width: v.renderer.domElement.clientWidth,
        height: v.renderer.domElement.clientHeight } : null),
      frameCount: () => v.frames,
      mr: () => (v.mr ? v.mr.snapshot() : null),
      mrPoint: (i) => (v.mr ? v.mr.point(i) : null),
      overlay: () => ({ shown: v.mode === 'heatmap', max: v.overlayMax, nearest: v.overlayNearest,
        image: v.overlay ? { name: v.overlay.name, kind: v.overlay.kind, width: v.overlay.width, height: v.overlay.height,
          scalar: v.overlay.scalar } : null }),
    };
  }
}

const viewer = new Viewer();
const hook = viewer.hook();
hook.ready = viewer.start().catch((e) => {
  viewer.fail(`viewer: ${e.message || e}`);
  throw e;
});
hook.ready.catch(() => {});
window.lucentViewer = hook;
