// Sparse feature tracking for the registration (thesis 7.4.1): SURF points in the
// first frame, pyramidal Lucas-Kanade from frame to frame, and the filters that drop bad tracks.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "tracking/affine_refine.h"
#include "tracking/instrument.h"
#include "tracking/lucas_kanade.h"
#include "tracking/surf.h"

namespace arreg {

// Why a feature is (no longer) followed. Anything but kTracked takes the
// feature out of the active set: an outlier or a feature that rode an
// instrument for good, the others until it is re-identified (ReidentifyOptions),
// which continues the same id.
enum class TrackStatus : uint8_t {
  kTracked = 0,            // followed into this frame (or detected in it)
  kLostBorder,             // left the image or came within border_px of its edge
  kLostRoi,                // left the region of interest
  kLostFlow,               // Lucas-Kanade found no solution (flat or occluded window)
  kLostForwardBackward,    // tracking back does not return to the start
  kOutlierSpatioTemporal,  // moved far more than its neighbours in one frame
  kSpecular,               // landed on a specular highlight
  kLostAppearance,         // its window no longer looks like it did when acquired (dragged off)
  kInstrument,             // on a surgical instrument, or moving rigidly with one (instrument.h)
};
constexpr int kNumTrackStatuses = 9;
const char* TrackStatusName(TrackStatus status);

// Spatio-temporal outlier filter (thesis 7.4.1): a feature whose frame-to-frame
// displacement is far above the average displacement of its neighbours jumps
// or slides implausibly and is dropped for good.
struct OutlierFilterOptions {
  bool enabled = true;  // default true
  // Neighbours compared with (k nearest tracked features); 0 compares with the
  // average over all tracked features, as the thesis does. Default 8.
  int neighbours = 8;
  // Outlier when displacement > ratio * neighbours' mean displacement + slack_px. Default 3.
  double ratio = 3.0;
  // Absolute allowance, pixels, so that still scenes (mean ~0) do not flag noise. Default 2.0.
  double slack_px = 2.0;

  void Check() const;  // throws arreg::Error naming the bad field
};

// Specular highlights: bright, colourless pixels whose appearance moves with
// the light, not with the tissue.
struct SpecularOptions {
  bool enabled = true;  // default true
  // Minimum brightness max(B, G, R) of a highlight pixel, 0..255. Default 240.
  int min_value = 240;
  // Maximum HSV saturation 255 * (max - min) / max of a highlight pixel, 0..255
  // (not used for grey input). Default 60.
  int max_saturation = 60;
  // A feature within this many pixels of a highlight pixel is specular. Default 2.
  int radius_px = 2;

  void Check() const;  // throws arreg::Error naming the bad field
};

// Re-identification: a feature lost to occlusion, a failed forward-backward
// check, a highlight or the image border is looked for again among fresh SURF
// points near where its neighbours' motion has carried it, and keeps its id
// when found. Outliers of the spatio-temporal filter are never re-identified.
struct ReidentifyOptions {
  bool enabled = true;  // default true
  // SURF detection and matching every this many frames (while features wait). Default 5.
  int every_frames = 5;
  // A lost feature is forgotten after this many frames. Default 90 (3 s at 30 fps).
  int max_lost_frames = 90;
  // The features tracked both now and at the loss that were nearest to it then:
  // their mean displacement since the loss predicts where it is now. Default 8.
  int neighbours = 8;
  // No prediction (and no search) with fewer such features. Default 3.
  int min_neighbours = 3;
  // A SURF point is a candidate when within this distance of the prediction, pixels. Default 12.
  double gate_px = 12.0;
  // Largest Euclidean distance between the feature's reference descriptor and
  // the candidate's (unit-length 64-D SURF descriptors). The reference is
  // computed afresh (same scale, new orientation) at every re-identification
  // round while the feature is tracked: deforming tissue drifts away from its
  // frame-0 descriptor (median distance 0.18 after 10 frames, 0.45 after 30 on
  // the real clip), not from one a few frames old. Default 0.3.
  double max_descriptor_distance = 0.3;
  // Ratio test: the best candidate's distance must be below `ratio` times the
  // second best's among all points within 2 * gate_px. Default 0.8.
  double ratio = 0.8;
  // The candidate's SURF scale must be within this factor of the feature's
  // scale at detection (and its Laplacian sign the same). Default 2.
  double max_scale_factor = 2.0;
  // Verification of the match by appearance: the normalised cross-correlation
  // of the window_px x window_px patch at the candidate with the patch the
  // feature showed in its last tracked frame must reach this. Blob-like SURF
  // points of unrelated texture can have close descriptors (0.29 in
  // tests/tracking, passing the ratio test) but their patches do not correlate
  // (0.1); on the real clip the descriptor matches correlate with median 0.72,
  // as tissue deforms while hidden. Default 0.6.
  double min_patch_correlation = 0.6;
  // Compute the SURF responses only around the predictions
  // (SurfDetector::DetectNear: the same points) instead of on the whole frame;
  // false is the reference this reproduces. Default true.
  bool search_near_predictions = true;
  // Re-acquisition by Lucas-Kanade: a waiting feature that no SURF point
  // matched is followed, at level 0, from the patch it showed in its last
  // tracked frame, starting at its prediction; it is found when LK converges
  // within gate_px of the prediction, the patch there correlates with the
  // template by at least min_lk_correlation and LK from there back into the
  // feature's old surroundings returns within 1 px. SURF needs a detector
  // response at the feature; this does not (real clip: 37 -> 53 survivors of
  // 352). Default true.
  bool reacquire_by_lk = true;
  // Least normalised cross-correlation for re-acquisition by LK (stricter than
  // min_patch_correlation: no descriptor supports the match). Default 0.8.
  double min_lk_correlation = 0.8;
  // Features that an instrument passing over the tissue took (with
  // InstrumentRejectionOptions on): those that landed on its mask, rode it (the
  // motion test) or jumped beside it (a spatio-temporal outlier within the
  // motion band_px of the mask or of features just dropped as on it). The
  // instrument occluded or dragged tissue, which reappears where the tissue
  // moved once it has passed. With this on, such a feature waits to be
  // re-identified like the others when its window at acquisition lay at least
  // band_px from every instrument pixel (the look is tissue, not a part of the
  // instrument the colour mask misses), and it is matched, by SURF and by LK,
  // against that look (its last look may be the instrument's edge), and only
  // at least band_px from an instrument. Default false.
  bool after_instrument = false;

  void Check() const;  // throws arreg::Error naming the bad field
};

// Appearance check against the feature's look at acquisition: an occluder
// edge sliding slowly over textured tissue drags the features in front of it
// along (each frame-to-frame step is small and consistent both ways, so the
// forward-backward check and the outlier filter pass it). Every
// `every_frames` frames the window_px x window_px window at each tracked
// feature is compared (normalised cross-correlation) with its window when it
// was detected or last re-identified; below `min_correlation` it is lost
// (kLostAppearance). Such a feature may be re-identified, by SURF only and
// verified against its look at acquisition (its last look may be the edge
// that dragged it). tests/tracking: a 40 px bar of other texture sliding at
// 1, 2, 3 px per frame over a static texture leaves 36 of 36, 82 of 100, 111
// of 154 swept features tracked more than 3 px from their place at the end
// without the check, 5, 5, 2 with it. Off by default: on the real clip tissue that deforms over
// 30-50 frames falls below 0.5 too (vessels on the stretched left tissue), and the survivors drop
// from 53 to 34 of 352 (docs/tracking.md).
struct AppearanceCheckOptions {
  bool enabled = false;  // default false
  // Frames between checks (the check runs when the frame index is a multiple). Default 5.
  int every_frames = 5;
  // Least correlation with the window at acquisition, in [-1, 1]. Default 0.5.
  double min_correlation = 0.5;

  void Check() const;  // throws arreg::Error naming the bad field
};

struct FeatureTrackerOptions {
  // Detector. Endoscopic tissue is low-contrast, so the default Hessian
  // threshold is 8 instead of SURF's usual 100; max_keypoints is ignored (max_features rules).
  SurfOptions surf = SurfOptions{8.0};
  LucasKanadeOptions lk;
  OutlierFilterOptions outliers;
  SpecularOptions specular;
  ReidentifyOptions reidentify;
  AppearanceCheckOptions appearance;
  // Drift correction: every few frames each tracked feature's window at acquisition is
  // aligned to the frame with an affine warp from where Lucas-Kanade put it
  // (affine_refine.h); the feature moves there when it matches.
  DriftCorrectionOptions drift;
  // Features on surgical instruments (colour mask) or moving rigidly with one are dropped
  // (kInstrument); none is detected or re-identified on the mask. BGR input only.
  InstrumentRejectionOptions instruments;
  // Most features followed at once. Default 1000.
  int max_features = 1000;
  // Fewest features wanted after a detection (0 = off, the default). When the points above
  // surf.hessian_threshold leave fewer features followed than this, weaker points, down to
  // min_hessian_threshold, are added strongest first until there are this many (or none is
  // left). The points above the threshold are always all taken, as without the option, so a
  // well textured image gets exactly the same features; a weakly textured one is not left with
  // too few to cover it.
  int min_features = 0;
  // Weakest Hessian response taken to reach min_features. Default 0.5.
  double min_hessian_threshold = 0.5;
  // Detected features closer than this to a stronger one are skipped, pixels. Default 4.
  double min_distance_px = 4.0;
  // Features within this distance of the image edge are lost (kLostBorder), pixels. Default 4.
  int border_px = 4;
  // Re-detection: every `redetect_every_frames` frames (0 = never, the default)
  // new SURF points fill the ROI away from the followed ones; they get new ids.
  int redetect_every_frames = 0;
  // Re-detection fills holes only: with s the median distance from each frame-0 feature to its
  // nearest other one, a re-detected point lies at least redetect_hole_factor * s from every
  // followed feature and at least s from the other new points, so an area whose features were
  // lost (occlusion, tissue turning away) is covered again at frame 0's density while a
  // well-covered area gets nothing. Features lost one by one leave no hole; a patch of them
  // does. 0 = fill anywhere, min_distance_px apart. Default 2.
  double redetect_hole_factor = 2.0;

  void Check() const;  // throws arreg::Error naming the bad field
};

// One observation of one feature.
struct TrackObservation {
  int frame = 0;
  cv::Point2f position_px;  // where it was (for lost features: where LK put it)
  TrackStatus status = TrackStatus::kTracked;
  bool reidentified = false;  // found again in this frame after a loss
};

// Every feature ever detected, by id (0, 1, 2, ... in order of detection):
// its SURF keypoint and descriptor at detection and its history.
class TrackStore {
 public:
  // Registers a new feature; returns its id. `descriptor_row` is (1 x 64) CV_32F.
  int Add(const SurfKeypoint& keypoint, const cv::Mat& descriptor_row);
  void Record(int id, const TrackObservation& observation);

  int num_features() const { return static_cast<int>(histories_.size()); }
  const std::vector<TrackObservation>& history(int id) const;
  const SurfKeypoint& keypoint(int id) const;
  // (1 x 64) CV_32F descriptor at detection.
  cv::Mat descriptor(int id) const;
  // (#features x 64) CV_32F, row = id.
  const cv::Mat& descriptors() const { return descriptors_; }
  TrackStatus last_status(int id) const { return history(id).back().status; }
  int first_frame(int id) const { return history(id).front().frame; }

  // Writes the histories as CSV (id,frame,x,y,status) atomically.
  void WriteCsv(const std::string& path) const;

 private:
  std::vector<std::vector<TrackObservation>> histories_;
  std::vector<SurfKeypoint> keypoints_;
  cv::Mat descriptors_;
};

// A feature as seen in the current frame.
struct FeatureState {
  int id = 0;
  cv::Point2f position_px;
  cv::Point2f displacement_px;  // since the previous frame (0 for new features)
  TrackStatus status = TrackStatus::kTracked;
};

struct TrackFrameSummary {
  int frame = 0;
  int num_active = 0;                          // features tracked into this frame
  int num_new = 0;                             // of them, detected in this frame
  int num_reidentified = 0;                    // of them, lost before and found again
  std::array<int, kNumTrackStatuses> count{};  // features per status in this frame
};

// Follows SURF features through a video. Input images are CV_8UC1 or CV_8UC3
// (BGR; then highlights are told by their saturation too); ROI masks are
// CV_8UC1 of the image size, nonzero inside, or empty for the whole image.
class FeatureTracker {
 public:
  explicit FeatureTracker(const FeatureTrackerOptions& options = {});

  // Detects the features in the first frame (inside `roi_mask`, off highlights).
  TrackFrameSummary Initialize(const cv::Mat& image, const cv::Mat& roi_mask = cv::Mat());
  // Follows the active features into the next frame; `roi_mask` may change per
  // frame (e.g. the projected model silhouette).
  TrackFrameSummary Track(const cv::Mat& image, const cv::Mat& roi_mask = cv::Mat());

  // Active features plus those lost in the last frame (with their status).
  const std::vector<FeatureState>& current() const { return current_; }
  int num_active() const;
  int frame() const { return frame_; }
  const TrackStore& store() const { return store_; }
  const FeatureTrackerOptions& options() const { return options_; }
  // The current frame's instrument mask (CV_8UC1, 255 on instruments; empty when
  // instruments.enabled is off or the input is grey).
  const cv::Mat& instrument_mask() const { return instrument_mask_; }
  // Whether an instrument mask pixel lies in the lk.window_px square window centred on p: a
  // track there follows a window that holds two motions, the tissue's and the instrument's.
  bool WindowOnInstrument(cv::Point2f p) const;

 private:
  void PrepareFrame(const cv::Mat& image, const cv::Mat& roi_mask);
  bool IsSpecular(cv::Point2f p) const;
  bool InsideRoi(cv::Point2f p, const cv::Mat& roi_mask) const;
  // Detects new features in the current frame away from the active ones.
  int Detect(const cv::Mat& roi_mask);
  // Median distance from each frame-0 feature to its nearest other one, pixels (0 when fewer
  // than two): the spacing re-detection fills holes with.
  double initial_spacing_px_ = 0.0;
  // Remembers the features lost in this frame that may be re-identified later.
  void RememberLost();
  // Looks for the remembered features among this frame's SURF points.
  int Reidentify(const cv::Mat& roi_mask);

  // Sets the reference descriptors of the features lost in this frame: as of
  // the last re-identification round where they were tracked (round_surf_
  // still holds that frame), else their descriptor at detection.
  void ReferenceDescriptorsOfLost(const std::vector<int>& lost_ids);
  // Gives features detected since the last call their descriptor at detection as reference.
  void SyncReferenceDescriptors();

  // A lost feature waiting to be re-identified: where it was last followed,
  // in the frame before the loss.
  struct LostFeature {
    int id = 0;
    int lost_frame = 0;
    cv::Point2f position_px;
    std::vector<float> patch;  // window_px^2 grey levels around it, row by row
    // (window_px + 2 kReacquireMarginPx)^2 around it: the gradient of the
    // template and the target of the backward check of re-acquisition by LK.
    std::vector<float> surroundings;
    // Taken by an instrument (ReidentifyOptions::after_instrument): found only away from one.
    bool after_instrument = false;
  };
  static constexpr int kReacquireMarginPx = 10;
  // Re-acquisition by LK of the features Reidentify predicted but did not find.
  int Reacquire(const cv::Mat& roi_mask);
  // A lost feature found again at `position_px` continues its id as tracked in
  // the current frame (its observation marked re-identified).
  void Restore(int id, const cv::Point2f& position_px);
  // Removes the lost features with found[l] != 0, keeping the others' order.
  void ForgetFound(const std::vector<uint8_t>& found);
  std::vector<std::pair<int, cv::Point2f>> predictions_;  // (id, prediction) of the last round

  FeatureTrackerOptions options_;
  SurfDetector surf_;
  // The frame of the last re-identification round (round_frame_, -1 before
  // the first), kept until the next: its SURF points are searched, and the
  // reference descriptor of a feature lost later is computed from it, at the
  // feature's position then. Computing it at the loss, for the few features
  // lost, gives the descriptor a refresh of every tracked feature at every
  // round would have given.
  SurfDetector round_surf_;
  // Detects at min_hessian_threshold when the points above the threshold are too few.
  SurfDetector weak_surf_;
  int round_frame_ = -1;
  int frame_ = -1;
  cv::Mat gray_, bgr_;  // current frame (bgr_ empty for grey input)
  LucasKanadePyramid pyramid_, previous_pyramid_;
  std::vector<FeatureState> current_;
  std::vector<cv::Point2f> previous_position_;  // per current_ entry: position in the frame before
  std::vector<LostFeature> lost_;
  // (#features x 64) CV_32F, row = id: the descriptor re-identification compares
  // with (set for lost features: ReferenceDescriptorsOfLost).
  cv::Mat reference_descriptors_;
  TrackStore store_;
  // Per id: its window_px^2 window (row by row) in the frame where it was
  // detected or last re-identified (AppearanceCheckOptions,
  // ReidentifyOptions::after_instrument).
  std::vector<std::vector<float>> acquired_look_;
  // Per id, with ReidentifyOptions::after_instrument: the (window_px + 2
  // kReacquireMarginPx)^2 surroundings of that window (re-acquisition by LK from
  // the look at acquisition), and whether no instrument pixel lay within the
  // motion band_px of it then.
  std::vector<std::vector<float>> acquired_surroundings_;
  std::vector<uint8_t> acquired_clean_;
  // Whether an instrument mask pixel, or a feature dropped as on an instrument in the last
  // kInstrumentMemoryFrames frames, lies within the motion band_px of p.
  bool NearInstrument(cv::Point2f p) const;
  // Whether features dropped beside an instrument wait for re-identification
  // (ReidentifyOptions::after_instrument with instrument rejection on).
  bool ReidentifyAfterInstrument() const;
  // Keeps the current frame's window at `position_px` as the look of feature `id`.
  void RememberLook(int id, cv::Point2f position_px);
  // Marks the tracked features of current_ whose window no longer correlates
  // with their look at acquisition kLostAppearance.
  void CheckAppearance();
  // Per id: its window in the frame where it was detected or last re-identified,
  // as an affine anchor (DriftCorrectionOptions; side 0 when the window could not
  // anchor or the feature is lost), and the linear part of its last accepted warp.
  struct DriftAnchor {
    AffineAnchor window;
    cv::Matx22f linear = cv::Matx22f::eye();
  };
  std::vector<DriftAnchor> anchors_;
  cv::Mat roi_;  // the current frame's ROI mask (empty: the whole image)
  // Instrument rejection: the current frame's mask, and the ROI without it (where features
  // may be detected and re-identified; the ROI itself when there is no mask).
  cv::Mat instrument_mask_, free_roi_;
  bool instrument_in_frame_ = false;  // instrument_mask_ has a pixel set this frame
  bool OnInstrument(cv::Point2f p) const;
  // Marks the features of current_ that ride an instrument (RigidInstrumentMotion) kInstrument.
  void RejectRigidInstrumentMotion();
  // (frame, position) of the features dropped as on an instrument in the last few frames:
  // features near them are candidates of the motion test too (the instrument's parts that the
  // colour mask misses, e.g. jaws mirroring the tissue, are found by their features).
  static constexpr int kInstrumentMemoryFrames = 3;
  std::vector<std::pair<int, cv::Point2f>> instrument_seen_;
  // The previous frame's instrument mask shrunk by its downscale (static regions are no
  // instruments for the motion test).
  cv::Mat previous_small_mask_;
  // Per id: dropped by the motion test (it rode an instrument; never re-identified).
  std::vector<uint8_t> rode_;
  // Anchors feature `id` at `position_px` in the current frame.
  void Anchor(int id, cv::Point2f position_px);
  // Moves the tracked features of current_ to where their anchors align.
  void CorrectDrift();
  // Scratch kept between frames to avoid reallocation.
  std::vector<cv::Point2f> points_from_, points_to_, points_back_;
  std::vector<uint8_t> lk_status_, lk_status_back_;
  std::vector<int> candidates_;
  std::vector<cv::Point2f> candidate_positions_, candidate_displacements_;
  std::vector<bool> outlier_flags_;
};

// The spatio-temporal test on its own: flags[i] is true when |displacements_px[i]|
// exceeds options.ratio times the mean displacement magnitude of the
// options.neighbours nearest other points (of all others when 0) plus
// options.slack_px. Positions are where the points are now.
std::vector<bool> SpatioTemporalOutliers(const std::vector<cv::Point2f>& positions_px,
                                         const std::vector<cv::Point2f>& displacements_px,
                                         const OutlierFilterOptions& options);

// Highlight mask (CV_8UC1, 255 on highlight pixels) of a BGR or grey image.
cv::Mat SpecularMask(const cv::Mat& image, const SpecularOptions& options);

// Reads a mask image (any non-zero pixel is inside) and checks its size.
cv::Mat ReadMask(const std::string& path, int width, int height);

}  // namespace arreg
