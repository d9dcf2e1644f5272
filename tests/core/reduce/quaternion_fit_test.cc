#include "tempokey/core/reduce/quaternion_fit.h"

#include <cmath>
#include <stop_token>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

TEST(QuaternionFitTest, ConstantRotationNeedsTwoKeys) {
  const std::vector<Quat> rotations(100, EulerToQuat({2, 0, 1}, {30.0, -20.0, 75.0}));

  const absl::StatusOr<QuaternionCurve> curve = FitQuaternionCurve(rotations, 1.0 / 30.0, 0.5);

  ASSERT_TRUE(curve.ok()) << curve.status();
  EXPECT_EQ(curve->keys.size(), 2u);
  EXPECT_LE(MaxQuaternionCurveError(*curve, rotations, 1.0 / 30.0), 1e-4);  // float32 values
}

TEST(QuaternionFitTest, AStopEndsTheFitCancelled) {
  std::vector<Quat> rotations;
  for (int i = 0; i < 121; ++i) rotations.push_back(AxisRotation(2, 3.0 * i));
  std::stop_source stop;
  stop.request_stop();

  const absl::StatusOr<QuaternionCurve> curve =
      FitQuaternionCurve(rotations, 1.0 / 30.0, 0.1, stop.get_token());

  EXPECT_EQ(curve.status().code(), absl::StatusCode::kCancelled);
}

TEST(QuaternionFitTest, SteadyTurnIsFewKeysWithinTheBound) {
  // 90 degrees per second about a tilted axis for 4 s at 30 fps: a great-circle arc, which the
  // normalised cubic follows closely between sparse keys.
  std::vector<Quat> rotations;
  for (int i = 0; i < 121; ++i) {
    rotations.push_back(Multiply(AxisRotation(2, 3.0 * i), AxisRotation(0, 20.0)));
  }

  const absl::StatusOr<QuaternionCurve> curve = FitQuaternionCurve(rotations, 1.0 / 30.0, 0.1);

  ASSERT_TRUE(curve.ok()) << curve.status();
  EXPECT_LE(MaxQuaternionCurveError(*curve, rotations, 1.0 / 30.0), 0.1);
  EXPECT_LE(curve->keys.size(), 12u);
  for (const QuaternionKey& key : curve->keys) {
    EXPECT_NEAR(std::sqrt(Dot(key.value, key.value)), 1.0, 1e-6);  // validators want unit values
  }
}

// No two rotations are more than 180 degrees apart: every larger bound is the fit of 180, key for
// key. Taken as given, 359 degrees asked for about ten times the keys of 180 (the bound's sine
// turning down) and 400 failed with "the bound must be finite and > 0" (its sine negative).
TEST(QuaternionFitTest, BoundsOf180DegreesOrMoreAllGiveTheFitOf180) {
  std::vector<Quat> rotations;
  for (int i = 0; i < 121; ++i) {
    rotations.push_back(Multiply(AxisRotation(2, 7.0 * i), AxisRotation(0, 5.0 * std::sin(i))));
  }
  const absl::StatusOr<QuaternionCurve> at_180 = FitQuaternionCurve(rotations, 1.0 / 30.0, 180.0);
  ASSERT_TRUE(at_180.ok()) << at_180.status();

  for (double bound : {181.0, 270.0, 359.0, 360.0, 361.0, 400.0, 540.0, 720.0, 1e4, 1e9}) {
    const absl::StatusOr<QuaternionCurve> curve = FitQuaternionCurve(rotations, 1.0 / 30.0, bound);
    ASSERT_TRUE(curve.ok()) << bound << ": " << curve.status();
    ASSERT_EQ(curve->keys.size(), at_180->keys.size()) << bound;
    for (std::size_t k = 0; k < curve->keys.size(); ++k) {
      EXPECT_EQ(curve->keys[k].time_seconds, at_180->keys[k].time_seconds) << bound;
      const Quat& v = curve->keys[k].value;
      const Quat& w = at_180->keys[k].value;
      EXPECT_TRUE(v.w == w.w && v.x == w.x && v.y == w.y && v.z == w.z) << bound << " key " << k;
    }
  }
  EXPECT_LT(at_180->keys.size(), 20u);
}

TEST(QuaternionFitTest, EveryCmuJointStaysWithinTheBoundWithFewKeys) {
  absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  std::size_t keys = 0;
  std::size_t samples = 0;
  for (const JointRotation& rotation : JointRotations(*clip)) {
    std::vector<Quat> rotations;
    for (std::int64_t i = 0; i < clip->frame_count; ++i) {
      Vec3 angles{};
      for (int k = 0; k < 3; ++k) angles[k] = clip->channels[rotation.channels[k]].samples[i];
      rotations.push_back(EulerToQuat(rotation.order, angles));
    }

    const absl::StatusOr<QuaternionCurve> curve =
        FitQuaternionCurve(rotations, clip->frame_time_seconds, 0.5);

    ASSERT_TRUE(curve.ok()) << curve.status();
    EXPECT_LE(MaxQuaternionCurveError(*curve, rotations, clip->frame_time_seconds), 0.5)
        << clip->skeleton.joints[rotation.joint].name;
    keys += curve->keys.size();
    samples += rotations.size();
  }
  EXPECT_LT(keys, samples / 8);  // measured 5.6 %: see bench/export_bench
}

TEST(QuaternionFitTest, BadInputsAreRefusedWithTheReason) {
  const std::vector<Quat> two = {Quat{}, Quat{}};
  const std::vector<Quat> zero = {Quat{}, Quat{0, 0, 0, 0}};

  EXPECT_EQ(FitQuaternionCurve({}, 0.1, 0.5).status().message(), "no rotations to fit");
  EXPECT_EQ(FitQuaternionCurve(zero, 0.1, 0.5).status().message(),
            "rotation at frame 1 is not a finite non-zero quaternion");
  EXPECT_EQ(FitQuaternionCurve(two, 0.1, 0.0).status().message(),
            "rotation bound must be finite and > 0 degrees, got 0");
  EXPECT_EQ(FitQuaternionCurve(two, 1e-50, 0.5).status().message(),
            "frame time 1e-50 s is too small for float32 key times: frames 0 and 1 fall on the "
            "same time");
}

}  // namespace
}  // namespace tempokey::core
