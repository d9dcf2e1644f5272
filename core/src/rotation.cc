#include "tempokey/core/rotation.h"

#include <cmath>

namespace tempokey::core {

void UnwrapDegrees(std::span<double> degrees) {
  double shift = 0.0;
  for (std::size_t i = 1; i < degrees.size(); ++i) {
    const double raw_step = degrees[i] - (degrees[i - 1] - shift);
    // Turns to add so the step lands in [-180, 180].
    shift -= 360.0 * std::round(raw_step / 360.0);
    degrees[i] += shift;
  }
}

}  // namespace tempokey::core
