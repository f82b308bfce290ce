// Pointing files of boresight quaternions (docs/formats.md, "Pointing files"): dataset `boresight`,
// shape (N, 4), (x, y, z, w) per sample; optional `times` (N,). Read by hyperslab, chunk by chunk.
#include "pisco/pointing_file.hpp"

#include <unistd.h>

#include <cmath>
#include <optional>
#include <string>
#include <system_error>

#include "io/output_file.hpp"
#include "io/hdf5.hpp"
#include "pisco/error.hpp"

namespace pisco {

namespace fs = std::filesystem;
using namespace detail::hdf5;

struct BoresightFile::Impl {
  fs::path path;
  std::string where;
  Handle file;
  Dataset boresight;
  std::optional<Dataset> hwp_angle;
  std::size_t samples = 0;
};

namespace {
constexpr const char* expected_shape = "a floating-point dataset 'boresight' of shape (samples, 4): quaternions x, y, z, w";
}

BoresightFile::BoresightFile(const fs::path& file) : impl_(std::make_unique<Impl>()) {
  Session session;
  impl_->path = file;
  impl_->where = file.string();
  impl_->file = open_read_only(file);
  impl_->boresight = open_dataset(impl_->file.get(), "boresight", "/boresight", impl_->where, expected_shape);
  require_float(impl_->boresight, 2, impl_->where, expected_shape);
  if (impl_->boresight.shape[1] != 4)
    throw Error(impl_->where + ": dataset '/boresight' has shape (" + std::to_string(impl_->boresight.shape[0]) + ", " +
                std::to_string(impl_->boresight.shape[1]) + ") (expected " + expected_shape + ")");
  impl_->samples = impl_->boresight.shape[0];
  if (has_link(impl_->file.get(), "hwp_angle", impl_->where, "dataset '/hwp_angle'")) {
    const char* expected = "a floating-point dataset 'hwp_angle' with one angle per sample";
    impl_->hwp_angle = open_dataset(impl_->file.get(), "hwp_angle", "/hwp_angle", impl_->where, expected);
    require_float(*impl_->hwp_angle, 1, impl_->where, expected);
    if (impl_->hwp_angle->shape[0] != impl_->samples)
      throw Error(impl_->where + ": dataset '/hwp_angle' has " + std::to_string(impl_->hwp_angle->shape[0]) +
                  " samples but '/boresight' has " + std::to_string(impl_->samples) + " (expected one angle per quaternion)");
  }
  if (has_link(impl_->file.get(), "times", impl_->where, "dataset '/times'")) {
    Dataset times = open_dataset(impl_->file.get(), "times", "/times", impl_->where, "a float dataset of N times");
    require_float(times, 1, impl_->where, "a floating-point dataset 'times' with one time per sample");
    if (times.shape[0] != impl_->samples)
      throw Error(impl_->where + ": dataset '/times' has " + std::to_string(times.shape[0]) + " samples but '/boresight' has " +
                  std::to_string(impl_->samples) + " (expected one time per quaternion)");
  }
}

BoresightFile::~BoresightFile() {
  if (impl_) {
    Session session;
    impl_.reset();
  }
}
BoresightFile::BoresightFile(BoresightFile&&) noexcept = default;
BoresightFile& BoresightFile::operator=(BoresightFile&& o) noexcept {
  if (this != &o) {
    Session session;  // the handles being replaced close under the library's HDF5 lock
    impl_ = std::move(o.impl_);
  }
  return *this;
}

bool BoresightFile::holds_boresight(const fs::path& file) {
  Session session;
  const Handle f = open_read_only(file);
  return has_link(f.get(), "boresight", file.string(), "dataset '/boresight'");
}

std::size_t BoresightFile::size() const noexcept { return impl_->samples; }
const fs::path& BoresightFile::path() const noexcept { return impl_->path; }

void BoresightFile::read(std::size_t first, std::size_t count, std::vector<Quat>& out) const {
  const std::string& where = impl_->where;
  if (first > impl_->samples || count > impl_->samples - first)
    throw Error(where + ": samples " + std::to_string(first) + " to " + std::to_string(first + count) +
                " asked for, but '/boresight' has " + std::to_string(impl_->samples));
  out.resize(count);
  if (count == 0) return;
  Session session;
  const hid_t ds = impl_->boresight.handle.get();
  Handle space = checked(H5Dget_space(ds), H5Sclose, where, "cannot get the dataspace of '/boresight'");
  const hsize_t start[2] = {first, 0}, size[2] = {count, 4};
  check(H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, start, nullptr, size, nullptr), where,
        "cannot select samples of '/boresight'");
  Handle memory = checked(H5Screate_simple(2, size, nullptr), H5Sclose, where, "cannot create a dataspace");
  check(H5Dread(ds, H5T_NATIVE_DOUBLE, memory.get(), space.get(), H5P_DEFAULT, out.data()), where,
        "cannot read samples " + std::to_string(first) + " to " + std::to_string(first + count - 1) + " of '/boresight'");
  for (std::size_t i = 0; i < count; ++i) {
    if (const std::string problem = rotation_problem(out[i]); !problem.empty())
      throw Error(where + ": '/boresight' sample " + std::to_string(first + i) + " " + problem);
  }
}

bool BoresightFile::has_hwp_angle() const noexcept { return impl_->hwp_angle.has_value(); }

void BoresightFile::read_hwp_angle(std::size_t first, std::size_t count, std::vector<double>& out) const {
  const std::string& where = impl_->where;
  if (!impl_->hwp_angle) throw Error(where + ": no dataset '/hwp_angle' (expected one half-wave plate angle per sample)");
  if (first > impl_->samples || count > impl_->samples - first)
    throw Error(where + ": samples " + std::to_string(first) + " to " + std::to_string(first + count) +
                " asked for, but '/hwp_angle' has " + std::to_string(impl_->samples));
  out.resize(count);
  if (count == 0) return;
  Session session;
  const hid_t ds = impl_->hwp_angle->handle.get();
  Handle space = checked(H5Dget_space(ds), H5Sclose, where, "cannot get the dataspace of '/hwp_angle'");
  const hsize_t start[1] = {first}, size[1] = {count};
  check(H5Sselect_hyperslab(space.get(), H5S_SELECT_SET, start, nullptr, size, nullptr), where,
        "cannot select samples of '/hwp_angle'");
  Handle memory = checked(H5Screate_simple(1, size, nullptr), H5Sclose, where, "cannot create a dataspace");
  check(H5Dread(ds, H5T_NATIVE_DOUBLE, memory.get(), space.get(), H5P_DEFAULT, out.data()), where,
        "cannot read samples of '/hwp_angle'");
  for (std::size_t i = 0; i < count; ++i)
    if (!std::isfinite(out[i]))
      throw Error(where + ": '/hwp_angle' sample " + std::to_string(first + i) + " is not finite");
}

void BoresightFile::write(const fs::path& file, const std::vector<Quat>& quats, const std::vector<double>& times,
                          const std::vector<double>& hwp_angle) {
  const std::string where = file.string();
  if (!times.empty() && times.size() != quats.size())
    throw Error(where + ": " + std::to_string(times.size()) + " times for " + std::to_string(quats.size()) +
                " quaternions (expected one time per quaternion)");
  if (!hwp_angle.empty() && hwp_angle.size() != quats.size())
    throw Error(where + ": " + std::to_string(hwp_angle.size()) + " plate angles for " + std::to_string(quats.size()) +
                " quaternions (expected one angle per quaternion)");
  const detail::TemporaryListing listed(detail::temporary_name(file));
  const fs::path& temporary = listed.path();
  Session session;
  Handle f;
  try {
    Handle fapl = file_access_plist(where);
    f = checked(H5Fcreate(temporary.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()), H5Fclose, where,
                "cannot create the file");
    inject_write_fault(f.get(), file);
    check_room_for_data(temporary, 8ull * quats.size() * (4 + (times.empty() ? 0 : 1) + (hwp_angle.empty() ? 0 : 1)),
                        where, std::to_string(quats.size()) + " samples");
    const hsize_t dims[2] = {quats.size(), 4};
    Handle space = checked(H5Screate_simple(2, dims, nullptr), H5Sclose, where, "cannot create a dataspace");
    Handle ds = checked(H5Dcreate2(f.get(), "boresight", H5T_IEEE_F64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT,
                                   H5P_DEFAULT),
                        H5Dclose, where, "cannot create dataset '/boresight'");
    if (!quats.empty())
      check(H5Dwrite(ds.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, quats.data()), where,
            "cannot write '/boresight'");
    write_string_attribute(ds.get(), "layout", "quaternions x, y, z, w (scalar last)", where);
    if (!times.empty()) {
      Handle tspace = checked(H5Screate_simple(1, dims, nullptr), H5Sclose, where, "cannot create a dataspace");
      Handle ts = checked(H5Dcreate2(f.get(), "times", H5T_IEEE_F64LE, tspace.get(), H5P_DEFAULT, H5P_DEFAULT,
                                     H5P_DEFAULT),
                          H5Dclose, where, "cannot create dataset '/times'");
      check(H5Dwrite(ts.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, times.data()), where,
            "cannot write '/times'");
    }
    if (!hwp_angle.empty()) {
      Handle hspace = checked(H5Screate_simple(1, dims, nullptr), H5Sclose, where, "cannot create a dataspace");
      Handle hs = checked(H5Dcreate2(f.get(), "hwp_angle", H5T_IEEE_F64LE, hspace.get(), H5P_DEFAULT, H5P_DEFAULT,
                                     H5P_DEFAULT),
                          H5Dclose, where, "cannot create dataset '/hwp_angle'");
      check(H5Dwrite(hs.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, hwp_angle.data()), where,
            "cannot write '/hwp_angle'");
    }
    // Everything reaches the disk before the file is closed (a full disk fails here, not in a close).
    check_room_for_metadata(f.get(), temporary, where);
    check(H5Fflush(f.get(), H5F_SCOPE_GLOBAL), where, "cannot write the file");
    ds.reset();
    if (!f.close()) fail(where, "cannot close the file");
    std::error_code ec;
    fs::rename(temporary, file, ec);
    if (ec) throw Error(where + ": cannot rename the temporary file to it: " + ec.message());
  } catch (...) {
    if (f.valid()) abandon_file(f.get());
    f.reset();
    std::error_code ec;
    fs::remove(temporary, ec);
    throw;
  }
}

}  // namespace pisco
