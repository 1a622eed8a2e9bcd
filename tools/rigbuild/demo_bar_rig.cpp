// The demo bar rig (tetrig/rigbuild/demo_bar_rig.hpp).
#include "tetrig/rigbuild/demo_bar_rig.hpp"

#include "tetrig/rigbuild/bind_markers.hpp"
#include "tetrig/tet_mesh.hpp"
#include "tetrig/rigbuild/pose_transfer_weights.hpp"
#include "tetrig/version.h"

#include <stdexcept>
#include <string>
#include <vector>

namespace tetrig::rigbuild {

Rig makeDemoBarRig(const TetMesh& bar) {
  Rig rig;
  rig.name = "tetrig demo bar (assets/bar_4x4x33)";
  rig.unit = "cm";
  rig.builder = "tetrig demo " TETRIG_VERSION_STRING;
  // Fine mesh: the bar's boundary surface, on its own compact vertex list.
  const Triangles faces = boundaryFaces(bar);
  std::vector<std::int32_t> fine_of(static_cast<std::size_t>(bar.vertexCount()), -1);
  std::vector<std::int32_t> body_of;
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      std::int32_t& id = fine_of[static_cast<std::size_t>(faces(f, k))];
      if (id < 0) {
        id = static_cast<std::int32_t>(body_of.size());
        body_of.push_back(faces(f, k));
      }
    }
  rig.fine_vertices.resize(static_cast<Eigen::Index>(body_of.size()), 3);
  for (std::size_t i = 0; i < body_of.size(); ++i) rig.fine_vertices.row(static_cast<Eigen::Index>(i)) = bar.vertices.row(body_of[i]);
  rig.fine_triangles.resize(faces.rows(), 3);
  for (Eigen::Index f = 0; f < faces.rows(); ++f)
    for (int k = 0; k < 3; ++k) rig.fine_triangles(f, k) = fine_of[static_cast<std::size_t>(faces(f, k))];

  // Markers: four rings (near 6 %, 35 %, 65 %, 94 % of the length), one 0.6 units outside each side face.
  const Eigen::Vector3d lo = bar.vertices.colwise().minCoeff(), hi = bar.vertices.colwise().maxCoeff();
  const Eigen::Vector3d mid = 0.5 * (lo + hi);
  std::vector<Eigen::Vector3d> positions;
  std::vector<std::string> labels;
  const double offset = 0.6;
  const char* sides[4] = {"L", "R", "F", "B"};
  int ring = 0;
  for (const double fraction : {0.06, 0.35, 0.65, 0.94}) {
    const double z = lo.z() + fraction * (hi.z() - lo.z());
    const Eigen::Vector3d p[4] = {{lo.x() - offset, mid.y(), z}, {hi.x() + offset, mid.y(), z}, {mid.x(), lo.y() - offset, z}, {mid.x(), hi.y() + offset, z}};
    for (int s = 0; s < 4; ++s) {
      positions.push_back(p[s]);
      labels.push_back("BAR" + std::to_string(ring) + sides[s]);
    }
    ++ring;
  }
  const MarkerBindResult bound = bindMarkers(bar, positions, labels);
  rig.tet_mesh = bound.mesh;
  rig.body_vertex_count = bar.vertexCount();
  rig.body_tet_count = bar.tetCount();
  for (std::size_t m = 0; m < labels.size(); ++m) {
    RigMarker rm;
    rm.label = labels[m];
    rm.tet_vertex = bound.bindings[m].tet_vertex;
    rm.vertex_handle = static_cast<std::int32_t>(rig.setup.vertex_handles.size());
    rm.rest_position = positions[m];
    rm.bound_faces = bound.bindings[m].bound_faces;
    rm.surface_distance = offset;
    rig.setup.vertex_handles.push_back(rm.tet_vertex);
    rig.vertex_handle_names.push_back("marker:" + rm.label);
    rig.markers.push_back(rm);
  }
  std::vector<double> stiffness(static_cast<std::size_t>(rig.tet_mesh.tetCount()), 1.0);
  for (std::size_t t = static_cast<std::size_t>(bar.tetCount()); t < stiffness.size(); ++t) stiffness[t] = 0.1;
  rig.setup.stiffness = stiffness;
  Eigen::SparseMatrix<double, Eigen::RowMajor> b = poseTransferWeights(rig.fine_vertices, bar);
  b.conservativeResize(b.rows(), rig.tet_mesh.vertexCount());
  b.makeCompressed();
  rig.pose_transfer = makePoseTransferCsr<double>(b);
  rig.pose_transfer.cols = rig.tet_mesh.vertexCount();
  // Device millimetres -> bar units (1 unit = 10 mm); the synthetic source's cloud is centred on the bar.
  rig.alignment.rig_units_per_mm = 0.1;
  rig.alignment.linear = 0.1 * Eigen::Matrix3d::Identity();
  rig.alignment.translation = Eigen::Vector3d::Zero();
  rig.alignment.device_up = "z";
  rig.alignment.rig_up = "z";
  if (const std::string e = validateRig(rig); !e.empty()) throw std::runtime_error("the demo rig is inconsistent: " + e);
  return rig;
}

}  // namespace tetrig::rigbuild
