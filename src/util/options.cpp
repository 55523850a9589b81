// The names of the library's choices (vmap/options.h), in one table per enum.
#include "vmap/options.h"

#include <fmt/format.h>

#include <utility>

#include "vmap/error.h"

namespace vmap {
namespace {

template <class E>
struct Names;
template <>
struct Names<Backend> {
    static constexpr std::pair<const char*, Backend> table[] = {
        {"auto", Backend::kAuto}, {"cpu", Backend::kCpu}, {"cuda", Backend::kCuda}};
};
template <>
struct Names<OccluderSearch> {
    // "spheres" and "bresenham" are the names the searches had before (files, scripts).
    static constexpr std::pair<const char*, OccluderSearch> table[] = {
        {"boxes", OccluderSearch::kBoxes},
        {"grid", OccluderSearch::kGridWalk},
        {"spheres", OccluderSearch::kBoxes},
        {"bresenham", OccluderSearch::kGridWalk}};
};
template <>
struct Names<Construction> {
    static constexpr std::pair<const char*, Construction> table[] = {
        {"auto", Construction::kAuto},
        {"nodes", Construction::kNodes},
        {"leaf-pairs", Construction::kLeafPairs}};
};
template <>
struct Names<GiRefine> {
    static constexpr std::pair<const char*, GiRefine> table[] = {{"blocks", GiRefine::kBlocks},
                                                                 {"links", GiRefine::kLinks}};
};

template <>
struct Names<SamplePattern> {
    static constexpr std::pair<const char*, SamplePattern> table[] = {
        {"uniform", SamplePattern::kUniform}, {"blue-noise", SamplePattern::kBlueNoise}};
};

template <class E>
const char* lookup(E e) {
    for (const auto& [name, value] : Names<E>::table)
        if (value == e) return name;
    return "?";
}

// The canonical names: the first entry of each value.
template <class E>
std::string expected() {
    std::vector<std::string> names;
    for (const auto& [name, value] : Names<E>::table)
        if (lookup(value) == name) names.emplace_back(name);
    std::string s;
    for (size_t k = 0; k < names.size(); ++k)
        s += (k == 0 ? "" : k + 1 == names.size() ? " or " : ", ") + names[k];
    return s;
}

}  // namespace

const char* name_of(Backend e) { return lookup(e); }
const char* name_of(OccluderSearch e) { return lookup(e); }
const char* name_of(Construction e) { return lookup(e); }
const char* name_of(GiRefine e) { return lookup(e); }
const char* name_of(SamplePattern e) { return lookup(e); }

template <class E>
std::vector<std::string> names_of() {
    std::vector<std::string> out;
    for (const auto& [name, value] : Names<E>::table) out.emplace_back(name);
    return out;
}

template <class E>
E parse(std::string_view name, std::string_view what) {
    for (const auto& [n, value] : Names<E>::table)
        if (name == n) return value;
    throw Error(fmt::format("{}: unknown value '{}' (expected {})", what, name, expected<E>()));
}

template std::vector<std::string> names_of<Backend>();
template std::vector<std::string> names_of<OccluderSearch>();
template std::vector<std::string> names_of<Construction>();
template std::vector<std::string> names_of<GiRefine>();
template std::vector<std::string> names_of<SamplePattern>();
template Backend parse<Backend>(std::string_view, std::string_view);
template OccluderSearch parse<OccluderSearch>(std::string_view, std::string_view);
template Construction parse<Construction>(std::string_view, std::string_view);
template GiRefine parse<GiRefine>(std::string_view, std::string_view);
template SamplePattern parse<SamplePattern>(std::string_view, std::string_view);

}  // namespace vmap
