// Where tests find shared data, fixtures and built binaries.
#ifndef TEMPOKEY_TESTS_TESTING_TEST_PATHS_H_
#define TEMPOKEY_TESTS_TESTING_TEST_PATHS_H_

#include <string>
#include <vector>

namespace tempokey::testing {

// ../shared beside the checkout (TEMPOKEY_SHARED_DIR overrides).
std::string SharedDir();
// ../shared/data/bvh/<relative>.
std::string SharedBvh(const std::string& relative);
// Every *.bvh under ../shared/data/bvh, sorted.
std::vector<std::string> AllSharedBvhFiles();
// The build tree (for tempokey-server and tempokey binaries).
std::string BinaryDir();
// The source tree.
std::string SourceDir();
// A fresh empty directory for this test, removed with its contents when the test process exits
// (TEMPOKEY_KEEP_TEST_DIRS=1 keeps it).
std::string MakeTempDir();

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_TESTING_TEST_PATHS_H_
