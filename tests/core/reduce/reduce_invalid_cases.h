// Malformed parameters of the paper's reduction with their exact messages, shared by the core
// test (tests/core/reduce_test.cc) and the service test (tests/server/reduce_service_test.cc).
#ifndef TEMPOKEY_TESTS_CORE_REDUCE_INVALID_CASES_H_
#define TEMPOKEY_TESTS_CORE_REDUCE_INVALID_CASES_H_

#include <cmath>
#include <vector>

#include "tempokey/core/reduce/reduce.h"

namespace tempokey::core::reduce_cases {

struct BadPaperParams {
  void (*mutate)(PaperParams&);
  const char* message;
};

inline std::vector<BadPaperParams> BadPaperParamsTable() {
  return {
      {[](PaperParams& p) { p.step_y = -1; }, "paper.step_y must be > 0, got -1"},
      {[](PaperParams& p) { p.step_x_frames = 0; }, "paper.step_x_frames must be > 0, got 0"},
      {[](PaperParams& p) { p.step_tangent_x = NAN; }, "paper.step_tangent_x must be > 0, got NaN"},
      {[](PaperParams& p) { p.step_tangent_y = INFINITY; },
       "paper.step_tangent_y must be <= 1e+06, got +infinity"},
      {[](PaperParams& p) { p.accuracy = 0; }, "paper.accuracy must be > 0, got 0"},
      {[](PaperParams& p) { p.accuracy = -0.5; }, "paper.accuracy must be > 0, got -0.5"},
      {[](PaperParams& p) { p.max_iterations = 0; },
       "paper.max_iterations must be in [1, 1000], got 0"},
      {[](PaperParams& p) { p.max_iterations = 1'000'000; },
       "paper.max_iterations must be in [1, 1000], got 1000000"},
      {[](PaperParams& p) { p.smoothing_sigma_frames = NAN; },
       "paper.smoothing_sigma_frames must be 0 or in [0.01, 1000], got NaN"},
      {[](PaperParams& p) { p.smoothing_sigma_frames = -1; },
       "paper.smoothing_sigma_frames must be 0 or in [0.01, 1000], got -1"},
      // Found by fuzzing: a subnormal sigma squared to 0 made the smoothing kernel 0/0, every
      // initial key NaN, and a validated reduction fail when it ran.
      {[](PaperParams& p) { p.smoothing_sigma_frames = 3.2e-312; },
       "paper.smoothing_sigma_frames must be 0 or in [0.01, 1000], got 3.2e-312"},
      {[](PaperParams& p) { p.min_key_spacing_frames = 0; },
       "paper.min_key_spacing_frames must be in [1, 1000000], got 0"},
  };
}

}  // namespace tempokey::core::reduce_cases

#endif  // TEMPOKEY_TESTS_CORE_REDUCE_INVALID_CASES_H_
