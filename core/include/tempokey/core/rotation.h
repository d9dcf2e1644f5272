// Euler angles, quaternions and angle unwrapping for rotation channels (degrees throughout).
#ifndef TEMPOKEY_CORE_ROTATION_H_
#define TEMPOKEY_CORE_ROTATION_H_

#include <span>

namespace tempokey::core {

// Unwraps angles in degrees in place: adds multiples of 360 so consecutive samples differ by at
// most 180 degrees. The first sample is unchanged.
void UnwrapDegrees(std::span<double> degrees);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_ROTATION_H_
