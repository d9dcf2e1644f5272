// MakeTempDir(): a suite run makes thousands of directories, and none may outlive its test process.
#include "tests/testing/test_paths.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

namespace tempokey::testing {
namespace {

TEST(MakeTempDirTest, GivesAFreshEmptyDirectoryEachCall) {
  const std::string first = MakeTempDir();
  const std::string second = MakeTempDir();
  EXPECT_NE(first, second);
  EXPECT_TRUE(std::filesystem::is_directory(first));
  EXPECT_TRUE(std::filesystem::is_empty(first));
}

// A child process (gtest's death test forks) makes a directory, writes a file in it, tells the
// parent the path through a pipe and exits normally; the directory must be gone.
TEST(MakeTempDirTest, TheDirectoryAndItsContentsGoWhenTheProcessExits) {
  int path_pipe[2];
  ASSERT_EQ(pipe(path_pipe), 0);
  EXPECT_EXIT(
      {
        const std::string dir = MakeTempDir();
        std::ofstream(dir + "/output.json") << "{}";
        const std::string line = dir + "\n";
        if (write(path_pipe[1], line.data(), line.size()) != static_cast<ssize_t>(line.size())) {
          std::_Exit(2);
        }
        std::exit(0);
      },
      ::testing::ExitedWithCode(0), "");
  close(path_pipe[1]);
  std::string path;
  char c = 0;
  while (read(path_pipe[0], &c, 1) == 1 && c != '\n') path.push_back(c);
  close(path_pipe[0]);
  ASSERT_FALSE(path.empty());
  EXPECT_FALSE(std::filesystem::exists(path)) << path;
}

}  // namespace
}  // namespace tempokey::testing
