#include "exocet_servo/ros/acquisition_sequencer_ros.h"

#include <stdexcept>

#include <geometry_msgs/PoseStamped.h>
#include <std_srvs/Trigger.h>

#include "exocet_common/ros/parameter_reader.h"

namespace exocet_servo {

AcquisitionSequencerConfig readAcquisitionSequencerConfig(const ros::NodeHandle& private_nh) {
  AcquisitionSequencerConfig c;
  const exocet_common::ParameterReader p(private_nh);
  p.readInt("stops", &c.stops, 1, 10000, "stereo pairs to record (the first at the start pose)");
  p.readString("bag_path", &c.bag_path, {}, "output bag of the acquisition");
  p.readString("servo", &c.servo, {}, "name of the servo node");
  p.readString("world_frame", &c.world_frame, {}, "frame of the arm's base");
  p.readString("left_frame", &c.left_frame, {}, "optical frame of the left camera");
  p.readString("right_frame", &c.right_frame, {}, "optical frame of the right camera");
  p.readDouble("settle_s", &c.settle_s, 0.0, 60.0, "wait after convergence before recording (s)");
  return c;
}

AcquisitionSequencerRos::AcquisitionSequencerRos(ros::NodeHandle nh, ros::NodeHandle private_nh)
    : nh_(nh),
      pnh_(private_nh),
      config_(readAcquisitionSequencerConfig(private_nh)),
      tf_listener_(tf_buffer_),
      diagnostics_(nh, private_nh) {
  if (config_.bag_path.empty()) throw std::invalid_argument("parameter ~bag_path is required (the output bag)");
  try {
    bag_.open(config_.bag_path, rosbag::bagmode::Write);
  } catch (const rosbag::BagException& e) {
    throw std::runtime_error("cannot open the output bag " + config_.bag_path + ": " + e.what());
  }
  left_image_sub_ = nh_.subscribe<sensor_msgs::Image>("left/image_raw", 2,
                                                      [this](const sensor_msgs::ImageConstPtr& m) { left_image_ = m; });
  right_image_sub_ = nh_.subscribe<sensor_msgs::Image>(
      "right/image_raw", 2, [this](const sensor_msgs::ImageConstPtr& m) { right_image_ = m; });
  left_info_sub_ = nh_.subscribe<sensor_msgs::CameraInfo>(
      "left/camera_info", 2, [this](const sensor_msgs::CameraInfoConstPtr& m) { left_info_ = m; });
  right_info_sub_ = nh_.subscribe<sensor_msgs::CameraInfo>(
      "right/camera_info", 2, [this](const sensor_msgs::CameraInfoConstPtr& m) { right_info_ = m; });
  joints_sub_ = nh_.subscribe<sensor_msgs::JointState>(
      "joint_states", 2, [this](const sensor_msgs::JointStateConstPtr& m) { joints_ = m; });
  servo_status_sub_ = nh_.subscribe<std_msgs::String>(
      config_.servo + "/status", 5, [this](const std_msgs::StringConstPtr& m) { servo_status_ = m->data; });
  capture_client_ = nh_.serviceClient<std_srvs::Trigger>(config_.servo + "/capture_reference");
  status_pub_ = pnh_.advertise<std_msgs::String>("status", 1, true);
  diagnostics_.setHardwareID("exocet acquisition sequencer");
  diagnostics_.add("sequence", this, &AcquisitionSequencerRos::diagnose);
  state_ = State::kRecord;  // the first pair at the start pose
  settle_until_ = ros::Time::now();
  setStatus("recording stop 1 of " + std::to_string(config_.stops));
  timer_ = nh_.createTimer(ros::Duration(0.1), &AcquisitionSequencerRos::onTick, this);
}

void AcquisitionSequencerRos::setStatus(const std::string& text) {
  status_text_ = text;
  std_msgs::String s;
  s.data = text;
  status_pub_.publish(s);
  diagnostics_.force_update();
}

bool AcquisitionSequencerRos::record() {
  // Both images of one stamp, taken after the arm settled.
  if (!left_image_ || !right_image_ || !left_info_ || !right_info_ || !joints_) return false;
  const ros::Time stamp = left_image_->header.stamp;
  if (right_image_->header.stamp != stamp || stamp < settle_until_) return false;
  geometry_msgs::PoseStamped left_pose, right_pose;
  try {
    for (auto [frame, pose] :
         {std::make_pair(config_.left_frame, &left_pose), std::make_pair(config_.right_frame, &right_pose)}) {
      const geometry_msgs::TransformStamped t = tf_buffer_.lookupTransform(config_.world_frame, frame, stamp);
      pose->header = t.header;
      pose->pose.position.x = t.transform.translation.x;
      pose->pose.position.y = t.transform.translation.y;
      pose->pose.position.z = t.transform.translation.z;
      pose->pose.orientation = t.transform.rotation;
    }
  } catch (const tf2::TransformException& e) {
    ROS_WARN_THROTTLE(5.0, "acquisition_sequencer: no camera pose at %.3f yet: %s", stamp.toSec(), e.what());
    return false;
  }
  try {
    bag_.write("left/image_raw", stamp, *left_image_);
    bag_.write("left/camera_info", stamp, *left_info_);
    bag_.write("right/image_raw", stamp, *right_image_);
    bag_.write("right/camera_info", stamp, *right_info_);
    bag_.write("joint_states", stamp, *joints_);
    bag_.write("left/pose", stamp, left_pose);
    bag_.write("right/pose", stamp, right_pose);
  } catch (const rosbag::BagException& e) {
    state_ = State::kFailed;
    setStatus("failed at stop " + std::to_string(recorded_ + 1) + ": cannot write the bag " + config_.bag_path + ": " +
              e.what());
    return false;
  }
  ++recorded_;
  ROS_INFO("acquisition_sequencer: stop %d of %d recorded at %.3f", recorded_, config_.stops, stamp.toSec());
  return true;
}

void AcquisitionSequencerRos::onTick(const ros::TimerEvent&) {
  switch (state_) {
    case State::kRecord:
      if (!record()) break;
      if (recorded_ >= config_.stops) {
        bag_.close();
        state_ = State::kDone;
        setStatus("done: " + std::to_string(recorded_) + " stops in " + config_.bag_path);
        timer_.stop();
      } else {
        state_ = State::kCapture;
      }
      break;
    case State::kCapture: {
      std_srvs::Trigger trigger;
      if (!capture_client_.call(trigger) || !trigger.response.success) {
        ROS_WARN_THROTTLE(
            5.0, "acquisition_sequencer: capture_reference: %s",
            trigger.response.message.empty() ? "service not available" : trigger.response.message.c_str());
        break;  // tried again at the next tick
      }
      servo_status_ = "servoing";
      state_ = State::kServoing;
      setStatus("servoing to stop " + std::to_string(recorded_ + 1) + " of " + std::to_string(config_.stops));
      break;
    }
    case State::kServoing:
      if (servo_status_ == "servoing" || servo_status_.empty()) break;
      if (servo_status_.rfind("converged", 0) == 0) {
        state_ = State::kRecord;
        settle_until_ = ros::Time::now() + ros::Duration(config_.settle_s);
        setStatus("recording stop " + std::to_string(recorded_ + 1) + " of " + std::to_string(config_.stops));
      } else {
        bag_.close();  // what was recorded stays
        state_ = State::kFailed;
        setStatus("failed at stop " + std::to_string(recorded_ + 1) + ": " + servo_status_);
        timer_.stop();
      }
      break;
    default:
      break;
  }
}

void AcquisitionSequencerRos::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  using diagnostic_msgs::DiagnosticStatus;
  status.summary(state_ == State::kFailed ? DiagnosticStatus::ERROR : DiagnosticStatus::OK, status_text_);
  status.add("stops recorded", recorded_);
  status.add("stops planned", config_.stops);
  status.add("bag", config_.bag_path);
}

}  // namespace exocet_servo
