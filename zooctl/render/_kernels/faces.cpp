// Per-face screen data (zooctl.render.windows.project_faces) on the CPU: gather the projected
// vertices of every face, and scatter the gradients back; each face's pixel window.
//
// xy (B, V, 2) pixel positions and z (B, V) depths of the vertices; faces (F, 3) int64 ->
// tri (B*F, 3, 2), depth (B*F, 3) and valid (B*F,) uint8 = all three depths > near and all six
// coordinates finite. Backward: grad_xy (B, V, 2), grad_z (B, V) (zeroed here); images in
// parallel, faces in order within an image (deterministic).
#include <algorithm>
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

// Each face's screen window (zooctl.render.windows.face_windows): the inclusive pixel bounds
// x0, y0, x1, y1 of its box grown by `margin`, clipped to the image, in the same float steps as
// the PyTorch expression ((min - margin) - 0.5, ceil, clamp); (0, 0, -1, -1) for invalid faces.
template <typename T>
void face_windows(const T* tri, const uint8_t* valid, int64_t n, int64_t H, int64_t W, double margin, int32_t* win,
                  int64_t threads) {
  const T m = T(margin), half = T(0.5), w = T(W), h = T(H);
  constexpr int64_t kChunk = 4096;
  zk::parallel_for((n + kChunk - 1) / kChunk, threads, [&](int64_t task) {
    for (int64_t i = task * kChunk; i < std::min(n, (task + 1) * kChunk); ++i) {
      int32_t* o = win + 4 * i;
      if (!valid[i]) {
        o[0] = o[1] = 0;
        o[2] = o[3] = -1;
        continue;
      }
      const T* t = tri + 6 * i;
      const T xmin = std::min(std::min(t[0], t[2]), t[4]), xmax = std::max(std::max(t[0], t[2]), t[4]);
      const T ymin = std::min(std::min(t[1], t[3]), t[5]), ymax = std::max(std::max(t[1], t[3]), t[5]);
      o[0] = int32_t(std::min(std::max(std::ceil((xmin - m) - half), T(0)), w));
      o[1] = int32_t(std::min(std::max(std::ceil((ymin - m) - half), T(0)), h));
      o[2] = int32_t(std::min(std::max(std::floor((xmax + m) - half), T(-1)), w - T(1)));
      o[3] = int32_t(std::min(std::max(std::floor((ymax + m) - half), T(-1)), h - T(1)));
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

void zk_face_windows_f32(const float* tri, const uint8_t* valid, int64_t n, int64_t H, int64_t W, double margin,
                         int32_t* win, int64_t threads) {
  face_windows<float>(tri, valid, n, H, W, margin, win, threads);
}
void zk_face_windows_f64(const double* tri, const uint8_t* valid, int64_t n, int64_t H, int64_t W, double margin,
                         int32_t* win, int64_t threads) {
  face_windows<double>(tri, valid, n, H, W, margin, win, threads);
}

}  // extern "C"
