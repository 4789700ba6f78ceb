// Process-wide memory policy for frame loops.
#pragma once

namespace mobirt {

// Every frame allocates and frees buffers of megabytes (rays, hit records, texels, kd-tree
// arrays). glibc serves blocks above its mmap threshold with fresh pages from the kernel and
// returns them on free, so each frame pays a page fault per 4 KiB touched: on this machine
// allocating and filling one frame's ray arrays (5 MB) took 1.1 ms that way and 0.12 ms with the
// memory kept. This raises the mmap and trim thresholds (256 MiB, 1 GiB) so that freed frame
// buffers stay in the heap for the next frame. Call once at start-up, before any thread starts.
// The cost: the process keeps its peak heap until it exits.
void retain_freed_memory();

}  // namespace mobirt
