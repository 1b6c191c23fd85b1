// The baked scene's geometry (/scene.glb: one primitive per material, POSITION, NORMAL,
// TEXCOORD_1 = lightmap UV; materials with baseColorFactor and emission in nits) as static
// Lambertian meshes, the per-mode materials, the scene bounds and a default view.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { staticMaterial } from './shading.js';
import { overlayMaterial } from './overlay.js';

export async function loadGlb(url) {
  return new GLTFLoader().loadAsync(url);
}

export class StaticScene {
  constructor(gltf) {
    this.group = new THREE.Group();
    this.group.name = 'static';
    this.entries = []; // {mesh, lambert, texels, name, hasUv1}
    this.overlay = overlayMaterial(); // heat map mode, shared (overlay.js)
    this.noUv = new THREE.MeshBasicMaterial({ color: 0x404040, toneMapped: false }); // heat map mode without TEXCOORD_1
    this.byName = new Map();
    const meshes = [];
    gltf.scene.updateMatrixWorld(true);
    gltf.scene.traverse((o) => { if (o.isMesh) meshes.push(o); });
    for (const src of meshes) {
      const g = src.geometry.clone().applyMatrix4(src.matrixWorld);
      const sm = src.material;
      const lambert = staticMaterial({ color: sm.color.clone(), emissive: sm.emissive.clone(),
        emissiveIntensity: sm.emissiveIntensity, name: sm.name });
      const mesh = new THREE.Mesh(g, lambert);
      mesh.castShadow = mesh.receiveShadow = true;
      mesh.name = sm.name;
      const texels = new THREE.MeshBasicMaterial({ color: new THREE.Color(1 / Math.PI, 1 / Math.PI, 1 / Math.PI) });
      const e = { mesh, lambert, texels, name: sm.name, hasUv1: !!g.attributes.uv1 };
      this.entries.push(e);
      if (!this.byName.has(sm.name)) this.byName.set(sm.name, []);
      this.byName.get(sm.name).push(e);
      this.group.add(mesh);
    }
    this.bounds = new THREE.Box3().setFromObject(this.group);
    this.size = this.bounds.getSize(new THREE.Vector3()).length() || 1;
  }

  /** Every surface gets the lightmap texture (on TEXCOORD_1). */
  setLightmap(tex) {
    for (const e of this.entries) {
      if (!e.hasUv1) continue;
      e.lambert.lightMap = tex;
      e.texels.map = tex;
      e.lambert.needsUpdate = e.texels.needsUpdate = true;
    }
  }

  /** The overlay of heat map mode (overlay.js): its texture (null: none, flat grey), whether
   *  it is one channel to colour by the scale, and the scale's max (a fraction, 1 = 100%). */
  setOverlay(tex, scalar = false, max = 1) {
    const m = this.overlay;
    if (m.map !== tex) {
      m.map = tex;
      m.color.set(tex ? 0xffffff : 0x404040);
      m.needsUpdate = true;
    }
    m.userData.scalar.value = scalar ? 1 : 0;
    m.userData.max.value = max;
  }

  /** The state's emission per material name (nits, linear RGB). */
  setEmission(materials) {
    for (const m of materials || []) {
      for (const e of this.byName.get(m.name) || []) {
        e.lambert.emissive.setRGB(m.emission[0], m.emission[1], m.emission[2]);
        e.lambert.emissiveIntensity = 1;
      }
    }
  }

  /** mode: full/probes (lit, lightmap), direct (no lightmap), indirect (lightmap; lights are
   *  switched off by the caller), texels (E/pi of the lightmap alone), heatmap (the overlay,
   *  unlit). */
  applyMode(mode) {
    for (const e of this.entries) {
      if (mode === 'texels') e.mesh.material = e.texels;
      else if (mode === 'heatmap') e.mesh.material = e.hasUv1 ? this.overlay : this.noUv;
      else {
        e.mesh.material = e.lambert;
        e.lambert.lightMapIntensity = mode === 'direct' ? 0 : 1;
      }
    }
  }

  /** A view of the whole scene: from outside its open side when one of the four vertical
   *  faces of the bounds is mostly uncovered (a Cornell box), else from inside, at the
   *  centre looking along the longest horizontal axis (an atrium such as Sponza). */
  defaultView(fov = 40) {
    const b = this.bounds;
    const c = b.getCenter(new THREE.Vector3());
    const s = b.getSize(new THREE.Vector3());
    const faces = [
      { axis: 'x', sign: -1, area: s.y * s.z, covered: 0 }, { axis: 'x', sign: 1, area: s.y * s.z, covered: 0 },
      { axis: 'z', sign: -1, area: s.x * s.y, covered: 0 }, { axis: 'z', sign: 1, area: s.x * s.y, covered: 0 },
    ];
    // A face is covered by triangles near its plane whose normal points into the box.
    const near = 0.05 * this.size;
    const a = new THREE.Vector3(), bb = new THREE.Vector3(), cc = new THREE.Vector3();
    const tri = new THREE.Triangle(), n = new THREE.Vector3(), mid = new THREE.Vector3();
    for (const e of this.entries) {
      const pos = e.mesh.geometry.attributes.position;
      const idx = e.mesh.geometry.index;
      const count = idx ? idx.count : pos.count;
      for (let i = 0; i + 2 < count; i += 3) {
        a.fromBufferAttribute(pos, idx ? idx.getX(i) : i);
        bb.fromBufferAttribute(pos, idx ? idx.getX(i + 1) : i + 1);
        cc.fromBufferAttribute(pos, idx ? idx.getX(i + 2) : i + 2);
        tri.set(a, bb, cc);
        tri.getNormal(n);
        tri.getMidpoint(mid);
        for (const f of faces) {
          const plane = f.sign < 0 ? b.min[f.axis] : b.max[f.axis];
          if (Math.abs(mid[f.axis] - plane) < near && -f.sign * n[f.axis] > 0.9) f.covered += tri.getArea();
        }
      }
    }
    faces.sort((p, q) => p.covered / p.area - q.covered / q.area);
    const open = faces[0];
    const t = Math.tan(THREE.MathUtils.degToRad(fov) / 2);
    if (open.covered < 0.5 * open.area) {
      const other = open.axis === 'x' ? 'z' : 'x';
      const half = Math.max(s.y / 2, (s[other] / 2) / 1.333);
      const eye = c.clone();
      eye[open.axis] = (open.sign < 0 ? b.min[open.axis] : b.max[open.axis]) + open.sign * (half / t) * 1.05;
      return { camera: eye.toArray(), target: c.toArray(), fov };
    }
    const eye = c.clone();
    eye.y = b.min.y + 0.25 * s.y;
    const target = eye.clone();
    if (s.x >= s.z) { eye.x = b.min.x + 0.2 * s.x; target.x = b.max.x; } else { eye.z = b.min.z + 0.2 * s.z; target.z = b.max.z; }
    target.y = b.min.y + 0.35 * s.y;
    return { camera: eye.toArray(), target: target.toArray(), fov: 60 };
  }
}
