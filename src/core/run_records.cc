#include "core/run_records.h"

#include <algorithm>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/error.h"
#include "core/file_util.h"
#include "core/json_reader.h"

namespace arreg {

RunSummaryRecord ReadRunSummary(const std::string& path) {
  const nlohmann::json root = ParseJsonFile(path);
  ARREG_CHECK_INPUT(root.is_object(), path, "", "expected a JSON object");
  RunSummaryRecord info;
  ARREG_CHECK_INPUT(root.contains("camera"), path, "camera", "required key is missing");
  JsonObjectReader camera_reader(root.at("camera"), path, "camera");
  info.camera = ReadCameraJson(camera_reader);
  ARREG_CHECK_INPUT(root.contains("frames"), path, "frames", "required key is missing");
  ReadJsonValue(root.at("frames"), path, "frames", &info.frames);
  ARREG_CHECK_INPUT(info.frames >= 1, path, "frames", "must be >= 1, got ", info.frames);
  if (root.contains("topology") && !root.at("topology").is_null())
    ReadJsonValue(root.at("topology"), path, "topology", &info.topology);
  if (root.contains("interrupted") && !root.at("interrupted").is_null())
    ReadJsonValue(root.at("interrupted"), path, "interrupted", &info.interrupted);
  if (root.contains("thin_structures") && !root.at("thin_structures").is_null()) {
    const nlohmann::json& names = root.at("thin_structures");
    ARREG_CHECK_INPUT(names.is_array(), path, "thin_structures", "expected an array of names");
    for (size_t i = 0; i < names.size(); ++i) {
      const std::string key = "thin_structures[" + std::to_string(i) + "]";
      ARREG_CHECK_INPUT(names[i].is_string() && !names[i].get<std::string>().empty(), path, key,
                        "expected a non-empty name");
      const std::string name = names[i].get<std::string>();
      ARREG_CHECK_INPUT(std::find(info.thin_structures.begin(), info.thin_structures.end(), name) ==
                            info.thin_structures.end(),
                        path, key, "duplicate name '", name, "'");
      info.thin_structures.push_back(name);
    }
  }
  return info;
}

std::vector<FrameRecord> ReadFrameRecords(const std::string& path, int num_frames) {
  std::istringstream in(ReadFileToString(path));
  std::vector<FrameRecord> records;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const std::string where = "line " + std::to_string(line_number);
    nlohmann::json record;
    try {
      record = nlohmann::json::parse(line);
    } catch (const nlohmann::json::exception& e) {  // syntax, or a number out of range (1e400)
      throw Error(path, where, std::string("invalid JSON: ") + e.what());
    }
    ARREG_CHECK_INPUT(record.is_object() && record.contains("frame"), path, where,
                      "expected an object with a \"frame\" key");
    const int count = static_cast<int>(records.size());
    int frame = -1;
    ReadJsonValue(record.at("frame"), path, where + ": frame", &frame);
    ARREG_CHECK_INPUT(frame == count, path, where, "expected frame ", count, ", got ", frame);
    ARREG_CHECK_INPUT(count < num_frames, path, where, "more records than run.json's frames (",
                      num_frames, ")");
    FrameRecord& f = records.emplace_back();
    for (const auto& [key, target] : {std::pair{"feature_error_mean_mm", &f.feature_error_mean_mm},
                                      std::pair{"feature_error_max_mm", &f.feature_error_max_mm}}) {
      if (!record.contains(key) || record.at(key).is_null()) continue;
      double value = 0.0;
      ReadJsonValue(record.at(key), path, where + ": " + key, &value);
      *target = value;
    }
  }
  ARREG_CHECK_INPUT(static_cast<int>(records.size()) == num_frames, path, "", "has ",
                    records.size(), " frame records but run.json says frames = ", num_frames);
  return records;
}

GroundTruthMeta ReadGroundTruthMeta(const std::string& path) {
  const nlohmann::json meta = ParseJsonFile(path);
  ARREG_CHECK_INPUT(meta.is_object() && meta.contains("frames"), path, "frames",
                    "required key is missing");
  GroundTruthMeta out;
  ReadJsonValue(meta.at("frames"), path, "frames", &out.frames);
  for (const auto& [key, target] :
       {std::pair{"width", &out.width}, std::pair{"height", &out.height}}) {
    if (!meta.contains(key)) continue;
    int value = 0;
    ReadJsonValue(meta.at(key), path, key, &value);
    *target = value;
  }
  return out;
}

}  // namespace arreg
