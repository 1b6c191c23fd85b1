// SH grid probes drawn as spheres (each a white Lambertian sphere lit by its sample's
// irradiance SH: radiance E(n)/pi for the sphere's normal n).
import * as THREE from 'three';
import { SH_GLSL } from './shading.js';

const PER_ROW = 64; // samples per row of the SH texture (9 texels each)

export class ProbeGrid {
  constructor(scene, size) {
    this.scene = scene;
    this.size = size;
    this.mesh = null;
    this.texture = null;
    this.count = 0;
    this.visible = false;
  }

  /** The shgrid stream's copy: {dims, origin, cell, data: Float32Array(27 per sample)}. */
  update(grid) {
    const [nx, ny, nz] = grid.dims;
    const n = nx * ny * nz;
    if (!n) return;
    if (n !== this.count) this.rebuild(grid, n);
    const rows = Math.ceil(n / PER_ROW);
    const tex = this.texture;
    const d = tex.image.data;
    for (let i = 0; i < n; i++) {
      const base = (Math.floor(i / PER_ROW) * PER_ROW * 9 + (i % PER_ROW) * 9) * 4;
      for (let k = 0; k < 9; k++) {
        d[base + 4 * k] = grid.data[27 * i + 3 * k];
        d[base + 4 * k + 1] = grid.data[27 * i + 3 * k + 1];
        d[base + 4 * k + 2] = grid.data[27 * i + 3 * k + 2];
        d[base + 4 * k + 3] = 1;
      }
    }
    tex.needsUpdate = rows > 0;
  }

  rebuild(grid, n) {
    if (this.mesh) { this.scene.remove(this.mesh); this.mesh.geometry.dispose(); this.mesh.material.dispose(); this.texture.dispose(); }
    const rows = Math.ceil(n / PER_ROW);
    this.texture = new THREE.DataTexture(new Float32Array(PER_ROW * 9 * rows * 4), PER_ROW * 9, rows, THREE.RGBAFormat, THREE.FloatType);
    this.texture.minFilter = this.texture.magFilter = THREE.NearestFilter;
    this.texture.generateMipmaps = false;
    const cell = grid.cell;
    const mat = new THREE.ShaderMaterial({
      uniforms: { shTex: { value: this.texture } },
      vertexShader: /* glsl */ `
        uniform sampler2D shTex;
        varying vec3 vN;
        flat varying int vId;
        void main() {
          vId = gl_InstanceID;
          vN = normalize( mat3( modelMatrix ) * mat3( instanceMatrix ) * normal );
          gl_Position = projectionMatrix * viewMatrix * modelMatrix * instanceMatrix * vec4( position, 1.0 );
        }`,
      fragmentShader: /* glsl */ `
        uniform sampler2D shTex;
        varying vec3 vN;
        flat varying int vId;
        ${SH_GLSL}
        void main() {
          vec3 c[ 9 ];
          int row = vId / ${PER_ROW};
          int col = ( vId - row * ${PER_ROW} ) * 9;
          for ( int k = 0; k < 9; k++ ) c[ k ] = texelFetch( shTex, ivec2( col + k, row ), 0 ).rgb;
          vec3 E = max( lucentShIrradiance( c, normalize( vN ) ), vec3( 0.0 ) );
          gl_FragColor = vec4( E * 0.3183098862, 1.0 ); // E / pi
          #include <tonemapping_fragment>
          #include <colorspace_fragment>
        }`,
    });
    const geom = new THREE.SphereGeometry(0.18 * cell, 16, 12);
    const mesh = new THREE.InstancedMesh(geom, mat, n);
    const [nx, ny] = grid.dims;
    const m = new THREE.Matrix4();
    for (let i = 0; i < n; i++) {
      const x = i % nx, y = Math.floor(i / nx) % ny, z = Math.floor(i / (nx * ny));
      m.makeTranslation(grid.origin[0] + x * cell, grid.origin[1] + y * cell, grid.origin[2] + z * cell);
      mesh.setMatrixAt(i, m);
    }
    mesh.frustumCulled = false;
    mesh.visible = this.visible;
    this.mesh = mesh;
    this.count = n;
    this.scene.add(mesh);
  }

  setVisible(on) {
    this.visible = on;
    if (this.mesh) this.mesh.visible = on;
  }
}
