// Output files (base/atomic_file.hpp and the Matrix Market writers): a regular file is
// replaced atomically, a symbolic link is followed (the link stays a link, its target is
// written), a FIFO or a character device is written in place (it stays what it was), a
// directory is refused, and check_output_path finds an impossible write before any work
// — for write_file_atomically, rename_file, write_matrix_market and
// write_dense_matrix_market alike. The reference is the file system itself (lstat, the
// bytes read back, the reader of a FIFO).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>

#include "base/atomic_file.hpp"
#include "strata/errors.hpp"
#include "strata/matrix_market.hpp"

namespace strata {
namespace {

namespace fs = std::filesystem;

class OutputFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("strata_output_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string read(const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
  }
  // every file of the folder is one of `names` (no temporary left behind)
  void expect_only(std::initializer_list<std::string> names) const {
    std::size_t count = 0;
    for (const auto& e : fs::directory_iterator(dir_)) {
      ++count;
      bool known = false;
      for (const std::string& n : names) known |= e.path().filename() == n;
      EXPECT_TRUE(known) << "unexpected file " << e.path();
    }
    EXPECT_EQ(count, names.size());
  }
  fs::path dir_;
};

// The writers under test, each writing something recognisable to a path.
struct Writer {
  const char* name;
  std::function<void(const std::string&)> write;
  const char* marker;  // text the written file contains
};

const double kValues[3] = {1.5, -2.25, 3.0};

std::vector<Writer> writers() {
  SparseMatrix a;
  a.n_rows = a.n_cols = 2;
  a.offsets = {0, 1, 2};
  a.indices = {0, 1};
  a.values = {4.0, 5.0};
  return {
      {"write_file_atomically",
       [](const std::string& p) { write_file_atomically(p, "hello strata\n"); }, "hello strata"},
      {"write_dense_matrix_market",
       [](const std::string& p) { write_dense_matrix_market(p, kValues, 3, 1); }, "-2.25"},
      {"write_matrix_market", [a](const std::string& p) { write_matrix_market(p, a); }, "2 2 5"}};
}

TEST_F(OutputFile, RegularFileReplacedAtomically) {
  for (const Writer& w : writers()) {
    SCOPED_TRACE(w.name);
    const std::string p = path("out.txt");
    { std::ofstream(p) << "old\n"; }
    w.write(p);
    EXPECT_NE(read(p).find(w.marker), std::string::npos);
    expect_only({"out.txt"});
    fs::remove(p);
    w.write(p);  // a new file
    EXPECT_NE(read(p).find(w.marker), std::string::npos);
    fs::remove(p);
  }
}

TEST_F(OutputFile, SymbolicLinkIsFollowed) {
  for (const Writer& w : writers()) {
    SCOPED_TRACE(w.name);
    fs::create_directories(dir_ / "sub");
    { std::ofstream(path("sub/target.txt")) << "old\n"; }
    // a relative link through a second link
    fs::create_symlink("sub/target.txt", dir_ / "link1");
    fs::create_symlink("link1", dir_ / "link2");
    w.write(path("link2"));
    EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir_ / "link1")));
    EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir_ / "link2")));
    EXPECT_NE(read(path("sub/target.txt")).find(w.marker), std::string::npos);
    // a dangling link: its target is created
    fs::create_symlink("sub/new.txt", dir_ / "dangling");
    w.write(path("dangling"));
    EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir_ / "dangling")));
    EXPECT_NE(read(path("sub/new.txt")).find(w.marker), std::string::npos);
    fs::remove_all(dir_ / "sub");
    for (const char* l : {"link1", "link2", "dangling"}) fs::remove(dir_ / l);
  }
}

TEST_F(OutputFile, FifoIsWrittenInPlace) {
  for (const Writer& w : writers()) {
    SCOPED_TRACE(w.name);
    const std::string p = path("fifo");
    ASSERT_EQ(::mkfifo(p.c_str(), 0600), 0) << std::strerror(errno);
    check_output_path(p);  // does not open it (its reader would see end-of-file)
    std::string got;
    std::thread reader([&] { got = read(p); });
    w.write(p);
    reader.join();
    struct stat st {};
    ASSERT_EQ(::lstat(p.c_str(), &st), 0);
    EXPECT_TRUE(S_ISFIFO(st.st_mode));
    EXPECT_NE(got.find(w.marker), std::string::npos);
    expect_only({"fifo"});
    fs::remove(p);
  }
}

TEST_F(OutputFile, CharacterDeviceIsWrittenInPlace) {
  for (const Writer& w : writers()) {
    SCOPED_TRACE(w.name);
    check_output_path("/dev/null");
    w.write("/dev/null");
    struct stat st {};
    ASSERT_EQ(::lstat("/dev/null", &st), 0);
    EXPECT_TRUE(S_ISCHR(st.st_mode));
    if (::access("/dev/full", W_OK) == 0) {  // a device that refuses the bytes
      try {
        w.write("/dev/full");
        ADD_FAILURE() << "writing /dev/full did not fail";
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("/dev/full"), std::string::npos) << e.what();
      }
      ASSERT_EQ(::lstat("/dev/full", &st), 0);
      EXPECT_TRUE(S_ISCHR(st.st_mode));
    }
  }
}

TEST_F(OutputFile, ImpossibleTargetsAreRefused) {
  auto expect_refused = [](const std::function<void()>& f, const std::string& what) {
    try {
      f();
      ADD_FAILURE() << "no error; expected '" << what << "'";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  const std::string folder = dir_.string();
  const std::string missing = path("no/such/file.txt");
  expect_refused([&] { check_output_path(folder); }, "is a directory");
  expect_refused([&] { check_output_path(missing); }, "does not exist");
  for (const Writer& w : writers()) {
    SCOPED_TRACE(w.name);
    expect_refused([&] { w.write(folder); }, "is a directory");
    expect_refused([&] { w.write(missing); }, "no/such/file.txt");
  }
  fs::create_symlink("loop_b", dir_ / "loop_a");
  fs::create_symlink("loop_a", dir_ / "loop_b");
  expect_refused([&] { check_output_path(path("loop_a")); }, "symbolic links");
  expect_refused([&] { check_output_path(""); }, "empty name");
  expect_only({"loop_a", "loop_b"});  // nothing was created
}

// rename_file (the simulation's finished histories): onto the target of a link, into a
// FIFO in place.
TEST_F(OutputFile, RenameFollowsTheSameRules) {
  { std::ofstream(path("part")) << "rows\n"; }
  { std::ofstream(path("target.csv")) << "old\n"; }
  fs::create_symlink("target.csv", dir_ / "link.csv");
  rename_file(path("part"), path("link.csv"));
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir_ / "link.csv")));
  EXPECT_EQ(read(path("target.csv")), "rows\n");
  EXPECT_FALSE(fs::exists(dir_ / "part"));

  { std::ofstream(path("part")) << "more rows\n"; }
  ASSERT_EQ(::mkfifo(path("fifo").c_str(), 0600), 0);
  std::string got;
  std::thread reader([&] { got = read(path("fifo")); });
  rename_file(path("part"), path("fifo"));
  reader.join();
  EXPECT_EQ(got, "more rows\n");
  struct stat st {};
  ASSERT_EQ(::lstat(path("fifo").c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  EXPECT_FALSE(fs::exists(dir_ / "part"));
}

}  // namespace
}  // namespace strata
