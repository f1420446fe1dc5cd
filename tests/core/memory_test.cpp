#include "core/memory.h"

#include <gtest/gtest.h>
#include <malloc.h>

#include <cstring>
#include <memory>
#include <vector>

// A buffer above any mapping threshold glibc would pick on its own (at most 32 MB): without keepFreedMemory it gets a
// mapping of its own, handed back to the system on free, so the next such buffer faults in new pages.
TEST(Memory, AFreedBufferStaysInTheHeapForTheNextOne) {
    ganache::keepFreedMemory();
    constexpr std::size_t kBytes = std::size_t(64) << 20;
    const std::size_t mappedBefore = mallinfo2().hblkhd;
    {
        const std::unique_ptr<char[]> buffer(new char[kBytes]);
        std::memset(buffer.get(), 1, kBytes);
        EXPECT_LT(mallinfo2().hblkhd, mappedBefore + kBytes) << "the buffer got a mapping of its own";
    }
    EXPECT_GE(mallinfo2().fordblks, kBytes) << "the freed buffer left the heap";
}

// A pair count creeping up by a few per cent a step, as while a block of fluid is compressed on impact: the buffer
// is allocated anew only when its reserve runs out, not every step.
TEST(Memory, ABufferRefilledEveryStepGrowsOnlyWhenItsReserveRunsOut) {
    std::vector<double> buffer;
    std::size_t allocations = 0, capacity = 0;
    for (std::size_t step = 0, n = 100000; step < 40; ++step, n += n / 50) {
        ganache::resizeForRefill(buffer, n);
        ASSERT_EQ(buffer.size(), n);
        if (buffer.capacity() != capacity) ++allocations, capacity = buffer.capacity();
    }
    // 2 % a step over 40 steps is 2.2x; an eighth in reserve covers six steps of it.
    EXPECT_LE(allocations, 8u);
}
