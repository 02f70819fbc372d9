#pragma once
// The writer side of the shared-memory ring (layout: client/facecap_shm_layout.hpp,
// docs/shm-format.md). Created once at configure time; publish() and beat() run on the
// solve thread.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <sys/types.h>

#include "client/facecap_shm_layout.hpp"
#include "core/frame.hpp"

namespace facecap::outputs {

struct ShmOutputSpec {
  std::string name;                      // "facecap" or "/facecap"
  std::vector<std::string> shape_names;  // M
  std::vector<std::string> arkit_names;  // parallel to shape_names, "" where none (formats::arkit_names_of)
  uint32_t vertex_count = 0;             // N, 0 to publish weights only
  uint32_t slot_count = 8;
  double nominal_rate_hz = 0.0;
  std::string rig_name;
  uint64_t rig_hash = 0;
};

class ShmWriter {
 public:
  // Creates the segment with O_EXCL and mode 0640. A segment left behind by a writer that
  // is dead (or stopped beating) is removed first; a live one is an Error. Not RT-safe.
  explicit ShmWriter(const ShmOutputSpec& spec);
  // Marks the writer stopped, unmaps, and unlinks the name unless a newer writer has
  // already replaced this segment under it. Not RT-safe.
  ~ShmWriter();
  ShmWriter(const ShmWriter&) = delete;
  ShmWriter& operator=(const ShmWriter&) = delete;

  // Copies one solved frame into the next slot under its seqlock and releases it.
  // frame.weights must have shape_count entries and frame.vertices vertex_count columns
  // (both as sized at configure time). Returns the publish time. RT-safe (no allocation,
  // no lock, no system call besides clock_gettime).
  int64_t publish(const SolvedFrame& frame) noexcept;

  // Proves the writer is alive even when no frame arrives. RT-safe.
  void beat(int64_t now_ns) noexcept;

  // Tells readers no more frames will come (before unlinking). RT-safe.
  void mark_stopped() noexcept;

  const std::string& name() const noexcept { return name_; }
  uint64_t published() const noexcept { return published_; }
  uint32_t shape_count() const noexcept { return header_->shape_count; }
  uint32_t vertex_count() const noexcept { return header_->vertex_count; }

 private:
  shm::SlotHeader& slot_for(uint64_t sequence) noexcept;

  std::string name_;
  unsigned char* base_ = nullptr;
  std::size_t size_ = 0;
  dev_t device_ = 0;
  ino_t inode_ = 0;
  shm::Header* header_ = nullptr;
  uint64_t published_ = 0;
};

// "/name" from "name"; throws Error for names shm_open would refuse.
std::string shm_object_name(const std::string& name);

}  // namespace facecap::outputs
