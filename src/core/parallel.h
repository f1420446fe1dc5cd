#pragma once
// TBB loops shared by the solvers: per-particle gather loops and sums whose value does not depend on the
// thread count (fixed chunks, fixed combination order), so every run takes the same solver iterations.

#include "core/types.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <functional>
#include <vector>

namespace ganache {

/// Calls f(i) for i in [0, n) in parallel; f must write only particle i's slots.
template <class F>
void forEachParticle(std::size_t n, F&& f, std::size_t grain = 512) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
    });
}

/// Calls f(begin, end) on blocks of [0, n) in parallel; f must write only the slots of its block.
template <class F>
void forEachBlock(std::size_t n, F&& f, std::size_t grain = 512) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                      [&](const auto& r) { f(r.begin(), r.end()); });
}

/// f(begin, end) over fixed blocks of [0, n), the blocks' results joined by `join` (associative: a sum, a minimum, or
/// several at once) in an order that does not depend on the thread count. f may write the slots of its block.
template <class T, class F, class Join>
T deterministicBlockReduce(std::size_t n, F&& f, T zero, Join join) {
    return tbb::parallel_deterministic_reduce(
        tbb::blocked_range<std::size_t>(0, n, 2048), zero,
        [&](const auto& r, T s) { return join(s, f(r.begin(), r.end())); }, join);
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
