// The batch's test hooks: environment variables that make a run stop at an exact point (a
// signal after the N-th staged output, a kill after the N-th replacement), so that tests reach
// the moments between two file operations without depending on timing.
#ifndef TEMPOKEY_CLIENT_TEST_HOOK_H_
#define TEMPOKEY_CLIENT_TEST_HOOK_H_

#include <cstdlib>

namespace tempokey::client {

// The whole number `variable` holds; 0 when it is unset or not a number (the hook is off).
inline long TestHookCount(const char* variable) {
  const char* text = std::getenv(variable);
  return text == nullptr ? 0L : std::strtol(text, nullptr, 10);
}

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_TEST_HOOK_H_
