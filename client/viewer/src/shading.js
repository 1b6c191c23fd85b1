// The viewer's shading, in physical units. For every Lambertian surface:
//
//   L_out = L_emit + albedo / pi * (E_direct + E_indirect)
//
// L_emit: the material's emission in nits (emissive x emissiveIntensity). E_direct: irradiance
// (W/m^2) from the state's lights, computed here by three.js (point/spot in candela with
// decay 2, directional in lux, each shadowed by a shadow map; area lights in nits, unshadowed).
// E_indirect: the lightmap texel (indirect irradiance, which includes the light of emissive
// surfaces) on static surfaces; the object's irradiance SH (objects stream) on dynamic objects.
// three's MeshLambertMaterial is this BRDF exactly: lightMap texels are added to the indirect
// irradiance and multiplied by BRDF_Lambert = albedo / pi (lights_fragment_maps,
// lights_lambert_pars_fragment), punctual lights likewise. Two pieces are added to its shader
// here: area lights (three evaluates RectAreaLight only for MeshStandardMaterial) and the
// per-object irradiance SH (three's LightProbe is one for the whole scene).
import * as THREE from 'three';

// Irradiance of a rectangle of radiance `color` on a Lambertian receiver: the polygon's
// vector form factor with the horizon-clipped sphere approximation (as three's LTC code with
// the identity matrix, which is the clamped cosine), times albedo: albedo / pi * E.
const AREA_GLSL = /* glsl */ `
#if NUM_RECT_AREA_LIGHTS > 0
vec3 lucentEdgeFF( const in vec3 v1, const in vec3 v2 ) {
  float x = dot( v1, v2 );
  float y = abs( x );
  float a = 0.8543985 + ( 0.4965155 + 0.0145206 * y ) * y;
  float b = 3.4175940 + ( 4.1616724 + y ) * y;
  float v = a / b;
  float t = ( x > 0.0 ) ? v : 0.5 * inversesqrt( max( 1.0 - x * x, 1e-7 ) ) - v;
  return cross( v1, v2 ) * t;
}
void RE_Direct_RectArea_Lucent( const in RectAreaLight rectAreaLight, const in vec3 geometryPosition,
    const in vec3 geometryNormal, const in vec3 geometryViewDir, const in vec3 geometryClearcoatNormal,
    const in LambertMaterial material, inout ReflectedLight reflectedLight ) {
  vec3 P = geometryPosition;
  vec3 c0 = rectAreaLight.position + rectAreaLight.halfWidth - rectAreaLight.halfHeight;
  vec3 c1 = rectAreaLight.position - rectAreaLight.halfWidth - rectAreaLight.halfHeight;
  vec3 c2 = rectAreaLight.position - rectAreaLight.halfWidth + rectAreaLight.halfHeight;
  vec3 c3 = rectAreaLight.position + rectAreaLight.halfWidth + rectAreaLight.halfHeight;
  if ( dot( cross( c1 - c0, c3 - c0 ), P - c0 ) < 0.0 ) return;
  vec3 v0 = normalize( c0 - P ), v1 = normalize( c1 - P ), v2 = normalize( c2 - P ), v3 = normalize( c3 - P );
  vec3 F = lucentEdgeFF( v0, v1 ) + lucentEdgeFF( v1, v2 ) + lucentEdgeFF( v2, v3 ) + lucentEdgeFF( v3, v0 );
  float l = length( F );
  float ff = max( ( l * l - dot( F, geometryNormal ) ) / ( l + 1.0 ), 0.0 );
  reflectedLight.directDiffuse += rectAreaLight.color * material.diffuseColor * ff;
}
#define RE_Direct_RectArea RE_Direct_RectArea_Lucent
#endif
`;

// E(n) = sum_i c_i y_i(n): the irradiance SH of PROTOCOL.md §2.3 (already cosine-convolved).
export const SH_GLSL = /* glsl */ `
vec3 lucentShIrradiance( const in vec3 c[ 9 ], const in vec3 n ) {
  return c[ 0 ] * 0.282095
    + c[ 1 ] * ( 0.488603 * n.y ) + c[ 2 ] * ( 0.488603 * n.z ) + c[ 3 ] * ( 0.488603 * n.x )
    + c[ 4 ] * ( 1.092548 * n.x * n.y ) + c[ 5 ] * ( 1.092548 * n.y * n.z )
    + c[ 6 ] * ( 0.315392 * ( 3.0 * n.z * n.z - 1.0 ) ) + c[ 7 ] * ( 1.092548 * n.x * n.z )
    + c[ 8 ] * ( 0.546274 * ( n.x * n.x - n.y * n.y ) );
}
`;

// LightSkin's per-pixel diffuse term (PROTOCOL.md §8.7, the paper's interpolation): each vertex
// carries the weighted average of its 8 sparse points' records, I_d (attribute lucentMrI) and
// l_d (lucentMrL, world), set by mr.js; per pixel E = I_d cos(theta) / |x - l_d|^2 with x the
// world position, so that L = albedo / pi * E. Without the attributes (WebGL's default 0)
// or with lucentMrGain 0 it adds nothing.
const MR_VERTEX_PARS = /* glsl */ `
attribute vec3 lucentMrI;
attribute vec3 lucentMrL;
varying vec3 vLucentMrI;
varying vec3 vLucentMrL;
varying vec3 vLucentMrWorld;
`;
const MR_VERTEX = /* glsl */ `
vLucentMrI = lucentMrI;
vLucentMrL = lucentMrL;
vLucentMrWorld = ( modelMatrix * vec4( transformed, 1.0 ) ).xyz;
`;
const MR_FRAGMENT_PARS = /* glsl */ `
uniform float lucentMrGain;
varying vec3 vLucentMrI;
varying vec3 vLucentMrL;
varying vec3 vLucentMrWorld;
vec3 lucentMrIrradiance( const in vec3 n ) {
  vec3 d = vLucentMrL - vLucentMrWorld;
  float r2 = max( dot( d, d ), 1e-6 );
  return max( vLucentMrI, vec3( 0.0 ) ) * max( dot( n, d * inversesqrt( r2 ) ), 0.0 ) / r2;
}
`;

function patchArea(shader) {
  shader.fragmentShader = shader.fragmentShader.replace(
    '#include <lights_lambert_pars_fragment>', `#include <lights_lambert_pars_fragment>\n${AREA_GLSL}`);
}

/** A Lambertian material for static surfaces: albedo, emission (nits), the lightmap on uv1. */
export function staticMaterial({ color, emissive, emissiveIntensity, name }) {
  const m = new THREE.MeshLambertMaterial({ color, emissive, emissiveIntensity, name });
  m.onBeforeCompile = patchArea;
  m.customProgramCacheKey = () => 'lucent-static';
  return m;
}

/** A Lambertian material for a dynamic object: vertex-colour albedo, the state's lights, and
 *  its own irradiance SH (uniform lucentSH, set per object from the objects stream). */
export function objectMaterial() {
  const m = new THREE.MeshLambertMaterial({ vertexColors: true });
  const sh = { value: Array.from({ length: 9 }, () => new THREE.Vector3()) };
  const gain = { value: 1 };
  const mrGain = { value: 0 };
  m.userData.sh = sh;
  m.userData.shGain = gain;
  m.userData.mrGain = mrGain;
  m.onBeforeCompile = (shader) => {
    patchArea(shader);
    shader.uniforms.lucentSH = sh;
    shader.uniforms.lucentSHGain = gain;
    shader.uniforms.lucentMrGain = mrGain;
    shader.vertexShader = shader.vertexShader
      .replace('#include <common>', `#include <common>\n${MR_VERTEX_PARS}`)
      .replace('#include <project_vertex>', `#include <project_vertex>\n${MR_VERTEX}`);
    shader.fragmentShader = shader.fragmentShader
      .replace('#include <common>', `#include <common>\nuniform vec3 lucentSH[ 9 ];\nuniform float lucentSHGain;\n${SH_GLSL}\n${MR_FRAGMENT_PARS}`)
      .replace('#include <lights_fragment_maps>', `#include <lights_fragment_maps>
#if defined( RE_IndirectDiffuse )
  irradiance += lucentSHGain * max( lucentShIrradiance( lucentSH, inverseTransformDirection( geometryNormal, viewMatrix ) ), vec3( 0.0 ) );
  irradiance += lucentMrGain * lucentMrIrradiance( inverseTransformDirection( geometryNormal, viewMatrix ) );
#endif`);
  };
  m.customProgramCacheKey = () => 'lucent-object';
  return m;
}

/** Sets an object material's SH from 27 floats (RGB interleaved per coefficient). */
export function setObjectSH(material, coeffs) {
  const v = material.userData.sh.value;
  for (let i = 0; i < 9; i++) {
    if (coeffs) v[i].set(coeffs[3 * i], coeffs[3 * i + 1], coeffs[3 * i + 2]);
    else v[i].set(0, 0, 0);
  }
}
