// Tests for the log-linear latency histogram (runtime/src/latency_histogram.cpp): bucket edges,
// percentiles against an exact sort of random samples, merge, no allocation.
#include "tetrig/latency_histogram.hpp"

#include "counting_allocator.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <vector>

namespace {

using tetrig::LatencyHistogram;

TEST(LatencyHistogram, BucketsCoverEveryValueOnceWithinOneThirtySecond) {
  // Walk values across the range: each value's bucket holds it, buckets are monotone, and a bucket's
  // width is at most 1/32 of its lower edge above the linear range.
  int previous = -1;
  for (std::int64_t v = 0; v < (std::int64_t{1} << 41); v = v < 4096 ? v + 1 : v + v / 97 + 1) {
    const int b = LatencyHistogram::bucketOf(v);
    ASSERT_GE(b, previous) << v;
    ASSERT_LT(b, LatencyHistogram::kBucketCount);
    ASSERT_GE(LatencyHistogram::bucketUpperNs(b), v) << v;
    if (b > 0) {
      ASSERT_LT(LatencyHistogram::bucketUpperNs(b - 1), v) << v;
    }
    if (v >= 64) {
      ASSERT_LE(static_cast<double>(LatencyHistogram::bucketUpperNs(b) - v), static_cast<double>(v) / 32.0) << v;
    }
    previous = b;
  }
  EXPECT_EQ(LatencyHistogram::bucketOf(-5), 0);
  EXPECT_EQ(LatencyHistogram::bucketOf(std::int64_t{1} << 60), LatencyHistogram::kBucketCount - 1);
}

TEST(LatencyHistogram, PercentilesMatchAnExactSortWithinTheBucketWidth) {
  std::mt19937_64 rng(42);
  std::lognormal_distribution<double> dist(11.0, 1.2);  // ~60 us median, long tail
  auto h = std::make_unique<LatencyHistogram>();
  std::vector<std::int64_t> values;
  for (int i = 0; i < 100000; ++i) {
    const auto v = static_cast<std::int64_t>(dist(rng));
    values.push_back(v);
    h->record(v);
  }
  std::sort(values.begin(), values.end());
  EXPECT_EQ(h->count(), values.size());
  EXPECT_EQ(h->maxNs(), values.back());
  for (const double p : {0.0, 0.1, 0.5, 0.9, 0.99, 0.999, 1.0}) {
    const auto rank = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(p * static_cast<double>(values.size()))));
    const std::int64_t exact = values[rank - 1];
    const std::int64_t got = h->percentileNs(p);
    EXPECT_GE(got, exact) << p;
    EXPECT_LE(static_cast<double>(got), static_cast<double>(exact) * (1.0 + 1.0 / 32.0) + 1.0) << p;
  }
}

TEST(LatencyHistogram, EmptyMergeResetAndNoAllocation) {
  auto a = std::make_unique<LatencyHistogram>();
  auto b = std::make_unique<LatencyHistogram>();
  EXPECT_EQ(a->percentileNs(0.5), 0);
  const std::uint64_t before = tetrig::test::allocationCount();
  for (int i = 1; i <= 100; ++i) a->record(i * 1000);
  for (int i = 101; i <= 200; ++i) b->record(i * 1000);
  a->merge(*b);
  const std::int64_t median = a->percentileNs(0.5);
  EXPECT_EQ(tetrig::test::allocationCount(), before);
  EXPECT_EQ(a->count(), 200u);
  EXPECT_EQ(a->maxNs(), 200000);
  EXPECT_GE(median, 100000);
  EXPECT_LE(median, 100000 + 100000 / 32);
  a->reset();
  EXPECT_EQ(a->count(), 0u);
  EXPECT_EQ(a->percentileNs(0.99), 0);
}

}  // namespace
