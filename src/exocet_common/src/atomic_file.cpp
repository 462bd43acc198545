#include "exocet_common/atomic_file.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace exocet_common {

namespace {
std::string folderOf(const std::string& path) {
  const auto slash = path.find_last_of('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}
std::string nameOf(const std::string& path) {
  const auto slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}
}  // namespace

std::string temporaryPathFor(const std::string& final_path) {
  return folderOf(final_path) + "/." + nameOf(final_path) + ".partial-" + std::to_string(::getpid());
}

void commitTemporaryFile(const std::string& temporary_path, const std::string& final_path) {
  const int fd = ::open(temporary_path.c_str(), O_RDONLY);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
  if (std::rename(temporary_path.c_str(), final_path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(temporary_path.c_str());
    throw std::runtime_error("cannot rename '" + temporary_path + "' to '" + final_path + "': " + why);
  }
}

void writeFileAtomically(const std::string& final_path, const std::string& contents) {
  const std::string tmp = temporaryPathFor(final_path);
  FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw std::runtime_error("cannot write '" + final_path + "': " + std::strerror(errno));
  const size_t written = std::fwrite(contents.data(), 1, contents.size(), f);
  const bool ok = written == contents.size() && std::fflush(f) == 0;
  const std::string why = ok ? "" : std::strerror(errno);
  std::fclose(f);
  if (!ok) {
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot write '" + final_path + "': " + why);
  }
  commitTemporaryFile(tmp, final_path);
}

std::string checkWritableDestination(const std::string& path) {
  const std::string folder = folderOf(path);
  struct stat st;
  if (::stat(folder.c_str(), &st) != 0) return "output folder '" + folder + "' does not exist";
  if (!S_ISDIR(st.st_mode)) return "'" + folder + "' is not a folder";
  if (::access(folder.c_str(), W_OK) != 0) return "output folder '" + folder + "' is not writable";
  return "";
}

}  // namespace exocet_common
