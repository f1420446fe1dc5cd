#pragma once
// How the process holds on to memory it has freed, and how buffers refilled every step grow.

#include <cstddef>
#include <vector>

namespace ganache {

/// Keeps memory the program frees for its own later allocations instead of handing it back to the system. Each
/// surfaced frame, each particle cache written and each step's grids allocate and free buffers of tens to hundreds
/// of megabytes; handed back, the next frame's buffers are new pages, and every page's first touch is a page fault
/// (about 11 us each on the virtual machines this was measured on: a third of a 1M-particle frame's surfacing). The
/// price is that the process keeps the largest footprint any stage reached until it exits. Call once, first in main.
void keepFreedMemory();

/// Sizes a buffer that is about to be refilled whole: when it must grow, its old values are dropped instead of
/// copied, and an eighth more is kept in reserve, so that a size creeping up step after step (the pair count of a
/// fluid being compressed) does not reallocate, copy and first-touch new pages every step.
template <class T>
void resizeForRefill(std::vector<T>& buffer, std::size_t n) {
    if (n > buffer.capacity()) {
        std::vector<T>().swap(buffer);  // freed first, so that its block can serve the new one
        buffer.reserve(n + n / 8);
    }
    buffer.resize(n);
}

}  // namespace ganache
