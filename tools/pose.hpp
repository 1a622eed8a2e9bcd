// `tetrig pose`: pose a rig from the command line. Each --region NAME=FILE.def gives a region
// handle the rigid transform of a deformation-survey .def file (a 4x4 matrix); the other regions,
// the markers and the point handles stay at rest. The Deformer runs to convergence (its energy
// stops changing, bounded) or a fixed number of iterations, and the fine mesh is written as OBJ
// (atomically, in the rig's fine-vertex order: for OBJ/OFF/PLY assets the file's own order).
// The library behind it is tetrig/rigbuild/pose_rig.hpp.
#pragma once

#include <string>
#include <vector>

namespace tetrig::tools {

struct PoseOptions {
  std::string rig_path;               // rig file (tetrig build-rig)
  std::vector<std::string> regions;   // NAME=FILE.def, one per posed region handle
  std::string out;                    // OBJ file to write
  int iterations = 0;                 // > 0: exactly this many; 0: to convergence
  int max_iterations = 20000;         // bound when running to convergence
  double volume_weight = 0.0;         // the volume term's share of each tet's energy (DeformerOptions::volume_weight)
  bool force = false;                 // replace an existing --out that tetrig did not write (never an input)
  bool quiet = false;
};

// Poses the rig and writes the OBJ; prints a summary unless quiet. Returns a process exit code;
// throws (one line: what, where, what to do) on bad input, leaving no output file.
int runPose(const PoseOptions& options);

}  // namespace tetrig::tools
