#include "ar/render/coverage_layer.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/error.h"

namespace arreg::render {

namespace {

// Sub-pixel precision of the fixed-point vertex positions: 1/256 px.
constexpr int kSubpixelBits = 8;
constexpr double kSubpixel = 1 << kSubpixelBits;
// Projected positions beyond +-2^20 px would overflow the 64-bit edge functions; such
// triangles (vertices a hair in front of the near plane, far off-screen) are skipped.
constexpr double kMaxCoordinatePx = 1 << 20;

// Antisymmetric tie rule (as RenderTarget's): of two triangles sharing an edge, exactly one
// owns the pixel centres lying on it.
inline bool OwnsEdge(int64_t dx, int64_t dy) { return dy > 0 || (dy == 0 && dx < 0); }

inline int64_t FloorDiv(int64_t a, int64_t b) {  // b > 0
  const int64_t q = a / b;
  return (a % b != 0 && a < 0) ? q - 1 : q;
}
inline int64_t CeilDiv(int64_t a, int64_t b) { return -FloorDiv(-a, b); }  // b > 0

}  // namespace

void CoverageDrawOptions::Check() const {
  ARREG_CHECK_INPUT(opacity > 0 && opacity <= 1, "", "CoverageDrawOptions.opacity",
                    "must be in (0, 1], got ", opacity);
}

CoverageLayer::CoverageLayer(const RasterCamera& camera) : camera_(camera) {
  camera_.Check();
  pixels_.assign(static_cast<size_t>(camera_.width) * camera_.height, Pixel{0, 0, 0, 0, 0});
  row_begin_.assign(camera_.height, camera_.width);
  row_end_.assign(camera_.height, 0);
}

void CoverageLayer::Clear(const PixelRect& rect) {
  for (int y = 0; y < camera_.height; ++y) {
    if (row_begin_[y] < row_end_[y])
      std::fill(pixels_.begin() + Index(row_begin_[y], y), pixels_.begin() + Index(row_end_[y], y),
                Pixel{0, 0, 0, 0, 0});
    row_begin_[y] = camera_.width;
    row_end_[y] = 0;
  }
  rect_.x0 = std::clamp(rect.x0, 0, camera_.width);
  rect_.x1 = std::clamp(rect.x1, rect_.x0, camera_.width);
  rect_.y0 = std::clamp(rect.y0, 0, camera_.height);
  rect_.y1 = std::clamp(rect.y1, rect_.y0, camera_.height);
}

double CoverageLayer::CoveredArea() const {
  double sum = 0;
  for (int y = 0; y < camera_.height; ++y)
    for (int x = row_begin_[y]; x < row_end_[y]; ++x) sum += pixel(x, y).alpha;
  return sum;
}

const CoverageLayer::Adjacency& CoverageLayer::AdjacencyOf(const RowMatX3i& faces) {
  for (const Adjacency& a : adjacency_cache_)
    if (a.faces.rows() == faces.rows() &&
        std::memcmp(a.faces.data(), faces.data(), sizeof(int) * faces.size()) == 0)
      return a;
  // A few meshes are drawn per frame (organ, internal structures): a small cache keeps each
  // one's adjacency until its connectivity changes (a cut).
  constexpr size_t kCacheSize = 8;
  if (adjacency_cache_.size() < kCacheSize) adjacency_cache_.emplace_back();
  Adjacency& a = adjacency_cache_[adjacency_next_ % adjacency_cache_.size()];
  ++adjacency_next_;
  a.faces = faces;
  const int nf = static_cast<int>(faces.rows());
  a.neighbour.assign(3 * static_cast<size_t>(nf), -1);
  edge_keys_.clear();
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const int64_t i = faces(f, k), j = faces(f, (k + 1) % 3);
      edge_keys_.emplace_back((std::min(i, j) << 32) | std::max(i, j), 3 * f + k);
    }
  std::sort(edge_keys_.begin(), edge_keys_.end());
  for (size_t s = 0; s < edge_keys_.size();) {
    size_t e = s + 1;
    while (e < edge_keys_.size() && edge_keys_[e].first == edge_keys_[s].first) ++e;
    if (e - s == 2) {  // manifold edge; boundary and non-manifold edges keep -1
      a.neighbour[edge_keys_[s].second] = edge_keys_[s + 1].second / 3;
      a.neighbour[edge_keys_[s + 1].second] = edge_keys_[s].second / 3;
    }
    s = e;
  }
  return a;
}

int64_t CoverageLayer::Draw(
    const RowMatX3d& vertices_in_world, const RowMatX3i& faces,
    const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>& vertex_rgb,
    const CoverageDrawOptions& options) {
  options.Check();
  const int nv = static_cast<int>(vertices_in_world.rows());
  ARREG_CHECK_INPUT(vertex_rgb.rows() == nv, "", "vertex_rgb", "need one colour per vertex (", nv,
                    "), got ", vertex_rgb.rows());
  const int nf = static_cast<int>(faces.rows());
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k)
      ARREG_CHECK_INPUT(faces(f, k) >= 0 && faces(f, k) < nv, "", "faces", "face ", f,
                        " has vertex index ", faces(f, k), " outside [0, ", nv, ")");
  if (rect_.empty() || nf == 0) return 0;

  p_cam_.resize(nv);
  for (int i = 0; i < nv; ++i)
    p_cam_[i] = camera_.camera_from_world * Eigen::Vector3d(vertices_in_world.row(i).transpose());
  facing_.resize(nf);
  for (int f = 0; f < nf; ++f) {
    const Eigen::Vector3d& a = p_cam_[faces(f, 0)];
    const Eigen::Vector3d n = (p_cam_[faces(f, 1)] - a).cross(p_cam_[faces(f, 2)] - a);
    facing_[f] = n.squaredNorm() == 0 ? 0 : (n.dot(a) < 0 ? 1 : -1);
  }
  const Adjacency& adjacency = AdjacencyOf(faces);

  int64_t written = 0;
  const double near = camera_.near_mm;
  for (int f = 0; f < nf; ++f) {
    if (facing_[f] == 0 || (options.cull_back_faces && facing_[f] < 0)) continue;
    Vertex v[3];
    bool smooth[3];
    int inside = 0;
    for (int k = 0; k < 3; ++k) {
      v[k].p_cam = p_cam_[faces(f, k)];
      v[k].rgb = vertex_rgb.row(faces(f, k)).transpose();
      inside += v[k].p_cam.z() >= near;
      const int nb = adjacency.neighbour[3 * f + k];
      // A silhouette edge: the surface ends there in the image (no neighbour, a neighbour of the
      // other facing, or one that is culled or degenerate).
      smooth[k] = options.antialias && (nb < 0 || facing_[nb] != facing_[f]);
    }
    if (inside == 0) continue;
    if (inside == 3) {
      written += DrawTriangle(v, smooth, options.opacity);
      continue;
    }
    // Sutherland-Hodgman against z >= near. An output edge follows an input edge (keeps its
    // smoothness) or runs along the clip plane (hard: the surface goes on behind it).
    Vertex poly[4];
    bool poly_smooth[4];
    int n = 0;
    for (int i = 0; i < 3; ++i) {
      const int j = (i + 1) % 3;
      const bool in_i = v[i].p_cam.z() >= near, in_j = v[j].p_cam.z() >= near;
      if (in_i) {
        poly[n] = v[i];
        poly_smooth[n++] = smooth[i];
      }
      if (in_i != in_j) {
        const double t = (near - v[i].p_cam.z()) / (v[j].p_cam.z() - v[i].p_cam.z());
        poly[n].p_cam = v[i].p_cam + t * (v[j].p_cam - v[i].p_cam);
        poly[n].rgb = v[i].rgb + static_cast<float>(t) * (v[j].rgb - v[i].rgb);
        poly_smooth[n++] = in_j ? smooth[i] : false;
      }
    }
    for (int t = 1; t + 1 < n; ++t) {
      const Vertex sub[3] = {poly[0], poly[t], poly[t + 1]};
      const bool sub_smooth[3] = {t == 1 && poly_smooth[0], poly_smooth[t],
                                  t + 1 == n - 1 && poly_smooth[n - 1]};
      written += DrawTriangle(sub, sub_smooth, options.opacity);
    }
  }
  return written;
}

int64_t CoverageLayer::DrawTriangle(const Vertex v_in[3], const bool smooth_in[3], float opacity) {
  double px[3], py[3], inv_z[3];
  for (int k = 0; k < 3; ++k) {
    inv_z[k] = 1.0 / v_in[k].p_cam.z();
    px[k] = camera_.fx * v_in[k].p_cam.x() * inv_z[k] + camera_.cx;
    py[k] = camera_.fy * v_in[k].p_cam.y() * inv_z[k] + camera_.cy;
    if (!(std::abs(px[k]) < kMaxCoordinatePx && std::abs(py[k]) < kMaxCoordinatePx)) return 0;
  }
  int64_t fx[3], fy[3];
  for (int k = 0; k < 3; ++k) {
    fx[k] = std::llround(px[k] * kSubpixel);
    fy[k] = std::llround(py[k] * kSubpixel);
  }
  int64_t area = (fx[1] - fx[0]) * (fy[2] - fy[0]) - (fy[1] - fy[0]) * (fx[2] - fx[0]);
  if (area == 0) return 0;
  // Vertex order with positive area; edge e runs from vertex o[e] to o[e + 1].
  int o[3] = {0, 1, 2};
  bool smooth[3] = {smooth_in[0], smooth_in[1], smooth_in[2]};
  if (area < 0) {
    o[1] = 2;
    o[2] = 1;
    smooth[0] = smooth_in[2];  // edge (0, 2)
    smooth[2] = smooth_in[0];  // edge (1, 0)
    area = -area;
  }
  // Edge function of edge e at pixel centre (x, y): E = (Bx - Ax)(y*s - Ay) - (By - Ay)(x*s - Ax)
  // in 1/s^2 px^2 (s = 256); E / area is the barycentric weight of the vertex opposite e.
  int64_t step_x[3], step_y[3], threshold[3], interior[3];
  float to_distance[3];  // E -> signed distance to the edge line in px (positive inside)
  bool any_smooth = false;
  for (int e = 0; e < 3; ++e) {
    const int a = o[e], b = o[(e + 1) % 3];
    const int64_t dx = fx[b] - fx[a], dy = fy[b] - fy[a];
    step_x[e] = -dy * static_cast<int64_t>(kSubpixel);
    step_y[e] = dx * static_cast<int64_t>(kSubpixel);
    const double length = std::sqrt(static_cast<double>(dx) * dx + static_cast<double>(dy) * dy);
    to_distance[e] = static_cast<float>(1.0 / (kSubpixel * length));
    if (smooth[e]) {
      // Pixels whose centre lies less than half a pixel outside get partial coverage.
      threshold[e] = static_cast<int64_t>(std::floor(-0.5 * kSubpixel * length)) + 1;
      // At least half a pixel inside: full coverage (with a margin for the float rounding of
      // the coverage formula, so that the interior path below gives what it would).
      interior[e] = static_cast<int64_t>(std::ceil(0.5 * kSubpixel * length * (1 + 1e-6))) + 2;
      any_smooth = true;
    } else {
      threshold[e] = OwnsEdge(dx, dy) ? 0 : 1;
      interior[e] = threshold[e];
    }
  }
  const double margin = any_smooth ? 1.0 : 0.0;
  const int x0 =
      std::max(rect_.x0, static_cast<int>(std::ceil(std::min({px[0], px[1], px[2]}) - margin)));
  const int x1 = std::min(rect_.x1 - 1,
                          static_cast<int>(std::floor(std::max({px[0], px[1], px[2]}) + margin)));
  const int y0 =
      std::max(rect_.y0, static_cast<int>(std::ceil(std::min({py[0], py[1], py[2]}) - margin)));
  const int y1 = std::min(rect_.y1 - 1,
                          static_cast<int>(std::floor(std::max({py[0], py[1], py[2]}) + margin)));
  if (x0 > x1 || y0 > y1) return 0;

  // Attributes of the vertex opposite each edge.
  float opposite_inv_z[3];
  Eigen::Vector3f opposite_rgb[3];
  for (int e = 0; e < 3; ++e) {
    opposite_inv_z[e] = static_cast<float>(inv_z[o[(e + 2) % 3]]);
    opposite_rgb[e] = v_in[o[(e + 2) % 3]].rgb;
  }
  // The perspective numerators sum_e w_e / z_e and sum_e w_e rgb_e / z_e for weights w. Along a
  // row the weights are linear in x, so inside the triangle these advance by constant steps.
  const auto perspective_sums = [&](const int64_t w[3], double* inv_depth_sum,
                                    Eigen::Vector3d* rgb_sum) {
    *inv_depth_sum = 0;
    rgb_sum->setZero();
    for (int e = 0; e < 3; ++e) {
      const double wz = static_cast<double>(w[e]) * opposite_inv_z[e];
      *inv_depth_sum += wz;
      *rgb_sum += wz * opposite_rgb[e].cast<double>();
    }
  };
  double step_inv_depth;
  Eigen::Vector3d step_rgb;
  perspective_sums(step_x, &step_inv_depth, &step_rgb);
  int64_t row_e[3];
  for (int e = 0; e < 3; ++e) {
    const int a = o[e], b = o[(e + 1) % 3];
    row_e[e] = (fx[b] - fx[a]) * (y0 * static_cast<int64_t>(kSubpixel) - fy[a]) -
               (fy[b] - fy[a]) * (x0 * static_cast<int64_t>(kSubpixel) - fx[a]);
  }
  const float inv_area = static_cast<float>(1.0 / static_cast<double>(area));
  int64_t written = 0;
  // Merges a fragment into pixel p.
  const auto merge = [](Pixel& p, float coverage, float inv_depth, float r, float g, float b) {
    if (p.alpha == 0) {
      p = Pixel{coverage, inv_depth, r, g, b};
    } else if (inv_depth >= p.inv_depth) {  // in front of what is there
      const float merged = std::max(coverage, p.alpha), keep = (merged - coverage) / merged;
      const float take = coverage / merged;
      p = Pixel{merged, inv_depth, take * r + keep * p.r, take * g + keep * p.g,
                take * b + keep * p.b};
    } else if (coverage > p.alpha) {  // behind: shows where the front leaves room
      const float merged = coverage, keep = p.alpha / merged, take = 1.0f - keep;
      p.r = keep * p.r + take * r;
      p.g = keep * p.g + take * g;
      p.b = keep * p.b + take * b;
      p.alpha = merged;
    }
  };
  // Any pixel of the row's span, near the edges: partial coverage, clamped weights.
  const auto edge_pixel = [&](Pixel& p, const int64_t e_at[3]) {
    float coverage = opacity, weight_sum = 0, inv_depth = 0;
    bool clamped = false;
    Eigen::Vector3f rgb = Eigen::Vector3f::Zero();
    for (int e = 0; e < 3; ++e) {
      const float value = static_cast<float>(e_at[e]);
      if (smooth[e]) coverage *= std::min(1.0f, 0.5f + value * to_distance[e]);
      // Outside samples of the anti-aliased fringe take the colour and depth on the edge.
      const float w = value > 0 ? value : 0.0f;
      clamped |= value < 0;
      const float wz = w * opposite_inv_z[e];
      weight_sum += w;
      inv_depth += wz;
      rgb += wz * opposite_rgb[e];
    }
    if (inv_depth <= 0) return false;
    rgb *= 1.0f / inv_depth;  // perspective-correct Gouraud
    // The weights sum to the area inside the triangle; not where the fringe clamped them.
    inv_depth *= clamped ? 1.0f / weight_sum : inv_area;
    merge(p, coverage, inv_depth, rgb.x(), rgb.y(), rgb.z());
    return true;
  };
  // Columns [lo, hi] of the row (from x0) where step_x * (x - x0) >= limit - row_e for all edges.
  const auto solve_span = [&](const int64_t limit[3], int64_t* lo, int64_t* hi) {
    for (int e = 0; e < 3 && *lo <= *hi; ++e) {
      const int64_t need = limit[e] - row_e[e];
      if (step_x[e] > 0)
        *lo = std::max(*lo, x0 + CeilDiv(need, step_x[e]));
      else if (step_x[e] < 0)
        *hi = std::min(*hi, x0 + FloorDiv(-need, -step_x[e]));
      else if (need > 0)
        *hi = *lo - 1;
    }
  };
  for (int y = y0; y <= y1; ++y) {
    // The row's span where every edge passes its test, solved exactly in integers, and inside
    // it the span of full coverage and unclamped weights.
    int64_t lo = x0, hi = x1;
    solve_span(threshold, &lo, &hi);
    if (lo <= hi) {
      int64_t in_lo = lo, in_hi = hi;
      solve_span(interior, &in_lo, &in_hi);
      if (in_lo > in_hi) {  // no interior: the whole span is edge pixels
        in_lo = hi + 1;
        in_hi = hi;
      }
      Pixel* row = &pixels_[Index(0, y)];
      row_begin_[y] = std::min(row_begin_[y], static_cast<int>(lo));
      row_end_[y] = std::max(row_end_[y], static_cast<int>(hi) + 1);
      int64_t e_at[3];
      for (int e = 0; e < 3; ++e) e_at[e] = row_e[e] + step_x[e] * (lo - x0);
      const auto edge_run = [&](int64_t from, int64_t to) {  // columns [from, to)
        for (int64_t x = from; x < to; ++x) {
          written += edge_pixel(row[x], e_at);
          for (int e = 0; e < 3; ++e) e_at[e] += step_x[e];
        }
      };
      edge_run(lo, in_lo);
      if (in_lo <= in_hi) {
        double inv_depth_sum;
        Eigen::Vector3d rgb_sum;
        perspective_sums(e_at, &inv_depth_sum, &rgb_sum);
        for (int64_t x = in_lo; x <= in_hi; ++x) {
          const double to_rgb = 1.0 / inv_depth_sum;
          merge(row[x], opacity, static_cast<float>(inv_depth_sum) * inv_area,
                static_cast<float>(rgb_sum.x() * to_rgb), static_cast<float>(rgb_sum.y() * to_rgb),
                static_cast<float>(rgb_sum.z() * to_rgb));
          inv_depth_sum += step_inv_depth;
          rgb_sum += step_rgb;
        }
        written += in_hi - in_lo + 1;
        for (int e = 0; e < 3; ++e) e_at[e] += step_x[e] * (in_hi - in_lo + 1);
      }
      edge_run(std::max(lo, in_hi + 1), hi + 1);
    }
    for (int e = 0; e < 3; ++e) row_e[e] += step_y[e];
  }
  return written;
}

}  // namespace arreg::render
