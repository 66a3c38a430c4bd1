// Per-face screen data (zooctl.render.windows.project_faces) on the CPU: gather the projected
// vertices of every face, and scatter the gradients back.
//
// xy (B, V, 2) pixel positions and z (B, V) depths of the vertices; faces (F, 3) int64 ->
// tri (B*F, 3, 2), depth (B*F, 3) and valid (B*F,) uint8 = all three depths > near and all six
// coordinates finite. Backward: grad_xy (B, V, 2), grad_z (B, V) (zeroed here); images in
// parallel, faces in order within an image (deterministic).
#include <cmath>
#include <cstdint>

#include "parallel.h"

namespace {

template <typename T>
void gather_faces(const T* xy, const T* z, const int64_t* faces, int64_t B, int64_t V, int64_t F, double near,
                  T* tri, T* depth, uint8_t* valid, int64_t threads) {
  const T nr = T(near);
  zk::parallel_for(B, threads, [&](int64_t b) {
    for (int64_t f = 0; f < F; ++f) {
      const int64_t n = b * F + f;
      bool ok = true;
      for (int k = 0; k < 3; ++k) {
        const int64_t v = b * V + faces[3 * f + k];
        const T x = xy[2 * v], y = xy[2 * v + 1], d = z[v];
        tri[6 * n + 2 * k] = x;
        tri[6 * n + 2 * k + 1] = y;
        depth[3 * n + k] = d;
        ok = ok && (d > nr) && std::isfinite(x) && std::isfinite(y);
      }
      valid[n] = ok ? 1 : 0;
    }
  });
}

template <typename T>
void gather_faces_backward(const T* g_tri, const T* g_depth, const int64_t* faces, int64_t B, int64_t V, int64_t F,
                           T* g_xy, T* g_z, int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    for (int64_t i = b * V; i < (b + 1) * V; ++i) g_xy[2 * i] = g_xy[2 * i + 1] = g_z[i] = T(0);
    for (int64_t f = 0; f < F; ++f) {
      const int64_t n = b * F + f;
      for (int k = 0; k < 3; ++k) {
        const int64_t v = b * V + faces[3 * f + k];
        g_xy[2 * v] += g_tri[6 * n + 2 * k];
        g_xy[2 * v + 1] += g_tri[6 * n + 2 * k + 1];
        g_z[v] += g_depth[3 * n + k];
      }
    }
  });
}

}  // namespace

extern "C" {

void zk_gather_faces_f32(const float* xy, const float* z, const int64_t* faces, int64_t B, int64_t V, int64_t F,
                         double near, float* tri, float* depth, uint8_t* valid, int64_t threads) {
  gather_faces<float>(xy, z, faces, B, V, F, near, tri, depth, valid, threads);
}
void zk_gather_faces_f64(const double* xy, const double* z, const int64_t* faces, int64_t B, int64_t V, int64_t F,
                         double near, double* tri, double* depth, uint8_t* valid, int64_t threads) {
  gather_faces<double>(xy, z, faces, B, V, F, near, tri, depth, valid, threads);
}
void zk_gather_faces_backward_f32(const float* g_tri, const float* g_depth, const int64_t* faces, int64_t B,
                                  int64_t V, int64_t F, float* g_xy, float* g_z, int64_t threads) {
  gather_faces_backward<float>(g_tri, g_depth, faces, B, V, F, g_xy, g_z, threads);
}
void zk_gather_faces_backward_f64(const double* g_tri, const double* g_depth, const int64_t* faces, int64_t B,
                                  int64_t V, int64_t F, double* g_xy, double* g_z, int64_t threads) {
  gather_faces_backward<double>(g_tri, g_depth, faces, B, V, F, g_xy, g_z, threads);
}

}  // extern "C"
