#pragma once
// The preview renderer: headless OpenGL through OSMesa (Mesa's llvmpipe, software), so farm machines without a
// display render too. One Renderer owns one offscreen context; it draws a FrameView (meshes, particles, a ground
// plane) into an Image: a soft key light with shadows (a shadow map, which also gives the contact shadow on the
// ground), a cool fill light, sky ambient, 4x multisampling. Images are deterministic for the same input.

#include "core/types.h"

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace ganache {

/// An 8-bit sRGB image, rows from the top.
struct Image {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgb;  ///< width * height * 3
    const std::uint8_t* pixel(int x, int y) const { return &rgb[3 * (std::size_t(y) * width + x)]; }
    std::uint8_t* pixel(int x, int y) { return &rgb[3 * (std::size_t(y) * width + x)]; }
};

/// Writes a PNG atomically; runtime_error when the disk refuses.
void writePng(const std::filesystem::path& path, const Image& image);
/// Reads an 8-bit RGB or RGBA PNG; InputError naming the file when it is missing or not a PNG.
Image readPng(const std::filesystem::path& path);

struct Camera {
    Vec3 position = Vec3(0, 0, 1), target = Vec3::Zero();
    Real fovDegrees = 40;  ///< vertical
};

/// A camera that frames a box from the front right and above, the whole box in view at this aspect ratio.
Camera frameBounds(const Vec3& lo, const Vec3& hi, Real aspect, Real fovDegrees = 40);

/// Triangles with per-vertex normals, one colour (sRGB).
struct DrawMesh {
    std::vector<Vec3> points, normals;
    std::vector<std::array<std::uint32_t, 3>> triangles;  ///< counter-clockwise seen from outside
    Vec3 colour = Vec3(0.6, 0.6, 0.6);
    Real gloss = 0.3;  ///< specular strength in [0, 1]
    bool cutaway = false;  ///< draw only the faces turned away from the camera (a tank's far walls)
};
/// Flat-shaded triangles (each face its own normal) from corner positions.
DrawMesh flatMesh(const std::vector<Vec3>& vertices, const std::vector<std::array<std::uint32_t, 3>>& triangles,
                  const Vec3& colour);

/// A UV sphere of `segments` quads around and segments / 2 from pole to pole (2 segments^2 / 2 triangles),
/// with exact normals: the reference shape of the renderer's tests and benchmark.
DrawMesh sphereMesh(const Vec3& centre, Real radius, int segments, const Vec3& colour);

/// Particles drawn as shaded spheres of one radius, each with its own colour (sRGB).
struct DrawPoints {
    std::vector<Vec3> x, colour;
    Real radius = 0.01;  ///< [m]
};

/// A colour bar in the image's corner: the ramp from min to max with its title ("speed [m/s]").
struct Legend {
    std::string title;
    Real min = 0, max = 1;
};

/// The ramp particles are coloured with (perceptually ordered, dark blue to yellow), t in [0, 1], sRGB.
Vec3 colourRamp(Real t);

struct FrameView {
    Camera camera;
    std::vector<DrawMesh> meshes;
    std::optional<DrawPoints> points;
    std::optional<Legend> legend;
    std::optional<Real> groundHeight;  ///< a ground plane y = this, shaded and shadowed; none: no ground
};

/// The colours the renderer uses where nothing is drawn (sRGB), for tests and compositing.
Vec3 skyColour(Real heightInImage);  ///< 0 at the bottom row, 1 at the top
constexpr Real kGroundAlbedo = 0.2;  ///< linear reflectance of the ground plane (a mid grey)

class Renderer {
public:
    /// Creates the offscreen context; runtime_error when OSMesa cannot give one (the message says what to install).
    Renderer(int width, int height);
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    int width() const;
    int height() const;
    /// Draws one frame.
    Image render(const FrameView& view);

private:
    struct Gl;
    std::unique_ptr<Gl> m_gl;
};

/// Fills the pixels [x0, x1) x [y0, y1) (clipped to the image) with a colour in [0, 1].
void fillRect(Image& image, int x0, int y0, int x1, int y1, const Vec3& colour);

/// Draws text with the renderer's built-in 5x7 pixel font (digits, letters, ". - + [ ] / ^ = ( ) : , _ %"), scaled by
/// `scale`, top-left corner at (x, y).
void drawText(Image& image, int x, int y, const std::string& text, const Vec3& colour, int scale = 2);
/// Draws the legend's colour bar, ticks and title in the image's lower right corner.
void drawLegend(Image& image, const Legend& legend);

/// Frames side by side, scaled down to `columns` across, each labelled with its caption; rows as needed.
Image contactSheet(const std::vector<Image>& frames, const std::vector<std::string>& captions, int columns,
                   int sheetWidth);

}  // namespace ganache
