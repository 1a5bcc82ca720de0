#include "ar/debug/viewer.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <ostream>
#include <set>
#include <vector>

#include "ar/debug/recorder.h"
#include "ar/debug/viewer_assets.h"
#include "core/error.h"
#include "core/file_util.h"

namespace arreg::debug {

namespace fs = std::filesystem;

namespace {

nlohmann::json ReadJson(const std::string& path) {
  try {
    return nlohmann::json::parse(ReadFileToString(path));
  } catch (const nlohmann::json::exception& e) {
    throw Error(path, "", std::string("invalid JSON: ") + e.what());
  }
}

// Frame numbers of the NNNNNN.json records in `debug_dir`, ascending.
std::vector<int> RecordedFrames(const std::string& debug_dir) {
  std::vector<int> frames;
  for (const auto& entry : fs::directory_iterator(debug_dir)) {
    const std::string name = entry.path().filename().string();
    if (name.size() != 11 || name.substr(6) != ".json") continue;
    if (!std::all_of(name.begin(), name.begin() + 6, [](char c) { return std::isdigit(c); }))
      continue;
    frames.push_back(std::stoi(name.substr(0, 6)));
  }
  std::sort(frames.begin(), frames.end());
  return frames;
}

// Writes `call_prefix` + JSON + ");": a script that hands the data to the viewer.
void WriteScript(const fs::path& path, const std::string& call_prefix, const nlohmann::json& arg) {
  WriteFileAtomic(path.string(),
                  [&](std::ostream& os) { os << call_prefix << arg.dump() << ");\n"; });
}

// Per-feature history for the viewer's track and mu plot.
struct Track {
  std::vector<int> frames;
  std::vector<double> x, y;
  std::vector<nlohmann::json> mu, threshold;  // null where the feature had no pair
};

long long FolderBytes(const fs::path& dir) {
  long long bytes = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) bytes += static_cast<long long>(e.file_size());
  return bytes;
}

}  // namespace

void ViewerOptions::Check() const {
  ARREG_CHECK_INPUT(max_frames == -1 || max_frames >= 1, "", "viewer.max_frames",
                    "must be -1 (all) or >= 1, got ", max_frames);
}

ViewerSummary WriteDebugViewer(const std::string& run_dir, const std::string& out_dir,
                               const ViewerOptions& options) {
  options.Check();
  const std::string debug_dir = DebugDir(run_dir);
  const std::string meta_path = debug_dir + "/meta.json";
  ARREG_CHECK_INPUT(FileExists(meta_path), meta_path, "",
                    "no debug records in this run folder (run `arreg run ... --debug`)");
  const nlohmann::json meta = ReadJson(meta_path);
  ARREG_CHECK_INPUT(meta.value("format", "") == "arreg-debug", meta_path, "format",
                    "expected \"arreg-debug\"");
  std::vector<int> frames = RecordedFrames(debug_dir);
  ARREG_CHECK_INPUT(!frames.empty(), debug_dir, "", "no frame records (NNNNNN.json)");
  if (options.max_frames > 0 && static_cast<int>(frames.size()) > options.max_frames)
    frames.resize(options.max_frames);

  const fs::path out = fs::absolute(out_dir).lexically_normal();
  const fs::path tmp =
      out.parent_path() / ("." + out.filename().string() + ".tmp-" + std::to_string(::getpid()));
  fs::remove_all(tmp);
  CreateDirectories((tmp / "data").string());
  CreateDirectories((tmp / "frames").string());
  ViewerSummary summary;
  try {
    std::map<int, Track> tracks;
    std::set<int> topology_ids;
    for (int n : frames) {
      const std::string record_path = FrameRecordPath(run_dir, n);
      const nlohmann::json rec = ReadJson(record_path);
      try {
        const nlohmann::json& det = rec.at("detection");
        // Largest mu among the pairs of each feature this frame.
        std::map<int, double> max_mu;
        if (det.is_object())
          for (const auto& p : det.at("pairs")) {
            const double mu = p.at(2).get<double>();
            for (int k = 0; k < 2; ++k) {
              const int id = p.at(k).get<int>();
              auto it = max_mu.find(id);
              if (it == max_mu.end() || mu > it->second) max_mu[id] = mu;
            }
          }
        for (const auto& f : rec.at("features")) {
          const std::string status = f.at("status").get<std::string>();
          Track& t = tracks[f.at("id").get<int>()];
          // A lost feature keeps its last pixel; the track ends where it was lost.
          if (!t.frames.empty() && status != "tracked" && t.frames.back() < n &&
              t.x.back() == f.at("px").at(0).get<double>() &&
              t.y.back() == f.at("px").at(1).get<double>())
            continue;
          t.frames.push_back(n);
          t.x.push_back(f.at("px").at(0).get<double>());
          t.y.push_back(f.at("px").at(1).get<double>());
          const auto it = max_mu.find(f.at("id").get<int>());
          t.mu.push_back(it == max_mu.end() ? nlohmann::json(nullptr) : nlohmann::json(it->second));
          t.threshold.push_back(det.is_object() ? det.at("threshold") : nlohmann::json(nullptr));
        }
        if (rec.value("topology", -1) >= 0) topology_ids.insert(rec.at("topology").get<int>());
      } catch (const nlohmann::json::exception& e) {
        throw Error(record_path, "", std::string("unexpected record content: ") + e.what());
      }
      WriteScript(tmp / "data" / ("frame_" + FrameName(n) + ".js"),
                  "window.arregFrame(" + std::to_string(n) + ", ", rec);
      const std::string image = FrameImagePath(run_dir, n);
      if (FileExists(image))
        fs::copy_file(image, tmp / "frames" / (FrameName(n) + ".jpg"),
                      fs::copy_options::overwrite_existing);
    }
    for (int k : topology_ids) {
      const std::string path = TopologyRecordPath(run_dir, k);
      ARREG_CHECK_INPUT(FileExists(path), path, "", "topology record referenced by frames missing");
      WriteScript(tmp / "data" / ("topology_" + FrameName(k) + ".js"),
                  "window.arregTopology(" + std::to_string(k) + ", ", ReadJson(path));
    }
    nlohmann::json tracks_json = nlohmann::json::object();
    for (const auto& [id, t] : tracks)
      tracks_json[std::to_string(id)] = {
          {"f", t.frames}, {"x", t.x}, {"y", t.y}, {"mu", t.mu}, {"thr", t.threshold}};
    WriteFileAtomic((tmp / "data" / "tracks.js").string(), [&](std::ostream& os) {
      os << "window.arregTracks(" << tracks_json.dump() << ");\n";
    });
    const nlohmann::json& camera = meta.at("camera");
    const nlohmann::json viewer_meta = {
        {"title", options.title.empty()
                      ? fs::absolute(run_dir).lexically_normal().filename().string()
                      : options.title},
        {"frames", frames},
        {"width", camera.value("width", 0)},
        {"height", camera.value("height", 0)},
        {"fps", meta.at("start").value("fps", 0.0)},
        {"detector", meta.at("detector")},
        {"start", meta.at("start")}};
    WriteFileAtomic((tmp / "data" / "meta.js").string(), [&](std::ostream& os) {
      os << "window.ARREG_META = " << viewer_meta.dump() << ";\n";
    });
    WriteFileAtomic((tmp / "index.html").string(),
                    [](std::ostream& os) { os << kViewerIndexHtml; });
    WriteFileAtomic((tmp / "viewer.css").string(), [](std::ostream& os) { os << kViewerCss; });
    WriteFileAtomic((tmp / "viewer.js").string(), [](std::ostream& os) { os << kViewerJs; });
    summary.frames = static_cast<int>(frames.size());
    summary.features = static_cast<int>(tracks.size());
    summary.topology_files = static_cast<int>(topology_ids.size());
    summary.bytes = FolderBytes(tmp);
  } catch (...) {
    std::error_code ec;
    fs::remove_all(tmp, ec);
    throw;
  }
  // Swap the finished folder into place.
  std::error_code ec;
  const fs::path old =
      out.parent_path() / ("." + out.filename().string() + ".old-" + std::to_string(::getpid()));
  if (fs::exists(out)) {
    fs::rename(out, old, ec);
    ARREG_CHECK_INPUT(!ec, out.string(), "", "cannot replace the existing folder: ", ec.message());
  }
  fs::rename(tmp, out, ec);
  ARREG_CHECK_INPUT(!ec, out.string(), "", "cannot move the viewer into place: ", ec.message());
  fs::remove_all(old, ec);
  return summary;
}

}  // namespace arreg::debug
