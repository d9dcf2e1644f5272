// Forward kinematics over every frame, end sites included, and the figure's height, against
// closed forms: a planar chain of two bones turning about Z puts its points at sums of rotated
// bone vectors, (L1 cos a + L2 cos(a + b), L1 sin a + L2 sin(a + b)).
#include <cmath>
#include <numbers>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/model/kinematics.h"

#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// A few products of exact axis matrices: rounding of a few ulps of the lengths involved.
constexpr double kTolerance = 1e-12;
constexpr double kL1 = 3.0;
constexpr double kL2 = 2.0;

double Radians(double degrees) { return degrees * std::numbers::pi / 180.0; }

// Root "A" at (1, 5, 0) turning about Z by a[f]; child "B" at offset (L1, 0, 0) turning about Z
// by b[f]; B's end site at (L2, 0, 0).
Clip PlanarChain(const std::vector<double>& a, const std::vector<double>& b) {
  Clip clip;
  clip.frame_count = static_cast<std::int64_t>(a.size());
  clip.skeleton.joints = {{.name = "A", .parent = -1, .offset = {1, 5, 0}, .channels = {0}},
                          {.name = "B",
                           .parent = 0,
                           .offset = {kL1, 0, 0},
                           .channels = {1},
                           .end_sites = {{kL2, 0, 0}}}};
  clip.channels = {{.joint = 0, .kind = ChannelKind::kZRotation, .samples = a},
                   {.joint = 1, .kind = ChannelKind::kZRotation, .samples = b}};
  return clip;
}

void ExpectPosition(const Vec3& got, const Vec3& expected) {
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], expected[k], kTolerance) << "axis " << k;
}

TEST(WorldTrajectoriesTest, PlanarChainMatchesTheClosedFormAtEveryFrame) {
  const std::vector<double> a = {0, 30, 90, -45, 170};
  const std::vector<double> b = {0, 60, -90, 10, 35};
  const Clip clip = PlanarChain(a, b);

  const absl::StatusOr<PointTrajectories> world = WorldTrajectories(clip);

  ASSERT_TRUE(world.ok()) << world.status();
  ASSERT_EQ(world->points.size(), 3u);
  for (std::size_t f = 0; f < a.size(); ++f) {
    const double ra = Radians(a[f]);
    const double rab = Radians(a[f] + b[f]);
    const Vec3 b_position = {1 + kL1 * std::cos(ra), 5 + kL1 * std::sin(ra), 0};
    const Vec3 end = {b_position[0] + kL2 * std::cos(rab), b_position[1] + kL2 * std::sin(rab), 0};
    SCOPED_TRACE(::testing::Message() << "frame " << f);
    ExpectPosition(world->at(static_cast<std::int64_t>(f), 0), {1, 5, 0});
    ExpectPosition(world->at(static_cast<std::int64_t>(f), 1), b_position);
    ExpectPosition(world->at(static_cast<std::int64_t>(f), 2), end);
  }
}

TEST(WorldTrajectoriesTest, JointWorldPositionsAreTheTrajectoriesJoints) {
  const Clip clip = PlanarChain({10, 20}, {30, 40});

  const absl::StatusOr<PointTrajectories> world = WorldTrajectories(clip);
  const absl::StatusOr<std::vector<Vec3>> joints = JointWorldPositions(clip, 1);

  ASSERT_TRUE(world.ok());
  ASSERT_TRUE(joints.ok());
  ASSERT_EQ(joints->size(), 2u);
  EXPECT_EQ((*joints)[0], world->at(1, 0));
  EXPECT_EQ((*joints)[1], world->at(1, 1));
}

TEST(SkeletonPointsTest, ListJointsThenEndSitesAndNameThem) {
  Skeleton skeleton;
  skeleton.joints = {{.name = "Hips", .parent = -1, .end_sites = {}},
                     {.name = "Toe", .parent = 0, .end_sites = {{0, 0, 1}}},
                     {.name = "Hand", .parent = 0, .end_sites = {{1, 0, 0}, {0, 1, 0}}}};

  const std::vector<SkeletonPoint> points = SkeletonPoints(skeleton);

  const std::vector<SkeletonPoint> expected = {{0, -1}, {1, -1}, {2, -1}, {1, 0}, {2, 0}, {2, 1}};
  EXPECT_EQ(points, expected);
  EXPECT_EQ(SkeletonPointName(skeleton, points[1]), "Toe");
  EXPECT_EQ(SkeletonPointName(skeleton, points[3]), "Toe end site");
  EXPECT_EQ(SkeletonPointName(skeleton, points[5]), "Hand end site 2");
}

TEST(FigureHeightTest, IsTheVerticalExtentOfJointsAndEndSitesAtTheFirstFrame) {
  // At frame 0 the root turns the chain upright (+X to +Y): B at height 5 + L1, its end site at
  // 5 + L1 + L2 with B's own 0 turn, so the height is L1 + L2. Frame 1 lies flat and does not
  // count.
  const Clip clip = PlanarChain({90, 0}, {0, 0});

  const absl::StatusOr<double> height = FigureHeight(clip);

  ASSERT_TRUE(height.ok()) << height.status();
  EXPECT_NEAR(*height, kL1 + kL2, kTolerance);
}

TEST(FigureHeightTest, BentChainIsShorter) {
  // Root upright, B turned 90 more about Z: B's end site points along -X at B's height.
  const Clip clip = PlanarChain({90}, {90});

  const absl::StatusOr<double> height = FigureHeight(clip);

  ASSERT_TRUE(height.ok());
  EXPECT_NEAR(*height, kL1, kTolerance);
}

TEST(FigureHeightTest, RefusesClipsWithoutSkeleton) {
  Clip plain;
  plain.frame_count = 1;
  plain.channels.push_back({.name = "x", .samples = {1.0}});

  EXPECT_EQ(FigureHeight(plain).status().message(),
            "forward kinematics needs a skeleton, the clip has none");
  EXPECT_EQ(WorldTrajectories(plain).status().code(), absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace tempokey::core
