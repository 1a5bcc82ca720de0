// Synthetic scenes for the align tests: kidney-cut and band-stretch from `arreg synth`
// (2 frames, no video), generated once per test binary, with their model surface, frame-0
// outline (gt/masks/000000.png) and true pose.
#pragma once

#include <map>
#include <memory>
#include <string>

#include "ar/align/align_eval.h"
#include "ar/synth/generator.h"
#include "core/scene.h"
#include "test_util.h"

namespace arreg::testing {

using AlignScene = align::SceneCase;

inline const AlignScene& GetAlignScene(const std::string& scenario) {
  static std::map<std::string, std::unique_ptr<AlignScene>> cache;
  auto& slot = cache[scenario];
  if (!slot) {
    synth::SynthOptions o;
    o.scenario = scenario;
    o.out_dir = ScratchDir("align_" + scenario);
    o.frames = 2;
    o.write_video = false;
    synth::GenerateSyntheticScene(o);
    slot = std::make_unique<AlignScene>(
        align::LoadSceneCase(o.out_dir, align::AlignOptions().contour_spacing_px));
  }
  return *slot;
}

}  // namespace arreg::testing
