// A 64-bit digest of the exact bits of doubles (FNV-1a over their bytes), to pin a computation's
// output in a test: equal digests mean every value is bit for bit the same; and the same test for
// two values.
#ifndef TEMPOKEY_TESTS_TESTING_BIT_DIGEST_H_
#define TEMPOKEY_TESTS_TESTING_BIT_DIGEST_H_

#include <cstdint>
#include <cstring>
#include <span>

namespace tempokey::testing {

// Whether a and b are the same double bit for bit (+0 and -0 differ; a NaN equals its own bits).
inline bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

class BitDigest {
 public:
  void Add(double value) {
    unsigned char bytes[sizeof value];
    std::memcpy(bytes, &value, sizeof value);
    for (unsigned char b : bytes) {
      state_ ^= b;
      state_ *= 0x100000001b3ULL;
    }
  }
  void Add(std::span<const double> values) {
    for (double v : values) Add(v);
  }
  void AddCount(std::int64_t count) { Add(static_cast<double>(count)); }
  std::uint64_t value() const { return state_; }

 private:
  std::uint64_t state_ = 0xcbf29ce484222325ULL;
};

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_TESTING_BIT_DIGEST_H_
