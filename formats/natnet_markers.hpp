#pragma once
// NatNet frames of data as marker frames: the one conversion that the live NatNet driver
// and the replay of a capture share.
//
// The frame's slots are chosen once, from the model definitions: the markers of one marker
// set, by name (an actor's face), then slots for unlabelled points. Each frame then fills
// them:
//   - the set's markers from the labelled markers of the model of the same name (a rigid
//     body, skeleton or asset: id = model id << 16 | marker id), which carry Motive's
//     flags: occluded -> missing, model-solved -> kMarkerModelSolved. A set marker without
//     a labelled marker this frame is missing. When the frame has no labelled marker of
//     that model (or no model has the set's name), the set's positions in the frame's
//     marker set data are used, (0, 0, 0) counting as missing;
//   - the unlabelled slots from the labelled markers without a model (model id 0), or,
//     when no marker set is chosen, every labelled marker seen; a frame without labelled
//     markers gives its legacy "other markers" instead. Points beyond the slots are
//     counted and dropped.
// Positions stay in metres, as NatNet sends them (kPositionUnits).
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/frame.hpp"
#include "formats/natnet.hpp"
#include "formats/natnet_capture.hpp"
#include "formats/take.hpp"

namespace facecap::formats::natnet {

// The units of every NatNet position.
inline constexpr std::string_view kPositionUnits = "m";

struct MarkerSelection {
  std::string marker_set;             // whose markers are the labelled slots; "" for none
  std::size_t unlabelled_slots = 0;   // slots for unlabelled points after them
  uint16_t timecode_rate_hz = 30;     // SMPTE rate of the server's timecode (the frame does not say)
};

// What one frame gave.
struct ConversionCounts {
  uint32_t set_markers = 0;         // marker-set slots with a position
  uint32_t unlabelled = 0;          // unlabelled points put in slots
  uint32_t unlabelled_dropped = 0;  // unlabelled points beyond the slots
};

class FrameConverter {
 public:
  // Labels of the unlabelled slots: "unlabelled_1", "unlabelled_2", ...
  static std::string unlabelled_label(std::size_t index);

  // Chooses the slots from `definitions`. Throws Error naming `server` when the marker set
  // is not among them (listing the sets there are) or the selection has no slot at all.
  // Not RT-safe.
  FrameConverter(MarkerSelection selection, const ModelDefinitions& definitions, std::string server);

  // Slot labels: the set's marker names as the definitions at construction gave them,
  // then the unlabelled slots.
  const std::vector<std::string>& labels() const noexcept { return labels_; }
  std::size_t set_slots() const noexcept { return set_slots_; }
  const MarkerSelection& selection() const noexcept { return selection_; }

  // Follows new model definitions (the models changed, the server restarted): the slots
  // stay and the set's markers are matched to them by name. Returns what the operator
  // should know, "" when every slot has its marker again. Not RT-safe.
  std::string follow(const ModelDefinitions& definitions);

  // Fills `out`, made by make_marker_frame(labels()), from one frame: number, server time,
  // timecode and markers. Does not allocate.
  ConversionCounts convert(const FrameOfData& frame, MarkerFrame& out) const noexcept;

 private:
  void put_unlabelled(const Position& position, int32_t id, uint32_t& next, ConversionCounts& counts,
                      MarkerFrame& out) const noexcept;

  MarkerSelection selection_;
  std::string server_;
  std::vector<std::string> labels_;
  std::size_t set_slots_ = 0;
  bool set_known_ = false;                           // the set is in the current definitions
  std::optional<uint16_t> model_id_;                 // the model of the set's name, if any
  std::vector<std::pair<uint16_t, int>> model_slot_;  // (marker id, slot or -1), sorted by marker id
  std::vector<int> set_index_slot_;                  // marker set data index -> slot or -1
};

// The frames of a capture as a take, converted by FrameConverter with the capture's model
// definitions (the first NAT_MODELDEF, then each later one followed from where it comes).
// Frames keep their capture times as source_time_ns, so that a paced replay plays them at
// their recorded timing. Throws Error naming `name` when the capture holds no frame, or no
// model definitions while a marker set is chosen. Not RT-safe.
MarkerTake capture_take(const NatNetCapture& capture, const MarkerSelection& selection, const std::string& name);

}  // namespace facecap::formats::natnet
