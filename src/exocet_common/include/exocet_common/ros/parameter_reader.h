/**
 * @file parameter_reader.h
 * @brief Reads private parameters with their allowed range, so that every node rejects a bad value with a message
 * naming the parameter, the value and what is allowed.
 */
#pragma once

#include <string>
#include <vector>

#include <ros/ros.h>
#include <Eigen/Core>

namespace exocet_common {

/**
 * Each read leaves the value untouched when the parameter is not set (the caller's default stands) and throws
 * std::invalid_argument when it is set with the wrong type or outside its range. Ranges are closed unless said.
 */
class ParameterReader {
 public:
  explicit ParameterReader(const ros::NodeHandle& private_nh) : nh_(private_nh) {}

  /// A number in [min, max] (an integer is accepted). `meaning` says what it is, units included.
  void readDouble(const std::string& name, double* value, double min, double max, const std::string& meaning) const;
  /// A number in (min, max]: for strictly positive quantities.
  void readPositiveDouble(const std::string& name, double* value, double max, const std::string& meaning) const;
  void readInt(const std::string& name, int* value, int min, int max, const std::string& meaning) const;
  void readBool(const std::string& name, bool* value, const std::string& meaning) const;
  /// A string among `allowed` (any non-empty string when `allowed` is empty).
  void readString(const std::string& name, std::string* value, const std::vector<std::string>& allowed,
                  const std::string& meaning) const;
  /// A valid, non-empty ROS graph resource name.
  void readTopic(const std::string& name, std::string* topic) const;
  /// A valid ROS graph resource name, or "" for an input or output the user turns off.
  void readOptionalTopic(const std::string& name, std::string* topic) const;
  /// Any string, the empty one included (e.g. a file path where "" means "do not write").
  void readOptionalString(const std::string& name, std::string* value, const std::string& meaning) const;
  /// A non-empty string that must be set: @throws std::invalid_argument "... is required: meaning" when it is not.
  void readRequiredString(const std::string& name, std::string* value, const std::string& meaning) const;
  /// A list of `size` finite numbers (any length when size < 0).
  void readNumberList(const std::string& name, int size, std::vector<double>* values, const std::string& meaning) const;
  /// Three finite numbers, e.g. a lever arm [x, y, z].
  void readVector3(const std::string& name, Eigen::Vector3d* value, const std::string& meaning) const;
  /// A non-empty list of strings.
  void readStringList(const std::string& name, std::vector<std::string>* values, const std::string& meaning) const;

  /// "parameter ~name (/resolved/name)", for messages.
  std::string describe(const std::string& name) const;

 private:
  bool fetch(const std::string& name, XmlRpc::XmlRpcValue* raw) const;
  ros::NodeHandle nh_;
};

}  // namespace exocet_common
