//
// Tests of Yocto/FileIO's memory budget: the limit is a parameter of each
// load, and its default follows physical memory and ulimit -v. (The outputs
// and path helpers are tested with the savers that use them: test_output,
// test_image.)
//

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>
#include <yocto/yocto_fileio.h>

#include <filesystem>
#include <fstream>

using namespace yocto;

TEST(fileio, memory_limit_is_a_parameter_of_each_load) {
  auto error = std::string{};
  EXPECT_TRUE(check_load_memory("a.ply", "the shape", 1 << 20, 1 << 20, error));
  EXPECT_FALSE(check_load_memory("a.ply", "the shape", (1 << 20) + 1, 1 << 20, error));
  EXPECT_EQ(error, "a.ply: the shape needs 2 MiB, over the memory limit of 1 MiB (--max-memory)");
  // A file over the limit a load is given is refused; the default takes it.
  auto filename = (std::filesystem::temp_directory_path() /
                   ("yocto-fileio-" + std::to_string(getpid()) + ".txt"))
                      .string();
  std::ofstream(filename) << std::string(3 << 20, 'x');
  auto text = std::string{};
  EXPECT_FALSE(load_text(filename, text, error, 2 << 20));
  EXPECT_EQ(error, filename + ": reading the file needs 3 MiB, over the memory limit of 2 MiB "
                              "(--max-memory)");
  EXPECT_TRUE(text.empty());
  EXPECT_TRUE(load_text(filename, text, error)) << error;
  EXPECT_EQ(text.size(), (size_t)3 << 20);
  std::filesystem::remove(filename);
}

TEST(fileio, default_memory_limit_follows_memory_and_ulimit) {
  auto physical = (double)sysconf(_SC_PHYS_PAGES) * (double)sysconf(_SC_PAGE_SIZE);
  EXPECT_GT(default_memory_limit(), 0);
  EXPECT_LE(default_memory_limit(), 0.75 * physical);
  // Under an address-space limit lower than memory (ulimit -v), 3/4 of what
  // it leaves beside what the process maps already (its libraries: less than
  // 512 MiB here). Nothing is allocated while the limit is lowered but the
  // read of /proc/self/statm.
  auto saved = rlimit{};
  ASSERT_EQ(getrlimit(RLIMIT_AS, &saved), 0);
  auto lowered     = saved;
  lowered.rlim_cur = std::min((rlim_t)1 << 30, saved.rlim_max);
  if (setrlimit(RLIMIT_AS, &lowered) != 0) GTEST_SKIP() << "cannot set RLIMIT_AS";
  auto limit = default_memory_limit();
  setrlimit(RLIMIT_AS, &saved);
  auto lowest = 0.75 * std::min(physical, (double)lowered.rlim_cur);
  EXPECT_LE(limit, lowest);
#ifndef YOCTO_SANITIZED  // the sanitizers map terabytes of shadow memory
  EXPECT_LT(limit, lowest);
  EXPECT_GT(limit, lowest - 0.75 * 512 * (1 << 20));
#endif
}
