#include "tempokey/core/io/json.h"

#include <string>

#include "gtest/gtest.h"

namespace tempokey::core {
namespace {

TEST(JsonTest, ReadsNestedValuesWithTheirPositions) {
  absl::StatusOr<JsonValue> root =
      ParseJson("{\"ops\": [\n  {\"fps\": 29.97, \"on\": true, \"n\": null}\n]}", "p.json");
  ASSERT_TRUE(root.ok()) << root.status();
  const JsonValue* ops = root->Find("ops");
  ASSERT_NE(ops, nullptr);
  ASSERT_EQ(ops->type, JsonValue::Type::kArray);
  ASSERT_EQ(ops->array->size(), 1u);
  const JsonValue& op = (*ops->array)[0];
  EXPECT_EQ(op.line, 2);
  EXPECT_EQ(op.column, 3);
  const JsonValue* fps = op.Find("fps");
  ASSERT_NE(fps, nullptr);
  EXPECT_EQ(fps->number, 29.97);
  EXPECT_EQ(fps->text, "29.97");  // the token as written, for parsers with their own rules
  EXPECT_EQ(fps->column, 11);
  EXPECT_TRUE(op.Find("on")->boolean);
  EXPECT_EQ(op.Find("n")->type, JsonValue::Type::kNull);
  EXPECT_EQ(op.Find("missing"), nullptr);
  EXPECT_EQ(fps->Find("x"), nullptr);  // not an object
}

// JSON is UTF-8: a name from a Latin-1 file name ("caf\xe9") is written with U+FFFD in place of
// the byte that is not (a batch summary with the raw byte was not JSON any reader took).
TEST(JsonTest, AStringThatIsNotUtf8IsWrittenWithReplacementCharacters) {
  std::string out;
  AppendJsonString(out, "caf\xe9 \xc3\xa9\n");

  EXPECT_EQ(out, "\"caf\xEF\xBF\xBD \xc3\xa9\\n\"");
  EXPECT_TRUE(ParseJson(out, "s.json").ok());
  EXPECT_FALSE(IsUtf8("caf\xe9"));
  EXPECT_TRUE(IsUtf8("caf\xc3\xa9"));
}

// JSON text is UTF-8: a raw byte that is not is refused where it stands, so every string read
// writes back unchanged (the keyed-JSON fuzzer found a name of 0xff bytes read, then written as
// U+FFFD).
TEST(JsonTest, AStringThatIsNotUtf8IsRefusedWithItsPlace) {
  const absl::StatusOr<JsonValue> read = ParseJson("{\"name\": \"ab\xff\"}", "k.json");

  ASSERT_FALSE(read.ok());
  EXPECT_EQ(std::string(read.status().message()),
            "k.json:1:13: expected UTF-8 text in the string, got \"\\xff\"");
}

// A summary goes to the terminal: U+009B (CSI) and the other C1 controls are escaped.
TEST(JsonTest, C1ControlCharactersAreEscaped) {
  std::string out;
  AppendJsonString(out, "a\xc2\x9b" "2J");

  EXPECT_EQ(out, "\"a\\u009b2J\"");
  // ... and read back as the character it was (a manifest holding such a name stopped every
  // later run: the reader took only ASCII escapes).
  const absl::StatusOr<JsonValue> back = ParseJson(out, "s.json");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->text, "a\xc2\x9b" "2J");
  EXPECT_EQ(ParseJson("\"\\u00e9\\u20ac\"", "s.json")->text, "\xc3\xa9\xe2\x82\xac");
  EXPECT_FALSE(ParseJson("\"\\ud800\"", "s.json").ok());
}

TEST(JsonTest, DecodesStringEscapes) {
  absl::StatusOr<JsonValue> root = ParseJson(R"("a\"b\\c\n\u0041")", "s.json");
  ASSERT_TRUE(root.ok()) << root.status();
  EXPECT_EQ(root->text, "a\"b\\c\nA");
}

struct BadJson {
  const char* text;
  const char* message;
};

class JsonErrorTest : public ::testing::TestWithParam<BadJson> {};

TEST_P(JsonErrorTest, NamesLineAndColumn) {
  absl::StatusOr<JsonValue> root = ParseJson(GetParam().text, "p.json");
  ASSERT_FALSE(root.ok());
  EXPECT_EQ(root.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(root.status().message()), GetParam().message);
}

INSTANTIATE_TEST_SUITE_P(
    Cases, JsonErrorTest,
    ::testing::Values(
        BadJson{"", "p.json:1:1: expected a value, got the end of the text"},
        BadJson{"{\"a\": 1,\n \"b\" 2}", R"(p.json:2:6: expected ':', got "2")"},
        BadJson{"[1, 2", "p.json:1:6: expected ',' or ']', got the end of the text"},
        BadJson{"{\"a\": 1e999}", R"(p.json:1:7: number "1e999" is out of range for a double)"},
        BadJson{"{} x", R"(p.json:1:4: expected the end of the document, got "x")"},
        BadJson{"\"abc", "p.json:1:5: expected '\"' to end the string, got the end of the text"},
        BadJson{"[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]",
                "p.json:1:66: nesting deeper than 64 levels"}));

}  // namespace
}  // namespace tempokey::core
