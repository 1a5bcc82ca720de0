#include "ar/eval/benchmark.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "core/enum_names.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/mesh_io.h"

namespace arreg::eval {

namespace {

constexpr EnumName<SceneSource> kSceneSourceNames[] = {{SceneSource::kSynth, "synth"},
                                                       {SceneSource::kPhantom, "phantom"}};
constexpr EnumName<BenchSplit> kBenchSplitNames[] = {
    {BenchSplit::kDev, "dev"}, {BenchSplit::kTest, "test"}, {BenchSplit::kQuick, "quick"}};
constexpr EnumName<SceneClass> kSceneClassNames[] = {
    {SceneClass::kCut, "cut"}, {SceneClass::kNoCut, "no-cut"}, {SceneClass::kStretch, "stretch"}};
constexpr EnumName<SceneStatus> kSceneStatusNames[] = {
    {SceneStatus::kOk, "ok"}, {SceneStatus::kSkipped, "skipped"}, {SceneStatus::kFailed, "failed"}};

// Names end up in folder names: letters, digits, '.', '_' and '-' only.
bool IsSafeName(const std::string& s) {
  if (s.empty() || s[0] == '.') return false;
  for (char c : s)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-'))
      return false;
  return true;
}

BenchSceneParams ReadParams(JsonObjectReader r, SceneSource source) {
  BenchSceneParams p;
  r.Required("frames", &p.frames);
  if (p.frames < 2) r.Fail("frames", "must be >= 2, got " + std::to_string(p.frames));
  std::string size;
  r.Required("size", &size);
  char extra = 0;
  if (std::sscanf(size.c_str(), "%dx%d%c", &p.width, &p.height, &extra) != 2 || p.width <= 0 ||
      p.height <= 0 || p.width % 2 || p.height % 2)
    r.Fail("size", "expected WxH with even positive numbers, got '" + size + "'");
  if (source == SceneSource::kSynth) {
    r.Optional("zoom", &p.zoom);
    r.CheckInRange("zoom", p.zoom, 0.5, 4.0);
    r.Optional("amplitude", &p.amplitude);
    if (!(p.amplitude > 0 && p.amplitude <= 1.5))
      r.Fail("amplitude", "must be in (0, 1.5], got " + std::to_string(p.amplitude));
    r.Optional("noise", &p.noise);
    r.CheckNonNegative("noise", p.noise);
    r.Optional("blur", &p.blur);
    r.CheckNonNegative("blur", p.blur);
    r.Optional("occluder", &p.occluder);
  }
  r.Finish();  // a phantom entry with synth-only keys is an error here
  return p;
}

// FNV-1a, 64 bits: a stable hash of the parameters' canonical text.
uint64_t Fnv1a(const std::string& text) {
  uint64_t h = 1469598103934665603ULL;
  for (unsigned char c : text) {
    h ^= c;
    h *= 1099511628211ULL;
  }
  return h;
}

std::string Fixed(const std::optional<double>& v, int decimals) {
  if (!v) return "-";
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.*f", decimals, *v);
  return buf;
}

nlohmann::json Opt(const std::optional<double>& v) {
  return v ? nlohmann::json(*v) : nlohmann::json();
}
nlohmann::json Opt(const std::optional<int>& v) {
  return v ? nlohmann::json(*v) : nlohmann::json();
}

template <typename T>
void ReadOpt(const nlohmann::json& j, const char* key, std::optional<T>* out) {
  if (j.contains(key) && !j[key].is_null()) *out = j[key].get<T>();
}

double Mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return s / v.size();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// The length-weighted distance sum and length of the segments not in `seen` (which they join).
void AccumulateSegments(const std::vector<Eigen::Vector3d>& polyline,
                        const TriangleDistanceQuery& surface, double step_mm,
                        std::set<std::vector<double>>* seen, double* weighted, double* length) {
  for (size_t i = 0; i + 1 < polyline.size(); ++i) {
    const Eigen::Vector3d& a = polyline[i];
    const Eigen::Vector3d& b = polyline[i + 1];
    if (seen) {
      // A segment is the same in either direction.
      std::vector<double> key = {a.x(), a.y(), a.z(), b.x(), b.y(), b.z()};
      std::vector<double> reversed = {b.x(), b.y(), b.z(), a.x(), a.y(), a.z()};
      if (!seen->insert(std::min(key, reversed)).second) continue;
    }
    const double len = (b - a).norm();
    if (len <= 0) continue;
    const int pieces = std::max(1, static_cast<int>(std::ceil(len / step_mm)));
    for (int k = 0; k < pieces; ++k) {
      const Eigen::Vector3d p = a + (b - a) * ((k + 0.5) / pieces);
      *weighted += surface.Distance(p) * (len / pieces);
    }
    *length += len;
  }
}

// Scenes of one group, in order of appearance.
struct Group {
  GroupRow row;
  std::vector<const SceneResult*> ok;
};

}  // namespace

const char* SceneSourceName(SceneSource source) { return NameOf(kSceneSourceNames, source); }
const char* BenchSplitName(BenchSplit split) { return NameOf(kBenchSplitNames, split); }
const char* SceneClassName(SceneClass scene_class) { return NameOf(kSceneClassNames, scene_class); }

SceneSource ParseSceneSource(const std::string& name, const std::string& file,
                             const std::string& field) {
  return ParseName(kSceneSourceNames, name, file, field);
}
BenchSplit ParseBenchSplit(const std::string& name, const std::string& file,
                           const std::string& field) {
  return ParseName(kBenchSplitNames, name, file, field);
}
SceneClass ParseSceneClass(const std::string& name, const std::string& file,
                           const std::string& field) {
  return ParseName(kSceneClassNames, name, file, field);
}

nlohmann::json BenchSceneParams::ToJson(SceneSource source) const {
  nlohmann::json j = {{"frames", frames},
                      {"size", std::to_string(width) + "x" + std::to_string(height)}};
  if (source == SceneSource::kSynth) {
    j["zoom"] = zoom;
    j["amplitude"] = amplitude;
    j["noise"] = noise;
    j["blur"] = blur;
    j["occluder"] = occluder;
  }
  return j;
}

std::string BenchScene::CacheKey() const {
  const nlohmann::json key = {{"source", SceneSourceName(source)},
                              {"scenario", scenario},
                              {"seed", seed},
                              {"params", params.ToJson(source)}};
  char hash[20];
  std::snprintf(hash, sizeof(hash), "%012llx",
                static_cast<unsigned long long>(Fnv1a(key.dump()) & 0xffffffffffffULL));
  return SceneSourceName(source) + ("-" + scenario) + "-s" + std::to_string(seed) + "-" + hash;
}

std::vector<BenchScene> ParseBenchManifest(const nlohmann::json& json, const std::string& file) {
  JsonObjectReader root(json, file, "");
  int version = 0;
  root.Required("version", &version);
  if (version != 1) root.Fail("version", "expected 1, got " + std::to_string(version));
  root.Ignore("description");
  std::vector<BenchScene> scenes;
  std::set<std::string> names;
  for (JsonObjectReader& r : root.ObjectArray("scenes", /*required=*/true)) {
    BenchScene base;
    r.Required("name", &base.name);
    if (!IsSafeName(base.name))
      r.Fail("name", "letters, digits, '.', '_' and '-' only, got '" + base.name + "'");
    r.RequiredEnum("source", kSceneSourceNames, &base.source);
    r.Required("scenario", &base.scenario);
    if (!IsSafeName(base.scenario))
      r.Fail("scenario", "letters, digits, '.', '_' and '-' only, got '" + base.scenario + "'");
    r.RequiredEnum("split", kBenchSplitNames, &base.split);
    r.RequiredEnum("class", kSceneClassNames, &base.scene_class);
    base.params = ReadParams(r.Object("params"), base.source);
    r.Ignore("note");
    std::vector<int> seeds;
    const bool one = r.Has("seed"), many = r.Has("seeds");
    if (one == many) r.Fail("seed", "give exactly one of 'seed' (a number) or 'seeds' (a list)");
    if (one) {
      int seed = 0;
      r.Required("seed", &seed);
      seeds = {seed};
    } else {
      r.Required("seeds", &seeds);
      if (seeds.empty()) r.Fail("seeds", "must not be empty");
    }
    r.Finish();
    for (int seed : seeds) {
      if (seed < 0) r.Fail(one ? "seed" : "seeds", "must be >= 0, got " + std::to_string(seed));
      BenchScene s = base;
      s.seed = seed;
      if (many) s.name += "-s" + std::to_string(seed);
      if (!names.insert(s.name).second) r.Fail("name", "duplicate scene name '" + s.name + "'");
      scenes.push_back(std::move(s));
    }
  }
  root.Finish();
  return scenes;
}

std::vector<BenchScene> ReadBenchManifest(const std::string& path) {
  return ParseBenchManifest(ParseJsonFile(path), path);
}

void BenchMetricsOptions::Check() const {
  ARREG_CHECK_INPUT(found_within_mm > 0, "", "found_within_mm", "must be > 0");
  ARREG_CHECK_INPUT(opening_mm > 0, "", "opening_mm", "must be > 0");
  ARREG_CHECK_INPUT(sample_step_mm > 0, "", "sample_step_mm", "must be > 0");
}

double PolylineSurfaceError(const std::vector<Eigen::Vector3d>& polyline,
                            const TriangleDistanceQuery& surface, double step_mm) {
  return PolylinesSurfaceError({polyline}, surface, step_mm);
}

double PolylinesSurfaceError(const std::vector<std::vector<Eigen::Vector3d>>& polylines,
                             const TriangleDistanceQuery& surface, double step_mm) {
  ARREG_CHECK_INPUT(step_mm > 0, "", "step_mm", "must be > 0");
  std::set<std::vector<double>> seen;
  double weighted = 0, length = 0;
  for (const auto& polyline : polylines)
    AccumulateSegments(polyline, surface, step_mm, &seen, &weighted, &length);
  if (length > 0) return weighted / length;
  // Points only: their mean distance.
  double sum = 0;
  int n = 0;
  for (const auto& polyline : polylines)
    for (const Eigen::Vector3d& p : polyline) {
      sum += surface.Distance(p);
      ++n;
    }
  ARREG_CHECK_INPUT(n > 0, "", "polyline", "has no points");
  return sum / n;
}

std::optional<int> FirstFrameAtLeast(const std::vector<double>& values, double threshold) {
  for (size_t i = 0; i < values.size(); ++i)
    if (values[i] >= threshold) return static_cast<int>(i);
  return std::nullopt;
}

std::vector<AppliedCut> ReadAppliedCuts(const std::string& frames_jsonl) {
  std::ifstream in(frames_jsonl);
  ARREG_CHECK_INPUT(in.good(), frames_jsonl, "", "cannot read");
  std::vector<AppliedCut> cuts;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (line.empty()) continue;
    const std::string where = "line " + std::to_string(number);
    std::string context = frames_jsonl;
    context.append(" ").append(where);
    const nlohmann::json record = ParseJsonText(line, context);
    if (!record.contains("cut_events")) continue;
    for (const nlohmann::json& e : record["cut_events"]) {
      if (!e.is_object() || e.value("status", "") != "cut") continue;
      ARREG_CHECK_INPUT(e.contains("polyline_rest_mm") && e["polyline_rest_mm"].is_array() &&
                            !e["polyline_rest_mm"].empty(),
                        frames_jsonl, where + ": cut_events.polyline_rest_mm",
                        "an applied cut needs its rest polyline (a list of [x, y, z])");
      AppliedCut cut;
      ReadJsonValue(e["frame"], frames_jsonl, where + ": cut_events.frame", &cut.frame);
      for (const nlohmann::json& p : e["polyline_rest_mm"]) {
        Eigen::Vector3d v;
        ReadJsonValue(p, frames_jsonl, where + ": cut_events.polyline_rest_mm", &v);
        cut.polyline_rest_mm.push_back(v);
      }
      cuts.push_back(std::move(cut));
    }
  }
  return cuts;
}

TrueCut ReadTrueCut(const std::string& gt_dir) {
  const std::string path = gt_dir + "/cut.json";
  const nlohmann::json j = ParseJsonFile(path);
  ARREG_CHECK_INPUT(j.is_object() && j.contains("cut"), path, "cut", "missing");
  TrueCut truth;
  if (j["cut"].is_null()) return truth;
  ARREG_CHECK_INPUT(j["cut"].is_object(), path, "cut", "expected null or an object");
  const nlohmann::json& c = j["cut"];
  std::string surface;
  ARREG_CHECK_INPUT(c.contains("surface"), path, "cut.surface", "missing");
  ReadJsonValue(c["surface"], path, "cut.surface", &surface);
  truth.present = true;
  truth.surface = ReadSurfaceMesh(gt_dir + "/" + surface);
  ARREG_CHECK_INPUT(truth.surface.faces.rows() > 0, gt_dir + "/" + surface, "", "no triangles");
  if (c.contains("opening_mm") && !c["opening_mm"].is_null()) {
    std::vector<double> opening;
    ReadJsonValue(c["opening_mm"], path, "cut.opening_mm", &opening);
    truth.opening_mm = std::move(opening);
  }
  return truth;
}

SceneResult SceneResult::For(const BenchScene& scene) {
  SceneResult r;
  r.name = scene.name;
  r.source = scene.source;
  r.scenario = scene.scenario;
  r.split = scene.split;
  r.scene_class = scene.scene_class;
  return r;
}

const char* SceneStatusName(SceneStatus status) { return NameOf(kSceneStatusNames, status); }

SceneStatus ParseSceneStatus(const std::string& name, const std::string& field) {
  return ParseName(kSceneStatusNames, name, "", field);
}

nlohmann::json SceneResult::ToJson() const {
  return {{"name", name},
          {"source", SceneSourceName(source)},
          {"scenario", scenario},
          {"split", BenchSplitName(split)},
          {"class", SceneClassName(scene_class)},
          {"status", SceneStatusName(status)},
          {"reason", reason},
          {"applied_cuts", applied_cuts},
          {"found_cuts", found_cuts},
          {"misplaced_cuts", misplaced_cuts},
          {"cut_found", cut_found},
          {"cut_line_error_mm", Opt(cut_line_error_mm)},
          {"opening_frame", Opt(opening_frame)},
          {"first_found_cut_frame", Opt(first_found_cut_frame)},
          {"latency_frames", Opt(latency_frames)},
          {"dice_final", Opt(dice_final)},
          {"dice_final_no_topology", Opt(dice_final_no_topology)},
          {"dice_min", Opt(dice_min)},
          {"surface_mean_mm", Opt(surface_mean_mm)},
          {"surface_worst_mm", Opt(surface_worst_mm)},
          {"internal_mean_mm", Opt(internal_mean_mm)},
          {"internal_worst_mm", Opt(internal_worst_mm)},
          {"seconds", seconds}};
}

SceneResult SceneResult::FromJson(const nlohmann::json& j, const std::string& file) {
  SceneResult r;
  try {
    r.name = j.at("name").get<std::string>();
    r.source = ParseSceneSource(j.at("source").get<std::string>(), "", "source");
    r.scenario = j.at("scenario").get<std::string>();
    r.split = ParseBenchSplit(j.at("split").get<std::string>(), "", "split");
    r.scene_class = ParseSceneClass(j.at("class").get<std::string>(), "", "class");
    r.status = ParseSceneStatus(j.at("status").get<std::string>(), "status");
    r.reason = j.at("reason").get<std::string>();
    r.applied_cuts = j.at("applied_cuts").get<int>();
    r.found_cuts = j.at("found_cuts").get<int>();
    r.misplaced_cuts = j.at("misplaced_cuts").get<int>();
    r.cut_found = j.at("cut_found").get<bool>();
    ReadOpt(j, "cut_line_error_mm", &r.cut_line_error_mm);
    ReadOpt(j, "opening_frame", &r.opening_frame);
    ReadOpt(j, "first_found_cut_frame", &r.first_found_cut_frame);
    ReadOpt(j, "latency_frames", &r.latency_frames);
    ReadOpt(j, "dice_final", &r.dice_final);
    ReadOpt(j, "dice_final_no_topology", &r.dice_final_no_topology);
    ReadOpt(j, "dice_min", &r.dice_min);
    ReadOpt(j, "surface_mean_mm", &r.surface_mean_mm);
    ReadOpt(j, "surface_worst_mm", &r.surface_worst_mm);
    ReadOpt(j, "internal_mean_mm", &r.internal_mean_mm);
    ReadOpt(j, "internal_worst_mm", &r.internal_worst_mm);
    r.seconds = j.at("seconds").get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw Error(file, "", std::string("not a scene result: ") + e.what());
  } catch (const Error& e) {
    throw Error(file, e.where(), e.detail());
  }
  return r;
}

void ScoreCuts(const std::vector<AppliedCut>& applied, const TrueCut& truth,
               const BenchMetricsOptions& options, SceneResult* r) {
  options.Check();
  const bool expects_cut = r->scene_class == SceneClass::kCut;
  ARREG_CHECK_INPUT(truth.present == expects_cut, "", "cut.json", "the ground truth ",
                    truth.present ? "has" : "has no", " cut but scene '", r->name, "' is of class ",
                    SceneClassName(r->scene_class));
  r->applied_cuts = static_cast<int>(applied.size());
  r->found_cuts = r->misplaced_cuts = 0;
  r->cut_found = false;
  if (!truth.present) {
    r->misplaced_cuts = r->applied_cuts;  // every cut on a no-cut scene is a false one
    return;
  }
  const TriangleDistanceQuery surface(truth.surface.vertices, truth.surface.faces);
  std::vector<std::vector<Eigen::Vector3d>> polylines;
  for (const AppliedCut& c : applied) {
    const double e = PolylineSurfaceError(c.polyline_rest_mm, surface, options.sample_step_mm);
    if (e <= options.found_within_mm) {
      ++r->found_cuts;
      if (!r->first_found_cut_frame) r->first_found_cut_frame = c.frame;
    } else {
      ++r->misplaced_cuts;
    }
    polylines.push_back(c.polyline_rest_mm);
  }
  r->cut_found = r->found_cuts > 0;
  if (!polylines.empty())
    r->cut_line_error_mm = PolylinesSurfaceError(polylines, surface, options.sample_step_mm);
  if (truth.opening_mm) r->opening_frame = FirstFrameAtLeast(*truth.opening_mm, options.opening_mm);
  if (r->opening_frame && r->first_found_cut_frame)
    r->latency_frames = *r->first_found_cut_frame - *r->opening_frame;
}

void ScoreRegistration(const RunEvaluation& with, const RunEvaluation& without, SceneResult* r) {
  r->dice_final = with.dice_final;
  r->dice_final_no_topology = without.dice_final;
  auto symmetric_mean = [](const HausdorffFigures& h) {
    return 0.5 * (h.mean_model_to_gt + h.mean_gt_to_model);
  };
  std::vector<double> surface, internal;
  for (const FrameEvaluation& f : with.frames) {
    if (f.dice) r->dice_min = std::min(r->dice_min.value_or(1.0), *f.dice);
    if (f.surface) surface.push_back(symmetric_mean(*f.surface));
    if (f.internal) internal.push_back(symmetric_mean(*f.internal));
  }
  if (!surface.empty()) {
    r->surface_mean_mm = Mean(surface);
    r->surface_worst_mm = *std::max_element(surface.begin(), surface.end());
  }
  if (!internal.empty()) {
    r->internal_mean_mm = Mean(internal);
    r->internal_worst_mm = *std::max_element(internal.begin(), internal.end());
  }
}

nlohmann::json GroupRow::ToJson() const {
  return {{"source", SceneSourceName(source)},
          {"scenario", scenario},
          {"split", BenchSplitName(split)},
          {"class", SceneClassName(scene_class)},
          {"scenes", scenes},
          {"ok", ok},
          {"skipped", skipped},
          {"failed", failed},
          {"recall", Opt(recall)},
          {"false_cuts_per_scene", Opt(false_cuts_per_scene)},
          {"false_cut_scenes", Opt(false_cut_scenes)},
          {"misplaced_per_scene", Opt(misplaced_per_scene)},
          {"cut_line_error_mm", Opt(cut_line_error_mm)},
          {"latency_median_frames", Opt(latency_median_frames)},
          {"dice_final", Opt(dice_final)},
          {"dice_final_no_topology", Opt(dice_final_no_topology)},
          {"error_ratio", Opt(error_ratio)},
          {"dice_min", Opt(dice_min)},
          {"surface_mean_mm", Opt(surface_mean_mm)},
          {"surface_worst_mm", Opt(surface_worst_mm)},
          {"internal_mean_mm", Opt(internal_mean_mm)},
          {"internal_worst_mm", Opt(internal_worst_mm)}};
}

std::vector<GroupRow> AggregateResults(const std::vector<SceneResult>& results) {
  std::vector<Group> groups;
  for (const SceneResult& r : results) {
    auto it = std::find_if(groups.begin(), groups.end(), [&](const Group& g) {
      return g.row.source == r.source && g.row.scenario == r.scenario && g.row.split == r.split;
    });
    if (it == groups.end()) {
      groups.push_back({});
      it = groups.end() - 1;
      it->row.source = r.source;
      it->row.scenario = r.scenario;
      it->row.split = r.split;
      it->row.scene_class = r.scene_class;
    }
    ++it->row.scenes;
    if (r.status == SceneStatus::kOk) it->ok.push_back(&r);
    it->row.skipped += r.status == SceneStatus::kSkipped;
    it->row.failed += r.status == SceneStatus::kFailed;
  }
  std::vector<GroupRow> rows;
  for (Group& g : groups) {
    GroupRow& row = g.row;
    row.ok = static_cast<int>(g.ok.size());
    if (g.ok.empty()) {
      rows.push_back(row);
      continue;
    }
    const double n = row.ok;
    std::vector<double> errors, latencies, dice_with, dice_without, surface, internal;
    int found = 0, misplaced = 0, with_false = 0;
    double error_with = 0, error_without = 0;
    for (const SceneResult* r : g.ok) {
      found += r->cut_found;
      misplaced += r->misplaced_cuts;
      with_false += r->applied_cuts > 0;
      if (r->cut_line_error_mm) errors.push_back(*r->cut_line_error_mm);
      if (r->latency_frames) latencies.push_back(*r->latency_frames);
      if (r->dice_final) dice_with.push_back(*r->dice_final);
      if (r->dice_final_no_topology) dice_without.push_back(*r->dice_final_no_topology);
      if (r->dice_final && r->dice_final_no_topology) {
        error_with += 1 - *r->dice_final;
        error_without += 1 - *r->dice_final_no_topology;
      }
      if (r->dice_min) row.dice_min = std::min(row.dice_min.value_or(1.0), *r->dice_min);
      if (r->surface_mean_mm) surface.push_back(*r->surface_mean_mm);
      if (r->surface_worst_mm)
        row.surface_worst_mm = std::max(row.surface_worst_mm.value_or(0.0), *r->surface_worst_mm);
      if (r->internal_mean_mm) internal.push_back(*r->internal_mean_mm);
      if (r->internal_worst_mm)
        row.internal_worst_mm =
            std::max(row.internal_worst_mm.value_or(0.0), *r->internal_worst_mm);
    }
    if (row.scene_class == SceneClass::kCut) {
      row.recall = found / n;
      row.misplaced_per_scene = misplaced / n;
      if (!errors.empty()) row.cut_line_error_mm = Mean(errors);
      if (!latencies.empty()) row.latency_median_frames = Median(latencies);
    } else {
      row.false_cuts_per_scene = misplaced / n;
      row.false_cut_scenes = with_false / n;
    }
    if (!dice_with.empty()) row.dice_final = Mean(dice_with);
    if (!dice_without.empty()) row.dice_final_no_topology = Mean(dice_without);
    if (error_without > 0) row.error_ratio = error_with / error_without;
    if (!surface.empty()) row.surface_mean_mm = Mean(surface);
    if (!internal.empty()) row.internal_mean_mm = Mean(internal);
    rows.push_back(row);
  }
  return rows;
}

std::string FormatTable(const std::vector<GroupRow>& rows) {
  std::ostringstream out;
  char line[512];
  std::snprintf(line, sizeof(line),
                "%-7s %-20s %-5s %-7s %5s | %6s %6s %6s %7s %5s | %6s %6s %6s %6s | %11s %11s\n",
                "source", "scenario", "split", "class", "ok/n", "recall", "false", "misplc",
                "line_mm", "lat", "Dice", "noTopo", "ratio", "minDic", "surf mn/wst", "int mn/wst");
  out << line;
  for (const GroupRow& r : rows) {
    const std::string count = std::to_string(r.ok) + "/" + std::to_string(r.scenes);
    const std::string surf = Fixed(r.surface_mean_mm, 2) + "/" + Fixed(r.surface_worst_mm, 2);
    const std::string internal = Fixed(r.internal_mean_mm, 2) + "/" + Fixed(r.internal_worst_mm, 2);
    std::snprintf(line, sizeof(line),
                  "%-7s %-20s %-5s %-7s %5s | %6s %6s %6s %7s %5s | %6s %6s %6s %6s | %11s %11s\n",
                  SceneSourceName(r.source), r.scenario.c_str(), BenchSplitName(r.split),
                  SceneClassName(r.scene_class), count.c_str(), Fixed(r.recall, 2).c_str(),
                  Fixed(r.false_cuts_per_scene, 2).c_str(), Fixed(r.misplaced_per_scene, 2).c_str(),
                  Fixed(r.cut_line_error_mm, 2).c_str(), Fixed(r.latency_median_frames, 1).c_str(),
                  Fixed(r.dice_final, 4).c_str(), Fixed(r.dice_final_no_topology, 4).c_str(),
                  Fixed(r.error_ratio, 2).c_str(), Fixed(r.dice_min, 4).c_str(), surf.c_str(),
                  internal.c_str());
    out << line;
  }
  return out.str();
}

nlohmann::json Criterion::ToJson() const {
  return {{"criterion", text},
          {"measured", measured},
          {"pass", pass ? nlohmann::json(*pass) : nlohmann::json()}};
}

std::vector<Criterion> AcceptanceCriteria(const std::vector<SceneResult>& results) {
  std::vector<const SceneResult*> cut, no_cut, stretch;
  for (const SceneResult& r : results) {
    if (r.status != SceneStatus::kOk) continue;
    if (r.scene_class == SceneClass::kCut) cut.push_back(&r);
    if (r.scene_class != SceneClass::kCut) no_cut.push_back(&r);
    if (r.scene_class == SceneClass::kStretch) stretch.push_back(&r);
  }
  std::vector<GroupRow> cut_rows;
  {
    std::vector<SceneResult> cut_results;
    cut_results.reserve(cut.size());
    for (const SceneResult* r : cut) cut_results.push_back(*r);
    cut_rows = AggregateResults(cut_results);
  }
  std::vector<Criterion> c;
  auto add = [&](const std::string& text, const std::string& measured, std::optional<bool> pass) {
    c.push_back({text, measured, pass});
  };
  auto none = [](const char* what) { return std::string("no ") + what + " scene ran"; };
  char buf[256];

  if (cut.empty()) {
    add("cut scenes: a cut found in >= 95 % of them", none("cut"), std::nullopt);
  } else {
    int found = 0;
    for (const SceneResult* r : cut) found += r->cut_found;
    std::snprintf(buf, sizeof(buf), "%d of %zu (%.1f %%)", found, cut.size(),
                  100.0 * found / cut.size());
    add("cut scenes: a cut found in >= 95 % of them", buf, found >= 0.95 * cut.size());
  }
  // Per-scenario figures: every scenario must meet the bound.
  auto per_scenario = [&](const std::string& text, auto value, double bound, bool at_most,
                          int decimals) {
    std::string measured;
    std::optional<bool> pass;
    for (const GroupRow& row : cut_rows) {
      const std::optional<double> v = value(row);
      if (!measured.empty()) measured += ", ";
      measured += SceneSourceName(row.source) + ("/" + row.scenario) + " " + Fixed(v, decimals);
      if (!v) continue;
      const bool ok = at_most ? *v <= bound : *v >= bound;
      pass = pass.value_or(true) && ok;
    }
    add(text, measured.empty() ? none("cut") : measured, pass);
  };
  per_scenario(
      "cut scenes: cut-line error <= 3 mm (mean per scenario)",
      [](const GroupRow& r) { return r.cut_line_error_mm; }, 3.0, true, 2);
  {
    std::vector<double> latencies;
    for (const SceneResult* r : cut)
      if (r->latency_frames) latencies.push_back(*r->latency_frames);
    if (latencies.empty()) {
      add("cut scenes: latency <= 5 frames (median)", "no scene with a latency", std::nullopt);
    } else {
      const double m = Median(latencies);
      std::snprintf(buf, sizeof(buf), "median %.1f frames over %zu scenes", m, latencies.size());
      add("cut scenes: latency <= 5 frames (median)", buf, m <= 5.0);
    }
  }
  {
    std::optional<double> worst;
    std::string at;
    for (const SceneResult* r : cut)
      if (r->dice_final && (!worst || *r->dice_final < *worst)) {
        worst = r->dice_final;
        at = r->name;
      }
    if (!worst) {
      add("cut scenes: final Dice >= 0.95 on every scene", none("cut"), std::nullopt);
    } else {
      std::snprintf(buf, sizeof(buf), "lowest %.4f (%s)", *worst, at.c_str());
      add("cut scenes: final Dice >= 0.95 on every scene", buf, *worst >= 0.95);
    }
  }
  per_scenario(
      "cut scenes: (1 - Dice) with topology <= 0.5 x without (per scenario)",
      [](const GroupRow& r) { return r.error_ratio; }, 0.5, true, 2);
  if (no_cut.empty()) {
    add("no-cut scenes: false cuts in <= 2 % of them", none("no-cut"), std::nullopt);
  } else {
    int with_false = 0;
    for (const SceneResult* r : no_cut) with_false += r->applied_cuts > 0;
    std::snprintf(buf, sizeof(buf), "%d of %zu (%.1f %%)", with_false, no_cut.size(),
                  100.0 * with_false / no_cut.size());
    add("no-cut scenes: false cuts in <= 2 % of them", buf, with_false <= 0.02 * no_cut.size());
  }
  add("no false cut on ../shared/data/real/pulling_tissue.mp4",
      "not part of this benchmark (no ground truth); check with arreg run", std::nullopt);
  auto stretch_bound = [&](const std::string& text, auto value, double bound, bool at_most,
                           int decimals) {
    std::optional<double> worst;
    std::string at;
    for (const SceneResult* r : stretch) {
      const std::optional<double> v = value(*r);
      if (v && (!worst || (at_most ? *v > *worst : *v < *worst))) {
        worst = v;
        at = r->name;
      }
    }
    if (!worst) {
      add(text, stretch.empty() ? none("stretch") : "no stretch scene measures it", std::nullopt);
      return;
    }
    add(text, "worst " + Fixed(worst, decimals) + " (" + at + ")",
        at_most ? *worst <= bound : *worst >= bound);
  };
  stretch_bound(
      "stretch scenes: Dice >= 0.97 at every frame",
      [](const SceneResult& r) { return r.dice_min; }, 0.97, false, 4);
  stretch_bound(
      "stretch scenes: surface Hausdorff mean <= 1.5 mm at every evaluated frame",
      [](const SceneResult& r) { return r.surface_worst_mm; }, 1.5, true, 2);
  stretch_bound(
      "stretch scenes: internal Hausdorff mean <= 1.5 mm at every evaluated frame",
      [](const SceneResult& r) { return r.internal_worst_mm; }, 1.5, true, 2);
  return c;
}

}  // namespace arreg::eval
