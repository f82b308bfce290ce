// Streaming through device slots, shared by the device backends (docs/vulkan.md, "Streaming and
// memory"): pointing chunks go into two slots used in turn, so that while the device convolves one,
// the host fills the other and reads back the one before. Submissions complete in order.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <utility>

#include "pisco/error.hpp"

namespace pisco::detail {

// What a slot holds in flight: where its results go.
struct SlotJob {
  bool busy = false;
  std::uint64_t ticket = 0;
  std::size_t detector = 0;
  std::size_t first = 0;  // index of the slot's first sample within its submission
  std::size_t total = 0;  // samples in the submission
  std::span<double> tod;  // the caller's samples this slot writes
  bool accumulate = false;
};

// Which pointing samples a slot's staging buffer holds (PointingInput::shared): a submission that
// reads the same samples of the same shared chunk, in the same form, need not stage them again.
class StagedPointing {
 public:
  // Whether the buffer already holds samples [first, first + count) of shared chunk `shared` in this
  // form; if not, records them as what it holds from now on (the caller stages them) and counts them.
  // A `shared` of 0 is never held.
  bool reuse(std::uint64_t shared, std::size_t first, std::size_t count, bool quaternions) {
    if (shared != 0 && shared == shared_ && first == first_ && count == count_ && quaternions == quaternions_)
      return true;
    shared_ = shared;
    first_ = first;
    count_ = count;
    quaternions_ = quaternions;
    staged_ += count;
    return false;
  }
  // After an error, or when the buffer is written with anything else.
  void forget() noexcept { shared_ = 0; }
  // Samples staged so far.
  std::uint64_t staged() const noexcept { return staged_; }

 private:
  std::uint64_t shared_ = 0;
  std::size_t first_ = 0, count_ = 0;
  bool quaternions_ = false;
  std::uint64_t staged_ = 0;
};

// The pointing samples a backend's slots (each with a member `StagedPointing staged`) have staged.
template <class Slots>
std::uint64_t staged_samples(const Slots& slots) {
  std::uint64_t n = 0;
  for (const auto& s : slots) n += s.staged.staged();
  return n;
}

// Results of one slot into the caller's TOD: written, or added.
inline void deliver(const SlotJob& job, const double* results) {
  if (job.accumulate)
    for (std::size_t i = 0; i < job.tod.size(); ++i) job.tod[i] += results[i];
  else
    for (std::size_t i = 0; i < job.tod.size(); ++i) job.tod[i] = results[i];
}

// The ring of slots; Slot has a member `SlotJob job`. complete(slot) waits for a slot's work,
// delivers its results and returns the pixels it evaluated; it must not clear job.busy.
template <class Slot>
class SlotRing {
 public:
  SlotRing() = default;
  explicit SlotRing(std::span<Slot> slots) : slots_(slots) {}

  // The next slot in turn, completing its previous work first.
  template <class Complete>
  Slot& acquire(Complete&& complete) {
    Slot& s = slots_[next_ % slots_.size()];
    if (s.job.busy) finish(s, complete);
    ++next_;
    return s;
  }

  // Completes, oldest first, every busy slot whose ticket is at most `ticket`.
  template <class Complete>
  void drain(std::uint64_t ticket, Complete&& complete) {
    for (std::size_t k = 0; k < slots_.size(); ++k) {
      Slot& s = slots_[(next_ + k) % slots_.size()];
      if (s.job.busy && s.job.ticket <= ticket) finish(s, complete);
    }
  }

  std::uint64_t take_pixels() { return std::exchange(pixels_, 0); }
  // After an error: nothing is in flight any more (the caller has waited for the device).
  void abandon() {
    for (Slot& s : slots_) s.job.busy = false;
  }

 private:
  template <class Complete>
  void finish(Slot& s, Complete& complete) {
    pixels_ += complete(s);
    s.job.busy = false;
  }

  std::span<Slot> slots_;
  std::size_t next_ = 0;
  std::uint64_t pixels_ = 0;
};

// Makes device buffers for `chunk` samples a slot, halving the chunk on out-of-memory (OutOfMemory
// is the backend's exception type) down to one sample. Returns the chunk size that fitted.
template <class OutOfMemory, class Make, class Reset>
std::size_t fit_chunk_halving(std::size_t chunk, Make&& make, Reset&& reset, const std::string& device) {
  for (;;) {
    try {
      make(chunk);
      return chunk;
    } catch (const OutOfMemory&) {
      reset();
      if (chunk == 1) throw Error(device + ": out of memory even for one-sample chunks");
      chunk /= 2;
    }
  }
}

}  // namespace pisco::detail
