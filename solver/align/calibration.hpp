#pragma once
// The one calibration type: how an actor's markers relate to the rig. `facecap calibrate`
// measures it (Algorithm 1, calibrate.hpp) and saves it as a profile (profile.hpp);
// pipeline/calibration.hpp also reads it from a hand-written file or makes it for the
// default marker set. The marker mapper (pipeline/marker_mapper.hpp) turns it into
// per-frame solver targets, in facecapd and in every tool alike.
//
// Take units are the units of the calibration frame's markers; frames in other units are
// converted on the way in (a take in mm solved with a profile made in cm).
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "solver/align/geometry.hpp"
#include "solver/face_solver.hpp"
#include "solver/rig.hpp"

namespace facecap::align {

// A marker on the face: bound to a surface point and pinned there by the solve.
struct MarkerCalibration {
  std::string label;
  MarkerBinding binding;                                   // the surface point it sits on
  Eigen::Vector3d neutral = Eigen::Vector3d::Zero();       // take units, at the calibration frame
  Eigen::Vector3d bound_point = Eigen::Vector3d::Zero();   // rig space: the binding's position on the neutral mesh
  double residual_mm = 0.0;  // |transform(neutral) - bound_point| in rig millimetres
};

// A marker rigid with the skull but off the face (a headband, a cap, a helmet): used for
// the head pose only, never bound or pinned.
struct HeadMarkerCalibration {
  std::string label;
  Eigen::Vector3d neutral = Eigen::Vector3d::Zero();  // take units, at the calibration frame
};

// A rig shape the calibrated markers cannot observe: at full weight it moves no bound
// point by kObservableShapeMm or more, so Eq. 2 would set its weight from marker noise and
// calibration error alone (ICT's eyeLook*, eyeWide and cheekSquint move the eyeballs and
// lids, which no marker sits on). The solve leaves such shapes out of Eq. 2: their
// weights stay 0.
// A shape is also unobservable when a larger fitted shape moves the bound points the same
// way: same_as names it, and distinct_mm is the most a bound point's displacement differs
// from the best non-negative multiple of same_as's (ICT's eyeLookDown_R moves only
// Reye_Up, 3.5 mm down, as eyeBlink_R does: 0.6 mm apart, so the fit traded one for the
// other on marker noise).
struct UnobservedShape {
  std::string name;
  double max_displacement_mm = 0.0;  // rig mm: the most it moves a bound point at weight 1
  std::string same_as;               // empty: left out for moving the bound points too little
  double distinct_mm = 0.0;          // with same_as: rig mm, below distinct_shape_mm
};

// The threshold, rig mm at weight 1 (docs/solver.md, "Shapes no marker observes"): about
// twice the calibration's median per-marker residual on real takes (AnimFace on ICT:
// 1.5-1.7 mm), the mismatch between actor and rig that a weight fit will otherwise
// explain with whichever small shape fits it.
inline constexpr double kObservableShapeMm = 3.5;
// The least a shape's displacement at some bound point must differ from every larger
// fitted shape's (scaled to fit it best) for the markers to tell the two apart, rig mm at
// weight 1: above marker noise (0.2-0.4 mm). On AnimFace with ICT the shapes below it sit
// at 0.57-0.73 mm (eyeLookDown_* vs eyeBlink_*, cheekSquint_* vs cheekRaiser_*), the next
// at 1.65 mm.
inline constexpr double kDistinctShapeMm = 1.0;

struct Calibration {
  std::string rig_name;
  uint64_t rig_hash = 0;
  double rig_mm_per_unit = 10.0;
  double take_mm_per_unit = 10.0;
  bool units_detected = false;  // take units were detected, not given
  Similarity take_to_rig;       // rig = s R take + t at the calibration frame
  std::vector<MarkerCalibration> markers;           // bound, in solver order
  std::vector<HeadMarkerCalibration> head_markers;  // head pose only
  // Labels whose rigid motion is the head's (stabilisation): markers or head markers.
  std::vector<std::string> stable_markers;
  std::string source_take;      // the take calibrated from, or what made the calibration
  int64_t source_frame = -1;
  double hull_rms_mm = 0.0;     // rig mm, the winning start's hull ICP residual
  double trimmed_rms_mm = 0.0;  // rig mm, surface ICP residual over the kept markers
  int start_index = -1;         // which start won (diagnostics)
  bool scale_at_band_limit = false;  // the fit ended at its scale band's end (not stored: a note says so)
  std::vector<std::string> notes;  // what the operator should know (excluded markers, ...)
  // Shapes left out of Eq. 2 (find_unobserved_shapes). observability_known is false for
  // profiles written before it was stored: readers decide it then from the bindings.
  bool observability_known = false;
  double observable_shape_mm = kObservableShapeMm;  // the threshold it was decided with
  double distinct_shape_mm = 0.0;  // ditto for same_as (0: not decided, profiles before version 4)
  std::vector<UnobservedShape> unobserved_shapes;

  // The actor's face size over the rig's: actor mm per rig mm (1 / take_to_rig's scale,
  // in millimetres on both sides).
  double face_size_ratio() const { return take_mm_per_unit / (take_to_rig.scale * rig_mm_per_unit); }
  // Index of a label in markers, or -1.
  int find(const std::string& label) const;
  // Index of a label in head_markers, or -1.
  int find_head(const std::string& label) const;
  // The calibration-frame position (take units) of a bound or head marker, or nullptr.
  const Eigen::Vector3d* neutral_of(const std::string& label) const;
  // Bindings in solver order (the markers' order).
  std::vector<MarkerBinding> bindings() const;
  // The names of unobserved_shapes: the shapes the solve leaves out of Eq. 2.
  std::vector<std::string> unfitted_shapes() const;
};

// Decides unobserved_shapes from the markers' bindings on the rig: shapes moving no bound
// point by observable_shape_mm, then, largest first, shapes within kDistinctShapeMm of a
// larger shape still fitted (same_as); sets observability_known and distinct_shape_mm.
// Not real-time.
void find_unobserved_shapes(Calibration& calibration, const Rig& rig);

}  // namespace facecap::align
