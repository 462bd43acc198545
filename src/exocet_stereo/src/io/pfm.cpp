// Portable Float Map reading and writing.
#include "exocet_stereo/io/pfm.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace exocet_stereo {
namespace io {
namespace {

bool hostIsLittleEndian() {
  const uint16_t one = 1;
  uint8_t first;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

void swapBytes(float* values, size_t count) {
  for (size_t i = 0; i < count; ++i) {
    uint8_t bytes[4];
    std::memcpy(bytes, values + i, 4);
    std::swap(bytes[0], bytes[3]);
    std::swap(bytes[1], bytes[2]);
    std::memcpy(values + i, bytes, 4);
  }
}

}  // namespace

void writePfm(const std::string& path, const cv::Mat& image) {
  if (image.type() != CV_32FC1 && image.type() != CV_32FC3)
    throw std::invalid_argument("writePfm: image must be CV_32FC1 or CV_32FC3");
  std::ofstream out(path, std::ios::binary);
  if (!out) throw std::runtime_error("writePfm: cannot open " + path + " for writing");
  const int channels = image.channels();
  out << (channels == 1 ? "Pf" : "PF") << "\n" << image.cols << " " << image.rows << "\n-1.0\n";
  const size_t row_values = static_cast<size_t>(image.cols) * channels;
  std::vector<float> row(row_values);
  for (int y = image.rows - 1; y >= 0; --y) {  // PFM stores the bottom row first
    const float* in = image.ptr<float>(y);
    for (size_t i = 0; i < row_values; ++i) row[i] = std::isnan(in[i]) ? std::numeric_limits<float>::infinity() : in[i];
    if (!hostIsLittleEndian()) swapBytes(row.data(), row_values);
    out.write(reinterpret_cast<const char*>(row.data()), static_cast<std::streamsize>(row_values * sizeof(float)));
  }
  if (!out) throw std::runtime_error("writePfm: write failed for " + path);
}

cv::Mat readPfm(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("readPfm: cannot open " + path);
  std::string magic;
  int width = 0, height = 0;
  double scale = 0.0;
  if (!(in >> magic >> width >> height >> scale) || (magic != "Pf" && magic != "PF"))
    throw std::runtime_error("readPfm: " + path + " has no valid PFM header (Pf/PF, width, height, scale)");
  if (width <= 0 || height <= 0 || width > 100000 || height > 100000 || scale == 0.0)
    throw std::runtime_error("readPfm: " + path + " has a bad size or zero scale");
  in.get();  // the single whitespace character ending the header
  const int channels = magic == "Pf" ? 1 : 3;
  cv::Mat image(height, width, channels == 1 ? CV_32FC1 : CV_32FC3);
  const size_t row_values = static_cast<size_t>(width) * channels;
  const bool file_little = scale < 0.0;
  for (int y = height - 1; y >= 0; --y) {
    float* row = image.ptr<float>(y);
    in.read(reinterpret_cast<char*>(row), static_cast<std::streamsize>(row_values * sizeof(float)));
    if (!in) throw std::runtime_error("readPfm: " + path + " is truncated");
    if (file_little != hostIsLittleEndian()) swapBytes(row, row_values);
  }
  return image;
}

}  // namespace io
}  // namespace exocet_stereo
