// The registration as a nodelet (exocet_mosaic/RegistrationNodelet), to share images with the camera driver in one
// process without copies.
#include <memory>

#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "exocet_mosaic/ros/registration_ros.h"

namespace exocet_mosaic {

class RegistrationNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      registration_ = std::make_unique<RegistrationRos>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::invalid_argument& e) {
      NODELET_FATAL("%s", e.what());
      throw;
    }
  }
  std::unique_ptr<RegistrationRos> registration_;
};

}  // namespace exocet_mosaic

PLUGINLIB_EXPORT_CLASS(exocet_mosaic::RegistrationNodelet, nodelet::Nodelet)
