/**
 * @file registration_parameters.h
 * @brief Reads a RegistrationConfig from private parameters: ~method, ~model, ~klt/<field>, ~rmr/<field> (the field
 * names of KltConfig and RmrConfig).
 */
#pragma once

#include <ros/ros.h>

#include "exocet_mosaic/registration/registration_config.h"

namespace exocet_mosaic {

/// @throws std::invalid_argument naming the parameter, its value and the allowed range or values.
registration::RegistrationConfig readRegistrationConfig(const ros::NodeHandle& private_nh);

}  // namespace exocet_mosaic
