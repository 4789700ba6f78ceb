// A parallel loop for the CPU stages of a frame (hit decoding, the shading pass's inputs, ray
// ordering, the CPU ray engines), on TBB's persistent worker threads (the kd-tree build's too).
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <thread>

namespace mobirt {

namespace detail {
// The calling thread's arena of loops on `threads` threads (>= 2), made at its first use and kept
// while the thread lives: at most `threads` threads, the caller included, run a loop's chunks.
tbb::task_arena& parallel_arena(unsigned threads);
// How many of parallel_for's chunks the calling thread is running, one inside another: a loop
// started inside a chunk runs in the arena that runs the chunk.
inline thread_local int chunk_depth = 0;
struct InChunk {
  InChunk() { ++chunk_depth; }
  ~InChunk() { --chunk_depth; }
  InChunk(const InChunk&) = delete;
  InChunk& operator=(const InChunk&) = delete;
};
}  // namespace detail

// Runs f(i) for every i in [0, n) on `threads` threads (0 = all cores), the calling thread
// included, in chunks of about `chunk` indices taken by whichever thread is free: rays differ a
// lot in cost, so a static split would leave a thread idle. The first exception thrown by f
// stops the loop and is rethrown here.
//
// The chunks run on TBB's worker threads, which outlive the loop. A loop used to start threads
// of its own and join them (std::thread): about 11 us a loop on an idle machine, and on a busy one
// (lavapipe's threads and the next frame's kd-tree build on the same two cores) the caller, done
// with every chunk, still waited to join a thread the scheduler had not yet run. Here a chunk no
// worker has taken is run by the caller, and the caller waits only for chunks that are running.
//
// `threads` is an upper bound, not a promise: when no worker is free (the kd-tree build's arena
// holds it) the caller runs every chunk itself. So f(i) must never wait for another index.
template <class F>
void parallel_for(uint32_t n, unsigned threads, F&& f, uint32_t chunk = 64) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  chunk = std::max(chunk, 1u);
  if (threads <= 1 || n <= chunk) {
    for (uint32_t i = 0; i < n; ++i) f(i);
    return;
  }
  // Isolated: a loop inside f(i) waits for its own chunks only, never by running another chunk of
  // this loop on the stack of a suspended f(i).
  const auto loop = [&] {
    tbb::this_task_arena::isolate([&] {
      // simple_partitioner: ranges split down to chunk indices or fewer, each a task to steal.
      tbb::parallel_for(
          tbb::blocked_range<uint32_t>(0, n, chunk),
          [&](const tbb::blocked_range<uint32_t>& r) {
            const detail::InChunk in_chunk;
            for (uint32_t i = r.begin(); i < r.end(); ++i) f(i);
          },
          tbb::simple_partitioner());
    });
  };
  // A loop inside a chunk (on the caller or on a TBB worker) runs in the arena that runs the chunk;
  // any other in the calling thread's own arena for the thread count (not per count of chunks:
  // the partitioner already makes no more tasks than chunks).
  if (detail::chunk_depth > 0) {
    loop();
  } else {
    detail::parallel_arena(threads).execute(loop);
  }
}

// How many chunks of `chunk` indices cover [0, n).
inline uint32_t chunk_count(uint32_t n, uint32_t chunk) { return uint32_t((uint64_t(n) + chunk - 1) / chunk); }

// parallel_for over the chunks of `chunk` indices that cover [0, n), one task each: f(c, begin,
// end) for chunk c, [begin, end) = [c chunk, min(n, (c + 1) chunk)). For loops that keep state per
// chunk: a count added to a shared total once per chunk (not once per index, from every core onto
// one cache line), or the chunk's own part of an output.
template <class F>
void parallel_for_chunks(uint32_t n, uint32_t chunk, unsigned threads, F&& f) {
  parallel_for(chunk_count(n, chunk), threads, [&](uint32_t c) {
    const uint32_t begin = c * chunk;
    f(c, begin, uint32_t(std::min<uint64_t>(n, uint64_t(begin) + chunk)));
  }, 1);
}

// memcpy on all cores for large copies (a frame's rays and shading inputs into the driver's mapped
// buffers, its read-backs): on one thread a 3 MB copy kept the other core idle for about half a
// millisecond (docs/performance-history.md, *Session 30*). Pieces of kParallelCopyChunk bytes;
// below two of them, one memcpy.
inline constexpr size_t kParallelCopyChunk = size_t(256) << 10;
inline void parallel_copy(void* dst, const void* src, size_t bytes) {
  if (bytes < 2 * kParallelCopyChunk) {
    if (bytes) std::memcpy(dst, src, bytes);
    return;
  }
  const uint32_t pieces = uint32_t((bytes + kParallelCopyChunk - 1) / kParallelCopyChunk);
  parallel_for(pieces, 0, [&](uint32_t c) {
    const size_t begin = size_t(c) * kParallelCopyChunk;
    std::memcpy(static_cast<char*>(dst) + begin, static_cast<const char*>(src) + begin,
                std::min(kParallelCopyChunk, bytes - begin));
  }, 1);
}

}  // namespace mobirt
