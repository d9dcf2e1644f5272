// The fewest-keys search of the error-bounded fit (ToleranceFitOptions::fewest_keys,
// tolerance_fit.h): the same curve (a C1 cubic Hermite spline with keys on frames, every channel
// within its bound at every frame), keys placed by an exact search of what a key can be.
//
// For the keys placed so far, the set of (value, slope) pairs the last key can take, such that
// some curve through the keys before stays within the bound, is convex: a combination of two
// curves that keep the bound keeps it, the curve being linear in its keys' values and slopes.
// From it, the pairs the next key can take are the projection of a polytope in four dimensions
// (the two keys' values and slopes, one row per frame between them and the bound on each side),
// found by linear programs (small_lp.h): the largest value, slope and eight directions between
// give corners whose convex hull is held, a part of the set, never more. Every corner keeps the
// program's proof: its pair at the key before as a combination of that key's corners.
//
// Going forward, each key goes as far as its set reaches (a doubling, then halving, search: a
// stretch a cubic piece can follow, any part of it can), but a key that goes farthest may leave
// a set so narrow that the next key reaches little further. So of the candidates (the last
// kFewestKeysLookahead + 1 frames the key reaches, and as many spread back to the middle of its
// segment), the one whose set lets the next key reach farthest is taken (the farthest on a tie);
// a candidate whose programs give no verdict is passed over. Going back, from the centre of the
// last key's set, each key before takes the pair inside its own set that keeps the segment
// between within the bound with the widest margin (one more program). The programs' rows are in
// units of the bound (the same program for the same motion at any scale), keep the curve a
// ten-thousandth of the bound inside it, and start from a few dozen of a long segment's frames,
// adding those a solution misses; every solution taken is measured at every frame of its
// segment, and the whole curve at every frame against the bound at the end.
//
// Measured on ../shared/data at 0.5 degrees (rotation channels without constant ones): see the
// README's `tolerance` entry (`--fewest-keys`).
#ifndef TEMPOKEY_CORE_SRC_REDUCE_FEWEST_KEYS_FIT_H_
#define TEMPOKEY_CORE_SRC_REDUCE_FEWEST_KEYS_FIT_H_

#include <optional>
#include <span>
#include <stop_token>

#include "absl/status/statusor.h"
#include "tempokey/core/reduce/tolerance_fit.h"

namespace tempokey::core::reduce_internal {

// The frames searched back from the farthest a key reaches (and the candidates spread back to
// the middle of its segment), for the key whose set reaches farthest next.
inline constexpr int kFewestKeysLookahead = 8;

// The fit of `channels` (as FitWithinTolerance() takes them, already checked) by the search
// above, keys no further apart than kMaxMergedSegmentFrames. std::nullopt when a program did not
// reach a verdict or the curve misses a bound at some frame by rounding (the caller then fits
// the usual way); kCancelled when `stop` is requested (checked every 65536 rows of programs).
absl::StatusOr<std::optional<SplineFit>> FitFewestKeys(
    std::span<const std::span<const double>> channels, std::span<const double> max_errors,
    std::stop_token stop);

}  // namespace tempokey::core::reduce_internal

#endif  // TEMPOKEY_CORE_SRC_REDUCE_FEWEST_KEYS_FIT_H_
