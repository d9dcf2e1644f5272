// The rotation-aware retime is fast and gives the same output as it always did. Three pins:
//   1. the reference implementation (rotation_reference.h, the per-sample path as first written)
//      reproduces, bit for bit, digests recorded from the library before the fast path replaced
//      it, on every shared clip under every kernel kind;
//   2. every channel the fast path does not touch (positions, scalars, the euler mode) is pinned
//      bit for bit by digests recorded the same way, but for channels whose samples never change:
//      those now come out as their value to the bit (the recorded sums were within rounding of
//      it), and are digested as the sums they were (AsRecorded());
//   3. the fast path's rotation channels match the reference within kRotationTolerance degrees at
//      every output sample;
//   4. the fast path's rotation channels are the same bits whichever kernels the machine takes:
//      digests recorded with the 8-lane AVX-512 kernels must come out of the 4-lane ones too
//      (this test runs again as avx2.* with TEMPOKEY_MAX_ISA=avx2, and at -O0 with the portable
//      kernels: deploy/unoptimized-kernel-tests.sh).
// The digests are of this platform's libm (Debian 12's glibc on x86-64): the reference calls
// std::sin, std::cos and std::atan2, whose last bit another libm may round differently.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/retime/resample.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/core/retime/time_map.h"
#include "tests/core/retime/rotation_reference.h"
#include "tests/testing/bit_digest.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

using ::tempokey::testing::AllSharedBvhFiles;
using ::tempokey::testing::BitDigest;
using ::tempokey::testing::ReferenceResampleRotation;
using ::tempokey::testing::SameBits;

// The fast path converts with vectorised sine, cosine and arctangent accurate to a few units in
// the last place where libm's are correctly rounded or nearly so; an angle of up to a few hundred
// degrees then differs by a few 1e-14, and near gimbal lock (down to the batched conversions'
// kBatchedMinMiddleCos) by up to ten times more: the worst over every case is 4.8e-13 (below).
constexpr double kRotationTolerance = 1e-12;

struct Case {
  const char* name;
  const char* speed;  // speed over source time; empty: constant 1
  std::int64_t fps = 0;  // output rate; 0: the source's
  ResampleFilter filter = ResampleFilter::kTent;
};

// Every kind of output sample: copies, slerps (linear, and tent at a = 0), squad (cubic at
// 0.4x), weighted means over narrow and wide kernels (tent, box, lanczos3), ramps.
const std::vector<Case>& Cases() {
  static const std::vector<Case> cases = {
      {"half speed section", "0s:1,2s:1,2s:0.5,4s:0.5,4s:1"},
      {"2.5x", "0s:2.5"},
      {"30 fps", "", 30},
      {"ramp 0.5 to 2", "0s:0.5,3s:2"},
      {"cubic 0.4x", "0s:0.4", 0, ResampleFilter::kCubic},
      {"box 1.7x", "0s:1.7", 0, ResampleFilter::kBox},
      {"lanczos3 24 fps", "", 24, ResampleFilter::kLanczos3},
      {"linear 0.7x", "0s:0.7", 0, ResampleFilter::kLinear},
  };
  return cases;
}

struct Warp {
  TimeWarpSpec spec;
  RetimeOptions options;
};

Warp MakeWarp(const Case& c) {
  Warp w;
  if (c.speed[0] != '\0') {
    w.spec.domain = WarpDomain::kSpeedOverSource;
    w.spec.speed = *ParseSpeedKnots(c.speed);
  }
  if (c.fps > 0) w.options.output_rate = FrameRate{c.fps, 1};
  w.options.filter = c.filter;
  return w;
}

const std::vector<Clip>& SharedClips() {
  static const std::vector<Clip>* clips = [] {
    auto* out = new std::vector<Clip>();
    for (const std::string& path : AllSharedBvhFiles()) {
      absl::StatusOr<Clip> clip = ReadBvhFile(path);
      if (clip.ok()) out->push_back(*std::move(clip));
    }
    return out;
  }();
  return *clips;
}

// The three-channel joints: the channels the rotation-aware path resamples together.
std::vector<JointRotation> RotationGroups(const Clip& clip) {
  std::vector<JointRotation> groups;
  for (JointRotation& j : JointRotations(clip)) {
    if (j.channels.size() == 3) groups.push_back(std::move(j));
  }
  return groups;
}

std::vector<bool> InRotationGroup(const Clip& clip) {
  std::vector<bool> in(clip.channels.size(), false);
  for (const JointRotation& j : RotationGroups(clip)) {
    for (int c : j.channels) in[static_cast<std::size_t>(c)] = true;
  }
  return in;
}

ResamplePlan PlanFor(const Clip& clip, const Warp& w) {
  const absl::StatusOr<TimeMap> map =
      TimeMap::Compile(clip.frame_time_seconds, clip.frame_count, w.spec, w.options);
  EXPECT_TRUE(map.ok()) << map.status();
  std::vector<double> x(static_cast<std::size_t>(map->output_frame_count()));
  std::vector<double> rho(x.size());
  map->SampleOutputGrid(x, rho);
  absl::StatusOr<ResamplePlan> plan = MakeResamplePlan(x, rho, clip.frame_count, w.options.filter);
  EXPECT_TRUE(plan.ok()) << plan.status();
  return *std::move(plan);
}

// The reference's output of every three-channel joint of `clip`, by channel index (other
// channels empty).
std::vector<std::vector<double>> ReferenceRotations(const Clip& clip, const ResamplePlan& plan) {
  std::vector<std::vector<double>> out(clip.channels.size());
  for (const JointRotation& j : RotationGroups(clip)) {
    std::array<std::span<const double>, 3> in;
    std::array<std::span<double>, 3> target;
    for (int k = 0; k < 3; ++k) {
      const auto c = static_cast<std::size_t>(j.channels[static_cast<std::size_t>(k)]);
      out[c].resize(plan.position.size());
      in[k] = clip.channels[c].samples;
      target[k] = out[c];
    }
    ReferenceResampleRotation(plan, j.order, in, target);
  }
  return out;
}

bool IsConstant(std::span<const double> samples) {
  return std::all_of(samples.begin(), samples.end(),
                     [&](double v) { return v == samples[0]; });
}

// The scalar path's output as it was when the digests below were recorded, before a constant
// channel was given its own value: each output's weights times the samples, summed in order.
std::vector<double> WeightedSumsAsRecorded(const ResamplePlan& plan,
                                           std::span<const double> source) {
  std::vector<double> out(plan.position.size());
  for (std::size_t j = 0; j < out.size(); ++j) {
    const double* s = source.data() + plan.first[j];
    const double* w = plan.weights.data() + plan.offset[j];
    const std::int64_t n = plan.offset[j + 1] - plan.offset[j];
    double sum = w[0] * s[0];
    for (std::int64_t k = 1; k < n; ++k) sum += w[k] * s[k];
    out[j] = sum;
  }
  return out;
}

// How far the recorded weighted sums of a constant channel may lie from its value, relative to
// it: a sum of up to a few dozen products, each rounded once, and weights that sum to one within
// as much.
constexpr double kRecordedSumTolerance = 8 * std::numeric_limits<double>::epsilon();

// A resampled channel as the digests were recorded: a channel whose samples never change now
// comes out as its value to the bit (ResampleScalar(): a copy as its own sample, -0 kept, every
// other output as the first sample), which `got` must be, and is digested as the weighted sums it
// used to give, which must lie within kRecordedSumTolerance of that value (every filter's
// weights reproduce a constant); any other channel as it is.
std::vector<double> AsRecorded(const ResamplePlan& plan, std::span<const double> source,
                               const std::vector<double>& got, const char* name) {
  if (!IsConstant(source)) return got;
  const double value = source[0];
  std::size_t not_the_value = 0, sums_off = 0;
  std::vector<double> sums = WeightedSumsAsRecorded(plan, source);
  for (std::size_t j = 0; j < got.size(); ++j) {
    const bool copy = plan.kind[j] == SampleKind::kCopy;
    if (!SameBits(got[j], copy ? source[static_cast<std::size_t>(plan.first[j])] : value)) {
      ++not_the_value;
    }
    if (!(std::abs(sums[j] - value) <= kRecordedSumTolerance * std::abs(value))) ++sums_off;
  }
  EXPECT_EQ(not_the_value, 0u) << name << ": outputs of a constant channel that are not its value";
  EXPECT_EQ(sums_off, 0u) << name << ": recorded sums off the value by more than the tolerance";
  return sums;
}

std::string Hex(std::uint64_t value) {
  char text[32];
  std::snprintf(text, sizeof text, "0x%016llx", static_cast<unsigned long long>(value));
  return text;
}

// Recorded from the library before the fast path (commit eadaf91), one per case over the eight
// shared clips in AllSharedBvhFiles() order. Constant channels enter as the sums they were then
// (AsRecorded()).
struct Pinned {
  std::uint64_t reference_rotations;  // ReferenceResampleRotation() on every 3-channel joint
  std::uint64_t other_channels;       // Retime(): every channel outside those joints
  std::uint64_t euler_mode;           // Retime() with RotationMode::kEuler: every channel
};

const std::vector<Pinned>& PinnedDigests() {
  static const std::vector<Pinned> pinned = {
      {0x25230e177f146326, 0x80dfcad505712c22, 0x64b80cad819d9646},
      {0x79d360139539d61f, 0x657990602ac5b6bb, 0x64057c73624e10ca},
      {0xf6354a296c04c528, 0xc9919b29dd12bc70, 0xe55a4c2cb5196e60},
      {0x56fd89ac05640a85, 0x3d73703248eda54a, 0xeb008ed4b734e27d},
      {0x88193df7bc6d9011, 0x347ce226bbefafef, 0x30871e5166f88c50},
      {0x66149acab2521aa1, 0x8148102cdb8d5493, 0xa9c370e52a1e3dc1},
      {0x798246d799243d4f, 0x8a035dbfa3d68ea9, 0x7a97bf3867b5a56f},
      {0x6c52dfede4a1bbdd, 0x2b0825023da38c70, 0xcf5212a1bfa6b48f},
  };
  return pinned;
}

TEST(RetimeIdentityTest, ReferenceAndUntouchedChannelsReproduceThePinnedDigests) {
  ASSERT_EQ(SharedClips().size(), 8u);
  ASSERT_EQ(PinnedDigests().size(), Cases().size());

  for (std::size_t i = 0; i < Cases().size(); ++i) {
    const Case& c = Cases()[i];
    BitDigest reference, others, euler;
    for (const Clip& clip : SharedClips()) {
      Warp w = MakeWarp(c);
      const ResamplePlan plan = PlanFor(clip, w);
      const std::vector<std::vector<double>> rotations = ReferenceRotations(clip, plan);
      const absl::StatusOr<RetimeResult> fast = Retime(clip, w.spec, w.options);
      w.options.rotation_mode = RotationMode::kEuler;
      const absl::StatusOr<RetimeResult> scalar = Retime(clip, w.spec, w.options);
      ASSERT_TRUE(fast.ok()) << c.name << ": " << fast.status();
      ASSERT_TRUE(scalar.ok()) << c.name << ": " << scalar.status();
      const std::vector<bool> grouped = InRotationGroup(clip);
      for (std::size_t ch = 0; ch < clip.channels.size(); ++ch) {
        const std::vector<double>& source = clip.channels[ch].samples;
        if (grouped[ch]) {
          reference.Add(rotations[ch]);
        } else {
          others.Add(AsRecorded(plan, source, fast->clip.channels[ch].samples, c.name));
        }
        euler.Add(AsRecorded(plan, source, scalar->clip.channels[ch].samples, c.name));
      }
      others.AddCount(fast->clip.frame_count);
      euler.AddCount(scalar->clip.frame_count);
    }

    const Pinned& expected = PinnedDigests()[i];
    EXPECT_EQ(Hex(reference.value()), Hex(expected.reference_rotations)) << c.name;
    EXPECT_EQ(Hex(others.value()), Hex(expected.other_channels)) << c.name;
    EXPECT_EQ(Hex(euler.value()), Hex(expected.euler_mode)) << c.name;
  }
}

TEST(RetimeIdentityTest, RotationAwareRetimeMatchesTheReferenceOnEverySharedClip) {
  ASSERT_EQ(SharedClips().size(), 8u);

  for (const Case& c : Cases()) {
    for (const Clip& clip : SharedClips()) {
      const Warp w = MakeWarp(c);
      const ResamplePlan plan = PlanFor(clip, w);
      const std::vector<std::vector<double>> rotations = ReferenceRotations(clip, plan);

      const absl::StatusOr<RetimeResult> fast = Retime(clip, w.spec, w.options);

      ASSERT_TRUE(fast.ok()) << c.name << ": " << fast.status();
      double worst = 0.0, worst_got = 0.0, worst_expected = 0.0;
      std::size_t worst_channel = 0, worst_frame = 0;
      for (std::size_t ch = 0; ch < clip.channels.size(); ++ch) {
        if (rotations[ch].empty()) continue;
        const std::vector<double>& got = fast->clip.channels[ch].samples;
        ASSERT_EQ(got.size(), rotations[ch].size()) << c.name << " " << clip.name;
        for (std::size_t f = 0; f < got.size(); ++f) {
          const double d = std::abs(got[f] - rotations[ch][f]);
          if (!(d <= worst)) {
            worst = d;
            worst_channel = ch;
            worst_frame = f;
            worst_got = got[f];
            worst_expected = rotations[ch][f];
          }
        }
      }
      EXPECT_LE(worst, kRotationTolerance)
          << c.name << " " << clip.name << " channel " << worst_channel << " frame " << worst_frame
          << ": " << absl::StrFormat("%.17g", worst_got) << ", reference "
          << absl::StrFormat("%.17g", worst_expected);
    }
  }
}

// Recorded on an AVX-512 machine, one per case over the eight shared clips: Retime()'s output on
// every channel of every 3-channel joint. First at commit f2e04c7; the five cases that take
// Markley's means again when those came to be found by repeated squaring (rotation_batch.cc,
// PowerEigenvectors(): within a few units in the last place of the Jacobi sweeps' eigenvector,
// so pin 3 above holds unchanged); all eight again when the conversions back to angles stopped
// normalizing the unit quaternions they are given and the vector arctangent chose its reduction
// on its operands (one division instead of two): pin 3's worst difference from the reference
// over every case and clip went from 3.8e-13 to 4.8e-13 degrees.
const std::vector<std::uint64_t>& FastRotationDigests() {
  static const std::vector<std::uint64_t> pinned = {
      0x4bd26909e480f6ee, 0xe9d2fd579b33d0f6, 0xebc2526f271a7617, 0x7ca00603ba6dfae4,
      0x67445842c1d4cc17, 0xd690674653e2ef3d, 0xa8fcacd184563850, 0x53ef7eb3e86fa3ac,
  };
  return pinned;
}

TEST(RetimeIdentityTest, RotationAwareRetimeIsTheSameBitsOnEveryInstructionSet) {
  ASSERT_EQ(SharedClips().size(), 8u);
  ASSERT_EQ(FastRotationDigests().size(), Cases().size());

  for (std::size_t i = 0; i < Cases().size(); ++i) {
    const Case& c = Cases()[i];
    BitDigest rotations;
    for (const Clip& clip : SharedClips()) {
      const Warp w = MakeWarp(c);
      const absl::StatusOr<RetimeResult> fast = Retime(clip, w.spec, w.options);
      ASSERT_TRUE(fast.ok()) << c.name << ": " << fast.status();
      const std::vector<bool> grouped = InRotationGroup(clip);
      for (std::size_t ch = 0; ch < clip.channels.size(); ++ch) {
        if (grouped[ch]) rotations.Add(fast->clip.channels[ch].samples);
      }
    }

    EXPECT_EQ(Hex(rotations.value()), Hex(FastRotationDigests()[i])) << c.name;
  }
}

}  // namespace
}  // namespace tempokey::core
