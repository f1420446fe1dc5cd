#pragma once
// TBB loops shared by the solvers: per-particle gather loops and sums whose value does not depend on the
// thread count (fixed blocks, fixed combination order), so every run takes the same solver iterations.
//
// Loops over fewer than kStaticBelow items split their range into one contiguous part per thread (TBB's static
// partitioner), and TBB hands the k-th part of every such loop to the same thread: a thread then finds the particles it
// wrote in the loop before still in its own cache, where with work stealing each loop dealt the parts out afresh and
// the solver's sweeps began by moving them between the cores' caches. A step runs dozens of loops, most of them
// short at this size: the buckling anchor's 2,618 particles (2 threads) took 7 % less time a step. Larger loops
// keep TBB's work stealing, which evens out a thread that falls behind: there the data outgrows a core's cache either
// way, and the static split took the 50k anchor block 3 % longer a step.

#include "core/types.h"

#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <vector>

namespace ganache {

/// The fewest items a part of a loop holds: below twice this a loop runs on one thread.
constexpr std::size_t kGrain = 256;
/// Loops over fewer items split statically (see above).
constexpr std::size_t kStaticBelow = 8192;

/// Whether loops run on the calling thread alone (`--threads 1`).
inline bool serial() { return tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism) == 1; }

/// tbb::parallel_for over [0, n) in parts of at least `grain`, partitioned as above by `items`, the particles (or
/// other items) the loop covers. On one thread the parts of `grain` items are called in order, without TBB: its
/// tasks cost a few microseconds a loop even there, 6 % of the buckling anchor's step (2.41 -> 2.27 ms, 8
/// alternating runs). The parts stay small so that the bodies' block buffers keep fitting in the caches.
template <class Body>
void parallelRange(std::size_t n, std::size_t grain, std::size_t items, const Body& body) {
    if (serial()) {
        for (std::size_t b = 0; b < n; b += grain)
            body(tbb::blocked_range<std::size_t>(b, std::min(n, b + grain), grain));
        return;
    }
    const tbb::blocked_range<std::size_t> range(0, n, grain);
    if (items < kStaticBelow)
        tbb::parallel_for(range, body, tbb::static_partitioner());
    else
        tbb::parallel_for(range, body);
}

/// Calls f(i) for i in [0, n) in parallel; f must write only particle i's slots.
template <class F>
void forEachParticle(std::size_t n, F&& f, std::size_t grain = kGrain) {
    parallelRange(n, grain, n, [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
    });
}

/// Calls f(begin, end) on blocks of [0, n) in parallel; f must write only the slots of its block.
template <class F>
void forEachBlock(std::size_t n, F&& f, std::size_t grain = kGrain) {
    parallelRange(n, grain, n, [&](const auto& r) { f(r.begin(), r.end()); });
}

/// The blocks of the sums over [0, n): kGrain items, more from 64k items on so that there are at most 256 of them.
inline std::size_t sumBlock(std::size_t n) { return std::max<std::size_t>(kGrain, (n + 255) / 256); }

/// f(begin, end) over fixed blocks of [0, n), the blocks' results joined by `join` (associative: a sum, a minimum, or
/// several at once) in the blocks' order, which does not depend on the thread count. f may write the slots of its
/// block.
template <class T, class F, class Join>
T deterministicBlockReduce(std::size_t n, F&& f, T zero, Join join) {
    const std::size_t size = sumBlock(n), blocks = (n + size - 1) / size;
    std::vector<T> partial(blocks, zero);
    parallelRange(blocks, 1, n, [&](const auto& r) {
        for (std::size_t b = r.begin(); b != r.end(); ++b) partial[b] = f(b * size, std::min(n, (b + 1) * size));
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
