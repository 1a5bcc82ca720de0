// Surgical instruments in the image: where they are (a colour segmentation) and which tracked
// features move with them (a rigid-motion test), so that features on instruments are dropped.
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace arreg {

// Per-pixel colour segmentation. Perfused tissue is red to yellow under any endoscope white
// balance; instruments are grey steel or blue-grey plastic, whose colour is at most the tissue's
// reflection. The cue is the "warmth" w = a* cos(theta) + b* sin(theta) of the CIE L*a*b*
// chroma (a*, b* in L*a*b* units, OpenCV's 8-bit scale): the chroma's component along the tissue
// hue. Hysteresis: regions of w < grow_max_warmth that hold at least min_area_fraction of the
// image in seed pixels (w < seed_max_warmth, lightness >= min_seed_lightness) are instruments;
// small regions (glints, dark vessels, a shadow) are not. On the real clip's hand-labelled
// instruments (frames 0, 30, 60) the median warmth is -5 and tissue's 1st percentile 3.5-7
// (docs/instruments.md).
struct InstrumentMaskOptions {
  // Hue direction theta of tissue in the a*b* plane, degrees (0: red, 90: yellow). Tissue hues
  // span pink (-10) to yellow fat (70). Default 30.
  double hue_direction_deg = 30.0;
  // A seed pixel's warmth is below this (L*a*b* units): above the median of instruments
  // (real clip -5; the thin steel shaft of the Blender phantoms, which mirrors warm light, 2-8)
  // and near tissue's 1st percentile (real clip 3.5-7). Default 4.
  double seed_max_warmth = 4.0;
  // Pixels of a region grown from seeds have warmth below this, so reflections of tissue on
  // metal join while the pale tissue beside an instrument (warmth 3-15) does not grow into one
  // region with it. Default 10.
  double grow_max_warmth = 10.0;
  // Seed pixels are at least this light (L* on OpenCV's 0..255 scale): dark tissue (shadows,
  // vignetting) has little chroma of any hue, but may join a region grown from lit seeds.
  // Default 40.
  int min_seed_lightness = 40;
  // ... and darker than this: specular highlights (L* near 255, no chroma) occur on tissue as
  // much as on instruments. Default 230.
  int max_seed_lightness = 230;
  // A region is an instrument when its seed pixels cover at least this fraction of the image
  // (the smallest labelled instrument part on the real clip, a jaw, is 0.8 %). Default 0.002.
  double min_area_fraction = 0.002;
  // The segmentation runs on the image shrunk by this factor (area averaging), 1..4. Default 2.
  int downscale = 2;
  // Morphological closing of the regions, pixels of the shrunk image: fills the text,
  // highlights and seams on an instrument. Default 2.
  int close_px = 2;
  // The mask is grown by this, pixels of the image (rounded up to pixels of the shrunk image):
  // a feature whose window straddles the instrument's edge is on it. Default 4.
  int margin_px = 4;

  void Check() const;  // throws arreg::Error naming the bad field
};

// Rigid-motion test: features near an instrument that move together with one similarity
// transform (rotation, scale, translation), differently from the tissue around them, ride the
// instrument (parts the colour misses: jaws mirroring tissue, teeth, highlights) or are dragged by
// its edge. Tissue moves smoothly but not as one similarity with an instrument next to it.
struct InstrumentMotionOptions {
  bool enabled = true;  // default true
  // Features within this distance of the colour mask are candidates, pixels; those farther
  // away are the tissue the candidates are compared with. Default 24.
  double band_px = 24.0;
  // Fewest features in a rigid group. Default 4.
  int min_group = 4;
  // A feature belongs to a group when the group's similarity predicts its new position within
  // this, pixels (the forward-backward check allows 1 px). Default 1.
  double max_residual_px = 1.0;
  // A group member is dropped when its displacement this frame differs from its tissue
  // reference (the median displacement of its nearest tissue features) by at least this,
  // pixels. Default 2 (the spatio-temporal filter's slack).
  double min_relative_motion_px = 2.0;
  // Tissue features per reference: the nearest ones within reference_radius_px (at least 3,
  // else the member has no surroundings to differ from). Default 8, 80 px.
  int tissue_neighbours = 8;
  double reference_radius_px = 80.0;
  // Groups looked for per frame (one per instrument, and the tissue near them). Default 4.
  int max_groups = 4;
  // A group holding more than this fraction of all features is the tissue (a camera pan, or
  // the camera moving with a still instrument) and is kept. Default 0.25.
  double max_group_fraction = 0.25;

  void Check() const;  // throws arreg::Error naming the bad field
};

struct InstrumentRejectionOptions {
  // Off in the tracker (it needs BGR input); the pipeline turns it on
  // (`tracking.instrument_rejection`).
  bool enabled = false;  // default false
  InstrumentMaskOptions mask;
  InstrumentMotionOptions motion;

  void Check() const;  // throws arreg::Error naming the bad field
};

// Instrument mask (CV_8UC1 of the image size, 255 on instruments, grown by margin_px) of a BGR
// image (CV_8UC3).
cv::Mat InstrumentMask(const cv::Mat& bgr, const InstrumentMaskOptions& options);

// The rigid-motion test on its own. Feature i moved from from_px[i] to to_px[i] this frame;
// near[i] is nonzero for candidates (near an instrument). Groups of at least min_group
// candidates that one similarity carries within max_residual_px are found one after the other
// (RANSAC on pairs of points, deterministic), grown over every feature that the similarity
// carries within band_px of a member; in a group of at most max_group_fraction of the features,
// the members whose displacement differs by at least min_relative_motion_px from the median
// displacement of their nearest tissue features (not candidates, not in the group; at least 3
// within reference_radius_px) are flagged,
// when at least min_group of the group are.
std::vector<bool> RigidInstrumentMotion(const std::vector<cv::Point2f>& from_px,
                                        const std::vector<cv::Point2f>& to_px,
                                        const std::vector<uint8_t>& near,
                                        const InstrumentMotionOptions& options);

}  // namespace arreg
