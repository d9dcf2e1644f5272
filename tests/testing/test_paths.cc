#include "tests/testing/test_paths.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>

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
