// Scratch directories, whole-file reads and writes, error checks and build cases shared by tests.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "vmap/error.h"

namespace vmap::test {

// A directory of its own for each test, so tests can run in parallel (ctest -j).
class ScratchDir {
  public:
    ScratchDir() {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ = std::filesystem::temp_directory_path() /
               ("vmap_test_" + std::to_string(::getpid()) + "_" + info->test_suite_name() + "_" +
                info->name());
        std::filesystem::remove_all(dir_);
        std::filesystem::create_directories(dir_);
    }
    ~ScratchDir() {
        std::error_code ec;
        std::filesystem::remove_all(dir_, ec);
    }
    ScratchDir(const ScratchDir&) = delete;
    ScratchDir& operator=(const ScratchDir&) = delete;

    std::string path(const std::string& name) const { return (dir_ / name).string(); }
    const std::filesystem::path& dir() const { return dir_; }

    // Writes `bytes` to `name` in the directory; returns its path.
    std::string write(const std::string& name, std::string_view bytes) const {
        const std::string p = path(name);
        std::ofstream out(p, std::ios::binary);
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
        EXPECT_TRUE(out.good()) << p;
        return p;
    }

    // The names in the directory, sorted.
    std::vector<std::string> files() const {
        std::vector<std::string> names;
        for (const auto& entry : std::filesystem::directory_iterator(dir_)) {
            names.push_back(entry.path().filename().string());
        }
        std::sort(names.begin(), names.end());
        return names;
    }

  private:
    std::filesystem::path dir_;
};

// The whole of a file, as bytes.
inline std::string slurp(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream out;
    out << in.rdbuf();
    return out.str();
}

// Replaces the file at `path` with `bytes`.
inline void spit(const std::string& path, std::string_view bytes) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    ASSERT_TRUE(out.good()) << path;
}

// Calls f, which must throw vmap::Error whose one-line message holds every one of `parts`.
inline void expect_error(const std::function<void()>& f,
                         const std::vector<std::string_view>& parts) {
    try {
        f();
    } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.find('\n'), std::string::npos) << "message is not one line: " << what;
        for (std::string_view part : parts) {
            EXPECT_NE(what.find(part), std::string::npos)
                << "message \"" << what << "\" lacks \"" << part << "\"";
        }
        return;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "threw a non-vmap exception: " << e.what();
        return;
    }
    ADD_FAILURE() << "did not throw";
}

// One case of a parameterised build test: `points` samples of `scene` in an octree of
// `height` and `leaf_points`. `scene` is a shipped scene's name, or, when it holds a '/', a
// file under tests/data/oracle.
struct BuildCase {
    const char* scene;
    uint64_t points;
    int height, leaf_points;

    // The scene file the case samples.
    std::string file() const {
        return std::string(scene).find('/') == std::string::npos
                   ? std::string(VMAP_SOURCE_DIR) + "/scenes/" + scene + ".json"
                   : std::string(VMAP_TEST_DATA) + "/oracle/" + scene;
    }
};

// The test name of a case: <scene>_h<height>_lp<leaf_points>, then _n<points> if `with_points`,
// with every character but letters and digits made an underscore.
inline std::string case_name(const BuildCase& c, bool with_points) {
    std::string s = std::string(c.scene) + "_h" + std::to_string(c.height) + "_lp" +
                    std::to_string(c.leaf_points);
    if (with_points) s += "_n" + std::to_string(c.points);
    for (char& ch : s)
        if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
    return s;
}

}  // namespace vmap::test
