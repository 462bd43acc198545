// ParameterReader on a live parameter server: values in range are read, unset ones keep the caller's default, and
// a bad one is refused with a message naming the parameter, the value and what is allowed.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <vector>

#include <ros/ros.h>

#include "exocet_common/ros/parameter_reader.h"

namespace exocet_common {
namespace {

/// The message of the std::invalid_argument `read` throws ("" when it does not throw).
template <typename Read>
std::string refusal(Read read) {
  try {
    read();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(ParameterReader, ReadsValuesInRangeAndLeavesUnsetOnesAlone) {
  const ParameterReader params{ros::NodeHandle("~")};
  double rate = 0.0, unset = 3.5;
  params.readDouble("rate_hz", &rate, 0.0, 100.0, "the rate (Hz)");
  params.readDouble("not_set", &unset, 0.0, 100.0, "anything");
  EXPECT_DOUBLE_EQ(rate, 12.5);
  EXPECT_DOUBLE_EQ(unset, 3.5);
  int count = 0;
  params.readInt("count", &count, 1, 10, "a count");
  EXPECT_EQ(count, 7);
  bool flag = false;
  params.readBool("flag", &flag, "a switch");
  EXPECT_TRUE(flag);
  std::string method, topic;
  params.readString("method", &method, {"klt", "rmr"}, "the method");
  params.readTopic("topic", &topic);
  EXPECT_EQ(method, "klt");
  EXPECT_EQ(topic, "/camera/image_raw");
  Eigen::Vector3d lever = Eigen::Vector3d::Zero();
  params.readVector3("lever_arm_m", &lever, "the lever arm (m)");
  EXPECT_TRUE(lever.isApprox(Eigen::Vector3d(0.5, 0.0, -0.25)));
  std::vector<std::string> names;
  params.readStringList("names", &names, "the joints");
  EXPECT_EQ(names, (std::vector<std::string>{"joint_1", "joint_2"}));
  std::string empty = "default";
  params.readOptionalString("empty", &empty, "a file, empty for none");
  EXPECT_EQ(empty, "");
}

TEST(ParameterReader, RefusesBadValuesNamingTheParameterAndWhatIsAllowed) {
  const ParameterReader params{ros::NodeHandle("~")};
  double d = 0.0;
  const std::string range = refusal([&] { params.readDouble("too_big", &d, 0.0, 100.0, "the rate (Hz)"); });
  EXPECT_NE(range.find("~too_big"), std::string::npos) << range;
  EXPECT_NE(range.find("[0, 100]"), std::string::npos) << range;
  EXPECT_NE(range.find("the rate (Hz)"), std::string::npos) << range;
  const std::string type = refusal([&] { params.readDouble("text_number", &d, 0.0, 100.0, "the rate"); });
  EXPECT_NE(type.find("must be a number"), std::string::npos) << type;
  EXPECT_NE(type.find("fast"), std::string::npos) << type;
  const std::string positive = refusal([&] { params.readPositiveDouble("too_big", &d, 10.0, "a gain"); });
  EXPECT_NE(positive.find("(0, 10]"), std::string::npos) << positive;
  int i = 0;
  EXPECT_NE(refusal([&] { params.readInt("rate_hz", &i, 0, 100, "a count"); }).find("integer"), std::string::npos);
  std::string s;
  const std::string member = refusal([&] { params.readString("method", &s, {"rmr", "auto"}, "the method"); });
  EXPECT_NE(member.find("allowed: rmr, auto"), std::string::npos) << member;
  EXPECT_NE(refusal([&] { params.readTopic("bad_topic", &s); }).find("not a valid topic name"), std::string::npos);
  EXPECT_NE(refusal([&] {
              params.readRequiredString("absent", &s, "the output folder");
            }).find("~absent (/parameter_reader/absent) is required: the output folder"),
            std::string::npos);
  std::vector<double> list;
  EXPECT_NE(refusal([&] { params.readNumberList("short_list", 3, &list, "xyz"); }).find("a list of 3 numbers"),
            std::string::npos);
  EXPECT_NE(refusal([&] { params.readNumberList("mixed_list", -1, &list, "xyz"); }).find("item 1 is not a number"),
            std::string::npos);
  std::vector<std::string> names;
  EXPECT_NE(refusal([&] { params.readStringList("short_list", &names, "joints"); }).find("list of strings"),
            std::string::npos);
}

}  // namespace
}  // namespace exocet_common

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "parameter_reader");
  return RUN_ALL_TESTS();
}
