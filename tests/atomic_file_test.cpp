// The one writer every output goes through (vmap/files.h): writers to one path never mix,
// failures leave nothing behind, and output paths are checked before any work.
#include "vmap/files.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "test_files.h"
#include "vmap/error.h"

namespace vmap {
namespace {

namespace fs = std::filesystem;
using test::expect_error;
using test::ScratchDir;
using test::slurp;
using test::spit;

std::string pattern(char c, size_t n) {
    std::string s(n, c);
    for (size_t k = 0; k < n; k += 4096) s[k] = char('0' + k % 10);
    return s;
}

// Two writers of one path, open at the same time, their writes interleaved: whichever commits
// last wins, and the file is that writer's bytes, all of them. (Two writers sharing one fixed
// temporary name would truncate and overwrite each other's bytes.)
TEST(AtomicFile, TwoOverlappingWritersLeaveOneCompleteFile) {
    ScratchDir dir;
    const std::string p = dir.path("out.bin");
    const std::string a = pattern('a', 3 << 20), b = pattern('b', 2 << 20);
    for (int last = 0; last < 2; ++last) {
        io::AtomicFile fa(p), fb(p);
        EXPECT_NE(fa.temp_path(), fb.temp_path());
        const size_t half_a = a.size() / 2, half_b = b.size() / 2;
        fa.write(a.data(), half_a);
        fb.write(b.data(), half_b);
        fa.write(a.data() + half_a, a.size() - half_a);
        fb.write(b.data() + half_b, b.size() - half_b);
        if (last == 0) {
            fa.commit();
            EXPECT_EQ(slurp(p), a);
            fb.commit();
            EXPECT_EQ(slurp(p), b);
        } else {
            fb.commit();
            fa.commit();
            EXPECT_EQ(slurp(p), a);
        }
    }
    EXPECT_EQ(dir.files(), std::vector<std::string>{"out.bin"});
}

TEST(AtomicFile, ManyThreadsSavingOnePathLeaveOneOfTheirFiles) {
    ScratchDir dir;
    const std::string p = dir.path("out.txt");
    std::vector<std::thread> threads;
    for (int t = 0; t < 8; ++t)
        threads.emplace_back([&, t] {
            for (int k = 0; k < 20; ++k) io::write_file_atomic(p, pattern(char('a' + t), 70000));
        });
    for (auto& th : threads) th.join();
    const std::string got = slurp(p);
    ASSERT_EQ(got.size(), 70000u);
    EXPECT_EQ(got, pattern(got[1], 70000));
    EXPECT_EQ(dir.files(), std::vector<std::string>{"out.txt"});
}

TEST(AtomicFile, AnAbandonedWriteLeavesTheOldFileAndNoTemporary) {
    ScratchDir dir;
    const std::string p = dir.path("keep.txt");
    spit(p, "old");
    {
        io::AtomicFile f(p);
        f.write("new bytes that are never committed");
    }
    EXPECT_EQ(slurp(p), "old");
    EXPECT_EQ(dir.files(), std::vector<std::string>{"keep.txt"});
}

TEST(AtomicFile, OutputPathsAreCheckedBeforeAnyWork) {
    ScratchDir dir;
    expect_error([&] { io::check_output_path(dir.path("nodir/out.vmap"), "-o"); },
                 {"nodir/out.vmap", "-o", "does not exist"});
    fs::create_directory(dir.path("folder"));
    expect_error([&] { io::check_output_path(dir.path("folder"), "-o"); }, {"is a folder"});
    ASSERT_EQ(::mkfifo(dir.path("fifo").c_str(), 0600), 0);
    expect_error([&] { io::check_output_path(dir.path("fifo")); }, {"fifo", "FIFO"});
    spit(dir.path("file"), "x");
    expect_error([&] { io::check_output_path(dir.path("file/out.png")); }, {"not a folder"});
    EXPECT_NO_THROW(io::check_output_path(dir.path("file")));
    EXPECT_NO_THROW(io::check_output_path(dir.path("new.png")));
    if (::geteuid() != 0) {  // root writes anywhere
        fs::create_directory(dir.path("ro"));
        fs::permissions(dir.path("ro"), fs::perms::owner_read | fs::perms::owner_exec);
        expect_error([&] { io::check_output_path(dir.path("ro/x.png")); }, {"cannot write"});
    }
}

TEST(AtomicFile, InputsThatAreNotFilesAreRefusedWithoutOpening) {
    ScratchDir dir;
    ASSERT_EQ(::mkfifo(dir.path("f.ply").c_str(), 0600), 0);  // opening it would block
    expect_error([&] { io::check_input_path(dir.path("f.ply")); }, {"f.ply", "FIFO"});
    expect_error([&] { io::check_input_path(dir.path("")); }, {"is a folder"});
    expect_error([&] { io::check_input_path(dir.path("none.ply")); }, {"none.ply", "no such file"});
}

TEST(AtomicFile, SameFileComparesIdentityNotSpelling) {
    ScratchDir dir;
    const std::string p = dir.path("a.json"), q = dir.path("b.json");
    spit(p, "{}");
    spit(q, "{}");
    fs::create_symlink(p, dir.path("link.json"));
    fs::create_hard_link(p, dir.path("hard.json"));
    EXPECT_TRUE(io::same_file(p, dir.path("link.json")));
    EXPECT_TRUE(io::same_file(p, dir.path("hard.json")));
    EXPECT_TRUE(io::same_file(p, dir.path("./a.json")));
    EXPECT_FALSE(io::same_file(p, q));
    EXPECT_FALSE(io::same_file(p, dir.path("missing")));
}

}  // namespace
}  // namespace vmap
