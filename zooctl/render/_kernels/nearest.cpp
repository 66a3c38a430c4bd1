// The nearest of a set of 2-D points to each query (zooctl.fit.losses.contour_loss) on the CPU:
//   idx[b, s] = argmin_v |q[b, s] - p[b, v]|^2, the first minimum on ties (as torch.min),
// from the squared distance itself (no |p|^2 - 2 q.p expansion, which cancels in float32).
// q (B, S, 2), p (B, V, 2) -> idx (B, S) int64. A batch's points are copied once per task into
// x and y arrays padded to whole vectors with infinitely far points; each lane of a vector keeps its
// own first minimum, then the lanes are merged by (distance, index), so the lane count never
// changes the result. NaN points never win. Tasks are blocks
// of queries; each writes only its own outputs (deterministic).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "parallel.h"

namespace {

constexpr int64_t kBlock = 64;  // queries per task

// Lanes: one GCC/Clang vector of the machine's register width. A vector wider than the registers
// is lowered through memory (16 floats on an AVX2 machine: 30 times slower than 8).
#if defined(__AVX512F__)
constexpr int64_t kVectorBytes = 64;
#elif defined(__AVX__)
constexpr int64_t kVectorBytes = 32;
#else
constexpr int64_t kVectorBytes = 16;
#endif
template <typename T>
struct Lanes {
  static constexpr int64_t count = kVectorBytes / sizeof(T);
};
template <typename T>
struct LaneVec;
template <>
struct LaneVec<float> {
  typedef float type __attribute__((vector_size(kVectorBytes)));
};
template <>
struct LaneVec<double> {
  typedef double type __attribute__((vector_size(kVectorBytes)));
};

template <typename T>
void nearest_points(const T* q, const T* p, int64_t B, int64_t S, int64_t V, int64_t* idx, int64_t threads) {
  constexpr int64_t kLanes = Lanes<T>::count;
  const int64_t blocks = (S + kBlock - 1) / kBlock, Vp = (V + kLanes - 1) / kLanes * kLanes;
  zk::parallel_for(B * blocks, threads, [&](int64_t task) {
    const int64_t b = task / blocks, s0 = (task % blocks) * kBlock, s1 = std::min(S, s0 + kBlock);
    std::vector<T> xs(Vp, std::numeric_limits<T>::infinity()), ys(Vp, std::numeric_limits<T>::infinity());
    const T* pb = p + 2 * b * V;
    for (int64_t v = 0; v < V; ++v) xs[v] = pb[2 * v], ys[v] = pb[2 * v + 1];
    const T* __restrict X = xs.data();
    const T* __restrict Y = ys.data();
    using Vec = typename LaneVec<T>::type;
    Vec iota;
    for (int64_t l = 0; l < kLanes; ++l) iota[l] = T(l);
    for (int64_t s = s0; s < s1; ++s) {
      const T qx = q[2 * (b * S + s)], qy = q[2 * (b * S + s) + 1];
      // Each lane keeps its own first minimum (index as T: one vector type, exact below 2^24).
      Vec best = Vec{} + std::numeric_limits<T>::infinity(), at = Vec{} - T(1), pos = iota;
      for (int64_t v0 = 0; v0 < Vp; v0 += kLanes, pos += T(kLanes)) {
        Vec x, y;
        std::memcpy(&x, X + v0, sizeof(Vec));
        std::memcpy(&y, Y + v0, sizeof(Vec));
        const Vec dx = x - qx, dy = y - qy;
        const Vec d = dx * dx + dy * dy;
        const auto nearer = d < best;
        best = nearer ? d : best;
        at = nearer ? pos : at;
      }
      T d = std::numeric_limits<T>::infinity(), a = T(-1);
      for (int64_t l = 0; l < kLanes; ++l)
        if (at[l] >= T(0) && (a < T(0) || best[l] < d || (best[l] == d && at[l] < a))) d = best[l], a = at[l];
      idx[b * S + s] = a < T(0) ? 0 : int64_t(a);
    }
  });
}

}  // namespace

extern "C" {

void zk_nearest_points_f32(const float* q, const float* p, int64_t B, int64_t S, int64_t V, int64_t* idx,
                           int64_t threads) {
  nearest_points<float>(q, p, B, S, V, idx, threads);
}
void zk_nearest_points_f64(const double* q, const double* p, int64_t B, int64_t S, int64_t V, int64_t* idx,
                           int64_t threads) {
  nearest_points<double>(q, p, B, S, V, idx, threads);
}

}  // extern "C"
