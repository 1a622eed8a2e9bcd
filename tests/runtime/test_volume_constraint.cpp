// FineVolumeConstraint (tetrig/volume_constraint.hpp): the enclosed volume of x_fine = B x and its
// linearization in the tet-mesh positions, against a cube of known volume and finite differences.
#include "tetrig/volume_constraint.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <stdexcept>
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
  for (std::size_t i = 0; i < x.size(); ++i) {
    std::vector<double> up = x, down = x;
    up[i] += h;
    down[i] -= h;
    const double fd = (work.volume(fineOf(b, up).data()) - work.volume(fineOf(b, down).data())) / (2 * h);
    EXPECT_NEAR(g[i], fd, 1e-6 * (1.0 + std::abs(fd))) << "component " << i;  // B^T: float weights and sums
  }
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
  // dV/dx_fine by central differences.
  const double h = 1e-5;
  std::vector<double> d(24);
  for (std::size_t i = 0; i < 24; ++i) {
    std::vector<double> up = fine, down = fine;
    up[i] += h;
    down[i] -= h;
    d[i] = (exact.volume(up.data()) - exact.volume(down.data())) / (2 * h);
  }
  std::vector<double> expected(15, 0.0);
  double differs = 0.0;
  for (int r = 0; r < 8; ++r) {
    const int begin = b.offsets[r];
    int smallest = begin;  // of 3 entries, the cut drops the smallest
    for (int k = begin; k < begin + 3; ++k) smallest = b.weights[k] < b.weights[smallest] ? k : smallest;
    const double kept = 1.0 - b.weights[smallest];  // rows sum to 1
    for (int k = begin; k < begin + 3; ++k) {
      if (k == smallest) continue;
      for (int c = 0; c < 3; ++c) expected[3 * b.columns[k] + c] += b.weights[k] / kept * d[3 * r + c];
    }
  }
  for (std::size_t i = 0; i < 15; ++i) {
    EXPECT_NEAR(g_cut[i], expected[i], 1e-6 * (1.0 + std::abs(expected[i]))) << "component " << i;  // float weights
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

}  // namespace
}  // namespace tetrig
