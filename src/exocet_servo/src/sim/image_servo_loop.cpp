#include "exocet_servo/sim/image_servo_loop.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "exocet_servo/trajectory/se3.h"

namespace exocet_servo {
namespace sim {


std::string toString(ImageServoStatus status) {
  switch (status) {
    case ImageServoStatus::kConverged:
      return "converged";
    case ImageServoStatus::kLostTracking:
      return "lost tracking";
    case ImageServoStatus::kServoStopped:
      return "servo stopped";
    case ImageServoStatus::kMaxIterations:
      return "max iterations";
    case ImageServoStatus::kReferenceFailed:
      return "reference failed";
  }
  return "unknown";
}

ImageServoResult runImageServo(const VentRenderer& renderer, const ImageServoSetup& setup,
                               const ImageServoConfig& config, const CurrentImageRenderer& render_current) {
  control::ImageServoController controller(config, setup.k_estimate_reference, setup.k_estimate_controlled,
                                           setup.controlled_camera.width_px, setup.controlled_camera.height_px);
  ImageServoResult result;
  result.final_pose = setup.world_T_start;
  result.initial_error = poseError(setup.world_T_start, setup.world_T_reference);
  result.final_error = result.initial_error;

  // Depths from the renderer (the stereo rig's role in the real system), screened for discontinuities.
  const auto depth_lookup = [&](const RenderedView& view, const PinholeCamera& camera, const Eigen::Isometry3d& pose) {
    return [&view, &camera, pose, &renderer, &config](const Eigen::Vector2d& px) {
      double d = 0.0;
      if (!view.smoothDepthAt(px, config.depth_check_radius_px, config.depth_max_relative_step, &d))
        return std::numeric_limits<double>::quiet_NaN();
      return renderer.depthAt(camera, pose, px);
    };
  };
  const RenderedView reference = renderer.render(setup.reference_camera, setup.world_T_reference);
  const std::string err =
      controller.setReference(reference.image, depth_lookup(reference, setup.reference_camera, setup.world_T_reference));
  if (!err.empty()) {
    result.message = err;
    return result;
  }

  Eigen::Isometry3d pose = setup.world_T_start;
  bool finished = false;
  double control_sum = 0.0, control_cpu_sum = 0.0;
  for (int it = 0; it < config.servo.max_iterations && !finished; ++it) {
    const RenderedView view =
        render_current ? render_current(pose, it) : renderer.render(setup.controlled_camera, pose);
    const control::ImageStep step = controller.step(view.image, depth_lookup(view, setup.controlled_camera, pose));
    result.rematches = controller.rematches();
    result.initial_matches = controller.initialMatches();
    if (step.status == control::ImageStepStatus::kLostTracking) {
      result.status = ImageServoStatus::kLostTracking;
      result.message = step.message;
      break;
    }
    ImageServoIteration rec;
    rec.error = poseError(pose, setup.world_T_reference);
    rec.error_norm = step.error_norm;
    rec.servo_status = step.servo_status;
    rec.points = step.points;
    rec.rematched = step.rematched;
    rec.anchored = step.anchored;
    rec.control_time_s = step.control_time_s;
    rec.control_cpu_time_s = step.control_cpu_time_s;
    rec.match_time_s = step.match_time_s;
    result.history.push_back(rec);
    control_sum += step.control_time_s;
    control_cpu_sum += step.control_cpu_time_s;
    result.max_control_time_s = std::max(result.max_control_time_s, step.control_time_s);
    result.iterations = it + 1;
    result.servo_status = step.servo_status;
    switch (step.status) {
      case control::ImageStepStatus::kRunning:
        pose = pose * trajectory::expSe3(step.velocity * config.dt_s);
        break;
      case control::ImageStepStatus::kConverged:
        result.status = ImageServoStatus::kConverged;
        result.message = step.message;
        finished = true;
        break;
      default:
        result.status = ImageServoStatus::kServoStopped;
        result.message = step.message;
        finished = true;
        break;
    }
  }
  if (!finished && result.message.empty()) {
    result.status = ImageServoStatus::kMaxIterations;
    result.message = "not converged after " + std::to_string(result.iterations) + " iterations (servo.max_iterations)";
  }
  result.final_pose = pose;
  result.final_error = poseError(pose, setup.world_T_reference);
  if (!result.history.empty()) {
    result.mean_control_time_s = control_sum / result.history.size();
    result.mean_control_cpu_time_s = control_cpu_sum / result.history.size();
  }
  return result;
}

}  // namespace sim
}  // namespace exocet_servo
