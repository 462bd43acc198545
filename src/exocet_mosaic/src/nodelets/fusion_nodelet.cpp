// The navigation fusion as a nodelet (exocet_mosaic/FusionNodelet), to run in one process with the registration.
#include <memory>

#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "exocet_mosaic/ros/fusion_ros.h"

namespace exocet_mosaic {

class FusionNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      fusion_ = std::make_unique<FusionRos>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::invalid_argument& e) {
      NODELET_FATAL("%s", e.what());
      throw;
    }
  }
  std::unique_ptr<FusionRos> fusion_;
};

}  // namespace exocet_mosaic

PLUGINLIB_EXPORT_CLASS(exocet_mosaic::FusionNodelet, nodelet::Nodelet)
