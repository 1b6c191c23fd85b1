/* lcb_glb: the geometry of a bake as binary glTF 2.0, generated from the mapped .lcb alone,
 * so what a viewer loads is exactly what was baked (lucentd serves it as /scene.glb and
 * /assets/NAME.glb; lucent-bake writes OUT.glb with it). Pure functions of the file:
 * thread-safe, nothing cached. The caller frees *out with free().
 *
 * The scene: one mesh, one primitive per used material, each with its own compact vertex
 * subset (no primitive carries vertices it does not reference), under a node named
 * "lucent". Attributes: POSITION (with min/max), NORMAL (unit; a zero normal falls back to
 * the face's), TEXCOORD_1 = the lightmap UV (three.js reads lightMap from uv1, which
 * GLTFLoader fills from TEXCOORD_1) and TEXCOORD_0 = the same accessor, because glTF
 * requires indexed semantics to start at 0 (the .lcb holds no material UVs and no
 * textures). Indices UNSIGNED_INT. Materials: baseColorFactor = the base colour (linear;
 * for a textured material the mean albedo of its surfels, i.e. factor x texture, since
 * the file holds no images), metallic 0, roughness 1, emission in nits as emissiveFactor
 * (max channel 1) x KHR_materials_emissive_strength. asset.extras.lucent.bake_id =
 * lc_lcb_bake_id().
 *
 * An asset: its vertices in asset-local metres (POSITION, NORMAL, COLOR_0 = per-vertex
 * albedo, linear RGB float VEC3) and triangles, one material (baseColorFactor 1: the colour
 * is COLOR_0), one node named after the asset. With LightSkin sparse points (lcb ASPT/AVNN)
 * each vertex also carries its 8 nearest points and eq. 12 weights (PROTOCOL.md §8.7):
 * _LUCENT_SP_INDEX0/1 (VEC4 UNSIGNED_SHORT, indices among the asset's points) and
 * _LUCENT_SP_WEIGHT0/1 (VEC4 FLOAT, summing to 1), and the mesh's extras.lucent holds
 * {"sparse_points": N, "sparse_point_accessors": {"position", "normal", "radius"}}: accessors
 * of the points themselves (asset-local VEC3, VEC3, SCALAR float), used by no primitive.
 *
 * Outputs over the GLB format's 4 GiB limit are refused. */
#ifndef LC_LCB_GLB_H
#define LC_LCB_GLB_H
#include <stddef.h>
#include <stdint.h>

#include "lcb/lcb.h"

#define LC_LCB_BAKE_ID_LEN 32 /* bytes of lc_lcb_bake_id's buffer, the NUL included */

/* The static scene. Returns 0 with *out (malloc'd) and *len, or -1 with err set. */
int lc_lcb_scene_glb(const lc_lcb *f, unsigned char **out, size_t *len, char *err, size_t errlen);

/* Asset `asset` (an index into lc_lcb_get(f)->assets). Returns 0 with *out and *len, or -1
 * with err set (an index out of range is named). */
int lc_lcb_asset_glb(const lc_lcb *f, uint32_t asset, unsigned char **out, size_t *len, char *err, size_t errlen);

/* A stable identifier of the bake's content, 24 lowercase hex digits: "%08x%016llx" of the
 * section table's CRC-32 (the table holds every section's CRC, offset and size, so it changes
 * with any section's content; it equals the header's table_crc) and the file size the table
 * implies (its last section's end rounded up to the 64-byte alignment: the header's
 * file_size for every file lc_lcb_writer writes). "" for NULL. */
void lc_lcb_bake_id(const lc_lcb *f, char out[LC_LCB_BAKE_ID_LEN]);

#endif
