// Area-weighted bilinear point splatting (zooctl.render.splat) on the CPU: forward and backward.
//
// Face n puts S samples p_s = sum_k bary[s, k] v_k - 0.5 (pixel-centre coordinates), each of mass
// area_n / S with area_n = |cross(v1 - v0, v2 - v0)| / 2 (0 for invalid faces), bilinearly into a
// canvas padded by one pixel on each side (Hp = H + 2, Wp = W + 2); positions are clamped to
// [-1, W] x [-1, H], so a zero-weight neighbour may fall outside the canvas and is skipped.
// Layouts: tri (N, 3, 2) with N = B * F, bary (S, 3), valid (N,) 0/1, canvas (B, Hp, Wp).
#include <cmath>
#include <algorithm>
#include <cstdint>
#include <vector>

#include "parallel.h"

namespace {

template <typename T>
struct Sample {
  int64_t x0, y0;  // top-left neighbour in canvas coordinates
  T fx, fy;        // bilinear fractions
  bool pass_x, pass_y;  // gradient passes the clamp
};

template <typename T>
inline Sample<T> locate(const T* v, const T* bk, int64_t H, int64_t W) {
  Sample<T> s;
  const T px = bk[0] * v[0] + bk[1] * v[2] + bk[2] * v[4] - T(0.5);
  const T py = bk[0] * v[1] + bk[1] * v[3] + bk[2] * v[5] - T(0.5);
  s.pass_x = px >= T(-1) && px <= T(W);
  s.pass_y = py >= T(-1) && py <= T(H);
  const T x = px < T(-1) ? T(-1) : (px > T(W) ? T(W) : px);
  const T y = py < T(-1) ? T(-1) : (py > T(H) ? T(H) : py);
  const T fx0 = std::floor(x), fy0 = std::floor(y);
  s.fx = x - fx0;
  s.fy = y - fy0;
  s.x0 = int64_t(fx0) + 1;
  s.y0 = int64_t(fy0) + 1;
  return s;
}

template <typename T>
inline T half_cross(const T* v) {
  return (v[2] - v[0]) * (v[5] - v[1]) - (v[3] - v[1]) * (v[4] - v[0]);
}

template <typename T>
void splat_forward(const T* tri, const T* bary, const T* valid, int64_t S, int64_t B, int64_t F, int64_t H,
                   int64_t W, T* canvas, int64_t threads) {
  const int64_t Hp = H + 2, Wp = W + 2;
  zk::parallel_for(B, threads, [&](int64_t b) {
    T* img = canvas + b * Hp * Wp;
    for (int64_t n = b * F; n < (b + 1) * F; ++n) {
      if (valid[n] == T(0)) continue;
      const T* v = tri + 6 * n;
      const T mass = T(0.5) * std::fabs(half_cross(v)) * valid[n] / T(S);
      for (int64_t k = 0; k < S; ++k) {
        const Sample<T> s = locate(v, bary + 3 * k, H, W);
        const T w[4] = {(1 - s.fx) * (1 - s.fy), s.fx * (1 - s.fy), (1 - s.fx) * s.fy, s.fx * s.fy};
        for (int j = 0; j < 4; ++j) {
          const int64_t yy = s.y0 + (j >> 1), xx = s.x0 + (j & 1);
          if (yy < Hp && xx < Wp) img[yy * Wp + xx] += mass * w[j];  // else w[j] == 0 (clamped)
        }
      }
    }
  });
}

template <typename T>
void splat_backward(const T* tri, const T* bary, const T* valid, const T* grad_canvas, int64_t S, int64_t B,
                    int64_t F, int64_t H, int64_t W, T* grad_tri, int64_t threads) {
  const int64_t Hp = H + 2, Wp = W + 2, N = B * F, chunk = 256;
  zk::parallel_for((N + chunk - 1) / chunk, threads, [&](int64_t task) {
    for (int64_t n = task * chunk; n < std::min(N, (task + 1) * chunk); ++n) {
      T* g = grad_tri + 6 * n;
      for (int i = 0; i < 6; ++i) g[i] = T(0);
      if (valid[n] == T(0)) continue;
      const T* v = tri + 6 * n;
      const T* img = grad_canvas + (n / F) * Hp * Wp;
      const T cross = half_cross(v);
      const T mass = T(0.5) * std::fabs(cross) * valid[n] / T(S);
      T gmass = 0;
      for (int64_t k = 0; k < S; ++k) {
        const T* bk = bary + 3 * k;
        const Sample<T> s = locate(v, bk, H, W);
        T G[4];
        for (int j = 0; j < 4; ++j) {
          const int64_t yy = s.y0 + (j >> 1), xx = s.x0 + (j & 1);
          G[j] = (yy < Hp && xx < Wp) ? img[yy * Wp + xx] : T(0);
        }
        gmass += G[0] * (1 - s.fx) * (1 - s.fy) + G[1] * s.fx * (1 - s.fy) + G[2] * (1 - s.fx) * s.fy +
                 G[3] * s.fx * s.fy;
        const T gx = s.pass_x ? mass * ((1 - s.fy) * (G[1] - G[0]) + s.fy * (G[3] - G[2])) : T(0);
        const T gy = s.pass_y ? mass * ((1 - s.fx) * (G[2] - G[0]) + s.fx * (G[3] - G[1])) : T(0);
        for (int i = 0; i < 3; ++i) {
          g[2 * i] += bk[i] * gx;
          g[2 * i + 1] += bk[i] * gy;
        }
      }
      // mass = |cross| valid / (2 S); d cross / d (e1, e2) with e1 = v1 - v0, e2 = v2 - v0.
      const T sgn = cross > 0 ? T(1) : (cross < 0 ? T(-1) : T(0));
      const T gc = gmass * T(0.5) * sgn * valid[n] / T(S);
      const T e1x = v[2] - v[0], e1y = v[3] - v[1], e2x = v[4] - v[0], e2y = v[5] - v[1];
      const T d1x = gc * e2y, d1y = -gc * e2x, d2x = -gc * e1y, d2y = gc * e1x;
      g[2] += d1x;
      g[3] += d1y;
      g[4] += d2x;
      g[5] += d2y;
      g[0] -= d1x + d2x;
      g[1] -= d1y + d2y;
    }
  });
}

// Separable blur of one image x (H, W) by a symmetric 1D kernel k (2r + 1,) with zero padding,
// out = K_y K_x x. Symmetric with zero padding, the blur is its own adjoint.
template <typename T>
void blur_image(const T* x, int64_t x_stride, const T* k, int64_t r, int64_t H, int64_t W, T* out) {
  std::vector<T> tmp(H * W), pad(W + 2 * r, T(0));
  for (int64_t y = 0; y < H; ++y) {
    std::copy(x + y * x_stride, x + y * x_stride + W, pad.begin() + r);  // zero padding on both sides
    T* trow = tmp.data() + y * W;
    for (int64_t xx = 0; xx < W; ++xx) trow[xx] = T(0);
    for (int64_t j = 0; j <= 2 * r; ++j) {
      const T kj = k[j];
      const T* src = pad.data() + j;
#pragma omp simd
      for (int64_t xx = 0; xx < W; ++xx) trow[xx] += kj * src[xx];
    }
  }
  for (int64_t y = 0; y < H; ++y) {
    T* orow = out + y * W;
    for (int64_t xx = 0; xx < W; ++xx) orow[xx] = T(0);
    const int64_t j0 = std::max<int64_t>(-r, -y), j1 = std::min<int64_t>(r, H - 1 - y);
    for (int64_t j = j0; j <= j1; ++j) {
      const T kj = k[j + r];
      const T* trow = tmp.data() + (y + j) * W;
#pragma omp simd
      for (int64_t xx = 0; xx < W; ++xx) orow[xx] += kj * trow[xx];
    }
  }
}

// Density canvas (B, Hp, Wp) -> e = exp(-gain * blur(interior)) (B, H, W); the silhouette is
// 1 - e (r < 0: no blur). Backward, as d(1 - e) / d dens = gain e: grad_canvas (B, Hp, Wp) =
// blur(gain e grad_sil) on the interior, zero on the padding ring.
template <typename T>
void splat_finish_forward(const T* canvas, const T* k, int64_t r, double gain, int64_t B, int64_t H, int64_t W,
                          T* e, int64_t threads) {
  const int64_t Hp = H + 2, Wp = W + 2;
  const T g = T(gain);
  zk::parallel_for(B, threads, [&](int64_t b) {
    const T* interior = canvas + b * Hp * Wp + Wp + 1;
    T* eb = e + b * H * W;
    if (r >= 0) {
      blur_image(interior, Wp, k, r, H, W, eb);
    } else {
      for (int64_t y = 0; y < H; ++y) std::copy(interior + y * Wp, interior + y * Wp + W, eb + y * W);
    }
    for (int64_t i = 0; i < H * W; ++i) eb[i] = std::exp(-g * eb[i]);
  });
}

template <typename T>
void splat_finish_backward(const T* e, const T* g_sil, const T* k, int64_t r, double gain, int64_t B, int64_t H,
                           int64_t W, T* g_canvas, int64_t threads) {
  const int64_t Hp = H + 2, Wp = W + 2;
  const T g = T(gain);
  zk::parallel_for(B, threads, [&](int64_t b) {
    std::vector<T> gd(H * W), gb(H * W);
    for (int64_t i = 0; i < H * W; ++i) gd[i] = g_sil[b * H * W + i] * e[b * H * W + i] * g;
    if (r >= 0) blur_image(gd.data(), W, k, r, H, W, gb.data());
    const T* src = r >= 0 ? gb.data() : gd.data();
    T* gc = g_canvas + b * Hp * Wp;
    std::fill(gc, gc + Hp * Wp, T(0));
    for (int64_t y = 0; y < H; ++y) std::copy(src + y * W, src + (y + 1) * W, gc + (y + 1) * Wp + 1);
  });
}

}  // namespace

extern "C" {

void zk_splat_forward_f32(const float* tri, const float* bary, const float* valid, int64_t S, int64_t B,
                          int64_t F, int64_t H, int64_t W, float* canvas, int64_t threads) {
  splat_forward<float>(tri, bary, valid, S, B, F, H, W, canvas, threads);
}
void zk_splat_forward_f64(const double* tri, const double* bary, const double* valid, int64_t S, int64_t B,
                          int64_t F, int64_t H, int64_t W, double* canvas, int64_t threads) {
  splat_forward<double>(tri, bary, valid, S, B, F, H, W, canvas, threads);
}
void zk_splat_backward_f32(const float* tri, const float* bary, const float* valid, const float* grad_canvas,
                           int64_t S, int64_t B, int64_t F, int64_t H, int64_t W, float* grad_tri,
                           int64_t threads) {
  splat_backward<float>(tri, bary, valid, grad_canvas, S, B, F, H, W, grad_tri, threads);
}
void zk_splat_backward_f64(const double* tri, const double* bary, const double* valid,
                           const double* grad_canvas, int64_t S, int64_t B, int64_t F, int64_t H, int64_t W,
                           double* grad_tri, int64_t threads) {
  splat_backward<double>(tri, bary, valid, grad_canvas, S, B, F, H, W, grad_tri, threads);
}
void zk_splat_finish_forward_f32(const float* canvas, const float* k, int64_t r, double gain, int64_t B,
                                 int64_t H, int64_t W, float* e, int64_t threads) {
  splat_finish_forward<float>(canvas, k, r, gain, B, H, W, e, threads);
}
void zk_splat_finish_forward_f64(const double* canvas, const double* k, int64_t r, double gain, int64_t B,
                                 int64_t H, int64_t W, double* e, int64_t threads) {
  splat_finish_forward<double>(canvas, k, r, gain, B, H, W, e, threads);
}
void zk_splat_finish_backward_f32(const float* e, const float* g_sil, const float* k, int64_t r, double gain,
                                  int64_t B, int64_t H, int64_t W, float* g_canvas, int64_t threads) {
  splat_finish_backward<float>(e, g_sil, k, r, gain, B, H, W, g_canvas, threads);
}
void zk_splat_finish_backward_f64(const double* e, const double* g_sil, const double* k, int64_t r, double gain,
                                  int64_t B, int64_t H, int64_t W, double* g_canvas, int64_t threads) {
  splat_finish_backward<double>(e, g_sil, k, r, gain, B, H, W, g_canvas, threads);
}

}  // extern "C"
