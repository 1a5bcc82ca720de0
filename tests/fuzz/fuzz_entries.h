// The fuzz targets of arreg's readers: one entry per file format a user hands
// us. Each entry writes the input bytes to a private temporary file with the
// format's extension and reads it through the same public function the tools
// use. A reader may accept the input or throw arreg::Error; anything else (a
// crash, a sanitizer report, another exception, a hang) is a finding.
// Built twice: into libFuzzer executables (scripts/fuzz, tests/fuzz/fuzz_main.cc)
// and into the replay test that runs every saved finding (tests/data/fuzz/).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace arreg::fuzz {

struct Target {
  std::string name;       // e.g. "msh"; also the folder of its findings in tests/data/fuzz/
  std::string extension;  // the temporary file's extension, which selects the reader
  void (*read)(const std::string& path);
};

// Every target, in a fixed order.
const std::vector<Target>& Targets();
// The target called `name`; throws std::invalid_argument for an unknown one.
const Target& FindTarget(const std::string& name);

// Writes `data` to this process's temporary file for `target` and reads it.
// Returns 1 when the reader accepted the input, 0 when it threw arreg::Error.
int RunOne(const Target& target, const uint8_t* data, size_t size);

// Writes a seed corpus for `target` into `dir` (created): small valid files in
// every variant the project's own writers produce (e.g. .msh 2.2 and 4.1, VTK
// ASCII and binary, STL ASCII and binary), plus hand-written ones for the formats
// we only read. Returns the number of files written.
int WriteSeeds(const Target& target, const std::string& dir);

}  // namespace arreg::fuzz
