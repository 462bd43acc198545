/**
 * @file saved_fusion_state.h
 * @brief The fusion's last published state kept on disk, so that a fusion restarted mid-dive (a crash, a respawn)
 * resumes from it instead of starting blind; and the rule that decides whether a saved state belongs to the dive
 * that is coming in. No ROS in it.
 */
#pragma once

#include <optional>
#include <string>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "exocet_mosaic/fusion/filter_log.h"

namespace exocet_mosaic {
namespace fusion {

/// What a restarted fusion needs to carry the dive on: the filter's whole state and what framed it.
struct SavedFusionState {
  double stamp_s = 0.0;  ///< stamp of the state (s, the inputs' clock)
  StateVector x = StateVector::Zero();
  StateMatrix P = StateMatrix::Zero();
  bool dr_offset_known = false;  ///< the dead-reckoning offset in x was set by a dead reckoning
  std::string frame;             ///< frame of the positions (the UTM frame, or the dive's local frame)
  int utm_zone = 0;              ///< 0: none known (a local frame)
  bool northern_hemisphere = true;
  std::optional<Eigen::Vector2d> map_origin_en_m;  ///< the map frame's origin in use
  /// The operator's heading as the images carried it on (ENU yaw, rad), for a dive without an attitude sensor.
  std::optional<double> operator_heading_rad;
};

nlohmann::json savedFusionStateToJson(const SavedFusionState& state);
/// @throws std::invalid_argument naming the missing or bad field.
SavedFusionState savedFusionStateFromJson(const nlohmann::json& json);

/**
 * @brief Why a state saved at `saved_stamp_s` must not start the filter at the first input, stamped
 * `first_input_stamp_s` (a sensor's, not a late fix's); empty when it may. It may when the first input comes after
 * it (a restart carries the same clock on) by at most `max_age_s`; an input stamped at or before it is a bag played
 * again from its start or another dive, one much later is another dive or too long a gap for the state to mean
 * anything.
 */
std::string resumeRefusal(double saved_stamp_s, double first_input_stamp_s, double max_age_s);

}  // namespace fusion
}  // namespace exocet_mosaic
