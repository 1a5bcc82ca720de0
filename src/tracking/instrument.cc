#include "tracking/instrument.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <random>

#include <opencv2/imgproc.hpp>

#include "core/error.h"

namespace arreg {

void InstrumentMaskOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(hue_direction_deg), "", "InstrumentMaskOptions.hue_direction_deg",
                    "must be finite, got ", hue_direction_deg);
  ARREG_CHECK_INPUT(std::isfinite(seed_max_warmth) && std::isfinite(grow_max_warmth) &&
                        seed_max_warmth <= grow_max_warmth,
                    "", "InstrumentMaskOptions.seed_max_warmth",
                    "must be finite and <= grow_max_warmth, got ", seed_max_warmth, " and ",
                    grow_max_warmth);
  ARREG_CHECK_INPUT(min_seed_lightness >= 0 && min_seed_lightness < max_seed_lightness &&
                        max_seed_lightness <= 256,
                    "", "InstrumentMaskOptions.min_seed_lightness",
                    "must be in 0..max_seed_lightness - 1 (max_seed_lightness <= 256), got ",
                    min_seed_lightness, " and ", max_seed_lightness);
  ARREG_CHECK_INPUT(min_area_fraction >= 0 && min_area_fraction <= 1, "",
                    "InstrumentMaskOptions.min_area_fraction", "must be in [0, 1], got ",
                    min_area_fraction);
  ARREG_CHECK_INPUT(downscale >= 1 && downscale <= 4, "", "InstrumentMaskOptions.downscale",
                    "must be in 1..4, got ", downscale);
  ARREG_CHECK_INPUT(close_px >= 0 && close_px <= 32, "", "InstrumentMaskOptions.close_px",
                    "must be in 0..32, got ", close_px);
  ARREG_CHECK_INPUT(margin_px >= 0 && margin_px <= 64, "", "InstrumentMaskOptions.margin_px",
                    "must be in 0..64, got ", margin_px);
}

void InstrumentMotionOptions::Check() const {
  ARREG_CHECK_INPUT(std::isfinite(band_px) && band_px >= 0, "", "InstrumentMotionOptions.band_px",
                    "must be >= 0, got ", band_px);
  ARREG_CHECK_INPUT(min_group >= 2, "", "InstrumentMotionOptions.min_group", "must be >= 2, got ",
                    min_group);
  ARREG_CHECK_INPUT(std::isfinite(max_residual_px) && max_residual_px > 0, "",
                    "InstrumentMotionOptions.max_residual_px", "must be > 0, got ",
                    max_residual_px);
  ARREG_CHECK_INPUT(std::isfinite(min_relative_motion_px) && min_relative_motion_px > 0, "",
                    "InstrumentMotionOptions.min_relative_motion_px", "must be > 0, got ",
                    min_relative_motion_px);
  ARREG_CHECK_INPUT(tissue_neighbours >= 1, "", "InstrumentMotionOptions.tissue_neighbours",
                    "must be >= 1, got ", tissue_neighbours);
  ARREG_CHECK_INPUT(std::isfinite(reference_radius_px) && reference_radius_px > 0, "",
                    "InstrumentMotionOptions.reference_radius_px", "must be > 0, got ",
                    reference_radius_px);
  ARREG_CHECK_INPUT(max_groups >= 1, "", "InstrumentMotionOptions.max_groups", "must be >= 1, got ",
                    max_groups);
  ARREG_CHECK_INPUT(max_group_fraction > 0 && max_group_fraction <= 1, "",
                    "InstrumentMotionOptions.max_group_fraction", "must be in (0, 1], got ",
                    max_group_fraction);
}

void InstrumentRejectionOptions::Check() const {
  mask.Check();
  motion.Check();
}

cv::Mat InstrumentMask(const cv::Mat& bgr, const InstrumentMaskOptions& options) {
  ARREG_CHECK_INPUT(bgr.type() == CV_8UC3 && !bgr.empty(), "", "InstrumentMask image",
                    "expected a non-empty CV_8UC3 (BGR) image");
  const int ds = options.downscale;
  cv::Mat small;
  if (ds > 1)
    cv::resize(bgr, small, cv::Size((bgr.cols + ds - 1) / ds, (bgr.rows + ds - 1) / ds), 0, 0,
               cv::INTER_AREA);
  else
    small = bgr;
  cv::Mat lab;
  cv::cvtColor(small, lab, cv::COLOR_BGR2Lab);
  const double theta = options.hue_direction_deg * M_PI / 180.0;
  const float cs = static_cast<float>(std::cos(theta)), sn = static_cast<float>(std::sin(theta));
  const float seed_max = static_cast<float>(options.seed_max_warmth);
  const float grow_max = static_cast<float>(options.grow_max_warmth);
  cv::Mat grow(lab.size(), CV_8UC1), seed(lab.size(), CV_8UC1);
  for (int r = 0; r < lab.rows; ++r) {
    const cv::Vec3b* in = lab.ptr<cv::Vec3b>(r);
    uint8_t* g = grow.ptr<uint8_t>(r);
    uint8_t* s = seed.ptr<uint8_t>(r);
    for (int c = 0; c < lab.cols; ++c) {
      const float warmth = (in[c][1] - 128.f) * cs + (in[c][2] - 128.f) * sn;
      g[c] = warmth < grow_max ? 255 : 0;
      // Highlights are colourless on tissue too: they may join an instrument, not seed one.
      s[c] = g[c] && warmth < seed_max && in[c][0] >= options.min_seed_lightness &&
                     in[c][0] < options.max_seed_lightness
                 ? 1
                 : 0;
    }
  }
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(grow, labels, stats, centroids, 8, CV_32S);
  std::vector<int> seeds(n, 0);
  for (int r = 0; r < lab.rows; ++r) {
    const int* l = labels.ptr<int>(r);
    const uint8_t* s = seed.ptr<uint8_t>(r);
    for (int c = 0; c < lab.cols; ++c) seeds[l[c]] += s[c];
  }
  // Seed area in pixels of the full image.
  const double min_seeds = options.min_area_fraction * bgr.rows * bgr.cols / (ds * ds);
  std::vector<uint8_t> keep(n, 0);
  bool any = false;
  for (int k = 1; k < n; ++k) {
    keep[k] = seeds[k] > 0 && seeds[k] >= min_seeds ? 255 : 0;
    any = any || keep[k];
  }
  if (!any) return cv::Mat(bgr.size(), CV_8UC1, cv::Scalar(0));
  cv::Mat mask(lab.size(), CV_8UC1);
  for (int r = 0; r < lab.rows; ++r) {
    const int* l = labels.ptr<int>(r);
    uint8_t* m = mask.ptr<uint8_t>(r);
    for (int c = 0; c < lab.cols; ++c) m[c] = keep[l[c]];
  }
  if (options.close_px > 0)
    cv::morphologyEx(
        mask, mask, cv::MORPH_CLOSE,
        cv::getStructuringElement(cv::MORPH_ELLIPSE,
                                  cv::Size(2 * options.close_px + 1, 2 * options.close_px + 1)));
  // The margin is grown on the shrunk mask (rounded up to its pixels): a dilation of the full
  // image costs more than the rest together.
  const int margin = (options.margin_px + ds - 1) / ds;
  if (margin > 0)
    cv::dilate(
        mask, mask,
        cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * margin + 1, 2 * margin + 1)));
  cv::Mat full;
  if (ds > 1)
    cv::resize(mask, full, bgr.size(), 0, 0, cv::INTER_NEAREST);
  else
    full = mask;
  return full;
}

namespace {

using Complex = std::complex<double>;

// z -> a z + b.
struct Similarity {
  Complex a{1, 0}, b{0, 0};
  Complex operator()(Complex z) const { return a * z + b; }
};

Complex ToComplex(cv::Point2f p) { return {p.x, p.y}; }

// Least-squares similarity carrying from[i] to to[i] over `members` (at least 2, not coincident).
bool FitSimilarity(const std::vector<Complex>& from, const std::vector<Complex>& to,
                   const std::vector<int>& members, Similarity* s) {
  Complex mf(0, 0), mt(0, 0);
  for (int i : members) mf += from[i], mt += to[i];
  mf /= static_cast<double>(members.size());
  mt /= static_cast<double>(members.size());
  Complex num(0, 0);
  double den = 0;
  for (int i : members) {
    const Complex df = from[i] - mf;
    num += std::conj(df) * (to[i] - mt);
    den += std::norm(df);
  }
  if (den < 1e-9) return false;
  s->a = num / den;
  s->b = mt - s->a * mf;
  return true;
}

double Median(std::vector<double>* v) {
  const size_t h = v->size() / 2;
  std::nth_element(v->begin(), v->begin() + h, v->end());
  return (*v)[h];
}

}  // namespace

std::vector<bool> RigidInstrumentMotion(const std::vector<cv::Point2f>& from_px,
                                        const std::vector<cv::Point2f>& to_px,
                                        const std::vector<uint8_t>& near,
                                        const InstrumentMotionOptions& options) {
  ARREG_ASSERT(from_px.size() == to_px.size() && near.size() == to_px.size(), "");
  const int n = static_cast<int>(to_px.size());
  std::vector<bool> flagged(n, false);
  std::vector<int> pool;
  for (int i = 0; i < n; ++i)
    if (near[i]) pool.push_back(i);
  if (static_cast<int>(pool.size()) < options.min_group || static_cast<int>(pool.size()) == n)
    return flagged;

  std::vector<Complex> from(n), to(n);
  for (int i = 0; i < n; ++i) from[i] = ToComplex(from_px[i]), to[i] = ToComplex(to_px[i]);
  const double tolerance2 = options.max_residual_px * options.max_residual_px;
  const double reach2 = options.band_px * options.band_px;
  const double radius2 = options.reference_radius_px * options.reference_radius_px;
  auto fits = [&](const Similarity& s, int i) {
    return std::norm(s(from[i]) - to[i]) <= tolerance2;
  };

  std::vector<char> grouped(n, 0);  // member of a group found this frame
  std::mt19937 rng(1);              // fixed: the same frame gives the same groups
  std::vector<int> members, best, group;
  std::vector<std::pair<double, int>> by_distance;
  std::vector<double> dx, dy;
  for (int g = 0; g < options.max_groups && static_cast<int>(pool.size()) >= options.min_group;
       ++g) {
    // The largest consensus among the candidates of a similarity through two of them (all
    // pairs when few, else 300 random pairs: a group of a quarter of the pool is then missed
    // with probability (1 - 1/16)^300 < 1e-8), refitted to its members.
    const int m = static_cast<int>(pool.size());
    const bool all_pairs = m * (m - 1) / 2 <= 300;
    const int pairs = all_pairs ? m * (m - 1) / 2 : 300;
    std::uniform_int_distribution<int> pick(0, m - 1);
    best.clear();
    for (int p = 0, i = 0, j = 1; p < pairs; ++p) {
      int a = i, b = j;
      if (all_pairs) {
        if (++j == m) ++i, j = i + 1;
      } else {
        a = pick(rng), b = pick(rng);
        if (a == b) continue;
      }
      Similarity s;
      if (!FitSimilarity(from, to, {pool[a], pool[b]}, &s)) continue;
      members.clear();
      for (int c : pool)
        if (fits(s, c)) members.push_back(c);
      if (members.size() > best.size()) best.swap(members);
    }
    if (static_cast<int>(best.size()) < options.min_group) break;
    Similarity s;
    if (!FitSimilarity(from, to, best, &s)) break;
    // Grown over every feature the similarity carries that lies within band_px of a member:
    // an instrument's parts beyond the band (jaws, a tip) move with it too.
    group.clear();
    std::vector<char> in_group(n, 0);
    for (int i : best)
      if (fits(s, i)) group.push_back(i), in_group[i] = 1;
    for (size_t q = 0; q < group.size(); ++q)
      for (int j = 0; j < n; ++j)
        if (!in_group[j] && !grouped[j] && fits(s, j) && std::norm(to[j] - to[group[q]]) <= reach2)
          group.push_back(j), in_group[j] = 1;
    for (int i : group) grouped[i] = 1;
    pool.erase(std::remove_if(pool.begin(), pool.end(), [&](int i) { return grouped[i] != 0; }),
               pool.end());
    // The tissue carries most features: a group of more than max_group_fraction of them is the
    // tissue itself (a pan, the camera moving with a still instrument), never an instrument.
    if (static_cast<double>(group.size()) > options.max_group_fraction * n) continue;
    // Each member's motion relative to the tissue around it: the component-wise median
    // displacement of its nearest features away from the instruments (not candidates) and
    // outside this group. Candidates are not references: beside an instrument they may ride it.
    std::vector<int> moving;
    for (int i : group) {
      by_distance.clear();
      for (int t = 0; t < n; ++t)
        if (!near[t] && !in_group[t] && std::norm(to[t] - to[i]) <= radius2)
          by_distance.emplace_back(std::norm(to[t] - to[i]), t);
      // Inside a large group (tissue moving as one locally) there is no surrounding to differ
      // from: the motion field's variation over a distance is no sign of an instrument.
      if (static_cast<int>(by_distance.size()) < 3) continue;
      const int k = std::min<int>(options.tissue_neighbours, static_cast<int>(by_distance.size()));
      std::partial_sort(by_distance.begin(), by_distance.begin() + k, by_distance.end());
      dx.clear(), dy.clear();
      for (int r = 0; r < k; ++r) {
        const Complex d = to[by_distance[r].second] - from[by_distance[r].second];
        dx.push_back(d.real()), dy.push_back(d.imag());
      }
      const Complex reference(Median(&dx), Median(&dy));
      if (std::abs(to[i] - from[i] - reference) >= options.min_relative_motion_px)
        moving.push_back(i);
    }
    if (static_cast<int>(moving.size()) >= options.min_group)
      for (int i : moving) flagged[i] = true;
  }
  return flagged;
}

}  // namespace arreg
