// Images: sRGB conversion, composition, marks and labels, PNG files (include/vmap/render.h).
#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "vmap/error.h"
#include "vmap/files.h"
#include "vmap/render.h"

// The stb headers are third-party C: keep their warnings out of ours.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wunused-but-set-variable"
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb_image_write.h>
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_STATIC
#define STBI_ONLY_PNG
#include <stb_image.h>
#pragma GCC diagnostic pop

namespace vmap {

uint8_t linear_to_srgb8(float c) {
    if (!(c > 0)) return 0;  // also NaN
    if (c >= 1) return 255;
    const float v = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1 / 2.4f) - 0.055f;
    return uint8_t(std::lround(v * 255.f));
}

float srgb8_to_linear(uint8_t b) {
    const float v = b / 255.f;
    return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

Image side_by_side(std::span<const Image> images) {
    if (images.empty()) throw Error("side_by_side: no images");
    constexpr int kGap = 6;
    Image out;
    for (const Image& im : images) {
        out.width += im.width;
        out.height = std::max(out.height, im.height);
    }
    out.width += kGap * int(images.size() - 1);
    out.rgb.assign(size_t(out.width) * out.height * 3, 255);  // white gaps
    int x0 = 0;
    for (const Image& im : images) {
        const int y0 = (out.height - im.height) / 2;
        for (int y = 0; y < im.height; ++y)
            std::memcpy(out.pixel(x0, y0 + y), im.pixel(0, y), size_t(im.width) * 3);
        x0 += im.width + kGap;
    }
    return out;
}

void draw_dot(Image& img, float cx, float cy, float radius, const uint8_t rgb[3]) {
    const float outer = radius + 1.5f;
    const int x0 = std::max(0, int(std::floor(cx - outer))),
              x1 = std::min(img.width - 1, int(std::ceil(cx + outer)));
    const int y0 = std::max(0, int(std::floor(cy - outer))),
              y1 = std::min(img.height - 1, int(std::ceil(cy + outer)));
    for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
            const float dx = x + 0.5f - cx, dy = y + 0.5f - cy;
            const float d = std::sqrt(dx * dx + dy * dy);
            uint8_t* p = img.pixel(x, y);
            if (d <= radius) {
                std::memcpy(p, rgb, 3);
            } else if (d <= outer) {
                p[0] = p[1] = p[2] = 0;  // dark rim, so the dot reads on any background
            }
        }
}

namespace {

// 5x7 glyphs, one string of 7 rows of 5 columns each ('#' = ink).
const char* glyph(char c) {
    switch (c) {
        case '0':
            return " ### #   ##  ### # ###  ##   # ### ";
        case '1':
            return "  #   ##    #    #    #    #   ### ";
        case '2':
            return " ### #   #    #   #   #   #   #####";
        case '3':
            return "#####   #   #     #     ##   # ### ";
        case '4':
            return "   #   ##  # # #  # #####   #    # ";
        case '5':
            return "######    ####     #    ##   # ### ";
        case '6':
            return "  ##  #   #    #### #   ##   # ### ";
        case '7':
            return "#####    #   #   #   #    #    #   ";
        case '8':
            return " ### #   ##   # ### #   ##   # ### ";
        case '9':
            return " ### #   ##   # ####    #   #  ##  ";
        case 'a':
            return "           ###     # #####   # ####";
        case 'e':
            return "           ### #   #######     ### ";
        case 'g':
            return "      #####   ##   # ####    # ### ";
        case 'h':
            return "#    #    # ## ##  ##   ##   ##   #";
        case 'i':
            return "  #        ##    #    #    #   ### ";
        case 'l':
            return " ##    #    #    #    #    #   ### ";
        case 'm':
            return "          ## # # # ## # ##   ##   #";
        case 'o':
            return "           ### #   ##   ##   # ### ";
        case 'r':
            return "          # ## ##  ##    #    #    ";
        case 's':
            return "           #####     ###     ##### ";
        case 't':
            return " #    #   ###   #    #    #  #  ## ";
        case 'v':
            return "          #   ##   ##   # # #   #  ";
        case 'x':
            return "          #   # # #   #   # # #   #";
        case '=':
            return "          #####     #####          ";
        case ':':
            return "      ##   ##        ##   ##       ";
        case '-':
            return "               #####               ";
        case '.':
            return "                          ##   ##  ";
        case ',':
            return "                     ##    #   #   ";
        default:
            return nullptr;
    }
}

}  // namespace

void draw_text(Image& img, int x, int y, const std::string& text, int scale, const uint8_t rgb[3]) {
    scale = std::max(scale, 1);
    for (size_t k = 0; k < text.size(); ++k) {
        const char* g = glyph(text[k]);
        const int gx = x + int(k) * 6 * scale;
        if (g == nullptr) continue;
        const size_t len = std::strlen(g);
        for (int row = 0; row < 7; ++row)
            for (int col = 0; col < 5; ++col) {
                const size_t at = size_t(row) * 5 + col;
                if (at >= len || g[at] != '#') continue;
                for (int dy = 0; dy < scale; ++dy)
                    for (int dx = 0; dx < scale; ++dx) {
                        const int px = gx + col * scale + dx, py = y + row * scale + dy;
                        if (px >= 0 && py >= 0 && px < img.width && py < img.height)
                            std::memcpy(img.pixel(px, py), rgb, 3);
                    }
            }
    }
}

void write_png(const std::string& path, const Image& img) {
    if (img.width < 1 || img.height < 1 || img.rgb.size() != size_t(img.width) * img.height * 3)
        throw Error(fmt::format("{}: cannot write an image of {}x{} with {} bytes", path, img.width,
                                img.height, img.rgb.size()));
    std::vector<uint8_t> bytes;
    auto sink = [](void* ctx, void* data, int size) {
        auto* out = static_cast<std::vector<uint8_t>*>(ctx);
        out->insert(out->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
    };
    if (!stbi_write_png_to_func(sink, &bytes, img.width, img.height, 3, img.rgb.data(),
                                img.width * 3))
        throw Error(fmt::format("{}: PNG encoding failed", path));
    io::write_file_atomic(
        path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

Image read_png(const std::string& path) {
    int w = 0, h = 0, c = 0;
    uint8_t* data = stbi_load(path.c_str(), &w, &h, &c, 3);
    if (data == nullptr)
        throw Error(fmt::format("{}: cannot read PNG: {}", path, stbi_failure_reason()));
    Image img;
    img.width = w;
    img.height = h;
    img.rgb.assign(data, data + size_t(w) * h * 3);
    stbi_image_free(data);
    return img;
}

}  // namespace vmap
