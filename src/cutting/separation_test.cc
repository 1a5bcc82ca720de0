#include "cutting/separation_test.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <vector>

#include "core/error.h"

namespace arreg::cutting {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTiny = 1e-300;

// Continued fraction of the incomplete beta function (modified Lentz), valid for
// x < (a + 1) / (a + b + 2).
double BetaContinuedFraction(double a, double b, double x) {
  const double qab = a + b, qap = a + 1.0, qam = a - 1.0;
  double c = 1.0, d = 1.0 - qab * x / qap;
  if (std::abs(d) < kTiny) d = kTiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m <= 1000; ++m) {
    const double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((qam + m2) * (a + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < kTiny) d = kTiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    h *= d * c;
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < kTiny) d = kTiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double step = d * c;
    h *= step;
    if (std::abs(step - 1.0) < 1e-15) break;
  }
  return h;
}

// Upper tail Q(a, x) = 1 - P(a, x) of the regularised incomplete gamma function.
double GammaUpperTail(double a, double x) {
  if (x <= 0.0) return 1.0;
  const double log_prefactor = -x + a * std::log(x) - std::lgamma(a);
  if (x < a + 1.0) {
    double term = 1.0 / a, sum = term;
    for (int n = 1; n < 10000 && std::abs(term) > std::abs(sum) * 1e-16; ++n) {
      term *= x / (a + n);
      sum += term;
    }
    return 1.0 - sum * std::exp(log_prefactor);
  }
  double b = x + 1.0 - a, c = 1.0 / kTiny, d = 1.0 / b, h = d;
  for (int i = 1; i <= 10000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double step = d * c;
    h *= step;
    if (std::abs(step - 1.0) < 1e-15) break;
  }
  return std::exp(log_prefactor) * h;
}

// P(F > f) for F ~ F(d1, d2); d2 infinite gives P(chi2(d1) > d1 f).
double FisherUpperTail(double f, double d1, double d2) {
  if (f <= 0.0) return 1.0;
  if (!std::isfinite(d2)) return GammaUpperTail(0.5 * d1, 0.5 * d1 * f);
  return RegularizedIncompleteBeta(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f));
}

// The least-squares fit of one design: its column space's orthonormal basis and rank.
struct Projector {
  Eigen::MatrixXd q;  // (#n x rank)
  int rank = 0;
  explicit Projector(const Eigen::MatrixXd& design) {
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(design);
    qr.setThreshold(1e-10);
    rank = static_cast<int>(qr.rank());
    q = qr.householderQ() * Eigen::MatrixXd::Identity(design.rows(), rank);
  }
  // The part of v outside the column space.
  Eigen::MatrixXd Residual(const Eigen::MatrixXd& v) const { return v - q * (q.transpose() * v); }
};

// One line's F test on the strip features: their tangent coordinates (t, s), misfits and
// current positions.
struct LineFit {
  bool valid = false;
  double f = 0.0;
  double dof = 0.0;          // of the variance estimate: 3 (n - 9), or infinite at the floor
  double threshold = 0.0;    // the F quantile at 1 - alpha / tests for dof
  bool significant = false;  // f > threshold
  Eigen::Vector3d jump = Eigen::Vector3d::Zero();
  double opening = 0.0;
  int side_count[2] = {0, 0};
};

// The F(6, dof) quantile at 1 - alpha / tests per degree of freedom of the variance estimate,
// computed once each (index 0: the floor's infinite degrees of freedom).
class Thresholds {
 public:
  Thresholds(double alpha, double tests) : p_(1.0 - alpha / tests) {}
  double operator()(double dof) {
    const size_t k = std::isfinite(dof) ? static_cast<size_t>(dof) : 0;
    if (k >= cache_.size()) cache_.resize(k + 1, -1.0);
    if (cache_[k] < 0.0) cache_[k] = FisherQuantile(p_, 6.0, dof);
    return cache_[k];
  }

 private:
  double p_;
  std::vector<double> cache_;
};

LineFit FitLine(const Eigen::MatrixXd& ts, const Eigen::MatrixXd& misfit,
                const Eigen::MatrixXd& current, const SeparationTestOptions& options,
                Thresholds* thresholds) {
  LineFit fit;
  const int n = static_cast<int>(ts.rows());
  Eigen::VectorXd side(n);
  for (int i = 0; i < n; ++i) {
    side(i) = ts(i, 1) > 0.0 ? 1.0 : 0.0;
    ++fit.side_count[side(i) > 0.5 ? 1 : 0];
  }
  if (std::min(fit.side_count[0], fit.side_count[1]) < options.min_features_per_side) return fit;
  // H0's design, scaled to unit ranges for conditioning.
  const double t_scale = std::max(ts.col(0).cwiseAbs().maxCoeff(), 1e-9);
  const double s_scale = std::max(ts.col(1).cwiseAbs().maxCoeff(), 1e-9);
  Eigen::MatrixXd design(n, 7);
  for (int i = 0; i < n; ++i) {
    const double t = ts(i, 0) / t_scale, s = ts(i, 1) / s_scale;
    const double above = std::max(s, 0.0), below = std::min(s, 0.0);
    design.row(i) << 1.0, t, t * t, above, below, above * t, below * t;
  }
  // H1 adds the jump g(t) = g0 + g1 t on the side s > 0 (a cut opens more at one end than at
  // the other: a V's opening grows from its tip).
  Eigen::MatrixXd jump_design(n, 2);
  double t_mean = 0.0;
  for (int i = 0; i < n; ++i) {
    jump_design.row(i) << side(i), side(i) * ts(i, 0) / t_scale;
    t_mean += ts(i, 0) / t_scale;
  }
  t_mean /= n;
  const Projector h0(design);
  const int dof = 3 * (n - h0.rank - 2);
  if (dof <= 0) return fit;
  const Eigen::MatrixXd r = h0.Residual(misfit);       // (#n x 3)
  const Eigen::MatrixXd h = h0.Residual(jump_design);  // (#n x 2)
  const Eigen::Matrix2d gram = h.transpose() * h;
  if (gram.determinant() <= 1e-12 * n * n) return fit;
  const Eigen::Matrix<double, 2, 3> coefficients = gram.ldlt().solve(h.transpose() * r);
  const double explained = (r.transpose() * h * coefficients).trace();
  const double rss1 = std::max(r.squaredNorm() - explained, 0.0);
  const double floor2 = options.noise_floor_mm * options.noise_floor_mm;
  const bool floored = rss1 / dof < floor2;
  const double sigma2 = floored ? floor2 : rss1 / dof;
  fit.f = (explained / 6.0) / sigma2;
  fit.dof = floored ? std::numeric_limits<double>::infinity() : static_cast<double>(dof);
  fit.threshold = (*thresholds)(fit.dof);
  fit.significant = fit.f > fit.threshold;
  // The jump at the strip's mean position along the line.
  fit.jump = (coefficients.row(0) + t_mean * coefficients.row(1)).transpose();
  Eigen::RowVector3d centroid[2] = {Eigen::RowVector3d::Zero(), Eigen::RowVector3d::Zero()};
  for (int i = 0; i < n; ++i) centroid[side(i) > 0.5 ? 1 : 0] += current.row(i);
  const Eigen::Vector3d apart =
      (centroid[1] / fit.side_count[1] - centroid[0] / fit.side_count[0]).transpose();
  fit.opening = apart.norm() > 0.0 ? fit.jump.dot(apart.normalized()) : 0.0;
  fit.valid = true;
  return fit;
}

// Rows of m without row `skip`.
Eigen::MatrixXd WithoutRow(const Eigen::MatrixXd& m, int skip) {
  Eigen::MatrixXd out(m.rows() - 1, m.cols());
  if (skip > 0) out.topRows(skip) = m.topRows(skip);
  if (skip + 1 < m.rows()) out.bottomRows(m.rows() - skip - 1) = m.bottomRows(m.rows() - skip - 1);
  return out;
}

}  // namespace

void SeparationTestOptions::Check() const {
  ARREG_CHECK_INPUT(false_alarm_probability > 0.0 && false_alarm_probability < 1.0, "",
                    "cutting.false_alarm_probability", "must be in (0, 1), got ",
                    false_alarm_probability);
  ARREG_CHECK_INPUT(std::isfinite(noise_floor_mm) && noise_floor_mm > 0.0, "",
                    "cutting.tracking_noise_px (as mm)", "must be > 0, got ", noise_floor_mm);
  ARREG_CHECK_INPUT(min_features_per_side >= 3, "", "cutting.min_features_per_side",
                    "must be >= 3, got ", min_features_per_side);
  ARREG_CHECK_INPUT(directions >= 1, "", "cutting.separation_directions", "must be >= 1, got ",
                    directions);
  ARREG_CHECK_INPUT(std::isfinite(strip_half_width) && strip_half_width > 0.0, "",
                    "cutting.strip_half_width", "must be > 0, got ", strip_half_width);
}

double RegularizedIncompleteBeta(double a, double b, double x) {
  if (x <= 0.0) return 0.0;
  if (x >= 1.0) return 1.0;
  const double log_front =
      std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) + b * std::log1p(-x);
  const double front = std::exp(log_front);
  if (x < (a + 1.0) / (a + b + 2.0)) return front * BetaContinuedFraction(a, b, x) / a;
  return 1.0 - front * BetaContinuedFraction(b, a, 1.0 - x) / b;
}

double FisherQuantile(double p, double d1, double d2) {
  ARREG_ASSERT(p > 0.0 && p < 1.0 && d1 > 0.0 && d2 > 0.0, "FisherQuantile: bad arguments");
  const double tail = 1.0 - p;
  double lo = 0.0, hi = 1.0;
  while (FisherUpperTail(hi, d1, d2) > tail && hi < 1e12) hi *= 2.0;
  for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (FisherUpperTail(mid, d1, d2) > tail ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

SeparationTestResult TestSeparation(const RowMatX3d& rest_mm, const RowMatX3d& current_mm,
                                    const RowMatX3d& displacement_mm,
                                    const Eigen::Vector3d& centre_mm,
                                    const SeparationTestOptions& options,
                                    const std::optional<Eigen::Vector3d>& along, double cone_deg) {
  options.Check();
  const int n = static_cast<int>(rest_mm.rows());
  ARREG_ASSERT(current_mm.rows() == n && displacement_mm.rows() == n, "TestSeparation: row counts");
  SeparationTestResult result;
  result.num_features = n;
  if (n < 2 * options.min_features_per_side) return result;

  // Tangent frame of the rest surface around c: the two largest principal directions.
  const Eigen::RowVector3d mean = rest_mm.colwise().mean();
  const Eigen::MatrixXd centred = rest_mm.rowwise() - mean;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(centred.transpose() * centred);
  const Eigen::Vector3d e1 = eigen.eigenvectors().col(2), e2 = eigen.eigenvectors().col(1);
  Eigen::MatrixXd local(n, 2);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = rest_mm.row(i).transpose() - centre_mm;
    local(i, 0) = d.dot(e1);
    local(i, 1) = d.dot(e2);
  }
  // The features' spacing: the median distance to the nearest other feature.
  std::vector<double> nearest(n, std::numeric_limits<double>::infinity());
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      const double d = (local.row(i) - local.row(j)).norm();
      nearest[i] = std::min(nearest[i], d);
      nearest[j] = std::min(nearest[j], d);
    }
  std::nth_element(nearest.begin(), nearest.begin() + n / 2, nearest.end());
  const double spacing = nearest[n / 2];
  result.spacing_mm = spacing;
  if (!(spacing > 0.0)) return result;
  const double half_width = options.strip_half_width * spacing;

  // Lines to try: normal angles in [0, pi) (or within the cone of `along`), each at offsets of
  // -1/2 to 1/2 spacing from c in steps of 1/4 (a feature next to the line is on its wrong side
  // at a coarser step, and its misfit then counts against the jump).
  std::vector<double> angles;
  const double step = kPi / options.directions;
  double along_angle = 0.0;
  if (along) along_angle = std::atan2(along->dot(e2), along->dot(e1)) + 0.5 * kPi;
  for (int k = 0; k < options.directions; ++k) {
    const double angle = k * step;
    if (along) {
      double diff = std::fmod(std::abs(angle - along_angle), kPi);
      diff = std::min(diff, kPi - diff);
      if (diff > cone_deg * kPi / 180.0 + 1e-9) continue;
    }
    angles.push_back(angle);
  }
  if (along && angles.empty()) angles.push_back(std::fmod(along_angle + kPi, kPi));
  const double offsets[] = {-0.5 * spacing, -0.25 * spacing, 0.0, 0.25 * spacing, 0.5 * spacing};
  const double tests = static_cast<double>(angles.size() * std::size(offsets));
  Thresholds thresholds(options.false_alarm_probability, tests);

  // The strip of one line: (t, s) per feature inside it, their misfits, current positions, and
  // the indices of the features used.
  struct Strip {
    Eigen::MatrixXd ts, misfit, current;
  };
  // On each side, the strip starts at the feature nearest the line (the lips' features may be
  // lost over a gap) and reaches strip_half_width spacings beyond it. With `along`, only the
  // features ahead of c along it (the part a growing cut has not reached).
  const auto make_strip = [&](double angle, double offset) {
    const double c = std::cos(angle), s = std::sin(angle);
    // The line's direction (t grows along it) oriented with `along`.
    double t_sign = 1.0;
    if (along) t_sign = (-s * along->dot(e1) + c * along->dot(e2)) < 0.0 ? -1.0 : 1.0;
    double nearest_side[2] = {std::numeric_limits<double>::infinity(),
                              std::numeric_limits<double>::infinity()};
    std::vector<std::pair<int, double>> candidates;  // (feature, s)
    for (int i = 0; i < n; ++i) {
      const double t = t_sign * (-s * local(i, 0) + c * local(i, 1));
      if (along && t < 0.0) continue;
      const double d = c * local(i, 0) + s * local(i, 1) - offset;
      candidates.emplace_back(i, d);
      double& nearest_d = nearest_side[d > 0.0 ? 1 : 0];
      nearest_d = std::min(nearest_d, std::abs(d));
    }
    std::vector<int> rows;
    for (const auto& [i, d] : candidates)
      if (std::abs(d) <= nearest_side[d > 0.0 ? 1 : 0] + half_width) rows.push_back(i);
    Strip strip;
    const int m = static_cast<int>(rows.size());
    strip.ts.resize(m, 2);
    strip.misfit.resize(m, 3);
    strip.current.resize(m, 3);
    for (int k = 0; k < m; ++k) {
      const int i = rows[k];
      strip.ts(k, 0) = -s * local(i, 0) + c * local(i, 1);
      strip.ts(k, 1) = c * local(i, 0) + s * local(i, 1) - offset;
      strip.misfit.row(k) = displacement_mm.row(i);
      strip.current.row(k) = current_mm.row(i);
    }
    return strip;
  };

  LineFit best;
  Strip best_strip;
  double best_angle = 0.0, best_offset = 0.0;
  for (const double angle : angles)
    for (const double offset : offsets) {
      Strip strip = make_strip(angle, offset);
      const LineFit fit = FitLine(strip.ts, strip.misfit, strip.current, options, &thresholds);
      if (!fit.valid) continue;
      if (!best.valid || fit.f / fit.threshold > best.f / best.threshold) {
        best = fit;
        best_strip = std::move(strip);
        best_angle = angle;
        best_offset = offset;
      }
    }
  if (!best.valid) return result;
  result.tested = true;
  result.statistic = best.f;
  result.threshold = best.threshold;
  result.features_side[0] = best.side_count[0];
  result.features_side[1] = best.side_count[1];
  result.offset_mm = best_offset;
  result.normal = (std::cos(best_angle) * e1 + std::sin(best_angle) * e2).normalized();
  result.direction = e1.cross(e2).cross(result.normal).normalized();
  result.jump_mm = best.jump;
  result.opening_mm = best.opening;
  if (!best.significant || best.opening <= 0.0) return result;

  // Robust to one feature: the decision must hold with any single feature left out (a side may
  // then have one feature fewer than min_features_per_side).
  SeparationTestOptions reduced = options;
  reduced.min_features_per_side = options.min_features_per_side - 1;
  const int m = static_cast<int>(best_strip.ts.rows());
  double robust = std::numeric_limits<double>::infinity();
  bool holds = true;
  for (int skip = 0; skip < m && holds; ++skip) {
    const LineFit fit =
        FitLine(WithoutRow(best_strip.ts, skip), WithoutRow(best_strip.misfit, skip),
                WithoutRow(best_strip.current, skip), reduced, &thresholds);
    holds = fit.valid && fit.significant && fit.opening > 0.0;
    robust = std::min(robust, fit.valid ? fit.f : 0.0);
  }
  result.robust_statistic = robust;
  result.separated = holds;
  return result;
}

}  // namespace arreg::cutting
