#include "ar/debug/frame_render.h"

#include <algorithm>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <unordered_map>
#include <vector>

#include "ar/debug/recorder.h"
#include "core/error.h"
#include "core/file_util.h"

namespace arreg::debug {

namespace {

bool IsPoint(const nlohmann::json& p) {
  return p.is_array() && p.size() == 2 && p[0].is_number() && p[1].is_number();
}
cv::Point2d ToPoint(const nlohmann::json& p) { return {p[0].get<double>(), p[1].get<double>()}; }

// OpenCV draws with integer coordinates; 4 bits of sub-pixel precision keep lines smooth.
constexpr int kShift = 4;
cv::Point Fixed(const cv::Point2d& p) { return {cvRound(p.x * 16.0), cvRound(p.y * 16.0)}; }

void Line(cv::Mat* img, const cv::Point2d& a, const cv::Point2d& b, const cv::Scalar& c,
          int thickness = 1) {
  cv::line(*img, Fixed(a), Fixed(b), c, thickness, cv::LINE_AA, kShift);
}
void Circle(cv::Mat* img, const cv::Point2d& p, double r, const cv::Scalar& c, int thickness) {
  cv::circle(*img, Fixed(p), cvRound(r * 16.0), c, thickness, cv::LINE_AA, kShift);
}

// Wireframe of flattened pixels [u0, v0, ...] and edges [a0, b0, ...].
void Wireframe(const nlohmann::json& px, const nlohmann::json& edges, const cv::Scalar& colour,
               cv::Mat* img) {
  if (!px.is_array() || !edges.is_array()) return;
  const size_t nv = px.size() / 2;
  for (size_t e = 0; e + 1 < edges.size(); e += 2) {
    const size_t a = edges[e].get<size_t>(), b = edges[e + 1].get<size_t>();
    if (a >= nv || b >= nv) continue;
    if (!px[2 * a].is_number() || !px[2 * b].is_number()) continue;
    Line(img, {px[2 * a].get<double>(), px[2 * a + 1].get<double>()},
         {px[2 * b].get<double>(), px[2 * b + 1].get<double>()}, colour);
  }
}

void Polyline(const nlohmann::json& pts, const cv::Scalar& colour, int thickness, bool dashed,
              cv::Mat* img) {
  if (!pts.is_array()) return;
  for (size_t i = 0; i + 1 < pts.size(); ++i) {
    if (!IsPoint(pts[i]) || !IsPoint(pts[i + 1])) continue;
    const cv::Point2d a = ToPoint(pts[i]), b = ToPoint(pts[i + 1]);
    if (!dashed) {
      Line(img, a, b, colour, thickness);
      continue;
    }
    const double len = cv::norm(b - a);
    const int dashes = std::max(1, static_cast<int>(len / 6.0));
    for (int k = 0; k < dashes; k += 2)
      Line(img, a + (b - a) * (double(k) / dashes), a + (b - a) * (double(k + 1) / dashes), colour,
           thickness);
  }
}

void Text(cv::Mat* img, const std::string& s, int row) {
  const cv::Point org(8, 18 + 16 * row);
  cv::putText(*img, s, org, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
  cv::putText(*img, s, org, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
}

template <typename... Numbers>
std::string Format(const char* fmt, Numbers... numbers) {
  char buf[160];
  std::snprintf(buf, sizeof(buf), fmt, static_cast<double>(numbers)...);
  return buf;
}

}  // namespace

DebugLayers DebugLayers::Parse(const std::string& list) {
  DebugLayers l;
  l.features = l.targets = l.springs = l.pairs = l.outliers = l.cut = l.mesh = l.internal =
      l.numbers = l.instruments = false;
  std::stringstream ss(list);
  std::string name;
  while (std::getline(ss, name, ',')) {
    if (name.empty()) continue;
    if (name == "all") {
      l.features = l.targets = l.springs = l.pairs = l.outliers = l.cut = l.mesh = l.internal =
          l.numbers = l.instruments = true;
    } else if (name == "none") {
      l = DebugLayers::Parse("");
    } else if (name == "features") {
      l.features = true;
    } else if (name == "targets") {
      l.targets = true;
    } else if (name == "springs") {
      l.springs = true;
    } else if (name == "pairs") {
      l.pairs = true;
    } else if (name == "outliers") {
      l.outliers = true;
    } else if (name == "cut") {
      l.cut = true;
    } else if (name == "mesh") {
      l.mesh = true;
    } else if (name == "internal") {
      l.internal = true;
    } else if (name == "numbers") {
      l.numbers = true;
    } else if (name == "instruments") {
      l.instruments = true;
    } else {
      throw Error("", "--layers",
                  "unknown layer '" + name +
                      "' (valid: features, targets, springs, pairs, outliers, cut, mesh, "
                      "internal, numbers, instruments, all, none)");
    }
  }
  return l;
}

cv::Scalar RatioColor(double ratio) {
  const double r = std::clamp(ratio, 0.0, 1.0);
  // blue (255,0,0 BGR) -> green -> red
  if (r < 0.5) {
    const double t = r / 0.5;
    return cv::Scalar(255 * (1 - t), 255 * t, 0);
  }
  const double t = (r - 0.5) / 0.5;
  return cv::Scalar(0, 255 * (1 - t), 255 * t);
}

void DrawDebugLayers(const nlohmann::json& record, const nlohmann::json& topology,
                     const DebugLayers& layers, cv::Mat* image) {
  ARREG_ASSERT(image && image->type() == CV_8UC3, "BGR image expected");
  cv::Mat& img = *image;
  const nlohmann::json& features = record.at("features");
  std::unordered_map<int, cv::Point2d> pixel_of_id;
  for (const auto& f : features) pixel_of_id[f.at("id").get<int>()] = ToPoint(f.at("px"));

  if (layers.mesh && topology.is_object())
    Wireframe(record.at("surface_px"), topology.at("surface_edges"), cv::Scalar(200, 200, 200),
              &img);
  if (layers.internal && topology.is_object()) {
    const auto& internal = record.at("internal");
    const auto& edges = topology.at("internal_edges");
    for (size_t s = 0; s < internal.size() && s < edges.size(); ++s)
      Wireframe(internal[s].at("px"), edges[s], cv::Scalar(255, 120, 200), &img);
  }

  const nlohmann::json& det = record.at("detection");
  if (det.is_object() && (layers.pairs || layers.outliers)) {
    const double threshold = det.at("threshold").get<double>();
    for (const auto& p : det.at("pairs")) {
      const auto a = pixel_of_id.find(p[0].get<int>());
      const auto b = pixel_of_id.find(p[1].get<int>());
      if (a == pixel_of_id.end() || b == pixel_of_id.end()) continue;
      const bool outlier = p[3].get<int>() != 0;
      if (outlier && layers.outliers)
        Line(&img, a->second, b->second, cv::Scalar(0, 0, 255), 3);
      else if (layers.pairs)
        Line(&img, a->second, b->second,
             RatioColor(threshold > 0 ? p[2].get<double>() / threshold : 0.0), 1);
    }
  }

  const cv::Scalar orange(0, 140, 255);
  if (layers.instruments && record.contains("instruments"))
    for (const auto& outline : record.at("instruments")) {
      std::vector<cv::Point> poly;
      for (size_t k = 0; k + 1 < outline.size(); k += 2)
        poly.emplace_back(outline[k].get<int>(), outline[k + 1].get<int>());
      cv::polylines(img, std::vector<std::vector<cv::Point>>{poly}, true, orange, 1, cv::LINE_AA);
    }

  for (const auto& f : features) {
    const cv::Point2d px = ToPoint(f.at("px"));
    if (layers.instruments && f.at("status").get<std::string>() == "instrument")
      Circle(&img, px, 5.0, orange, 1);
    const bool has_target = f.contains("target_px") && IsPoint(f["target_px"]);
    const bool has_model = f.contains("model_px") && IsPoint(f["model_px"]);
    if (layers.springs && f.at("spring_active").get<bool>() && has_target && has_model)
      Line(&img, ToPoint(f["model_px"]), ToPoint(f["target_px"]), cv::Scalar(0, 230, 255), 1);
    if (layers.targets && has_target) {
      const cv::Point2d t = ToPoint(f["target_px"]);
      Line(&img, t + cv::Point2d(-3, -3), t + cv::Point2d(3, 3), cv::Scalar(255, 128, 0), 1);
      Line(&img, t + cv::Point2d(-3, 3), t + cv::Point2d(3, -3), cv::Scalar(255, 128, 0), 1);
    }
    if (layers.features) {
      const bool alive = f.at("alive").get<bool>();
      const bool attached = f.at("lift").get<std::string>() != "not-attached";
      const cv::Scalar c = alive      ? cv::Scalar(0, 220, 0)
                           : attached ? cv::Scalar(150, 150, 150)
                                      : cv::Scalar(60, 60, 220);
      Circle(&img, px, 3.0, c, alive ? -1 : 1);
    }
  }

  if (layers.cut) {
    const auto& cs = record.at("cut_surface");
    if (cs.is_object()) {
      const auto& px = cs.at("px");
      const auto& faces = cs.at("faces");
      cv::Mat fill = img.clone();
      for (size_t f = 0; f + 2 < faces.size(); f += 3) {
        std::vector<cv::Point> tri;
        for (int k = 0; k < 3; ++k) {
          const size_t v = faces[f + k].get<size_t>();
          if (2 * v + 1 >= px.size() || !px[2 * v].is_number()) break;
          tri.push_back(Fixed({px[2 * v].get<double>(), px[2 * v + 1].get<double>()}));
        }
        if (tri.size() == 3)
          cv::fillConvexPoly(fill, tri, cv::Scalar(255, 0, 255), cv::LINE_AA, kShift);
      }
      cv::addWeighted(fill, 0.3, img, 0.7, 0.0, img);
    }
    if (det.is_object()) {
      Polyline(det.at("extended_polyline_px"), cv::Scalar(255, 0, 255), 1, true, &img);
      Polyline(det.at("polyline_px"), cv::Scalar(255, 0, 255), 2, false, &img);
      for (const auto& p : det.at("polyline_px"))
        if (IsPoint(p)) Circle(&img, ToPoint(p), 4.0, cv::Scalar(255, 0, 255), -1);
      for (const auto& c : det.at("new_cut_points"))
        if (IsPoint(c.at("px"))) Circle(&img, ToPoint(c["px"]), 7.0, cv::Scalar(0, 255, 255), 2);
    }
  }

  if (layers.numbers) {
    int row = 0;
    const auto& stats = record.at("stats");
    Text(&img,
         Format("frame %.0f  t=%.3f s", record.at("frame").get<double>(),
                record.at("time_s").get<double>()),
         row++);
    Text(&img,
         Format("alive %.0f  lost %.0f  springs mean %.2f mm",
                stats.at("features_alive").get<double>(), stats.at("lost").get<double>(),
                stats.at("spring_length_mean_mm").get<double>()),
         row++);
    if (det.is_object()) {
      Text(&img,
           Format("pairs %.0f  outliers %.0f  mean mu %.4f mm",
                  static_cast<double>(det.at("pairs").size()), det.at("outliers").get<double>(),
                  det.at("mean_mu").get<double>()),
           row++);
      // Clusters rejected this frame (records of older runs lack some counters: 0).
      const auto count = [&](const char* key) { return det.value(key, 0.0); };
      Text(&img,
           Format("rejected: sliding %.0f  one-sided %.0f  star %.0f  unconfirmed %.0f  closing "
                  "%.0f  no growth %.0f  split %.0f",
                  count("lone_features"), count("one_sided_clusters"), count("star_starts"),
                  count("unconfirmed_starts"), count("closing_starts"), count("refused_points"),
                  count("refused_segments")),
           row++);
    }
    Text(&img, Format("total %.1f ms", record.at("ms").at("total").get<double>()), row++);
  }
}

void RenderDebugFrame(const std::string& run_dir, int frame, const DebugLayers& layers,
                      const std::string& png_path) {
  const std::string record_path = FrameRecordPath(run_dir, frame);
  ARREG_CHECK_INPUT(FileExists(record_path), record_path, "frame " + std::to_string(frame),
                    "frame not recorded (run `arreg run --debug` and check the frame range)");
  nlohmann::json record;
  try {
    record = nlohmann::json::parse(ReadFileToString(record_path));
  } catch (const nlohmann::json::exception& e) {
    throw Error(record_path, "", std::string("invalid JSON: ") + e.what());
  }
  nlohmann::json topology;
  const int topology_id = record.value("topology", -1);
  if ((layers.mesh || layers.internal) && topology_id >= 0) {
    const std::string tp = TopologyRecordPath(run_dir, topology_id);
    try {
      topology = nlohmann::json::parse(ReadFileToString(tp));
    } catch (const nlohmann::json::exception& e) {
      throw Error(tp, "", std::string("invalid JSON: ") + e.what());
    }
  }
  const std::string image_path = FrameImagePath(run_dir, frame);
  cv::Mat image = cv::imread(image_path, cv::IMREAD_COLOR);
  ARREG_CHECK_INPUT(!image.empty(), image_path, "frame " + std::to_string(frame),
                    "cannot read the recorded frame image");
  try {
    DrawDebugLayers(record, topology, layers, &image);
  } catch (const nlohmann::json::exception& e) {
    throw Error(record_path, "", std::string("unexpected record content: ") + e.what());
  }
  const std::string tmp = TemporaryPathFor(png_path);
  ARREG_CHECK_INPUT(cv::imwrite(tmp, image), png_path, "", "cannot write the PNG");
  CommitTemporaryFile(tmp, png_path);
}

}  // namespace arreg::debug
