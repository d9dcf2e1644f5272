// PrintableText() and LogValue(): what someone else wrote, printed on one line of a terminal or a
// log without acting on it.
#include "tempokey/core/io/printable_text.h"

#include <string>

#include "gtest/gtest.h"

namespace tempokey::core {
namespace {

TEST(PrintableTextTest, ControlCharactersAndInvalidBytesAreShownNotActedOn) {
  EXPECT_EQ(PrintableText("walk\x1b[2J.bvh"), "walk\\x1b[2J.bvh");
  EXPECT_EQ(PrintableText(std::string("a\0b", 3)), "a\\x00b");
  EXPECT_EQ(PrintableText("caf\xe9.bvh"), "caf\\xe9.bvh");           // Latin-1, not UTF-8
  EXPECT_EQ(PrintableText("x\xc2\x9b" "2J"), "x\\u009b2J");          // C1 CSI in UTF-8
  EXPECT_EQ(PrintableText("\xc3\xa9paule \xe2\x80\x94 ok"), "\xc3\xa9paule \xe2\x80\x94 ok");
  EXPECT_EQ(PrintableText("say \"hi\" \\"), "say \"hi\" \\");  // quotes are text on a terminal
}

TEST(PrintableTextTest, LineBreaksReadOnInATerminalAndAreShownInALog) {
  EXPECT_EQ(PrintableText("line one\nline two\r"), "line one line two ");
  EXPECT_EQ(PrintableText("line one\nline two\r", LineBreaks::kEscaped), "line one\\nline two\\r");
}

// A file name cannot forge a log line or a field: file="a.bvh outcome=succeeded" is one value.
TEST(PrintableTextTest, ALogValueIsOneQuotedFieldWhateverItHolds) {
  EXPECT_EQ(LogValue("walk.bvh"), "\"walk.bvh\"");
  EXPECT_EQ(LogValue("a.bvh\n[info] job id=forged outcome=succeeded"),
            "\"a.bvh\\n[info] job id=forged outcome=succeeded\"");
  EXPECT_EQ(LogValue("a\" outcome=\"succeeded"), "\"a\\\" outcome=\\\"succeeded\"");
  EXPECT_EQ(LogValue("back\\slash"), "\"back\\\\slash\"");
  EXPECT_EQ(LogValue(""), "\"\"");
}

}  // namespace
}  // namespace tempokey::core
