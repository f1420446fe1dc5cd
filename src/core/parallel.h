#pragma once
// TBB loops shared by the solvers: per-particle gather loops and sums whose value does not depend on the
// thread count (fixed blocks, fixed combination order), so every run takes the same solver iterations; and loops over
// items of uneven cost for the rest.

#include "core/types.h"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <functional>
#include <vector>

namespace ganache {

namespace detail {
// The passes over the particles take them in blocks of this many. Up to kSharesUpTo particles every pass gives each
// thread the same share of the blocks (a static partition), so that what a share's particles hold stays in the cache
// of the core that wrote it: scheduled dynamically, a pass read what the pass before had written on the other core,
// and on the buckling anchor's 2,618 particles a pressure sweep took as long on 2 threads as on 1. Past that the
// particles' data does not stay in the caches from one pass to the next, and the passes are scheduled dynamically so
// that a thread that falls behind has blocks taken from it (equal shares made a viscous product of 1M particles on 2
// threads 1.1-1.5 times slower).
constexpr std::size_t kParticleBlock = 256;
constexpr std::size_t kSharesUpTo = std::size_t(1) << 16;

/// body(first, last) on ranges of at most two of the blocks of [0, n), in parallel as described above. Two blocks, 512
/// particles, bound what a pass keeps for a range (the densities' kernel values, the viscous weights' terms) to what
/// the core's cache holds.
template <class Body>
void forEachParticleBlock(std::size_t n, Body&& body) {
    const std::size_t count = (n + kParticleBlock - 1) / kParticleBlock;
    const auto run = [&](std::size_t first, std::size_t last) {
        for (std::size_t b = first; b < last; b += 2) body(b, std::min(last, b + 2));
    };
    // On one thread the blocks in a row, without the scheduler's microsecond a loop (tens of loops a step).
    if (count <= 2 || tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism) == 1)
        return run(0, count);
    const tbb::blocked_range<std::size_t> blocks(0, count, 1);
    const auto share = [&](const auto& r) { run(r.begin(), r.end()); };
    if (n <= kSharesUpTo)
        tbb::parallel_for(blocks, share, tbb::static_partitioner());
    else
        tbb::parallel_for(blocks, share);
}
}  // namespace detail

/// Calls f(begin, end) on blocks of [0, n) in parallel (see detail::kSharesUpTo); f must write only the slots of its
/// block.
template <class F>
void forEachBlock(std::size_t n, F&& f) {
    detail::forEachParticleBlock(n, [&](std::size_t first, std::size_t last) {
        f(first * detail::kParticleBlock, std::min(n, last * detail::kParticleBlock));
    });
}

/// Calls f(i) for i in [0, n) in parallel, shared out as forEachBlock shares them; f must write only particle i's
/// slots.
template <class F>
void forEachParticle(std::size_t n, F&& f) {
    forEachBlock(n, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i != end; ++i) f(i);
    });
}

/// Calls f(begin, end) on ranges of [0, n), at least `grain` long where n allows, scheduled dynamically: for items
/// whose cost varies (a level set's leaves, clusters), where equal shares would leave a thread waiting.
template <class F>
void forEachRange(std::size_t n, F&& f, std::size_t grain) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain), [&](const auto& r) { f(r.begin(), r.end()); });
}

/// Calls f(i) for i in [0, n), scheduled as forEachRange.
template <class F>
void forEachItem(std::size_t n, F&& f, std::size_t grain) {
    forEachRange(n, [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i != end; ++i) f(i);
    }, grain);
}

/// f(begin, end) over fixed blocks of [0, n), the blocks' results joined by `join` (associative: a sum, a minimum, or
/// several at once) in their order, which does not depend on the thread count; the blocks are shared out as
/// forEachBlock shares the particles. f may write the slots of its block.
template <class T, class F, class Join>
T deterministicBlockReduce(std::size_t n, F&& f, T zero, Join join) {
    constexpr std::size_t kBlock = detail::kParticleBlock;
    const std::size_t blocks = (n + kBlock - 1) / kBlock;
    if (blocks <= 1) return join(zero, f(0, n));
    std::vector<T> partial(blocks, zero);
    detail::forEachParticleBlock(n, [&](std::size_t first, std::size_t last) {
        for (std::size_t b = first; b != last; ++b) partial[b] = f(b * kBlock, std::min(n, (b + 1) * kBlock));
    });
    T s = zero;
    for (const T& p : partial) s = join(s, p);
    return s;
}

/// sum over fixed blocks [begin, end) of [0, n) of f(begin, end), deterministic for any thread count (the blocks and
/// the order their sums combine in do not depend on it); f may write the slots of its block, so a loop that updates
/// vectors also returns their dot products without a second pass.
template <class T = Real, class F>
T deterministicBlockSum(std::size_t n, F&& f, T zero = T(0)) {
    return deterministicBlockReduce<T>(n, f, zero, [](const T& a, const T& b) -> T { return a + b; });
}

/// sum_i term(i), deterministic for any thread count; T is any type with + and a zero (Real, Eigen vectors). term may
/// write particle i's slots.
template <class T = Real, class Term>
T deterministicSum(std::size_t n, Term&& term, T zero = T(0)) {
    return deterministicBlockSum<T>(n, [&](std::size_t begin, std::size_t end) {
        T s = zero;
        for (std::size_t i = begin; i != end; ++i) s += term(i);
        return s;
    }, zero);
}

}  // namespace ganache
