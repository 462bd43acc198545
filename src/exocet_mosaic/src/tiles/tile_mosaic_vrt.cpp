#include "exocet_mosaic/tiles/tile_mosaic_vrt.h"

#include <cstdio>
#include <filesystem>

#include <cpl_error.h>
#include <cpl_string.h>
#include <gdal_priv.h>
#include <gdal_utils.h>

namespace exocet_mosaic {
namespace tiles {

std::string writeTileMosaicVrt(const std::string& vrt_path, const std::vector<std::string>& geotiff_paths) {
  if (geotiff_paths.empty()) return "no tile to put in " + vrt_path;
  GDALAllRegister();
  const std::filesystem::path final_path(vrt_path);
  const std::string temporary =
      (final_path.parent_path() / ("." + final_path.filename().string() + ".partial")).string();
  std::vector<const char*> sources;
  for (const auto& p : geotiff_paths) sources.push_back(p.c_str());
  // -addalpha: the tiles' own alpha keeps the no-data of one tile from hiding another underneath.
  char** options = nullptr;
  options = CSLAddString(options, "-addalpha");
  GDALBuildVRTOptions* vrt_options = GDALBuildVRTOptionsNew(options, nullptr);
  CSLDestroy(options);
  int usage_error = 0;
  CPLErrorReset();
  GDALDatasetH vrt = GDALBuildVRT(temporary.c_str(), static_cast<int>(sources.size()), nullptr, sources.data(),
                                  vrt_options, &usage_error);
  GDALBuildVRTOptionsFree(vrt_options);
  if (!vrt || usage_error) {
    const std::string why = CPLGetLastErrorMsg();
    if (vrt) GDALClose(vrt);
    std::remove(temporary.c_str());
    return "cannot build " + vrt_path + ": " + (why.empty() ? "GDALBuildVRT failed" : why);
  }
  GDALClose(vrt);  // written on close
  std::error_code error;
  std::filesystem::rename(temporary, final_path, error);
  if (error) {
    std::remove(temporary.c_str());
    return "cannot rename " + temporary + " to " + vrt_path + ": " + error.message();
  }
  return "";
}

}  // namespace tiles
}  // namespace exocet_mosaic
