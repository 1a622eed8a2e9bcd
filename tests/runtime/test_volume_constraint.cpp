// FineVolumeConstraint (tetrig/volume_constraint.hpp): the enclosed volume of x_fine = B x and its
// linearization in the tet-mesh positions, against a cube of known volume and finite differences.
#include "tetrig/volume_constraint.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace tetrig {
namespace {

// The unit cube's 8 corners (corner i at bits (x, y, z) of i) and its 12 outward triangles.
const std::vector<std::int32_t> kCubeTriangles = {0, 2, 3, 0, 3, 1,  4, 5, 7, 4, 7, 6,  0, 1, 5, 0, 5, 4,
                                                  2, 6, 7, 2, 7, 3,  0, 4, 6, 0, 6, 2,  1, 3, 7, 1, 7, 5};

std::vector<double> cube(double side) {
  std::vector<double> x;
  for (int i = 0; i < 8; ++i)
    for (int c = 0; c < 3; ++c) x.push_back(side * ((i >> c) & 1));
  return x;
}

// A row-stochastic 8 x 5 B (each fine corner a blend of 3 of 5 tet vertices).
struct Blend {
  std::vector<std::int32_t> offsets, columns;
  std::vector<double> weights;
  PoseTransferView<double> view() const { return {offsets.data(), columns.data(), weights.data(), 8, 5}; }
};

Blend randomBlend(std::mt19937& rng) {
  Blend b;
  std::uniform_real_distribution<double> u(0.1, 1.0);
  b.offsets.push_back(0);
  for (int r = 0; r < 8; ++r) {
    const double w[3] = {u(rng), u(rng), u(rng)};
    for (int k = 0; k < 3; ++k) {
      b.columns.push_back((r + 2 * k) % 5);
      b.weights.push_back(w[k] / (w[0] + w[1] + w[2]));
    }
    b.offsets.push_back(static_cast<std::int32_t>(b.columns.size()));
  }
  return b;
}

std::vector<double> fineOf(const Blend& b, const std::vector<double>& x_tet) {
  std::vector<double> out(24, 0.0);
  applyPoseTransfer(b.view(), x_tet.data(), out.data());
  return out;
}

// dV/dx_fine by central differences (V is cubic: exact up to rounding with h^2 terms).
std::vector<double> fineVolumeGradient(const FineVolumeConstraint& constraint, const std::vector<double>& fine) {
  const double h = 1e-5;
  std::vector<double> d(fine.size());
  for (std::size_t i = 0; i < fine.size(); ++i) {
    std::vector<double> up = fine, down = fine;
    up[i] += h;
    down[i] -= h;
    d[i] = (constraint.volume(up.data()) - constraint.volume(down.data())) / (2 * h);
  }
  return d;
}

// g = B^T dV/dx_fine is gathered with half-precision weights (|error| <= 2^-11 |w|) and float sums:
// its bound per component, 2^-11 sum_r |B_rj| |d_rc| plus float rounding.
double halfGatherBound(const Blend& b, const std::vector<double>& d, std::size_t component, double value) {
  double magnitude = 0.0;
  for (int r = 0; r < 8; ++r)
    for (int k = b.offsets[r]; k < b.offsets[r + 1]; ++k)
      if (static_cast<std::size_t>(b.columns[k]) == component / 3) magnitude += std::abs(b.weights[k] * d[3 * r + component % 3]);
  return 0x1p-11 * magnitude + 1e-6 * (1.0 + std::abs(value));
}

TEST(FineVolumeConstraint, TheCubesVolumeAndAnExactLinearization) {
  std::mt19937 rng(7);
  const Blend b = randomBlend(rng);
  const FineVolumeConstraint constraint(b.view(), kCubeTriangles, cube(2.0));
  EXPECT_NEAR(constraint.restVolume(), 8.0, 1e-12);  // outward triangles: positive
  EXPECT_NEAR(constraint.volume(cube(3.0).data()), 27.0, 1e-12);

  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<double> x(15);
  for (double& v : x) v = u(rng);
  const std::vector<double> fine = fineOf(b, x);
  std::vector<double> g(15);
  double now = 0.0;
  FineVolumeConstraint work(b.view(), kCubeTriangles, cube(2.0));
  const double c = work.linearize(x, fine.data(), g, &now);
  EXPECT_NEAR(now, work.volume(fine.data()), 1e-12);
  // g is dV(Bx)/dx: central differences (V is cubic in x: exact up to rounding with h^2 terms).
  const double h = 1e-5;
  const std::vector<double> d = fineVolumeGradient(work, fine);
  double largest_error = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    std::vector<double> up = x, down = x;
    up[i] += h;
    down[i] -= h;
    const double fd = (work.volume(fineOf(b, up).data()) - work.volume(fineOf(b, down).data())) / (2 * h);
    EXPECT_NEAR(g[i], fd, halfGatherBound(b, d, i, fd)) << "component " << i;
    largest_error = std::max(largest_error, std::abs(g[i] - fd));
  }
  EXPECT_LT(largest_error, 1e-2);  // the bound is ~2^-11 of |d|: g is not merely within a loose bound
  // c = V_rest - V(x0) + g . x0: a pose on the plane g . x = c keeps the rest volume to first order.
  double gx = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) gx += g[i] * x[i];
  EXPECT_NEAR(c, 8.0 - now + gx, 1e-12);
}

// gradient_entries: g = B'^T dV/dx_fine at the true fine pose B x, where B' keeps each row's
// largest weights rescaled to the row's sum. Checked against dV/dx_fine by central differences on
// the fine positions and B' made here; as many entries as a row has give the exact g.
TEST(FineVolumeConstraint, ACutGradientUsesEachRowsLargestWeightsRescaled) {
  std::mt19937 rng(11);
  const Blend b = randomBlend(rng);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<double> x(15);
  for (double& v : x) v = u(rng);
  const std::vector<double> fine = fineOf(b, x);
  FineVolumeConstraint exact(b.view(), kCubeTriangles, cube(2.0));
  FineVolumeConstraint cut(b.view(), kCubeTriangles, cube(2.0), 2);
  FineVolumeConstraint all(b.view(), kCubeTriangles, cube(2.0), 3);
  std::vector<double> g_exact(15), g_cut(15), g_all(15);
  const double c_exact = exact.linearize(x, fine.data(), g_exact);
  const double c_cut = cut.linearize(x, fine.data(), g_cut);
  all.linearize(x, fine.data(), g_all);
  const std::vector<double> d = fineVolumeGradient(exact, fine);
  std::vector<double> expected(15, 0.0), magnitude(15, 0.0);
  double differs = 0.0;
  for (int r = 0; r < 8; ++r) {
    const int begin = b.offsets[r];
    int smallest = begin;  // of 3 entries, the cut drops the smallest
    for (int k = begin; k < begin + 3; ++k) smallest = b.weights[k] < b.weights[smallest] ? k : smallest;
    const double kept = 1.0 - b.weights[smallest];  // rows sum to 1
    for (int k = begin; k < begin + 3; ++k) {
      if (k == smallest) continue;
      for (int c = 0; c < 3; ++c) {
        expected[3 * b.columns[k] + c] += b.weights[k] / kept * d[3 * r + c];
        magnitude[3 * b.columns[k] + c] += std::abs(b.weights[k] / kept * d[3 * r + c]);
      }
    }
  }
  for (std::size_t i = 0; i < 15; ++i) {
    // Half weights (2^-11) and float sums.
    EXPECT_NEAR(g_cut[i], expected[i], 0x1p-11 * magnitude[i] + 1e-6 * (1.0 + std::abs(expected[i]))) << "component " << i;
    EXPECT_EQ(g_all[i], g_exact[i]) << "component " << i;
    differs = std::max(differs, std::abs(g_cut[i] - g_exact[i]));
  }
  EXPECT_GT(differs, 1e-3) << "the cut must change g for the test to mean anything";
  // c still comes from the measured volume: V_rest - V(x0) + g . x0 with this g.
  double gx_cut = 0.0, gx_exact = 0.0;
  for (std::size_t i = 0; i < 15; ++i) {
    gx_cut += g_cut[i] * x[i];
    gx_exact += g_exact[i] * x[i];
  }
  EXPECT_NEAR(c_cut - gx_cut, c_exact - gx_exact, 1e-12);
  EXPECT_THROW(FineVolumeConstraint(b.view(), kCubeTriangles, cube(2.0), -1), std::invalid_argument);
}

TEST(FineVolumeConstraint, RefusesWhatDoesNotMatch) {
  std::mt19937 rng(1);
  const Blend b = randomBlend(rng);
  EXPECT_THROW(FineVolumeConstraint(b.view(), kCubeTriangles, std::vector<double>(21, 0.0)), std::invalid_argument);
  std::vector<std::int32_t> out_of_range = kCubeTriangles;
  out_of_range[4] = 8;
  EXPECT_THROW(FineVolumeConstraint(b.view(), out_of_range, cube(1.0)), std::invalid_argument);
  EXPECT_THROW(FineVolumeConstraint(b.view(), std::vector<std::int32_t>{0, 1}, cube(1.0)), std::invalid_argument);
}

// The one-pass gradient (volume_gradient.hpp) sums each triangle's area vector n = (b - a) x (c - a)
// at its corners, which equals 6 dV/dv only where the triangles close around v: an open or
// misoriented mesh is refused when the constraint is built.
TEST(FineVolumeConstraint, RefusesAnOpenOrMisorientedMesh) {
  std::mt19937 rng(3);
  const Blend b = randomBlend(rng);
  std::vector<std::int32_t> open(kCubeTriangles.begin(), kCubeTriangles.end() - 3);
  std::vector<std::int32_t> flipped = kCubeTriangles;
  std::swap(flipped[7], flipped[8]);
  for (const auto& triangles : {open, flipped}) {
    try {
      FineVolumeConstraint constraint(b.view(), triangles, cube(1.0));
      ADD_FAILURE() << "accepted a mesh that does not close";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("not closed and consistently oriented"), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(FineVolumeConstraint(b.view(), kCubeTriangles, cube(1.0)));
}

// A small closed mesh far from the origin (an icosahedron of radius 0.05 at 500 units), the fine
// pose in float as the live rig has it: g and the volume against double arithmetic on the same
// (float-rounded) positions, taken about the centre, where finite differences are exact enough.
// Products of whole positions would lose ~6 digits here (|a . (b x c)| ~ 10^8 against a volume of
// 5e-4); edges and a vertex of the mesh as the origin keep float's.
TEST(FineVolumeConstraint, TheFloatPassHoldsFarFromTheOrigin) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0, s = 0.05 / std::sqrt(1.0 + t * t);
  const double ico[12][3] = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                             {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  const std::vector<std::int32_t> faces = {0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4,
                                           11, 10, 2, 10, 7, 6, 7, 1, 8, 3, 9, 4, 3, 4, 2, 3, 2, 6, 3, 6, 8,
                                           3, 8, 9, 4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1};
  const double centre[3] = {500.0, -300.0, 200.0};
  std::vector<float> fine_f(36);
  std::vector<double> fine(36), local(36);
  for (int v = 0; v < 12; ++v)
    for (int c = 0; c < 3; ++c) {
      fine_f[3 * v + c] = static_cast<float>(centre[c] + s * ico[v][c]);
      fine[3 * v + c] = fine_f[3 * v + c];
      local[3 * v + c] = fine[3 * v + c] - centre[c];
    }
  // B = identity: g is dV/dx_fine itself.
  std::vector<std::int32_t> offsets(13), columns(12);
  std::vector<double> weights(12, 1.0);
  for (int v = 0; v < 12; ++v) {
    columns[v] = v;
    offsets[v + 1] = v + 1;
  }
  const PoseTransferView<double> identity{offsets.data(), columns.data(), weights.data(), 12, 12};
  FineVolumeConstraint constraint(identity, faces, local);
  const double volume = constraint.volume(local.data());
  ASSERT_GT(volume, 1e-4);  // outward faces: about 2.5e-4 * 2.18
  std::vector<double> g(36);
  double now = 0.0;
  constraint.linearize(fine, fine_f.data(), g, &now);
  EXPECT_NEAR(now, volume, 1e-6 * volume);
  const double h = 1e-6;
  double largest = 0.0;
  std::vector<double> expected(36);
  for (std::size_t i = 0; i < 36; ++i) {
    std::vector<double> up = local, down = local;
    up[i] += h;
    down[i] -= h;
    expected[i] = (constraint.volume(up.data()) - constraint.volume(down.data())) / (2 * h);
    largest = std::max(largest, std::abs(expected[i]));
  }
  for (std::size_t i = 0; i < 36; ++i) EXPECT_NEAR(g[i], expected[i], 1e-5 * largest) << "component " << i;
}

}  // namespace
}  // namespace tetrig
