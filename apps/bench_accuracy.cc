// `arreg bench accuracy`: registration and cut-detection accuracy over the scenes of a manifest
// (two scene sources, dev and test splits), one table; docs/benchmark.md.
// Each scene runs in its own process (fork): a crash or an exception in one scene becomes a
// failed row with its log, and --jobs scenes run side by side.
#include <sys/wait.h>
#include <unistd.h>

#include <fcntl.h>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "ar/eval/benchmark.h"
#include "ar/eval/evaluation.h"
#include "ar/pipeline/record_writer.h"
#include "ar/pipeline/registration_pipeline.h"
#include "ar/synth/generator.h"
#include "commands.h"
#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"
#include "core/scene.h"
#include "option_parser.h"

namespace arreg::cli {

namespace {

namespace fs = std::filesystem;

struct Settings {
  std::string cache;         // --cache
  std::string phantom_tool;  // --phantom-tool
  bool keep_runs = false;
  std::vector<std::string> overrides;  // --set SECTION.KEY=VALUE, applied to every scene
  eval::BenchMetricsOptions metrics;
};

// Marks a scene folder as complete: written last, after the generator succeeded.
constexpr const char* kCompleteMarker = "bench-scene.json";

bool IsExecutable(const std::string& path) { return access(path.c_str(), X_OK) == 0; }

// `name` found on PATH.
bool OnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  if (!path) return false;
  std::string dirs = path;
  size_t start = 0;
  while (start <= dirs.size()) {
    const size_t end = std::min(dirs.find(':', start), dirs.size());
    const std::string dir = dirs.substr(start, end - start);
    if (!dir.empty() && IsExecutable((fs::path(dir) / name).string())) return true;
    start = end + 1;
  }
  return false;
}

// Why a source cannot make scenes here, "" when it can.
std::string Unavailable(eval::SceneSource source, const Settings& s) {
  if (source != eval::SceneSource::kPhantom) return "";
  if (!IsExecutable(s.phantom_tool)) return s.phantom_tool + " is missing or not executable";
  if (!OnPath("blender")) return "blender is not installed (scripts/install-deps)";
  return "";
}

// Runs argv (stdout and stderr already go to the scene's log); throws on a non-zero exit.
void RunTool(const std::vector<std::string>& args) {
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = fork();
  ARREG_CHECK_INPUT(pid >= 0, args[0], "", "cannot start: ", std::strerror(errno));
  if (pid == 0) {
    std::vector<char*> argv;
    argv.reserve(args.size() + 1);
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    std::fprintf(stderr, "%s: cannot run: %s\n", args[0].c_str(), std::strerror(errno));
    _exit(127);
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  ARREG_CHECK_INPUT(WIFEXITED(status) && WEXITSTATUS(status) == 0, args[0], "",
                    WIFEXITED(status) ? "exited with code " + std::to_string(WEXITSTATUS(status))
                                      : std::string("was killed by a signal"));
}

// Writes the scene into `dir` with its source's generator.
void Generate(const eval::BenchScene& b, const Settings& s, const std::string& dir) {
  if (b.source == eval::SceneSource::kSynth) {
    synth::SynthOptions o;
    o.scenario = b.scenario;
    o.out_dir = dir;
    o.seed = static_cast<uint64_t>(b.seed);
    o.frames = b.params.frames;
    o.width = b.params.width;
    o.height = b.params.height;
    o.zoom = b.params.zoom;
    o.amplitude = b.params.amplitude;
    o.noise_sigma = b.params.noise;
    o.blur_sigma_px = b.params.blur;
    o.occluder = b.params.occluder;
    const synth::SynthSummary summary = synth::GenerateSyntheticScene(o);
    // The truth's shape still follows its grips; the scene is kept, the log says so.
    if (summary.unconverged_frames > 0)
      std::fprintf(stderr, "bench: %s: %d truth frames did not converge\n", b.name.c_str(),
                   summary.unconverged_frames);
  } else {
    RunTool({s.phantom_tool, "--scenario", b.scenario, "--seed", std::to_string(b.seed), "--out",
             dir, "--frames", std::to_string(b.params.frames), "--size",
             std::to_string(b.params.width) + "x" + std::to_string(b.params.height)});
    ARREG_CHECK_INPUT(FileExists(dir + "/scene.json"), s.phantom_tool, "",
                      "wrote no scene.json in ", dir);
  }
}

// The scene's folder in the cache, generated when missing or incomplete.
std::string EnsureScene(const eval::BenchScene& b, const Settings& s) {
  std::string dir = s.cache + "/scenes/" + b.CacheKey();
  if (FileExists(dir + "/" + kCompleteMarker) && FileExists(dir + "/scene.json")) return dir;
  std::error_code ec;
  fs::remove_all(dir, ec);  // an interrupted generation
  CreateDirectories(dir);
  try {
    Generate(b, s, dir);
  } catch (...) {
    fs::remove_all(dir, ec);  // no partial scene stays behind
    throw;
  }
  const nlohmann::json marker = {{"name", b.name},
                                 {"source", eval::SceneSourceName(b.source)},
                                 {"scenario", b.scenario},
                                 {"seed", b.seed},
                                 {"params", b.params.ToJson(b.source)}};
  WriteFileAtomic(dir + "/" + kCompleteMarker,
                  [&](std::ostream& out) { out << marker.dump(2) << '\n'; });
  return dir;
}

// `arreg run --no-video --no-render [--no-topology]` through the library. `save_every` 0 keeps
// the ground truth's frames.
void RunRegistration(const Scene& scene, const std::string& out_dir, bool topology,
                     int save_every) {
  pipeline::PipelineOptions options = pipeline::ReadPipelineOptions(scene);
  options.cutting.enabled = topology;
  options.output.video = false;
  options.render.enabled = false;
  options.Check();
  std::error_code ec;
  fs::remove_all(out_dir, ec);
  CreateDirectories(out_dir);
  pipeline::RegistrationPipeline pipe(scene, options);
  pipeline::RecordWriter records(out_dir, false);
  pipe.AddObserver(&records);
  pipeline::RunOptions run;
  run.save_every = save_every;
  const pipeline::RunSummary summary = pipe.Run(run);
  std::printf("%s: %d frames, %d cut events, %d applied, %.1f s\n", out_dir.c_str(), summary.frames,
              summary.cut_events, summary.cuts_applied, summary.seconds);
}

// One scene, in the worker process: generate, run with and without topology, evaluate, score.
eval::SceneResult ProcessScene(const eval::BenchScene& b, const Settings& s,
                               const std::function<void(const std::string&)>& say) {
  const auto start = std::chrono::steady_clock::now();
  eval::SceneResult result = eval::SceneResult::For(b);
  const std::string runs = s.cache + "/runs/" + b.name;
  const std::string with = runs + "/topology", without = runs + "/no-topology";
  try {
    say("scene");
    const std::string dir = EnsureScene(b, s);
    Scene scene = ReadScene(dir + "/scene.json");
    for (const std::string& o : s.overrides) SetSceneOption(&scene, o, "--set");
    ARREG_CHECK_INPUT(!scene.ground_truth_path.empty(), dir + "/scene.json", "ground_truth",
                      "the benchmark needs a ground-truth folder");
    say("run with topology");
    RunRegistration(scene, with, true, 0);
    say("run without topology");
    // Only its final Dice is reported: save the first and the last frame.
    RunRegistration(scene, without, false, b.params.frames);
    say("evaluate");
    eval::EvalOptions eo;
    eo.color_maps = false;
    const eval::RunEvaluation ew = eval::EvaluateRun(with, scene.ground_truth_path, eo);
    const eval::RunEvaluation eo_run = eval::EvaluateRun(without, scene.ground_truth_path, eo);
    eval::ScoreCuts(eval::ReadAppliedCuts(with + "/frames.jsonl"),
                    eval::ReadTrueCut(scene.ground_truth_path), s.metrics, &result);
    eval::ScoreRegistration(ew, eo_run, &result);
  } catch (const std::exception& e) {
    result.status = eval::SceneStatus::kFailed;
    result.reason = e.what();
  }
  if (!s.keep_runs) {
    std::error_code ec;
    fs::remove_all(with, ec);
    fs::remove_all(without, ec);
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

std::string ResultPath(const Settings& s, const std::string& name) {
  return s.cache + "/runs/" + name + "/result.json";
}
std::string LogPath(const Settings& s, const std::string& name) {
  return s.cache + "/logs/" + name + ".log";
}

// Forks the worker of scene i; its stdout and stderr go to the scene's log, its progress lines
// to this process's stderr.
pid_t StartWorker(const eval::BenchScene& b, int index, int total, const Settings& s,
                  bool single_threaded) {
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = fork();
  ARREG_CHECK_INPUT(pid >= 0, "", "--jobs", "cannot fork: ", std::strerror(errno));
  if (pid != 0) return pid;
  int code = 0;
  try {
    const int progress_fd = dup(STDERR_FILENO);
    const std::string log = LogPath(s, b.name);
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ARREG_CHECK_INPUT(fd >= 0, log, "", "cannot write: ", std::strerror(errno));
    dup2(fd, STDOUT_FILENO);
    dup2(fd, STDERR_FILENO);
    close(fd);
    // Scenes side by side share the cores: one thread each.
    if (single_threaded) {
      setenv("OMP_NUM_THREADS", "1", 1);
      setenv("OPENBLAS_NUM_THREADS", "1", 1);
    }
    auto say = [&](const std::string& what) {
      dprintf(progress_fd, "bench: [%d/%d] %s: %s\n", index + 1, total, b.name.c_str(),
              what.c_str());
    };
    const eval::SceneResult r = ProcessScene(b, s, say);
    if (r.status == eval::SceneStatus::kFailed)
      std::fprintf(stderr, "bench: %s: %s\n", b.name.c_str(), r.reason.c_str());
    CreateDirectories(s.cache + "/runs/" + b.name);
    WriteFileAtomic(ResultPath(s, b.name),
                    [&](std::ostream& out) { out << r.ToJson().dump(2) << '\n'; });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench: %s: %s\n", b.name.c_str(), e.what());
    code = 1;
  }
  std::fflush(stdout);
  std::fflush(stderr);
  _exit(code);
}

// Runs the scenes (skipped ones already filled in `results`), at most `jobs` at a time.
void RunScenes(const std::vector<eval::BenchScene>& scenes, int jobs, const Settings& s,
               std::vector<eval::SceneResult>* results) {
  const int total = static_cast<int>(scenes.size());
  std::map<pid_t, int> running;
  int next = 0, done = 0;
  while (next < total || !running.empty()) {
    while (static_cast<int>(running.size()) < jobs && next < total) {
      const int i = next++;
      if ((*results)[i].status == eval::SceneStatus::kSkipped) {
        std::fprintf(stderr, "bench: [%d/%d] %s: skipped (%s)\n", i + 1, total,
                     scenes[i].name.c_str(), (*results)[i].reason.c_str());
        ++done;
        continue;
      }
      std::error_code ec;
      fs::remove(ResultPath(s, scenes[i].name), ec);
      running[StartWorker(scenes[i], i, total, s, jobs > 1)] = i;
    }
    if (running.empty()) continue;
    int status = 0;
    const pid_t pid = waitpid(-1, &status, 0);
    if (pid < 0) {
      ARREG_CHECK_INPUT(errno == EINTR, "", "waitpid", std::strerror(errno));
      continue;
    }
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const int i = it->second;
    running.erase(it);
    ++done;
    eval::SceneResult& r = (*results)[i];
    const std::string path = ResultPath(s, scenes[i].name);
    if (FileExists(path)) {
      r = eval::SceneResult::FromJson(ParseJsonFile(path), path);
    } else {
      r.status = eval::SceneStatus::kFailed;
      r.reason = WIFSIGNALED(status)
                     ? "worker killed by signal " + std::to_string(WTERMSIG(status))
                     : "worker exited with code " + std::to_string(WEXITSTATUS(status));
    }
    if (r.status == eval::SceneStatus::kOk)
      std::fprintf(stderr, "bench: [%d/%d] %s: done in %.0f s (%d cuts applied), %d of %d left\n",
                   i + 1, total, r.name.c_str(), r.seconds, r.applied_cuts, total - done, total);
    else
      std::fprintf(stderr, "bench: [%d/%d] %s: FAILED: %s (log: %s)\n", i + 1, total,
                   r.name.c_str(), r.reason.c_str(), LogPath(s, r.name).c_str());
  }
}

}  // namespace

int RunBenchAccuracy(int argc, char** argv) {
  std::string manifest = "data/benchmark/accuracy.json", split = "dev", source = "all";
  std::string only, json_path;
  Settings s;
  s.cache = "data/cache/bench";
  s.phantom_tool = "tools/phantoms/make-scene";
  bool quick = false;
  const long cores = sysconf(_SC_NPROCESSORS_ONLN);
  int jobs = cores > 0 ? static_cast<int>(cores) : 1;
  OptionParser parser(
      "arreg bench accuracy [--split dev|test|all] [--source synth|phantom|all] [options]",
      "Generates the manifest's scenes (cached), registers each with and without topology, "
      "evaluates against the ground truth and prints one table per source, scenario and split: "
      "cut detection (recall, false and misplaced cuts, cut-line error, latency), Dice and "
      "Hausdorff figures, and the acceptance criteria of issue 33.");
  parser.AddString("manifest", &manifest, "FILE", "scene manifest (docs/benchmark.md)");
  parser.AddString("split", &split, "dev|test|all",
                   "which split to run (test: to report only, never to tune)");
  parser.AddString("source", &source, "synth|phantom|all", "which scene source");
  parser.AddString("only", &only, "REGEX", "only the scenes whose name matches (search)");
  parser.AddFlag("quick", &quick, "the manifest's short CI subset (split quick) instead");
  parser.AddInt("jobs", &jobs, "N", "scenes processed side by side (default: the cores)");
  parser.AddString("cache", &s.cache, "DIR",
                   "generated scenes (keyed by their parameters), runs, logs and results");
  parser.AddString("phantom-tool", &s.phantom_tool, "PATH", "the phantom scene generator");
  parser.AddStringList("set", &s.overrides, "SECTION.KEY=VALUE",
                       "override a module option of every scene (docs/pipeline-options.md), e.g. "
                       "tracking.redetect_every_frames=5");
  parser.AddFlag("keep-runs", &s.keep_runs, "keep the run folders (DIR/runs/NAME/...)");
  parser.AddDouble("found-within", &s.metrics.found_within_mm, "MM",
                   "an applied cut this close (mean) to the true cut surface is a found cut");
  parser.AddString("json", &json_path, "OUT", "also write the per-scene rows and the table");
  parser.SetEpilog(
      "Columns: recall (cut scenes with a found cut), false (applied cuts per no-cut scene),\n"
      "misplc (misplaced cuts per cut scene), line_mm (cut-line error), lat (median latency in\n"
      "frames from a 2 mm opening), Dice / noTopo (final Dice with and without topology), ratio\n"
      "(sum of 1 - Dice with / without), minDic (lowest Dice of any frame), surf and int (mean\n"
      "of the per-frame Hausdorff means / worst frame, mm). Run from the repository root, or\n"
      "give --manifest, --cache and --phantom-tool. See docs/benchmark.md.");
  if (!parser.Parse(argc, argv)) return 0;
  // "all" is no restriction.
  std::optional<eval::BenchSplit> only_split;
  if (split != "all") {
    ARREG_CHECK_INPUT(split == "dev" || split == "test", "", "--split",
                      "expected dev, test or all, got '", split, "'");
    only_split = eval::ParseBenchSplit(split, "", "--split");
  }
  std::optional<eval::SceneSource> only_source;
  if (source != "all") {
    ARREG_CHECK_INPUT(source == "synth" || source == "phantom", "", "--source",
                      "expected synth, phantom or all, got '", source, "'");
    only_source = eval::ParseSceneSource(source, "", "--source");
  }
  ARREG_CHECK_INPUT(jobs >= 1, "", "--jobs", "must be >= 1, got ", jobs);
  {
    // A bad --set fails here, once, not in every scene's worker.
    Scene probe;
    for (const std::string& o : s.overrides) SetSceneOption(&probe, o, "--set");
    pipeline::ReadPipelineOptions(probe).Check();
  }
  ARREG_CHECK_INPUT(!quick || !parser.Given("split"), "", "--quick",
                    "runs the quick split; do not combine with --split");
  s.metrics.Check();
  std::regex pattern;
  try {
    pattern = std::regex(only);
  } catch (const std::regex_error& e) {
    throw UsageError("--only", std::string("not a regular expression: ") + e.what());
  }

  std::vector<eval::BenchScene> scenes;
  for (const eval::BenchScene& b : eval::ReadBenchManifest(manifest)) {
    const bool split_ok =
        quick ? b.split == eval::BenchSplit::kQuick
              : (b.split != eval::BenchSplit::kQuick && (!only_split || b.split == *only_split));
    if (!split_ok || (only_source && b.source != *only_source)) continue;
    if (!only.empty() && !std::regex_search(b.name, pattern)) continue;
    scenes.push_back(b);
  }
  ARREG_CHECK_INPUT(!scenes.empty(), manifest, "scenes", "no scene matches the selection");
  for (const char* sub : {"/scenes", "/runs", "/logs"}) CreateDirectories(s.cache + sub);

  std::vector<eval::SceneResult> results;
  for (const eval::BenchScene& b : scenes) {
    eval::SceneResult r = eval::SceneResult::For(b);
    const std::string why = Unavailable(b.source, s);
    if (!why.empty()) {
      r.status = eval::SceneStatus::kSkipped;
      r.reason = why;
    }
    results.push_back(r);
  }
  std::fprintf(stderr, "bench: %zu scenes, %d at a time, cache %s\n", scenes.size(), jobs,
               s.cache.c_str());
  RunScenes(scenes, jobs, s, &results);

  const std::vector<eval::GroupRow> rows = eval::AggregateResults(results);
  std::printf("%s", eval::FormatTable(rows).c_str());
  int failed = 0;
  for (const eval::SceneResult& r : results) {
    if (r.status == eval::SceneStatus::kOk) continue;
    failed += r.status == eval::SceneStatus::kFailed;
    std::printf("%s %s: %s\n", eval::SceneStatusName(r.status), r.name.c_str(), r.reason.c_str());
  }
  nlohmann::json acceptance = nlohmann::json::object();
  std::set<eval::BenchSplit> splits;
  for (const eval::SceneResult& r : results) splits.insert(r.split);
  for (const eval::BenchSplit sp : splits) {
    std::vector<eval::SceneResult> in_split;
    for (const eval::SceneResult& r : results)
      if (r.split == sp) in_split.push_back(r);
    std::printf("\nacceptance (issue 33) on the %s split:\n", eval::BenchSplitName(sp));
    nlohmann::json lines = nlohmann::json::array();
    for (const eval::Criterion& c : eval::AcceptanceCriteria(in_split)) {
      std::printf("  %-5s %s: %s\n",
                  !c.pass   ? "n/a"
                  : *c.pass ? "PASS"
                            : "FAIL",
                  c.text.c_str(), c.measured.c_str());
      lines.push_back(c.ToJson());
    }
    acceptance[eval::BenchSplitName(sp)] = lines;
  }
  if (!json_path.empty()) {
    nlohmann::json j;
    j["manifest"] = manifest;
    j["split"] = quick ? "quick" : split;
    j["source"] = source;
    j["only"] = only;
    j["found_within_mm"] = s.metrics.found_within_mm;
    j["opening_mm"] = s.metrics.opening_mm;
    j["scenes"] = nlohmann::json::array();
    for (const eval::SceneResult& r : results) j["scenes"].push_back(r.ToJson());
    j["table"] = nlohmann::json::array();
    for (const eval::GroupRow& row : rows) j["table"].push_back(row.ToJson());
    j["acceptance"] = acceptance;
    WriteFileAtomic(json_path, [&](std::ostream& out) { out << j.dump(2) << '\n'; });
  }
  return failed > 0 ? 1 : 0;
}

}  // namespace arreg::cli
