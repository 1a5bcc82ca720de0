// Static files of the debug viewer (HTML, CSS, JavaScript), kept in one place so that the
// writer copies them byte for byte; no external libraries and no network access.
#pragma once

namespace arreg::debug {

extern const char kViewerIndexHtml[];
extern const char kViewerCss[];
extern const char kViewerJs[];

}  // namespace arreg::debug
