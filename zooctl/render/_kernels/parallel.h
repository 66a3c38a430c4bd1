// Minimal fork-join parallel loop over independent tasks (std::thread, no OpenMP runtime).
//
// PyTorch ships its own OpenMP runtime; a second one in the same process would spin its own
// pool on the same cores. Plain threads, sized by the caller from torch.get_num_threads(),
// avoid that. Each task writes only its own outputs, so results do not depend on the thread
// count or on which thread ran which task (bitwise deterministic).
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

namespace zk {

template <typename Fn>
void parallel_for(int64_t num_tasks, int64_t num_threads, Fn fn) {
  const int64_t workers = std::max<int64_t>(1, std::min(num_threads, num_tasks));
  if (workers <= 1) {
    for (int64_t i = 0; i < num_tasks; ++i) fn(i);
    return;
  }
  std::atomic<int64_t> next{0};
  auto run = [&]() {
    for (int64_t i = next.fetch_add(1); i < num_tasks; i = next.fetch_add(1)) fn(i);
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (int64_t w = 1; w < workers; ++w) pool.emplace_back(run);
  run();
  for (auto& t : pool) t.join();
}

// Row bands of an image: enough tasks to keep every thread busy even for a batch of one.
inline int64_t bands_per_image(int64_t batch, int64_t num_threads, int64_t height) {
  if (num_threads <= 1) return 1;
  int64_t bands = (2 * num_threads + batch - 1) / batch;
  return std::max<int64_t>(1, std::min(bands, height));
}

}  // namespace zk
