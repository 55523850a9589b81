// Queries from the V-map against the brute-force leaf-pair matrix.
#include <gtest/gtest.h>

#include <random>

#include "test_util.h"
#include "vmap/error.h"

namespace vmap {
namespace {

class QueryTest : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        vm_ = new VisibilityMap(
            build_vmap(test::sample(test::oracle_path("room-with-block.json"), 3000, 2),
                       test::cpu_params(7, 3)));
        m_ = new std::vector<uint8_t>(test::brute_matrix(*vm_));
    }
    static void TearDownTestSuite() {
        delete vm_;
        delete m_;
    }
    static bool brute(uint32_t i, uint32_t j) {
        const int32_t L = vm_->octree().num_leaves();
        const int32_t a = vm_->octree().leaf_of_point(vm_->inverse()[i]);
        const int32_t b = vm_->octree().leaf_of_point(vm_->inverse()[j]);
        return (*m_)[size_t(a) * L + b];
    }
    static VisibilityMap* vm_;
    static std::vector<uint8_t>* m_;
};
VisibilityMap* QueryTest::vm_ = nullptr;
std::vector<uint8_t>* QueryTest::m_ = nullptr;

TEST_F(QueryTest, PointPairMatchesBruteForceInInputOrder) {
    std::mt19937 rng(4);
    std::uniform_int_distribution<uint32_t> pick(0, uint32_t(vm_->points().size() - 1));
    int vis = 0, hid = 0, same = 0;
    for (int it = 0; it < 20000; ++it) {
        const uint32_t i = pick(rng), j = pick(rng);
        const PairVisibility v = vm_->query(i, j);
        const int32_t a = vm_->octree().leaf_of_point(vm_->inverse()[i]);
        const int32_t b = vm_->octree().leaf_of_point(vm_->inverse()[j]);
        if (a == b) {
            ASSERT_EQ(v, PairVisibility::kSameLeaf);
            ++same;
            continue;
        }
        ASSERT_EQ(v == PairVisibility::kVisible, brute(i, j)) << i << " " << j;
        ASSERT_EQ(vm_->query(j, i), v) << "symmetric";
        (v == PairVisibility::kVisible ? vis : hid)++;
    }
    EXPECT_GT(vis, 1000);
    EXPECT_GT(hid, 1000);
    EXPECT_GT(same, 0);
}

TEST_F(QueryTest, InputIdsSurviveTheOctreeReordering) {
    // Point i of the V-map (input order) is the point the scene sampled as i.
    const PointSet ps = test::sample(test::oracle_path("room-with-block.json"), 3000, 2);
    for (uint32_t i = 0; i < ps.size(); i += 37)
        ASSERT_EQ(vm_->points().positions[vm_->inverse()[i]], ps.positions[i]);
}

TEST_F(QueryTest, VisibleSetMatchesBruteForce) {
    for (uint32_t i : {0u, 17u, 555u, 2999u}) {
        std::vector<uint32_t> expect;
        const int32_t a = vm_->octree().leaf_of_point(vm_->inverse()[i]);
        for (uint32_t j = 0; j < vm_->points().size(); ++j) {
            const int32_t b = vm_->octree().leaf_of_point(vm_->inverse()[j]);
            if (a != b && brute(i, j)) expect.push_back(j);
        }
        EXPECT_EQ(vm_->visible_set(i), expect) << "point " << i;
    }
}

TEST_F(QueryTest, OutOfRangeIdsAreRejected) {
    EXPECT_THROW(vm_->query(0, 3000), Error);
    EXPECT_THROW(vm_->visible_set(123456), Error);
}

}  // namespace
}  // namespace vmap
