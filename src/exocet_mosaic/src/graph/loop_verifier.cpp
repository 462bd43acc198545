#include "exocet_mosaic/graph/loop_verifier.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace exocet_mosaic {
namespace graph {
namespace {

bool finitePositive(double v) { return std::isfinite(v) && v > 0.0; }

std::string fmt(double v) {
  std::ostringstream s;
  s.precision(3);
  s << v;
  return s.str();
}

Eigen::Vector2d transfer(const Eigen::Matrix3d& h, const Eigen::Vector2d& p) {
  const Eigen::Vector3d q = h * p.homogeneous();
  return q.hnormalized();
}

/// Pixel -> seabed point in the view's level frame (metres, origin under the camera), as a homography.
Eigen::Matrix3d groundFromPixel(const LoopView& view) {
  const Eigen::Matrix3d r = view.level_from_camera.normalized().toRotationMatrix();
  Eigen::Matrix3d m;
  m.row(0) = view.camera_height_m * r.row(0);
  m.row(1) = view.camera_height_m * r.row(1);
  m.row(2) = -r.row(2);
  return m * view.camera_matrix.inverse();
}

double groundSampleDistance_m(const LoopView& view) {
  return view.camera_height_m / std::sqrt(view.camera_matrix(0, 0) * view.camera_matrix(1, 1));
}

struct RigidFit {
  RelativePose2d pose;
  double scale = 1.0;  ///< of the similarity fit
  double rss_m2 = 0.0;
  Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
};

/// Least squares g_old = t + R(yaw) g_new (and the scale of the similarity fit).
RigidFit fitRigid(const std::vector<Eigen::Vector2d>& g_old, const std::vector<Eigen::Vector2d>& g_new) {
  RigidFit f;
  const size_t n = g_old.size();
  Eigen::Vector2d mo = Eigen::Vector2d::Zero(), mn = Eigen::Vector2d::Zero();
  for (size_t i = 0; i < n; ++i) {
    mo += g_old[i];
    mn += g_new[i];
  }
  mo /= double(n);
  mn /= double(n);
  double sdot = 0.0, scross = 0.0, snn = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d a = g_new[i] - mn, b = g_old[i] - mo;
    sdot += a.dot(b);
    scross += a.x() * b.y() - a.y() * b.x();
    snn += a.squaredNorm();
  }
  const double yaw = std::atan2(scross, sdot);
  f.scale = snn > 0.0 ? std::hypot(sdot, scross) / snn : 0.0;
  const Eigen::Rotation2Dd rot(yaw);
  f.pose.yaw_rad = yaw;
  f.pose.translation_m = mo - rot * mn;
  const Eigen::Matrix2d dr = rot.toRotationMatrix() * (Eigen::Matrix2d() << 0, -1, 1, 0).finished();
  for (size_t i = 0; i < n; ++i) {
    f.rss_m2 += (f.pose.translation_m + rot * g_new[i] - g_old[i]).squaredNorm();
    Eigen::Matrix<double, 2, 3> j;
    j.leftCols<2>().setIdentity();
    j.col(2) = dr * g_new[i];
    f.jtj += j.transpose() * j;
  }
  return f;
}

Eigen::Matrix3d toEigen(const cv::Mat& h) {
  Eigen::Matrix3d m;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m(i, j) = h.at<double>(i, j);
  return m;
}

std::vector<cv::Point2f> rectangle(const cv::Size& s) {
  return {{0.f, 0.f}, {float(s.width), 0.f}, {float(s.width), float(s.height)}, {0.f, float(s.height)}};
}

}  // namespace

Eigen::Quaterniond downwardLevelFromCamera() {
  Eigen::Matrix3d r;
  // Columns: the camera's x (image right) along -y (the key frame's right), its y (image down) along -x, its axis
  // down.
  r << 0, -1, 0, -1, 0, 0, 0, 0, -1;
  return Eigen::Quaterniond(r);
}

std::string LoopVerifierConfig::validate() const {
  std::ostringstream s;
  if (max_features < 0) s << "max_features = " << max_features << " must be >= 0; ";
  if (!finitePositive(sift_contrast_threshold))
    s << "sift_contrast_threshold = " << sift_contrast_threshold << " must be > 0; ";
  if (!(ratio > 0.0 && ratio <= 1.0)) s << "ratio = " << ratio << " must be in (0, 1]; ";
  if (!(std::abs(sift_offset_px) <= 1.0)) s << "sift_offset_px = " << sift_offset_px << " must be in [-1, 1]; ";
  if (!finitePositive(ransac_threshold_px)) s << "ransac_threshold_px = " << ransac_threshold_px << " must be > 0; ";
  if (ransac_iterations < 1) s << "ransac_iterations = " << ransac_iterations << " must be >= 1; ";
  if (min_inliers < 4) s << "min_inliers = " << min_inliers << " must be >= 4; ";
  auto unit = [&](const char* name, double v) {
    if (!(v >= 0.0 && v <= 1.0)) s << name << " = " << v << " must be in [0, 1]; ";
  };
  unit("min_inlier_fraction", min_inlier_fraction);
  unit("min_overlap_fraction", min_overlap_fraction);
  unit("min_hull_fraction", min_hull_fraction);
  if (!(max_scale_error >= 0.0 && max_scale_error < 1.0))
    s << "max_scale_error = " << max_scale_error << " must be in [0, 1); ";
  if (!finitePositive(max_projective_px)) s << "max_projective_px = " << max_projective_px << " must be > 0; ";
  if (!finitePositive(max_forward_backward_px))
    s << "max_forward_backward_px = " << max_forward_backward_px << " must be > 0; ";
  if (!finitePositive(max_rms_residual_px)) s << "max_rms_residual_px = " << max_rms_residual_px << " must be > 0; ";
  if (!(min_residual_sigma_px >= 0.0 && std::isfinite(min_residual_sigma_px)))
    s << "min_residual_sigma_px = " << min_residual_sigma_px << " must be finite and >= 0; ";
  if (max_effective_inliers < 1) s << "max_effective_inliers = " << max_effective_inliers << " must be >= 1; ";
  return s.str();
}

void checkLoopView(const LoopView& view, const char* which) {
  const std::string w = std::string(which) + " view: ";
  const Eigen::Matrix3d& k = view.camera_matrix;
  if (!k.allFinite()) throw std::invalid_argument(w + "camera_matrix is not finite");
  if (!(k(0, 0) > 0.0 && k(1, 1) > 0.0) || k(1, 0) != 0.0 || k(2, 0) != 0.0 || k(2, 1) != 0.0 || k(2, 2) != 1.0)
    throw std::invalid_argument(w + "camera_matrix is not [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0");
  if (view.image_size.width < 1 || view.image_size.height < 1)
    throw std::invalid_argument(w + "image_size must be positive");
  if (!finitePositive(view.camera_height_m))
    throw std::invalid_argument(w + "camera_height_m = " + fmt(view.camera_height_m) + " must be finite and > 0");
  if (!(view.camera_height_sigma_m >= 0.0 && std::isfinite(view.camera_height_sigma_m)))
    throw std::invalid_argument(w + "camera_height_sigma_m must be finite and >= 0");
  if (!(view.tilt_sigma_rad >= 0.0 && std::isfinite(view.tilt_sigma_rad)))
    throw std::invalid_argument(w + "tilt_sigma_rad must be finite and >= 0");
  const Eigen::Vector4d q = view.level_from_camera.coeffs();
  if (!q.allFinite() || q.norm() < 1e-6)
    throw std::invalid_argument(w + "level_from_camera is not a finite non-zero quaternion");
  // Every image corner must see the seabed (its ray pointing down).
  const Eigen::Matrix3d r = view.level_from_camera.normalized().toRotationMatrix();
  for (const cv::Point2f& c : rectangle(view.image_size)) {
    const Eigen::Vector3d ray = r * k.inverse() * Eigen::Vector3d(c.x, c.y, 1.0);
    if (!(ray.z() < -1e-3 * ray.norm()))
      throw std::invalid_argument(w + "the camera does not look down: an image corner's ray misses the seabed");
  }
}

LoopVerifier::LoopVerifier(const LoopVerifierConfig& config) : config_(config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("LoopVerifierConfig: " + problem);
}

LoopFeatures LoopVerifier::features(const cv::Mat& gray) const {
  if (gray.empty()) throw std::invalid_argument("loop verification: the image is empty");
  if (gray.type() != CV_8UC1) throw std::invalid_argument("loop verification: the image is not 8-bit grey (CV_8UC1)");
  LoopFeatures f;
  f.image_size = gray.size();
  cv::Ptr<cv::SIFT> sift = cv::SIFT::create(config_.max_features, 3, config_.sift_contrast_threshold);
  sift->detectAndCompute(gray, cv::noArray(), f.keypoints, f.descriptors);
  for (cv::KeyPoint& k : f.keypoints) k.pt -= cv::Point2f(config_.sift_offset_px, config_.sift_offset_px);
  return f;
}

LoopVerification LoopVerifier::verify(const cv::Mat& old_gray, const LoopView& old_view, const cv::Mat& new_gray,
                                      const LoopView& new_view) const {
  checkLoopView(old_view, "old");
  checkLoopView(new_view, "new");
  auto checkImage = [](const cv::Mat& g, const LoopView& v, const char* which) {
    const std::string w = std::string(which) + " image: ";
    if (g.empty()) throw std::invalid_argument(w + "empty");
    if (g.type() != CV_8UC1) throw std::invalid_argument(w + "not 8-bit grey (CV_8UC1)");
    if (g.size() != v.image_size)
      throw std::invalid_argument(w + std::to_string(g.cols) + "x" + std::to_string(g.rows) + " is not its view's " +
                                  std::to_string(v.image_size.width) + "x" + std::to_string(v.image_size.height));
  };
  checkImage(old_gray, old_view, "old");
  checkImage(new_gray, new_view, "new");
  return verify(features(old_gray), old_view, features(new_gray), new_view);
}

LoopVerification LoopVerifier::verify(const LoopFeatures& fo, const LoopView& old_view, const LoopFeatures& fn,
                                      const LoopView& new_view) const {
  checkLoopView(old_view, "old");
  checkLoopView(new_view, "new");
  if (fo.image_size != old_view.image_size) throw std::invalid_argument("old features: image size is not the view's");
  if (fn.image_size != new_view.image_size) throw std::invalid_argument("new features: image size is not the view's");
  LoopVerification v;
  v.features_old = int(fo.keypoints.size());
  v.features_new = int(fn.keypoints.size());
  auto refuse = [&v](const std::string& reason) {
    v.accepted = false;
    v.reason = reason;
    return v;
  };

  // ---- Matches and homography ----
  std::vector<cv::Point2f> pa, pb;
  if (!fo.descriptors.empty() && !fn.descriptors.empty() && fn.descriptors.rows >= 2) {
    std::vector<std::vector<cv::DMatch>> knn;
    cv::BFMatcher(cv::NORM_L2).knnMatch(fo.descriptors, fn.descriptors, knn, 2);
    for (const auto& m : knn)
      if (m.size() == 2 && m[0].distance < config_.ratio * m[1].distance) {
        pa.push_back(fo.keypoints[m[0].queryIdx].pt);
        pb.push_back(fn.keypoints[m[0].trainIdx].pt);
      }
  }
  v.matches = int(pa.size());
  if (v.matches < config_.min_inliers)
    return refuse("too few ratio-test matches: " + std::to_string(v.matches) + " < min_inliers " +
                  std::to_string(config_.min_inliers));
  cv::Mat mask;
  const cv::Mat h_ab =
      cv::findHomography(pa, pb, cv::USAC_MAGSAC, config_.ransac_threshold_px, mask, config_.ransac_iterations, 0.9999);
  if (h_ab.empty()) return refuse("no homography found from " + std::to_string(v.matches) + " matches");
  const Eigen::Matrix3d h = toEigen(h_ab) / h_ab.at<double>(2, 2);
  v.homography = h;
  const Eigen::Matrix3d h_inv = h.inverse();
  std::vector<Eigen::Vector2d> ia, ib;
  for (int i = 0; i < v.matches; ++i)
    if (mask.at<uchar>(i)) {
      ia.emplace_back(pa[i].x, pa[i].y);
      ib.emplace_back(pb[i].x, pb[i].y);
    }
  v.inliers = int(ia.size());
  v.inlier_fraction = double(v.inliers) / double(v.matches);
  if (v.inliers < config_.min_inliers)
    return refuse("too few inliers: " + std::to_string(v.inliers) + " < min_inliers " +
                  std::to_string(config_.min_inliers));
  if (v.inlier_fraction < config_.min_inlier_fraction)
    return refuse("inlier fraction " + fmt(v.inlier_fraction) + " < min_inlier_fraction " +
                  fmt(config_.min_inlier_fraction) + " (" + std::to_string(v.inliers) + " of " +
                  std::to_string(v.matches) + ")");

  // ---- Overlap in the new image and the inliers' spread over it ----
  std::vector<cv::Point2f> warped;
  for (const cv::Point2f& c : rectangle(old_view.image_size)) {
    const Eigen::Vector3d q = h * Eigen::Vector3d(c.x, c.y, 1.0);
    if (!(q.z() > 0.0)) return refuse("the homography sends an old image corner behind the new camera");
    warped.emplace_back(float(q.x() / q.z()), float(q.y() / q.z()));
  }
  if (!cv::isContourConvex(warped)) return refuse("the homography folds the old image (not convex)");
  std::vector<cv::Point2f> overlap;
  const double overlap_px2 = std::max(0.0f, cv::intersectConvexConvex(warped, rectangle(new_view.image_size), overlap));
  const double image_px2 = double(new_view.image_size.area());
  v.overlap_fraction = overlap_px2 / image_px2;
  if (v.overlap_fraction < config_.min_overlap_fraction || overlap.size() < 3)
    return refuse("overlap " + fmt(v.overlap_fraction) + " of the image < min_overlap_fraction " +
                  fmt(config_.min_overlap_fraction));
  std::vector<cv::Point2f> inliers_b, hull;
  for (const Eigen::Vector2d& p : ib) inliers_b.emplace_back(float(p.x()), float(p.y()));
  cv::convexHull(inliers_b, hull);
  v.hull_fraction = std::abs(cv::contourArea(hull)) / overlap_px2;
  if (v.hull_fraction < config_.min_hull_fraction)
    return refuse("inliers bunched: their convex hull covers " + fmt(v.hull_fraction) +
                  " of the overlap < min_hull_fraction " + fmt(config_.min_hull_fraction));

  // ---- Seabed-to-seabed map: close to rigid ----
  const Eigen::Matrix3d m_old = groundFromPixel(old_view), m_new = groundFromPixel(new_view);
  const Eigen::Matrix3d g_map = m_old * h_inv * m_new.inverse();  // new ground -> old ground
  {
    std::vector<Eigen::Vector2d> go, gn;
    for (const cv::Point2f& c : overlap) {
      const Eigen::Vector2d n = transfer(m_new, Eigen::Vector2d(c.x, c.y));
      gn.push_back(n);
      go.push_back(transfer(g_map, n));
    }
    const RigidFit sim = fitRigid(go, gn);
    v.scale = sim.scale;
    double worst_m = 0.0;
    const Eigen::Rotation2Dd rot(sim.pose.yaw_rad);
    Eigen::Vector2d mo = Eigen::Vector2d::Zero(), mn = Eigen::Vector2d::Zero();
    for (size_t i = 0; i < go.size(); ++i) {
      mo += go[i];
      mn += gn[i];
    }
    mo /= double(go.size());
    mn /= double(gn.size());
    for (size_t i = 0; i < go.size(); ++i)
      worst_m = std::max(worst_m, (mo + sim.scale * (rot * (gn[i] - mn)) - go[i]).norm());
    v.projective_px = worst_m / groundSampleDistance_m(old_view);
  }
  if (!(std::abs(v.scale - 1.0) <= config_.max_scale_error))
    return refuse("seabed scale " + fmt(v.scale) + " departs from 1 (the heights') by more than max_scale_error " +
                  fmt(config_.max_scale_error));
  if (!(v.projective_px <= config_.max_projective_px))
    return refuse("not a similarity on the seabed: departs by " + fmt(v.projective_px) + " px > max_projective_px " +
                  fmt(config_.max_projective_px));

  // ---- Forward-backward: an independent fit from new to old ----
  {
    cv::Mat mask_ba;
    const cv::Mat h_ba_cv = cv::findHomography(pb, pa, cv::USAC_MAGSAC, config_.ransac_threshold_px, mask_ba,
                                               config_.ransac_iterations, 0.9999);
    if (h_ba_cv.empty()) return refuse("forward-backward: no homography from the new image to the old one");
    const Eigen::Matrix3d round_trip = toEigen(h_ba_cv) * h;  // old -> old
    for (const cv::Point2f& c : overlap) {
      const Eigen::Vector2d q = transfer(h_inv, Eigen::Vector2d(c.x, c.y));
      v.forward_backward_px = std::max(v.forward_backward_px, (transfer(round_trip, q) - q).norm());
    }
  }
  if (!(v.forward_backward_px <= config_.max_forward_backward_px))
    return refuse("forward-backward: the two homographies disagree by " + fmt(v.forward_backward_px) +
                  " px > max_forward_backward_px " + fmt(config_.max_forward_backward_px));

  // ---- Residual ----
  double sum_sq = 0.0;
  for (size_t i = 0; i < ia.size(); ++i)
    sum_sq += 0.5 * ((transfer(h, ia[i]) - ib[i]).squaredNorm() + (transfer(h_inv, ib[i]) - ia[i]).squaredNorm());
  v.rms_residual_px = std::sqrt(sum_sq / double(ia.size()));
  if (!(v.rms_residual_px <= config_.max_rms_residual_px))
    return refuse("RMS transfer residual " + fmt(v.rms_residual_px) + " px > max_rms_residual_px " +
                  fmt(config_.max_rms_residual_px));

  // ---- Relative pose and covariance ----
  auto fitPose = [&](const LoopView& vo, const LoopView& vn) {
    const Eigen::Matrix3d mo = groundFromPixel(vo), mn = groundFromPixel(vn);
    std::vector<Eigen::Vector2d> go, gn;
    for (size_t i = 0; i < ia.size(); ++i) {
      go.push_back(transfer(mo, ia[i]));
      gn.push_back(transfer(mn, ib[i]));
    }
    return fitRigid(go, gn);
  };
  const RigidFit fit = fitPose(old_view, new_view);
  v.new_in_old = fit.pose;
  const double n = double(ia.size());
  const double gsd_m = 0.5 * (groundSampleDistance_m(old_view) + groundSampleDistance_m(new_view));
  // Both ends of a match are noisy: the ground residual's variance is the sum of theirs.
  const double floor_m = config_.min_residual_sigma_px * gsd_m * std::sqrt(2.0);
  const double sigma2 = std::max(fit.rss_m2 / std::max(1.0, 2.0 * n - 3.0), floor_m * floor_m);
  Eigen::Matrix3d cov = sigma2 * fit.jtj.inverse();
  if (n > config_.max_effective_inliers) cov *= n / double(config_.max_effective_inliers);
  auto addPerturbation = [&](const LoopView& vo, const LoopView& vn) {
    const RigidFit p = fitPose(vo, vn);
    Eigen::Vector3d d(p.pose.translation_m.x() - fit.pose.translation_m.x(),
                      p.pose.translation_m.y() - fit.pose.translation_m.y(),
                      wrapAngle(p.pose.yaw_rad - fit.pose.yaw_rad));
    cov += d * d.transpose();
  };
  for (int which = 0; which < 2; ++which) {
    const LoopView& base = which == 0 ? old_view : new_view;
    LoopView perturbed = base;
    if (base.camera_height_sigma_m > 0.0) {
      perturbed.camera_height_m = base.camera_height_m + base.camera_height_sigma_m;
      which == 0 ? addPerturbation(perturbed, new_view) : addPerturbation(old_view, perturbed);
    }
    if (base.tilt_sigma_rad > 0.0) {
      for (int a = 0; a < 2; ++a) {
        const Eigen::Vector3d axis = a == 0 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
        perturbed = base;
        perturbed.level_from_camera = Eigen::AngleAxisd(base.tilt_sigma_rad, axis) * base.level_from_camera;
        which == 0 ? addPerturbation(perturbed, new_view) : addPerturbation(old_view, perturbed);
      }
    }
  }
  v.covariance = 0.5 * (cov + cov.transpose());
  if (!v.covariance.allFinite() || !v.new_in_old.translation_m.allFinite())
    return refuse("the relative pose's fit is degenerate");
  v.accepted = true;
  v.reason.clear();
  return v;
}

}  // namespace graph
}  // namespace exocet_mosaic
