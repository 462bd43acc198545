// GDAL helpers of the tiles area (private): registration, datasets closed with their owner, the errors GDAL raises
// in this thread collected for a message instead of printed.
#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <cpl_conv.h>
#include <cpl_error.h>
#include <gdal.h>

namespace exocet_web {
namespace tiles {
namespace detail {

/// GDAL's block cache unless GDAL_CACHEMAX says otherwise: its default, 5 % of the machine's memory (1.2 GB on a 24 GB
/// station), fills over a long dive and reads as a node that grows. The cutter reads each GeoTIFF block once per cut,
/// so a cache only has to hold one cut's window.
constexpr GIntBig kGdalCacheBytes = GIntBig(32) << 20;

inline void registerGdalOnce() {
  static std::once_flag once;
  std::call_once(once, [] {
    GDALAllRegister();
    if (CPLGetConfigOption("GDAL_CACHEMAX", nullptr) == nullptr) GDALSetCacheMax64(kGdalCacheBytes);
  });
}

struct DatasetCloser {
  void operator()(void* dataset) const {
    if (dataset) GDALClose(static_cast<GDALDatasetH>(dataset));
  }
};
using DatasetPtr = std::unique_ptr<void, DatasetCloser>;

/// While it lives, GDAL's errors of this thread are kept (the first few distinct ones) rather than printed.
class GdalErrors {
 public:
  GdalErrors() {
    CPLErrorReset();
    CPLPushErrorHandlerEx(&GdalErrors::handle, this);
  }
  ~GdalErrors() { CPLPopErrorHandler(); }
  GdalErrors(const GdalErrors&) = delete;
  GdalErrors& operator=(const GdalErrors&) = delete;

  /// The failures so far, "; "-joined, "" if none; forgets them.
  std::string take() {
    std::string joined;
    for (const auto& m : messages_) joined += (joined.empty() ? "" : "; ") + m;
    messages_.clear();
    return joined;
  }

 private:
  static void CPL_STDCALL handle(CPLErr error_class, CPLErrorNum, const char* message) {
    auto* self = static_cast<GdalErrors*>(CPLGetErrorHandlerUserData());
    if (!self || error_class < CE_Failure) return;
    const std::string text = message ? message : "unknown GDAL error";
    for (const auto& m : self->messages_)
      if (m == text) return;
    if (self->messages_.size() < 3) self->messages_.push_back(text);
  }
  std::vector<std::string> messages_;
};

}  // namespace detail
}  // namespace tiles
}  // namespace exocet_web
