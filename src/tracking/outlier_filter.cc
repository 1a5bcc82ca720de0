// The spatio-temporal outlier filter: displacement against the k nearest neighbours'.
#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "core/error.h"

namespace arreg {

namespace {

// The k nearest other points of every point, from a uniform grid of about k
// points per cell searched ring by ring: O(n k) instead of O(n^2) for the
// ~500 features of a frame. neighbours[i * k + j] is the j-th of point i (unordered).
void NearestNeighbours(const std::vector<cv::Point2f>& points, int k,
                       std::vector<int>* neighbours) {
  const int n = static_cast<int>(points.size());
  neighbours->assign(static_cast<size_t>(n) * k, -1);
  cv::Point2f lo = points[0], hi = points[0];
  for (const cv::Point2f& p : points) {
    lo.x = std::min(lo.x, p.x), lo.y = std::min(lo.y, p.y);
    hi.x = std::max(hi.x, p.x), hi.y = std::max(hi.y, p.y);
  }
  const float area = std::max(1.f, (hi.x - lo.x) * (hi.y - lo.y));
  const float cell = std::max(1.f, std::sqrt(area * k / n));
  const int cols = static_cast<int>((hi.x - lo.x) / cell) + 1;
  const int rows = static_cast<int>((hi.y - lo.y) / cell) + 1;
  // Points sorted by cell (counting sort): cell c holds order[start[c] .. start[c+1]).
  std::vector<int> start(static_cast<size_t>(cols) * rows + 1, 0), order(n), cell_of(n);
  for (int i = 0; i < n; ++i) {
    const int cx = static_cast<int>((points[i].x - lo.x) / cell);
    const int cy = static_cast<int>((points[i].y - lo.y) / cell);
    cell_of[i] = cy * cols + cx;
    ++start[cell_of[i] + 1];
  }
  for (size_t c = 1; c < start.size(); ++c) start[c] += start[c - 1];
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (int i = 0; i < n; ++i) order[fill[cell_of[i]]++] = i;

  std::vector<std::pair<float, int>> best;  // max-heap of the k nearest so far
  for (int i = 0; i < n; ++i) {
    best.clear();
    const int cx = cell_of[i] % cols, cy = cell_of[i] / cols;
    for (int ring = 0;; ++ring) {
      for (int y = cy - ring; y <= cy + ring; ++y) {
        if (y < 0 || y >= rows) continue;
        const bool edge_row = y == cy - ring || y == cy + ring;
        for (int x = cx - ring; x <= cx + ring; x += edge_row ? 1 : 2 * ring) {
          if (x >= 0 && x < cols) {
            for (int m = start[y * cols + x]; m < start[y * cols + x + 1]; ++m) {
              const int j = order[m];
              if (j == i) continue;
              const cv::Point2f d = points[j] - points[i];
              const float d2 = d.dot(d);
              if (static_cast<int>(best.size()) < k) {
                best.emplace_back(d2, j);
                std::push_heap(best.begin(), best.end());
              } else if (d2 < best.front().first) {
                std::pop_heap(best.begin(), best.end());
                best.back() = {d2, j};
                std::push_heap(best.begin(), best.end());
              }
            }
          }
          if (ring == 0) break;
        }
      }
      // Points outside the rings searched are at least as far as the block's
      // nearest side that still has cells beyond it (at least ring * cell,
      // often nearly a cell more: ring 1 then suffices where ring * cell would
      // search ring 2 too, with twice the points). The margin covers a point
      // that float rounding put in the cell beside.
      const float inf = std::numeric_limits<float>::infinity();
      const cv::Point2f p = points[i] - lo;
      float reach = inf;
      if (cx - ring > 0) reach = std::min(reach, p.x - (cx - ring) * cell);
      if (cx + ring + 1 < cols) reach = std::min(reach, (cx + ring + 1) * cell - p.x);
      if (cy - ring > 0) reach = std::min(reach, p.y - (cy - ring) * cell);
      if (cy + ring + 1 < rows) reach = std::min(reach, (cy + ring + 1) * cell - p.y);
      if (reach == inf) break;  // every cell searched
      reach -= 1e-3f * cell;
      if (static_cast<int>(best.size()) == k && reach > 0 && best.front().first <= reach * reach)
        break;
    }
    for (int j = 0; j < k; ++j) (*neighbours)[static_cast<size_t>(i) * k + j] = best[j].second;
  }
}

}  // namespace

std::vector<bool> SpatioTemporalOutliers(const std::vector<cv::Point2f>& positions_px,
                                         const std::vector<cv::Point2f>& displacements_px,
                                         const OutlierFilterOptions& options) {
  ARREG_ASSERT(positions_px.size() == displacements_px.size(), "");
  const int n = static_cast<int>(positions_px.size());
  std::vector<bool> outlier(n, false);
  if (n < 2) return outlier;
  std::vector<double> magnitude(n);
  double total = 0;
  for (int i = 0; i < n; ++i) {
    magnitude[i] = std::hypot(displacements_px[i].x, displacements_px[i].y);
    total += magnitude[i];
  }
  const int k = std::min(options.neighbours, n - 1);
  std::vector<int> neighbours;
  if (k > 0) NearestNeighbours(positions_px, k, &neighbours);
  for (int i = 0; i < n; ++i) {
    double reference;
    if (k == 0) {
      reference = (total - magnitude[i]) / (n - 1);
    } else {
      double sum = 0;
      for (int j = 0; j < k; ++j) sum += magnitude[neighbours[static_cast<size_t>(i) * k + j]];
      reference = sum / k;
    }
    outlier[i] = magnitude[i] > options.ratio * reference + options.slack_px;
  }
  return outlier;
}

}  // namespace arreg
