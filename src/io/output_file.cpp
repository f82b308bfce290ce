#include "io/output_file.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <cstdio>
#include <mutex>
#include <random>
#include <set>
#include <string>
#include <system_error>

#include "pisco/error.hpp"
#include "pisco/output_file.hpp"

namespace pisco {
namespace detail {
namespace {

namespace fs = std::filesystem;

struct Listing {
  std::mutex mutex;
  std::multiset<fs::path> paths;
};

Listing& listing() {
  static Listing* l = new Listing;  // never destroyed: a signal may come during static destruction
  return *l;
}

std::string system_reason(int error) { return std::error_code(error, std::generic_category()).message(); }

}  // namespace

TemporaryListing::TemporaryListing(fs::path temporary) : path_(std::move(temporary)) {
  Listing& l = listing();
  std::lock_guard lock(l.mutex);
  l.paths.insert(path_);
}

TemporaryListing::~TemporaryListing() {
  Listing& l = listing();
  std::lock_guard lock(l.mutex);
  const auto it = l.paths.find(path_);
  if (it != l.paths.end()) l.paths.erase(it);
}

fs::path temporary_name(const fs::path& file) {
  fs::path t = file;
  t += temporary_suffix();
  return t;
}

bool write_fault_requested(const fs::path& file) {
  const char* v = std::getenv("PISCO_TEST_FAULT");
  if (!v) return false;
  const std::string s(v), prefix = "write-fail:";
  return s.rfind(prefix, 0) == 0 && s.substr(prefix.size()) == file.filename().string();
}

void make_disk_full(int fd, const fs::path& file) {
  const int full = ::open("/dev/full", O_WRONLY | O_CLOEXEC);
  if (full < 0 || ::dup3(full, fd, O_CLOEXEC) < 0) {
    const int e = errno;
    if (full >= 0) ::close(full);
    throw Error(file.string() + ": PISCO_TEST_FAULT: cannot open /dev/full (" + system_reason(e) + ")", ErrorKind::io);
  }
  ::close(full);
}

int descriptor_of(const fs::path& path) {
  std::error_code ec;
  const fs::path target = fs::weakly_canonical(fs::absolute(path, ec), ec);
  for (const auto& entry : fs::directory_iterator("/proc/self/fd", ec)) {
    std::error_code link_ec;
    const fs::path linked = fs::read_symlink(entry.path(), link_ec);
    if (!link_ec && linked == target) return std::atoi(entry.path().filename().c_str());
  }
  return -1;
}

bool divert_descriptor(int fd) noexcept {
  const int mem = ::memfd_create("pisco-abandoned", MFD_CLOEXEC);
  if (mem < 0) return false;
  const bool ok = ::dup3(mem, fd, O_CLOEXEC) >= 0;
  ::close(mem);
  return ok;
}

}  // namespace detail

const std::string& temporary_suffix() {
  // Made once: the process id names the run to a reader; 64 random bits make the name one that no
  // user's file and no other process has.
  static const std::string suffix = [] {
    std::random_device device;
    const std::uint64_t token = (std::uint64_t(device()) << 32) ^ std::uint64_t(device());
    char text[64];
    std::snprintf(text, sizeof text, ".tmp-pisco-%ld-%016llx", long(::getpid()), static_cast<unsigned long long>(token));
    return std::string(text);
  }();
  return suffix;
}

void write_file_atomically(const std::filesystem::path& file, std::string_view contents) {
  const std::string where = file.string();
  const detail::TemporaryListing temporary(detail::temporary_name(file));
  const char* tmp = temporary.path().c_str();
  const int fd = ::open(tmp, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
  if (fd < 0)
    throw Error(where + ": cannot create the temporary file '" + temporary.path().string() + "' (" +
                detail::system_reason(errno) + ")", ErrorKind::io);
  auto fail = [&](const std::string& what, int error) {
    ::close(fd);
    ::unlink(tmp);
    throw Error(where + ": " + what + " (" + detail::system_reason(error) + ")", ErrorKind::io);
  };
  try {
    if (detail::write_fault_requested(file)) detail::make_disk_full(fd, file);
  } catch (...) {
    ::close(fd);
    ::unlink(tmp);
    throw;
  }
  std::size_t done = 0;
  while (done < contents.size()) {
    const ssize_t n = ::write(fd, contents.data() + done, contents.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail("cannot write " + std::to_string(contents.size()) + " bytes", n < 0 ? errno : EIO);
    done += static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0) {
    const int e = errno;
    ::unlink(tmp);
    throw Error(where + ": cannot close the temporary file (" + detail::system_reason(e) + ")", ErrorKind::io);
  }
  if (::rename(tmp, file.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp);
    throw Error(where + ": cannot rename the temporary file to it (" + detail::system_reason(e) + ")", ErrorKind::io);
  }
}

std::vector<std::filesystem::path> temporary_files() {
  detail::Listing& l = detail::listing();
  std::lock_guard lock(l.mutex);
  std::vector<std::filesystem::path> out;
  for (const auto& p : l.paths) {
    std::error_code ec;
    if (std::filesystem::exists(p, ec)) out.push_back(p);
  }
  return out;
}

std::size_t remove_temporary_files() noexcept {
  detail::Listing& l = detail::listing();
  std::lock_guard lock(l.mutex);
  std::size_t removed = 0;
  for (const auto& p : l.paths)
    if (::unlink(p.c_str()) == 0) ++removed;
  detail::release_output_locks();
  return removed;
}

}  // namespace pisco
