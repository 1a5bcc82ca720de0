// Synthetic scenes for the align tests: kidney-cut and band-stretch from `arreg synth`
// (2 frames, no video), generated once per test binary, with their model surface, frame-0
// outline (gt/masks/000000.png) and true pose.
#pragma once

#include <map>
#include <memory>
#include <string>

#include "ar/align/align_job.h"
#include "ar/synth/generator.h"
#include "core/scene.h"
#include "test_util.h"

namespace arreg::testing {

struct AlignScene {
  std::string dir;
  Scene scene;
  std::unique_ptr<align::ModelSurface> surface;
  std::unique_ptr<align::Outline> outline;
  align::ModelPose truth;

  align::AlignInput Input() const {
    align::AlignInput in;
    in.camera = &scene.camera;
    in.surface = surface.get();
    in.outline = outline.get();
    return in;
  }
};

inline const AlignScene& GetAlignScene(const std::string& scenario) {
  static std::map<std::string, std::unique_ptr<AlignScene>> cache;
  auto& slot = cache[scenario];
  if (!slot) {
    slot = std::make_unique<AlignScene>();
    slot->dir = ScratchDir("align_" + scenario);
    synth::SynthOptions o;
    o.scenario = scenario;
    o.out_dir = slot->dir;
    o.frames = 2;
    o.write_video = false;
    synth::GenerateSyntheticScene(o);
    ReadSceneOptions ro;
    ro.check_files_exist = false;
    slot->scene = ReadScene(slot->dir + "/scene.json", ro);
    slot->surface = std::make_unique<align::ModelSurface>(align::LoadModelSurface(slot->scene));
    slot->outline = std::make_unique<align::Outline>(
        align::ReadOutline(slot->dir + "/gt/masks/000000.png", slot->scene.camera,
                           align::AlignOptions().contour_spacing_px));
    slot->truth = align::ModelPose::FromRigid(slot->scene.world_from_model);
  }
  return *slot;
}

}  // namespace arreg::testing
