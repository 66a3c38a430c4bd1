// Pinhole projection (zooctl.render.camera.Camera.project and .to_camera) on the CPU, with its
// gradients: a handful of arithmetic per point, where PyTorch spends a small batched matmul, a
// division and their backward passes over (B, N, 3) temporaries.
//
// pts (B, N, 3) world points; R (B, 3, 3), t (B, 3) world -> camera; K (B, 4) = fx, fy, cx, cy.
//   to_camera: pc = R p + t                                   -> pc (B, N, 3)
//   project:   z = pc_z, zs = z unless |z| < 1e-12 (then 1e-12), xy = pc_xy / zs * f + c
//                                                             -> xy (B, N, 2), z (B, N)
// The arithmetic follows Camera's PyTorch expressions term by term (no fused multiply-add: the
// library is built with -ffp-contract=off). Backward: the gradients of every input (of the camera's
// rotation and translation only when pose_grads is set: zeros otherwise); the camera's sums over
// points accumulate in double. Images in parallel, points in order within an image
// (deterministic for any thread count).
#include <cmath>
#include <cstdint>

#include "parallel.h"

namespace {

template <typename T>
inline void transform(const T* R, const T* t, const T* p, T* pc) {
  for (int i = 0; i < 3; ++i) pc[i] = R[3 * i] * p[0] + R[3 * i + 1] * p[1] + R[3 * i + 2] * p[2] + t[i];
}

template <typename T>
inline T safe_depth(T z) {
  return std::fabs(z) < T(1e-12) ? T(1e-12) : z;
}

template <typename T>
void to_camera(const T* pts, const T* R, const T* t, int64_t B, int64_t N, T* out, int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    for (int64_t n = b * N; n < (b + 1) * N; ++n) transform(R + 9 * b, t + 3 * b, pts + 3 * n, out + 3 * n);
  });
}

template <typename T>
void project(const T* pts, const T* R, const T* t, const T* K, int64_t B, int64_t N, T* xy, T* z, int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    const T* k = K + 4 * b;
    for (int64_t n = b * N; n < (b + 1) * N; ++n) {
      T pc[3];
      transform(R + 9 * b, t + 3 * b, pts + 3 * n, pc);
      const T zs = safe_depth(pc[2]);
      xy[2 * n] = pc[0] / zs * k[0] + k[2];
      xy[2 * n + 1] = pc[1] / zs * k[1] + k[3];
      z[n] = pc[2];
    }
  });
}

// Given dL/dpc for one point: dL/dp = R^T dL/dpc, and the camera's sums dL/dR += dL/dpc p^T,
// dL/dt += dL/dpc.
template <typename T>
inline void transform_backward(const T* R, const T* p, const T* gpc, T* gp, double* gR, double* gt) {
  for (int c = 0; c < 3; ++c) gp[c] = R[c] * gpc[0] + R[3 + c] * gpc[1] + R[6 + c] * gpc[2];
  for (int i = 0; i < 3; ++i) {
    gt[i] += gpc[i];
    for (int c = 0; c < 3; ++c) gR[3 * i + c] += double(gpc[i]) * double(p[c]);
  }
}

template <typename T>
void to_camera_backward(const T* pts, const T* R, const T* g_pc, int64_t B, int64_t N, T* g_pts, T* g_R, T* g_t,
                        int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    double gR[9] = {0}, gt[3] = {0};
    for (int64_t n = b * N; n < (b + 1) * N; ++n) transform_backward(R + 9 * b, pts + 3 * n, g_pc + 3 * n, g_pts + 3 * n, gR, gt);
    for (int i = 0; i < 9; ++i) g_R[9 * b + i] = T(gR[i]);
    for (int i = 0; i < 3; ++i) g_t[3 * b + i] = T(gt[i]);
  });
}

template <typename T>
void project_backward(const T* pts, const T* R, const T* t, const T* K, const T* g_xy, const T* g_z, int64_t B,
                      int64_t N, int64_t pose_grads, T* g_pts, T* g_R, T* g_t, T* g_K, int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    const T* k = K + 4 * b;
    double gR[9] = {0}, gt[3] = {0}, gK[4] = {0};
    for (int64_t n = b * N; n < (b + 1) * N; ++n) {
      T pc[3];
      transform(R + 9 * b, t + 3 * b, pts + 3 * n, pc);
      const bool clamped = std::fabs(pc[2]) < T(1e-12);
      const T zs = clamped ? T(1e-12) : pc[2];
      const T gx = g_xy[2 * n], gy = g_xy[2 * n + 1];
      const T qx = pc[0] / zs, qy = pc[1] / zs;  // xy = q * f + c
      gK[0] += double(gx) * double(qx);
      gK[1] += double(gy) * double(qy);
      gK[2] += gx;
      gK[3] += gy;
      const T hx = gx * k[0], hy = gy * k[1];  // dL/dq
      T gpc[3] = {hx / zs, hy / zs, g_z[n]};
      if (!clamped) gpc[2] -= (hx * qx + hy * qy) / zs;
      if (pose_grads) {
        transform_backward(R + 9 * b, pts + 3 * n, gpc, g_pts + 3 * n, gR, gt);
      } else {  // the camera's rotation and translation are constants (a fit's camera)
        const T* r = R + 9 * b;
        for (int c = 0; c < 3; ++c) g_pts[3 * n + c] = r[c] * gpc[0] + r[3 + c] * gpc[1] + r[6 + c] * gpc[2];
      }
    }
    for (int i = 0; i < 9; ++i) g_R[9 * b + i] = T(gR[i]);
    for (int i = 0; i < 3; ++i) g_t[3 * b + i] = T(gt[i]);
    for (int i = 0; i < 4; ++i) g_K[4 * b + i] = T(gK[i]);
  });
}

}  // namespace

extern "C" {

#define ZK_PROJECT(T, S)                                                                                        \
  void zk_to_camera_forward_##S(const T* pts, const T* R, const T* t, int64_t B, int64_t N, T* out,           \
                                int64_t threads) {                                                              \
    to_camera<T>(pts, R, t, B, N, out, threads);                                                                \
  }                                                                                                             \
  void zk_to_camera_backward_##S(const T* pts, const T* R, const T* g_pc, int64_t B, int64_t N, T* g_pts,       \
                                 T* g_R, T* g_t, int64_t threads) {                                             \
    to_camera_backward<T>(pts, R, g_pc, B, N, g_pts, g_R, g_t, threads);                                        \
  }                                                                                                             \
  void zk_project_forward_##S(const T* pts, const T* R, const T* t, const T* K, int64_t B, int64_t N, T* xy,    \
                              T* z, int64_t threads) {                                                          \
    project<T>(pts, R, t, K, B, N, xy, z, threads);                                                             \
  }                                                                                                             \
  void zk_project_backward_##S(const T* pts, const T* R, const T* t, const T* K, const T* g_xy, const T* g_z,   \
                               int64_t B, int64_t N, int64_t pose_grads, T* g_pts, T* g_R, T* g_t, T* g_K,      \
                               int64_t threads) {                                                               \
    project_backward<T>(pts, R, t, K, g_xy, g_z, B, N, pose_grads, g_pts, g_R, g_t, g_K, threads);              \
  }

ZK_PROJECT(float, f32)
ZK_PROJECT(double, f64)

#undef ZK_PROJECT

}  // extern "C"
