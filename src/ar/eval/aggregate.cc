#include "ar/eval/aggregate.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <utility>

#include "ar/eval/html.h"
#include "core/error.h"
#include "core/file_util.h"

namespace arreg::eval {

namespace fs = std::filesystem;

namespace {

std::optional<double> NumberAt(const nlohmann::json& j, std::initializer_list<const char*> path) {
  const nlohmann::json* node = &j;
  for (const char* key : path) {
    if (!node->is_object() || !node->contains(key)) return std::nullopt;
    node = &(*node)[key];
  }
  if (!node->is_number()) return std::nullopt;
  return node->get<double>();
}

nlohmann::json OptionalJson(const std::optional<double>& v) {
  return v ? nlohmann::json(*v) : nlohmann::json(nullptr);
}

std::string Trim(const std::string& s) {
  const size_t b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const size_t e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

// "arreg run: error: ..." (or "usage error", "internal error").
bool IsErrorLine(const std::string& line) {
  if (line.rfind("arreg ", 0) != 0) return false;
  for (const char* kind : {": error: ", ": usage error: ", ": internal error: "})
    if (line.find(kind) != std::string::npos) return true;
  return false;
}

struct LogLine {
  std::string log, line;
};

// The error line of the most recent log with one; else the last line of the most recent log.
std::optional<LogLine> ErrorFromLogs(const fs::path& dir) {
  std::vector<std::pair<fs::file_time_type, fs::path>> logs;
  for (const fs::path& folder : {dir / "logs", dir.parent_path() / "logs"}) {
    std::error_code ec;
    if (!fs::is_directory(folder, ec)) continue;
    for (const auto& e : fs::directory_iterator(folder, ec))
      if (e.is_regular_file() && e.path().extension() == ".log")
        logs.emplace_back(fs::last_write_time(e.path(), ec), e.path());
  }
  std::sort(logs.begin(), logs.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second < b.second;
  });
  std::optional<LogLine> fallback;
  for (const auto& [time, path] : logs) {
    std::ifstream in(path);
    std::string line, error, last;
    while (std::getline(in, line)) {
      // Progress bars redraw with carriage returns: keep the text after the last one.
      const size_t cr = line.find_last_of('\r', line.size() >= 2 ? line.size() - 2 : 0);
      if (cr != std::string::npos && cr + 1 < line.size()) line = line.substr(cr + 1);
      line = Trim(line);
      if (line.empty()) continue;
      if (IsErrorLine(line)) error = line;
      last = line;
    }
    if (!error.empty()) return LogLine{path.string(), error};
    if (!fallback && !last.empty()) fallback = LogLine{path.string(), last};
  }
  return fallback;
}

void SetHausdorff(const nlohmann::json& h, std::optional<double>* mean_m2g,
                  std::optional<double>* mean_g2m, std::optional<double>* max) {
  *mean_m2g = NumberAt(h, {"mean_model_to_gt"});
  *mean_g2m = NumberAt(h, {"mean_gt_to_model"});
  *max = NumberAt(h, {"max"});
}

std::string Cell(const std::optional<double>& v, int decimals) {
  if (!v) return "";
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", decimals, *v);
  return text;
}

std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

// Quantile of sorted values, linear interpolation.
double Quantile(const std::vector<double>& sorted, double q) {
  const double pos = q * static_cast<double>(sorted.size() - 1);
  const size_t i = static_cast<size_t>(std::floor(pos));
  if (i + 1 >= sorted.size()) return sorted.back();
  return sorted[i] + (pos - static_cast<double>(i)) * (sorted[i + 1] - sorted[i]);
}

double NiceStep(double span) {
  const double raw = span / 6.0;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (raw <= m * mag) return m * mag;
  return 10.0 * mag;
}

// The link from the aggregated page (in `out_dir`, absolute) to a scene's report.
std::string RelativeLink(const std::string& report, const fs::path& out_dir) {
  if (report.empty()) return "";
  return fs::absolute(report).lexically_normal().lexically_proximate(out_dir).string();
}

std::string Num(double v, int decimals = 2) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", decimals, v);
  return text;
}

struct Metric {
  const char* id;
  const char* title;
  std::optional<double> AggregateRow::*field;
  int decimals;
  bool higher_is_better;
};

const Metric kMetrics[] = {
    {"dice_final", "Dice, final frame", &AggregateRow::dice_final, 4, true},
    {"dice_mean", "Dice, mean over frames", &AggregateRow::dice_mean, 4, true},
    {"hd_surface_mean_gt_to_model", "Hausdorff surface mean gt\u2192model (mm)",
     &AggregateRow::surface_mean_gt_to_model, 3, false},
    {"hd_surface_mean_model_to_gt", "Hausdorff surface mean model\u2192gt (mm)",
     &AggregateRow::surface_mean_model_to_gt, 3, false},
    {"hd_surface_max", "Hausdorff surface max (mm)", &AggregateRow::surface_max, 3, false},
    {"hd_internal_mean_gt_to_model", "Hausdorff internal mean gt\u2192model (mm)",
     &AggregateRow::internal_mean_gt_to_model, 3, false},
    {"hd_internal_mean_model_to_gt", "Hausdorff internal mean model\u2192gt (mm)",
     &AggregateRow::internal_mean_model_to_gt, 3, false},
    {"hd_internal_max", "Hausdorff internal max (mm)", &AggregateRow::internal_max, 3, false},
    {"feature_error_mean_mm", "feature error mean (mm)", &AggregateRow::feature_error_mean_mm, 3,
     false},
    {"fps", "frames/s (end to end)", &AggregateRow::fps, 1, true},
    {"seconds", "run seconds", &AggregateRow::seconds, 2, false},
};

// A strip plot with a box (quartiles, median, whiskers to the extremes) per variant; each point
// is a link to its scene's report with the scene name as tooltip.
std::string StripPlot(const Metric& m, const std::vector<AggregateRow>& rows,
                      const std::vector<std::string>& variants, const fs::path& out_dir) {
  std::map<std::string, std::vector<const AggregateRow*>> lanes;
  double lo = INFINITY, hi = -INFINITY;
  for (const AggregateRow& r : rows) {
    const std::optional<double>& v = r.*(m.field);
    if (!r.ok || !v || !std::isfinite(*v)) continue;
    lanes[r.variant].push_back(&r);
    lo = std::min(lo, *v);
    hi = std::max(hi, *v);
  }
  std::ostringstream os;
  os << "<figure class=\"dist\"><figcaption>" << HtmlEscape(m.title) << "</figcaption>\n";
  if (lanes.empty()) {
    os << "<p class=\"meta\" id=\"plot-" << m.id << "\">no data</p></figure>\n";
    return os.str();
  }
  if (hi - lo < 1e-12) {
    const double pad = std::max(std::fabs(hi) * 0.01, 1e-6);
    lo -= pad;
    hi += pad;
  }
  const double step = NiceStep(hi - lo);
  const double x0 = std::floor(lo / step) * step, x1 = std::ceil(hi / step) * step;
  const int left = 130, right = 20, width = 620, lane_h = 44, top = 10;
  const int height = top + lane_h * static_cast<int>(variants.size()) + 36;
  auto X = [&](double v) {
    return left + (v - x0) / (x1 - x0) * static_cast<double>(width - left - right);
  };
  os << "<svg class=\"plot\" id=\"plot-" << m.id << "\" width=\"" << width << "\" height=\""
     << height << "\" viewBox=\"0 0 " << width << ' ' << height
     << "\" xmlns=\"http://www.w3.org/2000/svg\" font-size=\"11\">\n";
  const int axis_y = top + lane_h * static_cast<int>(variants.size());
  os << "<line x1=\"" << left << "\" y1=\"" << axis_y << "\" x2=\"" << width - right << "\" y2=\""
     << axis_y << "\" stroke=\"#444\"/>\n";
  const int decimals = step >= 1 ? 0 : static_cast<int>(std::ceil(-std::log10(step)));
  for (double t = x0; t <= x1 + step * 1e-6; t += step)
    os << "<line x1=\"" << Num(X(t), 1) << "\" y1=\"" << top << "\" x2=\"" << Num(X(t), 1)
       << "\" y2=\"" << axis_y + 4 << "\" stroke=\"#ddd\"/><text x=\"" << Num(X(t), 1) << "\" y=\""
       << axis_y + 16 << "\" text-anchor=\"middle\">" << Num(t, decimals) << "</text>\n";
  const char* colors[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"};
  for (size_t k = 0; k < variants.size(); ++k) {
    const double yc = top + lane_h * (static_cast<double>(k) + 0.5);
    os << "<text x=\"" << left - 8 << "\" y=\"" << Num(yc + 4, 1) << "\" text-anchor=\"end\">"
       << HtmlEscape(variants[k]) << "</text>\n";
    const auto it = lanes.find(variants[k]);
    if (it == lanes.end()) continue;
    std::vector<double> values;
    for (const AggregateRow* r : it->second) values.push_back(*(r->*(m.field)));
    std::sort(values.begin(), values.end());
    const double q1 = Quantile(values, 0.25), q2 = Quantile(values, 0.5),
                 q3 = Quantile(values, 0.75);
    const std::string color = colors[k % 6];
    os << "<g class=\"box\"><line x1=\"" << Num(X(values.front()), 1) << "\" y1=\"" << Num(yc, 1)
       << "\" x2=\"" << Num(X(values.back()), 1) << "\" y2=\"" << Num(yc, 1)
       << "\" stroke=\"#888\"/><rect x=\"" << Num(X(q1), 1) << "\" y=\"" << Num(yc - 12, 1)
       << "\" width=\"" << Num(std::max(X(q3) - X(q1), 1.0), 1)
       << "\" height=\"24\" fill=\"none\" stroke=\"#888\"/><line x1=\"" << Num(X(q2), 1)
       << "\" y1=\"" << Num(yc - 12, 1) << "\" x2=\"" << Num(X(q2), 1) << "\" y2=\""
       << Num(yc + 12, 1) << "\" stroke=\"#222\" stroke-width=\"2\"/><title>" << HtmlEscape(m.title)
       << ", " << HtmlEscape(variants[k]) << ": median " << Num(q2, m.decimals) << ", quartiles "
       << Num(q1, m.decimals) << " .. " << Num(q3, m.decimals) << ", n = " << values.size()
       << "</title></g>\n";
    for (size_t i = 0; i < it->second.size(); ++i) {
      const AggregateRow& r = *it->second[i];
      // Deterministic jitter so that equal values stay visible.
      const double jitter = (static_cast<double>((i * 7919) % 17) / 16.0 - 0.5) * 20.0;
      const std::string href = RelativeLink(r.report, out_dir);
      os << "<a class=\"point\" href=\"" << HtmlEscape(href) << "\"><circle cx=\""
         << Num(X(*(r.*(m.field))), 1) << "\" cy=\"" << Num(yc + jitter, 1)
         << "\" r=\"3.5\" fill=\"" << color << "\" fill-opacity=\"0.7\"><title>"
         << HtmlEscape(r.scene + " / " + r.variant) << ": " << Num(*(r.*(m.field)), m.decimals)
         << "</title></circle></a>\n";
    }
  }
  os << "</svg></figure>\n";
  return os.str();
}

std::string BuildHtml(const std::vector<AggregateRow>& rows, const fs::path& out_dir) {
  std::vector<std::string> variants;
  std::set<std::string> scenes;
  for (const AggregateRow& r : rows) {
    if (std::find(variants.begin(), variants.end(), r.variant) == variants.end())
      variants.push_back(r.variant);
    scenes.insert(r.scene);
  }
  const size_t failed = static_cast<size_t>(
      std::count_if(rows.begin(), rows.end(), [](const auto& r) { return !r.ok; }));
  auto link = [&](const AggregateRow& r) { return HtmlEscape(RelativeLink(r.report, out_dir)); };
  std::ostringstream os;
  os << "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
        "<title>arreg aggregated report</title>\n<style>\n"
        "body{font-family:sans-serif;margin:24px;color:#222;max-width:1400px}\n"
        "table{border-collapse:collapse;margin:8px 0 16px;font-size:13px}\n"
        "th,td{border:1px solid #bbb;padding:3px 6px;text-align:right}\n"
        "th{background:#f0f0f0;cursor:pointer;user-select:none}\n"
        "td.t{text-align:left}\ntd.err{text-align:left;min-width:360px}\n"
        "tr.failed td{background:#fde4e4}\n"
        "th.asc::after{content:' \\25B2'}\nth.desc::after{content:' \\25BC'}\n"
        "figure.dist{display:inline-block;margin:6px 12px 6px 0;vertical-align:top}\n"
        "figcaption{font-size:13px;font-weight:bold}\n.meta{font-size:13px;color:#555}\n"
        "</style>\n</head>\n<body>\n<h1>arreg aggregated report</h1>\n<p class=\"meta\" "
        "id=\"summary\">"
     << rows.size() << " runs: " << scenes.size() << " scenes &times; " << variants.size()
     << " variants (";
  for (size_t k = 0; k < variants.size(); ++k) os << (k ? ", " : "") << HtmlEscape(variants[k]);
  os << "); " << rows.size() - failed << " evaluated, " << failed
     << " failed. Each scene's own report is linked from its row and its points.</p>\n";

  os << "<h2>Distributions</h2>\n<p class=\"meta\">One lane per variant: every evaluated run is "
        "a point (hover: scene and value; click: its report); the box spans the quartiles, the "
        "thick line is the median, the whisker the range.</p>\n";
  for (const Metric& m : kMetrics) {
    const std::string id = m.id;
    if (id == "dice_final" || id == "hd_surface_mean_gt_to_model" ||
        id == "hd_surface_mean_model_to_gt" || id == "hd_internal_mean_gt_to_model" || id == "fps")
      os << StripPlot(m, rows, variants, out_dir);
  }

  std::vector<const AggregateRow*> ok_rows;
  for (const AggregateRow& r : rows)
    if (r.ok && r.dice_final) ok_rows.push_back(&r);
  std::sort(ok_rows.begin(), ok_rows.end(), [](const AggregateRow* a, const AggregateRow* b) {
    return *a->dice_final < *b->dice_final;
  });
  os << "<h2>Worst runs</h2>\n<ol id=\"worst\">\n";
  for (size_t i = 0; i < std::min<size_t>(5, ok_rows.size()); ++i) {
    const AggregateRow& r = *ok_rows[i];
    os << "<li><a href=\"" << link(r) << "\">" << HtmlEscape(r.scene) << " / "
       << HtmlEscape(r.variant) << "</a>: final Dice " << Cell(r.dice_final, 4)
       << ", Hausdorff surface mean gt&rarr;model " << Cell(r.surface_mean_gt_to_model, 3)
       << " mm</li>\n";
  }
  os << "</ol>\n";
  if (failed) {
    os << "<h2>Failed runs</h2>\n<ul id=\"failed\">\n";
    for (const AggregateRow& r : rows)
      if (!r.ok)
        os << "<li>" << HtmlEscape(r.scene) << " / " << HtmlEscape(r.variant) << ": <code>"
           << HtmlEscape(r.error) << "</code>"
           << (r.log.empty() ? "" : " (log <code>" + HtmlEscape(r.log) + "</code>)") << "</li>\n";
    os << "</ul>\n";
  }

  os << "<h2>All runs</h2>\n<p class=\"meta\">Click a column header to sort.</p>\n"
        "<table id=\"runs\">\n<thead><tr><th data-key=\"scene\">scene</th><th "
        "data-key=\"variant\">variant</th><th data-key=\"status\">status</th>";
  for (const Metric& m : kMetrics)
    os << "<th data-key=\"" << m.id << "\">" << HtmlEscape(m.title) << "</th>";
  os << "<th data-key=\"frames\">frames</th><th data-key=\"cuts_applied\">cuts applied</th><th "
        "data-key=\"report\">report / error</th></tr></thead>\n<tbody>\n";
  for (const AggregateRow& r : rows) {
    os << "<tr" << (r.ok ? "" : " class=\"failed\"") << "><td class=\"t\">" << HtmlEscape(r.scene)
       << "</td><td class=\"t\">" << HtmlEscape(r.variant) << "</td><td class=\"t\">"
       << (r.ok ? "ok" : "failed") << "</td>";
    for (const Metric& m : kMetrics) {
      const std::optional<double>& v = r.*(m.field);
      os << "<td" << (v ? " data-v=\"" + Num(*v, 9) + "\"" : "") << ">" << Cell(v, m.decimals)
         << "</td>";
    }
    os << "<td>" << (r.frames ? std::to_string(*r.frames) : "") << "</td><td>"
       << (r.cuts_applied ? std::to_string(*r.cuts_applied) : "") << "</td><td class=\"err\">";
    if (r.ok)
      os << "<a href=\"" << link(r) << "\">report</a>";
    else
      os << "<code>" << HtmlEscape(r.error) << "</code>";
    os << "</td></tr>\n";
  }
  os << "</tbody></table>\n";
  // Sorting: numbers by data-v (empty cells last), text otherwise.
  os << "<script>\n"
        "document.querySelectorAll('#runs th').forEach(function(th, col) {\n"
        "  th.addEventListener('click', function() {\n"
        "    var body = document.querySelector('#runs tbody');\n"
        "    var asc = !th.classList.contains('asc');\n"
        "    document.querySelectorAll('#runs th').forEach(function(h) {\n"
        "      h.classList.remove('asc', 'desc'); });\n"
        "    th.classList.add(asc ? 'asc' : 'desc');\n"
        "    var rows = Array.prototype.slice.call(body.rows);\n"
        "    rows.sort(function(a, b) {\n"
        "      var x = a.cells[col], y = b.cells[col];\n"
        "      var u = x.getAttribute('data-v'), v = y.getAttribute('data-v');\n"
        "      var c;\n"
        "      if (u !== null || v !== null) {\n"
        "        if (u === null) return 1;\n"
        "        if (v === null) return -1;\n"
        "        c = parseFloat(u) - parseFloat(v);\n"
        "      } else {\n"
        "        c = x.textContent.localeCompare(y.textContent);\n"
        "      }\n"
        "      return asc ? c : -c;\n"
        "    });\n"
        "    rows.forEach(function(r) { body.appendChild(r); });\n"
        "    document.getElementById('runs').setAttribute('data-sorted', "
        "th.getAttribute('data-key') +\n"
        "        (asc ? ':asc' : ':desc'));\n"
        "  });\n"
        "});\n"
        "// A link to a sorted view: report.html#sort=dice_final (ascending) or #sort=fps:desc.\n"
        "var m = /sort=([A-Za-z0-9_]+)(:desc)?/.exec(location.hash);\n"
        "if (m) {\n"
        "  var th = document.querySelector('#runs th[data-key=\"' + m[1] + '\"]');\n"
        "  if (th) { th.click(); if (m[2]) th.click(); }\n"
        "}\n"
        "</script>\n</body>\n</html>\n";
  return os.str();
}

}  // namespace

AggregateEntry ParseAggregateEntry(const std::string& argument) {
  AggregateEntry e;
  const size_t eq = argument.find('=');
  if (eq != std::string::npos) {
    const std::string label = argument.substr(0, eq);
    e.dir = argument.substr(eq + 1);
    const size_t slash = label.find('/');
    ARREG_CHECK_INPUT(slash != std::string::npos, "", "--runs " + argument,
                      "expected SCENE/VARIANT=DIR");
    e.scene = label.substr(0, slash);
    e.variant = label.substr(slash + 1);
  } else {
    e.dir = argument;
    fs::path p = fs::path(argument).lexically_normal();
    if (!p.has_filename()) p = p.parent_path();  // "a/b/" -> "a/b"
    e.variant = p.filename().string();
    e.scene = p.parent_path().filename().string();
  }
  ARREG_CHECK_INPUT(!e.dir.empty() && !e.scene.empty() && !e.variant.empty() && e.scene != "." &&
                        e.scene != ".." && e.variant != "." && e.variant != "..",
                    "", "--runs " + argument,
                    "needs a scene and a variant: SCENE/VARIANT=DIR or DIR inside a scene folder");
  return e;
}

AggregateRow ReadAggregateRow(const AggregateEntry& entry) {
  AggregateRow row;
  row.scene = entry.scene;
  row.variant = entry.variant;
  row.dir = entry.dir;
  const fs::path dir(entry.dir);
  fs::path report_json = dir / "eval" / "report.json";
  if (!FileExists(report_json.string()) && FileExists((dir / "report.json").string()))
    report_json = dir / "report.json";
  auto fail = [&](const std::string& why) {
    row.ok = false;
    if (const std::optional<LogLine> l = ErrorFromLogs(dir)) {
      row.error = l->line;
      row.log = l->log;
    } else {
      row.error = why;
    }
    return row;
  };
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return fail(entry.dir + ": no such folder");
  if (!FileExists(report_json.string()))
    return fail((dir / "eval" / "report.json").string() + ": missing (no log with an error)");
  nlohmann::json report;
  try {
    report = nlohmann::json::parse(ReadFileToString(report_json.string()));
  } catch (const std::exception& e) {
    row.error = report_json.string() + ": not valid JSON: " + Trim(e.what());
    return row;
  }
  if (!report.is_object() || !NumberAt(report, {"dice_final"})) {
    row.error = report_json.string() + ": dice_final: missing (not an `arreg eval` report)";
    return row;
  }
  row.ok = true;
  row.report = (report_json.parent_path() / "report.html").string();
  if (report.contains("label") && report["label"].is_string()) row.label = report["label"];
  row.dice_final = NumberAt(report, {"dice_final"});
  row.dice_mean = NumberAt(report, {"dice_mean"});
  if (report.contains("hausdorff_surface"))
    SetHausdorff(report["hausdorff_surface"], &row.surface_mean_model_to_gt,
                 &row.surface_mean_gt_to_model, &row.surface_max);
  if (report.contains("hausdorff_internal"))
    SetHausdorff(report["hausdorff_internal"], &row.internal_mean_model_to_gt,
                 &row.internal_mean_gt_to_model, &row.internal_max);
  row.feature_error_mean_mm = NumberAt(report, {"feature_error_mm", "mean"});
  if (const auto n = NumberAt(report, {"num_frames"})) row.frames = static_cast<int>(*n);

  // Speed and cut counts come from the run itself: DIR/run/run.json, else report.json `run`.
  fs::path run_json = dir / "run" / "run.json";
  if (!FileExists(run_json.string()) && report.contains("run") && report["run"].is_string())
    run_json = fs::path(report["run"].get<std::string>()) / "run.json";
  if (FileExists(run_json.string())) {
    try {
      const nlohmann::json run = nlohmann::json::parse(ReadFileToString(run_json.string()));
      row.fps = NumberAt(run, {"totals", "fps_end_to_end"});
      row.seconds = NumberAt(run, {"seconds"});
      if (const auto c = NumberAt(run, {"cuts_applied"})) row.cuts_applied = static_cast<int>(*c);
    } catch (const std::exception& e) {
      row.ok = false;
      row.error = run_json.string() + ": not valid JSON: " + Trim(e.what());
    }
  }
  return row;
}

nlohmann::json AggregateToJson(const std::vector<AggregateRow>& rows) {
  nlohmann::json out = nlohmann::json::array();
  size_t failed = 0;
  for (const AggregateRow& r : rows) {
    nlohmann::json j = {
        {"scene", r.scene},
        {"variant", r.variant},
        {"dir", r.dir},
        {"status", r.ok ? "ok" : "failed"},
        {"error", r.ok ? nlohmann::json(nullptr) : nlohmann::json(r.error)},
        {"log", r.log.empty() ? nlohmann::json(nullptr) : nlohmann::json(r.log)},
        {"report", r.report.empty() ? nlohmann::json(nullptr) : nlohmann::json(r.report)},
        {"label", r.label}};
    for (const Metric& m : kMetrics) j[m.id] = OptionalJson(r.*(m.field));
    j["frames"] = r.frames ? nlohmann::json(*r.frames) : nlohmann::json(nullptr);
    j["cuts_applied"] = r.cuts_applied ? nlohmann::json(*r.cuts_applied) : nlohmann::json(nullptr);
    if (!r.ok) ++failed;
    out.push_back(std::move(j));
  }
  nlohmann::json summary = {
      {"runs", rows.size()}, {"ok", rows.size() - failed}, {"failed", failed}};
  for (const Metric& m : kMetrics) {
    std::vector<double> v;
    for (const AggregateRow& r : rows)
      if (r.ok && (r.*(m.field))) v.push_back(*(r.*(m.field)));
    if (v.empty()) continue;
    std::sort(v.begin(), v.end());
    double sum = 0;
    for (double x : v) sum += x;
    summary[m.id] = {{"n", v.size()},
                     {"min", v.front()},
                     {"median", Quantile(v, 0.5)},
                     {"mean", sum / static_cast<double>(v.size())},
                     {"max", v.back()}};
  }
  return {{"rows", out}, {"summary", summary}};
}

void WriteAggregateReport(const std::string& out_dir, const std::vector<AggregateRow>& rows) {
  CreateDirectories(out_dir);
  const fs::path out(out_dir);
  const std::string json_text = AggregateToJson(rows).dump(2) + "\n";
  WriteFileAtomic((out / "report.json").string(), [&](std::ostream& os) { os << json_text; });
  WriteFileAtomic((out / "report.csv").string(), [&](std::ostream& os) {
    os << "scene,variant,status";
    for (const Metric& m : kMetrics) os << ',' << m.id;
    os << ",frames,cuts_applied,report,error\n";
    for (const AggregateRow& r : rows) {
      os << CsvField(r.scene) << ',' << CsvField(r.variant) << ',' << (r.ok ? "ok" : "failed");
      for (const Metric& m : kMetrics) {
        const std::optional<double>& v = r.*(m.field);
        os << ',' << (v ? Num(*v, 9) : "");
      }
      os << ',' << (r.frames ? std::to_string(*r.frames) : "") << ','
         << (r.cuts_applied ? std::to_string(*r.cuts_applied) : "") << ',' << CsvField(r.report)
         << ',' << CsvField(r.error) << '\n';
    }
  });
  const std::string html = BuildHtml(rows, fs::absolute(out).lexically_normal());
  WriteFileAtomic((out / "report.html").string(), [&](std::ostream& os) { os << html; });
}

}  // namespace arreg::eval
