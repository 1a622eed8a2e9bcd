// Run-time pose transfer x_fine = B x_tet over a CSR matrix.
#include "tetrig/pose_transfer.hpp"
#include "tetrig/pose_transfer_padded.hpp"
#include "tetrig/pose_transfer_blocked.hpp"
#include "tetrig/pose_transfer_split.hpp"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstring>
#include <memory>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <limits>
#include <new>
#include <numeric>
#include <span>
#include <random>
#include <vector>

#include "counting_allocator.hpp"

namespace tetrig {
namespace {

// A random sparse matrix (some rows empty).
Eigen::SparseMatrix<double, Eigen::RowMajor> randomB(int rows, int cols, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> count(0, 12);
  std::uniform_int_distribution<int> col(0, cols - 1);
  std::uniform_real_distribution<double> value(-0.5, 1.5);
  std::vector<Eigen::Triplet<double>> t;
  for (int i = 0; i < rows; ++i) {
    const int n = i % 7 == 0 ? 0 : count(rng);
    for (int k = 0; k < n; ++k) t.emplace_back(i, col(rng), value(rng));
  }
  Eigen::SparseMatrix<double, Eigen::RowMajor> b(rows, cols);
  b.setFromTriplets(t.begin(), t.end());
  return b;
}

using Positions = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// A random B (rows x cols), random tet positions x and the reference product B x (Eigen).
struct RandomProduct {
  Eigen::SparseMatrix<double, Eigen::RowMajor> b;
  Positions x;
  Positions expected;
};
RandomProduct randomProduct(int rows, int cols, unsigned seed) {
  RandomProduct p{randomB(rows, cols, seed), Eigen::MatrixXd::Random(cols, 3), {}};
  p.expected = p.b * p.x;
  return p;
}

// A random B of rows x cols with 0 to max_entries entries per row (weights in [-0.3, 1)).
Eigen::SparseMatrix<double, Eigen::RowMajor> randomRowsB(int rows, int cols, int max_entries, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> count(0, max_entries), col(0, cols - 1);
  std::uniform_real_distribution<double> value(-0.3, 1.0);
  std::vector<Eigen::Triplet<double>> t;
  for (int i = 0; i < rows; ++i) {
    const int n = count(rng);
    for (int k = 0; k < n; ++k) t.emplace_back(i, col(rng), value(rng));
  }
  Eigen::SparseMatrix<double, Eigen::RowMajor> b(rows, cols);
  b.setFromTriplets(t.begin(), t.end());
  return b;
}

// x as padded float positions (x, y, z, pad); the pad holds a huge value that must never reach a
// fine position (the CSR kernel sums it in its fourth lane, the blocked one never reads it).
std::vector<float> paddedFloatPositions(const Positions& x) {
  std::vector<float> x4(static_cast<size_t>(x.rows()) * 4);
  for (Eigen::Index v = 0; v < x.rows(); ++v) {
    for (int c = 0; c < 3; ++c) x4[4 * static_cast<size_t>(v) + static_cast<size_t>(c)] = static_cast<float>(x(v, c));
    x4[4 * static_cast<size_t>(v) + 3] = 1e30f;
  }
  return x4;
}

TEST(PoseTransfer, MatchesEigenProductInDoubleAndFloat) {
  const int rows = 500;
  const int cols = 80;
  const auto [b, x, expected] = randomProduct(rows, cols, 7);

  const PoseTransferCsr<double> bd = makePoseTransferCsr<double>(b);
  EXPECT_EQ(validatePoseTransfer(bd.view()), "");
  EXPECT_EQ(bd.nonzeros(), b.nonZeros());
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> out(rows, 3);
  applyPoseTransfer(bd.view(), x.data(), out.data());
  EXPECT_LT((out - expected).cwiseAbs().maxCoeff(), 1e-12);

  const PoseTransferCsr<float> bf = makePoseTransferCsr<float>(b);
  const Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor> xf = x.cast<float>();
  Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor> outf(rows, 3);
  applyPoseTransfer(bf.view(), xf.data(), outf.data());
  EXPECT_LT((outf.cast<double>() - expected).cwiseAbs().maxCoeff(), 1e-4);
  // Double positions in, float vertices out (the shared-memory case).
  applyPoseTransfer(bf.view(), x.data(), outf.data());
  EXPECT_LT((outf.cast<double>() - expected).cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_EQ(bf.bytes(), static_cast<std::int64_t>((rows + 1) * 4 + b.nonZeros() * 8));
}

TEST(PoseTransfer, RowRangeWritesOnlyThoseRows) {
  const auto b = randomB(40, 10, 3);
  const PoseTransferCsr<double> bd = makePoseTransferCsr<double>(b);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> x = Eigen::MatrixXd::Random(10, 3);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> out = Eigen::MatrixXd::Constant(40, 3, 42.0);
  applyPoseTransferRows(bd.view(), x.data(), out.data(), 10, 20);
  const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> expected = b * x;
  for (int i = 0; i < 40; ++i) {
    if (i >= 10 && i < 20) {
      EXPECT_LT((out.row(i) - expected.row(i)).norm(), 1e-12);
    } else {
      EXPECT_EQ(out.row(i), Eigen::RowVector3d::Constant(42.0));
    }
  }
}

// The padded-input kernel: same product from (x, y, z, pad) positions; the pad (set to garbage
// here) must not leak into the result; rows with an odd number of entries take the remainder path.
TEST(PoseTransfer, PaddedInputMatchesEigenProduct) {
  const int rows = 500;
  const int cols = 80;
  const auto [b, x, expected] = randomProduct(rows, cols, 13);
  std::vector<double> x4(static_cast<size_t>(cols) * 4);
  for (int v = 0; v < cols; ++v) {
    for (int c = 0; c < 3; ++c) x4[4 * static_cast<size_t>(v) + static_cast<size_t>(c)] = x(v, c);
    x4[4 * static_cast<size_t>(v) + 3] = 1e30;  // the pad lane is summed but never written out
  }
  int odd_rows = 0;
  for (int i = 0; i < rows; ++i) odd_rows += b.outerIndexPtr()[i + 1] % 2 != b.outerIndexPtr()[i] % 2;
  ASSERT_GT(odd_rows, 50);

  const PoseTransferCsr<double> bd = makePoseTransferCsr<double>(b);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> out(rows, 3);
  applyPoseTransferPadded(bd.view(), x4.data(), out.data());
  EXPECT_LT((out - expected).cwiseAbs().maxCoeff(), 1e-12);

  const PoseTransferCsr<float> bf = makePoseTransferCsr<float>(b);
  Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor> outf(rows, 3);
  applyPoseTransferPadded(bf.view(), x4.data(), outf.data());
  EXPECT_LT((outf.cast<double>() - expected).cwiseAbs().maxCoeff(), 1e-4);

  // Row ranges write only their rows.
  out.setConstant(42.0);
  applyPoseTransferPaddedRows(bd.view(), x4.data(), out.data(), 100, 201);
  for (int i = 0; i < rows; ++i) {
    if (i >= 100 && i < 201) {
      EXPECT_LT((out.row(i) - expected.row(i)).norm(), 1e-12) << i;
    } else {
      EXPECT_EQ(out.row(i), Eigen::RowVector3d::Constant(42.0)) << i;
    }
  }
}

TEST(PoseTransfer, ApplyDoesNotAllocate) {
  const auto b = randomB(300, 50, 11);
  const PoseTransferCsr<float> bf = makePoseTransferCsr<float>(b);
  const CompactPoseTransfer compact = narrowPoseTransfer(makePoseTransferCsr<double>(b));
  std::vector<double> x(150, 1.0);
  std::vector<float> out(900);
  const auto view = bf.view();
  std::vector<double> x4(200, 1.0);
  std::vector<float> x4f(200, 1.0f);
  const std::uint64_t before = ::tetrig::test::allocationCount();
  for (int frame = 0; frame < 10; ++frame) {
    applyPoseTransfer(view, x.data(), out.data());
    applyPoseTransferPadded(view, x4.data(), out.data());
    applyPoseTransferPadded(compact.view(), x4.data(), out.data());
    applyPoseTransferPadded(compact.view(), x4f.data(), out.data());
  }
  EXPECT_EQ(::tetrig::test::allocationCount(), before);
}

TEST(PoseTransfer, ValidateFindsBrokenStructure) {
  const auto b = randomB(20, 5, 5);
  PoseTransferCsr<float> bf = makePoseTransferCsr<float>(b);
  ASSERT_GT(bf.nonzeros(), 2);
  {
    PoseTransferCsr<float> bad = bf;
    bad.columns[1] = 5;
    EXPECT_NE(validatePoseTransfer(bad.view()).find("column index out of range at entry 1"), std::string::npos);
  }
  {
    PoseTransferCsr<float> bad = bf;
    bad.weights[0] = std::numeric_limits<float>::quiet_NaN();
    EXPECT_NE(validatePoseTransfer(bad.view()).find("non-finite weight at entry 0"), std::string::npos);
  }
  {
    PoseTransferCsr<float> bad = bf;
    bad.row_offsets[3] = bad.row_offsets[4] + 1;
    EXPECT_NE(validatePoseTransfer(bad.view()).find("decrease"), std::string::npos);
  }
}

// The live rig's compact copy (float weights, 16-bit columns): the same columns, and each fine
// vertex within the weights' rounding of the double product, |dx_i| <= 2^-24 sum_j |B_ij| |x_j|
// (+ the double sums' own rounding), with column indices above 32767 and up to 65535 (a signed
// or truncated index would gather the wrong vertex and miss the bound by orders of magnitude).
TEST(PoseTransfer, CompactCopyIsWithinTheWeightsRoundingOfTheDoubleProduct) {
  const int rows = 400;
  const int cols = 65536;
  const auto [b, x, expected] = randomProduct(rows, cols, 17);
  const PoseTransferCsr<double> bd = makePoseTransferCsr<double>(b);
  int high_columns = 0;
  for (const std::int32_t c : bd.columns) high_columns += c >= 32768;
  ASSERT_GT(high_columns, 100);
  const CompactPoseTransfer compact = narrowPoseTransfer(bd);
  EXPECT_EQ(validatePoseTransfer(compact.view()), "");
  ASSERT_EQ(compact.columns.size(), bd.columns.size());
  for (std::size_t k = 0; k < bd.columns.size(); ++k) ASSERT_EQ(static_cast<std::int32_t>(compact.columns[k]), bd.columns[k]);
  EXPECT_EQ(compact.row_offsets, bd.row_offsets);
  EXPECT_EQ(compact.bytes() - static_cast<std::int64_t>(compact.row_offsets.size() * 4), 6 * compact.nonzeros());

  std::vector<double> x4(static_cast<size_t>(cols) * 4, 0.0);
  for (int v = 0; v < cols; ++v)
    for (int c = 0; c < 3; ++c) x4[4 * static_cast<size_t>(v) + static_cast<size_t>(c)] = 1000.0 * x(v, c);
  Positions out(rows, 3);
  applyPoseTransferPadded(compact.view(), x4.data(), out.data());
  int rounded_rows = 0;
  for (int i = 0; i < rows; ++i) {
    for (int c = 0; c < 3; ++c) {
      double bound = 0.0;
      for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(b, i); it; ++it)
        bound += std::abs(it.value()) * std::abs(1000.0 * x(it.col(), c));
      const double error = std::abs(out(i, c) - 1000.0 * expected(i, c));
      EXPECT_LE(error, bound * (0x1p-24 + 1e-14)) << "row " << i << " coordinate " << c;
      rounded_rows += error > bound * 1e-14;
    }
  }
  EXPECT_GT(rounded_rows, 100);  // the float weights do round: the bound is not vacuous
}

// The compact copy's float kernel (float tet positions, float sums in four partial sums per row):
// each fine coordinate within its stated bound of the exact product of the double positions,
// |dx_ic| <= (n_i/4 + 5) 2^-24 sum_k |B_ik| |x_kc| (n_i: the row's entries; sums, weights and
// positions rounded), on rows of 0-60 entries (the four-sum loop and every remainder length), with
// the pad lane holding a huge value that must not reach the result. A wrong column or weight
// misses the bound by orders of magnitude.
TEST(PoseTransfer, FloatKernelIsWithinItsRoundingBoundOfTheDoubleProduct) {
  const int rows = 2000;
  const int cols = 3000;
  const Eigen::SparseMatrix<double, Eigen::RowMajor> b = randomRowsB(rows, cols, 60, 29);
  const Positions x = 1.5 * Positions::Random(cols, 3);
  const Positions expected = b * x;
  const CompactPoseTransfer compact = narrowPoseTransfer(makePoseTransferCsr<double>(b));
  const std::vector<float> x4 = paddedFloatPositions(x);
  std::vector<float> out(static_cast<size_t>(rows) * 3, -7.0f);
  applyPoseTransferPadded(compact.view(), x4.data(), out.data());
  std::array<int, 4> remainders{};
  double largest_ratio = 0.0;
  int rounded = 0;
  for (int i = 0; i < rows; ++i) {
    const int n = static_cast<int>(b.outerIndexPtr()[i + 1] - b.outerIndexPtr()[i]);
    if (n >= 4) ++remainders[static_cast<size_t>(n % 4)];
    for (int c = 0; c < 3; ++c) {
      double magnitude = 0.0;
      for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(b, i); it; ++it)
        magnitude += std::abs(it.value()) * std::abs(x(it.col(), c));
      const double bound = (n / 4.0 + 5.0) * 0x1p-24 * magnitude;
      const double error = std::abs(static_cast<double>(out[3 * static_cast<size_t>(i) + static_cast<size_t>(c)]) - expected(i, c));
      ASSERT_LE(error, bound) << "row " << i << " (" << n << " entries) coordinate " << c;
      if (bound > 0.0) largest_ratio = std::max(largest_ratio, error / bound);
      rounded += error > 1e-12;
    }
  }
  for (int r = 0; r < 4; ++r) EXPECT_GT(remainders[static_cast<size_t>(r)], 50) << "rows with " << r << " left over";
  EXPECT_GT(rounded, 1000);  // the float sums do round: the bound is not vacuous
  RecordProperty("largest_fraction_of_bound", ::testing::PrintToString(largest_ratio));

  // Row ranges write only their rows.
  std::vector<float> part(out.size(), 42.0f);
  applyPoseTransferPaddedRows(compact.view(), x4.data(), part.data(), 100, 201);
  for (int i = 0; i < rows; ++i)
    for (int c = 0; c < 3; ++c) {
      const size_t k = 3 * static_cast<size_t>(i) + static_cast<size_t>(c);
      ASSERT_EQ(part[k], i >= 100 && i < 201 ? out[k] : 42.0f) << i;
    }
}

TEST(PoseTransfer, CompactCopyRefusesTooManyColumnsAndBrokenMatrices) {
  PoseTransferCsr<double> wide = makePoseTransferCsr<double>(randomB(10, 65537, 3));
  EXPECT_FALSE(fitsCompactPoseTransfer(wide.cols));
  EXPECT_TRUE(fitsCompactPoseTransfer(65536));
  try {
    (void)narrowPoseTransfer(wide);
    ADD_FAILURE() << "65537 columns accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("65537 tet vertices"), std::string::npos) << e.what();
  }
  PoseTransferCsr<double> broken = makePoseTransferCsr<double>(randomB(20, 5, 5));
  ASSERT_GT(broken.nonzeros(), 2);
  broken.columns[1] = 5;
  EXPECT_THROW((void)narrowPoseTransfer(broken), std::invalid_argument);
}

// The two-core split gives the single-thread result bit for bit, whoever computes which chunk;
// the worker takes part (its chunks are counted); apply() allocates nothing.
TEST(PoseTransferSplit, BitIdenticalToOneThreadAndTheWorkerTakesChunks) {
  const int rows = 3001;  // not a multiple of the chunk size
  const int cols = 200;
  const auto [b, x, expected] = randomProduct(rows, cols, 21);
  std::vector<double> x4(static_cast<size_t>(cols) * 4, 0.0);
  const PoseTransferCsr<double> bd = makePoseTransferCsr<double>(b);
  std::vector<float> single(static_cast<size_t>(rows) * 3), split(static_cast<size_t>(rows) * 3);
  auto worker = std::make_unique<PoseTransferSplit>(bd.view(), 64);
  EXPECT_EQ(worker->chunkCount(), (rows + 63) / 64);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  const std::uint64_t before = test::allocationCount();
  int mismatches = 0;
  // At least 300 calls, and on until the worker took part (it wakes when the scheduler lets it:
  // on a loaded machine the caller may finish whole calls alone), at most 20000.
  for (int call = 0; call < 300 || (worker->workerChunks() == 0 && call < 20000); ++call) {
    for (double& v : x4) v = u(rng);
    applyPoseTransferPadded(bd.view(), x4.data(), single.data());
    std::fill(split.begin(), split.end(), -7.0f);
    worker->apply(x4.data(), split.data());
    mismatches += std::memcmp(single.data(), split.data(), single.size() * sizeof(float)) != 0;
  }
  EXPECT_EQ(test::allocationCount(), before);
  EXPECT_EQ(mismatches, 0);
  EXPECT_GT(worker->workerChunks(), 0u) << "the worker thread never computed a chunk";
}

// The same with the blocked copy and float positions (its float kernel), as the live rig runs it:
// chunks of whole blocks. Double positions are not its input: that overload writes nothing.
TEST(PoseTransferSplit, BlockedCopyBitIdenticalToOneThread) {
  const int rows = 3001;
  const int cols = 200;
  const auto [b, x, expected] = randomProduct(rows, cols, 23);
  const Positions points = Positions::Random(rows, 3);
  const BlockedPoseTransfer compact =
      blockPoseTransfer(makePoseTransferCsr<double>(b), std::span<const double>(points.data(), static_cast<std::size_t>(points.size())));
  std::vector<float> x4(static_cast<size_t>(cols) * 4, 0.0f);
  std::vector<float> single(static_cast<size_t>(rows) * 3), split(static_cast<size_t>(rows) * 3);
  auto worker = std::make_unique<PoseTransferSplit>(compact.view(), 64);
  EXPECT_EQ(worker->chunkCount(), (compact.blocks + 7) / 8);  // 64 rows: 8 blocks per chunk
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> u(-2.0f, 2.0f);
  int mismatches = 0;
  for (int call = 0; call < 300 || (worker->workerChunks() == 0 && call < 20000); ++call) {
    for (float& v : x4) v = u(rng);
    applyPoseTransferBlocked(compact.view(), x4.data(), single.data());
    std::fill(split.begin(), split.end(), -7.0f);
    worker->apply(x4.data(), split.data());
    mismatches += std::memcmp(single.data(), split.data(), single.size() * sizeof(float)) != 0;
  }
  EXPECT_EQ(mismatches, 0);
  EXPECT_GT(worker->workerChunks(), 0u) << "the worker thread never computed a chunk";
  const std::vector<double> x4d(x4.begin(), x4.end());
  std::fill(split.begin(), split.end(), -7.0f);
  worker->apply(x4d.data(), split.data());
  EXPECT_TRUE(std::all_of(split.begin(), split.end(), [](float v) { return v == -7.0f; }));
}

// The blocked copy (tetrig/pose_transfer_blocked.hpp): every fine coordinate within the kernel's
// stated bound of the exact product of the double positions, |dx_ic| <= (n_i + 4) 2^-24 sum_k |B_ik|
// |x_kc| (n_i: the row's entries), on rows of 0-60 entries, a row count that is not a multiple of the
// block, column indices up to 65535 (a signed or truncated index would gather the wrong vertex), and a
// pad lane holding a huge value that must not reach the result. Every row sits in exactly one lane of
// one block, and block ranges write only their blocks' rows.
TEST(BlockedPoseTransfer, WithinItsRoundingBoundOfTheDoubleProduct) {
  const int rows = 2003;
  const int cols = 65536;
  const Eigen::SparseMatrix<double, Eigen::RowMajor> b = randomRowsB(rows, cols, 60, 31);
  const Positions x = 1.5 * Positions::Random(cols, 3);
  const Positions expected = b * x;
  const Positions points = Positions::Random(rows, 3);
  const PoseTransferCsr<double> bd = makePoseTransferCsr<double>(b);
  int high_columns = 0;
  for (const std::int32_t c : bd.columns) high_columns += c >= 32768;
  ASSERT_GT(high_columns, 1000);
  const BlockedPoseTransfer blocked =
      blockPoseTransfer(bd, std::span<const double>(points.data(), static_cast<std::size_t>(points.size())));
  ASSERT_EQ(blocked.blocks, (rows + kPoseBlockRows - 1) / kPoseBlockRows);
  ASSERT_EQ(blocked.lane_rows.size(), static_cast<std::size_t>(blocked.blocks) * kPoseBlockRows);
  std::vector<int> seen(static_cast<std::size_t>(rows), 0);
  int empty_lanes = 0;
  for (const std::int32_t r : blocked.lane_rows) {
    if (r < 0) {
      ++empty_lanes;
      continue;
    }
    ASSERT_LT(r, rows);
    ++seen[static_cast<std::size_t>(r)];
  }
  EXPECT_EQ(empty_lanes, blocked.blocks * kPoseBlockRows - rows);
  EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int n) { return n == 1; }));
  EXPECT_EQ(blocked.weights.size(), blocked.columns.size() * kPoseBlockRows);
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(blocked.weights.data()) % 32, 0u);
  EXPECT_GE(blocked.fill(bd.nonzeros()), 1.0);

  const std::vector<float> x4 = paddedFloatPositions(x);
  std::vector<float> out(static_cast<size_t>(rows) * 3, -7.0f);
  applyPoseTransferBlocked(blocked.view(), x4.data(), out.data());
  double largest_ratio = 0.0;
  int rounded = 0;
  for (int i = 0; i < rows; ++i) {
    const int n = static_cast<int>(b.outerIndexPtr()[i + 1] - b.outerIndexPtr()[i]);
    for (int c = 0; c < 3; ++c) {
      double magnitude = 0.0;
      for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(b, i); it; ++it)
        magnitude += std::abs(it.value()) * std::abs(x(it.col(), c));
      const double bound = (n + 4.0) * 0x1p-24 * magnitude;
      const double error = std::abs(static_cast<double>(out[3 * static_cast<size_t>(i) + static_cast<size_t>(c)]) - expected(i, c));
      ASSERT_LE(error, bound) << "row " << i << " (" << n << " entries) coordinate " << c;
      if (bound > 0.0) largest_ratio = std::max(largest_ratio, error / bound);
      rounded += error > 1e-12;
    }
  }
  EXPECT_GT(rounded, 1000);  // the float sums do round: the bound is not vacuous
  RecordProperty("largest_fraction_of_bound", ::testing::PrintToString(largest_ratio));

  // Block ranges write only their blocks' rows.
  std::vector<float> part(out.size(), 42.0f);
  applyPoseTransferBlocked(blocked.view(), x4.data(), part.data(), 10, 31);
  std::vector<char> in_range(static_cast<std::size_t>(rows), 0);
  for (std::int32_t k = 10 * kPoseBlockRows; k < 31 * kPoseBlockRows; ++k) in_range[static_cast<std::size_t>(blocked.lane_rows[static_cast<std::size_t>(k)])] = 1;
  for (int i = 0; i < rows; ++i)
    for (int c = 0; c < 3; ++c) {
      const size_t k = 3 * static_cast<size_t>(i) + static_cast<size_t>(c);
      ASSERT_EQ(part[k], in_range[static_cast<std::size_t>(i)] ? out[k] : 42.0f) << i;
    }

  const std::uint64_t before = ::tetrig::test::allocationCount();
  for (int frame = 0; frame < 10; ++frame) applyPoseTransferBlocked(blocked.view(), x4.data(), out.data());
  EXPECT_EQ(::tetrig::test::allocationCount(), before);
}

// Rows are blocked by where their fine vertices lie, not by their order: on a surface grid whose rows
// take their weights from the nearest coarse grid points, listed in a shuffled order, the blocks hold
// less than half the weights that blocks of consecutive rows would (those gather 8 unrelated patches).
TEST(BlockedPoseTransfer, BlocksAreNearbyVertices) {
  const int side = 60, coarse = 12;  // a 60 x 60 grid of fine vertices over a 12 x 12 grid of tet vertices
  std::vector<int> order(side * side);
  std::iota(order.begin(), order.end(), 0);
  std::mt19937 rng(3);
  std::shuffle(order.begin(), order.end(), rng);
  Positions points(side * side, 3);
  std::vector<Eigen::Triplet<double>> t;
  for (int r = 0; r < side * side; ++r) {
    const int u = order[static_cast<std::size_t>(r)] % side, v = order[static_cast<std::size_t>(r)] / side;
    points.row(r) << u / double(side), v / double(side), 0.1 * std::sin(u * 0.1);
    const int cu = u * coarse / side, cv = v * coarse / side;
    for (int du = -1; du <= 1; ++du)
      for (int dv = -1; dv <= 1; ++dv) {
        const int a = std::clamp(cu + du, 0, coarse - 1), c = std::clamp(cv + dv, 0, coarse - 1);
        t.emplace_back(r, a + coarse * c, 1.0 / 9.0);
      }
  }
  Eigen::SparseMatrix<double, Eigen::RowMajor> b(side * side, coarse * coarse);
  b.setFromTriplets(t.begin(), t.end());
  const PoseTransferCsr<double> bd = makePoseTransferCsr<double>(b);
  const BlockedPoseTransfer blocked =
      blockPoseTransfer(bd, std::span<const double>(points.data(), static_cast<std::size_t>(points.size())));
  std::size_t consecutive = 0;  // weights stored by blocks of 8 consecutive rows
  for (int first = 0; first < side * side; first += kPoseBlockRows) {
    std::vector<int> columns;
    for (int r = first; r < std::min(side * side, first + kPoseBlockRows); ++r)
      for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(b, r); it; ++it) columns.push_back(static_cast<int>(it.col()));
    std::sort(columns.begin(), columns.end());
    consecutive += static_cast<std::size_t>(std::unique(columns.begin(), columns.end()) - columns.begin()) * kPoseBlockRows;
  }
  RecordProperty("fill", ::testing::PrintToString(blocked.fill(bd.nonzeros())));
  RecordProperty("fill_of_consecutive_rows", ::testing::PrintToString(static_cast<double>(consecutive) / static_cast<double>(bd.nonzeros())));
  EXPECT_LT(static_cast<double>(blocked.weights.size()), 0.5 * static_cast<double>(consecutive));
  EXPECT_LT(blocked.fill(bd.nonzeros()), 2.0);
}

TEST(BlockedPoseTransfer, RefusesWhatItCannotBlock) {
  const auto expectRefusal = [](const PoseTransferCsr<double>& b, std::span<const double> points, const char* what) {
    try {
      (void)blockPoseTransfer(b, points);
      ADD_FAILURE() << "accepted: expected \"" << what << "\"";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  const PoseTransferCsr<double> wide = makePoseTransferCsr<double>(randomB(10, 65537, 3));
  const std::vector<double> ten(30, 0.5);
  expectRefusal(wide, ten, "65537 tet vertices");
  PoseTransferCsr<double> broken = makePoseTransferCsr<double>(randomB(10, 5, 5));
  ASSERT_GT(broken.nonzeros(), 2);
  broken.columns[1] = 5;
  expectRefusal(broken, ten, "column index out of range");
  const PoseTransferCsr<double> fine = makePoseTransferCsr<double>(randomB(10, 5, 5));
  expectRefusal(fine, std::vector<double>(27, 0.5), "27 rest coordinates for 10 fine vertices");
  std::vector<double> nan_point = ten;
  nan_point[13] = std::numeric_limits<double>::quiet_NaN();
  expectRefusal(fine, nan_point, "not finite");
  EXPECT_NO_THROW((void)blockPoseTransfer(fine, ten));  // all points the same: one cell, still blocked
}

}  // namespace
}  // namespace tetrig
