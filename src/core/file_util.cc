#include "core/file_util.h"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/error.h"

namespace arreg {
namespace fs = std::filesystem;

std::string TemporaryPathFor(const std::string& path) {
  static std::atomic<int> counter{0};
  const fs::path p(path);
  const std::string name = "." + p.stem().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                           std::to_string(counter++) + p.extension().string();
  return (p.parent_path() / name).string();
}

void CommitTemporaryFile(const std::string& temporary, const std::string& path) {
  std::error_code ec;
  fs::rename(temporary, path, ec);
  if (ec) {
    fs::remove(temporary, ec);
    throw Error(path, "", "cannot move finished output into place: " + ec.message());
  }
}

void WriteFileAtomic(const std::string& path, const std::function<void(std::ostream&)>& write,
                     bool binary) {
  const std::string tmp = TemporaryPathFor(path);
  try {
    {
      std::ofstream out(tmp, binary ? std::ios::binary | std::ios::out : std::ios::out);
      if (!out)
        throw Error(path, "", std::string("cannot open for writing: ") + std::strerror(errno));
      write(out);
      out.flush();
      if (!out) throw Error(path, "", "write failed (disk full?)");
    }
    CommitTemporaryFile(tmp, path);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

std::string ReadFileToString(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error(path, "", "file not found");
  if (fs::is_directory(path, ec)) throw Error(path, "", "is a directory, expected a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path, "", std::string("cannot open: ") + std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void CreateDirectories(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw Error(dir, "", "cannot create directory: " + ec.message());
}

bool FileExists(const std::string& path) {
  std::error_code ec;
  return fs::exists(path, ec);
}

}  // namespace arreg
