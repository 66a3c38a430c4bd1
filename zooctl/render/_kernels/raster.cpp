// Hard z-buffer (zooctl.render.raster._zbuffer) on the CPU: the nearest face covering each pixel.
//
// Same arithmetic as the pure-PyTorch path, pixel by pixel inside each face's screen window:
// screen barycentrics from edge functions, inside iff all >= 0 and the face is not degenerate,
// perspective-correct depth z = 1 / sum(lambda_i / z_i); the smallest z wins and ties go to the
// higher face index. Layouts: tri (N, 3, 2), depth (N, 3) with N = B * F, windows (N, 4) int32
// inclusive pixel bounds (empty when x1 < x0); out winner (B, H, W) int64 index into N (-1: none)
// and zbuf (B, H, W) (+inf where none), face_ids (B, H, W) int64 index into F (-1: none).
#include <cmath>
#include <cstdint>
#include <limits>

#include "parallel.h"
#include "window.h"

namespace {

template <typename T>
void zbuffer(const T* tri, const T* depth, const int32_t* win, int64_t B, int64_t F, int64_t H, int64_t W,
             int64_t* winner, T* zbuf, int64_t* face_ids, int64_t threads) {
  const int64_t bands = zk::bands_per_image(B, threads, H);
  const int64_t rows_per_band = (H + bands - 1) / bands;
  zk::parallel_for(B * bands, threads, [&](int64_t task) {
    const int64_t b = task / bands;
    const int64_t r0 = (task % bands) * rows_per_band, r1 = std::min(H, r0 + rows_per_band);
    for (int64_t p = (b * H + r0) * W; p < (b * H + r1) * W; ++p) {
      winner[p] = -1;
      zbuf[p] = std::numeric_limits<T>::infinity();
    }
    for (int64_t f = 0; f < F; ++f) {  // ascending: "<=" hands ties to the higher index
      const int64_t n = b * F + f;
      const zk::Window w = zk::clip_window(win + 4 * n, H, W);
      const int64_t y0 = std::max<int64_t>(w.y0, r0), y1 = std::min<int64_t>(w.y1, r1 - 1);
      if (w.x1 < w.x0 || y1 < y0) continue;
      const T* v = tri + 6 * n;
      const T ax = v[0], ay = v[1], bx = v[2], by = v[3], cx = v[4], cy = v[5];
      const T area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
      if (!(std::fabs(area) > T(1e-12))) continue;
      const T safe = area;  // |area| > 1e-12 > 1e-20: no clamping needed
      const T z0 = depth[3 * n], z1 = depth[3 * n + 1], z2 = depth[3 * n + 2];
      for (int64_t y = y0; y <= y1; ++y) {
        const T py = T(y) + T(0.5);
        const int64_t rowp = (b * H + y) * W;
        for (int64_t x = w.x0; x <= w.x1; ++x) {
          const T px = T(x) + T(0.5);
          const T l0 = ((bx - px) * (cy - py) - (by - py) * (cx - px)) / safe;
          const T l1 = ((cx - px) * (ay - py) - (cy - py) * (ax - px)) / safe;
          const T l2 = ((ax - px) * (by - py) - (ay - py) * (bx - px)) / safe;
          if (!(l0 >= T(0) && l1 >= T(0) && l2 >= T(0))) continue;
          const T z = T(1) / ((l0 / z0 + l1 / z1) + l2 / z2);
          const int64_t p = rowp + x;
          if (z <= zbuf[p]) {
            zbuf[p] = z;
            winner[p] = n;
          }
        }
      }
    }
    for (int64_t p = (b * H + r0) * W; p < (b * H + r1) * W; ++p) face_ids[p] = winner[p] < 0 ? -1 : winner[p] - b * F;
  });
}

// Differentiable part of rasterisation for the winning faces (`rasterize` after the z-buffer):
// perspective-correct barycentrics and depth per pixel, and their gradients with respect to the
// projected vertices and their depths. winner (B*H*W,) int64 index into N or -1; bary (B*H*W, 3)
// and depth_img (B*H*W,) are zero on background. Backward writes grad_tri (N, 3, 2) and
// grad_depth (N, 3) (zeroed here); each face lies in one image, so images run in parallel.
template <typename T>
struct Frag {
  T w[3], area, inv[3], s;
};

template <typename T>
inline Frag<T> fragment(const T* v, const T* zd, T px, T py) {
  Frag<T> o;
  const T ax = v[0], ay = v[1], bx = v[2], by = v[3], cx = v[4], cy = v[5];
  o.area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
  o.w[0] = (bx - px) * (cy - py) - (by - py) * (cx - px);
  o.w[1] = (cx - px) * (ay - py) - (cy - py) * (ax - px);
  o.w[2] = (ax - px) * (by - py) - (ay - py) * (bx - px);
  const T safe = std::fabs(o.area) < T(1e-20) ? T(1e-20) : o.area;
  o.area = safe;
  for (int i = 0; i < 3; ++i) o.inv[i] = (o.w[i] / safe) / zd[i];
  o.s = (o.inv[0] + o.inv[1]) + o.inv[2];
  return o;
}

template <typename T>
void fragments_forward(const T* tri, const T* depth, const int64_t* winner, int64_t B, int64_t H, int64_t W,
                       T* bary, T* depth_img, int64_t threads) {
  const int64_t P = B * H * W, chunk = 4096;
  zk::parallel_for((P + chunk - 1) / chunk, threads, [&](int64_t task) {
    for (int64_t p = task * chunk; p < std::min(P, (task + 1) * chunk); ++p) {
      const int64_t n = winner[p];
      if (n < 0) {
        bary[3 * p] = bary[3 * p + 1] = bary[3 * p + 2] = depth_img[p] = T(0);
        continue;
      }
      const int64_t q = p % (H * W);
      const Frag<T> f = fragment(tri + 6 * n, depth + 3 * n, T(q % W) + T(0.5), T(q / W) + T(0.5));
      for (int i = 0; i < 3; ++i) bary[3 * p + i] = f.inv[i] / f.s;
      depth_img[p] = T(1) / f.s;
    }
  });
}

template <typename T>
void fragments_backward(const T* tri, const T* depth, const int64_t* winner, const T* g_bary, const T* g_depth,
                        int64_t B, int64_t F, int64_t H, int64_t W, T* grad_tri, T* grad_depth,
                        int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    for (int64_t n = b * F; n < (b + 1) * F; ++n) {
      for (int i = 0; i < 6; ++i) grad_tri[6 * n + i] = T(0);
      for (int i = 0; i < 3; ++i) grad_depth[3 * n + i] = T(0);
    }
    for (int64_t q = 0; q < H * W; ++q) {
      const int64_t p = b * H * W + q, n = winner[p];
      if (n < 0) continue;
      const T* v = tri + 6 * n;
      const T* zd = depth + 3 * n;
      const T px = T(q % W) + T(0.5), py = T(q / W) + T(0.5);
      const Frag<T> f = fragment(v, zd, px, py);
      // bary_i = inv_i / s, depth = 1 / s, inv_i = (w_i / A) / z_i, s = sum inv_i.
      const T s2 = f.s * f.s;
      T gs = -g_depth[p] / s2;
      for (int i = 0; i < 3; ++i) gs -= g_bary[3 * p + i] * f.inv[i] / s2;
      T gw[3], gA = 0;
      T* gz = grad_depth + 3 * n;
      for (int i = 0; i < 3; ++i) {
        const T ginv = g_bary[3 * p + i] / f.s + gs;
        const T lam = f.w[i] / f.area;
        const T glam = ginv / zd[i];
        gz[i] -= ginv * lam / (zd[i] * zd[i]);
        gw[i] = glam / f.area;
        gA -= glam * f.w[i] / (f.area * f.area);
      }
      const T ax = v[0], ay = v[1], bx = v[2], by = v[3], cx = v[4], cy = v[5];
      T* g = grad_tri + 6 * n;
      // Area A = (b - a) x (c - a).
      g[0] += gA * (by - cy), g[1] += gA * (cx - bx);
      g[2] += gA * (cy - ay), g[3] += gA * (ax - cx);
      g[4] += gA * (ay - by), g[5] += gA * (bx - ax);
      // w0 = (b - p) x (c - p), w1 = (c - p) x (a - p), w2 = (a - p) x (b - p).
      g[2] += gw[0] * (cy - py), g[3] -= gw[0] * (cx - px), g[4] -= gw[0] * (by - py), g[5] += gw[0] * (bx - px);
      g[4] += gw[1] * (ay - py), g[5] -= gw[1] * (ax - px), g[0] -= gw[1] * (cy - py), g[1] += gw[1] * (cx - px);
      g[0] += gw[2] * (by - py), g[1] -= gw[2] * (bx - px), g[2] -= gw[2] * (ay - py), g[3] += gw[2] * (ax - px);
    }
  });
}

// `interpolate`: out (B*H*W, C) = sum_i bary_i attributes[b, faces[fid, i]]; background reads
// face 0 (its bary is zero), as the PyTorch path does. attributes (B, V, C), faces (F, 3) int64,
// face_ids (B*H*W,) int64 into F or -1, bary (B*H*W, 3). Backward: grad_attr (B, V, C) (zeroed
// here) and grad_bary (B*H*W, 3); images in parallel.
template <typename T>
void interpolate_forward(const T* attr, const int64_t* faces, const int64_t* fid, const T* bary, int64_t B,
                         int64_t V, int64_t C, int64_t HW, T* out, int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    for (int64_t p = b * HW; p < (b + 1) * HW; ++p) {
      const int64_t f = fid[p] < 0 ? 0 : fid[p];
      const T* a0 = attr + (b * V + faces[3 * f]) * C;
      const T* a1 = attr + (b * V + faces[3 * f + 1]) * C;
      const T* a2 = attr + (b * V + faces[3 * f + 2]) * C;
      const T l0 = bary[3 * p], l1 = bary[3 * p + 1], l2 = bary[3 * p + 2];
      for (int64_t c = 0; c < C; ++c) out[p * C + c] = (l0 * a0[c] + l1 * a1[c]) + l2 * a2[c];
    }
  });
}

template <typename T>
void interpolate_backward(const T* attr, const int64_t* faces, const int64_t* fid, const T* bary, const T* g_out,
                          int64_t B, int64_t V, int64_t C, int64_t HW, T* g_attr, T* g_bary, int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    for (int64_t i = b * V * C; i < (b + 1) * V * C; ++i) g_attr[i] = T(0);
    for (int64_t p = b * HW; p < (b + 1) * HW; ++p) {
      const int64_t f = fid[p] < 0 ? 0 : fid[p];
      const T* g = g_out + p * C;
      for (int k = 0; k < 3; ++k) {
        const int64_t row = (b * V + faces[3 * f + k]) * C;
        const T l = bary[3 * p + k];
        T gb = 0;
        for (int64_t c = 0; c < C; ++c) {
          gb += g[c] * attr[row + c];
          g_attr[row + c] += l * g[c];
        }
        g_bary[3 * p + k] = gb;
      }
    }
  });
}

// RasterFlow's projection: pts (B*H*W, 3) camera-frame points at t+1, intrinsics (B, 4) =
// fx, fy, cx, cy -> flow (B*H*W, 2) = project(pts) - pixel centre where face_ids >= 0, else 0.
// Backward: grad_pts (B*H*W, 3) and grad_intr (B, 4) (both written here); images in parallel.
template <typename T>
void flow_project_forward(const T* pts, const T* intr, const int64_t* fid, int64_t B, int64_t H, int64_t W, T* flow,
                          int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    const T fx = intr[4 * b], fy = intr[4 * b + 1], cx = intr[4 * b + 2], cy = intr[4 * b + 3];
    for (int64_t q = 0; q < H * W; ++q) {
      const int64_t p = b * H * W + q;
      if (fid[p] < 0) {
        flow[2 * p] = flow[2 * p + 1] = T(0);
        continue;
      }
      const T* x = pts + 3 * p;
      flow[2 * p] = (x[0] / x[2] * fx + cx) - (T(q % W) + T(0.5));
      flow[2 * p + 1] = (x[1] / x[2] * fy + cy) - (T(q / W) + T(0.5));
    }
  });
}

template <typename T>
void flow_project_backward(const T* pts, const T* intr, const int64_t* fid, const T* g_flow, int64_t B, int64_t H,
                           int64_t W, T* g_pts, T* g_intr, int64_t threads) {
  zk::parallel_for(B, threads, [&](int64_t b) {
    const T fx = intr[4 * b], fy = intr[4 * b + 1];
    T gfx = 0, gfy = 0, gcx = 0, gcy = 0;
    for (int64_t p = b * H * W; p < (b + 1) * H * W; ++p) {
      T* g = g_pts + 3 * p;
      if (fid[p] < 0) {
        g[0] = g[1] = g[2] = T(0);
        continue;
      }
      const T* x = pts + 3 * p;
      const T gu = g_flow[2 * p], gv = g_flow[2 * p + 1];
      const T u = x[0] / x[2], v = x[1] / x[2];
      g[0] = gu * fx / x[2];
      g[1] = gv * fy / x[2];
      g[2] = -(gu * fx * u + gv * fy * v) / x[2];
      gfx += gu * u, gfy += gv * v, gcx += gu, gcy += gv;
    }
    g_intr[4 * b] = gfx, g_intr[4 * b + 1] = gfy, g_intr[4 * b + 2] = gcx, g_intr[4 * b + 3] = gcy;
  });
}

}  // namespace

extern "C" {

void zk_zbuffer_f32(const float* tri, const float* depth, const int32_t* win, int64_t B, int64_t F, int64_t H,
                    int64_t W, int64_t* winner, float* zbuf, int64_t* face_ids, int64_t threads) {
  zbuffer<float>(tri, depth, win, B, F, H, W, winner, zbuf, face_ids, threads);
}
void zk_zbuffer_f64(const double* tri, const double* depth, const int32_t* win, int64_t B, int64_t F, int64_t H,
                    int64_t W, int64_t* winner, double* zbuf, int64_t* face_ids, int64_t threads) {
  zbuffer<double>(tri, depth, win, B, F, H, W, winner, zbuf, face_ids, threads);
}


void zk_fragments_forward_f32(const float* tri, const float* depth, const int64_t* winner, int64_t B, int64_t H,
                              int64_t W, float* bary, float* depth_img, int64_t threads) {
  fragments_forward<float>(tri, depth, winner, B, H, W, bary, depth_img, threads);
}
void zk_fragments_forward_f64(const double* tri, const double* depth, const int64_t* winner, int64_t B,
                              int64_t H, int64_t W, double* bary, double* depth_img, int64_t threads) {
  fragments_forward<double>(tri, depth, winner, B, H, W, bary, depth_img, threads);
}
void zk_fragments_backward_f32(const float* tri, const float* depth, const int64_t* winner, const float* g_bary,
                               const float* g_depth, int64_t B, int64_t F, int64_t H, int64_t W, float* grad_tri,
                               float* grad_depth, int64_t threads) {
  fragments_backward<float>(tri, depth, winner, g_bary, g_depth, B, F, H, W, grad_tri, grad_depth, threads);
}
void zk_fragments_backward_f64(const double* tri, const double* depth, const int64_t* winner,
                               const double* g_bary, const double* g_depth, int64_t B, int64_t F, int64_t H,
                               int64_t W, double* grad_tri, double* grad_depth, int64_t threads) {
  fragments_backward<double>(tri, depth, winner, g_bary, g_depth, B, F, H, W, grad_tri, grad_depth, threads);
}
void zk_interpolate_forward_f32(const float* attr, const int64_t* faces, const int64_t* fid, const float* bary,
                                int64_t B, int64_t V, int64_t C, int64_t HW, float* out, int64_t threads) {
  interpolate_forward<float>(attr, faces, fid, bary, B, V, C, HW, out, threads);
}
void zk_interpolate_forward_f64(const double* attr, const int64_t* faces, const int64_t* fid, const double* bary,
                                int64_t B, int64_t V, int64_t C, int64_t HW, double* out, int64_t threads) {
  interpolate_forward<double>(attr, faces, fid, bary, B, V, C, HW, out, threads);
}
void zk_interpolate_backward_f32(const float* attr, const int64_t* faces, const int64_t* fid, const float* bary,
                                 const float* g_out, int64_t B, int64_t V, int64_t C, int64_t HW, float* g_attr,
                                 float* g_bary, int64_t threads) {
  interpolate_backward<float>(attr, faces, fid, bary, g_out, B, V, C, HW, g_attr, g_bary, threads);
}
void zk_interpolate_backward_f64(const double* attr, const int64_t* faces, const int64_t* fid,
                                 const double* bary, const double* g_out, int64_t B, int64_t V, int64_t C,
                                 int64_t HW, double* g_attr, double* g_bary, int64_t threads) {
  interpolate_backward<double>(attr, faces, fid, bary, g_out, B, V, C, HW, g_attr, g_bary, threads);
}
void zk_flow_project_forward_f32(const float* pts, const float* intr, const int64_t* fid, int64_t B, int64_t H,
                                 int64_t W, float* flow, int64_t threads) {
  flow_project_forward<float>(pts, intr, fid, B, H, W, flow, threads);
}
void zk_flow_project_forward_f64(const double* pts, const double* intr, const int64_t* fid, int64_t B, int64_t H,
                                 int64_t W, double* flow, int64_t threads) {
  flow_project_forward<double>(pts, intr, fid, B, H, W, flow, threads);
}
void zk_flow_project_backward_f32(const float* pts, const float* intr, const int64_t* fid, const float* g_flow,
                                  int64_t B, int64_t H, int64_t W, float* g_pts, float* g_intr, int64_t threads) {
  flow_project_backward<float>(pts, intr, fid, g_flow, B, H, W, g_pts, g_intr, threads);
}
void zk_flow_project_backward_f64(const double* pts, const double* intr, const int64_t* fid, const double* g_flow,
                                  int64_t B, int64_t H, int64_t W, double* g_pts, double* g_intr, int64_t threads) {
  flow_project_backward<double>(pts, intr, fid, g_flow, B, H, W, g_pts, g_intr, threads);
}

}  // extern "C"
