#include "physics/pair_sweeps.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#endif

namespace ganache::sweeps {

namespace {

// Four lanes of doubles: a group of four pairs' values of one coordinate, or one pair's coordinates. Gathering
// instructions were tried for the neighbours' values and ran at half the speed of the scalar loops on AMD's cores;
// aligned row loads (and a transpose) do not.
#if defined(__AVX2__) && defined(__FMA__)
struct Lanes {
    __m256d v;
};
inline Lanes operator+(Lanes a, Lanes b) { return {_mm256_add_pd(a.v, b.v)}; }
inline Lanes operator-(Lanes a, Lanes b) { return {_mm256_sub_pd(a.v, b.v)}; }
inline Lanes operator*(Lanes a, Lanes b) { return {_mm256_mul_pd(a.v, b.v)}; }
inline Lanes operator/(Lanes a, Lanes b) { return {_mm256_div_pd(a.v, b.v)}; }
inline Lanes zero() { return {_mm256_setzero_pd()}; }
// a[j[0]], ..., a[j[3]]
inline Lanes gather(const Real* a, const std::size_t (&j)[4]) {
    return {_mm256_setr_pd(a[j[0]], a[j[1]], a[j[2]], a[j[3]])};
}
// a[0, count), zero beyond
inline Lanes loadFirst(const Real* a, int count) {
    if (count == 4) return {_mm256_loadu_pd(a)};
    const __m256i mask = _mm256_cmpgt_epi64(_mm256_set1_epi64x(count), _mm256_setr_epi64x(0, 1, 2, 3));
    return {_mm256_maskload_pd(a, mask)};
}
// The lanes rounded to PairWeight, stored to w[0, count), and widened back.
inline Lanes storeWeights(Lanes a, PairWeight* w, int count) {
    const __m128 f = _mm256_cvtpd_ps(a.v);
    if (count == 4) {
        _mm_storeu_ps(w, f);
    } else {
        const __m128i mask = _mm_cmpgt_epi32(_mm_set1_epi32(count), _mm_setr_epi32(0, 1, 2, 3));
        _mm_maskstore_ps(w, mask, f);
    }
    return {_mm256_cvtps_pd(f)};
}
inline Lanes broadcast(Real a) { return {_mm256_set1_pd(a)}; }
inline Lanes load(const Row& r) { return {_mm256_load_pd(r.data())}; }
// a * b + c, rounded once (asked for by name: the build lets the compiler fuse nothing on its own)
inline Lanes fma(Lanes a, Lanes b, Lanes c) { return {_mm256_fmadd_pd(a.v, b.v, c.v)}; }
// w[0, count), zero beyond: a tail never reads past its particle's pairs.
inline Lanes loadWeights(const PairWeight* w, int count) {
    if (count == 4) return {_mm256_cvtps_pd(_mm_loadu_ps(w))};
    const __m128i mask = _mm_cmpgt_epi32(_mm_set1_epi32(count), _mm_setr_epi32(0, 1, 2, 3));
    return {_mm256_cvtps_pd(_mm_maskload_ps(w, mask))};
}
// Lane l of c[k] is entry k of row r[l].
inline void transpose(const Row* const (&r)[4], Lanes (&c)[4]) {
    const __m256d r0 = _mm256_load_pd(r[0]->data()), r1 = _mm256_load_pd(r[1]->data());
    const __m256d r2 = _mm256_load_pd(r[2]->data()), r3 = _mm256_load_pd(r[3]->data());
    const __m256d t0 = _mm256_unpacklo_pd(r0, r1), t1 = _mm256_unpackhi_pd(r0, r1);
    const __m256d t2 = _mm256_unpacklo_pd(r2, r3), t3 = _mm256_unpackhi_pd(r2, r3);
    c[0].v = _mm256_permute2f128_pd(t0, t2, 0x20);
    c[1].v = _mm256_permute2f128_pd(t1, t3, 0x20);
    c[2].v = _mm256_permute2f128_pd(t0, t2, 0x31);
    c[3].v = _mm256_permute2f128_pd(t1, t3, 0x31);
}
inline Row row(Lanes a) {
    Row r;
    _mm256_store_pd(r.data(), a.v);
    return r;
}
#else
struct Lanes {
    Real v[4];
};
template <class Op>
inline Lanes lanewise(Lanes a, Lanes b, Op op) {
    return {{op(a.v[0], b.v[0]), op(a.v[1], b.v[1]), op(a.v[2], b.v[2]), op(a.v[3], b.v[3])}};
}
inline Lanes operator+(Lanes a, Lanes b) { return lanewise(a, b, [](Real x, Real y) { return x + y; }); }
inline Lanes operator-(Lanes a, Lanes b) { return lanewise(a, b, [](Real x, Real y) { return x - y; }); }
inline Lanes operator*(Lanes a, Lanes b) { return lanewise(a, b, [](Real x, Real y) { return x * y; }); }
inline Lanes operator/(Lanes a, Lanes b) { return lanewise(a, b, [](Real x, Real y) { return x / y; }); }
inline Lanes zero() { return {{0, 0, 0, 0}}; }
inline Lanes gather(const Real* a, const std::size_t (&j)[4]) { return {{a[j[0]], a[j[1]], a[j[2]], a[j[3]]}}; }
inline Lanes loadFirst(const Real* a, int count) {
    Lanes out = zero();
    for (int l = 0; l < count; ++l) out.v[l] = a[l];
    return out;
}
inline Lanes storeWeights(Lanes a, PairWeight* w, int count) {
    Lanes out;
    for (int l = 0; l < 4; ++l) {
        const PairWeight f(a.v[l]);
        if (l < count) w[l] = f;
        out.v[l] = Real(f);
    }
    return out;
}
inline Lanes broadcast(Real a) { return {{a, a, a, a}}; }
inline Lanes fma(Lanes a, Lanes b, Lanes c) {
    return {{std::fma(a.v[0], b.v[0], c.v[0]), std::fma(a.v[1], b.v[1], c.v[1]), std::fma(a.v[2], b.v[2], c.v[2]),
             std::fma(a.v[3], b.v[3], c.v[3])}};
}
inline Lanes load(const Row& r) { return {{r[0], r[1], r[2], r[3]}}; }
inline Lanes loadWeights(const PairWeight* w, int count) {
    Lanes out = zero();
    for (int l = 0; l < count; ++l) out.v[l] = Real(w[l]);
    return out;
}
inline void transpose(const Row* const (&r)[4], Lanes (&c)[4]) {
    for (int k = 0; k < 4; ++k)
        for (int l = 0; l < 4; ++l) c[k].v[l] = (*r[l])[k];
}
inline Row row(Lanes a) { return Row(a.v[0], a.v[1], a.v[2], a.v[3]); }
#endif
inline Real sum(Lanes a) {
    const Row l = row(a);
    return (l[0] + l[1]) + (l[2] + l[3]);
}

// Past this many bytes of rows read at random, a sweep no longer finds its neighbours' rows in the caches between the
// particles that share them, and with the few loads a core keeps in flight it waits on memory: the viscous product at
// 1M particles ran 2.3-2.9x faster on two threads than on one, where the memory's streaming rate gains 1.1-1.9x. There
// the rows of the pair kAhead ahead are asked for in advance (`sweep_bench`, 1 / 2 threads, ns a particle: the viscous
// product at 1M 84 -> 52 / 33-44 -> 23-24, at 195k 45-80 -> 44-46 / 30-33 -> 25-27). Where the rows stay in the
// caches the extra instructions cost (8k: 26-40 -> 35 on 1 thread), and at 50k it was a draw.
constexpr std::size_t kPrefetchFrom = std::size_t(8) << 20;
constexpr std::uint64_t kAhead = 128;

// Calls group(c, p, count, j) for each group of four of particle i's pairs, p .. p + count: j the four neighbours and
// c[s] their rows of `rows[s]`, transposed (c[s][k]'s lanes are the neighbours' entries k). A tail's missing pairs are
// particle i itself: a pair of a particle with itself has x_ij = 0 and, with weight zero, adds nothing.
// With Ahead, the rows of the pairs kAhead further on are prefetched (see prefetches()).
template <int S, bool Ahead = false, class Group>
inline void forEachGroup(std::size_t i, const NeighbourList& list, const Row* const (&rows)[S], Group group) {
    const std::uint64_t begin = list.offsets[i], end = list.offsets[i + 1];
    const std::uint32_t* idx = list.indices.data();
    for (std::uint64_t p = begin; p < end; p += 4) {
        const int count = int(std::min<std::uint64_t>(4, end - p));
        if constexpr (Ahead)
            if (p + kAhead + 4 <= list.pairs())
                for (int l = 0; l < 4; ++l)
                    for (int s = 0; s < S; ++s) __builtin_prefetch(rows[s] + idx[p + kAhead + std::uint64_t(l)]);
        std::size_t j[4];
        for (int l = 0; l < 4; ++l) j[l] = l < count ? idx[p + l] : i;
        Lanes c[S][4];
        for (int s = 0; s < S; ++s) {
            const Row* const r[4] = {rows[s] + j[0], rows[s] + j[1], rows[s] + j[2], rows[s] + j[3]};
            transpose(r, c[s]);
        }
        group(c, p, count, j);
    }
}

// The viscous product for N inputs in one pass over the pairs (the pairs' geometry is read once for all of them).
template <int N, bool Ahead>
void viscousProductsOf(std::size_t begin, std::size_t end, Pairs fluid, const BoundaryBlocks& boundary, const Row* x,
                       const Row* const (&in)[N], Real dt, Vec3* const (&out)[N]) {
    const Row* rows[N + 1] = {x};
    // the next particle with a boundary block, from the first at or after `begin`
    std::size_t wall = std::size_t(std::lower_bound(boundary.particle, boundary.particle + boundary.count,
                                                    std::uint32_t(begin)) - boundary.particle);
    for (int c = 0; c < N; ++c) rows[c + 1] = in[c];
    for (std::size_t i = begin; i < end; ++i) {
        const Lanes xi[3] = {broadcast(x[i][0]), broadcast(x[i][1]), broadcast(x[i][2])};
        Lanes ui[N][3], a[N][3];
        for (int c = 0; c < N; ++c)
            for (int d = 0; d < 3; ++d) ui[c][d] = broadcast(in[c][i][d]), a[c][d] = zero();
        forEachGroup<N + 1, Ahead>(i, *fluid.list, rows, [&](const Lanes (&r)[N + 1][4], std::uint64_t p, int count,
                                                             const std::size_t (&)[4]) {
            const Lanes k = loadWeights(fluid.weight + p, count);
            const Lanes d0 = xi[0] - r[0][0], d1 = xi[1] - r[0][1], d2 = xi[2] - r[0][2];
            for (int c = 0; c < N; ++c) {
                const Lanes (&u)[4] = r[c + 1];
                const Lanes s = k * fma(d2, ui[c][2] - u[2], fma(d1, ui[c][1] - u[1], d0 * (ui[c][0] - u[0])));
                a[c][0] = fma(s, d0, a[c][0]);
                a[c][1] = fma(s, d1, a[c][1]);
                a[c][2] = fma(s, d2, a[c][2]);
            }
        });
        const bool walled = wall < boundary.count && boundary.particle[wall] == i;
        for (int c = 0; c < N; ++c) {
            const Vec3 v(in[c][i][0], in[c][i][1], in[c][i][2]);
            Vec3 o = v - dt * Vec3(sum(a[c][0]), sum(a[c][1]), sum(a[c][2]));
            if (walled) {
                // written out: Eigen's matrix product fuses multiply-adds where the target has them
                const Mat3& b = boundary.block[wall];
                for (int r = 0; r < 3; ++r) o[r] += (b(r, 0) * v[0] + b(r, 1) * v[1]) + b(r, 2) * v[2];
            }
            out[c][i] = o;
        }
        wall += walled;
    }
}

template <int N>
void viscousProductsOf(std::size_t begin, std::size_t end, Pairs fluid, const BoundaryBlocks& boundary, const Row* x,
                       const Row* const (&in)[N], Real dt, Vec3* const (&out)[N]) {
    if (prefetches(*fluid.list, N + 1))
        viscousProductsOf<N, true>(begin, end, fluid, boundary, x, in, dt, out);
    else
        viscousProductsOf<N, false>(begin, end, fluid, boundary, x, in, dt, out);
}

// Prefetches a[j] and b[j] for the neighbour j of pair p + kAhead, where the lists' `pairs` reach that far.
template <class A, class B>
inline void prefetchAhead(const std::uint32_t* idx, std::uint64_t p, std::uint64_t pairs, const A* a, const B* b) {
    if (p + kAhead < pairs) {
        __builtin_prefetch(a + idx[p + kAhead]);
        __builtin_prefetch(b + idx[p + kAhead]);
    }
}

// The pressure sweeps take one pair per vector, its lanes the coordinates, and add the lanes only at the end: their
// pairs need no sum over coordinates in between (the viscous product's do, hence its groups of four pairs).
template <bool Ahead>
void densityRateOf(std::size_t begin, std::size_t end, Pairs fluid, const Vec3* boundarySum, const Real* bodyRate,
                   const Row* x, const Row* u, Real* rate) {
    const std::uint64_t* off = fluid.list->offsets.data();
    const std::uint32_t* idx = fluid.list->indices.data();
    const std::uint64_t pairs = fluid.list->pairs();
    for (std::size_t i = begin; i < end; ++i) {
        const Lanes xi = load(x[i]), ui = load(u[i]);
        // The fourth lanes stay zero: the rows' fourth values are. The pairs go to four sums in turn, so that a pair's
        // add need not wait for the one before it: with two, `sweep_bench`'s pressure pair took 36.5-37.7 against
        // 33.0-33.3 ns a particle at 8k (1 thread), the add's latency a pair.
        Lanes a = zero(), b = zero(), c = zero(), d = zero();
        auto term = [&](std::uint64_t p, Lanes sum) {
            if constexpr (Ahead) prefetchAhead(idx, p, pairs, x, u);
            const std::uint32_t j = idx[p];
            return fma(broadcast(Real(fluid.weight[p])), (ui - load(u[j])) * (xi - load(x[j])), sum);
        };
        std::uint64_t p = off[i];
        for (; p + 3 < off[i + 1]; p += 4) a = term(p, a), b = term(p + 1, b), c = term(p + 2, c), d = term(p + 3, d);
        for (; p < off[i + 1]; ++p) a = term(p, a);
        const Row l = row((a + b) + (c + d));
        Real r = (l[0] + l[1]) + l[2];
        if (boundarySum)
            r += (u[i][0] * boundarySum[i].x() + u[i][1] * boundarySum[i].y()) + u[i][2] * boundarySum[i].z();
        if (bodyRate) r -= bodyRate[i];
        rate[i] = r;
    }
}

template <bool Ahead>
void pressureChangeOf(std::size_t begin, std::size_t end, Pairs fluid, const Vec3* boundarySum, const Row* x,
                      const Real* s, Real dt, Vec3* dv, Row* dvRows) {
    const std::uint64_t* off = fluid.list->offsets.data();
    const std::uint32_t* idx = fluid.list->indices.data();
    const std::uint64_t pairs = fluid.list->pairs();
    for (std::size_t i = begin; i < end; ++i) {
        const Lanes xi = load(x[i]), si = broadcast(s[i]);
        Lanes a = zero(), b = zero(), c = zero(), d = zero();  // four sums in turn, as in densityRate
        auto term = [&](std::uint64_t p, Lanes sum) {
            if constexpr (Ahead) prefetchAhead(idx, p, pairs, x, s);
            const std::uint32_t j = idx[p];
            return fma(broadcast(Real(fluid.weight[p])) * (si + broadcast(s[j])), xi - load(x[j]), sum);
        };
        std::uint64_t p = off[i];
        for (; p + 3 < off[i + 1]; p += 4) a = term(p, a), b = term(p + 1, b), c = term(p + 2, c), d = term(p + 3, d);
        for (; p < off[i + 1]; ++p) a = term(p, a);
        const Row l = row((a + b) + (c + d));
        Vec3 total(l[0], l[1], l[2]);
        if (boundarySum) total += s[i] * boundarySum[i];
        dv[i] = -dt * total;
        if (dvRows) dvRows[i] = Row(dv[i].x(), dv[i].y(), dv[i].z(), 0);
    }
}

}  // namespace

bool prefetches(const NeighbourList& list, int rows) {
    return list.particles() * sizeof(Row) * std::size_t(rows) > kPrefetchFrom;
}

void toRows(std::size_t begin, std::size_t end, const Vec3* v, Row* rows) {
    for (std::size_t i = begin; i < end; ++i) rows[i] = Row(v[i].x(), v[i].y(), v[i].z(), 0);
}

void viscousProduct(std::size_t begin, std::size_t end, Pairs fluid, const BoundaryBlocks& boundary, const Row* x,
                    const Row* in, Real dt, Vec3* out) {
    const Row* const inputs[1] = {in};
    Vec3* const outputs[1] = {out};
    viscousProductsOf<1>(begin, end, fluid, boundary, x, inputs, dt, outputs);
}

void viscousProducts(std::size_t begin, std::size_t end, Pairs fluid, const BoundaryBlocks& boundary, const Row* x,
                     const Row* in1, const Row* in2, Real dt, Vec3* out1, Vec3* out2) {
    const Row* const inputs[2] = {in1, in2};
    Vec3* const outputs[2] = {out1, out2};
    viscousProductsOf<2>(begin, end, fluid, boundary, x, inputs, dt, outputs);
}

void viscousProducts(std::size_t begin, std::size_t end, Pairs fluid, const BoundaryBlocks& boundary, const Row* x,
                     const Row* in1, const Row* in2, const Row* in3, Real dt, Vec3* out1, Vec3* out2, Vec3* out3) {
    const Row* const inputs[3] = {in1, in2, in3};
    Vec3* const outputs[3] = {out1, out2, out3};
    viscousProductsOf<3>(begin, end, fluid, boundary, x, inputs, dt, outputs);
}

void squaredDistances(std::size_t begin, std::size_t end, const NeighbourList& list, const Row* x, Real* d2) {
    const Row* const rows[1] = {x};
    const std::uint64_t p0 = list.offsets[begin];
    for (std::size_t i = begin; i < end; ++i) {
        const Lanes xi[3] = {broadcast(x[i][0]), broadcast(x[i][1]), broadcast(x[i][2])};
        forEachGroup<1>(i, list, rows, [&](const Lanes (&c)[1][4], std::uint64_t p, int count,
                                           const std::size_t (&)[4]) {
            const Lanes a = xi[0] - c[0][0], b = xi[1] - c[0][1], d = xi[2] - c[0][2];
            const Row s = row((a * a + b * b) + d * d);
            for (int l = 0; l < count; ++l) d2[p + l - p0] = s[l];
        });
    }
}

void viscousWeights(std::size_t begin, std::size_t end, const NeighbourList& list, const Row* x,
                    const ViscousWeightTerms& t, PairWeight* weights, Mat3* blocks) {
    const Row* const rows[1] = {x};
    const Lanes c = broadcast(t.c), eps = broadcast(t.eps), one = broadcast(1);
    const Lanes inverseSpacing2 = broadcast(t.inverseSpacing2), linear = broadcast(t.linear),
                quadratic = broadcast(t.quadratic);
    for (std::size_t i = begin; i < end; ++i) {
        const Lanes xi[3] = {broadcast(x[i][0]), broadcast(x[i][1]), broadcast(x[i][2])};
        const Real mui = t.mu ? t.mu[i] : t.muConstant;
        const Lanes mi = broadcast(t.mass[i]), ri = broadcast(t.inverseDensity[i]), muiLanes = broadcast(mui);
        Lanes b00 = zero(), b01 = zero(), b02 = zero(), b11 = zero(), b12 = zero(), b22 = zero();
        // A tail's missing pairs get gradient zero: weight zero.
        forEachGroup<1>(i, list, rows, [&](const Lanes (&xj)[1][4], std::uint64_t p, int count,
                                           const std::size_t (&j)[4]) {
            const Lanes d0 = xi[0] - xj[0][0], d1 = xi[1] - xj[0][1], d2 = xi[2] - xj[0][2];
            const Lanes dd = (d0 * d0 + d1 * d1) + d2 * d2;
            const Lanes u = dd * inverseSpacing2 - one;
            const Lanes k = loadFirst(t.gradient + p, count) * (one + u * (linear + u * quadratic)) / (dd + eps);
            const Lanes muj = t.mu ? gather(t.mu, j) : muiLanes;
            // every factor symmetric in i and j, multiplied in one order: k_ij = k_ji to the last bit
            const Lanes w = storeWeights(
                c * (muiLanes + muj) * (mi + gather(t.mass, j)) * k * (ri * gather(t.inverseDensity, j)), weights + p,
                count);
            const Lanes w0 = w * d0, w1 = w * d1;
            b00 = b00 + w0 * d0, b01 = b01 + w0 * d1, b02 = b02 + w0 * d2;
            b11 = b11 + w1 * d1, b12 = b12 + w1 * d2, b22 = b22 + (w * d2) * d2;
        });
        const Real s00 = sum(b00), s01 = sum(b01), s02 = sum(b02), s11 = sum(b11), s12 = sum(b12), s22 = sum(b22);
        blocks[i] << s00, s01, s02, s01, s11, s12, s02, s12, s22;
    }
}

void densityRate(std::size_t begin, std::size_t end, Pairs fluid, const Vec3* boundarySum, const Real* bodyRate,
                 const Row* x, const Row* u, Real* rate) {
    if (prefetches(*fluid.list, 2))
        densityRateOf<true>(begin, end, fluid, boundarySum, bodyRate, x, u, rate);
    else
        densityRateOf<false>(begin, end, fluid, boundarySum, bodyRate, x, u, rate);
}

void pressureWeights(std::size_t begin, std::size_t end, const NeighbourList& list, const Row* x, const Real* gradient,
                     const Real* mass, PairWeight* weights, Row* sums) {
    const std::uint64_t* off = list.offsets.data();
    const std::uint32_t* idx = list.indices.data();
    for (std::size_t i = begin; i < end; ++i) {
        const Lanes xi = load(x[i]);
        Lanes a = zero(), squares = zero();
        for (std::uint64_t p = off[i]; p < off[i + 1]; ++p) {
            const std::uint32_t j = idx[p];
            weights[p] = PairWeight(mass[j] * gradient[p]);
            const Lanes g = broadcast(Real(weights[p])) * (xi - load(x[j]));
            a = a + g;
            squares = squares + g * g;
        }
        const Row l = row(a), s = row(squares);
        sums[i - begin] = Row(l[0], l[1], l[2], (s[0] + s[1]) + s[2]);
    }
}

void pressureChange(std::size_t begin, std::size_t end, Pairs fluid, const Vec3* boundarySum, const Row* x,
                    const Real* s, Real dt, Vec3* dv, Row* dvRows) {
    // the positions' rows and the neighbours' pressures, both read at random, counted as two arrays of rows
    if (prefetches(*fluid.list, 2))
        pressureChangeOf<true>(begin, end, fluid, boundarySum, x, s, dt, dv, dvRows);
    else
        pressureChangeOf<false>(begin, end, fluid, boundarySum, x, s, dt, dv, dvRows);
}

}  // namespace ganache::sweeps
