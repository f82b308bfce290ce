// pisco::OutputLock (include/pisco/output_file.hpp): one run into an output directory at a time,
// without ever touching a file that is not this program's (docs/formats.md, "Errors and partial files").
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <mutex>
#include <string>
#include <system_error>
#include <vector>

#include "io/output_file.hpp"
#include "pisco/error.hpp"
#include "pisco/output_file.hpp"

namespace pisco {
namespace {

namespace fs = std::filesystem;

constexpr const char* header = "pisco-vk output lock\n";
constexpr std::size_t largest_lock_file = 4096;  // ours hold about 80 bytes

struct Held {
  dev_t dir_dev = 0;
  ino_t dir_ino = 0;
  fs::path file;
  int fd = -1;  // -1: a free slot
  dev_t dev = 0;
  ino_t ino = 0;
};

struct Registry {
  std::mutex mutex;
  std::vector<Held> held;
};

Registry& registry() {
  static Registry* r = new Registry;  // never destroyed: a signal may come during static destruction
  return *r;
}

std::string reason(int error) { return std::error_code(error, std::generic_category()).message(); }

// Removes the lock file if it is still the one `h` holds, then unlocks. Under the registry's mutex.
void release(Held& h) noexcept {
  if (h.fd < 0) return;
  struct stat st{};
  if (::lstat(h.file.c_str(), &st) == 0 && st.st_dev == h.dev && st.st_ino == h.ino) ::unlink(h.file.c_str());
  ::close(h.fd);
  h.fd = -1;
}

// What a lock file left by an earlier run says: empty (killed before it wrote), a process id alone
// (earlier versions), or ours: the header, "pid N" and "temporaries SUFFIX". Anything else is a
// file this program did not write.
struct Record {
  bool ours = false;
  std::string pid, suffix;
};

Record parse(const std::string& text) {
  Record r;
  if (text.empty()) {
    r.ours = true;
    return r;
  }
  if (text.find_first_not_of("0123456789\n") == std::string::npos && text.size() <= 12 && text.back() == '\n' &&
      text.find('\n') == text.size() - 1 && text.size() > 1) {
    r.ours = true;
    r.pid = text.substr(0, text.size() - 1);
    return r;
  }
  if (text.rfind(header, 0) != 0) return r;
  std::size_t at = std::strlen(header);
  while (at < text.size()) {
    const std::size_t end = text.find('\n', at);
    if (end == std::string::npos) return r;  // a line cut short: not as this program writes it
    const std::string line = text.substr(at, end - at);
    if (line.rfind("pid ", 0) == 0)
      r.pid = line.substr(4);
    else if (line.rfind("temporaries ", 0) == 0)
      r.suffix = line.substr(12);
    else
      return r;
    at = end + 1;
  }
  // The suffix as temporary_suffix() makes it, so that it can name no user's file.
  const std::string prefix = ".tmp-pisco-";
  if (!r.suffix.empty() && (r.suffix.rfind(prefix, 0) != 0 || r.suffix.size() < prefix.size() + 18 ||
                            r.suffix.find('/') != std::string::npos))
    return r;
  if (r.pid.empty() || r.pid.find_first_not_of("0123456789") != std::string::npos) return r;
  r.ours = true;
  return r;
}

std::string read_all(int fd, std::size_t size) {
  std::string text(size, '\0');
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::pread(fd, text.data() + done, size - done, off_t(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    done += std::size_t(n);
  }
  text.resize(done);
  return text;
}

}  // namespace

namespace detail {
void release_output_locks() noexcept {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  for (Held& h : r.held) release(h);
}
}  // namespace detail

bool OutputLock::held(const fs::path& dir) {
  struct stat st{};
  if (::stat(dir.c_str(), &st) != 0) return false;
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  for (const Held& h : r.held)
    if (h.fd >= 0 && h.dir_dev == st.st_dev && h.dir_ino == st.st_ino) return true;
  return false;
}

OutputLock::OutputLock(const fs::path& dir, const std::function<void(const std::string&)>& say) {
  const fs::path file = dir / file_name;
  const std::string where = file.string();
  auto refuse = [&](const std::string& what) {
    throw Error(where + ": " + what + "; it is left alone: remove it, or choose another output directory",
                ErrorKind::io);
  };
  struct stat dir_st{};
  if (::stat(dir.c_str(), &dir_st) != 0 || !S_ISDIR(dir_st.st_mode))
    throw Error(dir.string() + ": not a directory (expected the output directory, made before it is locked)",
                ErrorKind::io);
  Registry& r = registry();
  std::lock_guard guard(r.mutex);
  for (const Held& h : r.held)
    if (h.fd >= 0 && h.dir_dev == dir_st.st_dev && h.dir_ino == dir_st.st_ino)
      throw Error(dir.string() + ": another run of this process is writing into this directory; wait for it to "
                                 "end or choose another output directory",
                  ErrorKind::io);

  int fd = -1;
  struct stat st{};
  Record stale;
  for (int attempt = 0;; ++attempt) {
    if (attempt == 10)
      throw Error(where + ": the lock file keeps being replaced by another process; try again", ErrorKind::io);
    // Made here, or opened as it is: never through a link (O_NOFOLLOW), never truncated.
    bool made = true;
    fd = ::open(file.c_str(), O_RDWR | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
    if (fd < 0 && errno == EEXIST) {
      made = false;
      fd = ::open(file.c_str(), O_RDWR | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
      if (fd < 0 && errno == ENOENT) continue;  // removed meanwhile by the run that held it
      if (fd < 0 && errno == ELOOP) refuse("is a symbolic link, not a lock file of pisco-vk");
      if (fd < 0 && errno == EISDIR) refuse("is not a regular file, so not a lock file of pisco-vk");
    }
    if (fd < 0) {
      const int e = errno;
      throw Error(where + ": cannot " + (made ? "create" : "open") + " the run's lock file (" + reason(e) + ")",
                  ErrorKind::io);
    }
    auto give_up = [&](const std::string& what) {
      ::close(fd);
      refuse(what);
    };
    if (::fstat(fd, &st) != 0) give_up("cannot be examined (" + reason(errno) + ")");
    if (!S_ISREG(st.st_mode)) give_up("is not a regular file, so not a lock file of pisco-vk");
    if (st.st_nlink != 1)
      give_up("has " + std::to_string(st.st_nlink) + " hard links, so it is not a lock file of pisco-vk");
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const Record holder = parse(read_all(fd, std::min<std::size_t>(std::size_t(st.st_size), largest_lock_file)));
      ::close(fd);
      throw Error(dir.string() + ": another pisco-vk run (" +
                      (holder.ours && !holder.pid.empty() ? "process " + holder.pid : std::string("another process")) +
                      ") is writing into this directory; wait for it to end or choose another output directory",
                  ErrorKind::io);
    }
    // The run that held it may have removed it between our open and our lock: then lock the new one.
    struct stat now{};
    if (::lstat(file.c_str(), &now) != 0 || now.st_dev != st.st_dev || now.st_ino != st.st_ino) {
      ::close(fd);
      continue;
    }
    if (!made) {
      if (std::size_t(st.st_size) > largest_lock_file)
        give_up("holds " + std::to_string(st.st_size) + " bytes, so it is not a lock file of pisco-vk");
      stale = parse(read_all(fd, std::size_t(st.st_size)));
      if (!stale.ours) give_up("holds text that pisco-vk does not write, so it is not a lock file of pisco-vk");
    }
    break;
  }

  // Ours now (made here, or left by a run that ended): record this process.
  const std::string text = std::string(header) + "pid " + std::to_string(::getpid()) + "\ntemporaries " +
                           temporary_suffix() + "\n";
  bool written = ::ftruncate(fd, 0) == 0 && ::pwrite(fd, text.data(), text.size(), 0) == ssize_t(text.size());
  (void)written;  // without the record the lock still holds: only a second run's message is the poorer

  std::size_t slot = 0;
  while (slot < r.held.size() && r.held[slot].fd >= 0) ++slot;
  if (slot == r.held.size()) r.held.emplace_back();
  r.held[slot] = Held{dir_st.st_dev, dir_st.st_ino, file, fd, st.st_dev, st.st_ino};
  slot_ = int(slot);

  // The temporaries of the run that left the lock file: exactly the names that end with the suffix it
  // recorded. Its process has ended (its lock was released), so none of them is being written.
  if (stale.suffix.empty()) return;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name.size() <= stale.suffix.size() ||
        name.compare(name.size() - stale.suffix.size(), stale.suffix.size(), stale.suffix) != 0)
      continue;
    std::error_code rec;
    const fs::file_status s = e.symlink_status(rec);
    if (rec || !fs::is_regular_file(s)) continue;
    if (fs::remove(e.path(), rec) && say)
      say("removed " + e.path().string() + ", a temporary file left by process " + stale.pid + ", which has ended");
  }
}

OutputLock::~OutputLock() {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  if (slot_ >= 0 && std::size_t(slot_) < r.held.size()) release(r.held[std::size_t(slot_)]);
}

}  // namespace pisco
