// Minimal levelled logging to stderr. Library code logs warnings here instead
// of printing; applications choose the level (--quiet / --verbose).
#pragma once

#include <string>

#include "core/error.h"

namespace arreg {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3, kSilent = 4 };

void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
void LogMessage(LogLevel level, const std::string& message);

}  // namespace arreg

#define ARREG_LOG_DEBUG(...) \
  ::arreg::LogMessage(::arreg::LogLevel::kDebug, ::arreg::internal::Concat(__VA_ARGS__))
#define ARREG_LOG_INFO(...) \
  ::arreg::LogMessage(::arreg::LogLevel::kInfo, ::arreg::internal::Concat(__VA_ARGS__))
#define ARREG_LOG_WARNING(...) \
  ::arreg::LogMessage(::arreg::LogLevel::kWarning, ::arreg::internal::Concat(__VA_ARGS__))
