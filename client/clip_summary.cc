#include "client/clip_summary.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;

// Width of the label column, "rotation orders: " being the longest label.
constexpr std::size_t kLabelWidth = 17;

// Rates people mean when a file says 0.0083333 or 0.0333667: film, PAL, NTSC and their
// multiples, game and mocap rates.
struct CommonRate {
  double hz;
  std::string_view text;
};
constexpr CommonRate kCommonRates[] = {
    {10, "10"},   {12, "12"},   {15, "15"},   {24000.0 / 1001, "23.976"}, {24, "24"},
    {25, "25"},   {30000.0 / 1001, "29.97"},  {30, "30"},   {48, "48"},   {50, "50"},
    {60000.0 / 1001, "59.94"},  {60, "60"},   {72, "72"},   {90, "90"},   {96, "96"},
    {100, "100"}, {120000.0 / 1001, "119.88"}, {120, "120"}, {144, "144"}, {180, "180"},
    {200, "200"}, {240, "240"}, {250, "250"}, {360, "360"}, {480, "480"}, {500, "500"},
    {960, "960"}, {1000, "1000"},
};
constexpr double kSnapRelativeTolerance = 1e-4;

std::string Percent(std::int64_t part, std::int64_t whole) {
  if (whole <= 0) return "0%";
  return absl::StrFormat("%.2f%%", 100.0 * static_cast<double>(part) / static_cast<double>(whole));
}

}  // namespace

std::string FormatFrameRate(double frame_time_seconds) {
  const double hz = 1.0 / frame_time_seconds;
  std::string rate = absl::StrFormat("%.6g", hz);
  for (const CommonRate& common : kCommonRates) {
    if (std::abs(hz - common.hz) <= kSnapRelativeTolerance * common.hz) {
      rate = std::string(common.text);
      break;
    }
  }
  return absl::StrCat(rate, " fps (", core::FormatDouble(frame_time_seconds), " s)");
}

std::string FormatRotationOrders(const core::Clip& clip) {
  std::vector<std::pair<std::string, int>> orders;  // in order of first appearance
  for (const core::Joint& joint : clip.skeleton.joints) {
    std::string order;
    for (int index : joint.channels) {
      if (index < 0 || index >= static_cast<int>(clip.channels.size())) continue;
      const core::ChannelKind kind = clip.channels[static_cast<std::size_t>(index)].kind;
      if (core::IsRotation(kind)) order.push_back(static_cast<char>('X' + core::Axis(kind)));
    }
    if (order.empty()) continue;
    auto it = std::find_if(orders.begin(), orders.end(),
                           [&](const auto& entry) { return entry.first == order; });
    if (it == orders.end()) {
      orders.emplace_back(order, 1);
    } else {
      ++it->second;
    }
  }
  if (orders.empty()) return "none";
  std::stable_sort(orders.begin(), orders.end(),
                   [](const auto& a, const auto& b) { return a.second > b.second; });
  std::vector<std::string> parts;
  for (const auto& [order, count] : orders) {
    parts.push_back(absl::StrCat(order, " (", count, count == 1 ? " joint)" : " joints)"));
  }
  return absl::StrJoin(parts, ", ");
}

std::string SummaryLine(std::string_view label, std::string_view value) {
  std::string line = absl::StrCat(AsAbsl(label), ":");
  line.resize(std::max(line.size() + 1, kLabelWidth), ' ');
  return absl::StrCat(line, AsAbsl(value), "\n");
}

std::string FormatClipSummary(const core::Clip& clip) {
  int positions = 0;
  int rotations = 0;
  int scalars = 0;
  for (const core::Channel& channel : clip.channels) {
    if (core::IsRotation(channel.kind)) {
      ++rotations;
    } else if (core::IsPosition(channel.kind)) {
      ++positions;
    } else {
      ++scalars;
    }
  }
  std::string channels = absl::StrCat(clip.channels.size(), " (", positions, " position, ",
                                      rotations, " rotation");
  if (scalars > 0) absl::StrAppend(&channels, ", ", scalars, " scalar");
  absl::StrAppend(&channels, ")");

  return absl::StrCat(
      SummaryLine("name", clip.name), SummaryLine("frames", absl::StrCat(clip.frame_count)),
      SummaryLine("rate", FormatFrameRate(clip.frame_time_seconds)),
      SummaryLine("duration", absl::StrFormat("%.3f s", clip.duration_seconds())),
      SummaryLine("joints", absl::StrCat(clip.skeleton.joints.size())),
      SummaryLine("channels", channels), SummaryLine("rotation orders", FormatRotationOrders(clip)));
}

std::string FormatRetimeReport(const core::RetimeReport& report) {
  return absl::StrCat(
      SummaryLine("output frames", absl::StrCat(report.output_frame_count)),
      SummaryLine("output duration", absl::StrFormat("%.3f s", report.output_duration_seconds)),
      SummaryLine("fit factor", absl::StrFormat("%.6f", report.fit_factor)),
      SummaryLine("max decimation", absl::StrFormat("%.3f", report.max_decimation_ratio)),
      SummaryLine("filtered samples", absl::StrCat(report.filtered_sample_count)));
}

namespace {

// "noise rotations: median 0.5012 (0.4410 to 0.6012), estimated" per channel kind that has a
// noise level in the report (the noise method's); empty otherwise.
std::string FormatNoiseLevels(const core::ReductionReport& report, const core::Clip& layout) {
  std::string out;
  for (const bool rotations : {true, false}) {
    std::vector<double> levels;
    bool estimated = false;
    for (const core::ChannelReduction& channel : report.channels) {
      if (channel.noise_sigma <= 0.0 || channel.channel_index < 0 ||
          channel.channel_index >= static_cast<int>(layout.channels.size()) ||
          core::IsRotation(layout.channels[channel.channel_index].kind) != rotations) {
        continue;
      }
      levels.push_back(channel.noise_sigma);
      estimated = estimated || channel.noise_sigma_estimated;
    }
    if (levels.empty()) continue;
    std::sort(levels.begin(), levels.end());
    absl::StrAppend(
        &out, SummaryLine(rotations ? "noise rotations" : "noise positions",
                          absl::StrFormat("median %.4f (%.4f to %.4f), %s", levels[levels.size() / 2],
                                          levels.front(), levels.back(),
                                          estimated ? "estimated" : "given")));
  }
  return out;
}

}  // namespace

std::string FormatReductionReport(const core::ReductionReport& report, const core::Clip& layout) {
  std::string worst = absl::StrCat("channel ", report.worst_channel_index);
  if (report.worst_channel_index >= 0 &&
      report.worst_channel_index < static_cast<int>(layout.channels.size())) {
    worst = core::ChannelLabel(layout, report.worst_channel_index);
  }
  std::string out = absl::StrCat(
      SummaryLine("keys", absl::StrCat(report.key_count, " of ", report.sample_count, " samples (",
                                       Percent(report.key_count, report.sample_count), ")")),
      SummaryLine("rms error", absl::StrFormat("%.4f", report.rms_error)),
      SummaryLine("max error", absl::StrFormat("%.4f", report.max_error)),
      SummaryLine("worst", absl::StrCat(worst, " at frame ", report.worst_frame)));
  if (report.iterations > 0) absl::StrAppend(&out, SummaryLine("iterations", absl::StrCat(report.iterations)));
  absl::StrAppend(&out, FormatNoiseLevels(report, layout));
  if (report.euler_filtered_frames > 0) {
    absl::StrAppend(&out, SummaryLine("euler filter", absl::StrCat(report.euler_filtered_frames,
                                                                   " joint frames rewritten")));
  }
  if (report.world) absl::StrAppend(&out, FormatWorldErrorReport(*report.world));
  return out;
}

namespace {

// " (0.123% of height)", or nothing for a figure of height 0 (every point at one height at the
// first frame), which no distance is a share of: it printed "0.000% of height".
std::string OfHeight(const core::WorldErrorReport& world, double distance) {
  if (!(world.figure_height > 0.0)) return "";
  return absl::StrFormat(" (%.3f%% of height)", world.Percent(distance));
}

}  // namespace

std::string FormatWorldErrorReport(const core::WorldErrorReport& world) {
  std::string out = absl::StrCat(
      SummaryLine("figure height", absl::StrFormat("%.4g (first frame)", world.figure_height)),
      SummaryLine("joint max error",
                  absl::StrFormat("%.4f%s at %s, frame %d", world.max_error,
                                  OfHeight(world, world.max_error), world.worst_point_name,
                                  world.worst_frame)),
      SummaryLine("joint rms error",
                  absl::StrFormat("%.4f%s", world.rms_error, OfHeight(world, world.rms_error))));
  if (world.joint_tolerance > 0.0) {
    absl::StrAppend(&out, SummaryLine("joint bound",
                                      absl::StrFormat("%.4g%s", world.joint_tolerance,
                                                      OfHeight(world, world.joint_tolerance))));
  }
  return out;
}

std::string FormatGltfStats(const core::GltfStats& stats, const core::WorldErrorReport* world) {
  std::string out = SummaryLine(
      "gltf keys", absl::StrCat(stats.rotation_keys, " rotation (",
                                Percent(stats.rotation_keys, stats.rotation_samples), " of ",
                                stats.rotation_samples, " joint frames), ", stats.translation_keys,
                                " translation"));
  if (stats.joint_bound > 0.0) {
    const std::string percent =
        world != nullptr ? OfHeight(*world, stats.max_joint_error) : std::string();
    absl::StrAppend(&out, SummaryLine("gltf joint max",
                                      absl::StrFormat("%.4f%s, bound %.4g, as glTF plays the file",
                                                      stats.max_joint_error, percent,
                                                      stats.joint_bound)));
  }
  return out;
}

}  // namespace tempokey::client
