// Log-linear latency histogram (tetrig/latency_histogram.hpp).
//
// Bucket of v: v < 64: bucket v. Otherwise e = floor(log2 v) (6 <= e), the top kSubBucketBits
// bits below the leading one select the sub-bucket: bucket = 64 + (e - 6) * 32 + ((v >> (e - 5)) & 31).
// Its values are [(32 + s) << (e - 5), (33 + s) << (e - 5) - 1].
#include "tetrig/latency_histogram.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

namespace tetrig {

int LatencyHistogram::bucketOf(std::int64_t ns) noexcept {
  if (ns < kLinearBuckets) return ns < 0 ? 0 : static_cast<int>(ns);
  const auto v = static_cast<std::uint64_t>(ns);
  const int e = 63 - std::countl_zero(v);
  if (e > kMaxExponent) return kBucketCount - 1;
  const int sub = static_cast<int>((v >> (e - kSubBucketBits)) & ((1u << kSubBucketBits) - 1));
  return kLinearBuckets + (e - 6) * (1 << kSubBucketBits) + sub;
}

std::int64_t LatencyHistogram::bucketUpperNs(int bucket) noexcept {
  if (bucket < kLinearBuckets) return bucket;
  const int e = 6 + (bucket - kLinearBuckets) / (1 << kSubBucketBits);
  const int sub = (bucket - kLinearBuckets) % (1 << kSubBucketBits);
  return (static_cast<std::int64_t>((1 << kSubBucketBits) + sub + 1) << (e - kSubBucketBits)) - 1;
}

void LatencyHistogram::record(std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  ++counts_[static_cast<std::size_t>(bucketOf(ns))];
  ++count_;
  max_ = std::max(max_, ns);
}

std::int64_t LatencyHistogram::percentileNs(double p) const noexcept {
  if (count_ == 0) return 0;
  const double clamped = std::clamp(p, 0.0, 1.0);
  const auto rank = std::max<std::uint64_t>(1, static_cast<std::uint64_t>(std::ceil(clamped * static_cast<double>(count_))));
  std::uint64_t seen = 0;
  for (int b = 0; b < kBucketCount; ++b) {
    seen += counts_[static_cast<std::size_t>(b)];
    if (seen >= rank) return std::min(bucketUpperNs(b), max_);
  }
  return max_;
}

void LatencyHistogram::reset() noexcept {
  counts_.fill(0);
  count_ = 0;
  max_ = 0;
}

void LatencyHistogram::merge(const LatencyHistogram& other) noexcept {
  for (std::size_t b = 0; b < counts_.size(); ++b) counts_[b] += other.counts_[b];
  count_ += other.count_;
  max_ = std::max(max_, other.max_);
}

}  // namespace tetrig
