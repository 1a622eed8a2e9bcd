// A nanoflann k-d tree over a flat array of points (x0 y0 z0 x1 ...), for nearest-point queries in
// the rig builder (pose-transfer weights, the rest-frame search). Rig builder internal.
#pragma once

#include <nanoflann.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace tetrig::rigbuild {

// nanoflann dataset adaptor over a flat xyz array (borrowed: it must outlive the tree).
struct XyzPointCloud {
  const std::vector<double>* xyz = nullptr;
  std::size_t kdtree_get_point_count() const { return xyz->size() / 3; }
  double kdtree_get_pt(std::size_t idx, std::size_t dim) const { return (*xyz)[idx * 3 + dim]; }
  template <class Box>
  bool kdtree_get_bbox(Box& /*box*/) const {
    return false;
  }
};

using XyzKdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, XyzPointCloud>, XyzPointCloud, 3, std::uint32_t>;

}  // namespace tetrig::rigbuild
