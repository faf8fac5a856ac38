// The thread team of both C++ kernels (contact_kernel.cc: the contact call's passes;
// neighbor_kernel.cc: the neighbour build), on the threads of XLA's intra-op pool.
#pragma once
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <functional>
#include <memory>
#include <thread>
#include "xla/ffi/api/ffi.h"

namespace drumheat {

namespace ffi = xla::ffi;

// The threads of a team for `most` threads' worth of work over n particles: the pool's
// threads, at most `most`, and at most n; DRUMHEAT_KERNEL_THREADS sets the number exactly
// (within [1, n]); at least 1.
inline int64_t team_size(ffi::ThreadPool& pool, int64_t most, int64_t n) {
  int64_t nc = pool.num_threads();
  if (nc > most) nc = most;
  if (const char* e = std::getenv("DRUMHEAT_KERNEL_THREADS")) nc = std::atoi(e);  // exactly
  if (nc > n) nc = n;
  return nc < 1 ? 1 : nc;
}

// The threads of one call's passes (contact_kernel.cc, Threads): team.each(run) runs run(c) for
// the chunks c = 0 .. size() - 1 and returns when all are done. The team's pool threads
// (size() - 1 of them, each a task given to the pool when the team is made) stay with the
// team until it is destroyed, waiting between the passes, so that a pass does not wait for a
// pool thread to wake up; the calling thread takes any chunk no pool thread has started, so
// the passes get done whether the pool's threads come or not.
class Team {
 public:
  Team(ffi::ThreadPool& pool, int64_t nc) : st_(std::make_shared<State>()) {
    st_->nc = static_cast<int>(nc);
    for (int64_t t = 1; t < nc; ++t) {
      std::shared_ptr<State> st = st_;
      pool.Schedule([st] { member(*st); });
    }
  }
  ~Team() {  // no pool thread touches the caller's frame after this
    st_->closed.store(true, std::memory_order_release);
    while (st_->active.load(std::memory_order_acquire) != 0) std::this_thread::yield();
  }
  Team(const Team&) = delete;
  Team& operator=(const Team&) = delete;
  int64_t size() const { return st_->nc; }

  void each(const std::function<void(int)>& run) {
    State& s = *st_;
    if (s.nc == 1) { run(0); return; }
    s.run = &run;
    s.done.store(0, std::memory_order_relaxed);
    ++pass_;
    s.word.store(static_cast<uint64_t>(pass_) << 32, std::memory_order_release);
    claim(s);
    for (int spins = 0; s.done.load(std::memory_order_acquire) < s.nc;) wait(spins);
  }

 private:
  // The pass's number (the high 32 bits) and its next unclaimed chunk (the low 32) in one
  // word: a chunk is claimed by one compare-and-swap of both, so a thread that read the word
  // of a pass before the next one began can claim nothing of either; the number of chunks
  // is the same for every pass (a claim past it runs nothing). A pool thread registers in
  // `active` before it looks at `closed`, and the caller sets `closed` before it waits for
  // `active` to drop to zero.
  static constexpr uint64_t kIndex = 0xffffffffu;
  struct State {
    std::atomic<uint64_t> word{kIndex};  // (no pass yet: nothing to claim)
    std::atomic<int> done{0};  // the chunks of the pass finished
    std::atomic<int> active{0};
    std::atomic<bool> closed{false};
    int nc = 1;
    const std::function<void(int)>* run = nullptr;  // the pass's (set before its word)
  };

  // claims and runs the chunks of the word's pass that are left
  static void claim(State& s) {
    uint64_t w = s.word.load(std::memory_order_acquire);
    while ((w & kIndex) < static_cast<uint64_t>(s.nc)) {
      if (s.word.compare_exchange_weak(w, w + 1, std::memory_order_acq_rel,
                                       std::memory_order_acquire)) {
        (*s.run)(static_cast<int>(w & kIndex));
        s.done.fetch_add(1, std::memory_order_release);
        w = s.word.load(std::memory_order_acquire);
      }
    }
  }
  // a pause in a wait (`spins` the pauses so far, counted up to the limit): the processor's
  // spin hint at first, then the thread's time slice given up
  static void wait(int& spins) {
    if (spins < 4096) {
      ++spins;
#if defined(__x86_64__) || defined(__i386__)
      __builtin_ia32_pause();
#endif
    } else {
      std::this_thread::yield();
    }
  }
  static void member(State& s) {
    s.active.fetch_add(1, std::memory_order_acq_rel);
    for (int spins = 0; !s.closed.load(std::memory_order_acquire);) {
      if ((s.word.load(std::memory_order_acquire) & kIndex) < static_cast<uint64_t>(s.nc)) {
        claim(s);
        spins = 0;
      } else {
        wait(spins);
      }
    }
    s.active.fetch_sub(1, std::memory_order_acq_rel);
  }

  std::shared_ptr<State> st_;
  uint32_t pass_ = 0;
};

}  // namespace drumheat
