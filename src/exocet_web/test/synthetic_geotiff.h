// Synthetic GeoTIFF tiles for the tests, written with GDAL as exocet_mosaic's tile writer writes them: north-up in a
// UTM zone, RGB + alpha (unassociated), EXOCET_* metadata.
#pragma once

#include <functional>
#include <string>

#include <cpl_conv.h>
#include <cpl_string.h>
#include <gdal.h>
#include <ogr_srs_api.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "exocet_common/utm_grid.h"
#include "exocet_web/tiles/web_mercator.h"

namespace exocet_web {
namespace testing {

struct SyntheticTile {
  double origin_easting_m = 0.0;  ///< top-left corner
  double origin_northing_m = 0.0;
  double gsd_m = 0.005;
  int width_px = 400;
  int height_px = 300;
  int utm_zone = 31;
  bool northern = true;
  /// Colour (BGR) and alpha of pixel (col, row).
  std::function<cv::Vec4b(int col, int row)> pixel = [](int, int) { return cv::Vec4b(90, 120, 150, 255); };
  bool local_frame = false;  ///< an engineering CRS (a dive without a datum) instead of the UTM zone
};

/// Writes `t` to `path` (GTiff, RGBA, DEFLATE); false on failure.
inline bool writeSyntheticGeoTiff(const std::string& path, const SyntheticTile& t) {
  GDALAllRegister();
  GDALDriverH driver = GDALGetDriverByName("GTiff");
  char** options = nullptr;
  options = CSLSetNameValue(options, "COMPRESS", "DEFLATE");
  options = CSLSetNameValue(options, "TILED", "YES");
  options = CSLSetNameValue(options, "ALPHA", "YES");
  GDALDatasetH ds = GDALCreate(driver, path.c_str(), t.width_px, t.height_px, 4, GDT_Byte, options);
  CSLDestroy(options);
  if (!ds) return false;
  double gt[6] = {t.origin_easting_m, t.gsd_m, 0.0, t.origin_northing_m, 0.0, -t.gsd_m};
  GDALSetGeoTransform(ds, gt);
  OGRSpatialReferenceH srs = OSRNewSpatialReference(nullptr);
  if (t.local_frame) {
    OSRSetLocalCS(srs, "map");
    OSRSetLinearUnits(srs, SRS_UL_METER, 1.0);
  } else {
    OSRImportFromEPSG(srs, (t.northern ? 32600 : 32700) + t.utm_zone);
  }
  char* wkt = nullptr;
  OSRExportToWkt(srs, &wkt);
  GDALSetProjection(ds, wkt);
  CPLFree(wkt);
  OSRDestroySpatialReference(srs);
  GDALSetRasterColorInterpretation(GDALGetRasterBand(ds, 4), GCI_AlphaBand);
  GDALSetMetadataItem(ds, "EXOCET_START_TIME_S", "1700000000.5", nullptr);
  GDALSetMetadataItem(ds, "EXOCET_FRAMES_COMPOSED", "42", nullptr);
  GDALSetMetadataItem(ds, "EXOCET_POSITION_SIGMA_M", "0.25", nullptr);
  std::vector<uint8_t> rgba(size_t(t.width_px) * t.height_px * 4);
  for (int r = 0; r < t.height_px; ++r)
    for (int c = 0; c < t.width_px; ++c) {
      const cv::Vec4b p = t.pixel(c, r);
      uint8_t* out = &rgba[(size_t(r) * t.width_px + c) * 4];
      out[0] = p[2];
      out[1] = p[1];
      out[2] = p[0];
      out[3] = p[3];
    }
  const bool ok = GDALDatasetRasterIO(ds, GF_Write, 0, 0, t.width_px, t.height_px, rgba.data(), t.width_px, t.height_px,
                                      GDT_Byte, 4, nullptr, 4, t.width_px * 4, 1) == CE_None;
  GDALClose(ds);
  return ok;
}

/// The global pixel position (fractional, level z) of a WGS 84 point: its tile is floor(p / 256).
inline cv::Point2d webPixel(double latitude_deg, double longitude_deg, int z) {
  const double res = tiles::resolution_m_per_px(z);
  return {(tiles::mercatorX_m(longitude_deg) + tiles::kMercatorHalfSide_m) / res,
          (tiles::kMercatorHalfSide_m - tiles::mercatorY_m(latitude_deg)) / res};
}

/// A web tile's pixels as BGRA (empty if missing).
inline cv::Mat readWebTile(const std::string& path) { return cv::imread(path, cv::IMREAD_UNCHANGED); }

}  // namespace testing
}  // namespace exocet_web
