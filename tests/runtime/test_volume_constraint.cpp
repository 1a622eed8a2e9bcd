// FineVolumeConstraint (tetrig/volume_constraint.hpp): the enclosed volume of x_fine = B x, held by
// a linear constraint whose direction is the gradient of the volume the body tets' boundary
// encloses; against a cube of known volume, finite differences and the boundary built by hand.
#include "tetrig/volume_constraint.hpp"

#include "tetrig/pose_transfer.hpp"

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

// The tet mesh: the cube of side 2 cut into 6 tets around its diagonal 0-7 (Kuhn), their corners
// in both orientations, and a "marker" vertex 8 outside joined to face 1-3-7 by a seventh tet that
// is not the body's.
TetMesh cubeTets() {
  TetMesh m;
  m.vertices.resize(9, 3);
  const std::vector<double> x = cube(2.0);
  for (int v = 0; v < 8; ++v) m.vertices.row(v) = Eigen::Vector3d(x[3 * v], x[3 * v + 1], x[3 * v + 2]).transpose();
  m.vertices.row(8) = Eigen::Vector3d(3.0, 1.0, 1.0).transpose();
  m.tets.resize(7, 4);
  m.tets << 0, 1, 3, 7,  0, 3, 2, 7,  0, 2, 6, 7,  0, 6, 4, 7,  0, 4, 5, 7,  0, 5, 1, 7,  1, 3, 7, 8;
  m.tets.row(2) << 0, 6, 2, 7;  // the other orientation: the boundary must still face out
  return m;
}

std::vector<double> positionsOf(const Vertices& v) {
  std::vector<double> x;
  for (Eigen::Index i = 0; i < v.rows(); ++i)
    for (int c = 0; c < 3; ++c) x.push_back(v(i, c));
  return x;
}

// A row-stochastic 8 x 9 B (each fine corner a blend of 3 tet vertices, the marker's never).
struct Blend {
  std::vector<std::int32_t> offsets, columns;
  std::vector<double> weights;
  PoseTransferView<double> view() const { return {offsets.data(), columns.data(), weights.data(), 8, 9}; }
};

Blend randomBlend(std::mt19937& rng) {
  Blend b;
  std::uniform_real_distribution<double> u(0.1, 1.0);
  b.offsets.push_back(0);
  for (int r = 0; r < 8; ++r) {
    const double w[3] = {u(rng), u(rng), u(rng)};
    for (int k = 0; k < 3; ++k) {
      b.columns.push_back((r + 3 * k) % 8);
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

TEST(FineVolumeConstraint, TheBoundaryIsTheBodysOutwardFaces) {
  const TetMesh m = cubeTets();
  const FineVolumeConstraint constraint(m, 6, kCubeTriangles, cube(2.0));
  const std::span<const std::int32_t> boundary = constraint.boundaryTriangles();
  // The 12 faces of the cube (the 12 inner faces are shared by two tets), none with vertex 8.
  ASSERT_EQ(boundary.size(), 36u);
  EXPECT_TRUE(std::none_of(boundary.begin(), boundary.end(), [](std::int32_t v) { return v == 8; }));
  EXPECT_TRUE(closedOrientedSurface(boundary));
  // Outward, so the volume it encloses is the cube's.
  const std::vector<double> x = positionsOf(m.vertices);
  EXPECT_NEAR(enclosedVolume(boundary, x.data()), 8.0, 1e-12);
  // With the marker's tet counted as the body's, its three outer faces replace face 1-3-7.
  const FineVolumeConstraint with_marker(m, 7, kCubeTriangles, cube(2.0));
  EXPECT_EQ(with_marker.boundaryTriangles().size(), 42u);
  EXPECT_NEAR(enclosedVolume(with_marker.boundaryTriangles(), x.data()), 8.0 + 2.0 / 3.0, 1e-12);
}

TEST(FineVolumeConstraint, TheFineVolumeAndTheBoundarysGradient) {
  std::mt19937 rng(7);
  const Blend b = randomBlend(rng);
  const TetMesh m = cubeTets();
  FineVolumeConstraint constraint(m, 6, kCubeTriangles, cube(2.0));
  EXPECT_NEAR(constraint.restVolume(), 8.0, 1e-12);  // the fine mesh's, outward triangles: positive
  EXPECT_NEAR(constraint.volume(cube(3.0).data()), 27.0, 1e-12);

  std::uniform_real_distribution<double> u(-0.3, 0.3);
  std::vector<double> x = positionsOf(m.vertices);
  for (double& v : x) v += u(rng);
  const std::vector<double> fine = fineOf(b, x);
  std::vector<double> g(27);
  double now = 0.0;
  const double c = constraint.linearize(x, fine.data(), g, &now);
  EXPECT_NEAR(now, constraint.volume(fine.data()), 1e-12);
  // g is dW/dx, W the boundary's volume: central differences (W is cubic in x: exact up to rounding).
  const double h = 1e-5;
  for (std::size_t i = 0; i < x.size(); ++i) {
    std::vector<double> up = x, down = x;
    up[i] += h;
    down[i] -= h;
    const double fd = (enclosedVolume(constraint.boundaryTriangles(), up.data()) - enclosedVolume(constraint.boundaryTriangles(), down.data())) / (2 * h);
    EXPECT_NEAR(g[i], fd, 1e-8) << "component " << i;
  }
  for (std::size_t i = 24; i < 27; ++i) EXPECT_EQ(g[i], 0.0);  // the marker vertex is no body boundary's
  // c = V_rest - V(x_fine0) + g . x0, from the fine volume: a pose on the plane g . x = c keeps the
  // fine rest volume to first order along g.
  double gx = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) gx += g[i] * x[i];
  EXPECT_NEAR(c, 8.0 - now + gx, 1e-12);
  EXPECT_NEAR(constraint.value(x, fine.data(), g), c, 1e-12);
  // value() at a moved pose: the measured fine volume there, with the same g.
  std::vector<double> moved = x;
  for (double& v : moved) v *= 1.1;
  const std::vector<double> moved_fine = fineOf(b, moved);
  double g_moved = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) g_moved += g[i] * moved[i];
  EXPECT_NEAR(constraint.value(moved, moved_fine.data(), g), 8.0 - constraint.volume(moved_fine.data()) + g_moved, 1e-12);
}

TEST(FineVolumeConstraint, RefusesWhatDoesNotMatch) {
  const TetMesh m = cubeTets();
  EXPECT_THROW(FineVolumeConstraint(m, 6, kCubeTriangles, std::vector<double>(23, 0.0)), std::invalid_argument);
  EXPECT_THROW(FineVolumeConstraint(m, 6, kCubeTriangles, std::vector<double>(21, 0.0)), std::invalid_argument);
  std::vector<std::int32_t> out_of_range = kCubeTriangles;
  out_of_range[4] = 8;
  EXPECT_THROW(FineVolumeConstraint(m, 6, out_of_range, cube(1.0)), std::invalid_argument);
  EXPECT_THROW(FineVolumeConstraint(m, 6, std::vector<std::int32_t>{0, 1}, cube(1.0)), std::invalid_argument);
  EXPECT_THROW(FineVolumeConstraint(m, 0, kCubeTriangles, cube(1.0)), std::invalid_argument);
  EXPECT_THROW(FineVolumeConstraint(m, 8, kCubeTriangles, cube(1.0)), std::invalid_argument);
  TetMesh bad = m;
  bad.tets(1, 2) = 9;
  EXPECT_THROW(FineVolumeConstraint(bad, 6, kCubeTriangles, cube(1.0)), std::invalid_argument);
}

// The fine volume is measured on a closed, consistently oriented surface only (else it is not the
// volume the mesh encloses and depends on the origin): an open or misoriented fine mesh is refused
// when the constraint is built.
TEST(FineVolumeConstraint, RefusesAnOpenOrMisorientedMesh) {
  const TetMesh m = cubeTets();
  std::vector<std::int32_t> open(kCubeTriangles.begin(), kCubeTriangles.end() - 3);
  std::vector<std::int32_t> flipped = kCubeTriangles;
  std::swap(flipped[7], flipped[8]);
  for (const auto& triangles : {open, flipped}) {
    try {
      FineVolumeConstraint constraint(m, 6, triangles, cube(1.0));
      ADD_FAILURE() << "accepted a mesh that does not close";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("not closed and consistently oriented"), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(FineVolumeConstraint(m, 6, kCubeTriangles, cube(1.0)));
}

// A small closed mesh far from the origin (an icosahedron of radius 0.05 at 500 units), the fine
// pose in float as the live rig has it, the tet mesh its 20 faces joined to its centre: g and the
// volume against double arithmetic on the same (float-rounded) positions taken about the centre,
// where finite differences are exact enough. Products of whole positions would lose ~6 digits here
// (|a . (b x c)| ~ 10^8 against a volume of 5e-4); edges and a vertex of the mesh as the origin
// keep them.
TEST(FineVolumeConstraint, TheVolumeAndItsDirectionHoldFarFromTheOrigin) {
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
  // The tet mesh: the 12 fine vertices and the centre (vertex 12), a tet per face.
  TetMesh ball;
  ball.vertices.resize(13, 3);
  for (int v = 0; v < 12; ++v) ball.vertices.row(v) = Eigen::Vector3d(local[3 * v], local[3 * v + 1], local[3 * v + 2]).transpose();
  ball.vertices.row(12).setZero();
  ball.tets.resize(20, 4);
  for (int f = 0; f < 20; ++f) ball.tets.row(f) << faces[3 * f], faces[3 * f + 1], faces[3 * f + 2], 12;
  FineVolumeConstraint constraint(ball, 20, faces, local);
  const double volume = constraint.volume(local.data());
  ASSERT_GT(volume, 1e-4);  // outward faces: about 2.5e-4 * 2.18
  std::vector<double> x_tet(fine);
  x_tet.insert(x_tet.end(), centre, centre + 3);
  std::vector<double> g(39);
  double now = 0.0;
  constraint.linearize(x_tet, fine_f.data(), g, &now);
  EXPECT_NEAR(now, volume, 1e-9 * volume);
  // The boundary is the fine mesh here: g is dV/dx_fine, and 0 at the centre.
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
  for (std::size_t i = 0; i < 36; ++i) EXPECT_NEAR(g[i], expected[i], 1e-7 * largest) << "component " << i;
  for (std::size_t i = 36; i < 39; ++i) EXPECT_EQ(g[i], 0.0);
}

}  // namespace
}  // namespace tetrig
