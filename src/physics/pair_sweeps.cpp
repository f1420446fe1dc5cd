#include "physics/pair_sweeps.h"

#include <cstdint>

namespace ganache::sweeps {

namespace {

// Positions and velocities are arrays of Vec3: three doubles each, contiguous.
inline const Real* raw(const Vec3* v) { return v->data(); }

}  // namespace

void viscousProduct(std::size_t begin, std::size_t end, Pairs fluid, Pairs boundary, const Vec3* xv, const Vec3* xbv,
                    const Vec3* inv, Real dt, Vec3* out) {
    const Real* x = raw(xv);
    const Real* v = raw(inv);
    const std::uint64_t* off = fluid.list->offsets.data();
    const std::uint32_t* idx = fluid.list->indices.data();
    const Real* k = fluid.weight;
    for (std::size_t i = begin; i < end; ++i) {
        const Real xi0 = x[3 * i], xi1 = x[3 * i + 1], xi2 = x[3 * i + 2];
        const Real vi0 = v[3 * i], vi1 = v[3 * i + 1], vi2 = v[3 * i + 2];
        Real a0 = 0, a1 = 0, a2 = 0;
        for (std::uint64_t p = off[i]; p < off[i + 1]; ++p) {
            const std::size_t j = 3 * std::size_t(idx[p]);
            const Real d0 = xi0 - x[j], d1 = xi1 - x[j + 1], d2 = xi2 - x[j + 2];
            const Real s = k[p] * (d0 * (vi0 - v[j]) + d1 * (vi1 - v[j + 1]) + d2 * (vi2 - v[j + 2]));
            a0 += s * d0;
            a1 += s * d1;
            a2 += s * d2;
        }
        if (boundary.weight) {
            const Real* xb = raw(xbv);
            const std::uint64_t* boff = boundary.list->offsets.data();
            const std::uint32_t* bidx = boundary.list->indices.data();
            for (std::uint64_t q = boff[i]; q < boff[i + 1]; ++q) {
                const std::size_t k3 = 3 * std::size_t(bidx[q]);
                const Real d0 = xi0 - xb[k3], d1 = xi1 - xb[k3 + 1], d2 = xi2 - xb[k3 + 2];
                const Real s = boundary.weight[q] * (d0 * vi0 + d1 * vi1 + d2 * vi2);
                a0 += s * d0;
                a1 += s * d1;
                a2 += s * d2;
            }
        }
        out[i] = Vec3(vi0 - dt * a0, vi1 - dt * a1, vi2 - dt * a2);
    }
}

void viscousProducts(std::size_t begin, std::size_t end, Pairs fluid, Pairs boundary, const Vec3* xv, const Vec3* xbv,
                     const Vec3* in1, const Vec3* in2, Real dt, Vec3* out1, Vec3* out2) {
    const Real* x = raw(xv);
    const Real* v = raw(in1);
    const Real* w = raw(in2);
    const std::uint64_t* off = fluid.list->offsets.data();
    const std::uint32_t* idx = fluid.list->indices.data();
    const Real* k = fluid.weight;
    for (std::size_t i = begin; i < end; ++i) {
        const Real xi0 = x[3 * i], xi1 = x[3 * i + 1], xi2 = x[3 * i + 2];
        const Real vi0 = v[3 * i], vi1 = v[3 * i + 1], vi2 = v[3 * i + 2];
        const Real wi0 = w[3 * i], wi1 = w[3 * i + 1], wi2 = w[3 * i + 2];
        Real a0 = 0, a1 = 0, a2 = 0, b0 = 0, b1 = 0, b2 = 0;
        for (std::uint64_t p = off[i]; p < off[i + 1]; ++p) {
            const std::size_t j = 3 * std::size_t(idx[p]);
            const Real d0 = xi0 - x[j], d1 = xi1 - x[j + 1], d2 = xi2 - x[j + 2];
            const Real s = k[p] * (d0 * (vi0 - v[j]) + d1 * (vi1 - v[j + 1]) + d2 * (vi2 - v[j + 2]));
            const Real t = k[p] * (d0 * (wi0 - w[j]) + d1 * (wi1 - w[j + 1]) + d2 * (wi2 - w[j + 2]));
            a0 += s * d0;
            a1 += s * d1;
            a2 += s * d2;
            b0 += t * d0;
            b1 += t * d1;
            b2 += t * d2;
        }
        if (boundary.weight) {
            const Real* xb = raw(xbv);
            const std::uint64_t* boff = boundary.list->offsets.data();
            const std::uint32_t* bidx = boundary.list->indices.data();
            for (std::uint64_t q = boff[i]; q < boff[i + 1]; ++q) {
                const std::size_t k3 = 3 * std::size_t(bidx[q]);
                const Real d0 = xi0 - xb[k3], d1 = xi1 - xb[k3 + 1], d2 = xi2 - xb[k3 + 2];
                const Real s = boundary.weight[q] * (d0 * vi0 + d1 * vi1 + d2 * vi2);
                const Real t = boundary.weight[q] * (d0 * wi0 + d1 * wi1 + d2 * wi2);
                a0 += s * d0;
                a1 += s * d1;
                a2 += s * d2;
                b0 += t * d0;
                b1 += t * d1;
                b2 += t * d2;
            }
        }
        out1[i] = Vec3(vi0 - dt * a0, vi1 - dt * a1, vi2 - dt * a2);
        out2[i] = Vec3(wi0 - dt * b0, wi1 - dt * b1, wi2 - dt * b2);
    }
}

void densityRate(std::size_t begin, std::size_t end, Pairs fluid, Pairs boundary, const Vec3* xv, const Vec3* xbv,
                 const Vec3* uv, const Vec3* ubv, Real* rate) {
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
        if (boundary.weight) {
            const Real* xb = raw(xbv);
            const Real* ub = ubv ? raw(ubv) : nullptr;
            const std::uint64_t* boff = boundary.list->offsets.data();
            const std::uint32_t* bidx = boundary.list->indices.data();
            for (std::uint64_t q = boff[i]; q < boff[i + 1]; ++q) {
                const std::size_t k3 = 3 * std::size_t(bidx[q]);
                const Real b0 = ub ? ub[k3] : 0, b1 = ub ? ub[k3 + 1] : 0, b2 = ub ? ub[k3 + 2] : 0;
                r += boundary.weight[q] *
                     ((ui0 - b0) * (xi0 - xb[k3]) + (ui1 - b1) * (xi1 - xb[k3 + 1]) + (ui2 - b2) * (xi2 - xb[k3 + 2]));
            }
        }
        rate[i] = r;
    }
}

void pressureChange(std::size_t begin, std::size_t end, Pairs fluid, Pairs boundary, const Vec3* xv, const Vec3* xbv,
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
        if (boundary.weight && si != 0) {
            const Real* xb = raw(xbv);
            const std::uint64_t* boff = boundary.list->offsets.data();
            const std::uint32_t* bidx = boundary.list->indices.data();
            Real b0 = 0, b1 = 0, b2 = 0;
            for (std::uint64_t q = boff[i]; q < boff[i + 1]; ++q) {
                const std::size_t k3 = 3 * std::size_t(bidx[q]);
                b0 += boundary.weight[q] * (xi0 - xb[k3]);
                b1 += boundary.weight[q] * (xi1 - xb[k3 + 1]);
                b2 += boundary.weight[q] * (xi2 - xb[k3 + 2]);
            }
            a0 += si * b0;
            a1 += si * b1;
            a2 += si * b2;
        }
        dv[i] = Vec3(-dt * a0, -dt * a1, -dt * a2);
    }
}

}  // namespace ganache::sweeps
