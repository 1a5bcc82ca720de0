// Writers of the evaluation report: report.json, report.csv, the colour maps and a
// self-contained report.html (inline SVG plots, images as data URIs, no scripts).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <ostream>
#include <sstream>

#include "ar/eval/color_map.h"
#include "ar/eval/evaluation.h"
#include "ar/eval/html.h"
#include "core/error.h"
#include "core/file_util.h"

namespace arreg::eval {

namespace fs = std::filesystem;

namespace {

nlohmann::json OptionalNumber(const std::optional<double>& value) {
  return value ? nlohmann::json(*value) : nlohmann::json(nullptr);
}

nlohmann::json FiguresToJson(const std::optional<HausdorffFigures>& h) {
  if (!h) return nullptr;
  return {{"mean_model_to_gt", h->mean_model_to_gt},
          {"mean_gt_to_model", h->mean_gt_to_model},
          {"max_model_to_gt", h->max_model_to_gt},
          {"max_gt_to_model", h->max_gt_to_model},
          {"max", h->max}};
}

std::string Number(const std::optional<double>& value, int digits = 4) {
  if (!value) return "";
  char text[48];
  std::snprintf(text, sizeof(text), "%.*g", digits + 2, *value);
  return text;
}

std::string Fixed(const std::optional<double>& value, int decimals) {
  if (!value) return "&ndash;";
  char text[48];
  std::snprintf(text, sizeof(text), "%.*f", decimals, *value);
  return text;
}

std::string ColorMapFile(const std::string& prefix, const DistanceField& field,
                         const std::string& ext) {
  char frame[16];
  std::snprintf(frame, sizeof(frame), "%06d", field.frame);
  return "colormaps/" + prefix + field.name + "_" + frame + ext;
}

void WriteBytesAtomic(const std::string& path, const std::vector<uchar>& bytes) {
  WriteFileAtomic(
      path,
      [&](std::ostream& os) {
        os.write(reinterpret_cast<const char*>(bytes.data()),
                 static_cast<std::streamsize>(bytes.size()));
      },
      /*binary=*/true);
}

struct ColorMapImage {
  std::string caption;
  std::string png_path;          // relative to the report
  std::vector<uchar> png_bytes;  // embedded in the page
};

// Writes the OBJ and PNG of every distance field of `run`; returns the images.
std::vector<ColorMapImage> WriteColorMaps(const std::string& out_dir, const std::string& prefix,
                                          const RunEvaluation& run, const EvalOptions& options) {
  std::vector<ColorMapImage> images;
  for (const DistanceField& field : run.distance_fields) {
    const std::string obj = ColorMapFile(prefix, field, ".obj");
    const std::string png = ColorMapFile(prefix, field, ".png");
    WriteColoredObj((fs::path(out_dir) / obj).string(),
                    ColorByDistance(field.mesh, field.distances, field.scale_max_mm));
    ColorMapImageOptions image_options;
    image_options.max_distance = field.scale_max_mm;
    image_options.supersampling = options.color_map_supersampling;
    std::string title = field.name;
    std::replace(title.begin(), title.end(), '_', ' ');
    image_options.title = title + ", frame " + std::to_string(field.frame);
    const cv::Mat image =
        RenderDistanceImage(run.camera, field.mesh, field.distances, image_options);
    ColorMapImage entry;
    ARREG_CHECK_INPUT(cv::imencode(".png", image, entry.png_bytes), png, "", "PNG encoding failed");
    WriteBytesAtomic((fs::path(out_dir) / png).string(), entry.png_bytes);
    entry.caption = run.label + ": " + image_options.title + " (scale 0 to " +
                    Fixed(field.scale_max_mm, 2) + " mm)";
    entry.png_path = png;
    images.push_back(std::move(entry));
  }
  return images;
}

// The five figures of `h` (mean model->gt, mean gt->model, the directed maxima, the symmetric
// maximum), each absent when `h` is.
std::vector<std::optional<double>> FigureList(const std::optional<HausdorffFigures>& h) {
  if (!h) return std::vector<std::optional<double>>(5);
  return {h->mean_model_to_gt, h->mean_gt_to_model, h->max_model_to_gt, h->max_gt_to_model, h->max};
}

// `thin_names`: the thin structures whose columns the file has (those of the first run).
void WriteCsvRows(std::ostream& os, const std::string& name, const RunEvaluation& run,
                  const std::vector<std::string>& thin_names) {
  for (const FrameEvaluation& f : run.frames) {
    os << name << ',' << f.frame << ',' << Number(f.dice, 8);
    for (const auto* h : {&f.surface, &f.internal})
      for (const std::optional<double>& x : FigureList(*h)) os << ',' << Number(x, 8);
    os << ',' << Number(f.feature_error_mean_mm, 8) << ',' << Number(f.feature_error_max_mm, 8);
    for (const std::string& thin_name : thin_names) {
      ThinFrameFigures t;
      for (size_t k = 0; k < run.thin.size() && k < f.thin.size(); ++k)
        if (run.thin[k].name == thin_name) t = f.thin[k];
      os << ',' << Number(t.dice, 8);
      for (const std::optional<double>& x : FigureList(t.hausdorff)) os << ',' << Number(x, 8);
    }
    os << '\n';
  }
}

PlotSeries Series(const std::string& name, const std::string& color, bool dashed,
                  const RunEvaluation& run,
                  const std::function<std::optional<double>(const FrameEvaluation&)>& value) {
  PlotSeries s;
  s.name = name;
  s.color = color;
  s.dashed = dashed;
  for (const FrameEvaluation& f : run.frames)
    if (const auto v = value(f)) s.points.emplace_back(f.frame, *v);
  return s;
}

std::string NumbersRow(const RunEvaluation& run) {
  std::ostringstream os;
  os << "<tr><th scope=\"row\">" << HtmlEscape(run.label) << "</th><td>" << Fixed(run.dice_final, 4)
     << "</td><td>" << Fixed(run.dice_mean, 4) << "</td>";
  for (const auto* h : {&run.surface, &run.internal})
    for (const std::optional<double>& x : FigureList(*h)) os << "<td>" << Fixed(x, 3) << "</td>";
  os << "<td>" << Fixed(run.feature_error_mean_mm, 3) << "</td><td>"
     << Fixed(run.feature_error_max_mm, 3) << "</td></tr>\n";
  return os.str();
}

std::string BuildHtml(const std::string& gt_dir, const RunEvaluation& run,
                      const RunEvaluation* baseline, const EvalOptions& options,
                      const std::vector<ColorMapImage>& images) {
  std::vector<const RunEvaluation*> runs = {&run};
  if (baseline) runs.push_back(baseline);
  const char* colors[] = {"#1f77b4", "#d62728"};
  std::ostringstream os;
  os << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        "<title>arreg evaluation</title>\n<style>\n"
        "body{font-family:sans-serif;margin:24px;color:#222;max-width:1180px}\n"
        "table{border-collapse:collapse;margin:8px 0 16px;font-size:13px}\n"
        "th,td{border:1px solid #bbb;padding:4px 8px;text-align:right}\n"
        "th{background:#f0f0f0}\nth[scope=row]{text-align:left}\n"
        "figure{display:inline-block;margin:8px;vertical-align:top}\n"
        "figure img{max-width:540px;border:1px solid #888}\n"
        "figcaption{font-size:13px;max-width:540px}\n"
        ".meta{font-size:13px;color:#555}\nsvg.plot{margin:8px 0}\n"
        "</style>\n</head>\n<body>\n<h1>arreg evaluation</h1>\n<p class=\"meta\">";
  for (const RunEvaluation* r : runs)
    os << HtmlEscape(r->label) << ": <code>" << HtmlEscape(r->run_dir) << "</code> ("
       << r->num_frames << " frames" << (r->interrupted ? ", interrupted" : "") << ")<br>\n";
  const SurfaceSamplingOptions& s = options.hausdorff.sampling;
  os << "ground truth: <code>" << HtmlEscape(gt_dir) << "</code><br>\n"
     << "Hausdorff sampling: every vertex plus max(" << s.min_random_samples << ", min("
     << s.max_random_samples << ", " << s.samples_per_area
     << " per mm&sup2; &times; area)) uniform random points per surface (seed " << s.seed
     << "), exact point-to-triangle distances.</p>\n";

  os << "<h2>Key numbers</h2>\n<table id=\"key-numbers\">\n<tr><th rowspan=\"2\">run</th>"
        "<th colspan=\"2\">Dice</th><th colspan=\"5\">Hausdorff surface (mm)</th>"
        "<th colspan=\"5\">Hausdorff internal (mm)</th><th colspan=\"2\">feature error "
        "(mm)</th></tr>\n<tr><th>final</th><th>mean</th>";
  for (int k = 0; k < 2; ++k)
    os << "<th>mean model&rarr;gt</th><th>mean gt&rarr;model</th><th>max model&rarr;gt</th>"
          "<th>max gt&rarr;model</th><th>max</th>";
  os << "<th>mean</th><th>max</th></tr>\n";
  for (const RunEvaluation* r : runs) os << NumbersRow(*r);
  os << "</table>\n";
  if (!run.thin.empty()) {
    os << "<h2>Thin structures</h2>\n<p class=\"meta\">Dice above is that of the union "
          "silhouette (organ and thin structures); here each structure's own silhouette against "
          "its true one, and the Hausdorff figures of its surface.</p>\n<table "
          "id=\"thin-structures\">\n<tr><th rowspan=\"2\">run</th><th "
          "rowspan=\"2\">structure</th><th colspan=\"2\">Dice</th><th colspan=\"5\">Hausdorff "
          "(mm)</th></tr>\n<tr><th>final</th><th>mean</th><th>mean model&rarr;gt</th><th>mean "
          "gt&rarr;model</th><th>max model&rarr;gt</th><th>max "
          "gt&rarr;model</th><th>max</th></tr>\n";
    for (const RunEvaluation* r : runs)
      for (const ThinSummary& t : r->thin) {
        os << "<tr><th scope=\"row\">" << HtmlEscape(r->label) << "</th><td>" << HtmlEscape(t.name)
           << "</td><td>" << Fixed(t.dice_final, 4) << "</td><td>" << Fixed(t.dice_mean, 4)
           << "</td>";
        for (const std::optional<double>& x : FigureList(t.hausdorff))
          os << "<td>" << Fixed(x, 3) << "</td>";
        os << "</tr>\n";
      }
    os << "</table>\n";
  }

  std::vector<PlotSeries> dice, surface, internal, feature;
  for (size_t i = 0; i < runs.size(); ++i) {
    const RunEvaluation& r = *runs[i];
    dice.push_back(
        Series(r.label, colors[i], false, r, [](const FrameEvaluation& f) { return f.dice; }));
    const auto add_h = [&](std::vector<PlotSeries>* out,
                           std::optional<HausdorffFigures> FrameEvaluation::*field) {
      out->push_back(Series(r.label + ", mean model\u2192gt", colors[i], false, r,
                            [field](const FrameEvaluation& f) {
                              const auto& h = f.*field;
                              return h ? std::optional(h->mean_model_to_gt) : std::nullopt;
                            }));
      out->push_back(Series(r.label + ", mean gt\u2192model", colors[i], true, r,
                            [field](const FrameEvaluation& f) {
                              const auto& h = f.*field;
                              return h ? std::optional(h->mean_gt_to_model) : std::nullopt;
                            }));
    };
    add_h(&surface, &FrameEvaluation::surface);
    add_h(&internal, &FrameEvaluation::internal);
    feature.push_back(Series(r.label + ", mean", colors[i], false, r,
                             [](const FrameEvaluation& f) { return f.feature_error_mean_mm; }));
    feature.push_back(Series(r.label + ", max", colors[i], true, r,
                             [](const FrameEvaluation& f) { return f.feature_error_max_mm; }));
  }
  os << "<h2>Dice over time</h2>\n"
     << SvgLinePlot("plot-dice", "Dice coefficient per frame", "frame", "Dice", dice, 0.0, 1.0);
  if (!run.thin.empty()) {
    std::vector<PlotSeries> thin_dice, thin_distance;
    for (size_t i = 0; i < runs.size(); ++i)
      for (size_t k = 0; k < runs[i]->thin.size(); ++k) {
        const std::string name = runs[i]->label + ", " + runs[i]->thin[k].name;
        const bool dashed = k % 2 == 1;
        thin_dice.push_back(
            Series(name, colors[i], dashed, *runs[i], [k](const FrameEvaluation& f) {
              return k < f.thin.size() ? f.thin[k].dice : std::nullopt;
            }));
        thin_distance.push_back(Series(
            name + ", mean symmetric", colors[i], dashed, *runs[i], [k](const FrameEvaluation& f) {
              if (k >= f.thin.size() || !f.thin[k].hausdorff) return std::optional<double>();
              const HausdorffFigures& h = *f.thin[k].hausdorff;
              return std::optional(0.5 * (h.mean_model_to_gt + h.mean_gt_to_model));
            }));
      }
    os << "<h2>Thin structures over time</h2>\n"
       << SvgLinePlot("plot-thin-dice", "Dice of each thin structure's silhouette", "frame", "Dice",
                      thin_dice, 0.0, 1.0)
       << SvgLinePlot("plot-thin-hausdorff",
                      "Mean surface distance of each thin structure (average of both directions)",
                      "frame", "mm", thin_distance);
  }
  const auto has_points = [](const std::vector<PlotSeries>& series) {
    return std::any_of(series.begin(), series.end(),
                       [](const PlotSeries& s) { return !s.points.empty(); });
  };
  if (has_points(surface))
    os << "<h2>Hausdorff distance, surface</h2>\n"
       << SvgLinePlot("plot-hausdorff-surface", "Mean surface distance", "frame", "mm", surface);
  if (has_points(internal))
    os << "<h2>Hausdorff distance, internal structures</h2>\n"
       << SvgLinePlot("plot-hausdorff-internal", "Mean internal-structure distance", "frame", "mm",
                      internal);
  if (has_points(feature))
    os << "<h2>Feature error</h2>\n"
       << SvgLinePlot("plot-feature-error", "|p_F^t - p_F^1| over alive springs", "frame", "mm",
                      feature);
  if (!images.empty()) {
    os << "<h2>Distance colour maps</h2>\n<p class=\"meta\">Per-vertex distance to the other "
          "surface, rendered with the run camera; meshes with vertex colours beside the "
          "images (OBJ, <code>v x y z r g b</code>).</p>\n";
    for (const ColorMapImage& image : images)
      os << "<figure><img alt=\"" << HtmlEscape(image.caption) << "\" src=\"data:image/png;base64,"
         << Base64Encode(image.png_bytes) << "\"><figcaption>" << HtmlEscape(image.caption)
         << " &mdash; <code>" << HtmlEscape(image.png_path) << "</code></figcaption></figure>\n";
  }
  os << "</body>\n</html>\n";
  return os.str();
}

}  // namespace

nlohmann::json EvaluationToJson(const RunEvaluation& ev) {
  nlohmann::json j;
  j["run"] = ev.run_dir;
  j["label"] = ev.label;
  j["topology"] = ev.topology;
  j["interrupted"] = ev.interrupted;
  j["num_frames"] = ev.num_frames;
  j["dice_final"] = ev.dice_final;
  j["dice_mean"] = ev.dice_mean;
  j["hausdorff_surface"] = FiguresToJson(ev.surface);
  j["hausdorff_internal"] = FiguresToJson(ev.internal);
  j["feature_error_mm"] = {{"mean", OptionalNumber(ev.feature_error_mean_mm)},
                           {"max", OptionalNumber(ev.feature_error_max_mm)}};
  if (!ev.thin.empty()) {  // only for runs with thin structures (others keep their keys)
    nlohmann::json thin = nlohmann::json::array();
    for (const ThinSummary& t : ev.thin)
      thin.push_back({{"name", t.name},
                      {"dice_final", OptionalNumber(t.dice_final)},
                      {"dice_mean", OptionalNumber(t.dice_mean)},
                      {"hausdorff", FiguresToJson(t.hausdorff)}});
    j["thin_structures"] = std::move(thin);
  }
  nlohmann::json frames = nlohmann::json::array();
  for (const FrameEvaluation& f : ev.frames) {
    nlohmann::json frame = {{"frame", f.frame},
                            {"dice", OptionalNumber(f.dice)},
                            {"hausdorff_surface", FiguresToJson(f.surface)},
                            {"hausdorff_internal", FiguresToJson(f.internal)},
                            {"feature_error_mean_mm", OptionalNumber(f.feature_error_mean_mm)},
                            {"feature_error_max_mm", OptionalNumber(f.feature_error_max_mm)}};
    if (!ev.thin.empty()) {
      nlohmann::json thin = nlohmann::json::object();
      for (size_t k = 0; k < ev.thin.size(); ++k) {
        const ThinFrameFigures none;
        const ThinFrameFigures& t = k < f.thin.size() ? f.thin[k] : none;
        thin[ev.thin[k].name] = {{"dice", OptionalNumber(t.dice)},
                                 {"hausdorff", FiguresToJson(t.hausdorff)}};
      }
      frame["thin"] = std::move(thin);
    }
    frames.push_back(std::move(frame));
  }
  j["frames"] = std::move(frames);
  return j;
}

void WriteEvalReport(const std::string& out_dir, const std::string& gt_dir,
                     const RunEvaluation& run, const RunEvaluation* baseline,
                     const EvalOptions& options) {
  options.Check();
  CreateDirectories(out_dir);
  std::vector<ColorMapImage> images;
  if (options.color_maps &&
      (!run.distance_fields.empty() || (baseline && !baseline->distance_fields.empty()))) {
    CreateDirectories((fs::path(out_dir) / "colormaps").string());
    images = WriteColorMaps(out_dir, "", run, options);
    if (baseline) {
      std::vector<ColorMapImage> more = WriteColorMaps(out_dir, "baseline_", *baseline, options);
      images.insert(images.end(), more.begin(), more.end());
    }
  }

  nlohmann::json report = EvaluationToJson(run);
  report["gt"] = gt_dir;
  const SurfaceSamplingOptions& s = options.hausdorff.sampling;
  report["hausdorff_sampling"] = {{"include_vertices", s.include_vertices},
                                  {"samples_per_mm2", s.samples_per_area},
                                  {"min_random_samples", s.min_random_samples},
                                  {"max_random_samples", s.max_random_samples},
                                  {"seed", s.seed}};
  nlohmann::json maps = nlohmann::json::array();
  for (const ColorMapImage& image : images) {
    maps.push_back(image.png_path);
    maps.push_back(image.png_path.substr(0, image.png_path.size() - 4) + ".obj");
  }
  report["colormaps"] = maps;
  nlohmann::json overlaps = nlohmann::json::array();
  if (!run.overlap_pngs.empty() || (baseline && !baseline->overlap_pngs.empty()))
    CreateDirectories((fs::path(out_dir) / "overlap").string());
  for (const RunEvaluation* r : {&run, baseline}) {
    if (!r) continue;
    for (const auto& [frame, png] : r->overlap_pngs) {
      char name[40];
      std::snprintf(name, sizeof(name), "overlap/%s%06d.png", r == &run ? "" : "baseline_", frame);
      WriteBytesAtomic((fs::path(out_dir) / name).string(), png);
      overlaps.push_back(name);
    }
  }
  report["overlap_images"] = overlaps;
  if (baseline) report["baseline"] = EvaluationToJson(*baseline);
  const std::string json_text = report.dump(2) + "\n";
  WriteFileAtomic((fs::path(out_dir) / "report.json").string(),
                  [&](std::ostream& os) { os << json_text; });

  WriteFileAtomic((fs::path(out_dir) / "report.csv").string(), [&](std::ostream& os) {
    os << "run,frame,dice";
    for (const char* kind : {"surface", "internal"})
      for (const char* part :
           {"mean_model_to_gt", "mean_gt_to_model", "max_model_to_gt", "max_gt_to_model", "max"})
        os << ",hausdorff_" << kind << '_' << part;
    os << ",feature_error_mean_mm,feature_error_max_mm";
    std::vector<std::string> thin_names;
    for (const ThinSummary& t : run.thin) {
      thin_names.push_back(t.name);
      os << ",thin_" << t.name << "_dice";
      for (const char* part :
           {"mean_model_to_gt", "mean_gt_to_model", "max_model_to_gt", "max_gt_to_model", "max"})
        os << ",thin_" << t.name << "_hausdorff_" << part;
    }
    os << '\n';
    WriteCsvRows(os, "run", run, thin_names);
    if (baseline) WriteCsvRows(os, "baseline", *baseline, thin_names);
  });

  const std::string html = BuildHtml(gt_dir, run, baseline, options, images);
  WriteFileAtomic((fs::path(out_dir) / "report.html").string(),
                  [&](std::ostream& os) { os << html; });
}

}  // namespace arreg::eval
