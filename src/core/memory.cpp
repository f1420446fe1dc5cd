#include "core/memory.h"

#include <malloc.h>

#include <limits>

namespace ganache {

void keepFreedMemory() {
    // glibc serves large requests from mappings of their own, unmapped again on free: every buffer is new pages.
    // Without mappings they come from the heap, which shrinks only once 2 GB at its top lie free. A request too large
    // for a worker thread's own heap (64 MB) still gets a mapping.
    mallopt(M_MMAP_MAX, 0);
    mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max());
}

}  // namespace ganache
