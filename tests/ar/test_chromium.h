// Headless Chromium for the report-page tests: finding the browser, its command line and the
// check of its log for console errors.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace arreg::testing {

// The first Chromium or Chrome binary found, or "".
inline std::string FindChromium() {
  for (const char* candidate : {"/usr/bin/chromium", "/usr/bin/chromium-browser",
                                "/usr/bin/google-chrome", "/usr/bin/google-chrome-stable"})
    if (std::filesystem::exists(candidate)) return candidate;
  return "";
}

// Runs a shell command with stdout and stderr sent to files; returns the exit status.
inline int RunShell(const std::string& command, const std::filesystem::path& out,
                    const std::filesystem::path& err) {
  const std::string full = command + " >'" + out.string() + "' 2>'" + err.string() + "'";
  return std::system(full.c_str());
}

// Headless Chromium with its own profile folder and its log on stderr; append the action
// (--dump-dom URL, --screenshot=...).
inline std::string ChromiumCommand(const std::string& chromium,
                                   const std::filesystem::path& profile) {
  return "timeout 120 '" + chromium +
         "' --headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
         "--disable-background-networking --disable-component-update --disable-sync "
         "--disable-dev-shm-usage --user-data-dir='" +
         profile.string() + "' --enable-logging=stderr --v=0 ";
}

// Console messages reach stderr as "...:CONSOLE(line)] ..." with --enable-logging=stderr.
inline void ExpectNoConsoleErrors(const std::string& log) {
  for (const char* marker :
       {"CONSOLE", "Uncaught", "Failed to load resource", "ERR_FILE_NOT_FOUND"})
    EXPECT_EQ(log.find(marker), std::string::npos) << "console output in Chromium log:\n" << log;
}

}  // namespace arreg::testing
