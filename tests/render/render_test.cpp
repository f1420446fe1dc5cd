#include "render/render.h"

#include "core/errors.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <thread>

using namespace ganache;

namespace {

// A UV sphere fine enough that its polygon silhouette is within 0.01 % of the true sphere's area.
DrawMesh sphere(const Vec3& centre, Real radius, const Vec3& colour) {
    DrawMesh m = sphereMesh(centre, radius, 256, colour);
    m.gloss = 0;
    return m;
}

Real luminance(const std::uint8_t* p) { return (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) / 255; }

Vec3 colourAt(const Image& image, int x, int y) {
    const std::uint8_t* p = image.pixel(x, y);
    return Vec3(p[0], p[1], p[2]) / 255;
}

}  // namespace

TEST(Render, SphereSilhouetteMatchesItsProjection) {
    // A black sphere of radius R at distance d, seen with a vertical field of view fov on H rows: its outline
    // is a circle of radius f R / sqrt(d^2 - R^2) pixels, f = (H / 2) / tan(fov / 2). Each pixel counts by how
    // much darker than the sky it is (4 samples a pixel: edge pixels count their share), so the sum is the
    // covered area; 2 % is the bar (measured well inside it, see the printout).
    const int width = 640, height = 480;
    Renderer renderer(width, height);
    FrameView view;
    view.camera = Camera{Vec3(0.03, 0.02, 1.0), Vec3(0.03, 0.02, 0), 40};
    const Image sky = renderer.render(view);
    view.meshes.push_back(sphere(Vec3(0.03, 0.02, 0), 0.1, Vec3::Zero()));
    const Image image = renderer.render(view);
    Real covered = 0;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x)
            covered += std::clamp<Real>(1 - luminance(image.pixel(x, y)) / luminance(sky.pixel(x, y)), 0, 1);
    const Real f = 0.5 * height / std::tan(20 * M_PI / 180);
    const Real rho = f * 0.1 / std::sqrt(1 - 0.01);
    const Real expected = M_PI * rho * rho;
    std::printf("silhouette: %.1f pixels covered, %.1f expected (%+.2f %%)\n", covered, expected,
                100 * (covered / expected - 1));
    EXPECT_NEAR(covered / expected, 1.0, 0.02);
}

TEST(Render, SkyGroundAndShadowAreWhereTheyShouldBe) {
    // Seen from straight above (screen right is world -x, screen up is world +z), a sphere floating 0.5 m
    // over the ground casts its shadow away from the key light, towards +x and -z.
    const int width = 400, height = 400;
    Renderer renderer(width, height);
    FrameView view;
    view.camera = Camera{Vec3(0, 2, 0), Vec3::Zero(), 60};
    view.groundHeight = 0.0;
    view.meshes.push_back(sphere(Vec3(0, 0.5, 0), 0.1, Vec3(0.8, 0.2, 0.2)));
    const Image image = renderer.render(view);
    const Real f = 0.5 * height / std::tan(30 * M_PI / 180);
    auto pixelOfGround = [&](Real x, Real z) {  // camera 2 m above the ground
        return std::make_pair(int(width / 2 - f * x / 2), int(height / 2 - f * z / 2));
    };
    const Vec3 key = Vec3(-0.45, 1.0, 0.55).normalized();
    const Vec3 shadowCentre = Vec3(0, 0.5, 0) - key * (0.5 / key.y());
    const auto [sx, sy] = pixelOfGround(shadowCentre.x(), shadowCentre.z());
    const auto [lx, ly] = pixelOfGround(-shadowCentre.x(), -shadowCentre.z());
    const Real shadowed = luminance(image.pixel(sx, sy)), lit = luminance(image.pixel(lx, ly));
    std::printf("ground: lit %.3f, in the shadow %.3f\n", lit, shadowed);
    EXPECT_LT(shadowed, 0.7 * lit);
    // The lit ground is a light neutral grey (warm key, cool fill: channels within 10 % of each other).
    const Vec3 ground = colourAt(image, lx, ly);
    EXPECT_GT(ground.minCoeff(), 0.4);
    EXPECT_LT(ground.maxCoeff() - ground.minCoeff(), 0.1);
    // The sphere's centre is red; the sky shows above a ground seen from the side.
    const Vec3 centre = colourAt(image, width / 2, height / 2);
    EXPECT_GT(centre.x(), 2 * centre.y());

    view.camera = Camera{Vec3(0, 0.3, 2), Vec3(0, 0.3, 0), 40};
    const Image side = renderer.render(view);
    const Vec3 top = colourAt(side, 5, 0), expected = skyColour(1);
    EXPECT_LT((top - expected).cwiseAbs().maxCoeff(), 3.0 / 255) << top.transpose();
    const Vec3 near = colourAt(side, 5, height - 1);  // the ground in front of the camera: grey, not sky
    EXPECT_LT(near.maxCoeff() - near.minCoeff(), 0.1) << near.transpose();
    EXPECT_GT((near - skyColour(0)).cwiseAbs().maxCoeff(), 0.05) << near.transpose();
}

TEST(Render, ParticlesWithALegendAndAnEmptyFrame) {
    Renderer renderer(320, 240);
    FrameView view;
    view.camera = Camera{Vec3(0, 0, 1), Vec3::Zero(), 40};
    DrawPoints points;
    points.radius = 0.02;
    for (int k = -3; k <= 3; ++k)
        for (int j = -3; j <= 3; ++j) {
            points.x.emplace_back(0.04 * k, 0.04 * j, 0);
            points.colour.push_back(colourRamp(1));  // yellow
        }
    view.points = points;
    view.legend = Legend{"speed [m/s]", 0, 2};
    const Image image = renderer.render(view);
    const Vec3 middle = colourAt(image, 160, 120);
    EXPECT_GT(middle.x(), 1.5 * middle.z()) << middle.transpose();  // a lit yellow sphere
    EXPECT_GT(middle.y(), 1.5 * middle.z()) << middle.transpose();
    // The colour bar's top row holds the ramp's top colour.
    bool found = false;
    for (int y = 0; y < 240 && !found; ++y)
        for (int x = 200; x < 320 && !found; ++x)
            found = (colourAt(image, x, y) - colourRamp(1)).cwiseAbs().maxCoeff() < 1.0 / 255;
    EXPECT_TRUE(found);

    const Image empty = renderer.render(FrameView{});
    EXPECT_EQ(empty.width, 320);
    const Vec3 corner = colourAt(empty, 0, 0);
    EXPECT_LT((corner - skyColour(1)).cwiseAbs().maxCoeff(), 3.0 / 255);
}

TEST(Render, ImagesAreDeterministic) {
    // The same view gives the same bytes: twice on one context, and on a second context in another thread.
    FrameView view;
    view.camera = frameBounds(Vec3(-0.1, 0, -0.1), Vec3(0.1, 0.2, 0.1), 16.0 / 9);
    view.groundHeight = 0.0;
    view.meshes.push_back(sphere(Vec3(0, 0.1, 0), 0.1, Vec3(0.32, 0.17, 0.09)));
    Renderer renderer(320, 180);
    const Image a = renderer.render(view), b = renderer.render(view);
    Image c;
    std::thread([&] { c = Renderer(320, 180).render(view); }).join();
    EXPECT_EQ(a.rgb, b.rgb);
    EXPECT_EQ(a.rgb, c.rgb);
}

TEST(Render, PngRoundTripAndBadFiles) {
    Image image;
    image.width = 7;
    image.height = 3;
    for (int k = 0; k < 7 * 3 * 3; ++k) image.rgb.push_back(std::uint8_t(k * 5));
    const auto file = std::filesystem::temp_directory_path() / "ganache_round_trip.png";
    writePng(file, image);
    const Image back = readPng(file);
    EXPECT_EQ(back.width, 7);
    EXPECT_EQ(back.height, 3);
    EXPECT_EQ(back.rgb, image.rgb);
    const auto bad = std::filesystem::temp_directory_path() / "ganache_not_a.png";
    std::ofstream(bad) << "hello";
    EXPECT_THROW(readPng(bad), InputError);
}

TEST(Render, ContactSheetHoldsEveryFrame) {
    std::vector<Image> frames(5);
    for (std::size_t k = 0; k < frames.size(); ++k) {
        frames[k].width = 160;
        frames[k].height = 90;
        frames[k].rgb.assign(160 * 90 * 3, std::uint8_t(40 * k));
    }
    const Image sheet = contactSheet(frames, {"frame 1", "frame 2", "frame 3", "frame 4", "frame 5"}, 4, 800);
    EXPECT_EQ(sheet.width, 800);
    EXPECT_GT(sheet.height, 2 * 90);  // two rows
    EXPECT_EQ(colourAt(sheet, 8 + 10, 8 + 10), Vec3::Zero());  // the first frame, top left
}
