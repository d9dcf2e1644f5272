#include "tests/testing/test_paths.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <system_error>

namespace tempokey::testing {

std::string SharedDir() {
  if (const char* env = std::getenv("TEMPOKEY_SHARED_DIR"); env != nullptr && *env != '\0') {
    return env;
  }
  return TEMPOKEY_SHARED_DIR;
}

std::string SharedBvh(const std::string& relative) {
  return SharedDir() + "/data/bvh/" + relative;
}

std::vector<std::string> AllSharedBvhFiles() {
  std::vector<std::string> files;
  const std::filesystem::path root = SharedDir() + "/data/bvh";
  // Without the shared data (a checkout with no ../shared beside it) the list holds the missing
  // folder itself: the build's test discovery still succeeds, and every corpus test then fails
  // naming the path it could not read, instead of the build stopping at discovery.
  std::error_code missing;
  if (!std::filesystem::is_directory(root, missing)) return {root.string()};
  for (const auto& entry : std::filesystem::recursive_directory_iterator(root)) {
    if (entry.is_regular_file() && entry.path().extension() == ".bvh") {
      files.push_back(entry.path().string());
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::string BinaryDir() { return TEMPOKEY_BINARY_DIR; }
std::string SourceDir() { return TEMPOKEY_SOURCE_DIR; }

std::string MakeTempDir() {
  std::string pattern = (std::filesystem::temp_directory_path() / "tempokey-test-XXXXXX").string();
  if (mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
  return pattern;
}

}  // namespace tempokey::testing
