// The Euler filter: synthetic flips with known answers, and every shared clip against rotation
// matrices built here from the axis rotations (not the library's), with continuity checked
// against a brute-force enumeration of equivalent triples.
#include "tempokey/core/model/euler_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

// Matrices agree to this (entries of products of three rotation matrices; the filter adds 180 or
// 360 to angles of a few hundred degrees, a relative rounding of 1e-16 each).
constexpr double kMatrixTolerance = 1e-12;

using Matrix = std::array<std::array<double, 3>, 3>;

// R about axis 0/1/2 by `degrees`, written from the right-hand rule (column vectors).
Matrix Axis(int axis, double degrees) {
  const double r = degrees * std::numbers::pi / 180.0;
  const double c = std::cos(r);
  const double s = std::sin(r);
  if (axis == 0) return {{{1, 0, 0}, {0, c, -s}, {0, s, c}}};
  if (axis == 1) return {{{c, 0, s}, {0, 1, 0}, {-s, 0, c}}};
  return {{{c, -s, 0}, {s, c, 0}, {0, 0, 1}}};
}

Matrix Product(const Matrix& a, const Matrix& b) {
  Matrix m{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      for (int k = 0; k < 3; ++k) m[i][j] += a[i][k] * b[k][j];
    }
  }
  return m;
}

// BVH: intrinsic, listed order composed left to right.
Matrix Rotation(const EulerOrder& order, const Vec3& degrees) {
  return Product(Product(Axis(order[0], degrees[0]), Axis(order[1], degrees[1])),
                 Axis(order[2], degrees[2]));
}

double MaxDifference(const Matrix& a, const Matrix& b) {
  double worst = 0.0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) worst = std::max(worst, std::abs(a[i][j] - b[i][j]));
  }
  return worst;
}

// The filter's distance between triples: the sum of absolute angle differences.
double AbsoluteDistance(const Vec3& a, const Vec3& b) {
  return std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]);
}

// The least absolute distance to `previous` over triples of the rotation `degrees`: both
// branches, each angle shifted by -3..3 turns.
double NearestByEnumeration(const Vec3& degrees, const Vec3& previous) {
  double best = std::numeric_limits<double>::infinity();
  for (const Vec3& base : {degrees, Vec3{degrees[0] + 180.0, 180.0 - degrees[1],
                                         degrees[2] + 180.0}}) {
    for (int p = -3; p <= 3; ++p) {
      for (int q = -3; q <= 3; ++q) {
        for (int s = -3; s <= 3; ++s) {
          best = std::min(best, AbsoluteDistance({base[0] + 360.0 * p, base[1] + 360.0 * q,
                                                 base[2] + 360.0 * s},
                                                previous));
        }
      }
    }
  }
  return best;
}

// One joint "j" with rotation channels in `order` and the given triples as frames.
Clip JointClip(const EulerOrder& order, const std::vector<Vec3>& frames) {
  Clip clip;
  clip.name = "flip";
  clip.frame_time_seconds = 1.0 / 30.0;
  clip.frame_count = static_cast<std::int64_t>(frames.size());
  Joint joint;
  joint.name = "j";
  joint.parent = -1;
  clip.skeleton.joints.push_back(joint);
  constexpr ChannelKind kKinds[] = {ChannelKind::kXRotation, ChannelKind::kYRotation,
                                    ChannelKind::kZRotation};
  for (int k = 0; k < 3; ++k) {
    Channel channel;
    channel.joint = 0;
    channel.kind = kKinds[order[k]];
    for (const Vec3& f : frames) channel.samples.push_back(f[k]);
    clip.channels.push_back(channel);
    clip.skeleton.joints[0].channels.push_back(k);
  }
  return clip;
}

TEST(EulerFilterTest, SyntheticGimbalFlipIsUndoneExactly) {
  // A smooth ZXY motion; from frame 20 on the source switches to the other Euler branch
  // (a + 180, 180 - b, c + 180), wrapped into (-180, 180] as exporters write it.
  const EulerOrder order = {2, 0, 1};
  std::vector<Vec3> truth, source;
  for (int f = 0; f < 40; ++f) {
    const Vec3 t = {10.0 + 3.0 * f, 40.0 + 0.5 * f, -20.0 + 2.0 * f};
    truth.push_back(t);
    Vec3 s = t;
    if (f >= 20) s = {t[0] + 180.0 - 360.0, 180.0 - t[1], t[2] + 180.0};
    source.push_back(s);
  }
  Clip clip = JointClip(order, source);

  absl::StatusOr<EulerFilterReport> report = ApplyEulerFilter(clip);

  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_EQ(report->frames_changed, 20);
  EXPECT_EQ(report->joints_filtered, 1);
  for (int f = 0; f < 40; ++f) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(clip.channels[k].samples[f], truth[f][k], 1e-12) << "frame " << f;
    }
  }
}

TEST(EulerFilterTest, EveryOrderKeepsTheRotationOfTheFlippedBranch) {
  for (const EulerOrder& order :
       {EulerOrder{0, 1, 2}, EulerOrder{0, 2, 1}, EulerOrder{1, 0, 2}, EulerOrder{1, 2, 0},
        EulerOrder{2, 0, 1}, EulerOrder{2, 1, 0}}) {
    const Vec3 source = {170.0, -35.0, 95.0};
    const Vec3 previous = {-15.0, -150.0, -80.0};  // near the other branch

    const Vec3 filtered = NearestEquivalentEuler(source, previous);

    EXPECT_LT(MaxDifference(Rotation(order, filtered), Rotation(order, source)), kMatrixTolerance)
        << EulerOrderName(order);
    EXPECT_NEAR(AbsoluteDistance(filtered, previous), NearestByEnumeration(source, previous), 1e-9);
    EXPECT_LT(AbsoluteDistance(filtered, previous), AbsoluteDistance(source, previous));
  }
}

TEST(EulerFilterTest, ARealJumpTakesTheBranchWithTheSmallestTotalStep) {
  // CMU 131_01's right thumb (ZXY), frames 236 -> 237: the rotation itself turns by 171 degrees,
  // so both branches jump. Same branch, angles within 180: steps 78.3, -154.9, -121.3 (sum 354.5;
  // squares 44839). Other branch: -101.8, -178.4, 58.7 (sum 338.9; squares 45635). The filter
  // takes the smaller sum, where the least-squares choice would keep the same branch.
  const Vec3 previous = {85.290, 76.643, -71.474};
  const Vec3 source = {163.545, -78.221, 167.193};

  const Vec3 filtered = NearestEquivalentEuler(source, previous);

  EXPECT_NEAR(filtered[0], 163.545 + 180.0 - 360.0, 1e-12);
  EXPECT_NEAR(filtered[1], 180.0 + 78.221 - 360.0, 1e-12);
  EXPECT_NEAR(filtered[2], 167.193 + 180.0 - 360.0, 1e-12);
  EXPECT_NEAR(AbsoluteDistance(filtered, previous), NearestByEnumeration(source, previous), 1e-9);
  EXPECT_LT(MaxDifference(Rotation({2, 0, 1}, filtered), Rotation({2, 0, 1}, source)),
            kMatrixTolerance);
}

TEST(EulerFilterTest, PlainWrapsAreUnwrapped) {
  const Vec3 filtered = NearestEquivalentEuler({-179.0, 10.0, 5.0}, {178.0, 10.0, 5.0});

  EXPECT_DOUBLE_EQ(filtered[0], 181.0);
  EXPECT_DOUBLE_EQ(filtered[1], 10.0);
  EXPECT_DOUBLE_EQ(filtered[2], 5.0);
}

TEST(EulerFilterTest, ContinuousTriplesAreLeftBitForBit) {
  const Vec3 source = {12.5, -3.25, 100.0};

  const Vec3 filtered = NearestEquivalentEuler(source, {12.0, -3.0, 99.0});

  EXPECT_EQ(filtered, source);
}

TEST(EulerFilterTest, InvalidClipIsRefused) {
  Clip clip = JointClip({0, 1, 2}, {{0, 0, 0}, {1, 1, 1}});
  clip.channels[1].samples[1] = std::nan("");

  absl::StatusOr<EulerFilterReport> report = ApplyEulerFilter(clip);

  EXPECT_EQ(report.status().code(), absl::StatusCode::kInvalidArgument);
}

// Every shared clip: the same rotation at every frame of every joint, and each filtered triple
// the nearest equivalent of the previous filtered one (no step the rotation does not force).
TEST(EulerFilterCorpusTest, EverySharedClipKeepsItsRotationsAndBecomesContinuous) {
  const std::vector<std::string> files = testing::AllSharedBvhFiles();
  ASSERT_FALSE(files.empty());
  for (const std::string& path : files) {
    SCOPED_TRACE(path);
    absl::StatusOr<Clip> source = ReadBvhFile(path);
    ASSERT_TRUE(source.ok()) << source.status();
    Clip filtered = *source;

    absl::StatusOr<EulerFilterReport> report = ApplyEulerFilter(filtered);

    ASSERT_TRUE(report.ok()) << report.status();
    double worst_matrix = 0.0;
    double worst_excess = 0.0;
    for (const JointRotation& joint : JointRotations(*source)) {
      if (joint.channels.size() != 3) continue;
      auto triple = [&](const Clip& clip, std::int64_t f) {
        return Vec3{clip.channels[joint.channels[0]].samples[f],
                    clip.channels[joint.channels[1]].samples[f],
                    clip.channels[joint.channels[2]].samples[f]};
      };
      for (std::int64_t f = 0; f < source->frame_count; ++f) {
        worst_matrix = std::max(worst_matrix, MaxDifference(Rotation(joint.order, triple(filtered, f)),
                                                            Rotation(joint.order, triple(*source, f))));
        if (f == 0) continue;
        const Vec3 previous = triple(filtered, f - 1);
        const double step = AbsoluteDistance(triple(filtered, f), previous);
        worst_excess = std::max(worst_excess,
                                step - NearestByEnumeration(triple(*source, f), previous));
      }
    }
    EXPECT_LT(worst_matrix, kMatrixTolerance);
    EXPECT_LT(worst_excess, 1e-6);
  }
}

}  // namespace
}  // namespace tempokey::core
