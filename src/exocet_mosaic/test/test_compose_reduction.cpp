// Composing at the tiles' ground sample distance: the reduced images' pixel frame (block averages and libjpeg's
// scaled decoding agree with it), the choice of the reduction, the composer drawing reduced images into the same tile
// as full ones, the lighting field and the undistortion at any reduction.
#include <gtest/gtest.h>

#include <cstdio>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "compose_fixtures.h"
#include "exocet_mosaic/compose/image_reduction.h"
#include "exocet_mosaic/compose/lighting_corrector.h"
#include "exocet_mosaic/registration/image_undistorter.h"

namespace ec = exocet_mosaic::compose;
using compose_test::FrameFactory;
using compose_test::TruthOrtho;

namespace {

const TruthOrtho& truth() {
  static const TruthOrtho t = TruthOrtho::make(11.0, 7.0, 0.005, 500000.0 - 2.0, 4800000.0 + 3.0);
  return t;
}

/// A horizontal ramp: pixel (x, y) = 2 x + 8 (8 bits up to x = 120).
cv::Mat ramp(const cv::Size& size) {
  cv::Mat image(size, CV_8UC3);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) image.at<cv::Vec3b>(y, x) = cv::Vec3b::all(cv::saturate_cast<uchar>(2 * x + 8));
  return image;
}

/// Mean over the image of (value - expected(x)) where the ramp is not clipped.
double rampBias(const cv::Mat& reduced, int reduction, double* mean_abs) {
  const cv::Matx33d s = ec::fullFromReducedPx(reduction);
  double sum = 0, sum_abs = 0;
  int n = 0;
  for (int y = 1; y < reduced.rows - 1; ++y)
    for (int x = 1; x < reduced.cols - 1; ++x) {
      const double full_x = s(0, 0) * x + s(0, 2);
      const double expected = 2 * full_x + 8;
      if (expected > 240) continue;
      const double d = reduced.at<cv::Vec3b>(y, x)[1] - expected;
      sum += d;
      sum_abs += std::abs(d);
      ++n;
    }
  *mean_abs = sum_abs / std::max(1, n);
  return sum / std::max(1, n);
}

}  // namespace

TEST(ImageReduction, SizesAndPixelFrame) {
  EXPECT_EQ(ec::reducedImageSize(cv::Size(3840, 2160), 4), cv::Size(960, 540));
  EXPECT_EQ(ec::reducedImageSize(cv::Size(721, 577), 2), cv::Size(360, 288));  // floor
  const cv::Matx33d s = ec::fullFromReducedPx(4);
  EXPECT_DOUBLE_EQ(s(0, 0), 4.0);
  EXPECT_DOUBLE_EQ(s(0, 2), 1.5);  // reduced pixel 0 averages full pixels 0..3: centred on 1.5
  // The image's outer edge is the same line at any reduction.
  EXPECT_DOUBLE_EQ(s(0, 0) * -0.5 + s(0, 2), -0.5);
  EXPECT_FALSE(ec::isImageReduction(3));
  EXPECT_TRUE(ec::reduceImage(cv::Mat(10, 10, CV_8UC1), cv::Size(10, 10), 3).empty());
}

TEST(ImageReduction, BlockAveragesAndScaledJpegDecodingShareThePixelFrame) {
  const cv::Mat full = ramp(cv::Size(116, 64));  // 116: not a multiple of 8 (a partial last block)
  std::vector<uchar> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", full, jpeg, {cv::IMWRITE_JPEG_QUALITY, 98}));
  for (int r : {2, 4, 8}) {
    double mean_abs = 0;
    const cv::Mat averaged = ec::reduceImage(full, full.size(), r);
    ASSERT_EQ(averaged.size(), ec::reducedImageSize(full.size(), r));
    EXPECT_NEAR(rampBias(averaged, r, &mean_abs), 0.0, 0.6) << "block average, r = " << r;
    EXPECT_LT(mean_abs, 0.6);
    // OpenCV's IMREAD_REDUCED_COLOR_r: libjpeg's scaled decoding, ceil(size / r), cropped by reduceImage().
    const cv::Mat decoded = cv::imdecode(jpeg, 8 * r + 1);
    ASSERT_EQ(decoded.cols, (full.cols + r - 1) / r);
    const cv::Mat cropped = ec::reduceImage(decoded, full.size(), r);
    ASSERT_EQ(cropped.size(), averaged.size());
    const double bias = rampBias(cropped, r, &mean_abs);
    std::printf("r = %d: scaled JPEG decode against the ramp: bias %.2f, mean abs %.2f grey\n", r, bias, mean_abs);
    // Half a full pixel off would be a bias of 1 grey (the ramp is 2 grey / px).
    EXPECT_NEAR(bias, 0.0, 0.5) << "r = " << r;
    EXPECT_LT(mean_abs, 2.0);
  }
  // An image of neither shape is refused.
  EXPECT_TRUE(ec::reduceImage(full(cv::Rect(0, 0, 20, 20)), full.size(), 2).empty());
}

TEST(ImageReduction, ChoiceFollowsTheGroundSampleDistancesWithABand) {
  EXPECT_EQ(ec::chooseImageReduction(0.00075, 0.005, 8, 0), 4);  // 4K at 2.5 m into 5 mm tiles: 3 mm
  EXPECT_EQ(ec::chooseImageReduction(0.0015, 0.005, 8, 0), 2);   // HD
  EXPECT_EQ(ec::chooseImageReduction(0.0032, 0.0032, 8, 0), 1);  // tiles at the native GSD
  EXPECT_EQ(ec::chooseImageReduction(0.00075, 0.005, 2, 0), 2);  // capped
  EXPECT_EQ(ec::chooseImageReduction(0.0005, 0.05, 8, 0), 8);
  EXPECT_EQ(ec::chooseImageReduction(0.00075, 0.0, 8, 0), 1);  // native tiles (gsd 0)
  EXPECT_EQ(ec::chooseImageReduction(std::nan(""), 0.005, 8, 4), 1);
  // The band: kept at 4 while 4 x native stays within 10 % above the tile's GSD...
  EXPECT_EQ(ec::chooseImageReduction(0.0013, 0.005, 8, 4), 4);
  EXPECT_EQ(ec::chooseImageReduction(0.0014, 0.005, 8, 4), 2);
  // ...and kept at 2 until 4 x native is 10 % below it.
  EXPECT_EQ(ec::chooseImageReduction(0.0012, 0.005, 8, 2), 2);
  EXPECT_EQ(ec::chooseImageReduction(0.0011, 0.005, 8, 2), 4);
}

namespace {

struct ComposedRun {
  std::vector<ec::ClosedMosaic> tiles;
  std::vector<int> requested;  // reductions the loader was asked for
};

/// The fixture's flight (native GSD 5.25-5.75 mm) into 25 mm tiles, every image through a loader.
ComposedRun composeFlight(int max_reduction, bool scaled_jpeg) {
  FrameFactory factory;
  factory.truth = &truth();
  factory.flight.turn_rad_per_frame = 0.002;
  ec::ComposerConfig config;
  config.lighting.enabled = false;
  config.gsd_m = 0.025;
  config.frames_per_mosaic = 60;
  config.keep_composed_images = true;
  config.max_image_reduction = max_reduction;
  ec::MosaicComposer composer(config);
  ComposedRun run;
  for (int i = 0; i < 150; ++i) {
    ec::ComposerFrame frame = factory.frame(i);
    const cv::Mat image = frame.image;
    frame.image = cv::Mat();
    frame.image_size = image.size();
    frame.image_channels = 3;
    frame.load_image = [image, scaled_jpeg, &run](int reduction) {
      run.requested.push_back(reduction);
      if (!scaled_jpeg || reduction == 1) return image;
      std::vector<uchar> jpeg;
      cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, 98});
      return cv::imdecode(jpeg, 8 * reduction + 1);
    };
    if (auto t = composer.add(frame)) run.tiles.push_back(*t);
    EXPECT_EQ(composer.stats().image_reduction, std::min(4, max_reduction));
  }
  if (auto t = composer.flush()) run.tiles.push_back(*t);
  return run;
}

double errorAgainstTruth(const ec::ClosedMosaic& tile, cv::Point2d* shift) {
  cv::Mat inner;
  cv::erode(tile.mask, inner, cv::Mat(), cv::Point(-1, -1), 2);
  // The truth low-passed to the tile's GSD (as a camera at that GSD would see it).
  cv::Mat truth_at_gsd;
  const double sigma = 0.5 * tile.gsd_m / truth().gsd_m;
  cv::Mat blurred_truth;
  cv::GaussianBlur(truth().image, blurred_truth, cv::Size(0, 0), sigma);
  TruthOrtho low = truth();
  low.image = blurred_truth;
  truth_at_gsd = low.onGrid(tile.origin_easting_m, tile.origin_northing_m, tile.gsd_m, tile.image.size());
  const cv::Rect r = compose_test::innerRect(inner, 1.5);
  *shift = compose_test::phaseShift(truth_at_gsd(r), tile.image(r));
  return compose_test::meanAbsError(tile.image, truth_at_gsd, inner);
}

}  // namespace

TEST(ComposeReduction, ReducedImagesGiveTheSameTileAsFullOnes) {
  const ComposedRun full = composeFlight(1, false);
  const ComposedRun reduced = composeFlight(8, false);
  const ComposedRun jpeg = composeFlight(8, true);
  ASSERT_EQ(full.tiles.size(), 3u);
  ASSERT_EQ(reduced.tiles.size(), full.tiles.size());
  ASSERT_EQ(jpeg.tiles.size(), full.tiles.size());
  for (int r : reduced.requested) EXPECT_EQ(r, 4);  // 4 x 5.75 mm <= 25 mm < 8 x 5.25 mm
  for (int r : full.requested) EXPECT_EQ(r, 1);
  for (std::size_t k = 0; k < full.tiles.size(); ++k) {
    const ec::ClosedMosaic& a = full.tiles[k];
    for (const ec::ClosedMosaic* b : {&reduced.tiles[k], &jpeg.tiles[k]}) {
      // The geometry is the chain's and the navigation's: identical. The raster is on the same grid; its extent may
      // differ by the pixel on each side that the reduced images' wider fade at their edges reaches.
      const double de_px = (b->origin_easting_m - a.origin_easting_m) / a.gsd_m;
      const double dn_px = (b->origin_northing_m - a.origin_northing_m) / a.gsd_m;
      EXPECT_NEAR(de_px, std::round(de_px), 1e-6);
      EXPECT_NEAR(dn_px, std::round(dn_px), 1e-6);
      EXPECT_LE(std::abs(de_px), 1.0 + 1e-6);
      EXPECT_LE(std::abs(dn_px), 1.0 + 1e-6);
      EXPECT_LE(std::abs(b->image.cols - a.image.cols), 2);
      EXPECT_LE(std::abs(b->image.rows - a.image.rows), 2);
      ASSERT_EQ(b->footprints_en_m.size(), a.footprints_en_m.size());
      for (std::size_t i = 0; i < a.footprints_en_m.size(); ++i)
        for (int c = 0; c < 4; ++c) EXPECT_LT((b->footprints_en_m[i][c] - a.footprints_en_m[i][c]).norm(), 1e-9);
      // The kept images are the reduced ones, placed by their own pixels.
      ASSERT_EQ(b->images.size(), a.images.size());
      for (std::size_t i = 0; i < a.images.size(); ++i) {
        EXPECT_EQ(b->images[i].reduction, 4);
        EXPECT_EQ(b->images[i].image.size(), cv::Size(80, 60));
        const Eigen::Vector2d centre_full =
            ec::applyHomography(a.images[i].ground_from_px, Eigen::Vector2d(159.5, 119.5));
        const Eigen::Vector2d centre_reduced =
            ec::applyHomography(b->images[i].ground_from_px, Eigen::Vector2d(39.5, 29.5));
        EXPECT_LT((centre_full - centre_reduced).norm(), 1e-9);
      }
    }
    cv::Point2d shift_full, shift_reduced, shift_jpeg;
    const double mae_full = errorAgainstTruth(a, &shift_full);
    const double mae_reduced = errorAgainstTruth(reduced.tiles[k], &shift_reduced);
    const double mae_jpeg = errorAgainstTruth(jpeg.tiles[k], &shift_jpeg);
    std::printf(
        "tile %zu against the truth at 25 mm: full images %.2f grey (offset %.3f, %.3f px), reduced by 4 %.2f grey "
        "(%.3f, %.3f), scaled JPEG %.2f grey (%.3f, %.3f)\n",
        k, mae_full, shift_full.x, shift_full.y, mae_reduced, shift_reduced.x, shift_reduced.y, mae_jpeg, shift_jpeg.x,
        shift_jpeg.y);
    // Drawn from 4 px per tile px, bilinear sampling of full images aliases; the block averages do not.
    EXPECT_LE(mae_reduced, mae_full + 0.2);
    EXPECT_LT(mae_jpeg, mae_full + 1.0);
    // A pixel frame off by the (r - 1) / 2 full px of the block centres would show as 0.33 tile px.
    EXPECT_LT(std::hypot(shift_reduced.x, shift_reduced.y), 0.15);
    EXPECT_LT(std::hypot(shift_jpeg.x, shift_jpeg.y), 0.15);
  }
}

TEST(ComposeReduction, TheLightingFieldFitsTheImagesAtAnyReduction) {
  ec::LightingConfig config;
  config.warmup_frames = 3;
  ec::LightingCorrector corrector(config);
  // A lamp cone: bright centre, dark corners, on a flat grey seabed.
  cv::Mat lit(480, 640, CV_8UC3);
  for (int y = 0; y < lit.rows; ++y)
    for (int x = 0; x < lit.cols; ++x) {
      const double d = std::hypot(x - 320.0, y - 240.0) / 400.0;
      lit.at<cv::Vec3b>(y, x) = cv::Vec3b::all(cv::saturate_cast<uchar>(200 * (1.0 - 0.6 * d * d)));
    }
  for (int i = 0; i < 2; ++i) corrector.observe(lit);
  corrector.observe(ec::reduceImage(lit, lit.size(), 4));  // a reduced image feeds the same field
  EXPECT_EQ(corrector.framesUsed(), 3);
  ASSERT_TRUE(corrector.ready());
  const cv::Mat corrected_full = corrector.correct(lit);
  const cv::Mat corrected_reduced = corrector.correct(ec::reduceImage(lit, lit.size(), 4));
  ASSERT_EQ(corrected_reduced.size(), cv::Size(160, 120));
  const cv::Mat full_then_reduced = ec::reduceImage(corrected_full, lit.size(), 4);
  cv::Mat diff;
  cv::absdiff(corrected_reduced, full_then_reduced, diff);
  const double mean = cv::mean(diff)[0];
  std::printf("lighting: reduced then corrected vs corrected then reduced: mean %.2f grey\n", mean);
  EXPECT_LT(mean, 1.0);
  // The cone is corrected in the reduced image: its corner at 80 grey (centre 200) is brought up.
  EXPECT_GT(corrected_reduced.at<cv::Vec3b>(5, 5)[0], 160);
  // Another aspect restarts the field.
  corrector.observe(cv::Mat(100, 100, CV_8UC3, cv::Scalar::all(120)));
  EXPECT_EQ(corrector.framesUsed(), 1);
}

TEST(ComposeReduction, TheUndistortedReducedImageIsTheUndistortedImageReduced) {
  const cv::Size size(640, 480);
  const std::array<double, 9> k{500, 0, 319.5, 0, 500, 239.5, 0, 0, 1};
  const std::array<double, 5> d{-0.25, 0.08, 0.0, 0.0, 0.0};
  const exocet_mosaic::registration::ImageUndistorter full(size, k, d);
  ASSERT_TRUE(full.active());
  // A smooth texture, distorted (the camera's image).
  const cv::Mat texture = truth().image(cv::Rect(0, 0, size.width, size.height)).clone();
  cv::Mat blurred;
  cv::GaussianBlur(texture, blurred, cv::Size(0, 0), 2.0);
  for (int r : {2, 4}) {
    const exocet_mosaic::registration::ImageUndistorter reduced = full.reducedBy(r);
    EXPECT_EQ(reduced.size(), ec::reducedImageSize(size, r));
    const Eigen::Matrix3d expected_k =
        Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(ec::fullFromReducedPx(r).inv().val) *
        full.cameraMatrix();
    EXPECT_LT((reduced.cameraMatrix() - expected_k).norm(), 1e-9);
    const cv::Mat undistorted_reduced = reduced.apply(ec::reduceImage(blurred, size, r));
    const cv::Mat reduced_undistorted = ec::reduceImage(full.apply(blurred), size, r);
    ASSERT_EQ(undistorted_reduced.size(), reduced_undistorted.size());
    cv::Mat diff;
    cv::absdiff(undistorted_reduced, reduced_undistorted, diff);
    const cv::Rect inner(4, 4, diff.cols - 8, diff.rows - 8);
    const double mean = cv::mean(diff(inner))[0];
    const cv::Point2d shift = compose_test::phaseShift(reduced_undistorted(inner), undistorted_reduced(inner));
    std::printf("undistortion at 1/%d: mean difference %.2f grey, offset (%.3f, %.3f) px\n", r, mean, shift.x,
                shift.y);
    EXPECT_LT(mean, 3.0);
    EXPECT_LT(std::hypot(shift.x, shift.y), 0.05);
  }
  EXPECT_THROW(full.reducedBy(3), std::invalid_argument);
  EXPECT_THROW(full.reducedBy(2).apply(blurred), std::invalid_argument);  // a full image into the reduced one
}
