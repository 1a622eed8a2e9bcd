// The deformation core's load step and frame step: Stoll et al. 2007, sections 2.3.1-2.3.2.
#include "tetrig/deformer_impl.hpp"
#include "tetrig/rotation_prediction.hpp"

#include "tetrig/laplacian.hpp"
#include "tetrig/rigid_groups.hpp"
#include "tetrig/rotation_interpolation.hpp"
#include "padded_dot.hpp"

#include <algorithm>
#include <functional>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace tetrig {

namespace {

using Clock = std::chrono::steady_clock;

std::int64_t nanosecondsBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(b - a).count();
}

[[noreturn]] void fail(const std::string& what) { throw std::invalid_argument("deformer setup: " + what); }

void checkTetIndex(std::int32_t t, std::int32_t tet_count, const std::string& where) {
  if (t < 0 || t >= tet_count) {
    fail(where + " names tet " + std::to_string(t) + " but the mesh has " + std::to_string(tet_count) + " tets");
  }
}

}  // namespace

std::vector<double> tetVolumeWeights(const DeformerSetup& setup, std::int32_t tet_count) {
  const double floor = setup.options.volume_weight;
  if (!(floor >= 0.0 && floor < 1.0)) fail("volume_weight must be in [0, 1)");
  if (!setup.volume_weights.empty() && setup.volume_weights.size() != static_cast<size_t>(tet_count)) {
    fail("volume_weights has " + std::to_string(setup.volume_weights.size()) + " values for " + std::to_string(tet_count) + " tets");
  }
  std::vector<double> w(static_cast<size_t>(tet_count), setup.options.update_rotations ? floor : 0.0);
  for (size_t t = 0; t < setup.volume_weights.size(); ++t) {
    const double v = setup.volume_weights[t];
    if (!(v >= 0.0 && v < 1.0)) fail("volume weight of tet " + std::to_string(t) + " is not in [0, 1)");
    if (setup.options.update_rotations) w[t] = std::max(w[t], v);
  }
  for (const RigidGroup& g : setup.rigid_groups)
    for (const std::int32_t t : g.tets)
      if (t >= 0 && t < tet_count) w[static_cast<size_t>(t)] = 0.0;
  return w;
}

// Load time, in named steps: the options and the mesh checked, the handles' slots, the reduced
// Laplacian factored, the solver order and buffers, the handle coupling, the point handles, the tet
// blocks, the harmonic weights of rotation interpolation, the rigid groups and per-tet coefficients.
DeformerImpl::DeformerImpl(const TetMesh& mesh, const DeformerSetup& setup) : options_(setup.options) {
  vertex_count_ = mesh.vertexCount();
  tet_count_ = mesh.tetCount();
  if (tet_count_ == 0) fail("the mesh has no tets");
  checkOptions();
  checkMeshUsable(mesh);
  const std::vector<std::int32_t> handle_of_vertex = assignHandleSlots(mesh, setup);

  const TetRestFrames frames = computeRestFrames(mesh);
  const std::vector<double> weights = tetWeights(frames, setup.stiffness);
  const Eigen::SparseMatrix<double> laplacian = assembleLaplacian(mesh, frames, weights);
  std::vector<std::int32_t> free_index(static_cast<size_t>(vertex_count_), -1);
  for (std::int32_t v = 0, next = 0; v < vertex_count_; ++v) {
    if (handle_of_vertex[static_cast<size_t>(v)] < 0) free_index[static_cast<size_t>(v)] = next++;
  }
  factorReducedSystem(mesh, setup, laplacian, free_index);
  buildSolverOrder(mesh, handle_of_vertex, free_index);
  buildHandleCoupling(laplacian, handle_of_vertex, free_index);
  buildPointHandles(mesh, setup);
  buildTetBlocks(mesh, frames, weights);
  buildHarmonicWeights(mesh, setup, handle_of_vertex);
  buildRigidGroupsAndCoefficients(setup);

  if (options_.linear_constraint) {
    constraint_g_.assign(static_cast<size_t>(vertex_count_) * kVectorStride, 0.0);
    constraint_z_.assign(static_cast<size_t>(vertex_count_) * kVectorStride, 0.0);
  }
  vertex_targets_.resize(static_cast<size_t>(vertex_handle_count_));
  region_targets_.resize(setup.region_handles.size());
  point_targets_.resize(setup.point_handles.size());
  reset();
}

// Every option in its range (messages name the option and the range).
void DeformerImpl::checkOptions() {
  if (options_.rotation_steps < 0 || options_.rotation_steps > 64) fail("rotation_steps must be in [0, 64]");
  if (!(options_.rotation_extrapolation >= 0.0 && options_.rotation_extrapolation <= 1.0)) {
    fail("rotation_extrapolation must be in [0, 1]");
  }
  if (!(options_.volume_weight >= 0.0 && options_.volume_weight < 1.0)) fail("volume_weight must be in [0, 1)");
  if (options_.inversion_guard_solves < 0 || options_.inversion_guard_solves > 64) fail("inversion_guard_solves must be in [0, 64]");
  if (options_.inversion_guard_solves > 0) {
    if (!(options_.inversion_guard >= 0.0 && options_.inversion_guard <= kImplicitGuardMaxK)) {
      fail("inversion_guard must be in [0, " + std::to_string(static_cast<int>(kImplicitGuardMaxK)) + "] when implicit");
    }
  } else if (!(options_.inversion_guard >= 0.0 && options_.inversion_guard <= 1.0)) {
    fail("inversion_guard must be in [0, 1] (explicit; larger with inversion_guard_solves)");
  }
  if (!(options_.inversion_guard_threshold > 0.0 && options_.inversion_guard_threshold <= 1.0)) {
    fail("inversion_guard_threshold must be in (0, 1]");
  }
  if (!(options_.rotation_relaxation >= 1.0 && options_.rotation_relaxation < 2.0)) {
    fail("rotation_relaxation must be in [1, 2)");
  }
  if (!(options_.rotation_extrapolation_max_deg > 0.0 && options_.rotation_extrapolation_max_deg <= 180.0)) {
    fail("rotation_extrapolation_max_deg must be in (0, 180]");
  }
  extrapolation_max_sin_half_ = static_cast<float>(std::sin(0.5 * options_.rotation_extrapolation_max_deg * M_PI / 180.0));
}

// No out-of-range index, repeated corner, degenerate tet or non-finite vertex.
void DeformerImpl::checkMeshUsable(const TetMesh& mesh) {
  const TetMeshReport report = checkTetMesh(mesh);
  if (report.out_of_range_indices > 0 || report.repeated_corner_tets > 0 || report.degenerate_tets > 0 ||
      report.non_finite_vertices > 0) {
    fail("the tet mesh is not usable: " + report.summary());
  }
}

// Handle slots: the vertex handles first, then every corner of each region handle's tets (shared
// corners once per region). Returns each mesh vertex's slot, -1 for a free vertex.
std::vector<std::int32_t> DeformerImpl::assignHandleSlots(const TetMesh& mesh, const DeformerSetup& setup) {
  std::vector<std::int32_t> handle_of_vertex(static_cast<size_t>(vertex_count_), -1);
  auto add_handle = [&](std::int32_t v, std::int32_t region, const std::string& where) {
    if (v < 0 || v >= vertex_count_) {
      fail(where + " names vertex " + std::to_string(v) + " but the mesh has " + std::to_string(vertex_count_) +
           " vertices");
    }
    const std::int32_t existing = handle_of_vertex[static_cast<size_t>(v)];
    if (existing >= 0) {
      if (region >= 0 && handle_region_[static_cast<size_t>(existing)] == region) return;  // shared by two tets
      fail(where + " constrains vertex " + std::to_string(v) + ", which another handle already constrains");
    }
    handle_of_vertex[static_cast<size_t>(v)] = static_cast<std::int32_t>(handle_vertex_.size());
    handle_vertex_.push_back(v);
    handle_region_.push_back(region);
  };
  for (size_t i = 0; i < setup.vertex_handles.size(); ++i) {
    add_handle(setup.vertex_handles[i], -1, "vertex handle " + std::to_string(i));
  }
  vertex_handle_count_ = static_cast<std::int32_t>(handle_vertex_.size());
  for (size_t r = 0; r < setup.region_handles.size(); ++r) {
    const auto& region = setup.region_handles[r];
    if (region.tets.empty()) fail("region handle " + std::to_string(r) + " has no tets");
    for (auto t : region.tets) {
      checkTetIndex(t, tet_count_, "region handle " + std::to_string(r));
      for (int c = 0; c < 4; ++c)
        add_handle(mesh.tets(t, c), static_cast<std::int32_t>(r), "region handle " + std::to_string(r));
    }
  }
  handle_count_ = static_cast<std::int32_t>(handle_vertex_.size());
  free_count_ = vertex_count_ - handle_count_;
  if (handle_count_ == 0 && setup.point_handles.empty()) {
    fail("no handles: give at least one vertex, region or point handle (a mesh with nothing fixed can float anywhere)");
  }
  return handle_of_vertex;
}

// The Laplacian restricted to the free vertices, plus the point handles' soft terms
// lambda b_a b_b, factored (split LDL^T).
void DeformerImpl::factorReducedSystem(const TetMesh& mesh, const DeformerSetup& setup, const Eigen::SparseMatrix<double>& laplacian,
                                       const std::vector<std::int32_t>& free_index) {
  const double mean_diagonal = laplacian.diagonal().mean();
  point_lambda_ = options_.point_handle_weight * mean_diagonal;
  std::vector<Eigen::Triplet<double>> reduced;
  reduced.reserve(static_cast<size_t>(laplacian.nonZeros()));
  for (Eigen::Index col = 0; col < laplacian.outerSize(); ++col) {
    const std::int32_t fc = free_index[static_cast<size_t>(col)];
    if (fc < 0) continue;
    for (Eigen::SparseMatrix<double>::InnerIterator it(laplacian, col); it; ++it) {
      const std::int32_t fr = free_index[static_cast<size_t>(it.row())];
      if (fr >= 0) reduced.emplace_back(fr, fc, it.value());
    }
  }
  for (size_t p = 0; p < setup.point_handles.size(); ++p) {
    const auto& point = setup.point_handles[p];
    checkTetIndex(point.tet, tet_count_, "point handle " + std::to_string(p));
    if (!point.barycentric.allFinite() || std::abs(point.barycentric.sum() - 1.0) > 1e-6) {
      fail("point handle " + std::to_string(p) + " has barycentric weights that do not sum to 1");
    }
    for (int a = 0; a < 4; ++a) {
      const std::int32_t fa = free_index[static_cast<size_t>(mesh.tets(point.tet, a))];
      if (fa < 0) continue;
      for (int b = 0; b < 4; ++b) {
        const std::int32_t fb = free_index[static_cast<size_t>(mesh.tets(point.tet, b))];
        if (fb >= 0) reduced.emplace_back(fa, fb, point_lambda_ * point.barycentric[a] * point.barycentric[b]);
      }
    }
  }
  const auto factor_start = Clock::now();
  if (free_count_ > 0) {
    Eigen::SparseMatrix<double> a(free_count_, free_count_);
    a.setFromTriplets(reduced.begin(), reduced.end());
    factor_.factorize(a);
  }
  factorize_seconds_ = std::chrono::duration<double>(Clock::now() - factor_start).count();

}

// Solver order (free vertices at their factor positions, then handle slots) and the per-frame
// buffers laid out in it.
void DeformerImpl::buildSolverOrder(const TetMesh& mesh, const std::vector<std::int32_t>& handle_of_vertex,
                                    const std::vector<std::int32_t>& free_index) {
  solver_index_.resize(static_cast<size_t>(vertex_count_));
  mesh_vertex_.resize(static_cast<size_t>(vertex_count_));
  for (std::int32_t v = 0; v < vertex_count_; ++v) {
    const std::int32_t h = handle_of_vertex[static_cast<size_t>(v)];
    solver_index_[static_cast<size_t>(v)] =
        h >= 0 ? free_count_ + h : factor_.position(free_index[static_cast<size_t>(v)]);
    mesh_vertex_[static_cast<size_t>(solver_index_[static_cast<size_t>(v)])] = v;
  }
  const auto n3 = static_cast<size_t>(vertex_count_) * 3;
  const auto n4 = static_cast<size_t>(vertex_count_) * kVectorStride;  // x, y, z, 0 per vertex
  rest_solver_.assign(n4, 0.0);
  for (std::int32_t v = 0; v < vertex_count_; ++v)
    for (int c = 0; c < 3; ++c)
      rest_solver_[kVectorStride * static_cast<size_t>(solver_index_[static_cast<size_t>(v)]) + static_cast<size_t>(c)] =
          mesh.vertices(v, c);
  u_.assign(n4, 0.0);
  delta_.assign(n4, 0.0f);
  rhs_constant_.assign(static_cast<size_t>(free_count_) * kVectorStride, 0.0);
  positions_.assign(n3, 0.0);
  if (options_.padded_positions) padded_positions_.assign(n4, 0.0);
  if (options_.padded_float_positions) padded_float_positions_.assign(n4, 0.0f);

}

// The coupling -L_fh as CSR over the free rows (solver order) next to a handle.
void DeformerImpl::buildHandleCoupling(const Eigen::SparseMatrix<double>& laplacian, const std::vector<std::int32_t>& handle_of_vertex,
                                       const std::vector<std::int32_t>& free_index) {
  std::vector<std::vector<std::pair<std::int32_t, double>>> rows(static_cast<size_t>(free_count_));
  for (Eigen::Index col = 0; col < laplacian.outerSize(); ++col) {
    const std::int32_t h = handle_of_vertex[static_cast<size_t>(col)];
    if (h < 0) continue;
    for (Eigen::SparseMatrix<double>::InnerIterator it(laplacian, col); it; ++it) {
      const std::int32_t fr = free_index[static_cast<size_t>(it.row())];
      if (fr >= 0) rows[static_cast<size_t>(factor_.position(fr))].emplace_back(h, -it.value());
    }
  }
  // Only rows next to a handle: the others' -L_fh x_h is 0 and never changes.
  coupling_start_.push_back(0);
  for (std::int32_t i = 0; i < free_count_; ++i) {
    if (rows[static_cast<size_t>(i)].empty()) continue;
    coupling_row_.push_back(i);
    for (auto [h, value] : rows[static_cast<size_t>(i)]) {
      coupling_handle_.push_back(h);
      coupling_value_.push_back(value);
    }
    coupling_start_.push_back(static_cast<std::int32_t>(coupling_handle_.size()));
  }
}

// Point handles: corners in solver order, weights, rest positions p_rest = sum_c b_c x_rest_c.
void DeformerImpl::buildPointHandles(const TetMesh& mesh, const DeformerSetup& setup) {
  for (const auto& point : setup.point_handles) {
    Eigen::Vector3d rest = Eigen::Vector3d::Zero();
    for (int c = 0; c < 4; ++c) {
      point_corner_.push_back(solver_index_[static_cast<size_t>(mesh.tets(point.tet, c))]);
      point_weight_.push_back(point.barycentric[c]);
      rest += point.barycentric[c] * Eigen::Vector3d(mesh.vertices.row(mesh.tets(point.tet, c)).transpose());
    }
    point_rest_.push_back(rest);
  }

}

// Tets in blocks of kTetBlockWidth lanes, ordered by their lowest solver index (locality of the
// gathers and scatters): corners, rest frames and weights in float, identity rotations; padding
// lanes weigh 0.
void DeformerImpl::buildTetBlocks(const TetMesh& mesh, const TetRestFrames& frames, const std::vector<double>& weights) {
  std::vector<std::int32_t> order(static_cast<size_t>(tet_count_));
  std::iota(order.begin(), order.end(), 0);
  auto key = [&](std::int32_t t) {
    std::int32_t k = solver_index_[static_cast<size_t>(mesh.tets(t, 0))];
    for (int c = 1; c < 4; ++c) k = std::min(k, solver_index_[static_cast<size_t>(mesh.tets(t, c))]);
    return k;
  };
  std::stable_sort(order.begin(), order.end(), [&](std::int32_t a, std::int32_t b) { return key(a) < key(b); });
  const std::int32_t block_count = (tet_count_ + kTetBlockWidth - 1) / kTetBlockWidth;
  blocks_.assign(static_cast<size_t>(block_count), TetBlock{});
  exact_lanes_.assign(static_cast<size_t>(block_count), 0);
  if (options_.rotation_extrapolation > 0.0 || options_.frame_guide) {
    previous_rotation_.assign(static_cast<size_t>(block_count) * 4 * kTetBlockWidth, 0.0f);
  }
  if (options_.frame_guide) {
    guide_.assign(static_cast<size_t>(block_count) * 4 * kTetBlockWidth, 0.0f);
    for (size_t b = 0; b < static_cast<size_t>(block_count); ++b)
      std::fill_n(&guide_[4 * b * kTetBlockWidth], kTetBlockWidth, 1.0f);  // w = 1: identity
  }
  tet_slot_.assign(static_cast<size_t>(tet_count_), -1);
  for (std::int32_t b = 0; b < block_count; ++b) {
    TetBlock& block = blocks_[static_cast<size_t>(b)];
    for (int l = 0; l < kTetBlockWidth; ++l) {
      const std::int32_t s = b * kTetBlockWidth + l;
      block.rotation[0][l] = 1.0f;
      block.rotation[1][l] = block.rotation[2][l] = block.rotation[3][l] = 0.0f;
      if (s >= tet_count_) {  // padding lane: weight 0, identity frame, corners at vertex 0
        for (int c = 0; c < 4; ++c) block.corner_offset[c][l] = 0;
        for (int i = 0; i < 9; ++i) block.edge_inverse[i][l] = (i % 4 == 0) ? 1.0f : 0.0f;
        block.weight[l] = 0.0f;
        continue;
      }
      const std::int32_t t = order[static_cast<size_t>(s)];
      tet_slot_[static_cast<size_t>(t)] = s;
      for (int c = 0; c < 4; ++c)
        block.corner_offset[c][l] = kVectorStride * solver_index_[static_cast<size_t>(mesh.tets(t, c))];
      const Eigen::Matrix3d& e = frames.edge_inverse[static_cast<size_t>(t)];
      for (int i = 0; i < 9; ++i) block.edge_inverse[i][l] = static_cast<float>(e(i / 3, i % 3));
      block.weight[l] = static_cast<float>(weights[static_cast<size_t>(t)]);
      // The per-tet pass stores the rest frame in float (rotation_kernel.hpp).
      bool in_range = std::isfinite(block.weight[l]) && block.weight[l] >= std::numeric_limits<float>::min();
      for (int i = 0; i < 9; ++i) in_range = in_range && std::isfinite(block.edge_inverse[i][l]);
      if (!in_range) {
        char volume[32];
        std::snprintf(volume, sizeof volume, "%.3g", frames.volume[static_cast<size_t>(t)]);
        fail("tet " + std::to_string(t) + " (volume " + volume +
             ") is out of float range: its weight or inverse edge matrix does not fit in a float "
             "(about 1e-38 to 3e38); rescale the mesh to units where tets are between about 1e-9 and "
             "1e9 across");
      }
    }
  }
  if (options_.frame_guide) {
    // The frame guide's default sources: every tet its own row (setFrameGuideSources changes them).
    std::vector<std::int32_t> own(static_cast<size_t>(tet_count_));
    std::iota(own.begin(), own.end(), 0);
    setFrameGuideSources(own, tet_count_);
  }
}

// Rotation interpolation: harmonic weights per oriented region handle, 0 on tets touching another
// handle (slot order).
void DeformerImpl::buildHarmonicWeights(const TetMesh& mesh, const DeformerSetup& setup, const std::vector<std::int32_t>& handle_of_vertex) {
  const auto block_count = static_cast<std::int32_t>(blocks_.size());
  std::vector<std::vector<std::int32_t>> oriented_tets;
  for (size_t r = 0; r < setup.region_handles.size(); ++r) {
    if (setup.region_handles[r].oriented) {
      oriented_regions_.push_back(static_cast<std::int32_t>(r));
      oriented_tets.push_back(setup.region_handles[r].tets);
    }
  }
  if (options_.interpolate_rotations && options_.update_rotations && !oriented_regions_.empty()) {
    std::vector<std::int32_t> zero_tets;
    for (std::int32_t t = 0; t < tet_count_; ++t) {
      for (int c = 0; c < 4; ++c) {
        const std::int32_t h = handle_of_vertex[static_cast<size_t>(mesh.tets(t, c))];
        if (h < 0) continue;
        const std::int32_t region = handle_region_[static_cast<size_t>(h)];
        if (region < 0 || !setup.region_handles[static_cast<size_t>(region)].oriented) {
          zero_tets.push_back(t);
          break;
        }
      }
    }
    const std::vector<double> mesh_order = harmonicTetWeights(mesh, oriented_tets, zero_tets);
    const auto slots = static_cast<size_t>(block_count) * kTetBlockWidth;
    harmonic_weights_.assign(oriented_regions_.size() * slots, 0.0);
    for (size_t h = 0; h < oriented_regions_.size(); ++h)
      for (std::int32_t t = 0; t < tet_count_; ++t)
        harmonic_weights_[h * slots + static_cast<size_t>(tet_slot_[static_cast<size_t>(t)])] =
            mesh_order[h * static_cast<size_t>(tet_count_) + static_cast<size_t>(t)];
    interpolated_rotation_.assign(oriented_regions_.size(), Eigen::Quaterniond::Identity());
    rotation_increment_.assign(oriented_regions_.size(), Eigen::Quaterniond::Identity());
  }

}

// Rigid groups (CSR over slots), then the rotation pass's per-slot coefficients: volume-term weights
// and the inversion guard's k (0 in rigid groups), with the implicit guard's buffers.
void DeformerImpl::buildRigidGroupsAndCoefficients(const DeformerSetup& setup) {
  const auto block_count = static_cast<std::int32_t>(blocks_.size());
  std::vector<char> grouped(static_cast<size_t>(tet_count_), 0);
  group_start_.push_back(0);
  for (size_t g = 0; g < setup.rigid_groups.size(); ++g) {
    for (auto t : setup.rigid_groups[g].tets) {
      checkTetIndex(t, tet_count_, "rigid group " + std::to_string(g));
      if (grouped[static_cast<size_t>(t)]) fail("tet " + std::to_string(t) + " is in two rigid groups");
      grouped[static_cast<size_t>(t)] = 1;
      group_slot_.push_back(slotOfTet(t));
    }
    group_start_.push_back(static_cast<std::int32_t>(group_slot_.size()));
  }
  // Per-slot coefficients of the rotation pass: `value` on the first `count` tets that are in no
  // rigid group, 0 on the others and on the padding lanes.
  const auto perSlot = [&](AlignedVector<float>& slots, double value, std::int32_t count) {
    slots.assign(static_cast<size_t>(block_count) * kTetBlockWidth, 0.0f);
    for (std::int32_t t = 0; t < count; ++t)
      if (!grouped[static_cast<size_t>(t)]) slots[static_cast<size_t>(slotOfTet(t))] = static_cast<float>(value);
  };
  if (const std::vector<double> w = tetVolumeWeights(setup, tet_count_); std::any_of(w.begin(), w.end(), [](double x) { return x > 0.0; })) {
    volume_weight_.assign(static_cast<size_t>(block_count) * kTetBlockWidth, 0.0f);
    for (std::int32_t t = 0; t < tet_count_; ++t) volume_weight_[static_cast<size_t>(slotOfTet(t))] = static_cast<float>(w[static_cast<size_t>(t)]);
  }
  if (options_.inversion_guard > 0.0 && options_.update_rotations) {
    perSlot(guard_, options_.inversion_guard,
            setup.guarded_tet_count < 0 ? tet_count_ : std::min(setup.guarded_tet_count, tet_count_));
    if (options_.inversion_guard_solves > 0) {
      const auto guarded = static_cast<size_t>(std::count_if(guard_.begin(), guard_.end(), [](float k) { return k > 0.0f; }));
      guarded_.assign(guarded, GuardedTet{});
      guard_det_.assign(guard_.size(), 1.0f);
      guard_blocks_.assign(blocks_.size(), 0);
      if (options_.untangle) buildUntangleAdjacency();
      for (AlignedVector<double>* v : {&cg_r_, &cg_z_, &cg_p_, &cg_lp_})
        v->assign(static_cast<size_t>(vertex_count_) * kVectorStride, 0.0);
      cg_float_.assign(static_cast<size_t>(vertex_count_) * kVectorStride, 0.0f);
      guard_corners_.assign(4 * guarded, 0);
      guard_corner_mark_.assign(static_cast<size_t>(vertex_count_), 0);
      if (free_count_ > 0) factor_.prepareFloatSolve();
    }
  }

}

void DeformerImpl::reset() {
  for (auto& block : blocks_) {
    for (int l = 0; l < kTetBlockWidth; ++l) {
      block.rotation[0][l] = 1.0f;
      block.rotation[1][l] = block.rotation[2][l] = block.rotation[3][l] = 0.0f;
    }
  }
  std::fill(u_.begin(), u_.end(), 0.0);
  guarded_count_ = 0;
  guard_corner_count_ = 0;
  for (std::int32_t h = 0; h < vertex_handle_count_; ++h) {
    const double* p = &rest_solver_[kVectorStride * static_cast<size_t>(free_count_ + h)];
    vertex_targets_[static_cast<size_t>(h)] = Eigen::Vector3d(p[0], p[1], p[2]);
  }
  for (auto& region : region_targets_) region = RigidTransform{};
  guide_pending_ = false;
  std::copy(point_rest_.begin(), point_rest_.end(), point_targets_.begin());
  for (auto& q : interpolated_rotation_) q = Eigen::Quaterniond::Identity();
  constraint_active_ = false;
  rememberRotations();
  rebuildDelta();
  updateConstantRhs();
  writePositions();
}


void DeformerImpl::rememberRotations() {
  if (previous_rotation_.empty()) return;
  for (size_t b = 0; b < blocks_.size(); ++b) {
    for (int c = 0; c < 4; ++c) {
      std::copy_n(blocks_[b].rotation[c], kTetBlockWidth, &previous_rotation_[(4 * b + static_cast<size_t>(c)) * kTetBlockWidth]);
    }
  }
}

bool DeformerImpl::acceptTargets(const HandleTargets& targets, std::uint32_t& flags) {
  if (targets.vertex_positions.size() != static_cast<size_t>(vertex_handle_count_) ||
      targets.region_transforms.size() != region_targets_.size() ||
      targets.point_positions.size() != point_targets_.size()) {
    flags |= kStepTargetsWrongSize;
    return false;
  }
  const double limit = options_.max_abs_coordinate;
  auto sane = [limit](const Eigen::Vector3d& v) {
    return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]) && std::abs(v[0]) <= limit &&
           std::abs(v[1]) <= limit && std::abs(v[2]) <= limit;
  };
  for (const auto& v : targets.vertex_positions)
    if (!sane(v)) {
      flags |= kStepTargetsRejected;
      return false;
    }
  for (const auto& v : targets.point_positions)
    if (!sane(v)) {
      flags |= kStepTargetsRejected;
      return false;
    }
  for (const auto& t : targets.region_transforms) {
    const double norm = t.rotation.norm();
    if (!sane(t.translation) || !std::isfinite(norm) || norm < 1e-6) {
      flags |= kStepTargetsRejected;
      return false;
    }
  }
  std::copy(targets.vertex_positions.begin(), targets.vertex_positions.end(), vertex_targets_.begin());
  std::copy(targets.point_positions.begin(), targets.point_positions.end(), point_targets_.begin());
  for (size_t r = 0; r < region_targets_.size(); ++r) {
    region_targets_[r] = targets.region_transforms[r];
    region_targets_[r].rotation.normalize();
  }
  return true;
}

void DeformerImpl::updateConstantRhs() {
  // Handle displacements (target - rest) into the handle slots of u.
  for (std::int32_t h = 0; h < handle_count_; ++h) {
    double* out = &u_[kVectorStride * static_cast<size_t>(free_count_ + h)];
    const double* rest = &rest_solver_[kVectorStride * static_cast<size_t>(free_count_ + h)];
    const Eigen::Vector3d r(rest[0], rest[1], rest[2]);
    const std::int32_t region = handle_region_[static_cast<size_t>(h)];
    Eigen::Vector3d p;
    if (region < 0) {
      p = vertex_targets_[static_cast<size_t>(h)];
    } else {
      const RigidTransform& t = region_targets_[static_cast<size_t>(region)];
      p = t.rotation * r + t.translation;
    }
    out[0] = p[0] - r[0];
    out[1] = p[1] - r[1];
    out[2] = p[2] - r[2];
  }
  // Rows that take point terms start again from 0 (the coupling loop below overwrites its rows).
  for (const std::int32_t s : point_corner_) {
    if (s < free_count_) std::fill_n(&rhs_constant_[kVectorStride * static_cast<size_t>(s)], 3, 0.0);
  }
  // -L_fh u_h, on the rows next to a handle (0 elsewhere, and never changes there).
  const double* handles = u_.data() + kVectorStride * static_cast<size_t>(free_count_);
  for (size_t r = 0; r < coupling_row_.size(); ++r) {
    const auto i = static_cast<size_t>(coupling_row_[r]);
    double s0 = 0.0, s1 = 0.0, s2 = 0.0;
    for (auto p = coupling_start_[r]; p < coupling_start_[r + 1]; ++p) {
      const double* xh = handles + kVectorStride * coupling_handle_[static_cast<size_t>(p)];
      const double value = coupling_value_[static_cast<size_t>(p)];
      s0 += value * xh[0];
      s1 += value * xh[1];
      s2 += value * xh[2];
    }
    rhs_constant_[kVectorStride * i] = s0;
    rhs_constant_[kVectorStride * i + 1] = s1;
    rhs_constant_[kVectorStride * i + 2] = s2;
  }
  // Point handles: lambda b_a (p - p_rest - sum_{handle corners h} b_h u_h) for each free corner a.
  for (size_t p = 0; p < point_targets_.size(); ++p) {
    Eigen::Vector3d target = point_targets_[p] - point_rest_[p];
    for (int c = 0; c < 4; ++c) {
      const std::int32_t s = point_corner_[4 * p + static_cast<size_t>(c)];
      if (s >= free_count_) {
        const double* uh = &u_[kVectorStride * static_cast<size_t>(s)];
        target -= point_weight_[4 * p + static_cast<size_t>(c)] * Eigen::Vector3d(uh[0], uh[1], uh[2]);
      }
    }
    for (int c = 0; c < 4; ++c) {
      const std::int32_t s = point_corner_[4 * p + static_cast<size_t>(c)];
      if (s >= free_count_) continue;
      const double w = point_lambda_ * point_weight_[4 * p + static_cast<size_t>(c)];
      for (int k = 0; k < 3; ++k) rhs_constant_[kVectorStride * static_cast<size_t>(s) + static_cast<size_t>(k)] += w * target[k];
    }
  }
}

bool DeformerImpl::interpolateRotations() {
  if (harmonic_weights_.empty()) return false;
  bool any = false;
  for (size_t k = 0; k < oriented_regions_.size(); ++k) {
    const Eigen::Quaterniond& target = region_targets_[static_cast<size_t>(oriented_regions_[k])].rotation;
    Eigen::Quaterniond increment = target * interpolated_rotation_[k].conjugate();
    if (increment.w() < 0.0) increment.coeffs() = -increment.coeffs();
    increment.normalize();
    rotation_increment_[k] = increment;
    any = any || (1.0 - increment.w()) > 1e-15;
    interpolated_rotation_[k] = target;
  }
  if (!any) return false;
  applyRotationIncrements(harmonic_weights_, rotation_increment_, blocks_.data(),
                          static_cast<std::int32_t>(blocks_.size()) * kTetBlockWidth);
  return true;
}

void DeformerImpl::rebuildDelta() {
  delta_stale_ = false;
  std::fill(delta_.begin(), delta_.end(), 0.0f);
  differentialPass(blocks_.data(), static_cast<std::int32_t>(blocks_.size()), delta_.data(), u_.data(), volumeWeights(),
                   guard(), static_cast<float>(options_.inversion_guard_threshold));
}

void DeformerImpl::writePositions() {
  // Solver order: u and x_rest are read sequentially (the prefetchers follow; in mesh order the
  // reads were random and, after the rotation pass has streamed its blocks through the caches,
  // missed: measured ~8 % of a bar_8x8x85 step), the writes scatter.
  for (std::int32_t s = 0; s < vertex_count_; ++s) {
    const auto i = kVectorStride * static_cast<size_t>(s);
    double* out = &positions_[3 * static_cast<size_t>(mesh_vertex_[static_cast<size_t>(s)])];
    for (size_t c = 0; c < 3; ++c) out[c] = rest_solver_[i + c] + u_[i + c];
  }
  // The padded copies (double and/or float; empty when not asked for), (x, y, z, 0) per vertex.
  const auto mirror = [this](auto& padded) {
    using T = typename std::decay_t<decltype(padded)>::value_type;
    if (padded.empty()) return;
    for (std::int32_t v = 0; v < vertex_count_; ++v) {
      const double* out = &positions_[3 * static_cast<size_t>(v)];
      T* p = &padded[kVectorStride * static_cast<size_t>(v)];
      for (int c = 0; c < 3; ++c) p[c] = static_cast<T>(out[c]);
    }
  };
  mirror(padded_positions_);
  mirror(padded_float_positions_);
}

bool DeformerImpl::setLinearConstraint(std::span<const double> g, double c, ConstraintDirection direction) noexcept {
  const bool had_constraint = constraint_active_;
  constraint_active_ = false;
  if (!had_constraint) constraint_mu_ = 0.0;  // a new constraint's multiplier starts from 0
  const bool keep = direction == ConstraintDirection::kKeep;
  if (keep && !had_constraint) return false;  // no z to keep
  if (constraint_g_.empty() || g.size() != 3 * static_cast<size_t>(vertex_count_) || !std::isfinite(c)) return false;
  for (std::int32_t s = 0; s < vertex_count_; ++s) {
    const double* gv = &g[3 * static_cast<size_t>(mesh_vertex_[static_cast<size_t>(s)])];
    double* out = &constraint_g_[kVectorStride * static_cast<size_t>(s)];
    for (size_t k = 0; k < 3; ++k) out[k] = gv[k];  // the pad lane stays 0
  }
  const double rest_dot = dot(constraint_g_.data(), rest_solver_.data(), constraint_g_.size());
  const size_t free4 = static_cast<size_t>(free_count_) * kVectorStride;
  if (!keep) {
    std::copy_n(constraint_g_.data(), free4, constraint_z_.data());
    // g is zero but at the body boundary's vertices: the forward pass skips the supernodes it does not reach.
    if (free_count_ > 0) factor_.solveInPlace(constraint_z_.data(), /*skip_zero_nodes=*/true);
  }
  const double gz = dot(constraint_g_.data(), constraint_z_.data(), free4);
  // L_ff is positive definite: g_f . z > 0 for z = L_ff^-1 g_f unless g_f = 0 (nothing free to
  // move), or not finite. A kept z (solved for an earlier g) can fail it where g has turned too far.
  if (!(gz > 0.0) || !std::isfinite(gz) || !std::isfinite(rest_dot)) return false;
  constraint_rest_dot_ = rest_dot;
  constraint_rhs_ = c - rest_dot;
  constraint_gz_ = gz;
  constraint_active_ = true;
  return true;
}

bool DeformerImpl::setLinearConstraintValue(double c) noexcept {
  if (!constraint_active_ || !std::isfinite(c)) return false;
  constraint_rhs_ = c - constraint_rest_dot_;
  return true;
}

void DeformerImpl::applyLinearConstraint() {
  // g . x = g . x_rest + g . u: the displacement part over every slot (free and handles). The solve
  // already carried the multiplier so far (mu g in its right-hand side): what is left of it moves u
  // along z, and adds to the multiplier.
  const double gu = dot(constraint_g_.data(), u_.data(), u_.size());
  const double mu_left = (constraint_rhs_ - gu) / constraint_gz_;
  addScaled(u_.data(), mu_left, constraint_z_.data(), static_cast<size_t>(free_count_) * kVectorStride);
  constraint_mu_ += mu_left;
}

StepStats DeformerImpl::step(const HandleTargets& targets, const StepBudget& budget) {
  StepStats stats;
  const auto start = Clock::now();
  acceptTargets(targets, stats.flags);
  updateConstantRhs();
  if (options_.update_rotations) {
    const auto t0 = Clock::now();
    bool turned = false;
    if (!previous_rotation_.empty() && !budget.continues_frame &&
        (options_.rotation_extrapolation > 0.0 || guide_pending_)) {
      // Temporal prediction: each tet carried on by its last frame's rotation, and the frame guide
      // composed in (rotation_prediction.hpp).
      predictFrameRotations(blocks_.data(), static_cast<std::int32_t>(blocks_.size()), previous_rotation_.data(),
                            guide_pending_ ? guide_.data() : nullptr, static_cast<float>(options_.rotation_extrapolation),
                            extrapolation_max_sin_half_);
      guide_pending_ = false;
      turned = true;
    }
    // The differential coordinates once, from the rotations both have turned.
    if (interpolateRotations() || turned || delta_stale_) rebuildDelta();
    stats.interpolation_ns += nanosecondsBetween(t0, Clock::now());
  }
  const auto block_count = static_cast<std::int32_t>(blocks_.size());
  const bool has_groups = !group_slot_.empty();
  // With the temporal prediction on, or oriented regions whose turns are interpolated over the
  // tets, the next frame turns the tets' rotations before its first solve and builds delta again
  // from the turned rotations: the last rotation pass of a frame then leaves delta out (it only
  // refines the rotations). The next step builds it in any case when it did not turn (a step that
  // continues this frame unannounced, the first frame without a previous one, regions that stood
  // still), unless the caller said a continuation follows (StepBudget::continued_after).
  const bool last_pass_leaves_delta =
      (options_.rotation_extrapolation > 0.0 || !harmonic_weights_.empty()) && !has_groups && !budget.continued_after;
  const size_t free4 = static_cast<size_t>(free_count_) * kVectorStride;
  for (int iteration = 0; iteration < budget.max_iterations; ++iteration) {
    // 1. Linear solve: L_ff u_f = delta_f - L_fh u_h (+ point terms) (+ mu g_f, the constraint's
    //    multiplier so far).
    const auto t0 = Clock::now();
    if (constraint_active_) {
      const double mu = constraint_mu_;
      for (size_t i = 0; i < free4; ++i) u_[i] = delta_[i] + rhs_constant_[i] + mu * constraint_g_[i];
    } else {
      for (size_t i = 0; i < free4; ++i) u_[i] = delta_[i] + rhs_constant_[i];
    }
    if (free_count_ > 0) factor_.solveInPlace(u_.data());
    // The constraint's multiplier first, so that the guard's step solves (L + G) u = b + mu g: the
    // held tets' stiffness bears on the constraint's displacement too; then the little the guard's
    // step moved g . u is projected out again (docs/deformation.md, "Volume constraint").
    if (constraint_active_) applyLinearConstraint();
    if (guarded_count_ > 0) {
      implicitGuardSolve();  // ends on the constraint's plane (its last step projects)
      ++stats.guarded_solves;
    }
    const auto t1 = Clock::now();
    stats.solve_ns += nanosecondsBetween(t0, t1);
    ++stats.iterations;
    if (options_.update_rotations) {
      // 2.-4. Rotations, rigid groups, differential coordinates.
      delta_stale_ = last_pass_leaves_delta && iteration + 1 == budget.max_iterations;
      if (!delta_stale_) std::fill(delta_.begin(), delta_.end(), 0.0f);
      const RotationPassStats pass =
          rotationPass(blocks_.data(), block_count, u_.data(), has_groups || delta_stale_ ? nullptr : delta_.data(),
                       options_.rotation_steps, exact_lanes_.data(), static_cast<float>(options_.rotation_relaxation - 1.0),
                       volumeWeights(), guard(), static_cast<float>(options_.inversion_guard_threshold),
                       guarded_.empty() ? nullptr : guard_det_.data());
      stats.energy = pass.energy;
      if (!guarded_.empty()) collectGuardedTets();
      stats.exact_rotations += pass.exact_fallbacks;
      std::int64_t rigid_ns = 0;
      if (has_groups) {
        const auto t2 = Clock::now();
        applyRigidGroups(group_start_, group_slot_, blocks_.data());
        rigid_ns = nanosecondsBetween(t2, Clock::now());
        differentialPass(blocks_.data(), block_count, delta_.data(), u_.data(), volumeWeights(), guard(),
                         static_cast<float>(options_.inversion_guard_threshold));
      }
      stats.rigid_ns += rigid_ns;
      stats.rotation_ns += nanosecondsBetween(t1, Clock::now()) - rigid_ns;
    }
    if (iteration + 1 < budget.max_iterations && Clock::now() >= budget.deadline) {
      stats.flags |= kStepDeadlineHit;
      break;
    }
  }
  if (stats.exact_rotations > 0) stats.flags |= kStepExactRotations;
  stats.guarded_tets = static_cast<std::int32_t>(guarded_count_);
  if (!guarded_.empty() && stats.iterations > 0 && !untangle_start_.empty()) untangle();
  writePositions();
  stats.total_ns = nanosecondsBetween(start, Clock::now());
  return stats;
}

Eigen::Vector3d DeformerImpl::position(std::int32_t v) const {
  const double* p = &positions_[3 * static_cast<size_t>(v)];
  return {p[0], p[1], p[2]};
}

Eigen::Quaterniond DeformerImpl::rotation(std::int32_t t) const {
  const std::int32_t s = slotOfTet(t);
  const TetBlock& block = blocks_[static_cast<size_t>(s / kTetBlockWidth)];
  const int l = s % kTetBlockWidth;
  return {block.rotation[0][l], block.rotation[1][l], block.rotation[2][l], block.rotation[3][l]};
}

bool DeformerImpl::setFrameGuideSources(std::span<const std::int32_t> source_of_tet, std::int32_t sources) {
  if (guide_.empty() || source_of_tet.size() != static_cast<size_t>(tet_count_) || sources < 1) return false;
  for (const std::int32_t r : source_of_tet)
    if (r < 0 || r >= sources) return false;
  guide_source_of_slot_.assign(guide_.size() / 4, -1);
  for (std::int32_t t = 0; t < tet_count_; ++t)
    guide_source_of_slot_[static_cast<size_t>(slotOfTet(t))] = source_of_tet[static_cast<size_t>(t)];
  guide_sources_ = sources;
  return true;
}

bool DeformerImpl::setFrameGuide(std::span<const float> wxyz_per_source) noexcept {
  if (guide_.empty() || wxyz_per_source.size() != 4 * static_cast<size_t>(guide_sources_)) return false;
  // In slot order: the guide's blocks are written in sequence, the rows read from a small table.
  for (size_t s = 0; s < guide_source_of_slot_.size(); ++s) {
    const std::int32_t r = guide_source_of_slot_[s];
    if (r < 0) continue;  // padding lane: stays the identity
    const float* q = &wxyz_per_source[4 * static_cast<size_t>(r)];
    float* out = &guide_[4 * (s / kTetBlockWidth) * kTetBlockWidth + s % kTetBlockWidth];
    for (size_t c = 0; c < 4; ++c) out[c * kTetBlockWidth] = q[c];
  }
  guide_pending_ = true;
  return true;
}

bool DeformerImpl::rotations(std::span<float> wxyz) const noexcept {
  if (wxyz.size() != 4 * static_cast<size_t>(tet_count_)) return false;
  for (std::int32_t t = 0; t < tet_count_; ++t) {
    const std::int32_t s = slotOfTet(t);
    const TetBlock& block = blocks_[static_cast<size_t>(s / kTetBlockWidth)];
    const int l = s % kTetBlockWidth;
    for (size_t c = 0; c < 4; ++c) wxyz[4 * static_cast<size_t>(t) + c] = block.rotation[c][l];
  }
  return true;
}

void DeformerImpl::setRotations(std::span<const Eigen::Quaterniond> rotations) {
  if (rotations.size() != static_cast<size_t>(tet_count_)) return;
  for (std::int32_t t = 0; t < tet_count_; ++t) {
    const std::int32_t s = slotOfTet(t);
    TetBlock& block = blocks_[static_cast<size_t>(s / kTetBlockWidth)];
    const int l = s % kTetBlockWidth;
    const Eigen::Quaterniond q = rotations[static_cast<size_t>(t)].normalized();
    block.rotation[0][l] = static_cast<float>(q.w());
    block.rotation[1][l] = static_cast<float>(q.x());
    block.rotation[2][l] = static_cast<float>(q.y());
    block.rotation[3][l] = static_cast<float>(q.z());
  }
  rememberRotations();
  rebuildDelta();
}

// Deformer: the public face, each member forwarding to its DeformerImpl (one call, no other work).
Deformer::Deformer(const TetMesh& mesh, const DeformerSetup& setup) : impl_(std::make_unique<DeformerImpl>(mesh, setup)) {}
Deformer::~Deformer() = default;
Deformer::Deformer(Deformer&&) noexcept = default;
Deformer& Deformer::operator=(Deformer&&) noexcept = default;
StepStats Deformer::step(const HandleTargets& targets, const StepBudget& budget) { return impl_->step(targets, budget); }
std::span<const double> Deformer::positions() const noexcept { return impl_->positions(); }
std::span<const double> Deformer::paddedPositions() const noexcept { return impl_->paddedPositions(); }
std::span<const float> Deformer::paddedFloatPositions() const noexcept { return impl_->paddedFloatPositions(); }
Eigen::Vector3d Deformer::position(std::int32_t v) const { return impl_->position(v); }
Eigen::Quaterniond Deformer::rotation(std::int32_t t) const { return impl_->rotation(t); }
bool Deformer::rotations(std::span<float> wxyz) const noexcept { return impl_->rotations(wxyz); }
void Deformer::setRotations(std::span<const Eigen::Quaterniond> rotations) { impl_->setRotations(rotations); }
bool Deformer::setFrameGuide(std::span<const float> wxyz_per_source) noexcept { return impl_->setFrameGuide(wxyz_per_source); }
bool Deformer::setFrameGuideSources(std::span<const std::int32_t> source_of_tet, std::int32_t sources) {
  return impl_->setFrameGuideSources(source_of_tet, sources);
}
bool Deformer::setLinearConstraint(std::span<const double> g, double c, ConstraintDirection direction) noexcept {
  return impl_->setLinearConstraint(g, c, direction);
}
bool Deformer::setLinearConstraintValue(double c) noexcept { return impl_->setLinearConstraintValue(c); }
void Deformer::clearLinearConstraint() noexcept { impl_->clearLinearConstraint(); }
bool Deformer::hasLinearConstraint() const noexcept { return impl_->hasLinearConstraint(); }
void Deformer::reset() { impl_->reset(); }
std::size_t Deformer::frameWorkingSet(std::span<std::span<const std::byte>> out) const noexcept { return impl_->frameWorkingSet(out); }
std::int32_t Deformer::vertexCount() const noexcept { return impl_->vertexCount(); }
std::int32_t Deformer::tetCount() const noexcept { return impl_->tetCount(); }
std::int32_t Deformer::freeVertexCount() const noexcept { return impl_->freeVertexCount(); }
std::int64_t Deformer::factorNonZeros() const noexcept { return impl_->factorNonZeros(); }
double Deformer::factorizeSeconds() const noexcept { return impl_->factorizeSeconds(); }

}  // namespace tetrig
