// Vectorisable exp and sigmoids for float (a few ulp), exact libm calls for double.
//
// The float version uses only arithmetic, comparisons and a bit cast, so GCC vectorises loops
// that call it (`#pragma omp simd`); libm's expf is an opaque call that keeps such loops scalar.
// Accuracy: exp within 2 ulp on [-87, 0]; the soft silhouette multiplies ~20 such terms per
// pixel, far inside the 1e-5 agreement we test.
#pragma once

#include <cmath>
#include <cstdint>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

namespace zk {

// exp(x) for x <= 0 (x < -87 gives ~1e-38 instead of a denormal or 0).
inline float exp_nonpos(float x) {
  x = x < -87.0f ? -87.0f : x;
  const float n = std::floor(x * 1.44269504088896341f + 0.5f);
  float r = x - n * 0.693359375f;  // Cody-Waite: ln2 = 0.693359375 - 2.12194440e-4
  r = r + n * 2.12194440e-4f;
  // Cephes expf polynomial on |r| <= ln2 / 2.
  float p = 1.9875691500e-4f;
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  p = p * r * r + r + 1.0f;
  const int32_t bits = (static_cast<int32_t>(n) + 127) << 23;
  return p * __builtin_bit_cast(float, bits);
}
inline double exp_nonpos(double x) { return std::exp(x); }

// sigmoid(z) = 1 / (1 + exp(-z)), from exp(-|z|) so that nothing overflows.
template <typename T>
inline T sigmoid(T z) {
  const T e = exp_nonpos(-std::fabs(z));
  return (z >= T(0) ? T(1) : e) / (T(1) + e);
}

// sigmoid(-z) = 1 / (1 + exp(z)), from exp(-|z|) so that nothing overflows.
template <typename T>
inline T sigmoid_neg(T z) {
  const T e = exp_nonpos(-std::fabs(z));
  return (z >= T(0) ? e : T(1)) / (T(1) + e);
}

// Flush-to-zero and denormals-are-zero on this thread while in scope (x86's MXCSR; elsewhere a
// no-op), restored on exit so the caller's arithmetic is untouched. Products of a far pixel's
// tiny sigmoid and a small gradient fall below float's normal range, where x86 takes a slow
// microcode assist per operation; flushed to 0, each term changes by less than 1.2e-38 (float)
// or 2.3e-308 (double).
struct FlushDenormals {
#if defined(__SSE2__)
  unsigned int saved;
  FlushDenormals() : saved(_mm_getcsr()) { _mm_setcsr(saved | 0x8040u); }
  ~FlushDenormals() { _mm_setcsr(saved); }
  FlushDenormals(const FlushDenormals&) = delete;
  FlushDenormals& operator=(const FlushDenormals&) = delete;
#endif
};

}  // namespace zk
