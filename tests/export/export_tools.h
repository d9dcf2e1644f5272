// Running the export checks that are not ours from C++ tests: the Khronos validator and three.js
// under node (tests/export/*.mjs, packages pinned in tests/export/package.json and installed by
// deploy/install-deps.sh), and headless Chromium.
#ifndef TEMPOKEY_TESTS_EXPORT_EXPORT_TOOLS_H_
#define TEMPOKEY_TESTS_EXPORT_EXPORT_TOOLS_H_

#include <string>
#include <vector>

#include "absl/strings/str_split.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/json.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {

inline std::string ExportScript(const std::string& name) {
  return SourceDir() + "/tests/export/" + name;
}

// node SCRIPT args... in `dir`; the parsed JSON lines of its stdout. A failure (node missing,
// packages not installed, the script failing) fails the test with the tool's own message.
inline std::vector<core::JsonValue> RunNodeScript(const std::string& script,
                                                  const std::vector<std::string>& args,
                                                  const std::string& dir) {
  std::vector<std::string> argv = {TEMPOKEY_NODE, ExportScript(script)};
  argv.insert(argv.end(), args.begin(), args.end());
  const ProcessResult run = RunProcess(argv, dir);
  EXPECT_EQ(run.exit_code, 0) << script << " failed (deploy/install-deps.sh installs node and "
                              << "tests/export/node_modules):\n"
                              << run.err;
  std::vector<core::JsonValue> lines;
  for (const absl::string_view line : absl::StrSplit(run.out, '\n', absl::SkipEmpty())) {
    absl::StatusOr<core::JsonValue> json =
        core::ParseJson(std::string_view(line.data(), line.size()), script);
    EXPECT_TRUE(json.ok()) << json.status() << "\n" << run.out;
    if (json.ok()) lines.push_back(*std::move(json));
  }
  return lines;
}

inline double NumberOf(const core::JsonValue& object, const std::string& name) {
  const core::JsonValue* value = object.Find(name);
  EXPECT_NE(value, nullptr) << name;
  return value != nullptr ? value->number : -1.0;
}

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_EXPORT_EXPORT_TOOLS_H_
