#include "physics/pair_sweeps.h"

#include <cstdint>

namespace ganache::sweeps {

namespace {

// Positions and velocities are arrays of Vec3: three doubles each, contiguous.
inline const Real* raw(const Vec3* v) { return v->data(); }

}  // namespace

namespace {

// The viscous product for N inputs in one pass over the pairs (the pairs' geometry is read once for all of them).
template <int N>
void viscousProductsOf(std::size_t begin, std::size_t end, Pairs fluid, const Mat3* boundaryBlock, const Vec3* xv,
                       const Vec3* const (&inv)[N], Real dt, Vec3* const (&out)[N]) {
    const Real* x = raw(xv);
    const Real* v[N];
    for (int c = 0; c < N; ++c) v[c] = raw(inv[c]);
    const std::uint64_t* off = fluid.list->offsets.data();
    const std::uint32_t* idx = fluid.list->indices.data();
    const Real* k = fluid.weight;
    for (std::size_t i = begin; i < end; ++i) {
        const Real xi0 = x[3 * i], xi1 = x[3 * i + 1], xi2 = x[3 * i + 2];
        Real a[N][3] = {};
        for (std::uint64_t p = off[i]; p < off[i + 1]; ++p) {
            const std::size_t j = 3 * std::size_t(idx[p]);
            const Real d0 = xi0 - x[j], d1 = xi1 - x[j + 1], d2 = xi2 - x[j + 2];
            for (int c = 0; c < N; ++c) {
                const Real* u = v[c];
                const Real s =
                    k[p] * (d0 * (u[3 * i] - u[j]) + d1 * (u[3 * i + 1] - u[j + 1]) + d2 * (u[3 * i + 2] - u[j + 2]));
                a[c][0] += s * d0;
                a[c][1] += s * d1;
                a[c][2] += s * d2;
            }
        }
        for (int c = 0; c < N; ++c) {
            Vec3 o(v[c][3 * i] - dt * a[c][0], v[c][3 * i + 1] - dt * a[c][1], v[c][3 * i + 2] - dt * a[c][2]);
            if (boundaryBlock) o += boundaryBlock[i] * inv[c][i];
            out[c][i] = o;
        }
    }
}

}  // namespace

void viscousProduct(std::size_t begin, std::size_t end, Pairs fluid, const Mat3* boundaryBlock, const Vec3* x,
                    const Vec3* in, Real dt, Vec3* out) {
    const Vec3* const inputs[1] = {in};
    Vec3* const outputs[1] = {out};
    viscousProductsOf<1>(begin, end, fluid, boundaryBlock, x, inputs, dt, outputs);
}

void viscousProducts(std::size_t begin, std::size_t end, Pairs fluid, const Mat3* boundaryBlock, const Vec3* x,
                     const Vec3* in1, const Vec3* in2, Real dt, Vec3* out1, Vec3* out2) {
    const Vec3* const inputs[2] = {in1, in2};
    Vec3* const outputs[2] = {out1, out2};
    viscousProductsOf<2>(begin, end, fluid, boundaryBlock, x, inputs, dt, outputs);
}

void densityRate(std::size_t begin, std::size_t end, Pairs fluid, const Vec3* boundarySum, const Real* bodyRate,
                 const Vec3* xv, const Vec3* uv, Real* rate) {
    const Real* x = raw(xv);
    const Real* u = raw(uv);
    const std::uint64_t* off = fluid.list->offsets.data();
    const std::uint32_t* idx = fluid.list->indices.data();
    const Real* w = fluid.weight;
    for (std::size_t i = begin; i < end; ++i) {
        const Real xi0 = x[3 * i], xi1 = x[3 * i + 1], xi2 = x[3 * i + 2];
        const Real ui0 = u[3 * i], ui1 = u[3 * i + 1], ui2 = u[3 * i + 2];
        Real r = 0;
        for (std::uint64_t p = off[i]; p < off[i + 1]; ++p) {
            const std::size_t j = 3 * std::size_t(idx[p]);
            r += w[p] * ((ui0 - u[j]) * (xi0 - x[j]) + (ui1 - u[j + 1]) * (xi1 - x[j + 1]) +
                         (ui2 - u[j + 2]) * (xi2 - x[j + 2]));
        }
        if (boundarySum) r += ui0 * boundarySum[i].x() + ui1 * boundarySum[i].y() + ui2 * boundarySum[i].z();
        if (bodyRate) r -= bodyRate[i];
        rate[i] = r;
    }
}

void pressureChange(std::size_t begin, std::size_t end, Pairs fluid, const Vec3* boundarySum, const Vec3* xv,
                    const Real* s, Real dt, Vec3* dv) {
    const Real* x = raw(xv);
    const std::uint64_t* off = fluid.list->offsets.data();
    const std::uint32_t* idx = fluid.list->indices.data();
    const Real* w = fluid.weight;
    for (std::size_t i = begin; i < end; ++i) {
        const Real xi0 = x[3 * i], xi1 = x[3 * i + 1], xi2 = x[3 * i + 2];
        const Real si = s[i];
        Real a0 = 0, a1 = 0, a2 = 0;
        for (std::uint64_t p = off[i]; p < off[i + 1]; ++p) {
            const std::uint32_t j = idx[p];
            const Real c = w[p] * (si + s[j]);
            a0 += c * (xi0 - x[3 * std::size_t(j)]);
            a1 += c * (xi1 - x[3 * std::size_t(j) + 1]);
            a2 += c * (xi2 - x[3 * std::size_t(j) + 2]);
        }
        if (boundarySum) {
            a0 += si * boundarySum[i].x();
            a1 += si * boundarySum[i].y();
            a2 += si * boundarySum[i].z();
        }
        dv[i] = Vec3(-dt * a0, -dt * a1, -dt * a2);
    }
}

}  // namespace ganache::sweeps
