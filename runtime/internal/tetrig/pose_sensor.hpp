// Pose sensors as region handles ("puppeteering", e.g. a Razer Hydra controller): a tracked
// controller with a position and an orientation drives the rigid transform of one oriented region
// handle (Stoll et al. 2007, section 2.3.1: a region handle prescribes position and orientation;
// its rotation drives the rotation interpolation of section 2.3.2, so twists beyond 180 degrees
// propagate). The equations (also in docs/live.md, "Pose sensors"):
//
// Controller pose in rig axes. A marker gives p_mm (millimetres, device axes) and a unit
// quaternion q (device axes). With the rig's alignment x_rig = A x_mm + b (A = s Q, Q orthogonal,
// the orthogonal polar factor of A):
//   p_c = A p_mm + b,        R_c = Q R(q) Q^T
// (conjugation by Q, a proper rotation even when Q is a reflection, since Q R Q^T = P R P^T with
// P = det(Q) Q).
//
// Clutch mode (what puppeteers expect). The clutch is engaged while any of the sensor's
// clutch_buttons bits is set in Marker::buttons. When it goes down, the driver remembers the
// controller pose C0 = (R_c0, p_c0), the region's current transform T0 = (R_T0, t_T0) (x = R x_rest
// + t) and the region's current centroid c0 = R_T0 c_rest + t_T0, and leaves the target as it is
// (no jump at a press). While held, with dR = R_c R_c0^-1 and s = translation_scale:
//   x' = dR (T0 x_rest - c0) + c0 + s (p_c - p_c0),  i.e.
//   R' = dR R_T0,            t' = dR (t_T0 - c0) + c0 + s (p_c - p_c0)
// computed from the anchors every frame (no drift from accumulation). On release the target is
// left where it is; the next press re-anchors on the region's transform at that time.
//
// Absolute mode. Buttons are ignored; the first valid sample anchors C0 and puts the region at
// rest (T0 = identity, c0 = c_rest); afterwards the same equations with T0 = identity:
//   R' = dR,                 t' = c_rest - dR c_rest + s (p_c - p_c0).
//
// Samples that change nothing: no marker (nullptr), valid = 0, has_orientation = 0, a non-finite
// position or quaternion, or a quaternion whose length is outside (0.5, 2) (it is normalised
// otherwise). They leave both the target and the clutch state as they were: a hold that resumes
// after a dropout continues relative to the same anchor.
//
// The written rotation is kept in the hemisphere of the target's previous rotation (q and -q are
// the same rotation; consumers that difference consecutive targets see no sign flip).
//
// Threads: a PoseSensorDriver belongs to the thread that steps the rig (the solver thread); the
// constructor is load-time code.
#pragma once

#include "tetrig/deformer.hpp"
#include "tetrig/marker_frame.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace tetrig {

// Centroid (rig units) of the distinct corner vertices of `region`'s tets, at rest: the c_rest of
// the equations above. Load time: allocates; throws std::invalid_argument when the region is empty
// or names a tet outside `mesh`. Any thread.
Eigen::Vector3d regionRestCentroid(const TetMesh& mesh, const RegionHandle& region);

class PoseSensorDriver {
 public:
  // Load time (copies `sensor`, allocates). `alignment`: the rig's device mm -> rig units
  // transform; `region_rest_centroid`: c_rest of the driven region, rig units
  // (regionRestCentroid). Throws std::invalid_argument for a non-invertible or non-finite
  // alignment, a non-finite centroid, a translation scale that is not finite and positive, or
  // clutch mode with no clutch button.
  PoseSensorDriver(const RigPoseSensor& sensor, const RigAlignment& alignment, const Eigen::Vector3d& region_rest_centroid);

  // One frame. `marker`: this sensor's marker in the frame (position mm in device axes,
  // orientation w x y z, buttons), or nullptr when the frame has none. Updates `target`, the
  // region's current rigid transform (x = R x_rest + t, rig units), in place as described above;
  // samples that are not usable change nothing. Frame path: no allocation, lock, exception or I/O.
  void update(const Marker* marker, RigidTransform& target) noexcept;

  // Clutch mode: true from the press that anchored until the release. Absolute mode: true once
  // the first valid sample anchored the sensor. Any thread that owns the driver; no allocation.
  bool engaged() const noexcept { return engaged_; }

  // Forgets the clutch and the anchor (e.g. after the source reconnects): in clutch mode the next
  // held sample re-anchors; in absolute mode the next valid sample re-anchors and puts the region
  // back at rest. No allocation.
  void reset() noexcept { engaged_ = false; }

  const RigPoseSensor& sensor() const noexcept { return sensor_; }

 private:
  RigPoseSensor sensor_;
  Eigen::Matrix3d linear_ = Eigen::Matrix3d::Identity();      // A
  Eigen::Vector3d translation_ = Eigen::Vector3d::Zero();      // b
  Eigen::Quaterniond axes_ = Eigen::Quaterniond::Identity();  // P = det(Q) Q as a quaternion
  Eigen::Vector3d rest_centroid_ = Eigen::Vector3d::Zero();    // c_rest

  bool engaged_ = false;
  Eigen::Quaterniond anchor_controller_rotation_ = Eigen::Quaterniond::Identity();  // R_c0 (rig axes)
  Eigen::Vector3d anchor_controller_position_ = Eigen::Vector3d::Zero();            // p_c0 (rig units)
  Eigen::Quaterniond anchor_rotation_ = Eigen::Quaterniond::Identity();             // R_T0
  Eigen::Vector3d anchor_translation_ = Eigen::Vector3d::Zero();                    // t_T0
  Eigen::Vector3d anchor_centroid_ = Eigen::Vector3d::Zero();                       // c0
};

}  // namespace tetrig
