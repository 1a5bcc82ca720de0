// The separation test: its distribution functions against tabulated values, its false-alarm rate
// under the continuous model, its power on a jump, and the facts of a cut it checks.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/error.h"
#include "cutting/separation_test.h"

namespace arreg::cutting {
namespace {

TEST(SeparationTest, IncompleteBetaAndFisherQuantilesMatchTables) {
  // I_0.4(2, 3) = sum_{j=2..4} C(4, j) 0.4^j 0.6^(4-j).
  EXPECT_NEAR(RegularizedIncompleteBeta(2.0, 3.0, 0.4), 0.5248, 1e-12);
  EXPECT_NEAR(RegularizedIncompleteBeta(0.5, 0.5, 0.5), 0.5, 1e-12);
  // F tables (Abramowitz & Stegun 26.6) and chi-square(3) at 0.999 = 16.266.
  EXPECT_NEAR(FisherQuantile(0.95, 3.0, 10.0), 3.708, 1e-3);
  EXPECT_NEAR(FisherQuantile(0.99, 3.0, 60.0), 4.126, 1e-3);
  EXPECT_NEAR(FisherQuantile(0.95, 1.0, 1e9), 3.8415, 1e-3);
  EXPECT_NEAR(FisherQuantile(0.999, 3.0, std::numeric_limits<double>::infinity()), 16.266 / 3.0,
              1e-3);
}

// Features on a jittered 4 mm grid in a disc of radius 22 mm of the plane z = 0, rest = current.
struct Patch {
  RowMatX3d rest, current, misfit;
};

Patch MakePatch(std::mt19937* rng) {
  std::uniform_real_distribution<double> jitter(-1.0, 1.0);
  std::vector<Eigen::RowVector3d> points;
  for (double x = -22; x <= 22; x += 4)
    for (double y = -22; y <= 22; y += 4) {
      const Eigen::RowVector3d p(x + jitter(*rng), y + jitter(*rng), 0.0);
      if (p.norm() < 22.0) points.push_back(p);
    }
  Patch patch;
  patch.rest.resize(static_cast<int>(points.size()), 3);
  for (size_t i = 0; i < points.size(); ++i) patch.rest.row(static_cast<int>(i)) = points[i];
  patch.current = patch.rest;
  patch.misfit.setZero(patch.rest.rows(), 3);
  return patch;
}

// A smooth misfit the model misses (a quadratic field, 1-2 mm over the patch) plus noise.
void AddSmoothFieldAndNoise(Patch* patch, double noise_mm, std::mt19937* rng) {
  std::normal_distribution<double> gauss(0.0, noise_mm);
  for (int i = 0; i < patch->rest.rows(); ++i) {
    const double x = patch->rest(i, 0) / 22.0, y = patch->rest(i, 1) / 22.0;
    patch->misfit.row(i) +=
        Eigen::RowVector3d(0.8 * x + 0.6 * x * y, 1.2 * y * y - 0.4 * x, 0.3 * x * x);
    for (int c = 0; c < 3; ++c) patch->misfit(i, c) += gauss(*rng);
  }
}

SeparationTestOptions Options(double alpha) {
  SeparationTestOptions o;
  o.false_alarm_probability = alpha;
  o.noise_floor_mm = 0.01;
  return o;
}

TEST(SeparationTest, FalseAlarmRateUnderTheContinuousModelIsAtMostAlpha) {
  std::mt19937 rng(7);
  const double alpha = 0.05;
  const int trials = 400;
  int alarms = 0;
  for (int t = 0; t < trials; ++t) {
    Patch patch = MakePatch(&rng);
    AddSmoothFieldAndNoise(&patch, 0.2, &rng);
    const SeparationTestResult r = TestSeparation(patch.rest, patch.current, patch.misfit,
                                                  Eigen::Vector3d::Zero(), Options(alpha));
    ASSERT_TRUE(r.tested);
    // Significance alone (the opening and one-feature conditions only lower the rate further).
    alarms += r.statistic > r.threshold;
  }
  // Bonferroni over the directions is conservative: at most alpha, with 3 standard errors.
  EXPECT_LE(alarms, alpha * trials + 3.0 * std::sqrt(alpha * (1 - alpha) * trials));
}

// The patch cut along the line x = offset: the side x > offset has moved by `jump` relative to the
// model (its current points too, so that the pieces separate along +x when jump.x() > 0).
void AddJump(Patch* patch, const Eigen::RowVector3d& jump, double offset = 0.0) {
  for (int i = 0; i < patch->rest.rows(); ++i)
    if (patch->rest(i, 0) > offset) {
      patch->misfit.row(i) += 0.5 * jump;
      patch->current.row(i) += 0.5 * jump;
    } else {
      patch->misfit.row(i) -= 0.5 * jump;
      patch->current.row(i) -= 0.5 * jump;
    }
}

TEST(SeparationTest, AnOpeningJumpIsFoundWithItsDirection) {
  std::mt19937 rng(11);
  for (int t = 0; t < 30; ++t) {
    Patch patch = MakePatch(&rng);
    AddSmoothFieldAndNoise(&patch, 0.2, &rng);
    AddJump(&patch, Eigen::RowVector3d(1.5, 0.3, 0.0), 1.0);
    const SeparationTestResult r = TestSeparation(patch.rest, patch.current, patch.misfit,
                                                  Eigen::Vector3d::Zero(), Options(1e-6));
    ASSERT_TRUE(r.separated) << "trial " << t << " F " << r.statistic << " thr " << r.threshold;
    EXPECT_GT(std::abs(r.normal.x()), std::cos(16.0 * M_PI / 180.0));
    EXPECT_GT(r.opening_mm, 0.5);
    EXPECT_NEAR(std::abs(r.jump_mm.x()), 1.5, 0.4);
  }
}

TEST(SeparationTest, AClosingJumpIsNoCut) {
  std::mt19937 rng(13);
  Patch patch = MakePatch(&rng);
  AddSmoothFieldAndNoise(&patch, 0.2, &rng);
  // The targets of the side x > 0 lie inward of the model: the pieces would interpenetrate.
  for (int i = 0; i < patch.rest.rows(); ++i)
    patch.misfit.row(i) += (patch.rest(i, 0) > 0 ? -0.5 : 0.5) * Eigen::RowVector3d(1.5, 0, 0);
  const SeparationTestResult r = TestSeparation(patch.rest, patch.current, patch.misfit,
                                                Eigen::Vector3d::Zero(), Options(1e-6));
  EXPECT_GT(r.statistic, r.threshold);  // significant,
  EXPECT_LT(r.opening_mm, 0.0);         // but closing
  EXPECT_FALSE(r.separated);
}

TEST(SeparationTest, OneMistrackedFeatureIsNoCut) {
  std::mt19937 rng(17);
  for (int t = 0; t < 20; ++t) {
    Patch patch = MakePatch(&rng);
    AddSmoothFieldAndNoise(&patch, 0.1, &rng);
    // The feature nearest the centre is 4 mm off.
    int nearest = 0;
    patch.rest.rowwise().norm().minCoeff(&nearest);
    patch.misfit.row(nearest) += Eigen::RowVector3d(4.0, 0.0, 0.0);
    const SeparationTestResult r = TestSeparation(patch.rest, patch.current, patch.misfit,
                                                  Eigen::Vector3d::Zero(), Options(1e-6));
    EXPECT_FALSE(r.separated) << "trial " << t;
  }
}

TEST(SeparationTest, AStrainSpreadOverTheNeighbourhoodIsNoCut) {
  // The model misses a stretch concentrated in a band of half-width w around x = 0:
  // misfit_x = A tanh(x / w). Spread over the neighbourhood (w = 11 mm, half its radius) it is
  // a continuous deformation; as w shrinks below the feature spacing it becomes a jump.
  std::mt19937 rng(19);
  int found_wide = 0, found_narrow = 0;
  const int trials = 20;
  for (int t = 0; t < trials; ++t) {
    for (const double w : {11.0, 1.0}) {
      Patch patch = MakePatch(&rng);
      AddSmoothFieldAndNoise(&patch, 0.1, &rng);
      for (int i = 0; i < patch.rest.rows(); ++i) {
        const double u = 1.5 * std::tanh(patch.rest(i, 0) / w);
        patch.misfit(i, 0) += u;
        patch.current(i, 0) += u;
      }
      const SeparationTestResult r = TestSeparation(patch.rest, patch.current, patch.misfit,
                                                    Eigen::Vector3d::Zero(), Options(1e-6));
      (w > 5 ? found_wide : found_narrow) += r.separated;
    }
  }
  EXPECT_EQ(found_wide, 0);
  EXPECT_EQ(found_narrow, trials);
}

TEST(SeparationTest, AGrowingCutIsTestedWithinTheConeOfItsDirection) {
  std::mt19937 rng(23);
  Patch patch = MakePatch(&rng);
  AddSmoothFieldAndNoise(&patch, 0.1, &rng);
  AddJump(&patch, Eigen::RowVector3d(1.5, 0.0, 0.0));
  // The line x = 0 runs along y (only the half y > 0 ahead of c is tested): found when the cone
  // admits it, not when it is 90 degrees off.
  const SeparationTestOptions o = Options(1e-6);
  EXPECT_TRUE(TestSeparation(patch.rest, patch.current, patch.misfit, Eigen::Vector3d::Zero(), o,
                             Eigen::Vector3d(0, 1, 0), 30.0)
                  .separated);
  EXPECT_FALSE(TestSeparation(patch.rest, patch.current, patch.misfit, Eigen::Vector3d::Zero(), o,
                              Eigen::Vector3d(1, 0, 0), 30.0)
                   .separated);
}

TEST(SeparationTest, TooFewFeaturesOnASideAreNotTested) {
  std::mt19937 rng(29);
  Patch patch = MakePatch(&rng);
  const RowMatX3d few = patch.rest.topRows(5);
  const SeparationTestResult r =
      TestSeparation(few, few, RowMatX3d::Zero(5, 3), Eigen::Vector3d::Zero(), Options(1e-6));
  EXPECT_FALSE(r.tested);
  EXPECT_FALSE(r.separated);
  SeparationTestOptions bad;
  bad.false_alarm_probability = 0.0;
  EXPECT_THROW(bad.Check(), Error);
}

}  // namespace
}  // namespace arreg::cutting
