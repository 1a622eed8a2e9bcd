// Latency histogram for the frame path: fixed log-linear buckets (like HdrHistogram, written from
// the idea, not its code). Values below 64 ns have a bucket each; above, every power of two is
// split into 32 buckets, so a reported percentile is within 1/32 (3.1 %) above the true value
// (the bucket's upper edge, clamped to the exact maximum). Range: 0 .. 2^42 ns (~73 minutes);
// larger values land in the last bucket and still set max().
//
// Threads: one writer (record); readers copy it after the writer stopped, or accept a racy
// snapshot of monotone counters. record() allocates nothing, takes no lock and never throws.
#pragma once

#include <array>
#include <cstdint>

namespace tetrig {

class LatencyHistogram {
 public:
  static constexpr int kLinearBuckets = 64;
  static constexpr int kSubBucketBits = 5;  // 32 buckets per power of two
  static constexpr int kMaxExponent = 42;
  static constexpr int kBucketCount = kLinearBuckets + (kMaxExponent - 6 + 1) * (1 << kSubBucketBits);

  // Adds one sample (negative values count as 0).
  void record(std::int64_t ns) noexcept;
  // Smallest bucket upper edge such that at least fraction p (0..1) of the samples are <= it,
  // clamped to max(); 0 when empty.
  [[nodiscard]] std::int64_t percentileNs(double p) const noexcept;
  [[nodiscard]] std::int64_t maxNs() const noexcept { return max_; }
  [[nodiscard]] std::uint64_t count() const noexcept { return count_; }
  void reset() noexcept;
  void merge(const LatencyHistogram& other) noexcept;

  // Bucket of a value and the largest value that bucket holds (exposed for tests).
  [[nodiscard]] static int bucketOf(std::int64_t ns) noexcept;
  [[nodiscard]] static std::int64_t bucketUpperNs(int bucket) noexcept;

 private:
  std::array<std::uint64_t, kBucketCount> counts_{};
  std::uint64_t count_ = 0;
  std::int64_t max_ = 0;
};

}  // namespace tetrig
