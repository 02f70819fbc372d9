#include "pipeline/pipeline_state.hpp"

#include <fmt/format.h>

#include "formats/byte_io.hpp"

namespace facecap::pipeline {
namespace {

using formats::ByteReader;
using formats::ByteWriter;

// Which optional stages the state holds (the parts byte).
constexpr uint8_t kLabeller = 1, kTargetFilter = 2, kWeightFilter = 4;

template <class Derived>
void put_matrix(ByteWriter& w, const Eigen::PlainObjectBase<Derived>& m) noexcept {
  w.u32(uint32_t(m.rows()));
  w.u32(uint32_t(m.cols()));
  for (Eigen::Index i = 0; i < m.size(); ++i) w.f64(m.data()[i]);  // column-major
}
Eigen::MatrixXd get_matrix(ByteReader& r, std::string_view what) {
  const uint32_t rows = r.u32(what), cols = r.u32(what);
  if (rows != 0 && cols > r.remaining() / 8 / rows) r.fail(fmt::format("{} of {} x {} exceeds the chunk", what, rows, cols));
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = r.f64(what);
  return m;
}
Eigen::Matrix3Xd get_points(ByteReader& r, std::string_view what) {
  Eigen::MatrixXd m = get_matrix(r, what);
  if (m.rows() != 3 && m.size() != 0) r.fail(fmt::format("{} has {} rows, 3 expected", what, m.rows()));
  return m.size() == 0 ? Eigen::Matrix3Xd(3, 0) : Eigen::Matrix3Xd(m);
}
Eigen::VectorXd get_vector(ByteReader& r, std::string_view what) {
  Eigen::MatrixXd m = get_matrix(r, what);
  if (m.cols() != 1 && m.size() != 0) r.fail(fmt::format("{} has {} columns, 1 expected", what, m.cols()));
  return m.size() == 0 ? Eigen::VectorXd() : Eigen::VectorXd(m);
}

template <class T>
void put_list(ByteWriter& w, const std::vector<T>& list) noexcept {
  w.u32(uint32_t(list.size()));
  for (const T v : list) {
    if constexpr (sizeof(T) == 1) w.u8(uint8_t(v));
    else if constexpr (sizeof(T) == 4) w.i32(int32_t(v));
    else w.i64(int64_t(v));
  }
}
template <class T>
std::vector<T> get_list(ByteReader& r, std::string_view what) {
  const uint32_t count = r.u32(what);
  if (count > r.remaining() / sizeof(T)) r.fail(fmt::format("{} count {} exceeds the chunk", what, count));
  std::vector<T> list(count);
  for (T& v : list) {
    if constexpr (sizeof(T) == 1) v = T(r.u8(what));
    else if constexpr (sizeof(T) == 4) v = T(r.i32(what));
    else v = T(r.i64(what));
  }
  return list;
}

void put_similarity(ByteWriter& w, const align::Similarity& s) noexcept {
  for (Eigen::Index i = 0; i < 9; ++i) w.f64(s.rotation.data()[i]);
  w.f64(s.scale);
  for (int i = 0; i < 3; ++i) w.f64(s.translation[i]);
}
align::Similarity get_similarity(ByteReader& r, std::string_view what) {
  align::Similarity s;
  for (Eigen::Index i = 0; i < 9; ++i) s.rotation.data()[i] = r.f64(what);
  s.scale = r.f64(what);
  for (int i = 0; i < 3; ++i) s.translation[i] = r.f64(what);
  return s;
}

void put_filter(ByteWriter& w, const OneEuroFilter::State& f) noexcept {
  put_matrix(w, f.raw);
  put_matrix(w, f.filtered);
  put_matrix(w, f.speed);
  put_list(w, f.live);
  w.i64(f.last_ns);
  w.u8(f.started);
}
OneEuroFilter::State get_filter(ByteReader& r, std::string_view what) {
  OneEuroFilter::State f;
  f.raw = get_matrix(r, what);
  f.filtered = get_matrix(r, what);
  f.speed = get_matrix(r, what);
  f.live = get_list<uint8_t>(r, what);
  f.last_ns = r.i64(what);
  f.started = r.u8(what) != 0;
  return f;
}

}  // namespace

void encode_pipeline_state(const SolvePipeline::State& state, std::vector<char>& out) noexcept {
  out.clear();
  ByteWriter w(out);
  w.u32(kPipelineStateVersion);
  w.u8(uint8_t((state.labeller ? kLabeller : 0) | (state.target_filter ? kTargetFilter : 0) |
               (state.weight_filter ? kWeightFilter : 0)));
  put_similarity(w, state.mapper.head_pose);
  put_matrix(w, state.mapper.accepted_targets);
  put_list(w, state.mapper.accepted_ns);
  put_matrix(w, state.solver.previous);
  put_matrix(w, state.solver.previous_linear);
  put_matrix(w, state.weights);
  put_matrix(w, state.vertices);
  if (const auto& l = state.labeller) {
    put_matrix(w, l->last);
    put_matrix(w, l->velocity);
    put_matrix(w, l->last_in_reference);
    put_list(w, l->lost_frames);
    put_list(w, l->ever_seen);
    put_similarity(w, l->set_pose);
    w.u8(l->set_pose_known);
    w.u8(l->tracking);
  }
  if (state.target_filter) put_filter(w, *state.target_filter);
  if (state.weight_filter) put_filter(w, *state.weight_filter);
}

SolvePipeline::State decode_pipeline_state(std::span<const char> bytes, std::string_view name) {
  ByteReader r(bytes, fmt::format("{} [STAT]", name));
  const uint32_t version = r.u32("state version");
  if (version != kPipelineStateVersion)
    r.fail(fmt::format("pipeline state version {}; this build reads version {}", version, kPipelineStateVersion));
  const uint8_t parts = r.u8("state parts");
  if (parts & ~(kLabeller | kTargetFilter | kWeightFilter)) r.fail(fmt::format("unknown state parts 0x{:02x}", parts));
  SolvePipeline::State state;
  state.mapper.head_pose = get_similarity(r, "head pose");
  state.mapper.accepted_targets = get_points(r, "accepted targets");
  state.mapper.accepted_ns = get_list<int64_t>(r, "accepted times");
  state.solver.previous = get_vector(r, "previous weights");
  state.solver.previous_linear = get_vector(r, "previous linear weights");
  state.weights = get_vector(r, "last weights");
  state.vertices = get_points(r, "last vertices");
  if (parts & kLabeller) {
    auto& l = state.labeller.emplace();
    l.last = get_points(r, "labeller positions");
    l.velocity = get_points(r, "labeller velocities");
    l.last_in_reference = get_points(r, "labeller reference positions");
    l.lost_frames = get_list<int>(r, "labeller lost frames");
    l.ever_seen = get_list<uint8_t>(r, "labeller seen markers");
    l.set_pose = get_similarity(r, "labeller set pose");
    l.set_pose_known = r.u8("labeller set pose") != 0;
    l.tracking = r.u8("labeller tracking") != 0;
  }
  if (parts & kTargetFilter) state.target_filter = get_filter(r, "target filter");
  if (parts & kWeightFilter) state.weight_filter = get_filter(r, "weight filter");
  if (r.remaining() != 0) r.fail(fmt::format("{} bytes after the pipeline state", r.remaining()));
  return state;
}

}  // namespace facecap::pipeline
