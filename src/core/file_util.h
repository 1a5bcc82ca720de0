// File helpers shared by every writer: outputs are written to a temporary name
// beside the target and renamed into place, so a crash or bad input never
// leaves a partial file under the final name.
#pragma once

#include <functional>
#include <iosfwd>
#include <string>

namespace arreg {

// Calls `write(stream)` on a temporary file next to `path`, then renames it to
// `path`. On any exception the temporary is removed and the exception rethrown;
// an I/O failure throws arreg::Error naming `path`.
void WriteFileAtomic(const std::string& path, const std::function<void(std::ostream&)>& write,
                     bool binary = false);

// A temporary path next to `path` for writers that need a file name (FFmpeg,
// OpenCV): "<dir>/.<name>.tmp-<pid>-<n><ext>", keeping the extension so that
// format detection by suffix still works. Pair with CommitTemporaryFile().
std::string TemporaryPathFor(const std::string& path);
// Renames `temporary` to `path` (throws arreg::Error on failure).
void CommitTemporaryFile(const std::string& temporary, const std::string& path);

// Reads a whole file; throws arreg::Error naming the file when it cannot.
std::string ReadFileToString(const std::string& path);

// Creates `dir` and its parents; throws arreg::Error naming it on failure.
void CreateDirectories(const std::string& dir);

bool FileExists(const std::string& path);

}  // namespace arreg
