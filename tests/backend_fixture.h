// Tests on every backend (like Open3D's PermuteDevices): a value-parameterised fixture whose
// instances run the same case on the CPU and on the CUDA GPU. The CPU instance always runs; the
// CUDA one is always listed and reports SKIPPED, with the reason, where this build has no CUDA
// or no device is usable at run time. Each instance checks against the case's own oracle (brute
// force, closed forms), not against the other backend.
//
//   class VmapOracle : public test::OnEachBackendWith<BuildCase> {};
//   TEST_P(VmapOracle, LinksCoverExactlyTheVisibleLeafPairs) {
//       build_vmap(..., build_params(height, leaf_points));  // on backend()
//   }
//   VMAP_ON_EACH_BACKEND_WITH(VmapOracle, ::testing::Values(...), name_of_case);
//
// The instances are named Cpu/<Suite>.<Test>/<case> and Cuda/<Suite>.<Test>/<case>, so that
// --gtest_filter='Cuda/*' runs every GPU instance of an executable (scripts/device.sh gpu).
#pragma once

#include <gtest/gtest.h>

#include <cctype>
#include <memory>
#include <ostream>
#include <string>
#include <tuple>

#include "test_util.h"
#include "util/device.h"
#include "visibility/backend.h"
#include "vmap/error.h"
#include "vmap/gi.h"
#include "vmap/options.h"

namespace vmap::test {

// Why `b` cannot run in this process; empty when it can (the CPU always can).
inline std::string why_unusable(Backend b) {
    if (b != Backend::kCuda) return {};
    static const std::string why = [] {
        std::string w;
        return detail::cuda_device(&w) ? std::string() : (w.empty() ? "no usable device" : w);
    }();
    return why;
}

// The fixture's backend-dependent helpers, shared by the two fixtures below.
class BackendCase {
  public:
    virtual ~BackendCase() = default;
    virtual Backend backend() const = 0;

    // The build parameters of test::cpu_params, on this backend.
    BuildParams build_params(int max_height, int leaf_points) const {
        BuildParams bp = cpu_params(max_height, leaf_points);
        bp.backend = backend();
        return bp;
    }
    // GI parameters on this backend.
    GiParams gi_params(float theta, int bounces, GiRefine refine = GiRefine::kBlocks) const {
        GiParams p;
        p.backend = backend();
        p.refine = refine;
        p.theta = theta;
        p.bounces = bounces;
        return p;
    }
    // That a build's or solver's stats name this backend as the one that ran ("cpu (...)",
    // "cuda (...)"): no silent fallback.
    void expect_ran_here(const std::string& ran) const {
        EXPECT_EQ(ran.rfind(name_of(backend()), 0), 0u) << "ran on " << ran;
    }
    // The leaf-pair evaluator of this backend (visibility/backend.h), never null.
    std::unique_ptr<detail::Backend> leaf_pair_backend() const {
        if (backend() == Backend::kCpu) return detail::make_cpu_backend();
        std::string why;
        auto b = detail::make_cuda_backend(&why);
        if (!b) throw Error("no CUDA backend: " + why);
        return b;
    }

  protected:
    // In SetUp: GTEST_SKIP with the reason when the backend cannot run here.
    void skip_if_unusable() const {
        const std::string why = why_unusable(backend());
        if (!why.empty()) GTEST_SKIP() << name_of(backend()) << ": " << why;
    }
};

// One case on every backend: GetParam() is the backend.
class OnEachBackend : public ::testing::TestWithParam<Backend>, public BackendCase {
  public:
    Backend backend() const override { return GetParam(); }

  protected:
    void SetUp() override { skip_if_unusable(); }
};

// A table of cases on every backend: param() is the case.
template <class Case>
class OnEachBackendWith : public ::testing::TestWithParam<std::tuple<Backend, Case>>,
                          public BackendCase {
  public:
    Backend backend() const override { return std::get<0>(this->GetParam()); }
    const Case& param() const { return std::get<1>(this->GetParam()); }

  protected:
    void SetUp() override { skip_if_unusable(); }
};

// gtest names for OnEachBackend instances: the backend's.
inline std::string backend_name(const ::testing::TestParamInfo<Backend>& i) {
    return name_of(i.param);
}

// The case type of an OnEachBackendWith<Case> suite.
template <class Suite>
using CaseOf = std::tuple_element_t<1, typename Suite::ParamType>;

// gtest names for OnEachBackendWith<Case> instances: the case's name by `name(case)`.
template <class Case, class Name>
auto case_names(Name name) {
    return [name](const ::testing::TestParamInfo<std::tuple<Backend, Case>>& i) {
        std::string s = name(std::get<1>(i.param));
        for (char& ch : s)
            if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '_') ch = '_';
        return s;
    };
}

}  // namespace vmap::test

namespace vmap {
// gtest prints a Backend by its name (ctest's test names show parameter values).
inline void PrintTo(Backend b, std::ostream* os) { *os << name_of(b); }
}  // namespace vmap

// In a plain TEST of the GPU alone: GTEST_SKIP with the reason when no device is usable.
#define VMAP_REQUIRE_GPU()                                                          \
    do {                                                                            \
        const std::string why_ = ::vmap::test::why_unusable(::vmap::Backend::kCuda); \
        if (!why_.empty()) GTEST_SKIP() << "no GPU: " << why_;                      \
    } while (0)

// Instantiates Suite (an OnEachBackend) as Cpu/Suite.* and Cuda/Suite.*.
#define VMAP_ON_EACH_BACKEND(Suite)                                                   \
    INSTANTIATE_TEST_SUITE_P(Cpu, Suite, ::testing::Values(::vmap::Backend::kCpu),    \
                             ::vmap::test::backend_name);                             \
    INSTANTIATE_TEST_SUITE_P(Cuda, Suite, ::testing::Values(::vmap::Backend::kCuda),  \
                             ::vmap::test::backend_name)

// Instantiates Suite (an OnEachBackendWith<Case>) over the generator `cases`, names by
// name(const Case&), as Cpu/Suite.*/<name> and Cuda/Suite.*/<name>.
#define VMAP_ON_EACH_BACKEND_WITH(Suite, cases, name)                                          \
    INSTANTIATE_TEST_SUITE_P(                                                                  \
        Cpu, Suite, ::testing::Combine(::testing::Values(::vmap::Backend::kCpu), cases),       \
        ::vmap::test::case_names<::vmap::test::CaseOf<Suite>>(name));            \
    INSTANTIATE_TEST_SUITE_P(                                                                  \
        Cuda, Suite, ::testing::Combine(::testing::Values(::vmap::Backend::kCuda), cases),     \
        ::vmap::test::case_names<::vmap::test::CaseOf<Suite>>(name))
