#include "ar/eval/html.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

namespace arreg::eval {

std::string HtmlEscape(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string Base64Encode(const std::vector<unsigned char>& bytes) {
  static const char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = (uint32_t(bytes[i]) << 16) | (uint32_t(bytes[i + 1]) << 8) | bytes[i + 2];
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (i < bytes.size()) {
    uint32_t v = uint32_t(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= uint32_t(bytes[i + 1]) << 8;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

namespace {

// Tick spacing of 1, 2 or 5 times a power of ten giving about `target` intervals.
double NiceStep(double range, int target) {
  if (!(range > 0.0)) return 1.0;
  const double raw = range / target;
  const double power = std::pow(10.0, std::floor(std::log10(raw)));
  const double mantissa = raw / power;
  return (mantissa <= 1.0 ? 1.0 : mantissa <= 2.0 ? 2.0 : mantissa <= 5.0 ? 5.0 : 10.0) * power;
}

std::string Num(double v) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.2f", v);
  return text;
}

std::string TickLabel(double v, double step) {
  char text[32];
  const int decimals = std::clamp(static_cast<int>(-std::floor(std::log10(step) + 1e-9)), 0, 6);
  std::snprintf(text, sizeof(text), "%.*f", decimals, std::abs(v) < 1e-12 * step ? 0.0 : v);
  return text;
}

}  // namespace

std::string SvgLinePlot(const std::string& id, const std::string& title, const std::string& x_label,
                        const std::string& y_label, const std::vector<PlotSeries>& series,
                        std::optional<double> y_min, std::optional<double> y_max) {
  constexpr double kWidth = 1000, kHeight = 330;
  constexpr double kLeft = 70, kRight = 330, kTop = 34, kBottom = 50;
  const double plot_w = kWidth - kLeft - kRight, plot_h = kHeight - kTop - kBottom;

  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0;
  double y0 = x0, y1 = -x0;
  for (const PlotSeries& s : series)
    for (const auto& [x, y] : s.points) {
      if (!std::isfinite(x) || !std::isfinite(y)) continue;
      x0 = std::min(x0, x), x1 = std::max(x1, x);
      y0 = std::min(y0, y), y1 = std::max(y1, y);
    }
  const bool empty = !(x0 <= x1);
  if (empty) x0 = 0, x1 = 1, y0 = 0, y1 = 1;
  if (y_min) y0 = *y_min;
  if (y_max) y1 = *y_max;
  if (!y_min && y0 > 0.0 && y0 < 0.5 * y1) y0 = 0.0;  // distances: start the axis at zero
  if (x1 - x0 <= 0.0) x0 -= 0.5, x1 += 0.5;
  if (y1 - y0 <= 0.0) {
    const double pad = std::max(1e-3, 0.05 * std::abs(y1));
    y0 -= pad, y1 += pad;
  }
  const double x_step = NiceStep(x1 - x0, 8), y_step = NiceStep(y1 - y0, 5);
  if (!y_max) y1 = std::ceil(y1 / y_step - 1e-9) * y_step;
  if (!y_min) y0 = std::floor(y0 / y_step + 1e-9) * y_step;
  const auto px = [&](double x) { return kLeft + (x - x0) / (x1 - x0) * plot_w; };
  const auto py = [&](double y) { return kTop + (1.0 - (y - y0) / (y1 - y0)) * plot_h; };

  std::ostringstream os;
  os << "<svg class=\"plot\" id=\"" << HtmlEscape(id) << "\" xmlns=\"http://www.w3.org/2000/svg\" "
     << "width=\"" << kWidth << "\" height=\"" << kHeight << "\" viewBox=\"0 0 " << kWidth << ' '
     << kHeight << "\" font-family=\"sans-serif\" font-size=\"12\">\n"
     << "<title>" << HtmlEscape(title) << "</title>\n"
     << "<rect x=\"0\" y=\"0\" width=\"" << kWidth << "\" height=\"" << kHeight
     << "\" fill=\"#ffffff\"/>\n"
     << "<text x=\"" << kLeft << "\" y=\"20\" font-size=\"14\" font-weight=\"bold\">"
     << HtmlEscape(title) << "</text>\n";
  // Grid, ticks and labels.
  for (double y = std::ceil(y0 / y_step - 1e-9) * y_step; y <= y1 + 1e-9 * y_step; y += y_step) {
    os << "<line x1=\"" << Num(kLeft) << "\" x2=\"" << Num(kLeft + plot_w) << "\" y1=\""
       << Num(py(y)) << "\" y2=\"" << Num(py(y)) << "\" stroke=\"#e3e3e3\"/>"
       << "<text x=\"" << Num(kLeft - 6) << "\" y=\"" << Num(py(y) + 4) << "\" text-anchor=\"end\">"
       << TickLabel(y, y_step) << "</text>\n";
  }
  for (double x = std::ceil(x0 / x_step - 1e-9) * x_step; x <= x1 + 1e-9 * x_step; x += x_step) {
    os << "<line x1=\"" << Num(px(x)) << "\" x2=\"" << Num(px(x)) << "\" y1=\"" << Num(kTop)
       << "\" y2=\"" << Num(kTop + plot_h) << "\" stroke=\"#f0f0f0\"/>"
       << "<text x=\"" << Num(px(x)) << "\" y=\"" << Num(kTop + plot_h + 16)
       << "\" text-anchor=\"middle\">" << TickLabel(x, x_step) << "</text>\n";
  }
  os << "<rect x=\"" << kLeft << "\" y=\"" << kTop << "\" width=\"" << plot_w << "\" height=\""
     << plot_h << "\" fill=\"none\" stroke=\"#444\"/>\n"
     << "<text x=\"" << Num(kLeft + plot_w / 2) << "\" y=\"" << Num(kHeight - 10)
     << "\" text-anchor=\"middle\">" << HtmlEscape(x_label) << "</text>\n"
     << "<text transform=\"translate(16 " << Num(kTop + plot_h / 2)
     << ") rotate(-90)\" text-anchor=\"middle\">" << HtmlEscape(y_label) << "</text>\n";
  if (empty)
    os << "<text x=\"" << Num(kLeft + plot_w / 2) << "\" y=\"" << Num(kTop + plot_h / 2)
       << "\" text-anchor=\"middle\" fill=\"#888\">no data</text>\n";

  int legend_row = 0;
  for (const PlotSeries& s : series) {
    const std::string color = HtmlEscape(s.color);
    const std::string dash = s.dashed ? " stroke-dasharray=\"6 4\"" : "";
    std::ostringstream path;
    for (const auto& [x, y] : s.points)
      if (std::isfinite(x) && std::isfinite(y)) path << Num(px(x)) << ',' << Num(py(y)) << ' ';
    os << "<g class=\"series\" data-name=\"" << HtmlEscape(s.name) << "\">";
    if (s.points.size() > 1)
      os << "<polyline fill=\"none\" stroke=\"" << color << "\" stroke-width=\"2\"" << dash
         << " points=\"" << path.str() << "\"/>";
    if (s.points.size() <= 120)
      for (const auto& [x, y] : s.points)
        if (std::isfinite(x) && std::isfinite(y))
          os << "<circle cx=\"" << Num(px(x)) << "\" cy=\"" << Num(py(y)) << "\" r=\"2.5\" fill=\""
             << color << "\"/>";
    os << "</g>\n";
    const double ly = kTop + 10 + 18 * legend_row++;
    const double lx = kLeft + plot_w + 14;
    os << "<line x1=\"" << Num(lx) << "\" x2=\"" << Num(lx + 24) << "\" y1=\"" << Num(ly)
       << "\" y2=\"" << Num(ly) << "\" stroke=\"" << color << "\" stroke-width=\"2\"" << dash
       << "/><text x=\"" << Num(lx + 30) << "\" y=\"" << Num(ly + 4) << "\">" << HtmlEscape(s.name)
       << "</text>\n";
  }
  os << "</svg>\n";
  return os.str();
}

}  // namespace arreg::eval
