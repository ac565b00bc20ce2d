/* A thin C interface to Embree 3 for raypack's cross-check tests and benchmarks.
 *
 * One RpEmbree owns one device and one scene holding one triangle mesh (geometry id 0), so
 * the device's memory monitor measures exactly that scene's acceleration structure.
 * Rays and hits are exchanged as arrays of plain structs laid out like raypack's `Ray`
 * and `Hit` (src/embree.rs asserts the layouts at compile time); the packet calls gather
 * consecutive rays into Embree's SoA packets, masking the lanes past the end of the array.
 */
#ifndef RAYPACK_EMBREE_SHIM_H
#define RAYPACK_EMBREE_SHIM_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A ray `org + t dir` over (tnear, tfar], as raypack's `Ray`. */
typedef struct RpRay {
  float org[3];
  float dir[3];
  float tnear;
  float tfar;
} RpRay;

/* A closest hit, as raypack's `Hit`: prim == 0xFFFFFFFF and t == +inf for a miss. */
typedef struct RpHit {
  float t;
  float u;
  float v;
  uint32_t prim;
} RpHit;

/* Embree's build qualities. */
enum RpQuality { RP_QUALITY_LOW = 0, RP_QUALITY_MEDIUM = 1, RP_QUALITY_HIGH = 2 };

/* Scene flags (bit set). */
enum RpSceneFlags {
  /* RTC_SCENE_FLAG_ROBUST: conservative traversal and the watertight triangle test. */
  RP_SCENE_ROBUST = 1,
  /* RTC_SCENE_FLAG_COMPACT: Embree's smallest tree (compressed leaves), a little slower. */
  RP_SCENE_COMPACT = 2
};

typedef struct RpEmbree RpEmbree;

/* Creates a device and a scene holding one triangle mesh: `positions` holds x, y, z of
 * `num_vertices` vertices, `indices` three vertex indices per triangle. Copies both (into
 * Embree-allocated, padded buffers). `threads` > 0 limits the device's worker threads (its
 * builds and any internal parallelism) to that many; 0 uses all hardware threads. `max_isa`
 * (NULL or "" for none) caps the kernels Embree picks (its `max_isa=` device option: "sse2",
 * "sse4.2", "avx", "avx2", "avx512"). Returns NULL on failure and, when `error` is not NULL,
 * writes a static message there. */
RpEmbree* rp_embree_new(const float* positions, size_t num_vertices, const uint32_t* indices,
                        size_t num_triangles, int quality, int flags, int threads,
                        const char* max_isa, const char** error);

/* Builds the BVH. Returns 0 on success, or an Embree error code (see rp_embree_error). */
int rp_embree_commit(RpEmbree* e);

/* Bytes Embree allocated during rp_embree_commit and still holds (the BVH and its
 * triangle leaves), measured with rtcSetDeviceMemoryMonitorFunction. */
int64_t rp_embree_bvh_bytes(const RpEmbree* e);

/* Last error of the device as a static string, or NULL. */
const char* rp_embree_error(RpEmbree* e);

/* Embree's version as major * 10000 + minor * 100 + patch (e.g. 31305). */
int rp_embree_version(const RpEmbree* e);

/* 1 when the library was built with native 8- / 16-wide packet support. */
int rp_embree_native_packet(const RpEmbree* e, int width);

/* Closest hits of `n` rays with rtcIntersect1 / 8 / 16. `coherent` sets
 * RTC_INTERSECT_CONTEXT_FLAG_COHERENT in the intersect context. */
void rp_embree_intersect1(const RpEmbree* e, const RpRay* rays, RpHit* hits, size_t n, int coherent);
void rp_embree_intersect8(const RpEmbree* e, const RpRay* rays, RpHit* hits, size_t n, int coherent);
void rp_embree_intersect16(const RpEmbree* e, const RpRay* rays, RpHit* hits, size_t n, int coherent);

/* Occlusion of `n` rays over (tnear, tfar] with rtcOccluded1 / 8 / 16: out[i] = 1 when
 * ray i is blocked, 0 otherwise. */
void rp_embree_occluded1(const RpEmbree* e, const RpRay* rays, uint8_t* out, size_t n, int coherent);
void rp_embree_occluded8(const RpEmbree* e, const RpRay* rays, uint8_t* out, size_t n, int coherent);
void rp_embree_occluded16(const RpEmbree* e, const RpRay* rays, uint8_t* out, size_t n, int coherent);

/* Releases the scene and the device. NULL is ignored. */
void rp_embree_release(RpEmbree* e);

#ifdef __cplusplus
}
#endif

#endif
