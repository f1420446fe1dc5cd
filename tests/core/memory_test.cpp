#include "core/memory.h"

#include <gtest/gtest.h>
#include <malloc.h>

#include <cstring>
#include <memory>

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
