/**
 * @file dive_bag_writer.h
 * @brief Writes the records of a dive into a rosbag with the layout of dive_topics.h, atomically.
 *
 * The bag is written under a temporary name beside the final one and renamed by commit(); if the writer is
 * destroyed without commit() (error, exception, signal handled by the caller) the temporary file is removed, so
 * a partial bag never sits under the final name. The bytes depend only on what is written: the same records give
 * the same file.
 */
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <sensor_msgs/CameraInfo.h>

#include "exocet_common/camera_model.h"
#include "exocet_mosaic/dive/dive_records.h"

namespace rosbag {
class Bag;
}

namespace exocet_mosaic {

/// How camera images are stored.
enum class ImageStorage { kRaw, kJpeg, kPng };

/// Parses "raw", "jpeg" or "png"; throws std::invalid_argument naming the allowed values.
ImageStorage parseImageStorage(const std::string& name);

/// sensor_msgs/CameraInfo of a camera model (plumb_bob), frame camera_optical.
sensor_msgs::CameraInfo toCameraInfo(const exocet_common::CameraModel& camera, double stamp_s,
                                     const std::string& frame_id);

class DiveBagWriter {
 public:
  struct Options {
    ImageStorage image_storage = ImageStorage::kRaw;
    int jpeg_quality = 90;            ///< 1..100
    bool compress_chunks = false;     ///< LZ4 chunk compression (deterministic)
    std::string world_frame = "utm";  ///< frame of positions: "utm" (geo-referenced) or "map" (local)
  };

  /// Opens `final_path`'s temporary sibling for writing. Throws std::runtime_error naming the path on failure.
  DiveBagWriter(const std::string& final_path, const Options& options);
  ~DiveBagWriter();
  DiveBagWriter(const DiveBagWriter&) = delete;
  DiveBagWriter& operator=(const DiveBagWriter&) = delete;

  void writeDatum(const exocet_common::GeoReference& datum, double stamp_s);                         ///< latched
  void writeStaticTransforms(const std::vector<dive::StaticTransform>& transforms, double stamp_s);  ///< latched
  /// Image and its camera_info, both stamped at frame.stamp_s. A compressed storage uses frame.compressed if
  /// compressFrame() filled it, otherwise compresses the image here.
  void writeCameraFrame(const dive::CameraFrame& frame, const exocet_common::CameraModel& camera);
  /**
   * @brief Compresses frame->image as writeCameraFrame() stores it (JPEG or PNG, per the options) into
   * frame->compressed and frame->compressed_format; does nothing for raw storage. Touches only the frame: call it
   * on the threads that render, so that compression does not queue on the thread that writes.
   * Throws std::runtime_error if the image cannot be encoded.
   */
  void compressFrame(dive::CameraFrame* frame) const;
  void writeNavOdometry(const dive::PoseRecord& pose);
  void writeDvl(const dive::DvlRecord& dvl);
  void writeImu(const dive::ImuRecord& imu);
  void writeDepth(const dive::DepthRecord& depth);
  void writeAltitude(const dive::AltitudeRecord& altitude);
  void writeUsbl(const dive::FixRecord& fix);  ///< recorded at fix.arrival_s
  void writeGroundTruth(const dive::PoseRecord& base_link_pose);
  void writeGroundTruthCamera(double stamp_s, const Eigen::Isometry3d& world_from_camera, double altitude_m);

  /// Closes the bag and renames it to its final name. Throws std::runtime_error on failure.
  void commit();
  const std::string& finalPath() const { return final_path_; }
  size_t messageCount() const { return message_count_; }

 private:
  template <typename M>
  void write(const std::string& topic, double record_time_s, const M& msg, bool latched = false);

  std::string final_path_;
  std::string temporary_path_;
  Options options_;
  std::unique_ptr<rosbag::Bag> bag_;
  bool committed_ = false;
  size_t message_count_ = 0;
};

}  // namespace exocet_mosaic
