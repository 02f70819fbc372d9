#pragma once
// Marker labelling: each frame's points are matched to the markers' predicted positions
// by optimal assignment (Hungarian method, shortest augmenting paths as in Jonker and
// Volgenant), with a gate per marker. Points nothing claims are ghosts; markers without a
// point within their gate are dropouts (their gate widens while they stay lost). Labels
// the source gives are checked the same way, with a margin in their favour, so a swapped
// pair is corrected and flagged kMarkerRelabelled while noise never flips a good label.
// Everything is sized at construction; label() and check() are real-time safe.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/frame.hpp"
#include "solver/align/geometry.hpp"

namespace facecap::align {

// Minimum-cost assignment of rows to distinct columns (rows <= cols) of a dense cost
// matrix. O(rows^2 cols). Allocation-free after construction.
class AssignmentSolver {
 public:
  AssignmentSolver(int max_rows, int max_cols);
  // cost: row-major rows x cols. row_to_col: rows entries. Returns the total cost, or
  // NaN (nothing written) when rows > cols or the size exceeds the construction's.
  double solve(int rows, int cols, std::span<const double> cost, std::span<int> row_to_col) noexcept;

 private:
  int max_rows_, max_cols_;
  std::vector<double> u_, v_, minv_;
  std::vector<int> p_, way_;
  std::vector<uint8_t> used_;
};

struct LabellerParams {
  double gate = 1.0;                 // take units: a point further than this from a prediction is not that marker
  double gate_growth = 0.1;          // take units added per frame a marker stays lost ...
  double max_gate = 3.0;             // ... up to this
  double label_margin = 0.2;         // take units in favour of the label a point came with
  int max_points = 256;              // points per frame
  int initial_iterations = 8;        // rigid alignment iterations when (re)acquiring
  double reacquire_fraction = 0.5;   // fewer markers assigned than this: re-initialise next frame
};

struct LabelStats {
  int assigned = 0;
  int missing = 0;
  int ghosts = 0;       // points left unassigned
  int relabelled = 0;   // check(): markers whose point came with another label
  bool initialised = false;  // the frame was labelled by whole-set alignment to the reference
};

class MarkerLabeller {
 public:
  // labels: K names; reference: 3 x K positions of the markers in one pose (a calibration
  // frame), used to acquire the set on the first frame and after losing it. Throws Error
  // on size mismatch, non-finite reference or K < 3.
  MarkerLabeller(std::vector<std::string> labels, Eigen::Matrix3Xd reference, LabellerParams params = {});

  // Labels unlabelled points (at most max_points; extra points are ignored and counted
  // as ghosts). out.markers is resized to K at construction size (no allocation once
  // its capacity is K): marker k gets its point, or kMarkerMissing. Real-time safe.
  LabelStats label(std::span<const Eigen::Vector3d> points, MarkerFrame& out) noexcept;

  // Checks a labelled frame whose markers are in this labeller's label order (K markers):
  // swaps the positions of wrongly labelled markers back, flags them kMarkerRelabelled,
  // and marks points that fit no marker's gate kMarkerOutlier | kMarkerMissing. On the
  // first frame, and after losing the set, the reference shape is moved onto the points
  // (as label() acquires) and decides with the labels' margin; a marker it finds no point
  // for keeps its labelled point. Real-time safe.
  LabelStats check(MarkerFrame& frame) noexcept;

  void reset() noexcept;

  // What the labeller carries from one frame to the next: each marker's last position,
  // velocity and frames lost, and the set's motion.
  struct State {
    Eigen::Matrix3Xd last, velocity;  // 3 x K
    // The set's rigid motion (reference -> the last frame's points, fitted to the markers
    // assigned) and each marker's last position carried back by it: a lost marker is
    // predicted where the set's motion has taken it since, so it is found again after the
    // head moved while it was hidden.
    Similarity set_pose;
    bool set_pose_known = false;
    Eigen::Matrix3Xd last_in_reference;  // 3 x K
    std::vector<int> lost_frames;        // K: frames since last seen (0 = seen last frame)
    std::vector<uint8_t> ever_seen;      // K
    bool tracking = false;
  };
  // A state sized for this labeller. Not real-time.
  State make_state() const;
  // Copies the labeller's state into `state`; false (nothing copied) when it was not
  // sized for this labeller. Real-time safe.
  bool save(State& state) const noexcept;
  // Continues from `state`; false (nothing changed) when its marker count is not this
  // labeller's. Real-time safe.
  bool restore(const State& state) noexcept;

  const std::vector<std::string>& labels() const { return labels_; }
  Eigen::Index marker_count() const { return Eigen::Index(labels_.size()); }

 private:
  void predict() noexcept;
  // Assigns points_[0..n) to the predictions; own_label[j] is the marker point j came
  // labelled as (or -1). Fills assigned_point_ (K). Returns markers assigned.
  int assign(int n, std::span<const int> own_label, bool use_margin, double gate_scale) noexcept;
  void acquire(int n) noexcept;
  void update(int n) noexcept;
  bool fits(const State& state) const noexcept;

  std::vector<std::string> labels_;
  Eigen::Matrix3Xd reference_;
  LabellerParams params_;
  AssignmentSolver solver_;
  Eigen::Matrix3Xd points_, predicted_, aligned_reference_;
  State state_;
  std::vector<double> cost_;
  std::vector<int> row_to_col_, assigned_point_, own_label_, no_label_;
  std::vector<uint8_t> claimed_;  // max_points: check()'s (re)initialisation, a point taken
  std::vector<double> fit_weight_;
  Eigen::Matrix3Xd fit_src_, fit_dst_;
};

}  // namespace facecap::align
