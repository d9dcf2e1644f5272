#include "retime_paper.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "retime_internal.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core::retime_internal {
namespace {

// Bisection steps for the discrete integral's constant g: enough to pin a double.
constexpr int kMaxBisections = 200;
// Integration steps between two looks at the stop token.
constexpr std::int64_t kStopCheckSteps = 65536;

// A piece of the speed curve inside the clip, linear from va at xa to vb at xb (source frames).
struct Piece {
  double xa, xb, va, vb;
};

double SpeedIn(const Piece& p, double x) {
  if (p.va == p.vb) return p.va;
  return p.va + (p.vb - p.va) * ((x - p.xa) / (p.xb - p.xa));
}

std::vector<Piece> ClipPieces(const std::vector<SpeedKnot>& knots, double dt, double x_end) {
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> x(knots.size());
  for (std::size_t k = 0; k < knots.size(); ++k) x[k] = knots[k].time.in_frames ? knots[k].time.value : knots[k].time.value / dt;
  std::vector<Piece> raw;
  raw.push_back({-inf, x.front(), knots.front().speed, knots.front().speed});
  for (std::size_t k = 0; k + 1 < knots.size(); ++k) {
    if (x[k + 1] > x[k]) raw.push_back({x[k], x[k + 1], knots[k].speed, knots[k + 1].speed});
  }
  raw.push_back({x.back(), inf, knots.back().speed, knots.back().speed});
  std::vector<Piece> pieces;
  for (const Piece& p : raw) {
    const double lo = std::max(p.xa, 0.0);
    const double hi = std::min(p.xb, x_end);
    if (!(hi > lo)) continue;
    const bool flat = std::isinf(p.xa) || std::isinf(p.xb);
    pieces.push_back({lo, hi, flat ? p.va : SpeedIn(p, lo), flat ? p.va : SpeedIn(p, hi)});
  }
  return pieces;
}

int Sign(double d) { return d > 0.0 ? 1 : d < 0.0 ? -1 : 0; }

absl::Status CheckSupported(const TimeWarpSpec& warp, const RetimeOptions& options) {
  if (warp.domain == WarpDomain::kSpeedOverOutput || warp.domain == WarpDomain::kTimeMapKeys) {
    return absl::InvalidArgumentError(absl::StrCat(
        "the paper method takes a speed curve over source time, not ",
        warp.domain == WarpDomain::kSpeedOverOutput ? "speed over output time" : "time-map keys"));
  }
  if (!warp.holds.empty()) return absl::InvalidArgumentError("the paper method does not support holds");
  if (!options.pins.empty()) return absl::InvalidArgumentError("the paper method does not support pins");
  if (options.fit_seconds || options.fit_frames) {
    return absl::InvalidArgumentError(
        "the paper method does not support fit_seconds or fit_frames: it rounds each region's "
        "sample count itself");
  }
  if (options.output_rate) {
    return absl::InvalidArgumentError(
        "the paper method keeps the source frame rate: output_rate must be unset");
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<PaperSchedule> PlanPaperRegions(double dt, std::int64_t frame_count,
                                               const TimeWarpSpec& warp,
                                               const RetimeOptions& options) {
  TEMPOKEY_RETURN_IF_ERROR(CheckFrameTime(dt, "source frame time"));
  if (frame_count < 1) {
    return absl::InvalidArgumentError(absl::StrCat("a clip needs at least 1 frame, got ", frame_count));
  }
  TEMPOKEY_RETURN_IF_ERROR(ValidateSpeedRange(options));
  TEMPOKEY_RETURN_IF_ERROR(CheckSupported(warp, options));
  if (warp.domain == WarpDomain::kIdentity && !warp.speed.empty()) {
    return absl::InvalidArgumentError(
        "speed knots are given but the warp domain is identity; set it to speed over source "
        "time");
  }
  if (warp.speed.size() > kMaxWarpItems) {
    return OverLimitError(absl::StrCat("too many speed knots: ", warp.speed.size(),
                                       ", over the limit of ", kMaxWarpItems));
  }
  std::vector<SpeedKnot> knots = warp.speed;
  if (warp.domain == WarpDomain::kIdentity) knots = {SpeedKnot{}};
  if (knots.empty()) {
    return absl::InvalidArgumentError("speed over source time needs at least one speed knot");
  }
  TEMPOKEY_RETURN_IF_ERROR(ValidateSpeedKnots(knots, dt, options));

  PaperSchedule schedule;
  const auto x_end = static_cast<double>(frame_count - 1);
  const std::vector<Piece> pieces = ClipPieces(knots, dt, x_end);
  double start = 0.0;
  double area = 0.0;
  int direction = 0;
  double total = 0.0;
  auto close = [&](double at) -> absl::Status {
    if (!(at > start)) return absl::OkStatus();
    const double length = at - start;
    // New count = length · (c / n) with c = length (normal speed) and n = the speed's area.
    const double count = length * length / area;
    total += count;
    if (!(total < static_cast<double>(kMaxOutputFrames))) {
      return absl::InvalidArgumentError(absl::StrCat(
          "the paper method would produce over ", kMaxOutputFrames, " frames"));
    }
    schedule.regions.push_back({start, at, area, static_cast<std::int64_t>(std::llround(count))});
    start = at;
    area = 0.0;
    return absl::OkStatus();
  };
  double previous_end_speed = std::numeric_limits<double>::quiet_NaN();
  for (const Piece& p : pieces) {
    // A step between pieces and the piece's own slope both count as changes of direction.
    const int changes[2] = {std::isnan(previous_end_speed) ? 0 : Sign(p.va - previous_end_speed),
                            Sign(p.vb - p.va)};
    for (int s : changes) {
      if (s == 0) continue;
      if (direction != 0 && s != direction) TEMPOKEY_RETURN_IF_ERROR(close(p.xa));
      direction = s;
    }
    area += (p.xb - p.xa) * 0.5 * (p.va + p.vb);
    previous_end_speed = p.vb;
  }
  TEMPOKEY_RETURN_IF_ERROR(close(x_end));
  std::int64_t count = 1;
  for (const PaperRegion& r : schedule.regions) count += r.new_count;
  schedule.output_count = count;
  return schedule;
}

absl::StatusOr<PaperSchedule> MakePaperSchedule(double dt, std::int64_t frame_count,
                                                const TimeWarpSpec& warp,
                                                const RetimeOptions& options,
                                                std::stop_token stop) {
  TEMPOKEY_ASSIGN_OR_RETURN(PaperSchedule schedule,
                            PlanPaperRegions(dt, frame_count, warp, options));
  std::vector<SpeedKnot> knots = warp.speed;
  if (knots.empty()) knots = {SpeedKnot{}};
  const auto x_end = static_cast<double>(frame_count - 1);
  const std::vector<Piece> pieces = ClipPieces(knots, dt, x_end);
  schedule.positions.reserve(static_cast<std::size_t>(schedule.output_count));
  schedule.ratios.reserve(static_cast<std::size_t>(schedule.output_count));

  double last_g = 1.0;
  std::size_t region_first_piece = 0;
  for (const PaperRegion& region : schedule.regions) {
    while (region_first_piece + 1 < pieces.size() && pieces[region_first_piece].xb <= region.x0) {
      ++region_first_piece;
    }
    const std::int64_t n = region.new_count;
    if (n < 1) continue;
    double min_speed = std::numeric_limits<double>::infinity();
    for (std::size_t i = region_first_piece; i < pieces.size() && pieces[i].xa < region.x1; ++i) {
      min_speed = std::min({min_speed, pieces[i].va, pieces[i].vb});
    }
    // The discrete integral p_{k+1} = p_k + g·v(p_k); returns p_n.
    auto integrate = [&](double g, std::vector<double>* positions, std::vector<double>* steps) {
      double p = region.x0;
      std::size_t piece = region_first_piece;
      for (std::int64_t k = 0; k < n; ++k) {
        // A bisection integrates a long region some sixty times: look at the stop token.
        if (k % kStopCheckSteps == 0 && stop.stop_requested()) {
          return std::numeric_limits<double>::quiet_NaN();
        }
        while (piece + 1 < pieces.size() && p >= pieces[piece].xb) ++piece;
        const double step = g * SpeedIn(pieces[piece], std::min(p, pieces[piece].xb));
        if (positions != nullptr) {
          positions->push_back(p);
          steps->push_back(step);
        }
        p += step;
      }
      return p;
    };
    double lo = 0.0;
    double hi = (region.x1 - region.x0) / (static_cast<double>(n) * min_speed);
    for (int it = 0; it < kMaxBisections && hi - lo > 1e-16 * hi; ++it) {
      const double mid = 0.5 * (lo + hi);
      (integrate(mid, nullptr, nullptr) < region.x1 ? lo : hi) = mid;
    }
    if (stop.stop_requested()) return absl::CancelledError("cancelled");
    const double g = 0.5 * (lo + hi);
    integrate(g, &schedule.positions, &schedule.ratios);
    if (stop.stop_requested()) return absl::CancelledError("cancelled");
    last_g = g;
  }
  schedule.positions.push_back(x_end);
  schedule.ratios.push_back(pieces.empty() ? 0.0 : last_g * pieces.back().vb);
  if (warp.reverse) {
    std::reverse(schedule.positions.begin(), schedule.positions.end());
    std::reverse(schedule.ratios.begin(), schedule.ratios.end());
  }
  return schedule;
}

}  // namespace tempokey::core::retime_internal
