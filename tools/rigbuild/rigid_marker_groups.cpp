// Rigid marker groups from a clip's geometry (rigid_marker_groups.hpp has the method).
#include "tetrig/rigbuild/rigid_marker_groups.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace tetrig::rigbuild {
namespace {

double percentile(std::vector<double>& v, double p) {
  const std::size_t k = static_cast<std::size_t>(std::lround(p * static_cast<double>(v.size() - 1)));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// Twice the largest triangle area of the rest positions of `group` over the squared largest distance.
double flatness(const std::vector<Eigen::Vector3d>& rest, const std::vector<std::int32_t>& group) {
  double area2 = 0.0, longest2 = 0.0;
  for (std::size_t a = 0; a < group.size(); ++a) {
    for (std::size_t b = a + 1; b < group.size(); ++b) {
      const Eigen::Vector3d ab = rest[static_cast<std::size_t>(group[b])] - rest[static_cast<std::size_t>(group[a])];
      longest2 = std::max(longest2, ab.squaredNorm());
      for (std::size_t c = b + 1; c < group.size(); ++c) {
        const Eigen::Vector3d ac = rest[static_cast<std::size_t>(group[c])] - rest[static_cast<std::size_t>(group[a])];
        area2 = std::max(area2, ab.cross(ac).norm());
      }
    }
  }
  return longest2 > 0.0 ? 0.5 * area2 / longest2 : 0.0;
}

}  // namespace

std::vector<double> markerDistanceSpreads(std::int64_t frame_count, std::size_t marker_count, const MarkerFrameReader& frame,
                                          const RigidMarkerGroupOptions& options, std::vector<double>* median_distance) {
  const std::size_t n = marker_count;
  const std::int64_t samples = std::max<std::int64_t>(1, std::min<std::int64_t>(frame_count, options.max_frames));
  std::vector<std::vector<float>> d(n * n);
  std::vector<Eigen::Vector3d> x;
  std::vector<std::uint8_t> valid;
  for (std::int64_t s = 0; s < samples && frame_count > 0; ++s) {
    const std::int64_t f = samples == 1 ? 0 : s * (frame_count - 1) / (samples - 1);
    x.assign(n, Eigen::Vector3d::Zero());
    valid.assign(n, 0);
    frame(f, x, valid);
    for (std::size_t i = 0; i < n; ++i) {
      if (!valid[i] || !x[i].allFinite()) continue;
      for (std::size_t j = i + 1; j < n; ++j) {
        if (valid[j] && x[j].allFinite()) d[i * n + j].push_back(static_cast<float>((x[i] - x[j]).norm()));
      }
    }
  }
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> spread(n * n, inf);
  if (median_distance) median_distance->assign(n * n, inf);
  const double needed = std::max(2.0, options.min_valid_fraction * static_cast<double>(samples));
  std::vector<double> v;
  for (std::size_t i = 0; i < n; ++i) {
    spread[i * n + i] = 0.0;
    if (median_distance) (*median_distance)[i * n + i] = 0.0;
    for (std::size_t j = i + 1; j < n; ++j) {
      const std::vector<float>& dij = d[i * n + j];
      if (static_cast<double>(dij.size()) < needed) continue;
      v.assign(dij.begin(), dij.end());
      const double lo = percentile(v, 0.05), hi = percentile(v, 0.95), mid = percentile(v, 0.5);
      spread[i * n + j] = spread[j * n + i] = hi - lo;
      if (median_distance) (*median_distance)[i * n + j] = (*median_distance)[j * n + i] = mid;
    }
  }
  return spread;
}

std::vector<RigidMarkerGroup> findRigidMarkerGroups(std::int64_t frame_count, std::size_t marker_count, const MarkerFrameReader& frame,
                                                    const std::vector<Eigen::Vector3d>& rest, const RigidMarkerGroupOptions& options,
                                                    std::vector<RigidMarkerGroup>* too_large) {
  const std::size_t n = marker_count;
  std::vector<double> median;
  const std::vector<double> spread = markerDistanceSpreads(frame_count, n, frame, options, &median);
  const auto linked = [&](std::size_t i, std::size_t j) {
    const double s = spread[i * n + j];
    return std::isfinite(s) && s <= std::max(options.max_spread_mm, options.max_spread_fraction * median[i * n + j]);
  };
  // Complete linkage in order of increasing spread: two clusters merge when every cross pair is linked.
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      if (linked(i, j)) pairs.emplace_back(i, j);
    }
  }
  std::stable_sort(pairs.begin(), pairs.end(), [&](const auto& a, const auto& b) { return spread[a.first * n + a.second] < spread[b.first * n + b.second]; });
  std::vector<std::int32_t> cluster(n);
  std::iota(cluster.begin(), cluster.end(), 0);
  std::vector<std::vector<std::int32_t>> members(n);
  for (std::size_t i = 0; i < n; ++i) members[i] = {static_cast<std::int32_t>(i)};
  for (const auto& [i, j] : pairs) {
    const std::int32_t a = cluster[i], b = cluster[j];
    if (a == b) continue;
    bool all = true;
    for (const std::int32_t p : members[static_cast<std::size_t>(a)]) {
      for (const std::int32_t q : members[static_cast<std::size_t>(b)]) all = all && linked(static_cast<std::size_t>(p), static_cast<std::size_t>(q));
    }
    if (!all) continue;
    for (const std::int32_t q : members[static_cast<std::size_t>(b)]) {
      cluster[static_cast<std::size_t>(q)] = a;
      members[static_cast<std::size_t>(a)].push_back(q);
    }
    members[static_cast<std::size_t>(b)].clear();
  }
  double set_extent = 0.0;  // the whole marker set's: the largest median distance of any pair
  for (const double d : median) set_extent = std::isfinite(d) ? std::max(set_extent, d) : set_extent;
  if (too_large) too_large->clear();
  std::vector<RigidMarkerGroup> groups;
  for (std::vector<std::int32_t>& m : members) {
    if (static_cast<int>(m.size()) < options.min_markers) continue;
    std::sort(m.begin(), m.end());
    if (rest.size() == n && flatness(rest, m) < options.min_area_fraction) continue;
    RigidMarkerGroup g;
    g.markers = m;
    for (std::size_t a = 0; a < m.size(); ++a) {
      for (std::size_t b = a + 1; b < m.size(); ++b) {
        const std::size_t k = static_cast<std::size_t>(m[a]) * n + static_cast<std::size_t>(m[b]);
        g.spread_mm = std::max(g.spread_mm, spread[k]);
        g.extent_mm = std::max(g.extent_mm, median[k]);
      }
    }
    if (g.extent_mm > options.max_extent_fraction * set_extent) {
      if (too_large) too_large->push_back(std::move(g));
      continue;
    }
    groups.push_back(std::move(g));
  }
  std::sort(groups.begin(), groups.end(), [](const RigidMarkerGroup& a, const RigidMarkerGroup& b) { return a.markers < b.markers; });
  return groups;
}

std::vector<std::uint8_t> groupSkinMask(const Vertices& vertices, const std::vector<Eigen::Vector3d>& markers,
                                        const std::vector<std::int32_t>& group, double extent, const GroupSkinOptions& options) {
  std::vector<std::uint8_t> in_group(markers.size(), 0);
  for (const std::int32_t m : group) in_group[static_cast<std::size_t>(m)] = 1;
  const double radius2 = std::pow(options.radius_fraction * extent, 2);
  const double next2 = options.next_marker_fraction * options.next_marker_fraction;
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(vertices.rows()), 0);
  for (Eigen::Index v = 0; v < vertices.rows(); ++v) {
    const Eigen::Vector3d p = vertices.row(v).transpose();
    double inside2 = std::numeric_limits<double>::infinity();   // squared distance to the group's nearest marker
    double outside2 = std::numeric_limits<double>::infinity();  // ... to the nearest marker of the rest of the rig
    for (std::size_t m = 0; m < markers.size(); ++m) {
      double& d2 = in_group[m] ? inside2 : outside2;
      d2 = std::min(d2, (markers[m] - p).squaredNorm());
    }
    mask[static_cast<std::size_t>(v)] = inside2 <= radius2 && inside2 <= next2 * outside2;
  }
  return mask;
}

}  // namespace tetrig::rigbuild
