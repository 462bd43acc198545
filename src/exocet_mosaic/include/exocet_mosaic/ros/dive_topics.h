/**
 * @file dive_topics.h
 * @brief Topic and frame names of a dive bag (simulated or imported) and of the live system.
 */
#pragma once

namespace exocet_mosaic {
namespace topics {

constexpr char kImageRaw[] = "/camera/image_raw";                    // sensor_msgs/Image
constexpr char kImageCompressed[] = "/camera/image_raw/compressed";  // sensor_msgs/CompressedImage
constexpr char kCameraInfo[] = "/camera/camera_info";                // sensor_msgs/CameraInfo
constexpr char kNavOdometry[] = "/nav/odometry";  // nav_msgs/Odometry: dead reckoning, utm -> base_link
constexpr char kNavDvl[] = "/nav/dvl";            // geometry_msgs/TwistWithCovarianceStamped, base_link
constexpr char kNavImu[] = "/nav/imu";            // sensor_msgs/Imu, base_link, orientation in utm (ENU)
constexpr char kNavDepth[] = "/nav/depth";        // exocet_msgs/Depth
constexpr char kNavAltitude[] = "/nav/altitude";  // sensor_msgs/Range, altimeter frame
constexpr char kNavUsbl[] = "/nav/usbl";          // sensor_msgs/NavSatFix, stamped at measurement, recorded at arrival
constexpr char kNavDatum[] = "/nav/datum";        // exocet_msgs/GeoDatum, latched
constexpr char kGroundTruthOdometry[] = "/ground_truth/odometry";       // nav_msgs/Odometry, utm -> base_link
constexpr char kGroundTruthCameraPose[] = "/ground_truth/camera_pose";  // geometry_msgs/PoseStamped, utm
constexpr char kGroundTruthAltitude[] = "/ground_truth/altitude";       // sensor_msgs/Range, camera optical axis
constexpr char kMosaicMotion[] = "/mosaic/motion";                      // exocet_msgs/ImageMotion
constexpr char kTfStatic[] = "/tf_static";                              // tf2_msgs/TFMessage, latched

}  // namespace topics

namespace frames {
constexpr char kUtm[] = "utm";
constexpr char kMap[] = "map";
constexpr char kBaseLink[] = "base_link";
constexpr char kCameraOptical[] = "camera_optical";
constexpr char kAltimeter[] = "altimeter";
constexpr char kUsbl[] = "usbl_transponder";
}  // namespace frames
}  // namespace exocet_mosaic
