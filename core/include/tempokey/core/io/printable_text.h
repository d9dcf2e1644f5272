// Text that quotes what someone else wrote (a file name, a token of a file, a server's message),
// made safe to print on one line of a terminal or a log: control characters (C0, DEL, C1) and
// bytes that are not UTF-8 are shown as \xNN or \u00NN, so they cannot act on a terminal or
// start a line of their own in a log.
#ifndef TEMPOKEY_CORE_IO_PRINTABLE_TEXT_H_
#define TEMPOKEY_CORE_IO_PRINTABLE_TEXT_H_

#include <string>
#include <string_view>

namespace tempokey::core {

enum class LineBreaks {
  kAsSpaces,  // a terminal line: the text reads on
  kEscaped,   // a log line: shown as \n and \r, so no line can be forged and none is lost
};

// `text` with its control characters and invalid bytes escaped (above).
std::string PrintableText(std::string_view text, LineBreaks line_breaks = LineBreaks::kAsSpaces);

// A log field's value: PrintableText() with line breaks escaped, in double quotes with `\` and
// `"` escaped, so a value (a file name "a.bvh outcome=succeeded") cannot end its field or its
// line: file="a.bvh outcome=succeeded".
std::string LogValue(std::string_view text);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_PRINTABLE_TEXT_H_
