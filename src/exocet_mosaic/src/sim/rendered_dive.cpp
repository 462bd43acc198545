#include "exocet_mosaic/sim/rendered_dive.h"

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <opencv2/imgproc.hpp>

#include "exocet_common/atomic_file.h"
#include "exocet_common/binary_cache.h"
#include "exocet_mosaic/sim/dive_synthesizer.h"

namespace exocet_mosaic {
namespace sim {

RenderedDive renderDive(const DiveDescription& dive, int threads) {
  DiveSynthesisConfig config = dive.synthesis;
  config.threads = threads;
  Seabed seabed = makeSeabed(dive.seabed, config.seed);
  DiveSynthesizer synth(config, seabed.texture.get(), seabed.relief.get());
  RenderedDive out;
  out.camera = config.rig.camera;
  DiveSink sink;
  sink.frame = [&](const FrameTruth& truth) {
    if (truth.dropped) return;
    cv::Mat gray;
    const cv::Mat& image = truth.frame.image;
    if (image.channels() == 1 && image.depth() == CV_8U)
      gray = image.clone();
    else if (image.channels() == 3)
      cv::cvtColor(image, gray, truth.frame.encoding == "rgb8" ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
    else
      image.convertTo(gray, CV_8U, image.depth() == CV_16U ? 1.0 / 256.0 : 1.0);
    const double t = truth.frame.stamp_s - config.start_time_unix_s;
    out.gray.push_back(gray);
    out.stamps_s.push_back(truth.frame.stamp_s);
    out.local_from_camera.push_back(synth.cameraPoseLocal(t));
    double turbidity = 1.0, gain = 1.0;
    config.imaging.waterAt(t, &turbidity, &gain);
    out.turbidity.push_back(turbidity);
    out.light_gain.push_back(gain);
  };
  synth.run(sink);
  return out;
}

namespace {

using exocet_common::fnv1a;
using exocet_common::getValue;
using exocet_common::putValue;

constexpr uint64_t kCacheMagic = 0x31564944474552ULL;  // "REGDIV1"

bool readCache(const std::string& path, RenderedDive* dive) {
  std::ifstream in(path, std::ios::binary);
  uint64_t magic = 0, count = 0;
  int32_t width = 0, height = 0;
  if (!getValue(in, &magic) || magic != kCacheMagic || !getValue(in, &count) || !getValue(in, &width) ||
      !getValue(in, &height))
    return false;
  for (uint64_t i = 0; i < count; ++i) {
    double stamp, gain, turbidity, m[16];
    if (!getValue(in, &stamp) || !getValue(in, &gain) || !getValue(in, &turbidity)) return false;
    for (double& v : m)
      if (!getValue(in, &v)) return false;
    cv::Mat gray(height, width, CV_8UC1);
    if (!in.read(reinterpret_cast<char*>(gray.data), std::streamsize(width) * height)) return false;
    Eigen::Isometry3d pose;
    pose.matrix() = Eigen::Map<const Eigen::Matrix4d>(m);
    dive->gray.push_back(gray);
    dive->stamps_s.push_back(stamp);
    dive->light_gain.push_back(gain);
    dive->turbidity.push_back(turbidity);
    dive->local_from_camera.push_back(pose);
  }
  return true;
}

void writeCache(const std::string& path, const RenderedDive& dive) {
  // A cache is an optimisation: when it cannot be written the next run renders again.
  const std::string temporary = exocet_common::temporaryPathFor(path);
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    putValue(out, kCacheMagic);
    putValue(out, uint64_t(dive.gray.size()));
    putValue(out, int32_t(dive.camera.width));
    putValue(out, int32_t(dive.camera.height));
    for (size_t i = 0; i < dive.gray.size(); ++i) {
      putValue(out, dive.stamps_s[i]);
      putValue(out, dive.light_gain[i]);
      putValue(out, dive.turbidity[i]);
      const Eigen::Matrix4d m = dive.local_from_camera[i].matrix();
      for (int k = 0; k < 16; ++k) putValue(out, m.data()[k]);
      const cv::Mat g = dive.gray[i].isContinuous() ? dive.gray[i] : dive.gray[i].clone();
      out.write(reinterpret_cast<const char*>(g.data), std::streamsize(g.total()));
    }
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(temporary, ignored);
      return;
    }
  }
  try {
    exocet_common::commitTemporaryFile(temporary, path);
  } catch (const std::runtime_error&) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
  }
}

}  // namespace

RenderedDive renderDiveCached(const DiveDescription& dive, int threads, const std::string& cache_dir) {
  char name[64];
  std::snprintf(name, sizeof(name), "rendered_dive_%016llx.bin", static_cast<unsigned long long>(fnv1a(toYaml(dive))));
  const std::string path = cache_dir + "/" + name;
  RenderedDive cached;
  cached.camera = dive.synthesis.rig.camera;
  if (readCache(path, &cached) && !cached.gray.empty()) return cached;
  RenderedDive rendered = renderDive(dive, threads);
  std::error_code error;
  std::filesystem::create_directories(cache_dir, error);
  if (!error) writeCache(path, rendered);
  return rendered;
}

}  // namespace sim
}  // namespace exocet_mosaic
