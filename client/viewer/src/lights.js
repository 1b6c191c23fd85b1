// The state's lights as three.js lights in physical units (renderer defaults since r155):
// point -> PointLight (candela, distance = range, decay 2: three's window is glTF's range
// window), spot -> SpotLight (angle = outerConeAngle, penumbra = 1 - inner/outer, so the
// smooth step runs from the outer to the inner cone), directional -> DirectionalLight (lux,
// shadow camera fitted to the scene bounds), area -> RectAreaLight (nits; a disc becomes the
// square of the same area) plus its emissive shape. Point, spot and directional lights cast
// PCF shadow maps. Each light has a gizmo the user can click to select it.
import * as THREE from 'three';

const GIZMO_PX = 0.012; // gizmo radius as a fraction of the scene's diagonal

function linearColor(c) {
  return new THREE.Color().setRGB(c[0], c[1], c[2], THREE.LinearSRGBColorSpace);
}

function basis(direction, tangent) {
  const d = new THREE.Vector3().fromArray(direction).normalize();
  let t = tangent ? new THREE.Vector3().fromArray(tangent) : new THREE.Vector3(1, 0, 0);
  t.addScaledVector(d, -t.dot(d));
  if (t.lengthSq() < 1e-8) t = new THREE.Vector3(0, 0, 1).addScaledVector(d, -d.z);
  t.normalize();
  return { d, t };
}

export class LightSet {
  constructor(scene, staticScene) {
    this.scene = scene;
    this.bounds = staticScene.bounds;
    this.size = staticScene.size;
    this.center = this.bounds.getCenter(new THREE.Vector3());
    this.group = new THREE.Group();
    this.group.name = 'lights';
    this.gizmos = new THREE.Group();
    this.gizmos.name = 'gizmos';
    scene.add(this.group, this.gizmos);
    this.items = new Map(); // id -> {spec, light, target, shape, gizmo}
    this.enabled = true;
    this.gizmoGeometry = new THREE.SphereGeometry(GIZMO_PX * this.size, 16, 12);
  }

  /** Makes the three.js lights match `lights` (the state's array). `skip` (an id) is left
   *  alone: the light the user is dragging right now. */
  sync(lights, skip) {
    const seen = new Set();
    for (const spec of lights) {
      seen.add(spec.id);
      if (spec.id === skip) continue;
      this.upsert(spec);
    }
    for (const id of [...this.items.keys()]) if (!seen.has(id) && id !== skip) this.remove(id);
  }

  remove(id) {
    const it = this.items.get(id);
    if (!it) return;
    this.group.remove(it.light);
    if (it.target) this.group.remove(it.target);
    if (it.shape) { this.group.remove(it.shape); it.shape.geometry.dispose(); it.shape.material.dispose(); }
    this.gizmos.remove(it.gizmo);
    it.gizmo.material.dispose();
    if (it.light.shadow && it.light.shadow.map) it.light.shadow.map.dispose();
    this.items.delete(id);
  }

  upsert(spec) {
    let it = this.items.get(spec.id);
    if (it && it.spec.type !== spec.type) { this.remove(spec.id); it = null; }
    if (!it) it = this.create(spec);
    it.spec = JSON.parse(JSON.stringify(spec));
    this.apply(it);
    return it;
  }

  create(spec) {
    let light;
    const S = this.size;
    if (spec.type === 'point') light = new THREE.PointLight();
    else if (spec.type === 'spot') light = new THREE.SpotLight();
    else if (spec.type === 'directional') light = new THREE.DirectionalLight();
    else light = new THREE.RectAreaLight();
    light.name = spec.id;
    if (light.shadow) {
      light.castShadow = true;
      light.shadow.mapSize.set(1024, 1024);
      light.shadow.bias = -0.0005;
      light.shadow.normalBias = 0.002 * S;
      light.shadow.radius = 2;
      if (spec.type !== 'directional') {
        light.shadow.camera.near = 0.002 * S;
        light.shadow.camera.far = 4 * S;
        light.shadow.camera.updateProjectionMatrix(); // three updates it only when `distance` changes far
      }
    }
    this.group.add(light);
    let target = null;
    if (light.target) { target = light.target; this.group.add(target); }
    const gizmo = new THREE.Mesh(this.gizmoGeometry, new THREE.MeshBasicMaterial({ toneMapped: false }));
    gizmo.userData.lightId = spec.id;
    this.gizmos.add(gizmo);
    const it = { spec, light, target, shape: null, gizmo };
    this.items.set(spec.id, it);
    return it;
  }

  apply(it) {
    const { spec, light } = it;
    const color = linearColor(spec.color || [1, 1, 1]);
    light.color.copy(color);
    light.intensity = this.enabled ? (spec.intensity ?? 1) : 0;
    light.visible = this.enabled;
    const g = it.gizmo;
    const peak = Math.max(color.r, color.g, color.b, 1e-6);
    g.material.color.setRGB(color.r / peak, color.g / peak, color.b / peak, THREE.LinearSRGBColorSpace);
    if (spec.type === 'point' || spec.type === 'spot') {
      light.position.fromArray(spec.position);
      light.distance = spec.range || 0;
      light.decay = 2;
    }
    if (spec.type === 'spot') {
      const outer = spec.outerConeAngle ?? Math.PI / 4;
      const inner = spec.innerConeAngle ?? 0;
      light.angle = Math.max(outer, 1e-4);
      light.penumbra = THREE.MathUtils.clamp(1 - inner / light.angle, 0, 1);
      it.target.position.fromArray(spec.position).add(new THREE.Vector3().fromArray(spec.direction).normalize());
    }
    if (spec.type === 'directional') this.fitSun(it);
    if (spec.type === 'area') this.applyArea(it);
    g.position.copy(spec.type === 'directional' ? light.position : new THREE.Vector3().fromArray(spec.position));
    for (const o of [light, it.target, it.shape, g]) if (o) o.updateMatrixWorld(true);
  }

  fitSun(it) {
    const d = new THREE.Vector3().fromArray(it.spec.direction).normalize();
    const r = this.size / 2;
    it.light.position.copy(this.center).addScaledVector(d, -2 * r);
    it.target.position.copy(this.center);
    const cam = it.light.shadow.camera;
    cam.left = cam.bottom = -r;
    cam.right = cam.top = r;
    cam.near = 0.01 * r;
    cam.far = 4 * r;
    cam.updateProjectionMatrix();
  }

  applyArea(it) {
    const { spec, light } = it;
    const disc = spec.shape === 'disc';
    const size = spec.size || (disc ? [0.5] : [1, 1]);
    const w = disc ? size[0] * Math.sqrt(Math.PI) : size[0];
    const h = disc ? w : (size[1] ?? size[0]);
    light.width = w;
    light.height = h;
    const { d, t } = basis(spec.direction, spec.tangent);
    // RectAreaLight emits toward its local -z; x is the width (tangent) direction.
    const zl = d.clone().negate();
    light.quaternion.setFromRotationMatrix(new THREE.Matrix4().makeBasis(t, new THREE.Vector3().crossVectors(zl, t), zl));
    light.position.fromArray(spec.position);
    const key = `${spec.shape || 'quad'}:${size.join(',')}`;
    if (!it.shape || it.shapeKey !== key) {
      if (it.shape) { this.group.remove(it.shape); it.shape.geometry.dispose(); it.shape.material.dispose(); }
      const geom = disc ? new THREE.CircleGeometry(size[0], 48) : new THREE.PlaneGeometry(w, h);
      it.shape = new THREE.Mesh(geom, new THREE.MeshBasicMaterial());
      it.shapeKey = key;
      this.group.add(it.shape);
    }
    // The shape's front (+z of the geometry) faces the way its light travels; its radiance is
    // the light's, in nits.
    it.shape.quaternion.setFromRotationMatrix(new THREE.Matrix4().makeBasis(t, new THREE.Vector3().crossVectors(d, t), d));
    it.shape.position.copy(light.position).addScaledVector(d, 1e-4 * this.size);
    const I = this.enabled ? (spec.intensity ?? 1) : 0;
    it.shape.material.color.copy(light.color).multiplyScalar(I);
  }

  /** Direct light on or off (modes "indirect" and "texels" switch it off). */
  setEnabled(on) {
    this.enabled = on;
    for (const it of this.items.values()) this.apply(it);
  }

  setGizmosVisible(on) {
    this.gizmos.visible = on;
  }

  /** The light a gizmo belongs to (raycast hit object) or null. */
  idOf(object) {
    return object && object.userData ? object.userData.lightId ?? null : null;
  }

  get(id) {
    return this.items.get(id) || null;
  }
}
