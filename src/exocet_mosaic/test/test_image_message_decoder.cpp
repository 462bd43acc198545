// Decoding of compressed camera images (ros/image_message_decoder.h): as stored, or luminance only for the
// registration.
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "exocet_mosaic/ros/image_message_decoder.h"

namespace exocet_mosaic {
namespace {

cv::Mat colourScene() {
  cv::Mat image(240, 320, CV_8UC3);
  cv::RNG rng(7);
  rng.fill(image, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(image, image, cv::Size(0, 0), 2.0);
  cv::circle(image, cv::Point(160, 120), 50, cv::Scalar(20, 200, 90), -1);
  return image;
}

sensor_msgs::CompressedImage compress(const cv::Mat& image, const std::string& ext, const std::string& format) {
  sensor_msgs::CompressedImage msg;
  std::vector<uchar> data;
  cv::imencode(ext, image, data, {cv::IMWRITE_JPEG_QUALITY, 95});
  msg.data = data;
  msg.format = format;
  return msg;
}

TEST(ImageMessageDecoder, ColourJpegAsStoredAndAsGrey) {
  const cv::Mat scene = colourScene();
  const sensor_msgs::CompressedImage msg = compress(scene, ".jpg", "bgr8; jpeg compressed bgr8");
  DecodedImage colour, grey;
  ASSERT_EQ(decodeCompressedImage(msg, &colour), "");
  EXPECT_EQ(colour.encoding, "bgr8");
  EXPECT_EQ(colour.image.type(), CV_8UC3);
  ASSERT_EQ(decodeCompressedImage(msg, &grey, DecodeMode::kGreyIfJpeg), "");
  EXPECT_EQ(grey.encoding, "mono8");
  ASSERT_EQ(grey.image.type(), CV_8UC1);
  ASSERT_EQ(grey.image.size(), scene.size());
  // The JPEG's luminance is what cvtColor computes from the decoded colour (same BT.601 weights), up to rounding
  // and the colour round trip.
  cv::Mat reference, difference;
  cv::cvtColor(colour.image, reference, cv::COLOR_BGR2GRAY);
  cv::absdiff(reference, grey.image, difference);
  EXPECT_LT(cv::mean(difference)[0], 1.5);
  double max_difference = 0;
  cv::minMaxLoc(difference, nullptr, &max_difference);
  EXPECT_LE(max_difference, 12.0);
}

TEST(ImageMessageDecoder, PngBayerAndSixteenBitKeepWhatTheyStore) {
  const cv::Mat scene = colourScene();
  DecodedImage out;
  ASSERT_EQ(decodeCompressedImage(compress(scene, ".png", "bgr8; png compressed bgr8"), &out, DecodeMode::kGreyIfJpeg),
            "");
  EXPECT_EQ(out.encoding, "bgr8");
  EXPECT_EQ(cv::norm(out.image, scene, cv::NORM_INF), 0.0);  // lossless
  cv::Mat bayer(240, 320, CV_8UC1, cv::Scalar(9));
  ASSERT_EQ(
      decodeCompressedImage(compress(bayer, ".png", "bayer_rggb8; png compressed"), &out, DecodeMode::kGreyIfJpeg), "");
  EXPECT_EQ(out.encoding, "bayer_rggb8");
  cv::Mat deep(60, 80, CV_16UC1, cv::Scalar(3000));
  ASSERT_EQ(decodeCompressedImage(compress(deep, ".png", "mono16; png compressed"), &out, DecodeMode::kGreyIfJpeg), "");
  EXPECT_EQ(out.encoding, "mono16");
  EXPECT_EQ(out.image.at<uint16_t>(10, 10), 3000);
}

TEST(ImageMessageDecoder, CorruptDataIsNamed) {
  sensor_msgs::CompressedImage msg = compress(colourScene(), ".jpg", "bgr8; jpeg compressed bgr8");
  msg.data.resize(40);  // header only
  DecodedImage out;
  for (DecodeMode mode : {DecodeMode::kAsStored, DecodeMode::kGreyIfJpeg}) {
    const std::string error = decodeCompressedImage(msg, &out, mode);
    EXPECT_NE(error.find("cannot be decoded"), std::string::npos) << error;
    EXPECT_TRUE(out.image.empty());
  }
  msg.data.clear();
  EXPECT_NE(decodeCompressedImage(msg, &out, DecodeMode::kGreyIfJpeg), "");
}

TEST(ImageMessageDecoder, ShapeFromTheHeaderIsTheDecodedDisplayShape) {
  const cv::Mat colour = colourScene();
  cv::Mat grey;
  cv::cvtColor(colour, grey, cv::COLOR_BGR2GRAY);
  cv::Mat deep(61, 83, CV_16UC1, cv::Scalar(3000));
  const std::vector<sensor_msgs::CompressedImage> messages = {
      compress(colour, ".jpg", "bgr8; jpeg compressed bgr8"),
      compress(grey, ".jpg", "mono8; jpeg compressed mono8"),
      compress(colour, ".png", "bgr8; png compressed bgr8"),
      compress(grey, ".png", "mono8; png compressed mono8"),
      compress(grey, ".png", "bayer_rggb8; png compressed"),
      compress(deep, ".png", "mono16; png compressed"),
      compress(colour(cv::Rect(3, 5, 301, 177)).clone(), ".jpg", "")};
  for (const auto& msg : messages) {
    const auto shape = peekDisplayShape(msg);
    ASSERT_TRUE(shape) << msg.format;
    DecodedImage decoded;
    ASSERT_EQ(decodeCompressedImage(msg, &decoded), "");
    const cv::Mat display = toDisplayImage(decoded.image, decoded.encoding);
    EXPECT_EQ(shape->size, display.size()) << msg.format;
    EXPECT_EQ(shape->channels, display.channels()) << msg.format;
  }
  sensor_msgs::CompressedImage broken = messages[0];
  broken.data.resize(12);
  EXPECT_FALSE(peekDisplayShape(broken));
  broken.data = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27};
  EXPECT_FALSE(peekDisplayShape(broken));
}

}  // namespace
}  // namespace exocet_mosaic
