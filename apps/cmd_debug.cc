// `arreg debug`: the offline viewer of a run recorded with `arreg run --debug`, or one annotated
// frame as a PNG for reports and bug tickets (docs/debug.md).
#include <cstdio>
#include <string>

#include "ar/debug/frame_render.h"
#include "ar/debug/viewer.h"
#include "commands.h"
#include "core/error.h"
#include "option_parser.h"

namespace arreg::cli {

int RunDebug(int argc, char** argv) {
  std::string run_dir, out_dir, png,
      layers = "features,targets,springs,outliers,cut,numbers,instruments";
  std::string title;
  int frame = -1, max_frames = -1;
  OptionParser parser(
      "arreg debug --run DIR (--out VIEWER | --frame N --png OUT.png [--layers L,...])",
      "Inspects a run recorded with `arreg run ... --debug`: writes a self-contained viewer "
      "folder (open VIEWER/index.html from disk; frame slider, play/pause, arrow keys, layers, "
      "per-frame numbers, click a feature for its track and mu history), or renders one "
      "annotated frame as a PNG.");
  parser.AddString("run", &run_dir, "DIR", "run folder with debug/ records", true);
  parser.AddString("out", &out_dir, "VIEWER", "write the viewer folder (replaced whole)");
  parser.AddInt("frame", &frame, "N", "frame to render with --png");
  parser.AddString("png", &png, "OUT.png", "write frame N with the layers drawn");
  parser.AddString("layers", &layers, "L,...",
                   "layers for --png: features, targets, springs, pairs, outliers, cut, mesh, "
                   "internal, numbers, instruments, all, none");
  parser.AddInt("max-frames", &max_frames, "N", "viewer: at most the first N frames (-1: all)");
  parser.AddString("title", &title, "TEXT", "viewer title (default: the run folder's name)");
  parser.SetEpilog(
      "examples:\n"
      "  arreg run --scene scene.json --out run1 --debug\n"
      "  arreg debug --run run1 --out run1-viewer\n"
      "  arreg debug --run run1 --frame 42 --png f42.png --layers features,pairs,outliers,cut");
  if (!parser.Parse(argc, argv)) return 0;

  const bool want_png = parser.Given("png") || parser.Given("frame");
  ARREG_CHECK_INPUT(want_png || !out_dir.empty(), "", "--out",
                    "give --out VIEWER or --frame N --png OUT.png");
  if (want_png) {
    ARREG_CHECK_INPUT(parser.Given("png"), "", "--png", "--frame needs --png OUT.png");
    ARREG_CHECK_INPUT(parser.Given("frame") && frame >= 0, "", "--frame",
                      "--png needs --frame N with N >= 0");
    const debug::DebugLayers parsed = debug::DebugLayers::Parse(layers);
    debug::RenderDebugFrame(run_dir, frame, parsed, png);
    std::printf("wrote %s (frame %d)\n", png.c_str(), frame);
  } else {
    ARREG_CHECK_INPUT(!parser.Given("layers"), "", "--layers",
                      "only applies to --png (the viewer has checkboxes)");
  }
  if (!out_dir.empty()) {
    debug::ViewerOptions vo;
    vo.max_frames = max_frames;
    vo.title = title;
    const debug::ViewerSummary s = debug::WriteDebugViewer(run_dir, out_dir, vo);
    std::printf("wrote %s/index.html: %d frames, %d features, %.1f MB\n", out_dir.c_str(), s.frames,
                s.features, s.bytes / 1e6);
  }
  return 0;
}

}  // namespace arreg::cli
