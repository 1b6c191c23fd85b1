// The lightmap stream as a texture: RGB9_E5 words uploaded exactly as they arrive
// (THREE.RGBFormat + THREE.UnsignedInt5999Type -> GL internal format RGB9_E5, core in WebGL2
// and filterable), sampled on TEXCOORD_1 (texture.channel = 1, GLTFLoader's uv1).
// Orientation: row 0 of the image is v = 0 (PROTOCOL.md §2.4, the glTF convention) and three
// samples uv (u, v) at texture t = v, so rows are uploaded in order: flipY = false.
import * as THREE from 'three';

export class LightmapTexture {
  constructor() {
    this.texture = null;
    this.nearest = false;
    this.listeners = [];
  }

  /** Calls fn(texture) whenever a new texture object replaces the old one (size change). */
  onReplace(fn) {
    this.listeners.push(fn);
  }

  /** Uploads the client's copy of the lightmap ({width, height, encoding, data}). */
  update(lm) {
    if (lm.encoding && lm.encoding !== 'rgb9e5') throw new Error(`lightmap encoding ${lm.encoding}: the viewer subscribes rgb9e5`);
    const t = this.texture;
    if (!t || t.image.width !== lm.width || t.image.height !== lm.height) {
      const nt = new THREE.DataTexture(lm.data, lm.width, lm.height, THREE.RGBFormat, THREE.UnsignedInt5999Type);
      nt.flipY = false;
      nt.generateMipmaps = false;
      nt.channel = 1;
      nt.colorSpace = THREE.NoColorSpace;
      nt.wrapS = nt.wrapT = THREE.ClampToEdgeWrapping;
      this.texture = nt;
      this.setNearest(this.nearest);
      nt.needsUpdate = true;
      for (const fn of this.listeners) fn(nt);
      if (t) t.dispose();
      return;
    }
    t.image.data = lm.data;
    t.needsUpdate = true;
  }

  /** Nearest filtering shows the texels themselves (the "lightmap texels" mode). */
  setNearest(on) {
    this.nearest = on;
    const t = this.texture;
    if (!t) return;
    const f = on ? THREE.NearestFilter : THREE.LinearFilter;
    if (t.magFilter !== f) {
      t.magFilter = t.minFilter = f;
      t.needsUpdate = true;
    }
  }
}
