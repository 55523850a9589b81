// PLY reading (ascii, binary little- and big-endian) and point-cloud writing.
//
// The whole file is read into memory and parsed in place: per-token iostream extraction is an
// order of magnitude too slow for the full-resolution scanned models (tens of MB of ascii).

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <exception>
#include <new>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "io/ply_pieces.h"
#include "io/text_util.h"
#include "vmap/files.h"
#include "vmap/io.h"
#include "vmap/parallel.h"

namespace vmap {

using detail::append_words;
using detail::fail;
using detail::FileBuffer;
using detail::is_blank;
using detail::load_file;
using detail::parse_int;
using detail::parse_real;
using detail::quoted;

namespace {

// ---- header --------------------------------------------------------------------------------

enum class Format { kAscii, kBinaryLittle, kBinaryBig };
enum class Type : uint8_t { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64 };

struct TypeName {
    std::string_view name;
    Type type;
};
constexpr TypeName kTypeNames[] = {
    {"char", Type::kInt8},       {"int8", Type::kInt8},       {"uchar", Type::kUInt8},
    {"uint8", Type::kUInt8},     {"short", Type::kInt16},     {"int16", Type::kInt16},
    {"ushort", Type::kUInt16},   {"uint16", Type::kUInt16},   {"int", Type::kInt32},
    {"int32", Type::kInt32},     {"uint", Type::kUInt32},     {"uint32", Type::kUInt32},
    {"float", Type::kFloat32},   {"float32", Type::kFloat32}, {"double", Type::kFloat64},
    {"float64", Type::kFloat64},
};

size_t type_size(Type t) {
    switch (t) {
        case Type::kInt8:
        case Type::kUInt8:
            return 1;
        case Type::kInt16:
        case Type::kUInt16:
            return 2;
        case Type::kInt32:
        case Type::kUInt32:
        case Type::kFloat32:
            return 4;
        case Type::kFloat64:
            return 8;
    }
    return 0;
}

bool is_integer(Type t) { return t != Type::kFloat32 && t != Type::kFloat64; }

std::string_view type_name(Type t) {
    for (const auto& entry : kTypeNames) {
        if (entry.type == t) return entry.name;
    }
    return "?";
}

// What a property feeds in the result; everything else is read (to validate and to advance)
// and dropped.
enum Role : uint8_t {
    kSkip,
    kX,
    kY,
    kZ,
    kNx,
    kNy,
    kNz,
    kRed,
    kGreen,
    kBlue,
    kRadius,
    kEmissionR,
    kEmissionG,
    kEmissionB,
    kSensorX,  // per-point sensor (scanner) position, for orienting estimated normals
    kSensorY,
    kSensorZ,
    kIndices,
    kRoleCount
};

struct Property {
    std::string name;
    Type type = Type::kFloat32;  // the item type for a list
    bool is_list = false;
    Type count_type = Type::kUInt8;
    Role role = kSkip;
};

struct Element {
    std::string name;
    uint64_t count = 0;
    std::vector<Property> properties;
    bool has_lists = false;
};

struct Header {
    Format format = Format::kAscii;
    std::vector<Element> elements;
    size_t data_offset = 0;
    size_t data_line = 0;  // line number of the first data line, for ascii messages
    uint64_t vertex_count = 0;
};

std::vector<std::string_view> split_words(std::string_view line) {
    std::vector<std::string_view> words;
    append_words(line.data(), line.data() + line.size(), words);
    return words;
}

std::string_view trim(std::string_view s) {
    while (!s.empty() && is_blank(s.front())) s.remove_prefix(1);
    while (!s.empty() && is_blank(s.back())) s.remove_suffix(1);
    return s;
}

Type parse_type(const std::string& path, size_t line, std::string_view word) {
    for (const auto& entry : kTypeNames) {
        if (entry.name == word) return entry.type;
    }
    fail(path, "header line ", line, ": unknown property type ", quoted(word));
}

Role vertex_role(std::string_view name) {
    static constexpr std::pair<std::string_view, Role> kNames[] = {
        {"x", kX},
        {"y", kY},
        {"z", kZ},
        {"nx", kNx},
        {"ny", kNy},
        {"nz", kNz},
        {"normal_x", kNx},  // PCL
        {"normal_y", kNy},
        {"normal_z", kNz},
        {"red", kRed},
        {"green", kGreen},
        {"blue", kBlue},
        {"r", kRed},
        {"g", kGreen},
        {"b", kBlue},
        {"diffuse_red", kRed},
        {"diffuse_green", kGreen},
        {"diffuse_blue", kBlue},
        {"radius", kRadius},
        {"emission_r", kEmissionR},
        {"emission_g", kEmissionG},
        {"emission_b", kEmissionB},
        {"sensor_x", kSensorX},
        {"sensor_y", kSensorY},
        {"sensor_z", kSensorZ},
        {"vp_x", kSensorX},
        {"vp_y", kSensorY},
        {"vp_z", kSensorZ},
        {"viewpoint_x", kSensorX},
        {"viewpoint_y", kSensorY},
        {"viewpoint_z", kSensorZ},
    };
    for (const auto& [n, role] : kNames) {
        if (n == name) return role;
    }
    return kSkip;
}

// Assigns roles to the vertex and face properties and checks that the ones vmap needs exist.
void assign_roles(const std::string& path, Header& header) {
    bool seen_vertex = false;
    bool seen_face = false;
    for (Element& element : header.elements) {
        if (element.name == "vertex") {
            if (seen_vertex) fail(path, "header: more than one 'vertex' element");
            seen_vertex = true;
            header.vertex_count = element.count;
            const Property* by_role[kRoleCount] = {};
            for (Property& p : element.properties) {
                p.role = vertex_role(p.name);
                if (p.role == kSkip) continue;
                if (by_role[p.role] != nullptr) {
                    fail(path, "header: element vertex: properties '", by_role[p.role]->name,
                         "' and '", p.name, "' both give the same value");
                }
                if (p.is_list) {
                    fail(path, "header: element vertex: property '", p.name,
                         "' must be a scalar, not a list");
                }
                by_role[p.role] = &p;
            }
            for (Role r : {kX, kY, kZ}) {
                if (by_role[r] == nullptr) {
                    fail(path, "header: element vertex has no '", "xyz"[r - kX], "' property");
                }
            }
            auto all_or_none = [&](Role a, const char* what) {
                const int n = (by_role[a] != nullptr) + (by_role[a + 1] != nullptr) +
                              (by_role[a + 2] != nullptr);
                if (n != 0 && n != 3) {
                    fail(path, "header: element vertex has only ", n, " of the 3 ", what,
                         " properties");
                }
            };
            all_or_none(kNx, "normal (nx, ny, nz)");
            all_or_none(kRed, "colour (red, green, blue)");
            all_or_none(kEmissionR, "emission (emission_r, emission_g, emission_b)");
            all_or_none(kSensorX, "sensor position (sensor_x, sensor_y, sensor_z)");
        } else if (element.name == "face") {
            if (seen_face) fail(path, "header: more than one 'face' element");
            seen_face = true;
            Property* indices = nullptr;
            for (Property& p : element.properties) {
                if (p.name != "vertex_indices" && p.name != "vertex_index") continue;
                if (indices != nullptr) {
                    fail(path, "header: element face has both '", indices->name, "' and '", p.name,
                         "'");
                }
                if (!p.is_list) fail(path, "header: element face: '", p.name, "' must be a list");
                if (!is_integer(p.type) || !is_integer(p.count_type)) {
                    fail(path, "header: element face: '", p.name,
                         "' must have integer count and index types");
                }
                p.role = kIndices;
                indices = &p;
            }
            if (indices == nullptr) {
                fail(path, "header: element face has no 'vertex_indices' list property");
            }
        }
    }
    if (!seen_vertex) fail(path, "header: no 'vertex' element");
}

// A hostile or corrupt count must not turn into a huge allocation or a near-endless loop: every
// element needs some minimum number of bytes, and the file has only so many left.
void check_counts_fit(const std::string& path, const Header& header, size_t data_size) {
    const bool ascii = header.format == Format::kAscii;
    // An ascii value is at least one character plus a separator; the very last needs no
    // separator, hence the one byte of slack.
    uint64_t left = data_size + (ascii ? 1 : 0);
    for (const Element& element : header.elements) {
        uint64_t per_element = 0;
        for (const Property& p : element.properties) {
            per_element += ascii ? 2 : type_size(p.is_list ? p.count_type : p.type);
        }
        if (per_element == 0) continue;
        if (element.count > left / per_element) {
            fail(path, "truncated: element ", element.name, ": ", element.count,
                 element.count == 1 ? " element" : " elements", " of at least ", per_element,
                 " bytes each cannot fit in the ", data_size, " bytes after the header");
        }
        left -= element.count * per_element;
    }
}

// The header's lines (from the magic to before 'end_header'), found before they are
// interpreted, so that a header cut short is reported as such and not as garbage keywords from
// the data that follows. Sets where the data starts.
std::vector<std::string_view> header_lines(const std::string& path, const FileBuffer& file,
                                           Header& header) {
    const std::string_view text(file.begin(), file.size);
    const size_t first_end = text.find('\n');
    if (trim(text.substr(0, first_end)) != "ply") {
        fail(path, "header: bad magic (not a PLY file: the first line is not 'ply')");
    }
    std::vector<std::string_view> lines;
    size_t pos = 0;
    bool found_end = false;
    while (pos < text.size()) {
        size_t eol = text.find('\n', pos);
        const size_t next = eol == std::string_view::npos ? text.size() : eol + 1;
        if (eol == std::string_view::npos) eol = text.size();
        const std::string_view line = text.substr(pos, eol - pos);
        pos = next;
        if (trim(line) == "end_header") {
            found_end = true;
            break;
        }
        lines.push_back(line);
    }
    if (!found_end) fail(path, "header: missing 'end_header'");

    header.data_offset = pos;
    header.data_line = lines.size() + 2;
    return lines;
}

using Words = std::vector<std::string_view>;

// "format <type> 1.0".
void parse_format(const std::string& path, size_t line_no, const Words& words, bool& have_format,
                  Header& header) {
    if (have_format) fail(path, "header line ", line_no, ": second 'format' line");
    if (words.size() != 3) {
        fail(path, "header line ", line_no, ": expected 'format <type> 1.0'");
    }
    if (words[1] == "ascii") {
        header.format = Format::kAscii;
    } else if (words[1] == "binary_little_endian") {
        header.format = Format::kBinaryLittle;
    } else if (words[1] == "binary_big_endian") {
        header.format = Format::kBinaryBig;
    } else {
        fail(path, "header line ", line_no, ": unknown format ", quoted(words[1]));
    }
    if (words[2] != "1.0" && words[2] != "1") {
        fail(path, "header line ", line_no, ": unsupported PLY version ", quoted(words[2]));
    }
    have_format = true;
}

// "element <name> <count>".
void parse_element(const std::string& path, size_t line_no, const Words& words, Header& header) {
    if (words.size() != 3) {
        fail(path, "header line ", line_no, ": expected 'element <name> <count>'");
    }
    int64_t count = 0;
    if (!words[2].empty() && words[2][0] == '-' && parse_int(words[2], count)) {
        fail(path, "header: element ", words[1], ": negative count ", count);
    }
    Element element;
    element.name = words[1];
    const char* e = words[2].data() + words[2].size();
    auto [ptr, ec] = std::from_chars(words[2].data(), e, element.count);
    if (ec == std::errc::result_out_of_range) {
        fail(path, "header: element ", words[1], ": count ", quoted(words[2]), " is too large");
    }
    if (ec != std::errc() || ptr != e) {
        fail(path, "header: element ", words[1], ": invalid count ", quoted(words[2]));
    }
    header.elements.push_back(std::move(element));
}

// "property <type> <name>" or "property list <count type> <item type> <name>".
void parse_property(const std::string& path, size_t line_no, const Words& words, Header& header) {
    if (header.elements.empty()) {
        fail(path, "header line ", line_no, ": property before any element");
    }
    Element& element = header.elements.back();
    Property p;
    if (words.size() >= 2 && words[1] == "list") {
        if (words.size() != 5) {
            fail(path, "header line ", line_no,
                 ": expected 'property list <count type> <item type> <name>'");
        }
        p.is_list = true;
        p.count_type = parse_type(path, line_no, words[2]);
        if (!is_integer(p.count_type)) {
            fail(path, "header line ", line_no, ": list count type must be an integer");
        }
        p.type = parse_type(path, line_no, words[3]);
        p.name = words[4];
        element.has_lists = true;
    } else {
        if (words.size() != 3) {
            fail(path, "header line ", line_no, ": expected 'property <type> <name>'");
        }
        p.type = parse_type(path, line_no, words[1]);
        p.name = words[2];
    }
    for (const Property& other : element.properties) {
        if (other.name == p.name) {
            fail(path, "header: element ", element.name, ": duplicate property '", p.name, "'");
        }
    }
    element.properties.push_back(std::move(p));
}

Header parse_header(const std::string& path, const FileBuffer& file) {
    Header header;
    const std::vector<std::string_view> lines = header_lines(path, file, header);
    bool have_format = false;
    for (size_t i = 1; i < lines.size(); ++i) {
        const size_t line_no = i + 1;
        const auto words = split_words(lines[i]);
        if (words.empty()) continue;
        const std::string_view keyword = words[0];
        if (keyword == "comment" || keyword == "obj_info") continue;
        if (keyword == "format") {
            parse_format(path, line_no, words, have_format, header);
        } else if (keyword == "element") {
            parse_element(path, line_no, words, header);
        } else if (keyword == "property") {
            parse_property(path, line_no, words, header);
        } else {
            fail(path, "header line ", line_no, ": unknown keyword ", quoted(keyword));
        }
    }
    if (!have_format) fail(path, "header: missing 'format' line");
    assign_roles(path, header);
    check_counts_fit(path, header, file.size - header.data_offset);
    return header;
}

// What the header declares that vmap does not use, for ModelData::notes.
void note_skipped(const std::string& path, const Header& header, ModelData& out) {
    std::string skipped;
    for (const Element& element : header.elements) {
        const bool known = element.name == "vertex" || element.name == "face";
        if (!known && element.count > 0) {
            skipped += (skipped.empty() ? "element " : ", element ") + element.name;
            continue;
        }
        for (const Property& p : element.properties) {
            if (p.role != kSkip || element.count == 0) continue;
            skipped += (skipped.empty() ? "" : ", ") + element.name + "." + p.name;
        }
    }
    if (!skipped.empty()) out.notes.push_back(path + ": ignored " + skipped);
}

// ---- data sources --------------------------------------------------------------------------
//
// Both sources present the data as a stream of values for the element loop below; each knows
// how to say where it is in an error message.

class BinarySource {
  public:
    BinarySource(const std::string& path, const char* begin, const char* end, bool big_endian)
        : path_(path),
          p_(begin),
          end_(end),
          swap_(big_endian != (std::endian::native == std::endian::big)) {}

    void begin_element(const Element& element, uint64_t index) {
        element_ = &element;
        index_ = index;
    }
    void end_element() {}

    double value(Type t) {
        const size_t n = type_size(t);
        if (static_cast<size_t>(end_ - p_) < n) truncated();
        const char* at = p_;
        p_ += n;
        switch (t) {
            case Type::kInt8:
                return load<int8_t>(at);
            case Type::kUInt8:
                return load<uint8_t>(at);
            case Type::kInt16:
                return load<int16_t>(at);
            case Type::kUInt16:
                return load<uint16_t>(at);
            case Type::kInt32:
                return load<int32_t>(at);
            case Type::kUInt32:
                return load<uint32_t>(at);
            case Type::kFloat32:
                return load<float>(at);
            case Type::kFloat64:
                return load<double>(at);
        }
        return 0;
    }

    uint64_t list_count(Type t) {
        const double n = value(t);
        if (n < 0) fail(path_, where(), ": negative list length ", static_cast<int64_t>(n));
        return static_cast<uint64_t>(n);
    }

    void skip_list(uint64_t count, Type t) {
        const size_t n = type_size(t);
        if (count > static_cast<uint64_t>(end_ - p_) / n) truncated();
        p_ += count * n;
    }

    void finish() {
        if (p_ != end_) {
            fail(path_, "unexpected ", end_ - p_,
                 " bytes after the last element (the header does not describe the data)");
        }
    }

    std::string where() const { return element_->name + " " + std::to_string(index_); }

  private:
    template <class T>
    T load(const char* at) const {
        unsigned char bytes[sizeof(T)];
        std::memcpy(bytes, at, sizeof(T));
        if (swap_) std::reverse(bytes, bytes + sizeof(T));
        T v;
        std::memcpy(&v, bytes, sizeof(T));
        return v;
    }

    [[noreturn]] void truncated() const {
        fail(path_, "truncated: expected ", element_->count, " ", element_->name,
             " elements, found ", index_);
    }

    const std::string& path_;
    const char* p_;
    const char* end_;
    bool swap_;
    const Element* element_ = nullptr;
    uint64_t index_ = 0;
};

class AsciiSource {
  public:
    AsciiSource(const std::string& path, const char* begin, const char* end, size_t first_line)
        : path_(path), p_(begin), end_(end), line_(first_line - 1) {}

    // Each element is one line; its tokens are split up front so that a short or long line is
    // reported with the counts that make the mistake obvious.
    void begin_element(const Element& element, uint64_t index) {
        element_ = &element;
        index_ = index;
        if (!next_line()) {
            fail(path_, "truncated: expected ", element.count, " ", element.name,
                 " elements, found ", index);
        }
        next_ = 0;
        size_t expected = element.properties.size();
        bool at_least = false;
        if (element.has_lists) {
            expected = 0;
            for (const Property& p : element.properties) {
                if (!p.is_list) {
                    ++expected;
                } else if (expected < tokens_.size()) {
                    const int64_t length = integer(tokens_[expected], p.count_type);
                    if (length < 0) fail(path_, where(), ": negative list length ", length);
                    expected += 1 + static_cast<size_t>(length);
                } else {
                    // The count itself is missing; the rest cannot be known.
                    at_least = true;
                    ++expected;
                }
            }
        }
        if (expected != tokens_.size()) {
            fail(path_, where(), ": expected ", at_least ? "at least " : "", expected,
                 " values, found ", tokens_.size());
        }
    }
    void end_element() {}

    double value(Type t) {
        const std::string_view token = tokens_[next_++];
        if (is_integer(t)) return static_cast<double>(integer(token, t));
        if (t == Type::kFloat32) {
            float v;
            if (parse_real(token, v)) return v;
        } else {
            double v;
            if (parse_real(token, v)) return v;
        }
        fail(path_, where(), ": invalid number ", quoted(token));
    }

    uint64_t list_count(Type t) { return static_cast<uint64_t>(value(t)); }

    void skip_list(uint64_t count, Type t) {
        for (uint64_t i = 0; i < count; ++i) value(t);
    }

    void finish() {
        while (p_ != end_ && (is_blank(*p_) || *p_ == '\n')) {
            if (*p_ == '\n') ++line_;
            ++p_;
        }
        if (p_ != end_) {
            fail(path_, "line ", line_ + 1, ": unexpected data after the last element");
        }
    }

    std::string where() const {
        return element_->name + " " + std::to_string(index_) + " (line " + std::to_string(line_) +
               ")";
    }

    // Past the next line that holds data, unparsed: its line number, or 0 when there is none.
    size_t skip_data_line() { return next_line() ? line_ : 0; }

  private:
    bool next_line() {
        tokens_.clear();
        while (p_ != end_ && tokens_.empty()) {
            const char* eol = static_cast<const char*>(std::memchr(p_, '\n', end_ - p_));
            if (eol == nullptr) eol = end_;
            ++line_;
            append_words(p_, eol, tokens_);
            p_ = eol == end_ ? end_ : eol + 1;
        }
        return !tokens_.empty();
    }

    // Integers are checked against their declared type: a value that does not fit means the
    // file and its header disagree.
    int64_t integer(std::string_view token, Type t) const {
        int64_t v = 0;
        if (!parse_int(token, v)) fail(path_, where(), ": invalid integer ", quoted(token));
        int64_t lo = 0, hi = 0;
        switch (t) {
            case Type::kInt8:
                lo = INT8_MIN, hi = INT8_MAX;
                break;
            case Type::kUInt8:
                lo = 0, hi = UINT8_MAX;
                break;
            case Type::kInt16:
                lo = INT16_MIN, hi = INT16_MAX;
                break;
            case Type::kUInt16:
                lo = 0, hi = UINT16_MAX;
                break;
            case Type::kInt32:
                lo = INT32_MIN, hi = INT32_MAX;
                break;
            default:
                lo = 0, hi = UINT32_MAX;
                break;
        }
        if (v < lo || v > hi) {
            fail(path_, where(), ": value ", v, " out of range for ", type_name(t));
        }
        return v;
    }

    const std::string& path_;
    const char* p_;
    const char* end_;
    size_t line_;
    std::vector<std::string_view> tokens_;
    size_t next_ = 0;
    const Element* element_ = nullptr;
    uint64_t index_ = 0;
};

// Colours stored as integers are taken to use the full range of their type (8 or 16 bits);
// 32-bit integer colours in the wild hold 0..255.
float colour_range(Type t) {
    switch (t) {
        case Type::kFloat32:
        case Type::kFloat64:
            return 1.0f;
        case Type::kInt16:
        case Type::kUInt16:
            return 65535.0f;
        default:
            return 255.0f;
    }
}

// Which of the vertex roles an element's properties fill, and the colour channels' ranges.
struct VertexLayout {
    bool has_normals = false, has_colors = false, has_radii = false, has_emission = false,
         has_sensors = false;
    float range[3] = {1, 1, 1};
};

VertexLayout vertex_layout(const Element& element) {
    VertexLayout lay;
    for (const Property& p : element.properties) {
        lay.has_normals |= p.role == kNx;
        lay.has_colors |= p.role == kRed;
        lay.has_radii |= p.role == kRadius;
        lay.has_emission |= p.role == kEmissionR;
        lay.has_sensors |= p.role == kSensorX;
        if (p.role >= kRed && p.role <= kBlue) lay.range[p.role - kRed] = colour_range(p.type);
    }
    return lay;
}

// Element i's scalars into v (by role) and its vertex indices into corners; other lists are
// skipped.
template <class Source>
void read_values(Source& source, const Element& element, uint64_t i, double* v,
                 std::vector<int64_t>& corners) {
    source.begin_element(element, i);
    for (const Property& p : element.properties) {
        if (!p.is_list) {
            v[p.role] = source.value(p.type);
            continue;
        }
        const uint64_t count = source.list_count(p.count_type);
        if (p.role != kIndices) {
            source.skip_list(count, p.type);
            continue;
        }
        corners.clear();
        for (uint64_t k = 0; k < count; ++k) {
            corners.push_back(static_cast<int64_t>(source.value(p.type)));
        }
    }
    source.end_element();
}

// Room for `count` more vertices (the layout's arrays); returns the first one's index.
size_t make_room(const VertexLayout& lay, uint64_t count, ModelData& out) {
    PointSet& points = out.points;
    const size_t base = points.positions.size();
    points.positions.resize(base + count);
    if (lay.has_normals) points.normals.resize(base + count);
    if (lay.has_colors) points.colors.resize(base + count);
    if (lay.has_radii) points.radii.resize(base + count);
    if (lay.has_emission) points.emission.resize(base + count);
    if (lay.has_sensors) out.sensors.resize(base + count);
    return base;
}

// Vertex `at` (of the room make_room made) from its values, each checked (finite; radius and
// emission not negative).
template <class Source>
void add_vertex(const std::string& path, const Source& source, const VertexLayout& lay,
                const double* v, ModelData& out, size_t at) {
    const std::array<double, 3>& o = out.points.origin;  // read_ply's origin
    const Vec3 pos{static_cast<float>(v[kX] - o[0]), static_cast<float>(v[kY] - o[1]),
                   static_cast<float>(v[kZ] - o[2])};
    if (!is_finite(pos)) {
        fail(path, source.where(), ": non-finite coordinate (", v[kX], ", ", v[kY], ", ", v[kZ],
             ")");
    }
    out.points.positions[at] = pos;
    if (lay.has_normals) {
        const Vec3 n{static_cast<float>(v[kNx]), static_cast<float>(v[kNy]),
                     static_cast<float>(v[kNz])};
        if (!is_finite(n)) {
            fail(path, source.where(), ": non-finite normal (", v[kNx], ", ", v[kNy], ", ", v[kNz],
                 ")");
        }
        out.points.normals[at] = n;
    }
    if (lay.has_colors) {
        const Vec3 c{static_cast<float>(v[kRed]) / lay.range[0],
                     static_cast<float>(v[kGreen]) / lay.range[1],
                     static_cast<float>(v[kBlue]) / lay.range[2]};
        if (!is_finite(c)) {
            fail(path, source.where(), ": non-finite colour (", v[kRed], ", ", v[kGreen], ", ",
                 v[kBlue], ")");
        }
        out.points.colors[at] = c;
    }
    if (lay.has_sensors) {
        const Vec3 q{static_cast<float>(v[kSensorX] - o[0]), static_cast<float>(v[kSensorY] - o[1]),
                     static_cast<float>(v[kSensorZ] - o[2])};
        if (!is_finite(q)) {
            fail(path, source.where(), ": non-finite sensor position (", v[kSensorX], ", ",
                 v[kSensorY], ", ", v[kSensorZ], ")");
        }
        out.sensors[at] = q;
    }
    if (lay.has_radii) {
        const float r = static_cast<float>(v[kRadius]);
        if (!std::isfinite(r) || r < 0) {
            fail(path, source.where(), ": invalid radius ", v[kRadius]);
        }
        out.points.radii[at] = r;
    }
    if (lay.has_emission) {
        const Vec3 e{static_cast<float>(v[kEmissionR]), static_cast<float>(v[kEmissionG]),
                     static_cast<float>(v[kEmissionB])};
        if (!is_finite(e) || e.x < 0 || e.y < 0 || e.z < 0) {
            fail(path, source.where(), ": invalid emission (", v[kEmissionR], ", ", v[kEmissionG],
                 ", ", v[kEmissionB], "): must be finite and >= 0");
        }
        out.points.emission[at] = e;
    }
}

// A face as a fan of triangles, its corners checked.
template <class Source>
void add_face(const std::string& path, const Source& source, const Header& header,
              const std::vector<int64_t>& corners, ModelData& out) {
    if (corners.size() < 3) {
        fail(path, source.where(), ": degenerate face with ", corners.size(),
             corners.size() == 1 ? " vertex" : " vertices");
    }
    for (int64_t c : corners) {
        if (c < 0 || static_cast<uint64_t>(c) >= header.vertex_count) {
            fail(path, source.where(), ": vertex index ", c, " out of range (", header.vertex_count,
                 " vertices)");
        }
    }
    for (size_t k = 1; k + 1 < corners.size(); ++k) {
        out.triangles.push_back({static_cast<uint32_t>(corners[0]),
                                 static_cast<uint32_t>(corners[k]),
                                 static_cast<uint32_t>(corners[k + 1])});
    }
}

template <class Source>
void read_data(const std::string& path, const Header& header, Source& source, ModelData& out) {
    std::vector<int64_t> corners;
    for (const Element& element : header.elements) {
        if (element.properties.empty()) continue;
        const bool is_vertex = element.name == "vertex";
        const bool is_face = element.name == "face";
        const VertexLayout lay = is_vertex ? vertex_layout(element) : VertexLayout{};
        const size_t base = is_vertex ? make_room(lay, element.count, out) : 0;
        if (is_face) out.triangles.reserve(element.count);
        double v[kRoleCount] = {};
        for (uint64_t i = 0; i < element.count; ++i) {
            read_values(source, element, i, v, corners);
            if (is_vertex) {
                add_vertex(path, source, lay, v, out, base + i);
            } else if (is_face) {
                add_face(path, source, header, corners, out);
            }
        }
    }
    source.finish();
}

// An ascii body of at least this many bytes is parsed in parallel (read_ascii), in pieces of
// about kAsciiPiece bytes.
constexpr size_t kParallelAscii = size_t(4) << 20;
constexpr size_t kAsciiPiece = size_t(1) << 20;

// Does [b, e) hold anything but blanks (a line the serial reader takes as an element)?
bool has_data(const char* b, const char* e) {
    for (; b != e; ++b)
        if (!is_blank(*b)) return true;
    return false;
}

// A large ascii body, in parallel, with read_data's result and read_data's error: the body is
// cut after line ends into pieces; a first pass counts each piece's line ends and lines with
// data (an element each, blank lines skipped, as AsciiSource does), which gives each piece the
// line number of its first line and the element its first data line holds; a second pass
// parses the pieces, each vertex into its own place and each piece's triangles into a list of
// its own, joined in file order. Every piece stops at its first error, and the error thrown is
// the first piece's: the first in the file, as the serial reader would report it; then a body
// too short for the header's counts, then data after the last element. (A 34 MB model, the
// dragon, took 0.17 s in one thread; docs/results.md.)
void read_ascii(const std::string& path, const Header& header, const char* data, const char* end,
                ModelData& out, size_t piece_bytes) {
    std::vector<const char*> cut{data};
    while (size_t(end - cut.back()) > piece_bytes) {
        const char* at = cut.back() + piece_bytes;
        const char* eol = static_cast<const char*>(std::memchr(at, '\n', size_t(end - at)));
        if (eol == nullptr || eol + 1 == end) break;
        cut.push_back(eol + 1);
    }
    cut.push_back(end);
    const size_t pieces = cut.size() - 1;
    // Per piece: line ends, and lines with data.
    std::vector<uint64_t> ends(pieces + 1, 0), rows(pieces + 1, 0);
    parallel_for(pieces, [&](size_t k) {
        uint64_t nl = 0, data_lines = 0;
        for (const char* p = cut[k]; p != cut[k + 1];) {
            const char* eol =
                static_cast<const char*>(std::memchr(p, '\n', size_t(cut[k + 1] - p)));
            const char* stop = eol ? eol : cut[k + 1];
            data_lines += has_data(p, stop);
            nl += eol != nullptr;
            p = eol ? eol + 1 : stop;
        }
        ends[k + 1] = nl, rows[k + 1] = data_lines;
    });
    for (size_t k = 0; k < pieces; ++k) ends[k + 1] += ends[k], rows[k + 1] += rows[k];
    // The elements that take lines (read_data skips those without properties), where each
    // one's lines start among the data lines, and each vertex element's place in the arrays.
    struct Group {
        const Element* element;
        uint64_t first;  // its first data line, counted over the whole body
        VertexLayout lay;
        size_t base;  // a vertex element's first index in the arrays
    };
    std::vector<Group> groups;
    uint64_t needed = 0;
    for (const Element& element : header.elements) {
        if (element.properties.empty()) continue;
        Group g{&element, needed, {}, 0};
        if (element.name == "vertex") {
            g.lay = vertex_layout(element);
            g.base = make_room(g.lay, element.count, out);
        }
        groups.push_back(g);
        needed += element.count;
    }
    std::vector<std::vector<std::array<uint32_t, 3>>> triangles(pieces);
    std::vector<std::exception_ptr> errors(pieces);
    parallel_for(pieces, [&](size_t k) {
        try {
            AsciiSource source(path, cut[k], cut[k + 1], header.data_line + ends[k]);
            ModelData faces;  // this piece's triangles (add_face's output)
            std::vector<int64_t> corners;
            double v[kRoleCount] = {};
            size_t gi = 0;
            for (uint64_t line = rows[k]; line < rows[k + 1]; ++line) {
                if (line >= needed) {
                    fail(path, "line ", source.skip_data_line(),
                         ": unexpected data after the last element");
                }
                while (gi + 1 < groups.size() && groups[gi + 1].first <= line) ++gi;
                const Group& g = groups[gi];
                const Element& element = *g.element;
                const uint64_t i = line - g.first;
                read_values(source, element, i, v, corners);
                if (element.name == "vertex") {
                    add_vertex(path, source, g.lay, v, out, g.base + i);
                } else if (element.name == "face") {
                    add_face(path, source, header, corners, faces);
                }
            }
            triangles[k] = std::move(faces.triangles);
        } catch (...) {
            errors[k] = std::current_exception();
        }
    });
    for (const std::exception_ptr& e : errors)
        if (e) std::rethrow_exception(e);
    if (rows[pieces] < needed) {
        size_t gi = 0;
        while (gi + 1 < groups.size() && groups[gi + 1].first <= rows[pieces]) ++gi;
        const Element& element = *groups[gi].element;
        fail(path, "truncated: expected ", element.count, " ", element.name, " elements, found ",
             rows[pieces] - groups[gi].first);
    }
    size_t total = 0;
    for (const auto& t : triangles) total += t.size();
    out.triangles.reserve(total);
    for (const auto& t : triangles) out.triangles.insert(out.triangles.end(), t.begin(), t.end());
}

// ---- writing -------------------------------------------------------------------------------

template <class T>
void put_le(std::string& out, T v) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &v, sizeof(T));
    if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
    out.append(bytes, sizeof(T));
}

// Shortest representation that reads back to the same float (double).
template <class T>
void put_text(std::string& out, T v) {
    char buffer[32];
    const auto result = std::to_chars(buffer, buffer + sizeof(buffer), v);
    out.append(buffer, result.ptr);
}

uint8_t colour_byte(float c) {
    if (!(c > 0.0f)) return 0;  // also NaN
    if (c >= 1.0f) return 255;
    return static_cast<uint8_t>(std::lround(c * 255.0f));
}

// read_ply, with an ascii body of at least `parallel_from` bytes parsed in pieces of about
// `piece_bytes`.
ModelData read_ply_pieces(const std::string& path, const std::array<double, 3>& origin,
                          size_t parallel_from, size_t piece_bytes) try {
    const FileBuffer file = load_file(path);
    if (file.size == 0) fail(path, "empty file");
    const Header header = parse_header(path, file);
    ModelData out;
    out.points.origin = origin;
    const char* data = file.begin() + header.data_offset;
    if (header.format == Format::kAscii && size_t(file.end() - data) >= parallel_from) {
        read_ascii(path, header, data, file.end(), out, std::max<size_t>(piece_bytes, 1));
    } else if (header.format == Format::kAscii) {
        AsciiSource source(path, data, file.end(), header.data_line);
        read_data(path, header, source, out);
    } else {
        BinarySource source(path, data, file.end(), header.format == Format::kBinaryBig);
        read_data(path, header, source, out);
    }
    note_skipped(path, header, out);
    return out;
} catch (const std::bad_alloc&) {
    // Counts are checked against the file size, so only a file too big for memory gets here.
    fail(path, "out of memory while reading");
}

}  // namespace

ModelData read_ply(const std::string& path, const std::array<double, 3>& origin) {
    return read_ply_pieces(path, origin, kParallelAscii, kAsciiPiece);
}

ModelData detail::read_ply_in_pieces(const std::string& path, size_t piece_bytes) {
    return read_ply_pieces(path, {0, 0, 0}, piece_bytes == 0 ? SIZE_MAX : 0, piece_bytes);
}

namespace {

// Refuses what read_ply would refuse, so that every file written can be read back; returns
// whether any point emits (the emission columns are written only then).
bool check_writable(const std::string& path, const PointSet& points,
                    const std::vector<Vec3>& sensors) {
    const size_t n = points.size();
    auto check_size = [&](size_t size, const char* what) {
        if (size != 0 && size != n) {
            fail(path, "cannot write: ", size, " ", what, " for ", n, " points");
        }
    };
    check_size(points.normals.size(), "normals");
    check_size(points.colors.size(), "colours");
    check_size(points.radii.size(), "radii");
    check_size(sensors.size(), "sensor positions");
    check_size(points.emission.size(), "emission values");
    bool emits = false;
    for (const Vec3& e : points.emission) emits |= e.x > 0 || e.y > 0 || e.z > 0;
    // Refuse what read_ply would refuse, so that every file written can be read back.
    for (size_t i = 0; i < n; ++i) {
        if (!is_finite(points.positions[i])) fail(path, "point ", i, ": non-finite position");
        if (points.has_normals() && !is_finite(points.normals[i])) {
            fail(path, "point ", i, ": non-finite normal");
        }
        if (!sensors.empty() && !is_finite(sensors[i])) {
            fail(path, "point ", i, ": non-finite sensor position");
        }
        if (points.has_radii() && !(points.radii[i] >= 0 && std::isfinite(points.radii[i]))) {
            fail(path, "point ", i, ": invalid radius ", points.radii[i]);
        }
        if (emits) {
            const Vec3 e = points.emission[i];
            if (!is_finite(e) || e.x < 0 || e.y < 0 || e.z < 0) {
                fail(path, "point ", i, ": invalid emission");
            }
        }
    }
    return emits;
}

bool shifted(const PointSet& points) { return points.has_origin(); }

std::string ply_header(const PointSet& points, bool binary, bool emits, bool sensed) {
    const size_t n = points.size();
    std::string header = "ply\nformat ";
    header += binary ? "binary_little_endian" : "ascii";
    header += " 1.0\ncomment written by vmap\nelement vertex " + std::to_string(n) + "\n";
    // Positions with an origin go back to the input's coordinates, in double (float would lose
    // what the origin kept).
    header += shifted(points) ? "property double x\nproperty double y\nproperty double z\n"
                              : "property float x\nproperty float y\nproperty float z\n";
    if (points.has_normals()) header += "property float nx\nproperty float ny\nproperty float nz\n";
    if (points.has_colors()) {
        header += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
    }
    if (points.has_radii()) header += "property float radius\n";
    if (emits) {
        header +=
            "property float emission_r\nproperty float emission_g\n"
            "property float emission_b\n";
    }
    if (sensed) {
        header +=
            shifted(points)
                ? "property double sensor_x\nproperty double sensor_y\nproperty double sensor_z\n"
                : "property float sensor_x\nproperty float sensor_y\nproperty float sensor_z\n";
    }
    header += "end_header\n";
    return header;
}

// A position in the binary (little-endian) encoding: back in the file's coordinates, in double,
// when the points have an origin.
void put_binary_position(std::string& chunk, const PointSet& points, Vec3 p) {
    if (shifted(points)) {
        const std::array<double, 3>& o = points.origin;
        put_le(chunk, double(p.x) + o[0]);
        put_le(chunk, double(p.y) + o[1]);
        put_le(chunk, double(p.z) + o[2]);
    } else {
        put_le(chunk, p.x);
        put_le(chunk, p.y);
        put_le(chunk, p.z);
    }
}

// Point i's columns in the binary (little-endian) encoding.
void put_binary_point(std::string& chunk, const PointSet& points, size_t i, bool emits,
                      const std::vector<Vec3>& sensors) {
    put_binary_position(chunk, points, points.positions[i]);
    if (points.has_normals()) {
        const Vec3 q = points.normals[i];
        put_le(chunk, q.x);
        put_le(chunk, q.y);
        put_le(chunk, q.z);
    }
    if (points.has_colors()) {
        const Vec3 c = points.colors[i];
        chunk += static_cast<char>(colour_byte(c.x));
        chunk += static_cast<char>(colour_byte(c.y));
        chunk += static_cast<char>(colour_byte(c.z));
    }
    if (points.has_radii()) put_le(chunk, points.radii[i]);
    if (emits) {
        put_le(chunk, points.emission[i].x);
        put_le(chunk, points.emission[i].y);
        put_le(chunk, points.emission[i].z);
    }
    if (!sensors.empty()) put_binary_position(chunk, points, sensors[i]);
}

// A position in the ASCII encoding (in the file's coordinates, as put_binary_position).
void put_text_position(std::string& chunk, const PointSet& points, Vec3 p) {
    if (shifted(points)) {
        const std::array<double, 3>& o = points.origin;
        put_text(chunk, double(p.x) + o[0]);
        chunk += ' ';
        put_text(chunk, double(p.y) + o[1]);
        chunk += ' ';
        put_text(chunk, double(p.z) + o[2]);
    } else {
        put_text(chunk, p.x);
        chunk += ' ';
        put_text(chunk, p.y);
        chunk += ' ';
        put_text(chunk, p.z);
    }
}

// Point i's line in the ASCII encoding.
void put_text_point(std::string& chunk, const PointSet& points, size_t i, bool emits,
                    const std::vector<Vec3>& sensors) {
    put_text_position(chunk, points, points.positions[i]);
    if (points.has_normals()) {
        const Vec3 q = points.normals[i];
        for (float f : {q.x, q.y, q.z}) {
            chunk += ' ';
            put_text(chunk, f);
        }
    }
    if (points.has_colors()) {
        const Vec3 c = points.colors[i];
        for (float channel : {c.x, c.y, c.z}) {
            chunk += ' ';
            chunk += std::to_string(colour_byte(channel));
        }
    }
    if (points.has_radii()) {
        chunk += ' ';
        put_text(chunk, points.radii[i]);
    }
    if (emits) {
        const Vec3 e = points.emission[i];
        for (float f : {e.x, e.y, e.z}) {
            chunk += ' ';
            put_text(chunk, f);
        }
    }
    if (!sensors.empty()) {
        chunk += ' ';
        put_text_position(chunk, points, sensors[i]);
    }
    chunk += '\n';
}

}  // namespace

void write_ply(const std::string& path, const PointSet& points, bool binary,
               const std::vector<Vec3>& sensors) {
    const bool emits = check_writable(path, points, sensors);
    io::AtomicFile file(path);
    file.write(ply_header(points, binary, emits, !sensors.empty()));
    std::string chunk;
    constexpr size_t kChunk = 1 << 20;
    chunk.reserve(kChunk + 256);
    for (size_t i = 0; i < points.size(); ++i) {
        if (binary) {
            put_binary_point(chunk, points, i, emits, sensors);
        } else {
            put_text_point(chunk, points, i, emits, sensors);
        }
        if (chunk.size() >= kChunk) {
            file.write(chunk);
            chunk.clear();
        }
    }
    file.write(chunk);
    file.commit();
}

}  // namespace vmap
