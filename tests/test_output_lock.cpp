// The lock of an output directory (pisco::OutputLock, include/pisco/output_file.hpp; docs/formats.md,
// "Errors and partial files"): one run at a time, and never a file that is not this program's touched:
// a lock file that is a link or holds a user's text is refused and left whole, a user's file whose name
// looks temporary survives, and only the temporaries a killed run's lock recorded are removed.
#include <gtest/gtest.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "pisco/error.hpp"
#include "pisco/output_file.hpp"
#include "support.hpp"

namespace {

namespace fs = std::filesystem;
using pisco::OutputLock;
using pisco_test::contains;

std::string read(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void write(const fs::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }

class OutputLockTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = pisco_test::fresh_test_dir("lock");
    out_ = dir_ / "out";
    fs::create_directories(out_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string refusal() {
    try {
      OutputLock lock(out_);
    } catch (const pisco::Error& e) {
      return e.what();
    }
    return "";
  }
  fs::path dir_, out_;
};

TEST_F(OutputLockTest, TakenReleasedAndRecorded) {
  {
    OutputLock lock(out_);
    EXPECT_TRUE(OutputLock::held(out_));
    const std::string text = read(out_ / OutputLock::file_name);
    EXPECT_TRUE(contains(text, "pid " + std::to_string(::getpid()) + "\n")) << text;
    EXPECT_TRUE(contains(text, "temporaries " + pisco::temporary_suffix() + "\n")) << text;
    // The same process again: refused, the first lock kept.
    const std::string second = refusal();
    EXPECT_TRUE(contains(second, "another run of this process is writing into this directory")) << second;
    EXPECT_TRUE(OutputLock::held(out_));
  }
  EXPECT_FALSE(OutputLock::held(out_));
  EXPECT_FALSE(fs::exists(out_ / OutputLock::file_name));
  EXPECT_TRUE(fs::is_empty(out_));
}

TEST_F(OutputLockTest, TemporarySuffixIsNoUsersName) {
  const std::string& s = pisco::temporary_suffix();
  EXPECT_EQ(s.rfind(".tmp-pisco-" + std::to_string(::getpid()) + "-", 0), 0u) << s;
  EXPECT_EQ(s.size(), (".tmp-pisco-" + std::to_string(::getpid()) + "-").size() + 16) << s;
  EXPECT_EQ(&s, &pisco::temporary_suffix());  // one for the process
}

// A lock file that is a symbolic link (to a victim file, or dangling) or a hard link of a user's file
// is refused, named, and the victim is left byte for byte.
TEST_F(OutputLockTest, LinksAreNeverFollowedOrTruncated) {
  const fs::path victim = dir_ / "thesis.tex";
  const std::string words = "Chapter 1. Years of work.\n";
  write(victim, words);
  fs::create_symlink(victim, out_ / OutputLock::file_name);
  std::string m = refusal();
  EXPECT_TRUE(contains(m, (out_ / OutputLock::file_name).string() + ": is a symbolic link, not a lock file of pisco-vk"))
      << m;
  EXPECT_EQ(read(victim), words);
  EXPECT_TRUE(fs::is_symlink(out_ / OutputLock::file_name));

  fs::remove(out_ / OutputLock::file_name);
  fs::create_symlink(dir_ / "nowhere", out_ / OutputLock::file_name);  // dangling: not created through
  m = refusal();
  EXPECT_TRUE(contains(m, "is a symbolic link")) << m;
  EXPECT_FALSE(fs::exists(dir_ / "nowhere"));

  fs::remove(out_ / OutputLock::file_name);
  fs::create_hard_link(victim, out_ / OutputLock::file_name);
  m = refusal();
  EXPECT_TRUE(contains(m, "has 2 hard links, so it is not a lock file of pisco-vk")) << m;
  EXPECT_EQ(read(victim), words);
  EXPECT_TRUE(fs::exists(out_ / OutputLock::file_name));

  fs::remove(out_ / OutputLock::file_name);
  fs::create_directory(out_ / OutputLock::file_name);
  m = refusal();
  EXPECT_TRUE(contains(m, "not a regular file")) << m;
  EXPECT_TRUE(fs::is_directory(out_ / OutputLock::file_name));

  fs::remove(out_ / OutputLock::file_name);
  ASSERT_EQ(::mkfifo((out_ / OutputLock::file_name).c_str(), 0644), 0);  // opened without blocking
  m = refusal();
  EXPECT_TRUE(contains(m, "not a regular file")) << m;
}

// A regular file of that name holding anything this program does not write is left alone.
TEST_F(OutputLockTest, AUsersFileOfThatNameIsLeftAlone) {
  for (const std::string text : {std::string("my notes\n"), std::string("pisco-vk output lock\npid 12\nmine\n"),
                                 std::string(5000, 'x'), std::string("pisco-vk output lock\npid 12\ntemporaries .txt\n")}) {
    write(out_ / OutputLock::file_name, text);
    const std::string m = refusal();
    EXPECT_TRUE(contains(m, (out_ / OutputLock::file_name).string() + ": ") &&
                contains(m, "not a lock file of pisco-vk") && contains(m, "it is left alone"))
        << m;
    EXPECT_EQ(read(out_ / OutputLock::file_name), text);
  }
}

// The temporaries of a killed run: exactly the names ending with the suffix its lock file recorded.
// A user's NAME.tmp-DIGITS (once matched by a pattern) and another run's temporaries survive.
TEST_F(OutputLockTest, OnlyTheKilledRunsRecordedTemporariesAreRemoved) {
  const std::string dead = ".tmp-pisco-999999-0123456789abcdef";
  write(out_ / OutputLock::file_name, "pisco-vk output lock\npid 999999\ntemporaries " + dead + "\n");
  write(out_ / ("tod.h5" + dead), "half a TOD");
  write(out_ / ("maps.fits" + dead), "half a map");
  write(out_ / "notes.tmp-20261127", "a user's notes");
  write(out_ / "maps.fits.tmp-999999", "a user's file");
  write(out_ / "tod.h5.tmp-pisco-999999-fedcba9876543210", "not the recorded run's");
  fs::create_directory(out_ / ("folder" + dead));  // only regular files are removed
  std::vector<std::string> said;
  {
    OutputLock lock(out_, [&](const std::string& m) { said.push_back(m); });
    EXPECT_FALSE(fs::exists(out_ / ("tod.h5" + dead)));
    EXPECT_FALSE(fs::exists(out_ / ("maps.fits" + dead)));
    EXPECT_EQ(read(out_ / "notes.tmp-20261127"), "a user's notes");
    EXPECT_EQ(read(out_ / "maps.fits.tmp-999999"), "a user's file");
    EXPECT_TRUE(fs::exists(out_ / "tod.h5.tmp-pisco-999999-fedcba9876543210"));
    EXPECT_TRUE(fs::is_directory(out_ / ("folder" + dead)));
    ASSERT_EQ(said.size(), 2u);
    for (const auto& m : said) EXPECT_TRUE(contains(m, "a temporary file left by process 999999, which has ended")) << m;
  }
  // A lock left empty (killed before it wrote) or by an earlier version (a process id alone) is taken.
  write(out_ / OutputLock::file_name, "");
  { OutputLock lock(out_); }
  write(out_ / OutputLock::file_name, "4242\n");
  { OutputLock lock(out_); }
  EXPECT_FALSE(fs::exists(out_ / OutputLock::file_name));
}

// Another process holds it: refused, naming that process; the holder's lock file is untouched.
TEST_F(OutputLockTest, AnotherProcessHoldingItIsNamed) {
  int ready[2], release[2];
  ASSERT_EQ(::pipe(ready), 0);
  ASSERT_EQ(::pipe(release), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    int status = 0;
    try {
      OutputLock lock(out_);
      char c = 1;
      (void)!::write(ready[1], &c, 1);
      (void)!::read(release[0], &c, 1);
    } catch (...) {
      status = 1;
    }
    ::_exit(status);
  }
  char c = 0;
  ASSERT_EQ(::read(ready[0], &c, 1), 1);
  const std::string before = read(out_ / OutputLock::file_name);
  const std::string m = refusal();
  EXPECT_TRUE(contains(m, out_.string() + ": another pisco-vk run (process " + std::to_string(child) + ")")) << m;
  EXPECT_EQ(read(out_ / OutputLock::file_name), before);
  (void)!::write(release[1], &c, 1);
  int status = 0;
  ::waitpid(child, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  { OutputLock lock(out_); }  // free again
}

// remove_temporary_files (a process stopping at once) releases the locks too: the directory is left
// as a finished run leaves it.
TEST_F(OutputLockTest, StoppingAtOnceReleasesTheLock) {
  OutputLock lock(out_);
  pisco::remove_temporary_files();
  EXPECT_FALSE(fs::exists(out_ / OutputLock::file_name));
  EXPECT_FALSE(OutputLock::held(out_));
  { OutputLock again(out_); }
}

}  // namespace
