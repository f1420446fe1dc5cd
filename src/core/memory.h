#pragma once
// How the process holds on to memory it has freed.

namespace ganache {

/// Keeps memory the program frees for its own later allocations instead of handing it back to the system. Each
/// surfaced frame, each particle cache written and each step's grids allocate and free buffers of tens to hundreds
/// of megabytes; handed back, the next frame's buffers are new pages, and every page's first touch is a page fault
/// (about 11 us each on the virtual machines this was measured on: a third of a 1M-particle frame's surfacing). The
/// price is that the process keeps the largest footprint any stage reached until it exits. Call once, first in main.
void keepFreedMemory();

}  // namespace ganache
