// `tetrig pose` (tools/pose.hpp): --region NAME=FILE.def arguments -> poseRig -> OBJ.
#include "pose.hpp"

#include "tetrig/printable_text.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/output_guard.hpp"
#include "tetrig/rigbuild/pose_rig.hpp"

#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace tetrig::tools {

int runPose(const PoseOptions& options) {
  if (options.regions.empty()) {
    throw std::invalid_argument("nothing to pose: give at least one --region NAME=FILE.def (the rig's region handles: tetrig inspect RIG)");
  }
  if (options.out.empty()) throw std::invalid_argument("--out FILE.obj is required");
  // Parse every argument and read every .def before loading the rig, so that a typo costs nothing.
  std::vector<std::pair<std::string, std::string>> named;
  for (const std::string& arg : options.regions) {
    const std::size_t eq = arg.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == arg.size()) {
      throw std::invalid_argument("--region expects NAME=FILE.def (a region handle of the rig and its transform file), found '" +
                                  printableText(arg, 200) + "'");
    }
    named.emplace_back(arg.substr(0, eq), arg.substr(eq + 1));
  }
  std::vector<std::pair<std::string, RigidTransform>> regions;
  for (const auto& [name, path] : named) regions.emplace_back(name, rigbuild::readDefFile(path).rigid);
  std::vector<std::filesystem::path> inputs = {options.rig_path};
  for (const auto& named_def : named) inputs.emplace_back(named_def.second);
  rigbuild::checkOutputPath(options.out, rigbuild::OutputKind::kObj, inputs, options.force);

  const Rig rig = loadRigFile(options.rig_path);
  rigbuild::PoseOptions pose;
  pose.iterations = options.iterations;
  pose.max_iterations = options.max_iterations;
  pose.volume_weight = options.volume_weight;
  const rigbuild::PoseResult r = rigbuild::poseRig(rig, regions, pose);
  if (!r.converged) {
    char what[320];
    std::snprintf(what, sizeof what,
                  "did not converge in %d iterations (the tet mesh still moved %.2g of its diagonal over the last %d, the criterion is "
                  "%.2g): raise --max-iterations, or give --iterations N to accept a fixed count",
                  r.iterations, r.last_batch_step, pose.batch, pose.step_tolerance);
    throw std::runtime_error(what);
  }
  std::string comment = "tetrig pose: rig " + printableText(rig.name, 200) + " (" + printableText(options.rig_path) + ")\n";
  for (const auto& [name, path] : named) comment += "region " + printableText(name) + " = " + printableText(path) + "\n";
  comment += std::to_string(r.iterations) + " iterations";
  rigbuild::writeObjAtomically(options.out, rig, r.fine_positions, comment);
  if (!options.quiet) {
    std::printf("tetrig pose: %d iterations (%s; last %d moved the tet mesh by %.2g of the diagonal), energy %.6g; %d of %d tets "
                "inverted\n",
                r.iterations, options.iterations > 0 ? "fixed count" : "converged", std::min(r.iterations, pose.batch), r.last_batch_step,
                r.energy, r.inverted_tets, rig.body_tet_count);
    std::printf("  wrote %s (%lld vertices, %lld triangles)\n", options.out.c_str(), static_cast<long long>(rig.fine_vertices.rows()),
                static_cast<long long>(rig.fine_triangles.rows()));
  }
  if (r.inverted_tets > 0) {
    std::fprintf(stderr, "tetrig pose: warning: %d tets are inverted in this pose: the edit folds the rig's tet mesh (rebuild it with more "
                         "--tet-vertices, or pose less far)\n", r.inverted_tets);
  }
  return 0;
}

}  // namespace tetrig::tools
