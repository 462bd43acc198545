#include "exocet_mosaic/fusion/navigation_filter.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iterator>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <Eigen/Cholesky>
#include <Eigen/Dense>

namespace exocet_mosaic {
namespace fusion {
namespace {

/// d/dtheta R(theta) = J R(theta).
const Eigen::Matrix2d kJ = (Eigen::Matrix2d() << 0.0, -1.0, 1.0, 0.0).finished();

Eigen::Matrix2d rotation2d(double angle_rad) {
  const double c = std::cos(angle_rad), s = std::sin(angle_rad);
  return (Eigen::Matrix2d() << c, -s, s, c).finished();
}

/// "" when the 2x2 covariance is finite, symmetric and positive definite; otherwise what is wrong.
std::string covarianceProblem(const Eigen::Matrix2d& c, const char* name) {
  if (!c.allFinite()) return std::string(name) + " is not finite";
  if (std::abs(c(0, 1) - c(1, 0)) > 1e-9 * (1.0 + c.cwiseAbs().maxCoeff()))
    return std::string(name) + " is not symmetric";
  if (!(c(0, 0) > 0.0) || !(c(0, 0) * c(1, 1) - c(0, 1) * c(1, 0) > 0.0))
    return std::string(name) + " is not positive definite";
  return "";
}

std::string format(double v, int precision = 6) {
  std::ostringstream s;
  s << std::setprecision(precision) << v;
  return s.str();
}

std::string stampText(double stamp_s) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(3) << stamp_s;
  return s.str();
}

void checkNonNegative(std::ostringstream& err, const char* field, double v, const char* unit) {
  if (!std::isfinite(v) || v < 0.0) err << field << " = " << v << " out of range [0, inf) " << unit << "; ";
}
void checkPositive(std::ostringstream& err, const char* field, double v, const char* unit) {
  if (!std::isfinite(v) || !(v > 0.0)) err << field << " = " << v << " out of range (0, inf) " << unit << "; ";
}

}  // namespace

// ---- FilterState, config ---------------------------------------------------------------------------------------

FilterState FilterState::from(double stamp_s, const StateVector& x, const StateMatrix& P) {
  FilterState s;
  s.stamp_s = stamp_s;
  s.position_en_m = x.segment<2>(kEast);
  s.position_covariance_m2 = P.block<2, 2>(kEast, kEast);
  s.pixel_size_correction = x[kPixelSize];
  s.pixel_size_correction_sigma = std::sqrt(std::max(0.0, P(kPixelSize, kPixelSize)));
  s.heading_error_rad = x[kHeading];
  s.heading_error_sigma_rad = std::sqrt(std::max(0.0, P(kHeading, kHeading)));
  s.heading_drift_rps = x[kHeadingDrift];
  s.dr_offset_en_m = x.segment<2>(kDrEast);
  s.dr_offset_covariance_m2 = P.block<2, 2>(kDrEast, kDrEast);
  s.dr_scale_error = x[kDrScale];
  s.dr_scale_error_sigma = std::sqrt(std::max(0.0, P(kDrScale, kDrScale)));
  s.x = x;
  s.P = P;
  return s;
}

std::string FilterConfig::validate() const {
  std::ostringstream err;
  checkNonNegative(err, "position_noise_m2_per_s", position_noise_m2_per_s, "m^2/s");
  checkNonNegative(err, "image_step_noise_along_m", image_step_noise_along_m, "m");
  checkNonNegative(err, "image_step_noise_across_m", image_step_noise_across_m, "m");
  checkPositive(err, "no_motion_position_noise_m2_per_s", no_motion_position_noise_m2_per_s, "m^2/s");
  checkNonNegative(err, "no_motion_speed_mps", no_motion_speed_mps, "m/s");
  checkNonNegative(err, "initial_pixel_size_correction_sigma", initial_pixel_size_correction_sigma, "");
  if (!(initial_pixel_size_correction_sigma < 0.5))
    err << "initial_pixel_size_correction_sigma = " << initial_pixel_size_correction_sigma
        << " out of range [0, 0.5); ";
  checkNonNegative(err, "pixel_size_correction_noise_per_sqrt_s", pixel_size_correction_noise_per_sqrt_s, "1/sqrt(s)");
  checkNonNegative(err, "initial_heading_sigma_rad", initial_heading_sigma_rad, "rad");
  if (!(initial_heading_sigma_rad <= 0.5))
    err << "initial_heading_sigma_rad = " << initial_heading_sigma_rad << " out of range [0, 0.5] rad; ";
  checkNonNegative(err, "initial_heading_drift_sigma_rps", initial_heading_drift_sigma_rps, "rad/s");
  checkNonNegative(err, "heading_noise_rad_per_sqrt_s", heading_noise_rad_per_sqrt_s, "rad/sqrt(s)");
  checkNonNegative(err, "heading_drift_noise_rps_per_sqrt_s", heading_drift_noise_rps_per_sqrt_s, "rad/s/sqrt(s)");
  checkPositive(err, "dr_measurement_sigma_m", dr_measurement_sigma_m, "m");
  checkNonNegative(err, "dr_offset_noise_m2_per_m", dr_offset_noise_m2_per_m, "m^2/m");
  checkNonNegative(err, "dr_offset_noise_m2_per_s", dr_offset_noise_m2_per_s, "m^2/s");
  if (!(initial_dr_scale_sigma >= 0.0 && initial_dr_scale_sigma < 0.5))
    err << "initial_dr_scale_sigma = " << initial_dr_scale_sigma << " out of range [0, 0.5); ";
  checkNonNegative(err, "dr_scale_noise_per_sqrt_s", dr_scale_noise_per_sqrt_s, "1/sqrt(s)");
  if (!(gate_probability > 0.0 && gate_probability < 1.0))
    err << "gate_probability = " << gate_probability << " out of range (0, 1); ";
  if (recovery_rejections < 1) err << "recovery_rejections = " << recovery_rejections << " out of range [1, inf); ";
  checkPositive(err, "history_s", history_s, "s");
  checkPositive(err, "max_prediction_gap_s", max_prediction_gap_s, "s");
  std::string s = err.str();
  if (!s.empty()) s.resize(s.size() - 2);
  return s;
}

Eigen::Matrix2d FilterConfig::imageStepNoiseCovariance(const Eigen::Vector2d& motion_m) const {
  const double along2 = image_step_noise_along_m * image_step_noise_along_m;
  const double across2 = image_step_noise_across_m * image_step_noise_across_m;
  const double length_m = motion_m.norm();
  if (!(length_m > 1e-6)) return 0.5 * (along2 + across2) * Eigen::Matrix2d::Identity();
  const Eigen::Vector2d u = motion_m / length_m;
  const Eigen::Matrix2d uu = u * u.transpose();
  return along2 * uu + across2 * (Eigen::Matrix2d::Identity() - uu);
}

double FilterConfig::gateThreshold() const { return -2.0 * std::log1p(-gate_probability); }

void NavigationFilter::setGating(double gate_probability, int recovery_rejections) {
  FilterConfig changed = config_;
  changed.gate_probability = gate_probability;
  changed.recovery_rejections = recovery_rejections;
  const std::string problems = changed.validate();
  if (!problems.empty()) throw std::invalid_argument("gating: " + problems);
  config_ = changed;
}

std::string toString(UpdateStatus status) {
  switch (status) {
    case UpdateStatus::kApplied:
      return "applied";
    case UpdateStatus::kRejectedByGate:
      return "rejected_by_gate";
    case UpdateStatus::kTooOld:
      return "too_old";
    case UpdateStatus::kInvalid:
      return "invalid";
    case UpdateStatus::kNotInitialized:
      return "not_initialized";
  }
  return "unknown";
}

// ---- Life cycle ------------------------------------------------------------------------------------------------

NavigationFilter::NavigationFilter(const FilterConfig& config) : config_(config) {
  const std::string problem = config_.validate();
  if (!problem.empty()) throw std::invalid_argument("FilterConfig: " + problem);
}

void NavigationFilter::reset() {
  initialized_ = false;
  log_.steps.clear();
  if (log_file_) log_file_->clear();
  events_.clear();
  have_image_ = have_dr_ = false;
  last_image_stamp_s_ = last_dr_stamp_s_ = 0.0;
  counters_ = Counters();
}

void NavigationFilter::initialize(double stamp_s, const Eigen::Vector2d& camera_en_m,
                                  const Eigen::Matrix2d& covariance_m2) {
  if (!std::isfinite(stamp_s)) throw std::invalid_argument("initialize: stamp_s is not finite");
  if (!camera_en_m.allFinite()) throw std::invalid_argument("initialize: camera_en_m is not finite");
  const std::string problem = covarianceProblem(covariance_m2, "initialize: covariance_m2");
  if (!problem.empty()) throw std::invalid_argument(problem);
  StateVector x = StateVector::Zero();
  x.segment<2>(kEast) = camera_en_m;
  StateMatrix P = StateMatrix::Zero();
  P.block<2, 2>(kEast, kEast) = 0.5 * (covariance_m2 + covariance_m2.transpose());
  P(kPixelSize, kPixelSize) = std::pow(config_.initial_pixel_size_correction_sigma, 2);
  P(kHeading, kHeading) = std::pow(config_.initial_heading_sigma_rad, 2);
  P(kHeadingDrift, kHeadingDrift) = std::pow(config_.initial_heading_drift_sigma_rps, 2);
  P(kDrScale, kDrScale) = std::pow(config_.initial_dr_scale_sigma, 2);
  startAt(stamp_s, x, P, false);
}

void NavigationFilter::resume(double stamp_s, const StateVector& x, const StateMatrix& P, bool dr_offset_known) {
  if (!std::isfinite(stamp_s)) throw std::invalid_argument("resume: stamp_s is not finite");
  if (!x.allFinite()) throw std::invalid_argument("resume: the state is not finite");
  if (!P.allFinite() || !P.isApprox(P.transpose(), 1e-9 * (1.0 + P.cwiseAbs().maxCoeff())))
    throw std::invalid_argument("resume: the covariance is not finite and symmetric");
  const Eigen::SelfAdjointEigenSolver<StateMatrix> eigen(0.5 * (P + P.transpose()));
  if (eigen.info() != Eigen::Success || eigen.eigenvalues().minCoeff() < 0.0)
    throw std::invalid_argument("resume: the covariance is not positive semi-definite");
  const std::string problem = covarianceProblem(P.block<2, 2>(kEast, kEast), "resume: the position covariance");
  if (!problem.empty()) throw std::invalid_argument(problem);
  startAt(stamp_s, x, 0.5 * (P + P.transpose()), dr_offset_known);
}

void NavigationFilter::startAt(double stamp_s, const StateVector& x, const StateMatrix& P, bool dr_offset_known) {
  reset();
  FilterStep first;
  first.stamp_s = stamp_s;
  first.x_prior = first.x_posterior = x;
  first.P_prior = first.P_posterior = P;
  first.transition = StateMatrix::Identity();
  first.dr_initialized = dr_offset_known;
  log_.steps.push_back(first);
  initialized_ = true;
  initial_stamp_s_ = stamp_s;
  initial_dr_known_ = dr_offset_known;
  rewind_floor_s_ = -std::numeric_limits<double>::infinity();
}

bool NavigationFilter::drOffsetKnown() const {
  return initialized_ && !log_.steps.empty() && log_.steps.back().dr_initialized;
}

void NavigationFilter::setLogFile(const std::string& path) {
  // The steps written so far come back into memory; the next prune writes them to the new file.
  if (log_file_) {
    FilterLog whole = wholeLog();
    log_.steps.swap(whole.steps);
    log_file_.reset();
  }
  if (!path.empty()) log_file_ = std::make_unique<FilterStepFile>(path);
}

FilterLog NavigationFilter::wholeLog() const {
  FilterLog whole;
  if (log_file_) log_file_->readAll(&whole.steps);
  whole.steps.insert(whole.steps.end(), log_.steps.begin(), log_.steps.end());
  return whole;
}

uint64_t NavigationFilter::loggedToFile() const { return log_file_ ? log_file_->size() : 0; }

std::string NavigationFilter::logFileError() const { return log_file_ ? log_file_->error() : std::string(); }

void NavigationFilter::setKeepLog(bool keep) {
  keep_log_ = keep;
  if (!keep && initialized_) prune();
}

double NavigationFilter::latestStamp() const { return log_.steps.empty() ? 0.0 : log_.steps.back().stamp_s; }

FilterState NavigationFilter::current() const {
  if (!initialized_ || log_.steps.empty()) return FilterState();
  const FilterStep& s = log_.steps.back();
  return FilterState::from(s.stamp_s, s.x_posterior, s.P_posterior);
}

FilterState NavigationFilter::stateAt(double stamp_s) const {
  if (!initialized_ || log_.steps.empty()) return FilterState();
  const auto after = std::upper_bound(log_.steps.begin(), log_.steps.end(), stamp_s,
                                      [](double t, const FilterStep& s) { return t < s.stamp_s; });
  if (after == log_.steps.begin()) return current();
  const FilterStep& s = *std::prev(after);
  return FilterState::from(s.stamp_s, s.x_posterior, s.P_posterior);
}

NavigationFilter::Working NavigationFilter::workingFrom(const FilterStep& step, bool prior) const {
  Working w;
  w.stamp_s = step.stamp_s;
  w.x = prior ? step.x_prior : step.x_posterior;
  w.P = prior ? step.P_prior : step.P_posterior;
  if (!prior) {  // the prior is only restarted from at the initial step, whose bookkeeping starts afresh
    w.consecutive_fix_rejections = step.consecutive_fix_rejections;
    w.consecutive_dr_rejections = step.consecutive_dr_rejections;
    w.dr_initialized = step.dr_initialized;
  } else {
    w.dr_initialized = initial_dr_known_;  // a resumed filter knows its dead-reckoning offset from the start
  }
  return w;
}

FilterState NavigationFilter::predictedAt(double stamp_s) const {
  if (!initialized_ || log_.steps.empty()) return FilterState();
  const FilterStep& last = log_.steps.back();
  if (!(stamp_s > last.stamp_s)) return current();
  Working w = workingFrom(last, false);
  const double dt = stamp_s - last.stamp_s;
  StateMatrix transition = StateMatrix::Identity();
  const Event* recent = nullptr;
  for (auto it = events_.rbegin(); it != events_.rend(); ++it) {
    if (it->kind != EventKind::kImage) continue;
    if (!it->image_failed && it->stamp_s >= last.stamp_s - 1.0) recent = &*it;
    break;
  }
  if (recent) {
    const double f = dt / (recent->stamp_s - recent->previous_stamp_s);
    const Eigen::Vector2d motion = f * recent->value;
    const Eigen::Matrix2d cov = f * recent->covariance;
    predictSegment(&w, dt, f, &motion, &cov, &transition);
  } else {
    predictSegment(&w, dt, 0.0, nullptr, nullptr, &transition);
  }
  return FilterState::from(stamp_s, w.x, w.P);
}

// ---- Adding events ---------------------------------------------------------------------------------------------

std::string NavigationFilter::checkStamp(double stamp_s) const {
  if (!std::isfinite(stamp_s)) return "stamp is not finite";
  if (stamp_s > latestStamp() + config_.max_prediction_gap_s)
    return "stamp " + stampText(stamp_s) + " s is " + format(stamp_s - latestStamp()) +
           " s after the latest stamp, more than max_prediction_gap_s = " + format(config_.max_prediction_gap_s) +
           " s: clock jump? call reset()";
  return "";
}

UpdateResult NavigationFilter::addImageMotion(double previous_stamp_s, double stamp_s, const MetricMotion& motion) {
  UpdateResult r;
  if (!initialized_) {
    r.status = UpdateStatus::kNotInitialized;
    r.detail = "image motion before initialize()";
    return r;
  }
  r.status = UpdateStatus::kInvalid;
  if (!motion.valid) {
    r.detail = "image motion is not valid (" + motion.error + "): use addImageFailure()";
    return r;
  }
  if (!motion.camera_displacement_en_m.allFinite()) {
    r.detail = "image motion camera_displacement_en_m is not finite";
    return r;
  }
  const std::string problem = covarianceProblem(motion.covariance_m2, "image motion covariance_m2");
  if (!problem.empty()) {
    r.detail = problem;
    return r;
  }
  Event e;
  e.kind = EventKind::kImage;
  e.previous_stamp_s = previous_stamp_s;
  e.stamp_s = stamp_s;
  e.value = motion.camera_displacement_en_m;
  e.covariance = 0.5 * (motion.covariance_m2 + motion.covariance_m2.transpose());
  return addImageEvent(e);
}

UpdateResult NavigationFilter::addImageFailure(double previous_stamp_s, double stamp_s) {
  UpdateResult r;
  if (!initialized_) {
    r.status = UpdateStatus::kNotInitialized;
    r.detail = "image failure before initialize()";
    return r;
  }
  Event e;
  e.kind = EventKind::kImage;
  e.previous_stamp_s = previous_stamp_s;
  e.stamp_s = stamp_s;
  e.image_failed = true;
  return addImageEvent(e);
}

UpdateResult NavigationFilter::addImageEvent(const Event& e) {
  UpdateResult r;
  r.status = UpdateStatus::kInvalid;
  std::string problem = checkStamp(e.stamp_s);
  if (problem.empty() && !std::isfinite(e.previous_stamp_s)) problem = "previous_stamp_s is not finite";
  if (!problem.empty()) {
    r.detail = "image: " + problem;
    return r;
  }
  if (!(e.previous_stamp_s < e.stamp_s)) {
    r.detail =
        "image: previous_stamp_s " + stampText(e.previous_stamp_s) + " must be before stamp_s " + stampText(e.stamp_s);
    return r;
  }
  if (have_image_ && e.previous_stamp_s < last_image_stamp_s_) {
    r.detail = "image: the pair [" + stampText(e.previous_stamp_s) + ", " + stampText(e.stamp_s) +
               "] goes back before the previous image event's stamp " + stampText(last_image_stamp_s_) +
               " (image events must come in stamp order; clock jump? call reset())";
    return r;
  }
  if (e.stamp_s < windowStart()) {
    r.detail = "image: stamp " + stampText(e.stamp_s) + " goes back beyond the history window (latest " +
               stampText(latestStamp()) + " - history_s): clock jump? call reset()";
    return r;
  }
  if (e.stamp_s <= initial_stamp_s_) {
    r.status = UpdateStatus::kTooOld;
    r.detail = "image: pair ends at " + stampText(e.stamp_s) + ", not after the initialisation at " +
               stampText(initial_stamp_s_);
    return r;
  }
  if (e.previous_stamp_s < rewind_floor_s_) {
    r.status = UpdateStatus::kTooOld;
    r.detail = "image: pair starts at " + stampText(e.previous_stamp_s) + ", before the history window";
    return r;
  }
  Event event = e;
  r = insertAndProcess(&event, e.previous_stamp_s, false);
  have_image_ = true;
  last_image_stamp_s_ = e.stamp_s;
  if (e.image_failed)
    ++counters_.image_failures;
  else
    ++counters_.image_motions;
  return r;
}

UpdateResult NavigationFilter::addDeadReckoning(double stamp_s, const Eigen::Vector2d& camera_en_m,
                                                const Eigen::Matrix2d& covariance_m2) {
  UpdateResult r;
  if (!initialized_) {
    r.status = UpdateStatus::kNotInitialized;
    r.detail = "dead reckoning before initialize()";
    return r;
  }
  r.status = UpdateStatus::kInvalid;
  std::string problem = checkStamp(stamp_s);
  if (problem.empty() && !camera_en_m.allFinite()) problem = "camera_en_m is not finite";
  if (problem.empty()) problem = covarianceProblem(covariance_m2, "covariance_m2");
  if (!problem.empty()) {
    r.detail = "dead reckoning: " + problem;
    return r;
  }
  if (have_dr_ && !(stamp_s > last_dr_stamp_s_)) {
    r.detail = "dead reckoning: stamp " + stampText(stamp_s) + " does not follow the previous DR stamp " +
               stampText(last_dr_stamp_s_) + " (DR must come in stamp order; clock jump? call reset())";
    return r;
  }
  if (stamp_s < windowStart()) {
    r.detail = "dead reckoning: stamp " + stampText(stamp_s) + " goes back beyond the history window (latest " +
               stampText(latestStamp()) + " - history_s): clock jump? call reset()";
    return r;
  }
  if (stamp_s < initial_stamp_s_ || stamp_s <= rewind_floor_s_) {
    r.status = UpdateStatus::kTooOld;
    r.detail = "dead reckoning: stamp " + stampText(stamp_s) + " is before the initialisation at " +
               stampText(initial_stamp_s_);
    return r;
  }
  Event e;
  e.kind = EventKind::kDeadReckoning;
  e.stamp_s = stamp_s;
  e.value = camera_en_m;
  e.covariance = covariance_m2;
  r = insertAndProcess(&e, stamp_s, true);
  have_dr_ = true;
  last_dr_stamp_s_ = stamp_s;
  return r;
}

UpdateResult NavigationFilter::addAbsoluteFix(double stamp_s, const Eigen::Vector2d& camera_en_m,
                                              const Eigen::Matrix2d& covariance_m2) {
  UpdateResult r;
  if (!initialized_) {
    r.status = UpdateStatus::kNotInitialized;
    r.detail = "fix before initialize()";
    return r;
  }
  r.status = UpdateStatus::kInvalid;
  std::string problem = checkStamp(stamp_s);
  if (problem.empty() && !camera_en_m.allFinite()) problem = "camera_en_m is not finite";
  if (problem.empty()) problem = covarianceProblem(covariance_m2, "covariance_m2");
  if (!problem.empty()) {
    r.detail = "fix: " + problem;
    return r;
  }
  if (stamp_s < windowStart() || stamp_s < initial_stamp_s_ || stamp_s <= rewind_floor_s_) {
    r.status = UpdateStatus::kTooOld;
    r.detail = "fix: stamp " + stampText(stamp_s) + " is " + format(latestStamp() - stamp_s, 4) +
               " s before the latest stamp " + stampText(latestStamp()) +
               ", older than history_s = " + format(config_.history_s) + " s" +
               (stamp_s < initial_stamp_s_ ? " or the initialisation" : "");
    return r;
  }
  Event e;
  e.kind = EventKind::kFix;
  e.stamp_s = stamp_s;
  e.value = camera_en_m;
  e.covariance = 0.5 * (covariance_m2 + covariance_m2.transpose());
  return insertAndProcess(&e, stamp_s, true);
}

// ---- Processing ------------------------------------------------------------------------------------------------

namespace {
/// Events at one stamp are processed in this order: image events (they only end a prediction), DR, then fixes.
bool eventBefore(double stamp_a, int kind_a, uint64_t seq_a, double stamp_b, int kind_b, uint64_t seq_b) {
  if (stamp_a != stamp_b) return stamp_a < stamp_b;
  if (kind_a != kind_b) return kind_a < kind_b;
  return seq_a < seq_b;
}
}  // namespace

UpdateResult NavigationFilter::insertAndProcess(Event* event, double affected_from_s, bool inclusive) {
  event->sequence = next_sequence_++;
  // The first step whose processing the new event changes.
  size_t first = 0;
  {
    const auto& steps = log_.steps;
    auto it = std::upper_bound(
        steps.begin(), steps.end(), affected_from_s,
        [inclusive](double s, const FilterStep& step) { return inclusive ? s <= step.stamp_s : s < step.stamp_s; });
    first = static_cast<size_t>(it - steps.begin());
  }
  // Rewinding to before the first kept step is only possible from the initial state.
  const bool from_prior = first == 0;
  const Working start = from_prior ? workingFrom(log_.steps.front(), true) : workingFrom(log_.steps[first - 1], false);
  if (first < log_.steps.size()) ++counters_.rewinds;

  auto pos = std::upper_bound(events_.begin(), events_.end(), *event, [](const Event& a, const Event& b) {
    return eventBefore(a.stamp_s, int(a.kind), a.sequence, b.stamp_s, int(b.kind), b.sequence);
  });
  events_.insert(pos, *event);

  log_.steps.erase(log_.steps.begin() + static_cast<long>(first), log_.steps.end());
  UpdateResult result;
  result.status = UpdateStatus::kApplied;
  processFrom(start, from_prior, event->sequence, &result);
  prune();
  return result;
}

void NavigationFilter::processFrom(const Working& start, bool from_prior, uint64_t watched_sequence,
                                   UpdateResult* watched) {
  Working w = start;
  auto it = std::lower_bound(events_.begin(), events_.end(), start.stamp_s,
                             [](const Event& e, double s) { return e.stamp_s < s; });
  if (!from_prior) {
    while (it != events_.end() && it->stamp_s <= start.stamp_s) ++it;
  }
  bool first_step = from_prior;
  while (it != events_.end() || first_step) {
    const double stamp =
        (it != events_.end() && !(first_step && it->stamp_s > start.stamp_s)) ? it->stamp_s : start.stamp_s;
    FilterStep step;
    step.stamp_s = stamp;
    step.transition = StateMatrix::Identity();
    if (stamp > w.stamp_s) predict(&w, stamp, &step.transition);
    step.x_prior = w.x;
    step.P_prior = w.P;
    for (; it != events_.end() && it->stamp_s == stamp; ++it) {
      if (it->kind == EventKind::kImage) {
        step.image_motion = true;
        if (it->sequence == watched_sequence) {
          watched->status = UpdateStatus::kApplied;
          watched->detail = it->image_failed ? "registration failure: no image motion over the pair" : "";
        }
        continue;
      }
      const UpdateResult r = applyUpdate(&w, *it, &step);
      if (it->sequence == watched_sequence) *watched = r;
    }
    step.x_posterior = w.x;
    step.P_posterior = w.P;
    step.consecutive_fix_rejections = w.consecutive_fix_rejections;
    step.consecutive_dr_rejections = w.consecutive_dr_rejections;
    step.dr_initialized = w.dr_initialized;
    log_.steps.push_back(step);
    ++counters_.steps_processed;
    first_step = false;
  }
}

void NavigationFilter::predict(Working* w, double to_s, StateMatrix* transition) const {
  double u = w->stamp_s;
  auto it = std::upper_bound(events_.begin(), events_.end(), u, [](double s, const Event& e) { return s < e.stamp_s; });
  for (; it != events_.end() && u < to_s; ++it) {
    if (it->kind != EventKind::kImage) continue;
    if (it->previous_stamp_s >= to_s) break;
    if (it->previous_stamp_s > u) {
      predictSegment(w, it->previous_stamp_s - u, 0.0, nullptr, nullptr, transition);
      u = it->previous_stamp_s;
    }
    const double v = std::min(it->stamp_s, to_s);
    if (v > u) {
      if (it->image_failed) {
        predictSegment(w, v - u, 0.0, nullptr, nullptr, transition);
      } else {
        const double f = (v - u) / (it->stamp_s - it->previous_stamp_s);
        const Eigen::Vector2d motion = f * it->value;
        const Eigen::Matrix2d cov = f * it->covariance;
        predictSegment(w, v - u, f, &motion, &cov, transition);
      }
      u = v;
    }
  }
  if (u < to_s) predictSegment(w, to_s - u, 0.0, nullptr, nullptr, transition);
  w->stamp_s = to_s;
}

void NavigationFilter::predictSegment(Working* w, double dt_s, double image_fraction, const Eigen::Vector2d* motion_m,
                                      const Eigen::Matrix2d* motion_cov, StateMatrix* transition) const {
  StateVector& x = w->x;
  const double scale = 1.0 + x[kPixelSize];
  const Eigen::Matrix2d A = rotation2d(-x[kHeading]);
  StateMatrix F = StateMatrix::Identity();
  StateMatrix Q = StateMatrix::Zero();
  F(kHeading, kHeadingDrift) = dt_s;
  double distance_m = config_.no_motion_speed_mps * dt_s;
  const bool couple_dr = w->dr_initialized && config_.dr_shares_heading;
  if (motion_m) {
    const Eigen::Vector2d corrected = A * *motion_m;
    const Eigen::Vector2d dp = scale * corrected;
    F.block<2, 1>(kEast, kPixelSize) = corrected;
    F.block<2, 1>(kEast, kHeading) = -scale * kJ * corrected;
    const Eigen::Matrix2d G_p = scale * A;
    Q.block<2, 2>(kEast, kEast) +=
        G_p * *motion_cov * G_p.transpose() + image_fraction * config_.imageStepNoiseCovariance(*motion_m);
    x.segment<2>(kEast) += dp;
    if (w->dr_initialized) {
      // The DR offset d' = d + G_d m, first order in the small errors c, psi and s:
      //   the DR's scale error adds s dp; a shared heading error adds (1 + c) (I - R(-psi)) m.
      const double s = x[kDrScale];
      const Eigen::Matrix2d I_minus_A =
          couple_dr ? (Eigen::Matrix2d::Identity() - A).eval() : Eigen::Matrix2d::Zero().eval();
      const Eigen::Matrix2d G_d = scale * I_minus_A + s * G_p;
      F.block<2, 1>(kDrEast, kDrScale) = dp;
      F.block<2, 1>(kDrEast, kPixelSize) = I_minus_A * *motion_m + s * corrected;
      F.block<2, 1>(kDrEast, kHeading) = ((couple_dr ? 1.0 : 0.0) - s) * scale * kJ * corrected;
      Q.block<2, 2>(kDrEast, kDrEast) += G_d * *motion_cov * G_d.transpose();
      Q.block<2, 2>(kEast, kDrEast) += G_p * *motion_cov * G_d.transpose();
      Q.block<2, 2>(kDrEast, kEast) += G_d * *motion_cov * G_p.transpose();
      x.segment<2>(kDrEast) += G_d * *motion_m;
    }
    distance_m = dp.norm();
  } else {
    Q.block<2, 2>(kEast, kEast) += config_.no_motion_position_noise_m2_per_s * dt_s * Eigen::Matrix2d::Identity();
  }
  Q.block<2, 2>(kEast, kEast) += config_.position_noise_m2_per_s * dt_s * Eigen::Matrix2d::Identity();
  Q(kPixelSize, kPixelSize) += std::pow(config_.pixel_size_correction_noise_per_sqrt_s, 2) * dt_s;
  Q(kDrScale, kDrScale) += std::pow(config_.dr_scale_noise_per_sqrt_s, 2) * dt_s;
  const double q_angle = std::pow(config_.heading_noise_rad_per_sqrt_s, 2);
  const double q_drift = std::pow(config_.heading_drift_noise_rps_per_sqrt_s, 2);
  Q(kHeading, kHeading) += q_angle * dt_s + q_drift * dt_s * dt_s * dt_s / 3.0;
  Q(kHeading, kHeadingDrift) += q_drift * dt_s * dt_s / 2.0;
  Q(kHeadingDrift, kHeading) += q_drift * dt_s * dt_s / 2.0;
  Q(kHeadingDrift, kHeadingDrift) += q_drift * dt_s;
  if (w->dr_initialized)
    Q.block<2, 2>(kDrEast, kDrEast) +=
        (config_.dr_offset_noise_m2_per_m * distance_m + config_.dr_offset_noise_m2_per_s * dt_s) *
        Eigen::Matrix2d::Identity();
  x[kHeading] += x[kHeadingDrift] * dt_s;
  w->P = F * w->P * F.transpose() + Q;
  w->P = 0.5 * (w->P + w->P.transpose());
  *transition = F * *transition;
}

UpdateResult NavigationFilter::applyUpdate(Working* w, const Event& e, FilterStep* step) {
  UpdateResult r;
  const bool fix = e.kind == EventKind::kFix;
  const char* name = fix ? "fix" : "dead reckoning";
  StateVector& x = w->x;
  StateMatrix& P = w->P;
  const double sigma2_dr = config_.dr_measurement_sigma_m * config_.dr_measurement_sigma_m;

  auto initialise_dr_offset = [&]() {
    // d = z - p exactly: a change of variables, no information on p.
    StateMatrix T = StateMatrix::Identity();
    T.block<2, 2>(kDrEast, kDrEast).setZero();
    T.block<2, 2>(kDrEast, kEast) = -Eigen::Matrix2d::Identity();
    x = T * x;
    x.segment<2>(kDrEast) += e.value;
    P = T * P * T.transpose();
    P.block<2, 2>(kDrEast, kDrEast) += sigma2_dr * Eigen::Matrix2d::Identity();
    w->dr_initialized = true;
    w->consecutive_dr_rejections = 0;
  };

  if (!fix && !w->dr_initialized) {
    initialise_dr_offset();
    ++step->dr_applied;
    r.status = UpdateStatus::kApplied;
    r.detail = "dead-reckoning offset initialised";
    return r;
  }

  Eigen::Matrix<double, 2, kStateSize> H = Eigen::Matrix<double, 2, kStateSize>::Zero();
  H.block<2, 2>(0, kEast) = Eigen::Matrix2d::Identity();
  Eigen::Matrix2d R = e.covariance;
  if (!fix) {
    H.block<2, 2>(0, kDrEast) = Eigen::Matrix2d::Identity();
    R = sigma2_dr * Eigen::Matrix2d::Identity();
  }
  const Eigen::Vector2d innovation = e.value - H * x;
  const Eigen::Matrix2d S = H * P * H.transpose() + R;
  const Eigen::LLT<Eigen::Matrix2d> llt(S);
  const double d2 = innovation.dot(llt.solve(innovation));
  r.mahalanobis_sq = d2;
  const double gate = config_.gateThreshold();
  int& consecutive = fix ? w->consecutive_fix_rejections : w->consecutive_dr_rejections;
  if (!(d2 <= gate)) {
    ++consecutive;
    if (consecutive < config_.recovery_rejections) {
      (fix ? step->fixes_rejected : step->dr_rejected)++;
      r.status = UpdateStatus::kRejectedByGate;
      r.detail = std::string(name) + " at " + stampText(e.stamp_s) + " rejected: Mahalanobis^2 " + format(d2, 4) +
                 " > gate " + format(gate, 4) + " (" + std::to_string(consecutive) + " consecutive of " +
                 std::to_string(config_.recovery_rejections) + " before recovery)";
      return r;
    }
    // Recovery: the filter (or the DR track) is lost.
    ++counters_.recoveries;
    consecutive = 0;
    r.status = UpdateStatus::kApplied;
    if (fix) {
      x.segment<2>(kEast) = e.value;
      P.block<2, kStateSize>(kEast, 0).setZero();
      P.block<kStateSize, 2>(0, kEast).setZero();
      P.block<2, 2>(kEast, kEast) = R;
      x.segment<2>(kDrEast).setZero();
      P.block<2, kStateSize>(kDrEast, 0).setZero();
      P.block<kStateSize, 2>(0, kDrEast).setZero();
      w->dr_initialized = false;
      step->discontinuity = true;
      ++step->fixes_applied;
      r.detail = "fix at " + stampText(e.stamp_s) + ": Mahalanobis^2 " + format(d2, 4) + " > gate " + format(gate, 4) +
                 " for the " + std::to_string(config_.recovery_rejections) +
                 "th consecutive time: recovery, position re-anchored at the fix";
    } else {
      initialise_dr_offset();
      ++step->dr_applied;
      r.detail = "dead reckoning at " + stampText(e.stamp_s) + ": Mahalanobis^2 " + format(d2, 4) + " > gate " +
                 format(gate, 4) + " for the " + std::to_string(config_.recovery_rejections) +
                 "th consecutive time: recovery, dead-reckoning offset re-initialised";
    }
    return r;
  }
  consecutive = 0;
  // Kalman update, Joseph form.
  const Eigen::Matrix<double, kStateSize, 2> PHt = P * H.transpose();
  const Eigen::Matrix<double, kStateSize, 2> K = llt.solve(PHt.transpose()).transpose();
  x += K * innovation;
  const StateMatrix I_KH = StateMatrix::Identity() - K * H;
  P = I_KH * P * I_KH.transpose() + K * R * K.transpose();
  P = 0.5 * (P + P.transpose());
  (fix ? step->fixes_applied : step->dr_applied)++;
  r.status = UpdateStatus::kApplied;
  r.detail = std::string(name) + " applied: Mahalanobis^2 " + format(d2, 4) + " <= gate " + format(gate, 4);
  return r;
}

void NavigationFilter::prune() {
  auto& steps = log_.steps;
  if (steps.size() < 2) return;
  const double window_start = windowStart();
  // The last step strictly before the window: the oldest state a rewind may restart from.
  auto it = std::lower_bound(steps.begin(), steps.end(), window_start,
                             [](const FilterStep& s, double t) { return s.stamp_s < t; });
  if (it == steps.begin()) return;
  --it;
  const double keep_from_s = it->stamp_s;
  if (!keep_log_) {
    steps.erase(steps.begin(), it);
  } else if (log_file_ && log_file_->append(steps.begin(), it)) {
    steps.erase(steps.begin(), it);  // written out; on a failed write they stay and go with the next ones
  }
  rewind_floor_s_ = keep_from_s;
  // Events at or before that step are folded into its posterior; image events ending later still give coverage.
  auto e = std::upper_bound(events_.begin(), events_.end(), keep_from_s,
                            [](double s, const Event& ev) { return s < ev.stamp_s; });
  events_.erase(events_.begin(), e);
}

}  // namespace fusion
}  // namespace exocet_mosaic
