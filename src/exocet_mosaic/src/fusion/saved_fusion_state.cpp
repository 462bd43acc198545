#include "exocet_mosaic/fusion/saved_fusion_state.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace exocet_mosaic {
namespace fusion {

namespace {

template <typename Matrix>
nlohmann::json numbers(const Matrix& m) {
  std::vector<double> values(static_cast<std::size_t>(m.size()));
  for (Eigen::Index i = 0; i < m.size(); ++i) values[static_cast<std::size_t>(i)] = m(i / m.cols(), i % m.cols());
  return values;
}

template <typename Matrix>
void readNumbers(const nlohmann::json& json, const std::string& key, Matrix* m) {
  const auto it = json.find(key);
  if (it == json.end() || !it->is_array() || it->size() != static_cast<std::size_t>(m->size()))
    throw std::invalid_argument("saved fusion state: '" + key + "' must be an array of " + std::to_string(m->size()) +
                                " numbers");
  for (Eigen::Index i = 0; i < m->size(); ++i) {
    const nlohmann::json& v = (*it)[static_cast<std::size_t>(i)];
    if (!v.is_number()) throw std::invalid_argument("saved fusion state: '" + key + "' holds a non-number");
    (*m)(i / m->cols(), i % m->cols()) = v.get<double>();
  }
}

}  // namespace

nlohmann::json savedFusionStateToJson(const SavedFusionState& s) {
  nlohmann::json j;
  j["stamp_s"] = s.stamp_s;
  j["x"] = numbers(s.x);
  j["P"] = numbers(s.P);
  j["dr_offset_known"] = s.dr_offset_known;
  j["frame"] = s.frame;
  j["utm_zone"] = s.utm_zone;
  j["northern_hemisphere"] = s.northern_hemisphere;
  if (s.map_origin_en_m) j["map_origin_en_m"] = {s.map_origin_en_m->x(), s.map_origin_en_m->y()};
  if (s.operator_heading_rad) j["operator_heading_rad"] = *s.operator_heading_rad;
  return j;
}

SavedFusionState savedFusionStateFromJson(const nlohmann::json& j) {
  if (!j.is_object()) throw std::invalid_argument("saved fusion state: not a JSON object");
  SavedFusionState s;
  const auto stamp = j.find("stamp_s");
  if (stamp == j.end() || !stamp->is_number() || !std::isfinite(stamp->get<double>()) || stamp->get<double>() <= 0.0)
    throw std::invalid_argument("saved fusion state: 'stamp_s' must be a positive number");
  s.stamp_s = stamp->get<double>();
  readNumbers(j, "x", &s.x);
  readNumbers(j, "P", &s.P);
  s.dr_offset_known = j.value("dr_offset_known", false);
  s.frame = j.value("frame", std::string());
  if (s.frame.empty()) throw std::invalid_argument("saved fusion state: 'frame' is missing");
  s.utm_zone = j.value("utm_zone", 0);
  if (s.utm_zone < 0 || s.utm_zone > 60) throw std::invalid_argument("saved fusion state: 'utm_zone' not in [0, 60]");
  s.northern_hemisphere = j.value("northern_hemisphere", true);
  if (j.contains("map_origin_en_m")) {
    Eigen::Matrix<double, 1, 2> origin;
    readNumbers(j, "map_origin_en_m", &origin);
    s.map_origin_en_m = origin.transpose();
  }
  if (j.contains("operator_heading_rad")) {
    if (!j["operator_heading_rad"].is_number())
      throw std::invalid_argument("saved fusion state: 'operator_heading_rad' is not a number");
    s.operator_heading_rad = j["operator_heading_rad"].get<double>();
  }
  return s;
}

std::string resumeRefusal(double saved_stamp_s, double first_input_stamp_s, double max_age_s) {
  std::ostringstream why;
  why.precision(3);
  why << std::fixed;
  const double age_s = first_input_stamp_s - saved_stamp_s;
  if (!std::isfinite(age_s)) {
    why << "the first input's stamp is not finite";
  } else if (age_s <= 0.0) {
    why << "the first input is stamped " << -age_s
        << " s before the saved state (a bag played again from its start, or another dive)";
  } else if (age_s > max_age_s) {
    why << "the first input is stamped " << age_s << " s after the saved state, more than " << max_age_s
        << " s (another dive, or too long a gap)";
  }
  return why.str();
}

}  // namespace fusion
}  // namespace exocet_mosaic
