#include "solver/align/calibrate.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "core/error.hpp"
#include "solver/align/hull.hpp"
#include "solver/align/surface.hpp"

namespace facecap::align {

namespace {

double rms_radius(const Eigen::Matrix3Xd& p) {
  const Eigen::Vector3d c = p.rowwise().mean();
  return std::sqrt((p.colwise() - c).colwise().squaredNorm().mean());
}

// Refits the translation for a clamped scale: t = mean(dst) - s R mean(src).
void clamp_scale(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, std::span<const double> w, double smin,
                 double smax, Similarity& T) {
  if (T.scale >= smin && T.scale <= smax) return;
  T.scale = std::clamp(T.scale, smin, smax);
  Eigen::Vector3d ms = Eigen::Vector3d::Zero(), md = Eigen::Vector3d::Zero();
  double total = 0;
  for (Eigen::Index k = 0; k < src.cols(); ++k) {
    const double wk = w.empty() ? 1.0 : w[std::size_t(k)];
    ms += wk * src.col(k);
    md += wk * dst.col(k);
    total += wk;
  }
  if (total > 0) T.translation = md / total - T.scale * (T.rotation * (ms / total));
}

// Sets T's scale to the ratio of the weighted spreads of dst and src about their centroids
// and refits the translation. Least squares in dst's space (Umeyama) scales by
// cov(src, dst) / var(src), which shrinks as the correspondences get noisier; against
// closest points on a surface that feeds on itself (smaller, so closer, so smaller). The
// spread ratio is the symmetric estimate (Horn 1987): no pull in either direction.
void spread_scale(const Eigen::Matrix3Xd& src, const Eigen::Matrix3Xd& dst, std::span<const double> w, Similarity& T) {
  Eigen::Vector3d ms = Eigen::Vector3d::Zero(), md = Eigen::Vector3d::Zero();
  double total = 0;
  for (Eigen::Index k = 0; k < src.cols(); ++k) {
    const double wk = w.empty() ? 1.0 : w[std::size_t(k)];
    ms += wk * src.col(k), md += wk * dst.col(k), total += wk;
  }
  if (!(total > 0)) return;
  ms /= total, md /= total;
  double vs = 0, vd = 0;
  for (Eigen::Index k = 0; k < src.cols(); ++k) {
    const double wk = w.empty() ? 1.0 : w[std::size_t(k)];
    vs += wk * (src.col(k) - ms).squaredNorm(), vd += wk * (dst.col(k) - md).squaredNorm();
  }
  if (!(vs > 0) || !(vd > 0)) return;
  T.scale = std::sqrt(vd / vs);
  T.translation = md - T.scale * (T.rotation * ms);
}

bool converged(const Similarity& a, const Similarity& b, double length) {
  return rotation_angle(a.rotation.transpose() * b.rotation) < 1e-7 && std::abs(a.scale - b.scale) < 1e-9 * a.scale &&
         (a.translation - b.translation).norm() < 1e-9 * length;
}

}  // namespace

IcpResult icp_hulls(const Eigen::Matrix3Xd& marker_hull, const Eigen::Matrix3Xd& mesh_hull, const Similarity& start,
                    double scale_min, double scale_max, int iterations) {
  const PointIndex index(mesh_hull);
  IcpResult r{start, 0.0, 0};
  const Eigen::Index K = marker_hull.cols();
  Eigen::Matrix3Xd matched(3, K);
  const double length = rms_radius(mesh_hull);
  for (int it = 0; it < iterations; ++it) {
    for (Eigen::Index k = 0; k < K; ++k) matched.col(k) = mesh_hull.col(index.nearest(r.transform.apply(Eigen::Vector3d(marker_hull.col(k)))));
    Similarity next;
    if (!fit_similarity(marker_hull, matched, {}, true, next)) break;
    clamp_scale(marker_hull, matched, {}, scale_min, scale_max, next);
    r.iterations = it + 1;
    const bool done = converged(r.transform, next, length);
    r.transform = next;
    if (done) break;
  }
  double sum = 0;
  for (Eigen::Index k = 0; k < K; ++k) {
    double d2 = 0;
    index.nearest(r.transform.apply(Eigen::Vector3d(marker_hull.col(k))), &d2);
    sum += d2;
  }
  r.trimmed_rms = std::sqrt(sum / double(std::max<Eigen::Index>(K, 1)));
  return r;
}

namespace {

// One ICP run against the surface; the trimmed RMS over the best (1 - trim) markers.
// The first steps match points to their closest surface points (point-to-point, wide
// basin); then Gauss-Newton on the point-to-plane distance, which does not stall on the
// slow sliding along a smooth face that point-to-point ICP shows. Distances are weighed
// in the points' own units (rig distance / scale): in rig units every distance falls as
// the scale shrinks, and the fit would shrink the markers onto a patch of the face.
IcpResult surface_icp(const Eigen::Matrix3Xd& points, const SurfaceIndex& surface, const Similarity& start, double smin,
                      double smax, double trim, double trim_floor, int iterations, double length) {
  const Eigen::Index K = points.cols();
  IcpResult r{start, 0.0, 0};
  Eigen::Matrix3Xd matched(3, K), normal(3, K);
  std::vector<double> distance(static_cast<std::size_t>(K)), sorted(static_cast<std::size_t>(K)),
      weights(static_cast<std::size_t>(K));
  const std::size_t keep = std::max<std::size_t>(3, std::size_t(std::ceil(double(K) * (1.0 - trim))));
  auto correspond = [&](const Similarity& T) {
    for (Eigen::Index k = 0; k < K; ++k) {
      const SurfacePoint sp = surface.closest(T.apply(Eigen::Vector3d(points.col(k))));
      matched.col(k) = sp.position;
      normal.col(k) = surface.triangle_normal(sp.triangle);
      distance[std::size_t(k)] = sp.distance;
    }
    // Trimmed ICP (Chetverikov et al. 2002): the worst `trim` of the markers, where the
    // actor's face departs most from the rig's, are left out of each step and of the score,
    // unless they are within trim_floor of the surface.
    sorted = distance;
    std::nth_element(sorted.begin(), sorted.begin() + std::ptrdiff_t(keep - 1), sorted.end());
    const double cutoff = std::max(sorted[keep - 1], trim_floor);
    double sum = 0;
    std::size_t n = 0;
    for (Eigen::Index k = 0; k < K; ++k) {
      const bool kept = distance[std::size_t(k)] <= cutoff;
      weights[std::size_t(k)] = kept ? 1.0 : 0.0;
      if (kept) {
        sum += distance[std::size_t(k)] * distance[std::size_t(k)];
        ++n;
      }
    }
    return std::sqrt(sum / double(std::max<std::size_t>(n, 1)));
  };
  constexpr int kPointToPointSteps = 10;
  r.trimmed_rms = correspond(r.transform);
  for (int it = 0; it < iterations; ++it) {
    Similarity next;
    if (it < kPointToPointSteps) {
      if (!fit_similarity(points, matched, weights, true, next)) break;
      spread_scale(points, matched, weights, next);
    } else {
      // Linearised update about the kept points' centroid c: y -> y + w x (y - c) + d (y - c) + tau,
      // on the residual in the points' units, res / (s (1 + d)) ~ (res + J p - res d) / s.
      const Eigen::Matrix3Xd Y = r.transform.apply(points);
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      double total = 0;
      for (Eigen::Index k = 0; k < K; ++k) c += weights[std::size_t(k)] * Y.col(k), total += weights[std::size_t(k)];
      c /= std::max(total, 1.0);
      Eigen::Matrix<double, 7, 7> H = Eigen::Matrix<double, 7, 7>::Zero();
      Eigen::Matrix<double, 7, 1> g = Eigen::Matrix<double, 7, 1>::Zero();
      for (Eigen::Index k = 0; k < K; ++k) {
        if (weights[std::size_t(k)] <= 0.0) continue;
        const Eigen::Vector3d n = normal.col(k), a = Y.col(k) - c;
        Eigen::Matrix<double, 7, 1> J;
        const double res = n.dot(Y.col(k) - matched.col(k));
        J << a.cross(n), n.dot(a) - res, n;
        H += J * J.transpose();
        g += J * res;
      }
      H.diagonal().array() += 1e-9 * (H.diagonal().maxCoeff() + 1e-30);
      const Eigen::Matrix<double, 7, 1> step = -H.ldlt().solve(g);
      if (!step.allFinite()) break;
      const Eigen::Vector3d w = step.head<3>();
      const double angle = w.norm();
      const Eigen::Matrix3d dR = angle > 0 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
      Similarity U;
      U.rotation = dR;
      U.scale = 1.0 + step[3];
      if (!(U.scale > 0.5 && U.scale < 2.0)) break;
      U.translation = c + step.tail<3>() - U.scale * (dR * c);
      next = U * r.transform;
    }
    clamp_scale(points, matched, weights, smin, smax, next);
    const bool done = converged(r.transform, next, length);
    r.transform = next;
    r.iterations = it + 1;
    r.trimmed_rms = correspond(r.transform);
    if (done && it >= kPointToPointSteps) break;
  }
  return r;
}

}  // namespace

IcpResult icp_to_surface(const Eigen::Matrix3Xd& points, const Rig& rig, const Similarity& start, double scale_min,
                         double scale_max, double trim_fraction, int iterations) {
  const SurfaceIndex surface(rig.neutral, rig.triangles);
  return surface_icp(points, surface, start, scale_min, scale_max, trim_fraction, 0.0, iterations,
                     rms_radius(rig.neutral));
}

Calibration calibrate(const Rig& rig, const std::vector<std::string>& labels, const Eigen::Matrix3Xd& neutral,
                      const std::vector<uint8_t>& present, const CalibrationOptions& options) {
  const Eigen::Index K_all = neutral.cols();
  if (Eigen::Index(labels.size()) != K_all || Eigen::Index(present.size()) != K_all)
    throw Error(fmt::format("calibrate: {} labels, {} presence flags and {} marker positions disagree", labels.size(),
                            present.size(), K_all));
  if (rig.vertex_count() < 4 || rig.triangle_count() < 1) throw Error("calibrate: the rig has no usable mesh");
  Calibration cal;
  cal.rig_name = rig.name;
  cal.rig_hash = rig.content_hash();
  cal.rig_mm_per_unit = options.rig_mm_per_unit;

  std::vector<int> used;
  for (Eigen::Index k = 0; k < K_all; ++k) {
    const bool finite = neutral.col(k).allFinite();
    if (present[std::size_t(k)] && !finite)
      throw Error(fmt::format("calibrate: marker '{}' is flagged present but has a non-finite position (NaN)",
                              labels[std::size_t(k)]));
    if (present[std::size_t(k)]) used.push_back(int(k));
    else cal.notes.push_back(fmt::format("marker '{}' is missing in the calibration frame and is left out", labels[std::size_t(k)]));
  }
  if (int(used.size()) < options.minimum_markers)
    throw Error(fmt::format("calibrate: {} markers present in the calibration frame, at least {} needed", used.size(),
                            options.minimum_markers));
  const Eigen::Index K = Eigen::Index(used.size());
  Eigen::Matrix3Xd P(3, K);
  for (Eigen::Index i = 0; i < K; ++i) P.col(i) = neutral.col(used[std::size_t(i)]);

  const auto marker_hull_idx = convex_hull_vertices(P);
  const auto mesh_hull_idx = convex_hull_vertices(rig.neutral);
  Eigen::Matrix3Xd HP(3, Eigen::Index(marker_hull_idx.size())), HV(3, Eigen::Index(mesh_hull_idx.size()));
  for (std::size_t i = 0; i < marker_hull_idx.size(); ++i) HP.col(Eigen::Index(i)) = P.col(marker_hull_idx[i]);
  for (std::size_t i = 0; i < mesh_hull_idx.size(); ++i) HV.col(Eigen::Index(i)) = rig.neutral.col(mesh_hull_idx[i]);

  // Units: the hulls' size ratio names the decade (mm, cm, m are 10x apart; faces differ
  // far less), unless given.
  const double size_ratio = rms_radius(HV) / rms_radius(HP);  // rig units per take unit
  if (options.take_mm_per_unit) {
    cal.take_mm_per_unit = *options.take_mm_per_unit;
  } else {
    const double estimate = size_ratio * options.rig_mm_per_unit;  // mm per take unit
    double best = 1.0, best_gap = std::numeric_limits<double>::infinity();
    for (double candidate : {1.0, 10.0, 1000.0}) {
      const double gap = std::abs(std::log(estimate / candidate));
      if (gap < best_gap) best = candidate, best_gap = gap;
    }
    cal.take_mm_per_unit = best;
    cal.units_detected = true;
  }
  const double unit_scale = cal.take_mm_per_unit / options.rig_mm_per_unit;
  const double smin = unit_scale / options.scale_band, smax = unit_scale * options.scale_band;
  const double s0 = std::clamp(size_ratio, smin, smax);

  const SurfaceIndex surface(rig.neutral, rig.triangles);
  const double length = rms_radius(rig.neutral);
  const Eigen::Vector3d cP = HP.rowwise().mean(), cV = HV.rowwise().mean();
  const Eigen::Matrix3d axes_P = principal_axes(HP), axes_V = principal_axes(HV);

  std::vector<Eigen::Matrix3d> starts;
  for (const auto& Q : axis_rotations()) starts.push_back(axes_V * Q * axes_P.transpose());
  for (const auto& Q : axis_rotations()) starts.push_back(Q);

  IcpResult best{};
  best.trimmed_rms = std::numeric_limits<double>::infinity();
  double best_hull_rms = 0;
  for (std::size_t i = 0; i < starts.size(); ++i) {
    Similarity start;
    start.rotation = starts[i];
    start.scale = s0;
    start.translation = cV - s0 * (starts[i] * cP);
    const IcpResult hull = icp_hulls(HP, HV, start, smin, smax, options.hull_iterations);
    const IcpResult fine = surface_icp(P, surface, hull.transform, smin, smax, options.trim_fraction,
                                       options.trim_floor_mm / options.rig_mm_per_unit, options.surface_iterations, length);
    // Compared in take units (see surface_icp): a smaller scale must not win by itself.
    if (fine.trimmed_rms / fine.transform.scale < best.trimmed_rms / best.transform.scale) {
      best = fine;
      best_hull_rms = hull.trimmed_rms;
      cal.start_index = int(i);
    }
  }
  if (!std::isfinite(best.trimmed_rms)) throw Error("calibrate: no start converged (degenerate marker set?)");
  cal.take_to_rig = best.transform;
  cal.scale_at_band_limit = best.transform.scale <= smin * (1 + 1e-6) || best.transform.scale >= smax * (1 - 1e-6);
  if (cal.scale_at_band_limit)
    cal.notes.push_back(fmt::format("the scale reached the end of its search band ({:.4g} of {:.4g}..{:.4g} rig units per "
                                    "take unit): the face is {:.2f}x the rig's, or the fit is wrong",
                                    best.transform.scale, smin, smax, cal.face_size_ratio()));
  cal.hull_rms_mm = best_hull_rms * options.rig_mm_per_unit;
  cal.trimmed_rms_mm = best.trimmed_rms * options.rig_mm_per_unit;

  for (Eigen::Index i = 0; i < K; ++i) {
    const int k = used[std::size_t(i)];
    const Eigen::Vector3d x = cal.take_to_rig.apply(Eigen::Vector3d(P.col(i)));
    const SurfacePoint sp = surface.closest_exhaustive(x);
    MarkerCalibration m;
    m.label = labels[std::size_t(k)];
    m.binding.label = m.label;
    for (int j = 0; j < 3; ++j) m.binding.vertices[std::size_t(j)] = rig.triangles(j, sp.triangle);
    m.binding.barycentric = sp.barycentric;
    m.neutral = P.col(i);
    m.bound_point = sp.position;
    m.residual_mm = sp.distance * options.rig_mm_per_unit;
    cal.markers.push_back(std::move(m));
  }
  return cal;
}

}  // namespace facecap::align
