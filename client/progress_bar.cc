#include "client/progress_bar.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli_errors.h"
#include "tempokey/core/io/printable_text.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

constexpr int kMinBarWidth = 60;  // below this the bar itself is left out
constexpr int kBarCellsMin = 10;

std::string Plural(std::int64_t n, std::string_view word) {
  return absl::StrCat(n, " ", core::AsAbsl(word), n == 1 ? "" : "s");
}

std::string Rate(double files_per_second) {
  return files_per_second >= 0.1 ? absl::StrFormat("%.1f files/s", files_per_second)
                                 : absl::StrFormat("%.2f files/s", files_per_second);
}

}  // namespace

std::string FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "--:--";
  const auto whole = static_cast<std::int64_t>(std::llround(seconds));
  const std::int64_t hours = whole / 3600;
  const std::int64_t minutes = whole / 60 % 60;
  const std::int64_t secs = whole % 60;
  if (hours > 0) return absl::StrFormat("%d:%02d:%02d", hours, minutes, secs);
  return absl::StrFormat("%d:%02d", minutes, secs);
}

std::string RenderBatchBar(const BatchCounts& counts, double elapsed_seconds, int width) {
  const int finished = counts.finished();
  const int sent = counts.done + counts.failed;
  const int remaining = std::max(0, counts.total - finished);
  const double rate = elapsed_seconds > 0 ? sent / elapsed_seconds : 0.0;
  std::string left = "--:--";
  if (remaining == 0) {
    left = FormatDuration(0);
  } else if (rate > 0) {
    left = FormatDuration(remaining / rate);
  }
  const int digits = static_cast<int>(absl::StrCat(counts.total).size());
  const std::string text = absl::StrFormat(
      "%*d/%d  %d done  %d skipped  %d failed  %s  %s left", digits, finished, counts.total,
      counts.done, counts.skipped, counts.failed, Rate(rate), left);
  const int cells = width - static_cast<int>(text.size()) - 4;  // "[", "]", two spaces
  if (width < kMinBarWidth || cells < kBarCellsMin) return text;
  const double fraction =
      counts.total > 0 ? std::clamp(static_cast<double>(finished) / counts.total, 0.0, 1.0) : 1.0;
  const int full = static_cast<int>(std::floor(fraction * cells));
  return absl::StrCat("[", std::string(full, '#'), std::string(cells - full, '-'), "]  ", text);
}

std::string FormatBatchLogLine(const BatchFileResult& file, int finished, int total) {
  const int digits = static_cast<int>(absl::StrCat(total).size());
  const std::string head = absl::StrFormat("[%*d/%d] ", digits, finished, total);
  // Names and messages as a terminal should show them (a file name may hold any byte).
  const std::string name = core::PrintableText(file.name);
  const std::string output = core::PrintableText(file.output_path);
  if (!file.status.ok()) {
    return absl::StrFormat("%sfailed %s (%s, %.3f s): %s", head, name,
                           Plural(file.attempts, "attempt"), file.seconds,
                           core::PrintableText(core::AsStd(file.status.message())));
  }
  if (file.skipped) {
    return absl::StrFormat("%sskipped %s -> %s (up to date)", head, name, output);
  }
  return absl::StrFormat("%sok %s -> %s (%s, %.3f s)", head, name, output,
                         Plural(file.attempts, "attempt"), file.seconds);
}

BatchProgressDisplay::BatchProgressDisplay(std::ostream& err, ProgressMode mode, int total,
                                           int width)
    : err_(err), mode_(mode), width_(width), start_(std::chrono::steady_clock::now()) {
  counts_.total = total;
}

void BatchProgressDisplay::FileDone(const BatchFileResult& file) {
  if (!file.status.ok()) {
    ++counts_.failed;
  } else if (file.skipped) {
    ++counts_.skipped;
  } else {
    ++counts_.done;
  }
  if (mode_ == ProgressMode::kLines) {
    err_ << FormatBatchLogLine(file, counts_.finished(), counts_.total) << '\n' << std::flush;
  } else if (mode_ == ProgressMode::kBar) {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    std::string bar = RenderBatchBar(counts_, elapsed, width_ - 1);  // the last column wraps
    const std::size_t size = bar.size();
    if (bar.size() < drawn_) bar.resize(drawn_, ' ');
    err_ << '\r' << bar << std::flush;
    drawn_ = size;
  }
}

void BatchProgressDisplay::Finish() {
  if (mode_ != ProgressMode::kBar || drawn_ == 0) return;
  err_ << '\r' << std::string(drawn_, ' ') << '\r' << std::flush;
  drawn_ = 0;
}

}  // namespace tempokey::client
