// The state's environment: the background shows its radiance (constant colour x intensity, or
// the radiance SH L2 evaluated per view direction), tone mapped like the rest of the frame.
// Sky light on surfaces: the lightmap holds the sky's light only after a bounce (the engine
// lights surfels with the sky through their visibility, not the lightmap texels themselves),
// and a viewer cannot know each texel's sky visibility. So by default static surfaces and
// objects get no direct sky light (right for interiors such as the Cornell box; outdoors,
// use a directional light for the sun). The "sky on surfaces" option adds the sky's
// irradiance unshadowed (a three.js LightProbe with the radiance SH) to every surface.
import * as THREE from 'three';

const Y00 = 0.282095;

/** The environment's radiance SH (27 floats, RGB interleaved), intensity applied. */
export function radianceSH(env) {
  const out = new Float32Array(27);
  if (!env || env.type === 'none') return out;
  const k = env.intensity ?? 1;
  if (env.type === 'constant') {
    const c = env.color || [1, 1, 1];
    for (let i = 0; i < 3; i++) out[i] = c[i] * k / Y00; // L = c0 * Y00
  } else if (env.sh) for (let i = 0; i < 27; i++) out[i] = env.sh[i] * k;
  return out;
}

export class Environment {
  constructor(scene, size) {
    this.scene = scene;
    this.coeffs = { value: Array.from({ length: 9 }, () => new THREE.Vector3()) };
    const mat = new THREE.ShaderMaterial({
      uniforms: { sky: this.coeffs },
      side: THREE.BackSide,
      depthWrite: false,
      depthTest: false,
      vertexShader: /* glsl */ `
        varying vec3 vDir;
        void main() {
          vDir = position;
          gl_Position = projectionMatrix * viewMatrix * modelMatrix * vec4( position, 1.0 );
        }`,
      fragmentShader: /* glsl */ `
        uniform vec3 sky[ 9 ];
        varying vec3 vDir;
        void main() {
          vec3 n = normalize( vDir );
          vec3 L = sky[ 0 ] * 0.282095
            + sky[ 1 ] * ( 0.488603 * n.y ) + sky[ 2 ] * ( 0.488603 * n.z ) + sky[ 3 ] * ( 0.488603 * n.x )
            + sky[ 4 ] * ( 1.092548 * n.x * n.y ) + sky[ 5 ] * ( 1.092548 * n.y * n.z )
            + sky[ 6 ] * ( 0.315392 * ( 3.0 * n.z * n.z - 1.0 ) ) + sky[ 7 ] * ( 1.092548 * n.x * n.z )
            + sky[ 8 ] * ( 0.546274 * ( n.x * n.x - n.y * n.y ) );
          gl_FragColor = vec4( max( L, vec3( 0.0 ) ), 1.0 );
          #include <tonemapping_fragment>
          #include <colorspace_fragment>
        }`,
    });
    this.dome = new THREE.Mesh(new THREE.SphereGeometry(1, 32, 16), mat);
    this.dome.scale.setScalar(size * 20);
    this.dome.frustumCulled = false;
    this.dome.renderOrder = -1;
    this.dome.visible = false;
    scene.add(this.dome);
    this.probe = new THREE.LightProbe();
    this.probe.intensity = 0;
    scene.add(this.probe);
    this.skyOnSurfaces = false;
    this.env = { type: 'none' };
  }

  set(env) {
    this.env = env || { type: 'none' };
    const sh = radianceSH(this.env);
    for (let i = 0; i < 9; i++) {
      this.coeffs.value[i].set(sh[3 * i], sh[3 * i + 1], sh[3 * i + 2]);
      this.probe.sh.coefficients[i].set(sh[3 * i], sh[3 * i + 1], sh[3 * i + 2]);
    }
    this.dome.visible = this.env.type !== 'none';
    this.probe.intensity = this.skyOnSurfaces && this.dome.visible ? 1 : 0;
  }

  setSkyOnSurfaces(on) {
    this.skyOnSurfaces = on;
    this.set(this.env);
  }

  /** The dome follows the camera (it is "at infinity"). */
  follow(camera) {
    this.dome.position.copy(camera.position);
    this.dome.updateMatrixWorld();
  }
}
