#include "tracking/instrument.h"
#include "test_images.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "test_util.h"
#include "tracking/tracker.h"
#include "tracking/video_io.h"

namespace arreg {
namespace {

constexpr int kRows = 360, kCols = 480;

// Pink-red tissue: a band-limited texture modulating a perfused-tissue colour (BGR 80, 90, 200
// at mean brightness), shifted by (dx, dy) (a slow pan).
cv::Mat Tissue(double dx, double dy) {
  static const cv::Mat texture = testing::BandLimitedTexture(kRows + 40, kCols + 40, 5, 128, 30);
  cv::Mat shifted;
  const cv::Matx23d m(1, 0, dx - 20, 0, 1, dy - 20);
  cv::warpAffine(texture, shifted, m, cv::Size(kCols, kRows), cv::INTER_CUBIC, cv::BORDER_REFLECT);
  cv::Mat bgr(kRows, kCols, CV_8UC3);
  for (int r = 0; r < kRows; ++r)
    for (int c = 0; c < kCols; ++c) {
      const double s = shifted.at<uint8_t>(r, c) / 128.0;
      bgr.at<cv::Vec3b>(r, c) =
          cv::Vec3b(cv::saturate_cast<uint8_t>(80 * s), cv::saturate_cast<uint8_t>(90 * s),
                    cv::saturate_cast<uint8_t>(200 * s));
    }
  return bgr;
}

// A metal bar (an instrument shaft) 60 px wide from the right edge to its tip, turned by
// angle_deg about the tip: brushed grey steel (its own texture, a faint blue cast) with a
// highlight along its axis. Its pose in the image: tip at `tip`.
struct Bar {
  cv::Point2d tip;
  double angle_deg = 0;
  std::vector<cv::Point> Outline() const {
    const double a = angle_deg * M_PI / 180;
    const cv::Point2d axis(std::cos(a), std::sin(a)), normal(-axis.y, axis.x);
    const cv::Point2d p[4] = {tip - normal * 30.0, tip + axis * 600.0 - normal * 30.0,
                              tip + axis * 600.0 + normal * 30.0, tip + normal * 30.0};
    std::vector<cv::Point> outline;
    for (const cv::Point2d& q : p)
      outline.emplace_back(static_cast<int>(std::lround(q.x)), static_cast<int>(std::lround(q.y)));
    return outline;
  }
  // Bar coordinates (along the axis, across) of image point p.
  cv::Point2d Local(cv::Point2d p) const {
    const double a = angle_deg * M_PI / 180;
    const cv::Point2d axis(std::cos(a), std::sin(a)), normal(-axis.y, axis.x);
    return {(p - tip).dot(axis), (p - tip).dot(normal)};
  }
};

// Draws the bar over `bgr`; with `jaw_like_tissue`, its first 70 px (the jaws) carry a reddish
// reflection of the tissue colour that the colour mask does not catch.
void DrawBar(const Bar& bar, cv::Mat* bgr, bool jaw_like_tissue = false) {
  static const cv::Mat steel = testing::BandLimitedTexture(200, 800, 9, 150, 28);
  for (int r = 0; r < bgr->rows; ++r)
    for (int c = 0; c < bgr->cols; ++c) {
      const cv::Point2d q = bar.Local(cv::Point2d(c, r));
      if (q.x < 0 || std::abs(q.y) > 30) continue;
      // The texture is fixed to the bar: it moves rigidly with it.
      const int tx = std::clamp(static_cast<int>(q.x) + 100, 0, steel.cols - 1);
      const int ty = std::clamp(static_cast<int>(q.y) + 100, 0, steel.rows - 1);
      double g = steel.at<uint8_t>(ty, tx);
      if (std::abs(q.y + 8) < 3) g = 250;  // highlight along the cylinder
      if (jaw_like_tissue && q.x < 70)
        bgr->at<cv::Vec3b>(r, c) =
            cv::Vec3b(cv::saturate_cast<uint8_t>(0.55 * g), cv::saturate_cast<uint8_t>(0.6 * g),
                      cv::saturate_cast<uint8_t>(1.25 * g));
      else
        bgr->at<cv::Vec3b>(r, c) =
            cv::Vec3b(cv::saturate_cast<uint8_t>(1.03 * g), cv::saturate_cast<uint8_t>(g),
                      cv::saturate_cast<uint8_t>(0.96 * g));
    }
}

bool Inside(const std::vector<cv::Point>& polygon, cv::Point2f p, double margin = 0) {
  return cv::pointPolygonTest(polygon, p, true) > -margin;
}

TEST(InstrumentMask, CoversAMetalBarAndSparesPinkTissue) {
  const Bar bar{{200, 170}, -12};
  cv::Mat image = Tissue(0, 0);
  DrawBar(bar, &image);
  InstrumentMaskOptions options;
  const cv::Mat mask = InstrumentMask(image, options);
  ASSERT_EQ(mask.type(), CV_8UC1);
  ASSERT_EQ(mask.size(), image.size());
  const std::vector<cv::Point> outline = bar.Outline();
  int bar_pixels = 0, bar_covered = 0, tissue_pixels = 0, tissue_flagged = 0;
  for (int r = 0; r < kRows; ++r)
    for (int c = 0; c < kCols; ++c) {
      const double d = cv::pointPolygonTest(outline, cv::Point2f(c, r), true);
      if (d > 0) {
        ++bar_pixels;
        bar_covered += mask.at<uint8_t>(r, c) != 0;
      } else if (d < -(options.margin_px + 2)) {
        ++tissue_pixels;
        tissue_flagged += mask.at<uint8_t>(r, c) != 0;
      }
    }
  std::printf("bar covered %.4f, tissue flagged %.4f\n", 1.0 * bar_covered / bar_pixels,
              1.0 * tissue_flagged / tissue_pixels);
  EXPECT_GE(bar_covered, 0.99 * bar_pixels);
  EXPECT_LE(tissue_flagged, 0.002 * tissue_pixels);
  // Tissue alone: nothing.
  EXPECT_EQ(cv::countNonZero(InstrumentMask(Tissue(0, 0), options)), 0);
}

TEST(InstrumentMask, RejectsBadInput) {
  InstrumentMaskOptions options;
  EXPECT_THROW(InstrumentMask(cv::Mat(10, 10, CV_8UC1, cv::Scalar(0)), options), Error);
  options.seed_max_warmth = 20;  // above grow_max_warmth
  EXPECT_THROW(options.Check(), Error);
  options = InstrumentMaskOptions();
  options.downscale = 0;
  EXPECT_THROW(options.Check(), Error);
  InstrumentMotionOptions motion;
  motion.min_group = 1;
  EXPECT_THROW(motion.Check(), Error);
}

// A grey bar slides and turns over slowly panning tissue for 12 frames: without rejection SURF
// finds points on it and LK carries them along; with it none is detected on the bar, features
// are dropped where it covers them, and the tissue's features away from the bar are kept.
TEST(InstrumentRejection, AMetalBarMovingOverTissueLosesItsFeaturesAndTissueKeepsItsOwn) {
  constexpr int kFrames = 12;
  std::vector<Bar> bars;
  std::vector<cv::Mat> frames;
  for (int f = 0; f <= kFrames; ++f) {
    bars.push_back(Bar{{150.0 + 4.0 * f, 160.0 + 1.5 * f}, -10.0 + 0.5 * f});
    frames.push_back(Tissue(0.3 * f, 0.2 * f));
    DrawBar(bars.back(), &frames.back());
  }
  struct Counts {
    int on_bar_detected = 0, on_bar_tracked_late = 0, tissue_far = 0, tissue_far_kept = 0;
    int rejected = 0;
  };
  auto run = [&](bool reject) {
    FeatureTrackerOptions options;
    options.instruments.enabled = reject;
    FeatureTracker tracker(options);
    tracker.Initialize(frames[0]);
    Counts n;
    for (const FeatureState& f : tracker.current())
      n.on_bar_detected += Inside(bars[0].Outline(), f.position_px);
    for (int k = 1; k <= kFrames; ++k) {
      const TrackFrameSummary s = tracker.Track(frames[k]);
      n.rejected += s.count[static_cast<int>(TrackStatus::kInstrument)];
      for (const FeatureState& f : tracker.current())
        if (k == kFrames && f.status == TrackStatus::kTracked)
          n.on_bar_tracked_late += Inside(bars[k].Outline(), f.position_px);
    }
    // Tissue features that the bar never came near (20 px) in any frame: kept?
    for (int id = 0; id < tracker.store().num_features(); ++id) {
      const std::vector<TrackObservation>& h = tracker.store().history(id);
      bool far = true;
      for (int k = 0; k <= kFrames && far; ++k) {
        // Where the tissue point is at frame k (the pan is known).
        const cv::Point2f p = h.front().position_px + cv::Point2f(0.3f * k, 0.2f * k);
        far = !Inside(bars[k].Outline(), p, 20);
      }
      if (!far) continue;
      ++n.tissue_far;
      n.tissue_far_kept += tracker.store().last_status(id) == TrackStatus::kTracked;
    }
    return n;
  };
  const Counts off = run(false), on = run(true);
  std::printf(
      "without rejection: %d features detected on the bar, %d tracked on it at frame 12, tissue "
      "kept %d / %d\nwith: %d, %d, tissue kept %d / %d, %d rejected\n",
      off.on_bar_detected, off.on_bar_tracked_late, off.tissue_far_kept, off.tissue_far,
      on.on_bar_detected, on.on_bar_tracked_late, on.tissue_far_kept, on.tissue_far, on.rejected);
  // The bar is textured: without rejection SURF and LK use it.
  EXPECT_GE(off.on_bar_detected, 20);
  EXPECT_GE(off.on_bar_tracked_late, 10);
  EXPECT_EQ(on.on_bar_detected, 0);
  EXPECT_EQ(on.on_bar_tracked_late, 0);
  ASSERT_GE(on.tissue_far, 100);
  EXPECT_GE(on.tissue_far_kept, 0.97 * on.tissue_far);
  EXPECT_GE(on.tissue_far_kept, off.tissue_far_kept - 2);
}

// A window holds the bar when any mask pixel lies in the lk.window_px square around the point:
// the tip of the bar is at (200, 170) pointing left (angle 0), so the bar covers x >= 200,
// |y - 170| <= 30, and the mask's margin widens it by margin_px.
TEST(InstrumentRejection, WindowOnInstrumentIsTheMaskInTheTrackingWindow) {
  const Bar bar{{200, 170}, 0};
  cv::Mat image = Tissue(0, 0);
  DrawBar(bar, &image);
  FeatureTrackerOptions options;
  options.instruments.enabled = true;
  FeatureTracker tracker(options);
  tracker.Initialize(image);
  const cv::Mat& mask = tracker.instrument_mask();
  ASSERT_FALSE(mask.empty());
  const int half = options.lk.window_px / 2;
  // Against the mask itself, at every 3rd pixel of a region around the tip.
  int checked = 0, on = 0;
  for (int y = 100; y < 240; y += 3)
    for (int x = 120; x < 280; x += 3) {
      const cv::Rect window = cv::Rect(x - half, y - half, 2 * half + 1, 2 * half + 1) &
                              cv::Rect(0, 0, mask.cols, mask.rows);
      const bool expected = cv::countNonZero(mask(window)) > 0;
      EXPECT_EQ(tracker.WindowOnInstrument(cv::Point2f(x, y)), expected) << x << ", " << y;
      ++checked;
      on += expected;
    }
  EXPECT_GT(on, checked / 10);
  EXPECT_LT(on, checked - checked / 10);
  // Geometry: on the bar, and just beside it within half a window; tissue far from it.
  EXPECT_TRUE(tracker.WindowOnInstrument(cv::Point2f(260, 170)));
  EXPECT_TRUE(tracker.WindowOnInstrument(cv::Point2f(260, 170 + 30 + half - 1)));
  EXPECT_FALSE(tracker.WindowOnInstrument(cv::Point2f(260, 170 + 30 + half + 20)));
  EXPECT_FALSE(tracker.WindowOnInstrument(cv::Point2f(100, 170)));
  // Without instrument rejection there is no mask: never.
  FeatureTracker plain{FeatureTrackerOptions()};
  plain.Initialize(image);
  EXPECT_FALSE(plain.WindowOnInstrument(cv::Point2f(260, 170)));
}

// The ROI still rules: features are detected and followed only inside it and off the mask, and
// the caller's ROI image is left as it was.
TEST(InstrumentRejection, TheRoiIsKeptAndLeftUnchanged) {
  const Bar bar{{200, 170}, -12};
  cv::Mat image = Tissue(0, 0);
  DrawBar(bar, &image);
  cv::Mat roi(image.size(), CV_8UC1, cv::Scalar(0));
  cv::rectangle(roi, cv::Rect(100, 60, 300, 240), cv::Scalar(255), cv::FILLED);
  const cv::Mat roi_before = roi.clone();
  FeatureTrackerOptions options;
  options.instruments.enabled = true;
  FeatureTracker tracker(options);
  tracker.Initialize(image, roi);
  tracker.Track(image, roi);
  EXPECT_EQ(cv::norm(roi, roi_before, cv::NORM_INF), 0.0);
  ASSERT_GT(tracker.num_active(), 50);
  for (const FeatureState& f : tracker.current()) {
    const cv::Point p(static_cast<int>(std::lround(f.position_px.x)),
                      static_cast<int>(std::lround(f.position_px.y)));
    EXPECT_NE(roi.at<uint8_t>(p), 0) << "feature " << f.id << " outside the ROI at " << p;
    EXPECT_FALSE(Inside(bar.Outline(), f.position_px)) << "feature " << f.id << " on the bar";
  }
}

// RigidInstrumentMotion: tissue deforms smoothly (a pan plus a sinusoidal stretch), a group of
// points next to it turns and shifts as one similarity that differs from the tissue's motion.
struct MotionScene {
  std::vector<cv::Point2f> from, to;
  std::vector<uint8_t> near;
  std::vector<bool> instrument;
};

// instrument_shift_px = 0: the "instrument" points move with the tissue under them.
MotionScene MakeMotionScene(double instrument_shift_px, double noise_px, unsigned seed) {
  MotionScene s;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> noise(0, noise_px);
  auto tissue_motion = [](cv::Point2d p) {
    return cv::Point2d(0.8 + 1.5 * std::sin(p.y / 60.0), -0.5 + 1.2 * std::cos(p.x / 80.0));
  };
  // Tissue points over 400 x 300 px (but under the instrument); those within 40 px of the
  // instrument strip are "near".
  for (int i = 0; i < 300; ++i) {
    const cv::Point2d p(400 * u(rng), 300 * u(rng));
    if (p.y > 126 && p.y < 174 && p.x > 196) continue;  // hidden under the instrument
    const cv::Point2d q = p + tissue_motion(p) + cv::Point2d(noise(rng), noise(rng));
    s.from.emplace_back(p), s.to.emplace_back(q);
    s.near.push_back(p.y > 110 && p.y < 190 && p.x > 160);
    s.instrument.push_back(false);
  }
  // 20 instrument points in the strip y 130..170, x 200..400: a similarity (1.5 degrees about
  // (300, 150), scale 1.01, shift) on top of the tissue's motion there.
  const bool rigid = instrument_shift_px != 0;
  const double a = rigid ? 1.5 * M_PI / 180 : 0.0, sc = rigid ? 1.01 : 1.0;
  for (int i = 0; i < 20; ++i) {
    const cv::Point2d p(200 + 200 * u(rng), 130 + 40 * u(rng));
    if (!rigid) {
      s.from.emplace_back(p);
      s.to.emplace_back(p + tissue_motion(p) + cv::Point2d(noise(rng), noise(rng)));
      s.near.push_back(1);
      s.instrument.push_back(true);
      continue;
    }
    const cv::Point2d d = p - cv::Point2d(300, 150);
    const cv::Point2d turned(sc * (std::cos(a) * d.x - std::sin(a) * d.y),
                             sc * (std::sin(a) * d.x + std::cos(a) * d.y));
    const cv::Point2d q = cv::Point2d(300, 150) + turned + tissue_motion(cv::Point2d(300, 150)) +
                          cv::Point2d(instrument_shift_px, 0.5 * instrument_shift_px) +
                          cv::Point2d(noise(rng), noise(rng));
    s.from.emplace_back(p), s.to.emplace_back(q);
    s.near.push_back(1);
    s.instrument.push_back(true);
  }
  return s;
}

TEST(RigidInstrumentMotion, FlagsTheRigidGroupThatMovesAgainstTheTissueAndNothingElse) {
  InstrumentMotionOptions options;
  int instrument = 0, flagged_instrument = 0, flagged_tissue = 0, tissue_near = 0;
  for (unsigned seed = 1; seed <= 20; ++seed) {
    const MotionScene s = MakeMotionScene(4.0, 0.2, seed);
    const std::vector<bool> flags = RigidInstrumentMotion(s.from, s.to, s.near, options);
    for (size_t i = 0; i < flags.size(); ++i) {
      if (s.instrument[i]) {
        ++instrument;
        flagged_instrument += flags[i];
      } else {
        tissue_near += s.near[i];
        flagged_tissue += flags[i];
      }
    }
  }
  std::printf("instrument points flagged %d / %d, tissue flagged %d (%d near)\n",
              flagged_instrument, instrument, flagged_tissue, tissue_near);
  EXPECT_GE(flagged_instrument, 0.95 * instrument);
  EXPECT_LE(flagged_tissue, 0.01 * tissue_near);
}

TEST(RigidInstrumentMotion, AGroupMovingWithTheTissueOrTooSmallIsNotFlagged) {
  InstrumentMotionOptions options;
  for (unsigned seed = 1; seed <= 10; ++seed) {
    // The instrument moves as the tissue under it (held still against it): nothing to tell.
    const MotionScene with_tissue = MakeMotionScene(0.0, 0.2, seed);
    for (bool f :
         RigidInstrumentMotion(with_tissue.from, with_tissue.to, with_tissue.near, options))
      EXPECT_FALSE(f);
  }
  // Only 3 of the group (min_group 4): not a group.
  MotionScene s = MakeMotionScene(4.0, 0.2, 3);
  int kept = 0;
  for (size_t i = s.from.size(); i-- > 0;) {
    if (!s.instrument[i]) continue;
    if (kept++ < 3) continue;
    s.from.erase(s.from.begin() + i), s.to.erase(s.to.begin() + i);
    s.near.erase(s.near.begin() + i), s.instrument.erase(s.instrument.begin() + i);
  }
  for (bool f : RigidInstrumentMotion(s.from, s.to, s.near, options)) EXPECT_FALSE(f);
  // No tissue to compare with: nothing flagged.
  const MotionScene t = MakeMotionScene(4.0, 0.2, 4);
  const std::vector<uint8_t> all_near(t.near.size(), 1);
  for (bool f : RigidInstrumentMotion(t.from, t.to, all_near, options)) EXPECT_FALSE(f);
}

// The jaws of the bar mirror the tissue (reddish: the colour mask misses them); the shaft is
// grey. Features detected on the jaws are followed by LK as the instrument moves, until the
// motion test drops them: they move with one similarity next to the shaft, against the tissue.
TEST(InstrumentRejection, FeaturesOnJawsTheColourMissesAreDroppedByTheirRigidMotion) {
  auto frame = [](int f, Bar* bar) {
    *bar = Bar{{120.0 + 3.0 * f, 150.0 - 1.0 * f}, 5.0 + 0.4 * f};
    cv::Mat image = Tissue(0, 0);
    DrawBar(*bar, &image, true);
    return image;
  };
  auto run = [&](bool motion, bool after_instrument = false) {
    FeatureTrackerOptions options;
    options.instruments.enabled = true;
    options.instruments.motion.enabled = motion;
    options.reidentify.after_instrument = after_instrument;
    FeatureTracker tracker(options);
    Bar bar;
    tracker.Initialize(frame(0, &bar));
    std::vector<int> on_jaws;
    for (const FeatureState& f : tracker.current()) {
      const cv::Point2d q = bar.Local(f.position_px);
      if (q.x > 2 && q.x < 68 && std::abs(q.y) < 28) on_jaws.push_back(f.id);
    }
    for (int k = 1; k <= 6; ++k) tracker.Track(frame(k, &bar));
    int still_tracked = 0;
    for (int id : on_jaws)
      still_tracked += tracker.store().last_status(id) == TrackStatus::kTracked;
    return std::make_pair(static_cast<int>(on_jaws.size()), still_tracked);
  };
  const auto [jaws_off, tracked_off] = run(false);
  const auto [jaws_on, tracked_on] = run(true);
  // Riders are re-identified after an instrument only when their look at acquisition was tissue:
  // the jaws' features were detected on the instrument and stay dropped.
  const auto [jaws_after, tracked_after] = run(true, true);
  std::printf(
      "features on the jaws %d: still tracked after 6 frames %d without the motion test, "
      "%d with it, %d with it and after_instrument\n",
      jaws_on, tracked_off, tracked_on, tracked_after);
  EXPECT_EQ(jaws_after, jaws_on);
  EXPECT_LE(tracked_after, 0.2 * jaws_on);
  EXPECT_EQ(jaws_off, jaws_on);
  ASSERT_GE(jaws_on, 8) << "the colour mask must leave the reddish jaws to the motion test";
  EXPECT_GE(tracked_off, 0.5 * jaws_off) << "LK follows the jaws";
  // Measured: 3 of 32 left (on the jaws' border with the tissue, where LK's window straddles
  // both and the motion is neither the instrument's nor the tissue's).
  EXPECT_LE(tracked_on, 0.2 * jaws_on);
}

// A bar sweeps down over panning tissue (10 px per frame, its tip at x = 150: it covers the
// tissue right of x = 150, a 60 px band of rows at a time) and leaves the image at frame 43. The
// features it took (landed on its mask, dragged along by its edge, or jumping beside it) are
// tissue: with ReidentifyOptions::after_instrument they are found again where the pan carried them,
// matched against their look at acquisition; without it, those that rode it or jumped never come
// back.
TEST(InstrumentRejection, TissueTheBarPassedOverIsFoundAgainWhereThePanCarriedIt) {
  constexpr int kFrames = 55;
  const cv::Point2f pan(0.6f, -0.4f);  // px per frame
  auto bar_at = [](int f) { return Bar{{150.0, -40.0 + 10.0 * f}, 0.0}; };
  std::vector<cv::Mat> frames;
  for (int f = 0; f <= kFrames; ++f) {
    frames.push_back(Tissue(pan.x * f, pan.y * f));
    DrawBar(bar_at(f), &frames.back());  // gone below the image from frame 43
  }
  struct Counts {
    int taken = 0, back = 0, back_off = 0;
  };
  auto run = [&](bool after_instrument) {
    FeatureTrackerOptions options;
    options.instruments.enabled = true;
    options.reidentify.after_instrument = after_instrument;
    FeatureTracker tracker(options);
    tracker.Initialize(frames[0]);
    Counts n;
    std::vector<int> taken;
    for (int k = 1; k <= kFrames; ++k) {
      tracker.Track(frames[k]);
      for (const FeatureState& f : tracker.current())
        if (f.status == TrackStatus::kInstrument || f.status == TrackStatus::kOutlierSpatioTemporal)
          taken.push_back(f.id);
    }
    std::sort(taken.begin(), taken.end());
    taken.erase(std::unique(taken.begin(), taken.end()), taken.end());
    const Bar last = bar_at(kFrames);
    for (int id : taken) {
      // Tissue at frame 0 (away from the bar then), where the bar has passed by the end.
      const cv::Point2f p0 = tracker.store().history(id).front().position_px;
      if (Inside(bar_at(0).Outline(), p0, 30)) continue;
      const cv::Point2f truth = p0 + pan * static_cast<float>(kFrames);
      if (Inside(last.Outline(), truth, 30)) continue;
      ++n.taken;
      if (tracker.store().last_status(id) != TrackStatus::kTracked) continue;
      const cv::Point2f now = tracker.store().history(id).back().position_px;
      ++n.back;
      n.back_off += cv::norm(now - truth) > 1.0;
    }
    return n;
  };
  const Counts off = run(false), on = run(true);
  std::printf(
      "tissue features the bar took: %d; tracked at frame %d without after_instrument %d (%d "
      "more than 1 px off), with it %d of %d (%d off)\n",
      off.taken, kFrames, off.back, off.back_off, on.back, on.taken, on.back_off);
  ASSERT_GE(on.taken, 40);
  EXPECT_LE(on.back_off, 0.05 * on.back);
  EXPECT_GE(on.back, 0.8 * on.taken);
  EXPECT_GE(on.back, off.back + 0.1 * on.taken);
}

// Real clip: hand-labelled instrument polygons (tests/data/instruments) at frames 0, 30 and 60;
// features tracked inside them with and without rejection, and tissue features rejected.
TEST(InstrumentRejection, RealClipFeaturesOnTheLabelledInstrumentsAreDropped) {
  ARREG_REQUIRE_SHARED(path, "real/pulling_tissue.mp4");
  nlohmann::json labels;
  std::ifstream(std::string(ARREG_SOURCE_DIR) +
                "/tests/data/instruments/pulling_tissue_instruments.json") >>
      labels;
  std::map<int, std::vector<std::vector<cv::Point>>> polygons;
  for (const auto& f : labels.at("frames")) {
    auto& list = polygons[f.at("frame").get<int>()];
    for (const auto& p : f.at("polygons")) {
      list.emplace_back();
      for (const auto& xy : p.at("points")) list.back().emplace_back(xy[0], xy[1]);
    }
  }
  ASSERT_EQ(polygons.size(), 3u);
  // Distance to the nearest labelled instrument (negative inside).
  auto distance = [&](int frame, cv::Point2f p) {
    double d = 1e9;
    for (const auto& poly : polygons.at(frame))
      d = std::min(d, -cv::pointPolygonTest(poly, p, true));
    return d;
  };
  const double kTissueDistancePx = InstrumentMaskOptions().margin_px + 3;
  struct Counts {
    int inside = 0, tissue = 0, tissue_rejected = 0;
    double mask_on_instrument = 0, mask_on_tissue = 0;
  };
  // Frame-0 tissue features of the run without rejection (beyond kTissueDistancePx),
  // and how many of them the mask of the run with it covers (not detected there).
  std::vector<cv::Point2f> tissue_at_0;
  int tissue_at_0_masked = 0, rejected_in_all = 0;
  // Features followed to the last frame (62) off the frame-60 instruments (the instruments move
  // little at the end), per run: [0] without rejection, [1] with it.
  int tissue_survivors[2] = {0, 0}, instrument_survivors[2] = {0, 0};
  auto run = [&](bool reject) {
    FeatureTrackerOptions options;
    options.instruments.enabled = reject;
    FeatureTracker tracker(options);
    VideoReader reader;
    reader.Open(path);
    cv::Mat image;
    std::map<int, Counts> counts;
    for (int frame = 0; reader.Read(&image); ++frame) {
      if (frame == 0)
        tracker.Initialize(image);
      else
        rejected_in_all += tracker.Track(image).count[static_cast<int>(TrackStatus::kInstrument)];
      if (frame == 0 && !reject)
        for (const FeatureState& f : tracker.current())
          if (distance(0, f.position_px) > kTissueDistancePx) tissue_at_0.push_back(f.position_px);
      if (frame == 0 && reject)
        for (const cv::Point2f& p : tissue_at_0)
          tissue_at_0_masked +=
              tracker.instrument_mask().at<uint8_t>(static_cast<int>(std::lround(p.y)),
                                                    static_cast<int>(std::lround(p.x))) != 0;
      if (!polygons.count(frame)) continue;
      Counts& n = counts[frame];
      for (const FeatureState& f : tracker.current()) {
        const double d = distance(frame, f.position_px);
        if (f.status == TrackStatus::kTracked && d < 0) ++n.inside;
        // Tissue: farther from every labelled outline than the mask's margin (features whose
        // window straddles an instrument's edge are rejected on purpose) plus the labels'
        // accuracy (3 px).
        if (d > kTissueDistancePx &&
            (f.status == TrackStatus::kTracked || f.status == TrackStatus::kInstrument)) {
          ++n.tissue;
          n.tissue_rejected += f.status == TrackStatus::kInstrument;
        }
      }
      if (reject) {
        const cv::Mat& mask = tracker.instrument_mask();
        cv::Mat truth(image.size(), CV_8UC1, cv::Scalar(0));
        cv::fillPoly(truth, polygons.at(frame), 255);
        cv::Mat inside, outside, not_truth;
        cv::bitwise_and(mask, truth, inside);
        cv::bitwise_not(truth, not_truth);
        cv::bitwise_and(mask, not_truth, outside);
        n.mask_on_instrument = 1.0 * cv::countNonZero(inside) / cv::countNonZero(truth);
        n.mask_on_tissue = 1.0 * cv::countNonZero(outside) / cv::countNonZero(not_truth);
      }
    }
    for (const FeatureState& f : tracker.current()) {
      if (f.status != TrackStatus::kTracked) continue;
      if (distance(60, f.position_px) > 4)
        ++tissue_survivors[reject];
      else
        ++instrument_survivors[reject];
    }
    return counts;
  };
  const std::map<int, Counts> off = run(false), on = run(true);
  int inside_off = 0, inside_on = 0, tissue = 0, tissue_rejected = 0;
  for (const auto& [frame, n] : on) {
    const Counts& o = off.at(frame);
    std::printf(
        "frame %d: tracked inside the instruments %d without rejection, %d with; tissue features "
        "rejected this frame %d of %d; mask covers %.3f of the instruments, %.3f of the rest\n",
        frame, o.inside, n.inside, n.tissue_rejected, n.tissue, n.mask_on_instrument,
        n.mask_on_tissue);
    inside_off += o.inside, inside_on += n.inside;
    tissue += n.tissue, tissue_rejected += n.tissue_rejected;
  }
  std::printf(
      "frame-0 tissue features on the mask (not detected with rejection): %d of %zu; "
      "features rejected as on an instrument over the clip: %d\n",
      tissue_at_0_masked, tissue_at_0.size(), rejected_in_all);
  std::printf(
      "followed to the end: off the instruments %d without rejection, %d with; on them %d, %d\n",
      tissue_survivors[0], tissue_survivors[1], instrument_survivors[0], instrument_survivors[1]);
  // Measured: 42 and 39 tissue survivors, 8 and 0 on the instruments.
  EXPECT_EQ(instrument_survivors[1], 0);
  EXPECT_GE(tissue_survivors[1], 0.85 * tissue_survivors[0]);
  EXPECT_GE(inside_off, 50) << "the grasper is textured: SURF and LK use it";
  EXPECT_LE(tissue_at_0_masked, 0.02 * tissue_at_0.size());
  EXPECT_LE(inside_on, 0.1 * inside_off);
  EXPECT_LE(tissue_rejected, 0.02 * tissue);
}

}  // namespace
}  // namespace arreg
