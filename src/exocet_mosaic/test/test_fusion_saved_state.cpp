// The fusion's saved state (fusion/saved_fusion_state.h): read back exactly, bad files refused with the field named,
// and the rule that decides whether a saved state belongs to the dive coming in.
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "exocet_mosaic/fusion/saved_fusion_state.h"

using namespace exocet_mosaic::fusion;

TEST(SavedFusionState, ReadsBackExactly) {
  SavedFusionState s;
  s.stamp_s = 1780300844.2;
  for (int i = 0; i < kStateSize; ++i) s.x(i) = 0.1 * i + 734398.0 * (i < 2);
  s.P = StateMatrix::Identity() * 0.01;
  s.P(0, 1) = s.P(1, 0) = 0.002;
  s.dr_offset_known = true;
  s.frame = "utm";
  s.utm_zone = 31;
  s.northern_hemisphere = true;
  s.map_origin_en_m = Eigen::Vector2d(734400.0, 4772700.0);
  s.operator_heading_rad = 0.25;
  const SavedFusionState back = savedFusionStateFromJson(savedFusionStateToJson(s));
  EXPECT_EQ(back.stamp_s, s.stamp_s);
  EXPECT_EQ(back.x, s.x);
  EXPECT_EQ(back.P, s.P);
  EXPECT_TRUE(back.dr_offset_known);
  EXPECT_EQ(back.frame, "utm");
  EXPECT_EQ(back.utm_zone, 31);
  ASSERT_TRUE(back.map_origin_en_m);
  EXPECT_EQ(*back.map_origin_en_m, *s.map_origin_en_m);
  ASSERT_TRUE(back.operator_heading_rad);
  EXPECT_EQ(*back.operator_heading_rad, 0.25);

  SavedFusionState local;
  local.stamp_s = 12.0;
  local.frame = "map";
  const SavedFusionState local_back = savedFusionStateFromJson(savedFusionStateToJson(local));
  EXPECT_FALSE(local_back.map_origin_en_m);
  EXPECT_FALSE(local_back.operator_heading_rad);
  EXPECT_EQ(local_back.utm_zone, 0);
}

TEST(SavedFusionState, BadFilesAreRefusedNamingTheField) {
  SavedFusionState s;
  s.stamp_s = 100.0;
  s.frame = "utm";
  const nlohmann::json good = savedFusionStateToJson(s);
  const auto refusal = [](nlohmann::json j) {
    try {
      savedFusionStateFromJson(j);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  nlohmann::json j = good;
  j.erase("stamp_s");
  EXPECT_NE(refusal(j).find("stamp_s"), std::string::npos);
  j = good;
  j["x"] = {1.0, 2.0};
  EXPECT_NE(refusal(j).find("'x'"), std::string::npos);
  j = good;
  j["P"][3] = "a";
  EXPECT_NE(refusal(j).find("'P'"), std::string::npos);
  j = good;
  j["frame"] = "";
  EXPECT_NE(refusal(j).find("frame"), std::string::npos);
  j = good;
  j["utm_zone"] = 61;
  EXPECT_NE(refusal(j).find("utm_zone"), std::string::npos);
  EXPECT_NE(refusal(nlohmann::json::array()), "");
}

TEST(SavedFusionState, ResumedOnlyWhenTheFirstInputContinuesItsClock) {
  EXPECT_EQ(resumeRefusal(1000.0, 1003.5, 30.0), "") << "a restart";
  EXPECT_NE(resumeRefusal(1000.0, 1000.0, 30.0), "") << "the same stamp: the same inputs again";
  const std::string replayed = resumeRefusal(1000.0, 900.0, 30.0);
  EXPECT_NE(replayed.find("before the saved state"), std::string::npos) << replayed;
  const std::string later = resumeRefusal(1000.0, 1031.0, 30.0);
  EXPECT_NE(later.find("more than 30"), std::string::npos) << later;
  EXPECT_NE(resumeRefusal(1000.0, std::nan(""), 30.0), "");
}
