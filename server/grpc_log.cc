// gRPC's log through the server's logger (grpc_log.h).
#include "server/grpc_log.h"

#include <grpc/support/log.h>

#include <chrono>
#include <mutex>
#include <string>

#include "spdlog/spdlog.h"
#include "tempokey/core/io/printable_text.h"

namespace tempokey::server {
namespace {

struct Window {
  std::mutex mutex;
  std::chrono::steady_clock::time_point start;
  int shown = 0;
  int held = 0;
};

Window& GrpcWindow() {
  static Window window;
  return window;
}

void LogGrpcLine(gpr_log_func_args* args) {
  if (args == nullptr || args->message == nullptr) return;
  Window& window = GrpcWindow();
  int held = 0;
  {
    const std::lock_guard<std::mutex> lock(window.mutex);
    const auto now = std::chrono::steady_clock::now();
    if (now - window.start >= kGrpcLogWindow) {
      held = window.held;
      window.start = now;
      window.shown = 0;
      window.held = 0;
    }
    if (window.shown >= kGrpcLinesPerWindow) {
      ++window.held;
      return;
    }
    ++window.shown;
  }
  if (held > 0) spdlog::warn("grpc: {} more lines of the last window not shown", held);
  spdlog::warn("grpc: {}", core::PrintableText(args->message, core::LineBreaks::kEscaped));
}

}  // namespace

void RouteGrpcLogToSpdlog() { gpr_set_log_function(LogGrpcLine); }

}  // namespace tempokey::server
