// Reading a model by its extension (src/io/model.cpp), and the downloaded models.
#include "io_test_util.h"

namespace vmap {
namespace {

// ---- dispatch --------------------------------------------------------------------------------

TEST(Model, ReaderIsChosenByExtensionIgnoringCase) {
    ScratchDir dir;
    const std::string off = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    EXPECT_EQ(read_model(dir.write("a.off", off)).triangles.size(), 1u);
    EXPECT_EQ(read_model(dir.write("b.OFF", off)).triangles.size(), 1u);
    const std::string ply = make_ply("binary_little_endian", {xyz_vertices(kSquare)});
    EXPECT_EQ(read_model(dir.write("c.ply", ply)).points.size(), 4u);
    EXPECT_EQ(read_model(dir.write("d.Ply", ply)).points.size(), 4u);
    // The extension decides, not the contents.
    EXPECT_READ_ERROR(read_model(dir.write("e.ply", off)), "e.ply", "bad magic");
}

TEST(Model, UnknownOrMissingExtensionsAreRejected) {
    ScratchDir dir;
    EXPECT_READ_ERROR(read_model(dir.write("m.3ds", "v 0 0 0\n")), "m.3ds",
                      "unknown model format '.3ds'");
    EXPECT_READ_ERROR(read_model(dir.write("model", "OFF\n0 0 0\n")), "model", "no extension");
    EXPECT_READ_ERROR(read_model(dir.path("gone.ply")), "gone.ply: no such file");
}

// ---- the real models (scripts/fetch-models.sh) -------------------------------------------------

// The models are downloaded, not committed; a fresh checkout without them skips these.
#define REQUIRE_MODEL(name)                                                         \
    if (!fs::exists(kModels + name)) {                                              \
        GTEST_SKIP() << kModels << name << " missing: run scripts/fetch-models.sh"; \
    }

void expect_valid_mesh(const ModelData& m) {
    for (const Tri& t : m.triangles) {
        for (uint32_t i : t) ASSERT_LT(i, m.points.size());
    }
    for (const Vec3& p : m.points.positions) ASSERT_TRUE(is_finite(p));
}

// A downloaded model and the vertex and triangle counts it is published with.
struct PublishedModel {
    const char* name;
    size_t vertices, triangles;
};

// Each model reads with its published counts into a valid mesh; a missing one skips the test
// (call this last in a test).
void expect_published_counts(std::initializer_list<PublishedModel> models) {
    for (const PublishedModel& c : models) {
        SCOPED_TRACE(c.name);
        REQUIRE_MODEL(c.name);
        const ModelData m = read_model(kModels + c.name);
        EXPECT_EQ(m.points.size(), c.vertices);
        EXPECT_EQ(m.triangles.size(), c.triangles);
        expect_valid_mesh(m);
    }
}

TEST(RealModels, OffModelsHaveTheirPublishedCounts) {
    expect_published_counts({{"bunny.off", 37706, 75408},
                             {"armadillo.off", 26002, 52000},
                             {"elephant.off", 2775, 5558}});
}

TEST(RealModels, DragonsHaveTheirPublishedCounts) {
    expect_published_counts({{"dragon_res4.ply", 5205, 11102},
                             {"dragon_res3.ply", 22998, 47794},
                             {"dragon_res2.ply", 100250, 202520}});
}

TEST(RealModels, FullDragonReadsQuickly) {
    REQUIRE_MODEL("dragon.ply");
    const auto start = std::chrono::steady_clock::now();
    const ModelData m = read_ply(kModels + "dragon.ply");
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_EQ(m.points.size(), 437645u);
    EXPECT_EQ(m.triangles.size(), 871414u);
    expect_valid_mesh(m);
    // Reported, not asserted: debug and sanitizer builds are many times slower.
    RecordProperty("dragon_read_seconds", std::to_string(seconds));
    std::printf("    dragon.ply (33 MB ascii) read in %.3f s\n", seconds);
}

}  // namespace
}  // namespace vmap
