// The fewest-keys search's linear programs (core/src/reduce/small_lp.h) against the answers of
// enumerating every vertex of small programs.
#include "core/src/reduce/small_lp.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <vector>

#include "gtest/gtest.h"

namespace tempokey::core::reduce_internal {
namespace {

struct Row {
  double x, y, bound;  // x z0 + y z1 <= bound
};

SmallLp Program(const std::vector<Row>& rows) {
  SmallLp lp;
  lp.Reset(2);
  for (const Row& r : rows) {
    const double a[2] = {r.x, r.y};
    lp.AddRow(a, r.bound);
  }
  return lp;
}

// The best of c.z over the vertices of {rows, z >= 0} in the plane: every pair of boundary
// lines crossed, the crossings that meet every row kept. std::nullopt when none does (the
// programs below are bounded, so a feasible one has a vertex).
std::optional<double> VertexOptimum(const std::vector<Row>& rows, double cx, double cy) {
  std::vector<Row> lines = rows;
  lines.push_back({-1.0, 0.0, 0.0});
  lines.push_back({0.0, -1.0, 0.0});
  std::optional<double> best;
  for (std::size_t i = 0; i < lines.size(); ++i) {
    for (std::size_t j = i + 1; j < lines.size(); ++j) {
      const double det = lines[i].x * lines[j].y - lines[i].y * lines[j].x;
      if (std::abs(det) < 1e-12) continue;
      const double x = (lines[i].bound * lines[j].y - lines[i].y * lines[j].bound) / det;
      const double y = (lines[i].x * lines[j].bound - lines[i].bound * lines[j].x) / det;
      const bool inside = std::all_of(lines.begin(), lines.end(), [&](const Row& r) {
        return r.x * x + r.y * y <= r.bound + 1e-9 * (1.0 + std::abs(r.bound));
      });
      if (inside) best = std::max(best.value_or(-HUGE_VAL), cx * x + cy * y);
    }
  }
  return best;
}

TEST(SmallLpTest, TheBestCornerOfATriangleInEveryDirection) {
  // z0 + z1 <= 4, z0 <= 3: corners (0,0), (3,0), (3,1), (0,4).
  SmallLp lp = Program({{1, 1, 4}, {1, 0, 3}});
  ASSERT_TRUE(lp.FindFeasible());
  std::vector<double> z;
  const double c1[2] = {1, 0};
  ASSERT_TRUE(lp.Maximize(c1, z));
  EXPECT_NEAR(z[0], 3.0, 1e-12);
  const double c2[2] = {0, 1};
  ASSERT_TRUE(lp.Maximize(c2, z));
  EXPECT_NEAR(z[1], 4.0, 1e-12);
  const double c3[2] = {2, 1};
  ASSERT_TRUE(lp.Maximize(c3, z));
  EXPECT_NEAR(z[0], 3.0, 1e-12);
  EXPECT_NEAR(z[1], 1.0, 1e-12);
}

TEST(SmallLpTest, AStartOutsideIsMadeFeasibleByPhaseOne) {
  // z0 + z1 >= 2 (written -z0 - z1 <= -2), z0 <= 1.5, z1 <= 1.5: the origin misses it.
  SmallLp lp = Program({{-1, -1, -2}, {1, 0, 1.5}, {0, 1, 1.5}});
  ASSERT_TRUE(lp.FindFeasible());
  std::vector<double> z;
  lp.Point(z);
  EXPECT_GE(z[0] + z[1], 2.0 - 1e-12);
  EXPECT_LE(z[0], 1.5 + 1e-12);
  EXPECT_LE(z[1], 1.5 + 1e-12);
  const double c[2] = {-1, -1};  // the least sum
  ASSERT_TRUE(lp.Maximize(c, z));
  EXPECT_NEAR(z[0] + z[1], 2.0, 1e-12);
}

TEST(SmallLpTest, RowsNoPointMeetsAreFoundInfeasible) {
  EXPECT_FALSE(Program({{1, 1, 1}, {-1, -1, -2}}).FindFeasible());
  EXPECT_FALSE(Program({{1, 0, -1}}).FindFeasible());  // z0 <= -1 against z0 >= 0
}

TEST(SmallLpTest, AnUnboundedDirectionIsReported) {
  SmallLp lp = Program({{1, -1, 1}});
  ASSERT_TRUE(lp.FindFeasible());
  std::vector<double> z;
  const double c[2] = {1, 1};
  EXPECT_FALSE(lp.Maximize(c, z));
}

TEST(SmallLpTest, RepeatedAndScaledRowsThroughOnePointAreHandled) {
  // Degenerate: many rows through (1, 1), some repeated, some scaled.
  std::vector<Row> rows;
  for (int i = 0; i < 20; ++i) {
    const double angle = 0.1 + 1.3 * i / 19.0;
    const double scale = 1.0 + (i % 3) * 1e3;
    rows.push_back({scale * std::cos(angle), scale * std::sin(angle),
                    scale * (std::cos(angle) + std::sin(angle))});
    if (i % 4 == 0) rows.push_back(rows.back());
  }
  SmallLp lp = Program(rows);
  ASSERT_TRUE(lp.FindFeasible());
  std::vector<double> z;
  const double c[2] = {1, 1};
  ASSERT_TRUE(lp.Maximize(c, z));
  EXPECT_NEAR(z[0] + z[1], *VertexOptimum(rows, 1, 1), 1e-9);
}

TEST(SmallLpTest, RandomProgramsMatchTheirVertices) {
  std::mt19937 random(7);
  std::uniform_real_distribution<double> coefficient(-1.0, 1.0);
  std::uniform_real_distribution<double> offset(-0.5, 2.0);
  int feasible = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    std::vector<Row> rows = {{1, 0, 5}, {0, 1, 5}};  // bounded
    const int count = 2 + trial % 12;
    for (int i = 0; i < count; ++i) {
      rows.push_back({coefficient(random), coefficient(random), offset(random)});
    }
    const double cx = coefficient(random);
    const double cy = coefficient(random);
    const std::optional<double> expected = VertexOptimum(rows, cx, cy);
    SmallLp lp = Program(rows);
    const bool found = lp.FindFeasible();
    ASSERT_EQ(found, expected.has_value()) << "trial " << trial;
    if (!found) continue;
    ++feasible;
    std::vector<double> z;
    const double c[2] = {cx, cy};
    ASSERT_TRUE(lp.Maximize(c, z)) << "trial " << trial;
    EXPECT_NEAR(cx * z[0] + cy * z[1], *expected, 1e-9) << "trial " << trial;
    for (const Row& r : rows) {
      EXPECT_LE(r.x * z[0] + r.y * z[1], r.bound + 1e-9 * (1.0 + std::abs(r.bound)))
          << "trial " << trial;
    }
  }
  EXPECT_GT(feasible, 500);  // both verdicts are exercised
  EXPECT_LT(feasible, 1900);
}

TEST(SmallLpTest, MaximizingAgainStartsFromTheLastBasis) {
  SmallLp lp = Program({{1, 1, 4}, {1, 0, 3}, {0, 1, 2}});
  ASSERT_TRUE(lp.FindFeasible());
  std::vector<double> z;
  for (int round = 0; round < 3; ++round) {
    for (const auto& [cx, cy, best] : std::vector<std::tuple<double, double, double>>{
             {1, 0, 3}, {0, 1, 2}, {1, 1, 4}, {-1, 0, 0}, {1, -1, 3}}) {
      const double c[2] = {cx, cy};
      ASSERT_TRUE(lp.Maximize(c, z));
      EXPECT_NEAR(cx * z[0] + cy * z[1], best, 1e-12);
    }
  }
}

}  // namespace
}  // namespace tempokey::core::reduce_internal
