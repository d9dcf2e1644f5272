#include "tempokey/core/model/status.h"

#include <string>

#include "absl/status/status.h"
#include "absl/strings/cord.h"
#include "gtest/gtest.h"

namespace tempokey::core {
namespace {

TEST(AnnotateTest, PrefixesTheMessageAndKeepsTheCodeAndThePayloads) {
  absl::Status status = absl::ResourceExhaustedError("no room");
  status.SetPayload("type.example/hint", absl::Cord("250"));

  const absl::Status annotated = Annotate(status, "inline_clip");

  EXPECT_EQ(annotated.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(annotated.message(), "inline_clip: no room");
  ASSERT_TRUE(annotated.GetPayload("type.example/hint").has_value());
  EXPECT_EQ(std::string(*annotated.GetPayload("type.example/hint")), "250");
  EXPECT_TRUE(Annotate(absl::OkStatus(), "inline_clip").ok());
}

}  // namespace
}  // namespace tempokey::core
