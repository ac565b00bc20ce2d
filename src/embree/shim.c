/* Embree 3 or 4 shim for raypack: see shim.h. Compiled by build.rs with cargo feature
 * `embree`, which defines RAYPACK_EMBREE_MAJOR (3 or 4) for the Embree it found. */
#include "shim.h"

#if RAYPACK_EMBREE_MAJOR == 4
#include <embree4/rtcore.h>
#elif RAYPACK_EMBREE_MAJOR == 3
#include <embree3/rtcore.h>
#else
#error "RAYPACK_EMBREE_MAJOR must be 3 or 4 (build.rs sets it)"
#endif
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct RpEmbree {
  RTCDevice device;
  RTCScene scene;
  /* Bytes the device holds now (memory monitor callback, called from build threads). */
  _Atomic int64_t bytes;
  /* Bytes held before and after the last commit. */
  int64_t bytes_before_commit;
  int64_t bytes_after_commit;
};

static bool rp_memory_monitor(void* user, ssize_t bytes, bool post) {
  (void)post;
  RpEmbree* e = (RpEmbree*)user;
  atomic_fetch_add_explicit(&e->bytes, (int64_t)bytes, memory_order_relaxed);
  return true; /* never refuse an allocation */
}

static const char* rp_error_string(enum RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE: return NULL;
    case RTC_ERROR_INVALID_ARGUMENT: return "Embree: invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "Embree: invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "Embree: out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "Embree: unsupported CPU";
    case RTC_ERROR_CANCELLED: return "Embree: cancelled";
    default: return "Embree: unknown error";
  }
}

RpEmbree* rp_embree_new(const float* positions, size_t num_vertices, const uint32_t* indices,
                        size_t num_triangles, int quality, int flags, int threads,
                        const char* max_isa, const char** error) {
  const char* dummy;
  if (!error) error = &dummy;
  *error = NULL;
  RpEmbree* e = (RpEmbree*)calloc(1, sizeof(RpEmbree));
  if (!e) {
    *error = "out of memory";
    return NULL;
  }
  atomic_init(&e->bytes, 0);
  /* threads = 0: Embree's default (all hardware threads); no max_isa: the CPU's best. */
  char config[128] = "";
  size_t used = 0;
  if (threads > 0) used += snprintf(config, sizeof config, "threads=%d,set_affinity=0", threads);
  if (max_isa && *max_isa && used < sizeof config)
    snprintf(config + used, sizeof config - used, "%smax_isa=%s", used ? "," : "", max_isa);
  e->device = rtcNewDevice(config);
  if (!e->device) {
    *error = rp_error_string(rtcGetDeviceError(NULL));
    if (!*error) *error = "Embree: rtcNewDevice failed";
    free(e);
    return NULL;
  }
  rtcSetDeviceMemoryMonitorFunction(e->device, rp_memory_monitor, e);

  e->scene = rtcNewScene(e->device);
  enum RTCSceneFlags scene_flags = RTC_SCENE_FLAG_NONE;
  if (flags & RP_SCENE_ROBUST) scene_flags |= RTC_SCENE_FLAG_ROBUST;
  if (flags & RP_SCENE_COMPACT) scene_flags |= RTC_SCENE_FLAG_COMPACT;
  rtcSetSceneFlags(e->scene, scene_flags);
  enum RTCBuildQuality q = quality <= RP_QUALITY_LOW      ? RTC_BUILD_QUALITY_LOW
                           : quality == RP_QUALITY_MEDIUM ? RTC_BUILD_QUALITY_MEDIUM
                                                          : RTC_BUILD_QUALITY_HIGH;
  rtcSetSceneBuildQuality(e->scene, q);

  RTCGeometry geom = rtcNewGeometry(e->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  /* Buffers allocated by Embree are padded so that its 16-byte loads of the last vertex
   * stay inside the allocation. */
  float* vb = (float*)rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                              3 * sizeof(float), num_vertices);
  uint32_t* ib = (uint32_t*)rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                    3 * sizeof(uint32_t), num_triangles);
  if ((num_vertices && !vb) || (num_triangles && !ib)) {
    *error = rp_error_string(rtcGetDeviceError(e->device));
    if (!*error) *error = "Embree: buffer allocation failed";
    rtcReleaseGeometry(geom);
    rp_embree_release(e);
    return NULL;
  }
  if (num_vertices) memcpy(vb, positions, num_vertices * 3 * sizeof(float));
  if (num_triangles) memcpy(ib, indices, num_triangles * 3 * sizeof(uint32_t));
  rtcSetGeometryBuildQuality(geom, q);
  rtcCommitGeometry(geom);
  rtcAttachGeometryByID(e->scene, geom, 0);
  rtcReleaseGeometry(geom);

  *error = rp_error_string(rtcGetDeviceError(e->device));
  if (*error) {
    rp_embree_release(e);
    return NULL;
  }
  return e;
}

int rp_embree_commit(RpEmbree* e) {
  e->bytes_before_commit = atomic_load(&e->bytes);
  rtcCommitScene(e->scene);
  e->bytes_after_commit = atomic_load(&e->bytes);
  return (int)rtcGetDeviceError(e->device);
}

int64_t rp_embree_bvh_bytes(const RpEmbree* e) { return e->bytes_after_commit - e->bytes_before_commit; }

const char* rp_embree_error(RpEmbree* e) { return rp_error_string(rtcGetDeviceError(e->device)); }

int rp_embree_version(const RpEmbree* e) {
  return (int)rtcGetDeviceProperty(e->device, RTC_DEVICE_PROPERTY_VERSION);
}

int rp_embree_native_packet(const RpEmbree* e, int width) {
  enum RTCDeviceProperty p = width == 16  ? RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED
                             : width == 8 ? RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED
                                          : RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED;
  return (int)rtcGetDeviceProperty(e->device, p);
}

void rp_embree_release(RpEmbree* e) {
  if (!e) return;
  if (e->scene) rtcReleaseScene(e->scene);
  if (e->device) rtcReleaseDevice(e->device);
  free(e);
}

/* A query's options: Embree 3's intersect context, or Embree 4's intersect and occluded
 * arguments (the same coherence hint, in the versions' own words). The RP_* macros call the
 * versions' functions, whose argument orders differ. */
#if RAYPACK_EMBREE_MAJOR == 4
typedef struct {
  struct RTCIntersectArguments intersect;
  struct RTCOccludedArguments occluded;
} RpQuery;

static inline void rp_query(RpQuery* q, int coherent) {
  rtcInitIntersectArguments(&q->intersect);
  rtcInitOccludedArguments(&q->occluded);
  q->intersect.flags = q->occluded.flags = coherent ? RTC_RAY_QUERY_FLAG_COHERENT : RTC_RAY_QUERY_FLAG_INCOHERENT;
}
#define RP_INTERSECT1(scene, q, rayhit) rtcIntersect1(scene, rayhit, &(q)->intersect)
#define RP_OCCLUDED1(scene, q, ray) rtcOccluded1(scene, ray, &(q)->occluded)
#define RP_INTERSECTK(K, valid, scene, q, rayhit) rtcIntersect##K(valid, scene, rayhit, &(q)->intersect)
#define RP_OCCLUDEDK(K, valid, scene, q, ray) rtcOccluded##K(valid, scene, ray, &(q)->occluded)
#else
typedef struct {
  struct RTCIntersectContext context;
} RpQuery;

static inline void rp_query(RpQuery* q, int coherent) {
  rtcInitIntersectContext(&q->context);
  q->context.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
}
#define RP_INTERSECT1(scene, q, rayhit) rtcIntersect1(scene, &(q)->context, rayhit)
#define RP_OCCLUDED1(scene, q, ray) rtcOccluded1(scene, &(q)->context, ray)
#define RP_INTERSECTK(K, valid, scene, q, rayhit) rtcIntersect##K(valid, scene, &(q)->context, rayhit)
#define RP_OCCLUDEDK(K, valid, scene, q, ray) rtcOccluded##K(valid, scene, &(q)->context, ray)
#endif

static inline void rp_load_ray1(struct RTCRay* r, const RpRay* s) {
  r->org_x = s->org[0];
  r->org_y = s->org[1];
  r->org_z = s->org[2];
  r->tnear = s->tnear;
  r->dir_x = s->dir[0];
  r->dir_y = s->dir[1];
  r->dir_z = s->dir[2];
  r->time = 0.0f;
  r->tfar = s->tfar;
  r->mask = 0xFFFFFFFFu;
  r->id = 0;
  r->flags = 0;
}

void rp_embree_intersect1(const RpEmbree* e, const RpRay* rays, RpHit* hits, size_t n, int coherent) {
  RpQuery q;
  rp_query(&q, coherent);
  for (size_t i = 0; i < n; i++) {
    struct RTCRayHit rh;
    rp_load_ray1(&rh.ray, &rays[i]);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    RP_INTERSECT1(e->scene, &q, &rh);
    if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
      hits[i] = (RpHit){rh.ray.tfar, rh.hit.u, rh.hit.v, rh.hit.primID};
    } else {
      hits[i] = (RpHit){INFINITY, 0.0f, 0.0f, 0xFFFFFFFFu};
    }
  }
}

void rp_embree_occluded1(const RpEmbree* e, const RpRay* rays, uint8_t* out, size_t n, int coherent) {
  RpQuery q;
  rp_query(&q, coherent);
  for (size_t i = 0; i < n; i++) {
    struct RTCRay r;
    rp_load_ray1(&r, &rays[i]);
    RP_OCCLUDED1(e->scene, &q, &r);
    out[i] = r.tfar == -INFINITY;
  }
}

/* Packet versions for K = 8 and 16: gather K consecutive rays into SoA, mask the lanes past
 * `n`, trace, scatter. */
#define RP_PACKET_FUNCS(K)                                                                          \
  static inline int rp_load_ray##K(struct RTCRay##K* r, int* valid, const RpRay* rays, size_t n) {  \
    int count = n < K ? (int)n : K;                                                                 \
    for (int l = 0; l < K; l++) {                                                                   \
      const RpRay* s = &rays[l < count ? l : 0];                                                    \
      valid[l] = l < count ? -1 : 0;                                                                \
      r->org_x[l] = s->org[0];                                                                      \
      r->org_y[l] = s->org[1];                                                                      \
      r->org_z[l] = s->org[2];                                                                      \
      r->tnear[l] = s->tnear;                                                                       \
      r->dir_x[l] = s->dir[0];                                                                      \
      r->dir_y[l] = s->dir[1];                                                                      \
      r->dir_z[l] = s->dir[2];                                                                      \
      r->time[l] = 0.0f;                                                                            \
      r->tfar[l] = s->tfar;                                                                         \
      r->mask[l] = 0xFFFFFFFFu;                                                                     \
      r->id[l] = (unsigned)l;                                                                       \
      r->flags[l] = 0;                                                                              \
    }                                                                                               \
    return count;                                                                                   \
  }                                                                                                 \
                                                                                                    \
  void rp_embree_intersect##K(const RpEmbree* e, const RpRay* rays, RpHit* hits, size_t n,         \
                              int coherent) {                                                       \
    RpQuery q;                                                                                      \
    rp_query(&q, coherent);                                                                         \
    for (size_t i = 0; i < n; i += K) {                                                             \
      struct RTCRayHit##K rh;                                                                       \
      int valid[K];                                                                                 \
      int count = rp_load_ray##K(&rh.ray, valid, rays + i, n - i);                                  \
      for (int l = 0; l < K; l++) {                                                                 \
        rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;                                                 \
        rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;                                              \
      }                                                                                             \
      RP_INTERSECTK(K, valid, e->scene, &q, &rh);                                                   \
      for (int l = 0; l < count; l++) {                                                             \
        if (rh.hit.geomID[l] != RTC_INVALID_GEOMETRY_ID) {                                          \
          hits[i + l] = (RpHit){rh.ray.tfar[l], rh.hit.u[l], rh.hit.v[l], rh.hit.primID[l]};        \
        } else {                                                                                    \
          hits[i + l] = (RpHit){INFINITY, 0.0f, 0.0f, 0xFFFFFFFFu};                                 \
        }                                                                                           \
      }                                                                                             \
    }                                                                                               \
  }                                                                                                 \
                                                                                                    \
  void rp_embree_occluded##K(const RpEmbree* e, const RpRay* rays, uint8_t* out, size_t n,         \
                             int coherent) {                                                        \
    RpQuery q;                                                                                      \
    rp_query(&q, coherent);                                                                         \
    for (size_t i = 0; i < n; i += K) {                                                             \
      struct RTCRay##K r;                                                                           \
      int valid[K];                                                                                 \
      int count = rp_load_ray##K(&r, valid, rays + i, n - i);                                       \
      RP_OCCLUDEDK(K, valid, e->scene, &q, &r);                                                     \
      for (int l = 0; l < count; l++) out[i + l] = r.tfar[l] == -INFINITY;                          \
    }                                                                                               \
  }

RP_PACKET_FUNCS(8)
RP_PACKET_FUNCS(16)
