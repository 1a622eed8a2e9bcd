// matchFileVertices: imported (float) vertices matched back to a file's vertex list.
#include "tetrig/rigbuild/match_file_vertices.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <optional>
#include <random>
#include <vector>

namespace tetrig::rigbuild {
namespace {

Vertices rows(std::initializer_list<Eigen::RowVector3d> points) {
  Vertices v(static_cast<Eigen::Index>(points.size()), 3);
  Eigen::Index i = 0;
  for (const auto& p : points) v.row(i++) = p;
  return v;
}

// The contract's tolerance, written out from the header's formula.
double toleranceOf(const Vertices& file) {
  const Eigen::RowVector3d lo = file.colwise().minCoeff();
  const Eigen::RowVector3d hi = file.colwise().maxCoeff();
  return 1e-6 * (hi - lo).norm() + 8.0 * FLT_EPSILON * file.cwiseAbs().maxCoeff();
}

// What assimp hands over: the coordinates rounded to float.
Eigen::RowVector3d asFloat(const Eigen::RowVector3d& p) {
  return {double(float(p[0])), double(float(p[1])), double(float(p[2]))};
}

bool sameFloatKey(const Eigen::RowVector3d& a, const Eigen::RowVector3d& b) {
  for (int k = 0; k < 3; ++k) {
    if (float(a[k]) != float(b[k])) return false;  // float == treats -0 and +0 alike
  }
  return true;
}

// How often bruteForce needed the nearest search, and how often the nearest was not the first
// file vertex within the tolerance (so that a test using it cannot pass vacuously).
struct BruteForceCounts {
  int misses = 0;
  int nearest_not_first = 0;
};

// Brute-force reference of the contract (O(#I #F)): earliest float-key match, else nearest within
// the tolerance, ties to the lowest index.
std::optional<std::vector<std::int32_t>> bruteForce(const Vertices& imported, const Vertices& file,
                                                    BruteForceCounts* counts = nullptr) {
  if (!file.allFinite()) return std::nullopt;
  const double tol = file.rows() > 0 ? toleranceOf(file) : 0.0;
  std::vector<std::int32_t> out;
  for (Eigen::Index v = 0; v < imported.rows(); ++v) {
    std::int32_t hit = -1;
    for (Eigen::Index i = 0; i < file.rows() && hit < 0; ++i) {
      if (sameFloatKey(imported.row(v), file.row(i))) hit = static_cast<std::int32_t>(i);
    }
    if (hit < 0) {
      double best = std::numeric_limits<double>::infinity();
      std::int32_t first = -1;
      for (Eigen::Index i = 0; i < file.rows(); ++i) {
        const double d = (file.row(i) - imported.row(v)).norm();
        if (d <= tol && first < 0) first = static_cast<std::int32_t>(i);
        if (d <= tol && d < best) {
          best = d;
          hit = static_cast<std::int32_t>(i);
        }
      }
      if (counts != nullptr) {
        ++counts->misses;
        if (hit != first) ++counts->nearest_not_first;
      }
    }
    if (hit < 0) return std::nullopt;
    out.push_back(hit);
  }
  return out;
}

// Unit cube corners plus one vertex (0.5, 0.5, 0.5): tolerance about 2.7e-6.
Vertices cubeWithCentre() {
  Vertices v(9, 3);
  for (int i = 0; i < 8; ++i) v.row(i) << double(i & 1), double((i >> 1) & 1), double((i >> 2) & 1);
  v.row(8) << 0.5, 0.5, 0.5;
  return v;
}

TEST(MatchFileVertices, ExactMatchesInShuffledOrder) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coord(-3.0, 5.0);
  Vertices file(200, 3);
  for (Eigen::Index i = 0; i < file.rows(); ++i) file.row(i) << coord(rng), coord(rng), coord(rng);
  std::vector<std::int32_t> perm(300);
  for (size_t k = 0; k < perm.size(); ++k) perm[k] = static_cast<std::int32_t>(k % 200);  // some twice
  std::shuffle(perm.begin(), perm.end(), rng);
  Vertices imported(static_cast<Eigen::Index>(perm.size()), 3);
  for (size_t k = 0; k < perm.size(); ++k) imported.row(static_cast<Eigen::Index>(k)) = asFloat(file.row(perm[k]));
  const auto got = matchFileVertices(imported, file);
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, perm);
}

TEST(MatchFileVertices, FloatKeyMatchWinsOverANearerLaterVertex) {
  // Vertex 0 rounds to the same float as vertex 1 (1.0), which is at distance 0 from the imported
  // point: the float key match (the earliest with that key) wins, not the nearest.
  const Vertices file = rows({{1.0 + 2e-8, 2.0, 3.0}, {1.0, 2.0, 3.0}, {-4.0, 0.0, 1.0}});
  ASSERT_EQ(float(file(0, 0)), 1.0f);
  const auto got = matchFileVertices(rows({{1.0, 2.0, 3.0}}), file);
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, std::vector<std::int32_t>{0});
}

TEST(MatchFileVertices, DuplicateFilePositionsMapToTheEarliest) {
  const Vertices file = rows({{5.0, 1.0, 1.0},
                              {0.25, -1.0, 2.0},
                              {-0.0, 3.0, 1.5},
                              {0.25, -1.0, 2.0},
                              {5.0, 1.0, 1.0},
                              {0.0, 3.0, 1.5}});
  // -0 and +0 are one key, either way round.
  const Vertices imported = rows({{0.25, -1.0, 2.0}, {5.0, 1.0, 1.0}, {0.0, 3.0, 1.5}, {-0.0, 3.0, 1.5}});
  const auto got = matchFileVertices(imported, file);
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, (std::vector<std::int32_t>{1, 0, 2, 2}));
}

TEST(MatchFileVertices, PerturbedWithinToleranceMapsToTheNearest) {
  const Vertices file = cubeWithCentre();
  const double tol = toleranceOf(file);
  ASSERT_GT(tol, 2e-6);
  ASSERT_LT(tol, 3e-6);
  // Off by 0.5 tol on each axis (|d| = 0.87 tol), far more than a float ulp: the key misses.
  for (Eigen::Index i = 0; i < file.rows(); ++i) {
    const Eigen::RowVector3d p = file.row(i) + Eigen::RowVector3d(0.5 * tol, -0.5 * tol, 0.5 * tol);
    ASSERT_FALSE(sameFloatKey(p, file.row(i)));
    const auto got = matchFileVertices(rows({p}), file);
    ASSERT_TRUE(got.has_value()) << "vertex " << i;
    EXPECT_EQ(*got, std::vector<std::int32_t>{static_cast<std::int32_t>(i)});
  }
}

TEST(MatchFileVertices, TwoCandidatesWithinToleranceTakesTheNearer) {
  const Vertices cube = cubeWithCentre();
  const double tol = toleranceOf(cube);
  const Eigen::RowVector3d p(0.5, 0.5, 0.5);
  const Eigen::RowVector3d far = p + Eigen::RowVector3d(0.0, 0.8 * tol, 0.0);
  const Eigen::RowVector3d near = p + Eigen::RowVector3d(-0.3 * tol, 0.0, 0.0);
  for (const bool near_first : {true, false}) {
    Vertices file = cube;
    file.row(8) = near_first ? near : far;
    file.conservativeResize(10, 3);
    file.row(9) = near_first ? far : near;
    ASSERT_DOUBLE_EQ(toleranceOf(file), tol);  // the extra vertices stay inside the cube
    const auto got = matchFileVertices(rows({p}), file);
    ASSERT_TRUE(got.has_value());
    EXPECT_EQ(*got, std::vector<std::int32_t>{near_first ? 8 : 9}) << "near_first " << near_first;
  }
}

TEST(MatchFileVertices, EqualDistanceGoesToTheLowerIndex) {
  // 0.5 +- e (e = 2^-20 or 2^-19, both below the tolerance of 2.7e-6) and the differences are
  // exact in double and distinct floats, so the distances from (0.5, 0.5, 0.5) to the candidates
  // are exactly equal. With e = 2^-19, +e and -e are more than a tolerance apart (in different
  // cells of any grid of that cell size, on different sides of most k-d splits).
  const Eigen::RowVector3d p(0.5, 0.5, 0.5);
  for (const int e_exp : {-20, -19}) {
    const double e = std::ldexp(1.0, e_exp);
    const std::vector<Eigen::RowVector3d> offsets = {{e, 0, 0}, {-e, 0, 0}, {0, e, 0}, {0, -e, 0}, {0, 0, e}, {0, 0, -e}};
    // Every rotation of the candidate order, so "first found" or "last found" fails somewhere.
    for (size_t first = 0; first < offsets.size(); ++first) {
      Vertices file = cubeWithCentre();
      file.conservativeResize(8 + static_cast<Eigen::Index>(offsets.size()), 3);
      for (size_t k = 0; k < offsets.size(); ++k) {
        file.row(8 + static_cast<Eigen::Index>(k)) = p + offsets[(first + k) % offsets.size()];
      }
      ASSERT_DOUBLE_EQ(toleranceOf(file), toleranceOf(cubeWithCentre()));
      const auto got = matchFileVertices(rows({p}), file);
      ASSERT_TRUE(got.has_value());
      EXPECT_EQ(*got, std::vector<std::int32_t>{8}) << "e = 2^" << e_exp << ", rotation " << first;
    }
  }
  // And the lower index also when it comes later in space (z before -x in the file).
  const double e = std::ldexp(1.0, -20);
  Vertices file = cubeWithCentre();
  file.row(8) = p + Eigen::RowVector3d(0, 0, e);
  file.conservativeResize(10, 3);
  file.row(9) = p + Eigen::RowVector3d(-e, 0, 0);
  const auto got = matchFileVertices(rows({p}), file);
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, std::vector<std::int32_t>{8});
}

TEST(MatchFileVertices, ToleranceIsInclusiveAndExact) {
  // Nearest file vertex at the origin, imported vertex on the x axis: |d| is the x coordinate
  // exactly (sqrt(x*x) == x in IEEE arithmetic).
  const Vertices file = rows({{0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}});
  const double tol = toleranceOf(file);
  const auto at = matchFileVertices(rows({{tol, 0.0, 0.0}}), file);
  ASSERT_TRUE(at.has_value()) << "a vertex exactly at the tolerance matches";
  EXPECT_EQ(*at, std::vector<std::int32_t>{0});
  const double beyond = std::nextafter(tol, 1.0);
  EXPECT_FALSE(matchFileVertices(rows({{beyond, 0.0, 0.0}}), file).has_value())
      << "one ulp beyond the tolerance does not match";
}

TEST(MatchFileVertices, PerturbedBeyondToleranceGivesNullopt) {
  const Vertices file = cubeWithCentre();
  const double tol = toleranceOf(file);
  Vertices imported = file;  // all exact but one
  imported.row(8) += Eigen::RowVector3d(0.0, 0.0, 1.05 * tol);
  EXPECT_FALSE(matchFileVertices(imported, file).has_value());
  imported.row(8) = file.row(8) + Eigen::RowVector3d(0.0, 0.0, 0.95 * tol);
  EXPECT_TRUE(matchFileVertices(imported, file).has_value());
  // Far from everything.
  EXPECT_FALSE(matchFileVertices(rows({{0.25, 0.25, 0.25}}), file).has_value());
}

TEST(MatchFileVertices, NonFiniteGivesNullopt) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (const double bad : {nan, inf, -inf}) {
    for (int k = 0; k < 3; ++k) {
      Vertices file = cubeWithCentre();
      const Vertices imported = file.topRows(8);  // all would match exactly
      file(8, k) = bad;                          // a file vertex no imported vertex needs
      EXPECT_FALSE(matchFileVertices(imported, file).has_value()) << bad << " in column " << k;
      EXPECT_FALSE(matchFileVertices(Vertices(0, 3), file).has_value()) << bad << " in column " << k;
    }
    // A non-finite imported vertex has no file vertex.
    Eigen::RowVector3d p(0.5, 0.5, 0.5);
    p[1] = bad;
    EXPECT_FALSE(matchFileVertices(rows({p}), cubeWithCentre()).has_value()) << bad << " imported";
  }
}

TEST(MatchFileVertices, EmptyInputs) {
  const auto none = matchFileVertices(Vertices(0, 3), Vertices(0, 3));
  ASSERT_TRUE(none.has_value());
  EXPECT_TRUE(none->empty());
  const auto no_imported = matchFileVertices(Vertices(0, 3), cubeWithCentre());
  ASSERT_TRUE(no_imported.has_value());
  EXPECT_TRUE(no_imported->empty());
  EXPECT_FALSE(matchFileVertices(rows({{0.0, 0.0, 0.0}}), Vertices(0, 3)).has_value());
}

TEST(MatchFileVertices, SingleVertexAtOriginHasZeroTolerance) {
  const Vertices file = rows({{0.0, 0.0, 0.0}});
  const auto same = matchFileVertices(rows({{-0.0, 0.0, -0.0}}), file);
  ASSERT_TRUE(same.has_value());
  EXPECT_EQ(*same, std::vector<std::int32_t>{0});
  EXPECT_FALSE(matchFileVertices(rows({{1e-30, 0.0, 0.0}}), file).has_value());
}

TEST(MatchFileVertices, AgreesWithBruteForceOnRandomPerturbations) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> coord(-1.0, 1.0);
  std::uniform_int_distribution<int> pick(0, 99);
  BruteForceCounts counts;
  for (int round = 0; round < 20; ++round) {
    // Clustered file vertices (pairs and triples closer than the tolerance) so that the nearest
    // and the tie rule matter.
    Vertices file(120, 3);
    for (Eigen::Index i = 0; i < 100; ++i) file.row(i) << coord(rng), coord(rng), coord(rng);
    const double tol = toleranceOf(file.topRows(100));
    for (Eigen::Index i = 100; i < 120; ++i) {
      file.row(i) = file.row(pick(rng)) + Eigen::RowVector3d(coord(rng), coord(rng), coord(rng)) * 0.5 * tol;
    }
    const double ftol = toleranceOf(file);
    Vertices imported(200, 3);
    for (Eigen::Index v = 0; v < imported.rows(); ++v) {
      const Eigen::RowVector3d base = file.row(pick(rng) + (v % 5 == 0 ? 20 : 0));
      const double scale = (v % 3 == 0) ? 0.0 : 0.5 * ftol;  // exact, or within 0.87 tolerance
      imported.row(v) = asFloat(base + Eigen::RowVector3d(coord(rng), coord(rng), coord(rng)) * scale);
    }
    const auto want = bruteForce(imported, file, &counts);
    ASSERT_TRUE(want.has_value()) << "round " << round;  // |offset| <= 0.5 sqrt(3) tol + float rounding
    const auto got = matchFileVertices(imported, file);
    ASSERT_TRUE(got.has_value()) << "round " << round;
    EXPECT_EQ(*got, *want) << "round " << round;
    // One vertex pushed out of reach makes the whole match fail, as the reference says.
    imported.row(17) = Eigen::RowVector3d(3.0, 3.0, 3.0);
    EXPECT_FALSE(bruteForce(imported, file).has_value());
    EXPECT_FALSE(matchFileVertices(imported, file).has_value()) << "round " << round;
  }
  // The comparison covered the nearest search, including clusters where the nearest is not the
  // first file vertex within reach.
  EXPECT_GT(counts.misses, 1000);
  EXPECT_GT(counts.nearest_not_first, 50);
}

}  // namespace
}  // namespace tetrig::rigbuild
