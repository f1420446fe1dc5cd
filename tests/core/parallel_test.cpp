#include "core/parallel.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstddef>
#include <utility>
#include <vector>

namespace ganache {
namespace {

// The parts one thread runs without TBB: in order, none larger than the grain, together the whole range once.
TEST(Parallel, OneThreadRunsTheRangeInOrderInPartsOfTheGrain) {
    tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
    ASSERT_TRUE(serial());
    std::vector<std::pair<std::size_t, std::size_t>> parts;
    forEachBlock(1000, [&](std::size_t begin, std::size_t end) { parts.emplace_back(begin, end); }, 256);
    const std::vector<std::pair<std::size_t, std::size_t>> expected{{0, 256}, {256, 512}, {512, 768}, {768, 1000}};
    EXPECT_EQ(parts, expected);
}

// The same sums on one thread as on two: the blocks, not the threads, decide the order of the additions.
TEST(Parallel, SumsAreTheSameOnOneAndTwoThreads) {
    const std::size_t n = 100000;
    auto term = [](std::size_t i) { return 1.0 / double(i + 1); };
    double one = 0, two = 0;
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
        one = deterministicSum(n, term);
    }
    {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
        EXPECT_FALSE(serial());
        two = deterministicSum(n, term);
    }
    EXPECT_EQ(one, two);
}

}  // namespace
}  // namespace ganache
