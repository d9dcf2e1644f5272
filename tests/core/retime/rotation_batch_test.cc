// The batched kernels of the rotation-aware resampling (core/src/retime/rotation_batch.h) against
// the scalar functions of rotation.h they stand for: bit for bit where they promise the scalar
// arithmetic (weighted means, the several-argument trigonometry, Markley's means of broad
// spreads), within a few units in the last place where they use the vector sine, cosine and
// arctangent or (Markley's means of the usual spreads) repeated squaring for the eigenvector.
#include "core/src/retime/rotation_batch.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "core/src/simd/vector_trig.h"
#include "gtest/gtest.h"
#include "tempokey/core/model/rotation.h"
#include "tests/testing/bit_digest.h"

#pragma GCC diagnostic ignored "-Wpsabi"

namespace tempokey::core::retime_internal {
namespace {

using ::tempokey::testing::SameBits;

// A random unit quaternion within `spread_degrees` of `center` (either sign).
Quat Near(const Quat& center, double spread_degrees, std::mt19937_64& random) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const double half = 0.5 * spread_degrees * std::numbers::pi / 180.0 * unit(random);
  Quat axis{0.0, unit(random), unit(random), unit(random)};
  const double n = std::sqrt(Dot(axis, axis));
  const Quat turn{std::cos(half), std::sin(half) * axis.x / n, std::sin(half) * axis.y / n,
                  std::sin(half) * axis.z / n};
  const Quat q = Normalized(Multiply(center, turn));
  return unit(random) < 0.0 ? Negated(q) : q;
}

Quat RandomRotation(std::mt19937_64& random) {
  std::normal_distribution<double> normal;
  return Normalized(Quat{normal(random), normal(random), normal(random), normal(random)});
}

// Source quaternions (w, x, y, z) one after the other, as EulerToQuats() writes them.
std::vector<double> Interleaved(const std::vector<Quat>& quats) {
  std::vector<double> out;
  for (const Quat& q : quats) out.insert(out.end(), {q.w, q.x, q.y, q.z});
  return out;
}

struct Columns {
  std::vector<double> w, x, y, z;
  explicit Columns(std::size_t n) : w(n), x(n), y(n), z(n) {}
  QuatArrays Arrays() { return {w.data(), x.data(), y.data(), z.data()}; }
  Quat At(std::size_t i) const { return {w[i], x[i], y[i], z[i]}; }
};

// Weighted samples over a source of quaternions: windows of 1 to 12 taps with tent-like weights
// (some negative, some zero), spread from a few degrees to far past the Markley threshold.
struct MeanCase {
  std::vector<Quat> source;
  std::vector<double> weights;
  std::vector<WeightedMeanJob> jobs;
};

// Sample s's taps lie within spread(s) degrees of a random rotation.
template <class SpreadFn>
MeanCase MakeMeanCase(std::mt19937_64& random, std::size_t count, SpreadFn spread_of) {
  MeanCase c;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (std::size_t s = 0; s < count; ++s) {
    const auto taps = static_cast<std::int64_t>(1 + random() % 12);
    const double spread = spread_of(s);
    const Quat center = RandomRotation(random);
    WeightedMeanJob job{static_cast<std::int64_t>(c.source.size()), taps,
                        static_cast<std::int64_t>(c.weights.size()), 0};
    job.pivot = job.first + static_cast<std::int64_t>(random() % static_cast<std::uint64_t>(taps));
    for (std::int64_t n = 0; n < taps; ++n) {
      c.source.push_back(Near(center, spread, random));
      const double u = unit(random);
      c.weights.push_back(u < 0.1 ? 0.0 : u < 0.2 ? -0.1 * u : u);
    }
    c.jobs.push_back(job);
  }
  return c;
}

MeanCase MakeMeanCase(std::mt19937_64& random, std::size_t count) {
  return MakeMeanCase(random, count, [](std::size_t s) {
    return s % 3 == 0 ? 5.0 : s % 3 == 1 ? 40.0 : 170.0;
  });
}

// The lane-major tables of WeightedMeans() for `jobs`, as the schedule lays them out.
struct Tables {
  std::vector<MeanGroup> groups;
  std::vector<std::int64_t> source;
  std::vector<double> weight;
};

Tables MakeTables(const MeanCase& c) {
  Tables t;
  for (std::size_t g = 0; g < c.jobs.size(); g += kMeanLanes) {
    MeanGroup group{.tap_begin = t.source.size(), .taps = 0, .pivot = {}};
    for (std::size_t lane = 0; lane < kMeanLanes; ++lane) {
      const WeightedMeanJob& job = c.jobs[g + lane < c.jobs.size() ? g + lane : g];
      group.pivot[lane] = job.pivot;
      if (g + lane < c.jobs.size()) group.taps = std::max(group.taps, job.count);
    }
    for (std::int64_t n = 0; n < group.taps; ++n) {
      for (std::size_t lane = 0; lane < kMeanLanes; ++lane) {
        const bool in = g + lane < c.jobs.size();
        const WeightedMeanJob& job = c.jobs[in ? g + lane : g];
        const bool real = in && n < job.count;
        t.source.push_back(real ? job.first + n : job.pivot);
        t.weight.push_back(real ? c.weights[static_cast<std::size_t>(job.weight_offset + n)] : 0.0);
      }
    }
    t.groups.push_back(group);
  }
  return t;
}

std::vector<Quat> TapsOf(const MeanCase& c, const WeightedMeanJob& job) {
  return {c.source.begin() + job.first, c.source.begin() + job.first + job.count};
}

std::vector<double> WeightsOf(const MeanCase& c, const WeightedMeanJob& job) {
  return {c.weights.begin() + job.weight_offset,
          c.weights.begin() + job.weight_offset + job.count};
}

// WeightedMeans() on `c` against WeightedMeanRotation(): the same bits, and Markley's mean asked
// for exactly where the scalar function takes it. Returns how many samples asked for it.
int ExpectScalarWeightedMeans(const MeanCase& c) {
  const Tables tables = MakeTables(c);
  const std::vector<double> quats = Interleaved(c.source);
  const double min_dot = std::cos(0.5 * 30.0 * std::numbers::pi / 180.0);
  Columns out(c.jobs.size());
  std::vector<unsigned char> needs_markley(c.jobs.size(), 7);
  WeightedMeans(quats.data(), {tables.groups.data(), tables.source.data(), tables.weight.data()},
                c.jobs.size(), min_dot, out.Arrays(), needs_markley.data());
  int markley = 0;
  for (std::size_t i = 0; i < c.jobs.size(); ++i) {
    const WeightedMeanJob& job = c.jobs[i];
    const std::vector<Quat> taps = TapsOf(c, job);
    const std::vector<double> weights = WeightsOf(c, job);
    const auto pivot = static_cast<std::size_t>(job.pivot - job.first);
    const Quat expected = WeightedMeanRotation(taps, weights, pivot);
    // The scalar function took Markley's mean exactly where its result is Markley's.
    const Quat markley_mean = MarkleyMean(taps, weights, pivot);
    const bool scalar_took_markley =
        SameBits(expected.w, markley_mean.w) && SameBits(expected.x, markley_mean.x) &&
        SameBits(expected.y, markley_mean.y) && SameBits(expected.z, markley_mean.z);
    EXPECT_LE(needs_markley[i], 1) << "sample " << i;
    if (needs_markley[i]) {
      ++markley;
      EXPECT_TRUE(scalar_took_markley) << "sample " << i;
      continue;
    }
    const Quat got = out.At(i);
    EXPECT_TRUE(SameBits(got.w, expected.w) && SameBits(got.x, expected.x) &&
                SameBits(got.y, expected.y) && SameBits(got.z, expected.z))
        << "sample " << i << " (" << job.count << " taps)";
  }
  return markley;
}

TEST(RotationBatchTest, WeightedMeansAreTheScalarMeansBitForBitAndAskForMarkleyWhereItDoes) {
  std::mt19937_64 random(7);
  // Not a multiple of the lanes; both outcomes.
  const int markley = ExpectScalarWeightedMeans(MakeMeanCase(random, 303));
  EXPECT_GT(markley, 20);
  EXPECT_LT(markley, 280);
}

// Every count up to 40: the vectors summed in pairs, a last one alone (count mod 16 in 1..8 on
// 8 lanes, count mod 8 in 1..4 on 4), partial vectors and groups of different tap counts.
TEST(RotationBatchTest, WeightedMeansOfEveryCountUpToFortyAreTheScalarMeansBitForBit) {
  std::mt19937_64 random(41);
  for (std::size_t count = 1; count <= 40; ++count) {
    SCOPED_TRACE(::testing::Message() << count << " samples");
    ExpectScalarWeightedMeans(MakeMeanCase(random, count));
  }
}

TEST(RotationBatchTest, WeightedMeansDecideTheSpreadAsTheScalarFunctionNearItsLimit) {
  std::mt19937_64 random(23);
  // Narrow windows throughout (the test mostly settled from the pivot alone; Markley's mean only
  // for the few sums that do not normalize, such as a lone tap of weight 0), and windows around
  // the 30 degree spread (settled tap by tap, on either side).
  EXPECT_LT(ExpectScalarWeightedMeans(MakeMeanCase(random, 400, [](std::size_t) { return 8.0; })),
            20);
  std::uniform_real_distribution<double> spread(20.0, 45.0);
  const int markley = ExpectScalarWeightedMeans(
      MakeMeanCase(random, 400, [&](std::size_t) { return spread(random); }));
  EXPECT_GT(markley, 20);
  EXPECT_LT(markley, 380);
}

// How far the batched Markley mean may lie from the scalar one: the squarings and the Jacobi
// sweeps each land within a few units in the last place of the eigenvector.
constexpr double kMarkleyComponentTolerance = 2e-15;

// The criterion of rotation_batch.h for the squarings, computed here from the taps: the pivot's
// Rayleigh quotient on M + sigma I (sigma the sizes of the negative weights summed) over that
// matrix's trace. The squarings are taken at 3/4 and above; the sweeps below.
double PivotRayleighQuotient(const std::vector<Quat>& taps, const std::vector<double>& weights,
                             std::size_t pivot) {
  std::array<std::array<double, 4>, 4> m{};
  double sigma = 0.0;
  for (std::size_t n = 0; n < taps.size(); ++n) {
    const std::array<double, 4> v = {taps[n].w, taps[n].x, taps[n].y, taps[n].z};
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) m[r][c] += weights[n] * v[r] * v[c];
    }
    if (weights[n] < 0.0) sigma -= weights[n];
  }
  const std::array<double, 4> p = {taps[pivot].w, taps[pivot].x, taps[pivot].y, taps[pivot].z};
  double form = 0.0, trace = 0.0;
  for (int r = 0; r < 4; ++r) {
    trace += m[r][r] + sigma;
    for (int c = 0; c < 4; ++c) form += p[r] * (m[r][c] + (r == c ? sigma : 0.0)) * p[c];
  }
  return form / (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]) / trace;
}

// MarkleyMeans() on the jobs of `c` against MarkleyMean(): the same bits where the criterion
// sends a job to the sweeps, within kMarkleyComponentTolerance where it takes the squarings
// (jobs within rounding of the criterion's threshold may take either). The number of jobs the
// kernel says took the sweeps must be the criterion's, give or take those borderline jobs: a
// kernel that sent every job to the sweeps would give the right results but fail here.
struct MarkleyComparison {
  int squared = 0;
  int swept = 0;
  int borderline = 0;
};

MarkleyComparison CompareMarkleyMeans(const MeanCase& c) {
  const std::vector<double> quats = Interleaved(c.source);
  Columns out(c.jobs.size());
  const std::size_t kernel_swept =
      MarkleyMeans(quats.data(), c.weights.data(), c.jobs.data(), c.jobs.size(), out.Arrays());
  MarkleyComparison comparison;
  for (std::size_t i = 0; i < c.jobs.size(); ++i) {
    const WeightedMeanJob& job = c.jobs[i];
    const auto pivot = static_cast<std::size_t>(job.pivot - job.first);
    const Quat expected = MarkleyMean(TapsOf(c, job), WeightsOf(c, job), pivot);
    const Quat got = out.At(i);
    const double rayleigh = PivotRayleighQuotient(TapsOf(c, job), WeightsOf(c, job), pivot);
    const double worst = std::max({std::abs(got.w - expected.w), std::abs(got.x - expected.x),
                                   std::abs(got.y - expected.y), std::abs(got.z - expected.z)});
    // A spread that is not a number gives NaN either way (its sign bit may differ).
    const auto same = [](double a, double b) {
      return SameBits(a, b) || (std::isnan(a) && std::isnan(b));
    };
    const bool same_bits = same(got.w, expected.w) && same(got.x, expected.x) &&
                           same(got.y, expected.y) && same(got.z, expected.z);
    const auto describe = [&] {
      return ::testing::Message() << "sample " << i << " (" << job.count << " taps, Rayleigh "
                                << rayleigh << "): got " << got.w << " " << got.x << " " << got.y
                                << " " << got.z << ", expected " << expected.w << " "
                                << expected.x << " " << expected.y << " " << expected.z;
    };
    if (rayleigh >= 0.75 + 1e-9) {
      ++comparison.squared;
      EXPECT_LE(worst, kMarkleyComponentTolerance) << describe();
    } else if (!(rayleigh > 0.75 - 1e-9)) {
      ++comparison.swept;
      EXPECT_TRUE(same_bits) << describe();
    } else {
      ++comparison.borderline;
      EXPECT_LE(worst, kMarkleyComponentTolerance) << describe();
    }
  }
  EXPECT_GE(kernel_swept, static_cast<std::size_t>(comparison.swept));
  EXPECT_LE(kernel_swept, static_cast<std::size_t>(comparison.swept + comparison.borderline));
  return comparison;
}

TEST(RotationBatchTest, MarkleyMeansAreTheScalarMarkleyMeanWithinRoundingOrItsBits) {
  std::mt19937_64 random(11);
  // Spreads of 5, 40 and 170 degrees, negative and zero weights among the taps.
  const MarkleyComparison mixed = CompareMarkleyMeans(MakeMeanCase(random, 201));
  EXPECT_GT(mixed.squared, 50);
  EXPECT_GT(mixed.swept, 20);
  // Spreads where Markley's mean is taken in practice: past the 30-degree threshold.
  std::uniform_real_distribution<double> spread(30.0, 90.0);
  const MarkleyComparison typical =
      CompareMarkleyMeans(MakeMeanCase(random, 400, [&](std::size_t) { return spread(random); }));
  EXPECT_GT(typical.squared, 200);
}

TEST(RotationBatchTest, MarkleyMeansAtTheSquaringsLimitAndWithLargeNegativeWeights) {
  // Two equal taps a half-angle alpha apart and a small negative one: the pivot's Rayleigh
  // quotient crosses 3/4 near alpha = 34 degrees, where the squarings converge slowest. Then a
  // negative tap 60 degrees (half-angle) from the pivot, as heavy as or heavier than the others:
  // without the shift its eigenvalue is large and negative, the pivot's quotient on the unshifted
  // matrix over its trace passes 3/4, and the squarings, which square that eigenvalue too, would
  // leave an error far above rounding; with the shift the quotient falls below 3/4 and the job
  // takes the sweeps, bit for bit.
  MeanCase c;
  const auto add = [&](std::vector<Quat> taps, std::vector<double> weights) {
    c.jobs.push_back({static_cast<std::int64_t>(c.source.size()),
                      static_cast<std::int64_t>(taps.size()),
                      static_cast<std::int64_t>(c.weights.size()),
                      static_cast<std::int64_t>(c.source.size())});
    c.source.insert(c.source.end(), taps.begin(), taps.end());
    c.weights.insert(c.weights.end(), weights.begin(), weights.end());
  };
  const double axis = 1.0 / std::sqrt(14.0);
  for (double alpha = 26.0; alpha <= 42.0; alpha += 0.25) {
    const double h = alpha * std::numbers::pi / 180.0;
    add({{1, 0, 0, 0},
         {std::cos(h), std::sin(h) * axis, 2 * std::sin(h) * axis, 3 * std::sin(h) * axis},
         {std::cos(h / 2), 0, 0, std::sin(h / 2)}},
        {0.55, 0.5, -0.05});
  }
  const double sixty = std::numbers::pi / 3.0;
  for (double negative : {-0.2, -0.9, -1.2, -1.5, -1.8, -3.0}) {
    add({{1, 0, 0, 0},
         {std::cos(sixty), 0, std::sin(sixty), 0},
         {std::cos(0.02), std::sin(0.02), 0, 0}},
        {1.0, negative, 1.0});
  }
  const MarkleyComparison comparison = CompareMarkleyMeans(c);
  EXPECT_GT(comparison.squared, 10);
  EXPECT_GT(comparison.swept, 10);
}

TEST(RotationBatchTest, MarkleyMeansOfABroadSpreadAreTheScalarMarkleyMeanBitForBit) {
  // Equal weights on rotations 150 and 180 degrees apart (quaternions 75 and 90 degrees apart):
  // the largest eigenvalue is at most (1 + cos 75 deg) / 2 = 0.63 of the trace, or shared with
  // another, where squaring converges slowly or not at all. These take the Jacobi sweeps, as
  // does a spread that is not a number. Between them a job the squarings take, so the sweeps'
  // results go back to slots that are not in order.
  const double half = 75.0 * std::numbers::pi / 180.0;
  const std::vector<Quat> source = {{1, 0, 0, 0},
                                    {std::cos(half), 0, std::sin(half), 0},
                                    {0, 0, 0, 1},
                                    {0.5, 0.5, 0.5, 0.5},
                                    {0.5, -0.5, 0.5, -0.5}};
  const std::vector<double> weights = {0.5, 0.5, 0.5, 0.5, 0.25, 0.25, 0.25, 0.25,
                                       std::numeric_limits<double>::quiet_NaN(), 1.0, 1.0};
  const std::vector<WeightedMeanJob> jobs = {{0, 2, 0, 0}, {3, 1, 10, 3}, {0, 3, 1, 2},
                                             {2, 3, 3, 3}, {0, 4, 4, 1}, {1, 2, 8, 1}};
  const MarkleyComparison comparison = CompareMarkleyMeans({source, weights, jobs});
  EXPECT_EQ(comparison.squared, 1);
  EXPECT_EQ(comparison.swept, 5);
}

TEST(RotationBatchTest, MarkleyMeansOfIdenticalAndOppositeQuaternionsStopAsTheScalarOneDoes) {
  // A single tap, repeated taps and a quaternion with its negation: matrices already diagonal
  // or with exact zeros off the diagonal. The first three have one eigenvector and take the
  // squarings; the fourth and fifth take the sweeps, which
  // stop at once or skip rotations (their bits checked). The sixth, two orthogonal taps of
  // equal weight (a diagonal matrix with a tie), takes the sweeps as well.
  const std::vector<Quat> source = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0.6, 0.8, 0, 0},
                                    {-0.6, -0.8, 0, 0}, {0.5, 0.5, 0.5, 0.5}};
  const std::vector<double> weights = {1.0, 0.5, 0.25, 0.25, 1.0, 0.5, 0.5};
  const std::vector<WeightedMeanJob> jobs = {{0, 1, 0, 0}, {1, 1, 1, 1}, {2, 2, 2, 2},
                                             {0, 5, 0, 4}, {3, 2, 3, 3}, {0, 2, 5, 0}};
  const MarkleyComparison comparison = CompareMarkleyMeans({source, weights, jobs});
  EXPECT_EQ(comparison.squared, 3);
  EXPECT_EQ(comparison.swept, 3);
}

TEST(RotationBatchTest, SlerpsMatchTheScalarSlerpAndFlagDiscontinuities) {
  std::mt19937_64 random(13);
  std::vector<Quat> source;
  std::vector<std::int64_t> i0;
  std::vector<double> t;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int s = 0; s < 203; ++s) {
    const Quat a = RandomRotation(random);
    // Small steps (the series branch), large ones (the sine branch), past 90 degrees.
    const double spread = s % 3 == 0 ? 2.0 : s % 3 == 1 ? 60.0 : 200.0;
    i0.push_back(static_cast<std::int64_t>(source.size()));
    source.push_back(a);
    source.push_back(Near(a, spread, random));
    t.push_back(s % 17 == 0 ? 0.0 : s % 19 == 0 ? 1.0 : unit(random));
  }
  const std::vector<double> quats = Interleaved(source);
  Columns out(i0.size());
  std::vector<unsigned char> discontinuous(i0.size(), 7);
  SlerpQuats(quats.data(), i0.data(), t.data(), i0.size(), out.Arrays(), discontinuous.data());
  int flagged = 0;
  for (std::size_t i = 0; i < i0.size(); ++i) {
    const Quat& a = source[static_cast<std::size_t>(i0[i])];
    Quat b = source[static_cast<std::size_t>(i0[i]) + 1];
    if (Dot(b, a) < 0.0) b = Negated(b);
    ASSERT_LE(discontinuous[i], 1);
    EXPECT_EQ(discontinuous[i] == 1, Dot(a, b) < kDiscontinuityDot) << "sample " << i;
    if (discontinuous[i]) {
      ++flagged;
      continue;
    }
    const Quat expected = Slerp(a, b, t[i]);
    const Quat got = out.At(i);
    EXPECT_NEAR(got.w, expected.w, 4e-16) << "sample " << i;
    EXPECT_NEAR(got.x, expected.x, 4e-16) << "sample " << i;
    EXPECT_NEAR(got.y, expected.y, 4e-16) << "sample " << i;
    EXPECT_NEAR(got.z, expected.z, 4e-16) << "sample " << i;
  }
  EXPECT_GT(flagged, 10);
}

TEST(RotationBatchTest, ConversionsToQuaternionsAndBackMatchTheScalarFunctions) {
  std::mt19937_64 random(17);
  std::uniform_real_distribution<double> angle(-400.0, 400.0);
  constexpr std::size_t kCount = 1001;
  for (const char* name : {"XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"}) {
    const EulerOrder order = *ParseEulerOrder(name);
    std::array<std::vector<double>, 3> source;
    for (auto& channel : source) {
      for (std::size_t i = 0; i < kCount; ++i) channel.push_back(angle(random));
    }
    std::vector<double> quats(4 * kCount);
    EulerToQuats(order, source[0].data(), source[1].data(), source[2].data(), kCount, quats.data());
    Columns q(kCount);
    for (std::size_t i = 0; i < kCount; ++i) {
      const Quat expected = EulerToQuat(order, {source[0][i], source[1][i], source[2][i]});
      const Quat got{quats[4 * i], quats[4 * i + 1], quats[4 * i + 2], quats[4 * i + 3]};
      EXPECT_NEAR(got.w, expected.w, 1e-15) << name << " sample " << i;
      EXPECT_NEAR(got.x, expected.x, 1e-15) << name << " sample " << i;
      EXPECT_NEAR(got.y, expected.y, 1e-15) << name << " sample " << i;
      EXPECT_NEAR(got.z, expected.z, 1e-15) << name << " sample " << i;
      q.w[i] = got.w;
      q.x[i] = got.x;
      q.y[i] = got.y;
      q.z[i] = got.z;
    }
    // Back, against references near the source's angles (as the resampling's are) and turns
    // away from them: sample i between reference samples i and i + 1 (the last between its two
    // predecessors), written in reverse output order.
    std::uniform_real_distribution<double> near(-20.0, 20.0), away(-150.0, 150.0);
    std::array<std::vector<double>, 3> reference_values, turn_values;
    for (int c = 0; c < 3; ++c) {
      for (std::size_t i = 0; i < kCount; ++i) {
        reference_values[c].push_back(source[c][i] + near(random));
        turn_values[c].push_back(source[c][i] + away(random));
      }
    }
    std::vector<std::int64_t> i0(kCount), nearest(kCount), output(kCount);
    std::vector<double> t(kCount);
    for (std::size_t i = 0; i < kCount; ++i) {
      i0[i] = static_cast<std::int64_t>(i + 1 < kCount ? i : i - 1);
      t[i] = i + 1 < kCount ? 0.0 : 1.0;
      nearest[i] = static_cast<std::int64_t>(i);
      output[i] = static_cast<std::int64_t>(kCount - 1 - i);
    }
    std::array<std::vector<double>, 3> out;
    for (auto& channel : out) channel.assign(kCount, 0.0);
    std::vector<unsigned char> ill_conditioned(kCount, 7);
    const EulerTargets targets = {
        .i0 = i0.data(),
        .t = t.data(),
        .nearest = nearest.data(),
        .output = output.data(),
        .reference = {reference_values[0].data(), reference_values[1].data(),
                      reference_values[2].data()},
        .turn = {turn_values[0].data(), turn_values[1].data(), turn_values[2].data()},
        .out = {out[0].data(), out[1].data(), out[2].data()}};
    QuatsToEulerNearest(order, {q.w.data(), q.x.data(), q.y.data(), q.z.data()}, targets, kCount,
                        ill_conditioned.data());
    int ill = 0;
    for (std::size_t i = 0; i < kCount; ++i) {
      const std::size_t a = static_cast<std::size_t>(i0[i]);
      Vec3 reference;
      for (int c = 0; c < 3; ++c) {
        const std::vector<double>& v = reference_values[c];
        reference[c] = v[a] + t[i] * (v[a + 1] - v[a]);
      }
      const Vec3 angles = QuatToEulerNearest(q.At(i), order, reference);
      ASSERT_LE(ill_conditioned[i], 1);
      // The middle angle's cosine: the flag's own threshold.
      const double cos_b = std::cos(angles[1] * std::numbers::pi / 180.0);
      if (std::abs(std::abs(cos_b) - kBatchedMinMiddleCos) > 1e-9) {
        EXPECT_EQ(ill_conditioned[i] == 1, std::abs(cos_b) < kBatchedMinMiddleCos)
            << name << " sample " << i;
      }
      if (ill_conditioned[i]) {
        ++ill;
        continue;
      }
      for (int c = 0; c < 3; ++c) {
        const double expected = NearestTurn(angles[c], turn_values[c][i]);
        EXPECT_NEAR(out[c][kCount - 1 - i], expected, 1e-12) << name << " sample " << i;
      }
    }
    EXPECT_GT(ill, 0) << name;
  }
}

TEST(RotationBatchTest, AnAngleBeyondTheVectorSineLeavesItsNeighboursAsTheyAre) {
  // One sample far beyond the vector sine's range (or not a number) is converted by the scalar
  // code, bit for bit; the samples beside it in the same vector keep the vector path's bits, so
  // the output does not depend on how many samples a vector holds (avx2.* runs this at 4 lanes).
  std::mt19937_64 random(5);
  std::uniform_real_distribution<double> angle(-170.0, 170.0);
  constexpr std::size_t kCount = 41;
  const EulerOrder order = *ParseEulerOrder("ZXY");
  std::array<std::vector<double>, 3> source;
  for (auto& channel : source) {
    for (std::size_t i = 0; i < kCount; ++i) channel.push_back(angle(random));
  }
  std::vector<double> plain(4 * kCount);
  EulerToQuats(order, source[0].data(), source[1].data(), source[2].data(), kCount, plain.data());
  for (const double odd : {3e9, -2e10, std::numeric_limits<double>::quiet_NaN()}) {
    for (const std::size_t at : {std::size_t{3}, std::size_t{21}, std::size_t{40}}) {
      std::array<std::vector<double>, 3> changed = source;
      changed[at % 3][at] = odd;
      std::vector<double> quats(4 * kCount);
      EulerToQuats(order, changed[0].data(), changed[1].data(), changed[2].data(), kCount,
                   quats.data());
      const Quat scalar = EulerToQuat(order, {changed[0][at], changed[1][at], changed[2][at]});
      const std::array<double, 4> expected = {scalar.w, scalar.x, scalar.y, scalar.z};
      for (std::size_t i = 0; i < kCount; ++i) {
        for (std::size_t k = 0; k < 4; ++k) {
          const double want = i == at ? expected[k] : plain[4 * i + k];
          const double got = quats[4 * i + k];
          EXPECT_TRUE(SameBits(got, want) || (std::isnan(want) && std::isnan(got)))
              << "angle " << odd << " at sample " << at << ": sample " << i << " component " << k;
        }
      }
    }
  }
}

TEST(RotationBatchTest, SeveralArgumentTrigonometryIsTheSingleArgumentOneBitForBit) {
  using vector_trig::V4;
  std::mt19937_64 random(19);
  std::uniform_real_distribution<double> x(-8.0, 8.0);
  for (int round = 0; round < 200; ++round) {
    V4 args[3], ys[3];
    for (int k = 0; k < 3; ++k) {
      for (int lane = 0; lane < 4; ++lane) {
        args[k][lane] = x(random);
        ys[k][lane] = round % 7 == 0 ? 0.0 : x(random);
      }
    }
    V4 sine[3], cosine[3], angle[3];
    vector_trig::SinCos<3>(args, sine, cosine);
    vector_trig::Atan2<3>(ys, args, angle);
    for (int k = 0; k < 3; ++k) {
      V4 s, c;
      vector_trig::SinCos(args[k], s, c);
      const V4 a = vector_trig::Atan2(ys[k], args[k]);
      for (int lane = 0; lane < 4; ++lane) {
        EXPECT_TRUE(SameBits(sine[k][lane], s[lane]));
        EXPECT_TRUE(SameBits(cosine[k][lane], c[lane]));
        EXPECT_TRUE(SameBits(angle[k][lane], a[lane]));
      }
    }
  }
}

}  // namespace
}  // namespace tempokey::core::retime_internal
