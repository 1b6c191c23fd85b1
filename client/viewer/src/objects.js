// Dynamic objects: instances of /assets/NAME.glb (asset-local mesh, vertex-colour albedo)
// placed with the state's TRS, lit by the three.js lights and by their own irradiance SH from
// the objects stream (a per-material uniform: three's LightProbe is one for the whole scene).
import * as THREE from 'three';
import { loadGlb } from './scene.js';
import { objectMaterial, setObjectSH } from './shading.js';

export class ObjectSet {
  constructor(scene, assetPaths, onLoaded) {
    this.group = new THREE.Group();
    this.group.name = 'objects';
    scene.add(this.group);
    this.paths = assetPaths || {};
    this.assets = new Map(); // name -> Promise<BufferGeometry[]>
    this.items = new Map(); // id -> {spec, root, materials}
    this.sh = new Map();
    this.shGain = 1;
    this.onLoaded = onLoaded;
  }

  assetNames() {
    return Object.keys(this.paths);
  }

  geometry(name) {
    if (!this.assets.has(name)) {
      const url = this.paths[name] || `/assets/${encodeURIComponent(name)}.glb`;
      this.assets.set(name, loadGlb(url).then(async (gltf) => {
        const out = [];
        gltf.scene.updateMatrixWorld(true);
        gltf.scene.traverse((o) => { if (o.isMesh) out.push([o, o.geometry.clone().applyMatrix4(o.matrixWorld)]); });
        // LightSkin sparse points (PROTOCOL §8.7: accessors named in the mesh's extras.lucent),
        // asset-local like the geometry: geometry.userData.sparsePoints, 3 floats per point
        for (const [o, g] of out) {
          const acc = o.userData.lucent && o.userData.lucent.sparse_point_accessors;
          if (!acc || !Number.isInteger(acc.position)) continue;
          const a = await gltf.parser.getDependency('accessor', acc.position);
          const p = new Float32Array(3 * a.count), v = new THREE.Vector3();
          for (let i = 0; i < a.count; i++) v.fromBufferAttribute(a, i).applyMatrix4(o.matrixWorld).toArray(p, 3 * i);
          g.userData.sparsePoints = p;
        }
        return out.map(([, g]) => g);
      }));
    }
    return this.assets.get(name);
  }

  sync(objects, skip) {
    const seen = new Set();
    for (const spec of objects) {
      seen.add(spec.id);
      if (spec.id !== skip) this.upsert(spec);
    }
    for (const id of [...this.items.keys()]) if (!seen.has(id) && id !== skip) this.remove(id);
  }

  upsert(spec) {
    let it = this.items.get(spec.id);
    if (it && it.spec.asset !== spec.asset) { this.remove(spec.id); it = null; }
    if (!it) {
      const root = new THREE.Group();
      root.userData.objectId = spec.id;
      it = { spec, root, materials: [] };
      this.items.set(spec.id, it);
      this.group.add(root);
      this.geometry(spec.asset).then((geoms) => {
        if (this.items.get(spec.id) !== it) return;
        for (const g of geoms) {
          if (!g.attributes.color) g.setAttribute('color', new THREE.Float32BufferAttribute(new Float32Array(g.attributes.position.count * 3).fill(0.8), 3));
          const m = objectMaterial();
          m.userData.shGain.value = this.shGain;
          setObjectSH(m, this.sh.get(spec.id));
          const mesh = new THREE.Mesh(g, m);
          mesh.castShadow = mesh.receiveShadow = true;
          mesh.userData.objectId = spec.id;
          it.materials.push(m);
          root.add(mesh);
        }
        if (this.onLoaded) this.onLoaded();
      }).catch((e) => console.warn(`asset ${spec.asset}: ${e.message}`));
    }
    it.spec = JSON.parse(JSON.stringify(spec));
    this.applyTRS(it);
    return it;
  }

  applyTRS(it) {
    const s = it.spec;
    it.root.position.fromArray(s.translation || [0, 0, 0]);
    it.root.quaternion.fromArray(s.rotation || [0, 0, 0, 1]).normalize();
    it.root.scale.fromArray(s.scale || [1, 1, 1]);
    it.root.visible = s.visible !== false;
    it.root.updateMatrixWorld(true);
  }

  remove(id) {
    const it = this.items.get(id);
    if (!it) return;
    this.group.remove(it.root);
    for (const m of it.materials) m.dispose();
    this.items.delete(id);
  }

  /** The objects stream's copy: Map id -> Float32Array(27) irradiance SH. */
  setSH(byId) {
    this.sh = byId;
    for (const [id, it] of this.items) for (const m of it.materials) setObjectSH(m, byId.get(id));
  }

  /** 0 in "direct only" (no indirect light on objects), else 1. */
  setGain(g) {
    this.shGain = g;
    for (const it of this.items.values()) for (const m of it.materials) m.userData.shGain.value = g;
  }

  /** The object id a raycast hit belongs to, or null. */
  idOf(object) {
    for (let o = object; o; o = o.parent) if (o.userData && o.userData.objectId !== undefined) return o.userData.objectId;
    return null;
  }

  get(id) {
    return this.items.get(id) || null;
  }
}
