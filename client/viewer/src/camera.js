// Camera navigation: OrbitControls by default, and a fly mode (WASD/QE to move, drag to look,
// Shift for speed) that hands its position back to the orbit when it ends.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const KEYS = { KeyW: [0, 0, -1], KeyS: [0, 0, 1], KeyA: [-1, 0, 0], KeyD: [1, 0, 0], KeyQ: [0, -1, 0], KeyE: [0, 1, 0] };

export class CameraRig {
  constructor(camera, dom, size, onChange) {
    this.camera = camera;
    this.dom = dom;
    this.size = size;
    this.onChange = onChange;
    this.orbit = new OrbitControls(camera, dom);
    this.orbit.enableDamping = false;
    this.orbit.addEventListener('change', () => onChange());
    this.flying = false;
    this.keys = new Set();
    this.euler = new THREE.Euler(0, 0, 0, 'YXZ');
    this.last = 0;
    this.looking = null;
    window.addEventListener('keydown', (e) => this.key(e, true));
    window.addEventListener('keyup', (e) => this.key(e, false));
    dom.addEventListener('pointerdown', (e) => { if (this.flying) this.looking = { x: e.clientX, y: e.clientY }; });
    window.addEventListener('pointerup', () => { this.looking = null; });
    dom.addEventListener('pointermove', (e) => this.look(e));
  }

  set(view) {
    this.camera.position.fromArray(view.camera);
    this.orbit.target.fromArray(view.target);
    this.camera.fov = view.fov;
    this.camera.updateProjectionMatrix();
    this.camera.lookAt(this.orbit.target);
    this.orbit.update();
    this.onChange();
  }

  /** The view as the URL writes it. */
  view() {
    const target = this.flying
      ? this.camera.getWorldDirection(new THREE.Vector3()).multiplyScalar(this.size * 0.5).add(this.camera.position)
      : this.orbit.target;
    return { camera: this.camera.position.toArray(), target: target.toArray(), fov: this.camera.fov };
  }

  setFly(on) {
    if (on === this.flying) return;
    this.flying = on;
    this.orbit.enabled = !on;
    if (on) this.euler.setFromQuaternion(this.camera.quaternion);
    else {
      const d = this.camera.position.distanceTo(this.orbit.target) || this.size * 0.5;
      this.orbit.target.copy(this.camera.getWorldDirection(new THREE.Vector3()).multiplyScalar(d).add(this.camera.position));
      this.orbit.update();
    }
  }

  setEnabled(on) {
    this.orbit.enabled = on && !this.flying;
  }

  key(e, down) {
    if (!this.flying || !(e.code in KEYS) || e.target.tagName === 'INPUT') return;
    if (down) this.keys.add(e.code); else this.keys.delete(e.code);
    if (down && this.keys.size === 1) { this.last = performance.now(); requestAnimationFrame((t) => this.tick(t)); }
  }

  tick(t) {
    if (!this.flying || !this.keys.size) return;
    const dt = Math.min(0.1, (t - this.last) / 1000);
    this.last = t;
    const v = new THREE.Vector3();
    for (const k of this.keys) v.add(new THREE.Vector3(...KEYS[k]));
    v.multiplyScalar(dt * this.size * 0.4).applyQuaternion(this.camera.quaternion);
    this.camera.position.add(v);
    this.onChange();
    requestAnimationFrame((tt) => this.tick(tt));
  }

  look(e) {
    if (!this.flying || !this.looking) return;
    const dx = e.clientX - this.looking.x, dy = e.clientY - this.looking.y;
    this.looking = { x: e.clientX, y: e.clientY };
    this.euler.y -= dx * 0.004;
    this.euler.x = THREE.MathUtils.clamp(this.euler.x - dy * 0.004, -1.55, 1.55);
    this.camera.quaternion.setFromEuler(this.euler);
    this.onChange();
  }
}
