// The OpenGL part of the renderer: an OSMesa core-profile context (llvmpipe), a shadow map from the key light,
// a multisampled colour pass (sky, ground, meshes, particles as sphere sprites), read back into an Image.

#define GL_GLEXT_PROTOTYPES 1
#include "render/render.h"

#include <GL/osmesa.h>
#include <GL/gl.h>
#include <GL/glext.h>
#include <fmt/format.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace ganache {

namespace {

using Mat4f = Eigen::Matrix4f;
using Vec3f = Eigen::Vector3f;

constexpr int kShadowSize = 2048;
constexpr int kSamples = 4;
// Where the key light comes from (towards the light): above, left and in front of the default camera.
const Vec3f kKeyDirection = Vec3f(-0.45f, 1.0f, 0.55f).normalized();
const Vec3f kFillDirection = Vec3f(0.8f, 0.35f, -0.3f).normalized();

Vec3f toFloat(const Vec3& v) { return v.cast<float>(); }

Mat4f lookAt(const Vec3f& eye, const Vec3f& target, Vec3f up) {
    const Vec3f f = (target - eye).normalized();
    if (std::abs(f.dot(up)) > 0.999f) up = Vec3f(0, 0, 1);  // looking straight up or down
    const Vec3f s = f.cross(up).normalized(), u = s.cross(f);
    Mat4f m = Mat4f::Identity();
    m.block<1, 3>(0, 0) = s.transpose();
    m.block<1, 3>(1, 0) = u.transpose();
    m.block<1, 3>(2, 0) = -f.transpose();
    m(0, 3) = -s.dot(eye);
    m(1, 3) = -u.dot(eye);
    m(2, 3) = f.dot(eye);
    return m;
}

Mat4f perspective(float fovY, float aspect, float nearZ, float farZ) {
    const float f = 1.0f / std::tan(fovY / 2);
    Mat4f m = Mat4f::Zero();
    m(0, 0) = f / aspect;
    m(1, 1) = f;
    m(2, 2) = (farZ + nearZ) / (nearZ - farZ);
    m(2, 3) = 2 * farZ * nearZ / (nearZ - farZ);
    m(3, 2) = -1;
    return m;
}

Mat4f ortho(float halfWidth, float nearZ, float farZ) {
    Mat4f m = Mat4f::Identity();
    m(0, 0) = m(1, 1) = 1 / halfWidth;
    m(2, 2) = -2 / (farZ - nearZ);
    m(2, 3) = -(farZ + nearZ) / (farZ - nearZ);
    return m;
}

const char* kMeshVertex = R"(#version 330 core
layout(location = 0) in vec3 aPos;
layout(location = 1) in vec3 aNormal;
layout(location = 2) in vec3 aColour;
uniform mat4 uViewProj;
uniform mat4 uLightViewProj;
uniform float uPointScale;   // particles: pixels per metre at unit depth (0: triangles)
uniform float uPointRadius;
uniform vec3 uEye;
out vec3 vPos;
out vec3 vNormal;
out vec3 vColour;
out vec4 vLight;
void main() {
    vPos = aPos;
    vNormal = aNormal;
    vColour = aColour;
    vLight = uLightViewProj * vec4(aPos, 1.0);
    gl_Position = uViewProj * vec4(aPos, 1.0);
    if (uPointScale > 0.0) gl_PointSize = max(1.0, 2.0 * uPointRadius * uPointScale / gl_Position.w);
}
)";

const char* kMeshFragment = R"(#version 330 core
in vec3 vPos;
in vec3 vNormal;
in vec3 vColour;
in vec4 vLight;
uniform sampler2DShadow uShadow;
uniform vec3 uEye;
uniform vec3 uKey;
uniform vec3 uFill;
uniform float uGloss;
uniform int uMode;            // 0 mesh, 1 particle sprite, 2 ground
uniform mat3 uCameraToWorld;  // sprites: their normals are built in camera space
uniform vec3 uGroundCentre;
uniform float uGroundFade;    // ground: distance at which it has faded into the sky
uniform vec2 uViewport;
uniform vec3 uSkyBottom;
uniform vec3 uSkyTop;
out vec4 fragColour;

vec3 linear(vec3 c) { return pow(c, vec3(2.2)); }

float lit() {
    vec3 p = vLight.xyz / vLight.w * 0.5 + 0.5;
    if (any(lessThan(p.xy, vec2(0.0))) || any(greaterThan(p.xy, vec2(1.0)))) return 1.0;
    float texel = 1.0 / float(textureSize(uShadow, 0).x);
    float sum = 0.0;
    for (int i = -1; i <= 1; ++i)
        for (int j = -1; j <= 1; ++j) sum += texture(uShadow, vec3(p.xy + vec2(i, j) * 2.0 * texel, p.z - 0.0015));
    return sum / 9.0;
}

void main() {
    vec3 n = normalize(vNormal);
    if (uMode == 1) {
        vec2 c = gl_PointCoord * 2.0 - 1.0;
        float r2 = dot(c, c);
        if (r2 > 1.0) discard;
        n = normalize(uCameraToWorld * vec3(c.x, -c.y, sqrt(1.0 - r2)));
    } else if (!gl_FrontFacing) {
        n = -n;
    }
    vec3 v = normalize(uEye - vPos);
    float shadow = lit();
    vec3 albedo = linear(vColour);
    vec3 keyLight = vec3(1.0, 0.96, 0.9) * 2.4;
    vec3 fillLight = vec3(0.75, 0.85, 1.0) * 0.45;
    vec3 ambient = mix(vec3(0.30, 0.28, 0.26), vec3(0.45, 0.52, 0.62), 0.5 + 0.5 * n.y) * 0.55;
    float key = max(dot(n, uKey), 0.0) * shadow;
    float fill = max(dot(n, uFill), 0.0);
    vec3 colour = albedo * (keyLight * key + fillLight * fill + ambient);
    vec3 h = normalize(uKey + v);
    colour += keyLight * uGloss * 0.5 * pow(max(dot(n, h), 0.0), 64.0) * shadow;
    colour = pow(colour / (1.0 + colour * 0.15), vec3(1.0 / 2.2));  // a gentle shoulder, then sRGB
    if (uMode == 2) {
        float fade = smoothstep(0.35 * uGroundFade, uGroundFade, length(vPos.xz - uGroundCentre.xz));
        vec3 sky = mix(uSkyBottom, uSkyTop, gl_FragCoord.y / uViewport.y);
        colour = mix(colour, sky, fade);
    }
    fragColour = vec4(colour, 1.0);
}
)";

const char* kShadowVertex = R"(#version 330 core
layout(location = 0) in vec3 aPos;
uniform mat4 uLightViewProj;
uniform float uPointSize;
void main() {
    gl_Position = uLightViewProj * vec4(aPos, 1.0);
    gl_PointSize = uPointSize;
}
)";

const char* kShadowFragment = R"(#version 330 core
uniform int uSprite;
void main() {
    if (uSprite == 1 && dot(gl_PointCoord * 2.0 - 1.0, gl_PointCoord * 2.0 - 1.0) > 1.0) discard;
}
)";

const char* kSkyVertex = R"(#version 330 core
const vec2 corners[3] = vec2[3](vec2(-1.0, -1.0), vec2(3.0, -1.0), vec2(-1.0, 3.0));
void main() { gl_Position = vec4(corners[gl_VertexID], 0.0, 1.0); }
)";

const char* kSkyFragment = R"(#version 330 core
uniform vec2 uViewport;
uniform vec3 uSkyBottom;
uniform vec3 uSkyTop;
out vec4 fragColour;
void main() { fragColour = vec4(mix(uSkyBottom, uSkyTop, gl_FragCoord.y / uViewport.y), 1.0); }
)";

GLuint compile(GLenum type, const char* source) {
    const GLuint shader = glCreateShader(type);
    glShaderSource(shader, 1, &source, nullptr);
    glCompileShader(shader);
    GLint ok = 0;
    glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[2048];
        glGetShaderInfoLog(shader, sizeof log, nullptr, log);
        throw std::runtime_error(fmt::format("render: a shader does not compile on this OpenGL: {}", log));
    }
    return shader;
}

GLuint program(const char* vertex, const char* fragment) {
    const GLuint p = glCreateProgram();
    const GLuint v = compile(GL_VERTEX_SHADER, vertex), f = compile(GL_FRAGMENT_SHADER, fragment);
    glAttachShader(p, v);
    glAttachShader(p, f);
    glLinkProgram(p);
    glDeleteShader(v);
    glDeleteShader(f);
    GLint ok = 0;
    glGetProgramiv(p, GL_LINK_STATUS, &ok);
    if (!ok) throw std::runtime_error("render: the shaders do not link on this OpenGL");
    return p;
}

// Vertex data of one draw: interleaved position, normal, colour.
struct Batch {
    std::vector<float> vertices;
    std::vector<std::uint32_t> indices;  // empty: points
    void add(const Vec3& p, const Vec3& n, const Vec3& c) {
        for (const Vec3* v : {&p, &n, &c})
            for (int k = 0; k < 3; ++k) vertices.push_back(float((*v)[k]));
    }
    std::size_t count() const { return vertices.size() / 9; }
};

}  // namespace

struct Renderer::Gl {
    int width = 0, height = 0;
    OSMesaContext context = nullptr;
    std::vector<std::uint8_t> buffer;  // OSMesa's own framebuffer (unused: everything goes to FBOs)
    GLuint meshProgram = 0, shadowProgram = 0, skyProgram = 0;
    GLuint vao = 0, vbo = 0, ebo = 0;
    GLuint shadowFbo = 0, shadowTexture = 0;
    GLuint msFbo = 0, msColour = 0, msDepth = 0, outFbo = 0, outColour = 0;

    void makeCurrent() {
        if (!OSMesaMakeCurrent(context, buffer.data(), GL_UNSIGNED_BYTE, width, height))
            throw std::runtime_error("render: the OSMesa context cannot be made current");
    }
    void upload(const Batch& b) {
        glBindVertexArray(vao);
        glBindBuffer(GL_ARRAY_BUFFER, vbo);
        glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(b.vertices.size() * sizeof(float)), b.vertices.data(), GL_STREAM_DRAW);
        glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ebo);
        glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(b.indices.size() * sizeof(std::uint32_t)), b.indices.data(),
                     GL_STREAM_DRAW);
        for (GLuint k = 0; k < 3; ++k) {
            glEnableVertexAttribArray(k);
            glVertexAttribPointer(k, 3, GL_FLOAT, GL_FALSE, 9 * sizeof(float),
                                  reinterpret_cast<const void*>(std::uintptr_t(3 * k * sizeof(float))));
        }
    }
    void draw(const Batch& b) {
        if (b.indices.empty()) glDrawArrays(GL_POINTS, 0, GLsizei(b.count()));
        else glDrawElements(GL_TRIANGLES, GLsizei(b.indices.size()), GL_UNSIGNED_INT, nullptr);
    }
};

Renderer::Renderer(int width, int height) : m_gl(std::make_unique<Gl>()) {
    Gl& g = *m_gl;
    g.width = width;
    g.height = height;
    const int attributes[] = {OSMESA_FORMAT, OSMESA_RGBA, OSMESA_DEPTH_BITS, 24, OSMESA_PROFILE, OSMESA_CORE_PROFILE,
                              OSMESA_CONTEXT_MAJOR_VERSION, 3, OSMESA_CONTEXT_MINOR_VERSION, 3, 0};
    g.context = OSMesaCreateContextAttribs(attributes, nullptr);
    if (!g.context)
        throw std::runtime_error("render: no OpenGL 3.3 context from OSMesa (software rendering)\n  fix: install "
                                 "Debian's libosmesa6 (scripts/setup.sh does), built with llvmpipe");
    g.buffer.resize(std::size_t(width) * height * 4);
    g.makeCurrent();
    g.meshProgram = program(kMeshVertex, kMeshFragment);
    g.shadowProgram = program(kShadowVertex, kShadowFragment);
    g.skyProgram = program(kSkyVertex, kSkyFragment);
    glGenVertexArrays(1, &g.vao);
    glGenBuffers(1, &g.vbo);
    glGenBuffers(1, &g.ebo);

    glGenTextures(1, &g.shadowTexture);
    glBindTexture(GL_TEXTURE_2D, g.shadowTexture);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_DEPTH_COMPONENT24, kShadowSize, kShadowSize, 0, GL_DEPTH_COMPONENT, GL_FLOAT, nullptr);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
    glGenFramebuffers(1, &g.shadowFbo);
    glBindFramebuffer(GL_FRAMEBUFFER, g.shadowFbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, g.shadowTexture, 0);
    glDrawBuffer(GL_NONE);
    glReadBuffer(GL_NONE);

    glGenRenderbuffers(1, &g.msColour);
    glBindRenderbuffer(GL_RENDERBUFFER, g.msColour);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, kSamples, GL_RGBA8, width, height);
    glGenRenderbuffers(1, &g.msDepth);
    glBindRenderbuffer(GL_RENDERBUFFER, g.msDepth);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, kSamples, GL_DEPTH_COMPONENT24, width, height);
    glGenFramebuffers(1, &g.msFbo);
    glBindFramebuffer(GL_FRAMEBUFFER, g.msFbo);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, g.msColour);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, g.msDepth);
    glGenRenderbuffers(1, &g.outColour);
    glBindRenderbuffer(GL_RENDERBUFFER, g.outColour);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
    glGenFramebuffers(1, &g.outFbo);
    glBindFramebuffer(GL_FRAMEBUFFER, g.outFbo);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, g.outColour);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
        throw std::runtime_error(fmt::format("render: OSMesa cannot render {}x{} offscreen", width, height));
}

Renderer::~Renderer() {
    if (m_gl->context) OSMesaDestroyContext(m_gl->context);
}

int Renderer::width() const { return m_gl->width; }
int Renderer::height() const { return m_gl->height; }

Image Renderer::render(const FrameView& view) {
    Gl& g = *m_gl;
    g.makeCurrent();

    // What is drawn: meshes, particles, and the bounds that frame the shadow map and the ground.
    std::vector<Batch> meshes(view.meshes.size());
    Batch points;
    Vec3 lo = Vec3::Constant(std::numeric_limits<Real>::infinity()), hi = -lo;
    for (std::size_t i = 0; i < view.meshes.size(); ++i) {
        const DrawMesh& m = view.meshes[i];
        for (std::size_t k = 0; k < m.points.size(); ++k) {
            meshes[i].add(m.points[k], m.normals[k], m.colour);
            lo = lo.cwiseMin(m.points[k]), hi = hi.cwiseMax(m.points[k]);
        }
        for (const auto& t : m.triangles)
            for (std::uint32_t v : t) meshes[i].indices.push_back(v);
    }
    const Real pointRadius = view.points ? view.points->radius : 0;
    if (view.points)
        for (std::size_t k = 0; k < view.points->x.size(); ++k) {
            points.add(view.points->x[k], Vec3::UnitY(), view.points->colour[k]);
            lo = lo.cwiseMin(view.points->x[k]), hi = hi.cwiseMax(view.points->x[k]);
        }
    const bool empty = !(lo.array() <= hi.array()).all();
    if (empty) lo = hi = view.camera.target;
    const Vec3f centre = toFloat(0.5 * (lo + hi));
    const float radius = std::max(1e-3f, float(0.5 * (hi - lo).norm()) + float(pointRadius));

    // Ground: a square around the camera's target, fading into the sky. Its size follows the camera, not what is
    // drawn, so that a sequence with a fixed camera keeps the same horizon while the fluid moves and grows.
    Batch ground;
    float groundFade = 0;
    const Vec3f groundCentre = toFloat(view.camera.target);
    if (view.groundHeight) {
        const float y = float(*view.groundHeight);
        const float size = 4 * float((view.camera.position - view.camera.target).norm());
        groundFade = 0.8f * size;
        const Vec3 up = Vec3::UnitY(), tint = Vec3::Constant(std::pow(kGroundAlbedo, 1 / 2.2));
        for (int k = 0; k < 4; ++k) {
            const float sx = (k == 1 || k == 2) ? 1.f : -1.f, sz = k >= 2 ? 1.f : -1.f;
            ground.add(Vec3(groundCentre.x() + sx * size, y, groundCentre.z() + sz * size), up, tint);
        }
        ground.indices = {0, 2, 1, 0, 3, 2};
    }

    // Matrices: the camera's perspective, the key light's orthographic view of the scene.
    const Vec3f eye = toFloat(view.camera.position), target = toFloat(view.camera.target);
    const float aspect = float(g.width) / float(g.height);
    const float fov = float(view.camera.fovDegrees * M_PI / 180);
    const float distance = (eye - centre).norm();
    const float farZ = std::max({distance + 30 * radius, 6 * (eye - target).norm(), 1.0f});  // the ground too
    const float nearZ = std::max(farZ * 1e-5f, std::max(1e-4f, distance - 2 * radius) * 0.05f);
    const Mat4f viewMatrix = lookAt(eye, target, Vec3f::UnitY());
    const Mat4f viewProj = perspective(fov, aspect, nearZ, farZ) * viewMatrix;
    const Mat4f lightViewProj = ortho(1.6f * radius, 0.f, 6 * radius) *
                                lookAt(centre + 3 * radius * kKeyDirection, centre, Vec3f::UnitY());
    const Eigen::Matrix3f cameraToWorld = viewMatrix.block<3, 3>(0, 0).transpose();
    const Vec3f skyBottom = toFloat(skyColour(0)), skyTop = toFloat(skyColour(1));

    // Shadow map: meshes and particles seen from the key light.
    glBindFramebuffer(GL_FRAMEBUFFER, g.shadowFbo);
    glViewport(0, 0, kShadowSize, kShadowSize);
    glEnable(GL_DEPTH_TEST);
    glClear(GL_DEPTH_BUFFER_BIT);
    glEnable(GL_POLYGON_OFFSET_FILL);
    glPolygonOffset(2.0f, 4.0f);
    glEnable(GL_PROGRAM_POINT_SIZE);
    glUseProgram(g.shadowProgram);
    glUniformMatrix4fv(glGetUniformLocation(g.shadowProgram, "uLightViewProj"), 1, GL_FALSE, lightViewProj.data());
    glUniform1f(glGetUniformLocation(g.shadowProgram, "uPointSize"),
                std::max(1.f, float(pointRadius) / (1.6f * radius) * kShadowSize));
    std::vector<const Batch*> casters{&points};
    for (const Batch& b : meshes) casters.push_back(&b);
    for (const Batch* b : casters) {
        if (!b->count()) continue;
        glUniform1i(glGetUniformLocation(g.shadowProgram, "uSprite"), b == &points);
        g.upload(*b);
        g.draw(*b);
    }
    glDisable(GL_POLYGON_OFFSET_FILL);

    // Colour pass, multisampled.
    glBindFramebuffer(GL_FRAMEBUFFER, g.msFbo);
    glViewport(0, 0, g.width, g.height);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    glDisable(GL_DEPTH_TEST);
    glUseProgram(g.skyProgram);
    glUniform2f(glGetUniformLocation(g.skyProgram, "uViewport"), float(g.width), float(g.height));
    glUniform3fv(glGetUniformLocation(g.skyProgram, "uSkyBottom"), 1, skyBottom.data());
    glUniform3fv(glGetUniformLocation(g.skyProgram, "uSkyTop"), 1, skyTop.data());
    glBindVertexArray(g.vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glEnable(GL_DEPTH_TEST);

    const GLuint p = g.meshProgram;
    glUseProgram(p);
    auto uniform = [&](const char* name) { return glGetUniformLocation(p, name); };
    glUniformMatrix4fv(uniform("uViewProj"), 1, GL_FALSE, viewProj.data());
    glUniformMatrix4fv(uniform("uLightViewProj"), 1, GL_FALSE, lightViewProj.data());
    glUniformMatrix3fv(uniform("uCameraToWorld"), 1, GL_FALSE, cameraToWorld.data());
    glUniform3fv(uniform("uEye"), 1, eye.data());
    glUniform3fv(uniform("uKey"), 1, kKeyDirection.data());
    glUniform3fv(uniform("uFill"), 1, kFillDirection.data());
    glUniform3fv(uniform("uGroundCentre"), 1, groundCentre.data());
    glUniform1f(uniform("uGroundFade"), groundFade);
    glUniform2f(uniform("uViewport"), float(g.width), float(g.height));
    glUniform3fv(uniform("uSkyBottom"), 1, skyBottom.data());
    glUniform3fv(uniform("uSkyTop"), 1, skyTop.data());
    glUniform1f(uniform("uPointRadius"), float(pointRadius));
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, g.shadowTexture);
    glUniform1i(uniform("uShadow"), 0);
    struct Pass {
        const Batch* batch;
        int mode;  // as uMode
        float gloss;
        bool cutaway;
    };
    std::vector<Pass> passes{{&ground, 2, 0.f, false}, {&points, 1, 0.25f, false}};
    for (std::size_t i = 0; i < meshes.size(); ++i)
        passes.push_back({&meshes[i], 0, float(view.meshes[i].gloss), view.meshes[i].cutaway});
    glCullFace(GL_FRONT);
    for (const Pass& pass : passes) {
        if (!pass.batch->count()) continue;
        glUniform1i(uniform("uMode"), pass.mode);
        glUniform1f(uniform("uGloss"), pass.gloss);
        glUniform1f(uniform("uPointScale"), pass.mode == 1 ? float(g.height) / (2 * std::tan(fov / 2)) : 0.f);
        if (pass.cutaway) glEnable(GL_CULL_FACE);
        g.upload(*pass.batch);
        g.draw(*pass.batch);
        glDisable(GL_CULL_FACE);
    }

    // Resolve the samples and read the pixels back (OpenGL's rows run from the bottom).
    glBindFramebuffer(GL_READ_FRAMEBUFFER, g.msFbo);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, g.outFbo);
    glBlitFramebuffer(0, 0, g.width, g.height, 0, 0, g.width, g.height, GL_COLOR_BUFFER_BIT, GL_NEAREST);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, g.outFbo);
    std::vector<std::uint8_t> rgba(std::size_t(g.width) * g.height * 4);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, g.width, g.height, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
    if (const GLenum error = glGetError(); error != GL_NO_ERROR)
        throw std::runtime_error(fmt::format("render: OpenGL error 0x{:x} while drawing", error));
    Image image;
    image.width = g.width;
    image.height = g.height;
    image.rgb.resize(std::size_t(g.width) * g.height * 3);
    for (int y = 0; y < g.height; ++y)
        for (int x = 0; x < g.width; ++x)
            for (int c = 0; c < 3; ++c)
                image.pixel(x, y)[c] = rgba[4 * (std::size_t(g.height - 1 - y) * g.width + x) + c];
    if (view.legend) drawLegend(image, *view.legend);
    return image;
}

}  // namespace ganache
