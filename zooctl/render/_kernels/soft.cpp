// SoftRas-style soft silhouette (zooctl.render.soft): forward and backward on the CPU.
//
// Same quantity as the pure-PyTorch path (`_edge_terms` and `_SoftCoverage` in soft.py), pixel by
// pixel inside each face's screen window, without materialising (face, pixel) pairs in memory:
//   e[p] = prod_f (1 - D_f(p)) = prod_f sigmoid(-delta_f(p) d_f(p)^2 / sigma),   sil = 1 - e
// (D_f = sigmoid(delta d^2 / sigma): the soft coverage of face f)
// d_f(p): distance from the pixel centre to the nearest edge of face f; delta = +1 inside.
// The PyTorch path sums logsigmoid terms and exponentiates; the product is the same number
// (to float rounding) without a log per pair. Values of e below 1e-30 are flushed to 0 (the
// silhouette is 1 to float precision either way; this keeps denormals out of the loop).
// The backward pass takes e and grad_sil and forms d loss / d acc = -grad_sil e itself; it runs
// with denormals flushed to zero (zk::FlushDenormals: each pair's term changes by < 1.2e-38).
// Each face's window is flattened into one vectorised loop (windows are ~8 px wide, too short
// to vectorise row by row). Layouts: tri (N, 3, 2) with N = B * F, windows (N, 4) int32 =
// x0, y0, x1, y1 inclusive (empty when x1 < x0), e and grad_sil (B, H, W), grad_tri (N, 3, 2).
#include <cmath>
#include <cstdint>
#include <vector>

#include "fastmath.h"
#include "parallel.h"
#include "window.h"

namespace {

template <typename T>
constexpr T kTiny = T(1e-30);

// Edge data of one triangle: start point a_k, edge vector e_k = v_{k+1} - v_k, 1 / |e_k|^2.
template <typename T>
struct Tri {
  T ax[3], ay[3], ex[3], ey[3], inv_ee[3];
  explicit Tri(const T* v) {
    for (int k = 0; k < 3; ++k) {
      const int j = (k + 1) % 3;
      ax[k] = v[2 * k];
      ay[k] = v[2 * k + 1];
      ex[k] = v[2 * j] - v[2 * k];
      ey[k] = v[2 * j + 1] - v[2 * k + 1];
      const T n = ex[k] * ex[k] + ey[k] * ey[k];
      inv_ee[k] = T(1) / (n < T(1e-20) ? T(1e-20) : n);
    }
  }
};

// Nearest-edge terms of one pixel: d2, the clamped parameter t, residual r = p - (a + t e), the
// nearest edge index (as T, so that every lane of a vector loop has one type), and the sign
// -delta (-1 inside, +1 outside). Branch-free, on scalars only, so that loops calling it
// vectorise (GCC gives up on the per-face arrays inside an `omp simd` body).
template <typename T>
struct Terms {
  T d2, t, rx, ry, edge, sign;
};

template <typename T>
struct Edge {
  T d2, t, rx, ry, cross;
};

template <typename T>
inline Edge<T> edge(T px, T py, T ax, T ay, T ex, T ey, T inv_ee) {
  const T relx = px - ax, rely = py - ay;
  T t = (relx * ex + rely * ey) * inv_ee;
  t = t < T(0) ? T(0) : t;
  t = t > T(1) ? T(1) : t;
  const T rx = relx - t * ex, ry = rely - t * ey;
  return {rx * rx + ry * ry, t, rx, ry, ex * rely - ey * relx};
}

template <typename T>
struct FaceConsts {  // the same numbers as Tri, as plain scalars
  T ax0, ay0, ex0, ey0, ie0, ax1, ay1, ex1, ey1, ie1, ax2, ay2, ex2, ey2, ie2;
  explicit FaceConsts(const Tri<T>& t)
      : ax0(t.ax[0]), ay0(t.ay[0]), ex0(t.ex[0]), ey0(t.ey[0]), ie0(t.inv_ee[0]),
        ax1(t.ax[1]), ay1(t.ay[1]), ex1(t.ex[1]), ey1(t.ey[1]), ie1(t.inv_ee[1]),
        ax2(t.ax[2]), ay2(t.ay[2]), ex2(t.ex[2]), ey2(t.ey[2]), ie2(t.inv_ee[2]) {}
};

template <typename T>
inline Terms<T> edge_terms(const FaceConsts<T>& c, T px, T py) {
  const Edge<T> a = edge(px, py, c.ax0, c.ay0, c.ex0, c.ey0, c.ie0);
  const Edge<T> b = edge(px, py, c.ax1, c.ay1, c.ex1, c.ey1, c.ie1);
  const Edge<T> d = edge(px, py, c.ax2, c.ay2, c.ex2, c.ey2, c.ie2);
  Terms<T> o;
  const bool b_nearer = b.d2 < a.d2;  // strict: the first minimum, as torch.min
  o.d2 = b_nearer ? b.d2 : a.d2;
  o.t = b_nearer ? b.t : a.t;
  o.rx = b_nearer ? b.rx : a.rx;
  o.ry = b_nearer ? b.ry : a.ry;
  o.edge = b_nearer ? T(1) : T(0);
  const bool d_nearer = d.d2 < o.d2;
  o.d2 = d_nearer ? d.d2 : o.d2;
  o.t = d_nearer ? d.t : o.t;
  o.rx = d_nearer ? d.rx : o.rx;
  o.ry = d_nearer ? d.ry : o.ry;
  o.edge = d_nearer ? T(2) : o.edge;
  const bool pos = (a.cross >= T(0)) & (b.cross >= T(0)) & (d.cross >= T(0));
  const bool neg = (a.cross <= T(0)) & (b.cross <= T(0)) & (d.cross <= T(0));
  const bool inside = (pos | neg) & (std::fabs(a.cross) + std::fabs(b.cross) + std::fabs(d.cross) > T(0));
  o.sign = inside ? T(-1) : T(1);
  return o;
}

// Pixel centres of a window (rows y0..y1, columns x0..x1), flattened row-major.
template <typename T>
int64_t fill_centres(int64_t x0, int64_t x1, int64_t y0, int64_t y1, std::vector<T>& px, std::vector<T>& py) {
  const int64_t w = x1 - x0 + 1, n = w * (y1 - y0 + 1);
  if (int64_t(px.size()) < n) px.resize(n), py.resize(n);
  for (int64_t y = y0, i = 0; y <= y1; ++y)
    for (int64_t x = x0; x <= x1; ++x, ++i) px[i] = T(x) + T(0.5), py[i] = T(y) + T(0.5);
  return n;
}

template <typename T>
void soft_forward(const T* tri, const int32_t* win, int64_t B, int64_t F, int64_t H, int64_t W, double sigma,
                  T* e, int64_t threads) {
  const T inv_s = T(1) / T(sigma);
  const int64_t bands = zk::bands_per_image(B, threads, H);
  const int64_t rows_per_band = (H + bands - 1) / bands;
  zk::parallel_for(B * bands, threads, [&](int64_t task) {
    const int64_t b = task / bands;
    const int64_t r0 = (task % bands) * rows_per_band, r1 = std::min(H, r0 + rows_per_band);
    T* img = e + b * H * W;  // running product of (1 - D_f)
    for (int64_t i = r0 * W; i < r1 * W; ++i) img[i] = T(1);
    std::vector<T> px, py, val;
    for (int64_t f = 0; f < F; ++f) {
      const int64_t n = b * F + f;
      const zk::Window w = zk::clip_window(win + 4 * n, H, W);
      const int64_t y0 = std::max<int64_t>(w.y0, r0), y1 = std::min<int64_t>(w.y1, r1 - 1);
      if (w.x1 < w.x0 || y1 < y0) continue;
      const FaceConsts<T> tr(Tri<T>(tri + 6 * n));
      const int64_t m = fill_centres<T>(w.x0, w.x1, y0, y1, px, py);
      if (int64_t(val.size()) < m) val.resize(m);
      const T* __restrict PX = px.data();
      const T* __restrict PY = py.data();
      T* __restrict V = val.data();
#pragma omp simd
      for (int64_t i = 0; i < m; ++i) {
        const Terms<T> t = edge_terms(tr, PX[i], PY[i]);
        V[i] = zk::sigmoid(t.sign * t.d2 * inv_s);  // 1 - D_f = exp(logsigmoid(z))
      }
      for (int64_t y = y0, i = 0; y <= y1; ++y) {
        T* row = img + y * W;
        for (int64_t x = w.x0; x <= w.x1; ++x, ++i) {
          const T p = row[x] * V[i];
          row[x] = p < kTiny<T> ? T(0) : p;  // 1 - silhouette below 1e-30: exactly covered (no denormals)
        }
      }
    }
  });
}

template <typename T>
void soft_backward(const T* tri, const int32_t* win, const T* e, const T* grad_sil, int64_t B, int64_t F, int64_t H,
                   int64_t W, double sigma, T* grad_tri, int64_t threads) {
  const T inv_s = T(1) / T(sigma);
  const int64_t N = B * F, chunk = 64;
  zk::parallel_for((N + chunk - 1) / chunk, threads, [&](int64_t task) {
    const zk::FlushDenormals ftz;  // per worker thread: see fastmath.h
    std::vector<T> px, py, go, kx, ky, tt, edge;
    for (int64_t n = task * chunk; n < std::min(N, (task + 1) * chunk); ++n) {
      T* out = grad_tri + 6 * n;
      for (int i = 0; i < 6; ++i) out[i] = T(0);
      const zk::Window w = zk::clip_window(win + 4 * n, H, W);
      if (w.empty()) continue;
      const FaceConsts<T> tr(Tri<T>(tri + 6 * n));
      const int64_t m = fill_centres<T>(w.x0, w.x1, w.y0, w.y1, px, py);
      if (int64_t(go.size()) < m) go.resize(m), kx.resize(m), ky.resize(m), tt.resize(m), edge.resize(m);
      const int64_t off = (n / F) * H * W;
      for (int64_t y = w.y0, i = 0; y <= w.y1; ++y)
        for (int64_t x = w.x0; x <= w.x1; ++x, ++i) go[i] = -grad_sil[off + y * W + x] * e[off + y * W + x];
      const T* __restrict PX = px.data();
      const T* __restrict PY = py.data();
      const T* __restrict GO = go.data();
      T* __restrict KX = kx.data();
      T* __restrict KY = ky.data();
      T* __restrict TT = tt.data();
      T* __restrict EDGE = edge.data();
      // Two passes: the per-pixel terms in a plain vector loop, then the sums over the window; one
      // loop with six reductions ran 1.7x slower on windows of ~12 pixels.
#pragma omp simd
      for (int64_t i = 0; i < m; ++i) {
        const Terms<T> e = edge_terms(tr, PX[i], PY[i]);
        const T z = e.sign * e.d2 * inv_s;
        // d logsigmoid(z) / d d2 = sigmoid(-z) (-delta) / sigma; d d2 / d a = -2 (1 - t) r, d b = -2 t r.
        const T k = GO[i] * zk::sigmoid_neg(z) * e.sign * inv_s * T(-2);
        KX[i] = k * e.rx, KY[i] = k * e.ry, TT[i] = e.t, EDGE[i] = e.edge;
      }
      T g0x = 0, g0y = 0, g1x = 0, g1y = 0, g2x = 0, g2y = 0;
      for (int64_t i = 0; i < m; ++i) {
        // Edge j runs from vertex j (weight 1 - t) to vertex j + 1 mod 3 (weight t).
        const T t = TT[i], u = T(1) - t;
        const bool e0 = EDGE[i] == T(0), e1 = EDGE[i] == T(1), e2 = EDGE[i] == T(2);
        const T w0 = e0 ? u : (e2 ? t : T(0));
        const T w1 = e1 ? u : (e0 ? t : T(0));
        const T w2 = e2 ? u : (e1 ? t : T(0));
        g0x += w0 * KX[i], g0y += w0 * KY[i];
        g1x += w1 * KX[i], g1y += w1 * KY[i];
        g2x += w2 * KX[i], g2y += w2 * KY[i];
      }
      out[0] = g0x, out[1] = g0y, out[2] = g1x, out[3] = g1y, out[4] = g2x, out[5] = g2y;
    }
  });
}

}  // namespace

extern "C" {

void zk_soft_forward_f32(const float* tri, const int32_t* win, int64_t B, int64_t F, int64_t H, int64_t W,
                         double sigma, float* e, int64_t threads) {
  soft_forward<float>(tri, win, B, F, H, W, sigma, e, threads);
}
void zk_soft_forward_f64(const double* tri, const int32_t* win, int64_t B, int64_t F, int64_t H, int64_t W,
                         double sigma, double* e, int64_t threads) {
  soft_forward<double>(tri, win, B, F, H, W, sigma, e, threads);
}
void zk_soft_backward_f32(const float* tri, const int32_t* win, const float* e, const float* grad_sil, int64_t B,
                          int64_t F, int64_t H, int64_t W, double sigma, float* grad_tri, int64_t threads) {
  soft_backward<float>(tri, win, e, grad_sil, B, F, H, W, sigma, grad_tri, threads);
}
void zk_soft_backward_f64(const double* tri, const int32_t* win, const double* e, const double* grad_sil,
                          int64_t B, int64_t F, int64_t H, int64_t W, double sigma, double* grad_tri,
                          int64_t threads) {
  soft_backward<double>(tri, win, e, grad_sil, B, F, H, W, sigma, grad_tri, threads);
}

}  // extern "C"
