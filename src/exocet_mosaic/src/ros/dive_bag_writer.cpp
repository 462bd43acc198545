#include "exocet_mosaic/ros/dive_bag_writer.h"

#include <cstdio>
#include <stdexcept>

#include <cv_bridge/cv_bridge.h>
#include <exocet_msgs/Depth.h>
#include <exocet_msgs/GeoDatum.h>
#include <geometry_msgs/PoseStamped.h>
#include <geometry_msgs/TwistWithCovarianceStamped.h>
#include <nav_msgs/Odometry.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/NavSatFix.h>
#include <sensor_msgs/Range.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_msgs/TFMessage.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_mosaic/ros/dive_topics.h"

namespace exocet_mosaic {

namespace {
ros::Time toRosTime(double t_s) {
  ros::Time t;
  t.fromSec(t_s);
  return t;
}
std_msgs::Header header(double stamp_s, const std::string& frame_id) {
  std_msgs::Header h;
  h.stamp = toRosTime(stamp_s);
  h.frame_id = frame_id;
  return h;
}
geometry_msgs::Quaternion toMsg(const Eigen::Quaterniond& q_in) {
  const Eigen::Quaterniond q = q_in.normalized();
  geometry_msgs::Quaternion m;
  m.x = q.x();
  m.y = q.y();
  m.z = q.z();
  m.w = q.w();
  return m;
}
geometry_msgs::Point toPoint(const Eigen::Vector3d& p) {
  geometry_msgs::Point m;
  m.x = p.x();
  m.y = p.y();
  m.z = p.z();
  return m;
}
geometry_msgs::Vector3 toVector(const Eigen::Vector3d& v) {
  geometry_msgs::Vector3 m;
  m.x = v.x();
  m.y = v.y();
  m.z = v.z();
  return m;
}
template <size_t N>
void copyCovariance(const Eigen::Matrix<double, 6, 6>& c, boost::array<double, N>* out) {
  for (int r = 0; r < 6; ++r)
    for (int k = 0; k < 6; ++k) (*out)[r * 6 + k] = c(r, k);
}
nav_msgs::Odometry toOdometry(const dive::PoseRecord& pose, const std::string& frame) {
  nav_msgs::Odometry odom;
  odom.header = header(pose.stamp_s, frame);
  odom.child_frame_id = frames::kBaseLink;
  odom.pose.pose.position = toPoint(pose.position_m);
  odom.pose.pose.orientation = toMsg(pose.orientation);
  copyCovariance(pose.pose_covariance, &odom.pose.covariance);
  odom.twist.twist.linear = toVector(pose.linear_velocity_mps);
  odom.twist.twist.angular = toVector(pose.angular_velocity_rps);
  copyCovariance(pose.twist_covariance, &odom.twist.covariance);
  return odom;
}
}  // namespace

ImageStorage parseImageStorage(const std::string& name) {
  if (name == "raw") return ImageStorage::kRaw;
  if (name == "jpeg") return ImageStorage::kJpeg;
  if (name == "png") return ImageStorage::kPng;
  throw std::invalid_argument("image storage '" + name + "' is not one of raw, jpeg, png");
}

sensor_msgs::CameraInfo toCameraInfo(const exocet_common::CameraModel& c, double stamp_s, const std::string& frame_id) {
  sensor_msgs::CameraInfo info;
  info.header = header(stamp_s, frame_id);
  info.width = c.width;
  info.height = c.height;
  info.distortion_model = "plumb_bob";
  info.D.assign(c.distortion.begin(), c.distortion.end());
  info.K = {c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1};
  info.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  info.P = {c.fx, 0, c.cx, 0, 0, c.fy, c.cy, 0, 0, 0, 1, 0};
  return info;
}

DiveBagWriter::DiveBagWriter(const std::string& final_path, const Options& options)
    : final_path_(final_path), temporary_path_(exocet_common::temporaryPathFor(final_path)), options_(options) {
  const std::string problem = exocet_common::checkWritableDestination(final_path);
  if (!problem.empty()) throw std::runtime_error("cannot write bag '" + final_path + "': " + problem);
  if (options_.jpeg_quality < 1 || options_.jpeg_quality > 100)
    throw std::invalid_argument("jpeg_quality " + std::to_string(options_.jpeg_quality) + " out of range [1, 100]");
  bag_ = std::make_unique<rosbag::Bag>();
  try {
    bag_->open(temporary_path_, rosbag::bagmode::Write);
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot write bag '" + final_path + "': " + e.what());
  }
  bag_->setCompression(options_.compress_chunks ? rosbag::compression::LZ4 : rosbag::compression::Uncompressed);
}

DiveBagWriter::~DiveBagWriter() {
  if (!committed_) {
    try {
      bag_->close();
    } catch (...) {
    }
    std::remove(temporary_path_.c_str());
  }
}

template <typename M>
void DiveBagWriter::write(const std::string& topic, double record_time_s, const M& msg, bool latched) {
  boost::shared_ptr<ros::M_string> connection_header;
  if (latched) {
    connection_header = boost::make_shared<ros::M_string>();
    (*connection_header)["latching"] = "1";
    (*connection_header)["callerid"] = "/dive_bag_writer";
    // Given a header, rosbag writes it as is: it must carry the type, checksum and definition itself.
    (*connection_header)["type"] = ros::message_traits::datatype<M>();
    (*connection_header)["md5sum"] = ros::message_traits::md5sum<M>();
    (*connection_header)["message_definition"] = ros::message_traits::definition<M>();
  }
  bag_->write(topic, toRosTime(record_time_s), msg, connection_header);
  ++message_count_;
}

void DiveBagWriter::writeDatum(const exocet_common::GeoReference& d, double stamp_s) {
  exocet_msgs::GeoDatum m;
  m.header = header(stamp_s, options_.world_frame);
  m.frame_id = options_.world_frame;
  m.utm_zone = d.utm_zone;
  m.northern_hemisphere = d.northern_hemisphere;
  m.epsg = d.epsg;
  m.origin_latitude_deg = d.origin_latitude_deg;
  m.origin_longitude_deg = d.origin_longitude_deg;
  m.origin_easting_m = d.origin_easting_m;
  m.origin_northing_m = d.origin_northing_m;
  write(topics::kNavDatum, stamp_s, m, true);
}

void DiveBagWriter::writeStaticTransforms(const std::vector<dive::StaticTransform>& transforms, double stamp_s) {
  tf2_msgs::TFMessage m;
  for (const auto& t : transforms) {
    geometry_msgs::TransformStamped ts;
    ts.header = header(stamp_s, t.parent_frame);
    ts.child_frame_id = t.child_frame;
    ts.transform.translation = toVector(t.parent_from_child.translation());
    ts.transform.rotation = toMsg(Eigen::Quaterniond(t.parent_from_child.rotation()));
    m.transforms.push_back(ts);
  }
  write(topics::kTfStatic, stamp_s, m, true);
}

void DiveBagWriter::writeCameraFrame(const dive::CameraFrame& frame, const exocet_common::CameraModel& camera) {
  if (frame.image.cols != camera.width || frame.image.rows != camera.height)
    throw std::invalid_argument("frame " + std::to_string(frame.index) + " is " + std::to_string(frame.image.cols) +
                                "x" + std::to_string(frame.image.rows) + " but camera_info says " +
                                std::to_string(camera.width) + "x" + std::to_string(camera.height));
  const std_msgs::Header h = header(frame.stamp_s, frames::kCameraOptical);
  if (options_.image_storage == ImageStorage::kRaw) {
    cv_bridge::CvImage img(h, frame.encoding, frame.image);
    write(topics::kImageRaw, frame.stamp_s, *img.toImageMsg());
  } else {
    sensor_msgs::CompressedImage msg;
    msg.header = h;
    if (frame.compressed.empty()) {
      dive::CameraFrame compressed;
      compressed.index = frame.index;
      compressed.image = frame.image;
      compressed.encoding = frame.encoding;
      compressFrame(&compressed);
      msg.data = std::move(compressed.compressed);
      msg.format = std::move(compressed.compressed_format);
    } else {
      msg.data = frame.compressed;
      msg.format = frame.compressed_format;
    }
    write(topics::kImageCompressed, frame.stamp_s, msg);
  }
  write(topics::kCameraInfo, frame.stamp_s, toCameraInfo(camera, frame.stamp_s, frames::kCameraOptical));
}

void DiveBagWriter::compressFrame(dive::CameraFrame* frame) const {
  if (options_.image_storage == ImageStorage::kRaw) return;
  std::vector<int> params;
  std::string ext;
  if (options_.image_storage == ImageStorage::kJpeg) {
    ext = ".jpg";
    params = {cv::IMWRITE_JPEG_QUALITY, options_.jpeg_quality};
    frame->compressed_format = frame->encoding + "; jpeg compressed " + (frame->image.channels() == 3 ? "bgr8" : "");
  } else {
    ext = ".png";
    params = {cv::IMWRITE_PNG_COMPRESSION, 3};
    frame->compressed_format = frame->encoding + "; png compressed " + (frame->image.channels() == 3 ? "bgr8" : "");
  }
  if (!cv::imencode(ext, frame->image, frame->compressed, params))
    throw std::runtime_error("cannot encode frame " + std::to_string(frame->index) + " as " + ext);
}

void DiveBagWriter::writeNavOdometry(const dive::PoseRecord& pose) {
  write(topics::kNavOdometry, pose.stamp_s, toOdometry(pose, options_.world_frame));
}

void DiveBagWriter::writeDvl(const dive::DvlRecord& dvl) {
  geometry_msgs::TwistWithCovarianceStamped m;
  m.header = header(dvl.stamp_s, frames::kBaseLink);
  m.twist.twist.linear = toVector(dvl.velocity_mps);
  const double var = dvl.sigma_mps * dvl.sigma_mps;
  m.twist.covariance[0] = m.twist.covariance[7] = m.twist.covariance[14] = var;
  m.twist.covariance[21] = m.twist.covariance[28] = m.twist.covariance[35] = -1.0;  // angular part not measured
  write(topics::kNavDvl, dvl.stamp_s, m);
}

void DiveBagWriter::writeImu(const dive::ImuRecord& imu) {
  sensor_msgs::Imu m;
  m.header = header(imu.stamp_s, frames::kBaseLink);
  m.orientation = toMsg(imu.orientation);
  m.angular_velocity = toVector(imu.angular_velocity_rps);
  m.linear_acceleration = toVector(imu.linear_acceleration_mps2);
  for (int i = 0; i < 3; ++i) {
    m.orientation_covariance[i * 4] = imu.orientation_sigma_rad * imu.orientation_sigma_rad;
    m.angular_velocity_covariance[i * 4] = imu.angular_velocity_sigma_rps * imu.angular_velocity_sigma_rps;
    m.linear_acceleration_covariance[i * 4] = imu.linear_acceleration_sigma_mps2 * imu.linear_acceleration_sigma_mps2;
  }
  write(topics::kNavImu, imu.stamp_s, m);
}

void DiveBagWriter::writeDepth(const dive::DepthRecord& depth) {
  exocet_msgs::Depth m;
  m.header = header(depth.stamp_s, frames::kBaseLink);
  m.depth_m = depth.depth_m;
  m.variance_m2 = depth.sigma_m * depth.sigma_m;
  write(topics::kNavDepth, depth.stamp_s, m);
}

void DiveBagWriter::writeAltitude(const dive::AltitudeRecord& a) {
  sensor_msgs::Range m;
  m.header = header(a.stamp_s, frames::kAltimeter);
  m.radiation_type = sensor_msgs::Range::ULTRASOUND;
  m.field_of_view = static_cast<float>(a.field_of_view_rad);
  m.min_range = static_cast<float>(a.min_range_m);
  m.max_range = static_cast<float>(a.max_range_m);
  m.range = static_cast<float>(a.range_m);
  write(topics::kNavAltitude, a.stamp_s, m);
}

void DiveBagWriter::writeUsbl(const dive::FixRecord& fix) {
  sensor_msgs::NavSatFix m;
  m.header = header(fix.stamp_s, frames::kUsbl);
  m.status.status = sensor_msgs::NavSatStatus::STATUS_FIX;
  m.status.service = 0;  // acoustic positioning: none of the GNSS services
  m.latitude = fix.latitude_deg;
  m.longitude = fix.longitude_deg;
  m.altitude = fix.altitude_m;
  const double h2 = fix.horizontal_sigma_m * fix.horizontal_sigma_m;
  m.position_covariance = {h2, 0, 0, 0, h2, 0, 0, 0, fix.vertical_sigma_m * fix.vertical_sigma_m};
  m.position_covariance_type = sensor_msgs::NavSatFix::COVARIANCE_TYPE_DIAGONAL_KNOWN;
  write(topics::kNavUsbl, fix.arrival_s, m);
}

void DiveBagWriter::writeGroundTruth(const dive::PoseRecord& pose) {
  write(topics::kGroundTruthOdometry, pose.stamp_s, toOdometry(pose, options_.world_frame));
}

void DiveBagWriter::writeGroundTruthCamera(double stamp_s, const Eigen::Isometry3d& world_from_camera,
                                           double altitude_m) {
  geometry_msgs::PoseStamped p;
  p.header = header(stamp_s, options_.world_frame);
  p.pose.position = toPoint(world_from_camera.translation());
  p.pose.orientation = toMsg(Eigen::Quaterniond(world_from_camera.rotation()));
  write(topics::kGroundTruthCameraPose, stamp_s, p);
  sensor_msgs::Range r;
  r.header = header(stamp_s, frames::kCameraOptical);
  r.radiation_type = sensor_msgs::Range::INFRARED;  // not a sensor: the exact distance along the optical axis
  r.field_of_view = 0.0f;
  r.min_range = 0.0f;
  r.max_range = 1000.0f;
  r.range = static_cast<float>(altitude_m);
  write(topics::kGroundTruthAltitude, stamp_s, r);
}

void DiveBagWriter::commit() {
  try {
    bag_->close();
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot finish bag '" + final_path_ + "': " + e.what());
  }
  exocet_common::commitTemporaryFile(temporary_path_, final_path_);
  committed_ = true;
}

}  // namespace exocet_mosaic
