// Editing: click a light's gizmo or an object to select it, drag it with TransformControls
// (light.set / object.set throttled to at most 30 per second, the last pose always sent),
// edit a light in the panel, add and remove lights and objects, set the environment. Every
// edit is an ordinary protocol request; a viewer-role page is read-only (the server refuses
// with `forbidden`, and the UI disables editing once welcome says so).
import * as THREE from 'three';
import { TransformControls } from 'three/addons/controls/TransformControls.js';

const SEND_INTERVAL_MS = 1000 / 30;
const $ = (id) => document.getElementById(id);

function toLinear(hex) {
  const c = new THREE.Color(hex); // setStyle decodes sRGB into the linear working space
  return [c.r, c.g, c.b].map((x) => Number(x.toFixed(5)));
}

const short = (x) => Number(Number(x).toPrecision(6));

function toHex(rgb) {
  const peak = Math.max(rgb[0], rgb[1], rgb[2], 1);
  return `#${new THREE.Color().setRGB(rgb[0] / peak, rgb[1] / peak, rgb[2] / peak, THREE.LinearSRGBColorSpace).getHexString()}`;
}

/** Sends one request at a time per key, at most every SEND_INTERVAL_MS, and always the latest. */
class Throttle {
  constructor(send) {
    this.send = send;
    this.last = 0;
    this.timer = null;
    this.pendingMsg = null;
  }

  push(msg) {
    this.pendingMsg = msg;
    const wait = this.last + SEND_INTERVAL_MS - performance.now();
    if (wait <= 0) this.flush();
    else if (!this.timer) this.timer = setTimeout(() => this.flush(), wait);
  }

  flush() {
    clearTimeout(this.timer);
    this.timer = null;
    if (!this.pendingMsg) return;
    const m = this.pendingMsg;
    this.pendingMsg = null;
    this.last = performance.now();
    this.send(m);
  }
}

export class Editor {
  constructor(ctx) {
    Object.assign(this, ctx); // client, camera, scene, dom, lights, objects, staticScene, state, send, render, rig
    this.readOnly = false;
    this.selected = null; // {kind: 'light'|'object', id}
    this.dragging = false;
    this.proxy = new THREE.Object3D();
    this.scene.add(this.proxy);
    this.tc = new TransformControls(this.camera, this.dom);
    this.tc.setSize(0.8);
    this.scene.add(this.tc.getHelper());
    this.tc.addEventListener('dragging-changed', (e) => this.onDragging(e.value));
    this.tc.addEventListener('objectChange', () => this.onProxyMoved());
    this.tc.addEventListener('change', () => this.render(false));
    this.throttle = new Throttle((m) => this.send(m));
    this.raycaster = new THREE.Raycaster();
    this.down = null;
    this.dom.addEventListener('pointerdown', (e) => { this.down = { x: e.clientX, y: e.clientY }; });
    this.dom.addEventListener('pointerup', (e) => this.onClick(e));
    window.addEventListener('keydown', (e) => this.onKey(e));
    this.bindPanel();
  }

  setReadOnly(on) {
    this.readOnly = on;
    for (const el of document.querySelectorAll('.edit')) el.disabled = on;
    if (on) this.tc.detach();
  }

  // ----------------------------------------------------------------- selection

  onClick(e) {
    if (!this.down || this.dragging || this.tc.dragging) return;
    const moved = Math.hypot(e.clientX - this.down.x, e.clientY - this.down.y);
    this.down = null;
    if (moved > 4 || this.rig.flying) return;
    const r = this.dom.getBoundingClientRect();
    const ndc = new THREE.Vector2(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    if (this.lights.gizmos.visible) {
      const hit = this.raycaster.intersectObjects(this.lights.gizmos.children, false)[0];
      if (hit) return this.select({ kind: 'light', id: this.lights.idOf(hit.object) });
    }
    const hitObj = this.raycaster.intersectObjects(this.objects.group.children, true)[0];
    const hitStatic = this.raycaster.intersectObjects(this.staticScene.group.children, false)[0];
    if (hitObj && (!hitStatic || hitObj.distance <= hitStatic.distance))
      return this.select({ kind: 'object', id: this.objects.idOf(hitObj.object) });
    this.select(null);
  }

  select(sel) {
    this.selected = sel;
    this.tc.detach();
    $('selection').classList.toggle('hidden', !sel);
    if (!sel) return this.render();
    const spec = this.spec();
    if (!spec) { this.selected = null; return this.render(); }
    this.placeProxy(spec);
    if (!this.readOnly) {
      const rotatable = sel.kind === 'object' || spec.type === 'spot' || spec.type === 'area';
      if (this.tc.mode !== 'translate' && !rotatable) this.tc.setMode('translate');
      this.tc.attach(this.proxy);
    }
    this.fillPanel(spec);
    this.render();
  }

  spec() {
    const s = this.selected;
    if (!s) return null;
    const it = s.kind === 'light' ? this.lights.get(s.id) : this.objects.get(s.id);
    return it ? it.spec : null;
  }

  /** The proxy the TransformControls move: at the light (for a sun: its gizmo, whose
   *  direction to the scene centre is the sun's), its -z along the light's direction; or
   *  the object's TRS. */
  placeProxy(spec) {
    const p = this.proxy;
    p.scale.set(1, 1, 1);
    p.quaternion.identity();
    if (this.selected.kind === 'object') {
      p.position.fromArray(spec.translation || [0, 0, 0]);
      p.quaternion.fromArray(spec.rotation || [0, 0, 0, 1]).normalize();
      p.scale.fromArray(spec.scale || [1, 1, 1]);
    } else if (spec.type === 'directional') {
      p.position.copy(this.lights.get(spec.id).gizmo.position);
    } else {
      p.position.fromArray(spec.position);
      if (spec.direction) {
        const d = new THREE.Vector3().fromArray(spec.direction).normalize();
        p.quaternion.setFromUnitVectors(new THREE.Vector3(0, 0, -1), d);
      }
    }
    p.updateMatrixWorld(true);
  }

  onDragging(on) {
    this.dragging = on;
    this.rig.setEnabled(!on);
    if (!on) this.throttle.flush();
  }

  onProxyMoved() {
    const spec = this.spec();
    if (!spec) return;
    const p = this.proxy;
    const r = (x) => Number(x.toFixed(6));
    if (this.selected.kind === 'object') {
      spec.translation = p.position.toArray().map(r);
      spec.rotation = p.quaternion.toArray().map(r);
      spec.scale = p.scale.toArray().map((x) => r(Math.max(Math.abs(x), 1e-6)));
      this.objects.upsert(spec);
      this.throttle.push({ type: 'object.set', object: { ...spec } });
    } else {
      if (spec.type === 'directional') {
        const d = this.lights.center.clone().sub(p.position).normalize();
        spec.direction = d.toArray().map(r);
      } else {
        spec.position = p.position.toArray().map(r);
        if (spec.direction) spec.direction = new THREE.Vector3(0, 0, -1).applyQuaternion(p.quaternion).toArray().map(r);
      }
      this.lights.upsert(spec);
      this.throttle.push({ type: 'light.set', light: { ...spec } });
    }
    this.render(true);
  }

  /** The id the drag owns: state refreshes leave it alone until the drag ends. */
  draggedId(kind) {
    return this.dragging && this.selected && this.selected.kind === kind ? this.selected.id : null;
  }

  onKey(e) {
    if (e.target.tagName === 'INPUT' || e.target.tagName === 'SELECT') return;
    if (e.key === 'Escape') this.select(null);
    else if (e.key === 'Delete' && this.selected && !this.readOnly) this.removeSelected();
    else if (e.key === 't') this.tc.setMode('translate');
    else if (e.key === 'r') this.tc.setMode('rotate');
    else if (e.key === 's' && this.selected && this.selected.kind === 'object') this.tc.setMode('scale');
  }

  // ----------------------------------------------------------------- panel

  fillPanel(spec) {
    const light = this.selected.kind === 'light';
    $('sel-title').textContent = `${light ? spec.type : spec.asset} ${spec.id}`;
    $('sel-light').classList.toggle('hidden', !light);
    if (!light) return;
    $('sel-color').value = toHex(spec.color || [1, 1, 1]);
    $('sel-intensity').value = short(spec.intensity ?? 1);
    $('sel-intensity-label').textContent = { point: 'candela', spot: 'candela', directional: 'lux', area: 'nits' }[spec.type];
    $('sel-range').value = short(spec.range ?? 0);
    const deg = (x) => Number(THREE.MathUtils.radToDeg(x).toFixed(3));
    $('sel-inner').value = deg(spec.innerConeAngle ?? 0);
    $('sel-outer').value = deg(spec.outerConeAngle ?? Math.PI / 4);
    $('sel-size').value = short((spec.size || [1])[0]);
    for (const el of document.querySelectorAll('.spot-only')) el.classList.toggle('hidden', spec.type !== 'spot');
    for (const el of document.querySelectorAll('.area-only')) el.classList.toggle('hidden', spec.type !== 'area');
  }

  panelEdit() {
    const spec = this.spec();
    if (!spec || this.selected.kind !== 'light') return;
    const num = (id, lo, hi) => { const v = Number($(id).value); return Number.isFinite(v) ? Math.min(hi, Math.max(lo, v)) : null; };
    spec.color = toLinear($('sel-color').value);
    spec.intensity = num('sel-intensity', 0, 1e9) ?? spec.intensity;
    if (spec.type !== 'directional') spec.range = num('sel-range', 0, 1e6) ?? spec.range;
    if (spec.type === 'spot') {
      const outer = THREE.MathUtils.degToRad(num('sel-outer', 0, 90) ?? 45);
      spec.outerConeAngle = outer;
      spec.innerConeAngle = Math.min(outer, THREE.MathUtils.degToRad(num('sel-inner', 0, 90) ?? 0));
    }
    if (spec.type === 'area') {
      const s = num('sel-size', 1e-4, 1e4) ?? 1;
      spec.size = spec.shape === 'disc' ? [s] : [s, s * ((spec.size && spec.size[1]) / spec.size[0] || 1)];
    }
    this.lights.upsert(spec);
    this.send({ type: 'light.set', light: { ...spec } });
    this.render(true);
  }

  bindPanel() {
    for (const id of ['sel-color', 'sel-intensity', 'sel-range', 'sel-inner', 'sel-outer', 'sel-size'])
      $(id).addEventListener('change', () => this.panelEdit());
    $('sel-translate').addEventListener('click', () => this.tc.setMode('translate'));
    $('sel-rotate').addEventListener('click', () => this.tc.setMode('rotate'));
    $('sel-remove').addEventListener('click', () => this.removeSelected());
    $('sel-close').addEventListener('click', () => this.select(null));
    for (const type of ['point', 'spot', 'directional', 'area'])
      $(`add-${type}`).addEventListener('click', () => this.addLight(type));
    $('add-object').addEventListener('click', () => this.addObject($('asset').value));
    for (const id of ['env-type', 'env-color', 'env-intensity'])
      $(id).addEventListener('change', () => this.setEnvironment());
    const assets = $('asset');
    for (const name of this.objects.assetNames()) {
      const o = document.createElement('option');
      o.value = o.textContent = name;
      assets.appendChild(o);
    }
  }

  fillEnvironment(env) {
    if (!env) return;
    const known = ['none', 'constant'].includes(env.type);
    $('env-type').value = known ? env.type : 'constant';
    if (env.type === 'none') return; // keep the panel's sky colour for when one is switched on
    if (env.color) $('env-color').value = toHex(env.color);
    if (env.intensity !== undefined) $('env-intensity').value = short(env.intensity);
  }

  uniqueId(prefix, taken) {
    for (let i = 1; ; i++) if (!taken.has(`${prefix}-${i}`)) return `${prefix}-${i}`;
  }

  addLight(type) {
    const b = this.staticScene.bounds;
    const c = b.getCenter(new THREE.Vector3());
    const S = this.staticScene.size;
    const top = c.clone().setY(b.min.y + 0.85 * (b.max.y - b.min.y));
    const spec = { id: this.uniqueId(type, new Set(this.lights.items.keys())), type, color: [1, 1, 1] };
    if (type === 'point') Object.assign(spec, { position: c.toArray(), intensity: 0.5 * (S / 2) ** 2 });
    if (type === 'spot') Object.assign(spec, { position: top.toArray(), direction: [0, -1, 0], intensity: (S / 2) ** 2,
      innerConeAngle: 0.3, outerConeAngle: 0.6 });
    if (type === 'directional') Object.assign(spec, { direction: [0.3, -1, 0.2], intensity: 1 });
    if (type === 'area') Object.assign(spec, { position: top.toArray(), direction: [0, -1, 0], shape: 'quad',
      size: [S / 8, S / 8], intensity: 10 });
    this.lights.upsert(spec);
    this.send({ type: 'light.set', light: spec });
    this.select({ kind: 'light', id: spec.id });
    this.render(true);
  }

  addObject(asset) {
    if (!asset) return;
    const b = this.staticScene.bounds;
    const c = b.getCenter(new THREE.Vector3());
    const spec = { id: this.uniqueId(asset, new Set(this.objects.items.keys())), asset,
      translation: [c.x, b.min.y, c.z], rotation: [0, 0, 0, 1], scale: [1, 1, 1], visible: true };
    this.objects.upsert(spec);
    this.send({ type: 'object.set', object: spec });
    this.select({ kind: 'object', id: spec.id });
    this.render(true);
  }

  removeSelected() {
    const s = this.selected;
    if (!s) return;
    if (s.kind === 'light') {
      this.lights.remove(s.id);
      this.send({ type: 'light.remove', light_id: s.id });
    } else {
      this.objects.remove(s.id);
      this.send({ type: 'object.remove', object_id: s.id });
    }
    this.select(null);
    this.render(true);
  }

  setEnvironment() {
    const type = $('env-type').value;
    const env = type === 'none' ? { type: 'none' }
      : { type: 'constant', color: toLinear($('env-color').value), intensity: Number($('env-intensity').value) || 0 };
    this.send({ type: 'environment.set', environment: env });
  }
}
