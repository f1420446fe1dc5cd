#include "scene/scene.h"

#include "physics/gravity.h"
#include "physics/viscosity/viscosity.h"

#include "../physics/drag_effect.h"

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

using namespace ganache;
namespace fs = std::filesystem;

namespace {

const fs::path kSource = GANACHE_SOURCE_DIR;

struct Expectation {
    std::string at;                    // "line:col"
    std::vector<std::string> messages;  // substrings of the error
};

// Each broken scene states its expected error in leading comments: `# at: L:C` and `# expect: text`.
Expectation expectationOf(const fs::path& file) {
    std::ifstream in(file);
    Expectation e;
    std::string line;
    while (std::getline(in, line) && line.rfind("#", 0) == 0) {
        if (line.rfind("# at: ", 0) == 0) e.at = line.substr(6);
        if (line.rfind("# expect: ", 0) == 0) e.messages.push_back(line.substr(10));
    }
    return e;
}

fs::path writeTemp(const std::string& name, const std::string& text) {
    const fs::path dir = fs::temp_directory_path() / "ganache_scene_test";
    fs::create_directories(dir);
    std::ofstream(dir / name) << text;
    return dir / name;
}

const char* kMinimal = R"(ganache: 1
particles: {radius: 0.01}
domain: {min: [-1, -1, -1], max: [1, 1, 1]}
fluids:
  - box: {min: [0, 0, 0], max: [0.1, 0.1, 0.1]}
)";

}  // namespace

TEST(BrokenScenes, EachGivesItsLocatedMessageAndAFix) {
    std::size_t count = 0;
    for (const auto& entry : fs::directory_iterator(kSource / "tests/scenes/broken")) {
        const fs::path file = entry.path();
        const Expectation e = expectationOf(file);
        ASSERT_FALSE(e.at.empty()) << file << " lacks its `# at:` line";
        SCOPED_TRACE(file.filename().string());
        try {
            loadScene(file, Quality::parse("final"));
            ADD_FAILURE() << "no error for " << file;
        } catch (const SceneError& err) {
            const std::string what = err.what();
            EXPECT_EQ(what.rfind(file.string() + ":" + e.at + ": ", 0), 0u) << what;
            EXPECT_NE(what.find("\n  fix: "), std::string::npos) << what;
            for (const auto& m : e.messages) EXPECT_NE(what.find(m), std::string::npos) << "want: " << m << "\ngot: " << what;
        }
        ++count;
    }
    EXPECT_GE(count, 20u);
}

TEST(Scene, MissingFileIsAnInputError) {
    EXPECT_THROW(loadScene(kSource / "scenes/no_such_scene.yaml", Quality()), InputError);
    EXPECT_THROW(loadScene(kSource / "scenes", Quality()), InputError);
}

TEST(Scene, DefaultsFillWhatTheSceneLeavesOut) {
    const Scene s = loadScene(writeTemp("minimal.yaml", kMinimal), Quality::parse("final"));
    const FrameRange defaults;
    EXPECT_EQ(s.name, "minimal");  // from the file name
    EXPECT_EQ(s.frames.start, defaults.start);
    EXPECT_EQ(s.frames.end, defaults.end);
    EXPECT_EQ(s.frames.fps, defaults.fps);
    EXPECT_EQ(s.fluids.at(0).material.name, "water");
    EXPECT_EQ(s.fluids.at(0).name, "fluid0");
    EXPECT_TRUE(s.effects.empty());  // nothing asked for, nothing there
    EXPECT_EQ(s.findEffect("gravity"), nullptr);
}

TEST(Scene, QualityScalesTheParticleRadius) {
    const fs::path f = writeTemp("quality.yaml", std::string(kMinimal) + "");
    EXPECT_DOUBLE_EQ(loadScene(f, Quality::parse("final")).particleRadius, 0.01);
    EXPECT_DOUBLE_EQ(loadScene(f, Quality::parse("preview")).particleRadius, 0.02);  // default preview_scale 2
    EXPECT_DOUBLE_EQ(loadScene(f, Quality::parse("1.5")).particleRadius, 0.015);
    EXPECT_THROW(Quality::parse("best"), InputError);
    EXPECT_THROW(Quality::parse("-1"), InputError);
    EXPECT_THROW(Quality::parse("nan"), InputError);
}

TEST(Scene, ReadsEveryPartOfTheTinyScene) {
    const Scene s = loadScene(kSource / "tests/scenes/tiny.yaml", Quality::parse("preview"));
    ASSERT_EQ(s.fluids.size(), 1u);
    EXPECT_EQ(s.fluids[0].material.name, "thick_honey");
    EXPECT_DOUBLE_EQ(s.fluids[0].material.mu, 50.0);
    EXPECT_DOUBLE_EQ(s.fluids[0].material.density, 1420.0);  // from the honey preset it is based on
    ASSERT_EQ(s.boundaries.size(), 1u);
    EXPECT_TRUE(std::get<BoxBoundary>(s.boundaries[0].shape).openTop);
    const EffectSpec* g = s.findEffect("gravity");
    ASSERT_NE(g, nullptr);
    EXPECT_EQ(dynamic_cast<const GravityParams&>(*g->params).acceleration, Vec3(0, -9.81, 0));
}

TEST(Scene, ViscosityTakesTheLatticeWeightsUnlessThePapersAreAskedFor) {
    auto laplacian = [](const std::string& name, const std::string& viscosity) {
        const Scene s = loadScene(writeTemp(name, std::string(kMinimal) + "effects: {viscosity: " + viscosity + "}\n"),
                                  Quality::parse("final"));
        return static_cast<const ViscosityParams&>(*s.findEffect("viscosity")->params).laplacian;
    };
    EXPECT_EQ(laplacian("lattice.yaml", "{}"), ViscosityParams::Laplacian::Lattice);
    EXPECT_EQ(laplacian("paper.yaml", "{laplacian: paper}"), ViscosityParams::Laplacian::Paper);
}

TEST(Scene, ExplainedSceneLoadsBackToTheSameEffectiveScene) {
    // Every scene of the library, and the test scenes.
    std::vector<fs::path> files{kSource / "tests/scenes/tiny.yaml", kSource / "tests/scenes/pour.yaml",
                                kSource / "tests/scenes/bunny_on_bars.yaml"};
    for (const auto& entry : fs::recursive_directory_iterator(kSource / "scenes"))
        if (entry.path().extension() == ".yaml") files.push_back(entry.path());
    std::sort(files.begin(), files.end());
    ASSERT_GE(files.size(), 15u);  // scenes/study included
    for (const fs::path& file : files) {
        SCOPED_TRACE(file.string());
        const Scene s = loadScene(file, Quality::parse("final"));
        const std::string text = explainScene(s);
        EXPECT_NE(text.find("radius: 0."), std::string::npos);
        EXPECT_NE(text.find("# m"), std::string::npos) << "units appear as comments";
        const fs::path again = writeTemp(s.name + ".yaml", text);
        const Scene t = loadScene(again, Quality::parse("final"));
        EXPECT_EQ(effectiveJson(*s.effective), effectiveJson(*t.effective)) << text;
    }
}

TEST(Scene, DidYouMeanPicksTheClosestName) {
    EXPECT_EQ(closestMatch("viscosty", {"gravity", "viscosity", "heat"}), "viscosity");
    EXPECT_EQ(closestMatch("zzzzzz", {"gravity", "viscosity"}), "");
}

TEST(Scene, AnEffectRegisteredOutsideReadsItsOwnSection) {
    // The test-only drag effect (tests/physics/drag_effect.h) is read like a built-in one: its keys, their checks
    // and the did-you-mean come from its own reader and the Section API.
    ganache::testing::registerDrag();
    const Scene s = loadScene(writeTemp("drag.yaml", std::string(kMinimal) + "effects: {drag: {rate: 3}}\n"),
                              Quality::parse("final"));
    ASSERT_NE(s.findEffect("drag"), nullptr);
    EXPECT_EQ(static_cast<const ganache::testing::DragParams&>(*s.findEffect("drag")->params).rate, 3.0);
    try {
        loadScene(writeTemp("drag_typo.yaml", std::string(kMinimal) + "effects: {drag: {rat: 3}}\n"),
                  Quality::parse("final"));
        FAIL() << "a misspelt key must be refused";
    } catch (const SceneError& e) {
        EXPECT_NE(std::string(e.what()).find("did you mean 'rate'"), std::string::npos) << e.what();
    }
}

TEST(Scene, AMeshPathThatIsNoRegularFileSaysWhatItIs) {
    // Folders and devices are broken scenes (mesh_is_a_folder, mesh_is_a_device); a FIFO is made here.
    const fs::path fifo = fs::temp_directory_path() / "ganache_scene_test_fifo";
    fs::remove(fifo);
    ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
    const fs::path scene = writeTemp("fifo_mesh.yaml", std::string(kMinimal).substr(0, std::string(kMinimal).find("fluids:")) +
                                                           "fluids:\n  - mesh: {file: " + fifo.string() + "}\n");
    try {
        loadScene(scene, Quality::parse("final"));
        ADD_FAILURE() << "a FIFO was taken for a mesh";
    } catch (const SceneError& e) {
        EXPECT_NE(std::string(e.what()).find("is a FIFO (named pipe), not a regular file"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("fix: give the path of a regular file"), std::string::npos) << e.what();
    }
    fs::remove(fifo);
}
