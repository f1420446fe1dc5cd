// Everything of the renderer that is not OpenGL: PNG files, the colour ramp, camera framing, flat meshes, the
// pixel font, the legend and the contact sheet.

#include "render/render.h"

#include "core/errors.h"
#include "io/atomic_file.h"

#include <fmt/format.h>
#include <png.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <map>
#include <system_error>

namespace ganache {

namespace {

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

}  // namespace

void writePng(const std::filesystem::path& path, const Image& image) {
    writeAtomically(path, [&](const std::filesystem::path& tmp) {
        File f(std::fopen(tmp.c_str(), "wb"));
        if (!f) throw std::system_error(errno, std::generic_category(), "cannot open it");
        png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
        png_infop info = png ? png_create_info_struct(png) : nullptr;
        if (!info) throw std::runtime_error("libpng: out of memory");
        if (setjmp(png_jmpbuf(png))) {
            const int err = errno;
            png_destroy_write_struct(&png, &info);
            throw std::system_error(err, std::generic_category(), "libpng could not write the image");
        }
        png_init_io(png, f.get());
        png_set_IHDR(png, info, png_uint_32(image.width), png_uint_32(image.height), 8, PNG_COLOR_TYPE_RGB,
                     PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
        png_set_compression_level(png, 6);
        png_write_info(png, info);
        for (int y = 0; y < image.height; ++y) png_write_row(png, image.pixel(0, y));
        png_write_end(png, nullptr);
        png_destroy_write_struct(&png, &info);
        if (std::fclose(f.release()) != 0)
            throw std::system_error(errno, std::generic_category(), "writing the image failed");
    });
}

Image readPng(const std::filesystem::path& path) {
    File f(std::fopen(path.c_str(), "rb"));
    if (!f) throw InputError(fmt::format("{}: cannot open the image", path.string()));
    png_byte signature[8] = {};
    if (std::fread(signature, 1, 8, f.get()) != 8 || png_sig_cmp(signature, 0, 8) != 0)
        throw InputError(fmt::format("{}: not a PNG file", path.string()));
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png ? png_create_info_struct(png) : nullptr;
    if (!info) throw std::runtime_error("libpng: out of memory");
    Image image;
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_read_struct(&png, &info, nullptr);
        throw InputError(fmt::format("{}: damaged PNG file", path.string()));
    }
    png_init_io(png, f.get());
    png_set_sig_bytes(png, 8);
    png_read_info(png, info);
    png_set_strip_16(png);
    png_set_palette_to_rgb(png);
    png_set_gray_to_rgb(png);
    png_set_strip_alpha(png);
    png_read_update_info(png, info);
    image.width = int(png_get_image_width(png, info));
    image.height = int(png_get_image_height(png, info));
    image.rgb.resize(std::size_t(image.width) * image.height * 3);
    for (int y = 0; y < image.height; ++y) png_read_row(png, image.pixel(0, y), nullptr);
    png_destroy_read_struct(&png, &info, nullptr);
    return image;
}

Vec3 colourRamp(Real t) {
    // Stops of a viridis-like ramp: lightness rises monotonically from dark blue-violet to yellow.
    static const Vec3 stops[] = {{0.267, 0.005, 0.329}, {0.230, 0.322, 0.546}, {0.128, 0.567, 0.551},
                                 {0.369, 0.789, 0.383}, {0.993, 0.906, 0.144}};
    t = std::clamp<Real>(std::isfinite(t) ? t : 0, 0, 1) * 4;
    const int k = std::min(3, int(t));
    return stops[k] + (t - k) * (stops[k + 1] - stops[k]);
}

Vec3 skyColour(Real h) { return Vec3(0.93, 0.93, 0.92) + std::clamp<Real>(h, 0, 1) * (Vec3(0.62, 0.71, 0.82) - Vec3(0.93, 0.93, 0.92)); }

Camera frameBounds(const Vec3& lo, const Vec3& hi, Real aspect, Real fovDegrees) {
    Camera c;
    c.fovDegrees = fovDegrees;
    c.target = 0.5 * (lo + hi);
    const Real radius = std::max<Real>(0.5 * (hi - lo).norm(), 1e-3);
    // The bounding sphere fits the narrower of the two fields of view, with a margin.
    const Real halfV = 0.5 * fovDegrees * M_PI / 180;
    const Real halfH = std::atan(std::tan(halfV) * aspect);
    const Real distance = 1.1 * radius / std::sin(std::min(halfV, halfH));
    c.position = c.target + distance * Vec3(0.55, 0.45, 1.0).normalized();
    return c;
}

DrawMesh flatMesh(const std::vector<Vec3>& vertices, const std::vector<std::array<std::uint32_t, 3>>& triangles,
                  const Vec3& colour) {
    DrawMesh m;
    m.colour = colour;
    m.gloss = 0.15;
    m.points.reserve(3 * triangles.size());
    for (const auto& t : triangles) {
        const Vec3 n = (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]).normalized();
        const auto base = std::uint32_t(m.points.size());
        for (std::uint32_t v : t) m.points.push_back(vertices[v]), m.normals.push_back(n);
        m.triangles.push_back({base, base + 1, base + 2});
    }
    return m;
}

DrawMesh sphereMesh(const Vec3& centre, Real radius, int segments, const Vec3& colour) {
    DrawMesh m;
    m.colour = colour;
    const int nu = segments, nv = segments / 2;
    for (int j = 0; j <= nv; ++j)
        for (int i = 0; i <= nu; ++i) {
            const Real theta = M_PI * j / nv, phi = 2 * M_PI * i / nu;
            const Vec3 n(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
            m.points.push_back(centre + radius * n);
            m.normals.push_back(n);
        }
    for (int j = 0; j < nv; ++j)
        for (int i = 0; i < nu; ++i) {
            const auto a = std::uint32_t(j * (nu + 1) + i), b = a + 1, c = a + nu + 1, d = c + 1;
            m.triangles.push_back({a, b, c});
            m.triangles.push_back({b, d, c});
        }
    return m;
}

// --- the pixel font ------------------------------------------------------------------------------------------

namespace {

// 5x7 glyphs, one string of 7 rows of 5 columns each ('#' set).
const std::map<char, const char*>& glyphs() {
    static const std::map<char, const char*> g = {
        {'0', " ### #   ##  ### # ###  ##   # ### "}, {'1', "  #   ##    #    #    #    #   ### "},
        {'2', " ### #   #    #   #   #   #   #####"}, {'3', "#####   #   #     #     ##   # ### "},
        {'4', "   #   ##  # # #  # #####   #    # "}, {'5', "######    ####     #    ##   # ### "},
        {'6', "  ##  #   #    #### #   ##   # ### "}, {'7', "#####    #   #   #   #    #    #   "},
        {'8', " ### #   ##   # ### #   ##   # ### "}, {'9', " ### #   ##   # ####    #   #  ##  "},
        {'.', "                          ##   ##  "}, {'-', "               #####               "},
        {'+', "       #    #  #####  #    #       "}, {'[', " ###  #    #    #    #    #    ### "},
        {']', " ###    #    #    #    #    #  ### "}, {'/', "    #    #   #   #   #   #    #    "},
        {'^', "  #   # # #   #                    "}, {'=', "          #####     #####          "},
        {'(', "   #   #   #    #    #     #     # "}, {')', " #     #     #    #    #   #   #   "},
        {':', "      ##   ##        ##   ##       "}, {',', "                     ##    #   #   "},
        {'_', "                              #####"}, {'%', "##   ##  #   #   #   #   #  ##   ##"},
        {'a', "           ###     # #####   # ####"}, {'b', "#    #    # ## ##  ##   ##   ##### "},
        {'c', "           ### #    #    #   # ### "}, {'d', "    #    # ## ##  ###   ##   # ####"},
        {'e', "           ### #   #######     ### "}, {'f', "  ##  #  # #   ###   #    #    #   "},
        {'g', "      #####   ##   # ####    # ### "}, {'h', "#    #    # ## ##  ##   ##   ##   #"},
        {'i', "  #        ##    #    #    #   ### "}, {'j', "   #        ##    #    # #  #  ##  "},
        {'k', "#    #    #  # # #  ##   # #  #  # "}, {'l', " ##    #    #    #    #    #   ### "},
        {'m', "          ## # # # ## # ##   ##   #"}, {'n', "          # ## ##  ##   ##   ##   #"},
        {'o', "           ### #   ##   ##   # ### "}, {'p', "          #### #   ##### #    #    "},
        {'q', "           ## ##  ## ####    #    #"}, {'r', "          # ## ##  ##    #    #    "},
        {'s', "           #####     ###     ##### "}, {'t', " #    #   ###   #    #    #  #  ## "},
        {'u', "          #   ##   ##   ##  ## ## #"}, {'v', "          #   ##   ##   # # #   #  "},
        {'w', "          #   ##   ## # ## # # # # "}, {'x', "          #   # # #   #   # # #   #"},
        {'y', "          #   ##   # ####    # ### "}, {'z', "          #####   #   #   #   #####"},
    };
    return g;
}

}  // namespace

void fillRect(Image& image, int x0, int y0, int x1, int y1, const Vec3& colour) {
    for (int y = std::max(0, y0); y < std::min(image.height, y1); ++y)
        for (int x = std::max(0, x0); x < std::min(image.width, x1); ++x)
            for (int c = 0; c < 3; ++c) image.pixel(x, y)[c] = std::uint8_t(std::lround(255 * std::clamp<Real>(colour[c], 0, 1)));
}

namespace {

std::string tickLabel(Real v) {
    if (v != 0 && (std::abs(v) >= 1e4 || std::abs(v) < 1e-2)) return fmt::format("{:.1e}", v);
    return fmt::format("{:.3g}", v);
}

}  // namespace

void drawText(Image& image, int x, int y, const std::string& text, const Vec3& colour, int scale) {
    for (char ch : text) {
        const char lower = char(std::tolower(static_cast<unsigned char>(ch)));
        const auto it = glyphs().find(lower);
        if (it != glyphs().end()) {
            const std::string rows = it->second;
            for (int row = 0; row < 7; ++row)
                for (int col = 0; col < 5; ++col) {
                    const std::size_t k = std::size_t(row * 5 + col);
                    if (k < rows.size() && rows[k] == '#')
                        fillRect(image, x + col * scale, y + row * scale, x + (col + 1) * scale, y + (row + 1) * scale,
                                 colour);
                }
        }
        x += 6 * scale;
    }
}

void drawLegend(Image& image, const Legend& legend) {
    const int scale = std::max(1, image.height / 400);
    const int barWidth = 16 * scale, barHeight = std::min(image.height / 2, 160 * scale);
    const int x0 = image.width - barWidth - 70 * scale, y0 = image.height - barHeight - 28 * scale;
    const Vec3 ink(0.12, 0.12, 0.12);
    fillRect(image, x0 - 1, y0 - 1, x0 + barWidth + 1, y0 + barHeight + 1, ink);
    for (int y = 0; y < barHeight; ++y)
        fillRect(image, x0, y0 + y, x0 + barWidth, y0 + y + 1, colourRamp(1 - Real(y) / (barHeight - 1)));
    for (int k = 0; k <= 4; ++k) {
        const int y = y0 + (barHeight - 1) * k / 4;
        fillRect(image, x0 + barWidth, y, x0 + barWidth + 4 * scale, y + scale, ink);
        drawText(image, x0 + barWidth + 6 * scale, y - 3 * scale,
                 tickLabel(legend.max - (legend.max - legend.min) * k / 4), ink, scale);
    }
    const int titleWidth = int(legend.title.size()) * 6 * scale;
    drawText(image, std::max(0, x0 + barWidth / 2 - titleWidth / 2), y0 - 12 * scale, legend.title, ink, scale);
}

Image contactSheet(const std::vector<Image>& frames, const std::vector<std::string>& captions, int columns,
                   int sheetWidth) {
    Image sheet;
    if (frames.empty()) return sheet;
    columns = std::max(1, std::min(columns, int(frames.size())));
    const int gap = 8, caption = 22;
    const int cellWidth = (sheetWidth - gap * (columns + 1)) / columns;
    const int cellHeight = cellWidth * frames[0].height / frames[0].width;
    const int rows = (int(frames.size()) + columns - 1) / columns;
    sheet.width = sheetWidth;
    sheet.height = gap + rows * (cellHeight + caption + gap);
    sheet.rgb.assign(std::size_t(sheet.width) * sheet.height * 3, 255);
    for (std::size_t k = 0; k < frames.size(); ++k) {
        const Image& f = frames[k];
        const int x0 = gap + int(k % columns) * (cellWidth + gap), y0 = gap + int(k / columns) * (cellHeight + caption + gap);
        // Box filter: each sheet pixel averages the frame pixels it covers.
        for (int y = 0; y < cellHeight; ++y)
            for (int x = 0; x < cellWidth; ++x) {
                const int fx0 = x * f.width / cellWidth, fx1 = std::max(fx0 + 1, (x + 1) * f.width / cellWidth);
                const int fy0 = y * f.height / cellHeight, fy1 = std::max(fy0 + 1, (y + 1) * f.height / cellHeight);
                int sum[3] = {0, 0, 0};
                for (int fy = fy0; fy < fy1; ++fy)
                    for (int fx = fx0; fx < fx1; ++fx)
                        for (int c = 0; c < 3; ++c) sum[c] += f.pixel(fx, fy)[c];
                const int n = (fx1 - fx0) * (fy1 - fy0);
                for (int c = 0; c < 3; ++c) sheet.pixel(x0 + x, y0 + y)[c] = std::uint8_t(sum[c] / n);
            }
        if (k < captions.size()) drawText(sheet, x0, y0 + cellHeight + 5, captions[k], Vec3(0.1, 0.1, 0.1), 2);
    }
    return sheet;
}

}  // namespace ganache
