/* scene: the imported static scene in memory (geometry in metres, +Y up, materials, textures,
 * initial lights), as lucent-bake works on it. Owned by whoever called lc_scene_import();
 * released with lc_scene_release(). */
#ifndef LC_SCENE_H
#define LC_SCENE_H
#include <stddef.h>
#include <stdint.h>

#define LC_NAME_MAX 64
#define LC_NONE 0xFFFFFFFFu

typedef struct lc_texture {
    char path[512]; /* the file actually read (after case-insensitive resolution) */
    uint32_t width, height;
    float *rgb; /* linear RGB (sRGB-decoded), width*height*3, row 0 = top of the image */
} lc_texture;

typedef struct lc_material {
    char name[LC_NAME_MAX];
    float base_color[3];  /* linear factor (glTF baseColorFactor, MTL Kd) */
    int32_t base_texture; /* index into scene textures, -1 = none */
    float emission[3];    /* emitted radiance in nits (emissiveFactor x emissive_strength, MTL Ke) */
} lc_material;

typedef enum { LC_LIGHT_POINT = 0, LC_LIGHT_SPOT, LC_LIGHT_DIRECTIONAL, LC_LIGHT_AREA } lc_light_type;

/* Lights as KHR_lights_punctual (+ area quad/disc). Intensity: candela (point, spot),
 * lux (directional), nits (area). */
typedef struct lc_light {
    char name[LC_NAME_MAX];
    lc_light_type type;
    float color[3]; /* linear RGB, normalised so the intensity carries the magnitude */
    float intensity;
    float range; /* 0 = infinite */
    float position[3];
    float direction[3];           /* unit, the direction light travels (spot, directional, area normal) */
    float inner_cone, outer_cone; /* radians, spot */
    uint32_t area_shape;          /* 0 quad, 1 disc */
    float area_size[2];           /* quad width/height or disc radius in [0] (metres) */
} lc_light;

/* Indexed triangle mesh. All arrays malloc'd and owned by the mesh. */
typedef struct lc_mesh {
    uint32_t n_vertices, n_triangles;
    float *position;    /* 3 per vertex, metres, world space */
    float *normal;      /* 3 per vertex, unit shading normal */
    float *uv0;         /* 2 per vertex, material UV, OpenGL convention (v up: image row = (1-v)*H) */
    float *uv1;         /* 2 per vertex, lightmap UV in [0,1], glTF convention (v down), NULL until set */
    uint32_t *index;    /* 3 per triangle, counter-clockwise = front */
    uint32_t *material; /* 1 per triangle */
} lc_mesh;

typedef struct lc_scene {
    lc_mesh mesh;
    lc_material *materials;
    uint32_t n_materials;
    lc_texture *textures;
    uint32_t n_textures;
    lc_light *lights;
    uint32_t n_lights;
    float bounds_min[3], bounds_max[3];
    int has_lightmap_uv; /* the asset supplied a second UV set (mesh.uv1 filled by import) */
    char source[512];    /* path it was imported from */
    /* Import statistics, reported in the bake file's metadata. */
    uint32_t n_degenerate_dropped; /* zero-area / non-finite triangles removed at import */
} lc_scene;

typedef struct lc_import_params {
    double scale;     /* multiplies positions (e.g. 0.003 for the conference room) */
    int flip_winding; /* reverse triangle winding (assets with clockwise front faces) */
} lc_import_params;

/* Imports glTF 2.0 (.gltf/.glb), OBJ+MTL or PLY through Assimp, flattening the node tree
 * to world space (mirroring transforms flip the winding). Textures are read through
 * OpenImageIO; a texture whose exact file name is missing is resolved case-insensitively in
 * its directory; embedded glTF textures have path "*N". Degenerate and non-finite triangles
 * are dropped (counted). Fails with a message naming the file and the cause for: missing
 * file, unsupported format, no triangles, non-finite or non-positive scale. A missing or
 * unreadable texture is a warning: the material keeps its base colour factor.
 * On success returns 0 and fills *out (release with lc_scene_release). */
int lc_scene_import(const char *path, const lc_import_params *params, lc_scene *out, char *err, size_t errlen);
void lc_scene_release(lc_scene *scene);

/* Frees mesh arrays and zeroes the struct. */
void lc_mesh_release(lc_mesh *mesh);

/* Recomputes scene bounds from the mesh. */
void lc_scene_update_bounds(lc_scene *scene);

/* Material lookups at barycentric (b1, b2) of triangle tri (point = (1-b1-b2) v0 + b1 v1 + b2 v2):
 * base colour (factor x bilinear texture sample at uv0, repeat wrap), emission. */
void lc_scene_albedo(const lc_scene *scene, uint32_t tri, float b1, float b2, float out[3]);
void lc_scene_emission(const lc_scene *scene, uint32_t tri, float out[3]);

/* Geometric quantities of triangle tri. */
double lc_mesh_triangle_area(const lc_mesh *mesh, uint32_t tri);
/* Unit geometric normal from the winding (v1-v0)x(v2-v0). */
void lc_mesh_triangle_normal(const lc_mesh *mesh, uint32_t tri, float out[3]);
/* Interpolated position / unit shading normal at barycentrics. */
void lc_mesh_interpolate(const lc_mesh *mesh, uint32_t tri, float b1, float b2, float pos[3], float nrm[3]);
double lc_mesh_total_area(const lc_mesh *mesh);

#endif
