// The tile writer as a nodelet (exocet_mosaic/TileWriterNodelet), to share the camera images without copies.
#include <memory>

#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "exocet_mosaic/ros/tile_writer_ros.h"

namespace exocet_mosaic {

class TileWriterNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      writer_ = std::make_unique<TileWriterRos>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::exception& e) {
      NODELET_FATAL("%s", e.what());
      throw;
    }
  }
  std::unique_ptr<TileWriterRos> writer_;
};

}  // namespace exocet_mosaic

PLUGINLIB_EXPORT_CLASS(exocet_mosaic::TileWriterNodelet, nodelet::Nodelet)
