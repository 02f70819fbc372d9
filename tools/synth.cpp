// facecap synth: a synthetic marker take with its ground truth, for eval and tests.
// Drives a rig with weight curves (Live Link Face CSV or the built-in motion), samples
// marker vertices, optionally adds rigid head motion, noise and dropouts, and writes
// the take plus the truth (docs/tools.md).
#include <cmath>
#include <numbers>
#include <random>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "core/error.hpp"
#include "core/units.hpp"
#include "formats/take.hpp"
#include "solver/marker_layout.hpp"
#include "solver/solver_model.hpp"
#include "tools/commands.hpp"
#include "tools/synth_truth.hpp"
#include "tools/tool_support.hpp"

namespace facecap::tools {
namespace {

// Independent, reproducible random streams: one per effect, so that turning noise on
// does not change the dropouts of the same seed. std::mt19937_64 is fully specified by
// the standard; the distributions are written out here because the standard library's
// are not.
class RandomStream {
 public:
  RandomStream(uint64_t seed, uint64_t stream) : engine_(mix(seed ^ (0x9E3779B97F4A7C15ull * (stream + 1)))) {}
  double uniform() { return double(engine_() >> 11) * 0x1.0p-53; }  // [0, 1)
  double normal() {                                                  // Box-Muller
    const double u1 = 1.0 - uniform(), u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  static uint64_t mix(uint64_t z) {  // splitmix64 finaliser
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  std::mt19937_64 engine_;
};

constexpr double kMeanGapFrames = 6.0;  // dropouts come in runs of this mean length

struct SynthOptions {
  std::string rig, weights, output, units, rig_units_override;
  int markers = 60;
  std::vector<int> marker_vertices;
  long frames = -1;
  double rate = 0.0;
  double noise_mm = 0.0;
  double dropout = 0.0;
  bool head_motion = false;
  uint64_t seed = 1;
};

void run_synth(const SynthOptions& o) {
  const std::filesystem::path out_path(o.output);
  const auto format = formats::format_from_extension(out_path);
  if (!format || *format == formats::TakeFormat::kLiveLinkFace)
    throw Error(fmt::format("-o {}: the take must end in .trc, .c3d or .fcrec", o.output));
  if (!(o.dropout >= 0.0 && o.dropout < 1.0)) throw Error(fmt::format("--dropout {} must be in [0, 1)", o.dropout));
  if (!(o.noise_mm >= 0.0)) throw Error(fmt::format("--noise {} must be >= 0 mm", o.noise_mm));

  const Rig rig = load_rig(o.rig);
  const std::string rig_unit = rig_units(rig, o.rig_units_override);
  const std::string take_unit = o.units.empty() ? rig_unit : o.units;
  const auto take_mm = millimetres_per_unit(take_unit);
  if (!take_mm) throw Error(fmt::format("--units '{}': choose mm, cm or m", take_unit));
  const double mm_per_rig = *millimetres_per_unit(rig_unit);
  const double to_take_units = mm_per_rig / *take_mm;

  std::vector<MarkerBinding> layout;
  if (!o.marker_vertices.empty()) {
    for (int v : o.marker_vertices)
      if (v < 0 || v >= rig.vertex_count())
        throw Error(fmt::format("--marker-vertices: vertex {} is outside the rig's 0..{}", v, rig.vertex_count() - 1));
    layout = vertex_marker_layout(o.marker_vertices);
  } else {
    // Where facecapd's default calibration binds them, so that the take replays without one.
    layout = default_marker_set(rig, o.markers, 0).face;
  }
  const Eigen::Index K = Eigen::Index(layout.size());

  const WeightCurves curves = o.weights.empty() ? builtin_motion_curves(rig, o.rate > 0 ? o.rate : 60.0, o.frames < 0 ? 600 : o.frames)
                                                : livelinkface_curves(o.weights, rig, o.rate, o.frames);
  const std::size_t F = curves.frames.size();
  if (F == 0) throw Error("no frames to write");
  const bool builtin = is_builtin_face(rig);

  SynthTruth truth;
  truth.rig = o.rig;
  truth.rig_name = rig.name;
  truth.rig_hash = fmt::format("{:016x}", rig.content_hash());
  truth.rig_units = rig_unit;
  truth.take_file = out_path.filename().string();
  truth.take_units = take_unit;
  truth.rate_hz = curves.rate_hz;
  truth.seed = o.seed;
  truth.noise_mm = o.noise_mm;
  truth.dropout = o.dropout;
  truth.head_motion = o.head_motion;
  truth.weights_source = curves.source;
  for (const auto& b : layout) {
    truth.marker_labels.push_back(b.label);
    truth.marker_vertices.push_back(b.vertices[0]);
  }
  truth.shape_names = rig.shape_names;
  const std::filesystem::path stem = out_path.parent_path() / out_path.stem();
  const std::filesystem::path manifest_path = stem.string() + ".truth.json";
  truth.weights_file = stem.filename().string() + ".truth.csv";
  if (builtin) truth.vertices_file = stem.filename().string() + ".truth.vertices";

  RandomStream noise_rng(o.seed, 0), dropout_rng(o.seed, 1), head_rng(o.seed, 2);
  // Head motion: slow sinusoids about the face's centre, phases from the seed; up to
  // about 7 degrees of yaw and 15 mm of translation (typical of a seated performer).
  std::array<double, 6> phase{};
  for (double& p : phase) p = head_rng.uniform();
  const BoundingBox box = bounding_box(rig.neutral);
  const Eigen::Vector3d centre = 0.5 * (box.min + box.max);
  // Dropouts: per marker, a two-state chain whose missing fraction is --dropout and
  // whose gaps last kMeanGapFrames on average.
  const double p_recover = 1.0 / kMeanGapFrames;
  const double p_drop = o.dropout > 0 ? o.dropout * p_recover / (1.0 - o.dropout) : 0.0;
  std::vector<uint8_t> missing(std::size_t(K), 0);
  for (auto& m : missing) m = o.dropout > 0 && dropout_rng.uniform() < o.dropout;

  formats::MarkerTake take;
  take.format = *format;
  for (const auto& b : layout) take.labels.push_back(b.label);
  take.rate_hz = curves.rate_hz;
  take.units = take_unit;
  take.first_frame = 1;
  take.frames.reserve(F);
  std::unique_ptr<TruthVerticesWriter> vertices_out;
  if (builtin) vertices_out = std::make_unique<TruthVerticesWriter>(out_path.parent_path() / truth.vertices_file, rig.vertex_count(), int64_t(F));

  std::size_t missing_samples = 0;
  for (std::size_t f = 0; f < F; ++f) {
    const double t = double(f) / curves.rate_hz;
    const Eigen::VectorXd& w = curves.frames[f];
    const Eigen::Matrix3Xd pose = truth_pose(rig, builtin, w);
    if (vertices_out) vertices_out->append(pose);
    Eigen::Vector3d rotation = Eigen::Vector3d::Zero(), translation = Eigen::Vector3d::Zero();
    if (o.head_motion) {
      auto wave = [&](double period, int k) { return std::sin(2.0 * std::numbers::pi * (t / period + phase[std::size_t(k)])); };
      rotation = Eigen::Vector3d(0.06 * wave(4.7, 0), 0.12 * wave(6.3, 1), 0.04 * wave(5.9, 2));
      const Eigen::Vector3d shift_mm(8.0 * wave(7.3, 3), 5.0 * wave(5.1, 4), 10.0 * wave(8.9, 5));
      const Eigen::Matrix3d R = rotation_exp(rotation);
      translation = centre + shift_mm / mm_per_rig - R * centre;  // about the centre
    }
    const Eigen::Matrix3d R = rotation_exp(rotation);
    truth.weights.push_back(w);
    truth.head_rotation.push_back(rotation);
    truth.head_translation.push_back(translation);

    const Eigen::Matrix3Xd points = marker_positions(pose, layout);
    MarkerFrame& frame = formats::append_empty_frame(take, take.first_frame + int64_t(f), int64_t(std::llround(t * 1e9)));
    for (Eigen::Index k = 0; k < K; ++k) {
      Marker& marker = frame.markers[std::size_t(k)];
      marker.id = int32_t(k);
      if (f > 0 && o.dropout > 0) {
        const double u = dropout_rng.uniform();
        missing[std::size_t(k)] = missing[std::size_t(k)] ? (u >= p_recover) : (u < p_drop);
      }
      Eigen::Vector3d p = R * points.col(k) + translation;
      if (o.noise_mm > 0)
        for (int a = 0; a < 3; ++a) p[a] += noise_rng.normal() * o.noise_mm / mm_per_rig;
      if (missing[std::size_t(k)]) {
        formats::set_missing(marker);
        ++missing_samples;
        continue;
      }
      marker.position = p * to_take_units;
      marker.flags = 0;
    }
  }
  if (vertices_out) vertices_out->close();
  formats::write_take(out_path, take);
  write_synth_truth(manifest_path, truth);

  fmt::print("wrote {}: {} frames at {} Hz, {} markers, units {}\n", out_path.string(), F, curves.rate_hz, K, take_unit);
  fmt::print("  weights: {} ({} rig shapes driven{})\n", curves.source, curves.driven_shapes.size(),
             curves.held_frames ? fmt::format(", {} untracked rows held", curves.held_frames) : "");
  fmt::print("  noise {} mm, dropout {:.1f}% of samples ({} missing), head motion {}, seed {}\n", o.noise_mm,
             100.0 * double(missing_samples) / double(F * std::size_t(K)), missing_samples, o.head_motion ? "on" : "off", o.seed);
  fmt::print("  truth: {}, {}{}\n", manifest_path.string(), (out_path.parent_path() / truth.weights_file).string(),
             builtin ? ", " + (out_path.parent_path() / truth.vertices_file).string() + " (articulated vertices)"
                     : " (no truth vertices: eval uses the linear blend of the truth weights)");
}

}  // namespace

void add_synth_command(CLI::App& app, int& exit_code) {
  auto o = std::make_shared<SynthOptions>();
  auto* cmd = app.add_subcommand("synth", "Write a synthetic marker take and its ground truth from a rig and weight curves");
  cmd->add_option("--rig", o->rig, "builtin, an OBJ directory, a rig.toml manifest, a .gltf/.glb or an .fbx file")->required();
  cmd->add_option("--weights", o->weights, "Live Link Face CSV driving the rig (default: the built-in motion)")->check(CLI::ExistingFile);
  auto* markers = cmd->add_option("--markers", o->markers, "Markers on the face, where facecapd's default calibration puts that many (calibration.face_markers, with head_markers = 0)")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--marker-vertices", o->marker_vertices, "Markers on these vertex indices instead (comma-separated)")
      ->delimiter(',')
      ->excludes(markers);
  cmd->add_option("--frames", o->frames, "Frames to write (default: all the CSV covers, or 600 of the built-in motion)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--rate", o->rate, "Frame rate in Hz (default: the CSV's, or 60); CSV weights are resampled linearly")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--noise", o->noise_mm, "Gaussian noise per coordinate, standard deviation in mm")->capture_default_str();
  cmd->add_option("--dropout", o->dropout, "Fraction of marker samples missing, in runs of about 6 frames")->capture_default_str();
  cmd->add_flag("--head-motion", o->head_motion, "Move the whole face rigidly (up to ~7 degrees, ~15 mm)");
  cmd->add_option("--seed", o->seed, "Random seed: the same seed writes the same take")->capture_default_str();
  cmd->add_option("--units", o->units, "Units of the written take: mm, cm or m (default: the rig's)");
  cmd->add_option("--rig-units", o->rig_units_override, "The rig's units when they cannot be guessed: mm, cm or m");
  cmd->add_option("-o,--output", o->output, "The take to write: .trc, .c3d or .fcrec; the truth goes beside it")->required();
  cmd->callback([o, &exit_code] {
    run_synth(*o);
    exit_code = 0;
  });
}

}  // namespace facecap::tools
