#include "exocet_common/ros/parameter_reader.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace exocet_common {
namespace {

std::string valueText(XmlRpc::XmlRpcValue& raw) {
  std::ostringstream text;
  text << raw;
  return text.str();
}

std::string number(double v) {
  std::ostringstream text;
  text << v;
  return text.str();
}

}  // namespace

std::string ParameterReader::describe(const std::string& name) const {
  return "parameter ~" + name + " (" + nh_.resolveName(name) + ")";
}

bool ParameterReader::fetch(const std::string& name, XmlRpc::XmlRpcValue* raw) const {
  return nh_.getParam(name, *raw);
}

void ParameterReader::readDouble(const std::string& name, double* value, double min, double max,
                                 const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) return;
  double v = 0.0;
  if (raw.getType() == XmlRpc::XmlRpcValue::TypeDouble)
    v = static_cast<double>(raw);
  else if (raw.getType() == XmlRpc::XmlRpcValue::TypeInt)
    v = static_cast<int>(raw);
  else
    throw std::invalid_argument(describe(name) + " must be a number (" + meaning + "), got '" + valueText(raw) + "'");
  if (!(v >= min && v <= max))
    throw std::invalid_argument(describe(name) + " = " + number(v) + " is out of range [" + number(min) + ", " +
                                number(max) + "]: " + meaning);
  *value = v;
}

void ParameterReader::readPositiveDouble(const std::string& name, double* value, double max,
                                         const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) return;
  double v = *value;
  readDouble(name, &v, -std::numeric_limits<double>::max(), std::numeric_limits<double>::max(), meaning);
  if (!(v > 0.0 && v <= max))
    throw std::invalid_argument(describe(name) + " = " + number(v) + " is out of range (0, " + number(max) +
                                "]: " + meaning);
  *value = v;
}

void ParameterReader::readInt(const std::string& name, int* value, int min, int max, const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) return;
  if (raw.getType() != XmlRpc::XmlRpcValue::TypeInt)
    throw std::invalid_argument(describe(name) + " must be an integer (" + meaning + "), got '" + valueText(raw) + "'");
  const int v = static_cast<int>(raw);
  if (v < min || v > max)
    throw std::invalid_argument(describe(name) + " = " + std::to_string(v) + " is out of range [" +
                                std::to_string(min) + ", " + std::to_string(max) + "]: " + meaning);
  *value = v;
}

void ParameterReader::readBool(const std::string& name, bool* value, const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) return;
  if (raw.getType() != XmlRpc::XmlRpcValue::TypeBoolean)
    throw std::invalid_argument(describe(name) + " must be true or false (" + meaning + "), got '" + valueText(raw) +
                                "'");
  *value = static_cast<bool>(raw);
}

void ParameterReader::readString(const std::string& name, std::string* value, const std::vector<std::string>& allowed,
                                 const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) return;
  if (raw.getType() != XmlRpc::XmlRpcValue::TypeString)
    throw std::invalid_argument(describe(name) + " must be a string (" + meaning + "), got '" + valueText(raw) + "'");
  const std::string v = static_cast<std::string>(raw);
  if (allowed.empty() ? v.empty() : std::find(allowed.begin(), allowed.end(), v) == allowed.end()) {
    std::string list;
    for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
    throw std::invalid_argument(describe(name) + " = '" + v + "' is not allowed: " + meaning +
                                (allowed.empty() ? std::string(" (non-empty)") : "; allowed: " + list));
  }
  *value = v;
}

void ParameterReader::readOptionalString(const std::string& name, std::string* value,
                                         const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) return;
  if (raw.getType() != XmlRpc::XmlRpcValue::TypeString)
    throw std::invalid_argument(describe(name) + " must be a string (" + meaning + "), got '" + valueText(raw) + "'");
  *value = static_cast<std::string>(raw);
}

void ParameterReader::readOptionalTopic(const std::string& name, std::string* topic) const {
  readOptionalString(name, topic, "a topic name, or empty to turn it off");
  std::string why;
  if (!topic->empty() && !ros::names::validate(*topic, why))
    throw std::invalid_argument(describe(name) + " '" + *topic + "' is not a valid topic name" +
                                (why.empty() ? std::string() : ": " + why));
}

void ParameterReader::readTopic(const std::string& name, std::string* topic) const {
  readString(name, topic, {}, "a topic name");
  std::string why;
  if (topic->empty() || !ros::names::validate(*topic, why))
    throw std::invalid_argument(describe(name) + " '" + *topic + "' is not a valid topic name" +
                                (why.empty() ? std::string() : ": " + why));
}

void ParameterReader::readRequiredString(const std::string& name, std::string* value,
                                         const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) throw std::invalid_argument(describe(name) + " is required: " + meaning);
  std::string v = *value;
  readString(name, &v, {}, meaning);
  *value = v;
}

void ParameterReader::readNumberList(const std::string& name, int size, std::vector<double>* values,
                                     const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) return;
  const std::string expected = (size >= 0 ? "a list of " + std::to_string(size) + " numbers" : "a list of numbers");
  if (raw.getType() != XmlRpc::XmlRpcValue::TypeArray || (size >= 0 && raw.size() != size))
    throw std::invalid_argument(describe(name) + " must be " + expected + " (" + meaning + "), got '" + valueText(raw) +
                                "'");
  std::vector<double> out;
  for (int i = 0; i < raw.size(); ++i) {
    if (raw[i].getType() == XmlRpc::XmlRpcValue::TypeDouble)
      out.push_back(static_cast<double>(raw[i]));
    else if (raw[i].getType() == XmlRpc::XmlRpcValue::TypeInt)
      out.push_back(static_cast<int>(raw[i]));
    else
      throw std::invalid_argument(describe(name) + " must be " + expected + " (" + meaning + "), item " +
                                  std::to_string(i) + " is not a number");
    if (!std::isfinite(out.back()))
      throw std::invalid_argument(describe(name) + ": item " + std::to_string(i) + " is not finite (" + meaning + ")");
  }
  *values = out;
}

void ParameterReader::readVector3(const std::string& name, Eigen::Vector3d* value, const std::string& meaning) const {
  std::vector<double> v(value->data(), value->data() + 3);
  readNumberList(name, 3, &v, meaning);
  *value = Eigen::Vector3d(v[0], v[1], v[2]);
}

void ParameterReader::readStringList(const std::string& name, std::vector<std::string>* values,
                                     const std::string& meaning) const {
  XmlRpc::XmlRpcValue raw;
  if (!fetch(name, &raw)) return;
  std::vector<std::string> out;
  if (raw.getType() == XmlRpc::XmlRpcValue::TypeArray) {
    for (int i = 0; i < raw.size(); ++i) {
      if (raw[i].getType() != XmlRpc::XmlRpcValue::TypeString) {
        out.clear();
        break;
      }
      out.push_back(static_cast<std::string>(raw[i]));
    }
  }
  if (out.empty())
    throw std::invalid_argument(describe(name) + " must be a non-empty list of strings (" + meaning + "), got '" +
                                valueText(raw) + "'");
  *values = out;
}

}  // namespace exocet_common
