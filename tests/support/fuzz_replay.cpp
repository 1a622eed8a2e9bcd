// Replays a libFuzzer target's seed corpus (drivers/fuzz/corpus/<name>/, runtime/fuzz/corpus/<name>/)
// through the target's LLVMFuzzerTestOneInput in the ordinary test run, with every prefix of every
// file too. The targets trap on a broken invariant, so a failure here is a crash with the file name
// printed first. Built once per target (test_fuzz_replay_<name>, with TETRIG_FUZZ_CORPUS set).
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

#ifndef TETRIG_FUZZ_CORPUS
#error "define TETRIG_FUZZ_CORPUS to the corpus directory"
#endif

TEST(FuzzReplay, SeedCorpusAndAllPrefixes) {
  const std::filesystem::path dir = TETRIG_FUZZ_CORPUS;
  ASSERT_TRUE(std::filesystem::is_directory(dir)) << dir;
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    std::ifstream in(entry.path(), std::ios::binary);
    const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::fprintf(stderr, "replaying %s (%zu bytes)\n", entry.path().filename().c_str(), bytes.size());
    for (std::size_t len = 0; len <= bytes.size(); ++len) {
      EXPECT_EQ(LLVMFuzzerTestOneInput(bytes.data(), len), 0);
    }
    ++files;
  }
  EXPECT_GT(files, 0);
}
