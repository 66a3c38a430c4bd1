// A face's screen window (inclusive pixel bounds), clipped to the image once more on the C++
// side, so that no window handed in from Python can make a kernel touch memory outside it.
#pragma once

#include <algorithm>
#include <cstdint>

namespace zk {

struct Window {
  int64_t x0, y0, x1, y1;
  bool empty() const { return x1 < x0 || y1 < y0; }
};

inline Window clip_window(const int32_t* w, int64_t H, int64_t W) {
  return {std::max<int64_t>(w[0], 0), std::max<int64_t>(w[1], 0), std::min<int64_t>(w[2], W - 1),
          std::min<int64_t>(w[3], H - 1)};
}

}  // namespace zk
