#include "tempokey/core/model/status.h"

#include "absl/strings/cord.h"
#include "absl/strings/str_cat.h"

namespace tempokey::core {

absl::Status Annotate(const absl::Status& status, std::string_view context) {
  if (status.ok()) return status;
  absl::Status annotated(status.code(), absl::StrCat(AsAbsl(context), ": ", status.message()));
  // What the status carries besides its message goes along (a server's retry hint, say).
  status.ForEachPayload([&](absl::string_view type_url, const absl::Cord& payload) {
    annotated.SetPayload(type_url, payload);
  });
  return annotated;
}

}  // namespace tempokey::core
