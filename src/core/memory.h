// Process-wide memory policy for frame loops.
#pragma once

#include <memory>
#include <utility>

namespace mobirt {

// Every frame allocates and frees buffers of megabytes (rays, hit records, texels, kd-tree
// arrays). glibc serves blocks above its mmap threshold with fresh pages from the kernel and
// returns them on free, so each frame pays a page fault per 4 KiB touched: on this machine
// allocating and filling one frame's ray arrays (5 MB) took 1.1 ms that way and 0.12 ms with the
// memory kept. This raises the mmap and trim thresholds (256 MiB, 1 GiB) so that freed frame
// buffers stay in the heap for the next frame. Call once at start-up, before any thread starts.
// The cost: the process keeps its peak heap until it exits.
void retain_freed_memory();

// An allocator whose value-initialising construct() (what vector(n) and resize(n) call) writes
// nothing: the elements of such a vector are left as the allocation found them, and the code
// that fills it must write every one. For the per-ray arrays of a frame, which are filled on all
// cores right after they are made: a serial pass that first writes a default into each of them
// cost as much as the work itself (96,000 surface records, 6.9 MB: 1.0 ms, with the passes'
// data having pushed the array out of the cache; the parallel decoding that then overwrites them
// all, 1.1 ms). Only for implicit-lifetime types (aggregates, trivially constructible types),
// whose objects the allocation itself creates.
template <class T>
struct UnwrittenAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UnwrittenAllocator<U>;
  };
  UnwrittenAllocator() = default;
  template <class U>
  UnwrittenAllocator(const UnwrittenAllocator<U>&) noexcept {}
  template <class U>
  void construct(U*) noexcept {}  // value-initialisation: nothing written
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

}  // namespace mobirt
