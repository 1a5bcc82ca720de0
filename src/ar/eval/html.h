// Building blocks of the self-contained HTML report: escaping, base64 data URIs
// and inline SVG line plots (no scripts, no external resources).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace arreg::eval {

// Escapes &, <, >, " and ' for HTML text and attribute values.
std::string HtmlEscape(const std::string& text);

// Standard base64 (RFC 4648, with padding).
std::string Base64Encode(const std::vector<unsigned char>& bytes);

struct PlotSeries {
  std::string name;                               // legend entry
  std::string color = "#1f77b4";                  // any CSS colour
  bool dashed = false;                            // dashed line (second quantity, same run)
  std::vector<std::pair<double, double>> points;  // (x, y), drawn in the given order
};

// An <svg class="plot" id="..."> line chart with axes, 1-2-5 ticks, markers at
// the points and a legend. The y range covers the data unless y_min / y_max
// are given; an empty plot says "no data".
std::string SvgLinePlot(const std::string& id, const std::string& title, const std::string& x_label,
                        const std::string& y_label, const std::vector<PlotSeries>& series,
                        std::optional<double> y_min = std::nullopt,
                        std::optional<double> y_max = std::nullopt);

}  // namespace arreg::eval
