#include "tests/testing/test_paths.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <stdexcept>
#include <system_error>
#include <utility>

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

namespace {

// The temporary directories this test process made, removed when it exits normally (a crashed
// test leaves its own). The Release suite makes about 160 a run, 187 MB; left to the OS cleaner,
// runs piled up until CI's disk was full. TEMPOKEY_KEEP_TEST_DIRS=1 keeps them, to look at what a
// failing test wrote.
class OwnedTempDirs {
 public:
  ~OwnedTempDirs() {
    if (const char* keep = std::getenv("TEMPOKEY_KEEP_TEST_DIRS"); keep != nullptr && *keep == '1') {
      return;
    }
    for (const std::string& dir : dirs_) {
      std::error_code ignored;  // a directory a test already removed is not an error
      std::filesystem::remove_all(dir, ignored);
    }
  }

  void Add(std::string dir) {
    const std::lock_guard<std::mutex> lock(mutex_);
    dirs_.push_back(std::move(dir));
  }

 private:
  std::mutex mutex_;
  std::vector<std::string> dirs_;
};

OwnedTempDirs& TempDirsOfThisProcess() {
  static OwnedTempDirs dirs;
  return dirs;
}

}  // namespace

std::string MakeTempDir() {
  std::string pattern = (std::filesystem::temp_directory_path() / "tempokey-test-XXXXXX").string();
  if (mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
  TempDirsOfThisProcess().Add(pattern);
  return pattern;
}

}  // namespace tempokey::testing
